"""Deformable tracking on rendered aluminium-beam frames (thesis §4.5.1): markers localize the camera, glued
dots measure the deformation, LM on the PGD model estimates the load position s. The estimator sees the
images only; the truth is compared afterwards. Plus the extremes the node must survive."""

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.offline import Pipeline, track_sequence
from simreal_nodes.assimilation.tracker import DeformableTracker, TrackerConfig
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.states import EstimateState
from tests.synthdata import sequence

SPAN = 0.48  # the load range of the model, metres


def _run(name, **kw):
    seq = sequence(name, 640, 480)
    scene = build_spec_models(validate_scene(seq["scene"].scene_yaml(seq["scene"]), name, "."))
    r = track_sequence(seq, scene, **kw)["beam"]
    est = np.array([e.values[0] for e in r["est"]])
    std = np.array([np.sqrt(max(e.cov[0, 0], 0)) if np.isfinite(e.cov[0, 0]) else np.nan for e in r["est"]])
    states = np.array([e.state for e in r["est"]])
    return r["truth"][:, 0], est, std, states, r


def test_aluminium_beam_load_position_over_the_range():
    truth, est, _std, states, _ = _run("aluminium_beam")
    err = np.abs(est - truth)
    print(f"aluminium beam: median |s error| {1e3 * np.median(err):.2f} mm = {100 * np.median(err) / SPAN:.2f} % of "
          f"the span; states {np.bincount(states)}")
    assert np.median(err) < 0.005 * SPAN  # thesis's claim, issue 6
    assert np.all((est >= 0.0) & (est <= SPAN))
    settled = np.abs(np.gradient(truth)) < 1e-9  # frames where the load rests
    assert np.percentile(err[settled], 90) < 0.02 * SPAN
    assert np.mean(states == EstimateState.OK) > 0.9


def test_near_the_clamp_variance_grows_instead_of_wild_values():
    truth, est, std, states, _ = _run("aluminium_beam_clamp")
    assert np.all((est >= 0.0) & (est <= SPAN)), "never outside the model's range"
    near = truth < 0.03
    far = truth > 0.1
    assert near.any() and far.any()
    # low sensitivity shows as variance: the standard deviation is the residual's scale over the sensitivity, so the
    # ratio falls as the camera pose gets better (9.3 with OpenCV's marker corners, 4.4 with the edges' since stop 80);
    # the z test below keeps the variance honest
    assert np.nanmedian(std[near]) > 3 * np.nanmedian(std[far])
    assert np.all(states[near] == EstimateState.LOW_CONFIDENCE)
    # flagged estimates are consistent with their variance; confident ones are accurate
    z = np.abs(est - truth)[near] / std[near]
    assert np.median(z) < 2.0
    # s = 0.10-0.12 m: still little deflection (measured 2.6 mm)
    assert np.median(np.abs(est - truth)[far]) < 0.01 * SPAN


@pytest.fixture(scope="module")
def beam():
    seq = sequence("aluminium_beam", 640, 480)
    scene = build_spec_models(validate_scene(seq["scene"].scene_yaml(seq["scene"]), "aluminium_beam", "."))
    return seq, scene


def _tracker(scene, cam, model=None, **kw):
    o = scene["objects"][0]
    m = model or load_model(o["model"], fields=["displacement"])
    from simreal_nodes.assimilation.tracker import tracker_config

    return DeformableTracker(m, G.pose7_to_matrix(o["anchor"]["pose"]), o["parameters"], cam, tracker_config(o, **kw))


def test_extremes_are_stated_not_crashing(beam):
    seq, scene = beam
    cam = seq["cam"]
    i = 60
    bgr = np.ascontiguousarray(seq["rgb"][i][:, :, ::-1])
    T_wc = Pipeline(scene, cam).loc.step(seq["gray"][i], 0).T_wc
    assert T_wc is not None
    tr = _tracker(scene, cam)
    ok = tr.update(T_wc, image_bgr=bgr)
    assert ok.state == EstimateState.OK
    # no measurements: a black image
    e = tr.update(T_wc, image_bgr=np.zeros_like(bgr))
    assert e.state == EstimateState.LOST and "too few measurements" in e.reason
    # no camera pose
    e = tr.update(None, image_bgr=bgr)
    assert e.state == EstimateState.LOST and "pose" in e.reason
    # all outliers: every dot moved far from where any load could put it (blue blobs shifted 40 px up)
    shifted = np.roll(bgr, -40, axis=0)
    shifted[-40:] = bgr[-40:]
    e = tr.update(T_wc, image_bgr=shifted)
    assert e.state in (EstimateState.LOST, EstimateState.LOW_CONFIDENCE) and e.reason
    # NaN pixel coordinates and NaN points in map-point measurements
    trm = _tracker(scene, cam, measurements="map_points")
    ids = np.arange(10)
    P = np.full((10, 3), np.nan)
    uv = np.full((10, 2), np.nan)
    e = trm.update(T_wc, ids, P, uv)
    assert e.state == EstimateState.LOST and np.all(np.isfinite(e.values))
    # the tracker recovers on the next good frame
    assert tr.update(T_wc, image_bgr=bgr).state == EstimateState.OK


