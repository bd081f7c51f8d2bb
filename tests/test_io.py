"""Tests of light-field reading and writing (napari_lfdeblur.io).

Every reader test builds its file with an independent tool (imageio, tifffile,
h5py, scipy.io, numpy) from a known light field and checks what comes back;
every writer test reads its output back (and, where it can, with an
independent tool too). Each bad-input case of issue 3 has its own test.
"""

from __future__ import annotations

import json
import re
import warnings
import struct
import zlib
from pathlib import Path

import h5py
import imageio.v3 as iio
import numpy as np
import pytest
import scipy.io
import tifffile

from _reference import moving_texture
from napari_lfdeblur.io import (
    InsufficientMemoryError,
    LightFieldError,
    LightFieldFormatError,
    LightFieldReadError,
    ViewOrderWarning,
    detect_layout,
    path_json_beside,
    probe_layout,
    read_lightfield,
    read_lightfield_with_metadata,
    write_lightfield,
)
from napari_lfdeblur.io import _png, _views
from napari_lfdeblur.path import arc_path, linear_path, load_path_json, save_path_json

LYTRO = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "lytro-f01-img0001"

V, U, Y, X = 3, 4, 6, 7


@pytest.fixture
def lf_rgb():
    return np.random.default_rng(1).random((V, U, Y, X, 3)).astype(np.float32)


@pytest.fixture
def lf_gray():
    return np.random.default_rng(2).random((V, U, Y, X)).astype(np.float32)


def _u8(lf):
    return np.rint(lf * 255).astype(np.uint8)


def _u16(lf):
    return np.rint(lf * 65535).astype(np.uint16)


def _write_views(folder, img_lf, name, exts=".png"):
    """Write each view of an integer light field with imageio under name(r, c)."""
    folder.mkdir(exist_ok=True)
    for r in range(img_lf.shape[0]):
        for c in range(img_lf.shape[1]):
            iio.imwrite(folder / (name(r, c) + exts), img_lf[r, c])
    return folder


def _lytro_views(folder, lf8):
    """Lytro-toolbox names IMG_0007_KKK_RR_CC.png, KKK a serpentine sequence."""
    Vn, Un = lf8.shape[:2]

    def name(r, c):
        k = r * Un + (c if r % 2 == 0 else Un - 1 - c) + 1
        return f"IMG_0007_{k:03d}_{r + 1:02d}_{c + 1:02d}"

    return _write_views(folder, lf8, name)


# ------------------------------------------------------------------ real data


@pytest.fixture(scope="module")
def lytro():
    if not LYTRO.is_dir():
        pytest.skip(f"real data not found at {LYTRO}")
    # the capture's names number the views the other way round (RR is the horizontal one)
    with pytest.warns(ViewOrderWarning, match="look transposed.*pattern="):
        return read_lightfield_with_metadata(LYTRO)


def test_real_lytro_folder(lytro):
    lf, meta = lytro
    assert lf.shape == (10, 10, 256, 256, 3)
    assert lf.dtype == np.float32
    assert meta["layout"] == "views" and meta["file_dtype"] == "uint8"
    assert detect_layout(LYTRO) == "views"
    # view (RR, CC) of file IMG_0001_KKK_RR_CC.png is lf[RR-1, CC-1]
    for rr, cc in [(1, 1), (3, 4), (10, 1), (7, 9), (10, 10)]:
        (f,) = LYTRO.glob(f"IMG_0001_*_{rr:02d}_{cc:02d}.png")
        ref = iio.imread(f).astype(np.float32) / 255
        np.testing.assert_allclose(lf[rr - 1, cc - 1], ref, atol=1e-6)
    assert 0.0 <= lf.min() and lf.max() <= 1.0
    # the whole scene moves about 0.6 px/view (data README), across the axes: u moves y, v moves x
    np.testing.assert_allclose(meta["view_shifts"], [[0.0, 0.64], [0.64, 0.0]], atol=0.05)


def test_real_lytro_folder_read_the_right_way_round(lytro, recwarn):
    lf, _ = lytro
    fixed, meta = read_lightfield_with_metadata(LYTRO, pattern=r"_(?P<col>\d+)_(?P<row>\d+)\.\w+$")
    assert not [w for w in recwarn if issubclass(w.category, ViewOrderWarning)]
    np.testing.assert_array_equal(fixed, lf.swapaxes(0, 1))
    np.testing.assert_allclose(meta["view_shifts"], [[0.64, 0.0], [0.0, 0.64]], atol=0.05)


def test_transposed_views_warn_on_read_and_upright_ones_do_not(tmp_path, recwarn):
    lf = moving_texture()
    np.save(tmp_path / "upright.npy", lf)
    np.save(tmp_path / "transposed.npy", lf.swapaxes(0, 1))
    back, meta = read_lightfield_with_metadata(tmp_path / "upright.npy")
    assert not [w for w in recwarn if issubclass(w.category, ViewOrderWarning)]
    np.testing.assert_allclose(meta["view_shifts"], [[1.5, 0.0], [0.0, 1.5]], atol=0.05)
    with pytest.warns(ViewOrderWarning, match=r"transposed.*swapaxes\(0, 1\)") as rec:
        back, _ = read_lightfield_with_metadata(tmp_path / "transposed.npy")
    assert "pattern=" not in str(rec[0].message)  # only folders of views have names to reinterpret
    np.testing.assert_array_equal(back, lf.swapaxes(0, 1))  # warned about, never changed


def test_reading_views_in_threads_leaves_the_warning_filters_alone(tmp_path):
    """Decoding views in threads once left a process-wide 'ignore all warnings' filter behind."""

    folder = _lytro_views(tmp_path / "cap", _u8(np.random.default_rng(3).random((6, 6, 40, 40, 3))))
    before = list(warnings.filters)
    for _ in range(3):
        read_lightfield(folder, workers=6)
    assert warnings.filters == before
    with pytest.warns(UserWarning, match="still heard"):
        warnings.warn("still heard", UserWarning)


# ------------------------------------------------------------------ folder layouts


def test_views_lytro_names_rgb8(tmp_path, lf_rgb):
    lf8 = _u8(lf_rgb)
    folder = _lytro_views(tmp_path / "cap", lf8)
    (folder / "notes.txt").write_text("not a view")
    out, meta = read_lightfield_with_metadata(folder)
    assert meta["layout"] == "views" and meta["index_base"] == 1
    np.testing.assert_array_equal(out, lf8.astype(np.float32) / 255)


def test_views_gray16_zero_based(tmp_path, lf_gray):
    lf16 = _u16(lf_gray)
    folder = _write_views(tmp_path / "g", lf16, lambda r, c: f"sub_{r}_{c}")
    out = read_lightfield(folder)
    assert out.shape == (V, U, Y, X)
    np.testing.assert_allclose(out, lf16 / 65535, atol=1e-7)
    # index_base=1 on names that start at 0: the views of index 0 are refused, not dropped
    with pytest.raises(LightFieldFormatError, match="below the index base; pass index_base=0"):
        read_lightfield(folder, index_base=1)


def test_views_tiff16(tmp_path, lf_rgb):
    lf16 = _u16(lf_rgb)
    folder = tmp_path / "t"
    folder.mkdir()
    for r in range(V):
        for c in range(U):
            tifffile.imwrite(folder / f"view_{r + 1:02d}_{c + 1:02d}.tif", lf16[r, c], photometric="rgb")
    np.testing.assert_allclose(read_lightfield(folder), lf16 / 65535, atol=1e-7)


def test_views_jpeg(tmp_path, lf_rgb):
    folder = _write_views(tmp_path / "j", _u8(lf_rgb), lambda r, c: f"v_{r + 1}_{c + 1}", ".jpg")
    out = read_lightfield(folder)
    ref = iio.imread(folder / "v_2_3.jpg").astype(np.float32) / 255
    np.testing.assert_allclose(out[1, 2], ref, atol=1e-6)


def test_views_jpeg_cmyk(tmp_path, lf_rgb):
    """CMYK JPEG views are read as RGB (Pillow's conversion), not as RGBA of their ink amounts."""
    from PIL import Image

    folder = tmp_path / "cmyk"
    folder.mkdir()
    lf8 = _u8(lf_rgb)
    for r in range(V):
        for c in range(U):
            Image.fromarray(lf8[r, c]).convert("CMYK").save(folder / f"v_{r + 1}_{c + 1}.jpg", quality=95)
    out = read_lightfield(folder)
    assert out.shape == lf8.shape
    with Image.open(folder / "v_2_3.jpg") as im:
        assert im.mode == "CMYK"
        ref = np.asarray(im.convert("RGB")).astype(np.float32) / 255
    np.testing.assert_allclose(out[1, 2], ref, atol=1e-6)
    # the colours are the views' own, up to JPEG's loss (the ink amounts read as RGB are far off)
    assert np.abs(out - lf8 / 255).mean() < 0.05


