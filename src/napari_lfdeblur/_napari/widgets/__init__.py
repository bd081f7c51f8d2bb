"""The plugin's dock widgets (npe2 ``widgets`` contributions).

Each one is a thin shell over the core: it gathers parameters, runs the
core's generator in a napari ``thread_worker`` and turns its progress
records and result into a progress bar, previews and layers.
"""

from __future__ import annotations

__all__ = ["SimulateBlurWidget", "DeconvolveWidget", "BlindDeblurWidget", "EpiWidget", "OpenLightFieldWidget"]


def __getattr__(name):
    if name == "SimulateBlurWidget":
        from .simulate import SimulateBlurWidget

        return SimulateBlurWidget
    if name == "DeconvolveWidget":
        from .deconvolve import DeconvolveWidget

        return DeconvolveWidget
    if name == "BlindDeblurWidget":
        from .blind import BlindDeblurWidget

        return BlindDeblurWidget
    if name == "EpiWidget":
        from .epi import EpiWidget

        return EpiWidget
    if name == "OpenLightFieldWidget":
        from .open import OpenLightFieldWidget

        return OpenLightFieldWidget
    raise AttributeError(name)
