"""A per-view 2D blind deblurring baseline (L0-gradient prior, Xu 2013 / Pan 2014 style).

This is the comparison the paper makes: deblur every sub-aperture view on its
own with a good single-image blind method, ignoring the light field's angular
structure. It lives beside ``benchmarks/blind_eval.py``, which uses it, and is
not part of the package; numpy and scipy FFTs only.

Method, per view (kernel estimated on grayscale, applied to every channel):

1. **Coarse to fine** over an image pyramid (factor ``sqrt(2)`` per level)
   with the kernel upsampled from the previous level; the coarsest kernel is
   3x3, initialised to a two-pixel horizontal line (Pan et al. 2014).
2. At each level, ``n_iter`` alternations of
   - the **latent update**: an L0-gradient-regularised deconvolution
     ``min_x ||k * x - y||^2 + lam ||grad x||_0`` by half-quadratic
     splitting (Xu et al. 2011/2013): ``g = grad x`` hard-thresholded at
     ``|g|^2 < lam / beta``, then ``x`` in closed form with FFTs, ``beta``
     doubling from ``2 lam`` to ``1e5``; ``lam`` shrinks by 1/1.1 per iteration;
   - the **kernel update** in the gradient domain: ``min_k ||grad x * k -
     grad y||^2 + gamma ||k||^2`` on the ``ks x ks`` support, by conjugate
     gradients with FFT products, then negatives and values below
     ``max / 20`` set to 0, the largest connected component kept, the kernel
     normalised to sum 1 and re-centred on its centroid (sub-pixel).
3. A final **non-blind** deconvolution of each channel with the estimated
   kernel: by default a Wiener filter with a gradient prior,
   ``min_x ||k * x - y||^2 + omega ||grad x||^2`` (closed form, FFT); or
   total variation, ``min_x 0.5 ||k * x - y||^2 + mu TV(x)``, by
   half-quadratic splitting with FFTs. On the held-out light fields the
   Wiener filter did a little better on average (TV flattens the fine texture
   of real views).

Re-centring the kernel on its centroid puts every view in the gauge of the
mean camera position, which is what the light-field methods return too: for
a scene point at disparity ``d`` the view-space blur is the camera path
scaled by ``d``, whose centroid is the mean position.

Boundaries: every image is padded with a smooth wrap-around blend (as in
Liu & Jia 2008, ``wrap_boundary``) so that the FFTs' circular convolution does
not ring at the borders.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from scipy import ndimage

__all__ = ["Baseline2DParams", "blind_deconv_2d", "deblur_views_2d", "conv2_circular"]


@dataclass(frozen=True)
class Baseline2DParams:
    """Parameters of the 2D baseline.

    The structure and most values follow Pan et al. 2014's L0 code; the L0
    weight, the final step and its weight, and the kernel size were chosen on light fields
    that ``benchmarks/blind_eval.py`` does not evaluate on (synthetic scene
    seed 0 and the Lytro sample, blurred by ``random_path(seed=50)``).
    """

    kernel_size: int = 11
    n_iter: int = 5  # alternations per pyramid level
    lambda_grad: float = 1e-2  # L0 weight at the start of each level
    lambda_min: float = 1e-4
    beta_max: float = 1e5
    kernel_reg: float = 5e-3  # gamma, relative to the gradient energy
    kernel_cg_iters: int = 20
    kernel_threshold: float = 1 / 20
    final: str = "wiener"  # final non-blind step: "wiener" or "tv"
    wiener_weight: float = 5e-2  # omega of the gradient-regularised Wiener filter
    tv_weight: float = 1e-2  # mu of the TV deconvolution
    tv_steps: int = 14  # continuation steps of the TV deconvolution

    def __post_init__(self):
        if self.kernel_size < 3 or self.kernel_size % 2 == 0:
            raise ValueError(f"kernel_size must be an odd integer >= 3; got {self.kernel_size}")
        if self.n_iter < 1:
            raise ValueError(f"n_iter must be >= 1; got {self.n_iter}")
        if self.final not in ("wiener", "tv"):
            raise ValueError(f"final must be 'wiener' or 'tv'; got {self.final!r}")


# ------------------------------------------------------------ FFT helpers


def _psf2otf(k: np.ndarray, shape) -> np.ndarray:
    """The OTF of kernel ``k`` (centred) for circular convolution on ``shape``."""
    pad = np.zeros(shape)
    kh, kw = k.shape
    pad[:kh, :kw] = k
    pad = np.roll(pad, (-(kh // 2), -(kw // 2)), axis=(0, 1))
    return sfft.rfft2(pad)


def _otf2psf(otf: np.ndarray, shape, ks: int) -> np.ndarray:
    """Inverse of :func:`_psf2otf`: the centred ``ks x ks`` window of the spatial filter."""
    full = sfft.irfft2(otf, s=shape)
    full = np.roll(full, (ks // 2, ks // 2), axis=(0, 1))
    return full[:ks, :ks]


def conv2_circular(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Circular 2D convolution of image ``x`` with the centred kernel ``k``."""
    return sfft.irfft2(sfft.rfft2(x) * _psf2otf(k, x.shape), s=x.shape)


