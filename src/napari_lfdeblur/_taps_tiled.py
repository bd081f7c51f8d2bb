"""The blur of a path with rotation as 4D tap kernels on spatial tiles.

A camera rotation adds an image displacement that varies over the whole
view (docs/model.md, "Camera rotation"): instant ``k`` samples the sharp
light field at ``(v + s_v, u + s_u, y + t_y, x + t_x)`` with ``t_y, t_x``
functions of both ``y`` and ``x``. Bilinearly on every axis, that is a
16-tap kernel over integer offsets ``(a, b, c, e)`` of ``(v, y, u, x)`` at
every pixel, and summed over the exposure the bilinear histogram of the 4D
lookups the pixel goes through (as in :mod:`._taps4d`, which it generalises).

Across a whole view the displacement spreads over several pixels (a roll
turns the corners one way and the opposite corners the other), so one list
of offsets for the whole view would hold many taps that most pixels never
use. The kernel is therefore built and applied per spatial tile: each tile
keeps only the offsets some instant uses inside it, and each of those is one
multiply-add pass over the tile, whatever ``T``. Clamping the indices of
the taps reproduces the model's clamped-coordinate bilinear lookup exactly.
"""

from __future__ import annotations

import copy
import itertools
import math

import numpy as np
import torch

from . import _fused
from ._taps import fold
from ._taps4d import axis_taps

__all__ = ["rotation_displacement", "tiled_kernel", "TiledTaps", "tile_side", "FUSED_TILE_SIDE"]

_CORNERS = list(itertools.product((0, 1), repeat=4))


def rotation_displacement(rotations: torch.Tensor, xt: torch.Tensor, yt: torch.Tensor, r: float):
    """The image displacement of small camera rotations, in px (docs/model.md).

    ``x~' = x~ + r_y (1 + x~^2) - r_x x~ y~ - r_z y~`` and
    ``y~' = y~ - r_x (1 + y~^2) + r_y x~ y~ + r_z x~``: the rotation
    homography to first order in the angles, exact in ``x~, y~``.

    Parameters
    ----------
    rotations : torch.Tensor, shape (T, 3)
        ``(r_x, r_y, r_z)`` of each instant, radians.
    xt, yt : torch.Tensor, shapes (X,) and (Y,)
        Normalised coordinates ``x~, y~`` of the columns and rows.
    r : float
        ``R`` in px, the unit of ``x~``.

    Returns
    -------
    t_y, t_x : torch.Tensor, shape (T, Y, X)
        ``R (y~' - y~)`` and ``R (x~' - x~)``.
    """
    rx, ry, rz = (rotations[:, i, None, None] for i in range(3))
    x, y = xt[None, None, :], yt[None, :, None]
    t_x = r * (ry * (1.0 + x * x) - rx * (x * y) - rz * y)
    t_y = r * (-rx * (1.0 + y * y) + ry * (x * y) + rz * x)
    return t_y, t_x


#: Side of the tiles the fused CPU loops apply, px (see :func:`tile_side`).
FUSED_TILE_SIDE = 128


