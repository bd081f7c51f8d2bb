"""Sample data, EPIs and path helpers against independent expectations."""

import json

import numpy as np
import pytest
from scipy import ndimage

from _reference import bezier_reference, moving_texture
from napari_lfdeblur import (
    arc_path,
    bezier_positions,
    center_path,
    horizontal_epi,
    linear_path,
    load_path_json,
    lytro_sample,
    random_path,
    save_path_json,
    shake_path,
    synthetic_scene,
    vertical_epi,
    view_shifts,
    views_transposed,
)
from napari_lfdeblur.epi import ViewOrderWarning, warn_if_transposed
from napari_lfdeblur.deconvolution import estimate_noise_sigma
from napari_lfdeblur.path import PRESETS, preset_path, shake6_path

from conftest import LYTRO_DIR


def test_synthetic_scene_is_seeded_and_in_range():
    a, da = synthetic_scene((5, 5, 32, 32), n_layers=3, color=True, seed=3)
    b, db = synthetic_scene((5, 5, 32, 32), n_layers=3, color=True, seed=3)
    c, _ = synthetic_scene((5, 5, 32, 32), n_layers=3, color=True, seed=4)
    assert a.shape == (5, 5, 32, 32, 3) and a.dtype == np.float32 and da.shape == (32, 32)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(da, db)
    assert not np.array_equal(a, c)
    assert 0 <= a.min() and a.max() <= 1


def test_synthetic_scene_disparity_is_the_view_to_view_shift():
    """Each pixel of the centre view moves by its ground-truth disparity between views, along u and along v.

    Shift view (v, u + 1) back by d along x, and view (v + 1, u) back by d
    along y, and compare with view (v, u) on the pixels of each layer away
    from occlusion edges.
    """
    # integer disparities: every view samples the layer textures on the pixel grid
    lf, disp = synthetic_scene((5, 5, 64, 64), n_layers=2, seed=1, disparity_range=(1.0, 2.0))
    c = 2
    for d in np.unique(disp):
        inner = ndimage.binary_erosion(disp == d, iterations=4)
        inner[:, :4] = inner[:, -4:] = False
        inner[:4, :] = inner[-4:, :] = False
        assert inner.sum() > 50
        # view u = c + 1 sees the point of view c at x + d, and view v = c + 1 sees it at y + d
        # (docs/model.md, Coordinates): sample them there
        for neighbour, axis in ((lf[c, c + 1], 1), (lf[c + 1, c], 0)):
            shift = np.zeros(2)
            shift[axis] = -d
            moved = ndimage.shift(neighbour, shift, order=1, mode="nearest")
            err = np.abs(moved - lf[c, c])[inner].mean()
            assert err < 0.01, (d, axis, err)
            # and a wrong disparity, or the opposite direction, does not fit within that tolerance
            for wrong_d in (d + 1.0, -d):
                shift[axis] = -wrong_d
                wrong = ndimage.shift(neighbour, shift, order=1, mode="nearest")
                assert np.abs(wrong - lf[c, c])[inner].mean() > 0.01, (d, axis, wrong_d)


def test_synthetic_scene_occlusion_front_layer_wins():
    lf, disp = synthetic_scene((3, 3, 48, 48), n_layers=2, seed=2)
    assert set(np.unique(disp)) == {0.25, 1.5}  # both layers visible, near one in front somewhere


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_synthetic_scene_disparity_map_lies_on_its_layers(seed):
    # the same seed and disparity range draw the same background layer (and render margin) with one layer or two:
    # the centre view differs only where the front layer shows, and the ground truth gives that region the front
    # layer's disparity (the range's top, 1.0) pixel for pixel, but for the antialiased rim of its edges
    two, disp = synthetic_scene((5, 5, 48, 48), n_layers=2, seed=seed, disparity_range=(-1.0, 1.0))
    back, _ = synthetic_scene((5, 5, 48, 48), n_layers=1, seed=seed, disparity_range=(-1.0, 1.0))
    front = np.abs(two[2, 2] - back[2, 2]) > 1e-6
    assert front.sum() > 50
    rim = ndimage.binary_dilation(front, iterations=4) & ~ndimage.binary_erosion(front, iterations=4)
    np.testing.assert_array_equal((disp == 1.0)[~rim], front[~rim])


