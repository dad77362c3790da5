"""The object's deformation read from depth: the reduced model's deformed surface fitted to a depth cloud.

Why (issue 16, item 6): the dense measurement takes a reference view and compares later images with it; the
sparse one links map points where they were first seen. Both need the state of the object in that first view.
Taking it to be the rest shape is right for a scene that starts unloaded and wrong for one loaded from its first
frame: the deformation present then is never seen, and every later estimate is off by it. A depth image measures
that deformation directly, as the surface's shape, without any reference.

The fit is non-rigid point-to-plane ICP through the PGD (the depth counterpart of Eq. 4.7-4.11). Samples y_k on
the model surface (object frame, barycentric in a surface triangle) move with the deformation and a small upright
rigid correction (translation delta, turn psi about the object's z axis through its centre c):

    y_k(mu, psi, delta) = c + R_z(psi) (x_k + u_k(mu) - c) + delta,
    r_j = n_k . (q_j - y_k),     k = the sample nearest to the measured point q_j (object frame),

with n_k the sample's rest normal turned by R_z(psi) (the deformations here turn the surface by degrees at most).
Gauss-Newton with Levenberg damping on Tukey's biweight of r (scale: 1.4826 MAD, at least ``min_sigma``),
re-associating every iteration; mu stays in its box. The rigid part is upright on purpose: a turn about a
horizontal axis is what a cantilever's bending looks like over its length, and the support plane already fixes
those two angles (:func:`registration.register_rgbd` levels the object onto it).

Because mu may have no value that means "at rest" (a model of a load's position only), the deformed fit is
compared with the same fit at zero displacement, rigid part refitted: the deformation is taken only when it lowers
the robust cost by ``min_gain`` and moves the matched surface by ``min_motion`` (90th percentile). Otherwise the
object is reported at rest.

A body of revolution about the object's z axis (the joint boot) shows its turn psi only through its bend, and
Gauss-Newton finds that turn within a few degrees of its start only. Where a caller knows the object is one
(``DepthStateConfig.turn_steps``: a registration's ``revolves``, a tracker's ``depth_turn``), the deformed fit also
searches psi over the whole circle (:func:`_searched_turn`) and reports how well its shape holds the turn.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import cast

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.dense import TUKEY, sample_surface
from simreal_nodes.rom.model import DeformationView, ReducedModel

Array = NDArray[np.float64]
N_RIGID = 4  # delta (3), psi


@dataclass(frozen=True)
class DepthStateConfig:
    """Lengths in metres. ``spacing``: model surface samples about this far apart (at most ``max_samples``);
    ``radius``: a measured point farther than this from every sample is not the object's (it counts as an
    outlier); ``band``: points this close above the model's underside are dropped (the supports meet it there);
    ``margin``: the crop around every shape the model can take (the pose's error);
    ``grid``: candidates of the coarse search over the free parameters; ``min_gain`` / ``min_motion``: what a
    deformation must achieve over the rest shape to be taken (chosen on development seeds 0-49)."""

    spacing: float = 0.003
    max_samples: int = 8000
    radius: float = 0.01
    band: float = 0.004
    margin: float = 0.01  # around the box the model's shapes can take (:func:`extent`): the pose's error
    iterations: int = 20
    grid: int = 24
    min_sigma: float = 0.0005
    min_points: int = 300
    # on development seeds 0-49 (first frame, pose 1 mm / 0.3 deg off): unloaded beams gain at most +0.6 %, loaded
    # ones at least +1.3 % (one at +0.3 %, moving its surface 0.3 mm: a load next to the clamp)
    min_gain: float = 0.01
    min_motion: float = 0.0005
    slide_ratio: float = 0.05  # as :attr:`registration.RegistrationConfig.slide_ratio`
    rigid: bool = True
    # a body of revolution about the object's z axis (the boot), whose turn about it is the load's direction: the
    # deformed fit searched over that turn too (:func:`_searched_turn`), ``turn_steps`` turns over the whole circle.
    # Off (0) unless the caller knows the object is one (a registration's ``revolves``, a tracker's depth_turn)
    turn_steps: int = 0


@dataclass
class DepthState:
    """``mu``: the fitted state (None: at rest, or no fit); ``T_map_obj``: the pose with the fitted rigid correction;
    ``cost`` / ``rest_cost``: mean Tukey cost per measured point of the deformed fit and of the rest fit (the
    same scale); ``motion``: 90th percentile of |u(mu)| over the samples that matched (m); ``points``: measured
    points used; ``reason``: why ``mu`` is None, or what was found; ``rigid``: the upright rigid correction of
    ``T_map_obj`` on the pose given (x, y, z, turn psi about the object's z axis through the model's centroid), as
    :class:`DepthFollower` carries it (zeros where no fit ran); ``turn_held``: with ``turn_steps``, how well the
    deformed fit's shape holds its turn, as :attr:`DepthFit.turn_held` (inf: not computed)."""

    mu: Array | None
    T_map_obj: Array
    fitted: Array | None
    cost: float
    rest_cost: float
    motion: float
    points: int
    sigma: float
    reason: str
    rigid: Array = field(default_factory=lambda: np.zeros(N_RIGID))
    turn_held: float = float("inf")

    @property
    def deformed(self) -> bool:
        return self.mu is not None


class _Surface:
    """The model's surface samples, their displacement view and their rest normals."""

    def __init__(self, model: ReducedModel, cfg: DepthStateConfig, n_modes: int | None) -> None:
        smp = sample_surface(model, cfg.spacing, cfg.max_samples, seed=0)
        self.x = smp.x
        self.n = smp.normal
        self.view: DeformationView = model.deformation_view(smp.nodes, n_modes, smp.weights)
        self.c = np.asarray(model.points, np.float64).mean(axis=0)
        self.rest_tree = cKDTree(self.x)  # the rest samples' search tree (:func:`_weak_direction`, every frame)

    def place(self, mu: Array | None, rigid: Array) -> tuple[Array, Array]:
        """Samples y (N, 3) at the state mu (None: at rest) and the rigid correction, and the correction's rotation
        R_z(psi) (3, 3), which turns a sample's rest normal (:meth:`normals`)."""
        x = self.x if mu is None else self.x + self.view.field.evaluate(mu)
        Rz = G.rot_axis("z", rigid[3])
        return (x - self.c) @ Rz.T + self.c + rigid[:3], Rz

    def normals(self, k: NDArray[np.int64], Rz: Array) -> Array:
        """The normals of samples ``k`` turned by ``Rz``: only the samples that some point matched, rather than all
        of them at every placement (a row's product does not depend on the others'). A single row goes to BLAS's
        matrix-vector product, which may round differently: it is taken from the whole product."""
        if len(k) < 2:
            few: Array = (self.n @ Rz.T)[k]
            return few
        out: Array = self.n[k] @ Rz.T
        return out


def _lengths(d: Array) -> Array:
    """The lengths of vectors along the last axis (3), summed in the order ``np.sum`` takes (the same values), without
    its temporary of squares."""
    sq = d * d
    out: Array = np.sqrt(sq[..., 0] + sq[..., 1] + sq[..., 2])
    return out


def _rho(r: Array, c: float) -> Array:
    q = np.minimum((r / c) ** 2, 1.0)
    out: Array = c * c / 6.0 * (1.0 - (1.0 - q) ** 3)
    return out


class _Problem:
    """The fit's residuals over the measured points ``q`` (object frame). The association of a state (the samples
    placed, each point's nearest sample) is kept for the last few states asked for: Gauss-Newton asks for the
    residuals at a trial state, then for their Jacobian at the same state once the trial is taken.

    The nearest samples come from a KD-tree over the samples at an earlier placement, kept while no sample has moved
    half the sample ``spacing`` from it (most of a solve's steps, which move the surface by fractions of a
    millimetre). The answer is the one a tree over the samples where they are now would give: a sample that has
    moved by at most delta is now no nearer to a point than its distance there less delta (:meth:`_nearest`)."""

    _KEEP = 4
    _CANDIDATES = 8  # each point's nearest samples at the tree's placement, which decide most points

    def __init__(self, surf: _Surface, q: Array, cfg: DepthStateConfig, hold: Array | None = None) -> None:
        self.s, self.q, self.cfg = surf, q, cfg
        self.hold = hold  # a unit direction (object frame) along which the translation stays as given
        self._assoc: dict[bytes, tuple[Array, Array, NDArray[np.int64], NDArray[np.bool_]]] = {}
        # the tree's placement: its samples, the tree, each point's candidates and the distance beyond which lie
        # the samples that are not its candidates (both filled in when the tree is first reused)
        self._tree: tuple[Array, cKDTree, NDArray[np.int64] | None, Array | None, Array | None] | None = None
        self._placed: dict[bytes, tuple[Array, cKDTree]] = {}  # :meth:`turn_costs`' trees, by state

    def _nearest(self, y: Array) -> tuple[Array, NDArray[np.int64]]:
        """Each measured point's distance to its nearest sample among ``y`` and that sample's index, as
        ``cKDTree(y).query(q, distance_upper_bound=radius)`` answers it (inf and len(y) where no sample is nearer
        than the radius). With the samples moved by at most delta since the kept tree's placement, a sample that was
        not among a point's candidates (all at least d_k away there) is now at least d_k - delta away. So where the
        nearest candidate now is nearer than that, or the radius is, the candidates decide; the other points search
        the kept tree for every sample that was within their nearest candidate's distance (or the radius) plus
        delta."""
        R = self.cfg.radius
        if self._tree is not None:
            y0, tree, K, d1, dk = self._tree
            moved = y - y0
            delta = float(np.sqrt(np.max(np.einsum("ij,ij->i", moved, moved))))
            if delta < 0.5 * self.cfg.spacing:
                if K is None or d1 is None or dk is None:  # the tree is reused: each point's candidates there
                    bound = R + 2 * self.cfg.spacing
                    dK, K = cast(tuple[Array, NDArray[np.int64]],
                                 tree.query(self.q, k=self._CANDIDATES, distance_upper_bound=bound))
                    K = np.minimum(K, len(y0) - 1)  # a missing candidate (inf) stands in as any sample
                    d1, dk = np.minimum(dK[:, 0], bound), np.minimum(dK[:, -1], bound)
                    self._tree = (y0, tree, K, d1, dk)
                dist, k = np.full(len(self.q), np.inf), np.full(len(self.q), len(y), np.int64)
                # a point with no sample within the radius plus delta there has none within the radius now
                cand = np.flatnonzero(d1 - delta - 1e-9 < R)  # (1 nm for rounding)
                Kc = K[cand]
                D = _lengths(self.q[cand, None, :] - y[Kc])
                j = np.argmin(D, axis=1)
                dc, kc = D[np.arange(len(cand)), j], Kc[np.arange(len(cand)), j]
                beyond = dk[cand] - delta - 1e-9  # every other sample is at least this far now
                open_ = ~((dc < beyond) | (beyond >= R))
                if np.any(open_):
                    io = np.flatnonzero(open_)
                    balls = tree.query_ball_point(self.q[cand[io]], np.minimum(dc[io], R) + delta + 1e-9)
                    # every ball's samples in one pass: each point's nearest is the first of its ball's least
                    # distance, in the ball's order (a stable sort by point, then distance)
                    sizes = np.fromiter(map(len, balls), np.int64, len(balls))
                    if sizes.sum():
                        near = np.fromiter(itertools.chain.from_iterable(balls), np.int64, int(sizes.sum()))
                        owner = np.repeat(io, sizes)
                        d = _lengths(self.q[cand[owner]] - y[near])
                        order = np.lexsort((d, owner))
                        first = order[np.r_[0, np.cumsum(sizes[sizes > 0])[:-1]]]
                        dc[owner[first]], kc[owner[first]] = d[first], near[first]
                dist[cand], k[cand] = dc, kc
                out = dist >= R
                dist[out], k[out] = np.inf, len(y)
                return dist, k
        tree = cKDTree(y, balanced_tree=False, compact_nodes=False)  # unbalanced: half the build time
        self._tree = (y, tree, None, None, None)
        return cast(tuple[Array, NDArray[np.int64]], tree.query(self.q, distance_upper_bound=R))

    def _associate(self, mu: Array | None, rigid: Array) -> tuple[Array, Array, NDArray[np.int64], NDArray[np.bool_]]:
        """Samples placed at (mu, rigid), the rigid correction's rotation, each measured point's nearest sample and
        whether it lies within the radius."""
        key = (b"" if mu is None else np.asarray(mu, np.float64).tobytes()) + b"|" + rigid.tobytes()
        hit = self._assoc.get(key)
        if hit is not None:
            return hit
        y, Rz = self.s.place(mu, rigid)
        dist, k = self._nearest(y)
        out = (y, Rz, k, np.isfinite(dist))
        if len(self._assoc) >= self._KEEP:
            self._assoc.pop(next(iter(self._assoc)))
        self._assoc[key] = out
        return out

    def residuals(self, mu: Array | None, rigid: Array, jac: bool = False
                  ) -> tuple[Array, NDArray[np.bool_], Array | None]:
        """Point-to-plane residuals (one per measured point; NaN beyond the radius) and their Jacobian over
        (mu, delta, psi)."""
        y, Rz, k, ok = self._associate(mu, rigid)
        kk = k[ok]
        d = self.q[ok] - y[kk]
        nk = self.s.normals(kk, Rz)
        r = np.full(len(self.q), np.nan)
        r[ok] = np.sum(nk * d, axis=1)
        if not jac:
            return r, ok, None
        cols = []
        if mu is not None:
            dy = np.einsum("ij,njk->nik", Rz, self.s.view.with_jacobian(mu)[1][kk])
            cols.append(-np.einsum("nd,ndp->np", nk, dy))
        cols.append(-nk)  # delta
        # psi turns the sample about c + delta (d y / d psi = e_z x (y - c - delta)) and its normal
        # (d n / d psi = e_z x n): d r / d psi = (e_z x n) . (q - y) - n . (e_z x (y - c - delta))
        arm = y[kk] - self.s.c - rigid[:3]
        cols.append((-np.sum(nk * np.cross([0.0, 0.0, 1.0], arm), axis=1)
                     + np.sum(np.cross([0.0, 0.0, 1.0], nk) * d, axis=1))[:, None])
        return r, ok, np.concatenate(cols, axis=1)

    @staticmethod
    def _mean_cost(r: Array, ok: NDArray[np.bool_], c: float) -> float:
        out = np.full(len(r), c * c / 6.0)
        out[ok] = _rho(r[ok], c)
        return float(out.mean())

    def turn_std(self, mu: Array | None, rigid: Array) -> float:
        """The standard deviation of the turn psi at (mu, rigid) for unit residuals (the rigid block of Gauss-Newton's
        covariance, (J^T J)^-1, over the points within the radius): how well the shape holds the turn, to be
        compared between shapes on the same points. inf where the normal equations do not hold it."""
        _, _, J = self.residuals(mu, rigid, jac=True)
        assert J is not None
        Jr = J[:, J.shape[1] - N_RIGID:]
        try:
            var = float(np.linalg.inv(Jr.T @ Jr)[-1, -1])
        except np.linalg.LinAlgError:
            return float("inf")
        return float(np.sqrt(var)) if np.isfinite(var) and var > 0 else float("inf")

    def cost(self, mu: Array | None, rigid: Array, c: float) -> float:
        """Mean Tukey cost per measured point; a point with no sample within the radius costs the most."""
        r, ok, _ = self.residuals(mu, rigid)
        return self._mean_cost(r, ok, c)

    def turn_costs(self, mu: Array | None, t: Array, psis: Array, c: float) -> Array:
        """:meth:`cost` at each rigid correction (t, psi) for the turns ``psis``, from one search tree: the samples
        stay where mu places them and the measured points take the inverse of each correction instead. Distances
        and point-to-plane residuals do not change under a rigid motion of both, so each cost is the one
        :meth:`cost` gives (to rounding): with y = R (x - c) + c + t and the normal R n, (R n) . (q - y) =
        n . (q' - x) where q' = R^T (q - c - t) + c. One tree and one query for all the turns, where :meth:`cost`
        builds a tree for each (the turn moves every sample farther than the kept tree allows). The trees of the
        last few states are kept (a search asks again for the same states at other translations)."""
        key = b"" if mu is None else np.asarray(mu, np.float64).tobytes()  # as :meth:`_associate` keys a state
        if key not in self._placed:
            x, _ = self.s.place(mu, np.zeros(N_RIGID))
            if len(self._placed) >= 2 * self._KEEP:
                self._placed.pop(next(iter(self._placed)))
            self._placed[key] = (x, cKDTree(x, balanced_tree=False, compact_nodes=False))
        x, tree = self._placed[key]
        qc = self.q - self.s.c - t
        qs = np.stack([qc @ G.rot_axis("z", float(p)) for p in psis]) + self.s.c  # (turns, points, 3)
        dist, k = cast(tuple[Array, NDArray[np.int64]],
                       tree.query(qs.reshape(-1, 3), distance_upper_bound=self.cfg.radius))
        ok = np.isfinite(dist)
        r = np.full(len(dist), np.nan)
        r[ok] = np.sum(self.s.n[k[ok]] * (qs.reshape(-1, 3)[ok] - x[k[ok]]), axis=1)
        shape = (len(psis), len(self.q))
        return np.array([self._mean_cost(ri, oki, c) for ri, oki in zip(r.reshape(shape), ok.reshape(shape))])

    def solve(self, mu: Array | None, rigid: Array, lo: Array, hi: Array, c: float | None
              ) -> tuple[Array | None, Array, float]:
        """Levenberg-damped Gauss-Newton from (mu, rigid); returns (mu, rigid, Tukey threshold used last)."""
        cfg = self.cfg
        free = np.zeros(0, np.int64) if mu is None else np.flatnonzero(hi > lo)
        mu = None if mu is None else mu.copy()
        rigid = rigid.copy()
        lam = 1e-3
        thr = c if c is not None else TUKEY * cfg.radius
        for _ in range(cfg.iterations):
            r, ok, J = self.residuals(mu, rigid, jac=True)
            assert J is not None
            rr = r[ok]
            if len(rr) < cfg.min_points:
                break
            if c is None:
                thr = TUKEY * max(1.4826 * float(np.median(np.abs(rr - np.median(rr)))), cfg.min_sigma)
            n_mu = 0 if mu is None else len(mu)
            cols = np.r_[free, np.arange(n_mu, n_mu + N_RIGID) if cfg.rigid else np.zeros(0, np.int64)].astype(np.int64)
            if not len(cols):
                break
            Jf = J[:, cols]
            q = (rr / thr) ** 2
            w = np.where(q < 1.0, (1.0 - q) ** 2, 0.0)
            H = Jf.T @ (Jf * w[:, None])
            g = Jf.T @ (w * rr)
            damp = np.maximum(np.diag(H).copy(), 1e-12)  # before the spring: it must not damp the free directions
            if cfg.rigid and self.hold is not None:  # a stiff spring along the held direction
                k = len(free)
                stiff = 1e6 * max(float(np.trace(H)) / len(H), 1e-12)
                H[k:k + 3, k:k + 3] += stiff * np.outer(self.hold, self.hold)
                g[k:k + 3] += stiff * self.hold * float(self.hold @ rigid[:3])
            c0 = self._mean_cost(r, ok, thr)  # the residuals just computed are at (mu, rigid)
            improved = False
            for _try in range(5):
                try:
                    step = -np.linalg.solve(H + lam * np.diag(damp), g)
                except np.linalg.LinAlgError:
                    lam *= 10
                    continue
                mu_t = None if mu is None else mu.copy()
                if mu_t is not None and len(free):
                    mu_t[free] = np.clip(mu_t[free] + step[:len(free)], lo[free], hi[free])
                rig_t = rigid.copy()
                if cfg.rigid:
                    rig_t += step[len(free):]
                c1 = self.cost(mu_t, rig_t, thr)
                if c1 < c0:
                    improved = c0 - c1 > 1e-4 * c0
                    mu, rigid = mu_t, rig_t
                    lam = max(lam / 3, 1e-8)
                    break
                lam *= 4
            if not improved:
                break
        return mu, rigid, thr


def extent(model: ReducedModel, lo: Array, hi: Array, per_axis: int = 5, n_modes: int | None = None
           ) -> tuple[Array, Array]:
    """The box (object frame) the model's surface can occupy over mu's box: the rest shape and the deformed ones
    on a grid of ``per_axis`` values per free parameter (at most 3 of them searched)."""
    V = np.asarray(model.points, np.float64)
    nodes = np.unique(model.surface) if len(model.surface) else np.arange(len(V))
    view = model.deformation_view(nodes, n_modes)
    free = np.flatnonzero(hi > lo)[:3]
    axes = [np.linspace(lo[i], hi[i], per_axis) for i in free]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(free)) if len(free) else \
        np.zeros((1, 0))
    bmin, bmax = V[nodes].min(axis=0), V[nodes].max(axis=0)
    for g in grid:
        mu = lo.copy()
        mu[free] = g
        X = V[nodes] + view.field.evaluate(mu)
        bmin, bmax = np.minimum(bmin, X.min(axis=0)), np.maximum(bmax, X.max(axis=0))
    return bmin, bmax


