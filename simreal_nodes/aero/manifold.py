"""The manifold of car shapes (thesis §6.2.2, §6.3.2): Locally Linear Embedding of the presence vectors and the
interpolation of a new car's flow from its neighbours (Eq. 6.4).

* Each car is the vector ``z`` of its presence function on the grid (Eq. 6.1), ``z`` in R^D, D = 112 000.
* Eq. 6.2: each ``z_m`` is reconstructed from its ``M`` nearest neighbours with weights ``W_mi`` summing to one, the
  least-squares minimiser of ``|z_m - sum_i W_mi z_i|^2``; LLE then finds coordinates ``xi`` in R^d keeping the same
  weights (scikit-learn's :class:`~sklearn.manifold.LocallyLinearEmbedding`, Roweis & Saul 2000).
* A new car (§6.3.2) is embedded incrementally: its weights over its ``M`` nearest database cars are found the same
  way (:meth:`ShapeManifold.weights`), its coordinates are ``xi = sum_i W_i xi_i`` (what scikit-learn's ``transform``
  computes; a test checks the two agree), and its velocity is Eq. 6.4, ``v = sum_i W_i v_i``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.manifold import LocallyLinearEmbedding


def reconstruction_weights(z: np.ndarray, neighbours: np.ndarray, reg: float = 1e-3) -> np.ndarray:
    """Eq. 6.2 for one point: the weights ``w`` (summing to 1) minimising ``|z - w @ neighbours|^2``.

    With ``C = (neighbours - z)(neighbours - z)^T`` the local Gram matrix, the minimiser under ``sum w = 1`` is
    ``w = C^-1 1 / (1^T C^-1 1)``. ``C`` is singular when there are more neighbours than the dimension they span (or
    two identical cars), so ``reg * trace(C)`` is added to its diagonal: scikit-learn's regularisation, the same
    ``reg`` as the embedding."""
    d = np.asarray(neighbours, float) - np.asarray(z, float)[None, :]
    C = d @ d.T
    tr = float(np.trace(C))
    C[np.diag_indices_from(C)] += reg * tr if tr > 0 else reg
    w = np.linalg.solve(C, np.ones(len(C)))
    return w / w.sum()


@dataclass
class Neighbourhood:
    """A new car's place on the manifold: its database neighbours, their weights and its coordinates."""

    indices: np.ndarray  # (M,) into the database
    weights: np.ndarray  # (M,), sum 1
    coordinates: np.ndarray  # (d,)
    distances: np.ndarray  # (M,) Euclidean distance in R^D (sqrt of the number of grid points that differ)


class ShapeManifold:
    """LLE of a database of presence vectors ``Z`` (n_cars, D) with ``n_neighbors`` (the thesis's M, 6-15) into
    R^``n_components`` (the thesis: 2)."""

    def __init__(self, Z: np.ndarray, n_neighbors: int = 9, n_components: int = 2, reg: float = 1e-3) -> None:
        Z = np.asarray(Z, float)
        if Z.ndim != 2 or len(Z) <= n_neighbors:
            raise ValueError(f"LLE with {n_neighbors} neighbours needs more than {n_neighbors} cars; got {Z.shape}")
        self.Z = Z
        self.n_neighbors = n_neighbors
        self.reg = reg
        self.lle = LocallyLinearEmbedding(n_neighbors=n_neighbors, n_components=n_components, reg=reg,
                                          method="standard", eigen_solver="dense", random_state=0)
        self.embedding = self.lle.fit_transform(Z)
        self._sq = np.einsum("ij,ij->i", Z, Z)

    def neighbours(self, z: np.ndarray, exclude: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The ``M`` database cars nearest to ``z`` (index, distance), nearest first; ``exclude`` leaves one out."""
        z = np.asarray(z, float).ravel()
        d2 = np.maximum(self._sq - 2.0 * self.Z @ z + z @ z, 0.0)
        if exclude is not None:
            d2[exclude] = np.inf
        idx = np.argsort(d2, kind="stable")[: self.n_neighbors]
        return idx, np.sqrt(d2[idx])

    def place(self, z: np.ndarray, exclude: int | None = None) -> Neighbourhood:
        """Incremental embedding of a new car (§6.3.2): weights over its neighbours and its coordinates."""
        idx, dist = self.neighbours(z, exclude)
        w = reconstruction_weights(np.asarray(z, float).ravel(), self.Z[idx], self.reg)
        return Neighbourhood(indices=idx, weights=w, coordinates=w @ self.embedding[idx], distances=dist)

    @staticmethod
    def interpolate(fields: np.ndarray, nb: Neighbourhood) -> np.ndarray:
        """Eq. 6.4: ``sum_i W_i f_i`` over the neighbours' fields (``fields``: (n_cars, ...), any trailing shape)."""
        return np.tensordot(nb.weights, np.asarray(fields)[nb.indices], axes=1)
