"""Collision between real points (depth) or another virtual object and a virtual deformable object,
thesis Algorithm 5.1, and the mapping from contact state to model parameters.

Per frame:

    points  <- decimate(depth points, N_step)                       (the caller)
    d_min, node <- min over contact nodes of the distance to the nearest point   (KD-tree)
    if d_min < delta and tau < tau_max:  tau += step  (the node is fixed while tau > 0: one contact at a
                                                       time, superposition does not hold for non-linear laws)
    elif tau > tau_min:                  tau -= step  (reported CONTACT while one step back brings the surface
                                                       within delta again: held, the pseudo-time oscillating by one
                                                       step where the surface follows the point; else RELEASING)

Another virtual object that presses this one (§5.4.1, virtual-virtual contact) is an exact surface, not a noisy
sensor's points: its "distance" is the gap between the two surfaces along the direction each contact node would
be pushed (its load direction), negative where they overlap, and the contact starts at a gap of zero, not within
delta (delta is the sensor's margin: a depth camera sees a real probe's near side a few millimetres off its
surface). So the pushed object touches where the pusher's drawn surface reaches it and follows it there, instead of
starting delta early and staying delta ahead of it.

Several contacts at once (``max_contacts`` > 1; thesis §7.3's future work): where the model is linear (a load
scale on a linear-elastic model), the deformation of several loads is the sum of each one's, so each contact gets its
own slot of Alg. 5.1 (load point or position, pseudo-time) and the surface sits at the *summed* deformation. The
distance is then measured from samples of the drawn surface between the load points too (a probe between two load
points presses the surface there). A slot steps on the clearance of the samples within ``separation`` of its load;
touches farther than that from every slot start a new one. Because every slot sees the others' deformation, two
probes that press the same body share the load as they do in the body (each takes less where the other presses):
summing independent single-contact pseudo-times would not (`benchmarks/results/contact_anywhere.md`, "Two contacts at
once": two such trackers summed are 78-96 % off the two-sphere truth, these slots 0.7-7.9 %). Not offered for the
non-linear models (a pseudo-time axis: the probe models' NI-PGD over a discrete load point x pseudo-time, the SVK
beams' over the load's position x pseudo-time): their contacts do not superpose, they need the combined load
precomputed (thesis §5.3).

The contact nodes are the model's precomputed load points on its *surface*, at their *deformed* positions, so a
virtual surface pushed by a finger moves away from it and the pseudo-time settles where the surface follows the
finger. "On its surface": a load point that is a node of the drawn surface is its own contact node; a scanned body's
load points are nodes of its volume mesh, which lies up to a cell inside or outside the scan that is drawn (and that
a real object touches), so its contact node is the surface node nearest to it (the thesis measures the distance to
the virtual object's nodes; the probe scenes' full-order truth showed the volume nodes up to 5.5 mm off the scan).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import cast

import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.state import LOAD_POSITION_AXES, PSEUDO_TIME, LoadPointStates, ModelState
from simreal_nodes.states import ContactPhase


@dataclass(frozen=True)
class PusherSurface:
    """Another virtual object's deformed surface that can press this one (virtual-virtual contact, §5.4.1):
    ``vertices`` (n, 3) in the world frame and its closed surface's ``triangles`` (m, 3), outward-oriented;
    ``step_motion``: how far the pusher's loaded node moved back this frame when its held contact stepped its
    pseudo-time back (Alg. 5.1 oscillates by one step there; 0 when it did not), metres."""

    vertices: np.ndarray
    triangles: np.ndarray
    step_motion: float = 0.0


@dataclass
class ContactState:
    pseudo_time: float = 0.0
    load_point: int = -1  # index into the model's load points (-1: none)
    node: int = -1  # model node of that load point
    # the nearest real point's distance to a contact node; or, where a pushing virtual surface is nearer to contact
    # (its gap below the real point's distance less delta), that gap along the push direction (negative: the
    # surfaces overlap); metres
    min_distance: float = float("inf")
    nearest_load_point: int = -1  # where the nearest real point is now (may differ while a contact is held)
    state: ContactPhase = ContactPhase.FREE
    points_used: int = 0
    contact_point: tuple = (np.nan, np.nan, np.nan)
    reason: str = ""
    position: tuple = (np.nan, np.nan, np.nan)  # contact anywhere: where the load sits (object frame)

    @property
    def in_contact(self) -> bool:
        return self.state == ContactPhase.CONTACT


class ContactTracker:
    """Alg. 5.1 for one virtual object.

    ``model``: the object's reduced model; its load points are the contact nodes. The contact is a model
    state (:class:`~simreal_nodes.rom.state.LoadPointStates`): parameters (load_point, pseudo_time) for probe
    models (NI-PGD over contact point x pseudo-time), (s_x, s_y, pseudo_time) for the non-linear beams (NI-PGD
    over the load's position x pseudo-time), and (s_x[, s_y], load_scale) for linear PGD beams, where the
    pseudo-time scales the precomputed load. ``T_world_object``: where the virtual object sits.

    ``anywhere``: the load sits where the real object touches, between the load points (thesis §7.3's future work;
    models with load-position axes only, :meth:`state_at`; on a non-linear model the interpolation between load
    positions is the model's own, measured by its builder), instead of at the nearest load point.
    The load points stay the contact nodes of the distance test.
    """

    def __init__(self, model: ReducedModel, T_world_object: np.ndarray, threshold: float = 0.01, step: float = 0.05,
                 tau_min: float = 0.0, tau_max: float = 1.0, n_modes: int | None = None, min_fraction: float = 1e-3,
                 anywhere: bool = False, max_contacts: int = 1, separation: float = 0.0):
        self.load_states = LoadPointStates(model)
        if int(max_contacts) < 1:
            raise ValueError(f"max_contacts must be at least 1, not {max_contacts}")
        if int(max_contacts) > 1 and self.load_states.pseudo_time:
            raise ValueError(f"model '{model.name}': several contacts at once add their deformations, which holds for "
                             "a linear model whose contact scales its load; this one is an NI-PGD over its load "
                             f"and {PSEUDO_TIME} (a non-linear law): set collision.max_contacts: 1")
        if anywhere and self.load_states.probe:
            raise ValueError(f"model '{model.name}': its load points are discrete (NI-PGD over load point x "
                             "pseudo-time): a contact between them has no model state; contact anywhere needs "
                             f"load-position axes ({', '.join(LOAD_POSITION_AXES)}); set collision.anywhere: false")
        if anywhere and model.load_directions is None:
            raise ValueError(f"model '{model.name}' has no load directions: contact anywhere cannot tell where a real "
                             "point touches first; set collision.anywhere: false")
        self.anywhere = bool(anywhere)
        self._position_axes = [(LOAD_POSITION_AXES[a.name], a.range) for a in model.axes
                               if a.name in LOAD_POSITION_AXES] if anywhere else []
        self.model = model
        self.T = np.asarray(T_world_object, dtype=np.float64)
        self.threshold, self.step, self.tau_min, self.tau_max = threshold, step, tau_min, tau_max
        self.state = ContactState()
        self.lp_nodes = np.asarray(model.load_points, dtype=np.int64)
        self.contact_nodes = self._surface_nodes_of(model, self.lp_nodes)
        self.view = model.deformation_view(self.contact_nodes, n_modes)
        self.active = self._active_load_points(min_fraction)
        self.push_directions = self._push_directions(model)
        self.max_contacts = int(max_contacts)
        self.separation = float(separation) if separation > 0 else self._default_separation()
        self.contacts: list[ContactState] = []  # max_contacts > 1: the slots in contact, oldest first
        if self.max_contacts > 1:
            if model.load_directions is None:
                raise ValueError(f"model '{model.name}' has no load directions: several contacts cannot tell where "
                                 "a real point presses; set collision.max_contacts: 1")
            T, self._sample_weights = self._contact_samples()
            # the samples' triangle vertices, once: each frame deforms these only
            self._sample_nodes, inv = np.unique(T, return_inverse=True)
            self._sample_tris = inv.reshape(T.shape)
            P = np.asarray(model.points, dtype=np.float64)[self._sample_nodes]
            self._samples_rest = np.einsum("sk,skj->sj", self._sample_weights, P[self._sample_tris])

    def _push_directions(self, model: ReducedModel) -> np.ndarray:
        """Unit direction (object frame) in which a touching surface pushes each load point: the model's load
        direction, or where it has none the inward normal of the drawn surface at the contact node."""
        if model.load_directions is not None:
            d = np.asarray(model.load_directions, dtype=np.float64).reshape(-1, 3)
        else:
            P = np.asarray(model.points, dtype=np.float64)
            F = outward_triangles(P, np.asarray(model.surface, dtype=np.int64))
            n = np.zeros_like(P)
            if len(F):
                fn = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])  # area-weighted, outward
                for k in range(3):
                    np.add.at(n, F[:, k], fn)
            d = -n[self.contact_nodes]
        return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)

    @staticmethod
    def _surface_nodes_of(model: ReducedModel, nodes: np.ndarray) -> np.ndarray:
        """The drawn surface's node nearest to each of ``nodes`` (reference positions; a surface node is its own)."""
        surf = np.unique(np.asarray(model.surface, dtype=np.int64).ravel()) if len(model.surface) else nodes
        if len(surf) == 0:
            return nodes
        _, k = cast(tuple[np.ndarray, np.ndarray], cKDTree(model.points[surf]).query(model.points[nodes], k=1))
        return surf[np.asarray(k, dtype=np.int64)]

    def _active_load_points(self, min_fraction: float) -> np.ndarray:
        """Load points where a contact can deform the object: at supports (a clamp that touches the object is
        real geometry too) the largest precomputed displacement is ~0, and they are left out of the search.
        "~0": under ``min_fraction`` of the object's size. (It was a share of the largest displacement of any
        load point, which left out 11 of the bunny's 16 load points: an ear tip moves 67 mm, the body under 1 mm.
        The size rule keeps the crossed beams' 90 of 124, the same set, and every load point of the bunny and the
        dragon.)"""
        full = np.zeros(len(self.lp_nodes))
        for i in range(len(self.lp_nodes)):
            u = self.model.deformation(self.load_states.state(i, self.tau_max), nodes=[self.lp_nodes[i]])[0]
            full[i] = np.linalg.norm(u)
        self.full_motion = full
        size = float(np.max(np.ptp(np.asarray(self.model.points), axis=0)))
        act = full >= min_fraction * size if full.max() > 0 else np.ones(len(full), bool)
        if not act.any():  # a stiff object: none moves by that much; keep those within 2 % of the largest
            act = full >= 0.02 * full.max()
        return np.nonzero(act)[0]

    def _default_separation(self) -> float:
        """Two contacts are told apart when their load points are more than 2.5 load-point spacings apart (the
        median distance of an active load point to its nearest neighbour, rest shape): a probe touches a patch of
        neighbouring load points that belongs to one contact, and a closer pair of probes is taken as one."""
        P = self.model.points[self.contact_nodes[self.active]]
        if len(P) < 2:
            return float("inf")
        d = cast(tuple[np.ndarray, np.ndarray], cKDTree(P).query(P, k=2))[0][:, 1]
        size = float(np.max(np.ptp(np.asarray(self.model.points), axis=0)))
        # (load points stacked on one another: a floor, well over the surface samples' spacing)
        return 2.5 * max(float(np.median(d)), 0.01 * size)

    def _contact_samples(self) -> tuple[np.ndarray, np.ndarray]:
        """Several contacts: points on the drawn surface where a touch is looked for, in place of the load points
        alone (a probe between load points presses the surface between them): the triangles that face against the
        push direction (those a load can press; on a sheet, either side) sampled on a barycentric grid about a
        third of a load-point spacing apart, without those nearest an inactive load point (a support). Returns
        (vertex indices (s, 3), barycentric weights (s, 3)): a sample moves with its triangle's vertices."""
        P = np.asarray(self.model.points, dtype=np.float64)
        F = np.asarray(self.model.surface, dtype=np.int64).reshape(-1, 3)
        closed = _is_closed(F)
        F = outward_triangles(P, F) if closed else F
        d = np.mean(self.push_directions[self.active], axis=0)
        d /= max(float(np.linalg.norm(d)), 1e-12)
        n = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
        facing = -(n @ d) / np.maximum(np.linalg.norm(n, axis=1), 1e-300)
        F = F[facing > 0.3] if closed else F  # within about 70 degrees of facing the pusher
        size = float(np.ptp(P, axis=0).max())
        # samples a third of a load-point spacing apart, but never finer than a 300th of the object's size (a tiny
        # separation_m would otherwise ask for millions of samples a triangle)
        spacing = max(self.separation / 2.5 if np.isfinite(self.separation) else size, size / 100.0)
        tri, bary = [], []
        for f in F:
            edge = max(float(np.linalg.norm(P[f[i]] - P[f[(i + 1) % 3]])) for i in range(3))
            k = max(1, int(np.ceil(edge / (spacing / 3.0))))
            ij = np.array([(i, j) for i in range(k + 1) for j in range(k + 1 - i)], dtype=np.float64) / k
            w = np.c_[1.0 - ij.sum(axis=1), ij]
            tri.append(np.tile(f, (len(w), 1)))
            bary.append(w)
        if not tri:
            return np.zeros((0, 3), np.int64), np.zeros((0, 3))
        T, B = np.vstack(tri), np.vstack(bary)
        X = np.einsum("sk,skj->sj", B, P[T])
        near = cast(tuple[np.ndarray, np.ndarray], cKDTree(P[self.contact_nodes]).query(X, k=1))[1]
        keep = np.isin(np.asarray(near, np.int64), self.active)
        return T[keep], B[keep]

    # -- the contact as a model state -----------------------------------------------------------------------
    def model_state(self, state: ContactState | None = None) -> ModelState:
        """The model state of the current contact (load point 0 when there is none)."""
        st = state or self.state
        if self.anywhere and st.load_point >= 0 and np.all(np.isfinite(st.position)):
            return self.state_at(st.position, st.pseudo_time)
        return self.load_states.state(max(st.load_point, 0), st.pseudo_time)

    def state_at(self, point, pseudo_time: float) -> ModelState:
        """Contact anywhere (thesis §7.3): the model state of the load at ``point`` (object frame), between the load
        points. The load-position axes take the point's coordinates (clipped to their ranges) and the model
        interpolates its parameter modes along them: the reduced space's own interpolation, which for a linear
        model is the load shared among the neighbouring load positions with the axis' interpolation weights."""
        p = np.asarray(point, dtype=np.float64).ravel()
        return self.load_states.at([min(max(float(p[k]), lo), hi) for k, (lo, hi) in self._position_axes],
                                   pseudo_time)

    def parameter_names(self) -> list[str]:
        return self.load_states.layout.names

    def parameters(self, state: ContactState | None = None) -> np.ndarray:
        """The contact's model state as a vector: (load_point, pseudo_time), (s..., pseudo_time) or
        (s..., load_scale)."""
        return self.load_states.layout.vector(self.model_state(state))

    def displacement(self, nodes=None, state: ContactState | None = None, n_modes=None) -> np.ndarray:
        """The deformation of ``state`` (object frame); by default of the current contact, the sum of every
        contact's with ``max_contacts`` > 1."""
        if state is None and self.max_contacts > 1:
            n = self.model.n_nodes if nodes is None else len(nodes)
            return sum((self.displacement(nodes, c, n_modes) for c in self.states()), np.zeros((n, 3)))
        st = state or self.state
        if st.pseudo_time <= 0 or st.load_point < 0:
            n = self.model.n_nodes if nodes is None else len(nodes)
            return np.zeros((n, 3))
        return self.model.deformation(self.model_state(st), nodes, n_modes)

    def contact_nodes_world(self) -> np.ndarray:
        """The load points' contact nodes (on the surface) at their current deformed positions, world frame."""
        P = self.model.points[self.contact_nodes]
        for st in self.states():
            if st.pseudo_time > 0 and st.load_point >= 0:
                P = P + self.view(self.model_state(st))
        return G.transform(self.T, P)

    def states(self) -> list[ContactState]:
        """The contacts whose deformation is drawn: the slots in contact (``max_contacts`` > 1), else the one."""
        return list(self.contacts) if self.max_contacts > 1 else [self.state]

    def _contact_position(self, near: np.ndarray, nodes: np.ndarray) -> tuple:
        """Contact anywhere: where the real points ``near`` (world) touch first, object frame. Each point's gap is
        its height over the nearest contact node (across the load direction) along the load direction; the
        position is the mean of the points within 1 mm of the smallest gap (a sphere: its cap's centre; a flat
        pusher: the overlap's centre). The nearest real point to the nearest node would be pulled towards that
        node, up to half the load points' spacing."""
        d = np.mean(np.asarray(self.model.load_directions, dtype=np.float64)[self.active], axis=0)
        d /= max(float(np.linalg.norm(d)), 1e-12)
        T_inv = G.inv(self.T)
        q = G.transform(T_inv, near)
        X = G.transform(T_inv, nodes[self.active])
        lat = np.eye(3) - np.outer(d, d)
        _, k = cast(tuple[np.ndarray, np.ndarray], cKDTree(X @ lat).query(q @ lat, k=1))
        gap = np.einsum("ij,j->i", X[np.asarray(k, dtype=np.int64)] - q, d)
        sel = gap <= gap.min() + 1e-3
        return tuple(float(v) for v in q[sel].mean(axis=0))

    def step_motion(self, st: ContactState) -> float:
        """How far the loaded contact node moves when the pseudo-time steps back once from where it is (metres)."""
        if st.load_point < 0 or st.pseudo_time <= 0:
            return 0.0
        back = ContactState(pseudo_time=max(self.tau_min, st.pseudo_time - self.step), load_point=st.load_point,
                            position=st.position)
        return self.node_motion(st, back)

    def node_motion(self, a: ContactState, b: ContactState) -> float:
        """How far the loaded contact node of ``a`` moves between the states ``a`` and ``b`` of the same contact
        (metres; 0 without one)."""
        if a.load_point < 0:
            return 0.0
        node = [int(self.contact_nodes[a.load_point])]
        ua = self.model.deformation(self.model_state(a), nodes=node) if a.pseudo_time > 0 else np.zeros((1, 3))
        ub = self.model.deformation(self.model_state(b), nodes=node) if b.pseudo_time > 0 else np.zeros((1, 3))
        return float(np.linalg.norm(ua - ub))

    def _pusher_gap(self, nodes: np.ndarray,
                    surfaces: list[PusherSurface]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Virtual-virtual contact: for each active contact node (world ``nodes``), the gap to the pushing
        surfaces along its push direction (negative: they overlap; inf: none lies across it) and where that line
        meets them. The line through the node against its push direction is cut with the pusher's triangles
        that face the node (outward normal along the push direction); an overlap counts down to twice the
        node's largest precomputed motion (deeper, the surface behind would belong to another part of the
        pusher). Third: the winning surface's own step motion per node."""
        X = nodes[self.active]
        D = self.push_directions[self.active] @ self.T[:3, :3].T
        gap = np.full(len(X), np.inf)
        hit = np.full((len(X), 3), np.nan)
        slack = np.zeros(len(X))
        # an overlap deeper than that bound is not this contact (a line through the whole pusher can meet another of
        # its faces far behind); past the largest precomputed motion the pushed object is saturated anyway
        bound = 2.0 * self.full_motion[self.active] + self.threshold
        lo, hi = X.min(axis=0), X.max(axis=0)
        for s in surfaces:
            V = np.asarray(s.vertices, np.float64)
            F = np.asarray(s.triangles, np.int64).reshape(-1, 3)
            # only the pusher's triangles within reach of the nodes (a scanned pusher has 10^4-10^5 of them): farther
            # ones can neither overlap a node nor hold its contact (a hold reaches one step motion, under the bound)
            reach = float(bound.max()) + float(s.step_motion)
            tri = V[F]
            near = np.all((tri.max(axis=1) >= lo - reach) & (tri.min(axis=1) <= hi + reach), axis=1)
            t = _line_triangle_gaps(X, D, V, F[near])
            t[t < -bound[:, None]] = np.inf
            j = np.argmin(t, axis=1) if t.shape[1] else np.zeros(len(X), np.int64)
            tj = t[np.arange(len(X)), j] if t.shape[1] else np.full(len(X), np.inf)
            better = tj < gap
            gap[better] = tj[better]
            hit[better] = X[better] - tj[better, None] * D[better]
            slack[better] = float(s.step_motion)
        return gap, hit, slack

    # -- Alg. 5.1 ------------------------------------------------------------------------------------------
    def update(self, points_world: np.ndarray | None,
               surfaces: list[PusherSurface] | None = None) -> ContactState:
        """One frame. ``points_world``: (n, 3) real points, world frame; ``surfaces``: the deformed surfaces of the
        virtual objects that push this one. No valid points and no surface means no data this frame (the
        deformation relaxes, state NO_DATA).

        A real point is in contact within delta of a contact node; a pushing surface at a gap of zero or less
        along the node's push direction. Alg. 5.1 runs on the nearer to contact of the two ("clearance": the
        distance less delta, or the gap)."""
        st = self.state
        pts = None if points_world is None else np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        if pts is not None and pts.size:
            pts = pts[np.all(np.isfinite(pts), axis=1)]
        surfaces = [s for s in (surfaces or []) if len(s.triangles)]
        has_data = (pts is not None and len(pts) > 0) or bool(surfaces)
        if self.max_contacts > 1:
            return self._update_many(pts, surfaces, has_data)
        nodes = self.contact_nodes_world()
        st.points_used = 0 if pts is None else len(pts)
        d_min, nearest = np.inf, -1
        near = np.zeros((0, 3))
        if pts is not None and len(pts):
            # only points near the object can touch it: crop to its box grown by delta (a depth image is mostly
            # elsewhere; the KD-tree is then built on the few points there instead of 10^5). min_distance is exact
            # below delta; farther, when nothing is in the box, it is estimated from a subsample
            lo = nodes[self.active].min(axis=0) - self.threshold
            hi = nodes[self.active].max(axis=0) + self.threshold
            near = pts[np.all((pts >= lo) & (pts <= hi), axis=1)]
            if len(near) == 0:  # nothing can touch: the reported distance from at most 5 000 of the points
                near = pts[:: max(1, len(pts) // 5000)]
            if len(near):
                # many query points with k=1: arrays of distances and indices (the stubs also allow scalars)
                d, idx = cast(tuple[np.ndarray, np.ndarray], cKDTree(near).query(nodes[self.active], k=1))
                k = int(np.argmin(d))
                if np.isfinite(d[k]):  # points so far off (1e300 m) that their distance overflows: none near
                    nearest, d_min = int(self.active[k]), float(d[k])
                    st.contact_point = tuple(float(x) for x in near[idx[k]])
        clearance = d_min - self.threshold
        virtual, pusher_slack = False, 0.0
        if surfaces:
            gap, hit, slack = self._pusher_gap(nodes, surfaces)
            k = int(np.argmin(gap))
            if gap[k] < clearance:  # the pushing surface is nearer to contact than any real point
                virtual, clearance, nearest, d_min = True, float(gap[k]), int(self.active[k]), float(gap[k])
                st.contact_point = tuple(float(x) for x in hit[k])
                pusher_slack = float(slack[k])
        st.min_distance, st.nearest_load_point = d_min, nearest
        if clearance < 0 and st.pseudo_time < self.tau_max - 1e-12 and (st.pseudo_time <= 0 or st.load_point < 0):
            st.load_point = nearest  # a new contact starts where the real point (or the pushing surface) is
            if self.anywhere and virtual:  # where the pushing surface overlaps the object most
                sel = gap <= gap.min() + 1e-3
                st.position = tuple(float(v) for v in G.transform(G.inv(self.T), hit[sel]).mean(axis=0))
            elif self.anywhere:  # the real points within delta of the object: where they touch it first
                dn = cast(tuple[np.ndarray, np.ndarray], cKDTree(nodes[self.active]).query(near, k=1))[0]
                st.position = self._contact_position(near[dn < self.threshold], nodes)
        if clearance < 0 or st.pseudo_time > self.tau_min + 1e-12:
            self._step(st, clearance, pusher_slack, has_data)
        else:
            st.state = ContactPhase.FREE if has_data else ContactPhase.NO_DATA
            st.reason = "" if has_data else "no valid points"
            self._settle(st)
        return st

    def _all_back_motion(self, st: ContactState) -> float:
        """How far the loaded contact node of ``st`` moves when every contact steps its pseudo-time back once
        (several contacts: the deformations add, so the others' steps move it too; metres)."""
        node = [int(self.contact_nodes[st.load_point])]
        u = np.zeros((1, 3))
        for c in self.contacts:
            back = replace(c, pseudo_time=max(self.tau_min, c.pseudo_time - self.step))
            u += self.displacement(node, c) - self.displacement(node, back)
        return float(np.linalg.norm(u))

    def _step(self, st: ContactState, clearance: float, slack: float, has_data: bool,
              back: float | None = None) -> None:
        """Alg. 5.1's step of one contact on its clearance (the distance less delta, or a pushing surface's gap):
        on while under zero, held while one step back would bring it under zero again (``back``: how far its node
        moves then, by default its own step's motion; ``slack``: how far the pushing surface itself stepped
        back), else released."""
        if clearance < 0 and st.pseudo_time < self.tau_max - 1e-12:
            st.pseudo_time = min(self.tau_max, st.pseudo_time + self.step)
            st.state, st.reason = ContactPhase.CONTACT, ""
        elif clearance < 0:
            st.state, st.reason = ContactPhase.CONTACT, "largest precomputed deformation reached"
        else:
            # still held: one step back would bring the surface within delta (or onto the pushing surface) again:
            # the pseudo-time then oscillates by one step about where the surface follows, and the contact is there.
            # A pushing surface whose own held contact just stepped back has moved away by its step motion too
            held = clearance < (self.step_motion(st) if back is None else back) + slack
            st.pseudo_time = max(self.tau_min, st.pseudo_time - self.step)
            held = held and st.pseudo_time > self.tau_min + 1e-12
            st.state = ContactPhase.CONTACT if held else ContactPhase.RELEASING
            st.reason = "" if has_data else "no valid points: relaxing"
        self._settle(st)

    def _settle(self, st: ContactState) -> None:
        """A contact relaxed to zero forgets its load point and position; the node follows the load point."""
        if st.pseudo_time <= 1e-12:
            st.pseudo_time, st.load_point, st.position = 0.0, -1, (np.nan, np.nan, np.nan)
        st.node = int(self.lp_nodes[st.load_point]) if st.load_point >= 0 else -1

    def _touches(self, pts: np.ndarray | None,
                 surfaces: list[PusherSurface]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Where things touch the object this frame, for several contacts: (gap (n,), where on the object's surface
        (n, 3), object frame, at *rest*: a contact's load position and its neighbourhood are rest coordinates, whatever
        the deflection; slack (n,), from a pushing surface (n,) bool, the touching point (n, 3) world).

        Real points: Alg. 5.1's distance, from each of the drawn surface's contact samples
        (:meth:`_contact_samples`, at the summed deformation) to the nearest real point; a pushing virtual surface:
        its gap at each active contact node (:meth:`_pusher_gap`)."""
        gaps, hits, slack, virt, src = [np.zeros(0)], [np.zeros((0, 3))], [np.zeros(0)], [np.zeros(0, bool)], \
            [np.zeros((0, 3))]
        if pts is not None and len(pts) and len(self._samples_rest):
            rest = np.asarray(self.model.points, dtype=np.float64)[self._sample_nodes]
            V = rest + self.displacement(self._sample_nodes)
            X = G.transform(self.T, np.einsum("sk,skj->sj", self._sample_weights, V[self._sample_tris]))
            lo, hi = X.min(axis=0) - self.threshold, X.max(axis=0) + self.threshold
            near = pts[np.all((pts >= lo) & (pts <= hi), axis=1)]
            if len(near) == 0:  # nothing can touch: the reported distance from at most 5 000 of the points
                near = pts[:: max(1, len(pts) // 5000)]
            dist, idx = cast(tuple[np.ndarray, np.ndarray], cKDTree(near).query(X, k=1))
            ok = np.isfinite(dist)  # an overflowing distance (points 1e300 m off) is no neighbour
            gaps.append(np.asarray(dist, np.float64)[ok])
            hits.append(self._samples_rest[ok])
            slack.append(np.zeros(int(ok.sum())))
            virt.append(np.zeros(int(ok.sum()), bool))
            src.append(near[np.asarray(idx, np.int64)[ok]])
        if surfaces:
            nodes = self.contact_nodes_world()
            gap, hit, sl = self._pusher_gap(nodes, surfaces)
            ok = np.isfinite(gap)
            gaps.append(gap[ok])
            hits.append(np.asarray(self.model.points, dtype=np.float64)[self.contact_nodes[self.active]][ok])
            slack.append(sl[ok])
            virt.append(np.ones(int(ok.sum()), bool))
            src.append(hit[ok])
        return (np.concatenate(gaps), np.concatenate(hits), np.concatenate(slack), np.concatenate(virt),
                np.concatenate(src))

    def _update_many(self, pts: np.ndarray | None, surfaces: list[PusherSurface], has_data: bool) -> ContactState:
        """One frame of Alg. 5.1 with several contacts (``max_contacts`` > 1; the module docstring). Each slot steps
        on the smallest clearance (gap less delta for a real point, the gap for a pushing surface) of what touches
        the object within ``separation`` of the slot's load (rest coordinates), with the deformed surface at the
        summed deformation; touches farther than that from every slot start new slots (the deepest first) while
        fewer than ``max_contacts`` are held (in contact or releasing). ``self.state`` sums them up for the
        messages: the oldest contact's load and pseudo-time, the phase CONTACT while any is."""
        gap, at, slack, virtual, src = self._touches(pts, surfaces)  # at: where, object frame at rest
        clear = np.where(virtual, gap, gap - self.threshold)
        lp_rest = self.model.points[self.contact_nodes[self.active]]

        def centre(c: ContactState) -> np.ndarray:
            p = np.asarray(c.position, dtype=np.float64)
            if self.anywhere and np.all(np.isfinite(p)):
                return p
            return self.model.points[self.contact_nodes[c.load_point]]

        def around(c: np.ndarray) -> np.ndarray:
            return np.linalg.norm(at - c, axis=1) < self.separation

        # each slot's clearance, and how far its node moves when every slot steps back once (the held test: the
        # others' step back lifts it too), all on this frame's states before any of them steps
        steps = []
        for st in self.contacts:
            nb = around(centre(st))
            k = int(np.flatnonzero(nb)[np.argmin(clear[nb])]) if nb.any() else -1
            steps.append((k, self._all_back_motion(st)))
        for st, (k, back) in zip(self.contacts, steps):
            if k >= 0:
                st.min_distance, st.contact_point = float(gap[k]), tuple(float(v) for v in src[k])
                self._step(st, float(clear[k]), float(slack[k]), has_data, back)
            else:
                st.min_distance = float("inf")
                self._step(st, float("inf"), 0.0, has_data, back)
            st.points_used = 0 if pts is None else len(pts)
        self.contacts = [c for c in self.contacts if c.load_point >= 0]
        free = clear < 0
        for c in self.contacts:
            free &= ~around(centre(c))
        while free.any() and len(self.contacts) < self.max_contacts:
            k = int(np.argmin(np.where(free, clear, np.inf)))
            nb = around(at[k])
            lp = int(self.active[int(np.argmin(np.linalg.norm(lp_rest - at[k], axis=1)))])
            st = ContactState(load_point=lp, min_distance=float(gap[k]), nearest_load_point=lp,
                              contact_point=tuple(float(v) for v in src[k]),
                              points_used=0 if pts is None else len(pts))
            if self.anywhere:  # where it touches first: the mean of the touches within 1 mm of the deepest
                sel = nb & free & (clear <= clear[k] + 1e-3)
                st.position = tuple(float(v) for v in at[sel].mean(axis=0))
            self._step(st, float(clear[k]), float(slack[k]), has_data)
            self.contacts.append(st)
            free &= ~nb
        k = int(np.argmin(gap)) if len(gap) else -1
        nearest = (float(gap[k]), int(self.active[int(np.argmin(np.linalg.norm(lp_rest - at[k], axis=1)))]),
                   tuple(float(v) for v in src[k])) if k >= 0 else None
        return self._summary(nearest, pts, has_data)

    def _summary(self, nearest: tuple | None, pts: np.ndarray | None, has_data: bool) -> ContactState:
        """The state the messages carry with several contacts: the oldest contact's, the phase CONTACT while any
        contact is, the nearest touch over the whole object (``nearest``: gap, its load point, the touching point)."""
        st = replace(self.contacts[0]) if self.contacts else ContactState()
        if any(c.in_contact for c in self.contacts):
            st.state, st.reason = ContactPhase.CONTACT, next((c.reason for c in self.contacts if c.in_contact), "")
        elif self.contacts:
            st.state = ContactPhase.RELEASING
        else:
            st.state = ContactPhase.FREE if has_data else ContactPhase.NO_DATA
            st.reason = "" if has_data else "no valid points"
        if nearest is not None:
            st.min_distance, st.nearest_load_point, st.contact_point = nearest
        else:
            st.min_distance, st.nearest_load_point = float("inf"), -1
        st.points_used = 0 if pts is None else len(pts)
        self.state = st
        return st


def outward_triangles(P: np.ndarray, F: np.ndarray) -> np.ndarray:
    """A closed surface's triangles turned outward: reversed when the volume they enclose comes out negative (the
    pusher's gap test takes the triangles whose outward normal faces the pushed object; a model without load
    directions is pushed along its inward normals)."""
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    P = np.asarray(P, dtype=np.float64)
    if len(F) == 0:
        return F
    c = P[np.unique(F)].mean(axis=0)  # about the surface's own centre: the sum is exact for a closed surface
    a, b, d = P[F[:, 0]] - c, P[F[:, 1]] - c, P[F[:, 2]] - c
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, d)).sum()) / 6
    return F[:, ::-1].copy() if volume < 0 else F


def _is_closed(F: np.ndarray) -> bool:
    """Whether the triangles close a surface: every edge shared by exactly two of them."""
    if len(F) == 0:
        return False
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def _line_triangle_gaps(X: np.ndarray, D: np.ndarray, V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(n, m) signed gaps t at which the line X_i - t D_i (through each point, against its unit push direction
    D_i) crosses triangle j of (V, F), for the triangles that face the point (outward normal along D_i); inf where
    it misses one or the triangle faces away. Moller-Trumbore with the ray direction -D_i, t of either sign."""
    if len(F) == 0 or len(X) == 0:
        return np.full((len(X), len(F)), np.inf)
    A, e1, e2 = V[F[:, 0]], V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    r = -D[:, None, :]
    p = np.cross(r, e2[None])
    det = np.einsum("mk,nmk->nm", e1, p)  # = D_i . (e1 x e2): > 0 where the triangle faces the point
    ok = det > 1e-14 * np.einsum("mk,mk->m", e1, e1)[None]
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = X[:, None, :] - A[None]
    u = np.einsum("nmk,nmk->nm", s, p) * inv
    q = np.cross(s, e1[None])
    v = np.einsum("nmk,nmk->nm", np.broadcast_to(r, q.shape), q) * inv
    t = np.einsum("mk,nmk->nm", e2, q) * inv
    tol = 1e-9
    inside = ok & (u >= -tol) & (v >= -tol) & (u + v <= 1 + tol)
    return np.where(inside, t, np.inf)