def _hci_views(folder, lf8):
    """Write the views of ``lf8`` (V, U, Y, X, C) as HCI's input_CamNNN.png, row-major."""
    folder.mkdir()
    V, U = lf8.shape[:2]
    for k in range(V * U):
        iio.imwrite(folder / f"input_Cam{k:03d}.png", lf8[k // U, k % U])
    return folder


def test_views_hci(tmp_path, lf_rgb):
    lf8 = _u8(lf_rgb[:3, :3])
    folder = _hci_views(tmp_path / "boxes", lf8)
    iio.imwrite(folder / "valid_mask.png", lf8[0, 0, :, :, 0])  # an extra image that is not a view
    (folder / "parameters.cfg").write_text(
        "[intrinsics]\nfocal_length_mm = 100\nsensor_size_mm = 35\n\n"
        "[extrinsics]\nnum_cams_x = 3\nbaseline_mm = 90.0\n\n[meta]\ndisp_min = -1.5\nscene = boxes\n"
    )
    out, meta = read_lightfield_with_metadata(folder)
    assert meta["layout"] == "hci"
    np.testing.assert_array_equal(out, lf8 / np.float32(255))
    cam = meta["camera"]
    assert cam["intrinsics"]["focal_length_mm"] == 100
    assert cam["extrinsics"]["baseline_mm"] == 90.0
    assert cam["meta"]["disp_min"] == -1.5 and cam["meta"]["scene"] == "boxes"


def test_views_hci_non_square_grid(tmp_path, lf_rgb):
    # docs/io.md: input_CamNNN views are row-major; grid=(V, U) for a grid that is not square
    lf8 = _u8(lf_rgb[:2, :3])
    folder = _hci_views(tmp_path / "wide", lf8)
    np.testing.assert_array_equal(read_lightfield(folder, grid=(2, 3)), lf8 / np.float32(255))


def test_views_stanford(tmp_path, lf_rgb):
    lf8 = _u8(lf_rgb)
    folder = _write_views(
        tmp_path / "lego", lf8, lambda r, c: f"out_{r:02d}_{c:02d}_{-10.5 * r:.6f}_{3.25 * c:.6f}_"
    )
    out, meta = read_lightfield_with_metadata(folder)
    assert meta["layout"] == "stanford"
    np.testing.assert_array_equal(out, lf8 / np.float32(255))
    assert meta["camera"]["positions"][2][3] == [-21.0, 9.75]


def test_views_pattern_option(tmp_path, lf_gray):
    lf8 = _u8(lf_gray)
    folder = _write_views(tmp_path / "p", lf8, lambda r, c: f"r{r + 1}c{c + 1}")
    with pytest.raises(LightFieldFormatError):
        read_lightfield(folder)  # no recognised naming scheme
    out = read_lightfield(folder, layout="views", pattern=r"r(?P<row>\d+)c(?P<col>\d+)")
    np.testing.assert_array_equal(out, lf8 / np.float32(255))
    # unnamed groups: the first is the row, the second the column (3 x 4 views, so a swap cannot pass)
    out = read_lightfield(folder, layout="views", pattern=r"r(\d+)c(\d+)")
    np.testing.assert_array_equal(out, lf8 / np.float32(255))


# ------------------------------------------------------------------ single-image layouts


def test_eslf_default_14(tmp_path):
    A, Yl, Xl = 14, 3, 4
    lf8 = np.random.default_rng(3).integers(0, 256, (A, A, Yl, Xl, 3), dtype=np.uint8)
    mosaic = np.zeros((Yl * A, Xl * A, 3), np.uint8)
    for v in range(A):
        for u in range(A):
            for y in range(Yl):
                for x in range(Xl):
                    mosaic[y * A + v, x * A + u] = lf8[v, u, y, x]
    p = tmp_path / "scene.eslf.png"
    iio.imwrite(p, mosaic)
    assert detect_layout(p) == "eslf"
    out, meta = read_lightfield_with_metadata(p)
    assert meta["angular_size"] == 14
    np.testing.assert_array_equal(out, lf8 / np.float32(255))
    crop = read_lightfield(p, angular_crop=8)
    np.testing.assert_array_equal(crop, lf8[3:11, 3:11] / np.float32(255))


def test_eslf_angular_size_option_and_ambiguity(tmp_path, lf_gray):
    A = 5
    lf8 = _u8(np.random.default_rng(4).random((A, A, 8, 6)))
    mosaic = lf8.transpose(2, 0, 3, 1).reshape(8 * A, 6 * A)  # (y, v, x, u)
    p = tmp_path / "small.png"
    iio.imwrite(p, mosaic)
    out = read_lightfield(p, layout="eslf", angular_size=5)
    np.testing.assert_array_equal(out, lf8 / np.float32(255))
    with pytest.raises(LightFieldFormatError, match="angular_size"):
        read_lightfield(p, layout="eslf")  # 40x30: sizes 2, 5 and 10 all divide it


def test_view_grid_mosaic(tmp_path, lf_rgb):
    lf8 = _u8(lf_rgb)
    mosaic = np.zeros((V * Y, U * X, 3), np.uint8)
    for v in range(V):
        for u in range(U):
            mosaic[v * Y : (v + 1) * Y, u * X : (u + 1) * X] = lf8[v, u]
    p = tmp_path / "grid.png"
    iio.imwrite(p, mosaic)
    with pytest.raises(LightFieldFormatError, match="mosaic"):
        read_lightfield(p)  # a plain image needs layout=
    out = read_lightfield(p, layout="mosaic", grid=(V, U))
    np.testing.assert_array_equal(out, lf8 / np.float32(255))
    with pytest.raises(LightFieldFormatError, match="grid"):
        read_lightfield(p, layout="mosaic")
    with pytest.raises(LightFieldFormatError, match="does not split"):
        read_lightfield(p, layout="mosaic", grid=(4, 4))


# ------------------------------------------------------------------ MATLAB


def test_mat_v5_drops_weight(tmp_path, lf_rgb):
    lf16 = _u16(lf_rgb)
    weight = np.full(lf16.shape[:4] + (1,), 65535, np.uint16)
    p = tmp_path / "IMG_0001__Decoded.mat"
    scipy.io.savemat(p, {"LF": np.concatenate([lf16, weight], axis=-1), "LensletGridModel": {"HSpacing": 14.2}})
    out, meta = read_lightfield_with_metadata(p)
    assert meta["layout"] == "mat" and meta["mat_version"] == "5" and meta["dropped_weight_channel"]
    assert out.shape == (V, U, Y, X, 3)
    np.testing.assert_allclose(out, lf16 / 65535, atol=1e-7)
    assert meta["camera"]["LensletGridModel"]["HSpacing"] == pytest.approx(14.2)
    # a gray light field with its weight: the gray channel is kept, the weight (last) dropped
    gray16 = lf16[..., 1]
    scipy.io.savemat(tmp_path / "gray.mat", {"LF": np.stack([gray16, np.full_like(gray16, 65535)], axis=-1)})
    out, meta = read_lightfield_with_metadata(tmp_path / "gray.mat")
    assert meta["dropped_weight_channel"] and out.shape == (V, U, Y, X)
    np.testing.assert_allclose(out, gray16 / 65535, atol=1e-7)


def test_mat_v73_axes_reversed(tmp_path, lf_rgb):
    lf_w = np.concatenate([lf_rgb, np.ones(lf_rgb.shape[:4] + (1,), np.float32)], axis=-1)
    p = tmp_path / "decoded_v73.mat"
    with h5py.File(p, "w", userblock_size=512) as f:
        f.create_dataset("LF", data=lf_w.T)  # MATLAB v7.3 stores (c, k, l, i, j)
    with open(p, "r+b") as fh:  # MATLAB's text header lives in the user block
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 06:00:00 2026 HDF5 schema 1.00 .")
    out, meta = read_lightfield_with_metadata(p)
    assert meta["mat_version"] == "7.3"
    np.testing.assert_array_equal(out, lf_rgb)


# ------------------------------------------------------------------ arrays


def test_hdf5_default_and_axes_attribute(tmp_path, lf_rgb):
    p = tmp_path / "a.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("LF", data=lf_rgb)
        f.attrs["focal_length_mm"] = 6.45
    out, meta = read_lightfield_with_metadata(p)
    np.testing.assert_array_equal(out, lf_rgb)
    assert meta["camera"]["focal_length_mm"] == pytest.approx(6.45)

    q = tmp_path / "b.hdf5"
    with h5py.File(q, "w") as f:
        f.create_dataset("meta/centre", data=np.zeros((Y, X)))
        ds = f.create_dataset("scene/radiance", data=_u8(lf_rgb).transpose(3, 2, 4, 1, 0))  # x, y, c, u, v
        ds.attrs["axes"] = "xycuv"
    np.testing.assert_array_equal(read_lightfield(q), _u8(lf_rgb) / np.float32(255))
    # the option overrides the attribute
    with pytest.raises(LightFieldFormatError, match="axes"):
        read_lightfield(q, axes="vuyx")


def test_npy_npz_tiff_arrays(tmp_path, lf_rgb, lf_gray):
    np.save(tmp_path / "a.npy", lf_gray)
    np.testing.assert_array_equal(read_lightfield(tmp_path / "a.npy"), lf_gray)
    np.savez(tmp_path / "b.npz", lf=lf_rgb, disparity=np.zeros((Y, X)))
    np.testing.assert_array_equal(read_lightfield(tmp_path / "b.npz"), lf_rgb)
    np.savez(tmp_path / "c.npz", something=_u16(lf_gray))
    np.testing.assert_allclose(read_lightfield(tmp_path / "c.npz"), _u16(lf_gray) / 65535, atol=1e-7)
    tifffile.imwrite(tmp_path / "d.tif", _u16(lf_gray))
    np.testing.assert_allclose(read_lightfield(tmp_path / "d.tif"), _u16(lf_gray) / 65535, atol=1e-7)
    np.save(tmp_path / "e.npy", lf_rgb * 255)
    np.testing.assert_allclose(read_lightfield(tmp_path / "e.npy", value_range=(0, 255)), lf_rgb, atol=1e-6)
    # docs/io.md: an .npz's light field is the array `lf`, also beside another 4D array
    np.savez(tmp_path / "f.npz", blurred=lf_gray * 0.5, lf=lf_gray)
    np.testing.assert_array_equal(read_lightfield(tmp_path / "f.npz"), lf_gray)


def test_detect_and_probe(tmp_path, lf_gray):
    np.save(tmp_path / "lf.npy", lf_gray)
    np.save(tmp_path / "img.npy", lf_gray[0, 0])
    iio.imwrite(tmp_path / "photo.png", _u8(lf_gray[0, 0]))
    (tmp_path / "notes.txt").write_text("hello")
    assert detect_layout(tmp_path / "lf.npy") == "npy"
    assert probe_layout(tmp_path / "lf.npy") == "npy"
    assert probe_layout(tmp_path / "img.npy") is None  # 2D: not claimed
    assert probe_layout(tmp_path / "photo.png") is None
    assert probe_layout(tmp_path / "notes.txt") is None
    assert probe_layout(tmp_path / "missing.npz") is None
    assert probe_layout(tmp_path) is None  # a folder with no views
    with h5py.File(tmp_path / "cube.h5", "w") as f:
        f["LF"] = lf_gray[0]  # 3D: an image stack, not a light field
    assert probe_layout(tmp_path / "cube.h5") is None
    scipy.io.savemat(tmp_path / "img.mat", {"LF": lf_gray[0, 0]})  # 2D
    assert probe_layout(tmp_path / "img.mat") is None


# ------------------------------------------------------------------ writers


@pytest.mark.parametrize(
    "name, kwargs, read_kwargs, atol",
    [
        ("lf.npz", {}, {}, 0),
        ("lf.npy", {}, {}, 0),
        ("lf.tif", {}, {}, 0),
        ("lf16.tif", {"bit_depth": 16}, {}, 0.5 / 65535 + 1e-7),
        ("lf.h5", {}, {}, 0),
        ("views8", {}, {}, 0.5 / 255 + 1e-7),
        ("views16", {"bit_depth": 16}, {}, 0.5 / 65535 + 1e-7),
        ("grid.png", {"layout": "mosaic"}, {"layout": "mosaic", "grid": (V, U)}, 0.5 / 255 + 1e-7),
    ],
)
@pytest.mark.parametrize("colour", [True, False])
def test_writer_round_trip(tmp_path, lf_rgb, lf_gray, name, kwargs, read_kwargs, atol, colour):
    lf = lf_rgb if colour else lf_gray
    p = write_lightfield(tmp_path / name, lf, **kwargs)
    out = read_lightfield(p, **read_kwargs)
    assert out.shape == lf.shape and out.dtype == np.float32
    np.testing.assert_allclose(out, lf, atol=atol, rtol=0)
    leftovers = [q.name for q in tmp_path.iterdir() if q.name.startswith(".")]
    assert leftovers == []


def test_writer_eslf_round_trip(tmp_path, lf_rgb):
    lf = lf_rgb[:3, :3]
    for name in ("x.eslf.png", "x.eslf.tif"):  # both found to be ESLF by their name
        p = write_lightfield(tmp_path / name, lf, layout="eslf", bit_depth=16)
        assert detect_layout(p) == probe_layout(p) == "eslf"
        np.testing.assert_allclose(read_lightfield(p, angular_size=3), lf, atol=0.5 / 65535 + 1e-7)


@pytest.mark.parametrize("name, layout", [("e.png", "eslf"), ("e.tif", "eslf"), ("m.png", "mosaic"),
                                          ("m.tif", "mosaic")])
def test_a_mosaic_written_here_is_read_back_without_options(tmp_path, name, layout):
    # views of 12x18 px: the lenslet size has many candidates (2, 3, 4, 6) and a grid is never guessed.
    # ESLF needs V == U (4x4 views); the view-grid mosaic has 3 views down and 4 across, so that a grid stated
    # as (U, V) instead of (V, U) cannot read back
    V_, U_, Y_, X_ = (4, 4, 12, 18) if layout == "eslf" else (3, 4, 12, 18)
    lf = np.random.default_rng(1).random((V_, U_, Y_, X_, 3)).astype(np.float32)
    p = write_lightfield(tmp_path / name, lf, layout=layout, bit_depth=16)
    # the image, read by another tool, is the tiling built here: view (v, u) as block (v, u) of the grid, or
    # pixel (v, u) of lenslet (y, x) in ESLF; and it states its layout under the key docs/io.md names
    if layout == "eslf":
        tiling = lf.transpose(2, 0, 3, 1, 4).reshape(Y_ * V_, X_ * U_, 3)
        stated = {"layout": "eslf", "angular_size": 4}
    else:
        tiling = lf.swapaxes(1, 2).reshape(V_ * Y_, U_ * X_, 3)
        stated = {"layout": "mosaic", "grid": [3, 4]}
    if p.suffix == ".png":  # Pillow reads a 16-bit colour PNG as its high bytes
        from PIL import Image

        with Image.open(p) as im:
            text = im.text["lfdeblur_layout"]
        np.testing.assert_allclose(iio.imread(p) / 255, tiling, atol=1.01 / 255, rtol=0)
    else:
        with tifffile.TiffFile(p) as tif:
            text = tif.shaped_metadata[0]["lfdeblur_layout"]
            np.testing.assert_allclose(tif.asarray() / 65535, tiling, atol=0.5 / 65535 + 1e-7, rtol=0)
    assert json.loads(text) == stated
    assert detect_layout(p) == probe_layout(p) == layout  # the file states it (no eslf in the name)
    back, meta = read_lightfield_with_metadata(p)
    assert back.shape == lf.shape
    np.testing.assert_allclose(back, lf, atol=0.5 / 65535 + 1e-7)
    assert (meta["angular_size"] == 4) if layout == "eslf" else (meta["grid"] == [3, 4])
    # a statement that is not one (another tool's text under our key) is ignored, not an error
    from napari_lfdeblur.io._png import write_png

    for text in ("[4, 4]", '{"layout": "mosaic", "grid": [0, 4]}', "{not json"):
        write_png(tmp_path / "odd.png", (lf[0, 0] * 255).astype(np.uint8), text={"lfdeblur_layout": text})
        with pytest.raises(LightFieldFormatError, match="a single image is not a light field by itself"):
            read_lightfield(tmp_path / "odd.png")
    # a plain image of the same size states nothing: still refused, with the options to pass
    plain = tmp_path / f"plain{Path(name).suffix}"
    iio.imwrite(plain, (lf[0, 0] * 255).astype(np.uint8))
    with pytest.raises(LightFieldFormatError, match="layout='eslf'.*layout='mosaic'"):
        read_lightfield(plain)


def test_writer_outputs_readable_by_other_tools(tmp_path, lf_rgb):
    write_lightfield(tmp_path / "v", lf_rgb)
    np.testing.assert_array_equal(iio.imread(tmp_path / "v" / "view_02_04.png"), _u8(lf_rgb[1, 3]))
    write_lightfield(tmp_path / "a.h5", lf_rgb)
    with h5py.File(tmp_path / "a.h5") as f:
        np.testing.assert_array_equal(f["LF"][()], lf_rgb)
        assert f["LF"].attrs["axes"] == "vuyxc"
    write_lightfield(tmp_path / "a.tif", lf_rgb)
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "a.tif"), lf_rgb)
    write_lightfield(tmp_path / "a.npz", lf_rgb)
    np.testing.assert_array_equal(np.load(tmp_path / "a.npz")["lf"], lf_rgb)


