"""``anchor: registration`` on RGB-D (§4.5.3): a family scene's first depth images place its beam from a guess by
eye to about a millimetre; a fit that does not hold is refused; the guess decides between a beam and its mirror
image; the object trackers wait for the registration and then track from the registered pose."""

import copy
import time
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.objects import ObjectTrackers
from simreal_nodes.assimilation.registration import (
    DepthViews,
    Registration,
    RegistrationConfig,
    RegistrationError,
    SlideRefused,
    _Centres,
    _facing,
    _judged,
    _pin_slide,
    _polished,
    _slide_cover,
    _weak_axis,
    depth_cloud,
    icp_point_to_plane,
    register_loaded,
    register_rgbd,
    sample_surface,
)
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.states import EstimateState
from simreal_nodes.synth.sequence import sequence

CFG = RegistrationConfig(stride=1)  # 320x240: every pixel, as many points as every other one at 640x480
VIEWS = (0, 4, 8)


def test_depth_cloud_within_a_box_keeps_every_point_of_the_box():
    """``depth_cloud(..., within=corners)`` back-projects only the pixels that may hold a point of the box: the points
    in the box are exactly those of the whole cloud (same values, same order). Each depth image shows the box itself
    (its faces just inside the corners given, so that points lie at its nearest corner and along its outline) before
    a random background, through a strongly distorted lens (the bounds are taken on the undistorted pixels), with and
    without skew in K, at strides 1 to 3, for boxes inside the view, across its edge and reaching behind the camera; a
    box in view that fills under 40 % of it leaves out most of the image."""
    from simreal_nodes.assimilation.registration import _pixel_grid
    from simreal_nodes.camera import CameraModel

    rng = np.random.default_rng(1)
    D = [0.25, -0.3, 0.004, -0.003, 0.1]
    plain = CameraModel.from_intrinsics(128, 96, 100.0, 102.0, 63.5, 47.5, D=D)
    skewed = CameraModel(128, 96, np.array([[100.0, 6.0, 63.5], [0.0, 102.0, 47.5], [0.0, 0.0, 1.0]]), np.array(D))
    T_wc = G.make_T(G.rot_axis("y", 0.4) @ G.rot_axis("x", -0.2), [0.3, 0.1, -0.2])
    in_view = 0
    for i in range(60):
        cam, stride = (plain, skewed)[i // 3 % 2], 1 + i % 3
        rays = cam.backproject(_pixel_grid(cam, (96, 128), 1), np.ones(96 * 128))  # camera frame, z = 1
        T_co = G.make_T(G.rot_axis("z", rng.uniform(-np.pi, np.pi)) @ G.rot_axis("x", rng.uniform(-1, 1)),
                        [rng.uniform(-0.8, 0.8), rng.uniform(-0.6, 0.6), rng.uniform(-0.3, 2.0)])
        half = rng.uniform(0.05, 0.5, 3)
        # the box's faces at 0.999 of its half sizes: where each pixel's ray first meets them (slabs)
        o, d = G.transform(G.inv(T_co), np.zeros(3)), rays @ G.inv(T_co)[:3, :3].T
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (-0.999 * half - o) / d, (0.999 * half - o) / d
        near, far = np.minimum(t1, t2).max(axis=1), np.maximum(t1, t2).min(axis=1)
        t = np.where(near > 0, near, far)
        depth = rng.uniform(0.3, 2.5, 96 * 128)
        hit = (near <= far) & (t > 0.05)
        depth[hit] = t[hit]
        depth = depth.reshape(96, 128)
        depth[rng.random(depth.shape) < 0.05] = np.nan
        T_mo = T_wc @ T_co
        corners = G.transform(T_mo, np.array([[(-1) ** (j >> a & 1) for a in range(3)] for j in range(8)]) * half)
        full = depth_cloud(cam, depth, T_wc, stride=stride)
        part = depth_cloud(cam, depth, T_wc, stride=stride, within=corners)

        def inside(P, T_mo=T_mo, half=half):
            return P[np.all(np.abs(G.transform(G.inv(T_mo), P)) < half, axis=1)]

        np.testing.assert_array_equal(inside(part), inside(full))
        seen = len(inside(full))
        if np.all(T_co[2, 3] - np.abs(T_co[2, :3]) @ half > 0.1) and 200 / stride ** 2 < seen < 0.4 * len(full):
            in_view += 1
            assert len(part) < 0.8 * len(full)
    assert in_view >= 8


def test_depth_cloud_undoes_the_lens():
    """Each point of a depth image back-projected through a distorted lens projects (lens applied) onto its own
    pixel at its own depth; the undistorted pixel grid is kept per camera, so a camera with another lens gives
    other points."""
    from simreal_nodes.camera import CameraModel

    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 3.0, (48, 64))
    depth[rng.random(depth.shape) < 0.2] = np.nan
    depth[0, 2] = 0.0
    T_wc = G.make_T(G.rot_axis("x", 0.3), [0.1, -0.2, 0.5])
    clouds = []
    for D in ([0.1, -0.2, 0.001, 0.002, 0.05], [-0.05, 0.01, 0.0, -0.001, 0.0]):
        cam = CameraModel.from_intrinsics(64, 48, 52.0, 53.0, 31.5, 24.2, D=D)
        P = depth_cloud(cam, depth, T_wc, stride=2)
        v, u = np.mgrid[0:48:2, 0:64:2]
        z = depth[v, u].ravel()
        ok = np.isfinite(z) & (z > 0)
        assert len(P) == ok.sum()
        Pc = G.transform(G.inv(T_wc), P)
        np.testing.assert_allclose(Pc[:, 2], z[ok], atol=1e-9)
        np.testing.assert_allclose(cam.project(Pc), np.c_[u.ravel(), v.ravel()][ok], atol=1e-4)
        clouds.append(P)
    assert np.abs(clouds[0] - clouds[1]).max() > 1e-3