def test_synthetic_scene_bad_input():
    with pytest.raises(ValueError, match="shape"):
        synthetic_scene((5, 5, 32))
    with pytest.raises(ValueError, match="n_layers"):
        synthetic_scene((5, 5, 8, 8), n_layers=0)
    with pytest.raises(TypeError, match="n_layers"):
        synthetic_scene((5, 5, 8, 8), n_layers=2.5)
    with pytest.raises(ValueError, match="shape"):
        synthetic_scene((5, 5, 8.7, 8))  # not truncated to 8
    # the farther layer first: the other way round, it would occlude the nearer one
    with pytest.raises(ValueError, match="farthest layer's disparity first"):
        synthetic_scene((3, 3, 32, 32), n_layers=2, disparity_range=(2.0, -1.0))
    with pytest.raises(ValueError, match="finite"):
        synthetic_scene((3, 3, 32, 32), disparity_range=(float("nan"), 1.0))
    with pytest.raises(ValueError, match="two numbers"):
        synthetic_scene((3, 3, 32, 32), disparity_range=(1.0,))
    with pytest.raises(ValueError, match="more than half the view"):  # before any allocation
        synthetic_scene((3, 3, 32, 32), disparity_range=(0.0, 1e4))
    with pytest.raises(ValueError, match="seed"):
        synthetic_scene((3, 3, 8, 8), seed=-1)


def test_the_shipped_sample_file_opens_as_itself():
    """File > Open of the sample's PNG (napari offers the plugin's reader): its lenslet size is stated in it."""
    from napari_lfdeblur._napari.reader import napari_get_reader
    from napari_lfdeblur.samples import _lytro

    (data, kwargs, kind), = napari_get_reader(str(_lytro._FILE))(str(_lytro._FILE))
    np.testing.assert_array_equal(data, lytro_sample())
    assert kind == "image" and kwargs["rgb"]


def test_lytro_sample_is_the_crop_of_the_capture():
    lf = lytro_sample()
    assert lf.shape == (9, 9, 128, 128, 3) and lf.dtype == np.float32
    if not LYTRO_DIR.is_dir():
        pytest.skip("shared Lytro data not present")
    import imageio.v3 as iio

    # the capture's names give the horizontal view index first (RR): file RR_CC is view (CC, RR)
    for rr, cc in [(2, 2), (6, 9), (10, 10), (9, 3)]:
        (f,) = LYTRO_DIR.glob(f"IMG_0001_*_{rr:02d}_{cc:02d}.png")
        view = iio.imread(f)[64:192, 64:192, :3] / 255.0
        np.testing.assert_allclose(lf[cc - 2, rr - 2], view, atol=1e-6)


def test_lytro_sample_views_are_laid_out_as_model_md_says():
    """u moves the image along x and v along y, both by the scene's ~0.6 px/view (data README)."""
    lf = lytro_sample()
    np.testing.assert_allclose(view_shifts(lf), [[0.6, 0.0], [0.0, 0.6]], atol=0.06)
    assert views_transposed(lf) is False


def test_view_shifts_measure_the_disparity_along_the_right_axes():
    for d in (1.5, -0.6, 0.35):
        lf = moving_texture(n_views=5, d=d)
        np.testing.assert_allclose(view_shifts(lf), [[d, 0.0], [0.0, d]], atol=0.05)
        np.testing.assert_allclose(view_shifts(lf.swapaxes(0, 1)), [[0.0, d], [d, 0.0]], atol=0.05)
        assert views_transposed(lf) is False and views_transposed(lf.swapaxes(0, 1)) is True
    colour = np.repeat(moving_texture(n_views=3, d=1.0)[..., None], 3, axis=-1)
    np.testing.assert_allclose(view_shifts(colour), [[1.0, 0.0], [0.0, 1.0]], atol=0.05)
    # a scene in focus (every view alike) cannot tell, nor can an even mix of both layouts
    flat = np.repeat(np.repeat(moving_texture(n_views=1)[:, :1], 5, axis=0), 5, axis=1)
    assert views_transposed(flat) is None
    diag = moving_texture(n_views=5, d=1.0)
    diag = diag + diag.swapaxes(0, 1)
    assert views_transposed(diag) is None


