"""The blur with a non-zero infinity disparity as one kernel over 4D integer offsets.

With ``d_inf != 0`` instant ``k`` samples the sharp light field at
``(v + s_v, u + s_u, y + d s_v, x + d s_u)``, bilinearly on every axis. The
``(v, y)`` part of that lookup depends only on the row ``y`` and the
``(u, x)`` part only on the column ``x``, so each instant is, at every
pixel, a 16-tap kernel over integer offsets ``(a, b, c, e)`` of
``(v, y, u, x)``. Summed over the exposure the kernel of pixel ``(y, x)`` is

    K[y, x, (a, b), (c, e)] = (1/T) sum_k hv_k[y, (a, b)] hu_k[x, (c, e)],

the bilinear histogram of the 4D lookups the pixel goes through, and

    f[v, u, y, x] = sum_taps K[tap][y, x] l[clamp(v + a), clamp(u + c), clamp(y + b), clamp(x + e)].

Only the offset quadruples some instant actually uses are kept (the
``(v, y)`` offsets of a path trace a band, not a box), and each is one
multiply-add pass over blocks of rows, whatever ``T``, limited in each block
to the columns where it weighs something (with ``p_z != 0`` the offsets move
across the image). Clamping the indices
of the taps reproduces the clamped-coordinate bilinear lookup of the model
exactly: beyond an edge both taps of an axis read the edge sample.
"""

from __future__ import annotations

import torch

from ._taps import fold, rows_per_block

__all__ = ["axis_taps", "pair_splat", "tap_kernel_4d", "Taps4D"]


def axis_taps(shift: torch.Tensor, size: int):
    """Integer offset ``o`` and fraction ``f`` of shifts along an axis of ``size`` samples.

    The sample ``a + shift`` is ``(1 - f) l[a + o] + f l[a + o + 1]`` (indices
    clamped to the axis). Shifts beyond ``+-(size - 1)`` read only the edge
    sample, so they are clamped there first, which bounds the number of
    offsets; ``f`` stays differentiable in ``shift``.

    Returns
    -------
    o : torch.Tensor, int64, ``shift``'s shape
    f : torch.Tensor, ``shift``'s dtype and shape
    """
    if size == 1:
        return torch.zeros_like(shift, dtype=torch.long), torch.zeros_like(shift)
    lim = size - 1.0
    s = shift.clamp(-lim, lim)
    o = torch.floor(s.detach()).clamp_(-lim, lim - 1).long()
    return o, s - o.to(s.dtype)


