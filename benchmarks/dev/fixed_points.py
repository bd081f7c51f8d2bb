"""Diagnostic: the path fit agrees with whatever salient-edge latent it is given.

The alternating blind method (docs/blind.md) alternates a salient-edge latent
``l_p = argmin_l ||K_p G_sigma l - g||^2 + lambda ||grad l||_0`` and a path fit
against that latent (the gradient-domain quadratic form of the path stage).
This script asks which path the fit prefers under which latent. For each
evaluation case of ``blind_eval.py`` (development split) it estimates the path
blindly, builds the latent (``lambda`` at its floor, the edge model on) under
three paths (the true one, the estimate, and no motion) and evaluates the fit
of each of the three paths against each latent, on one fixed set of pixels.
It prints the fits relative to the true path's under the same latent
(negative: better than the true path; the fit is ``k^T G k - 2 b^T k``, a
constant left out), then each path's fit under its own latent relative to the
true path's under its own, with the estimate's blur mismatch, its gain when
restored whatever the evidence, and the in-plane extents of both paths.

A fit that prefers, under every latent, the path that made that latent shows
that the alternation has many fixed points; comparing the three diagonal
entries (each path under its own latent) shows which fixed point the
objective itself would choose.

Usage::

    python benchmarks/dev/fixed_points.py [--cases dev01,dev02,dev03,dev04,dev05,dev07]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="dev01,dev02,dev03,dev04,dev05,dev07")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)

    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.blind._disparity import disparity_weights, gray, shear_spectral
    from napari_lfdeblur.blind._latent import EdgeBlurred, edge_sigmas, l0_latent
    from napari_lfdeblur.blind._path_fit import GramLoss
    from napari_lfdeblur.blur import BlurOperator
    from napari_lfdeblur.metrics import path_error, psnr
    from napari_lfdeblur.path import bezier_positions, center_path
    from napari_lfdeblur.progress import run_to_completion

    p = BlindParams.preset("default")
    lam = p.latent.l0_weight * p.latent.l0_floor
    sigma = edge_sigmas(p.latent)
    names = ("true", "estimate", "zero")
    print("case | mismatch | gain dB restored anyway | latent under | fit of: " + " / ".join(names)
          + " (relative to the true path's, x1e-3)")
    for name in args.cases.split(","):
        specs, _ = ev.select_cases("dev", [name])
        case = ev.make_case(specs[0])
        d = case.infinity_disparity
        res = blind_deblur(case.blurred, infinity_disparity=d, params=p.replace(require_evidence=False), seed=0)
        mismatch = path_error(res.control_points, case.control_points, lightfield=case.sharp,
                              infinity_disparity=d).blur_mismatch
        gain = psnr(res.lightfield, case.sharp, crop=ev.CROP) - psnr(case.blurred, case.sharp, crop=ev.CROP)
        g = gray(torch.as_tensor(case.blurred))
        g = shear_spectral(g, d) if d else g  # the path stage's d_inf = 0 frame
        box = res.info["box"]  # the solver's box for the path, views
        fit = GramLoss(g, p.path.n_pixels, np.random.default_rng(0), p.n_times, box, box * p.path.z_box,
                       p.path.tiles, weight=disparity_weights(g, p.path.disparity_weight))
        paths = (center_path(case.control_points, p.n_times), np.asarray(res.control_points), np.zeros((2, 3)))
        extents = [np.ptp(bezier_positions(c, p.n_times)[:, :2], axis=0) for c in paths[:2]]
        print(f"{name} | in-plane extent (x, y), views: true {extents[0].round(2)}, estimate {extents[1].round(2)}")
        own = []  # each path's fit under its own latent
        for under, cp in zip(names, paths):
            op = EdgeBlurred(BlurOperator(tuple(g.shape), cp, n_times=p.n_times, infinity_disparity=0.0), sigma)
            latent = run_to_completion(l0_latent(op, g, lam, p.latent, g.clone()))
            fit.set_latent(latent, None, 0.0, sigma)
            values = [float(fit(torch.as_tensor(c, dtype=torch.float32))) for c in paths]
            own.append(values[len(own)])
            rel = [1e3 * (v - values[0]) / abs(values[0]) for v in values]
            print(f"{name} | {mismatch:.2f} | {gain:+.2f} | {under} | " + " / ".join(f"{r:+.2f}" for r in rel),
                  flush=True)
        rel = [1e3 * (v - own[0]) / abs(own[0]) for v in own]
        print(f"{name} | | | each under its own latent | " + " / ".join(f"{r:+.2f}" for r in rel), flush=True)


if __name__ == "__main__":
    main()
