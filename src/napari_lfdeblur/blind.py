"""Blind motion deblurring of light fields: the camera path and the sharp light field.

:func:`blind_deblur` (and its generator form :func:`iter_blind_deblur`) takes a
motion-blurred light field and returns both the sharp light field and the 3D
camera path (MODEL.md units, zero-mean gauge), with no depth estimation.

Two algorithms, chosen by :attr:`BlindParams.method`:

``'alternating'`` (the ``default`` preset)
    The plain joint MAP of the paper is trapped at "no blur" (FINDINGS.md,
    section 1): the blurred light field itself has a lower sparse-gradient
    prior than the sharp one. This method avoids the trap by design, in the
    manner of Xu et al. (2013) and Pan et al. (2014):

    1. the path is estimated on the grayscale light field, coarse to fine
       over a spatial pyramid (views untouched; ``p_x, p_y`` are in views and
       ``p_z`` in views per normalised ``x~``, so the path means the same at
       every level, while ``d_inf`` in px/view scales with the level);
    2. at each level the estimate alternates between
       (a) a strongly sparsified, salient-edge latent light field: the L0
       gradient-regularised solve ``min ||K_p l - f||^2 + lambda ||grad_yx l||_0``
       by half-quadratic splitting (conjugate gradients for the quadratic
       step), whose piecewise-constant result has step edges whatever the
       current path, and
       (b) the path fitted to that latent in the gradient domain,
       ``min_p ||grad_yx(K_p l_s) - grad_yx f||^2``, by Adam, on pixels drawn
       with a preference for strong gradients and large disparity (read off
       the blurred input), where the latent's over-sharp edges mislead the
       fit least; from the ``edge_sigma_from``-th alternation the latent is
       modelled as sharper than the scene by a spatial Gaussian
       (``K_p G_sigma``), so that the path need not absorb the edge profile;
    3. the fit has many local minima, so every alternation fits a wide batch
       of paths at once (cheap: the fit is a small quadratic form in the
       blur kernel) and keeps the best: at first short lines in spread
       directions and hundreds of random paths (never the zero path, where
       the gradient vanishes in the zero-mean gauge), later the current path,
       its mirror, perturbed copies and fresh random paths; with a pyramid,
       the degree is raised (exactly, by Bezier degree elevation) from a line
       to the requested number of control points on the way up;
    4. the zero-mean gauge holds throughout (the control points are
       re-centred inside every step) and the path is kept in a box of the
       aperture (FINDINGS.md, section 3);
    5. with ``estimate_z``, a last stage frees ``p_z``, starting from the
       in-plane path;
    6. the path found, each colour channel is restored by the 4D-TV
       non-blind :func:`~napari_lfdeblur.deconvolution.deconvolve`.

``'joint'`` (the ``paper`` preset)
    The paper's blind stage as published: Adam on the control points and
    the grayscale light field jointly, on ``mean((K_p l - f)^2) + w R_eps(l)``
    with the 4D sparse-gradient prior ``R_eps = mean(min(|grad l|^2 / eps^2, 1))``
    and ``w``, ``eps`` annealed; then the same TV non-blind stage.

Both return the path time-canonicalised (:func:`canonical_time_direction`)
since the blur does not depend on the order of the positions.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import torch

from ._params import JsonParams
from .progress import Progress, run_to_completion
from .blur import BlurOperator, _lerp_taps, validate_lightfield
from .devices import select_device
from .path import bernstein_matrix, bezier_positions, center_path

__all__ = [
    "BlindParams",
    "BlindResult",
    "PRESETS",
    "blind_deblur",
    "iter_blind_deblur",
    "sparse_gradient_prior",
    "estimate_blind_memory",
    "canonical_time_direction",
    "elevate_degree",
    "plan_device",
]

METHODS = ("alternating", "joint")


# ------------------------------------------------------------ parameters


@dataclass(frozen=True)
class BlindParams(JsonParams):
    """Parameters of :func:`blind_deblur`. Frozen; save with :meth:`to_json`.

    Attributes
    ----------
    method : {'alternating', 'joint'}
        ``'alternating'``: salient-edge latent / path alternation, coarse to
        fine (ours). ``'joint'``: the paper's joint Adam.
    n_control_points : int
        Control points of the estimated Bezier path (>= 2).
    n_times : int
        Exposure instants ``T`` of the model during path estimation (>= 2).
    max_extent : float
        Control points are kept within ``+-max_extent`` views of the centre
        in ``x`` and ``y`` (and ``+-max_extent`` in ``p_z``); 0 means half
        the angular aperture, ``(min(V, U) - 1) / 2``.
    n_levels : int
        Spatial pyramid levels of the alternating method (1 = full
        resolution only). Levels smaller than ``min_size`` px are skipped.
    min_size : int
        Smallest spatial size of a pyramid level.
    max_size : int
        Largest spatial size (smaller side) used for the path estimation;
        finer levels are skipped (0: up to full resolution). The path means
        the same at every resolution, so this trades little accuracy for time.
    n_outer : int
        Maximum latent/path alternations per level.
    n_restarts : int
        Initial paths tried on the coarsest level (linear paths of length
        ``init_length`` views in evenly spread directions), the best kept.
    init_length : float
        Length of the initial linear paths, in views.
    l0_weight : float
        ``lambda`` of the L0 gradient latent at the coarsest level.
    l0_decay : float
        ``lambda`` is multiplied by this after every alternation (floor
        ``l0_weight * l0_floor``).
    l0_floor : float
    latent_angular_weight : float
        Weight of the angular (``v, u``) differences in the L0 latent
        (0: spatial differences only).
    hqs_beta_max : float
        Half-quadratic splitting runs ``beta = 2 lambda * kappa^k`` up to this.
    hqs_kappa : float
    n_cg : int
        Conjugate-gradient iterations per splitting step.
    path_lr : float
        Adam step of the path (views).
    path_steps : int
        Adam steps on the path per alternation.
    n_pixels : int
        Pixels (chosen at random, favouring strong gradients, with all their
        views) on which the path is fitted to the latent.
    n_random : int
        Random paths (control points uniform within ``+-init_length`` views)
        tried at the start besides the lines, all fitted at once as a batch.
        The fit has many local minima; it is cheap (a few small products per
        step), so a wide batch is what finds the global one.
    n_random_later : int
        Fresh random paths added to the batch at every later alternation.
    fit_robust : float
        From the second alternation on, each fitted pixel is weighted by
        ``1 / (1 + r / (fit_robust * median(r)))``, ``r`` its residual under
        the current path: pixels whose texture the salient-edge latent lacks
        count less (0: no weighting).
    n_perturb : int
        Randomly perturbed copies of the current path tried at every later
        alternation (kept only when they fit better).
    perturb : float
        Standard deviation of those perturbations, in views.
    edge_sigma : float
        The salient-edge latent is taken to be sharper than the scene by a
        spatial Gaussian of this many pixels, applied inside the model, so
        that the path need not absorb the edge profile (0: off). Without it
        the path comes out inflated (docs/blind.md).
    edge_anisotropy : float
        How much softer the scene's edges are along ``x`` than along ``y``,
        in px: the Gaussian along ``y`` that would make them equally soft
        (negative: softer along ``y``). The edge model keeps its mean square
        width ``edge_sigma**2`` and splits it between the axes,
        ``sigma_x**2 = edge_sigma**2 + a |a| / 2`` and ``sigma_y**2 =
        edge_sigma**2 - a |a| / 2`` (at least 0). A property of the camera,
        not of the motion: views decoded from a first-generation Lytro
        capture are softer along ``x`` by about 0.6 px
        (``benchmarks/scene_anisotropy.py``), and with the isotropic default
        the path estimate absorbs the difference (docs/blind.md, "The Lytro
        views are softer along x"). 0: isotropic.
    edge_sigma_from : int
        The edge model is used from this alternation of the first level on
        (1: from the start). Used from the start it lets the Gaussian
        explain the whole of a small blur, and the path stays too short; the
        first alternations therefore find the (inflated) path without it.
    disparity_weight : float
        The pixels of the path fit are drawn with a probability also
        proportional to ``(|d| / max|d| + 0.02) ** disparity_weight``, ``d``
        the disparity estimated from the blurred light field itself (which
        stays consistent across views). Where ``|d|`` is small the blur
        moves the scene by little more than its edge profile, and a
        salient-edge latent misleads the fit most (0: uniform).
    tiles : int
        With ``p_z`` estimated, the fit takes the blur kernel constant over
        ``tiles x tiles`` tiles of the image.
    z_box : float
        ``|p_z|`` is kept below ``z_box`` times the ``x, y`` box.
    try_mirror : bool
        Also try the mirrored path ``-p`` at every alternation (a local
        minimum of the fit for curved paths), keeping the better.
    estimate_z : bool
        Estimate ``p_z`` (out-of-plane motion) in a last stage; False keeps
        the path in-plane.
    z_outer : int
        With ``estimate_z``, alternations of a last stage, on the finest
        level, in which ``p_z`` is free; it starts from the in-plane estimate
        (which dominates the blur) and tries it with random out-of-plane
        motions.
    path_tol : float
        A level stops when the path moves less than this (views, largest
        change of a sampled position) in two successive alternations.
    n_iter : int
        Iterations of the ``'joint'`` method.
    lf_lr : float
        Adam step of the light field (``'joint'``).
    prior_weight, prior_decay, prior_floor : float
        Weight of the sparse-gradient prior (``'joint'``), its decay per
        iteration and its floor as a fraction of the start.
    eps, eps_decay, eps_min : float
        ``eps`` of the sparse-gradient prior (``'joint'``), its decay per
        iteration and its floor.
    tv_weight : float
        Weight of the 4D TV of the final non-blind solve
        (``1/2 ||K l - f||^2 + tv_weight TV4(l)``).
    tv_iter : int
        Iterations of the final non-blind solve (0: skip it and return the
        blurred input as the light field).
    final_n_times : int
        Exposure instants of the final non-blind solve.
    preview_every : int
        Send a preview light field every so many progress records (0: never).
    """

    method: str = "alternating"
    n_control_points: int = 4
    n_times: int = 32
    max_extent: float = 0.0
    # alternating
    n_levels: int = 1
    min_size: int = 24
    max_size: int = 0
    n_outer: int = 6
    n_restarts: int = 4
    init_length: float = 1.5
    l0_weight: float = 4e-3
    l0_decay: float = 0.5
    l0_floor: float = 0.05
    latent_angular_weight: float = 0.5
    hqs_beta_max: float = 2.0
    hqs_kappa: float = 2.0
    n_cg: int = 3
    path_lr: float = 0.05
    path_steps: int = 300
    path_tol: float = 0.01
    n_pixels: int = 8000
    n_random: int = 500
    n_random_later: int = 200
    fit_robust: float = 0.3
    edge_sigma: float = 0.5
    edge_anisotropy: float = 0.0
    edge_sigma_from: int = 4
    disparity_weight: float = 4.0
    n_perturb: int = 4
    perturb: float = 0.3
    tiles: int = 4
    z_box: float = 0.5
    try_mirror: bool = True
    estimate_z: bool = True
    z_outer: int = 3
    # joint (paper)
    n_iter: int = 1000
    lf_lr: float = 0.04
    prior_weight: float = 8e-3
    prior_decay: float = 0.997
    prior_floor: float = 0.1
    eps: float = 0.12
    eps_decay: float = 0.997
    eps_min: float = 0.04
    # final non-blind stage
    tv_weight: float = 0.002
    tv_iter: int = 100
    final_n_times: int = 32
    preview_every: int = 10

    _what = "blind"

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"unknown blind method {self.method!r}: choose one of {', '.join(METHODS)}")
        ints = {
            "n_control_points": 2, "n_times": 2, "n_levels": 1, "min_size": 4, "n_outer": 1,
            "n_restarts": 1, "max_size": 0, "n_pixels": 16, "tiles": 1, "n_random": 0, "n_random_later": 0, "n_perturb": 0, "edge_sigma_from": 1, "z_outer": 0, "n_cg": 1, "path_steps": 1, "n_iter": 0, "tv_iter": 0,
            "final_n_times": 2, "preview_every": 0,
        }
        for name, lo in ints.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ValueError(f"BlindParams.{name} must be an integer >= {lo}; got {v!r}")
            if v < lo:
                raise ValueError(f"BlindParams.{name} must be >= {lo}; got {v}")
            object.__setattr__(self, name, int(v))
        nonneg = ("max_extent", "z_box", "latent_angular_weight", "perturb", "init_length", "fit_robust", "edge_sigma", "disparity_weight", "l0_weight", "l0_floor", "path_tol", "prior_weight",
                  "prior_floor", "tv_weight", "eps_min")
        positive = ("hqs_beta_max", "path_lr", "lf_lr", "eps", "l0_decay", "prior_decay", "eps_decay")
        signed = ("edge_anisotropy",)
        for name in nonneg + positive + signed:
            v = getattr(self, name)
            if isinstance(v, bool):
                raise ValueError(f"BlindParams.{name} must be a number; got {v!r}")
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"BlindParams.{name} must be a number; got {v!r}") from None
            if not math.isfinite(v) or (name not in signed and v < 0) or (name in positive and v == 0):
                kind = "> 0" if name in positive else ">= 0" if name in nonneg else "a number"
                raise ValueError(f"BlindParams.{name} must be finite and {kind}; got {v!r}")
            object.__setattr__(self, name, v)
        object.__setattr__(self, "estimate_z", bool(self.estimate_z))
        object.__setattr__(self, "try_mirror", bool(self.try_mirror))
        if self.hqs_kappa <= 1:
            raise ValueError(f"BlindParams.hqs_kappa must be > 1; got {self.hqs_kappa}")
        for name in ("l0_decay", "prior_decay", "eps_decay"):
            if getattr(self, name) > 1:
                raise ValueError(f"BlindParams.{name} must be in (0, 1]; got {getattr(self, name)}")

    # -- presets and (de)serialisation

    @classmethod
    def preset(cls, name: str) -> "BlindParams":
        """The named preset: ``'default'`` (ours) or ``'paper'`` (the published settings)."""
        try:
            return PRESETS[name]
        except (KeyError, TypeError):
            raise ValueError(f"unknown blind preset {name!r}: choose one of {', '.join(PRESETS)}") from None


#: named parameter sets
PRESETS = {
    "default": BlindParams(),
    "paper": BlindParams(
        method="joint",
        n_control_points=4,
        n_times=7,
        n_iter=1000,
        path_lr=1.0,
        lf_lr=0.04,
        prior_weight=8e-3,
        prior_decay=0.997,
        prior_floor=0.1,
        eps=0.12,
        eps_decay=0.997,
        eps_min=0.04,
        tv_weight=0.004,
        tv_iter=100,
        final_n_times=7,
        preview_every=50,
    ),
}


# ---------------------------------------------------------------- result


@dataclass
class BlindResult:
    """The result of :func:`blind_deblur`.

    Attributes
    ----------
    lightfield : ndarray, float32, the blurred input's shape
        The sharp light field seen from the path's mean position.
    control_points : ndarray, float64, shape (n, 3)
        The camera path (MODEL.md units), zero-mean gauge for ``params.n_times``
        (hence for any number of instants, up to sampling), time-canonicalised.
    loss_history : list of float
        The objective after every progress record of the path estimation.
    params : BlindParams
    timings : dict
        Seconds spent per stage (``'path'``, ``'final'``, ``'total'``).
    info : dict
        Extra details (device used, restart scores, levels, ...).
    """

    lightfield: np.ndarray
    control_points: np.ndarray
    loss_history: list = field(default_factory=list)
    params: BlindParams = field(default_factory=BlindParams)
    timings: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)


# ---------------------------------------------------------------- priors


def _grad_yx(L):
    """Forward differences along y and x (Neumann: zero at the last sample)."""
    gy = torch.zeros_like(L)
    gx = torch.zeros_like(L)
    gy[:, :, :-1] = L[:, :, 1:] - L[:, :, :-1]
    gx[:, :, :, :-1] = L[:, :, :, 1:] - L[:, :, :, :-1]
    return gy, gx


def _grad_yx_diff(L):
    """Differentiable version of :func:`_grad_yx` (no in-place writes)."""
    gy = torch.nn.functional.pad(L[:, :, 1:] - L[:, :, :-1], (0, 0, 0, 0, 0, 1))
    gx = torch.nn.functional.pad(L[:, :, :, 1:] - L[:, :, :, :-1], (0, 0, 0, 1))
    return gy, gx


def _div_yx(gy, gx):
    """Negative adjoint of :func:`_grad_yx`."""
    d = torch.zeros_like(gy)
    d[:, :, :-1] += gy[:, :, :-1]
    d[:, :, 1:] -= gy[:, :, :-1]
    d[:, :, :, :-1] += gx[:, :, :, :-1]
    d[:, :, :, 1:] -= gx[:, :, :, :-1]
    return d


def _grad4_diff(L):
    out = []
    for axis in range(4):
        n = L.shape[axis]
        d = L.narrow(axis, 1, n - 1) - L.narrow(axis, 0, n - 1) if n > 1 else None
        if d is None:
            out.append(torch.zeros_like(L))
            continue
        pad_shape = list(L.shape)
        pad_shape[axis] = 1
        out.append(torch.cat([d, torch.zeros(pad_shape, dtype=L.dtype, device=L.device)], dim=axis))
    return out


def sparse_gradient_prior(L: torch.Tensor, eps: float) -> torch.Tensor:
    """The L0-approximating prior ``sum_a mean(min(|d_a L|^2 / eps^2, 1))`` over the 4 axes.

    Parameters
    ----------
    L : torch.Tensor, shape (V, U, Y, X[, C])
    eps : float
        Gradients larger than ``eps`` cost 1 each; smaller ones quadratically less.

    Returns
    -------
    torch.Tensor, scalar (differentiable)
    """
    if eps <= 0:
        raise ValueError(f"eps must be > 0; got {eps}")
    return sum(torch.clamp(g * g / (eps * eps), max=1.0).mean() for g in _grad4_diff(L))


# ------------------------------------------------------------ path tools


def elevate_degree(control_points: np.ndarray, n_points: int) -> np.ndarray:
    """Raise the degree of a Bezier curve without changing it.

    Parameters
    ----------
    control_points : ndarray, shape (n, 3)
    n_points : int, >= n

    Returns
    -------
    ndarray, float64, shape (n_points, 3), the same curve
    """
    cp = np.asarray(control_points, dtype=np.float64)
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


def canonical_time_direction(control_points: np.ndarray) -> np.ndarray:
    """Pick one of the two time directions of a path (the blur cannot tell them apart).

    The path is reversed when the largest component (in magnitude) of
    ``last - first`` control point is negative, so that the path moves
    towards positive values along its main direction.

    Returns
    -------
    ndarray, float64, shape (n, 3)
    """
    cp = np.asarray(control_points, dtype=np.float64)
    d = cp[-1] - cp[0]
    if d[np.argmax(np.abs(d))] < 0:
        cp = cp[::-1].copy()
    return cp


class _PathParam:
    """Free control points ``q`` mapped to centred, boxed control points."""

    def __init__(self, cp0: np.ndarray, n_times: int, box: float, device, dtype=torch.float32,
                 free_z: bool = True, z_box: float | None = None):
        self.n_times = n_times
        self.z_box = box if z_box is None else z_box
        self.box = box
        mean_row = bernstein_matrix(np.shape(cp0)[-2], n_times).mean(axis=0)  # positions mean = mean_row @ cp
        self.mean_row = torch.as_tensor(mean_row, dtype=dtype, device=device)
        self.q = torch.as_tensor(np.asarray(cp0, dtype=np.float64), dtype=dtype, device=device).clone()
        if not free_z:
            with torch.no_grad():
                self.q[..., 2] = 0.0
        self.q.requires_grad_(True)
        if not free_z:
            mask = torch.tensor([1.0, 1.0, 0.0], dtype=dtype, device=device)
            self.q.register_hook(lambda grad: grad * mask)

    def control_points(self) -> torch.Tensor:
        return self.q - (self.mean_row @ self.q).unsqueeze(-2)

    @torch.no_grad()
    def project(self):
        """Re-centre and clamp into the box (in place)."""
        self.q.sub_((self.mean_row @ self.q).unsqueeze(-2))
        self.q[..., :2].clamp_(-self.box, self.box)
        self.q[..., 2].clamp_(-self.z_box, self.z_box)
        self.q.sub_((self.mean_row @ self.q).unsqueeze(-2))
        # re-centring can push a point out again by a little: shrink such paths about their
        # (zero) mean, which keeps the gauge
        for sl, lim in ((slice(0, 2), self.box), (slice(2, 3), self.z_box)):
            big = self.q[..., sl].abs().amax(dim=(-1, -2), keepdim=True)
            self.q[..., sl].mul_((lim / big.clamp_min(1e-12)).clamp(max=1.0))

    def numpy(self) -> np.ndarray:
        return self.control_points().detach().cpu().double().numpy()


# ---------------------------------------------------------------- memory


def estimate_blind_memory(shape, params: BlindParams | None = None) -> int:
    """A rough upper estimate of the peak memory of :func:`blind_deblur`, in bytes.

    Counts the light-field-sized float32 tensors alive at once in the final
    (colour) TV stage and in the grayscale path stage, plus the blur
    operator's blocks and interpolation tables.

    Parameters
    ----------
    shape : tuple, (V, U, Y, X[, C])
    params : BlindParams, optional

    Returns
    -------
    int
    """
    p = params or BlindParams()
    shape = tuple(int(s) for s in shape)
    V, U, Y, X = shape[:4]
    C = shape[4] if len(shape) == 5 else 1
    n = V * U * Y * X
    final = n * C * 4 * 12  # f, x, x_new, residual, gradient, 4 dual fields, temporaries
    path = n * 4 * 16  # f, latent, CG vectors, gradients and autograd buffers (grayscale)
    tables = 4 * max(p.n_times, p.final_n_times) * (X * U * U + Y * V * V) * 2
    blocks = 4 * (1 << 22) * 3
    return int(max(final, path) + tables + blocks + 64 * 2**20)


#: overlap (px) of neighbouring tiles in the final stage, on top of what ``d_inf`` shifts
TILE_MARGIN = 12
#: smallest tile side (px) worth working on
MIN_TILE = 32


def plan_tiles(shape, params: BlindParams | None, free: int | None):
    """The tile size ``(ty, tx)`` to work in when the whole light field does not fit, else None.

    The largest square-ish tiles (plus :data:`TILE_MARGIN` on each side) whose
    :func:`estimate_blind_memory` fits in ``free`` bytes, after the full-size
    result is set aside. None when ``free`` is unknown or enough.

    Parameters
    ----------
    shape : tuple, (V, U, Y, X[, C])
    params : BlindParams, optional
    free : int or None
        Bytes available.

    Returns
    -------
    tuple of 2 int, or None
    """
    p = params or BlindParams()
    shape = tuple(int(v) for v in shape)
    if free is None or estimate_blind_memory(shape, p) <= free:
        return None
    V, U, Y, X = shape[:4]
    C = shape[4] if len(shape) == 5 else 1
    budget = free - 4 * V * U * Y * X * C  # the result, full size

    def need(side):
        ty, tx = min(Y, side + 2 * TILE_MARGIN), min(X, side + 2 * TILE_MARGIN)
        return estimate_blind_memory((V, U, ty, tx, C), p)

    side = max(Y, X)
    while side > MIN_TILE and need(side) > budget:
        side = max(MIN_TILE, int(side * 0.8))
    return min(Y, side), min(X, side)


def _tiles(Y: int, X: int, tile, margin: int):
    """``(core, padded)`` slices (y, x) covering a Y x X image with tiles of ``tile`` and ``margin``."""
    ty, tx = tile
    for y0 in range(0, Y, ty):
        for x0 in range(0, X, tx):
            y1, x1 = min(Y, y0 + ty), min(X, x0 + tx)
            py0, px0 = max(0, y0 - margin), max(0, x0 - margin)
            py1, px1 = min(Y, y1 + margin), min(X, x1 + margin)
            yield (slice(y0, y1), slice(x0, x1)), (slice(py0, py1), slice(px0, px1))


def _free_memory(device: torch.device) -> int | None:
    from . import devices

    return devices.free_memory(device)


# ------------------------------------------------------------ validation


def _validate_input(blurred, infinity_disparity, n_control_points):
    arr = validate_lightfield(blurred, "blurred light field")
    V, U, Y, X = arr.shape[:4]
    if V < 2 or U < 2:
        raise ValueError(f"blind deblurring needs at least 2 x 2 views; got {V} x {U}")
    if Y < 4 or X < 4:
        raise ValueError(f"blind deblurring needs views of at least 4 x 4 pixels; got {Y} x {X}")
    if isinstance(infinity_disparity, bool):
        raise ValueError("infinity_disparity must be a number")
    try:
        d_inf = float(infinity_disparity)
    except (TypeError, ValueError):
        raise ValueError(f"infinity_disparity must be a number; got {infinity_disparity!r}") from None
    if not math.isfinite(d_inf):
        raise ValueError("infinity_disparity must be finite")
    if n_control_points is not None:
        if isinstance(n_control_points, bool) or not isinstance(n_control_points, (int, np.integer)) \
                or n_control_points < 2:
            raise ValueError(f"n_control_points must be an integer >= 2; got {n_control_points!r}")
    return arr, d_inf


def _make_params(params, overrides) -> BlindParams:
    if params is None:
        params = PRESETS["default"]
    elif isinstance(params, str):
        params = BlindParams.preset(params)
    elif isinstance(params, dict):
        params = BlindParams.from_dict(params)
    elif not isinstance(params, BlindParams):
        raise ValueError(f"params must be a BlindParams, a dict or a preset name; got {type(params).__name__}")
    if overrides:
        params = params.replace(**overrides)
    return params


# ------------------------------------------------------------ the solver


def _gray(f: torch.Tensor) -> torch.Tensor:
    return f.mean(dim=-1, keepdim=True)


def _shear(f: torch.Tensor, d: float) -> torch.Tensor:
    """Refocus: view ``(v, u)`` resampled at ``(y + d v_c, x + d u_c)`` (bilinear, replicate).

    With ``d = d_inf`` this maps the blur model with ``d_inf`` to the one with
    ``d_inf = 0`` (up to interpolation): the path estimate runs on the
    sheared light field.
    """
    V, U, Y, X, C = f.shape
    out = torch.empty_like(f)
    ys = torch.arange(Y, dtype=f.dtype, device=f.device)
    xs = torch.arange(X, dtype=f.dtype, device=f.device)
    for v in range(V):
        y0, y1, wy = _lerp_taps(ys + d * (v - (V - 1) / 2.0), Y)
        rows = f[v].index_select(1, y0) * (1 - wy)[None, :, None, None] + \
            f[v].index_select(1, y1) * wy[None, :, None, None]
        for u in range(U):
            x0, x1, wx = _lerp_taps(xs + d * (u - (U - 1) / 2.0), X)
            out[v, u] = rows[u].index_select(1, x0) * (1 - wx)[None, :, None] + \
                rows[u].index_select(1, x1) * wx[None, :, None]
    return out


@torch.no_grad()
def _disparity_map(f: torch.Tensor, d_max: float = 2.5, n: int = 41, smooth: int = 2) -> np.ndarray:
    """Per-pixel disparity (px/view) of the (blurred) light field (V, U, Y, X, 1): the shear that
    makes the views agree best (least angular variance, box-smoothed over ``2 smooth + 1`` px)."""
    best = torch.full(f.shape[2:4], math.inf, dtype=f.dtype, device=f.device)
    arg = torch.zeros_like(best)
    for d in np.linspace(-d_max, d_max, n):
        var = _shear(f, float(d)).var(dim=(0, 1))[..., 0]  # (Y, X)
        var = torch.nn.functional.avg_pool2d(var[None, None], 2 * smooth + 1, stride=1, padding=smooth,
                                             count_include_pad=False)[0, 0]
        better = var < best
        best = torch.where(better, var, best)
        arg = arg.masked_fill(better, float(d))
    return arg.cpu().numpy()


#: pixels (about) on which the disparity map of the fit's weights is estimated; larger views are
#: area-averaged down to it (the weights depend on |d| / max|d| only, which this keeps)
DISPARITY_PIXELS = 160 * 160
#: floor of the disparity weights of the fit's pixels (relative to the largest |d|)
DISPARITY_FLOOR = 0.02


def _disparity_weights(f: torch.Tensor, power: float) -> np.ndarray:
    """Pixel weights ``(|d| / max|d| + DISPARITY_FLOOR) ** power`` of the fit, (Y, X) float64."""
    Y, X = f.shape[2:4]
    k = max(1, int(math.sqrt(Y * X / DISPARITY_PIXELS)))
    d = np.abs(_disparity_map(_downsample(f, k)))
    w = (d / max(float(d.max()), 1e-6) + DISPARITY_FLOOR) ** power
    w = np.repeat(np.repeat(w, k, axis=0), k, axis=1)
    return np.pad(w, ((0, Y - w.shape[0]), (0, X - w.shape[1])), mode="edge")


def _downsample(f: torch.Tensor, factor: int) -> torch.Tensor:
    """Area-average the spatial axes by ``factor`` (views untouched)."""
    if factor == 1:
        return f
    V, U, Y, X, C = f.shape
    Yc, Xc = (Y // factor) * factor, (X // factor) * factor
    g = f[:, :, :Yc, :Xc].reshape(V, U, Yc // factor, factor, Xc // factor, factor, C)
    return g.mean(dim=(3, 5))


def _cg(apply_A, b, x0, n_iter):
    """Conjugate gradients for a symmetric positive (semi-)definite ``apply_A``.

    A generator: yields the iterate after every application of ``apply_A``
    (a point where the caller may stop), returns the solution.
    """
    x = x0.clone()
    r = b - apply_A(x)
    p = r.clone()
    rr = float((r * r).sum())
    yield x
    for _ in range(n_iter):
        if rr <= 1e-20:
            break
        Ap = apply_A(p)
        alpha = rr / max(float((p * Ap).sum()), 1e-30)
        x.add_(p, alpha=alpha)
        r.sub_(Ap, alpha=alpha)
        rr_new = float((r * r).sum())
        p.mul_(rr_new / rr).add_(r)
        rr = rr_new
        yield x
    return x


def _n_hqs_steps(lam: float, p: BlindParams) -> int:
    """Splitting steps :func:`_l0_latent` takes for ``lam`` (counted as its loop does)."""
    beta, n = 2.0 * lam, 1
    while 0 < beta < p.hqs_beta_max:
        beta = min(beta * p.hqs_kappa, p.hqs_beta_max)
        n += 1
    return n


@torch.no_grad()  # torch's decorator enters no_grad at every resume of the generator only
def _l0_latent(op: BlurOperator, f: torch.Tensor, lam: float, p: BlindParams, x0: torch.Tensor):
    """Salient-edge latent: ``min ||K l - f||^2 + lam ||grad l||_0`` by half-quadratic splitting.

    The gradient is over ``y, x`` and, with ``latent_angular_weight > 0``,
    also over ``v, u`` (weighted).

    A generator: yields the current latent after every conjugate-gradient
    iteration (``n_cg + 1`` per splitting step; the caller reports progress
    there, and can be stopped there) and returns the latent, (V, U, Y, X, 1)
    float32.
    """
    from .priors import divergence4d, gradient4d

    a = p.latent_angular_weight
    aw = (a, a, 1.0, 1.0)
    if a > 0:
        def grad(z):
            return gradient4d(z, aw)

        def div(g):
            return divergence4d(g, aw)
    else:
        def grad(z):
            return _grad_yx(z)

        def div(g):
            return _div_yx(*g)

    Ktf = op.adjoint(f)
    x = x0
    beta = 2.0 * lam
    while True:
        g = grad(x)
        keep = sum(c * c for c in g) >= lam / beta
        for c in g:
            c.mul_(keep)
        rhs = Ktf - beta * div(g)

        def apply_A(z, beta=beta):
            return op.adjoint(op.forward(z)) - beta * div(grad(z))

        x = yield from _cg(apply_A, rhs, x, p.n_cg)
        if beta >= p.hqs_beta_max:
            break
        beta = min(beta * p.hqs_kappa, p.hqs_beta_max)
    return x


def _edge_sigmas(p: BlindParams) -> tuple[float, float]:
    """``(sigma_y, sigma_x)`` of the edge model: ``edge_sigma`` split by ``edge_anisotropy``."""
    half = p.edge_anisotropy * abs(p.edge_anisotropy) / 2.0
    s2 = p.edge_sigma**2
    return math.sqrt(max(s2 - half, 0.0)), math.sqrt(max(s2 + half, 0.0))


def _gauss_yx(L: torch.Tensor, sigma) -> torch.Tensor:
    """Spatial Gaussian blur of (V, U, Y, X, C), zero padded (so the operator is self-adjoint).

    ``sigma``: px, one for both axes or ``(sigma_y, sigma_x)``.
    """
    sigmas = (sigma, sigma) if np.isscalar(sigma) else tuple(sigma)
    # separable, by shifted adds (conv2d on these shapes is about 15x slower on the CPU)
    for dim, sd in zip((2, 3), sigmas):
        if sd <= 0:
            continue
        r = max(1, int(math.ceil(3 * sd)))
        t = torch.arange(-r, r + 1, dtype=L.dtype, device=L.device)
        k = torch.exp(-0.5 * (t / sd) ** 2)
        k = k / k.sum()
        n = L.shape[dim]
        out = L * k[r]
        for j in range(1, min(r, n - 1) + 1):
            out.narrow(dim, j, n - j).add_(L.narrow(dim, 0, n - j), alpha=float(k[r - j]))
            out.narrow(dim, 0, n - j).add_(L.narrow(dim, j, n - j), alpha=float(k[r + j]))
        L = out
    return L


class _EdgeBlurred:
    """``K_p G_sigma``: the blur of a latent whose edges are sharper than the scene's by a
    spatial Gaussian of ``sigma`` px, or ``(sigma_y, sigma_x)`` (which commutes with the angular
    blur of an in-plane path)."""

    def __init__(self, op, sigma):
        self.op, self.sigma = op, sigma

    def forward(self, z):
        return self.op.forward(_gauss_yx(z, self.sigma))

    def adjoint(self, r):
        return _gauss_yx(self.op.adjoint(r), self.sigma)


class _GramLoss:
    """The gradient-domain path fit ``sum ||grad_yx(K_p l) - grad_yx f||^2`` as a quadratic form.

    With ``d_inf = 0`` the blur of a pixel is a kernel over integer view
    offsets applied to its replicate-padded angular samples: clamped
    bilinear interpolation at ``u + s`` equals ``(1 - w) l[clamp(u + o)] + w
    l[clamp(u + o + 1)]`` with ``o = floor(s)``, ``w = s - o``, for every
    ``s``. The kernel (the splat of the positions ``(s_v, s_u)`` over the
    instants) is shared by all pixels of an in-plane path; with ``p_z`` it
    varies slowly over the image, and is taken constant over each of
    ``tiles x tiles`` tiles (at the tile centre). The spatial differences
    commute with the angular blur, so the fit is

        sum_t  k_t^T G_t k_t - 2 b_t^T k_t + c,

    with ``G_t``, ``b_t`` the Gram matrix and correlation of the shifted
    latent gradients at a subset of pixels of tile ``t``: built once per
    latent, after which a path step costs a few small products.
    """

    def __init__(self, f, n_pixels, rng, T, box_xy, box_z, tiles, chunk=256, weight=None):
        V, U, Y, X, _ = f.shape
        self.V, self.U, self.Y, self.X, self.T = V, U, Y, X, T
        self.R = int(min(max(V, U) - 1, math.floor(box_xy + box_z) + 1))
        R = self.R
        self.nO = 2 * R + 1
        self.chunk = chunk
        dev, dt = f.device, f.dtype
        gy, gx = _grad_yx(f)
        score = (gy * gy + gx * gx).sum(dim=(0, 1, 4))[: Y - 1, : X - 1].sqrt().cpu().double().numpy()
        # stratified: the same number of pixels from every tile, favouring strong gradients
        ty = np.minimum((np.arange(Y - 1) * tiles) // (Y - 1), tiles - 1)
        tx = np.minimum((np.arange(X - 1) * tiles) // (X - 1), tiles - 1)
        tile_of = (ty[:, None] * tiles + tx[None, :]).ravel()
        per = max(1, int(n_pixels) // (tiles * tiles))
        sel, sel_tile = [], []
        flat = score.ravel()
        flat_w = None if weight is None else weight[: Y - 1, : X - 1].ravel()
        for t in range(tiles * tiles):
            idx = np.flatnonzero(tile_of == t)
            if idx.size == 0:
                continue
            pr = flat[idx] + 0.05 * flat.mean() + 1e-12
            if flat_w is not None:
                pr = pr * flat_w[idx]
            pr = pr / pr.sum()
            k = min(per, idx.size)
            sel.append(np.sort(rng.choice(idx, size=k, replace=False, p=pr)))
            sel_tile.append(np.full(k, t))
        sel = np.concatenate(sel)
        ys, xs = np.divmod(sel, X - 1)
        self.ys = torch.as_tensor(ys, device=dev)
        self.xs = torch.as_tensor(xs, device=dev)
        self.pix_tile = torch.as_tensor(np.concatenate(sel_tile), device=dev)
        self.n_tiles = tiles * tiles
        r = max(X, Y) / 2.0
        cy = np.array([(ys[tile_of[sel] // tiles == i]).mean() if np.any(tile_of[sel] // tiles == i) else 0
                       for i in range(tiles)])
        cx = np.array([(xs[tile_of[sel] % tiles == i]).mean() if np.any(tile_of[sel] % tiles == i) else 0
                       for i in range(tiles)])
        tyc = (np.repeat(cy, tiles) - (Y - 1) / 2.0) / r
        txc = (np.tile(cx, tiles) - (X - 1) / 2.0) / r
        self.xt = torch.as_tensor(txc, dtype=dt, device=dev)
        self.yt = torch.as_tensor(tyc, dtype=dt, device=dev)
        # the data's gradients at the pixels: (M, V*U*2)
        self.F = torch.cat([gy[:, :, self.ys, self.xs, 0], gx[:, :, self.ys, self.xs, 0]], dim=0)
        self.F = self.F.permute(2, 0, 1).reshape(len(sel), -1)
        offs = torch.arange(-R, R + 1, device=dev)
        self.vidx = (torch.arange(V, device=dev)[None, :] + offs[:, None]).clamp(0, V - 1)  # (nO, V)
        self.uidx = (torch.arange(U, device=dev)[None, :] + offs[:, None]).clamp(0, U - 1)
        self.G = None
        self.scale = 1.0 / max(1, self.F.numel())

    @torch.no_grad()
    def set_latent(self, latent, cp=None, robust: float = 0.0, sigma=0.0):
        gy, gx = _grad_yx(_gauss_yx(latent, sigma))
        Lg = torch.stack([gy[:, :, self.ys, self.xs, 0], gx[:, :, self.ys, self.xs, 0]], dim=0)  # (2, V, U, M)
        nO, M = self.nO, self.ys.shape[0]
        G = torch.zeros(self.n_tiles, nO * nO, nO * nO, dtype=latent.dtype, device=latent.device)
        b = torch.zeros(self.n_tiles, nO * nO, dtype=latent.dtype, device=latent.device)
        K = None
        if cp is not None and robust > 0:
            K = self.kernels(torch.as_tensor(np.asarray(cp), dtype=latent.dtype, device=latent.device))

        def chunks():
            for m0 in range(0, M, self.chunk):
                m1 = min(M, m0 + self.chunk)
                part = Lg[..., m0:m1]  # (2, V, U, m)
                # Z[ov, ou, m, (2, V, U)]: the samples at (clamp(v + ov), clamp(u + ou))
                Zv = part[:, self.vidx]  # (2, nO, V, U, m)
                Z = Zv[:, :, :, self.uidx]  # (2, nO_v, V, nO_u, U, m)
                yield m0, m1, Z.permute(1, 3, 5, 0, 2, 4).reshape(nO * nO, m1 - m0, -1)  # (O, m, 2VU)

        w = torch.ones(M, dtype=latent.dtype, device=latent.device)
        if K is not None:
            res = torch.empty(M, dtype=latent.dtype, device=latent.device)
            for m0, m1, Z in chunks():
                pred = torch.einsum("omj,mo->mj", Z, K[self.pix_tile[m0:m1]])
                res[m0:m1] = ((pred - self.F[m0:m1]) ** 2).sum(dim=1)
            scale = robust * res.median().clamp_min(1e-20)
            w = 1.0 / (1.0 + res / scale)
        for m0, m1, Z in chunks():
            sw = w[m0:m1].sqrt()
            Zw = Z * sw[None, :, None]
            Fw = self.F[m0:m1] * sw[:, None]  # (m, 2VU) in (2, V, U) order
            tiles = self.pix_tile[m0:m1]
            for t in torch.unique(tiles).tolist():
                sel = (tiles == t).nonzero().squeeze(1)
                Zt = Zw[:, sel].reshape(nO * nO, -1)
                G[t] += Zt @ Zt.T
                b[t] += Zt @ Fw[sel].reshape(-1)
        self.G, self.b = G, b

    def kernels(self, cp):
        """The splat kernels of the tiles, ([B,] n_tiles, nO*nO) for control points ([B,] n, 3)."""
        basis = torch.as_tensor(bernstein_matrix(cp.shape[-2], self.T), dtype=cp.dtype, device=cp.device)
        pos = basis @ cp  # ([B,] T, 3)
        R, nO = self.R, self.nO
        s_u = pos[..., None, :, 0] - self.xt[:, None] * pos[..., None, :, 2]  # ([B,] tiles, T)
        s_v = pos[..., None, :, 1] - self.yt[:, None] * pos[..., None, :, 2]
        s_u = s_u.clamp(-R + 1e-4, R - 1e-4)
        s_v = s_v.clamp(-R + 1e-4, R - 1e-4)
        fu, fv = torch.floor(s_u.detach()), torch.floor(s_v.detach())
        wu, wv = s_u - fu, s_v - fv
        iu, iv = (fu + R).long(), (fv + R).long()
        K = torch.zeros(s_u.shape[:-1] + (nO * nO,), dtype=cp.dtype, device=cp.device)
        for dv, wvv in ((0, 1 - wv), (1, wv)):
            for du, wuu in ((0, 1 - wu), (1, wu)):
                idx = ((iv + dv).clamp(max=nO - 1)) * nO + (iu + du).clamp(max=nO - 1)
                K = K.scatter_add(-1, idx, wvv * wuu)
        return K / self.T

    def __call__(self, cp):
        """The fit (up to a constant) of control points ([B,] n, 3): shape ([B,])."""
        K = self.kernels(cp)
        quad = torch.einsum("...ti,tij,...tj->...", K, self.G, K) - 2.0 * (self.b * K).sum(dim=(-1, -2))
        return quad * self.scale


#: Adam steps of the path fit between two progress reports
FIT_REPORT_EVERY = 10
#: the path fit stops when its best fit improved by less than this (relative) in FIT_PATIENCE steps
FIT_RTOL = 1e-6
FIT_PATIENCE = 30
#: least time (s) between two light-field previews of the path stage (its records come often)
PREVIEW_MIN_INTERVAL = 1.0


def _fit_path(pp: _PathParam, loss_fn, steps: int, lr: float, every: int = FIT_REPORT_EVERY):
    """Adam on a batch of paths for up to ``steps`` steps; returns their final fits, shape (B,).

    A generator: every ``every`` steps it yields ``(step, fit, control_points)``,
    the best current fit of the batch and its control points ((n, 3) float64).
    """
    opt = torch.optim.Adam([pp.q], lr=lr)
    best = float("inf")
    stall = 0
    for step in range(1, steps + 1):
        opt.zero_grad(set_to_none=True)
        with torch.enable_grad():  # whatever the caller's mode (a worker thread may have been left in no_grad)
            each = loss_fn(pp.control_points())
            each.sum().backward()
        opt.step()
        pp.project()
        # stop when the best path of the batch has not improved for a while (the batch's sum
        # is no guide: paths pressed against the box keep it oscillating)
        k = int(torch.argmin(each.detach()))
        loss = float(each[k].detach())
        if step % every == 0 and step < steps:
            yield step, loss, pp.numpy().reshape(-1, *pp.q.shape[-2:])[k]
        if loss < best - FIT_RTOL * abs(best):
            best, stall = loss, 0
        else:
            stall += 1
            if stall >= FIT_PATIENCE:
                break
    with torch.no_grad():
        return loss_fn(pp.control_points())


def _positions(cp: np.ndarray, n_times: int) -> np.ndarray:
    return bezier_positions(cp, n_times)


def _iter_alternating(g, d_inf, p: BlindParams, device, rng, n_cp, box, history, info, make_preview=None):
    """Coarse-to-fine salient-edge / path alternation on the grayscale ``g`` (V, U, Y, X, 1).

    Yields a record after every conjugate-gradient iteration of the latent, every
    :data:`FIT_REPORT_EVERY` steps of the path fit and at the end of every
    alternation. ``iteration`` counts these reports within a level, out of
    ``n_iterations = n_outer * per_alternation`` (an alternation that ends
    early jumps to its end), so that the fraction done only grows.
    ``make_preview(latent, factor)``, when given, makes the preview sent with
    every ``preview_every``-th record (at most one per
    :data:`PREVIEW_MIN_INTERVAL` seconds).
    """
    V, U, Y, X, _ = g.shape
    # pyramid: factors 2^k with the smallest side >= min_size
    top = 1
    while p.max_size and min(Y, X) // top > p.max_size and min(Y, X) // (2 * top) >= p.min_size:
        top *= 2
    factors = []
    for k in range(p.n_levels - 1, -1, -1):
        fac = top * 2**k
        if min(Y, X) // fac >= p.min_size or fac == top:
            factors.append(fac)
    # stages: (factor, p_z free, alternations); with estimate_z, a last stage on the finest level
    # frees p_z, starting from the in-plane estimate
    stages = [(fac, False, p.n_outer) for fac in factors]
    if p.estimate_z and p.z_outer > 0:
        stages.append((factors[-1], True, p.z_outer))
    n_stages = len(stages)
    info["n_path_stages"] = n_stages
    T = p.n_times
    # initial paths: short lines in evenly spread directions, jittered by the seed
    n_start = 2 if len(factors) > 1 or n_cp == 2 else n_cp
    starts = []
    for i in range(p.n_restarts):
        a = math.pi * (i + rng.uniform(-0.15, 0.15)) / p.n_restarts
        d = np.array([math.cos(a), math.sin(a), 0.0]) * p.init_length / 2
        starts.append(np.stack([-d, d]))
    cp = None
    lam0 = p.l0_weight
    # reports per alternation: latent steps (at most those at the smallest lambda), fit reports, the end
    lam_min = min(p.l0_weight, p.l0_weight * p.l0_floor)
    per_outer = _n_hqs_steps(lam_min, p) * (p.n_cg + 1) + (p.path_steps - 1) // FIT_REPORT_EVERY + 1
    n_records = 0
    last_preview = -math.inf

    def record(stage, fac, it, cur, latent, loss=float("nan"), **extra):
        nonlocal n_records, last_preview
        n_outer = stages[stage][2]
        n_records += 1
        preview = None
        if make_preview is not None and p.preview_every and n_records % p.preview_every == 0 \
                and time.perf_counter() - last_preview >= PREVIEW_MIN_INTERVAL:
            preview = make_preview(latent, fac)
            last_preview = time.perf_counter()
        return Progress(
            stage=f"path ({'p_z' if stages[stage][1] else 'level'} {stage + 1}/{n_stages}, {Y // fac}x{X // fac})",
            iteration=it, n_iterations=n_outer * per_outer, loss=loss, control_points=np.array(cur),
            preview=preview, stage_index=stage, n_stages=n_stages + 1, info={"level": stage, "factor": fac, **extra},
        )

    latent = None
    disparity = {}  # level factor -> pixel weights of the fit
    for stage, (fac, free_z, n_outer) in enumerate(stages):
        f = _downsample(g, fac)
        shape = tuple(f.shape)
        d_lvl = d_inf / fac
        n_lvl = n_cp if stage >= len(factors) - 1 else min(n_cp, n_start + stage)
        if p.disparity_weight > 0 and fac not in disparity:
            disparity[fac] = _disparity_weights(f, p.disparity_weight)
        sub = _GramLoss(f, p.n_pixels, rng, T, box, box * p.z_box if free_z else 0.0, p.tiles if free_z else 1,
                        weight=disparity.get(fac))
        lam = lam0
        if latent is None or latent.shape != f.shape:
            latent = f.clone()
        cur = np.zeros((n_lvl, 3)) if cp is None else elevate_degree(cp, n_lvl)
        if not free_z:
            cur[:, 2] = 0.0
        still = 0
        es_from = p.edge_sigma_from if stage == 0 else 1  # the edge model from this alternation on
        for outer in range(1, n_outer + 1):
            sigma = _edge_sigmas(p) if outer >= es_from else (0.0, 0.0)
            base = (outer - 1) * per_outer
            tick = 0
            op = BlurOperator(shape, cur, n_times=T, infinity_disparity=d_lvl, device=device)
            if max(sigma) > 0:
                op = _EdgeBlurred(op, sigma)
            gen, x = _l0_latent(op, f, lam, p, latent), None
            while True:
                try:
                    x = next(gen)
                except StopIteration as stop:
                    latent = stop.value
                    break
                tick = min(tick + 1, per_outer - 1)
                yield record(stage, fac, base + tick, cur, x, alternation=outer, phase="latent", **{"lambda": lam})
            del gen, x, op
            sub.set_latent(latent, cur if (cp is not None or outer > 1) else None, p.fit_robust, sigma)
            if cp is None and outer == 1:
                candidates = [elevate_degree(c, n_lvl) for c in starts]
                for _ in range(p.n_random):
                    c = rng.uniform(-1.0, 1.0, size=(n_lvl, 3)) * p.init_length
                    c[:, 2] = 0.0
                    candidates.append(c)
            else:
                candidates = [cur, -cur] if p.try_mirror else [cur]
                for _ in range(p.n_perturb):
                    c = cur + rng.normal(0.0, p.perturb, size=cur.shape)
                    c[:, 2] = cur[:, 2]
                    candidates.append(c)
                if free_z:  # the current in-plane shape with random out-of-plane motions
                    for _ in range(p.n_random_later):
                        c = cur.copy()
                        c[:, 2] = rng.uniform(-1.0, 1.0, size=len(cur)) * box * p.z_box
                        candidates.append(c)
                # fresh random starts too: the latent has changed, and with it the fit's minima
                for _ in range(p.n_random_later):
                    c = rng.uniform(-1.0, 1.0, size=(n_lvl, 3)) * p.init_length
                    c[:, 2] = 0.0
                    candidates.append(c)
            pp = _PathParam(np.stack(candidates), T, box, device, free_z=free_z, z_box=box * p.z_box)
            pp.project()
            gen = _fit_path(pp, sub, p.path_steps, p.path_lr)
            while True:
                try:
                    step, fit, shown = next(gen)
                except StopIteration as stop:
                    scores = stop.value.detach().cpu().numpy()
                    break
                tick = min(tick + 1, per_outer - 1)
                yield record(stage, fac, base + tick, shown, latent, alternation=outer, phase="path fit",
                             step=step, fit=fit, **{"lambda": lam})
            del gen
            k = int(np.argmin(scores))
            best = (float(scores[k]), pp.control_points()[k].detach().cpu().double().numpy())
            if cp is None and outer == 1:
                info["restart_losses"] = scores.tolist()
            loss, new = best
            move = float(np.abs(_positions(new, T) - _positions(cur, T)).max()) if len(new) == len(cur) else 1.0
            cur = new
            history.append(loss)
            lam = max(lam * p.l0_decay, p.l0_weight * p.l0_floor)
            yield record(stage, fac, outer * per_outer, cur, latent, loss=loss, alternation=outer, phase="done",
                         move=move, **{"lambda": lam})
            still = still + 1 if (move < p.path_tol and outer > es_from) else 0
            if still >= 2:
                break
        cp = cur
        lam0 = lam
    return elevate_degree(cp, n_cp), factors


def _iter_joint(g, d_inf, p: BlindParams, device, rng, n_cp, box, history, info, make_preview=None):
    """The paper's joint Adam on path and grayscale light field (one record per iteration)."""
    shape = tuple(g.shape)
    cp0 = rng.uniform(-0.25, 0.25, size=(n_cp, 3))
    cp0[:, 2] = 0.0
    pp = _PathParam(cp0, p.n_times, box, device)
    pp.project()
    L = g.clone().requires_grad_(True)
    opt = torch.optim.Adam([{"params": [pp.q], "lr": p.path_lr}, {"params": [L], "lr": p.lf_lr}])
    w0 = p.prior_weight
    for it in range(1, p.n_iter + 1):
        w = max(w0 * p.prior_decay ** (it - 1), w0 * p.prior_floor)
        eps = max(p.eps * p.eps_decay ** (it - 1), p.eps_min)
        opt.zero_grad(set_to_none=True)
        with torch.enable_grad():
            op = BlurOperator(shape, pp.control_points(), n_times=p.n_times, infinity_disparity=d_inf, device=device)
            r = op.forward(L) - g
            loss = (r * r).mean() + w * sparse_gradient_prior(L, eps)
            loss.backward()
        opt.step()
        pp.project()
        history.append(float(loss.detach()))
        preview = None
        if make_preview is not None and p.preview_every and it % p.preview_every == 0:
            preview = make_preview(L, 1)
        yield Progress(stage="path (joint)", iteration=it, n_iterations=p.n_iter, loss=history[-1],
                       control_points=pp.numpy(), preview=preview, stage_index=0, n_stages=2,
                       info={"prior_weight": w, "eps": eps})
    return pp.numpy(), [1]


def iter_blind_deblur(
    blurred,
    *,
    infinity_disparity: float = 0.0,
    params: BlindParams | dict | str | None = None,
    device="auto",
    seed: int = 0,
    n_control_points: int | None = None,
    **overrides,
):
    """Blind deblurring as a generator: yields progress, returns a :class:`BlindResult`.

    Takes the arguments of :func:`blind_deblur`. Arguments are checked when
    the generator is created; closing it stops the work at the next yield:
    records come after every conjugate-gradient iteration of the latent
    (one forward and one adjoint blur), every :data:`FIT_REPORT_EVERY` Adam steps of the
    path fit, every alternation and every TV iteration.

    Yields
    ------
    Progress
        ``stage`` names the stage (``'path (level i/n, YxX)'``, ``'final'``),
        ``control_points`` the current path (in every record), ``preview``
        on every ``params.preview_every``-th record (in the path stage, at
        most one per :data:`PREVIEW_MIN_INTERVAL` s) the current light-field
        estimate (input shape, float32; in the path stage the grayscale
        salient-edge latent, upsampled and repeated over the channels).
        In the path stage ``iteration`` counts the records of the level out
        of ``n_iterations`` (an alternation ending early jumps to its end);
        ``loss`` is the path fit at the end of an alternation
        (``info['phase'] == 'done'``) and NaN on the records inside one
        (``info['phase']`` ``'latent'`` or ``'path fit'``, with the current
        best fit in ``info['fit']``).

    Returns
    -------
    BlindResult
    """
    arr, d_inf = _validate_input(blurred, infinity_disparity, n_control_points)
    p = _make_params(params, overrides)
    dev = select_device(device)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed must be an integer; got {seed!r}")
    need = estimate_blind_memory(arr.shape, p)
    dev = plan_device(dev, need, tiles_possible=True)
    tile = plan_tiles(arr.shape, p, _free_memory(dev))
    if tile is not None:
        warnings.warn(
            f"blind deblurring needs about {need / 2**30:.2f} GiB, more than is "
            f"available: estimating the path on the central {tile[0]}x{tile[1]} pixels and restoring the light "
            f"field in overlapping tiles of {tile[0]}x{tile[1]}",
            RuntimeWarning,
            stacklevel=2,
        )
    return _run_with_fallback(arr, d_inf, p, dev, int(seed), n_control_points, tile)


def plan_device(device: torch.device, need: int, tiles_possible: bool = False) -> torch.device:
    """The device to run on, given an estimate of the memory needed (bytes).

    A CUDA device without ``need`` bytes free falls back to the CPU with a
    :class:`RuntimeWarning`; on the CPU a shortage is only warned about
    (unless ``tiles_possible``: the caller then works in tiles, see
    :func:`plan_tiles`).
    """
    free = _free_memory(device)
    if free is None or need <= free:
        return device
    if device.type != "cuda" and tiles_possible:
        return device
    if device.type == "cuda":
        warnings.warn(
            f"blind deblurring needs about {need / 2**30:.2f} GiB but {device} has {free / 2**30:.2f} GiB free: "
            "running on the CPU instead",
            RuntimeWarning,
            stacklevel=3,
        )
        return torch.device("cpu")
    warnings.warn(
        f"blind deblurring needs about {need / 2**30:.2f} GiB but only {free / 2**30:.2f} GiB of memory is "
        "available: it may fail or swap; crop the light field to be safe",
        RuntimeWarning,
        stacklevel=3,
    )
    return device


def _run_with_fallback(arr, d_inf, p, dev, seed, n_control_points, tile=None):
    try:
        result = yield from _run(arr, d_inf, p, dev, seed, n_control_points, tile)
        return result
    except torch.cuda.OutOfMemoryError as exc:
        if dev.type != "cuda":
            raise
        # leave the except block before going on: its traceback holds the failed run's frames,
        # and with them its GPU tensors
        message = str(exc).splitlines()[0] if str(exc) else "out of memory"
    finally:
        _empty_cache(dev)
    warnings.warn(f"the GPU ran out of memory ({message}); starting again on the CPU", RuntimeWarning, stacklevel=2)
    result = yield from _run(arr, d_inf, p, torch.device("cpu"), seed, n_control_points, tile)
    return result


def _empty_cache(dev):
    """Release cached GPU memory and cuBLAS workspaces (a no-op on the CPU)."""
    if dev.type == "cuda" and torch.cuda.is_available():  # pragma: no cover - needs a GPU
        torch.cuda.synchronize(dev)
        clear = getattr(torch._C, "_cuda_clearCublasWorkspaces", None)  # held by the caching allocator
        if clear is not None:
            clear()
        torch.cuda.empty_cache()


@torch.no_grad()
def _preview(latent: torch.Tensor, fac: int, shape, unshear: float, offset=(0, 0)) -> np.ndarray:
    """A path-stage latent (V, U, y, x, 1) at level ``fac`` as a preview of the input's ``shape``.

    Nearest upsampling, placed at ``offset`` (the top-left pixel of the crop
    the path is estimated on) and edge-padded to the full size, the refocus
    of the path stage undone when ``unshear`` is not 0, clipped to [0, 1]
    and repeated over the colour channels: float32, ``shape``.
    """
    V, U, Y, X = shape[:4]
    lat = latent.detach()[..., 0]
    if fac > 1:
        lat = lat.repeat_interleave(fac, dim=2).repeat_interleave(fac, dim=3)
    y, x = lat.shape[2:4]
    if (y, x) != (Y, X):
        oy, ox = offset
        lat = torch.nn.functional.pad(lat.reshape(V * U, 1, y, x), (ox, X - x - ox, oy, Y - y - oy),
                                      mode="replicate")
        lat = lat.reshape(V, U, Y, X)
    if unshear != 0.0:
        lat = _shear(lat[..., None], -unshear)[..., 0]
    out = lat.clamp(0.0, 1.0).to(device="cpu", dtype=torch.float32).numpy()
    if len(shape) == 5:
        out = np.repeat(out[..., None], shape[4], axis=-1)
    return np.ascontiguousarray(out, dtype=np.float32)


def _run(arr, d_inf, p: BlindParams, dev, seed, n_control_points, tile=None):
    t0 = time.perf_counter()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    V, U, Y, X = arr.shape[:4]
    n_cp = int(n_control_points) if n_control_points is not None else p.n_control_points
    box = p.max_extent if p.max_extent > 0 else max(0.5, 0.35 * (min(V, U) - 1))
    crop, offset = arr, (0, 0)
    if tile is not None:  # the path from the central tile-sized crop (the path is the same everywhere)
        cy, cx = min(Y, tile[0] + 2 * TILE_MARGIN), min(X, tile[1] + 2 * TILE_MARGIN)
        offset = ((Y - cy) // 2, (X - cx) // 2)
        crop = arr[:, :, offset[0] : offset[0] + cy, offset[1] : offset[1] + cx]
    f = torch.as_tensor(np.ascontiguousarray(crop), dtype=torch.float32, device=dev)
    if arr.ndim == 4:
        f = f.unsqueeze(-1)
    g = _gray(f).contiguous()
    history: list = []
    info: dict = {"device": str(dev), "box": box}
    sheared = p.method == "alternating" and d_inf != 0.0

    def make_preview(latent, fac):
        return _preview(latent, fac, arr.shape, d_inf if sheared else 0.0, offset)

    if p.method == "alternating":
        if sheared:
            g = _shear(g, d_inf)  # the path fit then uses the d_inf = 0 model
        cp, factors = yield from _iter_alternating(g, 0.0, p, dev, rng, n_cp, box, history, info, make_preview)
    else:
        cp, factors = yield from _iter_joint(g, d_inf, p, dev, rng, n_cp, box, history, info, make_preview)
    info["levels"] = [(crop.shape[2] // k, crop.shape[3] // k) for k in factors]
    n_path = info.pop("n_path_stages", len(factors))
    if crop is not arr:
        # p_z in the crop's normalised coordinates -> the full frame's (x~ scales by r_crop / r_full)
        cp = np.array(cp, dtype=np.float64)
        cp[:, 2] *= max(Y, X) / max(crop.shape[2], crop.shape[3])
        info["tile"] = tuple(tile)
    cp = canonical_time_direction(center_path(cp, p.n_times))
    t1 = time.perf_counter()
    del g, f
    # final non-blind stage, all channels at once (tile by tile when memory is short)
    if p.tv_iter > 0:
        from .deconvolution import iter_deconvolve

        if tile is None:
            parts = [((slice(None), slice(None)), (slice(None), slice(None)))]
        else:
            reach = float(np.abs(bezier_positions(cp, p.final_n_times)).sum(axis=1).max())  # |p_x| + |p_y| + |p_z|
            parts = list(_tiles(Y, X, tile, TILE_MARGIN + int(math.ceil(abs(d_inf) * reach))))
            out = np.array(arr, dtype=np.float32)  # restored tile by tile; the rest shows as blurred meanwhile
        n_all = p.tv_iter * len(parts)
        for i, (core, pad) in enumerate(parts):
            piece = arr[:, :, pad[0], pad[1]]
            y0, x0 = pad[0].start or 0, pad[1].start or 0
            frame = None if tile is None else (y0, x0, Y, X)
            gen = iter_deconvolve(
                piece, cp, n_times=p.final_n_times, infinity_disparity=d_inf, device=dev,
                method="tv", weight=p.tv_weight, n_iter=p.tv_iter, tol=0.0,
                preview_every=p.preview_every, frame=frame,
            )
            inner = (slice(core[0].start - y0, core[0].stop - y0), slice(core[1].start - x0, core[1].stop - x0)) \
                if tile is not None else None
            while True:
                try:
                    rec = next(gen)
                except StopIteration as stop:
                    res = stop.value
                    break
                preview = rec.preview
                if tile is not None and preview is not None:
                    preview = out.copy()
                    preview[:, :, core[0], core[1]] = rec.preview[:, :, inner[0], inner[1]]
                yield Progress(stage="final" if tile is None else f"final (tile {i + 1}/{len(parts)})",
                               iteration=i * p.tv_iter + rec.iteration, n_iterations=n_all,
                               loss=rec.loss, control_points=cp, preview=preview, stage_index=n_path,
                               n_stages=n_path + 1, info=rec.info)
            if tile is None:
                out = res
            else:
                out[:, :, core[0], core[1]] = res[:, :, inner[0], inner[1]]
    else:
        out = np.asarray(arr, dtype=np.float32).copy()
    t2 = time.perf_counter()
    return BlindResult(
        lightfield=np.asarray(out, dtype=np.float32),
        control_points=cp,
        loss_history=history,
        params=p,
        timings={"path": t1 - t0, "final": t2 - t1, "total": t2 - t0},
        info=info,
    )


def blind_deblur(
    blurred,
    *,
    infinity_disparity: float = 0.0,
    params: BlindParams | dict | str | None = None,
    device="auto",
    seed: int = 0,
    n_control_points: int | None = None,
    callback=None,
    **overrides,
) -> BlindResult:
    """Estimate the camera path and the sharp light field of a motion-blurred light field.

    Parameters
    ----------
    blurred : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        The blurred light field (MODEL.md layout), computed in float32.
    infinity_disparity : float, default 0.0
        ``d_inf`` in px/view of the blur model.
    params : BlindParams, dict or str, optional
        Parameters, or a preset name (``'default'``, ``'paper'``). Single
        fields may also be given as keywords, overriding them.
    device : {'auto', 'cpu', 'cuda'}, default 'auto'
        Falls back to the CPU, with a warning, when the GPU lacks the memory.
    seed : int, default 0
        Seed of the random parts (initial paths); equal seeds give equal results.
    n_control_points : int, optional
        Control points of the estimated path (default ``params.n_control_points``).
    callback : callable, optional
        Called with each :class:`~napari_lfdeblur.progress.Progress` record.

    Returns
    -------
    BlindResult
        ``.lightfield`` (input shape, float32), ``.control_points`` ((n, 3),
        zero-mean gauge), ``.loss_history``, ``.params``, ``.timings``.

    Raises
    ------
    ValueError
        On a malformed light field (wrong ndim, NaN), unknown or invalid
        parameters.
    """
    gen = iter_blind_deblur(
        blurred, infinity_disparity=infinity_disparity, params=params, device=device, seed=seed,
        n_control_points=n_control_points, **overrides,
    )
    return run_to_completion(gen, callback)
