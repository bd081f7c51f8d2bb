"""What the ``lfdeblur`` command says about light fields, paths and results: ``lfdeblur info`` on a light
field, a camera path file (``.json``) or a batch output folder, the path notes it prints, the metadata it
stores with a light field it computed, the checks of its outputs and options, the commands it suggests."""

from __future__ import annotations

import json
import re
import shlex
import sys
from pathlib import Path

import numpy as np

__all__ = ["CLIError", "check_targets", "in_cli_words", "DEFAULT_N_TIMES", "TV_ITERATIONS", "TV_TOL",
           "refuse_unused_tv_options", "deconvolve_command", "describes", "describe",
           "describe_lightfield", "describe_path", "describe_path_file", "describe_batch_folder", "result_metadata",
           "rotation_note", "stated_value", "warn_view_mismatch"]

#: Instants a path is sampled at when its file does not state ``n_times`` (``info``, ``simulate``, ``deconvolve``)
DEFAULT_N_TIMES = 32

#: ``lfdeblur deconvolve``'s defaults for the tv solve's ``--iterations`` and ``--tol``
TV_ITERATIONS, TV_TOL = 200, 1e-4


def stated_value(given, key: str, sources, default):
    """A command's ``n_times`` or ``infinity_disparity``: ``given`` (its option) when set, else the value
    the first of ``sources`` that states one states (said on stderr), else ``default``.

    ``sources`` are ``(name, fields)`` pairs, such as a path file's fields or an input's metadata.

    Raises
    ------
    ValueError
        When the value taken from a source is not an integer >= 2 (``n_times``) or a finite number
        (``infinity_disparity``); the message names the source and the option that overrides it.
    """
    from .io._write import check_path_field

    if given is not None:
        return given
    option = "--" + key.replace("_", "-")
    for name, fields in sources:
        if fields.get(key) is None:
            continue
        try:
            value = check_path_field(key, fields[key], name)
        except ValueError as exc:
            raise ValueError(f"{exc}; pass {option}") from None
        print(f"using {key} = {value:g}, as {name} states ({option} overrides it)", file=sys.stderr)
        return value
    return default


def warn_view_mismatch(command: str, cp, shape, name, fields) -> None:
    """Say on stderr when the path ``cp`` from ``name`` (whose ``fields`` may state its ``view_shape``) is for
    views of another size than those of a light field of ``shape`` (``io._write.view_shape_note``)."""
    from .io._write import view_shape_note

    note = view_shape_note(cp, shape, fields, name)
    if note:
        print(f"lfdeblur {command}: warning: {note}", file=sys.stderr)


def describes(path) -> bool:
    """Whether :func:`describe` takes ``path``: a ``.json`` file, or a folder with a batch manifest."""
    path = Path(path)
    return path.suffix.lower() == ".json" or (path / "manifest.jsonl").is_file()


def describe(path) -> list[str]:
    """:func:`describe_batch_folder` for a folder, else :func:`describe_path_file`."""
    return describe_batch_folder(path) if Path(path).is_dir() else describe_path_file(path)


def describe_batch_folder(out_dir) -> list[str]:
    """Lines that describe a folder written by ``lfdeblur batch``, from its manifest.

    The items (the last record of each output), how many are done and how
    many failed (with the first errors), and for ``deblur`` what the
    evidence test decided.
    """
    from ._cli_batch import weak_blur_summary
    from .batch import read_manifest

    records = list(read_manifest(out_dir).values())
    if not records:
        return [f"batch:       {out_dir} (lfdeblur batch)",
                "items:       none in the manifest yet: the batch has not finished an item (or was stopped first)"]
    kinds = sorted({str(r.get("kind")) for r in records})
    versions = sorted({str(r.get("version")) for r in records})
    status = [r.get("status") for r in records]
    lines = [f"batch:       {out_dir} (lfdeblur batch {', '.join(kinds) or '?'}; napari-lfdeblur "
             f"{', '.join(versions) or '?'})",
             f"items:       {len(records)} in the manifest: {status.count('ok')} done, {status.count('failed')} failed"]
    failed = [r for r in records if r.get("status") == "failed"]
    lines += [f"failed:      {r.get('output')}: {r.get('error')}" for r in failed[:5]]
    if len(failed) > 5:
        lines.append(f"             ... and {len(failed) - 5} more (manifest.jsonl)")
    found = [r.get("blur_found") for r in records if r.get("status") == "ok" and "blur_found" in r]
    if found:
        lines.append(f"blur found:  in {found.count(True)} of {len(found)}{weak_blur_summary(records)}")
    if failed:
        lines.append("rerun:       the command in README.md there redoes the failed items (and skips the done ones)")
    return lines


