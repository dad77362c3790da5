"""Relocalization (ORB-SLAM2's, without the bag of words): a lost frame's descriptors vote for the keyframes it
resembles; through each candidate keyframe's features it gets 2D-3D correspondences and a PnP RANSAC pose; the
best pose is then refined on the local map around it."""

from __future__ import annotations

import time

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.vision.orb import Features, match_descriptors
from simreal_nodes.vision.slam.config import LOST, NOT_STARTED, OK, RELOCALIZED
from simreal_nodes.vision.slam.context import SlamContext
from simreal_nodes.vision.slam.map import KeyFrame
from simreal_nodes.vision.slam.result import TrackResult, frame_result
from simreal_nodes.vision.slam.tracking import PoseFix, Tracker, no_matches, pnp_ransac


class Relocalizer:
    def __init__(self, ctx: SlamContext, tracker: Tracker) -> None:
        self.ctx = ctx
        self.tracker = tracker  # its local map, search by projection and pose optimization

    def relocalize(self, f: Features, tim: dict[str, float]) -> tuple[TrackResult, PoseFix | None]:
        """Place a frame in the map without a prediction; the result and, when placed, its pose and matches."""
        ctx = self.ctx
        t0 = time.perf_counter()
        if not ctx.map.points:
            ctx.state = NOT_STARTED
            return TrackResult(NOT_STARTED, "no map to relocalize in", timings=tim), None
        T, match, inl = None, np.zeros((0, 2), np.int64), np.zeros(0, bool)
        for kf in self.candidates(f):
            T_k, m_k, inl_k = self.pnp_keyframe(f, kf)
            if T_k is not None and inl_k.sum() > inl.sum():
                T, match, inl = T_k, m_k, inl_k
                if inl.sum() >= 50:
                    break
        tim["relocalization_ms"] = (time.perf_counter() - t0) * 1e3
        if T is None or inl.sum() < 25:
            n = 0 if T is None else int(inl.sum())
            return TrackResult(LOST, f"lost: relocalization found {n} inliers (need 25)", None, n_matches=len(match),
                               timings=tim), None
        local = self.tracker.local_points(match[inl, 1])
        more = self.tracker.search_projection(f, T, local, radius=10.0, exclude_kp=match[:, 0], exclude_pt=match[:, 1])
        if len(more):
            match = np.concatenate([match[inl], more])
            T, inl = self.tracker.pose(f, match, T)
        if inl.sum() < 30:
            return TrackResult(LOST, f"lost: relocalization kept {int(inl.sum())} inliers (need 30)", None,
                               timings=tim), None
        ctx.state = OK
        ctx.T_cw_last = T
        ctx.velocity = None
        ctx.ref_kf = self.most_shared(match[inl, 1]) or ctx.ref_kf  # the next frame's local map is around it
        lost_for = ctx.frame_id - (ctx.lost_since or ctx.frame_id)
        res = frame_result(ctx.map, RELOCALIZED, f"relocalized after {lost_for} frames", G.inv(T), f, match[:, 0],
                           match[:, 1], inl)
        res.n_matches, res.n_inliers = len(match), int(inl.sum())
        return res, PoseFix(T, match, inl)

    def most_shared(self, ids: np.ndarray) -> KeyFrame | None:
        """The keyframe that sees most of the points ``ids`` (ORB-SLAM2's reference keyframe after a relocalization:
        the last keyframe made may be far from where the camera is now)."""
        counts = self.ctx.map.observers(ids)
        best = max(counts, key=counts.__getitem__, default=None)
        return self.ctx.map.keyframes.get(best) if best is not None else None

    def candidates(self, f: Features, max_kfs: int = 12) -> list[KeyFrame]:
        """Keyframes to relocalize against (ORB-SLAM2 uses a bag of words; here a sample of the frame's
        descriptors votes for the keyframes with most close matches)."""
        kfs = list(self.ctx.map.keyframes.values())
        if len(kfs) <= max_kfs:
            return kfs
        sample = np.linspace(0, len(f) - 1, min(200, len(f))).astype(int)
        votes = []
        for kf in kfs:
            m = match_descriptors(f.desc[sample], kf.feats.desc, max_dist=40)
            votes.append(len(m))
        order = np.argsort(votes)[::-1][:max_kfs]
        return [kfs[i] for i in order]

    def pnp_keyframe(self, f: Features, kf: KeyFrame) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
        """2D-3D correspondences through one keyframe's features, then PnP RANSAC; (T_cw or None, matches,
        inlier mask)."""
        has = np.flatnonzero(kf.mp >= 0)
        if len(has) < 15:
            return no_matches()
        m = match_descriptors(f.desc, kf.feats.desc[has], max_dist=50, ratio=0.75)
        if len(m) < 15:
            return no_matches()
        ids = kf.mp[has[m[:, 1]]]
        alive = self.ctx.map.alive(ids) & self.ctx.rigid(ids)
        m, ids = m[alive], ids[alive]
        if len(m) < 15:
            return no_matches()
        T0 = pnp_ransac(self.ctx.map._pos[self.ctx.map.rows(ids)], f.und[m[:, 0]], self.ctx.K)
        if T0 is None:
            return no_matches()
        match = np.c_[m[:, 0], ids]
        T, inl = self.tracker.pose(f, match, T0)
        return T, match, inl
