"""Blind deblurring of camera shake with rotation: the 3-DOF solver, the 6-DOF solver, the per-view 2D baseline.

Usage::

    python benchmarks/blind_rotation_eval.py [--quick] [--cases N] [--degrees LO HI] [--split eval|dev]
        [--device auto|cpu|cuda] [--out PATH]

Cases (fixed seeds, none of them used to set the solver's parameters):
rendered scenes with depth range (``procedural_scene``) and crops of the
Lytro Illum capture (``lytro-illum-2067``, where present), 9x9x128x128x3,
blurred by rotation-only paths and by mixed paths (rotation plus a
translation of one view, ``p_z != 0``), noise sigma 0.002.

Rotations are drawn at handheld sizes (``--degrees``, default 0.2 to 0.6
degrees across the path) on a full Illum frame (R = 270 px): 1 to 3 px of
image motion. A crop is solved as a frame of its own (R = 64 px), so the
same image motion is a rotation 4.2 times larger there: what a user who
deblurs a crop gets.

For every case: the blurred input's PSNR; then, for the default solver
(``motion='3dof'``, what users get today), ``motion='6dof'``, the
per-view 2D baseline and the non-blind restoration with the true path
(``deconvolve`` with the blind solver's final settings: what a perfect
estimate would give), the PSNR, its gain over the input and the time; and
for the two light-field solvers the blur mismatch of their path on the full
6-DOF model, and that of the path they estimated (the same path, or the one
their evidence test rejected when they returned the input). The table goes
to ``docs/benchmarks/blind_rotation_eval.md`` (or ``--out``), rewritten
after every case.
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

SHAPE = (9, 9, 128, 128)
QUICK_SHAPE = (5, 5, 48, 48)
FULL_FRAME_R = 270.0  # px: R of a full Lytro Illum view (541 / 2)
DEGREES = (0.2, 0.6)  # handheld rotation sizes on the full frame
NOISE = 0.002
RENDER_TIMES = 64
PATH_TIMES = 64
CROP = 8


#: seeds of the case lists: the evaluation's, and a development list for trying changes on
SPLIT_SEEDS = {"eval": 18_001, "dev": 18_002}


def case_specs(n: int, split: str = "eval"):
    """``n`` cases: (name, scene kind, scene seed or crop, motion, d_inf, seed), rendered and Illum alternating."""
    rng = np.random.default_rng(SPLIT_SEEDS[split])
    illum = eval_set.capture_available("Illum")
    specs = []
    for i in range(n):
        group = "Illum" if illum and i % 2 == 1 else "rendered"
        motion = "rotation" if i % 3 == 0 else "mixed"
        d_inf = float(rng.choice([0.0, 0.0, 0.5, 1.0]))
        if group == "rendered":
            scene = ("seed", int(rng.integers(1_800_000, 1_900_000)))
        else:
            scene = ("crop", int(rng.integers(48, 239)), int(rng.integers(48, 376)))
        specs.append((f"{group[0]}{i + 1:02d}", group, scene, motion, d_inf, int(rng.integers(0, 2**31))))
    return specs


def sharp_lightfield(group, scene, d_inf, shape):
    from napari_lfdeblur import procedural_scene

    V, U, Y, X = shape
    if group == "rendered":
        return procedural_scene(shape, seed=scene[1], infinity_disparity=d_inf)[0]
    lf = eval_set.capture("Illum")
    a, b = (lf.shape[0] - V) // 2, (lf.shape[1] - U) // 2
    y0, x0 = scene[1:]
    return np.ascontiguousarray(lf[a : a + V, b : b + U, y0 : y0 + Y, x0 : x0 + X], dtype=np.float32)


def true_path(motion: str, seed: int, r_px: float, degrees=DEGREES) -> np.ndarray:
    """A 4-point 6-DOF path in the zero-mean gauge: a handheld rotation, plus a translation when ``mixed``."""
    from napari_lfdeblur.path import bezier_positions, center_path, random_path

    rng = np.random.default_rng(seed)
    rot = center_path(np.concatenate([np.zeros((4, 3)), rng.uniform(-0.1, 0.1, (4, 3))], axis=1), RENDER_TIMES)[:, 3:]
    pos = bezier_positions(np.concatenate([np.zeros((4, 3)), rot], axis=1), RENDER_TIMES)[:, 3:]
    size = np.sqrt(((pos[:, None] - pos[None]) ** 2).sum(-1)).max()  # the rotation's diameter, rad
    motion_px = FULL_FRAME_R * np.radians(rng.uniform(*degrees))  # its image motion on a full frame
    rot *= motion_px / r_px / size
    trans = np.zeros((4, 3))
    if motion == "mixed":
        trans = random_path(4, extent=1.0, z_extent=0.5, seed=int(rng.integers(0, 2**31)))
    return center_path(np.concatenate([trans, rot], axis=1), RENDER_TIMES)


def run_solver(name, blurred, d_inf, device, quick, true_cp=None):
    """(restored, control points or None, estimate or None, seconds, info or None) of one solver.

    The estimate is the path the solver found, also when its evidence test
    rejected it and returned the input (the control points are then zero);
    ``info`` is the blind result's ``info``. ``'truepath'`` restores with
    ``true_cp``, non-blind.
    """
    t0 = time.perf_counter()
    if name == "truepath":
        from napari_lfdeblur.blind import BlindParams
        from napari_lfdeblur.deconvolution import deconvolve
        from napari_lfdeblur.path import center_path

        p = BlindParams(motion="6dof")
        restored = deconvolve(blurred, center_path(true_cp, p.final_n_times), n_times=p.final_n_times,
                              infinity_disparity=d_inf, params=p.final, device=device)
        return restored, None, None, time.perf_counter() - t0, None
    if name == "baseline2d":
        from _baseline2d import Baseline2DParams, deblur_views_2d  # benchmarks/_baseline2d.py

        restored, _ = deblur_views_2d(blurred, Baseline2DParams(kernel_size=7) if quick else Baseline2DParams())
        return restored, None, None, time.perf_counter() - t0, None
    from napari_lfdeblur import blind_deblur
    from napari_lfdeblur.blind import BlindParams

    res = blind_deblur(blurred, params=BlindParams(motion=name), infinity_disparity=d_inf, device=device, seed=0)
    estimate = res.info.get("rejected_path", res.control_points)
    return res.lightfield, res.control_points, estimate, time.perf_counter() - t0, res.info


SOLVERS = ("3dof", "6dof", "baseline2d", "truepath")


def evaluate(spec, device, quick, degrees=DEGREES) -> dict:
    from napari_lfdeblur import simulate_blur
    from napari_lfdeblur.metrics import path_error, psnr

    name, group, scene, motion, d_inf, seed = spec
    shape = QUICK_SHAPE if quick else SHAPE
    sharp = sharp_lightfield(group, scene, d_inf, shape)
    cp = true_path(motion, seed, max(shape[2:]) / 2.0, degrees)
    blurred = simulate_blur(sharp, cp, n_times=RENDER_TIMES, infinity_disparity=d_inf, device="cpu")
    blurred = np.clip(blurred + np.random.default_rng(seed).normal(0, NOISE, blurred.shape), 0, 1).astype(np.float32)
    crop = 2 if quick else CROP
    base = psnr(blurred, sharp, crop=crop)
    from napari_lfdeblur.path import bezier_positions

    row = {"case": name, "group": group, "motion": motion, "d_inf": d_inf, "input": base,
           "rotation_mrad": 1000 * float(np.abs(bezier_positions(cp, RENDER_TIMES)[:, 3:]).max())}
    for solver in SOLVERS:
        restored, est, found, seconds, info = run_solver(solver, blurred, d_inf, device, quick, cp)
        row[solver] = psnr(restored, sharp, crop=crop) - base
        row[solver + "_s"] = seconds
        if est is not None:
            err = path_error(est, cp, n_times=PATH_TIMES, lightfield=sharp, infinity_disparity=d_inf)
            row[solver + "_mismatch"] = err.blur_mismatch
            if found is not est:  # the evidence test rejected it: judge the estimate too
                err = path_error(found, cp, n_times=PATH_TIMES, lightfield=sharp, infinity_disparity=d_inf)
            row[solver + "_found"] = err.blur_mismatch
            row[solver + "_made"] = f"{info['restoration']} ({info.get('discrepancy', float('nan')):.2f})"
        print(f"{name} {solver}: {row[solver]:+.2f} dB, {seconds:.0f} s", flush=True)
    return row


def _line(r) -> str:
    solvers = "".join(f"{r[s]:+.2f} | {r[s + '_made']} | {r[s + '_mismatch']:.2f} | {r[s + '_found']:.2f} | "
                      f"{r[s + '_s']:.0f} | " for s in ("3dof", "6dof"))
    return (f"| {r['case']} | {r['group']} | {r['motion']} | {r['d_inf']:+.1f} | {r['rotation_mrad']:.1f} | "
            f"{r['input']:.2f} | {solvers}{r['baseline2d']:+.2f} | {r['truepath']:+.2f} |")


def _summary(rows) -> list[str]:
    out = ["| motion | cases | 3-DOF gain (dB) | 3-DOF mismatch | 3-DOF estimate's mismatch | 6-DOF gain (dB) "
           "| 6-DOF mismatch | 6-DOF estimate's mismatch | 6-DOF - 3-DOF (dB) | 6-DOF / 3-DOF time "
           "| 2D baseline gain (dB) | true path gain (dB) |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for label, sel in (("rotation only", "rotation"), ("mixed", "mixed"), ("all", None)):
        rs = [r for r in rows if sel is None or r["motion"] == sel]
        if not rs:
            continue
        m = {k: float(np.mean([r[k] for r in rs])) for k in ("3dof", "3dof_mismatch", "3dof_found", "6dof",
                                                             "6dof_mismatch", "6dof_found", "baseline2d",
                                                             "truepath")}
        ratio = float(np.mean([r["6dof_s"] / r["3dof_s"] for r in rs]))
        out.append(f"| {label} | {len(rs)} | {m['3dof']:+.2f} | {m['3dof_mismatch']:.2f} | {m['3dof_found']:.2f} | "
                   f"{m['6dof']:+.2f} | {m['6dof_mismatch']:.2f} | {m['6dof_found']:.2f} | "
                   f"{m['6dof'] - m['3dof']:+.2f} | {ratio:.2f} | {m['baseline2d']:+.2f} | {m['truepath']:+.2f} |")
    return out


def write(rows, args, argv, device, smoke=False):
    body = [
        __doc__.split("\n\n")[3].replace("\n", " "),
        "",
        f"Rotations: {args.degrees[0]:g} to {args.degrees[1]:g} degrees across the path on a full Illum frame "
        f"(R = {FULL_FRAME_R:.0f} px), {FULL_FRAME_R * np.radians(args.degrees[0]):.1f} to "
        f"{FULL_FRAME_R * np.radians(args.degrees[1]):.1f} px of image motion. A crop is solved as a frame of its "
        "own (R = 64 px), where the same image motion is a rotation 4.2 times larger.",
        "",
        "Gains are PSNR over the blurred input (dB, 8-px border excluded); *mismatch* is the blur mismatch of "
        "the path a solver restored with on the full 6-DOF model (0 is perfect, 1 as bad as no blur; "
        "docs/model.md, *Judging an estimate*; 1.00 when it returned the input); *estimate's mismatch* is that of "
        "the path it estimated, also when its evidence test rejected it; *made*: the restoration the solver "
        "returned (`info['restoration']`: full, light or none) and, in brackets, its `info['discrepancy']` (the "
        "restoration's residual in noise variances per sample, nan where none was made); times in seconds. "
        "The 3-DOF solver is "
        "the default (`motion='3dof'`). *True path*: `deconvolve` with the true path and the blind solver's "
        "final settings, what a perfect estimate would give.",
        "",
        *_summary(rows),
        "",
        "| case | scene | motion | d_inf | max rotation (mrad) | input PSNR | 3-DOF gain | 3-DOF made "
        "| 3-DOF mismatch | 3-DOF estimate's mismatch | 3-DOF s | 6-DOF gain | 6-DOF made | 6-DOF mismatch "
        "| 6-DOF estimate's mismatch | 6-DOF s | 2D baseline gain | true path gain |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *[_line(r) for r in rows],
    ]
    path = _report.table_path(args.out, __file__, args.quick or smoke)
    if path is None:  # a smoke run or the dev split: print, write nothing (unless to --out)
        print("\n".join(body))
        return None
    return _report.write_table(path, "Blind deblurring with camera rotation", _report.command_line(__file__, argv),
                               _report.machine(str(device)), body)


def main(argv=None):
    from napari_lfdeblur.devices import select_device

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=6)
    parser.add_argument("--quick", action="store_true", help="tiny light fields, 2 cases: a smoke test")
    parser.add_argument("--degrees", type=float, nargs=2, default=DEGREES, metavar=("LO", "HI"),
                        help="size of the rotation across the path on a full frame, degrees (default 0.2 0.6)")
    parser.add_argument("--split", choices=sorted(SPLIT_SEEDS), default="eval",
                        help="'dev': another list of cases, for trying changes on (printed, or written to --out only)")
    parser.add_argument("--device", default="auto")
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    device = select_device(args.device)
    rows = []
    for spec in case_specs(2 if args.quick else args.cases, args.split):
        rows.append(evaluate(spec, str(device), args.quick, tuple(args.degrees)))
        if args.split == "eval":
            write(rows, args, argv, device)
    if args.split != "eval":
        write(rows, args, argv, device, smoke=True)


if __name__ == "__main__":
    main()
