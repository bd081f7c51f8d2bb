"""Interrupting ``lfdeblur batch`` for real: Ctrl-C to the whole process group, a killed scheduler.

Each test runs the command in a subprocess (its own process group, as a shell
job), interrupts it while items are running, then checks what is on disk:
every output file is complete and equal to the serial API's, and a rerun
completes the set.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")
pytestmark = [pytest.mark.filterwarnings("ignore::napari_lfdeblur.io.ViewOrderWarning"),
              pytest.mark.skipif(sys.platform == "win32", reason="process groups and POSIX signals")]

from napari_lfdeblur import read_lightfield, write_lightfield  # noqa: E402
from napari_lfdeblur.batch import read_manifest, simulate_item  # noqa: E402

# after the first record, the other 2 * N_PER_INPUT - 1 items (a few ms of work each, plus the cluster's
# overhead) take about half a second on two workers: far longer than the test needs to send the signal
N_PER_INPUT = 16
N_TIMES = 1024
OPTIONS = ["--n-per-input", str(N_PER_INPUT), "--path-kind", "shake", "--extent", "1.5", "--noise", "0.01",
           "--n-times", str(N_TIMES), "--device", "cpu", "--seed", "7"]


def _as_in_a_terminal():
    """Ctrl-C's default action in the child, as in a terminal's foreground job, even where this test runs with
    SIGINT ignored (a background job of a non-interactive shell), which a child would inherit."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _lfdeblur(*args, **kwargs):
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.Popen([sys.executable, "-m", "napari_lfdeblur.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True,
                            preexec_fn=_as_in_a_terminal, **kwargs)


def _wait_for_records(out: Path, n: int, proc, timeout: float = 120.0) -> None:
    """Wait until the manifest holds ``n`` records (the cluster is up and items are finishing)."""
    t0 = time.monotonic()
    manifest = out / "manifest.jsonl"
    while time.monotonic() - t0 < timeout:
        if manifest.is_file() and len(manifest.read_text().splitlines()) >= n:
            return
        if proc.poll() is not None:
            pytest.fail(f"the run ended before it could be interrupted:\n{proc.communicate()[1][-2000:]}")
        time.sleep(0.02)
    proc.kill()
    pytest.fail("no item finished in time")


@pytest.fixture
def inputs(tmp_path):
    rng = np.random.default_rng(5)
    folder = tmp_path / "in"
    folder.mkdir()
    return [write_lightfield(folder / f"s{i}.npz", rng.random((5, 5, 24, 24, 3)).astype(np.float32))
            for i in range(2)]


def _check_complete_outputs(out: Path, inputs) -> int:
    """Every ``.npz`` in ``out`` equals the serial API's item; returns how many there are."""
    import torch

    torch.set_num_threads(1)
    found = 0
    for p in inputs:
        lf = read_lightfield(p)
        for k in range(N_PER_INPUT):
            f = out / f"{p.stem}_{k:04d}.npz"
            if f.exists():
                want, _ = simulate_item(lf, p.name, k, path_kind="shake", extent=1.5, noise=0.01, seed=7,
                                        n_times=N_TIMES)
                assert np.array_equal(read_lightfield(f), want), f.name
                found += 1
    names = {f.name for f in out.glob("*.npz")}
    assert len(names) == found  # nothing else was written
    return found


def _rerun_completes(glob: str, out: Path, inputs) -> None:
    proc = _lfdeblur("batch", "simulate", glob, str(out), "--workers", "1", *OPTIONS)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err[-2000:]
    assert _check_complete_outputs(out, inputs) == 2 * N_PER_INPUT
    assert sorted(p.name for p in out.iterdir() if ".tmp" in p.name) == []
    assert all(r["status"] == "ok" for r in read_manifest(out).values())


def test_ctrl_c_stops_the_run_cleanly_and_a_rerun_completes_it(tmp_path, inputs):
    out = tmp_path / "out"
    glob = str(tmp_path / "in" / "*.npz")
    proc = _lfdeblur("batch", "simulate", glob, str(out), "--workers", "2", *OPTIONS)
    _wait_for_records(out, 1, proc)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole foreground group
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err[-2000:]
    assert "interrupted" in err and "Traceback" not in err, err[-3000:]
    assert "CancelledError" not in err and "still alive" not in err, err[-3000:]  # the shutdown's noise
    done = _check_complete_outputs(out, inputs)
    assert 1 <= done < 2 * N_PER_INPUT, (done, err[-3000:])
    _rerun_completes(glob, out, inputs)


def test_a_killed_scheduler_fails_the_run_cleanly_and_a_rerun_completes_it(tmp_path, inputs):
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                              "--port", "0", "--no-dashboard", "--scheduler-file", str(tmp_path / "s.json")],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, start_new_session=True)
    worker = None
    try:
        t0 = time.monotonic()
        while not (tmp_path / "s.json").is_file() and time.monotonic() - t0 < 60:
            time.sleep(0.05)
        import json

        address = json.loads((tmp_path / "s.json").read_text())["address"]
        worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                                   "--no-dashboard", "--death-timeout", "10"], stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL, env=env, start_new_session=True)
        out = tmp_path / "out"
        glob = str(tmp_path / "in" / "*.npz")
        proc = _lfdeblur("batch", "simulate", glob, str(out), "--scheduler", address, *OPTIONS)
        _wait_for_records(out, 1, proc)
        sched.kill()
        _, err = proc.communicate(timeout=120)
        assert proc.returncode in (1, 2), err[-2000:]  # items failed, or the connection was lost
        assert "Traceback" not in err, err[-3000:]
        _check_complete_outputs(out, inputs)
    finally:
        for p in (sched, worker):
            if p is not None and p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
    _rerun_completes(glob, out, inputs)
