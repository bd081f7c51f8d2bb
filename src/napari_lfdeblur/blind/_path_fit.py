"""The path fit of the alternating method: the path parameterisation, the Gram loss, batch Adam.

The path is fitted to a latent light field in the gradient domain,
``min_p ||grad_yx(K_p l_s) - grad_yx f||^2``, on a subset of pixels. The fit
is a small quadratic form in the blur kernel (:class:`GramLoss`), so a wide
batch of paths is fitted at once (:func:`fit_path`), which is what finds the
global minimum among the fit's many local ones.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..path import bernstein_matrix
from ..priors import gradient_yx
from ._adam import Adam
from ._latent import gauss_yx

__all__ = ["PathParam", "GramLoss", "SumLoss", "fit_path", "FIT_REPORT_EVERY", "FIT_RTOL", "FIT_PATIENCE"]

#: Adam steps of the path fit between two progress reports
FIT_REPORT_EVERY = 10
#: the path fit stops when its best fit improved by less than this (relative) in FIT_PATIENCE steps
FIT_RTOL = 1e-6
FIT_PATIENCE = 30


class PathParam:
    """Free control points ``q`` ([B,] n, 3) mapped to centred, boxed control points.

    ``control_points()`` is ``q`` re-centred (zero mean over ``n_times``
    instants, the gauge), differentiably; :meth:`project` keeps ``q`` itself
    centred and within ``+-box`` in ``x, y`` and ``+-z_box`` in ``z``. With
    ``free_z=False`` the ``z`` components are 0 and get no gradient.
    """

    def __init__(self, cp0: np.ndarray, n_times: int, box: float, device, dtype=torch.float32,
                 free_z: bool = True, z_box: float | None = None):
        self.n_times = n_times
        self.z_box = box if z_box is None else z_box
        self.box = box
        mean_row = bernstein_matrix(np.shape(cp0)[-2], n_times).mean(axis=0)  # positions mean = mean_row @ cp
        self.mean_row = torch.as_tensor(mean_row, dtype=dtype, device=device)
        self.q = torch.as_tensor(np.asarray(cp0, dtype=np.float64), dtype=dtype, device=device).clone()
        if not free_z:
            with torch.no_grad():
                self.q[..., 2] = 0.0
        self.q.requires_grad_(True)
        if not free_z:
            mask = torch.tensor([1.0, 1.0, 0.0], dtype=dtype, device=device)
            self.q.register_hook(lambda grad: grad * mask)

    def control_points(self) -> torch.Tensor:
        return self.q - (self.mean_row @ self.q).unsqueeze(-2)

    @torch.no_grad()
    def project(self):
        """Re-centre and clamp into the box (in place)."""
        self.q.sub_((self.mean_row @ self.q).unsqueeze(-2))
        self.q[..., :2].clamp_(-self.box, self.box)
        self.q[..., 2].clamp_(-self.z_box, self.z_box)
        self.q.sub_((self.mean_row @ self.q).unsqueeze(-2))
        # re-centring can push a point out again by a little: shrink such paths about their
        # (zero) mean, which keeps the gauge
        for sl, lim in ((slice(0, 2), self.box), (slice(2, 3), self.z_box)):
            big = self.q[..., sl].abs().amax(dim=(-1, -2), keepdim=True)
            self.q[..., sl].mul_((lim / big.clamp_min(1e-12)).clamp(max=1.0))

    def numpy(self) -> np.ndarray:
        return self.control_points().detach().cpu().double().numpy()


def _select_pixels(score: np.ndarray, n_pixels: int, rng, tiles: int, weight):
    """Pixels of the fit, stratified: the same number from every tile, favouring strong gradients.

    ``score`` is (Y-1, X-1); returns the flat indices into it and their tiles.
    """
    Y1, X1 = score.shape
    ty = np.minimum((np.arange(Y1) * tiles) // Y1, tiles - 1)
    tx = np.minimum((np.arange(X1) * tiles) // X1, tiles - 1)
    tile_of = (ty[:, None] * tiles + tx[None, :]).ravel()
    per = max(1, int(n_pixels) // (tiles * tiles))
    sel, sel_tile = [], []
    flat = score.ravel()
    flat_w = None if weight is None else weight[:Y1, :X1].ravel()
    for t in range(tiles * tiles):
        idx = np.flatnonzero(tile_of == t)
        if idx.size == 0:
            continue
        pr = flat[idx] + 0.05 * flat.mean() + 1e-12
        if flat_w is not None:
            pr = pr * flat_w[idx]
        pr = pr / pr.sum()
        k = min(per, idx.size)
        sel.append(np.sort(rng.choice(idx, size=k, replace=False, p=pr)))
        sel_tile.append(np.full(k, t))
    return np.concatenate(sel), np.concatenate(sel_tile), tile_of


class GramLoss:
    """The gradient-domain path fit ``sum ||grad_yx(K_p l) - grad_yx f||^2`` as a quadratic form.

    With ``d_inf = 0`` the blur of a pixel is a kernel over integer view
    offsets applied to its replicate-padded angular samples: clamped
    bilinear interpolation at ``u + s`` equals ``(1 - w) l[clamp(u + o)] + w
    l[clamp(u + o + 1)]`` with ``o = floor(s)``, ``w = s - o``, for every
    ``s``. The kernel (the splat of the positions ``(s_v, s_u)`` over the
    instants) is shared by all pixels of an in-plane path; with ``p_z`` it
    varies slowly over the image, and is taken constant over each of
    ``tiles x tiles`` tiles (at the tile centre). The spatial differences
    commute with the angular blur, so the fit is

        sum_t  k_t^T G_t k_t - 2 b_t^T k_t + c,

    with ``G_t``, ``b_t`` the Gram matrix and correlation of the shifted
    latent gradients at a subset of pixels of tile ``t``: built once per
    latent (:meth:`set_latent`), after which a path step costs a few small
    products. The shifts only re-index the views, so ``G_t`` and ``b_t``
    are sums of entries of the ``VU x VU`` Gram matrices of the views
    (latent with latent, latent with data), which are all that is computed
    over the pixels. Calling the loss leaves out the constant ``c`` (the
    data's squared gradients), which no path changes; :attr:`offset` holds
    it, so that ``loss(cp) + offset`` is the mean squared residual (>= 0).

    ``frame = (y0, x0, Y_full, X_full)`` says that ``f`` is the window at
    ``(y0, x0)`` of a larger view: the path is then that of the larger view
    (its ``x~, y~``), as in :class:`~napari_lfdeblur.blur.BlurOperator`.
    """

    def __init__(self, f, n_pixels, rng, T, box_xy, box_z, tiles, weight=None, frame=None):
        V, U, Y, X, _ = f.shape
        y0, x0, Yf, Xf = (0, 0, Y, X) if frame is None else frame
        self.V, self.U, self.Y, self.X, self.T = V, U, Y, X, T
        self.R = int(min(max(V, U) - 1, math.floor(box_xy + box_z) + 1))
        R = self.R
        self.nO = 2 * R + 1
        dev, dt = f.device, f.dtype
        gy, gx = gradient_yx(f)
        score = (gy * gy + gx * gx).sum(dim=(0, 1, 4))[: Y - 1, : X - 1].sqrt().cpu().double().numpy()
        sel, sel_tile, tile_of = _select_pixels(score, n_pixels, rng, tiles, weight)
        ys, xs = np.divmod(sel, X - 1)
        self.ys = torch.as_tensor(ys, device=dev)
        self.xs = torch.as_tensor(xs, device=dev)
        self.pix_tile = torch.as_tensor(sel_tile, device=dev)
        self.n_tiles = tiles * tiles
        r = max(Xf, Yf) / 2.0
        cy = np.array([(ys[tile_of[sel] // tiles == i]).mean() if np.any(tile_of[sel] // tiles == i) else 0
                       for i in range(tiles)])
        cx = np.array([(xs[tile_of[sel] % tiles == i]).mean() if np.any(tile_of[sel] % tiles == i) else 0
                       for i in range(tiles)])
        tyc = (y0 + np.repeat(cy, tiles) - (Yf - 1) / 2.0) / r
        txc = (x0 + np.tile(cx, tiles) - (Xf - 1) / 2.0) / r
        self.xt = torch.as_tensor(txc, dtype=dt, device=dev)
        self.yt = torch.as_tensor(tyc, dtype=dt, device=dev)
        # the data's gradients at the pixels: (M, V*U*2)
        self.F = torch.cat([gy[:, :, self.ys, self.xs, 0], gx[:, :, self.ys, self.xs, 0]], dim=0)
        self.F = self.F.permute(2, 0, 1).reshape(len(sel), -1)
        offs = torch.arange(-R, R + 1, device=dev)
        vidx = (torch.arange(V, device=dev)[None, :] + offs[:, None]).clamp(0, V - 1)  # (nO, V)
        uidx = (torch.arange(U, device=dev)[None, :] + offs[:, None]).clamp(0, U - 1)
        # view read by offset o = (ov, ou) for view s = (v, u): (clamp(v + ov), clamp(u + ou)), flat, (nO*nO, VU)
        self.shifted = (vidx[:, None, :, None] * U + uidx[None, :, None, :]).reshape(self.nO * self.nO, V * U)
        self.G = None
        self.scale = 1.0 / max(1, self.F.numel())
        self.offset = 0.0

    @torch.no_grad()
    def set_latent(self, latent, cp=None, robust: float = 0.0, sigma=0.0):
        """Build the quadratic form for ``latent`` (V, U, Y, X, 1) under the edge model ``sigma``.

        With ``cp`` and ``robust > 0`` each pixel is weighted by
        ``1 / (1 + r / (robust * median(r)))``, ``r`` its residual under ``cp``.
        """
        gy, gx = gradient_yx(gauss_yx(latent, sigma))
        M, VU, I = self.ys.shape[0], self.V * self.U, self.shifted
        L = torch.stack([gy[:, :, self.ys, self.xs, 0], gx[:, :, self.ys, self.xs, 0]], dim=0).reshape(2, VU, M)
        F = self.F.reshape(M, 2, VU).permute(1, 2, 0)  # (2, VU, M), as L
        w = torch.ones(M, dtype=latent.dtype, device=latent.device)
        if cp is not None and robust > 0:
            K = self.kernels(torch.as_tensor(np.asarray(cp), dtype=latent.dtype, device=latent.device))
            Kp = K[self.pix_tile]  # (M, nO*nO): each pixel's kernel
            pred = torch.zeros_like(L)
            for o in (K != 0).any(dim=0).nonzero().squeeze(1).tolist():
                pred.addcmul_(L[:, I[o]], Kp[:, o])
            res = ((pred - F) ** 2).sum(dim=(0, 1))
            scale = robust * res.median().clamp_min(1e-20)
            w = 1.0 / (1.0 + res / scale)
        nO2 = I.shape[0]
        G = torch.zeros(self.n_tiles, nO2, nO2, dtype=latent.dtype, device=latent.device)
        b = torch.zeros(self.n_tiles, nO2, dtype=latent.dtype, device=latent.device)
        diag = torch.arange(VU, device=latent.device)
        for t in torch.unique(self.pix_tile).tolist():
            sel = (self.pix_tile == t).nonzero().squeeze(1)
            Lw = L[:, :, sel] * w[sel]
            C = torch.einsum("csm,cqm->sq", Lw, L[:, :, sel])  # the views' Gram matrix, (VU, VU)
            D = torch.einsum("csm,cqm->sq", Lw, F[:, :, sel])  # latent views against data views
            G[t] = C[I[:, None, :], I[None, :, :]].sum(dim=-1)
            b[t] = D[I, diag[None, :]].sum(dim=-1)
        self.G, self.b = G, b
        self.offset = float((F.double().square().sum(dim=(0, 1)) * w.double()).sum()) * self.scale

    def kernels(self, cp):
        """The splat kernels of the tiles, ([B,] n_tiles, nO*nO) for control points ([B,] n, 3)."""
        basis = torch.as_tensor(bernstein_matrix(cp.shape[-2], self.T), dtype=cp.dtype, device=cp.device)
        pos = basis @ cp  # ([B,] T, 3)
        R, nO = self.R, self.nO
        s_u = pos[..., None, :, 0] - self.xt[:, None] * pos[..., None, :, 2]  # ([B,] tiles, T)
        s_v = pos[..., None, :, 1] - self.yt[:, None] * pos[..., None, :, 2]
        s_u = s_u.clamp(-R + 1e-4, R - 1e-4)
        s_v = s_v.clamp(-R + 1e-4, R - 1e-4)
        fu, fv = torch.floor(s_u.detach()), torch.floor(s_v.detach())
        wu, wv = s_u - fu, s_v - fv
        iu, iv = (fu + R).long(), (fv + R).long()
        K = torch.zeros(s_u.shape[:-1] + (nO * nO,), dtype=cp.dtype, device=cp.device)
        for dv, wvv in ((0, 1 - wv), (1, wv)):
            for du, wuu in ((0, 1 - wu), (1, wu)):
                idx = ((iv + dv).clamp(max=nO - 1)) * nO + (iu + du).clamp(max=nO - 1)
                K = K.scatter_add(-1, idx, wvv * wuu)
        return K / self.T

    def __call__(self, cp):
        """The fit of control points ([B,] n, 3) less :attr:`offset`: shape ([B,])."""
        K = self.kernels(cp)
        quad = torch.einsum("...ti,tij,...tj->...", K, self.G, K) - 2.0 * (self.b * K).sum(dim=(-1, -2))
        return quad * self.scale


class SumLoss:
    """The sum of :class:`GramLoss` fits of one path (one light field, or windows of one view; each its own latent)."""

    def __init__(self, parts):
        self.parts = list(parts)

    def set_latent(self, latents, cp=None, robust: float = 0.0, sigma=0.0):
        """:meth:`GramLoss.set_latent` of each part, with its own latent."""
        for part, latent in zip(self.parts, latents, strict=True):
            part.set_latent(latent, cp, robust, sigma)

    def __call__(self, cp):
        return sum(part(cp) for part in self.parts)

    @property
    def offset(self) -> float:
        """The constant the parts' losses leave out (:attr:`GramLoss.offset`)."""
        return sum(part.offset for part in self.parts)


def fit_path(pp: PathParam, loss_fn, steps: int, lr: float, every: int = FIT_REPORT_EVERY):
    """Adam on a batch of paths for up to ``steps`` steps; returns their final fits, shape (B,).

    A generator: every ``every`` steps it yields ``(step, fit, control_points)``,
    the best current fit of the batch and its control points ((n, 3) float64).
    It stops early when the best fit of the batch has improved by less than
    :data:`FIT_RTOL` (relative) in :data:`FIT_PATIENCE` steps.
    """
    opt = Adam([pp.q], lr=lr)
    best = float("inf")
    stall = 0
    for step in range(1, steps + 1):
        opt.zero_grad()
        with torch.enable_grad():  # whatever the caller's mode (a worker thread may have been left in no_grad)
            each = loss_fn(pp.control_points())
            each.sum().backward()
        opt.step()
        pp.project()
        # stop when the best path of the batch has not improved for a while (the batch's sum
        # is no guide: paths pressed against the box keep it oscillating)
        k = int(torch.argmin(each.detach()))
        loss = float(each[k].detach())
        if step % every == 0 and step < steps:
            yield step, loss, pp.numpy().reshape(-1, *pp.q.shape[-2:])[k]
        if loss < best - FIT_RTOL * abs(best):
            best, stall = loss, 0
        else:
            stall += 1
            if stall >= FIT_PATIENCE:
                break
    with torch.no_grad():
        return loss_fn(pp.control_points())
