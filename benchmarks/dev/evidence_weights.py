"""Diagnostic: what the evidence test says of the true path, the estimate, and at which latent weight.

The blind solver accepts an estimated path only when the evidence test finds
its blur significant (docs/blind.md, "Do no harm"): the salient-edge
objective ``E = |K l - g|^2 / N + lambda ||grad l||_0 / N`` of the latent
through the path's blur must beat that through the identity by more than one
noise variance per sample and by more than 6 % of it. This script asks how
the test judges paths whose quality is known. For each development case of
``blind_eval.py`` it estimates the path blindly, restores with it whatever
the evidence (``require_evidence=False``), and prints the estimate's blur
mismatch and PSNR gain, then the test's ``gain`` (noise variances per
sample) and ``relative`` for the true path and for the estimate, at the
test's own weight (the smallest of the alternation) and at larger ones
(``--weights``; the alternation's first weight is ``latent.l0_weight``).

A test that rejects the true path cannot accept a right estimate; a weight
at which it accepts the right estimates and rejects the wrong ones on these
cases must also be checked on scenes it was not chosen on.

Usage::

    python benchmarks/dev/evidence_weights.py [--cases dev01,dev03,dev04,dev05,dev07,dev09,dev14]
        [--weights 0.004,0.016]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import blind_eval as ev  # noqa: E402  (benchmarks/blind_eval.py)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="dev01,dev03,dev04,dev05,dev07,dev09,dev14")
    ap.add_argument("--weights", default="0.004,0.016", help="latent weights besides the test's own")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)

    from napari_lfdeblur.blind import BlindParams, blind_deblur
    from napari_lfdeblur.blind._disparity import gray, shear_spectral
    from napari_lfdeblur.blind._evidence import EVIDENCE_MARGIN, RELATIVE_MARGIN, blur_evidence, evidence_weight
    from napari_lfdeblur.metrics import path_error, psnr
    from napari_lfdeblur.path import center_path
    from napari_lfdeblur.progress import run_to_completion

    p = BlindParams.preset("default").replace(require_evidence=False)
    own = evidence_weight(p)
    weights = [own] + [float(w) for w in args.weights.split(",") if w]
    print(f"evidence test: gain > {EVIDENCE_MARGIN:g} noise variances per sample and relative > "
          f"{RELATIVE_MARGIN:g}; its own weight is {own:g}")
    print("case | group | noise | estimate's mismatch | gain dB restored anyway | weight | "
          "true path: gain, relative | estimate: gain, relative")
    specs, _ = ev.select_cases("dev", args.cases.split(","))
    for spec in specs:
        case = ev.make_case(spec)
        name = spec.name
        d = case.infinity_disparity
        res = blind_deblur(case.blurred, infinity_disparity=d, params=p, seed=0)
        mismatch = path_error(res.control_points, case.control_points, lightfield=case.sharp,
                              infinity_disparity=d).blur_mismatch
        gain = psnr(res.lightfield, case.sharp, crop=ev.CROP) - psnr(case.blurred, case.sharp, crop=ev.CROP)
        g = gray(torch.as_tensor(case.blurred))
        g = shear_spectral(g, d) if d else g  # the path stage's d_inf = 0 frame (the whole 128 x 128 view)
        paths = (center_path(case.control_points, p.n_times), center_path(res.control_points, p.n_times))
        for w in weights:
            q = p.replace(latent={"l0_weight": w, "l0_floor": 1.0})
            cells = []
            for cp in paths:
                e = run_to_completion(blur_evidence(g, cp, q, torch.device("cpu")))
                cells.append(f"{e['gain']:+.2f}, {e['relative']:+.3f}{' (accepted)' if e['blur_found'] else ''}")
            print(f"{name} | {case.spec.group} | {case.spec.noise:g} | {mismatch:.3f} | {gain:+.2f} | {w:g} | "
                  + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
