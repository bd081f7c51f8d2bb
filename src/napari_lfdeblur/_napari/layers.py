"""Layers for light fields, epipolar images and camera paths.

Every function here that builds a layer returns a napari *layer data tuple*
``(data, kwargs, layer_type)``; :func:`add_layer` adds one to a viewer (or
updates the layer of the same name in place). The tuples need no viewer, so
readers, sample data and scripts can use them too.

Layers
------
Light field
    One Image layer of shape ``(V, U, Y, X)``, or ``(V, U, Y, X, C)`` with
    ``rgb=True`` for colour (C = 3 or 4), ``axis_labels=('v', 'u', 'y', 'x')``.
    The view sliders are the two leading axes. ``metadata`` holds::

        'napari_lfdeblur_version'  the package version that made it
        'kind'                     'blurred', 'deconvolved', 'blind', 'preview', ...
        'parameters'               dict of the parameters of the operation: the
                                   solver's dataclass fields (``from_metadata``
                                   reads them back) and the run's settings
        'control_points'           list of [p_x, p_y, p_z] (the path used / found),
                                   or [p_x, p_y, p_z, r_x, r_y, r_z] with rotation
        'n_times', 'infinity_disparity', 'source_layer'
        'loss_history', 'timings'  (blind results)

Epipolar images (EPIs)
    ``'<name> EPI h'``: the horizontal EPI ``lf[v, :, y, :]``, shape
    ``(U, X[, C])``, placed below the light field (rows stretched by an integer
    factor so that a few views are visible). ``'<name> EPI v'``: the vertical
    EPI ``lf[:, u, :, x]`` **transposed** to ``(Y, V[, C])`` so that its rows
    line up with the image rows; placed to the right of the light field
    (columns stretched likewise). Both are 2D layers, shown at every view.

Camera path
    A 2D Shapes layer **overlaid on the centre view**. A camera position
    ``(p_x, p_y)`` in view units is drawn at pixel::

        (row, col) = ((Y - 1) / 2 + s * p_y,  (X - 1) / 2 + s * p_x)

    with the scale ``s = min(Y, X) / (2 * max(U, V))`` pixels per view
    (:func:`path_scale`). A grey rectangle marks the aperture, the views
    ``u_c`` in ``[-(U-1)/2, (U-1)/2]`` and ``v_c`` in ``[-(V-1)/2, (V-1)/2]``;
    it fills about half the image, whatever the sizes. The path, sampled at the
    ``T`` exposure instants, is a polyline (yellow for an estimate, cyan for
    the true path), with a small dot at ``t = 0``. ``p_z`` is not drawn, nor
    the rotation ``(r_x, r_y, r_z)`` of an ``(n, 6)`` path; the widgets plot
    every coordinate against ``t``. ``metadata`` holds ``'control_points'``
    (all 6 columns of a path with rotation), ``'n_times'``,
    ``'infinity_disparity'`` (when known), ``'lightfield_shape'``,
    ``'view_shape'`` (``[Y, X]``, the views the path belongs to),
    ``'pixels_per_view'``, ``'frame'`` (a sentence saying the above),
    ``'source_layer'`` (the light-field layer the path belongs to, from the
    readers and the widgets) and,
    for a path with rotation columns, ``'motion': '6dof'`` and
    ``'max_rotation_rad'`` (the largest ``|r|`` along the path).
"""

from __future__ import annotations

import re
import weakref
from typing import Any

import numpy as np

import napari_lfdeblur

from ..epi import horizontal_epi, vertical_epi
from ..path import bezier_positions, validate_control_points

__all__ = [
    "LF_AXIS_LABELS",
    "LayerError",
    "layer_kind",
    "lightfield_from_layer",
    "lightfield_layer_data",
    "lightfield_metadata",
    "control_points_from_layer",
    "windows_from_shapes",
    "path_scale",
    "path_layer_data",
    "epi_layer_data",
    "add_layer",
    "remove_layer",
]

LF_AXIS_LABELS = ("v", "u", "y", "x")

