"""Many light fields at once, on dask.distributed: simulated datasets and batch deblurring.

:func:`simulate_dataset` blurs each input by random camera paths, a set
number of times; :func:`deblur_many` deblurs each input blindly. Both run
one task per item on a dask cluster (an embedded ``LocalCluster`` by
default, or a scheduler's address), write one ``.npz`` and one path JSON
per item into an output folder, and append a record per item to its
``manifest.jsonl``; see docs/batch.md.

Each task reads its own input and writes its own output (atomically, with
:func:`~napari_lfdeblur.io.write_lightfield`): only file names and small
records pass through the scheduler. Rerunning a call skips the items whose
output exists and matches the manifest; an item that fails (unreadable
input, NaN, a solver error, out of memory, a killed worker) is recorded with
its error and the others complete. Importing this module does not import
dask; the functions need ``pip install "napari-lfdeblur[batch]"``.
"""

from __future__ import annotations

import json
from pathlib import Path

from ._items import PATH_KINDS, draw_path, item_seed, simulate_item
from ._manifest import read_manifest
from ._run import BatchReport, connect, expand_inputs, make_spec, run_batch

__all__ = ["simulate_dataset", "deblur_many", "simulate_item", "item_seed", "draw_path", "read_manifest",
           "connect", "BatchReport", "PATH_KINDS"]

_COMMON_DOC = """value_range : (float, float) or 'auto', optional
        How the inputs are read (:func:`~napari_lfdeblur.io.read_lightfield`):
        the stored values that become 0 and 1, for data stored on another
        scale; recorded in each item's parameters.
    client : distributed.Client, str or None
        ``None`` starts an embedded ``LocalCluster`` (single-threaded worker
        processes, one per core, or ``workers``); a string is a scheduler
        address such as ``'tcp://host:8786'``.
    workers : int, optional
        Worker processes of the embedded cluster.
    device : {'auto', 'cpu', 'cuda'}, default 'auto'
        ``'cuda'`` sends the items to workers started with the resource
        ``GPU=1`` (one item at a time each); ``'auto'`` does so when the
        cluster has such workers (the embedded one has when torch sees a GPU),
        else runs on the CPU.
    overwrite : bool, default False
        Recompute every item and replace its output. Without it, an item
        whose output exists and matches the manifest is skipped, and an
        output that is not this item's is never replaced (the item fails).
    callback : callable, optional
        Called in the client with each item's record as it finishes (and
        with ``status='skipped'`` for the items skipped).
    command : str, optional
        The command shown in the dataset card (default: this Python call)."""


def _version() -> str:
    from .. import __version__

    return __version__


def _reading(value_range) -> dict:
    """The reading option of the items' parameters: ``{'value_range': ...}``, or nothing when it is None."""
    from ..io._common import check_value_range

    value_range = check_value_range(value_range)
    if value_range is None:
        return {}
    return {"value_range": value_range if value_range == "auto" else list(value_range)}


def _stem(path: Path) -> str:
    """The output name of an input: a file's name without its last suffix, a folder's name."""
    return path.stem if path.is_file() else path.name


def _call_text(func: str, inputs, out_dir, **kwargs) -> str:
    shown = [str(p) for p in inputs]
    args = ", ".join(f"{k}={v!r}" for k, v in kwargs.items())
    return (f"from napari_lfdeblur.batch import {func}\n"
            f"{func}({shown!r}, {str(out_dir)!r}, {args})")


