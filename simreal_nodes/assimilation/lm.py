"""Data assimilation by Levenberg-Marquardt on image residuals (thesis §4.4, Eq. 4.7-4.12).

Functional (Eq. 4.11):  J(mu) = sum_j rho( u_j^meas - Pi_t( X_j + R_wo R_z(alpha) dX_j(mu) ) )^2
with Huber's rho, where X_j is where point j sits undeformed (map frame), dX_j(mu) its displacement
in the object frame interpolated from its linked model nodes (Eq. 4.10), Pi_t the camera projection.

Step (Eq. 4.8):  [J^T W J + lambda diag(J^T W J)] delta = J^T W r,   W = Huber weights (IRLS).

Jacobian (Eq. 4.12):  d u / d mu_i = J_Pi(X_c) R_cw R_wo R_z(alpha) d dX_j / d mu_i
                      d u / d alpha = J_Pi(X_c) R_cw R_wo R_z(alpha) [e_z]x dX_j(mu)     (the SO(3) derivative)

with J_Pi = [[fx/Z, 0, -fx X/Z^2], [0, fy/Z, -fy Y/Z^2]] the image Jacobian. Parameters stay inside
the model's range (a step that leaves it is clipped). The covariance of the estimate is
s^2 (J^T W J)^-1 with s^2 the weighted residual variance: a parameter the images barely see (a load
at the clamp) gets a large variance instead of a wild value. The unknowns x are a model state laid out
by a :class:`~simreal_nodes.rom.state.StateLayout`: mu, then alpha_z and the object shift when it has them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from simreal_nodes.rom.state import StateLayout

Vector = NDArray[np.float64]
# mu -> (dX (N, 3) object frame, d dX / d mu (N, 3, n_mu)): e.g. DeformationView.with_jacobian
Displacement = Callable[[Vector], tuple[Vector, Vector]]
# x -> (prediction (N, 2), Jacobian (N, 2, n), valid (N,))
MeasurementModel = Callable[[Vector], tuple[Vector, Vector, NDArray[np.bool_]]]


def huber_weights(r_norm: Vector, k: float) -> Vector:
    """IRLS weights of Huber's loss on residual norms: 1 inside k, k/|r| outside."""
    w = np.ones_like(r_norm)
    big = r_norm > k
    w[big] = k / r_norm[big]
    return w


def image_jacobian(Xc: Vector, K: Vector) -> Vector:
    """(N, 2, 3): d(u, v)/d(X_c) of the pinhole projection (thesis's ^I J Pi_C)."""
    X, Y = Xc[:, 0], Xc[:, 1]
    iz = 1.0 / Xc[:, 2]
    fx, fy, s = K[0, 0], K[1, 1], K[0, 1]
    J = np.zeros((len(Xc), 2, 3))
    J[:, 0, 0] = fx * iz
    J[:, 0, 1] = s * iz
    J[:, 0, 2] = -(fx * X + s * Y) * iz * iz
    J[:, 1, 1] = fy * iz
    J[:, 1, 2] = -fy * Y * iz * iz
    return J


@dataclass
class Problem:
    """One frame's measurements and geometry.

    ``X``: (N, 3) undeformed positions of the measured points, map frame; ``uv``: (N, 2) observed ideal
    pixels; ``disp``: mu -> (dX (N, 3) object frame, ddX (N, 3, n_mu)); ``T_cw``: camera pose;
    ``R_wo``: object orientation in the map; ``layout``: what the unknowns are (mu, alpha_z: a rotation about
    the object's z axis, shift: a map-frame translation of the whole object, metres; no load_scale);
    ``sigma``: (N,) pixel noise scale of each measurement. X, T_cw and K are read once (``q0``, K times the
    undeformed points in the camera frame).
    """

    X: Vector
    uv: Vector
    disp: Displacement
    T_cw: Vector
    R_wo: Vector
    K: Vector
    layout: StateLayout
    sigma: Vector | None = None
    q0: Vector = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.layout.load_scale:
            raise ValueError("the image residuals cannot estimate a load_scale: it is set by the contact")
        self.q0 = (np.asarray(self.X, dtype=np.float64) @ self.T_cw[:3, :3].T + self.T_cw[:3, 3]) @ self.K.T


