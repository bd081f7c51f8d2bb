"""Diagnostic: how well a shorter path plus a softer scene imitates the true blur.

Blind deblurring must split the blur it sees between the camera path and the
scene's own edge profile. This script measures how little the blurred data
alone tell the two apart on the evaluation cases of ``blind_eval.py``. For
each case and each scale ``s < 1`` it takes the true path scaled by ``s`` about
its mean (a path estimate with blur mismatch about ``1 - s``: docs/model.md,
"Judging an estimate") and looks for the spatial Gaussian ``G_sigma`` of the sharp scene
(the same in every view) that makes ``K_{s p} G_sigma l`` closest to the
noise-free blurred data ``K_p l``. It prints the rms of what is left, next to
the noise of the evaluation (sigma 0.002) and to the rms of the blur itself,
``rms(K_p l - l)``.

The Gaussian is only one of the softer scenes a solver could pick (the best
latent for the scaled path fits better still), so the residual is an upper
bound on how far apart the two explanations are. Computed on the grayscale
light field (the solver estimates the path on it), with ``CROP`` px borders
removed. docs/blind.md ("Results and limits") describes the ambiguity.

Usage::

    python benchmarks/dev/blind_ambiguity.py [--cases syn-p1,syn-p2,lytro-p1,lytro-p2] [--scales 0.7,0.8,0.9]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from blind_dev import _eval_module  # benchmarks/ is on the path when this script runs
from scipy import ndimage

SIGMAS = np.round(np.arange(0.0, 1.01, 0.05), 2)  # Gaussians tried, px


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default="syn-p1,syn-p2,syn2-p4,lytro-p1,lytro-p2,lytro2-p4,lytro3-p6")
    ap.add_argument("--scales", default="0.7,0.8,0.9")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    ev = _eval_module()
    from napari_lfdeblur import simulate_blur
    from napari_lfdeblur.metrics import path_error
    from napari_lfdeblur.path import center_path

    c = ev.CROP
    print(f"noise of the evaluation: sigma {ev.NOISE_SIGMA}")
    print("| case | rms of the blur | path scale | blur mismatch | best Gaussian (px) | rms left |")
    print("|---|---|---|---|---|---|")
    for name in args.cases.split(","):
        case = ev.make_case(name)
        sharp = case.sharp.mean(axis=-1) if case.sharp.ndim == 5 else case.sharp
        cp = center_path(case.control_points, ev.RENDER_TIMES)
        data = simulate_blur(sharp, cp, n_times=ev.RENDER_TIMES)
        blur_rms = float(np.sqrt(((data - sharp)[:, :, c:-c, c:-c] ** 2).mean()))
        soft = {s: ndimage.gaussian_filter(sharp, (0, 0, s, s), mode="nearest") if s > 0 else sharp
                for s in SIGMAS}
        for scale in (float(s) for s in args.scales.split(",")):
            mismatch = path_error(cp * scale, cp, lightfield=case.sharp).blur_mismatch
            left = []
            for s in SIGMAS:
                model = simulate_blur(soft[s], cp * scale, n_times=ev.RENDER_TIMES)
                left.append(float(np.sqrt(((model - data)[:, :, c:-c, c:-c] ** 2).mean())))
            k = int(np.argmin(left))
            print(f"| {name} | {blur_rms:.4f} | {scale:.1f} | {mismatch:.3f} | {SIGMAS[k]:.2f} | {left[k]:.4f} |",
                  flush=True)


if __name__ == "__main__":
    main()