def test_png16_colour_codec_matches_values(tmp_path, lf_rgb):
    # Pillow reads 16-bit colour PNGs as 8-bit; our reader must keep all 16 bits
    img = _u16(lf_rgb[0, 0])
    _png.write_png(tmp_path / "a.png", img)
    np.testing.assert_array_equal(_png.read_png16(tmp_path / "a.png"), img)


@pytest.mark.parametrize("ftype", [0, 1, 2, 3, 4])
def test_png16_decoder_all_row_filters(tmp_path, ftype):
    img = np.random.default_rng(ftype).integers(0, 65536, (5, 6, 3), dtype=np.uint16)
    raw = img.astype(">u2").view(np.uint8).reshape(5, -1).astype(np.int64)
    bpp = 6
    rows = []
    for r in range(5):  # reference PNG filter encoder (spec section 9)
        cur = raw[r]
        prev = raw[r - 1] if r else np.zeros_like(cur)
        left = np.concatenate([np.zeros(bpp, np.int64), cur[:-bpp]])
        upleft = np.concatenate([np.zeros(bpp, np.int64), prev[:-bpp]])
        if ftype == 0:
            pred = np.zeros_like(cur)
        elif ftype == 1:
            pred = left
        elif ftype == 2:
            pred = prev
        elif ftype == 3:
            pred = (left + prev) // 2
        else:
            p = left + prev - upleft
            pa, pb, pc = np.abs(p - left), np.abs(p - prev), np.abs(p - upleft)
            pred = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, prev, upleft))
        rows.append(bytes([ftype]) + bytes(((cur - pred) % 256).astype(np.uint8)))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    blob = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 6, 5, 16, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"".join(rows))) + chunk(b"IEND", b""))
    (tmp_path / "f.png").write_bytes(blob)
    np.testing.assert_array_equal(_png.read_png16(tmp_path / "f.png"), img)


