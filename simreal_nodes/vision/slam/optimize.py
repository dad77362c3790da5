"""Pose refinement (OpenCV) and local bundle adjustment (GTSAM factor graph)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

import cv2
import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel

CHI2_2D = 5.991  # 95 % for 2 dof
CHI2_3D = 7.815
FIXED_SIGMA = 1e-6  # prior sigma that holds a fixed keyframe in a GTSAM graph (radians, map units)


def project(T_cw: np.ndarray, P: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ideal pixels (N, 2) and depths (N,) of world points P under pose T_cw."""
    Pc = P @ T_cw[:3, :3].T + T_cw[:3, 3]
    z = Pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.c_[K[0, 0] * Pc[:, 0] / z + K[0, 1] * Pc[:, 1] / z + K[0, 2], K[1, 1] * Pc[:, 1] / z + K[1, 2]]
    return uv, z


def image_pose_lm(T_cw: np.ndarray, P: np.ndarray, uv: np.ndarray, w: np.ndarray, cam: CameraModel,
                  iterations: int = 10, eps: float = 1e-9) -> np.ndarray:
    """The pose that minimizes sum_i w_i |cam(T_cw P_i) - uv_i|^2 in the camera's own (distorted) pixels ``uv``:
    Levenberg-Marquardt on the rotation and translation vectors, the projection and its Jacobian from OpenCV
    (``cv2.fisheye.projectPoints`` for a fisheye, ``cv2.projectPoints`` else). A fisheye's pose refined in ideal
    pixels weighs every point alike although the lens stretches the ideal image up to 10 times towards its edge
    (more radially than across): here each point's error is read where it was measured. ``w``: 1 / sigma^2 per
    point (the pyramid level's). Stops when a step changes the vectors by less than ``eps`` or after
    ``iterations``."""
    import cv2

    if cam.fisheye:
        def project(x):
            out, J = cv2.fisheye.projectPoints(P.reshape(-1, 1, 3), x[:3], x[3:], cam.K, cam.D)
            return out.reshape(-1, 2), J[:, 8:14]  # (2N, 15): f, c, k1..k4, then rvec, tvec, alpha
    else:
        def project(x):
            out, J = cv2.projectPoints(P, x[:3], x[3:], cam.K, cam.cv_dist())
            return out.reshape(-1, 2), J[:, :6]  # rvec, tvec, then f, c, the coefficients

    def cost(x):
        proj, J = project(x)
        r = proj - uv
        # OpenCV projects a point behind the camera to a mirrored pixel: such a pose costs infinitely much
        z = P @ cv2.Rodrigues(x[:3])[0][2] + x[5]
        return r, J, float(np.sum(w * np.sum(r * r, axis=1))) if np.all(z > 1e-9) else np.inf

    x = np.r_[cv2.Rodrigues(T_cw[:3, :3])[0].ravel(), T_cw[:3, 3]]
    r, J, c = cost(x)
    if not np.isfinite(c):
        return T_cw.copy()
    w2 = np.repeat(w, 2)
    lam = 1e-3
    for _ in range(iterations):
        Jw = J * w2[:, None]
        H, g = Jw.T @ J, Jw.T @ r.ravel()
        while True:
            try:
                step = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), g)
            except np.linalg.LinAlgError:
                return G.make_T(cv2.Rodrigues(x[:3])[0], x[3:])
            r_new, J_new, c_new = cost(x + step)
            if np.isfinite(c_new) and c_new <= c:
                x, r, J, c = x + step, r_new, J_new, c_new
                lam = max(lam / 10, 1e-9)
                break
            lam *= 10
            if lam > 1e6:
                return G.make_T(cv2.Rodrigues(x[:3])[0], x[3:])
        if np.linalg.norm(step) < eps:
            break
    return G.make_T(cv2.Rodrigues(x[:3])[0], x[3:])


