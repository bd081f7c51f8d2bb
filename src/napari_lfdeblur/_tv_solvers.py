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

from . import _fused
from .priors import gradient_norm_bound, project_tv_dual, sum_channels_
from .progress import check_cancelled

__all__ = ["PROX_BLOCK_BYTES", "TVProx", "tv_value", "iter_fista_tv"]


def tv_value(x, isotropic, axis_weights, buffers=None, coupled=False, oriented=None) -> float:
    """``TV4(x)`` without materialising the four gradient components at once.

    ``coupled``: the colour TV of :func:`~napari_lfdeblur.priors.tv4d`, the
    norm taken over the last axis (the channels) too. ``oriented``: an
    :class:`~napari_lfdeblur._oriented.OrientedDifferences` whose angular
    differences replace those along the view axes (None: the view axes).

    ``buffers``, two tensors of ``x``'s shape, are used as scratch space
    instead of new allocations (large fresh tensors cost page faults on every
    use on the CPU). On the CPU, a (V, U, Y, X[, C]) ``x`` is summed by a
    fused loop instead (:func:`~napari_lfdeblur._fused.tv_value`) where it
    is available.
    """
    if oriented is None and x.dim() in (4, 5) and _fused.available(x.device, x.dtype):
        return _fused.tv_value(x, axis_weights, isotropic, coupled)
    if oriented is not None and (value := oriented.fused_tv(x, axis_weights, isotropic, coupled)) is not None:
        return value
    acc, diff_buf = buffers if buffers is not None else (torch.empty_like(x), torch.empty_like(x))
    if isotropic:
        acc.zero_()
    total = 0.0
    for axis in range(4):
        n = x.shape[axis]
        if n < 2 or axis_weights[axis] == 0:
            continue
        if oriented is not None and axis < 2:
            diff = oriented.add_difference(x, axis, diff_buf.zero_()).narrow(axis, 0, n - 1)
        else:
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


#: on the CPU the proximal map works through the light field in blocks of rows of about this many bytes
#: per array, so that each inner iteration's many passes over a block run in the processor's cache
PROX_BLOCK_BYTES = 2 << 20


