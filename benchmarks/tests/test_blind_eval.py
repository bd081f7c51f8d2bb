"""Smoke test of benchmarks/blind_eval.py at tiny sizes (baseline only), and its bookkeeping."""

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


def test_quick_run_writes_a_table(blind_eval, tmp_path, capsys):
    out, js = tmp_path / "eval.md", tmp_path / "eval.json"
    assert blind_eval.main(["--quick", "--methods", "baseline2d", "--output", str(out), "--json", str(js)]) == 0
    text = out.read_text()
    assert "Quick smoke run" in text and "| syn-p2 | baseline2d |" in text
    rows = json.loads(js.read_text())["rows"]
    inp = next(r for r in rows if r["method"] == "input (blurred)")
    base = next(r for r in rows if r["method"] == "baseline2d")
    # the input's path error is that of "no motion": a blur mismatch of exactly 1
    assert inp["blur_mismatch"] == pytest.approx(1.0, rel=1e-4)
    assert base["gain"] == pytest.approx(base["psnr"] - inp["psnr"])
    assert base["seconds"] > 0 and "blur_mismatch" not in base  # the 2D baseline estimates no path


def test_partial_report_is_marked(blind_eval, tmp_path):
    import argparse

    args = argparse.Namespace(quick=False, cases_for=[], note=[], json=None)
    env = {"machine": "m", "device": "cpu", "torch": "t", "threads": 1, "date": "d", "command": "c", "load_start": "0"}
    rows = [{"case": "syn-p1", "method": "input (blurred)", "psnr": 30.0}]
    out = tmp_path / "partial.md"
    blind_eval.write(rows, [], ["baseline2d"], {}, args, env, out, final=False, n_done=1, n_all=6)
    text = out.read_text()
    assert "**Partial: 1 of 6 cases done" in text and "| syn-p1 | input (blurred) | 30.00 |" in text


def test_case_ground_truth_is_in_the_zero_mean_gauge(blind_eval):
    from napari_lfdeblur import bezier_positions, simulate_blur

    case = blind_eval.make_case("syn-p3", quick=True)
    assert np.abs(bezier_positions(case.control_points, blind_eval.RENDER_TIMES).mean(0)).max() < 1e-12
    pos = bezier_positions(case.control_points, 500)
    diameter = np.sqrt(((pos[:, None] - pos[None]) ** 2).sum(-1)).max()
    assert diameter == pytest.approx(blind_eval.PATHS["p3"][1], rel=1e-2)
    assert np.ptp(pos[:, 2]) > 0.1  # p3 moves in z
    # the blurred input is the T=128 blur of the ground truth plus small noise
    clean = simulate_blur(case.sharp, case.control_points, n_times=blind_eval.RENDER_TIMES)
    resid = case.blurred - clean
    assert abs(resid.std() - blind_eval.NOISE_SIGMA) < 3e-4
    with pytest.raises(ValueError, match="unknown case"):
        blind_eval.make_case("syn-p99", quick=True)


def test_targets_are_checked_not_assumed(blind_eval):
    rows = [
        {"case": "a", "method": "default", "psnr": 30.0, "angular": 0.01},
        {"case": "b", "method": "default", "psnr": 30.0, "angular": 0.01},
        {"case": "a", "method": "baseline2d", "psnr": 31.0, "angular": 0.02},
        {"case": "c", "method": "baseline2d", "psnr": 10.0, "angular": 0.00},  # not paired
    ]
    means = [
        {"method": "default", "group": "all", "seconds": 50.0, "seconds_max": 70.0, "gain": 4.5, "blur_mismatch": 0.15},
        # a subgroup's means never stand in for the means over all cases
        {"method": "default", "group": "held-out", "seconds": 5.0, "seconds_max": 5.0, "gain": 1.0, "blur_mismatch": 0.9},
    ]
    lines = blind_eval.targets(means, quick=False, rows=rows)
    met = [line for line in lines if line.startswith("- met")]
    unmet = [line for line in lines if line.startswith("- **not met**")]
    assert len(met) == 3 and len(unmet) == 2
    assert any("60 s" in line for line in unmet) and any("PSNR above" in line for line in unmet)
    assert any("angular" in line and "over 1 common" in line for line in met)
    assert "did not run" in blind_eval.targets([], quick=False)[0]


def test_summary_skips_failures_and_nan(blind_eval):
    rows = [
        {"case": "a", "method": "baseline2d", "psnr": 30.0, "gain": 1.0},
        {"case": "b", "method": "baseline2d", "psnr": 32.0, "gain": math.nan},
        {"case": "c", "method": "baseline2d", "error": "RuntimeError: boom"},
    ]
    (mean,) = blind_eval.summarise(rows, ["baseline2d"])
    assert mean["psnr"] == pytest.approx(31.0) and mean["gain"] == pytest.approx(1.0)
    assert mean["case"] == "**mean of 2**"


def test_summary_gives_scene_family_means_apart(blind_eval):
    rows = [
        {"case": "syn-p1", "method": "default", "gain": 6.0},
        {"case": "syn2-p4", "method": "default", "gain": 4.0},
        {"case": "lytro-p1", "method": "default", "gain": 2.0},
        {"case": "lytro3-p6", "method": "default", "gain": 1.0},
        {"case": "lytro4-p8", "method": "default", "gain": 0.0},
    ]
    means = {m["group"]: m for m in blind_eval.summarise(rows, ["default"])}
    assert means["all"]["gain"] == pytest.approx(2.6) and means["all"]["case"] == "**mean of 5**"
    assert means["synthetic"]["gain"] == pytest.approx(5.0)
    assert means["Lytro"]["gain"] == pytest.approx(1.0) and means["Lytro"]["case"] == "**mean of 3 Lytro**"
    # one family only: no family means beside the overall one
    assert [m["group"] for m in blind_eval.summarise(rows[:2], ["default"])] == ["all"]
    cases = blind_eval.CASES
    assert len(cases) == len(set(cases)) == 22
    assert sum(blind_eval._family(c) == "syn" for c in cases) == sum(blind_eval._family(c) == "lytro" for c in cases)


def test_peak_memory_sees_an_allocation(blind_eval):
    with blind_eval.PeakMemory("cpu") as mem:
        a = np.ones(64 * 2**20 // 8)  # 64 MiB, touched
        a += 1
        time.sleep(0.1)  # the sampler looks every 10 ms: hold the memory long enough to be seen
        del a
    assert 48 < mem.delta_mib < 1024
