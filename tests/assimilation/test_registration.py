"""Linking map points to model nodes (Eq. 4.10): which 3 nodes and which weights, on the real model files."""

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.registration import link, ray_weights, surface_nodes
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


def test_ray_anchor_finds_the_material_point_under_the_pixel_despite_depth_error(boot):
    """A mapped point with a depth error along its viewing ray: its foot on the surface is a neighbouring
    material point (the error's tangential part), the ray's crossing with the triangle is the point itself."""
    rng = np.random.default_rng(3)
    P, f, _b = _surface_samples(boot, 300, seed=1)
    cam = np.array([0.25, -0.3, 0.35])  # an oblique view
    D = P - cam
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    mapped = P + D * rng.normal(0.0, 0.001, (len(P), 1))  # 1 mm depth noise, along the ray
    L = link(mapped, boot.points, surface_nodes(boot), 0.02, triangles=boot.surface)
    foot = np.einsum("nk,nkd->nd", L.weights, boot.points[L.nodes])
    w = ray_weights(cam, D, boot.points[L.nodes], L.weights)
    on_ray = np.einsum("nk,nkd->nd", w, boot.points[L.nodes])
    same = np.all(np.sort(L.nodes, axis=1) == np.sort(f, axis=1), axis=1)  # the link found the true triangle
    assert same.mean() > 0.3  # the rest moved onto a neighbouring (few-mm) triangle
    e_foot = np.linalg.norm(foot - P, axis=1)[same]
    e_ray = np.linalg.norm(on_ray - P, axis=1)[same]
    assert np.median(e_ray) < 1e-9 and np.median(e_foot) > 2e-4
    assert np.allclose(w.sum(axis=1), 1.0)


def test_ray_weights_keep_the_old_weights_for_rays_that_miss_or_graze():
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]] * 3)
    old = np.full((3, 3), 1 / 3)
    o = np.array([0.2, 0.2, 1.0])
    D = np.array([[0, 0, -1.0],  # hits (0.2, 0.2, 0): weights (0.6, 0.2, 0.2)
                  [2.0, 2.0, -1.0],  # hits far outside the triangle
                  [1.0, 0.0, 0.0]])  # parallel to its plane
    w = ray_weights(o, D, tri, old)
    assert np.allclose(w[0], [0.6, 0.2, 0.2])
    assert np.allclose(w[1:], old[1:])
    assert np.allclose(ray_weights(o, -D[:1], tri[:1], old[:1]), old[:1])  # behind the camera


def test_the_depth_noise_about_a_fit_is_measured_where_the_fit_residual_cannot_see_it():
    """Points scattered about a plane with sigma 1, 3 and 12 mm: the fit's own residual (inliers within 6 mm) stays
    under 3.5 mm however large the noise; :func:`_noise` follows it, and above ``max_noise`` the registration is
    kept but doubted (its estimates are flagged: ObjectTrackers.update)."""
    from simreal_nodes.assimilation.registration import (
        Registration,
        RegistrationConfig,
        _Centres,
        _judged,
        _noise,
        _quality,
    )

    rng = np.random.default_rng(0)
    g = np.linspace(0.0, 0.3, 120)
    S = np.c_[np.repeat(g, len(g)), np.tile(g, len(g)), np.zeros(len(g) ** 2)]
    N = np.tile([0.0, 0.0, 1.0], (len(S), 1))
    cfg = RegistrationConfig()
    T = np.eye(4)
    for sigma in (0.001, 0.003, 0.012):
        P = S[::3] + np.c_[np.zeros((len(S[::3]), 2)), rng.normal(0.0, sigma, len(S[::3]))]
        _, rmse, _ = _quality(P, T, S, N, _Centres(np.array([[0.15, 0.15, 1.0]])), cfg.inlier_dist)
        noise = _noise(P, T, S, N, 3 * cfg.inlier_dist)
        assert rmse < 0.0035
        assert noise == pytest.approx(sigma, rel=0.15 if sigma < 0.01 else 0.35)
        out = _judged(Registration(T, 1.0, rmse, len(P), None), P, T, S, N, cfg)
        assert bool(out.doubt) == (sigma > cfg.max_noise), (sigma, out.noise)


def test_the_support_plane_from_a_subset_of_the_points_counts_its_inliers_among_all_of_them():
    """RANSAC on 5000 of 80 000 points (a floor under clutter, as a fused depth cloud is) finds the same floor as on
    them all, and its inliers are counted over the whole cloud; a floor that is only a fifth of the cloud still wins
    in the subset."""
    from simreal_nodes.assimilation.registration import support_inliers

    rng = np.random.default_rng(3)
    floor = np.c_[rng.uniform(-1, 1, (50_000, 2)), rng.normal(0.0, 0.001, 50_000)]
    floor = floor @ G.rot_axis("x", np.deg2rad(4.0)).T  # tilted: not an axis plane
    clutter = rng.uniform([-1, -1, 0.03], [1, 1, 1.0], (30_000, 3))
    P = np.r_[floor, clutter]
    on = np.abs(P @ G.rot_axis("x", np.deg2rad(4.0))[:, 2]) <= 0.008  # within the distance of the true floor
    whole = support_inliers(P, 0.008, 0)
    sub = support_inliers(P, 0.008, 5000)
    assert len(sub) > 49_000 and np.mean(on[sub]) > 0.99  # all of the floor's points, nearly nothing else
    assert len(np.intersect1d(sub, whole)) > 0.99 * max(len(sub), len(whole))
    # a floor of 10 000 points under 40 000 of clutter is still the dominant plane in a 5000-point subset
    P2 = np.r_[floor[:10_000], rng.uniform([-1, -1, 0.03], [1, 1, 1.0], (40_000, 3))]
    on2 = np.abs(P2 @ G.rot_axis("x", np.deg2rad(4.0))[:, 2]) <= 0.008
    sub2 = support_inliers(P2, 0.008, 5000)
    assert np.sum(sub2 < 10_000) > 9_800 and np.mean(on2[sub2]) > 0.99
