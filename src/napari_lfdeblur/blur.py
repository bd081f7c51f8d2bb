"""The light-field motion-blur operator (docs/model.md, "Forward model").

For each exposure instant ``t_k`` the angular shifts are::

    s_u(x, t) = p_x(t) - x~ p_z(t)
    s_v(y, t) = p_y(t) - y~ p_z(t)

and the blurred light field is the mean over the ``T`` instants of the sharp
one resampled at ``(v + s_v, u + s_u, y + d_inf s_v, x + d_inf s_u)``, with
bilinear interpolation and replicated boundaries.

Implementation
--------------
With ``d_inf = 0`` the sample ``v + s_v`` splits into an integer offset and a
bilinear fraction, and so does ``u + s_u``. Summed over the exposure, every
pixel therefore sees a small 2D kernel over integer view offsets, the
bilinear histogram of the angular shifts it goes through (see
:func:`tap_kernel`)::

    f[a, b, y, x] = sum_(i, j) K[y, x, i, j] l[clamp(a + ov + i), clamp(b + ou + j), y, x]

``K`` is an outer product of per-row and per-column splats summed over the
instants, cheap to build and differentiable in the path. Applying it costs
one multiply-add pass per offset the path visits, over blocks of rows small
enough to stay in cache, with no ``T``-fold copy of the light field. A
custom autograd function recomputes the blocks in the backward pass, so
gradients for both the light field and the path store no intermediates.

With ``d_inf != 0`` each instant also shifts ``y`` and ``x``; the exposure is
then one kernel over 4D integer offsets ``(v, y, u, x)``, applied the same
way (:func:`~napari_lfdeblur._taps4d.tap_kernel_4d`).

On the CPU, when numba is installed, both kernels are applied by fused loops
instead (:mod:`~napari_lfdeblur._fused`): one parallel pass over the output
rows, with no padded copies, and the same sums.

A path with rotation (6 columns) displaces the image by amounts that vary
over the whole view; its 4D kernels are built and applied per spatial tile
(:mod:`~napari_lfdeblur._taps_tiled`).
"""

from __future__ import annotations

import operator

import numpy as np
import torch

from . import _fused
from ._lightfield import check_infinity_disparity, check_number, validate_lightfield
from .devices import select_device
from ._taps import TapBlur, Taps, tap_kernel
from ._taps4d import Taps4D, tap_kernel_4d
from ._taps_tiled import TiledTaps, rotation_displacement, tile_side, tiled_kernel
from .path import MAX_ROTATION, bezier_positions, has_rotation, validate_control_points, validate_n_times

__all__ = [
    "BlurOperator",
    "simulate_blur",
    "validate_lightfield",
    "validate_frame",
    "to_tensor",
    "from_tensor",
    "normalized_coordinates",
    "interpolation_matrices",
    "angular_shifts",
    "image_shifts",
    "tap_kernel",
    "lerp_taps",
]

#: elements of temporary memory one block may use (float32: 4 bytes each). Blocks
#: of a few MB keep the per-call overhead of torch (and the wait for OpenMP
#: threads on a busy machine) small against the work; on a GPU larger blocks
#: mean fewer kernel launches.
DEFAULT_BLOCK_ELEMENTS = {"cpu": 1 << 22, "cuda": 1 << 24}


# ----------------------------------------------------------------- arrays


def to_tensor(lf, device=None, dtype=torch.float32) -> torch.Tensor:
    """Numpy ``(V, U, Y, X[, C])`` to a torch ``(V, U, Y, X, C)`` tensor (C = 1 for grayscale)."""
    arr = np.ascontiguousarray(validate_lightfield(lf))
    if not arr.dtype.isnative or arr.dtype == np.longdouble:  # big-endian (FITS, MATLAB, HDF5 data), float128:
        arr = arr.astype(arr.dtype.newbyteorder("=") if arr.dtype != np.longdouble else np.float64)  # not torch's
    elif not arr.flags.writeable:  # torch shares a numpy array's memory, and warns when it is read-only
        arr = arr.copy()
    t = torch.as_tensor(arr, dtype=dtype, device=select_device(device))
    return t.unsqueeze(-1) if arr.ndim == 4 else t


