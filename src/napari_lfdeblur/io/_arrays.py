"""Array files: ``.npy``, ``.npz``, TIFF (4D/5D) and HDF5.

Shapes and dtypes are read from the headers first, so the memory check runs
before any pixel data is loaded.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ._common import (LightFieldFormatError, LightFieldReadError, central_views, check_memory, names_the_file,
                      to_float01, validate_lightfield)

_AXIS_ALIASES = {"v": "v", "u": "u", "y": "y", "x": "x", "c": "c", "s": "c", "channel": "c", "channels": "c",
                 "rgb": "c", "color": "c", "colour": "c"}
METADATA_KEY = "lfdeblur_metadata"  # JSON metadata stored by write_lightfield


def parse_axes(axes, ndim, path) -> tuple[int, ...] | None:
    """Permutation that takes an array whose axes are named ``axes`` to
    ``(v, u, y, x[, c])``. ``axes`` is a string (``'vuyxc'``, ``'v,u,y,x'``)
    or a sequence of names; None means already in order."""
    if axes is None:
        return None
    if isinstance(axes, bytes):
        axes = axes.decode()
    if isinstance(axes, str):
        names = [a.strip() for a in axes.split(",")] if "," in axes else list(axes.strip())
    else:
        names = [a.decode() if isinstance(a, bytes) else str(a) for a in axes]
    try:
        names = [_AXIS_ALIASES[n.lower()] for n in names]
    except KeyError as exc:
        raise LightFieldFormatError(
            f"{path}: unknown axis name {exc.args[0]!r} in axes={axes!r}; use the letters v, u, y, x, c"
        ) from None
    if len(names) != ndim:
        raise LightFieldFormatError(f"{path}: axes={axes!r} names {len(names)} axes but the data has {ndim}")
    want = ["v", "u", "y", "x", "c"][:ndim]
    if sorted(names) != sorted(want):
        raise LightFieldFormatError(f"{path}: axes={axes!r} must name each of {''.join(want)} once")
    return tuple(names.index(a) for a in want)


def kept_views(shape, axes, grid, angular_crop, path, meta):
    """Where the views that ``angular_crop`` keeps lie in an array as stored.

    ``shape`` is the stored array's, ``axes`` and ``grid`` as the readers
    take them. Returns ``(index, read_shape, grid)``: the index into the
    stored array (None: all of it), the shape that index reads, and the
    ``(V, U)`` grid of a stack of views after the crop (None when not a
    stack). Notes the crop in ``meta``.
    """
    if angular_crop is None:
        return None, tuple(shape), grid
    if grid is not None:  # a row-major stack of V*U views
        V, U = (int(g) for g in grid)
        sv, su = central_views(V, U, angular_crop, path)
        rows = [r * U + c for r in range(V)[sv] for c in range(U)[su]]
        index, read = (rows,), (len(rows),) + tuple(shape[1:])
        grid = (sv.stop - sv.start, su.stop - su.start)
    else:
        perm = parse_axes(axes, len(shape), path) or tuple(range(len(shape)))
        sv, su = central_views(shape[perm[0]], shape[perm[1]], angular_crop, path)
        index, read = [slice(None)] * len(shape), list(shape)
        index[perm[0]], index[perm[1]] = sv, su
        read[perm[0]], read[perm[1]] = sv.stop - sv.start, su.stop - su.start
        index, read = tuple(index), tuple(read)
    meta["angular_crop"] = [sv.stop - sv.start, su.stop - su.start]
    return index, read, grid


def _finish(raw, path, meta, axes, value_range, grid=None):
    raw = np.asarray(raw)
    if grid is not None:  # a stack of V*U views, row-major
        V, U = (int(g) for g in grid)
        raw = raw.reshape((V, U) + raw.shape[1:])
        meta["grid"] = [V, U]
    perm = parse_axes(axes, raw.ndim, path)
    if perm is not None:
        raw = np.transpose(raw, perm)
        meta["axes_in_file"] = axes if isinstance(axes, str) else list(axes)
    meta["file_dtype"] = str(raw.dtype)
    raw = validate_lightfield(raw, path)
    return to_float01(np.ascontiguousarray(raw), path, value_range=value_range), meta


def _shape_error(shape, path, what="the array", grid=None):
    """Raise on a shape that cannot be a light field (without loading data).

    With ``grid=(V, U)`` a 3D/4D stack of ``V*U`` views is accepted."""
    if grid is not None:
        V, U = (int(g) for g in grid)
        if len(shape) not in (3, 4) or shape[0] != V * U:
            raise LightFieldFormatError(
                f"{path}: grid={tuple(grid)} needs a stack of {V * U} views, shape ({V * U}, Y, X[, C]); "
                f"{what} has shape {tuple(shape)}"
            )
        return
    if len(shape) in (2, 3):
        raise LightFieldFormatError(
            f"{path}: {what} is {len(shape)}D, shape {tuple(shape)}; a light field is 4D (V, U, Y, X) or "
            f"5D (V, U, Y, X, C). A single image or a stack of views is not enough: arrange the views "
            f"on a (V, U) grid (for a stack of views pass grid=(V, U); for a mosaic image pass "
            f"layout='eslf' or layout='mosaic')"
        )
    if len(shape) not in (4, 5):
        raise LightFieldFormatError(
            f"{path}: {what} has shape {tuple(shape)}; a light field is 4D (V, U, Y, X) or 5D (V, U, Y, X, C)"
        )


def looks_like_image_stack(shape) -> bool:
    """Whether a 4D array without stated axes is a stack of colour images ``(N, H, W, 3 or 4)`` rather than a
    light field: read as ``(V, U, Y, X)`` its views would be 3 or 4 px wide and at least four times as tall."""
    return len(shape) == 4 and shape[3] in (3, 4) and shape[2] >= 4 * shape[3]


def _image_stack_error(shape, path, what, axes, grid):
    """Refuse a stack of colour images (:func:`looks_like_image_stack`) unless ``axes`` or ``grid`` says how to
    read it."""
    if axes is None and grid is None and looks_like_image_stack(shape):
        raise LightFieldFormatError(
            f"{path}: {what} has shape {tuple(shape)}, a stack of {shape[0]} colour images of {shape[1]}x{shape[2]} "
            f"rather than a light field of {shape[2]}x{shape[3]} px views; pass grid=(V, U) to arrange the images "
            f"as a V x U light field (or axes='vuyx' to read it as it is)"
        )


# ------------------------------------------------------------------ .npy / .npz


def npy_header(path) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype from a .npy header, without reading the data."""
    return _npy_header(path)[:2]


