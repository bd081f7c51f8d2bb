"""The napari dock widgets, end to end on tiny light fields (run under xvfb).

    xvfb-run -a .venv/bin/python -m pytest tests/test_widgets.py
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("napari")
pytest.importorskip("pytestqt")

import napari_lfdeblur  # noqa: E402
from napari_lfdeblur.blind import BlindParams  # noqa: E402
from napari_lfdeblur.blur import simulate_blur  # noqa: E402
from napari_lfdeblur.deconvolution import DeconvolutionParams  # noqa: E402
from napari_lfdeblur.path import bezier_positions  # noqa: E402
from conftest import wrap_prox_inner_iteration  # noqa: E402

SHAPE = (5, 5, 16, 16)
TIMEOUT = 120_000  # ms: a guard against hangs


@pytest.fixture
def lf():
    rng = np.random.default_rng(1)
    return rng.random(SHAPE).astype(np.float32)


def _dock(viewer, widget):
    viewer.window.add_dock_widget(widget)
    return widget


def _wait_done(qtbot, widget):
    qtbot.waitUntil(lambda: not widget.is_running, timeout=TIMEOUT)


# ------------------------------------------------------------ manifest


@pytest.mark.parametrize(
    "display_name, cls_name",
    [("Simulate blur", "SimulateBlurWidget"), ("4D deconvolution", "DeconvolveWidget"),
     ("Blind deblur", "BlindDeblurWidget"), ("Epipolar images", "EpiWidget"),
     ("Open light field", "OpenLightFieldWidget")],
)
def test_widgets_open_from_the_plugin_menu(make_napari_viewer, display_name, cls_name):
    viewer = make_napari_viewer()
    dock, widget = viewer.window.add_plugin_dock_widget("napari-lfdeblur", display_name)
    assert type(widget).__name__ == cls_name
    # napari hands plugins a public-only proxy of the viewer: the widget must work through it
    viewer.add_image(np.zeros((3, 3, 8, 8), np.float32), name="lf")
    if cls_name == "OpenLightFieldWidget":
        return  # it has no layer field
    combo = widget.epi.layer_combo if cls_name == "EpiWidget" else widget.layer_combo
    assert combo.value is not None and combo.current_choice == "lf"
    if cls_name == "SimulateBlurWidget":
        widget.form.n_times.value = 4
        timeout = TIMEOUT / 1000  # run_and_wait takes seconds; the first run may include numba's first compile
        assert [layer.name for layer in widget.run_and_wait(timeout=timeout)] == ["lf blurred", "lf blurred path"]
        # a second run updates its results in place, through the proxy too (its layers are new wrappers each
        # time: they piled up as 'lf blurred [1]', 'lf blurred path [1]')
        widget.form.n_times.value = 8
        assert [layer.name for layer in widget.run_and_wait(timeout=timeout)] == ["lf blurred", "lf blurred path"]
        assert [layer.name for layer in viewer.layers] == ["lf", "lf blurred", "lf blurred path"]
        assert viewer.layers["lf blurred"].metadata["n_times"] == 8


# ------------------------------------------------------------ simulate


def test_simulate_adds_blurred_and_path_layers(make_napari_viewer, qtbot, lf, notifications):
    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget

    viewer = make_napari_viewer()
    src = viewer.add_image(lf.copy(), name="sharp")
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.layer_combo.set_layer(src)
    w.path_form.preset.value = "arc"
    w.path_form.extent.value = 1.5
    w.path_form.apply_preset.clicked.emit()
    w.table.table.native.item(0, 2).setText("0.25")  # typed-in edit: p_z of the first point
    w.form.n_times.value = 8
    w.form.infinity_disparity.value = 0.5
    cp = w.table.control_points()
    assert cp[0, 2] == 0.25
    assert w.run() is not None
    _wait_done(qtbot, w)
    assert not [n for n in notifications if n[0] == "error"], notifications

    blurred = viewer.layers["sharp blurred"]
    expected = simulate_blur(lf, cp, n_times=8, infinity_disparity=0.5)
    assert blurred.data.shape == SHAPE
    np.testing.assert_allclose(blurred.data, expected, atol=1e-6)
    assert blurred.axis_labels == ("v", "u", "y", "x")
    meta = blurred.metadata
    assert meta["napari_lfdeblur_version"] == napari_lfdeblur.__version__
    np.testing.assert_allclose(meta["control_points"], cp)
    assert meta["n_times"] == 8 and meta["infinity_disparity"] == 0.5
    assert meta["source_layer"] == "sharp"
    # the input layer is untouched
    np.testing.assert_array_equal(src.data, lf)

    path = viewer.layers["sharp blurred path"]
    assert path.shape_type == ["rectangle", "path", "ellipse"]
    assert (path.metadata["n_times"], path.metadata["infinity_disparity"]) == (8, 0.5)
    assert path.metadata["source_layer"] == "sharp blurred"  # the light field it belongs to, as the reader says
    s = path.metadata["pixels_per_view"]
    assert s == pytest.approx(16 / (2 * 5))
    pos = bezier_positions(cp, 8)
    np.testing.assert_allclose(path.data[1][:, 0], 7.5 + s * pos[:, 1])
    np.testing.assert_allclose(path.data[1][:, 1], 7.5 + s * pos[:, 0])


def test_results_never_replace_a_layer_the_widgets_did_not_make(make_napari_viewer, qtbot, lf):
    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget

    viewer = make_napari_viewer()
    src = viewer.add_image(lf.copy(), name="sharp")
    points = viewer.add_points([[3.0, 3.0]], name="sharp blurred")  # the user's layers, named as the results
    mine = viewer.add_image(np.ones((3, 3, 8, 8), np.float32), name="sharp blurred path")
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.layer_combo.set_layer(src)
    w.form.n_times.value = 8
    assert w.run() is not None
    _wait_done(qtbot, w)
    assert viewer.layers["sharp blurred"] is points and viewer.layers["sharp blurred path"] is mine
    np.testing.assert_array_equal(mine.data, 1.0)
    blurred = viewer.layers["sharp blurred [1]"]  # napari's next free name
    np.testing.assert_allclose(blurred.data, simulate_blur(lf, w.table.control_points(), n_times=8), atol=1e-6)
    # the widget's own result is updated in place by the next run, not added again
    w.form.n_times.value = 4
    assert w.run() is not None
    _wait_done(qtbot, w)
    assert viewer.layers["sharp blurred [1]"] is blurred and len(viewer.layers) == 5
    np.testing.assert_allclose(blurred.data, simulate_blur(lf, w.table.control_points(), n_times=4), atol=1e-6)


def test_simulate_refuses_bad_settings_before_it_runs(make_napari_viewer, lf, notifications):
    import torch

    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget

    viewer = make_napari_viewer()
    src = viewer.add_image(lf.copy(), name="sharp")
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.layer_combo.set_layer(src)
    w.form.infinity_disparity.value = 19.0  # 5x5 views of 16x16 px: at most 4
    assert w.run() is None and not w.is_running
    assert notifications[-1][0] == "error" and "infinity_disparity = 19 px/view is beyond" in notifications[-1][1]
    assert w.progress.status.value == "Simulate blur: not started (see the error)"  # not an earlier run's 'done'
    if not torch.cuda.is_available():
        w.form.infinity_disparity.value = 0.0
        w.form.device.value = "cuda"
        assert w.run() is None
        assert notifications[-1][0] == "error" and "no CUDA GPU" in notifications[-1][1]
    assert "sharp blurred" not in viewer.layers


def test_results_lie_over_their_input(make_napari_viewer, qtbot, lf):
    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget

    viewer = make_napari_viewer()
    src = viewer.add_image(lf.copy(), name="sharp", scale=(1, 1, 0.5, 0.25), translate=(0, 0, 10, -4))
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.layer_combo.set_layer(src)
    w.form.n_times.value = 4
    assert w.run() is not None
    _wait_done(qtbot, w)
    out, path = viewer.layers["sharp blurred"], viewer.layers["sharp blurred path"]
    np.testing.assert_array_equal(out.scale, src.scale)
    np.testing.assert_array_equal(out.translate, src.translate)
    np.testing.assert_array_equal(path.scale, [0.5, 0.25])  # the path over the centre view: its (y, x)
    np.testing.assert_array_equal(path.translate, [10, -4])


def test_simulate_random_path_is_seeded(make_napari_viewer, lf):
    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget
    from napari_lfdeblur.path import random_path

    viewer = make_napari_viewer()
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.path_form.n_points.value = 5
    w.path_form.seed.value = 7
    w.path_form.extent.value = 3.0
    w.path_form.random.clicked.emit()
    np.testing.assert_allclose(w.table.control_points(), random_path(5, 3.0, seed=7), atol=1e-5)


def test_simulate_colour_layer(make_napari_viewer, qtbot):
    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget

    rgb = np.random.default_rng(2).random((3, 3, 8, 8, 3)).astype(np.float32)
    viewer = make_napari_viewer()
    viewer.add_image(rgb, name="rgb", rgb=True)
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.form.n_times.value = 4
    w.run()
    _wait_done(qtbot, w)
    out = viewer.layers["rgb blurred"]
    assert out.rgb and out.data.shape == rgb.shape
    np.testing.assert_allclose(out.data, simulate_blur(rgb, w.table.control_points(), n_times=4), atol=1e-6)


# -------------------------------------------------- bad inputs -> notes


def test_the_newest_light_field_is_the_input_by_default(make_napari_viewer, lf):
    from napari_lfdeblur._napari.widgets import SimulateBlurWidget

    viewer = make_napari_viewer()
    viewer.add_image(lf, name="first")
    second = viewer.add_image(lf.copy(), name="second")
    w = _dock(viewer, SimulateBlurWidget(viewer))
    assert w.layer_combo.value is second  # the LayerChoice default: the newest usable layer


def test_2d_layer_and_empty_selection_notify(make_napari_viewer, notifications):
    from napari_lfdeblur._napari.widgets.blind import BlindDeblurWidget
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget

    viewer = make_napari_viewer()
    widgets = [_dock(viewer, cls(viewer)) for cls in (SimulateBlurWidget, DeconvolveWidget, BlindDeblurWidget)]
    # empty selection
    for w in widgets:
        assert w.run() is None
    assert len([n for n in notifications if n[0] == "error"]) == 3
    assert all("no light-field layer" in msg for kind, msg in notifications)
    # a 2D image (an EPI, say) is not offered as the input: still nothing to run on
    notifications.clear()
    viewer.add_image(np.zeros((16, 16), np.float32), name="flat")
    for w in widgets:
        w.layer_combo.reset_choices()
        assert w.layer_combo.value is None and "flat" not in [str(c) for c in w.layer_combo.choices]
        assert w.run() is None
        assert not w.is_running
    errors = [msg for kind, msg in notifications if kind == "error"]
    assert len(errors) == 3 and all("no light-field layer" in m for m in errors)
    assert len(viewer.layers) == 1


def test_errors_reach_napari_notifications(make_napari_viewer):
    """Without the test fixture's patch, an empty selection is a real napari error notification."""
    from napari.utils.notifications import NotificationSeverity, notification_manager

    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget

    viewer = make_napari_viewer()
    w = _dock(viewer, SimulateBlurWidget(viewer))
    seen = []
    notification_manager.notification_ready.connect(seen.append)
    try:
        assert w.run() is None
    finally:
        notification_manager.notification_ready.disconnect(seen.append)
    assert [n.severity for n in seen] == [NotificationSeverity.ERROR]
    assert "no light-field layer" in seen[0].message


