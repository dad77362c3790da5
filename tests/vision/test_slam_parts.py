"""The SLAM's parts on synthetic features with exact geometry (no rendering): two-view initialization, depth
initialization + tracking + keyframe insertion, relocalization against a small map, the deformable tracks'
re-acquisition, and the config."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.vision.orb import Features
from simreal_nodes.vision.slam.config import INITIALIZING, LOST, NOT_STARTED, OK, RELOCALIZED, SlamConfig
from simreal_nodes.vision.slam.context import SlamContext
from simreal_nodes.vision.slam.deformable import DeformableTracks
from simreal_nodes.vision.slam.local_mapping import LocalMapper, close_points
from simreal_nodes.vision.slam.relocalization import Relocalizer
from simreal_nodes.vision.slam.result import TrackResult
from simreal_nodes.vision.slam.tracking import Tracker
from simreal_nodes.vision.slam.two_view import Initializer, two_view

CAM = CameraModel.from_intrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)


def scene(n: int = 400, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """World points 3-6 m in front of the origin camera, all in its image (so a map made there numbers its points
    as these), with a distinct random ORB descriptor each."""
    rng = np.random.default_rng(seed)
    uv = np.c_[rng.uniform(40.0, 600.0, n), rng.uniform(40.0, 440.0, n)]
    X = CAM.backproject(uv, rng.uniform(3.0, 6.0, n))
    return X, rng.integers(0, 256, (n, 32), dtype=np.uint8)


def view(X: np.ndarray, desc: np.ndarray, T_cw: np.ndarray, sel: np.ndarray | None = None,
         shift_px: float = 0.0) -> tuple[Features, np.ndarray, np.ndarray]:
    """The features a camera at T_cw sees of the points (those in the image; ``sel``: only these), at their exact
    projection (moved ``shift_px`` to the right); also the point indices and their depths."""
    Pc = X @ T_cw[:3, :3].T + T_cw[:3, 3]
    uv = CAM.project(Pc) + np.array([shift_px, 0.0])
    inside = (Pc[:, 2] > 0) & (uv[:, 0] >= 20) & (uv[:, 0] < 620) & (uv[:, 1] >= 20) & (uv[:, 1] < 460)
    idx = np.flatnonzero(inside if sel is None else inside & np.isin(np.arange(len(X)), sel))
    n = len(idx)
    f = Features(uv[idx].astype(np.float32), uv[idx].astype(np.float64), np.zeros(n, np.int32), desc[idx],
                 np.ones(n, np.float32))
    return f, idx, Pc[idx, 2]


def context(mode: str = "rgbd", **cfg: float) -> SlamContext:
    return SlamContext(CAM, CAM.K.copy(), mode, 0.08 if mode == "rgbd" else None, SlamConfig(**cfg))


def depth_map(ctx: SlamContext, X: np.ndarray, desc: np.ndarray) -> Initializer:
    """A map initialized from one RGB-D frame at the origin."""
    init = Initializer(ctx, LocalMapper(ctx, async_mapping=False), None)
    f, _, z = view(X, desc, np.eye(4))
    ctx.frame_id += 1
    res = init.initialize(f, z, 0)
    assert res.state == OK and res.keyframe and len(ctx.map.points) == len(X)
    return init


def test_two_view_recovers_the_relative_pose_up_to_scale():
    X, desc = scene()
    T_cw1 = G.make_T(G.rot_axis("y", np.deg2rad(2.0)), np.array([-0.3, 0.02, 0.05]))
    f0, i0, _ = view(X, desc, np.eye(4))
    f1, i1, _ = view(X, desc, T_cw1)
    reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0))
    assert sol is not None, reason
    assert reason == "fundamental model" and sol.kind == "fundamental"
    t_true = T_cw1[:3, 3] / np.linalg.norm(T_cw1[:3, 3])
    assert np.linalg.norm(sol.t - t_true) < 1e-3
    assert np.linalg.norm(sol.R - T_cw1[:3, :3]) < 1e-4
    assert len(sol.points) > 200
    # the points are the scene's, in view 0's frame, scaled by the unknown baseline
    truth = X[i0[sol.idx0]] / np.linalg.norm(T_cw1[:3, 3])
    assert np.array_equal(i0[sol.idx0], i1[sol.idx1])
    assert np.max(np.abs(sol.points - truth)) < 1e-3


def arc_views(seed: int, base_m: float, yaw_deg: float) -> tuple[Features, Features, np.ndarray]:
    """A monocular start in a room: 600 points 1-3 m away over the whole image, the camera sliding ``base_m``
    sideways while turning ``yaw_deg`` (a hand-held arc), 0.7 px of pixel noise; also the true 0 -> 1 pose."""
    rng = np.random.default_rng(seed)
    uv = np.c_[rng.uniform(20, 620, 600), rng.uniform(20, 460, 600)]
    X = CAM.backproject(uv, rng.uniform(1.0, 3.0, 600))
    desc = rng.integers(0, 256, (600, 32), dtype=np.uint8)
    T1 = G.make_T(G.rot_axis("y", np.deg2rad(yaw_deg)), np.array([-base_m, 0.005, 0.0]))
    uv1 = CAM.project(X @ T1[:3, :3].T + T1[:3, 3])
    uv0, uv1 = uv + rng.normal(0, 0.7, uv.shape), uv1 + rng.normal(0, 0.7, uv1.shape)
    inside = (uv1[:, 0] > 0) & (uv1[:, 0] < 640) & (uv1[:, 1] > 0) & (uv1[:, 1] < 480)

    def feats(u: np.ndarray, d: np.ndarray) -> Features:
        return Features(u.astype(np.float32), u.astype(np.float64), np.zeros(len(u), np.int32), d,
                        np.ones(len(u), np.float32))

    return feats(uv0, desc), feats(uv1[inside], desc[inside]), T1


@pytest.mark.parametrize("general", ["essential", "fundamental"])
def test_two_view_translation_at_a_monocular_starts_baseline(general):
    """10 cm sideways and 3 deg of turn, 1-3 m deep: the five-point essential matrix (``"essential"``) gets the
    translation's direction within 6 deg on each of 12 noise draws (median 2.5, worst 4.1 deg); ORB-SLAM2's
    eight-point fundamental matrix, which spends three degrees of freedom on intrinsics the camera already has, has
    its median at 8.4 deg and its worst at 13.8 (the old code's initializations on the rendered room were 10-78 deg
    off: benchmarks/results/two_view.md). The rotation is within 1.5 deg either way."""
    import cv2

    rot, dirs = [], []
    for seed in range(12):
        cv2.setRNGSeed(seed)  # OpenCV's RANSAC has its own generator
        f0, f1, T1 = arc_views(seed, 0.10, 3.0)
        reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0), general=general)
        assert sol is not None, (seed, reason)
        rot.append(np.rad2deg(np.arccos(np.clip((np.trace(sol.R.T @ T1[:3, :3]) - 1) / 2, -1, 1))))
        t = T1[:3, 3] / np.linalg.norm(T1[:3, 3])
        dirs.append(np.rad2deg(np.arccos(np.clip(sol.t @ t, -1, 1))))
    assert max(rot) < 1.5, np.round(rot, 2)
    good = max(dirs) < 6.0 and np.median(dirs) < 4.0
    assert good == (general == "essential"), (general, np.round(dirs, 1))


def test_two_view_refuses_an_unknown_general_model():
    X, desc = scene()
    f0, _, _ = view(X, desc, np.eye(4))
    with pytest.raises(ValueError, match="general model"):
        two_view(f0, f0, CAM.K, np.deg2rad(1.0), general="affine")
    with pytest.raises(ValueError, match="ambiguity"):
        two_view(f0, f0, CAM.K, np.deg2rad(1.0), ambiguity="most")


def slid_floor_views(seed: int, base_m: float) -> tuple[Features, Features, np.ndarray]:
    """A monocular start over a floor: 400 points on a plane tilted 50 deg, 1.2 m below the camera's axis, the camera
    sliding ``base_m`` sideways and turning 0.5 deg, 0.5 px of pixel noise; also the true 0 -> 1 pose."""
    rng = np.random.default_rng(seed)
    uv = np.c_[rng.uniform(20, 620, 400), rng.uniform(20, 460, 400)]
    rays = CAM.backproject(uv, np.ones(400))
    normal = np.array([0.0, -np.cos(np.deg2rad(50.0)), -np.sin(np.deg2rad(50.0))])
    X = rays * (-1.2 / (rays @ normal))[:, None]
    desc = rng.integers(0, 256, (400, 32), dtype=np.uint8)
    T1 = G.make_T(G.rot_axis("y", np.deg2rad(0.5)), np.array([-base_m, 0.003, 0.0]))
    uv1 = CAM.project(X @ T1[:3, :3].T + T1[:3, 3]) + rng.normal(0, 0.5, uv.shape)
    uv0 = uv + rng.normal(0, 0.5, uv.shape)

    def feats(u: np.ndarray) -> Features:
        return Features(u.astype(np.float32), u.astype(np.float64), np.zeros(len(u), np.int32), desc,
                        np.ones(len(u), np.float32))

    return feats(uv0), feats(uv1), T1


@pytest.mark.parametrize("ambiguity", ["explained", "triangulated"])
def test_homography_start_on_a_floor_at_low_parallax(ambiguity):
    """4 cm over a floor 1.5-3 m away: the homography's decompositions all explain the matches about alike (the
    count ORB-SLAM2 tells them apart by), so ``"explained"`` waits on each of 4 noise draws, while only one puts
    the points in front of both cameras with parallax: ``"triangulated"`` starts on it, its translation's
    direction within 3 deg (0.7-2.5). At 6 cm both start, on the same pose."""
    import cv2

    for seed in range(4):
        for base, starts in ((0.04, ambiguity == "triangulated"), (0.06, True)):
            cv2.setRNGSeed(seed)
            f0, f1, T1 = slid_floor_views(seed, base)
            reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0), ambiguity=ambiguity)
            assert (sol is not None) == starts, (seed, base, reason)
            if sol is not None:
                assert sol.kind == "homography"
                t = T1[:3, 3] / np.linalg.norm(T1[:3, 3])
                assert np.rad2deg(np.arccos(np.clip(sol.t @ t, -1, 1))) < 3.0, (seed, base)
            else:
                assert reason == "homography model gives no valid reconstruction"


def test_a_refused_homography_falls_back_to_the_general_model_only_when_asked():
    """``homography_fallback``: the 4 cm floor above, where the homography wins the score and every decomposition is
    refused as ambiguous: by default the start waits; with the fallback the same frames are reconstructed from the
    essential matrix where it gives a valid pose (draw 3: within 10 deg of the true direction of travel) and refused
    with the general model's reason where it does not (draw 1: too little parallax)."""
    import cv2

    for seed in range(4):
        cv2.setRNGSeed(seed)
        f0, f1, T1 = slid_floor_views(seed, 0.04)
        cv2.setRNGSeed(seed)
        reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0))
        assert sol is None and reason == "homography model gives no valid reconstruction"
        cv2.setRNGSeed(seed)
        reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0), fallback=True)
        if seed == 3:
            assert sol is not None and sol.kind == "fundamental", reason
            assert reason == "fundamental model (homography refused)"
            t = T1[:3, 3] / np.linalg.norm(T1[:3, 3])
            assert np.rad2deg(np.arccos(np.clip(sol.t @ t, -1, 1))) < 10.0
        elif seed == 1:  # the general model reconstructs, on too little parallax
            assert sol is None and reason.startswith("not enough parallax"), reason
        else:
            assert sol is None and reason == "homography refused; fundamental model gives no valid reconstruction"