def crop(cloud: Array, model: ReducedModel, T_map_obj: Array, cfg: DepthStateConfig,
         box: tuple[Array, Array] | None = None, bend: Array | None = None) -> Array:
    """The measured points in ``box`` (object frame; None: the rest shape's) grown by ``margin``, less the band
    above the underside, in the object frame: the rest shape's underside, or with ``bend`` (a displacement of the
    model's nodes) the bent one, each point against the underside node nearest it across the object (where the
    underside does not move, at a support, the rule is the rest shape's). A box that holds every shape the model
    can take and no more keeps a support's face beside the object out (a clamp block's top face drew a cantilever
    14 mm along its axis on development seed 11)."""
    q = G.transform(G.inv(np.asarray(T_map_obj, np.float64)), np.asarray(cloud, np.float64).reshape(-1, 3))
    V = np.asarray(model.points, np.float64)
    b_lo, b_hi = box if box is not None else (V.min(axis=0), V.max(axis=0))
    # a NaN coordinate fails both comparisons and an infinite one fails one: no separate test of finiteness
    q = q[np.all((q > b_lo - cfg.margin) & (q < b_hi + cfg.margin), axis=1)]
    floor: Array | float = V[:, 2].min()
    if bend is not None:
        under = np.flatnonzero(V[:, 2] <= V[:, 2].min() + 1e-9)
        sag = np.asarray(bend, np.float64)[under]
        if len(under) and len(q) and np.any(sag[:, 2] != 0.0):
            _, k = cKDTree(V[under, :2] + sag[:, :2]).query(q[:, :2])
            floor = V[:, 2].min() + sag[k, 2]
    out: Array = q[q[:, 2] > floor + cfg.band]
    return out


