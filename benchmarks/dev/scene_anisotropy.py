"""Diagnostic: the Lytro views are softer along x than along y, and the path estimate follows.

Blind deblurring must split the blur it sees between the camera path and the
scene's own edge profile (``blind_ambiguity.py``); the solver's edge model
assumes that profile is the same in every direction (``edge_sigma``, an
isotropic Gaussian). This script measures three things:

1. **Scenes.** For the central view of each scene of ``blind_eval.py``
   (grayscale), the share of its spectral power at high horizontal
   frequencies (``|k_x| > 0.25`` cycles/px, out of ``|k_x| > 0.05``), the same
   along y, and the Gaussian along y that makes the two shares equal (how much
   softer x is than y, px). Stripes in the scene move these shares too; the
   edge-profile ratio, each axis normalised by its own gradient energy,
   depends less on the directions of the scene's edges:
   ``(mean d2x^2 / mean dx^2) / (mean d2y^2 / mean dy^2)``, second over first
   differences along x, over the same along y (below 1: edges rounder along x).
2. **Path estimates** (``--json``, written by ``blind_eval.py --json``): the
   covariance of the positions of the estimated and of the true path over the
   exposure (x, y). A scene of one plane at disparity ``d`` is blurred by that
   distribution scaled by ``d``, so its principal axes are what the data
   constrain. Printed: the principal standard deviations (views) and the
   orientation of the major axis (degrees from +x toward +y), and the
   orientation error where the true path is elongated (ratio >= 1.5).
3. **Isotropic control** (``--run``): the path stage (``tv_iter=0``) on the
   named cases rebuilt from a scene softened along y by the Gaussian of part 1,
   so that it is about as soft along y as along x, blurred by the same path
   with the same noise as ``blind_eval.py``. Prints the same covariance figures.

docs/blind.md ("Cameras whose views are softer along one axis") explains its use.

Usage::

    python benchmarks/dev/scene_anisotropy.py [--json eval.json] [--run lytro-p1,lytro2-p4] [--sigma 0.57]
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch
from blind_dev import _eval_module  # benchmarks/ is on the path when this script runs
from scipy import ndimage

SCENES = ("syn", "syn2", "syn3", "syn4", "lytro", "lytro2", "lytro3", "lytro4")
SIGMAS = np.round(np.arange(0.0, 1.01, 0.01), 2)  # y-Gaussians tried, px
ELONGATED = 1.5  # principal-axis ratio above which a path's orientation is scored


def high_frequency_shares(img: np.ndarray) -> tuple[float, float]:
    """Share of the spectral power at ``|k| > 0.25`` out of ``|k| > 0.05`` along x and along y."""
    power = np.abs(np.fft.fft2(img - img.mean())) ** 2
    ky = np.abs(np.fft.fftfreq(img.shape[0]))[:, None]
    kx = np.abs(np.fft.fftfreq(img.shape[1]))[None, :]

    def share(k):
        return float((power * (k > 0.25)).sum() / (power * (k > 0.05)).sum())

    return share(kx), share(ky)


def edge_profile_ratio(img: np.ndarray) -> float:
    """Second over first differences along x, over the same along y (1 for equally sharp edges)."""
    def along(axis):
        return np.mean(np.diff(img, 2, axis=axis) ** 2) / np.mean(np.diff(img, axis=axis) ** 2)

    return float(along(1) / along(0))


def equalising_sigma(img: np.ndarray) -> float:
    """The Gaussian along y (px) after which the two shares are closest."""
    gaps = []
    for s in SIGMAS:
        sx, sy = high_frequency_shares(ndimage.gaussian_filter1d(img, s, axis=0, mode="nearest") if s > 0 else img)
        gaps.append(abs(sx - sy))
    return float(SIGMAS[int(np.argmin(gaps))])


def principal_axes(control_points: np.ndarray, n_times: int = 64) -> tuple[float, float, float]:
    """``(major sd, minor sd, orientation in degrees in [0, 180))`` of the path's x, y positions."""
    from napari_lfdeblur import bezier_positions

    pos = bezier_positions(np.asarray(control_points, dtype=float), n_times)[:, :2]
    w, v = np.linalg.eigh(np.cov(pos.T))
    major = v[:, 1]
    return float(np.sqrt(max(w[1], 0))), float(np.sqrt(max(w[0], 0))), float(np.degrees(np.arctan2(major[1], major[0])) % 180)


