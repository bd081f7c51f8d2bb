"""Layer data tuples for light fields, EPIs and camera paths (no viewer needed)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("napari")

from napari.layers import Image, Layer, Shapes  # noqa: E402

import napari_lfdeblur  # noqa: E402
from napari_lfdeblur._napari.layers import (  # noqa: E402
    LayerError,
    control_points_from_layer,
    epi_layer_data,
    lightfield_from_layer,
    lightfield_layer_data,
    lightfield_metadata,
    path_layer_data,
    path_scale,
    windows_from_shapes,
)
from napari_lfdeblur.path import bezier_positions  # noqa: E402


def test_lightfield_layer_grey_and_colour():
    grey = np.zeros((3, 4, 8, 10), np.float32)
    data, kw, kind = lightfield_layer_data(grey, name="g", metadata={"a": 1})
    layer = Layer.create(data, kw, kind)
    assert kind == "image" and not layer.rgb
    assert layer.axis_labels == ("v", "u", "y", "x") and layer.metadata == {"a": 1}
    colour = np.zeros((3, 4, 8, 10, 3), np.float32)
    layer = Layer.create(*lightfield_layer_data(colour, name="c"))
    assert layer.rgb and layer.data.shape == colour.shape
    # a single channel is squeezed to 4D
    data, kw, _ = lightfield_layer_data(grey[..., None], name="s")
    assert data.shape == grey.shape and not kw["rgb"]
    # a grey result is shown on 0..1, the scale of its input, not stretched to its own range
    mid = 0.25 + 0.5 * np.random.default_rng(0).random(grey.shape).astype(np.float32)
    assert tuple(Layer.create(*lightfield_layer_data(mid, name="m")).contrast_limits) == (0.0, 1.0)


def test_metadata_holds_version_parameters_and_path():
    meta = lightfield_metadata(kind="blurred", parameters={"w": 1}, control_points=[[0, 0, 0], [1, 2, 3]],
                               n_times=8, infinity_disparity=0.5, source_layer="x", extra=3)
    assert meta["napari_lfdeblur_version"] == napari_lfdeblur.__version__
    assert meta["control_points"] == [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]
    assert meta["parameters"] == {"w": 1} and meta["n_times"] == 8 and meta["extra"] == 3


def test_lightfield_from_layer_copies_and_scales_integers():
    data = np.full((2, 2, 3, 3), 255, np.uint8)
    layer = Image(data)
    lf = lightfield_from_layer(layer)
    assert lf.dtype == np.float32 and np.all(lf == 1.0)
    f = np.random.default_rng(0).random((2, 2, 3, 3)).astype(np.float32)
    layer = Image(f)
    lf = lightfield_from_layer(layer)
    np.testing.assert_array_equal(lf, f)
    assert not np.shares_memory(lf, layer.data)  # a copy: writing into it leaves the layer untouched


@pytest.mark.parametrize(
    "layer, message",
    [(None, "no light-field layer"), (Image(np.zeros((8, 8))), "4D"), (Image(np.zeros((2, 8, 8))), "4D")],
)
def test_lightfield_from_layer_rejects(layer, message):
    with pytest.raises(LayerError, match=message):
        lightfield_from_layer(layer)


def test_path_layer_frame():
    cp = np.array([[-1.0, 0.5, 0.0], [1.0, -0.5, 0.2], [0.5, 1.0, 0.0]])
    shape = (5, 7, 20, 30)
    shapes, kw, kind = path_layer_data(cp, shape, n_times=9, true_control_points=cp * 0.5)
    s = path_scale(shape)
    assert s == 20 / (2 * 7)
    assert kind == "shapes" and kw["shape_type"] == ["rectangle", "path", "path", "ellipse"]
    rect, true_line, line, start = shapes
    # aperture: views -(U-1)/2 .. (U-1)/2 around the centre pixel
    np.testing.assert_allclose(rect, [[9.5 - 2 * s, 14.5 - 3 * s], [9.5 + 2 * s, 14.5 + 3 * s]])
    pos = bezier_positions(cp, 9)
    np.testing.assert_allclose(line, np.stack([9.5 + s * pos[:, 1], 14.5 + s * pos[:, 0]], axis=1))
    np.testing.assert_allclose(start.mean(axis=0), line[0])
    np.testing.assert_allclose(true_line, np.stack([9.5 + s * pos[:, 1] / 2, 14.5 + s * pos[:, 0] / 2], axis=1))
    assert kw["metadata"]["pixels_per_view"] == s
    np.testing.assert_allclose(control_points_from_layer(Layer.create(shapes, kw, kind)), cp)


def test_epi_layer_data():
    lf = np.random.default_rng(0).random((5, 6, 12, 16, 3)).astype(np.float32)
    data, kw, _ = epi_layer_data(lf, "h", name="h", v=1, y=4)
    np.testing.assert_array_equal(data, lf[1, :, 4, :])
    assert kw["rgb"] and kw["translate"][0] > 12
    assert (kw["metadata"]["v"], kw["metadata"]["y"]) == (1, 4)  # the pick it shows
    data, kw, _ = epi_layer_data(lf, "v", name="v", u=2, x=9)
    np.testing.assert_array_equal(data, np.swapaxes(lf[:, 2, :, 9], 0, 1))
    assert kw["translate"][1] > 16
    assert (kw["metadata"]["u"], kw["metadata"]["x"]) == (2, 9)
    with pytest.raises(ValueError):
        epi_layer_data(lf, "q", name="q")
    with pytest.raises(ValueError):
        epi_layer_data(lf, "h", name="h", v=9)


def test_windows_from_shapes_are_the_pixels_covered_both_ends_included():
    lf = np.zeros((5, 5, 16, 16), np.float32)

    def rectangle(y0, x0, y1, x1):
        return Shapes([np.array([[y0, x0], [y0, x1], [y1, x1], [y1, x0]], float)], shape_type="rectangle")

    # corners on the first and the last pixel centres: the whole 16 x 16 view
    assert windows_from_shapes(rectangle(0, 0, 15, 15), Image(lf)) == [(0, 0, 16, 16)]
    # a layer placed in the world (2 units a pixel, its first row at y = 10): world rows 14..20, columns 6..12
    # are pixel rows (14 - 10) / 2 .. (20 - 10) / 2 = 2..5 and columns 6 / 2 .. 12 / 2 = 3..6
    placed = Image(lf, scale=(1, 1, 2, 2), translate=(0, 0, 10, 0))
    assert windows_from_shapes(rectangle(14, 6, 20, 12), placed) == [(2, 3, 4, 4)]


def test_no_path_in_metadata():
    with pytest.raises(LayerError, match="holds no camera path"):
        control_points_from_layer(Image(np.zeros((2, 2, 4, 4)), name="x"))


def test_6_column_path_layer_draws_the_translation_and_keeps_the_rotation(tmp_path):
    from napari_lfdeblur._napari.reader import read_lightfield_layer
    from napari_lfdeblur._napari.writer import write_npz
    from napari_lfdeblur.path import load_path_json, shake6_path

    cp = shake6_path(1.5, seed=2, rotation=0.01)
    shape = (5, 5, 16, 16)
    shapes, kw, kind = path_layer_data(cp, shape, n_times=9, true_control_points=cp[:, :3])
    s = path_scale(shape)
    pos = bezier_positions(cp, 9)
    translation = np.stack([7.5 + s * pos[:, 1], 7.5 + s * pos[:, 0]], axis=1)
    np.testing.assert_allclose(shapes[1], translation)  # the 3-column true path: the same translation
    np.testing.assert_allclose(shapes[2], translation)
    layer = Layer.create(shapes, kw, kind)
    np.testing.assert_array_equal(control_points_from_layer(layer), cp)
    assert layer.metadata["motion"] == "6dof" and 0 < layer.metadata["max_rotation_rad"] <= 0.01
    assert "rotation" in layer.metadata["frame"]
    # the largest |r| over all three axes: a constant r_x alone is the path's largest rotation
    tilt = np.zeros((2, 6))
    tilt[:, 3] = 0.01
    assert path_layer_data(tilt, shape, n_times=4)[1]["metadata"]["max_rotation_rad"] == pytest.approx(0.01)
    # a light field's metadata keeps the 6 columns, through the writer and the reader too
    meta = lightfield_metadata(kind="blurred", control_points=cp, n_times=9)
    lf = Image(np.zeros((2, 2, 4, 4), np.float32), metadata=meta)
    np.testing.assert_array_equal(control_points_from_layer(lf), cp)
    written = write_npz(str(tmp_path / "b"), lf.data, {"name": "b", "metadata": meta})
    np.testing.assert_allclose(load_path_json(written[1]), cp)
    (_, kw_read, _), (_, path_kw, _) = read_lightfield_layer(written[0])  # the light field, and its path drawn
    np.testing.assert_allclose(kw_read["metadata"]["control_points"], cp)
    np.testing.assert_allclose(path_kw["metadata"]["control_points"], cp)
    assert path_kw["metadata"]["motion"] == "6dof" and path_kw["metadata"]["n_times"] == 9