def test_bad_table_entry_notifies(make_napari_viewer, lf, notifications):
    from napari_lfdeblur._napari.widgets.simulate import SimulateBlurWidget

    viewer = make_napari_viewer()
    viewer.add_image(lf, name="sharp")
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.table.table.native.item(1, 0).setText("abc")
    assert w.run() is None
    assert notifications and "not a number" in notifications[-1][1]
    assert len(viewer.layers) == 1


# ---------------------------------------------------------- deconvolve


def test_deconvolve_takes_path_from_metadata(make_napari_viewer, qtbot, lf, notifications):
    from napari_lfdeblur._napari.layers import lightfield_layer_data, lightfield_metadata, add_layer
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur.deconvolution import deconvolve
    from napari_lfdeblur.path import linear_path

    cp = linear_path(1.5, angle_deg=30)
    blurred = simulate_blur(lf, cp, n_times=8)
    viewer = make_napari_viewer()
    meta = lightfield_metadata(kind="blurred", control_points=cp, n_times=8, infinity_disparity=0.0)
    layer = add_layer(viewer, lightfield_layer_data(blurred, name="b", metadata=meta))
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.layer_combo.set_layer(layer)
    # the path, T and d_inf came from the layer's metadata
    np.testing.assert_allclose(w.table.control_points(), cp)
    assert w.form.n_times.value == 8
    w.form.method.value = "inplane"
    assert not w.form.weight.enabled  # the weight comes from the noise until the box is unticked
    w.form.noise_weight.value = False
    assert w.form.weight.enabled
    w.form.weight.value = 0.0
    w.run()
    _wait_done(qtbot, w)
    assert not [n for n in notifications if n[0] == "error"], notifications
    out = viewer.layers["b deconvolved"]
    assert out.data.shape == SHAPE and out.axis_labels == ("v", "u", "y", "x")
    # exact in-plane inverse recovers the sharp light field
    np.testing.assert_allclose(out.data, lf, atol=2e-3)
    np.testing.assert_allclose(out.data, deconvolve(blurred, cp, n_times=8, method="inplane", weight=0.0), atol=1e-6)
    assert out.metadata["parameters"]["method"] == "inplane"
    assert out.metadata["napari_lfdeblur_version"] == napari_lfdeblur.__version__
    np.testing.assert_allclose(out.metadata["control_points"], cp)
    np.testing.assert_array_equal(layer.data, blurred)


def test_deconvolve_tv_with_path_from_path_layer(make_napari_viewer, qtbot, lf, notifications):
    from napari_lfdeblur._napari.layers import add_layer, path_layer_data
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur.deconvolution import deconvolve

    cp = np.array([[-0.5, 0.2, 0.1], [0.6, -0.3, -0.1]])
    blurred = simulate_blur(lf, cp, n_times=6)
    viewer = make_napari_viewer()
    viewer.add_image(blurred, name="b")
    add_layer(viewer, path_layer_data(cp, SHAPE, n_times=6, name="some path"))
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.layer_combo.set_layer("b")
    w.path_source.path_layer.set_layer("some path")
    w.path_source.take_button.clicked.emit()
    np.testing.assert_allclose(w.table.control_points(), cp)
    assert w.form.n_times.value == 6
    w.form.method.value = "tv"
    w.form.n_iter.value = 5
    w.run()
    _wait_done(qtbot, w)
    assert not [n for n in notifications if n[0] == "error"], notifications
    out = viewer.layers["b deconvolved"].data
    ref = deconvolve(blurred, cp, n_times=6, method="tv", weight=None, n_iter=5)  # the default noise rule
    np.testing.assert_allclose(out, ref, atol=1e-5)
    params = viewer.layers["b deconvolved"].metadata["parameters"]
    assert params["weight"] is None and params["noise_sigma"] > 0
    stamped = DeconvolutionParams.from_metadata(viewer.layers["b deconvolved"].metadata)  # a preset again
    assert (stamped.method, stamped.weight, stamped.n_iter) == ("tv", None, 5)  # the rule, not its choice
    np.testing.assert_allclose(deconvolve(blurred, cp, n_times=6, params=stamped), out, atol=1e-6)
    with pytest.raises(ValueError, match="not BlindParams's: they lack"):  # another solver's stamp
        BlindParams.from_metadata(viewer.layers["b deconvolved"].metadata)
    # the weight the rule chose is kept: given back, it restores the same light field
    np.testing.assert_allclose(deconvolve(blurred, cp, n_times=6, method="tv", weight=params["weight_used"], n_iter=5),
                               out, atol=1e-6)


@pytest.mark.parametrize("box", ["couple_channels", "saturation"], ids=["colour TV", "saturated samples"])
def test_deconvolve_boxes_reach_the_solver(box, make_napari_viewer, qtbot, notifications):
    from napari_lfdeblur import synthetic_scene
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur.deconvolution import deconvolve

    # colour TV: a colour scene; saturated samples: a scene brighter than the sensor's ceiling, its blur clipped
    colour = box == "couple_channels"
    lf, _ = synthetic_scene((3, 3, 16, 16), color=colour, seed=2)
    cp = np.array([[-0.5, 0.2, 0.1], [0.6, -0.3, -0.1]])
    blurred = simulate_blur(lf if colour else 1.4 * lf, cp, n_times=6)
    blurred = blurred if colour else np.clip(blurred, 0, 1).astype(np.float32)
    viewer = make_napari_viewer()
    viewer.add_image(blurred, name="b", rgb=colour)
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.layer_combo.set_layer("b")
    w.table.set_control_points(cp)
    w.form.n_times.value = 6
    w.form.n_iter.value = 4
    assert getattr(w.form, box).value  # on by default
    results = []
    for on in (True, False):
        getattr(w.form, box).value = on
        w.run()
        _wait_done(qtbot, w)
        assert not [n for n in notifications if n[0] == "error"], notifications
        out = viewer.layers["b deconvolved"]
        np.testing.assert_allclose(out.data, deconvolve(blurred, cp, n_times=6, n_iter=4, **{box: on}), atol=1e-5)
        assert out.metadata["parameters"][box] is on
        results.append(out.data.copy())
        viewer.layers.remove(out)
    assert not np.allclose(*results)  # the box changes the result


def test_deconvolve_tv_along_the_views_reaches_the_solver(make_napari_viewer, qtbot, lf, notifications):
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur.deconvolution import deconvolve

    cp = np.array([[-0.5, 0.2, 0.1], [0.6, -0.3, -0.1]])
    blurred = simulate_blur(lf, cp, n_times=6)
    viewer = make_napari_viewer()
    viewer.add_image(blurred, name="b")
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.layer_combo.set_layer("b")
    w.table.set_control_points(cp)
    w.form.n_times.value = 6
    w.form.n_iter.value = 4
    assert w.form.along_disparity.value  # on by default: the TV along the disparity
    w.form.along_disparity.value = False
    w.run()
    _wait_done(qtbot, w)
    assert not [n for n in notifications if n[0] == "error"], notifications
    out = viewer.layers["b deconvolved"]
    want = deconvolve(blurred, cp, n_times=6, n_iter=4, angular="views", isotropic=True)
    np.testing.assert_allclose(out.data, want, atol=1e-5)
    assert not np.allclose(want, deconvolve(blurred, cp, n_times=6, n_iter=4))
    params = out.metadata["parameters"]
    assert params["angular"] == "views" and params["isotropic"] is True and "along_disparity" not in params


