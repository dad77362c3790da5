"""Independent physics for the scenes that measure accuracy (no inverse crime).

A scene that scores the deformable tracker must not be rendered by the reduced model being fitted: its error
would then be zero by construction wherever the images are clean. Here a loaded beam's deformation comes from
its own full-order finite-element solve (scikit-fem through :class:`~simreal_nodes.physics.fem.Solid`) that
differs from the model's in every discretisation choice:

- another mesh: tetrahedra on a finer grid (the PGD models use hexahedra);
- another element: quadratic P2 tetrahedra;
- the load as what a weight physically is: a uniform pressure over its footprint (a disk of radius ``r``) on the
  top face, placed anywhere, instead of the model's nodal force on one of its centreline vertices.

For a linear material the stiffness is factorised once and the solution tabulated at load positions ``step``
apart; between two tabulated positions it is interpolated linearly — superposition: the exact solution for the
load shared between the two footprints, a smoothing far below the footprint's own size when ``step`` is small.
A hyperelastic material (the foam beam's Saint Venant-Kirchhoff) is solved by Newton at each tabulated position,
the weight sliding from one to the next. A plate (:func:`plate_load_truth`) is tabulated the same way over a
rectangle of positions on its top face and interpolated bilinearly.

:func:`model_error` then measures how far the reduced model is from this truth — the error a perfect tracker
would still make — so that every tracking error can be reported beside the model error of its scene.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse.linalg as spla

from simreal_nodes.errors import FemError
from simreal_nodes.physics import fem, materials, meshes
from simreal_nodes.rom.model import ReducedModel


@dataclass
class BeamLoadTruth:
    """Full-order displacement of a beam for a load at position ``s`` along its top centreline (object frame:
    x along the beam from 0 to L, y across 0..W, z up 0..H)."""

    points: np.ndarray  # (n, 3) reference vertices of the truth mesh
    surface: np.ndarray  # (m, 3) outward boundary triangles of the truth mesh
    tets: np.ndarray  # (k, 4) tetrahedra (for interpolation at arbitrary points)
    s: np.ndarray  # (n_s,) tabulated load positions, increasing
    U: np.ndarray  # (n_s, n, 3) vertex displacement for the load at each tabulated position, metres
    description: str = ""
    info: dict = field(default_factory=dict)
    # interpolation of arbitrary points: the skfem mesh, built once, and the last few point sets' embeddings
    _mesh: object | None = field(default=None, init=False, repr=False, compare=False)
    _embeds: dict[bytes, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict, init=False, repr=False,
                                                                compare=False)

    def displacement(self, s: float) -> np.ndarray:
        """(n, 3) vertex displacement for the load at ``s`` (clipped to the tabulated range)."""
        k, w = self._bracket(s)
        return (1 - w) * self.U[k] + w * self.U[k + 1] if w else self.U[k].copy()

    def scaled(self, factor: float) -> BeamLoadTruth:
        """The same truth for a load ``factor`` times larger (linear material: superposition)."""
        if not self.info.get("linear", True):
            raise ValueError("a nonlinear truth does not scale with its load: solve it for the load wanted")
        out = BeamLoadTruth(self.points, self.surface, self.tets, self.s, self.U * factor, self.description,
                            {**self.info, "scaled": factor})
        out._embeds, out._mesh = self._embeds, self._mesh
        return out

    def deformed_points(self, s: float) -> np.ndarray:
        return self.points + self.displacement(s)

    def at(self, s: float, P: np.ndarray) -> np.ndarray:
        """(len(P), 3) displacement at arbitrary reference points, interpolated linearly inside the truth mesh."""
        nodes, w = self.embed(P)
        return np.einsum("nk,nkc->nc", w, self.displacement(s)[nodes])

    def embed(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tetrahedron vertices (N, 4) and barycentric weights (N, 4) of reference points P (N, 3)."""
        import skfem

        P = np.asarray(P, dtype=np.float64).reshape(-1, 3)
        key = P.tobytes()
        hit = self._embeds.get(key)
        if hit is None:
            if self._mesh is None:
                self._mesh = skfem.MeshTet(np.ascontiguousarray(self.points.T), np.ascontiguousarray(self.tets.T))
            hit = meshes.embed_points(self._mesh, P)
            if len(self._embeds) >= 8:  # a few point sets are asked for again and again (the model's nodes);
                self._embeds.pop(next(iter(self._embeds)))  # a moving weight asks once per frame: bounded
            self._embeds[key] = hit
        return hit

    def _bracket(self, s: float) -> tuple[int, float]:
        if len(self.s) == 1:
            return 0, 0.0
        x = float(np.clip(s, self.s[0], self.s[-1]))
        k = int(np.clip(np.searchsorted(self.s, x, side="right") - 1, 0, len(self.s) - 2))
        w = (x - self.s[k]) / (self.s[k + 1] - self.s[k])
        return (k + 1, 0.0) if w >= 1.0 else (k, float(w))


