"""Stereo rectification from the pair's CameraInfo (vision/rectify.py): a raw pair (lens distortion, the right
camera turned and offset) calibrated as a stereo calibration would (OpenCV's stereoRectify: each camera's R and P),
its maps checked against the geometry written out, for a plumb_bob and an equidistant (fisheye) pair; and the check
that tells a raw pair's CameraInfo from a rectified one's."""

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import CameraInfoError
from simreal_nodes.vision.rectify import StereoRectification, rectification_of, rectified_problem

SIZE = (640, 480)
BASELINE = 0.12
R_LR = G.exp_so3([0.01, -0.02, 0.015])  # right camera frame from the left's: X_r = R_LR X_l + T_LR
T_LR = np.array([-BASELINE, 0.003, 0.002])


def _info(cam: CameraModel, R: np.ndarray, P: np.ndarray) -> SimpleNamespace:
    f = cam.camera_info_fields()
    f["r"], f["p"] = [float(x) for x in R.ravel()], [float(x) for x in P.ravel()]
    return SimpleNamespace(header=SimpleNamespace(frame_id="cam"), **f)


def _rig(fisheye: bool, zero_disparity: bool = True):
    """The raw pair and the rectification a stereo calibration gives it (each camera's R, P); without
    ``zero_disparity`` (plumb_bob only) the two rectified cameras' principal points differ."""
    if fisheye:
        D1, D2 = np.array([-0.021, 0.0043, -0.0012, 0.0001]), np.array([-0.018, 0.0031, -0.0009, 0.0001])
        left = CameraModel(*SIZE, [[330.0, 0, 321.3], [0, 328.0, 238.6], [0, 0, 1]], D1, "equidistant")
        right = CameraModel(*SIZE, [[333.0, 0, 317.9], [0, 331.5, 241.2], [0, 0, 1]], D2, "equidistant")
        R1, R2, P1, P2, _ = cv2.fisheye.stereoRectify(left.K, left.D, right.K, right.D, SIZE, R_LR, T_LR.reshape(3, 1),
                                                      cv2.CALIB_ZERO_DISPARITY, newImageSize=SIZE, balance=0.0,
                                                      fov_scale=1.0)
    else:
        left = CameraModel(*SIZE, [[525.0, 0, 321.3], [0, 523.0, 238.6], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0008, 0])
        right = CameraModel(*SIZE, [[528.0, 0, 317.9], [0, 526.5, 241.2], [0, 0, 1]], [-0.22, 0.06, -0.0005, 0.001, 0])
        R1, R2, P1, P2, *_ = cv2.stereoRectify(left.K, left.D, right.K, right.D, SIZE, R_LR, T_LR.reshape(3, 1),
                                               flags=cv2.CALIB_ZERO_DISPARITY if zero_disparity else 0, alpha=0)
        assert zero_disparity == (abs(P1[0, 2] - P2[0, 2]) < 1e-6)
    return left, right, (R1, P1), (R2, P2)


