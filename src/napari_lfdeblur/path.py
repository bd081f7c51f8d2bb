"""Camera paths: Bezier curves in R^3 or R^6 (docs/model.md, "Camera path").

A path ``p(t) = (p_x, p_y, p_z)`` for ``t`` in [0, 1] is a Bezier curve of
``n >= 2`` control points, an ``(n, 3)`` array. ``p_x`` and ``p_y`` are in view
units; ``p_z`` is in view units per unit of normalised image coordinate ``x~``.
A 6-DOF path adds a small camera rotation ``(r_x, r_y, r_z)`` in radians: an
``(n, 6)`` array (docs/model.md, "Camera rotation").
The exposure is sampled at ``T`` instants ``t_k = k / (T - 1)``.
"""

from __future__ import annotations

import json
import math
import operator
import os
from pathlib import Path

import numpy as np

from ._bezier import (
    MAX_ROTATION,
    validate_control_points,
    has_rotation,
    validate_n_times,
    sample_times,
    bernstein_matrix,
    bezier_positions,
    center_path,
    elevate_degree,
    canonical_time_direction,
)
from ._lightfield import check_seed

__all__ = [
    "MAX_ROTATION", "has_rotation", "path_in_frame", "path_in_window", "path_view_mismatch",
    "validate_control_points", "validate_n_times", "sample_times", "bernstein_matrix", "bezier_positions",
    "center_path", "elevate_degree", "canonical_time_direction", "linear_path", "arc_path", "shake_path",
    "shake6_path", "random_path", "preset_path", "PRESETS", "save_path_json", "load_path_json", "read_path_json",
]


# ---------------------------------------------------------------- presets


