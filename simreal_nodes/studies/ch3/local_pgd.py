"""Local PGD (thesis ch. 3): PGD on sub-domains of the time / parameter axes.

A discrete problem on a tensor grid (x, y₁, …, y_D) whose operator is a sum of Kronecker products,

    A(U) = Σ_a  A_a^x ⊗ A_a^{1} ⊗ … ⊗ A_a^{D},      A(U) = B,

(cantilever: K ⊗ I_s; heat: M ⊗ D_t + k K ⊗ I_t; parametric heat: M ⊗ D_t ⊗ I_k + K ⊗ I_t ⊗ diag(k)) is
solved for U ≈ Σ_i F_i(x) ⊗ G_i¹(y₁) ⊗ … by the greedy enrichment of Alg. 2.1: each new product R ⊗ S¹ ⊗ …
by an alternating-direction fixed point, every factor from the Galerkin projection of the residual on the
others:  (Σ_a Π_{l≠d} ⟨f_l, A_a^l f_l⟩ A_a^d) f_d = Res ×_{l≠d} f_l.

ℓ-PGD splits the partitioned axes into sub-domains and runs that PGD on each (:class:`LocalSolution`).
On a time axis the end state of one sub-domain is the initial condition of the next (Fig. 3.1): it enters
the first backward-difference row of the next sub-domain's right-hand side, so the assembled solution is
continuous in the time-discrete sense. Three partitionings:

- :func:`constant_partition` (Cℓ-PGD, §3.2.2): uniform sub-domains;
- :func:`mno_partition` (MNOℓ-PGD, Alg. 3.1): each sub-domain as long as possible with at most M local
  modes at the tolerance (one partitioned axis only);
- :func:`kpca_partition` (kℓ-PGD, Alg. 3.2): Gaussian-kernel PCA of a first constant-partition solution,
  Hausdorff distances between the k-PCA curves of neighbouring particularizations, ε-neighbourhoods per
  partitioned axis → a tensor grid of boxes; works with any number of partitioned axes.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import reduce
from typing import Any, cast

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial.distance import pdist


class PartitionWarning(UserWarning):
    """A partitioning request was degenerate; what was done instead is in the message."""


# ------------------------------------------------------------------------------------------------
# Greedy PGD on a Kronecker-sum operator (dense residual: the benchmark sizes are small)

Op = sp.csr_matrix | np.ndarray  # matrix (dense, or sparse as CSR), or a 1D array for a diagonal operator


def _apply(A: Op, v: np.ndarray) -> np.ndarray:
    return A * v if (isinstance(A, np.ndarray) and A.ndim == 1) else A @ v


def _quad(A: Op, u: np.ndarray, v: np.ndarray) -> float:
    return float(u @ _apply(A, v))


def _lhs_solve(terms: list[tuple[float | np.floating[Any], Op]], rhs: np.ndarray) -> np.ndarray:
    if all(isinstance(A, np.ndarray) and A.ndim == 1 for _, A in terms):
        d = sum(c * cast(np.ndarray, A) for c, A in terms)  # cast: every operator is a 1D array (checked above)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(np.abs(d) > 0, rhs / d, 0.0)
    mats = [c * (sp.diags(A) if isinstance(A, np.ndarray) and A.ndim == 1 else sp.csr_matrix(A)) for c, A in terms]
    return spla.spsolve(reduce(lambda a, b: a + b, mats).tocsc(), rhs)


def _contract(T: np.ndarray, vecs: list[np.ndarray | None]) -> np.ndarray:
    """T contracted with vecs[d] on every axis d whose vector is given (the free axis keeps its place)."""
    out = T
    for d in reversed(range(len(vecs))):
        v = vecs[d]
        if v is not None:
            out = np.tensordot(out, v, axes=([d], [0]))
    return out


def _outer(vs: list[np.ndarray]) -> np.ndarray:
    return reduce(np.multiply.outer, vs)


@dataclass
class Separated:
    """U ≈ Σ_i Π_d factors[d][i] on a grid; ``factors[d]``: (n_modes, n_d)."""

    factors: list[np.ndarray]
    indicator: list[float] = field(default_factory=list)  # ‖new term‖ / ‖U_n‖ after each enrichment
    fp_iterations: list[int] = field(default_factory=list)

    @property
    def n_modes(self) -> int:
        return self.factors[0].shape[0]

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(f.shape[1] for f in self.factors)

    @property
    def storage(self) -> int:
        """Numbers stored (Σ_d n_d per mode)."""
        return int(sum(f.size for f in self.factors))

    def full(self, n_modes: int | None = None) -> np.ndarray:
        n = self.n_modes if n_modes is None else min(n_modes, self.n_modes)
        if n == 0:
            return np.zeros(self.shape)
        letters = "abcdefgh"[: len(self.factors)]
        return np.einsum(",".join("m" + c for c in letters) + "->" + letters, *[f[:n] for f in self.factors])


def _op_T(A: Op) -> Op:
    return A if (isinstance(A, np.ndarray) and A.ndim == 1) else sp.csr_matrix(A).T.tocsr()


def _op_mul(A: Op, B: Op) -> Op:
    """A B for per-axis operators (1D arrays are diagonal matrices)."""
    da, db = isinstance(A, np.ndarray) and A.ndim == 1, isinstance(B, np.ndarray) and B.ndim == 1
    if da and db:
        return A * B
    if da:  # cast: da says A is a 1D array
        return sp.diags(cast(np.ndarray, A)) @ sp.csr_matrix(B)
    if db:  # cast: db says B is a 1D array
        return sp.csr_matrix(A) @ sp.diags(cast(np.ndarray, B))
    return (sp.csr_matrix(A) @ sp.csr_matrix(B)).tocsr()


def normal_equations(ops: list[list[Op]], B: np.ndarray) -> tuple[list[list[Op]], np.ndarray]:
    """AᵀA U = AᵀB for A = Σ_a ⊗_d ops[a][d], again a sum of Kronecker products (Σ_a Σ_b ⊗_d A_aᵈᵀ A_bᵈ):
    symmetric positive definite whatever A is, so Galerkin PGD on it minimises the residual ‖A U − B‖."""
    B = np.asarray(B, dtype=np.float64)
    D = B.ndim
    nops = [[_op_mul(_op_T(a[d]), b[d]) for d in range(D)] for a in ops for b in ops]
    rhs = np.zeros_like(B)
    for a in ops:
        t = B
        for d in range(D):  # A_aᵈᵀ along axis d
            t = np.moveaxis(_apply_axis0(_op_T(a[d]), np.moveaxis(t, d, 0)), 0, d)
        rhs += t
    return nops, rhs


def _apply_axis0(A: Op, T: np.ndarray) -> np.ndarray:
    """A applied along axis 0 of T."""
    flat = T.reshape(T.shape[0], -1)
    out = A[:, None] * flat if (isinstance(A, np.ndarray) and A.ndim == 1) else A @ flat
    return np.asarray(out).reshape((out.shape[0],) + T.shape[1:])


def pgd(ops: list[list[Op]], B: np.ndarray, tol: float = 1e-4, max_modes: int = 500, max_fp: int = 25,
        fp_tol: float = 1e-6, seed: int = 0, update: bool = False, residual: str = "galerkin") -> Separated:
    """Greedy PGD for Σ_a ⊗_d ops[a][d] U = B. Stops when the new term's norm falls below ``tol`` times the
    norm of the sum so far (an a-priori indicator: the reference solution is never used).

    ``residual="galerkin"`` (the thesis's PGD): each factor from the Galerkin projection of the residual. For a
    non-symmetric operator (a time derivative) the greedy terms are then not minimisers of anything and the
    enrichment can diverge: it does on the 3-axis parametric heat problem. ``residual="minimal"``: PGD on the
    normal equations (:func:`normal_equations`), each term minimises the residual norm, so the residual
    decreases monotonically (at the price of a squared condition number).

    ``update`` (two axes only): after each enrichment the space modes are orthonormalised and *all* the
    second-axis functions recomputed from the Galerkin projection on them (the classical PGD "update" step;
    on a time axis a reduced time stepping). Plain greedy PGD is what the thesis's global-PGD counts use."""
    B = np.asarray(B, dtype=np.float64)
    if residual not in ("galerkin", "minimal"):
        raise ValueError(f"residual must be 'galerkin' or 'minimal', not '{residual}'")
    if residual == "minimal":
        ops, B = normal_equations(ops, B)
    D = B.ndim
    if update and D == 2:
        return _pgd_updated(ops, B, tol, max_modes, max_fp, fp_tol, seed)
    shape = B.shape
    res = B.copy()
    rng = np.random.default_rng(seed)
    fac: list[list[np.ndarray]] = [[] for _ in range(D)]
    out = Separated([np.zeros((0, n)) for n in shape])
    if not np.any(B):
        return out  # nothing drives this sub-domain: the solution is zero (e.g. before the source starts)
    gram = np.zeros((0, 0))
    for _ in range(max_modes):
        f = [np.ones(n) + 0.1 * rng.standard_normal(n) for n in shape]
        f = [v / np.linalg.norm(v) for v in f]
        prev = None
        it = 0
        for it in range(1, max_fp + 1):  # noqa: B007 - read after the loop: the fixed-point iterations used
            for d in range(D):
                coef = [np.prod([_quad(ops_a[l], f[l], f[l]) for l in range(D) if l != d]) for ops_a in ops]
                rhs = _contract(res, [None if l == d else f[l] for l in range(D)])
                v = _lhs_solve([(c, ops_a[d]) for c, ops_a in zip(coef, ops)], rhs)
                nv = np.linalg.norm(v)
                if d < D - 1 and nv > 0:
                    v = v / nv
                f[d] = v
            if not all(np.all(np.isfinite(v)) for v in f) or np.linalg.norm(f[-1]) == 0:
                break
            if prev is not None and _rank1_distance(prev, f) < fp_tol:
                break
            prev = [v.copy() for v in f]
        if not all(np.all(np.isfinite(v)) for v in f) or np.linalg.norm(f[-1]) == 0:
            break
        # Gram of the terms for ‖U_n‖ (products of per-axis inner products)
        g = np.prod([np.array([v @ f[d] for v in fac[d]] + [f[d] @ f[d]]) for d in range(D)], axis=0)
        if g[-1] <= 1e-24 * max(gram.sum() + g[-1] + 2 * g[:-1].sum(), 1e-300):
            break  # the residual is at round-off: a new term would be noise
        for d in range(D):
            fac[d].append(f[d])
        gram = np.pad(gram, ((0, 1), (0, 1)))
        gram[-1, :] = gram[:, -1] = g
        ind = float(np.sqrt(max(g[-1], 0.0) / max(gram.sum(), 1e-300)))
        out.indicator.append(ind)
        out.fp_iterations.append(it)
        for ops_a in ops:
            res -= _outer([_apply(ops_a[d], f[d]) for d in range(D)])
        if ind < tol:
            break
    out.factors = [np.asarray(fd).reshape(len(fd), n) for fd, n in zip(fac, shape)]
    return out


def _project_second(ops: list[list[Op]], Q: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Second-axis functions G (n, n_y) of U = Qᵀ G from Σ_a (Q A_aˣ Qᵀ) G A_aʸᵀ = Q B, for second-axis
    operators that are diagonal or lower triangular (identity, backward differences): forward substitution."""
    n, ny = Q.shape[0], B.shape[1]
    Ar = [Q @ _apply(a[0], Q.T) for a in ops]
    C = Q @ B
    Ay = [sp.diags(a[1]).tocsr() if (isinstance(a[1], np.ndarray) and a[1].ndim == 1) else sp.csr_matrix(a[1])
          for a in ops]
    if any(sp.triu(A, 1).nnz for A in Ay):
        raise ValueError("the update step needs diagonal or lower-triangular second-axis operators")
    diag = [A.diagonal() for A in Ay]
    G = np.zeros((n, ny))
    lu_cache: dict[tuple, tuple] = {}
    for j in range(ny):
        rhs = C[:, j].copy()
        for A, R in zip(Ay, Ar):
            row = A.getrow(j)
            for i, v in zip(row.indices, row.data):
                if i < j:
                    rhs -= v * (R @ G[:, i])
        key = tuple(float(d[j]) for d in diag)
        if key not in lu_cache:
            lu_cache[key] = sla.lu_factor(sum(d * R for d, R in zip(key, Ar)))
        G[:, j] = sla.lu_solve(lu_cache[key], rhs)
    return G


def _pgd_updated(ops, B, tol, max_modes, max_fp, fp_tol, seed) -> Separated:
    nx, ny = B.shape
    rng = np.random.default_rng(seed)
    out = Separated([np.zeros((0, nx)), np.zeros((0, ny))])
    if not np.any(B):
        return out
    res = B.copy()
    Q = np.zeros((0, nx))
    G = np.zeros((0, ny))
    for _ in range(min(max_modes, nx)):
        f = [np.ones(n) + 0.1 * rng.standard_normal(n) for n in (nx, ny)]
        f = [v / np.linalg.norm(v) for v in f]
        prev = None
        it = 0
        for it in range(1, max_fp + 1):  # noqa: B007 - read after the loop: the fixed-point iterations used
            for d in range(2):
                o = 1 - d
                coef = [_quad(a[o], f[o], f[o]) for a in ops]
                rhs = res @ f[1] if d == 0 else res.T @ f[0]
                v = _lhs_solve([(c, a[d]) for c, a in zip(coef, ops)], rhs)
                f[d] = v / np.linalg.norm(v) if (d == 0 and np.linalg.norm(v) > 0) else v
            if not all(np.all(np.isfinite(v)) for v in f):
                break
            if prev is not None and _rank1_distance(prev, f) < fp_tol:
                break
            prev = [v.copy() for v in f]
        if not all(np.all(np.isfinite(v)) for v in f) or np.linalg.norm(f[0]) == 0:
            break
        # orthonormalise the new space mode against the basis, then re-project all second-axis functions
        r = f[0] - Q.T @ (Q @ f[0])
        r -= Q.T @ (Q @ r)
        nr = np.linalg.norm(r)
        if nr < 1e-12:
            break
        Q = np.vstack([Q, r / nr])
        G = _project_second(ops, Q, B)
        # indicator: size of the rank-one correction the fixed point found (as in plain PGD), over ‖U_n‖
        ind = float(np.linalg.norm(f[0]) * np.linalg.norm(f[1]) / max(float(np.linalg.norm(G)), 1e-300))
        out.indicator.append(ind)
        out.fp_iterations.append(it)
        res = B - sum(_apply(a[0], Q.T) @ (_apply(a[1], G.T) if not (isinstance(a[1], np.ndarray) and a[1].ndim == 1)
                                            else G.T * a[1][:, None]).T for a in ops)
        if ind < tol:
            break
    out.factors = [Q, G]
    return out


def _rank1_distance(a: list[np.ndarray], b: list[np.ndarray]) -> float:
    aa = np.prod([x @ x for x in a])
    bb = np.prod([y @ y for y in b])
    ab = np.prod([x @ y for x, y in zip(a, b)])
    return float(np.sqrt(max(aa + bb - 2 * ab, 0.0) / max(bb, 1e-300)))


# ------------------------------------------------------------------------------------------------
# Problems in the form ℓ-PGD needs


class LocalProblem:
    """A discrete problem that can be solved by PGD on a box of its partitioned axes.

    ``axes``: sizes of the partitioned axes; ``time_axis``: index of the axis carrying an initial condition
    (or None). ``block(box, ic)`` returns (operators, right-hand side) on the box, ``ic`` the state entering
    it (None when the box starts at the initial time). ``end_state(sol, box)`` is what leaves the box.
    """

    axes: tuple[int, ...]
    time_axis: int | None

    def block(self, box: tuple[slice, ...], ic: np.ndarray | None) -> tuple[list[list[Op]], np.ndarray]:
        raise NotImplementedError

    def end_state(self, sol: Separated, box: tuple[slice, ...]) -> np.ndarray:
        raise NotImplementedError


class ParametricStatic(LocalProblem):
    """K U = T, U (x, s): the cantilever (operator K ⊗ I_s; sub-domains in s are independent)."""

    def __init__(self, K: sp.csr_matrix, T: np.ndarray):
        self.K = sp.csr_matrix(K)
        self.T = np.asarray(T, dtype=np.float64)
        self.axes = (self.T.shape[1],)
        self.time_axis = None

    def block(self, box, ic):
        (s,) = box
        B = self.T[:, s]
        return [[self.K, np.ones(B.shape[1])]], B


class TransientHeat(LocalProblem):
    """M U Dᵀ + K U diag(k) = B over time nodes 1 … N_t−1 (and conductivities k, if several):
    operator M ⊗ D ⊗ I_k + K ⊗ I_t ⊗ diag(k). Axis 0 of the partitioned axes is time."""

    def __init__(self, M: sp.csr_matrix, K: sp.csr_matrix, B: np.ndarray, dt: float, k: np.ndarray):
        self.M, self.K = sp.csr_matrix(M), sp.csr_matrix(K)
        self.dt = float(dt)
        self.k = np.atleast_1d(np.asarray(k, dtype=np.float64))
        self.B = np.asarray(B, dtype=np.float64)[:, 1:]  # unknown time columns
        self.parametric = len(self.k) > 1
        self.axes = (self.B.shape[1], len(self.k)) if self.parametric else (self.B.shape[1],)
        self.time_axis = 0

    def _D(self, n: int) -> sp.csr_matrix:
        # scipy-stubs types `diagonals` as one array or nested sequences of scalars, not the documented list of
        # 1D arrays of different lengths
        return sp.diags([np.ones(n), -np.ones(n - 1)], [0, -1], format="csr") / self.dt  # type: ignore[call-overload]

    def block(self, box, ic):
        t = box[0]
        kk = self.k[box[1]] if self.parametric else self.k
        nt = len(range(*t.indices(self.axes[0])))
        B = self.B[:, t]
        B = np.repeat(B[:, :, None], len(kk), axis=2) if self.parametric else B.copy()
        if ic is not None:  # M (u¹ − u⁰)/Δt: the known u⁰ moves to the right-hand side of the first row
            B[:, 0] += (self.M @ ic) / self.dt
        D, It = self._D(nt), np.ones(nt)
        if self.parametric:
            ops = [[self.M, D, np.ones(len(kk))], [self.K, It, kk]]
        else:
            ops = [[self.M, D], [float(kk[0]) * self.K, It]]
        return ops, B

    def end_state(self, sol, box):
        if sol.n_modes == 0:
            shape = (self.M.shape[0],) + ((len(range(*box[1].indices(self.axes[1]))),) if self.parametric else ())
            return np.zeros(shape)
        F, G = sol.factors[0], sol.factors[1]
        if self.parametric:
            return np.einsum("mx,m,mk->xk", F, G[:, -1], sol.factors[2])
        return F.T @ G[:, -1]


# ------------------------------------------------------------------------------------------------
# ℓ-PGD over a partition (a tensor grid of boxes)


@dataclass
class LocalSolution:
    cuts: list[np.ndarray]  # per partitioned axis: sub-domain boundaries (indices, 0 … n)
    boxes: list[tuple[slice, ...]]
    sols: list[Separated]
    offline_s: float = 0.0

    @property
    def modes(self) -> np.ndarray:
        """Local modes per box, shaped like the box grid."""
        return np.array([s.n_modes for s in self.sols]).reshape([len(c) - 1 for c in self.cuts])

    @property
    def total_modes(self) -> int:
        return int(sum(s.n_modes for s in self.sols))

    @property
    def storage(self) -> int:
        return int(sum(s.storage for s in self.sols))

    def full(self, n_modes: int | None = None) -> np.ndarray:
        """Assembled solution on the whole grid (x, partitioned axes…); ``n_modes`` caps each box."""
        shape = self.sols[0].shape[:1] + tuple(int(c[-1]) for c in self.cuts)
        U = np.zeros(shape)
        for box, s in zip(self.boxes, self.sols):
            U[(slice(None),) + box] = s.full(n_modes)
        return U


def boxes_of(cuts: list[np.ndarray]) -> list[tuple[slice, ...]]:
    """All boxes of a tensor grid of cuts, the first axis (time) outermost so initial conditions flow."""
    ranges = [[slice(int(c[i]), int(c[i + 1])) for i in range(len(c) - 1)] for c in cuts]
    out: list[tuple[slice, ...]] = [()]
    for r in ranges:
        out = [b + (s,) for b in out for s in r]
    return out


def solve_local(problem: LocalProblem, cuts: list[np.ndarray], tol: float = 1e-4, max_modes: int = 200,
                seed: int = 0, update: bool = False) -> LocalSolution:
    """ℓ-PGD on the boxes of ``cuts``; along the time axis each box starts from the end state of the
    box before it (same slices in the other axes)."""
    cuts = [np.asarray(c, dtype=int) for c in cuts]
    for c, n in zip(cuts, problem.axes):
        if c[0] != 0 or c[-1] != n or np.any(np.diff(c) <= 0):
            raise ValueError(f"cuts must increase strictly from 0 to {n}: {c.tolist()}")
    t0 = time.perf_counter()
    boxes = boxes_of(cuts)
    sols = []
    ends: dict[tuple, np.ndarray] = {}
    ta = problem.time_axis
    for box in boxes:
        ic = None
        if ta is not None and box[ta].start > 0:
            key = tuple((b.start, b.stop) for j, b in enumerate(box) if j != ta) + (box[ta].start,)
            ic = ends[key]
        ops, B = problem.block(box, ic)
        s = pgd(ops, B, tol, max_modes, seed=seed, update=update)
        sols.append(s)
        if ta is not None:
            key = tuple((b.start, b.stop) for j, b in enumerate(box) if j != ta) + (box[ta].stop,)
            ends[key] = problem.end_state(s, box)
    return LocalSolution(cuts, boxes, sols, time.perf_counter() - t0)


# ------------------------------------------------------------------------------------------------
# Cℓ-PGD


def constant_partition(n: int, parts: int) -> np.ndarray:
    """Uniform cuts of an axis of n nodes into ``parts`` sub-domains (clamped to 1 … n, with a warning)."""
    if parts < 1 or parts > n:
        warnings.warn(f"{parts} sub-domains asked on an axis of {n} nodes: using {min(max(parts, 1), n)}",
                      PartitionWarning, stacklevel=2)
        parts = min(max(parts, 1), n)
    if parts == n and n > 1:
        warnings.warn(f"as many sub-domains as nodes ({n}): each is one particularization (one mode each, "
                      "more storage than the full-order solution)", PartitionWarning, stacklevel=2)
    return np.unique(np.round(np.linspace(0, n, parts + 1)).astype(int))


# ------------------------------------------------------------------------------------------------
# MNOℓ-PGD (Alg. 3.1)


def mno_partition(problem: LocalProblem, M: int, tol: float = 1e-4, seed_length: int | None = None,
                  seed: int = 0, update: bool = False) -> tuple[list[np.ndarray], LocalSolution]:
    """Sub-domains along the (single) partitioned axis, each as long as possible while its local PGD needs
    at most ``M`` modes at ``tol``. The length search starts from ``seed_length`` and moves by doubling /
    halving then bisection (the thesis moves by ±1: same result, fewer local solves)."""
    if len(problem.axes) != 1:
        raise ValueError("MNOℓ-PGD adapts one partitioned axis; use kℓ-PGD for more (thesis §3.2.3)")
    if M < 1:
        raise ValueError("M (allowed local modes) must be ≥ 1")
    n = problem.axes[0]
    p0 = max(1, min(seed_length or max(n // 10, 1), n))
    t0 = time.perf_counter()
    cuts = [0]
    sols: list[Separated] = []
    ic = None
    ta = problem.time_axis
    while cuts[-1] < n:
        a = cuts[-1]
        cache: dict[int, Separated] = {}

        def local(p: int) -> Separated:
            if p not in cache:  # noqa: B023 - called in the same iteration
                ops, B = problem.block((slice(a, a + p),), ic)  # noqa: B023 - called in the same iteration
                cache[p] = pgd(ops, B, tol, max_modes=M + 1, seed=seed, update=update)  # noqa: B023 - same iteration
            return cache[p]  # noqa: B023 - called in the same iteration

        def fits(p: int) -> bool:
            return local(p).n_modes <= M

        p = min(p0, n - a)
        if fits(p):
            lo, hi = p, None
            while hi is None and lo < n - a:
                q = min(2 * lo, n - a)
                if fits(q):
                    lo = q
                else:
                    hi = q
        else:
            hi = p
            lo = p // 2
            while lo >= 1 and not fits(lo):
                hi, lo = lo, lo // 2
            if lo < 1:  # even one node needs more than M modes: cannot happen for one column (rank 1)
                lo = 1
        if hi is not None:
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if fits(mid):
                    lo = mid
                else:
                    hi = mid
        s = local(lo)
        sols.append(s)
        cuts.append(a + lo)
        if ta is not None:
            ic = problem.end_state(s, (slice(a, a + lo),))
        p0 = lo
    c = [np.asarray(cuts)]
    return c, LocalSolution(c, boxes_of(c), sols, time.perf_counter() - t0)


# ------------------------------------------------------------------------------------------------
# kℓ-PGD (Alg. 3.2)


@dataclass
class KpcaMap:
    """What kℓ-PGD saw: per particularization (grid of the partitioned axes) its k-PCA curve, the Hausdorff
    distance of that curve to the origin (Fig. 3.4c / 3.11 / 3.13), and the cuts chosen."""

    curves: np.ndarray  # (*axes, n_blocks, n_components)
    h_origin: np.ndarray  # (*axes,)
    cuts: list[np.ndarray]
    sigma: float
    eps: float
    eigenvalues: np.ndarray
    notes: list[str] = field(default_factory=list)


def hausdorff(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Hausdorff distances between point sets A[..., i, :] and B[..., j, :] (batched over leading axes)."""
    d = np.linalg.norm(A[..., :, None, :] - B[..., None, :, :], axis=-1)
    return np.maximum(d.min(axis=-1).max(axis=-1), d.min(axis=-2).max(axis=-1))


def kpca_curves(U: np.ndarray, block: int, n_components: int = 3, sigma: float | None = None,
                fit_samples: int = 1500, seed: int = 0) -> tuple[np.ndarray, float, np.ndarray, float]:
    """Gaussian-kernel PCA of the blocks of every particularization (Fig. 3.4b: the nodal values of one
    particularization grouped into columns of ``block`` nodes). U: (n_x, *axes). Returns the curves
    (*axes, n_blocks, n_components), the kernel width, the kPCA eigenvalues and the median kernel value between
    distinct samples (≈ 0: width far too small; ≈ 1: far too large). The kernel is fitted on a
    random subset of ``fit_samples`` blocks (seeded: the partition is reproducible)."""
    from sklearn.decomposition import KernelPCA

    nx = U.shape[0]
    nb = nx // block
    X = np.moveaxis(U[: nb * block].reshape((nb, block) + U.shape[1:]), (0, 1), (-2, -1))  # (*axes, nb, block)
    flat = X.reshape(-1, block)
    rng = np.random.default_rng(seed)
    fit = flat[rng.choice(len(flat), min(fit_samples, len(flat)), replace=False)]
    d = pdist(fit)  # pairwise distances without the (n, n, block) difference array
    d = d[d > 0]
    if sigma is None:  # median heuristic
        sigma = float(np.median(d)) if d.size else 1.0
    kd = np.exp(-d ** 2 / (2 * sigma ** 2))
    kernel_median = float(np.median(kd)) if kd.size else 1.0  # kernel between distinct samples
    kp = KernelPCA(n_components=n_components, kernel="rbf", gamma=1.0 / (2 * sigma ** 2), eigen_solver="dense")
    kp.fit(fit)
    Z = np.concatenate([kp.transform(flat[i:i + 20000]) for i in range(0, len(flat), 20000)])
    ev = np.asarray(getattr(kp, "eigenvalues_", np.zeros(n_components)))
    return Z.reshape(X.shape[:-1] + (Z.shape[-1],)), float(sigma), ev, kernel_median


def eps_neighbourhood_cuts(curves: np.ndarray, axis: int, eps: float) -> np.ndarray:
    """ε-neighbourhood clustering along one partitioned axis: a sub-domain grows while every
    particularization stays within Hausdorff distance ε (measured along that axis only) of the sub-domain's
    first one, for every position on the other partitioned axes."""
    C = np.moveaxis(curves, axis, 0)  # (n, *other, nb, q)
    n = C.shape[0]
    cuts = [0]
    start = 0
    for j in range(1, n):
        if np.max(hausdorff(C[j], C[start])) >= eps:
            cuts.append(j)
            start = j
    cuts.append(n)
    return np.asarray(cuts)


def kpca_partition(problem: LocalProblem, first_parts: list[int] | int, block: int, eps: float = 0.1,
                   sigma: float | None = None, n_components: int = 3, tol_first: float = 1e-2,
                   seed: int = 0, max_parts: int | None = None,
                   update: bool = False) -> tuple[list[np.ndarray], KpcaMap]:
    """Alg. 3.2: a constant-partition solution at a coarse tolerance, k-PCA of it, Hausdorff distances,
    ε-neighbourhood clusters → cuts. ``eps`` is a fraction of the diameter of the k-PCA point cloud.
    Degenerate kernels (width far too small: every sample orthogonal to every other; far too large: all
    samples alike) are detected from the kPCA spectrum and fall back to the first partition, with a warning."""
    parts = [first_parts] * len(problem.axes) if isinstance(first_parts, int) else list(first_parts)
    first = [constant_partition(n, p) for n, p in zip(problem.axes, parts)]
    U = solve_local(problem, first, tol_first, seed=seed, update=update).full()
    curves, sig, ev, kmed = kpca_curves(U, block, n_components, sigma, seed=seed)
    notes = []
    pts = curves.reshape(-1, curves.shape[-1])
    diam = float(np.ptp(pts, axis=0).max()) if len(pts) else 0.0
    h0 = hausdorff(curves, np.zeros(curves.shape[:-2] + (1, curves.shape[-1])))
    ev_rel = ev / ev.max() if ev.size and ev.max() > 0 else ev
    degenerate = ""
    if kmed > 1 - 1e-6 or not ev.size or ev.max() <= 1e-10 or diam <= 1e-8:
        degenerate = (f"kernel width σ = {sig:.3g} is far too large: every sample looks alike to the kernel "
                      f"(median kernel value {kmed:.6f}, k-PCA spectrum ≈ 0)")
    elif kmed < 1e-6 or (ev.size >= 2 and np.all(ev_rel > 0.98)):
        degenerate = (f"kernel width σ = {sig:.3g} is far too small: the kernel matrix is ≈ identity "
                      f"(median kernel value {kmed:.2g}), distances carry no information")
    if degenerate:
        warnings.warn(degenerate + "; falling back to the first (constant) partition", PartitionWarning, stacklevel=2)
        notes.append(degenerate)
        return first, KpcaMap(curves, h0, first, sig, eps, ev, notes)
    cuts = [eps_neighbourhood_cuts(curves, a, eps * diam) for a in range(len(problem.axes))]
    for a, c in enumerate(cuts):
        if max_parts and len(c) - 1 > max_parts:
            msg = f"axis {a}: ε = {eps} gives {len(c) - 1} sub-domains; capped to {max_parts} uniform ones"
            warnings.warn(msg, PartitionWarning, stacklevel=2)
            notes.append(msg)
            cuts[a] = constant_partition(problem.axes[a], max_parts)
        elif len(c) == 2:
            notes.append(f"axis {a}: one sub-domain (ε larger than every distance): global PGD on that axis")
    return cuts, KpcaMap(curves, h0, cuts, sig, eps, ev, notes)


# ------------------------------------------------------------------------------------------------
# errors


def rel_error(U: np.ndarray, ref: np.ndarray) -> float:
    """Relative L2 (Frobenius) error on the grid."""
    n = np.linalg.norm(ref)
    return float(np.linalg.norm(U - ref) / n) if n > 0 else float(np.linalg.norm(U))


def error_curve(full_of_n: Callable[[int], np.ndarray], ref: np.ndarray, ns) -> np.ndarray:
    return np.array([rel_error(full_of_n(int(n)), ref) for n in ns])
