"""Diagnostic: how well a shorter path plus a softer scene imitates the true blur.

Blind deblurring must split the blur it sees between the camera path and the
scene's own edge profile. This script measures how little the blurred data
alone tell the two apart on the blurred development cases of
``blind_eval.py``. For each case and each scale ``s < 1`` it takes the true
path scaled by ``s`` about its mean (a path estimate with blur mismatch about
``1 - s``: docs/model.md, "Judging an estimate") and looks for the spatial
Gaussian ``G_sigma`` of the sharp scene (the same in every view) that makes
``K_{s p} G_sigma l`` closest to the noise-free blurred data ``K_p l`` (the
case's ``d_inf``). It prints the rms of what is left, next to the case's
noise and to the rms of the blur itself, ``rms(K_p l - l)``; "within the
noise" says whether the rms left is below the case's noise.

The Gaussian is only one of the softer scenes a solver could pick (the best
latent for the scaled path fits better still), so the residual is an upper
bound on how far apart the two explanations are. Computed on the grayscale
light field (the solver estimates the path on it), with ``blind_eval.CROP`` px
borders removed. docs/blind.md ("Results and limits") describes the ambiguity.

Usage::

    python benchmarks/dev/blind_ambiguity.py [--cases dev01,dev05] [--scales 0.7,0.8,0.9]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)

SIGMAS = np.round(np.arange(0.0, 1.01, 0.05), 2)  # Gaussians tried, px


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--scales", default="0.7,0.8,0.9")
    args = ap.parse_args(argv)
    from napari_lfdeblur import simulate_blur
    from napari_lfdeblur.metrics import path_error
    from napari_lfdeblur.path import center_path

    c, T = ev.CROP, ev.RENDER_TIMES
    scales = [float(s) for s in args.scales.split(",") if s]
    print("| case | group | d_inf | noise | rms of the blur | path scale | blur mismatch | best Gaussian (px) | "
          "rms left | within the noise |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    within = []
    for spec in ev.dev_study_cases(args):
        if spec.extent == 0:
            continue
        case = ev.make_case(spec)
        d = spec.infinity_disparity
        sharp = case.sharp.mean(axis=-1)
        cp = center_path(case.control_points, T)
        data = simulate_blur(sharp, cp, n_times=T, infinity_disparity=d)
        blur_rms = float(np.sqrt(((data - sharp)[:, :, c:-c, c:-c] ** 2).mean()))
        soft = {s: ndimage.gaussian_filter(sharp, (0, 0, s, s), mode="nearest") if s > 0 else sharp
                for s in SIGMAS}
        for scale in scales:
            mismatch = path_error(cp * scale, cp, lightfield=case.sharp, infinity_disparity=d).blur_mismatch
            left = []
            for s in SIGMAS:
                model = simulate_blur(soft[s], cp * scale, n_times=T, infinity_disparity=d)
                left.append(float(np.sqrt(((model - data)[:, :, c:-c, c:-c] ** 2).mean())))
            k = int(np.argmin(left))
            within.append(left[k] < spec.noise)
            print(f"| {spec.name} | {spec.group} | {d:+g} | {spec.noise:g} | {blur_rms:.4f} | {scale:.1f} | "
                  f"{mismatch:.3f} | {SIGMAS[k]:.2f} | {left[k]:.4f} | {'yes' if within[-1] else 'no'} |",
                  flush=True)
    print(f"\nwithin the noise: {sum(within)} of {len(within)} (case, scale) pairs")


if __name__ == "__main__":
    main()
