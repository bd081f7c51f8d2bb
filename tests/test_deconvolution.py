"""Non-blind deconvolution, refocusing and the paper's analytic special cases."""

import json

import numpy as np
import pytest
from scipy import ndimage
from skimage import restoration

from napari_lfdeblur import (
    DeconvolutionParams,
    deconvolve,
    iter_deconvolve,
    linear_path,
    procedural_scene,
    random_path,
    recover_plane_texture,
    refocus,
    simulate_blur,
    synthetic_scene,
)
from napari_lfdeblur.progress import run_to_completion, with_previews
from napari_lfdeblur.blur import BlurOperator, from_tensor, to_tensor
from napari_lfdeblur import _noise
from napari_lfdeblur.deconvolution import N_INNER, estimate_noise_sigma
from napari_lfdeblur.priors import divergence4d, gradient4d, gradient_norm_bound, project_tv_dual, tv4d
from napari_lfdeblur.special_cases import inplane_matrix, inplane_psf
from conftest import wrap_prox_inner_iteration


def rmse(a, b, mask=None):
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    return float(np.sqrt(np.mean(d[mask] ** 2 if mask is not None else d**2)))


def plane_lightfield(shape, d, seed=0):
    """A textured fronto-parallel plane at disparity ``d``: view (v, u) is the texture shifted by d (v_c, u_c)."""
    V, U, Y, X = shape
    rng = np.random.default_rng(seed)
    pad = int(abs(d) * max(U, V)) + 8
    tex = ndimage.gaussian_filter(rng.random((Y + 2 * pad, X + 2 * pad)), 1.0)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    yy, xx = np.mgrid[0:Y, 0:X].astype(float)
    lf = np.empty(shape, np.float32)
    for v in range(V):
        for u in range(U):
            lf[v, u] = ndimage.map_coordinates(
                tex, [yy + pad - d * (v - (V - 1) / 2), xx + pad - d * (u - (U - 1) / 2)], order=1
            )
    return lf


# ------------------------------------------------------------ in-plane exact


@pytest.mark.parametrize("shape", [(5, 5, 12, 10), (5, 4, 8, 9, 3)], ids=["gray", "colour"])
def test_inplane_matrix_reproduces_the_blur(shape):
    lf = np.random.default_rng(0).random(shape).astype(np.float32)
    cp = linear_path(2.3, angle_deg=35)
    M = inplane_matrix(cp, shape[0], shape[1], n_times=12)
    blurred = simulate_blur(lf, cp, n_times=12)
    flat = lf.reshape(shape[0] * shape[1], -1).astype(np.float64)
    np.testing.assert_allclose((M @ flat).reshape(shape), blurred, atol=1e-5)


@pytest.mark.parametrize("shape", [(5, 5, 16, 16), (5, 5, 10, 12, 3)], ids=["gray", "colour"])
@pytest.mark.parametrize("cp", [linear_path(1.5, angle_deg=20), [[-0.6, 0.3, 0], [0.9, -0.4, 0], [0.2, 0.8, 0]]])
def test_inplane_solver_inverts_noise_free_blur(shape, cp):
    lf = np.random.default_rng(1).random(shape).astype(np.float32)
    blurred = simulate_blur(lf, cp, n_times=16)
    records = []
    out = deconvolve(blurred, cp, n_times=16, method="inplane", weight=0.0, callback=records.append, device="cpu")
    assert records and records[-1].stage == "inplane"
    assert out.shape == lf.shape and out.dtype == np.float32
    assert np.abs(out - lf).max() < 1e-3
    assert np.abs(blurred - lf).max() > 0.1  # the blur was not trivial


def test_the_default_and_auto_are_tv_for_every_path():
    lf = np.random.default_rng(2).random((3, 3, 6, 6)).astype(np.float32)
    for cp, d_inf in ((linear_path(1.0, z=1.0), 0.0), (linear_path(1.0), 0.4), (linear_path(1.0), 0.0)):
        for method in ({}, {"method": "auto"}):
            gen = iter_deconvolve(simulate_blur(lf, cp, n_times=4), cp, n_times=4, infinity_disparity=d_inf,
                                  n_iter=2, **method)
            assert next(gen).stage == "tv"
            gen.close()


def test_default_beats_the_inplane_solve_on_noisy_inplane_blur():
    # the in-plane solve's fixed angular weight amplifies noise of 0.01; the default's TV weight follows it
    lf, _ = synthetic_scene((5, 5, 32, 32), seed=4)
    cp = random_path(3, extent=2.0, z_extent=0.0, seed=5)
    noise = np.random.default_rng(6).normal(0, 0.01, lf.shape).astype(np.float32)
    blurred = simulate_blur(lf, cp, n_times=8) + noise
    tv = deconvolve(blurred, cp, n_times=8, device="cpu")
    inplane = deconvolve(blurred, cp, n_times=8, method="inplane", device="cpu")
    assert rmse(tv, lf) < 0.8 * rmse(blurred, lf)
    assert rmse(tv, lf) < 0.8 * rmse(inplane, lf)


# ------------------------------------------------------------------- TV


def tv_case(d_inf):
    """``(sharp, path, blurred)``: a 5x5x24x24x3 scene, a curved path with ``p_z``, 8 instants, noise 0.005."""
    lf, _ = synthetic_scene((5, 5, 24, 24), seed=2)
    cp = random_path(3, extent=2.5, z_extent=2.0, seed=3)
    noise = np.random.default_rng(0).normal(0, 0.005, lf.shape).astype(np.float32)
    return lf, cp, simulate_blur(lf, cp, n_times=8, infinity_disparity=d_inf) + noise


@pytest.mark.parametrize("d_inf", [0.0, 0.5])
def test_tv_deconvolution_with_the_true_path_cuts_the_error(d_inf):
    lf, cp, blurred = tv_case(d_inf)
    out = deconvolve(blurred, cp, n_times=8, infinity_disparity=d_inf, method="tv", device="cpu")
    # measured: about 0.50 of the blurred input's error (0.0053 vs 0.0100; 0.0058 vs 0.0115)
    assert rmse(out, lf) < 0.7 * rmse(blurred, lf)
    assert out.dtype == np.float32 and out.shape == lf.shape


def test_tv_colour_and_early_stopping_and_progress():
    lf, _ = synthetic_scene((3, 3, 12, 12), color=True, seed=4)
    cp = linear_path(1.5, 30, z=1.0)
    blurred = simulate_blur(lf, cp, n_times=8)
    records = []
    gen = with_previews(iter_deconvolve(blurred, cp, n_times=8, n_iter=400, tol=1e-3, couple_channels=False), 2)
    out = run_to_completion(gen, records.append)
    assert out.shape == lf.shape and out.dtype == np.float32
    # one TV per channel: the channels are solved one after the other, each stopping early on its objective
    channels = [[r for r in records if r.info["channel"] == c] for c in range(3)]
    for c, recs in enumerate(channels):
        assert 3 <= len(recs) < 400
        assert 0 <= recs[-1].info["relative_decrease"] < 1e-3
        assert [r.iteration for r in recs] == [c * 400 + i for i in range(1, len(recs) + 1)]
        assert recs[-1].loss <= recs[0].loss
    assert [r.info["channel"] for r in records] == sorted(r.info["channel"] for r in records)
    assert all(r.stage == "tv" and r.n_iterations == 3 * 400 for r in records)
    assert records[1].preview is not None and records[1].preview.shape == lf.shape
    assert records[0].preview is None and records[2].preview is None
    # a preview of the first channel shows the others as they came in (was uninitialised memory)
    np.testing.assert_array_equal(records[1].preview[..., 1:], blurred[..., 1:])
    assert np.isfinite([r.loss for r in records]).all()
    assert rmse(out, lf) < rmse(blurred, lf)
    # the colour TV (the default): all channels at once, one count of iterations
    records = []
    out = run_to_completion(with_previews(iter_deconvolve(blurred, cp, n_times=8, n_iter=400, tol=1e-3), 2),
                            records.append)
    assert 3 <= len(records) < 400 and 0 <= records[-1].info["relative_decrease"] < 1e-3
    assert [r.iteration for r in records] == list(range(1, len(records) + 1))
    assert all(r.n_iterations == 400 and r.info["channel"] == 0 for r in records)
    assert records[1].preview.shape == lf.shape and rmse(out, lf) < rmse(blurred, lf)


