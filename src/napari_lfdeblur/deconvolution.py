"""Non-blind deconvolution of motion-blurred light fields: undo a *known* camera path.

:func:`deconvolve` (and its generator form :func:`iter_deconvolve`) offers:

* ``method='tv'``: regularised least squares with the exact blur operator
  of :mod:`napari_lfdeblur.blur` and a 4D total-variation prior over all
  four axes ``(v, u, y, x)``,

      min_l  1/2 ||K_p l - f||^2 + weight * TV4(l),

  solved by the primal-dual method of Condat and Vu (gradient steps on the
  data term, dual projections for TV), with an optional box constraint to
  ``[0, 1]`` and early stopping on the relative change of the iterate.
* ``method='inplane'``: for an in-plane path (``p_z = 0``) and ``d_inf = 0``
  the exact angular solve of :func:`~napari_lfdeblur.special_cases.solve_inplane`
  (Tikhonov on the angular differences), one small matrix for all pixels.
* ``method='auto'`` picks ``'inplane'`` when it applies and ``'tv'`` otherwise.

The paper's analytic special cases (refocusing, the textured plane, the
in-plane matrix) are in :mod:`napari_lfdeblur.special_cases`.

References
----------
.. [1] L. Condat, "A primal-dual splitting method for convex optimization
       involving Lipschitzian, proximable and linear composite terms",
       J. Optim. Theory Appl. 158, 2013.
.. [2] B. C. Vu, "A splitting algorithm for dual monotone inclusions
       involving cocoercive operators", Adv. Comput. Math. 38, 2013.
.. [3] P. P. Srinivasan, R. Ng and R. Ramamoorthi, "Light Field Blind Motion
       Deblurring", CVPR 2017.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np
import torch

from ._lightfield import check_int, check_number, validate_lightfield
from ._params import JsonParams
from .progress import Progress, run_to_completion
from .blur import BlurOperator, from_tensor, to_tensor, validate_frame
from .devices import select_device
from .path import validate_control_points, validate_n_times
from .priors import divergence4d, gradient_norm_bound, project_tv_dual
from .special_cases import inplane_matrix, solve_inplane

__all__ = [
    "DeconvolutionParams",
    "METHODS",
    "deconvolve",
    "iter_deconvolve",
]

METHODS = ("auto", "tv", "inplane")

#: default regularisation weight of each method
DEFAULT_WEIGHTS = {"tv": 2e-3, "inplane": 2e-3}


# ------------------------------------------------------------ parameters


@dataclass(frozen=True)
class DeconvolutionParams(JsonParams):
    """Parameters of :func:`deconvolve`.

    Attributes
    ----------
    method : {'auto', 'tv', 'inplane'}
        ``'auto'`` uses ``'inplane'`` when ``p_z = 0`` and ``d_inf = 0``.
    weight : float or None
        Regularisation weight >= 0 (None: the method's default, 2e-3). For
        ``'tv'`` it multiplies the 4D TV; for ``'inplane'`` the squared
        angular gradient (Tikhonov). 0 gives the exact (pseudo-)inverse
        for ``'inplane'``.
    n_iter : int
        Maximum iterations of ``'tv'``.
    tol : float
        ``'tv'`` stops when ``||l_k - l_{k-1}|| / ||l_k|| < tol``.
    isotropic : bool
        Isotropic (True) or anisotropic 4D TV.
    axis_weights : tuple of 4 floats
        Weights of the ``(v, u, y, x)`` differences in the TV.
    clip : bool
        Constrain the estimate to [0, 1] when the input lies in [0, 1].
    """

    method: str = "auto"
    weight: float | None = None
    n_iter: int = 200
    tol: float = 1e-4
    isotropic: bool = True
    axis_weights: tuple = (1.0, 1.0, 1.0, 1.0)
    clip: bool = True

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
        if tol < 0:
            raise ValueError(f"tol must be >= 0; got {tol}")
        object.__setattr__(self, "tol", tol)
        try:
            aw = tuple(float(a) for a in self.axis_weights)
        except (TypeError, ValueError):
            aw = ()
        if len(aw) != 4 or not all(math.isfinite(a) and a >= 0 for a in aw):
            raise ValueError(f"axis_weights must be 4 non-negative numbers (v, u, y, x); got {self.axis_weights!r}")
        object.__setattr__(self, "axis_weights", aw)
        object.__setattr__(self, "isotropic", bool(self.isotropic))
        object.__setattr__(self, "clip", bool(self.clip))

    def effective_weight(self, method: str) -> float:
        """The weight used by ``method`` (the default when ``weight`` is None)."""
        return DEFAULT_WEIGHTS[method] if self.weight is None else self.weight

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


def _add_gradient_(Y, x, alpha: float, axis_weights):
    """``Y[a] += alpha * w_a * D_a x`` in place, without a temporary per axis."""
    for axis in range(4):
        n = x.shape[axis]
        if n < 2 or axis_weights[axis] == 0:
            continue
        hi, lo = x.narrow(axis, 1, n - 1), x.narrow(axis, 0, n - 1)
        y = Y[axis].narrow(axis, 0, n - 1)
        y.add_(hi, alpha=alpha * axis_weights[axis]).sub_(lo, alpha=alpha * axis_weights[axis])


def _tv_value(x, isotropic, axis_weights) -> float:
    """``TV4(x)`` without materialising the four gradient components at once."""
    acc = torch.zeros_like(x) if isotropic else None
    total = 0.0
    for axis in range(4):
        n = x.shape[axis]
        if n < 2 or axis_weights[axis] == 0:
            continue
        diff = x.narrow(axis, 1, n - 1) - x.narrow(axis, 0, n - 1)
        if axis_weights[axis] != 1.0:
            diff.mul_(axis_weights[axis])
        if isotropic:
            acc.narrow(axis, 0, n - 1).addcmul_(diff, diff)
        else:
            total += float(diff.abs().sum())
    return float(acc.sqrt_().sum()) if isotropic else total


@torch.no_grad()  # entered at each resume and left at each yield: never leaks to the caller
def _iter_tv(op: BlurOperator, f: torch.Tensor, x0: torch.Tensor, params: DeconvolutionParams, weight, ndim):
    """Condat-Vu primal-dual iterations for ``1/2 ||K x - f||^2 + w TV4(x)`` (+ box)."""
    aw = params.axis_weights
    lo, hi = None, None
    if params.clip and float(f.min()) >= 0.0 and float(f.max()) <= 1.0:
        lo, hi = 0.0, 1.0
    # ||K||^2 <= ||K||_1 ||K||_inf; rows of K are averages of interpolations (sum 1, >= 0)
    lip = max(1.0, float(op.adjoint(torch.ones_like(f)).max()))
    knorm2 = gradient_norm_bound(aw)
    tau = 1.3 / lip  # measured: a little faster than 1 / lip, still within the Condat-Vu condition
    sigma = 0.99 * (1.0 / tau - lip / 2.0) / max(knorm2, 1e-12)
    x = x0.clone()
    if lo is not None:
        x.clamp_(lo, hi)
    dual = [torch.zeros_like(f) for _ in range(4)] if weight > 0 else None
    n = params.n_iter
    for it in range(1, n + 1):
        resid = op.forward(x) - f
        loss = 0.5 * float((resid * resid).sum())
        grad = op.adjoint(resid)
        del resid
        if dual is not None:
            loss += weight * _tv_value(x, params.isotropic, aw)
            grad.sub_(divergence4d(dual, aw))
        x_new = x - tau * grad
        del grad
        if lo is not None:
            x_new.clamp_(lo, hi)
        change = float(torch.linalg.vector_norm(x_new - x)) / max(float(torch.linalg.vector_norm(x_new)), 1e-12)
        if dual is not None:
            # dual ascent at the extrapolated point 2 x_new - x
            _add_gradient_(dual, x_new, 2.0 * sigma, aw)
            _add_gradient_(dual, x, -sigma, aw)
            project_tv_dual(dual, weight, params.isotropic)
        x = x_new
        done = change < params.tol and it >= 3
        yield Progress(
            stage="tv",
            iteration=it,
            n_iterations=n,
            loss=loss,
            estimate=lambda x=x: from_tensor(x, ndim).copy(),
            info={"relative_change": change, "weight": weight, "tau": tau, "sigma": sigma},
        )
        if done:
            break
    return x


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
    in_plane = d_inf == 0.0 and bool(np.all(cp[:, 2] == 0))
    if method == "auto":
        return "inplane" if in_plane else "tv"
    if method == "inplane" and not in_plane:
        raise ValueError(
            "method 'inplane' needs an in-plane path (p_z = 0 at every control point) and "
            f"infinity_disparity = 0; got max |p_z| = {np.abs(cp[:, 2]).max():g}, d_inf = {d_inf:g}. "
            "Use method='tv' or 'auto'."
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
    return _run(arr, cp, n_times, d_inf, p, method, dev, init, frame)


def _run(arr, cp, n_times, d_inf, p, method, dev, init, frame=None):
    weight = p.effective_weight(method)
    f = to_tensor(arr, device=dev)
    if method == "inplane":
        M = inplane_matrix(cp, arr.shape[0], arr.shape[1], n_times=n_times)
        with torch.no_grad():
            x = solve_inplane(f, M, weight)
        out = from_tensor(x, arr.ndim)
        yield Progress(stage="inplane", iteration=1, n_iterations=1, info={"weight": weight, "method": method},
                       estimate=out.copy)
        return out
    op = BlurOperator(f.shape, cp, n_times=n_times, infinity_disparity=d_inf, device=dev, frame=frame)
    x0 = f if init is None else to_tensor(init, device=dev)
    x = yield from _iter_tv(op, f, x0, p, weight, arr.ndim)
    return from_tensor(x, arr.ndim)


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
    control_points : array_like, shape (n, 3)
        Bezier control points of the path (view units; docs/model.md).
    n_times : int, default 32
        Exposure instants ``T`` of the blur model.
    infinity_disparity : float, default 0.0
        ``d_inf`` in px/view.
    params : DeconvolutionParams or dict, optional
        Solver parameters; single fields may also be given as keywords
        (``method=``, ``weight=``, ``n_iter=``, ``tol=``, ``isotropic=``,
        ``axis_weights=``, ``clip=``) and override it.
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
        On a malformed light field or path, mismatched shapes, NaN, a
        negative weight, an unknown method, or ``'inplane'`` for a path that
        is not in-plane.

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
