"""Serialized (CDR) ROS 2 messages written straight from numpy arrays, for messages whose bulk is a long
sequence of small structs: building them as rclpy message objects costs a Python object per element
(a mesh MarkerArray of 3 700 vertices took ~110 ms to build and convert). A publisher accepts the bytes.

CDR as ROS 2 writes it: a 4-byte encapsulation header (little-endian CDR), then every primitive aligned
to its own size counted from the end of that header; strings as uint32 length (with the terminating
NUL) + bytes + NUL; sequences as uint32 count + elements.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np


class CdrWriter:
    def __init__(self):
        self.buf = bytearray(b"\x00\x01\x00\x00")  # CDR_LE

    def _align(self, n: int) -> None:
        self.buf += b"\x00" * ((-(len(self.buf) - 4)) % n)

    def i32(self, v: int) -> None:
        self._align(4)
        self.buf += struct.pack("<i", int(v))

    def u32(self, v: int) -> None:
        self._align(4)
        self.buf += struct.pack("<I", int(v))

    def boolean(self, v: bool) -> None:
        self.buf += b"\x01" if v else b"\x00"

    def f64(self, *vals: float) -> None:
        self._align(8)
        self.buf += struct.pack(f"<{len(vals)}d", *vals)

    def f32(self, *vals: float) -> None:
        self._align(4)
        self.buf += struct.pack(f"<{len(vals)}f", *vals)

    def string(self, s: str) -> None:
        b = s.encode() + b"\x00"
        self.u32(len(b))
        self.buf += b

    def array(self, a: np.ndarray, dtype: str) -> None:
        """A sequence of fixed-size structs of one primitive type: count, then the rows' values."""
        a = np.ascontiguousarray(a, dtype=dtype)
        self.u32(len(a))
        if len(a):
            self._align(a.dtype.itemsize)
            self.buf += a.tobytes()

    def time(self, stamp_ns: int) -> None:
        self.i32(stamp_ns // 1_000_000_000)
        self.u32(stamp_ns % 1_000_000_000)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        self.time(stamp_ns)
        self.string(frame_id)

    def bytes(self) -> bytes:
        return bytes(self.buf)


LINE_STRIP, TRIANGLE_LIST, ADD = 4, 11, 0


@dataclass
class TriangleListMarker:
    """A visualization_msgs/Marker TRIANGLE_LIST with per-vertex colours (3 rows per triangle); with ``kind``
    LINE_STRIP a polyline of ``width`` (the marker's scale.x) through the points, coloured per point."""

    ns: str
    id: int
    pose: np.ndarray  # 4x4, the marker's frame in the header's frame
    points: np.ndarray  # (3 n_triangles, 3) metres
    colors: np.ndarray  # (3 n_triangles, 3 or 4) in 0..1
    kind: int = TRIANGLE_LIST
    width: float = 1.0


def marker_array_cdr(markers: list[TriangleListMarker], stamp_ns: int, frame_id: str) -> bytes:
    """visualization_msgs/msg/MarkerArray of triangle-list (or line-strip) markers, serialized."""
    from simreal_nodes.geometry import matrix_to_quat

    w = CdrWriter()
    w.u32(len(markers))
    for m in markers:
        w.header(stamp_ns, frame_id)
        w.string(m.ns)
        w.i32(m.id)
        w.i32(m.kind)
        w.i32(ADD)
        T = np.asarray(m.pose, dtype=np.float64)
        w.f64(*T[:3, 3], *matrix_to_quat(T[:3, :3]))  # pose: position, orientation (x, y, z, w)
        w.f64(m.width if m.kind == LINE_STRIP else 1.0, 1.0, 1.0)  # scale (x: a line strip's width)
        w.f32(1.0, 1.0, 1.0, 1.0)  # colour (per-vertex colours are used)
        w.time(0)  # lifetime: forever
        w.boolean(False)  # frame_locked
        pts = np.asarray(m.points, dtype=np.float64).reshape(-1, 3)
        col = np.asarray(m.colors, dtype=np.float32)
        if col.ndim != 2 or len(col) != len(pts) or col.shape[1] not in (3, 4):
            raise ValueError(f"marker '{m.ns}': {col.shape} colours for {len(pts)} points (expected (n, 3|4))")
        w.array(pts, "<f8")
        if col.shape[1] == 3:
            col = np.c_[col, np.ones(len(col), np.float32)]
        w.array(col, "<f4")
        w.string("")  # texture_resource
        w.header(0, "")  # texture (sensor_msgs/CompressedImage): header,
        w.string("")  # format,
        w.u32(0)  # data
        w.u32(0)  # uv_coordinates
        w.string("")  # text
        w.string("")  # mesh_resource
        w.string("")  # mesh_file: filename,
        w.u32(0)  # data
        w.boolean(False)  # mesh_use_embedded_materials
    return w.bytes()
