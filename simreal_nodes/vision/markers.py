"""Camera pose from fiducial markers (ArUco / AprilTag dictionaries of cv2.aruco) laid out in the map.

All corners of all visible markers of the layout go into one PnP (IPPE on the best marker for the
initial guess, then Levenberg-Marquardt on every corner), so the pose uses every marker in view.

A pose the corners hold too loosely is refused rather than passed on: the camera position's standard deviation from
the PnP's normal equations, at the corners' reprojection rms (no less than ``CORNER_FLOOR_PX``), in % of the
distance to the markers, over ``max_std_pct``. One or two small markers in a blurred image read 2-7 cm off with a
reprojection rms under a pixel (a square's four corners fit any pose near the right one), and the check is what
tells (``benchmarks/marker_quality.py``).
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
    # the camera position's standard deviation, % of the distance to the markers (at the corners' rms, floored)
    std_pct: float = float("nan")


# the least corner error the pose's uncertainty assumes (px): a sharp 30-px marker's corners are good to a tenth of a
# pixel, but motion blur and defocus round them off by more without raising the rms of a pose that fits only them
CORNER_FLOOR_PX = 0.5
# the default of max_std_pct, chosen on development views (benchmarks/marker_quality.py)
MAX_STD_PCT = 2.5


def marker_corners(size: float) -> np.ndarray:
    """Corners in the marker frame (x right, y up, z out of the marker), OpenCV's order: TL, TR, BR, BL."""
    h = size / 2
    return np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], dtype=np.float64)


class MarkerLocalizer:
    def __init__(self, cam: CameraModel, dictionary: str, size: float, poses: dict[int, np.ndarray],
                 max_std_pct: float = MAX_STD_PCT):
        """``max_std_pct``: refuse a pose whose camera position is held more loosely than this share of the
        distance to the markers (standard deviation, %; 0 or less: never)."""
        if not hasattr(cv2.aruco, dictionary):
            raise SimrealError(f"unknown marker dictionary '{dictionary}' (e.g. DICT_4X4_50, DICT_APRILTAG_36h11)")
        self.cam = cam
        self.size = float(size)
        self.max_std_pct = float(max_std_pct)
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
        std_m, distance = position_std(obj, K, rvec, tvec, max(res.rms_px, CORNER_FLOOR_PX))
        res.std_pct = 100.0 * std_m / distance
        if not np.isfinite(res.std_pct) and self.max_std_pct > 0:
            res.reason = ("pose refused: the markers' corners do not determine the camera position (degenerate "
                          "view; localization.markers.max_std_pct)")
            return res
        if not res.std_pct <= self.max_std_pct and self.max_std_pct > 0:
            n = len(res.ids)
            res.reason = (f"pose refused: {n} marker{'s hold' if n > 1 else ' holds'} the camera position only to "
                          f"+-{1e3 * std_m:.0f} mm ({res.std_pct:.1f} % of the {distance:.2f} m to them, over "
                          f"{self.max_std_pct:g} %): too few, too small or too blurred "
                          "(localization.markers.max_std_pct)")
            return res
        res.T_wc = G.inv(T_cw)
        return res


def position_std(obj: np.ndarray, K: np.ndarray, rvec: np.ndarray, tvec: np.ndarray,
                 sigma_px: float) -> tuple[float, float]:
    """The camera centre's standard deviation (metres, the root of the covariance's trace) from the Gauss-Newton
    normal equations of the reprojection of ``obj`` (map points, (N, 3)) at pose (``rvec``, ``tvec``: map -> camera)
    with ``sigma_px`` of pixel noise per coordinate, and the points' mean distance along the optical axis (m)."""
    _, J = cv2.projectPoints(obj, rvec, tvec, K, None)
    J = J[:, :6]  # d(u, v) / d(rvec, tvec)
    JtJ = J.T @ J
    if not np.all(np.isfinite(JtJ)) or np.linalg.cond(JtJ) > 1e14:
        return float("inf"), float("nan")
    cov = sigma_px ** 2 * np.linalg.inv(JtJ)
    # the centre c = -R(r)^T t: its Jacobian by central differences in the six pose parameters
    p0 = np.r_[np.ravel(rvec), np.ravel(tvec)]

    def centre(p: np.ndarray) -> np.ndarray:
        return -cv2.Rodrigues(p[:3].reshape(3, 1))[0].T @ p[3:]

    Jc = np.zeros((3, 6))
    for i in range(6):
        d = np.zeros(6)
        d[i] = 1e-7
        Jc[:, i] = (centre(p0 + d) - centre(p0 - d)) / 2e-7
    R = cv2.Rodrigues(np.reshape(rvec, (3, 1)))[0]
    depth = float(np.mean(obj @ R[2] + float(np.ravel(tvec)[2])))
    return float(np.sqrt(max(np.trace(Jc @ cov @ Jc.T), 0.0))), depth