def refine_pose(T_cw: np.ndarray, P: np.ndarray, uv: np.ndarray, sigma2: np.ndarray, K: np.ndarray,
                rounds: int = 4, lens: tuple[CameraModel, np.ndarray, np.ndarray] | None = None,
                ) -> tuple[np.ndarray, np.ndarray]:
    """Motion-only optimization with outlier rejection (ORB-SLAM2's PoseOptimization, on OpenCV's LM):
    refine on the current inliers, re-classify every match by its chi-square error, repeat. ``lens``: (camera,
    the matches' own pixels, their levels' sigma^2): the fit runs in the camera's pixels, each match weighed by its
    level (:func:`image_pose_lm`; for a fisheye, whose ideal image is stretched towards its edge); else OpenCV's LM
    in ideal pixels weighs them alike. The chi-square tests read ``uv`` and ``sigma2`` either way."""
    T = T_cw.copy()
    if len(P) < 4:
        return T, np.zeros(len(P), bool)
    # start from the matches the initial pose already explains (a generous bound): least squares on
    # gross outliers would drag a good initial pose away
    proj, z = project(T, P, K)
    e2 = np.sum((proj - uv) ** 2, axis=1) / sigma2
    inl = (e2 < 16 * CHI2_2D) & (z > 0)
    if inl.sum() < 6:
        inl = np.ones(len(P), bool)
    for _ in range(rounds):
        if inl.sum() < 4:
            break
        if lens is not None:
            cam, px, s2 = lens
            T = image_pose_lm(T, P[inl].astype(np.float64), px[inl].astype(np.float64), 1.0 / s2[inl], cam)
        else:
            rvec, _ = cv2.Rodrigues(T[:3, :3])
            tvec = T[:3, 3].reshape(3, 1).copy()  # (3, 1): OpenCV silently ignores a flat tvec here
            try:
                rvec, tvec = cv2.solvePnPRefineLM(P[inl].astype(np.float64), uv[inl].astype(np.float64), K, None,
                                                  rvec, tvec, (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 10,
                                                               1e-9))
            except cv2.error:
                break
            T = G.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
        proj, z = project(T, P, K)
        e2 = np.sum((proj - uv) ** 2, axis=1) / sigma2
        inl = (e2 < CHI2_2D) & (z > 0) & np.isfinite(e2)
    return T, inl


def ba_request(m, kfs_opt, kfs_fixed, pt_ids: np.ndarray) -> dict:
    """Everything a bundle adjustment needs, as plain arrays (it can cross a process boundary): the keyframes
    (``kfs_opt`` optimized, ``kfs_fixed`` held), the points ``pt_ids`` of the map ``m`` and every observation of
    those points by those keyframes (point-major, then in the keyframes' order), gathered from the map's
    observation arrays (no loop over points)."""
    kfs = list(kfs_opt) + list(kfs_fixed)
    pt_ids = np.asarray(pt_ids, np.int64)
    _, kid, idx = m.observations()
    jmap = np.full(m.n_rows, -1, np.int64)  # row -> the point's index in pt_ids
    jmap[m.rows(pt_ids)] = np.arange(len(pt_ids))
    kmap = np.full(max([k.id for k in kfs] + [int(kid.max()) if len(kid) else 0]) + 1, -1, np.int64)
    kmap[[k.id for k in kfs]] = np.arange(len(kfs))
    prow = m.observation_rows()
    sel = (jmap[prow] >= 0) & (kmap[kid] >= 0)
    obs_p, obs_k, fi = jmap[prow[sel]], kmap[kid[sel]], idx[sel]
    order = np.lexsort((obs_k, obs_p))
    obs_p, obs_k, fi = obs_p[order], obs_k[order], fi[order]
    uv = np.zeros((len(fi), 2))
    z = np.full(len(fi), np.nan)
    sig = np.ones(len(fi))
    for i, kf in enumerate(kfs):
        at = obs_k == i
        if not np.any(at):
            continue
        uv[at] = kf.feats.und[fi[at]]
        sig[at] = kf.feats.sigma()[fi[at]]
        if kf.depth is not None:
            z[at] = kf.depth[fi[at]]
    return {"kf_ids": np.array([kf.id for kf in kfs], np.int64), "poses": np.array([kf.T_wc for kf in kfs]),
            "fixed": np.array([False] * len(kfs_opt) + [True] * len(kfs_fixed)),
            "pt_ids": pt_ids, "pos": m._pos[m.rows(pt_ids)].reshape(-1, 3),
            "obs_p": obs_p, "obs_k": obs_k, "uv": uv, "z": z, "sigma": sig}


