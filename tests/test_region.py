"""The path window of large light fields: its choice, the path carried to the full frame, the pipeline."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from napari_lfdeblur.blind import BlindParams, blind_deblur, iter_blind_deblur
from napari_lfdeblur.blind._path_fit import GramLoss
from napari_lfdeblur.blind._region import choose_region, choose_regions
from napari_lfdeblur.path import path_in_frame, path_in_window
from napari_lfdeblur.blur import simulate_blur
from napari_lfdeblur.metrics import path_error
from napari_lfdeblur.progress import run_to_completion, with_previews
from napari_lfdeblur.path import bezier_positions, center_path
from napari_lfdeblur.samples import synthetic_scene


@pytest.mark.parametrize("window", [(0, 0, 24, 24), (20, 31, 24, 30), (36, 5, 28, 20)])
@pytest.mark.parametrize("d_inf", [0.0, 0.5])
def test_a_path_found_on_a_window_blurs_the_frame_as_it_blurred_the_window(window, d_inf):
    # independent expectation: the blur operator on the whole frame, cut to the window
    rng = np.random.default_rng(1)
    lf = rng.random((5, 5, 64, 72)).astype(np.float32)
    cp_window = np.array([[-0.7, 0.3, 0.9], [0.4, -0.5, -0.6], [0.6, 0.6, 0.4]])
    y0, x0, h, w = window
    on_window = simulate_blur(lf[:, :, y0:y0 + h, x0:x0 + w], cp_window, n_times=16, infinity_disparity=d_inf)
    on_frame = simulate_blur(lf, path_in_frame(cp_window, window, (64, 72)), n_times=16,
                             infinity_disparity=d_inf)[:, :, y0:y0 + h, x0:x0 + w]
    # d_inf = 0: the blur is per pixel (over the views), exact everywhere; d_inf != 0 moves samples
    # spatially, so the window's replicate border differs from the frame's pixels there
    m = 0 if d_inf == 0 else 3
    inner = (slice(None), slice(None), slice(m, h - m), slice(m, w - m))
    np.testing.assert_allclose(on_window[inner], on_frame[inner], atol=2e-6)
    assert np.abs(on_window - simulate_blur(lf, cp_window, n_times=16, infinity_disparity=d_inf)[
        :, :, y0:y0 + h, x0:x0 + w]).max() > 1e-2 or window[2:] == (64, 72)  # the conversion mattered


@pytest.mark.parametrize("window, frame, said", [
    ((0, 0, 0, 0), (64, 64), "does not lie in a 64x64 frame"),  # was +-inf control points (or p_z set to 0)
    ((200, 200, 16, 16), (64, 64), "does not lie in a 64x64 frame"),
    ((0, 0, -8, 16), (64, 64), "does not lie"),
    ((0, 0, 10), (64, 64), "window must be 4 whole numbers"),
    ((0, 0, 16, 16), (0, 0), "does not lie in a 0x0 frame"),
    ((0, 0, 16.5, 16), (64, 64), "window must be 4 whole numbers"),
])
def test_a_window_outside_its_frame_is_refused(window, frame, said):
    for move in (path_in_frame, path_in_window):
        with pytest.raises(ValueError, match=said):
            move([[-0.5, 0.0, 0.4], [0.5, 0.0, -0.4]], window, frame)


def test_the_whole_frame_as_window_leaves_the_path_unchanged():
    cp = np.array([[-0.7, 0.3, 0.9], [0.4, -0.5, -0.6]])
    np.testing.assert_allclose(path_in_frame(cp, (0, 0, 40, 50), (40, 50)), cp)
    np.testing.assert_allclose(path_in_window(cp, (0, 0, 40, 50), (40, 50)), cp)


@pytest.mark.parametrize("window", [(0, 0, 24, 24), (20, 31, 24, 30), (36, 5, 28, 20)])
@pytest.mark.parametrize("d_inf", [0.0, 0.5])
def test_a_frame_path_in_a_window_blurs_the_window_as_the_frame_was_blurred(window, d_inf):
    # independent expectation: the blur operator on the whole frame, cut to the window
    rng = np.random.default_rng(2)
    lf = rng.random((5, 5, 64, 72)).astype(np.float32)
    cp_frame = np.array([[0.6, -0.4, 0.5], [-0.3, 0.7, -0.8], [0.2, -0.2, 0.6]])
    y0, x0, h, w = window
    on_frame = simulate_blur(lf, cp_frame, n_times=16, infinity_disparity=d_inf)[:, :, y0:y0 + h, x0:x0 + w]
    cp_window = path_in_window(cp_frame, window, (64, 72))
    on_window = simulate_blur(lf[:, :, y0:y0 + h, x0:x0 + w], cp_window, n_times=16, infinity_disparity=d_inf)
    m = 0 if d_inf == 0 else 3  # d_inf != 0: the window's replicate border differs from the frame's pixels
    inner = (slice(None), slice(None), slice(m, h - m), slice(m, w - m))
    np.testing.assert_allclose(on_window[inner], on_frame[inner], atol=2e-6)
    # and it is path_in_frame's inverse
    np.testing.assert_allclose(path_in_frame(cp_window, window, (64, 72)), cp_frame, atol=1e-12)
    assert np.abs(cp_window - cp_frame).max() > 0.1  # the conversion mattered


def _textured_lf(texture, at, shape=(3, 3, 96, 96)):
    """A flat grey light field (no disparity: every view the same) with ``texture`` pasted at ``at``."""
    img = np.full(shape[2:], 0.5)
    (y, x), (h, w) = at, texture.shape
    img[y:y + h, x:x + w] = texture
    lf = np.broadcast_to(img, shape).astype(np.float32)
    return torch.as_tensor(np.ascontiguousarray(lf))[..., None]


def test_choose_region_finds_the_only_textured_patch():
    tex = np.random.default_rng(2).random((24, 24))
    g = _textured_lf(tex, (60, 10))
    y0, x0, h, w = choose_region(g, 32, disparity_power=0.0)
    assert (h, w) == (32, 32)
    assert y0 <= 60 and y0 + 32 >= 84 and x0 <= 10 and x0 + 32 >= 34


def test_choose_region_prefers_edges_in_two_directions_to_parallel_stripes():
    # stripes along x constrain the blur across them only; a checkerboard of the same contrast in both
    yy, xx = np.mgrid[:32, :32]
    stripes = 0.5 + 0.4 * np.sign(np.sin(yy * np.pi / 4))
    checks = 0.5 + 0.4 * np.sign(np.sin(yy * np.pi / 4)) * np.sign(np.sin(xx * np.pi / 4))
    img = np.full((96, 160), 0.5)
    img[10:42, 10:42] = stripes
    img[50:82, 110:142] = checks
    g = torch.as_tensor(np.broadcast_to(img, (3, 3, 96, 160)).astype(np.float32).copy())[..., None]
    y0, x0, _, _ = choose_region(g, 40, disparity_power=0.0)
    assert 40 <= y0 <= 52 and 100 <= x0 <= 112


def test_blind_on_a_large_view_estimates_the_path_on_a_window_and_restores_the_whole():
    sharp, _ = synthetic_scene((5, 5, 96, 128), seed=3)
    cp = np.array([[-0.8, 0.3, 0.4], [0.2, -0.6, -0.3], [0.7, 0.5, 0.2]])
    blurred = simulate_blur(sharp, cp, n_times=32)
    quick = dict(path=dict(n_outer=3, steps=100, n_random=100, n_random_later=40, z_outer=1), final={"n_iter": 30},
                 final_n_times=16, require_evidence=False, n_control_points=3)
    one_window = BlindParams().replace(**quick).replace(path={"region": 48, "n_regions": 1})
    windowed = blind_deblur(blurred, params=one_window, device="cpu", seed=0)
    y0, x0, h, w = windowed.info["window"]
    assert (h, w) == (48, 48)
    # the same pipeline on the window alone (the crop pipeline), carried to the frame
    crop = blind_deblur(blurred[:, :, y0:y0 + h, x0:x0 + w], params=BlindParams().replace(**quick), device="cpu",
                        seed=0)
    frame = center_path(path_in_frame(crop.control_points, (y0, x0, h, w), (96, 128)), 32)
    T = 32
    pos = bezier_positions(center_path(windowed.control_points, T), T)
    np.testing.assert_allclose(pos, bezier_positions(frame, T), atol=1e-6)
    # and the path is near the true one, so the whole frame is restored
    truth = bezier_positions(center_path(cp, T), T)
    assert np.abs(pos - truth).max() < 0.5  # measured 0.34 (the path spans about 1.6 views)
    err_in, err_out = np.abs(blurred - sharp).mean(), np.abs(windowed.lightfield - sharp).mean()
    assert windowed.lightfield.shape == sharp.shape and err_out < 0.7 * err_in


@pytest.mark.parametrize("window", [(0, 0, 24, 24), (20, 31, 24, 30), (36, 5, 28, 20)])
def test_the_path_fit_of_a_window_in_its_frame_equals_the_fit_of_the_path_moved_into_the_window(window):
    # independent expectation: the window's own fit of the frame path moved by path_in_window
    rng = np.random.default_rng(4)
    y0, x0, h, w = window
    f = torch.as_tensor(rng.random((5, 5, h, w, 1), dtype=np.float32))
    latent = torch.as_tensor(rng.random((5, 5, h, w, 1), dtype=np.float32))
    cps = rng.uniform(-0.8, 0.8, (6, 3, 3))
    fits = []
    for frame, paths in (((y0, x0, 64, 72), cps), (None, [path_in_window(c, window, (64, 72)) for c in cps])):
        fit = GramLoss(f, 200, np.random.default_rng(0), 16, 2.0, 1.0, 2, frame=frame)
        fit.set_latent(latent)
        fits.append(fit(torch.as_tensor(np.stack(paths), dtype=torch.float32)).numpy())
    np.testing.assert_allclose(fits[0], fits[1], rtol=1e-4)
    assert np.ptp(fits[0]) > 0.01 * np.abs(fits[0]).max()  # the paths fit differently


def test_choose_regions_spreads_its_windows_one_per_cell():
    rng = np.random.default_rng(5)
    g = torch.as_tensor(rng.random((3, 3, 100, 150, 1), dtype=np.float32))
    windows = choose_regions(g, 40, disparity_power=0.0, n=4)
    assert len(windows) == 4 and all((h, w) == (40, 40) for _, _, h, w in windows)
    cells = {(y0 >= 50, x0 >= 75) for y0, x0, _, _ in windows}  # 2 x 2 cells: one window in each
    assert cells == {(False, False), (False, True), (True, False), (True, True)}
    for i, (ya, xa, _, _) in enumerate(windows):
        for yb, xb, _, _ in windows[i + 1:]:
            assert abs(ya - yb) >= 40 or abs(xa - xb) >= 40  # no overlap
    # a view that holds one window per row only: a row of windows
    assert len(choose_regions(g[:, :, :60], 40, 0.0, n=4)) == 2
    assert choose_regions(g, 40, 0.0, n=1) == [choose_region(g, 40, 0.0)]
    assert choose_regions(g[:, :, :40, :40], 40, 0.0, n=4) == [(0, 0, 40, 40)]
    # cells that hold a window but not its margin from the view's edges (d_inf != 0): the windows stay in their
    # cells, disjoint (the margin pushed them into their neighbours'), and the margin is kept where it fits
    tight = choose_regions(g[:, :, :80, :80], 40, 0.0, margin=3, n=4)
    assert sorted(tight) == [(0, 0, 40, 40), (0, 40, 40, 40), (40, 0, 40, 40), (40, 40, 40, 40)]
    assert all(3 <= y0 <= 100 - 43 and 3 <= x0 <= 150 - 43 for y0, x0, _, _ in choose_regions(g, 40, 0.0, 3, 4))


def test_blind_on_a_large_view_fits_one_path_to_several_windows():
    sharp, _ = synthetic_scene((5, 5, 96, 128), seed=3)
    cp = np.array([[-0.8, 0.3, 0.4], [0.2, -0.6, -0.3], [0.7, 0.5, 0.2]])
    blurred = simulate_blur(sharp, cp, n_times=32)
    quick = dict(path=dict(n_outer=3, steps=100, n_random=100, n_random_later=40, z_outer=1, region=48, n_regions=4),
                 final={"n_iter": 30}, final_n_times=16, require_evidence=False, n_control_points=3)
    previews = []

    def collect(rec):
        if rec.stage.startswith("path") and rec.preview is not None:
            previews.append(rec.preview)

    gen = with_previews(iter_blind_deblur(blurred, params=BlindParams().replace(**quick), device="cpu", seed=0), 5)
    res = run_to_completion(gen, collect)
    windows = res.info["windows"]
    assert len(windows) == 4 and res.info["window"] == windows[0]
    # the previews show every window's latent where it is in the frame (none of them is the first's edge padding,
    # which is constant along y or along x)
    assert previews
    for prev in previews:
        for y0, x0, h, w in windows:
            region = prev[:, :, y0:y0 + h, x0:x0 + w]
            assert np.ptp(region, axis=2).max() > 0 and np.ptp(region, axis=3).max() > 0
    # the path is the frame's: it blurs the whole frame nearly as the true one does, and restores it
    assert path_error(res.control_points, cp, lightfield=sharp).blur_mismatch < 0.25  # measured 0.13
    err_in, err_out = np.abs(blurred - sharp).mean(), np.abs(res.lightfield - sharp).mean()
    assert err_out < 0.7 * err_in


_PEAK_SCRIPT = r"""
import json
import os
import threading

