"""The one check of light-field arrays, and of scalar arguments, shared by every module (numpy only); and the
warnings helpers the modules share."""

from __future__ import annotations

import math
import os
import sys
import warnings

import numpy as np

__all__ = ["as_array", "check_int", "check_view_grid", "check_number", "check_seed", "check_infinity_disparity",
           "validate_lightfield", "brightest", "white_level", "caller_stacklevel", "warnings_state",
           "restore_warnings", "DARK_LEVEL", "BRIGHT_LIMIT",
           "MAX_SEED"]

#: A light field whose :func:`brightest` value is below this is dark: the blind solver's salient-edge
#: weight is absolute, and dark data (10- or 12-bit values in a 16-bit file, a linear decode) show it few edges.
DARK_LEVEL = 0.25

#: A light field that reaches this is not on the [0, 1] scale (noise and highlights overshoot 1 by far less):
#: the blind solver, whose salient-edge weight is on that scale, refuses it rather than find no edges in it.
BRIGHT_LIMIT = 2.0

#: seeds are whole numbers from 0 to this (torch's generators take 64-bit signed seeds)
MAX_SEED = 2**63 - 1


def check_seed(seed, name: str = "seed") -> int:
    """A seed: a whole number from 0 to :data:`MAX_SEED` (TypeError when not an integer, ValueError out of range)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"{name} must be an integer; got {seed!r}")
    if not 0 <= seed <= MAX_SEED:
        raise ValueError(f"{name} must be a whole number from 0 to 2**63 - 1; got {seed}")
    return int(seed)


def caller_stacklevel() -> int:
    """The ``stacklevel`` with which the function calling this names, in a warning, the first caller outside
    this package (a user's line, whichever of the package's functions it went through)."""
    package = os.path.dirname(os.path.abspath(__file__))
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(package + os.sep):
        frame, level = frame.f_back, level + 1
    return level


def warnings_state() -> tuple:
    """The process-wide warnings machinery (``showwarning`` and the filters), for :func:`restore_warnings`."""
    return warnings.showwarning, list(warnings.filters)


def restore_warnings(state: tuple) -> None:
    """Put back a :func:`warnings_state`, as ``warnings.catch_warnings`` does on exit ("once" forgets)."""
    warnings.showwarning, warnings.filters[:] = state[0], state[1]
    getattr(warnings, "_filters_mutated", lambda: None)()


def brightest(lf) -> float:
    """The 99.9th percentile of the centre view of ``lf`` (V, U, Y, X[, C]), all channels: how bright it gets."""
    lf = np.asarray(lf)
    return float(np.percentile(lf[lf.shape[0] // 2, lf.shape[1] // 2], 99.9))


def white_level(dtype) -> float:
    """The top of the range of data of ``dtype``: its largest value for integers, else 1."""
    dtype = np.dtype(dtype)
    return float(np.iinfo(dtype).max) if dtype.kind in "iu" else 1.0


def check_number(value, name: str) -> float:
    """A finite real number as a float.

    Raises
    ------
    TypeError
        If ``value`` is not a real number (a bool, a string, None, ...).
    ValueError
        If it is NaN or infinite.
    """
    if isinstance(value, bool) or isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name} must be a number; got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number; got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite; got {value!r}")
    return v


def check_infinity_disparity(infinity_disparity, shape) -> float:
    """``infinity_disparity`` as a float, checked against the light field's ``shape`` (V, U, Y, X[, C]).

    The bound: ``|d_inf| * (max(V, U) - 1) / 2`` (the refocus of the
    outermost view, whose offset from the centre is ``(max(V, U) - 1) / 2``
    views) must not exceed half the smaller spatial size, ``min(Y, X) / 2``:
    beyond it, more than half of the outermost views' samples fall outside
    the view and are clamped to its border, and the model no longer sees the
    scene there.

    Raises
    ------
    TypeError
        If it is not a real number.
    ValueError
        If it is not finite or beyond the bound.
    """
    d_inf = check_number(infinity_disparity, "infinity_disparity")
    V, U, Y, X = shape[:4]
    half = (max(V, U) - 1) / 2.0
    if abs(d_inf) * half > min(Y, X) / 2.0:
        raise ValueError(
            f"infinity_disparity = {d_inf:g} px/view is beyond what {Y} x {X} views allow: the outermost view "
            f"would be shifted by {abs(d_inf) * half:g} px, more than half the view; |infinity_disparity| must "
            f"be at most {min(Y, X) / (2.0 * half):g}")
    return d_inf


def check_view_grid(shape) -> tuple:
    """``(V, U, Y, X)`` of a light field to make, as four ints (ValueError unless four positive integers)."""
    try:
        entries = list(shape)
    except TypeError:
        entries = []
    if len(entries) != 4 or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s >= 1
                                    for s in entries):
        raise ValueError(f"shape must be (V, U, Y, X) of positive integers; got {shape!r}")
    return tuple(int(s) for s in entries)


def check_int(value, name: str, minimum: int | None = None) -> int:
    """An integer (a Python or numpy integer, not a bool) as an int.

    Raises
    ------
    TypeError
        If ``value`` is not an integer.
    ValueError
        If it is below ``minimum``.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer; got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}; got {value}")
    return int(value)