def _number(name: str, value, minimum: float | None = None) -> float:
    """``value`` as a finite float (``>= minimum`` when given), or a ValueError naming ``name``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number; got {value!r}") from None
    if not math.isfinite(x) or (minimum is not None and x < minimum):
        bound = "" if minimum is None else f" >= {minimum:g}"
        raise ValueError(f"{name} must be a finite number{bound}; got {value!r}")
    return x


def linear_path(length: float = 2.0, angle_deg: float = 0.0, z: float = 0.0) -> np.ndarray:
    """A straight in-plane motion of ``length`` views at ``angle_deg``, centred.

    ``z`` adds a linear out-of-plane motion from ``-z/2`` to ``+z/2``.

    Returns
    -------
    ndarray, float64, shape (2, 3)

    Raises
    ------
    ValueError
        If ``length`` is negative, or any argument is not a finite number.
    """
    length, z = _number("length", length, 0.0), _number("z", z)
    a = math.radians(_number("angle_deg", angle_deg))
    d = np.array([math.cos(a), math.sin(a), 0.0]) * length / 2.0
    d[2] = z / 2.0
    return np.stack([-d, d])


def arc_path(length: float = 2.0, bend: float = 0.5, angle_deg: float = 0.0) -> np.ndarray:
    """A quadratic arc: a chord of ``length`` views bowed by ``bend * length``.

    Returns
    -------
    ndarray, float64, shape (3, 3), in the zero-mean gauge for T = 32

    Raises
    ------
    ValueError
        If ``length`` is negative, or any argument is not a finite number.
    """
    length, bend = _number("length", length, 0.0), _number("bend", bend)
    a = math.radians(_number("angle_deg", angle_deg))
    along = np.array([math.cos(a), math.sin(a), 0.0])
    across = np.array([-math.sin(a), math.cos(a), 0.0])
    cp = np.stack(
        [-along * length / 2, across * 2 * bend * length, along * length / 2]
    )
    return center_path(cp)


def shake_path(extent: float = 2.0, seed: int = 0, n_points: int = 5, z: float = 0.0) -> np.ndarray:
    """A hand-shake-like wiggle: random control points within ``extent`` views.

    Returns
    -------
    ndarray, float64, shape (n_points, 3), in the zero-mean gauge for T = 32

    Raises
    ------
    ValueError
        As :func:`random_path` (``z`` is its ``z_extent``).
    """
    return random_path(n_points=n_points, extent=extent, z_extent=_number("z", z, 0.0), seed=seed)


def random_path(
    n_points: int = 4, extent: float = 2.0, z_extent: float = 0.0, seed: int | None = 0
) -> np.ndarray:
    """A random Bezier path in the zero-mean gauge.

    Control points are drawn uniformly in a box of side ``extent`` views in
    x and y, and ``z_extent`` in z.

    Returns
    -------
    ndarray, float64, shape (n_points, 3)

    Raises
    ------
    ValueError
        If ``n_points`` is not an integer >= 2, or ``extent`` or
        ``z_extent`` is negative or not a finite number.
    """
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 2:
        raise ValueError(f"a Bezier path needs an integer number >= 2 of control points; got {n_points!r}")
    extent, z_extent = _number("extent", extent, 0.0), _number("z_extent", z_extent, 0.0)
    rng = np.random.default_rng(None if seed is None else check_seed(seed))
    cp = rng.uniform(-0.5, 0.5, size=(n_points, 3)) * np.array([extent, extent, z_extent])
    return center_path(cp)


def shake6_path(
    extent: float = 2.0, seed: int | None = 0, n_points: int = 5, rotation: float = 0.005, z: float = 0.0
) -> np.ndarray:
    """A handheld shake with camera rotation: :func:`shake_path` plus a random rotation.

    The translation is that of ``shake_path(extent, seed, n_points, z)``.
    The rotation control points ``(r_x, r_y, r_z)`` are drawn uniformly in
    ``[-rotation, rotation]`` radians (from a random stream independent of
    the translation's), moved to zero mean and, when that pushed one beyond
    ``rotation``, scaled back within it. A hand holds a camera to a few
    tenths of a degree: the default 0.005 rad moves the image by about
    ``0.005 R`` px, ``R = max(Y, X) / 2`` (docs/model.md, "Camera rotation").

    Parameters
    ----------
    extent : float
        Size of the translation, views.
    seed : int or None
        Random seed of both the translation and the rotation.
    n_points : int
        Control points (>= 2).
    rotation : float
        Largest rotation of a control point, radians, in
        ``[0, MAX_ROTATION]``.
    z : float
        Size of the out-of-plane motion ``p_z``.

    Returns
    -------
    ndarray, float64, shape (n_points, 6), in the zero-mean gauge for T = 32

    Raises
    ------
    ValueError
        If ``rotation`` is negative or beyond ``MAX_ROTATION``.
    """
    rotation = _number("rotation", rotation, 0.0)
    if not rotation <= MAX_ROTATION:
        raise ValueError(f"rotation must be in [0, {MAX_ROTATION}] rad; got {rotation:g}")
    translation = shake_path(extent=extent, seed=seed, n_points=n_points, z=z)
    rng = np.random.default_rng(None if seed is None else [int(seed), 6])
    rot = rng.uniform(-rotation, rotation, size=(n_points, 3))
    rot = center_path(np.concatenate([np.zeros_like(rot), rot], axis=1))[:, 3:]
    largest = np.abs(rot).max()
    if largest > rotation:
        rot *= rotation / largest  # still zero-mean: the mean is linear
    return np.concatenate([translation, rot], axis=1)


PRESETS = {
    "linear": linear_path,
    "arc": arc_path,
    "shake": shake_path,
    "shake6": shake6_path,
    "random": random_path,
}


def preset_path(name: str, extent: float = 2.0, seed: int = 0, rotation: float | None = None) -> np.ndarray:
    """A named preset path (``linear``, ``arc``, ``shake``, ``shake6`` or ``random``).

    ``extent`` (views) is the length of ``linear`` and ``arc``, the side of
    the box that ``shake``, ``shake6`` and ``random`` draw their control
    points from by ``seed`` (they move less). ``shake6`` is ``shake`` with
    a camera rotation of at most ``rotation`` radians (default 0.005), an
    ``(n, 6)`` path; the others are ``(n, 3)`` and take no rotation.

    Raises
    ------
    ValueError, TypeError
        For an unknown name, a negative or non-finite ``extent``, a ``seed``
        that is not a whole number from 0 to 2**63 - 1, or a ``rotation``
        given to a preset other than ``shake6``.
    """
    extent, seed = _number("the path's extent", extent, 0.0), check_seed(seed, "the path's seed")
    if rotation is not None and name != "shake6":
        raise ValueError(f"path preset {name!r} has no rotation; use shake6 for a path with rotation")
    if name == "linear":
        return linear_path(length=extent)
    if name == "arc":
        return arc_path(length=extent)
    if name == "shake":
        return shake_path(extent=extent, seed=seed)
    if name == "shake6":
        return shake6_path(extent=extent, seed=seed, rotation=0.005 if rotation is None else rotation)
    if name == "random":
        return random_path(extent=extent, seed=seed)
    raise ValueError(f"unknown path preset {name!r}: choose one of {sorted(PRESETS)}")


# ---------------------------------------------------------------- JSON


def save_path_json(path, control_points, *, overwrite: bool = False, **extra) -> Path:
    """Write control points to a JSON file, with units and any ``extra`` fields.

    The fields the package reads back are ``n_times``, ``infinity_disparity``
    and ``view_shape``, the ``(Y, X)`` of the views the path belongs to
    (:func:`path_view_mismatch`); they are checked here as the commands and
    widgets that use them check them (:func:`read_path_json` returns a
    file's fields as stated, since an option may replace them). Other
    values become JSON: numpy scalars numbers, tuples and small arrays
    lists, other objects their ``repr``. The file is written to a
    temporary name and renamed, so a failure leaves no half-written file.
    An existing file is kept unless ``overwrite``.

    Raises
    ------
    FileExistsError
        If the file exists and ``overwrite`` is False.
    FileNotFoundError
        If its folder does not exist.
    ValueError
        On malformed control points, ``n_times`` (a whole number >= 2),
        ``infinity_disparity`` (finite) or ``view_shape``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> f = pathlib.Path(tempfile.mkdtemp()) / "path.json"
    >>> _ = save_path_json(f, linear_path(2.0), n_times=32, view_shape=(376, 541))
    >>> read_path_json(f)[1]["view_shape"]
    [376, 541]
    """
    from .io._write import PATH_FIELDS, check_path_field, jsonable

    cp = validate_control_points(control_points)
    for key in PATH_FIELDS:
        if extra.get(key) is not None:
            value = extra[key]
            value = list(value) if key == "view_shape" and np.ndim(value) == 1 else value
            value = check_path_field(key, value, "the path")
            extra[key] = list(value) if key == "view_shape" else value
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"cannot write {path}: the folder {path.parent} does not exist")
    units = "p_x, p_y in views; p_z in views per unit of normalised x~"
    if cp.shape[1] == 6:
        units += "; r_x, r_y, r_z in radians"
    doc = {
        "control_points": cp.tolist(),
        "units": units + " (docs/model.md)",
        **extra,
    }
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        tmp.write_text(json.dumps(jsonable(doc), indent=2))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def load_path_json(path) -> np.ndarray:
    """Read control points from a JSON file written by :func:`save_path_json`.

    A bare list of ``[p_x, p_y, p_z]`` triples (or 6-DOF rows) is accepted too.
    """
    return read_path_json(path)[0]


def read_path_json(path) -> tuple[np.ndarray, dict]:
    """The control points of a path file (as :func:`load_path_json`) and its fields.

    Returns
    -------
    control_points : ndarray, float64, shape (n, 3) or (n, 6)
    fields : dict
        The file's JSON object (``n_times``, ``infinity_disparity``, ...,
        ``control_points`` included); empty for a bare list.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        On invalid JSON, no ``control_points`` entry, control points that
        are not an array of numbers as :func:`validate_control_points` takes
        them (the message names the file). The other fields are returned as
        stated.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path file {path} {'is a folder' if path.is_dir() else 'does not exist'}")
    try:
        doc = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not valid JSON: {exc}") from None
    from .io._write import path_from_document

    return path_from_document(doc, path)


def path_in_frame(cp, window, frame_shape) -> np.ndarray:
    """A path estimated on a window, in the full frame's coordinates.

    With ``x~ = (x - (X - 1) / 2) / R``, ``R = max(Y, X) / 2``, taken in the
    window (``x~_w``, ``R_w``) and in the frame (``x~``, ``R``): ``x~ = rho
    x~_w + delta_x`` with ``rho = R_w / R`` and ``delta_x`` the window
    centre's ``x~`` in the frame. The model's ``p_x - x~ p_z`` is then the
    window's ``p_x' - x~_w p_z'`` with ``p_z' = rho p_z`` and ``p_x' = p_x -
    delta_x p_z`` (likewise ``y``), which this inverts.

    Use it for a path estimated on a crop of a light field, to blur or
    restore the whole light field with it.

    Parameters
    ----------
    cp : array_like, shape (n, 3) or (n, 6)
        Control points found on the window. A rotation cannot be carried
        (its image displacement is quadratic in the frame's ``x~``, not in
        the window's); a 6-column path must have none.
    window : tuple of 4 int
        ``(y0, x0, height, width)`` of the window in the frame.
    frame_shape : tuple of 2 int
        ``(Y, X)`` of the frame.

    Returns
    -------
    ndarray, float64, the shape of ``cp``

    Raises
    ------
    ValueError
        If ``cp`` holds a rotation, or the window does not lie in the frame.

    Examples
    --------
    >>> cp_crop = [[-0.5, 0.0, 0.4], [0.5, 0.0, -0.4]]
    >>> path_in_frame(cp_crop, (0, 0, 128, 128), (376, 541)).round(3).tolist()
    [[-1.791, -0.775, 1.691], [1.791, 0.775, -1.691]]
    """
    cp = _translation_only(cp, "from a window to the frame")
    rho, dy, dx = _window_geometry(window, frame_shape)
    pz = cp[:, 2] / rho
    out = np.stack([cp[:, 0] + dx * pz, cp[:, 1] + dy * pz, pz], axis=1)
    return np.concatenate([out, cp[:, 3:]], axis=1)


def path_in_window(cp, window, frame_shape) -> np.ndarray:
    """A path of the full frame, in a window's own coordinates: the inverse of :func:`path_in_frame`.

    Blurring the frame with ``cp`` and cutting out the window gives the
    window blurred, as a light field of its own, with the returned path
    (exactly with ``d_inf = 0``; with ``d_inf != 0`` up to the window's
    replicate border). Use it to judge, on a crop, a path found on the whole
    light field, or to blur a crop as its frame was blurred.

    The arguments and the result are those of :func:`path_in_frame`, with
    ``cp`` in the frame's coordinates: ``(n, 3)``, or ``(n, 6)`` without a
    rotation (a rotation raises ``ValueError``); the result is float64, of
    ``cp``'s shape.

    Examples
    --------
    >>> cp = path_in_frame([[-0.5, 0.0, 0.4], [0.5, 0.0, -0.4]], (0, 0, 128, 128), (376, 541))
    >>> path_in_window(cp, (0, 0, 128, 128), (376, 541)).round(3).tolist()
    [[-0.5, 0.0, 0.4], [0.5, 0.0, -0.4]]
    """
    cp = _translation_only(cp, "from the frame to a window")
    rho, dy, dx = _window_geometry(window, frame_shape)
    out = np.stack([cp[:, 0] - dx * cp[:, 2], cp[:, 1] - dy * cp[:, 2], cp[:, 2] * rho], axis=1)
    return np.concatenate([out, cp[:, 3:]], axis=1)


def path_view_mismatch(control_points, view_shape, stated_view_shape) -> str | None:
    """Why a path found on views of ``stated_view_shape`` blurs views of ``view_shape`` differently, or None.

    ``p_x`` and ``p_y`` are in views whatever the view's size, but ``p_z``
    multiplies ``x~``, and a rotation moves the image by about ``R r`` px:
    both are taken about the view's centre with ``R = max(Y, X) / 2``
    (docs/model.md). So a path with ``p_z != 0`` or a rotation means another
    blur on views of another size, such as a crop of the views it was found
    on; :func:`path_in_window` and :func:`path_in_frame` move a path without
    rotation between a crop and its frame.

    Parameters
    ----------
    control_points : array_like, shape (n, 3) or (n, 6)
    view_shape : tuple of int
        ``(Y, X)`` of the views the path is applied to (a light field's
        shape ``(V, U, Y, X[, C])`` is taken too).
    stated_view_shape : tuple of 2 int or None
        ``(Y, X)`` of the views the path was found on or made for, as a path
        file states it (``view_shape``); None when not known.

    Returns
    -------
    str or None
        A sentence for people, or None when the sizes agree, are not known,
        or the path has neither ``p_z`` nor a rotation.

    Raises
    ------
    ValueError
        When ``view_shape`` (after dropping a light field's ``(V, U)``) or
        ``stated_view_shape`` is not ``(Y, X)``.

    Examples
    --------
    >>> path_view_mismatch([[0, 0, 0.5], [1, 0, -0.5]], (128, 128), (376, 541)) is not None
    True
    >>> path_view_mismatch([[0, 0, 0], [1, 0, 0]], (128, 128), (376, 541)) is None
    True
    """
    cp = validate_control_points(control_points)
    shape = tuple(int(s) for s in view_shape)
    shape = shape[2:4] if len(shape) >= 4 else shape
    if len(shape) != 2 or (stated_view_shape is not None and len(tuple(stated_view_shape)) != 2):
        raise ValueError(f"view_shape and stated_view_shape must be (Y, X); got {view_shape!r}, {stated_view_shape!r}")
    if stated_view_shape is None or tuple(stated_view_shape) == shape:
        return None
    rotation = has_rotation(cp)
    if not rotation and not np.any(cp[:, 2]):
        return None
    what = "p_z and rotation" if rotation and np.any(cp[:, 2]) else "rotation" if rotation else "p_z"
    (a, b), (c, d) = stated_view_shape, shape
    advice = ("a path with rotation cannot be moved between views of different sizes: estimate it on these views"
              if rotation else "if these views are a crop of those, move the path with path_in_window first "
              "(path_in_frame the other way round)")
    return (f"the path is for {a}x{b} views and these are {c}x{d}: its {what} is taken about the view's centre "
            f"and size (x~ = (x - (X - 1) / 2) / R, R = max(Y, X) / 2), so here it is another blur; {advice}")


def _translation_only(cp, move: str) -> np.ndarray:
    cp = validate_control_points(cp)
    if has_rotation(cp):
        raise ValueError(
            f"a path with rotation cannot be moved {move}; estimate it with the "
            "frame's coordinates (BlurOperator's frame argument)"
        )
    return cp


def _window_geometry(window, frame_shape):
    """``(rho, delta_y, delta_x)``: the window's ``R_w / R`` and its centre's ``(y~, x~)`` in the frame."""
    try:
        (y0, x0, h, w), (Y, X) = ([operator.index(v) for v in t] for t in (window, frame_shape))
    except (TypeError, ValueError):
        raise ValueError(f"window must be 4 whole numbers (y0, x0, height, width) and frame_shape 2 (Y, X); got "
                         f"{window!r} and {frame_shape!r}") from None
    if min(h, w, Y, X) < 1 or min(y0, x0) < 0 or y0 + h > Y or x0 + w > X:
        raise ValueError(f"the window {tuple(window)} does not lie in a {Y}x{X} frame")
    R, R_w = max(Y, X) / 2.0, max(h, w) / 2.0
    dy = (y0 + (h - 1) / 2.0 - (Y - 1) / 2.0) / R
    dx = (x0 + (w - 1) / 2.0 - (X - 1) / 2.0) / R
    return R_w / R, dy, dx
