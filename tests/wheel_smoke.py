"""Smoke test of the built wheel, installed (not editable) into a fresh environment.

Run by ``make wheel-test`` (part of ``make test``) with that environment's
Python, from an empty folder, so that only the installed package can be
imported. The environment has the wheel and npe2, and neither napari nor Qt:
what a user gets from ``pip install napari-lfdeblur`` in a napari environment,
minus napari. Not collected by pytest (its name does not start with ``test_``).
"""

from __future__ import annotations

import importlib
import importlib.metadata as md
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch


def check(condition, message):
    if not condition:
        sys.exit(f"wheel smoke test FAILED: {message}")
    print(f"ok: {message}")


def main():
    import napari_lfdeblur as lfd

    here = Path(lfd.__file__).resolve()
    check("site-packages" in str(here), f"the installed package is imported ({here})")

    # napari and Qt are optional: nothing the library needs pulls them in
    requires = md.requires("napari-lfdeblur") or []
    hard = [r for r in requires if "extra ==" not in r]
    check(not any(r.lower().startswith(("napari", "pyqt", "pyside", "qtpy", "magicgui")) for r in hard),
          f"no napari or Qt among the hard dependencies ({len(hard)} of them)")
    for name in lfd.__all__:
        getattr(lfd, name)
    check(not any(m.split(".")[0] in ("napari", "qtpy", "PyQt6", "PySide6") for m in sys.modules),
          f"every public name ({len(lfd.__all__)}) loads without napari or Qt")

    # the blur's fused CPU loops: numba comes with the package, and they agree with the torch version
    from napari_lfdeblur import _fused
    from napari_lfdeblur.blur import BlurOperator

    check(_fused.available("cpu"), "the fused CPU loops (numba) are available")
    x = torch.rand(3, 4, 6, 7, 2, dtype=torch.float64)
    op = BlurOperator(x.shape, [[-1, 0.5, 0.4], [1, -0.5, -0.4]], n_times=5, infinity_disparity=0.8, device="cpu",
                      dtype=torch.float64)
    fused = op.forward(x)
    available, _fused.available = _fused.available, lambda *args: False
    check(torch.allclose(fused, BlurOperator(x.shape, op.control_points, n_times=5, infinity_disparity=0.8,
                                             device="cpu", dtype=torch.float64).forward(x), atol=1e-12),
          "the fused loops blur as the torch version does")
    _fused.available = available  # the rest of the smoke test runs what a user gets

    # every sample loads (the Lytro crop is a PNG inside the wheel)
    lf, disp = lfd.synthetic_scene((5, 5, 16, 16))
    check(lf.shape == (5, 5, 16, 16) and disp.shape == (16, 16), "synthetic_scene")
    lytro = lfd.lytro_sample()
    check(lytro.ndim == 5 and lytro.dtype == np.float32 and 0 <= lytro.min() <= lytro.max() <= 1, "lytro_sample")
    from napari_lfdeblur._napari import sample_data

    for fn in (sample_data.synthetic_scene_sample, sample_data.synthetic_blurred_sample,
               sample_data.lytro_sample_layer):
        layers = fn()
        check(len(layers) >= 1 and np.asarray(layers[0][0]).ndim in (4, 5), f"napari sample {fn.__name__}")

    # the napari reader opens a light-field file and declines anything else
    from napari_lfdeblur._napari.reader import napari_get_reader

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scene.npz"
        lfd.write_lightfield(path, lf)
        reader = napari_get_reader(str(path))
        check(callable(reader), "napari_get_reader claims a light-field .npz")
        data = reader(str(path))[0][0]
        check(np.allclose(data, lf, atol=1e-6), "the reader returns the light field written")
        text = Path(tmp) / "notes.txt"
        text.write_text("not a light field")
        check(napari_get_reader(str(text)) is None, "napari_get_reader declines a text file")

        # the main job, without its blind part
        lfdeblur = Path(sys.executable).with_name("lfdeblur")
        out = Path(tmp) / "demo"
        run = subprocess.run([str(lfdeblur), "demo", "--quick", "--skip-blind", "--out", str(out)],
                             capture_output=True, text=True, timeout=600)
        check(run.returncode == 0, "lfdeblur demo --skip-blind runs" + (f": {run.stderr[-2000:]}" if run.returncode else ""))
        check(any(out.iterdir()), "the demo wrote its outputs")

    # npe2 finds the manifest and its contributions
    from npe2 import PluginManager

    pm = PluginManager.instance()
    pm.discover()
    manifest = pm.get_manifest("napari-lfdeblur")
    contrib = manifest.contributions
    check(len(contrib.readers) >= 1 and len(contrib.writers) >= 1 and len(contrib.widgets) >= 4
          and len(contrib.sample_data) >= 3, "npe2 discovers the manifest and its contributions")
    # the commands that need no Qt resolve to objects in the installed package
    for cmd in contrib.commands:
        module, _, attr = cmd.python_name.partition(":")
        if ".widgets" in module:
            continue
        getattr(importlib.import_module(module), attr)
    check(True, "the reader, writer and sample commands resolve")
    run = subprocess.run([str(Path(sys.executable).with_name("npe2")), "validate", "napari-lfdeblur"],
                         capture_output=True, text=True, timeout=300)
    check(run.returncode == 0, "npe2 validate napari-lfdeblur" + (f": {run.stdout[-1000:]} {run.stderr[-1000:]}" if run.returncode else ""))


if __name__ == "__main__":
    main()
