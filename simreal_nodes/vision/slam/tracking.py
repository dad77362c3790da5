"""Frame tracking (ORB-SLAM2's Tracking): a constant-velocity motion model predicts the pose, map points are
matched by projection, the pose is optimized with outlier rejection (descriptor matching + PnP RANSAC when the
prediction is off), then the local map (points of the keyframes covisible with the tracked ones) is searched for
more matches and the pose refined on all of them. Points flagged deformable never vote for the pose."""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.vision.orb import Features, hamming, match_descriptors
from simreal_nodes.vision.slam.config import LOST, OK
from simreal_nodes.vision.slam.context import SlamContext
from simreal_nodes.vision.slam.optimize import project, refine_pose
from simreal_nodes.vision.slam.result import TrackResult, frame_result

LOCAL_CACHE_SETS = 4  # local-map point sets the tracker keeps for one state of the map (Tracker.local_points)


@dataclass
class PoseFix:
    """A frame's pose and the matches it rests on: (feature index, point id) rows, pose inliers where ``inl``."""

    T_cw: np.ndarray
    match: np.ndarray
    inl: np.ndarray


def no_matches() -> tuple[None, np.ndarray, np.ndarray]:
    return None, np.zeros((0, 2), np.int64), np.zeros(0, bool)


def pnp_ransac(P: np.ndarray, und: np.ndarray, K: np.ndarray) -> np.ndarray | None:
    """World -> camera pose from 2D-3D correspondences (EPnP in RANSAC, 4 px), None with fewer than 12 inliers."""
    ok, rvec, tvec, inl_idx = cv2.solvePnPRansac(P, und.astype(np.float64), K, None, iterationsCount=300,
                                                 reprojectionError=4.0, confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
    if not ok or inl_idx is None or len(inl_idx) < 12:
        return None
    return G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())


