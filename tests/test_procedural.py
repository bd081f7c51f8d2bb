"""Tests of procedural_scene: seeded natural-texture scenes with physical disparities."""

import numpy as np
import pytest
from scipy import ndimage

from napari_lfdeblur import procedural_scene, view_shifts


def test_shape_dtype_range_and_determinism():
    lf, disp = procedural_scene((5, 5, 40, 48), seed=7, infinity_disparity=0.5)
    assert lf.shape == (5, 5, 40, 48, 3) and lf.dtype == np.float32
    assert disp.shape == (40, 48) and disp.dtype == np.float32
    assert 0.0 <= lf.min() and lf.max() <= 1.0 and np.isfinite(lf).all()
    lf2, disp2 = procedural_scene((5, 5, 40, 48), seed=7, infinity_disparity=0.5)
    np.testing.assert_array_equal(lf, lf2)
    np.testing.assert_array_equal(disp, disp2)
    grey, disp3 = procedural_scene((5, 5, 40, 48), seed=7, infinity_disparity=0.5, color=False)
    assert grey.shape == (5, 5, 40, 48) and grey.dtype == np.float32
    np.testing.assert_array_equal(disp, disp3)


def test_grey_scene_is_the_luminance_of_the_colour_scene():
    # color=False gives luminance (docstring) of the same draws as the colour scene: the Rec. 709 (sRGB) relative
    # luminance 0.2126 R + 0.7152 G + 0.0722 B of every colour view
    for seed in (0, 1, 2):
        colour, _ = procedural_scene((3, 3, 24, 24), seed=seed)
        grey, _ = procedural_scene((3, 3, 24, 24), seed=seed, color=False)
        np.testing.assert_allclose(grey, colour.astype(np.float64) @ [0.2126, 0.7152, 0.0722], atol=1e-5)


@pytest.mark.parametrize("d_inf", [0.0, -1.0, 2.0])
def test_disparities_are_nearer_than_infinity(d_inf):
    for seed in range(6):
        _, disp = procedural_scene((3, 3, 32, 32), seed=seed, infinity_disparity=d_inf)
        delta = disp - d_inf
        assert delta.min() > 0 and delta.max() <= 1.5 + 1e-6
        # the same scene, only moved in depth: the deltas do not depend on d_inf
        _, disp0 = procedural_scene((3, 3, 32, 32), seed=seed, infinity_disparity=0.0)
        np.testing.assert_allclose(delta, disp0, atol=1e-6)


def test_seeds_give_different_scenes_with_depth_and_occlusion():
    scenes = [procedural_scene((3, 3, 48, 48), seed=s) for s in range(12)]
    views = np.stack([lf[1, 1] for lf, _ in scenes]).reshape(12, -1)
    corr = np.corrcoef(views)
    assert np.abs(corr[np.triu_indices(12, 1)]).max() < 0.95
    n_planes = [len(np.unique(d)) for _, d in scenes]
    assert min(n_planes) >= 2 and max(n_planes) >= 4  # the nearer planes occlude the background
    means = [lf.mean() for lf, _ in scenes]
    assert max(means) - min(means) > 0.1  # bright and dark scenes


def test_default_scenes_have_3_to_6_planes_and_a_fine_texture(monkeypatch):
    from napari_lfdeblur.samples import _procedural

    # docstring: by default 3 to 6 planes, background included, drawn from the seed; at least one plane carries a
    # fine texture (FINE_TEXTURES). Record the plane count and the texture names each scene draws.
    counts, names = [], []
    deltas, texture = _procedural._deltas, _procedural._texture
    monkeypatch.setattr(_procedural, "_deltas", lambda rng, n: counts.append(n) or deltas(rng, n))

    def recording_texture(rng, name, *args):
        names[-1].append(name)
        return texture(rng, name, *args)

    monkeypatch.setattr(_procedural, "_texture", recording_texture)
    for seed in range(30):
        names.append([])
        procedural_scene((3, 3, 16, 16), seed=seed)
        assert any(name in _procedural.FINE_TEXTURES for name in names[-1]), (seed, names[-1])
    assert len(counts) == 30 and set(counts) == {3, 4, 5, 6}
    assert [len(n) for n in names] == counts  # one texture per plane