def test_two_view_refuses_a_pure_rotation():
    X, desc = scene()
    f0, _, _ = view(X, desc, np.eye(4))
    f1, _, _ = view(X, desc, G.make_T(G.rot_axis("y", np.deg2rad(3.0))))
    reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0))
    assert sol is None
    assert "parallax" in reason or "no valid reconstruction" in reason


def floor_views(seed: int, base_m: float, yaw_deg: float) -> tuple[Features, Features, np.ndarray]:
    """A camera 2 m above a textured floor (the car park's view: the floor fills the lower image) and a second view
    after ``base_m`` sideways and ``yaw_deg`` towards the centre, 0.7 px pixel noise; also the true world ->
    camera 1 pose."""
    rng = np.random.default_rng(seed)
    uv = np.c_[rng.uniform(20, 620, 400), rng.uniform(250, 460, 400)]
    ray = np.c_[(uv - [320.0, 240.0]) / 500.0, np.ones(400)]
    X = ray * (2.0 / ray[:, 1:2])
    desc = rng.integers(0, 256, (400, 32), dtype=np.uint8)
    T1 = G.make_T(G.rot_axis("y", np.deg2rad(yaw_deg)), np.array([-base_m, 0.0, 0.0]))
    uv1 = CAM.project(X @ T1[:3, :3].T + T1[:3, 3])
    uv0, uv1 = uv + rng.normal(0, 0.7, uv.shape), uv1 + rng.normal(0, 0.7, uv1.shape)
    inside = (uv1[:, 0] > 0) & (uv1[:, 0] < 640) & (uv1[:, 1] < 480)

    def feats(u: np.ndarray, d: np.ndarray) -> Features:
        return Features(u.astype(np.float32), u.astype(np.float64), np.zeros(len(u), np.int32), d,
                        np.ones(len(u), np.float32))

    return feats(uv0, desc), feats(uv1[inside], desc[inside]), T1


def test_two_view_on_a_floor_waits_for_parallax_instead_of_a_wrong_pose():
    """At low parallax a plane's homography decomposes into two poses that both reproject every match; the old count
    (points with parallax only) took the one that inflates the parallax, 2.3-2.5 deg off (4 of these 10 seeds at
    8 cm, 0.8 deg). Counting every reprojecting match, as ORB-SLAM2, leaves them tied: it waits. With more baseline
    the homography gives the pose."""
    def rot_err(sol: object, T1: np.ndarray) -> float:
        R = sol.R  # type: ignore[attr-defined]
        return float(np.rad2deg(np.arccos(np.clip((np.trace(R.T @ T1[:3, :3]) - 1) / 2, -1, 1))))

    for seed in range(10):
        f0, f1, T1 = floor_views(seed, 0.08, 0.8)
        reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0))
        assert sol is None or rot_err(sol, T1) < 0.5, (seed, reason, rot_err(sol, T1))
    good = 0
    for seed in range(10):
        f0, f1, T1 = floor_views(seed, 0.3, 3.0)
        reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0))
        good += sol is not None and sol.kind == "homography" and rot_err(sol, T1) < 1.0
    assert good >= 8


def test_monocular_initializer_sets_a_reference_then_builds_a_unit_depth_map():
    X, desc = scene()
    ctx = context("mono")
    init = Initializer(ctx, LocalMapper(ctx, async_mapping=False), None)
    ctx.frame_id = 1
    res = init.initialize(view(X, desc, np.eye(4))[0], None, 0)
    assert res.state == INITIALIZING and "reference frame set" in res.reason
    ctx.frame_id = 2
    res = init.initialize(view(X, desc, G.make_T(t=np.array([-0.3, 0.0, 0.0])))[0], None, 1)
    assert res.state == OK == ctx.state and res.keyframe and "fundamental" in res.reason
    P = np.array([p.pos for p in ctx.map.points.values()])
    assert abs(np.median(P[:, 2]) - 1.0) < 1e-9  # ORB-SLAM2's scale: median scene depth 1
    assert len(ctx.map.keyframes) == 2 and ctx.ref_kf is ctx.map.keyframes[1]


@pytest.mark.parametrize("field, value", [("two_view_model", "fundamental"), ("two_view_model", "essential"),
                                          ("homography_ambiguity", "explained"),
                                          ("homography_ambiguity", "triangulated"), ("homography_ratio", 0.40),
                                          ("homography_ratio", 0.50)])
def test_monocular_initializer_passes_its_two_view_settings(monkeypatch, field, value):
    """``SlamConfig.two_view_model``, ``homography_ambiguity`` and ``homography_ratio`` reach the two-view
    reconstruction, the defaults (the five-point model, ORB-SLAM2's count and ratio) when not set."""
    import simreal_nodes.vision.slam.two_view as tv

    f0, f1, _ = arc_views(3, 0.10, 3.0)
    seen: list[dict] = []

    def spy(*a, **k):
        seen.append(k)
        return two_view(*a, **k)

    monkeypatch.setattr(tv, "two_view", spy)
    ctx = context("mono") if getattr(SlamConfig(), field) == value else context("mono", **{field: value})
    init = Initializer(ctx, LocalMapper(ctx, async_mapping=False), None)
    ctx.frame_id = 1
    init.initialize(f0, None, 0)
    ctx.frame_id = 2
    assert init.initialize(f1, None, 1).state == OK
    key = {"two_view_model": "general", "homography_ambiguity": "ambiguity", "homography_ratio": "h_ratio"}[field]
    assert [k[key] for k in seen] == [value]


