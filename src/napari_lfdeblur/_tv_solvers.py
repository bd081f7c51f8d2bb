"""Solvers of ``min_l 1/2 ||K l - f||^2 + w TV4(l)`` (+ a box) for :mod:`napari_lfdeblur.deconvolution`.

:func:`iter_fista_tv` is FISTA (Beck & Teboulle) on the data term with the
proximal map of ``w TV4 + box`` computed by a few warm-started
iterations of the gradient projection on its dual (Beck & Teboulle's GP,
Chambolle's iteration with the box inside), and adaptive momentum restart
(O'Donoghue & Candes). :func:`estimate_noise_sigma` is the robust noise
estimate behind the default weight.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .priors import divergence4d, gradient_norm_bound, project_tv_dual

__all__ = ["TVProx", "add_gradient_", "tv_value", "iter_fista_tv", "estimate_noise_sigma"]


def add_gradient_(Y, x, alpha: float, axis_weights) -> None:
    """``Y[a] += alpha * w_a * D_a x`` in place, without a temporary per axis."""
    for axis in range(4):
        n = x.shape[axis]
        if n < 2 or axis_weights[axis] == 0:
            continue
        hi, lo = x.narrow(axis, 1, n - 1), x.narrow(axis, 0, n - 1)
        y = Y[axis].narrow(axis, 0, n - 1)
        y.add_(hi, alpha=alpha * axis_weights[axis]).sub_(lo, alpha=alpha * axis_weights[axis])


def tv_value(x, isotropic, axis_weights, buffers=None, coupled=False) -> float:
    """``TV4(x)`` without materialising the four gradient components at once.

    ``coupled``: the colour TV of :func:`~napari_lfdeblur.priors.tv4d`, the
    norm taken over the last axis (the channels) too.

    ``buffers``, two tensors of ``x``'s shape, are used as scratch space
    instead of new allocations (large fresh tensors cost page faults on every
    use on the CPU).
    """
    acc, diff_buf = buffers if buffers is not None else (torch.empty_like(x), torch.empty_like(x))
    if isotropic:
        acc.zero_()
    total = 0.0
    for axis in range(4):
        n = x.shape[axis]
        if n < 2 or axis_weights[axis] == 0:
            continue
        diff = torch.sub(x.narrow(axis, 1, n - 1), x.narrow(axis, 0, n - 1), out=diff_buf.narrow(axis, 0, n - 1))
        if axis_weights[axis] != 1.0:
            diff.mul_(axis_weights[axis])
        if isotropic:
            acc.narrow(axis, 0, n - 1).addcmul_(diff, diff)
        elif coupled:
            total += float(diff.square_().sum(-1).sqrt_().sum())
        else:
            total += float(diff.abs_().sum())
    if not isotropic:
        return total
    return float((acc.sum(-1) if coupled else acc).sqrt_().sum())


class TVProx:
    """``prox(v, mu) = argmin_x 1/2 ||x - v||^2 + mu TV4(x)`` over the box, by gradient projection on its dual.

    Each iteration takes a gradient step on the dual field (one component per
    axis, the primal clipped to the box) and projects it onto the unit ball,
    with step ``1 / (mu L)`` for ``L`` the bound on ``||gradient4d||^2``. The
    dual field is kept between calls, so each call starts from the previous
    solution: with the slowly moving ``v`` of an outer iteration a few inner
    iterations suffice (FISTA's outer momentum carries the acceleration). All
    work happens in buffers allocated once; ``out`` receives the result.
    ``scratch``, two tensors of ``like``'s shape that the caller does not
    need during a call, hold the primal and the dual norm (their contents
    are lost). ``coupled``: the colour TV (the last axis holds channels).
    """

    def __init__(self, like: torch.Tensor, n_inner: int, isotropic: bool, axis_weights, box, scratch,
                 coupled=False):
        self.n_inner = n_inner
        self.isotropic = isotropic
        self.coupled = coupled
        self.aw = axis_weights
        self.box = box
        self.lip = max(gradient_norm_bound(axis_weights), 1e-12)
        self.p = [torch.zeros_like(like) for _ in range(4)]
        self.x, self.norm = scratch

    def _primal(self, v, mu, q, out):
        """``v + mu div(q)``, clipped to the box, into ``out``."""
        x = divergence4d(q, self.aw, out=out.copy_(v), scale=mu, accumulate=True)
        return x if self.box is None else x.clamp_(*self.box)

    def __call__(self, v: torch.Tensor, mu: float, out: torch.Tensor) -> torch.Tensor:
        if mu <= 0:
            out.copy_(v)
            return out if self.box is None else out.clamp_(*self.box)
        step = 1.0 / (mu * self.lip)
        for _ in range(self.n_inner):
            add_gradient_(self.p, self._primal(v, mu, self.p, self.x), step, self.aw)
            project_tv_dual(self.p, 1.0, self.isotropic, self.norm, coupled_channels=self.coupled)
        return self._primal(v, mu, self.p, out)


def _dist2(a, b, buf) -> float:
    """``||a - b||^2``, with ``buf`` as scratch."""
    return float(torch.linalg.vector_norm(torch.sub(a, b, out=buf))) ** 2


@torch.no_grad()
def iter_fista_tv(op, f, x0, *, weight, n_iter, tol, isotropic, axis_weights, box, n_inner=5, lip=1.0,
                  record=None, coupled=False):
    """FISTA iterations; yields ``record(iteration, x, info)``, returns the last ``x``.

    ``box`` is None or ``(lo, hi)``. ``lip`` is the first estimate of the
    Lipschitz constant ``||K||^2`` of the data gradient; it is raised whenever
    the curvature seen along a step, ``||K d||^2 / ||d||^2``, exceeds it (the
    step is then redone), which costs no extra blur evaluation when the
    estimate holds. Stops after ``n_iter`` iterations or when the objective
    decreased by less than ``tol`` times its value.

    ``coupled``: the TV is the colour TV over the last axis of ``f``
    (:func:`~napari_lfdeblur.priors.tv4d` with ``coupled_channels``).

    The iterates live in buffers allocated once and reused: the ``x`` of a
    record is overwritten two iterations later (copy it to keep it).
    """
    tv = (isotropic, axis_weights, coupled)
    x = x0.clone() if box is None else x0.clamp(*box)
    x_new, y, work, spare = (torch.empty_like(x) for _ in range(4))
    Kx = op.forward(x)
    Ky, kwork = Kx.clone(), torch.empty_like(Kx)
    y.copy_(x)
    # the prox's primal and dual norm live only during a call: in spare and kwork, free then
    prox = TVProx(x, n_inner, isotropic, axis_weights, box, scratch=(spare, kwork), coupled=coupled)
    scratch = (work, spare)
    F = _objective(x, Kx, f, weight, tv, kwork, scratch)[0]
    t = 1.0
    restarts = evaluations = 0
    for it in range(1, n_iter + 1):
        grad = op.adjoint(torch.sub(Ky, f, out=kwork))
        if grad.data_ptr() == kwork.data_ptr():  # an adjoint that returns its input: kwork is the prox's scratch
            grad = grad.clone()
        evaluations += 1
        while True:  # backtracking on the Lipschitz estimate (Beck & Teboulle)
            prox(torch.add(y, grad, alpha=-1.0 / lip, out=work), weight / lip, x_new)
            Kx_new = op.forward(x_new)
            d2 = _dist2(x_new, y, work)
            curv = _dist2(Kx_new, Ky, kwork) / max(d2, 1e-30)
            if curv <= lip * (1.0 + 1e-6) or d2 == 0.0:
                break
            lip = 1.1 * curv
        del grad
        F_new, data = _objective(x_new, Kx_new, f, weight, tv, kwork, scratch)
        step = torch.sub(x_new, x, out=work)  # x_new - x
        # adaptive restart: momentum is dropped when the objective rose or the step turned back
        if it > 1 and (F_new > F or float(torch.vdot(torch.sub(y, x_new, out=spare).view(-1), step.view(-1))) > 0):
            t, restarts = 1.0, restarts + 1
        t_new = (1.0 + math.sqrt(1.0 + 4.0 * t * t)) / 2.0
        beta = (t - 1.0) / t_new
        y.copy_(x_new)
        torch.sub(Kx_new, Kx, out=Ky)
        if beta > 0:
            y.add_(step, alpha=beta)
            Ky.mul_(beta).add_(Kx_new)
        else:
            Ky.copy_(Kx_new)
        decrease = (F - F_new) / max(abs(F_new), 1e-30)
        x, x_new = x_new, x  # the old x's buffer takes the next iterate
        Kx, F, t = Kx_new, F_new, t_new
        info = {"objective": F, "data_term": data, "relative_decrease": decrease, "lipschitz": lip,
                "restarts": restarts, "blur_evaluations": evaluations}
        yield (it, x, info) if record is None else record(it, x, info)
        if 0.0 <= decrease < tol:
            break
    return x


def _objective(x, Kx, f, weight, tv, kbuf, scratch):
    """``(1/2 ||K x - f||^2 + w TV4(x), data term)`` from a precomputed ``K x``; ``kbuf``, ``scratch``: buffers.

    ``tv``: ``(isotropic, axis_weights, coupled)`` of :func:`tv_value`.
    """
    data = 0.5 * _dist2(Kx, f, kbuf)
    isotropic, axis_weights, coupled = tv
    return data + (weight * tv_value(x, isotropic, axis_weights, scratch, coupled) if weight > 0 else 0.0), data


#: blocks of :func:`estimate_noise_sigma`: 4 x 4 Haar coefficients (8 x 8 pixels), of which the 12 smallest are kept
_NOISE_BLOCK, _NOISE_KEPT = 4, 12
#: the share of blocks, the least detailed ones, that :func:`estimate_noise_sigma` reads the noise from
_NOISE_QUANTILE = 0.1
#: brightness classes of :func:`estimate_noise_sigma`, each an equal share of the blocks
_NOISE_BINS = 4
#: the 10th percentile of the mean of the 12 smallest of 16 squared standard Gaussians
#: (simulated: 16 million blocks, 8 seeds, standard error 4e-5)
_NOISE_UNIT = 0.19817


def estimate_noise_sigma(lf: np.ndarray) -> float:
    """Robust estimate of the standard deviation of white noise in a light field.

    Reads the noise from the finest diagonal Haar wavelet detail ``HH`` of
    every view and channel (Donoho & Johnstone), where white noise of standard
    deviation ``sigma`` keeps that standard deviation, but only from its least
    detailed parts:

    - ``HH`` is cut into blocks of 4 x 4 coefficients (8 x 8 pixels); each
      block is summarised by the mean of its 12 smallest squared
      coefficients, which up to 4 edge coefficients in the block do not move;
    - the blocks are sorted by brightness (their mean pixel value) into 4
      classes of equal size; in each class the noise variance is the 10th
      percentile of the block means, over the same percentile for pure
      Gaussian noise of unit standard deviation, so that pure noise comes
      out without bias;
    - the estimate is the square root of the mean of the 4 variances: the
      root-mean-square noise of the light field, also where the noise grows
      with brightness (photon noise), where the least detailed blocks of
      the whole light field would often be the darkest and read too little;
    - blocks without any detail (a clipped or constant region) say nothing
      about the noise and are left out.

    Blur removes fine detail but not the noise added after it, so many blocks
    of a blurred light field hold little besides noise. The median of all
    coefficients (the classical estimate) errs high wherever the scene keeps
    fine texture, most at low noise; the least detailed blocks remove much of
    that bias, though a scene finely textured everywhere still makes the
    estimate err high. On integer-coded images the rounding counts as noise
    (about 0.29 of a code step). Views smaller than 8 x 8 pixels fall back to
    the classical estimate, ``median(|HH|) / 0.6745``.

    Parameters
    ----------
    lf : array_like, shape (V, U, Y, X[, C])
        Views of at least 2 x 2 pixels.

    Returns
    -------
    float
        0.0 when the light field has no detail at all.

    Raises
    ------
    ValueError
        On views smaller than 2 x 2 pixels.
    """
    a = np.asarray(lf, dtype=np.float32)
    if a.ndim == 4:
        a = a[..., None]
    if min(a.shape[2:4]) < 2:
        raise ValueError(f"the noise estimate needs views of at least 2 x 2 pixels, not {a.shape[2]} x {a.shape[3]}")
    b = _NOISE_BLOCK
    Yb, Xb = a.shape[2] // (2 * b), a.shape[3] // (2 * b)
    if Yb == 0 or Xb == 0:
        Y, X = a.shape[2] // 2 * 2, a.shape[3] // 2 * 2
        views = a[:, :, :Y, :X].reshape(-1, Y, X, a.shape[4])
        return float(np.median(np.abs(_haar_hh(views)))) / 0.6744897501960817
    U, C = a.shape[1], a.shape[4]
    means, brightness = [], []
    for row in a:  # one row of views at a time: the temporaries stay small
        r = row[:, : 2 * b * Yb, : 2 * b * Xb]
        sq = np.square(_haar_hh(r).reshape(U, Yb, b, Xb, b, C).transpose(0, 1, 3, 5, 2, 4).reshape(-1, b * b))
        level = r.reshape(U, Yb, 2 * b, Xb, 2 * b, C).mean(axis=(2, 4)).reshape(-1)  # in the order of sq's blocks
        keep = sq.max(axis=1) > 0  # a block without any detail (clipped, constant) says nothing of the noise
        means.append(np.partition(sq[keep], _NOISE_KEPT - 1, axis=1)[:, :_NOISE_KEPT].mean(axis=1, dtype=np.float64))
        brightness.append(level[keep])
    means, brightness = np.concatenate(means), np.concatenate(brightness)
    if means.size == 0:
        return 0.0
    n_bins = max(1, min(_NOISE_BINS, means.size // 100))
    bins = np.array_split(np.argsort(brightness, kind="stable"), n_bins)  # equal shares of the blocks
    variance = np.mean([np.quantile(means[i], _NOISE_QUANTILE) for i in bins]) / _NOISE_UNIT
    return float(np.sqrt(variance))


def _haar_hh(a: np.ndarray) -> np.ndarray:
    """The finest diagonal Haar detail of views ``(N, Y, X, C)`` (even ``Y``, ``X``): ``(N, Y/2, X/2, C)``."""
    return (a[:, 0::2, 0::2] - a[:, 0::2, 1::2] - a[:, 1::2, 0::2] + a[:, 1::2, 1::2]) * 0.5
