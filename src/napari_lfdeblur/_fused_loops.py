"""The numba loops of :mod:`~napari_lfdeblur._fused`; importing this module needs numba.

Light fields are held as rows ``(V, U, Y, X * C)``. A kernel ``K`` of shape
``(S, h, w)`` covers the output pixels ``r0 <= y < r0 + h``,
``c0 <= x < c0 + w`` (the whole view, or one spatial tile); ``off`` holds the
``(S, 4)`` int64 offsets ``(a, b, c, e)`` of ``(v, y, u, x)``, and ``x0s``,
``x1s`` the ``(S, h)`` columns ``x0:x1`` (relative to ``c0``) outside which a
tap's weights are zero. The blurred light field holds the views ``0, step,
2 step, ...`` along ``v`` and ``u``. The TV prox's loops follow (see their
section).
"""

import numba
import numpy as np

from ._kernel_loops import tile_accumulate, tile_shift_grads
from ._tv_loops import project_dual_row, tv_add_row, tv_row_norms

__all__ = ["forward", "adjoint", "kernel_grad", "prox_sweep", "prox_primal", "tv_rows", "view_variance",
           "add_laplacian", "tile_accumulate", "tile_shift_grads"]

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


#: most taps one pass of :func:`forward` applies together (see :func:`_chunk`)
GROUP = 4


@numba.njit(cache=True)
def _chunk(K, off, x0s, x1s, g, S, yl, c0, C, kk):
    """``(g2, xa, xb)``: taps ``g:g2`` read the same rows (equal ``a, b, c``), at most GROUP, and one pass over the
    union ``xa:xb`` of their spans in row ``yl`` makes at most a quarter more multiply-adds than they need.
    Their weights go into the rows of ``kk``, over that union (0 outside each tap's span)."""
    xa, xb = c0 + x0s[g, yl], c0 + x1s[g, yl]
    g2, useful = g + 1, xb - xa
    while xa < xb and g2 < S and g2 - g < GROUP and (off[g2, :3] == off[g, :3]).all():
        a, b = c0 + x0s[g2, yl], c0 + x1s[g2, yl]
        lo, hi = min(xa, a), max(xb, b)
        if a >= b or 4 * (hi - lo) * (g2 - g + 1) > 5 * (useful + b - a):
            break
        xa, xb, useful = lo, hi, useful + b - a
        g2 += 1
    for j in range(g2 - g):
        a, b = c0 + x0s[g + j, yl], c0 + x1s[g + j, yl]
        kk[j, xa * C : a * C] = 0
        kk[j, b * C : xb * C] = 0
        for x in range(a, b):
            for ch in range(C):
                kk[j, x * C + ch] = K[g + j, yl, x - c0]
    return g2, xa, xb


@numba.njit(cache=True)
def _edge_columns(dst, src, kk, e, m, x0, x1, X, C):
    """The columns ``x0:x1`` of a pass whose taps read beyond an edge: each tap's column clamped."""
    for x in range(x0, x1):
        for j in range(m):
            xs = min(max(x + e[j], 0), X - 1)
            for ch in range(C):
                dst[x * C + ch] += kk[j, x * C + ch] * src[xs * C + ch]