def test_the_homography_ratio_picks_the_model_decomposed(monkeypatch):
    """``h_ratio`` is the share of the two models' scores the homography's must exceed: a floor seen from two views 30
    cm apart starts from the homography at ORB-SLAM2's 0.40 on most draws and is given to the general model where no
    share is enough (1.0); a room in depth starts from the general model at 0.40, and a share of 0 sends it to the
    homography. With the scores held at a share of 0.45, ORB-SLAM2's 0.40 takes the homography and ORB-SLAM3's 0.50
    the general model, as does a ratio equal to the share (the homography needs more)."""
    import simreal_nodes.vision.slam.two_view as tv

    kinds = []
    for seed in range(4):
        f0, f1, _ = floor_views(seed, 0.3, 3.0)
        kinds.append(two_view(f0, f1, CAM.K, np.deg2rad(1.0))[0])
        reason, sol = two_view(f0, f1, CAM.K, np.deg2rad(1.0), h_ratio=1.0)  # a plane leaves E ambiguous: refused
        assert reason.startswith("fundamental model") and (sol is None or sol.kind == "fundamental"), reason
    assert kinds.count("homography model") >= 3, kinds
    f0, f1, _ = arc_views(3, 0.10, 3.0)
    assert two_view(f0, f1, CAM.K, np.deg2rad(1.0))[0] == "fundamental model"
    assert two_view(f0, f1, CAM.K, np.deg2rad(1.0), h_ratio=0.0)[0].startswith("homography model")
    monkeypatch.setattr(tv, "_score_h", lambda *a, **k: 45.0)
    monkeypatch.setattr(tv, "_score_f", lambda *a, **k: 55.0)
    for ratio, model in ((0.40, "homography"), (0.45, "fundamental"), (0.50, "fundamental")):
        assert two_view(f0, f1, CAM.K, np.deg2rad(1.0), h_ratio=ratio)[0].startswith(f"{model} model"), ratio
    for bad in (1.5, -0.1, float("nan")):
        with pytest.raises(ValueError, match="homography_ratio"):
            SlamConfig(homography_ratio=bad)


def test_tracking_from_a_depth_map_and_a_keyframe():
    X, desc = scene()
    ctx = context()
    init = depth_map(ctx, X, desc)
    tracker = Tracker(ctx)
    T_cw1 = G.make_T(G.rot_axis("x", np.deg2rad(0.5)), np.array([0.02, -0.01, 0.01]))
    f1, _, z1 = view(X, desc, T_cw1)
    ctx.frame_id += 1
    res, fix = tracker.track(f1, {})
    assert res.state == OK and fix is not None
    assert np.max(np.abs(fix.T_cw - T_cw1)) < 1e-6
    assert res.n_inliers > 0.9 * len(f1)
    assert np.allclose(ctx.velocity, T_cw1, atol=1e-6)  # constant-velocity model: the motion from the origin
    kf = init.mapper.insert_keyframe(5, fix.T_cw, f1, z1, fix.match, fix.inl)
    assert ctx.ref_kf is kf and ctx.last_kf_frame == ctx.frame_id and ctx.kf_inliers == res.n_inliers
    assert np.max(np.abs(kf.T_cw - T_cw1)) < 1e-5  # the BA keeps the exact pose


def test_fusion_merges_a_point_mapped_twice_and_links_a_missed_observation():
    """ORB-SLAM2's SearchInNeighbors: keyframe A maps 300 points; keyframe B (4 cm aside) sees the same points,
    the first 100 as duplicates of their own (3 mm off, the same descriptor, also seen by a third keyframe C), the
    next 100 not linked at all, the rest with a descriptor that differs (not the same point). Fusing A's points into
    B merges each duplicate into one point seen by A, B and C, links the missed observations, and leaves the
    different descriptors alone."""
    X, desc = scene(300, seed=3)
    ctx = context("rgbd")
    m = ctx.map
    mapper = LocalMapper(ctx, async_mapping=False)
    T_b = G.make_T(G.rot_axis("y", np.deg2rad(0.3)), np.array([-0.04, 0.0, 0.0]))
    T_c = G.make_T(np.eye(3), np.array([-0.08, 0.0, 0.0]))
    fa, ia, _ = view(X, desc, np.eye(4))
    desc_b = desc.copy()
    desc_b[200:] ^= 0xFF  # far in Hamming distance: other points where A's are projected
    fb, ib, _ = view(X, desc_b, T_b)
    fc, ic, _ = view(X, desc, T_c)
    assert len(ia) == len(ib) == len(ic) == 300
    A = m.new_keyframe(0, np.eye(4), fa)
    B = m.new_keyframe(1, G.inv(T_b), fb)
    C = m.new_keyframe(2, G.inv(T_c), fc)
    own = [m.new_point(X[i], desc[i], A, k).id for k, i in enumerate(ia)]
    dup = {}
    for k, i in enumerate(ib[:100]):
        q = m.new_point(X[i] + 0.003, desc[i], B, k)
        m.link(q, C, int(np.flatnonzero(ic == i)[0]))
        dup[int(i)] = q.id
    touched = mapper._fuse_into(B, np.array(own))
    assert len(touched) == 200
    for k, i in enumerate(ia):
        p_ids = {int(B.mp[np.flatnonzero(ib == i)[0]])}
        if i < 100:  # one point left, seen by all three keyframes
            (pid,) = p_ids
            assert set(m.points[pid].obs) == {A.id, B.id, C.id}
            assert (own[k] in m.points) != (dup[int(i)] in m.points)
        elif i < 200:  # A's point, now also seen by B
            assert p_ids == {own[k]} and set(m.points[own[k]].obs) == {A.id, B.id}
        else:  # another descriptor: not the same point
            assert p_ids == {-1} and set(m.points[own[k]].obs) == {A.id}
    assert len(m.points) == 300
    # a second pass finds nothing more to do
    assert mapper._fuse_into(B, np.fromiter(m.points, np.int64)) == set()


@pytest.mark.parametrize("cap,in_ba", [(0, 300), (100, 100)])
def test_local_bundle_adjustment_optimizes_every_point_its_keyframes_see(monkeypatch, cap, in_ba):
    """Keyframe A (the oldest: held) and B (stored 1 cm and 0.6 degrees off its true pose) both see 300 exact points
    (RGB-D). The local BA brings B back to its true pose, leaves A exactly where it is, and optimizes every point
    unless ``max_ba_points`` caps them (a capped BA leaves the rest where they were while their keyframes move: on
    monocular maps at 2000 features that was 115 mm of drift against 1.8 mm, benchmarks/local_ba.py)."""
    from simreal_nodes.vision.slam import local_mapping

    seen = []
    real = local_mapping.bundle_adjust
    monkeypatch.setattr(local_mapping, "bundle_adjust", lambda req, *a, **k: seen.append(req) or real(req, *a, **k))
    X, desc = scene(300, seed=5)
    ctx = context("rgbd", max_ba_points=cap)
    m = ctx.map
    T_b = G.make_T(G.rot_axis("y", np.deg2rad(2.0)), np.array([-0.1, 0.02, 0.0]))
    fa, ia, za = view(X, desc, np.eye(4))
    fb, ib, zb = view(X, desc, T_b)
    assert len(ia) == len(ib) == 300
    A = m.new_keyframe(0, np.eye(4), fa, za)
    B = m.new_keyframe(1, G.inv(G.make_T(G.rot_axis("x", np.deg2rad(0.6)), np.array([0.01, 0.0, 0.0])) @ T_b), fb,
                       zb)
    for k, i in enumerate(ia):
        m.link(m.new_point(X[i], desc[i], A, k), B, int(np.flatnonzero(ib == i)[0]))
    LocalMapper(ctx, async_mapping=False).bundle_adjust([A, B], None)
    (req,) = seen
    assert list(req["fixed"]) == [False, True] and list(req["kf_ids"]) == [B.id, A.id]
    assert len(req["pt_ids"]) == in_ba
    assert np.array_equal(A.T_wc, np.eye(4))
    assert np.max(np.abs(B.T_cw - T_b)) < 1e-4
    moved = np.linalg.norm(m._pos[m.rows(np.asarray(sorted(m.points)))] - X[ia], axis=1)
    assert moved.max() < 1e-4  # exact observations: the optimized points stay on the truth, the others untouched


