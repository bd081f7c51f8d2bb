"""Cost of the blur operator with camera rotation (6-DOF paths), against the same path without it.

Usage::

    python benchmarks/bench_rotation.py [--shape 9 9 376 541 3] [--n-times 16 32]
        [--infinity-disparity 0 1] [--rotation 0.005] [--device auto|cpu|cuda] [--out PATH]

For every ``T`` and ``d_inf`` it measures the 3-DOF path of
``bench_infinity_disparity.py`` (a random 4-point path with ``p_z != 0``) and
the same path with a random rotation of up to ``--rotation`` rad per axis at
each control point (0.005 rad, about 0.3 degrees: handheld shake). Each
point runs in its own subprocess. Ratios are 6-DOF against 3-DOF at the same
``(T, d_inf)``. The table goes to ``docs/benchmarks/bench_rotation.md`` (or
``--out``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from napari_lfdeblur.devices import select_device

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
from bench_infinity_disparity import measure  # noqa: E402


def rotation_part(magnitude: float) -> np.ndarray:
    """Random ``(4, 3)`` rotation control points within ``+-magnitude`` rad, zero-mean over the control points."""
    r = np.random.default_rng(2).uniform(-magnitude, magnitude, size=(4, 3))
    return r - r.mean(axis=0)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", type=int, nargs="+", default=[9, 9, 376, 541, 3])
    parser.add_argument("--n-times", type=int, nargs="+", default=[16, 32])
    parser.add_argument("--infinity-disparity", type=float, nargs="+", default=[0.0, 1.0])
    parser.add_argument("--rotation", type=float, default=0.005)
    parser.add_argument("--device", default="auto")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--point", nargs=3, type=float, help=argparse.SUPPRESS)  # child: T, d_inf, rotation
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    shape = tuple(args.shape)
    if args.point:
        T, d, rot = args.point
        rotation = rotation_part(rot) if rot > 0 else None
        print(json.dumps(measure(shape, int(T), d, args.device, args.repeats, rotation=rotation)))
        return
    device = select_device(args.device)
    rows, failed = [], []
    for T in args.n_times:
        for d in args.infinity_disparity:
            pair = []
            for rot in (0.0, args.rotation):
                cmd = [sys.executable, __file__, "--point", str(T), str(d), str(rot), "--shape", *map(str, shape),
                       "--device", str(device), "--repeats", str(args.repeats)]
                res = subprocess.run(cmd, capture_output=True, text=True)
                if res.returncode != 0:
                    print(f"T={T} d_inf={d} rotation={rot} failed:\n{res.stderr[-2000:]}")
                    failed.append(f"T={T} d_inf={d} rotation={rot}")
                    break
                row = json.loads(res.stdout.strip().splitlines()[-1])
                row["motion"] = "6-DOF" if rot > 0 else "3-DOF"
                pair.append(row)
            for row in pair:
                row["ratio_fwd_adj"] = row["fwd_adj_s"] / pair[0]["fwd_adj_s"]
                row["ratio_fwd_bwd"] = row["fwd_bwd_s"] / pair[0]["fwd_bwd_s"]
                rows.append(row)
                print(_line(row), flush=True)
    if rows and not failed:
        _write(rows, shape, args, argv, device)
    return _report.exit_status(failed)


def _line(r) -> str:
    return (f"| {r['n_times']} | {r['d_inf']:+.1f} | {r['motion']} | {r['taps']:.0f} | {r['build_s']:.2f} | "
            f"{r['fwd_adj_s']:.2f} | {r['ratio_fwd_adj']:.2f} | {r['fwd_bwd_s']:.2f} | {r['ratio_fwd_bwd']:.2f} | "
            f"{r['peak_extra_x_lf']:.2f} |")


def _write(rows, shape, args, argv, device):
    body = [
        f"A random {'x'.join(map(str, shape))} float32 light field ({rows[0]['lf_mb']:.0f} MiB); a random 4-point "
        f"path with `p_z != 0` (extent 3 views), and the same path with a rotation of up to {args.rotation} rad "
        f"per axis at each control point; best of {args.repeats} runs. *Taps*: passes over the light field one "
        "forward costs (with rotation, the mean over the spatial tiles). *Build*: making the operator (its "
        "kernel). *Forward + adjoint*: one of each, as a non-blind iteration does. *Forward + backward*: loss "
        "`0.5 ||f - b||^2` with gradients for the light field and the path, as a blind path fit does. Ratios: "
        "6-DOF against 3-DOF at the same `T` and `d_inf`. Peak memory: above the light field, target and path "
        "during forward+backward, in units of the light field's size.",
        "",
        "| T | d_inf | motion | taps | build (s) | forward + adjoint (s) | ratio | forward + backward (s) | ratio "
        "| peak extra memory (x light field) |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *[_line(r) for r in rows],
    ]
    _report.write_table(_report.table_path(args.out, __file__), "Blur operator with camera rotation",
                        _report.command_line(__file__, argv), _report.machine(str(device)), body)


if __name__ == "__main__":
    raise SystemExit(main())
