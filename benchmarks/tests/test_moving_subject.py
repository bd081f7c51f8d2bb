"""The moving subject's own motion blur in benchmarks/moving_subject.py."""

import numpy as np
import pytest

from moving_subject import subject_motion  # benchmarks/moving_subject.py, on the path by conftest.py


@pytest.mark.parametrize("angle, along_y", [(0.0, False), (np.pi / 2, True)])
def test_subject_motion_is_one_line_blur_in_every_view(angle, along_y):
    lf = np.zeros((2, 3, 33, 33), np.float32)
    lf[:, :, 16, 16] = 1.0
    out = subject_motion(lf, 8.0, angle)
    np.testing.assert_allclose(out, np.broadcast_to(out[:1, :1], out.shape))  # the same in every view
    np.testing.assert_allclose(out.sum(axis=(2, 3)), 1.0, rtol=1e-6)  # nothing lost
    view = out[0, 0].T if along_y else out[0, 0]  # the motion along the columns of view
    profile = view.sum(axis=0)
    assert view.sum(axis=1).max() == pytest.approx(1.0, abs=1e-6)  # nothing across the motion
    x = np.arange(33)
    mean = (profile * x).sum()
    var = (profile * (x - mean) ** 2).sum()
    # 16 positions spread evenly over 8 px: variance 8^2 / 12 * 17 / 15, plus a little from bilinear sampling
    assert mean == pytest.approx(16.0, abs=1e-6)
    assert 64 / 12 * 17 / 15 <= var <= 64 / 12 * 17 / 15 + 0.25