@pytest.fixture(scope="module")
def scene3():
    seq = sequence("family-3", 320, 240, fps=15.0, ssaa=1, frames=9)
    sc = seq["scene"]
    doc = sc.scene_yaml(sc)
    cloud = np.vstack([depth_cloud(seq["cam"], seq["depth"][i], seq["T"][i], CFG.stride) for i in VIEWS])
    cams = np.array([seq["T"][i][:3, 3] for i in VIEWS])
    return {"seq": seq, "doc": doc, "model": sc.state["models"]["beam"], "cloud": cloud, "cams": cams,
            "truth": seq["truth"][0].object_poses["beam"],
            "guess": G.pose7_to_matrix(doc["objects"][0]["anchor"]["guess"])}


def _without_ends(s) -> np.ndarray:
    """The scene's fused cloud without the beam's last 5 cm at either end (measured in the true pose): nothing in it
    pins the beam along its axis."""
    m = s["model"]
    P_obj = (s["cloud"] - s["truth"][:3, 3]) @ s["truth"][:3, :3]
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    beam = np.all((P_obj > lo - 0.01) & (P_obj < hi + 0.01), axis=1)
    ends = (P_obj[:, 0] < lo[0] + 0.05) | (P_obj[:, 0] > hi[0] - 0.05)
    out: np.ndarray = s["cloud"][~(beam & ends)]
    return out


def _error(T, T_true):
    D = G.inv(T_true) @ T
    return 1e3 * np.linalg.norm(D[:3, 3]), np.rad2deg(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1)))


def test_registration_places_the_beam_from_a_rough_guess(scene3):
    s = scene3
    assert _error(s["guess"], s["truth"])[0] > 20  # the scene file's guess is centimetres off
    reg = register_rgbd(s["cloud"], s["model"], s["guess"], s["cams"], CFG)
    mm, deg = _error(reg.T_map_obj, s["truth"])
    assert mm < 2.0 and deg < 0.5, (mm, deg)
    assert reg.fitness > 0.9 and reg.rmse < 0.003 and reg.plane is not None
    assert reg.doubt == "" and reg.noise < CFG.max_noise, reg.noise


def test_a_fit_on_very_noisy_depth_is_kept_but_doubted_and_its_estimates_flagged(scene3):
    """Depth noise of 20 mm at 1 m (growing with z^2; benchmarks/depth_quality.py): the fit's own residual cannot
    see it (inliers within 6 mm), the scatter about the fit does; the registration is kept and doubted, and an
    estimate that would be OK is reported low-confidence with the doubt as its reason."""

    from simreal_nodes.assimilation.tracker import Estimate

    s, seq = scene3, scene3["seq"]
    rng = np.random.default_rng(5)
    noisy = [seq["depth"][i] + rng.normal(0, 1, seq["depth"][i].shape).astype(np.float32) * 0.02
             * seq["depth"][i] ** 2 for i in VIEWS]
    cloud = np.vstack([depth_cloud(seq["cam"], d, seq["T"][i], CFG.stride) for d, i in zip(noisy, VIEWS)])
    reg = register_rgbd(cloud, s["model"], s["guess"], s["cams"], CFG)
    assert reg.rmse < CFG.max_rmse  # the old check passes it
    assert reg.noise > CFG.max_noise and reg.doubt.startswith("registered on noisy depth"), reg.noise
    scene = build_spec_models(validate_scene(copy.deepcopy(s["doc"]), "family_3", "."))
    objs = ObjectTrackers(scene["objects"], {"beam": s["model"]}, registration=CFG)
    objs.set_camera(seq["cam"])
    objs.registrations["beam"] = reg
    tr = objs._tracker(scene["objects"][0])
    why = {EstimateState.OK: "", EstimateState.LOW_CONFIDENCE: "its own doubt", EstimateState.LOST: "lost"}
    for state, reason in why.items():
        ok = Estimate(tr.names, tr.units, tr.values.copy(), tr.frozen.copy(), np.zeros((1, 1)), state=state,
                      reason=reason)
        tr.update = lambda *a, ok=ok, **k: replace(ok)  # the tracker's own judgement, as it would give it
        est = objs.update(seq["T"][8])["beam"]
        if state == EstimateState.OK:
            assert est.state == EstimateState.LOW_CONFIDENCE and est.reason == reg.doubt
        elif state == EstimateState.LOW_CONFIDENCE:  # both doubts said, the registration's first
            assert est.state == state and est.reason == f"{reg.doubt}; its own doubt", est.reason
        else:
            assert est.state == EstimateState.LOST and est.reason == "lost"


def test_a_fit_without_the_object_is_refused(scene3):
    s = scene3
    P_obj = (s["cloud"] - s["truth"][:3, 3]) @ s["truth"][:3, :3]
    lo, hi = s["model"].points.min(axis=0) - 0.01, s["model"].points.max(axis=0) + 0.01
    away = ~np.all((P_obj > lo) & (P_obj < hi), axis=1)  # the beam is gone: supports, floor and clutter remain
    with pytest.raises(RegistrationError, match="registration"):
        register_rgbd(s["cloud"][away], s["model"], s["guess"], s["cams"], CFG)


def test_the_guess_decides_between_the_beam_and_its_mirror_image(scene3):
    s = scene3
    c = s["model"].points.mean(axis=0)
    flip = G.make_T(t=c) @ G.make_T(G.rot_axis("z", np.pi)) @ G.make_T(t=-c)  # end for end about the centre
    T_mirror = s["truth"] @ flip
    guess = T_mirror @ G.make_T(G.rot_axis("z", np.deg2rad(8.0)), [0.02, -0.015, 0.01])
    reg = register_rgbd(s["cloud"], s["model"], guess, s["cams"], CFG)
    mm, deg = _error(reg.T_map_obj, T_mirror)
    assert mm < 3.0 and deg < 1.0, (mm, deg)  # the box fits as well turned end for end: the guess picked it
    assert _error(reg.T_map_obj, s["truth"])[1] > 170


