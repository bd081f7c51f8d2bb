"""Sample light fields that ship with the package: no download needed.

- :func:`synthetic_scene`: a seeded procedural 3D scene of textured
  fronto-parallel layers with occlusion, and its ground-truth disparity.
- :func:`procedural_scene`: a seeded light field of natural textures
  (``skimage.data`` crops) on planes at random depths with occlusion, its
  disparities physical for a given infinity disparity, and its ground truth.
- :func:`lytro_sample`: a 9 x 9 x 128 x 128 x 3 crop of a real Lytro capture
  (CC BY 4.0; see ``ATTRIBUTION.txt`` in this folder).
"""

from ._lytro import LYTRO_ATTRIBUTION, lytro_sample
from ._procedural import procedural_scene
from ._synthetic import synthetic_scene

__all__ = ["synthetic_scene", "procedural_scene", "lytro_sample", "LYTRO_ATTRIBUTION"]
