"""Meshes for the seed objects (scikit-fem meshes) and their outer surfaces.

- boxes and rectangles (structured hexahedra / quadrilaterals or simplices),
- Cook's membrane (the classical trapezoid),
- a joint-boot-like bellows (structured hexahedra on a revolved, corrugated profile),
- tetrahedral meshes of closed triangle surfaces (bunny, dragon) through gmsh, after closing holes.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import skfem
from numpy.typing import NDArray

from simreal_nodes.errors import FemError


def box(L: float, W: float, H: float, n: Sequence[int], kind: str = "hex",
        origin: Sequence[float] = (0.0, 0.0, 0.0)) -> skfem.Mesh:
    """Box [0, L] x [0, W] x [0, H] (+ origin) with n = (nx, ny, nz) cells."""
    xs = [np.linspace(o, o + s, k + 1) for o, s, k in zip(origin, (L, W, H), n)]
    if kind == "hex":
        return skfem.MeshHex.init_tensor(*xs)
    if kind == "tet":
        return skfem.MeshTet.init_tensor(*xs)
    raise FemError(f"mesh kind must be 'hex' or 'tet', got '{kind}'")


def rectangle(L: float, H: float, n: tuple[int, int], kind: str = "quad"):
    xs = [np.linspace(0, L, n[0] + 1), np.linspace(0, H, n[1] + 1)]
    if kind == "quad":
        return skfem.MeshQuad.init_tensor(*xs)
    if kind == "tri":
        return skfem.MeshTri.init_tensor(*xs)
    raise FemError(f"2D mesh kind must be 'quad' or 'tri', got '{kind}'")


def cook_membrane(n: int, kind: str = "quad"):
    """Cook's membrane: trapezoid (0,0), (48,44), (48,60), (0,44), n x n cells."""
    m = rectangle(1.0, 1.0, (n, n), kind)
    xi, eta = m.p
    x = 48.0 * xi
    y_low, y_up = 44.0 * xi, 44.0 + 16.0 * xi
    p = np.stack([x, (1 - eta) * y_low + eta * y_up])
    return type(m)(p, m.t)


def joint_boot(n_profile: int = 48, n_around: int = 24, n_thick: int = 2, height: float = 0.12,
               r_bottom: float = 0.05, r_top: float = 0.018, wall: float = 0.004, folds: int = 3,
               fold_depth: float = 0.008) -> skfem.MeshHex:
    """A bellows-like rubber boot: a corrugated cone revolved about z, hexahedral wall.

    Bottom ring at z = 0 (clamped to the housing), top ring at z = ``height`` (gripping the lever).
    """
    s = np.linspace(0.0, 1.0, n_profile + 1)
    z_mid = height * s
    r_mid = r_bottom + (r_top - r_bottom) * s + fold_depth * np.sin(np.pi * 2 * folds * s) * np.sin(np.pi * s)
    t = np.linspace(-0.5, 0.5, n_thick + 1)
    phi = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    # wall normal of the profile curve (r(s), z(s)) in the r-z plane
    dr, dz = np.gradient(r_mid), np.gradient(z_mid)
    nl = np.hypot(dr, dz)
    nr, nz = dz / nl, -dr / nl
    R = r_mid[:, None] + wall * t[None, :] * nr[:, None]
    Z = z_mid[:, None] + wall * t[None, :] * nz[:, None]
    Z[0, :], Z[-1, :] = 0.0, height  # flat end rings
    # points indexed (i profile, j thickness, k around)
    P = np.empty((n_profile + 1, n_thick + 1, n_around, 3))
    P[..., 0] = R[:, :, None] * np.cos(phi)[None, None, :]
    P[..., 1] = R[:, :, None] * np.sin(phi)[None, None, :]
    P[..., 2] = Z[:, :, None]
    idx = np.arange(P[..., 0].size).reshape(n_profile + 1, n_thick + 1, n_around)
    cells = []
    for i in range(n_profile):
        for j in range(n_thick):
            for k in range(n_around):
                k1 = (k + 1) % n_around
                # skfem MeshHex vertex order: (0,0,0),(1,0,0),(0,1,0),(0,0,1),(1,1,0),(1,0,1),(0,1,1),(1,1,1)
                # local axes: a = profile, b = thickness, c = around
                v = lambda a, b, c: idx[i + a, j + b, k1 if c else k]  # noqa: E731, B023 - called in the iteration that defines it
                cells.append([v(0, 0, 0), v(1, 0, 0), v(0, 1, 0), v(0, 0, 1),
                              v(1, 1, 0), v(1, 0, 1), v(0, 1, 1), v(1, 1, 1)])
    t_cells = np.asarray(cells, dtype=np.int64).T
    p = P.reshape(-1, 3).T
    m = skfem.MeshHex(np.ascontiguousarray(p), np.ascontiguousarray(t_cells))
    return _fix_hex_orientation(m)