def test_single_plane_moves_by_its_disparity():
    for seed, d_inf in ((1, 0.0), (2, -1.0), (3, 1.0)):
        lf, disp = procedural_scene((5, 5, 64, 64), seed=seed, infinity_disparity=d_inf, n_layers=1)
        assert np.ptp(disp) == 0
        shifts = view_shifts(lf)
        np.testing.assert_allclose(shifts, [[disp[0, 0], 0], [0, disp[0, 0]]], atol=0.03)


def _warp_error(lf, disp, d_offset, region):
    """Mean |neighbour view sampled at x + d - centre view| over ``region``, disparities moved by d_offset."""
    c = lf.shape[0] // 2
    centre, right = lf[c, c].mean(-1), lf[c, c + 1].mean(-1)
    yy, xx = np.mgrid[0 : disp.shape[0], 0 : disp.shape[1]].astype(float)
    warped = ndimage.map_coordinates(right, [yy, xx + disp + d_offset], order=3, mode="nearest")
    return float(np.abs(warped - centre)[region].mean())


@pytest.mark.parametrize("seed,d_inf", [(4, 0.0), (5, -0.5), (6, 2.0)])
def test_light_field_matches_its_disparity_map(seed, d_inf):
    lf, disp = procedural_scene((5, 5, 96, 96), seed=seed, infinity_disparity=d_inf)
    # away from depth edges (where occlusion changes what is seen) and from the borders
    edges = ndimage.maximum_filter(disp, size=3) != ndimage.minimum_filter(disp, size=3)
    region = ~ndimage.binary_dilation(edges, iterations=4)
    region[:6], region[-6:], region[:, :6], region[:, -6:] = False, False, False, False
    assert region.mean() > 0.3
    err = _warp_error(lf, disp, 0.0, region)
    # a pixel of the centre view at disparity d is the pixel at x + d of the next view along u;
    # a disparity map off by half a pixel explains the views far worse
    assert err < 0.01
    assert err < 0.4 * min(_warp_error(lf, disp, +0.5, region), _warp_error(lf, disp, -0.5, region))


def test_bad_arguments():
    with pytest.raises(ValueError, match="shape"):
        procedural_scene((5, 5, 32), seed=0)
    with pytest.raises(ValueError, match="infinity_disparity"):
        procedural_scene((3, 3, 16, 16), seed=0, infinity_disparity=float("nan"))
    with pytest.raises(ValueError, match="n_layers"):
        procedural_scene((3, 3, 16, 16), seed=0, n_layers=0)
    with pytest.raises(TypeError, match="seed"):
        procedural_scene((3, 3, 16, 16), seed=1.5)
    with pytest.raises(TypeError):
        procedural_scene((3, 3, 16, 16))  # the seed is required
    with pytest.raises(ValueError, match="seed must be a whole number from 0"):
        procedural_scene((3, 3, 16, 16), seed=-1)
    with pytest.raises(ValueError, match="infinity_disparity = 1e\\+06 px/view is beyond"):  # before any allocation
        procedural_scene((3, 3, 16, 16), seed=0, infinity_disparity=1e6)
    with pytest.raises(ValueError, match="shape"):
        procedural_scene((3, 3, 16.5, 16), seed=0)
    from napari_lfdeblur.samples import synthetic_scene

    for make in (procedural_scene, synthetic_scene):  # a string is not a colour flag ('no' would be true)
        with pytest.raises(TypeError, match="color must be True or False; got 'no'"):
            make((3, 3, 16, 16), seed=0, color="no")
    a, _ = procedural_scene(np.array([3, 3, 8, 8]), seed=0)  # a numpy shape, as a tuple would be
    np.testing.assert_array_equal(a, procedural_scene((3, 3, 8, 8), seed=0)[0])


def test_texture_images_are_read_once(monkeypatch):
    from skimage import data

    from napari_lfdeblur.samples import _procedural

    _procedural._image.cache_clear()
    reads = []
    for name in set(_procedural.TEXTURE_IMAGES) | set(_procedural.FINE_TEXTURES):
        original = getattr(data, name)
        monkeypatch.setattr(data, name, lambda original=original, name=name: reads.append(name) or original())
    procedural_scene((3, 3, 16, 16), seed=0)
    first = list(reads)
    assert first and len(first) == len(set(first))  # each image it used, once
    for seed in (0, 1, 2):
        procedural_scene((3, 3, 16, 16), seed=seed)
    assert len(reads) == len(set(reads))  # none read again