def test_previews_are_the_estimate_of_their_iteration():
    lf = np.random.default_rng(6).random((3, 3, 8, 8)).astype(np.float32)
    cp = linear_path(1.0, z=1.0)
    blurred = simulate_blur(lf, cp, n_times=4)
    records = []
    run_to_completion(with_previews(iter_deconvolve(blurred, cp, n_times=4, n_iter=5, tol=0.0), 3), records.append)
    assert [r.preview is not None for r in records] == [False, False, True, False, False]
    # the preview of iteration 3 is what a 3-iteration run returns
    three = deconvolve(blurred, cp, n_times=4, n_iter=3, tol=0.0)
    np.testing.assert_array_equal(records[2].preview, three)
    with pytest.raises(ValueError, match="every"):
        with_previews(iter_deconvolve(blurred, cp, n_times=4), -1)
    with pytest.raises(TypeError, match="every"):
        with_previews(iter_deconvolve(blurred, cp, n_times=4), 1.5)


def test_previews_are_spaced_by_their_cost():
    from napari_lfdeblur.progress import Progress

    now = [0.0]  # a clock: each record takes 0.1 s, each preview 1 s

    def estimate():
        now[0] += 1.0
        return np.zeros(1)

    def solver(n):
        for i in range(n):
            now[0] += 0.1
            yield Progress("tv", i + 1, n, loss=0.0, estimate=estimate)
        return "done"

    records = []
    result = run_to_completion(with_previews(solver(60), 2, share=3.0, clock=lambda: now[0]), records.append)
    shown = [i for i, r in enumerate(records) if r.preview is not None]
    # a preview at the 2nd record; the next no sooner than 3 x 1 s later (30 records), and 2 records on
    assert result == "done" and shown == [1, 31]
    records = []
    run_to_completion(with_previews(solver(8), 2, clock=lambda: now[0]), records.append)  # share 0: by count
    assert [i for i, r in enumerate(records) if r.preview is not None] == [1, 3, 5, 7]
    with pytest.raises(ValueError, match="share"):
        with_previews(solver(1), 1, share=-1.0)


def test_generator_returns_result_and_close_stops_it():
    lf = np.random.default_rng(5).random((3, 3, 8, 8)).astype(np.float32)
    cp = linear_path(1.0, z=1.0)
    gen = iter_deconvolve(lf, cp, n_times=4, n_iter=50, tol=0.0)
    first = next(gen)
    assert first.iteration == 1
    gen.close()
    with pytest.raises(StopIteration):
        next(gen)
    gen = iter_deconvolve(lf, cp, n_times=4, n_iter=3, tol=0.0)
    n = 0
    while True:
        try:
            next(gen)
            n += 1
        except StopIteration as stop:
            result = stop.value
            break
    assert n == 3 and result.shape == lf.shape and result.dtype == np.float32


def test_a_cancelled_tv_solve_stops_inside_the_iteration(monkeypatch, engine):
    import threading

    from napari_lfdeblur.progress import Cancelled, cancellable

    lf = np.random.default_rng(5).random((3, 3, 8, 8)).astype(np.float32)
    cp = linear_path(1.0, z=1.0)
    stop = threading.Event()
    calls = []

    def counting(real, *args, **kwargs):  # one inner iteration of the TV prox; the second of iteration 2 stops
        calls.append(stop.is_set())
        if len(calls) == N_INNER + 2:
            stop.set()
        return real(*args, **kwargs)

    wrap_prox_inner_iteration(monkeypatch, counting)
    gen = iter_deconvolve(lf, cp, n_times=4, n_iter=50, tol=0.0)  # N_INNER inner iterations per iteration
    with cancellable(stop):
        assert next(gen).iteration == 1 and len(calls) == N_INNER
        with pytest.raises(Cancelled):
            next(gen)
    # it stopped right after the inner iteration that set the event, inside iteration 2
    assert len(calls) == N_INNER + 2 and not any(calls)
    # outside a cancellable context the checks do nothing, though the event is still set
    calls.clear()
    records = []
    out = run_to_completion(iter_deconvolve(lf, cp, n_times=4, n_iter=3, tol=0.0), records.append)
    assert len(records) == 3 and len(calls) == 3 * N_INNER and out.shape == lf.shape


def test_zero_weight_tv_fits_the_data():
    lf = np.random.default_rng(6).random((3, 3, 8, 8)).astype(np.float32)
    cp = linear_path(1.0, z=0.5)
    b = simulate_blur(lf, cp, n_times=6)
    out = deconvolve(b, cp, n_times=6, method="tv", weight=0.0, n_iter=300, tol=0.0)
    resid = simulate_blur(out, cp, n_times=6) - b
    # weight 0 is the plain least-squares fit in the box: on noise-free data of a light field inside the box it is
    # an exact round trip, the light field itself to float32 rounding (measured: 3e-6 of the blur's change)
    assert rmse(out, lf) < 1e-4 * rmse(b, lf)
    assert rmse(resid, 0) < 1e-4 * rmse(b, lf)


def _gradient(x, od):
    """The four differences of the TV: along the view axes (``od`` None) or along the disparity map of ``od``."""
    g = list(gradient4d(x))
    if od is not None:
        g[0], g[1] = od.difference(x, 0), od.difference(x, 1)
    return g


def _condat_vu_reference(blurred, cp, n_times, d_inf, weight, n_iter, coupled=False, censored=False, od=None):
    """A long run of a different algorithm (Condat-Vu primal-dual, fixed steps) for the same objective + box.

    ``censored``: the data term of a saturated input, ``1/2 min(K x - 1, 0)^2`` at its samples at 1, and the
    box ``x >= 0`` only (the solution clipped to [0, 1] at the end). ``od``: the anisotropic TV along the
    disparity map of these :class:`~napari_lfdeblur._oriented.OrientedDifferences` (None: the isotropic TV
    along the view axes)."""
    import torch

    f = to_tensor(blurred, device="cpu")
    sat = f >= 1.0

    def residual(x):
        r = op.forward(x) - f
        return torch.where(sat & (r > 0), torch.zeros_like(r), r) if censored else r

    hi = None if censored else 1.0
    op = BlurOperator(f.shape, cp, n_times=n_times, infinity_disparity=d_inf, device="cpu")
    aw = (1.0, 1.0, 1.0, 1.0)
    with torch.no_grad():
        lip = max(1.0, float(op.adjoint(torch.ones_like(f)).max()))
        tau = 1.0 / lip
        bound = gradient_norm_bound(aw) if od is None else od.norm_bound(0) + od.norm_bound(1) + 8.0
        sig = 0.99 * (1.0 / tau - lip / 2.0) / bound
        x, dual = f.clamp(0, 1), [torch.zeros_like(f) for _ in range(4)]
        for _ in range(n_iter):
            div = divergence4d(dual, aw)
            if od is not None:  # -D^T along the disparity for the angular components
                div = divergence4d([torch.zeros_like(f)] * 2 + dual[2:], aw)
                od.add_adjoint(dual[0], 0, div, alpha=-1.0)
                od.add_adjoint(dual[1], 1, div, alpha=-1.0)
            x_new = (x - tau * (op.adjoint(residual(x)) - div)).clamp_(0, hi)
            for d, g in zip(dual, _gradient(2 * x_new - x, od)):
                d.add_(g, alpha=sig)
            project_tv_dual(dual, weight, isotropic=od is None, coupled_channels=coupled)
            x = x_new
        return from_tensor(x, blurred.ndim)


