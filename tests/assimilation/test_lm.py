"""Eq. 4.7-4.12: the analytic Jacobian (model sensitivities through object -> world -> camera and the image
Jacobian, with the SO(3) derivative of alpha_z) against finite differences; LM recovers a known mu; robust
to outliers with the Huber loss; bounded."""

from dataclasses import replace

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.assimilation import lm
from simreal_nodes.rom.state import StateLayout
from tests.modelkit import beam_model

K = np.array([[520.0, 0.5, 320.0], [0, 515.0, 240.0], [0, 0, 1]])


def _layout(m, rigid_z):
    """mu, and alpha_z with a +-0.5 rad range when asked (the test beam declares no rigid parameter)."""
    return StateLayout(tuple(m.axes), (-0.5, 0.5) if rigid_z else None)


def _problem(rigid_z=False, noise=0.0, outliers=0, seed=0):
    m = beam_model(n_modes=6)
    nodes = np.arange(0, m.n_nodes, 2)
    view = m.deformation_view(nodes)
    R_wo = G.rot_axis("z", 0.3)
    T_wo = G.make_T(R_wo, [0.1, -0.2, 0.05])
    T_wc = G.make_T(G.rot_axis("x", np.pi) @ G.rot_axis("y", 0.2), [0.3, 0.0, 0.6])
    T_cw = np.linalg.inv(T_wc)
    X = G.transform(T_wo, m.points[nodes])
    disp = view.with_jacobian
    x_true = np.array([0.37] + ([0.08] if rigid_z else []))
    p = lm.Problem(X, np.zeros((len(X), 2)), disp, T_cw, R_wo, K, _layout(m, rigid_z))
    uv, _, _ = lm.predict(p, x_true, with_jacobian=False)
    rng = np.random.default_rng(seed)
    uv = uv + rng.normal(0, noise, uv.shape)
    if outliers:
        idx = rng.choice(len(uv), outliers, replace=False)
        uv[idx] += rng.uniform(20, 60, (outliers, 2))
    p.uv = uv
    return p, x_true, m


@pytest.mark.parametrize("rigid_z", [False, True])
def test_jacobian_matches_finite_differences(rigid_z):
    p, x, _ = _problem(rigid_z)
    x = x + np.r_[0.013, [0.02] * rigid_z]
    _uv, _, J = lm.predict(p, x)
    for k in range(len(x)):
        h = 1e-6
        e = np.zeros_like(x)
        e[k] = h
        fd = (lm.predict(p, x + e, False)[0] - lm.predict(p, x - e, False)[0]) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("rigid_z", [False, True])
def test_lm_recovers_parameters_within_its_covariance(rigid_z):
    p, x_true, _m = _problem(rigid_z, noise=0.2)
    lo, hi = np.r_[0.0, [-0.5] * rigid_z], np.r_[0.5, [0.5] * rigid_z]
    res = lm.solve(p, np.r_[0.2, [0.0] * rigid_z], lo, hi, huber_px=1.0, max_iter=30)
    assert res.converged
    tol = 3 * np.sqrt(np.diag(res.cov))
    assert np.all(np.abs(res.x - x_true) <= tol), (res.x, x_true, tol)
    assert res.inliers == len(p.X) and 0.1 < res.rms_px < 0.35


def test_huber_loss_limits_the_pull_of_outliers():
    p, x_true, _ = _problem(noise=0.2, outliers=2)
    robust = lm.solve(p, np.r_[0.2], np.r_[0.0], np.r_[0.5], huber_px=1.0, max_iter=30)
    plain = lm.solve(p, np.r_[0.2], np.r_[0.0], np.r_[0.5], huber_px=1e6, max_iter=30)
    assert abs(robust.x[0] - x_true[0]) < 0.03  # 6 % of the range with 2 of 26 points 20-60 px off
    assert abs(robust.x[0] - x_true[0]) < 0.5 * abs(plain.x[0] - x_true[0])
    assert robust.inliers == len(p.X) - 2


