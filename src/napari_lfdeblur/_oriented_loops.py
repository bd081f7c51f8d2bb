"""The numba loops of :mod:`~napari_lfdeblur._oriented`; importing this module needs numba.

Light fields are held as ``(V, U, N, C)`` arrays, ``N = Y * X`` the flat
pixels of a view; the shift along the disparity samples pixel ``j`` of the
next view at ``(1 - w[j]) * [i0[j]] + w[j] * [i1[j]]``. Each parallel step
owns one view of ``out``, so no two threads write the same sample.
"""

import numba

__all__ = ["difference_add", "adjoint_add"]

_jit = numba.njit(parallel=True, cache=True, fastmath={"contract", "reassoc"}, nogil=True)
prange = numba.prange


@_jit
def difference_add(x, axis, i0, i1, w, alpha, out):
    """``out[v, u] += alpha * (S x[next view] - x[v, u])`` for every view but the last along ``axis`` (0: v, 1: u)."""
    V, U, N, C = x.shape
    for k in prange(V * U):
        v, u = k // U, k % U
        if (axis == 0 and v == V - 1) or (axis == 1 and u == U - 1):
            continue
        src = x[v + 1, u] if axis == 0 else x[v, u + 1]
        cur, dst = x[v, u], out[v, u]
        for j in range(N):
            a, b, ww = i0[j], i1[j], w[j]
            for c in range(C):
                dst[j, c] += alpha * ((1 - ww) * src[a, c] + ww * src[b, c] - cur[j, c])


@_jit
def adjoint_add(g, axis, i0, i1, w, alpha, out):
    """``out += alpha * D^T g`` for :func:`difference_add`'s ``D``, gathered per view of ``out``.

    View ``(v, u)`` of ``out`` receives ``-g[v, u]`` (unless it is the last
    along ``axis``) and the transposed shift of ``g`` at the view before it.
    """
    V, U, N, C = g.shape
    for k in prange(V * U):
        v, u = k // U, k % U
        dst = out[v, u]
        if not ((axis == 0 and v == V - 1) or (axis == 1 and u == U - 1)):
            cur = g[v, u]
            for j in range(N):
                for c in range(C):
                    dst[j, c] -= alpha * cur[j, c]
        if (axis == 0 and v == 0) or (axis == 1 and u == 0):
            continue
        prev = g[v - 1, u] if axis == 0 else g[v, u - 1]
        for j in range(N):
            a, b, ww = i0[j], i1[j], w[j]
            for c in range(C):
                dst[a, c] += alpha * (1 - ww) * prev[j, c]
                dst[b, c] += alpha * ww * prev[j, c]