def _objective(x, blurred, cp, n_times, d_inf, weight, coupled=False, censored=False, od=None):
    import torch

    r = simulate_blur(x, cp, n_times=n_times, infinity_disparity=d_inf).astype(np.float64) - blurred
    if censored:
        r[(blurred >= 1.0) & (r > 0)] = 0.0
    xt = torch.from_numpy(np.ascontiguousarray(x)).double()
    if od is None:
        tv = tv4d(xt, coupled_channels=coupled)
    else:  # the anisotropic TV along the disparity: the sum of each difference's norm (over the channels)
        tv = sum((g * g).sum(-1).sqrt().sum() if coupled else g.abs().sum() for g in _gradient(xt, od))
    return 0.5 * float((r * r).sum()) + weight * float(tv)


@pytest.mark.parametrize("d_inf, z, coupled, angular", [(0.0, 1.5, False, "views"), (1.0, 0.0, False, "views"),
                                                        (1.0, 1.0, True, "views"), (1.0, 1.0, True, "disparity"),
                                                        (0.0, 1.5, False, "disparity")],
                         ids=["p_z", "d_inf", "colour TV", "along disparity", "along disparity, grey"])
def test_tv_reaches_the_optimum_of_a_long_reference_run(d_inf, z, coupled, angular, engine):
    import torch

    from napari_lfdeblur._oriented import OrientedDifferences
    from napari_lfdeblur.deconvolution import scene_disparity

    lf, _ = synthetic_scene((3, 3, 16, 16), color=coupled, seed=9)
    cp = random_path(3, extent=2.0, z_extent=z, seed=4)
    blurred = simulate_blur(lf, cp, n_times=8, infinity_disparity=d_inf)
    blurred = np.clip(blurred + np.random.default_rng(1).normal(0, 0.01, lf.shape), 0, 1).astype(np.float32)
    w = 0.01
    od = None  # the isotropic TV along the views; else the anisotropic TV along the disparity map deconvolve finds
    if angular == "disparity":
        f = to_tensor(blurred, device="cpu")
        od = OrientedDifferences(torch.as_tensor(scene_disparity(f, d_inf)).double())
    ref_x = _condat_vu_reference(blurred, cp, 8, d_inf, w, 1000, coupled, od=od)
    ref = _objective(ref_x, blurred, cp, 8, d_inf, w, coupled, od=od)
    records = []
    n_iter = 40 if od is None else 60  # the oriented differences' larger norm bound: shorter dual steps
    out = deconvolve(blurred, cp, n_times=8, infinity_disparity=d_inf, method="tv", weight=w, n_iter=n_iter, tol=0.0,
                     couple_channels=coupled, saturation=False, callback=records.append, angular=angular,
                     isotropic=angular == "views")
    got = _objective(out, blurred, cp, 8, d_inf, w, coupled, od=od)
    # 40 (60) iterations come within 0.1 % of what 1000 Condat-Vu iterations reach (or below it)
    assert got < ref * (1 + 1e-3)
    # and at its minimiser, not merely at a similar value: within 4 % of the input's distance from the reference
    # solution (measured: 0.5 to 2.2 %; a TV weight 10 % too high lands 6.7 to 12 % away)
    assert rmse(out, ref_x) < 0.04 * rmse(blurred, ref_x)
    assert records[-1].info["objective"] == pytest.approx(got, rel=1e-4)
    assert records[-1].info["blur_evaluations"] >= n_iter and records[-1].info["weight"] == w


def test_a_saturated_input_reaches_the_optimum_of_its_censored_objective():
    # a scene brighter than the sensor's ceiling: its blur clipped at 1. The solve fits the samples at 1 only from
    # below (the blur of the estimate must reach 1 there), lets the estimate exceed 1, and clips the result
    lf, _ = synthetic_scene((3, 3, 16, 16), seed=9)
    radiance = 1.3 * lf
    cp = random_path(3, extent=2.0, z_extent=0.5, seed=4)
    blurred = np.clip(simulate_blur(radiance, cp, n_times=8), 0, 1).astype(np.float32)
    assert 0.05 < np.mean(blurred >= 1.0) < 0.5
    w = 0.002
    ref_x = _condat_vu_reference(blurred, cp, 8, 0.0, w, 1000, censored=True)
    ref = _objective(ref_x, blurred, cp, 8, 0.0, w, censored=True)
    records = []
    views = dict(angular="views", isotropic=True)  # the TV of the reference
    got_x = deconvolve(blurred, cp, n_times=8, method="tv", weight=w, n_iter=60, tol=0.0, callback=records.append,
                       **views)
    assert got_x.min() >= 0.0 and got_x.max() <= 1.0  # clipped once solved
    raw = records[-1].info["objective"]  # the objective of the unclipped iterate
    assert raw < ref * (1 + 1e-3)
    # the censored objective is not the plain one: the plain optimum inside [0, 1] is worse on it
    plain = deconvolve(blurred, cp, n_times=8, method="tv", weight=w, n_iter=60, tol=0.0, saturation=False, **views)
    assert _objective(plain, blurred, cp, 8, 0.0, w, censored=True) > ref * 1.02
    # and it restores the clipped scene better than the plain fit does
    truth = np.clip(radiance, 0, 1)
    assert rmse(got_x, truth) < 0.9 * rmse(plain, truth)


def test_censored_residual_clips_only_the_positive_residual_of_saturated_samples():
    import torch

    from napari_lfdeblur._tv_solvers import _residual

    rng = np.random.default_rng(2)
    f = torch.from_numpy(np.clip(rng.random((4, 5)) * 1.4, 0, 1))
    Kx = torch.from_numpy(rng.random((4, 5)) * 1.4)
    censored = torch.ge(f.reshape(-1), 1.0).nonzero().squeeze(1)
    got = _residual(Kx, f, torch.empty_like(f), censored).numpy()
    r = (Kx - f).numpy()
    want = np.where((f.numpy() >= 1.0) & (r > 0), 0.0, r)
    np.testing.assert_array_equal(got, want)
    assert np.any(got != r) and np.any((f.numpy() >= 1.0) & (r < 0))  # both branches taken
    np.testing.assert_array_equal(_residual(Kx, f, torch.empty_like(f), None).numpy(), r)


def test_saturation_changes_nothing_below_the_ceiling():
    lf, _ = synthetic_scene((3, 3, 12, 12), seed=2)
    cp = linear_path(1.5)
    blurred = simulate_blur(0.9 * lf, cp, n_times=6)
    assert blurred.max() < 1.0
    on = deconvolve(blurred, cp, n_times=6, n_iter=10)
    off = deconvolve(blurred, cp, n_times=6, n_iter=10, saturation=False)
    np.testing.assert_array_equal(on, off)