@_jit
def forward(L, K, off, x0s, x1s, r0, c0, step, C, out):
    """``out = sum_s K[s] L[shifted by off[s]]`` on the kernel's pixels, one output row per parallel step.

    Taps that read the same rows and differ only in ``e`` share one pass over the output rows (:func:`_chunk`).
    """
    V, U, Y, XC = L.shape
    X = XC // C
    Vo, Uo = out.shape[0], out.shape[1]
    S, h, w = K.shape
    for yl in prange(h):
        y = r0 + yl
        kk = np.empty((GROUP, XC), L.dtype)
        out[:, :, y, c0 * C : (c0 + w) * C] = 0
        g2 = 0
        while g2 < S:
            g = g2
            g2, xa, xb = _chunk(K, off, x0s, x1s, g, S, yl, c0, C, kk)
            m, e = g2 - g, off[g : g + GROUP, 3]  # e[j] for j < m
            if xa >= xb:
                continue
            lo = min(max(xa, -e[:m].min()), xb)  # the columns every tap of the chunk reads inside the row
            hi = max(min(xb, X - e[:m].max()), lo)
            n = (hi - lo) * C
            yy = min(max(y + off[g, 1], 0), Y - 1)
            k0, k1 = kk[0, lo * C : hi * C], kk[1, lo * C : hi * C]
            k2, k3 = kk[2, lo * C : hi * C], kk[3, lo * C : hi * C]
            e1, e2, e3 = e[min(1, m - 1)], e[min(2, m - 1)], e[min(3, m - 1)]
            for vo in range(Vo):
                vv = min(max(vo * step + off[g, 0], 0), V - 1)
                for uo in range(Uo):
                    src = L[vv, min(max(uo * step + off[g, 2], 0), U - 1), yy]
                    dst = out[vo, uo, y]
                    _edge_columns(dst, src, kk, e, m, xa, lo, X, C)
                    _edge_columns(dst, src, kk, e, m, hi, xb, X, C)
                    d2, s0 = dst[lo * C : hi * C], src[(lo + e[0]) * C : (hi + e[0]) * C]
                    s1, s2 = src[(lo + e1) * C : (hi + e1) * C], src[(lo + e2) * C : (hi + e2) * C]
                    s3 = src[(lo + e3) * C : (hi + e3) * C]
                    if m == 1:
                        for i in range(n):
                            d2[i] += k0[i] * s0[i]
                    elif m == 2:
                        for i in range(n):
                            d2[i] += k0[i] * s0[i] + k1[i] * s1[i]
                    elif m == 3:
                        for i in range(n):
                            d2[i] += k0[i] * s0[i] + k1[i] * s1[i] + k2[i] * s2[i]
                    else:
                        for i in range(n):
                            d2[i] += k0[i] * s0[i] + k1[i] * s1[i] + k2[i] * s2[i] + k3[i] * s3[i]
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


# ------------------------------------------------ the TV prox's dual sweep
# The dual field is four arrays of rows (one component per axis v, u, y, x), as the light field; ``wp`` are
# the primal's weights (mu times the axis weights), ``wd`` the dual step's (step times the axis weights, 0 for
# an axis that is skipped). A component's last index along its axis is never written (it stays 0).


@numba.njit(cache=True, fastmath={"contract"})
def _primal_row(v, p0, p1, p2, p3, y, wp, lo, hi, C, xs):
    """``xs[:, :, y] = clip(v + div(p))`` at the row ``y`` (``div`` weighted by ``wp``; ``lo > hi``: no box)."""
    V, U, Y, XC = v.shape
    zero = np.zeros(XC, v.dtype)
    n = XC - C
    for a in range(V):
        for b in range(U):
            o, src = xs[a, b, y], v[a, b, y]
            v1 = p0[a, b, y] if a < V - 1 else zero
            v0 = p0[a - 1, b, y] if a > 0 else zero
            u1 = p1[a, b, y] if b < U - 1 else zero
            u0 = p1[a, b - 1, y] if b > 0 else zero
            y1 = p2[a, b, y] if y < Y - 1 else zero
            y0 = p2[a, b, y - 1] if y > 0 else zero
            for j in range(XC):
                o[j] = src[j] + wp[0] * (v1[j] - v0[j]) + wp[1] * (u1[j] - u0[j]) + wp[2] * (y1[j] - y0[j])
            if n > 0:
                g, head, tail = p3[a, b, y], o[:n], o[C:]
                for j in range(n):
                    head[j] += wp[3] * g[j]
                for j in range(n):
                    tail[j] -= wp[3] * g[j]
            if lo <= hi:
                for j in range(XC):
                    o[j] = min(max(o[j], lo), hi)


