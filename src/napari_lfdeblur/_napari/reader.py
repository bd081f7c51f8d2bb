"""napari reader contribution: open a light field as one 4D/5D Image layer.

``napari_get_reader(path)`` claims only paths that hold a light field (a
folder of views, an ``.eslf.png``, a Light Field Toolbox ``.mat``, or a
4D/5D ``.npy``/``.npz``/TIFF/HDF5 array) and returns None for anything else,
so napari's own readers still open ordinary images. It never raises.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..io import probe_layout, read_lightfield_with_metadata
from .layers import lightfield_layer_data

__all__ = ["napari_get_reader", "read_lightfield_layer"]


def _single_path(path):
    if isinstance(path, (list, tuple)):
        if len(path) != 1:
            return None
        path = path[0]
    try:
        return os.fspath(path)
    except TypeError:
        return None


def napari_get_reader(path):
    """Return :func:`read_lightfield_layer` if ``path`` is a light field, else None.

    Parameters
    ----------
    path : str or list of str
        One path (a list of exactly one path is accepted too).

    Returns
    -------
    callable or None
    """
    try:
        p = _single_path(path)
        if p is None or probe_layout(p) is None:
            return None
    except Exception:  # noqa: BLE001 - a reader hook must never raise
        return None
    return read_lightfield_layer


def read_lightfield_layer(path, **options):
    """Read a light field into a napari layer data tuple.

    Parameters
    ----------
    path : str or Path (or a list of one)
    **options
        Passed to :func:`napari_lfdeblur.io.read_lightfield_with_metadata`
        (``angular_crop``, ``layout``, ...); napari itself passes none.

    Returns
    -------
    list of one tuple ``(data, kwargs, 'image')``
        ``data`` is ``(V, U, Y, X[, C])`` float32 in [0, 1]; ``kwargs`` has
        ``axis_labels=('v', 'u', 'y', 'x')``, ``rgb`` (True for colour),
        ``name`` and ``metadata`` (``source``, ``layout``, ``camera`` when
        known, ...).
    """
    p = Path(_single_path(path))
    lf, meta = read_lightfield_with_metadata(p, **options)
    meta = {**meta, "kind": "input"}
    name = p.name
    for suffix in (".eslf.png", ".png", ".npz", ".npy", ".tiff", ".tif", ".hdf5", ".h5", ".mat"):
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            name = name[: -len(suffix)]
            break
    return [lightfield_layer_data(lf, name=name or str(p), metadata=meta)]
