"""Large-deformation contact truth of the crossed beams (issue 21, thesis §5.4.1): a rigid probe presses beam a,
and a, bending, presses beam b; both beams of the thesis's St. Venant-Kirchhoff law (any law of
:mod:`~simreal_nodes.physics.materials` works), total Lagrangian, frictionless.

The linear truth (:func:`~simreal_nodes.synth.contact_truth.crossed_beams_truth`) is a Signorini problem on
the bodies' compliance; with a non-linear law there is no compliance to condense, so here the two beams are
solved together on their full-order dofs ``U = [u_a; u_b]``, each its own
:class:`~simreal_nodes.physics.fem.Solid` (quadratic tetrahedra on a grid finer than the reduced model's
hexahedra: nothing of the reduced model is used but its box, material, supports and node positions), the
contacts exact (Lagrange multipliers, no penetration):

- the probe on a: samples ``X_i`` of a's top face around the press point, at ``x_i = X_i + u_a(X_i)``, must stay
  out of the sphere of centre ``c``: ``g_i = |x_i - c| - R >= 0``;
- a on b: samples ``X_j`` of a's bottom face over b, at ``x_j = X_j + u_a(X_j)`` seen in b's frame, must stay
  above b's *deformed* top face: with ``Y_j`` the point of b's top face (reference) whose deformed position
  ``y_j = Y_j + u_b(Y_j)`` lies under ``x_j`` (the same x, y; a fixed point: the slopes are small) and ``n_j``
  the deformed face's normal there (central differences of ``y`` along the face),
  ``h_j = n_j . (x_j - y_j) >= 0``;
- the contact forces ``lambda >= 0`` push along the gaps' gradients, complementary to the gaps.

``u(X)`` is the finite-element field itself at the sample (:func:`field_matrix`, any element order). Each
iteration is Newton's step of the equilibrium ``f_int(U) = G(U)' lambda`` with the gaps linearized,
``g + G dU >= 0``: a linear complementarity problem on the candidate samples (those within ``band`` of contact),
condensed with the bodies' tangents, ``M = G K^-1 G'`` (the linear truth's Delassus operator, now at the
current state), solved exactly by :func:`~simreal_nodes.synth.contact_truth.solve_lcp` (a sequential LCP: for a
linear law it is the linear truth in one step). The gaps' own curvature (the sphere's, b's slope under a moving
foot point) is left out of the tangent: a second-order term of a force over a radius, a few hundred N/m against
the beams' stiffness, which only slows the last iterations. A penalty formulation was tried first and dropped: a
penalty stiff enough to keep the penetration under a micrometre is 10^5 times a slender beam's stiffness, and
Newton then cycles between active sets on the flat contact of a's bottom on b's top.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from simreal_nodes import geometry as G
from simreal_nodes.errors import FemError
from simreal_nodes.physics import fem, materials
from simreal_nodes.synth.contact_truth import beam_solid, follow_path, solve_lcp

BODIES = ("a", "b")


def field_matrix(solid: fem.Solid, points: np.ndarray) -> sp.csr_matrix:
    """(3 n, N) sparse map from the solid's dofs to the displacement at ``points`` (n, 3) in its mesh: the
    finite-element interpolation itself (scikit-fem's probes of the scalar basis, whose dofs the vector basis
    interleaves per node: node k owns 3k, 3k + 1, 3k + 2), for any element order."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(P) == 0:
        return sp.csr_matrix((0, solid.N))
    S = solid.sbasis.probes(P.T).tocoo()
    rows = (3 * S.row[:, None] + np.arange(3)[None, :]).ravel()
    cols = (3 * S.col[:, None] + np.arange(3)[None, :]).ravel()
    return sp.coo_matrix((np.repeat(S.data, 3), (rows, cols)), shape=(3 * len(P), solid.N)).tocsr()


