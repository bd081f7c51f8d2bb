"""Fused CPU loops (numba): the tap blur with its adjoint and kernel gradient, the 4D-TV prox, two blind steps.

A tap kernel is ``S`` weight maps ``K[s]`` of shape ``(Y, X)`` with integer
offsets ``(a, b, c, e)`` of ``(v, y, u, x)``::

    f[v, u, y, x] = sum_s K[s, y, x] l[clamp(v + a), clamp(u + c), clamp(y + b), clamp(x + e)]

(:mod:`~napari_lfdeblur._taps` at ``d_inf = 0``, where ``b = e = 0``,
:mod:`~napari_lfdeblur._taps4d` otherwise, and with rotation one such kernel
per spatial tile, :mod:`~napari_lfdeblur._taps_tiled`). The torch versions make one
multiply-add pass over a block of the light field per tap, through padded
copies. These loops instead make one pass over the output, row by row in
parallel: the rows a tap reads stay in cache, nothing is padded or copied,
and the ``x`` loop is contiguous in ``(x, channel)``. The forward adds the
taps that read the same rows (they differ only in ``e``) in one pass, up to
four at a time; it agrees with the torch version to rounding.

The adjoint is written as a gather over the output rows of the adjoint (each
thread owns the rows it writes), so it needs no atomic adds. Clamped indices
make edge rows and columns collect the terms of every sample read beyond
the edge, as the model's replicate boundary does.

The TV prox's dual gradient projection (:func:`prox_sweep`,
:func:`prox_primal`) and the TV's value (:func:`tv_value`) are such loops
too, for :class:`~napari_lfdeblur._tv_solvers.TVProx`: each sample of the
dual is read and written once per iteration. So are, for the blind solver,
the variance of the refocused views behind its disparity maps
(:func:`view_variance`) and the Laplacian step of its salient-edge latent
(:func:`add_laplacian`), and, for a path with rotation, the build of its
tile kernels and their gradient in the shifts (:func:`tile_accumulate`,
:func:`tile_shift_grads`).

Used on the CPU when numba imports (a warning, once, says when it does not);
``NAPARI_LFDEBLUR_NUMBA=0`` turns it off (then the torch versions run). The
kernels are compiled on first use and cached on disk by numba.
"""

from __future__ import annotations

import functools
import os
import threading
import warnings

import numpy as np
import torch

from ._taps import active_offsets

__all__ = ["available", "call", "check_writable", "rows", "column_spans", "forward", "add_adjoint", "kernel_grad",
           "FusedTaps", "prox_sweep", "prox_primal", "tv_value", "view_variance", "add_laplacian", "tile_accumulate",
           "tile_shift_grads"]

_LOCK = threading.Lock()  # numba's default thread pool runs one parallel loop at a time