def beam_load_truth(length: float, width: float, height: float, material: materials.Material, supports: list[dict],
                    force: float, footprint_radius: float, s_range: tuple[float, float], step: float = 0.0025,
                    cells: tuple[int, int, int] | None = None, order: int = 2,
                    direction: tuple[float, float, float] = (0.0, 0.0, -1.0), load_steps: int = 4) -> BeamLoadTruth:
    """Tabulate the full-order solution of a beam loaded by a weight of ``force`` newtons resting on a disk of
    ``footprint_radius`` centred on the top centreline at x = s, for s over ``s_range``.

    A linear-elastic material is one factorisation and a solve per position. A hyperelastic one (Saint
    Venant-Kirchhoff, neo-Hookean) is Newton with load stepping to the first position, then continuation: the
    weight slides from each tabulated position to the next, each solve started from the last (the weight moves
    slowly: a sequence of static equilibria, the path a quasi-static experiment follows).

    ``supports``: as in model specs ({region, kind[, component]}). ``cells``: tetrahedral grid (default: about
    4 elements through the smaller cross-section side, and elements no longer than twice that size along the beam,
    capped so a scene's truth stays under ~30 000 dofs; tests/synth/test_truth.py bounds its error against
    Euler-Bernoulli). ``order``: 2 (P2, the default) or 1."""
    linear = isinstance(material, materials.LinearElastic)
    if cells is None:  # 3 quadratic elements through the thinner side, about square in section, <= 2:1 along the beam
        h = min(width, height) / 3
        cells = (int(np.clip(np.ceil(length / (2 * h)), 8, 90)), int(np.clip(round(width / h), 2, 8)),
                 int(np.clip(round(height / h), 2, 8)))
    mesh = meshes.box(length, width, height, cells, "tet")
    solid = fem.Solid(mesh, material, order, supports)
    lo, hi = s_range
    n_s = max(2, int(np.ceil((hi - lo) / step)) + 1)
    s_tab = np.linspace(lo, hi, n_s)
    dirv = np.asarray(direction, dtype=np.float64)
    dirv = dirv / np.linalg.norm(dirv)
    F = np.stack([solid.patch_load({"face": "zmax"}, (s, width / 2, height), footprint_radius, force * dirv)
                  for s in s_tab], axis=1)  # (N, n_s)
    X = np.zeros((solid.N, n_s))
    if linear:
        K = solid.stiffness()
        free = solid.free
        lu = spla.splu(K[free][:, free].tocsc(), permc_spec="MMD_AT_PLUS_A")  # symmetric: ~1/3 less fill than COLAMD
        X[free] = lu.solve(F[free] / material.E)  # the stiffness is assembled in units of E (fem.Solid)
    else:
        X[:, 0], _ = solid.solve(F[:, 0], steps=load_steps)
        path: list[np.ndarray] = []
        if n_s > 1:  # from the equilibrium at the first position (its state first: a sub-step then lies between two
            # positions, never on a partly lifted weight), the weight slides on
            solid.solve_states([(F[:, k], np.zeros(solid.N)) for k in range(n_s)], u0=X[:, 0], path=path)
        for k, u in enumerate(path[1:], start=1):
            X[:, k] = u
    if not np.all(np.isfinite(X)):
        raise FemError("the truth solve returned NaN/inf")
    U = np.stack([solid.vertex_displacement(X[:, k]) for k in range(n_s)])
    desc = (f"full-order P{order} tetrahedra {cells[0]}x{cells[1]}x{cells[2]} cells ({solid.N} dofs), "
            f"{material.law}, weight "
            f"{force:g} N on a {2e3 * footprint_radius:.0f} mm disk, "
            f"tabulated every {1e3 * (s_tab[1] - s_tab[0]):.2f} mm")
    return BeamLoadTruth(mesh.p.T.copy(), meshes.boundary_triangles(mesh), mesh.t.T.copy(), s_tab, U, desc,
                         {"cells": list(cells), "order": order, "dofs": int(solid.N), "n_s": int(n_s),
                          "linear": linear})