def from_tensor(t: torch.Tensor, ndim: int) -> np.ndarray:
    """Torch ``(V, U, Y, X, C)`` back to numpy float32 with ``ndim`` dimensions (4 or 5)."""
    out = t.detach()
    if ndim == 4:
        out = out[..., 0]
    return out.to(device="cpu", dtype=torch.float32).numpy()


def normalized_coordinates(n: int, r: float, dtype=torch.float32, device=None) -> torch.Tensor:
    """``(i - (n - 1) / 2) / r`` for ``i = 0 .. n-1``: centred, normalised pixel coordinates."""
    return (torch.arange(n, dtype=dtype, device=device) - (n - 1) / 2.0) / r


def validate_frame(frame, shape):
    """Check a tile's ``(y0, x0, Y_full, X_full)`` against the tile's ``shape``; None passes."""
    if frame is None:
        return None
    try:
        y0, x0, Yf, Xf = (operator.index(v) for v in frame)
    except (TypeError, ValueError):
        raise ValueError(f"frame must be (y0, x0, Y_full, X_full), whole numbers; got {frame!r}") from None
    Y, X = shape[2], shape[3]
    if y0 < 0 or x0 < 0 or y0 + Y > Yf or x0 + X > Xf:
        raise ValueError(f"a {Y}x{X} tile at ({y0}, {x0}) does not fit in a {Yf}x{Xf} frame")
    return (y0, x0, Yf, Xf)


def lerp_taps(coord: torch.Tensor, size: int):
    """Clamped bilinear taps for sample coordinates ``coord`` on an axis of ``size``.

    Parameters
    ----------
    coord : torch.Tensor, float
        Sample coordinates (clamped to ``[0, size - 1]``).
    size : int
        Length of the axis.

    Returns
    -------
    i0, i1 : torch.Tensor, int64, ``coord``'s shape
    w : torch.Tensor, ``coord``'s dtype and shape
        The value at ``coord`` is ``(1 - w) * a[i0] + w * a[i1]``; ``w``
        stays differentiable with respect to ``coord``.
    """
    c = coord.clamp(0.0, size - 1.0)
    i0 = torch.floor(c.detach()).clamp_(0, max(size - 2, 0)).long()
    i1 = (i0 + 1).clamp_(max=size - 1)
    w = c - i0.to(c.dtype)
    return i0, i1, w


def _interp_matrices(shift: torch.Tensor, size: int) -> torch.Tensor:
    """Interpolation matrices ``M[..., a, b]``: output sample ``a`` reads ``a + shift``.

    ``shift`` has any shape ``S``; the result has shape ``S + (size, size)``.
    """
    target = torch.arange(size, dtype=shift.dtype, device=shift.device)
    i0, i1, w = lerp_taps(shift[..., None] + target, size)
    cols = torch.arange(size, device=shift.device)
    m0 = (i0[..., None] == cols).to(shift.dtype)
    m1 = (i1[..., None] == cols).to(shift.dtype)
    return (1.0 - w)[..., None] * m0 + w[..., None] * m1


def _frame_coordinates(positions: torch.Tensor, shape, frame):
    """``x~`` (X,), ``y~`` (Y,) of a light field's columns and rows, in its frame, and ``R`` (px)."""
    Y, X = shape[2], shape[3]
    y0, x0, Yf, Xf = (0, 0, Y, X) if frame is None else frame
    r = max(Xf, Yf) / 2.0
    xt = normalized_coordinates(Xf, r, positions.dtype, positions.device)[x0 : x0 + X]
    yt = normalized_coordinates(Yf, r, positions.dtype, positions.device)[y0 : y0 + Y]
    return xt, yt, r


