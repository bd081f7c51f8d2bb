"""The *4D deconvolution* dock widget: undo a known camera path.

A thin shell over :func:`napari_lfdeblur.deconvolution.iter_deconvolve`. The
path comes from

- the blurred layer's own ``metadata['control_points']`` (set by the
  *Simulate blur* widget and by readers that find a path file), filled in
  automatically when the layer is chosen;
- any other layer holding a path (a path layer, a blind result), through
  *Take path from*;
- or typed into the table (or loaded from a path JSON file).

Running it adds ``'<source> deconvolved'`` with the parameters, the path and
the package version in its metadata.
"""

from __future__ import annotations

from qtpy.QtWidgets import QComboBox, QFileDialog, QGroupBox, QHBoxLayout, QPushButton, QVBoxLayout

from ...path import load_path_json
from ..layers import (
    LayerError,
    add_layer,
    control_points_from_layer,
    lightfield_layer_data,
    lightfield_metadata,
)
from ._common import (
    EpiPanel,
    LayerComboBox,
    PathPlot,
    PathTable,
    SolverWidget,
    device_combo,
    dspin,
    has_path,
    notify_error,
    spin,
)

__all__ = ["DeconvolveWidget"]


class DeconvolveWidget(SolverWidget):
    """Dock widget: non-blind 4D deconvolution with a known camera path."""

    title = "4D deconvolution"

    def __init__(self, napari_viewer, parent=None):
        super().__init__(napari_viewer, parent)
        from ...deconvolution import METHODS

        self.path_layer_combo = LayerComboBox(napari_viewer, predicate=has_path, allow_none=True)
        self.path_layer_combo.setToolTip("a layer whose metadata holds a camera path (path layers, results)")
        self.take_button = QPushButton("Take path")
        self.load_button = QPushButton("Load JSON...")
        self.table = PathTable()
        self.plot = PathPlot()
        group = QGroupBox("Camera path")
        g = QVBoxLayout(group)
        row = QHBoxLayout()
        row.addWidget(self.path_layer_combo, 1)
        row.addWidget(self.take_button)
        row.addWidget(self.load_button)
        g.addLayout(row)
        g.addWidget(self.table)
        g.addWidget(self.plot)
        self.extra_layout.addWidget(group)

        self.n_times_spin = spin(32, 2, 1024, "exposure instants T of the blur model")
        self.d_inf_spin = dspin(0.0, -20.0, 20.0, 0.1, 3, "infinity disparity d_inf, px/view")
        self.method_combo = QComboBox()
        self.method_combo.addItems(list(METHODS))
        self.method_combo.setToolTip("auto: exact in-plane solve when p_z = 0 and d_inf = 0, else 4D TV")
        self.weight_spin = dspin(2e-3, 0.0, 10.0, 1e-3, 5, "regularisation weight (TV or angular Tikhonov)")
        self.iter_spin = spin(100, 1, 100000, "maximum iterations of the TV solver")
        self.device_combo = device_combo()
        self.form.addRow("instants T", self.n_times_spin)
        self.form.addRow("infinity disparity", self.d_inf_spin)
        self.form.addRow("method", self.method_combo)
        self.form.addRow("weight", self.weight_spin)
        self.form.addRow("iterations", self.iter_spin)
        self.form.addRow("device", self.device_combo)

        self.epi = EpiPanel(napari_viewer)
        self.after_layout.addWidget(self.epi)

        self.layer_combo.currentTextChanged.connect(self._input_changed)
        self.take_button.clicked.connect(self.take_path)
        self.load_button.clicked.connect(self._load_json)
        self.table.changed.connect(self._replot)
        self._input_changed()

    # ------------------------------------------------------------ path
    def _input_changed(self, *_):
        """Fill the path (and T, d_inf) from the chosen blurred layer when it holds one."""
        layer = self.layer_combo.current_layer()
        if layer is not None and has_path(layer):
            self._take_from(layer, quiet=True)

    def take_path(self, *_):
        """Fill the table from the layer chosen in *Take path from*."""
        layer = self.path_layer_combo.current_layer()
        self._take_from(layer, quiet=False)

    def _take_from(self, layer, quiet: bool):
        try:
            cp = control_points_from_layer(layer)
        except LayerError as exc:
            if not quiet:
                notify_error(f"{self.title}: {exc}")
            return
        meta = layer.metadata
        if "n_times" in meta:
            self.n_times_spin.setValue(int(meta["n_times"]))
        if "infinity_disparity" in meta:
            self.d_inf_spin.setValue(float(meta["infinity_disparity"]))
        self.table.set_control_points(cp)

    def _load_json(self, *_):  # pragma: no cover - file dialog
        name, _filter = QFileDialog.getOpenFileName(self, "Camera path", "", "JSON (*.json)")
        if name:
            try:
                self.table.set_control_points(load_path_json(name))
            except (OSError, ValueError) as exc:
                notify_error(f"{self.title}: {exc}")

    def _replot(self, *_):
        try:
            cp = self.table.control_points()
        except ValueError:
            return
        self.plot.plot(cp, n_times=self.n_times_spin.value())

    # ------------------------------------------------------------- job
    def parameters(self) -> dict:
        return {
            "method": self.method_combo.currentText(),
            "weight": self.weight_spin.value(),
            "n_iter": self.iter_spin.value(),
            "n_times": self.n_times_spin.value(),
            "infinity_disparity": self.d_inf_spin.value(),
            "device": self.device_combo.currentText(),
        }

    def make_job(self, layer, lf):
        from ...deconvolution import iter_deconvolve

        cp = self.table.control_points()
        p = self.parameters()
        # argument errors surface here, in the GUI thread, as a notification
        gen = iter_deconvolve(
            lf, cp, n_times=p["n_times"], infinity_disparity=p["infinity_disparity"],
            method=p["method"], weight=p["weight"], n_iter=p["n_iter"], device=p["device"],
        )
        self._job = {"source": layer.name, "cp": cp, "params": p}
        return lambda: gen

    def on_result(self, result) -> None:
        job = self._job
        p = job["params"]
        name = f"{job['source']} deconvolved"
        meta = lightfield_metadata(
            kind="deconvolved",
            parameters={**p, "operation": "deconvolve"},
            control_points=job["cp"],
            n_times=p["n_times"],
            infinity_disparity=p["infinity_disparity"],
            source_layer=job["source"],
        )
        out = add_layer(self.viewer, lightfield_layer_data(result, name=name, metadata=meta))
        self.last_layers = [out]
        self.epi.layer_combo.set_layer(out)