def test_object_trackers_wait_for_the_registration_then_track_from_it(scene3):
    s, seq = scene3, scene3["seq"]
    scene = build_spec_models(validate_scene(copy.deepcopy(s["doc"]), "family_3", "."))
    objs = ObjectTrackers(scene["objects"], {"beam": s["model"]}, registration=CFG)
    objs.set_camera(seq["cam"])
    assert objs.update(None)["beam"].reason == "waiting for registration: no camera pose yet"
    assert objs.needs_depth
    for i in range(9):
        est = objs.update(seq["T"][i], depth=seq["depth"][i])["beam"]
        if i < 8:
            assert est.state == EstimateState.LOST and est.reason.startswith("waiting for registration")
    mm, deg = _error(objs.registrations["beam"].T_map_obj, s["truth"])
    assert mm < 2.0 and deg < 0.5
    assert np.allclose(objs.trackers["beam"].T_map_obj, objs.registrations["beam"].T_map_obj)
    assert est.reason != "" and not est.reason.startswith("waiting")  # tracked now (no map points given here)
    assert objs.needs_depth  # placed; the dense tracker still waits for its reference view (image and depth)
    bgr = np.ascontiguousarray(seq["rgb"][8][:, :, ::-1])
    est = objs.update(seq["T"][8], bgr=bgr, depth=seq["depth"][8])["beam"]
    assert est.reason.startswith("reference view") and objs.trackers["beam"].dense.static, est.reason
    assert not objs.needs_depth  # depth is not read any more
    (k, poly), = objs.focus(seq["T"][8])  # the beam's image region, for the localization's feature budget
    assert k == 0 and len(poly) >= 3 and objs.focus(None) == []


def test_object_trackers_take_the_guess_along_the_axis_after_repeated_slide_refusals(scene3, monkeypatch):
    """A registration refused for its slide alone is tried again on new views; after
    ``RegistrationConfig.slide_refusals`` such refusals the next try takes the position along the axis from the
    guess (``slide_from_guess``). Another refusal (too little matched) does not count."""
    import simreal_nodes.assimilation.objects as objects_module

    s, seq = scene3, scene3["seq"]
    scene = build_spec_models(validate_scene(copy.deepcopy(s["doc"]), "family_3", "."))
    asked: list[bool] = []
    outcomes = iter(["other", "slide", "slide"])

    def refusing(real):
        def register(*args, **kwargs):
            cfg = next(a for a in [*args, *kwargs.values()] if isinstance(a, RegistrationConfig))
            asked.append(cfg.slide_from_guess)
            what = next(outcomes, None)
            if what == "other":
                raise RegistrationError("registration refused: 10 % of the model surface facing the camera matched")
            if what == "slide":
                raise SlideRefused("registration refused: the fit can slide along the object's axis over 80 mm")
            return real(*args, **kwargs)
        return register

    # the beam's dense tracker registers with its deformation (register_loaded); either path counts the same
    monkeypatch.setattr(objects_module, "register_rgbd", refusing(objects_module.register_rgbd))
    monkeypatch.setattr(objects_module, "register_loaded", refusing(objects_module.register_loaded))
    objs = ObjectTrackers(scene["objects"], {"beam": s["model"]}, registration=replace(CFG, frames=1, every=1))
    objs.set_camera(seq["cam"])
    reasons = [objs.update(seq["T"][i], depth=seq["depth"][i])["beam"].reason for i in range(4)]
    assert asked == [False, False, False, True], (asked, reasons)
    assert "slide" in reasons[2] and "beam" in objs.registrations, reasons
    assert _error(objs.registrations["beam"].T_map_obj, s["truth"])[0] < 20.0  # placed (from one view)


def test_a_background_registration_lets_frames_go_on_and_places_the_beam_as_the_synchronous_one(scene3):
    """Live (``background=True``): the views go to a worker process and the frame that completes them returns at
    once, saying so; frames go on while it works, and its registration is the synchronous one (to rounding: another
    process's floating point differs in the last bit)."""
    s, seq = scene3, scene3["seq"]
    scene = build_spec_models(validate_scene(copy.deepcopy(s["doc"]), "family_3", "."))
    sync = ObjectTrackers(scene["objects"], {"beam": s["model"]}, registration=CFG)
    live = ObjectTrackers(scene["objects"], {"beam": s["model"]}, registration=CFG, background=True)
    try:
        for objs in (sync, live):
            objs.set_camera(seq["cam"])
            for i in range(9):
                est = objs.update(seq["T"][i], depth=seq["depth"][i])["beam"]
        assert "beam" in sync.registrations
        assert "beam" not in live.registrations  # the frame that completed the views did not wait for the fit
        assert est.state == EstimateState.LOST and est.reason == "registering from 3 depth views (in the background)"
        t_end = time.monotonic() + 120
        while "beam" not in live.registrations:
            assert time.monotonic() < t_end, "no registration from the worker"
            est = live.update(seq["T"][8], depth=seq["depth"][8])["beam"]
            if "beam" not in live.registrations:
                assert est.reason.startswith("registering"), est.reason
            time.sleep(0.05)
        np.testing.assert_allclose(live.registrations["beam"].T_map_obj, sync.registrations["beam"].T_map_obj,
                                   rtol=0, atol=1e-12)
        assert live.registrations["beam"].fitness == pytest.approx(sync.registrations["beam"].fitness, abs=1e-12)
        assert np.allclose(live.trackers["beam"].T_map_obj, sync.registrations["beam"].T_map_obj)
        assert live.background is not None and not live.background.pending("beam")
    finally:
        live.close()


