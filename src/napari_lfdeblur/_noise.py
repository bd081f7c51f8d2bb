"""The noise level of a light field: :func:`estimate_noise_sigma`, behind the default TV weight."""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import ndimage

from ._lightfield import validate_lightfield

__all__ = ["estimate_noise_sigma"]

#: side of the square patches whose covariance is analysed
PATCH = 5
#: at most this many patches are read (a regular subsampling of the positions beyond it)
MAX_PATCHES = 1_000_000
#: with fewer patches only the wavelet estimate is used; each brightness class holds at least this many
MIN_PATCHES = 4000
#: the patches are chosen where the neighbouring view is flat within this many px (the disparities it allows for)
SHIFT = 3
#: brightness classes, each an equal share of the patches
N_CLASSES = 4
#: the share of each class's patches, the least detailed ones, whose covariance is analysed
KEPT = 0.5
#: blocks of :func:`_wavelet_estimate`: 4 x 4 Haar coefficients (8 x 8 pixels), of which the 12 smallest are kept
_NOISE_BLOCK, _NOISE_KEPT = 4, 12
#: the share of blocks, the least detailed ones, that :func:`_wavelet_estimate` reads the noise from
_NOISE_QUANTILE = 0.1
#: brightness classes of :func:`_wavelet_estimate`, each an equal share of the blocks
_NOISE_BINS = 4
#: the 10th percentile of the mean of the 12 smallest of 16 squared standard Gaussians
#: (simulated: 16 million blocks, 8 seeds, standard error 4e-5)
_NOISE_UNIT = 0.19817
#: rows per block of the float64 covariance sums
_CHUNK = 65536


def estimate_noise_sigma(lf: np.ndarray) -> float:
    """Robust estimate of the standard deviation of white noise in a light field.

    The smaller of two estimates, each unbiased on pure noise and each erring
    high on some images (what they read besides the noise is image detail),
    so that the smaller is the nearer:

    1. **Principal components of patches** [1]_, [2]_. White noise of
       standard deviation ``sigma`` adds ``sigma^2`` to every eigenvalue of
       the covariance of the ``5 x 5`` patches of a view, while the image,
       above all a blurred one, leaves some directions almost empty; the
       smallest eigenvalue (after each patch's own mean is removed) is then
       close to ``sigma^2``, also in finely textured natural scenes.
       Patches are sorted by brightness (their mean) into 4 classes of equal
       size, and in each class the least detailed half is kept: the patches
       whose variance *in the neighbouring view* (the largest within 3 px
       along the axis that disparity moves points between the two views) is
       below the class median. The noise of the two views is independent,
       so the choice does not favour patches whose own noise happens to be
       small (that would bias the estimate low). A class's noise variance is
       the second smallest eigenvalue of its kept patches' covariance (the
       smallest belongs to the removed mean), times ``25 / 24``. Beyond a
       million patches the positions are subsampled on a regular grid.
    2. **The least detailed blocks of the finest diagonal Haar detail**
       ``HH`` (Donoho & Johnstone [3]_): ``HH`` is cut into blocks of 4 x 4
       coefficients, each summarised by the mean of its 12 smallest squared
       coefficients; in each brightness class the variance is the 10th
       percentile of the block means over the same percentile for unit
       Gaussian noise. ``HH`` does not see smooth ramps and edges along the
       pixel axes, so it reads piecewise-flat scenes well, where patches
       near edges can fool the first estimate; it reads fine natural texture
       as noise.

    Each is the square root of the mean of its 4 class variances: the
    root-mean-square noise, also where it grows with brightness (photon
    noise). Patches and blocks without any detail (a clipped or constant
    region) say nothing about the noise and are left out; a light field with
    no detail at all gives 0.

    Noise added after the blur keeps its level, so the blurred input of a
    deconvolution is where it is measured. On integer-coded images the
    rounding counts as noise (about 0.29 of a code step). Small views read a
    few percent low (the smallest eigenvalue of a small sample's covariance
    errs low), and a light field of a single view, whose patches are chosen
    by their own variance, 15-20 % low. With fewer than 4000 patches only the
    second estimate is used, and views smaller than 8 x 8 pixels fall back to
    the classical ``median(|HH|) / 0.6745``.

    Parameters
    ----------
    lf : array_like, shape (V, U, Y, X[, C])
        Views of at least 2 x 2 pixels.

    Returns
    -------
    float
        0.0 when the light field has no detail at all.

    Raises
    ------
    ValueError
        On views smaller than 2 x 2 pixels.

    References
    ----------
    .. [1] S. Pyatykh, J. Hesser and L. Zheng, "Image noise level estimation
           by principal component analysis", IEEE Trans. Image Process. 22, 2013.
    .. [2] X. Liu, M. Tanaka and M. Okutomi, "Single-image noise level
           estimation for blind denoising", IEEE Trans. Image Process. 22, 2013.
    .. [3] D. L. Donoho and I. M. Johnstone, "Ideal spatial adaptation by
           wavelet shrinkage", Biometrika 81, 1994.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> noisy = rng.normal(0.5, 0.01, (5, 5, 64, 64)).astype(np.float32)
    >>> round(estimate_noise_sigma(noisy), 3)
    0.01
    """
    a = validate_lightfield(lf).astype(np.float32, copy=False)  # 4D or 5D, finite: NaN gives no estimate
    if a.ndim == 4:
        a = a[..., None]
    if min(a.shape[2:4]) < 2:
        raise ValueError(f"the noise estimate needs views of at least 2 x 2 pixels, not {a.shape[2]} x {a.shape[3]}")
    wavelet = _wavelet_estimate(a)
    pca = _pca_estimate(a)
    return wavelet if pca is None else min(wavelet, pca)


