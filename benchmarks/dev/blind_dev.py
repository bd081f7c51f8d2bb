"""Development measurements of the blind solver (the official table is blind_eval.py).

Usage::

    python benchmarks/dev/blind_dev.py [--cases dev01,dev09] [--set key=value ...] [--oracle]
        [--device cpu] [--preset default]

Prints, per case of blind_eval.py's development split: PSNR of blurred / restored (8 px borders
cropped), blur mismatch, Chamfer distance, the evidence test's verdict, the restoration made and its
discrepancy (noise variances per sample), time; with ``--oracle``
also the non-blind restoration with the true path.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]


def _eval_module():
    spec = importlib.util.spec_from_file_location("blind_eval", ROOT / "benchmarks" / "blind_eval.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["blind_eval"] = mod
    spec.loader.exec_module(mod)
    return mod


def _value(text):
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default="", help="development cases, comma-separated (default: all)")
    ap.add_argument("--preset", default="default")
    ap.add_argument("--set", nargs="*", default=[])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--oracle", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--big", action="store_true",
                    help="one 9x9x376x541x3 synthetic case (the GPU target), instead of --cases")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    ev = _eval_module()
    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.metrics import path_error, psnr
    from napari_lfdeblur.path import center_path

    params = BlindParams.preset(args.preset)
    if args.set:
        changes = {}  # --set FIELD=VALUE or STAGE.FIELD=VALUE (latent, path, joint, final)
        for key, v in (s.split("=", 1) for s in args.set):
            stage, _, name = key.rpartition(".")
            (changes.setdefault(stage, {}) if stage else changes)[name] = _value(v)
        params = params.replace(**changes)
    rows = []
    if args.big:
        from napari_lfdeblur import random_path, simulate_blur, synthetic_scene

        sharp, _ = synthetic_scene(shape=(9, 9, 376, 541), n_layers=3, color=True, seed=1)
        cp = center_path(random_path(4, extent=3.0, z_extent=0.0, seed=102), 128)
        blurred = simulate_blur(sharp, cp, n_times=64, device=args.device)
        blurred = np.clip(blurred + np.random.default_rng(0).normal(0, 0.002, blurred.shape), 0, 1)
        cases = [("big", sharp, blurred.astype(np.float32), cp, 0.0)]
    else:
        specs, _ = ev.select_cases("dev", args.cases.split(",") if args.cases else None)
        cases = ((c.name, c.sharp, c.blurred, c.control_points, c.infinity_disparity)
                 for c in map(ev.make_case, specs))
    for name, sharp, blurred, cp, d in cases:
        t = time.perf_counter()
        res = blind_deblur(blurred, infinity_disparity=d, params=params, device=args.device, seed=args.seed)
        dt = time.perf_counter() - t
        pe = path_error(res.control_points, cp, lightfield=sharp, infinity_disparity=d)
        p0 = psnr(blurred, sharp, crop=ev.CROP)
        p1 = psnr(res.lightfield, sharp, crop=ev.CROP)
        line = (f"{name:9s} blurred {p0:6.2f}  restored {p1:6.2f}  gain {p1 - p0:+6.2f}  "
                f"mismatch {pe.blur_mismatch:5.3f}  chamfer {pe.chamfer:5.3f} (extent {pe.extent:4.2f})  "
                f"blur found {res.info.get('blur_found')}  restoration {res.info.get('restoration')}  "
                f"discrepancy {res.info.get('discrepancy', float('nan')):.2f}  "
                f"time {dt:5.1f}s (path {res.timings['path']:.1f}s)")
        if args.oracle:
            from napari_lfdeblur.deconvolution import deconvolve

            o = deconvolve(blurred, center_path(cp, params.final_n_times), n_times=params.final_n_times,
                           infinity_disparity=d, params=params.final, device=args.device)
            line += f"  oracle {psnr(o, sharp, crop=ev.CROP) - p0:+6.2f}"
        print(line, flush=True)
        rows.append((p1 - p0, pe.blur_mismatch, dt))
    a = np.array(rows)
    print(f"MEAN gain {a[:, 0].mean():+.2f} dB  mismatch {a[:, 1].mean():.3f}  time {a[:, 2].mean():.1f}s")


if __name__ == "__main__":
    main()
