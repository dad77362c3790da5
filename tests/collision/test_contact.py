"""Alg. 5.1 state machine: approach, press, hold, release; no data; a probe inside the object; two independent
objects."""

from dataclasses import replace

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.collision.contact import ContactTracker, PusherSurface, _line_triangle_gaps
from simreal_nodes.rom.state import ModelState
from simreal_nodes.states import ContactPhase
from tests.modelkit import plate_load_model, probe_model, strip_load_model

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


def test_a_load_point_far_more_compliant_than_the_rest_leaves_them_all_searchable():
    """The bunny: an ear tip moves 67 mm under the load that moves the body under 1 mm. Every load point that moves
    visibly (over a thousandth of the object's size) is searched; the old rule (a share of the largest) had left
    11 of the bunny's 16 out, so no contact with its body was ever found."""
    m = probe_model(depth=0.001)
    m.fields["displacement"].space[0] *= 100.0  # one load point 100 times more compliant (0.1 m: an ear)
    tr = ContactTracker(m, T_WO, threshold=0.005, step=0.25)
    assert len(tr.active) == len(m.load_points)
    node_w = G.transform(T_WO, m.points[14][None])[0]
    assert tr.update(_probe(node_w, 0.003)).state == ContactPhase.CONTACT


def test_a_load_point_inside_the_drawn_surface_is_touched_on_the_surface():
    """A scanned body's load points are nodes of its volume mesh, inside (or outside) the scan that is drawn and
    touched. The distance is measured to the surface node nearest the load point: a probe 3 mm above the surface
    (9 mm above the volume node) is in contact with a 5 mm threshold."""
    from simreal_nodes.rom.model import ReducedModel
    from simreal_nodes.rom.separated import Axis, SeparatedField
    from tests.modelkit import plate_points

    Ps, tris = plate_points(6, 0.1)
    k = len(Ps)
    P = np.vstack([Ps, Ps - [0, 0, 0.006]])  # the surface, and 6 mm under it the volume nodes that carry the loads
    space = np.zeros((k, 2 * k, 3))
    for i in range(k):
        r = np.linalg.norm(Ps - Ps[i], axis=1)
        space[i, :k, 2] = space[i, k:, 2] = -0.001 * np.exp(-(r / 0.025) ** 2)
    tau = np.linspace(0, 1, 11)
    axes = [Axis("load_point", np.arange(k, dtype=np.float64), "", "discrete", "linear"), Axis("pseudo_time", tau, "")]
    fld = SeparatedField("displacement", space, [np.eye(k), np.tile(tau, (k, 1))], axes, "m", ["x", "y", "z"])
    m = ReducedModel("slab", P, tris, "tri3", axes, {"displacement": fld}, tris, "test slab", {"law": "neo_hookean"},
                     load_points=k + np.arange(k), load_directions=np.tile([0, 0, -1.0], (k, 1)))
    tr = ContactTracker(m, T_WO, threshold=0.005, step=0.25)
    assert np.array_equal(tr.contact_nodes, np.arange(k))
    surface_w = G.transform(T_WO, Ps[14][None])[0]
    st = tr.update(_probe(surface_w, 0.003))
    assert st.state == ContactPhase.CONTACT and st.load_point == 14 and st.node == k + 14


def _sphere_points(center, radius, n=2000, seed=5):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    return np.asarray(center) + radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def test_contact_anywhere_puts_the_load_between_the_load_points():
    """A probe between two load points: snapped, the load sits at one of them; anywhere, at the probe (within a
    millimetre), and the deformation is the model's own interpolation there (half of each neighbour's bump)."""
    m = plate_load_model()  # load points every 20 mm
    target = np.array([0.03, 0.05, 0.0])  # midway between the nodes at x = 20 and 40 mm
    radius = 0.005
    probe = G.transform(T_WO, _sphere_points(target + [0, 0, radius + 0.002], radius))
    snap = ContactTracker(m, T_WO, threshold=0.012, step=0.5)  # the nearest load points are 10.8 mm from it
    anyw = ContactTracker(m, T_WO, threshold=0.012, step=0.5, anywhere=True)
    s1, s2 = snap.update(probe), anyw.update(probe)
    assert s1.in_contact and s2.in_contact
    mu_snap = snap.model_state().mu
    assert min(abs(mu_snap[0] - 0.02), abs(mu_snap[0] - 0.04)) < 1e-12  # a load point's position
    mu_any = anyw.model_state().mu
    assert mu_any == pytest.approx([0.03, 0.05], abs=1e-3)
    assert np.linalg.norm(np.asarray(s2.position)[:2] - target[:2]) < 1e-3
    u = anyw.displacement()
    assert np.isfinite(u).all() and u[:, 2].min() < 0
    # the model's interpolation: bilinear blend of the 4 neighbouring bumps, at load scale 0.5
    blend = np.zeros_like(u)
    wx = (mu_any[0] - 0.02) / 0.02
    wy = (mu_any[1] - 0.04) / 0.02
    for (ix, iy), w in (((1, 2), (1 - wx) * (1 - wy)), ((2, 2), wx * (1 - wy)), ((1, 3), (1 - wx) * wy),
                        ((2, 3), wx * wy)):
        r = np.linalg.norm(m.points - m.points[ix * 6 + iy], axis=1)
        blend[:, 2] += w * -0.01 * np.exp(-(r / 0.025) ** 2)
    assert u == pytest.approx(0.5 * blend, abs=1e-9)
    # the contact keeps its position while held, and forgets it once released
    anyw.update(probe + [0.01, 0, 0])
    assert anyw.state.position == s2.position
    for _ in range(3):
        anyw.update(probe + [0, 0, 0.2])
    assert anyw.state.load_point == -1 and not np.isfinite(anyw.state.position).any()


