"""Deformable tracking on rendered aluminium-beam frames (thesis §4.5.1): markers localize the camera, glued
dots measure the deformation, LM on the PGD model estimates the load position s. The estimator sees the
images only; the truth is compared afterwards. Plus the extremes the node must survive."""

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.offline import Pipeline, track_sequence
from simreal_nodes.assimilation.tracker import DeformableTracker
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
    assert np.nanmedian(std[near]) > 5 * np.nanmedian(std[far])  # low sensitivity shows as variance
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


def test_joint_boot_lever_angle_and_unknown_rotation_from_map_points():
    """Real boot turned by an unknown 20 degrees about its axis, lever 0 -> 50 -> 0 degrees: theta within
    0.5 degree (median), alpha_z estimated over the first well-deformed frames and frozen within 1 degree.
    And as a starved live graph sees it: every 10th frame, the tracker's feedback one frame late. Measured:
    theta median 0.85 deg (p90 4.5) over the loaded frames, nothing lost; before lost object tracks were
    re-acquired in a wider window: 12.4 deg (p90 33), 11 of 24 frames lost."""
    seq = sequence("joint_boot", 640, 480)
    truth, est, states = _track_map_points("joint_boot", "boot", seq=seq, every=10, feedback_delay=1)
    loaded = truth[:, 0] > 0.02
    err_theta = np.degrees(np.abs(est[loaded, 0] - truth[loaded, 0]))
    print(f"joint boot, every 10th frame, feedback 1 frame late: theta median {np.median(err_theta):.2f} deg, "
          f"p90 {np.percentile(err_theta, 90):.2f}, states {np.bincount(states, minlength=4)}")
    assert np.median(err_theta) < 1.5 and np.percentile(err_theta, 90) < 8.0
    assert not np.any(states == EstimateState.LOST)
    truth, est, states = _track_map_points("joint_boot", "boot", seq=seq)
    loaded = truth[:, 0] > 0.02  # the lever is moving
    err_theta = np.abs(est[loaded, 0] - truth[loaded, 0])
    err_alpha = abs(est[-1, 1] - truth[-1, 1])
    print(f"joint boot: theta median error {np.degrees(np.median(err_theta)):.2f} deg (p90 "
          f"{np.degrees(np.percentile(err_theta, 90)):.2f}), alpha_z error {np.degrees(err_alpha):.2f} deg, "
          f"states {np.bincount(states, minlength=4)}")
    assert np.degrees(np.median(err_theta)) < 0.5
    assert np.degrees(np.percentile(err_theta, 90)) < 1.5
    assert np.degrees(err_alpha) < 1.0
    assert np.mean(states[loaded] == EstimateState.OK) > 0.9


def test_foam_beam_load_position_from_its_own_texture():
    """Textured foam beam, a 15 N disk moved to five places (§4.5.2), filmed at the thesis's 1280 x 720: median
    load-position error under 0.5 % of the span (the issue's target; the span is the 757.5 mm between the support
    centres). Measured 1.5 mm (0.19 %), p90 12 mm, with the scene's object shift absorbing the map's drift (3.1 mm
    without it; 1.7 mm with the true camera pose, docs/tracking.md). Tracking holds after every jump of the load."""
    truth, est, states = _track_map_points("foam_beam", "beam", 1280, 720)
    loaded = np.isfinite(truth[:, 0])
    err = np.abs(est[loaded, 0] - truth[loaded, 0])
    span = 0.7575
    print(f"foam beam: median |s error| {1e3 * np.median(err):.1f} mm = {100 * np.median(err) / span:.2f} % of the "
          f"span, p90 {1e3 * np.percentile(err, 90):.1f} mm; states {np.bincount(states, minlength=4)}")
    assert np.median(err) < 0.005 * span
    assert np.percentile(err, 90) < 0.04 * span
    assert np.mean(states[loaded] != EstimateState.LOST) > 0.95
