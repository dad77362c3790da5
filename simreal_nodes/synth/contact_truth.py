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
