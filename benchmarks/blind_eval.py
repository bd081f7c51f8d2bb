"""Evaluate blind light-field deblurring against ground truth, on a development or a test split.

The cases (``benchmarks/eval_set.py``): rendered scenes of natural textures at random depths
(``procedural_scene``), crops of a Lytro F01 capture (one plane) and of a Lytro Illum capture
(depth range), at infinity disparities ``d_inf`` in {0, ±0.5, ±1, 2}, blurred by hidden paths
from none through barely there (0.3 view) to 4 views, most with ``p_z != 0``, noise sigma 0.002
or 0.01. ``dev`` is for development; ``test`` is run after the method is frozen
(``--frozen`` says so in the table).

Methods
-------
- ``default`` and ``paper``: ``blind_deblur`` with those presets, given the blurred light field and
  the true ``d_inf`` (skipped, and marked so, when ``napari_lfdeblur.blind`` cannot be imported);
- ``strict``: the ``default`` preset with ``light_restoration=0``: the input wherever the
  salient-edge test finds little blur;
- ``truepath``: non-blind ``deconvolve`` with the true path (zero-mean gauge for T = 32), the true
  ``d_inf``, ``T = 32`` and default parameters: the target a blind method can approach;
- ``baseline2d``: every view deblurred on its own by the L0-gradient 2D blind deconvolution of
  ``benchmarks/_baseline2d.py`` (no path estimate);
- ``views`` and ``truepath_views``: ``default`` and ``truepath`` with the final solve's TV isotropic
  and its angular differences between the same pixel of neighbouring views (``VIEWS_TV``; the
  default TV is anisotropic, along the scene's disparity).

Metrics (``napari_lfdeblur.metrics``), spatial borders of ``CROP`` px removed: PSNR and its gain
over the blurred input, SSIM, angular error, and for path estimates the blur mismatch, Chamfer
distance and relative RMSE. Each case's *blur length* (``eval_set.blur_length``: how far the true blur
moves the scene, px) groups the cases a second time, beside the blur lengths of the paths estimated
and restored with. Time is the wall-clock time of the method call (each method has run once before,
unrecorded, on a tiny case, so that no case is timed with the fused loops' compilation); peak memory the peak
resident set size above the level before the call (sampled every 10 ms), or
``torch.cuda.max_memory_allocated`` on a GPU.

Usage::

    python benchmarks/blind_eval.py --split dev --methods default,truepath   # docs/benchmarks/blind_eval_dev.md
    python benchmarks/blind_eval.py --split test --frozen                    # once, after freezing the method
    python benchmarks/blind_eval.py --quick --methods truepath               # tiny smoke run, writes nothing
    python benchmarks/blind_eval.py --split dev --cases dev03,dev09 --out /tmp/eval.md
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import threading
import time
import traceback
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)
import eval_set  # noqa: E402  (benchmarks/eval_set.py)

ROOT = _report.ROOT
RENDER_TIMES = eval_set.RENDER_TIMES
SOLVE_TIMES = 32  # instants of the truepath method's model
CROP = 8  # border pixels removed before PSNR / SSIM / angular error
PATH_TIMES = 64  # instants for the path errors
DEFAULT_METHODS = ("default", "paper", "truepath")
ALL_METHODS = ("default", "strict", "paper", "truepath", "baseline2d", "views", "truepath_views")
#: the final solve of the methods ``views`` and ``truepath_views`` (lfdeblur deconvolve --along-views)
VIEWS_TV = {"angular": "views", "isotropic": True}
#: ``strict``: the default preset returning the input wherever the salient-edge test finds little blur
STRICT_LIGHT_RESTORATION = 0.0
INPUT = "input (blurred)"
#: how many cases a quick run takes: the first rendered case at d_inf != 0 and the first of each real group
QUICK_CASES = 3


def table_for(split: str) -> Path:
    """``docs/benchmarks/blind_eval_<split>.md``: where a run on ``split`` writes its table."""
    return _report.TABLES / f"blind_eval_{split}.md"


# ------------------------------------------------------------------ cases


@dataclass
class Case:
    spec: eval_set.CaseSpec
    sharp: np.ndarray  # ground truth, zero-mean gauge
    blurred: np.ndarray
    control_points: np.ndarray  # true path, zero-mean gauge for RENDER_TIMES
    disparity: np.ndarray  # (Y, X) of the centre view: eval_set.scene_disparity
    blur_px: float  # eval_set.blur_length of the true path

    def blur_px_of(self, cp) -> float:
        """eval_set.blur_length of a path on this case's scene."""
        return eval_set.blur_length(cp, self.sharp, self.disparity, self.infinity_disparity)

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def infinity_disparity(self) -> float:
        return self.spec.infinity_disparity