def four_keyframes(ctx: SlamContext) -> list:
    """Four keyframes 10 cm apart (stored up to 0.9 degrees and 3 cm off their true poses) seeing 300 points stored
    2 cm (sigma) off theirs: a local BA that takes several iterations."""
    X, desc = scene(300, seed=5)
    rng = np.random.default_rng(1)
    m = ctx.map
    Ts = [G.make_T(G.rot_axis("y", np.deg2rad(2.0 * k)), np.array([-0.1 * k, 0.02 * k, 0.0])) for k in range(4)]
    views = [view(X, desc, T) for T in Ts]
    kfs = [m.new_keyframe(k, G.inv(G.make_T(G.rot_axis("x", np.deg2rad(0.3 * k)), np.array([0.01 * k, 0, 0])) @ T),
                          f, z if ctx.mode == "rgbd" else None) for k, (T, (f, _, z)) in enumerate(zip(Ts, views))]
    for k, i in enumerate(views[0][1]):
        p = m.new_point(X[i] + rng.normal(0.0, 0.02, 3), desc[i], kfs[0], k)
        for kf, (_, ids, _) in zip(kfs[1:], views[1:]):
            j = np.flatnonzero(ids == i)
            if len(j):
                m.link(p, kf, int(j[0]))
    return kfs


def test_bundle_adjustment_stops_when_asked_with_what_it_has():
    """GTSAM's own loop, run iteration by iteration: without a stop it gives what ``optimize()`` gives (bit for bit);
    a stop asked for ends it after the first iteration, and the points have moved toward the truth by then."""
    import gtsam

    from simreal_nodes.vision.slam import optimize as O

    ctx = context("mono")
    kfs = four_keyframes(ctx)
    m = ctx.map
    req = O.ba_request(m, kfs[2:], kfs[:2], np.array(sorted(m.points)))
    full = O.bundle_adjust(req, ctx.K, None, 10)
    graphs = []
    real = gtsam.LevenbergMarquardtOptimizer

    class Spy(real):  # type: ignore[misc,valid-type]
        def __init__(self, g, v, p):
            super().__init__(g, v, p)
            graphs.append((g, v, p))

    gtsam.LevenbergMarquardtOptimizer = Spy
    try:
        O.bundle_adjust(req, ctx.K, None, 10)
    finally:
        gtsam.LevenbergMarquardtOptimizer = real
    (g, v, p), = graphs
    ref = real(g, v, p).optimize()
    from gtsam.symbol_shorthand import L
    assert np.array_equal(full["pos"], np.array([np.asarray(ref.atPoint3(L(int(i)))) for i in req["pt_ids"]]))
    assert full["iterations"] > 2 and not full["stopped"]
    part = O.bundle_adjust(req, ctx.K, None, 10, stop=lambda: True)
    assert part["ok"] and part["stopped"] and part["iterations"] == 1
    truth_err = np.linalg.norm(full["pos"] - req["pos"], axis=1)
    assert 0 < np.median(np.linalg.norm(part["pos"] - full["pos"], axis=1)) < 0.5 * np.median(truth_err)


def test_bundle_adjustment_rejects_an_observation_whose_depth_disagrees():
    """RGB-D: a feature whose depth reads twice the point's (a depth edge, a hole filled wrongly) while its pixel is
    right is an outlier of the BA by the stereo factor's third coordinate (u_r, 3-dof chi-square 7.81, as
    ORB-SLAM2); the 2D reprojection alone passes it."""
    from simreal_nodes.vision.slam import optimize as O

    ctx = context("rgbd")
    kfs = four_keyframes(ctx)
    m = ctx.map
    k = kfs[2]
    fi = int(np.flatnonzero(k.mp >= 0)[7])
    pid = int(k.mp[fi])
    k.depth[fi] *= 2.0
    req = O.ba_request(m, kfs[2:], kfs[:2], np.array(sorted(m.points)))
    res = O.bundle_adjust(req, ctx.K, ctx.baseline, 10)
    assert (pid, k.id) in res["outliers"]
    assert len(res["outliers"]) < 5  # (the 2 cm noise of the points' start is no outlier)


def test_a_depth_camera_s_disparity_noise_weighs_its_depth_in_the_bundle_adjustment():
    """RGB-D with exact depth readings and pixels 1 px off (sigma): ORB-SLAM2's model (u_r as a measurement of its own
    at the level sigma, ``rgbd_disparity_sigma_px`` 0) lets the pixel noise move the points along their rays; a
    disparity sigma of 0.05 px (a structured-light camera's) keeps them on the depth they were read at."""

    errs = {}
    for sd in (0.0, 0.05):
        ctx = context("rgbd", rgbd_disparity_sigma_px=sd)
        kfs = four_keyframes(ctx)
        m = ctx.map
        rng = np.random.default_rng(3)
        for k in kfs:
            k.feats.und[:] += rng.normal(0.0, 1.0, k.feats.und.shape)
        LocalMapper(ctx, async_mapping=False).bundle_adjust(kfs, None)
        pid = np.array(sorted(i for i, p in m.points.items() if kfs[0].id in p.obs))
        assert len(pid) > 250
        Pc = m._pos[m.rows(pid)] @ kfs[0].T_cw[:3, :3].T + kfs[0].T_cw[:3, 3]  # in the held first keyframe's camera
        fi = np.array([m.points[int(i)].obs[kfs[0].id] for i in pid])
        errs[sd] = np.median(np.abs(Pc[:, 2] - kfs[0].depth[fi]))
    assert errs[0.05] < 0.3 * errs[0.0] and errs[0.05] < 0.003


def test_a_point_flagged_deformable_while_the_bundle_adjustment_ran_keeps_the_tracker_s_word():
    """Asynchronous mapping: the BA request holds a point rigid; before its result comes back the tracker flags the
    point deformable (it lies on the turning lever) and moves it to its estimate. The result neither moves it back
    nor, where the BA found it an outlier (its depth twice what it was), unlinks or erases it; the rigid points get
    the BA's positions. Stop 87: applied anyway, the live joint boot's lever points were erased as the lever
    turned, and the tracker lost every measurement on it."""
    from simreal_nodes.vision.slam import optimize as O

    ctx = context("rgbd")
    kfs = four_keyframes(ctx)
    m = ctx.map
    k = kfs[2]
    fis = np.flatnonzero(k.mp >= 0)
    fi, rigid = int(fis[7]), int(k.mp[fis[20]])
    pid = int(k.mp[fi])
    k.depth[fi] *= 2.0
    req = O.ba_request(m, kfs[2:], kfs[:2], np.array(sorted(m.points)))
    res = O.bundle_adjust(req, ctx.K, ctx.baseline, 10)
    assert (pid, k.id) in res["outliers"]  # what the result would do to it, had it stayed rigid
    P_tracker = m.points[pid].pos + np.array([0.0, 0.05, 0.0])
    m.points[pid].deformable = True
    m.points[pid].pos = P_tracker
    LocalMapper(ctx, async_mapping=False)._apply_ba(res, req)
    assert pid in m.points and k.id in m.points[pid].obs
    np.testing.assert_array_equal(m.points[pid].pos, P_tracker)
    j = int(np.flatnonzero(np.asarray(res["pt_ids"]) == rigid)[0])
    np.testing.assert_allclose(m.points[rigid].pos, res["pos"][j])


@pytest.mark.parametrize("interrupt", [True, False])
def test_a_waiting_keyframe_stops_the_running_asynchronous_bundle_adjustment(interrupt):
    """Asynchronous mapping: a second local BA asked for while the mapping process runs the first waits; with
    ``interrupt_ba`` it stops the first after its current iteration (ORB-SLAM2's abort flag), which is applied, and
    the waiting one then runs to its end."""
    import time

    ctx = context("mono", interrupt_ba=interrupt)
    kfs = four_keyframes(ctx)
    mapper = LocalMapper(ctx, async_mapping=True)
    try:
        mapper.bundle_adjust(kfs, None)
        mapper.bundle_adjust(kfs, None)  # the process is busy (it is still starting): deferred
        assert mapper.ba_stats["submitted"] == 1 and mapper.ba_stats["deferred"] == 1
        t0 = time.monotonic()
        while mapper.ba_stats["applied"] < 2 and time.monotonic() - t0 < 60:
            mapper.poll()
            time.sleep(0.01)
        assert mapper.ba_stats["applied"] == 2 and mapper.ba_stats["submitted"] == 2
        assert mapper.ba_stats["stopped"] == int(interrupt)  # the first if interrupted; never the second
    finally:
        mapper.close()


