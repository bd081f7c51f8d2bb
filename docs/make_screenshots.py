"""Screenshots of the napari dock widgets after a run, for the README.

Run under a virtual display from the repository root::

    xvfb-run -a .venv/bin/python docs/make_screenshots.py [--quick]

It opens napari, docks each widget, drives it on the built-in sample data
(the synthetic scene and the Lytro crop), waits for the run to finish and
saves the whole window to ``docs/images/``:

- ``widget_simulate.png``: *Simulate blur* on the synthetic scene (arc path),
  with the path layer over the centre view and the EPIs of the result;
- ``widget_deconvolve.png``: *4D deconvolution* of that blurred scene with the
  path taken from the layer's metadata;
- ``widget_blind.png``: *Blind deblur* of the blurred Lytro crop, with the
  estimated and true paths and the loss curve.

``--quick`` uses smaller light fields and fewer iterations (a smoke test);
``--out DIR`` saves elsewhere.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "images"


def _settle(viewer, seconds=0.5):
    from qtpy.QtWidgets import QApplication

    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        QApplication.processEvents()
        time.sleep(0.01)


def _save(viewer, name):
    import imageio.v3 as iio

    _settle(viewer)
    viewer.reset_view()  # after the dock widgets took their room
    _settle(viewer, 0.3)
    img = viewer.screenshot(canvas_only=False, flash=False)
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / name
    iio.imwrite(path, img)
    print(f"wrote {path} {img.shape}")
    return path


def _viewer():
    import napari

    viewer = napari.Viewer(show=True, title="napari-lfdeblur")
    viewer.window._qt_window.resize(1500, 950)
    return viewer


def _show_only(viewer, names):
    for layer in viewer.layers:
        layer.visible = layer.name in names


def simulate_and_deconvolve(quick: bool):
    from napari_lfdeblur._napari.layers import add_layer, lightfield_layer_data, lightfield_metadata
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget
    from napari_lfdeblur.samples import synthetic_scene

    shape = (7, 7, 64, 64) if quick else (9, 9, 128, 128)
    lf, _ = synthetic_scene(shape, n_layers=3, color=True, seed=0)

    viewer = _viewer()
    add_layer(viewer, lightfield_layer_data(lf, name="scene", metadata=lightfield_metadata(kind="input")))
    sim = SimulateBlurWidget(viewer)
    dock = viewer.window.add_dock_widget(sim, name="Simulate blur", area="right")
    sim.layer_combo.set_layer("scene")
    sim.path_form.preset.value = "arc"
    sim.path_form.extent.value = 3.0
    sim.apply_preset()
    blurred, path = sim.run_and_wait(timeout=300)
    sim.epi.layer_combo.set_layer(blurred)
    sim.epi.set_pick(v=shape[0] // 2, y=shape[2] // 2 + 6, u=shape[1] // 2, x=shape[3] // 2 - 4)
    sim.epi.show_epis()
    _show_only(viewer, {blurred.name, path.name, *sim.epi.layer_names()})
    viewer.reset_view()
    _save(viewer, "widget_simulate.png")
    viewer.window.remove_dock_widget(dock)

    dec = DeconvolveWidget(viewer)
    viewer.window.add_dock_widget(dec, name="4D deconvolution", area="right")
    dec.layer_combo.set_layer(blurred)  # the path comes from its metadata; the default method, 4D TV
    (result,) = dec.run_and_wait(timeout=600)
    dec.epi.layer_combo.set_layer(result)
    dec.epi.set_pick(v=shape[0] // 2, y=shape[2] // 2 + 6, u=shape[1] // 2, x=shape[3] // 2 - 4)
    dec.epi.show_epis()
    _show_only(viewer, {result.name, *dec.epi.layer_names()})
    viewer.reset_view()
    _save(viewer, "widget_deconvolve.png")
    viewer.close()


def blind(quick: bool):
    from napari_lfdeblur._napari.layers import add_layer, lightfield_layer_data, lightfield_metadata
    from napari_lfdeblur._napari.widgets.blind import BlindDeblurWidget
    from napari_lfdeblur.blur import simulate_blur
    from napari_lfdeblur.path import arc_path
    from napari_lfdeblur.samples import lytro_sample

    lf = lytro_sample()
    if quick:
        lf = lf[1:8, 1:8, 32:96, 32:96]
    cp = arc_path(length=2.5, bend=0.3, angle_deg=20.0)
    blurred = simulate_blur(lf, cp, n_times=32)
    viewer = _viewer()
    meta = lightfield_metadata(kind="blurred", control_points=cp, n_times=32, infinity_disparity=0.0)
    add_layer(viewer, lightfield_layer_data(blurred, name="Lytro blurred", metadata=meta))
    w = BlindDeblurWidget(viewer)
    viewer.window.add_dock_widget(w, name="Blind deblur", area="right")
    w.layer_combo.set_layer("Lytro blurred")
    if quick:
        w.form.n_iter.value = max(2, w.form.n_iter.value // 4)
    layers = w.run_and_wait(timeout=900)
    if not layers:
        print("blind run failed or timed out", file=sys.stderr)
        viewer.close()
        return
    result, path = layers[:2]  # a third layer, the rejected path, when it finds little blur
    w.epi.layer_combo.set_layer(result)
    w.epi.show_epis()
    _show_only(viewer, {result.name, path.name, *w.epi.layer_names()})
    viewer.reset_view()
    _save(viewer, "widget_blind.png")
    viewer.close()


def main(argv=None):
    global OUT
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, few iterations")
    parser.add_argument("--only", choices=["simulate", "blind"], help="make only some screenshots")
    parser.add_argument("--out", type=Path, default=OUT, help=f"folder to save them in (default {OUT})")
    args = parser.parse_args(argv)
    OUT = args.out
    np.random.seed(0)
    if args.only in (None, "simulate"):
        simulate_and_deconvolve(args.quick)
    if args.only in (None, "blind"):
        blind(args.quick)


if __name__ == "__main__":
    main()
