"""The cases of benchmarks/blind_rotation_eval.py: rotations of the stated image motion."""

import numpy as np
import pytest

import blind_rotation_eval as bre
from napari_lfdeblur.path import bezier_positions


@pytest.mark.parametrize("motion", ["rotation", "mixed"])
def test_paths_have_the_stated_image_motion(motion):
    for seed in range(3):
        cp = bre.true_path(motion, seed, 64.0, (0.4, 0.4))
        pos = bezier_positions(cp, bre.RENDER_TIMES)
        rot = pos[:, 3:]
        diameter = np.sqrt(((rot[:, None] - rot[None]) ** 2).sum(-1)).max()
        # 0.4 degrees on a full frame of R = 270 px is 1.88 px; on a 128-px crop (R = 64) that many px
        assert diameter * 64.0 == pytest.approx(270.0 * np.radians(0.4), rel=1e-9)
        np.testing.assert_allclose(pos.mean(axis=0), 0.0, atol=1e-12)  # the zero-mean gauge
        assert (np.abs(cp[:, :3]).max() > 0.1) == (motion == "mixed")


def test_cases_alternate_scenes_and_motions():
    specs = bre.case_specs(6)
    assert [s[3] for s in specs] == ["rotation", "mixed", "mixed"] * 2
    assert len({s[0] for s in specs}) == 6