def test_model_an_order_of_magnitude_off_in_scale_is_reported(beam):
    seq, scene = beam
    cam = seq["cam"]
    m = load_model(cached_model("aluminium_beam"), fields=["displacement"])
    m.points = m.points * 10.0  # a model in the wrong unit: 5 m beam
    tr = _tracker(scene, cam, model=m)
    loc = Pipeline(scene, cam).loc
    states = []
    for i in (30, 60, 90):
        T_wc = loc.step(seq["gray"][i], 0).T_wc
        e = tr.update(T_wc, image_bgr=np.ascontiguousarray(seq["rgb"][i][:, :, ::-1]))
        assert np.all(np.isfinite(e.values)) and 0.0 <= e.values[0] <= SPAN
        states.append(e.state)
        assert e.state == EstimateState.OK or e.reason
    assert EstimateState.OK not in states, f"a model 10x too large must not look fine: {states}"


# -- deformable ORB tracking through the RGB-D map (thesis §4.4, §4.5.2-4.5.4) ----------------------------------

def _track_map_points(name, oid, width=640, height=480, seq=None, **kw):
    seq = seq or sequence(name, width, height)
    scene = build_spec_models(validate_scene(seq["scene"].scene_yaml(seq["scene"]), name, "."))
    r = track_sequence(seq, scene, **kw)[oid]
    est = np.array([e.values for e in r["est"]])
    states = np.array([e.state for e in r["est"]])
    return r["truth"], est, states


def _check_starved_boot(label, **kw):
    """The thesis boot as a starved live graph sees it (every 10th frame, the tracker's feedback one frame late):
    the lever within 1.5 degrees at the median (p90 8) over the loaded frames, nothing lost."""
    truth, est, states = _track_map_points("joint_boot", "boot", every=10, feedback_delay=1, **kw)
    loaded = truth[:, 0] > 0.02
    err_theta = np.degrees(np.abs(est[loaded, 0] - truth[loaded, 0]))
    print(f"joint boot, every 10th frame, {label}: theta median {np.median(err_theta):.2f} deg, "
          f"p90 {np.percentile(err_theta, 90):.2f}, states {np.bincount(states, minlength=4)}")
    assert np.median(err_theta) < 1.5 and np.percentile(err_theta, 90) < 8.0
    assert not np.any(states == EstimateState.LOST)


def test_joint_boot_lever_angle_and_unknown_rotation_from_map_points():
    """Real boot turned by an unknown 20 degrees about its axis, lever 0 -> 50 -> 0 degrees: theta within
    0.6 degree (median), alpha_z estimated over the first well-deformed frames and frozen within 1 degree.
    And as a starved live graph sees it: every 10th frame, the tracker's feedback one frame late. Measured:
    theta median 0.85 deg (p90 4.5) over the loaded frames, nothing lost; before lost object tracks were
    re-acquired in a wider window: 12.4 deg (p90 33), 11 of 24 frames lost. Stop 124 (the SLAM's keyframes make
    points by ORB-SLAM2's rule, and a frame that cannot pin the lever no longer moves alpha_z): starved 1.07 deg
    (p90 4.57; 1.04 and 3.37 before), every 3rd frame alpha_z 0.30 deg off at the end (0.70), every frame 1.04 deg
    (p90 1.33, alpha_z 0.59; 1.56, 1.90, 0.19 before)."""
    seq = sequence("joint_boot", 640, 480)
    _check_starved_boot("feedback 1 frame late", seq=seq)
    # every 3rd frame (a graph taking 10 of 30 frames a second): fewer informative frames than constant_frames
    # counts, so alpha_z is never frozen; seen well once, it is held at the median of those frames, not moved by the
    # weaker ones. Stop 87: 0.5 degree off at the end; 138 before, left free while the lever came back to rest
    truth, est, states = _track_map_points("joint_boot", "boot", seq=seq, every=3, feedback_delay=1)
    err_alpha = np.degrees(np.abs(est[:, 1] - truth[:, 1]))
    print(f"joint boot, every 3rd frame: alpha_z {err_alpha[-1]:.2f} deg off at the end, "
          f"median {np.median(err_alpha):.2f}")
    assert err_alpha[-1] < 1.5
    truth, est, states = _track_map_points("joint_boot", "boot", seq=seq)
    loaded = truth[:, 0] > 0.02  # the lever is moving
    err_theta = np.abs(est[loaded, 0] - truth[loaded, 0])
    err_alpha = abs(est[-1, 1] - truth[-1, 1])
    print(f"joint boot: theta median error {np.degrees(np.median(err_theta)):.2f} deg (p90 "
          f"{np.degrees(np.percentile(err_theta, 90)):.2f}), alpha_z error {np.degrees(err_alpha):.2f} deg, "
          f"states {np.bincount(states, minlength=4)}")
    # 0.47 deg with the LM solver before stop 34; 0.56 since it solves in range units over the free parameters only
    # (lm.solve_generic). On independent physics (thesis_truth's boot table) the same change moved the three views
    # from 0.26 / 0.12 / 0.27 to 0.37 / 0.21 / 0.29 deg. The bound was 0.5, then 0.6. Stop 54: 0.61 with the SLAM's
    # array-based map queries (ties now broken by the newest keyframe, vision/slam/map.py:ranked, and the bundle
    # adjustments' observations gathered in another order; which of the two was not isolated): the bound is 0.65
    # (p90 0.85 and alpha_z 0.75 deg, within theirs). Stop 65: 1.55 deg (p90 1.85, alpha_z 0.19) since the map keeps
    # the points linked at rest (SlamConfig.hold_rest_points, chosen on the family's development boots 0-19, where
    # the median went 0.89 / 0.98 % -> 0.66 / 0.55 % of the range): here, on the model's own render, they read the
    # lever 0.6 degree off while it still rests (0.45 with them culled) and about 1.5 degrees high through the sweep;
    # with hold_rest_points=False this scene reads 0.37 deg. The bound is 1.7 (docs/family.md, the stop-65 paragraph).
    # Stop 66 measured the knob TrackerConfig.outlier_refits (not the default) here: 3 rounds read 1.46 deg (p90
    # 1.63, alpha_z 0.43) against 1.55 (1.78, 0.11) with Huber alone; the starved graph above 1.13 against 1.04 deg
    assert np.degrees(np.median(err_theta)) < 1.7
    assert np.degrees(np.percentile(err_theta, 90)) < 2.0
    assert np.degrees(err_alpha) < 1.0
    assert np.mean(states[loaded] == EstimateState.OK) > 0.9


