"""Checks of light-field arrays shared by the core modules (numpy only: no torch, no Qt)."""

from __future__ import annotations

import numpy as np


def validate_lightfield(lf, name: str = "light field") -> np.ndarray:
    """Check a light field array and return it as a numpy array.

    Accepts ``(V, U, Y, X)`` or ``(V, U, Y, X, C)`` with ``C`` in 1..4.

    Raises
    ------
    ValueError
        On a wrong number of dimensions, a non-numeric dtype, NaN or Inf.
    """
    arr = np.asarray(lf)
    if arr.ndim not in (4, 5):
        raise ValueError(
            f"a {name} must be a 4D (V, U, Y, X) or 5D (V, U, Y, X, C) array; "
            f"got {arr.ndim}D with shape {arr.shape}"
        )
    if arr.ndim == 5 and not 1 <= arr.shape[4] <= 4:
        raise ValueError(
            f"a colour {name} must have 1 to 4 channels in its last axis; got shape {arr.shape}"
        )
    if min(arr.shape) < 1:
        raise ValueError(f"the {name} is empty: shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise ValueError(f"a {name} must hold numbers; got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise ValueError(f"a {name} must be real; got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
        raise ValueError(f"the {name} contains NaN or Inf values")
    return arr
