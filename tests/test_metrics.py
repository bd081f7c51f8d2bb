"""Metrics against hand-computed values and the ambiguities of MODEL.md."""

import math

import numpy as np
import pytest

from napari_lfdeblur import path_error, psnr, random_path, ssim
from napari_lfdeblur.metrics import PathError, angular_error, chamfer_distance
from napari_lfdeblur.path import linear_path


# ------------------------------------------------------------------ PSNR


def test_psnr_of_a_known_mse():
    ref = np.zeros((3, 3, 8, 8), np.float32)
    est = ref + 0.1  # MSE = 0.01
    assert psnr(est, ref) == pytest.approx(20.0, abs=1e-4)
    assert psnr(est, ref, data_range=2.0) == pytest.approx(10 * math.log10(4 / 0.01), abs=1e-4)
    # half the samples off by 0.2: MSE = 0.02
    est2 = ref.copy()
    est2[:, :, :4] = 0.2
    assert psnr(est2, ref) == pytest.approx(10 * math.log10(1 / 0.02), abs=1e-4)


def test_psnr_identical_is_infinite_and_crop_removes_only_spatial_borders():
    rng = np.random.default_rng(0)
    ref = rng.random((2, 3, 10, 12, 3)).astype(np.float32)
    assert psnr(ref, ref) == math.inf
    est = ref.copy()
    est[:, :, 0] += 0.5  # top row of every view
    est[:, :, :, -2:] -= 0.5  # two right columns
    assert psnr(est, ref) < 20
    assert psnr(est, ref, crop=1) < 20  # the right columns are still inside
    assert psnr(est, ref, crop=2) == math.inf
    # a 2D image: its own axes are the spatial ones
    img = rng.random((9, 9))
    bad = img.copy()
    bad[0] = 0
    assert psnr(bad, img, crop=1) == math.inf


