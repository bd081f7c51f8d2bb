"""The small real light field shipped with the package."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["lytro_sample", "LYTRO_ATTRIBUTION"]

_FILE = Path(__file__).with_name("lytro_f01_img0001_crop.eslf.png")
_ANGULAR = 9

LYTRO_ATTRIBUTION = (
    "Lytro light field: crop of LF/Frames/IMG_0001 from the GitHub repository "
    "Jaramilloh/Process-Light-Fields-Captured-With-Lytro-Camera, CC BY 4.0"
)


def lytro_sample() -> np.ndarray:
    """A real light field: a crop of a first-generation Lytro capture.

    Returns
    -------
    ndarray, float32, shape (9, 9, 128, 128, 3)
        Values in [0, 1], in the ``(V, U, Y, X, C)`` layout of docs/model.md.

    Notes
    -----
    Views 2..10 (both directions) and pixels 64..191 of the 10 x 10 x 256 x
    256 capture ``IMG_0001`` of the repository
    ``Jaramilloh/Process-Light-Fields-Captured-With-Lytro-Camera``, under
    CC BY 4.0. Its content moves about 0.63 px per view, along ``x`` with
    ``u`` and along ``y`` with ``v`` (:func:`~napari_lfdeblur.view_shifts`):
    the capture's view ``RR_CC`` is ``lf[CC - 2, RR - 2]``, since its file
    names give the horizontal index first.
    """
    import imageio.v3 as iio

    mosaic = iio.imread(_FILE)
    a = _ANGULAR
    h, w = mosaic.shape[0] // a, mosaic.shape[1] // a
    # lenslet layout: pixel (y * A + v, x * A + u) holds lf[v, u, y, x]
    lf = mosaic.reshape(h, a, w, a, 3).transpose(1, 3, 0, 2, 4)
    return np.ascontiguousarray(lf, dtype=np.float32) / 255.0
