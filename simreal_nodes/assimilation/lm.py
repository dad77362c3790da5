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
at the clamp) gets a large variance instead of a wild value.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simreal_nodes import geometry as G


def huber_weights(r_norm: np.ndarray, k: float) -> np.ndarray:
    """IRLS weights of Huber's loss on residual norms: 1 inside k, k/|r| outside."""
    w = np.ones_like(r_norm)
    big = r_norm > k
    w[big] = k / r_norm[big]
    return w


def image_jacobian(Xc: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 2, 3): d(u, v)/d(X_c) of the pinhole projection (thesis's ^I J Pi_C)."""
    X, Y, Z = Xc[:, 0], Xc[:, 1], Xc[:, 2]
    fx, fy, s = K[0, 0], K[1, 1], K[0, 1]
    J = np.zeros((len(Xc), 2, 3))
    J[:, 0, 0] = fx / Z
    J[:, 0, 1] = s / Z
    J[:, 0, 2] = -(fx * X + s * Y) / Z ** 2
    J[:, 1, 1] = fy / Z
    J[:, 1, 2] = -fy * Y / Z ** 2
    return J


@dataclass
class Problem:
    """One frame's measurements and geometry.

    ``X``: (N, 3) undeformed positions of the measured points, map frame; ``uv``: (N, 2) observed ideal
    pixels; ``disp``: callable mu -> (dX (N, 3) object frame, ddX (N, 3, n_mu)); ``T_cw``: camera pose;
    ``R_wo``: object orientation in the map; ``sigma``: (N,) pixel noise scale of each measurement.
    """

    X: np.ndarray
    uv: np.ndarray
    disp: callable
    T_cw: np.ndarray
    R_wo: np.ndarray
    K: np.ndarray
    sigma: np.ndarray | None = None
    rigid_z: bool = False  # estimate alpha_z (the last parameter) as a rotation about the object's z axis


@dataclass
class Result:
    x: np.ndarray
    cov: np.ndarray
    rms_px: float
    inliers: int
    iterations: int
    converged: bool
    residuals: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cost: float = float("nan")
    reason: str = ""


def predict(p: Problem, x: np.ndarray, n_mu: int, with_jacobian: bool = True):
    """Projected pixels (N, 2) for parameters x and, optionally, their Jacobian (N, 2, n)."""
    mu = x[:n_mu]
    alpha = x[n_mu] if p.rigid_z else 0.0
    dX, ddX = p.disp(mu)
    Rz = G.rot_axis("z", alpha)
    R_w = p.R_wo @ Rz
    Xw = p.X + dX @ R_w.T
    Xc = Xw @ p.T_cw[:3, :3].T + p.T_cw[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.c_[p.K[0, 0] * Xc[:, 0] / Xc[:, 2] + p.K[0, 1] * Xc[:, 1] / Xc[:, 2] + p.K[0, 2],
                   p.K[1, 1] * Xc[:, 1] / Xc[:, 2] + p.K[1, 2]]
    if not with_jacobian:
        return uv, Xc, None
    JP = image_jacobian(Xc, p.K)  # (N, 2, 3)
    A = p.T_cw[:3, :3] @ R_w  # object frame -> camera frame (rotation only: derivatives are vectors)
    JA = JP @ A  # (N, 2, 3)
    J = np.einsum("nij,njk->nik", JA, ddX) if n_mu else np.zeros((len(uv), 2, 0))
    if p.rigid_z:
        dRz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # R_z(a)^-1 dR_z/da = [e_z]x
        Ja = np.einsum("nij,nj->ni", JA, dX @ dRz.T)
        J = np.concatenate([J, Ja[:, :, None]], axis=2)
    return uv, Xc, J


def solve(p: Problem, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, huber_px: float = 2.0, max_iter: int = 20,
          lam0: float = 1e-3, tol: float = 1e-9) -> Result:
    """Levenberg-Marquardt with Huber IRLS weights and box bounds (Eq. 4.8) on image residuals."""
    n = len(x0)
    n_mu = n - (1 if p.rigid_z else 0)

    def model(x):
        uv, Xc, J = predict(p, x, n_mu)
        return uv, J, Xc[:, 2] > 0

    return solve_generic(model, p.uv, x0, lo, hi, p.sigma, huber_px, max_iter, lam0, tol)


def solve_generic(model, obs: np.ndarray, x0, lo, hi, sigma=None, huber: float = 2.0, max_iter: int = 20,
                  lam0: float = 1e-3, tol: float = 1e-9) -> Result:
    """LM for any measurement model: ``model(x) -> (prediction (N, 2), Jacobian (N, 2, n), valid (N,))``;
    residual r = (obs - prediction) / sigma; Huber threshold ``huber`` in units of r."""
    x = np.clip(np.asarray(x0, dtype=np.float64), lo, hi)
    n = len(x)
    sig = np.ones(len(obs)) if sigma is None else np.asarray(sigma, dtype=np.float64)

    def evaluate(x):
        pred, J, ok = model(x)
        r = (obs - pred) / sig[:, None]
        valid = ok & np.all(np.isfinite(r), axis=1)
        rn = np.linalg.norm(np.where(valid[:, None], r, 0.0), axis=1)
        w = huber_weights(rn, huber) * valid
        c = np.where(rn <= huber, rn ** 2, 2 * huber * rn - huber ** 2)
        cost = float(np.sum(np.where(valid, c, 0.0)))
        return np.where(valid[:, None], r, 0.0), np.nan_to_num(J / sig[:, None, None]), w, valid, cost

    r, J, w, valid, cost = evaluate(x)
    lam = lam0
    it = 0
    converged = False
    for it in range(1, max_iter + 1):
        Jf = J.reshape(-1, n)
        wf = np.repeat(w, 2)
        H = Jf.T @ (Jf * wf[:, None])
        g = Jf.T @ (wf * r.ravel())
        improved = False
        for _ in range(12):
            A = H + lam * np.diag(np.maximum(np.diag(H), 1e-12 * max(np.trace(H), 1e-300)))
            try:
                step = np.linalg.solve(A, g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            xn = np.clip(x + step, lo, hi)
            rn_, Jn, wn, vn, cn = evaluate(xn)
            if cn < cost or (cn <= cost and np.allclose(xn, x)):
                dx = np.abs(xn - x)
                x, r, J, w, valid, cost = xn, rn_, Jn, wn, vn, cn
                lam = max(lam / 10, 1e-12)
                improved = True
                if np.all(dx <= tol * (np.abs(hi - lo) + tol)):
                    converged = True
                break
            lam *= 10
        if not improved or converged:
            converged = True
            break
    Jf = J.reshape(-1, n)
    wf = np.repeat(w, 2)
    H = Jf.T @ (Jf * wf[:, None])
    rnorm = np.linalg.norm(r, axis=1)
    inl = valid & (rnorm <= 3 * huber)
    dof = max(2 * int(inl.sum()) - n, 1)
    s2 = float(np.sum(r[inl] ** 2)) / dof if inl.any() else float("nan")
    cov = np.linalg.pinv(H) * s2 if np.all(np.isfinite(H)) else np.full((n, n), np.inf)
    rms = float(np.sqrt(np.mean(np.sum((r[inl] * sig[inl, None]) ** 2, axis=1)))) if inl.any() else float("nan")
    return Result(x, cov, rms, int(inl.sum()), it, converged, r, cost)