def test_writer_camera_path_json(tmp_path, lf_gray):
    cp = np.array([[0.0, 0.0, 0.0], [1.5, -0.5, 0.1], [2.0, 1.0, 0.0]])
    write_lightfield(tmp_path / "res.npz", lf_gray, control_points=cp, metadata={"kind": "blind"})
    np.testing.assert_allclose(load_path_json(tmp_path / "res.path.json"), cp)
    _, meta = read_lightfield_with_metadata(tmp_path / "res.npz")
    np.testing.assert_allclose(meta["control_points"], cp)
    assert meta["saved_metadata"]["kind"] == "blind"
    write_lightfield(tmp_path / "views", lf_gray, control_points=cp)
    np.testing.assert_allclose(load_path_json(tmp_path / "views" / "path.json"), cp)


@pytest.mark.parametrize("name, layout", [("res.npz", None), ("res.npy", None), ("res.tif", None), ("res.h5", None),
                                          ("res.eslf.png", "eslf"), ("views", None)])
def test_every_format_reads_back_the_path_written_with_it(tmp_path, lf_gray, name, layout):
    """The path, T and d_inf that write_lightfield stores come back from read_lightfield_with_metadata."""
    cp = np.array([[0.0, 0.0, 0.0], [1.5, -0.5, 0.1], [2.0, 1.0, 0.0]])
    written = write_lightfield(tmp_path / name, lf_gray[:3, :3], control_points=cp, layout=layout,
                               metadata={"n_times": 12, "infinity_disparity": -0.5})
    _, meta = read_lightfield_with_metadata(written)
    np.testing.assert_allclose(meta["control_points"], cp)
    assert meta["n_times"] == 12 and meta["infinity_disparity"] == -0.5
    # the path file beside it states the views' size, whatever the metadata says
    part = lf_gray[:3, :3, :5, :-1]
    written = write_lightfield(tmp_path / ("b" + name), part, control_points=cp, layout=layout,
                               metadata={"view_shape": [1, 1]})
    assert json.loads(path_json_beside(written).read_text())["view_shape"] == list(part.shape[2:4])


def test_two_channels_round_trip_in_arrays_and_are_refused_as_images(tmp_path):
    lf = np.random.default_rng(3).random((3, 3, 8, 8, 2)).astype(np.float32)
    for name in ("a.tif", "a.npz", "a.npy", "a.h5"):
        np.testing.assert_array_equal(read_lightfield(write_lightfield(tmp_path / name, lf)), lf)
    for name, layout in (("views", None), ("m.png", "mosaic"), ("e.png", "eslf")):
        with pytest.raises(LightFieldFormatError, match="an image holds 1, 3 or 4 channels"):
            write_lightfield(tmp_path / name, lf, layout=layout)
        assert not (tmp_path / name).exists()


def test_a_path_file_beside_a_file_is_that_files_own(tmp_path, lf_gray):
    # a.npy and a.npz share the name a.path.json: each file written with a path names itself in it
    write_lightfield(tmp_path / "a.npy", lf_gray, control_points=linear_path(1.0))
    assert json.loads((tmp_path / "a.path.json").read_text())["lightfield"] == "a.npy"
    write_lightfield(tmp_path / "a.npz", lf_gray, control_points=arc_path(2.0), overwrite=True)
    assert "control_points" not in read_lightfield_with_metadata(tmp_path / "a.npy")[1]  # not the arc
    assert np.allclose(read_lightfield_with_metadata(tmp_path / "a.npz")[1]["control_points"], arc_path(2.0))
    # a file replaced without a path takes the path of what it replaced away with it
    write_lightfield(tmp_path / "a.npz", lf_gray, overwrite=True)
    assert not (tmp_path / "a.path.json").exists()
    assert "control_points" not in read_lightfield_with_metadata(tmp_path / "a.npz")[1]
    # renamed together, a light field and its path file still go together
    write_lightfield(tmp_path / "c.npy", lf_gray, control_points=linear_path(2.5))
    (tmp_path / "c.npy").rename(tmp_path / "d.npy")
    (tmp_path / "c.path.json").rename(tmp_path / "d.path.json")
    assert np.allclose(read_lightfield_with_metadata(tmp_path / "d.npy")[1]["control_points"], linear_path(2.5))
    # a path file that names no light field (written by hand, or by an older version) is read as before
    save_path_json(tmp_path / "b.path.json", linear_path(1.5))
    write_lightfield(tmp_path / "b.npy", lf_gray, overwrite=True)
    np.testing.assert_allclose(read_lightfield_with_metadata(tmp_path / "b.npy")[1]["control_points"],
                               linear_path(1.5))


def test_a_path_file_for_views_of_another_size_is_read_with_a_warning(tmp_path, lf_gray):

    Y, X = lf_gray.shape[2:4]
    for name, cp in (("pz", [[0, 0, 0.3], [1, 0, -0.3]]), ("flat", [[0, 0, 0], [1, 0.5, 0]])):
        write_lightfield(tmp_path / f"{name}.npy", lf_gray, control_points=cp)
        np.save(tmp_path / f"{name}.npy", lf_gray[:, :, 2:-2])  # cropped by another program; its path file kept
    with pytest.warns(UserWarning, match=rf"pz.path.json: the path is for {Y}x{X} views and these are {Y - 4}x{X}"):
        _, meta = read_lightfield_with_metadata(tmp_path / "pz.npy")
    assert meta["view_shape"] == [Y, X] and meta["control_points"] == [[0, 0, 0.3], [1, 0, -0.3]]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_lightfield_with_metadata(tmp_path / "flat.npy")  # an in-plane path blurs any crop alike: nothing said
    doc = json.loads((tmp_path / "pz.path.json").read_text())
    (tmp_path / "pz.path.json").write_text(json.dumps({**doc, "view_shape": "tall"}))
    with pytest.warns(UserWarning, match="view_shape = 'tall'.*not checked against the views' size"):
        read_lightfield_with_metadata(tmp_path / "pz.npy")


def test_a_path_file_that_holds_no_path_is_ignored_with_a_warning(tmp_path, lf_gray):
    np.save(tmp_path / "a.npy", lf_gray)
    (tmp_path / "a.path.json").write_text('{"control_points": [[1, 2]]}')
    with pytest.warns(UserWarning, match=r"a.path.json was not read as the light field's camera path: .*\(1, 2\)"):
        lf, meta = read_lightfield_with_metadata(tmp_path / "a.npy")
    np.testing.assert_array_equal(lf, lf_gray)
    assert "control_points" not in meta
    (tmp_path / "a.path.json").write_text("not json")
    with pytest.warns(UserWarning, match="not read"):
        read_lightfield_with_metadata(tmp_path / "a.npy")


def test_writer_never_overwrites_unless_asked(tmp_path, lf_gray):
    p = write_lightfield(tmp_path / "a.npz", lf_gray)
    with pytest.raises(FileExistsError, match="overwrite"):
        write_lightfield(p, lf_gray * 0.5)
    write_lightfield(tmp_path / "b.npz", lf_gray, control_points=linear_path(1.0))
    with pytest.raises(FileExistsError, match=r"b\.npz exists"):  # named, not its b.path.json
        write_lightfield(tmp_path / "b.npz", lf_gray, control_points=linear_path(1.0))
    np.testing.assert_array_equal(read_lightfield(p), lf_gray)  # untouched
    write_lightfield(p, lf_gray * 0.5, overwrite=True)
    np.testing.assert_allclose(read_lightfield(p), lf_gray * 0.5)
    folder = write_lightfield(tmp_path / "v", lf_gray)
    with pytest.raises(FileExistsError):
        write_lightfield(folder, lf_gray)
    write_lightfield(folder, lf_gray[:2, :2] * 0.5, overwrite=True)  # fewer views: old ones gone
    assert read_lightfield(folder).shape == (2, 2, Y, X)
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.docx").write_text("precious")
    with pytest.raises(FileExistsError, match="not light-field views"):
        write_lightfield(tmp_path / "mine", lf_gray, overwrite=True)
    assert (tmp_path / "mine" / "thesis.docx").read_text() == "precious"
    capture = tmp_path / "capture"  # a user's own views, named as ours are but not written by us
    write_lightfield(capture, lf_gray)
    (capture / "lightfield.json").unlink()
    before = {f.name: f.read_bytes() for f in capture.iterdir()}
    with pytest.raises(FileExistsError, match="holds views that write_lightfield did not write"):
        write_lightfield(capture, lf_gray * 0.5, overwrite=True)
    assert {f.name: f.read_bytes() for f in capture.iterdir()} == before


def test_writer_failure_leaves_nothing(tmp_path, lf_gray, monkeypatch):
    import napari_lfdeblur.io._write as w

    calls = {"n": 0}
    real = w.write_png

    def failing(path, img, **kw):
        calls["n"] += 1
        if calls["n"] == 4:
            raise OSError("disk full")
        return real(path, img, **kw)

    monkeypatch.setattr(w, "write_png", failing)
    with pytest.raises(OSError, match="disk full"):
        write_lightfield(tmp_path / "v", lf_gray)
    monkeypatch.setattr(w.np, "savez_compressed", lambda *a, **k: (_ for _ in ()).throw(OSError("disk full")))
    with pytest.raises(OSError, match="disk full"):
        write_lightfield(tmp_path / "a.npz", lf_gray)
    assert list(tmp_path.iterdir()) == []