def _grad_otfs(shape):
    dx = _psf2otf(np.array([[1.0, -1.0, 0.0]]), shape)  # x[i+1] - x[i] (convolution flips)
    dy = _psf2otf(np.array([[1.0], [-1.0], [0.0]]), shape)
    return dx, dy


def _grad(x):
    return np.roll(x, -1, axis=1) - x, np.roll(x, -1, axis=0) - x


def _wrap_pad(img: np.ndarray, p: int) -> np.ndarray:
    """Pad by ``p`` pixels so that the periodic extension is continuous (linear blends)."""
    if p == 0:
        return img

    def pad_axis(a, axis):
        first = np.take(a, [0], axis=axis)
        last = np.take(a, [-1], axis=axis)
        w = (np.arange(1, 2 * p + 1) / (2 * p + 1)).reshape([-1 if i == axis else 1 for i in range(a.ndim)])
        blend = last * (1 - w) + first * w  # from the last sample back to the first
        return np.concatenate([blend[p:] if axis == 0 else blend[:, p:], a,
                               blend[:p] if axis == 0 else blend[:, :p]], axis=axis)

    return pad_axis(pad_axis(img, 1), 0)


def _smooth_pad(img, p):
    """Wrap-pad, then smooth only the padding so the blend has no kinks."""
    out = _wrap_pad(img, p)
    if p > 1:
        sm = ndimage.uniform_filter(out, size=p, mode="wrap")
        mask = np.ones_like(out, dtype=bool)
        mask[p:-p, p:-p] = False
        out[mask] = sm[mask]
    return out


# -------------------------------------------------------------- the steps


def _l0_restore(y, k_otf, lam, beta_max, dx, dy, denom_grad):
    """``min_x ||k * x - y||^2 + lam ||grad x||_0`` by half-quadratic splitting."""
    Y = sfft.rfft2(y)
    num_data = np.conj(k_otf) * Y
    den_data = np.abs(k_otf) ** 2
    x = y.copy()
    beta = 2 * lam
    while beta < beta_max:
        gx, gy = _grad(x)
        mask = gx**2 + gy**2 < lam / beta
        gx[mask] = 0
        gy[mask] = 0
        num = num_data + beta * (np.conj(dx) * sfft.rfft2(gx) + np.conj(dy) * sfft.rfft2(gy))
        x = sfft.irfft2(num / (den_data + beta * denom_grad), s=y.shape)
        beta *= 2
    return x