def test_deconvolve_solver_error_is_a_notification(make_napari_viewer, qtbot, lf, notifications, monkeypatch):
    from napari_lfdeblur import deconvolution
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur.progress import Progress

    viewer = make_napari_viewer()
    viewer.add_image(lf, name="b")
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.table.set_control_points([[0, 0, 0.5], [1, 0, 0]])  # not in-plane
    w.form.method.value = "inplane"
    w.run()
    _wait_done(qtbot, w)
    # the solver's own reason, under the widget's title: deconvolve refuses a path with p_z != 0 before it runs
    kind, msg = notifications[-1]
    assert kind == "error" and msg.startswith("4D deconvolution: method 'inplane' needs an in-plane path"), msg
    assert "max |p_z| = 0.5" in msg and "Use method 'tv'" in msg
    assert len(viewer.layers) == 1

    def failing_solve(*args, **kwargs):
        yield Progress("tv", 0, 4)
        raise RuntimeError("the solver ran out of memory")

    # an error the solver raises during its run (in the worker thread) reaches the user with its reason too
    monkeypatch.setattr(deconvolution, "iter_deconvolve", failing_solve)
    w.form.method.value = "tv"
    assert w.run() is not None
    _wait_done(qtbot, w)
    assert notifications[-1] == ("error", "4D deconvolution failed: the solver ran out of memory")
    assert len(viewer.layers) == 1


def test_deconvolve_device_reaches_the_solver(make_napari_viewer, lf, notifications, monkeypatch):
    from napari_lfdeblur import deconvolution
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur.progress import Progress

    seen = []

    def fake_iter_deconvolve(blurred, cp, **kwargs):
        seen.append(kwargs)
        yield Progress("tv", 0, 1)
        return blurred

    monkeypatch.setattr(deconvolution, "iter_deconvolve", fake_iter_deconvolve)
    viewer = make_napari_viewer()
    viewer.add_image(lf, name="b")
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.layer_combo.set_layer("b")
    for device in ("cpu", "auto"):
        w.form.device.value = device
        assert w.run_and_wait(timeout=60)
    # the device chosen is the one the solve runs on, not only the one the result records
    assert [k.get("device") for k in seen] == ["cpu", "auto"]
    assert viewer.layers["b deconvolved"].metadata["parameters"]["device"] == "auto"
    assert not [n for n in notifications if n[0] == "error"], notifications


# ----------------------------------------------------------------- EPI


def test_epi_layers_follow_the_pick(make_napari_viewer, lf):
    from napari_lfdeblur._napari.widgets.epi import EpiPanel

    viewer = make_napari_viewer()
    viewer.add_image(lf, name="lf")
    panel = EpiPanel(viewer)
    viewer.window.add_dock_widget(panel)
    panel.layer_combo.set_layer("lf")
    h, v = panel.show_epis()
    np.testing.assert_array_equal(h.data, lf[2, :, 8, :])
    np.testing.assert_array_equal(v.data, lf[:, 2, :, 8].T)
    panel.y.value = 3
    panel.v.value = 1
    np.testing.assert_array_equal(viewer.layers["lf EPI h"].data, lf[1, :, 3, :])
    panel.x.value = 11
    np.testing.assert_array_equal(viewer.layers["lf EPI v"].data, lf[:, 2, :, 11].T)
    assert viewer.layers["lf EPI h"].metadata["y"] == 3
    assert len(viewer.layers) == 3  # updated in place, not added again


def test_epis_lie_beside_a_layer_placed_in_the_world(make_napari_viewer, lf):
    from napari_lfdeblur._napari.widgets.epi import EpiPanel

    viewer = make_napari_viewer()
    plain = EpiPanel(viewer)
    viewer.add_image(lf, name="a")
    plain.layer_combo.set_layer("a")
    pix = [(tuple(e.scale), tuple(e.translate)) for e in plain.show_epis()]  # the EPIs of an unplaced layer
    viewer.add_image(lf, name="lf", scale=(1, 1, 2, 3), translate=(0, 0, 10, 20))
    panel = EpiPanel(viewer)
    panel.layer_combo.set_layer("lf")
    for epi, (scale, translate) in zip(panel.show_epis(), pix):
        # the same placement, taken through the layer's: it lay over the image (y 10-72), at x 0
        np.testing.assert_allclose(epi.scale, np.multiply(scale, (2, 3)))
        np.testing.assert_allclose(epi.translate, np.add((10, 20), np.multiply(translate, (2, 3))))
    h = viewer.layers["lf EPI h"]
    assert h.extent.world[0, 0] >= viewer.layers["lf"].extent.world[1, 2]  # below the light field


def test_epis_follow_a_layer_whose_data_change(make_napari_viewer, lf):
    from napari_lfdeblur._napari.layers import epi_layer_data
    from napari_lfdeblur._napari.widgets.epi import EpiPanel

    viewer = make_napari_viewer()
    layer = viewer.add_image(lf.copy(), name="lf")
    panel = EpiPanel(viewer)
    viewer.window.add_dock_widget(panel)
    panel.layer_combo.set_layer("lf")
    panel.set_pick(v=4, y=14, u=4, x=14)
    panel.show_epis()
    layer.data = lf[::-1].copy()  # a result updated in place: the EPIs on show are redrawn
    np.testing.assert_array_equal(viewer.layers["lf EPI h"].data, lf[::-1][4, :, 14, :])
    small = lf[:3, :3, :8, :8].copy()
    layer.data = small  # smaller: the picks stay within it
    assert (panel.v.value, panel.u.value, panel.y.value, panel.x.value) == (2, 2, 7, 7)
    assert panel.v.max == 2 and panel.x.max == 7
    np.testing.assert_array_equal(viewer.layers["lf EPI v"].data, small[:, 2, :, 7].T)
    # and they move with its edges: placed as the EPIs of the smaller light field are
    for which in ("h", "v"):
        want = epi_layer_data(small, which, name=f"lf EPI {which}")[1]
        np.testing.assert_allclose(viewer.layers[f"lf EPI {which}"].translate, want["translate"])
        np.testing.assert_allclose(viewer.layers[f"lf EPI {which}"].scale, want["scale"])


def _epi_picking_by_click(make_napari_viewer, data):
    """A viewer with ``data`` as layer 'lf' and the EPI widget on it picking by click: (viewer, widget, callback)."""
    from napari_lfdeblur._napari.widgets import EpiWidget

    viewer = make_napari_viewer()
    viewer.add_image(data, name="lf")
    w = EpiWidget(viewer)
    viewer.window.add_dock_widget(w)
    w.epi.layer_combo.set_layer("lf")
    w.epi.click_box.value = True
    return viewer, w, viewer.mouse_drag_callbacks[-1]


def test_epi_pick_by_clicking(make_napari_viewer, lf):
    from types import SimpleNamespace

    viewer, w, callback = _epi_picking_by_click(make_napari_viewer, lf)
    callback(viewer, SimpleNamespace(position=(1.0, 3.0, 5.2, 9.7)))  # (v, u, y, x) world coordinates
    assert (w.epi.v.value, w.epi.u.value, w.epi.y.value, w.epi.x.value) == (1, 3, 5, 10)
    np.testing.assert_array_equal(viewer.layers["lf EPI h"].data, lf[1, :, 5, :])
    np.testing.assert_array_equal(viewer.layers["lf EPI v"].data, lf[:, 3, :, 10].T)
    callback(viewer, SimpleNamespace(position=(1.0, 3.0, 40.0, 9.0)))  # outside the image: ignored
    assert w.epi.y.value == 5
    w.epi.click_box.value = False
    assert callback not in viewer.mouse_drag_callbacks


def test_epi_pick_by_clicking_on_more_view_rows_than_columns(make_napari_viewer):
    from types import SimpleNamespace

    tall = np.random.default_rng(0).random((7, 3, 8, 8)).astype(np.float32)  # 7 view rows, 3 view columns
    viewer, w, callback = _epi_picking_by_click(make_napari_viewer, tall)
    callback(viewer, SimpleNamespace(position=(6.0, 1.0, 2.0, 3.0)))  # the last view row
    assert (w.epi.v.value, w.epi.u.value, w.epi.y.value, w.epi.x.value) == (6, 1, 2, 3)
    np.testing.assert_array_equal(viewer.layers["lf EPI h"].data, tall[6, :, 2, :])


# --------------------------------------------------------------- blind


def _blind_layer(viewer, lf):
    from napari_lfdeblur._napari.layers import add_layer, lightfield_layer_data, lightfield_metadata
    from napari_lfdeblur.path import linear_path

    cp = linear_path(1.5, angle_deg=20.0)
    meta = lightfield_metadata(kind="blurred", control_points=cp, n_times=16, infinity_disparity=0.0)
    blurred = simulate_blur(lf, cp, n_times=16)
    return add_layer(viewer, lightfield_layer_data(blurred, name="b", metadata=meta)), cp