def test_views_that_are_no_shifted_copies_are_not_called_transposed(recwarn):
    # noise (or unrelated images): registration finds some shift, but the views do not match after it
    rng = np.random.default_rng(0)
    for shape in ((5, 5, 32, 40), (5, 5, 64, 64), (3, 9, 48, 32)):
        noise = rng.random(shape).astype(np.float32)
        assert views_transposed(noise) is None
        assert warn_if_transposed(noise, "noise") is not None
    assert not [w for w in recwarn if issubclass(w.category, ViewOrderWarning)]
    # the same views made shifted copies of each other are measured as before, in either layout
    lf = moving_texture(n_views=5, d=1.5)
    assert views_transposed(lf) is False and views_transposed(lf.swapaxes(0, 1)) is True


def test_view_shifts_bad_input():
    with pytest.raises(ValueError, match="4D"):
        view_shifts(np.zeros((5, 32, 32)))
    with pytest.raises(ValueError, match="at least 2 x 2 views"):
        view_shifts(np.zeros((1, 5, 32, 32)))
    with pytest.raises(ValueError, match="8 x 8 px"):
        view_shifts(np.zeros((3, 3, 4, 32)))


def test_epis_are_the_right_slices():
    lf = np.arange(3 * 4 * 5 * 6, dtype=np.float32).reshape(3, 4, 5, 6)
    h = horizontal_epi(lf, v=1, y=2)
    v = vertical_epi(lf, u=3, x=4)
    assert h.shape == (4, 6) and v.shape == (3, 5)
    for u in range(4):
        for x in range(6):
            assert h[u, x] == lf[1, u, 2, x]
    for vv in range(3):
        for y in range(5):
            assert v[vv, y] == lf[vv, 3, y, 4]
    col = np.random.default_rng(0).random((3, 4, 5, 6, 3))
    np.testing.assert_array_equal(horizontal_epi(col), col[1, :, 2, :])
    # lf[v, :, y, :] as numpy indexes it: negative indices count from the end, down to the first
    np.testing.assert_array_equal(horizontal_epi(lf, v=-3, y=-5), lf[0, :, 0, :])
    for bad in ({"v": 3}, {"v": -4}):
        with pytest.raises(ValueError, match="out of range"):
            horizontal_epi(lf, **bad)
    with pytest.raises(TypeError, match="integer"):
        vertical_epi(lf, u=1.5)


def test_bezier_positions_match_bernstein_formula():
    cp = random_path(5, extent=3.0, z_extent=1.0, seed=0)
    pos = bezier_positions(cp, 9)
    for k in range(9):
        np.testing.assert_allclose(pos[k], bezier_reference(cp, k / 8), atol=1e-12)
    np.testing.assert_allclose(pos[0], cp[0])
    np.testing.assert_allclose(pos[-1], cp[-1])
    # a torch tensor gives the same positions, one of integers too (not weights truncated to 0 or 1)
    import torch

    np.testing.assert_allclose(bezier_positions(torch.from_numpy(cp), 9).numpy(), pos, atol=1e-12)
    np.testing.assert_array_equal(bezier_positions(torch.tensor([[0, 0, 0], [2, 0, 0]]), 3).numpy(),
                                  [[0, 0, 0], [1, 0, 0], [2, 0, 0]])
    with pytest.raises(ValueError, match="NaN or Inf"):
        bezier_positions(torch.tensor([[0.0, 0, float("nan")], [2, 0, 0]]), 3)


def test_presets():
    lin = linear_path(3.0, angle_deg=90)
    np.testing.assert_allclose(lin, [[0, -1.5, 0], [0, 1.5, 0]], atol=1e-12)
    for name in PRESETS:
        cp = preset_path(name, extent=2.0, seed=1)
        np.testing.assert_allclose(bezier_positions(cp, 32).mean(axis=0)[:2], 0.0, atol=1e-9)
    np.testing.assert_allclose(center_path(arc_path() + 7.0), arc_path(), atol=1e-12)
    with pytest.raises(ValueError, match="unknown path preset"):
        preset_path("zigzag")
    # a seed is checked whether or not the preset draws from it (linear and arc do not)
    for bad in ("x", -5, 1.5):
        with pytest.raises((TypeError, ValueError), match="the path's seed must be"):
            preset_path("linear", seed=bad)


