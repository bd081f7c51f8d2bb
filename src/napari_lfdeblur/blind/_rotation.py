"""The rotation stage of 6-DOF blind estimation (``BlindParams(motion='6dof')``).

The 3-DOF alternation estimates the translation first. Its path, with zero
rotation, then starts an alternation over all six coordinates: the
salient-edge latent under the current 6-DOF path
(:func:`~napari_lfdeblur.blind._latent.l0_latent`), then Adam on the path's
control points against that latent, in the gradient domain,
``min_p ||grad_yx(K_p G_sigma l) - grad_yx f||^2``, through the exact
6-DOF operator. The rotation acts on the whole frame's coordinates
(docs/model.md, "Camera rotation"), so on a window the operator is told
the window's place in the frame.

Rotation and translation are partly confounded: yaw and ``p_x`` both move
the views, but translation moves each depth by its own disparity, rotation
all depths alike. Where the scene has depth range the fit separates them;
on a single plane it finds some mixture that blurs alike.
"""

from __future__ import annotations

import numpy as np
import torch

from ..blur import BlurOperator
from ..path import MAX_ROTATION, bernstein_matrix, path_in_frame
from ..priors import gradient_yx
from ..progress import Progress
from ._alternating import relay
from ._latent import EdgeBlurred, edge_sigmas, l0_latent, n_hqs_steps
from ._params import BlindParams, PathEstimate

__all__ = ["iter_rotation_fit"]


def iter_rotation_fit(g: torch.Tensor, est: PathEstimate, p: BlindParams, device, window, frame_shape, box: float):
    """Refine a 3-DOF estimate into a 6-DOF path on the grayscale ``g`` (V, U, h, w, 1), ``d_inf = 0`` model.

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
        record per conjugate-gradient iteration of the latent and per
        ``FIT_REPORT_EVERY`` path steps.
    """
    rp = p.rotation
    y0, x0 = window[:2]
    frame = (y0, x0, *frame_shape)
    r_px = max(frame_shape) / 2.0
    cp = path_in_frame(est.control_points, window, frame_shape)
    cp = np.concatenate([cp, np.zeros((len(cp), 3))], axis=1)
    lam = p.latent.l0_weight * min(1.0, p.latent.l0_floor)
    sigma = edge_sigmas(p.latent)
    stage, n_stages = est.n_stages, est.n_stages + 2  # then the evidence and the final stage
    per_outer = n_hqs_steps(lam, p.latent) * (p.latent.n_cg + 1) + rp.steps
    tick = [0]

    def record(cur, loss, phase):
        tick[0] += 1
        return Progress(stage=f"rotation ({g.shape[2]}x{g.shape[3]})", iteration=min(tick[0], rp.n_outer * per_outer),
                        n_iterations=rp.n_outer * per_outer, loss=loss, control_points=np.array(cur),
                        stage_index=stage, n_stages=n_stages, info={"phase": phase})

    latent, history = g.clone(), []
    for _ in range(rp.n_outer):
        op = EdgeBlurred(BlurOperator(tuple(g.shape), cp, n_times=rp.n_times, frame=frame, device=device), sigma)
        latent = yield from relay(l0_latent(op, g, lam, p.latent, latent),
                                  lambda _x, cp=cp: record(cp, float("nan"), "latent"))
        fit = _Fit(g, latent, sigma, frame, rp, r_px, box, cp, device)
        for step in range(1, rp.steps + 1):
            loss = fit.step()
            if step % 10 == 0 or step == rp.steps:
                yield record(fit.control_points(), loss, "path fit")
        cp = fit.control_points()
        history.append(loss)
    info = {**est.info, "rotation_fit": history}
    return PathEstimate(cp, est.factors, est.n_stages + 1, est.loss_history + history, info)


class _Fit:
    """Adam on the 6-DOF control points against a fixed latent, in the zero-mean gauge.

    The rotation is optimised as ``R r`` (px of image motion at the frame's
    edge scale), so that one learning rate suits translation (views) and
    rotation alike.
    """

    def __init__(self, g, latent, sigma, frame, rp, r_px, box, cp, device):
        self.g, self.latent, self.sigma, self.frame, self.rp, self.box = g, latent, sigma, frame, rp, box
        self.device = device
        self.scale = torch.tensor([1.0, 1.0, 1.0] + [1.0 / r_px] * 3, dtype=torch.float32, device=device)
        self.gy, self.gx = gradient_yx(g)
        mean_row = bernstein_matrix(len(cp), rp.n_times).mean(axis=0)
        self.mean_row = torch.as_tensor(mean_row, dtype=torch.float32, device=device)
        self.q = (torch.as_tensor(cp, dtype=torch.float32, device=device) / self.scale).requires_grad_(True)
        self.opt = torch.optim.Adam([self.q], lr=rp.lr)

    def control_points(self) -> np.ndarray:
        return (self.q.detach() * self.scale).cpu().double().numpy()

    def step(self) -> float:
        self.opt.zero_grad(set_to_none=True)
        with torch.enable_grad():
            cp = self.q * self.scale
            op = BlurOperator(tuple(self.g.shape), cp, n_times=self.rp.n_times, frame=self.frame, device=self.device)
            gy, gx = gradient_yx(EdgeBlurred(op, self.sigma).forward(self.latent))
            loss = ((gy - self.gy).square().mean() + (gx - self.gx).square().mean()) / 2
            loss.backward()
        self.opt.step()
        with torch.no_grad():  # the gauge, and the bounds of the model
            self.q.sub_((self.mean_row @ self.q).unsqueeze(0))
            self.q[:, :3].clamp_(-self.box, self.box)
            r_max = MAX_ROTATION / float(self.scale[3])
            self.q[:, 3:].clamp_(-r_max, r_max)
        return float(loss.detach())
