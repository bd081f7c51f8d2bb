"""The evaluation set of benchmarks/blind_eval.py: cases, fixed by seed, in a development and a test split.

Groups
------
- ``rendered``: ``procedural_scene(seed=...)`` (natural textures on planes at random depths,
  occlusions), rendered with the case's ``d_inf``, so that every point is nearer than infinity;
- ``F01``: 128 x 128 crops of the first-generation Lytro capture ``lytro-f01-img0001``
  (one dominant plane at about 0.6 px/view), views 2..10 in both directions;
- ``Illum``: 128 x 128 crops of the Lytro Illum capture ``lytro-illum-2067`` (a toy dinosaur in
  front of grass and a wall: a depth range of about -0.4 to -0.9 px/view), away from its black
  corners.

A real capture is the sharp light field as it is; its blur is rendered with the case's ``d_inf``
like a rendered scene's. Every case: a hidden Bezier path (3 to 5 control points) scaled to an
extent (largest distance between two of its positions, z included, in views) from 0 (no blur) through
barely there (0.3 to 0.4 view) to 4 views, most with ``p_z != 0``, rendered with ``T = 128``
instants, plus Gaussian noise of sigma 0.002 or 0.01, clipped to [0, 1]. The true path is moved
to the zero-mean gauge for ``T = 128``, so the ground truth is the sharp light field itself.

Splits
------
``dev`` (18 cases) is for development and tuning; ``test`` (24 cases) is run after the
method is frozen. Each split covers every group, every ``d_inf`` of ``D_INF`` and both noise
levels; each group has cases at ``d_inf = 0`` and ``!= 0`` and at both noise levels; each split has
one case with no blur and two barely blurred ones ("do no harm"). The two splits share no scene
seed, crop window or path.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("LFDEBLUR_DATA", ROOT.parent / "shared" / "data"))
#: the captures (environment variables LFDEBLUR_F01_CAPTURE / LFDEBLUR_ILLUM_CAPTURE override)
F01_CAPTURE = Path(os.environ.get("LFDEBLUR_F01_CAPTURE", DATA / "lytro-f01-img0001"))
ILLUM_CAPTURE = Path(os.environ.get("LFDEBLUR_ILLUM_CAPTURE", DATA / "lytro-illum-2067"))
#: F01 names are IMG_0001_KKK_AA_BB.png with AA the horizontal view index
F01_PATTERN = r"_(?P<col>\d+)_(?P<row>\d+)\.png$"

GROUPS = ("rendered", "F01", "Illum")
D_INF = (0.0, 0.5, -0.5, 1.0, -1.0, 2.0)
NOISE = (0.002, 0.01)
RENDER_TIMES = 128
SHAPE = (9, 9, 128, 128)
QUICK_SHAPE = (5, 5, 32, 32)
#: split -> (seed, cases per group)
SPLITS = {"dev": (15_001, {"rendered": 8, "F01": 5, "Illum": 5}),
          "test": (15_002, {"rendered": 10, "F01": 7, "Illum": 7})}
#: top-left corners of the crop windows: F01 anywhere in its 256 x 256 views; Illum inside the
#: region whose every view is lit (no black corner), below the far wall (depth range in the crop)
CROP_RANGE = {"F01": ((0, 128), (0, 128)), "Illum": ((48, 239), (48, 376))}
MIN_CROP_DISTANCE = 24  # px between two crop windows of the same capture (largest axis), across splits too


@dataclass(frozen=True)
class CaseSpec:
    """One case of the evaluation set: everything it needs, derived from the split's seed."""

    name: str
    split: str
    group: str
    scene: tuple  # ("seed", n) for rendered, ("crop", y0, x0) for a capture
    infinity_disparity: float
    extent: float  # views; 0: no blur
    z_ratio: float  # random_path's z_extent before scaling (0: in-plane)
    n_points: int
    path_seed: int
    noise: float
    noise_seed: int

    @property
    def kind(self) -> str:
        """``'none'``, ``'barely'`` or ``'blurred'``: how much blur the case has."""
        return "none" if self.extent == 0 else ("barely" if self.extent < 0.5 else "blurred")


def _spread(rng, values, n):
    """``n`` values cycling through ``values``, each cycle shuffled."""
    out = []
    while len(out) < n:
        out += list(rng.permutation(np.asarray(values, dtype=object)))
    return out[:n]


def _covers(cases) -> bool:
    if {c.infinity_disparity for c in cases} != set(D_INF) or {c.noise for c in cases} != set(NOISE):
        return False
    for g in GROUPS:
        sel = [c for c in cases if c.group == g]
        if {c.noise for c in sel} != set(NOISE) or len({c.infinity_disparity == 0 for c in sel}) != 2:
            return False
    return True


