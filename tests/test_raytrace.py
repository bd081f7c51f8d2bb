"""The blur operator against a ray tracer of the scene (tests/_raytrace.py), with and without rotation.

The truth is the mean of ray-traced renders at the path's poses; the
operator blurs the render at the identity pose. The error is
``||op(sharp) - truth|| / ||truth - sharp||`` over the interior views and
pixels (``_raytrace.path_margins``: a replicated boundary reads views and
pixels the camera never had).

The operator resamples the sampled light field bilinearly, which a ray
tracer does not: even where its geometry is exact (translation), the error
has a floor of bilinear interpolation, largest where the blur moves pixels
by a pixel or less. The tolerances below are the errors measured on these
scenes (see each test) with about 40 % headroom;
docs/benchmarks/rotation_model_check.md separates the floor from the
model's geometric error.
"""

import numpy as np
import pytest

from _raytrace import (
    bernstein_matrix,
    interior_error,
    make_scene,
    motion_paths,
    path_margins,
    render,
    render_blur,
    rotation_matrix,
)
from napari_lfdeblur.blur import simulate_blur

#: light fields of the translation tests (7 x 7 views: their paths need a margin of 2 views) and
#: of the rotation tests
SHAPE = (7, 7, 48, 48)
ROTATION_SHAPE = (5, 5, 48, 48)
RADIUS = 24.0
N_TIMES = 8
#: rotation of the rotation paths, rad: R r = 1.2 px at these sizes
MAGNITUDE = 0.05


@pytest.fixture(scope="module")
def scene():
    """Background at -0.5 px/view and soft-edged squares at -1 and -1.5, textures of 10-20 px."""
    return make_scene(RADIUS, disparities=(-0.5, -1.0, -1.5), wavelengths_px=(10.0, 20.0))


@pytest.fixture(scope="module")
def sharp(scene):
    """The light field at the identity pose."""
    return render(scene, SHAPE)


@pytest.fixture(scope="module")
def sharp_rotation(scene):
    """The light field at the identity pose, of ``ROTATION_SHAPE``."""
    return render(scene, ROTATION_SHAPE)


def _operator_error(sharp, truth, cp, cp_model=None, n_times=N_TIMES):
    """Interior relative error of ``simulate_blur(sharp, cp_model)`` (default ``cp``) against ``truth``."""
    cp_model = cp if cp_model is None else cp_model
    blurred = simulate_blur(sharp.astype(np.float32), cp_model, n_times=n_times, device="cpu")
    return interior_error(blurred, truth, sharp, *path_margins(cp, sharp.shape, n_times))


# ---------------------------------------------------------------- the ray tracer itself


def test_ray_tracer_conventions():
    """A plane at depth Z has disparity -R/Z along u and v; Rodrigues and Bernstein are sound."""
    plane = make_scene(RADIUS, disparities=(-1.0,))
    lf = render(plane, SHAPE)
    # a point at x in view u is at x + d = x - 1 in view u + 1, and likewise along v and y
    np.testing.assert_allclose(lf[:, 1:, :, :-1], lf[:, :-1, :, 1:], atol=1e-12)
    np.testing.assert_allclose(lf[1:, :, :-1, :], lf[:-1, :, 1:, :], atol=1e-12)
    assert np.abs(lf[:, 1:] - lf[:, :-1]).max() > 0.05  # and the views do differ
    yaw = rotation_matrix([0.0, 0.3, 0.0])  # about y: the optical axis turns towards +x
    np.testing.assert_allclose(yaw @ [0.0, 0.0, 1.0], [np.sin(0.3), 0.0, np.cos(0.3)], atol=1e-15)
    rot = rotation_matrix([0.2, -0.1, 0.3])
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(bernstein_matrix(4, 5).sum(axis=1), 1.0)


# ------------------------------------------------------------------------ translation


def test_integer_view_shifts_are_exact(scene, sharp):
    """Shifts of whole views at every instant need no interpolation: operator and ray tracer agree."""
    cp = np.array([[-1.0, 0.0, 0.0], [1.0, 2.0, 0.0]])  # (-1, 0), (0, 1), (1, 2) at T = 3
    truth = render_blur(scene, SHAPE, cp, 3)
    assert _operator_error(sharp, truth, cp, n_times=3) < 1e-5
    assert _operator_error(sharp, truth, cp, -cp, n_times=3) > 1.0  # measured 1.66


