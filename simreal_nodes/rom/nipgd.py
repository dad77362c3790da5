"""Non-intrusive PGD (thesis Eq. 5.4-5.5) and HOSVD, for snapshot tensors from any solver.

NI-PGD: greedy rank-one decomposition. For a tensor A of order D it finds

    A ~ sum_i f_i^1 (x) f_i^2 (x) ... (x) f_i^D

one term at a time: each new term minimizes ||A - (previous terms) - f^1 (x) ... (x) f^D|| by
alternating least squares (each factor is the contraction of the residual with the others, divided by
their squared norms), until the term stops changing; terms are added until the relative residual
falls below ``tol``. HOSVD (truncated Tucker, Kolda & Bader 2009) is the comparison.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray


@dataclass
class CPResult:
    factors: list[NDArray[np.float64]]  # per dimension: (n_terms, n_k)
    errors: NDArray[np.float64]  # relative residual after 1..n terms
    als_iterations: list[int] = field(default_factory=list)

    @property
    def n_terms(self) -> int:
        return int(self.factors[0].shape[0])

    def full(self, n_terms: int | None = None) -> NDArray[np.float64]:
        n = self.n_terms if n_terms is None else n_terms
        letters = "abcdefghij"[: len(self.factors)]
        expr = ",".join(f"m{c}" for c in letters) + "->" + letters
        A: NDArray[np.float64] = np.einsum(expr, *[f[:n] for f in self.factors])
        return A


def _contract_except(R: NDArray[np.float64], vecs: list[NDArray[np.float64]], k: int) -> NDArray[np.float64]:
    """R contracted with vecs[l] along every axis l != k."""
    out = R
    # contract from the last axis down so indices stay valid
    for l in reversed(range(R.ndim)):
        if l == k:
            continue
        out = np.tensordot(out, vecs[l], axes=([l], [0]))
    return out


def nipgd(A: NDArray[np.float64], max_terms: int = 50, tol: float = 1e-4, max_als: int = 100, als_tol: float = 1e-9,
          seed: int = 0, progress: Callable[[int, float], object] | None = None) -> CPResult:
    """Greedy rank-one decomposition of ``A`` (any order >= 2)."""
    A = np.asarray(A, dtype=np.float64)
    if A.ndim < 2:
        raise ValueError("NI-PGD needs a tensor of order >= 2")
    if not np.all(np.isfinite(A)):
        raise ValueError("the snapshot tensor contains NaN or inf")
    norm_A = np.linalg.norm(A)
    if norm_A == 0:
        raise ValueError("the snapshot tensor is zero")
    R = A.copy()
    rng = np.random.default_rng(seed)
    factors: list[list[NDArray[np.float64]]] = [[] for _ in range(A.ndim)]
    errors: list[float] = []
    iters: list[int] = []
    for n in range(max_terms):
        # start from the dominant fibre: a deterministic, well-aligned initial guess
        vecs: list[NDArray[np.float64]] = []
        for k in range(A.ndim):
            v = np.sqrt(np.sum(np.moveaxis(R, k, 0).reshape(R.shape[k], -1) ** 2, axis=1))
            v = v + 1e-3 * rng.standard_normal(v.shape) * (v.max() if v.max() > 0 else 1.0)
            vecs.append(v / np.linalg.norm(v))
        prev: list[NDArray[np.float64]] | None = None
        it = 0
        for it in range(1, max_als + 1):  # noqa: B007 - the sweeps run are read after the loop
            for k in range(A.ndim):
                denom = np.prod([vecs[l] @ vecs[l] for l in range(A.ndim) if l != k])
                vecs[k] = _contract_except(R, vecs, k) / denom
                if k < A.ndim - 1:
                    nk = np.linalg.norm(vecs[k])
                    if nk > 0:
                        vecs[k] = vecs[k] / nk
            if prev is not None:
                num = sum(np.linalg.norm(a - b) for a, b in zip(vecs, prev))
                if num <= als_tol * max(float(np.linalg.norm(vecs[-1])), 1e-300):
                    break
            prev = [v.copy() for v in vecs]
        term = vecs[0]
        for v in vecs[1:]:
            term = np.multiply.outer(term, v)
        R -= term
        for k in range(A.ndim):
            factors[k].append(vecs[k])
        err = float(np.linalg.norm(R) / norm_A)
        errors.append(err)
        iters.append(it)
        if progress:
            progress(n + 1, err)
        if err < tol:
            break
    return CPResult([np.asarray(f) for f in factors], np.asarray(errors), iters)


@dataclass
class TuckerResult:
    core: NDArray[np.float64]
    U: list[NDArray[np.float64]]  # per dimension (n_k, r_k)

    def full(self) -> NDArray[np.float64]:
        out = self.core
        for k, U in enumerate(self.U):
            out = np.moveaxis(np.tensordot(U, out, axes=([1], [k])), 0, k)
        return out

    @property
    def storage(self) -> int:
        return int(self.core.size + sum(U.size for U in self.U))


def hosvd(A: NDArray[np.float64], ranks: list[int] | None = None, tol: float | None = None) -> TuckerResult:
    """Truncated higher-order SVD: factor k = leading left singular vectors of the mode-k unfolding."""
    A = np.asarray(A, dtype=np.float64)
    Us = []
    for k in range(A.ndim):
        Ak = np.moveaxis(A, k, 0).reshape(A.shape[k], -1)
        U, s, _ = np.linalg.svd(Ak, full_matrices=False)
        if ranks is not None:
            r = min(ranks[k], len(s))
        elif tol is not None:
            tail = np.sqrt(np.cumsum((s ** 2)[::-1])[::-1]) / np.linalg.norm(s)
            r = max(1, int(np.sum(tail > tol / np.sqrt(A.ndim))))
        else:
            r = len(s)
        Us.append(U[:, :r])
    core = A
    for k, U in enumerate(Us):
        core = np.moveaxis(np.tensordot(U.T, core, axes=([1], [k])), 0, k)
    return TuckerResult(core, Us)