def _weak_direction(surf: _Surface, q: Array, cfg: DepthStateConfig) -> Array | None:
    """The direction no matched face holds (the axis of a prism whose end faces are a few noisy pixels), or None:
    the smallest eigenvector of the matched normals' scatter where its eigenvalue is under ``slide_ratio`` of the
    largest. The translation along it is not fitted: a bent cantilever slid along its axis with the load moved
    the same way fits its depth almost as well (6 mm on development seeds 10, 11, 18 where the registration's
    cover of the faces had it within 3 mm); the pose given (a registration pins that slide by its cover) holds
    it."""
    d, k = cast(tuple[Array, NDArray[np.int64]], surf.rest_tree.query(q, distance_upper_bound=cfg.radius))
    ok = np.isfinite(d)
    if ok.sum() < cfg.min_points:
        return None
    n = surf.n[k[ok]]
    w, V = np.linalg.eigh(n.T @ n)
    return V[:, 0].copy() if w[0] < cfg.slide_ratio * w[2] else None


def fit_state(cloud: Array, model: ReducedModel, T_map_obj: Array, lo: Array, hi: Array,
              mu0: Array | None = None, cfg: DepthStateConfig | None = None,
              n_modes: int | None = None) -> DepthState:
    """Fit the model's deformation (and an upright rigid correction) to ``cloud`` (map frame, (N, 3): a depth
    image back-projected, see :func:`registration.depth_cloud`). ``lo`` / ``hi``: mu's box (lo == hi: held at
    ``mu0``'s value). With ``cfg.turn_steps``, the turn about the z axis searched over the circle
    (:func:`_searched_turn`). See the module docstring.

    The crop drops the band above the rest shape's underside (where the supports meet it). A loaded beam that sags
    by more than the band loses its lower faces there, where it bends most: a cantilever's tip, the points that
    tell its load (held-out seed 1018's first views, fitted in the true pose: 3085 points, its load 4.9 % of the
    range off; 4944 points and 0.05 % with the band over the bent underside). So where the fit is deformed and
    the band over its bent underside keeps other points, the state is fitted again on those, from the first fit's
    mu; the second fit stands where it is deformed too. (Its rest fit, on the same points, meets the lower faces kept
    only for the bent band as outliers, so the second fit is nearly always judged deformed: the first fit's verdict
    is the one that decides whether the object is loaded.)"""
    cfg = cfg or DepthStateConfig()
    st = _fit_state(cloud, model, T_map_obj, lo, hi, mu0, cfg, n_modes, None)
    if st.mu is None or cfg.turn_steps:  # a body of revolution (the boot) is clamped by its base, which does not move
        return st
    bend = model.deformation_view(None, n_modes).field.evaluate(st.mu)
    box = extent(model, np.asarray(lo, np.float64), np.asarray(hi, np.float64), n_modes=n_modes)
    T = np.asarray(T_map_obj, np.float64)
    if np.array_equal(crop(cloud, model, T, cfg, box, bend), crop(cloud, model, T, cfg, box)):
        return st
    again = _fit_state(cloud, model, T, lo, hi, st.mu, cfg, n_modes, bend)
    return again if again.deformed else st


