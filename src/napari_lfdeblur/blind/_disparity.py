"""The pixel weights of the path fit, drawn from the disparity of the blurred light field.

The resampling the path stage shares (grayscale, refocus, area-averaging)
and the disparity map itself live in :mod:`napari_lfdeblur._disparity`.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .._disparity import disparity_map, downsample, gray, shear, shear_spectral, shear_taps

__all__ = ["gray", "shear_taps", "shear", "shear_spectral", "downsample", "disparity_map", "disparity_weights",
           "DISPARITY_PIXELS", "DISPARITY_FLOOR"]

#: pixels (about) on which the disparity map of the fit's weights is estimated; larger views are
#: area-averaged down to it (the weights depend on |d| / max|d| only, which this keeps)
DISPARITY_PIXELS = 160 * 160
#: floor of the disparity weights of the fit's pixels (relative to the largest |d|)
DISPARITY_FLOOR = 0.02


def disparity_weights(f: torch.Tensor, power: float) -> np.ndarray:
    """Pixel weights ``(|d| / max|d| + DISPARITY_FLOOR) ** power`` of the path fit, (Y, X) float64.

    ``d`` is :func:`disparity_map` of ``f`` (V, U, Y, X, 1), estimated on views
    area-averaged down to about :data:`DISPARITY_PIXELS` pixels and repeated
    back to full size.
    """
    Y, X = f.shape[2:4]
    k = max(1, int(math.sqrt(Y * X / DISPARITY_PIXELS)))
    d = np.abs(disparity_map(downsample(f, k)))
    w = (d / max(float(d.max()), 1e-6) + DISPARITY_FLOOR) ** power
    w = np.repeat(np.repeat(w, k, axis=0), k, axis=1)
    return np.pad(w, ((0, Y - w.shape[0]), (0, X - w.shape[1])), mode="edge")