def _fix_hex_orientation(m):
    """Swap hexahedra with negative Jacobian (our local axes may be left-handed)."""
    p, t = m.p, m.t.copy()
    a = p[:, t[1]] - p[:, t[0]]
    b = p[:, t[2]] - p[:, t[0]]
    c = p[:, t[3]] - p[:, t[0]]
    vol = np.einsum("ij,ij->j", np.cross(a.T, b.T).T, c)
    neg = vol < 0
    if np.any(neg):
        # mirror local axis b <-> c keeps a valid hex with positive orientation
        perm = [0, 1, 3, 2, 5, 4, 6, 7]
        t[:, neg] = t[perm][:, neg]
    return skfem.MeshHex(p, t)


# ---------------------------------------------------------------------------------------------
# Surfaces


def boundary_triangles(mesh: skfem.Mesh) -> NDArray[np.int64]:
    """Outward-oriented boundary triangles (n, 3) of a 3D mesh (quads are split in two)."""
    if mesh.dim() != 3:
        raise FemError("boundary triangles need a 3D mesh")
    bf = mesh.boundary_facets()
    fac = mesh.facets[:, bf]  # (3 or 4, nb)
    elem = mesh.f2t[0, bf]
    cent_e = mesh.p[:, mesh.t[:, elem]].mean(axis=1)
    if fac.shape[0] == 4:
        # skfem hex facets list vertices in cyclic order? make it so by sorting around the centroid
        fac = _cyclic_quads(mesh.p, fac)
        tris = np.concatenate([fac[[0, 1, 2]], fac[[0, 2, 3]]], axis=1)
        cent_e = np.concatenate([cent_e, cent_e], axis=1)
    else:
        tris = fac
    P = mesh.p
    a, b, c = P[:, tris[0]], P[:, tris[1]], P[:, tris[2]]
    n = np.cross((b - a).T, (c - a).T).T
    out = ((a + b + c) / 3 - cent_e)
    flip = np.einsum("ij,ij->j", n, out) < 0
    tris[[1, 2]] = np.where(flip, tris[[2, 1]], tris[[1, 2]])
    return tris.T.astype(np.int64)


def _cyclic_quads(P, fac):
    c = P[:, fac].mean(axis=1)  # (3, nb)
    v = P[:, fac] - c[:, None, :]  # (3, 4, nb)
    n = np.cross(v[:, 0].T, v[:, 1].T).T
    n_alt = np.cross(v[:, 0].T, v[:, 2].T).T
    n = np.where(np.linalg.norm(n, axis=0) > 1e-14 * np.linalg.norm(v[:, 0], axis=0), n, n_alt)
    e1 = v[:, 0] / np.linalg.norm(v[:, 0], axis=0)
    e2 = np.cross(n.T, e1.T).T
    e2 /= np.linalg.norm(e2, axis=0)
    ang = np.arctan2(np.einsum("ikj,ij->kj", v, e2), np.einsum("ikj,ij->kj", v, e1))
    order = np.argsort(ang, axis=0)
    return np.take_along_axis(fac, order, axis=0)


# ---------------------------------------------------------------------------------------------
# Closed-surface tetrahedral meshing (bunny, dragon)