@dataclass
class Result:
    x: Vector
    cov: Vector
    rms_px: float
    inliers: int
    iterations: int
    converged: bool
    residuals: Vector = field(default_factory=lambda: np.zeros(0))
    cost: float = float("nan")
    reason: str = ""


def predict(p: Problem, x: Vector, with_jacobian: bool = True) -> tuple[Vector, Vector, Vector | None]:
    """Projected pixels (N, 2), the points' depths (N,) and, optionally, the Jacobian (N, 2, n) for x.

    Written with q = K X_c (K's last row is (0, 0, 1), so q_z = Z): u = q_xy / Z and, for any derivative
    dX_c = A dX of the displaced point, du = (K dX_c)_xy / Z - u (K dX_c)_z / Z — Eq. 4.12's image Jacobian
    J_Pi applied without forming it."""
    state = p.layout.state(x)
    dX, ddX = p.disp(state.mu)
    A = p.T_cw[:3, :3] @ p.R_wo @ state.rotation()  # object frame -> camera frame (rotation only)
    KA = p.K @ A
    q = p.q0 + dX @ KA.T
    if p.layout.shift:
        KR = p.K @ p.T_cw[:3, :3]  # a map-frame translation of every point
        q = q + KR @ state.shift
    with np.errstate(divide="ignore", invalid="ignore"):
        iz = 1.0 / q[:, 2]
        uv = q[:, :2] * iz[:, None]
    if not with_jacobian:
        return uv, q[:, 2], None
    if p.layout.alpha_z is not None:
        ez_dX = np.stack([-dX[:, 1], dX[:, 0], np.zeros(len(dX))], axis=1)  # [e_z]x dX (the SO(3) derivative)
        dXo = np.concatenate([ddX, ez_dX[:, :, None]], axis=2)
    else:
        dXo = ddX
    dq = np.matmul(KA, dXo)  # (N, 3, n)
    if p.layout.shift:
        dq = np.concatenate([dq, np.broadcast_to(KR, (len(dq), 3, 3))], axis=2)
    J = (dq[:, :2, :] - uv[:, :, None] * dq[:, 2:3, :]) * iz[:, None, None]
    return uv, q[:, 2], J


def solve(p: Problem, x0: ArrayLike, lo: Vector, hi: Vector, huber_px: float = 2.0, max_iter: int = 20,
          lam0: float = 1e-3, tol: float = 1e-7, cost_tol: float = 1e-6, refits: int = 0) -> Result:
    """Levenberg-Marquardt with Huber IRLS weights and box bounds (Eq. 4.8) on image residuals; ``refits``: see
    :func:`solve_generic`."""

    def model(x: Vector) -> tuple[Vector, Vector, NDArray[np.bool_]]:
        uv, z, J = predict(p, x)
        assert J is not None
        return uv, J, z > 0

    return solve_generic(model, p.uv, x0, lo, hi, p.sigma, huber_px, max_iter, lam0, tol, cost_tol, refits)