def describe_lightfield(lf: np.ndarray, meta: dict, stretched: bool = False) -> list[str]:
    """Lines that describe a light field read with its metadata (``read_lightfield_with_metadata``'s pair).

    Layout, shape, dtype, value range, the share of saturated samples, a note
    when the data are dark (unless ``stretched``: read with a value range),
    the camera path its metadata holds (:func:`describe_path`), then the
    other metadata.
    """
    from ._lightfield import DARK_LEVEL, brightest

    lines = [f"file:        {meta['source']}", f"layout:      {meta['layout']}",
             f"shape:       {lf.shape}  (V, U, Y, X{', C' if lf.ndim == 5 else ''})",
             f"dtype:       {lf.dtype} (stored as {meta.get('file_dtype', '?')})",
             f"value range: [{float(lf.min()):.6g}, {float(lf.max()):.6g}], mean {float(lf.mean()):.6g}"]
    at_top = float(np.mean(lf >= 1.0))
    if at_top > 0:
        lines.append(f"saturated:   {100 * at_top:.3g} % of the samples are at 1 (deconvolution fits them as clipped "
                     "by the sensor: the light there reached at least 1)")
    bright = brightest(lf)
    if bright < DARK_LEVEL and not stretched:
        lines.append(f"note:        dark: 99.9 % of the centre view is below {bright:.3g} (10- or 12-bit data in a "
                     "16-bit file? a linear decode?); the blind solver finds few edges in dark data: --value-range "
                     "auto or LO,HI stretches it")
    if meta.get("control_points") is not None:
        lines.append("camera path:")
        lines += ["  " + line for line in describe_path(meta["control_points"], meta.get("n_times"))]
    rest = {k: v for k, v in meta.items() if k not in ("source", "layout", "shape", "dtype", "file_dtype")}
    lines.append("metadata:" + ("" if rest else "    (none)"))
    lines += [f"  {key}: {json.dumps(value, default=str)}" for key, value in rest.items()]
    return lines


def describe_path_file(path) -> list[str]:
    """Lines that describe the camera path in the JSON file ``path`` (as ``save_path_json`` writes it):
    :func:`describe_path`, then the file's other fields.

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`~napari_lfdeblur.path.read_path_json` (a missing file, bad
        JSON, no or malformed control points).
    """
    from .path import read_path_json

    cp, doc = read_path_json(path)
    extra = {k: v for k, v in doc.items() if k not in ("control_points", "units")}
    lines = [f"file:        {path}", *describe_path(cp, extra.get("n_times"))]
    lines.append("fields:" + ("" if extra else "      (none)"))
    lines += [f"  {key}: {json.dumps(value, default=str)}" for key, value in extra.items()]
    return lines


