"""The default TV weight: how good is ``NOISE_WEIGHT_FACTOR * estimated sigma``?

``deconvolve(method='tv')`` with ``weight=None`` uses ``w = NOISE_WEIGHT_FACTOR
* sigma``, ``sigma`` from ``estimate_noise_sigma`` on the blurred input, for
every channel with its own TV, ``COLOUR_WEIGHT_FACTOR * sigma`` for the colour
TV (``couple_channels``), and ``ANISOTROPIC_WEIGHT_SCALE`` times that for the
anisotropic TV, here the default, the colour TV along the scene's disparity
(``angular='disparity', isotropic=False``; the other two priors are the
isotropic TV along the views). This script checks the rule on cases of its own, not
the evaluation set of ``blind_eval.py``: the package's ``synthetic_scene``
(piecewise-constant textures, random colours) and ``procedural_scene``
(natural textures), two seeds each, blurred by random paths with ``p_z !=
0`` at ``d_inf`` 0 and 1, with Gaussian noise 0.002, 0.01 and 0.02. For each
case and prior it reports

- the noise estimate against the noise added (the scene's own fine detail
  makes it err high);
- the PSNR of the non-blind TV solve with the true path for weights
  ``factor * sigma_est`` over a grid of factors, against the sharp light field;
- the best factor of the grid, and what the rule's factor loses against it.

Usage::

    python benchmarks/weight_rule.py            # writes docs/benchmarks/weight_rule.md
    python benchmarks/weight_rule.py --quick    # one small case, writes nothing (or the table to --out)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from napari_lfdeblur import deconvolve, procedural_scene, simulate_blur, synthetic_scene
from napari_lfdeblur.deconvolution import (
    ANISOTROPIC_WEIGHT_SCALE,
    COLOUR_WEIGHT_FACTOR,
    NOISE_WEIGHT_FACTOR,
    estimate_noise_sigma,
)
from napari_lfdeblur.metrics import psnr
from napari_lfdeblur.path import center_path, random_path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)

FACTORS = (0.1, 0.15, 0.2, 0.3, 0.45, 0.7)
NOISES = (0.002, 0.01, 0.02)
SCENES = (("synthetic", 0), ("synthetic", 1), ("procedural", 0), ("procedural", 1))
#: the priors (``deconvolve``'s options): the isotropic TV along the views (``lfdeblur deconvolve
#: --along-views``) of every channel on its own and over the channels (``couple_channels``), and the default,
#: the anisotropic colour TV along the scene's disparity
VIEWS = {"angular": "views", "isotropic": True}
PRIORS = {"separate": {"couple_channels": False, **VIEWS}, "colour": {"couple_channels": True, **VIEWS},
          "disparity": {"couple_channels": True, "angular": "disparity", "isotropic": False}}
#: the default rule's factor of each prior, in units of its isotropic rule (an anisotropic prior's weight is
#: ``ANISOTROPIC_WEIGHT_SCALE`` times that: ``factor * ANISOTROPIC_WEIGHT_SCALE * sigma``)
RULES = {"separate": NOISE_WEIGHT_FACTOR, "colour": COLOUR_WEIGHT_FACTOR, "disparity": COLOUR_WEIGHT_FACTOR}
D_INFS = (0.0, 1.0)
N_TIMES = 16
CROP = 4


def make_case(shape, scene, d_inf, noise):
    """One case: the sharp light field, the true path and the blurred, noisy input."""
    kind, seed = scene
    if kind == "synthetic":
        lf, _ = synthetic_scene(shape, color=True, seed=seed)
    else:
        lf, _ = procedural_scene(shape, seed=seed)
    cp = center_path(random_path(3, extent=2.0, z_extent=1.0, seed=seed + 10), N_TIMES)
    blurred = simulate_blur(lf, cp, n_times=N_TIMES, infinity_disparity=d_inf)
    blurred = blurred + np.random.default_rng(seed).normal(0, noise, lf.shape).astype(np.float32)
    return lf, cp, blurred


def run_case(lf, cp, blurred, d_inf, factors, options):
    """The PSNR gain over the input at each factor, with one prior (``deconvolve``'s ``options``)."""
    sigma = estimate_noise_sigma(blurred)
    base = psnr(blurred, lf, crop=CROP)
    scale = 1.0 if options["isotropic"] else ANISOTROPIC_WEIGHT_SCALE
    gains = []
    for f in factors:
        out = deconvolve(blurred, cp, n_times=N_TIMES, infinity_disparity=d_inf, weight=f * scale * sigma,
                         **options)
        gains.append(psnr(out, lf, crop=CROP) - base)
    return gains


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one small case, writes nothing unless --out")
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    torch.set_num_threads(2)
    factors = FACTORS if not args.quick else (0.15,)
    factors = tuple(sorted(set(factors) | set(RULES.values())))
    grid = [(sc, d, n) for sc in SCENES for d in D_INFS for n in NOISES] if not args.quick else [(SCENES[2], 1.0, 0.01)]
    shape = (5, 5, 64, 64) if not args.quick else (3, 3, 24, 24)
    head = "| scene | d_inf | noise | sigma estimated | prior | " + " | ".join(f"gain at {f} dB" for f in factors)
    rows = [head + " | best factor | rule loses dB |", "|" + "---|" * (len(factors) + 7)]
    by_noise = {}
    for scene, d_inf, noise in grid:
        lf, cp, blurred = make_case(shape, scene, d_inf, noise)
        sigma = estimate_noise_sigma(blurred)
        for prior, options in PRIORS.items():
            gains = run_case(lf, cp, blurred, d_inf, factors, options)
            best, rule = int(np.argmax(gains)), factors.index(RULES[prior])
            by_noise.setdefault((noise, prior), []).append(gains)
            by_noise.setdefault((noise, f"{prior}, {scene[0]}"), []).append(gains)
            rows.append(f"| {scene[0]} {scene[1]} | {d_inf:+g} | {noise:g} | {sigma:.4f} ({sigma / noise:.2f}x) | "
                        f"{prior} | " + " | ".join(f"{g:+.2f}" for g in gains)
                        + f" | {factors[best]} | {gains[best] - gains[rule]:.2f} |")
            print(rows[-1], flush=True)
    summary = ["| noise | prior, scenes | cases | " + " | ".join(f"mean gain at {f} dB" for f in factors) + " |",
               "|" + "---|" * (len(factors) + 3)]
    for (noise, prior), gains in sorted(by_noise.items(), key=lambda kv: (kv[0][0], kv[0][1])):
        mean = np.mean(gains, axis=0)
        label = prior if "," in prior else f"{prior}, all"
        summary.append(f"| {noise:g} | {label} | {len(gains)} | " + " | ".join(f"{g:+.2f}" for g in mean) + " |")
    body = [
        f"The package's `synthetic_scene` and `procedural_scene`, {'x'.join(map(str, shape))}x3, "
        f"{', '.join(f'{k} seed {s}' for k, s in SCENES)}; random paths "
        f"of 3 control points (extent 2 views, `p_z` extent 1), T = {N_TIMES}; Gaussian noise; the non-blind "
        f"TV solve (`deconvolve`, default iterations and stopping) with the true path and the weight "
        f"`factor * sigma`, `sigma` estimated in the blurred input (`estimate_noise_sigma`), with the "
        f"isotropic TV along the views (`angular='views', isotropic=True`) of every channel on its own "
        f"(`separate`) and over the channels (`colour`, `couple_channels=True`), and with the default, the "
        f"anisotropic colour TV along the scene's disparity (`disparity`, `angular='disparity', "
        f"isotropic=False`), whose weight is `factor * {ANISOTROPIC_WEIGHT_SCALE} * sigma` "
        f"(`ANISOTROPIC_WEIGHT_SCALE`). Gains are "
        f"PSNR over the blurred input, borders of {CROP} px left out. The default rule's factor is "
        f"{NOISE_WEIGHT_FACTOR} (`NOISE_WEIGHT_FACTOR`), {COLOUR_WEIGHT_FACTOR} for the colour TV "
        f"(`COLOUR_WEIGHT_FACTOR`, also the `disparity` prior's in these units); 'rule loses' is against the "
        f"prior's own factor. These cases are not those of `blind_eval.py`.",
        "", "## Mean gain by noise level", "", *summary, "", "## Per case", "", *rows,
    ]
    out = _report.table_path(args.out, __file__, smoke=args.quick)
    if out is not None:
        _report.write_table(out, "The default TV weight: factor times the estimated noise",
                            _report.command_line(__file__, argv), _report.machine("auto"), body)


if __name__ == "__main__":
    main()
