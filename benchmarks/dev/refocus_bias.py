"""Diagnostic: is the path stage's refocusing what makes its estimates too long at ``d_inf != 0``?

With ``d_inf != 0`` the path is estimated on the light field refocused by
``d_inf``, in the ``d_inf = 0`` model (docs/blind.md), whose interpolation
differs from the ``d_inf`` model the data follow (docs/model.md,
"Interpolation with d_inf != 0"). For each development case of
``blind_eval.py`` with a blur and a non-zero integer ``d_inf`` (where the
refocus is an exact shift of whole pixels, up to the views' borders) it
prints:

- *model gap*: how much of the blur the refocused model misses with the
  true path, ``||S f - K0_p S l|| / ||S f - S l||`` (``S`` the refocus,
  ``f`` the noise-free blurred light field of the ``d_inf`` model, ``l``
  the sharp one, grayscale, 8-px border left out): 0 when it reproduces the
  blur exactly, 1 when it does no better than no blur;
- the *best scale* of the blind estimate (the default preset, restored
  whatever the evidence, no final stage): the factor in ``--scales`` by
  which the estimate, scaled about its mean, has the smallest blur mismatch
  against the true path, with that mismatch and the mismatch at 1;
- the same for the case rendered in the refocused model itself (``S^-1 K0_p
  S l`` plus the case's noise), where the path stage's model is exact: the
  control.

At the end, the median best scale over the cases where some scale brings
the mismatch below 0.5 (elsewhere the estimate has collapsed or is lost,
and no length is right). If the estimates come out as long on the control,
the refocusing is not what lengthens them.

Usage::

    python benchmarks/dev/refocus_bias.py [--cases dev03,dev05] [--scales 0.25,0.4,0.5,0.6,0.75,1,1.25]

The extent is the case's (views, z included), as in the evaluation's case list.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)


def main(argv=None):
    ap = ev.dev_study_parser(__doc__)
    ap.add_argument("--scales", default="0.25,0.4,0.5,0.6,0.75,1,1.25", help="scales of the estimated path to try")
    args = ap.parse_args(argv)

    import torch

    from napari_lfdeblur import simulate_blur
    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.blind._disparity import shear_spectral
    from napari_lfdeblur.metrics import path_error

    def refocus(lf, d):  # (V, U, Y, X[, C]) refocused by d px/view, as the path stage does
        return shear_spectral(torch.as_tensor(lf if lf.ndim == 5 else lf[..., None]), d).numpy().reshape(lf.shape)

    p = BlindParams.preset("default").replace(require_evidence=False, final=None)
    scales = [float(s) for s in args.scales.split(",") if s]
    best = {"data": [], "control": []}
    print("case | group | d_inf | extent | model gap | best scale, data | mismatch there / at 1 | "
          "best scale, control | mismatch there / at 1")
    T = ev.RENDER_TIMES  # the cases' exposure instants
    for spec in ev.dev_study_cases(args):
        case = ev.make_case(spec)
        d, cp = case.infinity_disparity, case.control_points
        if d == 0 or d != round(d) or not np.abs(cp).any():
            continue
        t0 = time.perf_counter()
        sharp = case.sharp.mean(axis=-1)
        clean = simulate_blur(sharp, cp, n_times=T, infinity_disparity=d)
        s_sharp = refocus(sharp, d)
        in_model = simulate_blur(s_sharp, cp, n_times=T)
        inner = (slice(None), slice(None), slice(ev.CROP, -ev.CROP), slice(ev.CROP, -ev.CROP))
        s_clean = refocus(clean, d)
        gap = np.linalg.norm((s_clean - in_model)[inner]) / np.linalg.norm((s_clean - s_sharp)[inner])
        noise = np.random.default_rng(spec.noise_seed).normal(0.0, spec.noise, case.sharp.shape)
        s_sharp_rgb = refocus(case.sharp, d)
        control = refocus(simulate_blur(s_sharp_rgb, cp, n_times=T), -d)
        control = np.clip(control + noise, 0.0, 1.0).astype(np.float32)
        cells = []
        for label, data, truth, d_judge in (("data", case.blurred, case.sharp, d),
                                            ("control", control, s_sharp_rgb, 0.0)):
            est = blind_deblur(data, infinity_disparity=d, params=p, seed=0).control_points
            mm = [path_error(s * est, cp, lightfield=truth, infinity_disparity=d_judge).blur_mismatch for s in scales]
            k = int(np.argmin(mm))
            if mm[k] < 0.5:  # an estimate of the blur at some length (not collapsed, not lost)
                best[label].append(scales[k])
            whole = path_error(est, cp, lightfield=truth, infinity_disparity=d_judge).blur_mismatch
            cells.append(f"{scales[k]:g} | {mm[k]:.2f} / {whole:.2f}")
        print(f"{spec.name} | {spec.group} | {d:+g} | {spec.extent:.2f} | {gap:.2f} | {cells[0]} | {cells[1]}",
              flush=True)
        print(f"# {spec.name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    for label, values in best.items():
        if values:
            print(f"{label}: median best scale {np.median(values):g} over the {len(values)} cases whose best "
                  "blur mismatch is below 0.5")


if __name__ == "__main__":
    main()