def face_samples(x_range, y_range, z: float, spacing: float) -> np.ndarray:
    """A grid of points on the plane ``z`` over [x0, x1] x [y0, y1], at most ``spacing`` apart, edges included."""
    axes = [np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / spacing - 1e-9)) + 1)) for lo, hi in (x_range, y_range)]
    gx, gy = np.meshgrid(*axes, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, float(z))], axis=1)


@dataclass
class BeamsState:
    """One solved probe position: the dofs ``u`` (a's, then b's), per body the total contact force it takes
    (newtons: the probe's on a, a's on b) and its force-weighted centroid (reference positions, the body's own
    frame; NaN without force), the deepest remaining penetration of any sample (metres: the linearization's last error),
    the smallest probe-to-a and a-to-b gaps (metres; negative: in contact) and the Newton iterations."""

    u: np.ndarray
    total: dict[str, float]
    centroid: dict[str, np.ndarray]
    penetration: float
    gap: dict[str, float]
    newton: int


class SphereOnCrossedBeams:
    """The probe (a rigid sphere of ``radius``) pressing beam a, a pressing beam b: module docstring.

    ``solid``: the full-order beam (both beams are the same body: geometry, law, supports), its box from the
    origin, top face ``z = H``; ``T_ab``: b's frame in a's; ``press_point``: where the probe presses a's top face
    (a's frame); ``spacing``, ``pair_spacing``: the probe's and the pair's contact samples' spacing; ``band``: a sample
    is a candidate contact of the next step when its gap is under it."""

    def __init__(self, solid: fem.Solid, T_ab: np.ndarray, radius: float, press_point, spacing: float = 1.0e-3,
                 pair_spacing: float = 2.0e-3, band: float = 1.0e-3, reach: float = 0.003):
        if solid.dim != 3:
            raise FemError("the crossed beams' truth needs a 3D solid")
        lo, hi = solid.bounds[:, 0], solid.bounds[:, 1]
        if np.max(np.abs(lo)) > 1e-12:
            raise FemError("the crossed beams' truth expects the beam's box to start at the object origin")
        self.solid = solid
        self.N = solid.N
        self.L, self.W, self.H = (float(v) for v in hi)
        self.R = float(radius)
        self.T_ab = np.asarray(T_ab, dtype=np.float64)
        self.T_ba = G.inv(self.T_ab)
        if abs(self.T_ab[2, 2] - 1.0) > 1e-9:
            raise FemError("beam b must be turned about z only (the push direction is -z in both frames)")
        c = np.asarray(press_point, dtype=np.float64)
        # a's top face around the press point: the probe's shadow and ``reach`` more (a's surface slides a little)
        span = self.R + reach
        self.Xt = face_samples((max(0.0, c[0] - span), min(self.L, c[0] + span)),
                               (max(0.0, c[1] - span), min(self.W, c[1] + span)), self.H, spacing)
        # a's bottom face over b's top face at rest, grown by ``reach``
        corners = G.transform(self.T_ab, np.array([[0, 0, self.H], [self.L, 0, self.H], [0, self.W, self.H],
                                                   [self.L, self.W, self.H]], dtype=np.float64))
        x0, y0 = corners[:, :2].min(axis=0) - reach
        x1, y1 = corners[:, :2].max(axis=0) + reach
        if x1 < 0 or x0 > self.L or y1 < 0 or y0 > self.W:
            raise FemError("beam b does not lie under beam a")
        self.Xb = face_samples((max(0.0, x0), min(self.L, x1)), (max(0.0, y0), min(self.W, y1)), 0.0, pair_spacing)
        self.Wt = field_matrix(solid, self.Xt)
        self.Wb = field_matrix(solid, self.Xb)
        self.E = float(solid.material.E)
        cells = np.asarray(solid.mesh.p)[:, np.asarray(solid.mesh.t)]  # (3, 4 or 8, n_cells)
        self.h = float(np.median(np.max(np.ptp(cells, axis=1), axis=0)))  # the mesh size
        self.band = float(band)
        self.dl = 0.25 * self.h  # the central differences' step for b's normal
        self.description = ""

    # -- contact geometry -----------------------------------------------------------------------------------
    def _sphere(self, ua: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gaps of a's top samples to the sphere and their outward normals (a's frame)."""
        d = self.Xt + (self.Wt @ ua).reshape(-1, 3) - c
        r = np.linalg.norm(d, axis=1)
        return r - self.R, d / np.maximum(r, 1e-15)[:, None]

    def _b_top(self, ub: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Deformed positions of b's top-face points ``Y`` (reference, b's frame)."""
        return Y + (field_matrix(self.solid, Y) @ ub).reshape(-1, 3)

    def _pairs(self, ua: np.ndarray, ub: np.ndarray):
        """a's bottom samples against b's deformed top: (sample indices over b, foot points Y on b (reference, b's
        frame), normals n (b's frame), gaps h)."""
        xa = self.Xb + (self.Wb @ ua).reshape(-1, 3)
        xb = G.transform(self.T_ba, xa)
        tol = 1e-9
        over = np.flatnonzero((xb[:, 0] >= -tol) & (xb[:, 0] <= self.L + tol) & (xb[:, 1] >= -tol)
                              & (xb[:, 1] <= self.W + tol))
        if len(over) == 0:
            return over, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
        target = xb[over, :2]
        Y = np.c_[np.clip(target[:, 0], 0, self.L), np.clip(target[:, 1], 0, self.W), np.full(len(over), self.H)]
        for _ in range(8):  # Y_xy + u_b,xy(Y) = x_xy: b's top slides by under a millimetre, a few sweeps suffice
            y = self._b_top(ub, Y)
            new = np.c_[np.clip(Y[:, 0] + target[:, 0] - y[:, 0], 0, self.L),
                        np.clip(Y[:, 1] + target[:, 1] - y[:, 1], 0, self.W)]
            moved = float(np.max(np.abs(new - Y[:, :2])))
            Y[:, :2] = new
            if moved < 1e-12:
                break
        y = self._b_top(ub, Y)
        # off b's top face (the foot point clipped to its edge and still not under x): no contact there
        on = np.max(np.abs(y[:, :2] - target), axis=1) < 1e-6
        over, Y, y = over[on], Y[on], y[on]
        tangents = []
        for ax, size in ((0, self.L), (1, self.W)):
            Yp, Ym = Y.copy(), Y.copy()
            Yp[:, ax] = np.minimum(Y[:, ax] + self.dl, size)
            Ym[:, ax] = np.maximum(Y[:, ax] - self.dl, 0.0)
            tangents.append((self._b_top(ub, Yp) - self._b_top(ub, Ym)) / (Yp[:, ax] - Ym[:, ax])[:, None])
        n = np.cross(tangents[0], tangents[1])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        gap = np.einsum("ij,ij->i", xb[over] - y, n)
        return over, Y, n, gap

    def _constraints(self, U: np.ndarray, c: np.ndarray, band: float):
        """The candidate contacts (gap under ``band``): their gaps (m,), gradients with respect to a's and b's
        dofs (two (m, N) sparse), force directions (m, 3: on a in a's frame for the probe's, on a in b's frame for
        the pair's), where each acts (reference: a's top sample; b's foot point in b's frame), the number of probe
        rows (the first ones), and the smallest gap of every sample (probe, pair)."""
        N = self.N
        g, n_t = self._sphere(U[:N], c)
        over, Y, n_b, h = self._pairs(U[:N], U[N:])
        ct, cp = np.flatnonzero(g < band), np.flatnonzero(h < band)

        def rows(W: sp.csr_matrix, idx: np.ndarray, n: np.ndarray) -> sp.csr_matrix:
            m = len(idx)
            S = sp.csr_matrix((n.ravel(), (np.repeat(np.arange(m), 3), np.arange(3 * m))), shape=(m, 3 * m))
            return S @ W[(3 * idx[:, None] + np.arange(3)[None, :]).ravel()]

        n_a = n_b[cp] @ self.T_ab[:3, :3].T  # the pair's normal in a's frame
        Ga = sp.vstack([rows(self.Wt, ct, n_t[ct]), rows(self.Wb, over[cp], n_a)]).tocsr()
        Pb = field_matrix(self.solid, Y[cp])
        Gb = sp.vstack([sp.csr_matrix((len(ct), N)), -rows(Pb, np.arange(len(cp)), n_b[cp])]).tocsr()
        where = np.concatenate([self.Xt[ct], Y[cp]]) if len(ct) + len(cp) else np.zeros((0, 3))
        mins = (float(g.min()) if len(g) else np.inf, float(h.min()) if len(h) else np.inf)
        return np.concatenate([g[ct], h[cp]]), Ga, Gb, np.concatenate([n_t[ct], n_b[cp]]), where, len(ct), mins

    # -- solves -------------------------------------------------------------------------------------------
    def solve(self, center, u0: np.ndarray | None = None, tol: float = 1e-7, max_iter: int = 25) -> BeamsState:
        """Equilibrium with the probe's centre at ``center`` (a's frame), from ``u0`` (a's dofs, then b's): Newton
        steps each solving the linearized contact problem exactly (module docstring), until a step moves no node by
        more than ``tol`` of the largest displacement."""
        c = np.asarray(center, dtype=np.float64)
        s, N = self.solid, self.N
        fr = s.free
        U = np.zeros(2 * N) if u0 is None else np.array(u0, dtype=np.float64)
        step = np.inf
        for it in range(1, max_iter + 1):
            gap, Ga, Gb, dirs, where, n_probe, _ = self._constraints(U, c, self.band)
            lu = [spla.splu(s.tangent(u)[fr][:, fr].tocsc(), permc_spec="MMD_AT_PLUS_A") for u in (U[:N], U[N:])]
            d0 = np.zeros(2 * N)
            d0[fr] = -lu[0].solve(s.internal_force(U[:N])[fr])
            d0[N + fr] = -lu[1].solve(s.internal_force(U[N:])[fr])
            lam = np.zeros(len(gap))
            dU = d0
            if len(gap):
                # M = G K^-1 G' through the few dofs the contacts touch (S: G's non-zero columns): |S| solves
                # instead of one per candidate, K^-1 G' lambda = Z (G_S' lambda)
                M = np.zeros((len(gap), len(gap)))
                q = gap.copy()
                Zs: list[tuple[np.ndarray, np.ndarray] | None] = []
                for k, Gk in enumerate((Ga[:, fr].tocsc(), Gb[:, fr].tocsc())):
                    S = np.flatnonzero(np.diff(Gk.indptr))
                    if len(S) == 0:
                        Zs.append(None)
                        continue
                    E_S = sp.csc_matrix((np.ones(len(S)), (S, np.arange(len(S)))), shape=(len(fr), len(S)))
                    Z = lu[k].solve(E_S.toarray())  # (free, |S|)
                    GS = Gk[:, S].toarray()
                    M += GS @ Z[S] @ GS.T
                    q += Gk @ d0[k * N + fr]
                    Zs.append((Z, GS))
                # samples finer than the mesh make M singular (more constraints than the face's dofs can tell
                # apart): the forces' split among them is then not unique and a plain solve can return huge
                # opposing ones. A compliance of 1e-7 of a sample's own, in series with each, makes it unique; the
                # surfaces then overlap by 1e-7 of how far the force moves them
                M = 0.5 * (M + M.T) + (1e-7 * float(np.mean(np.diag(M)))) * np.eye(len(q))
                lam, _ = solve_lcp(M, q)
                dU = d0.copy()
                for k, zs in enumerate(Zs):
                    if zs is not None:
                        dU[k * N + fr] += zs[0] @ (zs[1].T @ lam)
            if not np.all(np.isfinite(dU)):
                break
            U = U + dU
            step = float(np.max(np.abs(dU)))
            if step <= tol * max(float(np.max(np.abs(U))), 1e-6):
                return self._state(U, c, lam, dirs, where, n_probe, it)
        raise FemError(f"the crossed beams' contact did not converge with the probe at {np.round(c, 5).tolist()} "
                       f"(last step {step:.2e} m)")

    def _state(self, U, c, lam, dirs, where, n_probe, its) -> BeamsState:
        """The converged state; ``lam`` (E units) over the candidates of the last step."""
        f = (self.E * lam)[:, None] * dirs
        total, cen = {}, {}
        for body, sel in (("a", slice(0, n_probe)), ("b", slice(n_probe, None))):
            fb, mag = f[sel], self.E * lam[sel]
            total[body] = float(np.linalg.norm(fb.sum(axis=0)))
            cen[body] = (mag @ where[sel]) / mag.sum() if mag.sum() > 0 else np.full(3, np.nan)
        mins = self._constraints(U, c, 0.0)[-1]
        return BeamsState(U, total, cen, max(0.0, -min(mins)), {"a": mins[0], "b": mins[1]}, its)


