"""Solvers of ``min_l 1/2 ||K l - f||^2 + w TV4(l)`` (+ a box) for :mod:`napari_lfdeblur.deconvolution`.

:func:`iter_fista_tv` is FISTA (Beck & Teboulle) on the data term with the
proximal map of ``w TV4 + box`` computed by a few warm-started iterations of
the fast gradient projection on its dual, and adaptive momentum restart
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


def tv_value(x, isotropic, axis_weights) -> float:
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


class TVProx:
    """``prox(v, mu) = argmin_x 1/2 ||x - v||^2 + mu TV4(x)`` over the box, by dual FGP.

    The dual field (one component per axis, in the unit ball) is kept between
    calls, so each call starts from the previous solution: with the slowly
    moving ``v`` of an outer iteration a few inner iterations suffice.
    """

    def __init__(self, like: torch.Tensor, n_inner: int, isotropic: bool, axis_weights, box):
        self.n_inner = n_inner
        self.isotropic = isotropic
        self.aw = axis_weights
        self.box = box
        self.lip = max(gradient_norm_bound(axis_weights), 1e-12)
        self.p = [torch.zeros_like(like) for _ in range(4)]

    def _primal(self, v, mu, q):
        x = divergence4d(q, self.aw).mul_(mu).add_(v)
        return x if self.box is None else x.clamp_(*self.box)

    def __call__(self, v: torch.Tensor, mu: float) -> torch.Tensor:
        if mu <= 0:
            return v.clone() if self.box is None else v.clamp(*self.box)
        p = self.p
        r = [q.clone() for q in p]
        t = 1.0
        step = 1.0 / (mu * self.lip)
        for _ in range(self.n_inner):
            add_gradient_(r, self._primal(v, mu, r), step, self.aw)  # r <- p_new (in place)
            project_tv_dual(r, 1.0, self.isotropic)
            t_new = (1.0 + math.sqrt(1.0 + 4.0 * t * t)) / 2.0
            beta = (t - 1.0) / t_new
            for a in range(4):  # p <- p_new + beta (p_new - p); swap so that r holds the extrapolation
                p[a].sub_(r[a]).mul_(-beta).add_(r[a])
            p, r = r, p
            t = t_new
        self.p = p
        return self._primal(v, mu, p)


def _objective(x, Kx, f, weight, isotropic, axis_weights):
    """``(1/2 ||K x - f||^2 + w TV4(x), data term)`` from a precomputed ``K x``."""
    data = 0.5 * float(torch.linalg.vector_norm(Kx - f)) ** 2
    return data + (weight * tv_value(x, isotropic, axis_weights) if weight > 0 else 0.0), data


@torch.no_grad()
def iter_fista_tv(op, f, x0, *, weight, n_iter, tol, isotropic, axis_weights, box, n_inner=5, lip=1.0,
                  record=None):
    """FISTA iterations; yields ``record(iteration, x, info)``, returns the last ``x``.

    ``box`` is None or ``(lo, hi)``. ``lip`` is the first estimate of the
    Lipschitz constant ``||K||^2`` of the data gradient; it is raised whenever
    the curvature seen along a step, ``||K d||^2 / ||d||^2``, exceeds it (the
    step is then redone), which costs no extra blur evaluation when the
    estimate holds. Stops after ``n_iter`` iterations or when the objective
    decreased by less than ``tol`` times its value.
    """
    x = x0.clone() if box is None else x0.clamp(*box)
    Kx = op.forward(x)
    prox = TVProx(x, n_inner, isotropic, axis_weights, box)
    F, _ = _objective(x, Kx, f, weight, isotropic, axis_weights)
    y, Ky, t = x, Kx, 1.0
    restarts = evaluations = 0
    for it in range(1, n_iter + 1):
        grad = op.adjoint(Ky - f)
        evaluations += 1
        while True:  # backtracking on the Lipschitz estimate (Beck & Teboulle)
            x_new = prox(torch.add(y, grad, alpha=-1.0 / lip), weight / lip)
            Kx_new = op.forward(x_new)
            d2 = float(torch.linalg.vector_norm(x_new - y)) ** 2
            curv = float(torch.linalg.vector_norm(Kx_new - Ky)) ** 2 / max(d2, 1e-30)
            if curv <= lip * (1.0 + 1e-6) or d2 == 0.0:
                break
            lip = 1.1 * curv
        del grad
        F_new, data = _objective(x_new, Kx_new, f, weight, isotropic, axis_weights)
        # adaptive restart: momentum is dropped when the objective rose or the step turned back
        if it > 1 and (F_new > F or float(((y - x_new) * (x_new - x)).sum()) > 0):
            t, restarts = 1.0, restarts + 1
        t_new = (1.0 + math.sqrt(1.0 + 4.0 * t * t)) / 2.0
        beta = (t - 1.0) / t_new
        y = torch.add(x_new, x_new - x, alpha=beta) if beta > 0 else x_new
        Ky = torch.add(Kx_new, Kx_new - Kx, alpha=beta) if beta > 0 else Kx_new
        decrease = (F - F_new) / max(abs(F_new), 1e-30)
        x, Kx, F, t = x_new, Kx_new, F_new, t_new
        info = {"objective": F, "data_term": data, "relative_decrease": decrease, "lipschitz": lip,
                "restarts": restarts, "blur_evaluations": evaluations}
        yield (it, x, info) if record is None else record(it, x, info)
        if 0.0 <= decrease < tol:
            break
    return x


def estimate_noise_sigma(lf: np.ndarray) -> float:
    """Robust estimate of the standard deviation of white noise in a light field.

    The median absolute value of the finest diagonal Haar wavelet detail of
    every view (and channel), divided by 0.6745 (Donoho & Johnstone). Blur
    removes fine detail but not the noise added after it, so in a blurred
    light field this detail is mostly noise; what is left of the scene makes
    the estimate err high, less so the noisier the data.

    Parameters
    ----------
    lf : array_like, shape (V, U, Y, X[, C])

    Returns
    -------
    float
    """
    a = np.asarray(lf, dtype=np.float32)
    Y, X = a.shape[2] // 2 * 2, a.shape[3] // 2 * 2
    a = a[:, :, :Y, :X]
    hh = (a[:, :, 0::2, 0::2] - a[:, :, 0::2, 1::2] - a[:, :, 1::2, 0::2] + a[:, :, 1::2, 1::2]) * 0.5
    return float(np.median(np.abs(hh))) / 0.6744897501960817
