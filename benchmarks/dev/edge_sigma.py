"""Diagnostic: how the edge model's width changes the estimated path, case by case.

The path fit explains the blurred light field as the blur of a salient-edge
latent that is taken to be sharper than the scene by a spatial Gaussian of
``BlindParams.latent.edge_sigma`` px (docs/blind.md); what that Gaussian
does not explain of the scene's own edge softness, the path absorbs, and it
comes out too long. This script estimates the path (the default preset, no
final stage) of each development case of ``blind_eval.py`` with each of
``--sigmas`` and prints the blur mismatch against the true path, the ratio
of the estimate's RMS in-plane spread to the truth's (1: the right length;
above 1: too long), and whether the evidence test found the blur. At the end:
the mean and median mismatch of each width, and the number of cases below
0.3.

A width that suits one kind of scene can collapse the path on another, so
a better fixed default is not the point: the numbers say whether the
width should be chosen from the data.

Usage::

    python benchmarks/dev/edge_sigma.py [--cases dev00,dev05] [--sigmas 0.5,0.8,1.1]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--sigmas", default="0.5,0.8,1.1", help="edge model widths (px) to try")
    args = ap.parse_args(argv)

    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.metrics import path_error

    sigmas = [float(s) for s in args.sigmas.split(",") if s]
    base = BlindParams.preset("default").replace(require_evidence=False, final=None)
    mismatches = {s: [] for s in sigmas}
    print("case | group | d_inf | noise | edge_sigma | blur mismatch | spread ratio | blur found")
    for spec in ev.dev_study_cases(args):
        case = ev.make_case(spec)
        d = case.infinity_disparity
        true_spread = ev.path_spread(case.control_points)
        for s in sigmas:
            res = blind_deblur(case.blurred, infinity_disparity=d, params=base.replace(latent={"edge_sigma": s}),
                               seed=0)
            m = path_error(res.control_points, case.control_points, lightfield=case.sharp,
                           infinity_disparity=d).blur_mismatch
            mismatches[s].append(m)
            ratio = ev.path_spread(res.control_points) / true_spread if true_spread else float("nan")
            print(f"{spec.name} | {spec.group} | {d:+g} | {spec.noise:g} | {s:g} | {m:.3f} | {ratio:.2f} | "
                  f"{res.info['blur_found']}", flush=True)
    for s in sigmas:
        m = np.array([v for v in mismatches[s] if np.isfinite(v)])
        print(f"edge_sigma {s:g}: mean mismatch {m.mean():.3f}, median {np.median(m):.3f}, "
              f"{int((m < 0.3).sum())} of {m.size} below 0.3")


if __name__ == "__main__":
    main()
