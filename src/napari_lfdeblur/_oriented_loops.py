"""The numba loops of :mod:`~napari_lfdeblur._oriented`; importing this module needs numba.

Light fields are held as ``(V, U, N, C)`` arrays, ``N = Y * X`` the flat
pixels of a view; the shift along the disparity samples pixel ``j`` of the
next view at ``(1 - w[j]) * [i0[j]] + w[j] * [i1[j]]``. Each parallel step
owns one view of what it writes, so no two threads write the same sample.
"""

import numba
import numpy as np

from ._tv_loops import project_dual_row, tv_add_row, tv_row_norms

__all__ = ["prox_sweep", "prox_primal", "tv_views"]

_jit = numba.njit(parallel=True, cache=True, fastmath={"contract", "reassoc"}, nogil=True)
prange = numba.prange


# The TV prox along the disparity (as _tv_solvers.TVProx with ``oriented``): light fields (V, U, N, C) with
# ``N = Y * X``; the dual's components p0 (v), p1 (u), p2 (y), p3 (x) of that shape; ``(i00, i01, w0)`` and
# ``(i10, i11, w1)`` the taps of the shifts along y (for v) and along x (for u). A component's last index along its axis
# is never written (it stays 0). ``wp``: mu times the axis weights; ``wd``: the dual step times them (0 skips
# an axis); ``lo > hi``: no box.


@numba.njit(cache=True, fastmath={"contract"})
def _scatter(dst, g, i0, i1, w, alpha):
    """``dst += alpha * S^T g``, ``S`` the shift of the taps ``i0, i1, w`` (``dst``, ``g``: (N, C))."""
    C = dst.shape[1]
    if C == 3:  # unrolled: the common case
        for k in range(dst.shape[0]):
            k0, k1, ww = i0[k], i1[k], w[k]
            a, b = alpha * (1 - ww), alpha * ww
            t0, t1, t2 = g[k, 0], g[k, 1], g[k, 2]
            dst[k0, 0] += a * t0
            dst[k0, 1] += a * t1
            dst[k0, 2] += a * t2
            dst[k1, 0] += b * t0
            dst[k1, 1] += b * t1
            dst[k1, 2] += b * t2
        return
    for k in range(dst.shape[0]):
        k0, k1, ww = i0[k], i1[k], w[k]
        for c in range(C):
            t = alpha * g[k, c]
            dst[k0, c] += (1 - ww) * t
            dst[k1, c] += ww * t


@numba.njit(cache=True, fastmath={"contract"})
def _primal_view(v, p0, p1, p2, p3, a, b, X, i00, i01, w0, i10, i11, w1, wp, lo, hi, out):
    """``out[a, b] = clip(v + div(p))`` at the view ``(a, b)``, ``div = -D^T`` with the oriented ``D_v, D_u``.

    The rows' terms first (the loops index rows from 0, which lets them
    vectorise), then the transposed shifts of the previous views' duals, then the box.
    """
    V, U, N, C = v.shape
    Y, XC = N // X, X * C
    dst = out[a, b]
    o_, s_ = dst.reshape((Y, XC)), v[a, b].reshape((Y, XC))
    g0, g1 = p0[a, b].reshape((Y, XC)), p1[a, b].reshape((Y, XC))
    g2, g3 = p2[a, b].reshape((Y, XC)), p3[a, b].reshape((Y, XC))
    zero = np.zeros(XC, v.dtype)
    m = XC - C
    for y in range(Y):
        o, s = o_[y], s_[y]
        a0 = g0[y] if a < V - 1 else zero
        b0 = g1[y] if b < U - 1 else zero
        y1 = g2[y] if y < Y - 1 else zero
        y0 = g2[y - 1] if y > 0 else zero
        for j in range(XC):
            o[j] = s[j] + wp[0] * a0[j] + wp[1] * b0[j] + wp[2] * (y1[j] - y0[j])
        h, head, tail = g3[y], o[:m], o[C:]
        for j in range(m):
            head[j] += wp[3] * h[j]
        for j in range(m):
            tail[j] -= wp[3] * h[j]
    if a > 0:
        _scatter(dst, p0[a - 1, b], i00, i01, w0, -wp[0])
    if b > 0:
        _scatter(dst, p1[a, b - 1], i10, i11, w1, -wp[1])
    if lo <= hi:
        for y in range(Y):
            o = o_[y]
            for j in range(XC):
                o[j] = min(max(o[j], lo), hi)


