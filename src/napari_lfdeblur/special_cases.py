"""The paper's analytic special cases of light-field motion blur.

- :func:`inplane_matrix` / :func:`solve_inplane`: with an in-plane path
  (``p_z = 0``) and ``d_inf = 0`` every pixel ``(y, x)`` sees the same linear
  map ``M = mean_k B_k kron A_k`` on its ``V U`` angular samples, replicate
  boundary included, so known-path deblurring is one small matrix solve
  applied to all pixels at once (the paper's Sec. 3.2.1, a 4D convolution
  along ``(u, v)``).
- :func:`inplane_psf`: the 2D PSF such a path gives a view of a plane.
- :func:`refocus`: shift-and-sum (a sheared integral projection, i.e. a
  slice of the 4D spectrum) with sub-pixel shifts.
- :func:`recover_plane_texture`: blind recovery of a fronto-parallel
  textured plane under out-of-plane motion (the paper's Sec. 3.2.2).

References
----------
.. [1] P. P. Srinivasan, R. Ng and R. Ramamoorthi, "Light Field Blind Motion
       Deblurring", CVPR 2017, arXiv:1704.05416.
.. [2] R. Ng, "Fourier Slice Photography", ACM SIGGRAPH 2005.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from ._disparity import downsample, shear
from ._lightfield import check_int, check_number, validate_lightfield
from .blur import interpolation_matrices
from .path import bezier_positions, has_rotation, validate_control_points, validate_n_times

__all__ = [
    "inplane_matrix",
    "solve_inplane",
    "inplane_psf",
    "refocus",
    "PlaneTextureResult",
    "recover_plane_texture",
]


# -------------------------------------------------------------- in-plane


def _angular_difference_matrix(V: int, U: int) -> np.ndarray:
    """Forward differences along v and u on the V x U grid (Neumann), stacked: shape (2VU, VU)."""
    dv = np.zeros((V, V))
    du = np.zeros((U, U))
    for i in range(V - 1):
        dv[i, i], dv[i, i + 1] = -1.0, 1.0
    for i in range(U - 1):
        du[i, i], du[i, i + 1] = -1.0, 1.0
    return np.vstack([np.kron(dv, np.eye(U)), np.kron(np.eye(V), du)])


def inplane_matrix(control_points, V: int, U: int, *, n_times: int = 32) -> np.ndarray:
    """The angular blur matrix of an in-plane path: ``M = mean_k B_k kron A_k``.

    With ``p_z = 0`` and ``d_inf = 0`` the blurred angular samples of every
    pixel are ``f[:, :, y, x].ravel() = M @ l[:, :, y, x].ravel()`` (row-major
    ``(v, u)`` order), replicate boundary included.

    Returns
    -------
    ndarray, float64, shape (V*U, V*U)
    """
    cp = validate_control_points(control_points)
    if np.any(cp[:, 2] != 0) or has_rotation(cp):
        raise ValueError("inplane_matrix needs an in-plane path (p_z = 0 and no rotation at every control point)")
    pos = torch.as_tensor(bezier_positions(cp, validate_n_times(n_times)), dtype=torch.float64)
    A, B, _, _ = interpolation_matrices(pos, (V, U, 1, 1))
    A, B = A[:, 0].numpy(), B[:, 0].numpy()
    return np.mean([np.kron(B[k], A[k]) for k in range(len(A))], axis=0)


def solve_inplane(f: torch.Tensor, M: np.ndarray, weight: float) -> torch.Tensor:
    """Solve ``(M^T M + w D^T D) l = M^T f`` for every pixel at once.

    Parameters
    ----------
    f : torch.Tensor, shape (V, U, Y, X, C)
        The blurred light field.
    M : ndarray, shape (V*U, V*U)
        The angular blur matrix (:func:`inplane_matrix`).
    weight : float
        Tikhonov weight ``w`` on the angular finite differences ``D``
        (0: the pseudo-inverse of ``M``).

    Returns
    -------
    torch.Tensor, the shape, dtype and device of ``f``
    """
    V, U = f.shape[:2]
    if weight == 0.0:
        K = np.linalg.pinv(M)
    else:
        D = _angular_difference_matrix(V, U)
        K = np.linalg.solve(M.T @ M + weight * (D.T @ D), M.T)
    Kt = torch.as_tensor(K, dtype=f.dtype, device=f.device)
    flat = f.reshape(V * U, -1)
    return (Kt @ flat).reshape(f.shape)



# ---------------------------------------------------------------- refocus


def refocus(lf, disparity: float) -> np.ndarray:
    """Shift-and-sum refocusing with sub-pixel shifts.

    Averages ``lf[v, u](y + d v_c, x + d u_c)`` over all views, with
    ``u_c = u - (U - 1) / 2`` and ``v_c = v - (V - 1) / 2``. By the
    disparity sign convention (a point at ``x`` in view ``u`` is at ``x + d`` in view
    ``u + 1``) this brings the scene at disparity ``d`` into focus, aligned
    with the centre view. Samples are bilinear with a replicated boundary.

    Parameters
    ----------
    lf : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
    disparity : float
        px/view.

    Returns
    -------
    ndarray, float32, shape (Y, X) or (Y, X, C)
    """
    arr = validate_lightfield(lf).astype(np.float64, copy=False)
    d = check_number(disparity, "disparity")
    t = torch.as_tensor(arr if arr.ndim == 5 else arr[..., None])
    out = (shear(t, d) if d else t).mean(dim=(0, 1)).numpy()
    return (out if arr.ndim == 5 else out[..., 0]).astype(np.float32)


# ------------------------------------------------- textured plane (Sec. 3.2.2)


@dataclass
class PlaneTextureResult:
    """Result of :func:`recover_plane_texture`.

    Attributes
    ----------
    texture : ndarray, float32, shape (Y, X) or (Y, X, C)
        The recovered texture, seen from the path's mean position (centre view).
    refocused : ndarray, float32, shape (Y, X) or (Y, X, C)
        The refocused slice at the plane's disparity, before the correction.
    disparity : float
        Disparity of the plane at the mean camera position, px/view.
    zeta : float
        The correction's ``ζ`` (px/rad): ``texture = F^-1[(1 + ζ |Ω|) F[refocused]]``.
    dwell_p : ndarray, float64, shape (S,)
        Out-of-plane positions ``p_z`` (view units per unit of ``x~``) of the profile's samples.
    dwell : ndarray, float64, shape (S,)
        The sharpness profile at ``dwell_p`` (sums to 1): each slice's
        high-pass energy above the least of them. It peaks where the camera
        dwelt; it is wider than the dwell itself, since the refocusing
        softens every slice too, so it is a picture of the motion, not the
        fraction of the exposure spent at each position.
    kernel : ndarray, float32, shape (K, K)
        The 2D blur kernel of the refocused slice that ``dwell`` would give
        were it the dwell profile (sums to 1, centred); as wide as the
        profile, so wider than the true kernel.
    valid_radius : float
        Radius in pixels around the image centre inside which the plane's
        angular samples stay within the aperture, ``d (U - 1) / 2``: the
        recovery is trustworthy there; farther out it degrades.
    """

    texture: np.ndarray
    refocused: np.ndarray
    disparity: float
    zeta: float
    dwell_p: np.ndarray
    dwell: np.ndarray
    kernel: np.ndarray
    valid_radius: float


def _gray(img: np.ndarray) -> np.ndarray:
    return img.mean(axis=-1) if img.ndim == 3 else img


def _highpass_energy(img: np.ndarray, mask: np.ndarray) -> float:
    from scipy import ndimage

    g = _gray(img).astype(np.float64)
    hp = g - ndimage.gaussian_filter(g, 1.5, mode="nearest")
    return float(np.sqrt(np.mean(hp[mask] ** 2)))


def _kernel_image(p, w, d, R, V, U) -> np.ndarray:
    """The slice's PSF: each instant is a V x U grid of dots spaced ``d^2 p / R`` px (bilinear splats)."""
    uc = np.arange(U) - (U - 1) / 2.0
    vc = np.arange(V) - (V - 1) / 2.0
    reach = max(abs(d * d * np.max(np.abs(p)) / R) * max(U - 1, V - 1) / 2.0, 0.0)
    half = int(math.ceil(reach)) + 1
    K = np.zeros((2 * half + 1, 2 * half + 1))
    for pj, wj in zip(p, w):
        if wj <= 0:
            continue
        s = d * d * pj / R
        for vv in vc:
            for uu in uc:
                y, x = half + s * vv, half + s * uu
                y0, x0 = int(math.floor(y)), int(math.floor(x))
                fy, fx = y - y0, x - x0
                for dy, wy_ in ((0, 1 - fy), (1, fy)):
                    for dx, wx_ in ((0, 1 - fx), (1, fx)):
                        if 0 <= y0 + dy < K.shape[0] and 0 <= x0 + dx < K.shape[1]:
                            K[y0 + dy, x0 + dx] += wj * wy_ * wx_ / (U * V)
    return (K / K.sum()).astype(np.float32)