PATH_FRAME = (
    "2D overlay on the centre view: (p_x, p_y) in views drawn at pixel "
    "((Y-1)/2 + s*p_y, (X-1)/2 + s*p_x) with s = min(Y, X) / (2 * max(U, V)) px/view; "
    "grey rectangle = the aperture; p_z and a rotation (r_x, r_y, r_z, rad) are not drawn "
    "(see control_points)"
)


class LayerError(ValueError):
    """A layer cannot be used as a light field (or holds no path)."""


# ------------------------------------------------------------ light field


def layer_kind(layer) -> str | None:
    """``'image'``, ``'shapes'``, ... for a napari layer (works through napari's
    public-only proxies, which forbid private attributes), None for anything else."""
    from napari import layers

    for cls in (layers.Image, layers.Shapes, layers.Labels, layers.Points, layers.Vectors, layers.Surface,
                layers.Tracks):
        if isinstance(layer, cls):
            return cls.__name__.lower()
    return None


def lightfield_from_layer(layer) -> np.ndarray:
    """A float32 copy of a layer's light field, ``(V, U, Y, X[, C])`` in [0, 1].

    Integer data are divided by their dtype's maximum (docs/model.md). The layer
    is never modified: the result is always a new array.

    Parameters
    ----------
    layer : napari.layers.Image or None

    Returns
    -------
    ndarray, float32, shape (V, U, Y, X) or (V, U, Y, X, C)

    Raises
    ------
    LayerError
        When no layer is given, it is not an Image layer, is multiscale, or
        its data are not 4D (5D for an RGB layer).
    """
    if layer is None:
        raise LayerError("no light-field layer selected: open or choose a 4D image layer first")
    if layer_kind(layer) != "image":
        raise LayerError(f"layer {layer.name!r} is not an Image layer")
    if getattr(layer, "multiscale", False):
        raise LayerError(f"layer {layer.name!r} is multiscale; a plain 4D array is needed")
    data = np.asarray(layer.data)
    want = 5 if getattr(layer, "rgb", False) else 4
    if data.ndim != want and not (data.ndim == 5 and data.shape[-1] in (1, 2, 3, 4)):
        raise LayerError(
            f"layer {layer.name!r} has shape {data.shape}: a light field is a 4D "
            "(V, U, Y, X) array, or 5D (V, U, Y, X, C) for colour"
        )
    if np.issubdtype(data.dtype, np.integer):
        out = data.astype(np.float32) / np.float32(np.iinfo(data.dtype).max)
    elif data.dtype == bool:
        out = data.astype(np.float32)
    else:
        out = np.array(data, dtype=np.float32, copy=True)
    if not np.all(np.isfinite(out)):
        raise LayerError(f"layer {layer.name!r} contains NaN or Inf values")
    return out


def lightfield_metadata(
    *,
    kind: str,
    parameters: dict | None = None,
    control_points=None,
    n_times: int | None = None,
    infinity_disparity: float | None = None,
    source_layer: str | None = None,
    **extra: Any,
) -> dict:
    """The ``metadata`` dict of a light-field layer made by this plugin.

    ``control_points`` is stored as a list of ``[p_x, p_y, p_z]`` lists, or of
    6-element lists with the rotation (JSON friendly); the package version
    goes in ``'napari_lfdeblur_version'``.
    """
    meta: dict[str, Any] = {
        "napari_lfdeblur_version": napari_lfdeblur.__version__,
        "kind": kind,
        "parameters": dict(parameters or {}),
    }
    if control_points is not None:
        meta["control_points"] = validate_control_points(control_points).tolist()
    if n_times is not None:
        meta["n_times"] = int(n_times)
    if infinity_disparity is not None:
        meta["infinity_disparity"] = float(infinity_disparity)
    if source_layer is not None:
        meta["source_layer"] = str(source_layer)
    meta.update(extra)
    return meta