def test_contact_anywhere_refuses_a_model_with_discrete_load_points():
    with pytest.raises(ValueError, match="discrete"):
        ContactTracker(probe_model(), T_WO, anywhere=True)


def test_a_held_contact_stays_in_contact_while_the_pseudo_time_oscillates():
    """A probe pressed in and held: Alg. 5.1's pseudo-time settles into stepping up and down by one step about where
    the surface follows the probe; those down-steps are still the contact (one step back brings the surface within
    delta again), not a release. Moving the probe away is."""
    m = probe_model(depth=0.01)  # 1 mm of surface motion per 0.1 of pseudo-time at the node
    tr = ContactTracker(m, T_WO, threshold=0.004, step=0.1)
    node_w = G.transform(T_WO, m.points[14][None])[0]
    states, taus = [], []
    for _ in range(14):
        st = tr.update(_probe(node_w, -0.0025))  # 2.5 mm into the undeformed surface
        states.append(st.state)
        taus.append(st.pseudo_time)
    assert max(taus) == pytest.approx(0.7)
    assert sorted(taus[-2:]) == pytest.approx([0.6, 0.7]) and sorted(taus[-4:-2]) == pytest.approx([0.6, 0.7])
    assert states == [ContactPhase.CONTACT] * 14
    away = [tr.update(_probe(node_w, 0.05)).state for _ in range(3)]
    assert away == [ContactPhase.RELEASING] * 3


def test_a_stiff_object_keeps_its_load_points_searchable():
    """Every load point moving under 1e-3 of the object's size (the support rule) must not leave none to search."""
    m = probe_model(depth=1e-5)  # 0.01 mm at most on a 0.1 m plate
    tr = ContactTracker(m, T_WO, threshold=0.005)
    assert len(tr.active) == len(m.load_points)
    node_w = G.transform(T_WO, m.points[14][None])[0]
    assert tr.update(_probe(node_w, 0.002)).state == ContactPhase.CONTACT


def _sheet(center, half: float, up: bool) -> PusherSurface:
    """A square sheet of two triangles about ``center`` (world), normal +z if ``up`` else -z."""
    c = np.asarray(center, dtype=np.float64)
    V = c + np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
    F = np.array([[0, 1, 2], [0, 2, 3]]) if up else np.array([[0, 2, 1], [0, 3, 2]])
    return PusherSurface(V, F)


def test_a_pushing_virtual_surface_touches_at_a_gap_of_zero_not_within_delta():
    """Virtual-virtual contact: a pusher's drawn surface is exact, so the pushed object is in contact where the two
    surfaces meet or overlap along its push direction, not when they come within the depth's delta; a sheet facing
    away (its outward normal up, not towards the plate) cannot push."""
    m = probe_model(depth=0.01)
    tr = ContactTracker(m, T_WO, threshold=0.005, step=0.25)
    node_w = G.transform(T_WO, m.points[14][None])[0]
    st = tr.update(None, [_sheet(node_w + [0, 0, 0.003], 0.004, up=False)])  # 3 mm above: within delta, apart
    assert st.state == ContactPhase.FREE and st.pseudo_time == 0.0
    assert st.min_distance == pytest.approx(0.003) and st.nearest_load_point == 14
    st = tr.update(None, [_sheet(node_w + [0, 0, 0.003], 0.004, up=True)])  # facing away: no gap measured
    assert st.state == ContactPhase.FREE and st.min_distance == np.inf and st.reason == ""
    st = tr.update(None, [_sheet(node_w - [0, 0, 0.001], 0.004, up=False)])  # 1 mm through the surface
    assert st.state == ContactPhase.CONTACT and st.load_point == 14 and st.pseudo_time == 0.25
    assert st.min_distance == pytest.approx(-0.001)
    assert np.allclose(st.contact_point, node_w - [0, 0, 0.001])
    # held 2.5 mm into the rest surface: the drawn surface follows the sheet, the pseudo-time oscillating by one step
    # (1 mm at the node) about 0.25 where the two surfaces meet, in contact throughout
    tr = ContactTracker(m, T_WO, threshold=0.005, step=0.1)
    states, taus = [], []
    for _ in range(8):
        st = tr.update(None, [_sheet(node_w - [0, 0, 0.0025], 0.004, up=False)])
        states.append(st.state)
        taus.append(st.pseudo_time)
    assert states == [ContactPhase.CONTACT] * 8
    assert taus[:3] == pytest.approx([0.1, 0.2, 0.3]) and sorted(set(np.round(taus[2:], 6))) == [0.2, 0.3]


