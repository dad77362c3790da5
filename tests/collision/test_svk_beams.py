"""The thesis's St. Venant-Kirchhoff crossed beams (§5.4.1, issue 21) at test size: the SVK model over the load's
position and pseudo-time (``beam_contact_nipgd``) as a contact model, and the two crossed beams through the
collision scene (a probe seen in depth presses beam a, a presses beam b) scored against the independent
large-deformation contact truth (``synth/beams_truth.py``: finer P2 tetrahedra, exact contact), the lower beam's
contact asserted."""

import textwrap

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.collision.contact import ContactTracker
from simreal_nodes.collision.scene import ContactScene
from simreal_nodes.rom.build import build_model, load_spec
from simreal_nodes.rom.state import LoadPointStates
from simreal_nodes.states import ContactPhase
from simreal_nodes.synth.beams_truth import crossed_beams_path

L, W, H, R = 0.3, 0.03, 0.01, 0.012
SPEC = """
simreal_model_spec: 1
name: svk_crossed_small
kind: beam_contact_nipgd
material: {law: saint_venant_kirchhoff, E: 3.5e+9, nu: 0.36}
geometry: {length: 0.3, width: 0.03, height: 0.01}
mesh: {cells: [6, 2, 1]}
supports:
  - {region: xmin, kind: clamped}
load: {force: 15.0, increments: 4}
nipgd: {max_terms: 60, tol: 1.0e-5}
validation_points: 0
"""
# b along a's y axis, its free end under a's middle (its load points are 50 mm apart along it: the row at its tip is
# the one under a), its centre line 25 mm from a's tip, 3 mm under a
CROSS, GAP = 0.025, 0.003
T_AB = G.make_T(G.rot_axis("z", np.pi / 2), [L - CROSS + W / 2, W / 2 - L, -H - GAP])
PRESS_POINT = np.array([L, W / 2, H])  # the probe presses a's tip, mid-width
# a camera 0.3 m under the beams looking up: the virtual beams hide nothing, it sees the probe's lower cap
CAM = CameraModel.from_intrinsics(64, 48, 200.0, 200.0, 32.0, 24.0)
T_WC = G.make_T(np.eye(3), [L - 0.01, W / 2, -0.3])


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    f = tmp_path_factory.mktemp("svk") / "spec.yaml"
    f.write_text(textwrap.dedent(SPEC))
    return build_model(load_spec(f))


def test_the_svk_beam_is_a_contact_model_over_position_and_pseudo_time(model):
    lps = LoadPointStates(model)
    assert lps.pseudo_time and not lps.probe
    assert lps.layout.names == ["s_x", "s_y", "pseudo_time"]
    P = model.points[model.load_points]
    tip = int(np.flatnonzero((P[:, 0] == L) & (P[:, 1] == W / 2))[0])
    st = lps.state(tip, 0.5)
    assert st.mu.tolist() == [L, W / 2, 0.5] and st.load_scale == 1.0
    u1 = model.deformation(lps.state(tip, 1.0))
    uh = model.deformation(st)
    # the pseudo-time is the load's share, not a scale of the displacement: SVK's response is close to linear here
    # but not linear (the beam shortens as it bends)
    dev = np.linalg.norm(uh - 0.5 * u1) / np.linalg.norm(0.5 * u1)
    assert 1e-4 < dev < 0.05
    assert -u1[:, 2].min() == pytest.approx(0.0153, rel=0.05)  # 15 N on the tip of the 300 x 30 x 10 mm beam
    # several contacts add deformations: not for a non-linear law; contact anywhere is the model's interpolation
    with pytest.raises(ValueError, match="non-linear law"):
        ContactTracker(model, np.eye(4), max_contacts=2)
    tr = ContactTracker(model, np.eye(4), anywhere=True)
    between = tr.state_at([0.275, 0.01, H], 0.7)
    assert between.mu.tolist() == pytest.approx([0.275, 0.01, 0.7])


