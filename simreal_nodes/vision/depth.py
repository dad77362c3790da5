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


MAX_FOOTPRINT_PX = 16  # a depth pixel covers at most this many colour pixels a side (a depth camera 15 times coarser)
# the footprints grown by this much, so that neighbours overlap where the lenses and the turn vary their spacing (a
# surface behind would show through a gap) and a near edge grows by under a twentieth of a pixel
FOOTPRINT_OVERLAP = 1.1
LENS_LUT_MARGIN = 8  # ideal pixels around the ideal box of the image that the lens table covers
LENS_LUT_MAX_SIDE = 4  # the table spans at most this many image sizes a side (a fisheye's ideal image is unbounded)


@functools.lru_cache(maxsize=4)
def _lens_lut(width: int, height: int, K: tuple, D: tuple, model: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lens as a table over the ideal pixels that reach the image (the box of the image border's ideal pixels,
    grown by LENS_LUT_MARGIN, at most LENS_LUT_MAX_SIDE image sizes a side): for each, the distorted pixel its ray
    lands on (float32 maps, NaN where none), read bilinearly (within 1e-3 px of the exact projection); and the box's
    origin (x0, y0). Made in row blocks (float32), once per camera."""
    cam = CameraModel(width, height, np.asarray(K).reshape(3, 3), np.asarray(D), model)
    t = np.linspace(0.0, 1.0, 257)
    w1, h1 = t * (width - 1), t * (height - 1)
    border = np.concatenate([np.c_[w1, 0 * t], np.c_[w1, 0 * t + height - 1], np.c_[0 * t, h1],
                             np.c_[0 * t + width - 1, h1]])
    ideal = cam.undistort_points(border)
    ideal = ideal[np.all(np.isfinite(ideal), axis=1)]
    lo = np.minimum(ideal.min(axis=0, initial=0.0), 0.0) - LENS_LUT_MARGIN
    hi = np.maximum(ideal.max(axis=0, initial=0.0), [width - 1, height - 1]) + LENS_LUT_MARGIN
    cx, cy = (width - 1) / 2, (height - 1) / 2
    span = np.array([LENS_LUT_MAX_SIDE * width / 2, LENS_LUT_MAX_SIDE * height / 2])
    lo = np.floor(np.maximum(lo, [cx, cy] - span))
    hi = np.ceil(np.minimum(hi, [cx, cy] + span))
    xs = np.arange(lo[0], hi[0] + 1)
    mx = np.empty((int(hi[1] - lo[1]) + 1, len(xs)), np.float32)
    my = np.empty_like(mx)
    for r0 in range(0, mx.shape[0], 64):
        ys = lo[1] + np.arange(r0, min(r0 + 64, mx.shape[0]))
        vv, uu = np.meshgrid(ys, xs, indexing="ij")
        px = cam.project(cam.backproject(np.c_[uu.ravel(), vv.ravel()], np.ones(uu.size)))
        mx[r0:r0 + len(ys)] = px[:, 0].reshape(uu.shape)
        my[r0:r0 + len(ys)] = px[:, 1].reshape(uu.shape)
    return mx, my, lo


def _project_fast(cam: CameraModel, pts: np.ndarray) -> np.ndarray:
    """(N, 2) pixels of camera-frame points in front of ``cam``: the pinhole projection, then the lens read off its
    table (:func:`_lens_lut`). A point whose ideal pixel lies outside the table does not reach the image: NaN for a
    plumb_bob or rational lens (whose polynomial can fold far points back into the image); a fisheye's (whose table
    stops short of its 90 degrees) projected exactly."""
    with np.errstate(divide="ignore", invalid="ignore"):
        iz = 1.0 / pts[:, 2]
        x, y = pts[:, 0] * iz, pts[:, 1] * iz
        ideal = np.empty((len(pts), 2))
        np.multiply(x, cam.fx, out=ideal[:, 0])
        ideal[:, 0] += cam.K[0, 1] * y + cam.cx
        np.multiply(y, cam.fy, out=ideal[:, 1])
        ideal[:, 1] += cam.cy
    if not cam.has_distortion or not len(pts):
        return ideal
    mx, my, lo = _lens_lut(cam.width, cam.height, tuple(cam.K.ravel()), tuple(np.ravel(cam.D)), cam.distortion_model)
    q = (ideal - lo).astype(np.float32)
    with np.errstate(invalid="ignore"):
        inside = (q[:, 0] >= 0) & (q[:, 0] <= mx.shape[1] - 1) & (q[:, 1] >= 0) & (q[:, 1] <= mx.shape[0] - 1)
    out = np.full_like(ideal, np.nan)
    qi = q[inside]
    n = len(qi)
    if n:
        rows = np.pad(qi, ((0, -n % 4096), (0, 0))).reshape(-1, 4096, 2)  # (OpenCV's remap: under 32767 a side)
        for col, lut in ((0, mx), (1, my)):
            out[inside, col] = cv2.remap(lut, rows[..., 0], rows[..., 1], cv2.INTER_LINEAR).ravel()[:n]
    if cam.fisheye and not inside.all():
        out[~inside] = cam.project(pts[~inside])
    return out


@functools.lru_cache(maxsize=4)
def _stretch_grid(width: int, height: int, K: tuple, D: tuple, model: str) -> np.ndarray:
    """(height, width) ideal pixels per image pixel of a depth camera's lens (:meth:`CameraModel.stretch`; NaN where
    none): a depth pixel's footprint in the ideal image."""
    cam = CameraModel(width, height, np.asarray(K).reshape(3, 3), np.asarray(D), model)
    vs, us = np.mgrid[0:height, 0:width]
    return cam.stretch(np.c_[us.ravel(), vs.ravel()].astype(np.float64)).reshape(height, width).astype(np.float32)