def test_fusion_with_depth_keeps_points_apart_across_a_depth_edge():
    """RGB-D keyframes: keyframe B's features lie where A's points project, with A's descriptors, but the first 100
    read twice the depth (a surface behind: a depth edge). ORB-SLAM2's Fuse tests the virtual right coordinate as
    well (3 dof): those 100 are not linked to A's points; the ones whose depth agrees are, and so are those with no
    depth reading (the 2D test alone)."""
    X, desc = scene(200, seed=7)
    ctx = context("rgbd")
    m = ctx.map
    T_b = G.make_T(G.rot_axis("y", np.deg2rad(0.5)), np.array([-0.05, 0.0, 0.0]))
    fa, ia, za = view(X, desc, np.eye(4))
    fb, ib, zb = view(X, desc, T_b)
    assert len(ia) == len(ib) == 200
    zb = zb.copy()
    zb[:100] *= 2.0
    zb[100:150] = np.nan
    A = m.new_keyframe(0, np.eye(4), fa, za)
    B = m.new_keyframe(1, G.inv(T_b), fb, zb)
    own = np.array([m.new_point(X[i], desc[i], A, k).id for k, i in enumerate(ia)])
    touched = LocalMapper(ctx, async_mapping=False)._fuse_into(B, own)
    assert np.all(B.mp[:100] == -1)
    assert np.array_equal(B.mp[100:], own[np.searchsorted(ia, ib[100:])])
    assert len(touched) == 100


@pytest.mark.parametrize("fuse,mode,runs", [("mono", "rgbd", 0), ("all", "rgbd", 1), ("mono", "mono", 1),
                                             ("none", "mono", 0)])
def test_fusion_runs_for_the_configured_modes(monkeypatch, fuse, mode, runs):
    """The default fuses monocular keyframes only (RGB-D's depth fixes its scale; there it is a knob)."""
    calls = []
    monkeypatch.setattr(LocalMapper, "_fuse_neighbours", lambda self, kf: calls.append(kf.id))
    ctx = context(mode, fuse_neighbours=fuse)
    X, desc = scene(100)
    f, _, z = view(X, desc, np.eye(4))
    kf = ctx.map.new_keyframe(0, np.eye(4), f, z if mode == "rgbd" else None)
    LocalMapper(ctx, async_mapping=False)._local_mapping(kf)
    assert len(calls) == runs


def test_a_pose_refined_in_the_camera_s_own_pixels():
    """``image_pose_lm`` (a fisheye's pose refinement in the SLAM and the markers): through a plumb_bob lens with
    equal weights it lands where OpenCV's ``solvePnPRefineLM`` does on the same distorted pixels; through a fisheye
    with a weight per point, on the weighted least-squares optimum of the fisheye's pixels (scipy's solver on the
    same cost); ``refine_pose`` with ``lens`` fits there (its result a fixed point of it), away from where the fit in
    ideal pixels goes."""
    import cv2
    from scipy.optimize import least_squares

    from simreal_nodes.vision.slam.optimize import image_pose_lm, refine_pose

    X, _ = scene(200, seed=5)
    rng = np.random.default_rng(5)
    T_true = G.make_T(G.exp_so3([0.02, -0.03, 0.01]), [0.05, -0.02, 0.1])
    T0 = G.make_T(G.exp_so3([0.03, -0.02, 0.0]), [0.08, 0.0, 0.05])
    r0, t0 = cv2.Rodrigues(T0[:3, :3])[0], T0[:3, 3].reshape(3, 1).copy()

    barrel = CameraModel(640, 480, CAM.K, [-0.2, 0.05, 0.001, -0.001, 0.0])
    uv = barrel.project(G.transform(T_true, X)) + rng.normal(0, 1.0, (len(X), 2))
    rvec, tvec = cv2.solvePnPRefineLM(X, uv, barrel.K, barrel.D, r0, t0,
                                      (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12))
    T_cv = G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
    np.testing.assert_allclose(image_pose_lm(T0, X, uv, np.ones(len(X)), barrel, 50, 1e-12), T_cv, atol=1e-7)

    fish = CameraModel(640, 480, [[300.0, 0, 320.0], [0, 300.0, 240.0], [0, 0, 1]], [-0.021, 0.0043, -0.0012, 0.0001],
                       "equidistant")
    px = fish.project(G.transform(T_true, X)) + rng.normal(0, 1.0, (len(X), 2))
    w = 1.0 / rng.uniform(1.0, 2.0, len(X)) ** 2  # pyramid levels' sigma^2

    def res(p):
        return ((fish.project(X @ cv2.Rodrigues(p[:3])[0].T + p[3:]) - px) * np.sqrt(w)[:, None]).ravel()

    best = least_squares(res, np.r_[r0.ravel(), t0.ravel()], xtol=1e-14, ftol=1e-14, gtol=1e-14).x
    T_ls = G.make_T(cv2.Rodrigues(best[:3])[0], best[3:])
    T_img = image_pose_lm(T0, X, px, w, fish, 50, 1e-12)
    np.testing.assert_allclose(T_img, T_ls, atol=1e-8)
    # OpenCV projects points behind a camera to mirrored pixels: a pose with any behind it is no solution
    behind = G.make_T(t=[0.0, 0.0, -10.0])
    np.testing.assert_array_equal(image_pose_lm(behind, X, px, w, fish, 50, 1e-12), behind)

    und = fish.undistort_points(px)
    sigma2 = (np.sqrt(1.0 / w) * fish.stretch(px)) ** 2 * 9  # * 9: every match an inlier
    T_r, inl = refine_pose(T0, X, und, sigma2, fish.K, lens=(fish, px, 1.0 / w))
    assert inl.all()
    np.testing.assert_allclose(T_r, image_pose_lm(T_r, X, px, w, fish, 50, 1e-12), atol=1e-7)
    T_u, _ = refine_pose(T0, X, und, sigma2, fish.K)  # in ideal pixels, all alike
    assert np.abs(T_u[:3, 3] - T_r[:3, 3]).max() > 1e-4


def test_keyframe_decision():
    """ORB-SLAM2's rule: not within 5 frames of the last keyframe; then when tracking clearly fewer points than the
    reference keyframe (RGB-D: also under 100), or after 30 frames; never on 15 inliers or fewer."""
    X, desc = scene()
    ctx = context()
    init = depth_map(ctx, X, desc)
    n_ref = len(ctx.map.points)
    ctx.frame_id = ctx.last_kf_frame + 4
    assert not init.mapper.need_keyframe(10)
    ctx.frame_id = ctx.last_kf_frame + 6
    assert not init.mapper.need_keyframe(n_ref)
    assert init.mapper.need_keyframe(int(0.5 * n_ref)) and init.mapper.need_keyframe(99)
    assert not init.mapper.need_keyframe(15)
    ctx.frame_id = ctx.last_kf_frame + 31
    assert init.mapper.need_keyframe(n_ref)


def test_tracking_loses_a_frame_of_unknown_points():
    X, desc = scene()
    ctx = context()
    depth_map(ctx, X, desc)
    other, desc2 = scene(seed=1)
    ctx.frame_id += 1
    res, fix = Tracker(ctx).track(view(other, desc2, np.eye(4))[0], {})
    assert res.state == LOST == ctx.state and fix is None and "pose inliers" in res.reason
    assert ctx.lost_since == ctx.frame_id and ctx.velocity is None


def test_relocalization_against_a_small_map():
    X, desc = scene()
    ctx = context()
    depth_map(ctx, X, desc)
    ctx.state, ctx.lost_since = LOST, ctx.frame_id
    reloc = Relocalizer(ctx, Tracker(ctx))
    T_cw1 = G.make_T(G.rot_axis("y", np.deg2rad(-4.0)), np.array([0.15, 0.05, -0.1]))
    f1, _, _ = view(X, desc, T_cw1)
    ctx.frame_id += 3
    res, fix = reloc.relocalize(f1, {})
    assert res.state == RELOCALIZED and res.reason == "relocalized after 3 frames"
    assert ctx.state == OK and ctx.velocity is None
    assert np.max(np.abs(fix.T_cw - T_cw1)) < 1e-6 and np.array_equal(ctx.T_cw_last, fix.T_cw)
    # a frame of unknown points stays lost; without a map, nothing to relocalize in
    other, desc2 = scene(seed=1)
    res, fix = reloc.relocalize(view(other, desc2, T_cw1)[0], {})
    assert res.state == LOST and fix is None and "relocalization found 0 inliers" in res.reason
    empty = context()
    res, _ = Relocalizer(empty, Tracker(empty)).relocalize(f1, {})
    assert res.state == NOT_STARTED == empty.state


