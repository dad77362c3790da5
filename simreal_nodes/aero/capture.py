"""Capturing a car's shape from a SLAM map (thesis §6.3.2, §6.4.1, Alg. 6.1), down to its presence vector.

Alg. 6.1, step by step (``capture_car``), on the map's points (any pose; any scale for a monocular map):

0. (not in the thesis, whose maps were sparse) a map of more than ``max_points`` points is thinned on a voxel grid
   to that many (``thin``): an RGB-D capture cloud holds each surface point once for every keyframe that saw it
   (about 72 000 points for a car circled once), which every later step pays for; the count, not an edge length,
   is the setting, so a monocular map of any scale is thinned alike and the steps' cost is bounded;
1. ``densityPointCulling``: points with fewer than ``min_neighbours`` points (themselves included) within
   ``density_radius`` x the median distance to the ``min_neighbours``-th neighbour are dropped (Open3D's radius
   outlier removal): triangulation noise goes, a sparser but regular floor stays;
2. ``geometryAnalysis`` / ``centroidPointCulling``: the centroid, then the points farther from it than 95 % of all
   are dropped (the thesis's choice: no tuned distance);
3. ``planeEstimationRANSAC`` / ``floorRemoving``: the largest plane (Open3D RANSAC, seeded), refined by least
   squares on the band of points about it, is the floor; its points and everything under it go, and so do the points
   less than ``floor_sigmas`` of the floor's noise above the floor's level where they stand (level and noise from
   their 30 nearest points in the floor's band: a depth camera's floor 5 m away is several centimetres thick, 2 m
   away one, and a SLAM map's floor bends with its drift); its normal, pointing to the car, is gravity's opposite;
   then step 1's density culling again on the points left (radius factor ``above_floor_density``): what the cut
   leaves of the floor lies scattered around the car, sparser than the car's surface, and would widen the box;
4. ``PrincipalComponentAnalysis``: the principal axis of the remaining points projected on the floor is the car's
   length;
5. ``noiseRemoving``: along each of the car's three axes, the histogram of positions; only the contiguous run of
   populated bins holding most points is kept (the thesis's "histogram of positions"; ``noise_min_share`` > 0
   counts thinly filled bins as empty);
6. ``boxAdjustment`` and the similarity ``[S, R, T]``: the length axis turned (within 30 degrees) to the box of
   least area (PCA leans towards where a SLAM map holds more points); the box of the points in the car's axes
   (their quantiles ``box_quantile`` .. 1 - ``box_quantile``, 0.5-99.5 %) gives the car frame of
   :mod:`simreal_nodes.aero.grid` (nose at ``x = 0``, centre plane ``y = 0``, floor ``z = 0``); the scale is 1
   for a metric map (RGB-D, stereo) or ``length_m`` / box length for a monocular one (the user says how long the car
   is: the only way to fix a monocular map's scale here);
7. the alpha shape of the points (``alpha_m`` metres in the car frame: over half the body's thickness, or a shell of
   surface points leaves the interior hollow; 0.8-1.7 m gave the same overlap on development cars), after closing
   the underside the camera never sees by a cap at the lowest seen height (the sills): its surface from Open3D (for
   drawing and occlusion), and the presence function on the grid from its interior, the Delaunay tetrahedra of
   circumradius under alpha (the alpha complex, scipy): a point is in the car when it lies in one of them.
   (Ray-parity occupancy on Open3D's alpha shape mesh needs a watertight surface, which an alpha shape of a noisy
   map is not.)

The car's front is ambiguous after step 4 (which end of the principal axis?); ``choose_front`` (e.g. the end
whose presence vector lies closer to the database's cars) decides; without it the nose is the lower end.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from simreal_nodes.aero.grid import AeroGrid


@dataclass(frozen=True)
class CaptureSettings:
    density_radius: float = 3.0  # x the median distance to the min_neighbours-th neighbour
    min_neighbours: int = 4
    centroid_keep: float = 0.95
    floor_tolerance: float = 1.0  # RANSAC inlier distance, x median spacing
    floor_iterations: int = 2000
    floor_sigmas: float = 3.0  # points lower than this many of the floor's noise sigmas above it are the floor's
    noise_bins: int = 60
    noise_min_share: float = 0.0  # a bin holding no more than this share of the mean non-empty bin counts as empty
    alpha_m: float = 1.0  # alpha (m, in the car frame): over half the body's thickness, or the interior stays hollow
    cap_spacing: float = 0.1  # the underside's cap points, x alpha_m (never finer than the map; 0: the map's spacing)
    length_m: float | None = None  # the car's length, for a map without metric scale
    # a larger map is first thinned to this many points on a voxel grid (None or 0: never); 5000 is a spacing of
    # about 9 cm on the car-park captures (the grid's cells are 10 cm). Chosen on the development cars
    # (benchmarks/results/aero_video_dev.md) with above_floor_density
    max_points: int | None = 5000
    above_floor_density: float = 2.5  # step 1 again on the points above the floor, with this radius factor (0: off)
    box_quantile: float = 0.005  # the box spans the points' quantiles from this to 1 - this along each axis
    seed: int = 0


@dataclass
class CaptureResult:
    presence: np.ndarray  # (D,) on the grid
    points: np.ndarray  # (n, 3) the kept points in the car frame (metres)
    vertices: np.ndarray  # the alpha shape, car frame
    triangles: np.ndarray
    scale: float  # x_car = scale * R @ x_map + t
    rotation: np.ndarray
    translation: np.ndarray
    box: np.ndarray  # (3,) length, width, height (m)
    kept: dict[str, int] = field(default_factory=dict)  # points left after each step
    seconds: dict[str, float] = field(default_factory=dict)
    floor_cut: float = 0.0  # the median height (map units) under which the kept points' neighbourhoods were floor


def _spacing(p: np.ndarray) -> float:
    d = np.asarray(cKDTree(p).query(p, k=2)[0])
    return float(np.median(d[:, 1]))


def _density_cull(p: np.ndarray, min_neighbours: int, radius_factor: float) -> np.ndarray:
    """The points with at least ``min_neighbours`` points (themselves included) within ``radius_factor`` x the median
    distance to the ``min_neighbours``-th neighbour (Open3D's radius outlier removal)."""
    import open3d as o3d

    dk = np.asarray(cKDTree(p).query(p, k=min_neighbours + 1)[0])
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    _, idx = pcd.remove_radius_outlier(nb_points=min_neighbours, radius=radius_factor * float(np.median(dk[:, -1])))
    return p[np.asarray(idx, int)]


def thin(p: np.ndarray, max_points: int) -> np.ndarray:
    """At most ``max_points`` of ``p``: the centroids of the occupied cells of a voxel grid whose edge is rescaled until
    the count lands within 90-100 % of ``max_points`` (a surface's occupied cells fall with the square of the edge:
    the edge is multiplied by the square root of the count's ratio to its target, at most twelve times; the largest
    count under the bound is kept if none lands). Scale free: the first edge comes from the cloud's extent, so a
    monocular map of any scale thins alike; but a map covering more ground thins its car more coarsely. A dense map's
    redundancy goes (an RGB-D map holds a surface point once for each keyframe that saw it) and its density evens
    out: near surfaces are sampled no finer than far ones. Where no voxel edge brings the count under the bound (a
    degenerate cloud), ``max_points`` of the points themselves, drawn with a fixed seed."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    lo, hi = np.quantile(p, [0.01, 0.99], axis=0)
    extent = np.sort(hi - lo)[::-1]
    edge = float(np.sqrt(extent[0] * extent[1] / max_points))
    if not np.isfinite(edge) or edge <= 1e-9 * max(float(np.abs(p).max()), 1.0):  # flat or collinear: no area
        edge = float(extent[0]) / max_points
    best = None
    if np.isfinite(edge) and edge > 0:
        for _ in range(12):
            q = np.asarray(pcd.voxel_down_sample(edge).points)
            if len(q) <= max_points and (best is None or len(q) > len(best)):
                best = q
            if 0.9 * max_points <= len(q) <= max_points:
                break
            edge *= float(np.clip(np.sqrt(len(q) / (0.95 * max_points)), 0.5, 2.0))
    return best if best is not None else p[np.random.default_rng(0).choice(len(p), max_points, replace=False)]


def circumradii(tets: np.ndarray) -> np.ndarray:
    """Circumradius of each tetrahedron (m, 4, 3); inf for a flat one."""
    a = tets[:, 0]
    A = 2.0 * (tets[:, 1:] - a[:, None, :])
    rhs = np.einsum("mkj,mkj->mk", tets[:, 1:], tets[:, 1:]) - np.einsum("mj,mj->m", a, a)[:, None]
    det = np.linalg.det(A)
    ok = np.abs(det) > 1e-12 * np.max(np.abs(A), axis=(1, 2)) ** 3
    centre = np.zeros_like(a)
    centre[ok] = np.linalg.solve(A[ok], rhs[ok][..., None])[..., 0]
    r = np.linalg.norm(centre - a, axis=1)
    r[~ok] = np.inf
    return r


def _refine_plane(p: np.ndarray, n: np.ndarray, d0: float, tol: float, rounds: int = 3) -> tuple[np.ndarray, float]:
    """The plane n.x + d0 = 0 fitted (SVD) to the points within 2.5 robust sigmas of it (never closer than ``tol``),
    ``rounds`` times."""
    for _ in range(rounds):
        dist = p @ n + d0
        near = np.abs(dist) < max(tol, 2.5 * 1.4826 * float(np.median(np.abs(dist[np.abs(dist) < 3 * tol]))))
        if near.sum() < 3:
            break
        c = p[near].mean(axis=0)
        n_new = np.linalg.svd(p[near] - c, full_matrices=False)[2][2]
        n = n_new if n_new @ n > 0 else -n_new
        d0 = -float(n @ c)
    return n, d0


def _box_angle(xy: np.ndarray, span_deg: float = 30.0, step_deg: float = 0.5) -> float:
    """The turn (radians, within +-``span_deg``) of the axes that gives the points' box (1-99 % quantiles) the least
    area."""
    th = np.deg2rad(np.arange(-span_deg, span_deg + 1e-9, step_deg))
    u = xy[:, :1] * np.cos(th) + xy[:, 1:] * np.sin(th)
    v = xy[:, 1:] * np.cos(th) - xy[:, :1] * np.sin(th)
    qu, qv = np.quantile(u, [0.01, 0.99], axis=0), np.quantile(v, [0.01, 0.99], axis=0)
    return float(th[np.argmin((qu[1] - qu[0]) * (qv[1] - qv[0]))])


def _main_run(values: np.ndarray, bins: int, min_share: float = 0.0) -> np.ndarray:
    """Mask of the values in the contiguous run of populated histogram bins that holds the most points; a bin is
    populated when it holds more than ``min_share`` of the mean count of the non-empty bins (stray points scattered
    around the car fill bins thinly)."""
    counts, edges = np.histogram(values, bins=bins)
    floor = min_share * float(counts[counts > 0].mean())
    best, best_n, start = (0, 0), -1, None
    for k in range(bins + 1):
        filled = k < bins and counts[k] > floor
        if filled and start is None:
            start = k
        if not filled and start is not None:
            n = int(counts[start:k].sum())
            if n > best_n:
                best, best_n = (start, k), n
            start = None
    lo, hi = edges[best[0]], edges[best[1]]
    return (values >= lo) & (values <= hi)


def capture_car(cloud: np.ndarray, grid: AeroGrid, settings: CaptureSettings = CaptureSettings(),
                choose_front: Callable[[np.ndarray, np.ndarray], int] | None = None) -> CaptureResult:
    """Alg. 6.1 on a SLAM map ``cloud`` (n, 3); see the module's docstring. Raises ``ValueError`` with the step's
    name when too little is left to go on."""
    import open3d as o3d

    s = settings
    times: dict[str, float] = {}
    kept: dict[str, int] = {}
    t = time.perf_counter()
    p = np.asarray(cloud, float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    kept["input"] = len(p)
    if len(p) < 50:
        raise ValueError(f"capture: {len(p)} finite map points; at least 50 are needed")
    if s.max_points and len(p) > s.max_points:
        p = thin(p, s.max_points)
        kept["thinned"] = len(p)
        if len(p) < 50:
            raise ValueError(f"capture: max_points {s.max_points} thins the map to {len(p)} points; at least 50 are "
                             "needed (below about 2500 the car itself gets too few: benchmarks/results/aero_video.md)")
    times["thin"] = time.perf_counter() - t
    t = time.perf_counter()
    h = _spacing(p)
    p = _density_cull(p, s.min_neighbours, s.density_radius)
    kept["density"] = len(p)
    times["density"] = time.perf_counter() - t

    t = time.perf_counter()
    c = p.mean(axis=0)
    r = np.linalg.norm(p - c, axis=1)
    p = p[r <= np.quantile(r, s.centroid_keep)]
    kept["centroid"] = len(p)
    times["centroid"] = time.perf_counter() - t

    t = time.perf_counter()
    o3d.utility.random.seed(s.seed)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    plane, _inl = pcd.segment_plane(distance_threshold=s.floor_tolerance * h, ransac_n=3,
                                    num_iterations=s.floor_iterations)
    n = np.asarray(plane[:3], float)
    d0 = float(plane[3]) / float(np.linalg.norm(n))
    n /= np.linalg.norm(n)
    # RANSAC's plane through three of the points, refined by least squares on the floor's band (a band of robust
    # sigmas about the plane): on a thick floor the three-point plane tilts by a noise's worth, and which three
    # RANSAC draws differs from call to call
    n, d0 = _refine_plane(p, n, d0, s.floor_tolerance * h)
    off = np.abs(p @ n + d0) > s.floor_tolerance * h
    height = p @ n + d0
    if off.sum() < 30:
        raise ValueError(f"capture: {int(off.sum())} points off the floor plane; the map holds no car")
    # which side is up: the car reaches farther above the plane than the floor's noise reaches below it (a car
    # under about 2 % of the points would leave this to the noise; a count of points clear of the band on each
    # side was tried and flipped a development map whose far floor is thick)
    if np.quantile(height, 0.98) < -np.quantile(height, 0.02):  # the car stands farther above than noise reaches below
        n, d0, height = -n, -d0, -height
    # the floor's own level and thickness where each point stands: the median and robust spread of the heights of
    # its 30 nearest floor-band points (in the plane). A depth camera's floor grows thicker with distance and a
    # SLAM map's floor bends with its drift; the band is twice the cut of the global noise, which is measured from
    # the points under the plane (nothing of the car lies there; their median is 0.6745 sigma for a normal noise)
    under = height < 0
    cut = np.full(len(p), s.floor_tolerance * h)
    if under.sum() >= 30:
        e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        plane_xy = p @ np.stack([e1, np.cross(n, e1)]).T
        band = np.abs(height) < 2.0 * s.floor_sigmas * float(np.median(-height[under])) / 0.6745
        if band.sum() >= 30:
            _, nn = cKDTree(plane_xy[band]).query(plane_xy, k=30)
            hb = height[band][nn]
            level = np.median(hb, axis=1)
            sigma = 1.4826 * np.median(np.abs(hb - level[:, None]), axis=1)
            cut = np.maximum(cut, level + s.floor_sigmas * sigma)
    keep = off & (height > cut)
    floor_cut = float(np.median(cut[keep])) if keep.any() else float(np.median(cut))
    p = p[keep]
    kept["floor"] = len(p)
    if len(p) < 30:
        raise ValueError(f"capture: {len(p)} points above the floor; the map holds no car")
    if s.above_floor_density > 0:
        # the floor's remnants (points of a noisy or drifting floor a little above its cut) lie scattered around the
        # car, sparser than the car's own surface: the density culling of step 1 again, on what is left
        p = _density_cull(p, s.min_neighbours, s.above_floor_density)
        kept["above_floor_density"] = len(p)
        if len(p) < 30:
            raise ValueError(f"capture: {len(p)} points above the floor after its density culling; the map holds "
                             "no car")
    times["floor"] = time.perf_counter() - t

    t = time.perf_counter()
    q = p - np.outer(p @ n + d0, n)  # on the floor
    q0 = q.mean(axis=0)
    w, V = np.linalg.eigh(np.cov((q - q0).T))
    a = V[:, np.argmax(w)]
    a -= (a @ n) * n
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    R = np.stack([a, b, n])  # rows: the car's x (length), y (width), z (up)
    local = (p - q0) @ R.T
    local[:, 2] = p @ n + d0
    times["pca"] = time.perf_counter() - t

    t = time.perf_counter()
    keep = np.ones(len(local), bool)
    for k in range(3):
        keep &= _main_run(local[:, k], s.noise_bins, s.noise_min_share)
    local = local[keep]
    kept["noise"] = len(local)
    if len(local) < 30:
        raise ValueError(f"capture: {len(local)} points left after the noise removal; the map holds no car")
    # boxAdjustment: the length axis turned to the box of least area (PCA's axis leans towards where the map holds
    # more points, one side or one end: a SLAM map is not uniform)
    th = _box_angle(local[:, :2])
    c_, s_ = np.cos(th), np.sin(th)
    a, b = c_ * a + s_ * b, c_ * b - s_ * a
    R = np.stack([a, b, n])
    local[:, :2] = local[:, :2] @ np.array([[c_, -s_], [s_, c_]])
    lo = np.quantile(local, s.box_quantile, axis=0)
    hi = np.quantile(local, 1.0 - s.box_quantile, axis=0)
    length = float(hi[0] - lo[0])
    scale = s.length_m / length if s.length_m else 1.0
    centre = np.array([lo[0], 0.5 * (lo[1] + hi[1]), 0.0])
    car_pts = (local - centre) * scale
    box = np.array([length, hi[1] - lo[1], hi[2]]) * scale
    times["box"] = time.perf_counter() - t

    t = time.perf_counter()
    lowest = float(np.quantile(car_pts[:, 2], 0.02))
    hh = _spacing(car_pts)
    # close the unseen underside at the sills' height: the footprint's points dropped to the lowest seen height
    # (spaced a tenth of alpha, or the map's own spacing if coarser: closed for the alpha complex, few points)
    foot = car_pts[car_pts[:, 2] < lowest + 0.25 * (box[2] - lowest)].copy()
    step = max(hh, s.cap_spacing * s.alpha_m)
    xs = np.arange(car_pts[:, 0].min(), car_pts[:, 0].max(), step)
    cap = []
    for x0 in xs:
        sel = np.abs(foot[:, 0] - x0) < step
        if sel.sum() >= 2:
            y0, y1 = foot[sel, 1].min(), foot[sel, 1].max()
            ys = np.arange(y0, y1 + 1e-9, step)
            cap.append(np.column_stack([np.full(len(ys), x0), ys, np.full(len(ys), lowest)]))
    closed = np.vstack([car_pts] + cap)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(closed))
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):  # "invalid tetra" per sliver
        try:
            mesh = o3d.geometry.TriangleMesh.create_from_point_cloud_alpha_shape(pcd, s.alpha_m)
        except RuntimeError as err:  # Qhull refuses a degenerate set (flat, too few distinct points)
            why = re.sub(r"\x1b\[[0-9;]*m", "", " ".join(str(err).split()))[:160]
            raise ValueError(f"capture: the alpha shape of {len(closed)} points failed ({why})") from None
    verts, tris = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    times["alpha_shape"] = time.perf_counter() - t

    t = time.perf_counter()

    def mirror(flip: bool) -> tuple[np.ndarray, np.ndarray]:
        """The half turn about the vertical that puts the other end at x = 0 (D, e: x' = D x + e)."""
        if not flip:
            return np.eye(3), np.zeros(3)
        return np.diag([-1.0, -1.0, 1.0]), np.array([box[0], 0.0, 0.0])

    # the alpha shape's interior: the Delaunay tetrahedra of circumradius under alpha (the alpha complex)
    dt = Delaunay(closed)
    kept_tet = circumradii(closed[dt.simplices]) < s.alpha_m
    pts = grid.points()
    # only grid points inside the box of the closed cloud can be in it (the box is its own image under the half turn)
    lo_c, hi_c = closed.min(axis=0), closed.max(axis=0)
    half_w = max(abs(lo_c[1]), abs(hi_c[1]))
    near = np.flatnonzero((pts[:, 0] >= min(lo_c[0], box[0] - hi_c[0])) & (pts[:, 0] <= max(hi_c[0], box[0] - lo_c[0]))
                          & (np.abs(pts[:, 1]) <= half_w) & (pts[:, 2] >= lo_c[2]) & (pts[:, 2] <= hi_c[2]))

    def presence(flip: bool) -> np.ndarray:
        D, e = mirror(flip)
        simplex = dt.find_simplex((pts[near] - e) @ D)  # D is its own inverse
        out = np.zeros(len(pts))
        out[near] = (simplex >= 0) & kept_tet[np.maximum(simplex, 0)]
        return out

    phi = [presence(False), presence(True)]
    if choose_front is not None:
        flip = bool(choose_front(phi[0], phi[1]))
    else:  # without a database: the nose is the end whose top is lower (a hood, not a tailgate)
        third = box[0] / 3.0
        front = car_pts[car_pts[:, 0] < third, 2]
        rear = car_pts[car_pts[:, 0] > box[0] - third, 2]
        flip = bool(np.quantile(front, 0.9) > np.quantile(rear, 0.9))
    D, e = mirror(flip)
    times["presence"] = time.perf_counter() - t
    # the map -> car similarity: x_car = scale * D (R x + k) + e
    k = -(R @ q0) + np.array([0.0, 0.0, float(n @ q0) + d0]) - centre
    return CaptureResult(presence=phi[int(flip)], points=car_pts @ D.T + e, vertices=verts @ D.T + e,
                         triangles=tris, scale=scale, rotation=D @ R, translation=scale * (D @ k) + e, box=box,
                         kept=kept, seconds=times, floor_cut=floor_cut)
