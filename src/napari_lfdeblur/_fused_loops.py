"""The numba loops of :mod:`~napari_lfdeblur._fused`; importing this module needs numba.

Light fields are held as rows ``(V, U, Y, X * C)``; ``K`` is ``(S, Y, X)``,
``off`` the ``(S, 4)`` int64 offsets ``(a, b, c, e)`` of ``(v, y, u, x)``, and
``x0s``, ``x1s`` the ``(S, Y)`` columns ``x0:x1`` outside which a tap's
weights are zero. Each function writes ``out`` and returns it.
"""

import numba
import numpy as np

__all__ = ["forward", "adjoint", "kernel_grad"]

_jit = numba.njit(parallel=True, cache=True, fastmath={"contract", "reassoc"}, nogil=True)
prange = numba.prange


@numba.njit(cache=True)
def expand(k, x0, x1, C, k3):
    """``k3[x * C + ch] = k[x]`` for ``x0 <= x < x1``: a row of weights, one per sample of the row."""
    for x in range(x0, x1):
        for ch in range(C):
            k3[x * C + ch] = k[x]


@_jit
def forward(L, K, off, x0s, x1s, out):
    """``out = sum_s K[s] L[shifted by off[s]]``: the blur, one output row per parallel step."""
    V, U, Y, XC = L.shape
    S, _, X = K.shape
    C = XC // X
    for y in prange(Y):
        k3 = np.empty(XC, L.dtype)
        out[:, :, y, :] = 0
        for s in range(S):
            x0, x1 = x0s[s, y], x1s[s, y]
            if x0 >= x1:
                continue
            e = off[s, 3]
            yy = min(max(y + off[s, 1], 0), Y - 1)
            expand(K[s, y], x0, x1, C, k3)
            lo = min(max(x0, -e), x1)
            hi = max(min(x1, X - e), lo)
            n = (hi - lo) * C
            for v in range(V):
                vv = min(max(v + off[s, 0], 0), V - 1)
                for u in range(U):
                    src = L[vv, min(max(u + off[s, 2], 0), U - 1), yy]
                    dst = out[v, u, y]
                    for i in range(x0 * C, lo * C):  # columns reading the left edge
                        dst[i] += k3[i] * src[i % C]
                    d2, k2, s2 = dst[lo * C : hi * C], k3[lo * C : hi * C], src[(lo + e) * C : (hi + e) * C]
                    for i in range(n):
                        d2[i] += k2[i] * s2[i]
                    for i in range(hi * C, x1 * C):  # columns reading the right edge
                        dst[i] += k3[i] * src[(X - 1) * C + i % C]
    return out


@_jit
def adjoint(G, K, off, x0s, x1s, out):
    """The adjoint of :func:`forward` in the light field, gathered per output row (no atomics)."""
    V, U, Y, XC = G.shape
    S, _, X = K.shape
    C = XC // X
    for yo in prange(Y):  # the output row: every (y, tap) that reads it
        k3 = np.empty(XC, G.dtype)
        out[:, :, yo, :] = 0
        for s in range(S):
            b, e = off[s, 1], off[s, 3]
            y_lo = yo - b if yo > 0 else 0
            y_hi = yo - b if yo < Y - 1 else Y - 1
            for y in range(max(y_lo, 0), min(y_hi, Y - 1) + 1):
                x0, x1 = x0s[s, y], x1s[s, y]
                if x0 >= x1:
                    continue
                expand(K[s, y], x0, x1, C, k3)
                lo = min(max(x0, -e), x1)
                hi = max(min(x1, X - e), lo)
                n = (hi - lo) * C
                for v in range(V):
                    vo = min(max(v + off[s, 0], 0), V - 1)
                    for u in range(U):
                        dst = out[vo, min(max(u + off[s, 2], 0), U - 1), yo]
                        src = G[v, u, y]
                        for i in range(x0 * C, lo * C):
                            dst[i % C] += k3[i] * src[i]
                        d2, k2, s2 = dst[(lo + e) * C : (hi + e) * C], k3[lo * C : hi * C], src[lo * C : hi * C]
                        for i in range(n):
                            d2[i] += k2[i] * s2[i]
                        for i in range(hi * C, x1 * C):
                            dst[(X - 1) * C + i % C] += k3[i] * src[i]
    return out


@_jit
def kernel_grad(L, G, off, out):
    """``out[s, y, x] = sum_(v, u, ch) G[v, u, y, x, ch] L[shifted by off[s]]``: d<G, forward(L)>/dK."""
    V, U, Y, XC = L.shape
    S, _, X = out.shape
    C = XC // X
    for y in prange(Y):
        acc = np.empty(XC, L.dtype)
        for s in range(S):
            e = off[s, 3]
            yy = min(max(y + off[s, 1], 0), Y - 1)
            lo = min(max(0, -e), X)
            hi = max(min(X, X - e), lo)
            n = (hi - lo) * C
            acc[:] = 0
            for v in range(V):
                vv = min(max(v + off[s, 0], 0), V - 1)
                for u in range(U):
                    src = L[vv, min(max(u + off[s, 2], 0), U - 1), yy]
                    g = G[v, u, y]
                    for i in range(0, lo * C):
                        acc[i] += g[i] * src[i % C]
                    a2, g2, s2 = acc[lo * C : hi * C], g[lo * C : hi * C], src[(lo + e) * C : (hi + e) * C]
                    for i in range(n):
                        a2[i] += g2[i] * s2[i]
                    for i in range(hi * C, XC):
                        acc[i] += g[i] * src[(X - 1) * C + i % C]
            for x in range(X):
                t = acc[x * C]
                for ch in range(1, C):
                    t += acc[x * C + ch]
                out[s, y, x] = t
    return out
