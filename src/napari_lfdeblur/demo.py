"""The main job on built-in data: what ``lfdeblur demo`` (and ``make demo``) runs.

For each built-in light field (the synthetic scene and the real Lytro crop)
it renders a motion blur along a known 3D camera path, then restores it twice:
with the path known (4D deconvolution) and blind (the path estimated too). It
writes the light fields, one figure per sample and a JSON summary.
"""

from __future__ import annotations

import json
from contextlib import contextmanager
import time
from pathlib import Path

import numpy as np

from . import __version__
from .blur import simulate_blur
from .path import bezier_positions, center_path

__all__ = ["DEMO_PATH", "run_demo"]

#: the demo's camera path: a curved motion with a small out-of-plane part,
#: in the zero-mean gauge, so the ground truth is the sharp light field itself
DEMO_PATH = center_path(np.array([[-1.2, -0.5, -0.25], [0.4, 1.1, 0.0], [1.1, -0.4, 0.25]]))
#: instants used to render the ground-truth blur (more than the solvers use)
RENDER_N_TIMES = 64
#: instants of the known-path restoration's model (deconvolve's default)
RESTORE_N_TIMES = 32
NOISE_SIGMA = 0.002
#: border pixels left out of PSNR
CROP = 8


def _samples(quick: bool):
    from .samples import LYTRO_ATTRIBUTION, lytro_sample, synthetic_scene

    if quick:
        syn, _ = synthetic_scene((5, 5, 40, 40), n_layers=3, color=True, seed=0)
        real = lytro_sample()[2:7, 2:7, 40:80, 40:80]
    else:
        syn, _ = synthetic_scene((9, 9, 128, 128), n_layers=3, color=True, seed=0)
        real = lytro_sample()
    return {
        "synthetic": (syn, "synthetic_scene(seed=0)"),
        "lytro": (real, LYTRO_ATTRIBUTION),
    }


def _figure(path, sharp, results, paths, title, notes=None):
    """Centre views and EPIs of the sharp light field and ``results``; ``paths`` (label -> (n, 3)) beside.

    ``notes``: a line under a result's panel title (name -> text).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .epi import horizontal_epi, vertical_epi

    V, U, Y, X = sharp.shape[:4]
    names = ["sharp", *results]
    arrays = [sharp, *results.values()]
    fig, axes = plt.subplots(3, len(names) + 1, figsize=(3.2 * (len(names) + 1), 8.2),
                             gridspec_kw={"height_ratios": [4, 1.2, 1.2]})
    for col, (name, lf) in enumerate(zip(names, arrays)):
        show = np.clip(lf, 0, 1)
        axes[0, col].imshow(show[V // 2, U // 2])
        axes[0, col].set_title(name + (f"\n{notes[name]}" if name in (notes or {}) else ""), fontsize=10)
        axes[1, col].imshow(horizontal_epi(show, V // 2, Y // 2), aspect="auto", interpolation="nearest")
        axes[2, col].imshow(vertical_epi(show, U // 2, X // 2), aspect="auto", interpolation="nearest")
        for r in range(3):
            axes[r, col].set_xticks([])
            axes[r, col].set_yticks([])
    axes[1, 0].set_ylabel("EPI (u, x)", fontsize=8)
    axes[2, 0].set_ylabel("EPI (v, y)", fontsize=8)
    # the camera path
    gs = axes[0, -1].get_gridspec()
    for r in range(3):
        axes[r, -1].remove()
    ax = fig.add_subplot(gs[:, -1])
    t = np.linspace(0, 1, 64)
    for (label, cp), style in zip(paths.items(), ("-", "--", ":")):
        pos = bezier_positions(cp, 64)
        for i, (comp, colour) in enumerate(zip(("p_x", "p_y", "p_z"), ("C0", "C1", "C2"))):
            ax.plot(t, pos[:, i], style, color=colour, label=f"{comp} {label}")
    ax.set_xlabel("t")
    ax.set_ylabel("position (views)")
    ax.set_title("camera path (zero-mean gauge)", fontsize=10)
    ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _blind_params(quick: bool):
    from .blind import BlindParams

    params = BlindParams.preset("default")
    return params.replace(path={"n_outer": 2, "n_restarts": 1, "n_levels": 1}, final={"n_iter": 10}) if quick else params


class _StepTimer:
    """Times the demo's steps of one sample into ``seconds`` and advances the progress bar."""

    def __init__(self, name, seconds, bar):
        self.name, self.seconds, self.bar = name, seconds, bar

    @contextmanager
    def __call__(self, step):
        if self.bar is not None:
            self.bar.set_postfix_str(f"{self.name}: {step}")
        t0 = time.perf_counter()
        yield
        self.seconds[step] = round(time.perf_counter() - t0, 2)
        if self.bar is not None:
            self.bar.update(1)