def angular_shifts(positions: torch.Tensor, shape, frame=None):
    """``s_u(x, t_k) = p_x - x~ p_z`` and ``s_v(y, t_k) = p_y - y~ p_z`` (docs/model.md).

    Parameters
    ----------
    positions : torch.Tensor, shape (T, 3) or (T, 6)
        Path positions; a rotation (columns 3 to 5) does not enter here.
    shape : tuple
        ``(V, U, Y, X, ...)`` of the light field.
    frame : tuple of 4 int, optional
        ``(y0, x0, Y_full, X_full)`` when the light field is the tile at
        ``(y0, x0)`` of a larger one: ``x~, y~`` are then those of the full
        frame.

    Returns
    -------
    s_u : torch.Tensor, shape (T, X)
    s_v : torch.Tensor, shape (T, Y)
    """
    xt, yt, _ = _frame_coordinates(positions, shape, frame)
    return (
        positions[:, 0:1] - xt[None, :] * positions[:, 2:3],
        positions[:, 1:2] - yt[None, :] * positions[:, 2:3],
    )


def image_shifts(positions: torch.Tensor, shape, frame=None):
    """The image displacement ``R (x~' - x~)``, ``R (y~' - y~)`` of a path's rotation (docs/model.md).

    Parameters
    ----------
    positions : torch.Tensor, shape (T, 6)
        Path positions ``(p_x, p_y, p_z, r_x, r_y, r_z)`` at the instants.
    shape : tuple
        ``(V, U, Y, X, ...)`` of the light field.
    frame : tuple of 4 int, optional
        As in :func:`angular_shifts`.

    Returns
    -------
    t_y, t_x : torch.Tensor, shape (T, Y, X)
        Displacements in px, before the ``d_inf`` share of the angular shifts.
    """
    xt, yt, r = _frame_coordinates(positions, shape, frame)
    return rotation_displacement(positions[:, 3:6], xt, yt, r)


def interpolation_matrices(positions: torch.Tensor, shape):
    """The angular interpolation matrices of every instant.

    Parameters
    ----------
    positions : torch.Tensor, shape (T, 3)
        Path positions ``(p_x, p_y, p_z)`` at the instants.
    shape : tuple
        ``(V, U, Y, X)`` of the light field.

    Returns
    -------
    A : torch.Tensor, shape (T, X, U, U)
        ``A[k, x]`` maps the ``U`` samples of a row of views to their
        interpolation at ``u + s_u(x, t_k)``.
    B : torch.Tensor, shape (T, Y, V, V)
        Likewise along ``v`` at ``v + s_v(y, t_k)``.
    s_u : torch.Tensor, shape (T, X)
    s_v : torch.Tensor, shape (T, Y)
    """
    s_u, s_v = angular_shifts(positions, shape)
    return _interp_matrices(s_u, shape[1]), _interp_matrices(s_v, shape[0]), s_u, s_v


# -------------------------------------------------------------- operator


def _check_view_step(view_step) -> int:
    """``view_step`` as an int, or a ValueError when it is not a positive integer."""
    if isinstance(view_step, bool) or not isinstance(view_step, (int, np.integer)) or view_step < 1:
        raise ValueError(f"view_step must be a positive integer; got {view_step!r}")
    return int(view_step)


