"""One item of a batch: its seed, its camera path, and the task a worker runs for it.

A task receives a small dict (the item's *spec*: file names and parameters),
reads its own input, computes, writes its output and returns a small record.
Light fields never travel between the client, the scheduler and the workers.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import socket
import threading
import time
import warnings
from numbers import Real
from pathlib import Path

import numpy as np

from .._lightfield import restore_warnings, warnings_state, white_level

__all__ = ["PATH_KINDS", "item_seed", "draw_path", "simulate_item", "run_item", "item_metadata"]

PATH_KINDS = ("linear", "arc", "shake", "shake6", "random")


def item_seed(seed: int, name: str, index: int) -> int:
    """The seed of item ``index`` of the input called ``name`` in a run seeded ``seed``.

    The input's name (not its folder) enters through a SHA-256 hash, so a
    dataset made from copies of the inputs elsewhere is the same.

    Parameters
    ----------
    seed : int
        The run's seed, >= 0.
    name : str
        The input's file or folder name.
    index : int
        The item's index among those of its input, >= 0.

    Returns
    -------
    int
        A seed in ``[0, 2**32)``, from :class:`numpy.random.SeedSequence`.
    """
    for what, value in (("seed", seed), ("index", index)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{what} must be an integer; got {value!r}")
        if value < 0:
            raise ValueError(f"{what} must be >= 0; got {value}")
    digest = int.from_bytes(hashlib.sha256(str(name).encode("utf-8")).digest()[:8], "little")
    return int(np.random.SeedSequence([int(seed), digest, int(index)]).generate_state(1, np.uint32)[0])


def _extent_range(extent) -> tuple[float, float]:
    """``(lo, hi)`` of the motion's size in views: a number, or a pair to draw from uniformly."""
    if isinstance(extent, Real) and not isinstance(extent, bool):
        lo = hi = float(extent)
    elif isinstance(extent, (tuple, list)) and len(extent) == 2:
        lo, hi = (float(e) for e in extent)
    else:
        raise TypeError(f"extent must be a number or a (min, max) pair; got {extent!r}")
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo < 0 or hi < lo:
        raise ValueError(f"extent must be finite with 0 <= min <= max; got {extent!r}")
    return lo, hi


def draw_path(path_kind: str, extent, rng: np.random.Generator) -> np.ndarray:
    """A random camera path of a kind: its size, direction and shape drawn from ``rng``.

    Parameters
    ----------
    path_kind : {'linear', 'arc', 'shake', 'shake6', 'random'}
        ``linear``: a straight motion at a uniform angle; ``arc``: a bowed one
        (bend uniform in [-0.5, 0.5]); ``shake`` and ``random``: random
        control points (5 and 4) in a box, as :func:`~napari_lfdeblur.path.shake_path`
        and :func:`~napari_lfdeblur.path.random_path`; ``shake6``: ``shake``
        with a handheld camera rotation (up to 0.005 rad), as
        :func:`~napari_lfdeblur.path.shake6_path`.
    extent : float or (float, float)
        In views, or a range to draw it from uniformly: the length of
        ``linear`` and ``arc``, the side of the box of the random control
        points of the others (their motion is shorter).
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, float64, shape (n, 3), or (n, 6) for ``shake6``
    """
    from .. import path as paths

    lo, hi = _extent_range(extent)
    length = lo if lo == hi else float(rng.uniform(lo, hi))
    angle = float(rng.uniform(0.0, 360.0))
    if path_kind == "linear":
        return paths.linear_path(length=length, angle_deg=angle)
    if path_kind == "arc":
        return paths.arc_path(length=length, bend=float(rng.uniform(-0.5, 0.5)), angle_deg=angle)
    if path_kind == "shake":
        return paths.shake_path(extent=length, seed=int(rng.integers(2**31)))
    if path_kind == "shake6":
        return paths.shake6_path(extent=length, seed=int(rng.integers(2**31)))
    if path_kind == "random":
        return paths.random_path(extent=length, seed=int(rng.integers(2**31)))
    raise ValueError(f"unknown path kind {path_kind!r}: choose one of {', '.join(PATH_KINDS)}")