@dataclass
class PlateLoadTruth(BeamLoadTruth):
    """Full-order displacement of a plate for a load anywhere on its top face, at ``(s_x, s_y)`` (object frame as
    :class:`BeamLoadTruth`). ``s`` and ``sy`` are the tabulated positions along x and y, ``U`` is
    (n_x, n_y, n, 3); between tabulated positions the solution is interpolated bilinearly (superposition: the load
    shared between the four neighbouring footprints)."""

    sy: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def displacement(self, s) -> np.ndarray:
        """(n, 3) vertex displacement for the load at ``s = (s_x, s_y)`` (clipped to the tabulated rectangle)."""
        sx, sy = (float(v) for v in np.asarray(s, dtype=np.float64).ravel()[:2])
        i, wx = _bracket(self.s, sx)
        j, wy = _bracket(self.sy, sy)
        out = (1 - wx) * (1 - wy) * self.U[i, j]
        if wx:
            out = out + wx * (1 - wy) * self.U[i + 1, j]
        if wy:
            out = out + (1 - wx) * wy * self.U[i, j + 1]
        if wx and wy:
            out = out + wx * wy * self.U[i + 1, j + 1]
        return out

    def scaled(self, factor: float) -> PlateLoadTruth:
        out = PlateLoadTruth(self.points, self.surface, self.tets, self.s, self.U * factor, self.description,
                             {**self.info, "scaled": factor}, self.sy)
        out._embeds, out._mesh = self._embeds, self._mesh
        return out


def _bracket(tab: np.ndarray, s: float) -> tuple[int, float]:
    """Index k and weight w of ``s`` between tab[k] and tab[k + 1] (clipped; w = 0 on a tabulated value)."""
    if len(tab) == 1:
        return 0, 0.0
    x = float(np.clip(s, tab[0], tab[-1]))
    k = int(np.clip(np.searchsorted(tab, x, side="right") - 1, 0, len(tab) - 2))
    w = (x - tab[k]) / (tab[k + 1] - tab[k])
    return (k + 1, 0.0) if w >= 1.0 else (k, float(w))


