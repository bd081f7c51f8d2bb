"""Writing light fields: ``.npz``, ``.npy``, TIFF, HDF5, a folder of
``view_RR_CC.png`` views, and single-image mosaics. Every write goes to a
temporary name first and is renamed into place, so a failure leaves nothing
half-written, and nothing is overwritten unless ``overwrite=True``.
"""

from __future__ import annotations

import json
import re
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ._arrays import METADATA_KEY
from ._common import (
    LightFieldFormatError,
    atomic_dir,
    atomic_file,
    check_writable,
    to_float01,
    validate_lightfield,
)
from ._mosaic import LAYOUT_KEY, lightfield_to_mosaic, mosaic_layout_text
from ._png import write_png

WRITE_LAYOUTS = ("npz", "npy", "tiff", "h5", "views", "mosaic", "eslf")
_SUFFIX_LAYOUT = {".npz": "npz", ".npy": "npy", ".tif": "tiff", ".tiff": "tiff", ".h5": "h5", ".hdf5": "h5"}
_VIEW_NAME = re.compile(r"^view_\d+_\d+\.(png|tif)$")
SIDECAR_NAMES = ("lightfield.json", "path.json")


def jsonable(obj):
    """A JSON-serialisable copy of ``obj``.

    Dict keys become strings, tuples lists, numpy scalars Python numbers and
    paths strings. Arrays of up to 4096 elements become nested lists, larger
    ones a short ``"<array shape dtype>"`` description; any other object
    becomes its ``repr``.
    """
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist() if obj.size <= 4096 else f"<array {obj.shape} {obj.dtype}>"
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    if obj is None or isinstance(obj, (str, int, float, bool)):
        return obj
    return repr(obj)


def _quantize(lf: np.ndarray, bit_depth: int) -> np.ndarray:
    dtype = {8: np.uint8, 16: np.uint16}[bit_depth]
    top = float(np.iinfo(dtype).max)
    return np.rint(np.clip(lf, 0.0, 1.0) * top).astype(dtype)


def sidecar_path_json(path, layout: str | None = None) -> Path:
    """Where :func:`write_lightfield` puts the camera path of a light field written to ``path``.

    ``<name>.path.json`` beside a file, ``path.json`` inside a folder of
    views; ``layout`` as :func:`write_lightfield` takes it (None: from the
    suffix). Raises LightFieldFormatError when the suffix names no format.
    """
    path = Path(path)
    if _layout_of(path, layout) == "views":
        return path / "path.json"
    return path_json_beside(path)


def path_json_beside(path) -> Path:
    """``<name>.path.json`` beside the file ``path`` (its last suffix replaced), ``path.json`` in a folder."""
    path = Path(path)
    if path.is_dir():
        return path / "path.json"
    return path.with_name(path.name[: -len(path.suffix)] + ".path.json" if path.suffix else path.name + ".path.json")


def path_json_owner(path) -> Path | None:
    """The other light field that ``<name>.path.json`` beside the file ``path`` belongs to, if it is there.

    ``a.npy`` and ``a.npz`` share ``a.path.json``; the file names the light
    field it was written for (``lightfield``). None when it names ``path``,
    names nothing, cannot be read, or the file it names is gone.
    """
    path = Path(path)
    named = _stated_lightfield(path)
    if named is None:
        return None
    named = Path(named)
    if named.name != path.name and path_json_beside(named) == Path(path_json_beside(path).name) and (
            path.parent / named).exists():
        return path.parent / named
    return None


def path_json_names(path) -> bool:
    """Whether ``<name>.path.json`` beside the file ``path`` is there and names ``path`` as its light field."""
    return _stated_lightfield(Path(path)) == Path(path).name


def _stated_lightfield(path: Path) -> str | None:
    """The light field (``lightfield``) that ``<name>.path.json`` beside ``path`` states; None when it states
    none or cannot be read."""
    try:
        doc = json.loads(path_json_beside(path).read_text())
    except (OSError, ValueError):
        return None
    return str(doc["lightfield"]) if isinstance(doc, dict) and "lightfield" in doc else None


