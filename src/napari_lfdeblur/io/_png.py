"""A small PNG codec for what Pillow cannot do: 16-bit colour.

Pillow reads a 16-bit RGB(A) PNG as 8-bit, silently dropping the low byte, and
cannot write one. This module writes PNGs of any of our bit depths (8 or 16,
gray, gray+alpha, RGB, RGBA) and reads non-interlaced 16-bit PNGs exactly.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_COLOR_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}  # colour type -> samples per pixel


class PNGError(ValueError):
    """A PNG file is malformed or uses a feature this codec does not handle."""


def png_header(path) -> dict | None:
    """Return ``{'width', 'height', 'bit_depth', 'color_type', 'interlace'}``
    from a PNG's IHDR, or None if the file is not a PNG."""
    with open(path, "rb") as fh:
        head = fh.read(33)
    if len(head) < 33 or head[:8] != _SIGNATURE or head[12:16] != b"IHDR":
        return None
    w, h, depth, ctype, _comp, _filt, interlace = struct.unpack(">IIBBBBB", head[16:29])
    return {"width": w, "height": h, "bit_depth": depth, "color_type": ctype, "interlace": interlace}


def png_text(path) -> dict:
    """The ``tEXt`` chunks before a PNG's image data, ``{keyword: value}`` (empty for other files)."""
    out = {}
    with open(path, "rb") as fh:
        if fh.read(8) != _SIGNATURE:
            return out
        while True:
            head = fh.read(8)
            if len(head) < 8:
                return out
            size, kind = struct.unpack(">I", head[:4])[0], head[4:]
            if kind in (b"IDAT", b"IEND"):
                return out
            body = fh.read(size)
            fh.seek(4, 1)  # the CRC
            if kind == b"tEXt" and b"\0" in body:
                key, _, value = body.partition(b"\0")
                out[key.decode("latin-1")] = value.decode("latin-1")


def needs_own_decoder(header: dict | None) -> bool:
    """True for PNGs that Pillow would decode lossily (16-bit with colour or alpha)."""
    return bool(header) and header["bit_depth"] == 16 and header["color_type"] in (2, 4, 6)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def write_png(path, img: np.ndarray, *, level: int = 6, text: dict | None = None) -> None:
    """Write a uint8 or uint16 image of shape (H, W) or (H, W, C), C in 1..4.

    Rows use the PNG "Up" filter, which compresses smooth images well and
    decodes fast. ``text`` (Latin-1 keywords and values) goes into ``tEXt``
    chunks, which :func:`png_text` reads back.
    """
    img = np.asarray(img)
    if img.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"write_png needs uint8 or uint16, not {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim not in (2, 3):
        raise ValueError(f"write_png needs a 2D or 3D image, not shape {img.shape}")
    h, w = img.shape[:2]
    c = 1 if img.ndim == 2 else img.shape[2]
    ctype = {1: 0, 2: 4, 3: 2, 4: 6}[c]
    depth = 16 if img.dtype == np.uint16 else 8
    raw = np.ascontiguousarray(img.astype(">u2" if depth == 16 else np.uint8)).view(np.uint8).reshape(h, -1)
    up = raw.copy()
    up[1:] -= raw[:-1]  # uint8 arithmetic wraps, as the filter wants
    data = np.concatenate([np.full((h, 1), 2, np.uint8), up], axis=1).tobytes()
    ihdr = struct.pack(">IIBBBBB", w, h, depth, ctype, 0, 0, 0)
    texts = b"".join(_chunk(b"tEXt", k.encode("latin-1") + b"\0" + v.encode("latin-1"))
                     for k, v in (text or {}).items())
    blob = (_SIGNATURE + _chunk(b"IHDR", ihdr) + texts + _chunk(b"IDAT", zlib.compress(data, level))
            + _chunk(b"IEND", b""))
    with open(path, "wb") as fh:
        fh.write(blob)