@pytest.mark.parametrize("shape, isotropic, coupled, box", [
    ((3, 4, 7, 5, 2), True, True, (0.0, 1.0)),
    ((3, 4, 7, 5, 2), False, True, None),
    ((3, 4, 7, 5, 3), True, True, None),  # three channels: loops of their own
    ((3, 4, 7, 5, 3), False, True, (0.0, 1.0)),
    ((2, 3, 9, 6), True, False, None),
    ((3, 3, 8, 5), False, False, (0.0, 1.0)),
    ((3, 2, 1, 5), True, False, None),
])
def test_tv_prox_in_blocks_of_rows_is_the_whole_field_gradient_projection(shape, isotropic, coupled, box, engine):
    import torch

    from napari_lfdeblur._tv_solvers import TVProx

    aw, mu, n_inner = (1.0, 0.5, 1.0, 2.0), 0.3, 4
    rng = np.random.default_rng(3)
    vs = [torch.as_tensor(rng.uniform(-0.5, 1.5, shape), dtype=torch.float64) for _ in range(2)]

    def clip(x):
        return x if box is None else x.clamp(*box)

    # the reference: gradient projection on the dual written with the public operators, the dual kept
    # between calls
    p = [torch.zeros(shape, dtype=torch.float64) for _ in range(4)]
    step = 1.0 / (mu * gradient_norm_bound(aw))
    ref = []
    for v in vs:
        for _ in range(n_inner):
            g = gradient4d(clip(v + mu * divergence4d(p, aw)), aw)
            p = [a + step * b for a, b in zip(p, g)]
            project_tv_dual(p, 1.0, isotropic, coupled_channels=coupled)
        ref.append(clip(v + mu * divergence4d(p, aw)))
    for rows in (None, 1, 2, 3, 100):  # blocks of 1, 2, 3 rows, the whole field, the default (torch version)
        prox = TVProx(vs[0], n_inner, isotropic, aw, box, coupled=coupled, rows=rows)
        assert prox.fused == (engine == "fused")
        for v, r in zip(vs, ref):
            out = torch.empty_like(v)
            prox(v, mu, out)
            np.testing.assert_allclose(out.numpy(), r.numpy(), atol=1e-12)


@pytest.mark.parametrize("shape, coupled", [((3, 4, 7, 5, 3), True), ((3, 4, 7, 5, 3), False), ((2, 3, 6, 4), False),
                                            ((3, 1, 1, 5, 2), True)])
@pytest.mark.parametrize("isotropic", [True, False])
def test_tv_value_is_the_weighted_tv4(shape, coupled, isotropic, engine):
    import torch

    from napari_lfdeblur._tv_solvers import tv_value

    aw = (0.5, 0.0, 1.0, 2.0)
    x = torch.as_tensor(np.random.default_rng(4).random(shape))
    # the weighted forward differences, zero-padded to the field's shape, and their norms written out
    grads = [aw[a] * (x.narrow(a, 1, x.shape[a] - 1) - x.narrow(a, 0, x.shape[a] - 1)) for a in range(4)]
    full = [torch.nn.functional.pad(g, [0, 0] * (x.dim() - 1 - a) + [0, 1]) for a, g in enumerate(grads)]
    sq = [g * g for g in full]
    if isotropic:
        s = sum(sq)
        want = (s.sum(-1) if coupled else s).sqrt().sum()
    else:
        want = sum((q.sum(-1).sqrt() if coupled else q.sqrt()).sum() for q in sq)
    assert tv_value(x, isotropic, aw, coupled=coupled) == pytest.approx(float(want), rel=1e-12)


def test_colour_tv_of_equal_channels_is_the_grey_tv_at_sqrt3_its_weight():
    # three equal channels: 3/2 ||K x - f||^2 + w sqrt(3) TV(x) has the minimiser of 1/2 ||K x - f||^2 + w TV(x) / sqrt(3)
    lf, _ = synthetic_scene((3, 3, 12, 12), seed=2)
    cp = random_path(3, extent=1.5, z_extent=0.5, seed=3)
    grey = simulate_blur(lf, cp, n_times=6, infinity_disparity=0.5)
    grey = np.clip(grey + np.random.default_rng(0).normal(0, 0.01, grey.shape), 0, 1).astype(np.float32)
    colour = np.repeat(grey[..., None], 3, axis=-1)
    kw = dict(n_times=6, infinity_disparity=0.5, n_iter=200, tol=1e-7)
    separate = deconvolve(grey, cp, weight=0.02, **kw)
    coupled = deconvolve(colour, cp, weight=0.02 * np.sqrt(3), couple_channels=True, **kw)
    for c in range(3):
        np.testing.assert_allclose(coupled[..., c], separate, atol=1e-4)
    # on one channel the colour TV is the plain TV: the same result, bit for bit
    np.testing.assert_array_equal(deconvolve(grey, cp, weight=0.02, couple_channels=True, **kw), separate)
    # the default weights: each prior's own factor times the noise estimate (the colour one only on colour)
    est = estimate_noise_sigma(colour)
    records = []
    gen = iter_deconvolve(colour, cp, n_times=6, couple_channels=True)
    records.append(next(gen))
    gen.close()
    # docs/deconvolution.md, "The default weight": 0.45 sigma for the colour TV, 0.3 sigma per channel (and on one
    # channel, where the colour TV is the plain TV), half for the anisotropic TV: 0.225 sigma by default on colour
    assert records[0].info["weight"] == pytest.approx(0.225 * est)
    assert records[0].iteration == 1 and records[0].n_iterations == DeconvolutionParams().n_iter  # one solve, not 3
    assert DeconvolutionParams(couple_channels=True, isotropic=True).effective_weight("tv", est, 3) == pytest.approx(
        0.45 * est)
    p = DeconvolutionParams(couple_channels=True, isotropic=True)
    assert p.effective_weight("tv", est, 1) == pytest.approx(0.3 * est)
    assert DeconvolutionParams(couple_channels=False, isotropic=True).effective_weight("tv", est, 3) == pytest.approx(
        0.3 * est)


def test_tv_stops_on_the_objective():
    lf, _ = synthetic_scene((3, 3, 12, 12), seed=5)
    cp = linear_path(1.5, 30, z=1.0)
    blurred = simulate_blur(lf, cp, n_times=8)
    for tol in (1e-2, 1e-4):
        records = []
        deconvolve(blurred, cp, n_times=8, weight=1e-3, n_iter=300, tol=tol, callback=records.append)
        dec = [r.info["relative_decrease"] for r in records]
        assert len(records) < 300 and 0 <= dec[-1] < tol
        assert all(not 0 <= d < tol for d in dec[:-1])  # it stopped at the first such iteration
        objective = [r.info["objective"] for r in records]
        assert objective[-1] < objective[0]
        assert all(r.loss == r.info["objective"] for r in records)


def test_noise_estimate_and_the_default_weight_grow_with_the_noise():
    lf, _ = synthetic_scene((5, 5, 48, 48), color=True, seed=3)
    cp = random_path(3, extent=2.0, z_extent=1.0, seed=2)
    clean = simulate_blur(lf, cp, n_times=8)
    weights, errors = [], []
    for sigma in (0.01, 0.02, 0.04):
        noisy = clean + np.random.default_rng(0).normal(0, sigma, lf.shape).astype(np.float32)
        est = estimate_noise_sigma(noisy)
        # the blurred scene's faintest details add a little: the estimate errs high, and less with more noise
        assert sigma * 0.98 < est < sigma * 1.1
        errors.append(est / sigma - 1)
        gen = iter_deconvolve(noisy, cp, n_times=8, method="tv", n_iter=1)
        info = next(gen).info
        gen.close()
        # a colour light field: the rule of docs/deconvolution.md, "The default weight": 0.45 sigma for the colour
        # TV (the default on colour), halved for the default anisotropic TV, "so by default, on colour,
        # w = 0.225 * sigma"; 0.3 sigma with one TV per channel
        assert info["sigma"] == pytest.approx(est) and info["weight"] == pytest.approx(0.225 * est)
        assert DeconvolutionParams().effective_weight("tv", est, 3) == pytest.approx(0.225 * est)
        assert DeconvolutionParams(isotropic=True).effective_weight("tv", est, 3) == pytest.approx(0.45 * est)
        separate = DeconvolutionParams(couple_channels=False, isotropic=True)
        assert separate.effective_weight("tv", est, 3) == pytest.approx(0.3 * est)
        anisotropic = DeconvolutionParams(couple_channels=False)
        assert anisotropic.effective_weight("tv", est, 3) == pytest.approx(0.15 * est)
        weights.append(info["weight"])
    assert weights[0] < weights[1] < weights[2]
    assert errors[2] < errors[0] and errors[2] < 0.03
    # a given weight: no noise estimate is made
    gen = iter_deconvolve(noisy, cp, n_times=8, method="tv", weight=0.01, n_iter=1)
    info = next(gen).info
    gen.close()
    assert info["sigma"] is None and info["weight"] == 0.01
    assert DeconvolutionParams(weight=0.05).effective_weight("tv", 0.01) == 0.05  # an explicit weight wins
    assert DeconvolutionParams().effective_weight("inplane") == 2e-3
    with pytest.raises(ValueError, match="sigma"):
        DeconvolutionParams().effective_weight("tv")