def bundle_adjust(req: dict, K: np.ndarray, baseline: float | None = None, iterations: int = 10,
                  optimizer: str = "levenberg_marquardt", stop: Callable[[], bool] | None = None) -> dict:
    """GTSAM Levenberg-Marquardt on a :func:`ba_request`: optimizes the non-fixed poses and all points.
    Observations with a depth (RGB-D / stereo) are stereo factors (virtual right coordinate
    u_r = u - fx b / z), the others projection factors, all with a Huber loss scaled by the pyramid level.
    ``stop``: asked after every iteration (from the first on); True ends the BA there with what it has (ORB-SLAM2's
    abort flag: a new keyframe waits). Returns new poses and positions, the outlier observations (point id, keyframe
    id), the iterations run and whether it was stopped."""
    import gtsam
    from gtsam.symbol_shorthand import L, X

    t0 = time.perf_counter()
    graph = gtsam.NonlinearFactorGraph()
    vals = gtsam.Values()
    cal = gtsam.Cal3_S2(K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2])
    stereo_cal = gtsam.Cal3_S2Stereo(K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2], baseline) if baseline else None
    held = gtsam.noiseModel.Isotropic.Sigma(6, FIXED_SIGMA)
    huber2 = gtsam.noiseModel.mEstimator.Huber.Create(np.sqrt(CHI2_2D))
    huber3 = gtsam.noiseModel.mEstimator.Huber.Create(np.sqrt(CHI2_3D))
    for kid, T, fx in zip(req["kf_ids"], req["poses"], req["fixed"]):
        vals.insert(X(int(kid)), gtsam.Pose3(T))
        if fx:
            # held by a prior of 1e-6 (rad, map units): a hard NonlinearEquality makes GTSAM eliminate the clique of
            # every pose with a constrained (QR) factor, 25 times slower on a whole map, 5 times on a local window
            # (the result 1e-8 apart)
            graph.add(gtsam.PriorFactorPose3(X(int(kid)), gtsam.Pose3(T), held))
    n_obs = np.bincount(req["obs_p"], minlength=len(req["pt_ids"]))
    for j, (pid, P) in enumerate(zip(req["pt_ids"], req["pos"])):
        vals.insert(L(int(pid)), gtsam.Point3(*P))
        if n_obs[j] < 2 and stereo_cal is None:
            graph.add(gtsam.PriorFactorPoint3(L(int(pid)), gtsam.Point3(*P), gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
    # one robust noise model per pyramid-level sigma, shared by the factors at that level
    robust2: dict[float, gtsam.noiseModel.Robust] = {}
    robust3: dict[float, gtsam.noiseModel.Robust] = {}
    sd = float(req.get("disparity_sigma", 0.0))
    for j, i, (u, v), z, s in zip(req["obs_p"], req["obs_k"], req["uv"], req["z"], req["sigma"]):
        kx, lx = X(int(req["kf_ids"][i])), L(int(req["pt_ids"][j]))
        if stereo_cal is not None and np.isfinite(z) and z > 0:
            nm = robust3.get(s) or robust3.setdefault(
                s, gtsam.noiseModel.Robust.Create(huber3, _stereo_noise(gtsam, s, sd)))
            graph.add(gtsam.GenericStereoFactor3D(gtsam.StereoPoint2(u, u - K[0, 0] * baseline / z, v), nm, kx, lx,
                                                  stereo_cal))
        else:
            nm = robust2.get(s) or robust2.setdefault(
                s, gtsam.noiseModel.Robust.Create(huber2, gtsam.noiseModel.Isotropic.Sigma(2, s)))
            graph.add(gtsam.GenericProjectionFactorCal3_S2(gtsam.Point2(u, v), nm, kx, lx, cal))
    try:
        opt: gtsam.NonlinearOptimizer
        if optimizer == "gauss_newton":
            gn = gtsam.GaussNewtonParams()
            gn.setMaxIterations(iterations)
            gn.setRelativeErrorTol(1e-5)
            params: gtsam.NonlinearOptimizerParams = gn
            opt = gtsam.GaussNewtonOptimizer(graph, vals, gn)
        else:
            lm = gtsam.LevenbergMarquardtParams()
            lm.setMaxIterations(iterations)
            lm.setRelativeErrorTol(1e-5)
            lm.setVerbosityLM("SILENT")
            params = lm
            opt = gtsam.LevenbergMarquardtOptimizer(graph, vals, lm)
        n_it, stopped = _iterate(gtsam, opt, params, stop)
        result = opt.values()
    except RuntimeError as e:
        return {"ok": False, "error": str(e), "ms": (time.perf_counter() - t0) * 1e3}
    poses = np.array([result.atPose3(X(int(k))).matrix() for k in req["kf_ids"]])
    pos = np.array([np.asarray(result.atPoint3(L(int(p)))) for p in req["pt_ids"]]).reshape(-1, 3)
    # outliers: chi-square on the reprojection after optimization (vectorized over observations)
    out = []
    if len(req["obs_p"]):
        R = poses[:, :3, :3]
        t = poses[:, :3, 3]
        Rk, tk = R[req["obs_k"]], t[req["obs_k"]]
        Xc = np.einsum("nji,nj->ni", Rk, pos[req["obs_p"]] - tk)  # R^T (X - t)
        with np.errstate(divide="ignore", invalid="ignore"):
            pr = np.c_[K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 1] * Xc[:, 1] / Xc[:, 2] + K[0, 2],
                       K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]]
            e2 = np.sum((pr - req["uv"]) ** 2, axis=1) / req["sigma"] ** 2
            chi2 = np.full(len(e2), CHI2_2D)
            if stereo_cal is not None:  # a stereo factor's third coordinate, u_r = u - fx b / z: 3 dof (7.81)
                z = req["z"]
                has = np.isfinite(z) & (z > 0)
                e2 = e2 + np.where(has, depth_e2(pr[:, 0] - req["uv"][:, 0], K[0, 0] * baseline, Xc[:, 2], z,
                                                 req["sigma"], sd), 0.0)
                chi2[has] = CHI2_3D
        bad = ~np.isfinite(e2) | (e2 > chi2) | (Xc[:, 2] <= 0)
        out = list(zip(req["pt_ids"][req["obs_p"][bad]].tolist(), req["kf_ids"][req["obs_k"][bad]].tolist()))
    return {"ok": True, "kf_ids": req["kf_ids"], "fixed": req["fixed"], "poses": poses, "pt_ids": req["pt_ids"],
            "pos": pos, "outliers": out, "iterations": n_it, "stopped": stopped, "ms": (time.perf_counter() - t0) * 1e3}