def test_a_held_pusher_stepping_back_does_not_release_the_object_it_presses():
    """The pusher's own held contact oscillates by one pseudo-time step: the frame its surface steps back by its
    step motion, the pressed object's gap is within its own step motion plus the pusher's: still the contact."""
    m = probe_model(depth=0.01)
    node_w = G.transform(T_WO, m.points[14][None])[0]
    runs = {}
    for slack in (0.0, 0.004):
        tr = ContactTracker(m, T_WO, threshold=0.005, step=0.1)
        for _ in range(3):  # pressed to a pseudo-time of 0.3: 3 mm down at the node
            tr.update(None, [_sheet(node_w - [0, 0, 0.004], 0.004, up=False)])
        assert tr.state.pseudo_time == pytest.approx(0.3)
        # the pusher steps back: 2.5 mm above the pressed node's drawn position; one step back of the pressed
        # object (1 mm) does not reach it, one step of the pusher (4 mm) does
        sheet = _sheet(node_w - [0, 0, 0.0005], 0.004, up=False)
        runs[slack] = tr.update(None, [PusherSurface(sheet.vertices, sheet.triangles, slack)]).state
    assert runs[0.0] == ContactPhase.RELEASING and runs[0.004] == ContactPhase.CONTACT


def test_the_gap_is_measured_along_the_push_direction_through_a_tilted_surface():
    """The line through a point against its push direction cut with a tilted facing triangle: the signed gap is
    the distance along that line (negative behind the point), not the distance to the triangle."""
    X = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [5.0, 0.0, 0.0]])
    D = np.tile([0.0, 0.0, -1.0], (3, 1))  # pushed downwards: the pusher is looked for above
    V = np.array([[-1.0, -1.0, 1.0], [1.0, -1.0, 2.0], [1.0, 1.0, 2.0], [-1.0, 1.0, 1.0]])  # z = 1.5 + x / 2
    F = np.array([[0, 2, 1], [0, 3, 2]])  # normals down (towards the points)
    t = _line_triangle_gaps(X, D, V, F)
    assert t.shape == (3, 2)
    assert np.nanmin(t[0]) == pytest.approx(1.5) and np.nanmin(t[1]) == pytest.approx(1.75)
    assert np.all(np.isinf(t[2]))  # the line misses the sheet
    assert np.all(np.isinf(_line_triangle_gaps(X, D, V, F[:, ::-1])))  # facing away: never a gap
    assert np.nanmin(_line_triangle_gaps(X + [0, 0, 2.0], D, V, F)[0]) == pytest.approx(-0.5)  # overlapping


# -- several contacts at once (max_contacts > 1) -------------------------------------------------------------------

W_STRIP = 0.03  # strip_load_model's width: its centreline at y = 15 mm
DELTA, STEP = 0.002, 0.01


def _tip(x, z):
    """A probe tip seen over the strip's centreline at x (object frame), its lowest points at height z: five points
    within 0.3 mm (world frame)."""
    local = np.array([[x, W_STRIP / 2, z], [x + 3e-4, W_STRIP / 2, z], [x - 3e-4, W_STRIP / 2, z],
                      [x, W_STRIP / 2 + 3e-4, z + 1e-4], [x, W_STRIP / 2 - 3e-4, z + 1e-4]])
    return G.transform(T_WO, local)


def _strip_bends(m, xs):
    """B[i, k]: the strip's height at xs[i] under the load at xs[k] at load scale 1 (the model; m)."""
    nodes = [3 * round(x / 0.01) + 1 for x in xs]
    return np.array([[m.deformation(ModelState(np.array([xk]), load_scale=1.0), nodes=[n])[0, 2] for xk in xs]
                     for n in nodes])


