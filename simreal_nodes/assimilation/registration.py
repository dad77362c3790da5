"""Registration of a model to the SLAM map and linking of map points to model nodes (thesis §4.4.1, §4.5.3).

- :func:`register`: support plane by RANSAC, then ICP (Open3D) of the model surface to the map points from
  several yaw hypotheses about the plane normal (objects rest on a plane; a symmetric object's yaw stays
  ambiguous, which is why alpha_z is estimated from the deformation), optionally with scale (monocular).
- :func:`link`: each map point near the model surface gets its 3 nearest model nodes and inverse-distance
  weights (Eq. 4.10); points farther than ``max_dist`` are static scene points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G


@dataclass
class Links:
    nodes: np.ndarray  # (N, 3) model node indices
    weights: np.ndarray  # (N, 3) inverse-distance weights (sum 1)
    dist: np.ndarray  # (N,) distance to the nearest node (object frame units)
    on_object: np.ndarray  # (N,) bool


def link(points_obj: np.ndarray, model_points: np.ndarray, candidate_nodes: np.ndarray, max_dist: float,
         k: int = 3) -> Links:
    """Link points (object frame) to their k nearest candidate model nodes (Eq. 4.10)."""
    P = np.asarray(points_obj, dtype=np.float64).reshape(-1, 3)
    cand = np.asarray(candidate_nodes, dtype=np.int64)
    tree = cKDTree(model_points[cand])
    d, idx = tree.query(P, k=k)
    d = d.reshape(len(P), k)
    idx = idx.reshape(len(P), k)
    w = 1.0 / np.maximum(d, 1e-9)  # inverse distance (a point on a node takes that node)
    w /= w.sum(axis=1, keepdims=True)
    return Links(cand[idx], w, d[:, 0], d[:, 0] <= max_dist)


def surface_nodes(model) -> np.ndarray:
    """Nodes a camera can see: the surface vertices, and the extra (lever / embedded) nodes."""
    s = np.unique(model.surface) if len(model.surface) else np.arange(model.n_nodes)
    extra = model.provenance.get("lever_nodes") if isinstance(model.provenance, dict) else None
    if extra:
        s = np.union1d(s, np.arange(extra[0], extra[0] + extra[1]))
    return s


@dataclass
class Registration:
    T_map_obj: np.ndarray  # includes the scale in its rotation block when with_scale (s R)
    scale: float
    fitness: float
    rmse: float
    plane: np.ndarray | None  # (a, b, c, d) of the support plane in the map


def sample_surface(V: np.ndarray, F: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(B - A, C - A), axis=1)
    tri = rng.choice(len(F), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return A[tri] + u[:, None] * (B[tri] - A[tri]) + v[:, None] * (C[tri] - A[tri])


def register(map_points: np.ndarray, model, guess: np.ndarray | None = None, with_scale: bool = False,
             max_dist: float = 0.02, yaw_hypotheses: int = 12, seed: int = 0) -> Registration:
    """Place the model in the map. ``guess`` (T_map_obj) seeds ICP; without it the support plane and the
    centroid of the off-plane points give the seed and yaw is searched."""
    import open3d as o3d

    o3d.utility.random.seed(seed)
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(map_points, dtype=np.float64)))
    plane = None
    off = np.asarray(map_points)
    if len(map_points) > 50:
        coeff, inl = tgt.segment_plane(distance_threshold=max_dist / 2, ransac_n=3, num_iterations=500)
        plane = np.asarray(coeff)
        mask = np.ones(len(map_points), bool)
        mask[inl] = False
        off = np.asarray(map_points)[mask]
    src_pts = sample_surface(model.points, model.surface, 4000, seed) if len(model.surface) else model.points
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src_pts))
    est = o3d.pipelines.registration.TransformationEstimationPointToPoint(with_scaling=with_scale)
    crit = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=60)
    seeds = []
    if guess is not None:
        seeds = [np.asarray(guess, dtype=np.float64)]
    else:
        n = plane[:3] / np.linalg.norm(plane[:3]) if plane is not None else np.array([0, 0, 1.0])
        if plane is not None and np.dot(n, off.mean(axis=0) - np.asarray(map_points).mean(axis=0)) < 0:
            n = -n
        z = n
        x0 = np.cross([0, 1.0, 0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0, 0], z)
        x0 /= np.linalg.norm(x0)
        base = np.stack([x0, np.cross(z, x0), z], axis=1)
        c_obj = src_pts.mean(axis=0)
        target_c = off.mean(axis=0) if len(off) else np.asarray(map_points).mean(axis=0)
        for k in range(yaw_hypotheses):
            R = base @ G.rot_axis("z", 2 * np.pi * k / yaw_hypotheses)
            seeds.append(G.make_T(R, target_c - R @ c_obj))
    best = None
    for T0 in seeds:
        r = o3d.pipelines.registration.registration_icp(src, tgt, max_dist * 2, T0, est, crit)
        r = o3d.pipelines.registration.registration_icp(src, tgt, max_dist, r.transformation, est, crit)
        score = (r.fitness, -r.inlier_rmse)
        if best is None or score > best[0]:
            best = (score, r)
    r = best[1]
    T = np.asarray(r.transformation)
    s = float(np.cbrt(np.linalg.det(T[:3, :3]))) if with_scale else 1.0
    return Registration(T, s, float(r.fitness), float(r.inlier_rmse), plane)
