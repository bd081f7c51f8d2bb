"""Smoke test of benchmarks/blind_eval.py at tiny sizes (non-blind truepath only), its cases and bookkeeping."""

import importlib.util
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "blind_eval.py"


@pytest.fixture(scope="module")
def blind_eval():
    spec = importlib.util.spec_from_file_location("blind_eval", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["blind_eval"] = mod  # dataclasses look their module up there
    try:
        spec.loader.exec_module(mod)
        yield mod
    finally:
        sys.modules.pop("blind_eval", None)


def test_quick_run_writes_a_table(blind_eval, tmp_path):
    out, js = tmp_path / "eval.md", tmp_path / "eval.json"
    # dev04: a rendered scene at d_inf = 0 (always available); truepath is the cheap, non-blind method
    assert blind_eval.main(["--quick", "--cases", "dev04", "--methods", "truepath", "--output", str(out),
                            "--json", str(js)]) == 0
    text = out.read_text()
    assert "Quick smoke run" in text and "Development split" in text
    assert "| dev04 | rendered | +0 |" in text and "| truepath |" in text and "## By blur length" in text
    data = json.loads(js.read_text())
    rows = data["rows"]
    inp = next(r for r in rows if r["method"] == "input (blurred)")
    tp = next(r for r in rows if r["method"] == "truepath")
    # the input's path error is that of "no motion": a blur mismatch of exactly 1
    assert inp["blur_mismatch"] == pytest.approx(1.0, rel=1e-4)
    assert tp["gain"] == pytest.approx(tp["psnr"] - inp["psnr"]) and tp["gain"] > 0
    assert tp["seconds"] > 0 and "blur_mismatch" not in tp  # the true path is given, not estimated
    assert len(data["cases"]) == 1 and data["split"] == "dev"


def test_a_full_run_warms_each_method_up_on_a_tiny_case_first(blind_eval, tmp_path, monkeypatch):
    calls, real, real_make = [], blind_eval.run_method, blind_eval.make_case

    def spy(method, case, device, quick):
        calls.append((method, quick))
        return real(method, case, device, True)

    monkeypatch.setattr(blind_eval, "run_method", spy)
    monkeypatch.setattr(blind_eval, "make_case", lambda spec, quick=False: real_make(spec, quick=True))  # tiny
    assert blind_eval.main(["--cases", "dev04", "--methods", "truepath", "--output", str(tmp_path / "e.md")]) == 0
    # the warm-up's call (quick) comes before the timed one
    assert calls == [("truepath", True), ("truepath", False)]


def test_splits_cover_the_set_and_do_not_overlap(blind_eval):
    es = blind_eval.eval_set
    dev, test = es.split_cases("dev"), es.split_cases("test")
    assert len(dev) == 18 and len(test) == 24
    for cases in (dev, test):
        assert {c.group for c in cases} == set(es.GROUPS)
        assert {c.infinity_disparity for c in cases} == set(es.D_INF)
        assert {c.noise for c in cases} == set(es.NOISE)
        for g in es.GROUPS:  # each group: d_inf = 0 and != 0, both noise levels
            sel = [c for c in cases if c.group == g]
            assert {c.infinity_disparity == 0 for c in sel} == {True, False}
            assert {c.noise for c in sel} == set(es.NOISE)
        kinds = [c.kind for c in cases]
        assert kinds.count("none") == 1 and kinds.count("barely") == 2  # the "do no harm" cases
        assert all(0.3 <= c.extent <= 4.0 for c in cases if c.kind != "none")
        assert sum(c.z_ratio > 0 for c in cases) > len(cases) / 2  # most paths move in z
    assert not {c.scene for c in dev} & {c.scene for c in test}
    assert not {c.path_seed for c in dev} & {c.path_seed for c in test}
    assert es.split_cases("dev") == dev  # fixed: the same on every call
    with pytest.raises(ValueError, match="unknown split"):
        es.split_cases("train")


def test_case_ground_truth_is_in_the_zero_mean_gauge(blind_eval):
    from napari_lfdeblur import bezier_positions, simulate_blur

    spec = next(c for c in blind_eval.eval_set.split_cases("dev") if c.group == "rendered" and c.z_ratio > 0
                and c.infinity_disparity != 0 and c.kind == "blurred")
    case = blind_eval.make_case(spec, quick=True)
    assert np.abs(bezier_positions(case.control_points, blind_eval.RENDER_TIMES).mean(0)).max() < 1e-12
    pos = bezier_positions(case.control_points, 500)
    diameter = np.sqrt(((pos[:, None] - pos[None]) ** 2).sum(-1)).max()
    assert diameter == pytest.approx(spec.extent, rel=1e-2)
    assert np.ptp(pos[:, 2]) > 0.05
    # the blurred input is the T=128 blur at the case's d_inf of the ground truth, plus the case's noise
    clean = simulate_blur(case.sharp, case.control_points, n_times=blind_eval.RENDER_TIMES,
                          infinity_disparity=spec.infinity_disparity)
    resid = case.blurred - clean
    assert abs(resid.std() - spec.noise) < 0.15 * spec.noise
    with pytest.raises(ValueError, match="unknown case"):
        blind_eval.select_cases("dev", ["test03"])


def test_no_blur_case_is_the_sharp_light_field_plus_noise(blind_eval):
    spec = next(c for c in blind_eval.eval_set.split_cases("dev") if c.kind == "none")
    assert not blind_eval.eval_set.true_path(spec).any()
    if blind_eval.eval_set.capture_available(spec.group):
        case = blind_eval.make_case(spec, quick=True)
        assert np.abs(case.blurred - case.sharp).max() < 8 * spec.noise


def test_partial_report_is_marked_and_says_the_split(blind_eval, tmp_path):
    import argparse

    args = argparse.Namespace(quick=False, note=[], json=None, split="test", frozen=False, method_list=["truepath"])
    env = {"machine": "m", "device": "cpu", "torch": "t", "threads": 1, "command": "c"}
    rows = [{"case": "test03", "group": "rendered", "d_inf": 0.5, "method": "input (blurred)", "psnr": 30.0}]
    specs = blind_eval.eval_set.split_cases("test")[:4]
    out = tmp_path / "partial.md"
    blind_eval.write(rows, [], specs, {}, args, env, out, final=False, n_done=1, n_all=6)
    text = out.read_text()
    assert "**Partial: 1 of 6 cases done" in text and "| test03 | rendered | +0.5 |" in text
    assert "not marked frozen" in text
    args.frozen = True
    blind_eval.write(rows, [], specs, {}, args, env, out, final=False, n_done=1, n_all=6)
    assert "run after the method was frozen" in out.read_text()
    assert blind_eval.table_for("test").name == "blind_eval_test.md"


def test_targets_are_checked_not_assumed(blind_eval):
    rows = [
        {"case": "a", "group": "rendered", "d_inf": 0.0, "method": "default", "gain": 6.0, "blur_mismatch": 0.1,
         "seconds": 50.0},
        {"case": "b", "group": "Illum", "d_inf": 1.0, "method": "default", "gain": -0.5, "blur_mismatch": 0.9,
         "seconds": 70.0},
        {"case": "b", "group": "Illum", "d_inf": 1.0, "method": "truepath", "gain": 7.0, "seconds": 3.0},
    ]
    means = blind_eval.summarise(rows, ["default", "truepath"])
    lines = blind_eval.targets(means, quick=False)
    unmet = [line for line in lines if line.startswith("- **not met**")]
    met = [line for line in lines if line.startswith("- met")]
    assert any("worse than the input" in line and "-0.50" in line for line in unmet)
    assert any("60 s" in line for line in unmet)
    assert any("`default`, all: mean gain" in line and "+2.75" in line for line in unmet)
    assert any("`default`, Illum: mean gain" in line for line in unmet)
    assert any("`default`, all: mean blur mismatch" in line for line in unmet)  # (0.1 + 0.9) / 2
    assert any("`truepath`, d_inf ≠ 0" in line for line in met) and any("10 s" in line for line in met)
    assert "no method" in blind_eval.targets([], quick=False)[0]


def test_summary_by_group_skips_failures_and_nan(blind_eval):
    rows = [
        {"case": "a", "group": "rendered", "d_inf": 0.0, "method": "input (blurred)", "psnr": 28.0},
        {"case": "b", "group": "F01", "d_inf": 0.5, "method": "input (blurred)", "psnr": 30.0},
        {"case": "a", "group": "rendered", "d_inf": 0.0, "method": "truepath", "psnr": 30.0, "gain": 2.0},
        {"case": "b", "group": "F01", "d_inf": 0.5, "method": "truepath", "psnr": 31.0, "gain": 1.0,
         "blur_mismatch": math.nan},
        {"case": "c", "group": "F01", "d_inf": 0.5, "method": "truepath", "error": "RuntimeError: boom"},
    ]
    means = {m["group"]: m for m in blind_eval.summarise(rows, ["truepath"])}
    assert set(means) == {"all", "rendered", "F01", "d_inf = 0", "d_inf ≠ 0"}
    assert means["all"]["n"] == 2 and means["all"]["gain"] == pytest.approx(1.5)
    assert means["all"]["blurred_psnr"] == pytest.approx(29.0) and means["all"]["blur_mismatch"] is None
    assert means["all"]["worst_gain"] == 1.0 and means["all"]["worst_case"] == "b"
    assert means["d_inf = 0"]["psnr"] == pytest.approx(30.0) and means["F01"]["n"] == 1


def test_blur_length_of_a_straight_uniform_motion_is_its_image_length(blind_eval):
    es = blind_eval.eval_set
    rng = np.random.default_rng(0)
    sharp = rng.random((3, 3, 24, 32, 3)).astype(np.float32)
    # a straight motion of 2 views along x, at constant speed (a linear Bezier path), no p_z
    cp = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    T = es.RENDER_TIMES
    exact = 2.0 * math.sqrt((T + 1) / (T - 1))  # sqrt(12) x the RMS of T evenly spaced positions over 2 views
    flat = np.full((24, 32), 0.75, np.float32)
    # every point 0.75 - (-0.5) = 1.25 px/view from infinity: the image moves 1.25 x 2 views = 2.5 px
    assert es.blur_length(cp, sharp, flat, -0.5) == pytest.approx(1.25 * exact, rel=1e-9)
    assert es.blur_length(cp, sharp, flat, 0.75) == 0.0  # points at infinity do not move
    assert es.blur_length(np.zeros((2, 3)), sharp, flat, 0.0) == 0.0
    # in y by the same amount: the same length; both: the lengths add in quadrature
    assert es.blur_length(cp[:, [1, 0, 2]], sharp, flat, -0.5) == pytest.approx(1.25 * exact, rel=1e-9)
    both = cp + cp[:, [1, 0, 2]]
    assert es.blur_length(both, sharp, flat, -0.5) == pytest.approx(1.25 * exact * math.sqrt(2), rel=1e-9)
    # the motion of flat regions does not count: disparity only where the image has no gradient
    sharp[..., :, 16:, :] = 0.5
    split = flat.copy()
    split[:, 17:] = 10.0
    assert es.blur_length(cp, sharp, split, -0.5) == pytest.approx(1.25 * exact, rel=1e-9)


def test_summary_by_blur_length(blind_eval):
    rows = [
        {"case": "a", "method": "input (blurred)", "psnr": 30.0, "blur_px": 0.5},
        {"case": "b", "method": "input (blurred)", "psnr": 28.0, "blur_px": 3.0},
        {"case": "a", "method": "default", "psnr": 30.0, "gain": 0.0, "blur_px": 0.5, "restored_blur_px": 0.0,
         "estimate_blur_px": 1.0},
        {"case": "b", "method": "default", "psnr": 32.0, "gain": 4.0, "blur_px": 3.0, "restored_blur_px": 4.5,
         "estimate_blur_px": 4.5},
    ]
    means = {m["group"]: m for m in blind_eval.summarise(rows, ["default"], blind_eval.BLUR_GROUPS)}
    assert set(means) == {"no blur or < 1 px", "≥ 2 px"}
    assert means["≥ 2 px"]["gain"] == 4.0 and means["≥ 2 px"]["length_ratio"] == pytest.approx(1.5)
    low = means["no blur or < 1 px"]
    assert low["length_ratio"] == 0.0 and low["estimate_ratio"] == pytest.approx(2.0)  # returned, found 2x
    table = "\n".join(blind_eval._blur_table(list(means.values())))
    assert "| ≥ 2 px | default | 1 | 28.00 | +4.00 |" in table and "| 0.00 | 2.00 |" in table


def test_peak_memory_sees_an_allocation(blind_eval):
    with blind_eval.PeakMemory("cpu") as mem:
        a = np.ones(64 * 2**20 // 8)  # 64 MiB, touched
        a += 1
        time.sleep(0.1)  # the sampler looks every 10 ms: hold the memory long enough to be seen
        del a
    assert 48 < mem.delta_mib < 1024
