"""Diagnostic: why the large blurs of the real captures come back as no motion.

On the development split every real capture blurred by 1.7 px or more
(``eval_set.blur_length``) comes back from the path stage as no motion, while
rendered scenes blurred that much are found. This script separates what a
real capture brings. For each case it runs the default path stage (evidence
test off, so that the estimate itself is seen) on the case's sharp light field,
blurred by the case's path and noise, and on two variants of it:

- ``lambertian``: the centre view re-rendered into every view with the scene's
  own disparity map (bilinear), an exact Lambertian light field of the same
  content: no lenslet softness, vignetting or view-to-view differences;
- ``weight / 16``: the case as is, with the salient-edge weight
  (``latent.l0_weight``) 16 times smaller: for the latent, edges of a quarter
  of the contrast count as much (as if the scene had four times its contrast,
  without clipping it).

It prints the true blur length, the estimate's and its blur mismatch.
Where the variants collapse as the case does, the cause is the content's
texture (fine, without step edges that survive the blur), not the capture's
angular structure nor its contrast.

Usage::

    python benchmarks/dev/texture_collapse.py [--cases dev11,dev16,dev17,dev04]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.ndimage import map_coordinates

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)
import eval_set  # noqa: E402  (benchmarks/eval_set.py)

DEFAULT_CASES = "dev11,dev16,dev17,dev04"


def lambertian(sharp: np.ndarray, disparity: np.ndarray) -> np.ndarray:
    """The centre view of ``sharp`` (V, U, Y, X, C) seen from every view at ``disparity`` (Y, X), px/view."""
    V, U, Y, X, C = sharp.shape
    centre = sharp[V // 2, U // 2].astype(np.float64)
    yy, xx = np.mgrid[0:Y, 0:X].astype(np.float64)
    out = np.empty_like(sharp)
    for v in range(V):
        for u in range(U):
            at = [yy - disparity * (v - V // 2), xx - disparity * (u - U // 2)]
            for c in range(C):
                out[v, u, ..., c] = map_coordinates(centre[..., c], at, order=1, mode="nearest")
    return out


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.set_defaults(cases=DEFAULT_CASES)
    args = ap.parse_args(argv)

    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.metrics import path_error

    params = BlindParams.preset("default").replace(require_evidence=False, final={"n_iter": 1})
    weak = params.replace(latent={"l0_weight": params.latent.l0_weight / 16})
    print("case | group | d_inf | variant | true blur px | estimated blur px | blur mismatch")
    for spec in ev.dev_study_cases(args):
        sharp = eval_set.sharp_lightfield(spec)
        disparity = eval_set.scene_disparity(spec, sharp)
        cp = eval_set.true_path(spec)
        variants = {"as is": (sharp, params), "lambertian": (lambertian(sharp, disparity), params),
                    "weight / 16": (sharp, weak)}
        for label, (lf, p) in variants.items():
            blurred = eval_set.blurred_lightfield(spec, lf, cp)
            res = blind_deblur(blurred, infinity_disparity=spec.infinity_disparity, params=p, device="cpu", seed=0)
            true_px = eval_set.blur_length(cp, lf, disparity, spec.infinity_disparity)
            est_px = eval_set.blur_length(res.control_points, lf, disparity, spec.infinity_disparity)
            err = path_error(res.control_points, cp, n_times=ev.PATH_TIMES, lightfield=lf,
                             infinity_disparity=spec.infinity_disparity)
            print(f"{spec.name} | {spec.group} | {spec.infinity_disparity:+g} | {label} | {true_px:.2f} | "
                  f"{est_px:.2f} | {err.blur_mismatch:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