def as_array(x) -> np.ndarray:
    """``np.asarray(x)``; of a torch tensor, its data, detached and on the CPU (one that requires grad or
    sits on a GPU too)."""
    if hasattr(x, "detach") and hasattr(x, "cpu"):
        x = x.detach().cpu().numpy()
    return np.asarray(x)


def validate_lightfield(lf, name: str = "light field", *, finite: bool = True) -> np.ndarray:
    """Check a light field array and return it as a numpy array (not copied).

    A light field is ``(V, U, Y, X)`` (grayscale) or ``(V, U, Y, X, C)`` with
    ``C`` in 1..4, non-empty, of a real numeric (or bool) dtype, and finite.
    Every module checks light fields with this one function; the readers
    turn its ``ValueError`` into a :class:`~napari_lfdeblur.io.LightFieldFormatError`
    naming the file.

    Parameters
    ----------
    lf : array_like
    name : str
        What the array is, for the error message.
    finite : bool, default True
        Also check that a float array has no NaN or Inf.

    Returns
    -------
    ndarray
        ``np.asarray(lf)`` (a torch tensor's data, detached, on the CPU).

    Raises
    ------
    ValueError
        On a wrong number of dimensions or channels, an empty array, a
        non-numeric or complex dtype, NaN or Inf, or a tuple or list of
        arrays of different shapes or of light fields (such as the
        ``(lightfield, disparity)`` pair that
        :func:`~napari_lfdeblur.synthetic_scene` returns; a list of rows of
        views, ``(U, Y, X[, C])`` each, is one light field).
    """
    if isinstance(lf, (tuple, list)) and any(isinstance(x, np.ndarray) or hasattr(x, "detach") for x in lf):
        shapes = {tuple(getattr(x, "shape", ())) for x in lf}
        if len(shapes) > 1 or max(map(len, shapes)) >= 4:
            raise ValueError(
                f"a {name} is one array (V, U, Y, X[, C]); got a {type(lf).__name__} of {len(lf)} arrays of "
                f"shapes {sorted(shapes)}. synthetic_scene and procedural_scene return (lightfield, disparity): "
                "pass the first"
            )
    arr = as_array(lf)
    if arr.ndim in (2, 3):
        raise ValueError(
            f"a {name} is 4D (V, U, Y, X) or 5D (V, U, Y, X, C); got a {arr.ndim}D array of shape "
            f"{arr.shape}. A single image or a stack of views is not enough: arrange the views on a (V, U) grid"
        )
    if arr.ndim not in (4, 5):
        raise ValueError(
            f"a {name} must be a 4D (V, U, Y, X) or 5D (V, U, Y, X, C) array; "
            f"got {arr.ndim}D with shape {arr.shape}"
        )
    if arr.ndim == 5 and not 1 <= arr.shape[4] <= 4:
        raise ValueError(
            f"a colour {name} must have 1 to 4 channels in its last axis (the layout is (V, U, Y, X, C)); "
            f"got shape {arr.shape}"
        )
    if min(arr.shape) < 1:
        raise ValueError(f"the {name} is empty: shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise ValueError(f"a {name} must hold numbers; got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise ValueError(f"a {name} must be real; got dtype {arr.dtype}")
    if finite and np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
        raise ValueError(f"the {name} contains NaN or Inf values")
    return arr