def _layout_of(path: Path, layout: str | None) -> str:
    """The write layout: ``layout`` if given (and known), else from the suffix of ``path``."""
    if layout is None:
        if path.suffix.lower() in _SUFFIX_LAYOUT:
            layout = _SUFFIX_LAYOUT[path.suffix.lower()]
        elif path.suffix == "" or path.is_dir():
            layout = "views"
        else:
            raise LightFieldFormatError(
                f"{path}: cannot tell the format from the suffix {path.suffix!r}; use .npz, .npy, .tif, .h5, "
                f"a folder name without suffix, or pass layout= (one of {WRITE_LAYOUTS})"
            )
    if layout not in WRITE_LAYOUTS:
        raise ValueError(f"unknown layout {layout!r}; choose one of {WRITE_LAYOUTS}")
    return layout


def _float_lightfield(lf, path: Path) -> np.ndarray:
    """``lf`` checked and as float32 in [0, 1]; float data must be finite, integers are scaled."""
    arr = validate_lightfield(lf, "light field to write")
    if np.issubdtype(arr.dtype, np.floating):
        if not np.isfinite(arr).all():
            raise LightFieldFormatError(f"cannot write {path}: the light field contains NaN or Inf")
        return arr.astype(np.float32, copy=False)
    return to_float01(arr, "light field to write")


def _sample_depth(layout: str, path: Path, bit_depth: int | None) -> int:
    """Bits per sample: ``bit_depth``, or 8 for images and 32 (float) for array formats."""
    if layout in ("views", "mosaic", "eslf"):
        depth = 8 if bit_depth is None else bit_depth
        if depth == 32 and (layout == "views" or path.suffix.lower() == ".png"):
            raise ValueError("PNG stores 8 or 16 bits; use bit_depth=8 or 16, or a .tif/.npz for float32")
        return depth
    return 32 if bit_depth is None else bit_depth


def _write_npz(path, data, meta, cp, *, overwrite, compress):
    with atomic_file(path, overwrite=overwrite) as tmp:
        extra = {METADATA_KEY: np.array(json.dumps(meta))}
        if cp is not None:
            extra["control_points"] = cp
        with open(tmp, "wb") as fh:
            (np.savez_compressed if compress else np.savez)(fh, lf=data, **extra)


def _write_npy(path, data, meta, cp, *, overwrite, compress):
    with atomic_file(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, data, allow_pickle=False)


def _write_tiff(path, data, meta, cp, *, overwrite, compress):
    import tifffile

    with atomic_file(path, overwrite=overwrite) as tmp:
        tifffile.imwrite(
            tmp,
            data,
            photometric="rgb" if data.ndim == 5 and data.shape[4] in (3, 4) else "minisblack",
            compression="zlib" if compress else None,
            metadata={"lfdeblur_axes": "vuyxc"[: data.ndim], METADATA_KEY: json.dumps(meta)},
        )


def _write_h5(path, data, meta, cp, *, overwrite, compress):
    import h5py

    with atomic_file(path, overwrite=overwrite) as tmp:
        with h5py.File(tmp, "w") as f:
            ds = f.create_dataset(
                "LF",
                data=data,
                chunks=(1, 1) + data.shape[2:],
                compression="gzip" if compress else None,
            )
            ds.attrs["axes"] = "vuyxc"[: data.ndim]
            ds.attrs[METADATA_KEY] = json.dumps(meta)
            if cp is not None:
                ds.attrs["control_points"] = cp


def _write_mosaic(path, data, layout, *, overwrite):
    """One image, ``.png`` or ``.tif``: the view grid (``'mosaic'``) or the lenslet mosaic (``'eslf'``)."""
    if layout == "eslf" and data.shape[0] != data.shape[1]:
        raise LightFieldFormatError(f"cannot write {path} as ESLF: it needs V == U, got {data.shape[:2]}")
    img = lightfield_to_mosaic(data, "grid" if layout == "mosaic" else "eslf")
    stated = {LAYOUT_KEY: mosaic_layout_text(layout, data.shape)}  # read back without options
    with atomic_file(path, overwrite=overwrite) as tmp:
        if path.suffix.lower() in (".tif", ".tiff"):
            import tifffile

            tifffile.imwrite(tmp, img, photometric="rgb" if img.ndim == 3 else "minisblack", metadata=stated)
        elif path.suffix.lower() == ".png":
            write_png(tmp, img, text=stated)
        else:
            raise LightFieldFormatError(f"{path}: a mosaic is written as .png or .tif")