def pair_splat(shift: torch.Tensor, d_inf: float, n_views: int, n_pixels: int):
    """Bilinear splat of the lookups ``(a + shift, i + d_inf shift)`` onto integer offset pairs.

    Parameters
    ----------
    shift : torch.Tensor, shape (T, n)
        The angular shift of each instant at each of ``n`` rows (or columns).
    d_inf : float
        The infinity disparity, px/view.
    n_views, n_pixels : int
        Sizes of the angular and the spatial axis.

    Returns
    -------
    h : torch.Tensor, shape (T, n, P)
        Weight of each offset pair, differentiable in ``shift``.
    pairs : torch.Tensor, int64, shape (P, 2)
        The ``(angular, spatial)`` offsets of the pairs.
    touched : torch.Tensor, bool, shape (T, P)
        Whether a corner of some lookup of the instant lands on the pair,
        with a zero weight too: a lookup exactly on a sample still has the
        next sample in its derivative.
    """
    (oa, fa), (ob, fb) = axis_taps(shift, n_views), axis_taps(d_inf * shift, n_pixels)
    corners = [(0, 0, (1 - fa) * (1 - fb)), (1, 0, fa * (1 - fb)), (0, 1, (1 - fa) * fb), (1, 1, fa * fb)]
    a = torch.stack([oa + i for i, _, _ in corners], dim=-1)  # (T, n, 4)
    b = torch.stack([ob + j for _, j, _ in corners], dim=-1)
    w = torch.stack([c for _, _, c in corners], dim=-1)
    a_min, b_min = int(a.min()), int(b.min())
    width = int(b.max()) - b_min + 1
    code = (a - a_min) * width + (b - b_min)
    uniq, inverse = torch.unique(code, return_inverse=True)
    h = w.new_zeros(shift.shape + (len(uniq),)).scatter_add(-1, inverse, w)
    pairs = torch.stack([uniq // width + a_min, uniq % width + b_min], dim=1)
    touched = torch.zeros((shift.shape[0], len(uniq)), dtype=torch.bool, device=shift.device)
    touched[torch.arange(shift.shape[0], device=shift.device)[:, None], inverse.flatten(1)] = True
    return h, pairs, touched


def tap_kernel_4d(s_u: torch.Tensor, s_v: torch.Tensor, d_inf: float, shape):
    """The per-pixel kernel over the 4D offsets the exposure uses.

    Parameters
    ----------
    s_u : torch.Tensor, shape (T, X)
    s_v : torch.Tensor, shape (T, Y)
    d_inf : float
    shape : tuple
        ``(V, U, Y, X, ...)`` of the light field.

    Returns
    -------
    K : torch.Tensor, shape (S, Y, X)
        Weight maps of the ``S`` taps, differentiable in the shifts. Where
        the shifts need a gradient, the taps include those that only weigh
        zero (a lookup exactly on a sample: the derivative there reads the
        next sample); otherwise only those that weigh something.
    offsets : torch.Tensor, int64, shape (S, 4)
        The ``(a, b, c, e)`` offsets of ``(v, y, u, x)`` of each tap.
    """
    V, U, Y, X = shape[:4]
    hv, pv, tv = pair_splat(s_v, d_inf, V, Y)  # (T, Y, P)
    hu, pu, tu = pair_splat(s_u, d_inf, U, X)  # (T, X, Q)
    # the taps some instant uses: an offset pair of v active with one of u at the same instant
    grad = s_u.requires_grad or s_v.requires_grad
    av = (tv if grad else (hv.detach() != 0).any(dim=1)).to(hv.dtype)  # (T, P)
    au = (tu if grad else (hu.detach() != 0).any(dim=1)).to(hu.dtype)  # (T, Q)
    p, q = ((av.T @ au) > 0).nonzero(as_tuple=True)
    K = torch.einsum("kys,kxs->syx", hv[:, :, p], hu[:, :, q]) / s_u.shape[0]
    offsets = torch.stack([pv[p, 0], pv[p, 1], pu[q, 0], pu[q, 1]], dim=1)
    return K, offsets


class Taps4D:
    """Block-wise application of a 4D tap kernel, its adjoint and its kernel gradient (no autograd).

    Inside a block the light field is held replicate-padded as
    ``(V', U', C, rows', X')``, so every tap is a strided slice and the
    innermost loop of its multiply-add runs along ``x``.
    """

    def __init__(self, shape, K, offsets, block_elements):
        V, U, Y, X, C = shape
        self.shape = shape
        self.K = K.detach()
        dev = K.device
        off = offsets.tolist()
        self.lo = [min(min(o[i] for o in off), 0) for i in range(4)]  # (v, y, u, x)
        self.hi = hi = [max(max(o[i] for o in off), 0) for i in range(4)]
        self.iv = torch.arange(self.lo[0], V + hi[0], device=dev).clamp_(0, V - 1)
        self.iu = torch.arange(self.lo[2], U + hi[2], device=dev).clamp_(0, U - 1)
        self.ix = torch.arange(self.lo[3], X + hi[3], device=dev).clamp_(0, X - 1)
        self.iv_list, self.iu_list = self.iv.tolist(), self.iu.tolist()
        self.pad_y = (self.lo[1], hi[1])
        self.taps = [(a - self.lo[0], b - self.lo[1], c - self.lo[2], e - self.lo[3]) for a, b, c, e in off]
        per_row = len(self.iv) * len(self.iu) * len(self.ix) * C
        self.step = rows_per_block(per_row, block_elements, Y)
        self.spans = [self._spans(block) for block, _ in self.blocks()]

    def blocks(self):
        Y = self.shape[2]
        for y0 in range(0, Y, self.step):
            y1 = min(Y, y0 + self.step)
            rows = torch.arange(y0 + self.pad_y[0], y1 + self.pad_y[1], device=self.K.device).clamp_(0, Y - 1)
            yield slice(y0, y1), rows

    def _spans(self, block):
        """``(s, x0, x1)`` of the taps with a non-zero weight in the rows ``block``: their columns ``x0:x1``.

        With ``p_z != 0`` the shifts vary across the image, so a tap of the
        exposure may weigh nothing in some rows or columns. Leaving out
        those zero terms changes no sum.
        """
        used = (self.K[:, block] != 0).any(dim=1).to(torch.uint8)  # (S, X)
        x0 = used.argmax(dim=1)  # the first used column
        x1 = used.shape[1] - used.flip(1).argmax(dim=1)  # past the last one
        keep = used.any(dim=1)
        return [(s, a, b) for s, (a, b, k) in enumerate(zip(x0.tolist(), x1.tolist(), keep.tolist())) if k]

    def _padded(self, T, rows):
        """``T`` at the padded rows ``rows``, replicate-padded in (v, u, x), as (V', U', C, rows', X')."""
        # (C, rows', V, U, X) padded in its last three axes in one pass; the offsets bound the padding by
        # V - 1, U - 1 and X - 1, within what replicate padding takes
        Tb = T.index_select(2, rows).permute(4, 2, 0, 1, 3)
        lo, hi = self.lo, self.hi
        Tp = torch.nn.functional.pad(Tb, (-lo[3], hi[3], -lo[2], hi[2], -lo[0], hi[0]), mode="replicate")
        return Tp.permute(2, 3, 0, 1, 4)

    def _slice(self, t, tap, n_rows):
        V, U, _, X, _ = self.shape
        a, b, c, e = tap
        return t[a : a + V, c : c + U, :, b : b + n_rows, e : e + X]

    def forward(self, L):
        V, U = self.shape[:2]
        out = torch.empty_like(L)
        for (block, rows), spans in zip(self.blocks(), self.spans):
            Lp = self._padded(L, rows)
            n = block.stop - block.start
            acc = Lp.new_zeros((V, U, Lp.shape[2], n, self.shape[3]))
            for s, x0, x1 in spans:
                acc[..., x0:x1].addcmul_(self._slice(Lp, self.taps[s], n)[..., x0:x1], self.K[s, block, x0:x1])
            out[:, :, block] = acc.permute(0, 1, 3, 4, 2)
        return out

    def backward(self, L, G, need_L=True, need_K=False):
        """``(adjoint(G), d<G, forward(L)>/dK)``, each None when not needed."""
        V, U, Y, X, C = self.shape
        gL = torch.zeros_like(G) if need_L else None
        gK = torch.zeros_like(self.K) if need_K else None
        for (block, rows), spans in zip(self.blocks(), self.spans):
            n = block.stop - block.start
            Gb = G[:, :, block].permute(0, 1, 4, 2, 3).contiguous()
            if need_K:  # every weight's gradient, zero weights included
                Lp = self._padded(L, rows)
                for s, tap in enumerate(self.taps):
                    gK[s, block] = (Gb * self._slice(Lp, tap, n)).sum(dim=(0, 1, 2))
            if need_L:
                gp = Gb.new_zeros((len(self.iv), len(self.iu), C, len(rows), len(self.ix)))
                for s, x0, x1 in spans:
                    self._slice(gp, self.taps[s], n)[..., x0:x1].addcmul_(Gb[..., x0:x1], self.K[s, block, x0:x1])
                # adjoint of the padding: v and u (few) by slices, x and y by index_add
                g = fold(fold(gp, 0, self.iv_list, V), 1, self.iu_list, U)
                g = g.new_zeros(g.shape[:4] + (X,)).index_add_(4, self.ix, g)
                gL.index_add_(2, rows, g.permute(0, 1, 3, 4, 2))
        return gL, gK

    def adjoint(self, G):
        return self.backward(None, G, need_L=True, need_K=False)[0]
