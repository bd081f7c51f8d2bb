"""Do no harm beyond the evaluation set: blind deblurring of seeded scenes of every kind, blurred or not.

``blind_eval.py`` judges the blind method on its own cases. This script asks
one question on cases it does not have: is the ``default`` preset's result
ever worse than its input? The cases are drawn from a seed: the package's
``synthetic_scene`` (flat colours, steps for edges) and ``procedural_scene``
(natural textures), 9x9 views of 20x200, 48x48 and 32x96 px (thin strips and
small squares), each unblurred, barely blurred (a 0.3-view path) or blurred
(0.8 to 2.5 views), by a curved path with ``p_z != 0`` on half of the cases,
at ``d_inf`` in {0, +-0.5, +-1}, with no noise, 0.002 or 0.01. Every
combination of scene kind, size and blur class comes up equally often.

For each case it reports the gain over the input (the ratio of the mean squared
errors against the sharp light field, in dB: noise-free unblurred input has
no error, so any change to it is a gain of -inf), the restoration made (``full``,
``light`` or ``none``) and the discrepancy of the restoration
(``info['discrepancy']``; a restoration refused by the discrepancy check comes
back as ``none`` with its discrepancy above the limit).

Usage::

    python benchmarks/no_harm.py                   # 54 cases of seed 0, writes docs/benchmarks/no_harm.md
    python benchmarks/no_harm.py --seed 1 --cases 108
    python benchmarks/no_harm.py --quick           # two tiny cases, writes nothing (or the table to --out)
    python benchmarks/no_harm.py --without-discrepancy-check   # what the check refuses; writes nothing
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

from napari_lfdeblur import blind_deblur, procedural_scene, simulate_blur, synthetic_scene
from napari_lfdeblur.blind import BlindParams
from napari_lfdeblur.blind import _evidence
from napari_lfdeblur.path import arc_path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)

KINDS = ("flat colours", "natural textures")
SHAPES = ((9, 9, 20, 200), (9, 9, 48, 48), (9, 9, 32, 96))
BLURS = ("unblurred", "barely blurred", "blurred")
D_INFS = (0.0, 0.5, -0.5, 1.0, -1.0)
NOISES = (0.0, 0.002, 0.01)
#: a result this much worse than its input (dB) counts as harm (the evaluation's limit)
HARM_DB = 0.1


def make_case(seed: int, k: int, shape=None):
    """Case ``k`` of ``seed``: (description dict, sharp, blurred, control points)."""
    rng = np.random.default_rng([seed, k])
    kind, blur = KINDS[k % 2], BLURS[(k // 6) % 3]
    shape = SHAPES[(k // 2) % 3] if shape is None else shape
    extent = {"unblurred": 0.0, "barely blurred": 0.3, "blurred": float(rng.uniform(0.8, 2.5))}[blur]
    cp = arc_path(extent, float(rng.uniform(-0.5, 0.5)), float(rng.uniform(0.0, 180.0))) if extent else np.zeros((3, 3))
    if extent and rng.random() < 0.5:
        cp[:, 2] = rng.uniform(-0.15, 0.15, len(cp))
    d_inf, noise = float(rng.choice(D_INFS)), float(rng.choice(NOISES))
    make = synthetic_scene if kind == KINDS[0] else procedural_scene
    sharp, _ = make(shape, seed=int(rng.integers(0, 2**31)))
    blurred = simulate_blur(sharp, cp, infinity_disparity=d_inf) if extent else sharp.copy()
    blurred = np.clip(blurred + noise * rng.standard_normal(blurred.shape), 0.0, 1.0).astype(np.float32)
    case = {"case": k, "scene": kind, "size": f"{shape[2]}x{shape[3]}", "blur": blur, "extent": extent,
            "p_z": bool(np.any(cp[:, 2])), "d_inf": d_inf, "noise": noise}
    return case, sharp, blurred, cp


def gain_db(sharp, blurred, restored) -> float:
    """``10 log10(MSE(input) / MSE(result))`` against ``sharp``.

    An exact input (no error) gives 0 when the result is exact too, else ``-inf``.
    """
    e_in = float(np.mean((blurred.astype(np.float64) - sharp) ** 2))
    e_out = float(np.mean((restored.astype(np.float64) - sharp) ** 2))
    if e_in == 0.0:
        return 0.0 if e_out == 0.0 else -math.inf
    return math.inf if e_out == 0.0 else 10.0 * math.log10(e_in / e_out)


def run(seed: int, n_cases: int, shape=None):
    rows = []
    params = BlindParams.preset("default")
    for k in range(n_cases):
        case, sharp, blurred, _ = make_case(seed, k, shape)
        t = time.perf_counter()
        res = blind_deblur(blurred, infinity_disparity=case["d_inf"], params=params, seed=0)
        case.update(time=time.perf_counter() - t, gain=gain_db(sharp, blurred, res.lightfield),
                    restoration=res.info["restoration"], discrepancy=res.info.get("discrepancy", float("nan")))
        case["refused"] = case["restoration"] == "none" and case["discrepancy"] > _evidence.DISCREPANCY_MARGIN
        rows.append(case)
        print(f"{k:3d} {case['scene']:16s} {case['size']:6s} {case['blur']:14s} d_inf {case['d_inf']:+g} "
              f"noise {case['noise']:g}: {case['restoration']:5s} gain {case['gain']:+7.2f} dB "
              f"discrepancy {case['discrepancy']:.2f} ({case['time']:.1f} s)", flush=True)
    return rows


def summary(rows, key) -> list[str]:
    out = [f"| {key} | cases | worse than the input by > {HARM_DB} dB | worst gain dB | mean gain dB (finite) | "
           "restored fully / lightly / not | refused by the discrepancy check |", "|---|---|---|---|---|---|---|"]
    for value in dict.fromkeys(r[key] for r in rows):
        rs = [r for r in rows if r[key] == value]
        g = np.array([r["gain"] for r in rs])
        finite = g[np.isfinite(g)]
        made = " / ".join(str(sum(r["restoration"] == m for r in rs)) for m in ("full", "light", "none"))
        mean = f"{finite.mean():+.2f}" if finite.size else "—"
        out.append(f"| {value} | {len(rs)} | {int(np.sum(g < -HARM_DB))} | {g.min():+.2f} | {mean} | "
                   f"{made} | {sum(r['refused'] for r in rs)} |")
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="the seed the cases are drawn from")
    parser.add_argument("--cases", type=int, default=54, help="how many cases (54: three of every combination)")
    parser.add_argument("--quick", action="store_true", help="two tiny cases, writes nothing unless --out")
    parser.add_argument("--without-discrepancy-check", action="store_true",
                        help="restore whatever the restoration's discrepancy (what the check refuses, and what it "
                             "would have given); writes nothing unless --out")
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    torch.set_num_threads(2)
    if args.without_discrepancy_check:  # the limit the solver reads, out of reach
        _evidence.DISCREPANCY_MARGIN = math.inf
    rows = run(args.seed, 2 if args.quick else args.cases, (5, 5, 24, 24) if args.quick else None)
    for r in rows:
        r["all"] = "all"
    per_case = ["| case | scene | size | blur (extent, views) | p_z | d_inf | noise | restoration | gain dB | "
                "discrepancy | time s |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    per_case += [f"| {r['case']} | {r['scene']} | {r['size']} | {r['blur']} ({r['extent']:.2f}) | "
                 f"{'yes' if r['p_z'] else 'no'} | {r['d_inf']:+g} | {r['noise']:g} | {r['restoration']} | "
                 f"{r['gain']:+.2f} | {r['discrepancy']:.2f} | {r['time']:.1f} |" for r in rows]
    body = [
        f"Cases of seed {args.seed} (`make_case`): the package's `synthetic_scene` (flat colours) and "
        f"`procedural_scene` (natural textures), 9x9 views of 20x200, 48x48 and 32x96 px, unblurred, barely "
        f"blurred (0.3 views) or blurred (0.8-2.5 views) by a curved path (`p_z != 0` on about half), `d_inf` in "
        f"{{0, +-0.5, +-1}}, noise 0, 0.002 or 0.01; `blind_deblur` with the `default` preset and the true "
        f"`d_inf`. Gain: `10 log10(MSE(input) / MSE(result))` against the sharp light field (a noise-free "
        f"unblurred input has no error: any change to it is a gain of -inf, and the mean gain leaves such cases "
        f"out). Discrepancy: the restoration's, in noise "
        f"variances per sample (nan where none was made; above {_evidence.DISCREPANCY_MARGIN:g} the restoration is "
        f"refused and the input returned). These cases are not those of `blind_eval.py`.",
        "", "## By blur", "", *summary(rows, "blur"), "", "## By scene", "", *summary(rows, "scene"),
        "", "## All", "", *summary(rows, "all"), "", "## Per case", "", *per_case,
    ]
    out = _report.table_path(args.out, __file__, smoke=args.quick or args.without_discrepancy_check)
    if out is not None:
        _report.write_table(out, "Do no harm beyond the evaluation set", _report.command_line(__file__, argv),
                            _report.machine("auto"), body)


if __name__ == "__main__":
    main()