def test_joint_boot_in_a_starved_graph_with_the_nearest_keyframe_points():
    """The starved graph above (every 10th frame, the feedback one frame late) with the SLAM's keyframes making
    points from their 250 nearest features (``SlamConfig.keyframe_depth_points`` 250, stop 123's default, now a
    knob): 1.04 deg (p90 3.37). With ORB-SLAM2's rule, before a frame that cannot pin the tracked parameters stopped
    moving a constant (``DeformableTracker._conclude``, stop 124), the 10th step (lever at 22 degrees; 16
    measurements, the lever "barely observable") turned alpha_z by 90 degrees, which the next frames kept: 3.22
    (p90 8.22)."""
    from simreal_nodes.vision.slam.config import SlamConfig

    _check_starved_boot("the 250 nearest keyframe points", slam_config=SlamConfig(keyframe_depth_points=250))


def test_foam_beam_load_position_from_its_own_texture():
    """Textured foam beam, a 15 N disk moved to five places (§4.5.2), filmed at the thesis's 1280 x 720, sparse
    map points (the scene rendered by the model it fits: the mechanics, not the accuracy): median load-position
    error under 1 % of the span (the 757.5 mm between the support centres). Measured 5.5 mm (0.73 %), p90 11 mm,
    on the corrected foam model (40 quadratic hexahedra; 2.0 mm, 0.26 %, on the earlier 32 linear ones, 26 % too
    soft: the scene changed with the model, smaller deflections on a coarser surface mesh; the issue-6 target of
    0.5 % held there). The
    accuracy on independent physics is benchmarks/thesis_truth.py's (dense, 1.3 mm). Tracking holds after every
    jump of the load."""
    truth, est, states = _track_map_points("foam_beam", "beam", 1280, 720)
    loaded = np.isfinite(truth[:, 0])
    err = np.abs(est[loaded, 0] - truth[loaded, 0])
    span = 0.7575
    print(f"foam beam: median |s error| {1e3 * np.median(err):.1f} mm = {100 * np.median(err) / span:.2f} % of the "
          f"span, p90 {1e3 * np.percentile(err, 90):.1f} mm; states {np.bincount(states, minlength=4)}")
    assert np.median(err) < 0.01 * span
    assert np.percentile(err, 90) < 0.04 * span
    assert np.mean(states[loaded] != EstimateState.LOST) > 0.95


def _dot_frame(cam, T_cw, X_map, color=(0.1, 0.25, 0.95)):
    """A grey image with the dots drawn where they project (what the blob detector looks for), 3.5 px radius."""
    import cv2

    img = np.full((cam.height, cam.width, 3), 128, np.uint8)
    Xc = X_map @ T_cw[:3, :3].T + T_cw[:3, 3]
    uv = Xc[:, :2] / Xc[:, 2:] * [cam.K[0, 0], cam.K[1, 1]] + cam.K[:2, 2]
    bgr = tuple(int(255 * c) for c in color[::-1])
    for u, v in uv:
        cv2.circle(img, (round(u * 16), round(v * 16)), 56, bgr, -1, cv2.LINE_AA, shift=4)
    return img


