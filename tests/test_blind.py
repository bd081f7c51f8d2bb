"""Tests of blind deblurring (napari_lfdeblur.blind) at tiny sizes."""

import json
import sys
import weakref

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter, map_coordinates

from napari_lfdeblur import _disparity as core_disparity, blind, devices
from napari_lfdeblur.blind import (
    BlindParams,
    BlindResult,
    JointParams,
    LatentParams,
    PathFitParams,
    _alternating,
    _disparity,
    _evidence,
    _latent,
    _memory,
    _path_fit,
    blind_deblur,
    iter_blind_deblur,
)
from napari_lfdeblur.blur import BlurOperator, simulate_blur
from napari_lfdeblur.deconvolution import DeconvolutionParams, deconvolve
from napari_lfdeblur.path import arc_path, bezier_positions, center_path, linear_path
from napari_lfdeblur.priors import gradient_yx, sparse_gradient_prior
from napari_lfdeblur.progress import run_to_completion, with_previews
from napari_lfdeblur.samples import synthetic_scene

from napari_lfdeblur.metrics import path_error, psnr

# small and fast: the test cases use few iterations
FAST = dict(path=dict(n_outer=2, steps=100, n_restarts=3), final={"n_iter": 15}, final_n_times=6)


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    # tiny tensors: one thread avoids OpenMP overhead (index_add_ is pathological with 2 busy threads)
    prev = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(prev)