def describe_path(cp, n_times=None) -> list[str]:
    """Lines that describe a camera path ``cp`` ``(n, 3)`` or ``(n, 6)`` sampled at ``n_times`` instants.

    The motion (3- or 6-DOF), the in-plane extent (the largest distance
    between two positions of ``(p_x, p_y)`` over the exposure, views), the
    distance travelled (views), the range of ``p_z`` over the exposure and
    the largest rotation of the control points. ``n_times`` that is not an
    integer >= 2 (None: not stated) counts as :data:`DEFAULT_N_TIMES`.
    """
    from .path import bezier_positions, validate_control_points

    cp = validate_control_points(cp)
    n_times = n_times if isinstance(n_times, int) and n_times >= 2 else DEFAULT_N_TIMES
    pos = bezier_positions(cp, n_times)
    xy = pos[:, :2]
    extent = float(np.linalg.norm(xy[:, None] - xy[None], axis=-1).max())
    travelled = float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())
    six = cp.shape[1] == 6
    lines = [f"motion:      {'6-DOF' if six else '3-DOF'}, {len(cp)} control points "
             f"({'p_x, p_y, p_z, r_x, r_y, r_z' if six else 'p_x, p_y, p_z'})",
             f"extent:      {extent:.3g} views in (p_x, p_y) over the exposure ({n_times} instants); "
             f"{travelled:.3g} views travelled"]
    pz = pos[:, 2]
    lines.append("p_z:         0 (in-plane motion)" if not np.any(cp[:, 2]) else
                 f"p_z:         {pz.min():.3g} to {pz.max():.3g} (views per unit of normalised x~)")
    if six:
        r = np.abs(cp[:, 3:]).max(axis=0)  # of the control points, as rotation_note and the shake6 preset
        lines.append(f"rotation:    up to {1000 * r.max():.2f} mrad ({np.degrees(r.max()):.3g} deg; pitch r_x "
                     f"{1000 * r[0]:.2f}, yaw r_y {1000 * r[1]:.2f}, roll r_z {1000 * r[2]:.2f}; of the control "
                     "points)")
    if extent == 0 and not np.any(cp[:, 2:]):
        lines.append("note:        the camera does not move: this path does not blur")
    return lines


def rotation_note(cp) -> str:
    """`` (6-DOF, rotation up to X mrad)`` for a path with rotation columns, else ``''``.

    X is the largest ``|r_x|, |r_y|, |r_z|`` of the control points (which
    bounds the path's, and is the ROTATION of a ``shake6`` preset).
    """
    cp = np.asarray(cp)
    if cp.ndim != 2 or cp.shape[1] != 6:
        return ""
    return f" (6-DOF, rotation up to {1000 * float(np.abs(cp[:, 3:]).max()):.2f} mrad)"


def result_metadata(kind: str, parameters: dict, **fields) -> dict:
    """The metadata stored with a light field the command computed: its ``kind``, ``fields`` (``n_times``,
    ``infinity_disparity``, ...), the ``parameters`` and the package version (as a napari layer's)."""
    from . import __version__

    return {"kind": kind, **fields, "parameters": dict(parameters), "napari_lfdeblur_version": __version__}


class CLIError(Exception):
    """An error to report to the user as one line."""


def check_targets(targets, overwrite: bool, inputs=()) -> None:
    """Refuse, before any work, an output file (None: none) that exists without ``--overwrite``, or whose
    folder does not exist (unless that folder is one of the outputs: a folder of views and its path.json);
    also two outputs of one name, and an output that is one of the ``inputs`` or the path file beside one
    (``b.path.json`` of the input ``b.npy``, which an output ``b.tif`` would write its own path to)."""
    from .io._common import check_writable
    from .io._write import path_json_beside

    named = [Path(t).resolve() for t in targets if t is not None]
    beside = {b.resolve(): i for i in inputs if (b := path_json_beside(i)).is_file()}
    for target in (t for t in targets if t is not None):
        where = Path(target).resolve()
        if named.count(where) > 1:
            raise CLIError(f"{target} is named for two of this command's outputs (the light field, its path "
                           "file, --path-out): give each its own name")
        if any(where == Path(i).resolve() for i in inputs):
            raise CLIError(f"{target} is the input; an output may not replace it")
        if where in beside:
            raise CLIError(f"{target} holds the camera path of the input {beside[where]}; an output may not replace "
                           "it: give the output another name")
        if target.exists() and not overwrite:
            raise CLIError(f"{target} exists; pass --overwrite to replace it")  # the option's name, not the API's
        if target.parent not in targets:
            check_writable(target, overwrite=True)  # its folder exists
            _check_folder_takes_files(target)


