"""Bezier camera paths: validation, sampling, gauge, time direction (re-exported by :mod:`napari_lfdeblur.path`)."""

from __future__ import annotations

import math

import numpy as np

from ._lightfield import as_array, check_int

__all__ = [
    "MAX_ROTATION",
    "validate_control_points",
    "has_rotation",
    "validate_n_times",
    "sample_times",
    "bernstein_matrix",
    "bezier_positions",
    "center_path",
    "elevate_degree",
    "canonical_time_direction",
]


#: largest rotation (radians) a control point may hold: beyond about 0.2 rad
#: (11 degrees) the first-order rotation model of docs/model.md breaks down.
MAX_ROTATION = 0.2


def validate_control_points(control_points) -> np.ndarray:
    """Check control points and return them as a new float64 ``(n, 3)`` or ``(n, 6)`` array.

    Columns are ``(p_x, p_y, p_z)`` or ``(p_x, p_y, p_z, r_x, r_y, r_z)``.

    Raises
    ------
    ValueError
        If the array is not ``(n, 3)`` or ``(n, 6)`` with ``n >= 2``, holds NaN
        or Inf or values beyond float32's range, or a rotation beyond
        ``MAX_ROTATION`` radians.
    """
    try:
        cp = as_array(control_points).astype(np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"control points must be numbers: {exc}") from None
    if cp.ndim != 2 or cp.shape[1] not in (3, 6):
        raise ValueError(
            "control points must be an (n, 3) array of (p_x, p_y, p_z) or an (n, 6) array of "
            f"(p_x, p_y, p_z, r_x, r_y, r_z); got shape {cp.shape}"
        )
    if cp.shape[0] < 2:
        raise ValueError(
            f"a Bezier path needs at least 2 control points; got {cp.shape[0]}"
        )
    if not np.all(np.isfinite(cp)):
        raise ValueError("control points contain NaN or Inf")
    if np.abs(cp).max() > np.finfo(np.float32).max:
        raise ValueError(f"control points must lie within +-{np.finfo(np.float32).max:.3g}, the range of float32 "
                         f"in which paths are computed; got {np.abs(cp).max():.3g}")
    if cp.shape[1] == 6 and np.abs(cp[:, 3:]).max() > MAX_ROTATION:
        raise ValueError(
            f"rotations must stay within {MAX_ROTATION} rad ({math.degrees(MAX_ROTATION):.1f} degrees), "
            f"where the small-angle model holds; got {np.abs(cp[:, 3:]).max():.3g} rad"
        )
    return np.array(cp, order="C")  # a copy: never the caller's own array


def has_rotation(control_points) -> bool:
    """True when ``control_points`` is ``(n, 6)`` with a rotation that is not zero."""
    shape = getattr(control_points, "shape", None) or np.shape(control_points)
    if len(shape) != 2 or shape[1] != 6:
        return False
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        torch = None
    if torch is not None and isinstance(control_points, torch.Tensor):
        return bool((control_points.detach()[:, 3:] != 0).any())
    return bool(np.any(np.asarray(control_points)[:, 3:] != 0))


def validate_n_times(n_times) -> int:
    """Check the number of exposure instants ``T`` (an integer >= 2)."""
    if isinstance(n_times, bool) or not isinstance(n_times, (int, np.integer)):
        raise ValueError(f"n_times must be an integer >= 2; got {n_times!r}")
    if n_times < 2:
        raise ValueError(f"n_times must be at least 2; got {n_times}")
    return int(n_times)


def sample_times(n_times: int) -> np.ndarray:
    """The exposure instants ``t_k = k / (T - 1)``, a float64 ``(T,)`` array."""
    n_times = validate_n_times(n_times)
    return np.arange(n_times, dtype=np.float64) / (n_times - 1)


def bernstein_matrix(n_points: int, n_times: int) -> np.ndarray:
    """Bernstein basis ``M[k, i] = C(n-1, i) t_k^i (1 - t_k)^(n-1-i)``.

    ``M @ control_points`` gives the path's positions at the ``T`` instants.

    Returns
    -------
    ndarray, float64, shape (T, n)
    """
    t = sample_times(n_times)[:, None]
    deg = n_points - 1
    i = np.arange(n_points)[None, :]
    binom = np.array([math.comb(deg, k) for k in range(n_points)], dtype=np.float64)
    return binom * t**i * (1.0 - t) ** (deg - i)


