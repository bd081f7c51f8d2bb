"""The *Blind deblur* dock widget on a whole light field: responsiveness, previews, memory, Cancel.

Usage::

    xvfb-run -a python benchmarks/bench_widget_fullres.py [--scene synthetic|illum] [--device cpu]
        [--cancel-in path final] [--cancel-after 2] [--rounds 2] [--out PATH]

The scene is ``bench_fullres``'s full-size case (``synthetic``: the rendered 9 x 9 x 376 x 541 x 3
scene; ``illum``: the whole Lytro Illum capture), blurred by its known path with ``d_inf = 0``, noise
0.005, written to an ``.npz`` file. In a hidden napari viewer this script

1. opens the file with the plugin's reader (timed);
2. runs *Blind deblur* with the default preset and *restore anyway* ticked (so that the final stage
   runs at full size), the widget's default preview cadence, to the end, while a Qt timer that should
   fire every 20 ms measures how long Qt's thread was kept from running (the longest gap, with the
   widget's status line before and after it, and the 99th percentile);
3. reports the previews (how many, Qt-thread time per preview), the peak resident memory above the
   level before the run (in units of the light field's size), whether the result layer holds the
   solver's array itself (no copy), and the run's time against the same solver iterated by a script
   (``--rounds`` of each, alternating; the other figures are the worst round's). All torch work of
   this script runs on the plugin's torch thread, as in a napari session: the script's run too, so
   that the process keeps one OpenMP thread pool, as a script of its own would;
4. starts the run again once for each stage of ``--cancel-in`` (``path``: the path stage, run on a
   window; ``final``: the final solve over the whole light field), presses Cancel ``--cancel-after``
   seconds after that stage began, and reports how long the run took to stop and which layers were
   left.

The table goes to ``docs/benchmarks/bench_widget_fullres.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
import bench_fullres  # noqa: E402
from blind_eval import PeakMemory  # noqa: E402

NOISE = 0.005
TICK_MS = 20


class TickGaps:
    """Gaps between the firings of a Qt timer that should fire every ``TICK_MS`` ms, and what
    ``label()`` (the widget's status line) said at each firing."""

    def __init__(self, label):
        from qtpy.QtCore import QTimer

        self.times, self.labels, self.label = [], [], label
        self.timer = QTimer()
        self.timer.setInterval(TICK_MS)
        self.timer.timeout.connect(self._tick)

    def _tick(self):
        self.times.append(time.perf_counter())
        self.labels.append(self.label())

    def __enter__(self):
        self.timer.start()
        return self

    def __exit__(self, *exc):
        self.timer.stop()

    def gaps_ms(self) -> np.ndarray:
        return np.diff(self.times) * 1000 if len(self.times) > 1 else np.zeros(1)

    def longest_between(self) -> str:
        """The status lines before and after the longest gap."""
        if len(self.times) < 2:
            return "-"
        i = int(np.argmax(self.gaps_ms()))
        return f"{self.labels[i]!r} -> {self.labels[i + 1]!r}"


def blurred_file(scene: str, folder: Path) -> Path:
    from napari_lfdeblur import simulate_blur, write_lightfield

    sharp = bench_fullres.sharp_lightfield("Illum" if scene == "illum" else "synthetic", 0.0)
    blurred = simulate_blur(sharp, bench_fullres.PATH, n_times=64)
    blurred += np.random.default_rng(0).normal(0, NOISE, blurred.shape).astype(np.float32)
    return write_lightfield(folder / f"{scene}_blurred.npz", np.clip(blurred, 0, 1), compress=False)


def timed_on_progress(widget) -> list:
    """Wrap the widget's ``on_progress`` (Qt's thread); return the list of (had preview, seconds)."""
    calls = []
    original = widget.on_progress

    def on_progress(progress):
        t0 = time.perf_counter()
        original(progress)
        calls.append((progress.preview is not None, time.perf_counter() - t0))

    widget.on_progress = on_progress
    return calls


def wait_while_running(widget, seconds: float | None = None) -> None:
    from qtpy.QtWidgets import QApplication

    t0 = time.perf_counter()
    while widget.is_running and (seconds is None or time.perf_counter() - t0 < seconds):
        QApplication.processEvents()
        time.sleep(0.005)


def full_run(widget, layer, nbytes: int) -> dict:
    calls = timed_on_progress(widget)
    with PeakMemory("cpu") as mem, TickGaps(lambda: widget.progress.status.value) as ticks:
        t0 = time.perf_counter()
        if widget.run() is None:
            raise SystemExit("the run did not start (see the notification above)")
        wait_while_running(widget)
        seconds = time.perf_counter() - t0
    out = widget.last_layers[0]
    preview_s = [s for had, s in calls if had]
    gaps = ticks.gaps_ms()
    return {"seconds": seconds, "records": len(calls), "previews": len(preview_s),
            "preview_ms": 1000 * float(np.median(preview_s)) if preview_s else float("nan"),
            "gap_max_ms": float(gaps.max()), "gap_p99_ms": float(np.percentile(gaps, 99)),
            "gap_where": ticks.longest_between(),
            "memory_x": mem.delta_mib * 2**20 / nbytes,
            "no_copy": bool(np.shares_memory(out.data, widget.last_result.lightfield))}


def script_run(lf, params, device: str) -> float:
    from napari_lfdeblur.blind import iter_blind_deblur
    from napari_lfdeblur.progress import run_to_completion

    t0 = time.perf_counter()
    run_to_completion(iter_blind_deblur(lf, infinity_disparity=0.0, params=params, device=device, seed=0))
    return time.perf_counter() - t0


def current_stage(widget) -> str:
    return widget.progress.status.value.split(":")[0]


def cancels(widget, viewer, stages, after: float) -> list[str]:
    from qtpy.QtWidgets import QApplication

    rows = []
    for name in stages:
        if widget.run() is None:
            raise SystemExit("the run did not start")
        while widget.is_running and not current_stage(widget).startswith(name):
            QApplication.processEvents()
            time.sleep(0.005)
        wait_while_running(widget, after)
        if not widget.is_running:
            rows.append(f"| Cancel {after:g} s into the *{name}* stage | the run had finished |")
            continue
        stage = current_stage(widget)
        widget.cancel()
        t1 = time.perf_counter()
        wait_while_running(widget)
        latency = time.perf_counter() - t1
        left = ", ".join(layer.name for layer in viewer.layers)
        rows.append(f"| Cancel {after:g} s into the *{name}* stage (*{stage}*) | stopped {latency:.2f} s later; "
                    f"layers left: {left} |")
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="synthetic", choices=("synthetic", "illum"))
    parser.add_argument("--device", default="cpu", help="auto, cpu or cuda (default cpu)")
    parser.add_argument("--cancel-in", nargs="*", default=["path", "final"], choices=("path", "final"),
                        help="stages to cancel a run in, one run each (default path final)")
    parser.add_argument("--cancel-after", type=float, default=2.0,
                        help="seconds into the stage before Cancel (default 2)")
    parser.add_argument("--rounds", type=int, default=2, help="widget and script runs, alternating (default 2)")
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)

    import napari

    from napari_lfdeblur._napari._torch_thread import call
    from napari_lfdeblur._napari.widgets.blind import BlindDeblurWidget, _make_params

    with tempfile.TemporaryDirectory() as tmp:  # torch work stays off the GUI thread, as in napari
        path = call(blurred_file, args.scene, Path(tmp))
        viewer = napari.Viewer(show=False)
        t0 = time.perf_counter()
        [layer] = viewer.open(path, plugin="napari-lfdeblur")
        open_s = time.perf_counter() - t0
    lf = np.asarray(layer.data)
    widget = BlindDeblurWidget(viewer)
    viewer.window.add_dock_widget(widget)
    widget.layer_combo.set_layer(layer)
    widget.form.device.value = args.device
    widget.form.restore_anyway.value = True
    f = widget.form
    params = _make_params(f.preset.value, n_control_points=f.n_control_points.value, n_iter=f.n_iter.value,
                          tv_iter=f.tv_iter.value, edge_anisotropy=f.edge_anisotropy.value,
                          motion=f.motion.value, restore_anyway=True)
    runs, script_s = [], []
    for _ in range(args.rounds):  # alternating, so that drift of the machine hits both alike
        runs.append(full_run(widget, layer, lf.nbytes))
        print(f"widget: {runs[-1]}", file=sys.stderr, flush=True)
        for name in [ly.name for ly in viewer.layers if ly is not layer]:
            viewer.layers.remove(name)
        script_s.append(call(script_run, lf, params, args.device))  # one thread, as a script's
        print(f"script: {script_s[-1]:.1f} s", file=sys.stderr, flush=True)
    run = {key: max(r[key] for r in runs) for key in runs[0] if key != "gap_where"}  # the worst of the rounds
    run["gap_where"] = max(runs, key=lambda r: r["gap_max_ms"])["gap_where"]
    run["seconds"], script_s = sum(r["seconds"] for r in runs), sum(script_s)
    cancel_rows = cancels(widget, viewer, args.cancel_in, args.cancel_after)
    viewer.close()

    rows = [
        "| measurement | result |", "|---|---|",
        f"| open the `.npz` with the plugin's reader ({lf.nbytes / 2**20:.0f} MiB) | {open_s:.2f} s |",
        f"| *Blind deblur*, to the end, {args.rounds} runs | {run['seconds']:.1f} s; a script iterating the "
        f"solver: {script_s:.1f} s ({100 * (run['seconds'] / script_s - 1):+.1f} %) |",
        f"| Qt's thread kept from running | longest {run['gap_max_ms']:.0f} ms (status before and after: "
        f"{run['gap_where']}), 99th percentile {run['gap_p99_ms']:.0f} ms (timer every {TICK_MS} ms) |",
        f"| progress records; light-field previews | {run['records']}; {run['previews']}, "
        f"{run['preview_ms']:.0f} ms each in Qt's thread (median) |",
        f"| peak memory above the level before the run | {run['memory_x']:.1f}x the light field |",
        f"| result layer holds the solver's array (no copy) | {'yes' if run['no_copy'] else 'no'} |",
        *cancel_rows,
    ]
    print("\n".join(rows))
    body = [f"Scene: `{args.scene}` ({' x '.join(map(str, lf.shape))}), blurred by `bench_fullres`'s path "
            f"(`d_inf = 0`, noise {NOISE}); default preset, *restore anyway*, preview every "
            f"{f.preview_every.value} records, device {args.device}; a hidden napari viewer driven by "
            "`QApplication.processEvents` every 5 ms.", "", *rows]
    _report.write_table(_report.table_path(args.out, __file__), "The Blind deblur widget on a whole light field",
                        _report.command_line(__file__, argv), _report.machine(args.device), body)


if __name__ == "__main__":
    main()
