"""napari side of light-field I/O: the npe2 reader and writers.

The viewer tests need Qt; run them with ``xvfb-run -a python -m pytest``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from napari_lfdeblur.io import read_lightfield, read_lightfield_with_metadata, write_lightfield
from napari_lfdeblur._napari.writer import LayerNotSaved

LYTRO = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "lytro-f01-img0001"


@pytest.fixture
def lf_rgb():
    return np.random.default_rng(5).random((3, 4, 6, 7, 3)).astype(np.float32)


# ------------------------------------------------------------------ hook, no viewer


def test_get_reader_claims_only_light_fields(tmp_path, lf_rgb):
    import h5py
    import imageio.v3 as iio

    from napari_lfdeblur._napari.reader import napari_get_reader

    write_lightfield(tmp_path / "views", lf_rgb)
    write_lightfield(tmp_path / "lf.npz", lf_rgb)
    np.save(tmp_path / "image.npy", lf_rgb[0, 0])
    iio.imwrite(tmp_path / "photo.png", (lf_rgb[0, 0] * 255).astype(np.uint8))
    (tmp_path / "broken.h5").write_bytes(b"\x89HDF\r\n\x1a\n garbage")
    with h5py.File(tmp_path / "stack.h5", "w") as f:
        f["LF"] = lf_rgb[0, 0]  # a dataset named LF that is 3D: not a light field, left to other readers
    assert callable(napari_get_reader(str(tmp_path / "views")))
    assert callable(napari_get_reader([str(tmp_path / "lf.npz")]))
    for p in ["image.npy", "photo.png", "broken.h5", "stack.h5", "nope.npz", "empty_dir"]:
        assert napari_get_reader(str(tmp_path / p)) is None, p
    assert napari_get_reader([str(tmp_path / "lf.npz"), str(tmp_path / "views")]) is None
    assert napari_get_reader(None) is None
    assert napari_get_reader(12) is None


def test_get_reader_leaves_npy_files_whose_header_says_they_cannot_be_read(tmp_path, lf_rgb):
    from napari_lfdeblur._napari.reader import napari_get_reader

    np.save(tmp_path / "ok.npy", lf_rgb)
    assert callable(napari_get_reader(str(tmp_path / "ok.npy")))
    np.save(tmp_path / "complex.npy", lf_rgb.astype(np.complex64))
    np.save(tmp_path / "objects.npy", np.empty((2, 2, 3, 3), dtype=object), allow_pickle=True)
    np.save(tmp_path / "empty.npy", np.zeros((0, 2, 3, 3), np.float32))
    whole = (tmp_path / "ok.npy").read_bytes()
    (tmp_path / "truncated.npy").write_bytes(whole[: len(whole) - 1])
    for name in ("complex.npy", "objects.npy", "empty.npy", "truncated.npy"):
        assert napari_get_reader(str(tmp_path / name)) is None, name


@pytest.mark.parametrize("name", ["x.npy", "x.npz", "x.tif", "x.h5", "x.mat", "x.eslf.png", "x.ESLF.png", "x.json"])
def test_get_reader_never_raises_on_garbage(tmp_path, name):
    """The npe2 reader contract: the hook never raises; None for a file it cannot read."""
    from napari_lfdeblur._napari.reader import napari_get_reader

    (tmp_path / name).write_bytes(b"not a light field \x00\xff" * 7)
    assert napari_get_reader(str(tmp_path / name)) is None
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / name).write_bytes(b"")
    assert napari_get_reader(str(tmp_path / "empty")) is None
    assert napari_get_reader(str(tmp_path / "empty" / name)) is None


def test_reader_layer_tuple(tmp_path, lf_rgb):
    from napari_lfdeblur._napari.reader import napari_get_reader

    write_lightfield(tmp_path / "scene.h5", lf_rgb[..., 0])
    ((data, kw, kind),) = napari_get_reader(str(tmp_path / "scene.h5"))(str(tmp_path / "scene.h5"))
    assert kind == "image" and kw["name"] == "scene"
    assert kw["axis_labels"] == ("v", "u", "y", "x") and kw["rgb"] is False
    assert kw["metadata"]["layout"] == "h5" and kw["metadata"]["source"].endswith("scene.h5")
    np.testing.assert_array_equal(data, lf_rgb[..., 0])


def test_reader_opens_the_camera_path_a_file_holds(tmp_path, lf_rgb):
    from napari_lfdeblur._napari.reader import read_lightfield_layer
    from napari_lfdeblur.path import bezier_positions, load_path_json

    cp = np.array([[-1.0, 0.5, 0.2], [0.0, -0.5, 0.0], [1.0, 0.0, -0.2]])
    write_lightfield(tmp_path / "out.npz", lf_rgb, control_points=cp,
                     metadata={"n_times": 9, "infinity_disparity": -0.5})
    (data, kw, kind), (shapes, path_kw, path_kind) = read_lightfield_layer(tmp_path / "out.npz")
    assert kind == "image" and path_kind == "shapes" and path_kw["name"] == "out path"
    np.testing.assert_allclose(path_kw["metadata"]["control_points"], load_path_json(tmp_path / "out.path.json"))
    assert path_kw["metadata"]["n_times"] == 9 and path_kw["metadata"]["source_layer"] == "out"
    assert path_kw["metadata"]["infinity_disparity"] == -0.5  # the whole blur model goes with the path
    # the polyline is the path at the file's 9 instants, in the frame of the centre view, drawn at
    # min(Y, X) / (2 max(U, V)) = min(6, 7) / (2 * max(3, 4)) = 0.75 px a view (path_scale's documented overlay scale)
    V, U, Y, X = lf_rgb.shape[:4]
    assert (V, U, Y, X) == (3, 4, 6, 7)
    (line,) = [s for s, k in zip(shapes, path_kw["features"]["kind"]) if k == "path"]
    pos = bezier_positions(cp, 9)
    expected = np.stack([(Y - 1) / 2 + 0.75 * pos[:, 1], (X - 1) / 2 + 0.75 * pos[:, 0]], axis=1)
    np.testing.assert_allclose(line, expected, atol=1e-9)


def test_reader_draws_a_path_without_n_times_at_32_instants(tmp_path, lf_rgb):
    from napari_lfdeblur._napari.reader import read_lightfield_layer
    from napari_lfdeblur.path import bezier_positions

    cp = np.array([[-1.0, 0.5, 0.2], [0.0, -0.5, 0.0], [1.0, 0.0, -0.2]])
    write_lightfield(tmp_path / "out.npz", lf_rgb, control_points=cp)  # no n_times stated
    _, (shapes, path_kw, _) = read_lightfield_layer(tmp_path / "out.npz")
    # read_lightfield_layer's docstring: the path is sampled at the file's n_times, else 32; drawn as in
    # test_reader_opens_the_camera_path_a_file_holds (0.75 px a view about the centre of the 6 x 7 views)
    assert path_kw["metadata"]["n_times"] == 32
    (line,) = [s for s, k in zip(shapes, path_kw["features"]["kind"]) if k == "path"]
    pos = bezier_positions(cp, 32)
    np.testing.assert_allclose(line, np.stack([2.5 + 0.75 * pos[:, 1], 3.0 + 0.75 * pos[:, 0]], axis=1), atol=1e-9)


def test_reader_path_layer_keeps_the_views_its_file_states(tmp_path, lf_rgb):
    from napari_lfdeblur._napari.reader import read_lightfield_layer

    cp = [[0.0, 0.0, 0.3], [1.0, 0.0, -0.3]]
    write_lightfield(tmp_path / "a.npy", lf_rgb, control_points=cp)
    (_, kw, _), (_, path_kw, _) = read_lightfield_layer(tmp_path / "a.npy")
    assert path_kw["metadata"]["view_shape"] == list(lf_rgb.shape[2:4])
    np.save(tmp_path / "a.npy", lf_rgb[:, :, 1:])  # cropped by another program; its path file kept
    with pytest.warns(UserWarning, match="the path is for"):
        (_, kw, _), (_, path_kw, _) = read_lightfield_layer(tmp_path / "a.npy")
    # the path layer says which views the path is for, so that taking it elsewhere warns again
    assert path_kw["metadata"]["view_shape"] == list(lf_rgb.shape[2:4])
    assert path_kw["metadata"]["lightfield_shape"][2] == lf_rgb.shape[2] - 1


def test_reader_opens_the_light_field_when_its_path_is_unusable(tmp_path, lf_rgb):
    from napari_lfdeblur._napari.reader import read_lightfield_layer

    write_lightfield(tmp_path / "plain.npz", lf_rgb)
    assert [k for *_, k in read_lightfield_layer(tmp_path / "plain.npz")] == ["image"]
    np.savez(tmp_path / "odd.npz", lf=lf_rgb, control_points=np.zeros((3, 4)))  # 4 columns: no path
    with pytest.warns(UserWarning, match="odd.npz: the camera path it holds was not read"):
        ((data, kw, kind),) = read_lightfield_layer(tmp_path / "odd.npz")
    np.testing.assert_array_equal(data, lf_rgb)
    assert "control_points" not in kw["metadata"]  # not offered to the widgets as a path


@pytest.mark.parametrize("n_times", [8.9, "8", 0])
def test_reader_draws_no_path_whose_n_times_is_stated_badly(tmp_path, lf_rgb, n_times):
    """A path whose n_times is stated badly (lfdeblur refuses it) is not drawn at another number of
    instants: the light field opens alone, its metadata as the file states it."""
    from napari_lfdeblur._napari.reader import read_lightfield_layer

    np.save(tmp_path / "b.npy", lf_rgb)
    (tmp_path / "b.path.json").write_text(json.dumps({"control_points": [[0, 0, 0], [1, 0, 0]], "n_times": n_times}))
    layers = read_lightfield_layer(tmp_path / "b.npy")
    assert [k for *_, k in layers] == ["image"] and layers[0][1]["metadata"]["n_times"] == n_times
    # a file that holds its path itself, with a bad n_times, opens with no path layer either
    doc = {"control_points": [[0.0, 0, 0], [1, 0, 0]], "n_times": n_times}
    np.savez(tmp_path / "c.npz", lf=lf_rgb, lfdeblur_metadata=np.array(json.dumps(doc)))
    assert [k for *_, k in read_lightfield_layer(tmp_path / "c.npz")] == ["image"]


def test_writer_functions(tmp_path, lf_rgb):
    from napari_lfdeblur._napari.writer import write_h5, write_npz, write_tiff

    cp = [[0.0, 0.0, 0.0], [1.0, 0.5, 0.0]]
    attrs = {"name": "deblurred", "metadata": {"kind": "blind", "control_points": cp}}
    for fn, name in [(write_npz, "a"), (write_tiff, "b.tif"), (write_h5, "c.hdf5")]:
        written = fn(str(tmp_path / name), lf_rgb, attrs)
        assert Path(written[0]).exists() and Path(written[1]).name.endswith(".path.json")
        np.testing.assert_array_equal(read_lightfield(written[0]), lf_rgb)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "a.npz", "a.path.json", "b.path.json", "b.tif", "c.hdf5", "c.path.json"]
    with pytest.raises(LayerNotSaved, match="4D"):
        write_npz(str(tmp_path / "d.npz"), lf_rgb[0, 0], {"name": "img"})
    # never replaced, and the message says what a napari user can do (not the API's overwrite=True)
    with pytest.raises(FileExistsError, match=r"a\.npz exists; napari-lfdeblur never replaces a file: save under a "
                                              "new name") as caught:
        write_npz(str(tmp_path / "a.npz"), lf_rgb, {"name": "again"})
    assert "overwrite=" not in str(caught.value)


def test_writer_saves_a_layer_with_a_path_in_a_second_format(tmp_path, lf_rgb):
    lf_gray = lf_rgb[..., 0]
    # a.npz and a.tif would share a.path.json: the second keeps its path in itself, a.npz keeps its file
    from napari_lfdeblur._napari.writer import write_npz, write_tiff

    cp = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.0]])
    attrs = {"name": "blur", "metadata": {"control_points": cp.tolist(), "n_times": 8}}
    assert [Path(p).name for p in write_npz(str(tmp_path / "a"), lf_gray, attrs)] == ["a.npz", "a.path.json"]
    before = (tmp_path / "a.path.json").read_text()
    with pytest.warns(UserWarning, match="a.path.json belongs to a.npz and was left as it is; the camera path of "
                                         "a.tif is stored in the file itself"):
        assert [Path(p).name for p in write_tiff(str(tmp_path / "a"), lf_gray, attrs)] == ["a.tif"]
    assert (tmp_path / "a.path.json").read_text() == before
    for name in ("a.npz", "a.tif"):
        meta = read_lightfield_with_metadata(tmp_path / name)[1]
        np.testing.assert_allclose(meta["control_points"], cp)
        assert meta["n_times"] == 8
    # a format that cannot hold the path itself still refuses to take another file's path file
    with pytest.raises(FileExistsError, match="a.path.json exists"):
        write_lightfield(tmp_path / "a.npy", lf_gray, control_points=cp)
    assert not (tmp_path / "a.npy").exists()


# ------------------------------------------------------------------ viewer


def test_viewer_open_folder(make_napari_viewer, tmp_path, lf_rgb):
    folder = write_lightfield(tmp_path / "capture", lf_rgb, bit_depth=16)
    viewer = make_napari_viewer()
    layers = viewer.open(str(folder), plugin="napari-lfdeblur")
    assert len(layers) == 1 and len(viewer.layers) == 1
    layer = viewer.layers[0]
    assert layer.data.shape == lf_rgb.shape and layer.rgb
    assert tuple(layer.axis_labels) == ("v", "u", "y", "x")
    assert layer.metadata["layout"] == "views"
    np.testing.assert_allclose(layer.data, lf_rgb, atol=0.5 / 65535 + 1e-7)
    # the two view axes are the sliders
    assert viewer.dims.ndim == 4 and tuple(viewer.dims.axis_labels) == ("v", "u", "y", "x")


def test_viewer_open_draws_the_path_the_file_holds(make_napari_viewer, tmp_path, lf_rgb):
    cp = [[-1.0, 0.0, 0.0], [1.0, 0.5, 0.0]]
    write_lightfield(tmp_path / "blurred.tif", lf_rgb, control_points=cp)
    viewer = make_napari_viewer()
    viewer.open(str(tmp_path / "blurred.tif"), plugin="napari-lfdeblur")
    assert [layer.name for layer in viewer.layers] == ["blurred", "blurred path"]
    assert viewer.layers["blurred path"].metadata["control_points"] == cp
    assert viewer.layers["blurred"].metadata["control_points"] == cp  # where the widgets take it from


def test_viewer_open_real_lytro(make_napari_viewer):
    if not LYTRO.is_dir():
        pytest.skip(f"real data not found at {LYTRO}")
    from napari_lfdeblur.io import ViewOrderWarning

    viewer = make_napari_viewer()
    with pytest.warns(ViewOrderWarning, match="look transposed"):  # its names give the horizontal view first
        viewer.open(str(LYTRO), plugin="napari-lfdeblur")
    (layer,) = viewer.layers
    assert layer.data.shape == (10, 10, 256, 256, 3) and layer.rgb
    np.testing.assert_allclose(layer.metadata["view_shifts"], [[0.0, 0.64], [0.64, 0.0]], atol=0.05)
    assert tuple(layer.axis_labels) == ("v", "u", "y", "x")


def test_path_writer(tmp_path):
    from napari_lfdeblur._napari.layers import path_layer_data
    from napari_lfdeblur._napari.writer import write_path_json
    from napari_lfdeblur.path import read_path_json, shake6_path

    cp = shake6_path(1.0, seed=2, rotation=0.01)
    shapes, kw, _ = path_layer_data(cp, (5, 5, 16, 16), n_times=12, infinity_disparity=1.5, name="p")
    (written,) = write_path_json(str(tmp_path / "p"), shapes, kw)
    assert Path(written).name == "p.json"
    back, fields = read_path_json(written)
    np.testing.assert_allclose(back, cp, rtol=0, atol=0)
    assert (fields["n_times"], fields["infinity_disparity"]) == (12, 1.5)
    with pytest.raises(FileExistsError, match="never replaces a file: save under a new name"):
        write_path_json(written, shapes, kw)
    with pytest.raises(LayerNotSaved, match="'rect' holds no camera path"):
        write_path_json(str(tmp_path / "r.json"), [np.zeros((4, 2))], {"name": "rect", "metadata": {}})
    with pytest.raises(LayerNotSaved, match="'odd': control points must be"):
        write_path_json(str(tmp_path / "o.json"), [], {"name": "odd", "metadata": {"control_points": [[0, 1]] * 3}})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.json"]


def test_viewer_saves_a_path_layer_as_json(make_napari_viewer, tmp_path):
    from napari_lfdeblur._napari.layers import add_layer, path_layer_data
    from napari_lfdeblur.path import arc_path, read_path_json

    viewer = make_napari_viewer()
    cp = arc_path(length=2.0, bend=0.3)
    layer = add_layer(viewer, path_layer_data(cp, (5, 5, 16, 16), n_times=8, infinity_disparity=0.5, name="est"))
    viewer.layers.selection = {layer}
    viewer.layers.save(str(tmp_path / "est.json"), plugin="napari-lfdeblur")
    back, fields = read_path_json(tmp_path / "est.json")
    np.testing.assert_allclose(back, cp)
    assert (fields["n_times"], fields["infinity_disparity"], fields["view_shape"]) == (8, 0.5, [16, 16])


def test_viewer_save_layer_with_plugin_writer(make_napari_viewer, tmp_path, lf_rgb):
    viewer = make_napari_viewer()
    viewer.add_image(lf_rgb[..., 1], name="lf", metadata={"kind": "input"})
    out = tmp_path / "saved.npz"
    viewer.layers.save(str(out), selected=False, plugin="napari-lfdeblur")
    np.testing.assert_array_equal(read_lightfield(out), lf_rgb[..., 1])
    viewer.layers.save(str(tmp_path / "saved.tif"), plugin="napari-lfdeblur")
    np.testing.assert_array_equal(read_lightfield(tmp_path / "saved.tif"), lf_rgb[..., 1])
    # a layer the writer cannot take: napari shows the writer's reason (a ValueError it read as "not a
    # valid writer" and dropped)
    viewer.layers.clear()
    viewer.add_image(np.zeros((4, 8, 8), np.float32), name="stack")
    with pytest.raises(LayerNotSaved, match="'stack' has shape \\(4, 8, 8\\); only 4D"):
        viewer.layers.save(str(tmp_path / "stack.npz"), plugin="napari-lfdeblur")
    assert not (tmp_path / "stack.npz").exists()
