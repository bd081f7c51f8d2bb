"""Non-blind deconvolution of motion-blurred light fields: undo a *known* camera path.

:func:`deconvolve` (and its generator form :func:`iter_deconvolve`) offers:

* ``method='tv'``: regularised least squares with the exact blur operator
  of :mod:`napari_lfdeblur.blur` and a 4D total-variation prior over all
  four axes ``(v, u, y, x)``, on a colour light field by default the colour
  TV [6]_ (by default anisotropic: the sum of the four axes' norms, each
  over the channels); by default its angular differences are taken along
  the scene's disparity (estimated from the data), where a sharp Lambertian
  scene makes them vanish [7]_ (``angular='views'``: between the same pixel
  of neighbouring views),

      min_l  1/2 ||K_p l - f||^2 + weight * TV4(l),   l in [0, 1] (optional box),

  solved by FISTA [1]_ on the data term: each iteration takes one gradient
  step (one blur forward and one adjoint) and the proximal map of
  ``weight * TV4`` plus the box, computed by a few iterations of the
  gradient projection on its dual [2]_, warm-started from the previous
  iteration's dual field. The step ``1 / L`` uses an estimate of
  ``L = ||K||^2`` that is raised whenever a step shows more curvature
  (backtracking at no extra blur evaluation: ``K`` of the step is at hand);
  momentum is restarted when the objective rises or the step turns back
  [3]_. It stops when the objective decreases by less than ``tol`` times its
  value in one iteration. The default weight is ``NOISE_WEIGHT_FACTOR``
  (``COLOUR_WEIGHT_FACTOR`` for the colour TV) times the noise level
  estimated in the data (:func:`estimate_noise_sigma`), times
  ``ANISOTROPIC_WEIGHT_SCALE`` for the anisotropic TV.
* ``method='inplane'``: for an in-plane path (``p_z = 0``) and ``d_inf = 0``
  the exact angular solve of :func:`~napari_lfdeblur.special_cases.solve_inplane`
  (Tikhonov on the angular differences), one small matrix for all pixels:
  fast, but its fixed weight does not follow the noise and it has no
  spatial prior, so ``'tv'`` restores better, most of all on noisy data.
* ``method='auto'`` (kept for saved presets) is ``'tv'``, the default.

The paper's analytic special cases (refocusing, the textured plane, the
in-plane matrix) are in :mod:`napari_lfdeblur.special_cases`. See
``docs/deconvolution.md``.

References
----------
.. [1] A. Beck and M. Teboulle, "A fast iterative shrinkage-thresholding
       algorithm for linear inverse problems", SIAM J. Imaging Sci. 2, 2009.
.. [2] A. Beck and M. Teboulle, "Fast gradient-based algorithms for
       constrained total variation image denoising and deblurring problems",
       IEEE Trans. Image Process. 18, 2009.
.. [3] B. O'Donoghue and E. Candes, "Adaptive restart for accelerated
       gradient schemes", Found. Comput. Math. 15, 2015.
.. [4] S. Pyatykh, J. Hesser and L. Zheng, "Image noise level estimation
       by principal component analysis", IEEE Trans. Image Process. 22, 2013
       (the noise estimate).
.. [5] P. P. Srinivasan, R. Ng and R. Ramamoorthi, "Light Field Blind Motion
       Deblurring", CVPR 2017.
.. [6] X. Bresson and T. F. Chan, "Fast dual minimization of the vectorial
       total variation norm and applications to color image processing",
       Inverse Problems and Imaging 2, 2008.
.. [7] S. Wanner and B. Goldluecke, "Variational light field analysis for
       disparity estimation and super-resolution", IEEE Trans. Pattern Anal.
       Mach. Intell. 36, 2014 (regularisation along the disparity of the
       epipolar lines).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np
import torch

from ._lightfield import check_infinity_disparity, check_int, check_number, validate_lightfield, white_level
from ._params import JsonParams, check_bool
from .progress import Progress, run_to_completion
from .blur import BlurOperator, from_tensor, to_tensor, validate_frame
from .devices import select_device
from .path import has_rotation, validate_control_points, validate_n_times
from .special_cases import inplane_matrix, solve_inplane
from ._noise import estimate_noise_sigma
from ._disparity import scene_disparity
from ._oriented import OrientedDifferences
from ._tv_solvers import iter_fista_tv

__all__ = [
    "ANGULAR",
    "DeconvolutionParams",
    "METHODS",
    "deconvolve",
    "estimate_noise_sigma",
    "iter_deconvolve",
    "scene_disparity",
]

METHODS = ("auto", "tv", "inplane")
#: the angular differences of the TV (DeconvolutionParams.angular)
ANGULAR = ("disparity", "views")

#: default Tikhonov weight of ``'inplane'``
INPLANE_WEIGHT = 2e-3
#: ``'tv'``'s default weight is this factor times the noise level estimated in the data
NOISE_WEIGHT_FACTOR = 0.3
#: the factor of the colour TV (``couple_channels`` on more than one channel); near ``sqrt(3)`` times
#: NOISE_WEIGHT_FACTOR, as the colour TV of grey edges is ``sqrt(3)`` times smaller than three separate TVs
COLOUR_WEIGHT_FACTOR = 0.45
#: the anisotropic TV's rule is this times the isotropic one's: it sums the four axes' norms, which is up to
#: twice the norm of the 4-vector the isotropic TV takes (the two are equal on an edge along one axis)
ANISOTROPIC_WEIGHT_SCALE = 0.5
#: inner (dual) iterations of the warm-started TV proximal map per outer iteration (docs/deconvolution.md)
N_INNER = 3


# ------------------------------------------------------------ parameters


@dataclass(frozen=True)
class DeconvolutionParams(JsonParams):
    """Parameters of :func:`deconvolve`.

    Attributes
    ----------
    method : {'auto', 'tv', 'inplane'}
        ``'tv'`` (the default) for every path and ``d_inf``; ``'inplane'``
        only for ``p_z = 0`` and ``d_inf = 0``; ``'auto'`` is ``'tv'``.
    weight : float or None
        Regularisation weight >= 0. For ``'tv'`` it multiplies the 4D TV;
        None (the default) sets it from the data: ``NOISE_WEIGHT_FACTOR *
        sigma`` with ``sigma`` from :func:`estimate_noise_sigma` (the
        optimal TV weight of the least-squares objective grows with the
        noise level), ``COLOUR_WEIGHT_FACTOR * sigma`` for the colour TV,
        both times ``ANISOTROPIC_WEIGHT_SCALE`` for the anisotropic TV.
        For ``'inplane'`` it multiplies the squared angular gradient
        (Tikhonov; None: 2e-3), and 0 gives the exact (pseudo-)inverse.
    n_iter : int
        Maximum iterations of ``'tv'`` (each one blur forward and adjoint).
    tol : float
        ``'tv'`` stops at the first iteration whose objective ``F`` fell by
        less than ``tol * F`` (a rise never stops it); 0 runs ``n_iter``.
        In [0, 1).
    isotropic : bool
        Isotropic 4D TV (True: the norm of the four differences at each
        sample) or anisotropic (False, the default: the sum of their norms,
        which charges the angular differences in full also where the
        spatial gradient is large; with ``angular='disparity'`` that is
        what keeps the views consistent at edges and in texture).
    axis_weights : tuple of 4 floats
        Weights of the ``(v, u, y, x)`` differences in the TV.
    angular : {'disparity', 'views'}
        The angular differences of ``'tv'``. ``'views'`` compares the same
        pixel of neighbouring views (the plain 4D TV), which also charges
        the parallax of every textured point off the plane of zero
        disparity. ``'disparity'`` (the default) compares each sample with
        the neighbouring view where the scene's disparity moves it,
        ``l(v, u + 1, y, x + d) - l(v, u, y, x)`` (and likewise along ``v``
        and ``y``), with ``d(y, x)`` estimated from the blurred input
        (:func:`scene_disparity`; an in-plane blur keeps the views
        consistent there): on a Lambertian scene these differences vanish
        whatever the texture, so the TV removes what differs from view to
        view (noise, ringing) and keeps the texture. With
        ``isotropic=False`` it restores best (docs/deconvolution.md,
        *Angular differences*), at about twice the cost of ``'views'``.
    couple_channels : bool
        ``'tv'`` on a colour light field: one colour TV over all channels
        (the default; the norm per sample taken over the channels too, see
        :func:`~napari_lfdeblur.priors.tv4d`), solved for all channels at
        once, so that edges the channels share are kept and noise that they
        do not share is removed. False solves every channel on its own with
        its own TV, in about a third of the memory; it suits channels whose
        edges are unrelated.
    clip : bool
        Constrain the estimate to [0, 1] when the input lies in [0, 1]
        (integer input: to [0, its dtype's largest value] when it lies
        there). ``'inplane'``, a linear solve, clips its result instead.
    saturation : bool
        ``'tv'`` only. With ``clip``, samples of the input at 1 (integer
        input: at its dtype's largest value), the top of the range, are
        taken as clipped by the sensor: they say only that the light reached
        at least 1. The data term then asks the blur of the estimate to
        reach 1 there, not to equal it (a censored fit), the estimate may
        exceed 1 while it is solved (a blurred highlight needs a brighter
        source than its clipped plateau), and the result is clipped to
        [0, 1]. False fits every sample as it is, inside [0, 1] throughout.
        No effect on an input below 1 everywhere.
    """

    method: str = "tv"
    weight: float | None = None
    n_iter: int = 200
    tol: float = 1e-4
    isotropic: bool = False
    axis_weights: tuple = (1.0, 1.0, 1.0, 1.0)
    angular: str = "disparity"
    couple_channels: bool = True
    clip: bool = True
    saturation: bool = True

    _what = "deconvolution"

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"unknown deconvolution method {self.method!r}: choose one of {', '.join(METHODS)}")
        if self.weight is not None:
            w = check_number(self.weight, "weight")
            if w < 0:
                raise ValueError(f"the regularisation weight must be >= 0; got {w}")
            object.__setattr__(self, "weight", w)
        object.__setattr__(self, "n_iter", check_int(self.n_iter, "n_iter", 1))
        tol = check_number(self.tol, "tol")
        if not 0 <= tol < 1:  # the objective is >= 0: it never falls by all of itself
            raise ValueError(f"tol must be in [0, 1), a fraction of the objective; got {tol}")
        object.__setattr__(self, "tol", tol)
        try:  # numbers (a string's characters would each be read as one)
            aw = () if isinstance(self.axis_weights, (str, bytes)) else tuple(
                check_number(a, "axis_weights") for a in self.axis_weights)
        except (TypeError, ValueError):
            aw = ()
        if len(aw) != 4 or not all(math.isfinite(a) and a >= 0 for a in aw):
            raise ValueError(f"axis_weights must be 4 non-negative numbers (v, u, y, x); got {self.axis_weights!r}")
        object.__setattr__(self, "axis_weights", aw)
        if self.angular not in ANGULAR:
            raise ValueError(f"unknown angular differences {self.angular!r}: choose one of {', '.join(ANGULAR)}")
        for name in ("isotropic", "couple_channels", "clip", "saturation"):
            check_bool(self, name, name)

    def effective_weight(self, method: str, sigma: float | None = None, n_channels: int = 1) -> float:
        """The weight used by ``method``.

        Parameters
        ----------
        method : {'tv', 'inplane', 'auto'}
        sigma : float, optional
            The noise level of the data (:func:`estimate_noise_sigma`); needed
            by ``'tv'`` when ``weight`` is None.
        n_channels : int, default 1
            Channels of the light field: the colour TV's rule applies to
            more than one (on one channel it is the plain TV).

        Returns
        -------
        float
            ``weight`` when set; otherwise ``INPLANE_WEIGHT`` for ``'inplane'``
            and, for ``'tv'`` (and ``'auto'``), ``COLOUR_WEIGHT_FACTOR * sigma``
            with ``couple_channels`` on more than one channel, else
            ``NOISE_WEIGHT_FACTOR * sigma``; times ``ANISOTROPIC_WEIGHT_SCALE``
            for the anisotropic TV.
        """
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}: choose one of {', '.join(METHODS)}")
        if self.weight is not None:
            return self.weight
        if method == "inplane":
            return INPLANE_WEIGHT
        if sigma is None:
            raise ValueError("the noise rule of the 'tv' weight needs sigma (see estimate_noise_sigma)")
        if not check_number(sigma, "sigma") >= 0:
            raise ValueError(f"sigma must be >= 0; got {sigma}")
        colour = self.couple_channels and n_channels > 1
        scale = 1.0 if self.isotropic else ANISOTROPIC_WEIGHT_SCALE
        return scale * (COLOUR_WEIGHT_FACTOR if colour else NOISE_WEIGHT_FACTOR) * float(sigma)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["axis_weights"] = list(self.axis_weights)
        return d


def _make_params(params, overrides) -> DeconvolutionParams:
    if params is None:
        params = DeconvolutionParams()
    elif isinstance(params, dict):
        params = DeconvolutionParams.from_dict(params)
    elif not isinstance(params, DeconvolutionParams):
        raise TypeError(f"params must be a DeconvolutionParams or a dict; got {type(params).__name__}")
    known = {f.name for f in fields(DeconvolutionParams)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise TypeError(f"unexpected keyword argument(s): {', '.join(unknown)}")
    return replace(params, **overrides) if overrides else params


# ----------------------------------------------------------------- TV


def _channel_groups(params: DeconvolutionParams, C: int) -> list[slice]:
    """The channels solved together: all at once (``couple_channels``), else one by one."""
    return [slice(0, C)] if params.couple_channels else [slice(c, c + 1) for c in range(C)]


def _clipped(params: DeconvolutionParams, f: torch.Tensor, white: float) -> bool:
    """Whether the estimate is held to ``[0, white]``: ``params.clip`` and the input ``f`` lies there."""
    return params.clip and float(f.min()) >= 0.0 and float(f.max()) <= white


def _iter_tv(op: BlurOperator, f: torch.Tensor, x0: torch.Tensor, params: DeconvolutionParams, weight, sigma,
             out: np.ndarray, oriented=None, white: float = 1.0):
    """FISTA with a warm-started TV prox for ``1/2 ||K x - f||^2 + w TV4(x)`` (+ box); yields Progress.

    Without ``couple_channels`` the channels are independent, so they are
    solved one after the other: the solver's buffers then hold one channel,
    not all. ``op`` is the operator of one group of :func:`_channel_groups`.
    ``f``, ``x0``: (V, U, Y, X, C); each group's result is written into
    ``out`` (the input's numpy shape), which is returned. ``oriented``: the
    angular differences along the disparity (None: along the view axes).
    ``white``: the top of the input's range (:func:`~napari_lfdeblur._lightfield.white_level`).
    """
    box, saturated = None, False
    if _clipped(params, f, white):
        saturated = params.saturation and float(f.max()) >= white
        box = (0.0, None) if saturated else (0.0, white)  # saturated: clipped to [0, white] once solved
    C = f.shape[-1]
    view = out if out.ndim == 5 else out[..., None]
    groups = _channel_groups(params, C)
    for g, cs in enumerate(groups):
        def record(it, x, info, cs=cs, g=g):
            def estimate():
                full = out.copy()
                part = from_tensor(x, 5)
                (full if full.ndim == 5 else full[..., None])[..., cs] = part.clip(0.0, white) if saturated else part
                return full

            return Progress(stage="tv", iteration=g * params.n_iter + it, n_iterations=len(groups) * params.n_iter,
                            loss=info["objective"], estimate=estimate,
                            info={**info, "weight": weight, "sigma": sigma, "channel": cs.start, "n_channels": C})

        fc = f[..., cs].contiguous()
        x0c = fc if x0 is f else x0[..., cs].contiguous()  # the start is the data unless given
        x = yield from iter_fista_tv(op, fc, x0c, weight=weight, n_iter=params.n_iter, tol=params.tol,
                                     isotropic=params.isotropic, axis_weights=params.axis_weights, box=box,
                                     n_inner=N_INNER, record=record, coupled=params.couple_channels,
                                     ceiling=white if saturated else None, oriented=oriented)
        view[..., cs] = from_tensor(x.clamp_(0.0, white) if saturated else x, 5)
        del x
    return out


# ------------------------------------------------------------ front end


def _validate(blurred, control_points, n_times, infinity_disparity, init):
    arr = validate_lightfield(blurred, "blurred light field")
    if isinstance(control_points, torch.Tensor):
        control_points = control_points.detach().cpu().numpy()
    cp = validate_control_points(control_points)
    n_times = validate_n_times(n_times)
    d_inf = check_number(infinity_disparity, "infinity_disparity")
    if init is not None:
        init = validate_lightfield(init, "initial light field")
        if init.shape != arr.shape:
            raise ValueError(
                f"the initial light field has shape {init.shape} but the blurred one has shape {arr.shape}"
            )
    return arr, cp, n_times, d_inf, init


def _choose_method(method: str, cp: np.ndarray, d_inf: float) -> str:
    in_plane = d_inf == 0.0 and bool(np.all(cp[:, 2] == 0)) and not has_rotation(cp)
    if method == "auto":
        return "tv"
    if method == "inplane" and not in_plane:
        raise ValueError(
            "method 'inplane' needs an in-plane path (p_z = 0 and no rotation at every control point) and "
            f"infinity_disparity = 0; got max |p_z| = {np.abs(cp[:, 2]).max():g}, d_inf = {d_inf:g}"
            f"{', a rotation' if has_rotation(cp) else ''}. Use method 'tv' (command line: --method tv)."
        )
    return method


def iter_deconvolve(
    blurred,
    control_points,
    *,
    n_times: int = 32,
    infinity_disparity: float = 0.0,
    params: DeconvolutionParams | dict | None = None,
    device="auto",
    init=None,
    frame=None,
    **overrides,
):
    """Deconvolve a light field blurred by a known path, as a generator.

    Takes the arguments of :func:`deconvolve`. Yields
    :class:`~napari_lfdeblur.progress.Progress` records and *returns* the
    result (``StopIteration.value``); closing the generator stops the work at
    the next ``yield``. Arguments are checked when the generator is created.

    Returns
    -------
    ndarray, float32, the input's shape
    """
    arr, cp, n_times, d_inf, init = _validate(blurred, control_points, n_times, infinity_disparity, init)
    p = _make_params(params, overrides)
    method = _choose_method(p.method, cp, d_inf)
    dev = select_device(device)
    frame = validate_frame(frame, arr.shape)
    check_infinity_disparity(d_inf, arr.shape if frame is None else (*arr.shape[:2], *frame[2:]))  # whole views
    if method == "tv" and p.weight is None and min(arr.shape[2:4]) < 2:
        raise ValueError(f"views of {arr.shape[2]} x {arr.shape[3]} px are too small to estimate the noise the "
                         "default weight follows (2 x 2 at least): pass weight=")
    return _run(arr, cp, n_times, d_inf, p, method, dev, init, frame)


def _run(arr, cp, n_times, d_inf, p, method, dev, init, frame=None):
    sigma = estimate_noise_sigma(arr) if method == "tv" and p.weight is None else None  # for the weight rule
    weight = p.effective_weight(method, sigma, arr.shape[4] if arr.ndim == 5 else 1)
    f, white = to_tensor(arr, device=dev), white_level(arr.dtype)
    if method == "inplane":
        M = inplane_matrix(cp, arr.shape[0], arr.shape[1], n_times=n_times)
        with torch.no_grad():
            x = solve_inplane(f, M, weight)
            if _clipped(p, f, white):
                x.clamp_(0.0, white)
        out = from_tensor(x, arr.ndim)
        yield Progress(stage="inplane", iteration=1, n_iterations=1, info={"weight": weight, "method": method},
                       estimate=out.copy)
        return out
    width = _channel_groups(p, f.shape[-1])[0]
    op = BlurOperator((*f.shape[:4], width.stop - width.start), cp, n_times=n_times, infinity_disparity=d_inf,
                      device=dev, frame=frame)
    x0 = f if init is None else to_tensor(init, device=dev)
    oriented = None
    if p.angular == "disparity" and max(f.shape[:2]) > 1:
        oriented = OrientedDifferences(torch.as_tensor(scene_disparity(f, d_inf), device=dev))
    # the channels not solved yet show the input in the records' estimates
    return (yield from _iter_tv(op, f, x0, p, weight, sigma, np.array(arr, dtype=np.float32), oriented, white))


def deconvolve(
    blurred,
    control_points,
    *,
    n_times: int = 32,
    infinity_disparity: float = 0.0,
    params: DeconvolutionParams | dict | None = None,
    device="auto",
    init=None,
    frame=None,
    callback=None,
    **overrides,
) -> np.ndarray:
    """Undo the motion blur of a known camera path.

    Parameters
    ----------
    blurred : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        The blurred light field (docs/model.md layout), computed in float32.
    control_points : array_like, shape (n, 3) or (n, 6)
        Bezier control points of the path: translation in view units, then
        optionally a rotation in radians (docs/model.md).
    n_times : int, default 32
        Exposure instants ``T`` of the blur model.
    infinity_disparity : float, default 0.0
        ``d_inf`` in px/view, within the bound of :func:`~napari_lfdeblur.blur.simulate_blur`.
    params : DeconvolutionParams or dict, optional
        Solver parameters; single fields may also be given as keywords
        (``method=``, ``weight=``, ``n_iter=``, ``tol=``, ``isotropic=``,
        ``axis_weights=``, ``angular=``, ``couple_channels=``, ``clip=``,
        ``saturation=``) and
        override it.
    device : {'auto', 'cpu', 'cuda'}, default 'auto'
    init : ndarray, optional
        Initial estimate for ``'tv'`` (default: the blurred input).
    frame : tuple of 4 int, optional
        ``(y0, x0, Y_full, X_full)`` when ``blurred`` is the tile at ``(y0, x0)``
        of a larger light field (for tiled processing): ``p_z``'s shifts are
        then those of the full frame (see :class:`~napari_lfdeblur.blur.BlurOperator`).
    callback : callable, optional
        Called with each :class:`~napari_lfdeblur.progress.Progress` record.

    Returns
    -------
    ndarray, float32, the shape of ``blurred``

    Raises
    ------
    ValueError
        On a malformed light field or path, mismatched shapes, NaN, an
        infinity disparity beyond the views' size, a negative weight, an
        unknown method or kind of angular differences, ``'inplane'`` for
        a path that is not in-plane, or a ``params`` dict with keys that are
        not fields.
    TypeError
        On an unknown keyword argument, or ``params`` of another type.

    Examples
    --------
    >>> import numpy as np
    >>> from napari_lfdeblur import simulate_blur, linear_path
    >>> lf = np.random.default_rng(0).random((5, 5, 8, 8)).astype(np.float32)
    >>> cp = linear_path(1.5)
    >>> out = deconvolve(simulate_blur(lf, cp), cp, weight=0.0)  # exact in-plane inverse
    >>> bool(np.abs(out - lf).max() < 1e-3)
    True
    """
    gen = iter_deconvolve(
        blurred, control_points, n_times=n_times, infinity_disparity=infinity_disparity,
        params=params, device=device, init=init, frame=frame, **overrides,
    )
    return run_to_completion(gen, callback)