def test_relocalization_makes_the_keyframe_it_sees_most_the_reference():
    """After a relocalization the next frame's local map is built around the reference keyframe: it must be where
    the camera is, not the last keyframe made (a circling camera relocalized half a turn later lost the very next
    frame, the local map being on the other side)."""
    X, desc = scene()
    ctx = context()
    init = Initializer(ctx, LocalMapper(ctx, async_mapping=False), None)
    ctx.frame_id = 1
    f0, _, z0 = view(X, desc, np.eye(4), sel=np.arange(200))
    init.initialize(f0, z0, 0)
    kf0 = ctx.ref_kf
    T_cw1 = G.make_T(t=np.array([-0.05, 0.0, 0.0]))
    f1, _, z1 = view(X, desc, T_cw1, sel=np.arange(200, 400))  # another part of the scene: new points only
    ctx.frame_id = 10
    kf1 = init.mapper.insert_keyframe(9, T_cw1, f1, z1, np.zeros((0, 2), np.int64), np.zeros(0, bool))
    assert ctx.ref_kf is kf1 and kf0 is not None and kf0 is not kf1
    ctx.state, ctx.lost_since = LOST, ctx.frame_id
    ctx.frame_id += 1
    res, fix = Relocalizer(ctx, Tracker(ctx)).relocalize(view(X, desc, np.eye(4), sel=np.arange(200))[0], {})
    assert res.state == RELOCALIZED and fix is not None
    assert ctx.ref_kf is kf0


def test_deformable_points_never_vote_for_the_pose():
    X, desc = scene()
    ctx = context()
    depth_map(ctx, X, desc)
    tracks = DeformableTracks(ctx)
    flagged = np.arange(0, 40)
    tracks.set_deformable(flagged)
    assert ctx.deformable == set(flagged.tolist()) and all(ctx.map.points[int(i)].deformable for i in flagged)
    local = Tracker(ctx).local_points()
    assert not np.isin(local, flagged).any() and len(local) == len(ctx.map.points) - len(flagged)


def test_young_object_points_are_culled_unless_linked_at_rest():
    """A point on a deforming object gains no keyframes (it never joins the pose's matches nor the fusion):
    the culling of young points erases it two keyframes on, which suits a point linked while the object was
    deformed (its link carries that moment's estimate error), and not one the tracker linked at rest (held)."""
    X, desc = scene()
    ctx = context()
    depth_map(ctx, X, desc)
    m = ctx.map
    mapper = LocalMapper(ctx, async_mapping=False)
    kf0 = max(m.keyframes.values(), key=lambda k: k.id)
    young = [m.new_point(X[i] + 0.001, desc[i], kf0, int(i)).id for i in range(60)]  # seen by one keyframe each
    mapper._recent_points = [(pid, kf0.id) for pid in young]
    ctx.deformable, ctx.held = set(young), set(young[:20])
    later = [m.new_keyframe(k, np.eye(4), Features.empty()) for k in (1, 2)]
    mapper._cull_points(later[-1])
    assert later[-1].id - kf0.id == 2
    assert all(pid in m.points for pid in young[:20])  # held
    assert not any(pid in m.points for pid in young[20:])  # linked while deformed: culled like any young point
    assert mapper._recent_points == []


def test_a_keyframe_makes_no_second_point_where_a_deformable_point_is_followed():
    """A followed deformable point is left out of the pose's matches, so its feature looks free to a new keyframe;
    within ``followed_px`` of where the point was measured no new point is made (it would be a copy)."""
    X, desc = scene()
    ctx = context(followed_px=3.0)
    init = depth_map(ctx, X, desc)
    obj, obj_desc = scene(60, seed=5)
    f, idx, z = view(obj * 0.4, obj_desc, np.eye(4))  # an object in front of the mapped scene, no point yet
    assert len(idx) == 60
    followed = f.uv[:25].astype(np.float64) + np.array([1.5, -1.0])  # measured 1.8 px from the features
    ctx.frame_id += 1
    n0 = len(ctx.map.points)
    kf = init.mapper.insert_keyframe(1, np.eye(4), f, z, np.zeros((0, 2), np.int64), np.zeros(0, bool),
                                     followed=followed)
    assert len(ctx.map.points) - n0 == 35
    assert np.all(kf.mp[:25] < 0) and np.all(kf.mp[25:] >= 0)


def test_deformable_tracks_reacquire_by_descriptor_and_widely_after_a_gap():
    X, desc = scene()
    ctx = context(reacquire_below=8, reacquire_wide_px=80.0, deformable_radius=20.0)
    depth_map(ctx, X, desc)
    tracks = DeformableTracks(ctx)
    ids = np.arange(0, 30)
    moved = X[ids] + np.array([0.02, 0.0, 0.0])  # the object deformed 2 cm sideways: predicted there
    tracks.set_deformable(ids, moved)
    gray = np.zeros((480, 640), np.uint8)

    def frame(frame_id: int, shift_px: float) -> tuple[TrackResult, list[int]]:
        """The object's features where the prediction puts them (moved ``shift_px``), nothing else matched; the
        result and the points in the image."""
        ctx.frame_id = frame_id
        tracks.new_frame(gray)
        pts = X.copy()
        pts[ids] = moved
        f, idx, _ = view(pts, desc, np.eye(4), sel=ids, shift_px=shift_px)
        res = TrackResult(OK)
        tracks.observe(f, np.eye(4), res, exclude=np.zeros(0, np.int64))
        return res, idx.tolist()

    res, seen = frame(10, 0.0)  # first frame: no flow yet, every point is re-acquired at its predicted pixel
    assert seen == ids.tolist() and sorted(res.obs_ids.tolist()) == seen and not res.obs_inlier.any()
    assert tracks.sources == dict.fromkeys(seen, "descriptor")
    expect = CAM.project(moved)[np.argsort(ids)]
    assert np.allclose(res.obs_uv[np.argsort(res.obs_ids)], expect, atol=1e-4)
    assert np.allclose(res.obs_pos, X[res.obs_ids])  # with their rest positions
    # a long gap (no flow) and 50 px away: only the wide radius finds them, the points having been followed
    res, seen = frame(20, 50.0)
    assert len(seen) > 20 and sorted(res.obs_ids.tolist()) == seen
    ctx.config = SlamConfig(reacquire_below=8, reacquire_wide_px=20.0, deformable_radius=20.0)
    tracks.drop_tracks(ids)
    res, seen = frame(30, 50.0)
    assert len(seen) > 20 and len(res.obs_ids) == 0  # the same gap without the wide radius loses them
    assert tracks.sources == {}


def test_deformable_reacquisition_radius_is_in_a_fisheye_s_own_pixels():
    """The re-acquisition radius (``deformable_radius``, 20 px) means image pixels: through a fisheye, object points
    50-60 degrees off the axis (the ideal image stretched 2-4 times there) whose features lie 15 image pixels from
    the prediction are re-acquired, those 25 image pixels away are not; in ideal pixels (stop 100) the nearer ones
    were 30-60 pixels off and lost."""
    fish = CameraModel(640, 480, [[300.0, 0, 319.5], [0, 300.0, 239.5], [0, 0, 1]],
                       [-0.021, 0.0043, -0.0012, 0.0001], "equidistant")
    rng = np.random.default_rng(7)
    n = 120  # (an RGB-D map starts from 100 features with depth)
    # left and right of the centre (the image's wide side), within 20 degrees of its horizontal
    ang, phi = np.radians(rng.uniform(50, 60, n)), np.radians(rng.uniform(-20, 20, n) + 180 * (np.arange(n) % 2))
    rays = np.c_[np.sin(ang) * np.cos(phi), np.sin(ang) * np.sin(phi), np.cos(ang)]
    X = rays / rays[:, 2:] * rng.uniform(2.0, 4.0, (n, 1))  # z 2-4 m
    desc = rng.integers(0, 256, (n, 32), dtype=np.uint8)
    px = fish.project(X)
    assert np.all((px > 0) & (px < [639, 479]))

    def features(shift_px: float) -> Features:
        """The points' features moved ``shift_px`` image pixels radially (away from the image's centre)."""
        out = px + shift_px * (px - [319.5, 239.5]) / np.linalg.norm(px - [319.5, 239.5], axis=1, keepdims=True)
        return Features(out.astype(np.float32), fish.undistort_points(out), np.zeros(n, np.int32), desc,
                        np.ones(n, np.float32), 1.2, fish.stretch(out))

    found = {}
    for shift in (15.0, 25.0):
        ctx = SlamContext(fish, fish.K.copy(), "rgbd", 0.08,
                          SlamConfig(reacquire_below=8, reacquire_wide_px=20.0, deformable_radius=20.0))
        init = Initializer(ctx, LocalMapper(ctx, async_mapping=False), None)
        ctx.frame_id += 1
        assert init.initialize(features(0.0), X[:, 2], 0).state == OK
        tracks = DeformableTracks(ctx)
        ids = np.array(sorted(ctx.map.points))
        tracks.set_deformable(ids, ctx.map._pos[ctx.map.rows(ids)])
        ctx.frame_id = 10
        tracks.new_frame(np.zeros((480, 640), np.uint8))
        f = features(shift)
        ideal_off = np.linalg.norm(f.und - fish.undistort_points(px), axis=1)
        res = TrackResult(OK)
        tracks.observe(f, np.eye(4), res, exclude=np.zeros(0, np.int64))
        found[shift] = (len(ids), len(res.obs_ids), float(np.median(ideal_off)))
    assert found[15.0][0] == n and found[15.0][1] == n and found[15.0][2] > 30, found
    assert found[25.0][1] == 0, found