def bezier_positions(control_points, n_times: int):
    """Positions of the Bezier path at the ``T`` exposure instants.

    Parameters
    ----------
    control_points : array_like or torch.Tensor, shape (n, 3) or (n, 6)
        A torch tensor stays a tensor (differentiable; one of integers
        becomes float64); anything else gives a numpy array.
    n_times : int
        Number of instants ``T >= 2``.

    Returns
    -------
    ndarray or torch.Tensor, shape (T, 3) or (T, 6)
        ``(p_x, p_y, p_z[, r_x, r_y, r_z])`` at ``t_k = k / (T - 1)``.

    Examples
    --------
    >>> bezier_positions([[0, 0, 0], [2, 0, 0]], 3)
    array([[0., 0., 0.],
           [1., 0., 0.],
           [2., 0., 0.]])
    """
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        torch = None
    if torch is not None and isinstance(control_points, torch.Tensor):
        if control_points.ndim != 2 or control_points.shape[1] not in (3, 6) or control_points.shape[0] < 2:
            raise ValueError(
                f"control points must be an (n, 3) or (n, 6) tensor with n >= 2; got {tuple(control_points.shape)}"
            )
        if not control_points.is_floating_point():
            control_points = control_points.to(torch.float64)  # as a numpy array of integers is read
        if not bool(torch.isfinite(control_points.detach()).all()):
            raise ValueError("control points contain NaN or Inf")
        basis = torch.as_tensor(
            bernstein_matrix(control_points.shape[0], n_times),
            dtype=control_points.dtype,
            device=control_points.device,
        )
        return basis @ control_points
    cp = validate_control_points(control_points)
    return bernstein_matrix(cp.shape[0], n_times) @ cp


def center_path(control_points, n_times: int = 32) -> np.ndarray:
    """Move a path to the zero-mean gauge (docs/model.md).

    The mean of ``p(t_k)`` over the ``T`` instants becomes 0. Bernstein weights
    sum to one, so subtracting that mean from every control point shifts the
    whole curve by it.

    Returns
    -------
    ndarray, float64, shape (n, 3) or (n, 6), as given
    """
    cp = validate_control_points(control_points)
    return cp - bezier_positions(cp, n_times).mean(axis=0)


def elevate_degree(control_points, n_points: int) -> np.ndarray:
    """Raise the degree of a Bezier curve without changing it.

    Parameters
    ----------
    control_points : array_like, shape (n, 3) or (n, 6)
    n_points : int, >= n

    Returns
    -------
    ndarray, float64, shape (n_points, 3) or (n_points, 6), the same curve

    Raises
    ------
    TypeError
        If ``n_points`` is not an integer.
    ValueError
        If the control points are not valid (:func:`validate_control_points`)
        or ``n_points < n`` (a degree cannot be lowered exactly).
    """
    cp = validate_control_points(control_points)
    n_points = check_int(n_points, "n_points")
    if n_points < len(cp):
        raise ValueError(f"cannot lower a Bezier curve's degree: {len(cp)} -> {n_points} control points")
    while len(cp) < n_points:
        n = len(cp)  # degree n-1 -> n
        new = np.empty((n + 1, cp.shape[1]))
        new[0], new[n] = cp[0], cp[n - 1]
        for i in range(1, n):
            a = i / n
            new[i] = a * cp[i - 1] + (1 - a) * cp[i]
        cp = new
    return cp


def canonical_time_direction(control_points) -> np.ndarray:
    """Pick one of the two time directions of a path (the blur cannot tell them apart).

    The path is reversed when the largest component (in magnitude) of
    ``last - first`` control point is negative, so that the path moves
    towards positive values along its main direction. The translation
    decides; the rotation only when the translation's ends coincide.

    Parameters
    ----------
    control_points : array_like, shape (n, 3) or (n, 6)

    Returns
    -------
    ndarray, float64, the shape given (a new array)

    Raises
    ------
    ValueError
        If the control points are not valid (:func:`validate_control_points`).
    """
    cp = validate_control_points(control_points)
    d = cp[-1] - cp[0]
    if np.any(d[:3] != 0):
        d = d[:3]
    return cp[::-1].copy() if d[np.argmax(np.abs(d))] < 0 else cp
