"""A naive ray tracer of light fields seen by a moving camera, for tests and benchmarks only.

It renders a scene of fronto-parallel textured planes through the aperture
of a light-field camera at any 6-DOF pose, and the motion blur of a path as
the mean of the renders at the exposure instants. It is written from the
camera conventions alone and imports nothing from ``napari_lfdeblur``, so
that the package's blur operator can be checked against it.

Conventions (all lengths in views, the aperture baseline of one view step):

- light field ``(V, U, Y, X)``; ``u_c = u - (U-1)/2``, ``v_c = v - (V-1)/2``;
  ``x~ = (x - (X-1)/2) / R``, ``y~ = (y - (Y-1)/2) / R``, ``R = max(X, Y) / 2``;
- camera frame x right, y down, z forward; view ``(v, u)`` has its aperture
  point at ``(u_c, v_c, 0)`` and its pixel ``(y, x)`` sees the ray of
  direction ``(x~, y~, 1)``;
- a pose ``(p_x, p_y, p_z, r_x, r_y, r_z)`` maps a camera-frame point ``q``
  to the reference point ``Rot @ q + p``, ``Rot = exp([r]_x)``;
- a plane at depth ``Z`` has disparity ``-R / Z`` px/view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Plane",
    "bernstein_matrix",
    "interior_error",
    "make_scene",
    "normalized_grid",
    "path_margins",
    "path_poses",
    "render",
    "render_blur",
    "rotation_matrix",
    "sample_sharp",
    "trace",
]


@dataclass
class Plane:
    """A fronto-parallel textured plane (or rectangle) of the scene.

    Attributes
    ----------
    depth : float
        ``Z`` of the plane in the reference frame, views.
    offset : float
        Constant part of the texture.
    amplitudes, phases : ndarray, shape (n,)
        Amplitude and phase of each sinusoid of the texture.
    wavevectors : ndarray, shape (n, 2)
        Angular wavenumbers ``(k_X, k_Y)`` in radians per view of the plane's
        own ``(X, Y)`` coordinates.
    bounds : tuple of 4 float, optional
        ``(X_min, X_max, Y_min, Y_max)`` of a bounded rectangle; None for an
        unbounded plane.
    edge : float, default 0
        Width, in plane units, of the ramp over which the rectangle's opacity
        falls from 1 inside to 0 outside its bounds (a raised cosine centred
        on them). 0 gives a hard, opaque edge.
    """

    depth: float
    offset: float
    amplitudes: np.ndarray
    phases: np.ndarray
    wavevectors: np.ndarray
    bounds: tuple | None = None
    edge: float = 0.0

    def texture(self, X, Y):
        """The texture at plane coordinates ``X, Y`` (arrays of one shape)."""
        out = np.full(np.shape(X), self.offset, dtype=np.float64)
        for amp, phase, (kx, ky) in zip(self.amplitudes, self.phases, self.wavevectors):
            out += amp * np.cos(kx * X + ky * Y + phase)
        return out

    def opacity(self, X, Y):
        """Opacity of the plane at ``X, Y``: 1 inside its bounds, 0 outside, a ramp of ``edge`` between."""
        if self.bounds is None:
            return np.ones(np.shape(X))
        x0, x1, y0, y1 = self.bounds
        inside = [X - x0, x1 - X, Y - y0, y1 - Y]  # signed distances to the four edges
        alpha = np.ones(np.shape(X))
        for dist in inside:
            if self.edge == 0.0:
                alpha = alpha * (dist >= 0)
            else:
                ramp = np.clip(dist / self.edge + 0.5, 0.0, 1.0)
                alpha = alpha * (0.5 - 0.5 * np.cos(np.pi * ramp))
        return alpha


def bernstein_matrix(n_control: int, n_times: int) -> np.ndarray:
    """Bernstein basis of a Bezier curve at ``t_k = k / (T - 1)``.

    Returns
    -------
    ndarray, shape (n_times, n_control)
        ``B[k, i] = C(n-1, i) t_k^i (1 - t_k)^(n-1-i)``.
    """
    degree = n_control - 1
    t = np.arange(n_times) / (n_times - 1)
    return np.stack(
        [math.comb(degree, i) * t**i * (1.0 - t) ** (degree - i) for i in range(n_control)], axis=1
    )


def path_poses(control_points, n_times: int) -> np.ndarray:
    """The ``(T, 6)`` poses of a Bezier path; ``(n, 3)`` control points get zero rotation."""
    cp = np.asarray(control_points, dtype=np.float64)
    if cp.shape[1] == 3:
        cp = np.concatenate([cp, np.zeros_like(cp)], axis=1)
    return bernstein_matrix(len(cp), n_times) @ cp


def rotation_matrix(rotvec) -> np.ndarray:
    """``exp([r]_x)`` by Rodrigues' formula (exact, any angle)."""
    r = np.asarray(rotvec, dtype=np.float64)
    angle = float(np.linalg.norm(r))
    if angle == 0.0:
        return np.eye(3)
    kx, ky, kz = r / angle
    cross = np.array([[0.0, -kz, ky], [kz, 0.0, -kx], [-ky, kx, 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * cross @ cross


def _random_texture(rng, radius, depth, wavelengths_px, n_waves):
    """Amplitudes, phases and wavevectors of ``n_waves`` sinusoids of image wavelengths in a range."""
    lam = rng.uniform(wavelengths_px[0], wavelengths_px[1], n_waves)
    theta = rng.uniform(0.0, np.pi, n_waves)
    k = 2.0 * np.pi * radius / (lam * depth)  # a wavelength of lam px at depth Z
    wavevectors = np.stack([k * np.cos(theta), k * np.sin(theta)], axis=1)
    amplitudes = rng.uniform(0.5, 1.0, n_waves) / n_waves * 0.4
    return amplitudes, rng.uniform(0.0, 2.0 * np.pi, n_waves), wavevectors


def make_scene(radius: float, disparities=(-0.5, -1.0), wavelengths_px=(6.0, 12.0), n_waves: int = 4,
               occluder_extent: float = 0.45, edge_px: float = 6.0, seed: int = 0) -> list[Plane]:
    """A background plane and, in front of it, soft-edged squares near the optical axis.

    Parameters
    ----------
    radius : float
        ``R`` of the light fields the scene is meant for, px: sets the depths
        ``Z = -R / d`` and the texture's wavenumbers.
    disparities : sequence of float
        Disparity of each plane, px/view, all negative (``d_inf = 0``); the
        first is the unbounded background, the others are squares.
    wavelengths_px : (float, float)
        Range of the textures' wavelengths in the image at their own depth.
    n_waves : int
        Sinusoids per texture.
    occluder_extent : float
        Half side of the squares in ``x~`` units as seen from the reference
        pose; successive squares are offset diagonally so their edges show.
    edge_px : float
        Width of the squares' soft edges in the image at their own depth, px
        (0: hard, opaque edges, which bilinear resampling cannot follow).
    seed : int

    Returns
    -------
    list of Plane
    """
    rng = np.random.default_rng(seed)
    planes = []
    for i, d in enumerate(disparities):
        depth = -radius / d
        amps, phases, waves = _random_texture(rng, radius, depth, wavelengths_px, n_waves)
        bounds = None
        if i > 0:
            half = occluder_extent * depth
            shift = 0.25 * (i - 1) * depth * (1 if i % 2 else -1)
            bounds = (shift - half, shift + half, shift - half, shift + half)
        planes.append(Plane(depth, 0.5, amps, phases, waves, bounds, edge_px * depth / radius))
    return planes


def trace(scene, origins, directions) -> np.ndarray:
    """What each ray sees: the nearest plane in front of it, through any soft edges.

    Planes are composited front to back by their opacity, so with hard
    edges a ray sees the texture of the nearest plane it hits.

    Parameters
    ----------
    scene : list of Plane
    origins, directions : ndarray, shape (..., 3)
        Rays in the reference frame (``direction_z > 0``); the two shapes
        broadcast.

    Returns
    -------
    ndarray, the broadcast shape less the last axis
        0 where a ray hits nothing.
    """
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    if np.any(d[..., 2] <= 0):
        raise ValueError("rays must point forward (direction z > 0)")
    shape = np.broadcast_shapes(o.shape, d.shape)[:-1]
    value = np.zeros(shape)
    # with fronto-parallel planes and forward rays, the order along every ray is the order in depth:
    # composite from the farthest plane to the nearest
    for plane in sorted(scene, key=lambda p: -p.depth):
        t = (plane.depth - o[..., 2]) / d[..., 2]
        X = o[..., 0] + t * d[..., 0]
        Y = o[..., 1] + t * d[..., 1]
        alpha = np.where(t > 0, plane.opacity(X, Y), 0.0)
        value = alpha * plane.texture(X, Y) + (1.0 - alpha) * value
    return value


def normalized_grid(n: int, radius: float) -> np.ndarray:
    """``(i - (n - 1) / 2) / R`` for ``i = 0 .. n - 1``."""
    return (np.arange(n) - (n - 1) / 2.0) / radius


def render(scene, shape, pose=None) -> np.ndarray:
    """The ``(V, U, Y, X)`` light field the camera sees at ``pose`` (default: the identity).

    Parameters
    ----------
    scene : list of Plane
    shape : tuple of 4 int
    pose : array_like of 6 float, optional
        ``(p_x, p_y, p_z, r_x, r_y, r_z)``.
    """
    V, U, Y, X = shape
    pose = np.zeros(6) if pose is None else np.asarray(pose, dtype=np.float64)
    rot = rotation_matrix(pose[3:])
    radius = max(X, Y) / 2.0
    u_c = np.arange(U) - (U - 1) / 2.0
    v_c = np.arange(V) - (V - 1) / 2.0
    aperture = np.stack(np.broadcast_arrays(u_c[None, :], v_c[:, None], 0.0), axis=-1)  # (V, U, 3)
    xt = normalized_grid(X, radius)
    yt = normalized_grid(Y, radius)
    pixel = np.stack(np.broadcast_arrays(xt[None, :], yt[:, None], 1.0), axis=-1)  # (Y, X, 3)
    origins = aperture @ rot.T + pose[:3]
    directions = pixel @ rot.T
    return trace(scene, origins[:, :, None, None, :], directions[None, None, :, :, :])


def render_blur(scene, shape, control_points, n_times: int) -> np.ndarray:
    """Mean of the renders at the ``T`` poses of a Bezier path of ``(n, 3)`` or ``(n, 6)`` points."""
    poses = path_poses(control_points, n_times)
    return sum(render(scene, shape, pose) for pose in poses) / n_times


def sample_sharp(scene, shape, v, u, y, x) -> np.ndarray:
    """The sharp light field (identity pose) at fractional view and pixel coordinates, exactly.

    ``v, u, y, x`` are arrays of one broadcast shape in index units of a
    light field of ``shape``; no boundary applies (the scene goes on beyond
    the frame and the aperture).
    """
    V, U, Y, X = shape
    radius = max(X, Y) / 2.0
    v, u, y, x = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (v, u, y, x)))
    origins = np.stack([u - (U - 1) / 2.0, v - (V - 1) / 2.0, np.zeros_like(u)], axis=-1)
    directions = np.stack([(x - (X - 1) / 2.0) / radius, (y - (Y - 1) / 2.0) / radius, np.ones_like(x)],
                          axis=-1)
    return trace(scene, origins, directions)


def path_margins(control_points, shape, n_times: int) -> tuple[int, int]:
    """Views and pixels to drop at each border before comparing blurs of this path.

    The view margin covers the angular shifts of the translation,
    ``max |p_x - x~ p_z|`` and ``max |p_y - y~ p_z|``, where a replicated
    boundary reads a view the camera never had; the pixel margin covers the
    image motion of the rotation, ``R`` times the largest change of a ray's
    slope, plus one pixel, where it reads beyond the frame. Translation alone
    moves no pixel, so its pixel margin is 0.
    """
    Y, X = shape[2], shape[3]
    radius = max(X, Y) / 2.0
    poses = path_poses(control_points, n_times)
    edge = max(X - 1, Y - 1) / 2.0 / radius
    shift = np.abs(poses[:, :2]).max() + edge * np.abs(poses[:, 2]).max()
    view_margin = math.ceil(shift - 1e-9)
    corners = np.array([[sx * (X - 1) / 2.0 / radius, sy * (Y - 1) / 2.0 / radius, 1.0]
                        for sx in (-1, 1) for sy in (-1, 1)])
    motion = 0.0
    for pose in poses:
        ray = corners @ rotation_matrix(pose[3:]).T
        slope = ray[:, :2] / ray[:, 2:3]
        motion = max(motion, float(np.abs(slope - corners[:, :2]).max()) * radius)
    pixel_margin = 0 if motion == 0.0 else math.ceil(motion) + 1
    return view_margin, pixel_margin


def interior_error(estimate, blurred, sharp, view_margin: int, pixel_margin: int) -> float:
    """``||estimate - blurred|| / ||blurred - sharp||`` over the interior views and pixels."""
    V, U, Y, X = np.shape(blurred)
    inner = (slice(view_margin, V - view_margin), slice(view_margin, U - view_margin),
             slice(pixel_margin, Y - pixel_margin), slice(pixel_margin, X - pixel_margin))
    est, ref, base = (np.asarray(a, dtype=np.float64)[inner] for a in (estimate, blurred, sharp))
    return float(np.linalg.norm(est - ref) / np.linalg.norm(ref - base))


def motion_paths(magnitude: float) -> dict[str, np.ndarray]:
    """Bezier control points ``(n, 6)`` of the four motions, rotations of about ``magnitude`` rad.

    Every path starts at the identity pose (the sharp light field's) and is
    curved, so that its mean pose is not its midpoint.
    """
    m = magnitude
    zero = np.zeros((3, 6))
    yaw, pitch, roll = zero.copy(), zero.copy(), zero.copy()
    yaw[:, 4] = (0.0, m, 0.4 * m)
    pitch[:, 3] = (0.0, -m, -0.3 * m)
    roll[:, 5] = (0.0, m, 0.5 * m)
    mixed = np.array([
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.6, -0.3, 0.4, 0.5 * m, m, -0.5 * m],
        [0.3, 0.4, -0.2, -0.7 * m, 0.2 * m, 0.8 * m],
    ])
    return {"yaw": yaw, "pitch": pitch, "roll": roll, "mixed": mixed}
