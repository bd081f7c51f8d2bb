"""Where to estimate the path of a whole light field: the chosen windows, other windows, the coarse whole view.

Usage::

    python benchmarks/path_window_study.py [--seeds 7 8] [--infinity-disparity 0 1] [--random-windows 2]
        [--out PATH]

For each scene (``procedural_scene((9, 9, 376, 541), seed=...)`` rendered for the case's ``d_inf``, and
the Lytro Illum capture ``lytro-illum-2067`` at ``d_inf = 0`` when it is available), blurred by one
known path with ``p_z != 0`` (64 instants, noise 0.005), the path stage of ``blind_deblur`` (default
parameters, no final stage) runs on:

- ``windows``: the default: four 128 x 128 windows, one in each quarter of the view, each the best there
  (edges in two directions times disparity weight), one path fitted to all four;
- ``one window``: the best 128 x 128 window of the whole view (``path.n_regions = 1``);
- ``central``: the central 128 x 128 crop;
- ``random k``: 128 x 128 windows at random positions (seeded);
- ``coarse``: the whole view, area-averaged by 4 (``path.region = 0``, ``path.max_size = 128``).

Every path is carried to the full frame (``path_in_frame``) and judged by its blur mismatch on the
whole sharp light field. The table goes to ``docs/benchmarks/path_window_study.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
import eval_set  # noqa: E402
from bench_fullres import PATH, sharp_lightfield  # noqa: E402  (the same path and scenes)

SIZE = 128


def scenes(seeds, d_infs):
    for seed in seeds:
        for d_inf in d_infs:
            yield f"rendered, seed {seed}", d_inf, sharp_lightfield("synthetic", d_inf, seed)
    if eval_set.capture_available("Illum"):
        yield "Illum", 0.0, sharp_lightfield("Illum", 0.0)


def estimate(blurred, d_inf, window, params):
    """The path found on ``window`` (None: ``params``' own choice), in frame coordinates, the windows, seconds."""
    from napari_lfdeblur.blind import blind_deblur
    from napari_lfdeblur.path import path_in_frame

    t0 = time.perf_counter()
    if window is None:
        res = blind_deblur(blurred, infinity_disparity=d_inf, params=params, device="cpu", seed=0)
        used = [tuple(w) for w in res.info["windows"]]
        return res.control_points, used[0] if len(used) == 1 else used, time.perf_counter() - t0
    y0, x0, h, w = window
    res = blind_deblur(blurred[:, :, y0 : y0 + h, x0 : x0 + w], infinity_disparity=d_inf, params=params,
                       device="cpu", seed=0)
    return path_in_frame(res.control_points, window, blurred.shape[2:4]), window, time.perf_counter() - t0


def run(args) -> list[str]:
    from napari_lfdeblur import simulate_blur
    from napari_lfdeblur.blind import BlindParams
    from napari_lfdeblur.metrics import path_error

    base = BlindParams().replace(final=None, require_evidence=False)
    coarse = base.replace(path={"region": 0, "max_size": SIZE})
    rng = np.random.default_rng(0)
    rows = ["| scene | d_inf | where | windows (y0, x0, h, w) | blur mismatch | seconds |", "|---|---|---|---|---|---|"]
    summary: dict = {}
    for name, d_inf, sharp in scenes(args.seeds, args.infinity_disparity):
        blurred = simulate_blur(sharp, PATH, n_times=64, infinity_disparity=d_inf)
        blurred = np.clip(blurred + rng.normal(0, 0.005, blurred.shape), 0, 1).astype(np.float32)
        Y, X = sharp.shape[2:4]
        central = ((Y - SIZE) // 2, (X - SIZE) // 2, SIZE, SIZE)
        choices = [("windows", None, base), ("one window", None, base.replace(path={"n_regions": 1})),
                   ("central", central, base)]
        choices += [(f"random {k + 1}", (int(rng.integers(0, Y - SIZE)), int(rng.integers(0, X - SIZE)), SIZE, SIZE),
                     base) for k in range(args.random_windows)]
        choices.append(("coarse", (0, 0, Y, X), coarse))
        for label, window, params in choices:
            cp, used, seconds = estimate(blurred, d_inf, window, params)
            mismatch = path_error(cp, PATH, lightfield=sharp, infinity_disparity=d_inf).blur_mismatch
            kind = "random" if label.startswith("random") else label
            summary.setdefault(kind, []).append(mismatch)
            rows.append(f"| {name} | {d_inf:+g} | {label} | {used} | {mismatch:.3f} | {seconds:.1f} |")
            print(rows[-1], file=sys.stderr, flush=True)
    rows += ["", "| where | cases | mean blur mismatch | worst |", "|---|---|---|---|"]
    rows += [f"| {k} | {len(v)} | {np.mean(v):.3f} | {np.max(v):.3f} |" for k, v in summary.items()]
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[7, 8])
    parser.add_argument("--infinity-disparity", type=float, nargs="+", default=[0.0, 1.0])
    parser.add_argument("--random-windows", type=int, default=2)
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    body = [f"One known path (control points {PATH.tolist()}, 64 instants), noise 0.005; the path stage of "
            "`blind_deblur` with the default parameters, on the CPU. Blur mismatch: of the path carried to the "
            "full frame, on the whole sharp light field (0 is exact; 1 is as far from the truth as no blur).",
            "", *run(args)]
    _report.write_table(_report.table_path(args.out, __file__), "Where the path of a whole light field is estimated",
                        _report.command_line(__file__, argv), _report.machine("cpu"), body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