def _npy_header(path):
    """Shape, dtype and the offset of the data in a .npy file."""
    with open(path, "rb") as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        else:
            shape, _fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        return tuple(shape), np.dtype(dtype), fh.tell()


def npy_may_be_lightfield(path) -> bool:
    """Whether a .npy file's header describes a light field the reader can take: 4D or 5D, not empty, of
    numbers (not complex or objects), with all its data in the file (not truncated)."""
    shape, dtype, offset = _npy_header(path)
    return (len(shape) in (4, 5) and min(shape) > 0 and not looks_like_image_stack(shape) and dtype.kind in "biuf"
            and Path(path).stat().st_size >= offset + int(np.prod(shape)) * dtype.itemsize)


def read_npy(path, *, axes=None, grid=None, value_range=None, max_bytes=None, angular_crop=None):
    path = Path(path)
    try:
        shape, dtype = npy_header(path)
    except Exception as exc:  # noqa: BLE001
        raise LightFieldReadError(f"{path}: not a readable .npy file ({type(exc).__name__}: {exc})") from None
    _shape_error(shape, path, grid=grid)
    _image_stack_error(shape, path, "the array", axes, grid)
    meta: dict = {"layout": "npy"}
    index, read, grid = kept_views(shape, axes, grid, angular_crop, path, meta)
    check_memory(read, dtype.itemsize, path, max_bytes=max_bytes)  # a memory map reads only the kept views
    try:
        if index is None:
            raw = np.load(path, allow_pickle=False)
        else:
            raw = np.array(np.load(path, allow_pickle=False, mmap_mode="r")[index])
    except Exception as exc:  # noqa: BLE001
        raise LightFieldReadError(f"{path}: cannot read the data, the file may be truncated ({exc})") from None
    return _finish(raw, path, meta, axes, value_range, grid)