@functools.lru_cache(maxsize=1)
def _loops():
    """The module of compiled loops, or None when numba is missing, broken or turned off."""
    if os.environ.get("NAPARI_LFDEBLUR_NUMBA", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    try:
        from . import _fused_loops
    except Exception as exc:  # noqa: BLE001 - numba not installed, or built for another numpy
        warnings.warn(f"numba could not be loaded ({type(exc).__name__}: {exc}); the blur and the TV solver run their "
                      "slower torch versions on the CPU (set NAPARI_LFDEBLUR_NUMBA=0 to choose that and silence this)",
                      RuntimeWarning, stacklevel=2)
        return None
    return _fused_loops


def available(device, dtype=torch.float32) -> bool:
    """True when the fused loops can run on ``device`` and ``dtype``: the CPU, float32 or float64, with numba."""
    return torch.device(device).type == "cpu" and dtype in (torch.float32, torch.float64) and _loops() is not None


def _run(name, *args):
    call(getattr(_loops(), name), *args)


def call(loop, *args):
    """Run the compiled parallel ``loop`` on ``args`` with torch's number of threads, one loop at a time.

    numba's thread count (a setting of the calling thread) is put back afterwards, and so is torch's: numba's
    OpenMP pool, started by the first call, sets the calling thread's OpenMP count (torch's) to every core.
    """
    import numba

    want = torch.get_num_threads()  # read before numba's pool may start
    with _LOCK:
        before = numba.get_num_threads()
        numba.set_num_threads(max(1, min(want, numba.config.NUMBA_NUM_THREADS)))
        try:
            loop(*args)
        finally:
            numba.set_num_threads(before)
            if torch.get_num_threads() != want:
                torch.set_num_threads(want)


def check_writable(t: torch.Tensor) -> None:
    """The loops write into ``t`` through numpy: it must be contiguous (a copy would lose what they write)."""
    if not t.is_contiguous():
        raise ValueError("the fused loops write into contiguous tensors only")


def rows(t: torch.Tensor, out: bool = False) -> np.ndarray:
    """``t`` (V, U, Y, X, C) as a numpy array of rows (V, U, Y, X * C), sharing its memory where contiguous.

    An ``out`` tensor, which the loops write, must be contiguous (a copy would lose what they write).
    """
    if out:
        check_writable(t)
    V, U, Y, X, C = t.shape
    return t.detach().contiguous().numpy().reshape(V, U, Y, X * C)


def column_spans(K: torch.Tensor):
    """``(x0, x1)``, int64 numpy arrays (S, h): per tap and row of ``K`` (S, h, w), the columns it weighs in."""
    used = K.detach() != 0
    first = used.to(torch.uint8).argmax(dim=2)
    past = K.shape[2] - used.flip(2).to(torch.uint8).argmax(dim=2)
    any_x = used.any(dim=2)
    return tuple(torch.where(any_x, t, 0).numpy().astype(np.int64) for t in (first, past))


def forward(L, K, offsets, spans, out, origin=(0, 0), view_step=1):
    """Writes the blur of ``L`` at the pixels of ``K`` (S, h, w), at ``origin`` ``(r0, c0)``, into ``out``.

    ``L`` is (V, U, Y, X, C); ``out`` holds the views ``0, view_step, ...``
    and must be contiguous. ``offsets`` is an int64 numpy array (S, 4),
    ``spans`` what :func:`column_spans` gives for ``K``.
    """
    _run("forward", rows(L), K.detach().to(L.dtype).contiguous().numpy(), offsets, *spans, *origin, view_step,
         L.shape[4], rows(out, out=True))


def add_adjoint(G, K, offsets, spans, out, origin=(0, 0), view_step=1):
    """Adds the adjoint of :func:`forward` applied to ``G`` to ``out`` (V, U, Y, X, C), contiguous."""
    _run("adjoint", rows(G), K.detach().to(G.dtype).contiguous().numpy(), offsets, *spans, *origin, view_step,
         G.shape[4], rows(out, out=True))


def kernel_grad(L, G, offsets, out, origin=(0, 0), view_step=1):
    """Writes ``d<G, forward(L)>/dK`` into ``out`` (S, h, w), contiguous, of ``G``'s dtype."""
    check_writable(out)
    _run("kernel_grad", rows(L.to(G.dtype)), rows(G), offsets, *origin, view_step, G.shape[4], out.numpy())


def tile_accumulate(base, slot, delta, pairs, n_taps):
    """The sums of a rotation's tile kernel (not yet divided by ``T``) and its column spans.

    ``base`` (int32, (T, h, w)), ``slot`` and ``delta`` (int64) as
    ``_taps_tiled._tile_kernel`` makes them; ``pairs``: ``(1 - f, f)`` of the
    fractions along ``v, y, u, x``, of shapes (2, T, h, 1), (2, T, h, w),
    (2, T, 1, w), (2, T, h, w). Returns ``K`` (n_taps, h, w), in the pairs'
    dtype, and ``(x0, x1)`` as :func:`column_spans`.
    """
    _, h, w = base.shape
    K = torch.zeros((n_taps, h, w), dtype=pairs[1].dtype)
    spans = tuple(np.empty((n_taps, h), np.int64) for _ in range(2))
    pairs = (pairs[0][..., 0], pairs[1], pairs[2][:, :, 0], pairs[3])  # v per row, u per column
    pv, py, pu, px = (t.detach().contiguous().numpy() for t in pairs)
    _run("tile_accumulate", base.contiguous().numpy(), slot.numpy(), delta.numpy(), pv, py, pu, px, K.numpy(), *spans)
    return K, spans


def tile_shift_grads(gK, base, slot, delta, fracs):
    """The derivatives of ``<gK, K>`` in each lookup's fractions along ``v, y, u, x``, each (T, h, w).

    ``gK`` (S, h, w) is a tile's kernel gradient (divided by ``T``);
    ``fracs`` the fractions of shapes (T, h), (T, h, w), (T, w), (T, h, w);
    the rest as :func:`tile_accumulate`.
    """
    gK = gK.detach().contiguous()
    out = [torch.empty(base.shape, dtype=gK.dtype) for _ in range(4)]
    f = [t.detach().to(gK.dtype).contiguous().numpy() for t in fracs]
    _run("tile_shift_grads", gK.numpy(), base.contiguous().numpy(), slot.numpy(), delta.numpy(), *f,
         *(t.numpy() for t in out))
    return out


def _rows5(t, out=False):
    """:func:`rows` of a (V, U, Y, X, C) tensor, or of a (V, U, Y, X) one as one channel."""
    return rows(t if t.dim() == 5 else t.unsqueeze(-1), out)


def _prox_args(v, dual, weights, box):
    """The arguments the prox loops share: rows of ``v`` and of the dual, weights, box and unit in v's dtype."""
    arr = _rows5(v)
    t = arr.dtype.type
    lo, hi = (1.0, 0.0) if box is None else (box[0], np.inf if box[1] is None else box[1])
    return arr, [_rows5(p, out=True) for p in dual], np.asarray(weights, arr.dtype), t(lo), t(hi), t(1.0)


def prox_sweep(v, dual, primal_weights, dual_weights, box, isotropic, coupled, blocks, scratch):
    """One iteration of the TV prox's dual gradient projection, in place on ``dual``.

    ``v`` (V, U, Y, X, C), or (V, U, Y, X) as one channel; ``dual``: its four components (v, u, y, x),
    contiguous; ``primal_weights`` (mu times the axis weights) and ``dual_weights`` (the step times the axis
    weights; 0 skips an axis); ``box`` None or ``(lo, hi)`` (``hi`` None: no upper bound); ``coupled``: the
    colour TV (the norm over C too); ``blocks``: how many blocks of rows run in parallel; ``scratch``: a
    contiguous tensor of ``v``'s shape, overwritten. See :func:`~napari_lfdeblur._fused_loops.prox_sweep`.
    """
    arr, ps, wp, lo, hi, one = _prox_args(v, dual, primal_weights, box)
    Y = arr.shape[2]
    _run("prox_sweep", arr, *ps, wp, np.asarray(dual_weights, arr.dtype), lo, hi, arr.shape[3] // v.shape[3],
         bool(isotropic), bool(coupled), one, max(1, -(-Y // max(1, blocks))), _rows5(scratch, out=True))


def prox_primal(v, dual, primal_weights, box, out):
    """``out = clip(v + div(dual))``, the prox's result (arguments as :func:`prox_sweep`)."""
    arr, ps, wp, lo, hi, _ = _prox_args(v, dual, primal_weights, box)
    _run("prox_primal", arr, *ps, wp, lo, hi, arr.shape[3] // v.shape[3], _rows5(out, out=True))


def tv_value(x, axis_weights, isotropic, coupled) -> float:
    """The weighted TV4 of ``x`` (V, U, Y, X[, C]) in one parallel pass (as ``_tv_solvers.tv_value``)."""
    arr = _rows5(x)
    out = np.empty(arr.shape[2], np.float64)
    _run("tv_rows", arr, np.asarray(axis_weights, arr.dtype), arr.shape[3] // x.shape[3], bool(isotropic),
         bool(coupled), out)
    return float(out.sum())


def view_variance(f, y0, y1, wy, x0, x1, wx) -> torch.Tensor:
    """(n, Y, X): the variance over the views of ``f`` (V, U, Y, X, 1) resampled by ``n`` shears, in one pass.

    The shears' bilinear taps are numpy arrays: ``y0, y1`` (int64) and
    ``wy`` of shape (n, V, Y), ``x0, x1, wx`` of shape (n, U, X), as
    ``_disparity.shear_taps`` makes them (``wy`` and ``wx`` in ``f``'s dtype).
    """
    arr = rows(f)
    out = np.empty((wy.shape[0], f.shape[2], f.shape[3]), arr.dtype)
    _run("view_variance", arr, y0, y1, 1 - wy, wy, x0, x1, 1 - wx, wx, out)
    return torch.from_numpy(out)


def add_laplacian(a, z, axis_weights, scale):
    """``a + scale * priors.laplacian4d(z, axis_weights)`` in one pass, as a new tensor.

    ``a`` and ``z`` are (V, U, Y, X) or (V, U, Y, X, C), of one shape.
    """
    out = torch.empty(z.shape, dtype=z.dtype)
    arr = _rows5(z)
    w2 = np.asarray([w * w for w in axis_weights], arr.dtype)
    _run("add_laplacian", _rows5(a.to(z.dtype)), arr, w2, arr.dtype.type(scale), arr.shape[3] // z.shape[3],
         _rows5(out, out=True))
    return out


class FusedTaps:
    """A tap kernel over the whole view, applied by the fused loops (the interface of :class:`~._taps.Taps`).

    Parameters
    ----------
    shape : tuple
        ``(V, U, Y, X, C)`` of the light fields.
    K : torch.Tensor, shape (S, Y, X), on the CPU
        The taps' weight maps (detached here).
    offsets : torch.Tensor or sequence, int, shape (S, 4)
        The ``(a, b, c, e)`` offsets of ``(v, y, u, x)`` of each tap.
    to_kernel : callable, optional
        Maps the gradient for ``K`` (S, Y, X) to the shape the caller's
        kernel has (see :meth:`angular`).
    """

    def __init__(self, shape, K, offsets, to_kernel=None):
        self.shape = tuple(shape)
        self.to_kernel = to_kernel
        self.K = K.detach().contiguous()
        self.offsets = np.ascontiguousarray(np.asarray(offsets, dtype=np.int64).reshape(-1, 4))
        self.spans = column_spans(self.K)

    @classmethod
    def angular(cls, shape, K, ov, ou):
        """The ``d_inf = 0`` kernel of :func:`~napari_lfdeblur._taps.tap_kernel`, ``K`` (Y, X, Dv, Du).

        The offsets of :func:`~napari_lfdeblur._taps.active_offsets` become
        taps; the kernel gradient comes back as ``(Y, X, Dv, Du)``, zero at
        the others.
        """
        Kd = K.detach()
        active = active_offsets(K)
        stack = torch.stack([Kd[:, :, i, j] for i, j in active])

        def to_kernel(g):
            out = g.new_zeros(K.shape)
            for s, (i, j) in enumerate(active):
                out[:, :, i, j] = g[s]
            return out

        return cls(shape, stack, [(ov + i, 0, ou + j, 0) for i, j in active], to_kernel)

    def forward(self, L):
        out = torch.empty(self.shape, dtype=L.dtype)
        forward(L, self.K, self.offsets, self.spans, out)
        return out

    def backward(self, L, G, need_L=True, need_K=False):
        """``(adjoint(G), d<G, forward(L)>/dK)``, each None when not needed."""
        gL = gK = None
        if need_L:
            gL = torch.zeros(self.shape, dtype=G.dtype)
            add_adjoint(G, self.K, self.offsets, self.spans, gL)
        if need_K:
            gK = torch.empty(self.K.shape, dtype=G.dtype)
            kernel_grad(L, G, self.offsets, gK)
            gK = gK.to(self.K.dtype)
            if self.to_kernel is not None:
                gK = self.to_kernel(gK)
        return gL, gK

    def adjoint(self, G):
        return self.backward(None, G, need_L=True, need_K=False)[0]
