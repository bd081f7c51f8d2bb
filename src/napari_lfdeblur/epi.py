"""Epipolar images (EPIs) of a light field, and the geometry of its views.

A horizontal EPI fixes a view row ``v`` and a pixel row ``y`` and shows
``(u, x)``: a scene point at disparity ``d`` traces a line of slope ``d``
px/view in it. Motion blur smears those lines, which makes EPIs the natural
place to see both blur and its removal.
"""

from __future__ import annotations

import warnings

import numpy as np

from ._lightfield import check_int, validate_lightfield

__all__ = [
    "horizontal_epi",
    "vertical_epi",
    "view_shifts",
    "views_transposed",
    "MIN_VIEW_CORRELATION",
    "shifts_measurable",
    "transposed_from_shifts",
    "warn_if_transposed",
    "ViewOrderWarning",
]


def _index(value, size, name):
    value = check_int(value, name)
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


def _gray_view(arr: np.ndarray, v: int, u: int) -> np.ndarray:
    view = np.asarray(arr[v, u], dtype=np.float64)
    return view.mean(axis=-1) if view.ndim == 3 else view


#: registered views that correlate less than this with the centre view are not shifted copies of it
MIN_VIEW_CORRELATION = 0.3


def _register(ref: np.ndarray, moving: np.ndarray, n_refine: int = 4) -> tuple[np.ndarray, float]:
    """The ``(dy, dx)`` shift that, applied to ``moving``, best matches ``ref``, and how well it does.

    Phase correlation finds it to within a fraction of a pixel (its
    upsampled peak is biased towards whole pixels on smooth images); a few
    Gauss-Newton steps on the squared difference (Lucas-Kanade) refine it.
    The second value is the correlation coefficient of ``ref`` and the
    shifted ``moving`` away from the edges: nan for flat views, 0 for a
    shift that leaves no overlap.
    """
    from scipy import ndimage
    from skimage.registration import phase_cross_correlation

    if np.ptp(ref) == 0 or np.ptp(moving) == 0:  # a flat view has nothing to register (and skimage warns)
        return np.zeros(2), float("nan")
    shift = np.asarray(phase_cross_correlation(ref, moving, upsample_factor=10, normalization=None)[0], float)
    for _ in range(n_refine):
        m = ndimage.shift(moving, shift, order=3, mode="nearest")
        b = int(np.ceil(np.abs(shift).max())) + 2
        if min(ref.shape) <= 2 * b + 2:
            break
        crop = (slice(b, -b), slice(b, -b))
        gy, gx = np.gradient(m)
        jac = np.stack([gy[crop].ravel(), gx[crop].ravel()], axis=1)
        step, *_ = np.linalg.lstsq(jac, (m - ref)[crop].ravel(), rcond=None)
        shift += step
        if np.abs(step).max() < 1e-3:
            break
    b = int(np.ceil(np.abs(shift).max())) + 2
    if min(ref.shape) <= 2 * b + 2:
        return shift, 0.0  # shifted out of the view: no match
    crop = (slice(b, -b), slice(b, -b))
    a, m = ref[crop].ravel(), ndimage.shift(moving, shift, order=3, mode="nearest")[crop].ravel()
    a, m = a - a.mean(), m - m.mean()
    norm = float(np.sqrt((a * a).sum() * (m * m).sum()))
    return shift, float((a * m).sum()) / norm if norm > 0 else float("nan")


def view_shifts(lf, *, validate: bool = True) -> np.ndarray:
    """How far the image moves per view step along each angular axis, in px/view.

    The whole centre view is registered (phase correlation refined by
    Lucas-Kanade steps) with the views at both ends of the centre column and
    of the centre row. For a scene at one dominant disparity ``d`` laid out
    as in docs/model.md (a point at ``x`` in view ``u`` is at ``x + d`` in view
    ``u + 1``, likewise for ``v`` and ``y``) the result is
    ``[[d, 0], [0, d]]``.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        At least 2 views along each angular axis and 8 x 8 px per view
        (:func:`shifts_measurable`). Only five views are read.
    validate : bool, default True
        Check ``lf`` first (False for an array already checked, such as one
        just read: skips a pass over the whole array).

    Returns
    -------
    ndarray, float64, shape (2, 2)
        Row 0: the ``(y, x)`` displacement per step of ``v``; row 1: per
        step of ``u``.

    Examples
    --------
    A texture that moves by 2 px per view (circularly, so the shifts are exact):

    >>> import numpy as np
    >>> from napari_lfdeblur import view_shifts
    >>> tex = np.random.default_rng(0).random((32, 32))
    >>> lf = np.stack([np.stack([np.roll(tex, (2 * v, 2 * u), axis=(0, 1)) for u in range(5)])
    ...                for v in range(5)])
    >>> view_shifts(lf).round(3) + 0.0
    array([[2., 0.],
           [0., 2.]])
    >>> view_shifts(lf.swapaxes(0, 1)).round(3) + 0.0  # u now moves the image along y
    array([[0., 2.],
           [2., 0.]])
    """
    return _view_motion(lf, validate, "view_shifts")[0]