def npz_headers(path: Path) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Shape and dtype of each array in an .npz, from the headers, without reading the data.

    Parameters
    ----------
    path : Path
        The .npz file.

    Returns
    -------
    dict
        Array name (without ``.npy``) to ``(shape, dtype)``.
    """
    out = {}
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with zf.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                if version == (1, 0):
                    shape, _fortran, dtype = np.lib.format.read_array_header_1_0(fh)
                else:
                    shape, _fortran, dtype = np.lib.format.read_array_header_2_0(fh)
            out[info.filename[:-4]] = (tuple(shape), np.dtype(dtype))
    return out


def npz_lightfield_key(path, headers=None) -> str | None:
    """The key of the light field in an .npz: ``lf`` (or ``LF``), or the only
    4D/5D array. None when there is none."""
    headers = npz_headers(Path(path)) if headers is None else headers
    for k in ("lf", "LF"):
        if k in headers:
            return k
    cands = [k for k, (s, _d) in headers.items() if len(s) in (4, 5)]
    if len(cands) == 1:
        return cands[0]
    arrays = [k for k in headers if k != METADATA_KEY and k != "control_points"]
    if len(arrays) == 1:
        return arrays[0]
    return None


def read_npz(path, *, key=None, axes=None, grid=None, value_range=None, max_bytes=None, angular_crop=None):
    path = Path(path)
    try:
        headers = npz_headers(path)
    except Exception as exc:  # noqa: BLE001
        raise LightFieldReadError(f"{path}: not a readable .npz file ({type(exc).__name__}: {exc})") from None
    if key is None:
        key = npz_lightfield_key(path, headers)
        if key is None:
            raise LightFieldFormatError(
                f"{path}: no array named 'lf' and not exactly one 4D/5D array (found {sorted(headers)}); pass key="
            )
    elif key not in headers:
        raise LightFieldFormatError(f"{path}: no array {key!r} (found {sorted(headers)})")
    shape, dtype = headers[key]
    _shape_error(shape, path, f"array {key!r}", grid)
    _image_stack_error(shape, path, f"array {key!r}", axes, grid)
    meta: dict = {"layout": "npz", "key": key}
    index, read, grid = kept_views(shape, axes, grid, angular_crop, path, meta)
    check_memory(shape, dtype.itemsize, path, max_bytes=max_bytes, out_shape=read)  # read whole
    try:
        with np.load(path, allow_pickle=False) as z:
            raw = z[key] if index is None else z[key][index]
            if METADATA_KEY in z.files:
                meta.update(_load_json_meta(z[METADATA_KEY]))
            if "control_points" in z.files and key != "control_points":
                meta["control_points"] = np.asarray(z["control_points"], float).tolist()
    except Exception as exc:  # noqa: BLE001
        raise LightFieldReadError(f"{path}: cannot read array {key!r} ({type(exc).__name__}: {exc})") from None
    meta["layout"] = "npz"
    return _finish(raw, path, meta, axes, value_range, grid)


def _load_json_meta(value) -> dict:
    try:
        s = value.item() if isinstance(value, np.ndarray) else value
        if isinstance(s, bytes):
            s = s.decode()
        doc = json.loads(s)
        if isinstance(doc, dict):
            doc = {k: v for k, v in doc.items() if k not in ("source", "layout")}
            return {"saved_metadata": doc} if doc else {}
    except Exception:  # noqa: BLE001 - metadata is best effort
        pass
    return {}


# ------------------------------------------------------------------ TIFF


#: what tifffile logs when pages or data are missing (it reads on, with fewer pages)
_TIFF_BROKEN = ("invalid page offset", "failed to reshape", "truncat")


def tiff_shape(path) -> tuple[tuple[int, ...], np.dtype, dict]:
    """Shape, dtype and metadata of a TIFF's first series, from its tags; raises on a truncated or corrupt file.

    tifffile only logs what it finds broken (a page offset past the end, a series that does not fit its
    stated shape) and reads on; those records become a :class:`LightFieldReadError` here.
    """
    import logging

    import tifffile

    broken: list[str] = []
    handler = logging.Handler(logging.WARNING)  # only what says the file lacks data; tifffile logs other news too
    handler.emit = lambda record: broken.extend(
        [record.getMessage()] if any(k in record.getMessage() for k in _TIFF_BROKEN) else [])
    log = logging.getLogger("tifffile")
    log.addHandler(handler)
    try:
        with tifffile.TiffFile(path) as tif:
            s = tif.series[0]
            meta = {}
            if tif.shaped_metadata:
                meta = dict(tif.shaped_metadata[0])
            meta["_series_axes"] = s.axes
            shape, dtype = tuple(s.shape), np.dtype(s.dtype)
    finally:
        log.removeHandler(handler)
    if broken:
        raise LightFieldReadError(f"{path}: a truncated or corrupt TIFF file (tifffile: {broken[0]})")
    return shape, dtype, meta


def read_tiff(path, *, axes=None, grid=None, value_range=None, max_bytes=None, angular_crop=None):
    import tifffile

    path = Path(path)
    try:
        shape, dtype, tmeta = tiff_shape(path)
    except LightFieldReadError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise LightFieldReadError(f"{path}: not a readable TIFF file ({type(exc).__name__}: {exc})") from None
    meta: dict = {"layout": "tiff"}
    if axes is None and "lfdeblur_axes" in tmeta:
        axes = tmeta["lfdeblur_axes"]
    if len(shape) == 6 and shape[-1] == 1:
        shape = shape[:-1]
    if grid is None and len(shape) == 4 and tmeta.get("_series_axes", "").endswith("S"):
        raise LightFieldFormatError(
            f"{path}: the TIFF is a stack of {shape[0]} colour images of {shape[1]}x{shape[2]}, shape "
            f"{tuple(shape)}; pass grid=(V, U) to arrange them as a V x U light field"
        )
    _shape_error(shape, path, "the TIFF image series", grid)
    index, read, grid = kept_views(shape, axes, grid, angular_crop, path, meta)
    check_memory(shape, dtype.itemsize, path, max_bytes=max_bytes, out_shape=read)  # decoded whole
    try:
        raw = tifffile.imread(path)
    except Exception as exc:  # noqa: BLE001
        raise LightFieldReadError(f"{path}: cannot decode the TIFF data ({type(exc).__name__}: {exc})") from None
    raw = raw.reshape(shape)
    if index is not None:
        raw = raw[index]
    if METADATA_KEY in tmeta:
        meta.update(_load_json_meta(tmeta[METADATA_KEY]))
    return _finish(raw, path, meta, axes, value_range, grid)


# ------------------------------------------------------------------ HDF5


def _attrs_to_dict(attrs, limit=64) -> dict:
    out = {}
    for k, v in attrs.items():
        if k in (METADATA_KEY,):
            continue
        if isinstance(v, bytes):
            v = v.decode(errors="replace")
        elif isinstance(v, np.ndarray):
            if v.size > limit:
                continue
            v = [x.decode(errors="replace") if isinstance(x, bytes) else x for x in v.tolist()]
        elif isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, (str, int, float, bool, list)):
            out[k] = v
    return out


def h5_lightfield_name(f) -> str | None:
    """Name of the light-field dataset in an open h5py File: ``LF`` / ``lf``,
    or the only 4D/5D dataset anywhere in the file."""
    import h5py

    for k in ("LF", "lf"):
        if k in f and isinstance(f[k], h5py.Dataset):
            return k
    found = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.ndim in (4, 5):
            found.append(name)

    f.visititems(visit)
    return found[0] if len(found) == 1 else None


@names_the_file("not a readable HDF5 light field")
def read_h5(path, *, dataset=None, axes=None, grid=None, value_range=None, max_bytes=None, angular_crop=None):
    import h5py

    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except Exception as exc:  # noqa: BLE001
        raise LightFieldReadError(f"{path}: not a readable HDF5 file ({type(exc).__name__}: {exc})") from None
    with f:
        name = dataset or h5_lightfield_name(f)
        if name is None or name not in f or not isinstance(f[name], h5py.Dataset):
            datasets = []
            f.visititems(lambda n, o: datasets.append(f"{n} {o.shape}") if isinstance(o, h5py.Dataset) else None)
            what = f"no dataset {dataset!r}" if dataset else "no dataset 'LF' and not exactly one 4D/5D dataset"
            raise LightFieldFormatError(f"{path}: {what} (found {datasets[:10]}); pass dataset=")
        ds = f[name]
        _shape_error(ds.shape, path, f"dataset {name!r}", grid)
        if axes is None:
            for attr in ("axes", "axis_order", "dims", "dimension_order", "lfdeblur_axes"):
                if attr in ds.attrs:
                    axes = ds.attrs[attr]
                    if isinstance(axes, np.ndarray):
                        axes = [a.decode() if isinstance(a, bytes) else str(a) for a in axes.tolist()]
                    break
        meta: dict = {"layout": "h5", "dataset": name}
        index, read, grid = kept_views(ds.shape, axes, grid, angular_crop, path, meta)
        check_memory(read, ds.dtype.itemsize, path, max_bytes=max_bytes)  # HDF5 reads only the kept views
        try:
            raw = ds[()] if index is None else ds[index]
        except Exception as exc:  # noqa: BLE001
            raise LightFieldReadError(f"{path}: cannot read dataset {name!r} ({type(exc).__name__}: {exc})") from None
        cam = {**_attrs_to_dict(f.attrs), **_attrs_to_dict(ds.attrs)}
        cam = {k: v for k, v in cam.items() if k not in ("axes", "axis_order", "dims", "dimension_order",
                                                          "lfdeblur_axes")}
        if "control_points" in cam:
            meta["control_points"] = cam.pop("control_points")
        if cam:
            meta["camera"] = cam
        for holder in (ds.attrs, f.attrs):
            if METADATA_KEY in holder:
                meta.update(_load_json_meta(holder[METADATA_KEY]))
                break
    return _finish(raw, path, meta, axes, value_range, grid)
