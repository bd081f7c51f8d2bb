"""The alternating method: salient-edge latent and path fit, alternated coarse to fine.

On the grayscale light field, at each level of a spatial pyramid, the
estimate alternates between the L0 salient-edge latent
(:func:`~napari_lfdeblur.blind._latent.l0_latent`) under the current path and
a batch fit of paths to that latent
(:class:`~napari_lfdeblur.blind._path_fit.GramLoss`), keeping the best path.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..blur import BlurOperator
from ..path import bezier_positions, elevate_degree
from ..progress import Progress
from ._disparity import disparity_weights, downsample
from ._latent import EdgeBlurred, edge_sigmas, l0_latent, n_hqs_steps
from ._params import BlindParams, PathEstimate
from ._path_fit import FIT_REPORT_EVERY, GramLoss, PathParam, SumLoss, fit_path

__all__ = ["iter_alternating", "pyramid_factors", "relay"]


def pyramid_factors(Y: int, X: int, p: BlindParams) -> list[int]:
    """The downsampling factors ``2^k`` of the pyramid, coarse to fine, for a Y x X view."""
    pp = p.path
    top = 1
    while pp.max_size and min(Y, X) // top > pp.max_size and min(Y, X) // (2 * top) >= pp.min_size:
        top *= 2
    factors = []
    for k in range(pp.n_levels - 1, -1, -1):
        fac = top * 2**k
        if min(Y, X) // fac >= pp.min_size or fac == top:
            factors.append(fac)
    return factors


def iter_alternating(gs, p: BlindParams, device, rng, box: float, preview=None, frames=None):
    """Coarse-to-fine salient-edge / path alternation on grayscale light fields ``gs``, ``d_inf = 0``.

    ``gs`` is a list of ``(V, U, Y, X, 1)`` tensors: one light field, or
    windows of one view with ``frames`` their ``(y0, x0, Y_full, X_full)``.
    Each has its own latent, and the path is fitted to all of them at once
    (their fits summed); with ``frames`` it is the path of the whole view,
    without, the path of the single light field itself.

    A generator: yields a :class:`~napari_lfdeblur.progress.Progress` record
    after every conjugate-gradient iteration of the latent, every
    :data:`~napari_lfdeblur.blind._path_fit.FIT_REPORT_EVERY` steps of the
    path fit and at the end of every alternation, and returns a
    :class:`~napari_lfdeblur.blind._params.PathEstimate`. ``iteration``
    counts these reports within a level, out of ``n_iterations = n_outer *
    per_alternation`` (an alternation that ends early jumps to its end), so
    that the fraction done only grows. ``preview(latent, factor)``, when
    given, turns a latent at a pyramid factor into the light-field estimate
    of the records' ``estimate`` (``latent`` a list, one per window).
    """
    run = _Alternation(list(gs), [None] * len(gs) if frames is None else list(frames), p, device, rng, box, preview)
    cp = yield from run.run()
    return PathEstimate(cp, run.factors, len(run.stages), run.history, run.info)


class _Alternation:
    """The state of one run of :func:`iter_alternating`."""

    def __init__(self, gs, frames, p: BlindParams, device, rng, box, preview):
        self.gs, self.frames, self.p, self.device, self.rng, self.box = gs, frames, p, device, rng, box
        self.preview = preview
        self.Y, self.X = gs[0].shape[2:4]
        self.factors = pyramid_factors(self.Y, self.X, p)
        # stages: (factor, p_z free, alternations); with estimate_z, a last stage on the finest level
        # frees p_z, starting from the in-plane estimate
        self.stages = [(fac, False, p.path.n_outer) for fac in self.factors]
        if p.path.estimate_z and p.path.z_outer > 0:
            self.stages.append((self.factors[-1], True, p.path.z_outer))
        lat = p.latent
        # reports per alternation: latent steps (at most those at the smallest lambda), fit reports, the end
        lam_min = lat.l0_weight * lat.l0_floor
        self.per_outer = (len(gs) * n_hqs_steps(lam_min, lat) * (lat.n_cg + 1)
                          + (p.path.steps - 1) // FIT_REPORT_EVERY + 1)
        self.history: list = []
        self.info: dict = {}
        self.disparity: dict = {}  # (level factor, window) -> pixel weights of the fit

    def record(self, stage, fac, it, cur, latent, loss=float("nan"), **extra) -> Progress:
        n_stages = len(self.stages) + (self.p.motion == "6dof")  # then the rotation stage
        estimate = None
        if self.preview is not None:
            def estimate(latent=latent, fac=fac):
                return self.preview(latent, fac)
        kind = "p_z" if self.stages[stage][1] else "level"
        size = f"{self.Y // fac}x{self.X // fac}" + (f", {len(self.gs)} windows" if len(self.gs) > 1 else "")
        return Progress(
            stage=f"path ({kind} {stage + 1}/{n_stages}, {size})",
            iteration=it, n_iterations=self.stages[stage][2] * self.per_outer, loss=loss,
            control_points=np.array(cur), estimate=estimate, stage_index=stage, n_stages=n_stages + 2,
            info={"level": stage, "factor": fac, **extra},
        )

    def run(self):
        p, n_cp = self.p, self.p.n_control_points
        # initial paths: short lines in evenly spread directions, jittered by the seed
        n_start = 2 if len(self.factors) > 1 or n_cp == 2 else n_cp
        starts = []
        for i in range(p.path.n_restarts):
            a = math.pi * (i + self.rng.uniform(-0.15, 0.15)) / p.path.n_restarts
            d = np.array([math.cos(a), math.sin(a), 0.0]) * p.path.init_length / 2
            starts.append(np.stack([-d, d]))
        cp, lam, latent = None, p.latent.l0_weight, None
        for stage in range(len(self.stages)):
            n_lvl = n_cp if stage >= len(self.factors) - 1 else min(n_cp, n_start + stage)
            cp, lam, latent = yield from self.level(stage, cp, lam, latent, n_lvl, starts)
        return elevate_degree(cp, n_cp)

    def level(self, stage, cp, lam, latent, n_lvl, starts):
        """One pyramid level (or the ``p_z`` stage): alternations until the path stands still."""
        p, rng = self.p, self.rng
        fac, free_z, n_outer = self.stages[stage]
        fs = [downsample(g, fac) for g in self.gs]
        frames = [self.level_frame(fr, fac) for fr in self.frames]
        parts = []
        for i, (f, frame) in enumerate(zip(fs, frames)):
            if p.path.disparity_weight > 0 and (fac, i) not in self.disparity:
                self.disparity[fac, i] = disparity_weights(f, p.path.disparity_weight)
            parts.append(GramLoss(f, p.path.n_pixels // len(fs), rng, p.n_times, self.box,
                                  self.box * p.path.z_box if free_z else 0.0, p.path.tiles if free_z else 1,
                                  weight=self.disparity.get((fac, i)), frame=frame))
        sub = SumLoss(parts)
        if latent is None or latent[0].shape != fs[0].shape:
            latent = [f.clone() for f in fs]
        cur = np.zeros((n_lvl, 3)) if cp is None else elevate_degree(cp, n_lvl)
        if not free_z:
            cur[:, 2] = 0.0
        still = 0
        es_from = p.latent.edge_sigma_from if stage == 0 else 1  # the edge model from this alternation on
        for outer in range(1, n_outer + 1):
            first = cp is None and outer == 1
            sigma = edge_sigmas(p.latent) if outer >= es_from else (0.0, 0.0)
            base, tick = (outer - 1) * self.per_outer, [0]
            latent = yield from self.latent_step(stage, fs, frames, cur, latent, lam, sigma, base, tick, outer)
            sub.set_latent(latent, None if first else cur, p.path.robust, sigma)
            candidates = self.candidates(first, cur, n_lvl, free_z, starts)
            loss, new = yield from self.fit_step(stage, fac, sub, candidates, free_z, latent, lam, base, tick, outer,
                                                 first)
            move = (float(np.abs(bezier_positions(new, p.n_times) - bezier_positions(cur, p.n_times)).max())
                    if len(new) == len(cur) else 1.0)
            cur = new
            self.history.append(loss)
            lam = max(lam * p.latent.l0_decay, p.latent.l0_weight * p.latent.l0_floor)
            yield self.record(stage, fac, outer * self.per_outer, cur, latent, loss=loss, alternation=outer,
                              phase="done", move=move, **{"lambda": lam})
            still = still + 1 if (move < p.path.tol and outer > es_from) else 0
            if still >= 2:
                break
        return cur, lam, latent

    @staticmethod
    def level_frame(frame, fac):
        """A window's frame at the pyramid level of factor ``fac`` (None: the window is the view)."""
        return None if frame is None else tuple(int(v) // fac for v in frame)

    def latent_step(self, stage, fs, frames, cur, latent, lam, sigma, base, tick, outer):
        """The salient-edge latent of each window under the current path, one record per CG iteration."""
        fac = self.stages[stage][0]
        out = list(latent)
        for i, (f, frame) in enumerate(zip(fs, frames)):
            op = BlurOperator(tuple(f.shape), cur, n_times=self.p.n_times, infinity_disparity=0.0,
                              device=self.device, frame=frame)
            if max(sigma) > 0:
                op = EdgeBlurred(op, sigma)

            def report(x, i=i):
                tick[0] = min(tick[0] + 1, self.per_outer - 1)
                shown = out[:i] + [x] + out[i + 1 :]
                return self.record(stage, fac, base + tick[0], cur, shown, alternation=outer, phase="latent",
                                   **{"lambda": lam})

            out[i] = yield from relay(l0_latent(op, f, lam, self.p.latent, out[i]), report)
        return out

    def candidates(self, first, cur, n_lvl, free_z, starts):
        """The batch of paths to fit: lines and random paths at first; later the current path and variants."""
        pp, rng = self.p.path, self.rng
        if first:
            out = [elevate_degree(c, n_lvl) for c in starts]
            for _ in range(pp.n_random):
                c = rng.uniform(-1.0, 1.0, size=(n_lvl, 3)) * pp.init_length
                c[:, 2] = 0.0
                out.append(c)
            return out
        out = [cur, -cur] if pp.try_mirror else [cur]
        for _ in range(pp.n_perturb):
            c = cur + rng.normal(0.0, pp.perturb, size=cur.shape)
            c[:, 2] = cur[:, 2]
            out.append(c)
        if free_z:  # the current in-plane shape with random out-of-plane motions
            for _ in range(pp.n_random_later):
                c = cur.copy()
                c[:, 2] = rng.uniform(-1.0, 1.0, size=len(cur)) * self.box * pp.z_box
                out.append(c)
        # fresh random starts too: the latent has changed, and with it the fit's minima
        for _ in range(pp.n_random_later):
            c = rng.uniform(-1.0, 1.0, size=(n_lvl, 3)) * pp.init_length
            c[:, 2] = 0.0
            out.append(c)
        return out

    def fit_step(self, stage, fac, sub, candidates, free_z, latent, lam, base, tick, outer, first):
        """Fit the batch of paths to the latent; returns the best ``(fit, control_points)``."""
        box, pp = self.box, self.p.path
        params = PathParam(np.stack(candidates), self.p.n_times, box, self.device, free_z=free_z,
                           z_box=box * pp.z_box)
        params.project()

        def report(item):
            step, fit, shown = item
            tick[0] = min(tick[0] + 1, self.per_outer - 1)
            return self.record(stage, fac, base + tick[0], shown, latent, alternation=outer, phase="path fit",
                               step=step, fit=fit + sub.offset, **{"lambda": lam})

        scores = (yield from relay(fit_path(params, sub, pp.steps, pp.lr), report)).detach().cpu().double().numpy()
        scores += sub.offset  # the mean squared residuals themselves
        k = int(np.argmin(scores))
        if first:
            self.info["restart_losses"] = scores.tolist()
        return float(scores[k]), params.control_points()[k].detach().cpu().double().numpy()


def relay(gen, report):
    """Yield ``report(item)`` for every item the generator ``gen`` yields; return what it returns."""
    out = {}

    def items():
        out["result"] = yield from gen

    for item in items():
        yield report(item)
    return out["result"]
