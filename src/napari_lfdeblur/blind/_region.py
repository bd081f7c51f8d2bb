"""Where the path is estimated on a large light field: the window that conditions the fit best.

The camera path is one for the whole light field, so it can be estimated on
part of it and used everywhere. The path fit needs two things of its pixels:
edges in more than one direction (an edge constrains the blur only across
itself, so a window of parallel edges leaves the path's component along them
free), and disparity away from the infinity disparity (the blur of a point
scales with ``|d - d_inf|``: points at infinity are not blurred by a
translation at all). :func:`choose_region` scores every window by the sum,
over its pixels, of the smaller eigenvalue of the centre view's structure
tensor (large only where the gradients span two directions; Shi & Tomasi,
1994) times the fit's own disparity weight, and picks the best;
:func:`choose_regions` picks the best of each part of the view, so that the
windows spread over it.

:func:`~napari_lfdeblur.path.path_in_frame` carries the path found on the
window over to the full frame.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from scipy import ndimage

from ._disparity import disparity_weights

__all__ = ["choose_region", "choose_regions", "region_grid", "region_score", "STRUCTURE_SIGMA"]

#: Gaussian (px) integrating the structure tensor
STRUCTURE_SIGMA = 2.0


def region_score(g: torch.Tensor, disparity_power: float) -> np.ndarray:
    """Per-pixel score of the path fit's conditioning, (Y, X) float64.

    Parameters
    ----------
    g : torch.Tensor, shape (V, U, Y, X, 1)
        Grayscale light field in the ``d_inf = 0`` model (refocused by ``d_inf``).
    disparity_power : float
        The fit's ``disparity_weight``; 0 scores the edges alone.

    Returns
    -------
    ndarray, float64, shape (Y, X)
        Smaller eigenvalue of the centre view's structure tensor, times the
        disparity weight of :func:`~napari_lfdeblur.blind._disparity.disparity_weights`.
    """
    V, U = g.shape[:2]
    c = g[V // 2, U // 2, :, :, 0].detach().cpu().double().numpy()
    gy, gx = np.gradient(c)
    jxx = ndimage.gaussian_filter(gx * gx, STRUCTURE_SIGMA)
    jyy = ndimage.gaussian_filter(gy * gy, STRUCTURE_SIGMA)
    jxy = ndimage.gaussian_filter(gx * gy, STRUCTURE_SIGMA)
    lam_min = 0.5 * (jxx + jyy) - np.sqrt(0.25 * (jxx - jyy) ** 2 + jxy**2)
    score = np.maximum(lam_min, 0.0)
    if disparity_power > 0:
        score = score * disparity_weights(g, disparity_power)
    return score


def choose_region(g: torch.Tensor, size: int, disparity_power: float, margin: int = 0) -> tuple[int, int, int, int]:
    """The ``size x size`` window (clipped to the view) with the largest total :func:`region_score`.

    Candidate corners lie on a grid of step ``max(1, size // 8)`` px, the last
    one flush with the far edge, and the window keeps ``margin`` px from the
    view's edges where the view is large enough.

    Parameters
    ----------
    g : torch.Tensor, shape (V, U, Y, X, 1)
    size : int
        Window side, px (>= 1).
    disparity_power : float
    margin : int
        Px to keep from the edges: where ``g`` was refocused by ``d_inf``, the
        outer views' samples within ``|d_inf| (max(V, U) - 1) / 2`` px of the
        edge were read beyond it (clamped), and they mislead the fit.

    Returns
    -------
    y0, x0, height, width : int
        The window, inside the view.
    """
    return choose_regions(g, size, disparity_power, margin, 1)[0]


def region_grid(Y: int, X: int, size: int, n: int) -> tuple[int, int]:
    """``(rows, cols)`` of the grid of cells :func:`choose_regions` picks one window from each of.

    ``rows * cols <= n``, each cell at least ``size`` px on each side (so the
    windows do not overlap), and the cells as near square as ``n`` allows:
    ``rows`` the largest divisor of ``n`` not above ``sqrt(n)``, along the
    shorter side of the view.
    """
    a = max(r for r in range(1, math.isqrt(max(n, 1)) + 1) if n % r == 0)
    short, long_ = (a, n // a)
    rows, cols = (short, long_) if Y <= X else (long_, short)
    return max(1, min(rows, Y // max(size, 1))), max(1, min(cols, X // max(size, 1)))


def choose_regions(g: torch.Tensor, size: int, disparity_power: float, margin: int = 0,
                   n: int = 1) -> list[tuple[int, int, int, int]]:
    """Up to ``n`` windows spread over the view: the best of :func:`choose_region` in each cell of a grid.

    Out-of-plane motion (``p_z``) blurs each part of the view by a different
    amount, in proportion to its distance from the centre, so windows far
    apart constrain it far better than one window of as many pixels. The
    view is cut into :func:`region_grid` cells and the window with the
    largest total :func:`region_score` is chosen inside each (where a cell is
    smaller than the window, the window may reach into its neighbours).

    Parameters
    ----------
    g, size, disparity_power, margin
        As in :func:`choose_region`.
    n : int
        The number of windows wanted (>= 1); fewer where the view holds fewer
        cells of ``size`` px.

    Returns
    -------
    list of (y0, x0, height, width)
        Row by row; a single ``(0, 0, Y, X)`` when the view is no larger than
        the window.
    """
    Y, X = g.shape[2:4]
    h, w = min(size, Y), min(size, X)
    if (h, w) == (Y, X):
        return [(0, 0, Y, X)]
    s = region_score(g, disparity_power)
    integral = np.zeros((Y + 1, X + 1))
    integral[1:, 1:] = s.cumsum(axis=0).cumsum(axis=1)
    step = max(1, size // 8)

    def corners(n_px, m, a, b):
        """Corners of an ``m``-px window along an axis of ``n_px``, inside the cell ``[a, b)`` (so that the
        windows are disjoint) and ``margin`` px from the view's edges, or centred in the cell where it cannot
        keep the margin (a cell smaller than the window: centred on the view)."""
        lo, hi = max(a, margin), min(b, n_px - margin) - m
        if hi < lo:
            lo = hi = max(0, a + (min(b, n_px) - a - m) // 2) if b - a >= m else max(0, (n_px - m) // 2)
        return np.unique(np.r_[np.arange(lo, hi + 1, step), hi])

    rows, cols = region_grid(Y, X, size, n)
    out = []
    for r in range(rows):
        for c in range(cols):
            ys = corners(Y, h, r * Y // rows, (r + 1) * Y // rows)
            xs = corners(X, w, c * X // cols, (c + 1) * X // cols)
            total = (integral[ys[:, None] + h, xs[None, :] + w] - integral[ys[:, None], xs[None, :] + w]
                     - integral[ys[:, None] + h, xs[None, :]] + integral[ys[:, None], xs[None, :]])
            i, j = np.unravel_index(int(np.argmax(total)), total.shape)
            out.append((int(ys[i]), int(xs[j]), h, w))
    return out