class TVProx:
    """``prox(v, mu) = argmin_x 1/2 ||x - v||^2 + mu TV4(x)`` over the box, by gradient projection on its dual.

    Each iteration takes a gradient step on the dual field (one component per
    axis, the primal clipped to the box) and projects it onto the unit ball,
    with step ``1 / (mu L)`` for ``L`` the bound on ``||gradient4d||^2``. The
    dual field is kept between calls, so each call starts from the previous
    solution: with the slowly moving ``v`` of an outer iteration a few inner
    iterations suffice (FISTA's outer momentum carries the acceleration). All
    work happens in buffers allocated once; ``out`` receives the result.
    ``coupled``: the colour TV (the last axis holds channels).

    An iteration sweeps the light field in blocks of ``rows`` rows (``y``):
    the primal of a block and of the row after it, then the block's dual
    step and projection. The primal row after a block is computed from the
    dual before the block's update, and carried over to the next block, so
    the sweep computes exactly what one pass over the whole field does.
    ``rows`` defaults to all rows on a GPU (fewer, larger kernels) and to
    blocks of about :data:`PROX_BLOCK_BYTES` per array on the CPU (each
    block's passes then run in cache). ``scratch``, two tensors of
    ``like``'s shape that the caller does not need during a call, are used
    for the primal and the dual norm when the block is the whole field
    (their contents are lost).

    On the CPU, where the fused loops are available
    (:func:`~napari_lfdeblur._fused.available`), an iteration is instead one
    parallel pass of :func:`~napari_lfdeblur._fused.prox_sweep`, which
    computes the same iteration with each row's primal, dual step and
    projection in one loop (``rows`` is then unused; the primal needs a
    whole-field buffer, the first of ``scratch`` when given).

    ``oriented``: an :class:`~napari_lfdeblur._oriented.OrientedDifferences`
    whose angular differences replace those along the view axes. Its
    iteration is :meth:`~napari_lfdeblur._oriented.OrientedDifferences.fused_prox`
    where the fused loops run, else the torch one over the whole field at
    once (``rows`` is unused either way).
    """

    def __init__(self, like: torch.Tensor, n_inner: int, isotropic: bool, axis_weights, box, scratch=None,
                 coupled=False, rows: int | None = None, oriented=None):
        self.n_inner = n_inner
        self.isotropic = isotropic
        self.coupled = coupled
        self.aw = axis_weights
        self.box = box
        self.oriented = oriented
        if oriented is None:
            self.lip = max(gradient_norm_bound(axis_weights), 1e-12)
        else:
            bounds = (oriented.norm_bound(0), oriented.norm_bound(1), 4.0, 4.0)
            self.lip = max(sum(w * w * b for w, b in zip(axis_weights, bounds)), 1e-12)
        self.p = [torch.zeros_like(like) for _ in range(4)]
        if oriented is None:
            self.fused = like.dim() in (4, 5) and _fused.available(like.device, like.dtype)
        else:
            self.fused = oriented.fused_available(like) and all(p.is_contiguous() for p in self.p)
        if self.fused:
            self.x = scratch[0] if scratch is not None else torch.empty_like(like)
            return
        Y = like.shape[2]
        if oriented is not None:
            rows = Y
        elif rows is None:
            row_bytes = max(1, like.narrow(2, 0, 1).numel() * like.element_size())
            rows = Y if like.device.type != "cpu" else PROX_BLOCK_BYTES // row_bytes
        self.rows = max(1, min(Y, int(rows)))
        if self.rows >= Y - 1 and scratch is not None:
            self.x, self.norm = scratch
        else:
            shape = list(like.shape)
            shape[2] = min(Y, self.rows + 1)
            self.x = like.new_empty(shape)
            shape[2] = self.rows
            self.norm = like.new_empty(shape)

    def _primal_rows(self, v, mu, r0, r1, out):
        """``v + mu div(p)`` at the rows ``r0:r1``, clipped to the box, into ``out`` (those rows)."""
        out.copy_(v.narrow(2, r0, r1 - r0))
        for axis, g in enumerate(self.p):
            n, w = g.shape[axis], mu * self.aw[axis]
            if n == 1:
                continue
            if self.oriented is not None and axis < 2:  # the whole field (rows = Y): -w D^T g
                self.oriented.add_adjoint(g, axis, out, alpha=-w)
                continue
            # as divergence4d: div_i += w g_i for i <= n - 2, div_i -= w g_{i-1} for i >= 1
            if axis != 2:
                gr = g.narrow(2, r0, r1 - r0)
                last = gr.narrow(axis, 0, n - 1)
                out.narrow(axis, 0, n - 1).add_(last, alpha=w)
                out.narrow(axis, 1, n - 1).sub_(last, alpha=w)
                continue
            a, b = r0, min(r1, n - 1)  # rows with a g_i term
            if b > a:
                out.narrow(2, 0, b - a).add_(g.narrow(2, a, b - a), alpha=w)
            a = max(r0, 1)  # rows with a g_{i-1} term
            if r1 > a:
                out.narrow(2, a - r0, r1 - a).sub_(g.narrow(2, a - 1, r1 - a), alpha=w)
        return out if self.box is None else out.clamp_(*self.box)

    def _dual_rows(self, x, y0, n, step):
        """The dual step at the rows ``y0:y0+n`` from the primal ``x`` at rows ``y0:y0+n`` (+ the next, if any)."""
        Y = self.p[0].shape[2]
        for axis, g in enumerate(self.p):
            m, w = g.shape[axis], step * self.aw[axis]
            if m < 2 or self.aw[axis] == 0:
                continue
            if self.oriented is not None and axis < 2:  # the whole field (rows = Y)
                self.oriented.add_difference(x, axis, g, alpha=w)
                continue
            if axis != 2:
                xs, gr = x.narrow(2, 0, n), g.narrow(2, y0, n)
                gr.narrow(axis, 0, m - 1).add_(xs.narrow(axis, 1, m - 1), alpha=w).sub_(xs.narrow(axis, 0, m - 1),
                                                                                        alpha=w)
                continue
            k = min(y0 + n, Y - 1) - y0  # rows with a forward difference
            if k > 0:
                g.narrow(2, y0, k).add_(x.narrow(2, 1, k), alpha=w).sub_(x.narrow(2, 0, k), alpha=w)
        project_tv_dual([g.narrow(2, y0, n) for g in self.p], 1.0, self.isotropic, self.norm.narrow(2, 0, n),
                        coupled_channels=self.coupled)

    def _sweep(self, v, mu, step):
        """One iteration of the dual gradient projection, block by block."""
        Y, rows = v.shape[2], self.rows
        for y0 in range(0, Y, rows):
            n = min(rows, Y - y0)
            hi = min(Y, y0 + n + 1)  # the primal is needed up to the row after the block
            x = self.x.narrow(2, 0, hi - y0)
            if y0 == 0:
                self._primal_rows(v, mu, 0, hi, x)
            else:  # the block's first row was computed by the previous block, before its dual update
                x.narrow(2, 0, 1).copy_(self.x.narrow(2, rows, 1))
                if hi > y0 + 1:
                    self._primal_rows(v, mu, y0 + 1, hi, x.narrow(2, 1, hi - y0 - 1))
            self._dual_rows(x, y0, n, step)

    def __call__(self, v: torch.Tensor, mu: float, out: torch.Tensor) -> torch.Tensor:
        if mu <= 0:
            out.copy_(v)
            return out if self.box is None else out.clamp_(*self.box)
        step = 1.0 / (mu * self.lip)
        if self.fused:
            return self._fused_call(v, mu, step, out)
        for _ in range(self.n_inner):
            self._sweep(v, mu, step)
            check_cancelled()
        Y = v.shape[2]
        for y0 in range(0, Y, self.rows):
            y1 = min(Y, y0 + self.rows)
            self._primal_rows(v, mu, y0, y1, out.narrow(2, y0, y1 - y0))
        return out

    def _fused_call(self, v, mu, step, out):
        """The iterations and the result by the fused loops (:func:`~napari_lfdeblur._fused.prox_sweep`)."""
        wp = [mu * w for w in self.aw]
        wd = [step * w if v.shape[axis] > 1 else 0.0 for axis, w in enumerate(self.aw)]
        if self.oriented is not None:
            for _ in range(self.n_inner):
                self.oriented.fused_prox(v, self.p, wp, self.box, self.x, wd, self.isotropic, self.coupled)
                check_cancelled()
            self.oriented.fused_prox(v, self.p, wp, self.box, out)
            return out
        blocks = 4 * torch.get_num_threads()
        for _ in range(self.n_inner):
            _fused.prox_sweep(v, self.p, wp, wd, self.box, self.isotropic, self.coupled, blocks, self.x)
            check_cancelled()
        _fused.prox_primal(v, self.p, wp, self.box, out)
        return out


