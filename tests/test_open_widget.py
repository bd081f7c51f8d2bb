"""The *Open light field* dock widget (angular crop, layout), under xvfb."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

from napari_lfdeblur.io import read_lightfield, write_lightfield  # noqa: E402

TIMEOUT = 60_000  # ms: a guard against hangs


@pytest.fixture
def lf():
    rng = np.random.default_rng(3)
    return rng.random((7, 5, 6, 8, 3)).astype(np.float32)


def _widget(make_napari_viewer):
    from napari_lfdeblur._napari.widgets.open import OpenLightFieldWidget

    viewer = make_napari_viewer()
    widget = OpenLightFieldWidget(viewer)
    viewer.window.add_dock_widget(widget)
    return viewer, widget


def _open(qtbot, widget):
    worker = widget.open()
    assert worker is not None
    qtbot.waitUntil(lambda: widget.worker is None, timeout=TIMEOUT)


def test_opens_the_central_views_only(make_napari_viewer, qtbot, tmp_path, lf, notifications):
    path = tmp_path / "scene.h5"
    write_lightfield(path, lf)
    viewer, w = _widget(make_napari_viewer)
    w.source.value = path
    assert w.status.value == "layout: h5"
    w.views_v.value, w.views_u.value = 3, 5
    layer = w.open_and_wait()
    assert list(viewer.layers) == [layer]
    assert layer.name == "scene" and layer.rgb
    np.testing.assert_array_equal(layer.data, read_lightfield(path)[2:5, 0:5])
    assert layer.metadata["angular_crop"] == [3, 5]
    assert layer.metadata["layout"] == "h5"
    assert [kind for kind, _ in notifications] == ["info"]
    assert w.open_button.enabled
    # an odd margin: docs/io.md puts the first kept view at ((V - n_v) // 2, (U - n_u) // 2) = (1, 1) for 4x2 of 7x5
    w.views_v.value, w.views_u.value = 4, 2
    layer = w.open_and_wait()
    np.testing.assert_array_equal(layer.data, read_lightfield(path)[1:5, 1:3])
    assert layer.metadata["angular_crop"] == [4, 2]


def test_opening_again_adds_a_layer_and_replaces_nothing(make_napari_viewer, qtbot, tmp_path, lf, notifications):
    path = tmp_path / "scene.npz"
    write_lightfield(path, lf)
    viewer, w = _widget(make_napari_viewer)
    w.source.value = path
    _open(qtbot, w)
    first = viewer.layers[0]
    w.views_v.value = w.views_u.value = 1
    _open(qtbot, w)
    assert len(viewer.layers) == 2 and viewer.layers[0] is first
    assert first.data.shape == lf.shape and viewer.layers[1].data.shape == (1, 1, 6, 8, 3)
    assert viewer.layers[1].name != first.name


def test_a_file_with_its_path_opens_the_path_too(make_napari_viewer, qtbot, tmp_path, lf, notifications):
    cp = [[-1.0, 0.0, 0.0], [1.0, 0.5, 0.1]]
    path = tmp_path / "blurred.npy"  # the path in blurred.path.json beside it
    write_lightfield(path, lf, control_points=cp)
    viewer, w = _widget(make_napari_viewer)
    viewer.add_image(np.zeros((2, 2)), name="blurred")  # the new layer's name is made unique
    w.source.value = path
    layer = w.open_and_wait()
    assert layer.name == "blurred [1]" and layer.metadata["control_points"] == cp
    drawn = viewer.layers["blurred [1] path"]
    assert drawn.metadata["control_points"] == cp and drawn.metadata["source_layer"] == "blurred [1]"
    assert [x.name for x in viewer.layers] == ["blurred", "blurred [1]", "blurred [1] path"]


def test_folder_of_views_with_a_chosen_layout(make_napari_viewer, qtbot, tmp_path, lf, notifications):
    folder = tmp_path / "views"
    write_lightfield(folder, lf, layout="views")
    viewer, w = _widget(make_napari_viewer)
    w.folder_box.value = True
    assert w.source.mode.value == "d"
    w.source.value = folder
    w.layout_combo.value = "views"
    w.views_v.value, w.views_u.value = 5, 3
    _open(qtbot, w)
    (layer,) = viewer.layers
    np.testing.assert_array_equal(layer.data, read_lightfield(folder)[1:6, 1:4])
    # an odd margin: docs/io.md puts the first kept view at ((V - n_v) // 2, (U - n_u) // 2) = (1, 1) for 4x2 of 7x5
    w.views_v.value, w.views_u.value = 4, 2
    _open(qtbot, w)
    np.testing.assert_array_equal(viewer.layers[-1].data, read_lightfield(folder)[1:5, 1:3])


@pytest.mark.parametrize(
    "crop, expected",
    [((3, 0), "set both numbers"), ((9, 9), "angular_crop"), (None, "choose a file")],
)
def test_bad_input_is_a_notification_and_adds_nothing(make_napari_viewer, qtbot, tmp_path, lf, notifications,
                                                      crop, expected):
    path = tmp_path / "scene.npy"
    write_lightfield(path, lf)
    viewer, w = _widget(make_napari_viewer)
    if crop is not None:
        w.source.value = path
        w.views_v.value, w.views_u.value = crop
    worker = w.open()
    if worker is not None:  # the crop is refused by the reader, in the worker
        qtbot.waitUntil(lambda: w.worker is None, timeout=TIMEOUT)
        assert w.status.value == "not opened"
    assert len(viewer.layers) == 0
    ((kind, message),) = notifications
    assert kind == "error" and expected in message and "Traceback" not in message


def test_a_file_that_is_not_a_light_field(make_napari_viewer, qtbot, tmp_path, notifications):
    path = tmp_path / "notes.npy"
    np.save(path, np.zeros((4, 4), np.float32))
    viewer, w = _widget(make_napari_viewer)
    w.source.value = path
    assert "not recognised" in w.status.value
    assert w.open_and_wait() is None
    assert len(viewer.layers) == 0
    ((kind, message),) = notifications
    assert kind == "error" and "notes.npy" in message


def test_value_range_rescales_and_a_bad_one_is_a_notification(make_napari_viewer, qtbot, tmp_path, lf,
                                                               notifications):
    path = tmp_path / "raw.npy"
    np.save(path, lf * 4095.0)  # floats on a 12-bit scale: refused without a value range
    viewer, w = _widget(make_napari_viewer)
    w.source.value = path
    assert w.open_and_wait() is None
    assert notifications[-1][0] == "error" and "value range" in notifications[-1][1]
    w.value_range.value = "5,1"
    assert w.open() is None  # refused in the form, before any read
    assert notifications[-1] == ("error", "Open a light field: value range '5,1': expected LO,HI with LO < HI, "
                                 "such as 0,4095, or auto")
    assert len(viewer.layers) == 0
    w.value_range.value = "0,4095"
    layer = w.open_and_wait()
    np.testing.assert_allclose(layer.data, lf, atol=1e-6)
    assert layer.metadata["value_range"] == [0.0, 4095.0]


def test_closing_the_viewer_during_a_read_adds_nothing(make_napari_viewer, qtbot, tmp_path, lf, notifications,
                                                       monkeypatch):
    import time

    from napari_lfdeblur._napari.widgets import open as open_widget

    real_read = open_widget._read
    monkeypatch.setattr(open_widget, "_read", lambda path, options: (time.sleep(0.5), real_read(path, options))[1])
    write_lightfield(tmp_path / "scene.npz", lf)
    viewer, w = _widget(make_napari_viewer)
    w.source.value = tmp_path / "scene.npz"
    worker = w.open()
    finished = []
    worker.finished.connect(lambda: finished.append(True))
    viewer.close()  # while the read sleeps
    qtbot.waitUntil(lambda: bool(finished), timeout=TIMEOUT)
    qtbot.wait(100)
    assert w.worker is None and w.last_layer is None
    assert not [n for n in notifications if n[0] == "error"], notifications
