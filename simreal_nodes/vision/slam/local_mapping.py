"""Local mapping (ORB-SLAM2's LocalMapping, run in the tracking thread): the keyframe decision, keyframe insertion,
new points (triangulated with covisible keyframes, or from depth), fusion of the keyframe's points with its
neighbours' (SearchInNeighbors; monocular maps by default), local bundle adjustment in GTSAM (synchronous, or in a
mapping process whose result is applied at a later frame) and map-point and keyframe culling."""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.vision.orb import Features, hamming, match_descriptors
from simreal_nodes.vision.slam.context import SlamContext
from simreal_nodes.vision.slam.map import KeyFrame
from simreal_nodes.vision.slam.optimize import (
    CHI2_2D,
    CHI2_3D,
    AsyncBundleAdjuster,
    ba_request,
    bundle_adjust,
    depth_e2,
    project,
)


class LocalMapper:
    def __init__(self, ctx: SlamContext, async_mapping: bool) -> None:
        self.ctx = ctx
        cfg = ctx.config
        self._ba = AsyncBundleAdjuster(ctx.K, ctx.baseline, cfg.ba_iterations) if async_mapping else None
        # ba_ms: the BAs' own time; stopped: local BAs ended early by a newer keyframe (``SlamConfig.interrupt_ba``)
        self.ba_stats = {"submitted": 0, "applied": 0, "deferred": 0, "stopped": 0, "ba_ms": 0.0}
        self._pending_ba: KeyFrame | None = None  # newest keyframe of a BA deferred while the worker was busy
        self._recent_points: list[tuple[int, int]] = []  # (point id, keyframe id at creation)
        self._epoch = 0  # bumped when the map is corrected (a loop): a BA submitted before is stale
        self._submitted_epoch = 0
        self._inflight: dict | None = None  # the request the mapping process is optimizing
        self._pending_global = False  # a global BA (after a loop) waits for the mapping process

    def close(self) -> None:
        if self._ba is not None:
            self._ba.close()
            self._ba = None

    def poll(self) -> None:
        """Apply a finished asynchronous BA; then run the one deferred while the mapping process was busy."""
        if self._ba is None:
            return
        res = self._ba.poll()
        if res is None:
            return
        if self._submitted_epoch == self._epoch:
            self._apply_ba(res, self._inflight)
        else:  # it optimized the map as it was before a loop correction
            self.ba_stats["stale"] = self.ba_stats.get("stale", 0) + 1
            self.ba_stats["ba_ms"] += float(res.get("ms", 0.0))
        self._inflight = None
        if self._pending_global:
            self._pending_global = False
            self.global_bundle_adjust()
        elif self._pending_ba is not None and self._pending_ba.id in self.ctx.map.keyframes:
            kf, self._pending_ba = self._pending_ba, None
            self.bundle_adjust([kf] + self.ctx.map.covisible(kf, self.ctx.config.local_kfs), None)

    def stale(self) -> None:
        """The map was corrected as a whole (a closed loop): a bundle adjustment still running in the mapping process
        optimized the old map, and its result is dropped."""
        self._epoch += 1

    def need_keyframe(self, n_inliers: int) -> bool:
        """ORB-SLAM2's rule, simplified: the current frame tracks clearly fewer points than the reference
        keyframe holds (seen by >= 2 keyframes), or too long since the last keyframe."""
        ctx = self.ctx
        if ctx.ref_kf is None:
            return True
        ids = ctx.ref_kf.mp[ctx.ref_kf.mp >= 0]
        ref_n = sum(1 for i in ids if int(i) in ctx.map.points and len(ctx.map.points[int(i)].obs) >= 2)
        if ctx.mode != "mono" and len(ctx.map.keyframes) < 3:
            ref_n = len(ids)
        since = ctx.frame_id - ctx.last_kf_frame
        if since < 5:
            return False  # (new points are triangulated here at once; only their refinement is asynchronous)
        ratio = 0.9 if ctx.mode == "mono" else 0.6
        # fewer tracked points than the reference keyframe holds, or tracking clearly degrading since it
        few = n_inliers < ratio * ref_n or n_inliers < 0.6 * ctx.kf_inliers
        if ctx.mode != "mono":
            few = few or n_inliers < 100
        return (few or since > 30) and n_inliers > 15

    def insert_keyframe(self, stamp: int, T_cw: np.ndarray, f: Features, z: np.ndarray | None, match: np.ndarray,
                        inl: np.ndarray, followed: np.ndarray | None = None) -> KeyFrame:
        """A keyframe from the tracked frame (linked to its inlier points), mapped at once; it becomes the
        reference keyframe. ``followed``: (N, 2) raw pixels where this frame measured points on a deforming
        object (:class:`~.deformable.DeformableTracks`); no new point is made from a feature within
        ``followed_px`` of one: it is that point, which the pose's matches leave out."""
        ctx = self.ctx
        kf = ctx.map.new_keyframe(stamp, G.inv(T_cw), f, z)
        for (kp, pid), ok in zip(match, inl):
            if ok and int(pid) in ctx.map.points:
                ctx.map.link(ctx.map.points[int(pid)], kf, int(kp))
        taken = np.zeros(len(f), bool)
        if followed is not None and len(followed) and len(f) and ctx.config.followed_px > 0:
            d, _ = cKDTree(np.asarray(followed, np.float64).reshape(-1, 2)).query(f.uv, k=1)
            taken = np.asarray(d) <= ctx.config.followed_px
        self._local_mapping(kf, taken)
        ctx.ref_kf = kf
        ctx.last_kf_frame = ctx.frame_id
        ctx.kf_inliers = int(inl.sum())
        return kf

    def _local_mapping(self, kf: KeyFrame, taken: np.ndarray | None = None) -> None:
        new = self._create_points(kf, taken)
        for pid in new:
            self._recent_points.append((pid, kf.id))
        if self.ctx.config.fuses(self.ctx.mode):
            self._fuse_neighbours(kf)
        neighbours = self.ctx.map.covisible(kf, self.ctx.config.local_kfs)
        self.bundle_adjust([kf] + neighbours, None)
        self._cull_points(kf)
        self._cull_keyframes(neighbours)

    def _create_points(self, kf: KeyFrame, taken: np.ndarray | None = None) -> list[int]:
        """New map points from the keyframe's features that no point holds (nor ``taken``): RGB-D and stereo
        from their depth (:func:`close_points`), monocular by triangulation with covisible keyframes."""
        ctx, m, K = self.ctx, self.ctx.map, self.ctx.K
        created = []
        f = kf.feats
        free = kf.mp < 0
        if taken is not None:
            free &= ~taken
        if ctx.mode != "mono" and kf.depth is not None:
            idx = close_points(kf.depth, free, kf.mp >= 0, ctx.config.keyframe_depth_points,
                               ctx.config.keyframe_close_depth_m)
            P = ctx.cam.backproject(f.und[idx], kf.depth[idx])
            T = kf.T_wc
            for i, p in zip(idx, P @ T[:3, :3].T + T[:3, 3]):
                created.append(m.new_point(p, f.desc[i], kf, int(i)).id)
            return created
        # monocular: triangulate unmatched features with the covisible keyframes
        for other in m.covisible(kf, 6):
            base = np.linalg.norm(kf.center - other.center)
            med = self._median_depth(other)
            if med <= 0 or base / med < 0.01:
                continue
            fa = np.flatnonzero(free & (kf.mp < 0))  # (kf.mp changes as this loop makes points)
            fb = np.flatnonzero(other.mp < 0)
            if len(fa) == 0 or len(fb) == 0:
                continue
            mt = match_descriptors(f.desc[fa], other.feats.desc[fb], max_dist=50, ratio=0.7)
            if len(mt) == 0:
                continue
            ia, ib = fa[mt[:, 0]], fb[mt[:, 1]]
            T_a, T_b = kf.T_cw, other.T_cw
            F = _fundamental(T_a, T_b, K)
            xa = np.c_[f.und[ia], np.ones(len(ia))]
            xb = np.c_[other.feats.und[ib], np.ones(len(ib))]
            lines = xa @ F.T  # epipolar lines in b
            dist2 = (np.sum(lines * xb, axis=1) ** 2) / np.maximum(lines[:, 0] ** 2 + lines[:, 1] ** 2, 1e-12)
            ok = dist2 < 3.84 * other.feats.sigma2()[ib]
            ia, ib = ia[ok], ib[ok]
            if len(ia) == 0:
                continue
            X = cv2.triangulatePoints(K @ T_a[:3], K @ T_b[:3], f.und[ia].T, other.feats.und[ib].T)
            X = (X[:3] / X[3]).T
            ua, za = project(T_a, X, K)
            ub, zb = project(T_b, X, K)
            ea = np.sum((ua - f.und[ia]) ** 2, axis=1) / f.sigma2()[ia]
            eb = np.sum((ub - other.feats.und[ib]) ** 2, axis=1) / other.feats.sigma2()[ib]
            ra = X - kf.center
            rb = X - other.center
            norms = np.linalg.norm(ra, axis=1) * np.linalg.norm(rb, axis=1)
            cospar = np.sum(ra * rb, axis=1) / np.maximum(norms, 1e-12)
            good = ((za > 0) & (zb > 0) & (ea < CHI2_2D) & (eb < CHI2_2D) & (cospar < 0.9998)
                    & np.all(np.isfinite(X), axis=1))
            for a, b, p in zip(ia[good], ib[good], X[good]):
                if kf.mp[a] >= 0 or other.mp[b] >= 0:
                    continue
                mp = m.new_point(p, f.desc[a], kf, int(a))
                m.link(mp, other, int(b))
                created.append(mp.id)
        return created

    def _fuse_neighbours(self, kf: KeyFrame) -> None:
        """ORB-SLAM2's SearchInNeighbors: the new keyframe's points are projected into its covisible keyframes (20
        for a monocular map, 10 otherwise, and 5 of each one's own) and theirs into it; a projection landing on a
        feature with a like descriptor either adds that observation to the point or, where the feature already
        has a point, fuses the two (the better observed one stays). The same physical point triangulated twice in
        different keyframe pairs becomes one, so the bundle adjustment ties the keyframes together (monocular
        scale drift) instead of leaving parallel copies. Touched points get a representative descriptor."""
        m = self.ctx.map
        n = 20 if self.ctx.mode == "mono" else 10
        targets = {k.id: k for k in m.covisible(kf, n)}
        for k in list(targets.values()):
            for k2 in m.covisible(k, 5):
                if k2.id != kf.id:
                    targets.setdefault(k2.id, k2)
        touched: set[int] = set()

        def own(k: KeyFrame) -> np.ndarray:
            ids = k.mp[k.mp >= 0]
            ids = ids[m.alive(ids)]
            if self.ctx.deformable:
                ids = ids[self.ctx.rigid(ids)]
            return ids

        for t in targets.values():
            touched |= self._fuse_into(t, own(kf))
        pool = np.unique(np.concatenate([own(t) for t in targets.values()])) if targets else np.zeros(0, np.int64)
        touched |= self._fuse_into(kf, pool)
        for pid in touched:
            p = m.points.get(pid)
            if p is not None:
                m.update_descriptor(p)

    def _fuse_into(self, kf: KeyFrame, ids: np.ndarray, radius: float = 3.0) -> set[int]:
        """Project the points ``ids`` into ``kf`` and fuse or link them (ORB-SLAM2's Fuse): a candidate feature lies
        within ``radius`` x its level's scale of the projection and passes the reprojection chi-square test (5.99,
        its level's variance; 7.81 with the virtual right coordinate where the feature has a depth), its level is
        within one of the level the point's distance predicts, and its descriptor is the closest within 50 bits.
        Returns the ids of points that gained observations."""
        m, K, f = self.ctx.map, self.ctx.K, kf.feats
        ids = ids[m.alive(ids)]
        if len(ids) == 0 or len(f) == 0:
            return set()
        ids = ids[~np.isin(ids, kf.mp)]  # not observed by kf already (kf.mp and the points' obs agree)
        if len(ids) == 0:
            return set()
        P = m._pos[m.rows(ids)]
        uv, z = project(kf.T_cw, P, K)
        vis = self.ctx.in_image(uv, z)
        ids, uv, z = ids[vis], uv[vis], z[vis]
        if len(ids) == 0:
            return set()
        pred = m.predicted_level(ids, kf.center, f.scale_factor)
        rmax = radius * f.max_sigma()
        k_nn = min(8, len(f))
        dpix, nn = kf.tree.query(uv, k=k_nn, distance_upper_bound=rmax)
        dpix, nn = np.reshape(dpix, (len(uv), k_nn)), nn.reshape(len(uv), k_nn)
        valid = np.isfinite(dpix)
        rows = np.broadcast_to(np.arange(len(uv))[:, None], nn.shape)[valid]
        cols = nn[valid]
        oct_ = f.octave[cols].astype(np.float64)
        e2 = np.sum((f.und[cols] - uv[rows]) ** 2, axis=1) / f.sigma2()[cols]
        chi2 = np.full(len(rows), CHI2_2D)
        if kf.depth is not None and self.ctx.baseline:
            # a feature with a depth (RGB-D, stereo) must agree in depth too: the virtual right coordinate
            # u_r = u - fx b / z (ORB-SLAM2's Fuse, 3 dof), so a point is not fused across a depth edge
            zf = kf.depth[cols]
            has = np.isfinite(zf) & (zf > 0)
            e2 = e2 + np.where(has, depth_e2(uv[rows, 0] - f.und[cols, 0], K[0, 0] * self.ctx.baseline, z[rows],
                                             np.where(has, zf, 1.0), np.sqrt(f.sigma2()[cols]),
                                             self._disparity_sigma()), 0.0)
            chi2[has] = CHI2_3D
        lvl = np.floor(pred[rows])
        ok = (dpix[valid] <= radius * f.sigma()[cols]) & (e2 < chi2) & (np.isnan(lvl) | (np.abs(oct_ - lvl) <= 1))
        rows, cols = rows[ok], cols[ok]
        if len(rows) == 0:
            return set()
        dist = hamming(m._desc[m.rows(ids[rows])], f.desc[cols])
        good = dist <= 50
        rows, cols, dist = rows[good], cols[good], dist[good]
        if len(rows) == 0:
            return set()
        order = np.lexsort((dist, rows))
        rows, cols = rows[order], cols[order]
        first = np.r_[True, rows[1:] != rows[:-1]]
        touched: set[int] = set()
        for r, c in zip(rows[first], cols[first]):
            pid = int(ids[r])
            p = m.points.get(pid)
            if p is None or kf.id in p.obs:
                continue
            other = int(kf.mp[c])
            if other >= 0 and other in m.points:
                q = m.points[other]
                if q.deformable or p.deformable:
                    continue
                keep, drop = (p, q) if len(p.obs) >= len(q.obs) else (q, p)
                m.fuse(keep, drop)
                touched.add(keep.id)
            else:  # a free feature (or one whose point is gone): a missed observation of p
                m.link(p, kf, int(c))
                touched.add(pid)
        return touched

    def _disparity_sigma(self) -> float:
        """The depth camera's disparity noise the BA and the fusion weigh a depth reading by (RGB-D only; 0: the
        isotropic model, which a stereo pair keeps)."""
        return self.ctx.config.rgbd_disparity_sigma_px if self.ctx.mode == "rgbd" else 0.0

    def _median_depth(self, kf: KeyFrame) -> float:
        _, P, _ = self.ctx.map.point_arrays(kf.mp[kf.mp >= 0])
        if len(P) == 0:
            return 0.0
        _, z = project(kf.T_cw, P, self.ctx.K)
        return float(np.median(z))

    def global_bundle_adjust(self, sync: bool = False) -> None:
        """Bundle adjustment of the whole map (after a loop closure, as ORB-SLAM2): every keyframe but the first
        (the first two for a monocular map: its scale) and every rigid point. In the mapping process when mapping
        is asynchronous; keyframes and points made meanwhile follow the correction of the keyframe they share most
        points with (:meth:`_apply_ba`)."""
        kfs = sorted(self.ctx.map.keyframes.values(), key=lambda k: k.id)
        nf = 2 if self.ctx.mode == "mono" else 1
        if len(kfs) > nf:
            self.bundle_adjust(kfs[nf:], kfs[:nf], sync=sync, max_points=10 ** 9, whole=True)

    def bundle_adjust(self, kfs_opt: list[KeyFrame], kfs_fixed: list[KeyFrame] | None, sync: bool = False,
                      max_points: int | None = None, whole: bool = False) -> None:
        """Local BA over ``kfs_opt`` and the points they see (all of them, or the best observed ``max_ba_points``);
        keyframes outside that also see the points are held fixed (or, without any,
        the oldest optimized one). Synchronous, or handed to the mapping process."""
        ctx, m, cfg = self.ctx, self.ctx.map, self.ctx.config
        kfs_opt = [k for k in kfs_opt if k.id in m.keyframes]
        if not kfs_opt:
            return
        opt_ids = {k.id for k in kfs_opt}
        # the points they see, in the order first seen (keyframe by keyframe), rigid ones only
        seen = np.concatenate([k.mp[k.mp >= 0] for k in kfs_opt])
        _, first = np.unique(seen, return_index=True)
        pts = seen[np.sort(first)]
        pts = pts[m.alive(pts)]
        pts = pts[~np.fromiter((m.points[int(i)].deformable for i in pts), bool, len(pts))]
        _, kid, _ = m.observations()
        max_points = cfg.max_ba_points if max_points is None else max_points
        if 0 < max_points < len(pts):  # the most observed (stable: first seen first among equals)
            n_obs = np.bincount(m.observation_rows(), minlength=m.n_rows)
            pts = pts[np.argsort(-n_obs[m.rows(pts)], kind="stable")[:max_points]]
        if kfs_fixed is None:
            # keyframes outside the window that see the points, most shared first (ties: the newest), at most 10
            inside = np.zeros(m.n_rows, bool)
            inside[m.rows(pts)] = True
            outer = kid[inside[m.observation_rows()] & ~np.isin(kid, list(opt_ids))]
            fixed = m.ranked(outer)
            kfs_fixed = [m.keyframes[k] for k in fixed if k in m.keyframes][:10]
            # gauge: 6 dof need one fixed keyframe; a monocular map's scale needs a second one
            need = 2 if ctx.mode == "mono" else 1
            for oldest in sorted(kfs_opt, key=lambda k: k.id):
                if len(kfs_fixed) >= need or len(kfs_opt) <= 1:
                    break
                kfs_fixed.append(oldest)
                kfs_opt = [k for k in kfs_opt if k.id != oldest.id]
        if not kfs_opt or not len(pts):
            return
        req = ba_request(m, kfs_opt, kfs_fixed, pts)
        req["whole"] = whole
        req["disparity_sigma"] = self._disparity_sigma()
        if self._ba is not None and not sync:
            if self._ba.submit(req):
                self.ba_stats["submitted"] += 1
                self._submitted_epoch = self._epoch
                self._inflight = req
            else:
                if whole:  # the mapping process is busy: the global BA goes first when it is free
                    self._pending_global = True
                else:  # the mapping process is busy: optimize around the newest keyframe when it is free
                    self.ba_stats["deferred"] += 1
                    self._pending_ba = max(kfs_opt, key=lambda k: k.id)
                if cfg.interrupt_ba:  # ORB-SLAM2: a new keyframe stops the running local BA
                    self._ba.interrupt()
            return
        self._apply_ba(bundle_adjust(req, ctx.K, ctx.baseline, cfg.ba_iterations), req)

    def _apply_ba(self, res: dict, req: dict | None = None) -> None:
        self.ba_stats["ba_ms"] += float(res.get("ms", 0.0))
        self.ba_stats["stopped"] += int(bool(res.get("stopped")))
        if not res.get("ok"):
            return
        m = self.ctx.map
        self.ba_stats["applied"] += 1
        moved: dict[int, np.ndarray] = {}  # a global BA: keyframe id -> its world correction (new pose x old^-1)
        if req is not None and req.get("whole"):
            for kid, T0, T1, fx in zip(req["kf_ids"], req["poses"], res["poses"], res["fixed"]):
                moved[int(kid)] = np.eye(4) if fx else T1 @ G.inv(T0)
            for new in sorted(m.keyframes.values(), key=lambda k: k.id):  # made while it ran: follow a neighbour
                if new.id not in moved:
                    ref = next((k.id for k in m.covisible(new, 10 ** 6) if k.id in moved), None)
                    moved[new.id] = moved[ref] if ref is not None else np.eye(4)
                    new.T_wc = moved[new.id] @ new.T_wc
        for kid, T, fx in zip(res["kf_ids"], res["poses"], res["fixed"]):
            kf = m.keyframes.get(int(kid))
            if kf is not None and not fx:
                kf.T_wc = T
        if moved:  # points made while it ran follow their reference keyframe
            done = set(np.asarray(res["pt_ids"]).tolist())
            for pid, q in m.points.items():
                if pid in done:
                    continue
                C = moved.get(m.reference_keyframe(q))
                if C is not None:
                    q.pos = C[:3, :3] @ q.pos + C[:3, 3]
            m.version += 1
        # a point flagged deformable while an asynchronous BA ran (the request held it rigid) is the tracker's now:
        # its position follows the tracker's estimate and its keyframe links are the object's rest observations.
        # The BA's word on it (moved as if rigid, or an outlier because it deformed) is dropped. Applied anyway, it
        # unlinked and erased the joint boot's lever points as the lever turned: live on 2 cores the tracker lost
        # every measurement on it for seconds (stop 87); the same run with synchronous BA tracked.
        for pid, P in zip(res["pt_ids"], res["pos"]):
            if (p := m.points.get(int(pid))) is not None and not p.deformable:
                p.pos = P
        for pid, kid in res["outliers"]:
            p = m.points.get(pid)
            kf = m.keyframes.get(kid)
            if p is None or kf is None or p.deformable:
                continue
            m.unlink(p, kf)
            if len(p.obs) < (1 if self.ctx.mode != "mono" else 2):
                m.erase_point(pid)

    def _cull_points(self, kf: KeyFrame) -> None:
        """Recent points found in too few of the frames that should see them, or (after two keyframes) seen
        by too few keyframes, are erased; after three keyframes a point is no longer recent.

        A point on a deforming object never joins the pose's matches nor a keyframe's fusion, so it gains
        neither keyframes nor finds: these rules erase it two keyframes later. That suits a point the tracker
        linked while the object was deformed (its link holds the estimate's error of that moment; a fresh point
        replaces it), not one linked at rest (``ctx.held``, thesis §4.4's scanned points): with
        ``config.hold_rest_points`` those are kept. On the joint boot, culling them too erased 556 points in 124
        frames of development seed 13."""
        m = self.ctx.map
        keep = []
        for pid, kid in self._recent_points:
            p = m.points.get(pid)
            if p is None or (pid in self.ctx.held and self.ctx.config.hold_rest_points):
                continue
            age = kf.id - kid
            if (p.found_ratio < 0.25 and p.n_visible > 4) or (
                    age >= 2 and len(p.obs) <= (2 if self.ctx.mode == "mono" else 1)):
                m.erase_point(pid)
            elif age < 3:
                keep.append((pid, kid))
        self._recent_points = keep

    def _cull_keyframes(self, kfs: list[KeyFrame]) -> None:
        """A keyframe whose points are (90 %) seen by more than three others is redundant."""
        m = self.ctx.map
        first = min(m.keyframes) if m.keyframes else -1
        for kf in kfs:
            if kf.id == first or kf.id not in m.keyframes or kf is self.ctx.ref_kf:
                continue
            ids = kf.mp[kf.mp >= 0]
            if len(ids) == 0:
                continue
            redundant = sum(1 for pid in ids if int(pid) in m.points and len(m.points[int(pid)].obs) > 3)
            if redundant > 0.9 * len(ids):
                m.erase_keyframe(kf.id)