def _probe_depth(center: np.ndarray) -> np.ndarray:
    """What the camera under the beams sees: the probe sphere alone (the ray's first hit), NaN elsewhere."""
    v, u = np.mgrid[0:CAM.height, 0:CAM.width]
    rays = np.stack([(u - CAM.K[0, 2]) / CAM.K[0, 0], (v - CAM.K[1, 2]) / CAM.K[1, 1], np.ones_like(u, float)], -1)
    o = G.transform(G.inv(T_WC), center[None])[0]  # the sphere's centre in the camera frame
    b = rays @ o
    a = np.sum(rays ** 2, axis=-1)
    disc = b ** 2 - a * (o @ o - R ** 2)
    with np.errstate(invalid="ignore"):
        t = (b - np.sqrt(disc)) / a
    return np.where(disc > 0, t, np.nan).astype(np.float32)  # depth = t (the rays' z is 1)


def test_crossed_svk_beams_follow_the_large_deformation_truth(model):
    """The probe presses a's tip 8 mm down over 40 frames and holds for 10. The truth (P2 tetrahedra, exact
    contact, SVK) has b touched from about 3 mm on; Alg. 5.1 must bring b into contact through a's drawn surface
    and hold it, with b's deformation near the truth's."""
    press = 0.008
    path = crossed_beams_path(model, PRESS_POINT, T_AB, R, press, cells=(12, 2, 2), n_travels=8)
    assert path.info["b_touch_m"] == pytest.approx(0.0035, abs=0.001)
    objs = [{"id": "b", "anchor": {"pose": G.matrix_to_pose7(T_AB)},
             "collision": {"enabled": True, "pushes": [], "threshold_m": 0.002, "step": 0.02, "decimation": 1,
                           "max_depth_m": 2.0}},
            {"id": "a", "anchor": {"pose": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]},  # exact depth: a small delta
             "collision": {"enabled": True, "pushes": ["b"], "threshold_m": 0.001, "step": 0.02, "decimation": 1,
                           "max_depth_m": 2.0}}]
    scene = ContactScene(objs, {"a": model, "b": model})
    # the probe moves 0.28 mm a frame, under Alg. 5.1's delta: it cannot pass a contact node unseen
    travels = np.r_[np.linspace(-0.003, press, 40), np.full(10, press)]
    rows = []
    for s in travels:
        center = PRESS_POINT + [0.0, 0.0, R - s]
        by_id = {c.object_id: c.state for c in scene.step(_probe_depth(center), CAM, T_WC)}
        truth = path.at(s)
        u_b = scene.trackers["b"].displacement()
        rows.append((s, by_id["a"].in_contact, by_id["b"].in_contact, truth["b"][0] > 1e-3, by_id["b"].pseudo_time,
                     truth["b"][0] / 15.0, np.sqrt(np.mean(np.sum((u_b - truth["b"][2]) ** 2, axis=1))),
                     np.sqrt(np.mean(np.sum(truth["b"][2] ** 2, axis=1)))))
    s, a_on, b_on, b_true, tau_b, tau_true, err, size = (np.array(c) for c in zip(*rows))
    print(np.c_[s * 1e3, a_on, b_on, b_true, tau_b, tau_true, err * 1e3, size * 1e3].round(3))
    assert np.all(a_on[s > 0.001])  # the probe 1 mm into a's rest surface: a in contact from then on
    # b untouched while a is still far from it (a's drawn surface runs delta ahead of the probe)
    assert not np.any(b_on[s < path.info["b_touch_m"] - 0.0015])
    hold = s == press
    assert np.all(b_on[hold]) and np.all(b_true[hold])  # the lower beam is in contact, as the truth says
    assert np.mean(b_on == b_true) >= 0.8
    assert np.all(np.abs(tau_b[hold] - tau_true[hold]) < 0.1)  # b's load within 1.5 N of the truth's
    assert np.all(err[hold] < 0.35 * size[hold])  # b's drawn surface near the truth's deformation
    assert scene.trackers["b"].state.state == ContactPhase.CONTACT