def _angle_gap(a: float, b: float) -> float:
    d = abs(a - b) % 180
    return min(d, 180 - d)


def covariance_table(rows, ev) -> None:
    print("| case | blur mismatch | estimated sd (views) | estimated orientation | true sd (views) | true orientation | orientation error |")
    print("|---|---|---|---|---|---|---|")
    errors = {"syn": [], "lytro": []}
    for name, mismatch, cp in rows:
        e1, e2, ea = principal_axes(cp)
        t1, t2, ta = principal_axes(ev.true_path(name.partition("-")[2]))
        scored = t1 >= ELONGATED * t2
        gap = _angle_gap(ea, ta)
        if scored:
            errors["lytro" if name.startswith("lytro") else "syn"].append(gap)
        print(f"| {name} | {mismatch:.3f} | {e1:.2f} / {e2:.2f} | {ea:.0f}° | {t1:.2f} / {t2:.2f} | {ta:.0f}° | "
              f"{f'{gap:.0f}°' if scored else '(round path)'} |", flush=True)
    for group, gaps in errors.items():
        if gaps:
            print(f"mean orientation error, {group} cases with elongated true paths: {np.mean(gaps):.0f}° ({len(gaps)} cases)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", help="rows of blind_eval.py --json: tabulate their path estimates")
    ap.add_argument("--method", default="default", help="method of the --json rows to tabulate")
    ap.add_argument("--run", help="comma-separated cases for the isotropic control (minutes each)")
    ap.add_argument("--sigma", type=float, default=None,
                    help="y-Gaussian (px) of the isotropic control (default: measured per scene)")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    ev = _eval_module()

    print("## Directional softness of the scenes (central view, grayscale)\n")
    print("| scene | high-frequency share along x | along y | y-Gaussian equalising them (px) | edge-profile ratio x/y |")
    print("|---|---|---|---|---|")
    equalise = {}
    for scene in SCENES:
        lf = ev._scene(scene, False)
        img = lf[lf.shape[0] // 2, lf.shape[1] // 2].mean(axis=-1)
        sx, sy = high_frequency_shares(img)
        equalise[scene] = equalising_sigma(img)
        print(f"| {scene} | {sx:.4f} | {sy:.4f} | {equalise[scene]:.2f} | {edge_profile_ratio(img):.2f} |", flush=True)

    if args.json:
        rows = [(r["case"], r["blur_mismatch"], r["control_points"])
                for r in json.loads(open(args.json).read())["rows"]
                if r.get("method") == args.method and r.get("control_points") is not None]
        print(f"\n## Path estimates of `{args.method}` ({args.json})\n")
        covariance_table(rows, ev)

    if args.run:
        from napari_lfdeblur import blind_deblur, simulate_blur
        from napari_lfdeblur.blind import BlindParams
        from napari_lfdeblur.metrics import path_error

        params = BlindParams.preset("default").replace(final=None)
        rows = []
        for name in args.run.split(","):
            scene, _, pname = name.partition("-")
            sigma = equalise[scene] if args.sigma is None else args.sigma
            sharp = ndimage.gaussian_filter1d(ev._scene(scene, False), sigma, axis=2, mode="nearest")
            case = ev.make_case(name)  # for the path and its noise draw
            blurred = simulate_blur(sharp, case.control_points, n_times=ev.RENDER_TIMES)
            rng = np.random.default_rng(1000 + ev.PATHS[pname][3])
            blurred = np.clip(blurred + rng.normal(0.0, ev.NOISE_SIGMA, blurred.shape), 0.0, 1.0).astype(np.float32)
            res = blind_deblur(blurred, params=params, seed=0)
            err = path_error(res.control_points, case.control_points, n_times=ev.PATH_TIMES, lightfield=sharp)
            rows.append((name, err.blur_mismatch, res.control_points))
        print("\n## Isotropic control: the scene softened along y before the blur (path stage only)\n")
        covariance_table(rows, ev)


if __name__ == "__main__":
    main()