def _fit_state(cloud: Array, model: ReducedModel, T_map_obj: Array, lo: Array, hi: Array, mu0: Array | None,
               cfg: DepthStateConfig, n_modes: int | None, bend: Array | None) -> DepthState:
    """:func:`fit_state` on the cloud cropped with the band over the underside bent by ``bend`` (None: the rest
    shape's, :func:`crop`)."""
    T = np.asarray(T_map_obj, np.float64)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    mu_start = np.clip(0.5 * (lo + hi) if mu0 is None else np.asarray(mu0, np.float64), lo, hi)
    q = crop(cloud, model, T, cfg, extent(model, lo, hi, n_modes=n_modes), bend)
    nan = float("nan")
    if len(q) < cfg.min_points:
        return DepthState(None, T, None, nan, nan, 0.0, len(q), nan,
                          f"only {len(q)} depth points on the object (need {cfg.min_points})")
    surf = _Surface(model, cfg, n_modes)
    prob = _Problem(surf, q, cfg, _weak_direction(surf, q, cfg))
    zero = np.zeros(N_RIGID)
    # the rest fit first: its robust scale is the yardstick of both costs
    _, rig0, thr = prob.solve(None, zero, lo, hi, None)
    _, rig0, thr = prob.solve(None, rig0, lo, hi, thr)
    rest_cost = prob.cost(None, rig0, thr)
    # the deformed fit: coarse search over the free parameters, then Gauss-Newton; from the given pose and from
    # the rest fit's (the rest shape fitted to a bent cantilever slides it along its axis to split the misfit, a
    # basin the deformed fit may not leave: development seed 11, 14 mm), the lower cost kept
    free = np.flatnonzero(hi > lo)
    mu, rig, cost = mu_start, zero, np.inf
    for r_start in ([zero, rig0] if cfg.rigid else [zero]):
        best_mu, best_c = mu_start, prob.cost(mu_start, r_start, thr)
        if 0 < len(free) <= 3:  # more free parameters: Gauss-Newton from the start alone (the grid grows as 2^n)
            per = max(2, round(cfg.grid ** (1.0 / len(free))))
            axes = [np.linspace(lo[i], hi[i], per) for i in free]
            for cand in np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(free)):
                m = mu_start.copy()
                m[free] = cand
                cst = prob.cost(m, r_start, thr)
                if cst < best_c:
                    best_mu, best_c = m, cst
        mu_t, rig_t, _ = prob.solve(best_mu, r_start, lo, hi, thr)
        assert mu_t is not None
        c_t = prob.cost(mu_t, rig_t, thr)
        if c_t < cost:
            mu, rig, cost = mu_t, rig_t, c_t
    held = float("inf")
    if cfg.turn_steps and cfg.rigid and len(free):
        mu, rig, cost = _searched_turn(prob, mu, rig, cost, lo, hi, thr, cfg.turn_steps)
        held = _turn_held(prob, mu, rig)
    motion = _motion(prob, mu, rig)
    T_fit = T @ G.make_T(G.rot_axis("z", rig[3]), surf.c - G.rot_axis("z", rig[3]) @ surf.c + rig[:3])
    T_rest = T @ G.make_T(G.rot_axis("z", rig0[3]), surf.c - G.rot_axis("z", rig0[3]) @ surf.c + rig0[:3])
    gain = 1.0 - cost / rest_cost if rest_cost > 0 else 0.0
    sigma = thr / TUKEY
    what = (f"depth: deformed fit {gain:+.0%} on the rest shape's cost, surface moved {1e3 * motion:.1f} mm "
            f"(90th percentile), {len(q)} points, sigma {1e3 * sigma:.1f} mm")
    if gain >= cfg.min_gain and motion >= cfg.min_motion:
        return DepthState(mu, T_fit, mu, cost, rest_cost, motion, len(q), sigma, what, rig.copy(), held)
    return DepthState(None, T_rest, mu, cost, rest_cost, motion, len(q), sigma, "at rest: " + what, rig0.copy())