def _stereo_noise(gtsam, s: float, disparity_sigma: float):
    """The noise of a stereo factor's (u_l, u_r, v) at pyramid sigma ``s``: ORB-SLAM2's isotropic ``s`` on each
    (``disparity_sigma`` 0; right for a matched stereo pair, whose u_r is measured in its own image); or, for a depth
    camera, u_r = u_l - d with the disparity d = fx b / z read from the depth image: u_l's noise shared by u_r and
    the disparity's own ``disparity_sigma`` (pixels) added, covariance [[s2, s2, 0], [s2, s2 + sd2, 0], [0, 0, s2]]."""
    if disparity_sigma <= 0:
        return gtsam.noiseModel.Isotropic.Sigma(3, s)
    s2 = s * s
    return gtsam.noiseModel.Gaussian.Covariance(np.array([[s2, s2, 0.0], [s2, s2 + disparity_sigma ** 2, 0.0],
                                                          [0.0, 0.0, s2]]))


def depth_e2(du: np.ndarray, bf: float, z_pred: np.ndarray, z_meas: np.ndarray, sigma: np.ndarray,
             disparity_sigma: float) -> np.ndarray:
    """The depth part of a stereo observation's chi-square, beside the 2D part (du^2 + dv^2) / s^2, under
    :func:`_stereo_noise`: the u_r residual (u_l error ``du`` minus the disparity error) over s^2 (isotropic), or
    the disparity error over ``disparity_sigma``^2 (depth camera). ``bf``: fx times the (virtual) baseline."""
    with np.errstate(divide="ignore", invalid="ignore"):
        e_d = bf / z_pred - bf / z_meas  # predicted minus measured disparity
    if disparity_sigma > 0:
        return e_d ** 2 / disparity_sigma ** 2
    return (du - e_d) ** 2 / np.asarray(sigma) ** 2