def plate_load_truth(length: float, width: float, height: float, material: materials.Material,
                     supports: list[dict], force: float, footprint_radius: float, x_range: tuple[float, float],
                     y_range: tuple[float, float], cells: tuple[int, int, int], step: float,
                     order: int = 2) -> PlateLoadTruth:
    """Tabulate the full-order solution of a plate (a box of ``length`` x ``width`` x ``height``) loaded by a weight
    of ``force`` newtons on a disk of ``footprint_radius`` centred at (s_x, s_y) on its top face, over the rectangle
    ``x_range`` x ``y_range``, about ``step`` apart in both directions: one factorisation of the stiffness (linear
    material only) and one solve per position, ``cells`` tetrahedral cells of order ``order``."""
    if not isinstance(material, materials.LinearElastic):
        raise ValueError("plate_load_truth tabulates a linear material (superposition between positions)")
    mesh = meshes.box(length, width, height, cells, "tet")
    solid = fem.Solid(mesh, material, order, supports)
    sx = np.linspace(x_range[0], x_range[1], max(2, int(np.ceil((x_range[1] - x_range[0]) / step)) + 1))
    sy = np.linspace(y_range[0], y_range[1], max(2, int(np.ceil((y_range[1] - y_range[0]) / step)) + 1))
    K = solid.stiffness()
    free = solid.free
    lu = spla.splu(K[free][:, free].tocsc(), permc_spec="MMD_AT_PLUS_A")
    n_v = mesh.p.shape[1]
    U = np.zeros((len(sx), len(sy), n_v, 3))
    X = np.zeros((solid.N, len(sy)))
    for i, x in enumerate(sx):  # one row of positions at a time: the loads of a row fit in memory
        F = np.stack([solid.patch_load({"face": "zmax"}, (x, y, height), footprint_radius, (0.0, 0.0, -force))
                      for y in sy], axis=1)
        X[free] = lu.solve(F[free] / material.E)  # the stiffness is assembled in units of E (fem.Solid)
        for j in range(len(sy)):
            U[i, j] = solid.vertex_displacement(X[:, j])
    if not np.all(np.isfinite(U)):
        raise FemError("the truth solve returned NaN/inf")
    desc = (f"full-order P{order} tetrahedra {cells[0]}x{cells[1]}x{cells[2]} cells ({solid.N} dofs), "
            f"{material.law}, weight {force:g} N on a {2e3 * footprint_radius:.0f} mm disk anywhere on the top face, "
            f"tabulated on {len(sx)} x {len(sy)} positions")
    return PlateLoadTruth(mesh.p.T.copy(), meshes.boundary_triangles(mesh), mesh.t.T.copy(), sx, U, desc,
                          {"cells": list(cells), "order": order, "dofs": int(solid.N), "n_s": int(len(sx) * len(sy)),
                           "linear": True}, sy)


@dataclass
class LeverTruth:
    """Full-order displacement of the joint boot for its lever turned by ``theta`` (object frame: the boot's axis
    is z, its bottom ring at z = 0; the lever pivots about ``axis`` through ``pivot``)."""

    points: np.ndarray  # (n, 3) reference vertices of the truth mesh
    surface: np.ndarray  # (m, 3) outward boundary triangles
    theta: np.ndarray  # (n_t,) tabulated lever angles (rad), increasing
    U: np.ndarray  # (n_t, n, 3) vertex displacement at each tabulated angle, metres
    description: str = ""
    info: dict = field(default_factory=dict)

    def displacement(self, theta: float) -> np.ndarray:
        """(n, 3) vertex displacement at ``theta`` (linear between tabulated angles, clipped to their range)."""
        x = float(np.clip(theta, self.theta[0], self.theta[-1]))
        k = int(np.clip(np.searchsorted(self.theta, x, side="right") - 1, 0, len(self.theta) - 2))
        w = (x - self.theta[k]) / (self.theta[k + 1] - self.theta[k])
        return (1 - w) * self.U[k] + w * self.U[k + 1]

    def deformed_points(self, theta: float) -> np.ndarray:
        return self.points + self.displacement(theta)