def held_gains(cloud: Array, model: ReducedModel, T_map_obj: Array, lo: Array, hi: Array,
               states: list[Array], cfg: DepthStateConfig | None = None, n_modes: int | None = None) -> Array:
    """How much each of ``states`` lowers the rest shape's cost on ``cloud`` (map frame): ``1 - cost / rest_cost``
    per state, each held (its upright rigid correction a nuisance, fitted from none and from the rest fit's, the
    lower cost kept), all on the same points (cropped by the rest rule, :func:`crop`, around every shape ``lo`` ..
    ``hi`` lets the model take) and at the rest fit's robust scale; NaN for each where too few points are left or
    the rest fit costs nothing.
    States compared on equal terms: :func:`fit_state`'s own gain may come from its second fit's points (the band over
    the fitted state's bent underside), on their own scale, so two fits' gains are not comparable."""
    cfg = cfg or DepthStateConfig()
    T = np.asarray(T_map_obj, np.float64)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    q = crop(cloud, model, T, cfg, extent(model, lo, hi, n_modes=n_modes))
    if len(q) < cfg.min_points:
        return np.full(len(states), np.nan)
    surf = _Surface(model, cfg, n_modes)
    prob = _Problem(surf, q, cfg, _weak_direction(surf, q, cfg))
    zero = np.zeros(N_RIGID)
    _, rig0, thr = prob.solve(None, zero, lo, hi, None)
    _, rig0, thr = prob.solve(None, rig0, lo, hi, thr)
    rest_cost = prob.cost(None, rig0, thr)
    if not rest_cost > 0:
        return np.full(len(states), np.nan)
    out = []
    for mu in states:
        m = np.clip(np.asarray(mu, np.float64), lo, hi)
        cost = np.inf
        for r_start in ([zero, rig0] if cfg.rigid else [zero]):
            m_t, rig_t, _ = prob.solve(m, r_start, m, m, thr)
            cost = min(cost, prob.cost(m_t, rig_t, thr))
        out.append(1.0 - cost / rest_cost)
    return np.array(out)


