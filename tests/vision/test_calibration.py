"""`simreal calibrate` recovers known intrinsics and distortion from synthetic chessboard views."""

import cv2
import numpy as np
import pytest

from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import SimrealError
from simreal_nodes.vision.calibration import board_points, calibrate


def _render_views(cam: CameraModel, cols, rows, square, n, rng, off_axis_deg: float = 0.0):
    """Chessboard views: plane -> ideal image by homography, then lens distortion by remapping. ``off_axis_deg``:
    the boards' centres drawn over a cone of that half-angle at 0.35-0.5 m (the ideal image grown to hold them: a
    fisheye's periphery lies far outside the pinhole image of its K); 0, the near-axis boards of the first test."""
    sq_px = 40
    board = np.kron((np.indices((rows + 1, cols + 1)).sum(0) % 2), np.ones((sq_px, sq_px))).astype(np.uint8) * 255
    board = cv2.copyMakeBorder(board, sq_px, sq_px, sq_px, sq_px, cv2.BORDER_CONSTANT, value=255)
    # board pixel (x, y) -> board-plane metres: corner (0,0) of the inner grid sits at pixel 2*sq_px
    S = np.array([[square / sq_px, 0, -2 * square], [0, square / sq_px, -2 * square], [0, 0, 1]])
    h, w = cam.height, cam.width
    m = 0 if not off_axis_deg else int(np.ceil(np.tan(np.radians(off_axis_deg + 25)) * cam.fx))
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    ideal = cam.undistort_points(np.c_[xs.ravel(), ys.ravel()]).reshape(h, w, 2).astype(np.float32) + m
    ideal[~np.isfinite(ideal)] = -1e5  # a fisheye's pixels with no ray in front: outside the ideal image
    shift = np.array([[1.0, 0, m], [0, 1, m], [0, 0, 1]])
    middle = np.array([cols - 1, rows - 1, 0]) * square / 2
    views = []
    for i in range(n):
        rvec = rng.uniform(-0.5, 0.5, 3)
        R = cv2.Rodrigues(rvec)[0]
        if off_axis_deg:
            a, phi = np.radians(off_axis_deg) * np.sqrt(rng.uniform()), rng.uniform(0, 2 * np.pi)
            t = np.array([np.sin(a) * np.cos(phi), np.sin(a) * np.sin(phi), np.cos(a)]) * rng.uniform(0.35, 0.5)
            t -= R @ middle
        else:
            t = np.array([rng.uniform(-0.08, 0.02), rng.uniform(-0.06, 0.02), rng.uniform(0.35, 0.5)])
        H = shift @ cam.K @ np.c_[R[:, :2], t] @ S  # board pixel -> ideal pixel
        img_ideal = cv2.warpPerspective(board, H, (w + 2 * m, h + 2 * m), flags=cv2.INTER_AREA, borderValue=128)
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


def test_recovers_a_fisheye_lens():
    """``--model equidistant`` calibrates a fisheye by OpenCV's fisheye model (before, it ran the pinhole
    calibration and wrote its five coefficients under the fisheye's name): K within 0.5 %, the lens's radius at 20
    and 45 degrees off the axis within 0.3 %, and a lens model not offered refused."""
    truth = CameraModel(640, 480, [[330.0, 0, 321.3], [0, 328.0, 238.6], [0, 0, 1]],
                        [-0.021, 0.0043, -0.0012, 0.0001], "equidistant")
    views = _render_views(truth, 8, 6, 0.025, 20, np.random.default_rng(5), off_axis_deg=45)
    res = calibrate(views, 8, 6, 0.025, "equidistant")
    c = res.camera
    assert c.fisheye and len(c.D) == 4 and len(res.used) >= 15
    assert res.rms_px < 0.3 and max(res.per_view_rms_px) < 0.5
    assert abs(c.fx / 330 - 1) < 0.005 and abs(c.fy / 328 - 1) < 0.005
    assert abs(c.cx - 321.3) < 1 and abs(c.cy - 238.6) < 1
    for deg in (20, 45):  # the boards were seen up to about 60 degrees off the axis
        ray = np.array([[np.sin(np.radians(deg)), 0.0, np.cos(np.radians(deg))]])
        assert abs((c.project(ray)[0, 0] - c.cx) / (truth.project(ray)[0, 0] - truth.cx) - 1) < 0.003
    with pytest.raises(SimrealError, match="lens model 'fisheye'"):
        calibrate(views, 8, 6, 0.025, "fisheye")