def _blind_dock(make_napari_viewer, lf, via_menu=False):
    """A viewer holding ``_blind_layer``'s blurred layer and a docked *Blind deblur* widget set to it:
    ``(viewer, layer, true path, widget)``. ``via_menu``: opened as napari's plugin menu does (the widget
    then gets a public-only proxy of the viewer)."""
    from napari_lfdeblur._napari.widgets.blind import BlindDeblurWidget

    viewer = make_napari_viewer()
    layer, cp = _blind_layer(viewer, lf)
    if via_menu:
        w = viewer.window.add_plugin_dock_widget("napari-lfdeblur", "Blind deblur")[1]
    else:
        w = _dock(viewer, BlindDeblurWidget(viewer))
    w.layer_combo.set_layer(layer)
    return viewer, layer, cp, w


@pytest.mark.parametrize("via_menu", [False, True])
def test_blind_end_to_end(make_napari_viewer, qtbot, lf, notifications, via_menu):
    pytest.importorskip("napari_lfdeblur.blind")
    viewer, layer, cp_true, w = _blind_dock(make_napari_viewer, lf, via_menu)
    before = layer.data.copy()
    assert w.form.true_path.current_choice == "b"  # the true path comes from the metadata
    w.form.n_control_points.value = 3
    w.form.n_iter.value = 2
    w.form.tv_iter.value = 3
    w.form.device.value = "cpu"
    w.form.preview_every.value = 1
    w.form.edge_anisotropy.value = 0.3
    inserted = {}  # layer id -> the name it was added under
    viewer.layers.events.inserted.connect(lambda e: inserted.setdefault(id(e.value), e.value.name))
    w.run()
    _wait_done(qtbot, w)
    assert not [n for n in notifications if n[0] == "error"], notifications
    res = w.last_result
    # the previews became the result layers (updated in place, not added anew)
    assert inserted[id(viewer.layers["b deblurred (blind)"])] == "b blind (preview)"
    assert inserted[id(viewer.layers["b estimated path"])] == "b path (preview)"
    rejected = [] if res.info["blur_found"] else ["b rejected path"]  # the evidence test's verdict
    assert [layer.name for layer in viewer.layers] == ["b", "b deblurred (blind)", "b estimated path", *rejected]
    out = viewer.layers["b deblurred (blind)"]
    assert out.data.shape == SHAPE and out.axis_labels == ("v", "u", "y", "x")
    np.testing.assert_array_equal(out.data, res.lightfield)
    meta = out.metadata
    cp = np.asarray(meta["control_points"])
    assert cp.shape == (3, 3)
    np.testing.assert_allclose(cp, res.control_points)
    # zero-mean gauge (docs/model.md)
    np.testing.assert_allclose(bezier_positions(cp, meta["n_times"]).mean(axis=0), 0.0, atol=1e-5)
    assert meta["napari_lfdeblur_version"] == napari_lfdeblur.__version__
    assert meta["parameters"]["device"] == "cpu" and meta["parameters"]["seed"] == 0
    assert meta["loss_history"] == [float(v) for v in res.loss_history]
    assert meta.get("final_weight") == res.info.get("final_weight")  # None only when the input was returned
    assert ("final_weight" in meta) == (res.info["restoration"] != "none")
    assert meta["path_windows"] == [[0, 0, *SHAPE[2:4]]]  # a small view: the path is estimated on all of it
    path = viewer.layers["b estimated path"]
    assert path.metadata["source_layer"] == "b deblurred (blind)"
    # the true path is shown in the estimate's gauge (linear_path is centred; maybe time-reversed)
    true_shown = np.asarray(path.metadata["true_control_points"])
    assert np.allclose(true_shown, cp_true) or np.allclose(true_shown, cp_true[::-1])
    np.testing.assert_allclose(path.metadata["control_points"], cp)
    # the loss curve shows the path-estimation objective of every progress record
    np.testing.assert_allclose(w.loss_plot.values, meta["loss_history"])
    assert len(meta["loss_history"]) >= 2
    assert w.preview_updates >= 1 and w.path_preview_updates >= 1  # live previews were shown (then removed)
    assert meta["parameters"]["n_control_points"] == 3 and meta["parameters"]["final"]["n_iter"] == 3
    assert meta["parameters"]["latent"]["edge_anisotropy"] == pytest.approx(0.3)
    assert BlindParams.from_metadata(meta) == res.params  # the stamp is a preset: the run's parameters again
    np.testing.assert_array_equal(layer.data, before)


def _long_blind_run(make_napari_viewer, qtbot, lf):
    """A viewer and a *Blind deblur* widget whose (endless) run has shown its live path preview."""
    pytest.importorskip("napari_lfdeblur.blind")
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    w.form.n_iter.value = 100000
    w.form.device.value = "cpu"
    worker = w.run()
    qtbot.waitUntil(lambda: "b path (preview)" in viewer.layers, timeout=TIMEOUT)
    return viewer, w, worker


def test_blind_cancel_leaves_no_partial_layer(make_napari_viewer, qtbot, lf, notifications, monkeypatch):
    from napari_lfdeblur import blind

    closed, real = [], blind.iter_blind_deblur

    def watched(*args, **kwargs):
        try:
            return (yield from real(*args, **kwargs))
        finally:
            closed.append(True)

    monkeypatch.setattr(blind, "iter_blind_deblur", watched)
    viewer, w, _ = _long_blind_run(make_napari_viewer, qtbot, lf)
    assert w.is_running
    w.cancel()
    qtbot.waitUntil(lambda: not w.is_running, timeout=10_000)
    qtbot.wait(100)
    # the solver is closed, and its memory freed (the quit worker left it suspended, and napari keeps the worker)
    assert closed == [True]
    assert [layer.name for layer in viewer.layers] == ["b"]
    assert w.last_result is None
    assert ("info", "Blind deblur: cancelled") in notifications
    assert not [n for n in notifications if n[0] == "error"], notifications


def test_a_failed_blind_run_leaves_no_preview_layer(make_napari_viewer, lf, notifications, monkeypatch):
    import napari_lfdeblur.blind as blind_core
    from napari_lfdeblur._napari.widgets import _runner
    from napari_lfdeblur.progress import Progress

    # previews at every step, not also spaced by their cost: on a loaded machine that spacing can skip one
    monkeypatch.setattr(_runner, "PREVIEW_SHARE", 0.0)

    def failing(lf, **kwargs):  # two steps with live previews, then an error
        for i in range(2):
            yield Progress("path", i, 3, loss=1.0, control_points=np.zeros((2, 3)), estimate=lambda: lf)
        raise RuntimeError("out of memory")

    monkeypatch.setattr(blind_core, "iter_blind_deblur", failing)
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    w.form.preview_every.value = 1
    assert w.run_and_wait(timeout=60) == []
    assert w.preview_updates >= 1 and w.path_preview_updates >= 1  # the previews were shown, then removed
    assert [layer.name for layer in viewer.layers] == ["b"]
    assert notifications[-1] == ("error", "Blind deblur failed: out of memory")


def test_closing_the_viewer_during_a_run_stops_it_quietly(make_napari_viewer, qtbot, lf, notifications,
                                                           monkeypatch):
    """The run's late signals must not reach the deleted widgets (that raised in a Qt slot, then aborted)."""
    from napari_lfdeblur._napari.widgets._runner import ProgressPanel

    viewer, w, worker = _long_blind_run(make_napari_viewer, qtbot, lf)
    closed, late = [], []  # the progress displays called once the viewer is closed
    for cls, name in ((ProgressPanel, "update_progress"), (type(w), "on_progress")):
        def watched(self, progress, _real=getattr(cls, name), _name=name):
            if closed:
                late.append(_name)
            return _real(self, progress)

        monkeypatch.setattr(cls, name, watched)
    finished = []
    worker.finished.connect(lambda: finished.append(True))
    closed.append(True)
    viewer.close()
    qtbot.waitUntil(lambda: bool(finished), timeout=10_000)  # the solver stopped at its next cancellation point
    qtbot.wait(200)
    assert not w.is_running and w.last_result is None
    assert late == []
    assert notifications == []  # quietly: not even a warning


def test_cancel_stops_inside_a_tv_iteration(make_napari_viewer, qtbot, lf, notifications, monkeypatch):
    import time

    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur.deconvolution import N_INNER

    calls = []

    def slow(real, *args, **kwargs):  # each inner iteration of the TV prox takes 0.1 s, N_INNER per iteration
        calls.append(time.perf_counter())
        time.sleep(0.1)
        return real(*args, **kwargs)

    wrap_prox_inner_iteration(monkeypatch, slow)
    viewer = make_napari_viewer()
    viewer.add_image(lf, name="b")
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.layer_combo.set_layer("b")
    w.table.set_control_points([[-0.5, 0.2, 0.1], [0.6, -0.3, -0.1]])
    w.form.method.value = "tv"
    w.form.n_iter.value = 1000
    w.run()
    qtbot.waitUntil(lambda: len(calls) >= N_INNER + 1, timeout=TIMEOUT)  # inside the second iteration
    at_cancel = len(calls)
    w.cancel()
    _wait_done(qtbot, w)
    qtbot.wait(100)
    # the inner iteration under way finishes, then the solve stops: it does not run to the iteration's end
    assert len(calls) <= at_cancel + 1 < 2 * N_INNER
    assert [layer.name for layer in viewer.layers] == ["b"] and w.last_result is None
    assert ("info", "4D deconvolution: cancelled") in notifications
    assert not [n for n in notifications if n[0] == "error"], notifications


