"""Epipolar images (EPIs) of a light field.

A horizontal EPI fixes a view row ``v`` and a pixel row ``y`` and shows
``(u, x)``: a scene point at disparity ``d`` traces a line of slope ``d``
px/view in it. Motion blur smears those lines, which makes EPIs the natural
place to see both blur and its removal.
"""

from __future__ import annotations

import numpy as np

from .blur import validate_lightfield

__all__ = ["horizontal_epi", "vertical_epi"]


def _index(value, size, name):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer; got {value!r}")
    if not -size <= value < size:
        raise ValueError(f"{name}={value} is out of range for an axis of length {size}")
    return int(value)


def horizontal_epi(lf, v: int | None = None, y: int | None = None) -> np.ndarray:
    """The horizontal EPI ``lf[v, :, y, :]`` at view row ``v`` and pixel row ``y``.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
    v, y : int, optional
        View row and pixel row; the centre ones when omitted.

    Returns
    -------
    ndarray, shape (U, X) or (U, X, C), same dtype as ``lf``
    """
    arr = validate_lightfield(lf)
    V, U, Y, X = arr.shape[:4]
    v = V // 2 if v is None else _index(v, V, "v")
    y = Y // 2 if y is None else _index(y, Y, "y")
    return arr[v, :, y, :]


def vertical_epi(lf, u: int | None = None, x: int | None = None) -> np.ndarray:
    """The vertical EPI ``lf[:, u, :, x]`` at view column ``u`` and pixel column ``x``.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
    u, x : int, optional
        View column and pixel column; the centre ones when omitted.

    Returns
    -------
    ndarray, shape (V, Y) or (V, Y, C), same dtype as ``lf``
    """
    arr = validate_lightfield(lf)
    V, U, Y, X = arr.shape[:4]
    u = U // 2 if u is None else _index(u, U, "u")
    x = X // 2 if x is None else _index(x, X, "x")
    return arr[:, u, :, x]
