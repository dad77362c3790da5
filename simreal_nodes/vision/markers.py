"""Camera pose from fiducial markers (ArUco / AprilTag dictionaries of cv2.aruco) laid out in the map.

All corners of all visible markers of the layout go into one PnP (IPPE on the best marker for the
initial guess, then Levenberg-Marquardt on every corner), so the pose uses every marker in view.

A pose the corners hold too loosely is refused rather than passed on: the camera position's standard deviation from
the PnP's normal equations, at the corners' reprojection rms (no less than ``CORNER_FLOOR_PX``), in % of the
distance to the markers, over ``max_std_pct``. One or two small markers in a blurred image read 2-7 cm off with a
reprojection rms under a pixel (a square's four corners fit any pose near the right one), and the check is what
tells (``benchmarks/marker_quality.py``).

Corners are refined from the marker's edges (``corner_refinement: edges``, the default): OpenCV's sub-pixel corner
search looks at a window round the corner itself, where blur rounds the square off, and reads it inward (0.2 px when
sharp, 0.6 px under a 2-px blur on ``tests/vision/test_marker_corners.py``'s marker). Each side's outer edge is located
across the side away from its ends (the steepest dark-inside descent in a profile no wider than the black border),
a line is fitted through those points, and the corners are the lines' intersections: blur spreads a straight edge
symmetrically, so the line stays where it is. ``subpix`` keeps OpenCV's corners.

With the edges, OpenCV's detector runs on the image reduced to ``detect_scale`` of its size (0.5 by default: its
contours and its reading of the bits are most of the time), the corners it finds searched again in the full image;
a marker of the layout the first pose puts in view that the reduced image missed is read in a window of the full
image, and the full image is searched whole where the reduced one gives no pose or a refused one
(:meth:`MarkerLocalizer.locate`; ``benchmarks/marker_quality.py`` measures the trade).
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
# corner refinements: "edges" (lines fitted to the sides' edges, intersected) or "subpix" (OpenCV's corner search)
CORNER_REFINEMENTS = ("edges", "subpix")
# the edge search: the share of a side searched (its ends are rounded by blur), the profile's half-width as a share
# of the black border's width (the bits inside have edges of their own), its step (px), and the most a corner may
# move from OpenCV's (in border widths; beyond it the marker keeps OpenCV's corners)
EDGE_SPAN = (0.2, 0.8)
EDGE_HALF_WIDTH = 0.6
EDGE_STEP_PX = 0.25
EDGE_MAX_SHIFT = 1.5
# OpenCV's sub-pixel corner search ("subpix", and the start and fall-back of "edges"): half-window (px), iterations,
# the step (px) it stops at
SUBPIX_WIN = 4
SUBPIX_MAX_ITER = 50
SUBPIX_MIN_ACCURACY = 0.01
# the detection's scale (issue 18): OpenCV's detector runs on the image reduced to this share of its size (area
# averaging) and the corners it finds are refined in the full image; 1: the full image
DETECT_SCALE = 0.5
# a layout marker the pose predicts in view but the reduced image missed (too small there) is looked for in the full
# image, in a window round its predicted square padded by this many of its sides (and no less than the detector's
# largest adaptive-threshold window plus its distance to the border: nearer the crop's edge the threshold sees
# another image and a blurred marker is missed), if its predicted side is at least WINDOW_MIN_SIDE_PX (smaller than
# any marker the full image's detector reads)
WINDOW_PAD = 1.5
WINDOW_MIN_SIDE_PX = 10.0
# the reduced image's detector takes no contour with less than this many pixels a cell (its perimeter under 4 x cells
# x this): OpenCV's least perimeter is a share of the image's size, and in a small reduced image it would let every
# speck through as a candidate to read (the 320 x 240 demo's half-size image: 12.7 ms against 3 ms for the full one);
# a marker under about 1.5 px a cell is not read there anyway (its windows or the full image read it)
REDUCED_MIN_CELL_PX = 1.0


def refine_by_edges(gray: np.ndarray, corners: np.ndarray, cells: int, iterations: int = 3) -> np.ndarray | None:
    """Corners (4, 2), clockwise in the image as OpenCV gives them, of a marker ``cells`` cells wide (its bits and
    its black border), refined as the intersections of lines fitted to its four sides' outer edges; None when a side
    is too short or too faint to fit or a corner would move further than ``EDGE_MAX_SHIFT`` border widths. One
    marker of :func:`refine_markers_by_edges`."""
    return refine_markers_by_edges(gray, [corners], cells, iterations)[0]


def refine_markers_by_edges(gray: np.ndarray, corners: list[np.ndarray], cells: int,
                            iterations: int = 3) -> list[np.ndarray | None]:
    """:func:`refine_by_edges` for every marker of an image at once (one array computation for all of them).

    Along each side, at points from ``EDGE_SPAN[0]`` to ``EDGE_SPAN[1]`` of its length, the image is sampled
    across it (bilinear, about ``EDGE_STEP_PX``); the edge is the centroid of the intensity's fall from the light
    outside into the black border (weights: the fall above a fifth of its largest, over a profile
    ``EDGE_HALF_WIDTH`` border widths either side), recentred ``iterations`` times. A line through those points
    (total least squares; points more than three median deviations off dropped, at most twice) is that side's edge,
    and a corner is where its two sides' lines meet."""
    if not len(corners):
        return []
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
    M = len(c)
    nxt = np.roll(c, -1, axis=1)
    side = np.linalg.norm(nxt - c, axis=2)  # (M, 4): side i runs from corner i to corner i + 1
    valid = side.min(axis=1) >= 2 * cells
    side = np.maximum(side, 1e-6)
    d = (nxt - c) / side[..., None]
    n = np.stack([-d[..., 1], d[..., 0]], axis=2)
    n *= np.where(np.sum(n * (c.mean(axis=1, keepdims=True) - c), axis=2) < 0, -1.0, 1.0)[..., None]  # inward
    # the black border's width across each side: a cell of the two sides that meet it
    border = np.minimum(np.roll(side, 1, axis=1), np.roll(side, -1, axis=1)) / cells
    half = np.maximum(EDGE_HALF_WIDTH * border, 1.0)
    k = int(np.clip(side.max() / 2, 6, 40))
    m = int(np.ceil(2 * half.max() / EDGE_STEP_PX)) + 1
    t = np.linspace(EDGE_SPAN[0], EDGE_SPAN[1], k)
    prof_s = np.linspace(-1.0, 1.0, m) * half[..., None]  # (M, 4, m): each side's profile
    mid = 0.5 * (prof_s[..., 1:] + prof_s[..., :-1])
    base = c[:, :, None, :] + (t[:, None] * side[:, :, None, None]) * d[:, :, None, :]  # (M, 4, k, 2)
    # only the pixels the profiles can reach (room for the recentring), as floats
    reach = 2.5 * border.max() + 2.0
    x0, y0 = np.floor(c.reshape(-1, 2).min(axis=0) - reach).astype(int).clip(0)
    x1, y1 = np.ceil(c.reshape(-1, 2).max(axis=0) + reach).astype(int) + 1
    img = gray[y0:y1, x0:x1].astype(np.float32)
    if img.size == 0:
        return [None] * M
    off = np.zeros((M, 4, k))
    bx, by = base[..., 0, None], base[..., 1, None]
    nx, ny = n[:, :, None, 0, None], n[:, :, None, 1, None]
    for _ in range(iterations):
        across = off[..., None] + prof_s[:, :, None, :]  # (M, 4, k, m): each sample's distance from the side
        prof = cv2.remap(img, (bx + across * nx - x0).reshape(-1, m).astype(np.float32),
                         (by + across * ny - y0).reshape(-1, m).astype(np.float32), cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE).reshape(M, 4, k, m)
        fall = np.maximum(prof[..., :-1] - prof[..., 1:], 0.0)  # light outside -> dark border along n
        w = np.maximum(fall - 0.2 * fall.max(axis=3, keepdims=True), 0.0)
        sw = w.sum(axis=3)
        off = off + np.where(sw > 1e-6, (w * mid[:, :, None, :]).sum(axis=3) / np.maximum(sw, 1e-9), 0.0)
    good = (sw > 1e-6) & (np.abs(off) < border[..., None])
    pts = base + off[..., None] * n[:, :, None, :]  # (M, 4, k, 2): the edge points
    for _ in range(3):
        valid &= (good.sum(axis=2) >= 4).all(axis=1)
        wgt = good.astype(np.float64)
        mean = (pts * wgt[..., None]).sum(axis=2) / np.maximum(wgt.sum(axis=2), 1.0)[..., None]
        dev = (pts - mean[:, :, None, :]) * wgt[..., None]
        sxx, syy = (dev[..., 0] ** 2).sum(axis=2), (dev[..., 1] ** 2).sum(axis=2)
        sxy = (dev[..., 0] * dev[..., 1]).sum(axis=2)
        theta = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # the points' main direction (total least squares)
        normal = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)  # (M, 4, 2)
        dist = np.abs(np.sum((pts - mean[:, :, None, :]) * normal[:, :, None, :], axis=3))
        ranked = np.sort(np.where(good, dist, np.inf), axis=2)
        spread = np.take_along_axis(ranked, ((good.sum(axis=2) - 1) // 2).clip(0)[..., None], axis=2)[..., 0]
        keep = good & (dist <= 3 * np.maximum(spread, 0.02)[..., None])
        if (keep == good).all():
            break
        good = keep
    offset = np.sum(normal * mean, axis=2)  # (M, 4): each line is normal . x = offset
    # corner i is where side i - 1 meets side i
    A = np.stack([np.roll(normal, 1, axis=1), normal], axis=2)  # (M, 4, 2, 2)
    b = np.stack([np.roll(offset, 1, axis=1), offset], axis=2)
    det = np.linalg.det(A)
    valid &= (np.abs(det) >= 1e-3).all(axis=1)
    A[np.abs(det) < 1e-3] = np.eye(2)
    out = np.linalg.solve(A, b[..., None])[..., 0]
    room = EDGE_MAX_SHIFT * np.maximum(np.roll(border, 1, axis=1), border)
    valid &= (np.linalg.norm(out - c, axis=2) <= room).all(axis=1)
    return [out[i] if valid[i] else None for i in range(M)]


def _inside(uv: np.ndarray, w: int, h: int) -> bool:
    """Whether every point of ``uv`` lies in a ``w`` x ``h`` image (pixel centres 0 .. w - 1, 0 .. h - 1)."""
    return bool(np.all(uv >= 0.0) and np.all(uv[:, 0] <= w - 1) and np.all(uv[:, 1] <= h - 1))


def marker_corners(size: float) -> np.ndarray:
    """Corners in the marker frame (x right, y up, z out of the marker), OpenCV's order: TL, TR, BR, BL."""
    h = size / 2
    return np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], dtype=np.float64)


