"""Procedural light fields of natural textures on layered planes, one scene per seed."""

from __future__ import annotations

import functools
import math
import numbers

import numpy as np
from scipy import ndimage

from .._lightfield import check_infinity_disparity, check_seed, check_view_grid

__all__ = ["procedural_scene", "TEXTURE_IMAGES"]

#: the ``skimage.data`` images the textures are cut from (all ship with scikit-image)
TEXTURE_IMAGES = ("astronaut", "coffee", "chelsea", "rocket", "camera", "brick", "grass", "gravel", "text",
                  "coins", "moon", "page", "immunohistochemistry", "hubble_deep_field")
#: images of fine, repetitive texture: a scene always has at least one layer cut from one of them
FINE_TEXTURES = ("brick", "grass", "gravel", "text", "page")
#: the largest disparity above ``infinity_disparity`` (the nearest layer's), px/view
MAX_DELTA = 1.5
_LUMA = np.array([0.2126, 0.7152, 0.0722])


@functools.lru_cache(maxsize=None)
def _image(name: str) -> np.ndarray:
    """A ``skimage.data`` image as float32 RGB in [0, 1], shape (H, W, 3)."""
    from skimage import data

    img = np.asarray(getattr(data, name)(), dtype=np.float32)
    img = img / (255.0 if img.max() > 1 else 1.0)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=-1)
    img = img[..., :3]
    img.setflags(write=False)
    return img


def _texture(rng, name: str, size: tuple, margin: int, channels: int) -> np.ndarray:
    """A crop of image ``name`` for a ``size = (Y, X)`` view plus ``margin`` px around: scaled, rotated, re-toned.

    The crop is sampled through a random similarity transform (scale 0.35 to 1.6
    source pixels per pixel, any angle), low-passed first when it shrinks the
    image (no aliasing). Grey images get a random tint; about one texture in
    seven is made dark, and as many low in contrast. The random draws depend
    on ``size`` only, not on ``margin``.
    """
    img = _image(name)
    step = float(np.exp(rng.uniform(np.log(0.35), np.log(1.6))))  # source pixels per output pixel
    if step > 1.0:
        img = ndimage.gaussian_filter(img, sigma=(0.5 * step, 0.5 * step, 0))
    angle = rng.uniform(0.0, 2 * np.pi)
    c, s = np.cos(angle) * step, np.sin(angle) * step
    # the view's corners stay inside the image where it is large enough: its half-diagonal in source pixels
    half = 0.5 * math.hypot(*size) * step
    H, W = img.shape[:2]
    cy = rng.uniform(min(half, H / 2), max(H - half, H / 2))
    cx = rng.uniform(min(half, W / 2), max(W - half, W / 2))
    yy, xx = np.mgrid[-margin : size[0] + margin, -margin : size[1] + margin].astype(np.float64)
    yy -= (size[0] - 1) / 2
    xx -= (size[1] - 1) / 2
    coords = np.stack([cy + c * yy - s * xx, cx + s * yy + c * xx])
    tex = np.stack([ndimage.map_coordinates(img[..., k], coords, order=1, mode="mirror") for k in range(3)], -1)
    if np.ptp(img.reshape(-1, 3).mean(0)) < 1e-3 or rng.random() < 0.15:  # grey source, or a colour made grey
        tex = tex.mean(-1, keepdims=True) * rng.uniform(0.5, 1.0, size=3)
    tone = rng.random()
    if tone < 0.15:  # dark
        tex = tex * rng.uniform(0.08, 0.3)
    elif tone < 0.3:  # low contrast
        tex = tex.mean((0, 1)) + (tex - tex.mean((0, 1))) * rng.uniform(0.1, 0.3)
    if channels == 1:
        tex = (tex @ _LUMA)[..., None] if tex.shape[-1] == 3 else tex[..., :1]
    return np.clip(tex, 0.0, 1.0).astype(np.float32)


