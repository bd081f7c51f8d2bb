"""The *Blind deblur* dock widget: estimate the camera path and the sharp light field.

A thin shell over :func:`napari_lfdeblur.blind.iter_blind_deblur`, run in a
napari ``thread_worker``. Its magicgui form (``form``) holds the input
``layer``, the solver ``preset`` (choosing one shows its values in the
fields below), ``motion`` (3-DOF translation, or 6-DOF with a camera
rotation: an ``(n, 6)`` path, plotted in a second panel),
``n_control_points``, ``n_iter`` (path iterations),
``tv_iter`` (final TV iterations), ``restore_anyway`` (restore even when
the evidence test finds little blur), ``light_restoration`` (the scale of
the path of a light restoration then, made when two parts of the data
agree on the path; 0: the input), ``device``, ``seed``,
``infinity_disparity``, ``edge_anisotropy``, ``preview_every``, an
optional ``windows`` layer (a Shapes layer whose rectangles mark where the
path is estimated: ``blind_deblur(windows=...)``) and an optional
``true_path`` layer. While it runs:

- a progress bar with the stage, iteration, loss and time left;
- a live preview: the layer ``'<source> path (preview)'`` and the path plot
  show the current path (with the true path, dashed / cyan, when known),
  redrawn at most every :data:`REDRAW_INTERVAL` seconds and after a pause of
  :data:`REDRAW_SHARE` times what the last redraw took (the redraws run in
  Qt's thread and hold Python's lock, so they would otherwise slow the solver
  down on a machine with few cores); the layer ``'<source> blind (preview)'``
  shows the current light-field estimate every *preview every* progress
  records (computed in the worker thread);
- the loss curve.

Cancel stops the solver at its next progress report (in the final stage,
within the current iteration), removes the preview layers and adds nothing.
When it finishes, the previews are replaced by
``'<source> deblurred (blind)'`` (metadata: parameters, path, loss history,
timings, package version, the verdict of the evidence test in
``blur_evidence``, the final stage's weight in ``final_weight`` and the
windows the path was estimated on in ``path_windows``) and ``'<source> estimated path'``. When the data show
little blur, the result is a light restoration or the input with a zero
path (unless *restore anyway* is ticked), and a notification says why
(:attr:`napari_lfdeblur.blind.BlindResult.info`).
"""

from __future__ import annotations

import time

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Label

from ...path import validate_control_points
from ..layers import (
    LayerError,
    control_points_from_layer,
    layer_kind,
    lightfield_layer_data,
    lightfield_metadata,
    path_layer_data,
    remove_layer,
    windows_from_shapes,
)
from ._controls import (
    INFINITY_DISPARITY_TIP,
    LayerChoice,
    device_choice,
    fspin,
    infinity_disparity_field,
    has_path,
    heading,
    notify_info,
    set_stated,
    spin,
)
from ._plots import LossPlot, PathPlot
from ._runner import SolverWidget
from .epi import EpiPanel

__all__ = ["BlindDeblurWidget", "REDRAW_INTERVAL", "REDRAW_SHARE"]

#: least seconds between two redraws of the plots and the path preview during a run
REDRAW_INTERVAL = 0.3
#: a redraw that took ``c`` seconds is followed by at least ``REDRAW_SHARE * c`` seconds without one, so that
#: the redraws (in Qt's thread, holding Python's lock) take at most about 5 % of a run
REDRAW_SHARE = 20.0


def _iteration_field(params) -> tuple[str, str]:
    """The stage and field the *path iterations* field sets: Adam steps ('joint') or alternations per level."""
    return ("joint", "n_iter") if params.method == "joint" else ("path", "n_outer")


def _make_params(preset: str, *, n_control_points: int, n_iter: int, tv_iter: int, edge_anisotropy: float,
                 motion: str = "3dof", restore_anyway: bool = False, light_restoration: float | None = None):
    """``BlindParams`` of a preset with the form's values (``tv_iter`` 0: no final solve;
    ``restore_anyway``: ``require_evidence=False``; ``light_restoration``: its field, None: the preset's).

    Raises
    ------
    ValueError
        On values the parameters refuse (``motion='6dof'`` with the joint
        method of the 'paper' preset, say).
    """
    from ...blind import BlindParams

    params = BlindParams.preset(preset)
    if motion == "6dof" and params.method != "alternating":
        raise ValueError(f"6-DOF motion needs the alternating method (the 'default' preset); the {preset!r} "
                         f"preset's {params.method!r} method estimates translation only")
    stage, field = _iteration_field(params)
    return params.replace(
        n_control_points=n_control_points, final=None if tv_iter == 0 else {"n_iter": tv_iter},
        latent={"edge_anisotropy": edge_anisotropy}, motion=motion, require_evidence=not restore_anyway,
        light_restoration=params.light_restoration if light_restoration is None else light_restoration,
        **{stage: {field: n_iter}},
    )