def test_writer_rejects_bad_arrays(tmp_path, lf_gray):
    with pytest.raises(LightFieldFormatError, match="3D"):
        write_lightfield(tmp_path / "a.npz", lf_gray[0])
    bad = lf_gray.copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(LightFieldFormatError, match="NaN"):
        write_lightfield(tmp_path / "a.npz", bad)
    with pytest.raises(ValueError, match="PNG"):
        write_lightfield(tmp_path / "v", lf_gray, bit_depth=32)
    with pytest.raises(TypeError, match="metadata must be a dict"):
        write_lightfield(tmp_path / "a.npz", lf_gray, metadata=[("source", "x")])
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ bad input, one test per case


@pytest.fixture
def views8(tmp_path, lf_rgb):
    return _write_views(tmp_path / "views", _u8(lf_rgb), lambda r, c: f"view_{r + 1:02d}_{c + 1:02d}")


def test_bad_missing_view(views8):
    (views8 / "view_02_03.png").unlink()
    with pytest.raises(LightFieldFormatError, match=r"missing.*\(2, 3\)") as exc:
        read_lightfield(views8)
    assert str(views8) in str(exc.value)


def test_bad_missing_hci_view(tmp_path, lf_gray):
    folder = tmp_path / "hci"
    folder.mkdir()
    for k in range(9):
        if k != 4:
            iio.imwrite(folder / f"input_Cam{k:03d}.png", _u8(lf_gray[0, 0]))
    with pytest.raises(LightFieldFormatError, match="input_Cam004"):
        read_lightfield(folder)
    (folder / "input_Cam008.png").rename(folder / "input_Cam004.png")  # the last one missing: 8 of 9
    with pytest.raises(LightFieldFormatError, match="as a 3x3 grid it lacks input_Cam008; pass grid="):
        read_lightfield(folder)


def test_hci_scheme_on_a_folder_without_hci_names(tmp_path, lf_gray):
    folder = tmp_path / "not_hci"
    folder.mkdir()
    iio.imwrite(folder / "view_01_01.png", _u8(lf_gray[0, 0]))
    with pytest.raises(LightFieldFormatError, match="no view file names match the 'hci'"):
        read_lightfield(folder, layout="hci")


def test_bad_views_of_different_sizes(views8, lf_rgb):
    iio.imwrite(views8 / "view_03_02.png", _u8(lf_rgb[2, 1, :-1]))
    with pytest.raises(LightFieldFormatError, match="view_03_02.png.*same size"):
        read_lightfield(views8)


def test_bad_views_of_different_dtypes(views8, lf_rgb):
    _png.write_png(views8 / "view_01_02.png", _u16(lf_rgb[0, 1]))
    with pytest.raises(LightFieldFormatError, match="view_01_02.png.*bit depth"):
        read_lightfield(views8)


def test_bad_truncated_image(views8):
    f = views8 / "view_02_02.png"
    f.write_bytes(f.read_bytes()[:60])
    with pytest.raises(LightFieldReadError, match="view_02_02.png") as exc:
        read_lightfield(views8)
    assert isinstance(exc.value, OSError) and isinstance(exc.value, ValueError)


def test_a_file_that_is_not_an_image_is_named_in_one_line(views8):
    (views8 / "view_02_02.png").write_text("junk")  # imageio's error lists plugins to install, over many lines
    with pytest.raises(LightFieldReadError, match="view_02_02.png: cannot decode the image") as exc:
        read_lightfield(views8)
    assert "\n" not in str(exc.value)


def test_bad_truncated_16bit_colour_png(tmp_path, lf_rgb):
    folder = write_lightfield(tmp_path / "v16", lf_rgb, bit_depth=16)
    f = folder / "view_03_04.png"
    f.write_bytes(f.read_bytes()[:-30])
    with pytest.raises(LightFieldReadError, match="view_03_04.png.*truncated"):
        read_lightfield(folder)


def test_bad_corrupt_image(views8):
    f = views8 / "view_01_01.png"
    data = bytearray(f.read_bytes())
    data[50:70] = b"\x00" * 20  # inside the image data: CRC / zlib fail
    f.write_bytes(bytes(data))
    with pytest.raises(LightFieldReadError, match="view_01_01.png"):
        read_lightfield(views8)


def test_bad_non_image_with_image_extension(views8):
    (views8 / "view_03_01.png").write_text("this is a text file, not a PNG\n")
    with pytest.raises(LightFieldReadError, match="view_03_01.png.*not an image"):
        read_lightfield(views8)


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("suffix", [".npy", ".npz", ".tif", ".h5"])
def test_bad_2d_or_3d_array(tmp_path, lf_gray, ndim, suffix):
    arr = lf_gray[0, 0] if ndim == 2 else lf_gray[0]
    p = tmp_path / f"a{suffix}"
    if suffix == ".npy":
        np.save(p, arr)
    elif suffix == ".npz":
        np.savez(p, lf=arr)
    elif suffix == ".tif":
        tifffile.imwrite(p, arr)
    else:
        with h5py.File(p, "w") as f:
            f["LF"] = arr
    with pytest.raises(LightFieldFormatError, match=f"{ndim}D") as exc:
        read_lightfield(p)
    assert p.name in str(exc.value)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("suffix", [".npy", ".h5", ".tif"])
def test_bad_nan_or_inf(tmp_path, lf_gray, value, suffix):
    arr = lf_gray.copy()
    arr[1, 2, 3, 4] = value
    p = tmp_path / f"a{suffix}"
    if suffix == ".npy":
        np.save(p, arr)
    elif suffix == ".tif":
        tifffile.imwrite(p, arr)
    else:
        with h5py.File(p, "w") as f:
            f["LF"] = arr
    with pytest.raises(LightFieldFormatError, match="NaN or Inf") as exc:
        read_lightfield(p)
    assert p.name in str(exc.value)


def test_bad_path_does_not_exist(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing_here"):
        read_lightfield(tmp_path / "nothing_here")
    with pytest.raises(FileNotFoundError):
        detect_layout(tmp_path / "nothing_here.npz")


def test_bad_too_big_for_memory_checked_before_allocating(tmp_path):
    # a 128-byte .npy whose header claims a 4 TB light field: must fail on the header alone
    p = tmp_path / "huge.npy"
    with open(p, "wb") as fh:
        np.lib.format.write_array_header_1_0(
            fh, {"descr": "<f4", "fortran_order": False, "shape": (100, 100, 10000, 10000)}
        )
    with pytest.raises(InsufficientMemoryError, match="huge.npy.*needs about") as exc:
        read_lightfield(p)
    assert isinstance(exc.value, LightFieldError) and isinstance(exc.value, MemoryError)


def test_bad_too_big_views_checked_before_decoding(views8, monkeypatch):
    decoded = []
    monkeypatch.setattr(_views, "read_image", lambda p: decoded.append(p))
    with pytest.raises(InsufficientMemoryError, match="views"):
        read_lightfield(views8, max_bytes=5_000)  # 1512 uint8 samples + their float32 copy: 7560 B
    monkeypatch.setenv("LFDEBLUR_MEMORY_LIMIT", "5000")
    with pytest.raises(InsufficientMemoryError):
        read_lightfield(views8)
    assert decoded == []


def test_bad_options_and_types(tmp_path, lf_gray):
    np.save(tmp_path / "a.npy", lf_gray)
    with pytest.raises(TypeError, match="angular_size"):
        read_lightfield(tmp_path / "a.npy", angular_size=14)
    with pytest.raises(ValueError, match="unknown layout"):
        read_lightfield(tmp_path / "a.npy", layout="lytro-raw")
    (tmp_path / "a.xyz").write_text("?")
    with pytest.raises(LightFieldFormatError, match="unknown light-field file type"):
        read_lightfield(tmp_path / "a.xyz")
    (tmp_path / "IMG_0001.LFR").write_bytes(b"\x89LFP")  # a raw Lytro capture: how to get views from it
    with pytest.raises(LightFieldFormatError, match=r"raw plenoptic capture \(Lytro \.lfr\) must be decoded"):
        read_lightfield(tmp_path / "IMG_0001.LFR")
    np.save(tmp_path / "b.npy", lf_gray * 3)
    with pytest.raises(LightFieldFormatError, match="value_range"):
        read_lightfield(tmp_path / "b.npy")


# ------------------------------------------------------------------ CLI


def test_cli_info(tmp_path, lf_rgb, capsys):
    from napari_lfdeblur.cli import main

    write_lightfield(tmp_path / "v", lf_rgb, bit_depth=16)
    assert main(["info", str(tmp_path / "v")]) == 0
    out = capsys.readouterr().out
    assert "layout:      views" in out
    assert f"shape:       {lf_rgb.shape}" in out
    assert "float32 (stored as uint16)" in out
    lo, hi = (float(s) for s in out.split("value range: [")[1].split("]")[0].split(","))
    assert lo == pytest.approx(lf_rgb.min(), abs=1e-4) and hi == pytest.approx(lf_rgb.max(), abs=1e-4)
    assert "saved_metadata" in out
    assert main(["info", str(tmp_path / "missing")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_metadata_is_json_serialisable(tmp_path, lf_rgb):
    write_lightfield(tmp_path / "a.h5", lf_rgb, metadata={"kind": "x"}, control_points=[[0, 0, 0], [1, 1, 0]])
    _, meta = read_lightfield_with_metadata(tmp_path / "a.h5")
    assert json.loads(json.dumps(meta))["source"].endswith("a.h5")
    assert meta["layout"] == "h5" and meta["shape"] == list(lf_rgb.shape)


def test_photo_folder_is_not_a_light_field(tmp_path, lf_gray):
    # names with two numbers that do not index a view grid (date_time) are not views
    folder = _write_views(tmp_path / "phone", _u8(lf_gray), lambda r, c: f"IMG_2023050{r + 1}_12000{c}", ".jpg")
    assert probe_layout(folder) is None
    with pytest.raises(LightFieldFormatError, match="no light-field views"):
        read_lightfield(folder)


def test_mat_float_overshoot_is_clipped(tmp_path, lf_gray):
    arr = lf_gray * 1.1 - 0.05
    scipy.io.savemat(tmp_path / "f.mat", {"LF": arr})
    np.testing.assert_allclose(read_lightfield(tmp_path / "f.mat"), np.clip(arr, 0, 1), atol=1e-7)
    # data on another scale is not an overshoot: refused, as other formats do, until value_range says its scale
    scipy.io.savemat(tmp_path / "g.mat", {"LF": lf_gray * 255})
    with pytest.raises(LightFieldFormatError, match="outside \\[0, 1\\]"):
        read_lightfield(tmp_path / "g.mat")
    np.testing.assert_allclose(read_lightfield(tmp_path / "g.mat", value_range=(0, 255)), lf_gray, atol=1e-6)
    # docs/io.md: float data within [-0.5, 1.5] is clipped to [0, 1]; beyond that it needs value_range
    wide = lf_gray * 1.9 - 0.45  # within [-0.45, 1.45]
    scipy.io.savemat(tmp_path / "h.mat", {"LF": wide})
    np.testing.assert_allclose(read_lightfield(tmp_path / "h.mat"), np.clip(wide, 0, 1), atol=1e-7)
    assert wide.max() > 1.4 and wide.min() < -0.4
    for name, beyond in (("over.mat", lf_gray + 0.6), ("under.mat", lf_gray - 0.6)):  # up to 1.6, down to -0.6
        scipy.io.savemat(tmp_path / name, {"LF": beyond})
        with pytest.raises(LightFieldFormatError, match="outside \\[0, 1\\]"):
            read_lightfield(tmp_path / name)


def test_png16_decoder_mixed_row_filters_matches_reference(tmp_path):
    # rows filtered with random types; decode must invert the reference encoder exactly
    img = np.random.default_rng(9).integers(0, 65536, (23, 17, 4), dtype=np.uint16)
    raw = img.astype(">u2").view(np.uint8).reshape(23, -1).astype(np.int64)
    bpp = 8
    types = np.random.default_rng(10).integers(0, 5, 23)
    rows = []
    for r in range(23):
        cur = raw[r]
        prev = raw[r - 1] if r else np.zeros_like(cur)
        left = np.concatenate([np.zeros(bpp, np.int64), cur[:-bpp]])
        upleft = np.concatenate([np.zeros(bpp, np.int64), prev[:-bpp]])
        p = left + prev - upleft
        pa, pb, pc = np.abs(p - left), np.abs(p - prev), np.abs(p - upleft)
        paeth = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, prev, upleft))
        pred = [np.zeros_like(cur), left, prev, (left + prev) // 2, paeth][types[r]]
        rows.append(bytes([types[r]]) + bytes(((cur - pred) % 256).astype(np.uint8)))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    blob = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 17, 23, 16, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"".join(rows))) + chunk(b"IEND", b""))
    (tmp_path / "m.png").write_bytes(blob)
    np.testing.assert_array_equal(_png.read_png16(tmp_path / "m.png"), img)


