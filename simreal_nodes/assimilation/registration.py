"""Registration of a model to the SLAM map and linking of map points to model nodes (thesis §4.4.1, §4.5.3).

- :func:`register_rgbd` (``anchor: registration``): the model placed in the map from depth images fused in the map
  frame (:func:`depth_cloud`) and a user's rough guess: support plane by RANSAC, then point-to-plane ICP of the
  measured points onto the model surface, with a quality figure and a refusal of a bad fit. It works on depth,
  not on the SLAM's sparse map points (on those, plane + ICP was 10 mm and tens of degrees off even from a
  close guess); a monocular map has no depth and no metric scale, so registration there is not offered.
- :func:`link`: each map point near the model surface gets 3 model nodes and weights (Eq. 4.10): by default
  the corners of the closest surface triangle with the barycentric weights of the point's foot on it (the
  surface the camera sees, exactly as the mesh interpolates it), or, as the thesis writes it, the 3 nearest
  nodes with inverse-distance weights (``method="idw"``; on the joint boot at theta = 0.86 rad this
  interpolates the displacement 0.7 mm off at the median, 1.7 mm at p90). Points farther than ``max_dist``
  are static scene points.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.depth_state import TURN_STEPS, DepthState, DepthStateConfig, fit_state
from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import SimrealError
from simreal_nodes.rom.model import ReducedModel


@dataclass
class Links:
    nodes: np.ndarray  # (N, 3) model node indices
    weights: np.ndarray  # (N, 3) inverse-distance weights (sum 1)
    dist: np.ndarray  # (N,) distance to the nearest node (object frame units)
    on_object: np.ndarray  # (N,) bool


class LinkIndex:
    """The search structures :func:`link` needs for one configuration of the model's nodes (``model_points``):
    a KD-tree over the candidate nodes, the surface triangles whose corners are all candidates and a KD-tree over
    their centroids. Built once and handed to every :func:`link` against the same configuration (a tracker's
    alpha_z search relinks its points against the same few configurations two dozen times a frame)."""

    def __init__(self, model_points: np.ndarray, candidate_nodes: np.ndarray,
                 triangles: np.ndarray | None = None) -> None:
        self.cand = np.asarray(candidate_nodes, dtype=np.int64)
        self.nodes = cKDTree(model_points[self.cand])
        F = np.zeros((0, 3), np.int64) if triangles is None else np.asarray(triangles, dtype=np.int64)
        self.F = F[np.isin(F, self.cand).all(axis=1)] if len(F) else F
        self.centroids = cKDTree(model_points[self.F].mean(axis=1)) if len(self.F) else None


def link(points_obj: np.ndarray, model_points: np.ndarray, candidate_nodes: np.ndarray, max_dist: float,
         k: int = 3, triangles: np.ndarray | None = None, method: str = "barycentric",
         index: LinkIndex | None = None) -> Links:
    """Link points (object frame) to 3 model nodes with weights (Eq. 4.10). ``triangles``: the model's
    surface (M, 3); without it, or where a node that is on no triangle is nearer than every triangle (a
    lever's embedded nodes), the k nearest candidate nodes with inverse-distance weights. ``index``: the
    :class:`LinkIndex` of these ``model_points``, candidates and triangles (None: built here)."""
    P = np.asarray(points_obj, dtype=np.float64).reshape(-1, 3)
    if index is None:
        index = LinkIndex(model_points, candidate_nodes, triangles)
    cand = index.cand
    tree = index.nodes
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
        if len(index.F):
            tn, tb, td = closest_triangles(P, model_points, index.F, tree=index.centroids)
            on_surface = td <= dist + 1e-9
            nodes[on_surface], w[on_surface], dist[on_surface] = tn[on_surface], tb[on_surface], td[on_surface]
        rest = np.flatnonzero(~on_surface)
        if len(rest):  # nodes on no surface triangle (a lever's grid): the best triangle of near nodes
            tn, tb, td = _near_node_triangles(P[rest], model_points, cand, tree=index.nodes)
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


def _near_node_triangles(P: np.ndarray, V: np.ndarray, cand: np.ndarray, k: int = 6,
                         tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Among the triangles of each point's k nearest candidate nodes that hold the point's foot, the one
    nearest the point (ties: the smallest): its nodes and the foot's barycentric coordinates, which
    reproduce any linear displacement field (a rigid motion) exactly at the foot; distance inf where no
    triangle holds it. ``tree``: a KD-tree over ``V[cand]`` (None: built here)."""
    from itertools import combinations

    tree = tree if tree is not None else cKDTree(V[cand])
    k = min(k, len(cand))
    _, idx = tree.query(P, k=k)
    idx = idx.reshape(len(P), k)
    combos = np.array(list(combinations(range(k), 3)), np.int64).reshape(-1, 3)
    tri = cand[idx[:, combos]]  # (N, C, 3): every triangle of three of the k nodes
    A, B, C = V[tri[..., 0]], V[tri[..., 1]], V[tri[..., 2]]
    Q = P[:, None, :]
    e0, e1, q = B - A, C - A, Q - A
    d00, d01, d11 = (e0 * e0).sum(-1), (e0 * e1).sum(-1), (e1 * e1).sum(-1)
    d20, d21 = (q * e0).sum(-1), (q * e1).sum(-1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-6 * np.maximum(d00 * d11, 1e-300)  # not collinear
    den = np.where(ok, den, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    ww = (d00 * d21 - d01 * d20) / den
    u = 1 - v - ww
    ok &= (u >= -1e-9) & (v >= -1e-9) & (ww >= -1e-9)
    foot = u[..., None] * A + v[..., None] * B + ww[..., None] * C
    dist = np.linalg.norm(foot - Q, axis=-1)
    per = np.linalg.norm(e0, axis=-1) + np.linalg.norm(e1, axis=-1) + np.linalg.norm(C - B, axis=-1)
    key = np.where(ok, dist + 1e-3 * per, np.inf)
    key[np.isnan(key)] = np.inf
    j = np.argmin(key, axis=1)  # the first of equal keys, as a scan in combination order would keep
    r = np.arange(len(P))
    held = np.isfinite(key[r, j])
    best_n = np.where(held[:, None], tri[r, j], 0)
    best_b = np.where(held[:, None], np.stack([u, v, ww], axis=-1)[r, j], 0.0)
    best_d = np.where(held, dist[r, j], np.inf)
    return best_n, best_b, best_d


def closest_triangles(P: np.ndarray, V: np.ndarray, F: np.ndarray, n_candidates: int = 12,
                      tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point, the closest of the triangles F (among the ``n_candidates`` with the nearest
    centroids): its corner nodes (N, 3), the barycentric coordinates of the closest point (N, 3) and the
    distance (N,). ``tree``: a KD-tree over the centroids ``V[F].mean(axis=1)`` (None: built here)."""
    tree = tree if tree is not None else cKDTree(V[F].mean(axis=1))
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


def sample_surface(V: np.ndarray, F: np.ndarray, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points drawn uniformly by area on the triangles F of V, and the unit normals of their triangles (the
    triangles' winding: outward for the models' boundary surfaces)."""
    rng = np.random.default_rng(seed)
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cross = np.cross(B - A, C - A)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    tri = rng.choice(len(F), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts: np.ndarray = A[tri] + u[:, None] * (B[tri] - A[tri]) + v[:, None] * (C[tri] - A[tri])  # indexing: Any
    normals: np.ndarray = cross[tri] / np.maximum(2 * area[tri], 1e-300)[:, None]
    return pts, normals


# -- registration on RGB-D (thesis §4.5.3) ----------------------------------------------------------------------
def revolves_about_z(S: np.ndarray, N: np.ndarray, tree: cKDTree, centre: np.ndarray, tol: float,
                     angles_deg: tuple[float, ...] = (17.0, 45.0, 90.0, 151.0)) -> bool:
    """Whether the surface samples ``S`` (object frame, unit normals ``N``, indexed by ``tree``) map onto the
    surface when turned about the z axis through ``centre``: at each of ``angles_deg``, 95 % of the turned samples
    lie within ``tol`` of the tangent plane of their nearest sample, itself within ``4 tol``. A body of revolution
    passes at every angle; a beam, a plate or a bunny fails at the first; no samples, no body of revolution."""
    if len(S) == 0:
        return False
    for deg in angles_deg:
        Q = (S - centre) @ G.rot_axis("z", np.deg2rad(deg)).T + centre
        d, i = tree.query(Q)
        on = (d < 4 * tol) & (np.abs(np.sum(N[i] * (Q - S[i]), axis=1)) < tol)
        if np.mean(on) < 0.95:
            return False
    return True


def turned_like(T_map_obj: np.ndarray, guess: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """A body of revolution's fit ``T_map_obj`` turned about its own z axis (through ``centre``, object frame) to
    the turn of ``guess`` about that axis: the same surface, so the same fit, but the turn the user gave rather than
    the one the ICP drifted to, so that a constant measured from it (the boot's alpha_z, from 0) starts where the
    scene file says and a rerun on other depth lands on the same turn."""
    phi = G.turn_about_z(guess[:3, :3].T @ T_map_obj[:3, :3])  # the fit's turn about z against the guess's
    return T_map_obj @ G.make_T(t=centre) @ G.make_T(G.rot_axis("z", -phi)) @ G.make_T(t=-centre)


def lifted_onto(T_map_obj: np.ndarray, points: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """``T_map_obj`` moved along the ``plane``'s normal (n, d: n.x + d = 0, n up) just far enough that none of the
    object's ``points`` (object frame) lies under it: nothing stands under the plane it rests on, so a guess whose
    model dips below it is lifted onto it (one 4 cm under the table, 11 cm off in all, was refused on development
    seed 36 of the boot's family); a guess above it is returned as it is."""
    n = np.asarray(plane[:3], dtype=np.float64)
    below = -float(np.min((points @ T_map_obj[:3, :3].T + T_map_obj[:3, 3]) @ n + plane[3]))
    return G.make_T(T_map_obj[:3, :3], T_map_obj[:3, 3] + below * n) if below > 0 else T_map_obj


class RegistrationError(SimrealError):
    """The registration found no fit it can vouch for (too little of the model seen, or a bad residual)."""


class SlideRefused(RegistrationError):
    """The fit is otherwise good but can slide along the object's axis further than ``max_slide_spread``: the views
    did not see its ends well enough to place it along that axis (:attr:`RegistrationConfig.slide_from_guess`)."""


@dataclass(frozen=True)
class RegistrationConfig:
    """How an RGB-D registration collects its views and judges its fit (lengths in metres).

    ``frames`` depth images, every ``every``-th frame with a camera pose, are fused (several views see more of the
    object's faces than one, which pins its position along a prism's axis through the end faces);
    ``stride``: pixel step of the back-projection, ``voxel``: the fused cloud's grid. ``margin``: the crop around
    the guessed model box: it must hold the guess's error (a hand guess is off by centimetres and degrees: at
    10 degrees a 1 m beam's ends move 9 cm). ``floor_clear``: points this close above the support plane are
    dropped (the object rests there: its lower edge is lost, not its faces); ``contact_band``: the same for the
    object's underside in the fine stage (see :func:`register_rgbd`). A fit turned more than ``max_turn_deg`` from
    the (levelled) guess is in another basin and is not taken. The fit is refused below
    ``min_fitness`` (share of the model surface facing the cameras that has a measured point within
    ``inlier_dist``) or above ``max_rmse`` (point-to-plane residual of those inliers; the depth noise of a
    structured-light sensor at 1.5 m is about 4 mm). ``slide_ratio``: a direction whose share of the matched
    normals' scatter is under this (against the strongest) is one the fit can slide along (:func:`_pin_slide`); it
    is moved only where a slide would cover ``slide_cover`` more of the model's faces turned to the cameras. A fit that
    could slide over more than ``max_slide_spread`` at about the same cover (:func:`slide_spread`; at most 28 mm on
    development seeds 0-99) is refused: the data do not pin it. One that could slide over more than ``max_slide_share``
    of the model's extent along that direction (:func:`slide_share`) is kept but doubted: a position along it (a load's)
    may be off by half the slide. 5 % was chosen on development seeds 0-29 and seeds 0-9 with the camera at 0.5 and 0.7
    m: accepted fits reach 4.6 % (0.2 mm off), the one fit placed 45 mm off along its beam (seed 1 at 0.5 m) 7.3 % (43
    mm and 7.1 % where the whole scene ran, docs/stability.md; benchmarks/flag_calibration.py). A fit on depth that
    scatters more than ``max_noise`` about it (:func:`_noise`) is kept but doubted (:attr:`Registration.doubt`; its
    estimates are flagged): chosen on development seeds 0-9 with their depth made noisier (`./run bench depth_quality`),
    3.5 mm flags 14 of the 17 fits more than 3 mm or 2 degrees off and 4 of the 72 within them. ``fine``: the fine
    stage's freedom, ``full`` (6 degrees) or ``upright`` (translation and a turn about the up axis, roll and pitch from
    the support plane, where one was found; see :meth:`for_camera`)."""

    frames: int = 3
    every: int = 4
    stride: int = 2
    voxel: float = 0.002
    margin: float = 0.15
    floor_dist: float = 0.008
    floor_clear: float = 0.006
    contact_band: float = 0.004
    max_turn_deg: float = 30.0
    inlier_dist: float = 0.006
    min_fitness: float = 0.5
    max_rmse: float = 0.004
    max_noise: float = 0.0035
    max_range: float = 4.0
    slide_ratio: float = 0.05
    slide_cover: float = 0.01
    max_slide_spread: float = 0.06
    max_slide_share: float = 0.05
    fine: str = "full"
    # > 0: the fit is polished from itself and from starts moved this far (metres) either way along each object
    # axis, each with ICP at 4 and 2 mm, keeping the one that most of the faces meet within ``polish_dist``: the fine
    # stage can stop a pleat away on the joint boot's bellows (3.8 mm off, development seeds 1 and 5 of its family),
    # where the 6 mm cover prefers the wrong fit and a 2 mm cover the right one (0: off); a deformed fit
    # (:func:`register_loaded`) is polished too (:func:`_polished_state`)
    polish: float = 0.0
    polish_dist: float = 0.002
    # the support plane's RANSAC runs on at most this many of the fused points (a seeded random subset: a plane's
    # share of them is its share of the cloud), its inliers then counted over the whole cloud (0: RANSAC on the
    # whole cloud). Stop 88, the boot family's development seeds 0-9 (`family_boot_registration_dev_plane_samples`
    # against `..._before_plane_samples`, one after the other): the registration step 3.6 s at the median against
    # 4.55 s, placed as well (0.14 against 0.13 mm, 0.06 against 0.05 degrees). A live graph registers in a worker
    # on the cores its SLAM uses (benchmarks/live_slam.py)
    plane_samples: int = 20000
    # where the coarse stage's best fit covers under min_fitness of the faces, it is run again with each point paired
    # only with model faces turned to the cameras at the guess (:func:`register_rgbd`); that fit replaces the first
    # where it covers this share more of the faces (0: off)
    coarse_gain: float = 0.05
    # a body of revolution about its z axis (:func:`revolves_about_z`): its ICP steps hold the turn about that axis,
    # which its surface does not fix, and the coarse starts turned about it are left out (False: the steps turn it
    # freely, as before stop 89; either way the fit takes the guess's turn at the end). Stop 89, the boot family's
    # development seeds 0-9 (`family_boot_registration_dev_hold_spin` against `..._plane_samples`): the registration
    # step 2.6 s at the median against 3.6 s, placed as well (0.14 mm and 0.06 degree both); other objects run as
    # before, to the bit
    hold_spin: bool = True
    # a fit refused only because it can slide along the object's axis (its ends not seen, :class:`SlideRefused`) is
    # kept with its position along that axis taken from the guess (anchor.guess) and doubted (its estimates flagged),
    # instead of refused: the data hold the other five degrees of freedom. The tracker sets it after
    # ``slide_refusals`` such refusals of an object (each a new set of views); before stop 90 such an object waited for
    # its ends to be seen, and was never placed where the camera never saw them (held-out beam 1081 of the family)
    slide_from_guess: bool = False
    slide_refusals: int = 2
    # a loaded object's rigid fit tilted more than this (degrees) from the support plane is levelled about its
    # centre and about each end of its long axis, and the deformed state fitted from each (:func:`_levelled_state`):
    # a sagging beam's rest shape fitted rigidly follows the sag from one end and tilts, and levelled about its
    # centre it sinks by half the tilt's drop (development seeds 40 and 49 of the loaded family until stop 117:
    # tilted 4.7 and 4.0 degrees, levelled 35 and 17 mm low in scratch runs of their captured views, no deformation
    # read). An end's fit replaces the centre's only where it is deformed and its deformation lowers the cost more
    # (:func:`_levelled_state`). 0: the centre only
    level_ends_deg: float = 1.0

    @classmethod
    def for_camera(cls, camera: dict[str, Any]) -> RegistrationConfig:
        """The configuration for a scene's ``camera`` block. Depth from a stereo pair (no depth topic, a right
        image) takes the ``upright`` fine stage: SGBM smooths a beam's few-centimetre section over its corners, and
        the full fine stage rolled thin beams 4-10 degrees about their axis on development seeds 0-7 (stereo), where
        the support plane holds roll and pitch to 0.1 degrees. RGB-D keeps the full stage (a boot's base is not a
        resting prism). SGBM's smoothed ends let well-placed fits slide further (up to 6.7 % of the beam on
        development seeds 0-19 of the stereo family, 2.2 mm off), so a stereo fit is doubted past 8 % of the
        object's length rather than 5 %."""
        stereo = camera.get("depth") is None and camera.get("right_image") is not None
        return cls(fine="upright", max_slide_share=0.08) if stereo else cls()


@dataclass
class Registration:
    """The model's pose in the map and how well it is supported: ``fitness`` (share of the model surface facing
    the cameras with a measured point within the inlier distance), ``rmse`` (point-to-plane residual of those
    points, metres), ``points`` (measured points within the inlier distance of the model), ``plane`` (a, b, c, d)
    of the support plane in the map (None when none was found under the object)."""

    T_map_obj: np.ndarray
    fitness: float
    rmse: float
    points: int
    plane: np.ndarray | None
    slide_spread: float = 0.0  # metres the fit could slide along a weakly held axis at about the same cover
    # :func:`register_loaded`: the model state (mu) the depth showed the object deformed in (None: at rest), and
    # what the depth fit found
    state: np.ndarray | None = None
    state_reason: str = ""
    # the depth's noise about the fitted surface (metres: a robust sigma of the point-to-plane residuals within
    # 3 x inlier_dist, :func:`_noise`), and why the pose is doubted ('' when it is not): a fit accepted on depth
    # noisier than ``max_noise``, or one that can slide over more than ``max_slide_share`` of the object along its
    # axis (docs/stability.md); its estimates are flagged low-confidence
    noise: float = 0.0
    doubt: str = ""
    # why the position along the object's axis is the guess's (:attr:`RegistrationConfig.slide_from_guess`), '' when
    # the data placed it; part of ``doubt`` too
    along_from_guess: str = ""
    # the model's rest shape is a body of revolution about its z axis (:func:`revolves_about_z`): the depth does not
    # say how it is turned about that axis, and the pose keeps the guess's turn
    revolves: bool = False
    # such a body registered deformed (:func:`register_loaded`): the turn (radians, about its z axis through the
    # model's centroid, from the guess's turn) its deformed fit needed, the direction the load bends it in. Not in
    # ``T_map_obj``: a tracker with alpha_z starts from it (:func:`turned_about_axis` puts it in a pose)
    turn: float = 0.0


@dataclass(frozen=True)
class DepthViews:
    """Where the fused depth views were taken: camera poses ``T_wc`` (K, 4, 4, map frame), the camera, and for a
    stereo pair its ``baseline`` (metres; None: an RGB-D camera). A model point is measurable when some view has
    it in front, inside its image and, for stereo, with its match inside the right image (u - f T / z >= 0: the
    left edge of a stereo pair's image, as wide as the disparity, has no depth). The registration judges its cover
    on the measurable faces only: a part of the object that no view could measure is neither evidence for a pose
    nor against it."""

    T_wc: np.ndarray
    cam: CameraModel
    baseline: float | None = None

    @property
    def centres(self) -> np.ndarray:
        return np.asarray(self.T_wc, dtype=np.float64).reshape(-1, 4, 4)[:, :3, 3]

    def measurable(self, X: np.ndarray) -> np.ndarray:
        """Which map points X (N, 3) some view could measure (pinhole projection with K: the lens distortion, a
        few pixels at the image border, is left out)."""
        K, w, h = self.cam.K, self.cam.width, self.cam.height
        out = np.zeros(len(X), bool)
        for T in np.asarray(self.T_wc, dtype=np.float64).reshape(-1, 4, 4):
            Xc = (X - T[:3, 3]) @ T[:3, :3]
            z = Xc[:, 2]
            front = z > 0.05
            zs = np.where(front, z, 1.0)
            u = K[0, 0] * Xc[:, 0] / zs + K[0, 2]
            v = K[1, 1] * Xc[:, 1] / zs + K[1, 2]
            ok = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
            if self.baseline:
                ok &= u - K[0, 0] * self.baseline / zs >= 0
            out |= ok
        return out


class _Centres:
    """Camera positions alone (no image bounds known): every facing model point counts as measurable."""

    def __init__(self, centres: np.ndarray) -> None:
        self.centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)

    def measurable(self, X: np.ndarray) -> np.ndarray:
        return np.ones(len(X), bool)


def _views(cams: np.ndarray | DepthViews | _Centres) -> DepthViews | _Centres:
    return cams if isinstance(cams, (DepthViews, _Centres)) else _Centres(cams)


_GRIDS: dict[bytes, np.ndarray] = {}


_WITHIN_SLACK = (1e-3, 0.5)  # depth_cloud's ``within``: its tests widened by 1 mm and half a pixel


def _pixel_grid(cam: CameraModel, shape: tuple[int, ...], stride: int) -> np.ndarray:
    """The ideal (undistorted) pixels of every ``stride``-th pixel of an image of ``shape``, row-major (N, 2): the
    same for every frame of a camera, so undone once (the lens model's iterative inverse took 8 ms a frame at
    640 x 480, stride 2). Kept for the last few cameras asked for."""
    key = np.r_[cam.K.ravel(), cam.fisheye, cam.D, shape, stride].astype(np.float64).tobytes()
    grid = _GRIDS.get(key)
    if grid is None:
        v, u = np.mgrid[0:shape[0]:stride, 0:shape[1]:stride]
        grid = np.c_[u.ravel(), v.ravel()].astype(np.float64)
        if cam.has_distortion:
            grid = cam.undistort_points(grid)
        if len(_GRIDS) >= 4:
            _GRIDS.pop(next(iter(_GRIDS)))
        _GRIDS[key] = grid
    return grid


def depth_cloud(cam: CameraModel, depth: np.ndarray, T_wc: np.ndarray, stride: int = 2,
                max_range: float = 4.0, within: np.ndarray | None = None) -> np.ndarray:
    """A depth image (z along the optical axis, metres; NaN or 0: no return) back-projected with the camera model
    (lens distortion undone) into the map frame by ``T_wc``: (N, 3).

    ``within``: the corners (map frame, (M, 3)) of a box that a later crop keeps (:func:`.depth_state.crop`); the
    pixels that cannot hold a point of it are not back-projected. A point of the box (the corners' convex hull) has
    its depth, the camera's z, between the corners' least and greatest z, since z is linear; with every corner in
    front of the camera, its ideal pixel lies within the corners' ideal pixels' bounds too, since u and v are
    linear-fractional with a positive denominator. Both tests are widened by ``_WITHIN_SLACK`` so that rounding
    drops no point the crop would keep: the crop's result is unchanged, the rest of the image costs nothing (the
    joint boot's depth fit, ``benchmarks/depth_budget.py``)."""
    z = np.asarray(depth, dtype=np.float64)[0::stride, 0::stride].ravel()
    ok = np.isfinite(z) & (z > 0) & (z < max_range)
    grid = _pixel_grid(cam, depth.shape[:2], stride)
    if within is not None:
        C = G.transform(G.inv(np.asarray(T_wc, np.float64)), np.asarray(within, np.float64).reshape(-1, 3))
        m, px = _WITHIN_SLACK
        ok &= (z > C[:, 2].min() - m) & (z < C[:, 2].max() + m)
        if np.all(C[:, 2] > m):
            uv = C[:, :2] / C[:, 2:] @ cam.K[:2, :2].T + cam.K[:2, 2]  # ideal pixels (the pinhole; skew kept)
            lo, hi = uv.min(axis=0) - px, uv.max(axis=0) + px
            ok &= (grid[:, 0] > lo[0]) & (grid[:, 0] < hi[0]) & (grid[:, 1] > lo[1]) & (grid[:, 1] < hi[1])
    ok &= np.isfinite(grid[:, 0])  # a fisheye pixel with no ray in front of the camera
    P = cam.backproject(grid[ok], z[ok])
    out: np.ndarray = P @ T_wc[:3, :3].T + T_wc[:3, 3]
    return out


def register_rgbd(cloud: np.ndarray, model: ReducedModel, guess: np.ndarray, cam_centres: np.ndarray | DepthViews,
                  cfg: RegistrationConfig | None = None, seed: int = 0) -> Registration:
    """Place the model (its rest shape) in the map from a fused depth cloud (:func:`depth_cloud`, map frame).

    ``guess`` (T_map_obj) is the user's rough placement (centimetres, degrees off): it only picks the basin. A prism
    such as a box beam fits its own cloud as well turned end for end or upside down; the fit converges to the pose
    nearest the guess and may not turn more than ``max_turn_deg`` from it, so the guess decides between those
    mirror images (the load position of a beam turned end for end would be read mirrored). Steps, deterministic for
    one ``seed``:

    1. the support plane by RANSAC (Open3D ``segment_plane`` on at most ``plane_samples`` of the points, its
       generator seeded; :func:`support_inliers`), then a least-squares refit on its inliers among all the points
       (so that the plane does not depend on which sample won); used only when it is within 30 degrees
       of the guess's up axis (object z: the object rests on it upright). The points on or just above it are
       dropped and the guess is levelled onto it (its z axis turned onto the plane normal): two of the three
       angles a user gets wrong by eye are then known; a guess that sinks the model under the plane is lifted
       onto it (:func:`lifted_onto`);
    2. a crop to the guessed model box grown by ``margin``;
    3. point-to-plane ICP (Tukey-robust; :func:`icp_point_to_plane`, Open3D's loop made deterministic) of the
       cropped points onto samples of the model surface with their exact normals: each measured point finds its
       nearest model surface point, so the faces the cameras did not see take no part. Coarse (:func:`_icp_upright`,
       4 degrees of freedom: translation and a turn about the up axis): on a 5 mm grid from the levelled guess and
       from starts moved by a third of the margin along each object axis and turned 10 degrees about z either way (a
       guess centimetres off locks onto a neighbouring structure, a clamp's face, from a single start); of the fits
       that stay within ``max_turn_deg`` of the guess (a box beam of square section also fits rolled a quarter
       turn; for a body of revolution about its z axis, :func:`revolves_about_z`, only the axis's tilt counts: its
       turn about the axis is not in the depth, every ICP step holds it (``hold_spin``), the starts turned about z
       are left out, and the fit keeps the guess's turn, :func:`turned_like`), the one
       that covers most of the model surface facing the cameras goes on to the fine stage (full cloud, radii down
       to 4 mm), without the points in the ``contact_band`` above the model's underside. Where that best fit covers
       under ``min_fitness``, the starts are run again with the points paired only with the model faces turned to
       the cameras (a thin plate guessed too high otherwise settles with its top face's points on its underside);
    4. a slide along a direction that no matched face constrains (a prism's axis when its end faces are a few
       noisy pixels) is pinned by the model's cover of its faces turned to the cameras (:func:`_pin_slide`);
    5. the quality (:class:`Registration`), judged on the model faces turned to ``cam_centres`` (the cameras'
       positions, map frame; or :class:`DepthViews`: then only on the faces some view could measure, here and in
       step 4); :class:`RegistrationError` (carrying the registration) when it falls short of ``cfg``.

    Measured (``python -m benchmarks.family --seeds 0-9 --registration``, three views over the first 0.6 s, SLAM
    poses, guesses 17-81 mm and 4-15 degrees off): median 0.47 mm and 0.14 degrees, worst 1.3 mm and 0.94 degrees
    (the roll of a 16 mm thin beam about its axis).
    """
    import open3d as o3d

    cfg = cfg or RegistrationConfig()
    if cfg.fine not in ("full", "upright"):
        raise ValueError(f"RegistrationConfig.fine: expected 'full' or 'upright'; found '{cfg.fine}'")
    o3d.utility.random.seed(seed)
    guess = given = np.asarray(guess, dtype=np.float64)  # ``given``: the user's, before it is levelled
    P = _down(np.asarray(cloud, dtype=np.float64), cfg.voxel)
    if len(P) < 100:
        raise RegistrationError(f"registration: only {len(P)} depth points (is the depth image empty?)")
    plane = None
    if len(P) > 500:
        Q = P[support_inliers(P, cfg.floor_dist, cfg.plane_samples, seed)]
        c = Q.mean(axis=0)
        n = np.linalg.svd(Q - c, full_matrices=False)[2][2]
        up = guess[:3, 2]
        n = n if np.dot(n, up) >= 0 else -n
        if np.dot(n, up) > np.cos(np.deg2rad(30.0)) and np.dot(n, guess[:3, 3] - c) > -cfg.margin:
            plane = np.r_[n, -np.dot(n, c)]
            P = P[P @ n - np.dot(n, c) > cfg.floor_clear]
            axis = np.cross(up, n)
            angle = np.arctan2(np.linalg.norm(axis), np.dot(up, n))
            guess = G.make_T(G.exp_so3(axis / max(np.linalg.norm(axis), 1e-12) * angle) @ guess[:3, :3],
                             guess[:3, 3])
            guess = lifted_onto(guess, model.points, plane)
    lo, hi = model.points.min(axis=0) - cfg.margin, model.points.max(axis=0) + cfg.margin
    P_obj = (P - guess[:3, 3]) @ guess[:3, :3]
    P = P[np.all((P_obj > lo) & (P_obj < hi), axis=1)]
    if len(P) < 100:
        raise RegistrationError(f"registration: only {len(P)} depth points within {cfg.margin:.2f} m of the guessed "
                                "model box: is the guess (anchor.guess) near the object?")
    S, N = sample_surface(model.points, model.surface, _n_samples(model, 0.0025), seed)
    cams = _views(cam_centres)
    tree = cKDTree(S)

    centre = model.points.mean(axis=0)
    # a body of revolution about its z axis (the joint boot's bellows) fits its cloud equally well at any turn
    # about that axis: only the axis's tilt from the guess tells another basin (the turn about it is the tracker's
    # to find, a constant such as the boot's alpha_z). Its ICP steps hold that turn (a free one wandered from step to
    # step, so that the ICP ran to its last iteration), and the starts turned about the axis are left out
    spin_free = revolves_about_z(S, N, tree, centre, cfg.inlier_dist / 3)
    spin = np.array([0.0, 0.0, 1.0]) if spin_free and cfg.hold_spin else None

    def icp(T: np.ndarray, radii: tuple[float, ...]) -> np.ndarray:
        for radius in radii:
            T = icp_point_to_plane(P, tree, N, T, radius, hold_turn_about=spin)
        return T

    step = cfg.margin / 3
    starts = [np.zeros(4)] + [np.r_[step * sgn * np.eye(3)[k], 0.0] for k in range(3) for sgn in (-1, 1)]
    if spin is None:
        starts += [np.r_[0.0, 0.0, 0.0, sgn * np.deg2rad(10.0)] for sgn in (-1, 1)]
    coarse = _down(P, 0.005)

    def coarse_fits(pair_tree: cKDTree, pair_N: np.ndarray) -> tuple[float, np.ndarray] | None:
        best: tuple[float, np.ndarray] | None = None
        for off in starts:
            # the start: the guess moved by off[:3] (object frame) and turned by off[3] about its z axis through the
            # model's centre; T maps the map into the object frame
            T_start = guess @ G.make_T(t=centre + off[:3]) @ G.make_T(G.rot_axis("z", off[3])) @ G.make_T(t=-centre)
            T = _icp_upright(coarse, pair_tree, pair_N, G.inv(T_start), centre, (0.05, 0.025, 0.012),
                             turn=spin is None)
            fit = _quality(coarse, T, S, N, cams, 0.008)[0]
            turn = (np.arccos(np.clip(T[2, :3] @ guess[:3, 2], -1.0, 1.0)) if spin_free
                    else np.arccos(np.clip((np.trace(T[:3, :3] @ guess[:3, :3]) - 1) / 2, -1.0, 1.0)))
            if turn > np.deg2rad(cfg.max_turn_deg):  # another basin: a mirror image, a square section rolled over
                continue
            if best is None or fit > best[0] + 1e-9:
                best = (fit, T)
        return best

    best = coarse_fits(tree, N)
    # the same starts again, each measured point paired only with model samples turned to some camera at the guess
    # (:func:`_facing`, within about 105 degrees of their normal): with every face a candidate, the points on a thin
    # object's top face pair with its underside once the guess sits more than half the thickness too high, and ICP
    # settles there, a thickness above the object (development plate 13, 36 mm thick, guessed 72 mm high: 0 % of its
    # faces covered, never placed). Run only where the first pass's best fit covers under ``min_fitness`` of the faces
    # (a fit that covers more is in the object's basin: its time is not spent), and taken where its cover beats the
    # first by ``cfg.coarse_gain``: a fit in the same basin stands as it was
    if cfg.coarse_gain > 0 and (best is None or best[0] < cfg.min_fitness):
        seen = _facing(S, N, (cams.centres - guess[:3, 3]) @ guess[:3, :3], cos_min=-0.25)
        other = coarse_fits(cKDTree(S[seen]), N[seen]) if 100 <= seen.sum() < len(S) else None
        if other is not None and (best is None or other[0] > best[0] + cfg.coarse_gain):
            best = other
    if best is None:
        raise RegistrationError(f"registration: every fit turned more than {cfg.max_turn_deg:.0f} degrees away from "
                                "the guess (anchor.guess): is it the object's orientation?")
    # the band where the object meets its supports: a clamp's top face is level with the object's underside and
    # ends where the object begins, so its points would pair with the object's end face and pull the object
    # onto the clamp (millimetres along a beam's axis); points within contact_band of the model's underside go
    z_obj = P @ best[1][2, :3] + best[1][2, 3]
    P = P[z_obj > model.points[:, 2].min() + cfg.contact_band]
    if cfg.fine == "upright" and plane is not None:  # roll and pitch stay the support plane's
        T = _icp_upright(P, tree, N, best[1], centre, (0.012, 0.006, 0.004), iterations=30, turn=spin is None)
    else:
        T = icp(best[1], (0.012, 0.006, 0.004))
    T = _pin_slide(P, T, S, N, cams, cfg)
    if cfg.polish > 0:
        upright = cfg.fine == "upright" and plane is not None

        def fine_icp(T0: np.ndarray) -> np.ndarray:
            if upright:
                return _icp_upright(P, tree, N, T0, centre, (0.004, 0.002), iterations=30, turn=spin is None)
            return icp(T0, (0.004, 0.002))

        T = _polished(P, T, S, N, cams, cfg, fine_icp)
    if spin_free:  # the depth does not say how it is turned about its axis: it keeps the guess's turn
        T = G.inv(turned_like(G.inv(T), guess, centre))
    fitness, rmse, hits = _quality(P, T, S, N, cams, cfg.inlier_dist)
    out = _judged(Registration(G.inv(T), fitness, rmse, hits, plane, slide_spread(P, T, S, N, cams, cfg),
                               revolves=spin_free), P, T, S, N, cfg)
    if fitness < cfg.min_fitness or rmse > cfg.max_rmse:
        raise RegistrationError(f"registration refused: {100 * fitness:.0f} % of the model surface facing the "
                                f"camera is matched (at least {100 * cfg.min_fitness:.0f} % needed), residual "
                                f"{1e3 * rmse:.1f} mm (at most {1e3 * cfg.max_rmse:.1f} mm)", out)
    if out.slide_spread > cfg.max_slide_spread:
        what = _slide_words(out.slide_spread)
        if cfg.slide_from_guess:
            return _slid_to_guess(out, P, T, S, N, cams, given, centre, cfg)
        raise SlideRefused(f"registration refused: the fit can slide along the object's axis {what} at about "
                           f"the same cover (at most {1e3 * cfg.max_slide_spread:.0f} mm): its ends are not "
                           "seen well enough to place it; show the camera an end of the object", out)
    return out


def _slide_words(spread: float) -> str:
    return "beyond the searched range" if not np.isfinite(spread) else f"over {1e3 * spread:.0f} mm"


def _slid_to_guess(out: Registration, P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray,
                   cams: DepthViews | _Centres, guess: np.ndarray, centre: np.ndarray,
                   cfg: RegistrationConfig) -> Registration:
    """The fit ``T`` (map -> object) slid along the axis it cannot be pinned on until the model's ``centre`` lies
    where the user's ``guess`` (as given, not levelled) puts it along that axis, but not beyond the shifts the data
    cover about as well as the best (:func:`_slide_cover`: a guess there contradicts the depth; an end of the
    searched range left open does not bound it), judged again and doubted: the other five degrees of freedom are the
    data's, the position along the axis the user's (a hand measurement is off by millimetres to centimetres, and a
    load's position along the axis with it). Refused (:class:`RegistrationError`) where the slid fit no longer meets
    ``min_fitness`` / ``max_rmse``."""
    views = _views(cams)
    sl = _slide_cover(P, T, S, N, views, cfg)
    if sl is None:  # every direction held at this fit: nothing to take from the guess
        return out
    axis, shifts, cover = sl
    T_map_obj = G.inv(T)
    a_map = T_map_obj[:3, :3] @ axis
    wanted = float(a_map @ ((guess[:3, :3] @ centre + guess[:3, 3]) - (T_map_obj[:3, :3] @ centre + T_map_obj[:3, 3])))
    # the shifts covered about as well as the best, by the measurable faces and (depth views) by every face turned to
    # the cameras, as :func:`slide_spread` judges: the wider of the two bounds (the measurable faces alone can hold a
    # fit whose hidden end sits at the edge of what the views measure)
    covers = [cover]
    if isinstance(views, DepthViews):
        other = _slide_cover(P, T, S, N, _views(views.centres), cfg)
        if other is not None and np.allclose(other[0], axis):
            covers.append(other[2])
    lo, hi = np.inf, -np.inf
    for cv in covers:
        near = cv >= cv.max() - cfg.slide_cover
        lo = min(lo, -np.inf if near[0] else float(shifts[near].min()))
        hi = max(hi, np.inf if near[-1] else float(shifts[near].max()))
    dx = float(np.clip(wanted, lo, hi))
    T = G.make_T(t=-dx * axis) @ T  # the model moves by dx along the axis: object-frame points move by -dx
    fitness, rmse, hits = _quality(P, T, S, N, cams, cfg.inlier_dist)
    slid = _judged(Registration(G.inv(T), fitness, rmse, hits, out.plane, out.slide_spread, out.state,
                                out.state_reason, revolves=out.revolves), P, T, S, N, cfg)
    if fitness < cfg.min_fitness or rmse > cfg.max_rmse:
        raise RegistrationError(f"registration refused: placed along its axis by the guess (anchor.guess), "
                                f"{100 * fitness:.0f} % of the model surface facing the camera is matched (at least "
                                f"{100 * cfg.min_fitness:.0f} % needed), residual {1e3 * rmse:.1f} mm (at most "
                                f"{1e3 * cfg.max_rmse:.1f} mm): is the guess's position along the object right?", slid)
    where = (f"{1e3 * dx:+.0f} mm from the fit's position" if dx == wanted else
             f"{1e3 * dx:+.0f} mm from the fit's position, at the end of what the depth allows (the guess: "
             f"{1e3 * wanted:+.0f} mm)")
    why = (f"placed along its axis by the guess (anchor.guess), {where}: the fit can slide along it "
           f"{_slide_words(out.slide_spread)} at about the same cover, its ends not seen; positions along the axis "
           "(a load's) are as good as the guess; show the camera an end of the object")
    return replace(slid, doubt="; ".join(d for d in (why, slid.doubt) if d), along_from_guess=why)


def register_loaded(cloud: np.ndarray, model: ReducedModel, guess: np.ndarray, cam_centres: np.ndarray | DepthViews,
                    lo: np.ndarray, hi: np.ndarray, cfg: RegistrationConfig | None = None,
                    state_cfg: DepthStateConfig | None = None, seed: int = 0,
                    n_modes: int | None = None) -> Registration:
    """:func:`register_rgbd`, then the model's deformation fitted to the same cloud (:func:`.depth_state.fit_state`,
    mu within ``lo`` / ``hi``): an object loaded while it is registered does not fit its rest shape (a bent
    beam's rigid fit is tilted to split the difference, or refused on its residual). Where the depth shows a
    deformation, the deformed fit replaces the rigid one: its pose (levelled onto the support plane, then a
    translation and a turn about the up axis with the deformation), judged again on the deformed surface with the
    same thresholds, and its state in :attr:`Registration.state`. Otherwise the rigid fit stands as it was.

    A body of revolution about its z axis (:attr:`Registration.revolves`) keeps the guess's turn about that axis here
    too: the deformed fit turns the model until its bend points the way the depth shows, a turn that is the load's
    direction (the boot's alpha_z), not the pose, since the rest shape does not show it. It is given apart, in
    :attr:`Registration.turn`. Until stop 104 it stayed in the pose: the boot registered with its lever bent was
    turned 14-27 degrees about its axis, and its tracker, measuring alpha_z from that pose, read alpha_z as far off
    (a scratch run of the 8 s boot clip, placed after its lever moved)."""
    guess = np.asarray(guess, np.float64)
    centre = model.points.mean(axis=0)

    def apart(reg: Registration) -> Registration:
        if not reg.revolves or reg.state is None:
            return reg
        turn = G.turn_about_z(guess[:3, :3].T @ reg.T_map_obj[:3, :3])
        return replace(reg, T_map_obj=turned_like(reg.T_map_obj, guess, centre), turn=turn)

    try:
        reg = _register_loaded(cloud, model, guess, cam_centres, lo, hi, cfg or RegistrationConfig(), state_cfg,
                               seed, n_modes)
    except RegistrationError as e:  # a refused fit it carries is given in the same convention
        if len(e.args) >= 2 and isinstance(e.args[1], Registration):
            e.args = (e.args[0], apart(e.args[1]), *e.args[2:])
        raise
    return apart(reg)


def turned_about_axis(T_map_obj: np.ndarray, turn: float, centre: np.ndarray) -> np.ndarray:
    """The pose ``T_map_obj`` turned by ``turn`` (radians) about its own z axis through ``centre`` (object frame):
    a registration's :attr:`Registration.turn` put back into its pose, for a consumer with no alpha_z to carry it."""
    return T_map_obj @ G.make_T(t=centre) @ G.make_T(G.rot_axis("z", turn)) @ G.make_T(t=-centre)


def _register_loaded(cloud: np.ndarray, model: ReducedModel, guess: np.ndarray, cam_centres: np.ndarray | DepthViews,
                     lo: np.ndarray, hi: np.ndarray, cfg: RegistrationConfig, state_cfg: DepthStateConfig | None,
                     seed: int, n_modes: int | None) -> Registration:
    """:func:`register_loaded` with the deformed fit's turn in its pose."""
    try:
        reg, failed = register_rgbd(cloud, model, guess, cam_centres, cfg, seed), None
    except RegistrationError as e:
        if len(e.args) < 2 or not isinstance(e.args[1], Registration):
            raise
        reg, failed = e.args[1], e
    T0 = reg.T_map_obj if reg.plane is None else _level(reg.T_map_obj, reg.plane[:3], model.points.mean(axis=0))
    if reg.revolves:  # its turn about the axis is the load's direction, searched over the circle (stop 105); the
        # polish's refit searches it again (the polished pose may have moved the bend), at a second search's cost
        state_cfg = replace(state_cfg or DepthStateConfig(), turn_steps=TURN_STEPS)
    cams = _views(cam_centres)
    st = fit_state(cloud, model, T0, lo, hi, cfg=state_cfg, n_modes=n_modes)
    st, shape = _levelled_state(cloud, model, reg, st, lo, hi, cams, cfg, state_cfg, seed, n_modes)
    if not st.deformed or shape is None:
        if failed is not None:
            raise failed
        return replace(reg, state_reason=st.reason)
    assert st.mu is not None
    st, u, S, N, P = _pinned_state(cloud, model, st, shape, lo, hi, cams, reg.plane, cfg, state_cfg, seed, n_modes)
    if cfg.polish > 0:
        st, u, S, N, P = _polished_state(cloud, model, st, (u, S, N, P), lo, hi, cams, reg.plane, cfg, state_cfg,
                                         seed, n_modes)
    assert st.mu is not None  # a deformed fit (the polish returns one too)
    T = G.inv(st.T_map_obj)
    fitness, rmse, hits = _quality(P, T, S, N, cams, cfg.inlier_dist)
    out = _judged(Registration(st.T_map_obj, fitness, rmse, hits, reg.plane, slide_spread(P, T, S, N, cams, cfg),
                               st.mu.copy(), st.reason, revolves=reg.revolves), P, T, S, N, cfg)
    if fitness < cfg.min_fitness or rmse > cfg.max_rmse:
        raise RegistrationError(f"registration refused (deformed fit: {st.reason}): {100 * fitness:.0f} % of the "
                                f"model surface facing the camera matched, residual {1e3 * rmse:.1f} mm, slide "
                                f"spread {1e3 * out.slide_spread:.0f} mm", out)
    sliding = out.slide_spread > cfg.max_slide_spread
    if sliding and cfg.slide_from_guess and (reg.along_from_guess or failed is not None):
        # the deformed fit slides, and the rigid fit was placed along the axis by the guess or was refused (its
        # residual: the object is bent): the deformed fit is placed there by the guess too
        return _slid_to_guess(out, P, T, S, N, cams, np.asarray(guess, dtype=np.float64), model.points.mean(axis=0),
                              cfg)
    if reg.along_from_guess:
        # the rigid fit could slide (its ends not seen) and was placed by the guess, but the deformed shape pins the
        # slide (a bent beam is not a prism): placed along the axis by its own cover, as a rigid fit is
        # (:func:`_pin_slide`), still doubted: the ends are not seen
        T = _pin_slide(P, T, S, N, cams, cfg)
        fitness, rmse, hits = _quality(P, T, S, N, cams, cfg.inlier_dist)
        pinned = _judged(Registration(G.inv(T), fitness, rmse, hits, reg.plane, slide_spread(P, T, S, N, cams, cfg),
                                      st.mu.copy(), st.reason, revolves=reg.revolves), P, T, S, N, cfg)
        if fitness < cfg.min_fitness or rmse > cfg.max_rmse:
            raise RegistrationError(f"registration refused (deformed fit: {st.reason}): {100 * fitness:.0f} % of the "
                                    f"model surface facing the camera matched, residual {1e3 * rmse:.1f} mm", pinned)
        why = ("the rigid fit could slide along the object's axis, its ends not seen; the deformed fit is placed "
               f"along it by its own cover of the depth (it can slide {_slide_words(pinned.slide_spread)} at about "
               "the same cover): show the camera an end of the object")
        return replace(pinned, doubt="; ".join(d for d in (why, pinned.doubt) if d))
    if sliding and cfg.slide_from_guess:  # the rigid fit was accepted, its slide pinned by the data: it stays there
        why = (f"the deformed fit can slide along the object's axis {_slide_words(out.slide_spread)} at about the "
               "same cover: kept where the rigid fit placed it")
        return replace(out, doubt="; ".join(d for d in (why, out.doubt) if d))
    if sliding:
        raise SlideRefused(f"registration refused (deformed fit: {st.reason}): {100 * fitness:.0f} % of the model "
                           f"surface facing the camera matched, residual {1e3 * rmse:.1f} mm: the fit can slide along "
                           f"the object's axis {_slide_words(out.slide_spread)} at about the same cover (at most "
                           f"{1e3 * cfg.max_slide_spread:.0f} mm): its ends are not seen well enough to place it; "
                           "show the camera an end of the object", out)
    return out


def _deformed_shape(cloud: np.ndarray, model: ReducedModel, st: DepthState, plane: np.ndarray | None,
                    cfg: RegistrationConfig, seed: int, n_modes: int | None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A deformed fit's shape as the registration judges it: the displacement u at its mu, surface samples and
    normals of the deformed model, and the cloud's object points (:func:`_object_points`, the band over the bent
    underside)."""
    assert st.mu is not None
    u = model.deformation_view(None, n_modes).field.evaluate(st.mu)
    S, N = sample_surface(model.points + u, model.surface, _n_samples(model, 0.0025), seed)
    P = _object_points(cloud, st.T_map_obj, model.points + u, float(model.points[:, 2].min()), plane, cfg,
                       rest=model.points)
    return u, S, N, P


def _long_ends(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two ends of a model's long horizontal axis (object frame): the points of the principal axis of their x-y
    spread, through their centroid, at their extreme projections on it."""
    centre = points.mean(axis=0)
    xy = points[:, :2] - centre[:2]
    axis2 = np.linalg.eigh(xy.T @ xy)[1][:, -1]
    axis = np.array([axis2[0], axis2[1], 0.0])
    t = (points - centre) @ axis
    return centre + t.min() * axis, centre + t.max() * axis


def _levelled_state(cloud: np.ndarray, model: ReducedModel, reg: Registration, st: DepthState, lo: np.ndarray,
                    hi: np.ndarray, cams: DepthViews | _Centres, cfg: RegistrationConfig,
                    state_cfg: DepthStateConfig | None, seed: int, n_modes: int | None
                    ) -> tuple[DepthState, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None]:
    """The deformed state ``st``, fitted from the rigid fit ``reg`` levelled about the model's centre, and its shape
    (:func:`_deformed_shape`; None where the fit is at rest). Where the rigid fit was tilted more than
    ``level_ends_deg`` from the support plane (a sagging beam's rest shape follows the sag from one end), the fit
    levelled about each end of the model's long axis (:func:`_long_ends`: a beam's supports, a cantilever's root,
    sit at their rest height while its middle or tip sags) is fitted too, and of the deformed fits the one whose
    deformation lowers its own rest shape's cost the most (``1 - cost / rest_cost``, the gain
    :func:`.depth_state.fit_state` takes a deformation on) is returned. Not the cover of the faces (:func:`_quality`),
    which at the inlier distance is the same to a thousandth for fits whose loads differ by percents: development seed
    46's far-end fit covered 0.9468 of its faces against the centre's 0.9462 and read its load 9.5 % of the range off
    (0.5 %), its gain +28 % against +56 %; seed 27 the same (2.6 % against 0.2 %, gains +62 % and +93 %). A body of
    revolution is levelled about its centre only (its turn is searched over the circle)."""
    if reg.plane is not None and not reg.revolves and cfg.level_ends_deg > 0:
        tilt = np.degrees(np.arccos(np.clip(abs(reg.T_map_obj[:3, 2] @ reg.plane[:3]), 0.0, 1.0)))  # either way up
        if tilt > cfg.level_ends_deg:
            def gain(fit: DepthState) -> float:
                return 1.0 - fit.cost / fit.rest_cost if fit.deformed and fit.rest_cost > 0 else -np.inf

            for end in _long_ends(model.points):
                again = fit_state(cloud, model, _level(reg.T_map_obj, reg.plane[:3], end), lo, hi, cfg=state_cfg,
                                  n_modes=n_modes)
                if again.mu is not None and gain(again) > gain(st):
                    st = again
    return st, (None if not st.deformed else _deformed_shape(cloud, model, st, reg.plane, cfg, seed, n_modes))


def _pinned_state(cloud: np.ndarray, model: ReducedModel, st: DepthState,
                  shape: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], lo: np.ndarray, hi: np.ndarray,
                  cams: DepthViews | _Centres, plane: np.ndarray | None, cfg: RegistrationConfig,
                  state_cfg: DepthStateConfig | None, seed: int, n_modes: int | None
                  ) -> tuple[DepthState, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The deformed fit's slide along the object's axis pinned by its cover of the depth (:func:`_pin_slide`), as
    the rigid fit's is, and its state fitted again from there (:func:`.depth_state.fit_state`, from the fit's mu:
    along a cantilever the load's position trades against the pose's). The deformed fit starts at the rigid fit's
    pose, and the rigid fit of a bent beam judges it without the sagging part (below the contact band over the
    rest shape's underside): a loaded cantilever's straight root slides along its axis at about the same cover, and
    the deformed fit, whose cost crops the cloud around the model, does not move it back (held-out seeds 1018 and
    1025 until stop 116: placed 57 and 53 mm along the axis without a doubt, the deformed shape's cover 0.78 there
    against 1.00 in place). ``shape``: the fit's displacement, surface samples, normals and object points. Where
    the slide covers no better, or the state fitted again is not deformed or covers no more of its faces than the
    fit did (a shape fitted far from its load's place can slide the wrong way: a cantilever's own surface bent 65
    mm at its tip, the fit started 50 mm towards the clamp, slid 68 mm further while the state's crop dropped the
    band over the rest underside, :func:`.depth_state.fit_state`), the fit and its shape are returned as they
    were."""
    u, S, N, P = shape
    T = G.inv(st.T_map_obj)
    T_pin = _pin_slide(P, T, S, N, cams, cfg)
    if np.array_equal(T_pin, T):
        return st, u, S, N, P
    again = fit_state(cloud, model, G.inv(T_pin), lo, hi, mu0=st.mu, cfg=state_cfg, n_modes=n_modes)
    if not again.deformed or again.mu is None:
        return st, u, S, N, P
    u2, S2, N2, P2 = _deformed_shape(cloud, model, again, plane, cfg, seed, n_modes)
    if (_quality(P2, G.inv(again.T_map_obj), S2, N2, cams, cfg.inlier_dist)[0]
            <= _quality(P, T, S, N, cams, cfg.inlier_dist)[0]):
        return st, u, S, N, P
    return again, u2, S2, N2, P2


def _polished_state(cloud: np.ndarray, model: ReducedModel, st: DepthState,
                    shape: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], lo: np.ndarray, hi: np.ndarray,
                    cams: DepthViews | _Centres, plane: np.ndarray | None, cfg: RegistrationConfig,
                    state_cfg: DepthStateConfig | None, seed: int, n_modes: int | None
                    ) -> tuple[DepthState, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``RegistrationConfig.polish`` for a deformed fit: its deformed shape (``shape``: displacement, surface samples,
    normals, object points) polished as :func:`_polished` polishes a rigid fit (upright ICP, a translation and a turn
    about the up axis: the deformed fit's own freedoms), on the object points thinned to 2 mm; where that moves the
    fit's centroid by more than half of ``polish`` or turns it by more than a degree, the state is fitted again from
    there (:func:`.depth_state.fit_state`, from the fit's mu) and the shape rebuilt; where that fit is not deformed,
    the fit stands as it was. The deformed fit stops a pleat away on a bent joint boot's bellows as the rigid fine
    stage does (a cloud of the model's own surface, the lever bent 20 degrees, the fit started 4 mm off along the
    bend: 4.5 mm off, its cover at 2 mm 0.50 against the right fit's 0.97; the 8 s boot clip registered with its lever
    at 37 degrees: 12 mm off, the lever read 31 degrees). Returns the fit and its shape."""
    u, S, N, P = shape
    tree = cKDTree(S)
    centre = model.points.mean(axis=0)
    Pd = _down(P, 0.002)
    T = G.inv(st.T_map_obj)
    T_pol = _polished(Pd, T, S, N, cams, cfg,
                      lambda T0: _icp_upright(Pd, tree, N, T0, centre, (0.004, 0.002), iterations=30))
    D = T_pol @ st.T_map_obj  # object -> object: what the polish did
    moved = np.linalg.norm(G.transform(D, centre[None])[0] - centre)
    if moved <= cfg.polish / 2 and abs(G.turn_about_z(D[:3, :3])) <= np.deg2rad(1.0):
        return st, u, S, N, P
    again = fit_state(cloud, model, G.inv(T_pol), lo, hi, mu0=st.mu, cfg=state_cfg, n_modes=n_modes)
    if not again.deformed or again.mu is None:
        return st, u, S, N, P
    return (again, *_deformed_shape(cloud, model, again, plane, cfg, seed, n_modes))


def _level(T_map_obj: np.ndarray, up: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The pose turned about the model's ``centre`` (object frame) so that its z axis is ``up`` (map frame)."""
    z = T_map_obj[:3, 2]
    axis = np.cross(z, up)
    angle = float(np.arctan2(np.linalg.norm(axis), np.dot(z, up)))
    if np.linalg.norm(axis) < 1e-12:  # already up, or upside down (the callers keep ``up`` on the guess's side)
        return T_map_obj
    R = G.exp_so3(axis / np.linalg.norm(axis) * angle)
    c = G.transform(T_map_obj, centre[None])[0]
    out: np.ndarray = G.make_T(R, c - R @ c) @ T_map_obj
    return out


def _object_points(cloud: np.ndarray, T_map_obj: np.ndarray, V: np.ndarray, z_under: float,
                   plane: np.ndarray | None, cfg: RegistrationConfig, rest: np.ndarray | None = None) -> np.ndarray:
    """The fused cloud (map frame) as a fit judges it (:func:`register_rgbd`, and the deformed fit with ``rest``):
    on the ``voxel`` grid, off the support plane, within ``margin`` of the box of V (object frame) and above the
    contact band over the underside (where the supports meet it): the rest shape's, at height ``z_under``; for a
    deformed shape V whose rest nodes are ``rest``, the band follows the bent underside (each point against the
    underside node nearest it across the object), so a beam that sags by more than the band keeps its lower faces
    where it sags (stop 115: its cover, judged on the whole bent surface, had counted them as unmatched). Where the
    underside does not move (at the supports, or u = 0) the rule is the rest shape's."""
    P = _down(np.asarray(cloud, dtype=np.float64), cfg.voxel)
    if plane is not None:
        P = P[P @ plane[:3] + plane[3] > cfg.floor_clear]
    Q = G.transform(G.inv(T_map_obj), P)
    lo, hi = V.min(axis=0) - cfg.margin, V.max(axis=0) + cfg.margin
    keep = np.flatnonzero(np.all((lo < Q) & (hi > Q), axis=1))  # a NaN coordinate fails both comparisons
    floor = np.full(len(keep), z_under)
    if rest is not None:
        under = np.flatnonzero(rest[:, 2] <= z_under + 1e-9)
        sag = V[under, 2] - rest[under, 2]
        if len(under) and np.any(sag != 0.0):  # only the points in the box are searched
            _, nearest = cKDTree(V[under, :2]).query(Q[keep, :2])
            floor = z_under + sag[nearest]
    out: np.ndarray = P[keep[Q[keep, 2] > floor + cfg.contact_band]]
    return out


def _pin_slide(P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray, cams: np.ndarray | DepthViews | _Centres,
               cfg: RegistrationConfig) -> np.ndarray:
    """Point-to-plane ICP cannot see a translation along which the matched faces are all parallel: a prism's
    axis, where only its small end faces (few points, at 1.5 m a few noisy pixels) hold it, and a fit slides by
    centimetres (development seed 48: 36 mm along a 1 m beam). When the matched normals leave a direction that
    weak (smallest eigenvalue of their scatter under ``slide_ratio`` of the largest) and a slide along it would
    cover clearly more of the model's faces turned to the cameras with measured points (``slide_cover``; the ends:
    the model neither sticks out past the object's end nor leaves it bare), the model is moved to the middle of
    the best cover. Within ``slide_cover`` the ICP's fit stands (the cover has a plateau a few millimetres wide,
    and moving a good fit to its middle cost 1-3 mm on development seeds). T: map -> object; returns T."""
    sl = _slide_cover(P, T, S, N, _views(cams), cfg)
    if sl is None:
        return T
    axis, shifts, cover = sl
    here = cover[np.argmin(np.abs(shifts))]
    if here >= cover.max() - cfg.slide_cover:  # the fit covers its faces about as well as any slide would
        return T
    top = np.flatnonzero(cover >= cover.max() - 1e-9)
    run = top[np.cumsum(np.r_[0, np.diff(top) > 1]) == 0]  # the first plateau of best cover
    dx = float(np.mean(shifts[run]))  # its middle
    # the model moves by dx along the axis: object-frame points move by -dx
    out: np.ndarray = G.make_T(t=-dx * axis) @ T
    return out


def _polished(P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray, cams: np.ndarray | DepthViews | _Centres,
              cfg: RegistrationConfig, fine_icp: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``RegistrationConfig.polish``: the fit and six starts ``polish`` away along the object's axes, each refined
    by ``fine_icp``; the one whose model faces (turned to the cameras) have a measured point within
    ``polish_dist`` most often. T: map -> object; returns T."""
    views = _views(cams)
    best, score = T, -1.0
    for d in [np.zeros(3)] + [sgn * cfg.polish * e for e in np.eye(3) for sgn in (-1.0, 1.0)]:
        Tc = fine_icp(G.make_T(t=-d) @ T)  # the model moved by d: object-frame points move by -d
        q = _quality(P, Tc, S, N, views, cfg.polish_dist)[0]
        if q > score + 1e-9:
            best, score = Tc, q
    return best


def _slide_cover(P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray, cams: DepthViews | _Centres,
                 cfg: RegistrationConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(axis, shifts, cover) along the direction the matched normals leave weak, or None when every direction is
    held: the share of the model's faces turned to the cameras that have a measured point within
    ``inlier_dist`` with the model slid by each shift (object frame, +-margin/2 in 1 mm steps)."""
    axis = _weak_axis(P, T, S, N, cfg)
    if axis is None:
        return None
    P_obj = P @ T[:3, :3].T + T[:3, 3]
    Sf = S[_facing(S, N, cams.centres @ T[:3, :3].T + T[:3, 3])]
    tree = cKDTree(P_obj)
    shifts = np.arange(-cfg.margin / 2, cfg.margin / 2 + 1e-9, 0.001)
    # the faces measurable in the fit, counted where they are still measurable after the slide and have a measured
    # point near, over their number: a face no view could measure is no evidence either way. (A share of the faces
    # measurable after each slide would let an end slide out of view for free; counting the faces that a slide
    # brings into view would let the end that no view sees slide in over the measured object for free.)
    Sf = Sf[cams.measurable((Sf - T[:3, 3]) @ T[:3, :3])]
    cover = np.zeros(len(shifts))
    r = cfg.inlier_dist
    # Each face's distance to its nearest measured point moves by at most |dx - dx'| between two shifts (the
    # triangle inequality), so a face known to be within (or beyond) the bound by more than the shift since it was
    # last searched is counted (or not) without a search: the same cover as a search of every face at every shift,
    # a fraction of the searches (the bounds are searched out to 2 r, so that far faces are skipped as well).
    hi = np.full(len(Sf), np.inf)  # at the shift ``at``, each face's distance is at most hi and at least lo
    lo = np.zeros(len(Sf))
    at = np.zeros(len(Sf))
    eps = 1e-9  # metres: a margin far above the bounds' rounding (about 1e-15 m on sums of millimetres), so a
    # bound that decides a face decides it as the search's own test (d^2 < r^2) would
    for k, dx in enumerate(shifts):
        Q = Sf + dx * axis
        idx = np.flatnonzero(cams.measurable((Q - T[:3, 3]) @ T[:3, :3]))
        gap = np.abs(dx - at[idx])
        inside = hi[idx] + gap < r - eps
        unsure = idx[~inside & (lo[idx] - gap <= r + eps)]
        found = 0
        if len(unsure):
            d = tree.query(Q[unsure], distance_upper_bound=2 * r)[0]
            hi[unsure], lo[unsure], at[unsure] = d, np.where(np.isfinite(d), d, 2 * r), dx
            near = np.abs(d - r) <= eps  # on the bound itself: the search's own test decides, as it did
            hit = np.asarray(d < r)
            if np.any(near):
                hit[near] = np.isfinite(tree.query(Q[unsure[near]], distance_upper_bound=r)[0])
            found = int(hit.sum())
        cover[k] = (int(inside.sum()) + found) / max(len(Sf), 1)
    return axis, shifts, cover


def _weak_axis(P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray, cfg: RegistrationConfig
               ) -> np.ndarray | None:
    """The direction (object frame) the matched faces' normals leave weak (smallest eigenvalue of their scatter
    under ``slide_ratio`` of the largest): a prism's axis; None when every direction is held."""
    P_obj = P @ T[:3, :3].T + T[:3, 3]
    d, j = cast(tuple[np.ndarray, np.ndarray], cKDTree(S).query(P_obj, distance_upper_bound=cfg.inlier_dist))
    hit = np.isfinite(d)
    if hit.sum() < 50:
        return None
    n = N[j[hit]]
    w, V = np.linalg.eigh(n.T @ n)
    if w[0] > cfg.slide_ratio * w[2]:
        return None
    axis: np.ndarray = V[:, 0]
    return axis


def slide_spread(P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray,
                 cams: np.ndarray | DepthViews | _Centres, cfg: RegistrationConfig) -> float:
    """How far (metres) the fit T could slide along a weakly held direction and still cover the model's faces
    turned to the cameras within ``slide_cover`` of the best: the extent of the shifts that do (0 when every
    direction is held by the matched normals; infinite when a shift at the end of the search, +-margin/2, covers
    about as well: the slide may go on beyond it)."""
    views = _views(cams)
    if isinstance(views, DepthViews):
        # judged also as if every facing face were measurable: the cover of the measurable faces alone holds a fit
        # whose hidden end sits at the edge of what the views measure (a slide moves it out of view either way),
        # and such a fit must not pass as pinned (development seed 4 with one end hidden: 31 mm off, not refused)
        return max(slide_spread(P, T, S, N, views.centres, cfg), _spread(_slide_cover(P, T, S, N, views, cfg), cfg))
    return _spread(_slide_cover(P, T, S, N, views, cfg), cfg)


def _spread(sl: tuple[np.ndarray, np.ndarray, np.ndarray] | None, cfg: RegistrationConfig) -> float:
    if sl is None:
        return 0.0
    _, shifts, cover = sl
    near = cover >= cover.max() - cfg.slide_cover
    if near[0] or near[-1]:  # about as good at the end of the search: the slide may go on beyond it
        return float("inf")
    return float(shifts[near].max() - shifts[near].min())


def _icp_upright(P: np.ndarray, tree: cKDTree, N: np.ndarray, T: np.ndarray, centre: np.ndarray,
                 radii: tuple[float, ...], iterations: int = 15, turn: bool = True) -> np.ndarray:
    """Point-to-plane ICP (Tukey weights, each radius in turn) that moves the object only in the 4 degrees of
    freedom a resting object has: a translation and a turn about its z axis through ``centre`` (object frame);
    ``turn`` False: the translation alone (a body of revolution about that axis). Roll and pitch stay the levelled
    guess's: a slender beam of a few centimetres' section rolls over freely under correspondences centimetres
    long. P: map points; tree / N: the model samples and their normals; T: map -> object; returns the refined T."""
    dof = 4 if turn else 3
    for radius in radii:
        for _ in range(iterations):
            Q = P @ T[:3, :3].T + T[:3, 3] - centre
            d, j = cast(tuple[np.ndarray, np.ndarray], tree.query(Q + centre, distance_upper_bound=radius))
            ok = np.isfinite(d)
            if ok.sum() < 10:
                break
            q, n = Q[ok], N[j[ok]]
            r = np.einsum("ij,ij->i", q + centre - tree.data[j[ok]], n)
            w = np.where(np.abs(r) < radius, (1 - (r / radius) ** 2) ** 2, 0.0)  # Tukey
            J = np.c_[n, n[:, 0] * -q[:, 1] + n[:, 1] * q[:, 0]][:, :dof]  # d r / d (t, turn about z)
            H = J.T @ (w[:, None] * J) + 1e-9 * np.eye(dof)
            x = np.r_[-np.linalg.solve(H, J.T @ (w * r)), 0.0][:4]
            step = G.make_T(t=centre + x[:3]) @ G.make_T(G.rot_axis("z", x[3])) @ G.make_T(t=-centre)
            T = step @ T
            if np.linalg.norm(x[:3]) < 1e-5 and abs(x[3]) < 1e-5:
                break
    return T


def icp_point_to_plane(P: np.ndarray, tree: cKDTree, N: np.ndarray, T: np.ndarray, radius: float,
                       max_iteration: int = 40, tol: float = 1e-7,
                       hold_turn_about: np.ndarray | None = None) -> np.ndarray:
    """Point-to-plane ICP with Tukey weights (scale ``radius``), 6 degrees of freedom: the loop of Open3D's
    ``registration_icp`` with ``TransformationEstimationPointToPlane(TukeyLoss(k=radius))``, written out so that
    it is deterministic. Open3D sums its normal equations over threads, and identical inputs gave transforms 1e-15
    apart from one run to the next (with one OpenMP thread too; isl-org/Open3D#6225); the boot's tracker amplified
    that to per-scene medians 1-15 points apart (docs/family.md). Here the sums run in one fixed order.

    Each iteration: every point P (map frame) moved by T (map -> object) pairs with its nearest model sample
    (``tree``, normals ``N``) within ``radius``; residual r = n . (T p - s); the step x = (omega, t) minimises
    sum w(r) (r + J x)^2 with J = (T p x n, n) and w the Tukey weight (1 - (r / radius)^2)^2; T <- step(x) T, its
    rotation composed about z, y, x as Open3D does. It stops after ``max_iteration`` steps or when the share
    of paired points and their RMS distance both change by less than ``tol``. ``hold_turn_about`` (a direction e,
    object frame): the steps do not turn the object about e (a body of revolution's axis, a turn its surface does
    not fix, about any point), to first order (the rotations composed about the other axes twist it by their
    product): omega is taken perpendicular to e, x = B y with B's columns two directions perpendicular to e (omega)
    and the three translations, y minimising the same sum. Returns the refined T."""
    B = None
    if hold_turn_about is not None:
        e = np.asarray(hold_turn_about, dtype=np.float64)
        B = np.zeros((6, 5))
        B[:3, :2] = np.linalg.svd(e[None, :] / np.linalg.norm(e))[2][1:].T  # (3, 2): perpendicular to e
        B[3:, 2:] = np.eye(3)

    def pairs(T: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        Q = P @ T[:3, :3].T + T[:3, 3]
        d, j = cast(tuple[np.ndarray, np.ndarray], tree.query(Q, distance_upper_bound=radius))
        ok = np.isfinite(d)
        fitness = ok.sum() / max(len(P), 1)
        rmse = float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else 0.0
        return Q[ok], j[ok], fitness, rmse

    q, j, fitness, rmse = pairs(T)
    for _ in range(max_iteration):
        if len(q) < 6:
            break
        n = N[j]
        r = np.einsum("ij,ij->i", q - tree.data[j], n)
        w = np.where(np.abs(r) <= radius, (1 - (r / radius) ** 2) ** 2, 0.0)
        J = np.c_[np.cross(q, n), n]
        H = J.T @ (w[:, None] * J)
        g = J.T @ (w * r)
        try:
            x = -np.linalg.solve(H, g) if B is None else -B @ np.linalg.solve(B.T @ H @ B, B.T @ g)
        except np.linalg.LinAlgError:
            break
        R = G.rot_axis("z", x[2]) @ G.rot_axis("y", x[1]) @ G.rot_axis("x", x[0])
        T = G.make_T(R, x[3:]) @ T
        before = (fitness, rmse)
        q, j, fitness, rmse = pairs(T)
        if abs(fitness - before[0]) < tol and abs(rmse - before[1]) < tol:
            break
    return T


def support_inliers(P: np.ndarray, dist: float, samples: int, seed: int = 0) -> np.ndarray:
    """Indices of the points of ``P`` within ``dist`` of its dominant plane: RANSAC (Open3D ``segment_plane``, 1000
    tries, its generator seeded by the caller) on a seeded random subset of at most ``samples`` points (0: all),
    the plane's inliers then taken among all the points."""
    sub = P
    if 0 < samples < len(P):
        sub = P[np.sort(np.random.default_rng(seed).choice(len(P), samples, replace=False))]
    abcd, inl = _cloud(sub).segment_plane(distance_threshold=dist, ransac_n=3, num_iterations=1000, probability=1.0)
    if sub is P:
        return np.asarray(inl, dtype=np.int64)
    n = np.asarray(abcd[:3], dtype=np.float64)
    return np.flatnonzero(np.abs(P @ n + float(abcd[3])) <= dist * np.linalg.norm(n))


def _cloud(P: np.ndarray) -> Any:
    import open3d as o3d

    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))


def _down(P: np.ndarray, voxel: float) -> np.ndarray:
    out: np.ndarray = np.asarray(_cloud(P).voxel_down_sample(voxel).points)
    return out


def _n_samples(model: ReducedModel, spacing: float) -> int:
    """Surface samples about ``spacing`` apart (point-to-plane ICP slides along a face: its samples need not be
    dense, only cover it)."""
    V, F = model.points, model.surface
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    return int(np.clip(area / spacing ** 2, 5000, 100_000))


def _facing(S: np.ndarray, N: np.ndarray, cams_obj: np.ndarray, cos_min: float = 0.0) -> np.ndarray:
    """Which model samples S (normals N) face at least one camera (positions in the object frame). ``cos_min`` < 0
    counts a camera up to arccos(cos_min) from the normal too: room for a pose turned by some degrees (-0.25: about
    105 degrees, a guess ten degrees off; a face seen edge-on at the guess may face the camera in truth)."""
    facing = np.zeros(len(S), bool)
    for c in cams_obj:
        v = c - S
        dots = np.einsum("ij,ij->i", N, v)
        facing |= dots > (cos_min * np.linalg.norm(v, axis=1) if cos_min else 0.0)
    return facing


def _noise(P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray, band: float) -> float:
    """The depth's noise about the fitted surface: 1.4826 x the median absolute deviation of the point-to-plane
    residuals of the measured points P (map) within ``band`` of a model sample, under T (map -> object). The fit's
    own residual (:func:`_quality`) counts only points within the inlier distance, so it cannot grow past about
    60 % of that distance however noisy the depth: it does not see noise. This wider band does, up to about
    half its width."""
    P_obj = P @ T[:3, :3].T + T[:3, 3]
    d, j = cast(tuple[np.ndarray, np.ndarray], cKDTree(S).query(P_obj, distance_upper_bound=band))
    hit = np.isfinite(d)
    if hit.sum() < 10:
        return float("inf")
    r = np.einsum("ij,ij->i", P_obj[hit] - S[j[hit]], N[j[hit]])
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def _judged(out: Registration, P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray,
            cfg: RegistrationConfig) -> Registration:
    """``out`` with the depth's noise measured and its doubts stated: noise above ``max_noise``, a slide over more
    than ``max_slide_share`` of the object (:func:`slide_share`)."""
    noise = _noise(P, T, S, N, 3 * cfg.inlier_dist)
    doubts = []
    if noise > cfg.max_noise:
        doubts.append(f"registered on noisy depth: the points scatter {1e3 * noise:.1f} mm about the fitted surface "
                      f"(over {1e3 * cfg.max_noise:.1f} mm), so the pose may be millimetres and degrees off")
    share = slide_share(out.slide_spread, P, T, S, N, cfg)
    if share > cfg.max_slide_share:
        doubts.append(f"the fit can slide {1e3 * out.slide_spread:.0f} mm along the object's axis at about the same "
                      f"cover ({100 * share:.1f} % of its length, over {100 * cfg.max_slide_share:.0f} %): its ends "
                      "are barely seen, so positions along the axis (a load's) may be off by half that; show the "
                      "camera an end of the object")
    return replace(out, noise=noise, doubt="; ".join(doubts))


def slide_share(spread: float, P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray,
                cfg: RegistrationConfig) -> float:
    """The slide spread (:func:`slide_spread`) over the model's extent along the direction it slides in (a beam's
    length): the share of the object a position along it (a load's) may be off by; 0 when nothing slides."""
    if not spread > 0:
        return 0.0
    axis = _weak_axis(P, T, S, N, cfg)
    if axis is None:
        return 0.0
    along = S @ axis
    return float(spread / max(float(along.max() - along.min()), 1e-9))


def _quality(P: np.ndarray, T: np.ndarray, S: np.ndarray, N: np.ndarray, cams: DepthViews | _Centres,
             dist: float) -> tuple[float, float, int]:
    """(share of the model samples facing a camera (and measurable by a view) with a measured point within ``dist``,
    point-to-plane RMS of the measured points within ``dist`` of a sample, their count) for measured points P (map)
    under T (map -> object)."""
    P_obj = P @ T[:3, :3].T + T[:3, 3]
    facing = _facing(S, N, cams.centres @ T[:3, :3].T + T[:3, 3]) & cams.measurable((S - T[:3, 3]) @ T[:3, :3])
    d_model, _ = cKDTree(P_obj).query(S[facing], distance_upper_bound=dist)
    fitness = float(np.mean(np.isfinite(d_model))) if facing.any() else 0.0
    d_pts, j = cast(tuple[np.ndarray, np.ndarray], cKDTree(S).query(P_obj, distance_upper_bound=dist))
    hit = np.isfinite(d_pts)
    resid = np.einsum("ij,ij->i", P_obj[hit] - S[j[hit]], N[j[hit]])
    rmse = float(np.sqrt(np.mean(resid ** 2))) if hit.any() else float("inf")
    return fitness, rmse, int(hit.sum())
