"""The large-deformation contact truth of the crossed beams (issue 21, ``synth/beams_truth.py``): against the
independent linear Signorini solve where the law is linear, against Euler-Bernoulli's large-deflection kinematics
where it is St. Venant-Kirchhoff, and its own contact conditions."""

from types import SimpleNamespace

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.physics import materials
from simreal_nodes.synth import beams_truth as BT
from simreal_nodes.synth import contact_truth as CT

L, W, H, E, NU, R = 0.3, 0.03, 0.01, 3.5e9, 0.36, 0.012
CELLS = (20, 2, 2)
PRESS = np.array([L - 0.015, W / 2, H])


def beam_stub(law: str):
    """What the truths read of a reduced model: its box (a node grid on the truth grid's vertices), material and
    supports."""
    g = np.meshgrid(*(np.linspace(0, s, c + 1) for s, c in zip((L, W, H), CELLS)), indexing="ij")
    return SimpleNamespace(points=np.stack([a.ravel() for a in g], axis=1),
                           material={"law": law, "E": E, "nu": NU},
                           boundary_conditions=[{"region": "xmin", "kind": "clamped", "component": None}])


def t_ab(gap: float) -> np.ndarray:
    """b along a's y axis, its free end under a's far side, its centre line 15 mm from a's tip (the two grids' nodes
    then face each other, as the linear truth's node-to-node contact needs), ``gap`` under a."""
    return G.make_T(G.rot_axis("z", np.pi / 2), [L - 0.015 + W / 2, W - L, -H - gap])


def test_field_matrix_is_the_finite_element_interpolation():
    solid = CT.beam_solid(L, W, H, materials.make_material("linear_elastic", E, NU), [{"region": "xmin"}], (6, 2, 2))
    X = solid.basis.doflocs
    comp = np.arange(solid.N) % 3
    u = np.where(comp == 0, X[0] * X[2], np.where(comp == 1, X[1] ** 2, 2 * X[0] - X[2]))  # quadratic: exact in P2
    P = np.array([[L, W, H], [0.123, 0.0177, H], [0.2, 0.0, 0.0031], [0.0, 0.01, 0.005]])
    got = (BT.field_matrix(solid, P) @ u).reshape(-1, 3)
    np.testing.assert_allclose(got, np.c_[P[:, 0] * P[:, 2], P[:, 1] ** 2, 2 * P[:, 0] - P[:, 2]], atol=1e-15)


@pytest.fixture(scope="module")
def linear_pair():
    """The same crossed beams solved twice with a linear law: by this solver and by the linear truth's Signorini
    problem (a condensed compliance, node-to-node contact: another discretisation of the contact, another code)."""
    stub = beam_stub("linear_elastic")
    lcp = CT.crossed_beams_truth(stub, PRESS, t_ab(0.003), R, cells=CELLS)
    solid = CT.beam_solid(L, W, H, materials.make_material("linear_elastic", E, NU), [{"region": "xmin"}], CELLS)
    return BT.SphereOnCrossedBeams(solid, t_ab(0.003), R, PRESS), lcp, BT.field_matrix(solid, stub.points)


@pytest.mark.parametrize("press", [0.002, 0.006])
def test_with_a_linear_law_it_agrees_with_the_signorini_truth(linear_pair, press):
    prob, lcp, Wobs = linear_pair
    c = PRESS + [0.0, 0.0, R - press]
    st = CT.follow_path(prob.solve, np.zeros(2 * prob.N), PRESS + [0.0, 0.0, R], [0, 0, -1], [press / 2, press])[-1]
    ref = lcp.solve(c)
    assert st.total["a"] == pytest.approx(ref.total["a"], rel=0.02)
    assert st.total["b"] == pytest.approx(ref.total.get("b", 0.0), rel=0.03, abs=0.02)
    assert (st.total["b"] > 0) == (press > 0.003)  # b is touched once a's tip has moved more than the 3 mm gap
    ua = (Wobs @ st.u[:prob.N]).reshape(-1, 3)
    assert np.max(np.abs(ua - ref.displacement["a"])) < 0.02 * np.max(np.abs(ref.displacement["a"]))
    assert st.penetration < 1e-8  # exact contact: the last linearization's error only
    assert np.isclose(st.gap["a"], 0.0, atol=1e-8)  # the probe touches a


def test_svk_shortens_the_bent_beam_as_euler_bernoulli_says():
    """A cantilever bent to a tip deflection w shortens by about 0.6 w^2 / L (the end load's deflection shape,
    int w'^2 / 2): St. Venant-Kirchhoff's kinematics have it, a linear law has none of it (b far below, untouched)."""
    press = 0.012
    out = {}
    for law in ("saint_venant_kirchhoff", "linear_elastic"):
        solid = CT.beam_solid(L, W, H, materials.make_material(law, E, NU), [{"region": "xmin"}], CELLS)
        prob = BT.SphereOnCrossedBeams(solid, t_ab(0.05), R, [L, W / 2, H])
        st = CT.follow_path(prob.solve, np.zeros(2 * prob.N), [L, W / 2, H + R], [0, 0, -1], [0.004, 0.008, press])[-1]
        assert st.total["b"] == 0.0
        tip = (BT.field_matrix(solid, np.array([[L, W / 2, H / 2]])) @ st.u[:prob.N]).ravel()
        out[law] = tip
    w = -out["saint_venant_kirchhoff"][2]
    assert w == pytest.approx(press, rel=0.05)  # the tip follows the probe
    assert -out["saint_venant_kirchhoff"][0] == pytest.approx(0.6 * w ** 2 / L, rel=0.15)
    assert abs(out["linear_elastic"][0]) < 0.1 * 0.6 * w ** 2 / L


def test_the_path_is_interpolated_between_its_travels_and_finds_b_s_first_touch():
    path = BT.crossed_beams_path(beam_stub("saint_venant_kirchhoff"), PRESS, t_ab(0.003), R, 0.006,
                                 cells=(10, 2, 2), n_travels=5)
    assert path.travels[0] == 0.0 and path.travels[-1] == pytest.approx(0.006)
    assert 0.002 < path.info["b_touch_m"] < 0.004  # a's tip first moves the 3 mm gap (and the crossing less)
    k = int(np.searchsorted(path.travels, path.info["b_touch_m"]))
    assert path.total[k, 1] < 0.01 and path.total[k + 1, 1] > 0.05  # inserted at the kink: b's force starts there
    assert max(path.info["interp_err_pct"]) < 1.0
    before, after = path.at(-0.001), path.at(0.006)
    assert before["a"][0] == 0.0 and np.all(before["b"][2] == 0.0)
    assert after["a"][0] > after["b"][0] > 0  # b takes part of the probe's force
    assert np.all(np.diff(path.total[:, 0]) > 0)  # the force on a grows along the stroke