def test_deformable_descriptors_of_erased_points_are_forgotten():
    """The object's points are culled and made anew all the time (new ids, never reused): the last descriptor of each
    one measured is kept for its re-acquisition, and those of erased points must go while the map's size holds, or
    the store grows frame after frame (until stop 92 it was pruned only past twice the map's points)."""
    X, desc = scene()
    ctx = context()
    depth_map(ctx, X, desc)
    m = ctx.map
    tracks = DeformableTracks(ctx)
    gray = np.zeros((480, 640), np.uint8)
    rows = np.arange(0, 30)
    pid_of_row = np.arange(len(X))
    sizes, found = [], []
    for r in range(40):
        ctx.frame_id = 10 * (r + 1)  # frames apart: no flow, every point re-acquired by its descriptor
        for row in rows:  # the object's points culled and mapped again: the map keeps its size
            m.erase_point(int(pid_of_row[row]))
            pid_of_row[row] = m.new_point(X[row], desc[row]).id
        tracks.set_deformable(pid_of_row[rows], X[rows])
        tracks.new_frame(gray)
        f, _, _ = view(X, desc, np.eye(4), sel=rows)
        res = TrackResult(OK)
        tracks.observe(f, np.eye(4), res, exclude=np.zeros(0, np.int64))
        found.append(len(res.obs_ids))
        sizes.append(len(tracks._last_desc))
        assert {int(i) for i in pid_of_row[rows]} <= set(tracks._last_desc)  # a prune keeps the live points' ones
    assert len(m.points) == len(X) and found == [len(rows)] * 40
    # 30 new entries a frame: 1 200 in all, over twice the map's 400 points; kept to the live ones and a margin
    assert max(sizes) <= 2 * len(rows) + 256 + len(rows)


def test_deformable_tracks_follow_the_image_by_flow_from_the_previous_frame():
    """A point measured in the previous frame is followed by Lucas-Kanade on the images (not by its descriptor):
    the texture moved 3 px right and 2 px down, the features (and the prediction) stayed: the flow finds it moved."""
    import cv2

    X, desc = scene()
    ctx = context()
    depth_map(ctx, X, desc)
    tracks = DeformableTracks(ctx)
    ids = np.arange(0, 30)
    tracks.set_deformable(ids, X[ids])
    rng = np.random.default_rng(3)
    tex = cv2.GaussianBlur((rng.random((480, 640)) * 255).astype(np.uint8), (0, 0), 1.5)
    f, idx, _ = view(X, desc, np.eye(4), sel=ids)
    inside = [int(i) for i, q in zip(idx, f.uv) if 20 < q[0] < 620 and 20 < q[1] < 460]
    results = []
    for frame_id, gray in ((1, tex), (2, np.roll(tex, (2, 3), axis=(0, 1)))):
        ctx.frame_id = frame_id
        tracks.new_frame(gray)
        res = TrackResult(OK)
        tracks.observe(f, np.eye(4), res, exclude=np.zeros(0, np.int64))
        results.append(dict(zip(res.obs_ids.tolist(), res.obs_uv)))
    assert all(tracks.sources.get(i) == "flow" for i in inside) and len(inside) > 20
    moved = np.array([results[1][i] - results[0][i] for i in inside])
    assert np.allclose(moved, [3.0, 2.0], atol=0.2)


def test_deformable_measurements_moving_unlike_their_neighbours_are_dropped():
    """``coherence_px``: a lagging prediction offsets a region's measurements alike (all kept, 13 px off their
    predictions); a match on another feature moves unlike its neighbours (dropped); a point with too few
    neighbours is kept whatever its offset."""
    ctx = context(coherence_px=4.0, coherence_radius_px=40.0, coherence_min=3)
    tracks = DeformableTracks(ctx)
    g = np.stack(np.meshgrid(np.arange(6) * 15.0, np.arange(6) * 15.0), -1).reshape(-1, 2) + 100.0
    pred = {i: q for i, q in enumerate(g)}
    pred[99] = np.array([500.0, 400.0])  # alone, far from the others
    lag = np.array([12.0, -5.0])
    found = {i: q + lag for i, q in pred.items()}
    tracks.sources = dict.fromkeys(found, "flow")
    tracks._coherent(found, pred)
    assert sorted(found) == sorted(pred)  # a uniform lag: nothing dropped
    wrong = [7, 20, 33]
    for i in wrong:
        found[i] = found[i] + np.array([0.0, 9.0])  # re-acquired on a feature 9 px off
    found[99] = found[99] + 30.0
    tracks._coherent(found, pred)
    assert sorted(found) == sorted(set(pred) - set(wrong)) and not set(wrong) & set(tracks.sources)


def _reacquire_one_by_one(tracks, f, kp_idx, ids_a, D, uv, has_pred, todo, radius):
    """The re-acquisition as it was written until stop 96: a search and a descriptor comparison per point."""
    from scipy.spatial import cKDTree

    from simreal_nodes.vision.orb import hamming

    tree, out = cKDTree(f.und[kp_idx]), {}
    for k in todo:
        pid = int(ids_a[k])
        centres = [uv[k]] if (has_pred[k] or pid not in tracks._last_seen) else []
        if pid in tracks._last_seen:
            centres.append(tracks._last_seen[pid])
        near: set[int] = set()
        for q in centres:
            if np.all(np.isfinite(q)):
                near.update(tree.query_ball_point(q, radius))
        if not near:
            continue
        c = kp_idx[np.fromiter(near, np.int64)]
        d = hamming(np.repeat(D[k][None], len(c), axis=0), f.desc[c])
        last = tracks._last_desc.get(pid)
        if last is not None:
            d = np.minimum(d, hamming(np.repeat(last[None], len(c), axis=0), f.desc[c]))
        j = int(np.argmin(d))
        if d[j] <= 50:
            out[pid] = int(c[j])
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_deformable_reacquisition_in_one_batch_makes_the_matches_of_a_search_per_point(seed):
    """``DeformableTracks._reacquire`` (one tree query, one batch of distances) against the search per point it
    replaced: the same point -> feature matches, ties included (descriptors a few bits apart, so that many
    candidates tie at the least distance), with predictions, last observations, a last descriptor, points with no
    finite centre and points with no candidate."""
    rng = np.random.default_rng(seed)
    n_kp, n_pts, n_base = 1500, 150, 3
    base = rng.integers(0, 256, (n_base, 32), dtype=np.uint8)  # few distinct descriptors: many ties

    def near_copy(rows):
        out = base[rows].copy()
        flip = rng.integers(0, 32, (len(rows), 3))
        for r, cols in enumerate(flip):
            out[r, cols] ^= np.uint8(1 << int(rng.integers(8)))
        return out

    uv_kp = rng.uniform(0, 640, (n_kp, 2))
    f = Features(uv_kp.astype(np.float32), uv_kp, np.zeros(n_kp, np.int32), near_copy(rng.integers(0, n_base, n_kp)),
                 np.ones(n_kp, np.float32), 1.2)
    tracks = DeformableTracks(context())
    ids_a = np.arange(1000, 1000 + n_pts)
    D = near_copy(rng.integers(0, n_base, n_pts))
    uv = rng.uniform(-20, 660, (n_pts, 2))
    uv[rng.random(n_pts) < 0.1] = np.nan  # no finite prediction
    has_pred = rng.random(n_pts) < 0.6
    for k in np.flatnonzero(rng.random(n_pts) < 0.5):
        tracks._last_seen[int(ids_a[k])] = uv[k] + rng.normal(0, 8, 2) if rng.random() < 0.9 else np.full(2, np.nan)
    for k in np.flatnonzero(rng.random(n_pts) < 0.3):
        tracks._last_desc[int(ids_a[k])] = near_copy([int(rng.integers(n_base))])[0]
    kp_idx = np.flatnonzero(rng.random(n_kp) < 0.8)
    todo = [int(k) for k in np.flatnonzero(rng.random(n_pts) < 0.9)]
    for radius in (6.0, 20.0, 80.0):
        got = tracks._reacquire(f, kp_idx, ids_a, D, uv, has_pred, todo, radius)
        want = _reacquire_one_by_one(tracks, f, kp_idx, ids_a, D, uv, has_pred, todo, radius)
        assert list(got.items()) == list(want.items()) and len(want) > (5 if radius < 10 else 50)  # order too
    assert tracks._reacquire(f, kp_idx, ids_a, D, uv, has_pred, [], 20.0) == {}
    # the 50-bit bound, both sides of it
    one = DeformableTracks(context())
    desc = np.zeros((2, 32), np.uint8)
    desc[0, :6], desc[0, 6] = 255, 3  # 50 bits set
    desc[1, :6], desc[1, 6] = 255, 7  # 51
    for j, want in ((0, {7: 0}), (1, {})):
        g = Features(np.full((1, 2), 100, np.float32), np.full((1, 2), 100.0), np.zeros(1, np.int32), desc[j:j + 1],
                     np.ones(1, np.float32), 1.2)
        assert one._reacquire(g, np.arange(1), np.array([7]), np.zeros((1, 32), np.uint8), np.full((1, 2), 101.0),
                              np.ones(1, bool), [0], 20.0) == want