def _pca_estimate(a: np.ndarray) -> float | None:
    """The smallest principal component of the least detailed patches (None: too few patches)."""
    V, U, Y, X, C = a.shape
    b = PATCH
    n_positions = V * U * C * max(0, Y - b + 1) * max(0, X - b + 1)
    if n_positions < MIN_PATCHES:
        return None
    step = max(1, int(np.ceil(np.sqrt(n_positions / MAX_PATCHES))))
    windows = sliding_window_view(a, (b, b), axis=(2, 3))[:, :, ::step, ::step]  # (V, U, ny, nx, C, b, b)
    patches = np.ascontiguousarray(windows).reshape(*windows.shape[:5], b * b)
    del windows
    mean = patches.mean(axis=-1, dtype=np.float64)
    patches -= mean[..., None].astype(np.float32)
    own = np.einsum("...i,...i->...", patches, patches, dtype=np.float64)  # (V, U, ny, nx, C)
    chooser = _chooser(own, step)
    patches, mean = patches.reshape(-1, b * b), mean.reshape(-1)
    own, chooser = own.reshape(-1), chooser.reshape(-1)
    keep = (own > 0) & (chooser > 0)  # a patch without any detail says nothing about the noise
    if not keep.any():
        return 0.0
    index = np.flatnonzero(keep)
    index = index[np.argsort(mean[index], kind="stable")]
    variances = []
    for cls in np.array_split(index, max(1, min(N_CLASSES, index.size // MIN_PATCHES))):
        kept = cls[chooser[cls] <= np.quantile(chooser[cls], KEPT)]
        variances.append(_second_eigenvalue(patches, kept))
    return float(np.sqrt(max(float(np.mean(variances)), 0.0) * b * b / (b * b - 1)))


def _chooser(own: np.ndarray, step: int) -> np.ndarray:
    """What chooses the patches: the variance in the neighbouring view, the largest within ``SHIFT`` px.

    ``own``: the patches' variances (V, U, ny, nx, C) at positions ``step``
    px apart. The neighbour is along u (along v when U = 1); the maximum is
    taken along the axis that a disparity moves a point between the two
    views, so that a patch is chosen only when the neighbouring view is
    flat wherever the same scene can be. A single view chooses by its own
    variance.
    """
    V, U = own.shape[:2]
    if U == 1 and V == 1:
        return own
    axis = 3 if U > 1 else 2
    chooser = own[:, _partners(U)] if U > 1 else own[_partners(V)]
    reach = -(-SHIFT // step)  # positions within SHIFT px
    size = [1] * own.ndim
    size[axis] = 2 * reach + 1
    return ndimage.maximum_filter(chooser, size=size, mode="nearest")


def _partners(n: int) -> np.ndarray:
    """The neighbour of each of ``n >= 2`` views along one axis: 0 <-> 1, 2 <-> 3, ...; an odd last one takes n - 2."""
    partner = np.arange(n) ^ 1
    partner[partner >= n] = n - 2
    return partner


def _second_eigenvalue(patches: np.ndarray, rows: np.ndarray) -> float:
    """The second smallest eigenvalue of the (uncentred) covariance of ``patches[rows]``, summed in float64."""
    d = patches.shape[1]
    cov = np.zeros((d, d))
    for start in range(0, rows.size, _CHUNK):
        block = patches[rows[start : start + _CHUNK]].astype(np.float64)
        cov += block.T @ block
    return float(np.linalg.eigvalsh(cov / max(rows.size, 1))[1])


def _classical(a: np.ndarray) -> float:
    """``median(|HH|) / 0.6745`` of the finest diagonal Haar detail of every view (Y, X cut to even sizes)."""
    Y, X = a.shape[2] // 2 * 2, a.shape[3] // 2 * 2
    views = a[:, :, :Y, :X].reshape(-1, Y, X, a.shape[4])
    return float(np.median(np.abs(_haar_hh(views)))) / 0.6744897501960817


def _wavelet_estimate(a: np.ndarray) -> float:
    """The least detailed blocks of the finest diagonal Haar detail: see :func:`estimate_noise_sigma`."""
    b = _NOISE_BLOCK
    Yb, Xb = a.shape[2] // (2 * b), a.shape[3] // (2 * b)
    if Yb == 0 or Xb == 0:
        return _classical(a)
    U, C = a.shape[1], a.shape[4]
    means, brightness = [], []
    for row in a:  # one row of views at a time: the temporaries stay small
        r = row[:, : 2 * b * Yb, : 2 * b * Xb]
        sq = np.square(_haar_hh(r).reshape(U, Yb, b, Xb, b, C).transpose(0, 1, 3, 5, 2, 4).reshape(-1, b * b))
        level = r.reshape(U, Yb, 2 * b, Xb, 2 * b, C).mean(axis=(2, 4)).reshape(-1)  # in the order of sq's blocks
        keep = sq.max(axis=1) > 0  # a block without any detail (clipped, constant) says nothing of the noise
        means.append(np.partition(sq[keep], _NOISE_KEPT - 1, axis=1)[:, :_NOISE_KEPT].mean(axis=1, dtype=np.float64))
        brightness.append(level[keep])
    means, brightness = np.concatenate(means), np.concatenate(brightness)
    if means.size == 0:
        return 0.0
    n_bins = max(1, min(_NOISE_BINS, means.size // 100))
    bins = np.array_split(np.argsort(brightness, kind="stable"), n_bins)  # equal shares of the blocks
    variance = np.mean([np.quantile(means[i], _NOISE_QUANTILE) for i in bins]) / _NOISE_UNIT
    return float(np.sqrt(variance))


def _haar_hh(a: np.ndarray) -> np.ndarray:
    """The finest diagonal Haar detail of views ``(N, Y, X, C)`` (even ``Y``, ``X``): ``(N, Y/2, X/2, C)``."""
    return (a[:, 0::2, 0::2] - a[:, 0::2, 1::2] - a[:, 1::2, 0::2] + a[:, 1::2, 1::2]) * 0.5