# measured errors: in-plane 0.081, with p_z 0.299 (the floor of bilinear interpolation; p_z moves
# pixels near the centre by little). The same path negated: 1.85, 1.90; no blur: 1.0.
TRANSLATIONS = {
    "in-plane": ([[0.0, 0.0, 0.0], [2.0, -1.0, 0.0], [1.0, 1.0, 0.0]], 0.12),
    "with-p_z": ([[0.0, 0.0, 0.0], [0.5, -0.4, 1.4], [0.2, 0.5, -1.0]], 0.42),
}


@pytest.mark.parametrize("name", list(TRANSLATIONS))
def test_translation_matches_ray_tracer(scene, sharp, name):
    """Translation paths, (n, 3): the operator's exact geometry, up to the interpolation floor."""
    cp, tolerance = TRANSLATIONS[name]
    cp = np.array(cp)
    truth = render_blur(scene, SHAPE, cp, N_TIMES)
    error = _operator_error(sharp, truth, cp)
    assert error < tolerance, f"{name}: {error:.3f}"
    assert _operator_error(sharp, truth, cp, np.zeros_like(cp)) > 0.5
    assert _operator_error(sharp, truth, cp, -cp) > 3 * tolerance  # the sign of the path


@pytest.fixture(scope="module")
def smooth_scene():
    """Background at -0.25 px/view and a soft-edged square at -0.5, textures of 24-48 px.

    Textures this smooth keep the bilinear floor below the p_z term, which moves pixels by only
    ``x~ p_z`` views: on ``scene`` the floor swamps it.
    """
    return make_scene(RADIUS, disparities=(-0.25, -0.5), wavelengths_px=(24.0, 48.0))


# measured errors of the path along the optical axis: 0.212; p_z dropped 1.0, negated 1.94, scaled
# by 0.75 0.283, by 1.25 0.39.
DEPTH_PATH = [[0.0, 0.0, 0.0], [0.0, 0.0, 1.8], [0.0, 0.0, -1.0]]


def test_depth_translation_matches_ray_tracer(smooth_scene):
    """A path along p_z alone: the operator's magnification of the views' shifts, ``-x~ p_z`` and ``-y~ p_z``."""
    sharp = render(smooth_scene, SHAPE)
    cp = np.array(DEPTH_PATH)
    truth = render_blur(smooth_scene, SHAPE, cp, N_TIMES)
    error = _operator_error(sharp, truth, cp)
    assert error < 0.3, f"{error:.3f}"
    # an operator without p_z, or with its sign flipped, is far off
    assert _operator_error(sharp, truth, cp, cp * [1.0, 1.0, 0.0]) > 3 * error
    assert _operator_error(sharp, truth, cp, -cp) > 3 * error
    # and p_z scaled by 25 % either way is farther from the truth than the model's own scale
    for scale in (0.75, 1.25):
        assert _operator_error(sharp, truth, cp, cp * [1.0, 1.0, scale]) > 1.15 * error, scale


# --------------------------------------------------------------------------- rotation


# measured errors of the first-order rotation model: yaw 0.084, pitch 0.093, roll 0.186 (of which
# about 0.1 is the dropped rotation of the aperture point, large at R = 24), mixed 0.155; ignoring
# the rotation: 1.0, 1.0, 1.0, 0.72.
ROTATION_TOLERANCES = {"yaw": 0.12, "pitch": 0.13, "roll": 0.26, "mixed": 0.22}


@pytest.mark.parametrize("name", list(ROTATION_TOLERANCES))
def test_rotation_matches_ray_tracer(scene, sharp_rotation, name):
    """Rotation paths, (n, 6): the first-order model is close, and clearly closer than translation alone."""
    cp = motion_paths(MAGNITUDE)[name]
    truth = render_blur(scene, ROTATION_SHAPE, cp, N_TIMES)
    error = _operator_error(sharp_rotation, truth, cp)
    assert error < ROTATION_TOLERANCES[name], f"{name}: {error:.3f}"
    without_rotation = _operator_error(sharp_rotation, truth, cp, cp[:, :3])
    assert without_rotation > 3 * error, f"{name}: {without_rotation:.3f} against {error:.3f}"
