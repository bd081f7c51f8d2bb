"""The TV's angular differences: along the scene's disparity or along the view axes, with the true path.

``deconvolve`` (``method='tv'``) charges the differences between
neighbouring views. ``angular='views'`` compares the same pixel of two
views, which also charges the parallax of every textured point off the
plane of zero disparity; ``angular='disparity'`` (the default) compares the
samples that a Lambertian scene makes equal (docs/deconvolution.md,
*Angular differences*). This script restores every case of the development
split of ``blind_eval.py`` with its **true** path, non-blind, with four
priors at the default weight rule (``weight=None``): the two kinds of
angular differences, each with the isotropic and the anisotropic TV (the
default is the anisotropic TV along the disparity; ``lfdeblur deconvolve
--along-views`` is the isotropic TV along the views). It reports
the mean PSNR gain over the blurred input by group, the smallest gain, and
the time per light field.

Usage::

    python benchmarks/angular_tv.py             # writes docs/benchmarks/angular_tv.md
    python benchmarks/angular_tv.py --quick     # two tiny cases, writes nothing unless --out
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)

#: (label, angular, isotropic) of the priors compared: the first is ``--along-views``, the last the default
PRIORS = (("views, isotropic", "views", True), ("views, anisotropic", "views", False),
          ("disparity, isotropic", "disparity", True), ("disparity, anisotropic (default)", "disparity", False))


def restore_all(case, n_times: int) -> dict:
    """Gains (dB) and seconds of each prior on one case."""
    from napari_lfdeblur import deconvolve
    from napari_lfdeblur.metrics import psnr
    from napari_lfdeblur.path import center_path

    crop = 2 if case.sharp.shape[2] < 32 else ev.CROP
    cp = center_path(case.control_points, n_times)
    base = psnr(case.blurred, case.sharp, crop=crop)
    row = {"case": case.name, "group": case.spec.group}
    for label, angular, isotropic in PRIORS:
        t0 = time.perf_counter()
        out = deconvolve(case.blurred, cp, n_times=n_times, infinity_disparity=case.infinity_disparity,
                         angular=angular, isotropic=isotropic)
        row[label] = (psnr(out, case.sharp, crop=crop) - base, time.perf_counter() - t0)
        print(f"{case.name} {label}: {row[label][0]:+.2f} dB, {row[label][1]:.1f} s", flush=True)
    return row


def summary(rows: list[dict]) -> list[str]:
    """The table: per group and prior, the mean and smallest gain and the mean and largest time."""
    groups = ["all"] + [g for g in ev.eval_set.GROUPS if any(r["group"] == g for r in rows)]
    lines = ["| group | cases | " + " | ".join(f"{label}: gain dB (worst)" for label, _, _ in PRIORS)
             + " | time s (mean, max): views, isotropic / disparity, anisotropic (default) |",
             "|---|---|" + "---|" * (len(PRIORS) + 1)]
    for g in groups:
        sel = [r for r in rows if g == "all" or r["group"] == g]
        cells = []
        for label, _, _ in PRIORS:
            gains = [r[label][0] for r in sel]
            cells.append(f"{np.mean(gains):+.2f} ({min(gains):+.2f})")
        t_old, t_new = ([r[PRIORS[i][0]][1] for r in sel] for i in (0, -1))
        times = f"{np.mean(t_old):.1f}, {max(t_old):.1f} / {np.mean(t_new):.1f}, {max(t_new):.1f}"
        lines.append(f"| {g} | {len(sel)} | " + " | ".join(cells) + f" | {times} |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two tiny cases, writes nothing unless --out")
    ap.add_argument("--threads", type=int, default=2, help="torch's threads (default 2)")
    _report.add_out_argument(ap, __file__)
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(args.threads)
    specs, skipped = ev.select_cases("dev", quick=args.quick)
    if args.quick:
        specs = specs[:2]
    cases = [ev.make_case(spec, quick=args.quick) for spec in specs]
    rows = [restore_all(case, 8 if args.quick else ev.SOLVE_TIMES) for case in cases]
    shape = "x".join(map(str, cases[0].sharp.shape))
    body = [
        f"Every case of the development split of `blind_eval.py` ({shape}; cases it could not load: "
        f"{', '.join(skipped) or 'none'}), restored by `deconvolve` with its true path, its `d_inf` and "
        "`weight=None` (the noise rule; the anisotropic TV's weight is half the isotropic one's). Gains are PSNR "
        "over the blurred input (dB, 8-px border excluded), the mean over the group's cases and, in brackets, the "
        "smallest. The reference of a real capture (F01, Illum) holds the camera's own noise, which any "
        "denoising removes: there the gains count that as an error.",
        "",
        *summary(rows),
    ]
    path = _report.table_path(args.out, __file__, smoke=args.quick)
    if path is not None:
        _report.write_table(path, "Angular differences of the TV, with the true path", _report.command_line(__file__),
                            _report.machine("auto"), body)
    else:
        print("\n".join(body))
    return 0


if __name__ == "__main__":
    sys.exit(main())
