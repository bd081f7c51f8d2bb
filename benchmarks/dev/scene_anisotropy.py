"""Diagnostic: the F01 views are softer along x than along y, and the path estimate follows.

Blind deblurring must split the blur it sees between the camera path and the
scene's own edge profile (``blind_ambiguity.py``); the solver's edge model
assumes that profile is the same in every direction (``edge_sigma``, an
isotropic Gaussian). This script measures two things on the development
split of ``blind_eval.py``:

1. **Scenes.** For the central view of each case's sharp light field
   (grayscale), the share of its spectral power at high horizontal
   frequencies (``|k_x| > 0.25`` cycles/px, out of ``|k_x| > 0.05``), the same
   along y, and the Gaussian along y that makes the two shares equal (how much
   softer x is than y, px). Stripes in the scene move these shares too; the
   edge-profile ratio, each axis normalised by its own gradient energy,
   depends less on the directions of the scene's edges:
   ``(mean d2x^2 / mean dx^2) / (mean d2y^2 / mean dy^2)``, second over first
   differences along x, over the same along y (below 1: edges rounder along x).
   Then the median of each figure per group.
2. **Path estimates** (``--run``): the path stage (``final=None``) on the
   named cases (the estimated path, also where the evidence test finds it
   too weak to use), once as they are and once rebuilt from the scene softened
   along y by the Gaussian of part 1 (so that it is about as soft along y as
   along x), blurred by the same path with the same noise. For each it prints
   the covariance of the positions of the estimated and of the true path
   over the exposure (x, y): a scene of one plane at disparity ``d`` is
   blurred by that distribution scaled by ``d``, so its principal axes are
   what the data constrain. Printed: the principal standard deviations
   (views), the orientation of the major axis (degrees from +x toward +y),
   and the orientation error where the true path is elongated (ratio >= 1.5).

docs/blind.md ("Cameras whose views are softer along one axis") explains its use.

Usage::

    python benchmarks/dev/scene_anisotropy.py [--cases dev08,dev09] [--run dev08,dev09] [--sigma 0.57]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)
import eval_set  # noqa: E402

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
    angle = float(np.degrees(np.arctan2(major[1], major[0])) % 180)
    return float(np.sqrt(max(w[1], 0))), float(np.sqrt(max(w[0], 0))), angle


def _angle_gap(a: float, b: float) -> float:
    d = abs(a - b) % 180
    return min(d, 180 - d)


def central_view(lf: np.ndarray) -> np.ndarray:
    """The grayscale central view of a ``(V, U, Y, X, C)`` light field."""
    return lf[lf.shape[0] // 2, lf.shape[1] // 2].mean(axis=-1)


def scene_table(specs) -> None:
    """Part 1."""
    print("## Directional softness of the scenes (central view, grayscale)\n")
    print("| case | group | high-frequency share along x | along y | y-Gaussian equalising them (px) | "
          "edge-profile ratio x/y |")
    print("|---|---|---|---|---|---|")
    by_group = {}
    for spec in specs:
        img = central_view(eval_set.sharp_lightfield(spec))
        sx, sy = high_frequency_shares(img)
        sigma, ratio = equalising_sigma(img), edge_profile_ratio(img)
        by_group.setdefault(spec.group, []).append((sigma, ratio))
        print(f"| {spec.name} | {spec.group} | {sx:.4f} | {sy:.4f} | {sigma:.2f} | {ratio:.2f} |", flush=True)
    print("\n| group | cases | median y-Gaussian (px) | median edge-profile ratio x/y |")
    print("|---|---|---|---|")
    for group, vals in by_group.items():
        a = np.array(vals)
        print(f"| {group} | {len(a)} | {np.median(a[:, 0]):.2f} | {np.median(a[:, 1]):.2f} |")


def covariance_table(rows) -> None:
    print("| case | scene | blur mismatch | estimated sd (views) | estimated orientation | true sd (views) | "
          "true orientation | orientation error |")
    print("|---|---|---|---|---|---|---|---|")
    for name, label, mismatch, cp, true in rows:
        e1, e2, ea = principal_axes(cp)
        t1, t2, ta = principal_axes(true)
        gap = f"{_angle_gap(ea, ta):.0f}°" if t1 >= ELONGATED * t2 else "(round path)"
        print(f"| {name} | {label} | {mismatch:.3f} | {e1:.2f} / {e2:.2f} | {ea:.0f}° | {t1:.2f} / {t2:.2f} | "
              f"{ta:.0f}° | {gap} |", flush=True)


def path_table(specs, sigma) -> None:
    """Part 2: the path stage on each case as it is and with its scene softened along y."""
    from napari_lfdeblur import blind_deblur
    from napari_lfdeblur.blind import BlindParams
    from napari_lfdeblur.metrics import path_error

    params = BlindParams.preset("default").replace(final=None)
    rows = []
    for spec in specs:
        cp, sharp = eval_set.true_path(spec), eval_set.sharp_lightfield(spec)
        s = equalising_sigma(central_view(sharp)) if sigma is None else sigma
        softened = ndimage.gaussian_filter1d(sharp, s, axis=2, mode="nearest")
        for label, scene in (("as is", sharp), (f"softened along y by {s:.2f} px", softened)):
            blurred = eval_set.blurred_lightfield(spec, scene, cp)
            res = blind_deblur(blurred, infinity_disparity=spec.infinity_disparity, params=params, seed=0)
            est = res.info.get("rejected_path", res.control_points)  # the estimate, even where found too weak
            err = path_error(est, cp, n_times=ev.PATH_TIMES, lightfield=scene,
                             infinity_disparity=spec.infinity_disparity)
            rows.append((spec.name, label, err.blur_mismatch, est, cp))
    print("\n## Path estimates (path stage only)\n")
    covariance_table(rows)


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--run", default="", help="comma-separated cases for part 2 (about a minute each)")
    ap.add_argument("--sigma", type=float, default=None,
                    help="y-Gaussian (px) of part 2 (default: the one measured on each case)")
    args = ap.parse_args(argv)
    scene_table(ev.dev_study_cases(args))
    if args.run:
        path_table(ev.select_cases("dev", args.run.split(","))[0], args.sigma)


if __name__ == "__main__":
    main()
