"""Diagnostic: how the number of alternations of the path stage changes the estimated path.

The alternating blind method (docs/blind.md) runs ``path.n_outer``
alternations of a salient-edge latent and a path fit with ``p_z`` held at 0,
then ``path.z_outer`` more with ``p_z`` free. This script measures what each
schedule gives. For each development case of ``blind_eval.py`` it estimates
the path blindly with each schedule of ``--schedules`` (``n_outer:z_outer``,
the rest of the default preset, the evidence test off, no final stage) and
prints, per case and schedule, the in-plane extents of the true and the
estimated paths (views), the blur mismatch of the estimate and of the
estimate at half its length (the light restoration's path), and the time of
the call; at the end, per schedule, the mean mismatches over the blurred
cases (the unblurred case has no mismatch) and the mean time.

Usage::

    python benchmarks/dev/alternations.py [--cases dev01,dev03,...] [--schedules 1:1,2:1,6:3]
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
    ap.add_argument("--schedules", default="1:1,2:1,6:3", help="comma-separated n_outer:z_outer pairs")
    args = ap.parse_args(argv)

    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.metrics import path_error
    from napari_lfdeblur.path import bezier_positions

    base = BlindParams.preset("default").replace(require_evidence=False, final=None)
    schedules = [tuple(int(n) for n in s.split(":")) for s in args.schedules.split(",") if s]
    specs = ev.dev_study_cases(args)
    stats = {s: ([], [], []) for s in schedules}  # mismatch, mismatch at half length, seconds

    def extent(cp):
        return float(np.ptp(bezier_positions(np.asarray(cp), base.n_times)[:, :2], axis=0).max())

    print("case | group | d_inf | schedule | true extent | estimated extent | blur mismatch | at half length | s")
    for spec in specs:
        case = ev.make_case(spec)
        d = case.infinity_disparity
        for n_outer, z_outer in schedules:
            p = base.replace(path=base.path.replace(n_outer=n_outer, z_outer=z_outer))
            t0 = time.perf_counter()
            res = blind_deblur(case.blurred, infinity_disparity=d, params=p, seed=0)
            seconds = time.perf_counter() - t0
            mm = [path_error(s * res.control_points, case.control_points, lightfield=case.sharp,
                             infinity_disparity=d).blur_mismatch for s in (1.0, 0.5)]
            got = stats[(n_outer, z_outer)]
            got[2].append(seconds)
            if np.isfinite(mm[0]):
                got[0].append(mm[0])
                got[1].append(mm[1])
            print(f"{spec.name} | {spec.group} | {d:+g} | {n_outer}:{z_outer} | {extent(case.control_points):.2f} | "
                  f"{extent(res.control_points):.2f} | {mm[0]:.2f} | {mm[1]:.2f} | {seconds:.0f}", flush=True)
    for (n_outer, z_outer), (mm, half, seconds) in stats.items():
        print(f"schedule {n_outer}:{z_outer}: mean blur mismatch {np.mean(mm):.3f}, at half length "
              f"{np.mean(half):.3f} ({len(mm)} blurred cases); {np.mean(seconds):.1f} s per case")


if __name__ == "__main__":
    main()
