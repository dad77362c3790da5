"""Feature-based visual SLAM in the style of ORB-SLAM2 (Mur-Artal & Tardós 2017), on OpenCV and GTSAM.

Per frame: ORB features -> (not initialized) monocular two-view initialization (homography or
fundamental model, chosen by score) or an RGB-D / stereo map from the first frame -> tracking with a
constant-velocity motion model and search by projection, pose optimization with outlier rejection,
falling back to descriptor matching + PnP RANSAC -> tracking of the local map (points of the covisible
keyframes) -> keyframe decision. A new keyframe triggers local mapping: new points (triangulated with
covisible keyframes, or from depth), local bundle adjustment in GTSAM, map-point and keyframe culling.
A lost frame triggers relocalization (descriptor matching against the whole map + PnP RANSAC). In
localization-only mode the map is frozen: no keyframes, no new points.

Map points on a deforming object can be flagged ``deformable``: they never vote for the camera pose,
and they are followed from frame to frame with pyramidal Lucas-Kanade flow (started from where the
deformable tracker predicts them: their rest position moved by the current PGD estimate, §4.4.2), and
re-acquired by ORB descriptor near the prediction when the flow loses them. They are the deformable
tracker's measurements.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.states import TrackingState
from simreal_nodes.vision.camera import CameraModel
from simreal_nodes.vision.orb import Features, OrbExtractor, match_descriptors
from simreal_nodes.vision.slam.map import KeyFrame, Map
from simreal_nodes.vision.slam.optimize import CHI2_2D, AsyncBundleAdjuster, ba_request, bundle_adjust, project, refine_pose

NOT_STARTED, INITIALIZING, OK, LOST, RELOCALIZED = (TrackingState.NOT_STARTED, TrackingState.INITIALIZING,
                                                    TrackingState.OK, TrackingState.LOST, TrackingState.RELOCALIZED)
STATE_NAMES = {NOT_STARTED: "not started", INITIALIZING: "initializing", OK: "ok", LOST: "lost", RELOCALIZED: "relocalized"}
POPCOUNT = np.array([bin(i).count("1") for i in range(256)], np.uint8)


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise Hamming distance between two (n, 32) uint8 descriptor arrays."""
    return POPCOUNT[np.bitwise_xor(a, b)].sum(axis=1, dtype=np.int32)


@dataclass
class TrackResult:
    state: int
    reason: str = ""
    T_wc: np.ndarray | None = None
    n_features: int = 0
    n_matches: int = 0
    n_inliers: int = 0
    obs_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    obs_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))
    obs_inlier: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    obs_pos: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    keyframe: bool = False
    timings: dict = field(default_factory=dict)

    @property
    def state_name(self) -> str:
        return STATE_NAMES[self.state]


