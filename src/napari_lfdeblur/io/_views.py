"""Folder-of-views layouts: one image file per view.

Three naming schemes are recognised:

``rc``
    ``..._RR_CC.png``: the last two numbers of the name are the view row and
    column, 1-based (0-based when some index is 0). Other numbers are ignored,
    so Light Field Toolbox / Lytro names such as ``IMG_0001_001_01_01.png``
    work. This is also what :func:`write_lightfield` writes.
``hci``
    HCI 4D benchmark ``input_CamNNN.png``: row-major, the grid side is the
    square root of the number of views. ``parameters.cfg`` goes to metadata.
``stanford``
    Stanford gantry ``out_RR_CC_<y>_<x>_.png``: 0-based; the trailing camera
    positions are ignored for indexing and kept in metadata.
"""

from __future__ import annotations

import configparser
import json
import math
import os
import re
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ._common import LightFieldFormatError, central_views, check_memory, to_float01
from ._images import IMAGE_EXTENSIONS, drop_opaque_alpha, image_props, read_image

_EXT = r"\.(?:png|jpe?g|tiff?|bmp)$"
_HCI = re.compile(r"^input_Cam(\d+)" + _EXT, re.IGNORECASE)
_STANFORD = re.compile(r"^out_(\d+)_(\d+)(?:_(-?[\d.]+)_(-?[\d.]+))?.*" + _EXT, re.IGNORECASE)
_RC = re.compile(r"^(?:.*\D)?(\d+)[_-](\d+)" + _EXT, re.IGNORECASE)

SCHEMES = ("rc", "hci", "stanford")


def _image_files(folder: Path) -> list[str]:
    return sorted(
        n for n in os.listdir(folder) if n.lower().endswith(IMAGE_EXTENSIONS) and not n.startswith(".")
    )


def probe_scheme(folder) -> str | None:
    """The naming scheme of a folder of views, or None if it holds no light field.

    Cheap: looks at file names only. One view is a light field only where
    :func:`~napari_lfdeblur.io.write_lightfield` wrote it (beside its
    ``lightfield.json``).
    """
    folder = Path(folder)
    try:
        names = _image_files(folder)
    except OSError:
        return None
    if len(names) == 1 and _RC.match(names[0]) and (folder / "lightfield.json").is_file():
        return "rc"  # a single view that write_lightfield wrote: a 1 x 1 light field
    if len(names) < 2:
        return None
    counts = {
        "hci": sum(bool(_HCI.match(n)) for n in names),
        "stanford": sum(bool(_STANFORD.match(n)) for n in names),
        "rc": sum(bool(_RC.match(n)) for n in names),
    }
    for scheme in ("hci", "stanford", "rc"):  # most specific first
        if counts[scheme] >= 2 and counts[scheme] >= len(names) / 2 and _plausible_grid(names, scheme):
            return scheme
    return None


def _plausible_grid(names, scheme) -> bool:
    """True when the indices in the names span a grid not much larger than the
    number of files (a few missing views are allowed, so that reading them
    reports what is missing; names like IMG_20230501_120000.jpg are not views)."""
    if scheme == "hci":
        idx = [int(m.group(1)) for m in map(_HCI.match, names) if m]
        return max(idx) + 1 <= 4 * len(idx)
    rx = _STANFORD if scheme == "stanford" else _RC
    rc = [(int(m.group(1)), int(m.group(2))) for m in map(rx.match, names) if m]
    rows = max(r for r, _ in rc) + 1
    cols = max(c for _, c in rc) + 1
    return rows * cols <= 4 * len(rc)


def _parse_cfg(path: Path) -> dict:
    cp = configparser.ConfigParser()
    try:
        cp.read(path)
    except configparser.Error:
        return {}
    out: dict = {}
    for sec in cp.sections():
        d = {}
        for k, v in cp.items(sec):
            try:
                num = float(v)
                d[k] = int(num) if num.is_integer() and "." not in v and "e" not in v.lower() else num
            except ValueError:
                d[k] = v
        out[sec] = d
    return out


def _add_view(views: dict, dup: list, key: tuple[int, int], name: str) -> None:
    """Record ``name`` as view ``key``, or note it in ``dup`` when the view is taken."""
    if key in views:
        dup.append(f"{views[key]} and {name}")
    else:
        views[key] = name


def _pattern_views(names, pattern, index_base):
    """Views named by a user regex (groups ``row``/``col`` or the first two groups), 1-based by default."""
    rx = re.compile(pattern) if isinstance(pattern, str) else pattern
    base = 1 if index_base is None else int(index_base)
    views: dict[tuple[int, int], str] = {}
    dup: list[str] = []
    for n in names:
        m = rx.search(n)
        if m:
            gd = m.groupdict()
            r, c = (gd["row"], gd["col"]) if "row" in gd and "col" in gd else m.groups()[:2]
            _add_view(views, dup, (int(r) - base, int(c) - base), n)
    return views, dup


