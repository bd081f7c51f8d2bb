"""The napari side of the package, for scripts: the dock widgets and the layer helpers.

The plugin's dock widgets are what napari's *Plugins* menu opens; a script
can build them itself, on a viewer it shows or one it never shows
(``napari.Viewer(show=False)``, under a virtual display on a machine without
one). Each widget takes the viewer, its parameter form is ``widget.form``
and ``widget.run_and_wait()`` runs it to its end and returns the layers it
added (docs/headless.md).

The layer helpers build the layers the widgets read and write: a light
field as an Image layer with the axis labels ``('v', 'u', 'y', 'x')`` and
metadata that can hold the camera path it was blurred by, EPIs and camera
paths. Each ``*_layer_data`` function returns a napari layer data tuple
``(data, kwargs, layer_type)``; :func:`add_layer` adds one to a viewer.

Importing this module needs napari and a Qt binding (``pip install
"napari-lfdeblur[napari]" pyqt6``, or ``"napari-lfdeblur[all]"``);
``import napari_lfdeblur`` needs neither.
docs/headless.md shows each widget driven from a script.
"""

from __future__ import annotations

try:
    import napari  # noqa: F401
    import qtpy  # noqa: F401
except ImportError as exc:  # the library works without them; this module does not
    raise ImportError(
        f"napari_lfdeblur.widgets needs napari and Qt ({exc}); install them with "
        "pip install \"napari-lfdeblur[napari]\" pyqt6 (napari and a Qt binding; or \"napari-lfdeblur[all]\"), "
        "or use the core functions of napari_lfdeblur without a viewer"
    ) from exc

from ._napari.layers import (
    LF_AXIS_LABELS,
    LayerError,
    add_layer,
    control_points_from_layer,
    epi_layer_data,
    lightfield_from_layer,
    lightfield_layer_data,
    lightfield_metadata,
    path_layer_data,
)
from ._napari.widgets import (
    BlindDeblurWidget,
    DeconvolveWidget,
    EpiWidget,
    OpenLightFieldWidget,
    SimulateBlurWidget,
)

__all__ = [
    "SimulateBlurWidget",
    "DeconvolveWidget",
    "BlindDeblurWidget",
    "EpiWidget",
    "OpenLightFieldWidget",
    "add_layer",
    "lightfield_layer_data",
    "lightfield_metadata",
    "lightfield_from_layer",
    "control_points_from_layer",
    "path_layer_data",
    "epi_layer_data",
    "LF_AXIS_LABELS",
    "LayerError",
]