def _replaceable(name: str) -> bool:
    """Whether a file in an existing views folder is one that :func:`write_lightfield` writes."""
    return bool(_VIEW_NAME.match(name)) or name in SIDECAR_NAMES


#: metadata fields that describe a path's blur, copied into its path JSON so that a path file states them too:
#: the instants, the infinity disparity and the ``(Y, X)`` of the views the path belongs to (``p_z`` and a
#: rotation are taken about the view's centre and size: :func:`~napari_lfdeblur.path.path_view_mismatch`)
PATH_FIELDS = ("n_times", "infinity_disparity", "view_shape")


def check_path_field(key: str, value, source: str):
    """``value`` as the path field ``key`` (one of :data:`PATH_FIELDS`) that ``source`` states.

    Returns an ``int`` for ``n_times``, a ``float`` for ``infinity_disparity``
    and a tuple of two ``int`` for ``view_shape``.

    Raises
    ------
    ValueError
        When ``n_times`` is not an integer >= 2, ``infinity_disparity`` not a finite number or
        ``view_shape`` not two integers >= 1; the message names ``source``.
    """
    def whole(v, least):
        return isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= least

    if key == "view_shape":
        usable = isinstance(value, (list, tuple)) and len(value) == 2 and all(whole(v, 1) for v in value)
        need = "two whole numbers >= 1 (the views' Y, X)"
    elif key == "n_times":
        usable, need = whole(value, 2), "a whole number >= 2"
    else:
        number = isinstance(value, (int, float, np.number)) and not isinstance(value, bool)
        usable, need = number and bool(np.isfinite(value)), "a finite number"
    if not usable:
        raise ValueError(f"{source} states {key} = {value!r}, which is not {need}")
    if key == "view_shape":
        return tuple(int(v) for v in value)
    return int(value) if key == "n_times" else float(value)


def path_from_document(doc, source) -> tuple[np.ndarray, dict]:
    """The control points and the stated path fields of a path file's parsed JSON ``doc``.

    ``doc`` is an object with ``control_points`` (and optionally the
    :data:`PATH_FIELDS`) or a bare list of rows. The control points must be
    JSON numbers (not strings or booleans), as
    :func:`~napari_lfdeblur.path.validate_control_points` takes them. The
    other fields are checked where they are used (:func:`check_path_field`),
    where an option may override them.

    Returns
    -------
    control_points : ndarray, float64, shape (n, 3) or (n, 6)
    fields : dict
        The object itself, or ``{}`` for a bare list.

    Raises
    ------
    ValueError
        On malformed control points; the message names ``source`` (None:
        the caller names it).
    """
    from ..path import validate_control_points

    prefix = f"{source}: " if source else ""
    cp = doc.get("control_points") if isinstance(doc, dict) else doc
    if cp is None:
        raise ValueError(f"{source or 'the file'} has no 'control_points' entry")
    odd = [v for row in (cp if isinstance(cp, list) else []) if isinstance(row, list) for v in row
           if isinstance(v, bool) or not isinstance(v, (int, float))]
    if odd:
        raise ValueError(f"{prefix}control points must be numbers; got {odd[0]!r}")
    try:
        cp = validate_control_points(cp)
    except ValueError as exc:
        raise ValueError(f"{prefix}{exc}") from None
    return cp, doc if isinstance(doc, dict) else {}


def view_shape_note(control_points, shape, fields: dict, source) -> str | None:
    """What to tell someone who applies the path ``control_points`` from ``source`` (whose ``fields`` may state
    its ``view_shape``) to a light field of ``shape``, or None.

    :func:`~napari_lfdeblur.path.path_view_mismatch`, after ``source``; or, for a ``view_shape`` that
    :func:`check_path_field` refuses, that the path was not checked.
    """
    from ..path import path_view_mismatch

    if fields.get("view_shape") is None:
        return None
    try:
        stated = check_path_field("view_shape", fields["view_shape"], source)
    except ValueError as exc:
        return f"{exc}; the path was not checked against the views' size"
    note = path_view_mismatch(control_points, shape, stated)
    return None if note is None else f"{source}: {note}"


def _path_fields(meta: dict) -> dict:
    """The fields of the path JSON written with a light field of metadata ``meta``: its views' size too."""
    return {**{k: meta[k] for k in PATH_FIELDS if k in meta}, "view_shape": list(meta["shape"][2:4])}


