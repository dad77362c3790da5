"""sensor_msgs/Image <-> numpy without cv_bridge.

Works on anything with the Image fields (an rclpy message, a rosbags message, a plain object):
``height``, ``width``, ``encoding``, ``step``, ``is_bigendian``, ``data``. Every disagreement
between those fields raises :class:`ImageFormatError` with a message that names it.
"""

from __future__ import annotations

import array
from dataclasses import dataclass

import numpy as np

from simreal_nodes.errors import ImageFormatError

# encoding -> (numpy dtype, channels)
ENCODINGS: dict[str, tuple[np.dtype, int]] = {
    "rgb8": (np.dtype(np.uint8), 3),
    "bgr8": (np.dtype(np.uint8), 3),
    "rgba8": (np.dtype(np.uint8), 4),
    "bgra8": (np.dtype(np.uint8), 4),
    "mono8": (np.dtype(np.uint8), 1),
    "mono16": (np.dtype(np.uint16), 1),
    "8UC1": (np.dtype(np.uint8), 1),
    "8UC3": (np.dtype(np.uint8), 3),
    "16UC1": (np.dtype(np.uint16), 1),
    "16SC1": (np.dtype(np.int16), 1),
    "32FC1": (np.dtype(np.float32), 1),
    "64FC1": (np.dtype(np.float64), 1),
}

DEPTH_ENCODINGS = ("16UC1", "32FC1", "mono16")


@dataclass(frozen=True)
class ImageFields:
    """The fields of a sensor_msgs/Image, ready to be assigned to a message."""

    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: bytes


def image_to_array(msg, copy: bool = False) -> np.ndarray:
    """Return the pixels of an Image message as an (H, W) or (H, W, C) array.

    Respects ``step`` (row padding) and ``is_bigendian``. The array is a read-only view
    of the message buffer unless ``copy`` is true or a byte swap or repacking was needed.
    """
    enc = str(msg.encoding)
    if enc not in ENCODINGS:
        raise ImageFormatError(
            f"image encoding '{enc}' is not supported (supported: {', '.join(ENCODINGS)})")
    dtype, channels = ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if h <= 0 or w <= 0:
        raise ImageFormatError(f"image size {w}x{h} is empty")
    row_bytes = w * channels * dtype.itemsize
    if step < row_bytes:
        raise ImageFormatError(
            f"image step {step} is smaller than width*channels*bytes = {w}*{channels}*"
            f"{dtype.itemsize} = {row_bytes} for encoding '{enc}'")
    buf = msg.data
    if not isinstance(buf, (bytes, bytearray, memoryview, np.ndarray, array.array)):
        buf = bytes(buf)
    raw = np.frombuffer(buf, dtype=np.uint8)  # rclpy's array.array: a view of the message's own buffer, no copy
    raw.flags.writeable = False
    need = step * (h - 1) + row_bytes
    if raw.size < need:
        raise ImageFormatError(
            f"image data has {raw.size} bytes but {h} rows of step {step} need at least {need} "
            f"({w}x{h} '{enc}')")
    if raw.size > step * h:
        raise ImageFormatError(
            f"image data has {raw.size} bytes, more than height*step = {h}*{step} = {step * h}")
    rows = np.lib.stride_tricks.as_strided(raw, shape=(h, row_bytes), strides=(step, 1))
    dense = step == row_bytes and raw.size == step * h  # rows back to back: view the buffer as it is
    pix = raw.view(dtype) if dense else np.ascontiguousarray(rows).view(dtype)
    pix = pix.reshape(h, w, channels) if channels > 1 else pix.reshape(h, w)
    if dtype.itemsize > 1 and bool(msg.is_bigendian) != (np.little_endian is False):
        pix = pix.byteswap()
    return pix.copy() if copy else pix


def array_to_image_fields(img: np.ndarray, encoding: str) -> ImageFields:
    """Pack an array into Image fields (little-endian, no padding)."""
    if encoding not in ENCODINGS:
        raise ImageFormatError(f"image encoding '{encoding}' is not supported")
    dtype, channels = ENCODINGS[encoding]
    img = np.asarray(img)
    if img.ndim == 2:
        c = 1
    elif img.ndim == 3:
        c = img.shape[2]
    else:
        raise ImageFormatError(f"an image array must be 2-D or 3-D, got shape {img.shape}")
    if c != channels:
        raise ImageFormatError(f"encoding '{encoding}' has {channels} channels, array has {c}")
    if img.dtype != dtype:
        raise ImageFormatError(f"encoding '{encoding}' needs dtype {dtype}, array has {img.dtype}")
    img = np.ascontiguousarray(img)
    if not np.little_endian:  # pragma: no cover - big-endian hosts
        img = img.astype(img.dtype.newbyteorder("<"))
    h, w = img.shape[:2]
    return ImageFields(h, w, encoding, 0, w * channels * dtype.itemsize, img.tobytes())