def boot_lever_truth(spec: dict, n_profile: int | None = None, n_around: int | None = None, n_thick: int = 2,
                     step_deg: float = 2.0) -> LeverTruth:
    """The joint boot of a ``joint_boot`` model spec solved at full order on a finer mesh than its model: by default
    twice the spec's cells along the profile, 5/4 as many around (so that the model's vertices around the axis are
    not the truth's: the boot is a body of revolution, its model a polygon), ``n_thick`` layers through the wall
    (the model: one), Newton every ``step_deg`` of the lever, the top ring carried rigidly by the lever as in the
    model (that is how the boot is gripped, not a modelling choice).

    Trilinear hexahedra like the model: triquadratic ones on the model's own mesh failed to converge past 34 deg
    (the folds buckle; their self-contact is not modelled) after ten minutes, and so did 72 cells around with steps
    of 1.5 deg past 42 deg; the default (60 around for the spec's 48, 2 deg) converges in about 11 minutes on this
    project's 2-core host."""
    from simreal_nodes.geometry import rot_axis

    g, ms, lv = spec["geometry"], spec["mesh"], spec["lever"]
    n_profile = 2 * int(ms["n_profile"]) if n_profile is None else int(n_profile)
    n_around = (5 * int(ms["n_around"])) // 4 if n_around is None else int(n_around)
    mesh = meshes.joint_boot(n_profile, n_around, n_thick, g["height"], g["r_bottom"], g["r_top"], g["wall"],
                             int(g["folds"]), g["fold_depth"])
    m = spec["material"]
    material = materials.make_material(m["law"], float(m["E"]), float(m["nu"]))
    solid = fem.Solid(mesh, material, 1, [fem.Support(fem.Region("zmin")), fem.Support(fem.Region("zmax"))])
    X = solid.basis.doflocs
    comp = np.arange(solid.N) % 3
    top = solid.fixed[np.abs(X[2, solid.fixed] - X[2].max()) < 1e-9]
    pivot = np.asarray(lv["pivot"], dtype=np.float64)
    lo, hi = (float(v) for v in lv["theta_deg"])
    thetas = np.deg2rad(np.linspace(lo, hi, round((hi - lo) / step_deg) + 1))

    def ufix(theta: float) -> np.ndarray:
        u = np.zeros(solid.N)
        rel = X[:, top].T - pivot
        u[top] = (rel @ rot_axis(lv["axis"], theta).T + pivot - X[:, top].T)[np.arange(len(top)), comp[top]]
        return u

    path: list[np.ndarray] = []
    _u, info = solid.solve_states([(np.zeros(solid.N), ufix(t)) for t in thetas], path=path)
    U = np.stack([solid.vertex_displacement(v) for v in path])
    if not np.all(np.isfinite(U)):
        raise FemError("the truth solve returned NaN/inf")
    cells = (n_profile, n_thick, n_around)
    desc = (f"full-order trilinear hexahedra {cells[0]} x {cells[1]} x {cells[2]} (profile x wall x around, "
            f"{solid.N} dofs), {material.law}, Newton every {step_deg:g} deg of the lever "
            f"({info.newton_iterations} iterations)")
    return LeverTruth(mesh.p.T.copy(), meshes.boundary_triangles(mesh), thetas, U, desc,
                      {"cells": list(cells), "order": 1, "dofs": int(solid.N), "n_theta": len(thetas),
                       "newton_iterations": int(info.newton_iterations)})


@dataclass
class ModelError:
    """How far a reduced model is from the truth, over the truth's tabulated load positions.

    ``rel_l2``: ||u_model(s) - u_truth(s)|| / ||u_truth(s)|| over the model's surface nodes, per position;
    ``best_fit``: the model parameter whose displacement is closest to the truth's (least squares over the
    surface nodes) — what a tracker that saw every surface point exactly would report; ``bias``: best_fit - s."""

    s: np.ndarray
    rel_l2: np.ndarray
    best_fit: np.ndarray

    @property
    def bias(self) -> np.ndarray:
        return self.best_fit - self.s

    def summary(self, span: float) -> dict:
        b = np.abs(self.bias) / span * 100
        return {"model_rel_l2_median_pct": float(100 * np.median(self.rel_l2)),
                "model_rel_l2_max_pct": float(100 * np.max(self.rel_l2)),
                "model_bias_median_pct_span": float(np.median(b)), "model_bias_max_pct_span": float(np.max(b))}