class Tracker:
    def __init__(self, ctx: SlamContext) -> None:
        self.ctx = ctx
        # (map version, its links' count, sorted keyframe ids) -> the sorted ids of the points those keyframes hold
        self._local_cache: dict[tuple[int, int, tuple[int, ...]], np.ndarray] = {}

    def track(self, f: Features, tim: dict[str, float]) -> tuple[TrackResult, PoseFix | None]:
        """Track a frame from the last one; the result and, when tracked, its pose and matches (``tim``: the
        step timings, in ms)."""
        ctx = self.ctx
        t0 = time.perf_counter()
        assert ctx.T_cw_last is not None  # tracking runs only after an initialization or relocalization set it
        T_pred = ctx.velocity @ ctx.T_cw_last if ctx.velocity is not None else ctx.T_cw_last
        local_ids = self.local_points()
        match = self.search_projection(f, T_pred, local_ids, radius=15.0)
        if len(match) < 30:
            match = self.search_projection(f, T_pred, local_ids, radius=40.0)
        tim["match_ms"] = (time.perf_counter() - t0) * 1e3
        t1 = time.perf_counter()
        T, inl = self.pose(f, match, T_pred)
        if inl.sum() < 20:
            # fast motion: the prediction is off; match descriptors to the local map and solve PnP
            T2, m2, inl2 = self._pnp_local_map(f, local_ids)
            if T2 is not None and inl2.sum() > inl.sum():
                T, match, inl = T2, m2, inl2
        tim["pose_ms"] = (time.perf_counter() - t1) * 1e3
        if inl.sum() < 15:
            ctx.lose()
            return TrackResult(LOST, f"lost: only {int(inl.sum())} pose inliers (fast motion, occlusion or leaving the "
                                     "map)", None, n_matches=len(match), timings=tim), None
        # track the local map
        t2 = time.perf_counter()
        local_ids = self.local_points(match[inl, 1])
        more = self.search_projection(f, T, local_ids, radius=8.0, exclude_kp=match[:, 0], exclude_pt=match[:, 1])
        if len(more):
            match = np.concatenate([match[inl], more])
            T, inl = self.pose(f, match, T)
        tim["local_map_ms"] = (time.perf_counter() - t2) * 1e3
        # ORB-SLAM2's acceptance: enough inliers after tracking the local map (more just after a relocalization)
        need = 50 if ctx.lost_since is not None and ctx.frame_id - ctx.lost_since < 30 else 30
        if inl.sum() < need:
            ctx.lose()
            return TrackResult(LOST, f"lost: only {int(inl.sum())} inliers after tracking the local map (need {need})",
                               None, n_matches=len(match), timings=tim), None
        ctx.map._nfound[ctx.map.rows(match[inl, 1])] += 1
        ctx.state = OK
        ctx.velocity = T @ G.inv(ctx.T_cw_last)
        ctx.T_cw_last = T
        res = frame_result(ctx.map, OK, "", G.inv(T), f, match[:, 0], match[:, 1], inl)
        res.n_matches, res.n_inliers = len(match), int(inl.sum())
        return res, PoseFix(T, match, inl)

    def pose(self, f: Features, match: np.ndarray, T_init: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Motion-only optimization of the pose on the matches, from ``T_init``; (T_cw, inlier mask)."""
        if len(match) == 0:
            return T_init, np.zeros(0, bool)
        P = self.ctx.map._pos[self.ctx.map.rows(match[:, 1])]
        i = match[:, 0]
        # a fisheye's pose fitted in its own pixels (its features' stretch known), each weighed by its level
        lens = None if f.stretch is None else (self.ctx.cam, f.uv[i], (f.sigma()[i] / f.stretch[i]) ** 2)
        return refine_pose(T_init, P, f.und[i], f.sigma2()[i], self.ctx.K, lens=lens)

    def _pnp_local_map(self, f: Features, ids: np.ndarray) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
        """Pose without a prediction: the frame's descriptors matched to the local map's points, PnP RANSAC."""
        ids, P, D = self.ctx.map.point_arrays(ids)
        if self.ctx.deformable and len(ids):
            keep = self.ctx.rigid(ids)
            ids, P, D = ids[keep], P[keep], D[keep]
        m = match_descriptors(f.desc, D, max_dist=50, ratio=0.8)
        if len(m) < 15:
            return no_matches()
        T0 = pnp_ransac(P[m[:, 1]], f.und[m[:, 0]], self.ctx.K)
        if T0 is None:
            return no_matches()
        match = np.c_[m[:, 0], ids[m[:, 1]]]
        T, inl = self.pose(f, match, T0)
        return T, match, inl

    def local_points(self, seed_ids: np.ndarray | None = None) -> np.ndarray:
        """Point ids of the local map: keyframes that see the tracked points (``seed_ids``) most, plus the
        reference keyframe and its covisible neighbours (at most ~2 x local_kfs keyframes), less the points no
        longer in the map and those on a deforming object. The points of a set of keyframes are kept until the map's
        keyframes or their links change (the same result as computed afresh: the set is chosen every call)."""
        ctx, m, n_local = self.ctx, self.ctx.map, self.ctx.config.local_kfs
        kfs = {}
        if seed_ids is not None and len(seed_ids):
            counts = m.observers(seed_ids)
            for kid in sorted(counts, key=counts.__getitem__, reverse=True)[:n_local]:
                kfs[kid] = m.keyframes[kid]
        if ctx.ref_kf is not None and ctx.ref_kf.id in m.keyframes:
            kfs[ctx.ref_kf.id] = ctx.ref_kf
            for k in m.covisible(ctx.ref_kf, n_local):
                kfs[k.id] = k
        if not kfs and m.keyframes:
            last = max(m.keyframes)
            kfs[last] = m.keyframes[last]
        if not kfs:
            return np.zeros(0, np.int64)
        key = (m.version, m.links, tuple(sorted(kfs)))
        ids = self._local_cache.get(key)
        if ids is None:
            ids = np.unique(np.concatenate([kf.mp[kf.mp >= 0] for kf in kfs.values()]))
            # a frame asks for two sets (before and after its pose): the newest few of this map's state are kept (a
            # frozen map's state never changes while the camera moves over new sets of keyframes)
            kept = [(k, v) for k, v in self._local_cache.items() if k[:2] == key[:2]][-(LOCAL_CACHE_SETS - 1):]
            self._local_cache = dict(kept)
            self._local_cache[key] = ids
        ids = ids[m.alive(ids)]
        if ctx.deformable:
            ids = ids[ctx.rigid(ids)]
        return ids

    def search_projection(self, f: Features, T_cw: np.ndarray, ids: np.ndarray, radius: float,
                          exclude_kp: np.ndarray | None = None, exclude_pt: np.ndarray | None = None,
                          max_dist: int = 64) -> np.ndarray:
        """Matches (kp index, point id): each map point projected with T_cw, matched to the best
        descriptor among unmatched features within ``radius`` x scale pixels."""
        m = self.ctx.map
        ids = np.asarray(ids, np.int64)
        if exclude_pt is not None and len(exclude_pt):
            ids = ids[~np.isin(ids, np.asarray(exclude_pt, np.int64))]
        if len(ids) == 0 or len(f) == 0:
            return np.zeros((0, 2), np.int64)
        rows = m.rows(ids)
        P, D = m._pos[rows], m._desc[rows]
        uv, zc = project(T_cw, P, self.ctx.K)
        vis = self.ctx.in_image(uv, zc, 10.0)
        m._nvis[rows[vis]] += 1
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
        rmax = radius * f.scale_factor ** 2 * (1.0 if f.stretch is None else float(f.stretch.max()))
        k = min(8, len(kp_idx))
        dpix, nn = tree.query(uv, k=k, distance_upper_bound=rmax)  # fixed shape: vectorized candidates
        dpix, nn = np.reshape(dpix, (len(uv), k)), nn.reshape(len(uv), k)  # np.reshape: stubs say float | ndarray
        valid = np.isfinite(dpix)
        rows = np.broadcast_to(np.arange(len(uv))[:, None], nn.shape)[valid]
        cols = kp_idx[nn[valid]]
        dpix = dpix[valid]
        if len(rows) == 0:
            return np.zeros((0, 2), np.int64)
        ok = dpix <= radius * f.sigma()[cols]
        rows, cols = rows[ok], cols[ok]
        dist = hamming(D[rows], f.desc[cols])
        good = dist <= max_dist
        rows, cols, dist = rows[good], cols[good], dist[good]
        if len(rows) == 0:
            return np.zeros((0, 2), np.int64)
        # each point keeps its closest descriptor, then each feature its closest point
        order = np.lexsort((dist, rows))
        rows, cols, dist = rows[order], cols[order], dist[order]
        first = np.r_[True, rows[1:] != rows[:-1]]
        rows, cols, dist = rows[first], cols[first], dist[first]
        order = np.lexsort((dist, cols))
        rows, cols = rows[order], cols[order]
        first = np.r_[True, cols[1:] != cols[:-1]]
        return np.c_[cols[first], ids[rows[first]]].astype(np.int64)
