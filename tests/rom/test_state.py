"""The model state (rom/state.py): vector and (names, values) round trips, bounds, what a message may carry, and
the one deformation every consumer evaluates, against the formulas the LM, the contact and the overlay wrote
out before it existed."""

from __future__ import annotations

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.state import LoadPointStates, ModelState, StateLayout
from tests.modelkit import beam_model, probe_model


def _rigid(model: ReducedModel) -> ReducedModel:
    model.rigid_parameters = [{"name": "alpha_z", "axis": "z", "unit": "rad", "range": [-np.pi, np.pi]}]
    return model


def test_vector_and_named_round_trip() -> None:
    m = _rigid(beam_model())
    layout = StateLayout.of(m, alpha_z=True).with_shift()
    assert layout.names == ["s", "alpha_z", "shift_x", "shift_y", "shift_z"]
    assert layout.units == ["m", "rad", "m", "m", "m"]
    x = np.array([0.31, -0.2, 0.001, 0.002, -0.003])
    st = layout.state(x)
    assert st.mu.tolist() == [0.31] and st.alpha_z == -0.2 and st.load_scale == 1.0
    assert st.shift.tolist() == [0.001, 0.002, -0.003]
    np.testing.assert_array_equal(layout.vector(st), x)
    names, values = StateLayout.of(m, alpha_z=True).named(st)
    assert names == ["s", "alpha_z"] and values == [0.31, -0.2]
    back = ModelState.from_named(m.axes, names, values)
    assert back.mu.tolist() == [0.31] and back.alpha_z == -0.2 and back.load_scale == 1.0
    contact = StateLayout(tuple(m.axes), load_scale=True)
    assert contact.names == ["s", "load_scale"]
    np.testing.assert_array_equal(contact.vector(contact.state([0.2, 0.7])), [0.2, 0.7])
    with pytest.raises(ValueError, match="expected 2 values"):
        contact.state([0.2])


def test_bounds() -> None:
    m = _rigid(beam_model())
    lo, hi = StateLayout.of(m, alpha_z=True, load_scale=True, shift=True).bounds(shift_m=0.01)
    np.testing.assert_array_equal(lo, [0.0, -np.pi, 0.0, -0.01, -0.01, -0.01])
    np.testing.assert_array_equal(hi, [0.5, np.pi, 1.0, 0.01, 0.01, 0.01])
    with pytest.raises(ValueError, match="no rigid parameter 'alpha_z'"):
        StateLayout.of(beam_model(), alpha_z=True)


def test_from_named_unknown_missing_non_finite_out_of_range() -> None:
    axes = beam_model().axes  # s in [0, 0.5]
    with pytest.raises(ValueError, match=r"unknown parameter 'theta'.*s, alpha_z, load_scale"):
        ModelState.from_named(axes, ["s", "theta"], [0.1, 0.2])
    with pytest.raises(ValueError, match="2 parameter names for 1 values"):
        ModelState.from_named(axes, ["s", "alpha_z"], [0.1])
    st = ModelState.from_named(axes, [], [])
    assert st.mu.tolist() == [0.0] and st.alpha_z == 0.0 and st.load_scale == 1.0  # nothing known: lower bound
    st = ModelState.from_named(axes, ["s", "alpha_z", "load_scale"], [np.nan, np.inf, np.nan])
    assert st.mu.tolist() == [0.0] and st.alpha_z == 0.0 and st.load_scale == 0.0
    assert ModelState.from_named(axes, ["s"], [7.0]).mu.tolist() == [0.5]
    assert ModelState.from_named(axes, ["s"], [-7.0]).mu.tolist() == [0.0]
    st = ModelState.from_named(axes, ["load_scale", "alpha_z", "s"], [-0.5, 4.0, 0.25])
    assert st.mu.tolist() == [0.25] and st.alpha_z == 4.0 and st.load_scale == -0.5  # extras are not clipped


@pytest.mark.parametrize("alpha, scale", [(0.0, 1.0), (0.3, 1.0), (0.0, 0.4), (-0.7, 0.25)])
def test_deformation_is_scaled_then_rotated_field(alpha: float, scale: float) -> None:
    m = beam_model(n_modes=5)
    st = ModelState(np.array([0.37]), alpha, scale)
    nodes = np.arange(0, m.n_nodes, 3)
    u = m.field("displacement").evaluate([0.37], nodes)
    expected = scale * u @ G.rot_axis("z", alpha).T  # the overlay's formula
    np.testing.assert_allclose(m.deformation(st, nodes), expected, rtol=1e-12, atol=1e-18)
    view = m.deformation_view(nodes)
    np.testing.assert_allclose(view(st), expected, rtol=1e-12, atol=1e-18)
    # a live truncation of the view is the truncated field
    u2 = scale * m.field("displacement").evaluate([0.37], nodes, 2) @ G.rot_axis("z", alpha).T
    np.testing.assert_allclose(view(st, 2), u2, rtol=1e-12, atol=1e-18)
    with pytest.raises(ValueError, match="5 modes; 6"):
        view(st, 6)


