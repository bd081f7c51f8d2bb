"""Packaging: the public API, the Qt-free core, and the npe2 manifest."""

import subprocess
import sys
from pathlib import Path

import numpy as np

import napari_lfdeblur

ROOT = Path(__file__).resolve().parents[1]


def test_every_public_name_resolves():
    for name in napari_lfdeblur.__all__:
        assert getattr(napari_lfdeblur, name) is not None, name


def test_core_imports_neither_qt_nor_napari():
    code = (
        "import sys, napari_lfdeblur as m\n"
        "[getattr(m, n) for n in m.__all__]\n"
        "import napari_lfdeblur.cli, napari_lfdeblur.demo\n"
        "bad = sorted(k for k in sys.modules if k.split('.')[0] in "
        "('napari', 'qtpy', 'PyQt5', 'PyQt6', 'PySide2', 'PySide6', 'magicgui', 'vispy'))\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_manifest_symlink_and_name():
    link = ROOT / "src" / "napari_lfdeblur" / "napari.yaml"
    assert link.is_symlink() and link.resolve() == (ROOT / "napari.yaml").resolve()
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    from npe2 import PluginManifest

    manifest = PluginManifest.from_file(ROOT / "napari.yaml")
    assert manifest.name == project["name"] == "napari-lfdeblur"


def test_manifest_validates_and_its_commands_import():
    from npe2 import PluginManifest

    manifest = PluginManifest.from_distribution("napari-lfdeblur")
    manifest.validate_imports()
    assert manifest.contributions.sample_data and manifest.contributions.readers


def test_sample_data_contributions():
    from napari_lfdeblur._napari.sample_data import lytro_sample_layer, synthetic_blurred_sample
    from napari_lfdeblur import simulate_blur, synthetic_scene

    (data, kwargs, kind), = synthetic_blurred_sample()
    sharp, _ = synthetic_scene((9, 9, 128, 128), n_layers=3, color=True, seed=0)
    cp = kwargs["metadata"]["control_points"]
    np.testing.assert_allclose(data, simulate_blur(sharp, cp, n_times=kwargs["metadata"]["n_times"]), atol=1e-6)
    assert kind == "image" and kwargs["rgb"] and kwargs["axis_labels"] == ("v", "u", "y", "x")
    (lytro, kw, _), = lytro_sample_layer()
    assert lytro.shape == (9, 9, 128, 128, 3) and "CC BY 4.0" in kw["metadata"]["source"]