def _dist2(a, b, buf) -> float:
    """``||a - b||^2``, with ``buf`` as scratch."""
    return float(torch.linalg.vector_norm(torch.sub(a, b, out=buf))) ** 2


@torch.no_grad()
def iter_fista_tv(op, f, x0, *, weight, n_iter, tol, isotropic, axis_weights, box, n_inner, lip=1.0,
                  record=None, coupled=False, ceiling=None, oriented=None):
    """FISTA iterations; yields ``record(iteration, x, info)``, returns the last ``x``.

    ``box`` is None or ``(lo, hi)`` (``hi`` None: no upper bound); ``ceiling``:
    samples of ``f`` at or above it are censored, fitted by
    ``1/2 min(K x - f, 0)^2`` (the data only bound the light from below
    there; a sample of the residual above 0 costs nothing), a convex term
    with the same Lipschitz bound. ``n_inner``: the inner iterations of the
    :class:`TVProx` per iteration. ``lip`` is the first estimate of the
    Lipschitz constant ``||K||^2`` of the data gradient; it is raised whenever
    the curvature seen along a step, ``||K d||^2 / ||d||^2``, exceeds it (the
    step is then redone), which costs no extra blur evaluation when the
    estimate holds. Stops after ``n_iter`` iterations or when the objective
    decreased by less than ``tol`` times its value.

    ``coupled``: the TV is the colour TV over the last axis of ``f``
    (:func:`~napari_lfdeblur.priors.tv4d` with ``coupled_channels``).
    ``oriented``: angular differences along a disparity map
    (:class:`~napari_lfdeblur._oriented.OrientedDifferences`; None: along the
    view axes).

    The iterates live in buffers allocated once and reused: the ``x`` of a
    record is overwritten two iterations later (copy it to keep it).

    Between two records it passes cancellation points
    (:func:`~napari_lfdeblur.progress.check_cancelled`) after every blur
    evaluation, every inner iteration of the proximal map and the objective.
    """
    tv = (isotropic, axis_weights, coupled, oriented)
    x = x0.clone() if box is None else x0.clamp(*box)
    x_new, y, work, spare = (torch.empty_like(x) for _ in range(4))
    Kx = op.forward(x)
    Ky, kwork = Kx.clone(), torch.empty_like(Kx)
    y.copy_(x)
    # the prox's primal and dual norm live only during a call: in spare and kwork, free then
    prox = TVProx(x, n_inner, isotropic, axis_weights, box, scratch=(spare, kwork), coupled=coupled,
                  oriented=oriented)
    scratch = (work, spare)
    # the censored samples, as flat indices: their number, not the light field's size, sets the memory
    censored = None
    if ceiling is not None:
        censored = torch.ge(f.reshape(-1), ceiling).nonzero().squeeze(1)
        if f.numel() < 2**31:
            censored = censored.to(torch.int32)
    F = _objective(x, Kx, f, weight, tv, kwork, scratch, censored)[0]
    t = 1.0
    restarts = evaluations = 0
    for it in range(1, n_iter + 1):
        grad = op.adjoint(_residual(Ky, f, kwork, censored))
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
        F_new, data = _objective(x_new, Kx_new, f, weight, tv, kwork, scratch, censored)
        check_cancelled()
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


def _residual(Kx, f, out, censored):
    """``K x - f`` into ``out``, with its positive entries at the flat indices ``censored`` set to 0 (None: none)."""
    r = torch.sub(Kx, f, out=out)
    if censored is not None and censored.numel():
        flat = r.view(-1)
        flat[censored] = flat[censored].clamp_(max=0.0)
    return r


def _objective(x, Kx, f, weight, tv, kbuf, scratch, censored=None):
    """``(1/2 ||K x - f||^2 + w TV4(x), data term)`` from a precomputed ``K x``; ``kbuf``, ``scratch``: buffers.

    ``tv``: ``(isotropic, axis_weights, coupled, oriented)`` of :func:`tv_value`; ``censored``: as in
    :func:`_residual`.
    """
    data = 0.5 * float(torch.linalg.vector_norm(_residual(Kx, f, kbuf, censored))) ** 2
    return data + (weight * tv_value(x, *tv[:2], scratch, *tv[2:]) if weight > 0 else 0.0), data
