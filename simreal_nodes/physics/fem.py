"""Full-order finite-element solids on scikit-fem: the truth the reduced models are measured against.

Weak form (thesis Eq. 4.4 / 5.3, total Lagrangian, quasi-static):

    find u with u = 0 on Gamma_u such that  R(u; v) = int_Omega P(F) : grad v dV - int_Gamma_t t . v dA = 0
    for all v vanishing on Gamma_u, where F = I + grad u and P = dW/dF is the material's stress.

Newton: K(u) du = -R(u), with K(u)[du, v] = int_Omega dP(F)[grad du] : grad v dV, load stepping with
step halving on divergence. The linear case is the same form with P = sigma(eps) (one Newton step).

scikit-fem provides the meshes, elements, quadrature, basis functions, facet integrals, Dirichlet
condensation and projections; the element contractions of the tangent are vectorized here because a
per-basis-pair form would recompute the constitutive tangent hundreds of times per element.

Scaling: equations are solved with the material divided by E and loads divided by E, so the answer
does not depend on the magnitude of E (1e3 ... 1e11 Pa give the same u*E/F).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import skfem
from numpy.typing import ArrayLike, NDArray

from simreal_nodes.errors import FemError
from simreal_nodes.physics import materials as mat

FACES = {"xmin": (0, "min"), "xmax": (0, "max"), "ymin": (1, "min"), "ymax": (1, "max"),
         "zmin": (2, "min"), "zmax": (2, "max")}


def _element(mesh, order: int):
    table = {
        (skfem.MeshTet1, 1): skfem.ElementTetP1, (skfem.MeshTet1, 2): skfem.ElementTetP2,
        (skfem.MeshHex1, 1): skfem.ElementHex1, (skfem.MeshHex1, 2): skfem.ElementHex2,
        (skfem.MeshTri1, 1): skfem.ElementTriP1, (skfem.MeshTri1, 2): skfem.ElementTriP2,
        (skfem.MeshQuad1, 1): skfem.ElementQuad1, (skfem.MeshQuad1, 2): skfem.ElementQuad2,
    }
    for (mt, o), el in table.items():
        if isinstance(mesh, mt) and o == order:
            return el()
    raise FemError(f"no element of order {order} for {type(mesh).__name__} (orders 1 and 2 are available)")


@dataclass
class Region:
    """Points of the mesh boundary: an extreme face (``xmin`` ... ``zmax``), a box, or both.

    ``box`` is one [lo, hi] pair per axis; ``null`` bounds are open. Tolerance is relative to the mesh size.
    """

    face: str | None = None
    box: list | None = None
    tol: float = 1e-6

    def mask(self, X: np.ndarray, bounds: np.ndarray) -> np.ndarray:
        """X: (dim, n) points; bounds: (dim, 2) mesh bounding box."""
        dim, n = X.shape
        diag = float(np.linalg.norm(bounds[:, 1] - bounds[:, 0]))
        tol = self.tol * diag
        m = np.ones(n, bool)
        if self.face is not None:
            if self.face not in FACES:
                raise FemError(f"region face must be one of {', '.join(FACES)}, got '{self.face}'")
            ax, side = FACES[self.face]
            if ax >= dim:
                raise FemError(f"face '{self.face}' does not exist in {dim}D")
            ref = bounds[ax, 0] if side == "min" else bounds[ax, 1]
            m &= np.abs(X[ax] - ref) <= tol
        if self.box is not None:
            for ax, lim in enumerate(self.box[:dim]):
                if lim is None:
                    continue
                lo, hi = lim
                if lo is not None:
                    m &= X[ax] >= lo - tol
                if hi is not None:
                    m &= X[ax] <= hi + tol
        return m

    @classmethod
    def from_spec(cls, d: RegionSpec) -> Region:
        if isinstance(d, Region):
            return d
        if isinstance(d, str):
            return cls(face=d)
        return cls(face=d.get("face"), box=d.get("box"), tol=d.get("tol", 1e-6))


# What Region.from_spec takes: a Region, a face name, or {face, box, tol} from a spec.
RegionSpec = Region | str | dict[str, Any]


@dataclass
class Support:
    """Dirichlet support on a region: clamped / pinned fix every component, sliding fixes ``component``."""

    region: Region
    kind: str = "clamped"
    component: int | None = None

    def components(self, dim: int) -> list[int]:
        if self.kind in ("clamped", "pinned"):
            return list(range(dim))
        if self.kind == "sliding":
            if self.component is None or not 0 <= self.component < dim:
                raise FemError(f"a sliding support needs the fixed (normal) component 0..{dim - 1}")
            return [self.component]
        raise FemError(f"support kind must be clamped, pinned or sliding, got '{self.kind}'")

    @classmethod
    def from_spec(cls, d: dict[str, Any]) -> Support:
        comp = d.get("component")
        if isinstance(comp, str):
            comp = "xyz".index(comp)
        return cls(Region.from_spec(d["region"]), d.get("kind", "clamped"), comp)


@dataclass
class SolveInfo:
    converged: bool
    steps: int
    newton_iterations: int
    residuals: list[float] = field(default_factory=list)
    message: str = ""


RIGID_NAMES_3D = ["translation x", "translation y", "translation z",
                  "rotation about x", "rotation about y", "rotation about z"]
RIGID_NAMES_2D = ["translation x", "translation y", "rotation about z"]


class Solid:
    """A hyperelastic (or linear elastic) solid on a scikit-fem mesh.

    ``order``: 1 or 2 (Lagrange). 2D meshes are plane strain (or plane stress for linear
    elasticity, ``plane='stress'``) with ``thickness``.
    """

    def __init__(self, mesh: skfem.Mesh, material: mat.Material, order: int = 1,
                 supports: Sequence[Support | dict[str, Any]] = (), plane: str = "strain",
                 thickness: float = 1.0, intorder: int | None = None) -> None:
        self.mesh = mesh
        self.dim = mesh.dim()
        self.material = material
        self.order = order
        self.plane = plane
        self.thickness = thickness if self.dim == 2 else 1.0
        if plane not in ("strain", "stress"):
            raise FemError(f"plane must be 'strain' or 'stress', got '{plane}'")
        if self.dim == 2 and plane == "stress" and not isinstance(material, mat.LinearElastic):
            raise FemError("plane stress is available for linear elasticity only; use plane strain or 3D")
        material.check_locking(order)
        self._scale = 1.0 / material.E
        m = material.scaled(self._scale)
        if self.dim == 2 and plane == "stress":
            # plane stress = plane strain with lambda* = 2 lambda mu / (lambda + 2 mu): nu* = nu / (1 + nu)
            nu_s = material.nu / (1 + material.nu)
            E_s = m.E * (1 + 2 * material.nu) / (1 + material.nu) ** 2
            m = mat.LinearElastic(E_s, nu_s, material.name)
        self._m = m
        el = _element(mesh, order)
        q = intorder if intorder is not None else 2 * order
        self.basis = skfem.Basis(mesh, skfem.ElementVector(el, self.dim), intorder=q)
        self.sbasis = skfem.Basis(mesh, el, quadrature=self.basis.quadrature)
        self.N = self.basis.N
        self.bounds = np.stack([mesh.p.min(axis=1), mesh.p.max(axis=1)], axis=1)
        self.supports = [s if isinstance(s, Support) else Support.from_spec(s) for s in supports]
        self.fixed = self._fixed_dofs()
        self.free = np.setdiff1d(np.arange(self.N), self.fixed)
        self._check_rigid_modes()
        self._K_lin: sp.csr_matrix | None = None
        self._grads = None

    # -- supports -----------------------------------------------------------------------------
    def _fixed_dofs(self) -> np.ndarray:
        if not self.supports:
            return np.zeros(0, np.int64)
        locs = self.basis.doflocs  # (dim, N)
        comp = np.arange(self.N) % self.dim
        fixed = np.zeros(self.N, bool)
        for s in self.supports:
            inside = s.region.mask(locs, self.bounds)
            for c in s.components(self.dim):
                fixed |= inside & (comp == c)
        return np.flatnonzero(fixed)

    def rigid_modes(self) -> np.ndarray:
        """(N, 6) (3D) or (N, 3) (2D) rigid-body motions sampled on the dofs."""
        X = self.basis.doflocs
        c = X.mean(axis=1, keepdims=True)
        Xc = X - c
        comp = np.arange(self.N) % self.dim
        node_x = Xc[:, np.arange(self.N)]
        if self.dim == 3:
            modes = np.zeros((self.N, 6))
            for k in range(3):
                modes[comp == k, k] = 1.0
            for k, w in enumerate(np.eye(3)):
                v = np.cross(w, node_x.T)  # (N, 3)
                modes[:, 3 + k] = v[np.arange(self.N), comp]
        else:
            modes = np.zeros((self.N, 3))
            modes[comp == 0, 0] = 1.0
            modes[comp == 1, 1] = 1.0
            v = np.stack([-node_x[1], node_x[0]], axis=1)
            modes[:, 2] = v[np.arange(self.N), comp]
        return modes

    def _check_rigid_modes(self) -> None:
        modes = self.rigid_modes()
        names = RIGID_NAMES_3D if self.dim == 3 else RIGID_NAMES_2D
        Rf = modes[self.fixed]
        s = np.linalg.svd(Rf, compute_uv=False) if len(self.fixed) else np.zeros(0)
        rank = int(np.sum(s > 1e-9 * (s.max() if s.size else 1.0)))
        if rank < modes.shape[1]:
            # which motions are left free: null space of Rf
            if len(self.fixed):
                _, _, Vt = np.linalg.svd(Rf)
                null = Vt[rank:]
            else:
                null = np.eye(modes.shape[1])
            free = [names[int(np.argmax(np.abs(v)))] for v in null]
            raise FemError(
                f"the supports leave {modes.shape[1] - rank} rigid-body motion(s) free ({', '.join(free)}): "
                f"the stiffness matrix would be singular. Add a clamped / pinned / sliding support "
                f"({len(self.fixed)} dofs are fixed now).")

    # -- geometry helpers ---------------------------------------------------------------------
    def _F3(self, Hu):
        """F = I + grad u as (3, 3, ...); 2D is plane strain (F33 = 1)."""
        if self.dim == 3:
            return Hu + mat.eye_like(Hu)
        out = np.zeros((3, 3) + Hu.shape[2:])
        out[:2, :2] = Hu
        return out + mat.eye_like(out)

    def _grad_u(self, u: np.ndarray):
        return self.basis.interpolate(u).grad  # (dim, dim, ne, nq)

    def _scalar_grads(self):
        if self._grads is None:
            # (nb, dim, ne, nq)
            self._grads = np.stack([self.sbasis.basis[a][0].grad for a in range(self.sbasis.Nbfun)])
        return self._grads

    # -- assembly -----------------------------------------------------------------------------
    def internal_force(self, u: np.ndarray) -> np.ndarray:
        """f_int(u) = int P(F) : grad v (in E units)."""
        P = self._m.P(self._F3(self._grad_u(u)))[: self.dim, : self.dim]
        g = self._scalar_grads()
        fe = np.einsum("cjEq,ajEq,Eq->acE", P, g, self.basis.dx) * self.thickness  # (nb, dim, ne)
        dofs = self.sbasis.element_dofs[:, None, :] * self.dim + np.arange(self.dim)[None, :, None]
        return np.bincount(dofs.ravel(), weights=fe.ravel(), minlength=self.N)

    def tangent(self, u: np.ndarray) -> sp.csr_matrix:
        """K(u) = int dP(F)[grad du] : grad v (in E units), assembled element by element, vectorized."""
        Hu = self._grad_u(u)
        F3 = self._F3(Hu)
        d = self.dim
        # 4th-order tangent A[c, j, k, l] = dP_cj / dF_kl, restricted to the in-plane block in 2D
        A = np.empty((d, d, d, d) + Hu.shape[2:])
        for k in range(d):
            for l in range(d):
                E = np.zeros((3, 3) + Hu.shape[2:])
                E[k, l] = 1.0
                A[:, :, k, l] = self._m.dP(F3, E)[:d, :d]
        return self._assemble_A(A)

    def _assemble_A(self, A) -> sp.csr_matrix:
        g = self._scalar_grads()
        d = self.dim
        T1 = np.einsum("cjklEq,blEq,Eq->cjkbEq", A, g, self.basis.dx, optimize=True)
        Ke = np.einsum("ajEq,cjkbEq->ackbE", g, T1, optimize=True) * self.thickness  # (nb, d, d, nb, ne)
        nb = g.shape[0]
        dofs = (self.sbasis.element_dofs[:, None, :] * d + np.arange(d)[None, :, None]).reshape(nb * d, -1)
        Ke = Ke.transpose(0, 1, 3, 2, 4).reshape(nb * d, nb * d, -1)
        rows = np.broadcast_to(dofs[:, None, :], Ke.shape).ravel()
        cols = np.broadcast_to(dofs[None, :, :], Ke.shape).ravel()
        K = sp.coo_matrix((Ke.ravel(), (rows, cols)), shape=(self.N, self.N)).tocsr()
        K.sum_duplicates()
        return K

    def stiffness(self) -> sp.csr_matrix:
        """Linear(ized) stiffness at u = 0, in E units (K_physical = E * stiffness())."""
        if self._K_lin is None:
            self._K_lin = self.tangent(np.zeros(self.N))
        return self._K_lin

    # -- loads ----------------------------------------------------------------------------------
    def vertex_dofs(self, vertex: int | NDArray[np.integer]) -> NDArray[np.int64]:
        """(dim,) or (n, dim) global dofs of mesh vertices."""
        return self.basis.nodal_dofs[:, vertex].T

    def nearest_vertex(self, point) -> int:
        p = np.asarray(point, dtype=np.float64).reshape(self.dim, 1)
        return int(np.argmin(np.sum((self.mesh.p - p) ** 2, axis=0)))

    def point_load(self, point, force) -> np.ndarray:
        """Nodal force at the vertex nearest ``point`` (newtons)."""
        f = np.zeros(self.N)
        f[self.vertex_dofs(self.nearest_vertex(point))] += np.asarray(force, dtype=np.float64)
        return f

    def consistent_point_load(self, point, force) -> np.ndarray:
        """Nodal forces of a point force at ``point`` (newtons), anywhere in the mesh: each node takes its shape
        function's value there (the load's virtual work is exact; at a vertex it is that vertex's alone)."""
        S = self.sbasis.probes(np.asarray(point, dtype=np.float64).reshape(self.dim, 1)).tocoo()
        f = np.zeros(self.N)
        F = np.asarray(force, dtype=np.float64)
        for k, w in zip(S.col, S.data):
            f[self.dim * k:self.dim * k + self.dim] += w * F  # vector dofs are interleaved per scalar node
        return f

    def vertices_in(self, region: RegionSpec) -> NDArray[np.int64]:
        return np.flatnonzero(Region.from_spec(region).mask(self.mesh.p, self.bounds))

    def traction(self, region, vector, within=None) -> np.ndarray:
        """Consistent nodal forces of a uniform traction (force per area, per length in 2D) on boundary facets.

        ``within(x)`` optionally restricts the facets further (facet midpoints).
        """
        region = Region.from_spec(region)
        vec = np.asarray(vector, dtype=np.float64)

        def test(x):
            m = region.mask(x, self.bounds)
            return m & within(x) if within is not None else m

        facets = self.mesh.facets_satisfying(test, boundaries_only=True)
        if len(facets) == 0:
            raise FemError(f"no boundary facets in the traction region {region}")
        fb = skfem.FacetBasis(self.mesh, self.basis.elem, facets=facets, intorder=2 * self.order + 1)

        @skfem.LinearForm
        def load(v, w):
            return sum(vec[i] * v[i] for i in range(self.dim))

        return load.assemble(fb) * self.thickness

    def area(self, region, within=None) -> float:
        region = Region.from_spec(region)

        def test(x):
            m = region.mask(x, self.bounds)
            return m & within(x) if within is not None else m

        facets = self.mesh.facets_satisfying(test, boundaries_only=True)
        if len(facets) == 0:
            return 0.0
        sb = skfem.FacetBasis(self.mesh, self.sbasis.elem, facets=facets)

        @skfem.Functional
        def one(w):
            return 1.0 + 0 * w.x[0]

        return float(one.assemble(sb)) * self.thickness

    def patch_load(self, region: RegionSpec, center: ArrayLike, radius: float,
                   total_force: ArrayLike) -> NDArray[np.float64]:
        """A disk of uniform pressure (the foam beam's lead disks): total force exactly ``total_force``."""
        c = np.asarray(center, dtype=np.float64).reshape(-1, 1)
        F = np.asarray(total_force, dtype=np.float64)
        face = Region.from_spec(region).face
        normal_axis = FACES[face][0] if face else None

        def within(x):
            d = x - c
            if normal_axis is not None:
                d[normal_axis] = 0.0
            return np.sqrt(np.sum(d ** 2, axis=0)) <= radius

        a = self.area(region, within)
        if a <= 0:
            raise FemError(f"the load patch of radius {radius} at {c.ravel().tolist()} covers no boundary facet "
                           "(mesh too coarse or centre off the surface)")
        return self.traction(region, F / a, within)

    # -- solves ---------------------------------------------------------------------------------
    def _solve_free(self, K: sp.csr_matrix, r: np.ndarray) -> np.ndarray:
        x = np.zeros(self.N)
        Kff = K[self.free][:, self.free]
        with warnings.catch_warnings():
            warnings.simplefilter("error", spla.MatrixRankWarning)
            try:
                x[self.free] = spla.spsolve(Kff.tocsc(), r[self.free])
            except (spla.MatrixRankWarning, RuntimeError) as e:
                raise FemError(f"the stiffness matrix is singular ({e}); check supports and material") from None
        if not np.all(np.isfinite(x)):
            raise FemError("the linear solve returned NaN/inf (singular or ill-conditioned stiffness)")
        return x

    def solve_linear(self, f: np.ndarray) -> np.ndarray:
        """Linear elastic displacement for loads ``f`` (newtons)."""
        return self._solve_free(self.stiffness(), np.asarray(f) * self._scale)

    def solve(self, f: NDArray[np.float64], steps: int = 10, tol: float = 1e-9, max_iter: int = 25,
              u0: NDArray[np.float64] | None = None, path: list[NDArray[np.float64]] | None = None,
              min_step: float = 1e-4,
              progress: Callable[[int], object] | None = None,
              u_fixed: NDArray[np.float64] | None = None) -> tuple[NDArray[np.float64], SolveInfo]:
        """Newton with load stepping: loads (and prescribed displacements ``u_fixed`` on the fixed dofs)
        grow linearly over ``steps`` increments; ``path`` collects u after each increment (the
        pseudo-time snapshots)."""
        f = np.asarray(f, dtype=np.float64)
        uf = np.zeros(self.N) if u_fixed is None else np.asarray(u_fixed, dtype=np.float64)
        states = [((k + 1) / steps * f, (k + 1) / steps * uf) for k in range(steps)]
        return self.solve_states(states, tol, max_iter, u0, path, min_step, progress)

    def solve_states(self, states: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]], tol: float = 1e-9,
                     max_iter: int = 25, u0: NDArray[np.float64] | None = None,
                     path: list[NDArray[np.float64]] | None = None, min_step: float = 1e-3,
                     progress: Callable[[int], object] | None = None) -> tuple[NDArray[np.float64], SolveInfo]:
        """Follow a sequence of load states [(f, u_fixed), ...] (newtons; metres on the fixed dofs),
        interpolating linearly between consecutive states and halving the sub-step when Newton fails."""
        u = np.zeros(self.N) if u0 is None else np.array(u0, dtype=np.float64)
        f_prev = np.zeros(self.N)
        uf_prev = u[self.fixed].copy() if u0 is not None else np.zeros(len(self.fixed))
        info = SolveInfo(False, 0, 0)
        for k, (f_t, uf_t) in enumerate(states):
            f_t = np.asarray(f_t, dtype=np.float64) * self._scale
            uf_t = np.asarray(uf_t, dtype=np.float64)[self.fixed]
            fmax = max(float(np.linalg.norm(f_t[self.free])), float(np.linalg.norm(f_prev[self.free])), 1e-300)
            # displacement-driven (no load): None, _newton then uses a stiffness-scaled norm
            fnorm = None if fmax <= 1e-300 else fmax
            a, da = 0.0, 1.0
            while a < 1.0 - 1e-12:
                b = min(1.0, a + da)
                f_b = f_prev + b * (f_t - f_prev)
                uf_b = uf_prev + b * (uf_t - uf_prev)
                u_try, ok, its, res = self._newton(u, f_b, uf_b, fnorm, tol, max_iter)
                info.newton_iterations += its
                info.residuals.append(res)
                if ok:
                    u, a = u_try, b
                    info.steps += 1
                    da = min(2 * da, 1.0)
                else:
                    da *= 0.5
                    if da < min_step:
                        info.message = (f"Newton did not converge between load states {k} and {k + 1} "
                                        f"(at {a:.4f} of the way, residual {res:.2e}): the load may exceed what the "
                                        "model can carry (buckling, snap-through) or elements invert")
                        raise FemError(info.message)
            f_prev, uf_prev = f_t, uf_t
            if path is not None:
                path.append(u.copy())
            if progress:
                progress(k + 1)
        info.converged = True
        return u, info

    def _newton(self, u, f, u_fixed, fnorm, tol, max_iter):
        """Newton on R(u) = f_int(u) - f with u = u_fixed on the fixed dofs (the first step carries the
        prescribed increment). Converged when the relative residual is below ``tol``, or when the update
        stalled at round-off (|du| < 1e-12 |u|) with the residual below sqrt(tol): slender structures
        have a residual floor set by their stiffness ratio, not by the iteration."""
        u = u.copy()
        duc = u_fixed - u[self.fixed]
        pending_bc = bool(np.any(duc != 0))
        res, step = np.inf, np.inf
        for it in range(max_iter + 1):
            r = self.internal_force(u) - f
            ref = fnorm if fnorm is not None else max(np.linalg.norm(r[self.fixed]), 1e-300)
            res = np.linalg.norm(r[self.free]) / ref
            if not np.isfinite(res):
                return u, False, it, res
            if not pending_bc and (res < tol
                                   or (step <= 1e-12 * max(np.linalg.norm(u), 1e-300) and res < np.sqrt(tol))):
                return u, True, it, res
            if it == max_iter:
                break
            K = self.tangent(u)
            rhs = -r
            if pending_bc:
                rhs = rhs - K[:, self.fixed] @ duc
            try:
                du = self._solve_free(K, rhs)
            except FemError:
                return u, False, it, res
            if pending_bc:
                du[self.fixed] = duc
            alpha = 1.0
            for _ in range(8):
                trial = u + alpha * du
                if self.min_jacobian(trial) > 0:
                    break
                alpha *= 0.5
            else:
                return u, False, it, res
            if pending_bc and alpha < 1.0:
                return u, False, it, res  # the prescribed increment itself inverts elements: smaller step
            pending_bc = False
            step = alpha * np.linalg.norm(du)
            u = trial
        return u, False, max_iter, res

    def energy(self, u: np.ndarray) -> float:
        """The stored energy W_int(u) = int Psi(F) dV (in E units, as the internal force: its gradient)."""
        Psi = self._m.energy(self._F3(self._grad_u(u)))
        return float(np.sum(Psi * self.basis.dx)) * self.thickness

    def min_jacobian(self, u: np.ndarray) -> float:
        if isinstance(self.material, mat.LinearElastic):
            return 1.0
        return float(mat.det3(self._F3(self._grad_u(u))).min())

    # -- outputs ------------------------------------------------------------------------------------
    def vertex_displacement(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n_vertices, dim) displacement at the mesh vertices."""
        return u[self.basis.nodal_dofs].T.copy()

    def stress(self, u: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
        """Cauchy stress (Voigt xx, yy, zz, xy, yz, xz; pascals) and von Mises at the vertices.

        Quadrature-point values are L2-projected on the linear scalar space with a lumped mass.
        """
        F3 = self._F3(self._grad_u(u))
        if self.dim == 2 and self.plane == "stress":
            sig = self._m.P(F3)
            sig[2, 2] = 0.0
        else:
            sig = self._m.cauchy(F3)
        sig = sig / self._scale
        vm = mat.von_mises(sig)
        lin_el = {2: {skfem.MeshTri1: skfem.ElementTriP1, skfem.MeshQuad1: skfem.ElementQuad1},
                  3: {skfem.MeshTet1: skfem.ElementTetP1, skfem.MeshHex1: skfem.ElementHex1}}[self.dim]
        el = next(v for k, v in lin_el.items() if isinstance(self.mesh, k))
        pb = skfem.Basis(self.mesh, el(), quadrature=self.basis.quadrature)

        @skfem.LinearForm
        def proj(v, w):
            return w["s"] * v

        @skfem.BilinearForm
        def mass(a, b, w):
            return a * b

        M = np.asarray(mass.assemble(pb).sum(axis=1)).ravel()
        comps = [(0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2)]
        out = np.empty((self.mesh.p.shape[1], 6))
        for k, (i, j) in enumerate(comps):
            out[:, k] = proj.assemble(pb, s=sig[i, j])[: self.mesh.p.shape[1]] / M[: self.mesh.p.shape[1]]
        vmv = proj.assemble(pb, s=vm)[: self.mesh.p.shape[1]] / M[: self.mesh.p.shape[1]]
        return {"cauchy": out, "von_mises": vmv}