def test_noise_estimate_unit_quantile_matches_a_simulation():
    # the constant behind the wavelet estimate: the 10th percentile of the mean of the 12 smallest of 16 squared
    # standard Gaussians, simulated afresh (standard error about 0.1 % with 400 000 blocks)
    from napari_lfdeblur._noise import _NOISE_KEPT, _NOISE_QUANTILE, _NOISE_UNIT

    z = np.square(np.random.default_rng(11).normal(size=(400_000, 16)))
    kept = np.partition(z, _NOISE_KEPT - 1, axis=1)[:, :_NOISE_KEPT].mean(axis=1)
    assert np.quantile(kept, _NOISE_QUANTILE) == pytest.approx(_NOISE_UNIT, rel=0.006)


def test_noise_estimate_is_unbiased_on_noise_and_reads_the_least_detailed_patches():
    rng = np.random.default_rng(5)
    for sigma in (0.002, 0.02):
        est = estimate_noise_sigma(rng.normal(0.5, sigma, (5, 5, 64, 64, 3)).astype(np.float32))
        # the patches are chosen in the neighbouring view, whose noise is independent: no bias from the choice
        assert est == pytest.approx(sigma, rel=0.02)
    # finely textured natural scenes, blurred, at low noise: the finest Haar detail (the classical estimate) holds
    # much of the image; the least detailed patches' smallest principal component far less
    sigma = 0.002
    for seed in (0, 1, 2):
        lf, _ = procedural_scene((5, 5, 64, 64), seed=seed)
        noisy = simulate_blur(lf, random_path(3, extent=1.5, z_extent=0.5, seed=seed), n_times=8)
        noisy = noisy + rng.normal(0, sigma, lf.shape).astype(np.float32)
        hh = (noisy[:, :, 0::2, 0::2] - noisy[:, :, 0::2, 1::2] - noisy[:, :, 1::2, 0::2] + noisy[:, :, 1::2, 1::2]) / 2
        classical = np.median(np.abs(hh)) / 0.6745
        est = estimate_noise_sigma(noisy)
        assert sigma < est < 2 * sigma and est - sigma < 0.4 * (classical - sigma)
        assert est == min(_noise._wavelet_estimate(noisy), _noise._pca_estimate(noisy))  # the smaller of the two
        # more white noise adds in quadrature: what the estimate reads besides the noise is not the image's detail
        more = noisy + rng.normal(0, 0.01, lf.shape).astype(np.float32)
        assert estimate_noise_sigma(more) == pytest.approx(np.hypot(est, 0.01), rel=0.03)
    # clipped (constant) regions say nothing about the noise and are left out
    clipped = noisy.copy()
    clipped[:, :, :40] = 1.0
    assert estimate_noise_sigma(clipped) == pytest.approx(estimate_noise_sigma(noisy[:, :, 40:]), rel=0.15)
    assert estimate_noise_sigma(np.ones((3, 3, 16, 16), np.float32)) == 0.0
    # noise that grows with brightness (photon noise) on a smooth ramp: the root-mean-square noise, not the darkest
    ramp = np.broadcast_to(np.linspace(0.05, 0.95, 64, dtype=np.float32), (5, 5, 64, 64))
    var = 2e-4 * ramp
    photon = ramp + rng.normal(size=ramp.shape).astype(np.float32) * np.sqrt(var)
    assert estimate_noise_sigma(photon) == pytest.approx(np.sqrt(var.mean()), rel=0.1)
    # integer-coded images: the rounding (a uniform error of one code step) counts as noise
    for steps in (1.0, 3.0):
        coded = np.round(rng.normal(128, steps, (5, 5, 64, 64))) / 255
        assert estimate_noise_sigma(coded) == pytest.approx(np.sqrt(steps**2 + 1 / 12) / 255, rel=0.04)
    # too few patches: the classical estimate
    tiny = rng.normal(0.5, 0.01, (9, 9, 6, 6)).astype(np.float32)
    assert estimate_noise_sigma(tiny) == pytest.approx(np.median(np.abs(
        tiny[:, :, 0::2, 0::2] - tiny[:, :, 0::2, 1::2] - tiny[:, :, 1::2, 0::2] + tiny[:, :, 1::2, 1::2]) / 2) / 0.6745,
        rel=1e-4)
    with pytest.raises(ValueError, match="2 x 2"):
        estimate_noise_sigma(np.zeros((3, 3, 1, 5)))


# --------------------------------------------------------- 4D versus 2D


def test_inplane_psf_reproduces_the_blur_of_a_plane():
    lf = plane_lightfield((7, 7, 40, 40), 1.0)
    cp = [[-0.3, 0.2, 0.0], [1.4, -0.9, 0.0]]  # not symmetric: a flipped PSF would fail
    b = simulate_blur(lf, cp, n_times=16)
    psf = inplane_psf(cp, 1.0, n_times=16)
    c = ndimage.convolve(lf[3, 3].astype(np.float64), psf, mode="nearest")
    np.testing.assert_allclose(c[6:-6, 6:-6], b[3, 3, 6:-6, 6:-6], atol=1e-5)
    flipped = ndimage.convolve(lf[3, 3].astype(np.float64), psf[::-1, ::-1], mode="nearest")
    assert np.abs(flipped - b[3, 3])[6:-6, 6:-6].max() > 1e-2
    # a larger window holds the same PSF, centred; one that would cut taps off is refused (not renormalised)
    big = inplane_psf(cp, 1.0, n_times=16, size=psf.shape[0] + 4)
    np.testing.assert_array_equal(big[2:-2, 2:-2], psf)
    assert big.sum() == pytest.approx(1.0) and not big[:2].any() and not big[:, -2:].any()
    for size, words in ((3, "cuts off the PSF"), (0, "whole number >= 1"), (5.0, "whole number >= 1")):
        with pytest.raises(ValueError, match=words):
            inplane_psf([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], 10.0, n_times=3, size=size)


def test_4d_beats_2d_and_the_gap_grows_with_blur_length():
    """The paper's in-plane result at two blur lengths: 2D (one depth's PSF) degrades, 4D much less."""
    lf, disp = synthetic_scene((5, 5, 32, 32), seed=1)
    rng = np.random.default_rng(0)
    c = (2, 2)
    errors = {}
    for length in (1.0, 3.0):
        cp = linear_path(length, angle_deg=20)
        b = simulate_blur(lf, cp) + rng.normal(0, 0.003, lf.shape).astype(np.float32)
        out4 = deconvolve(b, cp, weight=1e-3)
        psf = inplane_psf(cp, float(np.median(disp)))
        out2 = restoration.wiener(b[c].astype(np.float64), psf, balance=0.02)
        errors[length] = (rmse(out4[c], lf[c]), rmse(out2, lf[c]))
    # measured: 4D 0.0045 -> 0.0162, 2D 0.0146 -> 0.0390
    for e4, e2 in errors.values():
        assert e4 < 0.6 * e2
    assert errors[3.0][1] - errors[1.0][1] > 1.5 * (errors[3.0][0] - errors[1.0][0])


