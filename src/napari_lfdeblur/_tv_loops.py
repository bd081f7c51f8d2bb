"""Row loops of the TV shared by :mod:`~napari_lfdeblur._fused_loops` and :mod:`~napari_lfdeblur._oriented_loops`.

A row is a 1D array of ``X * C`` samples (``C`` channels per pixel);
importing this module needs numba. The loops use numpy's error model (a
division by zero gives inf or nan instead of raising), which lets LLVM
vectorise the divisions and square roots of the projections; no division
here can meet a zero. Three channels, the common case, have loops of their
own (the pixels' norms), which vectorise where the general ones do not.

numba caches each compiled function with its own file, and the callers'
caches do not see edits here: after changing this module, delete the
``*.nbi`` and ``*.nbc`` files in ``__pycache__`` (or the callers keep
running the old code).
"""

import numba
import numpy as np

__all__ = ["project_dual_row", "tv_add_row", "tv_row_norms"]

_njit = numba.njit(cache=True, fastmath={"contract"}, error_model="numpy")
#: the TV's sums may be reordered (``reassoc``), which lets them vectorise
_njit_sum = numba.njit(cache=True, fastmath={"contract", "reassoc"}, error_model="numpy")


@_njit
def project_dual_row(g0, g1, g2, g3, C, isotropic, coupled, one, nrm):
    """One row of the dual onto the unit ball of the TV's dual norm (as ``priors.project_tv_dual``).

    ``one`` is 1 in the rows' dtype (float64 constants would promote the arithmetic).
    """
    XC = g0.shape[0]
    if not isotropic and not coupled:
        for j in range(XC):
            g0[j] = min(max(g0[j], -one), one)
            g1[j] = min(max(g1[j], -one), one)
            g2[j] = min(max(g2[j], -one), one)
            g3[j] = min(max(g3[j], -one), one)
        return
    if not isotropic:  # coupled: each component's vector over the channels
        for g in (g0, g1, g2, g3):
            for j in range(XC):
                nrm[j] = g[j] * g[j]
            _channel_scales(nrm, C, one)
            for j in range(XC):
                g[j] *= nrm[j]
        return
    for j in range(XC):
        nrm[j] = g0[j] * g0[j] + g1[j] * g1[j] + g2[j] * g2[j] + g3[j] * g3[j]
    if coupled:
        _channel_scales(nrm, C, one)
    else:
        for j in range(XC):
            nrm[j] = one / max(np.sqrt(nrm[j]), one)
    for j in range(XC):
        g0[j] *= nrm[j]
        g1[j] *= nrm[j]
        g2[j] *= nrm[j]
        g3[j] *= nrm[j]


@_njit
def _channel_scales(nrm, C, one):
    """``nrm`` (squares per sample) becomes ``1 / max(|.|, 1)`` of each pixel's norm over its ``C`` channels."""
    if C == 3:
        for p in range(nrm.shape[0] // 3):
            s = one / max(np.sqrt(nrm[3 * p] + nrm[3 * p + 1] + nrm[3 * p + 2]), one)
            nrm[3 * p] = s
            nrm[3 * p + 1] = s
            nrm[3 * p + 2] = s
        return
    for j in range(0, nrm.shape[0], C):
        s = nrm[j]
        for c in range(1, C):
            s += nrm[j + c]
        s = one / max(np.sqrt(s), one)
        for c in range(C):
            nrm[j + c] = s


@_njit_sum
def tv_add_row(d, acc, isotropic, coupled, C):
    """Adds a row of weighted differences ``d`` to the TV: squares into ``acc`` (isotropic), else the norms."""
    if isotropic:
        for j in range(d.shape[0]):
            acc[j] += d[j] * d[j]
        return 0.0
    total = 0.0
    if coupled:
        if C == 3:
            for p in range(d.shape[0] // 3):
                total += np.sqrt(d[3 * p] * d[3 * p] + d[3 * p + 1] * d[3 * p + 1] + d[3 * p + 2] * d[3 * p + 2])
            return total
        for j in range(0, d.shape[0], C):
            s = d[j] * d[j]
            for c in range(1, C):
                s += d[j + c] * d[j + c]
            total += np.sqrt(s)
        return total
    for j in range(d.shape[0]):
        total += abs(d[j])
    return total


@_njit_sum
def tv_row_norms(acc, isotropic, coupled, C):
    """The isotropic TV of a row from its squares ``acc`` (:func:`tv_add_row`): the sum of the samples' (with
    ``coupled``, the pixels') norms; 0 when not ``isotropic``."""
    total = 0.0
    if not isotropic:
        return total
    step = C if coupled else 1
    for j in range(0, acc.shape[0], step):
        s = acc[j]
        for c in range(1, step):
            s += acc[j + c]
        total += np.sqrt(s)
    return total