@pytest.mark.parametrize("rest_frames,loaded_from", [(0, 12), (10, 12), (10, 0)])
def test_a_hand_measured_pose_is_corrected_from_frames_at_rest(rest_frames, loaded_from):
    """The bar's pose as a user measures it (2 mm and 1 degree off): tracked as given, the turn reads as a load
    (a cantilever's bending looks like a turn about its clamp); with ``rest_frames`` the pose is corrected from the
    first frames, where the bar is at rest, and the load is then read right. A bar already loaded in those frames
    fits a rigid turn to a fraction of a pixel too: the correction is refused, and says why."""
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.synth.scenes import BEAM_ORIGIN, aluminium_beam, beam_dots

    sc = aluminium_beam()
    sc.state["dots_ref"] = np.zeros((1, 3))  # the scene's file without rendering it; the dots are set below
    spec = validate_scene(sc.scene_yaml(sc), "dots", ".")
    scene = build_spec_models(spec)
    o = scene["objects"][0]
    m = load_model(o["model"], fields=["displacement"])
    cam = CameraModel.from_intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
    dots = beam_dots(m)
    T_true = G.make_T(t=BEAM_ORIGIN)
    err = G.make_T(G.rot_axis("y", np.deg2rad(0.8)) @ G.rot_axis("x", np.deg2rad(0.5)), [0.0015, -0.001, 0.001])
    T_given = T_true @ err
    from simreal_nodes.assimilation.tracker import tracker_config

    o["tracking"].update(measurements="dots", dots=dots.tolist(), rest_frames=rest_frames)
    tr = DeformableTracker(m, T_given, o["parameters"], cam, tracker_config(o))
    from simreal_nodes.synth.scenes import _interp_disp

    s_true, ests = 0.36, []
    for k in range(30):
        eye = [0.25 + 0.15 * np.sin(0.2 * k), -0.32, 0.42]
        T_wc = G.look_at(eye, [0.25, 0.02, 0.1])
        loaded = k >= loaded_from
        du = _interp_disp(m, [s_true], dots) if loaded else 0.0
        img = _dot_frame(cam, G.inv(T_wc), G.transform(T_true, dots + du))
        e = tr.update(T_wc, image_bgr=img)
        if k < rest_frames - 1:
            assert e.state == EstimateState.INITIALIZING and "at rest" in e.reason
        elif k >= 17:
            ests.append(e.values[0])
    err_s = np.median(np.abs(np.array(ests) - s_true))
    if rest_frames and loaded_from == 0:
        assert tr.rest_correction is not None and not tr.rest_correction["applied"]
        assert "not at rest" in tr.rest_correction["reason"]
        np.testing.assert_array_equal(tr.T_map_obj, T_given)
    elif rest_frames:
        assert tr.rest_correction is not None and tr.rest_correction["applied"]
        moved = G.transform(tr.T_map_obj, dots) - G.transform(T_true, dots)
        assert np.linalg.norm(moved, axis=1).max() < 0.5e-3, "the dots' positions are corrected to within 0.5 mm"
        assert err_s < 0.005 * SPAN
    else:
        assert tr.rest_correction is None
        assert err_s > 0.05 * SPAN, "without the correction the turn reads as a load (the test can fail)"


def test_a_constant_keeps_its_value_in_frames_that_cannot_see_it():
    """alpha_z of the boot (a constant) moves only in a deformed frame whose fit pins it (std under 5 % of its
    range): an undeformed frame or a barely bent boot leaves it where it was (it had wandered to the mirror basin
    at rest on a second view of the boot on independent physics), while the tracked theta takes the fit's value."""
    from simreal_nodes.assimilation.tracker import Estimate
    from simreal_nodes.synth.scenes import default_camera

    model = load_model(cached_model("joint_boot"), fields=["displacement"])
    params = {"theta": {"mode": "tracked", "initial": 0.2}, "alpha_z": {"mode": "constant", "initial": 0.0}}
    tr = DeformableTracker(model, np.eye(4), params, default_camera(640, 480))
    assert tr.names == ["theta", "alpha_z"]

    def conclude(x, deforming, alpha_std):
        est = Estimate(tr.names, tr.units, np.array(x), tr.frozen.copy(), np.diag([1e-8, alpha_std ** 2]))
        return tr._conclude(est, np.array(x), deforming, "test")

    conclude([0.3, 1.0], False, 1e-3)  # at rest: nothing about alpha
    assert tr.values.tolist() == [0.3, 0.0]
    conclude([0.05, 2.0], True, 2.0)  # bent a little: alpha's std is 32 % of its range
    assert tr.values.tolist() == [0.05, 0.0]
    conclude([0.4, 0.6], True, 0.01)  # bent enough to see how the boot is turned
    assert tr.values.tolist() == [0.4, 0.6]


