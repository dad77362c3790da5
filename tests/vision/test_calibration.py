"""`simreal calibrate` recovers known intrinsics and distortion from synthetic chessboard views."""

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel
from simreal_nodes.vision.calibration import board_points, calibrate


def _render_views(cam: CameraModel, cols, rows, square, n, rng):
    """Chessboard views: plane -> ideal image by homography, then lens distortion by remapping."""
    sq_px = 40
    board = np.kron((np.indices((rows + 1, cols + 1)).sum(0) % 2), np.ones((sq_px, sq_px))).astype(np.uint8) * 255
    board = cv2.copyMakeBorder(board, sq_px, sq_px, sq_px, sq_px, cv2.BORDER_CONSTANT, value=255)
    # board pixel (x, y) -> board-plane metres: corner (0,0) of the inner grid sits at pixel 2*sq_px
    S = np.array([[square / sq_px, 0, -2 * square], [0, square / sq_px, -2 * square], [0, 0, 1]])
    h, w = cam.height, cam.width
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    ideal = cam.undistort_points(np.c_[xs.ravel(), ys.ravel()]).reshape(h, w, 2).astype(np.float32)
    views = []
    for i in range(n):
        rvec = rng.uniform(-0.5, 0.5, 3)
        R = cv2.Rodrigues(rvec)[0]
        t = np.array([rng.uniform(-0.08, 0.02), rng.uniform(-0.06, 0.02), rng.uniform(0.35, 0.5)])
        H = cam.K @ np.c_[R[:, :2], t] @ S  # board pixel -> ideal pixel
        img_ideal = cv2.warpPerspective(board, H, (w, h), flags=cv2.INTER_AREA, borderValue=128)
        img = cv2.remap(img_ideal, ideal[..., 0], ideal[..., 1], cv2.INTER_LINEAR)
        views.append((f"view{i}", img))
    return views


def test_recovers_intrinsics_and_distortion():
    truth = CameraModel.from_intrinsics(640, 480, 600.0, 600.0, 320.0, 240.0, D=[-0.12, 0.05, 0.0, 0.0, 0.0])
    views = _render_views(truth, 8, 6, 0.025, 14, np.random.default_rng(3))
    views.append(("blank", np.full((480, 640), 128, np.uint8)))
    res = calibrate(views, 8, 6, 0.025)
    c = res.camera
    assert res.rms_px < 0.5
    assert "blank" in res.rejected
    assert abs(c.fx - 600) < 6 and abs(c.fy - 600) < 6
    assert abs(c.cx - 320) < 6 and abs(c.cy - 240) < 6
    assert abs(c.D[0] - (-0.12)) < 0.03
    assert board_points(8, 6, 0.025).shape == (48, 3)
