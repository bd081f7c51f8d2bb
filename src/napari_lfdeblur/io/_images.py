"""Reading single 2D images (PNG, JPEG, TIFF, ...) with clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._lightfield import white_level
from ._common import LightFieldFormatError, LightFieldReadError
from ._png import PNGError, needs_own_decoder, png_header, read_png16

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
TIFF_EXTENSIONS = (".tif", ".tiff")


def _squeeze_channels(img: np.ndarray, path) -> np.ndarray:
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim == 3 and img.shape[2] == 2:  # gray + alpha: keep the gray
        img = img[..., 0]
    if img.ndim == 3 and img.shape[2] > 4 and img.shape[0] <= 4:  # planar TIFF (C, H, W)
        img = np.moveaxis(img, 0, -1)
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (3, 4)):
        raise LightFieldFormatError(
            f"{path}: expected a 2D gray or RGB(A) image, got an array of shape {img.shape}"
        )
    return img


def drop_opaque_alpha(img: np.ndarray) -> np.ndarray:
    """``img`` (one image or a stack, channels last) without its alpha channel when that is opaque everywhere."""
    if img.ndim >= 3 and img.shape[-1] == 4:
        if np.all(img[..., 3] == white_level(img.dtype)):
            return img[..., :3]
    return img


def image_props(path) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype of an image without decoding its pixels (when possible).

    Raises
    ------
    LightFieldReadError
        If the file cannot be opened as an image.
    """
    path = Path(path)
    if path.suffix.lower() in TIFF_EXTENSIONS:
        import tifffile

        try:
            with tifffile.TiffFile(path) as tif:
                s = tif.series[0]
                return tuple(s.shape), np.dtype(s.dtype)
        except Exception as exc:  # noqa: BLE001
            raise LightFieldReadError(f"{path}: cannot read as TIFF ({exc})") from None
    try:
        hdr = png_header(path)
    except OSError as exc:
        raise LightFieldReadError(f"{path}: cannot open ({exc})") from None
    if hdr is not None:
        c = {0: 1, 2: 3, 4: 2, 6: 4, 3: 3}.get(hdr["color_type"], 3)
        shape = (hdr["height"], hdr["width"]) + ((c,) if c in (3, 4) else ())
        return shape, np.dtype(np.uint16 if hdr["bit_depth"] == 16 else np.uint8)
    try:
        from PIL import Image

        with Image.open(path) as im:
            w, h = im.size
            mode = im.mode
    except Exception as exc:  # noqa: BLE001
        raise LightFieldReadError(f"{path}: not a readable image ({type(exc).__name__}: {exc})") from None
    c = {"RGB": 3, "RGBA": 4, "CMYK": 3, "P": 3, "YCbCr": 3}.get(mode, 1)
    dtype = np.uint16 if mode.startswith("I;16") else (np.float32 if mode == "F" else np.uint8)
    return (h, w) + ((c,) if c > 1 else ()), np.dtype(dtype)


def _pil_mode(path) -> str | None:
    """Pillow's mode of the image at ``path`` (its header only), or None where Pillow cannot open it."""
    try:
        from PIL import Image

        with Image.open(path) as im:
            return im.mode
    except Exception:  # noqa: BLE001 - any reader failure: not Pillow's image
        return None


def read_image(path) -> np.ndarray:
    """Decode one image to its native dtype, shape (H, W) or (H, W, C).

    A CMYK image (a JPEG from print workflows) comes back as RGB, converted
    as Pillow converts it.

    Raises
    ------
    LightFieldReadError
        If the file is truncated, corrupt or not an image.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    ext = path.suffix.lower()
    try:
        if ext in TIFF_EXTENSIONS:
            import tifffile

            img = tifffile.imread(path)
        else:
            hdr = png_header(path)
            if needs_own_decoder(hdr):
                img = read_png16(path)
            else:
                import imageio.v3 as iio

                # called from worker threads: no warnings.catch_warnings here, whose save and
                # restore of the process-wide filters is not thread-safe
                img = iio.imread(path)
                if np.ndim(img) == 3 and np.shape(img)[2] == 4 and _pil_mode(path) == "CMYK":
                    img = iio.imread(path, mode="RGB")  # ink amounts, not RGBA: Pillow's conversion
    except (PNGError, Exception) as exc:  # noqa: BLE001 - any decoder failure
        if isinstance(exc, FileNotFoundError):
            raise
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""  # not the decoder's install advice
        raise LightFieldReadError(
            f"{path}: cannot decode the image; it is truncated, corrupt or not an image "
            f"({type(exc).__name__}: {first})"
        ) from None
    img = np.asarray(img)
    if img.ndim == 0 or img.size == 0:
        raise LightFieldReadError(f"{path}: the image is empty")
    return _squeeze_channels(img, path)