def test_a_registration_worker_that_dies_is_reported_and_started_again(scene3):
    from simreal_nodes.assimilation.registration_worker import BackgroundRegistration

    def result(bg):
        t_end = time.monotonic() + 120
        while (got := bg.poll("beam")) is None:
            assert time.monotonic() < t_end, "no answer from the worker"
            time.sleep(0.05)
        return got

    s = scene3
    bg = BackgroundRegistration()
    try:
        bg.submit("beam", "rgbd", s["cloud"], s["model"], s["guess"], s["cams"], CFG)
        assert bg._proc is not None
        bg._proc.kill()  # killed while it imports or works: reported, not waited for forever
        status, why = result(bg)
        assert status == "failed" and "the registration worker exited" in why, why
        bg.submit("beam", "rgbd", s["cloud"], s["model"], s["guess"], s["cams"], CFG)  # a new worker
        status, reg = result(bg)
        assert status == "ok" and isinstance(reg, Registration)
        np.testing.assert_allclose(reg.T_map_obj, register_rgbd(s["cloud"], s["model"], s["guess"], s["cams"],
                                                                CFG).T_map_obj, rtol=0, atol=1e-12)
        bg.submit("beam", "rgbd", np.zeros((10, 3)))  # a failing call is reported with its error
        status, why = result(bg)
        assert status == "failed" and "TypeError" in why, why
        # a refusal for the slide alone is told apart (the tracker counts those): the beam without its ends
        bg.submit("beam", "rgbd", _without_ends(s), s["model"], s["guess"], s["cams"], CFG)
        status, why = result(bg)
        assert status == "slide" and "slide along the object's axis" in why, (status, why)
        with pytest.raises(ValueError, match="registration kind"):
            bg.submit("beam", "icp")
    finally:
        bg.close()


def test_a_fit_slid_along_the_beam_is_pinned_by_its_ends(scene3):
    """Point-to-plane ICP does not see a slide along a prism's axis once the end faces are lost (at 1.5 m a few
    noisy pixels; here cut away): a pose 30 mm off along the beam keeps its residual. The cover of the model's
    faces turned to the cameras puts it back."""
    s = scene3
    m = s["model"]
    P_obj = (s["cloud"] - s["truth"][:3, 3]) @ s["truth"][:3, :3]
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    on = np.all((P_obj > lo - 0.004) & (P_obj < hi + 0.004), axis=1) & (P_obj[:, 2] > lo[2] + CFG.contact_band)
    on &= (P_obj[:, 0] > lo[0] + 0.004) & (P_obj[:, 0] < hi[0] - 0.004)  # no end faces
    P = s["cloud"][on]
    S, N = sample_surface(m.points, m.surface, 20000)
    for off in (0.03, -0.03):
        slid = G.inv(s["truth"] @ G.make_T(t=[off, 0.0, 0.0]))  # map -> object of the model moved along its axis
        T = _pin_slide(P, slid, S, N, s["cams"], CFG)
        mm, _ = _error(G.inv(T), s["truth"])
        assert mm < 3.0, (off, mm)
    # a well-placed fit stays where it is
    T = _pin_slide(P, G.inv(s["truth"]), S, N, s["cams"], CFG)
    assert _error(G.inv(T), s["truth"])[0] < 3.0


def _cover_searched_at_every_shift(P, T, S, N, cams, cfg):
    """The slide's cover as its definition reads: every measurable face searched at every shift (the code before
    the searches were skipped by the distance bounds)."""
    axis = _weak_axis(P, T, S, N, cfg)
    tree = cKDTree(P @ T[:3, :3].T + T[:3, 3])
    Sf = S[_facing(S, N, cams.centres @ T[:3, :3].T + T[:3, 3])]
    Sf = Sf[cams.measurable((Sf - T[:3, 3]) @ T[:3, :3])]
    shifts = np.arange(-cfg.margin / 2, cfg.margin / 2 + 1e-9, 0.001)
    cover = np.zeros(len(shifts))
    for k, dx in enumerate(shifts):
        Q = Sf + dx * axis
        Q = Q[cams.measurable((Q - T[:3, 3]) @ T[:3, :3])]
        cover[k] = np.isfinite(tree.query(Q, distance_upper_bound=cfg.inlier_dist)[0]).sum() / max(len(Sf), 1)
    return axis, shifts, cover


def test_the_slides_cover_is_that_of_a_search_at_every_shift(scene3):
    """``_slide_cover`` skips the search of a face whose distance bounds (its last search, moved by the shift since)
    decide it: the cover is the one every face searched at every shift gives, to the bit, for fits on the beam, slid
    along it, turned, without its ends, judged by the views' image bounds or by the camera centres alone. The
    skipped searches matter: the registration spent 40 % of its time here (development seed 3, 0.87 -> 0.3 s a
    call)."""
    s = scene3
    m = s["model"]
    S, N = sample_surface(m.points, m.surface, 20000)
    seq = s["seq"]
    views = DepthViews(np.array([seq["T"][i] for i in VIEWS]), seq["cam"])
    cfg = replace(CFG, inlier_dist=0.006)
    checked = 0
    for P in (s["cloud"], _without_ends(s)):
        for off, turn in ((0.0, 0.0), (0.03, 0.0), (-0.02, 2.0), (0.004, -1.0)):
            T = G.inv(s["truth"] @ G.make_T(G.rot_axis("z", np.deg2rad(turn)), [off, 0.0, 0.0]))
            for cams in (views, _Centres(s["cams"])):
                ref = _cover_searched_at_every_shift(P, T, S, N, cams, cfg)
                got = _slide_cover(P, T, S, N, cams, cfg)
                assert got is not None and ref[0] is not None
                assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])
                assert np.array_equal(got[2], ref[2]), (off, turn, np.abs(got[2] - ref[2]).max())
                checked += 1
                assert 0.0 < got[2].min() < got[2].max() <= 1.0  # the cover changes along the slide
    assert checked == 16