class BlurOperator:
    """The motion-blur operator of one camera path on light fields of one shape.

    Parameters
    ----------
    shape : tuple of int
        ``(V, U, Y, X)`` or ``(V, U, Y, X, C)`` of the light fields it acts on.
    control_points : array_like or torch.Tensor, shape (n, 3) or (n, 6)
        Bezier control points of the path: ``(p_x, p_y, p_z)`` in view units,
        then optionally the rotation ``(r_x, r_y, r_z)`` in radians
        (docs/model.md). A tensor with ``requires_grad`` makes
        :meth:`forward` differentiable in the path.
    n_times : int, default 32
        Number of exposure instants ``T >= 2``.
    infinity_disparity : float, default 0.0
        ``d_inf`` in px/view.
    device : {'auto', 'cpu', 'cuda'} or torch.device, default 'auto'
    dtype : torch.dtype, default torch.float32
    block_elements : int, optional
        Temporary memory of one block, in elements; by default
        ``DEFAULT_BLOCK_ELEMENTS`` of the device type.
    frame : tuple of 4 int, optional
        ``(y0, x0, Y_full, X_full)``: the light fields are the tile at
        ``(y0, x0)`` of a ``Y_full x X_full`` one, whose normalised
        coordinates ``x~, y~`` (hence ``p_z``'s shifts) apply. The boundary
        stays the tile's own (replicate), so tiles of a larger light field
        need an overlap when ``d_inf != 0``.

    Notes
    -----
    :meth:`forward` and :meth:`adjoint` take and return torch tensors of shape
    ``(V, U, Y, X, C)`` (``C = 1`` for grayscale); :func:`to_tensor` and
    :func:`from_tensor` convert from and to numpy.

    Examples
    --------
    >>> import numpy as np, torch
    >>> op = BlurOperator((5, 5, 8, 8), [[-1, 0, 0], [1, 0, 0]], n_times=8, device="cpu")
    >>> x = torch.rand(5, 5, 8, 8, 1)
    >>> op.forward(x).shape
    torch.Size([5, 5, 8, 8, 1])
    """

    def __init__(
        self,
        shape,
        control_points,
        n_times: int = 32,
        infinity_disparity: float = 0.0,
        device="auto",
        dtype=torch.float32,
        block_elements: int | None = None,
        frame=None,
    ):
        try:
            shape = tuple(operator.index(s) for s in shape)  # no 3.7 taken as 3
        except TypeError:
            raise ValueError(f"shape must be (V, U, Y, X[, C]) of whole numbers; got {shape}") from None
        if len(shape) not in (4, 5) or min(shape) < 1:
            raise ValueError(f"shape must be (V, U, Y, X[, C]) of positive sizes; got {shape}")
        self.shape = shape[:4] + ((shape[4],) if len(shape) == 5 else (1,))
        self.frame = validate_frame(frame, self.shape)
        self.n_times = validate_n_times(n_times)
        self.infinity_disparity = check_number(infinity_disparity, "infinity_disparity")
        if not (isinstance(dtype, torch.dtype) and dtype.is_floating_point):
            raise TypeError(f"dtype must be a floating-point torch dtype (torch.float32, torch.float64); "
                            f"got {dtype!r}")
        self.dtype = dtype
        if isinstance(control_points, torch.Tensor):
            self.device = control_points.device if device in (None, "auto") else select_device(device)
            cp = control_points.to(device=self.device, dtype=dtype)
            if cp.ndim != 2 or cp.shape[1] not in (3, 6):
                raise ValueError(f"control points must be (n, 3) or (n, 6); got {tuple(cp.shape)}")
            if cp.shape[1] == 6 and float(cp.detach()[:, 3:].abs().max()) > MAX_ROTATION * (1 + 1e-5):  # (rounding)
                raise ValueError(f"rotations must stay within {MAX_ROTATION} rad, where the small-angle model holds; "
                                 f"got {float(cp.detach()[:, 3:].abs().max()):.3g} rad")
        else:
            self.device = select_device(device)
            cp = torch.as_tensor(validate_control_points(control_points), dtype=dtype, device=self.device)
        self.control_points = cp
        if block_elements is None:
            block_elements = DEFAULT_BLOCK_ELEMENTS.get(self.device.type, DEFAULT_BLOCK_ELEMENTS["cpu"])
        if isinstance(block_elements, bool) or not isinstance(block_elements, (int, np.integer)) or block_elements < 1:
            raise ValueError(f"block_elements must be a whole number >= 1; got {block_elements!r}")
        self.block_elements = int(block_elements)
        self.positions = bezier_positions(cp, self.n_times)  # refuses NaN or Inf in a tensor
        V, U = self.shape[:2]
        #: angular shifts s_u (T, X) and s_v (T, Y) of every instant
        self.s_u, self.s_v = angular_shifts(self.positions, self.shape, self.frame)
        #: 'angular' (d_inf = 0), '4d' (d_inf != 0) or 'tiled' (rotation): how the kernel is held
        self.kind = "angular" if self.infinity_disparity == 0.0 else "4d"
        # a 6-column path without rotation is the 3-DOF one, unless its rotation needs a gradient
        if cp.shape[1] == 6 and (cp.requires_grad or has_rotation(cp)):
            self.kind = "tiled"
        self._tiles = None  # the TiledTaps of a path with rotation (its tiles' index vectors cost to build)
        self._fused = None  # the FusedTaps of the kernel, on the CPU with numba (its column spans cost to find)
        if self.kind == "angular":
            self._kernel = tap_kernel(self.s_u, self.s_v, U, V)
        elif self.kind == "4d":
            self._kernel = tap_kernel_4d(self.s_u, self.s_v, self.infinity_disparity, self.shape)
        else:
            self._kernel = self._tiled_kernel()
            self._tiles = TiledTaps(self.shape, *self._kernel)

    def _tiled_kernel(self):
        t_y, t_x = image_shifts(self.positions, self.shape, self.frame)
        d = self.infinity_disparity
        if d != 0.0:
            t_y = t_y + d * self.s_v[:, :, None]
            t_x = t_x + d * self.s_u[:, None, :]
        fused = _fused.available(self.device, self.dtype)
        return tiled_kernel(self.s_v, self.s_u, t_y, t_x, self.shape, tile_side(self.shape, self.block_elements, fused),
                            fused)

    def _check(self, t: torch.Tensor, shape=None) -> torch.Tensor:
        """``t``, checked to be a torch tensor of ``shape`` (default: the operator's)."""
        shape = self.shape if shape is None else shape
        if not isinstance(t, torch.Tensor):
            raise TypeError("BlurOperator works on torch tensors; use simulate_blur for numpy arrays")
        if tuple(t.shape) != shape:
            raise ValueError(f"expected a tensor of shape {shape}; got {tuple(t.shape)}")
        if t.device.type != self.device.type or (t.device.index or 0) != (self.device.index or 0):
            raise ValueError(f"the tensor is on {t.device}, the operator on {self.device}: "
                             "move one of them")
        if t.dtype != self.dtype:
            raise TypeError(f"expected a tensor of dtype {self.dtype} (the operator's); got {t.dtype}")
        return t

    def forward(self, lf: torch.Tensor, view_step: int = 1) -> torch.Tensor:
        """Blur ``lf`` (shape ``(V, U, Y, X, C)``); differentiable in ``lf`` and the path.

        ``view_step = s > 1`` returns only the views ``0, s, 2s, ...`` along
        ``v`` and ``u``, shape ``(ceil(V/s), ceil(U/s), Y, X, C)``: a path fit
        on a subsample of the views. With a rotation only those views are
        computed; otherwise the whole blur is computed and sliced.
        """
        L = self._check(lf)
        s = _check_view_step(view_step)
        if s > 1 and self.kind == "tiled":
            return TapBlur.apply(L, self._kernel[0], self._tiles.with_view_step(s))
        out = TapBlur.apply(L, self._kernel[0], self._taps())
        return out if s == 1 else out[::s, ::s]

    __call__ = forward

    def adjoint(self, y: torch.Tensor, view_step: int = 1) -> torch.Tensor:
        """The adjoint (transpose) of :meth:`forward` in the light field, for a fixed path.

        With ``view_step = s > 1``, ``y`` holds the views ``0, s, 2s, ...``
        (the shape :meth:`forward` returns for that step) and the result is
        the whole light field's shape.
        """
        s = _check_view_step(view_step)
        V, U = self.shape[:2]
        G = self._check(y, (len(range(0, V, s)), len(range(0, U, s))) + self.shape[2:]).detach().contiguous()
        if s == 1:
            return self._taps().adjoint(G)
        if self.kind == "tiled":
            return self._tiles.with_view_step(s).adjoint(G)
        full = G.new_zeros(self.shape)  # the adjoint of keeping every s-th view: zeros at the others
        full[::s, ::s] = G
        return self._taps().adjoint(full)

    def _taps(self):
        """The object that applies the kernel: :class:`Taps`, :class:`Taps4D` or :class:`TiledTaps`.

        Without rotation, on the CPU and with numba, the fused loops of
        :mod:`~napari_lfdeblur._fused` (a :class:`FusedTaps`) instead.
        """
        if self.kind != "tiled" and _fused.available(self.device, self.dtype):
            if self._fused is None:
                if self.kind == "angular":
                    self._fused = _fused.FusedTaps.angular(self.shape, *self._kernel)
                else:
                    self._fused = _fused.FusedTaps(self.shape, *self._kernel)
            return self._fused
        if self.kind == "angular":
            K, ov, ou = self._kernel
            return Taps(self.shape, K, ov, ou, self.block_elements)
        if self.kind == "4d":
            K, offsets = self._kernel
            return Taps4D(self.shape, K, offsets, self.block_elements)
        return self._tiles

    @property
    def n_taps(self) -> float:
        """Passes over the light field one forward costs: the kernel's offsets that carry weight.

        With rotation, the mean over the spatial tiles.
        """
        if self.kind == "angular":
            return int((self._kernel[0].detach().abs().amax(dim=(0, 1)) > 0).sum())
        if self.kind == "4d":
            return int(self._kernel[0].shape[0])
        return self._taps().n_taps