def prepare_registration(depth_cam: CameraModel, color_cam: CameraModel) -> None:
    """Build the tables :func:`register_depth` reads for this pair of cameras (the colour lens's, the depth lens's
    stretch; about 0.4 s at 640 x 480), so that a node makes them when the cameras are known, not on a frame."""
    if color_cam.has_distortion:
        _lens_lut(color_cam.width, color_cam.height, tuple(color_cam.K.ravel()), tuple(np.ravel(color_cam.D)),
                  color_cam.distortion_model)
    if depth_cam.has_distortion:
        _stretch_grid(depth_cam.width, depth_cam.height, tuple(depth_cam.K.ravel()), tuple(np.ravel(depth_cam.D)),
                      depth_cam.distortion_model)


def register_depth(depth_m: np.ndarray, depth_cam: CameraModel, color_cam: CameraModel,
                   T_color_depth: np.ndarray, min_depth: float = 0.05, max_depth: float = 20.0) -> np.ndarray:
    """A depth image (metres; NaN, 0, inf or negative invalid) of a depth camera that is not the colour camera
    (its own intrinsics, lens and pose ``T_color_depth``: the depth camera's optical frame in the colour camera's),
    registered to the colour camera as a driver's depth-to-colour alignment does it: each valid depth pixel's point
    X_d = Z K_d^-1 undistort([u, v]) moved into the colour frame, X_c = T_color_depth X_d, and its depth z_c written
    over the colour pixels its footprint covers (the pixel's width seen from the colour camera: about
    s_d (f_c / f_d) (z_d / z_c) colour pixels, s_d the depth lens's stretch there, grown by FOOTPRINT_OVERLAP; at
    least the pixel nearest its projection, at most MAX_FOOTPRINT_PX a side, centred on it), so that the samples leave
    no holes between them; where several land on one pixel the nearest wins (a z-buffer: a near edge is not
    overwritten by what it hides). The colour lens's own compression towards its edge is not in the footprint (the
    overlap covers a mild one). Returns the colour camera's (height, width) float32 depth in metres, NaN where
    nothing landed (what the depth camera did not see: beside a near edge, outside its view)."""
    d = np.asarray(depth_m)
    if d.shape != (depth_cam.height, depth_cam.width):
        raise ValueError(f"depth image is {d.shape[1]}x{d.shape[0]}, its CameraInfo says "
                         f"{depth_cam.width}x{depth_cam.height}")
    out = np.full((color_cam.height, color_cam.width), np.nan, np.float32)
    dp = depth_points(d, depth_cam, 1, None, min_depth, max_depth)
    if not len(dp.points):
        return out
    z_d = dp.points[:, 2]
    s_d = np.ones(len(z_d), np.float32)
    if depth_cam.has_distortion:
        pix = dp.pixels.astype(np.int64)
        s_d = _stretch_grid(depth_cam.width, depth_cam.height, tuple(depth_cam.K.ravel()), tuple(np.ravel(depth_cam.D)),
                            depth_cam.distortion_model)[pix[:, 1], pix[:, 0]]
    pts = G.transform(np.asarray(T_color_depth, np.float64), dp.points)
    z = pts[:, 2]
    front = z > min_depth
    pts, z, z_d, s_d = pts[front], z[front], z_d[front], s_d[front]
    uv = _project_fast(color_cam, pts)
    scale = FOOTPRINT_OVERLAP * 0.5 * s_d * z_d / z
    with np.errstate(invalid="ignore"):
        ok = (uv[:, 0] > -MAX_FOOTPRINT_PX) & (uv[:, 1] > -MAX_FOOTPRINT_PX) & np.isfinite(scale) \
            & (uv[:, 0] < color_cam.width + MAX_FOOTPRINT_PX) & (uv[:, 1] < color_cam.height + MAX_FOOTPRINT_PX)
    uv, scale, z = uv[ok], scale[ok], z[ok]  # (NaN pixels fail the bounds)
    half = np.minimum(np.c_[color_cam.fx / depth_cam.fx * scale, color_cam.fy / depth_cam.fy * scale],
                      MAX_FOOTPRINT_PX / 2)
    if not len(z):
        return out
    # the colour pixel centres within half a footprint of the projection; a footprint smaller than a pixel between
    # two centres: the nearest
    start = np.ceil(uv - half).astype(np.int64)
    end = np.floor(uv + half).astype(np.int64)
    none = end < start
    start[none] = np.rint(uv[none]).astype(np.int64)
    count = np.maximum(end - start + 1, 1)
    W, H = color_cam.width, color_cam.height
    u0, v0 = start[:, 0], start[:, 1]
    base = v0 * W + u0
    zf = z.astype(np.float32)
    zbuf = np.full(out.size, np.inf, np.float32)
    for dy in range(int(count[:, 1].max())):
        rows = (count[:, 1] > dy) & (v0 + dy >= 0) & (v0 + dy < H)
        for dx in range(int(count[:, 0].max())):
            take = rows & (count[:, 0] > dx) & (u0 + dx >= 0) & (u0 + dx < W)
            np.minimum.at(zbuf, base[take] + (dy * W + dx), zf[take])  # each pixel's nearest: a z-buffer
    zbuf[np.isinf(zbuf)] = np.nan
    return zbuf.reshape(out.shape)


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
