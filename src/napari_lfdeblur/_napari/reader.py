"""napari reader contribution: open a light field as a 4D/5D Image layer.

A file that holds the camera path it was blurred or restored with (as
``simulate_blur``'s, ``deconvolve``'s and ``blind_deblur``'s outputs written
by ``write_lightfield`` or the ``lfdeblur`` commands do) also opens that path,
as the widgets draw it: a Shapes layer ``'<name> path'`` over the centre view.

``napari_get_reader(path)`` claims only paths that hold a light field (a
folder of views, an ``.eslf.png``, a Light Field Toolbox ``.mat``, or a
4D/5D ``.npy``/``.npz``/TIFF/HDF5 array) and returns None for anything else,
so napari's own readers still open ordinary images. It never raises.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..io import probe_layout, read_lightfield_with_metadata
from ..io._write import check_path_field
from .layers import lightfield_layer_data, path_layer_data

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
    list of layer data tuples
        First ``(data, kwargs, 'image')``: ``data`` is ``(V, U, Y, X[, C])``
        float32 in [0, 1]; ``kwargs`` has ``axis_labels=('v', 'u', 'y', 'x')``,
        ``rgb`` (True for colour), ``name`` and ``metadata`` (``source``,
        ``layout``, ``camera`` when known, ``control_points`` when the file
        holds a camera path, ...). Then, when the file holds a valid camera
        path, ``(shapes, kwargs, 'shapes')`` drawing it
        (:func:`~napari_lfdeblur._napari.layers.path_layer_data`, sampled at
        the file's ``n_times``, else 32; its metadata holds the file's
        ``n_times`` and ``infinity_disparity``). A path the file states badly
        draws nothing; the light field opens all the same.
    """
    p = Path(_single_path(path))
    lf, meta = read_lightfield_with_metadata(p, **options)
    meta = {**meta, "kind": "input"}
    name = p.name
    for suffix in (".eslf.png", ".png", ".npz", ".npy", ".tiff", ".tif", ".hdf5", ".h5", ".mat"):
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            name = name[: -len(suffix)]
            break
    name = name or str(p)
    layers = [lightfield_layer_data(lf, name=name, metadata=meta)]
    if meta.get("control_points") is not None:
        try:
            stated = meta.get("n_times")
            n_times = 32 if stated is None else check_path_field("n_times", stated, p.name)
            layers.append(path_layer_data(meta["control_points"], lf.shape, n_times=n_times, name=f"{name} path",
                                          infinity_disparity=meta.get("infinity_disparity"),
                                          metadata={"source_layer": name,  # the views the file says it is for
                                                    **({"view_shape": meta["view_shape"]} if "view_shape" in meta
                                                       else {})}))
        except (TypeError, ValueError):
            pass  # not a path this package can draw: the light field alone, its metadata as the file said
    return layers