def _write_views(path, data, meta, cp, *, overwrite):
    """A folder of ``view_RR_CC.png`` (1-based), ``lightfield.json`` and, with a path, ``path.json``."""
    V, U = data.shape[:2]
    width = max(2, len(str(max(V, U))))
    names = [p.name for p in path.iterdir()] if overwrite and path.is_dir() else []
    if names and all(map(_replaceable, names)) and "lightfield.json" not in names:  # (other files: atomic_dir)
        raise FileExistsError(f"{path} holds views that write_lightfield did not write (it has no lightfield.json); "
                              "refusing to replace it, choose another folder")
    with atomic_dir(path, overwrite=overwrite, replaceable=_replaceable) as tmp:
        for v in range(V):
            for u in range(U):
                write_png(tmp / f"view_{v + 1:0{width}d}_{u + 1:0{width}d}.png", data[v, u])
        (tmp / "lightfield.json").write_text(json.dumps(meta, indent=2))
        if cp is not None:
            from ..path import save_path_json

            save_path_json(tmp / "path.json", cp, **_path_fields(meta))


_ARRAY_WRITERS = {"npz": _write_npz, "npy": _write_npy, "tiff": _write_tiff, "h5": _write_h5}
#: the layouts that store the camera path in the file itself (read back by ``read_lightfield_with_metadata``)
_EMBEDS_PATH = ("npz", "tiff", "h5")