def lightfield_layer_data(lf, *, name: str, metadata: dict | None = None, **kwargs):
    """A layer data tuple for a light field.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        C = 3 or 4 gives an RGB layer; C = 1 is squeezed to 4D.
    name : str
    metadata : dict, optional
        Usually from :func:`lightfield_metadata`.
    **kwargs
        More Image layer keyword arguments.

    Returns
    -------
    tuple ``(data, kwargs, 'image')``
    """
    arr = np.asarray(lf)
    if arr.ndim == 5 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (4, 5):
        raise LayerError(f"a light field is 4D or 5D; got shape {arr.shape}")
    rgb = arr.ndim == 5 and arr.shape[-1] in (3, 4)
    labels = LF_AXIS_LABELS if arr.ndim == 4 or rgb else LF_AXIS_LABELS + ("c",)
    kw = {"name": name, "axis_labels": labels, "rgb": rgb, "metadata": dict(metadata or {})}
    if not rgb:
        kw["contrast_limits"] = (0.0, 1.0)
    kw.update(kwargs)
    return arr, kw, "image"


def control_points_from_layer(layer) -> np.ndarray:
    """The path stored in a layer's ``metadata['control_points']``.

    Returns
    -------
    ndarray, float64, shape (n, 3), or (n, 6) for a path with rotation

    Raises
    ------
    LayerError
        When the layer holds no (valid) path.
    """
    if layer is None:
        raise LayerError("no layer selected to take the path from")
    cp = getattr(layer, "metadata", {}).get("control_points")
    if cp is None:
        raise LayerError(f"layer {layer.name!r} holds no camera path (metadata['control_points'])")
    try:
        return validate_control_points(cp)
    except ValueError as exc:
        raise LayerError(f"layer {layer.name!r}: {exc}") from None


def windows_from_shapes(shapes, image) -> list[tuple[int, int, int, int]]:
    """The windows ``(y0, x0, height, width)`` of a light field's views that a Shapes layer marks.

    Each shape (a rectangle, or any shape: its bounding box), drawn over the
    light-field Image layer ``image`` at any view, gives the pixels its
    ``(y, x)`` extent covers (vertices rounded to the nearest pixel centre,
    both ends included), clipped to the view. The layers' scale and
    translation are taken into account.

    Raises
    ------
    LayerError
        When the layer holds no shape, or a shape lies outside the view.
    """
    Y, X = image.data.shape[2:4]
    if len(shapes.data) == 0:
        raise LayerError(f"layer {shapes.name!r} holds no shape; draw a rectangle where the path is to be estimated")
    windows = []
    for verts in shapes.data:
        world = np.asarray(verts)[:, -2:] * np.asarray(shapes.scale)[-2:] + np.asarray(shapes.translate)[-2:]
        pix = (world - np.asarray(image.translate)[-2:]) / np.asarray(image.scale)[-2:]
        (y0, x0), (y1, x1) = np.floor(pix.min(axis=0) + 0.5), np.floor(pix.max(axis=0) + 0.5) + 1
        y0, x0, y1, x1 = int(max(y0, 0)), int(max(x0, 0)), int(min(y1, Y)), int(min(x1, X))
        if y1 <= y0 or x1 <= x0:
            raise LayerError(f"a shape of layer {shapes.name!r} lies outside the {Y} x {X} views of {image.name!r}")
        windows.append((y0, x0, y1 - y0, x1 - x0))
    return windows


# ---------------------------------------------------------------- paths


def path_scale(shape) -> float:
    """Pixels per view of the path overlay: ``min(Y, X) / (2 * max(U, V))``."""
    V, U, Y, X = (int(s) for s in tuple(shape)[:4])
    return min(Y, X) / (2.0 * max(U, V, 1))


def _path_polyline(cp, shape, n_times, s):
    """The translation ``(p_x, p_y)`` of a 3- or 6-column path at ``n_times`` instants, in pixels."""
    V, U, Y, X = tuple(shape)[:4]
    pos = bezier_positions(cp, n_times)
    return np.stack([(Y - 1) / 2 + s * pos[:, 1], (X - 1) / 2 + s * pos[:, 0]], axis=1)


