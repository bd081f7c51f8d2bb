"""Quality metrics for restored light fields and estimated camera paths.

Image metrics (:func:`psnr`, :func:`ssim`, :func:`angular_error`) compare an
estimate with a reference of the same shape. Light fields are
``(V, U, Y, X)`` or ``(V, U, Y, X, C)``; plain images ``(Y, X)`` or
``(Y, X, C)`` are accepted too. ``crop`` removes that many pixels from every
spatial border (``y`` and ``x`` only, never views) before comparing, because
the replicated boundary of the blur model makes the outermost pixels
unrecoverable.
Arrays may also be torch tensors (their data is read, detached and on the
CPU).

Path metrics (:func:`path_error`) are blind to what a blur cannot identify
(docs/model.md, "Ambiguities"): the mean offset of the path
(the zero-mean gauge) and the order in which positions are visited.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ._lightfield import as_array, check_number, white_level
from .path import bezier_positions, validate_control_points, validate_n_times

__all__ = [
    "psnr",
    "ssim",
    "angular_error",
    "path_error",
    "chamfer_distance",
    "PathError",
]


# ----------------------------------------------------------------- helpers


def _spatial_axes(ndim: int) -> tuple[int, int]:
    if ndim in (2, 3):
        return (0, 1)
    if ndim in (4, 5):
        return (2, 3)
    raise ValueError(
        "expected an image (Y, X[, C]) or a light field (V, U, Y, X[, C]); "
        f"got a {ndim}D array"
    )


def _crop(arr: np.ndarray, crop: int) -> np.ndarray:
    if crop == 0:
        return arr
    ay, ax = _spatial_axes(arr.ndim)
    index = [slice(None)] * arr.ndim
    index[ay] = slice(crop, arr.shape[ay] - crop)
    index[ax] = slice(crop, arr.shape[ax] - crop)
    return arr[tuple(index)]


def _pair(estimate, reference, crop) -> tuple[np.ndarray, np.ndarray]:
    """Validate two arrays of equal shape and crop their spatial borders (float64)."""
    est = as_array(estimate)
    ref = as_array(reference)
    for name, arr in (("estimate", est), ("reference", ref)):
        if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool) or np.iscomplexobj(arr):
            raise ValueError(f"the {name} must hold real numbers; got dtype {arr.dtype}")
    if est.shape != ref.shape:
        raise ValueError(f"estimate and reference shapes differ: {est.shape} vs {ref.shape}")
    if est.size == 0:
        raise ValueError(f"estimate and reference are empty (shape {est.shape})")
    ay, ax = _spatial_axes(est.ndim)
    if isinstance(crop, bool) or not isinstance(crop, (int, np.integer)) or crop < 0:
        raise ValueError(f"crop must be a non-negative integer; got {crop!r}")
    crop = int(crop)
    if 2 * crop >= min(est.shape[ay], est.shape[ax]):
        raise ValueError(
            f"crop={crop} removes the whole image of {est.shape[ay]}x{est.shape[ax]} pixels"
        )
    est = _crop(est, crop).astype(np.float64)
    ref = _crop(ref, crop).astype(np.float64)
    if not (np.all(np.isfinite(est)) and np.all(np.isfinite(ref))):
        raise ValueError("estimate or reference contains NaN or Inf")
    return est, ref


# ------------------------------------------------------------ image metrics


def psnr(estimate, reference, *, data_range: float | None = None, crop: int = 0) -> float:
    """Peak signal-to-noise ratio in dB, ``10 log10(data_range^2 / MSE)``.

    Parameters
    ----------
    estimate, reference : ndarray
        Same shape: a light field ``(V, U, Y, X[, C])`` or an image ``(Y, X[, C])``.
    data_range : float, optional
        The intensity range. Default: 1 for floating-point inputs (light
        fields in [0, 1]), the dtype's largest value for integer inputs (255
        for uint8); inputs of two different dtypes, one of them integer,
        need it given.
    crop : int, default 0
        Pixels removed from each spatial border before comparing.

    Returns
    -------
    float
        The PSNR over all views, pixels and channels; ``inf`` when they are equal.
    """
    est, ref, data_range = _ranged_pair(estimate, reference, crop, data_range)
    mse = float(np.mean((est - ref) ** 2))
    if mse == 0.0:
        return float("inf")
    return float(10.0 * np.log10(float(data_range) ** 2 / mse))


def _ranged_pair(estimate, reference, crop, data_range):
    """:func:`_pair`'s arrays and :func:`_data_range`'s range, the inputs read once (a tensor is copied once)."""
    estimate, reference = as_array(estimate), as_array(reference)
    value = _data_range(data_range, estimate.dtype, reference.dtype)
    return (*_pair(estimate, reference, crop), value)


def _common_white_level(est_dtype, ref_dtype, remedy: str) -> float:
    """The top of the range of both dtypes (:func:`white_level`); ValueError, ending in ``remedy``, when they differ."""
    levels = {white_level(d) for d in (est_dtype, ref_dtype)}
    if len(levels) > 1:
        raise ValueError(f"estimate ({est_dtype}) and reference ({ref_dtype}) have different ranges: {remedy}")
    return levels.pop()


def _data_range(value, est_dtype, ref_dtype) -> float:
    """``data_range`` as a positive float (TypeError for a non-number, ValueError when not positive).

    None: the top of the inputs' range (:func:`white_level` of their dtypes), when they agree on it.
    """
    if value is None:
        return _common_white_level(est_dtype, ref_dtype, "give data_range")
    value = check_number(value, "data_range")
    if not value > 0:
        raise ValueError(f"data_range must be positive; got {value!r}")
    return value


def ssim(estimate, reference, *, data_range: float | None = None, crop: int = 0) -> float:
    """Structural similarity, the mean over views and channels.

    Each view (and each colour channel) is compared as a 2D image with
    :func:`skimage.metrics.structural_similarity` (its default 7x7 uniform
    window, or the largest odd window that fits a smaller image), and the
    values are averaged.

    Parameters
    ----------
    estimate, reference : ndarray
        Same shape: a light field ``(V, U, Y, X[, C])`` or an image ``(Y, X[, C])``.
    data_range : float, optional
        The intensity range, as in :func:`psnr`.
    crop : int, default 0
        Pixels removed from each spatial border before comparing.

    Returns
    -------
    float
        In [-1, 1]; 1 when equal.
    """
    from skimage.metrics import structural_similarity

    est, ref, data_range = _ranged_pair(estimate, reference, crop, data_range)
    ay, ax = _spatial_axes(est.ndim)
    win = min(7, est.shape[ay], est.shape[ax])
    win -= 1 - win % 2  # odd
    if win < 3:
        raise ValueError(f"SSIM needs images of at least 3x3 pixels; got {est.shape[ay]}x{est.shape[ax]}")
    # bring to (N, Y, X): every view and channel one 2D image
    if est.ndim in (3, 5):
        est = np.moveaxis(est, -1, 0)
        ref = np.moveaxis(ref, -1, 0)
    est = est.reshape(-1, est.shape[-2], est.shape[-1])
    ref = ref.reshape(-1, ref.shape[-2], ref.shape[-1])
    values = [
        structural_similarity(e, r, data_range=data_range, win_size=win)
        for e, r in zip(est, ref)
    ]
    return float(np.mean(values))


def angular_error(estimate, reference, *, crop: int = 0) -> float:
    """RMSE of the angular finite differences: how well the views agree with each other.

    A light field is consistent across views when every scene point moves
    along a straight line of slope = disparity in the EPIs. Independent
    per-view processing breaks that (each view gets its own residual blur,
    shift or ringing) even when every single view looks sharp. This metric
    compares the *differences between neighbouring views*,
    ``l[v, u+1] - l[v, u]`` and ``l[v+1, u] - l[v, u]``, of the estimate with
    those of the reference::

        sqrt( mean( (D_u e - D_u r)^2  over all samples of D_u
                  ++ (D_v e - D_v r)^2 over all samples of D_v ) )

    It is the error of the EPIs' angular derivative. It ignores an error that
    is the same in every view (a global intensity offset, say); use it next
    to :func:`psnr`, not instead of it. Lower is better; 0 for equal inputs.

    Parameters
    ----------
    estimate, reference : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        ``V * U >= 2``.
    crop : int, default 0
        Pixels removed from each spatial border before comparing.

    Returns
    -------
    float
        In the inputs' units (0..255 for two ``uint8`` light fields).

    Raises
    ------
    ValueError
        For inputs of different shapes, empty ones, NaN or Inf, light
        fields of one view, or dtypes of different ranges (integers against
        floats).
    """
    estimate, reference = as_array(estimate), as_array(reference)
    _common_white_level(estimate.dtype, reference.dtype,
                        "convert one to the other's (for example, integers to 0..1 floats)")
    est, ref = _pair(estimate, reference, crop)
    if est.ndim not in (4, 5):
        raise ValueError(f"angular_error needs light fields (V, U, Y, X[, C]); got {est.ndim}D arrays")
    diff = est - ref
    parts = []
    if diff.shape[1] > 1:
        parts.append(np.diff(diff, axis=1).ravel())
    if diff.shape[0] > 1:
        parts.append(np.diff(diff, axis=0).ravel())
    if not parts:
        raise ValueError("angular_error needs more than one view")
    d = np.concatenate(parts)
    return float(np.sqrt(np.mean(d**2)))


# ------------------------------------------------------------- path metrics


@dataclass(frozen=True)
class PathError:
    """Errors of an estimated camera path against the true one.

    All distances are in view units (``p_z`` counts as view units too: at the
    image edge one unit of ``p_z`` shifts the angular sample by one view).
    Both paths are first moved to the zero-mean gauge.

    Attributes
    ----------
    chamfer : float
        Symmetric Chamfer distance between the two sets of sampled positions:
        the mean of the two directed mean nearest-neighbour distances. Blind
        to time order.
    chamfer_relative : float
        ``chamfer / extent`` (``nan`` for a true path of zero extent).
    rmse : float
        Pointwise RMSE between positions at equal instants, for the better
        of the two time directions of the estimate.
    rmse_relative : float
        ``rmse / extent`` (``nan`` for a true path of zero extent).
    extent : float
        The true path's extent: the largest distance between two of its
        sampled positions.
    reversed : bool
        Whether the time-reversed estimate gave the lower RMSE.
    blur_mismatch : float or None
        ``||B(l, p_est) - B(l, p_true)|| / ||B(l, p_true) - l||`` on the light
        field given to :func:`path_error`; ``None`` when none was given,
        ``nan`` when the true path does not blur it.
    """

    chamfer: float
    chamfer_relative: float
    rmse: float
    rmse_relative: float
    extent: float
    reversed: bool
    blur_mismatch: float | None = None

    def as_dict(self) -> dict:
        """The fields as a plain dict (JSON-friendly)."""
        return asdict(self)


def chamfer_distance(a, b) -> float:
    """Symmetric Chamfer distance between two point sets.

    ``0.5 * (mean_i min_j |a_i - b_j| + mean_j min_i |a_i - b_j|)``, with
    Euclidean distances.

    Parameters
    ----------
    a : array_like, shape (N, D)
    b : array_like, shape (M, D)

    Returns
    -------
    float

    Raises
    ------
    ValueError
        If the sets are empty, of different ``D``, or hold NaN or Inf.
    """
    a = as_array(a).astype(np.float64)
    b = as_array(b).astype(np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or len(a) == 0 or len(b) == 0:
        raise ValueError(f"point sets must be non-empty (N, D) arrays of equal D; got {a.shape} and {b.shape}")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("point sets contain NaN or Inf")
    d = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1))
    return float(0.5 * (d.min(axis=1).mean() + d.min(axis=0).mean()))


def path_error(
    estimated_cp,
    true_cp,
    *,
    n_times: int = 64,
    lightfield=None,
    infinity_disparity: float = 0.0,
) -> PathError:
    """Compare an estimated camera path with the true one, blind to gauge and time order.

    Both paths are sampled at ``n_times`` instants and moved to the zero-mean
    gauge (their mean position over the exposure subtracted), as docs/model.md
    prescribes. Then:

    - the **Chamfer distance** compares the two sets of positions;
    - the **RMSE** compares positions at equal instants, for the better of
      the two time directions, also relative to the true path's extent;
    - with ``lightfield`` given, the **blur mismatch** (docs/model.md, "Judging an estimate")
      ``||B(l, p_est) - B(l, p_true)|| / ||B(l, p_true) - l||`` compares the
      blurs the two centred paths produce on that (sharp) light field.

    The estimate may have a different number of control points, and either
    path may have a rotation (6 columns): the Chamfer distance and the RMSE
    compare the translations ``(p_x, p_y, p_z)``; the blur mismatch compares
    the whole motion.

    Parameters
    ----------
    estimated_cp, true_cp : array_like, shape (n, 3) or (n, 6)
        Bezier control points (docs/model.md).
    n_times : int, default 64
        Instants used to sample both paths and to render the blurs.
    lightfield : ndarray, optional, shape (V, U, Y, X[, C])
        A sharp light field for the blur mismatch, ideally the ground truth.
    infinity_disparity : float, default 0.0
        ``d_inf`` of the blur model used for the blur mismatch.

    Returns
    -------
    PathError
    """
    n_times = validate_n_times(n_times)
    infinity_disparity = check_number(infinity_disparity, "infinity_disparity")
    est = bezier_positions(validate_control_points(estimated_cp), n_times)[:, :3]
    true = bezier_positions(validate_control_points(true_cp), n_times)[:, :3]
    est = est - est.mean(axis=0)
    true = true - true.mean(axis=0)

    d = np.sqrt(((true[:, None, :] - true[None, :, :]) ** 2).sum(-1))
    extent = float(d.max())
    chamfer = chamfer_distance(est, true)
    rmse_fwd = float(np.sqrt(np.mean(((est - true) ** 2).sum(-1))))
    rmse_rev = float(np.sqrt(np.mean(((est[::-1] - true) ** 2).sum(-1))))
    rmse = min(rmse_fwd, rmse_rev)
    rel = (lambda v: v / extent) if extent > 0 else (lambda v: float("nan"))

    mismatch = None
    if lightfield is not None:
        mismatch = _blur_mismatch(
            lightfield, estimated_cp, true_cp, n_times=n_times, infinity_disparity=infinity_disparity
        )
    return PathError(
        chamfer=chamfer,
        chamfer_relative=rel(chamfer),
        rmse=rmse,
        rmse_relative=rel(rmse),
        extent=extent,
        reversed=rmse_rev < rmse_fwd,
        blur_mismatch=mismatch,
    )


def _blur_mismatch(lightfield, estimated_cp, true_cp, *, n_times, infinity_disparity) -> float:
    from .blur import simulate_blur, validate_lightfield
    from .path import center_path

    lf = validate_lightfield(lightfield).astype(np.float32, copy=False)
    p_est = center_path(estimated_cp, n_times)
    p_true = center_path(true_cp, n_times)
    kw = dict(n_times=n_times, infinity_disparity=infinity_disparity, device="cpu")
    b_true = simulate_blur(lf, p_true, **kw).astype(np.float64)
    b_est = simulate_blur(lf, p_est, **kw).astype(np.float64)
    den = float(np.linalg.norm(b_true - lf))
    if den <= 1e-6 * float(np.linalg.norm(lf)):  # the true path does not blur lf (float32 noise)
        return float("nan")
    return float(np.linalg.norm(b_est - b_true) / den)
