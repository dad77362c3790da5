"""Registration of a model to the SLAM map and linking of map points to model nodes (thesis §4.4.1, §4.5.3).

- :func:`register`: support plane by RANSAC, then ICP (Open3D) of the model surface to the map points from
  several yaw hypotheses about the plane normal (objects rest on a plane; a symmetric object's yaw stays
  ambiguous, which is why alpha_z is estimated from the deformation), optionally with scale (monocular).
- :func:`link`: each map point near the model surface gets 3 model nodes and weights (Eq. 4.10): by default
  the corners of the closest surface triangle with the barycentric weights of the point's foot on it (the
  surface the camera sees, exactly as the mesh interpolates it), or, as the thesis writes it, the 3 nearest
  nodes with inverse-distance weights (``method="idw"``; on the joint boot at theta = 0.86 rad this
  interpolates the displacement 0.7 mm off at the median, 1.7 mm at p90). Points farther than ``max_dist``
  are static scene points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.rom.model import ReducedModel


@dataclass
class Links:
    nodes: np.ndarray  # (N, 3) model node indices
    weights: np.ndarray  # (N, 3) inverse-distance weights (sum 1)
    dist: np.ndarray  # (N,) distance to the nearest node (object frame units)
    on_object: np.ndarray  # (N,) bool


def link(points_obj: np.ndarray, model_points: np.ndarray, candidate_nodes: np.ndarray, max_dist: float,
         k: int = 3, triangles: np.ndarray | None = None, method: str = "barycentric") -> Links:
    """Link points (object frame) to 3 model nodes with weights (Eq. 4.10). ``triangles``: the model's
    surface (M, 3); without it, or where a node that is on no triangle is nearer than every triangle (a
    lever's embedded nodes), the k nearest candidate nodes with inverse-distance weights."""
    P = np.asarray(points_obj, dtype=np.float64).reshape(-1, 3)
    cand = np.asarray(candidate_nodes, dtype=np.int64)
    tree = cKDTree(model_points[cand])
    # an array of points: arrays of distances and indices (the stubs also allow scalars)
    d, idx = cast(tuple[np.ndarray, np.ndarray], tree.query(P, k=k))
    d = d.reshape(len(P), k)
    idx = idx.reshape(len(P), k)
    w = 1.0 / np.maximum(d, 1e-9)  # inverse distance (a point on a node takes that node)
    w /= w.sum(axis=1, keepdims=True)
    nodes, dist = cand[idx], d[:, 0]
    if method not in ("barycentric", "idw"):
        raise ValueError(f"link method must be 'barycentric' or 'idw', not '{method}'")
    if method == "barycentric" and k == 3 and len(P):
        on_surface = np.zeros(len(P), bool)
        if triangles is not None and len(triangles):
            F = np.asarray(triangles, dtype=np.int64)
            F = F[np.isin(F, cand).all(axis=1)]
            if len(F):
                tn, tb, td = closest_triangles(P, model_points, F)
                on_surface = td <= dist + 1e-9
                nodes[on_surface], w[on_surface], dist[on_surface] = tn[on_surface], tb[on_surface], td[on_surface]
        rest = np.flatnonzero(~on_surface)
        if len(rest):  # nodes on no surface triangle (a lever's grid): the best triangle of near nodes
            tn, tb, td = _near_node_triangles(P[rest], model_points, cand)
            use = np.isfinite(td)
            nodes[rest[use]], w[rest[use]] = tn[use], tb[use]
    return Links(nodes, w, dist, dist <= max_dist)


def ray_weights(origin: np.ndarray, directions: np.ndarray, corners: np.ndarray, weights: np.ndarray,
                tol: float = 0.02) -> np.ndarray:
    """Barycentric weights of where each viewing ray (``origin`` (3,) or (N, 3) + t ``directions[n]``, t > 0)
    meets the plane of its triangle ``corners[n]`` (3, 3); rows whose ray misses the triangle (beyond ``tol``
    outside an edge) or runs along its plane keep ``weights``. Solves o + t d = w0 A + w1 B + (1 - w0 - w1) C."""
    C = np.asarray(corners, dtype=np.float64)
    D = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    out = np.array(weights, dtype=np.float64, copy=True)
    if len(D) == 0:
        return out
    M = np.stack([C[:, 0] - C[:, 2], C[:, 1] - C[:, 2], -D], axis=2)  # (N, 3, 3), columns
    rhs = np.asarray(origin, dtype=np.float64).reshape(-1, 3) - C[:, 2]
    det = np.linalg.det(M)
    scale = np.linalg.norm(D, axis=1) * np.linalg.norm(np.cross(C[:, 0] - C[:, 2], C[:, 1] - C[:, 2]), axis=1)
    ok = np.abs(det) > 1e-3 * np.maximum(scale, 1e-300)  # not grazing (> 0.06 deg off the plane); NaN rays: False
    sol = np.full((len(D), 3), np.nan)
    if ok.any():
        sol[ok] = np.linalg.solve(M[ok], rhs[ok][..., None])[..., 0]
    w = np.c_[sol[:, 0], sol[:, 1], 1.0 - sol[:, 0] - sol[:, 1]]
    ok &= np.all(w >= -tol, axis=1) & (sol[:, 2] > 0)
    out[ok] = w[ok]
    return out


def _near_node_triangles(P: np.ndarray, V: np.ndarray, cand: np.ndarray,
                         k: int = 6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Among the triangles of each point's k nearest candidate nodes that hold the point's foot, the one
    nearest the point (ties: the smallest): its nodes and the foot's barycentric coordinates, which
    reproduce any linear displacement field (a rigid motion) exactly at the foot; distance inf where no
    triangle holds it."""
    from itertools import combinations

    tree = cKDTree(V[cand])
    k = min(k, len(cand))
    _, idx = tree.query(P, k=k)
    idx = idx.reshape(len(P), k)
    best_n = np.zeros((len(P), 3), np.int64)
    best_b = np.zeros((len(P), 3))
    best_key = np.full(len(P), np.inf)
    best_d = np.full(len(P), np.inf)
    for c in combinations(range(k), 3):
        tri = cand[idx[:, list(c)]]  # (N, 3)
        A, B, C = V[tri[:, 0]], V[tri[:, 1]], V[tri[:, 2]]
        e0, e1, q = B - A, C - A, P - A
        d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
        d20, d21 = (q * e0).sum(1), (q * e1).sum(1)
        den = d00 * d11 - d01 * d01
        ok = den > 1e-6 * np.maximum(d00 * d11, 1e-300)  # not collinear
        den = np.where(ok, den, 1.0)
        v = (d11 * d20 - d01 * d21) / den
        ww = (d00 * d21 - d01 * d20) / den
        u = 1 - v - ww
        ok &= (u >= -1e-9) & (v >= -1e-9) & (ww >= -1e-9)
        foot = u[:, None] * A + v[:, None] * B + ww[:, None] * C
        dist = np.linalg.norm(foot - P, axis=1)
        per = np.linalg.norm(e0, axis=1) + np.linalg.norm(e1, axis=1) + np.linalg.norm(C - B, axis=1)
        key = dist + 1e-3 * per
        take = ok & (key < best_key)
        best_key[take] = key[take]
        best_n[take] = tri[take]
        best_b[take] = np.c_[u, v, ww][take]
        best_d[take] = dist[take]
    return best_n, best_b, best_d


def closest_triangles(P: np.ndarray, V: np.ndarray, F: np.ndarray,
                      n_candidates: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point, the closest of the triangles F (among the ``n_candidates`` with the nearest
    centroids): its corner nodes (N, 3), the barycentric coordinates of the closest point (N, 3) and the
    distance (N,)."""
    tree = cKDTree(V[F].mean(axis=1))
    m = min(n_candidates, len(F))
    _, ti = tree.query(P, k=m)
    ti = ti.reshape(len(P), m)
    A, B, C = (V[F[ti, j]] for j in range(3))  # (N, m, 3) each
    Q = P[:, None, :]
    bary = _closest_point_barycentric(Q, A, B, C)
    foot = bary[..., :1] * A + bary[..., 1:2] * B + bary[..., 2:] * C
    dist = np.linalg.norm(foot - Q, axis=2)
    j = np.argmin(dist, axis=1)
    r = np.arange(len(P))
    return F[ti[r, j]], bary[r, j], dist[r, j]


def _closest_point_barycentric(Q: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of the point of triangle ABC closest to Q (broadcast over leading axes):
    the foot of the perpendicular when it falls inside, else the closest point of the nearest edge."""
    def seg(Pa: np.ndarray, Pb: np.ndarray) -> np.ndarray:
        """The closest point of segment Pa-Pb to Q as the parameter t in [0, 1]."""
        e = Pb - Pa
        t: np.ndarray = np.clip(np.einsum("...i,...i", Q - Pa, e) / np.maximum(np.einsum("...i,...i", e, e), 1e-300),
                                0.0, 1.0)  # einsum is typed Any
        return t

    e0, e1, q = B - A, C - A, Q - A
    d00, d01, d11 = (np.einsum("...i,...i", a, b) for a, b in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.einsum("...i,...i", q, e0), np.einsum("...i,...i", q, e1)
    den = np.maximum(d00 * d11 - d01 * d01, 1e-300)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    inside = np.stack([1 - v - w, v, w], axis=-1)
    t_ab, t_bc, t_ca = seg(A, B), seg(B, C), seg(C, A)
    cands = [inside,
             np.stack([1 - t_ab, t_ab, np.zeros_like(t_ab)], axis=-1),
             np.stack([np.zeros_like(t_bc), 1 - t_bc, t_bc], axis=-1),
             np.stack([t_ca, np.zeros_like(t_ca), 1 - t_ca], axis=-1)]
    ok_inside = (v >= 0) & (w >= 0) & (v + w <= 1)
    best: np.ndarray  # set by the first candidate (inside), which every later one is compared with
    best_d: np.ndarray
    for i, bc in enumerate(cands):
        foot = bc[..., :1] * A + bc[..., 1:2] * B + bc[..., 2:] * C
        dd = np.linalg.norm(foot - Q, axis=-1)
        if i == 0:
            dd = np.where(ok_inside, dd, np.inf)
            best, best_d = bc, dd
        else:
            pick = dd < best_d
            best = np.where(pick[..., None], bc, best)
            best_d = np.where(pick, dd, best_d)
    return best


def surface_nodes(model: ReducedModel) -> np.ndarray:
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
    pts: np.ndarray = A[tri] + u[:, None] * (B[tri] - A[tri]) + v[:, None] * (C[tri] - A[tri])  # indexing: Any
    return pts


def register(map_points: np.ndarray, model: ReducedModel, guess: np.ndarray | None = None, with_scale: bool = False,
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
    seeds: list[np.ndarray] = []
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
    best: tuple[tuple[float, float], Any] | None = None
    for T0 in seeds:
        r = o3d.pipelines.registration.registration_icp(src, tgt, max_dist * 2, T0, est, crit)
        r = o3d.pipelines.registration.registration_icp(src, tgt, max_dist, r.transformation, est, crit)
        score = (r.fitness, -r.inlier_rmse)
        if best is None or score > best[0]:
            best = (score, r)
    # seeds is never empty (a guess, or yaw_hypotheses seeds); the cast keeps the error of an empty one as it was
    r = cast(tuple[tuple[float, float], Any], best)[1]
    T = np.asarray(r.transformation)
    s = float(np.cbrt(np.linalg.det(T[:3, :3]))) if with_scale else 1.0
    return Registration(T, s, float(r.fitness), float(r.inlier_rmse), plane)
