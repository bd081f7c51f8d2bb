"""napari sample data: the synthetic scene (sharp and blurred) and the Lytro crop."""

from __future__ import annotations

import numpy as np

from .. import __version__
from ..blur import simulate_blur
from ..path import arc_path
from ..samples import LYTRO_ATTRIBUTION, lytro_sample, synthetic_scene
from ._torch_thread import call

#: size of the synthetic sample
SYNTHETIC_SHAPE = (9, 9, 128, 128)
#: the known path of the pre-blurred synthetic sample, and its exposure instants
BLURRED_SAMPLE_PATH = arc_path(length=2.5, bend=0.3, angle_deg=20.0)
BLURRED_SAMPLE_N_TIMES = 32


def _layer(lf: np.ndarray, name: str, metadata: dict):
    kwargs = {
        "name": name,
        "rgb": lf.ndim == 5,
        "axis_labels": ("v", "u", "y", "x"),
        "metadata": {"napari_lfdeblur_version": __version__, **metadata},
    }
    return [(lf, kwargs, "image")]


def synthetic_scene_sample():
    lf, disparity = synthetic_scene(SYNTHETIC_SHAPE, n_layers=3, color=True, seed=0)
    return _layer(lf, "synthetic scene", {"source": "synthetic_scene", "disparity": disparity})


def synthetic_blurred_sample():
    lf, disparity = synthetic_scene(SYNTHETIC_SHAPE, n_layers=3, color=True, seed=0)
    # on the plugin's torch thread, not napari's GUI thread (see _torch_thread)
    blurred = call(simulate_blur, lf, BLURRED_SAMPLE_PATH, n_times=BLURRED_SAMPLE_N_TIMES)
    return _layer(
        blurred,
        "synthetic scene (blurred)",
        {
            "source": "synthetic_scene, blurred by simulate_blur",
            "control_points": BLURRED_SAMPLE_PATH.tolist(),
            "n_times": BLURRED_SAMPLE_N_TIMES,
            "infinity_disparity": 0.0,
            "disparity": disparity,
        },
    )


def lytro_sample_layer():
    return _layer(lytro_sample(), "Lytro IMG_0001 (crop)", {"source": LYTRO_ATTRIBUTION})
