"""Diagnostic: blind deblurring of the same blurred light field at lower exposures.

The salient-edge latent of the blind solver (docs/blind.md) keeps the
gradients above a fixed threshold, on an absolute intensity scale. So the
same scene, darker, shows it fewer edges. For each chosen development case of
``blind_eval.py`` this script multiplies the sharp and the blurred light
field by each of ``--exposures`` and runs ``blind_deblur`` (the ``default``
preset, the true ``d_inf``) on the darkened input, and on it stretched back
to [0, 1] by its own minimum and maximum (what ``value_range='auto'`` does
when reading a file). It prints the PSNR gain over the darkened input
(8 px borders cropped; judged at the darkened scale), the restoration
(``full``, ``light`` or ``none``) and the input's ``info['brightest']``.

Usage::

    python benchmarks/dev/exposure.py [--cases dev01,dev05,dev06] [--exposures 1,0.25]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--exposures", default="1,0.25", help="factors applied to the light fields")
    args = ap.parse_args(argv)
    if not args.cases:
        args.cases = "dev01,dev05,dev06"
    from napari_lfdeblur.blind import blind_deblur
    from napari_lfdeblur.metrics import psnr

    exposures = [float(e) for e in args.exposures.split(",") if e]
    print("case | exposure | brightest | gain dB, as it is | restoration | gain dB, stretched | restoration")
    for spec in ev.dev_study_cases(args):
        case = ev.make_case(spec)
        for a in exposures:
            sharp, blurred = case.sharp * a, (case.blurred * a).astype(np.float32)
            base = psnr(blurred, sharp, crop=ev.CROP, data_range=a)
            res = blind_deblur(blurred, infinity_disparity=case.infinity_disparity, device="cpu", seed=0)
            lo, hi = float(blurred.min()), float(blurred.max())
            res_s = blind_deblur((blurred - lo) / (hi - lo), infinity_disparity=case.infinity_disparity,
                                 device="cpu", seed=0)
            back = res_s.lightfield * (hi - lo) + lo
            gains = [psnr(out, sharp, crop=ev.CROP, data_range=a) - base for out in (res.lightfield, back)]
            print(f"{spec.name} | {a:g} | {res.info['brightest']:.3f} | {gains[0]:+.2f} | {res.info['restoration']} | "
                  f"{gains[1]:+.2f} | {res_s.info['restoration']}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