def _hci_views(folder: Path, names, grid):
    """HCI ``input_CamNNN`` views, row-major on a square grid unless ``grid=(V, U)``.

    Returns ``(views, duplicates, (V, U))``; raises when the indices do not
    fit the grid.
    """
    idx = {}
    dup: list[str] = []
    width = 3  # digits of the names' numbers
    for n in names:
        m = _HCI.match(n)
        if m:
            k, width = int(m.group(1)), len(m.group(1))
            if k in idx:
                dup.append(f"{idx[k]} and {n}")
            idx[k] = n
    if not idx:
        raise LightFieldFormatError(f"{folder}: no view file names match the 'hci' naming scheme (input_CamNNN)")
    total = max(idx) + 1
    if grid is not None:
        V, U = (int(g) for g in grid)
    else:
        side = math.isqrt(total)
        if side * side != total:
            up = side + 1  # the last views of a square grid may be what is missing
            missing = [f"input_Cam{k:0{width}d}" for k in range(up * up) if k not in idx]
            raise LightFieldFormatError(
                f"{folder}: {len(idx)} HCI views input_CamNNN with indices up to {total - 1} do not form a "
                f"square grid; as a {up}x{up} grid it lacks {', '.join(missing[:5])}"
                f"{' and more' if len(missing) > 5 else ''}; pass grid=(V, U) if the grid is not square"
            )
        V = U = side
    views: dict[tuple[int, int], str] = {}
    for k, n in idx.items():
        if k >= V * U:
            raise LightFieldFormatError(f"{folder}: {n} is outside the {V}x{U} grid")
        _add_view(views, dup, (k // U, k % U), n)
    return views, dup, (V, U)


def _stanford_views(names, index_base):
    """Stanford ``out_RR_CC_<y>_<x>_`` views, 0-based by default, and the camera positions in the names."""
    base = 0 if index_base is None else int(index_base)
    views: dict[tuple[int, int], str] = {}
    dup: list[str] = []
    positions = {}
    for n in names:
        m = _STANFORD.match(n)
        if m:
            key = (int(m.group(1)) - base, int(m.group(2)) - base)
            _add_view(views, dup, key, n)
            if m.group(3) is not None:
                try:
                    positions[key] = (float(m.group(3)), float(m.group(4)))
                except ValueError:
                    pass
    return views, dup, positions


def _rc_views(names, index_base):
    """``..._RR_CC`` views: 0-based when some index is 0, else 1-based, unless ``index_base`` is given.

    Returns ``(views, duplicates, base)``.
    """
    parsed = []
    for n in names:
        m = _RC.match(n)
        if m:
            parsed.append((int(m.group(1)), int(m.group(2)), n))
    if index_base is None:
        base = 0 if any(r == 0 or c == 0 for r, c, _ in parsed) else 1
    else:
        base = int(index_base)
    views: dict[tuple[int, int], str] = {}
    dup: list[str] = []
    for r, c, n in parsed:
        _add_view(views, dup, (r - base, c - base), n)
    return views, dup, base


def _check_grid(folder: Path, scheme: str, views: dict, dup: list, shape, missing_name) -> tuple[int, int]:
    """Check that ``views`` fill a grid exactly once; return its ``(V, U)``.

    ``shape`` is ``(V, U)`` (the numbers are converted with ``int``), or None
    to take the grid from the largest indices. ``missing_name(r, c, U)``
    names a missing view in the message.
    """
    if dup:
        raise LightFieldFormatError(
            f"{folder}: several files give the same view: {'; '.join(dup[:3])}; keep one light field "
            f"per folder or pass pattern= to select the files"
        )
    if not views:
        raise LightFieldFormatError(f"{folder}: no view file names match the {scheme!r} naming scheme")
    if min(min(k) for k in views) < 0:
        raise LightFieldFormatError(f"{folder}: view indices below the index base; pass index_base=0")
    if shape is None:
        V = max(k[0] for k in views) + 1
        U = max(k[1] for k in views) + 1
    else:
        V, U = (int(g) for g in shape)
    outside = [n for k, n in views.items() if k[0] >= V or k[1] >= U]
    if outside:
        raise LightFieldFormatError(f"{folder}: {outside[0]} lies outside the {V}x{U} grid")
    missing = [(r, c) for r in range(V) for c in range(U) if (r, c) not in views]
    if missing:
        shown = ", ".join(missing_name(r, c, U) for r, c in missing[:5])
        raise LightFieldFormatError(
            f"{folder}: {len(missing)} view(s) missing from the {V}x{U} grid: {shown}"
            f"{', ...' if len(missing) > 5 else ''}"
        )
    return V, U


def _map_views(folder: Path, scheme: str, pattern=None, index_base=None, grid=None):
    """Map (row, col), 0-based, to file names. Returns (mapping, (V, U), info)."""
    names = _image_files(folder)
    info: dict = {}
    shape = None
    if pattern is not None:
        views, dup = _pattern_views(names, pattern, index_base)
    elif scheme == "hci":
        views, dup, shape = _hci_views(folder, names, grid)
        cfg = folder / "parameters.cfg"
        if cfg.is_file():
            info["camera"] = _parse_cfg(cfg)
    elif scheme == "stanford":
        views, dup, positions = _stanford_views(names, index_base)
        if positions:
            info["camera_positions"] = positions
    else:  # rc
        views, dup, info["index_base"] = _rc_views(names, index_base)
    if grid is not None and scheme != "hci":
        shape = grid

    if scheme == "hci" and pattern is None:

        def missing_name(r, c, U):
            return f"input_Cam{r * U + c:03d}"

    else:
        b = info.get("index_base", 0 if scheme == "stanford" else 1)

        def missing_name(r, c, U):
            return f"({r + b}, {c + b})"

    return views, _check_grid(folder, scheme, views, dup, shape, missing_name), info


def read_views(folder, *, scheme=None, pattern=None, index_base=None, grid=None, value_range=None,
               max_bytes=None, workers=None, angular_crop=None):
    """Read a folder of view images.

    Parameters
    ----------
    folder : path
        The folder.
    scheme : {'rc', 'hci', 'stanford'}, optional
        Naming scheme; detected from the file names by default.
    pattern : str, optional
        Regular expression with groups ``row`` and ``col`` (or two plain
        groups) matched against each file name; overrides the scheme.
    index_base : {0, 1}, optional
        Base of the indices in the names.
    grid : (int, int), optional
        ``(V, U)`` when it cannot be inferred (non-square HCI grids).
    value_range, max_bytes, angular_crop :
        See :func:`napari_lfdeblur.io.read_lightfield`; with ``angular_crop``
        only the central views are decoded.

    Returns
    -------
    lf : ndarray, (V, U, Y, X[, C]) float32 in [0, 1]
    metadata : dict
    """
    folder = Path(folder)
    if scheme is None:
        scheme = probe_scheme(folder) or ("rc" if pattern is not None else None)
        if scheme is None:
            raise LightFieldFormatError(
                f"{folder}: no light-field view files found; expected names like view_RR_CC.png, "
                f"input_CamNNN.png or out_RR_CC_*.png (or pass pattern=)"
            )
    elif scheme not in SCHEMES:
        raise ValueError(f"unknown naming scheme {scheme!r}; choose one of {SCHEMES}")
    views, (V_file, U_file), info = _map_views(folder, scheme, pattern, index_base, grid)
    rows, cols = range(V_file), range(U_file)
    if angular_crop is not None:
        sv, su = central_views(V_file, U_file, angular_crop, folder)
        rows, cols = rows[sv], cols[su]
    V, U = len(rows), len(cols)
    keys = [(r, c) for r in rows for c in cols]
    first = folder / views[keys[0]]
    shape0, dtype0 = image_props(first)
    check_memory((V, U) + tuple(shape0), dtype0.itemsize, folder, max_bytes=max_bytes)

    paths = [folder / views[k] for k in keys]
    n_workers = workers or min(8, os.cpu_count() or 1, len(paths))
    with ThreadPoolExecutor(max_workers=max(1, n_workers)) as pool:
        it = pool.map(read_image, paths)
        first_img = next(it)
        raw = np.empty((V, U) + first_img.shape, first_img.dtype)
        raw[0, 0] = first_img
        for i, ((r, c), p, img) in enumerate(zip(keys[1:], paths[1:], it), start=1):
            if img.shape != first_img.shape:
                raise LightFieldFormatError(
                    f"{p}: view ({r}, {c}) has shape {img.shape} but {paths[0].name} has {first_img.shape}; "
                    f"all views must have the same size"
                )
            if img.dtype != first_img.dtype:
                raise LightFieldFormatError(
                    f"{p}: view has dtype {img.dtype} but {paths[0].name} has {first_img.dtype}; "
                    f"all views must have the same bit depth"
                )
            raw[i // U, i % U] = img
    lf = to_float01(drop_opaque_alpha(raw), folder, value_range=value_range)  # as a mosaic's
    meta = {
        "layout": {"rc": "views", "hci": "hci", "stanford": "stanford"}[scheme],
        "naming": scheme,
        "n_views": [V_file, U_file],
        "file_dtype": str(first_img.dtype),
        "files": [views[k] for k in (keys[0], keys[-1])],
    }
    if angular_crop is not None:
        meta["angular_crop"] = [V, U]
    if "index_base" in info:
        meta["index_base"] = info["index_base"]
    if "camera" in info:
        meta["camera"] = info["camera"]
    if "camera_positions" in info:
        pos = info["camera_positions"]
        meta["camera"] = {
            "positions": [[list(pos.get((r, c), (math.nan, math.nan))) for c in cols] for r in rows],
            "positions_note": "the two numbers after out_RR_CC_ in each file name, per view (v, u)",
        }
    saved = folder / "lightfield.json"
    if saved.is_file():  # written by write_lightfield
        try:
            doc = json.loads(saved.read_text())
            if isinstance(doc, dict):
                meta["saved_metadata"] = doc
                if "control_points" in doc:
                    meta["control_points"] = doc["control_points"]
        except (OSError, ValueError):
            pass
    return lf, meta
