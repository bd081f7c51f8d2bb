"""Disparity of a light field, and the resampling it shares with the blind solver's path stage.

Grayscale, refocus (shear), spatial area-averaging, and the per-pixel
disparity map: the shear that makes the views agree best.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from . import _fused
from .blur import lerp_taps

__all__ = ["gray", "shear_taps", "shear", "shear_spectral", "downsample", "disparity_map", "scene_disparity",
           "DISPARITY_STEP", "DISPARITY_REACH"]


def gray(f: torch.Tensor) -> torch.Tensor:
    """The mean over the colour axis of (V, U, Y, X, C), kept as a length-1 axis."""
    return f.mean(dim=-1, keepdim=True)


def shear_taps(shape, d: float, dtype, device):
    """The bilinear taps of :func:`shear` by ``d`` for light fields of ``shape`` (V, U, Y, X[, C]).

    Returns ``(ty, tx)``: ``ty`` a list over the view rows ``v`` of
    ``(y0, y1, wy)``, each of shape (Y,), and ``tx`` the ``(x0, x1, wx)`` of
    every view column, each (U, X), as :func:`~napari_lfdeblur.blur.lerp_taps`
    gives them.
    """
    V, U, Y, X = shape[:4]
    ys = torch.arange(Y, dtype=dtype, device=device)
    ty = [lerp_taps(ys + d * (v - (V - 1) / 2.0), Y) for v in range(V)]
    shift = torch.tensor([d * (u - (U - 1) / 2.0) for u in range(U)], dtype=dtype, device=device)  # px, per column
    tx = lerp_taps(torch.arange(X, dtype=dtype, device=device)[None, :] + shift[:, None], X)  # (U, X)
    return ty, tx


def shear(f: torch.Tensor, d: float) -> torch.Tensor:
    """Refocus: view ``(v, u)`` resampled at ``(y + d v_c, x + d u_c)`` (bilinear, replicate).

    ``f`` is (V, U, Y, X, C); ``v_c, u_c`` are the view offsets from the
    centre. With ``d = d_inf`` this maps the blur model with ``d_inf`` to the
    one with ``d_inf = 0`` (up to interpolation): the path estimate runs on
    the sheared light field.
    """
    V, U, Y, X, C = f.shape
    dev = f.device
    ty, (x0, x1, wx) = shear_taps(f.shape, d, f.dtype, dev)
    # one lookup reads the columns of every view in a row of views: an index into the flattened (u, x) axis
    first = (torch.arange(U, device=dev) * X)[:, None]
    ix0, ix1 = (x0 + first).view(-1), (x1 + first).view(-1)
    wx1 = wx.reshape(1, U * X, 1)
    wx0 = 1 - wx1
    out = torch.empty_like(f)
    for v, (y0, y1, wy) in enumerate(ty):
        fv = f[v].permute(1, 0, 2, 3)  # (Y, U, X, C)
        rows = fv.index_select(0, y0) * (1 - wy)[:, None, None, None] + fv.index_select(0, y1) * wy[:, None, None, None]
        rows = rows.reshape(Y, U * X, C)
        cols = rows.index_select(1, ix0) * wx0 + rows.index_select(1, ix1) * wx1
        out[v] = cols.view(Y, U, X, C).permute(1, 0, 2, 3)
    return out


def shear_spectral(f: torch.Tensor, d: float) -> torch.Tensor:
    """Refocus as :func:`shear` does, without its interpolation blur.

    View ``(v, u)`` is resampled at ``(y + d v_c, x + d u_c)``: the whole
    pixels of each shift are taken as :func:`shear` takes them (the same
    result wherever ``d v_c`` and ``d u_c`` are whole, replicate boundary),
    the fraction left (at most half a pixel) by a Fourier shift of the view's
    mirrored extension, which keeps every frequency below the Nyquist
    frequency at full contrast. Bilinear interpolation at a shift of half a
    pixel halves the contrast of a period of 3 px and averages a period of
    2 px away; in a path stage, where the views' shifts are fractions of a
    pixel that differ from view to view, that loss reads as a blur.

    ``f`` is (V, U, Y, X, C); returns the same shape and dtype.
    """
    V, U, Y, X, C = f.shape
    dev, d = f.device, float(d)  # a numpy scalar would turn the phase ramps below into numpy arrays
    offsets_v = [d * (v - (V - 1) / 2.0) for v in range(V)]
    offsets_u = [d * (u - (U - 1) / 2.0) for u in range(U)]
    whole_v, whole_u = [round(s) for s in offsets_v], [round(s) for s in offsets_u]
    # whole pixels: clamped indices, as shear's taps with weights 0 and 1
    rows = [torch.clamp(torch.arange(Y, device=dev) + n, 0, Y - 1) for n in whole_v]
    cols = torch.clamp(torch.arange(X, device=dev)[None, :] + torch.tensor(whole_u, device=dev)[:, None], 0, X - 1)
    frac_u = torch.tensor([s - n for s, n in zip(offsets_u, whole_u)], dtype=torch.float64, device=dev)
    cdtype = torch.complex128 if f.dtype == torch.float64 else torch.complex64
    ky = torch.fft.fftfreq(2 * Y, dtype=torch.float64, device=dev)
    kx = torch.fft.rfftfreq(2 * X, dtype=torch.float64, device=dev)
    ramp_x = torch.exp(2j * math.pi * frac_u[:, None] * kx[None, :]).to(cdtype)[:, None, None, :]  # (U, 1, 1, X + 1)
    whole_u_only = not bool(frac_u.any())
    out = torch.empty_like(f)
    for v in range(V):
        g = f[v].index_select(1, rows[v])  # (U, Y, X, C)
        g = torch.stack([g[u].index_select(1, cols[u]) for u in range(U)])
        frac_v = offsets_v[v] - whole_v[v]
        if frac_v == 0 and whole_u_only:
            out[v] = g
            continue
        g = g.permute(0, 3, 1, 2)  # (U, C, Y, X)
        g = torch.cat([g, g.flip(-1)], dim=-1)
        g = torch.cat([g, g.flip(-2)], dim=-2)  # the mirrored extension: periodic without a jump
        spectrum = torch.fft.rfft2(g)
        spectrum *= torch.exp(2j * math.pi * frac_v * ky).to(cdtype)[:, None]
        spectrum *= ramp_x
        out[v] = torch.fft.irfft2(spectrum, s=(2 * Y, 2 * X))[..., :Y, :X].permute(0, 2, 3, 1)
    return out


def _view_variances(f: torch.Tensor, shears) -> torch.Tensor:
    """(n, Y, X): the variance over the views of ``f`` (V, U, Y, X, 1) sheared by each of ``shears``.

    On the CPU, by the fused loop (:func:`~napari_lfdeblur._fused.view_variance`)
    with :func:`shear_taps`' taps stacked over the shears.
    """
    taps = [shear_taps(f.shape, d, f.dtype, f.device) for d in shears]
    ys = [np.stack([np.stack([t[i].numpy() for t in ty]) for ty, _ in taps]) for i in range(3)]  # (n, V, Y)
    xs = [np.stack([tx[i].numpy() for _, tx in taps]) for i in range(3)]  # (n, U, X)
    return _fused.view_variance(f, *ys, *xs)


def downsample(f: torch.Tensor, factor: int) -> torch.Tensor:
    """Area-average the spatial axes of (V, U, Y, X, C) by ``factor`` (views untouched)."""
    if factor == 1:
        return f
    V, U, Y, X, C = f.shape
    Yc, Xc = (Y // factor) * factor, (X // factor) * factor
    g = f[:, :, :Yc, :Xc].reshape(V, U, Yc // factor, factor, Xc // factor, factor, C)
    return g.mean(dim=(3, 5))


@torch.no_grad()
def disparity_map(f: torch.Tensor, d_max: float = 2.5, n: int = 41, smooth: int = 2) -> np.ndarray:
    """Per-pixel disparity (px/view) of a (blurred) light field (V, U, Y, X, 1).

    The shear, among ``n`` in ``[-d_max, d_max]``, that makes the views agree
    best (least angular variance, box-smoothed over ``2 smooth + 1`` px).
    An in-plane blur keeps the views consistent at the scene's disparity.

    Returns
    -------
    ndarray, float32, shape (Y, X)
    """
    best = torch.full(f.shape[2:4], math.inf, dtype=f.dtype, device=f.device)
    arg = torch.zeros_like(best)
    shears = [float(d) for d in np.linspace(-d_max, d_max, n)]
    fused = _view_variances(f, shears) if _fused.available(f.device, f.dtype) else None
    for k, d in enumerate(shears):
        var = fused[k] if fused is not None else shear(f, d).var(dim=(0, 1))[..., 0]  # (Y, X)
        var = torch.nn.functional.avg_pool2d(var[None, None], 2 * smooth + 1, stride=1, padding=smooth,
                                             count_include_pad=False)[0, 0]
        better = var < best
        best = torch.where(better, var, best)
        arg = arg.masked_fill(better, float(d))
    return arg.cpu().numpy()


#: the spacing (px/view) of the shears :func:`scene_disparity` tries
DISPARITY_STEP = 0.125
#: the disparities :func:`scene_disparity` tries reach this far (px/view) beyond ``|d_inf|``
DISPARITY_REACH = 2.5


def scene_disparity(f: torch.Tensor, infinity_disparity: float = 0.0) -> np.ndarray:
    """The per-pixel disparity (px/view) of ``f`` (V, U, Y, X, C) that the TV's angular differences follow.

    Among the shears ``|d| <= DISPARITY_REACH + |d_inf|`` in steps of
    ``DISPARITY_STEP``, the one that makes the views of the grayscale agree
    best at each pixel (box-smoothed variance over the views). Returns
    float32 of shape (Y, X).
    """
    reach = DISPARITY_REACH + abs(float(infinity_disparity))
    n = 2 * int(math.ceil(reach / DISPARITY_STEP)) + 1
    return disparity_map(gray(f), d_max=DISPARITY_STEP * (n // 2), n=n)
