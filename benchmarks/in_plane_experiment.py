"""The paper's in-plane experiment: 4D deconvolution versus 2D deconvolution as blur grows.

With in-plane camera motion (``p_z = 0``, ``d_inf = 0``) the blurred light
field is a convolution of the sharp one along ``(u, v)`` only, the same at
every pixel whatever the scene's depth. A known path can therefore be undone
exactly in 4D (``deconvolve(..., method='inplane')``). A conventional camera
sees one view; its motion blur is a 2D blur whose length scales with each
point's disparity, so a 2D deconvolution with the PSF of a single depth is
wrong everywhere else, and more so the longer the blur.

For each blur length ``L`` (views) of a linear in-plane path at 30 degrees:

- blur the sharp light field (the forward model of docs/model.md, T = 32), add Gaussian
  noise (sigma = 0.005, seeded), or none;
- **4D**: ``deconvolve(method='inplane')``, the exact per-pixel solve
  (weight 0 without noise);
- **2D**: ``skimage.restoration.wiener`` of the centre view (each colour
  channel) with the centre view's PSF for one disparity (``inplane_psf``):
  the ground-truth median disparity of the synthetic scene, and for the Lytro
  capture the disparity whose refocused image is sharpest;
- each method gets the best of a small grid of regularisation weights
  (an oracle choice, the same courtesy for both);
- with ``--tv``, also ``deconvolve(method='tv')`` (4D TV, one weight, 30
  iterations started from the in-plane solve) at a few lengths;
- score: RMSE of the centre view against the sharp centre view, borders of
  ``CROP`` px removed.

Usage::

    python benchmarks/in_plane_experiment.py --tv       # writes docs/images/in_plane_experiment.png
                                                         # and docs/benchmarks/in_plane_experiment.md
    python benchmarks/in_plane_experiment.py            # the same without the 4D TV runs
    python benchmarks/in_plane_experiment.py --quick    # small smoke run, writes nothing (or the table to --out)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from skimage import restoration

from napari_lfdeblur import deconvolve, linear_path, lytro_sample, refocus, simulate_blur, synthetic_scene
from napari_lfdeblur.special_cases import inplane_psf

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)

ROOT = Path(__file__).resolve().parents[1]
LENGTHS = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0)
NOISE = 0.005
CROP = 8
WEIGHTS_4D = (1e-3, 3e-3, 1e-2, 3e-2)
BALANCES_2D = (0.003, 0.01, 0.03, 0.1)
TV_LENGTHS = (1.0, 2.0, 4.0)
TV_WEIGHT = 3e-3
TV_ITERATIONS = 30


def _rmse(a, b):
    a = np.asarray(a, np.float64)[CROP:-CROP, CROP:-CROP]
    b = np.asarray(b, np.float64)[CROP:-CROP, CROP:-CROP]
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _sharpest_disparity(lf):
    from scipy import ndimage

    best, best_d = -1.0, 0.0
    for d in np.linspace(-2.0, 2.0, 81):
        img = refocus(lf, float(d))
        g = img.mean(-1) if img.ndim == 3 else img
        e = float(np.mean((g - ndimage.gaussian_filter(g, 1.5)) ** 2))
        if e > best:
            best, best_d = e, float(d)
    return best_d


def _wiener(view, psf, balance):
    if view.ndim == 2:
        return restoration.wiener(view.astype(np.float64), psf, balance)
    return np.stack([restoration.wiener(view[..., c].astype(np.float64), psf, balance)
                     for c in range(view.shape[-1])], axis=-1)


def run_case(name, lf, disparity, lengths, seed=0, tv=True):
    V, U = lf.shape[:2]
    c = ((V - 1) // 2, (U - 1) // 2)
    truth = lf[c]
    rng = np.random.default_rng(seed)
    rows = []
    for length in lengths:
        cp = linear_path(length, angle_deg=30.0)
        clean = simulate_blur(lf, cp, n_times=32)
        psf = inplane_psf(cp, disparity)
        r = {"case": name, "length": length, "blurred": _rmse(clean[c], truth)}
        # noise-free: the exact inverse in 4D; the best a single-depth PSF allows in 2D
        r["rmse_4d_clean"] = _rmse(deconvolve(clean, cp, method="inplane", weight=0.0)[c], truth)
        r["rmse_2d_clean"] = min(_rmse(_wiener(clean[c], psf, b), truth) for b in (1e-4, 1e-3) + BALANCES_2D)
        noisy = clean + rng.normal(0.0, NOISE, clean.shape).astype(np.float32)
        r["blurred_noisy"] = _rmse(noisy[c], truth)
        t0 = time.perf_counter()
        r["rmse_4d"], r["weight_4d"] = min(
            (_rmse(deconvolve(noisy, cp, method="inplane", weight=w)[c], truth), w) for w in WEIGHTS_4D
        )
        r["time_4d"] = (time.perf_counter() - t0) / len(WEIGHTS_4D)
        r["rmse_2d"], r["balance_2d"] = min((_rmse(_wiener(noisy[c], psf, b), truth), b) for b in BALANCES_2D)
        if tv and length in TV_LENGTHS:
            x0 = deconvolve(noisy, cp, method="inplane", weight=r["weight_4d"])
            t0 = time.perf_counter()
            out = deconvolve(noisy, cp, method="tv", weight=TV_WEIGHT, n_iter=TV_ITERATIONS, init=x0)
            r["time_tv"] = time.perf_counter() - t0
            r["rmse_tv"] = _rmse(out[c], truth)
        rows.append(r)
        print(f"{name:9s} L={length:3.1f}  blurred {r['blurred']:.4f} | noise-free: 2D {r['rmse_2d_clean']:.4f} "
              f"4D {r['rmse_4d_clean']:.2e} | sigma={NOISE}: 2D {r['rmse_2d']:.4f} 4D {r['rmse_4d']:.4f} "
              f"({r['time_4d']:.2f} s per 4D solve)"
              + (f" | 4D TV {r['rmse_tv']:.4f} ({r['time_tv']:.0f} s)" if "rmse_tv" in r else ""), flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes, writes nothing")
    ap.add_argument("--tv", action="store_true",
                    help="add 4D TV runs at a few blur lengths (much slower)")
    _report.add_out_argument(ap, __file__)
    args = ap.parse_args(argv)
    if args.quick:
        syn, disp = synthetic_scene((5, 5, 32, 32), seed=1)
        cases = [("synthetic", syn, float(np.median(disp)))]
        lengths = (1.0, 2.0)
    else:
        syn, disp = synthetic_scene((9, 9, 128, 128), n_layers=3, color=True, seed=1)
        lytro = lytro_sample()
        cases = [
            ("synthetic", syn, float(np.median(disp))),
            ("lytro", lytro, _sharpest_disparity(lytro)),
        ]
        lengths = LENGTHS
    rows = []
    for name, lf, d in cases:
        print(f"{name}: {lf.shape}, 2D PSF for disparity {d:.3f} px/view")
        rows += run_case(name, lf, d, lengths, tv=args.tv)
    out = _report.table_path(args.out, __file__, smoke=args.quick)
    if not args.quick:
        _figure(rows, cases)
    if out is not None:
        _table(rows, out, argv)
    return rows


def _figure(rows, cases):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [c[0] for c in cases]
    fig, axes = plt.subplots(1, len(names), figsize=(5.2 * len(names), 3.8), squeeze=False)
    for ax, name in zip(axes[0], names):
        r = [x for x in rows if x["case"] == name]
        L = [x["length"] for x in r]
        ax.plot(L, [x["blurred"] for x in r], "o:", color="0.5", label="blurred centre view")
        ax.plot(L, [x["rmse_2d_clean"] for x in r], "s--", color="tab:red", mfc="none",
                label="2D Wiener, one depth's PSF (noise-free)")
        ax.plot(L, [x["rmse_4d_clean"] for x in r], "^--", color="tab:blue", mfc="none",
                label="4D in-plane solve (noise-free)")
        ax.plot(L, [x["rmse_2d"] for x in r], "s-", color="tab:red", label=f"2D Wiener (noise {NOISE})")
        ax.plot(L, [x["rmse_4d"] for x in r], "^-", color="tab:blue", label=f"4D in-plane solve (noise {NOISE})")
        rt = [x for x in r if "rmse_tv" in x]
        if rt:
            ax.plot([x["length"] for x in rt], [x["rmse_tv"] for x in rt], "D-", color="tab:green",
                    label=f"4D TV, {TV_ITERATIONS} iterations (noise {NOISE})")
        ax.set_xlabel("in-plane blur length (views)")
        ax.set_ylabel("RMSE of the centre view")
        ax.set_title(f"{name} ({'x'.join(map(str, cases[names.index(name)][1].shape))})")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    out_png = ROOT / "docs" / "images" / "in_plane_experiment.png"
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=110)
    print(f"wrote {out_png}")


def _table(rows, out, argv):
    lines = [
        "The protocol is in the script's docstring.",
        "Linear in-plane path at 30 degrees, T = 32; RMSE of the centre view against the sharp one,",
        f"borders of {CROP} px removed. Noise-free: 4D is the exact solve (weight 0), 2D the best Wiener",
        f"balance. With noise sigma = {NOISE}: each method with its best weight from a small grid.",
        "",
        "![in-plane experiment](../images/in_plane_experiment.png)",
        "",
        *([f"4D TV: `method='tv'`, weight {TV_WEIGHT}, {TV_ITERATIONS} iterations from the in-plane solve, "
           f"at blur lengths {', '.join(map(str, TV_LENGTHS))}.", ""] if any("rmse_tv" in r for r in rows) else
          ["4D TV: not run (`--tv` adds it).", ""]),
        "| case | blur length (views) | blurred | 2D noise-free | 4D noise-free | "
        f"blurred + noise | 2D, noise {NOISE} | 4D, noise {NOISE} | 4D TV, noise {NOISE} | 4D weight | 2D balance |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        tv = f"{r['rmse_tv']:.4f}" if "rmse_tv" in r else "-"
        lines.append(
            f"| {r['case']} | {r['length']:.1f} | {r['blurred']:.4f} | {r['rmse_2d_clean']:.4f} | "
            f"{r['rmse_4d_clean']:.1e} | {r['blurred_noisy']:.4f} | {r['rmse_2d']:.4f} | {r['rmse_4d']:.4f} | "
            f"{tv} | {r['weight_4d']:g} | {r['balance_2d']:g} |"
        )
    _report.write_table(out, "In-plane experiment: 4D versus 2D deconvolution", _report.command_line(__file__, argv),
                        _report.machine("auto"), lines)


if __name__ == "__main__":
    main()
