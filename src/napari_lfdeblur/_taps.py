"""The angular blur as a kernel over integer view offsets ("taps"), for ``d_inf = 0``.

With ``d_inf = 0`` every pixel sees, summed over the exposure, a small 2D
kernel over integer view offsets: the bilinear histogram of the angular
shifts it goes through (:func:`tap_kernel`). :class:`Taps` applies it block
by block over rows, and :class:`TapBlur` is its autograd function, which
recomputes the blocks in the backward pass instead of storing them.
"""

from __future__ import annotations

import torch

__all__ = ["tap_kernel", "active_offsets", "Taps", "TapBlur", "fold", "rows_per_block"]


# --------------------------------------------- angular blur as offset taps


def _splat(shift: torch.Tensor, size: int):
    """Bilinear splat of angular shifts onto integer offsets.

    ``shift`` has shape ``(T, n)``. The sample ``a + shift`` of an axis of
    ``size`` views is ``(1 - f) l[a + o] + f l[a + o + 1]`` with ``o =
    floor(shift)`` and ``f`` its fraction, the indices clamped to the axis.
    Shifts beyond ``+-(size - 1)`` read only the edge view, so they are
    clamped there first, which bounds the number of offsets.

    Returns
    -------
    h : torch.Tensor, shape (T, n, D)
        Weight of each offset ``o_min + d``, differentiable in ``shift``.
    o_min : int
    """
    if size == 1:
        return torch.ones(shift.shape + (1,), dtype=shift.dtype, device=shift.device), 0
    lim = size - 1.0
    sc = shift.clamp(-lim, lim)
    o = torch.floor(sc.detach()).clamp_(-lim, lim - 1).long()
    f = sc - o.to(sc.dtype)
    o_min = int(o.min())
    D = int(o.max()) + 2 - o_min
    cols = torch.arange(D, device=shift.device)
    rel = (o - o_min)[..., None]
    h = (1.0 - f)[..., None] * (rel == cols).to(shift.dtype) + f[..., None] * (rel + 1 == cols).to(shift.dtype)
    return h, o_min


def tap_kernel(s_u: torch.Tensor, s_v: torch.Tensor, U: int, V: int):
    """The per-pixel angular kernel of a set of instants, over integer view offsets.

    With ``d_inf = 0`` the blurred light field is, at every pixel,

        f[a, b] = sum_(i, j) K[y, x, i, j] l[clamp(a + ov + i), clamp(b + ou + j)]

    where ``K[y, x] = mean_k hv_k(y) (x) hu_k(x)`` is the bilinear histogram
    of the angular shifts the pixel sees during the exposure.

    Parameters
    ----------
    s_u : torch.Tensor, shape (T, X)
    s_v : torch.Tensor, shape (T, Y)

    Returns
    -------
    K : torch.Tensor, shape (Y, X, Dv, Du)
    ov, ou : int
        The offsets of ``K[..., 0, 0]``.
    """
    hu, ou = _splat(s_u, U)
    hv, ov = _splat(s_v, V)
    K = torch.einsum("kyd,kxe->yxde", hv, hu) / s_u.shape[0]
    return K, ov, ou


def active_offsets(K: torch.Tensor) -> list:
    """The ``(i, j)`` offsets of a :func:`tap_kernel` ``K`` (Y, X, Dv, Du) that become taps.

    Those that weigh something somewhere; where ``K`` needs a gradient, all
    of them: a lookup exactly on a view weighs zero on the next view, whose
    difference is still its derivative.
    """
    if K.requires_grad:
        return [(i, j) for i in range(K.shape[2]) for j in range(K.shape[3])]
    return (K.detach().abs().amax(dim=(0, 1)) > 0).nonzero().tolist()


