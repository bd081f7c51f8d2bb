"""The *Blind deblur* dock widget: estimate the camera path and the sharp light field.

A thin shell over :func:`napari_lfdeblur.blind.iter_blind_deblur`, run in a
napari ``thread_worker``. While it runs:

- a progress bar with the time left (extrapolated from the fraction done);
- a live preview: the layer ``'<source> path (preview)'`` and the path plot
  show the current path (with the true path, dashed / cyan, when the input
  layer's metadata holds one, e.g. after *Simulate blur*), redrawn at most
  every 0.3 s, and after a pause of five times what the last redraw took (the
  redraws run in Qt's thread and hold Python's lock, so that on a slow machine
  they would otherwise slow the solver down: ``benchmarks/widget_overhead.py``);
  the layer ``'<source> blind (preview)'`` shows the current light-field
  estimate whenever the solver sends one (every *preview every* reports: the
  salient-edge latent during path estimation, then the estimate of the final
  non-blind stage);
- the loss curve.

Cancel stops the solver at its next progress report, which comes after
every conjugate-gradient step of the latent solve, every 10 path-fit steps
and every TV iteration (at most 3 blur evaluations apart; on a 9x9x128x128
light field on a loaded 2-core CPU, 0.5 s apart typically, 1.9 s at most), removes
the preview layers and adds nothing. When it finishes, the preview is replaced by
``'<source> deblurred (blind)'`` (metadata: parameters, path, loss history,
timings, package version) and ``'<source> estimated path'``.
"""

from __future__ import annotations

import time

import numpy as np
from qtpy.QtWidgets import QComboBox, QGroupBox, QLabel, QVBoxLayout

from ...path import validate_control_points
from ..layers import (
    LayerError,
    add_layer,
    control_points_from_layer,
    lightfield_layer_data,
    lightfield_metadata,
    path_layer_data,
    remove_layer,
)
from ._common import (
    EpiPanel,
    LayerComboBox,
    LossPlot,
    PathPlot,
    SolverWidget,
    device_combo,
    dspin,
    has_path,
    spin,
)

__all__ = ["BlindDeblurWidget"]

#: least seconds between two redraws of the plots and the path preview during a run
REDRAW_INTERVAL = 0.3
#: a redraw that took ``c`` seconds is followed by at least ``REDRAW_SHARE * c`` seconds without
#: one, so that redraws (Qt's thread, holding Python's lock) leave the solver most of the time
#: on a slow machine
REDRAW_SHARE = 5.0


def _presets() -> list[str]:
    from ...blind import PRESETS

    return list(PRESETS)


def _iteration_field(params) -> str:
    """The BlindParams field the *iterations* box sets: Adam steps ('joint') or alternations per level."""
    return "n_iter" if params.method == "joint" else "n_outer"


def _make_params(preset: str, *, n_points: int, n_iter: int, tv_iter: int, preview_every: int,
                 edge_anisotropy: float = 0.0):
    """``BlindParams`` of a preset with the widget's values."""
    from ...blind import BlindParams

    params = BlindParams.preset(preset)
    return params.replace(
        n_control_points=n_points, tv_iter=tv_iter, preview_every=preview_every,
        edge_anisotropy=edge_anisotropy, **{_iteration_field(params): n_iter},
    )