def dev_study_parser(doc: str) -> argparse.ArgumentParser:
    """A parser with the arguments of the studies in ``benchmarks/dev/`` on the development split:
    ``--cases`` (comma-separated names, default all) and ``--threads`` (torch's, default 2)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--cases", default="", help="comma-separated case names (default: the whole dev split)")
    ap.add_argument("--threads", type=int, default=2)
    return ap


def dev_study_cases(args) -> list:
    """Set torch's threads to ``args.threads``; return the development cases ``args.cases`` names."""
    import torch

    torch.set_num_threads(args.threads)
    return select_cases("dev", [n for n in args.cases.split(",") if n] or None)[0]


def make_case(spec: eval_set.CaseSpec, quick: bool = False) -> Case:
    """Render a case: its sharp light field, true path and blurred, noisy input."""
    sharp = eval_set.sharp_lightfield(spec, quick)
    cp = eval_set.true_path(spec)
    disparity = eval_set.scene_disparity(spec, sharp)
    return Case(spec, sharp, eval_set.blurred_lightfield(spec, sharp, cp), cp, disparity,
                eval_set.blur_length(cp, sharp, disparity, spec.infinity_disparity))


def path_spread(cp, n_times: int = 128) -> float:
    """RMS distance (views) of a path's in-plane positions from their mean, over ``n_times`` instants."""
    from napari_lfdeblur.path import bezier_positions

    pos = bezier_positions(np.asarray(cp, dtype=np.float64)[:, :3], n_times)[:, :2]
    return float(np.sqrt(((pos - pos.mean(axis=0)) ** 2).sum(axis=1).mean()))


def select_cases(split: str, names=None, quick: bool = False):
    """The cases to run and the ones skipped (name -> why): a real capture may be missing."""
    specs = list(eval_set.split_cases(split))
    if names:
        known = {s.name: s for s in specs}
        bad = [n for n in names if n not in known]
        if bad:
            raise ValueError(f"unknown case(s) {bad} in split {split!r}: {sorted(known)}")
        specs = [known[n] for n in names]
    elif quick:  # one case of each group, blurred, the rendered one at d_inf != 0
        specs = [next(s for s in specs if s.group == g and s.kind == "blurred"
                      and (g != "rendered" or s.infinity_disparity != 0)) for g in eval_set.GROUPS]
    missing = {s.name: f"the {s.group} capture is not on this machine" for s in specs
               if not eval_set.capture_available(s.group)}
    return [s for s in specs if s.name not in missing], missing


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
    def base(self) -> int:
        """The level on entry, bytes."""
        return self._base

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
    if method in ("baseline2d", "truepath", "truepath_views"):
        return True, ""
    try:
        from napari_lfdeblur import blind

        _blind_params(blind, "default" if method in ("strict", "views") else method)
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
    if method in ("truepath", "truepath_views"):
        from napari_lfdeblur import deconvolve
        from napari_lfdeblur.path import center_path

        cp = center_path(case.control_points, SOLVE_TIMES)
        restored = deconvolve(case.blurred, cp, n_times=SOLVE_TIMES, infinity_disparity=case.infinity_disparity,
                              device=device, **(VIEWS_TV if method == "truepath_views" else {}))
        return restored, None, {}
    from napari_lfdeblur import blind

    params = _blind_params(blind, "default" if method in ("strict", "views") else method)
    if method == "strict":
        params = params.replace(light_restoration=STRICT_LIGHT_RESTORATION)
    if method == "views":
        params = params.replace(final=VIEWS_TV)
    res = blind.blind_deblur(case.blurred, infinity_disparity=case.infinity_disparity, params=params,
                             device=device, seed=0)
    info = {}
    timings = getattr(res, "timings", None)
    if isinstance(timings, dict):
        info["timings"] = {k: float(v) for k, v in timings.items() if isinstance(v, (int, float))}
    extra = getattr(res, "info", None)
    if isinstance(extra, dict):
        info["info"] = {k: v for k, v in extra.items() if isinstance(v, (int, float, str, bool))}
        # the path estimated, also where the evidence test returned the input or restored lightly
        info["estimate"] = extra.get("rejected_path")
    if info.get("estimate") is None:
        info["estimate"] = res.control_points
    return np.asarray(res.lightfield), np.asarray(res.control_points), info