import numpy as np
from napari_lfdeblur.blind import BlindParams, blind_deblur, estimate_blind_memory
from napari_lfdeblur.blur import simulate_blur

page = os.sysconf("SC_PAGE_SIZE")

def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * page

def reset_high_water_mark():
    # writing 5 to clear_refs resets the kernel's peak resident set size (VmHWM); not every kernel allows it
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False

def high_water_mark():
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmHWM:"))

shape = (5, 5, 224, 224, 3)
lf = np.random.default_rng(0).random(shape, dtype=np.float32)
blurred = simulate_blur(lf, [[-0.6, 0.2, -0.3], [0.5, -0.3, 0.3]], n_times=8)
del lf
p = BlindParams().replace(n_control_points=2, final_n_times=8, require_evidence=False, final={"n_iter": 3, "tol": 0.0},
                          path=dict(n_outer=1, steps=20, n_random=20, n_random_later=5, z_outer=1, region=32))
exact = reset_high_water_mark()
base = rss()
peak, stop = [base], threading.Event()

def sample():
    while not stop.wait(0.003):
        peak[0] = max(peak[0], rss())

thread = threading.Thread(target=sample, daemon=True)
thread.start()
blind_deblur(blurred, params=p, device="cpu")
stop.set()
thread.join()
top = max(peak[0], rss(), high_water_mark() if exact else 0)
print(json.dumps({"measured": top - base, "estimate": estimate_blind_memory(shape, p), "exact": exact}))
"""


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="reads the resident set size from /proc")
def test_the_memory_estimate_is_within_30_percent_of_the_measured_peak():
    # A fresh process, so that nothing else's memory counts. The peak is the kernel's high-water mark of the resident
    # set, reset just before the solve (sampling every 3 ms where the kernel refuses the reset). A fixed mmap
    # threshold makes glibc hand every large block back on free, so that blocks freed before the solve cannot be
    # reused unseen by it.
    env = {**os.environ, "OMP_NUM_THREADS": "2", "MALLOC_MMAP_THRESHOLD_": "65536"}
    out = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT], capture_output=True, text=True, check=True, env=env)
    m = json.loads(out.stdout.strip().splitlines()[-1])
    assert abs(m["estimate"] - m["measured"]) <= 0.3 * m["measured"], m


def test_choose_region_keeps_the_margin_from_the_edges():
    tex = np.random.default_rng(3).random((24, 24))
    g = _textured_lf(tex, (0, 0))  # the only texture in the corner
    y0, x0, _, _ = choose_region(g, 32, disparity_power=0.0, margin=5)
    assert y0 >= 5 and x0 >= 5
    assert choose_region(g, 32, disparity_power=0.0)[:2] == (0, 0)
    # a view too small for the margin: the window is centred
    assert choose_region(_textured_lf(tex, (0, 0), shape=(3, 3, 36, 96)), 32, 0.0, margin=5)[0] == 2


def test_final_stage_progress_counts_every_channel_and_only_grows():
    from napari_lfdeblur.blind import iter_blind_deblur
    from napari_lfdeblur.progress import run_to_completion

    sharp, _ = synthetic_scene((3, 3, 24, 24), color=True, seed=1)
    blurred = simulate_blur(sharp, [[-0.5, 0.2, 0.0], [0.5, -0.2, 0.0]], n_times=8)
    p = BlindParams().replace(n_control_points=2, n_times=8, final_n_times=8, require_evidence=False,
                              final={"n_iter": 3, "tol": 0.0, "couple_channels": False},
                              path=dict(n_outer=1, steps=5, n_random=5, n_random_later=1, z_outer=1))
    records = []
    run_to_completion(iter_blind_deblur(blurred, params=p, device="cpu"), records.append)
    final = [r for r in records if r.stage == "final"]
    assert [r.iteration for r in final] == list(range(1, 10)) and {r.n_iterations for r in final} == {9}
    assert [r.info["channel"] for r in final] == [0, 0, 0, 1, 1, 1, 2, 2, 2]
    fractions = [r.fraction for r in records if r.fraction is not None]
    assert fractions == sorted(fractions)
    # the colour TV (the default) solves the channels at once: one count
    records = []
    run_to_completion(iter_blind_deblur(blurred, params=p.replace(final={"couple_channels": True}), device="cpu"),
                      records.append)
    final = [r for r in records if r.stage == "final"]
    assert [r.iteration for r in final] == [1, 2, 3] and {r.n_iterations for r in final} == {3}


def test_check_windows_takes_windows_up_to_the_view_edge_and_touching_windows_but_not_one_px_beyond():
    from napari_lfdeblur.blind._windows import check_windows

    p = BlindParams()  # 3dof, alternating: several windows allowed
    shape = (5, 5, 40, 80)
    # a window reaching exactly to the far edge lies inside the view; one px further does not
    assert check_windows([(0, 40, 40, 40)], shape, p) == [(0, 40, 40, 40)]
    for outside in [(1, 0, 40, 40), (0, 41, 40, 40)]:
        with pytest.raises(ValueError, match="reaches outside"):
            check_windows([outside], shape, p)
    # two halves of the view touch but share no pixel: they do not overlap
    halves = [(0, 0, 40, 40), (0, 40, 40, 40)]
    assert check_windows(halves, shape, p) == halves
    with pytest.raises(ValueError, match="overlap"):
        check_windows([(0, 0, 40, 41), (0, 40, 40, 40)], shape, p)


@pytest.mark.parametrize("d_inf", [1.5, -1.5])
def test_chosen_windows_keep_the_refocusing_margin_for_either_sign_of_the_infinity_disparity(d_inf):
    from napari_lfdeblur.blind._windows import path_windows

    # refocused samples read |d_inf| (max(V, U) - 1) / 2 px beyond the view (choose_region): 1.5 * 4 / 2 = 3 px
    arr = np.full((5, 5, 100, 100), 0.5, np.float32)
    arr[:, :, :30, :30] = np.random.default_rng(3).random((30, 30))  # the only texture in a corner
    p = BlindParams().replace(path={"region": 40, "n_regions": 1})
    _, windows = path_windows(arr, d_inf, p, torch.device("cpu"), True)
    assert len(windows) == 1 and windows[0][2:] == (40, 40)
    assert windows[0][0] >= 3 and windows[0][1] >= 3


def test_region_grid_puts_its_rows_along_the_shorter_side():
    from napari_lfdeblur.blind._region import region_grid

    # region_grid: rows the largest divisor of n not above sqrt(n), along the shorter side of the view
    assert region_grid(100, 300, 40, 2) == (1, 2)
    assert region_grid(300, 100, 40, 2) == (2, 1)
    assert region_grid(100, 300, 40, 6) == (2, 3)
    g = torch.as_tensor(np.random.default_rng(5).random((3, 3, 100, 300, 1), dtype=np.float32))
    windows = choose_regions(g, 40, 0.0, n=2)
    # one window in each half of the 300-px side
    assert sorted(x0 + w <= 150 for _, x0, _, w in windows) == [False, True]
    assert all(x0 >= 150 for _, x0, _, w in windows if x0 + w > 150)


def test_choose_region_tries_the_window_flush_with_the_far_edges():
    # choose_region: candidate corners on a grid of step size // 8, the last one flush with the far edge; with
    # size 38 the step is 4 and y0 = 100 - 38 = 62 is off that grid, so only the flush candidate reaches the
    # texture's far rows
    img = np.full((100, 150), 0.5)
    img[80:, 130:] = np.random.default_rng(2).random((20, 20))
    g = torch.as_tensor(np.broadcast_to(img, (3, 3, 100, 150)).astype(np.float32).copy())[..., None]
    y0, x0, h, w = choose_region(g, 38, 0.0)
    assert (y0 + h, x0 + w) == (100, 150)
