"""The joint method: the paper's blind stage, Adam on the path and the light field together.

Minimises ``mean((K_p l - f)^2) + w R_eps(l)`` over the control points ``p``
and the grayscale light field ``l`` by Adam, with the 4D sparse-gradient
prior :func:`~napari_lfdeblur.priors.sparse_gradient_prior` and ``w``,
``eps`` annealed (Srinivasan et al., 2017).
"""

from __future__ import annotations

import torch

from ..blur import BlurOperator
from ..priors import sparse_gradient_prior
from ..progress import Progress
from ._adam import Adam
from ._params import BlindParams, PathEstimate
from ._path_fit import PathParam

__all__ = ["iter_joint"]


def iter_joint(g: torch.Tensor, d_inf: float, p: BlindParams, device, rng, box: float, preview=None):
    """The paper's joint Adam on path and grayscale light field ``g`` (V, U, Y, X, 1).

    A generator: yields one :class:`~napari_lfdeblur.progress.Progress`
    record per iteration and returns a
    :class:`~napari_lfdeblur.blind._params.PathEstimate`. ``preview(latent,
    1)``, when given, turns the current light field into the estimate of the
    records' ``estimate``.

    References
    ----------
    .. [1] P. P. Srinivasan, R. Ng and R. Ramamoorthi, "Light Field Blind
           Motion Deblurring", CVPR 2017.
    """
    jp = p.joint
    shape = tuple(g.shape)
    cp0 = rng.uniform(-0.25, 0.25, size=(p.n_control_points, 3))
    cp0[:, 2] = 0.0
    pp = PathParam(cp0, p.n_times, box, device)
    pp.project()
    L = g.clone().requires_grad_(True)
    opt = Adam([{"params": [pp.q], "lr": jp.lr}, {"params": [L], "lr": jp.lf_lr}])
    w0 = jp.prior_weight
    history = []
    for it in range(1, jp.n_iter + 1):
        w = max(w0 * jp.prior_decay ** (it - 1), w0 * jp.prior_floor)
        eps = max(jp.eps * jp.eps_decay ** (it - 1), jp.eps_min)
        opt.zero_grad()
        with torch.enable_grad():
            op = BlurOperator(shape, pp.control_points(), n_times=p.n_times, infinity_disparity=d_inf, device=device)
            r = op.forward(L) - g
            loss = (r * r).mean() + w * sparse_gradient_prior(L, eps)
            loss.backward()
        opt.step()
        pp.project()
        history.append(float(loss.detach()))
        estimate = None if preview is None else (lambda: preview(L, 1))
        yield Progress(stage="path (joint)", iteration=it, n_iterations=jp.n_iter, loss=history[-1],
                       control_points=pp.numpy(), estimate=estimate, stage_index=0, n_stages=3,
                       info={"prior_weight": w, "eps": eps})
    return PathEstimate(pp.numpy(), [1], 1, history, {})
