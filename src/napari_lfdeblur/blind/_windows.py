"""Where the path is estimated: the windows of the view the path stage works on, chosen or given.

On views larger than ``BlindParams.path.region`` the path stage works on a few
windows that :func:`~napari_lfdeblur.blind._region.choose_regions` picks
(textured, with depth range); the caller may name them instead
(``blind_deblur(windows=...)``), for instance to keep the estimate off a
moving subject, whose blur is not the camera's. The path stage's previews
are pasted back into the whole view here too.
"""

from __future__ import annotations

import math
import operator

import numpy as np
import torch

from ..blur import to_tensor
from ._disparity import gray, shear, shear_spectral
from ._params import BlindParams
from ._region import choose_regions

__all__ = ["MIN_WINDOW", "check_windows", "path_windows", "stage_preview"]

#: the smallest side (px) of a window the caller names
MIN_WINDOW = 16


def check_windows(windows, shape, p: BlindParams):
    """``windows`` as a list of ``(y0, x0, h, w)`` int tuples inside views of ``shape`` (V, U, Y, X[, C]).

    None stays None (the windows are chosen). Each window is at least
    :data:`MIN_WINDOW` px on each side and lies inside the view; one window
    only for the ``'6dof'`` motion and the ``'joint'`` method
    (``p.path_windows()``).

    Raises
    ------
    ValueError
        On an empty list, a window that is not four whole numbers, one that
        is too small or reaches outside the view, windows that overlap, or
        too many windows.
    """
    if windows is None:
        return None
    Y, X = (int(s) for s in shape[2:4])
    try:
        out = [tuple(operator.index(v) for v in w) for w in windows]
    except TypeError:
        raise ValueError(f"windows must be a list of (y0, x0, height, width), whole numbers; got {windows!r}") from None
    if not out or any(len(w) != 4 for w in out):
        raise ValueError(f"windows must be a non-empty list of (y0, x0, height, width); got {windows!r}")
    for y0, x0, h, w in out:
        if min(h, w) < MIN_WINDOW:
            raise ValueError(f"window {(y0, x0, h, w)} (y0, x0, height, width) is smaller than {MIN_WINDOW} x "
                             f"{MIN_WINDOW} px: too little to estimate a camera motion on")
        if y0 < 0 or x0 < 0 or y0 + h > Y or x0 + w > X:
            raise ValueError(f"window {(y0, x0, h, w)} (y0, x0, height, width) reaches outside the {Y} x {X} views")
    if len(out) > 1 and p.path_windows() == 1:
        raise ValueError(f"motion={p.motion!r} with method={p.method!r} estimates the path on one window; got "
                         f"{len(out)}")
    for i, a in enumerate(out):  # the agreement check deals the windows out into two parts, which must be disjoint
        for b in out[i + 1 :]:
            if a[0] < b[0] + b[2] and b[0] < a[0] + a[2] and a[1] < b[1] + b[3] and b[1] < a[1] + a[3]:
                raise ValueError(f"windows {a} and {b} (y0, x0, height, width) overlap: the windows must be "
                                 "disjoint (the check of a weak estimate compares parts of the data estimated apart)")
    return out


@torch.no_grad()
def stage_preview(latents, fac: int, shape, unshear: float, offsets=((0, 0),)) -> np.ndarray:
    """Path-stage latents (V, U, y, x, 1) at level ``fac`` as a light field of the input's ``shape``.

    Nearest upsampling, the first latent placed at the first of ``offsets``
    (the top-left pixel of the window the path is estimated on) and
    edge-padded to the full size, the others pasted at theirs, the refocus
    of the path stage undone when ``unshear`` is not 0, clipped to [0, 1]
    and repeated over the colour channels: float32, ``shape``.
    """
    V, U, Y, X = shape[:4]
    ups = []
    for latent in latents:
        lat = latent.detach()[..., 0]
        if fac > 1:
            lat = lat.repeat_interleave(fac, dim=2).repeat_interleave(fac, dim=3)
        ups.append(lat)
    lat = ups[0]
    y, x = lat.shape[2:4]
    if (y, x) != (Y, X):
        oy, ox = offsets[0]
        lat = torch.nn.functional.pad(lat.reshape(V * U, 1, y, x), (ox, X - x - ox, oy, Y - y - oy),
                                      mode="replicate")
        lat = lat.reshape(V, U, Y, X)
        for other, (oy, ox) in zip(ups[1:], offsets[1:]):
            h, w = other.shape[2:4]
            lat[:, :, oy : oy + h, ox : ox + w] = other
    if unshear != 0.0:
        lat = shear(lat[..., None], -unshear)[..., 0]
    out = lat.clamp(0.0, 1.0).to(device="cpu", dtype=torch.float32).numpy()
    if len(shape) == 5:
        out = np.repeat(out[..., None], shape[4], axis=-1)
    return np.ascontiguousarray(out, dtype=np.float32)


def path_windows(arr, d_inf, p: BlindParams, dev, sheared, windows=None):
    """The grayscale light fields the path is estimated on, and their windows ``(y0, x0, h, w)`` in the view.

    Refocused by ``d_inf`` when ``sheared`` (the path fit then uses the
    ``d_inf = 0`` model); cut to ``windows`` when given (as
    :func:`check_windows` returns them), else to
    :func:`~napari_lfdeblur.blind._region.choose_regions`' windows
    (``p.path_windows()`` of them) when the views are larger than
    ``p.path.region``.
    """
    Y, X = arr.shape[2:4]
    g = gray(to_tensor(arr, dev)).contiguous()
    if sheared:
        g = shear_spectral(g, d_inf)
    if windows is None and not p.path.region:
        return [g], [(0, 0, Y, X)]
    if windows is None:
        margin = math.ceil(abs(d_inf) * (max(arr.shape[:2]) - 1) / 2.0)  # refocused samples read beyond the edge
        windows = choose_regions(g, p.path.region, p.path.disparity_weight, margin, p.path_windows())
    if windows == [(0, 0, Y, X)]:
        return [g], windows
    return [g[:, :, y0 : y0 + h, x0 : x0 + w].contiguous() for y0, x0, h, w in windows], windows