def test_the_polish_keeps_the_start_most_faces_meet_within_2_mm(scene3):
    """``RegistrationConfig.polish``: a fit left 3.5 mm off across the beam (as the joint boot's fine stage stops a
    pleat away, docs/family.md) is compared with starts 4 mm either way along each axis, here without ICP, by the
    share of the faces turned to the cameras that have a measured point within 2 mm: the start 0.5 mm from the
    truth wins. And the whole registration with the polish on places the beam as well as without."""
    s = scene3
    m = s["model"]
    S, N = sample_surface(m.points, m.surface, 20000)
    cfg = RegistrationConfig(stride=1, polish=0.004)
    P_obj = (s["cloud"] - s["truth"][:3, 3]) @ s["truth"][:3, :3]
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    P = s["cloud"][np.all((P_obj > lo - 0.004) & (P_obj < hi + 0.004), axis=1)
                   & (P_obj[:, 2] > lo[2] + CFG.contact_band)]
    off = G.inv(s["truth"] @ G.make_T(t=[0.0, 0.0035, 0.0]))  # map -> object of the model moved 3.5 mm in y
    T = _polished(P, off, S, N, s["cams"], cfg, lambda T0: T0)
    assert _error(G.inv(T), s["truth"])[0] < 1.0
    reg = register_rgbd(s["cloud"], m, s["guess"], s["cams"], cfg)
    assert _error(reg.T_map_obj, s["truth"])[0] < 2.0


def test_a_fit_whose_ends_are_not_seen_is_refused_not_slid(scene3):
    """Without the beam's ends in the data nothing pins the slide along its axis (held-out seed 1081 was accepted
    148 mm off that way): the registration must refuse, saying why, rather than place the beam anywhere along it.
    The same scene with its ends seen slides over a few millimetres only."""
    s = scene3
    m = s["model"]
    whole = register_rgbd(s["cloud"], m, s["guess"], s["cams"], CFG)
    assert whole.slide_spread < 0.03, whole.slide_spread
    with pytest.raises(RegistrationError, match="slide along the object's axis"):
        register_rgbd(_without_ends(s), m, s["guess"], s["cams"], CFG)


def test_a_fit_whose_ends_are_not_seen_takes_its_position_along_the_axis_from_the_guess(scene3):
    """With ``slide_from_guess`` (the tracker's, after repeated refusals for the slide alone) the same fit is kept:
    the five degrees of freedom the data hold are the fit's, the position along the beam's axis is the guess's, and
    the pose is doubted, saying so. Without the option the same cloud is refused (above)."""
    s = scene3
    m = s["model"]
    cloud = _without_ends(s)
    guess = G.make_T(s["guess"][:3, :3], s["guess"][:3, 3] - 0.04 * s["guess"][:3, 0])  # 40 mm back along the beam
    with pytest.raises(SlideRefused):
        register_rgbd(cloud, m, guess, s["cams"], CFG)
    reg = register_rgbd(cloud, m, guess, s["cams"], replace(CFG, slide_from_guess=True))
    assert reg.doubt.startswith("placed along its axis by the guess"), reg.doubt
    c = m.points.mean(axis=0)
    axis = s["truth"][:3, 0]  # the beam's length, in the map
    placed, true, guessed = (T[:3, :3] @ c + T[:3, 3] for T in (reg.T_map_obj, s["truth"], guess))
    along = float(axis @ (placed - true))
    # along the axis: where the guess puts the centre (the guess is levelled onto the floor first: a few mm)
    assert abs(along - float(axis @ (guessed - true))) < 3.0e-3, (along, float(axis @ (guessed - true)))
    across = np.linalg.norm((placed - true) - along * axis)
    deg = _error(reg.T_map_obj, s["truth"])[1]
    assert 1e3 * across < 2.0 and deg < 0.5, (1e3 * across, deg)
    assert abs(along) > 0.015  # the guess is off along the axis: the test tells the guess's position from the truth's
    assert reg.along_from_guess and reg.along_from_guess in reg.doubt
    # the same from the depth views themselves (what the tracker passes: the faces each view can measure)
    seq = s["seq"]
    views = DepthViews(np.array([seq["T"][i] for i in VIEWS]), seq["cam"])
    with pytest.raises(SlideRefused):
        register_rgbd(cloud, m, guess, views, CFG)
    by_views = register_rgbd(cloud, m, guess, views, replace(CFG, slide_from_guess=True))
    placed_v = by_views.T_map_obj[:3, :3] @ c + by_views.T_map_obj[:3, 3]
    assert abs(float(axis @ (placed_v - true)) - float(axis @ (guessed - true))) < 3.0e-3, by_views.doubt
    assert by_views.along_from_guess
    # with its deformation fitted too (the beam is at rest here: the rigid fit stands, and says the same)
    lo_mu, hi_mu = np.array([a.values[0] for a in m.axes]), np.array([a.values[-1] for a in m.axes])
    loaded = register_loaded(cloud, m, guess, s["cams"], lo_mu, hi_mu, replace(CFG, slide_from_guess=True))
    assert loaded.along_from_guess and loaded.state is None, loaded.state_reason
    np.testing.assert_allclose(loaded.T_map_obj, reg.T_map_obj, atol=1e-9)
    # a guess the depth contradicts (11 cm further back, 15 cm from the truth along the 0.46 m beam) is
    # followed only to the end of the shifts the depth covers about as well as the best, and says so
    far = G.make_T(guess[:3, :3], guess[:3, 3] - 0.11 * guess[:3, 0])
    reg = register_rgbd(cloud, m, far, s["cams"], replace(CFG, slide_from_guess=True))
    along_far = float(axis @ (reg.T_map_obj[:3, :3] @ c + reg.T_map_obj[:3, 3] - true))
    guessed_far = float(axis @ (far[:3, :3] @ c + far[:3, 3] - true))
    assert "at the end of what the depth allows" in reg.doubt, reg.doubt
    assert guessed_far < along_far - 0.05 and reg.fitness >= CFG.min_fitness, (guessed_far, along_far, reg.fitness)


