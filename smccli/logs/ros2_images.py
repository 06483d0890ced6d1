"""ROS image messages to arrays: colour (``sensor_msgs/Image`` rgb8 or bgr8, or a
``CompressedImage``) and depth (``Image`` 16UC1 or 32FC1, or image_transport's
``compressedDepth``)."""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

from smccli.errors import LogError


def ros_rgb(msg: Any, where: str) -> np.ndarray:
    """A colour Image (rgb8, bgr8) or CompressedImage -> RGB (H, W, 3) uint8; LogError
    (``where``: the bag and topic) when it does not decode."""
    from smccli.logs.topics import decode_color

    if hasattr(msg, "format"):  # CompressedImage
        rgb = decode_color(bytes(msg.data))
        if rgb is None:
            raise LogError(f"{where}: image does not decode (format {msg.format!r})")
        return rgb
    enc = msg.encoding.lower()
    if enc not in ("rgb8", "bgr8"):
        raise LogError(f"{where}: encoding {msg.encoding!r}, expected rgb8 or bgr8")
    img = _rows(msg, 3, np.uint8)
    return img[:, :, ::-1].copy() if enc == "bgr8" else img


def ros_depth(msg: Any, shape: tuple[int, ...], scale: float, where: str) -> np.ndarray:
    """A depth Image (16UC1 times ``scale`` [m per unit], or 32FC1 [m]) or a compressedDepth
    CompressedImage -> depth [m], float32 (H, W); LogError (``where``: the bag and topic)
    when it does not decode or its size is not the colour image's ``shape`` (H, W)."""
    if hasattr(msg, "format"):  # CompressedImage
        depth = compressed_depth(bytes(msg.data), msg.format, scale)
        if isinstance(depth, str):
            raise LogError(f"{where}: {depth}")
        if depth.shape != shape:
            raise LogError(
                f"{where}: depth {depth.shape[1]}x{depth.shape[0]} differs "
                f"from the colour image's {shape[1]}x{shape[0]}"
            )
        return depth
    enc = msg.encoding.upper()
    if enc == "16UC1":
        img = _rows(msg, 1, np.dtype("<u2") if not msg.is_bigendian else np.dtype(">u2"))
        # In float64, then float32: for millimetres with scale 0.001 this equals the native
        # reader's mm / 1000 for every 16-bit value (float32 * 0.001 differs for 38850).
        depth = (img.astype(np.float64) * scale).astype(np.float32)
    elif enc == "32FC1":
        img = _rows(msg, 1, np.dtype("<f4") if not msg.is_bigendian else np.dtype(">f4"))
        depth = np.nan_to_num(img.astype(np.float32), nan=0.0, posinf=0.0)
    else:
        raise LogError(f"{where}: encoding {msg.encoding!r}, expected 16UC1 or 32FC1")
    depth = depth.reshape(msg.height, msg.width)
    if depth.shape != shape:
        raise LogError(
            f"{where}: depth {msg.width}x{msg.height} differs from the colour "
            f"image's {shape[1]}x{shape[0]}"
        )
    return depth


COMPRESSED_DEPTH_HEADER = struct.Struct("<iff")
"""image_transport's compressedDepth header before the PNG: the format (-1 undefined, 0
inverse depth) and the two quantisation parameters of a 32FC1 image's inverse depth."""


def compressed_depth(data: bytes, fmt: str, scale: float) -> np.ndarray | str:
    """A ``compressedDepth`` CompressedImage (image_transport's plugin, as RealSense users
    record depth) -> depth [m], float32 (h, w), 0 where there is none; or why it cannot be
    read (one line). 16UC1 is the PNG's values times ``scale``; 32FC1 is quantised inverse
    depth: depth = a / (v - b) for v > 0, a and b from the header."""
    import cv2

    kind = fmt.lower()
    if "compresseddepth" not in kind:
        return f"format {fmt!r}: a depth CompressedImage must be compressedDepth (PNG)"
    if "rvl" in kind:
        return (
            f"format {fmt!r}: compressedDepth RVL is not read; record with the plugin's "
            "format png, or republish the depth raw"
        )
    n = COMPRESSED_DEPTH_HEADER.size
    if len(data) <= n:
        return f"format {fmt!r}: {len(data)} bytes, no image after the {n}-byte header"
    _, a, b = COMPRESSED_DEPTH_HEADER.unpack(data[:n])
    img = cv2.imdecode(np.frombuffer(data[n:], dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 2:
        return f"format {fmt!r}: the image after the header is not a 16-bit PNG"
    encoding = fmt.split(";")[0].strip().upper()
    if encoding == "16UC1":
        # In float64, then float32, as a raw 16UC1 image (the same values to the bit).
        return (img.astype(np.float64) * scale).astype(np.float32)
    if encoding == "32FC1":
        v = img.astype(np.float32)
        with np.errstate(divide="ignore"):
            depth = np.where(v > 0, np.float32(a) / (v - np.float32(b)), 0.0)
        return np.nan_to_num(depth.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    return f"format {fmt!r}: encoding {encoding!r}, expected 16UC1 or 32FC1"


def _rows(msg: Any, channels: int, dtype: Any) -> np.ndarray:
    """The pixels of a sensor_msgs/Image, rows of ``step`` bytes (padding dropped)."""
    dt = np.dtype(dtype)
    row = msg.width * channels * dt.itemsize
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.step)[:, :row]
    img = raw.copy().view(dt).reshape(msg.height, msg.width, channels)
    return img[:, :, 0] if channels == 1 else img
