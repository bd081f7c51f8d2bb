"""Diagnostic: what the first alternation sees, and why some blurred cases come back with no motion.

The alternating blind method (docs/blind.md) starts from the salient-edge
latent under no motion, ``argmin_l ||l - g||^2 + lambda ||grad l||_0`` at the
first weight ``lambda = latent.l0_weight``, and fits the path to it. For each
development case of ``blind_eval.py`` this script prints

- the share of the latent's samples that keep their (weighted 4D) gradient,
  the ``||grad l||_0`` of its objective: the edges the first path fit can use;
- the scale ``a`` of the true path, among ``--scales``, that the path stage's
  gradient-domain fit prefers under three latents: the first one (no
  motion), the salient-edge latent under the true path (same weight), and
  the sharp light field itself (the truth, refocused like the input).

Where the truth prefers ``a = 1`` but the first latent prefers 0, the model
and the fit are right and the latent is what fails; where the latent under
the true path prefers ``a = 1`` and the first latent 0, the alternation has
two fixed points and starts at the wrong one.

Usage::

    python benchmarks/dev/first_latent.py [--cases dev05,dev14,dev16,dev17] [--scales 0,0.25,0.5,1,1.5]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--scales", default="0,0.25,0.5,1,1.5", help="scales of the true path to fit")
    args = ap.parse_args(argv)

    from napari_lfdeblur.blind import BlindParams
    from napari_lfdeblur.blind._disparity import disparity_weights, gray, shear_spectral
    from napari_lfdeblur.blind._latent import difference_pair, l0_latent
    from napari_lfdeblur.blind._path_fit import GramLoss
    from napari_lfdeblur.blur import BlurOperator
    from napari_lfdeblur.path import center_path
    from napari_lfdeblur.progress import run_to_completion

    p = BlindParams.preset("default")
    lam = p.latent.l0_weight
    grad, _ = difference_pair(p.latent.angular_weight)
    scales = [float(s) for s in args.scales.split(",") if s]
    print(f"first weight {lam:g}; best scale of the true path among {scales} under each latent")
    print("case | group | d_inf | extent | noise | edges kept % | first latent (no motion) | "
          "latent under the true path | the truth")
    for spec in ev.dev_study_cases(args):
        if spec.extent == 0:
            continue
        case = ev.make_case(spec)
        d = case.infinity_disparity
        g = gray(torch.as_tensor(case.blurred, dtype=torch.float32))
        truth = gray(torch.as_tensor(case.sharp, dtype=torch.float32))
        if d:  # the path stage's d_inf = 0 frame
            g, truth = shear_spectral(g, d), shear_spectral(truth, d)
        V, U = g.shape[:2]
        box = p.path_box(V, U)
        cp_true = center_path(case.control_points, p.n_times)

        def latent(cp):
            op = BlurOperator(tuple(g.shape), cp, n_times=p.n_times, infinity_disparity=0.0)
            return run_to_completion(l0_latent(op, g, lam, p.latent, g.clone()))

        first = latent(np.zeros((2, 3)))
        kept = float((sum(c * c for c in grad(first)) >= lam / p.latent.hqs_beta_max).float().mean())
        fit = GramLoss(g, p.path.n_pixels, np.random.default_rng(0), p.n_times, box, box * p.path.z_box,
                       p.path.tiles, weight=disparity_weights(g, p.path.disparity_weight))
        best = []
        for lat in (first, latent(cp_true), truth):
            fit.set_latent(lat)
            fits = [float(fit(torch.as_tensor(a * cp_true, dtype=torch.float32))) for a in scales]
            best.append(scales[int(np.argmin(fits))])
        print(f"{spec.name} | {spec.group} | {d:+g} | {spec.extent:.2f} | {spec.noise:g} | {100 * kept:.1f} | "
              + " | ".join(f"{b:g}" for b in best), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
