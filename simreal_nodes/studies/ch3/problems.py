"""The three benchmark problems of thesis §3.3, as discrete full-order models (FOM) in separated form.

1. :func:`cantilever` (§3.3.1): 2D linear elasticity on Ω = [0, 9] × [0, 1] m, Δx = Δy = Δs = 0.1 m,
   E = 1000, ν = 0.3 (plane stress, unit thickness), a vertical unit load F = −1 at position s on the upper
   edge, clamped at x = 0. Doubly weak form over Ω × Γ̄ (discrete: one column of loads per s node)::

       ∫_Γ̄ ∫_Ω ∇ₛu* : σ(u) dΩ ds = ∫_Γ̄ ∫_Γt u* · t dΓ ds,    t = F δ(x − s) e_y

   → K U = T,  U (n_dof × n_s),  T[:, j] = F e_y at the top node x = s_j.

2. :func:`heat` (§3.3.2, Idelsohn's benchmark): ρ c_p ∂ₜu − ∇·(k∇u) = f(x, t) on Ω = [0, π], I = [0, 1],
   u = 0 on ∂Ω and at t = 0, with the moving source

       f = A cos(π/L (x − x₀(t)))  for t_i < t < t_f and |x − x₀(t)| < L/2,
       x₀(t) = x_i + (x_f − x_i)(t − t_i)/(t_f − t_i)

   and A = 100, L = 0.15, t_i = 0.2, t_f = 0.7, x_i = 2π/7, k = 0.05, ρ = c_p = 1; N_x = 301, N_t = 401.
   Linear finite elements in x, implicit Euler in t:  M (uⁿ − uⁿ⁻¹)/Δt + k K uⁿ = M f(·, tⁿ), i.e. in matrix
   form over the unknown columns n = 1 … N_t−1:   M U Dᵀ + k K U = B  with D the backward-difference matrix.

3. The parametric version (§3.3.3): the same with k ∈ [k_min, k_max] as a third coordinate, U (x, t, k).

:func:`heat_series` is the independent exact solution (Fourier sine series with closed-form time integrals)
used to validate the heat FOM, and :func:`euler_bernoulli_tip` the beam-theory tip deflection of Fig. 3.5c.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import skfem
from skfem.helpers import ddot, sym_grad, trace

# ------------------------------------------------------------------------------------------------
# 1. Cantilever with a moving load


@dataclass
class Cantilever:
    mesh: skfem.MeshQuad
    basis: skfem.Basis
    K: sp.csr_matrix  # stiffness on all dofs
    free: np.ndarray  # unconstrained dofs (clamp at x = 0)
    s: np.ndarray  # load positions (top nodes), m
    T: sp.csr_matrix  # (n_dof, n_s) load columns
    uy_dofs: np.ndarray  # vertical-displacement dof of every node
    E: float
    nu: float
    F: float
    L: float
    H: float

    def solve_fom(self) -> np.ndarray:
        """Full-order displacements for every load position: (n_dof, n_s)."""
        U = np.zeros((self.K.shape[0], len(self.s)))
        lu = spla.splu(self.K[self.free][:, self.free].tocsc())
        U[self.free] = lu.solve(self.T[self.free].toarray())
        return U

    @property
    def tip_dof(self) -> int:
        """Vertical dof of the node at (L, H), where the load sits for s = L."""
        p = self.mesh.p
        node = int(np.argmin((p[0] - self.L) ** 2 + (p[1] - self.H) ** 2))
        return int(self.uy_dofs[node])


def cantilever(L: float = 9.0, H: float = 1.0, h: float = 0.1, E: float = 1000.0, nu: float = 0.3,
               F: float = -1.0) -> Cantilever:
    nx, ny = round(L / h), round(H / h)
    mesh = skfem.MeshQuad.init_tensor(np.linspace(0, L, nx + 1), np.linspace(0, H, ny + 1))
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementQuad1()))
    lam = E * nu / (1 - nu ** 2)  # plane stress: σ = λ' tr(ε) I + 2 μ ε with λ' = Eν/(1 − ν²)
    mu = E / (2 * (1 + nu))

    @skfem.BilinearForm
    def elasticity(u, v, w):
        eps_u, eps_v = sym_grad(u), sym_grad(v)
        return ddot(lam * trace(eps_u) * np.eye(2)[:, :, None, None] + 2 * mu * eps_u, eps_v)

    K = elasticity.assemble(basis).tocsr()
    clamped = basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).all()
    free = np.setdiff1d(np.arange(K.shape[0]), clamped)
    nodal = basis.nodal_dofs  # (2, n_nodes)
    top = np.where(np.isclose(mesh.p[1], H))[0]
    top = top[np.argsort(mesh.p[0, top])]
    s = mesh.p[0, top]
    T = sp.csr_matrix((np.full(len(top), F), (nodal[1, top], np.arange(len(top)))), shape=(K.shape[0], len(top)))
    return Cantilever(mesh, basis, K, free, s, T, nodal[1], E, nu, F, L, H)


def euler_bernoulli_tip(c: Cantilever) -> float:
    """Tip deflection F L³ / (3 E I) of the 1D Euler–Bernoulli–Navier cantilever, I = b H³/12, b = 1."""
    return c.F * c.L ** 3 / (3 * c.E * c.H ** 3 / 12)


# ------------------------------------------------------------------------------------------------
# 2-3. Idelsohn's benchmark (1D transient heat with a moving source)


@dataclass
class HeatParams:
    A: float = 100.0
    L: float = 0.15
    t_i: float = 0.2
    t_f: float = 0.7
    x_i: float = 2 * np.pi / 7
    x_f: float = 5 * np.pi / 7
    k: float = 0.05
    rho_cp: float = 1.0
    length: float = np.pi
    duration: float = 1.0


@dataclass
class Heat:
    p: HeatParams
    x: np.ndarray  # (Nx,) nodes
    t: np.ndarray  # (Nt,) time nodes, t[0] = 0 holds the initial condition
    M: sp.csr_matrix  # mass on the interior nodes (ρ c_p included)
    K: sp.csr_matrix  # stiffness on the interior nodes for k = 1
    B: np.ndarray  # (n_int, Nt) consistent source loads M f(·, tⁿ); column 0 unused
    k: np.ndarray = field(default_factory=lambda: np.array([0.05]))  # conductivity grid (parametric case)

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    @property
    def interior(self) -> slice:
        return slice(1, len(self.x) - 1)

    def solve_fom(self, k: float | None = None) -> np.ndarray:
        """Implicit Euler time stepping; returns u on all nodes and times, (Nx, Nt)."""
        k = self.p.k if k is None else k
        A = (self.M / self.dt + k * self.K).tocsc()
        lu = spla.splu(A)
        U = np.zeros((len(self.x), len(self.t)))
        u = np.zeros(len(self.x) - 2)
        for n in range(1, len(self.t)):
            u = lu.solve(self.M @ u / self.dt + self.B[:, n])
            U[1:-1, n] = u
        return U

    def solve_fom_parametric(self) -> np.ndarray:
        """(Nx, Nt, Nk) on the conductivity grid ``self.k``."""
        return np.stack([self.solve_fom(float(k)) for k in self.k], axis=2)

    def time_operator(self, n0: int, n1: int) -> np.ndarray:
        """Backward-difference matrix D over the unknown time nodes n0+1 … n1 (u at n0 is the initial state)."""
        n = n1 - n0
        return (np.eye(n) - np.eye(n, k=-1)) / self.dt


def source(p: HeatParams, x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """f(x, t) of §3.3.2 on a grid: (len(x), len(t))."""
    x = np.asarray(x)[:, None]
    t = np.asarray(t)[None, :]
    x0 = p.x_i + (p.x_f - p.x_i) * (t - p.t_i) / (p.t_f - p.t_i)
    on = (t > p.t_i) & (t < p.t_f) & (np.abs(x - x0) < p.L / 2)
    return np.where(on, p.A * np.cos(np.pi / p.L * (x - x0)), 0.0)


def heat(Nx: int = 301, Nt: int = 401, x_f: float = 5 * np.pi / 7, k: float = 0.05,
         k_grid: np.ndarray | None = None, **overrides) -> Heat:
    p = HeatParams(x_f=x_f, k=k, **overrides)
    x = np.linspace(0.0, p.length, Nx)
    t = np.linspace(0.0, p.duration, Nt)
    mesh = skfem.MeshLine(x)
    basis = skfem.Basis(mesh, skfem.ElementLineP1())

    @skfem.BilinearForm
    def mass(u, v, w):
        return u * v

    @skfem.BilinearForm
    def laplace(u, v, w):
        return u.grad[0] * v.grad[0]

    Mfull = mass.assemble(basis).tocsr()
    Kfull = laplace.assemble(basis).tocsr()
    # skfem numbers MeshLine nodes in the order given: interior = 1 … Nx−2
    inner = np.arange(1, Nx - 1)
    M = p.rho_cp * Mfull[inner][:, inner].tocsr()
    K = Kfull[inner][:, inner].tocsr()
    B = (Mfull @ source(p, x, t))[inner]  # consistent load of the interpolated source
    kg = np.array([k]) if k_grid is None else np.asarray(k_grid, dtype=np.float64)
    return Heat(p, x, t, M, K, B, kg)


def heat_series(p: HeatParams, x: np.ndarray, t: np.ndarray, k: float | None = None, n_terms: int = 2000) -> np.ndarray:
    """Exact solution of the continuous problem as a sine series (independent of the FE/time discretisation).

    u = Σₙ bₙ(t) sin(n x) with ρc_p bₙ' + k n² bₙ = fₙ(t), fₙ = (2/π) ∫ f sin(n x) dx. For the cosine bump,
    fₙ(τ) = (2A/π) Iₙ sin(n x₀(τ)), Iₙ = ∫_{−L/2}^{L/2} cos(πy/L) cos(ny) dy = cos(nL/2) 2a/(a² − n²), a = π/L,
    and the Duhamel integral of e^{−λ(t−τ)} sin(n x₀(τ)) over the active window is closed form.
    """
    if abs(p.length - np.pi) > 1e-12:
        raise ValueError("the series solution is written for Ω = [0, π]")
    k = p.k if k is None else k
    n = np.arange(1, n_terms + 1, dtype=np.float64)
    a = np.pi / p.L
    with np.errstate(divide="ignore", invalid="ignore"):
        In = np.cos(n * p.L / 2) * 2 * a / (a ** 2 - n ** 2)
    lam = k * n ** 2 / p.rho_cp
    v = (p.x_f - p.x_i) / (p.t_f - p.t_i)
    out = np.zeros((len(x), len(t)))
    S = np.sin(np.outer(n, x))  # (n, Nx)
    for j, tj in enumerate(t):
        ta, tb = p.t_i, min(tj, p.t_f)
        if tb <= ta:
            continue
        # ∫_{ta}^{tb} e^{−λ(t−τ)} e^{iφ(τ)} dτ = [e^{−λ(t−τ)} e^{iφ(τ)} / (λ + i n v)]_{ta}^{tb}, φ = n x₀(τ)
        phi_b = n * (p.x_i + v * (tb - p.t_i))
        phi_a = n * p.x_i
        z = (np.exp(-lam * (tj - tb) + 1j * phi_b) - np.exp(-lam * (tj - ta) + 1j * phi_a)) / (lam + 1j * n * v)
        b = (2 * p.A / np.pi) * In * np.imag(z) / p.rho_cp
        out[:, j] = b @ S
    return out