@numba.njit(cache=True, fastmath={"contract"})
def _dual_row(p0, p1, p2, p3, xs, y, wd, C, isotropic, coupled, one, nrm):
    """The dual step at the row ``y`` from the primal rows ``y`` and ``y + 1`` of ``xs``, then the projection."""
    V, U, Y, XC = p0.shape
    n = XC - C
    for a in range(V):
        for b in range(U):
            x = xs[a, b, y]
            g0, g1, g2, g3 = p0[a, b, y], p1[a, b, y], p2[a, b, y], p3[a, b, y]
            if a < V - 1 and wd[0] != 0:
                nx = xs[a + 1, b, y]
                for j in range(XC):
                    g0[j] += wd[0] * (nx[j] - x[j])
            if b < U - 1 and wd[1] != 0:
                nx = xs[a, b + 1, y]
                for j in range(XC):
                    g1[j] += wd[1] * (nx[j] - x[j])
            if y < Y - 1 and wd[2] != 0:
                nx = xs[a, b, y + 1]
                for j in range(XC):
                    g2[j] += wd[2] * (nx[j] - x[j])
            if n > 0 and wd[3] != 0:
                h, nx, x0 = g3[:n], x[C:], x[:n]
                for j in range(n):
                    h[j] += wd[3] * (nx[j] - x0[j])
            project_dual_row(g0, g1, g2, g3, C, isotropic, coupled, one, nrm)


@_jit
def prox_sweep(v, p0, p1, p2, p3, wp, wd, lo, hi, C, isotropic, coupled, one, rows, xs):
    """One dual gradient-projection iteration of the TV prox, in place on ``p0..p3``; ``xs`` is scratch.

    The rows are cut in blocks of ``rows``; each block's first primal row is
    computed first from the dual as it was, then every block, in parallel,
    walks its rows: the primal of the next row (from the dual rows it owns,
    not yet updated), then the dual step of this row. That is one Jacobi
    iteration over the whole field, as the torch version computes it.
    """
    V, U, Y, XC = v.shape
    nb = (Y + rows - 1) // rows
    for k in prange(nb):
        _primal_row(v, p0, p1, p2, p3, k * rows, wp, lo, hi, C, xs)
    for k in prange(nb):
        nrm = np.empty(XC, v.dtype)
        y0, y1 = k * rows, min(Y, k * rows + rows)
        for y in range(y0, y1):
            if y + 1 < y1:
                _primal_row(v, p0, p1, p2, p3, y + 1, wp, lo, hi, C, xs)
            _dual_row(p0, p1, p2, p3, xs, y, wd, C, isotropic, coupled, one, nrm)


@_jit
def prox_primal(v, p0, p1, p2, p3, wp, lo, hi, C, out):
    """``out = clip(v + div(p))``: the prox's result from its dual."""
    for y in prange(v.shape[2]):
        _primal_row(v, p0, p1, p2, p3, y, wp, lo, hi, C, out)


@numba.njit(cache=True)
def _step(a, b, y, axis, side, V, U, Y):
    """``(a, b, y)`` moved by ``side`` along ``axis`` (0: v, 1: u, 2: y), and whether it stays in the field."""
    a, b, y = np.int64(a), np.int64(b), np.int64(y)  # a parallel loop's index may be unsigned
    if axis == 0:
        return a + side, b, y, 0 <= a + side < V
    if axis == 1:
        return a, b + side, y, 0 <= b + side < U
    return a, b, y + side, 0 <= y + side < Y


@_jit
def tv_rows(x, w, C, isotropic, coupled, out):
    """``out[y]``: the TV4 of ``x`` (rows (V, U, Y, X * C)) summed over the row ``y`` (forward differences
    weighted by ``w``; isotropic: the norm of each sample's 4-vector, over its channels too when ``coupled``)."""
    V, U, Y, XC = x.shape
    n = XC - C
    for y in prange(Y):
        acc = np.empty(XC, x.dtype)
        d = np.empty(XC, x.dtype)
        total = 0.0
        for a in range(V):
            for b in range(U):
                row = x[a, b, y]
                acc[:] = 0
                for axis in range(3):
                    na, nb, ny, inside = _step(a, b, y, axis, 1, V, U, Y)
                    if w[axis] == 0 or not inside:
                        continue
                    nxt = x[na, nb, ny]
                    for j in range(XC):
                        d[j] = w[axis] * (nxt[j] - row[j])
                    total += tv_add_row(d, acc, isotropic, coupled, C)
                if n > 0 and w[3] != 0:
                    d2, nx, r0 = d[:n], row[C:], row[:n]
                    for j in range(n):
                        d2[j] = w[3] * (nx[j] - r0[j])
                    total += tv_add_row(d2, acc, isotropic, coupled, C)
                total += tv_row_norms(acc, isotropic, coupled, C)
        out[y] = total


