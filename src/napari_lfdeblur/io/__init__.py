"""Reading and writing light fields.

:func:`read_lightfield` turns any supported layout into a ``(V, U, Y, X)`` or
``(V, U, Y, X, C)`` float32 array in [0, 1] (see docs/model.md);
:func:`write_lightfield` writes one back. Supported layouts (the names that
:func:`detect_layout` returns and ``layout=`` accepts):

============  ==============================================================
``views``     folder of ``..._RR_CC.png`` views (1-based; Lytro toolbox names)
``hci``       folder of HCI benchmark ``input_CamNNN.png`` (+ parameters.cfg)
``stanford``  folder of Stanford gantry ``out_RR_CC_*.png`` (0-based)
``eslf``      lenslet mosaic ``*.eslf.png``: pixel ``(y*A + v, x*A + u)``
``mosaic``    views tiled in one image: pixel ``(v*Y + y, u*X + x)`` (detected
              when the image states it, as ``write_lightfield`` writes both)
``mat``       Light Field Toolbox ``.mat`` (MATLAB v5 or v7.3), variable LF
``h5``        HDF5 dataset ``LF`` (or the only 4D/5D one)
``npy``       ``.npy`` array
``npz``       ``.npz`` array ``lf`` (or the only array)
``tiff``      4D/5D TIFF
============  ==============================================================

Errors are :class:`LightFieldError` (a ``ValueError``) or one of its
subclasses, or ``FileNotFoundError``; each message names the file and what is
wrong with it.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from ..epi import ViewOrderWarning, warn_if_transposed
from ._common import (
    MEMORY_LIMIT_ENV,
    InsufficientMemoryError,
    LightFieldError,
    LightFieldFormatError,
    LightFieldReadError,
    available_memory,
    check_value_range,
    parse_value_range,
)
from ._write import PATH_FIELDS, path_json_beside, path_json_owner, write_lightfield

__all__ = [
    "read_lightfield",
    "read_lightfield_with_metadata",
    "write_lightfield",
    "detect_layout",
    "probe_layout",
    "LAYOUTS",
    "LightFieldError",
    "LightFieldFormatError",
    "LightFieldReadError",
    "ViewOrderWarning",
    "InsufficientMemoryError",
    "MEMORY_LIMIT_ENV",
    "available_memory",
    "parse_value_range",
]

LAYOUTS = ("views", "hci", "stanford", "eslf", "mosaic", "mat", "h5", "npy", "npz", "tiff")

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
#: the first bytes of PNG, TIFF (both byte orders), JPEG and BMP files
_IMAGE_MAGIC = (b"\x89PNG\r\n\x1a\n", b"II*\x00", b"MM\x00*", b"\xff\xd8\xff", b"BM")
_SUFFIX_LAYOUT = {
    ".npy": "npy",
    ".npz": "npz",
    ".tif": "tiff",
    ".tiff": "tiff",
    ".h5": "h5",
    ".hdf5": "h5",
    ".he5": "h5",
    ".mat": "mat",
}

# options each layout's reader accepts, besides value_range, max_bytes and angular_crop
_OPTIONS = {
    "views": ("scheme", "pattern", "index_base", "grid", "workers"),
    "hci": ("pattern", "index_base", "grid", "workers"),
    "stanford": ("pattern", "index_base", "grid", "workers"),
    "eslf": ("angular_size",),
    "mosaic": ("grid",),
    "mat": ("variable", "drop_weight"),
    "h5": ("dataset", "axes", "grid"),
    "npy": ("axes", "grid"),
    "npz": ("key", "axes", "grid"),
    "tiff": ("axes", "grid"),
}


def _as_path(path) -> Path:
    if isinstance(path, (list, tuple)):
        if len(path) != 1:
            raise ValueError(f"expected one path, got {len(path)}")
        path = path[0]
    try:
        return Path(os.fspath(path)).expanduser()
    except TypeError:
        raise TypeError(f"expected a file or folder path, not {type(path).__name__}") from None


def detect_layout(path) -> str:
    """Name the layout of a light-field file or folder (one of :data:`LAYOUTS`).

    Looks at names and suffixes only, never at pixel data.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    LightFieldFormatError
        If the layout cannot be told (for instance a plain image, which may be
        an ESLF or a view-grid mosaic: pass ``layout=``).
    """
    from ._views import probe_scheme

    path = _as_path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder")
    if path.is_dir():
        scheme = probe_scheme(path)
        if scheme is None:
            raise LightFieldFormatError(
                f"{path}: the folder holds no light-field views (expected image names like view_RR_CC.png, "
                f"IMG_0001_001_RR_CC.png, input_CamNNN.png or out_RR_CC_*.png)"
            )
        return {"rc": "views", "hci": "hci", "stanford": "stanford"}[scheme]
    name = path.name.lower()
    suffix = path.suffix.lower()
    if suffix in _IMAGE_SUFFIXES + (".tif", ".tiff") and path.is_file():
        from ._mosaic import stated_layout

        stated = stated_layout(path).get("layout")  # a mosaic written by write_lightfield says so
        if stated:
            return stated
    if suffix in _SUFFIX_LAYOUT and not (suffix in (".tif", ".tiff") and "eslf" in name):
        return _SUFFIX_LAYOUT[suffix]
    if suffix in _IMAGE_SUFFIXES or suffix in (".tif", ".tiff"):
        if "eslf" in name:
            return "eslf"
        raise LightFieldFormatError(
            f"{path}: a single image is not a light field by itself; if it is a lenslet mosaic pass "
            f"layout='eslf' (angular_size=A), if it is a grid of views pass layout='mosaic', grid=(V, U)"
        )
    if suffix in (".lfr", ".lfp", ".raw"):
        raise LightFieldFormatError(
            f"{path}: a raw plenoptic capture (Lytro {suffix}) must be decoded into views first, with the "
            f"camera's calibration: for example by the Light Field Toolbox for MATLAB (LFUtilDecodeLytroFolder), "
            f"whose decoded .mat this reader opens, or by a tool that writes the views as images or a lenslet "
            f"(ESLF) image"
        )
    raise LightFieldFormatError(
        f"{path}: unknown light-field file type {suffix or '(no suffix)'!r}; supported: folders of views, "
        f".eslf.png, .mat, .h5/.hdf5, .npy, .npz, .tif/.tiff"
    )


def probe_layout(path) -> str | None:
    """The layout of ``path`` if it holds a light field we can read, else None.

    Never raises. Checks headers (array dimensions, dataset names) so that
    ordinary 2D/3D images and arrays are *not* claimed; used by the napari
    reader.
    """
    try:
        layout = detect_layout(path)
        p = _as_path(path)
        if layout == "npy":
            from ._arrays import npy_may_be_lightfield

            return layout if npy_may_be_lightfield(p) else None
        if layout == "npz":
            from ._arrays import looks_like_image_stack, npz_headers, npz_lightfield_key

            headers = npz_headers(p)
            key = npz_lightfield_key(p, headers)
            shape = headers[key][0] if key is not None else ()
            return layout if len(shape) in (4, 5) and not looks_like_image_stack(shape) else None
        if layout == "tiff":
            from ._arrays import tiff_shape

            shape, _dtype, meta = tiff_shape(p)
            if len(shape) == 4 and meta.get("_series_axes", "").endswith("S"):
                return None  # a stack of colour images, not a light field
            return layout if len(shape) in (4, 5) else None
        if layout == "h5":
            import h5py

            from ._arrays import h5_lightfield_name

            with h5py.File(p, "r") as f:
                name = h5_lightfield_name(f)
                return layout if name is not None and f[name].ndim in (4, 5) else None
        if layout == "mat":
            from ._matlab import is_hdf5

            if is_hdf5(p):
                import h5py

                with h5py.File(p, "r") as f:
                    return layout if "LF" in f and getattr(f["LF"], "ndim", 0) in (4, 5) else None
            import scipy.io

            return layout if any(n == "LF" and len(s) in (4, 5) for n, s, _c in scipy.io.whosmat(p)) else None
        if layout == "eslf":  # an image file (PNG, TIFF, JPEG, BMP) by its first bytes
            with open(p, "rb") as fh:
                head = fh.read(8)
            return layout if head.startswith(_IMAGE_MAGIC) else None
        return layout
    except Exception:  # noqa: BLE001 - a probe never raises
        return None


def read_lightfield_with_metadata(path, *, layout: str | None = None, value_range=None, max_bytes=None,
                                  angular_crop=None, **options) -> tuple[np.ndarray, dict]:
    """Read a light field and describe where it came from.

    Parameters are those of :func:`read_lightfield`.

    Returns
    -------
    lf : ndarray, (V, U, Y, X) or (V, U, Y, X, C), float32 in [0, 1]
    metadata : dict
        JSON-serialisable: ``source`` (the path), ``layout``, ``shape``,
        ``dtype``, ``file_dtype`` (as stored), ``angular_crop`` (``[n_v, n_u]``,
        when the views were cropped), ``value_range`` (when given), and layout-specific entries,
        such as ``camera`` (camera parameters when the file has them).
        Metadata stored by :func:`write_lightfield` is in ``saved_metadata``;
        the blur it states, ``n_times`` and ``infinity_disparity`` (as
        ``lfdeblur simulate`` and the napari writers store them), is also
        copied to the top level.
    """
    path = _as_path(path)
    value_range = check_value_range(value_range)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder")
    if layout is None:
        layout = detect_layout(path)
    elif layout not in LAYOUTS:
        raise ValueError(f"unknown layout {layout!r}; choose one of {LAYOUTS}")
    allowed = _OPTIONS[layout]
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise TypeError(
            f"option(s) {unknown} do not apply to layout {layout!r}; it accepts {list(allowed)} "
            f"plus value_range, max_bytes and angular_crop"
        )
    if path.is_dir() != (layout in ("views", "hci", "stanford")):
        raise LightFieldFormatError(
            f"{path}: layout {layout!r} expects a {'folder' if layout in ('views', 'hci', 'stanford') else 'file'}"
        )
    common = {"value_range": value_range, "max_bytes": max_bytes, "angular_crop": angular_crop}
    if layout in ("views", "hci", "stanford"):
        from ._views import read_views

        scheme = options.pop("scheme", None) or {"views": "rc", "hci": "hci", "stanford": "stanford"}[layout]
        lf, meta = read_views(path, scheme=scheme, **options, **common)
    elif layout == "eslf":
        from ._mosaic import read_eslf

        lf, meta = read_eslf(path, **options, **common)
    elif layout == "mosaic":
        from ._mosaic import read_mosaic

        lf, meta = read_mosaic(path, **options, **common)
    elif layout == "mat":
        from ._matlab import read_mat

        lf, meta = read_mat(path, **options, **common)
    else:
        from . import _arrays

        reader = {"h5": _arrays.read_h5, "npy": _arrays.read_npy, "npz": _arrays.read_npz,
                  "tiff": _arrays.read_tiff}[layout]
        lf, meta = reader(path, **options, **common)
    metadata = {
        "source": str(path.resolve()),
        "layout": meta.pop("layout", layout),
        "shape": list(lf.shape),
        "dtype": str(lf.dtype),
        **meta,
    }
    if value_range is not None:
        metadata["value_range"] = value_range if value_range == "auto" else list(value_range)
    # what a file written by this package states about the blur (path, T, d_inf) is read back as such
    saved = metadata.get("saved_metadata")
    for key in ("control_points", *PATH_FIELDS):
        if isinstance(saved, dict) and key in saved and key not in metadata:
            metadata[key] = saved[key]
    if "control_points" in metadata:  # stored in the file: read like a path file beside it
        from ..path import validate_control_points

        try:
            metadata["control_points"] = validate_control_points(metadata["control_points"]).tolist()
        except (ValueError, TypeError) as exc:
            warnings.warn(f"{path}: the camera path it holds was not read: {exc}", stacklevel=2)
            del metadata["control_points"]
    if "control_points" not in metadata:
        _read_path_beside(path, metadata)
    _check_view_order(lf, path, metadata)
    return lf, metadata


def _read_path_beside(path: Path, metadata: dict) -> None:
    """Add to ``metadata`` the camera path that :func:`write_lightfield` put beside ``path``, if any.

    That is ``<name>.path.json`` (``path.json`` in a folder), for the formats
    that hold no path themselves. Its ``control_points`` (and the
    ``n_times`` and ``infinity_disparity`` it states) go to the top level,
    its name to ``path_file``. A file there that holds no valid path
    (:func:`~napari_lfdeblur.path.read_path_json`) is ignored with a
    warning: the light field is read all the same. One that names
    (``lightfield``) another light field of the same name that is
    there too (``a.npz``'s beside ``a.npy``: both would read ``a.path.json``)
    is that one's and is left alone. A path
    file that states views of another size than the light field's (it was
    cropped, say) is read with a warning when the path has ``p_z`` or a
    rotation (:func:`~napari_lfdeblur.path.path_view_mismatch`).
    """
    import json

    from ._write import path_from_document, view_shape_note

    beside = path_json_beside(path)
    if not beside.is_file():
        return
    if path_json_owner(path) is not None:
        return  # the path of a.npz, beside a.npy
    try:
        doc = json.loads(beside.read_text())
        cp, _ = path_from_document(doc, None)
    except (OSError, ValueError, TypeError) as exc:
        warnings.warn(f"{beside} was not read as the light field's camera path: {exc}", stacklevel=3)
        return
    metadata["control_points"] = cp.tolist()
    metadata["path_file"] = str(beside.resolve())
    for key in PATH_FIELDS:
        if isinstance(doc, dict) and key in doc and key not in metadata:
            metadata[key] = doc[key]
    note = view_shape_note(cp, metadata["shape"], doc if isinstance(doc, dict) else {}, beside)
    if note:
        warnings.warn(note, stacklevel=3)


def _check_view_order(lf, path, metadata) -> None:
    """Record the views' motion (px/view) in ``metadata`` and warn when the view axes look swapped."""
    fix = (r"pass pattern=r'_(?P<col>\d+)_(?P<row>\d+)\.\w+$' to name the numbers the other way round, or "
           if metadata["layout"] in ("views", "hci", "stanford") else "")
    shifts = warn_if_transposed(lf, str(path), fix=fix, stacklevel=3)
    if shifts is not None:
        metadata["view_shifts"] = np.round(shifts, 3).tolist()


