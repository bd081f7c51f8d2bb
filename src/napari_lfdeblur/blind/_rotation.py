"""The rotation stage of 6-DOF blind estimation (``BlindParams(motion='6dof')``).

The 3-DOF alternation estimates the translation first. Its image motion,
explained half by the translation and half by rotation, then starts an
alternation over all six coordinates: the
salient-edge latent under the current 6-DOF path
(:func:`~napari_lfdeblur.blind._latent.l0_latent`), then Adam on the path's
control points against that latent, in the gradient domain,
``min_p ||grad_yx(K_p G_sigma l) - grad_yx f||^2``, through the exact
6-DOF operator, on every other view along ``v`` and ``u``
(:data:`FIT_VIEW_STEP`). The rotation acts on the whole frame's coordinates
(docs/model.md, "Camera rotation"), so on a window the operator is told
the window's place in the frame.

Rotation and translation are partly confounded: yaw and ``p_x`` both move
the views, but translation moves each depth by its own disparity, rotation
all depths alike. Where the scene has depth range the fit separates them;
on a single plane it finds some mixture that blurs alike.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..blur import BlurOperator
from ..path import MAX_ROTATION, bernstein_matrix, bezier_positions, path_in_frame
from ..priors import gradient_yx
from ..progress import Progress
from ._adam import Adam
from ._alternating import relay
from ._disparity import DISPARITY_PIXELS, disparity_map, downsample
from ._evidence import evidence_weight, path_disagreement
from ._latent import EdgeBlurred, edge_sigmas, gauss_yx, l0_latent, n_hqs_steps
from ._params import BlindParams, PathEstimate

__all__ = ["iter_rotation_fit", "dominant_disparity", "rotation_equivalent", "FIT_VIEW_STEP"]

#: The path fit compares the views ``0, 2, 4, ...`` along ``v`` and ``u`` (where there are at least 5):
#: a third of the work, and the whole aperture, whose parallax tells rotation from translation.
FIT_VIEW_STEP = 2


def iter_rotation_fit(g: torch.Tensor, est: PathEstimate, p: BlindParams, device, window, frame_shape, box: float):
    """Refine a 3-DOF estimate into a 6-DOF path on the grayscale ``g`` (V, U, h, w, 1), ``d_inf = 0`` model.

    The start explains the image motion found half by the translation and
    half by rotation (:func:`rotation_equivalent`): the two extremes move the
    scene at its dominant disparity alike, and only the depths tell them
    apart, so the fit starts between them. Up to ``p.rotation.n_outer``
    alternations follow, each latent after the first warm-started from the
    previous one with the last ``p.rotation.warm_hqs_steps`` splitting
    steps; they stop once one moves the path by less than ``p.rotation.path_tol``
    (:func:`~napari_lfdeblur.blind._evidence.path_disagreement`). Each path
    fit stops once its loss falls by less than ``p.rotation.fit_tol`` over
    10 steps (the first 10 counted from the loss after step 1, so that a
    fit that starts converged stops at its first check).

    Parameters
    ----------
    g : torch.Tensor
        The light field of the path stage (the window, refocused by ``d_inf``).
    est : PathEstimate
        The 3-DOF estimate, in the window's coordinates.
    window : tuple of 4 int
        ``(y0, x0, h, w)`` of ``g`` in the frame.
    frame_shape : tuple of 2 int
        ``(Y, X)`` of the frame.
    box : float
        Bound of the translation's control points, views.

    Returns
    -------
    PathEstimate
        With ``(n, 6)`` control points in the frame's coordinates, one more
        stage, and the fits of the stage appended to the loss history.
        A generator: yields a :class:`~napari_lfdeblur.progress.Progress`
        record per conjugate-gradient iteration of the latent and every 10
        path steps.
    """
    run = _Stage(g, p, device, window, frame_shape, box, est.n_stages)
    cp3 = path_in_frame(est.control_points, window, frame_shape)
    cp = np.concatenate([cp3, np.zeros((len(cp3), 3))], axis=1)
    disparity = dominant_disparity(g)
    if abs(disparity) * run.extent(cp3) >= 0.1:  # the translation moves the image: half of it as a rotation
        cp = 0.5 * (cp + rotation_equivalent(cp3, disparity, run.r_px))
    cp, latent, loss = yield from run.alternation(cp, g.clone(), 0)
    history = [loss]
    for _ in range(p.rotation.n_outer - 1):
        previous = cp
        cp, latent, loss = yield from run.alternation(cp, latent, p.rotation.warm_hqs_steps)
        history.append(loss)
        if path_disagreement(g, previous, cp, p.rotation.n_times, run.frame) < p.rotation.path_tol:
            break  # the path has settled
    info = {**est.info, "rotation_fit": history}
    return PathEstimate(cp, est.factors, est.n_stages + 1, est.loss_history + history, info)


def dominant_disparity(g: torch.Tensor) -> float:
    """Median disparity (px/view) of the better-textured half of ``g`` (V, U, Y, X, 1)."""
    Y, X = g.shape[2:4]
    k = max(1, int(math.sqrt(Y * X / DISPARITY_PIXELS)))
    small = downsample(g, k)
    d = disparity_map(small)
    gy, gx = gradient_yx(small.mean(dim=(0, 1))[None, None])
    mag = (gy * gy + gx * gx)[0, 0, ..., 0].cpu().numpy()
    return k * float(np.median(d[mag >= np.median(mag)]))


def rotation_equivalent(cp3: np.ndarray, disparity: float, r_px: float) -> np.ndarray:
    """A rotation-only ``(n, 6)`` path that moves a plane at ``disparity`` like the translation ``cp3``.

    Translating by ``p_x`` views moves the image of a plane at disparity
    ``d`` by ``-d p_x`` px; a yaw ``r_y`` moves the centre of every view by
    ``R r_y`` px. So ``r_y = -d p_x / R`` and, likewise, ``r_x = d p_y / R``.
    """
    out = np.zeros((len(cp3), 6))
    out[:, 3] = disparity * cp3[:, 1] / r_px
    out[:, 4] = -disparity * cp3[:, 0] / r_px
    out[:, 3:] = np.clip(out[:, 3:], -MAX_ROTATION, MAX_ROTATION)
    return out


class _Stage:
    """One rotation stage: its alternations (latent, then path fit) and progress records."""

    def __init__(self, g, p: BlindParams, device, window, frame_shape, box, stage):
        self.g, self.p, self.device, self.box = g, p, device, box
        self.frame = (window[0], window[1], *frame_shape)
        self.r_px = max(frame_shape) / 2.0
        self.lam = evidence_weight(p)  # the alternation's smallest latent weight
        self.sigma = edge_sigmas(p.latent)
        self.stage, self.n_stages = stage, stage + 3  # then the evidence and the final stage
        rp = p.rotation
        fit = math.ceil(rp.steps / 10)
        cold = n_hqs_steps(self.lam, p.latent) * (p.latent.n_cg + 1) + fit  # the first alternation
        warm = n_hqs_steps(self.lam, p.latent, rp.warm_hqs_steps) * (p.latent.n_cg + 1) + fit
        self.n_records = cold + (rp.n_outer - 1) * warm
        self.tick = 0

    def extent(self, cp) -> float:
        pos = bezier_positions(cp, self.p.rotation.n_times)[:, :2]
        return float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0)))

    def record(self, cp, loss, phase) -> Progress:
        self.tick = min(self.tick + 1, self.n_records)
        return Progress(stage=f"rotation ({self.g.shape[2]}x{self.g.shape[3]})", iteration=self.tick,
                        n_iterations=self.n_records, loss=loss, control_points=np.array(cp),
                        stage_index=self.stage, n_stages=self.n_stages, info={"phase": phase})

    def alternation(self, cp, latent, last):
        """The latent under ``cp`` from ``latent`` (the last ``last`` splitting steps; 0: all), then the path
        fitted to it; returns ``(cp, latent, fit)``."""
        rp = self.p.rotation
        op = BlurOperator(tuple(self.g.shape), cp, n_times=rp.n_times, frame=self.frame, device=self.device)
        latent = yield from relay(l0_latent(EdgeBlurred(op, self.sigma), self.g, self.lam, self.p.latent, latent,
                                            last), lambda _x: self.record(cp, float("nan"), "latent"))
        fit = _Fit(self.g, latent, self.sigma, self.frame, rp, self.r_px, self.box, cp, self.device)
        for step in range(1, rp.steps + 1):
            loss = fit.step()
            if step == 1:
                before = loss  # the reference of the first check
            if step % 10 == 0 or step == rp.steps:
                yield self.record(fit.control_points(), loss, "path fit")
                if rp.fit_tol > 0 and before - loss < rp.fit_tol * before:
                    break  # the fit has stalled
                before = loss
        return fit.control_points(), latent, loss


class _Fit:
    """Adam on the 6-DOF control points against a fixed latent, in the zero-mean gauge.

    The rotation is optimised as ``R r`` (px of image motion at a view's
    centre), so that one learning rate suits translation (views) and
    rotation alike.
    """

    def __init__(self, g, latent, sigma, frame, rp, r_px, box, cp, device):
        self.g, self.frame, self.rp, self.box = g, frame, rp, box
        self.source = gauss_yx(latent, sigma)  # what the path blurs: the latent with the scene's edge softness
        self.device = device
        self.scale = torch.tensor([1.0, 1.0, 1.0] + [1.0 / r_px] * 3, dtype=torch.float32, device=device)
        self.view_step = FIT_VIEW_STEP if min(g.shape[:2]) >= 5 else 1
        self.gy, self.gx = gradient_yx(g[:: self.view_step, :: self.view_step].contiguous())
        mean_row = bernstein_matrix(len(cp), rp.n_times).mean(axis=0)
        self.mean_row = torch.as_tensor(mean_row, dtype=torch.float32, device=device)
        self.q = (torch.as_tensor(cp, dtype=torch.float32, device=device) / self.scale).requires_grad_(True)
        self.opt = Adam([self.q], lr=rp.lr)

    def control_points(self) -> np.ndarray:
        return (self.q.detach() * self.scale).cpu().double().numpy()

    def step(self) -> float:
        self.opt.zero_grad()
        with torch.enable_grad():
            cp = self.q * self.scale
            op = BlurOperator(tuple(self.g.shape), cp, n_times=self.rp.n_times, frame=self.frame, device=self.device)
            gy, gx = gradient_yx(op.forward(self.source, self.view_step))
            loss = ((gy - self.gy).square().mean() + (gx - self.gx).square().mean()) / 2
            loss.backward()
        self.opt.step()
        with torch.no_grad():  # the gauge, and the bounds of the model
            self.q.sub_((self.mean_row @ self.q).unsqueeze(0))
            self.q[:, :3].clamp_(-self.box, self.box)
            r_max = MAX_ROTATION / float(self.scale[3])
            self.q[:, 3:].clamp_(-r_max, r_max)
        return float(loss.detach())
