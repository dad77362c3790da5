"""Independent contact truth (issue 21): a full-order finite-element contact solve of a rigid probe pressing
linear-elastic bodies, and of one body pressing another.

The probe scenes used to take their "truth" from the very :class:`~simreal_nodes.collision.contact.ContactTracker`
(Alg. 5.1) being scored, run on perfect probe points: agreement then measured depth noise only. Here the truth
is the Signorini problem of linear elasticity, solved on its own mesh (quadratic tetrahedra on a grid finer than
the reduced model's hexahedra), with nothing from the reduced model:

- bodies: :class:`~simreal_nodes.physics.fem.Solid` (scikit-fem), small strain, their own supports;
- contact: node-to-surface non-penetration of the candidate surface nodes, measured along the push direction
  ``n`` (unit, into the body). A node at coordinate ``t_i = X_i . n`` with displacement ``d_i = u_i . n`` must
  stay ahead of a sphere of radius ``R`` centred at ``c``: ``g_i = t_i + d_i - c.n - sqrt(R^2 - r_i^2) >= 0``
  (``r_i``: the node's distance from the probe axis); between two bodies, a node pair at the same place across
  the interface must not interpenetrate;
- the contact forces ``lambda >= 0`` act along ``n`` on the nodes; the gaps are affine in them through the
  bodies' compliance condensed on the candidate nodes (the Delassus operator ``M``): ``g = g0 + M lambda``;
- ``lambda`` solves the linear complementarity problem ``lambda >= 0, g >= 0, lambda . g = 0``, which for a
  symmetric positive definite ``M`` is the convex QP ``min 1/2 lambda' M lambda + g0' lambda, lambda >= 0``,
  solved exactly as a non-negative least-squares problem on the Cholesky factor of ``M`` (scipy ``nnls``).

The contact is frictionless and the normal is the push direction for every node (small slip, small rotation:
the scenes press a few millimetres on a 300 mm beam). The full-order displacement anywhere is
``u = X lambda`` with ``X`` the unit responses, solved once per body (one factorisation, one column per
candidate node).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np
import scipy.linalg as sla
import scipy.optimize as so
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from simreal_nodes.errors import FemError
from simreal_nodes.physics import fem, materials, meshes


@dataclass
class CondensedBody:
    """A linear-elastic body condensed on a set of candidate contact nodes (object frame of the body).

    ``cand``: (n_c, 3) reference positions of the candidate nodes, each loaded along the condensation's direction;
    ``X``: (n_obs * 3, n_c) displacement of the observed nodes ``obs`` (n_obs, 3)
    per newton at each candidate; ``C``: (n_c, n_c) the compliance between candidates along their directions."""

    cand: np.ndarray
    obs: np.ndarray
    X: np.ndarray
    C: np.ndarray
    info: dict = field(default_factory=dict)

    def displacement(self, forces: np.ndarray) -> np.ndarray:
        """(n_obs, 3) displacement of the observed nodes under candidate forces (n_c,) newtons."""
        return (self.X @ np.asarray(forces, dtype=np.float64)).reshape(-1, 3)


def beam_solid(length: float, width: float, height: float, material: materials.Material, supports: list[dict],
               cells: tuple[int, int, int], order: int = 2) -> fem.Solid:
    """The full-order beam: P2 tetrahedra on a box grid (the reduced models use hexahedra)."""
    return fem.Solid(meshes.box(length, width, height, cells, "tet"), material, order, supports)


def condense(solid: fem.Solid, cand_select, direction, obs: np.ndarray, tol: float = 1e-7) -> CondensedBody:
    """Unit responses of ``solid`` to a force along ``direction`` at each node chosen by ``cand_select``
    ((n, 3) node positions -> bool mask), observed at the nodes placed at ``obs`` (n_obs, 3; each must coincide
    with a node of the solid within ``tol`` metres)."""
    nodes = solid.basis.doflocs[:, ::3].T  # dofs are interleaved per node: node k owns 3k, 3k+1, 3k+2
    if solid.dim != 3 or nodes.shape[0] * 3 != solid.N:
        raise FemError("contact truth needs a 3D vector basis with interleaved dofs")
    ci = np.flatnonzero(cand_select(nodes))
    if len(ci) == 0:
        raise FemError("no candidate contact node in the selected region")
    n = np.asarray(direction, dtype=np.float64)
    n = n / np.linalg.norm(n)
    d, oi = cast(tuple[np.ndarray, np.ndarray], cKDTree(nodes).query(np.asarray(obs, dtype=np.float64).reshape(-1, 3)))
    if np.max(d, initial=0.0) > tol:
        raise FemError(f"an observed point is {1e3 * float(np.max(d)):.3f} mm from every truth node: the truth grid "
                       "must contain the observed points")
    rows_obs = (3 * oi[:, None] + np.arange(3)[None, :]).ravel()
    rows_c = (3 * ci[:, None] + np.arange(3)[None, :]).ravel()
    free = solid.free
    lu = spla.splu(solid.stiffness()[free][:, free].tocsc(), permc_spec="MMD_AT_PLUS_A")
    X = np.zeros((len(rows_obs), len(ci)))
    Uc = np.zeros((len(rows_c), len(ci)))
    for j0 in range(0, len(ci), 64):  # unit loads in chunks: memory bounded by 64 full-order columns
        js = np.arange(j0, min(j0 + 64, len(ci)))
        F = np.zeros((solid.N, len(js)))
        for col, j in enumerate(js):
            F[3 * ci[j]:3 * ci[j] + 3, col] = n
        U = np.zeros((solid.N, len(js)))
        U[free] = lu.solve(F[free] / solid.material.E)  # the stiffness is in units of E (fem.Solid)
        if not np.all(np.isfinite(U)):
            raise FemError("the contact truth's unit solves returned NaN/inf")
        X[:, js] = U[rows_obs]
        Uc[:, js] = U[rows_c]
    C = np.einsum("c,icj->ij", n, Uc.reshape(len(ci), 3, len(ci)))
    C = 0.5 * (C + C.T)  # Maxwell-Betti: symmetric up to round-off
    return CondensedBody(nodes[ci], np.asarray(obs, dtype=np.float64).reshape(-1, 3), X, C,
                         info={"dofs": int(solid.N), "candidates": len(ci)})


def solve_lcp(M: np.ndarray, g0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """lambda >= 0 with g = g0 + M lambda >= 0 and lambda . g = 0, for symmetric positive definite M (the QP
    min 1/2 l'Ml + g0'l, l >= 0 = min |L'l + L^-1 g0|^2 with M = LL'). Returns (lambda, g)."""
    g0 = np.asarray(g0, dtype=np.float64)
    lam = np.zeros(len(g0))
    if len(g0) == 0 or np.all(g0 >= 0):
        return lam, g0.copy()
    # only the candidates that could ever touch matter to the solution's support; the QP is solved on all of
    # them (a node far from the probe stays at zero force by complementarity)
    reg = 1e-12 * float(np.trace(M)) / len(g0)
    L = sla.cholesky(M + reg * np.eye(len(g0)), lower=True)
    b = -sla.solve_triangular(L, g0, lower=True)
    lam, _ = so.nnls(L.T, b, maxiter=50 * len(g0))
    g = g0 + M @ lam
    return lam, g


@dataclass
class ProbeContact:
    """One frame of the truth. Per body ("a": the probed one, "b": the one it presses): the contact forces on its
    candidate nodes (newtons, along the push direction), their total, their centroid (the body's frame), and the
    observed nodes' displacement; ``min_gap``: the smallest probe-to-a gap after the solve (0 in contact)."""

    forces: dict[str, np.ndarray]
    total: dict[str, float]
    centroid: dict[str, np.ndarray]
    min_gap: float
    displacement: dict[str, np.ndarray]

    def in_contact(self, body: str, min_force: float = 1e-3) -> bool:
        return self.total.get(body, 0.0) > min_force


class SphereOnBodies:
    """A rigid sphere of ``radius`` pressing body ``a`` along ``direction`` (a's frame, into a), and optionally
    ``a`` pressing body ``b`` through node pairs facing each other across their interface.

    ``probe``: indices of a's candidates the sphere can touch; ``pairs``: (n_p, 2) indices (into a's candidates,
    into b's) of facing nodes, ``pair_gap0``: their gaps at rest (metres). Every force acts along the push
    direction, which must be the same in both bodies' frames (the crossed beams are turned about it). The
    unknowns are the probe forces p on a and the pair forces q (pushing b on and a back):

        g_probe = g0_probe + C_a[P, P] p - C_a[P, A] q
        g_pair  = g0_pair  - C_a[A, P] p + (C_a[A, A] + C_b[B, B]) q
    """

    def __init__(self, a: CondensedBody, probe: np.ndarray, radius: float, direction,
                 b: CondensedBody | None = None, pairs: np.ndarray | None = None, pair_gap0: np.ndarray | None = None):
        self.a, self.b = a, b
        self.probe = np.asarray(probe, np.int64)
        self.R = float(radius)
        n = np.asarray(direction, dtype=np.float64)
        self.n = n / np.linalg.norm(n)
        self.pairs = np.zeros((0, 2), np.int64) if pairs is None else np.asarray(pairs, np.int64).reshape(-1, 2)
        self.pair_gap0 = np.zeros(len(self.pairs)) if pair_gap0 is None else np.asarray(pair_gap0, np.float64)
        if len(self.pairs) and b is None:
            raise ValueError("contact pairs need the pressed body b")
        P, A = self.probe, self.pairs[:, 0]
        n_p, n_q = len(P), len(A)
        M = np.zeros((n_p + n_q, n_p + n_q))
        M[:n_p, :n_p] = a.C[np.ix_(P, P)]
        if n_q and b is not None:
            B = self.pairs[:, 1]
            M[:n_p, n_p:] = -a.C[np.ix_(P, A)]
            M[n_p:, :n_p] = -a.C[np.ix_(A, P)]
            M[n_p:, n_p:] = a.C[np.ix_(A, A)] + b.C[np.ix_(B, B)]
        self.M = 0.5 * (M + M.T)
        self.description = ""

    def probe_gaps(self, center) -> np.ndarray:
        """Gaps of a's probe candidates to the sphere at ``center`` (a's frame), before any deformation."""
        c = np.asarray(center, dtype=np.float64)
        X = self.a.cand[self.probe] - c
        t = X @ self.n
        r2 = np.sum(X ** 2, axis=1) - t ** 2
        g = np.full(len(X), 1.0)  # beside the sphere's shadow along n a node cannot be touched
        under = r2 < self.R ** 2
        g[under] = t[under] - np.sqrt(self.R ** 2 - r2[under])
        return g

    def solve(self, center) -> ProbeContact:
        g0 = np.concatenate([self.probe_gaps(center), self.pair_gap0])
        lam, g = solve_lcp(self.M, g0)
        n_p = len(self.probe)
        fa = np.zeros(len(self.a.cand))
        fa[self.probe] += lam[:n_p]
        p_only = fa.copy()
        out_f, total, cen, disp = {}, {}, {}, {}
        if len(self.pairs) and self.b is not None:
            q = lam[n_p:]
            np.subtract.at(fa, self.pairs[:, 0], q)
            fb = np.zeros(len(self.b.cand))
            np.add.at(fb, self.pairs[:, 1], q)
            out_f["b"], total["b"] = fb, float(q.sum())
            cen["b"] = (fb @ self.b.cand) / fb.sum() if fb.sum() > 0 else np.full(3, np.nan)
            disp["b"] = self.b.displacement(fb)
        out_f["a"], total["a"] = p_only, float(p_only.sum())
        cen["a"] = (p_only @ self.a.cand) / p_only.sum() if p_only.sum() > 0 else np.full(3, np.nan)
        disp["a"] = self.a.displacement(fa)
        return ProbeContact(out_f, total, cen, float(np.min(g[:n_p])) if n_p else np.inf, disp)


def crossed_beams_truth(model, press_point, T_ab: np.ndarray, radius: float, cells=(60, 6, 4),
                        order: int = 2) -> SphereOnBodies:
    """The full-order truth of the crossed-beams probe scene (thesis §5.4.1): beam a pressed by a sphere of
    ``radius`` at ``press_point`` (a's frame, on its top face), pressing beam b through their crossing. Both beams
    are the physical beam the reduced ``model`` describes (its box, material and supports; nothing else of the
    model is used). ``T_ab``: b's frame in a's frame, turned about z only (the push direction, -z, is then the
    same in both). One condensation serves both beams: they share geometry and supports, and the candidates of
    a (under the probe, a's bottom over b) and of b (its top under a) are distinct nodes of the same body; the
    displacements are observed at the model's nodes (``displacement['a']``, ``['b']``, each beam's frame)."""
    P = np.asarray(model.points, dtype=np.float64)
    lo, hi = P.min(axis=0), P.max(axis=0)
    if np.max(np.abs(lo)) > 1e-9:
        raise FemError("the crossed-beams truth expects the beam's box to start at the object origin")
    L, W, H = (float(v) for v in hi)
    mat = materials.make_material(model.material["law"], model.material["E"], model.material["nu"])
    sup = [{k: v for k, v in bc.items() if v is not None} for bc in model.boundary_conditions]
    solid = beam_solid(L, W, H, mat, sup, tuple(cells), order)
    T_ab = np.asarray(T_ab, dtype=np.float64)
    T_ba = np.linalg.inv(T_ab)
    c = np.asarray(press_point, dtype=np.float64)
    eps = 1e-7

    def in_box(Q):
        return np.all((Q[:, :2] >= lo[:2] - eps) & (Q[:, :2] <= hi[:2] + eps), axis=1)

    def select(X):
        probe = (np.abs(X[:, 2] - H) < eps) & (np.hypot(X[:, 0] - c[0], X[:, 1] - c[1]) < radius + 1e-3)
        a_bottom = (np.abs(X[:, 2]) < eps) & in_box(X @ T_ba[:3, :3].T + T_ba[:3, 3])  # a's bottom above b
        b_top = (np.abs(X[:, 2] - H) < eps) & in_box(X @ T_ab[:3, :3].T + T_ab[:3, 3])  # b's top under a
        return probe | a_bottom | b_top

    body = condense(solid, select, (0.0, 0.0, -1.0), P)
    X = body.cand
    probe = np.flatnonzero((np.abs(X[:, 2] - H) < eps) & (np.hypot(X[:, 0] - c[0], X[:, 1] - c[1]) < radius + 1e-3))
    a_bot = np.flatnonzero((np.abs(X[:, 2]) < eps) & in_box(X @ T_ba[:3, :3].T + T_ba[:3, 3]))
    b_top = np.flatnonzero((np.abs(X[:, 2] - H) < eps) & in_box(X @ T_ab[:3, :3].T + T_ab[:3, 3]))
    b_in_a = X[b_top] @ T_ab[:3, :3].T + T_ab[:3, 3]
    d, k = cast(tuple[np.ndarray, np.ndarray], cKDTree(b_in_a[:, :2]).query(X[a_bot, :2]))
    hit = d < 1e-6  # node pairs facing each other across the interface (both grids share the crossing's lattice)
    pairs = np.stack([a_bot[hit], b_top[k[hit]]], axis=1)
    gap0 = X[a_bot[hit], 2] - b_in_a[k[hit], 2]
    if len(pairs) and np.min(gap0) < 0:
        raise FemError("the crossed beams interpenetrate at rest")
    prob = SphereOnBodies(body, probe, radius, (0.0, 0.0, -1.0), b=body, pairs=pairs, pair_gap0=gap0)
    prob.description = (f"full-order P{order} tetrahedra {cells[0]}x{cells[1]}x{cells[2]} per beam "
                        f"({solid.N} dofs), {mat.law}, frictionless node-to-surface contact: "
                        f"{len(probe)} probe nodes, {len(pairs)} node pairs between the beams")
    return prob


# ------------------------------------------------------------------------------------------------
# Large strain: a rigid sphere pressing a hyperelastic body (the bunny and dragon probe scenes, thesis §5.4.2-3)


def embedding_matrix(solid: fem.Solid, points: np.ndarray) -> sp.csr_matrix:
    """(3 n, N) sparse map from the solid's dofs to the displacement of ``points`` (n, 3) embedded in its
    tetrahedra (barycentric weights; a point outside the mesh moves like the nearest tetrahedron's face)."""
    if solid.order != 1 or solid.dim != 3:
        raise FemError("embedding needs a 3D solid with linear tetrahedra")
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tets, w = meshes.embed_points(solid.mesh, P)
    n = len(P)
    rows = (3 * np.arange(n)[:, None, None] + np.arange(3)[None, None, :]).repeat(4, axis=1)  # (n, 4, 3)
    dofs = solid.basis.nodal_dofs[:, tets]  # (3, n, 4)
    cols = np.moveaxis(dofs, 0, -1)  # (n, 4, 3)
    vals = np.broadcast_to(w[:, :, None], (n, 4, 3))
    return sp.coo_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * n, solid.N)).tocsr()


