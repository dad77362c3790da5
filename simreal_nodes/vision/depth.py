"""Depth images to points (thesis §5.2.3-5.2.4), ROS-free.

    depth (metres, NaN invalid)  --decimate N-->  pixels (u, v) with valid Z
    X_c = Z K^-1 undistort([u, v])               (rays per pixel grid cached; distortion from CameraInfo)
    X_w = T_world_cam X_c

Decimation keeps every N-th pixel in each direction (N = 1: all), which is the collision node's
speed/accuracy knob: the distance to the nearest real point grows by at most ~N pixel footprints.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel


@functools.lru_cache(maxsize=16)
def _rays(width: int, height: int, K: tuple, D: tuple, model: str, step: int) -> np.ndarray:
    """(h', w', 3) rays with z = 1 through the decimated pixel grid, lens distortion removed (the depth image is
    registered to the distorted colour image); NaN where a fisheye pixel has no ray in front of the camera."""
    cam = CameraModel(width, height, np.asarray(K).reshape(3, 3), np.asarray(D), model)
    vs, us = np.mgrid[0:height:step, 0:width:step]
    uv = np.c_[us.ravel(), vs.ravel()].astype(np.float64)
    if cam.has_distortion:
        uv = cam.undistort_points(uv)
    return cam.backproject(uv, np.ones(len(uv))).reshape(vs.shape + (3,))


@dataclass
class DepthPoints:
    points: np.ndarray  # (n, 3) world frame (or camera frame when no pose is given)
    pixels: np.ndarray  # (n, 2) their pixel coordinates
    valid_fraction: float  # of the decimated pixels
    total: int  # decimated pixels considered


def depth_points(depth_m: np.ndarray, cam: CameraModel, step: int = 1, T_world_cam: np.ndarray | None = None,
                 min_depth: float = 0.05, max_depth: float = 10.0) -> DepthPoints:
    """Back-project a metric depth image (NaN / 0 / inf / negative invalid) decimated by ``step``."""
    d = np.asarray(depth_m)
    if d.ndim != 2:
        raise ValueError(f"depth image must be 2-D, got shape {d.shape}")
    if d.shape != (cam.height, cam.width):
        raise ValueError(f"depth image is {d.shape[1]}x{d.shape[0]}, CameraInfo says {cam.width}x{cam.height}")
    step = max(1, int(step))
    sub = d[::step, ::step].astype(np.float64)
    total = sub.size
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(sub) & (sub >= min_depth) & (sub <= max_depth)
    rays = _rays(cam.width, cam.height, tuple(cam.K.ravel()), tuple(np.ravel(cam.D)), cam.distortion_model,
                 step)  # distortion removed
    ok &= np.isfinite(rays[..., 0])
    vv, uu = np.nonzero(ok)
    z = sub[vv, uu]
    uv = np.stack([uu * step, vv * step], axis=1).astype(np.float64)
    P = rays[vv, uu] * z[:, None]
    if T_world_cam is not None:
        P = G.transform(np.asarray(T_world_cam, dtype=np.float64), P)
    return DepthPoints(P, uv, float(len(z)) / max(total, 1), total)


MAX_FOOTPRINT_PX = 4  # a depth pixel covers at most this many colour pixels a side (a much coarser depth camera)
# the footprints grown by this much, so that neighbours overlap where the lenses and the turn vary their spacing (a
# surface behind would show through a gap) and a near edge grows by under a twentieth of a pixel
FOOTPRINT_OVERLAP = 1.1
LENS_LUT_MARGIN = 64  # ideal pixels around the image that the lens table covers (points beyond: projected exactly)


@functools.lru_cache(maxsize=8)
def _lens_lut(width: int, height: int, K: tuple, D: tuple, model: str) -> tuple[np.ndarray, np.ndarray]:
    """The lens as a table: for every ideal pixel of the image grown by LENS_LUT_MARGIN, the distorted pixel its ray
    lands on (float32 maps, NaN where none); read bilinearly (within 1e-3 px of the exact projection)."""
    cam = CameraModel(width, height, np.asarray(K).reshape(3, 3), np.asarray(D), model)
    m = LENS_LUT_MARGIN
    vs, us = np.mgrid[-m:height + m, -m:width + m].astype(np.float64)
    rays = cam.backproject(np.c_[us.ravel(), vs.ravel()], np.ones(us.size))
    px = cam.project(rays).astype(np.float32)
    return px[:, 0].reshape(us.shape), px[:, 1].reshape(us.shape)


def _project_fast(cam: CameraModel, pts: np.ndarray) -> np.ndarray:
    """(N, 2) pixels of camera-frame points in front of ``cam``: the pinhole projection, then the lens read off its
    table (:func:`_lens_lut`); points whose ideal pixel falls outside the table projected exactly."""
    ideal = cam.project(pts, distort=False)
    if not cam.has_distortion:
        return ideal
    mx, my = _lens_lut(cam.width, cam.height, tuple(cam.K.ravel()), tuple(np.ravel(cam.D)), cam.distortion_model)
    m = LENS_LUT_MARGIN
    q = (ideal + m).astype(np.float32)
    with np.errstate(invalid="ignore"):
        inside = (q[:, 0] >= 0) & (q[:, 0] <= mx.shape[1] - 1) & (q[:, 1] >= 0) & (q[:, 1] <= mx.shape[0] - 1)
    out = np.empty_like(ideal)
    qi = q[inside]
    n = len(qi)
    rows = np.pad(qi, ((0, -n % 4096), (0, 0))).reshape(-1, 4096, 2)  # (OpenCV's remap: under 32767 a side)
    for col, lut in ((0, mx), (1, my)):
        out[inside, col] = cv2.remap(lut, rows[..., 0], rows[..., 1], cv2.INTER_LINEAR).ravel()[:n]
    if not inside.all():
        out[~inside] = cam.project(pts[~inside])
    return out


def register_depth(depth_m: np.ndarray, depth_cam: CameraModel, color_cam: CameraModel,
                   T_color_depth: np.ndarray, min_depth: float = 0.05, max_depth: float = 20.0) -> np.ndarray:
    """A depth image (metres; NaN, 0, inf or negative invalid) of a depth camera that is not the colour camera
    (its own intrinsics, lens and pose ``T_color_depth``: the depth camera's optical frame in the colour camera's),
    registered to the colour camera as a driver's depth-to-colour alignment does it: each valid depth pixel's point
    X_d = Z K_d^-1 undistort([u, v]) moved into the colour frame, X_c = T_color_depth X_d, and its depth z_c written
    over the colour pixels its footprint covers (the pixel's width seen from the colour camera: about
    (f_c / f_d) (z_d / z_c) colour pixels, at least the one nearest its projection, at most
    :data:`MAX_FOOTPRINT_PX` a side), so that the samples leave no holes between them; where several land on one
    pixel the nearest wins (a z-buffer: a near edge is not overwritten by what it hides). Returns the colour camera's
    (height, width) float32 depth in metres, NaN where nothing landed (what the depth camera did not see: beside a
    near edge, outside its view)."""
    d = np.asarray(depth_m)
    if d.shape != (depth_cam.height, depth_cam.width):
        raise ValueError(f"depth image is {d.shape[1]}x{d.shape[0]}, its CameraInfo says "
                         f"{depth_cam.width}x{depth_cam.height}")
    out = np.full((color_cam.height, color_cam.width), np.nan, np.float32)
    dp = depth_points(d, depth_cam, 1, None, min_depth, max_depth)
    if not len(dp.points):
        return out
    z_d = dp.points[:, 2]
    pts = G.transform(np.asarray(T_color_depth, np.float64), dp.points)
    z = pts[:, 2]
    front = z > min_depth
    pts, z, z_d = pts[front], z[front], z_d[front]
    uv = _project_fast(color_cam, pts)
    half = FOOTPRINT_OVERLAP * 0.5 * np.c_[color_cam.fx / depth_cam.fx * z_d / z, color_cam.fy / depth_cam.fy * z_d / z]
    with np.errstate(invalid="ignore"):
        ok = np.all(np.isfinite(uv), axis=1) & (uv[:, 0] > -MAX_FOOTPRINT_PX) & (uv[:, 1] > -MAX_FOOTPRINT_PX) \
            & (uv[:, 0] < color_cam.width + MAX_FOOTPRINT_PX) & (uv[:, 1] < color_cam.height + MAX_FOOTPRINT_PX)
    uv, half, z = uv[ok], half[ok], z[ok]
    start = np.ceil(uv - half).astype(np.int64)  # the colour pixel centres within half a footprint of the centre
    count = np.clip(np.floor(uv + half).astype(np.int64) - start + 1, 1, MAX_FOOTPRINT_PX)
    pix, depth = [], []
    for dy in range(int(count[:, 1].max())):
        for dx in range(int(count[:, 0].max())):
            take = np.flatnonzero((count[:, 0] > dx) & (count[:, 1] > dy)) if dx or dy else np.arange(len(z))
            u, v = start[take, 0] + dx, start[take, 1] + dy
            inside = (u >= 0) & (u < color_cam.width) & (v >= 0) & (v < color_cam.height)
            pix.append(v[inside] * color_cam.width + u[inside])
            depth.append(z[take[inside]])
    if not pix:
        return out
    flat, zs = np.concatenate(pix), np.concatenate(depth)
    order = np.argsort(-zs, kind="stable")  # far first: the nearest written last wins its pixel
    out.ravel()[flat[order]] = zs[order]
    return out


def bad_pixel_rate(disp: np.ndarray, truth: np.ndarray, threshold: float = 2.0) -> tuple[float, float]:
    """Middlebury's bad-pixel rate: fraction of pixels with a valid truth whose estimated disparity is missing
    or off by more than ``threshold`` pixels; also the fraction of those that have an estimate (density)."""
    t = np.asarray(truth, dtype=np.float64)
    e = np.asarray(disp, dtype=np.float64)
    valid = np.isfinite(t) & (t > 0)
    have = valid & np.isfinite(e)
    bad = valid & (~np.isfinite(e) | (np.abs(np.nan_to_num(e) - t) > threshold))
    n = max(int(valid.sum()), 1)
    return float(bad.sum()) / n, float(have.sum()) / n