def test_blind_live_redraws_are_spaced_by_their_cost(make_napari_viewer, monkeypatch):
    import time

    from napari_lfdeblur._napari.widgets import blind
    from napari_lfdeblur.progress import Progress

    viewer = make_napari_viewer()
    w = blind.BlindDeblurWidget(viewer)
    w._job = {"source": "b", "shape": SHAPE, "n_times": 16, "true": None}
    drawn = []

    def slow_plot(*args, **kwargs):  # a redraw that takes 0.1 s
        drawn.append(kwargs.get("live"))
        time.sleep(0.1)

    # patched on the class: magicgui containers treat attribute deletion (monkeypatch's undo) as widget removal
    monkeypatch.setattr(type(w.plot), "plot", slow_plot)
    record = Progress(stage="path", iteration=1, n_iterations=10, loss=1.0, control_points=np.zeros((2, 3)))
    w.on_progress(record)
    assert drawn == [True] and "b path (preview)" in viewer.layers
    # the next redraw waits for at least REDRAW_SHARE times the cost of this one (over 0.3 s here)
    assert w._next_draw - time.perf_counter() > blind.REDRAW_SHARE * 0.1 - 0.05 > blind.REDRAW_INTERVAL
    w.on_progress(record)
    assert drawn == [True]
    w._next_draw = 0.0
    w.on_progress(record)
    assert drawn == [True, True]


def test_overlapping_runs_leave_the_sessions_warnings_as_they_were(make_napari_viewer, qtbot, lf):
    """Two widgets' runs at once, the first started ending first: warnings raised after them are shown as
    before (not sent to a finished worker), under the filters there were."""
    import warnings

    from napari_lfdeblur._napari.widgets import DeconvolveWidget

    viewer, layer, _, blind_widget = _blind_dock(make_napari_viewer, lf)
    blind_widget.form.n_iter.value, blind_widget.form.tv_iter.value = 2, 10
    deconvolve_widget = _dock(viewer, DeconvolveWidget(viewer))
    deconvolve_widget.layer_combo.value = layer
    deconvolve_widget.form.n_iter.value = 3
    show, filters = warnings.showwarning, list(warnings.filters)
    deconvolve_widget.run()
    blind_widget.run()
    for w in (deconvolve_widget, blind_widget):
        _wait_done(qtbot, w)
    assert warnings.showwarning is show and warnings.filters == filters


def test_blind_unavailable_device_notifies(make_napari_viewer, lf, notifications):
    pytest.importorskip("napari_lfdeblur.blind")
    import torch

    from napari_lfdeblur._napari.widgets.blind import BlindDeblurWidget

    if torch.cuda.is_available():
        pytest.skip("a GPU is available")
    viewer = make_napari_viewer()
    _blind_layer(viewer, lf)
    w = _dock(viewer, BlindDeblurWidget(viewer))
    w.form.device.value = "cuda"
    assert w.run() is None
    assert notifications[-1][0] == "error" and "cuda" in notifications[-1][1]
    assert [layer.name for layer in viewer.layers] == ["b"]


def test_blurred_sample_feeds_the_deconvolution_widget(make_napari_viewer, qtbot, notifications):
    """The plugin's blurred sample carries its path; the widget picks it up and inverts it."""
    from napari_lfdeblur._napari.sample_data import BLURRED_SAMPLE_PATH, synthetic_scene_sample
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget

    viewer = make_napari_viewer()
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.form.infinity_disparity.value = 0.5  # as an earlier layer left it
    viewer.open_sample("napari-lfdeblur", "synthetic_scene_blurred")
    (layer,) = viewer.layers
    w.layer_combo.set_layer(layer)
    np.testing.assert_allclose(w.table.control_points(), BLURRED_SAMPLE_PATH, atol=1e-5)
    # the sample states the d_inf it was blurred with (simulate_blur's default, 0)
    assert w.form.infinity_disparity.value == 0.0
    w.form.method.value = "inplane"
    assert not w.form.weight.enabled  # the weight comes from the noise until the box is unticked
    w.form.noise_weight.value = False
    assert w.form.weight.enabled
    w.form.weight.value = 0.0
    w.run()
    _wait_done(qtbot, w)
    assert not [n for n in notifications if n[0] == "error"], notifications
    sharp = synthetic_scene_sample()[0][0]
    out = viewer.layers[f"{layer.name} deconvolved"].data
    assert out.shape == sharp.shape
    # the exact in-plane inverse of the known path (up to the table's 6 digits) gives back the scene
    assert np.abs(out - sharp).max() < 1e-3


# ------------------------------------------------------------- magicgui


def test_magicgui_form_runs_the_solver(make_napari_viewer, qtbot, lf, notifications):
    """Fill the deconvolution widget's magicgui form through magicgui and run the core through it."""
    from magicgui.widgets import Container

    from napari_lfdeblur._napari.widgets import DeconvolveWidget
    from napari_lfdeblur.deconvolution import deconvolve

    cp = np.array([[-0.4, 0.3, 0.05], [0.5, -0.2, -0.05]])
    blurred = simulate_blur(lf, cp, n_times=6, infinity_disparity=0.25)
    viewer = make_napari_viewer()
    viewer.add_image(blurred, name="b")
    w = _dock(viewer, DeconvolveWidget(viewer))
    assert isinstance(w, Container) and isinstance(w.form, Container)
    form = w.form
    form.layer.value = viewer.layers["b"]
    form.n_times.value = 6
    form.infinity_disparity.value = 0.25
    form.method.value = "tv"
    form.noise_weight.value = False
    form.weight.value = 0.004
    form.n_iter.value = 3
    form.device.value = "cpu"
    w.table.set_control_points(cp)
    w.run_button.clicked.emit()  # as if Run were pressed
    _wait_done(qtbot, w)
    assert not [n for n in notifications if n[0] == "error"], notifications
    out = viewer.layers["b deconvolved"]
    expected = deconvolve(blurred, cp, n_times=6, infinity_disparity=0.25, method="tv", weight=0.004, n_iter=3,
                          device="cpu")
    assert np.allclose(out.data, expected)
    params = out.metadata["parameters"]
    assert {k: params[k] for k in ("n_times", "infinity_disparity", "method", "weight", "n_iter", "device")} == {
        "n_times": 6, "infinity_disparity": 0.25, "method": "tv", "weight": 0.004, "n_iter": 3, "device": "cpu"}
    np.testing.assert_allclose(out.metadata["control_points"], cp)
    np.testing.assert_array_equal(viewer.layers["b"].data, blurred)


def test_path_json_file_fills_the_table(make_napari_viewer, tmp_path, notifications):
    from napari_lfdeblur._napari.widgets import DeconvolveWidget
    from napari_lfdeblur.path import arc_path, save_path_json

    cp = arc_path(length=2.0, bend=0.3)
    save_path_json(tmp_path / "p.json", cp)
    viewer = make_napari_viewer()
    w = _dock(viewer, DeconvolveWidget(viewer))
    w.path_source.json_file.value = tmp_path / "p.json"
    # the table shows 6 digits but holds the file's numbers exactly (arc_path's are not 6-digit numbers)
    assert [w.table.table.native.item(i, 1).text() for i in range(3)] == ["-0.387097", "0.812903", "-0.387097"]
    assert w.table.table.native.item(1, 0).text() == "0.0"  # not 6.93889e-18
    np.testing.assert_array_equal(w.table.control_points(), cp)
    assert (w.form.n_times.value, w.form.infinity_disparity.value) == (32, 0.0)  # the file states neither
    # the T and d_inf a file states reach the form, as a layer's do
    save_path_json(tmp_path / "q.json", cp[::-1], n_times=12, infinity_disparity=-0.5)
    w.path_source.json_file.value = tmp_path / "q.json"
    np.testing.assert_array_equal(w.table.control_points(), cp[::-1])
    assert (w.form.n_times.value, w.form.infinity_disparity.value) == (12, -0.5)
    assert not notifications
    # the same file, changed on disk, is read again by *Load path file* (choosing it again changes nothing)
    save_path_json(tmp_path / "q.json", 2 * cp, n_times=10, overwrite=True)
    w.path_source.json_file.value = tmp_path / "q.json"
    np.testing.assert_array_equal(w.table.control_points(), cp[::-1])
    w.path_source.load_button.clicked.emit()
    np.testing.assert_array_equal(w.table.control_points(), 2 * cp)
    assert w.form.n_times.value == 10 and not notifications
    # values the form cannot take (lfdeblur refuses them too: no 8.0 or '8' for T) are left out with a
    # warning; the path is still taken
    for i, n_times in enumerate((7.5, 8.0, "8")):
        (tmp_path / "bad.json").write_text(json.dumps(
            {"control_points": (3 * cp).tolist(), "n_times": n_times, "infinity_disparity": 50.0}))
        if i == 0:
            w.path_source.json_file.value = tmp_path / "bad.json"
        else:
            w.path_source.load_button.clicked.emit()
        np.testing.assert_array_equal(w.table.control_points(), 3 * cp)
        assert (w.form.n_times.value, w.form.infinity_disparity.value) == (10, -0.5)
        assert [kind for kind, _ in notifications] == ["warning", "warning"]
        assert f"n_times = {n_times!r}" in notifications[0][1] and "infinity_disparity = 50.0" in notifications[1][1]
        notifications.clear()