def _case_fields(case: Case) -> dict:
    s = case.spec
    return {"case": s.name, "group": s.group, "d_inf": s.infinity_disparity, "extent": s.extent,
            "z_ratio": s.z_ratio, "noise": s.noise, "blur_px": case.blur_px}


def evaluate(case: Case, method: str, device: str, quick: bool) -> dict:
    from napari_lfdeblur.metrics import angular_error, path_error, psnr, ssim

    with PeakMemory(device) as mem:
        t0 = time.perf_counter()
        restored, cp, info = run_method(method, case, device, quick)
        seconds = time.perf_counter() - t0
    estimate = info.pop("estimate", None)
    crop = 2 if quick else CROP
    row = {
        **_case_fields(case),
        "method": method,
        "psnr": psnr(restored, case.sharp, crop=crop),
        "ssim": ssim(restored, case.sharp, crop=crop),
        "angular": angular_error(restored, case.sharp, crop=crop),
        "seconds": seconds,
        "peak_mib": mem.delta_mib,
        **info,
    }
    if cp is not None:
        err = path_error(cp, case.control_points, n_times=PATH_TIMES, lightfield=case.sharp,
                         infinity_disparity=case.infinity_disparity)
        # no true blur: the mismatch is undefined (NaN); the estimate's extent says how much blur was found
        row.update(blur_mismatch=err.blur_mismatch, chamfer=err.chamfer, rmse_relative=err.rmse_relative,
                   found_extent=path_error(cp, np.zeros((2, 3)), n_times=PATH_TIMES).chamfer,
                   restored_blur_px=case.blur_px_of(cp), estimate_blur_px=case.blur_px_of(estimate),
                   control_points=np.asarray(cp).tolist())
    return row


def input_row(case: Case, quick: bool) -> dict:
    from napari_lfdeblur.deconvolution import estimate_noise_sigma
    from napari_lfdeblur.metrics import angular_error, path_error, psnr, ssim

    crop = 2 if quick else CROP
    # the blurred input is the estimate "no motion": its path error is that of the zero path
    err = path_error(np.zeros((2, 3)), case.control_points, n_times=PATH_TIMES, lightfield=case.sharp,
                     infinity_disparity=case.infinity_disparity)
    return {
        **_case_fields(case),
        "method": INPUT,
        "psnr": psnr(case.blurred, case.sharp, crop=crop),
        "ssim": ssim(case.blurred, case.sharp, crop=crop),
        "angular": angular_error(case.blurred, case.sharp, crop=crop),
        "blur_mismatch": err.blur_mismatch,
        "chamfer": err.chamfer,
        "rmse_relative": err.rmse_relative,
        "restored_blur_px": 0.0,
        "reference_sigma": estimate_noise_sigma(case.sharp),  # the ground truth's finest detail
    }


# ----------------------------------------------------------------- report


def _fmt(value, spec):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    return format(value, spec)


def _finite(rows, key):
    return [r[key] for r in rows if isinstance(r.get(key), (int, float)) and not math.isnan(r[key])]


def _mean(rows, key):
    vals = _finite(rows, key)
    return float(np.mean(vals)) if vals else None


