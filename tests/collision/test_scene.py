"""One collision frame over a scene's objects (ContactScene): pusher order, real points from depth, and
virtual-virtual contact -- an upper plate pressed by a probe seen in depth bends onto a lower plate it crosses, and
the lower plate is touched only once the upper one's drawn surface reaches it (a gap of zero, not delta)."""

import itertools

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.collision.contact import outward_triangles
from simreal_nodes.collision.scene import ContactScene, pusher_order
from simreal_nodes.states import ContactPhase
from tests.modelkit import plate_load_model, probe_model

CAM = CameraModel.from_intrinsics(64, 48, 100.0, 100.0, 32.0, 24.0)
# looking straight down from 0.3 m above the plates' node 14 (0.04, 0.04): camera z = -world z, camera y = -world y
T_WC = G.make_T(np.diag([1.0, -1.0, -1.0]), [0.04, 0.04, 0.3])
GAP = 0.006  # the upper plate lies this far above the lower one


def test_pushers_go_first():
    objs = [{"id": "lower", "collision": {"pushes": []}}, {"id": "upper", "collision": {"pushes": ["lower"]}},
            {"id": "free", "collision": {"pushes": []}}]
    assert [o["id"] for o in pusher_order(objs)] == ["upper", "lower", "free"]
    cyc = [{"id": "x", "collision": {"pushes": ["y"]}}, {"id": "y", "collision": {"pushes": ["x"]}}]
    assert sorted(o["id"] for o in pusher_order(cyc)) == ["x", "y"]


def _obj(oid, z, pushes=()):
    return {"id": oid, "anchor": {"pose": [0.0, 0.0, z, 0.0, 0.0, 0.0, 1.0]},
            "collision": {"enabled": True, "pushes": list(pushes), "threshold_m": 0.005, "step": 0.5,
                          "decimation": 1, "max_depth_m": 2.0}}


def _scene():
    upper = probe_model()
    upper.surface = np.vstack([upper.surface, upper.surface[:, ::-1]])  # both faces of the plate: its lower one
    # faces the lower plate
    objects = [_obj("lower", 0.0), _obj("upper", GAP, pushes=["lower"])]  # file order: the pushed one first
    return ContactScene(objects, {"lower": probe_model(), "upper": upper})


def _probe_depth(height: float) -> np.ndarray:
    """Depth of a small probe tip ``height`` above the upper plate at node 14, nothing else seen (NaN)."""
    d = np.full((CAM.height, CAM.width), np.nan, np.float32)
    d[23:26, 31:34] = 0.3 - (GAP + height)
    return d


def test_a_pressed_upper_plate_pushes_the_lower_one():
    scene = _scene()
    assert [o["id"] for o in scene.objects] == ["upper", "lower"]
    # the probe 2 mm above the upper plate: only the upper one is within delta
    up, low = scene.step(_probe_depth(0.002), CAM, T_WC)
    assert up.object_id == "upper" and up.state.state == ContactPhase.CONTACT
    assert up.state.load_point == 14 and up.source == "depth"
    assert up.state.points_used == 9
    # the upper plate bent 5 mm down at node 14 (pseudo-time 0.5) in this frame: 1 mm above the lower plate now.
    # That is within the lower plate's delta (5 mm), but two drawn surfaces 1 mm apart do not touch: delta is the
    # depth sensor's margin, a pushing virtual surface is exact
    assert low.object_id == "lower" and low.source == "depth+upper"
    assert low.state.state == ContactPhase.FREE and low.state.pseudo_time == 0.0
    assert low.state.nearest_load_point == 14
    assert low.state.min_distance == pytest.approx(0.001, abs=1e-6)  # the gap along the push direction (-z)
    # the probe pushes on, 3 mm into the upper plate's rest surface: the upper plate goes to its full 10 mm, 4 mm
    # through the lower plate's rest surface: the lower plate is in contact at node 14, its gap -4 mm
    up, low = scene.step(_probe_depth(-0.003), CAM, T_WC)
    assert up.state.state == ContactPhase.CONTACT and up.state.pseudo_time == 1.0
    assert low.state.state == ContactPhase.CONTACT and low.state.load_point == 14
    assert low.state.min_distance == pytest.approx(-0.004, abs=1e-6)
    assert low.state.pseudo_time == 0.5  # one step of Alg. 5.1 per frame
    assert np.allclose(low.state.contact_point, [0.04, 0.04, GAP - 0.010], atol=1e-9)  # where the surfaces meet