def _preset_values(preset: str) -> dict:
    """The form's fields as a preset sets them."""
    from ...blind import BlindParams

    p = BlindParams.preset(preset)
    stage, field = _iteration_field(p)
    return {"n_control_points": p.n_control_points, "n_iter": getattr(getattr(p, stage), field),
            "tv_iter": 0 if p.final is None else p.final.n_iter, "edge_anisotropy": p.latent.edge_anisotropy,
            "motion": p.motion, "restore_anyway": not p.require_evidence, "light_restoration": p.light_restoration}


def _fields(viewer) -> list:
    """The solver fields of the form (the input layer aside)."""
    from ...blind import PRESETS

    return [
        ComboBox(name="preset", choices=list(PRESETS), value="default",
                 tooltip="solver parameter preset (BlindParams.preset)"),
        ComboBox(name="motion", choices=[("3-DOF (translation)", "3dof"), ("6-DOF (+ rotation)", "6dof")],
                 value="3dof", label="camera motion",
                 tooltip="3-DOF: the camera translates, an (n, 3) path. 6-DOF: for handheld shake; a rotation "
                 "stage (r_x, r_y, r_z, radians) follows the translation's estimate, an (n, 6) path. Slower; "
                 "'default' preset (alternating method) only (BlindParams.motion)"),
        spin("n_control_points", 4, 2, 12, label="control points",
             tooltip="control points of the estimated Bezier path"),
        spin("n_iter", 8, 1, 100000, label="path iterations", tooltip="path iterations: alternations "
             "per pyramid level ('default' preset) or joint Adam steps ('paper' preset)"),
        spin("tv_iter", 100, 0, 100000, label="final TV iterations", tooltip="iterations of the final "
             "non-blind TV solve (0: return the blurred input with the path)"),
        CheckBox(name="restore_anyway", value=False, label="restore anyway",
                 tooltip="restore with the estimated path even when the data give little evidence of blur "
                 "(BlindParams.require_evidence=False; unticked: then a light restoration or the input)"),
        fspin("light_restoration", PRESETS["default"].light_restoration, 0.0, 1.0, 0.05, label="light restoration",
              tooltip="when the data give little evidence of blur but two parts of them, estimated apart, agree "
              "on the path, restore with the estimated path scaled by this factor instead of returning the "
              "input (BlindParams.light_restoration; 0: the input)"),
        device_choice(),
        spin("seed", 0, 0, 2**31 - 1, tooltip="random seed of the initial path"),
        infinity_disparity_field(INFINITY_DISPARITY_TIP),
        fspin("edge_anisotropy", 0.0, -2.0, 2.0, 0.05, label="views softer along x (px)",
              tooltip="how much softer the camera's views are along x than along y, px "
              "(0: the same; see docs/blind.md)"),
        spin("preview_every", 10, 0, 1000, label="preview every", tooltip="preview the light field every "
             "N progress records (0: none); the path is previewed at every record"),
        LayerChoice(viewer, predicate=_marks_windows, nullable=True, name="windows", label="estimate path in",
                    tooltip="optional: a Shapes layer whose rectangles (drawn over the light field, at any view) "
                    "mark where the camera path is estimated; none: chosen from the data. Keep them off a subject "
                    "that moved by itself: its blur is not the camera's. The whole light field is restored"),
        LayerChoice(viewer, predicate=has_path, nullable=True, name="true_path", label="true path (optional)",
                    tooltip="a layer holding the true path, to plot for comparison"),
    ]


def _marks_windows(layer) -> bool:
    """Whether ``layer`` may mark the path's windows: a Shapes layer that is not a path layer (whose grey
    rectangle is the aperture)."""
    return layer_kind(layer) == "shapes" and not has_path(layer)


