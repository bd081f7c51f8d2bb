"""How fast Cancel stops a run of the *Blind deblur* dock widget.

Runs the widget on the blurred Lytro sample (9x9x128x128x3, arc path) in a
hidden napari viewer, presses Cancel after a few waiting times (so that the
solver is at different pyramid levels or in its final stage), and prints how
long the worker took to stop, the stage it was in, and the layers left (only
the input, if no partial layer was added).

    xvfb-run -a .venv/bin/python benchmarks/dev/widget_cancel_latency.py [--device cuda] [--waits 3 20 45]
"""

from __future__ import annotations

import argparse
import time


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="auto", help="auto, cpu or cuda")
    parser.add_argument("--waits", type=float, nargs="+", default=[3.0, 20.0, 45.0],
                        help="seconds to let the solver run before each Cancel")
    parser.add_argument("--crop", type=int, default=128, help="spatial size of the Lytro crop (<= 128)")
    args = parser.parse_args(argv)

    import napari
    from qtpy.QtWidgets import QApplication

    from napari_lfdeblur import arc_path, lytro_sample, simulate_blur
    from napari_lfdeblur._napari.layers import add_layer, lightfield_layer_data
    from napari_lfdeblur._napari.widgets.blind import BlindDeblurWidget

    lf = lytro_sample()[:, :, : args.crop, : args.crop]
    blurred = simulate_blur(lf, arc_path(2.5, 0.3, 20.0))
    viewer = napari.Viewer(show=False)
    add_layer(viewer, lightfield_layer_data(blurred, name="blurred"))
    widget = BlindDeblurWidget(viewer)
    viewer.window.add_dock_widget(widget)
    widget.form.device.value = args.device
    print(f"light field {blurred.shape}, device {args.device}")
    for wait in args.waits:
        if widget.run() is None:
            raise SystemExit("the run did not start (see the notification above)")
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < wait and widget.is_running:
            QApplication.processEvents()
            time.sleep(0.01)
        if not widget.is_running:
            print(f"wait {wait:5.1f} s: the run finished before Cancel")
            continue
        stage = widget.progress.status.value.split(":")[0]
        widget.cancel()
        t1 = time.perf_counter()
        while widget.is_running:
            QApplication.processEvents()
            time.sleep(0.005)
        left = [layer.name for layer in viewer.layers]
        print(f"wait {wait:5.1f} s: stopped {time.perf_counter() - t1:5.2f} s after Cancel, "
              f"in stage '{stage}'; layers left: {left}")
    viewer.close()


if __name__ == "__main__":
    main()