def _crops(rng, group, n, taken):
    (y_lo, y_hi), (x_lo, x_hi) = CROP_RANGE[group]
    out = []
    for _ in range(10_000):
        if len(out) == n:
            break
        y0, x0 = int(rng.integers(y_lo, y_hi + 1)), int(rng.integers(x_lo, x_hi + 1))
        if all(max(abs(y0 - y), abs(x0 - x)) >= MIN_CROP_DISTANCE for y, x in taken + out):
            out.append((y0, x0))
    if len(out) < n:
        raise RuntimeError(f"cannot place {n} distinct {group} crops")
    return out


def _attempt(split: str, rng, taken_crops) -> list[CaseSpec]:
    seed, counts = SPLITS[split]
    groups = [g for g in GROUPS for _ in range(counts[g])]
    n = len(groups)
    n_zero = n // 3  # a third at d_inf = 0, the others spread over the non-zero values
    d_infs = list(rng.permutation([0.0] * n_zero + _spread(rng, [d for d in D_INF if d != 0], n - n_zero)))
    noise = {g: _spread(rng, NOISE, counts[g]) for g in GROUPS}
    # the "do no harm" cases: one without blur, two barely blurred, in three different groups
    special = dict(zip(rng.permutation(GROUPS), (0.0, rng.uniform(0.3, 0.4), rng.uniform(0.3, 0.4))))
    crops = {g: _crops(rng, g, counts[g], taken_crops.get(g, [])) for g in ("F01", "Illum")}
    cases, index = [], {g: 0 for g in GROUPS}
    for k, g in enumerate(groups):
        i = index[g]
        index[g] += 1
        extent = float(special[g]) if i == 0 and g in special else float(np.exp(rng.uniform(np.log(0.5), np.log(4.0))))
        z_ratio = 0.0 if rng.random() < 0.2 else float(rng.uniform(0.2, 0.6))
        scene = ("seed", seed * 100 + k) if g == "rendered" else ("crop", *crops[g][i])
        cases.append(CaseSpec(
            name=f"{split}{k:02d}", split=split, group=g, scene=scene, infinity_disparity=float(d_infs[k]),
            extent=round(extent, 3), z_ratio=round(z_ratio, 3), n_points=int(rng.choice([3, 4, 4, 5])),
            path_seed=seed * 100 + k, noise=float(noise[g][i]), noise_seed=seed * 1000 + k,
        ))
    return cases


@functools.lru_cache(maxsize=None)
def split_cases(split: str) -> tuple[CaseSpec, ...]:
    """The cases of ``split`` (``'dev'`` or ``'test'``), the same on every call and machine."""
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}: choose from {sorted(SPLITS)}")
    taken = {}
    if split == "test":  # the test crops keep away from the dev ones
        for c in split_cases("dev"):
            if c.scene[0] == "crop":
                taken.setdefault(c.group, []).append(c.scene[1:])
    rng = np.random.default_rng(SPLITS[split][0])
    for _ in range(100):
        cases = _attempt(split, rng, taken)
        if _covers(cases):
            return tuple(cases)
    raise RuntimeError(f"no draw of split {split!r} covers every group, d_inf and noise level")


# ------------------------------------------------------------------ data


def capture_available(group: str) -> bool:
    """Whether the capture of a real group is on this machine (rendered scenes always are)."""
    return group == "rendered" or {"F01": F01_CAPTURE, "Illum": ILLUM_CAPTURE}[group].is_dir()


@functools.lru_cache(maxsize=2)
def capture(group: str) -> np.ndarray:
    """The whole capture of ``group`` (``"F01"``: views 2..10 of both axes; ``"Illum"``), float32."""
    from napari_lfdeblur import read_lightfield

    if group == "F01":  # views 2..10 of the 10 x 10, horizontal index first in the names
        return read_lightfield(F01_CAPTURE, pattern=F01_PATTERN)[1:10, 1:10]
    return read_lightfield(ILLUM_CAPTURE)


def sharp_lightfield(spec: CaseSpec, quick: bool = False) -> np.ndarray:
    """The ground-truth light field of a case, float32 ``(V, U, Y, X, 3)`` (tiny when ``quick``)."""
    from napari_lfdeblur import procedural_scene

    V, U, Y, X = QUICK_SHAPE if quick else SHAPE
    if spec.group == "rendered":
        lf, _ = procedural_scene((V, U, Y, X), seed=spec.scene[1], infinity_disparity=spec.infinity_disparity)
        return lf
    y0, x0 = spec.scene[1:]
    lf = capture(spec.group)
    a, b = (lf.shape[0] - V) // 2, (lf.shape[1] - U) // 2
    return np.ascontiguousarray(lf[a : a + V, b : b + U, y0 : y0 + Y, x0 : x0 + X], dtype=np.float32)