def test_a_fit_that_can_slide_over_a_share_of_the_beam_is_doubted(scene3):
    """A fit whose ends are barely seen can slide along the beam at about the same cover: under the refusal's 60 mm
    but over 5 % of the beam's length, a load position along it may be that far off (a camera 0.5 m from a 0.63 m
    beam, development seed 1: 45 mm of slide, placed 43 mm off, every frame OK before). Such a fit is kept and
    doubted, saying why; a slide of a few millimetres is not."""
    s = scene3
    m = s["model"]
    P_obj = (s["cloud"] - s["truth"][:3, 3]) @ s["truth"][:3, :3]
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    on = np.all((P_obj > lo - 0.004) & (P_obj < hi + 0.004), axis=1) & (P_obj[:, 2] > lo[2] + CFG.contact_band)
    S, N = sample_surface(m.points, m.surface, 20000)
    T = G.inv(s["truth"])
    length = hi[0] - lo[0]
    for share, doubted in ((0.02, False), (0.04, False), (0.06, True), (0.10, True)):
        out = _judged(Registration(s["truth"], 0.9, 0.001, 1000, None, share * length), s["cloud"][on], T, S, N, CFG)
        assert bool(out.doubt) == doubted, (share, out.doubt)
        if doubted:
            assert "slide" in out.doubt and f"{100 * share:.1f} % of its length" in out.doubt, out.doubt


def test_stereo_depth_lets_a_fit_slide_further_before_it_is_doubted():
    """SGBM smooths a beam's ends, so well-placed stereo fits slide further (development stereo seeds: up to 6.7 % of
    the beam): a scene seen through a pair doubts a slide past 8 % of the object, an RGB-D one past 5 %."""
    stereo = RegistrationConfig.for_camera({"depth": None, "right_image": "/camera/right/image_rect"})
    rgbd = RegistrationConfig.for_camera({"depth": "/camera/depth/image_rect", "right_image": None})
    assert (stereo.max_slide_share, stereo.fine) == (0.08, "upright")
    assert (rgbd.max_slide_share, rgbd.fine) == (0.05, "full")


