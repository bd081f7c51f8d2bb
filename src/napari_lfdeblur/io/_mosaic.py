"""Single-image layouts: the ESLF lenslet mosaic and the view-grid mosaic.

ESLF (as in the Stanford Lytro archive's ``*.eslf.png``)
    Each lenslet is an ``A x A`` block: mosaic pixel ``(y*A + v, x*A + u)``
    is light-field sample ``(v, u, y, x)``.
View-grid mosaic
    Each view is a ``Y x X`` block: mosaic pixel ``(v*Y + y, u*X + x)`` is
    light-field sample ``(v, u, y, x)``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ._arrays import kept_views
from ._common import LightFieldFormatError, check_memory, to_float01
from ._images import drop_opaque_alpha, image_props, read_image
from ._png import png_text

DEFAULT_ANGULAR_SIZE = 14
#: the PNG text keyword (TIFF: shaped-metadata key) under which a mosaic written by this package states its layout
LAYOUT_KEY = "lfdeblur_layout"


def mosaic_layout_text(layout: str, shape) -> str:
    """What a mosaic image of the light field ``shape`` states about its layout (JSON), as written."""
    V, U = (int(n) for n in shape[:2])
    doc = {"layout": "eslf", "angular_size": V} if layout == "eslf" else {"layout": "mosaic", "grid": [V, U]}
    return json.dumps(doc)


def stated_layout(path) -> dict:
    """The layout an image file states (``{'layout': 'eslf', 'angular_size': A}`` or ``{'layout':
    'mosaic', 'grid': [V, U]}``), as :func:`~napari_lfdeblur.io.write_lightfield` writes it; ``{}`` when it
    states none or cannot be read."""
    path = Path(path)
    try:
        if path.suffix.lower() in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tif:
                text = (tif.shaped_metadata or [{}])[0].get(LAYOUT_KEY)
        else:
            text = png_text(path).get(LAYOUT_KEY)
        doc = json.loads(text) if text else {}
    except Exception:  # noqa: BLE001 - a statement that cannot be read is none
        return {}
    if not isinstance(doc, dict):
        return {}
    if doc.get("layout") == "eslf" and isinstance(doc.get("angular_size"), int) and doc["angular_size"] > 0:
        return doc
    grid = doc.get("grid")
    if doc.get("layout") == "mosaic" and isinstance(grid, list) and len(grid) == 2 and all(
            isinstance(g, int) and g > 0 for g in grid):
        return doc
    return {}


def detect_angular_size(height: int, width: int, path="mosaic") -> int:
    """The ESLF lenslet size ``A``: 14 when it divides both sides, else the only
    size in 2..32 that does; raises when there are several (any multiple of
    the true size that divides the image would fit the layout as well)."""
    if height % DEFAULT_ANGULAR_SIZE == 0 and width % DEFAULT_ANGULAR_SIZE == 0:
        return DEFAULT_ANGULAR_SIZE
    cands = [a for a in range(2, 33) if height % a == 0 and width % a == 0 and min(height, width) // a >= 4]
    if len(cands) == 1:
        return cands[0]
    raise LightFieldFormatError(
        f"{path}: cannot tell the lenslet size of a {height}x{width} ESLF image "
        f"(candidates {cands or 'none'}); pass angular_size=A"
    )


def read_eslf(path, *, angular_size=None, angular_crop=None, value_range=None, max_bytes=None):
    """Read an ESLF lenslet mosaic.

    Parameters
    ----------
    angular_size : int, optional
        Lenslet size ``A`` in pixels (views per side). Default: the one the
        file states (as :func:`~napari_lfdeblur.io.write_lightfield` writes
        it), else 14, else the only size that divides the image.
    angular_crop : int or (int, int), optional
        Keep only the central ``n x n`` (or ``n_v x n_u``) views (the outer
        ones of a Lytro ESLF are dark).

    Returns
    -------
    lf : ndarray, (A, A, Y, X[, C]) float32 in [0, 1]
    metadata : dict
    """
    path = Path(path)
    shape, dtype = image_props(path)
    H, W = shape[:2]
    if angular_size is None:
        A = stated_layout(path).get("angular_size") or detect_angular_size(H, W, path)
    else:
        A = int(angular_size)
        if A < 1:
            raise ValueError(f"angular_size must be positive, not {angular_size}")
    if H < A or W < A:
        raise LightFieldFormatError(f"{path}: a {H}x{W} image is smaller than one {A}x{A} lenslet")
    meta = {"layout": "eslf", "angular_size": A, "mosaic_shape": [H, W]}
    index, out, _ = kept_views((A, A, H // A, W // A) + tuple(shape[2:]), None, None, angular_crop, path, meta)
    check_memory(shape, dtype.itemsize, path, max_bytes=max_bytes, out_shape=out)
    img = drop_opaque_alpha(read_image(path))
    Y, X = img.shape[0] // A, img.shape[1] // A
    img = img[: Y * A, : X * A]
    lf = img.reshape((Y, A, X, A) + img.shape[2:])
    lf = np.moveaxis(lf, (1, 3), (0, 1))  # (A, A, Y, X[, C])
    meta["file_dtype"] = str(img.dtype)
    lf = lf if index is None else lf[index]
    return to_float01(np.ascontiguousarray(lf), path, value_range=value_range), meta


def read_mosaic(path, *, grid=None, value_range=None, max_bytes=None, angular_crop=None):
    """Read a view-grid mosaic: views tiled as ``grid = (V, U)`` blocks.

    ``grid`` defaults to the one the file states (as
    :func:`~napari_lfdeblur.io.write_lightfield` writes it). ``angular_crop``
    keeps the central views, as in :func:`read_eslf`.

    Returns
    -------
    lf : ndarray, (V, U, Y, X[, C]) float32 in [0, 1]
    metadata : dict
    """
    path = Path(path)
    grid = grid or stated_layout(path).get("grid")
    if grid is None:
        raise LightFieldFormatError(
            f"{path}: a view-grid mosaic needs its grid size; pass grid=(V, U) (views down, views across)"
        )
    V, U = (int(g) for g in grid)
    if V < 1 or U < 1:
        raise ValueError(f"grid must be two positive integers, not {grid}")
    shape, dtype = image_props(path)
    H, W = shape[:2]
    if H % V or W % U:
        raise LightFieldFormatError(
            f"{path}: a {H}x{W} image does not split into a {V}x{U} grid of equal views"
        )
    meta = {"layout": "mosaic", "grid": [V, U], "mosaic_shape": [H, W]}
    index, out, _ = kept_views((V, U, H // V, W // U) + tuple(shape[2:]), None, None, angular_crop, path, meta)
    check_memory(shape, dtype.itemsize, path, max_bytes=max_bytes, out_shape=out)
    img = drop_opaque_alpha(read_image(path))
    Y, X = H // V, W // U
    lf = img.reshape((V, Y, U, X) + img.shape[2:]).swapaxes(1, 2)
    meta["file_dtype"] = str(img.dtype)
    lf = lf if index is None else lf[index]
    return to_float01(np.ascontiguousarray(lf), path, value_range=value_range), meta


def lightfield_to_mosaic(lf: np.ndarray, kind: str = "grid") -> np.ndarray:
    """Tile a ``(V, U, Y, X[, C])`` light field into one image.

    ``kind='grid'`` gives the view-grid mosaic ``(V*Y, U*X[, C])``;
    ``kind='eslf'`` the lenslet mosaic ``(Y*V, X*U[, C])`` (needs V == U).
    """
    V, U, Y, X = lf.shape[:4]
    rest = lf.shape[4:]
    if kind == "grid":
        return np.ascontiguousarray(lf.swapaxes(1, 2)).reshape((V * Y, U * X) + rest)
    if kind == "eslf":
        return np.ascontiguousarray(np.moveaxis(lf, (0, 1), (1, 3))).reshape((Y * V, X * U) + rest)
    raise ValueError(f"kind must be 'grid' or 'eslf', not {kind!r}")
