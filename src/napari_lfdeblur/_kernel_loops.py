"""The numba loops that build a rotation's per-tile kernel and its gradient in the shifts; importing needs numba.

A tile's bilinear lookups come as in :func:`~napari_lfdeblur._taps_tiled._lookups`:
``base`` (int32, ``(T, h, w)``), the code of each lookup's lowest corner in
the box of offsets, and ``delta``, the code offsets of its 16 corners (``v``
slowest, ``x`` fastest); ``slot`` maps a code to its tap (-1: none). The
fractions (or their pairs ``(1 - f, f)``) are ``(T, h)`` for ``v``, ``(T, w)``
for ``u`` and ``(T, h, w)`` for ``y`` and ``x``. Each loop adds and
multiplies in the order of the torch version, without fused multiply-adds,
so the two give the same numbers.
"""

import numba
import numpy as np

__all__ = ["tile_accumulate", "tile_shift_grads"]

_jit = numba.njit(parallel=True, cache=True, nogil=True)  # no fastmath: the torch version's rounding


@_jit
def tile_accumulate(base, slot, delta, pv, py, pu, px, K, x0s, x1s):
    """``K[slot[base + delta[c]]] += w_c`` over corners ``c``, then instants; then each tap's column span per row.

    ``K`` (S, h, w) starts at 0. The weight of corner ``(i, j, k, l)`` is
    ``pv[i] py[j] pu[k] px[l]``. ``x0s, x1s`` (S, h) receive the columns
    ``x0 <= x < x1`` outside which a tap's weights are 0 (``0, 0`` where it
    has none in the row).
    """
    T, h, w = base.shape
    S = K.shape[0]
    for yl in numba.prange(h):
        for c in range(16):
            i, j, k, m = (c >> 3) & 1, (c >> 2) & 1, (c >> 1) & 1, c & 1
            d = delta[c]
            for t in range(T):
                for xl in range(w):
                    wgt = pv[i, t, yl] * py[j, t, yl, xl] * pu[k, t, xl] * px[m, t, yl, xl]
                    K[slot[base[t, yl, xl] + d], yl, xl] += wgt
        for s in range(S):
            first, past = 0, 0
            for xl in range(w):
                if K[s, yl, xl] != 0:
                    first = xl
                    break
            for xl in range(w - 1, -1, -1):
                if K[s, yl, xl] != 0:
                    past = xl + 1
                    break
            x0s[s, yl], x1s[s, yl] = first, past


@numba.njit(cache=True)
def _contract(g0, g1, f):
    """``g0 + (g1 - g0) f``: a weighted sum over an axis's two corners."""
    return g0 + (g1 - g0) * f


@_jit
def tile_shift_grads(gK, base, slot, delta, fv, fy, fu, fx, dv, dy, du, dx):
    """The derivative of ``<gK, K>`` in each lookup's four fractions, into ``dv, dy, du, dx`` (T, h, w).

    The corners' gradients are gathered and summed out one axis at a time
    (``x``, ``u``, ``y``, ``v``), each contraction weighting the other
    axes' factors, as :func:`~napari_lfdeblur._taps_tiled._tile_shift_grads`.
    """
    T, h, w = base.shape
    for yl in numba.prange(h):
        g = np.empty(16, gK.dtype)
        e = np.empty(8, gK.dtype)  # differences over x, then over x and u, then over x, u and y
        a = np.empty(4, gK.dtype)  # differences over u, then over u and y
        for t in range(T):
            for xl in range(w):
                b = base[t, yl, xl]
                for c in range(16):
                    g[c] = gK[slot[b + delta[c]], yl, xl]
                f_x, f_u, f_y, f_v = fx[t, yl, xl], fu[t, xl], fy[t, yl, xl], fv[t, yl]
                for q in range(8):  # over x: 8 (v, y, u) corners
                    e[q] = g[2 * q + 1] - g[2 * q]
                    g[q] = _contract(g[2 * q], g[2 * q + 1], f_x)
                for q in range(4):  # over u: 4 (v, y) corners
                    a[q] = g[2 * q + 1] - g[2 * q]
                    g[q] = _contract(g[2 * q], g[2 * q + 1], f_u)
                    e[q] = _contract(e[2 * q], e[2 * q + 1], f_u)
                ey0, ey1 = g[1] - g[0], g[3] - g[2]  # over y: 2 v corners
                gv0, gv1 = _contract(g[0], g[1], f_y), _contract(g[2], g[3], f_y)
                for q in range(2):
                    a[q] = _contract(a[2 * q], a[2 * q + 1], f_y)
                    e[q] = _contract(e[2 * q], e[2 * q + 1], f_y)
                dv[t, yl, xl] = gv1 - gv0
                dy[t, yl, xl] = _contract(ey0, ey1, f_v)
                du[t, yl, xl] = _contract(a[0], a[1], f_v)
                dx[t, yl, xl] = _contract(e[0], e[1], f_v)