class BlindDeblurWidget(SolverWidget):
    """Dock widget: blind motion deblurring of a light-field layer."""

    title = "Blind deblur"

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer)
        self.form.extend(_fields(napari_viewer))
        self.plot = PathPlot()
        self.loss_plot = LossPlot()
        self.epi = EpiPanel(napari_viewer)
        caption = Label(value="camera path (solid: estimate, dashed: true)")
        self.assemble(after=[heading("Path and loss"), caption, self.plot, self.loss_plot, self.epi])
        self.form.preset.changed.connect(self._preset_changed)
        self.form.restore_anyway.changed.connect(self._restore_anyway_changed)
        self._preset_changed()
        self.follow_input(self._input_changed)
        self._next_draw = 0.0
        self.preview_updates = 0
        self.path_preview_updates = 0
        # napari imports pandas for the features table of the first Shapes layer it makes (about half a
        # second); the path preview is such a layer, drawn in Qt's thread during a run: pay it now instead
        import pandas  # noqa: F401

    def _preset_changed(self, *_):
        """Show the preset's values in the fields."""
        try:
            values = _preset_values(self.form.preset.value)
        except ValueError:
            return
        for key, value in values.items():
            self.form[key].value = value

    def _restore_anyway_changed(self, *_):
        """A light restoration is for little blur found; restoring anyway makes it moot."""
        self.form.light_restoration.enabled = not self.form.restore_anyway.value

    def _input_changed(self, *_):
        """Take the true path and the infinity disparity the chosen layer states, where it states them.

        A true path or an infinity disparity taken from the previous input is dropped when the new one states
        none (the disparity back to 0, with a notice).
        """
        layer = self.layer_combo.value
        if layer is None:
            return
        if has_path(layer):
            self.form.true_path.set_layer(layer)
            self._true_from_input = layer
        elif self.form.true_path.value is not None and self.form.true_path.value is getattr(self, "_true_from_input", 0):
            self.form.true_path.value = None
        field = self.form.infinity_disparity
        if "infinity_disparity" in layer.metadata:
            if set_stated(field, layer.metadata["infinity_disparity"], f"{self.title}: layer {layer.name!r}"):
                self._dinf_from_input = field.value
        elif field.value != 0.0 and field.value == getattr(self, "_dinf_from_input", None):
            field.value, self._dinf_from_input = 0.0, None
            notify_info(f"{self.title}: layer {layer.name!r} states no infinity disparity; the previous layer's is "
                        "not carried over (set to 0)")

    def true_path(self):
        """The chosen true path, or None.

        It is moved to the zero-mean gauge and the canonical time direction of
        the blind estimates, so that the two can be compared by eye (the blur
        depends on neither; docs/model.md).
        """
        from ...path import canonical_time_direction
        from ...path import center_path

        from ...io._write import check_path_field

        layer = self.form.true_path.value
        if layer is None:
            return None
        try:
            cp = control_points_from_layer(layer)
        except LayerError:
            return None
        try:  # drawn for comparison only: an odd T stated in the layer falls back to the default
            n_times = check_path_field("n_times", layer.metadata.get("n_times", 32), "the true path's layer")
        except ValueError:
            n_times = 32
        return canonical_time_direction(center_path(cp, n_times))

    def preview_name(self) -> str:
        """Name of the light-field preview layer of the current run."""
        return f"{self._job['source']} blind (preview)" if getattr(self, "_job", None) else ""

    def path_preview_name(self) -> str:
        """Name of the path preview layer of the current run."""
        return f"{self._job['source']} path (preview)" if getattr(self, "_job", None) else ""

    def preview_every(self) -> int:
        return int(self.form.preview_every.value)

    # ------------------------------------------------------------- job
    def make_job(self, layer, lf):
        from ...blind import iter_blind_deblur

        f = self.form
        params = _make_params(f.preset.value, n_control_points=f.n_control_points.value, n_iter=f.n_iter.value,
                              tv_iter=f.tv_iter.value, edge_anisotropy=f.edge_anisotropy.value,
                              motion=f.motion.value, restore_anyway=f.restore_anyway.value,
                              light_restoration=f.light_restoration.value)
        settings = {"preset": f.preset.value, "device": f.device.value, "seed": f.seed.value,
                    "infinity_disparity": f.infinity_disparity.value}
        windows = None if f.windows.value is None else windows_from_shapes(f.windows.value, layer)
        if windows is not None:
            settings["windows"] = [list(w) for w in windows]
        # a layer the reader made was checked for transposed views when read (it records view_shifts)
        gen = iter_blind_deblur(lf, infinity_disparity=settings["infinity_disparity"], params=params,
                                device=settings["device"], seed=settings["seed"], windows=windows,
                                check_view_order="view_shifts" not in layer.metadata)
        self._job = {"source": layer.name, "shape": lf.shape, "true": self.true_path(),
                     "n_times": params.n_times, "settings": settings}
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
            self.add_result(data)
            self.preview_updates += 1
        start = time.perf_counter()
        if start >= self._next_draw:
            self._redraw_live(progress)
            end = time.perf_counter()
            self._next_draw = end + max(REDRAW_INTERVAL, REDRAW_SHARE * (end - start))

    def _redraw_live(self, progress) -> None:
        """Redraw the loss curve, the path plot and the path preview layer."""
        self.loss_plot.plot(self.loss_plot.values, live=True)
        if progress.control_points is not None:
            self.plot.plot(progress.control_points, self._job["true"], live=True)
            self.add_result(path_layer_data(
                progress.control_points, self._job["shape"], n_times=self._job["n_times"],
                name=self.path_preview_name(), true_control_points=self._job["true"],
                metadata={"kind": "path preview"}))
            self.path_preview_updates += 1

    def _adopt_previews(self, name: str, path_name: str) -> None:
        """Rename the preview layers to the result layers' names (where those are free), so that adding the
        results updates them in place: a new layer would cost Qt's thread a new canvas visual."""
        for old, new in ((self.preview_name(), name), (self.path_preview_name(), path_name)):
            if old in self.viewer.layers and new not in self.viewer.layers:
                self.viewer.layers[old].name = new

    def cleanup(self) -> None:
        if getattr(self, "_job", None):
            remove_layer(self.viewer, self.preview_name())
            remove_layer(self.viewer, self.path_preview_name())

    def on_result(self, result) -> None:
        job = self._job
        cp = validate_control_points(result.control_points)
        params = result.params.to_dict() if hasattr(result.params, "to_dict") else dict(result.params)
        n_times = int(params["final_n_times"])  # the instants the result was restored with
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
        if "message" in (getattr(result, "info", None) or {}):
            meta["blur_evidence"] = result.info["message"]
        if (getattr(result, "info", None) or {}).get("final_weight") is not None:
            meta["final_weight"] = result.info["final_weight"]  # the final stage's weight (the noise rule's choice)
        if (getattr(result, "info", None) or {}).get("windows"):  # where the path was estimated, as the CLI records
            meta["path_windows"] = [list(w) for w in result.info["windows"]]
        path_name = f"{job['source']} estimated path"
        self._adopt_previews(name, path_name)
        out = self.add_result(lightfield_layer_data(result.lightfield, name=name, metadata=meta))
        d_inf = job["settings"]["infinity_disparity"]
        path = self.add_result(path_layer_data(
            cp, job["shape"], n_times=n_times, name=path_name, true_control_points=job["true"],
            infinity_disparity=d_inf, metadata={"source_layer": out.name}))
        layers = self.viewer.layers
        if layers.index(out) > layers.index(path):
            layers.move(layers.index(out), layers.index(path))  # the path is drawn over the light field
        self.last_layers = [out, path]
        info = getattr(result, "info", None) or {}
        note = ""
        if "rejected_path" in info:  # kept as a layer, for *4D deconvolution*: no need to estimate it again
            rejected = self.add_result(path_layer_data(
                info["rejected_path"], job["shape"], n_times=n_times, name=f"{job['source']} rejected path",
                true_control_points=job["true"], infinity_disparity=d_inf,
                metadata={"kind": "rejected path", "source_layer": out.name}))
            self.last_layers.append(rejected)
            note = f"; the path it rejected is in the layer '{rejected.name}', for 4D deconvolution"
        else:  # an earlier run's rejected path is not this result's
            remove_layer(self.viewer, f"{job['source']} rejected path")
        self.plot.plot(cp, job["true"], n_times=max(64, n_times))
        if meta["loss_history"] and len(meta["loss_history"]) != len(self.loss_plot.values):
            self.loss_plot.plot(meta["loss_history"], [])
        else:
            self.loss_plot.plot(self.loss_plot.values)
        self.epi.layer_combo.set_layer(out)
        if info.get("blur_found") is False or info.get("restoration") == "none":  # not the restoration asked for
            notify_info(f"{self.title}: {info.get('message', 'little blur found')}{note}")
