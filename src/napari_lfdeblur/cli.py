"""The ``lfdeblur`` command.

Each subcommand is an ``_add_<name>(subparsers)`` function that declares its
arguments and a ``_run_<name>(args)`` function that does the work. Errors a
user can act on (missing files, bad values) are printed as one line, with
exit status 2, never as a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

from ._cli_batch import add_batch as _add_batch, blind_params, run_batch as _run_batch  # noqa: F401 (batch)
from ._cli_info import (
    DEFAULT_N_TIMES,
    TV_ITERATIONS,
    TV_TOL,
    CLIError,
    check_targets as _check_targets,
    deconvolve_command,
    describe,
    describe_lightfield,
    describes,
    in_cli_words,
    refuse_unused_tv_options,
    result_metadata,
    rotation_note,
    stated_value,
    warn_view_mismatch,
)
from ._cli_progress import StageProgress, counting_bar
from ._cli_types import angular_crop, fraction, gib, seed, value_range, view_grid, window
from ._lightfield import MAX_SEED

__all__ = ["main"]


def _input_argument(p, help_text="light field file or folder"):
    """INPUT and how to read it (layout, views, values): the options of the commands that read a light field."""
    p.add_argument("input", help=help_text)
    p.add_argument("--layout", default=None, help="override the detected layout (views, hci, stanford, eslf, "
                   "mosaic, mat, h5, npy, npz, tiff)")
    p.add_argument("--grid", type=view_grid, default=None, metavar="V,U", help="view grid (mosaic layout)")
    p.add_argument("--angular-size", type=int, default=None, metavar="A", help="lenslet size A (eslf layout)")
    p.add_argument("--swap-views", action="store_true",
                   help="swap the two view axes after reading (for exports that name the horizontal view first)")
    p.add_argument("--angular-crop", type=angular_crop, default=None, metavar="N",
                   help="keep only the central N x N views (or NV,NU): a Lytro decode's outer views are dark, and "
                   "folders, HDF5, MATLAB v7.3 and .npy files then read only the views kept")
    p.add_argument("--value-range", type=value_range, default=None, metavar="LO,HI",
                   help="the stored values that become 0 and 1, such as 0,4095 for 12-bit data in a 16-bit file, "
                   "or auto (the data's own minimum and maximum); default: integers by their type's maximum, "
                   "floats as they are (they must lie in [0, 1])")


def _read(args, **options):
    """Read ``args.input`` (a light field and its metadata), swapping the view axes on ``--swap-views``.

    A :class:`~napari_lfdeblur.io.ViewOrderWarning` from the reader becomes one line on stderr that
    names the option to use; any other warning of the reader, one line on stderr too.
    """
    import numpy as np

    from .io import ViewOrderWarning, read_lightfield_with_metadata

    if not Path(args.input).exists():
        raise CLIError(f"input {args.input} does not exist")
    for key in ("layout", "grid", "angular_size", "angular_crop", "value_range"):
        if getattr(args, key) is not None:
            options[key] = getattr(args, key)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ViewOrderWarning)
        lf, meta = read_lightfield_with_metadata(args.input, **options)
    transposed = None
    for w in caught:
        if issubclass(w.category, ViewOrderWarning):
            transposed = w.message
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)  # one line: main's
    if args.swap_views:
        lf = np.ascontiguousarray(lf.swapaxes(0, 1))
        if "view_shifts" in meta:
            meta["view_shifts"] = np.asarray(meta["view_shifts"])[::-1].tolist()
        if transposed is None:
            print(f"lfdeblur {args.command}: note: the views did not look transposed; swapped them as asked",
                  file=sys.stderr)
    elif transposed is not None:
        (sy, _), (_, sx) = transposed.shifts[1], transposed.shifts[0]
        print(f"lfdeblur {args.command}: warning: the views of {args.input} look transposed (u moves the image "
              f"along y by {sy:+.2f} px/view, v along x by {sx:+.2f}); rerun with --swap-views to read them "
              f"the other way round", file=sys.stderr)
    return lf, meta


def _path_argument(text: str):
    """Control points from ``--path`` (a JSON file, or ``PRESET[:EXTENT[:SEED[:ROTATION]]]``) and the fields
    the file states (``read_path_json``; ``{}`` for a preset).

    ``ROTATION`` (radians) is for ``shake6`` only.
    """
    from .path import PRESETS, preset_path, read_path_json

    if Path(text).is_dir():
        raise CLIError(f"--path {text!r} is a folder: give a path .json file or a preset such as linear:3")
    if Path(text).suffix.lower() == ".json" or Path(text).exists():
        return read_path_json(text)
    name, *rest = text.split(":")
    if name not in PRESETS:
        raise CLIError(
            f"--path {text!r} is neither a JSON file nor a preset; presets: {', '.join(sorted(PRESETS))} "
            "(e.g. linear:3 for a 3-view linear motion, random:2:7 for seed 7, shake6:2:7:0.01 for a shake "
            "with rotations up to 0.01 rad)"
        )
    if len(rest) > (3 if name == "shake6" else 2):
        form = "shake6[:EXTENT[:SEED[:ROTATION]]]" if name == "shake6" else "PRESET[:EXTENT[:SEED]]"
        raise CLIError(f"--path {text!r}: expected {form} (only shake6 takes a ROTATION)")
    try:
        extent = float(rest[0]) if rest else 2.0
        seed = int(rest[1]) if len(rest) > 1 else 0
        rotation = float(rest[2]) if len(rest) > 2 else None
    except ValueError:
        raise CLIError(f"--path {text!r}: expected PRESET[:EXTENT[:SEED]] or shake6:EXTENT:SEED:ROTATION") from None
    if not 0 <= seed <= MAX_SEED:
        raise CLIError(f"--path {text!r}: the SEED must be a whole number from 0 to 2**63 - 1")
    if len(rest) > 1 and name in ("linear", "arc"):
        raise CLIError(f"--path {text!r}: {name} is not random and takes no SEED: {name}[:EXTENT]")
    return preset_path(name, extent=extent, seed=seed, rotation=rotation), {}


# ------------------------------------------------------------- simulate


def _add_simulate(sub):
    p = sub.add_parser("simulate", help="blur a light field by a known camera path")
    _input_argument(p)
    p.add_argument("output", help="output file (.npz, .npy, .tif, .h5) or folder of views")
    p.add_argument("--path", required=True,
                   help="camera path: a JSON file of control points ((n, 3), or (n, 6) with a rotation), or "
                   "PRESET[:EXTENT[:SEED]] with PRESET one of linear, arc, shake, shake6, random; EXTENT in views, "
                   "default 2 (the length of linear and arc; the side of the box that shake and random draw their "
                   "control points from, whose motion is shorter); SEED for shake, shake6 and random, default 0. "
                   "shake6 is shake plus a random camera rotation (handheld shake), written "
                   "shake6[:EXTENT[:SEED[:ROTATION]]] with ROTATION the largest rotation in radians (default 0.005, "
                   "at most 0.2)")
    p.add_argument("--n-times", type=int, default=None,
                   help="exposure instants T (default: the one a --path file states, else 32)")
    p.add_argument("--infinity-disparity", type=float, default=None,
                   help="d_inf in px/view (default: the one a --path file states, else 0)")
    p.add_argument("--device", default="auto", help="auto, cpu or cuda (default auto)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")


def _run_simulate(args):
    from .blur import simulate_blur
    from .io._write import sidecar_path_json, write_lightfield

    out = Path(args.output)
    path_file = [args.path] if Path(args.path).is_file() else []  # a --path file is an input too
    _check_targets([out, sidecar_path_json(out)], args.overwrite, [args.input, *path_file])
    cp, stated = _path_argument(args.path)
    n_times = stated_value(args.n_times, "n_times", [(args.path, stated)], DEFAULT_N_TIMES)
    d_inf = stated_value(args.infinity_disparity, "infinity_disparity", [(args.path, stated)], 0.0)
    lf, _ = _read(args)
    warn_view_mismatch("simulate", cp, lf.shape, args.path, stated)
    blurred = simulate_blur(lf, cp, n_times=n_times, infinity_disparity=d_inf, device=args.device)
    written = write_lightfield(out, blurred, overwrite=args.overwrite, control_points=cp,
                               metadata={"kind": "blurred", "n_times": n_times, "infinity_disparity": d_inf})
    print(f"wrote {written} {blurred.shape}; its camera path, T and d_inf: {sidecar_path_json(written)}"
          f"{rotation_note(cp)}")


# ---------------------------------------------------------------- deblur


def _add_deblur(sub):
    p = sub.add_parser("deblur", help="blind deblurring: estimate the camera path and the sharp light field")
    _input_argument(p, "blurred light field file or folder")
    p.add_argument("output", help="output file (.npz, .npy, .tif, .h5) or folder of views")
    p.add_argument("--preset", default="default", help="parameter preset: default or paper (default: default)")
    p.add_argument("--params", help="a JSON file of BlindParams, nested by stage as BlindParams.to_json writes "
                   "it; keys left out take their defaults (overrides --preset)")
    p.add_argument("--device", default="auto", help="auto, cpu or cuda (default auto)")
    p.add_argument("--infinity-disparity", type=float, default=None, metavar="D_INF",
                   help="disparity of points at infinity, px/view (default: the value the input file states, as "
                        "files written by lfdeblur simulate do, else 0: a camera focused at infinity). "
                        "With the views' zero disparity on the focal plane, it is about the disparity of the "
                        "farthest content (sky, a far wall); the blind solver cannot estimate it (see "
                        "docs/blind.md)")
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--max-memory", type=gib, default=None, metavar="GIB",
                   help="memory the run may use on its device, in GiB (default: what it has free); with less "
                        "than it needs, the light field is restored in tiles")
    p.add_argument("--motion", choices=["3dof", "6dof"], default=None,
                   help="camera motion to estimate (BlindParams.motion; default: the preset's or --params', "
                        "3dof). 3dof: translation only, an (n, 3) path. 6dof: a rotation stage follows, for "
                        "handheld shake, and the path is (n, 6) with (r_x, r_y, r_z) in radians; slower "
                        "(alternating method only)")
    p.add_argument("--edge-anisotropy", type=float, metavar="PX",
                   help="how much softer the camera's views are along x than along y, px "
                        "(BlindParams.latent.edge_anisotropy; default: the preset's, 0)")
    p.add_argument("--restore-anyway", action="store_true",
                   help="restore with the estimated path even when the data give little evidence of blur "
                        "(BlindParams.require_evidence=False; default: then a light restoration, see "
                        "--light-restoration, or the input unchanged)")
    p.add_argument("--light-restoration", type=fraction, metavar="FRACTION",
                   help="when the data give little evidence of blur but two parts of them agree on the path, "
                        "restore with the estimated path scaled by FRACTION (in [0, 1]) instead of returning "
                        "the input: a light restoration (BlindParams.light_restoration; default: the preset's, "
                        "0.5 for 'default', 0 for 'paper'; 0: return the input)")
    p.add_argument("--window", type=window, action="append", metavar="Y0,X0,H,W",
                   help="estimate the path on this window of the view, in pixels (repeat for several; one with "
                        "--motion 6dof); default: chosen from the data. Keeps the estimate off a subject that moved "
                        "by itself; the whole light field is restored with the path found")
    p.add_argument("--path-out", help="also save the estimated path here (it always goes beside OUTPUT as NAME.path"
                   ".json, in a folder of views as path.json); a rejected path goes beside OUTPUT as NAME.path_"
                   "rejected.json, or with --path-out beside that file as *_rejected.json")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")


def _run_deblur(args):
    from .blind import iter_blind_deblur
    from .progress import run_to_completion
    from .io._write import sidecar_path_json, write_lightfield
    from .path import save_path_json

    out = Path(args.output)
    path_file = sidecar_path_json(out)  # where reading the result back finds its path
    extra_file = Path(args.path_out) if args.path_out else None
    rejected_file = (extra_file.with_name(extra_file.stem + "_rejected" + extra_file.suffix) if extra_file else
                     out.with_name(out.stem + ".path_rejected.json"))
    _check_targets([out, path_file, extra_file, rejected_file], args.overwrite, [args.input])
    params = blind_params(args)
    if args.edge_anisotropy is not None:
        params = params.replace(latent={"edge_anisotropy": args.edge_anisotropy})
    if args.restore_anyway:
        params = params.replace(require_evidence=False)
    if args.light_restoration is not None:
        params = params.replace(light_restoration=args.light_restoration)
    if args.motion is not None:
        params = params.replace(motion=args.motion)
    lf, meta = _read(args)
    d_inf = stated_value(args.infinity_disparity, "infinity_disparity", [(args.input, meta)], 0.0)
    gen = iter_blind_deblur(lf, infinity_disparity=d_inf, params=params, device=args.device, seed=args.seed,
                            max_memory=args.max_memory, windows=args.window, check_view_order=False)  # _read did
    bar = StageProgress("deblur", 1000, unit="", bar_format="{l_bar}{bar}| {elapsed}<{remaining} {postfix}")

    def show(rec):
        # the final TV solve stops once its objective settles: no time left to show
        settles = "relative_decrease" in rec.info
        # records inside a path-fit step carry no loss (NaN): the last one stays shown
        bar.show(rec.stage, int(1000 * rec.fraction), postfix=f"loss {rec.loss:.3g}" if rec.loss == rec.loss else None,
                 bar_format="{l_bar}{bar}| {elapsed} {postfix}" if settles else None)

    try:
        result = run_to_completion(gen, show)
        bar.finish()
    finally:
        gen.close()
        bar.close()
    fields = dict(n_times=params.final_n_times, infinity_disparity=d_inf, motion=params.motion)  # as restored
    write_lightfield(out, result.lightfield, overwrite=args.overwrite, control_points=result.control_points,
                     metadata=result_metadata("deblurred (blind)", params.to_dict(), **fields, timings=result.timings,
                                              preset=None if args.params else args.preset, seed=args.seed,
                                              blur_found=result.info.get("blur_found"),
                                              restoration=result.info.get("restoration"),
                                              final_weight=result.info.get("final_weight"),
                                              path_windows=[list(w) for w in result.info.get("windows", [])]))
    fields["view_shape"] = list(lf.shape[2:4])  # the path files' only (the result's own shape says it)
    if extra_file is not None:
        save_path_json(extra_file, result.control_points, overwrite=True, **fields)
    if "message" in result.info:
        print(result.info["message"])
    if "rejected_path" in result.info:
        save_path_json(rejected_file, result.info["rejected_path"], overwrite=True, **fields)
        print(f"the path it rejected is in {rejected_file}; to restore with it without estimating it again: "
              f"{deconvolve_command(args, rejected_file)}")
    elif rejected_file.exists():  # an earlier run's (replaced with --overwrite): it would pass for this run's
        rejected_file.unlink()
    print(f"wrote {out} {result.lightfield.shape} and its path {path_file}{rotation_note(result.control_points)} "
          f"({result.timings.get('total', float('nan')):.1f} s)")


# ------------------------------------------------------------------ demo


def _add_demo(sub):
    p = sub.add_parser("demo", help="run the main job on the built-in sample light fields")
    p.add_argument("--out", default="demo_out", help="output folder (default demo_out)")
    p.add_argument("--device", default="auto", help="auto, cpu or cuda (default auto)")
    p.add_argument("--quick", action="store_true", help="smaller sizes and fewer iterations, for tests")
    p.add_argument("--skip-blind", action="store_true", help="skip blind deblurring (the slowest step)")


def _run_demo(args):
    from .demo import run_demo

    summary = run_demo(args.out, device=args.device, quick=args.quick, blind=not args.skip_blind,
                       progress=counting_bar)
    print(f"demo results in {summary['out_dir']}:")
    for name in summary["files"]:
        print(f"  {name}")
    for name, rec in summary["samples"].items():
        print(f"{name}: PSNR " + ", ".join(f"{k} {v:.1f} dB" for k, v in rec["psnr_db"].items()))
        if "blind_message" in rec:
            print(f"  blind: {rec['blind_message']}")


# ------------------------------------------------------------------ info


def _add_info(sub):
    p = sub.add_parser("info", help="describe a light field (layout, shape, dtype, value range, metadata), a "
                       "camera path .json (motion, extent, rotation) or a batch output folder (items, failures)")
    _input_argument(p, "light field file or folder, camera path .json, or lfdeblur batch output folder")


def _run_info(args):
    if describes(args.input):  # a camera path file, a batch output folder
        print("\n".join(describe(args.input)))
        return
    lf, meta = _read(args)
    print("\n".join(describe_lightfield(lf, meta, stretched=args.value_range is not None)))


# ------------------------------------------------------------ deconvolve


def _add_deconvolve(sub):
    p = sub.add_parser("deconvolve", help="undo the blur of a known camera path (non-blind)")
    _input_argument(p, "blurred light field file or folder")
    p.add_argument("path_json", nargs="?",
                   help="JSON file of the path's control points (as written by simulate); default: the path the "
                        "input holds (stored in it, or in the NAME.path.json beside it, as every lfdeblur "
                        "command writes its outputs)")
    p.add_argument("output", help="output file (.npz, .npy, .tif, .h5) or folder of views")
    p.add_argument("--path", default=None, help="the path as simulate takes it, a JSON file or a preset such as "
                   "linear:1.5 (see lfdeblur simulate --help), instead of PATH_JSON")
    p.add_argument("--method", default="tv", choices=["tv", "inplane", "auto"],
                   help="tv (default: 4D total variation, any path and d_inf), inplane (the exact angular "
                        "solve, p_z = 0 and d_inf = 0 only) or auto (the same as tv)")
    p.add_argument("--weight", type=float, default=None,
                   help="regularisation weight >= 0 (default: tv, 0.225 x the noise level estimated in the data for "
                        "the colour TV, 0.15 x for one TV per channel, x2 with --along-views; inplane, 2e-3)")
    p.add_argument("--separate-channels", action="store_true",
                   help="tv on colour: one TV per channel instead of one colour TV over the channels (about a "
                        "third of the memory; for channels whose edges are unrelated)")
    p.add_argument("--no-saturation", action="store_true",
                   help="tv: fit samples at 1 as they are, inside [0, 1] (default: as saturated, where the light "
                        "reached at least 1; see docs/deconvolution.md)")
    p.add_argument("--along-views", action="store_true",
                   help="tv: the isotropic TV whose angular differences compare the same pixel of neighbouring "
                        "views (default: the anisotropic TV along the scene's disparity, estimated from the input, "
                        "which restores better in about twice the time; docs/deconvolution.md)")
    p.add_argument("--iterations", type=int, default=TV_ITERATIONS,
                   help=f"maximum TV iterations (default {TV_ITERATIONS})")
    p.add_argument("--tol", type=float, default=TV_TOL, help="TV stops when the objective falls by less than this "
                   f"fraction in an iteration (default {TV_TOL:g})")
    p.add_argument("--n-times", type=int, default=None,
                   help="exposure instants T (default: those stated with the path, else 32)")
    p.add_argument("--infinity-disparity", type=float, default=None,
                   help="d_inf in px/view (default: the one stated with the path, else the input file's, else 0)")
    p.add_argument("--device", default="auto", help="auto, cpu or cuda (default auto)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")


def _run_deconvolve(args):
    from .deconvolution import DeconvolutionParams, iter_deconvolve
    from .io._write import sidecar_path_json, write_lightfield
    from .path import read_path_json, validate_control_points
    from .progress import run_to_completion

    refuse_unused_tv_options(args)
    out = Path(args.output)
    if args.path is not None and args.path_json is not None:
        raise CLIError(f"two paths given, {args.path_json} and --path {args.path}: give one")
    given = args.path_json or args.path  # the path's file or preset, when one is given
    inputs = [args.input] + ([given] if given and Path(given).is_file() else [])
    _check_targets([out, sidecar_path_json(out)], args.overwrite, inputs)  # the result, and its path
    if args.path is not None:  # before the read: fails fast
        known = _path_argument(args.path)
    else:
        known = None if args.path_json is None else read_path_json(args.path_json)
    blurred, meta = _read(args)
    if known is None and meta.get("control_points") is None:
        raise CLIError(f"{args.input} holds no camera path (in itself or in a NAME.path.json beside it): "
                       "give its path file, lfdeblur deconvolve INPUT PATH.json OUTPUT, or --path")
    cp, stated = known or (validate_control_points(meta["control_points"]), meta)
    sources = [(given or args.input, stated), (args.input, meta)]  # the path's fields, then the input's
    n_times = stated_value(args.n_times, "n_times", sources[:1], DEFAULT_N_TIMES)
    d_inf = stated_value(args.infinity_disparity, "infinity_disparity", sources, 0.0)
    if known is not None:  # (the reader has checked the path the input holds)
        warn_view_mismatch("deconvolve", cp, blurred.shape, given, stated)
    options = dict(method=args.method, weight=args.weight, n_iter=args.iterations, tol=args.tol,
                   couple_channels=not args.separate_channels, saturation=not args.no_saturation)
    if args.along_views:
        options.update(angular="views", isotropic=True)
    gen = iter_deconvolve(blurred, cp, n_times=n_times, infinity_disparity=d_inf, device=args.device, **options)
    # no bar and no time left: the solve usually stops well before its last iteration, when the objective settles
    bar = StageProgress("deconvolve", args.iterations, desc="deconvolve", unit="it",
                        bar_format="{desc}: iteration {n_fmt} of at most {total_fmt} [{elapsed}, {rate_fmt}{postfix}]")
    last = []

    def show(rec):
        last[:] = [rec]
        d = rec.info.get("relative_decrease")
        stop = f", decrease {d:.1e} (stops below {args.tol:g})" if d is not None and args.tol > 0 else ""
        loss = f" loss={rec.loss:.4g}" if rec.loss == rec.loss else ""  # the in-plane solve states none (NaN)
        bar.show(rec.stage, rec.iteration, total=rec.n_iterations, description="deconvolve",
                 postfix=f"{rec.stage}{loss}{stop}")

    try:
        result = run_to_completion(gen, show)
    finally:
        gen.close()
        bar.close()
    rec = last[-1]
    used = {"weight_used": rec.info.get("weight"), "noise_sigma": rec.info.get("sigma")}  # the weight rule's choice
    every = DeconvolutionParams().replace(**options).to_dict()  # every parameter of the solve, defaults too
    write_lightfield(out, result, overwrite=args.overwrite, control_points=cp, metadata=result_metadata(
        "deconvolved", {**every, **used}, n_times=n_times, infinity_disparity=d_inf))
    print(f"wrote {out} {result.shape} ({rec.stage}, {rec.iteration} iteration(s), weight {used['weight_used']})")


# ------------------------------------------------------------------ main

_COMMANDS = ["info", "simulate", "deconvolve", "deblur", "demo", "batch"]


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="lfdeblur",
        description="Motion deblurring of 4D light fields (Srinivasan, Ng & Ramamoorthi, CVPR 2017).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    module = sys.modules[__name__]
    for name in _COMMANDS:
        getattr(module, f"_add_{name}")(sub)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``lfdeblur`` command; returns the exit status."""
    parser = build_parser()
    if not (sys.argv[1:] if argv is None else argv):  # no command: say which there are
        parser.print_help()
        return 2
    args = parser.parse_args(argv)
    run = getattr(sys.modules[__name__], f"_run_{args.command}")
    try:
        with warnings.catch_warnings():  # a warning is one line on stderr, as the command's own messages
            warnings.showwarning = lambda message, *_a, **_k: print(
                f"lfdeblur {args.command}: warning: {message}", file=sys.stderr)
            status = run(args)
    except KeyboardInterrupt:
        print("lfdeblur: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of stdout went away (lfdeblur info X | head): stop quietly, as cat does
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # so that the exit's flush fails no more
        return 141
    except (CLIError, ValueError, TypeError, OSError, OverflowError) as exc:
        print(f"lfdeblur {args.command}: error: {in_cli_words(str(exc))}", file=sys.stderr)
        return 2
    except (MemoryError, RuntimeError) as exc:  # numpy's names the array it could not allocate
        gpu = type(exc).__name__ == "OutOfMemoryError"  # torch's, a RuntimeError: the GPU's memory
        if isinstance(exc, RuntimeError) and not gpu:
            raise
        what = (str(exc).splitlines() or [""])[0] or "the work does not fit"
        print(f"lfdeblur {args.command}: error: {'the GPU ran ' if gpu else ''}out of memory ({what}); try "
              f"{'--device cpu, ' if gpu else ''}a smaller input, fewer instants (--n-times) or, for deblur, "
              "--max-memory", file=sys.stderr)
        return 1
    return status or 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
