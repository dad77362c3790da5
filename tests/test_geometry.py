"""Helpers of the ROS-free geometry module: vertex normals, the winding of closed surfaces, a turn about z."""

import numpy as np
import pytest

from simreal_nodes import geometry as G

# a unit cube, 12 triangles wound counter-clockwise seen from outside
CUBE_V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
CUBE_F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def test_vertex_normals_point_out_of_a_closed_surface():
    n = G.vertex_normals(CUBE_V, CUBE_F)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    assert np.all(np.einsum("ij,ij->i", n, CUBE_V - 0.5) > 0)
    # a vertex on no triangle gets a zero normal, not NaN
    n2 = G.vertex_normals(np.r_[CUBE_V, [[5.0, 5, 5]]], CUBE_F)
    np.testing.assert_array_equal(n2[-1], 0.0)


def test_outward_triangles_keeps_flips_or_refuses():
    np.testing.assert_array_equal(G.outward_triangles(CUBE_V, CUBE_F), CUBE_F)
    flipped = CUBE_F[:, ::-1]
    out = G.outward_triangles(CUBE_V, flipped)
    np.testing.assert_array_equal(G.outward_triangles(CUBE_V, out), out)  # now outward: kept
    np.testing.assert_array_equal(np.sort(out, axis=1), np.sort(CUBE_F, axis=1))
    normals = np.cross(CUBE_V[out[:, 1]] - CUBE_V[out[:, 0]], CUBE_V[out[:, 2]] - CUBE_V[out[:, 0]])
    assert np.all(np.einsum("ij,ij->i", normals, CUBE_V[out].mean(axis=1) - 0.5) > 0)
    assert G.outward_triangles(CUBE_V, CUBE_F[:-1]) is None  # open: a missing face
    mixed = CUBE_F.copy()
    mixed[0] = mixed[0, ::-1]
    assert G.outward_triangles(CUBE_V, mixed) is None  # inconsistent winding


def test_turn_about_z_is_exact_for_a_turn_and_close_under_a_small_tilt():
    for a in (-3.0, -0.4, 0.0, 1.2, 3.1):
        assert G.turn_about_z(G.rot_axis("z", a)) == pytest.approx(a, abs=1e-12)
        T = G.make_T(G.rot_axis("x", np.deg2rad(2.0)) @ G.rot_axis("z", a), [0.1, 0.2, 0.3])
        assert G.turn_about_z(T) == pytest.approx(a, abs=np.deg2rad(0.05))
