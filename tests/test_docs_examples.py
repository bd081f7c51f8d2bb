"""The code blocks of docs/headless.md and of the README's API section, and the
Examples sections of the core modules' docstrings, run as written.

Blocks that import napari run in one subprocess (a viewer per block, closed by
the block); the others run here. Run under xvfb for the napari blocks:

    xvfb-run -a .venv/bin/python -m pytest tests/test_docs_examples.py
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "headless.md"
BLOCK = re.compile(r"```python\n(.*?)```", re.S)


README = DOC.parents[1] / "README.md"


def _blocks():
    """The blocks of headless.md, then those of the README's API section."""
    readme = README.read_text()
    start = readme.find("## Python API")
    section = readme[start: readme.find("\n## ", start + 5)] if start >= 0 else ""
    return BLOCK.findall(DOC.read_text()) + BLOCK.findall(section)


def _core_blocks():
    return [b for b in _blocks() if "napari_lfdeblur.widgets" not in b and "import napari\n" not in b]


def _viewer_blocks():
    return [b for b in _blocks() if b not in _core_blocks()]


def test_the_doc_has_both_kinds_of_example():
    assert len(_core_blocks()) >= 2 and len(_viewer_blocks()) >= 2


def _psnr_by_hand(estimate, reference):
    return 10 * np.log10(1 / np.mean((np.asarray(estimate, np.float64) - reference) ** 2))


def _deconvolution_gains(ns, out, seconds):
    # "PSNR blurred A -> deconvolved B": the two PSNRs of the block's arrays, and the known path restores
    (line,) = [line for line in out.splitlines() if line.startswith("PSNR blurred")]
    match = re.fullmatch(r"PSNR blurred (\S+) -> deconvolved (\S+)", line)
    before, after = float(match[1]), float(match[2])
    assert abs(before - _psnr_by_hand(ns["blurred"], ns["lf"])) < 0.01
    assert abs(after - _psnr_by_hand(ns["sharp"], ns["lf"])) < 0.01
    assert after > before + 3, line


def _progress_lines(ns, out, seconds):
    # one line a record, "stage iteration percent", the iterations counting up to at most n_iter=10
    records = [re.fullmatch(r"(\w+) (\d+) (\d+)%", line) for line in out.splitlines()]
    assert records and all(records), out
    assert [int(r[2]) for r in records] == list(range(1, len(records) + 1)) and len(records) <= 10, out
    percents = [int(r[3]) for r in records]
    assert percents == sorted(percents) and 0 < percents[-1] <= 100, out


def _stopped_early(ns, out, seconds):
    # the event, set after 0.5 s, stops the 100 000-iteration solve: Cancelled is raised and printed
    match = re.fullmatch(r"stopped after (\d+) iterations\n", out)
    assert match and int(match[1]) < 100_000, out
    assert ns["stop"].is_set() and seconds < 60, seconds


def _blind_result(ns, out, seconds):
    # "(n, 3), zero-mean gauge" (docs/model.md, Gauge: the mean of p(t_k) over the T instants is 0), then the
    # light field's shape, and the parameters as JSON: those the block set
    from napari_lfdeblur import BlindParams, bezier_positions

    result = ns["result"]
    assert result.control_points.ndim == 2 and result.control_points.shape[1] == 3
    mean = bezier_positions(result.control_points, result.params.n_times).mean(axis=0)
    np.testing.assert_allclose(mean, 0, atol=1e-6)
    assert "\n(5, 5, 24, 24) " in out and result.lightfield.shape == (5, 5, 24, 24)
    printed = BlindParams.from_json(out[out.index("\n{") + 1:])
    assert printed == BlindParams.preset("default").replace(path={"n_outer": 2, "n_restarts": 1}, final={"n_iter": 10})