def _scene(shape=(7, 7, 40, 40), seed=0, disparities=(2.0, -1.5)):
    """Two fronto-parallel piecewise-constant layers (a square in front of a background)."""
    V, U, Y, X = shape
    rng = np.random.default_rng(seed)

    def texture(h, w):
        t = np.full((h, w), rng.uniform(0.3, 0.7))
        for _ in range(40):
            y, x = rng.integers(0, h), rng.integers(0, w)
            s = rng.integers(2, 7)
            t[y : y + s, x : x + s] = rng.uniform(0, 1)
        return t

    pad = 16
    bg = texture(Y + 2 * pad, X + 2 * pad)
    fg = texture(Y + 2 * pad, X + 2 * pad)
    lf = np.empty(shape, np.float32)
    for v in range(V):
        for u in range(U):
            dv, du = v - (V - 1) / 2, u - (U - 1) / 2
            sb = (int(round(pad - disparities[1] * dv)), int(round(pad - disparities[1] * du)))
            sf = (int(round(pad - disparities[0] * dv)), int(round(pad - disparities[0] * du)))
            view = bg[sb[0] : sb[0] + Y, sb[1] : sb[1] + X].copy()
            f = fg[sf[0] : sf[0] + Y, sf[1] : sf[1] + X]
            view[Y // 4 : 3 * Y // 4, X // 4 : 3 * X // 4] = f[Y // 4 : 3 * Y // 4, X // 4 : 3 * X // 4]
            lf[v, u] = view
    return lf


def _positions(cp, n=64):
    p = bezier_positions(np.asarray(cp), n)
    return p - p.mean(0)


@pytest.fixture(scope="module")
def linear_case():
    sharp = _scene()
    cp = linear_path(2.0, angle_deg=30.0)
    rng = np.random.default_rng(1)
    blurred = simulate_blur(sharp, cp, n_times=32) + rng.normal(0, 0.002, sharp.shape).astype(np.float32)
    return sharp, cp, np.clip(blurred, 0, 1).astype(np.float32)


@pytest.fixture(scope="module")
def linear_result(linear_case):
    _, _, blurred = linear_case
    return blind_deblur(blurred, params=BlindParams().replace(n_control_points=2, **FAST), device="cpu")


# ------------------------------------------------------------ the solver


def test_lowers_the_error_against_ground_truth(linear_case, linear_result):
    sharp, _, blurred = linear_case
    res = linear_result
    assert isinstance(res, BlindResult)
    assert res.lightfield.shape == sharp.shape and res.lightfield.dtype == np.float32
    c = 6
    err_blurred = np.sqrt(np.mean((blurred - sharp)[:, :, c:-c, c:-c] ** 2))
    err_restored = np.sqrt(np.mean((res.lightfield - sharp)[:, :, c:-c, c:-c] ** 2))
    # at least 25 % less RMSE (about +2.5 dB) than the blurred input
    assert err_restored < 0.75 * err_blurred


def test_recovers_a_linear_in_plane_path(linear_case, linear_result):
    sharp, cp, _ = linear_case
    est = _positions(linear_result.control_points)
    true = _positions(cp)
    # the blur of the estimated path on the sharp light field is near the true one (docs/model.md, "Judging an
    # estimate"): a mismatch of 1 is no blur at all, and the true path's direction at a fraction s of its length
    # scores about 1 - s, so this asks for its direction and over half its length (measured: 0.39)
    assert path_error(linear_result.control_points, cp, lightfield=sharp).blur_mismatch < 0.55
    # and the direction of motion agrees within 20 degrees (up to sign)
    d_est = est[-1, :2] - est[0, :2]
    d_true = true[-1, :2] - true[0, :2]
    cos = abs(d_est @ d_true) / (np.linalg.norm(d_est) * np.linalg.norm(d_true))
    assert cos > np.cos(np.radians(20))


def test_result_gauge_and_range(linear_case, linear_result):
    res = linear_result
    cp = res.control_points
    assert cp.shape == (2, 3)
    # zero-mean gauge for the model's instants
    assert np.allclose(bezier_positions(cp, res.params.n_times).mean(0), 0, atol=1e-5)
    # the path stays within the aperture's box (docs/model.md)
    V = linear_case[0].shape[0]
    assert np.abs(cp).max() <= 0.35 * (V - 1) + 1e-6
    assert res.loss_history and all(np.isfinite(res.loss_history))
    # the path fits themselves, mean squared residuals of the gradients: never below 0
    assert min(res.loss_history) >= 0 and min(res.info["restart_losses"]) >= 0
    assert set(res.timings) >= {"path", "final", "total"}


def test_the_final_stage_reports_its_weight_which_reproduces_the_result(linear_case, linear_result):
    from napari_lfdeblur.deconvolution import deconvolve, estimate_noise_sigma

    _, _, blurred = linear_case
    res = linear_result
    final = res.params.final
    # the noise rule, as the deconvolution documents it, on the blurred data
    assert res.info["final_weight"] == pytest.approx(final.effective_weight(final.method, estimate_noise_sigma(blurred),
                                                                            1))
    again = deconvolve(blurred, res.control_points, n_times=res.params.final_n_times,
                       params=final.replace(weight=res.info["final_weight"]), device="cpu")
    np.testing.assert_allclose(again, res.lightfield, atol=1e-5)


def test_the_final_stage_takes_the_tv_along_the_views(linear_case, linear_result):
    from napari_lfdeblur.deconvolution import deconvolve

    _, _, blurred = linear_case
    assert linear_result.params.final.angular == "disparity" and not linear_result.params.final.isotropic
    params = linear_result.params.replace(final={"angular": "views", "isotropic": True})
    res = blind_deblur(blurred, params=params, device="cpu")
    np.testing.assert_array_equal(res.control_points, linear_result.control_points)  # the same path stage
    assert res.info["final_weight"] == pytest.approx(2 * linear_result.info["final_weight"])  # the isotropic rule
    again = deconvolve(blurred, res.control_points, n_times=params.final_n_times, device="cpu",
                       params=params.final.replace(weight=res.info["final_weight"]))
    np.testing.assert_allclose(again, res.lightfield, atol=1e-5)
    assert not np.allclose(res.lightfield, linear_result.lightfield, atol=1e-3)


def test_clear_blur_is_found_with_its_evidence(linear_result):
    info = linear_result.info
    assert info["blur_found"] is True and "blur found" in info["message"] and info["restoration"] == "full"
    ev = info["evidence"]
    assert ev["gain"] > _evidence.EVIDENCE_MARGIN and ev["relative"] > _evidence.RELATIVE_MARGIN
    assert ev["reach"] > 1.0 and "rejected_path" not in info


def test_a_dark_input_shows_little_blur_and_the_message_says_it_is_dark(linear_case, linear_result):
    # the same blurred scene at a tenth of its brightness: the salient edges are on an absolute scale
    _, _, blurred = linear_case
    dark = blurred * np.float32(0.1)
    res = blind_deblur(dark, params=BlindParams().replace(n_control_points=2, **FAST), device="cpu")
    assert linear_result.info["restoration"] == "full" and "dark" not in linear_result.info["message"]
    assert res.info["restoration"] == "none" and res.info["message"].startswith("little blur found")
    brightest = float(np.percentile(dark[3, 3], 99.9))
    assert res.info["brightest"] == pytest.approx(brightest, rel=1e-6) and brightest < 0.1
    assert f"The light field is dark (99.9 % of its centre view is below {brightest:.3g})" in res.info["message"]
    assert "value_range='auto'" in res.info["message"]
    ev = {"blur_found": False, "gain": 0.0, "relative": 0.0, "reach": 0.0}
    assert "dark" not in _evidence.evidence_message(ev, brightest=0.25)  # the threshold, DARK_LEVEL, excluded
    assert "dark" in _evidence.evidence_message(ev, brightest=0.249)
    assert "dark" not in _evidence.evidence_message({**ev, "blur_found": True}, brightest=0.1)


@pytest.mark.parametrize("gain_ok, relative_ok, reach_ok", [(False, True, True), (True, False, True),
                                                            (True, True, False), (False, False, False)])
def test_evidence_message_names_every_unmet_condition(gain_ok, relative_ok, reach_ok):
    ev = {"blur_found": False, "gain": 5.0 if gain_ok else 0.5, "relative": 0.2 if relative_ok else 0.01,
          "reach": 2.0 if reach_ok else 0.1}
    message = _evidence.evidence_message(ev)
    assert message.startswith("little blur found, the input is returned unchanged: ")
    assert ("noise variances" in message) != gain_ok
    assert ("by 1.0 % (needs > 6 %)" in message) != relative_ok
    assert ("moves the image by 0.10 px" in message) != reach_ok
    assert "restored anyway" in _evidence.evidence_message(ev, required=False)
    light = _evidence.evidence_message(ev, light=0.5)
    assert light.startswith("little blur found, a light restoration, with the estimated path at 50 % of its length")


@pytest.mark.parametrize("extent", [0.0, 0.15])
def test_no_harm_on_an_unblurred_or_barely_blurred_light_field(extent, monkeypatch):
    sharp = _scene()
    rng = np.random.default_rng(1)
    blurred = simulate_blur(sharp, linear_path(extent, 30.0), n_times=32) if extent else sharp
    blurred = np.clip(blurred + rng.normal(0, 0.002, sharp.shape), 0, 1).astype(np.float32)
    res = blind_deblur(blurred, params=BlindParams().replace(n_control_points=2, **FAST), device="cpu")
    assert psnr(res.lightfield, sharp) >= psnr(blurred, sharp) - 0.1
    assert res.info["blur_found"] is False and res.info["message"].startswith("little blur found")
    assert not np.any(res.control_points) and res.info["evidence"]["relative"] < 0.06
    assert "salient-edge objective" in res.info["message"]  # the margin it missed is named
    assert res.info["restoration"] == "none" and np.any(res.info["rejected_path"])
    if extent:  # require_evidence=False restores with the path estimated, whatever the evidence
        forced = blind_deblur(blurred, params=BlindParams().replace(n_control_points=2, require_evidence=False, **FAST),
                              device="cpu")
        assert "restored anyway" in forced.info["message"] and forced.info["restoration"] == "full"
        assert np.isnan(forced.info["evidence"]["disagreement"])  # no agreement check when it cannot matter
        np.testing.assert_array_equal(forced.control_points, res.info["rejected_path"])
        # a light restoration (the halves made to agree, and its blur counted as one whatever its size): the final
        # stage with the rejected path at half its length
        monkeypatch.setattr(_evidence, "AGREEMENT_MARGIN", float("inf"))
        monkeypatch.setattr(_evidence, "MIN_REACH", 0.0)
        params = BlindParams().replace(n_control_points=2, light_restoration=0.5, **FAST)
        light = blind_deblur(blurred, params=params, device="cpu")
        assert light.info["blur_found"] is False and light.info["restoration"] == "light"
        assert "a light restoration, with the estimated path at 50 % of its length" in light.info["message"]
        assert "agree on the path" in light.info["message"] and len(light.info["evidence"]["agreement_paths"]) == 2
        np.testing.assert_array_equal(light.info["rejected_path"], res.info["rejected_path"])
        np.testing.assert_allclose(light.control_points, 0.5 * res.info["rejected_path"], atol=1e-12)
        want = deconvolve(blurred, light.control_points, n_times=params.final_n_times, params=params.final,
                          device="cpu")
        np.testing.assert_allclose(light.lightfield, want, atol=1e-6)
        assert not np.array_equal(light.lightfield, blurred)
        # halves that disagree: the input, and the message says why
        monkeypatch.setattr(_evidence, "AGREEMENT_MARGIN", -1.0)
        none = blind_deblur(blurred, params=params, device="cpu")
        assert none.info["restoration"] == "none" and "disagree on the path" in none.info["message"]
        np.testing.assert_array_equal(none.lightfield, blurred)


def test_restoration_discrepancy_reads_the_noise_left_by_the_right_path():
    # f = K_p x + white noise: the right path and the sharp light field leave exactly the noise, one variance per
    # sample (to sampling error: 78400 samples per channel), whatever d_inf; a wrong path leaves more
    sharp = np.stack([_scene(seed=s) for s in (0, 1, 2)], axis=-1) * np.float32(0.8) + np.float32(0.1)
    cp, sigma = linear_path(2.0, angle_deg=30.0), 0.01
    for d_inf in (0.0, 0.5):
        noise = np.random.default_rng(3).normal(0, sigma, sharp.shape).astype(np.float32)
        f = simulate_blur(sharp, cp, n_times=8, infinity_disparity=d_inf) + noise
        assert float(f.max()) < 1.0
        d = _evidence.restoration_discrepancy(f, sharp, cp, 8, d_inf, sigma, "cpu")
        assert d == pytest.approx(float(np.mean(noise.astype(np.float64) ** 2)) / sigma**2, rel=1e-4)
        assert d == pytest.approx(1.0, abs=0.02)
        assert _evidence.restoration_discrepancy(f, sharp, 0 * cp, 8, d_inf, sigma, "cpu") > 5.0  # no blur: misses it
    # samples at the white level (clipped by the sensor) do not count, whatever the restoration makes of them
    clipped = f.copy()
    clipped[:, :, :5] = 1.0
    kept = np.ones(f.shape, bool)
    kept[:, :, :5] = False
    want = float(np.mean(noise[kept].astype(np.float64) ** 2)) / sigma**2
    assert _evidence.restoration_discrepancy(clipped, sharp, cp, 8, 0.5, sigma, "cpu") == pytest.approx(want, rel=1e-4)
    # grayscale; a restoration off by a constant 0.5 sigma leaves a quarter of a variance more than the noise
    grey = simulate_blur(sharp[..., 0], cp, n_times=8) + noise[..., 0]
    off = _evidence.restoration_discrepancy(grey, sharp[..., 0] + np.float32(0.5 * sigma), cp, 8, 0.0, sigma, "cpu")
    exact = _evidence.restoration_discrepancy(grey, sharp[..., 0], cp, 8, 0.0, sigma, "cpu")
    assert off == pytest.approx(exact + 0.25 - float(np.mean(noise[..., 0])) / sigma, rel=1e-3)
    with pytest.raises(ValueError, match="positive noise level"):  # no noise, no scale
        _evidence.restoration_discrepancy(grey, sharp[..., 0], cp, 8, 0.0, 0.0, "cpu")


def test_a_restoration_that_does_not_reproduce_the_data_is_not_returned(linear_case, linear_result, monkeypatch):
    from napari_lfdeblur.deconvolution import estimate_noise_sigma

    _, _, blurred = linear_case
    res, params = linear_result, linear_result.params
    assert res.info["noise_sigma"] == pytest.approx(estimate_noise_sigma(blurred))
    want = _evidence.restoration_discrepancy(blurred, res.lightfield, res.control_points, params.final_n_times, 0.0,
                                             res.info["noise_sigma"], "cpu")
    assert res.info["discrepancy"] == pytest.approx(want, rel=1e-6)
    assert 0.0 < res.info["discrepancy"] <= _evidence.DISCREPANCY_MARGIN and res.info["restoration"] == "full"
    # the same run with a limit it cannot meet: the input, a zero path, the estimate kept, and the reason
    monkeypatch.setattr(_evidence, "DISCREPANCY_MARGIN", 0.5 * res.info["discrepancy"])
    refused = blind_deblur(blurred, params=params, device="cpu")
    assert refused.info["restoration"] == "none" and refused.info["blur_found"] is True
    np.testing.assert_array_equal(refused.lightfield, blurred)
    assert not np.any(refused.control_points)
    np.testing.assert_array_equal(refused.info["rejected_path"], res.control_points)
    assert "misses the data by" in refused.info["message"] and "input is returned unchanged" in refused.info["message"]
    # with no measurable noise there is no scale to judge by: the restoration stands
    info = {"noise_sigma": 0.0, "restoration": "full", "message": "m"}
    out, cp = _evidence.discrepancy_check(blurred, res.lightfield, res.control_points, 0.0, params, "cpu", info)
    assert out is res.lightfield and cp is res.control_points and np.isnan(info["discrepancy"])
    assert info["restoration"] == "full" and info["message"] == "m"
    # restoring anyway means whatever the data say
    forced = blind_deblur(blurred, params=params.replace(require_evidence=False), device="cpu")
    assert forced.info["restoration"] == "full" and "discrepancy" not in forced.info
    np.testing.assert_array_equal(forced.lightfield, res.lightfield)


def test_no_harm_where_the_salient_edges_prefer_a_wrong_path():
    # a noise-free scene of flat colours in a thin strip, lightly blurred at d_inf = 0.5: a long path explains its
    # steps with fewer salient edges than the true one, clearly enough to pass the evidence test; restored with
    # it the result would be several dB worse than the input, and it misses the data by more than the noise
    sharp, _ = synthetic_scene((9, 9, 20, 200), seed=2)
    blurred = simulate_blur(sharp, arc_path(1.5, 0.3), infinity_disparity=0.5)
    res = blind_deblur(blurred, infinity_disparity=0.5, device="cpu", seed=0)
    assert psnr(res.lightfield, sharp) >= psnr(blurred, sharp) - 0.1


def test_split_parts_cut_the_data_in_two_and_place_the_parts():
    g = torch.rand(3, 3, 20, 36, 1)
    (a, fa), (b, fb) = _evidence.split_parts([g], [(4, 6, 20, 36)], (50, 60))  # wider: cut across x
    assert fa == [(4, 6, 50, 60)] and fb == [(4, 24, 50, 60)]
    torch.testing.assert_close(torch.cat([a[0], b[0]], dim=3), g, rtol=0, atol=0)
    tall = torch.rand(3, 3, 40, 20, 1)
    (a, fa), (b, fb) = _evidence.split_parts([tall], [(0, 0, 40, 20)], (40, 20))
    assert fa == [(0, 0, 40, 20)] and fb == [(20, 0, 40, 20)]
    torch.testing.assert_close(torch.cat([a[0], b[0]], dim=2), tall, rtol=0, atol=0)
    # several windows: dealt out alternately, each keeping its place
    ws = [torch.full((1, 1, 4, 4, 1), float(i)) for i in range(3)]
    (a, fa), (b, fb) = _evidence.split_parts(ws, [(0, 0, 4, 4), (0, 8, 4, 4), (8, 0, 4, 4)], (12, 12))
    assert [float(t[0, 0, 0, 0, 0]) for t in a] == [0.0, 2.0] and fa == [(0, 0, 12, 12), (8, 0, 12, 12)]
    assert [float(t[0, 0, 0, 0, 0]) for t in b] == [1.0] and fb == [(0, 8, 12, 12)]
    assert _evidence.split_parts([torch.rand(3, 3, 20, 30, 1)], [(0, 0, 20, 30)], (20, 30)) is None  # halves < 16 px


def test_path_disagreement_is_zero_for_one_path_symmetric_and_one_against_no_blur():
    g = torch.as_tensor(_scene()[..., None])
    a, b = linear_path(2.0, angle_deg=30.0), linear_path(1.0, angle_deg=100.0)
    n = 16
    assert _evidence.path_disagreement(g, a, a, n) == 0.0
    assert _evidence.path_disagreement(g, a, b, n) == pytest.approx(_evidence.path_disagreement(g, b, a, n), rel=1e-6)
    assert 0.3 < _evidence.path_disagreement(g, a, b, n) < 2.0
    zero = np.zeros_like(a)
    assert _evidence.path_disagreement(g, a, zero, n) == pytest.approx(1.0, rel=1e-6)  # as far as no blur
    assert _evidence.path_disagreement(g, zero, zero, n) == float("inf")


def test_two_halves_estimated_apart_agree_on_a_clear_blur(linear_case):
    sharp, cp, blurred = linear_case
    g = torch.as_tensor(blurred[..., None])
    Y, X = g.shape[2:4]
    p = BlindParams().replace(n_control_points=2, **FAST)
    parts = []
    d, paths = run_to_completion(_evidence.iter_disagreement([g], [(0, 0, Y, X)], (Y, X), p, torch.device("cpu"),
                                                             np.random.default_rng(0), p.path_box(7, 7)),
                                 lambda item: parts.append(item[0]))
    assert d <= _evidence.AGREEMENT_MARGIN and len(paths) == 2
    assert parts[0] == 0 and parts[-1] == 1 and parts == sorted(parts)  # records say which part they come from
    d_true = cp[-1, :2] - cp[0, :2]
    for path in paths:  # each half finds the camera's path: over half its length (measured: 0.40) ...
        assert path_error(path, cp, lightfield=sharp).blur_mismatch < 0.55
        # ... and its direction within 20 degrees, up to sign (measured: 13 and 14 degrees)
        d_est = path[-1, :2] - path[0, :2]
        assert abs(d_est @ d_true) / (np.linalg.norm(d_est) * np.linalg.norm(d_true)) > np.cos(np.radians(20))


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan"), "half"])
def test_light_restoration_must_be_a_fraction(bad):
    with pytest.raises((ValueError, TypeError), match="light_restoration"):
        BlindParams(light_restoration=bad)


def test_blind_deblurring_lowers_the_error_with_a_nonzero_infinity_disparity():
    d_inf = 1.0  # every disparity of the scene on one side of d_inf: (2.0, 0.5) relative to it
    sharp = _scene(disparities=(2.0 + d_inf, 0.5 + d_inf))
    rng = np.random.default_rng(1)
    blurred = simulate_blur(sharp, linear_path(2.0, 30.0), n_times=32, infinity_disparity=d_inf)
    blurred = np.clip(blurred + rng.normal(0, 0.002, sharp.shape), 0, 1).astype(np.float32)
    res = blind_deblur(blurred, infinity_disparity=d_inf, params=BlindParams().replace(n_control_points=2, **FAST),
                       device="cpu")
    assert res.info["blur_found"] is True
    assert psnr(res.lightfield, sharp) > psnr(blurred, sharp) + 2.0  # measured: +4.7 dB


def test_noise_sigma_is_robust_to_edges():
    rng = np.random.default_rng(0)
    flat = np.zeros((3, 3, 64, 64, 1), np.float32)
    flat[:, :, :, 32:] = 0.8  # a strong edge
    for sigma in (0.002, 0.01):
        g = torch.as_tensor(flat + rng.normal(0, sigma, flat.shape).astype(np.float32))
        assert _evidence.noise_sigma(g) == pytest.approx(sigma, rel=0.1)


def test_blur_reach_is_extent_times_disparity():
    lf = _two_disparity_halves(32, 32, 1, -2, seed=0, smooth=1.0)
    cp = linear_path(1.0)
    reach = _evidence.blur_reach(cp, 32, torch.as_tensor(lf))
    assert reach == pytest.approx(2.0, abs=0.2)  # 1 view x the larger |d|, 2 px/view
    assert _evidence.blur_reach(0.01 * cp, 32, torch.as_tensor(lf)) < _evidence.MIN_REACH


def test_same_seed_same_result():
    lf = _scene((5, 5, 24, 24), seed=3)
    blurred = simulate_blur(lf, linear_path(1.5, 60.0), n_times=16)
    p = BlindParams().replace(path=dict(n_outer=2, steps=40, n_restarts=2), final={"n_iter": 5}, final_n_times=4)
    a = blind_deblur(blurred, params=p, device="cpu", seed=7)
    b = blind_deblur(blurred, params=p, device="cpu", seed=7)
    np.testing.assert_array_equal(a.control_points, b.control_points)
    np.testing.assert_array_equal(a.lightfield, b.lightfield)


def test_estimated_paths_stay_in_range_on_flat_scene():
    # a scene of nearly zero disparity gives the path no hold: it must stay boxed
    rng = np.random.default_rng(0)
    view = rng.random((20, 20)).astype(np.float32)
    lf = np.broadcast_to(view, (5, 5, 20, 20)).copy()
    p = BlindParams().replace(path=dict(n_outer=2, steps=60, estimate_z=True), final=None)
    res = blind_deblur(lf, params=p, device="cpu")
    box = 0.35 * 4
    assert np.abs(res.control_points[:, :2]).max() <= box + 1e-6
    assert np.abs(res.control_points[:, 2]).max() <= 0.5 * box + 1e-6
    # final = None returns the input unchanged
    np.testing.assert_array_equal(res.lightfield, lf)


def test_a_constant_light_field_is_returned_with_a_sane_verdict():
    lf = np.full((3, 3, 16, 16), 0.5, np.float32)
    res = blind_deblur(lf, device="cpu", seed=0)
    np.testing.assert_array_equal(res.lightfield, lf)
    e = res.info["evidence"]
    # "no blur" costs nothing here: no relative gain (it was -6e16, rounding over 1e-30), none found
    assert e["relative"] == 0.0 and not e["blur_found"]
    assert "by 0.0 %" in res.info["message"]


def test_infinity_disparity_runs_and_keeps_shape():
    lf = _scene((5, 5, 20, 20), seed=2)[..., None].repeat(3, axis=-1)
    blurred = simulate_blur(lf, linear_path(1.0), n_times=8, infinity_disparity=0.5)
    p = BlindParams().replace(path=dict(n_outer=1, steps=20, n_restarts=1), final={"n_iter": 3}, final_n_times=4)
    res = blind_deblur(blurred, infinity_disparity=0.5, params=p, device="cpu")
    assert res.lightfield.shape == lf.shape and np.all(np.isfinite(res.lightfield))


def test_generator_yields_progress_and_closes_promptly(monkeypatch):
    lf = _scene((5, 5, 20, 20), seed=4)
    blurred = simulate_blur(lf, linear_path(1.5), n_times=8)
    calls = {"n": 0}
    real = _alternating.l0_latent

    def counting(*a, **k):
        calls["n"] += 1
        return real(*a, **k)

    monkeypatch.setattr(_alternating, "l0_latent", counting)
    gen = iter_blind_deblur(blurred, params=BlindParams().replace(path=dict(n_outer=50, tol=0.0)), device="cpu")
    first = next(gen)
    second = next(gen)
    assert first.stage.startswith("path") and first.control_points.shape[1] == 3
    assert second.iteration == first.iteration + 1
    # the loss is the fit at the end of an alternation (NaN on the reports inside one)
    rec = next(r for r in gen if r.info.get("phase") == "done")
    assert np.isfinite(rec.loss) and rec.iteration == rec.n_iterations // 50
    done = calls["n"]
    gen.close()
    assert calls["n"] <= done + 1
    with pytest.raises(StopIteration):
        next(gen)


def _count_blur_calls(monkeypatch):
    """Count BlurOperator.forward / adjoint calls (the bulk of the work of the path stage)."""
    count = {"n": 0}
    for name in ("forward", "adjoint"):
        real = getattr(BlurOperator, name)

        def counted(self, *a, _real=real, **k):
            count["n"] += 1
            return _real(self, *a, **k)

        monkeypatch.setattr(BlurOperator, name, counted)
    return count


def test_the_evidence_stage_reports_its_progress_through_the_agreement_check():
    # little blur (0.6 views), noise: the agreement check runs its two estimates (most of a quick run's time)
    lf, _ = synthetic_scene((5, 5, 48, 48), seed=0)
    b = simulate_blur(lf, linear_path(0.6), n_times=16)
    b = np.clip(b + np.random.default_rng(0).normal(0, 0.01, b.shape), 0, 1).astype(np.float32)
    p = BlindParams.preset("default").replace(path={"n_outer": 1}, final={"n_iter": 5})
    records = []
    result = run_to_completion(iter_blind_deblur(b, params=p, device="cpu"), records.append)
    assert np.isfinite(result.info["evidence"]["disagreement"])  # the check ran
    fractions = [r.fraction for r in records]
    assert fractions == sorted(fractions)
    evidence = [r for r in records if r.stage.startswith("evidence")]
    assert {r.stage for r in evidence} >= {"evidence (agreement check, part 1 of 2)",
                                            "evidence (agreement check, part 2 of 2)"}
    # its own share, between the path stages' and the final stage's, filled as the two estimates go
    # (it stayed at the path stages' end, for the two estimates' whole time)
    assert evidence[0].fraction == pytest.approx(2 / 4, abs=1e-3) and evidence[-1].fraction == pytest.approx(3 / 4)
    assert len({round(r.fraction, 2) for r in evidence}) >= 10


def test_path_stage_reports_often_with_monotone_progress_and_previews(monkeypatch):
    lf = _scene((5, 5, 20, 20), seed=4)
    blurred = simulate_blur(lf, linear_path(1.5), n_times=8)
    count = _count_blur_calls(monkeypatch)
    p = BlindParams().replace(path=dict(n_outer=3, tol=0.0, steps=60), final=None)
    every = 4
    gen = with_previews(iter_blind_deblur(blurred, params=p, device="cpu"), every)
    work, records, last = [], [], 0
    for rec in gen:
        work.append(count["n"] - last)
        last = count["n"]
        records.append(rec)
    total = count["n"]
    # the path stage, then the evidence for its blur (a stage of its own, before the final one)
    n_path = sum(r.stage.startswith("path") for r in records)
    assert all(r.stage.startswith("path") for r in records[:n_path])
    evidence = [r.fraction for r in records[n_path:]]  # the evidence test fills the first tenth of its stage
    assert all(r.stage == "evidence" for r in records[n_path:]) and evidence == sorted(evidence)
    assert 2 / 4 < evidence[0] < evidence[-1] <= (2 + 0.1) / 4 + 1e-9
    assert max(work) <= 3  # also in the evidence stage
    records = records[:n_path]
    # the work is split finely: many records, none after more than a small part of it
    assert len(records) >= 10
    assert {r.info["phase"] for r in records} == {"latent", "path fit", "done"}
    assert total > 0 and max(work) < 0.25 * total
    # at most one conjugate-gradient iteration (a forward and an adjoint blur, plus K^T f at a start)
    assert max(work) <= 3
    # every record carries the path; the progress only grows
    for r in records:
        assert r.control_points.shape == (4, 3)
        assert np.all(np.isfinite(r.control_points))
        # two path stages (in-plane, then p_z), then the evidence and the final one
        assert 1 <= r.iteration <= r.n_iterations and r.n_stages == 4 and r.stage_index in (0, 1)
    keys = [(r.stage_index, r.iteration) for r in records]
    assert keys == sorted(keys) and len(set(keys)) == len(keys)
    fractions = [r.fraction for r in records]
    assert fractions == sorted(fractions) and fractions[-1] <= 2 / 4 + 1e-9
    # every record can make a light-field estimate; with_previews(gen, every) makes one on every
    # every-th record, of the input's shape, in [0, 1]
    assert all(r.estimate is not None for r in records)
    with_preview = [i for i, r in enumerate(records, 1) if r.preview is not None]
    assert with_preview == list(range(every, n_path + 1, every))
    for i in with_preview:
        prev = records[i - 1].preview
        assert prev.shape == blurred.shape and prev.dtype == np.float32
        assert prev.min() >= 0.0 and prev.max() <= 1.0


def test_close_stops_the_work_at_once(monkeypatch):
    lf = _scene((5, 5, 20, 20), seed=4)
    blurred = simulate_blur(lf, linear_path(1.5), n_times=8)
    count = _count_blur_calls(monkeypatch)
    gen = iter_blind_deblur(blurred, params=BlindParams().replace(path=dict(n_outer=50, tol=0.0)), device="cpu")
    for _ in range(3):
        next(gen)
    done = count["n"]
    assert done > 0
    gen.close()
    assert count["n"] == done
    with pytest.raises(StopIteration):
        next(gen)


def test_path_stage_preview_matches_colour_input_and_undoes_the_refocus():
    lf = _scene((5, 5, 16, 16), seed=2)[..., None].repeat(3, axis=-1)
    blurred = simulate_blur(lf, linear_path(1.0), n_times=8, infinity_disparity=0.5)
    p = BlindParams().replace(path=dict(n_outer=1, steps=20, n_restarts=1), final=None)
    first = next(with_previews(iter_blind_deblur(blurred, infinity_disparity=0.5, params=p, device="cpu"), 1))
    prev = first.preview
    assert prev.shape == blurred.shape and prev.dtype == np.float32
    np.testing.assert_array_equal(prev[..., 0], prev[..., 2])  # grayscale estimate on every channel
    # the latent is of the refocused light field: the preview is back in the input's frame
    gray = blurred.mean(-1)
    err = np.abs(prev[..., 0] - gray)[:, :, 3:-3, 3:-3].mean()
    sheared = _disparity.shear(torch.as_tensor(gray)[..., None], 0.5)[..., 0].numpy()
    err_sheared = np.abs(prev[..., 0] - sheared)[:, :, 3:-3, 3:-3].mean()
    assert err < err_sheared


# ------------------------------------------------------------ parameters


@pytest.mark.parametrize("name", ["default", "paper"])
def test_presets_round_trip_through_json(name):
    p = BlindParams.preset(name)
    text = p.to_json()
    assert BlindParams.from_json(text) == p
    assert BlindParams.from_dict(json.loads(text)) == p


def test_params_from_a_results_metadata_leave_the_runs_settings_out():
    # a stamp is to_dict's fields beside the run's settings; from a layer's metadata or a file's, saved or read
    p = BlindParams.preset("paper").replace(n_control_points=5)
    stamp = {**p.to_dict(), "seed": 3, "device": "cpu", "infinity_disparity": 0.5, "operation": "blind_deblur"}
    layer_meta = {"kind": "blind", "parameters": stamp, "seed": 3}
    assert BlindParams.from_metadata(layer_meta) == p
    assert BlindParams.from_metadata({"layout": "npz", "saved_metadata": layer_meta}) == p  # as a file reads back
    for bad in ({}, {"parameters": None}, {"saved_metadata": {"kind": "blind"}}, None, "params.json"):
        with pytest.raises(ValueError, match="needs a result's metadata, with a 'parameters' dict"):
            BlindParams.from_metadata(bad)
    cut = {k: v for k, v in stamp.items() if k != "latent"}
    with pytest.raises(ValueError, match="lack latent"):
        BlindParams.from_metadata({"parameters": cut})
    with pytest.raises(ValueError, match="n_control_points"):  # the values are checked as from_dict checks them
        BlindParams.from_metadata({"parameters": {**stamp, "n_control_points": 1}})


def test_nested_params_json_is_nested_and_sub_dicts_merge_onto_the_defaults():
    d = json.loads(BlindParams.preset("paper").to_json())
    assert set(d) >= {"latent", "path", "joint", "final"} and d["joint"]["lr"] == 1.0
    assert d["final"]["weight"] == 0.004 and d["final"]["tol"] == 0.0
    # a partial file: missing keys, and missing keys of a sub-dict, take the defaults
    p = BlindParams.from_json('{"n_control_points": 3, "path": {"steps": 7}, "final": {"n_iter": 9}}')
    assert p.n_control_points == 3 and p.path == PathFitParams(steps=7)
    assert p.final == BlindParams().final.replace(n_iter=9) and p.latent == LatentParams()
    assert BlindParams.from_dict({"final": None}).final is None
    assert BlindParams.from_json(BlindParams().replace(final=None).to_json()).final is None
    # unknown keys, at the top or inside a sub-dict, are a data error
    with pytest.raises(ValueError, match="unknown blind path fit parameter.*bogus"):
        BlindParams.from_dict({"path": {"bogus": 1}})
    with pytest.raises(ValueError, match="unknown deconvolution parameter"):
        BlindParams.from_json('{"final": {"iterations": 3}}')
    with pytest.raises(ValueError, match="unknown blind parameter.*tv_iter"):
        BlindParams.from_dict({"tv_iter": 3})  # the old flat field
    with pytest.raises(ValueError, match="needs a dict"):
        BlindParams.from_json("[1, 2]")
    with pytest.raises(TypeError, match="needs a dict"):
        BlindParams.from_dict([("n_times", 3)])


def test_replace_merges_a_dict_into_the_current_sub_params_or_takes_an_instance():
    p = BlindParams().replace(latent={"edge_anisotropy": 0.6, "n_cg": 2})
    q = p.replace(n_control_points=5, latent={"edge_sigma": 0.3}, final={"n_iter": 50})
    assert q.n_control_points == 5
    assert q.latent == LatentParams(edge_anisotropy=0.6, n_cg=2, edge_sigma=0.3)  # merged into p's latent
    assert q.final == DeconvolutionParams(method="tv", n_iter=50)
    assert q.path == p.path and q.joint == p.joint
    assert p.replace(joint=JointParams(n_iter=3)).joint == JointParams(n_iter=3)
    # final = None skips the final stage; a dict then starts from the default final stage
    assert p.replace(final=None).replace(final={"n_iter": 4}).final == BlindParams().final.replace(n_iter=4)
    # unknown keywords, at the top or in a sub-dict, are a TypeError
    with pytest.raises(TypeError, match="unknown blind parameter.*tv_iter"):
        p.replace(tv_iter=3)
    with pytest.raises(TypeError, match="unknown blind latent parameter.*bogus"):
        p.replace(latent={"bogus": 1})
    with pytest.raises(TypeError, match="BlindParams.latent must be a LatentParams"):
        BlindParams(latent={"n_cg": 2})
    with pytest.raises(TypeError, match="BlindParams.final"):
        p.replace(final=JointParams())
    with pytest.raises(TypeError, match="n_control_points"):
        BlindParams(n_control_points=2.0)
    with pytest.raises(ValueError, match="path.steps"):
        p.replace(path={"steps": 0})
    for text in ('{"require_evidence": "false"}', '{"path": {"estimate_z": 0}}', '{"final": {"isotropic": "no"}}'):
        with pytest.raises(TypeError, match="must be true or false"):
            BlindParams.from_json(text)
    # blind_deblur: an override goes through replace(); an unknown keyword is a TypeError
    good = np.zeros((5, 5, 8, 8), np.float32)
    with pytest.raises(TypeError, match="tv_iter"):
        blind_deblur(good, tv_iter=3)
    with pytest.raises(TypeError, match="unknown blind path fit parameter"):
        iter_blind_deblur(good, path={"path_steps": 3})
    with pytest.raises(TypeError, match="seed"):
        iter_blind_deblur(good, seed=1.5)
    for bad in (-1, 2**63):  # torch's generators take 64-bit signed seeds
        with pytest.raises(ValueError, match="seed must be a whole number from 0 to 2\\*\\*63 - 1"):
            iter_blind_deblur(good, seed=bad)


def test_paper_preset_is_the_published_settings():
    p = BlindParams.preset("paper")
    j = p.joint
    assert (p.method, j.n_iter, j.lr, j.lf_lr, p.n_times) == ("joint", 1000, 1.0, 0.04, 7)
    assert (j.prior_weight, j.prior_decay, j.prior_floor) == (8e-3, 0.997, 0.1)
    assert (j.eps, j.eps_decay, j.eps_min) == (0.12, 0.997, 0.04)
    assert (p.final.weight, p.final.n_iter) == (0.004, 100)
    assert blind.PRESETS["paper"] == p


def test_joint_method_runs():
    lf = _scene((5, 5, 16, 16), seed=5)
    cp = linear_path(1.5)
    blurred = simulate_blur(lf, cp, n_times=8)
    p = BlindParams.preset("paper").replace(joint={"n_iter": 100}, final={"n_iter": 10})
    res = blind_deblur(blurred, params=p, device="cpu")
    assert res.lightfield.shape == lf.shape and len(res.loss_history) == 100
    # the joint Adam fits: its loss falls (measured: to 0.50 of the first; the prior's decaying weight alone,
    # with the path and the light field held, lowers it to 0.86) ...
    assert res.loss_history[-1] < 0.75 * res.loss_history[0]
    # ... towards the camera's path, whose blur of the sharp light field is near the true one (measured: 0.06;
    # 1 is no blur: a path left at its random start is rejected by the evidence check and returned as zero) ...
    assert res.info["restoration"] == "full"
    assert path_error(res.control_points, cp, lightfield=lf).blur_mismatch < 0.3
    # ... and the light field restored with it is nearer the sharp one (measured: +9.0 dB)
    assert psnr(res.lightfield, lf) > psnr(blurred, lf) + 4.0


def test_bad_input_gives_clear_errors():
    good = np.zeros((5, 5, 8, 8), np.float32)
    with pytest.raises(ValueError, match="4D"):
        blind_deblur(np.zeros((5, 8, 8), np.float32))
    bad = good.copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        blind_deblur(bad)
    with pytest.raises(ValueError, match="unknown blind parameter"):
        BlindParams.from_dict({"n_outer": 3, "bogus": 1})
    with pytest.raises(ValueError, match="unknown blind parameter"):
        BlindParams.from_json('{"learning_rate": 1}')
    with pytest.raises(ValueError, match="n_iter"):
        BlindParams(joint=JointParams(n_iter=-1))
    with pytest.raises(ValueError, match="path.steps"):
        blind_deblur(good, path={"steps": -5})
    with pytest.raises(ValueError, match="unknown blind preset"):
        BlindParams.preset("fastest")
    with pytest.raises(ValueError, match="method"):
        BlindParams(method="magic")
    with pytest.raises(ValueError, match="n_control_points"):
        blind_deblur(good, n_control_points=1)
    with pytest.raises(ValueError, match="n_random_later"):
        PathFitParams(n_random_later=-1)
    with pytest.raises(ValueError, match="path.robust"):
        PathFitParams(robust=-0.1)
    with pytest.raises(ValueError, match="edge_sigma"):
        LatentParams(edge_sigma=float("nan"))
    with pytest.raises(ValueError, match="edge_anisotropy"):
        LatentParams(edge_anisotropy=float("inf"))
    with pytest.raises(TypeError, match="edge_anisotropy"):  # a wrong type: TypeError by the error contract
        LatentParams(edge_anisotropy="wide")
    with pytest.raises(ValueError, match="edge_sigma_from"):
        LatentParams(edge_sigma_from=0)
    # a Gaussian of 3 sigma per side: 1e9 px asked for tens of GB (the process was killed)
    for field, value in (("edge_sigma", 5.5), ("edge_anisotropy", -1e9)):
        with pytest.raises(ValueError, match=f"latent.{field} must be within 5 px"):
            LatentParams(**{field: value})
    LatentParams(edge_sigma=5.0, edge_anisotropy=-5.0)
    with pytest.raises(ValueError, match="disparity_weight"):
        PathFitParams(disparity_weight=-1.0)
    with pytest.raises(ValueError, match="rotation.warm_hqs_steps"):
        BlindParams().replace(rotation={"warm_hqs_steps": -1})
    # a zero weight divided by zero mid-run (l0_floor=0: after the whole path stage); a floor above 1 grew it
    for bad in ({"l0_weight": 0.0}, {"l0_floor": 0.0}, {"l0_floor": 2.0}):
        with pytest.raises(ValueError, match=f"latent.{next(iter(bad))}"):
            BlindParams().replace(latent=bad)
    # a final in-plane solve cannot restore a path with p_z (estimated by default) or d_inf != 0: refused before
    # the path stage (it failed after it)
    inplane = BlindParams().replace(final={"method": "inplane"})
    for p, d_inf in ((inplane, 0.0), (inplane.replace(path={"estimate_z": False}), 0.5)):
        with pytest.raises(ValueError, match="final.method='inplane'"):
            iter_blind_deblur(good, params=p, infinity_disparity=d_inf)
    iter_blind_deblur(good, params=inplane.replace(path={"estimate_z": False})).close()
    # "no" is a true value: taken as given, it ran the check it was meant to switch off
    for flag in ("no", 0, None):
        with pytest.raises(TypeError, match="check_view_order must be True or False"):
            iter_blind_deblur(good, check_view_order=flag)


def test_a_light_field_on_another_scale_is_refused_not_returned_unchanged():
    """The salient-edge weight is on the [0, 1] scale: 8-bit values as floats would show it no edges."""
    lf = np.random.default_rng(0).random((3, 3, 8, 8)).astype(np.float32)
    with pytest.raises(ValueError, match=r"reaches 255: blind deblurring takes values in \[0, 1\].*255 for 8-bit"):
        iter_blind_deblur(np.where(lf > 0.5, 255.0, lf * 255).astype(np.float32))  # refused before any work
    with pytest.raises(ValueError, match=r"reaches 6\.55e\+04.*divide it by its white level \(65535 for uint16\)"):
        iter_blind_deblur((lf * 65535).astype(np.uint16))  # was told to divide by 255
    with pytest.raises(ValueError, match="reaches 2:"):  # 'values reaching 2' are refused
        iter_blind_deblur(np.where(lf > 0.5, 2.0, lf).astype(np.float32))
    lf[0, 0, 0, 0] = 1.2  # an overshoot of noise or a highlight is still on the [0, 1] scale
    iter_blind_deblur(lf).close()


def test_final_none_and_odd_inputs_report_what_happened(linear_case):
    _, cp, blurred = linear_case
    small = np.ascontiguousarray(blurred[:, :, :24, :24])
    quick = BlindParams().replace(path=dict(n_outer=1, steps=30, n_random=20, n_random_later=10), final={"n_iter": 3})
    # no final stage: the input comes back, and the result says that it was not restored
    res = blind_deblur(small, params=quick.replace(final=None, require_evidence=False), device="cpu")
    np.testing.assert_array_equal(res.lightfield, small)
    assert res.info["restoration"] == "none" and "final=None" in res.info["message"]
    assert np.abs(res.control_points).max() > 0  # the path estimated stands
    # a bool light field is data in {0, 1} (it failed inside numpy after the path stage)
    res = blind_deblur(small > 0.5, params=quick, device="cpu")
    assert res.lightfield.dtype == np.float32 and np.isfinite(res.lightfield).all()
    # a black one: no motion shows, so no agreement check runs, and the message says black
    res = blind_deblur(np.zeros_like(small), params=quick, device="cpu")
    assert res.info["evidence"]["reach"] == 0.0 and np.isnan(res.info["evidence"]["disagreement"])
    assert res.info["message"].endswith("The light field is black") and res.info["restoration"] == "none"
    # the evidence stage's records count from 1 and move (they stood at 0)
    its = [r.iteration for r in iter_blind_deblur(small, params=quick, device="cpu") if r.stage == "evidence"]
    assert its and min(its) >= 1 and its == sorted(its) and its[-1] > its[0]


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf"), 4.5, -4.01])
def test_infinity_disparity_must_be_finite_and_within_the_views(bad):
    good = np.zeros((5, 5, 16, 16), np.float32)  # bound: |d_inf| * 2 <= 16 / 2
    with pytest.raises(ValueError, match="infinity_disparity"):
        blind_deblur(good, infinity_disparity=bad)
    with pytest.raises(ValueError, match="infinity_disparity"):
        iter_blind_deblur(good, infinity_disparity=bad)  # checked when the generator is created


def test_infinity_disparity_of_the_wrong_type_or_auto():
    good = np.zeros((5, 5, 16, 16), np.float32)
    for bad in ("1.0", None, True, [1.0]):
        with pytest.raises(TypeError, match="infinity_disparity"):
            iter_blind_deblur(good, infinity_disparity=bad)
    with pytest.raises(ValueError, match="'auto' is not available.*farthest"):
        iter_blind_deblur(good, infinity_disparity="auto")
    assert blind.check_infinity_disparity(-4.0, good.shape) == -4.0  # the bound itself is allowed


# ------------------------------------------------------------ pieces


def _two_disparity_halves(Y, X, d_left, d_right, seed, smooth=0.0, V=5, pad=12):
    """A (V, V, Y, X, 1) light field: two textures seen at integer disparities ``d_left`` (left
    half) and ``d_right`` (right half) px/view, each view an exact shift of its texture."""
    tex = np.random.default_rng(seed).uniform(0, 1, (2, Y + 2 * pad, X + 2 * pad))
    if smooth > 0:
        tex = gaussian_filter(tex, (0, smooth, smooth))
    lf = np.empty((V, V, Y, X, 1), np.float32)
    for v in range(V):
        for u in range(V):
            dv, du = v - (V - 1) // 2, u - (V - 1) // 2
            left = tex[0, pad - d_left * dv : pad - d_left * dv + Y, pad - d_left * du : pad - d_left * du + X]
            right = tex[1, pad - d_right * dv : pad - d_right * dv + Y, pad - d_right * du : pad - d_right * du + X]
            lf[v, u, :, :, 0] = np.where(np.arange(X) < X // 2, left, right)
    return lf


def test_shear_resamples_each_view_bilinearly_at_its_refocused_coordinates():
    # reference: scipy's order-1 interpolation of each view on its own, edges replicated
    lf = np.random.default_rng(4).random((3, 5, 9, 11, 2))
    yy, xx = np.mgrid[0:9, 0:11].astype(np.float64)
    for d in (0.0, 0.4, -1.3, 7.0):  # at 7 px/view the outer views read far past the edges
        out = _disparity.shear(torch.as_tensor(lf), d).numpy()
        for v in range(3):
            for u in range(5):
                for c in range(2):
                    ref = map_coordinates(lf[v, u, :, :, c], [yy + d * (v - 1), xx + d * (u - 2)], order=1,
                                          mode="nearest")
                    np.testing.assert_allclose(out[v, u, :, :, c], ref, rtol=0, atol=1e-12)


def test_shear_spectral_is_shear_at_whole_shifts_and_shifts_exactly_between():
    lf = torch.as_tensor(np.random.default_rng(4).random((3, 5, 9, 11, 2)))
    for d in (0.0, 1.0, -2.0, 4.0):  # whole pixels in every view (past the edges at 4): shear's result exactly
        np.testing.assert_array_equal(_disparity.shear_spectral(lf, d).numpy(), _disparity.shear(lf, d).numpy())
    assert _disparity.shear_spectral(lf.float(), 0.5).dtype == torch.float32
    np.testing.assert_array_equal(_disparity.shear_spectral(lf, np.float32(0.5)).numpy(),
                                  _disparity.shear_spectral(lf, 0.5).numpy())  # a numpy scalar as a float
    # a pattern of periods 7 and 5 px, shifted by fractions of a pixel: the exact shift away from the edges
    # (where the mirrored extension bends it), where bilinear interpolation loses a third of the contrast
    Y, X, m = 64, 72, 16
    yy, xx = np.mgrid[0:Y, 0:X].astype(np.float64)

    def pattern(dy, dx):
        return np.sin(2 * np.pi * (yy + dy) / 7) * np.cos(2 * np.pi * (xx + dx) / 5)

    lf = torch.as_tensor(np.broadcast_to(pattern(0, 0)[None, None, :, :, None], (3, 5, Y, X, 1)).copy())
    for d in (0.5, -0.3, 1.7):
        truth = np.stack([np.stack([pattern(d * (v - 1), d * (u - 2)) for u in range(5)]) for v in range(3)])
        spectral = _disparity.shear_spectral(lf, d).numpy()[..., 0]
        bilinear = _disparity.shear(lf, d).numpy()[..., 0]
        assert np.abs(spectral - truth)[:, :, m:-m, m:-m].max() < 0.01
        assert np.abs(bilinear - truth)[:, :, m:-m, m:-m].max() > 0.1


def test_disparity_map_finds_the_disparity_of_each_half(engine):
    # left half: a noise texture at d = +1 px/view; right half: another at d = -2 (exact integer shifts)
    Y, X = 32, 48
    lf = _two_disparity_halves(Y, X, 1, -2, seed=0)
    # blurred by an in-plane path, the views stay consistent at the same disparity
    lf = simulate_blur(lf, linear_path(1.0), n_times=8)
    d = _disparity.disparity_map(torch.as_tensor(lf))
    assert d.shape == (Y, X)
    m = 2 * 2 + 2  # the smoothing window and the largest shift of a view
    np.testing.assert_allclose(d[m:-m, m : X // 2 - m], 1.0, atol=0.13)
    np.testing.assert_allclose(d[m:-m, X // 2 + m : -m], -2.0, atol=0.13)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_fused_view_variance_is_the_variance_of_the_refocused_views(dtype):
    from napari_lfdeblur import _fused

    if not _fused.available("cpu"):
        pytest.skip("numba is not installed")
    f = torch.as_tensor(np.random.default_rng(2).random((3, 5, 7, 9, 1)).astype(dtype))
    shears = [-2.3, -0.5, 0.0, 0.7, 4.0]  # 4 px/view reads far past the edges
    got = core_disparity._view_variances(f, shears)
    want = torch.stack([_disparity.shear(f, d).var(dim=(0, 1))[..., 0] for d in shears])
    assert got.dtype == f.dtype and got.shape == (5, 7, 9)
    torch.testing.assert_close(got, want, rtol=1e-5 if dtype == "float32" else 1e-12, atol=0)


def test_sparse_gradient_prior_matches_definition():
    L = torch.rand(3, 4, 5, 6, dtype=torch.float64)
    eps = 0.3
    ref = 0.0
    for axis in range(4):
        d = np.diff(L.numpy(), axis=axis)
        full = np.zeros(L.shape)
        sl = [slice(None)] * 4
        sl[axis] = slice(0, L.shape[axis] - 1)
        full[tuple(sl)] = d
        ref += np.minimum(full**2 / eps**2, 1).mean()
    assert float(sparse_gradient_prior(L, eps)) == pytest.approx(ref)


def test_gram_loss_plus_its_offset_equals_the_direct_fit():
    torch.manual_seed(1)
    f = torch.rand(5, 5, 20, 24, 1, dtype=torch.float64)
    lat = torch.rand(5, 5, 20, 24, 1, dtype=torch.float64)
    gl = _path_fit.GramLoss(f, 10**6, np.random.default_rng(0), 6, 1.4, 0.0, 1)
    gl.set_latent(lat)

    def direct(cp):
        b = BlurOperator(f.shape, cp, n_times=6, device="cpu", dtype=torch.float64).forward(lat)
        (by, bx), (fy, fx) = gradient_yx(b), gradient_yx(f)
        r = (by - fy)[:, :, gl.ys, gl.xs] ** 2 + (bx - fx)[:, :, gl.ys, gl.xs] ** 2
        return float(r.sum())

    cps = [np.array([[-0.6, 0.2, 0], [0.7, -0.4, 0], [0.1, 0.9, 0]]), linear_path(1.3, 20.0), linear_path(0.4, 100.0)]
    gram = [(float(gl(torch.tensor(c))) + gl.offset) / gl.scale for c in cps]
    ref = [direct(c) for c in cps]
    np.testing.assert_allclose(gram, ref, rtol=1e-8)


def test_gram_loss_with_robust_weights_equals_the_weighted_direct_fit():
    torch.manual_seed(2)
    f = torch.rand(5, 5, 16, 18, 1, dtype=torch.float64)
    lat = torch.rand(5, 5, 16, 18, 1, dtype=torch.float64)
    ref_cp = linear_path(1.0, 40.0)
    gl = _path_fit.GramLoss(f, 10**6, np.random.default_rng(0), 6, 1.4, 0.0, 1)
    gl.set_latent(lat, ref_cp, robust=0.5)

    def residuals(cp):
        b = BlurOperator(f.shape, cp, n_times=6, device="cpu", dtype=torch.float64).forward(lat)
        (by, bx), (fy, fx) = gradient_yx(b), gradient_yx(f)
        r = (by - fy)[:, :, gl.ys, gl.xs] ** 2 + (bx - fx)[:, :, gl.ys, gl.xs] ** 2
        return r.sum(dim=(0, 1, 3))  # per fitted pixel

    r0 = residuals(ref_cp)
    w = 1.0 / (1.0 + r0 / (0.5 * r0.median()))  # the documented weights, computed independently
    cps = [np.array([[-0.6, 0.2, 0], [0.7, -0.4, 0], [0.1, 0.9, 0]]), linear_path(1.3, 20.0), ref_cp]
    gram = [(float(gl(torch.tensor(c))) + gl.offset) / gl.scale for c in cps]
    ref = [float((w * residuals(c)).sum()) for c in cps]
    np.testing.assert_allclose(gram, ref, rtol=1e-8)


def test_edge_blurred_operator_is_adjoint_and_commutes():
    torch.manual_seed(3)
    shape = (4, 5, 12, 14, 1)
    op = BlurOperator(shape, linear_path(1.2, 30.0), n_times=5, device="cpu", dtype=torch.float64)
    A = _latent.EdgeBlurred(op, 0.6)
    x, y = torch.rand(shape, dtype=torch.float64), torch.rand(shape, dtype=torch.float64)
    assert float((A.forward(x) * y).sum()) == pytest.approx(float((x * A.adjoint(y)).sum()), rel=1e-10)
    # an in-plane blur acts over views, the Gaussian within views: away from the borders they commute
    a = A.forward(x)
    b = _latent.gauss_yx(op.forward(x), 0.6)
    np.testing.assert_allclose(a[:, :, 3:-3, 3:-3], b[:, :, 3:-3, 3:-3], atol=1e-12)
    # the Gaussian keeps constants away from the border
    one = _latent.gauss_yx(torch.ones(shape, dtype=torch.float64), 0.6)
    np.testing.assert_allclose(one[:, :, 3:-3, 3:-3], 1.0, atol=1e-12)


def test_warm_started_latent_takes_the_last_splitting_steps_and_keeps_a_converged_latent(engine):
    from napari_lfdeblur.samples import synthetic_scene

    lf, _ = synthetic_scene((3, 3, 24, 24), seed=2)
    cp = np.array([[-0.6, 0.2, 0.0], [0.1, -0.4, 0.0], [0.5, 0.2, 0.0]])
    g = torch.as_tensor(simulate_blur(lf, cp, n_times=16))[..., None]
    op = BlurOperator(tuple(g.shape), cp, n_times=16)
    p, lam = LatentParams(), 2e-4
    n_full = _latent.n_hqs_steps(lam, p)
    assert n_full > 4 and _latent.n_hqs_steps(lam, p, 4) == 4 and _latent.n_hqs_steps(lam, p, 99) == n_full

    def solve(x0, last=0):
        records = []
        x = run_to_completion(_latent.l0_latent(op, g, lam, p, x0, last), records.append)
        return x, len(records)

    full, n = solve(g.clone())
    assert n == n_full * (p.n_cg + 1)
    # more steps than the schedule has: the whole schedule, bit for bit
    np.testing.assert_array_equal(solve(g.clone(), 99)[0].numpy(), full.numpy())
    # from the converged latent, the last 4 steps stay by it; from the data, 4 steps do not get there
    warm, n = solve(full.clone(), 4)
    assert n == 4 * (p.n_cg + 1)
    cold, _ = solve(g.clone(), 4)
    assert float((warm - full).norm() / full.norm()) < 0.005 < float((cold - full).norm() / full.norm())


def test_path_fit_finds_the_true_curved_path_from_the_sharp_latent():
    # with the true sharp light field as the latent, the batch of random starts must find the
    # global minimum of the fit: the true path
    from napari_lfdeblur.metrics import path_error

    sharp = _scene((7, 7, 40, 40), seed=4)
    true = np.array([[-0.9, 0.3, 0.0], [0.6, 1.1, 0.0], [0.8, -0.9, 0.0], [-0.4, -0.2, 0.0]])
    true = center_path(true, 64)
    blurred = simulate_blur(sharp, true, n_times=64)
    p = BlindParams()
    f = torch.as_tensor(blurred)[..., None]
    lat = torch.as_tensor(sharp)[..., None]
    rng = np.random.default_rng(0)
    box = 0.35 * 6
    gl = _path_fit.GramLoss(f, p.path.n_pixels, rng, p.n_times, box, 0.0, 1)
    gl.set_latent(lat)
    starts = rng.uniform(-1.0, 1.0, size=(p.path.n_random, 4, 3)) * p.path.init_length
    starts[..., 2] = 0.0
    pp = _path_fit.PathParam(starts, p.n_times, box, "cpu", free_z=False)
    pp.project()
    reports = []
    scores = run_to_completion(_path_fit.fit_path(pp, gl, p.path.steps, p.path.lr), reports.append).numpy()
    n_reports = len(reports)
    assert n_reports >= 3  # the fit runs on while its best path improves (it used to stop after ~10 steps)
    best = pp.numpy()[int(np.argmin(scores))]
    assert path_error(best, true, lightfield=sharp).blur_mismatch < 0.1


# ------------------------------------------------------------ memory


def test_memory_estimate_grows_with_size():
    small = blind.estimate_blind_memory((5, 5, 32, 32, 3))
    big = blind.estimate_blind_memory((9, 9, 376, 541, 3))
    assert 0 < small < big
    # at least the colour input, output and a few work copies
    assert big > 9 * 9 * 376 * 541 * 3 * 4 * 5
    # without a final stage (final=None) the path stage is the peak: no tiles are planned for a stage that
    # does not run (it warned 'restoring the light field in tiles', and restored nothing)
    shape, path_only = (9, 9, 376, 541, 3), BlindParams().replace(final=None)
    assert blind.estimate_blind_memory(shape, path_only) == _memory._memory_of_stages(shape, path_only)[1] < big
    assert _memory.plan_tiles(shape, path_only, blind.estimate_blind_memory(shape, path_only)) is None


def test_plan_run_tiles_on_the_gpu_or_falls_back_to_the_cpu():
    shape = (9, 9, 600, 800, 3)
    p = BlindParams()
    gpu, cpu = torch.device("cuda"), torch.device("cpu")
    whole = blind.estimate_blind_memory(shape, p)
    path_stage = _memory._memory_of_stages(shape, p)[1]
    assert path_stage < whole
    # enough, or unknown: as asked, whole
    assert _memory.plan_run(shape, p, gpu, lambda d: whole) == (gpu, None)
    assert _memory.plan_run(shape, p, gpu, lambda d: None) == (gpu, None)
    # the path stage fits on the GPU but the whole does not: the GPU restores in tiles, whose results go to the
    # host; a CPU with as much memory also holds the result
    free = (path_stage + whole) // 2
    dev, tile = _memory.plan_run(shape, p, gpu, lambda d: free)
    assert dev == gpu and tile is not None and tile[0] < 600
    assert _memory._tile_memory(shape, p, tile) <= free
    result = 4 * 9 * 9 * 600 * 800 * 3
    dev, cpu_tile = _memory.plan_run(shape, p, cpu, lambda d: free)
    assert dev == cpu and _memory._tile_memory(shape, p, cpu_tile) + result <= free
    assert cpu_tile[0] <= tile[0] and cpu_tile[1] <= tile[1]
    # the GPU cannot hold the path stage: the run goes to the CPU, tiled by the CPU's memory
    host = {"cuda": path_stage // 2, "cpu": whole // 3}
    dev, tile = _memory.plan_run(shape, p, gpu, lambda d: host[d.type])
    assert dev == cpu and tile == _memory.plan_tiles(shape, p, whole // 3)
    assert _memory.plan_run(shape, p, gpu, lambda d: {"cuda": path_stage // 2, "cpu": None}[d.type]) == (cpu, None)


def test_blind_deblur_says_where_it_runs_when_memory_is_short(monkeypatch):
    blurred = np.random.default_rng(0).random((3, 3, 16, 16), dtype=np.float32)
    monkeypatch.setattr(devices, "select_device", lambda device: torch.device("cuda"))
    monkeypatch.setattr(devices, "free_memory", lambda device: {"cuda": 1024, "cpu": None}[device.type])
    monkeypatch.setattr(blind, "_run", lambda arr, d_inf, p, dev, seed, tile, windows: iter([dev]))
    with pytest.warns(RuntimeWarning, match="running on the CPU instead"):
        gen = iter_blind_deblur(blurred)
    assert next(gen) == torch.device("cpu")


def test_plan_tiles_fits_the_budget():
    shape = (9, 9, 600, 800, 3)
    p = BlindParams()
    assert _memory.plan_tiles(shape, p, None) is None
    assert _memory.plan_tiles(shape, p, blind.estimate_blind_memory(shape, p)) is None
    free = blind.estimate_blind_memory(shape, p) // 3
    ty, tx = _memory.plan_tiles(shape, p, free)
    assert _memory.MIN_TILE <= ty < 600 and _memory.MIN_TILE <= tx < 800
    m = _memory.TILE_MARGIN
    result = 4 * 9 * 9 * 600 * 800 * 3
    assert blind.estimate_blind_memory((9, 9, ty + 2 * m, tx + 2 * m, 3), p) + result <= free
    # not much smaller than needed: 1.25 times the side would not fit
    big = int(ty * 1.25)
    assert blind.estimate_blind_memory((9, 9, big + 2 * m, big + 2 * m, 3), p) + result > free
    # the tiles cover the image exactly once, each inside its padded window
    cover = np.zeros((600, 800), int)
    for core, pad in _memory.tiles(600, 800, (ty, tx), m):
        cover[core] += 1
        assert pad[0].start <= core[0].start and pad[0].stop >= core[0].stop
        assert pad[1].start <= core[1].start and pad[1].stop >= core[1].stop
    assert (cover == 1).all()


def test_a_memory_warning_names_the_callers_line_and_does_not_claim_tiles_a_small_view_cannot_have():
    import warnings

    b = np.random.default_rng(0).random((3, 3, 24, 20)).astype(np.float32)
    p = BlindParams.preset("default").replace(path={"n_outer": 1}, final={"n_iter": 2})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        blind_deblur(b, params=p, max_memory=1e5, device="cpu")
        line = sys._getframe().f_lineno - 1
        iter_blind_deblur(b, params=p, max_memory=1e5, device="cpu").close()
    said = [w for w in caught if "more than max_memory" in str(w.message)]
    assert [(w.filename, w.lineno) for w in said] == [(__file__, line), (__file__, line + 2)]  # not the library's
    for w in said:  # 24x20 views are one tile (it said 'tiles of 24x20', 'on 128x128 windows')
        assert "in one piece all the same" in str(w.message) and "on the whole view" in str(w.message)
        # and a cap that no plan can keep is said to be exceeded (the warning let one think tiles would keep it)
        assert "and will exceed max_memory" in str(w.message)


def test_short_memory_runs_in_overlapping_tiles(monkeypatch):
    from napari_lfdeblur.deconvolution import deconvolve

    sharp = _scene((5, 5, 72, 72), seed=6)
    cp = np.array([[-0.6, 0.2, -0.3], [0.5, -0.3, 0.3]])
    blurred = simulate_blur(sharp, cp, n_times=32)
    p = BlindParams().replace(n_control_points=2, path=dict(n_outer=2, steps=60, region=40), final={"n_iter": 20, "tol": 0.0},
                              final_n_times=8)
    full = blind.estimate_blind_memory(blurred.shape, p)
    monkeypatch.setattr(devices, "free_memory", lambda device: full // 2)
    releases = []
    monkeypatch.setattr(blind, "release_host_memory", lambda: releases.append(1))
    with pytest.warns(RuntimeWarning, match="overlapping tiles"):
        gen = with_previews(iter_blind_deblur(blurred, params=p, device="cpu"), 5)
    stages, previews = set(), []

    def collect(rec):
        stages.add(rec.stage)
        if rec.stage.startswith("path") and rec.preview is not None:
            previews.append(rec.preview)

    res = run_to_completion(gen, collect)
    assert res.info["tile"][0] < 72 and any(s.startswith("final (tile 2/") for s in stages)
    n_tiles = int(next(s for s in stages if s.startswith("final (tile ")).split("/")[1].rstrip(")"))
    assert len(releases) == n_tiles + 1  # freed memory handed back after the noise estimate and after each tile
    # the path-stage previews show the path's window where it is in the full frame, edge-padded around it
    y0, x0, h, w = res.info["window"]
    assert (h, w) == (40, 40) and previews
    for prev in previews:
        np.testing.assert_array_equal(prev[:, :, :y0], np.repeat(prev[:, :, y0:y0 + 1], y0, axis=2))
        np.testing.assert_array_equal(prev[:, :, y0 + h:], np.repeat(prev[:, :, y0 + h - 1:y0 + h], 72 - y0 - h, axis=2))
        np.testing.assert_array_equal(prev[:, :, :, :x0], np.repeat(prev[:, :, :, x0:x0 + 1], x0, axis=3))
        assert np.ptp(prev[:, :, y0:y0 + h, x0:x0 + w], axis=(2, 3)).min() > 0  # the window itself is not padding
    assert res.lightfield.shape == blurred.shape and np.isfinite(res.lightfield).all()
    # the tiles, with their overlap, give nearly what one full-frame solve with that path gives
    ref = deconvolve(blurred, res.control_points, n_times=8, method="tv", n_iter=20, tol=0.0, device="cpu")
    assert np.abs(res.lightfield - ref).max() < 2e-3


@pytest.mark.parametrize("d_inf", [2.0, -2.0])
def test_tiles_at_a_nonzero_infinity_disparity_meet_without_seams(d_inf):
    # d_inf moves the blur's samples across pixels: the tiles' overlap must grow with it, or their edges show
    # (the final stage in 24-px tiles of 72x72 views against one full-frame solve with the same path and weight)
    cp = np.array([[-1.0, 0.4, 0.0], [1.0, -0.4, 0.0]])
    sharp = _scene((5, 5, 72, 72), seed=6, disparities=(2.0 + d_inf, -1.5 + d_inf))
    blurred = simulate_blur(sharp, cp, n_times=8, infinity_disparity=d_inf)
    p = BlindParams().replace(final={"n_iter": 100, "tol": 0.0, "weight": 0.004}, final_n_times=8)
    ref = deconvolve(blurred, cp, n_times=8, infinity_disparity=d_inf, params=p.final, device="cpu")
    info = {}
    out = run_to_completion(blind._iter_final(blurred, cp, d_inf, p, torch.device("cpu"), (24, 24), 1, info))
    assert info["final_weight"] == 0.004
    # what the tiles leave is below what 24-px tiles leave at d_inf = 0 with this path (1.2e-3) times 5
    assert np.abs(out - ref).max() < 6e-3


def test_tiles_at_a_nonzero_infinity_disparity_stay_within_the_plan(monkeypatch):
    # the plan budgets each tile with 12 px of overlap; d_inf's wider overlap (here 12 + 3 * ceil(2 * 1.4) = 21
    # px) comes out of the tile, so that no tile with its overlap is larger than the plan's 64 + 2 * 12 px
    import napari_lfdeblur.deconvolution as deconvolution

    sizes, solve = [], deconvolution.iter_deconvolve

    def recording(arr, *args, **kwargs):
        sizes.append(arr.shape[2:4])
        return solve(arr, *args, **kwargs)

    monkeypatch.setattr(deconvolution, "iter_deconvolve", recording)
    cp = np.array([[-1.0, 0.4, 0.0], [1.0, -0.4, 0.0]])
    blurred = simulate_blur(_scene((3, 3, 150, 150), seed=6), cp, n_times=8, infinity_disparity=2.0)
    p = BlindParams().replace(final={"n_iter": 2, "weight": 0.004}, final_n_times=8)
    info = {}
    run_to_completion(blind._iter_final(blurred, cp, 2.0, p, torch.device("cpu"), (64, 64), 1, info))
    assert info["tile"] == (46, 46) and len(sizes) == 16  # 150 px in cores of 46 px: 4 x 4 tiles
    assert max(max(s) for s in sizes) == 64 + 24 and min(min(s) for s in sizes) == 12 + 21  # the last core is 12 px
    run_to_completion(blind._iter_final(blurred, cp, 0.0, p, torch.device("cpu"), (64, 64), 1, info))
    assert info["tile"] == (64, 64)  # at d_inf = 0 the plan's overlap is the overlap


def test_max_memory_bounds_the_run_by_tiles_and_is_checked(monkeypatch):
    sharp = _scene((5, 5, 160, 160), seed=6)
    blurred = simulate_blur(sharp, np.array([[-0.6, 0.2, 0.0], [0.5, -0.3, 0.0]]), n_times=16)
    p = BlindParams().replace(n_control_points=2, require_evidence=False, path=dict(n_outer=1, steps=20, region=32),
                              final={"n_iter": 5}, final_n_times=4)
    full = blind.estimate_blind_memory(blurred.shape, p)
    monkeypatch.setattr(devices, "free_memory", lambda device: 10 * full)  # plenty free: max_memory decides
    with pytest.warns(RuntimeWarning, match="more than max_memory"):
        res = blind_deblur(blurred, params=p, device="cpu", max_memory=full * 0.75)
    tile = res.info["tile"]
    assert _memory.MIN_TILE < tile[0] < 160 and tile == _memory.plan_tiles(blurred.shape, p, int(full * 0.75))
    for bad, error in ((0, ValueError), (0.5, ValueError), (-1e9, ValueError), (float("nan"), ValueError), ("4G", TypeError),
                       (True, TypeError)):
        with pytest.raises(error, match="max_memory"):
            blind_deblur(blurred, params=p, device="cpu", max_memory=bad)


def test_out_of_memory_mid_run_falls_back_and_releases(monkeypatch):
    released = []
    devices_run = []

    class Buffer:  # stands for a GPU tensor of the failed run
        pass

    gpu_buffers = []

    def fake_run(dev):
        devices_run.append(dev.type)
        yield "progress"
        if dev.type == "cuda":
            buf = Buffer()
            gpu_buffers.append(weakref.ref(buf))
            raise torch.cuda.OutOfMemoryError("CUDA out of memory. Tried to allocate 2 GiB")
        # the failed run's frame (and its tensors) is gone before the CPU run starts
        assert gpu_buffers[0]() is None
        return "done on cpu"

    monkeypatch.setattr(devices, "empty_cache", lambda dev: released.append(dev.type))
    gen = devices.run_with_cpu_fallback(fake_run, torch.device("cuda"))
    with pytest.warns(RuntimeWarning, match="out of memory"):
        out = run_to_completion(gen)
    assert out == "done on cpu"
    assert devices_run == ["cuda", "cpu"]
    assert "cuda" in released  # memory released after the failure (and in the finally)


# ------------------------------------------------------------ CLI


def test_cli_deblur_on_a_tiny_npz(tmp_path, capsys, monkeypatch):
    from napari_lfdeblur.cli import main
    from napari_lfdeblur.path import load_path_json

    lf = _scene((5, 5, 16, 16), seed=6)
    blurred = simulate_blur(lf, linear_path(1.5), n_times=8)
    src = tmp_path / "blurred.npz"
    np.savez(src, lightfield=blurred)
    params = tmp_path / "p.json"
    params.write_text(BlindParams().replace(path=dict(n_outer=1, steps=10, n_restarts=1), final={"n_iter": 2}).to_json())
    out = tmp_path / "sharp.npz"
    assert main(["deblur", str(src), str(out), "--params", str(params), "--device", "cpu"]) == 0
    assert out.exists()
    assert "blur found" in capsys.readouterr().out  # the verdict of the evidence test is printed
    cp = load_path_json(tmp_path / "sharp.path.json")
    assert cp.shape[1] == 3
    # the API's result, with the final stage's weight in the file's metadata
    from napari_lfdeblur.io import read_lightfield_with_metadata

    res = blind_deblur(blurred, params=BlindParams.from_json(params.read_text()), device="cpu", seed=0)
    got, meta = read_lightfield_with_metadata(out)
    np.testing.assert_allclose(got, res.lightfield, atol=1e-6)
    np.testing.assert_allclose(cp, res.control_points, atol=1e-9)
    assert meta["saved_metadata"]["final_weight"] == res.info.get("final_weight")
    # existing output without --overwrite: a one-line error, status 2
    assert main(["deblur", str(src), str(out), "--params", str(params)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["deblur", str(tmp_path / "missing.npz"), str(tmp_path / "o.npz")]) == 2
    assert main(["deblur", str(src), str(tmp_path / "o2.npz"), "--preset", "nope"]) == 2
    # --edge-anisotropy overrides the parameter file's value and nothing else
    seen = []
    real = blind.iter_blind_deblur

    def spy(*args, params=None, **kwargs):
        seen.append(params)
        return real(*args, params=params, **kwargs)

    monkeypatch.setattr(blind, "iter_blind_deblur", spy)
    out3 = tmp_path / "sharp3.npz"
    assert main(["deblur", str(src), str(out3), "--params", str(params), "--edge-anisotropy", "0.6",
                 "--device", "cpu"]) == 0
    assert seen[-1] == BlindParams.from_json(params.read_text()).replace(latent={"edge_anisotropy": 0.6})
    assert main(["deblur", str(src), str(tmp_path / "o4.npz"), "--edge-anisotropy", "nan"]) == 2
    assert "edge_anisotropy" in capsys.readouterr().err
    # --window: where the path is estimated, recorded with the result; a bad one is a one-line error
    seen_windows = []
    monkeypatch.setattr(blind, "iter_blind_deblur", lambda *a, windows=None, **k: (seen_windows.append(windows),
                                                                                   real(*a, windows=windows, **k))[1])
    assert main(["deblur", str(src), str(tmp_path / "w.npz"), "--params", str(params), "--device", "cpu",
                 "--window", "0,0,16,16"]) == 0
    assert seen_windows[-1] == [(0, 0, 16, 16)]
    assert read_lightfield_with_metadata(tmp_path / "w.npz")[1]["saved_metadata"]["path_windows"] == [[0, 0, 16, 16]]
    with pytest.raises(SystemExit):  # argparse's one line
        main(["deblur", str(src), str(tmp_path / "o5.npz"), "--window", "0,0,12"])
    assert "expected Y0,X0,HEIGHT,WIDTH" in capsys.readouterr().err
    assert main(["deblur", str(src), str(tmp_path / "o5.npz"), "--window", "8,0,16,16"]) == 2
    assert "reaches outside the 16 x 16 views" in capsys.readouterr().err and not (tmp_path / "o5.npz").exists()


def test_windows_name_where_the_path_is_estimated():
    """Two halves blurred by different motions (as a subject that moved by itself): the path follows the window."""
    sharp = _scene((7, 7, 40, 80))
    paths = linear_path(2.0, angle_deg=0.0), linear_path(2.0, angle_deg=90.0)
    halves = np.where(np.arange(80) < 40, *(simulate_blur(sharp, cp, n_times=32) for cp in paths))
    blurred = np.clip(halves + np.random.default_rng(1).normal(0, 0.002, sharp.shape), 0, 1).astype(np.float32)
    p = BlindParams().replace(n_control_points=2, require_evidence=False, final=None, path=FAST["path"])
    for window, cp in zip(([(0, 0, 40, 40)], [(0, 40, 40, 40)]), paths):
        res = blind_deblur(blurred, params=p, device="cpu", windows=window)
        assert res.info["windows"] == window
        est, true = _positions(res.control_points), _positions(cp)
        d_est, d_true = est[-1, :2] - est[0, :2], true[-1, :2] - true[0, :2]
        cos = abs(d_est @ d_true) / (np.linalg.norm(d_est) * np.linalg.norm(d_true))
        assert cos > np.cos(np.radians(20))  # that half's motion
        # and its extent: the blur of the estimate on the sharp light field is near that of that half's path
        # (measured: 0.27 and 0.16; 1 would be no blur, and the other half's path scores over 1)
        assert path_error(res.control_points, cp, lightfield=sharp).blur_mismatch < 0.45
    # windows the solver cannot take: clear errors before any work
    for bad, said in (([], "non-empty"), ([(0, 0, 40)], "non-empty list of"), ([(0, 0, 40.5, 40)], "whole numbers"), ((0, 0, 40, 40), "a list of"),
                      ([(0, 0, 8, 40)], "smaller than 16 x 16"), ([(0, 50, 40, 40)], "reaches outside the 40 x 80"),
                      ([(-1, 0, 30, 30)], "reaches outside"), ([(0, 0, 40, 40)] * 2, "overlap"),
                      ([(0, 0, 40, 40), (0, 20, 40, 40)], "overlap")):
        with pytest.raises(ValueError, match=said):
            blind_deblur(blurred, params=p, device="cpu", windows=bad)
    with pytest.raises(ValueError, match="one window"):
        blind_deblur(blurred, params=p.replace(motion="6dof"), windows=[(0, 0, 40, 40), (0, 40, 40, 40)])


def test_solvers_never_leave_the_caller_without_grad(linear_case):
    # a widget's worker thread runs the generators; a suspended (or abandoned) generator must not leave
    # the thread in no_grad mode, and a run must work whatever the caller's mode
    from napari_lfdeblur.deconvolution import iter_deconvolve

    _, cp, blurred = linear_case
    small = blurred[:, :, :16, :16]
    gen = iter_deconvolve(small, cp, method="tv", n_iter=5, device="cpu")
    next(gen)
    assert torch.is_grad_enabled()
    gen = iter_blind_deblur(small, params=BlindParams().replace(path=dict(n_outer=1, steps=20), final={"n_iter": 3}), device="cpu")
    for _ in range(40):
        next(gen)
        assert torch.is_grad_enabled()
    gen.close()
    with torch.no_grad():
        res = blind_deblur(small, params=BlindParams().replace(path=dict(n_outer=1, steps=20), final={"n_iter": 2}), device="cpu")
    assert np.isfinite(res.control_points).all()


def test_disparity_weights_of_a_large_view_come_from_a_downsampled_map(monkeypatch):
    # a light field whose left half has twice the disparity of the right half: the weights
    # (|d| / max|d| + floor) ** power say so whether the map is estimated at full resolution
    # or, for large views, at a lower one
    Y, X = 24, 40
    # smooth texture: on raw noise, bilinear shifts bias the least-variance match at fractional disparities
    f = torch.as_tensor(_two_disparity_halves(Y, X, 2, 1, seed=1, smooth=1.5))
    full = _disparity.disparity_weights(f, 1.0)
    monkeypatch.setattr(_disparity, "DISPARITY_PIXELS", Y * X // 4)  # -> estimated at half resolution
    half = _disparity.disparity_weights(f, 1.0)
    assert full.shape == half.shape == (Y, X)
    floor = _disparity.DISPARITY_FLOOR
    for w in (full, half):
        # power 1: w - floor is |d| / max|d|, so the two halves' ratio is that of their disparities
        left = np.median(w[6:-6, 6 : X // 2 - 6]) - floor
        right = np.median(w[6:-6, X // 2 + 6 : -6]) - floor
        assert left / right == pytest.approx(2.0, rel=0.08)


def test_edge_model_starts_at_edge_sigma_from_and_runs_two_alternations_before_stopping(monkeypatch):
    lf = _scene((5, 5, 20, 20), seed=4)
    blurred = simulate_blur(lf, linear_path(1.5), n_times=8)
    built = []

    class Recording(_latent.EdgeBlurred):
        def __init__(self, op, sigma):
            built.append(sigma)
            super().__init__(op, sigma)

    monkeypatch.setattr(_alternating, "EdgeBlurred", Recording)
    base = BlindParams().replace(path=dict(steps=20, n_random=10, n_random_later=5, estimate_z=False), final=None,
                                 latent=dict(edge_sigma=0.5, edge_sigma_from=3))

    def alternations(latent=None, **path):
        built.clear()
        gen = iter_blind_deblur(blurred, device="cpu", params=base, path=path, latent=latent or {})
        return max(r.info["alternation"] for r in gen if r.info.get("phase") == "done")

    # never still: all 6 alternations, the edge model in alternations 3..6 only
    assert alternations(n_outer=6, tol=0.0) == 6 and built == [(0.5, 0.5)] * 4
    # always still: moves count as still only after alternation 3, so the level stops after 5
    # (two still alternations after the switch), the edge model having run in 3, 4 and 5
    assert alternations(n_outer=9, tol=1e9) == 5 and built == [(0.5, 0.5)] * 3
    # edge_sigma = 0: no edge model at all
    assert alternations(n_outer=4, tol=0.0, latent={"edge_sigma": 0.0}) == 4 and built == []
    # edge_anisotropy splits the same mean square width between the axes, x the softer
    assert alternations(n_outer=4, tol=0.0, latent={"edge_anisotropy": 0.6}) == 4 and len(built) == 2
    sy, sx = built[0]
    assert (sy**2 + sx**2) / 2 == pytest.approx(0.25) and sx**2 - sy**2 == pytest.approx(0.36)


def test_anisotropic_edge_gaussian_has_the_widths_asked_and_is_self_adjoint():
    shape = (2, 2, 41, 41, 1)
    delta = torch.zeros(shape, dtype=torch.float64)
    delta[:, :, 20, 20] = 1.0
    g = _latent.gauss_yx(delta, (1.0, 2.0))[0, 0, :, :, 0].numpy()
    r = np.arange(41) - 20.0
    assert g.sum() == pytest.approx(1.0)
    # second moments of the kernel along y and x (sampled at whole pixels and cut at 3 sigma,
    # so a little below sigma^2)
    assert (g.sum(axis=1) * r**2).sum() == pytest.approx(1.0, rel=0.05)
    assert (g.sum(axis=0) * r**2).sum() == pytest.approx(4.0, rel=0.05)
    # one axis without blur leaves it untouched; a single sigma is the same on both axes
    only_x = _latent.gauss_yx(delta, (0.0, 1.1))[0, 0, :, :, 0].numpy()
    assert np.count_nonzero(only_x.sum(axis=1)) == 1
    np.testing.assert_array_equal(_latent.gauss_yx(delta, 0.7), _latent.gauss_yx(delta, (0.7, 0.7)))
    x, y = torch.rand(shape, dtype=torch.float64), torch.rand(shape, dtype=torch.float64)
    lhs = float((_latent.gauss_yx(x, (0.4, 1.1)) * y).sum())
    assert lhs == pytest.approx(float((x * _latent.gauss_yx(y, (0.4, 1.1))).sum()), rel=1e-12)


# ------------------------------------------------------------ optimiser


def test_adam_takes_the_steps_of_torch_optim_adam():
    from napari_lfdeblur.blind._adam import Adam

    rng = np.random.default_rng(5)
    target = torch.from_numpy(rng.standard_normal((4, 3)))
    start_a, start_b = torch.from_numpy(rng.standard_normal((4, 3))), torch.from_numpy(rng.standard_normal(7))

    def run(make):
        a, b = start_a.clone().requires_grad_(True), start_b.clone().requires_grad_(True)
        opt = make([{"params": [a], "lr": 0.05}, {"params": [b]}])
        for _ in range(25):
            opt.zero_grad()
            (((a - target) ** 4).sum() + (b**2).sum()).backward()
            opt.step()
        return a.detach(), b.detach()

    mine = run(lambda groups: Adam(groups, lr=0.2))
    theirs = run(lambda groups: torch.optim.Adam(groups, lr=0.2))
    for m, t in zip(mine, theirs):
        torch.testing.assert_close(m, t, rtol=0, atol=0)  # the same arithmetic, step by step
    assert not torch.equal(mine[0], start_a)  # it moved


def test_transposed_views_are_warned_about_before_any_work(recwarn):
    from _reference import moving_texture

    from napari_lfdeblur.epi import ViewOrderWarning

    lf = moving_texture(n_views=5, d=1.5, size=32)  # u moves the image along x by 1.5 px/view, v along y

    def view_order_warnings():
        return [w for w in recwarn if issubclass(w.category, ViewOrderWarning)]

    iter_blind_deblur(lf, device="cpu").close()
    assert not view_order_warnings()
    iter_blind_deblur(lf.swapaxes(0, 1), device="cpu").close()  # checked when the generator is made
    (w,) = view_order_warnings()
    assert str(w.message).startswith("the blurred light field: the views look transposed")
    assert "swapaxes(0, 1)" in str(w.message) and w.filename == __file__  # names the caller's line
    np.testing.assert_allclose(w.message.shifts, [[0.0, 1.5], [1.5, 0.0]], atol=0.05)
    recwarn.clear()
    iter_blind_deblur(lf.swapaxes(0, 1), device="cpu", check_view_order=False).close()
    assert not view_order_warnings()


def test_blind_deblur_leaves_the_global_random_generators_alone(linear_case):
    _, _, blurred = linear_case
    torch.manual_seed(123)
    np.random.seed(5)
    torch_state, numpy_state = torch.get_rng_state(), np.random.get_state()
    p = BlindParams().replace(n_control_points=2, **FAST).replace(final=None)
    blind_deblur(blurred, params=p, device="cpu", seed=3)
    assert torch.equal(torch.get_rng_state(), torch_state)  # not reseeded with the solver's seed
    assert all(np.array_equal(a, b) for a, b in zip(np.random.get_state(), numpy_state))


def test_joint_and_final_settings_are_checked_and_named():
    with pytest.raises(ValueError, match="BlindParams.joint.n_iter must be >= 1"):  # 0 would return the random start
        BlindParams().replace(joint={"n_iter": 0})
    with pytest.raises(ValueError, match="prior_floor is a fraction of the start, at most 1"):
        BlindParams().replace(joint={"prior_floor": 5.0})
    with pytest.raises(ValueError, match="eps_min must not exceed eps"):
        BlindParams().replace(joint={"eps": 0.1, "eps_min": 0.2})
    # the final stage's errors say that they are the final stage's (not joint's n_iter, say)
    with pytest.raises(ValueError, match=r"^BlindParams\.final: n_iter must be >= 1"):
        BlindParams().replace(final={"n_iter": 0})
    with pytest.raises(ValueError, match=r"^BlindParams\.final: n_iter must be >= 1"):
        BlindParams.from_dict({"final": {"n_iter": 0}})


# ------------------------------------------------------------ parameters, gauge and the small helpers


def test_a_curved_path_is_returned_in_the_zero_mean_gauge_of_n_times_not_of_final_n_times():
    # BlindResult: the control points are in the zero-mean gauge for params.n_times; with 3 control points the
    # gauges of 16 and of 3 instants differ, so the result must be centred for the 16
    lf, _ = synthetic_scene((3, 3, 24, 24), seed=0)
    b = simulate_blur(lf, np.array([[-0.8, 0.3, 0.0], [0.2, -0.6, 0.0], [0.7, 0.5, 0.0]]), n_times=32)
    p = BlindParams().replace(n_control_points=3, n_times=16, final_n_times=3, require_evidence=False, final=None,
                              path=dict(n_outer=1, steps=20, n_random=10, n_random_later=5, n_restarts=1,
                                        estimate_z=False))
    res = blind_deblur(b, params=p, device="cpu")
    cp = res.control_points
    assert cp.shape == (3, 3) and np.abs(cp[:, :2]).max() > 0.05  # a path, not the zero path
    # the mean of the Bezier curve at t_k = k / 15, written out: B(t) = (1-t)^2 P0 + 2 t (1-t) P1 + t^2 P2
    t = np.linspace(0, 1, 16)[:, None]
    curve = (1 - t) ** 2 * cp[0] + 2 * t * (1 - t) * cp[1] + t**2 * cp[2]
    np.testing.assert_allclose(curve.mean(0), 0, atol=1e-9)


def test_path_fit_settings_refuse_a_region_below_min_size_and_no_windows():
    # PathFitParams: region is 0 or at least min_size; n_regions at least 1
    with pytest.raises(ValueError, match="region"):
        PathFitParams(region=10)
    assert PathFitParams(region=0).region == 0 and PathFitParams(region=24).region == 24
    with pytest.raises(ValueError, match="n_regions"):
        PathFitParams(n_regions=0)


def test_the_default_path_box_is_a_fraction_of_the_smaller_aperture_side():
    # docs/blind.md, "Gauge and range": max_extent 0 means 0.35 (min(V, U) - 1) views, at least 0.5
    p = BlindParams()
    assert p.path_box(7, 7) == pytest.approx(0.35 * 6)
    assert p.path_box(5, 9) == pytest.approx(0.35 * 4)
    assert p.path_box(2, 2) == 0.5
    assert BlindParams(max_extent=1.25).path_box(7, 7) == 1.25


def test_pyramid_factors_skip_levels_below_min_size_and_above_max_size():
    # PathFitParams: n_levels levels, halving; levels smaller than min_size skipped; max_size the largest size
    # (smaller side) used, finer levels skipped
    def factors(Y, X, **path):
        return _alternating.pyramid_factors(Y, X, BlindParams().replace(path=path))

    assert factors(96, 96, n_levels=3, min_size=24) == [4, 2, 1]  # 24, 48, 96 px
    assert factors(96, 96, n_levels=3, min_size=40) == [2, 1]  # 24 px is below min_size
    assert factors(128, 128, max_size=32) == [4]  # 128 / 4 = 32 px
    assert factors(128, 200, n_levels=2, max_size=64) == [4, 2]  # 32 and 64 px on the smaller side
    assert factors(64, 64) == [1]


def test_a_small_relative_gain_alone_keeps_the_blur_from_being_found(monkeypatch):
    # _evidence: the blur is found only when E_none - E_blur > EVIDENCE_MARGIN sigma^2, the relative gain exceeds
    # RELATIVE_MARGIN (6 %, docs/blind.md) and the reach is at least MIN_REACH; here only the relative gain fails
    sigma = 0.01

    def objectives(e_none, e_blur):
        def fake(op, g, lam, p):
            return (e_none if isinstance(op, _evidence.Identity) else e_blur), 0.0
            yield

        return fake

    monkeypatch.setattr(_evidence, "noise_sigma", lambda g: sigma)
    monkeypatch.setattr(_evidence, "blur_reach", lambda *a, **k: 2.0)
    g = torch.zeros((3, 3, 16, 16, 1))
    gain = 10 * sigma**2
    for relative, found in ((0.03, False), (0.12, True)):
        monkeypatch.setattr(_evidence, "_objective", objectives(gain / relative, gain / relative - gain))
        ev = run_to_completion(_evidence.blur_evidence(g, linear_path(1.0), BlindParams(), torch.device("cpu")))
        assert ev["gain"] == pytest.approx(10) and ev["relative"] == pytest.approx(relative)
        assert ev["blur_found"] is found
        if not found:
            assert "%" in _evidence.evidence_message(ev)


def test_blur_reach_of_a_downsampled_large_view_is_in_full_resolution_px():
    # blur_reach: path extent (views) times the 95th percentile disparity (px/view) of the full-resolution view;
    # a plane at 2 px/view and a 1-view path: 2 px, also on a view large enough to be measured downsampled
    def halves(Y, d=2, V=5, pad=12):
        tex = gaussian_filter(np.random.default_rng(0).uniform(0, 1, (Y + 2 * pad, Y + 2 * pad)), 1.5)
        lf = np.empty((V, V, Y, Y, 1), np.float32)
        for v in range(V):
            for u in range(V):
                dv, du = v - (V - 1) // 2, u - (V - 1) // 2
                lf[v, u, :, :, 0] = tex[pad - d * dv : pad - d * dv + Y, pad - d * du : pad - d * du + Y]
        return torch.as_tensor(lf)

    for Y in (32, 340):  # 340 x 340 > 4 * DISPARITY_PIXELS: downsampled by 2
        assert _evidence.blur_reach(linear_path(1.0), 32, halves(Y)) == pytest.approx(2.0, abs=0.3), Y


def test_no_agreement_check_runs_when_the_evidence_is_not_required(monkeypatch):
    # iter_verdict: the agreement check runs only when the test finds little blur, require_evidence holds and the
    # light restoration would move the image by at least MIN_REACH px
    from napari_lfdeblur.blind._params import PathEstimate

    calls = []

    def evidence(*a, **k):
        return {"blur_found": False, "reach": 2.0, "gain": 0.5, "relative": 0.01}
        yield

    def disagreement(*a, **k):
        calls.append(1)
        return 0.0, []
        yield

    monkeypatch.setattr(_evidence, "blur_evidence", evidence)
    monkeypatch.setattr(_evidence, "iter_disagreement", disagreement)
    g = torch.zeros((3, 3, 16, 16, 1))
    split = ([g], [(0, 0, 16, 16)], (16, 16), np.random.default_rng(0), 1.0)
    est = PathEstimate(linear_path(1.0), [1.0], 1)
    for required, checked in ((False, False), (True, True)):
        p = BlindParams(require_evidence=required, light_restoration=0.5)
        calls.clear()
        ev, light = run_to_completion(_evidence.iter_verdict(split, est, p, torch.device("cpu")))
        assert bool(calls) is checked and np.isnan(ev["disagreement"]) is not checked
        assert light == (0.5 if checked else 0.0)


def _joint_run(monkeypatch, d_inf=0.0, n_iter=6):
    """The 'paper' preset on a tiny blurred scene: (its 'path (joint)' records, the d_inf of its operators)."""
    from napari_lfdeblur.blind import _joint

    seen = []

    class Spy(BlurOperator):
        def __init__(self, *a, **k):
            seen.append(k.get("infinity_disparity"))
            super().__init__(*a, **k)

    monkeypatch.setattr(_joint, "BlurOperator", Spy)
    lf, _ = synthetic_scene((3, 3, 16, 16), seed=0)
    b = simulate_blur(lf, linear_path(1.0), n_times=8, infinity_disparity=d_inf)
    p = BlindParams.preset("paper").replace(joint={"n_iter": n_iter}, final=None)
    recs = [r for r in iter_blind_deblur(b, params=p, infinity_disparity=d_inf, device="cpu")
            if r.stage == "path (joint)"]
    return recs, seen, p


def test_the_joint_prior_weight_and_eps_follow_their_published_schedule(monkeypatch):
    # JointParams: the prior weight decays by prior_decay per iteration down to prior_floor of its start, eps by
    # eps_decay down to eps_min
    recs, _, p = _joint_run(monkeypatch)
    j = p.joint
    its = [r.iteration for r in recs]
    assert its and its == sorted(set(its))
    w = [j.prior_weight * max(j.prior_decay ** (i - 1), j.prior_floor) for i in its]
    eps = [max(j.eps * j.eps_decay ** (i - 1), j.eps_min) for i in its]
    np.testing.assert_allclose([r.info["prior_weight"] for r in recs], w, rtol=1e-12)
    np.testing.assert_allclose([r.info["eps"] for r in recs], eps, rtol=1e-12)
    assert recs[0].info["prior_weight"] == pytest.approx(j.prior_weight)  # no decay at the first iteration


def test_the_joint_method_models_the_infinity_disparity_it_is_given(monkeypatch):
    # the joint method fits the blur of the MODEL.md d_inf model, so every blur operator it builds has that d_inf
    _, seen, _ = _joint_run(monkeypatch, d_inf=0.5, n_iter=2)
    assert seen and all(d == 0.5 for d in seen)