def _estimate_kernel(latent, blurred, ks, reg, iters, k0):
    """``min_k ||grad x * k - grad y||^2 + gamma ||k||^2`` on a ``ks x ks`` support (CG)."""
    lx, ly = _grad(latent)
    bx, by = _grad(blurred)
    Lx, Ly = sfft.rfft2(lx), sfft.rfft2(ly)
    m = np.abs(Lx) ** 2 + np.abs(Ly) ** 2
    b = _otf2psf(np.conj(Lx) * sfft.rfft2(bx) + np.conj(Ly) * sfft.rfft2(by), latent.shape, ks)
    gamma = reg * float(np.sum(lx**2 + ly**2))

    def apply(k):
        return _otf2psf(m * _psf2otf(k, latent.shape), latent.shape, ks) + gamma * k

    k = k0.copy()
    r = b - apply(k)
    p = r.copy()
    rs = float(np.sum(r * r))
    for _ in range(iters):
        if rs < 1e-20:
            break
        ap = apply(p)
        alpha = rs / float(np.sum(p * ap))
        k += alpha * p
        r -= alpha * ap
        rs_new = float(np.sum(r * r))
        p = r + (rs_new / rs) * p
        rs = rs_new
    return k


def _clean_kernel(k, threshold):
    k = np.where(k > 0, k, 0.0)
    if k.max() <= 0:
        out = np.zeros_like(k)
        out[k.shape[0] // 2, k.shape[1] // 2] = 1.0
        return out
    k[k < k.max() * threshold] = 0
    labels, n = ndimage.label(k > 0, structure=np.ones((3, 3)))
    if n > 1:  # keep the component holding the most mass
        mass = ndimage.sum(k, labels, index=np.arange(1, n + 1))
        k[labels != 1 + int(np.argmax(mass))] = 0
    return _recentre(k / k.sum())


def _recentre(k):
    """Shift the kernel so that its centroid is the centre pixel (bilinear, sub-pixel)."""
    c = (np.array(k.shape) - 1) / 2
    yy, xx = np.indices(k.shape)
    cy, cx = (k * yy).sum(), (k * xx).sum()
    out = ndimage.shift(k, (c[0] - cy, c[1] - cx), order=1, mode="constant")
    out = np.maximum(out, 0)
    s = out.sum()
    return out / s if s > 0 else k


def _resize_kernel(k, ks):
    if k.shape[0] == ks:
        return k
    z = ndimage.zoom(k, ks / k.shape[0], order=1)
    out = np.zeros((ks, ks))
    h = min(ks, z.shape[0])
    o1, o2 = (ks - h) // 2, (z.shape[0] - h) // 2
    out[o1 : o1 + h, o1 : o1 + h] = z[o2 : o2 + h, o2 : o2 + h]
    out = np.maximum(out, 0)
    return _recentre(out / out.sum()) if out.sum() > 0 else out


def _wiener_deconv(y, k, omega):
    """``min_x ||k * x - y||^2 + omega ||grad x||^2``: a Wiener filter with a gradient prior."""
    dx, dy = _grad_otfs(y.shape)
    K = _psf2otf(k, y.shape)
    den = np.abs(K) ** 2 + omega * (np.abs(dx) ** 2 + np.abs(dy) ** 2)
    return sfft.irfft2(np.conj(K) * sfft.rfft2(y) / den, s=y.shape)


def _tv_deconv(y, k, mu, n_steps):
    """``min_x 0.5 ||k * x - y||^2 + mu TV(x)`` (isotropic TV) by half-quadratic splitting.

    Splitting ``g = grad x`` with penalty ``beta/2 ||grad x - g||^2``: ``g`` is
    the soft-thresholded gradient (at ``mu / beta``), ``x`` a closed-form FFT
    solve; ``beta`` doubles from ``10 mu`` over ``n_steps`` steps.
    """
    dx, dy = _grad_otfs(y.shape)
    K = _psf2otf(k, y.shape)
    num_data = np.conj(K) * sfft.rfft2(y)
    den_data = np.abs(K) ** 2
    den_grad = np.abs(dx) ** 2 + np.abs(dy) ** 2
    x = y.copy()
    beta = 10.0 * mu
    for _ in range(n_steps):
        gx, gy = _grad(x)
        mag = np.sqrt(gx**2 + gy**2) + 1e-12
        shrink = np.maximum(mag - mu / beta, 0.0) / mag
        num = num_data + beta * (np.conj(dx) * sfft.rfft2(gx * shrink) + np.conj(dy) * sfft.rfft2(gy * shrink))
        x = sfft.irfft2(num / (den_data + beta * den_grad), s=y.shape)
        beta *= 2.0
    return x


# -------------------------------------------------------------- public


def blind_deconv_2d(image, params: Baseline2DParams | None = None):
    """Blind deblurring of one image with an L0-gradient prior.

    Parameters
    ----------
    image : ndarray, shape (Y, X) or (Y, X, C)
        Values in about [0, 1].
    params : Baseline2DParams, optional

    Returns
    -------
    restored : ndarray, float32, the input's shape
        Clipped to [0, 1].
    kernel : ndarray, float64, shape (ks, ks)
        The estimated blur kernel (non-negative, sums to 1, centroid at the centre).
    """
    p = params or Baseline2DParams()
    img = np.asarray(image, dtype=np.float64)
    if img.ndim not in (2, 3):
        raise ValueError(f"blind_deconv_2d needs a (Y, X) or (Y, X, C) image; got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("the image contains NaN or Inf")
    gray = img if img.ndim == 2 else img.mean(axis=2)
    ks = p.kernel_size
    if min(gray.shape) < 2 * ks:
        raise ValueError(f"the image ({gray.shape}) must be at least twice the kernel size {ks}")
    pad = ks

    # pyramid: kernel sizes from 3 up to ks by factors of sqrt(2)
    sizes = [ks]
    while sizes[-1] > 3:
        s = int(np.floor(sizes[-1] / np.sqrt(2)))
        s = max(3, s - (1 - s % 2))
        sizes.append(s)
    sizes = sizes[::-1]

    k = np.zeros((3, 3))
    k[1, 0:2] = 0.5
    for level, kl in enumerate(sizes):
        scale = kl / ks
        yl = ndimage.zoom(gray, scale, order=1) if scale < 1 else gray
        if level > 0:
            k = _resize_kernel(k, kl)
        yp = _smooth_pad(yl, kl)
        dx, dy = _grad_otfs(yp.shape)
        den_grad = np.abs(dx) ** 2 + np.abs(dy) ** 2
        lam = p.lambda_grad
        for _ in range(p.n_iter):
            latent = _l0_restore(yp, _psf2otf(k, yp.shape), lam, p.beta_max, dx, dy, den_grad)
            k = _estimate_kernel(latent, yp, kl, p.kernel_reg, p.kernel_cg_iters, k)
            k = _clean_kernel(k, p.kernel_threshold)
            lam = max(lam / 1.1, p.lambda_min)

    channels = img[..., None] if img.ndim == 2 else img
    out = np.empty_like(channels)
    for c in range(channels.shape[2]):
        yp = _smooth_pad(channels[..., c], pad)
        if p.final == "tv":
            x = _tv_deconv(yp, k, p.tv_weight, p.tv_steps)
        else:
            x = _wiener_deconv(yp, k, p.wiener_weight)
        out[..., c] = x[pad:-pad, pad:-pad]
    out = np.clip(out, 0, 1).astype(np.float32)
    return (out[..., 0] if img.ndim == 2 else out), k


def deblur_views_2d(lf, params: Baseline2DParams | None = None, progress=None):
    """Deblur every view of a light field on its own with :func:`blind_deconv_2d`.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
    params : Baseline2DParams, optional
    progress : callable, optional
        Called with ``(done, total)`` after each view.

    Returns
    -------
    restored : ndarray, float32, the input's shape
    kernels : ndarray, shape (V, U, ks, ks)
    """
    arr = np.asarray(lf)
    if arr.ndim not in (4, 5):
        raise ValueError(f"deblur_views_2d needs a (V, U, Y, X[, C]) light field; got shape {arr.shape}")
    p = params or Baseline2DParams()
    V, U = arr.shape[:2]
    out = np.empty(arr.shape, np.float32)
    kernels = np.empty((V, U, p.kernel_size, p.kernel_size))
    for v in range(V):
        for u in range(U):
            out[v, u], kernels[v, u] = blind_deconv_2d(arr[v, u], p)
            if progress is not None:
                progress(v * U + u + 1, V * U)
    return out, kernels
