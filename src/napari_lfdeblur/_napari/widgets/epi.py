"""The *Epipolar images* dock widget and the EPI panel of every widget.

The horizontal EPI is ``lf[v, :, y, :]`` and the vertical one
``lf[:, u, :, x]`` (see :mod:`napari_lfdeblur._napari.layers` for their
placement). Once shown, they follow the ``v``, ``y``, ``u``, ``x`` fields;
with *pick by clicking* on, a click on the canvas (whichever layer is
selected) sets ``y``, ``x`` from the click and ``v``, ``u`` from the view
sliders; clicks outside the light field (e.g. on an EPI) are ignored.
"""

from __future__ import annotations

import numpy as np
from magicgui.widgets import CheckBox, Container, PushButton

from ..layers import LayerError, add_layer, epi_layer_data
from ._controls import LayerChoice, heading, is_lightfield, notify_error, placed, spin

__all__ = ["EpiPanel", "EpiWidget"]

_PICKS = (
    ("v", "view row v of the horizontal EPI"),
    ("y", "pixel row y of the horizontal EPI"),
    ("u", "view column u of the vertical EPI"),
    ("x", "pixel column x of the vertical EPI"),
)


class EpiPanel(Container):
    """Horizontal and vertical EPI layers of a light-field layer at a picked row/column.

    Fields: ``layer`` (a light-field layer), ``v``, ``y``, ``u``, ``x`` (the
    picks, also reachable as attributes), *Show EPIs* and *pick by clicking*.
    """

    def __init__(self, viewer, name: str = "epi"):
        self._viewer = viewer
        self._active = False
        self.layer_combo = LayerChoice(viewer, predicate=is_lightfield, name="layer", label="layer")
        boxes = [spin(key, 0, 0, 0, tooltip=tip) for key, tip in _PICKS]
        self.v, self.y, self.u, self.x = boxes
        picks = Container(name="picks", layout="horizontal", widgets=boxes)
        picks.margins = (0, 0, 0, 0)
        self.show_button = PushButton(name="show_button", text="Show EPIs")
        self.click_box = CheckBox(name="pick_by_clicking", text="pick by clicking", value=False,
                                  tooltip="click on the canvas to set y, x from the click "
                                  "(and v, u from the view sliders)")
        super().__init__(name=name, widgets=[heading("Epipolar images"), self.layer_combo, picks, self.show_button, self.click_box],
                         labels=False)
        self.layer_combo.changed.connect(self._layer_changed)
        for box in boxes:
            box.changed.connect(self._pick_changed)
        self.show_button.changed.connect(self.show_epis)
        self.click_box.changed.connect(self._toggle_click)
        self._layer_changed()

    def layer_names(self):
        """Names of the two EPI layers of the chosen layer."""
        layer = self.layer_combo.value
        base = layer.name if layer is not None else ""
        return f"{base} EPI h", f"{base} EPI v"

    def _layer_changed(self, *_):
        layer = self.layer_combo.value
        watched = getattr(self, "_watched", None)
        if watched is not None and watched is not layer:
            watched.events.data.disconnect(self._data_changed)
        self._watched = layer
        if layer is None:
            return
        layer.events.data.connect(self._data_changed)  # a result updated in place: other data, maybe other sizes
        self._fit_picks(layer, middle=True)
        self._active = False

    def _fit_picks(self, layer, middle: bool) -> None:
        """Set the picks' ranges to the layer's sizes: the picks at the middle, or kept within the ranges."""
        if not is_lightfield(layer):
            return
        V, U, Y, X = layer.data.shape[:4]
        for box, n in ((self.v, V), (self.u, U), (self.y, Y), (self.x, X)):
            with box.changed.blocked():
                value = n // 2 if middle else min(box.value, n - 1)
                box.range = (0, n - 1)
                box.value = value

    def _data_changed(self, *_):
        """The chosen layer's data changed: the picks follow its sizes, and EPIs on show are redrawn."""
        layer = self.layer_combo.value
        if layer is None:
            return
        self._fit_picks(layer, middle=False)
        if self._active:
            self.show_epis()

    def set_pick(self, v=None, y=None, u=None, x=None) -> None:
        """Set the picked rows/columns (updates the EPI layers once shown)."""
        for box, value in ((self.v, v), (self.y, y), (self.u, u), (self.x, x)):
            if value is not None:
                with box.changed.blocked():
                    box.value = int(value)
        self._pick_changed()

    def _pick_changed(self, *_):
        if self._active:
            self.show_epis()

    def show_epis(self, *_):
        """Add (or update) the two EPI layers; returns them, or None on error."""
        layer = self.layer_combo.value
        try:
            lf = _lightfield_view(layer)
        except LayerError as exc:
            notify_error(f"EPIs: {exc}")
            return None
        h_name, v_name = self.layer_names()
        meta = {"source_layer": layer.name}
        h = add_layer(self._viewer, placed(epi_layer_data(
            lf, "h", name=h_name, v=self.v.value, y=self.y.value, metadata=meta), layer.scale, layer.translate))
        v = add_layer(self._viewer, placed(epi_layer_data(
            lf, "v", name=v_name, u=self.u.value, x=self.x.value, metadata=meta), layer.scale, layer.translate))
        self._active = True
        return h, v

    def _toggle_click(self, on: bool):
        """Listen (or stop listening) to clicks on the canvas, whichever layer is selected."""
        callbacks = self._viewer.mouse_drag_callbacks
        if on and self._on_click not in callbacks:
            callbacks.append(self._on_click)
        elif not on and self._on_click in callbacks:
            callbacks.remove(self._on_click)

    def _on_click(self, _viewer, event):
        layer = self.layer_combo.value
        if layer is None or not is_lightfield(layer):
            return
        coords = layer.world_to_data(event.position)
        if len(coords) < 4:
            return
        v, u, y, x = (int(round(c)) for c in coords[:4])
        shape = layer.data.shape
        if not (0 <= y < shape[2] and 0 <= x < shape[3]):
            return  # a click outside the light field (e.g. on an EPI)
        self.set_pick(v=min(max(v, 0), shape[0] - 1), y=y, u=min(max(u, 0), shape[1] - 1), x=x)
        if not self._active:
            self.show_epis()


def _lightfield_view(layer) -> np.ndarray:
    """The layer's data as a light field *without copying* (for EPIs; read only)."""
    if layer is None:
        raise LayerError("no light-field layer selected")
    if not is_lightfield(layer):
        raise LayerError(f"layer {layer.name!r} is not a 4D light field (shape {layer.data.shape})")
    arr = np.asarray(layer.data)
    if np.issubdtype(arr.dtype, np.integer):
        return arr.astype(np.float32) / np.float32(np.iinfo(arr.dtype).max)
    return arr


class EpiWidget(Container):
    """Dock widget: the EPI panel on its own, for any light-field layer."""

    def __init__(self, napari_viewer):
        self.viewer = napari_viewer
        self.epi = EpiPanel(napari_viewer)
        super().__init__(widgets=[self.epi], labels=False)
        self.native.layout().addStretch(1)