@dataclass
class BeamsPath:
    """The truth along the probe's straight stroke into a's top face: the probe's centre at ``start + s
    direction`` (a's frame; at s = 0 it touches the undeformed top face) for the solved ``travels`` s (metres,
    increasing). Per travel and body ("a": the probe's force on a, "b": a's on b): the total contact force (N), its
    centroid (reference positions, the body's frame) and the displacement of the observed points (the reduced
    model's nodes, the body's frame); the probe's smallest gap to a. Between travels everything is interpolated
    linearly (:meth:`at`); ``info``: the mesh, Newton's counts, the interpolation's measured error."""

    start: np.ndarray
    direction: np.ndarray
    travels: np.ndarray
    total: np.ndarray  # (n_travels, 2): a, b
    centroid: np.ndarray  # (n_travels, 2, 3)
    displacement: np.ndarray  # (n_travels, 2, n_obs, 3)
    gap: np.ndarray  # (n_travels,) the probe's smallest gap to a (metres)
    info: dict = field(default_factory=dict)

    def at(self, s: float) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
        """Per body (total force N, centroid (3,), displacement (n_obs, 3)) with the probe at travel ``s``; before
        the first touch: no force, no deformation (centroid NaN)."""
        tr = self.travels
        if s <= tr[0]:
            z = np.zeros_like(self.displacement[0, 0])
            return {b: (0.0, np.full(3, np.nan), z) for b in BODIES}
        j = int(np.clip(np.searchsorted(tr, s) - 1, 0, len(tr) - 2))
        w = float(np.clip((s - tr[j]) / (tr[j + 1] - tr[j]), 0.0, 1.0))
        out = {}
        for k, b in enumerate(BODIES):
            c0, c1 = self.centroid[j, k], self.centroid[j + 1, k]
            cen = c1 if not np.all(np.isfinite(c0)) else (1 - w) * c0 + w * c1
            out[b] = ((1 - w) * float(self.total[j, k]) + w * float(self.total[j + 1, k]), cen,
                      (1 - w) * self.displacement[j, k] + w * self.displacement[j + 1, k])
        return out


