"""Intrusive Proper Generalized Decomposition (thesis §2.1.3-2.1.4, Algorithm 2.1).

Problem in separated form, discrete in space (finite elements) and in every parameter axis k:

    K(mu) u(mu) = f(mu),   K(mu) = sum_a K_a prod_k d_a^k(mu_k),   f(mu) = sum_j h_j prod_k g_j^k(mu_k)

(e.g. u(x, s): one stiffness, loads h_j = unit load at position s_j, g_j(s) = delta at s_j;
u(x, s, E): K(E) = E K_1). Its Galerkin weak form over space x parameters, with quadrature weights
w^k on each axis, is solved for

    u(x, mu) ~ sum_i F_i(x) prod_k G_i^k(mu_k)

by a greedy enrichment (one new product R(x) prod S^k per step) and, within each enrichment, an
alternating-direction fixed point: R from the S^k (one sparse solve, the factorization is reused),
then each S^k from R and the other S^l (pointwise in mu_k: the parameter operators are diagonal).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import cast

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

# One rank-one term R (x) S^1 (x) ... (x) S^D: the space factor and the per-axis factors.
_Product = tuple[NDArray[np.float64], list[NDArray[np.float64]]]


@dataclass
class ParameterAxis:
    values: NDArray[np.float64]  # grid nodes
    weights: NDArray[np.float64] | None = None  # quadrature weights (trapezoid if None)

    def __post_init__(self) -> None:
        self.values = np.asarray(self.values, dtype=np.float64)
        if self.weights is None:
            self.weights = trapezoid_weights(self.values)
        self.weights = np.asarray(self.weights, dtype=np.float64)


def trapezoid_weights(x: NDArray[np.float64]) -> NDArray[np.float64]:
    x = np.asarray(x, dtype=np.float64)
    if len(x) == 1:
        return np.ones(1)
    w = np.zeros_like(x)
    d = np.diff(x)
    w[:-1] += d / 2
    w[1:] += d / 2
    return w


@dataclass
class SeparatedOperator:
    """K(mu) = sum_a K_a prod_k diag(d_a^k): ``terms`` = [(K_a, [d_a^1, ..., d_a^D])]."""

    terms: list[tuple[sp.csr_matrix, list[NDArray[np.float64]]]]


@dataclass
class SeparatedLoad:
    """f(mu) = H @ prod_k G^k: columns h_j of H (N x m) and per-axis factors G^k (m x n_k)."""

    H: sp.csr_matrix | NDArray[np.float64]
    G: list[NDArray[np.float64]]


@dataclass
class PGDResult:
    F: NDArray[np.float64]  # (n_modes, N) space modes (over all dofs, zeros on Dirichlet dofs)
    G: list[NDArray[np.float64]]  # per axis (n_modes, n_k)
    amplitudes: NDArray[np.float64]  # amplitude of each mode (product of weighted norms)
    fixed_point_iterations: list[int] = field(default_factory=list)
    converged: bool = False

    @property
    def n_modes(self) -> int:
        return int(self.F.shape[0])

    def evaluate_grid(self, n_modes: int | None = None) -> NDArray[np.float64]:
        """Full tensor u(x, mu_1, ..., mu_D) on the grids (for checks on small problems)."""
        n = self.n_modes if n_modes is None else n_modes
        letters = "abcdefgh"[: len(self.G)]
        expr = "mx," + ",".join(f"m{c}" for c in letters) + "->x" + letters
        U: NDArray[np.float64] = np.einsum(expr, self.F[:n], *[g[:n] for g in self.G])
        return U


def pgd_solve(op: SeparatedOperator, load: SeparatedLoad, axes: list[ParameterAxis], free: NDArray[np.int64],
              max_modes: int = 30, tol: float = 1e-4, max_fp_iter: int = 30, fp_tol: float = 1e-8,
              progress: Callable[[int, float], object] | None = None, seed: int = 0) -> PGDResult:
    """Greedy PGD (Algorithm 2.1). ``free``: indices of the unconstrained dofs (homogeneous Dirichlet
    elsewhere). Stops when a new mode's amplitude falls below ``tol`` times the first one's."""
    N = op.terms[0][0].shape[0]
    D = len(axes)
    Ka = [K.tocsr()[free][:, free] for K, _ in op.terms]
    da = [[np.asarray(d, dtype=np.float64) for d in ds] for _, ds in op.terms]
    H = load.H.tocsr()[free] if sp.issparse(load.H) else np.asarray(load.H)[free]
    Gl = [np.asarray(g, dtype=np.float64) for g in load.G]  # (m, n_k)
    w = [cast(NDArray[np.float64], ax.weights) for ax in axes]  # never None: __post_init__ fills them
    rng = np.random.default_rng(seed)
    Fs: list[NDArray[np.float64]] = []  # on free dofs
    Gs: list[list[NDArray[np.float64]]] = [[] for _ in range(D)]
    amps: list[float] = []
    iters: list[int] = []
    single = len(Ka) == 1
    lu = spla.splu(Ka[0].tocsc()) if single else None
    KF: list[list[NDArray[np.float64]]] = [[] for _ in Ka]  # K_a F_i cache

    def solve_space(alpha_a: NDArray[np.float64], rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        if lu is not None:  # the single-term operator: its factorization
            R: NDArray[np.float64] = lu.solve(rhs) / alpha_a[0]
            return R
        K = sum(a * K_ for a, K_ in zip(alpha_a, Ka))
        return spla.spsolve(K.tocsc(), rhs)

    converged = False
    for n in range(max_modes):
        S = [np.ones(len(ax.values)) + 0.1 * rng.standard_normal(len(ax.values)) for ax in axes]
        R = np.zeros(len(free))
        prev: _Product | None = None
        it = 0
        for it in range(1, max_fp_iter + 1):  # noqa: B007 - the iterations run are read after the loop
            # --- R from the S^k ---
            alpha = np.array([np.prod([np.sum(w[k] * da[a][k] * S[k] ** 2) for k in range(D)]) for a in range(len(Ka))])
            beta = np.prod([Gl[k] @ (w[k] * S[k]) for k in range(D)], axis=0)  # (m,)
            rhs = H @ beta
            for i in range(len(Fs)):
                for a in range(len(Ka)):
                    gam = np.prod([np.sum(w[k] * da[a][k] * S[k] * Gs[k][i]) for k in range(D)])
                    rhs = rhs - gam * KF[a][i]
            R = solve_space(alpha, rhs)
            nr = np.linalg.norm(R)
            if nr == 0 or not np.isfinite(nr):
                break
            R /= nr
            KR = [K @ R for K in Ka]
            RKR = np.array([R @ kr for kr in KR])
            RH = H.T @ R  # (m,)
            RKF = [[R @ KF[a][i] for i in range(len(Fs))] for a in range(len(Ka))]
            # --- each S^k from R and the other S^l ---
            for k in range(D):
                others = [l for l in range(D) if l != k]
                lhs = np.zeros(len(axes[k].values))
                for a in range(len(Ka)):
                    c = np.prod([np.sum(w[l] * da[a][l] * S[l] ** 2) for l in others]) if others else 1.0
                    lhs += RKR[a] * c * da[a][k]
                b_other = np.prod([Gl[l] @ (w[l] * S[l]) for l in others], axis=0) if others else np.ones(len(RH))
                r = (RH * b_other) @ Gl[k]
                for i in range(len(Fs)):
                    for a in range(len(Ka)):
                        c = np.prod([np.sum(w[l] * da[a][l] * S[l] * Gs[l][i]) for l in others]) if others else 1.0
                        r = r - RKF[a][i] * c * da[a][k] * Gs[k][i]
                with np.errstate(divide="ignore", invalid="ignore"):
                    S[k] = np.where(np.abs(lhs) > 0, r / lhs, 0.0)
                if k < D - 1:  # keep all but the last factor normalized
                    nk = np.sqrt(np.sum(w[k] * S[k] ** 2))
                    if nk > 0:
                        S[k] = S[k] / nk
            # fixed-point change of the product R (x) S^1 (x) ... (weighted norm)
            cur = (R, [s.copy() for s in S])
            if prev is not None:
                d = _product_distance(prev, cur, w)
                if d < fp_tol:
                    break
            prev = cur
        amp = np.sqrt(np.prod([np.sum(w[k] * S[k] ** 2) for k in range(D)]))
        Fs.append(R)
        for k in range(D):
            Gs[k].append(S[k])
        for a in range(len(Ka)):
            KF[a].append(Ka[a] @ R)
        amps.append(amp)
        iters.append(it)
        if progress:
            progress(n + 1, amp / amps[0])
        if amp < tol * amps[0]:
            converged = True
            break
    Ffull = np.zeros((len(Fs), N))
    Ffull[:, free] = np.asarray(Fs)
    return PGDResult(Ffull, [np.asarray(g) for g in Gs], np.asarray(amps), iters, converged)


def _product_distance(a: _Product, b: _Product, w: list[NDArray[np.float64]]) -> float:
    """Relative distance between two rank-one tensors R (x) S^1 (x) ... (weighted Frobenius)."""
    (Ra, Sa), (Rb, Sb) = a, b
    aa = (Ra @ Ra) * np.prod([np.sum(wk * s * s) for wk, s in zip(w, Sa)])
    bb = (Rb @ Rb) * np.prod([np.sum(wk * s * s) for wk, s in zip(w, Sb)])
    ab = (Ra @ Rb) * np.prod([np.sum(wk * s * t) for wk, s, t in zip(w, Sa, Sb)])
    return float(np.sqrt(max(aa + bb - 2 * ab, 0.0) / max(bb, 1e-300)))
