"""A procedural light field of a layered 3D scene."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .._lightfield import check_infinity_disparity, check_int, check_number, check_seed, check_view_grid

__all__ = ["synthetic_scene"]


def _texture(rng, height, width, channels):
    """A piecewise-constant texture of random rectangles and discs, lightly smoothed."""
    tex = np.empty((height, width, channels))
    tex[:] = rng.uniform(0.2, 0.8, size=channels)
    yy, xx = np.mgrid[0:height, 0:width]
    n_shapes = max(6, (height * width) // 120)
    for _ in range(n_shapes):
        colour = rng.uniform(0.0, 1.0, size=channels)
        cy, cx = rng.uniform(0, height), rng.uniform(0, width)
        size = rng.uniform(2.0, 0.18 * min(height, width) + 2.0)
        if rng.random() < 0.5:
            aspect = rng.uniform(0.3, 3.0)
            mask = (np.abs(yy - cy) < size * aspect**0.5) & (np.abs(xx - cx) < size / aspect**0.5)
        else:
            mask = (yy - cy) ** 2 + (xx - cx) ** 2 < size**2
        tex[mask] = colour
    return ndimage.gaussian_filter(tex, sigma=(0.6, 0.6, 0))


def _mask(rng, height, width):
    """A random blob: the union of a few discs and rectangles, with soft edges."""
    yy, xx = np.mgrid[0:height, 0:width]
    mask = np.zeros((height, width), dtype=bool)
    for _ in range(int(rng.integers(1, 4))):
        cy = rng.uniform(0.2, 0.8) * height
        cx = rng.uniform(0.2, 0.8) * width
        size = rng.uniform(0.12, 0.25) * min(height, width)
        if rng.random() < 0.5:
            mask |= (yy - cy) ** 2 + (xx - cx) ** 2 < size**2
        else:
            mask |= (np.abs(yy - cy) < size) & (np.abs(xx - cx) < size * rng.uniform(0.5, 1.5))
    return ndimage.gaussian_filter(mask.astype(float), sigma=0.6)


def _check_disparity_range(disparity_range, shape):
    """``(d_far, d_near)`` as floats: two finite numbers, the farthest first, each within the bound."""
    try:
        d_far, d_near = disparity_range
    except (TypeError, ValueError):
        raise ValueError(f"disparity_range must be two numbers (farthest, nearest); got {disparity_range!r}") from None
    d_far, d_near = (check_number(d, "disparity_range") for d in (d_far, d_near))
    if d_far > d_near:
        raise ValueError(f"disparity_range must give the farthest layer's disparity first (a nearer layer has the "
                         f"larger disparity); got {disparity_range!r}")
    for d in (d_far, d_near):
        try:
            check_infinity_disparity(d, shape)
        except ValueError:
            raise ValueError(f"disparity_range: {d:g} px/view would shift the outermost views by more than half "
                             f"the view ({shape[2]} x {shape[3]})") from None
    return d_far, d_near


def synthetic_scene(
    shape=(9, 9, 64, 64),
    n_layers: int = 3,
    color: bool = False,
    seed: int | None = 0,
    disparity_range=(0.25, 1.5),
):
    """A light field of textured fronto-parallel layers at different disparities.

    Layer 0 is a background that fills the view; each further layer is a
    textured blob nearer to the camera, with a larger disparity, that
    occludes the layers behind it. Every view is rendered exactly from the
    layer textures (bilinear sampling, soft alpha edges composited back to
    front), so occlusion and disocclusion are correct across views.

    Parameters
    ----------
    shape : tuple of int, default (9, 9, 64, 64)
        ``(V, U, Y, X)``.
    n_layers : int, default 3
        Number of depth layers, >= 1.
    color : bool, default False
        RGB output ``(V, U, Y, X, 3)`` instead of grayscale.
    seed : int or None, default 0
        Seed of the random textures, shapes and disparities.
    disparity_range : (float, float), default (0.25, 1.5)
        Disparities of the farthest and the nearest layer, px/view, the
        farthest first (a nearer layer has the larger disparity); the
        layers in between are evenly spaced. Each within the bound of
        :func:`~napari_lfdeblur.simulate_blur`'s ``infinity_disparity``,
        ``|d| (max(V, U) - 1) / 2 <= min(Y, X) / 2``.

    Returns
    -------
    lf : ndarray, float32, shape (V, U, Y, X) or (V, U, Y, X, 3)
        The light field, values in [0, 1].
    disparity : ndarray, float32, shape (Y, X)
        Ground-truth disparity of the centre view (px/view, docs/model.md sign:
        a point at ``x`` in view ``u`` is at ``x + d`` in view ``u + 1``).

    Raises
    ------
    ValueError
        On a malformed shape, ``n_layers < 1``, a seed outside ``0 .. 2**63 - 1``, or a
        ``disparity_range`` that is not two finite numbers, farthest first, within the bound.
    TypeError
        When ``n_layers`` or ``seed`` is not an integer, a disparity not a number, or ``color`` not a bool.

    Examples
    --------
    >>> lf, disp = synthetic_scene((5, 5, 32, 32), n_layers=2, seed=1)
    >>> lf.shape, disp.shape
    ((5, 5, 32, 32), (32, 32))
    """
    V, U, Y, X = check_view_grid(shape)
    n_layers = check_int(n_layers, "n_layers", 1)
    rng = np.random.default_rng(None if seed is None else check_seed(seed))
    if not isinstance(color, (bool, np.bool_)):  # 'no' would be true
        raise TypeError(f"color must be True or False; got {color!r}")
    channels = 3 if color else 1
    d_far, d_near = _check_disparity_range(disparity_range, (V, U, Y, X))
    disparities = np.linspace(d_far, d_near, n_layers) if n_layers > 1 else np.array([d_far])

    vc = np.arange(V) - (V - 1) / 2
    uc = np.arange(U) - (U - 1) / 2
    margin = int(np.ceil(np.max(np.abs(disparities)) * max(V, U) / 2)) + 3
    H, W = Y + 2 * margin, X + 2 * margin

    out = np.zeros((V, U, Y, X, channels))
    disparity = np.full((Y, X), disparities[0], dtype=np.float32)
    for i, d in enumerate(disparities):
        tex = _texture(rng, H, W, channels)
        alpha = np.ones((H, W)) if i == 0 else _mask(rng, H, W)
        # view (v, u) sees the centre-view point (y0, x0) at (y0 + d v_c, x0 + d u_c)
        ys = np.arange(Y)[None, None, :, None] - d * vc[:, None, None, None] + margin
        xs = np.arange(X)[None, None, None, :] - d * uc[None, :, None, None] + margin
        ys, xs = np.broadcast_arrays(ys, xs)
        coords = np.stack([ys, xs])
        a = ndimage.map_coordinates(alpha, coords, order=1, mode="nearest")[..., None]
        layer = np.stack(
            [ndimage.map_coordinates(tex[..., c], coords, order=1, mode="nearest") for c in range(channels)],
            axis=-1,
        )
        out = a * layer + (1 - a) * out
        centre = alpha[margin : margin + Y, margin : margin + X] > 0.5
        disparity[centre] = d
    out = np.clip(out, 0.0, 1.0).astype(np.float32)
    return (out if color else out[..., 0]), disparity
