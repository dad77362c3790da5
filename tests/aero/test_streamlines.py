"""Streamlines: exact in uniform and in rotating flow, mirrored across the symmetry plane, stopped by the body."""

from __future__ import annotations

import numpy as np
import pytest

from simreal_nodes.aero.grid import AeroGrid
from simreal_nodes.aero.streamlines import FlowField, section, seed_rake, trace, tubes

GRID = AeroGrid(lo=(-2.0, 0.0, 0.0), hi=(2.0, 2.0, 2.0), shape=(40, 20, 20))


def test_uniform_flow_gives_straight_lines_of_the_set_length() -> None:
    v = np.tile([2.0, 0.0, 0.5], (GRID.size, 1))
    lines = trace(FlowField(GRID, v), seed_rake(-1.8, (-0.5, 0.5), (0.5, 1.0), 3, 2), step=0.05, n_steps=20)
    assert len(lines) == 6
    d = np.array([2.0, 0.0, 0.5]) / np.linalg.norm([2.0, 0.0, 0.5])
    for ln in lines:
        seg = np.diff(ln[:, :3], axis=0)
        assert np.allclose(seg, 0.05 * d, atol=1e-9)
        assert np.allclose(ln[:, 3], np.linalg.norm([2.0, 0.0, 0.5]))


def test_the_half_field_is_mirrored_across_the_symmetry_plane() -> None:
    """v = (1, y, 0) stored on y >= 0 only: the mirror must give v_y = y on y < 0 too (the sign flipped and the rows
    reversed), continuous through y = 0."""
    P = GRID.points()
    f = FlowField(GRID, np.column_stack([np.ones(len(P)), P[:, 1], np.zeros(len(P))]))
    q = np.array([[0.3, y, 1.0] for y in (-0.8, -0.31, -0.02, 0.0, 0.02, 0.31, 0.8)])
    assert np.allclose(f(q), np.column_stack([np.ones(len(q)), q[:, 1], np.zeros(len(q))]), atol=1e-9)


def test_rigid_rotation_keeps_its_radius() -> None:
    """v = (-(z - 1), 0, x) about the axis (0, y, 1): circles (trilinear interpolation of a linear field is exact;
    what is left is RK4's drift)."""
    P = GRID.points()
    f = FlowField(GRID, np.column_stack([-(P[:, 2] - 1.0), np.zeros(len(P)), P[:, 0]]))
    ln = trace(f, np.array([[0.5, -0.3, 1.0]]), step=0.02, n_steps=150)[0]
    r = np.hypot(ln[:, 0], ln[:, 2] - 1.0)
    assert np.abs(r - 0.5).max() < 2e-3


def test_a_line_stops_at_the_body_and_tubes_are_closed_rings() -> None:
    P = GRID.points()
    body = np.linalg.norm(P - [0.0, 0.0, 1.0], axis=1) < 0.4
    v = np.tile([1.0, 0.0, 0.0], (GRID.size, 1))
    v[body] = 0.0
    ln = trace(FlowField(GRID, v), np.array([[-1.8, 0.05, 1.0]]), step=0.05, n_steps=200)[0]
    assert ln[-1, 0] < -0.3  # stopped in front of the sphere, did not cross it
    V, T, C = tubes([ln], radius=0.01, sides=5)
    assert V.shape == (5 * len(ln), 3) and T.shape == (2 * 5 * (len(ln) - 1), 3) and C.shape == V.shape
    assert np.allclose(np.linalg.norm(V.reshape(len(ln), 5, 3) - ln[:, None, :3], axis=2), 0.01)
    with pytest.raises(ValueError):
        FlowField(GRID, np.zeros((10, 3)))


def test_a_section_is_the_grid_plane_coloured_by_value_without_the_body() -> None:
    P = GRID.points()
    lut = np.linspace(0.0, 1.0, 256)[:, None].repeat(3, axis=1)
    keep = np.linalg.norm(P - [0.0, 0.0, 1.0], axis=1) > 0.4
    V, T, C = section(GRID, P[:, 0], axis=1, index=0, lut=lut, vmin=-2.0, vmax=2.0, keep=keep)
    assert V.shape == (40 * 20, 3) and np.allclose(V[:, 1], GRID.axes()[1][0])
    assert np.allclose(C[:, 0], np.floor((V[:, 0] + 2.0) / 4.0 * 255.0) / 255.0, atol=1 / 255)  # colour = x
    full = 2 * 39 * 19
    assert 0.8 * full < len(T) < full  # the quads with a corner in the sphere are left out
    centre = T[np.all(np.abs(V[T][:, :, [0, 2]] - [0.0, 1.0]).max(axis=2) < 0.2, axis=1)]
    assert len(centre) == 0
