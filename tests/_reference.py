"""Independent brute-force reference of the MODEL.md forward model, for tests only.

Deliberately naive: a Python loop over instants and a per-ray bilinear lookup
with clamping, written from MODEL.md without reusing any package code.
"""

import math

import numpy as np


def bezier_reference(cp, t):
    cp = np.asarray(cp, dtype=np.float64)
    n = len(cp) - 1
    return sum(math.comb(n, i) * t**i * (1 - t) ** (n - i) * cp[i] for i in range(n + 1))


def _lerp_axis(arr, axis, coord):
    """Sample ``arr`` along ``axis`` at per-element coordinates ``coord`` (clamped, linear)."""
    size = arr.shape[axis]
    c = np.clip(coord, 0, size - 1)
    i0 = np.floor(c).astype(int)
    i1 = np.minimum(i0 + 1, size - 1)
    w = c - i0
    a0 = np.take_along_axis(arr, i0, axis=axis)
    a1 = np.take_along_axis(arr, i1, axis=axis)
    return (1 - w) * a0 + w * a1


def blur_reference(lf, cp, n_times, d_inf=0.0):
    """The model's blur; ``cp`` of shape (n, 6) adds the first-order rotation of docs/model.md."""
    lf = np.asarray(lf, dtype=np.float64)
    gray = lf.ndim == 4
    if gray:
        lf = lf[..., None]
    V, U, Y, X, C = lf.shape
    R = max(X, Y) / 2
    out = np.zeros_like(lf)
    v, u, y, x = np.meshgrid(np.arange(V), np.arange(U), np.arange(Y), np.arange(X), indexing="ij")
    xt = (x - (X - 1) / 2) / R
    yt = (y - (Y - 1) / 2) / R
    for k in range(n_times):
        pos = bezier_reference(cp, k / (n_times - 1))
        px, py, pz = pos[:3]
        rx, ry, rz = pos[3:] if len(pos) == 6 else (0.0, 0.0, 0.0)
        su = px - xt * pz
        sv = py - yt * pz
        # the rotated ray's slopes, to first order in the angles
        dx = ry * (1 + xt**2) - rx * xt * yt - rz * yt
        dy = -rx * (1 + yt**2) + ry * xt * yt + rz * xt
        coords = [v + sv, u + su, y + R * dy + d_inf * sv, x + R * dx + d_inf * su]
        # quadrilinear lookup with clamping, ray by ray (16 corners)
        cl = [np.clip(c, 0, s - 1) for c, s in zip(coords, (V, U, Y, X))]
        i0 = [np.floor(c).astype(int) for c in cl]
        w = [c - i for c, i in zip(cl, i0)]
        acc = np.zeros((V, U, Y, X, C))
        for corner in range(16):
            bits = [(corner >> a) & 1 for a in range(4)]
            idx = [np.minimum(i0[a] + bits[a], s - 1) for a, s in enumerate((V, U, Y, X))]
            weight = np.ones((V, U, Y, X))
            for a in range(4):
                weight = weight * (w[a] if bits[a] else (1 - w[a]))
            acc += weight[..., None] * lf[idx[0], idx[1], idx[2], idx[3]]
        out += acc
    out /= n_times
    return out[..., 0] if gray else out


def moving_texture(n_views=5, d=1.5, size=48, seed=0):
    """A Lambertian light field at one disparity laid out as MODEL.md says: a smooth random
    texture that moves by ``d`` px along x per step of u and along y per step of v (circularly)."""
    from scipy import ndimage

    tex = ndimage.gaussian_filter(np.random.default_rng(seed).random((size, size)), 1.5)
    c = (n_views - 1) / 2
    lf = np.stack([np.stack([ndimage.shift(tex, (d * (v - c), d * (u - c)), order=3, mode="wrap")
                             for u in range(n_views)]) for v in range(n_views)])
    return ((lf - lf.min()) / (lf.max() - lf.min())).astype(np.float32)
