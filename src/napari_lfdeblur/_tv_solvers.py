"""Solvers of ``min_l 1/2 ||K l - f||^2 + w TV4(l)`` (+ a box) for :mod:`napari_lfdeblur.deconvolution`.

:func:`iter_fista_tv` is FISTA (Beck & Teboulle) on the data term with the
proximal map of ``w TV4 + box`` computed by a few warm-started
iterations of the gradient projection on its dual (Beck & Teboulle's GP,
Chambolle's iteration with the box inside), and adaptive momentum restart
(O'Donoghue & Candes).
"""

from __future__ import annotations

import math

import torch

from .priors import divergence4d, gradient_norm_bound, project_tv_dual, sum_channels_
from .progress import check_cancelled

__all__ = ["TVProx", "add_gradient_", "tv_value", "iter_fista_tv"]


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
    return float((sum_channels_(acc) if coupled else acc).sqrt_().sum())


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
            check_cancelled()
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

    Between two records it passes cancellation points
    (:func:`~napari_lfdeblur.progress.check_cancelled`) after every blur
    evaluation and every inner iteration of the proximal map.
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
        check_cancelled()
        if grad.data_ptr() == kwork.data_ptr():  # an adjoint that returns its input: kwork is the prox's scratch
            grad = grad.clone()
        evaluations += 1
        while True:  # backtracking on the Lipschitz estimate (Beck & Teboulle)
            prox(torch.add(y, grad, alpha=-1.0 / lip, out=work), weight / lip, x_new)
            Kx_new = op.forward(x_new)
            check_cancelled()
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
