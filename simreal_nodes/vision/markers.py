"""Camera pose from fiducial markers (ArUco / AprilTag dictionaries of cv2.aruco) laid out in the map.

All corners of all visible markers of the layout go into one PnP (IPPE on the best marker for the
initial guess, then Levenberg-Marquardt on every corner), so the pose uses every marker in view.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import SimrealError


@dataclass
class MarkerResult:
    T_wc: np.ndarray | None
    ids: list[int] = field(default_factory=list)
    unknown_ids: list[int] = field(default_factory=list)
    rms_px: float = float("nan")
    reason: str = ""
    corners: dict = field(default_factory=dict)  # id -> (4, 2) detected corners (distorted pixels)


def marker_corners(size: float) -> np.ndarray:
    """Corners in the marker frame (x right, y up, z out of the marker), OpenCV's order: TL, TR, BR, BL."""
    h = size / 2
    return np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], dtype=np.float64)


class MarkerLocalizer:
    def __init__(self, cam: CameraModel, dictionary: str, size: float, poses: dict[int, np.ndarray]):
        if not hasattr(cv2.aruco, dictionary):
            raise SimrealError(f"unknown marker dictionary '{dictionary}' (e.g. DICT_4X4_50, DICT_APRILTAG_36h11)")
        self.cam = cam
        self.size = float(size)
        self.poses = {int(k): np.asarray(v, dtype=np.float64) for k, v in poses.items()}
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        params.cornerRefinementWinSize = 4
        params.cornerRefinementMaxIterations = 50
        params.cornerRefinementMinAccuracy = 0.01
        self.detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)),
                                                params)
        self._local = marker_corners(self.size)
        self._world = {k: G.transform(T, self._local) for k, T in self.poses.items()}

    def detect(self, gray: np.ndarray) -> dict[int, np.ndarray]:
        corners, ids, _ = self.detector.detectMarkers(gray)
        if ids is None:
            return {}
        return {int(i): c.reshape(4, 2).astype(np.float64) for i, c in zip(ids.ravel(), corners)}

    def locate(self, gray: np.ndarray) -> MarkerResult:
        det = self.detect(gray)
        known = {k: v for k, v in det.items() if k in self._world}
        res = MarkerResult(None, sorted(known), sorted(set(det) - set(known)), corners=det)
        if not known:
            res.reason = ("no marker of the layout in view"
                          + (f" (saw unknown ids {res.unknown_ids})" if res.unknown_ids else ""))
            return res
        obj = np.concatenate([self._world[k] for k in known])
        img = np.concatenate([known[k] for k in known])
        und = self.cam.undistort_points(img)
        K = self.cam.K
        # initial guess: IPPE on the marker that looks largest
        best = max(known, key=lambda k: cv2.contourArea(known[k].astype(np.float32)))
        ok, rvec, tvec = cv2.solvePnP(self._local, self.cam.undistort_points(known[best]), K, None,
                                      flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            res.reason = "marker pose estimation failed"
            return res
        T_cm = G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
        T_cw = T_cm @ G.inv(self.poses[best])
        rvec, _ = cv2.Rodrigues(T_cw[:3, :3])
        tvec = T_cw[:3, 3].reshape(3, 1).copy()
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 1e-10)
        rvec, tvec = cv2.solvePnPRefineLM(obj, und, K, None, rvec, tvec, crit)
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, None)
        err = np.linalg.norm(proj.reshape(-1, 2) - und, axis=1)
        per_marker = err.reshape(-1, 4).max(axis=1)
        if len(known) > 2 and per_marker.max() > 1.0 and per_marker.max() > 4 * np.median(per_marker):
            # one marker disagrees (partly occluded, bent, glare): solve without it
            keep = np.repeat(per_marker < per_marker.max(), 4)
            res.ids = [k for k, bad in zip(known, per_marker >= per_marker.max()) if not bad]
            obj, und = obj[keep], und[keep]
            rvec, tvec = cv2.solvePnPRefineLM(obj, und, K, None, rvec, tvec, crit)
            proj, _ = cv2.projectPoints(obj, rvec, tvec, K, None)
            err = np.linalg.norm(proj.reshape(-1, 2) - und, axis=1)
        T_cw = G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
        res.rms_px = float(np.sqrt(np.mean(err ** 2)))
        if res.rms_px > 3.0:
            res.reason = (f"markers inconsistent with the layout (reprojection {res.rms_px:.1f} px): "
                          "moved marker or wrong size?")
            return res
        res.T_wc = G.inv(T_cw)
        return res