# -------------------------------------------------------- refocus, plane


def test_refocus_aligns_a_plane_at_its_disparity():
    lf = plane_lightfield((5, 5, 32, 32), 2.0)
    inner = (slice(6, -6), slice(6, -6))
    out = refocus(lf, 2.0)
    assert out.shape == (32, 32) and out.dtype == np.float32
    np.testing.assert_allclose(out[inner], lf[2, 2][inner], atol=1e-5)
    assert rmse(refocus(lf, -2.0)[inner], lf[2, 2][inner]) > 0.02  # the sign matters
    np.testing.assert_allclose(refocus(lf, 0.0), lf.mean(axis=(0, 1)), atol=1e-6)
    colour = np.stack([lf, 1 - lf], axis=-1)
    rc = refocus(colour, 2.0)
    assert rc.shape == (32, 32, 2)
    np.testing.assert_allclose(rc[..., 1][inner], 1 - lf[2, 2][inner], atol=1e-5)


def test_recover_plane_texture_beats_the_blurred_centre_view():
    d = 2.0
    lf = plane_lightfield((9, 9, 64, 64), d, seed=3)
    blurred = simulate_blur(lf, linear_path(0.0, z=8.0), n_times=32)  # linear out-of-plane motion
    truth = lf[4, 4]
    res = recover_plane_texture(blurred, disparity=d)
    yy, xx = np.mgrid[0:64, 0:64]
    disc = np.hypot(yy - 31.5, xx - 31.5) <= res.valid_radius
    assert res.valid_radius == pytest.approx(d * 4)
    e_blur, e_rec = rmse(blurred[4, 4], truth, disc), rmse(res.texture, truth, disc)
    # measured: 0.042 -> 0.029 (refocused slice alone: 0.046)
    assert e_rec < 0.8 * e_blur
    assert res.zeta > 0
    assert res.texture.shape == truth.shape and res.texture.dtype == np.float32
    assert res.dwell.sum() == pytest.approx(1.0) and np.all(res.dwell >= 0)
    assert res.dwell_p.shape == res.dwell.shape
    assert res.kernel.sum() == pytest.approx(1.0, rel=1e-5)
    # blind: the disparity is found too, and the result still beats the blurred view
    auto = recover_plane_texture(blurred)
    assert abs(auto.disparity - d) < 0.3
    assert rmse(auto.texture, truth, disc) < 0.85 * e_blur



@pytest.mark.parametrize("d", [2.37, -1.62, 5.3])
def test_recover_plane_texture_finds_the_disparity_of_a_symmetric_motion(d):
    # a motion symmetric about p_z = 0: the zero-mean gauge's disparity is the plane's own, up to the pull
    # towards 0 of the spread of magnifications (docstring; measured 1.2 % here); also beyond 4 px/view, where
    # the views still overlap about the centre (5 views, 64 px)
    lf = plane_lightfield((5, 5, 64, 64), d, seed=4)
    blurred = simulate_blur(lf, linear_path(0.0, z=3.0), n_times=32)
    assert recover_plane_texture(blurred).disparity == pytest.approx(d, rel=0.02)
    assert recover_plane_texture(lf).disparity == pytest.approx(d, abs=0.005)  # without blur: exactly


@pytest.mark.parametrize("d", [2.0, -1.5])
def test_recover_plane_texture_finds_the_disparity_on_views_larger_than_the_sweep(d):
    # views of 128 px are swept area-averaged by k = 2 (to about SWEEP_PIXELS = 64 px), where a disparity is
    # d / k px/view: the found disparity is that of the full views (the Lytro sample's views are 128 px)
    lf = plane_lightfield((5, 5, 128, 128), d, seed=4)
    assert recover_plane_texture(lf, n_slices=3).disparity == pytest.approx(d, abs=0.05)


@pytest.mark.parametrize("p_z", [3.0, -3.0])
def test_recover_plane_texture_profile_peaks_where_a_still_camera_stands(p_z):
    # a camera held still at p_z sees the plane magnified by s = 1 + d p_z / R, at disparity d / s (docstring of
    # recover_plane_texture): the slice refocused there is the sharpest, so the profile peaks at dwell_p = p_z, on
    # the side of p_z's sign. A non-integer d, so that the slice at p = 0 is not favoured by exact pixel shifts.
    d = 1.3
    lf = plane_lightfield((5, 5, 64, 64), d, seed=3)
    blurred = simulate_blur(lf, [[0.0, 0.0, p_z], [0.0, 0.0, p_z]], n_times=32)
    res = recover_plane_texture(blurred, disparity=d)  # p_range 3: the profile's grid ends at +-3
    assert res.dwell_p[np.argmax(res.dwell)] == pytest.approx(p_z)
    assert np.sign((res.dwell_p * res.dwell).sum()) == np.sign(p_z)


def test_plane_texture_kernel_dots_are_spaced_d_squared_p_over_r():
    from napari_lfdeblur.special_cases import _kernel_image

    # PlaneTextureResult.kernel: each instant p spreads into a V x U grid of dots spaced d^2 p / R px, each 1 / (UV)
    # of the instant's weight. d = 2, R = 32: p = 8 gives 1 px (a 5 x 5 block of 1/25), p = 16 gives 2 px.
    for p, spacing in ((8.0, 1), (16.0, 2)):
        K = _kernel_image(np.array([p]), np.array([1.0]), 2.0, 32.0, 5, 5)
        half = 2 * spacing + 1  # the dots reach 2 spacings from the centre, plus one pixel of margin
        want = np.zeros((2 * half + 1, 2 * half + 1))
        want[1 : 2 * half : spacing, 1 : 2 * half : spacing] = 1 / 25
        np.testing.assert_allclose(K, want, atol=1e-7)


# --------------------------------------------------------------- params


def test_params_json_round_trip_and_overrides():
    p = DeconvolutionParams(method="tv", weight=0.01, n_iter=7, axis_weights=(1, 1, 2, 2))
    q = DeconvolutionParams.from_json(p.to_json())
    assert q == p and q.axis_weights == (1.0, 1.0, 2.0, 2.0)
    assert DeconvolutionParams.from_dict(json.loads(p.to_json())) == p
    with pytest.raises(ValueError, match="unknown deconvolution parameter.*known: .*n_iter"):
        DeconvolutionParams.from_dict({"method": "tv", "bogus": 1})
    with pytest.raises(TypeError, match="unknown deconvolution parameter"):
        p.replace(iterations=3)
    assert p.replace(n_iter=9) == DeconvolutionParams(method="tv", weight=0.01, n_iter=9, axis_weights=(1, 1, 2, 2))
    for text in ("{not json", None):
        with pytest.raises(ValueError, match="invalid JSON for DeconvolutionParams"):
            DeconvolutionParams.from_json(text)
    with pytest.raises(ValueError, match="needs a dict"):
        DeconvolutionParams.from_json("[1, 2]")
    # a bool field takes a bool: the string "false" and the number 0 are refused, not read as truth values
    for field in ("isotropic", "couple_channels", "clip", "saturation"):
        for value in ("false", 0):
            with pytest.raises(TypeError, match=f"{field} must be true or false"):
                DeconvolutionParams.from_dict({field: value})
    assert DeconvolutionParams(isotropic=np.bool_(True)).isotropic is True
    for bad in ("1111", "2111", (1, 1, "2", 1), (1, 1, True, 1), (1, 1, 1), (1, 1, -1, 1)):  # a string: per character
        with pytest.raises(ValueError, match="axis_weights must be 4 non-negative numbers"):
            DeconvolutionParams(axis_weights=bad)
    lf = np.random.default_rng(7).random((3, 3, 6, 6)).astype(np.float32)
    recs = []
    deconvolve(lf, linear_path(1.0, z=1.0), n_times=4, params=p, n_iter=2, tol=0.0, callback=recs.append)
    assert len(recs) == 2  # the keyword overrides the params' n_iter


