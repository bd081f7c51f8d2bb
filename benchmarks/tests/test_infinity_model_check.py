"""The refocused camera of benchmarks/infinity_model_check.py, against its own ray tracer."""

import numpy as np
import pytest

import infinity_model_check as imc


@pytest.mark.parametrize("d_inf", [1, 2])
def test_refocusing_the_camera_focused_at_infinity_reindexes_its_views(d_inf):
    # independent expectation: the ray tracer renders the refocused camera directly; the sheared model
    # reindexes the camera focused at infinity, which is exact away from the clamped border
    import _raytrace

    scene = _raytrace.make_scene(32.0, disparities=(-0.3, -0.8), seed=1)
    direct = imc.render(scene, d_inf)
    reindexed = imc.refocus(imc.render(scene, 0), d_inf)
    m = 4 * d_inf
    np.testing.assert_allclose(reindexed[:, :, m:-m, m:-m], direct[:, :, m:-m, m:-m], atol=1e-12)
    # a point at infinity has disparity d_inf: view u + 1 sees at x + d_inf what view u sees at x
    far = _raytrace.make_scene(32.0, disparities=(-1e-9, -1e-9), seed=2)
    lf = imc.render(far, d_inf)
    np.testing.assert_allclose(lf[4, 5, :, m + d_inf:-m], lf[4, 4, :, m:-m - d_inf], atol=1e-6)
