"""Alg. 5.1 state machine: approach, press, hold, release; no data; a probe inside the object; two independent
objects."""

from dataclasses import replace

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.collision.contact import ContactTracker
from simreal_nodes.states import ContactPhase
from tests.modelkit import probe_model

T_WO = G.make_T(t=[1.0, 2.0, 0.5])


def _probe(node_world, height):
    """Points of a small probe tip ``height`` metres above a node (world frame)."""
    rng = np.random.default_rng(3)
    disc = rng.uniform(-0.002, 0.002, (30, 2))
    return np.c_[node_world[0] + disc[:, 0], node_world[1] + disc[:, 1], np.full(30, node_world[2] + height)]


def test_approach_press_hold_release():
    m = probe_model(depth=0.001)  # a shallow bump: the probe 3 mm above stays within delta while pressing
    tr = ContactTracker(m, T_WO, threshold=0.005, step=0.25)
    target = 14
    node_w = G.transform(T_WO, m.points[target][None])[0]
    # approach: far -> free, the nearest load point is reported
    for h in (0.10, 0.05, 0.02):
        st = tr.update(_probe(node_w, h))
        assert st.state == ContactPhase.FREE and st.pseudo_time == 0.0 and st.load_point == -1
        assert st.nearest_load_point == target
        assert st.min_distance == pytest.approx(h, abs=0.003)
    # press: within delta -> contact starts at the nearest load point; pseudo-time grows step by step
    taus = []
    for _ in range(4):
        st = tr.update(_probe(node_w, 0.003))
        assert st.state == ContactPhase.CONTACT and st.load_point == target and st.node == target
        taus.append(st.pseudo_time)
    assert taus == pytest.approx([0.25, 0.5, 0.75, 1.0])
    # hold at the largest precomputed deformation
    st = tr.update(_probe(node_w, 0.0))
    assert st.state == ContactPhase.CONTACT and st.pseudo_time == 1.0 and "largest" in st.reason
    # while held, the contact stays at the same load point even if the probe slides to another one
    other = G.transform(T_WO, m.points[15][None])[0]
    st = tr.update(_probe(other, -0.005))
    assert st.load_point == target
    # release: relax back to zero, then free
    rel = [replace(tr.update(_probe(node_w, 0.2))) for _ in range(4)]  # (the tracker updates one state in place)
    assert [s.state for s in rel[:3]] == [ContactPhase.RELEASING] * 3
    assert [s.pseudo_time for s in rel] == pytest.approx([0.75, 0.5, 0.25, 0.0])
    assert rel[-1].load_point == -1 and rel[-1].node == -1
    assert tr.update(_probe(node_w, 0.2)).state == ContactPhase.FREE
    # the deformation follows the state: zero when free, the model's bump when pressed
    assert np.abs(tr.displacement()).max() == 0.0


def test_contact_nodes_move_with_the_deformation():
    """Pressed surface moves away from the probe: the distance to a point hovering at the node grows."""
    m = probe_model(depth=0.01)
    tr = ContactTracker(m, T_WO, threshold=0.004, step=0.5)
    node_w = G.transform(T_WO, m.points[7][None])[0]
    st = tr.update(_probe(node_w, 0.001))
    assert st.pseudo_time == 0.5 and st.min_distance == pytest.approx(0.001, abs=0.003)
    z = tr.contact_nodes_world()[7, 2]
    assert z == pytest.approx(node_w[2] - 0.005, abs=1e-9)
    # the probe did not follow: the surface moved 5 mm away, beyond delta, so the contact relaxes (Alg. 5.1)
    st = tr.update(_probe(node_w, 0.001))
    assert st.min_distance > 0.004 and st.state == ContactPhase.RELEASING


def test_no_data_nan_points_and_probe_inside():
    m = probe_model(depth=0.001)
    tr = ContactTracker(m, T_WO, threshold=0.005, step=0.5)
    for pts in (None, np.zeros((0, 3)), np.full((10, 3), np.nan)):
        st = tr.update(pts)
        assert st.state == ContactPhase.NO_DATA and st.pseudo_time == 0.0 and st.reason
    node_w = G.transform(T_WO, m.points[20][None])[0]
    pts = np.vstack([_probe(node_w, -0.05), np.full((3, 3), np.inf)])  # the probe went through the object
    st = tr.update(pts)
    assert st.state in (ContactPhase.FREE, ContactPhase.CONTACT) and np.isfinite(st.min_distance)
    # deep inside: distance measured to contact nodes, bounded by the depth, no crash
    st = tr.update(_probe(node_w, -0.003))
    assert st.state == ContactPhase.CONTACT and st.load_point == 20
    # the data vanish while pressed: relax, stated
    st = tr.update(None)
    assert st.state == ContactPhase.RELEASING and "no valid points" in st.reason


def test_two_objects_are_independent():
    m = probe_model()
    a = ContactTracker(m, T_WO, threshold=0.005, step=0.5)
    b = ContactTracker(m, G.make_T(t=[1.0, 2.0, 0.3]), threshold=0.005, step=0.5)
    node_a = G.transform(T_WO, m.points[3][None])[0]
    pts = _probe(node_a, 0.002)
    sa, sb = a.update(pts), b.update(pts)
    assert sa.state == ContactPhase.CONTACT and sb.state == ContactPhase.FREE


def test_model_without_load_points_is_rejected():
    m = probe_model()
    m.load_points = None
    with pytest.raises(ValueError, match="no load points"):
        ContactTracker(m, T_WO)