def solve_generic(model: MeasurementModel, obs: Vector, x0: ArrayLike, lo: Vector, hi: Vector,
                  sigma: ArrayLike | None = None, huber: float = 2.0, max_iter: int = 20, lam0: float = 1e-3,
                  tol: float = 1e-7, cost_tol: float = 1e-6, refits: int = 0) -> Result:
    """LM for any measurement model: ``model(x) -> (prediction (N, 2), Jacobian (N, 2, n), valid (N,))``;
    residual r = (obs - prediction) / sigma; Huber threshold ``huber`` in units of r.

    Converged when a step is below ``tol`` x the parameter range or below 5 % of the parameter's standard
    deviation (the steps IRLS takes around Huber's kink then only trade measurements between its two
    branches), or when the decrease of the cost the linearisation promises (gᵀδ) or achieves is below
    ``cost_tol`` x the cost.

    The normal equations are formed in units of each parameter's range (z = x / (hi - lo); a parameter whose
    bounds are equal keeps its own unit): Marquardt's damping is scale-free anyway, but its floor for a column
    with no derivative, the covariance's rank cut-off and the standard deviations are not, and in SI units a
    Young's modulus (1e10 Pa) beside a position (0.5 m) has a squared Jacobian 1e20 times smaller: it was damped
    as if unseen and reported as if exactly known (`benchmarks/lm_conditioning.py`). The covariance is
    s^2 (H + eps I)^-1 in those units, eps = 1e-10 x mean(diag H): a direction the images do not see gets a huge
    variance (flagged downstream) instead of the zero that a pseudo-inverse gives it. A parameter pinned by equal
    bounds is given, not estimated: the step and the variance are over the free parameters only, and a pinned one's
    covariance is NaN (as :mod:`.dense` reports it). A free parameter whose standard deviation exceeds its range
    (the images do not see it) does not end the solve by the 5 %-of-sd test, only by the others.

    ``refits`` > 0: after the Huber solve, up to that many more solves from where it ended, each with only the
    measurements then within 3 x ``huber`` (the inliers) weighted, re-classified before each round; it stops early
    when the classification no longer changes. ORB-SLAM2's pose optimisation does the same (four rounds, outliers by
    a chi-square test, each re-classified): Huber bounds an outlier's pull but does not remove it, and a third of
    the measurements off in one direction (object points whose tracks or links went wrong as a surface bent) bias
    the fit by their bounded pull. A round that ends with fewer inliers than it was fitted to is undone and ends the
    refits. The reported ``cost`` is the Huber cost of every measurement at the final estimate (so that fits compare
    whatever their rounds); the covariance is that of the last round's measurements."""
    x = np.clip(np.asarray(x0, dtype=np.float64), lo, hi)
    n = len(x)
    sig = np.ones(len(obs)) if sigma is None else np.asarray(sigma, dtype=np.float64)
    width = np.abs(np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64))
    fi = np.flatnonzero(width > 0)  # the free parameters: the others are pinned by equal bounds
    unit = np.where(np.isfinite(width) & (width > 0), width, 1.0)  # x = unit * z (an unbounded one: its own unit)
    uf = unit[fi]

    isig = 1.0 / sig
    active = np.ones(len(obs), bool)  # the measurements this round weighs (all but in a refit round)

    def evaluate(x: Vector) -> tuple[Vector, Vector, Vector, NDArray[np.bool_], float]:
        pred, J, ok = model(x)
        r = (obs - pred) * isig[:, None]
        valid = ok & np.isfinite(r).all(axis=1)
        if not valid.all():
            r = np.where(valid[:, None], r, 0.0)
            J = np.where(valid[:, None, None], J, 0.0)
        rn = np.sqrt(r[:, 0] ** 2 + r[:, 1] ** 2)
        use = valid & active
        w = np.where(rn > huber, huber / np.maximum(rn, 1e-300), 1.0) * use
        c = np.where(rn <= huber, rn * rn, 2 * huber * rn - huber * huber)
        return r, J * isig[:, None, None] * unit, w, valid, float(c[use].sum())

    def normal(J: Vector, w: Vector, r: Vector) -> tuple[Vector, Vector]:
        """J^T W J and J^T W r over the free parameters (range units)."""
        Jf = J.reshape(-1, n)[:, fi]
        wf = np.repeat(w, 2)
        return Jf.T @ (Jf * wf[:, None]), Jf.T @ (wf * r.ravel())

    def levenberg_marquardt(x: Vector) -> tuple[Vector, Vector, Vector, Vector, NDArray[np.bool_], float, int, bool]:
        r, J, w, valid, cost = evaluate(x)
        lam = lam0
        it = 0
        converged = len(fi) == 0  # nothing to estimate
        while it < max_iter and not converged:
            it += 1
            H, g = normal(J, w, r)
            D = np.maximum(np.diag(H), 1e-12 * max(float(np.trace(H)), 1e-300))
            try:  # the free parameters' standard deviations at this iterate (x units)
                s2 = cost / max(2 * int((valid & active).sum()) - len(fi), 1)
                sd = uf * np.sqrt(np.clip(s2 * np.diag(np.linalg.inv(H + 1e-12 * np.diag(D))), 0.0, None))
            except np.linalg.LinAlgError:
                sd = np.zeros(len(fi))
            # a parameter the images do not see (sd over its range) stops on the resolution test only: its huge sd
            # would otherwise end the solve before the combination they do see is fitted
            seen = sd < np.where(np.isfinite(width[fi]), width[fi], np.inf)
            accepted = False
            for _ in range(8):
                try:
                    step = np.zeros(n)
                    step[fi] = uf * np.linalg.solve(H + lam * np.diag(D), g)
                except np.linalg.LinAlgError:
                    lam *= 10
                    continue
                xn = np.clip(x + step, lo, hi)
                dx = np.abs(xn - x)[fi]
                small = dx <= tol * uf
                if (np.all(small) or np.all(np.where(seen, dx <= 0.05 * sd, small))
                        or float(g @ ((xn - x)[fi] / uf)) <= cost_tol * max(cost, 1e-300)):
                    converged = True  # the step is below resolution, blocked by the bounds, or promises nothing
                    break
                rn_, Jn, wn, vn, cn = evaluate(xn)
                if cn < cost:
                    if cost - cn <= cost_tol * max(cost, 1e-300):
                        converged = True
                    x, r, J, w, valid, cost = xn, rn_, Jn, wn, vn, cn
                    lam = max(lam / 10, 1e-12)
                    accepted = True
                    break
                lam *= 10
            if not accepted:
                converged = True
        return x, r, J, w, valid, cost, it, converged

    x, r, J, w, valid, cost, it, converged = levenberg_marquardt(x)
    for _ in range(refits):
        keep = valid & (np.linalg.norm(r, axis=1) <= 3 * huber)
        if np.array_equal(keep, active) or 2 * int(keep.sum()) <= len(fi):
            break
        before = (x, r, J, w, valid, cost, converged, active)
        active = keep
        x, r, J, w, valid, cost, more, converged = levenberg_marquardt(x)
        it += more
        if np.count_nonzero(valid & (np.linalg.norm(r, axis=1) <= 3 * huber)) < np.count_nonzero(keep):
            # the round lost measurements it was fitted to: its classification came from a fit in the wrong place
            # (a few points agreeing by chance); the previous round's estimate stands
            x, r, J, w, valid, cost, converged, active = before
            break
    if not active.all():  # the cost of every measurement, as a solve without refits reports it
        active = np.ones(len(obs), bool)
        cost = evaluate(x)[4]
    rnorm = np.linalg.norm(r, axis=1)
    inl = valid & (rnorm <= 3 * huber)
    dof = max(2 * int(inl.sum()) - len(fi), 1)
    s2 = float(np.sum(r[inl] ** 2)) / dof if inl.any() else float("nan")
    # a parameter pinned by equal bounds is given, not estimated: NaN, as the dense solver reports it
    cov = np.full((n, n), np.nan)
    if len(fi):
        H, _ = normal(J, w, r)
        scale = float(np.trace(H)) / len(fi)
        if np.all(np.isfinite(H)) and scale > 0:
            cov[np.ix_(fi, fi)] = np.linalg.inv(H + 1e-10 * scale * np.eye(len(fi))) * s2 * np.outer(uf, uf)
        else:  # nothing seen at all
            cov[np.ix_(fi, fi)] = np.inf
    rms = float(np.sqrt(np.mean(np.sum((r[inl] * sig[inl, None]) ** 2, axis=1)))) if inl.any() else float("nan")
    return Result(x, cov, rms, int(inl.sum()), it, converged, r, cost)