def test_map_points_unseen_for_long_are_forgotten(beam):
    """The links are bounded by what the map still shows (a 10 000-frame soak grew the tracker without this): a
    point not observed for link_ttl_frames frames loses its link (or its static verdict); seen again, it is linked
    anew."""
    seq, scene = beam
    cam = seq["cam"]
    T_wc = Pipeline(scene, cam).loc.step(seq["gray"][60], 0).T_wc
    tr = _tracker(scene, cam, measurements="map_points", link_ttl_frames=8)
    o = scene["objects"][0]
    T_mo = G.pose7_to_matrix(o["anchor"]["pose"])
    on = G.transform(T_mo, tr.model.points[tr.cand_nodes[:20]].astype(np.float64))  # on the beam's surface
    off = on + np.array([0.0, 0.0, 0.5])  # half a metre away: static
    uv_on, uv_off = cam.project(G.transform(G.inv(T_wc), on)), cam.project(G.transform(G.inv(T_wc), off))
    tr.update(T_wc, np.arange(20), on, uv_on)
    tr.update(T_wc, np.arange(100, 120), off, uv_off)
    assert set(tr.links) == set(range(20)) and tr.static == set(range(100, 120))
    for _ in range(12):  # only the first ten on-object points go on being seen
        tr.update(T_wc, np.arange(10), on[:10], uv_on[:10])
    assert set(tr.links) == set(range(10)) and not tr.static
    tr.update(T_wc, np.arange(20), on, uv_on)
    assert set(tr.links) == set(range(20))  # linked anew
    # what a frame's observations give the fit: the linked ones, rows with a non-finite position or pixel left out
    P, q = np.r_[on[:5], off[:3]], np.r_[uv_on[:5], uv_off[:3]]
    P[1], q[2] = np.nan, np.inf
    X, uvm, nodes, w, mids, sigma = tr.map_point_measurements(np.r_[np.arange(5), np.arange(100, 103)], P, q)
    assert mids.tolist() == [0, 3, 4] and len(X) == len(uvm) == len(nodes) == len(w) == 3
    assert len(sigma) == 0  # (a fisheye's stretch only: 1 each here)
    np.testing.assert_allclose(uvm, cam.undistort_points(uv_on[[0, 3, 4]]))
    assert tr.map_point_measurements(np.arange(100, 103), off[:3], uv_off[:3]) is None  # none of them linked


class _BootScene:
    """A boot tracker (alpha_z a constant starting at 0) and synthetic map points on the model's own surface, the
    boot turned by ``alpha_deg``, at rest and with its lever at 25 degrees (the mechanics, not the accuracy)."""

    def __init__(self, alpha_deg: float, **cfg):
        from simreal_nodes.synth.scenes import default_camera

        model = load_model(cached_model("joint_boot"), fields=["displacement"])
        params = {"theta": {"mode": "tracked", "initial": 0.2}, "alpha_z": {"mode": "constant", "initial": 0.0}}
        self.cam = default_camera(640, 480)
        self.tr = DeformableTracker(model, np.eye(4), params, self.cam, TrackerConfig(measurements="map_points",
                                                                                      **cfg))
        self.alpha, self.theta = np.deg2rad(alpha_deg), np.deg2rad(25.0)
        nodes = self.tr.cand_nodes[::3]
        Rz = G.rot_axis("z", self.alpha)
        self.rest = model.points[nodes].astype(np.float64) @ Rz.T
        self.bent = np.asarray(model.deformed_points([self.theta]), np.float64)[nodes] @ Rz.T
        self.ids = np.arange(len(nodes))
        self.T_wc = G.look_at([0.45, -0.3, 0.3], [0.0, 0.0, 0.08])
        self.seen = G.transform(G.inv(self.T_wc), self.rest)[:, 2] > 0

    def show(self, bent: bool):
        """One frame: the map points (at rest in the map) seen where the rest or the bent boot has them."""
        X, s = (self.bent if bent else self.rest), self.seen
        return self.tr.update(self.T_wc, self.ids[s], self.rest[s], self.cam.project(G.transform(G.inv(self.T_wc),
                                                                                                 X[s])))

    def errors(self, est) -> tuple[float, float]:
        """(theta, alpha_z) errors in degrees."""
        return (float(np.rad2deg(abs(est.values[0] - self.theta))),
                float(np.rad2deg(abs((est.values[1] - self.alpha + np.pi) % (2 * np.pi) - np.pi))))