def test_the_probe_alone_does_not_reach_the_lower_plate():
    scene = _scene()
    up, low = scene.step(_probe_depth(0.02), CAM, T_WC)  # 2 cm above: nobody in contact, no surface pushed
    assert up.state.state == ContactPhase.FREE and low.state.state == ContactPhase.FREE and low.source == "depth"
    assert low.state.min_distance == pytest.approx(GAP + 0.02, abs=3e-3)


def test_no_pose_and_no_depth_are_stated():
    scene = _scene()
    for r in scene.step(_probe_depth(0.002), CAM, None):  # (the tracker's own reason comes first)
        assert r.state.state == ContactPhase.NO_DATA and r.state.reason
    empty = np.full((CAM.height, CAM.width), np.nan, np.float32)
    for r in scene.step(empty, CAM, T_WC):
        assert r.state.state == ContactPhase.NO_DATA and r.state.reason


def test_decimation_override():
    scene = _scene()
    scene.decimation = 4  # every 4th pixel: the 3x3 patch at rows/cols 23..25 keeps (24, 32) only
    up, _ = scene.step(_probe_depth(0.002), CAM, T_WC)
    assert up.state.points_used == 1 and up.state.state == ContactPhase.CONTACT


def test_collision_anywhere_reaches_the_tracker_and_is_refused_for_discrete_load_points():
    """`collision.anywhere` from the scene file: a linear model's tracker places the load at the probe, a probe
    model's scene is refused with a reason instead of silently snapping."""
    obj = _obj("plate", 0.0)
    obj["collision"].update(anywhere=True, threshold_m=0.012)
    scene = ContactScene([obj], {"plate": plate_load_model()})  # load points every 20 mm
    assert scene.trackers["plate"].anywhere
    d = np.full((CAM.height, CAM.width), np.nan, np.float32)
    d[23:26, 34:37] = 0.3 - 0.002  # a probe tip 2 mm above (48.9, 40) mm: columns 34-36 are 6-12 mm right of 32
    (c,) = scene.step(d, CAM, T_WC)
    assert c.state.in_contact and c.state.load_point == 14  # the nearest load point, (40, 40) mm
    x = 0.04 + 3 * 0.298 / 100.0
    assert scene.trackers["plate"].model_state().mu == pytest.approx([x, 0.04], abs=1e-3)
    with pytest.raises(ValueError, match="discrete"):
        ContactScene([obj], {"plate": probe_model()})


def test_an_inward_oriented_pusher_surface_is_turned_outward():
    """A closed surface stored with inward normals would never face what it presses: it is turned round."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # outward (volume +1/6)
    assert np.array_equal(outward_triangles(V + 5.0, F), F)
    assert np.array_equal(outward_triangles(V, F[:, ::-1]), F)


def test_the_lower_plate_stays_pressed_while_the_upper_one_oscillates_about_its_hold():
    """The probe holds the upper plate at its full bend; Alg. 5.1 then steps its pseudo-time down and up by one step
    each frame. The frames it steps back, its surface rises by its step (1 mm) off the lower plate: that is the
    pusher's own hold, passed on as its step back this frame, and the lower plate stays in contact throughout."""
    upper = probe_model()
    upper.surface = np.vstack([upper.surface, upper.surface[:, ::-1]])
    objects = [_obj("lower", 0.0), _obj("upper", GAP, pushes=["lower"])]
    for o in objects:
        o["collision"]["step"] = 0.1
    objects[0]["collision"]["threshold_m"] = 0.0005  # the probe's depth points never reach the lower plate
    scene = ContactScene(objects, {"lower": probe_model(), "upper": upper})
    runs = []
    for _ in range(16):
        up, low = scene.step(_probe_depth(-0.004), CAM, T_WC)
        runs.append((up.state.pseudo_time, scene._stepped_back["upper"], low.state.state, low.state.min_distance))
    assert [r[2] for r in runs[:6]] == [ContactPhase.FREE] * 6  # the upper plate comes down: 1 mm a frame
    assert runs[5][3] == pytest.approx(0.0, abs=1e-9)  # touching, not through: no contact yet
    assert [r[2] for r in runs[6:]] == [ContactPhase.CONTACT] * 10
    backs = [r for a, r in itertools.pairwise(runs[9:]) if r[0] < a[0]]  # the upper plate's steps back
    assert len(backs) == 3 and all(r[1] == pytest.approx(0.001) and r[3] == pytest.approx(0.001) for r in backs)
    assert all(r[1] == 0.0 for a, r in itertools.pairwise(runs) if r[0] >= a[0])