def path_layer_data(
    control_points,
    lf_shape,
    *,
    n_times: int = 32,
    name: str = "camera path",
    true_control_points=None,
    infinity_disparity: float | None = None,
    metadata: dict | None = None,
):
    """A Shapes layer data tuple that draws a camera path over the centre view.

    Parameters
    ----------
    control_points : array_like, shape (n, 3) or (n, 6)
        The (estimated or simulated) path. Its translation is drawn; a
        rotation is kept in the metadata (and plotted by the widgets).
    lf_shape : tuple
        ``(V, U, Y, X[, C])`` of the light field it belongs to.
    n_times : int
        Number of exposure instants at which the curve is sampled.
    true_control_points : array_like, shape (m, 3) or (m, 6), optional
        A known true path, drawn in cyan.
    infinity_disparity : float, optional
        The ``d_inf`` the path blurs with, kept in the metadata beside
        ``n_times`` (so that a widget taking the path, or the path JSON
        writer, has the whole blur model).
    metadata : dict, optional
        More metadata entries.

    Returns
    -------
    tuple ``(shapes, kwargs, 'shapes')``
        Shapes are 2D ``(row, col)`` pixel coordinates of the centre view,
        in the frame described in this module's docstring.
    """
    cp = validate_control_points(control_points)
    V, U, Y, X = (int(s) for s in tuple(lf_shape)[:4])
    s = path_scale((V, U, Y, X))
    cy, cx = (Y - 1) / 2, (X - 1) / 2
    hu, hv = s * (U - 1) / 2, s * (V - 1) / 2
    aperture = np.array([[cy - hv, cx - hu], [cy + hv, cx + hu]])
    shapes = [aperture]
    types = ["rectangle"]
    edge = ["#909090"]
    kinds = ["aperture"]
    if true_control_points is not None:
        true_line = _path_polyline(validate_control_points(true_control_points), (V, U, Y, X), n_times, s)
        shapes.append(true_line)
        types.append("path")
        edge.append("cyan")
        kinds.append("true path")
    line = _path_polyline(cp, (V, U, Y, X), n_times, s)
    r = max(0.5, s * 0.15)
    # an ellipse given by the 4 corners of its bounding box (2 rows would mean centre and radii)
    start = line[0] + r * np.array([[-1.0, -1.0], [-1.0, 1.0], [1.0, 1.0], [1.0, -1.0]])
    shapes += [line, start]
    types += ["path", "ellipse"]
    edge += ["yellow", "yellow"]
    kinds += ["path", "start (t = 0)"]
    meta = {
        "napari_lfdeblur_version": napari_lfdeblur.__version__,
        "kind": "path",
        "control_points": cp.tolist(),
        "n_times": int(n_times),
        **({} if infinity_disparity is None else {"infinity_disparity": float(infinity_disparity)}),
        "pixels_per_view": s,
        "lightfield_shape": [V, U, Y, X],
        "view_shape": [Y, X],
        "frame": PATH_FRAME,
    }
    if cp.shape[1] == 6:
        path_positions = bezier_positions(cp, n_times)
        meta["motion"] = "6dof"
        meta["max_rotation_rad"] = float(np.abs(path_positions[:, 3:]).max())
    if true_control_points is not None:
        meta["true_control_points"] = validate_control_points(true_control_points).tolist()
    meta.update(metadata or {})
    kw = {
        "name": name,
        "shape_type": types,
        "edge_color": edge,
        "face_color": "transparent",
        "edge_width": max(0.15, s * 0.12),
        "features": {"kind": kinds},
        "axis_labels": ("y", "x"),
        "metadata": meta,
    }
    return shapes, kw, "shapes"


# ------------------------------------------------------------------ EPIs


def _stretch(n_views: int, n_pixels: int) -> int:
    """Integer stretch so that ``n_views`` rows show as about a quarter of ``n_pixels``."""
    return max(1, int(round(n_pixels / (4.0 * max(1, n_views)))))