# -------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"control_points": [[0, 0, np.nan], [1, 0, 0]]}, "NaN"),
        ({"control_points": [[0, 0], [1, 0]]}, r"\(n, 3\)"),
        ({"weight": -1.0}, "weight must be >= 0"),
        ({"method": "magic"}, "unknown deconvolution method"),
        ({"method": "inplane", "control_points": [[0, 0, 0], [1, 0, 1]]}, "in-plane"),
        ({"init": np.zeros((3, 3, 5, 6), np.float32)}, "shape"),
        ({"n_iter": 0}, "n_iter"),
        ({"tol": -1}, "tol"),
        ({"tol": 5}, r"tol must be in \[0, 1\)"),  # a fraction: 5 stopped at the first check
        ({"n_times": 1}, "n_times"),
        ({"infinity_disparity": float("nan")}, "infinity_disparity"),
        ({"infinity_disparity": 3.5}, "at most 3"),  # 3x3 views of 6x6 px: the outer views would move 3.5 px
        ({"device": "tpu"}, "unknown device"),
        ({"blurred": np.zeros((3, 6, 6))}, "4D"),
        ({"blurred": np.full((3, 3, 6, 6), np.nan)}, "NaN"),
    ],
)
def test_bad_input_gives_clear_errors(kwargs, message):
    args = {"blurred": np.zeros((3, 3, 6, 6), np.float32), "control_points": [[0, 0, 0], [1, 0, 0]]}
    args.update(kwargs)
    blurred = args.pop("blurred")
    cp = args.pop("control_points")
    with pytest.raises(ValueError, match=message):
        deconvolve(blurred, cp, **args)


def test_odd_inputs_and_arguments_get_clear_errors_before_any_work():
    f = np.random.default_rng(0).random((5, 5, 1, 16)).astype(np.float32)
    with pytest.raises(ValueError, match="too small to estimate the noise.*pass weight="):
        iter_deconvolve(f, linear_path(1.0))  # was raised by the first next()
    assert deconvolve(f, linear_path(1.0), weight=0.01, n_iter=2).shape == f.shape
    with pytest.raises(TypeError, match="callback must be a function"):
        deconvolve(f, linear_path(1.0), weight=0.01, callback=5)
    p = DeconvolutionParams()
    with pytest.raises(ValueError, match="unknown method 'bogus'"):
        p.effective_weight("bogus", 0.01)
    with pytest.raises(ValueError, match="sigma must be >= 0"):
        p.effective_weight("tv", -0.01)


def test_integer_input_keeps_its_range_and_inplane_clips():
    # uint8 with clipped highlights: bounded and censored at 255 as float input is at 1 (it reached 337)
    lf, _ = synthetic_scene((3, 3, 16, 16), seed=2)
    cp = linear_path(1.5, 30)
    blurred = simulate_blur(np.clip(1.6 * lf, 0, None), cp, n_times=8)
    u8 = np.round(np.clip(blurred, 0, 1) * 255).astype(np.uint8)
    as_int, as_float = deconvolve(u8, cp, n_times=8, n_iter=30), deconvolve(u8 / 255.0, cp, n_times=8, n_iter=30)
    assert as_int.max() <= 255 and np.abs(as_int / 255.0 - as_float).max() < 1e-3
    # 'inplane' is a linear solve: with clip, its result is clipped to the input's range
    out = deconvolve(np.clip(blurred, 0, 1), cp, n_times=8, method="inplane", weight=1e-4)
    assert out.min() >= 0.0 and out.max() <= 1.0
    assert deconvolve(np.clip(blurred, 0, 1), cp, n_times=8, method="inplane", weight=1e-4, clip=False).max() > 1.0


def test_unknown_keyword_is_a_type_error():
    with pytest.raises(TypeError, match="bogus"):
        deconvolve(np.zeros((3, 3, 4, 4)), linear_path(1.0), bogus=1)


def test_plane_texture_bad_input():
    lf = np.zeros((3, 3, 8, 8), np.float32)
    with pytest.raises(ValueError, match="non-zero"):
        recover_plane_texture(lf, disparity=0.0)
    with pytest.raises(ValueError, match="zeta"):
        recover_plane_texture(lf, disparity=1.0, zeta=-1.0)
    with pytest.raises(ValueError, match="n_slices"):
        recover_plane_texture(lf, disparity=1.0, n_slices=1)
    with pytest.raises(ValueError, match="disparity"):
        refocus(lf, float("inf"))


# ------------------------------------------------------------------ CLI


