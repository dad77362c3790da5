"""Proper Orthogonal Decomposition (thesis §2.1.2).

Snapshot matrix P (D x M) -> SVD -> basis B = U[:, :N] chosen by an energy criterion; Galerkin
reduced solve of a linear system K U = F: xi = (B^T K B)^-1 B^T F (Eq. 2.5), U ~ B xi (Eq. 2.4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray


@dataclass
class PODBasis:
    B: NDArray[np.float64]  # (D, N) orthonormal columns
    singular_values: NDArray[np.float64]  # all of them, descending
    energy: NDArray[np.float64]  # cumulative energy fraction after 1..M modes

    @property
    def n_modes(self) -> int:
        return int(self.B.shape[1])

    def project(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        xi: NDArray[np.float64] = self.B.T @ U
        return xi

    def reconstruct(self, xi: NDArray[np.float64]) -> NDArray[np.float64]:
        U: NDArray[np.float64] = self.B @ xi
        return U


def pod(snapshots: NDArray[np.float64], energy: float = 0.999999, max_modes: int | None = None) -> PODBasis:
    """POD basis of the columns of ``snapshots`` keeping ``energy`` of sum(sigma^2)."""
    P = np.asarray(snapshots, dtype=np.float64)
    if P.ndim != 2 or min(P.shape) == 0:
        raise ValueError(f"snapshots must be a non-empty (D, M) matrix, got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError("snapshots contain NaN or inf")
    U, s, _ = np.linalg.svd(P, full_matrices=False)
    total = float(np.sum(s ** 2))
    cum = np.cumsum(s ** 2) / total if total > 0 else np.ones_like(s)
    n = int(np.searchsorted(cum, energy) + 1) if total > 0 else 1
    n = min(n, len(s))
    if max_modes is not None:
        n = min(n, max_modes)
    return PODBasis(U[:, :n], s, cum)


def galerkin_solve(K: NDArray[np.float64] | sp.csr_matrix, F: NDArray[np.float64],
                   B: NDArray[np.float64]) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Reduced solve (Eq. 2.5): returns (xi, B xi). K may be sparse; F may have several columns."""
    KB: NDArray[np.float64] = K @ B
    Kr = B.T @ KB
    Fr = B.T @ F
    xi = np.linalg.solve(Kr, Fr)
    return xi, B @ xi