@pytest.mark.parametrize("search", [0, 24])
def test_constant_search_finds_how_the_boot_is_turned(search):
    """The boot family's failure (docs/family.md, development seed 3): alpha_z starts far from the boot's turn
    (registration cannot tell it: the boot is a body of revolution), the bent boot then fits no better than an unbent
    one, the frame reads 'no measurable deformation', and alpha_z is held because the frame looked undeformed: theta
    stays at 0. `constant_search` fits each frame at alpha_z samples over its range, the points relinked at each,
    until it is first seen. Synthetic map points on the model's own surface, the boot's and the lever's (the
    mechanics, not the accuracy): turned 150 degrees, lever at 25 degrees. (Without the relinking, a first version
    of the search, the boot's many points linked at the wrong turn outvoted the lever's and it failed here.)"""
    b = _BootScene(150.0, constant_search=search)
    for _ in range(3):  # the boot at rest: its points are linked
        b.show(bent=False)
    for _ in range(6):  # the lever turned: the same map points seen where the bent boot has them
        est = b.show(bent=True)
    err_theta, err_alpha = b.errors(est)
    if search:
        assert err_theta < 1.0 and err_alpha < 3.0 and est.state == EstimateState.OK
        # every observed point stays linked, none both linked and static
        assert not set(b.tr.links) & b.tr.static and len(b.tr.links) == int(b.seen.sum())
    else:  # the deadlock the search breaks (the test can fail)
        assert err_theta > 10.0


def test_the_search_relinks_every_value_as_relink_does():
    """The search of alpha_z links each group of points for all its values in one call (``_relinked_at``): for
    every value, the same links (order, nodes, weights, rest and map positions, rays, the deformation they were
    mapped in) and the same static points as setting alpha_z there and calling ``relink``. Two groups (points mapped
    at rest and in the bent boot, whose lever points leave the surface at some turns), a static point and a point
    both linked and static (``link_points`` skips it)."""
    b = _BootScene(150.0, constant_search=24)
    for _ in range(3):
        b.show(bent=False)
    tr = b.tr
    theta = np.array([b.theta])
    for pid in list(tr.links)[::3]:  # mapped in the bent boot, where the bent boot has them
        tr.links[pid] = tr.links[pid]._replace(P_map=b.bent[pid].copy(), mu=theta.copy())
    tr.static.add(10_000)
    both = next(iter(tr.links))
    tr.static.add(both)  # linked and static: link_points' test skips it, so a relink drops it
    values = [float(g) for g in np.linspace(tr.lo[1], tr.hi[1], 24, endpoint=False)]
    saved = dict(tr.links), set(tr.static), tr.values.copy()
    batched = tr._relinked_at(1, values)
    assert (dict(tr.links), set(tr.static)) == saved[:2] and np.array_equal(tr.values, saved[2])  # left as it was
    static_sizes = set()
    for g, (links, static) in zip(values, batched, strict=True):
        tr.links, tr.static, tr.values = dict(saved[0]), set(saved[1]), saved[2].copy()
        tr.values[1] = g
        tr.relink()
        assert list(links) == list(tr.links) and static == tr.static
        for pid, lk in links.items():
            ref = tr.links[pid]
            for a, r in zip(lk, ref, strict=True):
                assert (a is None) == (r is None)
                if a is not None:
                    np.testing.assert_array_equal(a, r)
        static_sizes.add(len(static))
    assert len(static_sizes) > 1  # some turns leave points off the surface: the static path is exercised
    assert not any(both in links for links, _ in batched)


@pytest.mark.parametrize("until", ["seen", "frozen"])
def test_constant_search_until_frozen_leaves_a_wrong_basin(until):
    """Development seed 2 of the boot family: the depth image's reference state put alpha_z 63 degrees off, that
    first frame counted as informative, and a search that stops once the constant is seen never ran again; alpha_z
    then wandered and was fixed 50 degrees off (theta 11 % off). ``constant_search_until: frozen`` searches every
    frame until the constant is fixed, moves it where the images are explained visibly better and restarts its
    informative frames. Here the tracker is put in that state (alpha_z 100 degrees off, one sample taken there)
    and shown the bent boot."""
    b = _BootScene(40.0, constant_search=24, constant_search_until=until)
    tr = b.tr
    for _ in range(3):  # the boot at rest: its points are linked
        b.show(bent=False)
    tr.values[1] = b.alpha - np.deg2rad(100.0)  # a wrong basin, as a reference state read from depth left it
    tr.relink()
    tr._was_deforming = True
    tr._const_samples.append(tr.values.copy())  # and one informative frame taken there
    for _ in range(6):
        est = b.show(bent=True)
    err_theta, err_alpha = b.errors(est)
    if until == "frozen":
        assert err_theta < 1.0 and err_alpha < 3.0
        assert all(abs(s[1] - est.values[1]) < np.deg2rad(3.0) for s in tr._const_samples)  # the old one dropped
    else:  # stuck where it was left (the test can fail)
        assert err_alpha > 20.0 or err_theta > 5.0