def test_refits_remove_the_bias_of_outliers_off_in_one_direction():
    """A third of the points 8-20 px off, all the same way (tracks gone wrong on a bending surface): Huber bounds
    each one's pull but their sum still biases the fit; refits with the inliers only (ORB-SLAM2's rounds) do not.
    The reported cost stays that of every measurement, so fits with and without refits compare."""
    p, x_true, _ = _problem(noise=0.3, seed=3)
    rng = np.random.default_rng(4)
    idx = rng.choice(len(p.uv), len(p.uv) // 3, replace=False)
    p.uv = p.uv.copy()
    p.uv[idx] += np.c_[rng.uniform(8, 20, len(idx)), rng.uniform(8, 20, len(idx))]
    lo, hi = np.r_[0.0], np.r_[0.5]
    huber = lm.solve(p, np.r_[0.2], lo, hi, huber_px=1.0, max_iter=30)
    refit = lm.solve(p, np.r_[0.2], lo, hi, huber_px=1.0, max_iter=30, refits=3)
    assert abs(huber.x[0] - x_true[0]) > 0.01  # the bias the test is about
    assert abs(refit.x[0] - x_true[0]) < 0.25 * abs(huber.x[0] - x_true[0])
    assert abs(refit.x[0] - x_true[0]) < 3 * np.sqrt(refit.cov[0, 0])
    assert refit.inliers == len(p.uv) - len(idx)
    again = lm.solve(p, refit.x, lo, hi, huber_px=1.0, max_iter=0)  # no step: the Huber cost at refit.x
    assert refit.cost == pytest.approx(again.cost)


def test_refits_leave_a_fit_alone_when_no_measurement_agrees():
    """Every point 100 px off: no inlier to refit on, so the refits change nothing and the fit reports no inliers
    (the tracker then says the frame is lost) instead of failing."""
    p, _, _ = _problem(noise=0.2)
    p.uv = p.uv + 100.0
    lo, hi = np.r_[0.0], np.r_[0.5]
    huber = lm.solve(p, np.r_[0.2], lo, hi, huber_px=1.0, max_iter=30)
    refit = lm.solve(p, np.r_[0.2], lo, hi, huber_px=1.0, max_iter=30, refits=3)
    assert refit.inliers == huber.inliers == 0
    assert refit.x[0] == huber.x[0] and refit.cost == huber.cost


def test_bounds_hold_when_the_data_pull_outside():
    p, _, _ = _problem()
    uv_far, _, _ = lm.predict(p, np.array([0.5]), False)
    p.uv = uv_far + (uv_far - lm.predict(p, np.array([0.3]), False)[0])  # "beyond the tip"
    res = lm.solve(p, np.array([0.25]), np.array([0.0]), np.array([0.5]), 2.0, 30)
    # the data say "past the tip": the estimate goes to the bound and stops there (clipped steps, no wild value)
    assert res.x[0] == pytest.approx(0.5, abs=1e-9) and res.converged and np.isfinite(res.cov).all()


def _shifted_problem(noise=0.0):
    """The beam problem with alpha_z and a 3-parameter object shift (map frame), true shift 4 mm."""
    p, x_true, m = _problem(rigid_z=True)
    p = lm.Problem(p.X, p.uv, p.disp, p.T_cw, p.R_wo, p.K, _layout(m, True).with_shift())
    x_true = np.r_[x_true, 0.004, -0.003, 0.002]
    uv, _, _ = lm.predict(p, x_true, with_jacobian=False)
    p.uv = uv + np.random.default_rng(1).normal(0, noise, uv.shape)
    return p, x_true


def test_object_shift_jacobian_matches_finite_differences():
    p, x = _shifted_problem()
    assert p.layout.n_mu == 1 and p.layout.size == len(x)
    x = x + np.r_[0.013, 0.02, 0.001, 0.002, -0.001]
    _, _, J = lm.predict(p, x)
    for k in range(len(x)):
        e = np.zeros_like(x)
        e[k] = 1e-6
        fd = (lm.predict(p, x + e, False)[0] - lm.predict(p, x - e, False)[0]) / 2e-6
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_lm_separates_the_load_from_an_object_shift():
    """A camera-pose error of a few mm moves every point alike; fitted as a bounded object shift it does not
    leak into mu (the load position) on a beam seen whole."""
    p, x_true = _shifted_problem(noise=0.2)
    lo, hi = np.r_[0.0, -0.5, -0.01, -0.01, -0.01], np.r_[0.5, 0.5, 0.01, 0.01, 0.01]
    res = lm.solve(p, np.r_[0.2, 0.0, 0.0, 0.0, 0.0], lo, hi, huber_px=1.0, max_iter=40)
    tol = 3 * np.sqrt(np.diag(res.cov))
    assert np.all(np.abs(res.x - x_true) <= tol), (res.x, x_true, tol)
    assert abs(res.x[0] - x_true[0]) < 0.01
    no_shift = lm.Problem(p.X, p.uv, p.disp, p.T_cw, p.R_wo, p.K, replace(p.layout, shift=False))
    biased = lm.solve(no_shift, np.r_[0.2, 0.0], lo[:2], hi[:2], huber_px=1.0, max_iter=40)
    assert biased.rms_px > 2 * res.rms_px  # without the shift the same pixels cannot be explained


def test_prediction_is_the_projected_model_state() -> None:
    """predict decodes x with the problem's StateLayout: the map-frame point is X + R_wo R_z(alpha_z) dX(mu) + shift."""
    p, x = _shifted_problem()
    x = x + np.r_[0.01, 0.05, 0.001, -0.002, 0.003]
    uv, _, _ = lm.predict(p, x, with_jacobian=False)
    dX = p.disp(x[:1])[0]
    Xw = p.X + dX @ (p.R_wo @ G.rot_axis("z", x[1])).T + x[2:]
    Xc = Xw @ p.T_cw[:3, :3].T + p.T_cw[:3, 3]
    q = Xc @ p.K.T
    np.testing.assert_allclose(uv, q[:, :2] / q[:, 2:], rtol=1e-12)


def _linear(scales, noise=0.3, seed=3, n=200):
    """obs = A (x / scales): a linear model whose unknowns are in very different units (a position in metres, a
    Young's modulus in pascals). ``scales``: each unknown's typical size; equal columns make a direction unseen."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, 2, len(scales)))
    if len(scales) == 3:
        A[:, :, 2] = A[:, :, 1]  # the third unknown moves the pixels exactly as the second does
    J = A / np.asarray(scales, dtype=np.float64)

    def model(x):
        return np.einsum("nck,k->nc", J, x), J, np.ones(n, bool)
    return model, J, rng


def test_unknowns_in_very_different_units_are_all_estimated_and_their_variance_is_honest():
    """A position (0-0.5 m) beside a modulus (5e10-9e10 Pa): both recovered from a start 10 % of each range off,
    and the standard deviations match the scatter over noisy solves. In SI units the modulus's squared Jacobian is
    1e20 times smaller: before the normal equations were scaled by the ranges it never moved and its variance was
    reported as zero (benchmarks/lm_conditioning.py)."""
    lo, hi = np.array([0.0, 5e10]), np.array([0.5, 9e10])
    model, J, rng = _linear([0.05, 4e9])
    x_true = np.array([0.21, 7.3e10])
    ests, sds = [], []
    for _ in range(30):
        obs = np.einsum("nck,k->nc", J, x_true) + rng.normal(0, 0.3, (len(J), 2))
        r = lm.solve_generic(model, obs, x_true + 0.1 * (hi - lo), lo, hi, huber=1e9)
        ests.append(r.x)
        sds.append(np.sqrt(np.diag(r.cov)))
    ests, sds = np.array(ests), np.array(sds)
    assert np.all(np.abs(ests.mean(axis=0) - x_true) < 0.01 * (hi - lo))
    scatter = ests.std(axis=0)
    assert np.all(sds.mean(axis=0) > 0.6 * scatter) and np.all(sds.mean(axis=0) < 1.6 * scatter)


def test_an_unseen_direction_gets_a_huge_variance_and_a_pinned_parameter_none():
    lo, hi = np.array([0.0, 5e10, 5e10]), np.array([0.5, 9e10, 9e10])
    model, J, rng = _linear([0.05, 4e9, 4e9])
    x_true = np.array([0.21, 7.0e10, 7.0e10])
    obs = np.einsum("nck,k->nc", J, x_true) + rng.normal(0, 0.3, (len(J), 2))
    r = lm.solve_generic(model, obs, x_true, lo, hi, huber=1e9)
    sd = np.sqrt(np.diag(r.cov))
    assert sd[0] < 0.01 * 0.5
    assert np.all(sd[1:] > 10 * (hi - lo)[1:])  # only their sum is seen: each alone is unknown
    lo2, hi2 = lo.copy(), hi.copy()
    lo2[2] = hi2[2] = 7.0e10  # pinned: given, not estimated
    r = lm.solve_generic(model, obs, x_true, lo2, hi2, huber=1e9)
    sd = np.sqrt(np.diag(r.cov))
    assert np.isnan(sd[2]) and sd[1] < 0.01 * (hi - lo)[1]
    assert abs(r.x[1] - 7.0e10) < 0.01 * (hi - lo)[1]


def test_a_free_parameter_beside_a_pinned_twin_is_still_fitted():
    """The second unknown moves the pixels exactly as the first; the first is pinned at its truth. The free one is
    fitted from a start 60 % of its range off (a step on the whole system, pinned column included, was clipped and
    ended the solve at the start)."""
    model, J, rng = _linear([1.0, 1.0, 1.0])
    x_true = np.array([0.3, 0.3, 0.3])
    obs = np.einsum("nck,k->nc", J, x_true) + rng.normal(0, 0.01, (len(J), 2))
    lo, hi = np.array([0.3, 0.0, 0.3]), np.array([0.3, 1.0, 0.3])
    r = lm.solve_generic(model, obs, np.array([0.3, 0.9, 0.3]), lo, hi, huber=1e9)
    assert abs(r.x[1] - 0.3) < 0.01 and np.isnan(r.cov[0, 0]) and np.sqrt(r.cov[1, 1]) < 0.01
