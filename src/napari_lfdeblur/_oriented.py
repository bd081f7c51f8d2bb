"""Angular differences along the scene's disparity, for the TV of :mod:`napari_lfdeblur.deconvolution`.

A Lambertian point at disparity ``d`` seen at pixel ``(y, x)`` of view
``(v, u)`` is seen at ``(y, x + d)`` in view ``(v, u + 1)`` and at
``(y + d, x)`` in view ``(v + 1, u)``. The differences

    D_v l[v, u, y, x] = l(v + 1, u, y + d(y, x), x) - l[v, u, y, x]
    D_u l[v, u, y, x] = l(v, u + 1, y, x + d(y, x)) - l[v, u, y, x]

(bilinear in ``y`` or ``x``, replicate boundary; zero at the last view, like
the forward differences of :mod:`napari_lfdeblur.priors`) are then near zero
on a sharp, noise-free light field wherever ``d`` is right, whatever the
texture, while noise (independent from view to view) and the ghosts of a
wrong restoration make them large. The differences along the view axes
(``d = 0``) are large on every textured point away from the plane of zero
disparity. ``d`` is one map ``(Y, X)`` for every view (the centre view's).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from . import _fused
from .blur import lerp_taps

__all__ = ["OrientedDifferences"]


def _taps(pos: torch.Tensor, n: int, stride: int, base: torch.Tensor):
    """Flat indices ``(i0, i1)`` into ``Y * X`` and weight ``w`` of the clamped bilinear samples at ``pos``
    (:func:`~napari_lfdeblur.blur.lerp_taps` along an axis of ``n`` samples ``stride`` apart, from ``base``)."""
    i0, i1, w = lerp_taps(pos, n)
    return (i0 * stride + base).reshape(-1), (i1 * stride + base).reshape(-1), w.reshape(-1)


class OrientedDifferences:
    """The angular differences ``D_v``, ``D_u`` along a disparity map, with their adjoints.

    Parameters
    ----------
    disparity : torch.Tensor, shape (Y, X)
        Disparity (px/view) of every pixel, on the light fields' device.

    Notes
    -----
    Light fields are ``(V, U, Y, X, C)`` tensors. ``D_a`` is linear with
    adjoint :meth:`add_adjoint`; :meth:`norm_bound` bounds ``||D_a||^2``
    for the step of a dual method. On the CPU, the TV prox and the TV along
    the disparity run as compiled loops (:meth:`fused_prox`,
    :meth:`fused_tv`).
    """

    def __init__(self, disparity: torch.Tensor):
        d = torch.as_tensor(disparity)
        if d.dim() != 2 or not bool(torch.isfinite(d).all()):
            raise ValueError(f"the disparity map must be a finite (Y, X) array; got shape {tuple(d.shape)}")
        d = d.to(torch.float32) if not d.is_floating_point() else d
        Y, X = d.shape
        self.shape = (Y, X)
        rows = torch.arange(Y, dtype=d.dtype, device=d.device)[:, None]
        cols = torch.arange(X, dtype=d.dtype, device=d.device)[None, :]
        # per axis (v: along y, u: along x): the flat taps into (Y * X)
        self.taps = (_taps(rows + d, Y, X, cols.long()), _taps(cols + d, X, 1, rows.long() * X))
        self._numpy = {}  # the taps as numpy arrays, per dtype, for the fused loops

    def _fused_args(self, t: torch.Tensor, axis: int):
        """``(i0, i1, w)`` as numpy for the fused loops on ``t``'s dtype, or None where they do not run."""
        if not (t.is_contiguous() and _fused.available(t.device, t.dtype)):
            return None
        if t.dtype not in self._numpy:
            self._numpy[t.dtype] = [(i0.numpy(), i1.numpy(), w.to(t.dtype).numpy()) for i0, i1, w in self.taps]
        return self._numpy[t.dtype][axis]

    def _fused_taps(self, t: torch.Tensor) -> list:
        """``[i0, i1, w]`` of the v axis then of the u axis, as :meth:`_fused_args` gives them, in one list."""
        return [a for axis in (0, 1) for a in self._fused_args(t, axis)]

    def fused_available(self, t: torch.Tensor) -> bool:
        """Whether :meth:`fused_prox` runs on ``t`` (a contiguous (V, U, Y, X[, C]) tensor on the CPU, with numba)."""
        return t.dim() in (4, 5) and self._fused_args(t, 0) is not None

    def fused_prox(self, v, dual, primal_weights, box, out, dual_weights=None, isotropic=True, coupled=False):
        """The TV prox of :class:`~napari_lfdeblur._tv_solvers.TVProx` along the disparity, by the fused loops.

        ``v`` (V, U, Y, X[, C]); ``dual``: the four components (v, u, y, x) of
        ``v``'s shape, contiguous; ``primal_weights``: mu times the axis
        weights; ``box`` None or ``(lo, hi)`` (``hi`` None: no upper bound).
        With ``dual_weights`` (the step times the axis weights, 0 skips an
        axis): one iteration of the dual gradient projection, in place on
        ``dual``, ``out`` as scratch. Without: ``out = clip(v - sum_a w_a
        D_a^T dual_a)``, the prox's result. Needs :meth:`fused_available`.
        """
        from . import _oriented_loops

        X = v.shape[3]
        for t in (*dual, out):  # written through numpy
            _fused.check_writable(t)
        flat = [self._flat(t).numpy() for t in (v, *dual, out)]
        dt = flat[0].dtype.type
        lo, hi = (dt(1.0), dt(0.0)) if box is None else (dt(box[0]), dt(np.inf if box[1] is None else box[1]))
        taps = self._fused_taps(v)
        wp = np.asarray(primal_weights, flat[0].dtype)
        if dual_weights is None:
            _fused.call(_oriented_loops.prox_primal, *flat[:5], X, *taps, wp, lo, hi, flat[5])
            return
        wd = np.asarray(dual_weights, flat[0].dtype)
        _fused.call(_oriented_loops.prox_sweep, *flat[:5], X, *taps, wp, wd, lo, hi, bool(isotropic), bool(coupled),
                    dt(1.0), flat[5])

    def fused_tv(self, x: torch.Tensor, axis_weights, isotropic: bool, coupled: bool) -> float | None:
        """The TV4 of ``x`` (V, U, Y, X[, C]) along the disparity by the fused loops (as ``_tv_solvers.tv_value``),
        or None where they do not run (:meth:`fused_available`)."""
        if not self.fused_available(x):
            return None
        from . import _oriented_loops

        flat = self._flat(x).numpy()
        taps = self._fused_taps(x)
        out = np.empty(flat.shape[0] * flat.shape[1], np.float64)
        _fused.call(_oriented_loops.tv_views, flat, x.shape[3], *taps, np.asarray(axis_weights, flat.dtype),
                    bool(isotropic), bool(coupled), out)
        return float(out.sum())

    def _flat(self, t: torch.Tensor) -> torch.Tensor:
        """``t`` (V, U, Y, X[, C]) as (V, U, Y * X, C)."""
        V, U, Y, X, C = t.shape if t.dim() == 5 else (*t.shape, 1)
        if (Y, X) != self.shape:
            raise ValueError(f"light field of views {Y}x{X}; the disparity map is {self.shape[0]}x{self.shape[1]}")
        return t.reshape(V, U, Y * X, C)

    def shift(self, t: torch.Tensor, axis: int) -> torch.Tensor:
        """``t`` (A, B, Y, X, C) sampled at ``y + d`` (``axis`` 0) or ``x + d`` (``axis`` 1)."""
        i0, i1, w = self.taps[axis]
        flat = self._flat(t)
        w = w.to(t.dtype)[:, None]
        out = flat.index_select(2, i1).mul_(w)
        out.add_(flat.index_select(2, i0).mul_(1 - w))
        return out.view(t.shape)

    def shift_adjoint(self, g: torch.Tensor, axis: int) -> torch.Tensor:
        """The adjoint of :meth:`shift` applied to ``g`` (A, B, Y, X, C): a new tensor of its shape."""
        i0, i1, w = self.taps[axis]
        flat = self._flat(g)
        w = w.to(g.dtype)[:, None]
        out = torch.zeros_like(flat)
        out.index_add_(2, i0, flat * (1 - w))
        out.index_add_(2, i1, flat * w)
        return out.view(g.shape)

    def difference(self, x: torch.Tensor, axis: int) -> torch.Tensor:
        """``D_axis x`` for ``axis`` 0 (``v``) or 1 (``u``): ``x``'s shape, zero at the last view."""
        return self.add_difference(x, axis, torch.zeros_like(x))

    def add_difference(self, x: torch.Tensor, axis: int, out: torch.Tensor, alpha: float = 1.0) -> torch.Tensor:
        """``out += alpha D_axis x`` (``out`` of ``x``'s shape); returns ``out``."""
        n = x.shape[axis]
        if n < 2 or alpha == 0:
            return out
        d = self.shift(x.narrow(axis, 1, n - 1), axis).sub_(x.narrow(axis, 0, n - 1))
        out.narrow(axis, 0, n - 1).add_(d, alpha=alpha)
        return out

    def add_adjoint(self, g: torch.Tensor, axis: int, out: torch.Tensor, alpha: float = 1.0) -> torch.Tensor:
        """``out += alpha D_axis^T g`` (``g`` of ``D_axis``'s output shape; its last view is ignored)."""
        n = g.shape[axis]
        if n < 2 or alpha == 0:
            return out
        head = g.narrow(axis, 0, n - 1)
        out.narrow(axis, 0, n - 1).sub_(head, alpha=alpha)
        out.narrow(axis, 1, n - 1).add_(self.shift_adjoint(head, axis), alpha=alpha)
        return out

    def norm_bound(self, axis: int) -> float:
        """An upper bound on ``||D_axis||^2``: ``(1 + sqrt(c))^2``, ``c`` the largest column sum of the shift.

        The shift's rows sum to 1, so ``||S||^2 <= c`` (Schur's test).
        """
        i0, i1, w = self.taps[axis]
        cols = torch.zeros(self.shape[0] * self.shape[1], dtype=torch.float64, device=w.device)
        cols.index_add_(0, i0, (1 - w).double()).index_add_(0, i1, w.double())
        return (1.0 + math.sqrt(float(cols.max()))) ** 2