def _unfilter(data: np.ndarray, h: int, stride: int, bpp: int) -> np.ndarray:
    """Undo the PNG row filters; returns the (h, stride) raw bytes."""
    rows = data.reshape(h, stride + 1)
    ftypes = rows[:, 0]
    if ftypes.max(initial=0) > 4:
        raise PNGError(f"unknown PNG row filter type {int(ftypes.max())}")
    if np.any(ftypes >= 3):
        return _unfilter_wavefront(rows[:, 1:], ftypes, stride // bpp, bpp)
    out = np.empty((h, stride), np.uint8)
    prev = np.zeros(stride, np.uint8)
    for r in range(h):
        line = rows[r, 1:]
        ft = ftypes[r]
        if ft == 0:
            cur = line
        elif ft == 1:  # Sub: running sum along the row, per byte lane (uint8 wraps)
            cur = np.cumsum(line.reshape(-1, bpp), axis=0, dtype=np.uint8).reshape(-1)
        else:  # Up
            cur = line + prev
        out[r] = cur
        prev = out[r]
    return out


def _unfilter_wavefront(filtered: np.ndarray, ftypes: np.ndarray, w: int, bpp: int) -> np.ndarray:
    """Undo any mix of the five PNG filters, vectorised along anti-diagonals.

    Pixel (r, j) depends on its left, upper and upper-left neighbours only, so
    all pixels with the same r + j can be decoded at once: h + w - 1 numpy
    steps instead of h * w Python steps.
    """
    h = filtered.shape[0]
    f = filtered.reshape(h, w, bpp).astype(np.int16)
    x = np.zeros((h + 1, w + 1, bpp), np.int16)  # one row and column of zero padding
    types = ftypes.astype(np.int16)
    for d in range(h + w - 1):
        r = np.arange(max(0, d - (w - 1)), min(h - 1, d) + 1)
        j = d - r
        a = x[r + 1, j]  # left
        b = x[r, j + 1]  # up
        c = x[r, j]  # up-left
        t = types[r][:, None]
        p = a + b - c
        pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
        paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
        pred = np.where(t == 4, paeth, np.where(t == 3, (a + b) >> 1, np.where(t == 2, b, np.where(t == 1, a, 0))))
        x[r + 1, j + 1] = (f[r, j] + pred) & 0xFF
    return x[1:, 1:].astype(np.uint8).reshape(h, w * bpp)


def read_png16(path) -> np.ndarray:
    """Decode a non-interlaced 16-bit PNG to uint16, shape (H, W) or (H, W, C).

    Raises
    ------
    PNGError
        If the file is truncated, corrupt, interlaced or not 16-bit.
    """
    path = Path(path)
    blob = path.read_bytes()
    if blob[:8] != _SIGNATURE:
        raise PNGError("not a PNG file")
    pos = 8
    header = None
    idat = []
    ended = False
    while pos + 8 <= len(blob):
        (length,) = struct.unpack(">I", blob[pos : pos + 4])
        kind = blob[pos + 4 : pos + 8]
        data = blob[pos + 8 : pos + 8 + length]
        if len(data) < length or pos + 12 + length > len(blob):
            raise PNGError(f"the file is truncated inside the {kind.decode('latin-1')} chunk")
        (crc,) = struct.unpack(">I", blob[pos + 8 + length : pos + 12 + length])
        if zlib.crc32(kind + data) & 0xFFFFFFFF != crc:
            raise PNGError(f"the {kind.decode('latin-1')} chunk is corrupt (CRC mismatch)")
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", data[:13])
        elif kind == b"IDAT":
            idat.append(data)
        elif kind == b"IEND":
            ended = True
            break
        pos += 12 + length
    if header is None:
        raise PNGError("the PNG has no IHDR chunk")
    if not ended:
        raise PNGError("the file is truncated (no IEND chunk)")
    w, h, depth, ctype, _c, _f, interlace = header
    if depth != 16 or ctype not in _COLOR_CHANNELS:
        raise PNGError(f"read_png16 handles 16-bit gray/colour PNGs, not bit depth {depth}, colour type {ctype}")
    if interlace:
        raise PNGError("interlaced 16-bit PNGs are not supported; re-save the image without interlacing")
    channels = _COLOR_CHANNELS[ctype]
    bpp = 2 * channels
    stride = w * bpp
    try:
        raw = zlib.decompress(b"".join(idat))
    except zlib.error as exc:
        raise PNGError(f"the image data is corrupt ({exc})") from None
    if len(raw) != h * (stride + 1):
        raise PNGError(f"the image data has {len(raw)} bytes, expected {h * (stride + 1)} (truncated or corrupt)")
    pix = _unfilter(np.frombuffer(raw, np.uint8), h, stride, bpp)
    img = pix.view(">u2").astype(np.uint16).reshape(h, w, channels)
    return img[..., 0] if channels == 1 else img
