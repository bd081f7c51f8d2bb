"""Adam for the path fits, without :mod:`torch.optim`.

The first ``torch.optim`` optimiser made in a process imports ``torch._dynamo``,
a large module that is slow to load, only to update a few control points.
:class:`Adam` is the same update (Kingma & Ba; torch's single-tensor form
with its defaults: no weight decay, no AMSGrad).
"""

from __future__ import annotations

import torch

__all__ = ["Adam"]


class Adam:
    """Adam on parameter groups, with ``torch.optim.Adam``'s interface and update.

    Parameters
    ----------
    params : list of torch.Tensor, or list of dict
        Tensors, or groups ``{"params": [tensors], "lr": float}``.
    lr : float, default 1e-3
        Step size of groups that do not give their own.
    betas : tuple of 2 float, default (0.9, 0.999)
    eps : float, default 1e-8
    """

    def __init__(self, params, lr: float = 1e-3, betas=(0.9, 0.999), eps: float = 1e-8):
        params = list(params)
        groups = params if params and isinstance(params[0], dict) else [{"params": params}]
        self.param_groups = [{"lr": lr, **g, "params": list(g["params"])} for g in groups]
        self.betas, self.eps = betas, eps
        self.state = {}

    def zero_grad(self) -> None:
        """Drop the parameters' gradients (``set_to_none=True`` in torch's terms)."""
        for group in self.param_groups:
            for p in group["params"]:
                p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        """One update of every parameter that has a gradient."""
        b1, b2 = self.betas
        for group in self.param_groups:
            for p in group["params"]:
                if p.grad is None:
                    continue
                g = p.grad
                s = self.state.setdefault(p, {"step": 0, "m": torch.zeros_like(p), "v": torch.zeros_like(p)})
                s["step"] += 1
                s["m"].lerp_(g, 1 - b1)
                s["v"].mul_(b2).addcmul_(g, g.conj(), value=1 - b2)
                step_size = group["lr"] / (1 - b1 ** s["step"])
                denom = (s["v"].sqrt() / (1 - b2 ** s["step"]) ** 0.5).add_(self.eps)
                p.addcdiv_(s["m"], denom, value=-step_size)
