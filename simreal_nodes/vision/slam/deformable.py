"""Tracks of the map points on a deforming object (thesis §4.4): the deformable tracker's measurements.

Map points flagged deformable never vote for the camera pose (:attr:`SlamContext.deformable`). They are followed
from frame to frame with pyramidal Lucas-Kanade flow, started from where the deformable tracker predicts them
(their rest position moved by the current PGD estimate, §4.4.2), and re-acquired by ORB descriptor near the
prediction when the flow loses them (within a wider radius once most tracks are lost at once, as after a long gap
between the frames a live run processes).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from simreal_nodes.vision.orb import Features, hamming
from simreal_nodes.vision.slam.context import SlamContext
from simreal_nodes.vision.slam.optimize import project
from simreal_nodes.vision.slam.result import TrackResult

_LK_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)


class DeformableTracks:
    def __init__(self, ctx: SlamContext) -> None:
        self.ctx = ctx
        self.gray: np.ndarray | None = None  # the current frame's image
        self._last_seen: dict[int, np.ndarray] = {}  # deformable point id -> last observed ideal pixel
        self._predicted: dict[int, np.ndarray] = {}  # deformable point id -> predicted deformed position (map frame)
        self._last_desc: dict[int, np.ndarray] = {}  # deformable point id -> descriptor of its last match
        self._last_desc_kept = 0  # its size after its last prune
        self._flow: dict[int, np.ndarray] = {}  # deformable point id -> raw pixel in the frame ``_flow_frame``
        self._flow_frame = -1
        self._flow_gray: np.ndarray | None = None  # the image of the frame ``_flow_frame``
        self._anchor: dict[int, tuple[int, np.ndarray]] = {}  # point id -> (frame id, raw pixel) its track started at
        self._anchor_gray: dict[int, np.ndarray] = {}  # frame id -> image, for the anchors
        self._frame_obs: dict[int, np.ndarray] = {}  # point id -> raw pixel, every observation of the last frame
        self._peak = 0  # most object points followed in one frame so far
        # how this frame measured each deformable point it measured: "flow" (followed from the previous frame) or
        # "descriptor" (re-acquired by ORB); a diagnostic (benchmarks/boot_measurements.py)
        self.sources: dict[int, str] = {}

    def new_frame(self, gray: np.ndarray) -> None:
        self.gray = gray

    def set_deformable(self, ids: Iterable[int], predicted: ArrayLike | None = None) -> None:
        """Flag map points as lying on a deforming object. ``predicted``: (N, 3) map-frame positions of those
        points under the current deformation estimate (non-finite rows: no prediction), the centre of their
        image search in the next frames."""
        ctx = self.ctx
        ids = [int(i) for i in ids]
        new = [i for i in ids if i not in ctx.deformable]
        ctx.deformable = set(ids)
        # a newly flagged point observed in this frame starts its track here, at the pixel the deformable tracker
        # linked it with (so the measured pixel and the linked material point are the same from the start)
        if self._flow_frame == ctx.frame_id and self.gray is not None:
            for i in new:
                q = self._frame_obs.get(i)
                if q is not None and i not in self._flow:
                    self._flow[i] = q.copy()
                    if ctx.config.flow_anchor_px > 0:
                        self._start_anchor(i, q)
        for i in ctx.deformable:
            if i in ctx.map.points:
                ctx.map.points[i].deformable = True
        if predicted is None:
            return
        P = np.asarray(predicted, dtype=np.float64).reshape(-1, 3)
        if len(P) != len(ids):
            raise ValueError(f"{len(ids)} deformable point ids but {len(P)} predicted positions")
        good = np.all(np.isfinite(P), axis=1)
        self._predicted = {i: P[k].copy() for k, i in enumerate(ids) if good[k]}

    def followed(self) -> np.ndarray:
        """(N, 2) raw pixels where this frame measured deformable points (empty before :meth:`observe`)."""
        if self._flow_frame != self.ctx.frame_id or not self._flow:
            return np.zeros((0, 2))
        return np.array(list(self._flow.values()), np.float64)

    def drop_tracks(self, ids: Iterable[int]) -> None:
        """Forget the frame-to-frame tracks of these deformable points (the deformable tracker found them far
        from the model's fit: a flow track that slid); they are re-acquired by descriptor."""
        for i in ids:
            self._flow.pop(int(i), None)
            self._last_seen.pop(int(i), None)

    def observe(self, f: Features, T_cw: np.ndarray, res: TrackResult, exclude: np.ndarray) -> None:
        """:meth:`_measure`, then this frame's observations are kept: a point flagged deformable after it starts
        its track at the pixel it was seen at here (:meth:`set_deformable`). ``exclude``: the features the
        pose's matches took."""
        self._measure(f, T_cw, res, exclude)
        self._frame_obs = {int(i): q for i, q in zip(res.obs_ids, res.obs_uv)}
        if self._flow_frame != self.ctx.frame_id:  # no deformable points yet: this frame is where new tracks start
            self._flow, self._flow_frame, self._flow_gray = {}, self.ctx.frame_id, self.gray

    def _measure(self, f: Features, T_cw: np.ndarray, res: TrackResult, exclude: np.ndarray) -> None:
        """Measurements of the map points flagged deformable (never used for the pose), appended to the
        observations as pose outliers, with their rest positions (the tracker links those to the model).

        1. Flow: a point measured in the previous frame is followed with pyramidal Lucas-Kanade, started at
           its predicted pixel, and kept if the backward flow returns within ``flow_fb_px``. A deforming,
           obliquely seen surface soon looks unlike the keyframe that created the point, so descriptors alone
           lose it; the flow follows the appearance from frame to frame, to sub-pixel.
        2. Re-acquisition: any other point is searched among the ORB features within ``deformable_radius``
           pixels of its predicted projection and of its last observation, and matched to the closest
           descriptor (the map's, or that of its last ORB match) within 50 bits.
        With ``coherence_px`` > 0, the measurements that move unlike their image neighbours are then dropped
        (:meth:`_coherent`).
        The tracker's robust loss catches a flow track that slides onto a neighbour."""
        ctx, cfg, m = self.ctx, self.ctx.config, self.ctx.map
        self.sources = {}
        if not ctx.deformable:
            return
        ids = [i for i in ctx.deformable if i in m.points]
        if not ids:
            return
        ids_a, P, D = m.point_arrays(ids)
        P = P.copy()
        has_pred = np.array([int(i) in self._predicted for i in ids_a])
        if has_pred.any():
            P[has_pred] = np.array([self._predicted[int(i)] for i in ids_a[has_pred]])
        uv, zc = project(T_cw, P, ctx.K)  # ideal pixels of the predictions (rest positions without one)
        raw_pred = ctx.cam.project(P @ T_cw[:3, :3].T + T_cw[:3, 3])
        found: dict[int, np.ndarray] = {}  # point id -> raw pixel
        new_desc: dict[int, np.ndarray] = {}
        # 1. flow from the previous frame
        flow_ready = self._flow_frame == ctx.frame_id - 1 and self._flow_gray is not None and self.gray is not None
        if self._flow and flow_ready:
            sel = np.array([k for k, pid in enumerate(ids_a) if int(pid) in self._flow and zc[k] > 0], np.int64)
            if len(sel):
                assert self._flow_gray is not None and self.gray is not None  # flow_ready
                p0 = np.array([self._flow[int(ids_a[k])] for k in sel], np.float32).reshape(-1, 1, 2)
                guess = np.where(np.isfinite(raw_pred[sel]), raw_pred[sel], p0.reshape(-1, 2)).astype(np.float32)
                lk: dict[str, Any] = dict(winSize=(cfg.flow_win, cfg.flow_win), maxLevel=3, criteria=_LK_CRITERIA)
                p1, st, _ = cv2.calcOpticalFlowPyrLK(self._flow_gray, self.gray, p0, guess.reshape(-1, 1, 2).copy(),
                                                     flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
                pb, st2, _ = cv2.calcOpticalFlowPyrLK(self.gray, self._flow_gray, p1, p0.copy(),
                                                      flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
                p1, pb = p1.reshape(-1, 2), pb.reshape(-1, 2)
                H, W = self.gray.shape[:2]
                ok = ((st.ravel() == 1) & (st2.ravel() == 1)
                      & (np.linalg.norm(pb - p0.reshape(-1, 2), axis=1) < cfg.flow_fb_px))
                ok &= (p1[:, 0] >= 0) & (p1[:, 0] < W) & (p1[:, 1] >= 0) & (p1[:, 1] < H)
                for k, good, q in zip(sel, ok, p1):
                    if good:
                        found[int(ids_a[k])] = q.astype(np.float64)
        self.sources = dict.fromkeys(found, "flow")
        # 2. ORB re-acquisition of the others
        lost_tracks = len(found) < cfg.reacquire_below <= self._peak
        radius = max(cfg.deformable_radius, cfg.reacquire_wide_px) if lost_tracks else cfg.deformable_radius
        avail = np.ones(len(f), bool)
        avail[np.asarray(exclude, np.int64)] = False
        kp_idx = np.flatnonzero(avail)
        if len(kp_idx):
            todo = [k for k, pid in enumerate(ids_a) if int(pid) not in found and zc[k] > 0]
            for pid, j in self._reacquire(f, kp_idx, ids_a, D, uv, has_pred, todo, radius).items():
                found[pid] = f.uv[j].astype(np.float64)
                new_desc[pid] = f.desc[j].copy()
                self.sources[pid] = "descriptor"
        if cfg.coherence_px > 0 and len(found) > cfg.coherence_min:
            self._coherent(found, {int(pid): raw_pred[k] for k, pid in enumerate(ids_a)})
        # 3. every measurement of a point whose track started in an earlier image is taken against that image;
        # a point without one (or whose surface no longer looks like it) starts its track here
        if found and cfg.flow_anchor_px > 0:
            lk = dict(winSize=(cfg.flow_win, cfg.flow_win), maxLevel=1, criteria=_LK_CRITERIA)
            moved = self._refine_on_anchors(found, lk)
            for pid in found:
                if pid not in moved and (pid not in self._anchor or pid in new_desc):
                    self._start_anchor(pid, found[pid])
        self._prune_anchors()
        # the measurements and the state for the next frame
        self._peak = max(self._peak, len(found))
        self._flow, self._flow_frame, self._flow_gray = found, ctx.frame_id, self.gray
        self._last_desc.update({p: v for p, v in new_desc.items() if p in found})
        if len(self._last_desc) > 2 * self._last_desc_kept + 256:
            # bounded memory: the descriptors of points the map erased go (ids are never reused, so such an entry is
            # never read again); pruned when the dict has doubled since the last prune, so the work per entry is
            # bounded too. (Until stop 92 pruned only past twice the map's points: on the soak's boot frames,
            # `benchmarks/soak_map`, 443 -> 2 796 entries over 8 passes, mostly of erased points, where now 290-705.)
            self._last_desc = {p: v for p, v in self._last_desc.items() if p in m.points}
            self._last_desc_kept = len(self._last_desc)
        for pid in list(self._last_seen):
            if pid not in found:
                self._last_seen.pop(pid)
        if not found:
            return
        new_ids = np.fromiter(found, np.int64)
        raw = np.array([found[int(i)] for i in new_ids])
        und = ctx.cam.undistort_points(raw)
        for pid, q in zip(new_ids, und):
            self._last_seen[int(pid)] = q
        res.obs_ids = np.concatenate([res.obs_ids, new_ids])
        res.obs_uv = np.concatenate([res.obs_uv, raw])
        res.obs_inlier = np.concatenate([res.obs_inlier, np.zeros(len(new_ids), bool)])
        res.obs_pos = np.concatenate([res.obs_pos, m._pos[m.rows(new_ids)]])

    def _reacquire(self, f: Features, kp_idx: np.ndarray, ids_a: np.ndarray, D: np.ndarray, uv: np.ndarray,
                   has_pred: np.ndarray, todo: list[int], radius: float) -> dict[int, int]:
        """Step 2 of :meth:`_measure` for the points ``todo`` (rows of ``ids_a``, ``D``, ``uv``): point id -> the
        feature (index into ``f``) it is re-acquired at. A point's candidates are the features of ``kp_idx`` within
        ``radius`` (image pixels: a fisheye's searched in its own pixels) of its search centres (its predicted
        pixel, where it has a prediction or no last observation, and its last observation); its match is the candidate
        at the least Hamming distance to the map's descriptor or to that of its last ORB match, if within 50 bits (a
        tie: the first in the order the set of candidates iterates). The centres are searched in one query and the
        distances counted in one batch (stop 96: the same matches, in the same order, as a search per point)."""
        owner, centres = [], []  # each search centre and the row of ``todo`` it belongs to
        for t, k in enumerate(todo):
            pid = int(ids_a[k])
            if has_pred[k] or pid not in self._last_seen:
                owner.append(t)
                centres.append(uv[k])
            if pid in self._last_seen:
                owner.append(t)
                centres.append(self._last_seen[pid])
        if not centres:
            return {}
        Q = np.asarray(centres, np.float64).reshape(-1, 2)
        finite = np.all(np.isfinite(Q), axis=1)
        hits = np.empty(len(Q), object)
        if f.stretch is None:
            hits[finite] = cKDTree(f.und[kp_idx]).query_ball_point(Q[finite], radius, return_sorted=False)
        else:
            # a fisheye's radius is in its own pixels (its ideal image is stretched towards the edge, more radially
            # than across): the centres taken through the lens, the features searched where they were measured
            cam = self.ctx.cam
            at = cam.project(cam.backproject(Q, np.ones(len(Q))))
            finite &= np.all(np.isfinite(at), axis=1)
            hits[finite] = cKDTree(np.asarray(f.uv[kp_idx], np.float64)).query_ball_point(at[finite], radius,
                                                                                          return_sorted=False)
        near: list[set[int]] = [set() for _ in todo]
        for t, ok, h in zip(owner, finite, hits):
            if ok:
                near[t].update(h)
        rows = [t for t in range(len(todo)) if near[t]]
        if not rows:
            return {}
        sizes = np.array([len(near[t]) for t in rows])
        starts = np.r_[0, np.cumsum(sizes)[:-1]]
        cand = kp_idx[np.fromiter((i for t in rows for i in near[t]), np.int64, int(sizes.sum()))]
        k_of = np.repeat(np.asarray(todo, np.int64)[rows], sizes)
        d = hamming(D[k_of], f.desc[cand])
        last = [self._last_desc.get(int(ids_a[todo[t]])) for t in rows]
        with_last = np.array([x is not None for x in last])
        if with_last.any():
            L = np.stack([x for x in last if x is not None])
            sel = np.repeat(with_last, sizes)
            slot = np.repeat(np.cumsum(with_last) - 1, sizes)[sel]
            d[sel] = np.minimum(d[sel], hamming(L[slot], f.desc[cand[sel]]))
        best = np.minimum.reduceat(d, starts)
        seg = np.repeat(np.arange(len(rows)), sizes)
        at_best = np.flatnonzero(d == best[seg])
        _, first = np.unique(seg[at_best], return_index=True)  # each point's first candidate at its least distance
        j = cand[at_best[first]]
        return {int(ids_a[todo[t]]): int(j[n]) for n, t in enumerate(rows) if best[n] <= 50}

    def _coherent(self, found: dict[int, np.ndarray], pred: dict[int, np.ndarray]) -> None:
        """Drop from ``found`` the measurements that move unlike their image neighbours: each measurement's offset
        from its predicted pixel against the median offset of the others within ``coherence_radius_px``. A lagging
        prediction (a fast move) offsets a region's measurements alike; a match on another feature offsets its own.
        A point with fewer than ``coherence_min`` neighbours is kept."""
        cfg = self.ctx.config
        pids = [p for p in found if p in pred and np.all(np.isfinite(pred[p]))]
        if len(pids) <= cfg.coherence_min:
            return
        q = np.array([found[p] for p in pids])
        off = q - np.array([pred[p] for p in pids])
        tree = cKDTree(q)
        for k, nb in enumerate(tree.query_ball_point(q, cfg.coherence_radius_px)):
            nb = [j for j in nb if j != k]
            if len(nb) < cfg.coherence_min:
                continue
            if np.linalg.norm(off[k] - np.median(off[nb], axis=0)) > cfg.coherence_px:
                found.pop(pids[k])
                self.sources.pop(pids[k], None)

    def _start_anchor(self, pid: int, raw: np.ndarray) -> None:
        assert self.gray is not None  # anchors start in a frame given to new_frame
        self._anchor[pid] = (self.ctx.frame_id, np.asarray(raw, np.float64).copy())
        self._anchor_gray.setdefault(self.ctx.frame_id, self.gray)

    def _refine_on_anchors(self, found: dict[int, np.ndarray], lk: dict[str, Any]) -> set[int]:
        """Re-measure tracked points against the image their track started in (not the previous frame): frame-to-
        frame flow drifts like a random walk (0.4 px after 5 frames, 1 px after 30 on the foam beam at 1280 x 720),
        one Lucas-Kanade step from the first image does not. Kept where it lands within ``flow_anchor_px`` of the
        frame-to-frame result, which guards against a surface that has changed its look. Returns the ids moved.

        Off by default: on the foam beam it cuts the measurement error from 0.8 to 0.3 px but does not move the
        load estimate (the camera pose dominates), and on the joint boot's turning lever (translation-only
        Lucas-Kanade on a rotated patch) it biases alpha_z to 1.3 deg (0.4 deg without)."""
        groups: dict[int, list[int]] = {}
        for pid in found:
            a = self._anchor.get(pid)
            if a is not None and a[0] != self.ctx.frame_id and a[0] in self._anchor_gray:
                groups.setdefault(a[0], []).append(pid)
        moved = set()
        assert self.gray is not None  # called from _measure, after new_frame
        H, W = self.gray.shape[:2]
        for fid, pids in groups.items():
            p0 = np.array([self._anchor[p][1] for p in pids], np.float32).reshape(-1, 1, 2)
            q0 = np.array([found[p] for p in pids], np.float32).reshape(-1, 1, 2)
            q1, st, _ = cv2.calcOpticalFlowPyrLK(self._anchor_gray[fid], self.gray, p0, q0.copy(),
                                                 flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
            q1 = q1.reshape(-1, 2)
            ok = (st.ravel() == 1) & (np.linalg.norm(q1 - q0.reshape(-1, 2), axis=1) < self.ctx.config.flow_anchor_px)
            ok &= (q1[:, 0] >= 0) & (q1[:, 0] < W) & (q1[:, 1] >= 0) & (q1[:, 1] < H)
            for p, good, q in zip(pids, ok, q1):
                if good:
                    found[p] = q.astype(np.float64)
                    moved.add(p)
        return moved

    def _prune_anchors(self) -> None:
        ctx = self.ctx
        for pid in [p for p in self._anchor if p not in ctx.deformable or p not in ctx.map.points]:
            self._anchor.pop(pid)
        used = {a[0] for a in self._anchor.values()}
        for fid in [f for f in self._anchor_gray if f not in used]:
            self._anchor_gray.pop(fid)
        while len(self._anchor_gray) > ctx.config.max_anchor_images:  # bounded memory: the oldest anchors restart
            old = min(self._anchor_gray)
            self._anchor_gray.pop(old)
            for pid in [p for p, a in self._anchor.items() if a[0] == old]:
                self._anchor.pop(pid)