def test_cli_deconvolve(tmp_path, capsys):
    import napari_lfdeblur
    from napari_lfdeblur.cli import main
    from napari_lfdeblur.io import read_lightfield, read_lightfield_with_metadata
    from napari_lfdeblur.path import load_path_json, save_path_json

    lf = np.random.default_rng(8).random((5, 5, 10, 10)).astype(np.float32)
    cp = linear_path(1.5, angle_deg=10)
    blurred = simulate_blur(lf, cp, n_times=8)
    src = tmp_path / "blurred.npz"
    np.savez(src, lf=blurred)
    path_file = save_path_json(tmp_path / "path.json", cp, n_times=8)
    out = tmp_path / "out.npz"
    assert main(["deconvolve", str(src), str(path_file), str(out), "--weight", "0"]) == 0
    got, meta = read_lightfield_with_metadata(out)
    assert np.abs(got - lf).max() < 1e-3  # n_times came from the path file; exact in-plane inverse
    # the result states how it was made: the path beside it, the parameters and the version in its metadata
    np.testing.assert_allclose(load_path_json(tmp_path / "out.path.json"), cp)
    assert meta["n_times"] == 8 and meta["infinity_disparity"] == 0.0
    saved = meta["saved_metadata"]
    assert saved["kind"] == "deconvolved" and saved["napari_lfdeblur_version"] == napari_lfdeblur.__version__
    assert saved["parameters"]["weight"] == 0.0 and saved["parameters"]["method"] == "tv"
    assert saved["parameters"]["weight_used"] == 0.0
    # every parameter of the solve, those left at their defaults too: they make the same DeconvolutionParams
    from napari_lfdeblur.deconvolution import DeconvolutionParams

    stated = {k: v for k, v in saved["parameters"].items() if k not in ("weight_used", "noise_sigma")}
    assert set(stated) == set(DeconvolutionParams().to_dict())
    assert DeconvolutionParams.from_dict(stated).method == "tv"
    # an existing output (or path beside it) is kept unless --overwrite
    assert main(["deconvolve", str(src), str(path_file), str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    out.rename(tmp_path / "kept.npz")
    assert main(["deconvolve", str(src), str(path_file), str(out)]) == 2
    assert "out.path.json exists" in capsys.readouterr().err and not out.exists()
    assert main(["deconvolve", str(src), str(path_file), str(out), "--overwrite", "--method", "tv",
                 "--iterations", "3", "--device", "cpu"]) == 0
    # colour: the colour TV unless --separate-channels
    colour = np.stack([blurred, blurred[::-1], blurred[:, ::-1]], axis=-1)
    np.savez(src, lf=colour)
    for flag, coupled in (([], True), (["--separate-channels"], False)):
        assert main(["deconvolve", str(src), str(path_file), str(out), "--overwrite", "--iterations", "3", *flag]) == 0
        ref = deconvolve(colour, cp, n_times=8, n_iter=3, couple_channels=coupled)
        np.testing.assert_allclose(read_lightfield(out), ref, atol=1e-5)
    # saturated samples: fitted as such unless --no-saturation
    bright = np.clip(1.3 * blurred, 0, 1)
    np.savez(src, lf=bright)
    for flag, saturation in (([], True), (["--no-saturation"], False)):
        assert main(["deconvolve", str(src), str(path_file), str(out), "--overwrite", "--iterations", "3", *flag]) == 0
        ref = deconvolve(bright, cp, n_times=8, n_iter=3, saturation=saturation)
        np.testing.assert_allclose(read_lightfield(out), ref, atol=1e-5)
    assert not np.allclose(ref, deconvolve(bright, cp, n_times=8, n_iter=3))
    np.savez(src, lf=blurred)
    # --along-views: the isotropic TV between the same pixel of neighbouring views
    assert main(["deconvolve", str(src), str(path_file), str(out), "--overwrite", "--iterations", "3",
                 "--along-views"]) == 0
    ref = deconvolve(blurred, cp, n_times=8, n_iter=3, angular="views", isotropic=True)
    np.testing.assert_allclose(read_lightfield(out), ref, atol=1e-5)
    assert not np.allclose(ref, deconvolve(blurred, cp, n_times=8, n_iter=3))
    # the weight the rule chose is stored with the result: given back, it restores the same light field
    assert main(["deconvolve", str(src), str(path_file), str(out), "--overwrite", "--iterations", "4"]) == 0
    chosen, meta = read_lightfield_with_metadata(out)
    used = meta["saved_metadata"]["parameters"]
    assert used["weight"] is None and used["weight_used"] > 0 and used["noise_sigma"] > 0
    assert f"weight {used['weight_used']!r})" in capsys.readouterr().out
    assert main(["deconvolve", str(src), str(path_file), str(out), "--overwrite", "--iterations", "4",
                 "--weight", repr(used["weight_used"])]) == 0
    np.testing.assert_array_equal(read_lightfield(out), chosen)
    # bad input: one line, exit status 2
    assert main(["deconvolve", str(src), str(path_file), str(out), "--overwrite", "--weight", "-1"]) == 2
    assert "weight" in capsys.readouterr().err
    assert main(["deconvolve", str(tmp_path / "missing.npz"), str(path_file), str(out), "--overwrite"]) == 2
    assert main(["deconvolve", str(src), str(tmp_path / "nopath.json"), str(out), "--overwrite"]) == 2
    # a path file stating T or d_inf the model cannot take: one line naming the file and the option
    capsys.readouterr()
    for field, value, option in (("n_times", 7.5, "--n-times"), ("infinity_disparity", "far", "--infinity-disparity")):
        (tmp_path / "odd.json").write_text(json.dumps({"control_points": cp.tolist(), field: value}))  # by hand
        assert main(["deconvolve", str(src), str(tmp_path / "odd.json"), str(out), "--overwrite"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"odd.json states {field} = {value!r}" in err and option in err


def test_cli_deconvolve_takes_the_path_the_input_holds(tmp_path, capsys):
    from napari_lfdeblur.cli import main
    from napari_lfdeblur.io import read_lightfield, write_lightfield

    lf = np.random.default_rng(9).random((5, 5, 10, 10)).astype(np.float32)
    cp = linear_path(1.5, angle_deg=30)
    blurred = simulate_blur(lf, cp, n_times=8, infinity_disparity=0.5)
    # an .npy holds no metadata: its path, T and d_inf are in blurred.path.json beside it
    src = write_lightfield(tmp_path / "blurred.npy", blurred, control_points=cp,
                           metadata={"n_times": 8, "infinity_disparity": 0.5})
    capsys.readouterr()
    assert main(["deconvolve", str(src), str(tmp_path / "out.npz"), "--iterations", "5", "--device", "cpu"]) == 0
    err = capsys.readouterr().err  # where T and d_inf came from is said
    assert f"using n_times = 8, as {src} states" in err and f"using infinity_disparity = 0.5, as {src} states" in err
    expected = deconvolve(blurred, cp, n_times=8, infinity_disparity=0.5, n_iter=5, device="cpu")
    np.testing.assert_allclose(read_lightfield(tmp_path / "out.npz"), expected, atol=1e-6)
    # a light field that holds no path: one line that says what to give
    np.save(tmp_path / "bare.npy", blurred)
    capsys.readouterr()
    assert main(["deconvolve", str(tmp_path / "bare.npy"), str(tmp_path / "o.npz")]) == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]  # (random views may also draw a view-order warning)
    assert "error" in last and "holds no camera path" in last and "PATH.json" in last
    assert not (tmp_path / "o.npz").exists()


def test_inplane_refuses_what_it_cannot_solve_and_says_what_to_use():
    lf = np.random.default_rng(0).random((3, 3, 8, 8)).astype(np.float32)
    cp = [[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]]
    for kwargs in ({"infinity_disparity": 0.5}, {"control_points": [[-0.5, 0.0, 0.2], [0.5, 0.0, -0.2]]}):
        args = {"control_points": cp, **kwargs}
        with pytest.raises(ValueError, match=r"needs an in-plane path .* Use method 'tv' \(command line: --method tv\)"):
            deconvolve(lf, args.pop("control_points"), n_times=4, method="inplane", **args)


@pytest.mark.parametrize("grid", [(3, 3), (3, 4)])
def test_inplane_with_a_weight_is_the_tikhonov_optimum_on_the_angular_differences(grid):
    """'inplane' solves min |K l - f|^2 / 2 + w |D_vu l|^2 / 2 (D_vu: forward differences along v and u): its
    result zeroes the gradient K^T (K l - f) + w D_vu^T D_vu l (D_vu^T D_vu: laplacian4d on the v, u axes)."""
    import torch

    from napari_lfdeblur.blur import BlurOperator
    from napari_lfdeblur.priors import laplacian4d

    V, U = grid
    lf = np.random.default_rng(0).random((V, U, 6, 7)).astype(np.float32)
    cp, w = linear_path(1.3, angle_deg=30), 0.05
    f = simulate_blur(lf, cp, n_times=8)
    out = deconvolve(f, cp, n_times=8, method="inplane", weight=w, clip=False, device="cpu")
    op = BlurOperator((V, U, 6, 7, 1), cp, n_times=8, device="cpu")
    residual = op.forward(torch.from_numpy(out)[..., None]) - torch.from_numpy(f)[..., None]
    gradient = op.adjoint(residual)[..., 0].double() + w * laplacian4d(torch.from_numpy(out).double(), (1, 1, 0, 0))
    assert float(gradient.abs().max()) < 1e-5


def test_the_plane_texture_sharpening_multiplies_each_frequency_by_one_plus_zeta_times_its_max_norm():
    """recover_plane_texture's correction multiplies the spectrum by 1 + zeta |Omega|, |Omega| = max(|Omega_x|,
    |Omega_y|) rad/px: a checkerboard, all at (pi, pi), is scaled by 1 + zeta pi; stripes at (0, pi) likewise."""
    from napari_lfdeblur.special_cases import _sharpen_slice

    y, x = np.indices((16, 16))
    for pattern in (np.where((y + x) % 2, 1.0, -1.0), np.where(x % 2, 1.0, -1.0)):
        out = _sharpen_slice(pattern.astype(np.float32), 0.5, 0.0)
        np.testing.assert_allclose(out, (1 + 0.5 * np.pi) * pattern, rtol=1e-5)