@dataclass
class SphereState:
    """One solved probe position: the solid's dofs ``u``, the contact force on each sample (newtons, along its
    sphere normal, (n, 3)), their total, the force-weighted centroid of the touching samples (reference
    positions, body frame), and the deepest remaining penetration of a sample into the sphere (metres; the
    penalty's error)."""

    u: np.ndarray
    forces: np.ndarray
    total: np.ndarray
    centroid: np.ndarray
    penetration: float
    newton: int


class SphereOnSolid:
    """A rigid sphere of ``radius`` pressing a hyperelastic :class:`~simreal_nodes.physics.fem.Solid` (large
    strain: the solid's own law, e.g. neo-Hookean), frictionless.

    The body's surface is given by ``samples`` (n, 3), points spread over its real surface (the scan) and
    embedded in the tetrahedra (:func:`embedding_matrix`: ``x_i = X_i + (W u)_i``). Each sample inside the sphere
    (gap ``g_i = |x_i - c| - R < 0``) is pushed out along ``n_i = (x_i - c) / |x_i - c|`` by the penalty
    ``k (-g_i)``: the total potential ``W_int(u) + sum_i k/2 <-g_i>^2`` is minimised by Newton (consistent tangent
    ``k (n n' + g/|x-c| (I - n n'))`` per active sample). ``k`` is set from the penalty pressure ``beta E / h``
    (``h``: the mesh size) on each sample's share of the surface, so a sample sinks about ``p h / (beta E)``
    into the sphere under a contact pressure ``p``; :attr:`SphereState.penetration` reports it."""

    def __init__(self, solid: fem.Solid, samples: np.ndarray, radius: float, spacing: float, h: float,
                 beta: float = 1000.0):
        self.solid = solid
        self.X = np.asarray(samples, dtype=np.float64).reshape(-1, 3)
        self.R = float(radius)
        self.W = embedding_matrix(solid, self.X)
        self.Wt = self.W.T.tocsr()
        self.k = float(beta * solid.material.E * spacing ** 2 / h)
        self.E = float(solid.material.E)
        self.description = ""

    def _contact(self, u: np.ndarray, c: np.ndarray):
        x = self.X + (self.W @ u).reshape(-1, 3)
        d = x - c
        r = np.linalg.norm(d, axis=1)
        g = r - self.R
        act = np.flatnonzero(g < 0)
        n = d[act] / np.maximum(r[act], 1e-15)[:, None]
        return act, g[act], n, r[act]

    def forces(self, u: np.ndarray, center) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-sample contact forces (n, 3) newtons, the active samples and their gaps."""
        act, g, n, _ = self._contact(u, np.asarray(center, dtype=np.float64))
        f = np.zeros_like(self.X)
        f[act] = (-self.k * g)[:, None] * n
        return f, act, g

    def _residual(self, u, c):
        f, act, g = self.forces(u, c)
        return self.solid.internal_force(u) - (self.Wt @ f.ravel()) / self.E, f, act, g

    def _tangent(self, u, c, act, g):
        _, _, n, r = self._contact(u, c)
        blocks = self.k * (n[:, :, None] * n[:, None, :]
                           + (g / r)[:, None, None] * (np.eye(3)[None] - n[:, :, None] * n[:, None, :]))
        rows = (3 * act[:, None] + np.arange(3)[None, :])
        Wa = self.W[rows.ravel()]
        B = sp.block_diag(list(blocks), format="csr") if len(act) else sp.csr_matrix((0, 0))
        Kc = (Wa.T @ B @ Wa) / self.E if len(act) else sp.csr_matrix((self.solid.N, self.solid.N))
        return (self.solid.tangent(u) + Kc).tocsr()

    def solve(self, center, u0: np.ndarray | None = None, tol: float = 1e-8, max_iter: int = 30) -> SphereState:
        """Equilibrium with the sphere at ``center`` (body frame), Newton from ``u0`` (the previous probe
        position's solution: the path is followed in small steps by :meth:`solve_path`); where Newton fails, the
        potential's damped descent (:meth:`_descend`)."""
        c = np.asarray(center, dtype=np.float64)
        s = self.solid
        u = np.zeros(s.N) if u0 is None else np.array(u0, dtype=np.float64)
        start = u.copy()
        free = s.free
        prev = np.inf
        for it in range(max_iter + 1):
            r, f, act, g = self._residual(u, c)
            res, rn = self._relative(r, f)
            if not np.isfinite(res):
                break
            if self._converged(res, rn, prev, len(act), tol):
                return self._state(u, c, it)
            prev = rn
            if it == max_iter:
                break
            K = self._tangent(u, c, act, g)
            du = np.zeros(s.N)
            du[free] = spla.spsolve(K[free][:, free].tocsc(), -r[free])
            if not np.all(np.isfinite(du)):
                break
            # backtracking: keep the elements positive and the residual falling
            alpha, base = 1.0, float(np.linalg.norm(r[free]))
            for _ in range(10):
                trial = u + alpha * du
                if s.min_jacobian(trial) > 0 and np.linalg.norm(self._residual(trial, c)[0][free]) < base:
                    break
                alpha *= 0.5
            u = trial
        return self._descend(c, start, tol)

    def _relative(self, r: np.ndarray, f: np.ndarray) -> tuple[float, float]:
        """(the residual relative to the contact force, never below 0.1 mN: at the first touch the force is
        round-off; its norm, E units)."""
        rn = float(np.linalg.norm(r[self.solid.free]))
        return rn / (max(float(np.linalg.norm(f)), 1e-4) / self.E), rn

    @staticmethod
    def _converged(res: float, rn: float, prev: float, n_active: int, tol: float) -> bool:
        """Converged; or stalled at round-off (a stiff body's internal force carries a floor of E-unit round-off);
        without contact, at rest."""
        if n_active == 0:
            return rn < 1e-14
        return res < tol or (res < np.sqrt(tol) and rn > 0.5 * prev)

    def potential(self, u: np.ndarray, center) -> float:
        """The total potential (E units) whose gradient the residual is: the body's stored energy and the
        penalty's ``k/2 <-g>^2`` per sample."""
        _, g, _, _ = self._contact(u, np.asarray(center, dtype=np.float64))
        return self.solid.energy(u) + 0.5 * self.k * float(np.sum(g ** 2)) / self.E

    def _descend(self, c: np.ndarray, u: np.ndarray, tol: float, max_iter: int = 300) -> SphereState:
        """Newton's fallback: steps on the potential damped Levenberg-Marquardt style, ``(K + mu diag|K|) du = -r``,
        each kept only where the potential falls (the damping grows after a rejected step, shrinks after a good
        one). Plain Newton fails where a slender part bends away under the frictionless sphere: past a limit point
        of the quasi-static path the tangent is near-singular or indefinite and the penalty's active set flips
        between iterations. The descent follows the potential down to an equilibrium: the state a heavily damped
        motion would reach, the stable one beyond the limit point (the part slips off the probe, or stays on it)."""
        s, free = self.solid, self.solid.free
        u = np.array(u, dtype=np.float64)
        pot = self.potential(u, c)
        mu, res = 1e-3, np.inf
        for it in range(max_iter + 1):
            r, f, act, g = self._residual(u, c)
            res, rn = self._relative(r, f)
            if not np.isfinite(res):
                break
            # Newton's stall rule (the residual no longer halving) does not apply: a descent's residual falls slowly
            # by design, so only the tolerance ends it, or a stall at the potential's round-off (below)
            if res < tol or (len(act) == 0 and rn < 1e-14):
                return self._state(u, c, it)
            K = self._tangent(u, c, act, g)[free][:, free].tocsc()
            D = sp.diags(np.abs(K.diagonal()) + 1e-30)
            stepped = False
            for _ in range(2):
                while mu < 1e12:
                    du = spla.spsolve((K + mu * D).tocsc(), -r[free])
                    trial = u.copy()
                    trial[free] += du
                    if np.all(np.isfinite(du)) and s.min_jacobian(trial) > 0:
                        p_trial = self.potential(trial, c)
                        model = float(r[free] @ du) + 0.5 * float(du @ (K @ du))  # the quadratic model's change
                        # a step that lowers the residual and raises the potential by less than its round-off
                        # (about 1e-9 of it on this AVX-512 host) polishes the minimum: past that
                        # floor the potential cannot tell steps apart, the residual (its gradient) still can
                        if p_trial < pot or (p_trial <= pot + 1e-8 * abs(pot) and
                                             np.linalg.norm(self._residual(trial, c)[0][free]) < rn):
                            rho = (p_trial - pot) / model if model < 0 else 0.0
                            mu = mu / 3 if rho > 0.75 else (mu * 2 if rho < 0.25 else mu)
                            u, pot, stepped = trial, p_trial, True
                            break
                    mu = max(mu * 4, 1e-8)
                if stepped:
                    break
                # every damping from the current one up was refused: near the minimum a heavily damped step promises
                # a fall below the potential's round-off, and more damping only shrinks it; once per iteration the
                # damping starts again at Newton's end, where the fall is larger
                mu = 1e-8
            if not stepped:  # no damping lowers the potential: a minimum to its round-off
                if res < np.sqrt(tol):
                    return self._state(u, c, it)
                break
        raise FemError(f"the sphere contact did not converge at {np.round(c, 5).tolist()} (residual {res:.2e}), "
                       "neither by Newton nor by the potential's damped descent")

    def _state(self, u, c, its) -> SphereState:
        f, _, g = self.forces(u, c)
        mag = np.linalg.norm(f, axis=1)
        cen = (mag @ self.X) / mag.sum() if mag.sum() > 0 else np.full(3, np.nan)
        return SphereState(u, f, f.sum(axis=0), cen, float(-g.min()) if len(g) else 0.0, its)

    def first_touch(self, start, direction) -> float:
        """How far along ``direction`` from ``start`` the sphere's centre goes before touching the undeformed
        samples (metres; -inf when its path misses them all)."""
        n = np.asarray(direction, dtype=np.float64)
        n = n / np.linalg.norm(n)
        Y = self.X - np.asarray(start, dtype=np.float64)
        t = Y @ n
        r2 = np.sum(Y ** 2, axis=1) - t ** 2
        hit = r2 < self.R ** 2
        return float(np.min(t[hit] - np.sqrt(self.R ** 2 - r2[hit]))) if np.any(hit) else -np.inf

    def solve_path(self, start, direction, travels) -> list[SphereState]:
        """Follow the sphere's centre ``start + s direction`` over increasing ``travels`` s (metres)
        (:func:`follow_path`)."""
        return follow_path(self.solve, np.zeros(self.solid.N), start, direction, travels)


def follow_path(solve, u_zero: np.ndarray, start, direction, travels) -> list:
    """Follow a probe's centre ``start + s direction`` over increasing ``travels`` s (metres): ``solve(centre,
    guess)`` returns a state with the dofs ``.u`` or raises :class:`FemError`; each solve starts from a secant
    prediction along the stroke (the last two solutions), then from the last solution; a step that fails is
    halved (at most 6 times)."""
    n = np.asarray(direction, dtype=np.float64)
    n = n / np.linalg.norm(n)
    start = np.asarray(start, dtype=np.float64)
    out: list = []
    u = np.asarray(u_zero, dtype=np.float64)
    u_last, s_last = u, None  # the solution before u: a secant predictor along the stroke
    pos = float(travels[0]) if len(travels) else 0.0
    for s_t in (float(v) for v in travels):
        span = s_t - pos
        step = span
        st = None
        while st is None or pos < s_t - 1e-15:
            tgt = min(pos + step, s_t) if span > 0 else s_t
            guess = u
            if s_last is not None and pos > s_last:
                guess = u + (u - u_last) * (tgt - pos) / (pos - s_last)
            try:
                try:
                    st = solve(start + n * tgt, guess)
                except FemError:
                    if guess is u:
                        raise
                    st = solve(start + n * tgt, u)
            except FemError:
                step *= 0.5
                if step < span / 64 or span <= 0:
                    raise
                continue
            u_last, s_last = u, pos
            u, pos = st.u, tgt
            step = 2 * step
        out.append(st)
    return out


@dataclass
class ProbePath:
    """The full-order truth along one straight probe stroke: the sphere's centre at ``start + s direction``
    (body frame) for the solved travels ``s`` (metres, increasing; the first touches the undeformed surface with
    no force). Per travel: the total contact force (3,) on the body, the force centroid (reference surface,
    body frame), the deepest penetration, the displacement of the observed points (the reduced model's nodes) and
    their von Mises stress (Pa: the truth mesh's nodal, L2-projected values interpolated there). Between solved
    travels everything is interpolated linearly (:meth:`at`); ``info`` holds the mesh, the penalty, the Newton
    counts and the measured interpolation error."""

    start: np.ndarray
    direction: np.ndarray
    travels: np.ndarray
    total: np.ndarray
    centroid: np.ndarray
    penetration: np.ndarray
    displacement: np.ndarray
    von_mises: np.ndarray
    info: dict = field(default_factory=dict)

    def at(self, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(total force (3,), centroid (3,), displacement (n_obs, 3), von Mises stress (n_obs,) Pa) with the
        sphere's centre at travel ``s``; before the first touch: no force, no deformation (centroid NaN)."""
        tr = self.travels
        if s <= tr[0]:
            return (np.zeros(3), np.full(3, np.nan), np.zeros_like(self.displacement[0]),
                    np.zeros_like(self.von_mises[0]))
        j = int(np.clip(np.searchsorted(tr, s) - 1, 0, len(tr) - 2))
        w = float(np.clip((s - tr[j]) / (tr[j + 1] - tr[j]), 0.0, 1.0))
        cen = self.centroid[j + 1] if j == 0 else (1 - w) * self.centroid[j] + w * self.centroid[j + 1]
        return ((1 - w) * self.total[j] + w * self.total[j + 1], cen,
                (1 - w) * self.displacement[j] + w * self.displacement[j + 1],
                (1 - w) * self.von_mises[j] + w * self.von_mises[j + 1])


def scan_solid(model, base_fraction: float, h: float) -> tuple[fem.Solid, np.ndarray, np.ndarray]:
    """The full-order body of a scanned probe model (bunny, dragon): the scan surface the model carries (its
    nodes from ``provenance['volume_nodes']`` on) meshed anew with linear tetrahedra of size ``h`` (the model's
    own voxel mesh is not used), its material law, clamped below ``base_fraction`` of its height like the model.
    Returns (solid, scan vertices, scan triangles)."""
    nv = int(model.provenance.get("volume_nodes", 0))
    if nv <= 0 or nv >= len(model.points):
        raise FemError("the model carries no scan surface (provenance 'volume_nodes'): not a probe_nipgd model")
    V = np.asarray(model.points[nv:], dtype=np.float64)
    F = np.asarray(model.surface, dtype=np.int64) - nv
    H = float(np.ptp(V[:, 2]))
    mesh = meshes.voxel_tet_mesh(V, F, h)
    mat = materials.make_material(model.material["law"], model.material["E"], model.material["nu"])
    zmin = float(V[:, 2].min())
    solid = fem.Solid(mesh, mat, 1, [fem.Support(fem.Region(box=[None, None, [None, zmin + base_fraction * H]]))])
    return solid, V, F


def triangle_samples(V: np.ndarray, F: np.ndarray, spacing: float) -> np.ndarray:
    """Points over triangles (V, F) at most about ``spacing`` apart: each triangle's vertices and a barycentric
    lattice of n = ceil(longest edge / spacing) steps per edge (the truth's own sampler: it shares no code with
    the estimator's)."""
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    edge = np.max(np.stack([np.linalg.norm(B - A, axis=1), np.linalg.norm(C - B, axis=1),
                            np.linalg.norm(A - C, axis=1)]), axis=0)
    steps = np.maximum(np.ceil(edge / spacing).astype(np.int64), 1)
    out = [V[np.unique(F)]]
    for n in np.unique(steps):
        if n < 2:
            continue
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        a, b = (i[keep] / n)[None, :, None], (j[keep] / n)[None, :, None]
        sel = steps == n
        out.append((a * A[sel][:, None] + b * B[sel][:, None] + (1 - a - b) * C[sel][:, None]).reshape(-1, 3))
    return np.unique(np.round(np.concatenate(out), 12), axis=0)


def _near_samples(V, F, start, n, reach, radius, spacing):
    def seg_dist(P):
        t = np.clip((P - start) @ n, 0.0, reach)
        return np.linalg.norm(P - start - t[:, None] * n[None, :], axis=1)

    tri_c = V[F].mean(axis=1)
    tri_r = np.max(np.linalg.norm(V[F] - tri_c[:, None], axis=2), axis=1)
    near = F[seg_dist(tri_c) < radius + tri_r + 2 * spacing]
    S = triangle_samples(V, near, spacing)
    return S[seg_dist(S) < radius + spacing]


def probe_path_truth(model, load_point: int, press: float, radius: float, base_fraction: float, h: float,
                     spacing: float = 1.5e-3, n_travels: int = 16, beta: float = 1000.0,
                     solid_cache: dict | None = None, at: tuple[np.ndarray, np.ndarray] | None = None) -> ProbePath:
    """The truth of a probe pressing the scanned body along the model's load direction at ``load_point``: the
    sphere's centre moves along ``d`` (the load direction, into the body) as ``X_node + d (s - radius)``; it first
    touches the undeformed scan surface at travel ``s0`` (``info['first_touch_m']``: the model's load point is a
    node of its voxel mesh, off the scan by up to a cell) and presses ``press`` metres past it (the probe scenes'
    stroke, ``synth.scenes._probe_path``). Solved at ``n_travels`` travels from ``s0`` to ``s0 + press``
    (spaced as (j/J)^1.5: denser at the touch, where the force grows fastest), plus two travels between solved
    ones, solved exactly and compared with the interpolation (``info['interp_err_pct']``).

    ``at``: (point, direction) in the object frame in place of the load point's node and load direction: a probe
    anywhere on the body (``load_point`` then only names it in messages)."""
    import time

    t0 = time.perf_counter()
    key = (model.model_id, round(h, 9), round(base_fraction, 9))
    if solid_cache is not None and key in solid_cache:
        solid, V, F, W_obs = solid_cache[key]
    else:
        solid, V, F = scan_solid(model, base_fraction, h)
        W_obs = embedding_matrix(solid, model.points)
        if solid_cache is not None:
            solid_cache[key] = (solid, V, F, W_obs)
    if at is None:
        X = np.asarray(model.points[int(model.load_points[load_point])], dtype=np.float64)
        d = np.asarray(model.load_directions[load_point], dtype=np.float64)
    else:
        X, d = (np.asarray(v, dtype=np.float64).ravel() for v in at)
    d = d / np.linalg.norm(d)
    start = X - d * radius
    S = _near_samples(V, F, start - d * 2 * radius, d, press + 3 * radius, radius, spacing)
    prob = SphereOnSolid(solid, S, radius, spacing, h, beta)
    s0 = prob.first_touch(start, d)
    if not np.isfinite(s0):
        raise FemError(f"the probe's stroke at load point {load_point} never touches the scan surface")
    J = int(n_travels)
    travels = s0 + press * (np.arange(J + 1) / J) ** 1.5
    states = prob.solve_path(start, d, travels)
    disp = np.stack([(W_obs @ st.u).reshape(-1, 3) for st in states])
    W_scalar = W_obs[0::3][:, 0::3]  # the same weights on the vertices (P1 dofs are interleaved per vertex)
    vm = np.stack([W_scalar @ solid.stress(st.u)["von_mises"] for st in states])
    path = ProbePath(start, d, travels, np.stack([st.total for st in states]),
                     np.stack([st.centroid for st in states]), np.array([st.penetration for st in states]), disp,
                     vm)
    # the interpolation's own error, at the middle of the first and of the last interval
    errs = []
    for j in (1, J - 1):
        s_mid = 0.5 * (travels[j] + travels[j + 1])
        exact = prob.solve(start + d * s_mid, states[j].u)
        u_ex = (W_obs @ exact.u).reshape(-1, 3)
        u_in = path.at(s_mid)[2]
        errs.append(100 * float(np.sqrt(np.mean(np.sum((u_in - u_ex) ** 2, axis=1))
                                        / max(np.mean(np.sum(u_ex ** 2, axis=1)), 1e-30))))
    path.info = {"dofs": int(solid.N), "h_m": float(h), "samples": len(S), "penalty_N_per_m": prob.k,
                 "newton": [int(st.newton) for st in states], "first_touch_m": float(s0),
                 "interp_err_pct": errs, "max_penetration_mm": 1e3 * float(path.penetration.max()),
                 "peak_force_N": float(np.linalg.norm(path.total[-1])), "seconds": time.perf_counter() - t0,
                 "law": solid.material.law}
    return path
