"""Blind and non-blind deblurring of whole light fields, against the same pipeline on a 128 x 128 crop.

Usage::

    python benchmarks/bench_fullres.py [--cases synthetic0,synthetic1,illum0,illumneg1] [--device auto|cpu|cuda]
        [--noise 0.005] [--max-memory X] [--out PATH]

Cases (each blurred by the same known path with ``p_z != 0``, 64 instants, plus Gaussian noise):

- ``synthetic0`` / ``synthetic1``: ``procedural_scene((9, 9, 376, 541), seed=7)`` rendered with
  ``d_inf = 0`` / ``1``;
- ``illum0`` / ``illumneg1``: the whole Lytro Illum capture ``lytro-illum-2067`` (9 x 9 x 383 x 552 x 3;
  scene disparities about -0.9 to -0.4 px/view) with ``d_inf = 0`` / ``-1`` (skipped when the
  capture is missing).

For each case, each run in its own process (so that peak memories do not mix):

- ``blind_deblur`` with the default parameters on the whole light field (what a user gets: a full
  restoration when the evidence test finds the blur, else a light restoration or the input), timed; and,
  where it did not restore with the whole estimated path, ``deconvolve`` with that path and the final
  stage's settings (*restored anyway*, what ``require_evidence=False`` gives), so that every estimate is
  judged by a restoration;
- the same on the central 128 x 128 crop (the crop pipeline);
- ``deconvolve`` with the true path on the whole light field (non-blind).

Reported: seconds by stage (path, final), peak memory above the input (resident set size sampled every
10 ms, in units of the input's size; CUDA's own peak on a GPU), PSNR gain over the blurred input and the
blur mismatch of the path on the central 128 x 128 crop of the sharp light field, the same for the full
and the crop pipeline: the true path and the path found on the whole light field are both moved into the
crop's own coordinates (``path_in_window``), where the crop pipeline's path already is. Also the gain of
every pipeline on the central crop alone (its 8-px border left out), which compares them like for like; the
gain of the central crop restored on its own with the whole pipeline's path (same final stage, so a difference
from the crop pipeline is the path's); and the length of each path (RMS spread of its in-plane positions) over
the true path's.
The table goes to ``docs/benchmarks/bench_fullres.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
import eval_set  # noqa: E402
from blind_eval import PeakMemory, path_spread  # noqa: E402

#: name -> (scene, d_inf)
CASES = {"synthetic0": ("synthetic", 0.0), "synthetic1": ("synthetic", 1.0), "illum0": ("Illum", 0.0),
         "illumneg1": ("Illum", -1.0)}
PATH = np.array([[-0.9, 0.4, 0.3], [0.3, -0.7, -0.2], [0.8, 0.6, 0.1]])
CROP = 128
BORDER = 8  # px of the crop's border left out of the like-for-like gain (the crop pipeline has no context there)


def sharp_lightfield(scene: str, d_inf: float, seed: int = 7) -> np.ndarray:
    """The sharp light field of a case: the Illum capture, or the rendered scene (nearer than ``d_inf``)."""
    if scene == "Illum":
        return eval_set.capture("Illum")
    from napari_lfdeblur.samples import procedural_scene

    return procedural_scene((9, 9, 376, 541), seed=seed, color=True, infinity_disparity=d_inf)[0]


def central_window(frame_shape, size=CROP) -> tuple:
    """``(y0, x0, size, size)``: the central window of a ``(Y, X)`` view."""
    Y, X = frame_shape
    return (Y - size) // 2, (X - size) // 2, size, size


def central(a, size=CROP):
    y0, x0, h, w = central_window(a.shape[2:4], size)
    return a[:, :, y0 : y0 + h, x0 : x0 + w]


RUNS = ("full", "crop", "capped", "truepath")


def run_case(name: str, run: str, device: str, noise: float, max_memory: float | None = None) -> dict:
    """One run of one case, in this process (so that its peak memory is its own): ``run`` is ``'full'``
    (the blind pipeline on the whole light field), ``'crop'`` (on the central crop), ``'capped'`` (the whole
    again with ``max_memory`` times the input's size) or ``'truepath'`` (non-blind, the true path)."""
    from napari_lfdeblur import deconvolve, simulate_blur
    from napari_lfdeblur.blind import blind_deblur
    from napari_lfdeblur.metrics import path_error, psnr
    from napari_lfdeblur.path import path_in_window

    scene, d_inf = CASES[name]
    sharp = sharp_lightfield(scene, d_inf)
    blurred = simulate_blur(sharp, PATH, n_times=64, infinity_disparity=d_inf)
    blurred = np.clip(blurred + np.random.default_rng(0).normal(0, noise, blurred.shape), 0, 1).astype(np.float32)
    ref_crop = central(sharp)
    window = central_window(sharp.shape[2:4])
    true_on_crop = path_in_window(PATH, window, sharp.shape[2:4])  # the blur the crop has, in its coordinates

    def on_crop_path(cp):
        return cp if run == "crop" else path_in_window(cp, window, sharp.shape[2:4])

    def on_crop_gain(restored_crop):  # both pipelines judged alike: on the central crop, its border excluded
        return psnr(restored_crop, ref_crop, crop=BORDER) - psnr(central(blurred), ref_crop, crop=BORDER)

    row = {"case": name, "scene": scene, "d_inf": d_inf, "shape": list(sharp.shape),
           "blurred_psnr": psnr(blurred, sharp), "crop_blurred_psnr": psnr(central(blurred), ref_crop)}
    if run == "truepath":
        with PeakMemory(device) as mem:
            t0 = time.perf_counter()
            restored = deconvolve(blurred, PATH, n_times=32, infinity_disparity=d_inf, device=device)
            seconds = time.perf_counter() - t0
        row[run] = {"seconds": seconds, "memory_x": mem.delta_mib * 2**20 / blurred.nbytes,
                    "gain": psnr(restored, sharp) - row["blurred_psnr"],
                    "gain_on_crop": on_crop_gain(central(restored))}
        return row
    data, truth = (central(blurred), ref_crop) if run == "crop" else (blurred, sharp)
    cap = max_memory * blurred.nbytes if run == "capped" else None
    with PeakMemory(device) as mem:
        t0 = time.perf_counter()
        res = blind_deblur(data, infinity_disparity=d_inf, device=device, max_memory=cap)
        seconds = time.perf_counter() - t0
    found, p = bool(res.info["blur_found"]), res.params
    estimate = res.info.get("rejected_path", res.control_points)  # the whole path estimated
    anyway = res.lightfield
    if not found:
        anyway = deconvolve(data, estimate, n_times=p.final_n_times, infinity_disparity=d_inf, device=device,
                            params=p.final)
    out = {"seconds": seconds, "path_s": res.timings["path"], "final_s": res.timings["final"],
           "memory_x": mem.delta_mib * 2**20 / data.nbytes, "blur_found": found,
           "restoration": res.info["restoration"],
           "gain_anyway": psnr(anyway, truth) - psnr(data, truth),
           "gain_default": psnr(res.lightfield, truth) - psnr(data, truth),
           "gain_on_crop": on_crop_gain(anyway if run == "crop" else central(anyway)),
           "gain_default_on_crop": on_crop_gain(res.lightfield if run == "crop" else central(res.lightfield)),
           "mismatch": path_error(on_crop_path(estimate), true_on_crop, lightfield=ref_crop,
                                  infinity_disparity=d_inf).blur_mismatch,
           "length": path_spread(on_crop_path(estimate), 64) / path_spread(true_on_crop, 64),
           "windows": res.info["windows"], "tile": res.info.get("tile")}
    if run != "crop":  # the path found, judged on the whole frame too, and restoring the crop alone
        out["mismatch_whole"] = path_error(estimate, PATH, lightfield=sharp, infinity_disparity=d_inf).blur_mismatch
        crossed = deconvolve(central(blurred), on_crop_path(estimate), n_times=p.final_n_times,
                             infinity_disparity=d_inf, device=device, params=p.final)
        out["gain_crossed"] = on_crop_gain(crossed)
    print(f"{name} {run}: {out}", file=sys.stderr, flush=True)
    row[run] = out
    return row


def table(rows, max_memory=None) -> list[str]:
    lines = ["| case | d_inf | pipeline | restoration | time s (path + final) | peak memory (x input) | "
             "gain dB, default | gain dB, restored anyway | on the crop, default | on the crop, restored anyway | "
             "the crop alone, this path | blur mismatch on the crop | on the whole frame | length (x true) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for label in ("full", "crop", "capped"):
            if label not in r:
                continue
            o = r[label]
            size = "x".join(str(s) for s in r["shape"]) if label != "crop" else f"central {CROP}x{CROP} crop"
            if label == "capped":
                tiles = f"{o['tile'][0]}x{o['tile'][1]} tiles" if o["tile"] else "not tiled"
                size += f", max_memory {max_memory:g}x input ({tiles})"
            whole = f"{o['mismatch_whole']:.3f}" if label != "crop" else "—"
            crossed = f"{o['gain_crossed']:+.2f}" if label != "crop" else "—"
            lines.append(f"| {r['case']} | {r['d_inf']:+g} | blind, {size} | {o['restoration']} | "
                         f"{o['seconds']:.1f} ({o['path_s']:.1f} + {o['final_s']:.1f}) | {o['memory_x']:.1f} | "
                         f"{o['gain_default']:+.2f} | {o['gain_anyway']:+.2f} | {o['gain_default_on_crop']:+.2f} | "
                         f"{o['gain_on_crop']:+.2f} | {crossed} | "
                         f"{o['mismatch']:.3f} | {whole} | {o['length']:.2f} |")
        t = r["truepath"]
        lines.append(f"| {r['case']} | {r['d_inf']:+g} | non-blind, true path, whole | — | {t['seconds']:.1f} | "
                     f"{t['memory_x']:.1f} | {t['gain']:+.2f} | {t['gain']:+.2f} | {t['gain_on_crop']:+.2f} | "
                     f"{t['gain_on_crop']:+.2f} | — | "
                     "— | — | 1.00 |")
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
    parser.add_argument("--device", default="auto")
    parser.add_argument("--noise", type=float, default=0.005)
    parser.add_argument("--max-memory", type=float, default=None, metavar="X",
                        help="also run the whole blind pipeline with max_memory = X times the input's size")
    parser.add_argument("--case-json", help=argparse.SUPPRESS)  # internal: run CASE:RUN, print its JSON
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    unknown = sorted(set(args.cases.split(",")) - set(CASES))
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}: choose from {', '.join(CASES)}")
    from napari_lfdeblur.devices import select_device

    device = str(select_device(args.device))
    if args.case_json:
        name, run = args.case_json.split(":")
        print(json.dumps(run_case(name, run, device, args.noise, args.max_memory)))
        return 0
    rows, skipped = [], []
    for name in args.cases.split(","):
        if CASES[name][0] == "Illum" and not eval_set.capture_available("Illum"):
            skipped.append(f"- `{name}`: the Illum capture is not available")
            continue
        cap = ["--max-memory", str(args.max_memory)] if args.max_memory else []
        row = {}
        for run in RUNS if args.max_memory else [r for r in RUNS if r != "capped"]:
            proc = subprocess.run([sys.executable, __file__, "--case-json", f"{name}:{run}", "--device", device,
                                   "--noise", str(args.noise), *cap], capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                print(proc.stderr, file=sys.stderr)
                raise SystemExit(f"case {name} ({run}) failed")
            row.update(json.loads(proc.stdout.strip().splitlines()[-1]))
        rows.append(row)
    body = [
        f"Each case: the sharp light field blurred by one known path (control points {PATH.tolist()}, 64 "
        f"instants) plus noise of sigma {args.noise:g}. Blind: `blind_deblur` with the default parameters; the "
        "path is estimated on four 128 x 128 windows of the views (one per quarter) and the final stage runs on "
        "the whole light field. "
        "*Default* is what a user gets, and its time and memory are the default's: a full restoration where the "
        "evidence test finds the blur (*restoration* `full`), else, where two parts of the data agree on the path, "
        "a light restoration (`light`, the path at half its length) or the input (`none`); *restored anyway* is "
        "the restoration with the whole estimated path (`require_evidence=False`). The blur mismatch is that of "
        "the whole estimate, measured on the "
        "central 128 x 128 crop of the sharp light field, with every path in the crop's own coordinates, and for "
        "the whole pipeline also on the whole sharp light field. *On the crop*: the gain of each pipeline (its "
        "default result, and restored anyway) on the "
        f"central crop alone, its {BORDER}-px border left out, so that the two compare like for like (the whole "
        "pipeline's own gain is over the whole frame, whose content differs from the crop's). *The crop alone, this "
        "path*: the central crop restored on its own (`deconvolve`, the final stage's settings) with the whole "
        "pipeline's estimate moved into the crop's coordinates; where it equals the whole pipeline's gain on the "
        "crop, the two final stages agree and any difference from the crop pipeline is the path's. *Length*: "
        "the RMS spread of the estimate's in-plane positions over the true path's, both in the crop's "
        "coordinates (1: the right length; above 1: too long). Peak memory: above "
        "the input, in units of its size, each run in a process of its own."
        + (f" *max_memory*: the whole pipeline again with `max_memory` set to {args.max_memory:g} times the "
           "input's size (the final stage then runs in tiles where the estimate says the whole would not fit)."
           if args.max_memory else ""),
        "", *table(rows, args.max_memory)]
    if skipped:
        body += ["", "Skipped:", *skipped]
    _report.write_table(_report.table_path(args.out, __file__), "Whole light fields: blind and non-blind",
                        _report.command_line(__file__, argv), _report.machine(device), body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