def model_error(model: ReducedModel, truth: BeamLoadTruth, axis: str = "s", n_fit: int = 401,
                every: int = 4, n_modes: int | None = None) -> ModelError:
    """Compare a one-parameter load-position model with the truth at every ``every``-th tabulated position, with
    all its modes or the first ``n_modes`` (the best fit searched on ``n_fit`` positions over the axis).

    Both are expressed in the same object frame; the truth is interpolated at the model's surface nodes."""
    ax = model.axis(axis)
    if len(model.axes) != 1:
        raise ValueError(f"model_error compares one-parameter models; '{model.name}' has {len(model.axes)} axes")
    nodes = np.unique(np.asarray(model.surface).ravel()) if len(model.surface) else np.arange(model.n_nodes)
    emb = truth.embed(model.points[nodes])
    grid = np.linspace(*ax.range, n_fit)
    view = model.field("displacement").view(nodes, n_modes)
    table = np.stack([view.evaluate([g]).ravel() for g in grid])  # (n_fit, 3 n)
    s_out, rel, best = [], [], []
    for k in range(0, len(truth.s), every):
        s = float(truth.s[k])
        if not ax.contains(s):
            continue
        ut = np.einsum("nk,nkc->nc", emb[1], truth.U[k][emb[0]]).ravel()
        um = view.evaluate([s]).ravel()
        s_out.append(s)
        rel.append(float(np.linalg.norm(um - ut)) / max(float(np.linalg.norm(ut)), 1e-300))
        j = int(np.argmin(np.sum((table - ut) ** 2, axis=1)))
        best.append(grid[j])
    return ModelError(np.asarray(s_out), np.asarray(rel), np.asarray(best))


def plate_model_error(model: ReducedModel, truth: PlateLoadTruth, every: int = 3, n_fit: int = 41) -> dict:
    """:func:`model_error` for a two-parameter load-position model (s_x, s_y) against a plate's truth, at every
    ``every``-th tabulated position in each direction: the relative L2 error over the model's surface nodes and the
    bias of the best fit (a grid of ``n_fit`` x ``n_fit`` positions, then least squares from its best), each axis
    in % of its range; a position's bias is the larger of its two."""
    from scipy.optimize import least_squares

    if [a.name for a in model.axes] != ["s_x", "s_y"]:
        raise ValueError(f"plate_model_error compares (s_x, s_y) models; '{model.name}' has "
                         f"{[a.name for a in model.axes]}")
    ax, ay = model.axes
    spans = np.array([ax.range[1] - ax.range[0], ay.range[1] - ay.range[0]])
    nodes = np.unique(np.asarray(model.surface).ravel()) if len(model.surface) else np.arange(model.n_nodes)
    emb = truth.embed(model.points[nodes])
    view = model.field("displacement").view(nodes)
    gx, gy = np.linspace(*ax.range, n_fit), np.linspace(*ay.range, n_fit)
    grid = np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)
    table = np.stack([view.evaluate(list(g)).ravel() for g in grid])
    rel, bias = [], []
    for i in range(0, len(truth.s), every):
        for j in range(0, len(truth.sy), every):
            s = np.array([truth.s[i], truth.sy[j]])
            if not (ax.contains(float(s[0])) and ay.contains(float(s[1]))):
                continue
            ut = np.einsum("nk,nkc->nc", emb[1], truth.U[i, j][emb[0]]).ravel()
            rel.append(float(np.linalg.norm(view.evaluate(list(s)).ravel() - ut)) / max(float(np.linalg.norm(ut)),
                                                                                         1e-300))
            g0 = grid[int(np.argmin(np.sum((table - ut) ** 2, axis=1)))]
            def misfit(m: np.ndarray, target: np.ndarray = ut) -> np.ndarray:
                return view.evaluate(list(m)).ravel() - target

            fit = least_squares(misfit, g0,
                                bounds=([ax.range[0], ay.range[0]], [ax.range[1], ay.range[1]]), x_scale=spans)
            bias.append(float(np.max(np.abs(fit.x - s) / spans)))
    if not rel:
        raise ValueError("no tabulated truth position lies inside the model's load range")
    r, b = 100 * np.asarray(rel), 100 * np.asarray(bias)
    return {"model_rel_l2_median_pct": float(np.median(r)), "model_rel_l2_max_pct": float(np.max(r)),
            "model_bias_median_pct_span": float(np.median(b)), "model_bias_max_pct_span": float(np.max(b))}
