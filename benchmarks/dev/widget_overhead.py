"""What the *Blind deblur* dock widget adds to the solver's time.

Runs the same blind deblurring (``default`` preset, seed 0) on the blurred
Lytro sample twice: as a script does (iterating ``iter_blind_deblur``), then
from the widget in a hidden napari viewer (live path and loss plots, path and
light-field previews). Prints both times, the number of progress records, the
redraws of the plots and path preview, and the time Qt's thread spent showing
progress. The redraws hold Python's lock, so on a machine with few cores they
slow the solver down; the widget spaces them by their own cost.

    xvfb-run -a .venv/bin/python benchmarks/dev/widget_overhead.py [--crop 64] [--preview-every 10] [--device cpu]
"""

from __future__ import annotations

import argparse
import time


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cpu", help="auto, cpu or cuda")
    parser.add_argument("--crop", type=int, default=64, help="spatial size of the Lytro crop (<= 128)")
    parser.add_argument("--preview-every", type=int, default=10, help="the widget's 'preview every'")
    parser.add_argument("--tv-iter", type=int, default=100, help="final TV iterations")
    args = parser.parse_args(argv)

    import napari

    from napari_lfdeblur import arc_path, lytro_sample, simulate_blur
    from napari_lfdeblur._napari.layers import add_layer, lightfield_layer_data
    from napari_lfdeblur._napari.widgets.blind import BlindDeblurWidget
    from napari_lfdeblur.blind import BlindParams, iter_blind_deblur
    from napari_lfdeblur.progress import with_previews

    lf = lytro_sample()[:, :, : args.crop, : args.crop]
    blurred = simulate_blur(lf, arc_path(2.5, 0.3, 20.0))
    params = BlindParams.preset("default").replace(final={"n_iter": args.tv_iter})
    t0 = time.perf_counter()
    gen = with_previews(iter_blind_deblur(blurred, params=params, device=args.device), args.preview_every)
    n_records = sum(1 for _ in gen)
    bare = time.perf_counter() - t0
    print(f"light field {blurred.shape}, device {args.device}")
    print(f"script (iterating the generator): {bare:.1f} s, {n_records} progress records")

    viewer = napari.Viewer(show=False)
    add_layer(viewer, lightfield_layer_data(blurred, name="blurred"))
    widget = BlindDeblurWidget(viewer)
    viewer.window.add_dock_widget(widget)
    widget.form.device.value = args.device
    widget.form.tv_iter.value = args.tv_iter
    widget.form.preview_every.value = args.preview_every
    shown = {"calls": 0, "seconds": 0.0}
    on_progress = widget.on_progress

    def timed(progress):
        t = time.perf_counter()
        on_progress(progress)
        shown["calls"] += 1
        shown["seconds"] += time.perf_counter() - t

    widget.on_progress = timed
    t0 = time.perf_counter()
    layers = widget.run_and_wait()
    gui = time.perf_counter() - t0
    print(f"widget: {gui:.1f} s ({gui / bare:.2f}x the script), {shown['calls']} progress records shown in "
          f"{shown['seconds']:.1f} s, {widget.path_preview_updates} path-preview redraws, "
          f"{widget.preview_updates} light-field previews, layers added: {[layer.name for layer in layers]}")
    viewer.close()


if __name__ == "__main__":
    main()