def crossed_beams_path(model, press_point, T_ab: np.ndarray, radius: float, press: float,
                       cells=(40, 4, 3), order: int = 2, n_travels: int = 16, spacing: float = 1.0e-3,
                       pair_spacing: float = 2.0e-3) -> BeamsPath:
    """The large-deformation truth of the crossed-beams probe (thesis §5.4.1) along the probe's stroke: the probe
    presses a's top face at ``press_point`` (a's frame) straight down by ``press`` metres past the first touch.
    Both beams are the physical beam the reduced ``model`` describes (its box, material law and supports) on
    P``order`` tetrahedra ``cells`` (the reduced models: hexahedra); the displacement is observed at the model's
    nodes. Solved at ``n_travels`` travels (spaced as (j/J)^1.2, denser at the touch), plus the travel where b is
    first touched (from the a-b gap of the travels before it, so the interpolation is exact at that kink), plus
    two mid-interval travels solved exactly and compared with the interpolation (``info['interp_err_pct']``)."""
    t0 = time.perf_counter()
    P = np.asarray(model.points, dtype=np.float64)
    L, W, H = (float(v) for v in P.max(axis=0))
    if np.max(np.abs(P.min(axis=0))) > 1e-9:
        raise FemError("the crossed-beams truth expects the beam's box to start at the object origin")
    mat = materials.make_material(model.material["law"], model.material["E"], model.material["nu"])
    sup = [{k: v for k, v in bc.items() if v is not None} for bc in model.boundary_conditions]
    solid = beam_solid(L, W, H, mat, sup, tuple(cells), order)
    prob = SphereOnCrossedBeams(solid, T_ab, radius, press_point, spacing=spacing, pair_spacing=pair_spacing)
    d = np.array([0.0, 0.0, -1.0])
    c = np.asarray(press_point, dtype=np.float64)
    start = np.array([c[0], c[1], H]) - d * radius  # touching the undeformed top face at s = 0
    J = int(n_travels)
    travels = list(float(press) * (np.arange(J + 1) / J) ** 1.2)
    states = follow_path(prob.solve, np.zeros(2 * prob.N), start, d, travels)
    # b's first touch: the a-b gap falls linearly with the travel before it; solve there and insert it
    k = next((i for i, st in enumerate(states) if st.total["b"] > 0), None)
    if k is not None and k >= 2 and states[k - 1].gap["b"] > 0:
        g1, g0 = states[k - 1].gap["b"], states[k - 2].gap["b"]
        s1, s0 = travels[k - 1], travels[k - 2]
        s_touch = s1 + g1 * (s1 - s0) / max(g0 - g1, 1e-15)
        if s1 < s_touch < travels[k]:
            st = prob.solve(start + d * s_touch, states[k - 1].u)
            travels.insert(k, s_touch)
            states.insert(k, st)
    Wobs = field_matrix(solid, P)
    N = prob.N

    def observe(st: BeamsState) -> np.ndarray:
        return np.stack([(Wobs @ st.u[:N]).reshape(-1, 3), (Wobs @ st.u[N:]).reshape(-1, 3)])

    path = BeamsPath(start, d, np.asarray(travels), np.array([[st.total[b] for b in BODIES] for st in states]),
                     np.array([[st.centroid[b] for b in BODIES] for st in states]),
                     np.stack([observe(st) for st in states]), np.array([st.gap["a"] for st in states]))
    # the interpolation's own error, at the middle of the first and of the last interval
    errs = []
    for j in (1, len(travels) - 2):
        s_mid = 0.5 * (travels[j] + travels[j + 1])
        u_ex = observe(prob.solve(start + d * s_mid, states[j].u))
        u_in = np.stack([path.at(s_mid)[b][2] for b in BODIES])
        errs.append(100 * float(np.sqrt(np.sum((u_in - u_ex) ** 2) / max(np.sum(u_ex ** 2), 1e-30))))
    prob.description = (f"full-order P{order} tetrahedra {cells[0]}x{cells[1]}x{cells[2]} per beam "
                        f"({2 * N} dofs), {mat.law} (total Lagrangian), frictionless exact contact (sequential LCP): "
                        f"{len(prob.Xt)} probe samples {spacing * 1e3:g} mm apart, {len(prob.Xb)} samples of a over b "
                        f"{pair_spacing * 1e3:g} mm apart")
    path.info = {"description": prob.description, "dofs": int(2 * N),
                 "newton": [int(st.newton) for st in states], "b_touch_m": float(travels[k]) if k is not None else None,
                 "interp_err_pct": errs, "max_penetration_mm": 1e3 * max(st.penetration for st in states),
                 "peak_force_N": [float(v) for v in path.total[-1]], "seconds": time.perf_counter() - t0,
                 "law": mat.law}
    return path
