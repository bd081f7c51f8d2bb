"""The *4D deconvolution* dock widget: undo a known camera path.

A thin shell over :func:`napari_lfdeblur.deconvolution.iter_deconvolve`. Its
magicgui form (``form``) holds the input ``layer`` and the solver's keyword
arguments: ``n_times``, ``infinity_disparity``, ``method``, ``weight`` (None when
``noise_weight`` is ticked: the noise rule),
``n_iter``, ``device``. The path (``table``) comes from

- the blurred layer's own ``metadata['control_points']`` (set by the
  *Simulate blur* widget and by readers that find a path file), filled in
  automatically when the layer is chosen;
- any other layer holding a path (a path layer, a blind result), through
  *Take path* (``path_source``);
- a path JSON file (``path_source.json_file``);
- or typed into the table.

Each of these sets ``n_times`` and ``infinity_disparity`` too where it states
them; a blurred layer that holds no path but states ``infinity_disparity``
sets that.

Running it adds ``'<source> deconvolved'`` with the parameters (and the weight
the solve used, ``weight_used``, with ``noise_sigma``), the path and the
package version in its metadata.
"""

from __future__ import annotations

from magicgui.widgets import CheckBox, ComboBox

from ..layers import lightfield_layer_data, lightfield_metadata
from ._controls import (
    INFINITY_DISPARITY_TIP,
    PathSource,
    PathTable,
    device_choice,
    fill_path,
    fspin,
    infinity_disparity_field,
    has_path,
    heading,
    set_stated,
    spin,
    warn_view_mismatch,
)
from ._plots import PathPlot
from ._runner import SolverWidget
from .epi import EpiPanel

__all__ = ["DeconvolveWidget"]


def _fields() -> list:
    """The solver fields of the form, named as ``iter_deconvolve``'s keyword arguments."""
    from ...deconvolution import ANISOTROPIC_WEIGHT_SCALE, COLOUR_WEIGHT_FACTOR, METHODS, NOISE_WEIGHT_FACTOR

    return [
        spin("n_times", 32, 2, 1024, label="instants T", tooltip="exposure instants T of the blur model"),
        infinity_disparity_field(INFINITY_DISPARITY_TIP),
        ComboBox(name="method", choices=[m for m in METHODS if m != "auto"], value="tv",
                 tooltip="tv: 4D total variation, any path and d_inf; inplane: the exact angular solve, "
                         "p_z = 0 and d_inf = 0 only"),
        CheckBox(name="couple_channels", value=True, label="colour TV",
                 tooltip="tv on colour: one TV over the channels, which keeps the edges they share (the "
                         "default); untick for one TV per channel, in about a third of the memory"),
        CheckBox(name="along_disparity", value=True, label="TV along disparity",
                 tooltip="tv: the anisotropic TV whose angular differences follow the scene's disparity (estimated "
                         "from the data), which charges noise and ringing but not the scene's parallax (the "
                         "default); untick for the isotropic TV between the same pixel of neighbouring views, "
                         "about twice as fast, which restores less well (its weight from the noise is twice this "
                         "one's)"),
        CheckBox(name="saturation", value=True, label="saturated samples",
                 tooltip="tv: samples at 1 are taken as clipped by the sensor (the light there reached at least "
                         "1): the blur of the result must reach 1 there, and the result is clipped to [0, 1] "
                         "(the default); untick to fit them as they are"),
        CheckBox(name="noise_weight", value=True, label="weight from noise",
                 tooltip=f"TV weight = {COLOUR_WEIGHT_FACTOR} x (colour TV) or {NOISE_WEIGHT_FACTOR} x (one TV per "
                         f"channel) the noise level estimated in the data, times {ANISOTROPIC_WEIGHT_SCALE} along the "
                         "disparity (inplane: 2e-3); untick to set the weight yourself"),
        # 7 decimals: a small weight must not round to 0 (no regularisation); the arrows step by 1e-3
        fspin("weight", 2e-3, 0.0, 10.0, 1e-7, tooltip="regularisation weight (TV or angular Tikhonov)"),
        spin("n_iter", 100, 1, 100000, label="iterations", tooltip="maximum iterations of the TV solver"),
        device_choice(),
    ]