def read_lightfield(path, *, layout: str | None = None, value_range=None, max_bytes=None, angular_crop=None,
                    **options) -> np.ndarray:
    """Read a light field from any supported layout.

    Parameters
    ----------
    path : str or Path
        A file or a folder of views.
    layout : str, optional
        One of :data:`LAYOUTS`; detected from the path by default
        (:func:`detect_layout`).
    value_range : (float, float) or 'auto', optional
        Map this range of stored values to [0, 1] (values beyond it are
        clipped); ``'auto'``: the data's own minimum and maximum. By default
        integers are divided by their dtype's maximum and floats must lie
        in [0, 1]. Use it for data stored on another scale, such as 10- or
        12-bit values in a 16-bit file (``(0, 4095)``): they would
        otherwise come out dark, and the blind solver finds few edges in
        dark data (docs/io.md). :func:`parse_value_range` reads it from
        text. ``lo < hi``, both finite, else ``ValueError``.
    max_bytes : int, optional
        Memory the decoded light field may use; by default the available
        memory (or the ``LFDEBLUR_MEMORY_LIMIT`` environment variable). The
        check runs before any pixel data is decoded.
    angular_crop : int or (int, int), optional
        Keep only the central ``n x n`` (or ``n_v x n_u``) views, the block
        starting at view ``((V - n_v) // 2, (U - n_u) // 2)``. Where the
        layout allows (folders of views, HDF5, MATLAB v7.3, ``.npy``) only
        those views are read; the others are read whole and cropped before
        the conversion to float32.
    **options
        Layout-specific overrides:

        - folders (``views``, ``hci``, ``stanford``): ``pattern`` (regex with
          groups ``row``, ``col``), ``index_base`` (0 or 1), ``grid``
          ``(V, U)``, ``workers`` (decoding threads);
        - ``eslf``: ``angular_size`` (lenslet size A, default 14 or detected);
        - ``mosaic``: ``grid`` ``(V, U)`` (required);
        - ``mat``: ``variable`` (default ``'LF'``), ``drop_weight`` (default True);
        - ``h5``: ``dataset``, ``axes`` (e.g. ``'vuyxc'``; default from the
          dataset's ``axes`` attribute, else v, u, y, x, c);
        - ``npz``: ``key``, ``axes``; ``npy``, ``tiff``: ``axes``;
        - arrays (``h5``, ``npy``, ``npz``, ``tiff``): ``grid=(V, U)`` reads a
          3D/4D stack of ``V*U`` views ``(V*U, Y, X[, C])``, row-major.

    Returns
    -------
    ndarray
        ``(V, U, Y, X)`` or ``(V, U, Y, X, C)`` float32 in [0, 1].

    Raises
    ------
    FileNotFoundError
        The path does not exist.
    LightFieldFormatError
        Missing view, views of different sizes or dtypes, 2D/3D data, NaN or
        Inf, undetectable layout.
    LightFieldReadError
        Truncated, corrupt or non-image file (also an ``OSError``).
    InsufficientMemoryError
        The decoded light field would not fit in memory.

    Examples
    --------
    >>> lf = read_lightfield("IMG_0001/")                      # doctest: +SKIP
    >>> lf = read_lightfield("scene.eslf.png", angular_crop=9)  # doctest: +SKIP
    >>> lf = read_lightfield("IMG_0001__Decoded.mat", angular_crop=9)  # doctest: +SKIP
    >>> lf = read_lightfield("grid.png", layout="mosaic", grid=(9, 9))  # doctest: +SKIP
    """
    return read_lightfield_with_metadata(path, layout=layout, value_range=value_range, max_bytes=max_bytes,
                                         angular_crop=angular_crop, **options)[0]
