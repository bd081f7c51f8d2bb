"""The per-view 2D blind deblurring baseline on images blurred by a known kernel."""

import numpy as np
import pytest
from scipy import ndimage
from skimage import data, transform

from _baseline2d import (  # benchmarks/_baseline2d.py, on the path by conftest.py
    Baseline2DParams,
    blind_deconv_2d,
    conv2_circular,
    deblur_views_2d,
)
from napari_lfdeblur.metrics import psnr


def _line_kernel(size=11, length=6.0, angle=0.5):
    k = np.zeros((size, size))
    c = size // 2
    for t in np.linspace(-length / 2, length / 2, 60):
        k[int(round(c + t * np.sin(angle))), int(round(c + t * np.cos(angle)))] += 1
    return k / k.sum()


def _moments(k):
    yy, xx = np.indices(k.shape)
    cy, cx = (k * yy).sum(), (k * xx).sum()
    cov = np.array(
        [
            [(k * (yy - cy) ** 2).sum(), (k * (yy - cy) * (xx - cx)).sum()],
            [(k * (yy - cy) * (xx - cx)).sum(), (k * (xx - cx) ** 2).sum()],
        ]
    )
    w, v = np.linalg.eigh(cov)
    return (cy, cx), np.sqrt(w[1]), np.arctan2(v[0, 1], v[1, 1]) % np.pi


def test_circular_convolution_matches_scipy():
    rng = np.random.default_rng(0)
    x, k = rng.random((13, 17)), rng.random((5, 5))
    np.testing.assert_allclose(conv2_circular(x, k), ndimage.convolve(x, k, mode="wrap"), atol=1e-12)


@pytest.mark.parametrize("final", ["wiener", "tv"])
def test_blind_deconv_recovers_a_line_kernel_and_sharpens(final):
    img = transform.resize(data.camera().astype(float) / 255, (96, 96), anti_aliasing=True)
    k_true = _line_kernel()
    blurred = ndimage.convolve(img, k_true, mode="nearest")
    blurred += np.random.default_rng(1).normal(0, 0.002, img.shape)
    restored, k = blind_deconv_2d(blurred, Baseline2DParams(final=final))
    assert restored.shape == img.shape and restored.dtype == np.float32
    # sharper than the input by a clear margin
    assert psnr(restored, img, crop=6) > psnr(blurred, img, crop=6) + 2.0
    # a valid kernel, centred on its centroid
    assert k.shape == (11, 11) and k.min() >= 0 and k.sum() == pytest.approx(1.0)
    (cy, cx), _, _ = _moments(k)
    assert abs(cy - 5) < 0.05 and abs(cx - 5) < 0.05
    # ... of the right direction and length (within 10 degrees and 25 %)
    _, length_true, angle_true = _moments(k_true)
    _, length, angle = _moments(k)
    d_angle = abs((angle - angle_true + np.pi / 2) % np.pi - np.pi / 2)
    assert d_angle < np.radians(10)
    assert abs(length - length_true) < 0.25 * length_true


def test_deblur_views_handles_colour_light_fields_view_by_view():
    rng = np.random.default_rng(2)
    base = ndimage.gaussian_filter(rng.random((40, 40, 3)), (1.5, 1.5, 0))
    lf = np.stack([np.stack([base, base[::-1]]), np.stack([base[:, ::-1], base])]).astype(np.float32)
    params = Baseline2DParams(kernel_size=5, n_iter=2)
    out, kernels = deblur_views_2d(lf, params)
    assert out.shape == lf.shape and out.dtype == np.float32
    assert kernels.shape == (2, 2, 5, 5)
    one, k01 = blind_deconv_2d(lf[0, 1], params)
    np.testing.assert_array_equal(out[0, 1], one)
    np.testing.assert_array_equal(kernels[0, 1], k01)


def test_bad_input():
    with pytest.raises(ValueError, match="odd"):
        Baseline2DParams(kernel_size=4)
    with pytest.raises(ValueError, match="final"):
        Baseline2DParams(final="lucy")
    with pytest.raises(ValueError, match="image"):
        blind_deconv_2d(np.zeros((2, 3, 4, 5)))
    with pytest.raises(ValueError, match="twice the kernel"):
        blind_deconv_2d(np.zeros((15, 15)))
    with pytest.raises(ValueError, match="light field"):
        deblur_views_2d(np.zeros((8, 8)))
