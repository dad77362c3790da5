"""Helpers shared by tests: synthetic camera bags written with rosbags (no ROS needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simreal_nodes.io import bags


def camera_info_obj(ts, w, h, fx=500.0, stamp=(0, 0), frame="camera_optical_frame", zeros=False):
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    RoI = ts.types["sensor_msgs/msg/RegionOfInterest"]
    Info = ts.types["sensor_msgs/msg/CameraInfo"]
    k = np.zeros(9) if zeros else np.array([fx, 0, (w - 1) / 2, 0, fx, (h - 1) / 2, 0, 0, 1.0])
    p = np.zeros(12)
    p[:3], p[4:7], p[8:11] = k[:3], k[3:6], k[6:9]
    return Info(header=Header(stamp=Time(sec=stamp[0], nanosec=stamp[1]), frame_id=frame), height=h, width=w,
                distortion_model="plumb_bob", d=np.zeros(5), k=k, r=np.eye(3).ravel(), p=p,
                binning_x=0, binning_y=0, roi=RoI(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


def image_obj(ts, img, encoding, stamp=(0, 0), frame="camera_optical_frame", step=None, data=None):
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    Image = ts.types["sensor_msgs/msg/Image"]
    h, w = img.shape[:2]
    raw = np.ascontiguousarray(img).view(np.uint8).ravel()
    return Image(header=Header(stamp=Time(sec=stamp[0], nanosec=stamp[1]), frame_id=frame), height=h, width=w,
                 encoding=encoding, is_bigendian=0, step=step if step is not None else raw.size // h,
                 data=raw if data is None else data)


def frame_pixels(i: int, w: int, h: int) -> np.ndarray:
    """A deterministic textured frame whose first pixel row encodes the frame index."""
    rng = np.random.default_rng(i)
    img = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    img[0, :4, 0] = np.frombuffer(np.uint32(i).tobytes(), np.uint8)
    return img


def write_camera_bag(path: Path, n: int = 30, w: int = 160, h: int = 120, fps: float = 30.0, storage: str = "mcap",
                     bad_step: tuple[int, ...] = (), zero_info: bool = False, depth: bool = False,
                     start_s: int = 100) -> list[int]:
    """A bag with /camera/image_raw, /camera/camera_info (and depth). Returns image stamps (ns)."""
    ts = bags.typestore()
    stamps = []
    with bags.BagWriter(path, storage) as wr:
        for i in range(n):
            t = start_s * 10**9 + round(i * 1e9 / fps)
            st = (t // 10**9, t % 10**9)
            wr.write("/camera/camera_info", t, camera_info_obj(ts, w, h, stamp=st, zeros=zero_info),
                     "sensor_msgs/msg/CameraInfo")
            img = frame_pixels(i, w, h)
            # on the frames in bad_step the row step disagrees with the width
            msg = image_obj(ts, img, "rgb8", st, step=w * 3 - 7) if i in bad_step else image_obj(ts, img, "rgb8", st)
            wr.write("/camera/image_raw", t + 1000, msg, "sensor_msgs/msg/Image")
            if depth:
                d = np.full((h, w), 1000 + i, np.uint16)
                wr.write("/camera/depth/image_raw", t + 2000, image_obj(ts, d, "16UC1", st), "sensor_msgs/msg/Image")
            stamps.append(t)
    return stamps
