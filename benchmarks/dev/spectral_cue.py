"""Diagnostic: could the blur be read off the data's power spectrum instead of its edges?

Spectral blind methods (Goldstein & Fattal, ECCV 2012) estimate a blur kernel
from the power spectrum of the blurred image's gradients: a natural scene's
gradient spectrum is taken to be about the same in every direction, so what
varies with direction is the kernel's ``|K|^2``. Fine texture, where the
salient-edge latent finds no edges (docs/blind.md, *Results and limits*), is
where such a method would have to help. This script measures its premise on
the development split of ``blind_eval.py``.

For each blurred case, in the path stage's frame (grayscale, refocused by
``d_inf``, 8 px borders cropped), it takes the gradient power spectrum of every
view (Hann window), averaged over the views, of the sharp and of the blurred
light field, and their *directional profiles*: the mean log power in each of
``--bins`` orientations of an annulus of 0.08 to 0.3 cycles/px, less its mean
over the orientations. It prints

- the scene's own anisotropy: the standard deviation of the sharp profile;
- the blur's: that of the profile of blurred over sharp (what the blur
  changes, per orientation);
- how well what a blind method sees, the blurred profile, follows the blur's
  profile (their correlation over the orientations).

Where the scene's anisotropy is as large as the blur's, the direction the
blurred spectrum is weakest in says more about the scene than about the blur.

Usage::

    python benchmarks/dev/spectral_cue.py [--cases dev11,dev16,dev17] [--bins 12]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)

BORDER = 8  # px cropped on every side (the replicate boundary and the refocusing's edge)
ANNULUS = (0.08, 0.3)  # cycles/px: above the window's leakage, below the noise floor


def gradient_power(views: np.ndarray) -> np.ndarray:
    """Mean over the views ``(N, Y, X)`` of the power spectrum of their gradients (forward differences)."""
    N, Y, X = views.shape
    window = np.outer(np.hanning(Y), np.hanning(X))
    spectra = np.fft.fft2((views - views.mean(axis=(1, 2), keepdims=True)) * window)
    power = (np.abs(spectra) ** 2).mean(axis=0)
    fy, fx = np.fft.fftfreq(Y)[:, None], np.fft.fftfreq(X)[None, :]
    return power * ((2 * np.sin(np.pi * fy)) ** 2 + (2 * np.sin(np.pi * fx)) ** 2)


def directional_profile(power: np.ndarray, bins: int) -> np.ndarray:
    """Mean log power per orientation bin over :data:`ANNULUS`, less its mean over the bins."""
    Y, X = power.shape
    fy, fx = np.fft.fftfreq(Y)[:, None], np.fft.fftfreq(X)[None, :]
    radius, angle = np.hypot(fy, fx), np.mod(np.arctan2(fy, fx), np.pi)
    ring = (radius > ANNULUS[0]) & (radius < ANNULUS[1])
    which = np.minimum((angle / np.pi * bins).astype(int), bins - 1)
    logp = np.log(np.maximum(power, 1e-30))
    profile = np.array([logp[ring & (which == k)].mean() for k in range(bins)])
    return profile - profile.mean()


def frame_views(lf: np.ndarray, d_inf: float) -> np.ndarray:
    """The path stage's grayscale views ``(V*U, Y, X)`` of a ``(V, U, Y, X, C)`` light field, borders cropped."""
    import torch

    from napari_lfdeblur.blind._disparity import gray, shear_spectral

    g = gray(torch.as_tensor(lf, dtype=torch.float32))
    if d_inf:
        g = shear_spectral(g, d_inf)
    g = g[:, :, BORDER:-BORDER, BORDER:-BORDER, 0].numpy().astype(np.float64)
    return g.reshape(-1, *g.shape[2:])


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--bins", type=int, default=12, help="orientation bins over 180 degrees")
    args = ap.parse_args(argv)
    print("| case | group | d_inf | blur length px | scene anisotropy | blur anisotropy | scene / blur | "
          "corr(blurred, blur) |")
    print("|---|---|---|---|---|---|---|---|")
    ratios, corrs = [], []
    for spec in ev.dev_study_cases(args):
        if spec.extent == 0:
            continue
        case = ev.make_case(spec)
        sharp = gradient_power(frame_views(case.sharp, case.infinity_disparity))
        blurred = gradient_power(frame_views(case.blurred, case.infinity_disparity))
        scene = directional_profile(sharp, args.bins)
        blur = directional_profile(np.divide(blurred, sharp, out=np.ones_like(sharp), where=sharp > 0), args.bins)
        seen = directional_profile(blurred, args.bins)
        ratio, corr = scene.std() / blur.std(), float(np.corrcoef(seen, blur)[0, 1])
        ratios.append(ratio)
        corrs.append(corr)
        print(f"| {spec.name} | {spec.group} | {case.infinity_disparity:+g} | {case.blur_px:.2f} | "
              f"{scene.std():.2f} | {blur.std():.2f} | {ratio:.1f} | {corr:+.2f} |", flush=True)
    print(f"\n{len(ratios)} blurred cases: scene / blur anisotropy median {np.median(ratios):.1f} "
          f"(above 1 on {sum(r > 1 for r in ratios)}); correlation median {np.median(corrs):+.2f} "
          f"(above 0.5 on {sum(c > 0.5 for c in corrs)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
