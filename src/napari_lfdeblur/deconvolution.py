"""Non-blind deconvolution of motion-blurred light fields, and the paper's analytic special cases.

- :func:`deconvolve` / :func:`iter_deconvolve`: undo a *known* camera path.

  * ``method='tv'``: regularised least squares with the exact blur operator
    of :mod:`napari_lfdeblur.blur` and a 4D total-variation prior over all
    four axes ``(v, u, y, x)``,

        min_l  1/2 ||K_p l - f||^2 + weight * TV4(l),

    solved by the primal-dual method of Condat and Vu (gradient steps on the
    data term, dual projections for TV), with an optional box constraint to
    ``[0, 1]`` and early stopping on the relative change of the iterate.
    Measured on a 7x7x40x40 scene: after 20, 32 and 50 iterations it is 2 to
    8 times closer to the converged solution than FISTA on a Huber-smoothed
    TV (eps 0.01 or 0.003) after as many blur evaluations.
  * ``method='inplane'``: for an in-plane path (``p_z = 0``) and
    ``d_inf = 0`` every pixel ``(y, x)`` sees the same linear map
    ``M = mean_k B_k kron A_k`` on its ``V U`` angular samples, with the
    replicate boundary exact (no circular FFT over 9 samples). The solve
    ``(M^T M + weight D^T D) l = M^T f`` (``D`` the angular finite
    differences) is one small matrix applied to all pixels at once.
  * ``method='auto'`` picks ``'inplane'`` when it applies and ``'tv'`` otherwise.

- :func:`refocus`: shift-and-sum (a sheared integral projection, i.e. a
  slice of the 4D spectrum) with sub-pixel shifts.
- :func:`recover_plane_texture`: blind recovery of a fronto-parallel
  textured plane under out-of-plane motion (paper, Sec. 3.2.2).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np
import torch

from ._params import JsonParams
from .progress import Progress, run_to_completion
from .blur import BlurOperator, from_tensor, interpolation_matrices, to_tensor, validate_frame, validate_lightfield
from .devices import select_device
from .path import bezier_positions, validate_control_points, validate_n_times
from .priors import divergence4d, gradient_norm_bound, project_tv_dual

__all__ = [
    "DeconvolutionParams",
    "METHODS",
    "deconvolve",
    "iter_deconvolve",
    "inplane_matrix",
    "inplane_psf",
    "refocus",
    "PlaneTextureResult",
    "recover_plane_texture",
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
    preview_every : int
        Send a light-field preview with every ``preview_every``-th progress
        record (0: never).
    """

    method: str = "auto"
    weight: float | None = None
    n_iter: int = 200
    tol: float = 1e-4
    isotropic: bool = True
    axis_weights: tuple = (1.0, 1.0, 1.0, 1.0)
    clip: bool = True
    preview_every: int = 0

    _what = "deconvolution"

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"unknown deconvolution method {self.method!r}: choose one of {', '.join(METHODS)}")
        if self.weight is not None:
            w = _number(self.weight, "weight")
            if w < 0:
                raise ValueError(f"the regularisation weight must be >= 0; got {w}")
            object.__setattr__(self, "weight", w)
        if isinstance(self.n_iter, bool) or not isinstance(self.n_iter, (int, np.integer)) or self.n_iter < 1:
            raise ValueError(f"n_iter must be an integer >= 1; got {self.n_iter!r}")
        object.__setattr__(self, "n_iter", int(self.n_iter))
        tol = _number(self.tol, "tol")
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
        if isinstance(self.preview_every, bool) or not isinstance(self.preview_every, (int, np.integer)) or self.preview_every < 0:
            raise ValueError(f"preview_every must be an integer >= 0; got {self.preview_every!r}")
        object.__setattr__(self, "isotropic", bool(self.isotropic))
        object.__setattr__(self, "clip", bool(self.clip))

    def effective_weight(self, method: str) -> float:
        """The weight used by ``method`` (the default when ``weight`` is None)."""
        return DEFAULT_WEIGHTS[method] if self.weight is None else self.weight

    def to_dict(self) -> dict:
        d = asdict(self)
        d["axis_weights"] = list(self.axis_weights)
        return d