def test_feedback_holds_points_linked_at_rest_not_those_linked_deformed():
    """The map keeps the points the tracker linked at rest (flag held, thesis §4.4's scanned points); a point first
    seen on the bent boot was linked through the estimate of that moment and is left to the map's culling."""
    from simreal_nodes.assimilation.tracker import FLAG_DROP, FLAG_HELD, deformable_feedback

    b = _BootScene(0.0)
    b.show(False)
    for _ in range(6):
        est = b.show(True)
    assert est.deforming
    s = b.seen
    new_ids = b.ids[s] + 10_000  # other map points, mapped on the bent surface
    uv = b.cam.project(G.transform(G.inv(b.T_wc), b.bent[s]))
    b.tr.update(b.T_wc, np.r_[b.ids[s], new_ids], np.r_[b.rest[s], b.bent[s]], np.r_[uv, uv])
    ids, P, flags = deformable_feedback([b.tr])
    old, new = np.isin(ids, b.ids), np.isin(ids, new_ids)
    assert old.sum() > 20 and new.sum() > 20 and np.all(np.isfinite(P))
    assert np.all(flags[old] & FLAG_HELD) and not np.any(flags[new] & FLAG_HELD)
    assert not np.any(flags & FLAG_DROP)  # the fit agrees with every point


@pytest.mark.parametrize("std_share,kept", [(0.5, True), (0.1, False)])
def test_a_parameter_the_frame_does_not_measure_keeps_its_last_value(std_share, kept):
    """A tracked parameter whose standard deviation exceeds that of a uniform draw over its range (range / sqrt 12)
    was not measured by the frame: it keeps its last value, flagged (development boot 12 read its lever at 0.4
    degree where it stood at 47, from 17 points); a merely weak one (10 % of the range) takes the fit's value."""
    from simreal_nodes.assimilation.tracker import Estimate

    tr = _BootScene(0.0).tr
    tr.values[:] = [0.8, 0.0]
    tr.frozen[1] = True  # alpha_z fixed: only theta in question
    r = tr.hi[0] - tr.lo[0]
    assert std_share * r > r / np.sqrt(12) if kept else std_share * r < r / np.sqrt(12)
    est = Estimate(tr.names, tr.units, np.array([0.1, 0.0]), tr.frozen.copy(), np.diag([(std_share * r) ** 2, 0.0]))
    est = tr._conclude(est, est.values.copy(), True, "test")
    want = 0.8 if kept else 0.1
    assert est.values[0] == pytest.approx(want) and tr.values[0] == pytest.approx(want)
    assert est.state == EstimateState.LOW_CONFIDENCE and "barely observable" in est.reason
    assert ("last value kept" in est.reason) == kept


def test_dots_seen_through_a_fisheye_read_the_load():
    """The bar's dots drawn where an equidistant (fisheye) lens puts them: the tracker on that camera reads the load
    within 0.5 % of the span, each dot's residual weighed by the lens's stretch there (over 1 off the axis); the same
    frames read with the coefficients taken as plumb_bob's (what an equidistant CameraInfo was taken as) miss it."""
    import cv2

    from simreal_nodes.assimilation.tracker import tracker_config
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.synth.scenes import BEAM_ORIGIN, _interp_disp, aluminium_beam, beam_dots

    sc = aluminium_beam()
    sc.state["dots_ref"] = np.zeros((1, 3))  # the scene's file without rendering it; the dots are set below
    scene = build_spec_models(validate_scene(sc.scene_yaml(sc), "dots", "."))
    o = scene["objects"][0]
    m = load_model(o["model"], fields=["displacement"])
    fish = CameraModel(640, 480, [[336.0, 0, 319.8], [0, 336.0, 239.3], [0, 0, 1]],
                       [-0.021, 0.0043, -0.0012, 0.0001], "equidistant")
    misread = CameraModel(640, 480, fish.K, fish.D, "plumb_bob")
    dots = beam_dots(m)
    T_obj = G.make_T(t=BEAM_ORIGIN)
    o["tracking"].update(measurements="dots", dots=dots.tolist())
    trackers = {c.distortion_model: DeformableTracker(m, T_obj, o["parameters"], c, tracker_config(o))
                for c in (fish, misread)}
    s_true, ests = 0.36, {k: [] for k in trackers}
    X = G.transform(T_obj, dots + _interp_disp(m, [s_true], dots))
    for k in range(12):
        T_wc = G.look_at([0.25 + 0.12 * np.sin(0.3 * k), -0.22, 0.3], [0.25, 0.02, 0.1])
        img = np.full((480, 640, 3), 128, np.uint8)
        for u, v in fish.project(G.transform(G.inv(T_wc), X)):  # 2.2 px dots where the lens puts them
            cv2.circle(img, (round(u * 16), round(v * 16)), 35, (242, 64, 26), -1, cv2.LINE_AA, shift=4)
        for key, tr in trackers.items():
            e = tr.update(T_wc, image_bgr=img)
            if k >= 4:
                ests[key].append(e.values[0])
        if k == 0:
            meas, _ = trackers["equidistant"]._dot_measurements(img, G.inv(T_wc))
            assert meas is not None and meas[5].min() >= 1.0 and meas[5].max() > 1.1
    err = {key: np.median(np.abs(np.array(v) - s_true)) for key, v in ests.items()}
    assert err["equidistant"] < 0.005 * SPAN, err
    assert err["plumb_bob"] > 4 * err["equidistant"], err


