"""Closed, outward triangulations of the validation bodies the CFD is checked on (a sphere, a cube)."""

from __future__ import annotations

import numpy as np


def sphere_surface(d: float = 1.0, n_theta: int = 32, n_phi: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere of diameter ``d`` centred at the origin, closed by a vertex at each pole."""
    th = np.linspace(0.0, np.pi, n_theta + 1)[1:-1]
    ph = np.linspace(0.0, 2.0 * np.pi, n_phi, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    ring = 0.5 * d * np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    v = np.vstack([ring, [[0.0, 0.0, 0.5 * d]], [[0.0, 0.0, -0.5 * d]]])
    j = np.arange(n_phi)
    jn = (j + 1) % n_phi
    f = []
    for i in range(n_theta - 2):
        a, b, a2, b2 = i * n_phi + j, i * n_phi + jn, (i + 1) * n_phi + j, (i + 1) * n_phi + jn
        f += [np.stack([a, a2, b2], 1), np.stack([a, b2, b], 1)]
    f.append(np.stack([np.full(n_phi, len(ring)), j, jn], 1))
    last = (n_theta - 2) * n_phi
    f.append(np.stack([np.full(n_phi, len(ring) + 1), last + jn, last + j], 1))
    return v, np.vstack(f)


def cube_surface(a: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A cube of edge ``a`` centred at the origin, wound outwards."""
    v = 0.5 * a * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    f = np.array([t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])
    if np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() < 0:
        f = f[:, ::-1]
    return v, f