def test_stack_of_views_with_grid_option(tmp_path, lf_rgb):
    tifffile.imwrite(tmp_path / "stack.tif", _u8(lf_rgb).reshape(V * U, Y, X, 3), photometric="rgb")
    with pytest.raises(LightFieldFormatError, match="stack of 12 colour images"):
        read_lightfield(tmp_path / "stack.tif")
    assert probe_layout(tmp_path / "stack.tif") is None  # napari's own reader opens it as a stack
    out = read_lightfield(tmp_path / "stack.tif", grid=(V, U))
    np.testing.assert_array_equal(out, _u8(lf_rgb) / np.float32(255))
    np.save(tmp_path / "g.npy", lf_rgb[..., 0].reshape(V * U, Y, X))
    np.testing.assert_array_equal(read_lightfield(tmp_path / "g.npy", grid=(V, U)), lf_rgb[..., 0])
    with pytest.raises(LightFieldFormatError, match="needs a stack of 9 views"):
        read_lightfield(tmp_path / "g.npy", grid=(3, 3))


@pytest.mark.parametrize("suffix", ["npy", "npz"])
def test_array_stack_of_colour_images_is_refused_unless_its_layout_is_given(tmp_path, suffix):
    # an (N, H, W, 3) array has no axes to say what it is; read as (V, U, Y, X) its views would be 3 px wide
    lf = np.random.default_rng(0).random((3, 4, 16, 20, 3)).astype(np.float32)
    stack = lf.reshape(12, 16, 20, 3)
    f = tmp_path / f"stack.{suffix}"
    np.save(f, stack) if suffix == "npy" else np.savez(f, lf=stack)
    with pytest.raises(LightFieldFormatError, match=r"a stack of 12 colour images of 16x20 rather than a light "
                                                    r"field of 20x3 px views; pass grid=\(V, U\)"):
        read_lightfield(f)
    assert probe_layout(f) is None  # napari's own reader opens it as a stack
    np.testing.assert_array_equal(read_lightfield(f, grid=(3, 4)), lf)
    assert read_lightfield(f, axes="vuyx").shape == (12, 16, 20, 3)  # read as it is, when asked
    np.save(tmp_path / "narrow.npy", lf[:, :, :11, :3, 0])  # views 3 px wide, under four times as tall
    assert probe_layout(tmp_path / "narrow.npy") == "npy" and read_lightfield(tmp_path / "narrow.npy").shape[3] == 3


# ------------------------------------------------------------------ angular crop


def _every_layout(folder, lf8):
    """``lf8`` (V, U, Y, X, 3) uint8 written in every layout; name -> (path, read options)."""
    V_, U_ = lf8.shape[:2]
    out = {"views": (_write_views(folder / "views", lf8, lambda r, c: f"IMG_{r + 1:02d}_{c + 1:02d}"), {})}
    Y_, X_ = lf8.shape[2:4]
    iio.imwrite(folder / "grid.png", lf8.swapaxes(1, 2).reshape(V_ * Y_, U_ * X_, 3))  # view (v, u) at block (v, u)
    out["mosaic"] = (folder / "grid.png", {"layout": "mosaic", "grid": (V_, U_)})
    np.save(folder / "a.npy", lf8)
    out["npy"] = (folder / "a.npy", {})
    np.save(folder / "stack.npy", lf8.reshape((V_ * U_,) + lf8.shape[2:]))
    out["npy stack"] = (folder / "stack.npy", {"grid": (V_, U_)})
    np.savez(folder / "b.npz", lf=lf8)
    out["npz"] = (folder / "b.npz", {})
    tifffile.imwrite(folder / "c.tif", lf8)
    out["tiff"] = (folder / "c.tif", {})
    with h5py.File(folder / "d.h5", "w") as f:
        f.create_dataset("LF", data=lf8.transpose(3, 2, 4, 1, 0)).attrs["axes"] = "xycuv"
    out["h5, axes permuted"] = (folder / "d.h5", {})
    scipy.io.savemat(folder / "e.mat", {"LF": lf8})
    out["mat v5"] = (folder / "e.mat", {})
    with h5py.File(folder / "f.mat", "w", userblock_size=512) as f:
        f.create_dataset("LF", data=lf8.T)
    with open(folder / "f.mat", "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .")
    out["mat v7.3"] = (folder / "f.mat", {})
    return out


LAZY = ("views", "npy", "npy stack", "h5, axes permuted", "mat v7.3")  # these read only the kept views


def test_angular_crop_keeps_the_central_views_in_every_layout(tmp_path):
    lf8 = np.random.default_rng(5).integers(0, 256, (7, 6, 5, 4, 3), dtype=np.uint8)
    for name, (path, opts) in _every_layout(tmp_path, lf8).items():
        out, meta = read_lightfield_with_metadata(path, angular_crop=3, **opts)
        np.testing.assert_array_equal(out, lf8[2:5, 1:4] / np.float32(255), err_msg=name)
        assert meta["angular_crop"] == [3, 3], name
        assert meta["shape"] == [3, 3, 5, 4, 3], name
        out = read_lightfield(path, angular_crop=(7, 2), **opts)  # (n_v, n_u)
        np.testing.assert_array_equal(out, lf8[:, 2:4] / np.float32(255), err_msg=name)


def test_angular_crop_reads_only_the_kept_views_where_the_layout_allows(tmp_path):
    lf8 = np.random.default_rng(6).integers(0, 256, (9, 9, 8, 8, 3), dtype=np.uint8)
    whole, kept = lf8.size * 5, 9 * lf8[0, 0].size * 5  # uint8 samples + their float32 copy
    for name, (path, opts) in _every_layout(tmp_path, lf8).items():
        limit = kept + 100
        if name in LAZY:
            out = read_lightfield(path, angular_crop=3, max_bytes=limit, **opts)
            np.testing.assert_array_equal(out, lf8[3:6, 3:6] / np.float32(255), err_msg=name)
        else:  # read whole, then cropped before the float copy: that is what is checked
            with pytest.raises(InsufficientMemoryError):
                read_lightfield(path, angular_crop=3, max_bytes=limit, **opts)
            read_lightfield(path, angular_crop=3, max_bytes=lf8.size + 9 * lf8[0, 0].size * 4 + 100, **opts)
        with pytest.raises(InsufficientMemoryError):
            read_lightfield(path, max_bytes=whole - 100, **opts)


