"""napari writer contributions: save a light-field Image layer, or a camera path.

One writer per format (``.npz``, ``.tif``, ``.h5``); each takes a single
Image layer whose data is 4D ``(V, U, Y, X)`` (or 5D RGB) and writes it with
:func:`napari_lfdeblur.io.write_lightfield` (float32, lossless, atomic).
The layer's metadata goes with it; a camera path in
``metadata['control_points']`` is also written as ``<name>.path.json``,
unless that file is there for another format of the same name (the layer
saved as ``.npz``, then as ``.tif``): the file keeps the path itself.
A path layer (a Shapes layer holding ``metadata['control_points']``, as the
widgets and the reader add them) is saved as a path JSON file.
An existing file is never replaced: save under a new name.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from ..io import PATH_FIELDS, write_lightfield
from ..io._write import path_json_owner, sidecar_path_json
from ..path import save_path_json

__all__ = ["write_npz", "write_tiff", "write_h5", "write_layer", "write_path_json", "LayerNotSaved"]


class LayerNotSaved(RuntimeError):
    """A layer this plugin's writer cannot save, and why. Not a ValueError: napari takes a writer's
    ValueError for "no writer here" and says only that, dropping the reason."""


def _says_why(write):
    """The writer ``write``, whose ValueError and TypeError become :class:`LayerNotSaved` (napari shows it);
    an existing file's FileExistsError says what a napari user can do (the API's ``overwrite=`` is not theirs)."""
    @functools.wraps(write)
    def writer(*args, **kwargs):
        try:
            return write(*args, **kwargs)
        except (ValueError, TypeError) as exc:
            raise LayerNotSaved(str(exc)) from None
        except FileExistsError as exc:
            where = exc.filename or str(exc).split(" exists")[0]
            raise FileExistsError(f"{where} exists; napari-lfdeblur never replaces a file: save under a new name, "
                                  "or move that file away") from None
    return writer


@_says_why
def write_layer(path: str, data, attributes: dict, suffix: str) -> list[str]:
    """Write one Image layer's light field to ``path`` (``suffix`` added if missing).

    Returns
    -------
    list of str
        The written path(s).

    Raises
    ------
    LayerNotSaved
        If the layer is not a 4D (5D RGB) light field, or one
        :func:`~napari_lfdeblur.io.write_lightfield` refuses (NaN, say).
    FileExistsError
        If ``path`` exists.
    """
    p = Path(path)
    allowed = {".npz": (".npz",), ".tif": (".tif", ".tiff"), ".h5": (".h5", ".hdf5")}[suffix]
    if p.suffix.lower() not in allowed:
        p = p.with_name(p.name + suffix)
    arr = np.asarray(data)
    if arr.ndim not in (4, 5):
        raise ValueError(
            f"layer {attributes.get('name', '')!r} has shape {arr.shape}; only 4D (V, U, Y, X) or 5D RGB "
            f"light fields can be saved in this format by napari-lfdeblur"
        )
    meta = dict(attributes.get("metadata") or {})
    cp = meta.pop("control_points", None)
    meta = {"layer_name": attributes.get("name"), **meta}  # made JSON-friendly by write_lightfield
    owner = path_json_owner(p)  # a path file beside that is another file's is left to it
    written = write_lightfield(p, arr, metadata=meta, control_points=cp)
    out = [str(written)]
    if cp is not None and owner is None:
        out.append(str(sidecar_path_json(Path(written), "npz")))
    return out


def write_npz(path: str, data, attributes: dict) -> list[str]:
    """npe2 writer: a light-field Image layer to ``.npz``."""
    return write_layer(path, data, attributes, ".npz")


def write_tiff(path: str, data, attributes: dict) -> list[str]:
    """npe2 writer: a light-field Image layer to a 4D/5D ``.tif``."""
    return write_layer(path, data, attributes, ".tif")


def write_h5(path: str, data, attributes: dict) -> list[str]:
    """npe2 writer: a light-field Image layer to ``.h5`` (dataset ``LF``)."""
    return write_layer(path, data, attributes, ".h5")


@_says_why
def write_path_json(path: str, data, attributes: dict) -> list[str]:
    """npe2 writer: the camera path of a path layer to a path JSON file.

    The file is what :func:`napari_lfdeblur.path.save_path_json` writes: the
    control points, and the ``n_times``, ``infinity_disparity`` and
    ``view_shape`` the layer states, so that the *4D deconvolution* widget,
    ``lfdeblur deconvolve`` and :func:`~napari_lfdeblur.path.read_path_json`
    take the whole blur model back (and can tell a path for views of
    another size). ``.json`` is added to ``path`` if missing.

    Raises
    ------
    LayerNotSaved
        If the layer holds no valid camera path (``metadata['control_points']``).
    FileExistsError
        If the file exists.
    """
    p = Path(path)
    if p.suffix.lower() != ".json":
        p = p.with_name(p.name + ".json")
    meta = attributes.get("metadata") or {}
    name = attributes.get("name", "")
    if meta.get("control_points") is None:
        raise ValueError(f"layer {name!r} holds no camera path (metadata['control_points']); only path layers, "
                         "such as those the napari-lfdeblur widgets add, can be saved as a path JSON")
    try:
        extra = {key: meta[key] for key in PATH_FIELDS if key in meta}
        return [str(save_path_json(p, meta["control_points"], **extra))]
    except (TypeError, ValueError) as exc:  # a malformed path, or a field JSON cannot hold
        raise ValueError(f"layer {name!r}: {exc}") from None
