"""Diagnostic: how far the salient-edge latent alone moves the path fit off the truth.

For each case, a salient-edge latent is computed *at the true path* (three
half-quadratic splitting solves, ``lambda`` 4e-3, 2e-3, 1e-3, as the first
alternations do), with the edge model ``K_p G_sigma`` for each ``sigma`` given.
The path is then fitted to that latent, from the true path and from 300 random
starts, and the blur mismatch (docs/model.md) of the fit started at the
truth and of the best fit is printed. With the true sharp light field as the
latent both are 0.02 to 0.05, so what this prints is the latent's share of the
path error (docs/blind.md, "The alternating method", the edge model).

Usage::

    python benchmarks/dev/blind_latent_at_true_path.py [--cases syn-p1,lytro-p1,lytro2-p4] [--sigmas 0,0.3,0.5,0.8]

In-plane cases only (the true path's ``p_z`` is dropped for the latent).
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from blind_dev import _eval_module  # benchmarks/ is on the path when this script runs

from napari_lfdeblur.progress import run_to_completion


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default="syn-p1,lytro-p1,lytro2-p4")
    ap.add_argument("--sigmas", default="0,0.3,0.5,0.8")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    ev = _eval_module()
    from napari_lfdeblur import blind as B
    from napari_lfdeblur.blind._disparity import gray
    from napari_lfdeblur.blind._latent import EdgeBlurred, l0_latent
    from napari_lfdeblur.blind._path_fit import GramLoss, PathParam, fit_path
    from napari_lfdeblur.blur import BlurOperator
    from napari_lfdeblur.metrics import path_error
    from napari_lfdeblur.path import center_path

    p = B.BlindParams()
    T = p.n_times
    for name in args.cases.split(","):
        case = ev.make_case(name)
        g = gray(torch.as_tensor(case.blurred, dtype=torch.float32))
        V, U = g.shape[:2]
        box = p.path_box(V, U)
        true = center_path(case.control_points, T)
        true[:, 2] = 0.0
        for sigma in (float(s) for s in args.sigmas.split(",")):
            op = BlurOperator(tuple(g.shape), true, n_times=T, device="cpu")
            if sigma > 0:
                op = EdgeBlurred(op, sigma)
            latent = g.clone()
            for lam in (4e-3, 2e-3, 1e-3):
                latent = run_to_completion(l0_latent(op, g, lam, p.latent, latent))
            rng = np.random.default_rng(0)
            fit = GramLoss(g, p.path.n_pixels, rng, T, box, 0.0, 1)
            fit.set_latent(latent, true, p.path.robust, sigma)
            starts = [true] + [np.c_[rng.uniform(-1, 1, (4, 2)) * p.path.init_length, np.zeros(4)] for _ in range(300)]
            pp = PathParam(np.stack(starts), T, box, "cpu", free_z=False)
            pp.project()
            scores = run_to_completion(fit_path(pp, fit, p.path.steps, p.path.lr)).numpy()
            cps = pp.control_points().detach().double().numpy()
            k = int(np.argmin(scores))
            from_true = path_error(cps[0], case.control_points, lightfield=case.sharp).blur_mismatch
            best = path_error(cps[k], case.control_points, lightfield=case.sharp).blur_mismatch
            print(f"{name:9s} edge sigma {sigma:4.2f} px  blur mismatch: fit from the true path {from_true:.3f}, "
                  f"best fit {best:.3f}", flush=True)


if __name__ == "__main__":
    main()