def _readme_result(ns, out, seconds):
    # the README's comments: "(3, 3) control points", "(5, 5, 32, 32), (4, 3)", and a path file that states the
    # blur's n_times and infinity_disparity and the views' size
    from napari_lfdeblur.blind import BlindParams

    assert np.shape(ns["cp"]) == (3, 3)
    assert ns["result"].lightfield.shape == (5, 5, 32, 32) and ns["result"].control_points.shape == (4, 3)
    np.testing.assert_allclose(ns["path"], ns["result"].control_points, atol=1e-12)
    stated = ns["stated"]
    n_times = BlindParams.preset("default").n_times
    assert (stated["n_times"], stated["infinity_disparity"], stated["view_shape"]) == (n_times, 0.0, [32, 32])


#: a line that marks a block -> the check of the outputs its text and comments state
STATED = {
    'print("PSNR blurred"': _deconvolution_gains,
    "callback=lambda p: print(p.stage": _progress_lines,
    'print("stopped after"': _stopped_early,
    "print(result.params.to_json())": _blind_result,
    "result.lightfield, result.control_points": _readme_result,
}


def test_every_stated_output_is_checked():
    for marker in STATED:
        assert sum(marker in code for code in _core_blocks()) == 1, marker


@pytest.mark.parametrize("index", range(len(_core_blocks())))
def test_core_example_runs(index, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # examples may write files
    code = _core_blocks()[index]
    if "blind" in code:
        pytest.importorskip("napari_lfdeblur.blind")
    capsys.readouterr()
    namespace, start = {"__name__": "__doc_example__"}, time.perf_counter()
    exec(compile(code, f"{DOC.name}[core {index}]", "exec"), namespace)
    seconds, out = time.perf_counter() - start, capsys.readouterr().out
    for marker, check in STATED.items():
        if marker in code:
            check(namespace, out, seconds)


def test_viewer_examples_run(tmp_path):
    pytest.importorskip("napari")
    if not os.environ.get("DISPLAY") and os.environ.get("QT_QPA_PLATFORM") != "offscreen":
        pytest.skip("needs a display: run under xvfb-run")
    blocks = _viewer_blocks()
    runner = textwrap.dedent(
        """
        import sys
        blocks = {blocks!r}
        for i, code in enumerate(blocks):
            exec(compile(code, f"headless.md[viewer {{i}}]", "exec"), {{"__name__": "__doc_example__"}})
            print(f"block {{i}} ok", flush=True)
        """
    ).format(blocks=blocks)
    proc = subprocess.run([sys.executable, "-c", runner], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    assert proc.stdout.count(" ok") == len(blocks)


def _modules_with_examples():
    """The core modules (not ``_napari``, which needs Qt) whose docstrings hold ``>>>`` examples."""
    src = Path(__file__).resolve().parents[1] / "src"
    names = []
    for file in sorted((src / "napari_lfdeblur").rglob("*.py")):
        parts = file.relative_to(src).with_suffix("").parts
        if "_napari" in parts or ">>>" not in file.read_text():
            continue
        names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


def test_the_package_has_docstring_examples():
    assert {"napari_lfdeblur.blur", "napari_lfdeblur.deconvolution", "napari_lfdeblur.path"} <= set(
        _modules_with_examples())


@pytest.mark.parametrize("module", _modules_with_examples())
def test_docstring_examples_run(module, tmp_path, monkeypatch):
    """Every Examples section of the core modules runs and prints what it shows."""
    import doctest
    import importlib

    monkeypatch.chdir(tmp_path)  # examples may write files
    result = doctest.testmod(importlib.import_module(module), report=False,
                             optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {module} failed (see above)"


def test_the_screenshot_script_runs(tmp_path):
    """docs/make_screenshots.py, which makes the README's pictures of the widgets, still drives them."""
    pytest.importorskip("napari")
    if not os.environ.get("DISPLAY") and os.environ.get("QT_QPA_PLATFORM") != "offscreen":
        pytest.skip("needs a display: run under xvfb-run")
    script = DOC.parent / "make_screenshots.py"
    run = subprocess.run([sys.executable, str(script), "--quick", "--out", str(tmp_path)], capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "widget_blind.png", "widget_deconvolve.png", "widget_simulate.png"]