def test_psnr_and_ssim_reject_bad_input():
    a = np.zeros((3, 3, 8, 8))
    with pytest.raises(ValueError, match="shapes differ"):
        psnr(a, np.zeros((3, 3, 8, 7)))
    with pytest.raises(ValueError, match="crop"):
        psnr(a, a, crop=4)
    with pytest.raises(ValueError, match="crop"):
        ssim(a, a, crop=-1)
    b = a.copy()
    b[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        psnr(b, a)
    with pytest.raises(ValueError, match="6D"):
        psnr(np.zeros((1,) * 6), np.zeros((1,) * 6))
    with pytest.raises(ValueError, match="give data_range"):  # integer against float: which range?
        psnr(a.astype(np.uint8), a)
    for metric in (psnr, ssim, angular_error):  # no samples: refused, not NaN
        with pytest.raises(ValueError, match="empty"):
            metric(np.zeros((0, 3, 8, 8)), np.zeros((0, 3, 8, 8)))
    with pytest.raises(ValueError, match="different ranges"):  # 0..255 against 0..1 (it has no data_range)
        angular_error(a.astype(np.uint8), a)
    for metric in (psnr, ssim):  # a string was compared with 0 ('>' not supported)
        with pytest.raises(TypeError, match="data_range must be a number; got '1'"):
            metric(a, a + 0.1, data_range="1")
        with pytest.raises(ValueError, match="data_range must be positive; got 0.0"):
            metric(a, a + 0.1, data_range=0)


# ------------------------------------------------------------------ SSIM


def _ssim_brute(est, ref, data_range):
    """Mean SSIM of 2D images ``(..., Y, X)`` over every 7 x 7 window inside the frame, averaged over images.

    Wang et al. 2004, eq. 13, with skimage.metrics.structural_similarity's defaults as its docs give them:
    K1 = 0.01, K2 = 0.03, a 7 x 7 uniform window, sample (N - 1) covariances, and the mean taken where the
    window lies inside the image.
    """
    c1 = (0.01 * data_range) ** 2
    c2 = (0.03 * data_range) ** 2
    values = []
    for e, r in zip(np.reshape(est, (-1,) + np.shape(est)[-2:]), np.reshape(ref, (-1,) + np.shape(ref)[-2:])):
        we = np.lib.stride_tricks.sliding_window_view(e.astype(np.float64), (7, 7)).reshape(-1, 49)
        wr = np.lib.stride_tricks.sliding_window_view(r.astype(np.float64), (7, 7)).reshape(-1, 49)
        me, mr = we.mean(axis=1), wr.mean(axis=1)
        ve, vr = we.var(axis=1, ddof=1), wr.var(axis=1, ddof=1)
        cov = ((we - me[:, None]) * (wr - mr[:, None])).sum(axis=1) / 48
        s = (2 * me * mr + c1) * (2 * cov + c2) / ((me**2 + mr**2 + c1) * (ve + vr + c2))
        values.append(s.mean())
    return float(np.mean(values))


def test_ssim_is_one_for_equal_and_the_mean_over_views():
    rng = np.random.default_rng(1)
    ref = rng.random((2, 2, 16, 16)).astype(np.float32)
    assert ssim(ref, ref) == pytest.approx(1.0)
    # one view in four replaced by a constant image of the same mean: SSIM of that view is small, its
    # contrast-structure term being c2 / (var + c2) in each window for an estimate with zero variance ...
    est = ref.copy()
    est[1, 1] = ref[1, 1].mean()
    s_view = ssim(est[1, 1], ref[1, 1])
    assert 0 <= s_view < 0.1
    # its value is SSIM's formula over 7 x 7 windows, computed here
    assert s_view == pytest.approx(_ssim_brute(est[1, 1], ref[1, 1], 1.0), abs=1e-5)
    # ... and the light field's SSIM is the mean of the four views' values
    assert ssim(est, ref) == pytest.approx((3 + s_view) / 4, abs=1e-9)


def test_ssim_colour_averages_channels_and_falls_with_noise():
    rng = np.random.default_rng(2)
    ref = rng.random((2, 2, 12, 12, 3))
    est = ref.copy()
    est[..., 2] = 1 - ref[..., 2]  # one channel inverted
    s_inv = ssim(est[..., 2], ref[..., 2])
    assert s_inv < 0
    # a colour light field is scored per view and channel over 7 x 7 windows (channels last)
    assert s_inv == pytest.approx(_ssim_brute(est[..., 2], ref[..., 2], 1.0), abs=1e-9)
    assert ssim(est, ref) == pytest.approx((2 + s_inv) / 3, abs=1e-9)
    noisy = ref + rng.normal(0, 0.02, ref.shape)
    small = ssim(noisy, ref)
    large = ssim(ref + rng.normal(0, 0.2, ref.shape), ref)
    assert 1 > small > large
    channels_first = np.moveaxis(noisy, -1, 0), np.moveaxis(ref, -1, 0)
    assert small == pytest.approx(_ssim_brute(*channels_first, 1.0), abs=1e-9)


# ---------------------------------------------------------- angular error


def test_angular_error_ignores_common_errors_and_sees_per_view_ones():
    rng = np.random.default_rng(3)
    V, U, Y, X = 3, 4, 5, 6
    ref = rng.random((V, U, Y, X))
    common = rng.normal(0, 0.1, (Y, X))  # same error in every view
    assert angular_error(ref + common, ref) == pytest.approx(0.0, abs=1e-12)
    a = 0.05
    est = ref + a * np.arange(U)[None, :, None, None]  # error grows by a per view column
    n_u = V * (U - 1) * Y * X
    n_v = (V - 1) * U * Y * X
    want = math.sqrt(n_u * a**2 / (n_u + n_v))
    assert angular_error(est, ref) == pytest.approx(want, rel=1e-9)
    with pytest.raises(ValueError, match="light fields"):
        angular_error(ref[0, 0], ref[0, 0])


# ----------------------------------------------------------------- Chamfer


def test_chamfer_hand_cases():
    assert chamfer_distance([[0, 0]], [[1, 0], [3, 0]]) == pytest.approx(0.5 * (1 + 2))
    a = [[0, 0, 0], [1, 0, 0]]
    assert chamfer_distance(a, a) == 0.0
    # unit squares 3 apart in y: the near side's points are 2 away, the far side's 3
    sq = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    assert chamfer_distance(sq, sq + [0, 3]) == pytest.approx(2.5)
    with pytest.raises(ValueError):
        chamfer_distance(np.zeros((0, 2)), sq)


# -------------------------------------------------------------- path error


def test_identical_reversed_and_offset_paths_have_zero_error():
    rng = np.random.default_rng(4)
    lf = rng.random((5, 5, 12, 12)).astype(np.float32)
    cp = random_path(4, extent=3.0, z_extent=1.0, seed=3)
    for est in (cp, cp[::-1], cp + [0.7, -1.2, 0.3], cp[::-1] - [0.5, 0.5, 0.0]):
        err = path_error(est, cp, n_times=16, lightfield=lf)
        assert isinstance(err, PathError)
        assert err.chamfer == pytest.approx(0.0, abs=1e-9)
        assert err.rmse == pytest.approx(0.0, abs=1e-9)
        assert err.rmse_relative == pytest.approx(0.0, abs=1e-9)
        assert err.blur_mismatch == pytest.approx(0.0, abs=1e-4)
    assert path_error(cp[::-1], cp).reversed
    assert not path_error(cp, cp).reversed
    assert path_error(cp, cp).blur_mismatch is None


def test_path_error_hand_case_perpendicular_lines():
    # T = 3 instants: est visits (-1,0),(0,0),(1,0); true visits (0,-1),(0,0),(0,1)
    est = linear_path(2.0, angle_deg=0.0)
    true = linear_path(2.0, angle_deg=90.0)
    err = path_error(est, true, n_times=3)
    assert err.chamfer == pytest.approx(2 / 3)
    assert err.rmse == pytest.approx(math.sqrt(4 / 3))
    assert err.extent == pytest.approx(2.0)
    assert err.rmse_relative == pytest.approx(math.sqrt(4 / 3) / 2)
    assert err.chamfer_relative == pytest.approx(1 / 3)


def test_path_error_same_curve_with_more_control_points():
    two = np.array([[-1.0, 0.5, 0.0], [1.0, -0.5, 0.2]])
    three = np.array([two[0], two.mean(0), two[1]])  # degree-elevated: the same curve
    err = path_error(three, two, n_times=20)
    assert err.chamfer == pytest.approx(0.0, abs=1e-12)
    assert err.rmse == pytest.approx(0.0, abs=1e-12)


def test_blur_mismatch_of_no_motion_is_one_and_of_a_static_truth_is_nan():
    rng = np.random.default_rng(5)
    lf = rng.random((5, 5, 10, 10, 2)).astype(np.float32)
    true = linear_path(2.0, angle_deg=30.0)
    # the zero path leaves lf as it is: ||lf - B(lf)|| / ||B(lf) - lf|| = 1
    err = path_error(np.zeros((2, 3)), true, n_times=8, lightfield=lf)
    assert err.blur_mismatch == pytest.approx(1.0, rel=1e-5)
    # a half-length estimate is in between
    half = path_error(linear_path(1.0, angle_deg=30.0), true, n_times=8, lightfield=lf)
    assert 0.1 < half.blur_mismatch < 0.9
    static = path_error(true, np.zeros((2, 3)), n_times=8, lightfield=lf)
    assert math.isnan(static.blur_mismatch)
    assert math.isnan(static.rmse_relative) and static.extent == 0.0
    assert set(static.as_dict()) >= {"chamfer", "rmse_relative", "blur_mismatch"}


def test_path_error_rejects_bad_paths():
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        path_error(np.zeros((3, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="n_times"):
        path_error(np.zeros((2, 3)), np.zeros((2, 3)), n_times=1)


def test_integer_inputs_are_scored_on_their_dtypes_range():
    rng = np.random.default_rng(0)
    ref = rng.integers(0, 256, (3, 3, 16, 16)).astype(np.uint8)
    est = np.clip(ref.astype(int) + rng.integers(-3, 4, ref.shape), 0, 255).astype(np.uint8)
    mse = np.mean((est.astype(float) - ref) ** 2)
    assert psnr(est, ref) == pytest.approx(10 * np.log10(255.0**2 / mse))  # not on [0, 1] (about -22 dB)
    assert psnr(est, ref) == pytest.approx(psnr(est / 255.0, ref / 255.0))
    assert ssim(est, ref) == pytest.approx(ssim(est / 255.0, ref / 255.0))
    assert ssim(est, ref) == pytest.approx(_ssim_brute(est, ref, 255.0), abs=1e-9)
    assert angular_error(est, ref) == pytest.approx(255.0 * angular_error(est / 255.0, ref / 255.0))
    wide = ref.astype(np.uint16)
    assert psnr(wide, wide + 1) == pytest.approx(10 * np.log10(65535.0**2))


def test_non_finite_points_and_infinity_disparity_are_refused():
    with pytest.raises(ValueError, match="NaN or Inf"):
        chamfer_distance([[np.nan, 0.0]], [[0.0, 0.0]])
    cp = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    with pytest.raises(ValueError, match="infinity_disparity must be finite"):
        path_error(cp, cp, infinity_disparity=float("nan"))


def test_metrics_take_torch_tensors_that_require_grad():
    # what a script in the middle of an optimisation holds: the numbers are those of the arrays
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(0)
    est, ref = rng.random((3, 3, 12, 12)), rng.random((3, 3, 12, 12))
    t = torch.tensor(est, requires_grad=True)
    assert psnr(t, ref) == psnr(est, ref) and ssim(t, ref) == ssim(est, ref)
    assert angular_error(t, torch.tensor(ref)) == angular_error(est, ref)
    a, b = linear_path(1.0), linear_path(2.0, angle_deg=30)
    assert chamfer_distance(torch.tensor(a, requires_grad=True), b) == chamfer_distance(a, b)
    with pytest.raises(ValueError, match="different ranges"):  # a uint8 tensor is scored on 0..255, as its array
        psnr(torch.tensor((est * 255).astype(np.uint8)), ref)