def test_simulate_takes_a_path_from_a_json_file_or_a_layer(make_napari_viewer, qtbot, lf, tmp_path, notifications):
    from napari_lfdeblur._napari.layers import add_layer, path_layer_data
    from napari_lfdeblur._napari.widgets import SimulateBlurWidget
    from napari_lfdeblur.path import arc_path, save_path_json, shake6_path

    cp = arc_path(length=1.5, bend=0.4)
    cp[:, 2] = [0.2, 0.0, -0.1]  # with p_z
    save_path_json(tmp_path / "p.json", cp, n_times=6, infinity_disparity=0.5)
    viewer = make_napari_viewer()
    src = viewer.add_image(lf.copy(), name="sharp")
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.layer_combo.set_layer(src)
    w.path_source.json_file.value = tmp_path / "p.json"
    assert (w.form.n_times.value, w.form.infinity_disparity.value) == (6, 0.5)
    w.run()
    _wait_done(qtbot, w)
    np.testing.assert_allclose(viewer.layers["sharp blurred"].data,
                               simulate_blur(lf, cp, n_times=6, infinity_disparity=0.5), atol=1e-6)
    cp6 = shake6_path(1.0, seed=1, rotation=0.01)
    add_layer(viewer, path_layer_data(cp6, lf.shape, n_times=9, infinity_disparity=-0.5, name="other path"))
    w.path_source.path_layer.set_layer("other path")
    w.path_source.take_button.clicked.emit()
    np.testing.assert_allclose(w.table.control_points(), cp6, atol=1e-6)
    assert (w.form.n_times.value, w.form.infinity_disparity.value) == (9, -0.5)
    assert not notifications


def test_a_path_for_views_of_another_size_is_warned_about(make_napari_viewer, qtbot, lf, tmp_path, notifications):
    from napari_lfdeblur._napari.layers import add_layer, path_layer_data
    from napari_lfdeblur._napari.widgets import DeconvolveWidget, SimulateBlurWidget
    from napari_lfdeblur.path import save_path_json

    Y, X = lf.shape[2:4]
    cp = np.array([[-0.4, 0.3, 0.3], [0.5, -0.2, -0.3]])  # with p_z: its blur depends on the views' size
    save_path_json(tmp_path / "p.json", cp, n_times=6, view_shape=[Y, 2 * X])
    viewer = make_napari_viewer()
    viewer.add_image(lf.copy(), name="sharp")
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.path_source.json_file.value = tmp_path / "p.json"
    w.run()
    _wait_done(qtbot, w)
    assert [kind for kind, _ in notifications] == ["warning"]
    assert f"Simulate blur: the path is for {Y}x{2 * X} views and these are {Y}x{X}" in notifications[0][1]
    assert "path_in_window" in notifications[0][1]
    np.testing.assert_allclose(viewer.layers["sharp blurred"].data, simulate_blur(lf, cp, n_times=6), atol=1e-6)
    # a preset is for any views: nothing to say
    notifications.clear()
    w.path_form.preset.value = "linear"
    w.apply_preset()
    w.table.set_control_points(cp)  # typed in: its views are not known
    w.run()
    _wait_done(qtbot, w)
    assert not notifications
    # the blurred layer's own path is for its views; a path layer of a larger light field is not
    d = _dock(viewer, DeconvolveWidget(viewer))
    d.form.layer.value = viewer.layers["sharp blurred"]  # takes its path
    d.form.n_iter.value = 2
    d.run()
    _wait_done(qtbot, d)
    assert not notifications
    add_layer(viewer, path_layer_data(cp, (*lf.shape[:2], 2 * Y, X), n_times=6, name="big path"))
    d.path_source.path_layer.set_layer("big path")
    d.path_source.take_button.clicked.emit()
    d.run()
    _wait_done(qtbot, d)
    assert [kind for kind, _ in notifications] == ["warning"]
    assert f"4D deconvolution: the path is for {2 * Y}x{X} views and these are {Y}x{X}" in notifications[0][1]


def test_path_table_rows_can_be_added_and_removed(make_napari_viewer):
    from napari_lfdeblur._napari.widgets import SimulateBlurWidget

    viewer = make_napari_viewer()
    w = _dock(viewer, SimulateBlurWidget(viewer))
    w.table.set_control_points([[0, 0, 0], [1, 2, 0]])
    w.table.add_button.clicked.emit()
    np.testing.assert_allclose(w.table.control_points(), [[0, 0, 0], [1, 2, 0], [1, 2, 0]])
    w.table.remove_button.clicked.emit()
    w.table.remove_button.clicked.emit()  # two points at least
    np.testing.assert_allclose(w.table.control_points(), [[0, 0, 0], [1, 2, 0]])


# ------------------------------------------------------ 6-DOF paths


def test_path_table_rotation_columns_round_trip(make_napari_viewer, tmp_path, notifications):
    from napari_lfdeblur._napari.widgets import DeconvolveWidget
    from napari_lfdeblur.path import save_path_json, shake6_path

    viewer = make_napari_viewer()
    w = _dock(viewer, DeconvolveWidget(viewer))
    table = w.table
    assert not table.rotation.value and table.table.column_headers[-1] == "p_z (views/x~)"
    cp6 = shake6_path(1.0, seed=4, rotation=0.01)
    save_path_json(tmp_path / "p6.json", cp6)
    w.path_source.json_file.value = tmp_path / "p6.json"  # a 6-column file ticks the box
    assert table.rotation.value and table.table.column_headers[3:] == ("r_x (rad)", "r_y (rad)", "r_z (rad)")
    np.testing.assert_allclose(table.control_points(), cp6, atol=1e-6)
    assert w.plot.ax_rot is not None and len(w.plot.ax_rot.lines) == 3  # rotation panel, mrad
    assert "mrad" in w.plot.ax_rot.get_ylabel()
    table.rotation.value = False  # hidden ...
    np.testing.assert_allclose(table.control_points(), cp6[:, :3], atol=1e-6)
    assert w.plot.ax_rot is None
    table.rotation.value = True  # ... and shown again
    np.testing.assert_allclose(table.control_points(), cp6, atol=1e-6)
    table.add_button.clicked.emit()
    assert table.control_points().shape == (6, 6)
    # a 3-column file unticks it
    save_path_json(tmp_path / "p3.json", cp6[:, :3])
    w.path_source.json_file.value = tmp_path / "p3.json"
    assert not table.rotation.value and table.control_points().shape == (5, 3)
    # ticking it on a 3-column path adds zero rotations
    table.rotation.value = True
    np.testing.assert_allclose(table.control_points()[:, 3:], 0.0)
    assert not [n for n in notifications if n[0] == "error"], notifications


def test_simulate_shake6_preset_and_a_too_large_rotation(make_napari_viewer, qtbot, lf, notifications):
    from napari_lfdeblur._napari.widgets import SimulateBlurWidget
    from napari_lfdeblur.path import preset_path

    viewer = make_napari_viewer()
    viewer.add_image(lf, name="sharp")
    w = _dock(viewer, SimulateBlurWidget(viewer))
    f = w.path_form
    assert "shake6" in f.preset.choices
    f.preset.value, f.extent.value, f.seed.value, f.rotation.value = "shake6", 1.0, 3, 0.01
    f.apply_preset.clicked.emit()
    expected = preset_path("shake6", 1.0, 3, rotation=0.01)
    np.testing.assert_allclose(w.table.control_points(), expected, atol=1e-6)
    w.form.n_times.value = 4
    assert [layer.name for layer in w.run_and_wait(timeout=60)] == ["sharp blurred", "sharp blurred path"]
    assert not [n for n in notifications if n[0] == "error"], notifications
    # the layers hold the preset's path, and the light field blurred with that path
    np.testing.assert_allclose(viewer.layers["sharp blurred"].metadata["control_points"], expected, atol=1e-6)
    np.testing.assert_allclose(viewer.layers["sharp blurred"].data, simulate_blur(lf, expected, n_times=4),
                               atol=1e-6)
    np.testing.assert_allclose(viewer.layers["sharp blurred path"].metadata["control_points"], expected, atol=1e-6)
    # a rotation beyond 0.2 rad: a notification naming the cell, no traceback, no layer
    w.table.table.native.item(1, 4).setText("0.3")
    assert w.run() is None
    kind, msg = notifications[-1]
    assert kind == "error" and "control point 2, r_y" in msg and "0.2 rad" in msg
    assert len(viewer.layers) == 3


