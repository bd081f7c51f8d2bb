"""Sample light fields that ship with the package: no download needed.

- :func:`synthetic_scene`: a seeded procedural 3D scene of textured
  fronto-parallel layers with occlusion, and its ground-truth disparity.
- :func:`lytro_sample`: a 9 x 9 x 128 x 128 x 3 crop of a real Lytro capture
  (CC BY 4.0; see ``ATTRIBUTION.txt`` in this folder).
"""

from ._lytro import LYTRO_ATTRIBUTION, lytro_sample
from ._synthetic import synthetic_scene

__all__ = ["synthetic_scene", "lytro_sample", "LYTRO_ATTRIBUTION"]