def _press(tr, probes, frames, descent=100):
    """The probes come down from 1 mm above the strip to their depths over ``descent`` frames (slower than the
    surface can follow at one step a frame), then stay; each is seen delta above where it presses."""
    for f in range(frames):
        a = max(0.0, 1.0 - f / descent) if descent else 0.0
        tr.update(np.vstack([_tip(x, (1 - a) * z + a * 0.001 + DELTA) for x, z in probes]))
    return {round(c.position[0], 3): c.pseudo_time for c in tr.contacts}


def _rms(u):
    return float(np.sqrt(np.mean(np.sum(u * u, axis=1))))


def test_two_probes_press_at_once_and_share_the_load_as_the_body_does():
    """Two probes press a linear cantilever strip at once, each to a depth of its own. Each contact's slot steps on
    the clearance at its own probe with the surface at the *summed* deformation, so the drawn surface settles at the
    coupled problem's (the loads tau solving B tau = -press, B the model's bending at each probe under each load):
    within about 1 % of its RMS, where summing what each probe would take alone (-press_i / B_ii) is 96 % off.
    (The pseudo-times themselves are ill-determined here, B's condition number 74: two loads 80 mm apart near the
    tip bend the strip alike; the surface is what is drawn and scored.) Lifting one probe releases its contact only;
    the other then takes the load it needs alone."""
    m = strip_load_model()
    tr = ContactTracker(m, T_WO, threshold=DELTA, step=STEP, anywhere=True, max_contacts=2)
    xs, coupled = [0.20, 0.28], np.array([0.3, 0.3])
    B = _strip_bends(m, xs)
    press = -B @ coupled  # 4.6 and 7.7 mm: the depths at which the coupled problem's solution is (0.3, 0.3)
    alone = -press / np.diag(B)  # 0.78, 0.47
    u1 = [m.deformation(ModelState(np.array([x]), load_scale=1.0)) for x in xs]
    truth = coupled[0] * u1[0] + coupled[1] * u1[1]
    summed = alone[0] * u1[0] + alone[1] * u1[1]
    assert _rms(summed - truth) > 0.5 * _rms(truth)  # the coupling is large here: the test can tell
    _press(tr, list(zip(xs, -press)), 200)
    assert len(tr.contacts) == 2
    assert sorted(c.position[0] for c in tr.contacts) == pytest.approx(xs, abs=1e-3)  # where the probes are
    assert tr.state.in_contact and tr.state.pseudo_time == tr.contacts[0].pseudo_time
    u = np.mean([_press(tr, list(zip(xs, -press)), 1, descent=0) and tr.displacement() for _ in range(20)],
                axis=0)
    assert _rms(u - truth) < 0.03 * _rms(truth)
    for x, p in zip(xs, press):  # under each probe, where it presses (within the oscillation)
        assert u[3 * round(x / 0.01) + 1, 2] == pytest.approx(-p, abs=0.0003)
    # lift the second probe: its contact relaxes and goes, the first one's takes over the load it needs alone
    taus = _press(tr, [(xs[0], -press[0]), (xs[1], 0.1)], 150, descent=0)
    assert list(taus) == [0.2] and taus[0.2] == pytest.approx(alone[0], abs=2.5 * STEP)


def test_contacts_are_told_apart_by_the_separation_and_capped():
    """Touches closer than the separation (2.5 load-point spacings: 25 mm on the strip) are one contact; at most
    max_contacts are tracked at once (the deepest touch first)."""
    m = strip_load_model()
    tr = ContactTracker(m, T_WO, threshold=DELTA, step=STEP, anywhere=True, max_contacts=3)
    assert tr.separation == pytest.approx(0.025)
    _press(tr, [(0.20, -0.001), (0.21, -0.001)], 5, descent=0)  # seen 1 mm over the strip: within delta
    assert len(tr.contacts) == 1
    capped = ContactTracker(m, T_WO, threshold=DELTA, step=STEP, anywhere=True, max_contacts=2)
    _press(capped, [(0.10, -0.0005), (0.20, -0.001), (0.29, -0.0015)], 1, descent=0)  # 1.5, 1, 0.5 mm over it
    assert len(capped.contacts) == 2 and capped.contacts[0].position[0] == pytest.approx(0.29, abs=1e-3)