def _shape_mask(rng, size: tuple, margin: int) -> np.ndarray:
    """Soft alpha of a random union of rotated rectangles, discs and blobs over a view plus ``margin``.

    Shapes are placed relative to the ``size = (Y, X)`` view, so the random draws
    and the shapes do not depend on ``margin``.
    """
    Y, X = size
    yy, xx = np.mgrid[-margin : Y + margin, -margin : X + margin].astype(np.float64)
    mask = np.zeros(yy.shape, dtype=bool)
    for _ in range(int(rng.integers(1, 4))):
        cy, cx = rng.uniform(0.15, 0.85) * Y, rng.uniform(0.15, 0.85) * X
        size = rng.uniform(0.08, 0.3) * min(Y, X)
        kind = rng.integers(3)
        if kind == 0:  # rotated rectangle
            a = rng.uniform(0, np.pi)
            r = (yy - cy) * np.cos(a) + (xx - cx) * np.sin(a)
            t = -(yy - cy) * np.sin(a) + (xx - cx) * np.cos(a)
            mask |= (np.abs(r) < size) & (np.abs(t) < size * rng.uniform(0.3, 2.0))
        elif kind == 1:  # disc
            mask |= (yy - cy) ** 2 + (xx - cx) ** 2 < size**2
        else:  # blob: the level set of a sum of Gaussian bumps around the centre
            field = np.zeros(yy.shape)
            for by, bx, w in zip(*rng.normal(0, 0.8 * size, (2, 6)), rng.uniform(0.5, 1.0, 6)):
                field += w * np.exp(-((yy - cy - by) ** 2 + (xx - cx - bx) ** 2) / (2 * (0.5 * size) ** 2))
            mask |= field > 0.5
    return ndimage.gaussian_filter(mask.astype(np.float32), sigma=0.6)


def _lerp(img: np.ndarray, offset: float, size: int, axis: int) -> np.ndarray:
    """Bilinear sample of ``img`` along ``axis`` at ``offset + k``, ``k = 0 .. size - 1`` (in range)."""
    i = int(np.floor(offset))
    f = np.float32(offset - i)
    a = np.moveaxis(img, axis, 0)
    out = a[i : i + size] * (1 - f)
    out += a[i + 1 : i + size + 1] * f
    return np.moveaxis(out, 0, axis)


def _deltas(rng, n_layers: int) -> np.ndarray:
    """Disparities above infinity, farthest (the background) first: increasing, in (0, MAX_DELTA]."""
    far = rng.uniform(0.03, 0.6)
    near = rng.uniform(max(far + 0.2, 0.6), MAX_DELTA)
    inner = np.sort(rng.uniform(far, near, size=max(n_layers - 2, 0)))
    return np.concatenate([[far], inner, [near]])[:n_layers] if n_layers > 1 else np.array([far])


def _check(shape, seed, infinity_disparity, n_layers) -> tuple:
    """The arguments checked; returns ``(V, U, Y, X)`` as ints."""
    shape = check_view_grid(shape)
    check_seed(seed)
    if not isinstance(infinity_disparity, numbers.Real) or not math.isfinite(infinity_disparity):
        raise ValueError(f"infinity_disparity must be a finite number; got {infinity_disparity!r}")
    check_infinity_disparity(infinity_disparity, shape)
    if n_layers is not None and (not isinstance(n_layers, numbers.Integral) or n_layers < 1):
        raise ValueError(f"n_layers must be a positive int or None; got {n_layers!r}")
    return shape