def simulate_blur(lf, control_points, *, n_times: int = 32, infinity_disparity: float = 0.0, device="auto"):
    """Blur a light field by a camera path, following the forward model of docs/model.md exactly.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        The sharp light field. Any real dtype; computed in float32.
    control_points : array_like, shape (n, 3) or (n, 6)
        Bezier control points ``(p_x, p_y, p_z)`` in views, ``n >= 2``,
        optionally followed by a rotation ``(r_x, r_y, r_z)`` in radians
        (each within ``MAX_ROTATION``).
    n_times : int, default 32
        Number of exposure instants ``T >= 2``.
    infinity_disparity : float, default 0.0
        Disparity of points at infinity ``d_inf``, px/view: finite, and
        ``|d_inf| (max(V, U) - 1) / 2 <= min(Y, X) / 2`` (the outermost
        view's refocus within half the view).
    device : {'auto', 'cpu', 'cuda'}, default 'auto'

    Returns
    -------
    ndarray, float32, same shape as ``lf``
        The blurred light field.

    Raises
    ------
    ValueError
        If ``infinity_disparity`` is not finite or beyond that bound.

    Examples
    --------
    >>> import numpy as np
    >>> lf = np.random.default_rng(0).random((5, 5, 16, 16)).astype(np.float32)
    >>> zero_path = [[0, 0, 0], [0, 0, 0]]
    >>> simulate_blur(lf, zero_path).shape
    (5, 5, 16, 16)
    >>> bool(np.allclose(simulate_blur(lf, zero_path), lf))  # a zero path is the identity
    True
    """
    arr = validate_lightfield(lf)
    n_times = validate_n_times(n_times)
    cp = validate_control_points(control_points)
    d_inf = check_infinity_disparity(infinity_disparity, arr.shape)
    op = BlurOperator(arr.shape, cp, n_times=n_times, infinity_disparity=d_inf, device=device)
    with torch.no_grad():
        out = op.forward(to_tensor(arr, device=op.device))
    return from_tensor(out, arr.ndim)