def epi_layer_data(lf, which: str, *, name: str, v=None, u=None, y=None, x=None, metadata=None):
    """A layer data tuple for a horizontal (``'h'``) or vertical (``'v'``) EPI.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
    which : {'h', 'v'}
        ``'h'``: ``lf[v, :, y, :]``, shape ``(U, X[, C])``, placed below the
        light field. ``'v'``: ``lf[:, u, :, x]`` transposed to ``(Y, V[, C])``,
        placed to its right.
    v, y : int
        View row and pixel row of the horizontal EPI (centre by default).
    u, x : int
        View column and pixel column of the vertical EPI.

    Returns
    -------
    tuple ``(data, kwargs, 'image')``
    """
    arr = np.asarray(lf)
    V, U, Y, X = arr.shape[:4]
    rgb = arr.ndim == 5 and arr.shape[-1] in (3, 4)
    gap = max(2, Y // 16)
    if which == "h":
        data = horizontal_epi(arr, v, y)
        k = _stretch(U, Y)
        place = {"scale": (k, 1), "translate": (Y + gap, 0), "axis_labels": ("u", "x")}
        pick = {"v": V // 2 if v is None else int(v), "y": Y // 2 if y is None else int(y)}
    elif which == "v":
        data = np.swapaxes(vertical_epi(arr, u, x), 0, 1)
        k = _stretch(V, X)
        place = {"scale": (1, k), "translate": (0, X + gap), "axis_labels": ("y", "v")}
        pick = {"u": U // 2 if u is None else int(u), "x": X // 2 if x is None else int(x)}
    else:
        raise ValueError(f"which must be 'h' or 'v'; got {which!r}")
    data = np.ascontiguousarray(data)
    meta = {"napari_lfdeblur_version": napari_lfdeblur.__version__, "kind": f"epi-{which}", **pick}
    meta.update(metadata or {})
    kw = {"name": name, "rgb": rgb, "metadata": meta, **place}
    if not rgb:
        kw["contrast_limits"] = (0.0, 1.0)
    return data, kw, "image"


# --------------------------------------------------------------- viewer


#: the layers :func:`add_layer` made with ``replace``: the only ones a later call may update or remove
_REPLACEABLE = weakref.WeakSet()


def _unwrapped(layer):
    """The layer itself: a widget opened from napari's plugin menu gets a proxy of the viewer, which hands
    out a new wrapper of a layer each time (a weak set of wrappers would lose them at once)."""
    return getattr(layer, "__wrapped__", layer)


def add_layer(viewer, layer_data, *, replace: bool = True):
    """Add a layer data tuple to ``viewer``; return the layer.

    With ``replace`` (default) a layer of the same name that an earlier call
    with ``replace`` made (a previous result) is updated in place (data,
    metadata and placement) when it is of the same type, else removed and
    added again. Any other layer of that name (the user's, or one a reader
    or the *Open* widget added) is left as it is: the new layer gets
    napari's next free name (``'name [1]'``), which the next call updates.
    """
    data, kwargs, layer_type = layer_data
    name = kwargs.get("name")
    previous = [layer for layer in viewer.layers if _unwrapped(layer) in _REPLACEABLE and _named(layer.name, name)]
    if replace and previous:
        layer = previous[0]
        if layer_kind(layer) == layer_type and _compatible(layer, data, kwargs):
            if layer_type == "shapes":
                layer.data = []
                layer.add(data, shape_type=kwargs["shape_type"],
                          edge_color=kwargs["edge_color"], face_color=kwargs["face_color"],
                          edge_width=kwargs["edge_width"])
                layer.features = kwargs["features"]
            else:
                layer.data = data
            for key in ("scale", "translate"):
                if key in kwargs:
                    setattr(layer, key, kwargs[key])
            layer.metadata = kwargs.get("metadata", {})
            return layer
        viewer.layers.remove(layer)
    layer = getattr(viewer, f"add_{layer_type}")(data, **kwargs)
    if replace:
        _REPLACEABLE.add(_unwrapped(layer))
    return layer


def _named(actual: str, name) -> bool:
    """Whether a layer called ``actual`` is one asked to be called ``name`` (napari adds ``' [k]'`` to a taken name)."""
    return isinstance(name, str) and re.fullmatch(re.escape(name) + r"( \[\d+\])?", actual) is not None


def _compatible(layer, data, kwargs) -> bool:
    if layer_kind(layer) == "shapes":
        return True
    arr = np.asarray(data)
    return arr.ndim == layer.data.ndim and bool(getattr(layer, "rgb", False)) == bool(kwargs.get("rgb", False))


def remove_layer(viewer, name: str) -> None:
    """Remove the layer that :func:`add_layer` (with ``replace``) made as ``name``, when there is one."""
    for layer in list(viewer.layers):
        if _unwrapped(layer) in _REPLACEABLE and _named(layer.name, name):
            viewer.layers.remove(layer)
            return
