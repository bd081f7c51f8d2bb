"""The *Simulate blur* dock widget: blur a light-field layer by a camera path.

A thin shell over :func:`napari_lfdeblur.simulate_blur`. The path is edited
in a table of control points, filled from a preset (linear, arc, shake) or a
random path with a seed. Running it adds:

- ``'<source> blurred'``: the blurred light field (metadata: the path in
  ``'control_points'``, ``'n_times'``, ``'infinity_disparity'``, the
  parameters and the package version), which the deconvolution and blind
  widgets pick up as the (true) path;
- ``'<source> blurred path'``: the path drawn over the centre view (frame:
  :mod:`napari_lfdeblur._napari.layers`).
"""

from __future__ import annotations

from qtpy.QtWidgets import QComboBox, QFormLayout, QGroupBox, QHBoxLayout, QPushButton

from ...progress import Progress
from ...path import preset_path, random_path
from ..layers import add_layer, lightfield_layer_data, lightfield_metadata, path_layer_data
from ._common import (
    EpiPanel,
    PathPlot,
    PathTable,
    SolverWidget,
    device_combo,
    dspin,
    spin,
)

__all__ = ["SimulateBlurWidget"]


class SimulateBlurWidget(SolverWidget):
    """Dock widget: simulate the motion blur of a light-field layer."""

    title = "Simulate blur"

    def __init__(self, napari_viewer, parent=None):
        super().__init__(napari_viewer, parent)
        # path presets
        self.preset_combo = QComboBox()
        self.preset_combo.addItems(["linear", "arc", "shake"])
        self.extent_spin = dspin(2.0, 0.0, 50.0, 0.25, 2, "size of the motion, in views")
        self.preset_button = QPushButton("Apply preset")
        self.n_points_spin = spin(4, 2, 12, "control points of the random path")
        self.seed_spin = spin(0, 0, 2**31 - 1, "random seed (random path and shake preset)")
        self.random_button = QPushButton("Random path")
        self.table = PathTable(preset_path("linear", 2.0))
        self.plot = PathPlot()

        group = QGroupBox("Camera path")
        g = QFormLayout(group)
        row = QHBoxLayout()
        row.addWidget(self.preset_combo)
        row.addWidget(self.extent_spin)
        row.addWidget(self.preset_button)
        g.addRow("preset / extent", row)
        row = QHBoxLayout()
        row.addWidget(self.n_points_spin)
        row.addWidget(self.seed_spin)
        row.addWidget(self.random_button)
        g.addRow("points / seed", row)
        g.addRow(self.table)
        g.addRow(self.plot)
        self.extra_layout.addWidget(group)

        self.n_times_spin = spin(32, 2, 1024, "exposure instants T")
        self.d_inf_spin = dspin(0.0, -20.0, 20.0, 0.1, 3, "infinity disparity d_inf, px/view")
        self.device_combo = device_combo()
        self.form.addRow("instants T", self.n_times_spin)
        self.form.addRow("infinity disparity", self.d_inf_spin)
        self.form.addRow("device", self.device_combo)

        self.epi = EpiPanel(napari_viewer)
        self.after_layout.addWidget(self.epi)

        self.preset_button.clicked.connect(self.apply_preset)
        self.random_button.clicked.connect(self.apply_random)
        self.table.changed.connect(self._replot)
        self._replot()

    # ------------------------------------------------------------ path
    def apply_preset(self, *_):
        """Fill the table with the chosen preset of the chosen extent."""
        cp = preset_path(self.preset_combo.currentText(), extent=self.extent_spin.value(),
                         seed=self.seed_spin.value())
        self.table.set_control_points(cp)

    def apply_random(self, *_):
        """Fill the table with a random path (points, extent and seed from the spin boxes)."""
        cp = random_path(n_points=self.n_points_spin.value(), extent=self.extent_spin.value(),
                         seed=self.seed_spin.value())
        self.table.set_control_points(cp)

    def _replot(self, *_):
        try:
            cp = self.table.control_points()
        except ValueError:
            return
        self.plot.plot(cp, n_times=self.n_times_spin.value())

    # ------------------------------------------------------------- job
    def make_job(self, layer, lf):
        from ...blur import simulate_blur

        cp = self.table.control_points()
        params = {
            "n_times": self.n_times_spin.value(),
            "infinity_disparity": self.d_inf_spin.value(),
            "device": self.device_combo.currentText(),
        }
        self._job = {"source": layer.name, "cp": cp, "params": params, "shape": lf.shape}

        def job():
            yield Progress("blur", 0, 1)
            out = simulate_blur(lf, cp, n_times=params["n_times"],
                                infinity_disparity=params["infinity_disparity"], device=params["device"])
            yield Progress("blur", 1, 1)
            return out

        return job

    def on_result(self, blurred) -> None:
        job = self._job
        p = job["params"]
        name = f"{job['source']} blurred"
        meta = lightfield_metadata(
            kind="blurred",
            parameters={**p, "operation": "simulate_blur"},
            control_points=job["cp"],
            n_times=p["n_times"],
            infinity_disparity=p["infinity_disparity"],
            source_layer=job["source"],
        )
        out = add_layer(self.viewer, lightfield_layer_data(blurred, name=name, metadata=meta))
        path = add_layer(self.viewer, path_layer_data(job["cp"], job["shape"], n_times=p["n_times"],
                                                      name=f"{name} path"))
        self.last_layers = [out, path]
        self.plot.plot(job["cp"], n_times=p["n_times"])
        self.epi.layer_combo.set_layer(out)
