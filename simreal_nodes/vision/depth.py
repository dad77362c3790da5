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