def test_angular_crop_reads_only_the_kept_views_as_measured(tmp_path, monkeypatch):
    # what is read, seen from outside the reader's own estimate. A folder: only the kept views' images are decoded
    lf8 = np.random.default_rng(6).integers(0, 256, (9, 9, 8, 8, 3), dtype=np.uint8)
    folder = _write_views(tmp_path / "views", lf8, lambda r, c: f"IMG_{r + 1:02d}_{c + 1:02d}")
    decoded, read_image = [], _views.read_image
    monkeypatch.setattr(_views, "read_image", lambda p: decoded.append(Path(p).name) or read_image(p))
    np.testing.assert_array_equal(read_lightfield(folder, angular_crop=3), lf8[3:6, 3:6] / np.float32(255))
    assert sorted(decoded) == [f"IMG_{r:02d}_{c:02d}.png" for r in (4, 5, 6) for c in (4, 5, 6)]
    # the array files: the most memory the read allocates. The 3x3 kept views are 1/49 of these 21x21 views;
    # they and their float32 copy take about 8 bytes a kept sample, 1/6 of the file's bytes, while a read of the
    # whole array allocates at least the file's bytes; half of them lies far from both
    import tracemalloc

    big = np.random.default_rng(7).integers(0, 256, (21, 21, 32, 32, 3), dtype=np.uint8)
    (tmp_path / "big").mkdir()
    layouts = _every_layout(tmp_path / "big", big)
    for name in LAZY[1:]:
        path, opts = layouts[name]
        read_lightfield(path, angular_crop=3, **opts)  # imports and caches of a first read are not counted
        tracemalloc.start()
        try:
            out = read_lightfield(path, angular_crop=3, **opts)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        np.testing.assert_array_equal(out, big[9:12, 9:12] / np.float32(255), err_msg=name)
        assert peak < big.nbytes / 2, (name, peak, big.nbytes)


@pytest.mark.parametrize("crop", [0, 10, -1, 2.5, "3", True, (3, 3, 3), (3, 0)])
def test_bad_angular_crop_is_refused_before_reading(tmp_path, lf_gray, crop):
    np.save(tmp_path / "a.npy", lf_gray)
    with pytest.raises(ValueError, match="angular_crop"):
        read_lightfield(tmp_path / "a.npy", angular_crop=crop)


def test_angular_crop_bounds_each_axis_by_its_own_number_of_views(tmp_path, lf_gray):
    np.save(tmp_path / "wide.npy", lf_gray)  # 3 x 4 views: all 4 columns of the central row can be kept
    np.testing.assert_array_equal(read_lightfield(tmp_path / "wide.npy", angular_crop=(1, 4)), lf_gray[1:2])
    np.save(tmp_path / "tall.npy", lf_gray.swapaxes(0, 1))  # 4 x 3 views: 4 columns cannot
    with pytest.raises(ValueError, match="angular_crop=\\(1, 4\\) must be .* 1 <= n_u <= 3"):
        read_lightfield(tmp_path / "tall.npy", angular_crop=(1, 4))


@pytest.mark.parametrize("text, expected", [("", None), (None, None), ("auto", "auto"), (" AUTO ", "auto"),
                                            ("0,4095", (0.0, 4095.0)), (" -1.5 , 2e3 ", (-1.5, 2000.0))])
def test_parse_value_range(text, expected):
    from napari_lfdeblur.io import parse_value_range

    assert parse_value_range(text) == expected


@pytest.mark.parametrize("text", ["5,1", "3,3", "a,b", "1", "1,2,3", "nan,1", "0,inf", "max"])
def test_parse_value_range_refuses_with_an_example(text):
    from napari_lfdeblur.io import parse_value_range

    with pytest.raises(ValueError, match="expected LO,HI with LO < HI, such as 0,4095, or auto"):
        parse_value_range(text)


@pytest.mark.parametrize("value_range", [(5, 1), (0, float("nan")), (0, 1, 2), "max", 3])
def test_bad_value_range_is_refused_before_reading(tmp_path, value_range):
    with pytest.raises(ValueError, match="value_range"):
        read_lightfield(tmp_path / "missing.npy", value_range=value_range)  # refused before the file is looked for


def test_twelve_bit_values_in_a_sixteen_bit_file(tmp_path, lf_gray):
    raw = np.round(lf_gray * 4095).astype(np.uint16)
    tifffile.imwrite(tmp_path / "raw.tif", raw)
    np.testing.assert_allclose(read_lightfield(tmp_path / "raw.tif"), raw / 65535, atol=1e-7)  # dark by default
    lf, meta = read_lightfield_with_metadata(tmp_path / "raw.tif", value_range=(0, 4095))
    np.testing.assert_allclose(lf, raw / 4095, atol=1e-6)
    assert meta["value_range"] == [0.0, 4095.0]
    lf, meta = read_lightfield_with_metadata(tmp_path / "raw.tif", value_range="auto")
    np.testing.assert_allclose(lf, (raw - raw.min()) / (raw.max() - raw.min()), atol=1e-6)
    assert meta["value_range"] == "auto"
    # constant data has no range to stretch: read as 0, and said (it turned black without a word)
    tifffile.imwrite(tmp_path / "flat.tif", np.full_like(raw, 700))
    with pytest.warns(UserWarning, match="every value is 700, so value_range='auto' has no range"):
        lf = read_lightfield(tmp_path / "flat.tif", value_range="auto")
    assert lf.shape == raw.shape and not lf.any()


