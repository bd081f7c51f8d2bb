"""Diagnostic: does the final solve's data residual tell right paths from wrong ones?

The discrepancy principle says that a restoration through the right blur
leaves a residual ``|K x - f|^2`` of about one noise variance per sample
(somewhat less: the TV prior takes some of the noise too), and that a path
the data cannot be explained with leaves more. This script measures that
residual for paths whose quality is known. For each development case of
``blind_eval.py`` it estimates the path blindly (``require_evidence=False``),
restores with the estimate, with the true path and with paths 0.5, 2 and 3
times the true one (``deconvolve`` with its default weight), and prints, per
path: the residual in noise variances per sample, as the solver's
discrepancy check computes it (``restoration_discrepancy``: the noise level
estimated in the blurred input, samples at the white level left out), the PSNR gain over the input and
the blur mismatch against the true path.

Usage::

    python benchmarks/dev/residual_check.py [--cases dev01,dev03,...] [--scales 0.5,2,3]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--scales", default="0.5,2,3", help="multiples of the true path to try")
    args = ap.parse_args(argv)

    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.blind._evidence import restoration_discrepancy
    from napari_lfdeblur.deconvolution import deconvolve, estimate_noise_sigma
    from napari_lfdeblur.metrics import path_error, psnr
    from napari_lfdeblur.path import center_path

    p = BlindParams.preset("default").replace(require_evidence=False)
    scales = [float(s) for s in args.scales.split(",") if s]
    print("case | group | d_inf | noise | path | residual (noise variances) | gain dB | blur mismatch")
    specs = ev.dev_study_cases(args)
    for spec in specs:
        t0 = time.perf_counter()
        case = ev.make_case(spec)
        d, f = case.infinity_disparity, case.blurred
        sigma = estimate_noise_sigma(f)
        start = psnr(f, case.sharp, crop=ev.CROP)
        true = center_path(case.control_points, p.n_times)
        est = blind_deblur(f, infinity_disparity=d, params=p, seed=0).control_points
        paths = {"estimate": est, "true": true, **{f"{s:g} x true": s * true for s in scales}}
        for label, cp in paths.items():
            x = deconvolve(f, cp, n_times=p.n_times, infinity_disparity=d)
            residual = restoration_discrepancy(f, x, cp, p.n_times, d, sigma, "auto")  # what the solver checks
            mismatch = path_error(cp, case.control_points, lightfield=case.sharp, infinity_disparity=d).blur_mismatch
            print(f"{spec.name} | {spec.group} | {d:+g} | {spec.noise:g} | {label} | "
                  f"{residual:.2f} | {psnr(x, case.sharp, crop=ev.CROP) - start:+.2f} | "
                  f"{mismatch:.2f}", flush=True)
        print(f"# {spec.name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
