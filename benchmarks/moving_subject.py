"""A subject that moved by itself: the camera path estimated on the windows the solver chooses or on named ones.

Usage::

    python benchmarks/moving_subject.py [--seeds 11 12 13] [--out PATH]

For each scene (``procedural_scene((9, 9, 128, 384), seed=...)``, and a 128 x 384 crop of the Lytro
Illum capture ``lytro-illum-2067`` when it is available), the camera's blur, a random path with
``p_z != 0`` (64 instants), covers the whole view. The right part of the view (``x >= SUBJECT_X``),
the subject, is blurred again by its own motion: the same straight image motion of ``SUBJECT_PX`` px in
every view, in a random direction, as a subject moving across the picture is. Noise 0.002.

``blind_deblur`` runs with the default parameters, seed 0:

- ``chosen``: the windows it chooses itself (two 128 x 128 windows on a 128 x 384 view);
- ``static``: ``windows=STATIC``, two named windows on the static part;
- ``one on the subject``: ``windows=ON_SUBJECT``, as many, one of them on the subject.

Reported: the blur mismatch of the path each estimated (also when its evidence test rejected it) against
the camera's path, on the whole sharp light field (0 is exact, 1 as far from the truth as no blur); the
PSNR gain over the blurred input on the static part (``x < SUBJECT_X``, ``BORDER`` px left out), of the
result the default pipeline returns; whether it found the blur; the windows; seconds. The table goes to
``docs/benchmarks/moving_subject.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
import eval_set  # noqa: E402  (benchmarks/eval_set.py)

SHAPE = (9, 9, 128, 384)
SUBJECT_X = 256  # the subject: columns from here on
SUBJECT_PX = 2.5  # its own image motion over the exposure, px
BORDER = 8
NOISE = 0.002
STATIC = [(0, 0, 128, 128), (0, 128, 128, 128)]  # two windows on the static part
ON_SUBJECT = [(0, 0, 128, 128), (0, 256, 128, 128)]  # the same amount of data, one window on the subject


def scenes(seeds):
    from napari_lfdeblur.samples import procedural_scene

    for seed in seeds:
        yield f"rendered, seed {seed}", seed, procedural_scene(SHAPE, seed=seed, color=True)[0]
    if eval_set.capture_available("Illum"):
        lf = eval_set.capture("Illum")
        a, b = (lf.shape[0] - SHAPE[0]) // 2, (lf.shape[1] - SHAPE[1]) // 2
        crop = lf[a : a + SHAPE[0], b : b + SHAPE[1], 120 : 120 + SHAPE[2], 80 : 80 + SHAPE[3]]
        yield "Illum", 1, np.ascontiguousarray(crop, dtype=np.float32)


def subject_motion(lf, length: float, angle: float, n: int = 16) -> np.ndarray:
    """Every view of ``lf`` (V, U, Y, X[, C]) averaged over ``n`` shifts along a line of ``length`` px at
    ``angle`` (radians): the same 2D motion blur in every view, bilinear, edges replicated."""
    from scipy import ndimage

    out = np.zeros_like(lf)
    for t in np.linspace(-0.5, 0.5, n):
        shift = [0.0, 0.0, t * length * np.sin(angle), t * length * np.cos(angle)] + [0.0] * (lf.ndim - 4)
        out += ndimage.shift(lf, shift, order=1, mode="nearest")
    return out / n


def case(name, seed, sharp):
    """The blurred input and the camera's path of one scene."""
    from napari_lfdeblur import simulate_blur
    from napari_lfdeblur.path import center_path, random_path

    rng = np.random.default_rng(seed)
    cp = center_path(random_path(4, extent=1.5, z_extent=0.4, seed=int(rng.integers(0, 2**31))), 64)
    blurred = simulate_blur(sharp, cp, n_times=64)
    moved = subject_motion(blurred, SUBJECT_PX, float(rng.uniform(0, np.pi)))
    blurred[:, :, :, SUBJECT_X:] = moved[:, :, :, SUBJECT_X:]
    blurred = np.clip(blurred + rng.normal(0, NOISE, blurred.shape), 0, 1).astype(np.float32)
    return cp, blurred


def run(args) -> list[str]:
    from napari_lfdeblur.blind import blind_deblur
    from napari_lfdeblur.metrics import path_error, psnr

    rows = ["| scene | windows | path stage's windows (y0, x0, h, w) | estimate's blur mismatch | blur found | "
            "gain on the static part (dB) | seconds |", "|---|---|---|---|---|---|---|"]
    summary: dict = {}
    for name, seed, sharp in scenes(args.seeds):
        cp, blurred = case(name, seed, sharp)

        def static(a):
            return a[:, :, BORDER:-BORDER, BORDER : SUBJECT_X - BORDER]

        base = psnr(static(blurred), static(sharp))
        for label, windows in (("chosen", None), ("static", STATIC), ("one on the subject", ON_SUBJECT)):
            t0 = time.perf_counter()
            res = blind_deblur(blurred, device="cpu", seed=0, windows=windows)
            seconds = time.perf_counter() - t0
            est = res.info.get("rejected_path", res.control_points)
            mismatch = path_error(est, cp, n_times=64, lightfield=sharp).blur_mismatch
            gain = psnr(static(res.lightfield), static(sharp)) - base
            summary.setdefault(label, []).append((mismatch, gain))
            used = [tuple(int(v) for v in w) for w in res.info["windows"]]
            rows.append(f"| {name} | {label} | {used} | {mismatch:.3f} | {'yes' if res.info['blur_found'] else 'no'} "
                        f"| {gain:+.2f} | {seconds:.1f} |")
            print(rows[-1], file=sys.stderr, flush=True)
    rows += ["", "| windows | cases | mean blur mismatch | mean gain on the static part (dB) |", "|---|---|---|---|"]
    rows += [f"| {k} | {len(v)} | {np.mean([m for m, _ in v]):.3f} | {np.mean([g for _, g in v]):+.2f} |"
             for k, v in summary.items()]
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    body = [f"Light fields {SHAPE[0]}x{SHAPE[1]}x{SHAPE[2]}x{SHAPE[3]}x3, `d_inf = 0`. The camera's path: a random "
            f"4-point path of extent 1.5 views with `p_z != 0`; the subject (columns {SUBJECT_X} on) moves "
            f"{SUBJECT_PX:g} px more in a random direction; noise {NOISE}. `blind_deblur` with the default "
            f"parameters: *chosen*, its own windows; *static*, `windows={STATIC}`; *one on the subject*, "
            f"`windows={ON_SUBJECT}`. The gain is "
            f"PSNR over the blurred input on the static part (columns below {SUBJECT_X}, {BORDER} px border left "
            "out), of what the default pipeline returns.", "", *run(args)]
    _report.write_table(_report.table_path(args.out, __file__), "A subject that moved by itself",
                        _report.command_line(__file__, argv), _report.machine("cpu"), body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