class Slam:
    def __init__(self, cam: CameraModel, mode: str = "mono", n_features: int = 1000, scale_factor: float = 1.2,
                 n_levels: int = 8, baseline: float | None = None, known_scale: float | None = None,
                 min_parallax_deg: float = 1.0, max_depth: float = 8.0, local_kfs: int = 10, ba_iterations: int = 10,
                 min_features: int = 40, async_mapping: bool = False, max_ba_points: int = 800):
        if mode not in ("mono", "rgbd", "stereo"):
            raise ValueError(f"SLAM mode must be mono, rgbd or stereo, not '{mode}'")
        if mode == "stereo" and not baseline:
            raise ValueError("stereo SLAM needs the stereo baseline (from the right CameraInfo's P[0,3] = -fx b)")
        self.cam = cam
        self.K = cam.K.copy()
        self.mode = mode
        self.baseline = baseline if mode == "stereo" else (0.08 if mode == "rgbd" else None)  # rgbd: virtual stereo
        self.known_scale = known_scale
        self.min_parallax = np.deg2rad(min_parallax_deg)
        self.max_depth = max_depth
        self.n_local = local_kfs
        self.ba_iterations = ba_iterations
        self.min_features = min_features
        self.extractor = OrbExtractor(n_features, scale_factor, n_levels)
        self.map = Map()
        self.state = NOT_STARTED
        self.localization_only = False
        self.T_cw_last: np.ndarray | None = None
        self.velocity: np.ndarray | None = None
        self.ref_kf: KeyFrame | None = None
        self.last_kf_frame = 0
        self.frame_id = 0
        self.init_frame = None  # (feats, stamp) for monocular initialization
        self.deformable: set[int] = set()
        self._last_seen: dict[int, np.ndarray] = {}  # deformable point id -> last observed ideal pixel
        self._predicted: dict[int, np.ndarray] = {}  # deformable point id -> predicted deformed position (map frame)
        self._last_desc: dict[int, np.ndarray] = {}  # deformable point id -> descriptor of its last match
        self._flow: dict[int, np.ndarray] = {}  # deformable point id -> raw pixel in the frame ``_flow_frame``
        self._flow_frame, self._flow_gray = -1, None
        self._anchor: dict[int, tuple[int, np.ndarray]] = {}  # deformable point id -> (frame id, raw pixel) its track started at
        self._anchor_gray: dict[int, np.ndarray] = {}  # frame id -> image, for the anchors
        self._frame_obs: dict[int, np.ndarray] = {}  # point id -> raw pixel, every observation of the last frame
        # > 0: a track is re-measured against the image it started in when that lands this close (pixels) to the
        # frame-to-frame result. Off by default: on the foam beam it cuts the measurement error from 0.8 to 0.3 px
        # but does not move the load estimate (the camera pose dominates), and on the joint boot's turning lever
        # (translation-only Lucas-Kanade on a rotated patch) it biases alpha_z to 1.3 deg (0.4 deg without)
        self.flow_anchor_px = 0.0
        self.max_anchor_images = 40
        self._gray: np.ndarray | None = None
        self.deformable_radius = 20.0  # ORB re-acquisition radius (pixels) around each predicted / last-seen pixel
        # once the object's points were followed (at least this many at a time), a frame in which the flow keeps
        # fewer (tracks lost over a long gap between frames, the prediction stale) re-acquires them within
        # reacquire_wide_px: without it a live run that skips ~10 frames at once never gets them back
        self.reacquire_below = 8
        self.reacquire_wide_px = 80.0
        self._deformable_peak = 0  # most object points followed in one frame so far
        self.flow_fb_px = 0.5  # forward-backward flow agreement to keep a deformable point's track
        self.flow_win = 11  # Lucas-Kanade window (pixels); larger windows straddle the object's silhouette and drift
        self._recent_points: list[tuple[int, int]] = []  # (point id, keyframe id at creation)
        self.lost_since: int | None = None
        self.max_ba_points = max_ba_points
        self.async_mapping = async_mapping
        self._ba = AsyncBundleAdjuster(self.K, self.baseline, ba_iterations) if async_mapping else None
        self.ba_stats = {"submitted": 0, "applied": 0, "deferred": 0}
        self._pending_ba: KeyFrame | None = None
        self._kf_inliers = 0

    def close(self) -> None:
        if self._ba is not None:
            self._ba.close()
            self._ba = None

    # ---------------------------------------------------------------------------------------------------
    # public

    def set_localization_only(self, on: bool) -> None:
        self.localization_only = bool(on)

    def set_deformable(self, ids, predicted=None) -> None:
        """Flag map points as lying on a deforming object. ``predicted``: (N, 3) map-frame positions of those
        points under the current deformation estimate (non-finite rows: no prediction), the centre of their
        image search in the next frames."""
        ids = [int(i) for i in ids]
        new = [i for i in ids if i not in self.deformable]
        self.deformable = set(ids)
        # a newly flagged point observed in this frame starts its track here, at the pixel the deformable tracker
        # linked it with (so the measured pixel and the linked material point are the same from the start)
        if self._flow_frame == self.frame_id and self._gray is not None:
            for i in new:
                q = self._frame_obs.get(i)
                if q is not None and i not in self._flow:
                    self._flow[i] = q.copy()
                    if self.flow_anchor_px > 0:
                        self._start_anchor(i, q)
        for i in self.deformable:
            if i in self.map.points:
                self.map.points[i].deformable = True
        if predicted is None:
            return
        P = np.asarray(predicted, dtype=np.float64).reshape(-1, 3)
        if len(P) != len(ids):
            raise ValueError(f"{len(ids)} deformable point ids but {len(P)} predicted positions")
        good = np.all(np.isfinite(P), axis=1)
        self._predicted = {i: P[k].copy() for k, i in enumerate(ids) if good[k]}

    def drop_tracks(self, ids) -> None:
        """Forget the frame-to-frame tracks of these deformable points (the deformable tracker found them far
        from the model's fit: a flow track that slid); they are re-acquired by descriptor."""
        for i in ids:
            self._flow.pop(int(i), None)
            self._last_seen.pop(int(i), None)

    def _start_anchor(self, pid: int, raw: np.ndarray) -> None:
        self._anchor[pid] = (self.frame_id, np.asarray(raw, np.float64).copy())
        self._anchor_gray.setdefault(self.frame_id, self._gray)

    def _refine_on_anchors(self, found: dict, lk: dict) -> set:
        """Re-measure tracked points against the image their track started in (not the previous frame): frame-to-
        frame flow drifts like a random walk (0.4 px after 5 frames, 1 px after 30 on the foam beam at 1280 x 720),
        one Lucas-Kanade step from the first image does not. Kept where it lands within ``flow_anchor_px`` of the
        frame-to-frame result, which guards against a surface that has changed its look. Returns the ids moved."""
        groups: dict[int, list[int]] = {}
        for pid in found:
            a = self._anchor.get(pid)
            if a is not None and a[0] != self.frame_id and a[0] in self._anchor_gray:
                groups.setdefault(a[0], []).append(pid)
        moved = set()
        H, W = self._gray.shape[:2]
        for fid, pids in groups.items():
            p0 = np.array([self._anchor[p][1] for p in pids], np.float32).reshape(-1, 1, 2)
            q0 = np.array([found[p] for p in pids], np.float32).reshape(-1, 1, 2)
            q1, st, _ = cv2.calcOpticalFlowPyrLK(self._anchor_gray[fid], self._gray, p0, q0.copy(),
                                                 flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **{**lk, "maxLevel": 1})
            q1 = q1.reshape(-1, 2)
            ok = (st.ravel() == 1) & (np.linalg.norm(q1 - q0.reshape(-1, 2), axis=1) < self.flow_anchor_px)
            ok &= (q1[:, 0] >= 0) & (q1[:, 0] < W) & (q1[:, 1] >= 0) & (q1[:, 1] < H)
            for p, good, q in zip(pids, ok, q1):
                if good:
                    found[p] = q.astype(np.float64)
                    moved.add(p)
        return moved

    def _prune_anchors(self) -> None:
        for pid in [p for p in self._anchor if p not in self.deformable or p not in self.map.points]:
            self._anchor.pop(pid)
        used = {a[0] for a in self._anchor.values()}
        for fid in [f for f in self._anchor_gray if f not in used]:
            self._anchor_gray.pop(fid)
        while len(self._anchor_gray) > self.max_anchor_images:  # bounded memory: the oldest anchors restart
            old = min(self._anchor_gray)
            self._anchor_gray.pop(old)
            for pid in [p for p, a in self._anchor.items() if a[0] == old]:
                self._anchor.pop(pid)

    def reset(self) -> None:
        self.close()
        self.__init__(self.cam, self.mode, self.extractor.n, self.extractor.sf, self.extractor.levels,
                      self.baseline if self.mode == "stereo" else None, self.known_scale,
                      np.rad2deg(self.min_parallax), self.max_depth, self.n_local, self.ba_iterations, self.min_features,
                      self.async_mapping, self.max_ba_points)

    def load_map(self, m: Map) -> None:
        self.map = m
        self.state = LOST  # relocalize into it
        self.set_deformable({p.id for p in m.points.values() if p.deformable})

    def track(self, gray: np.ndarray, stamp: int = 0, depth: np.ndarray | None = None, right: np.ndarray | None = None) -> TrackResult:
        """Process one frame. ``gray``: uint8 image; ``depth``: metres (NaN/0 invalid) registered to it;
        ``right``: the right image of a rectified stereo pair."""
        t0 = time.perf_counter()
        self.frame_id += 1
        self._gray = gray
        tim = {}
        if self._ba is not None:
            res = self._ba.poll()
            if res is not None:
                self._apply_ba(res)
                if self._pending_ba is not None and self._pending_ba.id in self.map.keyframes:
                    kf, self._pending_ba = self._pending_ba, None
                    self._bundle_adjust([kf] + self.map.covisible(kf, self.n_local), None)
        quality = self._image_problem(gray)
        feats = Features.empty() if quality else self.extractor.extract(gray, self.cam)
        tim["extract_ms"] = (time.perf_counter() - t0) * 1e3
        if not quality and len(feats) < self.min_features:
            quality = f"too few features ({len(feats)}): textureless view"
        if quality:
            return self._fail(quality, tim, len(feats))
        z = self._feature_depth(feats, depth, right)
        tim["depth_ms"] = (time.perf_counter() - t0) * 1e3 - tim["extract_ms"]
        if self.state in (NOT_STARTED, INITIALIZING):
            res = self._initialize(feats, z, stamp)
        elif self.state == LOST:
            res = self._relocalize(feats, z, stamp, tim)
        else:
            res = self._track(feats, z, stamp, tim)
        res.n_features = len(feats)
        res.timings.update(tim)
        res.timings["total_ms"] = (time.perf_counter() - t0) * 1e3
        return res

    # ---------------------------------------------------------------------------------------------------
    # frame checks and depth

    @staticmethod
    def _image_problem(gray: np.ndarray) -> str:
        m = float(gray[::4, ::4].mean())
        if m < 6:
            return "black frame (no light, lens covered or camera blackout)"
        if m > 249:
            return "saturated frame (overexposed)"
        if float(gray[::4, ::4].std()) < 2.0:
            return "textureless frame (uniform image)"
        return ""

    def _fail(self, reason: str, tim: dict, nf: int) -> TrackResult:
        if self.state in (OK, RELOCALIZED):
            self.state = LOST
            self.lost_since = self.frame_id
            self.velocity = None
        st = self.state if self.state != NOT_STARTED else NOT_STARTED
        if st == LOST:
            reason = f"lost: {reason}"
        return TrackResult(st, reason, None, nf, timings=tim)

    def _feature_depth(self, f: Features, depth, right) -> np.ndarray | None:
        if self.mode == "rgbd":
            if depth is None:
                return np.full(len(f), np.nan)
            h, w = depth.shape
            u = np.clip(np.round(f.uv[:, 0]).astype(int), 0, w - 1)
            v = np.clip(np.round(f.uv[:, 1]).astype(int), 0, h - 1)
            z = depth[v, u].astype(np.float64)
            z[~np.isfinite(z) | (z <= 0.05) | (z > self.max_depth)] = np.nan
            return z
        if self.mode == "stereo":
            if right is None:
                return np.full(len(f), np.nan)
            from simreal_nodes.vision.stereo import sparse_stereo_depth

            return sparse_stereo_depth(f, right, self.extractor, self.cam, self.baseline, self.max_depth)
        return None

    # ---------------------------------------------------------------------------------------------------
    # initialization

    def _initialize(self, f: Features, z, stamp) -> TrackResult:
        if self.mode in ("rgbd", "stereo"):
            ok = np.isfinite(z)
            if ok.sum() < 100:
                self.state = INITIALIZING
                return TrackResult(INITIALIZING, f"waiting for depth: {int(ok.sum())} features with valid depth (need 100)")
            kf = self.map.new_keyframe(stamp, np.eye(4), f, z)
            P = self._backproject(f.und[ok], z[ok])
            for i, p in zip(np.flatnonzero(ok), P):
                self.map.new_point(p, f.desc[i], kf, int(i))
            self.map.scale_known = True
            return self._initialized(kf, f, stamp)
        # monocular: two-view initialization against a reference frame
        if self.init_frame is None or len(self.init_frame[0]) < 100 or self.frame_id - self.init_frame[2] > 60:
            self.init_frame = (f, stamp, self.frame_id)
            self.state = INITIALIZING
            return TrackResult(INITIALIZING, "initializing: reference frame set, move the camera sideways")
        f0, s0, _ = self.init_frame
        reason, sol = self._two_view(f0, f)
        if sol is None:
            self.state = INITIALIZING
            return TrackResult(INITIALIZING, f"initializing: {reason}")
        R, t, P, i0, i1 = sol
        kf0 = self.map.new_keyframe(s0, np.eye(4), f0)
        T_cw1 = G.make_T(R, t)
        kf1 = self.map.new_keyframe(stamp, G.inv(T_cw1), f)
        for p, a, b in zip(P, i0, i1):
            mp = self.map.new_point(p, f.desc[b], kf0, int(a))
            self.map.link(mp, kf1, int(b))
        self._bundle_adjust([kf1], [kf0], sync=True)  # before the scale is fixed: never asynchronous
        # scale: median scene depth 1 (ORB-SLAM2) or the known baseline between the two views
        Pc = np.array([p.pos for p in self.map.points.values()])
        s = self.known_scale / np.linalg.norm(kf1.center) if self.known_scale else 1.0 / np.median(Pc[:, 2])
        for p in self.map.points.values():
            p.pos = p.pos * s
        kf1.T_wc[:3, 3] *= s
        self.map.scale_known = bool(self.known_scale)
        self.init_frame = None
        return self._initialized(kf1, f, stamp, f"initialized from {len(P)} points ({sol_kind(reason)})")

    def _initialized(self, kf: KeyFrame, f: Features, stamp, msg: str = "") -> TrackResult:
        self.ref_kf = kf
        self.T_cw_last = kf.T_cw
        self.velocity = None
        self.last_kf_frame = self.frame_id
        self._kf_inliers = int(np.sum(kf.mp >= 0))
        self.state = OK
        ids = kf.mp[kf.mp >= 0]
        res = self._result(OK, msg or f"initialized with {len(ids)} points from depth", kf.T_wc, f,
                           np.flatnonzero(kf.mp >= 0), ids, np.ones(len(ids), bool))
        res.keyframe = True
        return res

    def _two_view(self, f0: Features, f1: Features):
        d = np.linalg.norm(f0.und[:, None, :] - f1.und[None, :, :], axis=2) if len(f0) * len(f1) < 4e6 else None
        mask = (d < 150) if d is not None else None
        m = match_descriptors(f0.desc, f1.desc, mask, max_dist=50, ratio=0.9)
        if len(m) < 100:
            return f"only {len(m)} matches with the reference frame (need 100): too little overlap or texture", None
        x0, x1 = f0.und[m[:, 0]], f1.und[m[:, 1]]
        H, mh = cv2.findHomography(x0, x1, cv2.RANSAC, 2.0)
        F, mf = cv2.findFundamentalMat(x0, x1, cv2.FM_RANSAC, 1.5, 0.999)
        if F is None or F.shape != (3, 3) or H is None:
            return "cannot estimate two-view geometry", None
        sh = _score_h(H, x0, x1)
        sf = _score_f(F, x0, x1)
        rh = sh / max(sh + sf, 1e-9)
        parallax = None
        if rh > 0.45:
            sol = self._from_h(H, x0, x1)
            kind = "homography"
        else:
            sol = self._from_f(F, x0, x1, mf.ravel().astype(bool))
            kind = "fundamental"
        if sol is None:
            return f"{kind} model gives no valid reconstruction", None
        R, t, P, good, parallax = sol
        if parallax < self.min_parallax:
            return (f"not enough parallax ({np.rad2deg(parallax):.2f} deg, need {np.rad2deg(self.min_parallax):.1f}): "
                    "a pure rotation cannot initialize a monocular map, translate the camera"), None
        if good.sum() < 50:
            return f"only {int(good.sum())} points triangulate well (need 50)", None
        return f"{kind} model", (R, t, P[good], m[good, 0], m[good, 1])

    def _triangulate_check(self, R, t, x0, x1):
        Kinv = np.linalg.inv(self.K)
        P0 = self.K @ np.c_[np.eye(3), np.zeros(3)]
        P1 = self.K @ np.c_[R, t]
        X = cv2.triangulatePoints(P0, P1, x0.T.astype(np.float64), x1.T.astype(np.float64))
        X = (X[:3] / X[3]).T
        z0 = X[:, 2]
        X1 = X @ R.T + t
        z1 = X1[:, 2]
        uv0, _ = project(np.eye(4), X, self.K)
        uv1, _ = project(G.make_T(R, t), X, self.K)
        e0 = np.sum((uv0 - x0) ** 2, axis=1)
        e1 = np.sum((uv1 - x1) ** 2, axis=1)
        c0 = -R.T @ t
        r0 = X / np.maximum(np.linalg.norm(X, axis=1, keepdims=True), 1e-12)
        r1 = (X - c0) / np.maximum(np.linalg.norm(X - c0, axis=1, keepdims=True), 1e-12)
        cospar = np.sum(r0 * r1, axis=1)
        good = (z0 > 0) & (z1 > 0) & (e0 < 4 * CHI2_2D) & (e1 < 4 * CHI2_2D) & np.all(np.isfinite(X), axis=1)
        good &= cospar < 0.99998
        par = float(np.arccos(np.clip(np.median(cospar[good]), -1, 1))) if good.sum() else 0.0
        return X, good, par

    def _from_f(self, F, x0, x1, inl):
        E = self.K.T @ F @ self.K
        _, R, t, _ = cv2.recoverPose(E, x0[inl].astype(np.float64), x1[inl].astype(np.float64), self.K)
        t = t.ravel()
        X, good, par = self._triangulate_check(R, t, x0, x1)
        good &= inl
        return (R, t, X, good, par) if good.sum() >= 50 else None

    def _from_h(self, H, x0, x1):
        n, Rs, ts, _ = cv2.decomposeHomographyMat(H, self.K)
        best, second = None, 0
        for R, t in zip(Rs, ts):
            t = t.ravel()
            if np.linalg.norm(t) < 1e-9:
                continue
            X, good, par = self._triangulate_check(R, t / np.linalg.norm(t), x0, x1)
            c = int(good.sum())
            if best is None or c > best[3].sum():
                second = best[3].sum() if best is not None else second
                best = (R, t / np.linalg.norm(t), X, good, par)
            elif c > second:
                second = c
        if best is None or best[3].sum() < 50 or second > 0.75 * best[3].sum():
            return None
        return best

    # ---------------------------------------------------------------------------------------------------
    # tracking

    def _track(self, f: Features, z, stamp, tim) -> TrackResult:
        t0 = time.perf_counter()
        T_pred = self.velocity @ self.T_cw_last if self.velocity is not None else self.T_cw_last
        local_ids = self._local_points()
        match = self._search_projection(f, T_pred, local_ids, radius=15.0)
        if len(match) < 30:
            match = self._search_projection(f, T_pred, local_ids, radius=40.0)
        tim["match_ms"] = (time.perf_counter() - t0) * 1e3
        t1 = time.perf_counter()
        T, inl = self._pose(f, match, T_pred)
        if inl.sum() < 20:
            # fast motion: the prediction is off; match descriptors to the local map and solve PnP
            T2, m2, inl2 = self._pnp_ransac(f, local_ids)
            if T2 is not None and inl2.sum() > inl.sum():
                T, match, inl = T2, m2, inl2
        tim["pose_ms"] = (time.perf_counter() - t1) * 1e3
        if inl.sum() < 15:
            self.state = LOST
            self.lost_since = self.frame_id
            self.velocity = None
            return TrackResult(LOST, f"lost: only {int(inl.sum())} pose inliers (fast motion, occlusion or leaving the map)",
                               None, n_matches=len(match), timings=tim)
        # track the local map
        t2 = time.perf_counter()
        self._update_visibility(match[inl])
        local_ids = self._local_points(match[inl, 1])
        more = self._search_projection(f, T, local_ids, radius=8.0, exclude_kp=match[:, 0], exclude_pt=match[:, 1])
        if len(more):
            match = np.concatenate([match[inl], more])
            T, inl = self._pose(f, match, T)
        tim["local_map_ms"] = (time.perf_counter() - t2) * 1e3
        # ORB-SLAM2's acceptance: enough inliers after tracking the local map (more just after a relocalization)
        need = 50 if self.lost_since is not None and self.frame_id - self.lost_since < 30 else 30
        if inl.sum() < need:
            self.state = LOST
            self.lost_since = self.frame_id
            self.velocity = None
            return TrackResult(LOST, f"lost: only {int(inl.sum())} inliers after tracking the local map (need {need})",
                               None, n_matches=len(match), timings=tim)
        self.map._nfound[match[inl, 1]] += 1
        state = RELOCALIZED if self.state == RELOCALIZED else OK
        self.state = OK
        self.velocity = T @ G.inv(self.T_cw_last)
        self.T_cw_last = T
        res = self._result(state, "", G.inv(T), f, match[:, 0], match[:, 1], inl)
        res.n_matches, res.n_inliers = len(match), int(inl.sum())
        self._deformable_observations(f, T, res, exclude=match[:, 0])
        # keyframe decision and local mapping
        if not self.localization_only and self._need_keyframe(int(inl.sum()), z):
            t3 = time.perf_counter()
            kf = self.map.new_keyframe(stamp, G.inv(T), f, z)
            for (kp, pid), ok in zip(match, inl):
                if ok and int(pid) in self.map.points:
                    self.map.link(self.map.points[int(pid)], kf, int(kp))
            self._local_mapping(kf)
            self.ref_kf = kf
            self.last_kf_frame = self.frame_id
            self._kf_inliers = int(inl.sum())
            res.keyframe = True
            tim["mapping_ms"] = (time.perf_counter() - t3) * 1e3
        return res

    def _pose(self, f: Features, match: np.ndarray, T_init: np.ndarray):
        if len(match) == 0:
            return T_init, np.zeros(0, bool)
        P = self.map._pos[match[:, 1]]
        return refine_pose(T_init, P, f.und[match[:, 0]], f.sigma2()[match[:, 0]], self.K)

    def _pnp_ransac(self, f: Features, ids=None):
        ids, P, D = self.map.point_arrays(ids)
        if self.deformable and len(ids):
            keep = ~np.isin(ids, np.fromiter(self.deformable, np.int64))
            ids, P, D = ids[keep], P[keep], D[keep]
        m = match_descriptors(f.desc, D, max_dist=50, ratio=0.8)
        if len(m) < 15:
            return None, np.zeros((0, 2), np.int64), np.zeros(0, bool)
        ok, rvec, tvec, inl_idx = cv2.solvePnPRansac(P[m[:, 1]], f.und[m[:, 0]].astype(np.float64), self.K, None,
                                                     iterationsCount=300, reprojectionError=4.0, confidence=0.999,
                                                     flags=cv2.SOLVEPNP_EPNP)
        if not ok or inl_idx is None or len(inl_idx) < 12:
            return None, np.zeros((0, 2), np.int64), np.zeros(0, bool)
        T0 = G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
        match = np.c_[m[:, 0], ids[m[:, 1]]]
        T, inl = self._pose(f, match, T0)
        return T, match, inl

    def _relocalization_candidates(self, f: Features, max_kfs: int = 12):
        """Keyframes to relocalize against (ORB-SLAM2 uses a bag of words; here a sample of the frame's
        descriptors votes for the keyframes with most close matches)."""
        kfs = list(self.map.keyframes.values())
        if len(kfs) <= max_kfs:
            return kfs
        sample = np.linspace(0, len(f) - 1, min(200, len(f))).astype(int)
        votes = []
        for kf in kfs:
            m = match_descriptors(f.desc[sample], kf.feats.desc, max_dist=40)
            votes.append(len(m))
        order = np.argsort(votes)[::-1][:max_kfs]
        return [kfs[i] for i in order]

    def _pnp_keyframe(self, f: Features, kf: KeyFrame):
        """2D-3D correspondences through one keyframe's features, then PnP RANSAC."""
        has = np.flatnonzero(kf.mp >= 0)
        if len(has) < 15:
            return None, np.zeros((0, 2), np.int64), np.zeros(0, bool)
        m = match_descriptors(f.desc, kf.feats.desc[has], max_dist=50, ratio=0.75)
        if len(m) < 15:
            return None, np.zeros((0, 2), np.int64), np.zeros(0, bool)
        ids = kf.mp[has[m[:, 1]]]
        alive = self.map.alive(ids) & ~np.isin(ids, np.fromiter(self.deformable, np.int64) if self.deformable else np.zeros(0, np.int64))
        m, ids = m[alive], ids[alive]
        if len(m) < 15:
            return None, np.zeros((0, 2), np.int64), np.zeros(0, bool)
        P = self.map._pos[ids]
        ok, rvec, tvec, inl_idx = cv2.solvePnPRansac(P, f.und[m[:, 0]].astype(np.float64), self.K, None,
                                                     iterationsCount=300, reprojectionError=4.0, confidence=0.999,
                                                     flags=cv2.SOLVEPNP_EPNP)
        if not ok or inl_idx is None or len(inl_idx) < 12:
            return None, np.zeros((0, 2), np.int64), np.zeros(0, bool)
        T0 = G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
        match = np.c_[m[:, 0], ids]
        T, inl = self._pose(f, match, T0)
        return T, match, inl

    def _relocalize(self, f: Features, z, stamp, tim) -> TrackResult:
        t0 = time.perf_counter()
        if not self.map.points:
            self.state = NOT_STARTED
            return TrackResult(NOT_STARTED, "no map to relocalize in", timings=tim)
        T, match, inl = None, np.zeros((0, 2), np.int64), np.zeros(0, bool)
        for kf in self._relocalization_candidates(f):
            T_k, m_k, inl_k = self._pnp_keyframe(f, kf)
            if T_k is not None and inl_k.sum() > inl.sum():
                T, match, inl = T_k, m_k, inl_k
                if inl.sum() >= 50:
                    break
        tim["relocalization_ms"] = (time.perf_counter() - t0) * 1e3
        if T is None or inl.sum() < 25:
            n = 0 if T is None else int(inl.sum())
            return TrackResult(LOST, f"lost: relocalization found {n} inliers (need 25)", None, n_matches=len(match), timings=tim)
        local = self._local_points(match[inl, 1])
        more = self._search_projection(f, T, local, radius=10.0, exclude_kp=match[:, 0], exclude_pt=match[:, 1])
        if len(more):
            match = np.concatenate([match[inl], more])
            T, inl = self._pose(f, match, T)
        if inl.sum() < 30:
            return TrackResult(LOST, f"lost: relocalization kept {int(inl.sum())} inliers (need 30)", None, timings=tim)
        self.state = OK
        self.T_cw_last = T
        self.velocity = None
        lost_for = self.frame_id - (self.lost_since or self.frame_id)
        res = self._result(RELOCALIZED, f"relocalized after {lost_for} frames", G.inv(T), f, match[:, 0], match[:, 1], inl)
        res.n_matches, res.n_inliers = len(match), int(inl.sum())
        self._deformable_observations(f, T, res, exclude=match[:, 0])
        return res

    def _local_points(self, seed_ids=None) -> np.ndarray:
        """Point ids of the local map: keyframes that see the tracked points (``seed_ids``) most, plus the
        reference keyframe and its covisible neighbours (at most ~2 x n_local keyframes). The keyframe set
        is cached until the map's keyframes change (or a few frames pass)."""
        key = (self.map.version, self.ref_kf.id if self.ref_kf is not None else -1, self.frame_id // 5, seed_ids is None)
        if getattr(self, "_local_key", None) == key:
            ids = self._local_cache
            ids = ids[self.map.alive(ids)]
            return ids
        ids = self._compute_local_points(seed_ids)
        self._local_key, self._local_cache = key, ids
        return ids

    def _compute_local_points(self, seed_ids=None) -> np.ndarray:
        kfs = {}
        if seed_ids is not None and len(seed_ids):
            counts: dict[int, int] = {}
            for pid in seed_ids:
                p = self.map.points.get(int(pid))
                if p is None:
                    continue
                for kid in p.obs:
                    counts[kid] = counts.get(kid, 0) + 1
            for kid in sorted(counts, key=counts.get, reverse=True)[: self.n_local]:
                kfs[kid] = self.map.keyframes[kid]
        if self.ref_kf is not None and self.ref_kf.id in self.map.keyframes:
            kfs[self.ref_kf.id] = self.ref_kf
            for k in self.map.covisible(self.ref_kf, self.n_local):
                kfs[k.id] = k
        if not kfs and self.map.keyframes:
            last = max(self.map.keyframes)
            kfs[last] = self.map.keyframes[last]
        if not kfs:
            return np.zeros(0, np.int64)
        ids = np.unique(np.concatenate([kf.mp[kf.mp >= 0] for kf in kfs.values()]))
        ids = ids[self.map.alive(ids)]
        if self.deformable:
            ids = ids[~np.isin(ids, np.fromiter(self.deformable, np.int64))]
        return ids

    def _search_projection(self, f: Features, T_cw, ids, radius: float, exclude_kp=None, exclude_pt=None,
                           max_dist: int = 64) -> np.ndarray:
        """Matches (kp index, point id): each map point projected with T_cw, matched to the best
        descriptor among unmatched features within ``radius`` x scale pixels."""
        ids = np.asarray(ids, np.int64)
        if exclude_pt is not None and len(exclude_pt):
            ids = ids[~np.isin(ids, np.asarray(exclude_pt, np.int64))]
        if len(ids):
            P, D = self.map._pos[ids], self.map._desc[ids]
        if len(ids) == 0 or len(f) == 0:
            return np.zeros((0, 2), np.int64)
        uv, zc = project(T_cw, P, self.K)
        W, H = self.cam.width, self.cam.height
        vis = (zc > 0) & (uv[:, 0] >= -10) & (uv[:, 0] < W + 10) & (uv[:, 1] >= -10) & (uv[:, 1] < H + 10)
        self.map._nvis[ids[vis]] += 1
        if not np.any(vis):
            return np.zeros((0, 2), np.int64)
        ids, uv, D = ids[vis], uv[vis], D[vis]
        avail = np.ones(len(f), bool)
        if exclude_kp is not None and len(exclude_kp):
            avail[np.asarray(exclude_kp, np.int64)] = False
        kp_idx = np.flatnonzero(avail)
        if len(kp_idx) == 0:
            return np.zeros((0, 2), np.int64)
        tree = cKDTree(f.und[kp_idx])
        rmax = radius * f.scale_factor ** 2
        k = min(8, len(kp_idx))
        dpix, nn = tree.query(uv, k=k, distance_upper_bound=rmax)  # fixed shape: vectorized candidates
        dpix, nn = dpix.reshape(len(uv), k), nn.reshape(len(uv), k)
        valid = np.isfinite(dpix)
        rows = np.broadcast_to(np.arange(len(uv))[:, None], nn.shape)[valid]
        cols = kp_idx[nn[valid]]
        dpix = dpix[valid]
        if len(rows) == 0:
            return np.zeros((0, 2), np.int64)
        ok = dpix <= radius * f.scale_factor ** f.octave[cols]
        rows, cols = rows[ok], cols[ok]
        dist = hamming(D[rows], f.desc[cols])
        good = dist <= max_dist
        rows, cols, dist = rows[good], cols[good], dist[good]
        if len(rows) == 0:
            return np.zeros((0, 2), np.int64)
        order = np.lexsort((dist, rows))
        rows, cols, dist = rows[order], cols[order], dist[order]
        first = np.r_[True, rows[1:] != rows[:-1]]
        rows, cols, dist = rows[first], cols[first], dist[first]
        order = np.lexsort((dist, cols))
        rows, cols = rows[order], cols[order]
        first = np.r_[True, cols[1:] != cols[:-1]]
        return np.c_[cols[first], ids[rows[first]]].astype(np.int64)

    def _deformable_observations(self, f: Features, T_cw, res: TrackResult, exclude) -> None:
        """:meth:`_measure_deformable`, then this frame's observations are kept: a point flagged deformable after it
        starts its track at the pixel it was seen at here (:meth:`set_deformable`)."""
        self._measure_deformable(f, T_cw, res, exclude)
        self._frame_obs = {int(i): q for i, q in zip(res.obs_ids, res.obs_uv)}
        if self._flow_frame != self.frame_id:  # no deformable points yet: this frame is where new tracks start
            self._flow, self._flow_frame, self._flow_gray = {}, self.frame_id, self._gray

    def _measure_deformable(self, f: Features, T_cw, res: TrackResult, exclude) -> None:
        """Measurements of the map points flagged deformable (never used for the pose), appended to the
        observations as pose outliers, with their rest positions (the tracker links those to the model).

        1. Flow: a point measured in the previous frame is followed with pyramidal Lucas-Kanade, started at
           its predicted pixel, and kept if the backward flow returns within ``flow_fb_px``. A deforming,
           obliquely seen surface soon looks unlike the keyframe that created the point, so descriptors alone
           lose it; the flow follows the appearance from frame to frame, to sub-pixel.
        2. Re-acquisition: any other point is searched among the ORB features within ``deformable_radius``
           pixels of its predicted projection and of its last observation, and matched to the closest
           descriptor (the map's, or that of its last ORB match) within 50 bits.
        The tracker's robust loss catches a flow track that slides onto a neighbour."""
        if not self.deformable:
            return
        ids = [i for i in self.deformable if i in self.map.points]
        if not ids:
            return
        ids_a, P, D = self.map.point_arrays(ids)
        P = P.copy()
        has_pred = np.array([int(i) in self._predicted for i in ids_a])
        if has_pred.any():
            P[has_pred] = np.array([self._predicted[int(i)] for i in ids_a[has_pred]])
        uv, zc = project(T_cw, P, self.K)  # ideal pixels of the predictions (rest positions without one)
        raw_pred = self.cam.project(P @ T_cw[:3, :3].T + T_cw[:3, 3])
        found: dict[int, np.ndarray] = {}  # point id -> raw pixel
        new_desc: dict[int, np.ndarray] = {}
        # 1. flow from the previous frame
        if self._flow and self._flow_frame == self.frame_id - 1 and self._flow_gray is not None and self._gray is not None:
            sel = np.array([k for k, pid in enumerate(ids_a) if int(pid) in self._flow and zc[k] > 0], np.int64)
            if len(sel):
                p0 = np.array([self._flow[int(ids_a[k])] for k in sel], np.float32).reshape(-1, 1, 2)
                guess = np.where(np.isfinite(raw_pred[sel]), raw_pred[sel], p0.reshape(-1, 2)).astype(np.float32)
                lk = dict(winSize=(self.flow_win, self.flow_win), maxLevel=3, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
                p1, st, _ = cv2.calcOpticalFlowPyrLK(self._flow_gray, self._gray, p0, guess.reshape(-1, 1, 2).copy(),
                                                     flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
                pb, st2, _ = cv2.calcOpticalFlowPyrLK(self._gray, self._flow_gray, p1, p0.copy(),
                                                      flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
                p1, pb = p1.reshape(-1, 2), pb.reshape(-1, 2)
                H, W = self._gray.shape[:2]
                ok = (st.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm(pb - p0.reshape(-1, 2), axis=1) < self.flow_fb_px)
                ok &= (p1[:, 0] >= 0) & (p1[:, 0] < W) & (p1[:, 1] >= 0) & (p1[:, 1] < H)
                for k, good, q in zip(sel, ok, p1):
                    if good:
                        found[int(ids_a[k])] = q.astype(np.float64)
        # 2. ORB re-acquisition of the others
        lost_tracks = len(found) < self.reacquire_below <= self._deformable_peak
        radius = max(self.deformable_radius, self.reacquire_wide_px) if lost_tracks else self.deformable_radius
        avail = np.ones(len(f), bool)
        avail[np.asarray(exclude, np.int64)] = False
        kp_idx = np.flatnonzero(avail)
        if len(kp_idx):
            tree = cKDTree(f.und[kp_idx])
            for k, pid in enumerate(ids_a):
                pid = int(pid)
                if pid in found or zc[k] <= 0:
                    continue
                centres = [uv[k]] if (has_pred[k] or pid not in self._last_seen) else []
                if pid in self._last_seen:
                    centres.append(self._last_seen[pid])
                c = set()
                for q in centres:
                    if np.all(np.isfinite(q)):
                        c.update(tree.query_ball_point(q, radius))
                if not c:
                    continue
                c = kp_idx[np.fromiter(c, np.int64)]
                d = hamming(np.repeat(D[k][None], len(c), axis=0), f.desc[c])
                last = self._last_desc.get(pid)
                if last is not None:
                    d = np.minimum(d, hamming(np.repeat(last[None], len(c), axis=0), f.desc[c]))
                j = int(np.argmin(d))
                if d[j] <= 50:
                    found[pid] = f.uv[c[j]].astype(np.float64)
                    new_desc[pid] = f.desc[c[j]].copy()
        # 3. every measurement of a point whose track started in an earlier image is taken against that image;
        # a point without one (or whose surface no longer looks like it) starts its track here
        if found and self.flow_anchor_px > 0:
            lk = dict(winSize=(self.flow_win, self.flow_win), maxLevel=1, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
            moved = self._refine_on_anchors(found, lk)
            for pid in found:
                if pid not in moved and (pid not in self._anchor or pid in new_desc):
                    self._start_anchor(pid, found[pid])
        self._prune_anchors()
        # the measurements and the state for the next frame
        self._deformable_peak = max(self._deformable_peak, len(found))
        self._flow, self._flow_frame, self._flow_gray = found, self.frame_id, self._gray
        self._last_desc.update(new_desc)
        for pid in list(self._last_seen):
            if pid not in found:
                self._last_seen.pop(pid)
        if not found:
            return
        new_ids = np.fromiter(found, np.int64)
        raw = np.array([found[int(i)] for i in new_ids])
        und = self.cam.undistort_points(raw)
        for pid, q in zip(new_ids, und):
            self._last_seen[int(pid)] = q
        res.obs_ids = np.concatenate([res.obs_ids, new_ids])
        res.obs_uv = np.concatenate([res.obs_uv, raw])
        res.obs_inlier = np.concatenate([res.obs_inlier, np.zeros(len(new_ids), bool)])
        res.obs_pos = np.concatenate([res.obs_pos, self.map._pos[new_ids]])

    def _update_visibility(self, match) -> None:
        pass

    def _result(self, state, reason, T_wc, f, kp, ids, inl) -> TrackResult:
        ids = np.asarray(ids, np.int64)
        kp = np.asarray(kp, np.int64)
        pos = self.map._pos[ids].copy() if len(ids) else np.zeros((0, 3))
        return TrackResult(state, reason, T_wc, len(f), len(ids), int(np.sum(inl)), ids, f.uv[kp], np.asarray(inl, bool), pos)

    # ---------------------------------------------------------------------------------------------------
    # mapping

    def _need_keyframe(self, n_inliers: int, z) -> bool:
        """ORB-SLAM2's rule, simplified: the current frame tracks clearly fewer points than the reference
        keyframe holds (seen by >= 2 keyframes), or too long since the last keyframe."""
        if self.ref_kf is None:
            return True
        ids = self.ref_kf.mp[self.ref_kf.mp >= 0]
        ref_n = sum(1 for i in ids if int(i) in self.map.points and len(self.map.points[int(i)].obs) >= 2)
        if self.mode != "mono" and len(self.map.keyframes) < 3:
            ref_n = len(ids)
        since = self.frame_id - self.last_kf_frame
        if since < 5:
            return False  # (new points are triangulated here at once; only their refinement is asynchronous)
        ratio = 0.9 if self.mode == "mono" else 0.6
        # fewer tracked points than the reference keyframe holds, or tracking clearly degrading since it
        few = n_inliers < ratio * ref_n or n_inliers < 0.6 * self._kf_inliers
        if self.mode != "mono":
            few = few or n_inliers < 100
        return (few or since > 30) and n_inliers > 15

    def _local_mapping(self, kf: KeyFrame) -> None:
        new = self._create_points(kf)
        for pid in new:
            self._recent_points.append((pid, kf.id))
        neighbours = self.map.covisible(kf, self.n_local)
        self._bundle_adjust([kf] + neighbours, None)
        self._cull_points(kf)
        self._cull_keyframes(neighbours)

    def _create_points(self, kf: KeyFrame) -> list[int]:
        created = []
        f = kf.feats
        free = kf.mp < 0
        if self.mode != "mono" and kf.depth is not None:
            ok = free & np.isfinite(kf.depth)
            idx = np.flatnonzero(ok)
            idx = idx[np.argsort(kf.depth[idx])][:250]
            P = self._backproject(f.und[idx], kf.depth[idx])
            T = kf.T_wc
            for i, p in zip(idx, P @ T[:3, :3].T + T[:3, 3]):
                created.append(self.map.new_point(p, f.desc[i], kf, int(i)).id)
            return created
        # monocular: triangulate unmatched features with the covisible keyframes
        for other in self.map.covisible(kf, 6):
            base = np.linalg.norm(kf.center - other.center)
            med = self._median_depth(other)
            if med <= 0 or base / med < 0.01:
                continue
            fa = np.flatnonzero(kf.mp < 0)
            fb = np.flatnonzero(other.mp < 0)
            if len(fa) == 0 or len(fb) == 0:
                continue
            m = match_descriptors(f.desc[fa], other.feats.desc[fb], max_dist=50, ratio=0.7)
            if len(m) == 0:
                continue
            ia, ib = fa[m[:, 0]], fb[m[:, 1]]
            T_a, T_b = kf.T_cw, other.T_cw
            F = _fundamental(T_a, T_b, self.K)
            xa = np.c_[f.und[ia], np.ones(len(ia))]
            xb = np.c_[other.feats.und[ib], np.ones(len(ib))]
            l = xa @ F.T  # epipolar lines in b
            dist2 = (np.sum(l * xb, axis=1) ** 2) / np.maximum(l[:, 0] ** 2 + l[:, 1] ** 2, 1e-12)
            ok = dist2 < 3.84 * other.feats.sigma2()[ib]
            ia, ib = ia[ok], ib[ok]
            if len(ia) == 0:
                continue
            X = cv2.triangulatePoints(self.K @ T_a[:3], self.K @ T_b[:3], f.und[ia].T, other.feats.und[ib].T)
            X = (X[:3] / X[3]).T
            ua, za = project(T_a, X, self.K)
            ub, zb = project(T_b, X, self.K)
            ea = np.sum((ua - f.und[ia]) ** 2, axis=1) / f.sigma2()[ia]
            eb = np.sum((ub - other.feats.und[ib]) ** 2, axis=1) / other.feats.sigma2()[ib]
            ra = X - kf.center
            rb = X - other.center
            cospar = np.sum(ra * rb, axis=1) / np.maximum(np.linalg.norm(ra, axis=1) * np.linalg.norm(rb, axis=1), 1e-12)
            good = (za > 0) & (zb > 0) & (ea < CHI2_2D) & (eb < CHI2_2D) & (cospar < 0.9998) & np.all(np.isfinite(X), axis=1)
            for a, b, p in zip(ia[good], ib[good], X[good]):
                if kf.mp[a] >= 0 or other.mp[b] >= 0:
                    continue
                mp = self.map.new_point(p, f.desc[a], kf, int(a))
                self.map.link(mp, other, int(b))
                created.append(mp.id)
        return created

    def _median_depth(self, kf: KeyFrame) -> float:
        ids = kf.mp[kf.mp >= 0]
        if len(ids) == 0:
            return 0.0
        P = np.array([self.map.points[int(i)].pos for i in ids if int(i) in self.map.points])
        if len(P) == 0:
            return 0.0
        _, z = project(kf.T_cw, P, self.K)
        return float(np.median(z))

    def _bundle_adjust(self, kfs_opt, kfs_fixed, sync: bool = False) -> None:
        """Local BA over ``kfs_opt`` and the points they see (the best observed ones, at most
        ``max_ba_points``); keyframes outside that also see the points are held fixed (or, without any,
        the oldest optimized one). Synchronous, or handed to the mapping process."""
        kfs_opt = [k for k in kfs_opt if k.id in self.map.keyframes]
        opt_ids = {k.id for k in kfs_opt}
        pts = {}
        for kf in kfs_opt:
            for pid in kf.mp[kf.mp >= 0]:
                p = self.map.points.get(int(pid))
                if p is not None and not p.deformable:
                    pts[p.id] = p
        if len(pts) > self.max_ba_points:
            best = sorted(pts.values(), key=lambda p: len(p.obs), reverse=True)[: self.max_ba_points]
            pts = {p.id: p for p in best}
        if kfs_fixed is None:
            fixed = {}
            for p in pts.values():
                for kid in p.obs:
                    if kid not in opt_ids and kid in self.map.keyframes:
                        fixed[kid] = fixed.get(kid, 0) + 1
            kfs_fixed = [self.map.keyframes[k] for k in sorted(fixed, key=fixed.get, reverse=True)[:10]]
            # gauge: 6 dof need one fixed keyframe; a monocular map's scale needs a second one
            need = 2 if self.mode == "mono" else 1
            for oldest in sorted(kfs_opt, key=lambda k: k.id):
                if len(kfs_fixed) >= need or len(kfs_opt) <= 1:
                    break
                kfs_fixed.append(oldest)
                kfs_opt = [k for k in kfs_opt if k.id != oldest.id]
        if not kfs_opt or not pts:
            return
        req = ba_request(kfs_opt, kfs_fixed, list(pts.values()))
        if self._ba is not None and not sync:
            if self._ba.submit(req):
                self.ba_stats["submitted"] += 1
            else:  # the mapping process is busy: optimize around the newest keyframe when it is free
                self.ba_stats["deferred"] += 1
                self._pending_ba = max(kfs_opt, key=lambda k: k.id)
            return
        self._apply_ba(bundle_adjust(req, self.K, self.baseline, self.ba_iterations))

    def _apply_ba(self, res: dict) -> None:
        if not res.get("ok"):
            return
        self.ba_stats["applied"] += 1
        for kid, T, fx in zip(res["kf_ids"], res["poses"], res["fixed"]):
            kf = self.map.keyframes.get(int(kid))
            if kf is not None and not fx:
                kf.T_wc = T
        for pid, P in zip(res["pt_ids"], res["pos"]):
            if int(pid) in self.map.points:
                self.map._pos[int(pid)] = P
        for pid, kid in res["outliers"]:
            p = self.map.points.get(pid)
            kf = self.map.keyframes.get(kid)
            if p is None or kf is None:
                continue
            idx = p.obs.pop(kid, None)
            if idx is not None and kf.mp[idx] == pid:
                kf.mp[idx] = -1
            if len(p.obs) < (1 if self.mode != "mono" else 2):
                self.map.erase_point(pid)

    def _cull_points(self, kf: KeyFrame) -> None:
        keep = []
        for pid, kid in self._recent_points:
            p = self.map.points.get(pid)
            if p is None:
                continue
            age = kf.id - kid
            if p.found_ratio < 0.25 and p.n_visible > 4:
                self.map.erase_point(pid)
            elif age >= 2 and len(p.obs) <= (2 if self.mode == "mono" else 1):
                self.map.erase_point(pid)
            elif age < 3:
                keep.append((pid, kid))
        self._recent_points = keep

    def _cull_keyframes(self, kfs) -> None:
        first = min(self.map.keyframes) if self.map.keyframes else -1
        for kf in kfs:
            if kf.id == first or kf.id not in self.map.keyframes or kf is self.ref_kf:
                continue
            ids = kf.mp[kf.mp >= 0]
            if len(ids) == 0:
                continue
            redundant = sum(1 for pid in ids if int(pid) in self.map.points and len(self.map.points[int(pid)].obs) > 3)
            if redundant > 0.9 * len(ids):
                self.map.erase_keyframe(kf.id)

    def _backproject(self, und: np.ndarray, z: np.ndarray) -> np.ndarray:
        return self.cam.backproject(und, z)


def sol_kind(reason: str) -> str:
    return reason.split(" model")[0] if " model" in reason else reason


def _score_h(H, x0, x1, th=5.991) -> float:
    Hi = np.linalg.inv(H)
    a = np.c_[x0, np.ones(len(x0))] @ H.T
    b = np.c_[x1, np.ones(len(x1))] @ Hi.T
    e1 = np.sum((a[:, :2] / a[:, 2:] - x1) ** 2, axis=1)
    e2 = np.sum((b[:, :2] / b[:, 2:] - x0) ** 2, axis=1)
    return float(np.sum(np.where(e1 < th, th - e1, 0) + np.where(e2 < th, th - e2, 0)))


def _score_f(F, x0, x1, th=3.841, th_score=5.991) -> float:
    a = np.c_[x0, np.ones(len(x0))]
    b = np.c_[x1, np.ones(len(x1))]
    l2 = a @ F.T
    l1 = b @ F
    d2 = np.sum(l2 * b, axis=1) ** 2 / np.maximum(l2[:, 0] ** 2 + l2[:, 1] ** 2, 1e-12)
    d1 = np.sum(l1 * a, axis=1) ** 2 / np.maximum(l1[:, 0] ** 2 + l1[:, 1] ** 2, 1e-12)
    return float(np.sum(np.where(d2 < th, th_score - d2, 0) + np.where(d1 < th, th_score - d1, 0)))


def _fundamental(T_a, T_b, K) -> np.ndarray:
    """F with x_b^T F x_a = 0 for ideal pixels, from world->camera poses."""
    T_ba = T_b @ G.inv(T_a)
    R, t = T_ba[:3, :3], T_ba[:3, 3]
    Ki = np.linalg.inv(K)
    return Ki.T @ G.hat(t) @ R @ Ki
