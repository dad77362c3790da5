"""Loop closing (ORB-SLAM2's LoopClosing, Mur-Artal & Tardos 2017, sec. V-VI): a new keyframe that sees a place the
map already holds, from keyframes it is not connected to, closes a loop; the drift accumulated around the loop is
measured as one similarity (Sim3: rotation, translation and, for a monocular map, scale) and spread over the map by
an essential-graph optimization in GTSAM.

Per keyframe (:meth:`LoopCloser.process`, after its local mapping):

1. **Candidates** (ORB-SLAM2 scores with a bag of words; here the keyframe's mapped descriptors vote): every
   keyframe not connected to the new one (sharing no point with it) offers its strongest mapped descriptors; each of
   the new keyframe's mapped descriptors votes for the keyframe of its nearest one (within ``DESC_DIST`` bits). A
   keyframe's score is its votes plus those of its covisible neighbours (ORB-SLAM2's accumulated group score); the
   best few with at least ``MIN_VOTES`` of their own are verified.
2. **Sim3** (ORB-SLAM2's ComputeSim3): the new keyframe's map points matched by descriptor to the candidate's local
   map points (the candidate and its covisible keyframes) give 3D-3D pairs; RANSAC on three pairs (Umeyama's
   closed form, with scale for a monocular map) scored by the reprojection of the loop side's points in the new
   keyframe (chi-square 5.99 at their level), refit on the inliers; then every loop-side point is projected with
   the corrected pose and matched in the new keyframe (ORB-SLAM2's SearchByProjection): at least ``MIN_MATCHES``
   accept the loop.
3. **Correction** (CorrectLoop): the new keyframe and its connected keyframes, with their points, are moved by the
   similarity; the loop side's points are fused into them (:meth:`LocalMapper._fuse_into`: duplicates of one
   physical point merge, so the loop is closed in the map itself); then the essential graph (every keyframe a
   Sim3 node for a monocular map, a Pose3 node otherwise; edges: consecutive keyframes, covisibility of at least
   ``ESSENTIAL_MIN_SHARED`` points measured before the correction, and the loop's new connections measured after
   it; the loop keyframe held) is optimized with Levenberg-Marquardt, and every point follows its reference
   keyframe. The tracker's last pose and motion and any local BA still running are brought into the corrected map.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.vision.orb import hamming, match_descriptors
from simreal_nodes.vision.slam.map import KeyFrame
from simreal_nodes.vision.slam.optimize import CHI2_2D, FIXED_SIGMA, project
from simreal_nodes.vision.trajectory import umeyama

MIN_KEYFRAMES = 12  # no loop search in a smaller map (ORB-SLAM2: 10)
GAP_KEYFRAMES = 10  # keyframes after a closed loop before the next search (ORB-SLAM2: 10)
BANK = 120  # strongest mapped descriptors each candidate keyframe offers to the vote
QUERY = 400  # strongest mapped descriptors of the new keyframe that vote
DESC_DIST = 40  # bits: a vote's descriptor distance bound (a likely same point)
MIN_VOTES = 20  # a candidate's own votes
CANDIDATES = 3  # candidates verified per keyframe, best score first
MIN_RANSAC = 20  # Sim3 RANSAC inliers
MIN_MATCHES = 40  # projection matches that accept a loop (ORB-SLAM2: 40)
ESSENTIAL_MIN_SHARED = 100  # covisibility edges of the essential graph (ORB-SLAM2: 100)


@dataclass
class Loop:
    """A closed loop: the new keyframe, the keyframe it closed on, the similarity's scale (1 with metric depth),
    RANSAC inliers and projection matches, points fused, the largest keyframe correction (map units) and the time."""

    kf: int
    loop_kf: int
    scale: float
    inliers: int
    matches: int
    fused: int
    max_shift: float
    ms: float


def similarity(X: np.ndarray, Y: np.ndarray, with_scale: bool) -> tuple[float, np.ndarray, np.ndarray]:
    """(s, R, t) minimizing sum |Y - (s R X + t)|^2 (Umeyama, :func:`~simreal_nodes.vision.trajectory.umeyama`); s = 1
    without scale."""
    R, t, s = umeyama(X, Y, with_scale)
    return s, R, t


def sim_apply(S: tuple[float, np.ndarray, np.ndarray], X: np.ndarray) -> np.ndarray:
    s, R, t = S
    return s * X @ R.T + t


class LoopCloser:
    """Loop detection, Sim3 verification and correction for one SLAM (see the module's description). ``mapper``: the
    local mapper, whose fusion closes the loop in the map and whose in-flight bundle adjustment is made stale."""

    def __init__(self, ctx, mapper) -> None:
        self.ctx, self.mapper = ctx, mapper
        self.loops: list[Loop] = []
        self._last = -(10 ** 9)

    def process(self, kf: KeyFrame) -> Loop | None:
        """Search a loop for the new keyframe ``kf``; correct the map if one is found."""
        m = self.ctx.map
        if kf.id not in m.keyframes or len(m.keyframes) < MIN_KEYFRAMES or kf.id - self._last < GAP_KEYFRAMES:
            return None
        t0 = time.perf_counter()
        for cand in self.candidates(kf):
            fit = self.sim3(kf, cand)
            if fit is None:
                continue
            S, inliers, matches, loop_side = fit
            fused, shift = self.correct(kf, cand, S, loop_side)
            loop = Loop(kf.id, cand.id, S[0], inliers, matches, fused, shift, (time.perf_counter() - t0) * 1e3)
            self.loops.append(loop)
            self._last = kf.id
            return loop
        return None

    # -- 1. candidates ---------------------------------------------------------------------------------------
    def _mapped(self, kf: KeyFrame, n: int) -> np.ndarray:
        """Indices of ``kf``'s features that hold a live rigid map point, the ``n`` strongest."""
        m = self.ctx.map
        fi = np.flatnonzero(kf.mp >= 0)
        fi = fi[m.alive(kf.mp[fi])]
        if self.ctx.deformable:
            fi = fi[self.ctx.rigid(kf.mp[fi])]
        if len(fi) > n:
            fi = fi[np.argsort(-kf.feats.response[fi], kind="stable")[:n]]
        return fi

    def candidates(self, kf: KeyFrame) -> list[KeyFrame]:
        """Keyframes not connected to ``kf`` that look like it, best group score first (at most ``CANDIDATES``)."""
        m = self.ctx.map
        connected = set(m.observers(kf.mp[kf.mp >= 0])) | {kf.id}
        others = [k for k in m.keyframes.values() if k.id not in connected]
        q = self._mapped(kf, QUERY)
        if not others or len(q) < MIN_VOTES:
            return []
        rows, owner = [], []
        for k in others:
            fi = self._mapped(k, BANK)
            rows.append(k.feats.desc[fi])
            owner.append(np.full(len(fi), k.id, np.int64))
        bank, own = np.concatenate(rows), np.concatenate(owner)
        if len(bank) == 0:
            return []
        mt = match_descriptors(kf.feats.desc[q], bank, max_dist=DESC_DIST)
        votes = np.bincount(own[mt[:, 1]], minlength=m._next_kf) if len(mt) else np.zeros(m._next_kf, np.int64)
        scored = []
        for k in others:
            if votes[k.id] < MIN_VOTES:
                continue
            group = votes[k.id] + sum(int(votes[c.id]) for c in m.covisible(k, 10) if c.id not in connected)
            scored.append((group, int(votes[k.id]), k.id))
        scored.sort(reverse=True)
        return [m.keyframes[k] for _, _, k in scored[:CANDIDATES]]

    # -- 2. Sim3 ---------------------------------------------------------------------------------------------
    def _corrected_cam(self, kf: KeyFrame, S) -> tuple[np.ndarray, float]:
        """The corrected world -> camera pose of ``kf`` under the world similarity ``S`` (rigid part) and the factor
        by which camera-frame lengths change (1 / s)."""
        s, R, t = S
        Rwc = R @ kf.T_wc[:3, :3]
        C = s * R @ kf.center + t
        return G.inv(G.make_T(Rwc, C)), 1.0 / s

    def sim3(self, kf: KeyFrame, cand: KeyFrame):
        """The world similarity taking ``kf``'s side of the loop onto ``cand``'s, with its RANSAC inliers and
        projection matches and the loop side's keyframes; None when the loop is not confirmed."""
        ctx, m = self.ctx, self.ctx.map
        loop_side = [cand] + m.covisible(cand, 10)
        B = np.unique(np.concatenate([k.mp[k.mp >= 0] for k in loop_side]))
        B = B[m.alive(B)]
        if ctx.deformable:
            B = B[ctx.rigid(B)]
        B = B[~np.isin(B, kf.mp)]
        qi = self._mapped(kf, 10 ** 6)
        if len(B) < MIN_RANSAC or len(qi) < MIN_RANSAC:
            return None
        mt = match_descriptors(kf.feats.desc[qi], m._desc[m.rows(B)], max_dist=50, ratio=0.75)
        if len(mt) < MIN_RANSAC:
            return None
        fa = qi[mt[:, 0]]
        XA, XB = m._pos[m.rows(kf.mp[fa])], m._pos[m.rows(B[mt[:, 1]])]
        uv, sig2 = kf.feats.und[fa], kf.feats.sigma2()[fa]
        scaled = ctx.mode == "mono"

        def inliers(S) -> np.ndarray:
            T, _ = self._corrected_cam(kf, S)
            p, z = project(T, XB, ctx.K)  # the loop side's points seen from the corrected keyframe
            with np.errstate(invalid="ignore"):
                return (z > 0) & (np.sum((p - uv) ** 2, axis=1) / sig2 < CHI2_2D)

        rng = np.random.default_rng(kf.id)
        best, best_n = None, 0
        for _ in range(300):
            pick = rng.choice(len(XA), 3, replace=False)
            if np.linalg.matrix_rank(XA[pick] - XA[pick].mean(axis=0), tol=1e-9) < 2:
                continue
            S = similarity(XA[pick], XB[pick], scaled)
            if not (0.2 < S[0] < 5.0):
                continue
            n = int(inliers(S).sum())
            if n > best_n:
                best, best_n = S, n
        if best is None or best_n < MIN_RANSAC:
            return None
        inl = inliers(best)
        S = similarity(XA[inl], XB[inl], scaled)
        inl = inliers(S)
        if inl.sum() < MIN_RANSAC:
            return None
        matches = self._projection_matches(kf, S, B)
        if matches < MIN_MATCHES:
            return None
        return S, int(inl.sum()), matches, loop_side

    def _projection_matches(self, kf: KeyFrame, S, B: np.ndarray, radius: float = 3.0) -> int:
        """How many of ``kf``'s features the loop side's points ``B`` match when projected with the corrected pose
        (within ``radius`` x the level's scale, descriptor within 50 bits, each feature once)."""
        ctx, m, f = self.ctx, self.ctx.map, kf.feats
        T, _ = self._corrected_cam(kf, S)
        uv, z = project(T, m._pos[m.rows(B)], ctx.K)
        vis = ctx.in_image(uv, z)
        if not np.any(vis):
            return 0
        ids, uv = B[vis], uv[vis]
        k = min(8, len(f))
        dpix, nn = kf.tree.query(uv, k=k, distance_upper_bound=radius * f.max_sigma())
        dpix, nn = np.reshape(dpix, (len(uv), k)), nn.reshape(len(uv), k)
        valid = np.isfinite(dpix)
        rows = np.broadcast_to(np.arange(len(uv))[:, None], nn.shape)[valid]
        cols = nn[valid]
        ok = dpix[valid] <= radius * f.sigma()[cols]
        rows, cols = rows[ok], cols[ok]
        good = hamming(m._desc[m.rows(ids[rows])], f.desc[cols]) <= 50
        return len(np.unique(cols[good]))

    # -- 3. correction ---------------------------------------------------------------------------------------
    def correct(self, kf: KeyFrame, cand: KeyFrame, S, loop_side: list[KeyFrame]) -> tuple[int, float]:
        """Move ``kf``'s side by ``S``, fuse the loop side's points into it, optimize the essential graph and move
        every point with its reference keyframe. Returns the points fused or newly linked and the largest keyframe
        shift (map units)."""
        ctx, m = self.ctx, self.ctx.map
        s, R, t = S
        kfs = sorted(m.keyframes.values(), key=lambda k: k.id)
        old = {k.id: (1.0, k.T_wc[:3, :3].copy(), k.center.copy()) for k in kfs}  # uncorrected (scale, R_wc, C)
        centers0 = np.array([k.center for k in kfs])
        connected = [kf] + m.covisible(kf, 10 ** 6, min_shared=15)
        conn_ids = {k.id for k in connected}
        before = {k.id: set(m.observers(k.mp[k.mp >= 0])) for k in connected}
        essential = self._covisibility_edges(kfs)
        # the connected side moved by S (its points too): the initial values of the graph
        init = dict(old)
        pts = np.unique(np.concatenate([k.mp[k.mp >= 0] for k in connected]))
        pts = pts[m.alive(pts)]
        rows = m.rows(pts)
        m._pos[rows] = sim_apply(S, m._pos[rows])
        m._dist0[rows] *= s
        for k in connected:
            sc, Rk, C = old[k.id]
            init[k.id] = (s * sc, R @ Rk, s * R @ C + t)
            k.T_wc = G.make_T(R @ Rk, s * R @ C + t)
        # fuse the loop side's points into the corrected keyframes: the loop closes in the map
        loop_pts = np.unique(np.concatenate([k.mp[k.mp >= 0] for k in loop_side]))
        touched: set[int] = set()
        for k in connected:
            touched |= self.mapper._fuse_into(k, loop_pts)
        for pid in touched:
            if pid in m.points:
                m.update_descriptor(m.points[pid])
        loop_edges = []
        for k in connected:
            for j, c in m.observers(k.mp[k.mp >= 0]).items():
                if j not in conn_ids and j not in before[k.id] and c >= 15:
                    loop_edges.append((k.id, j))
        final = self._optimize(kfs, old, init, essential, loop_edges, cand.id)
        # keyframes and points to the optimized poses; each point follows its reference keyframe
        ref: dict[int, list[int]] = {}
        for pid, p in m.points.items():
            ref.setdefault(m.reference_keyframe(p), []).append(pid)
        for k in kfs:
            s0, R0, C0 = init[k.id]
            s1, R1, C1 = final[k.id]
            ids = np.array(ref.get(k.id, []), np.int64)
            if len(ids):
                rows = m.rows(ids)
                Xc = (m._pos[rows] - C0) @ R0 / s0  # in the keyframe's camera (initial-value units)
                m._pos[rows] = s1 * Xc @ R1.T + C1
                m._dist0[rows] *= s1 / s0
            k.T_wc = G.make_T(R1, C1)
        # the tracker continues from the corrected keyframe (this frame); its motion in the new units (camera-frame
        # lengths at this keyframe grew by its node's scale)
        ctx.T_cw_last = kf.T_cw
        if ctx.velocity is not None:
            v = ctx.velocity.copy()
            v[:3, 3] *= final[kf.id][0]
            ctx.velocity = v
        m.version += 1
        self.mapper.stale()
        self.mapper.global_bundle_adjust()  # synchronous or in the mapping process, as the local ones
        ctx.T_cw_last = kf.T_cw
        shift = float(np.max(np.linalg.norm(np.array([k.center for k in kfs]) - centers0, axis=1)))
        return len(touched), shift

    def _covisibility_edges(self, kfs: list[KeyFrame]) -> list[tuple[int, int]]:
        """Consecutive keyframes (ORB-SLAM2's spanning tree) and pairs sharing ``ESSENTIAL_MIN_SHARED`` points."""
        m = self.ctx.map
        edges = {(a.id, b.id) for a, b in itertools.pairwise(kfs)}
        for k in kfs:
            for j, c in m.observers(k.mp[k.mp >= 0]).items():
                if j > k.id and c >= ESSENTIAL_MIN_SHARED:
                    edges.add((k.id, j))
        return sorted(edges)

    def _optimize(self, kfs, old, init, essential, loop_edges, fixed_id):
        """The essential graph in GTSAM: Sim3 nodes (monocular) or Pose3 nodes; ``essential`` edges measured on the
        uncorrected poses ``old``, ``loop_edges`` on the corrected ``init``; ``fixed_id`` held. Returns the
        optimized (scale, R_wc, centre) of every keyframe."""
        import gtsam
        from gtsam.symbol_shorthand import X

        sim = self.ctx.mode == "mono"

        def node(v):
            sc, Rw, C = v
            if sim:  # GTSAM's Similarity3 maps p -> s (R p + t): t = C / s
                return gtsam.Similarity3(gtsam.Rot3(Rw), gtsam.Point3(*(C / sc)), sc)
            return gtsam.Pose3(gtsam.Rot3(Rw), gtsam.Point3(*C))

        graph = gtsam.NonlinearFactorGraph()
        vals = gtsam.Values()
        noise = gtsam.noiseModel.Isotropic.Sigma(7 if sim else 6, 1.0)
        between = gtsam.BetweenFactorSimilarity3 if sim else gtsam.BetweenFactorPose3
        for k in kfs:
            vals.insert(X(k.id), node(init[k.id]))
        held = gtsam.noiseModel.Isotropic.Sigma(7 if sim else 6, FIXED_SIGMA)  # the loop keyframe
        graph.add((gtsam.PriorFactorSimilarity3 if sim else gtsam.PriorFactorPose3)(X(fixed_id), node(init[fixed_id]),
                                                                                      held))
        for i, j in essential:
            graph.add(between(X(i), X(j), node(old[i]).inverse().compose(node(old[j])), noise))
        for i, j in loop_edges:
            graph.add(between(X(i), X(j), node(init[i]).inverse().compose(node(init[j])), noise))
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(20)
        params.setVerbosityLM("SILENT")
        try:
            res = gtsam.LevenbergMarquardtOptimizer(graph, vals, params).optimize()
        except RuntimeError:
            return init
        out = {}
        for k in kfs:
            v = res.atSimilarity3(X(k.id)) if sim else res.atPose3(X(k.id))
            Rw = v.rotation().matrix()
            if sim:
                sc = float(v.scale())
                out[k.id] = (sc, Rw, sc * np.asarray(v.translation()))
            else:
                out[k.id] = (1.0, Rw, np.asarray(v.translation()))
        return out