def _motion(prob: _Problem, mu: Array, rig: Array) -> float:
    """The 90th percentile of the displacement |u(mu)| over the samples the measured points meet (m)."""
    _, _, k_all, ok = prob._associate(mu, rig)
    k = k_all[ok]
    u = prob.s.view.field.evaluate(mu)
    return float(np.percentile(np.linalg.norm(u[np.unique(k)], axis=1), 90)) if len(k) else 0.0


TURN_HELD = 0.5  # a fitted shape holds its turn where its turn's deviation is under this share of the rest shape's
# the turns a body of revolution's deformed fit searches over the circle (DepthStateConfig.turn_steps) where a caller
# asks for the search: 15 degrees apart, then quarter steps about the best, so that the Gauss-Newton starts within
# about 2 degrees of the best turn (its basin on the boot: a few degrees, :func:`_searched_turn`)
TURN_STEPS = 24
TURN_POINTS = 800  # the turn search ranks its candidates on at most this many measured points (evenly taken)
TURN_SHIFT = 0.002  # m: the turn search also starts from the pose as given where the fit moved it farther than this


def _searched_turn(prob: _Problem, mu: Array, rig: Array, cost: float, lo: Array, hi: Array, thr: float,
                   steps: int) -> tuple[Array, Array, float]:
    """The deformed fit (mu, rig) of a body of revolution searched over its turn psi about its axis. A coarse search
    ranks ``steps`` turns over the whole circle, each with the fit's mu and, for one free parameter, with 5 more
    values over its range, at the fit's translation and, where that is over TURN_SHIFT off, at the pose's as given
    (the rigid fit of a registration drags a round rest shape towards a bent lever: 18 mm in a test); about the best
    of each translation, quarter, half and three-quarter steps either side; Gauss-Newton from the best of those, one
    start per translation. The ranking runs on at most TURN_POINTS of the measured points, with one search tree per
    state for all its turns (:meth:`_Problem.turn_costs`; stop 106: a tree per candidate before, the search 0.45 s of
    CPU on the boot's test image then, 0.18 s now), the rest on all of them. Returns the best fit and its cost where
    it costs less than ``cost`` and its shape holds its turn (the turn's deviation under TURN_HELD of the rest shape's
    on the same points, as :class:`DepthFollower` judges it: a bellows barely bent holds none, and a search would pick
    a turn by the noise); else (mu, rig, cost) as given.

    Why (stop 105): the Gauss-Newton's turn has a basin of a few degrees. The bent bellows holds the turn, but its
    round part gives most of the points and their re-association makes the cost bumpy: on the model's own depth image
    of the boot bent 0.6 rad, turned 25 degrees, the fit from 20 degrees stopped there (cost 2.3 times the true
    turn's) and the fit from no turn stopped at 20; turned 120 degrees, the fit from no turn found no deformation."""
    free = np.flatnonzero(hi > lo)
    mus = [mu]
    if len(free) == 1:
        for v in np.linspace(lo[free[0]], hi[free[0]], 6)[1:]:  # the first is the range's end, at rest for a lever
            m = mu.copy()
            m[free[0]] = v
            mus.append(m)
    every = -(-len(prob.q) // TURN_POINTS)
    rank = prob if every == 1 else _Problem(prob.s, prob.q[::every], prob.cfg, prob.hold)
    step = 2 * np.pi / steps
    psis = rig[3] + step * np.arange(steps)
    shifts = [rig[:3]] + ([np.zeros(3)] if np.linalg.norm(rig[:3]) > TURN_SHIFT else [])
    best = (mu, rig, cost)
    for t in shifts:
        costs = np.array([rank.turn_costs(m, t, psis, thr) for m in mus])
        k, j = np.unravel_index(int(np.argmin(costs)), costs.shape)
        m0, psi0 = mus[int(k)], float(psis[j])
        cand = psi0 + step * np.array([0.0, -0.75, -0.5, -0.25, 0.25, 0.5, 0.75])
        fine = [float(costs[k, j])] + list(rank.turn_costs(m0, t, cand[1:], thr))
        psi = float(np.angle(np.exp(1j * cand[int(np.argmin(fine))])))  # in (-pi, pi]
        mu_t, rig_t, _ = prob.solve(m0, np.r_[t, psi], lo, hi, thr)
        assert mu_t is not None
        c_t = prob.cost(mu_t, rig_t, thr)
        if c_t < best[2]:
            best = (mu_t, rig_t, c_t)
    if best[2] >= cost or not _turn_held(prob, best[0], best[1]) < TURN_HELD:
        return mu, rig, cost
    return best


def _turn_held(prob: _Problem, mu: Array, rig: Array) -> float:
    """How well the shape at (mu, rig) holds its turn: the turn's standard deviation on it over the rest shape's on the
    same points (:attr:`DepthFit.turn_held`; inf where either is not finite: a shape that holds no turn, or a rest
    shape that meets none of the points, leaves nothing to compare)."""
    held, rest = prob.turn_std(mu, rig), prob.turn_std(None, rig)
    return held / rest if np.isfinite(held) and np.isfinite(rest) and rest > 0 else float("inf")


@dataclass
class DepthFit:
    """One frame's state read from depth by :class:`DepthFollower`. ``mu``: the fitted state (None: no sound fit this
    frame, ``reason`` says why); ``points``: measured points on the object; ``inliers``: their share within the
    Tukey threshold; ``sigma``: the robust residual scale (m); ``turn``: the fit's turn psi about the object's z axis
    (rad, on the pose given); ``turn_held``: how well the fitted shape holds that turn, as the ratio of its standard
    deviation to the rest shape's on the same points (about 1 for a body of revolution at rest, smaller the more its
    bend shows the turn; inf: not computed)."""

    mu: Array | None
    points: int
    inliers: float
    sigma: float
    reason: str
    turn: float = 0.0
    turn_held: float = float("inf")


class DepthFollower:
    """The state measured from every depth image (``tracking.depth_fit``): the non-rigid point-to-plane fit of
    :func:`fit_state` (same samples, Tukey cost, upright rigid correction; the crop's band over the rest underside
    only, not :func:`fit_state`'s second pass over a bent one), warm-started frame to frame.

    Why (issue 16, the joint boot): the sparse tracker's measurements are ORB map points followed by optical flow and
    re-acquired by descriptor on a faint, deforming speckle. Labelled against the independent truth
    (``benchmarks/boot_measurements.py``), most re-acquisitions on the bent boot and many flow tracks sit pixels away
    from the material point their link claims, and on stop 70's code 11 of the 14 development scenes (seeds 0-39)
    worse than 2 % read the lever low. The depth image measures the surface's shape with no matching at all. Per
    frame: Gauss-Newton from the image fit's state and, where it differs by more than 1 %
    of the range, from the last depth state too (the lever jumps between frames; one start alone stalled at the old
    angle on development seed 1); the lower cost is kept. The rigid correction (drift of the camera against the
    registered pose, a turn the image fit's alpha_z missed) carries over to the next frame. No rest fit and no coarse
    grid: the fit follows the state, it does not find it."""

    def __init__(self, model: ReducedModel, cfg: DepthStateConfig, n_modes: int | None, lo: Array,
                 hi: Array) -> None:
        self.model, self.cfg = model, cfg
        self.surf = _Surface(model, cfg, n_modes)
        self.box = extent(model, np.asarray(lo, np.float64), np.asarray(hi, np.float64), n_modes=n_modes)
        self.rigid = np.zeros(N_RIGID)
        self.mu: Array | None = None
        self.min_inliers = 0.5  # a fit that explains fewer of the object's points is not taken
        # the rigid correction's turn (about the model's centroid) is a turn about the object's z axis: a body of
        # revolution about it, such as the boot, whose alpha_z it then corrects (DeformableTracker.depth_turn)
        self.turns_about_axis = bool(np.hypot(*self.surf.c[:2]) < 1e-3)
        # a body of revolution shows that turn only while it is bent; a fit of the round shape lets it drift. A fit
        # holds its turn where the turn's standard deviation on the fitted shape is under turn_ratio_max of what the
        # rest shape gives on the same points (the same pose, unit residuals): the ratio, not the deviation itself,
        # so that it does not depend on how many points the camera sees (DepthFit.turn_held)
        self.turn_ratio_max = TURN_HELD
        self.judge_turn = True  # False: turn_held is not computed (its rest-shape search costs a KD-tree a frame)

    def corners(self, T_map_obj: Array) -> Array:
        """The corners (map frame, (8, 3)) of the box that :meth:`fit` crops the cloud to with the object at
        ``T_map_obj``: what :func:`.registration.depth_cloud` needs to back-project only the pixels that may hold
        it (``within``)."""
        b_lo, b_hi = self.box[0] - self.cfg.margin, self.box[1] + self.cfg.margin
        c = np.array([[(b_lo, b_hi)[i >> a & 1][a] for a in range(3)] for i in range(8)])
        return G.transform(np.asarray(T_map_obj, np.float64), c)

    def fit(self, cloud: Array, T_map_obj: Array, lo: Array, hi: Array, mu_image: Array) -> DepthFit:
        """The state in this depth ``cloud`` (map frame) with the object at ``T_map_obj``, mu in [lo, hi], starting
        from ``mu_image`` (the image fit's) and the last depth state."""
        cfg, nan = self.cfg, float("nan")
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        q = crop(cloud, self.model, np.asarray(T_map_obj, np.float64), cfg, self.box)
        if len(q) < cfg.min_points:
            return DepthFit(None, len(q), 0.0, nan, f"only {len(q)} depth points on the object (need "
                                                     f"{cfg.min_points})")
        prob = _Problem(self.surf, q, cfg, _weak_direction(self.surf, q, cfg))
        starts = [np.clip(np.asarray(mu_image, np.float64), lo, hi)]
        span = np.maximum(hi - lo, 1e-12)
        if self.mu is not None and np.max(np.abs(self.mu - starts[0]) / span) > 0.01:
            starts.append(np.clip(self.mu, lo, hi))
        fits = [prob.solve(m0, self.rigid, lo, hi, None) for m0 in starts]
        thr = max(f[2] for f in fits)  # one yardstick for both
        mu, rig, _ = min(fits, key=lambda f: prob.cost(f[0], f[1], thr))
        assert mu is not None
        r, ok, _ = prob.residuals(mu, rig)
        inl = float(np.mean(ok & (np.abs(np.nan_to_num(r, nan=np.inf)) < thr))) if len(r) else 0.0
        sigma = thr / TUKEY
        if inl < self.min_inliers:
            return DepthFit(None, len(q), inl, sigma, f"the depth fit explains {100 * inl:.0f} % of the object's "
                                                      f"{len(q)} depth points (need {100 * self.min_inliers:.0f} %)")
        self.mu, self.rigid = mu.copy(), rig.copy()
        turn_held = _turn_held(prob, mu, rig) if self.turns_about_axis and self.judge_turn else float("inf")
        return DepthFit(mu, len(q), inl, sigma, f"depth: {len(q)} points, {100 * inl:.0f} % within the threshold, "
                                                f"sigma {1e3 * sigma:.1f} mm", float(rig[3]), turn_held)