def test_blind_motion_choice_reaches_the_params_and_6dof_results_display(make_napari_viewer, monkeypatch, lf,
                                                                         notifications):
    import napari_lfdeblur.blind as blind_core
    from napari_lfdeblur.path import preset_path
    from napari_lfdeblur.progress import Progress

    cp6 = preset_path("shake6", 1.0, 0, rotation=0.01)[:4]
    seen = {}

    def fake_iter_blind_deblur(lf, *, infinity_disparity, params, device, seed, windows=None, check_view_order=True):
        seen["params"] = params
        yield Progress("path", 1, 2, loss=1.0, control_points=cp6)
        return blind_core.BlindResult(lf, cp6, loss_history=[1.0], params=params)

    monkeypatch.setattr(blind_core, "iter_blind_deblur", fake_iter_blind_deblur)
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    assert w.form.motion.value == "3dof" and "slower" in w.form.motion.tooltip.lower()
    w.form.motion.value = "6dof"
    names = [layer.name for layer in w.run_and_wait(timeout=60)]
    assert not [n for n in notifications if n[0] == "error"], notifications
    assert seen["params"].motion == "6dof"
    assert names == ["b deblurred (blind)", "b estimated path"]
    np.testing.assert_allclose(viewer.layers["b estimated path"].metadata["control_points"], cp6)
    assert viewer.layers["b deblurred (blind)"].metadata["parameters"]["motion"] == "6dof"
    assert w.plot.ax_rot is not None and len(w.plot.ax_rot.lines) == 3  # estimate only: the true path is 3-DOF
    # the paper preset (joint method) cannot estimate a rotation: a clear note, no run
    w.form.preset.value = "paper"
    assert w.form.motion.value == "3dof"  # the preset's motion
    w.form.motion.value = "6dof"
    assert w.run() is None
    assert notifications[-1][0] == "error" and "6-DOF motion needs the alternating method" in notifications[-1][1]


def _fake_blind_solver(monkeypatch) -> list:
    """Replace the blind solver by one that returns its input with a zero path; the keyword arguments of
    each call go to the list returned."""
    import napari_lfdeblur.blind as blind_core
    from napari_lfdeblur.progress import Progress

    seen = []

    def fake_iter_blind_deblur(lf, **kwargs):
        seen.append(kwargs)
        yield Progress("path", 1, 1, loss=1.0)
        return blind_core.BlindResult(lf, np.zeros((3, 3)), loss_history=[1.0], params=kwargs["params"])

    monkeypatch.setattr(blind_core, "iter_blind_deblur", fake_iter_blind_deblur)
    return seen


def test_blind_windows_drawn_on_a_shapes_layer_reach_the_solver(make_napari_viewer, monkeypatch, lf, notifications):
    seen = _fake_blind_solver(monkeypatch)
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    assert w.form.windows.value is None  # by default the solver chooses
    marks = viewer.add_shapes(ndim=4, name="static part")  # drawn over the light field, at view (2, 3)
    marks.add_rectangles(np.array([[2, 3, 1.2, 2.6], [2, 3, 1.2, 13.4], [2, 3, 10.4, 13.4], [2, 3, 10.4, 2.6]]))
    # a path layer is not offered (its grey rectangle is the aperture), a Shapes layer is
    offered = [c for c in w.form.windows.choices if c is not None]
    assert offered == [marks] and w.form.windows.value is None
    w.run_and_wait(timeout=60)
    w.form.windows.value = marks
    w.run_and_wait(timeout=60)
    assert [k["windows"] for k in seen] == [None, [(1, 3, 10, 11)]]  # rows 1..10, columns 3..13: the pixels the rectangle covers
    assert viewer.layers["b deblurred (blind)"].metadata["parameters"]["windows"] == [[1, 3, 10, 11]]
    assert not notifications
    # a shape off the views, or none at all: an error, and no run
    marks.add_rectangles(np.array([[2, 3, 20, 20], [2, 3, 20, 30], [2, 3, 30, 30], [2, 3, 30, 20]]))
    assert w.run() is None and "lies outside the 16 x 16 views" in notifications[-1][1]
    marks.data = []
    assert w.run() is None and "holds no shape" in notifications[-1][1]
    assert len(seen) == 2


def test_blind_checks_the_view_order_of_a_layer_no_reader_checked(make_napari_viewer, monkeypatch, lf, notifications):
    seen = _fake_blind_solver(monkeypatch)
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    w.run_and_wait(timeout=60)
    layer.metadata = {**layer.metadata, "view_shifts": [[0.6, 0.0], [0.0, 0.6]]}  # as the reader records it
    w.run_and_wait(timeout=60)
    assert [k["check_view_order"] for k in seen] == [True, False]


def test_blind_restore_anyway_reaches_the_params(make_napari_viewer, monkeypatch, lf, notifications):
    calls = _fake_blind_solver(monkeypatch)
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    assert w.form.restore_anyway.value is False  # the presets require evidence of blur
    w.run_and_wait(timeout=60)
    w.form.restore_anyway.value = True
    w.run_and_wait(timeout=60)
    assert [k["params"].require_evidence for k in calls] == [True, False]
    assert viewer.layers["b deblurred (blind)"].metadata["parameters"]["require_evidence"] is False
    assert w.form.light_restoration.value == 0.5  # the default preset's light restoration
    assert not w.form.light_restoration.enabled  # moot while restoring anyway
    w.form.restore_anyway.value = False
    assert w.form.light_restoration.enabled
    w.form.light_restoration.value = 0.25
    w.run_and_wait(timeout=60)
    assert [k["params"].light_restoration for k in calls] == [0.5, 0.5, 0.25]
    assert calls[-1]["params"].require_evidence is True
    assert viewer.layers["b deblurred (blind)"].metadata["parameters"]["light_restoration"] == 0.25
    w.form.restore_anyway.value = True
    w.form.preset.value = "paper"  # choosing a preset shows its own setting again
    assert w.form.restore_anyway.value is False and w.form.light_restoration.value == 0.0
    w.form.preset.value = "default"
    assert w.form.light_restoration.value == 0.5
    assert not [n for n in notifications if n[0] == "error"], notifications


def test_blind_seed_infinity_disparity_and_device_reach_the_solver(make_napari_viewer, monkeypatch, lf,
                                                                    notifications):
    calls = _fake_blind_solver(monkeypatch)
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    w.form.seed.value, w.form.infinity_disparity.value, w.form.device.value = 5, 0.5, "cpu"
    assert w.run_and_wait(timeout=60)
    # the values the solve ran with, not only the ones the result records
    assert [(k["seed"], k["infinity_disparity"], k["device"]) for k in calls] == [(5, 0.5, "cpu")]
    params = viewer.layers["b deblurred (blind)"].metadata["parameters"]
    assert (params["seed"], params["infinity_disparity"], params["device"]) == (5, 0.5, "cpu")
    assert not [n for n in notifications if n[0] == "error"], notifications


def test_blind_true_path_follows_the_input_and_an_odd_t_only_changes_its_drawing(make_napari_viewer, monkeypatch,
                                                                                    lf, notifications):
    _fake_blind_solver(monkeypatch)
    viewer, layer, cp, w = _blind_dock(make_napari_viewer, lf)
    assert w.form.true_path.value is layer  # taken from the input's metadata
    layer.metadata["n_times"] = None  # as a file may state it: drawn with T = 32, and the run goes on
    w.run_and_wait(timeout=60)
    assert not [n for n in notifications if n[0] == "error"], notifications
    assert "b deblurred (blind)" in viewer.layers
    other = viewer.add_image(lf.copy(), name="other")  # states no path: the previous input's is not its truth
    w.layer_combo.set_layer(other)
    assert w.form.true_path.value is None
    truth = viewer.add_image(lf.copy(), name="truth", metadata={"control_points": cp.tolist()})
    w.form.true_path.set_layer(truth)  # chosen by hand: kept when the input changes
    w.layer_combo.set_layer(viewer.add_image(lf.copy(), name="third"))
    assert w.form.true_path.value is truth


def test_widgets_take_the_infinity_disparity_a_layer_states(make_napari_viewer, lf, notifications):
    from napari_lfdeblur._napari.widgets import BlindDeblurWidget, DeconvolveWidget

    viewer = make_napari_viewer()
    stated = viewer.add_image(lf, name="capture", metadata={"infinity_disparity": -1.5})  # no path
    odd = viewer.add_image(lf, name="odd", metadata={"infinity_disparity": "far"})
    plain = viewer.add_image(lf, name="plain")
    w = _dock(viewer, BlindDeblurWidget(viewer))
    w.layer_combo.set_layer(stated)
    assert w.form.infinity_disparity.value == -1.5 and w.form.true_path.value is None
    assert not notifications
    w.layer_combo.set_layer(odd)  # a value the field cannot take: a warning, the field unchanged
    assert w.form.infinity_disparity.value == -1.5
    assert notifications == [("warning", "Blind deblur: layer 'odd' states infinity_disparity = 'far', which this "
                                         "form cannot take (-20 to 20); infinity_disparity stays -1.5")]
    notifications.clear()
    w.layer_combo.set_layer(plain)  # states nothing: the capture's value is not carried over to another one
    assert w.form.infinity_disparity.value == 0.0
    assert notifications == [("info", "Blind deblur: layer 'plain' states no infinity disparity; the previous "
                                      "layer's is not carried over (set to 0)")]
    w.form.infinity_disparity.value = 0.75  # but a value the user typed stays
    w.layer_combo.set_layer(odd)
    w.layer_combo.set_layer(plain)
    assert w.form.infinity_disparity.value == 0.75
    # a stated value keeps its decimals (the field rounded 0.125 to 0.13, silently)
    w.layer_combo.set_layer(viewer.add_image(lf, name="fine", metadata={"infinity_disparity": 0.125}))
    assert w.form.infinity_disparity.value == 0.125
    # the deconvolution widget too (the path comes from elsewhere)
    d = _dock(viewer, DeconvolveWidget(viewer))
    d.layer_combo.set_layer(stated)
    assert d.form.infinity_disparity.value == -1.5