# ------------------------------------------------ refocused views' variance (disparity maps)


@numba.njit(cache=True, parallel=True, nogil=True)
def view_variance(f, y0, y1, wy0, wy1, x0, x1, wx0, wx1, out):
    """``out[k, y, x]``: the variance over the views of ``f`` (V, U, Y, X) resampled by the ``k``-th shear.

    The shear's bilinear taps are given per view row and column: ``y0, y1``
    and the weights ``wy0, wy1`` (n, V, Y), ``x0, x1, wx0, wx1`` (n, U, X), as
    ``blur.lerp_taps`` makes them (``wy0 = 1 - wy1``); a view is interpolated
    along ``y`` first, then along ``x``, as ``blind._disparity.shear`` does,
    and the variance is the unbiased one (two passes: the mean, then the
    squared deviations). No fused multiply-adds, so the resampled values are
    those of the torch version.
    """
    n, V, Y = wy0.shape
    U, X = wx0.shape[1], wx0.shape[2]
    m = V * U
    for y in prange(Y):
        vals = np.empty((m, X), f.dtype)
        mean = np.empty(X, f.dtype)
        acc = np.empty(X, f.dtype)
        for k in range(n):
            for v in range(V):
                a, b, w0, w1 = y0[k, v, y], y1[k, v, y], wy0[k, v, y], wy1[k, v, y]
                for u in range(U):
                    ra, rb, val = f[v, u, a], f[v, u, b], vals[v * U + u]
                    c0, c1, cw0, cw1 = x0[k, u], x1[k, u], wx0[k, u], wx1[k, u]
                    for x in range(X):
                        lo = ra[c0[x]] * w0 + rb[c0[x]] * w1
                        hi = ra[c1[x]] * w0 + rb[c1[x]] * w1
                        val[x] = lo * cw0[x] + hi * cw1[x]
            # deviations from the first view's value: equal values give exactly 0, as torch's variance does
            first = vals[0]
            mean[:] = 0
            for i in range(1, m):
                row = vals[i]
                for x in range(X):
                    mean[x] += row[x] - first[x]
            for x in range(X):
                mean[x] = first[x] + mean[x] / m
            acc[:] = 0
            for i in range(m):
                row = vals[i]
                for x in range(X):
                    e = row[x] - mean[x]
                    acc[x] += e * e
            for x in range(X):
                out[k, y, x] = acc[x] / max(m - 1, 1)


@_jit
def add_laplacian(a, z, w2, scale, C, out):
    """``out = a + scale * D^T W^2 D z``: the weighted 4D Laplacian of ``z`` (Neumann), rows (V, U, Y, X * C).

    ``w2`` holds the squared axis weights (0 skips an axis), as ``priors.laplacian4d``.
    """
    V, U, Y, XC = z.shape
    n = XC - C
    for y in prange(Y):
        t = np.empty(XC, z.dtype)
        for v in range(V):
            for u in range(U):
                zr = z[v, u, y]
                t[:] = 0
                for axis in range(3):
                    for side in (-1, 1):
                        nv, nu, ny, inside = _step(v, u, y, axis, side, V, U, Y)
                        if w2[axis] == 0 or not inside:
                            continue
                        nb = z[nv, nu, ny]
                        for j in range(XC):
                            t[j] += w2[axis] * (zr[j] - nb[j])
                if n > 0 and w2[3] != 0:
                    head, tail, z0, z1 = t[:n], t[C:], zr[:n], zr[C:]
                    for j in range(n):
                        head[j] += w2[3] * (z0[j] - z1[j])
                    for j in range(n):
                        tail[j] += w2[3] * (z1[j] - z0[j])
                o, ar = out[v, u, y], a[v, u, y]
                for j in range(XC):
                    o[j] = ar[j] + scale * t[j]