def true_path(spec: CaseSpec) -> np.ndarray:
    """The case's path, in the zero-mean gauge for ``RENDER_TIMES`` instants, scaled to its extent."""
    from napari_lfdeblur import bezier_positions, random_path
    from napari_lfdeblur.path import center_path

    if spec.extent == 0:
        return np.zeros((2, 3))
    cp = center_path(random_path(spec.n_points, extent=1.0, z_extent=spec.z_ratio, seed=spec.path_seed),
                     RENDER_TIMES)
    pos = bezier_positions(cp, RENDER_TIMES)
    diameter = np.sqrt(((pos[:, None] - pos[None]) ** 2).sum(-1)).max()
    return cp * (spec.extent / diameter)


def blurred_lightfield(spec: CaseSpec, sharp: np.ndarray, cp: np.ndarray) -> np.ndarray:
    """``sharp`` blurred by ``cp`` (``T = RENDER_TIMES``, the case's ``d_inf``), plus the case's noise, in [0, 1]."""
    from napari_lfdeblur import simulate_blur

    blurred = simulate_blur(sharp, cp, n_times=RENDER_TIMES, infinity_disparity=spec.infinity_disparity,
                            device="cpu")
    rng = np.random.default_rng(spec.noise_seed)
    return np.clip(blurred + rng.normal(0.0, spec.noise, blurred.shape), 0.0, 1.0).astype(np.float32)


def scene_disparity(spec: CaseSpec, sharp: np.ndarray) -> np.ndarray:
    """Disparity (px/view) of the centre view of a case's sharp light field, ``(Y, X)`` float32.

    Rendered scenes: the renderer's own map (exact). Captures: estimated from the views (the shear
    that makes them agree best; ``napari_lfdeblur.blind._disparity.disparity_map``), reliable where
    there is texture, which is where a blur shows.
    """
    import torch

    from napari_lfdeblur import procedural_scene
    from napari_lfdeblur.blind._disparity import disparity_map, gray

    if spec.group == "rendered":
        return procedural_scene(sharp.shape[:4], seed=spec.scene[1], infinity_disparity=spec.infinity_disparity)[1]
    return disparity_map(gray(torch.as_tensor(sharp)))


def blur_length(cp, sharp: np.ndarray, disparity: np.ndarray, infinity_disparity: float) -> float:
    """How far the blur of path ``cp`` moves the scene, in px: the length of the equivalent straight blur.

    A point at disparity ``d`` moves by ``(d - d_inf) s`` px when the camera moves by ``s`` views,
    with ``s = (p_x - x~ p_z, p_y - y~ p_z)`` at its pixel (the forward model). Its RMS motion over
    the exposure is averaged (root mean square) over the centre view's pixels, weighted by the squared
    gradient of its grayscale (the motion of a flat region does not show), and multiplied by
    ``sqrt(12)``: a uniform motion along a straight line of length ``L`` has RMS ``L / sqrt(12)``.
    0 for no blur. Rotation columns, if any, are not counted.
    """
    from napari_lfdeblur import bezier_positions

    pos = bezier_positions(np.asarray(cp, dtype=np.float64)[:, :3], RENDER_TIMES)
    Y, X = disparity.shape
    R = max(Y, X) / 2
    xt, yt = (np.arange(X) - (X - 1) / 2) / R, (np.arange(Y) - (Y - 1) / 2) / R
    s_u = pos[:, 0, None] - pos[:, 2, None] * xt[None]  # (T, X)
    s_v = pos[:, 1, None] - pos[:, 2, None] * yt[None]  # (T, Y)
    spread = s_v.var(axis=0)[:, None] + s_u.var(axis=0)[None, :]  # (Y, X), views^2
    centre = sharp[sharp.shape[0] // 2, sharp.shape[1] // 2].astype(np.float64)
    gy, gx = np.gradient(centre.mean(axis=-1) if centre.ndim == 3 else centre)
    w = gy * gy + gx * gx
    rel = disparity.astype(np.float64) - infinity_disparity
    return float(np.sqrt(12.0 * (w * rel * rel * spread).sum() / max(w.sum(), 1e-30)))


def describe(spec: CaseSpec) -> str:
    """The scene of a case in words: ``seed 1500103`` or ``crop y 64, x 120``."""
    return f"seed {spec.scene[1]}" if spec.scene[0] == "seed" else f"crop y {spec.scene[1]}, x {spec.scene[2]}"