def _run_sample(name, sharp, out, rng, rec, timer, *, device, quick, blind) -> list:
    """Blur one sample, restore it (known path, then blind), record the figures; returns the files written."""
    from .deconvolution import deconvolve
    from .io import write_lightfield
    from .metrics import psnr, ssim

    files = []

    def save(kind, lf, cp, n_times):  # the light field and, beside it, the path it was blurred or restored with
        write_lightfield(out / f"{name}_{kind}.npz", lf, overwrite=True, control_points=cp,
                         metadata={"n_times": n_times, "infinity_disparity": 0.0})
        files.extend([f"{name}_{kind}.npz", f"{name}_{kind}.path.json"])

    with timer("blur"):
        blurred = simulate_blur(sharp, DEMO_PATH, n_times=RENDER_N_TIMES, device=device)
        blurred = np.clip(blurred + rng.normal(0, NOISE_SIGMA, blurred.shape), 0, 1).astype(np.float32)
        save("blurred", blurred, DEMO_PATH, RENDER_N_TIMES)
    results = {"blurred": blurred}
    with timer("deconvolve"):
        restored = deconvolve(blurred, DEMO_PATH, n_times=RESTORE_N_TIMES, device=device,
                              **({"n_iter": 30} if quick else {}))
        save("deconvolved", restored, DEMO_PATH, RESTORE_N_TIMES)
    results["deconvolved (path known)"] = restored
    paths, notes = {"true": DEMO_PATH}, {}
    if blind:
        from .blind import blind_deblur
        from .metrics import path_error

        with timer("blind"):
            res = blind_deblur(blurred, params=_blind_params(quick), device=device, seed=0)
            est_cp = res.control_points
            save("blind", res.lightfield, est_cp, res.params.final_n_times)
        results["blind"] = res.lightfield
        rec["blind_control_points"] = np.asarray(est_cp).tolist()
        rec["blind_path_error"] = path_error(est_cp, DEMO_PATH, lightfield=sharp).as_dict()
        rec["blind_blur_found"] = bool(res.info["blur_found"])
        rec["blind_message"] = res.info["message"]
        rec["blind_restoration"] = res.info["restoration"]
        paths["blind estimate"] = est_cp
        if "rejected_path" in res.info:  # little blur found: show the path estimated
            rejected = res.info["rejected_path"]
            rec["blind_rejected_path"] = np.asarray(rejected).tolist()
            rec["blind_rejected_path_error"] = path_error(rejected, DEMO_PATH, lightfield=sharp).as_dict()
            paths["rejected estimate"] = rejected
            light = res.info["restoration"] == "light"
            notes["blind"] = "(little blur found: a light restoration)" if light else "(little blur found: the input)"
    rec["psnr_db"] = {k: round(psnr(v, sharp, crop=CROP), 2) for k, v in results.items()}
    rec["ssim"] = {k: round(ssim(v, sharp, crop=CROP), 4) for k, v in results.items()}
    title = f"{name}: " + ", ".join(f"{k} {v:.1f} dB" for k, v in rec["psnr_db"].items())
    _figure(out / f"{name}.png", sharp, results, paths, title, notes)
    return files + [f"{name}.png"]


def run_demo(out_dir="demo_out", *, device="auto", quick: bool = False, blind: bool = True, progress=None):
    """Blur the built-in samples by a known path and restore them; write the results.

    Parameters
    ----------
    out_dir : str or Path
        Output folder, created if needed. The demo's own files in it (those
        its last run's ``summary.json`` lists) are replaced on every run, and
        those this run does not make (the blind results, after a run without
        them) are removed; nothing else in it is touched.
    device : {'auto', 'cpu', 'cuda'}
    quick : bool
        Small crops and few iterations (for tests).
    blind : bool
        Also run blind deblurring.
    progress : callable, optional
        A tqdm-like factory, called as ``progress(total=..., desc=...)``.

    Returns
    -------
    dict
        The summary also written to ``summary.json``.

    Raises
    ------
    FileExistsError
        When the folder holds a file of a name the demo writes that an
        earlier demo run did not write (before any work).
    ValueError
        When ``out_dir`` is an empty string (``"."`` names the current
        folder), as an unset shell variable gives.
    """
    from .devices import select_device

    if isinstance(out_dir, str) and not out_dir.strip():
        raise ValueError("the demo's output folder is an empty name: give a folder ('.' for the current one)")
    select_device(device)  # an unusable device: an error before the folder is made
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out} is a file; the demo writes into a folder")
    samples = _samples(quick)
    earlier = _earlier_files(out)
    every = {f"{name}_{kind}{ext}" for name in samples for kind in ("blurred", "deconvolved", "blind")
             for ext in (".npz", ".path.json")} | {f"{name}.png" for name in samples} | {"summary.json"}
    planned = {f for f in every if blind or "_blind." not in f}
    theirs = sorted(f for f in planned if (out / f).exists() and f not in earlier)
    if theirs:
        raise FileExistsError(f"{out / theirs[0]} exists and is not the demo's (no summary.json of a demo run lists "
                              "it): the demo replaces only its own files; choose another --out folder")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    summary = {
        "napari_lfdeblur_version": __version__,
        "true_control_points": DEMO_PATH.tolist(),
        "render_n_times": RENDER_N_TIMES,
        "noise_sigma": NOISE_SIGMA,
        "psnr_crop": CROP,
        "samples": {},
    }
    files = []
    bar = progress(total=len(samples) * (3 if blind else 2), desc="demo") if progress else None
    for name, (sharp, source) in samples.items():
        rec = summary["samples"][name] = {"source": source, "shape": list(sharp.shape), "seconds": {}}
        timer = _StepTimer(name, rec["seconds"], bar)
        files += _run_sample(name, sharp, out, rng, rec, timer, device=device, quick=quick, blind=blind)
    if bar is not None:
        bar.close()
    files.append("summary.json")
    summary["files"] = files
    summary["out_dir"] = str(out)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    for name in (earlier & every) - set(files):  # an earlier run's results that this run did not make: stale
        (out / name).unlink(missing_ok=True)
    return summary


def _earlier_files(out: Path) -> set:
    """The files an earlier demo run wrote in ``out`` (its ``summary.json`` lists them); empty when there was none."""
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError):
        return set()
    if not (isinstance(summary, dict) and "true_control_points" in summary and isinstance(summary.get("files"), list)):
        return set()
    return {f for f in summary["files"] if isinstance(f, str) and Path(f).name == f}  # names in the folder only