def read_surface(path: str | Path) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(vertices (n, 3), triangles (m, 3)) from an OBJ / PLY / STL file (meshio)."""
    import meshio

    path = Path(path)
    if not path.exists():
        raise FemError(f"surface mesh not found: {path}")
    try:
        m = meshio.read(path)
    except Exception as e:  # noqa: BLE001
        raise FemError(f"cannot read surface mesh {path}: {e}") from None
    tris = [c.data for c in m.cells if c.type == "triangle"]
    if not tris:
        raise FemError(f"{path} has no triangles")
    return np.asarray(m.points[:, :3], dtype=np.float64), np.concatenate(tris).astype(np.int64)


def clean_surface(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop degenerate and duplicate triangles and unreferenced vertices."""
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    key = np.sort(F, axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    F = F[np.sort(first)]
    used = np.unique(F)
    remap = -np.ones(len(V), np.int64)
    remap[used] = np.arange(len(used))
    return V[used], remap[F]


def boundary_loops(F: np.ndarray) -> list[list[int]]:
    """Closed loops of boundary edges (edges used by one triangle), oriented as in the triangles.

    A vertex where two holes touch has two outgoing boundary edges; edges are consumed one by one so
    such figure-eight boundaries still split into simple loops.
    """
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    border = e[cnt[inv.ravel()] == 1]
    out: dict[int, list[int]] = {}
    for a, b in border:
        out.setdefault(int(a), []).append(int(b))
    loops = []
    while out:
        start = next(iter(out))
        loop, v = [start], start
        while True:
            nxts = out.get(v)
            if not nxts:
                break
            w = nxts.pop()
            if not nxts:
                del out[v]
            if w == start:
                break
            if w in loop:  # a pinch: split off the inner loop
                i = loop.index(w)
                inner = loop[i:]
                if len(inner) >= 3:
                    loops.append(inner)
                loop = loop[:i + 1]
                v = w
                continue
            loop.append(w)
            v = w
        if len(loop) >= 3:
            loops.append(loop)
    return loops


def close_holes(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Close every hole by a fan around the loop's centroid (bunny base holes). Returns (V, F, n_holes)."""
    verts = list(V)
    total = 0
    for _ in range(5):
        loops = boundary_loops(F)
        if not loops:
            break
        newF = [F]
        for loop in loops:
            c = np.mean([verts[i] for i in loop], axis=0)
            ci = len(verts)
            verts.append(c)
            # boundary edges run a->b in the existing triangles; the cap must use b->a
            fan = [[loop[(k + 1) % len(loop)], loop[k], ci] for k in range(len(loop))]
            newF.append(np.asarray(fan, np.int64))
        F = np.concatenate(newF)
        total += len(loops)
    return np.asarray(verts), F, total


def tet_mesh_from_surface(V: np.ndarray, F: np.ndarray, size: float, optimize: bool = True):
    """Tetrahedral mesh of the volume enclosed by a closed, consistently oriented triangle surface."""
    import gmsh

    loops = boundary_loops(F)
    if loops:
        raise FemError(f"the surface has {len(loops)} open boundary loop(s); close them first (close_holes)")
    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("surface")
        s = gmsh.model.addDiscreteEntity(2)
        node_tags = np.arange(1, len(V) + 1)
        gmsh.model.mesh.addNodes(2, s, node_tags, V.ravel())
        gmsh.model.mesh.addElementsByType(s, 2, [], (F + 1).ravel())
        gmsh.model.mesh.createTopology()
        gmsh.model.mesh.classifySurfaces(np.pi, True, True, np.pi)
        gmsh.model.mesh.createGeometry()
        surfaces = [t for _, t in gmsh.model.getEntities(2)]
        sl = gmsh.model.geo.addSurfaceLoop(surfaces)
        gmsh.model.geo.addVolume([sl])
        gmsh.model.geo.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", size * 0.5)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1 if optimize else 0)
        gmsh.model.mesh.generate(3)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        etypes, _, enodes = gmsh.model.mesh.getElements(3)
        if 4 not in list(etypes):
            raise FemError("gmsh produced no tetrahedra (is the surface closed and not self-intersecting?)")
        tet = np.asarray(enodes[list(etypes).index(4)], np.int64).reshape(-1, 4)
    except FemError:
        raise
    except Exception as e:  # noqa: BLE001 - gmsh raises plain Exceptions
        raise FemError(f"tetrahedral meshing failed: {e}") from None
    finally:
        gmsh.finalize()
    pts = np.asarray(coords).reshape(-1, 3)
    order = np.argsort(tags)
    lookup = np.empty(int(tags.max()) + 1, np.int64)
    lookup[np.asarray(tags, np.int64)[order]] = np.arange(len(tags))
    t = lookup[tet]
    used = np.unique(t)
    remap = -np.ones(len(pts), np.int64)
    remap[used] = np.arange(len(used))
    m = skfem.MeshTet(pts[used].T.copy(), remap[t].T.copy())
    return _fix_tet_orientation(m)


def _fix_tet_orientation(m):
    p, t = m.p, m.t.copy()
    a, b, c = (p[:, t[k]] - p[:, t[0]] for k in (1, 2, 3))
    vol = np.einsum("ij,ij->j", np.cross(a.T, b.T).T, c)
    neg = vol < 0
    t[[1, 2]] = np.where(neg, t[[2, 1]], t[[1, 2]])
    return skfem.MeshTet(p, t)


# ---------------------------------------------------------------------------------------------
# Robust volumetric meshing of scanned surfaces (holes, non-manifold edges): winding number + grid


def winding_number(V: np.ndarray, F: np.ndarray, P: np.ndarray, chunk: int = 256) -> np.ndarray:
    """Generalized winding number of a triangle soup at points P (n, 3): ~1 inside, ~0 outside.

    Sum of signed solid angles (Van Oosterom & Strackee) / 4 pi; robust to holes and non-manifold edges.
    """
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    out = np.empty(len(P))
    for s in range(0, len(P), chunk):
        p = P[s:s + chunk, None, :]
        a, b, c = A[None] - p, B[None] - p, C[None] - p
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ijk,ijk->ij", a, b) * lc + np.einsum("ijk,ijk->ij", b, c) * la
               + np.einsum("ijk,ijk->ij", c, a) * lb)
        out[s:s + chunk] = np.sum(2 * np.arctan2(det, den), axis=1) / (4 * np.pi)
    return out


def inside_field(V: np.ndarray, F: np.ndarray, P: np.ndarray, near: float) -> np.ndarray:
    """~1 inside, ~0 outside at points P: the winding number where P is within ``near`` of the surface
    (where ray parity is unreliable on open scans), Open3D's voted ray parity elsewhere (fast)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    # open3d's generated stubs make dtype and device required; at run time they default to the array's / CPU
    scene.add_triangles(o3d.core.Tensor(V.astype(np.float32)),  # type: ignore[call-overload]
                        o3d.core.Tensor(F.astype(np.uint32)))  # type: ignore[call-overload]
    q = o3d.core.Tensor(P.astype(np.float32))  # type: ignore[call-overload]
    out = scene.compute_occupancy(q, nsamples=7).numpy().astype(np.float64)
    close = scene.compute_distance(q).numpy() < near
    if np.any(close):
        out[close] = winding_number(V, F, P[close])
    return out


def voxel_tet_mesh(V: NDArray[np.float64], F: NDArray[np.int64], h: float) -> skfem.MeshTet:
    """Tetrahedra of a regular grid of spacing ``h`` whose centroids lie inside the surface (winding
    number > 1/2), largest connected piece only. Works on scans that gmsh rejects."""
    lo, hi = V.min(axis=0) - h, V.max(axis=0) + h
    xs = [np.arange(l, u + h, h) for l, u in zip(lo, hi)]
    grid = skfem.MeshTet.init_tensor(*xs)
    w = inside_field(V, F, grid.p.T, near=2.0 * h)
    keep = w[grid.t].mean(axis=0) > 0.5
    if not np.any(keep):
        raise FemError(f"no grid cell of size {h} lies inside the surface (is it closed, and h small enough?)")
    t = grid.t[:, keep]
    # largest connected component through shared faces
    import scipy.sparse as sps
    from scipy.sparse.csgraph import connected_components

    nt = t.shape[1]
    faces = np.sort(np.concatenate([t[[0, 1, 2]], t[[0, 1, 3]], t[[0, 2, 3]], t[[1, 2, 3]]], axis=1), axis=0).T
    owner = np.tile(np.arange(nt), 4)
    _, inv = np.unique(faces, axis=0, return_inverse=True)
    inv = inv.ravel()
    order = np.argsort(inv)
    same = inv[order][1:] == inv[order][:-1]
    a, b = owner[order][:-1][same], owner[order][1:][same]
    g = sps.coo_matrix((np.ones(len(a)), (a, b)), shape=(nt, nt))
    ncomp, lab = connected_components(g, directed=False)
    if ncomp > 1:
        t = t[:, lab == np.argmax(np.bincount(lab))]
    used = np.unique(t)
    remap = -np.ones(grid.p.shape[1], np.int64)
    remap[used] = np.arange(len(used))
    m = skfem.MeshTet(np.ascontiguousarray(grid.p[:, used]), np.ascontiguousarray(remap[t]))
    return _fix_tet_orientation(m)


def embed_points(mesh: skfem.MeshTet, P: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """For points P (n, 3), the tetrahedron of ``mesh`` that contains them (or the nearest one) and
    barycentric weights (clipped to the simplex outside), so that u(P) = sum_k w_k u(node_k)."""
    from scipy.spatial import cKDTree

    p, t = mesh.p.T, mesh.t.T
    cent = p[t].mean(axis=1)
    tree = cKDTree(cent)
    k = min(16, len(t))
    _, cand = tree.query(P, k=k)
    cand = cand.reshape(len(P), -1)
    best_t = np.empty(len(P), np.int64)
    best_w = np.empty((len(P), 4))
    for i in range(len(P)):
        score_best = -np.inf
        for c in cand[i]:
            X = p[t[c]]
            T = (X[:3] - X[3]).T
            try:
                lam = np.linalg.solve(T, P[i] - X[3])
            except np.linalg.LinAlgError:
                continue
            wv = np.append(lam, 1 - lam.sum())
            score = wv.min()
            if score > score_best:
                score_best, best_t[i], best_w[i] = score, c, wv
            if score >= -1e-9:
                break
        if score_best < -1e-9:  # outside every candidate: clip to the simplex
            wv = np.clip(best_w[i], 0, None)
            best_w[i] = wv / wv.sum()
    return t[best_t], best_w
