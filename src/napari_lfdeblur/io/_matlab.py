"""Light Field Toolbox for MATLAB ``.mat`` files (v5 and v7.3).

The toolbox stores the decoded light field as variable ``LF`` indexed
``(j, i, l, k, c)`` = ``(v, u, y, x, c)``, where the fourth colour channel is
a weight (confidence) channel that we drop. MATLAB v7.3 files are HDF5 and
store the axes in reverse order, ``(c, k, l, i, j)``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._arrays import kept_views
from ._common import (LightFieldFormatError, LightFieldReadError, check_memory, names_the_file, to_float01,
                      validate_lightfield)


def _small_metadata(obj, depth=0):
    """Best-effort conversion of a loaded MATLAB value to JSON-friendly data."""
    if depth > 4:
        return None
    if isinstance(obj, np.ndarray):
        if obj.dtype.names:  # struct array
            if obj.size != 1:
                return None
            return {n: _small_metadata(obj[n].reshape(-1)[0], depth + 1) for n in obj.dtype.names}
        if obj.dtype == object:
            if obj.size == 1:
                return _small_metadata(obj.reshape(-1)[0], depth + 1)
            return None
        if obj.dtype.kind in "US":
            return str(obj.reshape(-1)[0]) if obj.size == 1 else [str(s) for s in obj.reshape(-1)[:64]]
        if obj.size <= 64:
            arr = obj.squeeze()
            return arr.item() if arr.ndim == 0 else arr.tolist()
        return None
    if isinstance(obj, (int, float, str, bool)):
        return obj
    if isinstance(obj, np.generic):
        return obj.item()
    return None


def is_hdf5(path: Path) -> bool:
    """Whether ``path`` is an HDF5 file (a MATLAB v7.3 ``.mat``), from its first 1024 bytes."""
    with open(path, "rb") as fh:
        head = fh.read(1024)
    # MATLAB v7.3 files start with a 512-byte text header, then the HDF5 signature
    return b"\x89HDF\r\n\x1a\n" in head


#: float data within [-OVERSHOOT, 1 + OVERSHOOT] is taken as [0, 1] overshot by colour correction, and clipped
OVERSHOOT = 0.5


@names_the_file("not a readable MATLAB light field")
def read_mat(path, *, variable="LF", drop_weight=True, value_range=None, max_bytes=None, angular_crop=None):
    """Read a Light Field Toolbox ``.mat`` file (MATLAB v5 or v7.3).

    Parameters
    ----------
    variable : str
        Name of the light-field variable (default ``'LF'``).
    drop_weight : bool
        Drop the fourth (weight) channel of a 4-channel ``LF``.
    angular_crop : int or (int, int), optional
        Keep only the central views. A v7.3 file reads only those; a v5
        file is read whole, then cropped.

    Returns
    -------
    lf : ndarray, (V, U, Y, X[, C]) float32 in [0, 1]
    metadata : dict
    """
    path = Path(path)
    meta: dict = {"layout": "mat", "variable": variable}
    if is_hdf5(path):
        import h5py

        try:
            f = h5py.File(path, "r")
        except OSError as exc:
            raise LightFieldReadError(f"{path}: cannot open the MATLAB v7.3 (HDF5) file ({exc})") from None
        with f:
            if variable not in f or not isinstance(f[variable], h5py.Dataset):
                names = [k for k in f.keys() if not k.startswith("#")]
                raise LightFieldFormatError(f"{path}: no variable {variable!r} (found {names}); pass variable=")
            ds = f[variable]
            shape = tuple(reversed(ds.shape))
            meta["mat_version"] = "7.3"
            _check_shape(shape, path, variable)
            index, read, _ = kept_views(shape, None, None, angular_crop, path, meta)
            check_memory(read, ds.dtype.itemsize, path, max_bytes=max_bytes)
            try:
                raw = ds[()] if index is None else ds[index[::-1]]
            except Exception as exc:  # noqa: BLE001
                raise LightFieldReadError(f"{path}: cannot read variable {variable!r} ({exc})") from None
            raw = np.transpose(raw)  # v7.3 stores the axes reversed
            meta["variables"] = [k for k in f.keys() if not k.startswith("#")]
    else:
        import scipy.io

        try:
            info = scipy.io.whosmat(path)
        except Exception as exc:  # noqa: BLE001
            raise LightFieldReadError(f"{path}: not a readable MATLAB file ({type(exc).__name__}: {exc})") from None
        found = {name: (shape, cls) for name, shape, cls in info}
        if variable not in found:
            raise LightFieldFormatError(f"{path}: no variable {variable!r} (found {sorted(found)}); pass variable=")
        shape, cls = found[variable]
        itemsize = {"uint8": 1, "int8": 1, "uint16": 2, "int16": 2, "single": 4, "uint32": 4, "int32": 4}.get(cls, 8)
        _check_shape(shape, path, variable)
        index, read, _ = kept_views(shape, None, None, angular_crop, path, meta)
        check_memory(shape, itemsize, path, max_bytes=max_bytes, out_shape=read)  # read whole
        try:
            small = [n for n, (s, _c) in found.items() if n != variable and np.prod(s) <= 4096]
            loaded = scipy.io.loadmat(path, variable_names=[variable, *small])
        except Exception as exc:  # noqa: BLE001
            raise LightFieldReadError(f"{path}: cannot read variable {variable!r} ({type(exc).__name__}: {exc})") from None
        raw = loaded[variable] if index is None else loaded[variable][index]
        meta["mat_version"] = "5"
        meta["variables"] = sorted(found)
        extra = {n: _small_metadata(loaded[n]) for n in small}
        extra = {k: v for k, v in extra.items() if v is not None}
        if extra:
            meta["camera"] = extra
    raw = np.asarray(raw)
    if raw.ndim == 5 and raw.shape[-1] == 4 and drop_weight:
        raw = raw[..., :3]
        meta["dropped_weight_channel"] = True
    elif raw.ndim == 5 and raw.shape[-1] == 2 and drop_weight:  # gray + weight
        raw = raw[..., :1]
        meta["dropped_weight_channel"] = True
    meta["file_dtype"] = str(raw.dtype)
    raw = validate_lightfield(raw, path)
    if value_range is None and np.issubdtype(raw.dtype, np.floating) and raw.size and np.isfinite(raw).all():
        # the toolbox's float light fields are nominally in [0, 1]; colour correction can overshoot a little,
        # so clip that instead of refusing; data on another scale (0..255, say) is refused, with the hint
        if -OVERSHOOT <= float(raw.min()) and float(raw.max()) <= 1 + OVERSHOOT:
            value_range = (0.0, 1.0)
    return to_float01(np.ascontiguousarray(raw), path, value_range=value_range), meta


def _check_shape(shape, path, variable):
    if len(shape) not in (4, 5):
        raise LightFieldFormatError(
            f"{path}: variable {variable!r} has shape {tuple(shape)}; a light field is 4D (V, U, Y, X) or "
            f"5D (V, U, Y, X, C)"
        )