def fill_image_msg(msg, img: np.ndarray, encoding: str):
    """Fill an rclpy sensor_msgs/Image in place (fast path: array.array for ``data``)."""
    f = array_to_image_fields(img, encoding)
    msg.height, msg.width, msg.encoding = f.height, f.width, f.encoding
    msg.is_bigendian, msg.step = f.is_bigendian, f.step
    msg.data = array.array("B", f.data)
    return msg


def to_bgr8(img: np.ndarray, encoding: str) -> np.ndarray:
    """Colour or grey image to a contiguous BGR uint8 array (what OpenCV and our nodes use)."""
    import cv2

    if encoding == "bgr8" or encoding == "8UC3":
        return np.ascontiguousarray(img)
    if encoding == "rgb8":
        return cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    if encoding == "rgba8":
        return cv2.cvtColor(img, cv2.COLOR_RGBA2BGR)
    if encoding == "bgra8":
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    if encoding in ("mono8", "8UC1"):
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if encoding == "mono16":
        return cv2.cvtColor((img >> 8).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    raise ImageFormatError(f"encoding '{encoding}' is not a colour or grey image")


def to_gray8(img: np.ndarray, encoding: str) -> np.ndarray:
    """Colour or grey image to a grey uint8 array (what feature detection takes); a grey image of another type
    is scaled so that its largest value is 255."""
    import cv2

    if img.ndim == 2:
        return img if img.dtype == np.uint8 else cv2.convertScaleAbs(img, alpha=255.0 / max(float(img.max()), 1.0))
    return cv2.cvtColor(to_bgr8(img, encoding), cv2.COLOR_BGR2GRAY)


def depth_to_metres(img: np.ndarray, encoding: str) -> np.ndarray:
    """Depth image to float32 metres with NaN for invalid pixels.

    16UC1 / mono16 are millimetres with 0 invalid (REP-118); 32FC1 is metres with 0, NaN or
    +-inf invalid. Negative depths are invalid too.
    """
    if encoding in ("16UC1", "mono16"):
        d = img.astype(np.float32) * np.float32(1e-3)
        d[img == 0] = np.nan
        return d
    if encoding == "32FC1":
        d = np.array(img, dtype=np.float32, copy=True)
        d[~np.isfinite(d) | (d <= 0)] = np.nan
        return d
    raise ImageFormatError(
        f"depth encoding '{encoding}' is not supported (16UC1 millimetres or 32FC1 metres)")


def bgr8_of(msg) -> np.ndarray:
    """:func:`to_bgr8` of an Image message's pixels."""
    return to_bgr8(image_to_array(msg), msg.encoding)


def gray8_of(msg) -> np.ndarray:
    """:func:`to_gray8` of an Image message's pixels."""
    return to_gray8(image_to_array(msg), msg.encoding)


def depth_metres_of(msg) -> np.ndarray:
    """:func:`depth_to_metres` of a depth Image message's pixels."""
    return depth_to_metres(image_to_array(msg), msg.encoding)


def decode_compressed(msg) -> tuple[np.ndarray, str]:
    """sensor_msgs/CompressedImage (jpeg / png, image_transport's 'compressed' plugin) -> (array, encoding)."""
    import cv2

    fmt = str(getattr(msg, "format", "")).lower()
    if "compresseddepth" in fmt:
        raise ImageFormatError(f"compressedDepth images are not supported here (format '{msg.format}')")
    buf = np.frombuffer(bytes(msg.data) if not isinstance(msg.data, np.ndarray) else msg.data, dtype=np.uint8)
    if buf.size == 0:
        raise ImageFormatError("compressed image has no data")
    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageFormatError(f"compressed image (format '{msg.format}') cannot be decoded")
    if img.ndim == 2:
        return img, "mono8" if img.dtype == np.uint8 else "mono16"
    if img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img, "bgr8"
