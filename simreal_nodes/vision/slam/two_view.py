"""Map initialization: from the first frame's depth (RGB-D / stereo), or two-view for a monocular camera.

The two-view reconstruction follows ORB-SLAM2: a homography and a general two-view model are fitted to the matches
with a reference frame, scored by their symmetric transfer errors, and the better explained model (homography for a
planar or low-parallax scene, chosen above a score ratio of 0.40: ``SlamConfig.homography_ratio``) is decomposed into
candidate poses. The general model is by default (``SlamConfig.two_view_model = "essential"``) the essential matrix
from the five-point RANSAC on the calibrated matches, which does not spend three degrees of freedom on intrinsics the
camera already has, or ORB-SLAM2's eight-point fundamental matrix (``"fundamental"``). The five-point pose is the
better first pose (the measurements in docs/localization.md, from `benchmarks/two_view.py`). The pose that explains
most matches wins (its points with parallax in front of both cameras, every point reprojecting: ORB-SLAM2's CheckRT),
and it is refused without enough parallax (a pure rotation has no depth) or when a second pose comes close (an
ambiguous decomposition: a plane at low parallax, or F on a near-planar scene; the initialization then waits for more
motion).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.vision.orb import Features, match_descriptors
from simreal_nodes.vision.slam.config import H_AMBIGUITY, INITIALIZING, OK, TWO_VIEW_MODELS
from simreal_nodes.vision.slam.context import SlamContext
from simreal_nodes.vision.slam.local_mapping import LocalMapper
from simreal_nodes.vision.slam.map import KeyFrame
from simreal_nodes.vision.slam.optimize import CHI2_2D, project
from simreal_nodes.vision.slam.result import TrackResult, frame_result


@dataclass
class TwoViewSolution:
    """Relative pose of view 1 (``x1 = R x0 + t``, ``|t| = 1``), the well-triangulated points (view 0's frame) and
    the feature indices in each view they come from."""

    R: np.ndarray
    t: np.ndarray
    points: np.ndarray
    idx0: np.ndarray
    idx1: np.ndarray
    kind: str  # homography or fundamental


def initial_matches(f0: Features, f1: Features) -> np.ndarray:
    """The reference frame's features matched to the current frame's ((M, 2) indices): descriptors within 150 px of
    each other (where there are few enough features to compare positions), Hamming distance at most 50, ratio 0.9."""
    d = np.linalg.norm(f0.und[:, None, :] - f1.und[None, :, :], axis=2) if len(f0) * len(f1) < 4e6 else None
    mask = (d < 150) if d is not None else None
    return match_descriptors(f0.desc, f1.desc, mask, max_dist=50, ratio=0.9)


def two_view(f0: Features, f1: Features, K: np.ndarray, min_parallax: float,
             general: str = "essential", ambiguity: str = "explained",
             h_ratio: float = 0.40, fallback: bool = False) -> tuple[str, TwoViewSolution | None]:
    """Reconstruct two views of a static scene; returns (why not, None) or ("<kind> model", solution).
    ``min_parallax``: radians, the least median parallax of the triangulated points accepted. ``general``: the
    non-planar model, "essential" (five-point, calibrated; the default) or "fundamental" (ORB-SLAM2's eight-point;
    ``SlamConfig.two_view_model``); ``ambiguity``: how a homography's decompositions are told apart
    (:func:`_from_h`); ``h_ratio``: the share of the two models' scores the homography's must exceed
    (``SlamConfig.homography_ratio``); ``fallback``: where the homography wins the score but no decomposition of it
    is accepted, reconstruct from the general model instead of waiting (``SlamConfig.homography_fallback``). Either
    way the solution's kind is "fundamental" for the general model (as ORB-SLAM2 names it) and "homography" for the
    planar one."""
    if general not in TWO_VIEW_MODELS:
        raise ValueError(f"two_view: general model {general!r} is not one of {', '.join(TWO_VIEW_MODELS)}")
    if ambiguity not in H_AMBIGUITY:
        raise ValueError(f"two_view: ambiguity {ambiguity!r} is not one of {', '.join(H_AMBIGUITY)}")
    m = initial_matches(f0, f1)
    if len(m) < 100:
        return f"only {len(m)} matches with the reference frame (need 100): too little overlap or texture", None
    x0, x1 = f0.und[m[:, 0]], f1.und[m[:, 1]]
    H, _mh = cv2.findHomography(x0, x1, cv2.RANSAC, 2.0)
    E: np.ndarray | None
    if general == "essential":
        E, mf = cv2.findEssentialMat(x0, x1, K, cv2.RANSAC, 0.999, 1.0)
    else:
        F8, mf = cv2.findFundamentalMat(x0, x1, cv2.FM_RANSAC, 1.5, 0.999)
        E = K.T @ F8 @ K if F8 is not None and F8.shape == (3, 3) else None
    if E is None or E.shape != (3, 3) or H is None or mf is None:
        return "cannot estimate two-view geometry", None
    Ki = np.linalg.inv(K)
    F = Ki.T @ E @ Ki  # the fundamental matrix of the essential one, for ORB-SLAM2's score
    sh = _score_h(H, x0, x1)
    sf = _score_f(F, x0, x1)
    rh = sh / max(sh + sf, 1e-9)
    use_h = bool(rh > h_ratio)  # ORB-SLAM2 (0.40): a homography unless the general model explains clearly more
    sol: _Reconstruction | None = None
    kind, note = "homography", ""
    if use_h:
        sol = _from_h(H, x0, x1, K, ambiguity)
    if not use_h or (sol is None and fallback):
        note = "homography refused; " if use_h else ""
        sol = _from_f(E, x0, x1, mf.ravel().astype(bool), K)
        kind = "fundamental"
    if sol is None:
        return f"{note}{kind} model gives no valid reconstruction", None
    R, t, P, good, parallax = sol
    if parallax < min_parallax:
        return (f"not enough parallax ({np.rad2deg(parallax):.2f} deg, need {np.rad2deg(min_parallax):.1f}): "
                "a pure rotation cannot initialize a monocular map, translate the camera"), None
    if good.sum() < 50:
        return f"only {int(good.sum())} points triangulate well (need 50)", None
    return f"{kind} model" + (" (homography refused)" if note else ""), TwoViewSolution(R, t, P[good], m[good, 0],
                                                                                        m[good, 1], kind)


_Reconstruction = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]  # R, t, points, good, parallax


def _triangulate_check(R: np.ndarray, t: np.ndarray, x0: np.ndarray, x1: np.ndarray,
                       K: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Points triangulated under (R, t): which of them make map points (in front of both cameras, reprojected within
    4 x the chi-square bound, not at infinity), their median parallax (radians), and how many matches the pose
    explains: ORB-SLAM2's count, which includes the reprojecting points too far to show parallax (their side of the
    camera is not observable). Counting only the map points would favour a wrong pose that inflates the parallax:
    at low parallax it keeps more points from "infinity" than the right one."""
    P0 = K @ np.c_[np.eye(3), np.zeros(3)]
    P1 = K @ np.c_[R, t]
    X = cv2.triangulatePoints(P0, P1, x0.T.astype(np.float64), x1.T.astype(np.float64))
    X = (X[:3] / X[3]).T
    z0 = X[:, 2]
    X1 = X @ R.T + t
    z1 = X1[:, 2]
    uv0, _ = project(np.eye(4), X, K)
    uv1, _ = project(G.make_T(R, t), X, K)
    e0 = np.sum((uv0 - x0) ** 2, axis=1)
    e1 = np.sum((uv1 - x1) ** 2, axis=1)
    c0 = -R.T @ t
    r0 = X / np.maximum(np.linalg.norm(X, axis=1, keepdims=True), 1e-12)
    r1 = (X - c0) / np.maximum(np.linalg.norm(X - c0, axis=1, keepdims=True), 1e-12)
    cospar = np.sum(r0 * r1, axis=1)
    finite = cospar < 0.99998
    # a point with parallax must lie in front of both cameras and reproject; one without must reproject (where a
    # point near infinity falls on a pixel is known, its depth's sign is not)
    consistent = ((~finite | ((z0 > 0) & (z1 > 0))) & np.all(np.isfinite(X), axis=1) & (e0 < 4 * CHI2_2D)
                  & (e1 < 4 * CHI2_2D))
    good = consistent & finite
    par = float(np.arccos(np.clip(np.median(cospar[good]), -1, 1))) if good.sum() else 0.0
    return X, good, par, int(consistent.sum())


def _from_f(E: np.ndarray, x0: np.ndarray, x1: np.ndarray, inl: np.ndarray, K: np.ndarray) -> _Reconstruction | None:
    """The essential matrix's four poses (``inl``: the RANSAC's inliers): the one that puts most of the model's
    inliers in front of both cameras with parallax, refused when another comes within 70 % of it (ORB-SLAM2's test; a
    near-planar or low-parallax scene leaves F ill-determined). Points without parallax are left out of this count:
    they fit all four alike."""
    R1, R2, t0 = cv2.decomposeEssentialMat(E)
    t = np.asarray(t0, np.float64).ravel() / max(float(np.linalg.norm(t0)), 1e-12)
    sols = []
    for R, tt in ((R1, t), (R1, -t), (R2, t), (R2, -t)):
        good = _triangulate_check(R, tt, x0[inl], x1[inl], K)[1]
        sols.append((int(good.sum()), R, tt))
    sols.sort(key=lambda r: r[0], reverse=True)
    n_good, R, t = sols[0]
    if n_good < 50 or sum(1 for r in sols if r[0] > 0.7 * n_good) > 1:
        return None
    X, good, par, _n = _triangulate_check(R, t, x0, x1, K)
    good &= inl
    return (R, t, X, good, par) if good.sum() >= 50 else None


def _from_h(H: np.ndarray, x0: np.ndarray, x1: np.ndarray, K: np.ndarray,
            ambiguity: str = "explained") -> _Reconstruction | None:
    """The decomposition that explains most matches, refused when another comes close (ambiguous). ``ambiguity``:
    what "close" counts (``SlamConfig.homography_ambiguity``): "explained", every match a pose explains (ORB-SLAM2;
    the points too far for parallax fit every decomposition alike), or "triangulated", only the points it puts in
    front of both cameras with parallax (as :func:`_from_f` does)."""
    _n, Rs, ts, _ = cv2.decomposeHomographyMat(H, K)
    cands = []
    for R, t in zip(Rs, ts):
        t = t.ravel()
        if np.linalg.norm(t) < 1e-9:
            continue
        X, good, par, n = _triangulate_check(R, t / np.linalg.norm(t), x0, x1, K)
        cands.append((n, (R, t / np.linalg.norm(t), X, good, par)))
    if not cands:
        return None
    i = max(range(len(cands)), key=lambda j: cands[j][0])
    best = cands[i][1]
    score = (lambda c: c[0]) if ambiguity == "explained" else (lambda c: int(c[1][3].sum()))
    second = max((score(c) for j, c in enumerate(cands) if j != i), default=0)
    if best[3].sum() < 50 or second > 0.75 * score(cands[i]):
        return None
    return best


def _score_h(H: np.ndarray, x0: np.ndarray, x1: np.ndarray, th: float = 5.991) -> float:
    Hi = np.linalg.inv(H)
    a = np.c_[x0, np.ones(len(x0))] @ H.T
    b = np.c_[x1, np.ones(len(x1))] @ Hi.T
    e1 = np.sum((a[:, :2] / a[:, 2:] - x1) ** 2, axis=1)
    e2 = np.sum((b[:, :2] / b[:, 2:] - x0) ** 2, axis=1)
    return float(np.sum(np.where(e1 < th, th - e1, 0) + np.where(e2 < th, th - e2, 0)))


def _score_f(F: np.ndarray, x0: np.ndarray, x1: np.ndarray, th: float = 3.841, th_score: float = 5.991) -> float:
    a = np.c_[x0, np.ones(len(x0))]
    b = np.c_[x1, np.ones(len(x1))]
    l2 = a @ F.T
    l1 = b @ F
    d2 = np.sum(l2 * b, axis=1) ** 2 / np.maximum(l2[:, 0] ** 2 + l2[:, 1] ** 2, 1e-12)
    d1 = np.sum(l1 * a, axis=1) ** 2 / np.maximum(l1[:, 0] ** 2 + l1[:, 1] ** 2, 1e-12)
    return float(np.sum(np.where(d2 < th, th_score - d2, 0) + np.where(d1 < th, th_score - d1, 0)))


class Initializer:
    """Builds the first map: from depth at once, or (monocular) from a reference frame and a later one that
    reconstructs with :func:`two_view`; then bundle-adjusts it and fixes its scale."""

    def __init__(self, ctx: SlamContext, mapper: LocalMapper, known_scale: float | None) -> None:
        self.ctx = ctx
        self.mapper = mapper
        self.known_scale = known_scale  # metres between the two initial views (monocular), when known
        self.ref: tuple[Features, int, int] | None = None  # monocular reference frame: features, stamp, frame id

    def initialize(self, f: Features, z: np.ndarray | None, stamp: int) -> TrackResult:
        ctx, m = self.ctx, self.ctx.map
        if ctx.mode in ("rgbd", "stereo"):
            assert z is not None  # rgbd / stereo frames always come with their feature depths
            ok = np.isfinite(z)
            if ok.sum() < 100:
                ctx.state = INITIALIZING
                return TrackResult(INITIALIZING,
                                   f"waiting for depth: {int(ok.sum())} features with valid depth (need 100)")
            kf = m.new_keyframe(stamp, np.eye(4), f, z)
            P = ctx.cam.backproject(f.und[ok], z[ok])
            for i, p in zip(np.flatnonzero(ok), P):
                m.new_point(p, f.desc[i], kf, int(i))
            m.scale_known = True
            return self._initialized(kf, f)
        if self.ref is None or len(self.ref[0]) < 100 or ctx.frame_id - self.ref[2] > 60:
            self.ref = (f, stamp, ctx.frame_id)
            ctx.state = INITIALIZING
            return TrackResult(INITIALIZING, "initializing: reference frame set, move the camera sideways")
        f0, s0, _ = self.ref
        reason, sol = two_view(f0, f, ctx.K, ctx.config.min_parallax, general=ctx.config.two_view_model,
                               ambiguity=ctx.config.homography_ambiguity, h_ratio=ctx.config.homography_ratio,
                               fallback=ctx.config.homography_fallback)
        if sol is None:
            ctx.state = INITIALIZING
            return TrackResult(INITIALIZING, f"initializing: {reason}")
        kf0 = m.new_keyframe(s0, np.eye(4), f0)
        T_cw1 = G.make_T(sol.R, sol.t)
        kf1 = m.new_keyframe(stamp, G.inv(T_cw1), f)
        for p, a, b in zip(sol.points, sol.idx0, sol.idx1):
            mp = m.new_point(p, f.desc[b], kf0, int(a))
            m.link(mp, kf1, int(b))
        self.mapper.bundle_adjust([kf1], [kf0], sync=True)  # before the scale is fixed: never asynchronous
        # scale: median scene depth 1 (ORB-SLAM2) or the known baseline between the two views
        Pc = np.array([p.pos for p in m.points.values()])
        s = self.known_scale / np.linalg.norm(kf1.center) if self.known_scale else 1.0 / np.median(Pc[:, 2])
        for p in m.points.values():
            p.pos = p.pos * s
        kf1.T_wc[:3, 3] *= s
        m.scale_known = bool(self.known_scale)
        self.ref = None
        return self._initialized(kf1, f, f"initialized from {len(sol.points)} points ({sol.kind})")

    def _initialized(self, kf: KeyFrame, f: Features, msg: str = "") -> TrackResult:
        ctx = self.ctx
        ctx.ref_kf = kf
        ctx.T_cw_last = kf.T_cw
        ctx.velocity = None
        ctx.last_kf_frame = ctx.frame_id
        ctx.kf_inliers = int(np.sum(kf.mp >= 0))
        ctx.state = OK
        ids = kf.mp[kf.mp >= 0]
        res = frame_result(ctx.map, OK, msg or f"initialized with {len(ids)} points from depth", kf.T_wc, f,
                           np.flatnonzero(kf.mp >= 0), ids, np.ones(len(ids), bool))
        res.keyframe = True
        return res
