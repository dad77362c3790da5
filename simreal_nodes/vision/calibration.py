"""Intrinsic calibration from chessboard images (OpenCV), for `simreal calibrate`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import cast

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel
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
    """Estimate K and distortion from chessboard views. ``cols`` x ``rows`` counts inner corners."""
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
    flags = cv2.CALIB_RATIONAL_MODEL if distortion == "rational_polynomial" else 0
    wh = cast(tuple[int, ...], size)  # (width, height) of the first view used: min_views of them were
    rms, K, D, rvecs, tvecs = cv2.calibrateCamera(obj, img_pts, wh, None, None, flags=flags)
    per_view = []
    for o, p, r, t in zip(obj, img_pts, rvecs, tvecs):
        proj, _ = cv2.projectPoints(o, r, t, K, D)
        per_view.append(float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - p) ** 2, axis=1)))))
    cam = CameraModel(wh[0], wh[1], K, D.ravel(), distortion)
    return CalibrationResult(cam, float(rms), per_view, used, rejected)


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
