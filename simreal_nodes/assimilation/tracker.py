"""Deformable tracking of one object (thesis ch. 4): per frame, the parameters mu of the object's
reduced model whose deformation best explains the image measurements.

Measurements are map points of the SLAM map linked to model nodes (Eq. 4.10), or dots glued on the
object at known places (§4.5.1), in the image (perspective) or mapped onto the object's face by a
homography (the planar variant of §4.5.1). Parameters declared ``constant`` (material, the rotation
alpha_z of §4.5.4) are estimated jointly over the first frames with deformation and then frozen
(Fig. 4.19); ``fixed`` ones never move. The estimate starts from the previous frame's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.assimilation import lm
from simreal_nodes.assimilation.registration import link, surface_nodes
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.vision.camera import CameraModel

OK, LOW_CONFIDENCE, LOST, INITIALIZING = 0, 1, 2, 3  # ModelParameters.STATE_*


@dataclass
class TrackerConfig:
    measurements: str = "map_points"  # map_points | dots | homography
    huber_px: float = 2.0
    n_modes: int = 0  # 0: all
    max_iterations: int = 20
    constant_frames: int = 15
    min_measurements: int = 6
    link_dist: float = 0.01  # metres from the model surface for a map point to belong to the object
    max_points: int = 0  # 0: all
    dots: np.ndarray | None = None  # (N, 3) object frame
    dot_color: tuple = (0.1, 0.25, 0.95)
    dot_radius_px: float = 12.0  # association radius
    min_deformation_px: float = 0.3  # below this improvement over "no deformation": nothing measurable


@dataclass
class Estimate:
    names: list
    units: list
    values: np.ndarray
    frozen: np.ndarray
    cov: np.ndarray
    rms_px: float = float("nan")
    inliers: int = 0
    measurements: int = 0
    iterations: int = 0
    state: int = INITIALIZING
    reason: str = ""
    deforming: bool = False
    solve_ms: float = 0.0
    debug: dict = field(default_factory=dict)


class DeformableTracker:
    def __init__(self, model: ReducedModel, T_map_obj: np.ndarray, params: dict, cam: CameraModel,
                 cfg: TrackerConfig | None = None):
        self.model = model
        self.cfg = cfg or TrackerConfig()
        self.cam = cam
        self.K = cam.K
        self.T_map_obj = np.asarray(T_map_obj, dtype=np.float64)
        self.field = model.field("displacement")
        axes = model.axes
        for a in axes:
            if a.kind != "continuous":
                raise ValueError(f"parameter '{a.name}' of model '{model.name}' is discrete: it cannot be tracked "
                                 "from images (it is set by collision)")
        rigid = {r["name"]: r for r in model.rigid_parameters}
        self.rigid_z = "alpha_z" in params and "alpha_z" in rigid
        self.names = [a.name for a in axes] + (["alpha_z"] if self.rigid_z else [])
        self.units = [a.unit for a in axes] + (["rad"] if self.rigid_z else [])
        lo = [a.range[0] for a in axes] + ([rigid["alpha_z"]["range"][0]] if self.rigid_z else [])
        hi = [a.range[1] for a in axes] + ([rigid["alpha_z"]["range"][1]] if self.rigid_z else [])
        self.lo, self.hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        n = len(self.names)
        self.x = 0.5 * (self.lo + self.hi)
        self.mode = ["tracked"] * n
        for i, name in enumerate(self.names):
            cfgp = params.get(name, {})
            self.mode[i] = cfgp.get("mode", "tracked")
            init = cfgp.get("initial")
            if self.mode[i] == "fixed":
                init = cfgp.get("value")
            if init is not None:
                self.x[i] = float(np.clip(init, self.lo[i], self.hi[i]))
            elif self.names[i] == "alpha_z":
                self.x[i] = 0.0
        self.frozen = np.array([m == "fixed" for m in self.mode])
        self._const_samples: list[np.ndarray] = []
        self._was_deforming = False  # constants move only once deformation makes them observable
        self.n_mu = len(axes)
        self.cand_nodes = surface_nodes(model)
        self.links: dict[int, tuple] = {}  # map point id -> (nodes (3,), weights (3,), X_map (3,))
        self.static: set[int] = set()
        self._alpha_linked = None
        self.deforming_frames = 0
        self._dot_links = None
        if self.cfg.measurements in ("dots", "homography"):
            if self.cfg.dots is None or len(self.cfg.dots) == 0:
                raise ValueError("measurements 'dots' need the dots' reference positions (tracking.dots)")
            L = link(self.cfg.dots, model.points, self.cand_nodes, max_dist=np.inf)
            self._dot_links = (L.nodes, L.weights)

    # -- geometry ----------------------------------------------------------------------------------------
    @property
    def R_wo(self) -> np.ndarray:
        return self.T_map_obj[:3, :3]

    def _alpha(self) -> float:
        return float(self.x[self.n_mu]) if self.rigid_z else 0.0

    def _disp_fn(self, nodes: np.ndarray, weights: np.ndarray):
        """mu -> (dX (N, 3), d dX / d mu (N, 3, n_mu)) in the object frame, through the linked nodes."""
        uniq, inv = np.unique(nodes, return_inverse=True)
        view = self.field.view(uniq, self.cfg.n_modes or None)
        inv = inv.reshape(nodes.shape)

        w3 = weights[:, :, None]
        w4 = weights[:, :, None, None]

        def f(mu):
            u, J = view.evaluate_with_jacobian(mu, checked=True)  # LM keeps mu inside the bounds
            return (u[inv] * w3).sum(axis=1), (J[inv] * w4).sum(axis=1)

        return f

    def link_points(self, ids: np.ndarray, P_map: np.ndarray) -> None:
        """Link newly seen map points to model nodes (object frame, undoing the current alpha)."""
        new = [i for i, pid in enumerate(ids) if int(pid) not in self.links and int(pid) not in self.static]
        if not new:
            return
        P = P_map[new]
        T_om = G.inv(self.T_map_obj)
        X = G.transform(T_om, P) @ G.rot_axis("z", self._alpha())  # R_z(-a) applied: row vectors
        L = link(X, self.model.points, self.cand_nodes, self.cfg.link_dist)
        for k, i in enumerate(new):
            pid = int(ids[i])
            if L.on_object[k]:
                self.links[pid] = (L.nodes[k], L.weights[k], P_map[i].copy())
            else:
                self.static.add(pid)

    def relink(self) -> None:
        """alpha changed: the same map points now sit at other material points."""
        if not self.links:
            return
        ids = np.array(list(self.links))
        P = np.array([self.links[i][2] for i in ids])
        self.links.clear()
        self.link_points(ids, P)

    @property
    def deformable_ids(self) -> list[int]:
        return sorted(self.links)

    # -- measurements ------------------------------------------------------------------------------------------
    def _map_point_measurements(self, ids, P_map, uv):
        sel = [k for k, pid in enumerate(ids) if int(pid) in self.links]
        if self.cfg.max_points and len(sel) > self.cfg.max_points:
            sel = sel[:: max(1, len(sel) // self.cfg.max_points)][: self.cfg.max_points]
        if not sel:
            return None
        nodes = np.array([self.links[int(ids[k])][0] for k in sel])
        w = np.array([self.links[int(ids[k])][1] for k in sel])
        X = np.array([self.links[int(ids[k])][2] for k in sel])
        return X, self.cam.undistort_points(uv[sel]), nodes, w

    def _dot_measurements(self, image_bgr, T_cw):
        from simreal_nodes.vision.blobs import detect_color_blobs

        found = detect_color_blobs(image_bgr, self.cfg.dot_color)
        nodes, w = self._dot_links
        X = G.transform(self.T_map_obj, self.cfg.dots)
        if len(found) == 0:
            return None, 0
        # predicted dot pixels with the current estimate
        dX, _ = self._disp_fn(nodes, w)(self.x[: self.n_mu])
        Xw = X + dX @ (self.R_wo @ G.rot_axis("z", self._alpha())).T
        pred, z = _project(T_cw, Xw, self.K)
        und = self.cam.undistort_points(found)
        tree = cKDTree(und)
        d, j = tree.query(np.nan_to_num(pred, nan=-1e6), k=1)
        ok = (d <= self.cfg.dot_radius_px) & (z > 0)
        # one detection per dot
        ok &= np.bincount(j[ok], minlength=len(und))[j] == 1
        if not ok.any():
            return None, len(found)
        return (X[ok], und[j[ok]], nodes[ok], w[ok]), len(found)

    # -- per frame ----------------------------------------------------------------------------------------------
    def update(self, T_wc: np.ndarray | None, ids=None, P_map=None, uv=None, image_bgr=None) -> Estimate:
        import time

        est = Estimate(self.names, self.units, self.x.copy(), self.frozen.copy(), np.full((len(self.x),) * 2, np.nan))
        if T_wc is None:
            est.state, est.reason = LOST, "no camera pose this frame (localization lost)"
            return est
        T_cw = G.inv(T_wc)
        if self.cfg.measurements == "map_points":
            if ids is None or len(ids) == 0:
                est.state, est.reason = LOST, "no measurements: no map points observed on the object"
                return est
            ids = np.asarray(ids)
            P_map = np.asarray(P_map, dtype=np.float64).reshape(-1, 3)
            uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
            good = np.all(np.isfinite(P_map), axis=1) & np.all(np.isfinite(uv), axis=1)
            ids, P_map, uv = ids[good], P_map[good], uv[good]
            self.link_points(ids, P_map)
            meas = self._map_point_measurements(ids, P_map, uv)
            found = len(ids)
        else:
            if image_bgr is None:
                est.state, est.reason = LOST, "measurements 'dots' need the image"
                return est
            meas, found = self._dot_measurements(image_bgr, T_cw)
        if meas is None or len(meas[0]) < self.cfg.min_measurements:
            n = 0 if meas is None else len(meas[0])
            est.state = LOST
            est.reason = f"too few measurements on the object ({n}, need {self.cfg.min_measurements}; {found} candidates seen)"
            est.measurements = n
            return est
        X, uvm, nodes, w = meas
        est.measurements = len(X)
        disp = self._disp_fn(nodes, w)
        free = ~self.frozen
        if not self._was_deforming:
            # an undeformed object says nothing about its constants (alpha_z of an axisymmetric boot, a stiffness):
            # hold them until a deformation is seen, or they drift along the flat directions of the cost
            free &= np.array([m != "constant" for m in self.mode])
        lo = np.where(free, self.lo, self.x)
        hi = np.where(free, self.hi, self.x)
        t0 = time.perf_counter()
        if self.cfg.measurements == "homography":
            res, rest_rms = self._solve_planar(X, uvm, disp, T_cw, lo, hi)
        else:
            p = lm.Problem(X, uvm, disp, T_cw, self.R_wo, self.K, rigid_z=self.rigid_z)
            res = lm.solve(p, self.x, lo, hi, self.cfg.huber_px, self.cfg.max_iterations)
            rest_rms = self._rest_rms(X, uvm, T_cw)
        est.solve_ms = (time.perf_counter() - t0) * 1e3
        est.values, est.cov = res.x.copy(), res.cov
        est.rms_px, est.inliers, est.iterations = res.rms_px, res.inliers, res.iterations
        est.debug = {"rest_rms_px": rest_rms}
        if res.inliers < self.cfg.min_measurements or not np.isfinite(res.rms_px):
            est.state = LOST
            est.reason = f"only {res.inliers} of {len(X)} measurements agree with the model (all outliers?)"
            return est
        gain = rest_rms - res.rms_px
        est.deforming = bool(gain > self.cfg.min_deformation_px)
        self._was_deforming = est.deforming
        if not est.deforming:
            # barely anything to see (load absent, or near the clamp where the images hardly see its effect):
            # report the bounded estimate with the large variance the normal equations give, flagged; the
            # constants are not estimated from such frames
            self.x = res.x.copy()
            est.state = LOW_CONFIDENCE
            est.reason = (f"no measurable deformation (residual {res.rms_px:.2f} px vs {rest_rms:.2f} px undeformed): "
                          "the load may be absent or where the images cannot see its effect")
            return est
        self.x = res.x.copy()
        self.deforming_frames += 1
        est.state = OK
        std = np.sqrt(np.clip(np.diag(est.cov), 0, None))
        weak = [(nm, s, h - l) for nm, s, l, h, fr in zip(self.names, std, self.lo, self.hi, self.frozen)
                if not fr and s > 0.05 * (h - l)]
        if weak:
            est.state = LOW_CONFIDENCE
            est.reason = "; ".join(f"{nm} barely observable (std {s:.3g}, {100 * s / r:.0f} % of its range)" for nm, s, r in weak)
        self._update_constants(est)
        est.frozen = self.frozen.copy()
        return est

    def _rest_rms(self, X, uvm, T_cw) -> float:
        pred, z = _project(T_cw, X, self.K)
        r = np.linalg.norm(uvm - pred, axis=1)
        r = r[np.isfinite(r)]
        return float(np.sqrt(np.mean(np.minimum(r, 3 * self.cfg.huber_px) ** 2))) if len(r) else float("nan")

    def _update_constants(self, est: Estimate) -> None:
        const = np.array([m == "constant" for m in self.mode]) & ~self.frozen
        if not const.any() or est.state != OK:
            return
        self._const_samples.append(self.x.copy())
        if self.rigid_z and const[self.n_mu]:
            # the links were made with an earlier alpha: re-link the map points once it moved noticeably
            if self._alpha_linked is None or abs(self._alpha() - self._alpha_linked) > np.deg2rad(0.25):
                self.relink()
                self._alpha_linked = self._alpha()
        if len(self._const_samples) >= self.cfg.constant_frames:
            vals = np.median(np.array(self._const_samples), axis=0)
            self.x[const] = vals[const]
            self.frozen |= const
            if self.rigid_z and const[self.n_mu]:
                self.relink()

    def _solve_planar(self, X, uvm, disp, T_cw, lo, hi):
        """Homography variant (§4.5.1): observations mapped onto the object's y = 0 face, residuals in
        metres in that plane; the Huber threshold is converted with the pixel size on the face."""
        T_co = T_cw @ self.T_map_obj
        H = self.K @ np.c_[T_co[:3, 0], T_co[:3, 2], T_co[:3, 3]]  # plane (x, z) of y = 0 -> image
        Hi = np.linalg.inv(H)
        q = np.c_[uvm, np.ones(len(uvm))] @ Hi.T
        obs = q[:, :2] / q[:, 2:]
        Xo = G.transform(G.inv(self.T_map_obj), X)
        depth = np.median((Xo @ T_co[:3, :3].T + T_co[:3, 3])[:, 2])
        px = depth / self.K[0, 0]  # metres per pixel on the face
        n_mu = self.n_mu

        def model(x):
            dX, ddX = disp(x[:n_mu])
            pred = np.c_[Xo[:, 0] + dX[:, 0], Xo[:, 2] + dX[:, 2]]
            J = ddX[:, [0, 2], :]
            if self.rigid_z:
                J = np.concatenate([J, np.zeros((len(J), 2, 1))], axis=2)
            return pred, J, np.ones(len(pred), bool)

        res = lm.solve_generic(model, obs, self.x, lo, hi, np.full(len(obs), px), self.cfg.huber_px, self.cfg.max_iterations)
        rest = np.linalg.norm(obs - np.c_[Xo[:, 0], Xo[:, 2]], axis=1) / px
        return res, float(np.sqrt(np.mean(np.minimum(rest, 3 * self.cfg.huber_px) ** 2)))


def _project(T_cw, X, K):
    Xc = X @ T_cw[:3, :3].T + T_cw[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.c_[K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 1] * Xc[:, 1] / Xc[:, 2] + K[0, 2], K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]]
    return uv, Xc[:, 2]