def _windowed_magnitude(img, radius):
    g = _gray(img).astype(np.float64)
    Y, X = g.shape
    yy, xx = np.mgrid[0:Y, 0:X]
    rr = np.hypot(yy - (Y - 1) / 2.0, xx - (X - 1) / 2.0)
    win = np.where(rr < radius, 0.5 + 0.5 * np.cos(np.pi * rr / radius), 0.0)
    g = (g - (g * win).sum() / win.sum()) * win
    return np.abs(np.fft.fft2(g))


def _fit_zeta(slice_img, centre_view, radius, zetas=np.linspace(0.0, 6.0, 241)) -> float:
    """ζ such that ``(1 + ζ |Ω|) |S(Ω)|`` best matches the centre view's ``|C(Ω)|`` near the centre.

    Both magnitudes are taken in a raised-cosine window of ``radius`` about
    the image centre, where out-of-plane blur in the centre view vanishes
    (it grows linearly with the distance from the centre) and where the
    slice holds the plane's samples. Log-magnitudes of radial bins of
    ``|Ω| = max(|Ω_x|, |Ω_y|)`` in [0.25, 2.0] rad/px are compared.
    """
    S = _windowed_magnitude(slice_img, radius)
    C = _windowed_magnitude(centre_view, radius)
    Y, X = S.shape
    wy = np.fft.fftfreq(Y)[:, None] * 2 * np.pi
    wx = np.fft.fftfreq(X)[None, :] * 2 * np.pi
    om = np.maximum(np.abs(wy), np.abs(wx))
    edges = np.linspace(0.25, 2.0, 15)
    ratio, centres = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (om >= lo) & (om < hi)
        s_m, c_m = S[sel].mean(), C[sel].mean()
        if s_m > 0 and c_m > 0:
            ratio.append(np.log(c_m / s_m))
            centres.append(0.5 * (lo + hi))
    if not centres:
        return 0.0
    ratio, centres = np.array(ratio), np.array(centres)
    err = [np.sum((np.log1p(z * centres) - ratio) ** 2) for z in zetas]
    return float(zetas[int(np.argmin(err))])