def tile_side(shape, block_elements: int, fused: bool = False) -> int:
    """Side of the square tiles, px.

    The torch version copies each tile, padded, for all views at once, so its
    tiles hold about ``block_elements`` padded elements each, 16 to 64 px.
    The fused loops (``fused``) copy nothing: each tap of a tile is one loop
    along the part of each row where it weighs, and the setup of such a loop
    costs as much as a few dozen multiply-adds. Their tiles are
    :data:`FUSED_TILE_SIDE` px: longer rows share that setup among more
    pixels, while the taps a tile holds grow with the spread of the
    rotation's displacement over it. The tiling changes the blur only by
    rounding (the order in which the loops add up).
    """
    if fused:
        return FUSED_TILE_SIDE
    V, U, _, _, C = shape
    side = math.isqrt(max(1, block_elements // max(1, (V + 2) * (U + 2) * C)))
    return int(min(64, max(16, side)))


def _lookups(shifts, sizes):
    """Where one tile's bilinear lookups along (v, y, u, x) fall in the box of integer offsets they use.

    ``shifts`` are broadcastable to ``(T, h, w)``. Returns ``base`` (int32,
    ``(T, h, w)``, the flat code of each lookup's lowest corner in the box),
    ``delta`` (the code offsets of the 16 corners, in the order of
    ``_CORNERS``), the four fractions (each of its shift's shape), and the
    lowest offset and the width of the box along each axis.
    """
    taps = [axis_taps(s, n) for s, n in zip(shifts, sizes)]
    full = torch.broadcast_shapes(*(o.shape for o, _ in taps))
    lo = [int(o.min()) for o, _ in taps]
    width = [int(o.max()) - m + 2 for (o, _), m in zip(taps, lo)]
    base = torch.zeros(full, dtype=torch.int32, device=taps[0][0].device)
    for (o, _), m, w in zip(taps, lo, width):
        base = base * w + (o - m).to(torch.int32)
    strides = [width[1] * width[2] * width[3], width[2] * width[3], width[3], 1]
    delta = [sum(b * s for b, s in zip(bits, strides)) for bits in _CORNERS]
    return base, delta, [f for _, f in taps], lo, width


def _factor_pairs(fracs):
    """Each axis's two bilinear factors ``(1 - f, f)``, stacked: ``(2, ...)`` of its fraction's shape."""
    return [torch.stack(torch.broadcast_tensors(1.0 - f, f)) for f in fracs]


def _corner_weights(fracs):
    """The 16 bilinear weights of each lookup, ``(16, T, h, w)``: products of one factor per axis."""
    w = None
    for pair in _factor_pairs(fracs):
        w = pair if w is None else (w[:, None] * pair[None]).flatten(0, 1)
    return w


def _tile_kernel(shifts, sizes, n_times, fused=False):
    """The kernel of one tile from its per-instant shifts along (v, y, u, x).

    ``shifts`` are broadcastable to ``(T, h, w)``. Returns ``K (S, h, w)``,
    the ``(S, 4)`` integer offsets of its taps, what its gradient needs to
    find where each of the 16 corners of each lookup lands in ``K`` (the
    int32 index ``(16, T, h, w)``; with ``fused``, the lowest corners'
    codes, the code-to-tap map and the corners' code offsets, from which
    the loops of :mod:`~napari_lfdeblur._fused` find it), and, with
    ``fused``, the column spans of the taps (:func:`~napari_lfdeblur._fused.column_spans`).
    """
    base, delta, fracs, lo, width = _lookups(shifts, sizes)
    h, w = base.shape[1:]
    n = math.prod(width)
    # the offsets some corner touches (a zero weight still carries a gradient): the lowest corners'
    # codes, moved by each corner's offset
    lowest = torch.zeros(n, dtype=torch.bool, device=base.device)
    lowest[base.reshape(-1)] = True
    used = torch.zeros_like(lowest)
    for d in delta:
        used[d:] |= lowest[: n - d]
    active = used.nonzero().squeeze(1)
    offsets = []
    for m, wd in zip(lo[::-1], width[::-1]):
        offsets.append(active % wd + m)
        active = active // wd
    offsets = torch.stack(offsets[::-1], dim=1)
    if fused:
        where = (base, torch.cumsum(used, 0) - 1, torch.tensor(delta, dtype=torch.int64))
        K, spans = _fused.tile_accumulate(*where, _factor_pairs(fracs), len(offsets))
        return K / n_times, offsets, where, spans
    slot = (torch.cumsum(used, 0, dtype=torch.int32) - 1) * (h * w)
    pix = torch.arange(h * w, dtype=torch.int32, device=base.device).view(1, h, w)
    index = torch.stack([slot[d:][base] + pix for d in delta])
    weights = _corner_weights(fracs)
    K = weights.new_zeros(len(offsets) * h * w).index_add_(0, index.view(-1), weights.reshape(-1)) / n_times
    return K.view(-1, h, w), offsets, index, None


def _contract(g, f):
    """``g[0] (1 - f) + g[1] f`` and ``g[1] - g[0]``: the weighted sum over an axis's two corners, and its
    derivative in ``f``."""
    return g[0] + (g[1] - g[0]) * f, g[1] - g[0]


def _tile_shift_grads(gK, shifts, sizes, index):
    """The gradient of ``<gK, K>`` with respect to each of the tile's four shifts (each of its shape).

    ``gK`` is the tile's ``(S, h, w)`` kernel gradient, already divided by
    ``T``; ``index`` what :func:`_tile_kernel` returned for its gradient
    (a tuple: the fused loops' inputs). Each weight is a product of one
    factor per axis, ``1 - f`` or ``f``, so the derivative along an axis is
    the difference of the gathered gradients of its two corners, weighted
    by the other axes' factors; the corners are summed out one axis at a
    time (x, u, y, v). ``f`` follows its shift within the clamped range,
    and not beyond (:func:`axis_taps`).
    """
    fv, fy, fu, fx = (axis_taps(s, n)[1] for s, n in zip(shifts, sizes))
    if isinstance(index, tuple):  # the fused loops' (base, slot, delta)
        dv, dy, du, dx = _fused.tile_shift_grads(gK, *index, (fv[:, :, 0], fy, fu[:, 0], fx))
    else:
        g = gK.reshape(-1)[index].view((2, 2, 2, 2) + index.shape[1:])  # (v, y, u, x) corners
        g, dx = _contract(g.movedim(3, 0), fx)  # (v, y, u) corners each
        g, du = _contract(g.movedim(2, 0), fu)
        dx, _ = _contract(dx.movedim(2, 0), fu)
        g, dy = _contract(g.movedim(1, 0), fy)
        du, _ = _contract(du.movedim(1, 0), fy)
        dx, _ = _contract(dx.movedim(1, 0), fy)
        dv = g[1] - g[0]
        dy, du, dx = (_contract(t, fv)[0] for t in (dy, du, dx))
    grads = []
    for d, s, n in zip((dv, dy, du, dx), shifts, sizes):
        lim = n - 1.0
        d = d * ((s >= -lim) & (s <= lim) & (n > 1)).to(d.dtype)
        grads.append(d.sum_to_size(s.shape))
    return grads


class _TiledKernel(torch.autograd.Function):
    """:func:`tiled_kernel`'s kernels with an analytic gradient in the shifts.

    The forward pass keeps, per tile, only where each corner of each lookup
    landed in the kernel (int32; with ``fused``, the codes from which the
    loops find it); the backward pass recomputes the
    fractions and gathers the kernel's gradient there. Autograd's own
    record of the 16 weights of every lookup, and of the products that make
    them, is many times the light field's size on a whole view. With
    ``fused`` both passes run the loops of :mod:`~napari_lfdeblur._fused`.
    """

    @staticmethod
    def forward(ctx, s_v, s_u, t_y, t_x, shape, side, layout, fused):
        V, U, Y, X = shape[:4]
        T = s_v.shape[0]
        parts, tiles, start = [], [], 0
        for y0 in range(0, Y, side):
            rows = slice(y0, min(Y, y0 + side))
            for x0 in range(0, X, side):
                cols = slice(x0, min(X, x0 + side))
                shifts = (s_v[:, rows, None], t_y[:, rows, cols], s_u[:, None, cols], t_x[:, rows, cols])
                Kt, offsets, index, spans = _tile_kernel(shifts, (V, Y, U, X), T, fused)
                parts.append(Kt.reshape(-1))
                layout.append((rows, cols, start, offsets, spans))
                tiles.append((rows, cols, start, Kt.shape, index))
                start += Kt.numel()
        ctx.save_for_backward(s_v, s_u, t_y, t_x)
        ctx.tiles, ctx.sizes = tiles, (V, Y, U, X)
        return torch.cat(parts)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, gK):
        s_v, s_u, t_y, t_x = ctx.saved_tensors
        grads = [torch.zeros_like(t) for t in (s_v, s_u, t_y, t_x)]
        gK = gK / s_v.shape[0]
        for rows, cols, start, kshape, index in ctx.tiles:
            g = gK[start : start + math.prod(kshape)].view(kshape)
            shifts = (s_v[:, rows, None], t_y[:, rows, cols], s_u[:, None, cols], t_x[:, rows, cols])
            gv, gy, gu, gx = _tile_shift_grads(g, shifts, ctx.sizes, index)
            grads[0][:, rows] += gv[:, :, 0]
            grads[1][:, cols] += gu[:, 0, :]
            grads[2][:, rows, cols] += gy
            grads[3][:, rows, cols] += gx
        return (*grads, None, None, None, None)


def tiled_kernel(s_v, s_u, t_y, t_x, shape, side: int, fused: bool = False):
    """Per-tile 4D kernels of an exposure.

    Parameters
    ----------
    s_v : torch.Tensor, shape (T, Y)
        Angular shift along ``v`` of each instant at each row.
    s_u : torch.Tensor, shape (T, X)
        Angular shift along ``u`` at each column.
    t_y, t_x : torch.Tensor, shape (T, Y, X)
        Spatial shifts, px.
    shape : tuple
        ``(V, U, Y, X, ...)`` of the light field.
    side : int
        Tile side, px.
    fused : bool, default False
        Build the kernels, and their gradient, with the fused CPU loops of
        :mod:`~napari_lfdeblur._fused` (the same numbers).

    Returns
    -------
    K : torch.Tensor, 1D
        The tiles' kernels, flattened one after another; differentiable in
        the shifts.
    layout : list of (slice, slice, int, torch.Tensor, tuple or None)
        Per tile: its rows, its columns, where its ``(S, h, w)`` kernel
        starts in ``K``, its ``(S, 4)`` offsets of ``(v, y, u, x)``, and,
        with ``fused``, its taps' column spans (:func:`~napari_lfdeblur._fused.column_spans`).
    """
    layout = []
    t_y, t_x = (torch.broadcast_to(t, (s_v.shape[0], shape[2], shape[3])) for t in (t_y, t_x))
    K = _TiledKernel.apply(s_v, s_u, t_y, t_x, tuple(shape), side, layout, bool(fused))
    return K, layout


def _clamped_range(start: int, stop: int, size: int, device):
    """``clamp(arange(start, stop), 0, size - 1)``, the slice of distinct indices it reads and
    how many of its entries fall below and above ``[0, size)``."""
    index = torch.arange(start, stop, device=device).clamp_(0, size - 1)
    src = slice(max(start, 0), min(stop, size))
    return index, src, (max(-start, 0), max(stop - size, 0))


def _fold_clamped(g: torch.Tensor, dim: int, pad) -> torch.Tensor:
    """Adjoint of reading a clamped range along ``dim``: the padding adds onto the edge samples."""
    low, high = pad
    n = g.shape[dim] - low - high
    out = g.narrow(dim, low, n).clone()
    if low:
        out.narrow(dim, 0, 1).add_(g.narrow(dim, 0, low).sum(dim, keepdim=True))
    if high:
        out.narrow(dim, n - 1, 1).add_(g.narrow(dim, low + n, high).sum(dim, keepdim=True))
    return out


class _Tile:
    """Index vectors of one tile: its replicate-padded source region and where it folds back."""

    def __init__(self, shape, rows, cols, start, offsets, spans=None):
        V, U, Y, X, _ = shape
        dev = offsets.device
        self.rows, self.cols, self.start = rows, cols, start
        self.h, self.w = rows.stop - rows.start, cols.stop - cols.start
        self.origin = (rows.start, cols.start)
        self.offsets = np.ascontiguousarray(offsets.cpu().numpy(), dtype=np.int64)
        self.spans = spans  # the fused loops' column spans of its taps, when they are used
        off = offsets.tolist()
        lo = [min(min(o[i] for o in off), 0) for i in range(4)]
        hi = [max(max(o[i] for o in off), 0) for i in range(4)]
        self.taps = [(a - lo[0], b - lo[1], c - lo[2], e - lo[3]) for a, b, c, e in off]
        self.iv = torch.arange(lo[0], V + hi[0], device=dev).clamp_(0, V - 1)
        self.iu = torch.arange(lo[2], U + hi[2], device=dev).clamp_(0, U - 1)
        self.iv_list, self.iu_list = self.iv.tolist(), self.iu.tolist()
        # padded rows and columns: clamped ranges; the source region they read and the padding
        # beyond the light field's edges (which reads the edge sample)
        self.iy, self.src_rows, self.pad_rows = _clamped_range(rows.start + lo[1], rows.stop + hi[1], Y, dev)
        self.ix, self.src_cols, self.pad_cols = _clamped_range(cols.start + lo[3], cols.stop + hi[3], X, dev)

    def kernel(self, K):
        n = len(self.taps)
        return K[self.start : self.start + n * self.h * self.w].view(n, self.h, self.w)

    def padded(self, T):
        """``T`` around the tile, replicate-padded, as ``(V', U', C, h', w')``."""
        Tb = T.index_select(2, self.iy).index_select(3, self.ix)[self.iv[:, None], self.iu[None, :]]
        return Tb.permute(0, 1, 4, 2, 3).contiguous()


class TiledTaps:
    """Tile-wise application of :func:`tiled_kernel`'s kernels, their adjoint and kernel gradient.

    Used through :class:`~napari_lfdeblur._taps.TapBlur` (no autograd inside).
    A copy made by :meth:`with_view_step` ``(s)`` outputs only the views
    ``0, s, 2s, ...`` along ``v`` and ``u``, ``(ceil(V/s), ceil(U/s), Y, X,
    C)``, and computes only those; its adjoint takes that shape back to the
    whole light field.
    """

    def __init__(self, shape, K, layout):
        self.shape = shape
        self.K = K.detach()
        self.tiles = [_Tile(shape, *entry) for entry in layout]
        self.view_step = 1
        #: on the CPU with numba, each tile is applied by the fused loops of :mod:`~napari_lfdeblur._fused`
        self.fused = _fused.available(self.K.device, self.K.dtype)
        if self.fused:
            for tile in self.tiles:
                if tile.spans is None:
                    tile.spans = _fused.column_spans(tile.kernel(self.K))

    def with_view_step(self, view_step: int) -> "TiledTaps":
        """The same kernels and tiles, with output views ``0, view_step, ...`` only."""
        out = copy.copy(self)
        out.view_step = view_step
        return out

    @property
    def n_taps(self) -> float:
        """Mean number of taps per tile: passes over the light field one forward costs."""
        return sum(len(t.taps) for t in self.tiles) / len(self.tiles)

    def _window(self, tile, t, tap):
        """The part of ``t`` (padded as ``(V', U', C, h', w')``) that tap ``tap`` reads for the output views."""
        V, U = self.shape[:2]
        a, b, c, e = tap
        s = self.view_step
        return t[a : a + V : s, c : c + U : s, :, b : b + tile.h, e : e + tile.w]

    def forward(self, L):
        V, U, Y, X, C = self.shape
        s = self.view_step
        out = L.new_empty((len(range(0, V, s)), len(range(0, U, s)), Y, X, C))
        if self.fused:
            L = L.contiguous()
            for tile in self.tiles:
                _fused.forward(L, tile.kernel(self.K), tile.offsets, tile.spans, out, tile.origin, s)
            return out
        for tile in self.tiles:
            Lp = tile.padded(L)
            Kt = tile.kernel(self.K)
            acc = Lp.new_zeros((out.shape[0], out.shape[1], C, tile.h, tile.w))
            for k, tap in enumerate(tile.taps):
                acc.addcmul_(self._window(tile, Lp, tap), Kt[k])
            out[:, :, tile.rows, tile.cols] = acc.permute(0, 1, 3, 4, 2)
        return out

    def backward(self, L, G, need_L=True, need_K=False):
        """``(adjoint(G), d<G, forward(L)>/dK)``, each None when not needed."""
        V, U, _, _, C = self.shape
        gL = G.new_zeros(self.shape) if need_L else None
        gK = torch.zeros_like(self.K) if need_K else None
        if self.fused:
            return self._backward_fused(L, G, gL, gK)
        for tile in self.tiles:
            Gb = G[:, :, tile.rows, tile.cols].permute(0, 1, 4, 2, 3).contiguous()
            if need_K:
                Lp = tile.padded(L)
                gKt = tile.kernel(gK)
                for k, tap in enumerate(tile.taps):
                    gKt[k] = (Gb * self._window(tile, Lp, tap)).sum(dim=(0, 1, 2))
            if need_L:
                Kt = tile.kernel(self.K)
                gp = Gb.new_zeros((len(tile.iv), len(tile.iu), C, len(tile.iy), len(tile.ix)))
                for k, tap in enumerate(tile.taps):
                    self._window(tile, gp, tap).addcmul_(Gb, Kt[k])
                # adjoint of the padding: v and u (few views) by slices, y and x at the edges
                g = fold(fold(gp, 0, tile.iv_list, V), 1, tile.iu_list, U)
                g = _fold_clamped(_fold_clamped(g, 3, tile.pad_rows), 4, tile.pad_cols)
                gL[:, :, tile.src_rows, tile.src_cols] += g.permute(0, 1, 3, 4, 2)
        return gL, gK

    def _backward_fused(self, L, G, gL, gK):
        G = G.contiguous()
        if gK is not None:
            L = L.to(G.dtype).contiguous()  # once, not per tile
        for tile in self.tiles:
            if gK is not None:
                g = G.new_empty((len(tile.taps), tile.h, tile.w))
                _fused.kernel_grad(L, G, tile.offsets, g, tile.origin, self.view_step)
                tile.kernel(gK).copy_(g)
            if gL is not None:
                _fused.add_adjoint(G, tile.kernel(self.K), tile.offsets, tile.spans, gL, tile.origin, self.view_step)
        return gL, gK

    def adjoint(self, G):
        return self.backward(None, G, need_L=True, need_K=False)[0]
