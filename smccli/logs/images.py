"""Camera images in a log: their size from the header (JPEG, PNG) without decoding, and
their decoding to RGB and metric depth."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from smccli.logs import topics as tp
from smccli.logs.checks import message_error


def decode_color(path: Path, t_ns: int, fmt: str, data: bytes) -> np.ndarray:
    rgb = tp.decode_color(data)
    if rgb is None:
        raise message_error(path, tp.COLOR, t_ns, f"image does not decode {image_kind(fmt, data)}")
    return rgb


def decode_depth(
    path: Path, t_ns: int, fmt: str, data: bytes, shape: tuple[int, ...]
) -> np.ndarray:
    """Depth image [m], shape (H, W) float32, of the colour image of shape ``shape``."""
    shape = shape[:2]
    img = tp.decode_image(data)
    if img is None:
        raise message_error(path, tp.DEPTH, t_ns, f"image does not decode {image_kind(fmt, data)}")
    if img.ndim != 2 or img.dtype != np.uint16:
        found = f"{img.dtype} {'x'.join(str(n) for n in img.shape)}"
        raise message_error(
            path, tp.DEPTH, t_ns, f"expected a 16-bit one-channel image, found {found}"
        )
    if img.shape != shape:
        raise message_error(
            path,
            tp.DEPTH,
            t_ns,
            f"depth {img.shape[1]}x{img.shape[0]} differs from the colour image's "
            f"{shape[1]}x{shape[0]}",
        )
    return (img.astype(np.float32) / np.float32(tp.DEPTH_SCALE)).astype(np.float32)


_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


_JPEG_SOF = frozenset({0xC0, 0xC1, 0xC2})  # baseline, extended, progressive Huffman


_JPEG_PLAIN = _JPEG_SOF | {0xE0, 0xDB, 0xC4, 0xDD, 0xFE}  # + APP0 (JFIF), DQT, DHT, DRI, COM


def _jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(H, W) of a plain 8-bit three-component JPEG that ends with its EOI, else None."""
    if len(data) < 4 or data[:2] != b"\xff\xd8" or data[-2:] != b"\xff\xd9":
        return None
    pos, size = 2, None
    while pos + 4 <= len(data) and data[pos] == 0xFF:
        marker = data[pos + 1]
        if marker == 0xDA:  # start of scan: the headers are over
            return size
        if marker not in _JPEG_PLAIN:
            return None
        (n,) = struct.unpack_from(">H", data, pos + 2)
        if marker in _JPEG_SOF:
            if size is not None or n != 17 or pos + 2 + n > len(data):
                return None
            bits, h, w, n_comp = struct.unpack_from(">BHHB", data, pos + 4)
            if bits != 8 or n_comp != 3 or not (h and w):
                return None
            size = (h, w)
        pos += 2 + n
    return None


def _png_header(data: bytes) -> tuple[int, int, int, int] | None:
    """(H, W, bit depth, colour type) of a PNG of only IHDR, IDAT and IEND chunks, each with
    its CRC right and nothing after IEND, else None."""
    if data[:8] != _PNG_MAGIC:
        return None
    view = memoryview(data)
    pos, header, idat = 8, None, False
    while pos + 12 <= len(data):
        n, kind = struct.unpack_from(">I4s", data, pos)
        end = pos + 12 + n
        if (
            end > len(data)
            or zlib.crc32(view[pos + 4 : end - 4]) != struct.unpack_from(">I", data, end - 4)[0]
        ):
            return None
        if kind == b"IHDR":
            if pos != 8 or n != 13:
                return None
            w, h, bits, colour, method, filt, interlace = struct.unpack_from(
                ">IIBBBBB", data, pos + 8
            )
            if method or filt or interlace > 1 or not (h and w):
                return None
            header = (h, w, bits, colour)
        elif kind == b"IEND":
            return header if idat and end == len(data) else None
        elif kind == b"IDAT" and header is not None:
            idat = True
        else:
            return None
        pos = end
    return None


def color_size(data: bytes) -> tuple[int, int] | None:
    """(H, W) of a colour image that decodes to 8-bit three channels, judged by its header."""
    size = _jpeg_size(data)
    if size is None:
        png = _png_header(data)
        size = png[:2] if png is not None and png[2:] == (8, 2) else None  # 8-bit RGB
    return size


def depth_size(data: bytes) -> tuple[int, int] | None:
    """(H, W) of a 16-bit one-channel PNG, judged by its header, else None."""
    png = _png_header(data)
    return png[:2] if png is not None and png[2:] == (16, 0) else None


def image_kind(fmt: str, data: bytes) -> str:
    return f"(format {fmt!r}, {len(data)} bytes)"