def recover_plane_texture(
    blurred,
    *,
    disparity: float | None = None,
    p_range: float = 3.0,
    n_slices: int = 31,
    zeta: float | None = None,
) -> PlaneTextureResult:
    """Blind recovery of a fronto-parallel textured plane blurred by out-of-plane motion.

    The paper's Sec. 3.2.2, derived for this project's model (docs/model.md). A
    plane at disparity ``d`` seen from the out-of-plane position ``p`` (with
    ``p_x = p_y = 0``, ``d_inf = 0``) is ``l(u, x) = τ(s x - d u_c)`` with
    ``s = 1 + d p / R``: again a plane, at disparity ``d / s``, with its
    texture magnified by ``s`` about the image centre. The blurred light field
    is the dwell-time weighted mean of these planes (in Fourier terms, a fan
    of sheared copies of the plane's spectral slice).

    Refocusing at ``d`` (the Fourier slice at the plane's depth) keeps the
    instants near ``p = 0`` sharp and spreads every other instant ``p`` into
    a ``V x U`` grid of copies spaced ``d^2 p / R`` px: a blur whose transfer
    function falls off as ``1 / (1 + ζ |Ω|)`` (``|Ω|`` = max(|Ω_x|, |Ω_y|),
    rad/px). Multiplying the slice's spectrum by ``1 + ζ |Ω|`` restores the
    texture. Without the path:

    1. the disparity is the one at which the views, shifted into the centre
       view's place, agree best near the image centre, where out-of-plane
       motion blurs least (for a motion symmetric about its mean position,
       close to the plane's disparity seen from there: the zero-mean gauge
       of blind estimates; the spread of magnifications pulls it towards 0
       by a few percent on long motions);
    2. ζ is fitted where the centre view holds the sharp texture: near the
       image centre out-of-plane motion does not blur it (its blur grows
       with the distance from the centre), so ζ is the value for which
       ``(1 + ζ |Ω|)`` times the slice's spectrum best matches the centre
       view's there (log-magnitudes of radial frequency bands).

    A sharpness profile over ``p_z`` is reported as well: the high-pass
    energy of the slices refocused for a grid of positions ``p_j``, at the
    disparities ``d / (1 + d p_j / R)``. It peaks where the camera dwelt,
    but each slice is also softened by the refocusing itself, so the profile
    is wider than the motion's dwell (a still camera gives a broad peak, not
    a spike).

    The plane's angular samples leave the aperture at ``|x - c| > d (U-1)/2``
    px from the image centre, so the recovery is best within
    ``valid_radius`` of the centre. Refocusing shifts the views bilinearly,
    which smooths them where a shift is a fraction of a pixel: at a
    non-integer disparity the slice is softer than the plane, and at small
    ones the recovery can be worse than the blurred centre view.

    Parameters
    ----------
    blurred : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        A light field of a textured fronto-parallel plane, blurred by an
        out-of-plane motion (``d_inf = 0``).
    disparity : float, optional
        The plane's disparity in px/view (non-zero). By default the
        disparity at which the views agree best (step 1), searched over all
        those at which they still overlap about the centre
        (``|d| (max(U, V) - 1) / 2 <= 0.35 min(Y, X)``).
    p_range : float, default 3.0
        The sharpness profile covers ``p_z`` in ``[-p_range, p_range]``.
    n_slices : int, default 31
        Number of slices of the profile.
    zeta : float, optional
        Use this ζ instead of the automatic one.

    Returns
    -------
    PlaneTextureResult
    """
    arr = validate_lightfield(blurred, "blurred light field").astype(np.float32, copy=False)
    V, U, Y, X = arr.shape[:4]
    R = max(X, Y) / 2.0
    p_range = check_number(p_range, "p_range")
    if p_range <= 0:
        raise ValueError(f"p_range must be > 0; got {p_range}")
    n_slices = check_int(n_slices, "n_slices", 3)
    if max(U, V) < 2:
        raise ValueError("recover_plane_texture needs at least 2 views along u or v")
    yy, xx = np.mgrid[0:Y, 0:X]
    rr = np.hypot(yy - (Y - 1) / 2.0, xx - (X - 1) / 2.0)

    if disparity is None:
        d = _agreeing_disparity(arr)
    else:
        d = check_number(disparity, "disparity")
        if d == 0:
            raise ValueError("the plane's disparity must be non-zero: a plane at infinity shows no out-of-plane blur")
    p, w, radius = _dwell_profile(arr, d, rr, p_range, n_slices)
    refocused = refocus(arr, d)
    if zeta is None:
        zeta = _fit_zeta(refocused, arr[(V - 1) // 2, (U - 1) // 2], max(radius, 6.0))
    else:
        zeta = check_number(zeta, "zeta")
        if zeta < 0:
            raise ValueError(f"zeta must be >= 0; got {zeta}")
    return PlaneTextureResult(
        texture=_sharpen_slice(refocused, zeta, abs(d) * (max(U, V) - 1) / 2.0),
        refocused=refocused,
        disparity=float(d),
        zeta=zeta,
        dwell_p=p,
        dwell=w,
        kernel=_kernel_image(p, w, d, R, V, U),
        valid_radius=float(radius),
    )


#: the disparity search: its step (px/view) on views of about SWEEP_PIXELS px, and the fraction of
#: min(Y, X) about the image centre within which the views are compared
SWEEP_STEP, SWEEP_PIXELS, AGREEMENT_RADIUS = 0.1, 64, 0.15


def _agreeing_disparity(arr: np.ndarray) -> float:
    """The disparity (px/view) at which the views, shifted into the centre view's place, agree best.

    Agreement is the variance across the aligned views (grayscale), within
    ``AGREEMENT_RADIUS min(Y, X)`` px of the image centre, where
    out-of-plane motion blurs least. The sweep covers every non-zero
    disparity whose shifts keep the compared pixels inside the views,
    ``|d| (max(U, V) - 1) / 2 <= 0.35 min(Y, X)`` (at least ``|d| <= 4``),
    at :data:`SWEEP_STEP` on views area-averaged to about
    :data:`SWEEP_PIXELS` px (a disparity scales with the views), then
    refines twice on the full views, each time 10 times finer.
    """
    V, U, Y, X = arr.shape[:4]
    g = torch.as_tensor((arr.mean(axis=-1) if arr.ndim == 5 else arr).astype(np.float64))[..., None]
    k = max(1, min(Y, X) // SWEEP_PIXELS)
    small = downsample(g, k)
    d_max = max(4.0, 0.35 * min(Y, X) / max((max(U, V) - 1) / 2.0, 0.5)) / k
    cand = np.arange(-d_max, d_max + SWEEP_STEP / 2, SWEEP_STEP)
    best = k * _best_agreement(small, cand[np.abs(cand) > SWEEP_STEP / 2])
    step = k * SWEEP_STEP
    for _ in range(2):
        best = _best_agreement(g, best + np.linspace(-1.5 * step, 1.5 * step, 31))
        step /= 10.0
    return best


def _best_agreement(g: torch.Tensor, cand: np.ndarray) -> float:
    """The candidate disparity whose views (V, U, Y, X, 1), aligned by :func:`shear`, vary least about the
    image centre."""
    Y, X = g.shape[2:4]
    yy, xx = np.mgrid[0:Y, 0:X]
    mask = torch.as_tensor(np.hypot(yy - (Y - 1) / 2.0, xx - (X - 1) / 2.0) <= max(AGREEMENT_RADIUS * min(X, Y), 2.0))
    scores = [float(shear(g, d).var(dim=(0, 1), unbiased=False)[..., 0][mask].mean()) if d else np.inf for d in cand]
    return float(cand[int(np.argmin(scores))])


def _dwell_profile(arr: np.ndarray, d: float, rr: np.ndarray, p_range: float, n_slices: int):
    """Dwell-time profile over ``p_z``: positions, normalised weights and the valid radius (px)."""
    V, U, Y, X = arr.shape[:4]
    R = max(X, Y) / 2.0
    radius = abs(d) * (max(U, V) - 1) / 2.0
    mask = rr <= max(radius, 3.0)
    p = np.linspace(-p_range, p_range, n_slices)
    p = p[np.abs(d * p / R) < 0.9]
    m = np.array([_highpass_energy(refocus(arr, d / (1.0 + d * pj / R)), mask) for pj in p])
    w = np.clip(m - m.min(), 0.0, None)
    if w.sum() <= 0:
        w = np.ones_like(m)
    return p, w / w.sum(), radius


def _sharpen_slice(refocused: np.ndarray, zeta: float, reach: float) -> np.ndarray:
    """Multiply the slice's spectrum by ``1 + zeta |Omega|`` (reflect-padded by ``reach`` px against wrap-around)."""
    Y, X = refocused.shape[:2]
    pad = max(4, int(math.ceil(reach)))
    pw = [(pad, pad), (pad, pad)] + ([(0, 0)] if refocused.ndim == 3 else [])
    padded = np.pad(refocused.astype(np.float64), pw, mode="reflect")
    Py, Px = padded.shape[:2]
    wy = np.fft.fftfreq(Py)[:, None] * 2 * np.pi
    wx = np.fft.fftfreq(Px)[None, :] * 2 * np.pi
    gain = 1.0 + zeta * np.maximum(np.abs(wy), np.abs(wx))
    if padded.ndim == 3:
        gain = gain[..., None]
    spec = np.fft.fft2(padded, axes=(0, 1)) * gain
    return np.real(np.fft.ifft2(spec, axes=(0, 1)))[pad : pad + Y, pad : pad + X].astype(np.float32)


def inplane_psf(control_points, disparity: float, *, n_times: int = 32, size: int | None = None) -> np.ndarray:
    """The 2D PSF that an in-plane path gives a view, for a scene at one disparity.

    What a conventional camera's 2D deconvolution would use: with
    ``p_z = 0`` and ``d_inf = 0``, instant ``k`` samples the views at angular
    offset ``(p_y, p_x)``, bilinearly between the two nearest views, and a
    plane at disparity ``d`` appears in view offset ``j`` shifted by ``d j``
    px. So the PSF has weight at ``d * floor(p)`` and ``d * (floor(p) + 1)``
    (bilinear splats for fractional positions), averaged over the instants.
    Views are assumed inside the aperture (no boundary clamping).

    ``size`` (None: the smallest odd size that holds every tap) must hold
    every tap too.

    Returns
    -------
    ndarray, float64, shape (size, size), centred (at ``size // 2``), sums to 1

    Raises
    ------
    ValueError
        For a path that is not in-plane, or a ``size`` that is not a whole
        number or cuts taps off.
    """
    cp = validate_control_points(control_points)
    if np.any(cp[:, 2] != 0) or has_rotation(cp):
        raise ValueError("inplane_psf needs an in-plane path (p_z = 0, no rotation)")
    d = check_number(disparity, "disparity")
    pos = bezier_positions(cp, validate_n_times(n_times))
    taps = []
    for px, py, *_ in pos:
        fx, fy = math.floor(px), math.floor(py)
        ax, ay = px - fx, py - fy
        for jy, wy in ((fy, 1 - ay), (fy + 1, ay)):
            for jx, wx in ((fx, 1 - ax), (fx + 1, ax)):
                if wy * wx > 0:
                    taps.append((d * jy, d * jx, wy * wx / len(pos)))
    reach = max(max(abs(t[0]), abs(t[1])) for t in taps)
    if size is None:
        size = 2 * int(math.ceil(reach)) + 3
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 1:
        raise ValueError(f"size must be a whole number >= 1 or None; got {size!r}")
    half = size // 2
    K = np.zeros((size, size))
    for sy, sx, w in taps:
        y, x = half + sy, half + sx
        y0, x0 = math.floor(y), math.floor(x)
        ay, ax = y - y0, x - x0
        for dy, wy in ((0, 1 - ay), (1, ay)):
            for dx, wx in ((0, 1 - ax), (1, ax)):
                if 0 <= y0 + dy < size and 0 <= x0 + dx < size:
                    K[y0 + dy, x0 + dx] += w * wy * wx
    if not K.sum() > 1 - 1e-9:
        raise ValueError(f"size {size} cuts off the PSF, whose taps reach {reach:.3g} px from the centre: give "
                         f"size >= {2 * int(math.ceil(reach)) + 3}, or None")
    return K
