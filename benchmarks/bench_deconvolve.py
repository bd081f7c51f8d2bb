"""Time and peak memory of ``deconvolve`` on a full-size light field (9 x 9 x 376 x 541 x 3).

Cases (``d_inf = 0``, T = 32):

- ``inplane``: a linear in-plane path of 2 views, ``method='inplane'`` (one
  exact per-pixel solve);
- ``tv``: a linear path of 2 views with ``p_z`` from -0.5 to 0.5,
  ``method='tv'`` with ``n_iter`` capped (``tol=0``, so every iteration runs);
  per-iteration time is the mean over the iterations after the first.

Every case runs in a fresh subprocess so that its peak memory is its own:
on the CPU, the peak resident set size above the level after the input was
made (sampled every 5 ms); on CUDA, ``torch.cuda.max_memory_allocated``
(the input lives on the host; the solver's tensors on the GPU).

Usage::

    python benchmarks/bench_deconvolve.py                    # CPU, and CUDA when available
    python benchmarks/bench_deconvolve.py --devices cuda --tv-iterations 50
    python benchmarks/bench_deconvolve.py --quick            # small smoke run, writes nothing

The table goes to ``docs/benchmarks/bench_deconvolve.md`` (or ``--out``),
replacing it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)

SHAPE = (9, 9, 376, 541, 3)


def _rss_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


class _PeakSampler:
    def __init__(self):
        self.peak = _rss_bytes()
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self._stop.is_set():
            self.peak = max(self.peak, _rss_bytes())
            time.sleep(0.02)  # often enough for a plateau of seconds, rarely enough not to slow the solver

    def __enter__(self):
        self._t.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._t.join()
        self.peak = max(self.peak, _rss_bytes())


def child(case: str, device: str, shape, tv_iterations: int) -> dict:
    import numpy as np
    import torch

    from napari_lfdeblur import DeconvolutionParams, deconvolve, linear_path

    rng = np.random.default_rng(0)
    blurred = rng.random(shape, dtype=np.float32)
    if case == "inplane":
        cp, kw = linear_path(2.0, angle_deg=30.0), {"method": "inplane"}
    else:
        cp, kw = linear_path(2.0, angle_deg=30.0, z=1.0), {"method": "tv", "n_iter": tv_iterations, "tol": 0.0}
    if device == "cuda":
        torch.cuda.synchronize()
        torch.cuda.reset_peak_memory_stats()
    stamps = []

    def cb(rec):
        if device == "cuda":
            torch.cuda.synchronize()
        stamps.append(time.perf_counter())

    # one TV per channel solves the channels one after the other; the colour TV (the default) all at once
    separate = kw.get("method") == "tv" and not DeconvolutionParams().couple_channels
    channels = shape[4] if len(shape) == 5 and separate else 1
    base = _rss_bytes()
    with _PeakSampler() as sampler:
        t0 = time.perf_counter()
        out = deconvolve(blurred, cp, device=device, callback=cb, **kw)
        total = time.perf_counter() - t0
    assert out.shape == blurred.shape
    res = {
        "case": case,
        "device": device,
        "device_name": torch.cuda.get_device_name() if device == "cuda" else platform.processor() or platform.machine(),
        "threads": torch.get_num_threads(),
        "shape": list(shape),
        "iterations": len(stamps) // channels,
        "total_s": total,
        "rss_peak_above_input_gib": (sampler.peak - base) / 2**30,
        "load_average": os.getloadavg()[0],
    }
    if len(stamps) > 1:  # an iteration updates every channel
        res["per_iteration_s"] = channels * (stamps[-1] - stamps[0]) / (len(stamps) - 1)
        res["first_iteration_s"] = stamps[0] - t0
    if device == "cuda":
        res["cuda_peak_gib"] = torch.cuda.max_memory_allocated() / 2**30
    return res


def _fmt(r: dict) -> str:
    per = f"{r['per_iteration_s']:.2f}" if "per_iteration_s" in r else "-"
    mem = f"{r['cuda_peak_gib']:.2f} (GPU)" if "cuda_peak_gib" in r else f"{r['rss_peak_above_input_gib']:.2f} (RSS)"
    return (f"| {r['device']} ({r['device_name']}, {r['threads']} threads) | {r['case']} | "
            f"{'x'.join(map(str, r['shape']))} | {r['iterations']} | {r['total_s']:.1f} | {per} | {mem} |")


HEADER = [
    "| device | method | shape | iterations | total (s) | per iteration (s) | peak memory (GiB) |",
    "|---|---|---|---|---|---|---|",
]


def _write(results, shape, out, argv):
    """The table file, replaced as a whole."""
    body = [
        f"A random {'x'.join(map(str, shape))} float32 light field, T = 32, d_inf = 0.",
        "`inplane`: linear in-plane path of 2 views, one exact per-pixel solve. `tv`: linear path of 2 views",
        "with p_z from -0.5 to 0.5, 4D-TV iterations (FISTA with a warm-started TV prox; capped, `tol=0`; the",
        "default colour TV solves the colour channels at once, and an iteration here is one of every channel).",
        "Peak memory: resident set size above the input's level on the CPU; `torch.cuda.max_memory_allocated` on a GPU.",
        "",
        *HEADER,
        *[_fmt(r) for r in results],
    ]
    devices = sorted({r["device"] for r in results})
    _report.write_table(out, "deconvolve: time and peak memory", _report.command_line(__file__, argv),
                        _report.machine(devices[-1] if devices else None), body)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", nargs="+", default=None, help="cpu and/or cuda (default: cpu, plus cuda if available)")
    ap.add_argument("--cases", nargs="+", default=["inplane", "tv"], choices=["inplane", "tv"])
    ap.add_argument("--tv-iterations", type=int, default=None, help="TV iterations (default 4 on CPU, 50 on CUDA)")
    ap.add_argument("--quick", action="store_true", help="a 5x5x64x64x3 light field; writes nothing unless --out")
    _report.add_out_argument(ap, __file__)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    shape = (5, 5, 64, 64, 3) if args.quick else SHAPE
    if args.child:
        case, device, iters = args.child.split(":")
        print("RESULT " + json.dumps(child(case, device, shape, int(iters))))
        return None
    if args.devices is None:
        import torch

        args.devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    results, failed = [], []
    print("\n".join(HEADER))
    for device in args.devices:
        for case in args.cases:
            iters = args.tv_iterations or (50 if device == "cuda" else 4)
            cmd = [sys.executable, __file__, "--child", f"{case}:{device}:{iters}"] + (["--quick"] if args.quick else [])
            proc = subprocess.run(cmd, capture_output=True, text=True)
            line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
            if proc.returncode != 0 or not line:
                print(f"| {device} | {case} | failed: {proc.stderr.strip().splitlines()[-1:]} |", flush=True)
                failed.append(f"{device} {case}")
                continue
            r = json.loads(line[0][7:])
            results.append(r)
            print(_fmt(r), flush=True)
    out = _report.table_path(args.out, __file__, smoke=args.quick)
    if out is not None and results and not failed:
        _write(results, shape, out, argv)
    return _report.exit_status(failed)


if __name__ == "__main__":
    raise SystemExit(main())