def _slab(m, h=0.01):
    """The strip made a closed solid ``h`` thick: its nodes copied h below with the same displacement, the bottom
    face the top one reversed, the sides closed along the boundary edges (orientations consistent)."""
    from simreal_nodes.rom.model import ReducedModel
    from simreal_nodes.rom.separated import SeparatedField

    n, F = len(m.points), np.asarray(m.surface)
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    sides = [[b, a, a + n] for a, b in e[counts[inv] == 1]] + [[b, a + n, b + n] for a, b in e[counts[inv] == 1]]
    tris = np.vstack([F, F[:, ::-1] + n, np.asarray(sides)])
    fld = m.fields["displacement"]
    f2 = SeparatedField("displacement", np.concatenate([fld.space, fld.space], axis=1), fld.params, fld.axes, "m",
                        ["x", "y", "z"])
    return ReducedModel("slab_load", np.vstack([m.points, m.points - [0, 0, h]]), tris, "tri3", m.axes,
                        {"displacement": f2}, tris, "test slab", {"law": "linear_elastic"}, load_points=m.load_points,
                        load_directions=m.load_directions)


def test_a_probe_seen_between_load_points_is_touched_there():
    """Several contacts measure Alg. 5.1's distance from the drawn surface between the load points too (its samples),
    not from the load points alone: a probe 5 mm from the nearest load points, 0.3 mm over the surface, is a contact
    at its own position (the load points are over delta away). On a solid only the faces a load presses are
    sampled: a point under it (the table) is not a touch, nor is one over a support (the clamp's block)."""
    slab = _slab(strip_load_model())
    for m in (slab, strip_load_model()):
        tr = ContactTracker(m, T_WO, threshold=0.0005, step=STEP, anywhere=True, max_contacts=2)
        assert tr.update(_tip(0.155, 0.0003)).in_contact and len(tr.contacts) == 1
        assert tr.contacts[0].position[0] == pytest.approx(0.155, abs=1e-3)
        snap = ContactTracker(m, T_WO, threshold=0.0005, step=STEP, anywhere=True)  # the load points' distance
        assert not snap.update(_tip(0.155, 0.0003)).in_contact
    tr = ContactTracker(slab, T_WO, threshold=0.0005, step=STEP, anywhere=True, max_contacts=2)
    assert not tr.update(np.vstack([_tip(0.25, -0.0103), _tip(0.0, 0.0002)])).in_contact  # under it; the clamp
    assert 0 not in tr.active


def test_several_contacts_need_a_linear_model_with_load_directions():
    with pytest.raises(ValueError, match="max_contacts"):
        ContactTracker(probe_model(), T_WO, max_contacts=2)
    m = strip_load_model()
    m.load_directions = None
    with pytest.raises(ValueError, match="load directions"):
        ContactTracker(m, T_WO, max_contacts=2)
    with pytest.raises(ValueError, match="at least 1"):
        ContactTracker(strip_load_model(), T_WO, max_contacts=0)


def test_points_so_far_off_that_their_distance_overflows_touch_nothing():
    """Found by the graph fuzz (a camera pose 1e300 m off put the depth there): the KD-tree's distance overflows to
    inf and its index points past the end; the tracker, with one contact or several, reports nothing near."""
    far = np.full((50, 3), 1e300)
    for kw in ({}, {"max_contacts": 2, "anywhere": True}):
        m = strip_load_model() if kw else probe_model()
        st = ContactTracker(m, T_WO, threshold=0.005, step=0.25, **kw).update(far)
        assert st.state == ContactPhase.FREE and not st.in_contact and st.min_distance == np.inf


def test_a_contact_pressed_deeper_than_its_separation_keeps_its_probe():
    """A contact's neighbourhood is taken at rest: pressed 30 mm deep (over the 25 mm separation), the slot still
    sees its own probe, as one contact does (found in review: measured on the deformed surface, the slot lost its
    probe, released, and the probe ended up through the strip)."""
    m = strip_load_model(tip=0.1)  # 100 mm at the tip under the model's load
    depth = 0.03
    one = ContactTracker(m, T_WO, threshold=DELTA, step=STEP, anywhere=True)
    many = ContactTracker(m, T_WO, threshold=DELTA, step=STEP, anywhere=True, max_contacts=2)
    slots = []
    for tr in (one, many):
        for f in range(400):  # down over 100 frames, then held
            z = -depth * min(1.0, f / 100)
            tr.update(_tip(0.29, z + DELTA))
            if tr is many:
                slots.append(len(many.contacts))
    u_one, u_many = one.displacement()[3 * 29 + 1, 2], many.displacement()[3 * 29 + 1, 2]
    assert u_many == pytest.approx(-depth, abs=0.001) and u_one == pytest.approx(-depth, abs=0.001)
    assert max(slots) == 1 and len(many.contacts) == 1  # never a second slot for the same probe