@pytest.mark.parametrize("fisheye,zero_disparity", [(False, True), (False, False), (True, True)])
def test_a_raw_pair_is_rectified_from_its_camera_info(fisheye, zero_disparity):
    """Points 1-5 m in front: their rectified pixels lie on the same row in both images, their disparity gives
    their depth in the rectified left camera (Z = f b / d), and the maps take each rectified pixel to the raw pixel
    its ray lands on (0.05 px: OpenCV's fixed-point maps); the rectified cameras have no distortion and the left
    P's K (a calibration whose right P has another principal point: the right image shifted to the left's)."""
    left, right, rp_l, rp_r = _rig(fisheye, zero_disparity)
    rect = StereoRectification(left, rectification_of(_info(left, *rp_l)), right,
                               rectification_of(_info(right, *rp_r)))
    assert rect.baseline == pytest.approx(np.linalg.norm(T_LR), rel=1e-6)
    assert not rect.left_camera.has_distortion and np.allclose(rect.left_camera.K, rp_l[1][:, :3])
    assert rect.right_P[0, 3] == pytest.approx(-rect.right_camera.fx * rect.baseline)
    rng = np.random.default_rng(1)
    X = np.c_[rng.uniform(-1, 1, 400), rng.uniform(-0.7, 0.7, 400), np.ones(400)] * rng.uniform(1, 5, (400, 1))
    K = rect.left_camera.K
    Xl, Xr = X @ rp_l[0].T, (X @ R_LR.T + T_LR) @ rp_r[0].T  # in each rectified camera's frame
    ul = np.c_[K[0, 0] * Xl[:, 0] / Xl[:, 2] + K[0, 2], K[1, 1] * Xl[:, 1] / Xl[:, 2] + K[1, 2]]
    ur = np.c_[K[0, 0] * Xr[:, 0] / Xr[:, 2] + K[0, 2], K[1, 1] * Xr[:, 1] / Xr[:, 2] + K[1, 2]]
    inside = np.all((ul > 1) & (ul < np.array(SIZE) - 2) & (ur > 1) & (ur < np.array(SIZE) - 2), axis=1)
    assert inside.sum() > 100
    ul, ur, Xl = ul[inside], ur[inside], Xl[inside]
    np.testing.assert_allclose(ul[:, 1], ur[:, 1], atol=1e-6)  # the same row
    np.testing.assert_allclose(K[0, 0] * rect.baseline / (ul[:, 0] - ur[:, 0]), Xl[:, 2], rtol=1e-6)
    for (m1, m2), cam, u, P_raw in ((rect._maps[0], left, ul, X[inside]),
                                    (rect._maps[1], right, ur, X[inside] @ R_LR.T + T_LR)):
        mx, my = cv2.convertMaps(m1, m2, cv2.CV_32FC1)
        look = np.c_[cv2.remap(mx, u[:, 0].astype(np.float32)[None], u[:, 1].astype(np.float32)[None],
                               cv2.INTER_LINEAR).ravel(),
                     cv2.remap(my, u[:, 0].astype(np.float32)[None], u[:, 1].astype(np.float32)[None],
                               cv2.INTER_LINEAR).ravel()]
        np.testing.assert_allclose(look, cam.project(P_raw), atol=0.05)
    img = rng.integers(0, 255, (480, 640), np.uint8)
    assert rect.left(img).shape == img.shape and rect.right(img).shape == img.shape


def test_a_raw_pair_s_camera_info_is_told_from_a_rectified_one():
    """A rectified pair's CameraInfo (R the identity, no distortion, K = P's 3 x 3, as `make-bag` writes it) passes;
    a raw one says why it is raw; a malformed R or P, or a pair whose P matrices are not one rectified camera, is
    refused with its reason."""
    left, right, rp_l, rp_r = _rig(False)
    ideal = CameraModel(*SIZE, rp_l[1][:, :3])
    P = np.c_[ideal.K, [-ideal.fx * BASELINE, 0, 0]]
    assert rectified_problem(_info(ideal, np.eye(3), P)) == ""
    assert rectified_problem(_info(ideal, np.zeros((3, 3)), P)) == ""  # R left unset by the driver
    why = rectified_problem(_info(right, *rp_r))
    assert "R is not the identity" in why and "distortion" in why and "K differs" in why
    with pytest.raises(CameraInfoError, match="not a rotation"):
        rectification_of(_info(ideal, 2 * np.eye(3), P))
    with pytest.raises(CameraInfoError, match="NaN"):
        rectification_of(_info(ideal, np.eye(3), np.full((3, 4), np.nan)))
    bad = rp_r[1].copy()
    bad[1, 2] += 5.0  # the right camera's rows elsewhere: no rectified pair
    with pytest.raises(CameraInfoError, match="not one rectified camera"):
        StereoRectification(left, rp_l, right, (rp_r[0], bad))
    with pytest.raises(CameraInfoError, match="focal lengths must be positive"):
        rectified_problem(SimpleNamespace(**{**vars(_info(ideal, np.eye(3), P)), "k": [0.0] * 9}))
    shifted = _rig(False, zero_disparity=False)
    with pytest.raises(CameraInfoError, match="principal points differ"):  # already rectified: no map to shift by
        StereoRectification(shifted[0], shifted[2], shifted[1], shifted[3], rectified=True)
