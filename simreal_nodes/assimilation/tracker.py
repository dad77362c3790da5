"""Deformable tracking of one object (thesis ch. 4): per frame, the parameters mu of the object's
reduced model whose deformation best explains the image measurements.

Measurements are map points of the SLAM map linked to model nodes (Eq. 4.10), or dots glued on the
object at known places (§4.5.1), in the image (perspective) or mapped onto the object's face by a
homography (the planar variant of §4.5.1). Parameters declared ``constant`` (material, the rotation
alpha_z of §4.5.4) are estimated jointly over the first frames with deformation and then frozen
(Fig. 4.19); ``fixed`` ones never move. The estimate starts from the previous frame's.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple, cast

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.assimilation import lm
from simreal_nodes.assimilation.dense import DenseAligner, DenseResult, DenseSettings
from simreal_nodes.assimilation.depth_state import (
    TURN_HELD,
    TURN_STEPS,
    DepthFit,
    DepthFollower,
    DepthState,
    DepthStateConfig,
    fit_state,
    held_gains,
)
from simreal_nodes.assimilation.registration import LinkIndex, Links, depth_cloud, link, ray_weights, surface_nodes
from simreal_nodes.camera import CameraModel
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.state import ALPHA_Z, ModelState, StateLayout
from simreal_nodes.states import EstimateState, PointFlag

# (X map-frame rest positions (N, 3), ideal pixels (N, 2), nodes (N, 3), weights (N, 3)[, map point ids (N,)])
Measurements = tuple[np.ndarray, ...]


def _sigma(meas: Measurements) -> np.ndarray | None:
    """The measurements' pixel noise scales where they carry them (a fisheye's stretch), else None (1 each)."""
    return meas[5] if len(meas) > 5 and len(meas[5]) else None


class Link(NamedTuple):
    """A map point linked to the model (Eq. 4.10)."""

    nodes: np.ndarray  # (3,) model nodes
    weights: np.ndarray  # (3,) barycentric weights on them
    X_rest: np.ndarray  # (3,) map-frame rest position (the linked material point)
    P_map: np.ndarray  # (3,) the map point's position when linked
    mu: np.ndarray | None  # the deformation it was linked in (None: rest shape)
    ray: np.ndarray | None  # (2, 3) map-frame viewing ray (centre, direction) it was linked from, or None


@dataclass
class TrackerConfig:
    measurements: str = "map_points"  # map_points | dots | homography | dense (a scene's default is dense)
    huber_px: float = 2.0
    n_modes: int = 0  # 0: all
    max_iterations: int = 20
    # > 0: after each frame's Huber fit, refit with only the measurements then within 3 x huber_px, re-classified
    # before each of at most this many rounds (ORB-SLAM2's pose optimisation; :func:`lm.solve_generic`). A knob: on
    # the boot's development seeds 0-39, 3 rounds read 0.96 % of the lever's range at the median against Huber
    # alone's 0.93 % (80 % of the scenes within 2 % against 70 %), so the default stays Huber alone (docs/family.md)
    outlier_refits: int = 0
    constant_frames: int = 15
    # a frame informs a constant only if its std is below this fraction of its range
    constant_std_frac: float = 0.0025
    min_measurements: int = 6
    link_dist: float = 0.01  # metres from the model surface for a map point to belong to the object
    # a map point not observed in this many frames is forgotten (its link, or that it is static); seen again, it is
    # linked anew. Bounds the links to what the map still shows: the SLAM culls points and makes new ones, and over
    # 10 000 frames of the joint boot the tracker grew by 2.4 MB per 1000 frames without it (benchmarks/soak.py).
    # The price, for an object out of view longer than this: a point of it seen again votes once for the camera
    # pose before it is flagged deformable again, and its new link is made in the current estimate from where the
    # map last had it (0: never forget)
    link_ttl_frames: int = 450
    snap_to_surface: bool = True  # measure a linked point at its foot on the model surface, not at its mapped position
    anchor: str = "ray"  # where on its triangle a linked point sits: "ray" (the observed pixel's viewing ray) | "foot"
    max_points: int = 0  # 0: all
    dots: np.ndarray | None = None  # (N, 3) object frame
    dot_color: tuple[float, ...] = (0.1, 0.25, 0.95)
    dot_radius_px: float = 12.0  # association radius
    min_deformation_px: float = 0.3  # below this improvement over "no deformation": nothing measurable
    # > 0: also fit a translation of the whole object (bounded), absorbing camera-pose drift
    object_shift_m: float = 0.0
    # measurements 'dots' / 'homography': > 0: the object is at rest in the first so many frames with a camera pose; its
    # pose is corrected from its dots there (rigidly) and held (a pose measured by hand, a few mm and a degree off)
    rest_frames: int = 0
    global_samples: int = 32  # coarse search over the tracked parameters when the warm start fits badly (0: off)
    # > 0 (measurements map_points): until a 'constant' (alpha_z) has its first informative frame, every frame also
    # fits the tracked parameters with the constant held at each of this many values over its range (the map points
    # relinked at each), and keeps the best fit where it explains the images visibly better (0: off; the constant
    # then moves only by the frame's own fit, and not at all while the object looks undeformed)
    constant_search: int = 0
    # how long the search runs: "seen" (until the constant's first informative frame) or "frozen" (every frame until
    # the constant is fixed: a search that wins there by ``min_deformation_px`` moves the constant to another basin
    # and restarts its informative frames, which came from the basin it left)
    constant_search_until: str = "seen"
    dense: DenseSettings = field(default_factory=DenseSettings)  # measurements 'dense'
    # measurements 'dense': a deformation is seen when it lowers the photometric residual by this fraction
    dense_min_gain: float = 0.05
    # the state in the reference view: "depth" (fitted to the depth image where there is one, :mod:`.depth_state`)
    # or "rest"
    reference: str = "depth"
    depth_state: DepthStateConfig = field(default_factory=DepthStateConfig)
    # measurements 'map_points' with a depth image (RGB-D): the tracked state is read from every frame's depth
    # (:class:`.depth_state.DepthFollower`; the boot's tracker: 9 -> 58 ms a frame on 2 cores), the image fit
    # giving its start, the constants (alpha_z) and whether a deformation is seen. A knob: the boot's scene files
    # set it (docs/family.md, stop 71)
    depth_fit: bool = False
    # with depth_fit: the depth image's pixels taken, one in depth_stride along each axis (2: a quarter of them). The
    # fit's time goes with the points it matches; fewer points, a noisier fit (docs/family.md, stop 73)
    depth_stride: int = 2
    # with depth_fit on a body of revolution about its z axis (the boot): alpha_z reported with the depth fit's turn
    # about that axis, taken from the frames whose depth holds it (DeformableTracker.depth_turn)
    depth_turn: bool = False
    # with depth_fit: a frame with too few image measurements on the object (its map points lost while a busy
    # localization skipped frames, or the object moved before it was placed) is read from its depth alone, the
    # constants (alpha_z) held, and reported low-confidence, instead of lost with its last values (stop 88: the live
    # joint boot, benchmarks/live_slam.py; measured on the boot family's development seeds, docs/family.md)
    depth_alone: bool = True


@dataclass
class Estimate:
    names: list[str]
    units: list[str]
    values: np.ndarray
    frozen: np.ndarray
    cov: np.ndarray
    rms_px: float = float("nan")
    inliers: int = 0
    measurements: int = 0
    iterations: int = 0
    state: EstimateState = EstimateState.INITIALIZING
    reason: str = ""
    deforming: bool = False
    solve_ms: float = 0.0
    debug: dict[str, Any] = field(default_factory=dict)


class DeformableTracker:
    """One object's estimate. ``values``: the model state in ``layout`` order (mu, then alpha_z when the scene
    estimates it), what :class:`Estimate` and the ModelParameters message carry."""

    def __init__(self, model: ReducedModel, T_map_obj: np.ndarray, params: dict[str, dict[str, Any]],
                 cam: CameraModel, cfg: TrackerConfig | None = None) -> None:
        self.model = model
        self.cfg = cfg or TrackerConfig()
        self.cam = cam
        self.K = cam.K
        self.T_map_obj = np.asarray(T_map_obj, dtype=np.float64)
        axes = model.axes
        for a in axes:
            if a.kind != "continuous":
                raise ValueError(f"parameter '{a.name}' of model '{model.name}' is discrete: it cannot be tracked "
                                 "from images (it is set by collision)")
        self.rigid_z = ALPHA_Z in params and any(r["name"] == ALPHA_Z for r in model.rigid_parameters)
        self.layout = StateLayout.of(model, alpha_z=self.rigid_z)
        self.names, self.units = self.layout.names, self.layout.units
        self.lo, self.hi = self.layout.bounds()
        n = len(self.names)
        self.values = 0.5 * (self.lo + self.hi)
        self.shift = np.zeros(3)  # object translation (map frame) fitted with cfg.object_shift_m
        self.mode = ["tracked"] * n
        for i, name in enumerate(self.names):
            cfgp = params.get(name, {})
            self.mode[i] = cfgp.get("mode", "tracked")
            init = cfgp.get("initial")
            if self.mode[i] == "fixed":
                init = cfgp.get("value")
            if init is not None:
                self.values[i] = float(np.clip(init, self.lo[i], self.hi[i]))
            elif self.names[i] == ALPHA_Z:
                self.values[i] = 0.0
        self.frozen = np.array([m == "fixed" for m in self.mode])
        self._initial = self.values.copy()  # the scene's start values
        self._const_samples: list[np.ndarray] = []
        self._was_deforming = False  # constants move only once deformation makes them observable
        self.cand_nodes = surface_nodes(model)
        # the nodes' configuration a map point is linked in (rest, or the deformation it was mapped in) -> those
        # positions and their :class:`LinkIndex`: the alpha_z search relinks every point two dozen times a frame
        self._link_geometry: dict[bytes, tuple[np.ndarray, LinkIndex]] = {}
        self._cand_view = model.deformation_view(self.cand_nodes, self.cfg.n_modes or None)
        # map point id -> its link (nodes, weights, rest position, position as mapped, mu it was mapped in, ray)
        self.links: dict[int, Link] = {}
        self.static: set[int] = set()
        self._last_seen: dict[int, int] = {}  # map point id (linked or static) -> the _seen_frames count it was seen at
        self._seen_frames = 0
        self._alpha_linked: float | None = None
        self.deforming_frames = 0
        self._dot_links: tuple[np.ndarray, np.ndarray] | None = None
        self.outlier_ids = np.zeros(0, np.int64)  # map points the last fit rejected (their image tracks slid)
        self._rms_ref: float | None = None  # running residual RMS of good fits: what "fits badly" is measured against
        self._frames = 0  # frames solved (a periodic global restart every 30th)
        # cfg.rest_frames: (object-frame dots, their pixels, T_cw, nodes, weights) of the frames at rest, and how many
        # frames with a camera pose have passed since the first (the window is the first rest_frames of them)
        self._rest_obs: list[tuple[np.ndarray, ...]] | None = [] if self.cfg.rest_frames else None
        self._rest_seen = 0
        self.rest_correction: dict[str, Any] | None = None  # what the rest alignment did (cfg.rest_frames)
        self._outline: tuple[np.ndarray, lm.Displacement] | None = None  # screen_region's nodes and their view
        self.dense: DenseAligner | None = None
        self.reference_state: np.ndarray | None = None  # mu a registration's depth fit found (None: at rest)
        # sparse measurements: whether the object's state was read from a depth image yet (see needs_depth)
        self._reference_read = self.cfg.reference != "depth" or self.cfg.measurements != "map_points"
        self._reference_tries = 0
        self.depth: DepthFollower | None = None
        self._turns: deque[float] = deque(maxlen=300)  # the object's turn in the frames whose depth held it
        if self.cfg.depth_fit and self.cfg.measurements == "map_points":
            n_mu = len(model.axes)
            self.depth = DepthFollower(model, self.cfg.depth_state, self.cfg.n_modes or None, self.lo[:n_mu],
                                       self.hi[:n_mu])
            self.depth.judge_turn = self.cfg.depth_turn
        self._turn_is_alpha = self._turn_axis_is_alpha()  # fixed by the model and the settings: once, not per frame
        if self.cfg.measurements == "dense":
            if self.rigid_z:
                raise ValueError("measurements 'dense' do not estimate alpha_z: use map_points for this object")
            self.dense = DenseAligner(model, self.T_map_obj, cam, self.cfg.n_modes or None, self.cfg.dense)
        if self.cfg.measurements in ("dots", "homography"):
            if self.cfg.dots is None or len(self.cfg.dots) == 0:
                raise ValueError("measurements 'dots' need the dots' reference positions (tracking.dots)")
            L = link(self.cfg.dots, model.points, self.cand_nodes, max_dist=np.inf, triangles=model.surface)
            self._dot_links = (L.nodes, L.weights)

    # -- geometry ----------------------------------------------------------------------------------------
    @property
    def R_wo(self) -> np.ndarray:
        return self.T_map_obj[:3, :3]

    @property
    def model_state(self) -> ModelState:
        """The current estimate as a model state (its mu is a view of ``values``)."""
        return self.layout.state(self.values)

    def _disp_fn(self, nodes: np.ndarray, weights: np.ndarray) -> lm.Displacement:
        """mu -> (dX (N, 3), d dX / d mu (N, 3, n_mu)) in the object frame, through the linked nodes (the link
        weights folded into the modes once: one small product per evaluation)."""
        return self.model.deformation_view(nodes, self.cfg.n_modes or None, weights).with_jacobian

    def viewing_rays(self, T_wc: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(N, 2, 3) map-frame viewing rays (camera centre, unit direction) of raw pixels ``uv`` (N, 2)."""
        und = self.cam.undistort_points(np.asarray(uv, np.float64).reshape(-1, 2))
        d = np.c_[und, np.ones(len(und))] @ np.linalg.inv(self.K).T @ T_wc[:3, :3].T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.stack([np.broadcast_to(T_wc[:3, 3], d.shape), d], axis=1)

    def link_points(self, ids: np.ndarray, P_map: np.ndarray, mu: np.ndarray | str | None = "current",
                    rays: np.ndarray | None = None) -> None:
        """Link newly seen map points to model nodes (object frame, undoing the current alpha). ``mu``: the
        deformation the points were mapped in, None for the rest shape; "current": the current estimate once
        deformation was seen, else the rest shape.

        With ``snap_to_surface`` the rest position used from then on is the point's foot on the registered
        model surface (Sum w_i x_i of its link): a depth or triangulation error across the surface, a few mm
        on a thin lever seen at its edges, would otherwise turn into an image error that grows with the
        rotation (radius error x angle); the link then describes the material point exactly."""
        new = [i for i, pid in enumerate(ids) if int(pid) not in self.links and int(pid) not in self.static]
        if not new:
            return
        if isinstance(mu, str):
            mu = self.model_state.mu.copy() if (self._was_deforming and self.cfg.snap_to_surface) else None
        P = P_map[new]
        R = None if rays is None else np.asarray(rays, np.float64)[new]
        ((L, X_rest),) = self._links_of(P, mu, R, [self.model_state.rotation()])
        self._keep_links(self.links, self.static, [int(ids[i]) for i in new], P, L, X_rest, mu, R)

    def _links_of(self, P: np.ndarray, mu: np.ndarray | None, rays: np.ndarray | None,
                  turns: list[np.ndarray]) -> list[tuple[Links, np.ndarray]]:
        """The links of map points ``P`` (map frame, (N, 3)) that were mapped in the deformation ``mu`` (None: the
        rest shape), seen along ``rays`` ((N, 2, 3) or None), with the object turned by each rotation of ``turns``
        (alpha, undone: object frame X = T_om P R_z): per turn the links and the rest positions kept with them (map
        frame). Every turn's points go through one :func:`link` (a point's link does not depend on the others'):
        the search of alpha_z relinks the same points at every value it tries (:meth:`_relinked_at`). The rest
        positions: see :meth:`link_points`."""
        T_om = G.inv(self.T_map_obj)
        Po = G.transform(T_om, P)
        X = np.concatenate([Po @ Rz for Rz in turns])  # R_z(-a) applied: row vectors
        V, index = self._linked_in(mu)
        L = link(X, V, self.cand_nodes, self.cfg.link_dist, triangles=self.model.surface, index=index)
        if self.cfg.snap_to_surface and self.cfg.anchor == "ray" and rays is not None:
            # the material point a track follows is the one under its pixel: where that pixel's viewing ray
            # crosses the link's triangle (a depth error along the ray then moves nothing)
            O0, D0 = G.transform(T_om, rays[:, 0]), rays[:, 1] @ T_om[:3, :3].T
            O, D = np.concatenate([O0 @ Rz for Rz in turns]), np.concatenate([D0 @ Rz for Rz in turns])
            L.weights = ray_weights(O, D, V[L.nodes], L.weights)
        out = []
        for j, Rz in enumerate(turns):
            part = slice(j * len(P), (j + 1) * len(P))
            Lj = Links(L.nodes[part], L.weights[part], L.dist[part], L.on_object[part])
            if self.cfg.snap_to_surface:
                foot = np.einsum("nk,nkd->nd", Lj.weights, self.model.points[Lj.nodes])  # rest configuration
                out.append((Lj, G.transform(self.T_map_obj, foot @ Rz.T)))
            else:
                out.append((Lj, P))
        return out

    @staticmethod
    def _keep_links(links: dict[int, Link], static: set[int], pids: list[int], P: np.ndarray, L: Links,
                    X_rest: np.ndarray, mu: np.ndarray | None, rays: np.ndarray | None) -> None:
        """Points ``pids`` (map positions ``P``) into ``links`` with their links ``L`` and rest positions ``X_rest``,
        or, off the object, into ``static``."""
        for k, pid in enumerate(pids):
            if L.on_object[k]:
                links[pid] = Link(L.nodes[k], L.weights[k], X_rest[k].copy(), P[k].copy(), mu,
                                  None if rays is None else rays[k].copy())
            else:
                static.add(pid)

    def _linked_in(self, mu: np.ndarray | None) -> tuple[np.ndarray, LinkIndex]:
        """The nodes' positions a point is linked against (object frame, alpha undone) and their search index:
        the rest shape (``mu`` None), or the deformation ``mu`` a point was first mapped in (it sits on the deformed
        surface: linked there, its weights carry it back to the rest configuration, the inverse of Eq. 4.10's
        interpolation). Kept for the last 32 configurations asked for."""
        key = b"rest" if mu is None else np.asarray(mu, np.float64).tobytes()
        hit = self._link_geometry.get(key)
        if hit is not None:
            return hit
        V = self.model.points
        if mu is not None:
            V = V.copy()
            V[self.cand_nodes] += self._cand_view.with_jacobian(mu)[0]
        out = (V, LinkIndex(V, self.cand_nodes, self.model.surface))
        if len(self._link_geometry) >= 32:
            self._link_geometry.pop(next(iter(self._link_geometry)))
        self._link_geometry[key] = out
        return out

    def relink(self) -> None:
        """alpha changed: the same map points now sit at other material points (each relinked in the
        deformation it was mapped in)."""
        if not self.links:
            return
        groups = self._link_groups()
        old = dict(self.links)
        self.links.clear()
        for pids in groups:
            rays = np.array([np.full((2, 3), np.nan) if old[i].ray is None else old[i].ray for i in pids])
            self.link_points(np.array(pids), np.array([old[i].P_map for i in pids]), old[pids[0]].mu, rays)

    def _link_groups(self) -> list[list[int]]:
        """The linked points grouped by the deformation they were mapped in (as :meth:`relink` links them)."""
        groups: dict[tuple[Any, ...] | None, list[int]] = {}
        for pid, lk in self.links.items():
            key = None if lk.mu is None else tuple(np.round(lk.mu, 12))
            groups.setdefault(key, []).append(pid)
        return list(groups.values())

    def _relinked_at(self, c: int, values: list[float]) -> list[tuple[dict[int, Link], set[int]]]:
        """What :meth:`relink` would leave (the links and the static points) with the constant ``c`` (alpha_z) at
        each of ``values``, each time from the present links: the same links, each group's points linked for every
        value in one call (:meth:`_links_of`) instead of one call per group and value."""
        if not values:
            return []
        turns = []
        for g in values:
            v = self.values.copy()
            v[c] = g
            turns.append(self.layout.state(v).rotation())
        old = dict(self.links)
        out: list[tuple[dict[int, Link], set[int]]] = [({}, set(self.static)) for _ in values]
        for pids in self._link_groups():
            new = [p for p in pids if p not in self.static]  # link_points' test (the links are cleared first)
            if not new:
                continue
            mu = old[pids[0]].mu
            P = np.array([old[i].P_map for i in new])
            rays = np.array([np.full((2, 3), np.nan) if old[i].ray is None else old[i].ray for i in new])
            for (links, static), (L, X_rest) in zip(out, self._links_of(P, mu, rays, turns), strict=True):
                self._keep_links(links, static, new, P, L, X_rest, mu, rays)
        return out

    @property
    def deformable_ids(self) -> list[int]:
        return sorted(self.links)

    def predicted_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(ids, (N, 3) map-frame positions) of the linked map points moved by the current estimate: where the
        localization should look for them in the next image (deformable ORB tracking, §4.4.2). Before any
        deformation has been seen the rest positions are the prediction (the estimate is then meaningless)."""
        ids = np.array(self.deformable_ids, dtype=np.int64)
        if len(ids) == 0:
            return ids, np.zeros((0, 3))
        X = np.array([self.links[int(i)].X_rest for i in ids])
        if not self._was_deforming:
            return ids, X
        nodes = np.array([self.links[int(i)].nodes for i in ids])
        w = np.array([self.links[int(i)].weights for i in ids])
        state = self.model_state
        dX = self._disp_fn(nodes, w)(state.mu)[0]
        return ids, X + dX @ (self.R_wo @ state.rotation()).T

    def screen_region(self, T_wc: np.ndarray, max_nodes: int = 200) -> np.ndarray | None:
        """(K, 2) convex polygon in image pixels (distorted) where the object's surface projects from camera pose
        ``T_wc`` under the current estimate, or None where none of it is in front of the camera: the region whose
        features the SLAM's extractor guarantees a share (a faint object still gets measured). Up to ``max_nodes``
        surface nodes, evenly picked, bound it: the hull needs only the outline, not every node."""
        import cv2

        cand = self.cand_nodes[:: max(1, len(self.cand_nodes) // max_nodes)]
        X = self.model.points[cand].astype(np.float64)
        state = self.model_state
        if self._was_deforming:
            if self._outline is None or len(self._outline[0]) != len(cand):  # the outline's view, built once
                self._outline = (cand, self._disp_fn(cand[:, None], np.ones((len(cand), 1))))
            X = X + self._outline[1](state.mu)[0] @ state.rotation().T
        Xc = G.transform(G.inv(np.asarray(T_wc, np.float64)) @ self.T_map_obj, X)
        Xc = Xc[Xc[:, 2] > 0.05]
        if len(Xc) < 3:
            return None
        uv = self.cam.project(Xc).astype(np.float32)
        return cv2.convexHull(uv)[:, 0].astype(np.float64)

    def _link_observed(self, T_wc: np.ndarray, ids: np.ndarray, P_map: np.ndarray,
                       uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """This frame's observed map points with finite positions and pixels, the new ones linked (from their
        pixels' viewing rays): (ids, map positions (N, 3), raw pixels (N, 2))."""
        ids, P, q = _finite_observations(ids, P_map, uv)
        self.link_points(ids, P, rays=self.viewing_rays(T_wc, q))
        self._forget_unseen(ids)
        return ids, P, q

    def _forget_unseen(self, ids: np.ndarray) -> None:
        """Note this frame's observed map points; every ``link_ttl_frames // 4`` frames, forget the links (and the
        static verdicts) of points not observed for ``link_ttl_frames`` frames."""
        self._seen_frames += 1
        now = self._seen_frames
        self._last_seen.update((int(i), now) for i in ids)
        ttl = self.cfg.link_ttl_frames
        if ttl <= 0 or now % max(ttl // 4, 1):
            return
        old = [pid for pid, t in self._last_seen.items() if now - t > ttl]
        for pid in old:
            del self._last_seen[pid]
            self.links.pop(pid, None)
            self.static.discard(pid)

    # -- measurements ------------------------------------------------------------------------------------------
    def map_point_measurements(self, ids: np.ndarray, P_map: np.ndarray, uv: np.ndarray) -> Measurements | None:
        """The measurements a frame's observed map points give once linked (what :meth:`update` fits): (X rest
        positions, ideal pixels, nodes, weights, point ids, pixel noise scales: a fisheye's stretch, else empty), or
        None where none of them is linked."""
        return self._map_point_measurements(*_finite_observations(ids, P_map, uv))

    def _map_point_measurements(self, ids: np.ndarray, P_map: np.ndarray, uv: np.ndarray) -> Measurements | None:
        sel = [k for k, pid in enumerate(ids) if int(pid) in self.links]
        if self.cfg.max_points and len(sel) > self.cfg.max_points:
            sel = sel[:: max(1, len(sel) // self.cfg.max_points)][: self.cfg.max_points]
        if not sel:
            return None
        lks = [self.links[int(ids[k])] for k in sel]
        nodes = np.array([lk.nodes for lk in lks])
        w = np.array([lk.weights for lk in lks])
        X = np.array([lk.X_rest for lk in lks])
        # a fisheye's periphery is stretched in the ideal image: each residual weighed as the image pixel it is
        # (CameraModel.stretch), so that the Huber threshold means the same on every part of the image
        sigma = self.cam.stretch(uv[sel]) if self.cam.fisheye else np.zeros(0)  # (none: 1 each)
        return X, self.cam.undistort_points(uv[sel]), nodes, w, np.asarray(ids)[sel], sigma

    def _dot_measurements(self, image_bgr: np.ndarray, T_cw: np.ndarray) -> tuple[Measurements | None, int]:
        from simreal_nodes.vision.blobs import detect_color_blobs

        # the constructor linked the dots (it raises without them) for the dot measurements this serves
        assert self._dot_links is not None
        nodes, w = self._dot_links
        X, pred, z = self._predicted_dots(T_cw)
        # blobs are looked for only where one may be associated with a dot: within the association radius of a
        # prediction in front of the camera (issue 18: a tenth to a third of the image for the demo's dots)
        box = self._dot_box(pred[(z > 0) & np.isfinite(pred).all(axis=1)])
        if box is None:
            return None, 0
        found = detect_color_blobs(image_bgr, self.cfg.dot_color, within=box)
        if len(found) == 0:
            return None, 0
        und = self.cam.undistort_points(found)
        ray = np.isfinite(und).all(axis=1)
        if not ray.all():  # a fisheye's blob past 90 degrees off the axis: no ray to fit
            found, und = found[ray], und[ray]
            if len(found) == 0:
                return None, 0
        tree = cKDTree(und)
        # many query points with k=1: arrays of distances and indices (the stubs also allow scalars)
        d, j = cast(tuple[np.ndarray, np.ndarray], tree.query(np.nan_to_num(pred, nan=-1e6), k=1))
        ok = (d <= self.cfg.dot_radius_px) & (z > 0)
        # one detection per dot
        ok &= np.bincount(j[ok], minlength=len(und))[j] == 1
        if not ok.any():
            return None, len(found)
        # (no map point ids: dots; a fisheye's stretch weighs each residual as in _map_point_measurements)
        sigma = self.cam.stretch(found[j[ok]]) if self.cam.fisheye else np.zeros(0)
        return (X[ok], und[j[ok]], nodes[ok], w[ok], np.zeros(0, np.int64), sigma), len(found)

    def _predicted_dots(self, T_cw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The glued dots at rest in the map frame (N, 3), and where the current estimate puts them: ideal pixels
        (N, 2) and depths (N,) seen from ``T_cw``."""
        assert self._dot_links is not None and self.cfg.dots is not None
        X = G.transform(self.T_map_obj, self.cfg.dots)
        state = self.model_state
        dX, _ = self._disp_fn(*self._dot_links)(state.mu)
        pred, z = _project(T_cw, X + dX @ (self.R_wo @ state.rotation()).T, self.K)
        return X, pred, z

    def _dot_box(self, pred: np.ndarray) -> tuple[float, float, float, float] | None:
        """The image-pixel box that holds every point within ``dot_radius_px`` (ideal pixels) of the predicted dots
        ``pred`` (ideal pixels, in front of the camera): with a lens, the bounds of each disc's rim taken through it
        (32 points a rim, the box grown by a pixel for the rim's curve between them); None without a prediction.
        Where a plumb_bob lens's curve turns back (far outside the image for a strong barrel) the rim does not bound
        the disc's pixels; the undistortion does not converge there either, so no association holds there."""
        if not len(pred):
            return None
        r = float(self.cfg.dot_radius_px)
        if not self.cam.has_distortion:
            lo, hi = pred.min(axis=0) - r, pred.max(axis=0) + r
        else:
            t = np.linspace(0.0, 2.0 * np.pi, 32, endpoint=False)
            rim = (pred[:, None, :] + r * np.stack((np.cos(t), np.sin(t)), axis=1)[None]).reshape(-1, 2)
            raw = self.cam.project(self.cam.backproject(rim, np.ones(len(rim))))
            raw = raw[np.isfinite(raw).all(axis=1)]
            if not len(raw):
                return None
            lo, hi = raw.min(axis=0) - 1.0, raw.max(axis=0) + 1.0
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    # -- per frame ----------------------------------------------------------------------------------------------
    def update(self, T_wc: np.ndarray | None, ids: np.ndarray | None = None, P_map: np.ndarray | None = None,
               uv: np.ndarray | None = None, image_bgr: np.ndarray | None = None,
               depth: np.ndarray | None = None) -> Estimate:
        import time

        est = Estimate(self.names, self.units, self.values.copy(), self.frozen.copy(),
                       np.full((len(self.values),) * 2, np.nan))
        if T_wc is None:
            est.state, est.reason = EstimateState.LOST, "no camera pose this frame (localization lost)"
            return est
        T_cw = G.inv(T_wc)
        if self.dense is not None:
            return self._update_dense(est, T_wc, ids, P_map, uv, image_bgr, depth)
        if self.cfg.measurements == "map_points":
            self._read_reference(est, T_wc, depth)
            if ids is None or len(ids) == 0 or P_map is None or uv is None:
                why = "no map points observed on the object"
                alone = self._depth_alone(est, T_wc, depth, why)
                if alone is not None:
                    return alone
                est.state, est.reason = EstimateState.LOST, f"no measurements: {why}"
                return est
            ids, P_map, uv = self._link_observed(T_wc, ids, P_map, uv)
            meas = self._map_point_measurements(ids, P_map, uv)
            found = len(ids)
        else:
            if image_bgr is None:
                est.state, est.reason = EstimateState.LOST, "measurements 'dots' need the image"
                return est
            meas, found = self._dot_measurements(image_bgr, T_cw)
            if self._rest_obs is not None:  # the first rest_frames frames: the pose is measured, nothing else
                self._rest_seen += 1
                if meas is not None and len(meas[0]) >= self.cfg.min_measurements:
                    X, uvm, nodes, w = meas[:4]
                    self._rest_obs.append((G.transform(G.inv(self.T_map_obj), X), uvm, T_cw, nodes, w))
                if self._rest_seen < self.cfg.rest_frames:
                    est.state = EstimateState.INITIALIZING
                    est.reason = (f"measuring the object's pose at rest ({self._rest_seen} of {self.cfg.rest_frames}"
                                  f" frames, {len(self._rest_obs)} with its dots)")
                    return est
                self._align_at_rest()
                meas, found = self._dot_measurements(image_bgr, T_cw)
            if self.rest_correction:
                est.debug["rest_correction"] = self.rest_correction
        if meas is None or len(meas[0]) < self.cfg.min_measurements:
            n = 0 if meas is None else len(meas[0])
            why = (f"too few measurements on the object ({n}, need {self.cfg.min_measurements}; "
                   f"{found} candidates seen{' near the predicted dots' if self.cfg.measurements == 'dots' else ''})")
            alone = self._depth_alone(est, T_wc, depth, why)  # None but with map points and depth_fit
            if alone is not None:
                alone.measurements = n
                return alone
            est.state = EstimateState.LOST
            est.reason = why
            est.measurements = n
            return est
        X, uvm, nodes, w = meas[:4]
        est.measurements = len(X)
        disp = self._disp_fn(nodes, w)
        lo, hi = self._free_bounds()
        t0 = time.perf_counter()
        if self.cfg.measurements == "homography":
            res, rest_rms = self._solve_planar(X, uvm, disp, T_cw, lo, hi)
        else:
            sh = self.cfg.object_shift_m
            p = lm.Problem(X, uvm, disp, T_cw, self.R_wo, self.K, self.layout.with_shift() if sh > 0 else self.layout,
                           _sigma(meas))
            x0, lo_p, hi_p = self.values, lo, hi
            if sh > 0:
                x0, lo_p, hi_p = np.r_[self.values, self.shift], np.r_[lo, -sh, -sh, -sh], np.r_[hi, sh, sh, sh]
            res = lm.solve(p, x0, lo_p, hi_p, self.cfg.huber_px, self.cfg.max_iterations,
                           refits=self.cfg.outlier_refits)
            self._frames += 1
            if self.cfg.global_samples and self._fits_badly(res, len(X)):
                res = self._global_restart(p, res, lo_p, hi_p)
                est.debug["restarted"] = True
            searching = not self._const_samples or (self.cfg.constant_search_until == "frozen"
                                                    and self._unfrozen_constants().size > 0)
            if (self.cfg.constant_search and searching and sh <= 0
                    and self.cfg.measurements == "map_points" and ids is not None and P_map is not None
                    and uv is not None):
                res, meas = self._constant_search(res, meas, lo_p, hi_p, est, T_cw, ids, P_map, uv)
                X, uvm = meas[0], meas[1]
            if sh > 0:  # the shift is a nuisance: kept for the next frame, reported in debug, marginalised out
                n = len(self.values)
                self.shift = res.x[n:].copy()
                est.debug["object_shift_m"] = self.shift.copy()
                res.x, res.cov = res.x[:n], res.cov[:n, :n]
            if self.depth is not None and depth is not None:
                self._depth_state(res, T_wc, depth, lo, hi, est, meas, T_cw)
            if res.inliers >= 0.85 * len(X) and np.isfinite(res.rms_px):
                self._rms_ref = res.rms_px if self._rms_ref is None else 0.9 * self._rms_ref + 0.1 * res.rms_px
            rest_rms = self._rest_rms(X, uvm, T_cw)
        est.solve_ms = (time.perf_counter() - t0) * 1e3
        est.values, est.cov = res.x.copy(), res.cov
        est.rms_px, est.inliers, est.iterations = res.rms_px, res.inliers, res.iterations
        est.debug["rest_rms_px"] = rest_rms
        self.outlier_ids = np.zeros(0, np.int64)
        # a fit the majority agrees with judges the rest, and so does the depth's state (measured without them)
        if len(meas) > 4 and len(meas[4]) == len(X) and (res.inliers >= 0.6 * len(X) or "image_mu" in est.debug):
            self.outlier_ids = meas[4][np.linalg.norm(res.residuals, axis=1) > 2 * self.cfg.huber_px]
        if (res.inliers < self.cfg.min_measurements or not np.isfinite(res.rms_px)) and "image_mu" not in est.debug:
            est.state = EstimateState.LOST
            est.reason = f"only {res.inliers} of {len(X)} measurements agree with the model (all outliers?)"
            return est
        gain = rest_rms - res.rms_px
        est = self._conclude(est, res.x, bool(gain > self.cfg.min_deformation_px),
                             f"residual {res.rms_px:.2f} px vs {rest_rms:.2f} px undeformed")
        self._report_turn(est)
        return est

    def _report_turn(self, est: Estimate) -> None:
        """alpha_z reported with the depth's turn (:attr:`depth_turn`, ``cfg.depth_turn`` on the boot)."""
        turn = self.depth_turn if self.rigid_z else 0.0
        if turn:
            i = self.layout.alpha_index
            est.values[i] = _wrap(est.values[i] + turn, self.lo[i], self.hi[i])
            est.debug["depth_turn"] = turn

    def _fit_depth(self, x: np.ndarray, T_wc: np.ndarray, depth: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray) -> DepthFit:
        """The depth follower's fit of this frame's depth image from state ``x`` (its crop around the object posed
        with ``x``'s rotation; ``lo`` / ``hi``: this frame's bounds)."""
        assert self.depth is not None
        n_mu = len(self.model.axes)
        T = self.T_map_obj @ G.make_T(self.layout.state(x).rotation())
        cloud = depth_cloud(self.cam, depth, T_wc, stride=self.cfg.depth_stride, within=self.depth.corners(T))
        return self.depth.fit(cloud, T, lo[:n_mu], hi[:n_mu], x[:n_mu])

    @property
    def depth_turn(self) -> float:
        """With ``depth_fit`` and ``depth_turn`` on a body of revolution about its z axis (the boot): what the depth
        adds to the images' alpha_z. Each frame whose depth holds the turn (:attr:`.depth_state.DepthFit.turn_held`:
        the bellows bent) gives the object's whole turn about its axis, the images' alpha_z of that frame's fit plus
        the depth fit's turn on it (its upright rigid correction turns the model about its centroid, which lies on
        the axis); the estimate reports the median of those turns (the last 300 such frames). The depth sees which
        way the bellows bends, the images (its ORB map points) see it only as well as they follow the material; the
        images' own alpha_z stays what the links, the search and the freezing use. 0.0 otherwise, until such a
        frame, and where alpha_z is 'fixed' (given, not estimated: a scene file cannot ask for both, and until stop
        106 a tracker built with both reported the depth's turn on the fixed value)."""
        if not self._turns or self.mode[self.layout.alpha_index] == "fixed":
            return 0.0
        t = np.array(self._turns)
        total = t[-1] + float(np.median(_signed_angle(t - t[-1])))
        return float(_signed_angle(total - self.values[self.layout.alpha_index]))

    def _depth_state(self, res: lm.Result, T_wc: np.ndarray, depth: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                     est: Estimate, meas: Measurements, T_cw: np.ndarray) -> None:
        """``cfg.depth_fit``: the tracked state read from this frame's depth, placed with the image fit's alpha_z
        (:class:`.depth_state.DepthFollower`), replaces the image fit's mu in ``res``; where the depth gives no sound
        fit the image fit's stands (``est.debug['depth']`` says why). The measurements' residuals are then those at
        the depth's state: the tracks that slid from it are dropped (:attr:`outlier_ids`) and found again."""
        assert self.depth is not None
        depth = np.asarray(depth)
        if depth.shape != (self.cam.height, self.cam.width):
            est.debug["depth"] = (f"depth image {depth.shape} is not the camera's {self.cam.height} x "
                                  f"{self.cam.width}: the image fit stands")
            return
        n_mu = len(self.model.axes)
        fit = self._fit_depth(res.x, T_wc, depth, lo, hi)
        est.debug["depth"] = fit.reason
        self._take_turn(res.x, fit)
        if fit.mu is not None:
            est.debug["image_mu"] = res.x[:n_mu].copy()
            res.x = res.x.copy()
            res.x[:n_mu] = fit.mu
            X, uvm, nodes, w = meas[:4]
            sig = _sigma(meas)
            p = lm.Problem(X, uvm, self._disp_fn(nodes, w), T_cw, self.R_wo, self.K, self.layout, sig)
            res.residuals = uvm - lm.predict(p, res.x, with_jacobian=False)[0]
            if sig is not None:  # in units of each measurement's noise, as lm.solve gives them
                res.residuals = res.residuals / sig[:, None]

    def _take_turn(self, x: np.ndarray, fit: DepthFit) -> None:
        """A depth fit from state ``x`` that holds its turn (the bellows bent, :attr:`.depth_state.DepthFit.turn_held`)
        adds the object's whole turn, ``x``'s alpha_z plus the fit's turn, to those :attr:`depth_turn` reports the
        median of (``cfg.depth_turn`` on a body of revolution about its z axis)."""
        if (self._turn_is_alpha and self.depth is not None and fit.mu is not None
                and fit.turn_held < self.depth.turn_ratio_max):
            self._turns.append(float(x[self.layout.alpha_index]) + fit.turn)

    def _depth_alone(self, est: Estimate, T_wc: np.ndarray, depth: np.ndarray | None, why: str) -> Estimate | None:
        """``cfg.depth_alone`` (with ``depth_fit``): a frame whose images give too few measurements on the object
        (``why``) is read from its depth alone: the depth fit (:class:`.depth_state.DepthFollower`) from the last
        values, the constants held (the depth does not see alpha_z's sign; the images give it), reported
        low-confidence with why. The new values also say where the object's map points are searched next frame. None
        where the fit cannot run or gives no sound fit (the caller reports the frame lost, as without it)."""
        if not self.cfg.depth_alone or self.depth is None or depth is None or not self._reference_read:
            return None
        depth = np.asarray(depth)
        if depth.shape != (self.cam.height, self.cam.width):
            return None
        fit = self._fit_depth(self.values, T_wc, depth, *self._free_bounds())
        est.debug["depth"] = fit.reason
        # its turn counts as an image-fitted frame's does: the bent boot placed late is read from its depth alone
        # until its map points are linked, and its alpha_z stayed at its start meanwhile (stop 105)
        self._take_turn(self.values, fit)
        if fit.mu is None:
            return None
        self.values = self.values.copy()
        self.values[:len(fit.mu)] = fit.mu
        est.values = self.values.copy()
        self._report_turn(est)
        est.deforming = self._was_deforming
        est.state = EstimateState.LOW_CONFIDENCE
        est.reason = f"{why}: read from the depth alone, the constants held ({fit.reason})"
        return est

    def _free_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """This frame's bounds: fixed and frozen parameters pinned at their values (lo == hi)."""
        free = ~self.frozen
        if not self._was_deforming:
            # an undeformed object says nothing about its constants (alpha_z of an axisymmetric boot, a stiffness):
            # hold them until a deformation is seen, or they drift along the flat directions of the cost
            free &= np.array([m != "constant" for m in self.mode])
        return np.where(free, self.lo, self.values), np.where(free, self.hi, self.values)

    def _conclude(self, est: Estimate, x: np.ndarray, deforming: bool, evidence: str) -> Estimate:
        """The common end of a solved frame: the new estimate, whether a deformation was seen (``evidence``
        says how it was judged), the observability check and the constants."""
        est.deforming = deforming
        self._was_deforming = est.deforming
        # a constant this frame cannot see keeps its value: an undeformed frame, or one whose constant has a standard
        # deviation over 5 % of its range (alpha_z of a barely bent boot). Left free, it wanders along the flat cost
        # and the load's first frames find it in another basin (the lever turning the other way). Nor does a frame
        # move it whose tracked parameters it cannot pin (a standard deviation over 5 % of their range: the frame
        # is flagged below): the two are fitted together, and such a frame's constant is one end of a valley. Stop
        # 124: the thesis's boot in a starved graph (every 10th frame), 16 measurements, lever "barely observable",
        # turned alpha_z by 90 degrees, which the next frames kept (lever 3.2 degrees off at the median)
        std = np.sqrt(np.clip(np.diag(est.cov), 0, None))
        loose = std > 0.05 * (self.hi - self.lo)
        unpinned = bool(np.any(np.array([m == "tracked" for m in self.mode]) & ~self.frozen & loose))
        blind = np.array([m == "constant" for m in self.mode]) & ~self.frozen & ((not deforming) | unpinned | loose)
        x = np.where(blind, self.values, x)
        est.values = np.where(blind, self.values, est.values)  # and it is reported with the value it keeps
        # a tracked parameter whose standard deviation exceeds that of a value drawn uniformly over its range (range
        # / sqrt(12)) was not measured by this frame at all: the fit's value is wherever the flat cost let LM stop
        # (development seed 12 of the boot: its lever at 47 degrees, 17 points left, read 0.4 degree). It keeps the
        # last value, flagged below, and the next frame starts from there
        uniform = (self.hi - self.lo) / np.sqrt(12.0)
        unseen = np.array([m == "tracked" for m in self.mode]) & ~self.frozen & (std > uniform)
        x = np.where(unseen, self.values, x)
        est.values = np.where(unseen, self.values, est.values)
        self.values = x.copy()
        if not est.deforming:
            # barely anything to see (load absent, or near the clamp where the images hardly see its effect):
            # report the bounded estimate with the large variance the normal equations give, flagged; the
            # constants are not estimated from such frames
            est.state = EstimateState.LOW_CONFIDENCE
            est.reason = (f"no measurable deformation ({evidence}): "
                          "the load may be absent or where the images cannot see its effect")
            return est
        self.deforming_frames += 1
        est.state = EstimateState.OK
        weak = [(nm, s, r, s > u) for nm, s, r, u, fr in zip(self.names, std, self.hi - self.lo, uniform, self.frozen)
                if not fr and s > 0.05 * r]
        if weak:
            est.state = EstimateState.LOW_CONFIDENCE
            est.reason = "; ".join(f"{nm} barely observable (std {s:.3g}, {100 * s / r:.0f} % of its range"
                                   + ("; its last value kept)" if kept else ")")
                                   for nm, s, r, kept in weak)
        self._update_constants(est)
        est.frozen = self.frozen.copy()
        return est

    def _update_dense(self, est: Estimate, T_wc: np.ndarray, ids: np.ndarray | None, P_map: np.ndarray | None,
                      uv: np.ndarray | None, image_bgr: np.ndarray | None, depth: np.ndarray | None) -> Estimate:
        """Measurements 'dense' (:mod:`.dense`): the object's own texture against the reference view. Map points
        observed on the object are still linked: the localization must leave them out of the camera pose and
        look for them where the estimate moves them (the SLAM feedback), as with sparse measurements."""
        import time

        import cv2

        assert self.dense is not None
        if ids is not None and len(ids) and P_map is not None and uv is not None:
            self._link_observed(T_wc, ids, P_map, uv)
        if image_bgr is None:
            est.state, est.reason = EstimateState.LOST, "measurements 'dense' need the image"
            return est
        gray = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY) if image_bgr.ndim == 3 else image_bgr
        T_cw = G.inv(T_wc)
        if not self.dense.has_template:
            mu_ref, state, _ = self.reference_from_depth(T_wc, depth)
            if self.dense.set_reference(gray, T_cw, depth, mu_ref):
                n_s = len(self.dense.static[0].X) if self.dense.static else 0
                if mu_ref is not None:
                    self.values[:len(mu_ref)] = mu_ref  # the next frame starts there
                elif self.reference_state is not None:  # the registration saw a load this frame does not show
                    self.values[:] = self._initial
                est.values = self.values.copy()
                est.reason = (f"reference view taken for dense measurement (the object {state} in it; "
                              f"{len(self.dense.levels[0].x)} surface samples, {n_s} of its static surroundings)")
                est.debug["reference_state"] = state
            else:
                est.state, est.reason = EstimateState.LOST, "the object is not in view: no reference view yet"
            return est
        lo, hi = self._free_bounds()
        t0 = time.perf_counter()
        res: DenseResult = self.dense.solve(gray, T_cw, self.values, lo, hi)
        est.solve_ms = (time.perf_counter() - t0) * 1e3
        est.values, est.cov = res.mu.copy(), res.cov_mu
        est.measurements, est.inliers, est.iterations = res.used, res.inliers, res.iterations
        est.debug.update(res.debug, photometric_rms=res.rms, rest_photometric_rms=res.rest_rms,
                         motion_px=res.motion_px)
        if res.reason:
            est.state, est.reason = EstimateState.LOST, res.reason
            return est
        fit = res.debug.get("rms_at_rest_level", res.rms)
        deforming = res.rest_rms - fit > self.cfg.dense_min_gain * res.rest_rms and \
            res.motion_px > self.cfg.min_deformation_px
        if not deforming and self.deforming_frames == 0:
            # at rest before any load was seen: the placement error as the images see it (later frames judged
            # undeformed may carry a small load the rigid fit would absorb), and another view of the template
            self.dense.hold_rest()
            est.debug["template_samples"] = float(self.dense.refine_template(gray, T_cw, res.motion_px))
        est = self._conclude(est, res.mu, bool(deforming),
                             f"photometric residual {fit:.2f} vs {res.rest_rms:.2f} undeformed, "
                             f"motion {res.motion_px:.2f} px")
        gap = float(res.debug.get("camera_gap_sigma", float("nan")))
        if est.state in (EstimateState.OK, EstimateState.LOW_CONFIDENCE) and gap > self.cfg.dense.max_camera_gap:
            why = (f"the static surroundings alone put the camera {gap:.1f} sigma from the joint fit's (at most "
                   f"{self.cfg.dense.max_camera_gap:g}): the fit traded the camera's error against the object's "
                   "deformation (a view along the floor?)")
            _doubt(est, why)
        why = ambiguity(res.debug, self.cfg.dense, [a.name for a in self.model.axes])
        if est.state in (EstimateState.OK, EstimateState.LOW_CONFIDENCE) and why:
            _doubt(est, why)
        gain = float(res.debug.get("gain", float("nan")))
        if est.state in (EstimateState.OK, EstimateState.LOW_CONFIDENCE) and not gain >= self.cfg.dense.min_gain:
            why = (f"the image shows the object's texture at {gain:.2f} of the reference view's contrast (at least "
                   f"{self.cfg.dense.min_gain:g}): the fit is misaligned, or the view no longer shows what the "
                   "reference saw")
            _doubt(est, why)
        if est.state == EstimateState.OK:  # a sound fit's shading joins the next frames' prior (shading_frames)
            self.dense.accept_shading()
        # after the shading is fused: this flag changes the frame's state only, not its estimate or the next frames'
        free = np.array([m == "tracked" for m in self.mode]) & ~self.frozen
        why = loosely_held(est, free, self.hi - self.lo, self.cfg.dense.max_std_frac)
        if est.state == EstimateState.OK and why:
            _doubt(est, why)
        return est

    def reference_from_depth(self, T_wc: np.ndarray, depth: np.ndarray | None
                             ) -> tuple[np.ndarray | None, str, bool]:
        """The object's state (mu) in the reference view, how it was judged, and whether the depth saw the object:
        fitted to this frame's depth (:func:`.depth_state.fit_state`, the rigid part a nuisance: the pose is not
        changed) where ``cfg.reference`` is "depth" and there is a depth image, unless a registration's fit
        (:attr:`reference_state`) agrees with that depth as well (:meth:`_registration_agrees`: then the
        registration's, fitted on more views); failing a depth fit, :attr:`reference_state`; None: at rest.

        With ``depth_turn`` on a body of revolution about its z axis (:attr:`_turn_is_alpha`, the boot), the fit also
        searches the turn about that axis (``turn_steps``), and where it finds the object deformed, its shape holding
        the turn, that turn starts alpha_z and the depth follower (:meth:`_start_turn`; this method's one side effect),
        as a registration's turn does (``objects.py``): the boot registered at rest and placed once its lever was bent
        (a live graph's late registration) kept alpha_z at its start until its map points were linked and searched (6
        frames of the 8 s boot clip, 20 degrees off; stop 105)."""
        if self.cfg.reference != "depth":
            return None, "taken to be at rest", False
        if depth is not None:
            lo, hi = self._free_bounds()
            n_mu = len(self.model.axes)
            cloud = depth_cloud(self.cam, np.asarray(depth), T_wc, stride=2)
            # the model as the tracker draws it: turned by alpha_z (a registration's turn, objects.py), as every
            # later depth fit has it (_fit_depth)
            T = self.T_map_obj
            if self.rigid_z and self.values[self.layout.alpha_index] != 0.0:
                T = T @ G.make_T(self.layout.state(self.values).rotation())
            turns = self._turn_is_alpha
            dcfg = replace(self.cfg.depth_state, turn_steps=TURN_STEPS) if turns else self.cfg.depth_state
            st = fit_state(cloud, self.model, T, lo[:n_mu], hi[:n_mu], self.values[:n_mu], dcfg,
                           self.cfg.n_modes or None)
            agrees = "" if turns else self._registration_agrees(st, cloud, T, lo[:n_mu], hi[:n_mu], dcfg)
            if agrees:
                assert self.reference_state is not None
                return self.reference_state.copy(), "deformed as the registration's depth fit showed, " + ", ".join(
                    f"{nm} {v:.4g}" for nm, v in zip(self.names, self.reference_state)) + f" ({agrees})", True
            if st.mu is not None:
                turned = ""
                if turns and st.turn_held < TURN_HELD and self._start_turn(st.rigid):
                    turned = f", alpha_z from its turn {np.degrees(self.values[self.layout.alpha_index]):.1f} deg"
                return st.mu, "deformed as its depth shows, " + ", ".join(
                    f"{nm} {v:.4g}" for nm, v in zip(self.names, st.mu)) + turned + f" ({st.reason})", True
            if np.isfinite(st.cost):
                return None, f"at rest as its depth shows ({st.reason})", True
        if self.reference_state is not None:
            return self.reference_state.copy(), "deformed as the registration's depth fit showed", False
        return None, "taken to be at rest (no depth fit)", False

    def _registration_agrees(self, st: DepthState, cloud: np.ndarray, T: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                             cfg: DepthStateConfig) -> str:
        """Whether this frame's depth agrees with the state a registration found (:attr:`reference_state`, fitted to
        the registration's depth views fused), ``st`` being this frame's own fit (:meth:`reference_from_depth`), ``lo``
        / ``hi`` the state's box: "" where there is no such state, or this frame sees another; else what agreed.

        The frame agrees where the registration's state lowers the rest shape's cost on this frame's depth by at most
        ``cfg.min_gain`` less than the frame's own verdict does (its deformed fit, or the rest shape: no gain), both
        held on the same points at the same scale (:func:`.depth_state.held_gains`, their rigid parts a nuisance):
        ``min_gain`` is the yardstick a deformation must pass for the depth to see it at all. Where the frame's verdict
        is the rest shape, the registration's state must lower its cost at all (a gain above zero; the code asks it
        always, and where the frame's own fit is deformed the first condition asks more already): a state that fits
        this frame's depth worse than the rest shape is not one the frame cannot tell apart, the frame speaks against
        it (held-out stereo seed 1001: the fused views' fit read a load on the unloaded beam, -0.4 % on the reference
        frame, and every later estimate carried it, 8.8 % of the range off). A state one depth image cannot tell from
        another is then taken from the fit on more views: on development seeds 0-19 of the loaded family, the
        registration's fit (its last view is the reference frame) read the load 0.36 % of its range off (median) where
        the reference frame's own fit read it 0.63 % off or saw none (seed 4: its 0.5 mm deformation under
        ``min_motion`` in one view, 1.25 % off from three). Where the load moved or went after the registration's views
        (a live graph registers in the background), the frame's own verdict lowers the cost by more and
        stands."""
        if self.reference_state is None or st.fitted is None:
            return ""
        reg = np.asarray(self.reference_state, np.float64)
        states = [reg] if st.mu is None else [reg, st.mu]
        gains = held_gains(cloud, self.model, T, lo, hi, states, cfg, self.cfg.n_modes or None)
        gain, own = float(gains[0]), (float(gains[1]) if st.mu is not None else 0.0)
        if not own - gain <= cfg.min_gain or not gain > 0.0:
            return ""
        verdict = "its own fit" if st.mu is not None else "the rest shape (its verdict)"
        return (f"this frame's depth agrees: the registration's state lowers the rest shape's cost by {gain:+.1%}, "
                f"{verdict} by {own:+.1%}")

    def _turn_axis_is_alpha(self) -> bool:
        """Whether a depth fit's turn about the object's z axis is alpha_z's: ``depth_turn`` on (the scene says the
        object is a body of revolution about that axis), the fit's turn about the vertical through the model's
        centroid is a turn about the object's z axis (:attr:`.depth_state.DepthFollower.turns_about_axis`), and so is
        alpha_z's as the model declares it (its origin within 1 mm of that vertical, as ``objects.py`` asks)."""
        if not (self.cfg.depth_turn and self.rigid_z and self.depth is not None and self.depth.turns_about_axis):
            return False
        rigid = next(r for r in self.model.rigid_parameters if r["name"] == ALPHA_Z)
        origin = np.asarray(rigid.get("origin", (0.0, 0.0, 0.0)), np.float64)
        return rigid.get("axis", "z") == "z" and bool(np.hypot(*(self.depth.surf.c[:2] - origin[:2])) < 1e-3)

    def _start_turn(self, rigid: np.ndarray) -> bool:
        """The reference fit's rigid correction ``rigid`` (x, y, z, turn psi; :attr:`.depth_state.DepthState.rigid`):
        its turn starts alpha_z where the tracker estimates it (a fixed alpha_z stays), and the depth follower starts
        from what alpha_z does not carry of it (its translation, in the frame turned by alpha_z), where it has not
        fitted yet. Whether alpha_z was moved."""
        assert self.depth is not None
        i = self.layout.alpha_index
        seed = np.asarray(rigid, np.float64).copy()
        moved = self.mode[i] != "fixed" and not self.frozen[i]
        if moved:
            # the fit places x at R(psi) (x - c) + c + delta in the frame turned by alpha_z; in the frame turned by
            # alpha_z + psi the same place is x + R(-psi) (c + delta) - c (c: the model's centroid)
            psi = float(seed[3])
            c = self.depth.surf.c
            self.values[i] = _wrap(self.values[i] + psi, self.lo[i], self.hi[i])
            seed = np.r_[G.rot_axis("z", -psi) @ (c + seed[:3]) - c, 0.0]
        if moved or self.depth.mu is None:  # a follower that fitted already carries a correction of the old frame
            self.depth.rigid = seed
        return moved

    @property
    def needs_depth(self) -> bool:
        """Sparse measurements with ``reference: depth``: the object's state is read from the first depth image
        that shows it (points first seen on a loaded object are then linked where they are); with ``depth_fit``
        from every one."""
        return not self._reference_read or self.depth is not None

    def _read_reference(self, est: Estimate, T_wc: np.ndarray, depth: np.ndarray | None) -> None:
        """Sparse measurements: the state the depth shows the object in, once (see :attr:`needs_depth`); a
        deformation found there is the start of the estimate and counts as seen (new map points are linked on
        the deformed surface)."""
        if self._reference_read or depth is None:
            return
        mu, state, seen = self.reference_from_depth(T_wc, depth)
        self._reference_tries += 1
        if not seen and mu is None and self._reference_tries < 15:
            return  # the object not in this depth image: the next one (15 at most: each costs a fit)
        self._reference_read = True
        est.debug["reference_state"] = state
        if mu is not None:
            self.values[:len(mu)] = mu
            self._was_deforming = True
        elif self.reference_state is not None:  # the registration saw a load this depth image does not show
            self.values[:] = self._initial
        est.values = self.values.copy()

    def _fits_badly(self, res: lm.Result, n: int) -> bool:
        """The warm-started fit may sit in the wrong basin: its residual jumped above the running level of good
        fits (x 1.3, at least 0.75 x Huber), under 85 % of the measurements agree, or, every 30th frame, to
        catch a slow slide into a neighbouring basin."""
        if res.inliers < 0.85 * n or not np.isfinite(res.rms_px) or self._frames % 30 == 0:
            return True
        ref = self._rms_ref if self._rms_ref is not None else 0.0
        return res.rms_px > max(1.3 * ref, 0.75 * self.cfg.huber_px)

    def _unfrozen_constants(self) -> np.ndarray:
        return np.flatnonzero(np.array([m == "constant" for m in self.mode], dtype=bool) & ~self.frozen)

    def _constant_search(self, res: lm.Result, meas: Measurements, lo: np.ndarray, hi: np.ndarray, est: Estimate,
                         T_cw: np.ndarray, ids: np.ndarray, P_map: np.ndarray,
                         uv: np.ndarray) -> tuple[lm.Result, Measurements]:
        """Before a constant (alpha_z) is known (``constant_search`` > 0): the frame is also fitted with the constant
        held at each of ``constant_search`` values over its range, the map points relinked at each (a point's
        material point depends on how the boot is turned), the tracked parameters free. The frame's own fit starts
        from the current constant, and while the object looked undeformed the constant is held: a wrong alpha_z then
        reads a bent boot as unbent, and an unbent boot never moves alpha_z. The best sample (least Huber cost per
        measurement, at least 80 % of the frame's measurements linked) is polished with the constant free and kept
        if its RMS beats the frame's fit by ``min_deformation_px``; otherwise the links and values are restored.
        One unfrozen constant only (alpha_z). Returns the fit and its measurements."""
        const = self._unfrozen_constants()
        if len(const) != 1 or not np.isfinite(res.rms_px):
            return res, meas
        c = int(const[0])
        tracked = np.flatnonzero(np.array([m == "tracked" for m in self.mode]) & ~self.frozen)
        saved_values, saved_links, saved_static = self.values.copy(), dict(self.links), set(self.static)
        n0 = len(meas[0])
        lo_s, hi_s = lo.copy(), hi.copy()
        lo_s[tracked], hi_s[tracked] = self.lo[tracked], self.hi[tracked]

        values = [float(g) for g in np.linspace(self.lo[c], self.hi[c], self.cfg.constant_search, endpoint=False)]
        relinked = dict(zip(values, self._relinked_at(c, values), strict=True))

        def fit_at(g: float, free: bool) -> tuple[lm.Result, Measurements] | None:
            self.values = saved_values.copy()
            self.values[c] = g
            links, static = relinked[g]  # relinked at this turn; a point off the surface at it is static for this
            self.links, self.static = dict(links), set(static)  # sample only
            m = self._map_point_measurements(ids, P_map, uv)
            if m is None or len(m[0]) < max(self.cfg.min_measurements, 0.8 * n0):
                return None
            p = lm.Problem(m[0], m[1], self._disp_fn(m[2], m[3]), T_cw, self.R_wo, self.K, self.layout, _sigma(m))
            x = res.x.copy()
            x[c] = g
            lo_g, hi_g = lo_s.copy(), hi_s.copy()
            if free:
                lo_g[c], hi_g[c] = self.lo[c], self.hi[c]
            else:
                lo_g[c] = hi_g[c] = g
            return lm.solve(p, x, lo_g, hi_g, self.cfg.huber_px, self.cfg.max_iterations,
                            refits=self.cfg.outlier_refits), m

        best_g, best_score = None, res.cost / max(n0, 1)
        for g in values:
            out = fit_at(g, False)
            if out is not None and np.isfinite(out[0].cost) and out[0].cost / len(out[1][0]) < best_score:
                best_g, best_score = float(g), out[0].cost / len(out[1][0])
        found = fit_at(best_g, True) if best_g is not None else None
        est.debug["constant_search_rms_px"] = float(found[0].rms_px) if found is not None else float("nan")
        if found is None or not (found[0].rms_px < res.rms_px - self.cfg.min_deformation_px):
            self.values, self.links, self.static = saved_values, saved_links, saved_static  # as the frame left them
            return res, meas
        r, m = found
        span = self.hi[c] - self.lo[c]  # searched as a turn (the samples leave out the range's end): the gap wraps
        gap = abs(best_g - saved_values[c]) % span
        if self._const_samples and min(gap, span - gap) > span / self.cfg.constant_search:
            self._const_samples.clear()  # they were taken in the basin the search left
            est.debug["constant_samples_cleared"] = 1.0
        # the links stay those made at the sample (a relink at the polished value happens as alpha_z is sampled)
        self.values = saved_values.copy()
        self.values[c] = best_g
        est.debug["constant_searched"] = float(r.x[c])
        return r, m

    def _global_restart(self, p: lm.Problem, res: lm.Result, lo: np.ndarray, hi: np.ndarray) -> lm.Result:
        """The warm start fitted badly: the load may have jumped into another basin of the cost (a load moved
        across mid-span passes a larger deflection). Evaluate the Huber cost on a coarse grid of the free
        parameters (about ``global_samples`` points; the others at the current estimate) and run LM again
        from the best sample if it beats the warm start's result; keep the lower cost."""
        free = np.flatnonzero(hi > lo)
        free = free[free < len(self.values)]  # not the object shift: it stays at the warm start's value
        if self._const_samples:  # constants already seen well (Fig. 4.19) are not searched again: a frame that lost
            # most of its measurements would otherwise pick another basin for them (alpha_z turned by 45 deg)
            free = free[np.array([self.mode[i] != "constant" for i in free], dtype=bool)]
        if len(free) == 0:
            return res
        per_axis = max(2, round(self.cfg.global_samples ** (1.0 / len(free))))
        axes = [np.linspace(lo[i], hi[i], per_axis) for i in free]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(free))
        k = self.cfg.huber_px
        best, best_cost = None, res.cost
        for g in grid:
            x = res.x.copy()
            x[free] = g
            uv, z, _ = lm.predict(p, x, with_jacobian=False)
            rn = np.linalg.norm(p.uv - uv, axis=1)
            rn = rn[np.isfinite(rn) & (z > 0)]
            c = float(np.sum(np.where(rn <= k, rn * rn, 2 * k * rn - k * k)))
            if c < best_cost:
                best, best_cost = x, c
        if best is None:
            return res
        res2 = lm.solve(p, best, lo, hi, k, self.cfg.max_iterations, refits=self.cfg.outlier_refits)
        return res2 if res2.cost < res.cost else res

    def _align_at_rest(self, max_deg: float = 5.0, max_m: float = 0.03, bent_ratio: float = 0.5,
                       bent_px: float = 0.2) -> None:
        """The object's pose from the frames collected at rest (``cfg.rest_frames``): the small rigid motion of the
        undeformed object, about its dots' centroid, that best reprojects them (Huber), with a weak prior (2 degrees,
        5 mm) for the directions the dots cannot see (the roll about a row of dots). Applied once, then held.

        Refused (the pose kept, the reason in :attr:`rest_correction`) when fewer than 3 frames saw the dots, when
        it does not lower the residual or leaves it above 1.5 x Huber, when it is larger than a hand-measured pose
        is off, and when the object was not at rest: a bent cantilever fits a rigid turn to a fraction of a pixel,
        so the same frames are fitted with the model's deformation free too, and a residual under ``bent_ratio`` of
        the rigid one (the rigid one above ``bent_px``, what dot centroids reach at rest) says they were loaded."""
        from scipy.optimize import least_squares

        obs, self._rest_obs = self._rest_obs or [], None
        if len(obs) < 3:
            self.rest_correction = {"frames": len(obs), "applied": False,
                                    "reason": f"the dots were seen in {len(obs)} of the first {self._rest_seen} frames"}
            return
        Xo = np.concatenate([o[0] for o in obs])
        uv = np.concatenate([o[1] for o in obs])
        T_co = [o[2] @ self.T_map_obj for o in obs]
        c = Xo.mean(axis=0)
        sizes = [len(o[0]) for o in obs]
        prior = np.r_[np.full(3, 1 / np.deg2rad(2.0)), np.full(3, 1 / 0.005)]

        def moved(p: np.ndarray) -> np.ndarray:
            return G.make_T(G.exp_so3(p[:3]), c + p[3:]) @ G.make_T(t=-c)

        def residuals(p: np.ndarray) -> np.ndarray:
            D = moved(p)
            r, k = [], 0
            for T, n in zip(T_co, sizes):
                pred, _z = _project(T @ D, Xo[k:k + n], self.K)
                r.append((pred - uv[k:k + n]).ravel())
                k += n
            out: np.ndarray = np.r_[np.concatenate(r), prior * p]
            return out

        r0 = residuals(np.zeros(6))[:-6].reshape(-1, 2)
        sol = least_squares(residuals, np.zeros(6), loss="huber", f_scale=self.cfg.huber_px, x_scale=1 / prior)
        r1 = sol.fun[:-6].reshape(-1, 2)
        def rms(r: np.ndarray) -> float:
            return float(np.sqrt(np.mean(np.minimum(np.linalg.norm(r, axis=1), 3 * self.cfg.huber_px) ** 2)))

        deg, m = float(np.rad2deg(np.linalg.norm(sol.x[:3]))), float(np.linalg.norm(sol.x[3:]))
        info: dict[str, Any] = {"frames": len(obs), "rms_before_px": rms(r0), "rms_after_px": rms(r1), "deg": deg,
                                "mm": 1e3 * m}
        T_new = self.T_map_obj @ moved(sol.x)
        # the same frames with the model's deformation free as well: a loaded object fits it far better
        n_mu = len(self.model.axes)
        lo, hi = self._free_bounds()

        def residuals_bent(x: np.ndarray) -> np.ndarray:
            D, mu = moved(x[:6]), x[6:]
            r = []
            for (Xo_f, uv_f, _T, nodes_f, w_f), T in zip(obs, T_co):
                dX, _J = self._disp_fn(nodes_f, w_f)(mu)
                r.append((_project(T @ D, Xo_f + dX, self.K)[0] - uv_f).ravel())
            out: np.ndarray = np.r_[np.concatenate(r), prior * x[:6]]
            return out

        best = None
        for start in (lo[:n_mu], 0.5 * (lo[:n_mu] + hi[:n_mu]), hi[:n_mu]):
            b = least_squares(residuals_bent, np.r_[sol.x, start], loss="huber", f_scale=self.cfg.huber_px,
                              x_scale=np.r_[1 / prior, np.maximum(hi[:n_mu] - lo[:n_mu], 1e-9)],
                              bounds=(np.r_[np.full(6, -np.inf), lo[:n_mu] - 1e-12],
                                      np.r_[np.full(6, np.inf), hi[:n_mu] + 1e-12]))
            best = b if best is None or b.cost < best.cost else best
        assert best is not None
        rms_bent = rms(best.fun[:-6].reshape(-1, 2))
        rigid_last = info["rms_after_px"]
        info["rms_deformed_px"] = rms_bent
        why = ("the solve failed" if not sol.success else
               "it does not lower the residual" if info["rms_after_px"] > info["rms_before_px"] else
               f"the residual stays above {1.5 * self.cfg.huber_px:.2f} px"
               if info["rms_after_px"] > 1.5 * self.cfg.huber_px else
               f"it is larger than {max_deg:g} deg / {1e3 * max_m:g} mm" if deg > max_deg or m > max_m else
               f"the object was not at rest (with its deformation the frames fit to {rms_bent:.2f} px, as a rigid "
               f"body to {rigid_last:.2f} px)" if rigid_last > bent_px and rms_bent < bent_ratio * rigid_last
               else "")
        if not why:
            self.T_map_obj = T_new
            # what was fitted under the old pose starts afresh
            self.shift[:] = 0.0
            self._rms_ref, self._const_samples, self._was_deforming, self.deforming_frames = None, [], False, 0
        self.rest_correction = {**info, "applied": not why, "reason": why}

    def _rest_rms(self, X: np.ndarray, uvm: np.ndarray, T_cw: np.ndarray) -> float:
        """Residual of the undeformed object (moved by the best object shift when that is estimated)."""
        sh = self.cfg.object_shift_m
        if sh > 0:
            still = lambda mu: (np.zeros_like(X), np.zeros((len(X), 3, 0)))  # noqa: E731
            p0 = lm.Problem(X, uvm, still, T_cw, self.R_wo, self.K, StateLayout((), shift=True))
            r0 = lm.solve(p0, self.shift, np.full(3, -sh), np.full(3, sh), self.cfg.huber_px, 10)
            X = X + r0.x
        pred, _z = _project(T_cw, X, self.K)
        r = np.linalg.norm(uvm - pred, axis=1)
        r = r[np.isfinite(r)]
        return float(np.sqrt(np.mean(np.minimum(r, 3 * self.cfg.huber_px) ** 2))) if len(r) else float("nan")

    def _update_constants(self, est: Estimate) -> None:
        """Fig. 4.19: the constants (alpha_z, a stiffness) are estimated with the tracked parameters in the
        first frames that show them well (their standard deviation below ``constant_std_frac`` of their
        range: a barely bent boot says little about how it is turned) and frozen at the median of
        ``constant_frames`` such frames."""
        const = np.array([m == "constant" for m in self.mode]) & ~self.frozen
        if not const.any() or est.state == EstimateState.LOST or not est.deforming:
            return
        std = np.sqrt(np.clip(np.diag(est.cov), 0, None))
        if not np.all(std[const] < self.cfg.constant_std_frac * (self.hi - self.lo)[const]):
            if self._const_samples:
                # seen well before, not by this frame: held at the median of the frames that saw it, not moved by
                # weaker evidence. A graph that takes fewer frames a second gathers fewer informative frames than
                # constant_frames counts; left free between them and after them, alpha_z wandered (stop 87: the boot
                # sample's every 3rd frame, tests/assimilation/test_tracker.py, ended 138 degrees off; 0.5 held)
                held = np.median(np.array(self._const_samples), axis=0)
                self.values[const] = held[const]
                est.values = np.where(const, held, est.values)
            return
        self._const_samples.append(self.values.copy())
        if self.rigid_z and const[self.layout.alpha_index]:
            # the links were made with an earlier alpha: re-link the map points once it moved noticeably
            alpha = self.model_state.alpha_z
            if self._alpha_linked is None or abs(alpha - self._alpha_linked) > np.deg2rad(0.25):
                self.relink()
                self._alpha_linked = self.model_state.alpha_z
        if len(self._const_samples) >= self.cfg.constant_frames:
            vals = np.median(np.array(self._const_samples), axis=0)
            self.values[const] = vals[const]
            self.frozen |= const
            if self.rigid_z and const[self.layout.alpha_index]:
                self.relink()

    def _solve_planar(self, X: np.ndarray, uvm: np.ndarray, disp: lm.Displacement, T_cw: np.ndarray,
                      lo: np.ndarray, hi: np.ndarray) -> tuple[lm.Result, float]:
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
        n_mu = self.layout.n_mu

        def model(x: lm.Vector) -> tuple[lm.Vector, lm.Vector, NDArray[np.bool_]]:
            dX, ddX = disp(x[:n_mu])
            pred = np.c_[Xo[:, 0] + dX[:, 0], Xo[:, 2] + dX[:, 2]]
            J = ddX[:, [0, 2], :]
            if self.rigid_z:
                J = np.concatenate([J, np.zeros((len(J), 2, 1))], axis=2)
            return pred, J, np.ones(len(pred), bool)

        res = lm.solve_generic(model, obs, self.values, lo, hi, np.full(len(obs), px), self.cfg.huber_px,
                               self.cfg.max_iterations)
        rest = np.linalg.norm(obs - np.c_[Xo[:, 0], Xo[:, 2]], axis=1) / px
        return res, float(np.sqrt(np.mean(np.minimum(rest, 3 * self.cfg.huber_px) ** 2)))


def ambiguity(debug: dict[str, float], s: DenseSettings, names: list[str]) -> str:
    """Why a dense fit is a coin toss between two loads, or "": its other basin's fit (``basin_check``) ended more
    than ``s.ambiguity_apart`` of a range away and cost less than ``s.max_ambiguity_gap`` more at full resolution
    (:meth:`DenseAligner.solve`'s debug values ``basin_gap``, ``basin_apart``, ``basin_other_i``)."""
    gap, apart = float(debug.get("basin_gap", float("nan"))), float(debug.get("basin_apart", 0.0))
    if not (gap < s.max_ambiguity_gap and apart > s.ambiguity_apart):
        return ""
    alt = ", ".join(f"{n}={debug[f'basin_other_{i}']:.3g}" for i, n in enumerate(names) if f"basin_other_{i}" in debug)
    return (f"another load ({alt}) explains the image as well: its fit costs {100 * gap:.2f} % more at full "
            f"resolution (at least {100 * s.max_ambiguity_gap:g} % tells them apart)")


def loosely_held(est: Estimate, free: np.ndarray, ranges: np.ndarray, max_frac: float) -> str:
    """Why a fit's estimate is held too loosely to vouch for, or "": a parameter of ``free`` (tracked, not frozen)
    whose standard deviation (``est.cov``: the fit's normal equations scaled by its residual) exceeds ``max_frac`` of
    its range. What the model does not explain (shading, texture, the camera's error) moves such a parameter as
    readily as noise does. A shelf (a plate clamped along one edge) bends nearly alike wherever across its width the
    load sits: 1 % of s_y's range moves its image by about 0.01 px, and its fits hold s_y to 2-3 % of the range
    (docs/family.md, stop 76)."""
    n = len(free)
    if not max_frac > 0 or np.ndim(est.cov) != 2 or len(est.cov) < n:
        return ""
    std = np.sqrt(np.clip(np.diag(est.cov)[:n], 0, None))
    loose = [(nm, 100 * sd / r) for nm, sd, r, f in zip(est.names, std, ranges, free) if f and sd > max_frac * r > 0]
    return "; ".join(f"{nm} loosely held by the images (std {pct:.1f} % of its range, at most {100 * max_frac:g} %)"
                     for nm, pct in loose)


def _doubt(est: Estimate, why: str) -> None:
    """Report a measured estimate (OK or already doubted) low-confidence, adding why to its reasons."""
    est.reason = why if est.state == EstimateState.OK else f"{est.reason}; {why}"
    est.state = EstimateState.LOW_CONFIDENCE


def tracker_config(obj: dict[str, Any], **overrides: Any) -> TrackerConfig:
    """The tracker settings of a validated scene object (its ``tracking`` block), with overrides."""
    t = obj["tracking"]
    cfg = TrackerConfig(measurements=t["measurements"], huber_px=t["huber_px"], n_modes=t["modes"],
                        max_iterations=t["max_iterations"], outlier_refits=t["outlier_refits"],
                        constant_frames=t["constant_frames"],
                        constant_std_frac=t["constant_std_frac"], constant_search=t["constant_search"],
                        constant_search_until=t["constant_search_until"],
                        min_measurements=t["min_measurements"], max_points=t["points"], anchor=t["anchor"],
                        object_shift_m=t["object_shift_m"], rest_frames=t["rest_frames"],
                        reference=t["reference"], depth_fit=t["depth_fit"], depth_turn=t["depth_turn"],
                        depth_alone=t["depth_alone"],
                        depth_stride=t["depth_stride"],
                        dense=DenseSettings(step_px=t["dense_step_px"], rigid=t["dense_rigid"],
                                          static_ring_px=t["dense_surroundings_px"], refine=t["dense_refine"],
                                          camera_first=t["dense_camera_first"],
                                          camera_check=t["dense_camera_check"], shading=t["dense_shading"],
                                          shading_frames=t["dense_shading_frames"],
                                          template_frames=t["dense_template_frames"],
                                          grid_brightness=t["dense_grid_brightness"],
                                          basin_check=t["dense_basin_check"], basin_warm=t["dense_basin_warm"],
                                          placement_measured=obj["anchor"]["kind"] == "registration"),
                        dots=np.asarray(t["dots"]) if t["dots"] else None, dot_color=tuple(t["dot_color"]))
    return replace(cfg, **overrides)


FLAG_DROP, FLAG_HELD = int(PointFlag.DROP), int(PointFlag.HELD)


def deformable_feedback(trackers: Iterable[DeformableTracker]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the trackers tell the localization after a frame: (ids (N,) uint32, predicted map-frame positions
    (N, 3), flags (N,) uint8: :data:`FLAG_DROP` | :data:`FLAG_HELD`).

    A point linked while the object was deformed took its material point from the estimate of that moment, and
    holds whatever error it had: the map may cull it like any young point and make a fresh one at a later
    keyframe. A point linked at rest names its material point exactly; it is held. (Without ``snap_to_surface``
    every link is made in the rest shape, so every point is held.)"""
    ids, P, flags = [], [], []
    for tr in trackers:
        i, p = tr.predicted_points()
        ids.append(i)
        P.append(p)
        held = np.array([tr.links[int(k)].mu is None for k in i], bool)
        flags.append(np.where(np.isin(i, tr.outlier_ids), FLAG_DROP, 0) | np.where(held, FLAG_HELD, 0))
    if not ids:
        return np.zeros(0, np.uint32), np.zeros((0, 3)), np.zeros(0, np.uint8)
    return (np.concatenate(ids).astype(np.uint32), np.concatenate(P).reshape(-1, 3),
            np.concatenate(flags).astype(np.uint8))


def _signed_angle(a: Any) -> Any:
    """Angles (rad, scalar or array) brought into [-pi, pi) by whole turns."""
    return (a + np.pi) % (2 * np.pi) - np.pi


def _wrap(a: float, lo: float, hi: float) -> float:
    """An angle brought into [lo, hi) by whole turns where that range spans one (alpha_z), else clipped."""
    if hi - lo >= 2 * np.pi - 1e-9:
        return float(lo + (a - lo) % (2 * np.pi))
    return float(np.clip(a, lo, hi))


def _finite_observations(ids: np.ndarray, P_map: np.ndarray, uv: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The observations (ids, map positions (N, 3), raw pixels (N, 2)) whose position and pixel are finite."""
    P = np.asarray(P_map, dtype=np.float64).reshape(-1, 3)
    q = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    good = np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(q), axis=1)
    return np.asarray(ids)[good], P[good], q[good]


def _project(T_cw: np.ndarray, X: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ideal pixels (N, 2) and depths (N,) of map-frame points X (N, 3) seen from camera pose T_cw."""
    Xc = X @ T_cw[:3, :3].T + T_cw[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.c_[K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 1] * Xc[:, 1] / Xc[:, 2] + K[0, 2],
                   K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]]
    return uv, Xc[:, 2]
