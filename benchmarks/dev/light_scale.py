"""Diagnostic: how much of the estimated path a light restoration should keep.

Where the evidence test finds little blur, ``BlindParams.light_restoration``
restores with the estimated path scaled about its mean. This script measures
what each scale is worth. For each development case of ``blind_eval.py`` it
estimates the path blindly (the default preset, without the final stage),
then restores with the estimate scaled by each of ``--scales``
(``deconvolve`` with the final stage's settings) and prints, per scale, the
PSNR gain over the input and the blur mismatch against the true path, and at
the end the mean and the worst gain of each scale. Scale 0 is the input
itself.

Usage::

    python benchmarks/dev/light_scale.py [--cases dev01,dev03,...] [--scales 0.25,0.5,0.75,1]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--scales", default="0.25,0.5,0.75,1", help="scales of the estimated path to try")
    args = ap.parse_args(argv)

    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.deconvolution import deconvolve
    from napari_lfdeblur.metrics import path_error, psnr

    p = BlindParams.preset("default")
    scales = [float(s) for s in args.scales.split(",") if s]
    gains = {s: [] for s in scales}
    print("case | group | d_inf | noise | scale | gain dB | blur mismatch")
    specs = ev.dev_study_cases(args)
    for spec in specs:
        t0 = time.perf_counter()
        case = ev.make_case(spec)
        d, f = case.infinity_disparity, case.blurred
        start = psnr(f, case.sharp, crop=ev.CROP)
        res = blind_deblur(f, infinity_disparity=d, params=p.replace(require_evidence=False, final=None), seed=0)
        for s in scales:
            cp = s * res.control_points
            x = deconvolve(f, cp, n_times=p.final_n_times, infinity_disparity=d, params=p.final) if s else f
            mismatch = path_error(cp, case.control_points, lightfield=case.sharp, infinity_disparity=d).blur_mismatch
            gains[s].append(psnr(x, case.sharp, crop=ev.CROP) - start)
            print(f"{spec.name} | {spec.group} | {d:+g} | {spec.noise:g} | {s:g} | {gains[s][-1]:+.2f} | "
                  f"{mismatch:.2f}", flush=True)
        print(f"# {spec.name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    for s in scales:
        g = np.array(gains[s])
        print(f"scale {s:g}: mean gain {g.mean():+.2f} dB, worst {g.min():+.2f} dB, "
              f"{int((g < -0.1).sum())} of {len(g)} cases worse than the input by more than 0.1 dB")


if __name__ == "__main__":
    main()