def simulate_item(lf, name: str, index: int, *, path_kind: str = "random", extent=2.0,
                  infinity_disparity: float = 0.0, noise: float = 0.0, seed: int = 0, n_times: int = 32,
                  device="cpu"):
    """One simulated item, in memory: what :func:`simulate_dataset` writes for ``(name, index)``.

    The path is drawn by :func:`draw_path` and the noise from
    ``numpy.random.default_rng(item_seed(seed, name, index))``; the light
    field is blurred by :func:`~napari_lfdeblur.blur.simulate_blur`, then
    Gaussian noise of standard deviation ``noise`` is added and the result
    clipped to [0, 1] (no clipping when ``noise`` is 0). Both are on the
    light field's own scale: for an integer array (kept on its scale, as
    :func:`~napari_lfdeblur.blur.simulate_blur` keeps it), ``noise`` and the
    clipping range are multiplied by the dtype's largest value.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        The sharp light field.
    name, index
        The input's name and the item's index (see :func:`item_seed`).

    Returns
    -------
    blurred : ndarray, float32, same shape as ``lf``
    control_points : ndarray, float64, shape (n, 3), or (n, 6) for ``path_kind='shake6'``
    """
    from ..blur import simulate_blur

    if not (isinstance(noise, Real) and math.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise must be a finite number >= 0; got {noise!r}")
    rng = np.random.default_rng(item_seed(seed, name, index))
    cp = draw_path(path_kind, extent, rng)
    blurred = simulate_blur(lf, cp, n_times=n_times, infinity_disparity=infinity_disparity, device=device)
    if noise > 0:
        white = white_level(lf.dtype) if isinstance(lf, np.ndarray) else 1.0  # uint8: noise 0.01 is 2.55
        blurred = np.clip(blurred + rng.normal(0.0, noise * white, blurred.shape).astype(np.float32), 0.0, white)
    return blurred, cp


def item_metadata(spec: dict) -> dict:
    """What identifies an item's output: stored in the file and compared when resuming."""
    return {"kind": spec["kind"], "name": spec["name"], "index": spec["index"], "seed": spec["seed"],
            "parameters": spec["parameters"]}


def _simulate(lf, spec: dict, device, meta: dict):
    p = spec["parameters"]
    blurred, cp = simulate_item(lf, spec["name"], spec["index"], path_kind=p["path_kind"], extent=p["extent"],
                                infinity_disparity=p["infinity_disparity"], noise=p["noise"], seed=spec["seed"],
                                n_times=p["n_times"], device=device)
    return blurred, cp, {"n_times": p["n_times"], "infinity_disparity": p["infinity_disparity"]}


def item_infinity_disparity(given, meta: dict, name: str) -> float:
    """The ``d_inf`` an item is deblurred with: ``given`` when set, else the one the input states
    (``meta``, as :func:`~napari_lfdeblur.io.read_lightfield_with_metadata` returns it), else 0.

    Raises
    ------
    ValueError
        When the input states a value that is not a finite number.
    """
    if given is not None:
        return float(given)
    from ..io._write import check_path_field

    if meta.get("infinity_disparity") is None:
        return 0.0
    try:
        return check_path_field("infinity_disparity", meta["infinity_disparity"], name)
    except ValueError as exc:
        raise ValueError(f"{exc}; give infinity_disparity (--infinity-disparity on the command line)") from None


def _deblur(lf, spec: dict, device, meta: dict):
    from ..blind import BlindParams, blind_deblur

    p = spec["parameters"]
    params = BlindParams.from_dict(p["params"])
    d_inf = item_infinity_disparity(p["infinity_disparity"], meta, Path(spec["input"]).name)
    result = blind_deblur(lf, params=params, infinity_disparity=d_inf, device=device, seed=spec["item_seed"],
                          check_view_order=False)  # read from a file, whose reader checked
    info = result.info
    extra = {"device": info.get("device", str(device)),  # where it ran: the GPU may have fallen back to the CPU
             "n_times": params.final_n_times, "infinity_disparity": d_inf,  # the instants restored with
             "timings": result.timings, "blur_found": bool(info.get("blur_found", True)),
             "restoration": info.get("restoration", "full")}
    if "message" in info:
        extra["blur_evidence"] = info["message"]
    if info.get("final_weight") is not None:  # the final stage's weight: passed to deconvolve, it gives the output
        extra["final_weight"] = info["final_weight"]
    extra["path_windows"] = [list(w) for w in info.get("windows", [])]  # where the path was estimated
    if "rejected_path" in info:  # the output is the input or a light restoration: keep the path, to restore with it
        extra["rejected_control_points"] = np.asarray(info["rejected_path"]).tolist()
    return result.lightfield, result.control_points, extra


#: what an item's output file states besides its path: the blur's instants and d_inf, the blind verdict
_STATED = ("n_times", "infinity_disparity", "blur_found", "restoration")


def _recover(spec: dict, out: Path) -> dict:
    """An output that exists but is not in the manifest: keep it if it is this item's, else refuse.

    Returns None when the file cannot be read as a light field but the manifest records an output of this
    item there (``spec['recorded']``: damaged since), or when it is this item's output but its path file is
    gone: the item is redone. Unreadable and unrecorded, it is another file (this package writes atomically),
    and refused.
    """
    from ..io import LightFieldError, read_lightfield_with_metadata
    from ..io._write import jsonable

    try:
        lf, meta = read_lightfield_with_metadata(out)
    except (LightFieldError, OSError, ValueError) as exc:
        if spec.get("recorded"):
            return None
        raise FileExistsError(f"{out} exists and is not this item's output (it is not a light field: {exc}); "
                              "pass overwrite=True (command line: --overwrite) to replace it") from None
    stated = meta.get("saved_metadata", {})
    if stated.get("batch") == jsonable(item_metadata(spec)) and not Path(spec["path_json"]).is_file():
        return None  # this item's output, its path file lost since: redone
    if stated.get("batch") != jsonable(item_metadata(spec)):
        raise FileExistsError(f"{out} exists and is not this item's output; pass overwrite=True (command line: "
                              "--overwrite) to replace it")
    verdict = {k: stated[k] for k in ("blur_found", "restoration") if k in stated}
    return {"shape": list(lf.shape), "recovered": True, **verdict}


def _check_path_file(spec: dict, out: Path) -> None:
    """Refuse to replace a path file at the item's path-file name that is not this item's (without overwrite).

    Its own names ``out`` (``lightfield``), or the manifest records an output of this item there.
    """
    from ..io._write import path_json_names

    path_json = Path(spec["path_json"])  # the path JSON beside ``out``
    if spec["overwrite"] or spec.get("recorded") or not path_json.exists():
        return
    if not path_json_names(out):
        raise FileExistsError(f"{path_json} exists and is not this item's path file; pass overwrite=True "
                              "(command line: --overwrite) to replace it")


def run_item(spec: dict) -> dict:
    """The task of one item, run on a worker: read, compute, write atomically, return a small record.

    The path JSON is written before the light field (both atomically), so an
    existing output always has its path beside it. Any exception (unreadable
    input, NaN, a solver error, out of memory) becomes ``status='failed'``
    with its ``error``, and warnings are listed in ``warnings``; the record
    never holds a light field.
    """
    t0 = time.perf_counter()
    rec = {"status": "failed", "error": None, "size": None, "shape": None, "recovered": False,
           "worker": f"{socket.gethostname()}:{os.getpid()}"}
    with _item_scope() as caught:
        _run(spec, Path(spec["output"]), rec)
    rec["warnings"] = sorted({w[:500] for w in caught})
    rec["time"] = round(time.perf_counter() - t0, 4)
    return rec


#: what the items running in this process share: how many run, and what they changed (put back by the last)
_SCOPE = {"lock": threading.Lock(), "depth": 0, "saved": None}
_THREAD = threading.local()  # the item of the thread (its list of warnings)


@contextlib.contextmanager
def _item_scope():
    """While items run in this process (a worker may run several at once, on its threads): a warning goes to
    the list of the item whose thread raised it (others are shown as before), every time it is raised, and
    torch runs on one thread. The last item to end puts the warnings machinery and torch's thread count back.
    (``warnings.catch_warnings`` would not do: it is process-wide, and items that overlap undo each other's.)"""
    import torch

    with _SCOPE["lock"]:
        if _SCOPE["depth"] == 0:
            _SCOPE["saved"] = (warnings_state(), torch.get_num_threads())
            warnings.showwarning = _to_the_item
            warnings.simplefilter("always")
        _SCOPE["depth"] += 1
    torch.set_num_threads(1)  # this thread's, and the default of threads that start
    _THREAD.caught = caught = []
    try:
        yield caught
    finally:
        _THREAD.caught = None
        with _SCOPE["lock"]:
            _SCOPE["depth"] -= 1
            if _SCOPE["depth"] == 0:
                state, n_threads = _SCOPE["saved"]
                restore_warnings(state)
                torch.set_num_threads(n_threads)


def _to_the_item(message, category, filename, lineno, file=None, line=None):
    caught = getattr(_THREAD, "caught", None)
    if caught is None:  # a thread that runs no item
        _SCOPE["saved"][0][0](message, category, filename, lineno, file, line)  # the showwarning it found
    else:
        caught.append(f"{category.__name__}: {message}")


def _run(spec: dict, out: Path, rec: dict) -> None:
    """The body of :func:`run_item`: fills ``rec`` in place."""
    from ..devices import select_device
    from ..io import read_lightfield_with_metadata, write_lightfield
    from ..path import save_path_json

    try:
        device = select_device(spec["device"])
        rec["device"] = str(device)
        kept = _recover(spec, out) if out.exists() and not spec["overwrite"] else None
        if kept is not None:
            rec.update(kept)
        else:
            _check_path_file(spec, out)
            compute = _simulate if spec["kind"] == "simulate" else _deblur
            lf, meta = read_lightfield_with_metadata(spec["input"], value_range=spec["parameters"].get("value_range"))
            result, cp, extra = compute(lf, spec, device, meta)
            rec["device"] = extra.pop("device", rec["device"])
            save_path_json(spec["path_json"], cp, overwrite=True, **extra, view_shape=lf.shape[2:4],
                           lightfield=out.name)
            # what the file states of its blur (read back, as by deconvolve and deblur) and of the verdict
            meta = {"batch": item_metadata(spec), "control_points": np.asarray(cp).tolist(),
                    "version": spec["version"], **{k: extra[k] for k in _STATED if k in extra}}
            write_lightfield(out, result, overwrite=spec["overwrite"] or out.exists(), metadata=meta,
                             compress=False)
            rec["shape"] = list(result.shape)
            if "blur_found" in extra:
                rec["blur_found"], rec["restoration"] = extra["blur_found"], extra["restoration"]
        rec["size"] = out.stat().st_size
        rec["status"] = "ok"
    except Exception as exc:  # every failure of one item is recorded, never raised
        rec["error"] = f"{type(exc).__name__}: {exc}"
