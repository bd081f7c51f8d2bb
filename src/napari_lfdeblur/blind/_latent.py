"""The salient-edge latent light field: L0 gradient regularisation by half-quadratic splitting.

The latent ``l_s = argmin ||K l - f||^2 + lambda ||grad l||_0`` is solved by
half-quadratic splitting (Xu, Zheng & Jia, 2013): auxiliary gradients are
hard-thresholded, then the quadratic step is solved by conjugate gradients,
with the splitting weight ``beta`` growing geometrically. Its piecewise-constant
result has step edges whatever the current path. The edge model ``K_p G_sigma``
lets the path fit take the latent as sharper than the scene.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .. import _fused
from ..blur import BlurOperator
from ..priors import divergence4d, divergence_yx, gradient4d, gradient_yx, laplacian4d
from ._params import LatentParams

__all__ = ["cg", "n_hqs_steps", "difference_pair", "l0_latent", "edge_sigmas", "gauss_yx", "EdgeBlurred"]


def cg(apply_A, b, x0, n_iter):
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


def n_hqs_steps(lam: float, p: LatentParams, last: int = 0) -> int:
    """Splitting steps :func:`l0_latent` takes for ``lam`` and ``last`` (counted as its loop does)."""
    beta, n = _first_beta(lam, p, last), 1
    while 0 < beta < p.hqs_beta_max:
        beta = min(beta * p.hqs_kappa, p.hqs_beta_max)
        n += 1
    return n


def _first_beta(lam: float, p: LatentParams, last: int) -> float:
    """The splitting weight of the first step: ``2 lam``, or that of the ``last``-th step before the end."""
    beta = 2.0 * lam
    if last > 0:
        beta = max(beta, p.hqs_beta_max / p.hqs_kappa ** (last - 1))
    return beta


def _axis_weights(angular_weight: float) -> tuple[float, float, float, float]:
    """The regulariser's weights of ``(v, u, y, x)``: the angular axes weighted, or left out when 0."""
    a = max(float(angular_weight), 0.0)
    return (a, a, 1.0, 1.0)


def difference_pair(angular_weight: float):
    """``(grad, div)`` of the latent's regulariser: 4D with weighted angular axes, or spatial only."""
    if angular_weight > 0:
        aw = _axis_weights(angular_weight)
        return (lambda z: gradient4d(z, aw)), (lambda g: divergence4d(g, aw))
    return gradient_yx, (lambda g: divergence_yx(*g))


@torch.no_grad()  # torch's decorator enters no_grad at every resume of the generator only
def l0_latent(op: BlurOperator, f: torch.Tensor, lam: float, p: LatentParams, x0: torch.Tensor, last: int = 0):
    """Salient-edge latent: ``min ||K l - f||^2 + lam ||grad l||_0`` by half-quadratic splitting.

    The gradient is over ``y, x`` and, with ``p.angular_weight > 0``, also
    over ``v, u`` (weighted). The splitting weight ``beta`` grows from
    ``2 lam`` by ``p.hqs_kappa`` per step up to ``p.hqs_beta_max``; with
    ``last > 0`` only the last ``last`` steps of that schedule are taken (at
    most all of them), for a warm start ``x0`` that is already a latent of
    a nearby problem.

    A generator: yields the current latent after every conjugate-gradient
    iteration (``p.n_cg + 1`` per splitting step; the caller reports progress
    there, and can be stopped there) and returns the latent, (V, U, Y, X, 1)
    float32.

    References
    ----------
    .. [1] L. Xu, S. Zheng and J. Jia, "Unnatural L0 Sparse Representation
           for Natural Image Deblurring", CVPR 2013.
    .. [2] J. Pan, Z. Hu, Z. Su and M.-H. Yang, "Deblurring Text Images via
           L0-Regularized Intensity and Gradient Prior", CVPR 2014.
    """
    grad, div = difference_pair(p.angular_weight)
    # div(grad(.)) of the quadratic step without the gradient components: -laplacian4d
    lap_weights = _axis_weights(p.angular_weight)
    fused = f.dim() in (4, 5) and _fused.available(f.device, f.dtype)
    Ktf = op.adjoint(f)
    x = x0
    beta = _first_beta(lam, p, last)
    while True:
        g = grad(x)
        keep = sum(c * c for c in g) >= lam / beta
        for c in g:
            c.mul_(keep)
        rhs = Ktf - beta * div(g)

        def apply_A(z, beta=beta):
            if fused:
                return _fused.add_laplacian(op.adjoint(op.forward(z)), z, lap_weights, beta)
            return torch.add(op.adjoint(op.forward(z)), laplacian4d(z, lap_weights), alpha=beta)

        x = yield from cg(apply_A, rhs, x, p.n_cg)
        if beta >= p.hqs_beta_max:
            break
        beta = min(beta * p.hqs_kappa, p.hqs_beta_max)
    return x


def edge_sigmas(p: LatentParams) -> tuple[float, float]:
    """``(sigma_y, sigma_x)`` of the edge model: ``p.edge_sigma`` split by ``p.edge_anisotropy``."""
    half = p.edge_anisotropy * abs(p.edge_anisotropy) / 2.0
    s2 = p.edge_sigma**2
    return math.sqrt(max(s2 - half, 0.0)), math.sqrt(max(s2 + half, 0.0))


def gauss_yx(L: torch.Tensor, sigma) -> torch.Tensor:
    """Spatial Gaussian blur of (V, U, Y, X, C), zero padded (so the operator is self-adjoint).

    ``sigma``: px, one for both axes or ``(sigma_y, sigma_x)``; an axis with
    ``sigma <= 0`` is left alone. The kernel is cut at ``3 sigma``.
    """
    sigmas = (sigma, sigma) if np.isscalar(sigma) else tuple(sigma)
    # separable, by shifted adds (faster than conv2d on these shapes on the CPU)
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


class EdgeBlurred:
    """``K_p G_sigma``: the blur of a latent whose edges are sharper than the scene's.

    ``G_sigma`` is a spatial Gaussian of ``sigma`` px, or ``(sigma_y,
    sigma_x)`` (which commutes with the angular blur of an in-plane path).
    """

    def __init__(self, op, sigma):
        self.op, self.sigma = op, sigma

    def forward(self, z):
        return self.op.forward(gauss_yx(z, self.sigma))

    def adjoint(self, r):
        return gauss_yx(self.op.adjoint(r), self.sigma)