#: summary groups: label -> which rows
SUMMARY_GROUPS = {
    "all": lambda r: True,
    **{g: (lambda r, g=g: r.get("group") == g) for g in eval_set.GROUPS},
    "d_inf = 0": lambda r: r.get("d_inf") == 0,
    "d_inf ≠ 0": lambda r: r.get("d_inf") not in (None, 0),
}


#: blur-length groups (``eval_set.blur_length`` of the true path, px): label -> which rows
BLUR_GROUPS = {
    "no blur or < 1 px": lambda r: r.get("blur_px", math.nan) < 1.0,
    "1 to 2 px": lambda r: 1.0 <= r.get("blur_px", math.nan) < 2.0,
    "≥ 2 px": lambda r: r.get("blur_px", math.nan) >= 2.0,
}


def _length_ratio(rows, key: str = "restored_blur_px") -> float | None:
    """Median over the blurred cases of a path's blur length (``key``) over the true path's."""
    ratios = [r[key] / r["blur_px"] for r in rows if r.get("blur_px", 0) > 0 and r.get(key) is not None]
    return float(np.median(ratios)) if ratios else None


def summarise(rows: list[dict], methods: list[str], groups=None) -> list[dict]:
    """Per group (``SUMMARY_GROUPS`` unless given) and method: means over the cases it ran on, the worst
    gain, the slowest time, the median blur-length ratio."""
    out = []
    blurred = {r["case"]: r.get("psnr") for r in rows if r["method"] == INPUT}
    for label, keep in (groups or SUMMARY_GROUPS).items():
        for method in methods:
            sel = [r for r in rows if r["method"] == method and "error" not in r and keep(r)]
            if not sel:
                continue
            gains = [(r["gain"], r["case"]) for r in sel if isinstance(r.get("gain"), (int, float))]
            worst = min(gains) if gains else (None, None)
            out.append({
                "group": label, "method": method, "n": len(sel),
                "blurred_psnr": _mean([{"v": blurred.get(r["case"])} for r in sel], "v"),
                **{k: _mean(sel, k) for k in ("psnr", "gain", "ssim", "angular", "blur_mismatch", "seconds",
                                               "peak_mib")},
                "worst_gain": worst[0], "worst_case": worst[1],
                "seconds_max": max(_finite(sel, "seconds"), default=None),
                "length_ratio": _length_ratio(sel), "estimate_ratio": _length_ratio(sel, "estimate_blur_px"),
            })
    return out


def _table(head: str, means: list[dict], cells) -> list[str]:
    """A markdown table: ``head``, then one row of ``cells(m)`` per group mean ``m``."""
    return [head, "|" + "---|" * (head.count("|") - 1), *("| " + " | ".join(cells(m)) + " |" for m in means)]


def _worst(m: dict) -> str:
    return _fmt(m["worst_gain"], "+.2f") + (f" ({m['worst_case']})" if m["worst_case"] else "")


def _summary_table(means: list[dict]) -> list[str]:
    head = ("| group | method | cases | blurred PSNR dB | PSNR dB | gain dB | worst gain dB (case) | blur mismatch "
            "| SSIM | time s (mean / max) |")
    return _table(head, means, lambda m: [
        m["group"], m["method"], str(m["n"]), _fmt(m["blurred_psnr"], ".2f"), _fmt(m["psnr"], ".2f"),
        _fmt(m["gain"], "+.2f"), _worst(m), _fmt(m["blur_mismatch"], ".3f"), _fmt(m["ssim"], ".4f"),
        f"{_fmt(m['seconds'], '.1f')} / {_fmt(m['seconds_max'], '.1f')}"])


def _blur_table(means: list[dict]) -> list[str]:
    head = ("| true blur length | method | cases | blurred PSNR dB | gain dB | worst gain dB (case) | blur mismatch "
            "| blur length / true (median): restored with | estimated |")
    return _table(head, means, lambda m: [
        m["group"], m["method"], str(m["n"]), _fmt(m["blurred_psnr"], ".2f"), _fmt(m["gain"], "+.2f"), _worst(m),
        _fmt(m["blur_mismatch"], ".3f"), _fmt(m["length_ratio"], ".2f"), _fmt(m["estimate_ratio"], ".2f")])