def simulate_dataset(inputs, out_dir, *, n_per_input: int = 1, path_kind: str = "random", extent=2.0,
                     infinity_disparity: float = 0.0, noise: float = 0.0, seed: int = 0, n_times: int = 32,
                     value_range=None, client=None, workers: int | None = None, device: str = "auto",
                     overwrite: bool = False, callback=None, command: str | None = None) -> BatchReport:
    """Blur each input by ``n_per_input`` random camera paths: a dataset of (sharp, blurred, path).

    Item ``k`` of the input named ``name`` is written to
    ``out_dir/<name stem>_<k:04d>.npz`` (float32; the path in its metadata)
    with ``<...>.path.json`` beside it, and equals
    ``simulate_item(read_lightfield(input, value_range=value_range), name, k, ...)`` with the same
    arguments, bit for bit on the same device and torch thread count (one
    per task here).

    Parameters
    ----------
    inputs : str, Path or sequence of them
        A glob pattern (``'scenes/*.npz'``), or light-field files or folders
        :func:`~napari_lfdeblur.io.read_lightfield` reads. Names must be unique.
    out_dir : str or Path
        The output folder (created when missing).
    n_per_input : int, default 1
    path_kind : {'linear', 'arc', 'shake', 'shake6', 'random'}, default 'random'
        See :func:`draw_path`.
    extent : float or (float, float), default 2.0
        In views, or a range it is drawn from uniformly: the length of
        ``linear`` and ``arc``, the side of the box of the random control
        points of the others (their motion is shorter).
    infinity_disparity : float, default 0.0
        ``d_inf`` of the blur model, px/view.
    noise : float, default 0.0
        Standard deviation of the Gaussian noise added to the blurred light
        field (then clipped to [0, 1]).
    seed : int, default 0
        The run's seed; each item's is :func:`item_seed` ``(seed, name, k)``.
    n_times : int, default 32
        Exposure instants of the blur.
    {common}

    Returns
    -------
    BatchReport
    """
    if isinstance(n_per_input, bool) or not isinstance(n_per_input, int) or n_per_input < 1:
        raise ValueError(f"n_per_input must be an integer >= 1; got {n_per_input!r}")
    import numpy as np

    from .._lightfield import check_int, check_number

    draw_path(path_kind, extent, np.random.default_rng(0))  # bad arguments: fail before starting, not per item
    item_seed(seed, "", 0)
    if check_number(noise, "noise") < 0:
        raise ValueError(f"noise must be >= 0; got {noise!r}")
    infinity_disparity = check_number(infinity_disparity, "infinity_disparity")
    n_times = check_int(n_times, "n_times", 2)
    paths = expand_inputs(inputs)
    out_dir = Path(out_dir)
    extent = list(extent) if isinstance(extent, (tuple, list)) else float(extent)
    parameters = {"path_kind": path_kind, "extent": extent, "infinity_disparity": float(infinity_disparity),
                  "noise": float(noise), "n_times": int(n_times), **_reading(value_range)}
    version = _version()
    specs = [make_spec("simulate", p, k, out_dir / f"{_stem(p)}_{k:04d}.npz",
                       parameters=parameters, seed=seed, overwrite=overwrite, version=version)
             for p in paths for k in range(n_per_input)]
    command = command or _call_text("simulate_dataset", paths, out_dir, n_per_input=n_per_input, seed=seed,
                                    **parameters)
    card = {"kind": "simulate", "command": command, "parameters": parameters, "seed": seed, "version": version}
    return run_batch(specs, out_dir, client=client, workers=workers, device=device, card=card, callback=callback)


def deblur_many(inputs, out_dir, *, params=None, infinity_disparity: float | None = None, seed: int = 0,
                value_range=None, client=None, workers: int | None = None, device: str = "auto",
                overwrite: bool = False, callback=None, command: str | None = None) -> BatchReport:
    """Deblur each input blindly (:func:`~napari_lfdeblur.blind.blind_deblur`) into ``out_dir``.

    The input named ``name`` gives ``out_dir/<name stem>.npz`` (the sharp
    estimate, float32) and ``<name stem>.path.json`` (the estimated path),
    equal to ``blind_deblur(read_lightfield(input, value_range=value_range), params=params,
    seed=item_seed(seed, name, 0), ...)`` on the same device and torch
    thread count (one per task here).

    Parameters
    ----------
    inputs : str, Path or sequence of them
        A glob pattern or light-field files or folders; names must be unique.
    out_dir : str or Path
    params : BlindParams, dict or str, optional
        As in :func:`~napari_lfdeblur.blind.blind_deblur` (a preset name, a
        nested dict, or parameters); default the ``default`` preset.
    infinity_disparity : float, optional
        ``d_inf`` for every item; by default each input's own: the one its
        file states (:func:`~napari_lfdeblur.io.read_lightfield_with_metadata`,
        as ``simulate_dataset``'s outputs do), else 0. An input that states
        one that is not a finite number is a failed item.
    seed : int, default 0
    {common}

    Returns
    -------
    BatchReport
    """
    from .._lightfield import check_number
    from ..blind import BlindParams

    if params is None or isinstance(params, str):
        params = BlindParams.preset(params or "default")
    elif isinstance(params, dict):
        params = BlindParams.from_dict(params)
    elif not isinstance(params, BlindParams):
        raise TypeError(f"params must be BlindParams, a dict or a preset name; got {type(params).__name__}")
    item_seed(seed, "", 0)
    paths = expand_inputs(inputs)
    out_dir = Path(out_dir)
    reading = _reading(value_range)
    d_inf = None if infinity_disparity is None else check_number(infinity_disparity, "infinity_disparity")
    parameters = {"params": json.loads(params.to_json()), "infinity_disparity": d_inf, **reading}
    version = _version()
    specs = [make_spec("deblur", p, 0, out_dir / f"{_stem(p)}.npz",
                       parameters=parameters, seed=seed, overwrite=overwrite, version=version) for p in paths]
    command = command or _call_text("deblur_many", paths, out_dir, params=parameters["params"], seed=seed,
                                    infinity_disparity=d_inf, **reading)
    card = {"kind": "deblur", "command": command, "parameters": parameters, "seed": seed, "version": version}
    return run_batch(specs, out_dir, client=client, workers=workers, device=device, card=card, callback=callback)


simulate_dataset.__doc__ = simulate_dataset.__doc__.replace("{common}", _COMMON_DOC)
deblur_many.__doc__ = deblur_many.__doc__.replace("{common}", _COMMON_DOC)
