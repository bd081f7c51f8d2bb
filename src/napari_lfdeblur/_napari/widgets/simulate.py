"""The *Simulate blur* dock widget: blur a light-field layer by a camera path.

A thin shell over :func:`napari_lfdeblur.simulate_blur`. The form (magicgui,
``form``) holds the input ``layer``, ``n_times``, ``infinity_disparity`` and
``device``; the path is edited in a table of control points (``table``; its
*rotation* box adds the columns ``r_x, r_y, r_z`` in radians), filled from a
preset (linear, arc, shake, shake6: a shake with camera rotation) or a
random path with a seed (``path_form``), or taken from a layer or a path
JSON file (``path_source``, with the ``n_times`` and ``infinity_disparity``
stated there). Running it adds:

- ``'<source> blurred'``: the blurred light field (metadata: the path in
  ``'control_points'``, ``'n_times'``, ``'infinity_disparity'``, the
  parameters and the package version), which the deconvolution and blind
  widgets pick up as the (true) path;
- ``'<source> blurred path'``: the path drawn over the centre view (frame:
  :mod:`napari_lfdeblur._napari.layers`).
"""

from __future__ import annotations

from magicgui.widgets import ComboBox, Container, PushButton

from ...path import MAX_ROTATION, preset_path, random_path
from ...progress import Progress
from ..layers import lightfield_layer_data, lightfield_metadata, path_layer_data
from ._controls import (PathSource, PathTable, device_choice, fill_path, fspin, heading, infinity_disparity_field,
                        spin, warn_view_mismatch)
from ._plots import PathPlot
from ._runner import SolverWidget
from .epi import EpiPanel

__all__ = ["SimulateBlurWidget"]


def _path_form() -> Container:
    """Preset and random-path fields of the *Camera path* section."""
    return Container(name="path_form", widgets=[
        ComboBox(name="preset", choices=["linear", "arc", "shake", "shake6"], value="linear",
                 tooltip="linear, arc, shake (a random wiggle) or shake6 (a shake with camera rotation, "
                 "as a handheld camera: a 6-column path)"),
        fspin("extent", 2.0, 0.0, 50.0, 0.25, tooltip=(
            "in views: the length of linear and arc; the side of the box that shake, shake6 and random draw "
            "their control points from (they move less)")),
        fspin("rotation", 0.005, 0.0, MAX_ROTATION, 0.0005, label="rotation (rad)",
              tooltip="largest camera rotation of the shake6 preset, radians (handheld: a few thousandths; "
              "0.005 rad moves the image by about 0.005 max(Y, X) / 2 px)"),
        PushButton(name="apply_preset", text="Apply preset"),
        spin("n_points", 4, 2, 12, label="points", tooltip="control points of the random path"),
        spin("seed", 0, 0, 2**31 - 1, tooltip="random seed (random path and shake presets)"),
        PushButton(name="random", text="Random path"),
    ])


class SimulateBlurWidget(SolverWidget):
    """Dock widget: simulate the motion blur of a light-field layer."""

    title = "Simulate blur"

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer)
        self.form.extend([
            spin("n_times", 32, 2, 1024, label="instants T", tooltip="exposure instants T"),
            infinity_disparity_field("infinity disparity d_inf, px/view"),
            device_choice(),
        ])
        self.path_form = _path_form()
        self.path_source = PathSource(napari_viewer, self.set_path, title=self.title)
        self.table = PathTable(preset_path("linear", 2.0))
        self.plot = PathPlot()
        self.epi = EpiPanel(napari_viewer)
        self.assemble(before=[heading("Camera path"), self.path_form, self.path_source, self.table, self.plot],
                      after=[self.epi])
        self.path_form.apply_preset.changed.connect(self.apply_preset)
        self.path_form.random.changed.connect(self.apply_random)
        self.table.changed.connect(self._replot)
        self.form.n_times.changed.connect(self._replot)
        self._replot()

    # ------------------------------------------------------------ path
    def apply_preset(self, *_):
        """Fill the table with the chosen preset of the chosen extent (and rotation, for shake6)."""
        f = self.path_form
        rotation = f.rotation.value if f.preset.value == "shake6" else None
        self.table.set_control_points(preset_path(f.preset.value, extent=f.extent.value, seed=f.seed.value,
                                                  rotation=rotation))

    def set_path(self, control_points, metadata=None) -> None:
        """Fill the table (and ``n_times``, ``infinity_disparity`` when ``metadata`` states them)."""
        fill_path(self.form, self.table, control_points, metadata, f"{self.title}: the path")

    def apply_random(self, *_):
        """Fill the table with a random path (points, extent and seed from the form)."""
        f = self.path_form
        self.table.set_control_points(random_path(n_points=f.n_points.value, extent=f.extent.value,
                                                  seed=f.seed.value))

    def _replot(self, *_):
        try:
            cp = self.table.control_points()
        except ValueError:
            return
        self.plot.plot(cp, n_times=self.form.n_times.value)

    # ------------------------------------------------------------- job
    def parameters(self) -> dict:
        """The form's values (the input layer aside)."""
        return {k: v for k, v in self.form.asdict().items() if k != "layer"}

    def make_job(self, layer, lf):
        from ..._lightfield import check_infinity_disparity
        from ...blur import simulate_blur
        from ...devices import select_device

        cp = self.table.control_points()
        params = self.parameters()
        check_infinity_disparity(params["infinity_disparity"], lf.shape)  # as the other widgets: before the run
        select_device(params["device"])
        warn_view_mismatch(self.title, self.table, lf.shape)
        self._job = {"source": layer.name, "cp": cp, "params": params, "shape": lf.shape}

        def job():
            yield Progress("blur", 0, 1)
            out = simulate_blur(lf, cp, **params)
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
        out = self.add_result(lightfield_layer_data(blurred, name=name, metadata=meta))
        path = self.add_result(path_layer_data(job["cp"], job["shape"], n_times=p["n_times"],
                                               infinity_disparity=p["infinity_disparity"], name=f"{name} path",
                                               metadata={"source_layer": out.name}))
        self.last_layers = [out, path]
        self.plot.plot(job["cp"], n_times=p["n_times"])
        self.epi.layer_combo.set_layer(out)