def _case_table(rows: list[dict]) -> list[str]:
    head = ("| case | group | d_inf | extent | noise | method | PSNR dB | gain dB | SSIM | angular err "
            "| blur mismatch | Chamfer (views) | blur length px (restored / estimated / true) | time s | peak MiB |")
    out = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        out.append("| " + " | ".join([
            r["case"], r.get("group", ""), _fmt(r.get("d_inf"), "+g"), _fmt(r.get("extent"), ".2f"),
            _fmt(r.get("noise"), "g"), r["method"], _fmt(r.get("psnr"), ".2f"), _fmt(r.get("gain"), "+.2f"),
            _fmt(r.get("ssim"), ".4f"), _fmt(r.get("angular"), ".5f"), _fmt(r.get("blur_mismatch"), ".3f"),
            _fmt(r.get("chamfer"), ".3f"),
            f"{_fmt(r.get('restored_blur_px'), '.2f')} / {_fmt(r.get('estimate_blur_px'), '.2f')} / "
            f"{_fmt(r.get('blur_px'), '.2f')}",
            _fmt(r.get("seconds"), ".1f"), _fmt(r.get("peak_mib"), ".0f"),
        ]) + " |")
    return out


def _cases_table(specs, rows) -> list[str]:
    ref = {r["case"]: r.get("reference_sigma") for r in rows if r["method"] == INPUT}
    blur = {r["case"]: r.get("blur_px") for r in rows if r["method"] == INPUT}
    out = ["| case | group | scene | d_inf | path extent (views) | z ratio | control points | blur length px "
           "| noise σ | σ estimated in the ground truth |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for s in specs:
        out.append(f"| {s.name} | {s.group} | {eval_set.describe(s)} | {s.infinity_disparity:+g} | {s.extent:.2f} "
                   f"| {s.z_ratio:.2f} | {s.n_points} | {_fmt(blur.get(s.name), '.2f')} | {s.noise:g} "
                   f"| {_fmt(ref.get(s.name), '.4f')} |")
    return out


def targets(means: list[dict], quick: bool) -> list[str]:
    """The issue's CPU targets, checked against the measured figures (never assumed)."""
    by = {(m["group"], m["method"]): m for m in means}
    lines = []

    def check(ok, text):
        lines.append(f"- {'met' if ok else '**not met**'}: {text}")

    for method in ("default", "strict", "paper", "views"):
        if (("all", method)) not in by:
            continue
        for group in ("all", "d_inf ≠ 0", "Illum"):
            m = by.get((group, method))
            if m is None:
                continue
            if m["gain"] is not None:
                check(m["gain"] >= 4.0, f"`{method}`, {group}: mean gain ≥ +4 dB ({m['gain']:+.2f} dB)")
            if m["blur_mismatch"] is not None:
                check(m["blur_mismatch"] <= 0.25,
                      f"`{method}`, {group}: mean blur mismatch ≤ 0.25 ({m['blur_mismatch']:.3f})")
        m = by[("all", method)]
        if m["worst_gain"] is not None:
            check(m["worst_gain"] >= -0.1, f"`{method}`: no case worse than the input by more than 0.1 dB "
                                           f"(worst {m['worst_gain']:+.2f} dB, {m['worst_case']})")
        if m["seconds_max"] is not None:
            check(m["seconds_max"] <= 60, f"`{method}`: ≤ 60 s per light field (slowest {m['seconds_max']:.1f} s)")
    m = by.get(("d_inf ≠ 0", "truepath"))
    if m is not None and m["gain"] is not None:
        check(m["gain"] >= 6.0, f"`truepath`, d_inf ≠ 0: mean gain ≥ +6 dB ({m['gain']:+.2f} dB)")
    m = by.get(("all", "truepath"))
    if m is not None and m["seconds_max"] is not None:
        check(m["seconds_max"] <= 10, f"`truepath`: ≤ 10 s per light field (slowest {m['seconds_max']:.1f} s)")
    if not lines:
        lines.append("- no method with a target ran")
    if quick:
        lines.append("- (quick run: tiny sizes, the targets do not apply)")
    return lines


def split_line(split: str, frozen: bool) -> str:
    """What the split is, and for the test split whether the method was frozen before it ran."""
    if split == "dev":
        return ("**Development split** (`dev`): the cases a method may be developed and tuned on. "
                "The held-out figures are those of the test split.")
    if frozen:
        return ("**Test split** (`test`), run after the method was frozen: no parameter was chosen "
                "on these cases.")
    return ("**Test split** (`test`), **not marked frozen** (no `--frozen`): these figures are not the "
            "held-out report.")


BLUR_TEXT = """\
The cases grouped by how far their true blur moves the scene (*blur length*: the length of the straight,
uniform motion with the same RMS image motion, on the textured pixels of the centre view; see *How the
figures are made*). The last two columns compare blur lengths with the true one (1 is right, above 1 too
long; the median over the group's blurred cases): of the path each method restored with (0 where it returned
the input; the light restoration's path is the estimate scaled down), and of the path it estimated, whatever
the evidence test then decided."""


METHOD_TEXT = """\
## How the figures are made

- **Cases** (`benchmarks/eval_set.py`, fixed by the split's seed; the case list above). `rendered`:
  `procedural_scene(seed=...)`, natural textures (crops of `skimage.data` images at random scale and
  angle, some dark, some low in contrast, some fine) on 3 to 6 planes at random depths with
  occlusions, rendered with the case's `d_inf`: every point is nearer than infinity (disparity
  `d_inf + δ`, 0 < δ ≤ 1.5 px/view). `F01`: 128×128 crops of a first-generation Lytro capture (one
  dominant plane, about 0.6 px/view), views 2..10. `Illum`: 128×128 crops of a Lytro Illum capture
  with depth range (about −0.4 to −0.9 px/view), away from its black corners. A real capture is the
  sharp light field as it is, so its content's disparities may lie on either side of the case's
  `d_inf`. All 9×9×128×128×3.
- **Blur.** A hidden Bézier path (3 to 5 control points, most with `p_z ≠ 0`) scaled to its extent
  (largest distance between two positions, z included, in views): 0 (no blur), 0.3 to 0.4
  (barely there) or 0.5 to 4 views; rendered with **T = 128** instants and the case's `d_inf`, plus
  Gaussian noise σ = 0.002 or 0.01 (seeded), clipped to [0, 1]. The true path is in the zero-mean
  gauge for T = 128, so the ground truth is the sharp light field (docs/model.md, "Gauge").
- **Methods.** `default`, `paper`: `blind_deblur` with those presets, given the blurred light field
  and the true `d_inf`. `strict`: the `default` preset with `light_restoration={strict:g}`: the input
  wherever the salient-edge test finds little blur (no light restoration). `truepath`: non-blind
  `deconvolve` with the true path (zero-mean gauge for T = 32), the true `d_inf`, T = 32 and default
  parameters. `baseline2d`: each view deblurred on its own by a compact L0-gradient 2D blind
  deconvolution (`benchmarks/_baseline2d.py`). `views`, `truepath_views`: `default` and `truepath`
  with the final solve's TV isotropic and its angular differences between the same pixel of
  neighbouring views (`deconvolve(angular="views", isotropic=True)`; the default TV is anisotropic,
  along the scene's disparity: docs/deconvolution.md, *Angular differences*).
- **Image metrics** (`napari_lfdeblur.metrics`), {crop} border pixels cropped in y and x: PSNR over
  all views and channels, and the gain over the blurred input's; the worst gain is the smallest over
  the group's cases; SSIM (mean over views and channels); angular error (RMSE of the differences
  between neighbouring views).
- **Path metrics**, both paths sampled at 64 instants and moved to zero mean: **blur mismatch**
  `||B(l, p_est) - B(l, p_true)|| / ||B(l, p_true) - l||` on the ground truth with the case's
  `d_inf` (0 is perfect, 1 is as bad as "no motion"; undefined without blur); **Chamfer** distance
  between the two sets of positions, in views. The input row is "no motion" (the zero path).
- **Blur length** (`eval_set.blur_length`): a point at disparity `d` moves by `(d - d_inf) s` px
  when the camera moves by `s` views, `s = (p_x - x~ p_z, p_y - y~ p_z)` at its pixel. Its RMS motion
  over the exposure, averaged (root mean square) over the centre view's pixels weighted by the
  squared gradient of its grayscale (a flat region's motion does not show), times √12: a straight
  uniform motion of length `L` has RMS `L / √12`. Disparities: the renderer's map for rendered
  scenes; for the captures, estimated from the views (the shear that makes them agree best).
- **Fine detail in the ground truth.** The last column of the case list applies the noise estimate
  behind the default TV weight (`napari_lfdeblur.deconvolution.estimate_noise_sigma`) to the sharp
  light field itself: it measures the finest-scale detail there, which is sensor noise in a real
  capture (a real capture is its own ground truth, noise included) and fine texture in a rendered
  scene. Where
  it exceeds the added noise, a restoration that smooths at that scale (the TV prior
  does) moves away from the reference, so even `truepath` can score below the input on cases with
  little blur: the PSNR then counts the detail removed as well as the blur undone.
- **Time**: wall-clock time of the method call, after one unrecorded call of each method on a tiny
  case (which compiles the fused loops not yet cached). **Peak memory**: peak resident set size above the
  level before the call, sampled every 10 ms (CPU), or `torch.cuda.max_memory_allocated` (GPU).
"""


def render(rows, means, specs, skipped, args, env) -> str:
    lines = [f"# Blind deblurring: evaluation against ground truth, {args.split} split", "",
             f"Command: `{env['command']}`", "", f"Machine: {env['machine']}", "",
             split_line(args.split, args.frozen), ""]
    if args.quick:
        lines += ["**Quick smoke run at tiny sizes: not the benchmark.**", ""]
    lines += ["## Summary", "", "Means over the cases of each group; gains are over the blurred input.", "",
              *_summary_table(means), "", "## Targets (CPU)", "", *targets(means, args.quick), ""]
    methods = list(dict.fromkeys(m["method"] for m in means))
    lines += ["## By blur length", "", BLUR_TEXT, "", *_blur_table(summarise(rows, methods, BLUR_GROUPS)), ""]
    notes = [f"- `{m}`: skipped, {why}" for m, why in skipped.items()]
    notes += [f"- `{m}`: not run (not in `--methods`)." for m in ALL_METHODS if m not in args.method_list]
    notes += [f"- {note}" for note in args.note]
    if notes:
        lines += ["## Skipped and notes", "", *notes, ""]
    errors = [r for r in rows if "error" in r]
    if errors:
        lines += ["## Failures", "", *[f"- `{r['method']}` on `{r['case']}`: {r['error']}" for r in errors], ""]
    methods = METHOD_TEXT.format(crop=2 if args.quick else CROP, strict=STRICT_LIGHT_RESTORATION)
    lines += ["## Cases", "", *_cases_table(specs, rows), "", "## Per case", "",
              *_case_table([r for r in rows if "error" not in r]), "", methods]
    return "\n".join(lines)


# ------------------------------------------------------------------- main


def write(rows, run, specs, skipped, args, env, output, *, final, n_done=0, n_all=0):
    """Render the report; print and write it (and the JSON) when final, only write it when partial."""
    means = summarise(rows, run)
    text = render(rows, means, specs, skipped, args, env)
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
        Path(args.json).write_text(json.dumps(
            {"env": env, "split": args.split, "frozen": args.frozen, "cases": [asdict(s) for s in specs],
             "rows": rows, "means": means, "skipped": skipped, "final": final}, indent=1))


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--split", choices=sorted(eval_set.SPLITS), default="dev", help="the cases (default dev)")
    ap.add_argument("--frozen", action="store_true",
                    help="say in the table that the method was frozen before this run (the test split)")
    ap.add_argument("--quick", action="store_true", help="tiny sizes, one case per group: a smoke run")
    ap.add_argument("--cases", help="comma-separated case names of the split, e.g. dev03,dev09 (default: all)")
    ap.add_argument("--methods", default=",".join(DEFAULT_METHODS), help=f"comma-separated, from {ALL_METHODS}")
    ap.add_argument("--device", default="cpu", help="cpu, cuda or auto (default cpu)")
    ap.add_argument("--out", "--output", type=Path, default=None, metavar="PATH",
                    help="markdown file for the table (default docs/benchmarks/blind_eval_<split>.md; "
                         "none for a quick run)")
    ap.add_argument("--json", help="also write every row as JSON here")
    ap.add_argument("--note", action="append", default=[], help="a line of text for the report; repeatable")
    args = ap.parse_args(argv)
    args.method_list = [m.strip() for m in args.methods.split(",") if m.strip()]
    bad = [m for m in args.method_list if m not in ALL_METHODS]
    if bad:
        ap.error(f"unknown method(s) {bad}; choose from {ALL_METHODS}")
    if args.split == "dev" and args.frozen:
        ap.error("--frozen is for the test split")
    return args


def run_case(spec, run, device, quick) -> list[dict]:
    case = make_case(spec, quick=quick)
    inp = input_row(case, quick)
    rows = [inp]
    print(f"[case] {spec.name} ({spec.group}, d_inf {spec.infinity_disparity:+g}, extent {spec.extent:.2f}, "
          f"noise {spec.noise:g}): input PSNR {inp['psnr']:.2f} dB", file=sys.stderr)
    for m in run:
        try:
            row = evaluate(case, m, device, quick)
            row["gain"] = row["psnr"] - inp["psnr"]
        except Exception as exc:  # noqa: BLE001 - a failure is reported, never hidden
            traceback.print_exc()
            row = {**_case_fields(case), "method": m, "error": f"{type(exc).__name__}: {exc}"}
        rows.append(row)
        msg = row.get("error") or (
            f"PSNR {row['psnr']:.2f} ({row['gain']:+.2f}) dB, {row['seconds']:.1f} s"
            + (f", mismatch {row['blur_mismatch']:.3f}" if row.get("blur_mismatch") is not None else ""))
        print(f"    {m}: {msg}", file=sys.stderr)
    return rows


def warm_up(run, spec, device) -> None:
    """Run each method once, unrecorded, on a tiny version of ``spec``: the first call in a process compiles
    the fused loops that are not yet in numba's disk cache, which would otherwise be timed with the first case."""
    case = make_case(spec, quick=True)
    for m in run:
        try:
            run_method(m, case, device, True)
        except Exception:  # noqa: BLE001 - the timed run reports it
            pass


def main(argv=None) -> int:
    args = parse_args(argv)
    names = [c.strip() for c in args.cases.split(",") if c.strip()] if args.cases else None
    try:
        specs, missing = select_cases(args.split, names, args.quick)
    except ValueError as exc:  # an unknown case name
        print(f"blind_eval.py: error: {exc}", file=sys.stderr)
        return 2
    output = args.out if args.out is not None else (None if args.quick else table_for(args.split))

    import torch

    from napari_lfdeblur.devices import select_device

    device = str(select_device(args.device))
    env = {"machine": _report.machine(device), "device": device, "torch": torch.__version__,
           "threads": torch.get_num_threads(), "command": _report.command_line(__file__, argv)}
    skipped = {}
    for m in args.method_list:
        ok, why = method_available(m)
        if not ok:
            skipped[m] = why
            print(f"[skip] {m}: {why}", file=sys.stderr)
    args.note = [*args.note, *(f"case `{n}` skipped: {why}." for n, why in missing.items())]
    run = [m for m in args.method_list if m not in skipped]

    if specs and not args.quick:
        warm_up(run, specs[0], device)
    rows = []
    for k, spec in enumerate(specs):
        rows += run_case(spec, run, device, args.quick)
        if k + 1 < len(specs):  # a partial report after each case, in case the run is cut short
            write(rows, run, specs, skipped, args, env, output, final=False, n_done=k + 1, n_all=len(specs))
    write(rows, run, specs, skipped, args, env, output, final=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
