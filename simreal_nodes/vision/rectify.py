"""Stereo rectification from the pair's CameraInfo, as ROS's stereo_image_proc does it.

A stereo driver publishes its raw images with a CameraInfo each that holds the raw lens (K, D, distortion model)
and the rectification a stereo calibration found: R, the rotation from the raw camera to the rectified one, and P,
the rectified camera's projection (3 x 4; the right one's P[0, 3] = -fx' * baseline). The rectified images are the
raw ones seen through R by the pinhole camera P[:, :3] without distortion: rows of the two images then hold the same
scene points, which is what the stereo matching along rows (``vision/stereo.py``) takes. :class:`StereoRectification`
builds the remap maps once per pair of CameraInfos (``cv2.initUndistortRectifyMap``, or its fisheye counterpart for
an ``equidistant`` lens) and gives the rectified cameras; :func:`rectified_problem` says why a CameraInfo does not
describe rectified images, so that a raw pair is never matched along rows as if it were rectified.
"""

from __future__ import annotations

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel, sensor_reduction
from simreal_nodes.errors import CameraInfoError

IDENTITY_TOL = 1e-6  # a CameraInfo's R and K against the identity and P's 3 x 3 (a rectified pair's own, exact)


def rectification_of(msg) -> tuple[np.ndarray, np.ndarray]:
    """(R 3 x 3, P 3 x 4) of a CameraInfo (anything with ``r`` and ``p``); an all-zero R (a driver that leaves it
    unset) reads as the identity. CameraInfoError when either is missing, of the wrong size or not finite."""
    r = np.asarray(getattr(msg, "r", ()), np.float64).ravel()
    p = np.asarray(getattr(msg, "p", ()), np.float64).ravel()
    if r.size != 9 or p.size != 12:
        raise CameraInfoError(f"CameraInfo has {r.size} values in R and {p.size} in P (expected 9 and 12)")
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(p))):
        raise CameraInfoError("CameraInfo R or P has NaN or inf entries")
    R = r.reshape(3, 3) if np.any(r) else np.eye(3)
    P = sensor_reduction(msg)[0] @ p.reshape(3, 4)  # (binning and a region of interest, as for K)
    if P[0, 0] <= 0 or P[1, 1] <= 0 or abs(P[2, 2] - 1.0) > 1e-9:
        raise CameraInfoError(f"CameraInfo P is not a rectified camera's projection: {P.tolist()}")
    if abs(np.linalg.det(R) - 1.0) > 1e-3 or not np.allclose(R @ R.T, np.eye(3), atol=1e-3):
        raise CameraInfoError(f"CameraInfo R is not a rotation: {R.tolist()}")
    return R, P


def rectified_problem(msg) -> str:
    """'' when a CameraInfo describes rectified images (R the identity, no lens distortion, K the same as P's
    3 x 3), else what says the images are raw: a stereo pair's rows hold the same points only once rectified.
    CameraInfoError when the CameraInfo is malformed."""
    cam = CameraModel.from_camera_info(msg)
    R, P = rectification_of(msg)
    why = []
    if not np.allclose(R, np.eye(3), atol=IDENTITY_TOL):
        why.append("R is not the identity")
    if cam.has_distortion:
        why.append(f"its lens ({cam.distortion_model}) has distortion")
    if not np.allclose(cam.K, P[:, :3], rtol=IDENTITY_TOL, atol=IDENTITY_TOL):
        why.append("K differs from P's rectified camera")
    return "; ".join(why)


def rectified_camera(cam: CameraModel, P: np.ndarray) -> CameraModel:
    """The rectified camera of a CameraInfo's P (its 3 x 3, no distortion; the size and frame of ``cam``)."""
    return CameraModel(cam.width, cam.height, P[:, :3].copy(), np.zeros(5), "plumb_bob", cam.frame_id)


class StereoRectification:
    """The remap maps of a raw stereo pair (each camera's lens and its R, P) to its rectified images, and the
    rectified cameras (no distortion): both the left P's 3 x 3, the right P's principal point being the left's
    (a calibration that left them apart, OpenCV's stereoRectify without CALIB_ZERO_DISPARITY, shifts the right
    image's columns by the difference: disparity then means f b / Z as the stereo matching takes it); the baseline
    from the two P's fourth columns."""

    def __init__(self, left: CameraModel, left_rp: tuple[np.ndarray, np.ndarray], right: CameraModel,
                 right_rp: tuple[np.ndarray, np.ndarray], rectified: bool = False) -> None:
        """``rectified``: the images are rectified already (ROS's image_rect topics beside the raw cameras'
        CameraInfo): no maps; the cameras and the baseline from the P matrices alone."""
        (R_l, P_l), (R_r, P_r) = left_rp, right_rp
        same = np.allclose(np.r_[P_l[0, :2], P_l[1], P_l[2]], np.r_[P_r[0, :2], P_r[1], P_r[2]], rtol=1e-6, atol=1e-6)
        if not same:
            raise CameraInfoError("the stereo pair's P matrices are not one rectified camera (focal lengths, rows or "
                                  "skew differ): not a calibrated stereo pair")
        self.baseline = float((P_l[0, 3] - P_r[0, 3]) / P_r[0, 0])
        if not self.baseline > 0:
            raise CameraInfoError(f"the right camera's P puts it {self.baseline:g} m to the left one's right "
                                  "(expected > 0)")
        if (left.width, left.height) != (right.width, right.height):
            raise CameraInfoError(f"the stereo pair's images differ in size ({left.width}x{left.height} and "
                                  f"{right.width}x{right.height})")
        self.inputs = (left, R_l.copy(), P_l.copy(), right, R_r.copy(), P_r.copy(), rectified)
        K = P_l[:, :3]
        if rectified and abs(P_l[0, 2] - P_r[0, 2]) > 1e-6:
            raise CameraInfoError(f"the rectified pair's principal points differ (cx {P_l[0, 2]:g} and {P_r[0, 2]:g}): "
                                  "give the raw images (camera.stereo_input: raw), which are rectified to one")
        self._maps = None if rectified else [cam.undistort_maps(K, (cam.width, cam.height), cv2.CV_16SC2, R)
                                             for cam, R in ((left, R_l), (right, R_r))]
        self.left_camera = rectified_camera(left, P_l)
        self.right_camera = rectified_camera(right, P_l)
        # the baseline lives in P[0, 3], as a rectified pair's CameraInfo gives it (the left at the origin)
        self.right_P = np.c_[K, [-K[0, 0] * self.baseline, 0.0, 0.0]]

    def same(self, left: CameraModel, left_rp, right: CameraModel, right_rp) -> bool:
        """Built from these cameras and rectifications (the maps can be kept)."""
        l0, Rl, Pl, r0, Rr, Pr, _ = self.inputs
        return left.same_as(l0) and right.same_as(r0) and all(
            np.array_equal(a, b) for a, b in ((left_rp[0], Rl), (left_rp[1], Pl), (right_rp[0], Rr), (right_rp[1], Pr)))

    def left(self, img: np.ndarray) -> np.ndarray | None:
        """The left image rectified; None when it is already (nothing to change)."""
        return None if self._maps is None else cv2.remap(img, self._maps[0][0], self._maps[0][1], cv2.INTER_LINEAR)

    def right(self, img: np.ndarray) -> np.ndarray | None:
        return None if self._maps is None else cv2.remap(img, self._maps[1][0], self._maps[1][1], cv2.INTER_LINEAR)