class BlindDeblurWidget(SolverWidget):
    """Dock widget: blind motion deblurring of a light-field layer."""

    title = "Blind deblur"

    def __init__(self, napari_viewer, parent=None):
        super().__init__(napari_viewer, parent)
        self.preset_combo = QComboBox()
        self.preset_combo.addItems(_presets())
        self.preset_combo.setToolTip("solver parameter preset (BlindParams.preset)")
        self.points_spin = spin(4, 2, 12, "control points of the estimated Bezier path")
        self.iter_spin = spin(8, 1, 100000, "path iterations: alternations per pyramid level "
                              "('default' preset) or joint Adam steps ('paper' preset)")
        self.tv_iter_spin = spin(100, 0, 100000, "iterations of the final non-blind TV solve "
                                 "(0: return the blurred input with the path)")
        self.device_combo = device_combo()
        self.seed_spin = spin(0, 0, 2**31 - 1, "random seed of the initial path")
        self.d_inf_spin = dspin(0.0, -20.0, 20.0, 0.1, 3, "infinity disparity d_inf, px/view")
        self.anisotropy_spin = dspin(0.0, -2.0, 2.0, 0.05, 2, "how much softer the camera's views are "
                                     "along x than along y, px (BlindParams.edge_anisotropy; views "
                                     "decoded from a first-generation Lytro: about 0.6; 0: the same)")
        self.preview_spin = spin(10, 0, 1000, "preview the light field every N iterations of the "
                                 "final solve (0: none); the path is previewed at every iteration")
        self.true_combo = LayerComboBox(napari_viewer, predicate=has_path, allow_none=True)
        self.true_combo.setToolTip("a layer holding the true path, to plot for comparison (optional)")
        self.form.addRow("preset", self.preset_combo)
        self.form.addRow("control points", self.points_spin)
        self.form.addRow("path iterations", self.iter_spin)
        self.form.addRow("final TV iterations", self.tv_iter_spin)
        self.form.addRow("device", self.device_combo)
        self.form.addRow("seed", self.seed_spin)
        self.form.addRow("infinity disparity", self.d_inf_spin)
        self.form.addRow("views softer along x (px)", self.anisotropy_spin)
        self.form.addRow("preview every", self.preview_spin)
        self.form.addRow("true path (optional)", self.true_combo)

        plots = QGroupBox("Path and loss")
        g = QVBoxLayout(plots)
        self.plot = PathPlot()
        self.loss_plot = LossPlot()
        g.addWidget(QLabel("camera path (solid: estimate, dashed: true)"))
        g.addWidget(self.plot)
        g.addWidget(self.loss_plot)
        self.after_layout.addWidget(plots)
        self.epi = EpiPanel(napari_viewer)
        self.after_layout.addWidget(self.epi)

        self.layer_combo.currentTextChanged.connect(self._input_changed)
        self.preset_combo.currentTextChanged.connect(self._preset_changed)
        self._preset_changed()
        self._input_changed()
        self._next_draw = 0.0
        self.preview_updates = 0
        self.path_preview_updates = 0

    def _preset_changed(self, *_):
        """Show the preset's values in the boxes."""
        from ...blind import BlindParams

        try:
            p = BlindParams.preset(self.preset_combo.currentText())
        except ValueError:
            return
        self.points_spin.setValue(p.n_control_points)
        self.iter_spin.setValue(getattr(p, _iteration_field(p)))
        self.tv_iter_spin.setValue(p.tv_iter)
        self.preview_spin.setValue(p.preview_every)
        self.anisotropy_spin.setValue(p.edge_anisotropy)

    def _input_changed(self, *_):
        layer = self.layer_combo.current_layer()
        if layer is not None and has_path(layer):
            self.true_combo.set_layer(layer)
            if "infinity_disparity" in layer.metadata:
                self.d_inf_spin.setValue(float(layer.metadata["infinity_disparity"]))

    def true_path(self):
        """The chosen true path, or None.

        It is moved to the zero-mean gauge and the canonical time direction of
        the blind estimates, so that the two can be compared by eye (the blur
        does not depend on either, MODEL.md "Ambiguities").
        """
        from ...blind import canonical_time_direction
        from ...path import center_path

        layer = self.true_combo.current_layer()
        if layer is None:
            return None
        try:
            cp = control_points_from_layer(layer)
        except LayerError:
            return None
        n_times = int(layer.metadata.get("n_times", 32))
        return canonical_time_direction(center_path(cp, n_times))

    def preview_name(self) -> str:
        """Name of the light-field preview layer of the current run."""
        return f"{self._job['source']} blind (preview)" if getattr(self, "_job", None) else ""

    def path_preview_name(self) -> str:
        """Name of the path preview layer of the current run."""
        return f"{self._job['source']} path (preview)" if getattr(self, "_job", None) else ""

    # ------------------------------------------------------------- job
    def make_job(self, layer, lf):
        from ...blind import iter_blind_deblur

        params = _make_params(
            self.preset_combo.currentText(),
            n_points=self.points_spin.value(),
            n_iter=self.iter_spin.value(),
            tv_iter=self.tv_iter_spin.value(),
            preview_every=self.preview_spin.value(),
            edge_anisotropy=self.anisotropy_spin.value(),
        )
        device = self.device_combo.currentText()
        d_inf = self.d_inf_spin.value()
        seed = self.seed_spin.value()
        gen = iter_blind_deblur(lf, infinity_disparity=d_inf, params=params, device=device, seed=seed)
        self._job = {
            "source": layer.name,
            "shape": lf.shape,
            "true": self.true_path(),
            "n_times": params.n_times,
            "settings": {"preset": self.preset_combo.currentText(), "device": device,
                         "seed": seed, "infinity_disparity": d_inf},
        }
        self.loss_plot.reset()
        self.plot.plot(None, self._job["true"])
        self._next_draw = 0.0
        self.preview_updates = 0
        self.path_preview_updates = 0
        return lambda: gen

    def on_progress(self, progress) -> None:
        if np.isfinite(progress.loss) and not progress.stage.startswith("final"):
            # the path-estimation objective (the final TV stage has another one)
            self.loss_plot.append(progress.loss, stage=progress.stage)
        if progress.preview is not None:
            data = lightfield_layer_data(progress.preview, name=self.preview_name(),
                                         metadata=lightfield_metadata(kind="preview"), opacity=1.0)
            add_layer(self.viewer, data)
            self.preview_updates += 1
        start = time.perf_counter()
        if start >= self._next_draw:
            self.loss_plot.plot(self.loss_plot.values, live=True)
            if progress.control_points is not None:
                self.plot.plot(progress.control_points, self._job["true"], live=True)
                add_layer(self.viewer, path_layer_data(
                    progress.control_points, self._job["shape"], n_times=self._job["n_times"],
                    name=self.path_preview_name(), true_control_points=self._job["true"],
                    metadata={"kind": "path preview"}))
                self.path_preview_updates += 1
            end = time.perf_counter()
            self._next_draw = end + max(REDRAW_INTERVAL, REDRAW_SHARE * (end - start))

    def cleanup(self) -> None:
        if getattr(self, "_job", None):
            remove_layer(self.viewer, self.preview_name())
            remove_layer(self.viewer, self.path_preview_name())

    def on_result(self, result) -> None:
        job = self._job
        cp = validate_control_points(result.control_points)
        params = result.params.to_dict() if hasattr(result.params, "to_dict") else dict(result.params)
        n_times = int(params.get("n_times", 32))
        name = f"{job['source']} deblurred (blind)"
        meta = lightfield_metadata(
            kind="blind",
            parameters={**params, **job["settings"], "operation": "blind_deblur"},
            control_points=cp,
            n_times=n_times,
            infinity_disparity=job["settings"]["infinity_disparity"],
            source_layer=job["source"],
            loss_history=[float(v) for v in getattr(result, "loss_history", [])],
            timings=dict(getattr(result, "timings", {}) or {}),
        )
        out = add_layer(self.viewer, lightfield_layer_data(result.lightfield, name=name, metadata=meta))
        path = add_layer(self.viewer, path_layer_data(
            cp, job["shape"], n_times=n_times, name=f"{job['source']} estimated path",
            true_control_points=job["true"]))
        self.last_layers = [out, path]
        self.plot.plot(cp, job["true"], n_times=max(64, n_times))
        if meta["loss_history"] and len(meta["loss_history"]) != len(self.loss_plot.values):
            self.loss_plot.plot(meta["loss_history"], [])
        else:
            self.loss_plot.plot(self.loss_plot.values)
        self.epi.layer_combo.set_layer(out)
