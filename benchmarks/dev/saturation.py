"""Diagnostic: restoring a light field whose highlights the sensor clipped.

Rendered scenes (``procedural_scene``, 9x9x96x96x3) are made brighter by each
of ``--brightness``, blurred by a random path of 2 views (``p_z = 0``),
given noise of 0.002 and clipped to [0, 1], as a sensor clips light above its
ceiling. The reference is the sharp scene clipped the same way. For each scene
and brightness the script prints the share of blurred samples at 1 and the
PSNR gain (8 px borders cropped) over the blurred input of: ``deconvolve``
with the true path, with and without ``saturation`` (the censored fit of the
samples at 1, docs/deconvolution.md), and ``blind_deblur`` (the ``default``
preset, whose final stage has ``saturation`` on).

Usage::

    python benchmarks/dev/saturation.py [--seeds 3,7] [--brightness 1,1.3,1.6,2.5] [--threads 2]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="3,7", help="procedural_scene seeds (the path's seed too)")
    ap.add_argument("--brightness", default="1,1.3,1.6,2.5", help="factors applied to the scene before the blur")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    from napari_lfdeblur import blind_deblur, deconvolve, procedural_scene, random_path, simulate_blur
    from napari_lfdeblur.metrics import psnr
    from napari_lfdeblur.path import center_path

    print("scene seed | brightness | samples at 1 | true path, saturation on | true path, off | blind")
    for seed in (int(s) for s in args.seeds.split(",") if s):
        scene = procedural_scene((9, 9, 96, 96), seed=seed)[0]
        cp = random_path(4, extent=2.0, z_extent=0.0, seed=seed)
        for b in (float(x) for x in args.brightness.split(",") if x):
            radiance = scene * np.float32(b)
            noise = np.random.default_rng(0).normal(0.0, 0.002, scene.shape)
            blurred = np.clip(simulate_blur(radiance, cp, n_times=32) + noise, 0, 1).astype(np.float32)
            truth = np.clip(radiance, 0, 1)
            base = psnr(blurred, truth, crop=8)
            gains = [psnr(deconvolve(blurred, center_path(cp, 32), n_times=32, device="cpu", saturation=s), truth,
                          crop=8) - base for s in (True, False)]
            blind = blind_deblur(blurred, device="cpu", seed=0).lightfield
            gains.append(psnr(blind, truth, crop=8) - base)
            print(f"{seed} | {b:g} | {100 * np.mean(blurred >= 1.0):.1f} % | "
                  + " | ".join(f"{g:+.2f}" for g in gains), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