class DeconvolveWidget(SolverWidget):
    """Dock widget: non-blind 4D deconvolution with a known camera path."""

    title = "4D deconvolution"

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer)
        self.form.extend(_fields())
        self.form.weight.native.setSingleStep(1e-3)
        self.form.noise_weight.changed.connect(self._weight_mode)
        self._weight_mode()
        self.path_source = PathSource(napari_viewer, self.set_path, title=self.title)
        self.table = PathTable()
        self.plot = PathPlot()
        self.epi = EpiPanel(napari_viewer)
        self.assemble(before=[heading("Camera path"), self.path_source, self.table, self.plot], after=[self.epi])
        self.table.changed.connect(self._replot)
        self.follow_input(self._input_changed)

    # ------------------------------------------------------------ path
    def set_path(self, control_points, metadata=None) -> None:
        """Fill the table (and ``n_times``, ``infinity_disparity`` when ``metadata`` has them).

        A stated value the form cannot take (not a number, not whole for
        ``n_times``, outside the field's range) is left out with a warning
        notification; the field keeps its value.
        """
        fill_path(self.form, self.table, control_points, metadata, f"{self.title}: the path")

    def _input_changed(self, *_):
        """Take the path (and T, d_inf) of the chosen blurred layer when it holds one, else the d_inf it states."""
        layer = self.layer_combo.value
        if layer is not None and has_path(layer):
            self.path_source.take_from(layer, quiet=True)
        elif layer is not None and "infinity_disparity" in layer.metadata:
            set_stated(self.form.infinity_disparity, layer.metadata["infinity_disparity"],
                       f"{self.title}: layer {layer.name!r}")

    def _weight_mode(self, *_):
        """The weight field is editable only when the weight does not come from the noise."""
        self.form.weight.enabled = not self.form.noise_weight.value

    def take_path(self, *_):
        """Fill the table from the layer chosen in *take path from*."""
        self.path_source.take_path()

    def _replot(self, *_):
        try:
            cp = self.table.control_points()
        except ValueError:
            return
        self.plot.plot(cp, n_times=self.form.n_times.value)

    # ------------------------------------------------------------- job
    def parameters(self) -> dict:
        """The form's values (the input layer aside): ``iter_deconvolve``'s keyword arguments."""
        p = {k: v for k, v in self.form.asdict().items() if k != "layer"}
        if p.pop("noise_weight"):
            p["weight"] = None
        if not p.pop("along_disparity"):
            p.update(angular="views", isotropic=True)
        return p

    def make_job(self, layer, lf):
        from ...deconvolution import DeconvolutionParams, iter_deconvolve

        cp = self.table.control_points()
        p = self.parameters()
        call = {k: p.pop(k) for k in ("n_times", "infinity_disparity", "device")}
        # argument errors surface here, in the GUI thread, as a notification
        solver = DeconvolutionParams().replace(**p)
        gen = iter_deconvolve(lf, cp, params=solver, **call)
        warn_view_mismatch(self.title, self.table, lf.shape)
        self._job = {"source": layer.name, "cp": cp, "params": {**solver.to_dict(), **call}}  # all, for the result
        return lambda: gen

    def on_progress(self, progress) -> None:
        """Keep the weight the solve uses (the noise rule's choice when ``weight`` is None) for the result."""
        if "weight" in progress.info:
            self._job["used"] = {"weight_used": progress.info["weight"], "noise_sigma": progress.info.get("sigma")}

    def on_result(self, result) -> None:
        job = self._job
        p = job["params"]
        name = f"{job['source']} deconvolved"
        meta = lightfield_metadata(
            kind="deconvolved",
            parameters={**p, **job.get("used", {}), "operation": "deconvolve"},
            control_points=job["cp"],
            n_times=p["n_times"],
            infinity_disparity=p["infinity_disparity"],
            source_layer=job["source"],
        )
        out = self.add_result(lightfield_layer_data(result, name=name, metadata=meta))
        self.last_layers = [out]
        self.epi.layer_combo.set_layer(out)
