"""napari writer contributions: save a light-field Image layer.

One writer per format (``.npz``, ``.tif``, ``.h5``); each takes a single
Image layer whose data is 4D ``(V, U, Y, X)`` (or 5D RGB) and writes it with
:func:`napari_lfdeblur.io.write_lightfield` (float32, lossless, atomic).
The layer's metadata goes with it; a camera path in
``metadata['control_points']`` is also written as ``<name>.path.json``.
An existing file is never replaced: save under a new name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import write_lightfield
from ..io._write import sidecar_path_json

__all__ = ["write_npz", "write_tiff", "write_h5", "write_layer"]


def write_layer(path: str, data, attributes: dict, suffix: str) -> list[str]:
    """Write one Image layer's light field to ``path`` (``suffix`` added if missing).

    Returns
    -------
    list of str
        The written path(s).

    Raises
    ------
    ValueError
        If the layer is not a 4D (5D RGB) light field.
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
    written = write_lightfield(p, arr, metadata=meta, control_points=cp)
    out = [str(written)]
    if cp is not None:
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
