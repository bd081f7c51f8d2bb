"""Priors over 4D light fields: finite differences, total variation and their proxes.

All functions work on torch tensors whose first four axes are ``(V, U, Y, X)``;
any trailing axes (a colour axis ``C``) are carried along and never
differenced. The differences are *forward* differences with a replicate
(Neumann) boundary: the difference at the last sample of an axis is zero.

:func:`divergence4d` is the exact negative adjoint of :func:`gradient4d`::

    sum(gradient4d(L)[a] * G[a] for a in range(4)) == -sum(L * divergence4d(G))

so ``-divergence4d(gradient4d(L))`` is the (positive semi-definite) Neumann
Laplacian.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

__all__ = [
    "AXES",
    "gradient4d",
    "divergence4d",
    "laplacian4d",
    "gradient_magnitude4d",
    "tv4d",
    "project_tv_dual",
    "sum_channels_",
    "prox_l1",
    "gradient_norm_bound",
    "gradient_yx",
    "divergence_yx",
    "sparse_gradient_prior",
]

#: the four differenced axes, in order
AXES = ("v", "u", "y", "x")


def _check(L: torch.Tensor) -> torch.Tensor:
    if not isinstance(L, torch.Tensor):
        raise TypeError(f"expected a torch tensor; got {type(L).__name__}")
    if L.ndim < 4:
        raise ValueError(f"expected a tensor with at least the 4 axes (V, U, Y, X); got shape {tuple(L.shape)}")
    return L


def _weights(axis_weights) -> tuple[float, float, float, float]:
    if axis_weights is None:
        return (1.0, 1.0, 1.0, 1.0)
    w = tuple(float(a) for a in axis_weights)
    if len(w) != 4 or not all(0 <= a < math.inf for a in w):  # NaN fails too
        raise ValueError(f"axis_weights must be 4 non-negative numbers (v, u, y, x), finite; got {axis_weights!r}")
    return w


def gradient4d(L: torch.Tensor, axis_weights: Sequence[float] | None = None) -> tuple[torch.Tensor, ...]:
    """Forward differences along ``v``, ``u``, ``y`` and ``x``.

    Parameters
    ----------
    L : torch.Tensor, shape (V, U, Y, X, ...)
        A light field (any trailing axes, e.g. colour, are not differenced).
    axis_weights : sequence of 4 floats, optional
        Multiply the difference along each axis by this weight (default 1).

    Returns
    -------
    tuple of 4 torch.Tensor, each of ``L``'s shape and dtype
        ``g[a][..., i, ...] = L[..., i + 1, ...] - L[..., i, ...]`` along axis
        ``a``, and 0 at the last sample (replicate / Neumann boundary).
    """
    return _forward_differences(_check(L), range(4), _weights(axis_weights))


def _forward_differences(L: torch.Tensor, axes, w) -> tuple[torch.Tensor, ...]:
    """Forward differences of ``L`` along ``axes``, weighted by ``w[axis]`` (zero at the last sample)."""
    out = []
    for axis in axes:
        g = torch.zeros_like(L)
        n = L.shape[axis]
        if n > 1:
            g.narrow(axis, 0, n - 1).copy_(L.narrow(axis, 1, n - 1) - L.narrow(axis, 0, n - 1))
        if w[axis] != 1.0:
            g = g * w[axis]
        out.append(g)
    return tuple(out)


def divergence4d(G: Sequence[torch.Tensor], axis_weights: Sequence[float] | None = None,
                 out: torch.Tensor | None = None, *, scale: float = 1.0, accumulate: bool = False) -> torch.Tensor:
    """Discrete divergence: the exact negative adjoint of :func:`gradient4d`.

    Parameters
    ----------
    G : sequence of 4 torch.Tensor, each of shape (V, U, Y, X, ...)
        A vector field, one component per axis ``v, u, y, x``.
    axis_weights : sequence of 4 floats, optional
        The same weights as given to :func:`gradient4d`.
    out : torch.Tensor, optional
        Written in place and returned, instead of a new tensor (the
        components' shape, dtype and device).
    scale : float, default 1.0
        The result is ``scale * div``.
    accumulate : bool, default False
        Add the result to ``out``'s contents instead of overwriting them
        (``out`` is then required): one pass fewer than adding afterwards.

    Returns
    -------
    torch.Tensor, the components' shape
        ``div`` with ``<gradient4d(L), G> = -<L, div>`` for every ``L``.
    """
    if len(G) != 4:
        raise ValueError(f"divergence4d takes 4 components (v, u, y, x); got {len(G)}")
    if accumulate and out is None:
        raise ValueError("divergence4d: accumulate=True needs out")
    w = tuple(scale * a for a in _weights(axis_weights))
    return _divergence(G, range(4), w, out, accumulate)


def laplacian4d(L: torch.Tensor, axis_weights: Sequence[float] | None = None,
                out: torch.Tensor | None = None) -> torch.Tensor:
    """``-divergence4d(gradient4d(L, w), w)``: the weighted 4D Laplacian with Neumann boundaries.

    Computed without the four gradient components: one difference buffer is
    reused along every axis.

    Parameters
    ----------
    L : torch.Tensor, shape (V, U, Y, X, ...)
    axis_weights : sequence of 4 floats, optional
        The weights of :func:`gradient4d`; each axis's term is scaled by the
        square of its weight (an axis of weight 0 is skipped).
    out : torch.Tensor, optional
        Written in place and returned (``L``'s shape, dtype and device).

    Returns
    -------
    torch.Tensor, ``L``'s shape
        ``D^T W^2 D L``, positive semi-definite in ``L``.
    """
    w = _weights(axis_weights)
    _check(L)
    out = torch.zeros_like(L) if out is None else out.zero_()
    diff = torch.empty_like(L)
    for axis in range(4):
        n = L.shape[axis]
        if n < 2 or w[axis] == 0:
            continue
        d = torch.sub(L.narrow(axis, 1, n - 1), L.narrow(axis, 0, n - 1), out=diff.narrow(axis, 0, n - 1))
        out.narrow(axis, 0, n - 1).sub_(d, alpha=w[axis] ** 2)
        out.narrow(axis, 1, n - 1).add_(d, alpha=w[axis] ** 2)
    return out


def _divergence(G: Sequence[torch.Tensor], axes, w, out=None, accumulate=False) -> torch.Tensor:
    """The negative adjoint of :func:`_forward_differences` along ``axes``, one component each (into ``out``)."""
    shape = G[0].shape
    div = torch.zeros_like(G[0]) if out is None else (out if accumulate else out.zero_())
    for axis, g in zip(axes, G):
        _check(g)
        if g.shape != shape:
            raise ValueError("divergence4d: the 4 components must have the same shape")
        n = g.shape[axis]
        if n == 1:
            continue
        # adjoint of D: (D^T g)_i = g_{i-1} - g_i with g_{-1} = 0 and g_{n-1} ignored
        last = g.narrow(axis, 0, n - 1)
        div.narrow(axis, 0, n - 1).add_(last, alpha=w[axis])
        div.narrow(axis, 1, n - 1).sub_(last, alpha=w[axis])
    return div


def gradient_yx(L: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The spatial components ``(g_y, g_x)`` of :func:`gradient4d` (the angular ones are not computed).

    Parameters
    ----------
    L : torch.Tensor, shape (V, U, Y, X, ...)

    Returns
    -------
    tuple of 2 torch.Tensor, each of ``L``'s shape and dtype
    """
    return _forward_differences(_check(L), (2, 3), (1.0, 1.0, 1.0, 1.0))


def divergence_yx(gy: torch.Tensor, gx: torch.Tensor) -> torch.Tensor:
    """The negative adjoint of :func:`gradient_yx`: :func:`divergence4d` of ``(0, 0, gy, gx)``.

    Parameters
    ----------
    gy, gx : torch.Tensor, each of shape (V, U, Y, X, ...)

    Returns
    -------
    torch.Tensor, the components' shape
    """
    return _divergence((gy, gx), (2, 3), (1.0, 1.0, 1.0, 1.0))


def sparse_gradient_prior(L: torch.Tensor, eps: float) -> torch.Tensor:
    """The L0-approximating prior ``sum_a mean(min(|d_a L|^2 / eps^2, 1))`` over the 4 axes.

    ``d_a`` are the forward differences of :func:`gradient4d`. This is the
    sparse-gradient prior of the joint blind method (Srinivasan et al., 2017;
    after Xu et al., 2013).

    Parameters
    ----------
    L : torch.Tensor, shape (V, U, Y, X[, C])
    eps : float
        Gradients larger than ``eps`` cost 1 each; smaller ones quadratically less.

    Returns
    -------
    torch.Tensor, scalar (differentiable)

    Raises
    ------
    ValueError
        If ``eps <= 0``.

    References
    ----------
    .. [1] P. P. Srinivasan, R. Ng and R. Ramamoorthi, "Light Field Blind
           Motion Deblurring", CVPR 2017.
    .. [2] L. Xu, S. Zheng and J. Jia, "Unnatural L0 Sparse Representation
           for Natural Image Deblurring", CVPR 2013.
    """
    if eps <= 0:
        raise ValueError(f"eps must be > 0; got {eps}")
    return sum(torch.clamp(g * g / (eps * eps), max=1.0).mean() for g in gradient4d(L))


def gradient_magnitude4d(grads: Sequence[torch.Tensor], eps: float = 0.0) -> torch.Tensor:
    """Pointwise ``sqrt(sum_a g_a^2 + eps^2)`` over the four components."""
    sq = sum(g * g for g in grads)
    if eps:
        sq = sq + eps * eps
    return torch.sqrt(sq)


def tv4d(
    L: torch.Tensor,
    *,
    isotropic: bool = True,
    eps: float = 0.0,
    axis_weights: Sequence[float] | None = None,
    reduction: str = "sum",
    coupled_channels: bool = False,
) -> torch.Tensor:
    """4D total variation over all four axes.

    Parameters
    ----------
    L : torch.Tensor, shape (V, U, Y, X, ...)
    isotropic : bool, default True
        ``sum sqrt(g_v^2 + g_u^2 + g_y^2 + g_x^2)`` per sample (isotropic) or
        ``sum |g_v| + |g_u| + |g_y| + |g_x|`` (anisotropic).
    eps : float, default 0
        Smoothing (Huber-like) ``sqrt(|g|^2 + eps^2) - eps``; keeps the value
        differentiable at zero gradient. Anisotropic TV smooths each axis.
    axis_weights : sequence of 4 floats, optional
    reduction : {'sum', 'mean'}
    coupled_channels : bool, default False
        Colour TV [1]_ over the last axis of a (V, U, Y, X, C) light field:
        the norm per sample is taken over the axes *and* the channels,
        ``sqrt(sum_a sum_c g_ac^2)`` (isotropic) or ``sum_a sqrt(sum_c
        g_ac^2)`` (anisotropic), so that an edge shared by the channels
        costs less than separate edges. False: every channel on its own.

    Returns
    -------
    torch.Tensor, a scalar (differentiable)

    Raises
    ------
    ValueError
        On ``coupled_channels`` without a channel axis, or a bad ``reduction``.

    References
    ----------
    .. [1] X. Bresson and T. F. Chan, "Fast dual minimization of the vectorial
           total variation norm and applications to color image processing",
           Inverse Problems and Imaging 2, 2008.
    """
    grads = gradient4d(L, axis_weights)
    if coupled_channels:
        if L.ndim != 5:
            raise ValueError(f"coupled_channels needs a light field with a channel axis (V, U, Y, X, C); got {L.ndim}D")
        if isotropic:
            val = torch.sqrt(sum((g * g).sum(-1) for g in grads) + eps * eps) - eps
        else:
            val = sum(torch.sqrt((g * g).sum(-1) + eps * eps) - eps for g in grads)
    elif isotropic:
        val = gradient_magnitude4d(grads, eps) - eps
    else:
        val = sum((torch.sqrt(g * g + eps * eps) - eps) if eps else g.abs() for g in grads)
    if reduction == "sum":
        return val.sum()
    if reduction == "mean":
        return val.mean()
    raise ValueError(f"reduction must be 'sum' or 'mean'; got {reduction!r}")


def project_tv_dual(P: Sequence[torch.Tensor], radius: float, isotropic: bool = True,
                    work: torch.Tensor | None = None, coupled_channels: bool = False) -> tuple[torch.Tensor, ...]:
    """Project a dual field onto the TV dual ball (the prox of the conjugate of ``radius * TV``).

    Isotropic: each sample's 4-vector is scaled into the l2 ball of ``radius``;
    anisotropic: each component is clipped to ``[-radius, radius]``. With
    ``coupled_channels`` (the colour TV of :func:`tv4d`) the last axis of the
    components holds the channels, and the ball is that of the norm over
    the channels too: a sample's 4 x C matrix (isotropic), or each axis's
    C-vector (anisotropic). Works in place on ``P`` and returns it.
    ``work``, a tensor of the components' shape, holds the per-sample norm
    instead of a new tensor.
    """
    if radius <= 0:
        for p in P:
            p.zero_()
        return tuple(P)
    if not isotropic and not coupled_channels:
        for p in P:
            p.clamp_(-radius, radius)
        return tuple(P)
    if not isotropic:  # coupled: each axis's vector over the channels
        for p in P:
            _shrink(torch.mul(p, p, out=work) if work is not None else p * p, [p], radius, True)
        return tuple(P)
    norm = torch.mul(P[0], P[0], out=work) if work is not None else P[0] * P[0]
    for p in P[1:]:
        norm.addcmul_(p, p)
    _shrink(norm, P, radius, coupled_channels)
    return tuple(P)


def _shrink(norm: torch.Tensor, P, radius: float, coupled: bool) -> None:
    """Divide each of ``P`` by ``max(1, sqrt(norm) / radius)``, ``norm`` the squared norm per sample (summed over
    the channels first when ``coupled``); ``norm`` is overwritten."""
    scale = sum_channels_(norm) if coupled else norm
    scale.sqrt_()
    if radius != 1.0:  # the TV prox's ball is the unit one: no pass for it
        scale.div_(radius)
    scale.clamp_(min=1.0)
    if scale is not norm:  # spread back over the channels: same-shape divisions are faster than broadcasting
        for c in range(1, norm.shape[-1]):
            norm.narrow(-1, c, 1).copy_(scale)
        scale = norm
    for p in P:
        p.div_(scale)


def sum_channels_(t: torch.Tensor) -> torch.Tensor:
    """The sum over the last axis, written into (and returned as) ``t``'s first channel: a view, no new tensor."""
    first = t.narrow(-1, 0, 1)
    for c in range(1, t.shape[-1]):
        first.add_(t.narrow(-1, c, 1))
    return first


def prox_l1(x: torch.Tensor, threshold: float) -> torch.Tensor:
    """Soft thresholding ``sign(x) max(|x| - threshold, 0)`` (the prox of ``threshold |.|_1``)."""
    return torch.sign(x) * torch.clamp(x.abs() - threshold, min=0.0)


def gradient_norm_bound(axis_weights: Sequence[float] | None = None) -> float:
    """An upper bound on ``||gradient4d||^2`` (operator norm squared): ``4 sum_a w_a^2``."""
    return 4.0 * sum(a * a for a in _weights(axis_weights))