def test_cli_value_range_and_the_dark_note(tmp_path, lf_rgb, capsys):
    from napari_lfdeblur.cli import main

    np.save(tmp_path / "scaled.npy", lf_rgb * 255)
    assert main(["info", str(tmp_path / "scaled.npy")]) == 2
    err = capsys.readouterr().err
    assert "--value-range LO,HI" in err and len(err.strip().splitlines()) == 1
    assert main(["simulate", str(tmp_path / "scaled.npy"), str(tmp_path / "b.npy"), "--value-range", "0,255",
                 "--path", "linear:0", "--n-times", "2"]) == 0  # no motion: the input, rescaled
    np.testing.assert_allclose(np.load(tmp_path / "b.npy"), lf_rgb, atol=1e-5)
    with pytest.raises(SystemExit):
        main(["info", str(tmp_path / "scaled.npy"), "--value-range", "255,0"])
    assert "expected LO,HI with LO < HI" in capsys.readouterr().err
    np.save(tmp_path / "dim.npy", lf_rgb * 0.2)
    assert main(["info", str(tmp_path / "dim.npy")]) == 0
    bright = np.percentile((lf_rgb * 0.2)[lf_rgb.shape[0] // 2, lf_rgb.shape[1] // 2], 99.9)
    assert f"dark: 99.9 % of the centre view is below {bright:.3g} (" in capsys.readouterr().out
    assert main(["info", str(tmp_path / "dim.npy"), "--value-range", "auto"]) == 0
    out = capsys.readouterr().out
    assert "dark" not in out and "value range: [0, 1]" in out
    assert "saturated:   " + f"{100 / (lf_rgb.size):.3g} % of the samples are at 1" in out  # the maximum, stretched
    assert main(["info", str(tmp_path / "dim.npy")]) == 0 and "saturated" not in capsys.readouterr().out


def test_cli_angular_crop(tmp_path, lf_rgb, capsys):
    from napari_lfdeblur.cli import main

    np.save(tmp_path / "a.npy", lf_rgb)
    assert main(["info", str(tmp_path / "a.npy"), "--angular-crop", "1,2"]) == 0
    assert f"shape:       {(1, 2) + lf_rgb.shape[2:]}" in capsys.readouterr().out
    assert main(["simulate", str(tmp_path / "a.npy"), str(tmp_path / "b.npy"), "--angular-crop", "3",
                 "--path", "linear:1", "--n-times", "4"]) == 0
    assert np.load(tmp_path / "b.npy").shape == (3, 3) + lf_rgb.shape[2:]
    assert main(["info", str(tmp_path / "a.npy"), "--angular-crop", "9"]) == 2  # more views than the file has
    err = capsys.readouterr().err
    assert "angular_crop=9" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(SystemExit):
        main(["info", str(tmp_path / "a.npy"), "--angular-crop", "three"])
    assert "expected N or NV,NU" in capsys.readouterr().err


def test_a_file_holding_no_light_field_is_named_once_in_a_sentence(tmp_path):
    np.save(tmp_path / "c7.npy", np.zeros((3, 3, 8, 8, 7), np.float32))
    with pytest.raises(LightFieldFormatError) as exc:
        read_lightfield(tmp_path / "c7.npy")
    assert str(exc.value).startswith(f"{tmp_path / 'c7.npy'}: a colour light field must have 1 to 4 channels")
    assert str(exc.value).count("c7.npy") == 1


def test_a_write_that_fails_on_the_paths_fields_leaves_nothing(tmp_path, lf_gray):
    cp = linear_path(1.0)
    for name in ("nt.npz", "nt.npy", "nt.tif", "nt.h5", "views"):
        for bad, said in (({"n_times": 16.0}, "n_times = 16.0"), ({"infinity_disparity": float("nan")}, "nan")):
            with pytest.raises(ValueError, match=said):
                write_lightfield(tmp_path / name, lf_gray, metadata=bad, control_points=cp)
            assert list(tmp_path.iterdir()) == []


def test_metadata_passed_along_does_not_override_the_arrays_own_shape(tmp_path, lf_gray):
    # metadata read from a light field, written with a crop of it: the crop's shape, and its views' size in the path
    meta = read_lightfield_with_metadata(write_lightfield(tmp_path / "whole.npz", lf_gray,
                                                          control_points=linear_path(1.0)))[1]
    part = lf_gray[:, :, 1:, :-2]
    written = write_lightfield(tmp_path / "part.npz", part, metadata=meta, control_points=linear_path(1.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back, meta2 = read_lightfield_with_metadata(written)
    assert not [w for w in caught if "the path is for" in str(w.message)]
    assert back.shape == part.shape and meta2["saved_metadata"]["shape"] == list(part.shape)
    assert json.loads(path_json_beside(written).read_text())["view_shape"] == list(part.shape[2:4])


def test_a_path_file_of_an_earlier_file_is_not_removed_without_overwrite(tmp_path, lf_gray):
    write_lightfield(tmp_path / "a.npz", lf_gray, control_points=linear_path(1.0))
    (tmp_path / "a.npz").unlink()
    before = (tmp_path / "a.path.json").read_text()
    with pytest.raises(FileExistsError, match="a.path.json exists and holds the camera path of an earlier a.npz"):
        write_lightfield(tmp_path / "a.npz", lf_gray)
    assert not (tmp_path / "a.npz").exists() and (tmp_path / "a.path.json").read_text() == before
    write_lightfield(tmp_path / "a.npz", lf_gray, overwrite=True)  # replaced: the old path goes with it
    assert not (tmp_path / "a.path.json").exists()
    assert "control_points" not in read_lightfield_with_metadata(tmp_path / "a.npz")[1]


@pytest.mark.parametrize("suffix", [".h5", ".mat"])
def test_a_corrupt_hdf5_file_is_one_read_error_that_names_it(tmp_path, lf_gray, suffix):
    good = write_lightfield(tmp_path / "good.h5", lf_gray)
    raw = bytearray(good.read_bytes())
    raw[16:20] = b"\xff\xff\xff\xff"  # the superblock's addresses: h5py fails on opening a group (RuntimeError)
    bad = tmp_path / f"bad{suffix}"  # .mat: a MATLAB v7.3 file is HDF5 (with the variable "LF")
    bad.write_bytes(bytes(raw))
    with pytest.raises(LightFieldReadError, match=rf"{bad.name}: not a readable (HDF5|MATLAB) light field \("):
        read_lightfield(bad)


def test_writing_values_outside_0_1_warns_how_to_read_them_back(tmp_path, lf_gray):
    lf = lf_gray * 2.0 - 0.5  # [-0.5, 1.5]
    lo, hi = float(lf.min()), float(lf.max())
    with pytest.warns(UserWarning, match=r"o.npz: the values span .*outside \[0, 1\]; they are stored as they are"):
        written = write_lightfield(tmp_path / "o.npz", lf)
    with pytest.raises(LightFieldFormatError, match="outside"):
        read_lightfield(written)
    np.testing.assert_allclose(read_lightfield(written, value_range=(lo, hi)), (lf - lo) / (hi - lo), atol=1e-6)
    with pytest.warns(UserWarning, match="the 8-bit samples clip them to"):
        write_lightfield(tmp_path / "o.png", lf, layout="mosaic")


def test_integer_samples_clip_values_outside_0_1_instead_of_wrapping(tmp_path):
    # docs/io.md: bit_depth=8 or 16 quantises to unsigned integers, clipping to [0, 1]
    lf = np.full((2, 2, 3, 4), 1.2, np.float32)
    lf[1, 0] = -0.2
    for name, kwargs in (("views", {}), ("m.png", {"layout": "mosaic"}), ("d.tif", {"bit_depth": 16})):
        with pytest.warns(UserWarning, match="-bit samples clip them to"):
            written = write_lightfield(tmp_path / name, lf, **kwargs)
        np.testing.assert_array_equal(read_lightfield(written), np.clip(lf, 0, 1), err_msg=name)


def test_float_overshoots_beyond_rounding_and_negative_integers_are_refused(tmp_path):
    # to_float01's docstring: float overshoots of up to 1e-3 (rounding) are clipped, larger ones refused
    for value, expected in ((1.0005, 1.0), (-0.0005, 0.0), (1.05, None), (-0.05, None)):
        np.save(tmp_path / "f.npy", np.full((2, 2, 4, 4), value, np.float32))
        if expected is None:
            with pytest.raises(LightFieldFormatError, match="outside \\[0, 1\\]; to rescale, pass value_range"):
                read_lightfield(tmp_path / "f.npy")
        else:
            np.testing.assert_array_equal(read_lightfield(tmp_path / "f.npy"), expected)
    # signed integers are divided by their maximum; a negative one has no place in [0, 1]: refused
    ints = np.zeros((2, 2, 4, 4), np.int16)
    ints[1, 1, 1, 1] = 32767
    np.save(tmp_path / "i.npy", ints)
    assert read_lightfield(tmp_path / "i.npy")[1, 1, 1, 1] == 1.0
    ints[0, 0, 0, 0] = -5
    np.save(tmp_path / "i.npy", ints)
    with pytest.raises(LightFieldFormatError, match="signed integer data has negative values; pass value_range"):
        read_lightfield(tmp_path / "i.npy")


def test_float64_beyond_float32_and_timedelta_data(tmp_path):
    np.save(tmp_path / "big.npy", np.full((2, 2, 8, 8), 1e300))  # finite in float64, inf in float32
    with pytest.raises(LightFieldFormatError, match=r"float values span \[1e\+300, 1e\+300\], outside"):
        read_lightfield(tmp_path / "big.npy")  # was "contains 256 NaN or Inf value(s)"
    np.testing.assert_array_equal(read_lightfield(tmp_path / "big.npy", value_range=(0, 2e300)), 0.5)
    np.save(tmp_path / "td.npy", np.zeros((2, 2, 8, 8), "m8[s]"))
    with pytest.raises(LightFieldFormatError, match="unsupported data type timedelta64"):
        read_lightfield(tmp_path / "td.npy")


def test_a_truncated_tiff_is_a_read_error(tmp_path, lf_gray, capsys):
    whole = write_lightfield(tmp_path / "whole.tif", lf_gray, compress=False).read_bytes()
    (tmp_path / "half.tif").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(LightFieldReadError, match=r"half.tif: a truncated or corrupt TIFF file \(tifffile: "):
        read_lightfield(tmp_path / "half.tif")  # was a 2D-series LightFieldFormatError after two log lines
    assert capsys.readouterr().err == ""


def test_an_opaque_alpha_channel_is_dropped_from_views_as_from_mosaics(tmp_path, lf_rgb):
    rgb8 = _u8(lf_rgb)
    rgba = np.concatenate([rgb8, np.full(rgb8.shape[:-1] + (1,), 255, np.uint8)], axis=-1)
    holed = rgba.copy()
    holed[:, :, 0, 0, 3] = 0  # opaque but for one pixel a view: the channel is not opaque everywhere
    for name, data in (("opaque", rgba), ("translucent", np.where(np.arange(4) == 3, rgba // 2, rgba)),
                       ("holed", holed)):
        folder = tmp_path / name
        folder.mkdir()
        for v in range(rgba.shape[0]):
            for u in range(rgba.shape[1]):
                iio.imwrite(folder / f"view_{v + 1:02d}_{u + 1:02d}.png", data[v, u])
        back = read_lightfield(folder)
        if name == "opaque":  # the same colour light field as without the channel
            np.testing.assert_array_equal(back, read_lightfield(write_lightfield(tmp_path / "rgb", lf_rgb)))
        else:  # transparency is data: kept
            assert back.shape[-1] == 4
            np.testing.assert_array_equal(back, data / np.float32(255))


@pytest.mark.parametrize("suffix", [".h5", ".mat"])
def test_a_crop_the_file_cannot_give_is_said_as_such_not_as_an_unreadable_file(tmp_path, lf_gray, suffix):
    p = tmp_path / f"a{suffix}"
    if suffix == ".h5":
        write_lightfield(p, lf_gray)
    else:
        scipy.io.savemat(p, {"LF": lf_gray})
    with pytest.raises(ValueError, match=rf"^{re.escape(str(p))}: angular_crop=99 must be n or \(n_v, n_u\)") as err:
        read_lightfield(p, angular_crop=99)
    assert not isinstance(err.value, LightFieldReadError)  # the file is readable: the request does not fit it


def test_a_one_view_folder_written_here_reads_back(tmp_path):
    """A 1 x 1 light field is a folder of one view beside write_lightfield's lightfield.json; a folder of one
    image without it is not a light field (a single photo)."""
    lf = np.random.default_rng(0).random((1, 1, 8, 8)).astype(np.float32)
    folder = write_lightfield(tmp_path / "one", lf, bit_depth=16)
    np.testing.assert_allclose(read_lightfield(folder), lf, atol=1e-4)
    (folder / "lightfield.json").unlink()
    with pytest.raises(LightFieldFormatError, match="holds no light-field views"):
        read_lightfield(folder)