def test_our_icp_is_open3ds_point_to_plane_icp_and_repeats_to_the_bit(scene3):
    """The fine stage's ICP (:func:`icp_point_to_plane`) replaces Open3D's ``registration_icp``, whose threaded
    sums made identical inputs end 1e-15 apart from run to run (amplified by the boot's tracker): from a start
    5 mm and 1 degree off it lands where Open3D's does (to a micrometre and a microradian), twice on the same bits."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    s = scene3
    S, N = sample_surface(s["model"].points, s["model"].surface, 20000, 0)
    P = s["cloud"]
    T_true = G.inv(s["truth"])  # map -> object
    P = P[np.all(np.abs(P @ T_true[:3, :3].T + T_true[:3, 3] - s["model"].points.mean(axis=0)) < 0.6, axis=1)]
    T0 = G.make_T(G.exp_so3(np.deg2rad([0.6, -0.5, 0.6])), [0.004, -0.003, 0.002]) @ T_true
    ours = [icp_point_to_plane(P, cKDTree(S), N, T0.copy(), 0.012) for _ in range(2)]
    assert np.array_equal(ours[0], ours[1])
    src, tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P)), o3d.geometry.PointCloud(
        o3d.utility.Vector3dVector(S))
    tgt.normals = o3d.utility.Vector3dVector(N)
    theirs = np.asarray(reg.registration_icp(
        src, tgt, 0.012, T0, reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=0.012)),
        reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=40)).transformation)
    D = theirs @ G.inv(ours[0])
    assert np.linalg.norm(D[:3, 3]) < 1e-6 and np.linalg.norm(G.log_so3(D[:3, :3])) < 1e-6, D
    assert np.linalg.norm((ours[0] @ G.inv(T0))[:3, 3]) > 1e-3  # it moved


def test_a_registration_repeats_to_the_bit(scene3):
    s = scene3
    a, b = (register_rgbd(s["cloud"].copy(), s["model"], s["guess"], s["cams"], replace(CFG, polish=0.004))
            for _ in range(2))
    assert np.array_equal(a.T_map_obj, b.T_map_obj) and a.fitness == b.fitness


def _thin_plate_scene(rng: np.random.Generator, L: float = 0.5, W: float = 0.33, h: float = 0.036):
    """A plate L x W x h (object frame: a corner of its underside at the origin) on a block 12 cm above a floor,
    sampled as depth would see it from three cameras in front and above (top, front and free end, the block's
    faces, the floor), 0.5 mm of noise; the plate's true pose in the map and the cameras' positions."""
    from types import SimpleNamespace

    from simreal_nodes.synth.world import box

    V, F = box((L, W, h), (L / 2, W / 2, h / 2))
    plate = SimpleNamespace(points=V, surface=F)
    T_true = G.make_T(G.rot_axis("z", np.deg2rad(20.0)), [0.3, -0.2, 0.12])

    def face(n, x, y, z):  # n points uniformly on an axis-aligned rectangle: x, y, z are (lo, hi) or a value
        return np.column_stack([rng.uniform(*v, n) if isinstance(v, tuple) else np.full(n, v) for v in (x, y, z)])

    P_obj = np.vstack([face(6000, (0, L), (0, W), h), face(1500, (0, L), 0.0, (0, h)), face(1000, L, (0, W), (0, h)),
                       face(800, (-0.06, 0), (-0.02, W + 0.02), 0.0), face(1500, (-0.06, 0), -0.02, (-0.12, 0)),
                       face(12000, (-0.4, L + 0.4), (-0.5, W + 0.1), -0.12)])
    P_obj += rng.normal(0.0, 0.0005, P_obj.shape)
    cams_obj = np.array([[L / 2 + dx, -0.8, 0.7] for dx in (-0.3, 0.0, 0.3)])
    return plate, G.transform(T_true, P_obj), T_true, G.transform(T_true, cams_obj)


def test_a_thin_plate_guessed_too_high_is_not_placed_on_its_own_top_face():
    """With every model face a candidate for each measured point, a plate guessed more than half its thickness too
    high settles with the points of its top face on its underside (placed a thickness above the object, covering
    none of its faces: refused). The coarse stage run again with the points paired only with the faces turned to the
    cameras places it."""
    plate, cloud, T_true, cams = _thin_plate_scene(np.random.default_rng(3))
    guess = T_true @ G.make_T(G.rot_axis("z", np.deg2rad(4.0)), [0.01, 0.015, 0.072])
    with pytest.raises(RegistrationError, match="refused") as e:
        register_rgbd(cloud, plate, guess, cams, RegistrationConfig(coarse_gain=0.0))
    assert _error(e.value.args[1].T_map_obj, T_true)[0] > 30.0  # a thickness (36 mm) too high
    reg = register_rgbd(cloud, plate, guess, cams)
    mm, deg = _error(reg.T_map_obj, T_true)
    assert mm < 2.0 and deg < 0.3 and reg.fitness > 0.9


def test_the_contact_band_follows_a_bent_underside_and_is_the_rest_rule_where_nothing_moved():
    """A loaded beam's points are judged above the contact band over its *bent* underside (stop 115: development
    seed 17, a two-support beam sagging 23 mm, kept no points of its lower faces near the load, judged them unmatched
    and was refused on every try). Points of the front face 5 mm over the sagged underside are all kept (the rest
    rule dropped every one where the beam sags by more than 1 mm); points 2 mm over it are in the band and dropped;
    with u = 0 the rule is the rest shape's, point for point."""
    from simreal_nodes.assimilation.registration import _object_points

    cfg = RegistrationConfig()  # contact band 4 mm
    x = np.linspace(0.0, 0.6, 61)
    rest = np.array([(xi, y, z) for xi in x for y in (0.0, 0.03) for z in (0.0, 0.02)])  # nodes of a 600 x 30 x 20 beam
    bent = rest.copy()
    bent[:, 2] -= 0.02 * np.sin(np.pi * rest[:, 0] / 0.6)  # 20 mm down at mid-span, none at the supports
    T = G.make_T(t=[0.1, -0.2, 0.8])
    xs = np.arange(0.0, 0.601, 0.005)
    under = -0.02 * np.sin(np.pi * xs / 0.6)

    def judged(height: float, **kw) -> np.ndarray:  # the front face's points kept, by their x
        front = np.c_[xs, np.zeros_like(xs), under + height]
        kept = _object_points(G.transform(T, front), T, bent, 0.0, None, cfg, **kw)
        return np.sort(np.round(G.transform(G.inv(T), kept)[:, 0], 3))

    np.testing.assert_array_equal(judged(0.005, rest=rest), np.round(xs, 3))
    assert np.all(np.abs(judged(0.005) - 0.3) >= 0.29 - 1e-9)  # the rest rule: only within 10 mm of the supports
    assert len(judged(0.002, rest=rest)) == 0
    cloud = G.transform(T, np.c_[xs, np.zeros_like(xs), 0.001 + 0.01 * (xs % 0.01 > 0.004)])
    np.testing.assert_array_equal(_object_points(cloud, T, rest, 0.0, None, cfg, rest=rest),
                                  _object_points(cloud, T, rest, 0.0, None, cfg))
    # only the underside counts: the top nodes moved (a lever turned over a clamped base, the boot) and the
    # underside not is the rest rule too
    lifted = rest.copy()
    lifted[rest[:, 2] > 0, 2] -= 0.02
    np.testing.assert_array_equal(_object_points(cloud, T, lifted, 0.0, None, cfg, rest=rest),
                                  _object_points(cloud, T, lifted, 0.0, None, cfg))


def test_a_loaded_fit_slid_along_its_axis_is_pinned_by_its_cover_and_its_load_fitted_again(monkeypatch):
    """The deformed fit starts where the rigid fit of the bent beam put it, and the rigid fit, judged without the
    sagging part, can leave a loaded cantilever centimetres along its axis (held-out seeds 1018 and 1025 until stop
    116: 57 and 53 mm, no doubt raised); the deformed fit's cost does not fit that slide (:func:`fit_state`'s weak
    direction), so the registration pins it by the deformed shape's cover and fits the load again from there. A
    cantilever of the family (development seed 4, 562 mm), its own bent surface seen from above and the front, the
    fit started 50 mm towards the clamp, the load at 35 % and 80 % of its range (the tip bent 20 and 65 mm): the
    pinned fit is within 4 mm (3.3 for the larger load) and its load within 1 % of its range. A fit in place is
    returned as it was, the same objects; so is a slid one whose state fitted again covers fewer of its faces than
    it did (a fit that would make the registration worse)."""
    from simreal_nodes.assimilation import registration as registration_module
    from simreal_nodes.assimilation.depth_state import fit_state
    from simreal_nodes.assimilation.registration import _n_samples, _object_points, _pinned_state

    m = sequence("family-4-preloaded", 160, 120, fps=15.0, ssaa=1, frames=1)["scene"].state["models"]["beam"]
    values = m.axes[0].values
    lo, hi = np.array([values.min()]), np.array([values.max()])
    T_true = G.make_T(G.rot_axis("z", 0.3), [0.1, 0.2, 0.5])
    cams_obj = np.array([[0.25, -0.6, 0.5], [0.35, -0.55, 0.55]])  # above and in front of the beam
    cams = _Centres(G.transform(T_true, cams_obj))
    cfg = RegistrationConfig()

    def shape(st, cloud):
        u = m.deformation_view(None, None).field.evaluate(st.mu)
        S, N = sample_surface(m.points + u, m.surface, _n_samples(m, 0.0025), 0)
        return u, S, N, _object_points(cloud, st.T_map_obj, m.points + u, 0.0, None, cfg, rest=m.points)

    def cloud_of(share: float) -> tuple[np.ndarray, np.ndarray]:
        mu_true = lo + share * (hi - lo)
        S, N = sample_surface(m.points + m.deformation_view(None, None).field.evaluate(mu_true), m.surface, 40_000,
                              seed=1)
        return mu_true, G.transform(T_true, S[_facing(S, N, cams_obj)])

    for share in (0.35, 0.8):
        mu_true, cloud = cloud_of(share)
        slid = fit_state(cloud, m, T_true @ G.make_T(t=[-0.05, 0.0, 0.0]), lo, hi)
        assert slid.deformed and abs((G.inv(T_true) @ slid.T_map_obj)[0, 3] + 0.05) < 0.005  # it stays slid
        again = _pinned_state(cloud, m, slid, shape(slid, cloud), lo, hi, cams, None, cfg, None, 0, None)[0]
        assert np.linalg.norm((G.inv(T_true) @ again.T_map_obj)[:3, 3]) < 0.004, share
        assert abs(again.mu[0] - mu_true[0]) < 0.01 * (hi[0] - lo[0]), share
    placed = fit_state(cloud, m, T_true, lo, hi)
    assert _pinned_state(cloud, m, placed, shape(placed, cloud), lo, hi, cams, None, cfg, None, 0, None)[0] is placed

    def worse(cloud, model, T, lo, hi, mu0=None, cfg=None, n_modes=None):  # the load fitted again at its far end
        st = fit_state(cloud, model, T, lo, hi, mu0=mu0, cfg=cfg, n_modes=n_modes)
        return replace(st, mu=lo.copy())

    monkeypatch.setattr(registration_module, "fit_state", worse)
    assert _pinned_state(cloud, m, slid, shape(slid, cloud), lo, hi, cams, None, cfg, None, 0, None)[0] is slid