def test_identity_extras_leave_the_field_untouched() -> None:
    m = beam_model()
    st = ModelState(np.array([0.2]))
    np.testing.assert_array_equal(m.deformation(st), m.displacement([0.2]))


def test_view_jacobian_is_the_field_sensitivity_at_interpolated_points() -> None:
    m = beam_model(n_modes=4)
    nodes = np.array([[0, 1, 2], [10, 11, 12]])
    w = np.array([[0.2, 0.3, 0.5], [0.6, 0.2, 0.2]])
    u, J = m.deformation_view(nodes, weights=w).with_jacobian(np.array([0.3]))
    f = m.field("displacement")
    ref_u = np.einsum("nk,nkc->nc", w, f.evaluate([0.3], nodes.ravel()).reshape(2, 3, 3))
    ref_J = np.einsum("nk,nkc->nc", w, f.sensitivity([0.3], 0, nodes.ravel()).reshape(2, 3, 3))
    np.testing.assert_allclose(u, ref_u, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(J[:, :, 0], ref_J, rtol=1e-12, atol=1e-18)


def test_load_point_states_probe_and_linear() -> None:
    probe = probe_model()
    lps = LoadPointStates(probe)
    assert lps.probe and lps.layout.names == ["load_point", "pseudo_time"] and len(lps) == probe.n_nodes
    st = lps.state(7, 0.4)
    assert st.mu.tolist() == [7.0, 0.4] and st.load_scale == 1.0
    np.testing.assert_array_equal(probe.deformation(st), probe.displacement([7.0, 0.4]))
    beam = beam_model()
    beam.load_points = np.arange(1, beam.n_nodes, 2)
    lin = LoadPointStates(beam)
    assert not lin.probe and lin.layout.names == ["s", "load_scale"]
    st = lin.state(4, 0.3)
    x = beam.points[beam.load_points[4], 0]
    assert st.mu.tolist() == [x] and st.load_scale == 0.3
    # the contact's formula for a linear model: the pseudo-time times the load at the load point's position
    np.testing.assert_array_equal(beam.deformation(st), 0.3 * beam.displacement([x]))
    np.testing.assert_array_equal(lin.layout.vector(st), [x, 0.3])


def test_load_point_states_reject_what_a_contact_cannot_drive() -> None:
    beam = beam_model()
    with pytest.raises(ValueError, match="no load points"):
        LoadPointStates(beam)
    beam.load_points = np.arange(3)
    beam.material = {"law": "neo_hookean"}
    with pytest.raises(ValueError, match="not linear"):
        LoadPointStates(beam)
    beam.material = {"law": "linear_elastic"}
    beam.axes[0].name = "E"
    with pytest.raises(ValueError, match="not load positions"):
        LoadPointStates(beam)


def test_a_message_with_several_contacts_gives_one_state_each() -> None:
    """A collision with max_contacts > 1 sends the k-th contact's parameters as name@k: each is read as one contact
    is, in order; a malformed suffix is an error, not a silently dropped contact."""
    axes = beam_model().axes
    sts = ModelState.from_named_contacts(axes, ["s", "load_scale", "s@2", "load_scale@2", "s@3", "load_scale@3"],
                                         [0.1, 0.5, 0.3, 0.25, 0.45, 0.1])
    assert [s.mu.tolist() for s in sts] == [[0.1], [0.3], [0.45]]
    assert [s.load_scale for s in sts] == [0.5, 0.25, 0.1]
    (one,) = ModelState.from_named_contacts(axes, ["s"], [0.2])
    assert one.mu.tolist() == [0.2] and one.load_scale == 1.0
    for bad in ("s@1", "s@x", "s@", "s@02"):
        with pytest.raises(ValueError, match="@2"):
            ModelState.from_named_contacts(axes, ["s", bad], [0.1, 0.2])
    with pytest.raises(ValueError, match="unknown parameter"):
        ModelState.from_named_contacts(axes, ["s", "theta@2"], [0.1, 0.2])
    for names in (["s", "s@3"], ["s@2", "load_scale@2"]):  # a gap; a further contact without the first
        with pytest.raises(ValueError, match="without gaps"):
            ModelState.from_named_contacts(axes, names, [0.1, 0.2])
