"""Frame sources for the camera ingest: a video file, an image folder, a bag (ROS-free).

Each yields :class:`Frame` objects; a frame that cannot be decoded is yielded with ``error`` set
(and no pixels) so that the caller reports it and goes on.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simreal_nodes.errors import SimrealError
from simreal_nodes.io import bags, images

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")


@dataclass
class Frame:
    index: int
    stamp_ns: int
    image: np.ndarray | None = None  # BGR uint8 or mono8
    encoding: str = "bgr8"
    depth: np.ndarray | None = None  # raw depth array (encoding below)
    depth_encoding: str = ""
    camera_info: object | None = None  # a CameraInfo-like message from a bag
    error: str = ""


def video_frames(path: str | Path, rate_hz: float | None = None) -> Iterator[Frame]:
    import cv2

    path = Path(path)
    if not path.exists():
        raise SimrealError(f"video file not found: {path}")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise SimrealError(f"cannot open video {path} (unknown container or codec)")
    fps = cap.get(cv2.CAP_PROP_FPS) or 0.0
    period = 1.0 / (rate_hz or fps or 30.0)
    i = 0
    try:
        while True:
            ok, img = cap.read()
            if not ok:
                return
            yield Frame(i, round(i * period * 1e9), img, "bgr8")
            i += 1
    finally:
        cap.release()


def folder_frames(path: str | Path, rate_hz: float = 30.0) -> Iterator[Frame]:
    import cv2

    path = Path(path)
    if not path.is_dir():
        raise SimrealError(f"image folder not found: {path}")
    files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise SimrealError(f"image folder {path} has no images ({', '.join(IMAGE_SUFFIXES)})")
    for i, f in enumerate(files):
        stamp = round(i / rate_hz * 1e9)
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        if img is None:
            yield Frame(i, stamp, error=f"cannot decode image {f.name}")
            continue
        if img.ndim == 2:
            enc = "mono8" if img.dtype == np.uint8 else "mono16"
        elif img.shape[2] == 4:
            img, enc = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR), "bgr8"
        else:
            enc = "bgr8"
        if img.dtype != np.uint8 and enc != "mono16":
            yield Frame(i, stamp, error=f"{f.name}: unsupported pixel type {img.dtype}")
            continue
        yield Frame(i, stamp, img, enc)


def bag_frames(path: str | Path, image_topic: str, info_topic: str, depth_topic: str | None = None,
               report: bags.BagReport | None = None) -> Iterator[Frame]:
    """Frames of a bag: each image with the latest CameraInfo and the depth of the same stamp."""
    wanted = [t for t in (image_topic, image_topic + "/compressed", info_topic, depth_topic) if t]
    info = None
    pending_depth: dict[int, tuple[np.ndarray, str]] = {}
    pending_img: list[tuple[int, int, object]] = []
    i = 0

    def make(stamp, msg):
        nonlocal i
        f = Frame(i, stamp, camera_info=info)
        i += 1
        try:
            if hasattr(msg, "format"):  # CompressedImage
                f.image, f.encoding = images.decode_compressed(msg)
            else:
                f.image, f.encoding = images.image_to_array(msg), msg.encoding
        except images.ImageFormatError as e:
            f.error = str(e)
        if depth_topic and stamp in pending_depth:
            f.depth, f.depth_encoding = pending_depth.pop(stamp)
        return f

    for m in bags.read_bag(path, report, topics=wanted):
        try:
            obj = bags.decode(m)
        except Exception as e:  # noqa: BLE001
            if m.topic == image_topic:
                yield Frame(i, m.log_time_ns, error=f"undecodable image message: {e}")
                i += 1
            continue
        if m.topic == info_topic:
            info = obj
        elif m.topic == depth_topic:
            with contextlib.suppress(images.ImageFormatError):
                pending_depth[bags.stamp_ns(obj)] = (images.image_to_array(obj, copy=True), obj.encoding)
        elif m.topic in (image_topic, image_topic + "/compressed"):
            pending_img.append((bags.stamp_ns(obj), m.log_time_ns, obj))
        # images wait (briefly) for their depth of the same stamp
        while pending_img and (not depth_topic or pending_img[0][0] in pending_depth or len(pending_img) > 3):
            stamp, _, msg = pending_img.pop(0)
            yield make(stamp, msg)
    for stamp, _, msg in pending_img:
        yield make(stamp, msg)


def open_source(source: str, path: str, rate_hz: float, image_topic: str = "", info_topic: str = "",
                depth_topic: str | None = None) -> Iterator[Frame]:
    """The frames of a file source: ``video``, ``images`` (a folder) at ``rate_hz``, or ``bag`` (its image, CameraInfo
    and depth topics)."""
    if source == "video":
        return video_frames(path, rate_hz)
    if source == "images":
        return folder_frames(path, rate_hz)
    if source == "bag":
        return bag_frames(path, image_topic, info_topic, depth_topic)
    raise SimrealError(f"unknown source '{source}'")