def _view_motion(lf, validate: bool, caller: str) -> tuple[np.ndarray, float]:
    """:func:`view_shifts` of ``lf``, and the least correlation of a registered view pair."""
    arr = validate_lightfield(lf) if validate else np.asarray(lf)
    if not shifts_measurable(arr.shape):
        raise ValueError(f"{caller} needs at least 2 x 2 views of 8 x 8 px; got shape {arr.shape}")
    V, U = arr.shape[:2]
    cv, cu = (V - 1) // 2, (U - 1) // 2
    ref = _gray_view(arr, cv, cu)
    out, least = np.zeros((2, 2)), 1.0
    for axis, (n, c) in enumerate(((V, cv), (U, cu))):
        per_step = []
        for end in (0, n - 1):
            if end == c:
                continue
            v, u = (end, cu) if axis == 0 else (cv, end)
            # the shift that registers the end view onto the centre one is -(end - c) * d
            shift, agreement = _register(ref, _gray_view(arr, v, u))
            per_step.append(-shift / (end - c))
            least = min(least, agreement) if not np.isnan(agreement) else least
        out[axis] = np.mean(per_step, axis=0)
    return out, least


def shifts_measurable(shape) -> bool:
    """Whether :func:`view_shifts` can measure a light field of this shape (at least 2 x 2 views of 8 x 8 px)."""
    return min(shape[:2]) >= 2 and min(shape[2:4]) >= 8


def views_transposed(lf, min_shift: float = 0.1) -> bool | None:
    """Whether the angular axes of a light field look swapped against its spatial ones.

    In the layout of docs/model.md, stepping through ``u`` moves the image along
    ``x`` and stepping through ``v`` moves it along ``y``. Exported view
    folders sometimes name their views the other way round (the row index
    being the horizontal one), and the light field read then moves along
    ``y`` with ``u``: blur simulation, deconvolution and the blind solver
    all assume that layout. Swapping the first two axes
    (``lf.swapaxes(0, 1)``) fixes such a light field.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
    min_shift : float, default 0.1
        Below this many px/view of motion the views are too alike to tell.

    Returns
    -------
    bool or None
        True when the motion is mostly across (``u`` moves ``y``, ``v``
        moves ``x``), False when it is mostly along the documented axes, None
        when the scene barely moves between views (a light field focused on
        its content), the motion is not clearly either, or the views are not
        shifted copies of each other (registered, a pair correlates by less
        than :data:`MIN_VIEW_CORRELATION`: noise, unrelated images).
    """
    if isinstance(min_shift, bool) or not isinstance(min_shift, (int, float, np.number)) or not min_shift >= 0:
        raise ValueError(f"min_shift must be a number >= 0 (px/view); got {min_shift!r}")
    shifts, agreement = _view_motion(lf, True, "views_transposed")
    return transposed_from_shifts(shifts, min_shift) if agreement >= MIN_VIEW_CORRELATION else None


def transposed_from_shifts(shifts: np.ndarray, min_shift: float = 0.1) -> bool | None:
    """:func:`views_transposed` from the ``(2, 2)`` result of :func:`view_shifts`."""
    s = np.abs(shifts)
    along, across = s[0, 0] + s[1, 1], s[0, 1] + s[1, 0]
    if max(along, across) < 2 * min_shift:
        return None
    if across > 2 * along:
        return True
    if along > 2 * across:
        return False
    return None


class ViewOrderWarning(UserWarning):
    """The views of a light field look transposed against the light-field layout.

    Its ``shifts`` attribute holds the measurement, as :func:`view_shifts` returns it.
    """


def warn_if_transposed(lf, source: str, *, fix: str = "", stacklevel: int = 2) -> np.ndarray | None:
    """Measure the views' motion and warn (:class:`ViewOrderWarning`) when their axes look swapped.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        A checked light field (it is not validated again).
    source : str
        What the warning names: a file, or ``'the blurred light field'``.
    fix : str, optional
        A remedy to offer before swapping the first two axes (ends with
        ``', or '``).
    stacklevel : int, default 2
        As in :func:`warnings.warn`, counted from the caller.

    Returns
    -------
    ndarray of shape (2, 2), or None
        :func:`view_shifts`' measurement; None where it cannot be made
        (:func:`shifts_measurable`), and then nothing is warned. Nor is it
        when the views are not shifted copies of each other
        (:func:`views_transposed`).
    """
    if not shifts_measurable(lf.shape):
        return None
    shifts, agreement = _view_motion(lf, False, "warn_if_transposed")
    if agreement >= MIN_VIEW_CORRELATION and transposed_from_shifts(shifts):
        warning = ViewOrderWarning(
            f"{source}: the views look transposed: stepping through u moves the image along y by "
            f"{shifts[1, 0]:+.2f} px/view and stepping through v moves it along x by {shifts[0, 1]:+.2f} px/view, "
            f"where the light-field layout has u move x and v move y. Blur, deconvolution and blind deblurring "
            f"assume that layout: {fix}swap the first two axes (lf.swapaxes(0, 1))."
        )
        warning.shifts = shifts
        warnings.warn(warning, stacklevel=stacklevel + 1)
    return shifts
