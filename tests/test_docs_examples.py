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
from pathlib import Path

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


@pytest.mark.parametrize("index", range(len(_core_blocks())))
def test_core_example_runs(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # examples may write files
    code = _core_blocks()[index]
    if "blind" in code:
        pytest.importorskip("napari_lfdeblur.blind")
    exec(compile(code, f"{DOC.name}[core {index}]", "exec"), {"__name__": "__doc_example__"})


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
