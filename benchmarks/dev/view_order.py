"""Diagnostic: the view order of the Lytro capture, and what it does to the blind solver's disparity map.

Prints, for the F01 capture of the evaluation (``eval_set.F01_CAPTURE``) read as its
names say (``RR`` the view row) and read the other way round, the motion per
view step (``view_shifts``: row ``v``, then row ``u``; columns ``y``, ``x``;
px/view), and for four 128 x 128 crops of it (centre and three corners) the
percentiles of the disparity map the blind solver weights its fit pixels by
(``disparity_map`` of ``napari_lfdeblur.blind._disparity`` on the grayscale sharp crop). docs/io.md
("View order") explains why the view order matters.

Usage::

    python benchmarks/dev/view_order.py
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import eval_set  # noqa: E402  (benchmarks/eval_set.py)


def main():
    torch.set_num_threads(2)
    from napari_lfdeblur import read_lightfield, view_shifts
    from napari_lfdeblur.blind._disparity import disparity_map, gray
    from napari_lfdeblur.io import ViewOrderWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ViewOrderWarning)
        as_named = read_lightfield(eval_set.F01_CAPTURE)
    upright = read_lightfield(eval_set.F01_CAPTURE, pattern=eval_set.F01_PATTERN)
    for label, lf in (("as named (RR = row)", as_named), ("other way round (RR = column)", upright)):
        print(f"capture read {label}: view_shifts {np.round(view_shifts(lf), 3).tolist()}")
    windows = {"centre": (slice(64, 192), slice(64, 192)), "top left": (slice(None, 128), slice(None, 128)),
               "bottom right": (slice(-128, None), slice(-128, None)),
               "top right": (slice(None, 128), slice(-128, None))}
    print("| crop | read | d percentiles 5/25/50/75/95 | max |d| | share of |d| < 0.15 |")
    print("|---|---|---|---|---|")
    for name, (ys, xs) in windows.items():
        for label, lf in (("as named", as_named), ("upright", upright)):
            crop = np.ascontiguousarray(lf[1:10, 1:10, ys, xs])
            d = disparity_map(gray(torch.as_tensor(crop)))
            pct = np.percentile(d, [5, 25, 50, 75, 95])
            print(f"| {name} | {label} | {' / '.join(f'{p:+.2f}' for p in pct)} | {np.abs(d).max():.2f} | "
                  f"{(np.abs(d) < 0.15).mean():.2f} |", flush=True)


if __name__ == "__main__":
    main()