#: ORB-SLAM2's least count of a keyframe's depth points (held and new) before its close-depth bound stops it
MIN_KEYFRAME_DEPTH_POINTS = 100


def close_points(depth: np.ndarray, free: np.ndarray, held: np.ndarray, cap: int, close_m: float) -> np.ndarray:
    """The features of an RGB-D / stereo keyframe that get new map points from their depth (``depth``: metres per
    feature, NaN unknown; ``free``: no point holds the feature and none may be made there; ``held``: a point holds
    it), nearest first. ``cap`` > 0 (the default's 250): the ``cap`` nearest free ones. ``cap`` 0: ORB-SLAM2's rule
    (``Tracking::CreateNewKeyFrame``): walking the features with depth nearest first, every free one gets a point,
    and the walk stops at the first feature beyond ``close_m`` once more than
    :data:`MIN_KEYFRAME_DEPTH_POINTS` features (held or new) have been counted."""
    with_depth = np.isfinite(depth)
    if cap > 0:
        idx = np.flatnonzero(free & with_depth)
        return idx[np.argsort(depth[idx])][:cap]  # (the sort the cap always had: the same points on ties)
    order = np.flatnonzero(with_depth & (free | held))
    order = order[np.argsort(depth[order], kind="stable")]
    counted = np.arange(1, len(order) + 1)  # features counted up to and including each
    stop = (depth[order] > close_m) & (counted > MIN_KEYFRAME_DEPTH_POINTS)
    end = int(np.argmax(stop)) + 1 if stop.any() else len(order)  # ORB-SLAM2 counts the feature it stops on
    walked = order[:end]
    return walked[free[walked]]


def _fundamental(T_a: np.ndarray, T_b: np.ndarray, K: np.ndarray) -> np.ndarray:
    """F with x_b^T F x_a = 0 for ideal pixels, from world->camera poses."""
    T_ba = T_b @ G.inv(T_a)
    R, t = T_ba[:3, :3], T_ba[:3, 3]
    Ki = np.linalg.inv(K)
    return Ki.T @ G.hat(t) @ R @ Ki
