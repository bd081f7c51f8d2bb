"""How many inner iterations of the TV proximal map each FISTA iteration of ``deconvolve`` needs.

``method='tv'`` solves ``1/2 ||K l - f||^2 + w TV4(l)`` by FISTA whose TV
proximal map is itself solved by a few warm-started dual iterations
(``napari_lfdeblur.deconvolution.N_INNER`` of them, docs/deconvolution.md).
Fewer inner iterations make each outer iteration cheaper but the prox less
exact; this script measures the trade on known-path cases.

Cases: 9 x 9 x 128 x 128 x 3 central crops of the rendered scene
(``procedural_scene``, nearer than ``d_inf``) and of the Lytro Illum capture
(when present), each blurred by one path with ``p_z != 0`` (T = 64) and noise
of sigma 0.002 and 0.01, at ``d_inf = 0`` and ``d_inf != 0``. Each is solved
with the default parameters (the weight from the noise, the stopping rule on
the objective) and ``n_inner`` inner iterations; the reference optimum
``F*`` is the lowest objective of a long run (``n_inner = 10``, 150
iterations, no stopping rule). Reported: outer iterations until the stopping
rule, seconds, the objective's gap to ``F*`` relative to ``F*``, and the PSNR
against the sharp crop (8-px border excluded).

Usage::

    python benchmarks/prox_iterations.py [--inner 1,2,3,5,8]
    python benchmarks/prox_iterations.py --quick     # one small case, writes nothing (or the table to --out)

The table goes to ``docs/benchmarks/prox_iterations.md`` (or ``--out``),
replacing it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
import bench_fullres  # noqa: E402  (its scenes and path)
import eval_set  # noqa: E402

NOISES = (0.002, 0.01)
REFERENCE = (10, 150)  # n_inner, iterations of the reference run


def cases(quick: bool):
    """``(name, sharp crop, d_inf)`` of every case."""
    size = 32 if quick else 128
    scenes = [("rendered", 0.0), ("rendered", 1.0)] if not quick else [("rendered", 1.0)]
    if not quick and eval_set.capture_available("Illum"):
        scenes += [("Illum", 0.0), ("Illum", -1.0)]
    for scene, d_inf in scenes:
        sharp = bench_fullres.sharp_lightfield("synthetic" if scene == "rendered" else scene, d_inf)
        yield f"{scene}, d_inf {d_inf:+g}", bench_fullres.central(sharp, size).astype(np.float32), d_inf


def solve(blurred, cp, d_inf, n_inner, **overrides):
    """``(iterations, seconds, final objective, result)`` of ``iter_deconvolve`` with ``n_inner``."""
    from napari_lfdeblur import deconvolution

    deconvolution.N_INNER, saved = n_inner, deconvolution.N_INNER
    try:
        t0 = time.perf_counter()
        last = None
        for last in deconvolution.iter_deconvolve(blurred, cp, n_times=32, infinity_disparity=d_inf, device="cpu",
                                                  **overrides):
            pass
        return last.iteration, time.perf_counter() - t0, float(last.loss), last.estimate()
    finally:
        deconvolution.N_INNER = saved


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--inner", default="1,2,3,5,8", help="inner iterations to compare")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="one small case; writes nothing unless --out")
    _report.add_out_argument(ap, __file__)
    args = ap.parse_args(argv)
    try:
        inner = [int(v) for v in args.inner.split(",")]
    except ValueError:
        ap.error(f"--inner takes whole numbers separated by commas; got {args.inner!r}")
    import torch

    from napari_lfdeblur.blur import simulate_blur
    from napari_lfdeblur.deconvolution import N_INNER
    from napari_lfdeblur.metrics import psnr

    torch.set_num_threads(args.threads)
    noises = NOISES[:1] if args.quick else NOISES
    ref_inner, ref_iter = (2, 20) if args.quick else REFERENCE
    cp = bench_fullres.PATH - bench_fullres.PATH.mean(axis=0)
    rows = []
    for name, sharp, d_inf in cases(args.quick):
        clean = simulate_blur(sharp, bench_fullres.PATH, n_times=64, infinity_disparity=d_inf, device="cpu")
        for noise in noises:
            blurred = (clean + np.random.default_rng(0).normal(0, noise, clean.shape)).astype(np.float32)
            f_ref = solve(blurred, cp, d_inf, ref_inner, n_iter=ref_iter, tol=0.0)[2]
            runs = {n: solve(blurred, cp, d_inf, n) for n in inner}
            f_star = min([f_ref] + [r[2] for r in runs.values()])
            for n, (its, sec, f, out) in runs.items():
                row = (f"| {name} | {noise:g} | {n}{' (default)' if n == N_INNER else ''} | {its} | {sec:.1f} | "
                       f"{(f - f_star) / f_star:.1e} | {psnr(out, sharp, crop=8 if not args.quick else 2):.2f} |")
                rows.append(row)
                print(row, flush=True)
    body = [
        "Each case: a 9x9 crop blurred by the path [[-0.9, 0.4, 0.3], [0.3, -0.7, -0.2], [0.8, 0.6, 0.1]] "
        "(T = 64) plus noise, solved by `deconvolve` with the true path (T = 32), the default weight and "
        "stopping rule, and `n_inner` inner iterations of the TV prox per outer iteration. *Gap*: "
        f"`(F - F*) / F*`, with `F*` the lowest objective of a long run (`n_inner = {ref_inner}`, {ref_iter} "
        "iterations) or of the runs shown.",
        "",
        "| case | noise | n_inner | iterations | time (s) | gap to the optimum | PSNR (dB) |",
        "|---|---|---|---|---|---|---|",
        *rows,
    ]
    out = _report.table_path(args.out, __file__, smoke=args.quick)
    if out is not None:
        _report.write_table(out, "TV deconvolution: inner iterations of the proximal map",
                            _report.command_line(__file__, argv), _report.machine("cpu"), body)


if __name__ == "__main__":
    main()