def test_config_defaults_are_documented_and_checked():
    src = inspect.getsource(SlamConfig)
    for f in dataclasses.fields(SlamConfig):
        line = next(ln for ln in src.splitlines() if ln.strip().startswith(f"{f.name}:"))
        assert "#" in line and len(line.split("#", 1)[1].strip()) > 10, f"{f.name} has no comment"
    c = SlamConfig()
    assert c.min_parallax == pytest.approx(np.deg2rad(1.0)) and c.flow_anchor_px == 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.flow_win = 21  # type: ignore[misc]
    with pytest.raises(ValueError, match="reacquire_wide_px"):
        SlamConfig(reacquire_wide_px=-1.0)
    with pytest.raises(ValueError, match="flow_win"):
        SlamConfig(flow_win=1)
    with pytest.raises(ValueError, match="two_view_model"):
        SlamConfig(two_view_model="affine")
    with pytest.raises(ValueError, match="homography_ambiguity"):
        SlamConfig(homography_ambiguity="most")
    with pytest.raises(ValueError, match="fuse_neighbours"):
        SlamConfig(fuse_neighbours="yes")


def ba_problem(n_pts: int, n_kf: int = 10, seed: int = 0) -> tuple[np.ndarray, dict]:
    """A monocular BA request (:func:`~simreal_nodes.vision.slam.optimize.ba_request`'s layout): ``n_kf`` cameras
    10 cm apart along x, every point seen by each, positions 2 cm and pixels 0.5 px off."""
    rng = np.random.default_rng(seed)
    K = CAM.K
    poses = np.repeat(np.eye(4)[None], n_kf, axis=0)
    poses[:, 0, 3] = 0.1 * np.arange(n_kf)
    P = np.c_[rng.uniform(-2, 3, n_pts), rng.uniform(-1, 1, n_pts), rng.uniform(3, 5, n_pts)]
    obs_p, obs_k = np.repeat(np.arange(n_pts), n_kf), np.tile(np.arange(n_kf), n_pts)
    x = P[obs_p] - poses[obs_k, :3, 3]
    uv = np.c_[K[0, 0] * x[:, 0] / x[:, 2] + K[0, 2], K[1, 1] * x[:, 1] / x[:, 2] + K[1, 2]]
    n = len(obs_p)
    return K, {"kf_ids": np.arange(n_kf), "poses": poses, "fixed": np.arange(n_kf) < 2, "pt_ids": np.arange(n_pts),
               "pos": P + rng.normal(0, 0.02, P.shape), "obs_p": obs_p, "obs_k": obs_k,
               "uv": uv + rng.normal(0, 0.5, (n, 2)), "z": np.full(n, np.nan), "sigma": np.ones(n)}


def test_closing_the_mapping_process_does_not_wait_for_its_bundle_adjustment():
    """Slam.reset / close (a map loaded, a node's shutdown) end the mapping process while a BA may be in flight: the
    close kills it at once rather than wait for a result it would drop (stop 93's note: up to 2 s). The BA's own
    time, measured in this process on the same request, is the yardstick (no fixed time bound)."""
    import time

    from simreal_nodes.vision.slam.optimize import AsyncBundleAdjuster, bundle_adjust

    K, req = ba_problem(6000)
    t0 = time.perf_counter()
    bundle_adjust(req, K, None, 10)
    ba_s = time.perf_counter() - t0
    ba = AsyncBundleAdjuster(K, None, 10)
    # the request (several MB) fills the pipe: submit returns once the worker, its imports done, is reading it, so
    # the BA is in flight when the close comes
    assert ba.submit(req)
    t0 = time.perf_counter()
    ba.close()
    close_s = time.perf_counter() - t0
    assert not ba.proc.is_alive()
    assert close_s < 0.25 * ba_s, (close_s, ba_s)
    idle = AsyncBundleAdjuster(K, None, 10)  # an idle one is told to end, and does so by itself
    idle.close(timeout=60)  # its imports may still run on a busy host: the end waits for them
    assert idle.proc.exitcode == 0


def test_close_points_follow_orb_slam2_s_rule_and_the_cap_keeps_the_nearest():
    """``close_points``: every free feature nearer than the close depth, and beyond it on until more than 100
    features (held or new) are counted, the feature the walk stops on included (ORB-SLAM2's CreateNewKeyFrame);
    with a cap (a knob; stop 123's default, 250), the cap's nearest free features."""
    rng = np.random.default_rng(3)
    depth = np.r_[rng.uniform(0.4, 3.0, 300), rng.uniform(3.2, 6.0, 200), [np.nan] * 20]
    held = np.zeros(len(depth), bool)
    held[:40] = True  # 40 near features already hold points
    free = ~held
    got = close_points(depth, free, held, 0, 3.1)
    assert sorted(got.tolist()) == list(range(40, 300)) + [int(np.flatnonzero(depth == depth[300:500].min())[0])]
    assert np.all(np.diff(depth[got]) >= 0)  # nearest first
    # few near features: the walk goes on past the close depth until 101 are counted
    far = np.r_[rng.uniform(0.4, 3.0, 30), rng.uniform(3.2, 6.0, 200)]
    got = close_points(far, np.ones(230, bool), np.zeros(230, bool), 0, 3.1)
    assert len(got) == 101 and set(range(30)) <= set(got.tolist())
    assert np.all(far[got] <= np.sort(far)[100])
    # the cap: the nearest free ones, held features neither made nor counted
    got = close_points(depth, free, held, 250, 3.1)
    assert len(got) == 250 and set(got.tolist()) <= set(range(40, 300))
    assert depth[got].max() <= np.sort(depth[40:300])[249]
    assert len(close_points(np.full(5, np.nan), np.ones(5, bool), np.zeros(5, bool), 0, 3.1)) == 0


@pytest.mark.parametrize("cap", [0, 250])
def test_a_near_object_does_not_take_a_keyframe_s_every_new_point(cap):
    """A deforming object close to the camera (300 features at 0.4-0.6 m) in front of the static scene (400 at 1.5-3
    m): ORB-SLAM2's rule (cap 0, the default) gives the background its points as well; a cap of the 250 nearest
    (stop 123's default) puts every new point on the object, whose points the culling then erases, and the static
    map starves (held-out boot 1083 lost the camera for 46 % of its frames)."""
    ctx = context(keyframe_depth_points=cap)
    rng = np.random.default_rng(7)
    near = CAM.backproject(np.c_[rng.uniform(200, 440, 300), rng.uniform(150, 330, 300)], rng.uniform(0.4, 0.6, 300))
    back = CAM.backproject(np.c_[rng.uniform(20, 620, 400), rng.uniform(20, 460, 400)], rng.uniform(1.5, 3.0, 400))
    X = np.r_[near, back]
    desc = rng.integers(0, 256, (len(X), 32), dtype=np.uint8)
    f, idx, z = view(X, desc, np.eye(4))
    mapper = LocalMapper(ctx, async_mapping=False)
    ctx.frame_id += 1
    kf = mapper.insert_keyframe(1, np.eye(4), f, z, np.zeros((0, 2), np.int64), np.zeros(0, bool))
    on_background = int(np.sum((kf.mp >= 0) & (idx >= 300)))
    if cap:
        assert (int(np.sum(kf.mp >= 0)), on_background) == (250, 0)
    else:
        assert int(np.sum(kf.mp >= 0)) == len(idx) and on_background == int(np.sum(idx >= 300)) > 350


def test_the_default_keyframe_points_follow_orb_slam2_s_rule():
    """The default is ORB-SLAM2's rule (stop 124; ``keyframe_depth_points`` 0): it mended held-out boot 1083 and
    lowered the camera's error on the development beams and boots (stops 123, 124). It put the thesis's boot in a
    starved graph 3.2 degrees off against 1.0 until a frame that cannot pin the lever no longer moved alpha_z (stop
    124, ``DeformableTracker._conclude``)."""
    assert SlamConfig().keyframe_depth_points == 0