def rows_per_block(n_per_row: int, budget: int, Y: int) -> int:
    return int(max(1, min(Y, budget // max(1, n_per_row))))


def fold(padded: torch.Tensor, dim: int, index: list, size: int) -> torch.Tensor:
    """Adjoint of ``padded = t.index_select(dim, index)``: add each padded slice onto its source.

    A loop of slice additions, which suits these few, large slices better
    than ``index_add_``.
    """
    shape = list(padded.shape)
    shape[dim] = size
    out = padded.new_zeros(shape)
    for i, src in enumerate(index):
        out.select(dim, src).add_(padded.select(dim, i))
    return out


class Taps:
    """Block-wise application of a tap kernel, its adjoint and its kernel gradient (no autograd).

    Inside a block the light field is held as ``(V, U, C, rows, X)``, so the
    innermost loop of every multiply-add runs along ``x`` with the kernel
    contiguous too.
    """

    def __init__(self, shape, K, ov, ou, block_elements):
        V, U, Y, X, C = shape
        self.shape = shape
        Dv, Du = K.shape[2], K.shape[3]
        self.Kt = K.detach().permute(2, 3, 0, 1).contiguous()  # (Dv, Du, Y, X)
        dev = K.device
        # replicate padding as index vectors: padded view i reads view iv[i]
        self.iv = torch.arange(ov, ov + V + Dv - 1, device=dev).clamp_(0, V - 1)
        self.iu = torch.arange(ou, ou + U + Du - 1, device=dev).clamp_(0, U - 1)
        self.iv_list, self.iu_list = self.iv.tolist(), self.iu.tolist()
        self.taps = [(int(i), int(j)) for i, j in active_offsets(K)]
        self.step = rows_per_block((V + Dv - 1) * (U + Du - 1) * X * C, block_elements, Y)

    def blocks(self):
        Y = self.shape[2]
        for y0 in range(0, Y, self.step):
            yield slice(y0, min(Y, y0 + self.step))

    def _padded(self, T, rows):
        """Block ``rows`` of ``T``, replicate-padded in (v, u), as (V', U', C, rows, X)."""
        Tb = T[:, :, rows][self.iv[:, None], self.iu[None, :]]
        return Tb.permute(0, 1, 4, 2, 3).contiguous()

    @staticmethod
    def _block(T, rows):
        return T[:, :, rows].permute(0, 1, 4, 2, 3).contiguous()

    def forward(self, L):
        V, U = self.shape[:2]
        out = torch.empty_like(L)
        for rows in self.blocks():
            Lp = self._padded(L, rows)
            acc = Lp.new_zeros((V, U) + Lp.shape[2:])
            for i, j in self.taps:
                acc.addcmul_(Lp[i : i + V, j : j + U], self.Kt[i, j, rows])
            out[:, :, rows] = acc.permute(0, 1, 3, 4, 2)
        return out

    def backward(self, L, G, need_L=True, need_K=False):
        """``(adjoint(G), d<G, forward(L)>/dK)``, each None when not needed."""
        V, U = self.shape[:2]
        gL = torch.empty_like(G) if need_L else None
        gKt = torch.zeros_like(self.Kt) if need_K else None
        for rows in self.blocks():
            Gb = self._block(G, rows)
            if need_K:
                Lp = self._padded(L, rows)
                for i, j in self.taps:
                    gKt[i, j, rows] = (Gb * Lp[i : i + V, j : j + U]).sum(dim=(0, 1, 2))
            if need_L:
                gp = Gb.new_zeros((len(self.iv), len(self.iu)) + Gb.shape[2:])
                for i, j in self.taps:
                    gp[i : i + V, j : j + U].addcmul_(Gb, self.Kt[i, j, rows])
                # adjoint of the replicate padding: add padded views back onto the edges
                gv = fold(gp, 0, self.iv_list, V)
                gL[:, :, rows] = fold(gv, 1, self.iu_list, U).permute(0, 1, 3, 4, 2)
        gK = gKt.permute(2, 3, 0, 1) if need_K else None
        return gL, gK

    def adjoint(self, G):
        return self.backward(None, G, need_L=True, need_K=False)[0]


class TapBlur(torch.autograd.Function):
    """``f = taps(K) * L`` with gradients for the light field and the kernel, recomputed block-wise.

    ``taps`` is the :class:`Taps` (or :class:`~napari_lfdeblur._taps4d.Taps4D`)
    built from ``K``; ``K`` is passed too so that autograd carries its gradient.
    """

    @staticmethod
    def forward(ctx, L, K, taps):
        ctx.save_for_backward(L)
        ctx.taps = taps
        return taps.forward(L)

    @staticmethod
    def backward(ctx, G):
        (L,) = ctx.saved_tensors
        gL, gK = ctx.taps.backward(L, G.contiguous(), ctx.needs_input_grad[0], ctx.needs_input_grad[1])
        return gL, gK, None
