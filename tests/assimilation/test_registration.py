"""Linking map points to model nodes (Eq. 4.10): which 3 nodes and which weights, on the real model files."""

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.registration import link, surface_nodes
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model


@pytest.fixture(scope="module")
def boot():
    return load_model(cached_model("joint_boot"), fields=["displacement"])


def _surface_samples(m, n, seed=0):
    rng = np.random.default_rng(seed)
    f = m.surface[rng.integers(0, len(m.surface), n)]
    b = rng.dirichlet([1.0, 1.0, 1.0], n)
    return np.einsum("nk,nkd->nd", b, m.points[f]), f, b


def _interpolate(L, U):
    return np.einsum("nk,nkd->nd", L.weights, U[L.nodes])


def test_barycentric_link_reproduces_the_mesh_interpolation_idw_does_not(boot):
    P, f, b = _surface_samples(boot, 400)
    U = boot.deformed_points([0.86]) - boot.points
    truth = np.einsum("nk,nkd->nd", b, U[f])
    bary = link(P, boot.points, surface_nodes(boot), 0.01, triangles=boot.surface)
    idw = link(P, boot.points, surface_nodes(boot), 0.01, triangles=boot.surface, method="idw")
    e_b = np.linalg.norm(_interpolate(bary, U) - truth, axis=1)
    e_i = np.linalg.norm(_interpolate(idw, U) - truth, axis=1)
    assert np.all(bary.on_object) and np.allclose(bary.weights.sum(axis=1), 1.0)
    assert np.median(e_b) < 1e-12 and np.max(e_b) < 1e-5  # each point is a material point of its triangle
    assert np.median(e_i) > 1e-4  # inverse distances smear it (0.7 mm median here)


def test_points_off_the_surface_snap_to_their_foot_and_far_ones_are_static(boot):
    P, f, _ = _surface_samples(boot, 200, seed=1)
    A, B, C = (boot.points[f[:, j]] for j in range(3))
    n = np.cross(B - A, C - A)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    L = link(P + 0.002 * n, boot.points, surface_nodes(boot), 0.01, triangles=boot.surface)
    foot = np.einsum("nk,nkd->nd", L.weights, boot.points[L.nodes])
    assert np.all(L.on_object) and np.median(np.linalg.norm(foot - P, axis=1)) < 1e-6
    assert np.allclose(L.dist[np.linalg.norm(foot - P, axis=1) < 1e-9], 0.002, atol=1e-9)
    far = link(P + np.array([0.5, 0.0, 0.0]), boot.points, surface_nodes(boot), 0.01, triangles=boot.surface)
    assert not far.on_object.any()


def test_lever_grid_points_follow_the_rigid_rotation_exactly(boot):
    """The lever's nodes are a grid on no surface triangle: triangles of near nodes still reproduce the rigid
    motion at the point (inverse distances are ~1 mm off at 50 degrees)."""
    rng = np.random.default_rng(2)
    z = rng.uniform(0.03, 0.25, 300)
    a = rng.uniform(-0.008, 0.008, 300)
    side = rng.integers(0, 4, 300)
    P = np.c_[np.choose(side, [np.full(300, 0.008), np.full(300, -0.008), a, a]),
              np.choose(side, [a, a, np.full(300, 0.008), np.full(300, -0.008)]), z]
    lv = boot.loads["lever"]
    th = 0.86
    R = G.rot_axis(lv["axis"], th)
    truth = (P - lv["pivot"]) @ R.T + lv["pivot"] - P
    U = boot.deformed_points([th]) - boot.points
    L = link(P, boot.points, surface_nodes(boot), 0.01, triangles=boot.surface)
    on_lever = np.all(L.nodes >= boot.provenance["lever_nodes"][0], axis=1)  # (the rest is nearer the boot's folds)
    assert on_lever.mean() > 0.5
    e = np.linalg.norm(_interpolate(L, U) - truth, axis=1)[on_lever]
    assert np.percentile(e, 95) < 1e-6 and e.max() < 5e-4  # (at the bar's edges no 6 near nodes lie in its face)
    idw = link(P, boot.points, surface_nodes(boot), 0.01, method="idw")
    assert np.median(np.linalg.norm(_interpolate(idw, U) - truth, axis=1)) > 3e-4


def test_unknown_method_is_refused(boot):
    with pytest.raises(ValueError, match="barycentric"):
        link(np.zeros((1, 3)), boot.points, surface_nodes(boot), 0.01, method="nearest")