def procedural_scene(
    shape=(9, 9, 128, 128),
    *,
    seed: int,
    infinity_disparity: float = 0.0,
    color: bool = True,
    n_layers: int | None = None,
):
    """A light field of natural textures on fronto-parallel planes at random depths.

    Each seed gives a different scene: a background plane that fills the view
    and further planes nearer to the camera, each a textured shape (rotated
    rectangles, discs, smooth blobs, or unions of them) that occludes the
    planes behind it. Textures are crops of ``skimage.data`` images
    (:data:`TEXTURE_IMAGES`) at random scale, angle and position, some tinted,
    some dark, some low in contrast; at least one plane carries a fine texture
    (:data:`FINE_TEXTURES`). Every view is rendered exactly from the planes
    (bilinear sampling of each plane, soft alpha edges composited back to
    front), so occlusion and disocclusion are right in every view. The scene
    depends on the seed, the view size and ``color``; ``infinity_disparity``
    moves all of it in depth. One thing more depends on the border the views
    need (which grows with ``infinity_disparity`` and the number of views):
    a texture drawn low in contrast keeps its mean level over the view and
    that border, so its level can differ by a few hundredths between two
    such calls.

    Disparities are physical for ``infinity_disparity = d_inf``: every point is
    nearer than infinity, so plane ``i`` has disparity ``d_inf + delta_i`` with
    ``0 < delta_0 < delta_1 < ... <= 1.5`` px/view, the background the farthest.

    Parameters
    ----------
    shape : tuple of 4 int, default (9, 9, 128, 128)
        ``(V, U, Y, X)``.
    seed : int
        Seed of everything random: the number of planes, their depths,
        textures and shapes.
    infinity_disparity : float, default 0.0
        ``d_inf``, the disparity of points at infinity, px/view (docs/model.md).
    color : bool, default True
        RGB output ``(V, U, Y, X, 3)``; False gives luminance ``(V, U, Y, X)``.
    n_layers : int, optional
        Number of planes, background included (default: 3 to 6, from the seed).

    Returns
    -------
    lf : ndarray, float32, shape (V, U, Y, X, 3) or (V, U, Y, X)
        The light field, values in [0, 1].
    disparity : ndarray, float32, shape (Y, X)
        Disparity of the centre view (the view at the mean angular position),
        px/view, docs/model.md sign: a point at ``x`` in view ``u`` is at
        ``x + d`` in view ``u + 1``. Where planes overlap, the nearest plane
        whose alpha exceeds 0.5.

    Raises
    ------
    ValueError
        On a malformed shape, a bad ``n_layers``, a seed outside ``0 .. 2**63 - 1``, or an
        ``infinity_disparity`` that is not finite or beyond the bound of
        :func:`~napari_lfdeblur.simulate_blur` (``|d_inf| (max(V, U) - 1) / 2 <= min(Y, X) / 2``).
    TypeError
        When ``seed`` is not an int, or ``color`` not a bool.

    See Also
    --------
    synthetic_scene : piecewise-constant textures, disparities set by the caller.

    Examples
    --------
    >>> lf, disp = procedural_scene((5, 5, 32, 32), seed=3, infinity_disparity=-0.5)
    >>> lf.shape, lf.dtype, disp.shape
    ((5, 5, 32, 32, 3), dtype('float32'), (32, 32))
    >>> bool(disp.min() > -0.5)
    True
    """
    V, U, Y, X = _check(shape, seed, infinity_disparity, n_layers)
    if not isinstance(color, (bool, np.bool_)):  # 'no' would be true
        raise TypeError(f"color must be True or False; got {color!r}")
    d_inf = float(infinity_disparity)
    rng = np.random.default_rng([seed, 0x1F5CE])
    n = int(rng.integers(3, 7)) if n_layers is None else int(n_layers)
    disparities = d_inf + _deltas(rng, n)
    names = list(rng.choice(TEXTURE_IMAGES, size=n))
    names[int(rng.integers(n))] = str(rng.choice(FINE_TEXTURES))
    channels = 3 if color else 1

    vc = np.arange(V) - (V - 1) / 2
    uc = np.arange(U) - (U - 1) / 2
    margin = int(np.ceil(np.max(np.abs(disparities)) * max(V, U) / 2)) + 2
    H, W = Y + 2 * margin, X + 2 * margin

    out = np.zeros((V, U, Y, X, channels), dtype=np.float32)
    disparity = np.full((Y, X), disparities[0], dtype=np.float32)
    for i, d in enumerate(disparities):
        alpha = np.ones((H, W), np.float32) if i == 0 else _shape_mask(rng, (Y, X), margin)
        # plane texture and alpha together: view (v, u) sees the centre-view point (y0, x0) at (y0 + d v_c, x0 + d u_c)
        layer = np.concatenate([_texture(rng, str(names[i]), (Y, X), margin, channels), alpha[..., None]], axis=-1)
        for v in range(V):
            rows = _lerp(layer, margin - d * vc[v], Y, axis=0)  # view row v samples y - d v_c
            for u in range(U):
                s = _lerp(rows, margin - d * uc[u], X, axis=1)
                if i == 0:
                    out[v, u] = s[..., :-1]
                else:  # composite over what is behind: out += alpha (layer - out)
                    s[..., :-1] -= out[v, u]
                    s[..., :-1] *= s[..., -1:]
                    out[v, u] += s[..., :-1]
        disparity[alpha[margin : margin + Y, margin : margin + X] > 0.5] = d
    np.clip(out, 0.0, 1.0, out=out)
    return (out if color else out[..., 0]), disparity