def test_widgets_follow_an_input_updated_in_place_and_record_every_parameter(make_napari_viewer, qtbot, lf,
                                                                             notifications):
    # a re-run of Simulate blur updates its result layer in place: the deconvolution widget, with that layer
    # chosen, takes the new path, T and d_inf (it kept the first run's and deconvolved with them)
    from napari_lfdeblur._napari.widgets import DeconvolveWidget, SimulateBlurWidget
    from napari_lfdeblur.path import arc_path

    viewer = make_napari_viewer()
    viewer.add_image(lf, name="scene")
    s = _dock(viewer, SimulateBlurWidget(viewer))
    s.layer_combo.set_layer("scene")
    s.run()
    _wait_done(qtbot, s)
    d = _dock(viewer, DeconvolveWidget(viewer))
    d.layer_combo.set_layer("scene blurred")
    first = d.table.control_points()
    s.set_path(arc_path(2.0, 0.3))
    s.form.n_times.value, s.form.infinity_disparity.value = 8, 0.5
    s.run()
    _wait_done(qtbot, s)
    arc = arc_path(2.0, 0.3)
    assert first.shape != arc.shape or not np.allclose(first, arc, atol=1e-3)  # the first run's path
    np.testing.assert_allclose(d.table.control_points(), arc, atol=1e-6)
    assert (d.form.n_times.value, d.form.infinity_disparity.value) == (8, 0.5)
    d.form.n_iter.value = 3
    d.run()
    _wait_done(qtbot, d)
    recorded = viewer.layers["scene blurred deconvolved"].metadata["parameters"]
    assert set(DeconvolutionParams().to_dict()) <= set(recorded)  # tol, clip, angular, ... too
    assert (recorded["n_times"], recorded["infinity_disparity"], recorded["n_iter"]) == (8, 0.5, 3)
    assert not [n for n in notifications if n[0] == "error"], notifications


def test_blind_rejected_path_becomes_a_layer_that_deconvolve_takes(make_napari_viewer, monkeypatch, lf,
                                                                    notifications):
    import napari_lfdeblur.blind as blind_core
    from napari_lfdeblur._napari.widgets.deconvolve import DeconvolveWidget
    from napari_lfdeblur.progress import Progress

    rejected = np.array([[-0.6, 0.3, 0.1], [0.2, -0.4, 0.0], [0.4, 0.1, -0.1]])

    # the evidence test says no
    def fake_iter_blind_deblur(lf, *, infinity_disparity, params, device, seed, windows=None, check_view_order=True):
        yield Progress("path", 1, 1, loss=1.0)
        return blind_core.BlindResult(lf, np.zeros((3, 3)), loss_history=[1.0], params=params,
                                      info={"blur_found": False, "message": "little blur found",
                                            "rejected_path": rejected})

    monkeypatch.setattr(blind_core, "iter_blind_deblur", fake_iter_blind_deblur)
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    w.form.infinity_disparity.value = 0.5
    names = [layer.name for layer in w.run_and_wait(timeout=60)]
    assert names == ["b deblurred (blind)", "b estimated path", "b rejected path"]
    assert notifications[-1][0] == "info" and "little blur found" in notifications[-1][1]
    assert "'b rejected path'" in notifications[-1][1]
    d = _dock(viewer, DeconvolveWidget(viewer))
    d.path_source.path_layer.set_layer("b rejected path")
    d.path_source.take_button.clicked.emit()
    np.testing.assert_allclose(d.table.control_points(), rejected)
    assert d.form.infinity_disparity.value == 0.5
    # the estimated path too holds the d_inf it was estimated with
    d.form.infinity_disparity.value = 0.0
    d.path_source.path_layer.set_layer("b estimated path")
    d.path_source.take_button.clicked.emit()
    assert d.form.infinity_disparity.value == 0.5
    # with blur found nothing is rejected: no such layer
    def fake_found(lf, *, infinity_disparity, params, device, seed, windows=None, check_view_order=True):
        yield Progress("path", 1, 1, loss=1.0)
        return blind_core.BlindResult(lf, rejected, loss_history=[1.0], params=params, info={"blur_found": True})

    monkeypatch.setattr(blind_core, "iter_blind_deblur", fake_found)
    assert "b rejected path" not in [layer.name for layer in w.run_and_wait(timeout=60)]
    assert "b rejected path" not in viewer.layers  # the earlier run's is not this result's: removed
    # blur found, but its restoration did not reproduce the data: the input, the path kept, and the reason shown
    def fake_refused(lf, *, infinity_disparity, params, device, seed, windows=None, check_view_order=True):
        yield Progress("path", 1, 1, loss=1.0)
        return blind_core.BlindResult(lf, np.zeros((3, 3)), loss_history=[1.0], params=params,
                                      info={"blur_found": True, "restoration": "none", "rejected_path": rejected,
                                            "message": "blur found ...; but the restoration ... misses the data"})

    monkeypatch.setattr(blind_core, "iter_blind_deblur", fake_refused)
    assert "b rejected path" in [layer.name for layer in w.run_and_wait(timeout=60)]
    assert notifications[-1][0] == "info" and "misses the data" in notifications[-1][1]
    assert "'b rejected path'" in notifications[-1][1]
    assert not [n for n in notifications if n[0] == "error"], notifications


def test_solver_steps_and_samples_run_on_one_torch_thread(make_napari_viewer, monkeypatch, lf, notifications):
    # libgomp keeps a thread pool per thread that uses torch: the plugin keeps all its torch work on one thread
    import threading

    import napari_lfdeblur.blind as blind_core
    from napari_lfdeblur._napari import sample_data
    from napari_lfdeblur._napari.widgets import _runner
    from napari_lfdeblur.progress import Progress

    # previews at every step, not also spaced by their cost: on a loaded machine that spacing can skip one
    monkeypatch.setattr(_runner, "PREVIEW_SHARE", 0.0)
    seen = []

    def fake_iter_blind_deblur(lf, *, infinity_disparity, params, device, seed, windows=None, check_view_order=True):
        for i in range(3):
            seen.append(threading.current_thread())
            yield Progress("path", i, 3, loss=1.0, estimate=lambda: seen.append(threading.current_thread()) or lf)
        return blind_core.BlindResult(lf, np.zeros((3, 3)), loss_history=[1.0], params=params)

    monkeypatch.setattr(blind_core, "iter_blind_deblur", fake_iter_blind_deblur)
    real_blur = sample_data.simulate_blur
    monkeypatch.setattr(sample_data, "simulate_blur",
                        lambda *a, **k: seen.append(threading.current_thread()) or real_blur(*a, **k))
    viewer, layer, _, w = _blind_dock(make_napari_viewer, lf)
    w.form.preview_every.value = 1
    for _ in range(2):
        assert w.run_and_wait(timeout=60)
    [(data, _, _)] = sample_data.synthetic_blurred_sample()
    assert len(seen) == 2 * (3 + 3) + 1  # 3 steps and 3 previews per run, and the sample's blur
    assert len(set(seen)) == 1 and seen[0] is not threading.main_thread()
    assert data.shape[:4] == sample_data.SYNTHETIC_SHAPE
    assert not [n for n in notifications if n[0] == "error"], notifications


def test_progress_panel_promises_no_time_left_to_a_solve_that_stops_when_it_settles(qapp):
    from napari_lfdeblur._napari.widgets._runner import ProgressPanel
    from napari_lfdeblur.progress import Progress

    panel = ProgressPanel()
    panel.start()
    panel._t0 -= 10.0  # 10 s into the run
    panel.update_progress(Progress(stage="path", iteration=20, n_iterations=100, loss=1.0))
    # a fifth done in 10 s: the other four fifths take 40 s more at that pace
    assert "left" in panel.status.value and panel.eta_seconds == pytest.approx(40.0, abs=0.5)
    # the TV solve: 20 of at most 200 iterations says nothing of the time left
    panel.update_progress(Progress(stage="tv", iteration=20, n_iterations=200, loss=1.0,
                                   info={"relative_decrease": 3e-4}))
    assert "left" not in panel.status.value and "decreasing by 3.0e-04" in panel.status.value
    assert panel.eta_seconds is None


def test_loss_plot_counts_iterations_in_whole_numbers(qtbot):
    from napari_lfdeblur._napari.widgets._plots import LossPlot

    plot = LossPlot()
    plot.plot([4e-4, 5e-5, 3e-5])  # three iterations: matplotlib alone would tick 1.00, 1.25, ...
    plot.figure.canvas.draw()
    ticks = [t for t in plot.ax.get_xticks() if 1 <= t <= 3]
    assert ticks and all(float(t).is_integer() for t in ticks)
    assert plot.ax.get_yscale() == "log"