def test_a_tilted_rigid_fit_of_a_sagging_beam_is_levelled_about_its_ends_too():
    """A sagging beam's rest shape fitted rigidly follows the sag from one end and tilts; levelled about its centre it
    starts the deformed fit centimetres off in height, where the fit reads the load wrong or not at all (development
    seeds 40 and 49 of the loaded family until stop 117: tilted 4.7 and 4.0 degrees, no deformation read, 40 left
    72 mm off at its far end without a doubt). A two-support beam of the family (seed 40, 897 mm), its own bent
    surface seen from the front, the rigid fit turned about its origin end: with the far end 5 degrees low (the load
    near a support, at 2 % of its range, the beam sagging 44 mm), levelled about the centre the fit sits 39 mm low
    and reads no deformation; turned the other way (3 degrees up, the load at 20 %) it is placed 7 mm off and reads
    its load 70 % of the range off. Levelled about its ends too (:func:`_levelled_state`), the deformed fit that
    lowers its rest shape's cost most is within 3 mm and its load within 1 % in both. A fit tilted under
    ``level_ends_deg`` (or with it 0) is returned as it was."""
    from simreal_nodes.assimilation.depth_state import fit_state
    from simreal_nodes.assimilation.registration import _level, _levelled_state

    m = sequence("family-40-preloaded", 160, 120, fps=15.0, ssaa=1, frames=1)["scene"].state["models"]["beam"]
    values = m.axes[0].values
    lo, hi = np.array([values.min()]), np.array([values.max()])
    T_true = G.make_T(G.rot_axis("z", 0.3), [0.1, 0.2, 0.5])
    length = float(np.ptp(m.points[:, 0]))
    cams_obj = np.array([[0.3 * length, -0.8, 0.6], [0.7 * length, -0.75, 0.65]])  # in front of the beam, above it
    cams = _Centres(G.transform(T_true, cams_obj))
    plane = np.array([0.0, 0.0, 1.0, -0.38])  # the floor 120 mm under the beam

    def fits(share: float, deg: float, cfg: RegistrationConfig):
        mu_true = lo + share * (hi - lo)
        S, N = sample_surface(m.points + m.deformation_view(None, None).field.evaluate(mu_true), m.surface, 40_000,
                              seed=1)
        cloud = G.transform(T_true, S[_facing(S, N, cams_obj)])
        T_rigid = T_true @ G.make_T(G.rot_axis("y", np.radians(deg)))  # turned about the origin end (+: far end low)
        reg = Registration(T_rigid, 0.6, 0.0015, 100, plane)
        st = fit_state(cloud, m, _level(T_rigid, plane[:3], m.points.mean(axis=0)), lo, hi)
        return mu_true, st, _levelled_state(cloud, m, reg, st, lo, hi, cams, cfg, None, 0, None)

    def off_mm(st) -> float:
        return float(np.linalg.norm(1e3 * (G.inv(T_true) @ st.T_map_obj)[:3, 3]))

    def load_pct(st, mu_true) -> float:
        return float(100 * abs(st.mu[0] - mu_true[0]) / (hi[0] - lo[0]))

    mu_true, centre, (best, shape) = fits(0.02, 5.0, RegistrationConfig())
    assert not centre.deformed and off_mm(centre) > 30.0  # the fault: levelled about the centre only
    assert best.deformed and shape is not None
    assert off_mm(best) < 3.0 and load_pct(best, mu_true) < 1.0
    mu_true, centre, (best, _) = fits(0.2, -3.0, RegistrationConfig())
    assert off_mm(centre) > 5.0 and load_pct(centre, mu_true) > 10.0
    assert off_mm(best) < 3.0 and load_pct(best, mu_true) < 1.0
    _, centre, (kept, _) = fits(0.02, 5.0, RegistrationConfig(level_ends_deg=0.0))
    assert kept is centre
    _, centre, (kept, _) = fits(0.02, 0.5, RegistrationConfig())
    assert kept is centre