def _check_folder_takes_files(target: Path) -> None:
    """Refuse, before any work, an output whose folder exists but takes no new file (read-only, or not ours),
    found by creating a file there and removing it (permission bits do not tell root's refusals)."""
    from .io._common import temporary_name

    probe = temporary_name(target)
    try:
        probe.touch(exist_ok=False)
    except OSError as exc:
        raise CLIError(f"cannot write {target}: the folder {target.parent} takes no new file "
                       f"({exc.strerror or exc})") from None
    probe.unlink()


#: the library's hints in Python keywords, and their command-line spelling
_HINTS = ((re.compile(r"grid=\(V, U\)"), "--grid V,U"), (re.compile(r"layout='(\w+)'"), r"--layout \1"),
          (re.compile(r"device='(\w+)' or '(\w+)'"), r"--device \1 or \2"),
          (re.compile(r", or pass layout= \(one of \([^)]*\)\)"), ""),  # an output's layout is its suffix here
          (re.compile(r"pass weight=$"), "pass --weight W"))
#: the reader's refusal of options a layout does not take, in Python keywords
_READER_OPTIONS = re.compile(r"option\(s\) \[(.*)\] do not apply to layout '(\w+)'; it accepts \[(.*)\] plus .*")


def in_cli_words(message: str) -> str:
    """An error message of the library with its keyword hints (``grid=(V, U)``, ``device='cpu'``) as options."""
    for pattern, words in _HINTS:
        message = pattern.sub(words, message)
    found = _READER_OPTIONS.fullmatch(message)
    if found:  # the commands take two of the reader's options: --grid and --angular-size
        def spelt(names):
            return ["--" + n.strip(" '").replace("_", "-") for n in names.split(",")
                    if n.strip(" '") in ("grid", "angular_size")]

        taken = ", ".join(spelt(found.group(3)) + ["--value-range", "--angular-crop"])
        message = (f"{', '.join(spelt(found.group(1)))} does not apply to layout {found.group(2)!r} "
                   f"(its options: {taken})")
    return message


def refuse_unused_tv_options(args) -> None:
    """Refuse ``lfdeblur deconvolve --method inplane`` given options of the tv solve, which it would not use."""
    given = {"--separate-channels": args.separate_channels, "--no-saturation": args.no_saturation,
             "--along-views": args.along_views, "--iterations": args.iterations != TV_ITERATIONS,
             "--tol": args.tol != TV_TOL}
    if args.method == "inplane" and any(given.values()):
        raise CLIError(f"{', '.join(k for k, v in given.items() if v)}: options of the tv solve, which --method "
                       "inplane (a linear solve that takes only --weight) does not use; leave them out or use "
                       "--method tv")


def deconvolve_command(args, path_file) -> str:
    """The ``lfdeblur deconvolve`` line that reads ``args.input`` as ``deblur`` did and restores with ``path_file``."""
    words = ["lfdeblur", "deconvolve", args.input, str(path_file), "OUTPUT"]
    if args.swap_views:
        words.append("--swap-views")
    for option, key in (("--layout", "layout"), ("--grid", "grid"), ("--angular-size", "angular_size"),
                        ("--angular-crop", "angular_crop")):
        value = getattr(args, key)
        if value is not None:
            words += [option, ",".join(map(str, value)) if isinstance(value, tuple) else str(value)]
    if args.value_range is not None:  # one word, so that a negative LO is not read as an option
        vr = args.value_range
        words.append("--value-range=" + (vr if isinstance(vr, str) else ",".join(repr(float(v)) for v in vr)))
    return shlex.join(words)