def _iterate(gtsam, opt, params, stop: Callable[[], bool] | None) -> tuple[int, bool]:
    """GTSAM's own optimize loop (NonlinearOptimizer::defaultOptimize: iterate until the maximum count or the
    relative / absolute decrease is below its tolerance), with ``stop`` asked between iterations."""
    err = opt.error()
    if err <= params.getErrorTol():
        return 0, False
    n = 0
    while True:
        prev = err
        opt.iterate()
        n += 1
        err = opt.error()
        if n >= params.getMaxIterations() or not np.isfinite(prev) or gtsam.checkConvergence(
                params.getRelativeErrorTol(), params.getAbsoluteErrorTol(), params.getErrorTol(), prev, err):
            return n, False
        if stop is not None and stop():
            return n, True


def _worker(conn, K, baseline, iterations, abort):  # pragma: no cover - runs in the mapping process
    while True:
        try:
            req = conn.recv()
        except (EOFError, KeyboardInterrupt):
            return
        if req is None:
            return
        # a global BA (after a loop) runs to the end; a local one stops when a newer keyframe waits
        conn.send(bundle_adjust(req, K, baseline, iterations, stop=None if req.get("whole") else abort.is_set))


class AsyncBundleAdjuster:
    """Local BA in a worker process (GTSAM holds the GIL: a thread would stall tracking). One request at
    a time; the tracker keeps going and applies the result when it arrives."""

    def __init__(self, K, baseline, iterations):
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self._abort = ctx.Event()
        self.proc = ctx.Process(target=_worker, args=(child, K, baseline, iterations, self._abort), daemon=True,
                                name="simreal-local-mapping")
        self.proc.start()
        self.busy = False

    def interrupt(self) -> None:
        """Ask the running local BA to stop after its current iteration (it returns what it has)."""
        if self.busy:
            self._abort.set()

    def submit(self, req: dict) -> bool:
        if self.busy or not self.proc.is_alive():
            return False
        self._abort.clear()  # a stop asked for while the last BA ran (it finished meanwhile) is not this one's
        self.conn.send(req)
        self.busy = True
        return True

    def poll(self) -> dict | None:
        if self.busy and self.conn.poll():
            self.busy = False
            return self.conn.recv()
        return None

    def close(self, timeout: float = 2.0) -> None:
        """End the mapping process. An idle one is told to end; one with a BA in flight is killed at once: its result
        would be dropped anyway, and the BA looks at its stop flag only between iterations, not while it builds its
        factor graph (a BA of ten thousand points held the old close for its whole 2-s timeout before the kill:
        ``tests/vision/test_slam_parts.py``). ``timeout``: the wait for an idle process to end before it is killed."""
        if self.busy and self.proc.is_alive():
            self.proc.terminate()
        else:
            with contextlib.suppress(BrokenPipeError, OSError):
                self.conn.send(None)
        self.proc.join(timeout=timeout)
        if self.proc.is_alive():
            self.proc.terminate()
            self.proc.join(timeout=1.0)
        self.conn.close()
        self.busy = False