@pytest.mark.parametrize("lens", ["none", "pincushion", "equidistant"])
def test_dots_looked_for_near_their_predictions_measure_what_the_whole_image_does(lens, monkeypatch):
    """The tracker looks for its dots only in the box of pixels that can hold a dot it would associate (within the
    association radius of a prediction, taken through the lens): the measurements are those the whole image gives,
    through no lens, a plumb_bob lens that stretches the image outwards (the box from the radius alone would be too
    small there) and a fisheye; every pixel within the radius of a prediction (ideal pixels) lies in the box."""
    import cv2

    from simreal_nodes.assimilation.tracker import tracker_config
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.synth.scenes import BEAM_ORIGIN, _interp_disp, aluminium_beam, beam_dots
    from simreal_nodes.vision import blobs

    sc = aluminium_beam()
    sc.state["dots_ref"] = np.zeros((1, 3))
    scene = build_spec_models(validate_scene(sc.scene_yaml(sc), "dots", "."))
    o = scene["objects"][0]
    m = load_model(o["model"], fields=["displacement"])
    K = [[336.0, 0, 319.8], [0, 336.0, 239.3], [0, 0, 1]]
    cam = {"none": CameraModel(640, 480, K), "pincushion": CameraModel(640, 480, K, [0.3, 0.1, 0, 0, 0]),
           "equidistant": CameraModel(640, 480, K, [-0.021, 0.0043, -0.0012, 0.0001], "equidistant")}[lens]
    dots = beam_dots(m)
    T_obj = G.make_T(t=BEAM_ORIGIN)
    o["tracking"].update(measurements="dots", dots=dots.tolist())
    tr = DeformableTracker(m, T_obj, o["parameters"], cam, tracker_config(o))
    X = G.transform(T_obj, dots + _interp_disp(m, [0.3], dots))  # loaded: the dots off their predictions
    T_wc = G.look_at([0.1, -0.3, 0.32], [0.25, 0.02, 0.1])
    img = np.full((480, 640, 3), 128, np.uint8)
    for u, v in cam.project(G.transform(G.inv(T_wc), X)):
        cv2.circle(img, (round(u * 16), round(v * 16)), 40, (242, 64, 26), -1, cv2.LINE_AA, shift=4)
    cv2.circle(img, (60, 60), 4, (242, 64, 26), -1)  # a blue spot far from the beam
    T_cw = G.inv(T_wc)
    got, n_got = tr._dot_measurements(img, T_cw)
    whole = blobs.detect_color_blobs
    monkeypatch.setattr(blobs, "detect_color_blobs", lambda bgr, color, within=None: whole(bgr, color))
    want, n_want = tr._dot_measurements(img, T_cw)
    assert got is not None and want is not None and len(got[0]) >= 12 and n_want == n_got + 1
    for a, b in zip(got, want):
        np.testing.assert_allclose(a, b, atol=1e-9)
    # no image pixel outside the box has its ideal position (the lens's undistortion, not the box's projection)
    # within the radius of a prediction: the image sampled every pixel, and every quarter pixel within 8 px of the box
    _, pred, z = tr._predicted_dots(T_cw)
    box = tr._dot_box(pred[z > 0])
    r = tr.cfg.dot_radius_px

    def near(raw):
        und = cam.undistort_points(raw)
        return np.min([np.hypot(*(und - p).T) for p in pred], axis=0) <= r

    def inside(raw):
        return (raw[:, 0] >= box[0]) & (raw[:, 0] <= box[2]) & (raw[:, 1] >= box[1]) & (raw[:, 1] <= box[3])

    coarse = np.stack(np.meshgrid(np.arange(640.0), np.arange(480.0)), axis=-1).reshape(-1, 2)
    u, v = np.meshgrid(np.arange(max(box[0] - 8, 0), min(box[2] + 8, 640), 0.25),
                       np.arange(max(box[1] - 8, 0), min(box[3] + 8, 480), 0.25))
    band = np.c_[u.ravel(), v.ravel()]
    band = band[~inside(band)]
    hit = near(coarse)
    assert hit.sum() > 12 * 300  # the discs' pixels
    assert not near(band).any() and np.all(inside(coarse[hit]))
    if lens == "pincushion":  # the radius alone in image pixels would not hold them
        lo, hi = pred.min(axis=0) - r, pred.max(axis=0) + r
        assert np.any((coarse[hit] < lo) | (coarse[hit] > hi))
