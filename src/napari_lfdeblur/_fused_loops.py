"""The numba loops of :mod:`~napari_lfdeblur._fused`; importing this module needs numba.

Light fields are held as rows ``(V, U, Y, X * C)``. A kernel ``K`` of shape
``(S, h, w)`` covers the output pixels ``r0 <= y < r0 + h``,
``c0 <= x < c0 + w`` (the whole view, or one spatial tile); ``off`` holds the
``(S, 4)`` int64 offsets ``(a, b, c, e)`` of ``(v, y, u, x)``, and ``x0s``,
``x1s`` the ``(S, h)`` columns ``x0:x1`` (relative to ``c0``) outside which a
tap's weights are zero. The blurred light field holds the views ``0, step,
2 step, ...`` along ``v`` and ``u``.
"""

import numba
import numpy as np

__all__ = ["forward", "adjoint", "kernel_grad"]

_jit = numba.njit(parallel=True, cache=True, fastmath={"contract", "reassoc"}, nogil=True)
prange = numba.prange


@numba.njit(cache=True)
def _expand(k, x0, x1, c0, C, k3):
    """``k3[(c0 + x) * C + ch] = k[x]`` for ``x0 <= x < x1``: a row of weights, one per sample of the row."""
    for x in range(x0, x1):
        for ch in range(C):
            k3[(c0 + x) * C + ch] = k[x]


@numba.njit(cache=True)
def _inside(x0, x1, e, X):
    """``(lo, hi)``: the columns ``x0 <= lo <= x < hi <= x1`` whose ``x + e`` lies within ``[0, X)``."""
    lo = min(max(x0, -e), x1)
    return lo, max(min(x1, X - e), lo)


@_jit
def forward(L, K, off, x0s, x1s, r0, c0, step, C, out):
    """``out = sum_s K[s] L[shifted by off[s]]`` on the kernel's pixels, one output row per parallel step."""
    V, U, Y, XC = L.shape
    X = XC // C
    Vo, Uo = out.shape[0], out.shape[1]
    S, h, w = K.shape
    for yl in prange(h):
        y = r0 + yl
        k3 = np.empty(XC, L.dtype)
        out[:, :, y, c0 * C : (c0 + w) * C] = 0
        for s in range(S):
            x0, x1 = c0 + x0s[s, yl], c0 + x1s[s, yl]
            if x0 >= x1:
                continue
            e = off[s, 3]
            yy = min(max(y + off[s, 1], 0), Y - 1)
            _expand(K[s, yl], x0s[s, yl], x1s[s, yl], c0, C, k3)
            lo, hi = _inside(x0, x1, e, X)
            n = (hi - lo) * C
            for vo in range(Vo):
                vv = min(max(vo * step + off[s, 0], 0), V - 1)
                for uo in range(Uo):
                    src = L[vv, min(max(uo * step + off[s, 2], 0), U - 1), yy]
                    dst = out[vo, uo, y]
                    for i in range(x0 * C, lo * C):  # columns reading the left edge
                        dst[i] += k3[i] * src[i % C]
                    d2, k2, s2 = dst[lo * C : hi * C], k3[lo * C : hi * C], src[(lo + e) * C : (hi + e) * C]
                    for i in range(n):
                        d2[i] += k2[i] * s2[i]
                    for i in range(hi * C, x1 * C):  # columns reading the right edge
                        dst[i] += k3[i] * src[(X - 1) * C + i % C]
    return out


@_jit
def adjoint(G, K, off, x0s, x1s, r0, c0, step, C, out):
    """Adds the adjoint of :func:`forward` to ``out``, gathered per row of ``out`` (no atomics)."""
    V, U, Y, XC = out.shape
    X = XC // C
    Vo, Uo = G.shape[0], G.shape[1]
    S, h, w = K.shape
    y_first = max(r0 + min(off[:, 1].min(), 0), 0)  # the rows of out the kernel's pixels read
    y_last = min(r0 + h - 1 + max(off[:, 1].max(), 0), Y - 1)
    for i_row in prange(y_last - y_first + 1):
        yo = y_first + i_row
        k3 = np.empty(XC, G.dtype)
        for s in range(S):
            b, e = off[s, 1], off[s, 3]
            # the kernel's rows y with clamp(y + b) == yo: one inside, a run at the edges
            y_lo = yo - b if yo > 0 else r0
            y_hi = yo - b if yo < Y - 1 else r0 + h - 1
            for y in range(max(y_lo, r0), min(y_hi, r0 + h - 1) + 1):
                yl = y - r0
                x0, x1 = c0 + x0s[s, yl], c0 + x1s[s, yl]
                if x0 >= x1:
                    continue
                _expand(K[s, yl], x0s[s, yl], x1s[s, yl], c0, C, k3)
                lo, hi = _inside(x0, x1, e, X)
                n = (hi - lo) * C
                for vo in range(Vo):
                    vd = min(max(vo * step + off[s, 0], 0), V - 1)
                    for uo in range(Uo):
                        dst = out[vd, min(max(uo * step + off[s, 2], 0), U - 1), yo]
                        src = G[vo, uo, y]
                        for i in range(x0 * C, lo * C):
                            dst[i % C] += k3[i] * src[i]
                        d2, k2, s2 = dst[(lo + e) * C : (hi + e) * C], k3[lo * C : hi * C], src[lo * C : hi * C]
                        for i in range(n):
                            d2[i] += k2[i] * s2[i]
                        for i in range(hi * C, x1 * C):
                            dst[(X - 1) * C + i % C] += k3[i] * src[i]
    return out


@_jit
def kernel_grad(L, G, off, r0, c0, step, C, out):
    """``out[s, y, x] = sum G[v, u, y, x, ch] L[shifted by off[s]]`` over views and channels: d<G, forward(L)>/dK."""
    V, U, Y, XC = L.shape
    X = XC // C
    Vo, Uo = G.shape[0], G.shape[1]
    S, h, w = out.shape
    for yl in prange(h):
        y = r0 + yl
        acc = np.empty(XC, L.dtype)
        for s in range(S):
            e = off[s, 3]
            yy = min(max(y + off[s, 1], 0), Y - 1)
            x0, x1 = c0, c0 + w
            lo, hi = _inside(x0, x1, e, X)
            n = (hi - lo) * C
            acc[x0 * C : x1 * C] = 0
            for vo in range(Vo):
                vv = min(max(vo * step + off[s, 0], 0), V - 1)
                for uo in range(Uo):
                    src = L[vv, min(max(uo * step + off[s, 2], 0), U - 1), yy]
                    g = G[vo, uo, y]
                    for i in range(x0 * C, lo * C):
                        acc[i] += g[i] * src[i % C]
                    a2, g2, s2 = acc[lo * C : hi * C], g[lo * C : hi * C], src[(lo + e) * C : (hi + e) * C]
                    for i in range(n):
                        a2[i] += g2[i] * s2[i]
                    for i in range(hi * C, x1 * C):
                        acc[i] += g[i] * src[(X - 1) * C + i % C]
            for xl in range(w):
                t = acc[(c0 + xl) * C]
                for ch in range(1, C):
                    t += acc[(c0 + xl) * C + ch]
                out[s, yl, xl] = t
    return out
