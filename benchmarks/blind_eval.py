"""Evaluate blind light-field deblurring against ground truth.

Cases
-----
- ``syn``: the synthetic layered scene ``synthetic_scene(shape=(9, 9, 128, 128),
  n_layers=3, color=True, seed=1)`` (ground-truth disparities 0.25..1.5 px/view);
- ``lytro``: the real Lytro crop shipped with the package, ``lytro_sample()``
  (9 x 9 x 128 x 128 x 3, views 2..10 and the central 128 x 128 pixels of the
  Lytro capture ``IMG_0001``);
- more scenes (``syn2`` .. ``syn5``: other seeds; ``lytro2`` .. ``lytro5``: the
  four corners of the same capture, read from ``LYTRO_CAPTURE``);

each blurred by the fixed random paths of ``PATHS`` (``random_path`` with
fixed seeds, in-plane and with some ``z``), rendered with ``T = 128`` instants
(far more than any solver uses), plus Gaussian noise of sigma 0.002 (seeded),
clipped to [0, 1]. ``d_inf = 0`` for rendering and solving.

Ground truth
------------
Each true path is moved to the zero-mean gauge for ``T = 128`` (docs/model.md,
"Gauge"), so the ground-truth restored light field is the sharp
light field itself (the view from the mean camera position).

Methods
-------
- ``default`` and ``paper``: ``blind_deblur`` with those presets (skipped, and
  marked so, when ``napari_lfdeblur.blind`` cannot be imported);
- ``baseline2d``: every view deblurred on its own by the L0-gradient 2D blind
  deconvolution of ``benchmarks/_baseline2d.py`` (no path estimate);
- ``camera`` (only when asked for): ``default`` told how much softer the
  camera's views are along x than along y (``edge_anisotropy``, from
  ``CAMERA_EDGE_ANISOTROPY``): knowledge of the camera that a blind method
  does not have, so it is not the headline, and it shows what the isotropic
  edge model costs on the Lytro crops (docs/blind.md, "Cameras whose views
  are softer along one axis").

Metrics (``napari_lfdeblur.metrics``), spatial borders of ``CROP`` px removed:
PSNR, SSIM, angular error (RMSE of the differences between neighbouring
views: angular consistency), and for path estimates the blur mismatch, the
Chamfer distance and the best-time-direction RMSE relative to the path's
extent. Time is wall-clock time of the method call; peak memory is the peak
resident set size above the level before the call (sampled every 10 ms), or
``torch.cuda.max_memory_allocated`` on a GPU.

Usage::

    python benchmarks/blind_eval.py                       # full run, writes docs/benchmarks/blind_eval.md
    python benchmarks/blind_eval.py --quick               # tiny smoke run, writes nothing
    python benchmarks/blind_eval.py --methods baseline2d --cases syn-p1,lytro-p2 --out /tmp/eval.md
    python benchmarks/blind_eval.py --device cuda
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)

ROOT = _report.ROOT
DEFAULT_OUTPUT = _report.default_table(__file__)

RENDER_TIMES = 128  # instants of the ground-truth blur
NOISE_SIGMA = 0.002
CROP = 8  # border pixels removed before PSNR / SSIM / angular error
PATH_TIMES = 64  # instants for the path errors
DEFAULT_METHODS = ("default", "paper", "baseline2d")
ALL_METHODS = (*DEFAULT_METHODS, "camera")
#: ``edge_anisotropy`` of the ``camera`` method by scene family: the renderer's views are
#: isotropic by construction; the Lytro value is the mean, over the four crops, of the y-Gaussian
#: that makes a crop's central view as soft along y as along x (benchmarks/scene_anisotropy.py:
#: 0.65, 0.55, 0.70, 0.49; leaving any one crop out gives 0.56 to 0.63)
CAMERA_EDGE_ANISOTROPY = {"syn": 0.0, "lytro": 0.6}

#: name -> (n_points, extent, z_ratio, seed): ``random_path(n_points, extent=1, z_extent=z_ratio,
#: seed=seed)`` scaled so that its extent (the largest distance between two of its positions,
#: z included, in views) is ``extent``
PATHS = {
    "p1": (4, 2.0, 0.0, 101),
    "p2": (4, 3.0, 0.0, 102),
    "p3": (4, 2.5, 0.5, 103),
    "p4": (4, 2.5, 0.0, 104),
    "p5": (4, 2.0, 0.3, 105),
    "p6": (4, 2.5, 0.0, 106),
    "p7": (4, 2.5, 0.4, 107),
    "p8": (4, 2.5, 0.0, 108),
    "p9": (4, 2.0, 0.4, 109),
    "p10": (4, 2.5, 0.0, 110),
    "p11": (4, 2.0, 0.4, 111),
}

#: the cases: each scene with its paths (scene ``syn`` and ``lytro`` with ``p1``..``p3``, ``syn2`` and
#: ``lytro2`` with ``p4``, ``p5``, ...), eleven synthetic and eleven Lytro ones
CASES = [f"{s}{n}-{p}" for n, paths in (("", ("p1", "p2", "p3")), ("2", ("p4", "p5")), ("3", ("p6", "p7")),
                                        ("4", ("p8", "p9")), ("5", ("p10", "p11")))
         for s in ("syn", "lytro") for p in paths]
#: scene families, whose means the summary gives apart
FAMILIES = {"synthetic": "syn", "Lytro": "lytro"}
#: the full Lytro capture the ``lytro2`` .. ``lytro5`` crops come from, a folder of views (the
#: environment variable LFDEBLUR_LYTRO_CAPTURE overrides)
LYTRO_CAPTURE = Path(os.environ.get("LFDEBLUR_LYTRO_CAPTURE", ROOT.parent / "shared" / "data" / "lytro-f01-img0001"))
#: the capture's names are IMG_0001_KKK_RR_CC.png with RR the horizontal view index
LYTRO_PATTERN = r"_(?P<col>\d+)_(?P<row>\d+)\.png$"


def true_path(name: str) -> np.ndarray:
    """The true path of ``PATHS[name]``, in the zero-mean gauge for ``RENDER_TIMES`` instants."""
    from napari_lfdeblur import bezier_positions, random_path
    from napari_lfdeblur.path import center_path

    n_points, extent, z_ratio, seed = PATHS[name]
    cp = center_path(random_path(n_points, extent=1.0, z_extent=z_ratio, seed=seed), RENDER_TIMES)
    pos = bezier_positions(cp, RENDER_TIMES)
    diameter = np.sqrt(((pos[:, None] - pos[None]) ** 2).sum(-1)).max()
    return cp * (extent / diameter)


# ------------------------------------------------------------------ cases


@dataclass
class Case:
    name: str
    scene: str
    sharp: np.ndarray  # ground truth, zero-mean gauge
    blurred: np.ndarray
    control_points: np.ndarray  # true path, zero-mean gauge for RENDER_TIMES
    infinity_disparity: float = 0.0
    info: dict = field(default_factory=dict)


def _scene(name: str, quick: bool):
    from napari_lfdeblur import lytro_sample, synthetic_scene

    if name == "syn":
        shape = (5, 5, 32, 32) if quick else (9, 9, 128, 128)
        lf, _ = synthetic_scene(shape=shape, n_layers=3, color=True, seed=1)
        return lf
    if name == "lytro":
        lf = lytro_sample()
        if quick:
            lf = lf[2:7, 2:7, 48:80, 48:80]
        return np.ascontiguousarray(lf)
    if name == "syn2":
        lf, _ = synthetic_scene(shape=(9, 9, 128, 128), n_layers=3, color=True, seed=2)
        return lf
    if name in ("syn3", "syn4", "syn5"):
        lf, _ = synthetic_scene(shape=(9, 9, 128, 128), n_layers=3, color=True, seed=int(name[-1]))
        return lf
    if name in ("lytro2", "lytro3", "lytro4", "lytro5"):
        from napari_lfdeblur import read_lightfield

        # lytro2: the top-left 128 x 128 pixels of the capture (the `lytro` crop is pixels 64..191);
        # lytro3: the bottom-right ones; lytro4: the top-right ones; lytro5: the bottom-left ones;
        # same views. The capture's file
        # names give the horizontal view index first (read as named, u would move the image along y)
        lf = read_lightfield(LYTRO_CAPTURE, pattern=LYTRO_PATTERN)
        win = {"lytro2": (slice(None, 128), slice(None, 128)), "lytro3": (slice(-128, None), slice(-128, None)),
               "lytro4": (slice(None, 128), slice(-128, None)),
               "lytro5": (slice(-128, None), slice(None, 128))}[name]
        return np.ascontiguousarray(lf[1:10, 1:10, win[0], win[1]], dtype=np.float32)
    raise ValueError(f"unknown scene {name!r}")


def make_case(name: str, quick: bool = False) -> Case:
    """Build the case ``<scene>-<path>`` (e.g. ``syn-p1``)."""
    from napari_lfdeblur import simulate_blur

    scene, _, pname = name.partition("-")
    if pname not in PATHS:
        raise ValueError(f"unknown case {name!r}: paths are {sorted(PATHS)}")
    seed = PATHS[pname][3]
    cp = true_path(pname)
    sharp = _scene(scene, quick)
    blurred = simulate_blur(sharp, cp, n_times=RENDER_TIMES, infinity_disparity=0.0)
    rng = np.random.default_rng(1000 + seed)
    blurred = np.clip(blurred + rng.normal(0.0, NOISE_SIGMA, blurred.shape), 0.0, 1.0).astype(np.float32)
    return Case(name, scene, sharp, blurred, cp, 0.0, {"path": PATHS[pname]})


def case_names(quick: bool) -> list[str]:
    if quick:
        return ["syn-p2"]
    # lytro2..lytro5 need the capture; `syn` and `lytro` are built in
    return [c for c in CASES if c.startswith("syn") or c.split("-")[0] == "lytro" or LYTRO_CAPTURE.is_dir()]


# ------------------------------------------------------------ measurement


class PeakMemory:
    """Peak memory of a block: RSS sampled in a thread (CPU), or CUDA's own peak."""

    def __init__(self, device: str):
        self.cuda = device.startswith("cuda")
        self.peak = 0
        self._stop = threading.Event()

    @staticmethod
    def _rss() -> int:
        try:
            import psutil

            return psutil.Process().memory_info().rss
        except ImportError:  # ru_maxrss is a lifetime peak: a coarse fallback
            return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

    def _sample(self):
        while not self._stop.wait(0.01):
            self.peak = max(self.peak, self._rss())

    def __enter__(self):
        if self.cuda:
            import torch

            torch.cuda.synchronize()
            torch.cuda.reset_peak_memory_stats()
            self._base = torch.cuda.memory_allocated()
        else:
            self._base = self._rss()
            self.peak = self._base
            self._thread = threading.Thread(target=self._sample, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        if self.cuda:
            import torch

            torch.cuda.synchronize()
            self.peak = torch.cuda.max_memory_allocated()
        else:
            self._stop.set()
            self._thread.join()
            self.peak = max(self.peak, self._rss())
        return False

    @property
    def delta_mib(self) -> float:
        return (self.peak - self._base) / 2**20


# ---------------------------------------------------------------- methods


def _blind_params(blind, preset: str):
    """The blind solver's parameters for ``preset``, whatever the solver calls it."""
    Params = getattr(blind, "BlindParams")
    for name in ("preset", "from_preset"):
        make = getattr(Params, name, None)
        if callable(make):
            return make(preset)
    presets = getattr(blind, "PRESETS", None)
    if isinstance(presets, dict) and preset in presets:
        return presets[preset]
    raise AttributeError(f"cannot find preset {preset!r} in napari_lfdeblur.blind")


def method_available(method: str) -> tuple[bool, str]:
    if method == "baseline2d":
        return True, ""
    try:
        from napari_lfdeblur import blind

        _blind_params(blind, "default" if method == "camera" else method)
        getattr(blind, "blind_deblur")
    except Exception as exc:  # noqa: BLE001 - any failure means "not available"
        return False, f"napari_lfdeblur.blind not usable: {type(exc).__name__}: {exc}"
    return True, ""


def run_method(method: str, case: Case, device: str, quick: bool):
    """Run one method; returns (restored light field, control points or None, extra info)."""
    if method == "baseline2d":
        from _baseline2d import Baseline2DParams, deblur_views_2d  # benchmarks/_baseline2d.py

        params = Baseline2DParams(kernel_size=7) if quick else Baseline2DParams()
        restored, _ = deblur_views_2d(case.blurred, params)
        return restored, None, {}
    from napari_lfdeblur import blind

    if method == "camera":
        params = _blind_params(blind, "default").replace(
            latent={"edge_anisotropy": CAMERA_EDGE_ANISOTROPY[case.scene.rstrip("0123456789")]})
    else:
        params = _blind_params(blind, method)
    res = blind.blind_deblur(
        case.blurred,
        infinity_disparity=case.infinity_disparity,
        params=params,
        device=device,
        seed=0,
    )
    info = {}
    timings = getattr(res, "timings", None)
    if isinstance(timings, dict):
        info["timings"] = {k: float(v) for k, v in timings.items() if isinstance(v, (int, float))}
    return np.asarray(res.lightfield), np.asarray(res.control_points), info


def evaluate(case: Case, method: str, device: str, quick: bool) -> dict:
    from napari_lfdeblur.metrics import angular_error, path_error, psnr, ssim

    with PeakMemory(device) as mem:
        t0 = time.perf_counter()
        restored, cp, info = run_method(method, case, device, quick)
        seconds = time.perf_counter() - t0
    crop = 2 if quick else CROP
    row = {
        "case": case.name,
        "method": method,
        "psnr": psnr(restored, case.sharp, crop=crop),
        "ssim": ssim(restored, case.sharp, crop=crop),
        "angular": angular_error(restored, case.sharp, crop=crop),
        "seconds": seconds,
        "peak_mib": mem.delta_mib,
        **info,
    }
    if cp is not None:
        err = path_error(
            cp,
            case.control_points,
            n_times=PATH_TIMES,
            lightfield=case.sharp,
            infinity_disparity=case.infinity_disparity,
        )
        row.update(
            blur_mismatch=err.blur_mismatch,
            chamfer=err.chamfer,
            rmse_relative=err.rmse_relative,
            control_points=np.asarray(cp).tolist(),
        )
    return row


def input_row(case: Case, quick: bool) -> dict:
    from napari_lfdeblur.metrics import angular_error, path_error, psnr, ssim

    crop = 2 if quick else CROP
    # the blurred input is the estimate "no motion": its path error is that of the zero path
    err = path_error(np.zeros((2, 3)), case.control_points, n_times=PATH_TIMES, lightfield=case.sharp)
    return {
        "case": case.name,
        "method": "input (blurred)",
        "psnr": psnr(case.blurred, case.sharp, crop=crop),
        "ssim": ssim(case.blurred, case.sharp, crop=crop),
        "angular": angular_error(case.blurred, case.sharp, crop=crop),
        "blur_mismatch": err.blur_mismatch,
        "chamfer": err.chamfer,
        "rmse_relative": err.rmse_relative,
        "path_extent": err.extent,
    }


# ----------------------------------------------------------------- report


def _fmt(value, spec):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    return format(value, spec)


def _table(rows: list[dict]) -> list[str]:
    head = (
        "| case | method | PSNR dB | ΔPSNR dB | SSIM | angular err | blur mismatch | Chamfer (views) "
        "| rel. RMSE | time s | peak MiB |"
    )
    out = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        out.append(
            "| {case} | {method} | {psnr} | {gain} | {ssim} | {ang} | {bm} | {ch} | {rr} | {t} | {m} |".format(
                case=r["case"],
                method=r["method"],
                psnr=_fmt(r.get("psnr"), ".2f"),
                gain=_fmt(r.get("gain"), "+.2f"),
                ssim=_fmt(r.get("ssim"), ".4f"),
                ang=_fmt(r.get("angular"), ".5f"),
                bm=_fmt(r.get("blur_mismatch"), ".3f"),
                ch=_fmt(r.get("chamfer"), ".3f"),
                rr=_fmt(r.get("rmse_relative"), ".3f"),
                t=_fmt(r.get("seconds"), ".1f"),
                m=_fmt(r.get("peak_mib"), ".0f"),
            )
        )
    return out


def _mean(rows, key):
    vals = [r[key] for r in rows if isinstance(r.get(key), (int, float)) and not math.isnan(r[key])]
    return float(np.mean(vals)) if vals else None


def _family(case: str) -> str:
    """The scene family of a case: ``'syn'`` for ``syn3-p6``, ``'lytro'`` for ``lytro-p1``."""
    return case.split("-")[0].rstrip("0123456789")


def summarise(rows: list[dict], methods: list[str]) -> list[dict]:
    """One mean row per method (and for the input), over the cases it ran on."""
    out = []
    groups = [("", lambda c: True)]
    families = {label: prefix for label, prefix in FAMILIES.items() if any(_family(r["case"]) == prefix for r in rows)}
    if len(families) > 1:
        groups += [(f" {label}", lambda c, prefix=prefix: _family(c) == prefix) for label, prefix in families.items()]
    for (label, keep), method in ((g, m) for g in groups for m in ["input (blurred)", *methods]):
        sel = [r for r in rows if r["method"] == method and "error" not in r and "skipped" not in r and keep(r["case"])]
        if not sel:
            continue
        out.append(
            {
                "case": f"**mean of {len(sel)}{label}**",
                "group": label.strip() or "all",
                "method": method,
                **{
                    k: _mean(sel, k)
                    for k in ("psnr", "gain", "ssim", "angular", "blur_mismatch", "chamfer", "rmse_relative", "seconds", "peak_mib")
                },
                "seconds_max": max((r["seconds"] for r in sel if "seconds" in r), default=None),
            }
        )
    return out


def _paired(rows, a, b, key):
    """Means of ``key`` for methods ``a`` and ``b`` over the cases where both gave a value."""
    va = {r["case"]: r.get(key) for r in rows if r["method"] == a}
    vb = {r["case"]: r.get(key) for r in rows if r["method"] == b}
    common = [c for c in va if c in vb and va[c] is not None and vb[c] is not None]
    if not common:
        return None
    return float(np.mean([va[c] for c in common])), float(np.mean([vb[c] for c in common])), len(common)


def targets(means: list[dict], quick: bool, rows: list[dict] | None = None) -> list[str]:
    """The issue's CPU targets, checked against the measured figures (never assumed)."""
    by = {r["method"]: r for r in means if r.get("group") == "all"}
    d = by.get("default")
    if d is None:
        return ["- `default` did not run: no target can be checked."]
    lines = []

    def check(ok, text):
        lines.append(f"- {'met' if ok else '**not met**'}: {text}")

    if d.get("seconds_max") is not None:
        check(
            d["seconds_max"] <= 60,
            f"≤ 60 s per light field (slowest {d['seconds_max']:.1f} s, mean {d['seconds']:.1f} s)",
        )
    if d.get("gain") is not None:
        check(d["gain"] >= 4.0, f"mean PSNR gain ≥ +4 dB (mean {d['gain']:+.3f} dB)")
    if d.get("blur_mismatch") is not None:
        check(d["blur_mismatch"] <= 0.2, f"mean blur mismatch ≤ 0.2 (mean {d['blur_mismatch']:.4f})")
    for key, label, better, spec in (
        ("psnr", "PSNR above", np.greater, ".2f"),
        ("angular", "angular error below", np.less, ".5f"),
    ):
        pair = _paired(rows or [], "default", "baseline2d", key)
        if pair is not None:
            x, y, n = pair
            check(
                bool(better(x, y)),
                f"{label} the per-view 2D baseline (means over {n} common cases: "
                f"{format(x, spec)} vs {format(y, spec)})",
            )
    if quick:
        lines.append("- (quick run: tiny sizes, the targets do not apply)")
    return lines


METHOD_TEXT = """\
## How the figures are made

- **Scenes.** `syn`: `synthetic_scene(shape=(9, 9, 128, 128), n_layers=3, color=True, seed=1)`,
  layered textured planes at disparities 0.25..1.5 px/view with occlusions; `syn2` .. `syn5` the
  same with `seed=2..5`. `lytro`: the real Lytro crop `lytro_sample()` (9×9×128×128×3, its content
  at about 0.63 px/view); `lytro2` .. `lytro5`: the top-left, bottom-right, top-right and bottom-left
  128×128 pixels of the same capture, views 2..10, read with the horizontal view index first (as
  its file names give it; docs/io.md, "View order").
- **Paths.** Fixed random cubic Bézier paths `random_path(4, seed=100 + k)` for `pk`, scaled so that
  the largest distance between two positions is 2 to 3 views; `p3`, `p5`, `p7`, `p9` and `p11`
  also move in z. Each scene is blurred by two or three of them (`syn-p1`, `syn-p2`, `syn-p3`,
  `syn2-p4`, `syn2-p5`, ...), rendered with **T = 128** instants (far more than a solver uses) with
  `d_inf = 0`, plus Gaussian noise σ = 0.002 (seeded), clipped to [0, 1]. The summary gives the
  means over all cases and over each scene family.
- **Ground truth.** The true path is moved to the zero-mean gauge for T = 128, so the ground-truth
  light field is the sharp one seen from the mean camera position (docs/model.md, "Gauge").
- **Image metrics** (`napari_lfdeblur.metrics`), with {crop} border pixels cropped in y and x:
  PSNR over all views and channels; SSIM, the mean over views and channels of scikit-image's SSIM
  (7×7 window); **angular error**, the RMSE between the differences of neighbouring views
  (`l[v, u+1] - l[v, u]`, `l[v+1, u] - l[v, u]`) of the estimate and of the ground truth. It measures
  angular consistency: independent per-view processing leaves each view its own residual blur, shift
  and ringing, which shows up in these differences even when every view looks sharp. Lower is better.
- **Path metrics**, both paths sampled at 64 instants and moved to zero mean (docs/model.md,
  "Judging an estimate"): **blur mismatch** `||B(l, p_est) - B(l, p_true)|| / ||B(l, p_true) - l||`
  on the ground-truth light field (0 is perfect, 1 is as bad as assuming no motion); **Chamfer**
  distance between the two sets of positions, in views (blind to time order); **rel. RMSE**, the
  pointwise RMSE for the better time direction divided by the true path's extent (reported, not
  optimised for). The input row shows the path errors of "no motion" (the zero path).
- **Methods.** `default` and `paper`: `blind_deblur` with those presets, given only the blurred light
  field and `d_inf`. `camera`: `default` with `edge_anisotropy=0.6` on the Lytro cases (how much
  softer the capture's views are along x; knowledge a blind method does not have). `baseline2d`:
  each view deblurred on its own by a compact L0-gradient blind deconvolution (Xu et al. 2013 /
  Pan et al. 2014 style; `benchmarks/_baseline2d.py`): coarse-to-fine kernel estimation (11×11
  kernel, pyramid factor √2) alternating an L0-gradient latent update (half-quadratic splitting,
  FFT) with a gradient-domain least-squares kernel update (conjugate gradients, non-negative,
  thresholded, sum 1, re-centred on its centroid), then a non-blind Wiener filter with a gradient
  prior (`min ||k*x - y||² + 0.05 ||∇x||²`) per colour channel. Its free parameters were set on light
  fields not in this table (synthetic scene seed 0 and the Lytro sample, blurred by path seed 50).
  One spatially uniform kernel per view cannot follow the light field's blur, which scales with
  disparity and flips with its sign; that is the point of the comparison. It estimates no camera
  path.
- **Time** is the wall-clock time of the method call. **Peak memory** is the peak resident set size
  above the level before the call, sampled every 10 ms (CPU), or `torch.cuda.max_memory_allocated`
  (GPU).
"""


def render(rows, means, methods, skipped, args, env) -> str:
    lines = ["# Blind deblurring: evaluation against ground truth", "",
             f"Command: `{env['command']}`", "", f"Machine: {env['machine']}", ""]
    if args.quick:
        lines += ["**Quick smoke run at tiny sizes: not the benchmark.**", ""]
    lines += [
        "## Summary (means over the cases)",
        "",
        *_table(means),
        "",
        "## Targets (CPU)",
        "",
        *targets(means, args.quick, rows),
        "",
    ]
    not_requested = [m for m in ALL_METHODS if m not in methods]
    if skipped or not_requested or args.note:
        lines += ["## Skipped and notes", ""]
        lines += [f"- `{m}`: skipped, {why}" for m, why in skipped.items()]
        lines += [f"- `{m}`: not run (not in `--methods`)." for m in not_requested]
        lines += [f"- {note}" for note in args.note]
        lines += [""]
    errors = [r for r in rows if "error" in r]
    if errors:
        lines += ["## Failures", ""]
        lines += [f"- `{r['method']}` on `{r['case']}`: {r['error']}" for r in errors]
        lines += [""]
    if args.cases_for:
        lines += ["Methods run on a subset of the cases: " + "; ".join(f"`{c}`" for c in args.cases_for) + ".", ""]
    lines += ["## Per case", "", *_table([r for r in rows if "error" not in r]), ""]
    lines += [METHOD_TEXT.format(crop=2 if args.quick else CROP)]
    return "\n".join(lines)


# ------------------------------------------------------------------- main


def write(rows, run, methods, skipped, args, env, output, *, final, n_done=0, n_all=0):
    """Render the report; print and write it (and the JSON) when final, only write it when partial."""
    means = summarise(rows, run)
    text = render(rows, means, methods, skipped, args, env)
    if not final:
        head, _, rest = text.partition("\n\n")
        text = f"{head}\n\n**Partial: {n_done} of {n_all} cases done; the run is still going or was cut short.**\n\n{rest}"
    else:
        print(text)
    if output is not None:
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(text + "\n")
        if final:
            print(f"wrote {output}", file=sys.stderr)
    if args.json:
        Path(args.json).write_text(
            json.dumps({"env": env, "rows": rows, "means": means, "skipped": skipped, "final": final}, indent=1)
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny sizes, one case: a smoke run")
    ap.add_argument("--cases", help="comma-separated case names, e.g. syn-p1,lytro-p3 (default: all)")
    ap.add_argument("--methods", default=",".join(DEFAULT_METHODS), help=f"comma-separated, from {ALL_METHODS}")
    ap.add_argument(
        "--cases-for",
        action="append",
        default=[],
        metavar="METHOD=CASE,CASE",
        help="run METHOD only on these cases (e.g. a slow preset on a subset); repeatable",
    )
    ap.add_argument("--device", default="cpu", help="cpu, cuda or auto (default cpu)")
    _report.add_out_argument(ap, __file__, "--output")
    ap.add_argument("--json", help="also write every row as JSON here")
    ap.add_argument("--note", action="append", default=[], help="a line of text for the report; repeatable")
    args = ap.parse_args(argv)

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    bad = [m for m in methods if m not in ALL_METHODS]
    if bad:
        ap.error(f"unknown method(s) {bad}; choose from {ALL_METHODS}")
    names = [c.strip() for c in args.cases.split(",")] if args.cases else case_names(args.quick)
    output = _report.table_path(args.out, __file__, smoke=args.quick)
    only = {}
    for spec in args.cases_for:
        method, sep, cases = spec.partition("=")
        if not sep or method not in methods:
            ap.error(f"--cases-for wants METHOD=CASE,CASE with a METHOD from --methods; got {spec!r}")
        only[method] = [c.strip() for c in cases.split(",") if c.strip()]

    import torch

    from napari_lfdeblur.devices import select_device

    device = str(select_device(args.device))
    env = {
        "machine": _report.machine(device),
        "device": device,
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "command": _report.command_line(__file__, argv),
    }

    skipped = {}
    for m in methods:
        ok, why = method_available(m)
        if not ok:
            skipped[m] = why
            print(f"[skip] {m}: {why}", file=sys.stderr)
    run = [m for m in methods if m not in skipped]

    rows = []
    for name in names:
        case = make_case(name, quick=args.quick)
        inp = input_row(case, args.quick)
        rows.append(inp)
        print(f"[case] {name}: shape {case.sharp.shape}, input PSNR {inp['psnr']:.2f} dB", file=sys.stderr)
        for m in run:
            if m in only and name not in only[m]:
                continue
            try:
                row = evaluate(case, m, device, args.quick)
                row["gain"] = row["psnr"] - inp["psnr"]
            except Exception as exc:  # noqa: BLE001 - a failure is reported, never hidden
                traceback.print_exc()
                row = {"case": name, "method": m, "error": f"{type(exc).__name__}: {exc}"}
            rows.append(row)
            msg = row.get("error") or (
                f"PSNR {row['psnr']:.2f} ({row['gain']:+.2f}) dB, {row['seconds']:.1f} s"
                + (f", mismatch {row['blur_mismatch']:.3f}" if row.get("blur_mismatch") is not None else "")
            )
            print(f"    {m}: {msg}", file=sys.stderr)
        if name != names[-1]:  # a partial report after each case, in case the run is cut short
            write(rows, run, methods, skipped, args, env, output, final=False, n_done=names.index(name) + 1, n_all=len(names))

    write(rows, run, methods, skipped, args, env, output, final=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