@numba.njit(cache=True, fastmath={"contract"})
def _add_difference(dst, src, cur, i0, i1, w, r0, alpha):
    """``dst[j] += alpha * ((S src)[r0 + p] - cur[r0 + p])`` for the pixels ``p`` of a row, ``dst`` (X * C) a row,
    ``src``, ``cur`` (N, C) views (``S``: the shift of the taps ``i0, i1, w``)."""
    C = src.shape[1]
    if C == 3:  # unrolled: the common case
        for p in range(dst.shape[0] // 3):
            k = r0 + p
            k0, k1, ww = i0[k], i1[k], w[k]
            a, b = alpha * (1 - ww), alpha * ww
            dst[3 * p] += a * src[k0, 0] + b * src[k1, 0] - alpha * cur[k, 0]
            dst[3 * p + 1] += a * src[k0, 1] + b * src[k1, 1] - alpha * cur[k, 1]
            dst[3 * p + 2] += a * src[k0, 2] + b * src[k1, 2] - alpha * cur[k, 2]
        return
    for p in range(dst.shape[0] // C):
        k = r0 + p
        k0, k1, ww = i0[k], i1[k], w[k]
        for c in range(C):
            dst[p * C + c] += alpha * ((1 - ww) * src[k0, c] + ww * src[k1, c] - cur[k, c])


@numba.njit(cache=True, fastmath={"contract"})
def _dual_view(p0, p1, p2, p3, xs, a, b, X, i00, i01, w0, i10, i11, w1, wd, isotropic, coupled, one, nrm):
    """The dual step at the view ``(a, b)`` from the primal ``xs``, then its projection, row by row."""
    V, U, N, C = xs.shape
    Y, XC = N // X, X * C
    m = XC - C
    cur = xs[a, b]
    x_ = cur.reshape((Y, XC))
    r0, r1 = p0[a, b].reshape((Y, XC)), p1[a, b].reshape((Y, XC))
    r2, r3 = p2[a, b].reshape((Y, XC)), p3[a, b].reshape((Y, XC))
    for y in range(Y):
        x, f0, f1, f2, f3 = x_[y], r0[y], r1[y], r2[y], r3[y]
        if a < V - 1 and wd[0] != 0:
            _add_difference(f0, xs[a + 1, b], cur, i00, i01, w0, y * X, wd[0])
        if b < U - 1 and wd[1] != 0:
            _add_difference(f1, xs[a, b + 1], cur, i10, i11, w1, y * X, wd[1])
        if y < Y - 1 and wd[2] != 0:
            nx = x_[y + 1]
            for j in range(XC):
                f2[j] += wd[2] * (nx[j] - x[j])
        if wd[3] != 0:
            h, nx = f3[:m], x[C:]
            for j in range(m):
                h[j] += wd[3] * (nx[j] - x[j])
        project_dual_row(f0, f1, f2, f3, C, isotropic, coupled, one, nrm)


@_jit
def prox_sweep(v, p0, p1, p2, p3, X, i00, i01, w0, i10, i11, w1, wp, wd, lo, hi, isotropic, coupled, one, xs):
    """One dual gradient-projection iteration of the oriented TV prox, in place on ``p0..p3``; ``xs``: scratch.

    The primal of every view from the dual as it was, then every view's dual
    step and projection: one Jacobi iteration, as the torch version.
    """
    V, U, N, C = v.shape
    for k in prange(V * U):
        _primal_view(v, p0, p1, p2, p3, k // U, k % U, X, i00, i01, w0, i10, i11, w1, wp, lo, hi, xs)
    for k in prange(V * U):
        nrm = np.empty(X * C, v.dtype)
        _dual_view(p0, p1, p2, p3, xs, k // U, k % U, X, i00, i01, w0, i10, i11, w1, wd, isotropic, coupled, one,
                   nrm)


@_jit
def prox_primal(v, p0, p1, p2, p3, X, i00, i01, w0, i10, i11, w1, wp, lo, hi, out):
    """``out = clip(v + div(p))``: the oriented prox's result from its dual."""
    V, U, N, C = v.shape
    for k in prange(V * U):
        _primal_view(v, p0, p1, p2, p3, k // U, k % U, X, i00, i01, w0, i10, i11, w1, wp, lo, hi, out)


@_jit
def tv_views(x, X, i00, i01, w0, i10, i11, w1, aw, isotropic, coupled, out):
    """``out[k]``: the TV4 along the disparity of ``x`` (V, U, N, C) summed over the view ``k`` (row-major).

    The differences are weighted by ``aw``; ``isotropic``: the norm of each
    sample's 4-vector (each pixel's, over its channels too, when
    ``coupled``), else the sum of the components' norms.
    """
    V, U, N, C = x.shape
    Y, XC = N // X, X * C
    m = XC - C
    for k in prange(V * U):
        a, b = k // U, k % U
        cur = x[a, b]
        x_ = cur.reshape((Y, XC))
        acc, d = np.empty(XC, x.dtype), np.empty(XC, x.dtype)
        total = 0.0
        for y in range(Y):
            row = x_[y]
            acc[:] = 0
            for axis in range(2):
                if aw[axis] == 0 or (axis == 0 and a == V - 1) or (axis == 1 and b == U - 1):
                    continue
                d[:] = 0
                if axis == 0:
                    _add_difference(d, x[a + 1, b], cur, i00, i01, w0, y * X, aw[0])
                else:
                    _add_difference(d, x[a, b + 1], cur, i10, i11, w1, y * X, aw[1])
                total += tv_add_row(d, acc, isotropic, coupled, C)
            if y < Y - 1 and aw[2] != 0:
                nx = x_[y + 1]
                for j in range(XC):
                    d[j] = aw[2] * (nx[j] - row[j])
                total += tv_add_row(d, acc, isotropic, coupled, C)
            if m > 0 and aw[3] != 0:
                d2, nx = d[:m], row[C:]
                for j in range(m):
                    d2[j] = aw[3] * (nx[j] - row[j])
                total += tv_add_row(d2, acc, isotropic, coupled, C)
            total += tv_row_norms(acc, isotropic, coupled, C)
        out[k] = total
