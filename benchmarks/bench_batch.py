"""Throughput and overhead of ``napari_lfdeblur.batch`` on a local dask cluster.

Usage::

    python benchmarks/bench_batch.py [--items 1000] [--scaling-items 64] [--overhead-items 64] [--out PATH]

Three measurements, all of ``simulate_dataset`` (random paths, T = 32, noise 0.01) on
single-threaded worker processes, timed from the submission of the items to the last
manifest line (the cluster is started beforehand):

1. scaling: the same items (9x9x128x128x3) on 1 and on 2 workers, in alternating rounds;
2. overhead: the items (9x9x128x128x3) on 1 worker against a plain loop in this process
   (one torch thread) that reads, simulates and writes the same files, in alternating rounds;
3. many items: ``--items`` items of 9x9x64x64x3 on 2 workers, with the peak memory of this
   process, which holds the client and the scheduler (the workers are other processes).

The table goes to ``docs/benchmarks/bench_batch.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from napari_lfdeblur import read_lightfield, write_lightfield
from napari_lfdeblur.batch import connect, simulate_dataset, simulate_item
from napari_lfdeblur.path import save_path_json

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
from blind_eval import PeakMemory  # noqa: E402

OPTIONS = dict(path_kind="random", extent=2.0, noise=0.01, seed=0)


def make_inputs(folder: Path, n: int, shape) -> list[Path]:
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    return [write_lightfield(folder / f"lf{i:03d}.npz", rng.random(shape, dtype=np.float32), compress=False)
            for i in range(n)]


ROUNDS = 4  # alternating rounds of the overhead measurement


def _warm():
    """Import and run the simulation once in a worker, so that no timed item pays for it."""
    import torch

    torch.set_num_threads(1)
    simulate_item(np.zeros((3, 3, 8, 8), np.float32), "warm", 0, device="cpu")


def timed_batch(client, inputs, out: Path, n_per_input: int) -> float:
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    report = simulate_dataset(inputs, out, n_per_input=n_per_input, client=client, device="cpu", **OPTIONS)
    elapsed = time.perf_counter() - t0
    if report.n_ok != len(inputs) * n_per_input:
        raise RuntimeError(f"{report.n_failed} items failed: {report.failed[:1]}")
    return elapsed


def plain_loop(inputs, out: Path, n_per_input: int) -> float:
    """The same items without dask: read, simulate, write (one torch thread)."""
    import torch

    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    for p in inputs:
        for k in range(n_per_input):
            blurred, cp = simulate_item(read_lightfield(p), p.name, k, device="cpu", **OPTIONS)
            save_path_json(out / f"{p.stem}_{k:04d}.path.json", cp)
            write_lightfield(out / f"{p.stem}_{k:04d}.npz", blurred, compress=False)
    elapsed = time.perf_counter() - t0
    torch.set_num_threads(threads)
    return elapsed


def run(args, work: Path) -> list[str]:
    small = make_inputs(work / "small", 4, (9, 9, 64, 64, 3))
    large = make_inputs(work / "large", 2, (9, 9, 128, 128, 3))
    per = max(1, args.scaling_items // (ROUNDS * len(large)))
    per_large = max(1, args.overhead_items // (ROUNDS * len(large)))
    times = {1: 0.0, 2: 0.0}
    t_dask = t_loop = 0.0
    # both clusters run side by side; 1 worker, 2 workers, dask and the plain loop alternate by round,
    # so that drift of the machine hits every measurement alike
    with connect(workers=1, device="cpu") as one, connect(workers=2, device="cpu") as two:
        one.run(_warm), two.run(_warm)
        plain_loop(large[:1], work / "warm_loop", 1)
        for _ in range(ROUNDS):
            for n, client in ((1, one), (2, two)):
                times[n] += timed_batch(client, large, work / f"scale{n}", per)
            t_dask += timed_batch(one, large, work / "over_dask", per_large)
            t_loop += plain_loop(large, work / "over_loop", per_large)
    print(f"1 worker: {times[1]:.2f} s, 2 workers: {times[2]:.2f} s", file=sys.stderr)
    n_s, n_o = ROUNDS * per * len(large), ROUNDS * per_large * len(large)
    rows = [
        "| measurement | items | result |", "|---|---|---|",
        f"| 1 worker, 9x9x128x128x3 | {n_s} | {times[1]:.2f} s ({n_s / times[1]:.2f} items/s) |",
        f"| 2 workers, 9x9x128x128x3 | {n_s} | {times[2]:.2f} s ({n_s / times[2]:.2f} items/s): "
        f"**{times[1] / times[2]:.2f}x** one worker |",
        f"| plain loop, 9x9x128x128x3 | {n_o} | {t_loop:.2f} s ({t_loop / n_o:.3f} s/item) |",
        f"| 1 worker, 9x9x128x128x3 | {n_o} | {t_dask:.2f} s ({t_dask / n_o:.3f} s/item): "
        f"overhead **{100 * (t_dask / t_loop - 1):+.1f} %** |",
    ]
    shutil.rmtree(work / "over_dask"), shutil.rmtree(work / "over_loop")
    per_many = max(1, args.items // len(small))
    with connect(workers=2, device="cpu") as client:
        client.run(_warm)
        with PeakMemory("cpu") as mem:
            t_many = timed_batch(client, small, work / "many", per_many)
    n_m = per_many * len(small)
    rows.append(f"| 2 workers, 9x9x64x64x3 | {n_m} | {t_many:.1f} s ({n_m / t_many:.2f} items/s); client and "
                f"scheduler process: peak +{mem.delta_mib:.0f} MiB over "
                f"{mem.base / 2**20:.0f} MiB (one item is {9 * 9 * 64 * 64 * 3 * 4 / 2**20:.1f} MiB) |")
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--items", type=int, default=1000, help="items of the many-items run (default 1000)")
    parser.add_argument("--scaling-items", type=int, default=64, help="items of the 1 vs 2 workers runs")
    parser.add_argument("--overhead-items", type=int, default=64, help="items of the overhead runs")
    parser.add_argument("--workdir", type=Path, help="scratch folder (default: a temporary one, removed)")
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    with tempfile.TemporaryDirectory(dir=args.workdir) as tmp:
        rows = run(args, Path(tmp))
    load = max(load, os.getloadavg()[0]) if hasattr(os, "getloadavg") else load
    print("\n".join(rows))
    path = _report.table_path(args.out, __file__)
    body = [
        "`simulate_dataset` (random paths, T = 32, noise 0.01) on single-threaded worker processes of a local "
        "dask cluster, timed from submission to the last manifest line, the cluster already started (a 1-worker "
        "and a 2-worker cluster side by side). The plain loop reads, simulates and writes the same items in one "
        "process with one torch thread. The 1-worker, 2-worker, dask and plain-loop runs alternate in "
        f"{ROUNDS} rounds, each round writing a fresh output folder. "
        f"Load average of the machine before and after the run: up to {load:.1f} on {os.cpu_count()} cores.",
        "",
        *rows,
    ]
    _report.write_table(path, "Batch simulation on dask.distributed", _report.command_line(__file__, argv),
                        _report.machine("cpu"), body)


if __name__ == "__main__":
    main()