def write_lightfield(
    path,
    lf,
    *,
    overwrite: bool = False,
    bit_depth: int | None = None,
    layout: str | None = None,
    metadata: dict | None = None,
    control_points=None,
    compress: bool = True,
) -> Path:
    """Write a light field to a file or a folder of views.

    Parameters
    ----------
    path : str or Path
        Destination. The suffix picks the format: ``.npz``, ``.npy``,
        ``.tif``/``.tiff``, ``.h5``/``.hdf5``; no suffix (or an existing
        folder) writes a folder of ``view_RR_CC.png`` views, 1-based, which
        :func:`read_lightfield` reads back.
    lf : array_like, (V, U, Y, X) or (V, U, Y, X, C)
        The light field. Float data should be in [0, 1]: beyond it, a warning
        says that integer formats clip it and that a float file needs
        ``value_range`` to be read back. Integer data is scaled by its
        dtype's maximum.
    overwrite : bool
        Replace an existing file. Default False: raise FileExistsError. A
        folder is only replaced if it holds nothing but views written by us.
    bit_depth : {None, 8, 16, 32}
        Sample format. ``None``: float32 for array formats (lossless), 8-bit
        for PNG views and mosaics. 8 and 16 store unsigned integers; 32 float32.
    layout : {'npz', 'npy', 'tiff', 'h5', 'views', 'mosaic', 'eslf'}, optional
        Override the format chosen from the suffix. ``'mosaic'`` tiles the
        views into one image (``.png`` or ``.tif``); ``'eslf'`` writes the
        lenslet mosaic (pixel ``(y*V + v, x*U + u)``).
    metadata : dict, optional
        JSON-serialisable metadata stored with the data (not in ``.npy``).
    control_points : array_like (n, 3), optional
        A camera path; written next to the output as JSON by
        :func:`napari_lfdeblur.path.save_path_json` (``<name>.path.json``, or
        ``path.json`` inside a views folder), and embedded in ``.npz``/``.h5``.
        The path JSON also states ``n_times`` and ``infinity_disparity`` when
        ``metadata`` holds them, and beside a file the name of that file
        (``lightfield``): ``a.npy`` and ``a.npz`` would share
        ``a.path.json``, and a reader leaves it to the file it names while
        that file is there. Such a path JSON is left as it is (with a
        warning) when the new file keeps its path itself (``.npz``,
        ``.tif``, ``.h5``) and ``overwrite`` is False; otherwise it is a
        FileExistsError. Writing a file without a path where a path JSON
        names it (that of an earlier file of this name) removes that JSON
        with ``overwrite=True`` and is a FileExistsError without.
    compress : bool
        Compress ``.npz``, TIFF and HDF5 data (lossless).

    Returns
    -------
    Path
        The written file or folder.

    Raises
    ------
    FileExistsError
        If the destination (or the path JSON beside it, see
        ``control_points``) exists and ``overwrite`` is False.
    LightFieldFormatError
        If ``lf`` is not a light field or contains NaN/Inf, the format
        cannot be told from the suffix, or it has 2 channels and the format
        is an image (views, mosaic, ESLF: images hold 1, 3 or 4 channels).
    TypeError
        If ``metadata`` is not a mapping.
    ValueError
        On an unknown ``layout`` or ``bit_depth``, ``bit_depth=32`` for PNG,
        or, with ``control_points``, ``n_times`` or ``infinity_disparity`` in
        ``metadata`` that a path file cannot state; nothing is written then.
    """
    path = Path(path)
    layout = _layout_of(path, layout)
    if bit_depth not in (None, 8, 16, 32):
        raise ValueError(f"bit_depth must be 8, 16 or 32 (float), not {bit_depth!r}")
    arr = _float_lightfield(lf, path)
    if layout in ("views", "mosaic", "eslf") and arr.ndim == 5 and arr.shape[4] == 2:
        raise LightFieldFormatError(f"cannot write {path} as images ({layout}): an image holds 1, 3 or 4 channels, "
                                    "and this light field has 2 (a second one would be read as transparency); "
                                    "write it as .npz, .npy, .h5 or .tif")

    cp = None
    if control_points is not None:
        from ..path import validate_control_points

        cp = validate_control_points(control_points)
    if metadata is not None and not isinstance(metadata, Mapping):
        raise TypeError(f"metadata must be a dict (or None); got {type(metadata).__name__}")
    # the array's own axes and shape win over those of metadata passed along from another light field
    meta = jsonable({**(metadata or {}), "axes": "vuyxc"[: arr.ndim], "shape": list(arr.shape)})
    if cp is not None:
        meta["control_points"] = cp.tolist()
        fields = _path_fields(meta)  # checked before anything is written: a failure leaves nothing behind
        for key in ("n_times", "infinity_disparity"):
            if fields.get(key) is not None:
                check_path_field(key, fields[key], "the path")
    if layout != "views":
        check_writable(path, overwrite)  # the file itself first: its error names it, not its path file
    sidecar = sidecar_path_json(path, layout) if cp is not None else None
    owner = None
    if sidecar is not None and layout in _EMBEDS_PATH and not overwrite:
        owner = path_json_owner(path)  # a.path.json is a.npz's: a.tif keeps its path in itself only
        sidecar = None if owner is not None else sidecar
    if sidecar is not None and layout != "views":
        check_writable(sidecar, overwrite)
    pathless = cp is None and "control_points" not in meta  # (a path in metadata is kept in the file too)
    if pathless and layout != "views" and not overwrite and path_json_names(path):
        raise FileExistsError(f"{path_json_beside(path)} exists and holds the camera path of an earlier {path.name}; "
                              "pass overwrite=True to replace it, or move it away")

    depth = _sample_depth(layout, path, bit_depth)
    lo, hi = (float(arr.min()), float(arr.max())) if arr.size else (0.0, 1.0)
    if lo < -1e-3 or hi > 1 + 1e-3:  # the readers clip overshoots of up to 1e-3 (rounding)
        warnings.warn(f"{path.name}: the values span [{lo:.4g}, {hi:.4g}], outside [0, 1]; " + (
            f"they are stored as they are, and reading the file back needs value_range=({lo:.4g}, {hi:.4g}) or "
            "'auto' (which maps that span to [0, 1])" if depth == 32 else
            f"the {depth}-bit samples clip them to [0, 1]"), stacklevel=2)
    data = arr if depth == 32 else _quantize(arr, depth)
    meta["bit_depth"] = depth

    if layout == "views":
        _write_views(path, data, meta, cp, overwrite=overwrite)
        return path
    if layout in ("mosaic", "eslf"):
        _write_mosaic(path, data, layout, overwrite=overwrite)
    else:
        _ARRAY_WRITERS[layout](path, data, meta, cp, overwrite=overwrite, compress=compress)
    if sidecar is not None:
        from ..path import save_path_json

        save_path_json(sidecar, cp, overwrite=overwrite, **_path_fields(meta), lightfield=path.name)
    elif owner is not None:
        warnings.warn(f"{path_json_beside(path).name} belongs to {owner.name} and was left as it is; the camera "
                      f"path of {path.name} is stored in the file itself", stacklevel=2)
    elif pathless and overwrite and path_json_names(path):  # what was replaced had a path: it is not this file's
        path_json_beside(path).unlink()
    return path