def _number(value, name: str) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number; got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number; got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite; got {value!r}")
    return v


def _make_params(params, overrides) -> DeconvolutionParams:
    if params is None:
        params = DeconvolutionParams()
    elif isinstance(params, dict):
        params = DeconvolutionParams.from_dict(params)
    elif not isinstance(params, DeconvolutionParams):
        raise ValueError(f"params must be a DeconvolutionParams or a dict; got {type(params).__name__}")
    known = {f.name for f in fields(DeconvolutionParams)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise TypeError(f"unexpected keyword argument(s): {', '.join(unknown)}")
    return replace(params, **overrides) if overrides else params


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
    if np.any(cp[:, 2] != 0):
        raise ValueError("inplane_matrix needs an in-plane path (p_z = 0 at every control point)")
    pos = torch.as_tensor(bezier_positions(cp, validate_n_times(n_times)), dtype=torch.float64)
    A, B, _, _ = interpolation_matrices(pos, (V, U, 1, 1))
    A, B = A[:, 0].numpy(), B[:, 0].numpy()
    return np.mean([np.kron(B[k], A[k]) for k in range(len(A))], axis=0)


def _inplane_solve(f: torch.Tensor, M: np.ndarray, weight: float) -> torch.Tensor:
    """Solve ``(M^T M + w D^T D) l = M^T f`` for every pixel of ``f`` (V, U, Y, X, C)."""
    V, U = f.shape[:2]
    if weight == 0.0:
        K = np.linalg.pinv(M)
    else:
        D = _angular_difference_matrix(V, U)
        K = np.linalg.solve(M.T @ M + weight * (D.T @ D), M.T)
    Kt = torch.as_tensor(K, dtype=f.dtype, device=f.device)
    flat = f.reshape(V * U, -1)
    return (Kt @ flat).reshape(f.shape)


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
        preview = None
        if params.preview_every and it % params.preview_every == 0:
            preview = from_tensor(x, ndim)
        done = change < params.tol and it >= 3
        yield Progress(
            stage="tv",
            iteration=it,
            n_iterations=n,
            loss=loss,
            preview=preview,
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
    d_inf = _number(infinity_disparity, "infinity_disparity")
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
            x = _inplane_solve(f, M, weight)
        out = from_tensor(x, arr.ndim)
        yield Progress(stage="inplane", iteration=1, n_iterations=1, info={"weight": weight, "method": method},
                       preview=out if p.preview_every else None)
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
        The blurred light field (MODEL.md layout), computed in float32.
    control_points : array_like, shape (n, 3)
        Bezier control points of the path (MODEL.md units).
    n_times : int, default 32
        Exposure instants ``T`` of the blur model.
    infinity_disparity : float, default 0.0
        ``d_inf`` in px/view.
    params : DeconvolutionParams or dict, optional
        Solver parameters; single fields may also be given as keywords
        (``method=``, ``weight=``, ``n_iter=``, ``tol=``, ``isotropic=``,
        ``axis_weights=``, ``clip=``, ``preview_every=``) and override it.
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


# ---------------------------------------------------------------- refocus


def _lerp_shift(img: np.ndarray, shift: float, axis: int) -> np.ndarray:
    """``out[i] = img[i + shift]`` along ``axis``, bilinear, replicate boundary."""
    n = img.shape[axis]
    c = np.clip(np.arange(n, dtype=np.float64) + shift, 0.0, n - 1.0)
    i0 = np.clip(np.floor(c).astype(np.int64), 0, max(n - 2, 0))
    i1 = np.minimum(i0 + 1, n - 1)
    w = c - i0
    shape = [1] * img.ndim
    shape[axis] = n
    w = w.reshape(shape)
    return np.take(img, i0, axis=axis) * (1.0 - w) + np.take(img, i1, axis=axis) * w


def refocus(lf, disparity: float) -> np.ndarray:
    """Shift-and-sum refocusing with sub-pixel shifts.

    Averages ``lf[v, u](y + d v_c, x + d u_c)`` over all views, with
    ``u_c = u - (U - 1) / 2`` and ``v_c = v - (V - 1) / 2``. By MODEL.md's
    sign convention (a point at ``x`` in view ``u`` is at ``x + d`` in view
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
    d = _number(disparity, "disparity")
    V, U = arr.shape[:2]
    acc = np.zeros(arr.shape[2:], dtype=np.float64)
    for v in range(V):
        for u in range(U):
            view = arr[v, u]
            shifted = _lerp_shift(view, d * (v - (V - 1) / 2.0), 0) if d else view
            acc += _lerp_shift(shifted, d * (u - (U - 1) / 2.0), 1) if d else shifted
    return (acc / (V * U)).astype(np.float32)


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
        Out-of-plane positions ``p_z`` (MODEL.md units) of the profile's samples.
    dwell : ndarray, float64, shape (S,)
        Estimated dwell-time profile: the fraction of the exposure spent at
        each ``dwell_p`` (sums to 1).
    kernel : ndarray, float32, shape (K, K)
        The 2D blur kernel of the refocused slice implied by the dwell
        profile (sums to 1, centred).
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


def _slice_transfer(p, w, d, R, V, U, wy, wx):
    """``K^(Ω) = sum_j w_j mean_v e^{i Ω_y s_j v_c} mean_u e^{i Ω_x s_j u_c}``, ``s_j = d^2 p_j / R``."""
    uc = np.arange(U) - (U - 1) / 2.0
    vc = np.arange(V) - (V - 1) / 2.0
    H = np.zeros(np.broadcast_shapes(wy.shape, wx.shape))
    for pj, wj in zip(p, w):
        if wj <= 0:
            continue
        s = d * d * pj / R
        hx = np.cos(wx[..., None] * s * uc).mean(-1)
        hy = np.cos(wy[..., None] * s * vc).mean(-1)
        H = H + wj * hy * hx
    return H


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

    The paper's Sec. 3.2.2, derived for this project's model (MODEL.md). A
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
    texture. ζ is found automatically:

    1. refocus at the disparities ``d / (1 + d p_j / R)`` of a grid of
       ``p_j``; the high-frequency magnitude of each slice measures how long
       the camera dwelt at ``p_j`` (comparing slice magnitudes gives the
       dwell-time profile, moved to zero mean as in MODEL.md's gauge);
    2. the dwell profile gives the slice's exact transfer function and
       kernel; ζ is the least-squares fit of ``1 / (1 + ζ |Ω|)`` to it.

    The plane's angular samples leave the aperture at ``|x - c| > d (U-1)/2``
    px from the image centre, so the recovery is best within
    ``valid_radius`` of the centre.

    Parameters
    ----------
    blurred : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        A light field of a textured fronto-parallel plane, blurred by an
        out-of-plane motion (``d_inf = 0``).
    disparity : float, optional
        The plane's disparity in px/view (non-zero). By default the
        disparity of the sharpest refocused slice, then moved to the mean
        of the estimated dwell profile.
    p_range : float, default 3.0
        The dwell profile is estimated on ``p_z`` in ``[-p_range, p_range]``.
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
    p_range = _number(p_range, "p_range")
    if p_range <= 0:
        raise ValueError(f"p_range must be > 0; got {p_range}")
    if isinstance(n_slices, bool) or not isinstance(n_slices, (int, np.integer)) or n_slices < 3:
        raise ValueError(f"n_slices must be an integer >= 3; got {n_slices!r}")
    if max(U, V) < 2:
        raise ValueError("recover_plane_texture needs at least 2 views along u or v")
    yy, xx = np.mgrid[0:Y, 0:X]
    rr = np.hypot(yy - (Y - 1) / 2.0, xx - (X - 1) / 2.0)

    if disparity is None:
        # the sharpest refocused slice over a coarse disparity sweep
        cand = np.linspace(-4.0, 4.0, 81)
        cand = cand[np.abs(cand) > 0.05]
        mask = rr <= 0.35 * min(X, Y)
        scores = [_highpass_energy(refocus(arr, c), mask) for c in cand]
        d0 = float(cand[int(np.argmax(scores))])
    else:
        d0 = _number(disparity, "disparity")
        if d0 == 0:
            raise ValueError("the plane's disparity must be non-zero: a plane at infinity shows no out-of-plane blur")

    def profile(d):
        radius = abs(d) * (max(U, V) - 1) / 2.0
        mask = rr <= max(radius, 3.0)
        p = np.linspace(-p_range, p_range, n_slices)
        ok = np.abs(d * p / R) < 0.9
        p = p[ok]
        m = np.array([_highpass_energy(refocus(arr, d / (1.0 + d * pj / R)), mask) for pj in p])
        w = np.clip(m - m.min(), 0.0, None)
        if w.sum() <= 0:
            w = np.ones_like(m)
        return p, w / w.sum(), radius

    p, w, radius = profile(d0)
    p_mean = float(np.sum(p * w))
    d = d0 / (1.0 + d0 * p_mean / R)  # disparity at the mean position: zero-mean gauge
    if disparity is None:
        p, w, radius = profile(d)
    else:
        # the given disparity defines the gauge; report the profile relative to it
        d = d0

    refocused = refocus(arr, d)
    # pad by reflection against FFT wrap-around
    pad = max(4, int(math.ceil(abs(d) * (max(U, V) - 1) / 2.0)))
    pw = [(pad, pad), (pad, pad)] + ([(0, 0)] if refocused.ndim == 3 else [])
    padded = np.pad(refocused.astype(np.float64), pw, mode="reflect")
    Py, Px = padded.shape[:2]
    wy = np.fft.fftfreq(Py)[:, None] * 2 * np.pi
    wx = np.fft.fftfreq(Px)[None, :] * 2 * np.pi
    omega = np.maximum(np.abs(wy), np.abs(wx))
    if zeta is None:
        zeta = _fit_zeta(refocused, arr[(V - 1) // 2, (U - 1) // 2], max(radius, 6.0))
    else:
        zeta = _number(zeta, "zeta")
        if zeta < 0:
            raise ValueError(f"zeta must be >= 0; got {zeta}")
    gain = 1.0 + zeta * omega
    if padded.ndim == 3:
        gain = gain[..., None]
    spec = np.fft.fft2(padded, axes=(0, 1)) * gain
    texture = np.real(np.fft.ifft2(spec, axes=(0, 1)))[pad : pad + Y, pad : pad + X]
    return PlaneTextureResult(
        texture=texture.astype(np.float32),
        refocused=refocused,
        disparity=float(d),
        zeta=zeta,
        dwell_p=p,
        dwell=w,
        kernel=_kernel_image(p, w, d, R, V, U),
        valid_radius=float(radius),
    )


def inplane_psf(control_points, disparity: float, *, n_times: int = 32, size: int | None = None) -> np.ndarray:
    """The 2D PSF that an in-plane path gives a view, for a scene at one disparity.

    What a conventional camera's 2D deconvolution would use: with
    ``p_z = 0`` and ``d_inf = 0``, instant ``k`` samples the views at angular
    offset ``(p_y, p_x)``, bilinearly between the two nearest views, and a
    plane at disparity ``d`` appears in view offset ``j`` shifted by ``d j``
    px. So the PSF has weight at ``d * floor(p)`` and ``d * (floor(p) + 1)``
    (bilinear splats for fractional positions), averaged over the instants.
    Views are assumed inside the aperture (no boundary clamping).

    Returns
    -------
    ndarray, float64, shape (size, size), centred, sums to 1
    """
    cp = validate_control_points(control_points)
    if np.any(cp[:, 2] != 0):
        raise ValueError("inplane_psf needs an in-plane path (p_z = 0)")
    d = _number(disparity, "disparity")
    pos = bezier_positions(cp, validate_n_times(n_times))
    taps = []
    for px, py, _ in pos:
        fx, fy = math.floor(px), math.floor(py)
        ax, ay = px - fx, py - fy
        for jy, wy in ((fy, 1 - ay), (fy + 1, ay)):
            for jx, wx in ((fx, 1 - ax), (fx + 1, ax)):
                if wy * wx > 0:
                    taps.append((d * jy, d * jx, wy * wx / len(pos)))
    reach = max(max(abs(t[0]), abs(t[1])) for t in taps)
    if size is None:
        size = 2 * int(math.ceil(reach)) + 3
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
    return K / K.sum()
