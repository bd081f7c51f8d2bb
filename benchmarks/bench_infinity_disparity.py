"""Cost of the blur operator at non-zero infinity disparities, against d_inf = 0.

Usage::

    python benchmarks/bench_infinity_disparity.py [--shape 9 9 376 541 3] [--n-times 16 32]
        [--infinity-disparity 0 0.5 1 1.5 2 -1] [--device auto|cpu|cuda]
        [--engine fused torch] [--out PATH]

For every ``T`` and ``d_inf`` it measures, on a random light field and a
random path with ``p_z != 0``: the time to build the operator (its kernel),
one forward plus one adjoint (what a non-blind solver iteration costs), and
forward+backward with gradients for the light field and the path (what a
blind path fit costs); the peak memory above the light field during
forward+backward, in units of the light field's size; the number of
taps of the kernel; and forward plus adjoint against the memory-traffic
floor (each must read and write one light field at least: twice the time
of a plain copy of the light field on the device). Each ``(T, d_inf)``
runs in its own subprocess, so peaks don't mix. The cost ratio is against ``d_inf = 0`` at the same ``T``.
The table goes to ``docs/benchmarks/bench_infinity_disparity.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from napari_lfdeblur import _fused
from napari_lfdeblur.blur import BlurOperator
from napari_lfdeblur.devices import select_device
from napari_lfdeblur.path import random_path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
from bench_forward import PeakRSS, _sync  # noqa: E402


def measure(shape, n_times, d_inf, device, repeats, rotation=None):
    """One ``(T, d_inf)`` point: build, forward+adjoint and forward+backward times, peak memory, taps.

    ``rotation``, a ``(4, 3)`` array in radians, makes the path 6-DOF.
    """
    device = select_device(device)
    torch.manual_seed(0)
    L = torch.rand(shape, device=device)
    target = torch.rand(shape, device=device)
    cp = random_path(4, extent=3.0, z_extent=1.0, seed=1)
    if rotation is not None:
        cp = np.concatenate([cp, rotation], axis=1)
    cp0 = torch.tensor(cp, dtype=torch.float32, device=device)
    lf_bytes = L.numel() * L.element_size()

    def timed(fn):
        best = float("inf")
        for _ in range(repeats):
            _sync(device)
            t0 = time.perf_counter()
            out = fn()
            _sync(device)
            best = min(best, time.perf_counter() - t0)
            del out
        return best

    t_build = timed(lambda: BlurOperator(shape, cp0, n_times=n_times, infinity_disparity=d_inf, device=device))
    op = BlurOperator(shape, cp0, n_times=n_times, infinity_disparity=d_inf, device=device)
    n_taps = int(op.n_taps)
    with torch.no_grad():
        op.adjoint(op.forward(L))  # warm-up
        t_fa = timed(lambda: op.adjoint(op.forward(L)))
        # the memory-traffic floor: a forward and an adjoint each read one light field and write one, at
        # least; a plain copy of the light field (read + write) measures what that costs on this device
        dst = torch.empty_like(L)
        dst.copy_(L)
        t_copy = min(timed(lambda: dst.copy_(L)) for _ in range(3))
        del dst

    def fwd_bwd():
        Lg = L.detach().requires_grad_(True)
        cp = cp0.clone().requires_grad_(True)
        blur = BlurOperator(shape, cp, n_times=n_times, infinity_disparity=d_inf, device=device)
        F.mse_loss(blur.forward(Lg), target, reduction="sum").mul(0.5).backward()
        return Lg.grad, cp.grad

    t_fb, peak = float("inf"), 0.0
    for _ in range(repeats):
        if device.type == "cuda":
            torch.cuda.reset_peak_memory_stats()
            base = torch.cuda.memory_allocated()
        with PeakRSS() as mem:
            t0 = time.perf_counter()
            grads = fwd_bwd()
            _sync(device)
            t_fb = min(t_fb, time.perf_counter() - t0)
        extra = torch.cuda.max_memory_allocated() - base if device.type == "cuda" else mem.peak - mem.base
        peak = max(peak, extra / lf_bytes)
        del grads
    return {"n_times": n_times, "d_inf": d_inf, "device": str(device), "build_s": t_build,
            "fwd_adj_s": t_fa, "fwd_bwd_s": t_fb, "peak_extra_x_lf": peak, "taps": n_taps, "copy_s": t_copy,
            "lf_mb": lf_bytes / 2**20}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", type=int, nargs="+", default=[9, 9, 376, 541, 3])
    parser.add_argument("--n-times", type=int, nargs="+", default=[16, 32])
    parser.add_argument("--infinity-disparity", type=float, nargs="+", default=[0.0, 0.5, 1.0, 1.5, 2.0, -1.0])
    parser.add_argument("--device", default="auto")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--engine", nargs="+", choices=["fused", "torch"], default=["fused", "torch"],
                        help="the blur's fused CPU loops (numba) and/or its torch version; a GPU has only the latter")
    parser.add_argument("--point", nargs=2, type=float, help=argparse.SUPPRESS)  # child: T, d_inf
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    shape = tuple(args.shape)
    if args.point:
        print(json.dumps(measure(shape, int(args.point[0]), args.point[1], args.device, args.repeats)))
        return
    device = select_device(args.device)
    ds = sorted(set(args.infinity_disparity) | {0.0}, key=lambda d: (d != 0.0, abs(d), d))
    engines = [e for e in args.engine if e == "torch" or (device.type == "cpu" and _fused.available(device))]
    rows, failed = [], []
    for engine, T, d in itertools.product(engines, args.n_times, ds):
        cmd = [sys.executable, __file__, "--point", str(T), str(d), "--shape", *map(str, shape),
               "--device", str(device), "--repeats", str(args.repeats)]
        env = {**os.environ, "NAPARI_LFDEBLUR_NUMBA": "1" if engine == "fused" else "0"}
        res = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if res.returncode != 0:
            print(f"{engine} T={T} d_inf={d} failed:\n{res.stderr[-2000:]}")
            failed.append(f"{engine} T={T} d_inf={d}")
            continue
        row = json.loads(res.stdout.strip().splitlines()[-1]) | {"engine": engine}
        ref = next((r for r in rows if (r["engine"], r["n_times"], r["d_inf"]) == (engine, T, 0.0)), row)
        row["ratio_fwd_adj"] = row["fwd_adj_s"] / ref["fwd_adj_s"]
        row["ratio_fwd_bwd"] = row["fwd_bwd_s"] / ref["fwd_bwd_s"]
        rows.append(row)
        print(_line(row), flush=True)
    if rows and not failed:
        _write(rows, shape, args, argv, device)
    return _report.exit_status(failed)


def _line(r) -> str:
    return (f"| {r['engine']} | {r['n_times']} | {r['d_inf']:+.1f} | {r['taps']} | {r['build_s']:.3f} | "
            f"{r['fwd_adj_s']:.3f} | "
            f"{r['ratio_fwd_adj']:.2f} | {2000 * r['copy_s']:.3g} | {r['fwd_adj_s'] / (2 * r['copy_s']):.1f} | "
            f"{r['fwd_bwd_s']:.3f} | {r['ratio_fwd_bwd']:.2f} | {r['peak_extra_x_lf']:.2f} |")


def _write(rows, shape, args, argv, device):
    body = [
        f"A random {'x'.join(map(str, shape))} float32 light field ({rows[0]['lf_mb']:.0f} MiB) and a random "
        f"4-point path with `p_z != 0` (extent 3 views); best of {args.repeats} runs. *Build*: making the "
        "operator (its kernel). *Forward + adjoint*: one of each, as a non-blind iteration does. *Forward + "
        "backward*: loss `0.5 ||f - b||^2` with gradients for the light field and the path, as a blind path fit "
        "does. *Engine*: `fused`, the CPU loops compiled by numba (the default on the CPU), or `torch`, the torch "
        "version (`NAPARI_LFDEBLUR_NUMBA=0`; the only one on a GPU). Ratios are against `d_inf = 0` with the same "
        "engine and `T`. *Floor*: the memory-traffic floor of a forward "
        "plus an adjoint, each of which must read one light field and write one: twice the time of a plain copy "
        "of the light field on the device (`dst.copy_(src)`, best of 3 x the runs), which measures the "
        "bandwidth actually available; *x floor*: forward + adjoint over that floor. Peak memory: above the "
        "light field, target and path during forward+backward, in units of the light field's size.",
        "",
        "| engine | T | d_inf | taps | build (s) | forward + adjoint (s) | ratio | floor (ms) | x floor | "
        "forward + backward (s) | ratio | peak extra memory (x light field) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        *[_line(r) for r in rows],
    ]
    _report.write_table(_report.table_path(args.out, __file__), "Blur operator at non-zero infinity disparity",
                        _report.command_line(__file__, argv), _report.machine(str(device)), body)


if __name__ == "__main__":
    raise SystemExit(main())
