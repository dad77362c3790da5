"""Intrinsic calibration from chessboard images (OpenCV), for `simreal calibrate`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import cast

import cv2
import numpy as np

from simreal_nodes.camera import CALIBRATION_MODELS, CameraModel
from simreal_nodes.errors import SimrealError


@dataclass
class CalibrationResult:
    camera: CameraModel
    rms_px: float
    per_view_rms_px: list[float]
    used: list[str]
    rejected: dict[str, str]


def board_points(cols: int, rows: int, square: float) -> np.ndarray:
    """Inner-corner coordinates of a chessboard in its own plane (z = 0), row-major like OpenCV."""
    g = np.zeros((rows * cols, 3), np.float32)
    g[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    return g


def find_corners(gray: np.ndarray, cols: int, rows: int) -> np.ndarray | None:
    ok, corners = cv2.findChessboardCornersSB(gray, (cols, rows), flags=cv2.CALIB_CB_ACCURACY)
    if not ok:
        ok, corners = cv2.findChessboardCorners(gray, (cols, rows))
        if not ok:
            return None
        corners = cv2.cornerSubPix(gray, corners, (7, 7), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3))
    return corners.reshape(-1, 2)


def calibrate(images: list[tuple[str, np.ndarray | None]], cols: int, rows: int, square: float,
              distortion: str = "plumb_bob", min_views: int = 5) -> CalibrationResult:
    """Estimate K and distortion from chessboard views. ``cols`` x ``rows`` counts inner corners. ``distortion``:
    ``plumb_bob`` (k1 k2 p1 p2 k3), ``rational_polynomial`` (8 coefficients) or ``equidistant`` (a fisheye lens,
    k1..k4, by ``cv2.fisheye.calibrate``, skew fixed at 0)."""
    if distortion not in CALIBRATION_MODELS:
        raise SimrealError(f"lens model '{distortion}': one of {', '.join(CALIBRATION_MODELS)}")
    obj, img_pts, used, rejected = [], [], [], {}
    size: tuple[int, ...] | None = None
    grid = board_points(cols, rows, square)
    for name, img in images:
        if img is None:
            rejected[name] = "cannot be read"
            continue
        gray = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        if size is None:
            size = gray.shape[::-1]
        elif gray.shape[::-1] != size:
            rejected[name] = f"size {gray.shape[::-1]} differs from {size}"
            continue
        c = find_corners(gray, cols, rows)
        if c is None:
            rejected[name] = f"no {cols}x{rows} chessboard found"
            continue
        obj.append(grid)
        img_pts.append(c.astype(np.float32))
        used.append(name)
    if len(used) < min_views:
        raise SimrealError(f"calibration needs at least {min_views} views with the board; found {len(used)} "
                           f"of {len(images)} ({'; '.join(f'{k}: {v}' for k, v in list(rejected.items())[:5])})")
    wh = cast(tuple[int, ...], size)  # (width, height) of the first view used: min_views of them were
    if distortion == "equidistant":
        rms, K, D, rvecs, tvecs = _fisheye(obj, img_pts, wh)
    else:
        flags = cv2.CALIB_RATIONAL_MODEL if distortion == "rational_polynomial" else 0
        rms, K, D, rvecs, tvecs = cv2.calibrateCamera(obj, img_pts, wh, None, None, flags=flags)
    cam = CameraModel(wh[0], wh[1], K, D.ravel(), distortion)
    per_view = []
    for o, p, r, t in zip(obj, img_pts, rvecs, tvecs):
        proj = cam.project(o.astype(np.float64) @ cv2.Rodrigues(r)[0].T + np.ravel(t))
        per_view.append(float(np.sqrt(np.mean(np.sum((proj - p) ** 2, axis=1)))))
    return CalibrationResult(cam, float(rms), per_view, used, rejected)


def _fisheye(obj: list[np.ndarray], img_pts: list[np.ndarray], wh: tuple[int, ...]):
    """OpenCV's fisheye calibration (its point lists as (1, N, 3) and (1, N, 2) float64): the extrinsics
    recomputed after each intrinsic step, skew fixed; a view too ill-conditioned for it named in the error."""
    flags = cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW  # (OpenCV 5 keeps them with the others)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-9)
    try:
        rms, K, D, rvecs, tvecs = cv2.fisheye.calibrate(
            [o.reshape(1, -1, 3).astype(np.float64) for o in obj], [p.reshape(1, -1, 2).astype(np.float64)
                                                                   for p in img_pts],
            (int(wh[0]), int(wh[1])), np.zeros((3, 3)), np.zeros(4), flags=flags, criteria=crit)
    except cv2.error as e:
        raise SimrealError(f"the fisheye calibration failed ({str(e).strip().splitlines()[-1]}): take views with "
                           "the board nearer the image's centre, or fewer tilted ones") from None
    return rms, K, D, rvecs, tvecs


def load_images(paths: list[str]) -> list[tuple[str, np.ndarray | None]]:
    """Grayscale images of the files and folders (their image files) in ``paths``; None where unreadable."""
    files: list[Path] = []
    for p in paths:
        q = Path(p)
        if q.is_dir():
            files += sorted(x for x in q.iterdir()
                            if x.suffix.lower() in (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"))
        else:
            files.append(q)
    return [(str(f), cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)) for f in files]
