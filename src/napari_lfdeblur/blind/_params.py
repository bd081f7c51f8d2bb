"""Parameters of blind deblurring, nested by stage, the named presets and the result type."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._params import JsonParams, check_fields
from ..deconvolution import DeconvolutionParams

__all__ = ["METHODS", "MOTIONS", "LatentParams", "PathFitParams", "RotationFitParams", "JointParams", "BlindParams",
           "BlindResult", "PRESETS", "PathEstimate", "MAX_EDGE_WIDTH"]

METHODS = ("alternating", "joint")
MOTIONS = ("3dof", "6dof")
#: the widest edge model (``edge_sigma``, ``|edge_anisotropy|``) taken, px: a wider edge profile is blur, not an edge
MAX_EDGE_WIDTH = 5.0


@dataclass(frozen=True)
class LatentParams(JsonParams):
    """The salient-edge latent of the ``'alternating'`` method (:attr:`BlindParams.latent`).

    Attributes
    ----------
    l0_weight : float
        ``lambda`` of the L0 gradient latent at the coarsest level (> 0).
    l0_decay : float
        ``lambda`` is multiplied by this after every alternation, in (0, 1]
        (floor ``l0_weight * l0_floor``).
    l0_floor : float
        The floor of ``lambda`` as a fraction of ``l0_weight``, in (0, 1];
        also the evidence test's weight, ``l0_weight * l0_floor``.
    angular_weight : float
        Weight of the angular (``v, u``) differences in the L0 latent
        (0: spatial differences only).
    hqs_beta_max : float
        Half-quadratic splitting runs ``beta = 2 lambda * kappa^k`` up to this.
    hqs_kappa : float
        The splitting's growth factor of ``beta`` (> 1).
    n_cg : int
        Conjugate-gradient iterations per splitting step.
    edge_sigma : float
        The salient-edge latent is taken to be sharper than the scene by a
        spatial Gaussian of this many pixels, applied inside the model, so
        that the path need not absorb the edge profile (0: off; at most
        5 px). Without it the path comes out too long (docs/blind.md).
    edge_anisotropy : float
        How much softer the scene's edges are along ``x`` than along ``y``,
        in px: the Gaussian along ``y`` that would make them equally soft
        (negative: softer along ``y``). The edge model keeps its mean square
        width ``edge_sigma**2`` and splits it between the axes,
        ``sigma_x**2 = edge_sigma**2 + a |a| / 2`` and ``sigma_y**2 =
        edge_sigma**2 - a |a| / 2`` (at least 0). A property of the camera,
        not of the motion (``benchmarks/scene_anisotropy.py`` measures it;
        docs/blind.md); with the isotropic default the path estimate absorbs
        the difference. 0: isotropic. Within +-5 px.
    edge_sigma_from : int
        The edge model is used from this alternation of the first level on
        (1: from the start). Used from the start it lets the Gaussian
        explain the whole of a small blur, and the path stays too short; the
        first alternations therefore find the (too long) path without it.
    """

    l0_weight: float = 4e-3
    l0_decay: float = 0.5
    l0_floor: float = 0.05
    angular_weight: float = 0.5
    hqs_beta_max: float = 2.0
    hqs_kappa: float = 2.0
    n_cg: int = 3
    edge_sigma: float = 0.5
    edge_anisotropy: float = 0.0
    edge_sigma_from: int = 4

    _what = "blind latent"

    def __post_init__(self):
        check_fields(self, "BlindParams.latent", ints={"n_cg": 1, "edge_sigma_from": 1},
                     nonneg=("angular_weight", "edge_sigma"),
                     positive=("l0_weight", "l0_floor", "hqs_beta_max", "l0_decay", "hqs_kappa"),
                     signed=("edge_anisotropy",), unit=("l0_decay", "l0_floor"))
        if self.hqs_kappa <= 1:
            raise ValueError(f"BlindParams.latent.hqs_kappa must be > 1; got {self.hqs_kappa}")
        for name, value in (("edge_sigma", self.edge_sigma), ("edge_anisotropy", self.edge_anisotropy)):
            if abs(value) > MAX_EDGE_WIDTH:
                raise ValueError(f"BlindParams.latent.{name} must be within {MAX_EDGE_WIDTH:g} px; got {value}")


@dataclass(frozen=True)
class PathFitParams(JsonParams):
    """The path fit and the alternation schedule of the ``'alternating'`` method (:attr:`BlindParams.path`).

    Attributes
    ----------
    region : int
        On views larger than ``region x region`` px, the path is estimated on
        the window of that size that conditions the fit best (edges in two
        directions, disparity away from ``d_inf``; docs/blind.md) and used
        for the whole light field, so that its cost does not grow with the
        capture (0: on the whole view; else at least ``min_size``).
    n_regions : int
        On views larger than ``region``, the number of such windows, spread
        over the view (one in each cell of a grid, see
        :func:`~napari_lfdeblur.blind._region.choose_regions`), each with its
        own latent, the path fitted to all at once. Out-of-plane motion
        blurs the parts of the view differently, so windows far apart
        constrain ``p_z`` (and the path as a whole) better than one window
        of as many pixels. Each window costs the path stage about as much
        as the first. ``'6dof'`` motion and the ``'joint'`` method use one.
    n_levels : int
        Spatial pyramid levels (1 = full resolution only). Levels smaller
        than ``min_size`` px are skipped.
    min_size : int
        Smallest spatial size of a pyramid level (>= 4).
    max_size : int
        Largest spatial size (smaller side) used for the path estimation;
        finer levels are skipped (0: up to full resolution). The path means
        the same at every resolution, so this trades little accuracy for time.
    n_outer : int
        Maximum latent/path alternations per level. Every alternation tends
        to lengthen the path (the latent it fits is sharper than the scene),
        so the default is short (docs/blind.md, *Stopping*).
    n_restarts : int
        Initial paths tried on the coarsest level (linear paths of length
        ``init_length`` views in evenly spread directions), the best kept.
    init_length : float
        Length of the initial linear paths, in views.
    lr : float
        Adam step of the path (views).
    steps : int
        Adam steps on the path per alternation.
    tol : float
        A level stops when the path moves less than this (views, largest
        change of a sampled position) in two successive alternations.
    n_pixels : int
        Pixels (chosen at random, favouring strong gradients, with all their
        views) on which the path is fitted to the latent (>= 16).
    n_random : int
        Random paths (control points uniform within ``+-init_length`` views)
        tried at the start besides the lines, all fitted at once as a batch.
        The fit has many local minima; it is cheap (a few small products per
        step), so a wide batch is what finds the global one.
    n_random_later : int
        Fresh random paths added to the batch at every later alternation.
    robust : float
        From the second alternation on, each fitted pixel is weighted by
        ``1 / (1 + r / (robust * median(r)))``, ``r`` its residual under the
        current path: pixels whose texture the salient-edge latent lacks
        count less (0: no weighting).
    n_perturb : int
        Randomly perturbed copies of the current path tried at every later
        alternation (kept only when they fit better).
    perturb : float
        Standard deviation of those perturbations, in views.
    disparity_weight : float
        The pixels of the fit are drawn with a probability also proportional
        to ``(|d| / max|d| + 0.02) ** disparity_weight``, ``d`` the disparity
        estimated from the blurred light field itself (which stays
        consistent across views). Where ``|d|`` is small the blur moves the
        scene by little more than its edge profile, and a salient-edge
        latent misleads the fit most (0: uniform).
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
    """

    region: int = 128
    n_regions: int = 4
    n_levels: int = 1
    min_size: int = 24
    max_size: int = 0
    n_outer: int = 2
    n_restarts: int = 4
    init_length: float = 1.5
    lr: float = 0.05
    steps: int = 300
    tol: float = 0.01
    n_pixels: int = 8000
    n_random: int = 500
    n_random_later: int = 200
    robust: float = 0.3
    n_perturb: int = 4
    perturb: float = 0.3
    disparity_weight: float = 4.0
    tiles: int = 4
    z_box: float = 0.5
    try_mirror: bool = True
    estimate_z: bool = True
    z_outer: int = 1

    _what = "blind path fit"

    def __post_init__(self):
        ints = {"region": 0, "n_regions": 1, "n_levels": 1, "min_size": 4, "max_size": 0, "n_outer": 1,
                "n_restarts": 1, "steps": 1, "n_pixels": 16, "n_random": 0, "n_random_later": 0, "n_perturb": 0,
                "tiles": 1, "z_outer": 0}
        check_fields(self, "BlindParams.path", ints=ints,
                     nonneg=("init_length", "tol", "robust", "perturb", "disparity_weight", "z_box"),
                     positive=("lr",), bools=("try_mirror", "estimate_z"))
        if 0 < self.region < self.min_size:
            raise ValueError(f"BlindParams.path.region must be 0 or at least min_size = {self.min_size} px; "
                             f"got {self.region}")


@dataclass(frozen=True)
class RotationFitParams(JsonParams):
    """The rotation stage of ``motion='6dof'`` (docs/blind.md, "Camera rotation"). Frozen.

    Attributes
    ----------
    n_outer : int
        Alternations of the salient-edge latent and the 6-DOF path fit.
    steps : int
        Adam steps of the path fit per alternation.
    lr : float
        Adam's step: views for the translation, px of image motion
        (``R r``) for the rotation.
    n_times : int
        Exposure instants of the model during the stage (>= 2).
    fit_tol : float
        The path fit stops early when its loss fell by less than this
        fraction over the last 10 steps, the first 10 counted from the
        loss after step 1 (0: always ``steps`` steps).
    path_tol : float
        The alternations stop early when one moved the path by less than
        this: the two paths' blurs of the data differ by less than
        ``path_tol`` of the larger blur (0: always ``n_outer``).
    warm_hqs_steps : int
        The latents after the first start from the previous latent and take
        only this many last splitting steps (0: the whole schedule).
    """

    n_outer: int = 4
    steps: int = 40
    lr: float = 0.05
    n_times: int = 8
    fit_tol: float = 0.01
    path_tol: float = 0.05
    warm_hqs_steps: int = 4

    _what = "blind rotation fit"

    def __post_init__(self):
        ints = {"n_outer": 1, "steps": 1, "n_times": 2, "warm_hqs_steps": 0}
        check_fields(self, "BlindParams.rotation", ints=ints, positive=("lr",), nonneg=("fit_tol", "path_tol"))


@dataclass(frozen=True)
class JointParams(JsonParams):
    """The paper's joint Adam, the ``'joint'`` method (:attr:`BlindParams.joint`).

    Attributes
    ----------
    n_iter : int
        Iterations (Adam steps on the path and the light field together), >= 1.
    lr : float
        Adam step of the path (views).
    lf_lr : float
        Adam step of the light field.
    prior_weight, prior_decay, prior_floor : float
        Weight of the sparse-gradient prior, its decay per iteration, in
        (0, 1], and its floor as a fraction of the start, in [0, 1].
    eps, eps_decay, eps_min : float
        ``eps`` of the sparse-gradient prior, its decay per iteration, in
        (0, 1], and its floor, at most ``eps``.
    """

    n_iter: int = 1000
    lr: float = 0.05
    lf_lr: float = 0.04
    prior_weight: float = 8e-3
    prior_decay: float = 0.997
    prior_floor: float = 0.1
    eps: float = 0.12
    eps_decay: float = 0.997
    eps_min: float = 0.04

    _what = "blind joint"

    def __post_init__(self):
        check_fields(self, "BlindParams.joint", ints={"n_iter": 1}, nonneg=("prior_weight", "prior_floor", "eps_min"),
                     positive=("lr", "lf_lr", "eps", "prior_decay", "eps_decay"), unit=("prior_decay", "eps_decay"))
        if self.prior_floor > 1:
            raise ValueError(f"BlindParams.joint.prior_floor is a fraction of the start, at most 1; "
                             f"got {self.prior_floor}")
        if self.eps_min > self.eps:
            raise ValueError(f"BlindParams.joint.eps_min must not exceed eps ({self.eps}); got {self.eps_min}")


def _default_final() -> DeconvolutionParams:
    return DeconvolutionParams(method="tv")  # weight from the noise, stops on the objective


_NESTED = {"latent": LatentParams, "path": PathFitParams, "rotation": RotationFitParams, "joint": JointParams}


@dataclass(frozen=True)
class BlindParams(JsonParams):
    """Parameters of :func:`~napari_lfdeblur.blind.blind_deblur`, nested by stage. Frozen.

    Save with :meth:`to_json`; change with :meth:`replace`, which takes a
    dict for a nested field (merged into its current value), e.g.
    ``p.replace(n_control_points=5, latent={"edge_anisotropy": 0.6})``.

    Attributes
    ----------
    method : {'alternating', 'joint'}
        ``'alternating'``: salient-edge latent / path alternation, coarse to
        fine. ``'joint'``: the paper's joint Adam.
    motion : {'3dof', '6dof'}
        ``'3dof'``: the camera translates (``(n, 3)`` paths). ``'6dof'``: it
        may rotate too; a rotation stage follows the translation's estimate
        and the path is ``(n, 6)`` (``'alternating'`` only).
    n_control_points : int
        Control points of the estimated Bezier path (>= 2).
    n_times : int
        Exposure instants ``T`` of the model during path estimation (>= 2).
    max_extent : float
        Control points are kept within ``+-max_extent`` views of the centre
        in ``x`` and ``y``, and ``p_z`` within ``path.z_box`` times that
        (``'alternating'``) or ``+-max_extent`` (``'joint'``); 0 means
        ``max(0.5, 0.35 (min(V, U) - 1))``.
    final_n_times : int
        Exposure instants of the final non-blind solve (>= 2).
    latent : LatentParams
        The salient-edge latent (``'alternating'``).
    path : PathFitParams
        The path fit and its schedule (``'alternating'``).
    rotation : RotationFitParams
        The rotation stage (``motion='6dof'``).
    joint : JointParams
        The joint Adam (``'joint'``).
    final : DeconvolutionParams or None
        The final non-blind solve of every colour channel with the path
        found (see :func:`~napari_lfdeblur.deconvolution.deconvolve`; by
        default its TV along the scene's disparity); None skips it and
        returns the blurred input as the light field.
    require_evidence : bool
        Restore only when the data give evidence of a significant blur
        (docs/blind.md, "What makes it robust"); otherwise return a light
        restoration (``light_restoration``) or the input with a zero path.
        False: always restore with the path estimated
        (the evidence is still reported in ``BlindResult.info``).
    light_restoration : float
        In [0, 1]. When the evidence test finds little blur (with
        ``require_evidence``) but two disjoint parts of the data, estimated
        apart, agree on the path, restore with the estimated path scaled by
        this factor about its mean instead of returning the input: a light
        restoration (docs/blind.md, "A light restoration"). 0.5 by default
        ('paper' preset: 0); 0: always return the input unchanged then.
    """

    method: str = "alternating"
    motion: str = "3dof"
    n_control_points: int = 4
    n_times: int = 32
    max_extent: float = 0.0
    final_n_times: int = 32
    latent: LatentParams = field(default_factory=LatentParams)
    path: PathFitParams = field(default_factory=PathFitParams)
    rotation: RotationFitParams = field(default_factory=RotationFitParams)
    joint: JointParams = field(default_factory=JointParams)
    final: DeconvolutionParams | None = field(default_factory=_default_final)
    require_evidence: bool = True
    light_restoration: float = 0.5

    _what = "blind"

    def __post_init__(self):
        if not isinstance(self.method, str):
            raise TypeError(f"BlindParams.method must be a string; got {self.method!r}")
        if self.method not in METHODS:
            raise ValueError(f"unknown blind method {self.method!r}: choose one of {', '.join(METHODS)}")
        if self.motion not in MOTIONS:
            raise ValueError(f"unknown motion {self.motion!r}: choose one of {', '.join(MOTIONS)}")
        if self.motion == "6dof" and self.method != "alternating":
            raise ValueError("motion='6dof' needs method='alternating'")
        check_fields(self, "BlindParams", ints={"n_control_points": 2, "n_times": 2, "final_n_times": 2},
                     nonneg=("max_extent", "light_restoration"), bools=("require_evidence",))
        if self.light_restoration > 1:
            raise ValueError(f"BlindParams.light_restoration must be in [0, 1]; got {self.light_restoration}")
        for name, cls in _NESTED.items():
            if not isinstance(getattr(self, name), cls):
                raise TypeError(f"BlindParams.{name} must be a {cls.__name__} (or, in replace() and from_dict(), "
                                f"a dict of its fields); got {type(getattr(self, name)).__name__}")
        if self.final is not None and not isinstance(self.final, DeconvolutionParams):
            raise TypeError(f"BlindParams.final must be a DeconvolutionParams or None; got {type(self.final).__name__}")

    def path_box(self, V: int, U: int) -> float:
        """The bound of the estimated control points for ``V x U`` views, views: ``max_extent``, or
        ``max(0.5, 0.35 (min(V, U) - 1))`` when it is 0."""
        return self.max_extent if self.max_extent > 0 else max(0.5, 0.35 * (min(V, U) - 1))

    def path_windows(self) -> int:
        """How many windows the path stage asks for on a view larger than ``path.region``:
        ``path.n_regions``, or 1 for the ``'6dof'`` motion and the ``'joint'`` method."""
        return self.path.n_regions if self.motion == "3dof" and self.method == "alternating" else 1

    @classmethod
    def preset(cls, name: str) -> "BlindParams":
        """The named preset: ``'default'`` (the alternating method) or ``'paper'`` (the published settings)."""
        try:
            return PRESETS[name]
        except (KeyError, TypeError):
            raise ValueError(f"unknown blind preset {name!r}: choose one of {', '.join(PRESETS)}") from None


#: named parameter sets
PRESETS = {
    "default": BlindParams(),
    "paper": BlindParams(
        method="joint", n_control_points=4, n_times=7, final_n_times=7,
        joint=JointParams(n_iter=1000, lr=1.0, lf_lr=0.04, prior_weight=8e-3, prior_decay=0.997, prior_floor=0.1,
                          eps=0.12, eps_decay=0.997, eps_min=0.04),
        final=DeconvolutionParams(method="tv", weight=0.004, n_iter=100, tol=0.0, couple_channels=False,
                                  isotropic=True, angular="views"),
        light_restoration=0.0,
    ),
}


@dataclass
class BlindResult:
    """The result of :func:`~napari_lfdeblur.blind.blind_deblur`.

    Attributes
    ----------
    lightfield : ndarray, float32, the blurred input's shape
        The sharp light field seen from the path's mean position.
    control_points : ndarray, float64, shape (n, 3), or (n, 6) with ``motion='6dof'``
        The camera path (docs/model.md units), zero-mean gauge for
        ``params.n_times`` (hence for any number of instants, up to
        sampling), time-canonicalised.
    loss_history : list of float
        The objective after every alternation (``'alternating'``: the path fit,
        >= 0) or iteration (``'joint'``) of the path estimation.
    params : BlindParams
    timings : dict
        Seconds spent per stage (``'path'``, ``'final'``, ``'total'``).
    info : dict
        Extra details (device used, restart scores, levels, the windows
        of a large view the path was estimated on: ``'windows'``, a list of
        ``(y0, x0, height, width)``, and ``'window'``, the first), and the
        verdict of the evidence test (docs/blind.md, "What makes it
        robust"): ``'blur_found'`` (bool), ``'evidence'`` (dict of its
        numbers), ``'message'`` (one line for people), ``'restoration'``
        (``'full'``: with the path estimated; ``'light'``: with that path
        scaled by ``params.light_restoration``; ``'none'``: the input
        returned) and, when no significant blur was found or the restoration
        did not reproduce the data, ``'rejected_path'`` (the path estimated;
        ``control_points`` is then the path restored with, zero when
        ``lightfield`` is the input). With ``params.final=None`` nothing is
        restored: ``'restoration'`` is ``'none'`` and ``control_points`` the
        path a final stage would have restored with; ``'brightest'`` (the
        input's centre view's 99.9th percentile); when the final stage ran, ``'final_weight'``, ``'noise_sigma'``
        (its noise estimate), ``'discrepancy'`` (with ``require_evidence``: the residual, noise variances/sample)."""

    lightfield: np.ndarray
    control_points: np.ndarray
    loss_history: list = field(default_factory=list)
    params: BlindParams = field(default_factory=BlindParams)
    timings: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)


@dataclass
class PathEstimate:
    """What a path stage (alternating or joint) returns to the solver.

    Attributes
    ----------
    control_points : ndarray, float64, shape (n_control_points, 3) or (n_control_points, 6)
    factors : list of int
        The pyramid's downsampling factors, coarse to fine.
    n_stages : int
        Path stages run (pyramid levels, plus the ``p_z`` stage).
    loss_history : list of float
    info : dict
    """

    control_points: np.ndarray
    factors: list
    n_stages: int
    loss_history: list = field(default_factory=list)
    info: dict = field(default_factory=dict)