@pytest.mark.parametrize("make, message", [
    (lambda: linear_path(-1.0), "length must be a finite number >= 0; got -1.0"),
    (lambda: linear_path(2.0, angle_deg=float("nan")), "angle_deg must be a finite number"),
    (lambda: arc_path(float("inf")), "length must be a finite number >= 0"),
    (lambda: arc_path(bend="x"), "bend must be a number; got 'x'"),
    (lambda: random_path(4, extent=-2.0), "extent must be a finite number >= 0"),
    (lambda: random_path(2.5), "integer number >= 2 of control points; got 2.5"),
    (lambda: random_path(1), "integer number >= 2 of control points; got 1"),
    (lambda: shake_path(z=-0.5), "z must be a finite number >= 0"),
    (lambda: preset_path("linear", extent=float("nan")), "the path's extent must be a finite number >= 0"),
    (lambda: shake_path(seed=-1), "seed must be a whole number from 0 to 2\\*\\*63 - 1; got -1"),
])
def test_path_generators_refuse_bad_sizes(make, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        make()


def test_path_generators_keep_their_shapes_at_zero_size():
    # size 0 is allowed and means no motion; a signed z (linear_path) and bend are directions, not sizes
    assert np.all(linear_path(0.0) == 0) and np.all(random_path(3, extent=0.0) == 0)
    np.testing.assert_allclose(linear_path(2.0, z=-1.0)[:, 2], [0.5, -0.5])
    np.testing.assert_allclose(arc_path(2.0, bend=-0.5), arc_path(2.0, bend=0.5) * [1, -1, 1], atol=1e-12)


def test_elevate_degree_keeps_the_curve():
    from napari_lfdeblur.path import elevate_degree

    cp = np.array([[0.0, 0, 0], [1, 2, 0.5], [3, -1, 0]])
    up = elevate_degree(cp, 5)
    assert up.shape == (5, 3)
    np.testing.assert_allclose(bezier_positions(up, 33), bezier_positions(cp, 33), atol=1e-12)
    # the functions that may return the path unchanged return a new array, never the caller's own
    from napari_lfdeblur.path import canonical_time_direction, validate_control_points

    for same in (elevate_degree(cp, 3), canonical_time_direction(cp), validate_control_points(cp)):
        assert not np.shares_memory(same, cp)
        np.testing.assert_array_equal(same, cp)
    with pytest.raises(ValueError, match="NaN or Inf"):
        canonical_time_direction([[0.0, 0, np.nan], [1, 0, 0]])


def test_canonical_time_direction():
    from napari_lfdeblur.path import canonical_time_direction

    cp = np.array([[1.0, 0, 0], [0.2, 0.5, 0], [-1, 0.1, 0]])
    out = canonical_time_direction(cp)
    np.testing.assert_array_equal(out, cp[::-1])
    np.testing.assert_array_equal(canonical_time_direction(out), out)


def test_path_view_mismatch_speaks_exactly_when_the_blur_changes_on_other_views():
    from napari_lfdeblur import simulate_blur
    from napari_lfdeblur.path import path_in_window, path_view_mismatch, shake6_path

    frame = np.random.default_rng(3).random((3, 3, 12, 20)).astype(np.float32)
    window = (2, 5, 8, 10)

    def crop(a):
        return a[:, :, 2:10, 5:15]

    def blur(lf, cp):
        return simulate_blur(lf, cp, n_times=8)

    # in-plane (d_inf = 0): blurring a crop is cropping the blurred frame, so there is nothing to say
    in_plane = np.array([[-0.6, 0.2, 0.0], [0.7, -0.3, 0.0]])
    np.testing.assert_allclose(blur(crop(frame), in_plane), crop(blur(frame, in_plane)), atol=1e-6)
    assert path_view_mismatch(in_plane, crop(frame).shape, (12, 20)) is None
    # with p_z the same control points blur the crop otherwise; path_in_window, which the message names, is right
    with_pz = np.array([[-0.6, 0.2, 0.5], [0.7, -0.3, -0.4]])
    wanted = crop(blur(frame, with_pz))
    assert np.abs(blur(crop(frame), with_pz) - wanted).max() > 0.01
    np.testing.assert_allclose(blur(crop(frame), path_in_window(with_pz, window, (12, 20))), wanted, atol=1e-5)
    note = path_view_mismatch(with_pz, crop(frame).shape, (12, 20))
    assert "12x20" in note and "8x10" in note and "its p_z" in note and "path_in_window" in note
    # the same views, or views not stated: nothing to say
    assert path_view_mismatch(with_pz, (3, 3, 12, 20, 3), (12, 20)) is None
    assert path_view_mismatch(with_pz, (8, 10), None) is None
    # a rotation cannot be moved to other views
    cp6 = shake6_path(1.0, seed=1, rotation=0.01)
    cp6[:, 2] = 0.0
    assert "its rotation" in path_view_mismatch(cp6, (8, 10), (12, 20))
    assert "cannot be moved" in path_view_mismatch(cp6, (8, 10), (12, 20))
    # shapes that are not (Y, X): named (it failed unpacking them)
    for shape, stated in (((16,), (12, 20)), ((8, 10), (12, 20, 3))):
        with pytest.raises(ValueError, match="view_shape must be"):
            path_view_mismatch(with_pz, shape, stated)


def test_save_path_json_checks_the_view_shape(tmp_path):
    from napari_lfdeblur.path import read_path_json

    f = save_path_json(tmp_path / "p.json", linear_path(1.0), view_shape=np.array([376, 541]))
    assert read_path_json(f)[1]["view_shape"] == [376, 541]
    for bad in ([3.5, 4], [0, 4], [4], "376x541"):
        with pytest.raises(ValueError, match="view_shape .* not two whole numbers"):
            save_path_json(tmp_path / "q.json", linear_path(1.0), view_shape=bad)
    # the other fields the package reads back are checked as the readers check them
    for bad in (0, 2.5, "many"):
        with pytest.raises(ValueError, match="n_times .* not a whole number >= 2"):
            save_path_json(tmp_path / "q.json", linear_path(1.0), n_times=bad)
    with pytest.raises(ValueError, match="infinity_disparity .* not a finite number"):
        save_path_json(tmp_path / "q.json", linear_path(1.0), infinity_disparity=float("nan"))
    assert not (tmp_path / "q.json").exists()
    with pytest.raises(FileNotFoundError, match="the folder .*nodir does not exist"):
        save_path_json(tmp_path / "nodir" / "q.json", linear_path(1.0))
    assert list(tmp_path.iterdir()) == [f]  # no temporary file left


def test_elevate_degree_cannot_lower_the_degree():
    from napari_lfdeblur.path import elevate_degree

    with pytest.raises(ValueError, match="lower"):
        elevate_degree(np.zeros((4, 3)), 3)
    # checked as every path is (an (n, 2) array became 3 points; 3.5 gave 4; True was a count)
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        elevate_degree(np.zeros((2, 2)), 3)
    for bad in (3.5, True):
        with pytest.raises(TypeError, match="n_points"):
            elevate_degree(np.zeros((2, 3)), bad)


def test_path_json_round_trip_and_no_overwrite(tmp_path):
    cp = random_path(4, extent=2.0, z_extent=0.5, seed=2)
    f = save_path_json(tmp_path / "p.json", cp, n_times=16)
    np.testing.assert_array_equal(load_path_json(f), cp)
    assert json.loads(f.read_text())["n_times"] == 16
    with pytest.raises(FileExistsError):
        save_path_json(f, cp)
    save_path_json(f, cp * 2, overwrite=True)
    np.testing.assert_array_equal(load_path_json(f), cp * 2)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_path_json(tmp_path / "bad.json")
    (tmp_path / "short.json").write_text('{"control_points": [[0, 0, 0]]}')
    with pytest.raises(ValueError, match="at least 2"):
        load_path_json(tmp_path / "short.json")
    with pytest.raises(FileNotFoundError, match="missing.json does not exist"):
        load_path_json(tmp_path / "missing.json")
    with pytest.raises(FileNotFoundError, match="is a folder"):  # not 'does not exist': the folder exists
        load_path_json(tmp_path)
    # with its fields: those save_path_json stored, none for a bare list
    from napari_lfdeblur.path import read_path_json

    cp2, fields = read_path_json(save_path_json(tmp_path / "q.json", cp, n_times=16, infinity_disparity=0.5))
    np.testing.assert_array_equal(cp2, cp)
    assert fields["n_times"] == 16 and fields["infinity_disparity"] == 0.5
    (tmp_path / "bare.json").write_text(json.dumps(cp.tolist()))
    cp3, fields = read_path_json(tmp_path / "bare.json")
    np.testing.assert_array_equal(cp3, cp)
    assert fields == {}


def test_path_json_takes_numpy_values_in_its_fields(tmp_path):
    # what a script has at hand (a seed drawn by numpy, a float32 score, a small array) is written as JSON
    from napari_lfdeblur.path import read_path_json

    f = save_path_json(tmp_path / "p.json", linear_path(1.0), n_times=np.int64(16), seed=np.int64(7),
                       score=np.float32(0.25), window=np.array([4, 8]), note={"k": (np.float64(1.5), "a")})
    _, fields = read_path_json(f)
    assert fields["n_times"] == 16 and fields["seed"] == 7 and fields["score"] == 0.25
    assert fields["window"] == [4, 8] and fields["note"] == {"k": [1.5, "a"]}
    assert not [p for p in tmp_path.iterdir() if p.name != "p.json"]  # no temporary left behind


@pytest.mark.parametrize("doc, words", [
    ({"control_points": [["1", 0, 0], [0, 0, 0]]}, "control points must be numbers; got '1'"),
    ({"control_points": [[True, 0, 0], [0, 0, 0]]}, "control points must be numbers; got True"),
])
def test_a_path_files_control_points_are_json_numbers(tmp_path, doc, words):
    """The control points of a path file are JSON numbers, as save_path_json writes them: a string or a
    boolean is refused, naming the file, not taken as a number."""
    from napari_lfdeblur.path import read_path_json

    f = tmp_path / "odd.json"
    f.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="odd.json") as err:
        read_path_json(f)
    assert words in str(err.value)