class MarkerLocalizer:
    def __init__(self, cam: CameraModel, dictionary: str, size: float, poses: dict[int, np.ndarray],
                 max_std_pct: float = MAX_STD_PCT, corner_refinement: str = "edges",
                 detect_scale: float = DETECT_SCALE):
        """``max_std_pct``: refuse a pose whose camera position is held more loosely than this share of the
        distance to the markers (standard deviation, %; 0 or less: never). ``corner_refinement``: "edges" (lines
        fitted to the sides, :func:`refine_by_edges`) or "subpix" (OpenCV's corners). ``detect_scale``: the share of
        the image's size OpenCV's detector runs on with the edges' refinement (1: the full image; see
        :meth:`locate` and :attr:`reduced`)."""
        if not hasattr(cv2.aruco, dictionary):
            raise SimrealError(f"unknown marker dictionary '{dictionary}' (e.g. DICT_4X4_50, DICT_APRILTAG_36h11)")
        if corner_refinement not in CORNER_REFINEMENTS:
            raise SimrealError(f"unknown corner refinement '{corner_refinement}' "
                               f"(one of {', '.join(CORNER_REFINEMENTS)})")
        if not 0.0 < float(detect_scale) <= 1.0:
            raise SimrealError(f"marker detection scale {detect_scale}: expected a share of the image's size in (0, 1]")
        self.corner_refinement = corner_refinement
        self.detect_scale = float(detect_scale)
        self.cam = cam
        self.size = float(size)
        self.max_std_pct = float(max_std_pct)
        self.poses = {int(k): np.asarray(v, dtype=np.float64) for k, v in poses.items()}
        params = cv2.aruco.DetectorParameters()
        # the edges start from OpenCV's sub-pixel corners: from the unrefined ones, a marker under 20 px (320 x 240)
        # can be more than the search's reach off, and its lines land on the wrong edge
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        params.cornerRefinementWinSize = SUBPIX_WIN
        params.cornerRefinementMaxIterations = SUBPIX_MAX_ITER
        params.cornerRefinementMinAccuracy = SUBPIX_MIN_ACCURACY
        self._relative_win = float(params.relativeCornerRefinmentWinSize)
        self._min_pad_px = float(params.adaptiveThreshWinSizeMax + params.minDistanceToBorder)
        dictionary_ = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
        self.detector = cv2.aruco.ArucoDetector(dictionary_, params)
        # the windows' detector: as the full image's, its least perimeter set per window (see _in_windows)
        self._window_params = self.detector.getDetectorParameters()  # a copy: the full image's stays as it is
        self._window_detector = cv2.aruco.ArucoDetector(dictionary_, self._window_params)
        self._min_perimeter_rate = float(params.minMarkerPerimeterRate)
        # the reduced image's detector leaves the corners as found: they are refined in the full image
        self._reduced_params = cv2.aruco.DetectorParameters()
        self._reduced = cv2.aruco.ArucoDetector(dictionary_, self._reduced_params)
        self._reduced_size: tuple[int, int] | None = None
        self._cells = int(dictionary_.markerSize) + 2 * int(params.markerBorderBits)
        self._local = marker_corners(self.size)
        self._world = {k: G.transform(T, self._local) for k, T in self.poses.items()}
        # the searches of the last locate(): "reduced", "windows" (how many), "full"
        self.last_passes: dict[str, int] = {}

    @property
    def reduced(self) -> bool:
        """Whether the detector runs on a reduced image: ``detect_scale`` under 1 with the edges' refinement. OpenCV's
        corners (``subpix``) need the full image's contours to start from: from the reduced image's, their search
        (a window of 0.3 of a cell) lands off (stop 94, tried: the demo's sharp frames' median error doubled), so
        ``subpix`` detects in the full image at any scale."""
        return self.detect_scale < 1.0 and self.corner_refinement == "edges"

    def detect(self, gray: np.ndarray) -> dict[int, np.ndarray]:
        """Every marker OpenCV's detector finds in ``gray`` (at ``detect_scale`` of its size where :attr:`reduced`):
        id -> (4, 2) corners (distorted pixels of ``gray``, OpenCV's order), refined in the full image as
        ``corner_refinement`` says."""
        if gray.ndim != 2:
            raise SimrealError(f"marker detection takes a grey image (H, W), not an array of shape {gray.shape}")
        if not self.reduced:
            return self._refined(gray, self._found(self.detector, gray))
        return self._refined(gray, self._from_reduced(gray))

    def _from_reduced(self, gray: np.ndarray) -> dict[int, np.ndarray]:
        """The markers the detector finds in ``gray`` reduced to ``detect_scale`` of its size, their corners mapped to
        ``gray`` and searched there by OpenCV's sub-pixel rule (before the edges' refinement)."""
        h, w = gray.shape[:2]
        size = (max(1, round(w * self.detect_scale)), max(1, round(h * self.detect_scale)))
        small = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
        if size != self._reduced_size:  # the least perimeter in the reduced image's pixels (see REDUCED_MIN_CELL_PX)
            self._reduced_params.minMarkerPerimeterRate = max(self._min_perimeter_rate,
                                                              4 * self._cells * REDUCED_MIN_CELL_PX / max(size))
            self._reduced.setDetectorParameters(self._reduced_params)
            self._reduced_size = size
        found = self._found(self._reduced, small)
        # a reduced pixel's centre i is the full image's (i + 1/2) / scale - 1/2
        scale = np.array([size[0] / w, size[1] / h])
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, SUBPIX_MAX_ITER, SUBPIX_MIN_ACCURACY)
        for k, c in found.items():
            c = ((c + 0.5) / scale - 0.5).astype(np.float32)
            # OpenCV's sub-pixel search in the full image with the detector's own window: SUBPIX_WIN at most, and
            # no more than 0.3 of a cell (a wider one reaches the bits' edges and pulls the corner off)
            cell = float(np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1).sum()) / (4 * self._cells)
            win = min(SUBPIX_WIN, max(1, round(self._relative_win * cell)))
            found[k] = cv2.cornerSubPix(gray, c.reshape(-1, 1, 2), (win, win), (-1, -1), crit).reshape(4, 2)
        return {k: c.astype(np.float64) for k, c in found.items()}

    @staticmethod
    def _found(detector: cv2.aruco.ArucoDetector, gray: np.ndarray) -> dict[int, np.ndarray]:
        corners, ids, _ = detector.detectMarkers(gray)
        if ids is None:
            return {}
        return {int(i): c.reshape(4, 2).astype(np.float64) for i, c in zip(ids.ravel(), corners)}

    def _refined(self, gray: np.ndarray, found: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        if self.corner_refinement == "edges" and found:
            for k, refined in zip(list(found), refine_markers_by_edges(gray, list(found.values()), self._cells)):
                if refined is not None:
                    found[k] = refined
        return found

    def _windows(self, shape: tuple[int, ...], T_cw: np.ndarray,
                 det: dict[int, np.ndarray]) -> list[tuple[int, int, int, int, float]]:
        """Where to look for the layout's markers that the pose ``T_cw`` (map -> camera) puts wholly in the image,
        facing the camera and at least ``WINDOW_MIN_SIDE_PX`` a side, but ``det`` lacks: for each, (x0, y0, x1, y1)
        round its predicted square, padded by ``WINDOW_PAD`` sides (no less than the detector's threshold window and
        border distance) and clipped to the image, and the square's predicted perimeter (px)."""
        h, w = shape[:2]
        out = []
        centre = G.inv(T_cw)[:3, 3]
        for k, X in self._world.items():
            if k in det:
                continue
            if float(self.poses[k][:3, 2] @ (centre - self.poses[k][:3, 3])) <= 0.0:
                continue  # seen from behind (the marker's face is its frame's +z)
            uv = self.cam.project(G.transform(T_cw, X))
            if not np.all(np.isfinite(uv)) or not _inside(uv, w, h):
                continue  # behind the camera, or cut by the image's edge (the detector reads no such marker)
            sides = np.linalg.norm(uv - np.roll(uv, 1, axis=0), axis=1)
            if sides.min() < WINDOW_MIN_SIDE_PX:
                continue
            pad = max(WINDOW_PAD * float(sides.min()), self._min_pad_px)
            x0, y0 = (int(np.floor(v)) for v in np.maximum(uv.min(axis=0) - pad, 0.0))
            x1, y1 = int(np.ceil(min(uv[:, 0].max() + pad, w))), int(np.ceil(min(uv[:, 1].max() + pad, h)))
            out.append((x0, y0, x1, y1, float(sides.sum())))
        return out

    def _in_windows(self, gray: np.ndarray, windows: list[tuple[int, int, int, int, float]],
                    det: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        """The layout's markers the full image's detector finds in ``windows`` that ``det`` lacks, refined. In a
        window the detector takes no contour shorter than half the predicted perimeter (nor than the full image's
        least): its least perimeter is a share of the image it is given, and in a small crop every speck of
        texture would be a candidate to read (a 160-px window cost three times the whole 320 x 240 image)."""
        found: dict[int, np.ndarray] = {}
        least = self._min_perimeter_rate * max(gray.shape[:2])
        for x0, y0, x1, y1, perimeter in windows:
            self._window_params.minMarkerPerimeterRate = max(0.5 * perimeter, least) / max(x1 - x0, y1 - y0)
            self._window_detector.setDetectorParameters(self._window_params)
            for i, c in self._found(self._window_detector, np.ascontiguousarray(gray[y0:y1, x0:x1])).items():
                if i in self._world and i not in det and i not in found:
                    found[i] = c + (x0, y0)
        return self._refined(gray, found)

    def locate(self, gray: np.ndarray) -> MarkerResult:
        """The camera pose from the layout's markers in ``gray``. Where :attr:`reduced`: the markers the reduced
        image shows give a first pose (refused or not); a layout marker that pose puts in view but the reduced image
        missed is looked for in a window of the full image round where it should be, and the pose solved again with
        it (the first pose kept if that one fails). The whole full image is searched, as without the reduction, where
        the reduced image gives no pose (no marker of the layout, or none consistent), where the windows would cover
        more than the image, and where the pose is refused in the end."""
        self.last_passes = {"reduced" if self.reduced else "full": 1}
        det = self.detect(gray)
        res, T_cw = self._solve(det)
        if not self.reduced:
            return res
        if T_cw is not None:
            windows = self._windows(gray.shape, T_cw, det)
            if sum((x1 - x0) * (y1 - y0) for x0, y0, x1, y1, _ in windows) <= gray.shape[0] * gray.shape[1]:
                if windows:
                    self.last_passes["windows"] = len(windows)
                    more = self._in_windows(gray, windows, det)
                    if more:
                        again = self._solve({**det, **more})[0]
                        if again.T_wc is not None or res.T_wc is None:
                            res = again
                if res.T_wc is not None:
                    return res
        self.last_passes["full"] = 1
        return self._solve(self._refined(gray, self._found(self.detector, gray)))[0]

    def _solve(self, det: dict[int, np.ndarray]) -> tuple[MarkerResult, np.ndarray | None]:
        """The pose from detected markers ``det``, and the map -> camera pose it solved before the loose-pose check
        (None where there was none, or it did not fit the layout)."""
        known = {k: v for k, v in det.items() if k in self._world}
        unknown = sorted(set(det) - set(known))
        ideal = {k: self.cam.undistort_points(v) for k, v in known.items()}  # each marker's corners, undistorted once
        # a marker with a corner past 90 degrees off a fisheye's axis has no ray to solve with (NaN)
        known = {k: v for k, v in known.items() if np.isfinite(ideal[k]).all()}
        res = MarkerResult(None, sorted(known), unknown, corners=det)
        if not known:
            res.reason = ("no marker of the layout in view"
                          + (f" (saw unknown ids {res.unknown_ids})" if res.unknown_ids else ""))
            return res, None
        obj = np.concatenate([self._world[k] for k in known])
        img = np.concatenate([known[k] for k in known])
        und = np.concatenate([ideal[k] for k in known])
        # a fisheye's corners are measured in its own pixels, where the pose is polished and each corner's error
        # read, so that the checks below mean the same at the periphery (4 ideal pixels a pixel at 60 degrees) as
        # at the centre; the stretch weighs the position's spread (ideal pixels); other lenses: ideal pixels
        stretch = self.cam.stretch(img) if self.cam.fisheye else None
        K = self.cam.K

        def errors(rvec, tvec):
            if stretch is not None:  # (a corner behind the camera has no pixel: an infinite error)
                e = np.linalg.norm(self.cam.project(obj @ cv2.Rodrigues(rvec)[0].T + tvec.ravel()) - img, axis=1)
                return np.where(np.isfinite(e), e, np.inf)
            proj, _ = cv2.projectPoints(obj, rvec, tvec, K, None)
            return np.linalg.norm(proj.reshape(-1, 2) - und, axis=1)

        # initial guess: IPPE on the marker that looks largest
        best = max(known, key=lambda k: cv2.contourArea(known[k].astype(np.float32)))
        ok, rvec, tvec = cv2.solvePnP(self._local, ideal[best], K, None,
                                      flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            res.reason = "marker pose estimation failed"
            return res, None
        T_cm = G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
        T_cw = T_cm @ G.inv(self.poses[best])
        rvec, _ = cv2.Rodrigues(T_cw[:3, :3])
        tvec = T_cw[:3, 3].reshape(3, 1).copy()
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 1e-10)
        rvec, tvec = _polish(obj, und, self.cam, rvec, tvec, crit, None if stretch is None else img)
        err = errors(rvec, tvec)
        per_marker = err.reshape(-1, 4).max(axis=1)
        if len(known) > 2 and per_marker.max() > 1.0 and per_marker.max() > 4 * np.median(per_marker):
            # one marker disagrees (partly occluded, bent, glare): solve without it
            keep = np.repeat(per_marker < per_marker.max(), 4)
            res.ids = [k for k, bad in zip(known, per_marker >= per_marker.max()) if not bad]
            obj, und, img = obj[keep], und[keep], img[keep]
            if stretch is not None:
                stretch = stretch[keep]
            rvec, tvec = _polish(obj, und, self.cam, rvec, tvec, crit, None if stretch is None else img)
            err = errors(rvec, tvec)
        T_cw = G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
        res.rms_px = float(np.sqrt(np.mean(err ** 2)))
        if not res.rms_px <= 3.0:
            res.reason = (f"markers inconsistent with the layout (reprojection {res.rms_px:.1f} px): "
                          "moved marker or wrong size?")
            return res, None
        sigma = max(res.rms_px, CORNER_FLOOR_PX)
        std_m, distance = position_std(obj, K, rvec, tvec, sigma if stretch is None else sigma * stretch)
        res.std_pct = 100.0 * std_m / distance
        if not np.isfinite(res.std_pct) and self.max_std_pct > 0:
            res.reason = ("pose refused: the markers' corners do not determine the camera position (degenerate "
                          "view; localization.markers.max_std_pct)")
            return res, T_cw
        if not res.std_pct <= self.max_std_pct and self.max_std_pct > 0:
            n = len(res.ids)
            res.reason = (f"pose refused: {n} marker{'s hold' if n > 1 else ' holds'} the camera position only to "
                          f"+-{1e3 * std_m:.0f} mm ({res.std_pct:.1f} % of the {distance:.2f} m to them, over "
                          f"{self.max_std_pct:g} %): too few, too small or too blurred "
                          "(localization.markers.max_std_pct)")
            return res, T_cw
        res.T_wc = G.inv(T_cw)
        return res, T_cw


def position_std(obj: np.ndarray, K: np.ndarray, rvec: np.ndarray, tvec: np.ndarray,
                 sigma_px: float | np.ndarray) -> tuple[float, float]:
    """The camera centre's standard deviation (metres, the root of the covariance's trace) from the Gauss-Newton
    normal equations of the reprojection of ``obj`` (map points, (N, 3)) at pose (``rvec``, ``tvec``: map -> camera)
    with ``sigma_px`` of pixel noise per coordinate (one for all, or (N,) one a point: a fisheye's, in ideal pixels),
    and the points' mean distance along the optical axis (m)."""
    _, J = cv2.projectPoints(obj, rvec, tvec, K, None)
    J = J[:, :6]  # d(u, v) / d(rvec, tvec)
    if np.ndim(sigma_px):  # rows u, v of each point: each weighted by its point's 1 / sigma
        J = J / np.repeat(np.asarray(sigma_px, dtype=np.float64), 2)[:, None]
    JtJ = J.T @ J
    if not np.all(np.isfinite(JtJ)) or np.linalg.cond(JtJ) > 1e14:
        return float("inf"), float("nan")
    cov = (sigma_px ** 2 if not np.ndim(sigma_px) else 1.0) * np.linalg.inv(JtJ)
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


def _polish(obj: np.ndarray, und: np.ndarray, cam: CameraModel, rvec: np.ndarray, tvec: np.ndarray, crit,
            img: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The pose's least-squares polish: OpenCV's LM on the corners' ideal pixels; through a fisheye (``img``, the
    corners as measured) in the camera's own pixels, so that the periphery's corners, stretched up to 10 times in
    the ideal image, do not pull the pose with their amplified noise (``slam.optimize.image_pose_lm``)."""
    if img is None:
        return cv2.solvePnPRefineLM(obj, und, cam.K, None, rvec, tvec, crit)
    from simreal_nodes.vision.slam.optimize import image_pose_lm

    T = image_pose_lm(G.make_T(cv2.Rodrigues(rvec)[0], np.ravel(tvec)), obj.astype(np.float64), img,
                      np.ones(len(img)), cam, iterations=crit[1], eps=crit[2])
    return cv2.Rodrigues(T[:3, :3])[0], T[:3, 3].reshape(3, 1).copy()