@pytest.mark.parametrize("call, words", [
    (lambda lf: views_transposed(lf, "a"), "min_shift must be a number >= 0"),
    (lambda lf: views_transposed(lf, float("nan")), "min_shift must be a number >= 0"),
    (lambda lf: shake6_path(rotation=None), "rotation must be a number; got None"),
    (lambda lf: shake6_path(rotation=-0.1), "rotation must be a finite number >= 0"),
    (lambda lf: estimate_noise_sigma(np.where(lf > 0.5, np.nan, lf)), "NaN or Inf"),
    (lambda lf: estimate_noise_sigma(lf[0]), "a light field is 4D"),
])
def test_bad_arguments_of_the_helpers_are_clear_errors(call, words):
    lf = np.random.default_rng(0).random((3, 3, 8, 8))
    with pytest.raises(ValueError, match=words):
        call(lf)


def test_arc_path_is_a_chord_of_its_length_bowed_by_bend_times_it():
    from napari_lfdeblur.path import arc_path

    for length, bend, angle in ((2.0, 0.5, 0.0), (3.0, -0.2, 30.0), (1.0, 0.0, 90.0)):
        pos = bezier_positions(arc_path(length, bend, angle), 3)[:, :2]  # t = 0, 1/2, 1
        chord = pos[2] - pos[0]
        assert np.isclose(np.linalg.norm(chord), length)
        assert np.isclose(np.degrees(np.arctan2(chord[1], chord[0])), angle)
        # the curve's middle lies bend * length from the chord's middle, across it (to the left for bend > 0)
        offset = pos[1] - (pos[0] + pos[2]) / 2
        across = np.array([-chord[1], chord[0]]) / length
        np.testing.assert_allclose(offset, bend * length * across, atol=1e-12)


def test_shake6_rotations_stay_within_the_stated_largest_and_the_preset_default_is_0_005():
    for seed in range(40):
        cp = shake6_path(extent=2.0, seed=seed, rotation=0.01)
        assert np.abs(cp[:, 3:]).max() <= 0.01 + 1e-15
    # the preset's documented default rotation, 0.005 rad
    np.testing.assert_array_equal(preset_path("shake6", 2.0, 3), shake6_path(extent=2.0, seed=3, rotation=0.005))


def test_canonical_time_direction_follows_the_translation_before_the_rotation():
    from napari_lfdeblur.path import canonical_time_direction

    # the translation ends further along +x, the rotation goes the other way by more: kept as it is
    cp = np.array([[0.0, 0, 0, 0.1, 0, 0], [0.05, 0, 0, -0.1, 0, 0]])
    np.testing.assert_array_equal(canonical_time_direction(cp), cp)
    np.testing.assert_array_equal(canonical_time_direction(cp[::-1]), cp)
    # no translation between the ends: the rotation decides
    roll = np.array([[0.0, 0, 0, 0, 0, 0.05], [0.0, 0, 0, 0, 0, -0.05]])
    np.testing.assert_array_equal(canonical_time_direction(roll), roll[::-1])
