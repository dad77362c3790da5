"""`simreal build-model SPEC.yaml -o MODEL.h5`: full-order snapshots / intrusive PGD -> model file.

Builders (``kind`` in the spec):

- ``beam_pgd``: linear elastic beam, intrusive PGD u(x, s) (load on the top centreline) or u(x, s_x, s_y)
  (load anywhere on the top face), optionally with E as a further axis (the three-field u(x, s, E)).
  Aluminium beam, crossed beams.
- ``beam_snapshots``: hyperelastic (SVK) beam under a patch load at each position s (Newton), NI-PGD of the
  displacement and stress snapshots. Foam beam.
- ``beam_contact_nipgd``: hyperelastic (SVK) beam under a point load at each top-face vertex growing over
  pseudo-time (Newton increments); NI-PGD of the (space x s_x x s_y x pseudo-time) tensors: u(x, s_x, s_y, tau).
  The thesis's crossed beams (§5.4.1, St. Venant-Kirchhoff).
- ``joint_boot``: neo-Hookean bellows whose top ring follows a lever rotated by theta (Newton along theta),
  NI-PGD. Joint boot (virtual and real; alpha_z is a rigid parameter handled by the tracker).
- ``probe_nipgd``: scanned surface (bunny, dragon) -> volumetric mesh; loads at contact points growing over
  pseudo-time (Newton increments); NI-PGD of the (space x load point x pseudo-time) tensors (Eq. 5.4-5.5).

Every model stores displacement and Cauchy-stress fields (von Mises is computed from the stress
components when drawn), the error against the full-order snapshots versus the number of modes, and
its provenance (spec, versions, timings).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import os
import platform
import subprocess
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import scipy.sparse as sp
import yaml
from numpy.typing import NDArray

from simreal_nodes import __version__
from simreal_nodes.errors import FemError, SceneError
from simreal_nodes.geometry import rot_axis, vertex_normals
from simreal_nodes.physics import fem, materials, meshes
from simreal_nodes.rom import nipgd as nip
from simreal_nodes.rom import pgd
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.separated import Axis, SeparatedField
from simreal_nodes.spec import Context, Enum, ListOf, Number, Record, Str, Vector

if TYPE_CHECKING:
    import skfem

REPO = Path(__file__).resolve().parents[2]
SPEC_DIR = Path(__file__).resolve().parents[1] / "specs"
STRESS_COMPONENTS = ["xx", "yy", "zz", "xy", "yz", "xz"]
KEEP_SNAPSHOTS = False  # benchmarks set this to compare NI-PGD with HOSVD on the same tensors

# A validated model spec: the YAML document after SPECS[kind].validate (the schema below gives its keys).
ModelSpec = dict[str, Any]
# progress(stage, done, total, message): what `simreal build-model` prints.
Progress = Callable[[str, int, int, str], object]

# ------------------------------------------------------------------------------------------------
# Spec schema

MATERIAL = Record({
    "law": Enum(tuple(materials.LAWS), "constitutive law", required=True),
    "E": Number("Young's modulus, Pa", lo=0, lo_open=True, required=True),
    "nu": Number("Poisson's ratio", lo=-0.999, hi=0.4999, required=True),
})


class _Region(Str):
    """A face name (xmin ...) or {face, box}."""

    def validate(self, v: Any, path: str, ctx: Context) -> Any:
        if isinstance(v, str):
            if v not in fem.FACES:
                self.fail(path, "a face name " + ", ".join(fem.FACES) + " or {face, box}", v, ctx)
            return v
        rec = Record({"face": Enum(tuple(fem.FACES), nullable=True),
                      "box": ListOf(Vector(2, what="[lo, hi]", nullable=True), nullable=True)})
        return rec.validate(v, path, ctx)


SUPPORT = Record({
    "region": _Region("support region", required=True),
    "kind": Enum(("clamped", "pinned", "sliding"), default="clamped"),
    "component": Enum(("x", "y", "z"), nullable=True),
})

COMMON = {
    "simreal_model_spec": Number("spec format version", integer=True, required=True),
    "name": Str("model name", required=True),
    "description": Str(default=""),
    "kind": Enum(("beam_pgd", "beam_snapshots", "beam_contact_nipgd", "joint_boot", "probe_nipgd"), "builder",
                 required=True),
    "material": MATERIAL,
}
NIPGD = Record({"max_terms": Number(integer=True, lo=1, default=30), "tol": Number(lo=0, lo_open=True, default=1e-4)})

SPECS = {
    "beam_pgd": Record({**COMMON,
        "geometry": Record({"length": Number(lo=0, lo_open=True, required=True),
                            "width": Number(lo=0, lo_open=True, required=True),
                            "height": Number(lo=0, lo_open=True, required=True)}),
        "mesh": Record({"cells": Vector(3, what="[nx, ny, nz]", required=True),
                        "element": Enum(("hex", "tet"), default="hex"),
                        "order": Number(integer=True, lo=1, hi=2, default=2)}),
        "supports": ListOf(SUPPORT, min_len=1, required=True),
        "load": Record({"force": Number(lo=0, lo_open=True, required=True), "direction": Vector(3, default=[0, 0, -1]),
                        "where": Enum(("centreline", "top_face"), default="centreline"),
                        "x_range": Vector(2, nullable=True), "y_range": Vector(2, nullable=True)}),
        "young_modulus_axis": Record({"range": Vector(2, required=True), "n": Number(integer=True, lo=2, default=9)},
                                     nullable=True),
        "pgd": Record({"max_modes": Number(integer=True, lo=1, default=30),
                       "tol": Number(lo=0, lo_open=True, default=1e-5),
                       "fixed_point_iterations": Number(integer=True, lo=1, default=40)}),
        "validation_every": Number("FEM truth at every k-th load position", integer=True, lo=1, default=4),
        "interpolation": Enum(("cubic", "linear"), default="cubic"),
    }),
    "beam_snapshots": Record({**COMMON,
        "geometry": Record({"length": Number(lo=0, lo_open=True, required=True),
                            "width": Number(lo=0, lo_open=True, required=True),
                            "height": Number(lo=0, lo_open=True, required=True)}),
        "mesh": Record({"cells": Vector(3, required=True), "element": Enum(("hex", "tet"), default="hex"),
                        "order": Number(integer=True, lo=1, hi=2, default=1)}),
        "supports": ListOf(SUPPORT, min_len=1, required=True),
        "load": Record({"force": Number(lo=0, lo_open=True, required=True), "direction": Vector(3, default=[0, 0, -1]),
                        "patch_radius": Number(lo=0, lo_open=True, required=True), "x_range": Vector(2, required=True),
                        "n": Number(integer=True, lo=2, required=True)}),
        "steps": Number("Newton load steps per snapshot", integer=True, lo=1, default=4),
        "nipgd": NIPGD,
        "interpolation": Enum(("cubic", "linear"), default="cubic"),
    }),
    "beam_contact_nipgd": Record({**COMMON,
        "geometry": Record({"length": Number(lo=0, lo_open=True, required=True),
                            "width": Number(lo=0, lo_open=True, required=True),
                            "height": Number(lo=0, lo_open=True, required=True)}),
        "mesh": Record({"cells": Vector(3, what="[nx, ny, nz]", required=True),
                        "element": Enum(("hex", "tet"), default="hex"),
                        "order": Number(integer=True, lo=1, hi=2, default=2)}),
        "supports": ListOf(SUPPORT, min_len=1, required=True),
        "load": Record({"force": Number("largest total force, N", lo=0, lo_open=True, required=True),
                        "direction": Vector(3, default=[0, 0, -1]),
                        "x_range": Vector(2, nullable=True), "y_range": Vector(2, nullable=True),
                        "increments": Number("Newton load increments: the pseudo-time axis has this many steps",
                                             integer=True, lo=2, default=8)}),
        "nipgd": NIPGD,
        "interpolation": Enum(("cubic", "linear"), default="cubic"),
        "validation_points": Number("full-order solves at load positions between the grid's (interpolation check)",
                                    integer=True, lo=0, default=4),
    }),
    "joint_boot": Record({**COMMON,
        "geometry": Record({k: Number(lo=0, lo_open=True, default=d) for k, d in
                            (("height", 0.12), ("r_bottom", 0.05), ("r_top", 0.018), ("wall", 0.004),
                             ("fold_depth", 0.008))}
                           | {"folds": Number(integer=True, lo=0, default=3)}),
        "mesh": Record({"n_profile": Number(integer=True, lo=4, default=36),
                        "n_around": Number(integer=True, lo=8, default=24),
                        "n_thick": Number(integer=True, lo=1, default=1),
                        "order": Number(integer=True, lo=1, hi=2, default=1)}),
        "lever": Record({"pivot": Vector(3, default=[0, 0, 0]), "axis": Enum(("x", "y"), default="y"),
                         "theta_deg": Vector(2, default=[0, 52]), "n": Number(integer=True, lo=3, default=27),
                         "bar": Vector(4, what="[width, depth, z_from, z_to] of the rigid lever bar (metres)",
                                       default=[0.016, 0.016, 0.02, 0.26])}),
        "nipgd": NIPGD,
    }),
    "probe_nipgd": Record({**COMMON,
        "surface": Str("surface mesh; 'data:' prefix = the shared data folder", required=True),
        "transform": Record({"rotate_deg": Vector(3, default=[0, 0, 0]),
                             "scale": Number(lo=0, lo_open=True, default=1.0),
                             "height_m": Number(lo=0, lo_open=True, nullable=True)}),
        "mesh": Record({"cell_size": Number("grid spacing as a fraction of the height", lo=0, lo_open=True,
                                            default=0.06)}),
        "base_fraction": Number("nodes below this fraction of the height are clamped", lo=0, hi=0.5, default=0.05),
        "contact": Record({"points": Number(integer=True, lo=1, default=16),
                           "min_height_fraction": Number(lo=0, hi=1, default=0.3),
                           "rings": Number("patch = contact node + this many graph rings", integer=True, lo=0,
                                           default=2),
                           "direction": Enum(("centroid", "normal"), default="centroid"),
                           "force": Number("largest total force, N", lo=0, lo_open=True, required=True),
                           "increments": Number(integer=True, lo=2, default=10)}),
        "nipgd": NIPGD,
    }),
}


def data_path(p: str) -> Path:
    """'data:meshes/x.ply' -> $SIMREAL_DATA/meshes/x.ply (default: <repo>/../shared/data)."""
    if p.startswith("data:"):
        base = Path(os.environ.get("SIMREAL_DATA", REPO.parent / "shared" / "data"))
        return base / p[5:]
    return Path(p)


def load_spec(path: str | Path) -> ModelSpec:
    path = Path(path)
    if not path.exists() and (SPEC_DIR / path).exists():
        path = SPEC_DIR / path
    try:
        doc = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise SceneError(f"model spec not found: {path} (built-in specs: "
                         f"{', '.join(p.name for p in sorted(SPEC_DIR.glob('*.yaml')))})") from None
    except yaml.YAMLError as e:
        raise SceneError(f"{path}: not valid YAML: {e}") from None
    if not isinstance(doc, dict) or doc.get("kind") not in SPECS:
        found = doc.get("kind") if isinstance(doc, dict) else doc
        raise SceneError(f"{path}: kind: expected one of {', '.join(SPECS)}; found {found!r}")
    spec: ModelSpec = SPECS[doc["kind"]].validate(doc, "", Context(str(path), path.parent))
    if spec["simreal_model_spec"] != 1:
        raise SceneError(f"{path}: simreal_model_spec: expected 1; found {spec['simreal_model_spec']}")
    spec["_text"] = path.read_text()
    spec["_path"] = str(path)
    return spec


def _material(spec: ModelSpec) -> materials.Material:
    m = spec["material"]
    return materials.make_material(m["law"], m["E"], m["nu"], spec["name"])


def _supports(spec: ModelSpec) -> list[fem.Support]:
    return [fem.Support(fem.Region.from_spec(s["region"]), s["kind"],
                        None if s["component"] is None else "xyz".index(s["component"]))
            for s in spec["supports"]]


def _provenance(spec: ModelSpec, t0: float, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    import h5py
    import scipy
    import skfem

    try:
        git = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             timeout=5).stdout.strip()
    except Exception:  # noqa: BLE001
        git = ""
    d = {"spec": spec["_text"], "spec_path": spec["_path"], "build_time_s": round(time.time() - t0, 2),
         "builder": builder_version(), "simreal": __version__, "git": git, "numpy": np.__version__,
         "scipy": scipy.__version__, "scikit_fem": getattr(skfem, "__version__", ""), "h5py": h5py.__version__,
         "python": platform.python_version(), "host": platform.node(), "built": time.strftime("%Y-%m-%dT%H:%M:%S")}
    d.update(extra or {})
    return d


def _cell_type(mesh: skfem.Mesh) -> str:
    import skfem

    return {skfem.MeshTet1: "tet4", skfem.MeshHex1: "hex8"}[type(mesh)]


def _stress_modes(solid: fem.Solid, dof_modes: NDArray[np.float64]) -> NDArray[np.float64]:
    """Stress of each (linear) displacement mode at the vertices: (m, n_vert, 6)."""
    return np.stack([solid.stress(u)["cauchy"] for u in dof_modes])


# ------------------------------------------------------------------------------------------------
# beam_pgd: intrusive PGD, Algorithm 2.1


def _warn_bending(spec: ModelSpec) -> None:
    """Linear elements lock in bending: a beam meshed with them is too stiff whatever its Poisson's ratio
    (docs/stability.md: with two cells through the section at L/h 20, hexahedra 12 %, tetrahedra 50 %)."""
    ms = spec["mesh"]
    if ms["order"] == 1:
        warnings.warn(f"{spec['_path']}: linear {ms['element']} elements are too stiff in bending (hexahedra 12 %, "
                      "tetrahedra 50 % with two cells through the section at L/h 20: docs/stability.md); use "
                      "mesh.order: 2", materials.LockingWarning, stacklevel=3)


def build_beam_pgd(spec: ModelSpec, progress: Progress | None = None) -> ReducedModel:
    t0 = time.time()
    g, ms = spec["geometry"], spec["mesh"]
    L, W, H = g["length"], g["width"], g["height"]
    _warn_bending(spec)
    mesh = meshes.box(L, W, H, tuple(int(c) for c in ms["cells"]), ms["element"])
    mat = _material(spec)
    if not isinstance(mat, materials.LinearElastic):
        raise SceneError(f"{spec['_path']}: beam_pgd needs material.law linear_elastic (intrusive PGD of a linear "
                         "problem); use kind beam_snapshots for hyperelastic beams")
    solid = fem.Solid(mesh, mat, ms["order"], _supports(spec))
    ld = spec["load"]
    top = solid.vertices_in({"face": "zmax"})
    P = mesh.p
    if ld["where"] == "centreline":
        ys = np.unique(np.round(P[1, top], 12))
        yc = ys[np.argmin(np.abs(ys - W / 2))]
        top = top[np.abs(P[1, top] - yc) < 1e-9]
    xr = ld["x_range"] or [0.0, L]
    top = top[(P[0, top] >= xr[0] - 1e-9) & (P[0, top] <= xr[1] + 1e-9)]
    if ld["where"] == "top_face" and ld["y_range"]:
        top = top[(P[1, top] >= ld["y_range"][0] - 1e-9) & (P[1, top] <= ld["y_range"][1] + 1e-9)]
    force = ld["force"] * np.asarray(ld["direction"], dtype=np.float64) / np.linalg.norm(ld["direction"])
    xs = np.unique(np.round(P[0, top], 12))
    ysx = np.unique(np.round(P[1, top], 12))
    if ld["where"] == "centreline":
        order = np.argsort(P[0, top])
        top = top[order]
        axes_vals = [P[0, top]]
        loads_G = [np.eye(len(top))]
        names = [("s", "position of the load along the top centreline (x)")]
    else:
        ix = np.searchsorted(xs, np.round(P[0, top], 12))
        iy = np.searchsorted(ysx, np.round(P[1, top], 12))
        axes_vals = [xs, ysx]
        loads_G = [np.eye(len(xs))[ix], np.eye(len(ysx))[iy]]
        names = [("s_x", "load position on the top face, x"), ("s_y", "load position on the top face, y")]
    Hl = sp.lil_matrix((solid.N, len(top)))
    for j, v in enumerate(top):
        for c in range(3):
            Hl[solid.vertex_dofs(v)[c], j] = force[c]
    Hm = Hl.tocsr()
    K1 = solid.stiffness()  # E units: K = E * K1
    E0 = mat.E
    op_d = [np.ones(len(v)) for v in axes_vals]
    pgd_axes = [pgd.ParameterAxis(v) for v in axes_vals]
    E_axis = spec["young_modulus_axis"]
    if E_axis:
        Ev = np.linspace(E_axis["range"][0], E_axis["range"][1], E_axis["n"])
        pgd_axes.append(pgd.ParameterAxis(Ev / E0))  # nondimensional E' = E / E0: K = E0 K1 E'
        op_d.append(Ev / E0)
        loads_G.append(np.ones((loads_G[0].shape[0], len(Ev))))
    op = pgd.SeparatedOperator([(K1 * 1.0, op_d)])
    # scipy-stubs type csr / scalar as any sparse format; it is a csr_matrix
    load = pgd.SeparatedLoad(cast(sp.csr_matrix, Hm / E0), loads_G)
    cfg = spec["pgd"]
    res = pgd.pgd_solve(op, load, pgd_axes, solid.free, max_modes=cfg["max_modes"], tol=cfg["tol"],
                        max_fp_iter=cfg["fixed_point_iterations"],
                        progress=(lambda n, a: progress("pgd", n, cfg["max_modes"],
                                                        f"mode {n}: amplitude ratio {a:.2e}")) if progress else None)
    m = res.n_modes
    space_u = res.F[:, solid.basis.nodal_dofs.T]  # (m, n_vert, 3)
    if progress:
        progress("stress", 0, m, "stress of each mode")
    space_s = _stress_modes(solid, res.F)
    axes = [Axis(n, v, "m", description=d, interpolation=spec["interpolation"]) for (n, d), v in zip(names, axes_vals)]
    params_u = [np.asarray(gk) for gk in res.G]
    params_s = [np.asarray(gk) for gk in res.G]
    if E_axis:
        axes.append(Axis("E", Ev, "Pa", description="Young's modulus", interpolation="cubic"))
        params_s[-1] = params_s[-1] * (Ev / E0)[None, :]  # stress = E C1 eps(u): the E factor moves into its mode
    # error against the full-order truth at every k-th load position (and each E node)
    every = spec["validation_every"]
    idx = np.arange(0, len(top), every)
    Us = []
    mus = []
    Evals = Ev if E_axis else [E0]
    import scipy.sparse.linalg as spla
    lu = spla.splu((K1[solid.free][:, solid.free]).tocsc())
    for E in (Evals if len(Evals) <= 3 else [Evals[0], Evals[len(Evals) // 2], Evals[-1]]):
        rhs = Hm[:, idx].toarray()[solid.free] / E
        U = np.zeros((solid.N, len(idx)))
        U[solid.free] = lu.solve(rhs)
        for k, jv in enumerate(idx):
            Us.append(U[:, k][solid.basis.nodal_dofs.T])
            if ld["where"] == "centreline":
                mu = [axes_vals[0][jv]]
            else:
                mu = [xs[np.argmax(loads_G[0][jv])], ysx[np.argmax(loads_G[1][jv])]]
            if E_axis:
                mu.append(E)
            mus.append(mu)
    fld_u = SeparatedField("displacement", space_u, params_u, axes, "m", ["x", "y", "z"])
    err = _error_vs_modes(fld_u, mus, Us)
    fld_u.error_vs_modes = err
    fld_s = SeparatedField("stress", space_s, params_s, axes, "Pa", STRESS_COMPONENTS, None)
    model = ReducedModel(spec["name"], mesh.p.T.copy(), mesh.t.T.copy(), _cell_type(mesh), axes,
                         {"displacement": fld_u, "stress": fld_s}, meshes.boundary_triangles(mesh), spec["description"],
                         mat.as_dict(), spec["supports"],
                         {"force_N": ld["force"], "direction": list(force / ld["force"]), "where": ld["where"]},
                         load_points=top, load_directions=np.tile(force / ld["force"], (len(top), 1)))
    model.provenance = _provenance(spec, t0, {"method": "intrusive PGD (Algorithm 2.1)",
                                              "pgd_amplitudes": res.amplitudes.tolist(),
                                              "fixed_point_iterations": res.fixed_point_iterations,
                                              "pgd_converged": res.converged, "dofs": int(solid.N)})
    return model


def _error_vs_modes(fld: SeparatedField, mus: list[list[float]], truths: list[NDArray[np.float64]]
                    ) -> NDArray[np.float64]:
    """Relative error ||u_rom - u_fem|| / ||u_fem|| over the validation set, for 1..n modes."""
    T = np.stack(truths)
    nt = np.linalg.norm(T)
    out = []
    for n in range(1, fld.n_modes + 1):
        R = np.stack([fld.evaluate(mu, n_modes=n) for mu in mus])
        out.append(np.linalg.norm(R - T) / max(float(nt), 1e-300))
    return np.asarray(out)


# ------------------------------------------------------------------------------------------------
# Snapshot-based builders + NI-PGD


def _nipgd_fields(name_axes: list[str], U: NDArray[np.float64], S: NDArray[np.float64], axes: list[Axis],
                  cfg: dict[str, Any], progress: Progress | None) -> dict[str, Any]:
    """Displacement (n_vert, 3, *axes) and stress (n_vert, 6, *axes) tensors -> separated fields."""
    out: dict[str, Any] = {}  # the fields, and "_snapshots" when KEEP_SNAPSHOTS
    if KEEP_SNAPSHOTS:
        out["_snapshots"] = {"displacement": U, "stress": S}
    for fname, T, unit, comps in (("displacement", U, "m", ["x", "y", "z"]), ("stress", S, "Pa", STRESS_COMPONENTS)):
        nv, nc = T.shape[:2]
        A = T.reshape((nv * nc,) + T.shape[2:])
        scale = np.abs(A).max() or 1.0
        on_term: Callable[[int, float], object] | None = None
        if progress:
            def on_term(n: int, e: float, f: str = fname, p: Progress = progress) -> object:
                return p(f"nipgd {f}", n, cfg["max_terms"], f"term {n}: error {e:.2e}")
        res = nip.nipgd(A / scale, max_terms=cfg["max_terms"], tol=cfg["tol"], progress=on_term)
        space = (res.factors[0] * scale).reshape(res.n_terms, nv, nc)
        out[fname] = SeparatedField(fname, space, [f.copy() for f in res.factors[1:]], axes, unit, comps, res.errors)
    return out


def build_beam_snapshots(spec: ModelSpec, progress: Progress | None = None) -> ReducedModel:
    t0 = time.time()
    g, ms, ld = spec["geometry"], spec["mesh"], spec["load"]
    L, W, H = g["length"], g["width"], g["height"]
    _warn_bending(spec)
    mesh = meshes.box(L, W, H, tuple(int(c) for c in ms["cells"]), ms["element"])
    mat = _material(spec)
    solid = fem.Solid(mesh, mat, ms["order"], _supports(spec))
    force = ld["force"] * np.asarray(ld["direction"], dtype=np.float64) / np.linalg.norm(ld["direction"])
    s_vals = np.linspace(ld["x_range"][0], ld["x_range"][1], ld["n"])
    nv = mesh.p.shape[1]
    U = np.zeros((nv, 3, len(s_vals)))
    S = np.zeros((nv, 6, len(s_vals)))
    newton = []
    for j, s in enumerate(s_vals):
        f = solid.patch_load("zmax", [s, W / 2, H], ld["patch_radius"], force)
        u, info = solid.solve(f, steps=spec["steps"])
        newton.append(info.newton_iterations)
        U[:, :, j] = solid.vertex_displacement(u)
        S[:, :, j] = solid.stress(u)["cauchy"]
        if progress:
            progress("snapshots", j + 1, len(s_vals), f"s = {s:.4f} m: {info.newton_iterations} Newton iterations")
    axes = [Axis("s", s_vals, "m", description="position of the load (centre of the lead disk) along x",
                 interpolation=spec["interpolation"])]
    fields = _nipgd_fields(["s"], U, S, axes, spec["nipgd"], progress)
    snaps = fields.pop("_snapshots", None)
    # interpolation check between snapshots: full-order solves at a few mid points
    mids = 0.5 * (s_vals[:-1] + s_vals[1:])[:: max(1, len(s_vals) // 4)]
    mid_err = []
    for s in mids:
        u, _ = solid.solve(solid.patch_load("zmax", [s, W / 2, H], ld["patch_radius"], force), steps=spec["steps"])
        ref = solid.vertex_displacement(u)
        mid_err.append(float(np.linalg.norm(fields["displacement"].evaluate([s]) - ref) / np.linalg.norm(ref)))
    model = ReducedModel(spec["name"], mesh.p.T.copy(), mesh.t.T.copy(), _cell_type(mesh), axes, fields,
                         meshes.boundary_triangles(mesh), spec["description"], mat.as_dict(), spec["supports"],
                         {"force_N": ld["force"], "patch_radius_m": ld["patch_radius"],
                          "direction": list(force / ld["force"])})
    model.provenance = _provenance(spec, t0, {"method": "Newton snapshots + NI-PGD (Eq. 5.4-5.5)",
                                              "newton_iterations": newton,
                                              "midpoint_interpolation_error": dict(zip([float(x) for x in mids],
                                                                                       mid_err))})
    model.snapshots = snaps
    return model


def _contact_solid(spec: ModelSpec) -> fem.Solid:
    g, ms = spec["geometry"], spec["mesh"]
    mesh = meshes.box(g["length"], g["width"], g["height"], tuple(int(c) for c in ms["cells"]), ms["element"])
    return fem.Solid(mesh, _material(spec), ms["order"], _supports(spec))


def _contact_paths(spec: ModelSpec, points: list[list[float]]) -> list[tuple[Any, Any, int]]:
    """Worker of :func:`build_beam_contact_nipgd`: for each load point, the Newton path of a point force growing
    to the spec's load over its increments -> (vertex displacement (nv, 3, n_inc), Cauchy stress (nv, 6, n_inc),
    Newton iterations). A module-level function: it runs in a process of its own."""
    solid = _contact_solid(spec)
    ld = spec["load"]
    force = ld["force"] * np.asarray(ld["direction"], dtype=np.float64) / np.linalg.norm(ld["direction"])
    out = []
    for p in points:
        path: list[NDArray[np.float64]] = []
        try:
            _, info = solid.solve(solid.consistent_point_load(p, force), steps=ld["increments"], path=path)
        except FemError as e:
            raise FemError(f"load point {np.round(p, 6).tolist()}: {e}; lower load.force") from None
        out.append((np.stack([solid.vertex_displacement(u) for u in path], axis=-1),
                    np.stack([solid.stress(u)["cauchy"] for u in path], axis=-1), info.newton_iterations))
    return out


def _build_workers() -> int:
    """Processes for a snapshot sweep: ``SIMREAL_BUILD_WORKERS``, else every core. The model does not depend on it."""
    return max(1, int(os.environ.get("SIMREAL_BUILD_WORKERS", "0")) or (os.cpu_count() or 1))


def build_beam_contact_nipgd(spec: ModelSpec, progress: Progress | None = None) -> ReducedModel:
    """The thesis's crossed beams (§5.4.1): a hyperelastic beam pressed at any vertex of its top face (the load
    positions S = (s_x, s_y) of Eq. 5.6) by a point force growing over the pseudo-time of Alg. 5.1 (Newton
    increments of the load: tau = force / the spec's force), snapshots reduced by NI-PGD into
    u(x, s_x, s_y, tau) (Eq. 5.4-5.5). Between load positions the model interpolates its parameter modes; the
    error of that is measured against full-order solves at ``validation_points`` positions between the grid's."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    t0 = time.time()
    _warn_bending(spec)
    ld = spec["load"]
    H = spec["geometry"]["height"]
    solid = _contact_solid(spec)
    mesh, P = solid.mesh, solid.mesh.p
    top = solid.vertices_in({"face": "zmax"})
    for ax, rng in ((0, ld["x_range"]), (1, ld["y_range"])):
        if rng:
            top = top[(P[ax, top] >= rng[0] - 1e-9) & (P[ax, top] <= rng[1] + 1e-9)]
    xs, ys = np.unique(np.round(P[0, top], 12)), np.unique(np.round(P[1, top], 12))
    ix, iy = np.searchsorted(xs, np.round(P[0, top], 12)), np.searchsorted(ys, np.round(P[1, top], 12))
    if len(top) != len(xs) * len(ys) or len(xs) < 2 or len(ys) < 2:
        raise SceneError(f"{spec['_path']}: the top face's load positions must form a grid of at least 2 x 2 vertices "
                         f"(found {len(top)} vertices, {len(xs)} x {len(ys)} coordinates)")
    order = np.lexsort((iy, ix))  # by x, then y
    top, ix, iy = top[order], ix[order], iy[order]
    n_inc = int(ld["increments"])
    force = ld["force"] * np.asarray(ld["direction"], dtype=np.float64) / np.linalg.norm(ld["direction"])
    nv = P.shape[1]
    U = np.zeros((nv, 3, len(xs), len(ys), n_inc + 1))
    S = np.zeros((nv, 6, len(xs), len(ys), n_inc + 1))
    newton = np.zeros((len(xs), len(ys)), np.int64)
    pts = [P[:, v].tolist() for v in top]
    workers = min(_build_workers(), len(pts))
    chunks = [list(range(k, min(k + 4, len(pts)))) for k in range(0, len(pts), 4)]
    done = 0

    def take(idx: list[int], res: list[tuple[Any, Any, int]]) -> None:
        nonlocal done
        for j, (u, st, its) in zip(idx, res):
            U[:, :, ix[j], iy[j], 1:], S[:, :, ix[j], iy[j], 1:], newton[ix[j], iy[j]] = u, st, its
        done += len(idx)
        if progress:
            progress("snapshots", done, len(pts), f"{done} of {len(pts)} load points ({workers} processes)")

    if workers > 1:
        # fork: the workers need nothing of the caller but this module (spawn would re-run a caller's script)
        with ProcessPoolExecutor(workers, mp_context=get_context("fork")) as ex:
            futs = [(idx, ex.submit(_contact_paths, spec, [pts[j] for j in idx])) for idx in chunks]
            for idx, fut in futs:
                take(idx, fut.result())
    else:
        for idx in chunks:
            take(idx, _contact_paths(spec, [pts[j] for j in idx]))
    tau = np.linspace(0.0, 1.0, n_inc + 1)
    interp = spec["interpolation"]
    axes = [Axis("s_x", xs, "m", description="load position on the top face, x", interpolation=interp),
            Axis("s_y", ys, "m", description="load position on the top face, y", interpolation=interp),
            Axis("pseudo_time", tau, "", description="deformation pseudo-time: 0 undeformed, 1 the full load "
                                                     "(Alg. 5.1); the force grows linearly with it",
                 interpolation=interp)]
    fields = _nipgd_fields(["s_x", "s_y", "pseudo_time"], U, S, axes, spec["nipgd"], progress)
    snaps = fields.pop("_snapshots", None)
    # the interpolation between load positions: full-order solves midway between grid positions, at the full load
    n_val = int(spec["validation_points"])
    rng = np.random.default_rng(0)
    val_err = []
    for _ in range(n_val):
        i, j = int(rng.integers(0, len(xs) - 1)), int(rng.integers(0, len(ys) - 1))
        p = [0.5 * (xs[i] + xs[i + 1]), 0.5 * (ys[j] + ys[j + 1]), H]
        u, _ = solid.solve(solid.consistent_point_load(p, force), steps=n_inc)
        ref = solid.vertex_displacement(u)
        err = float(np.linalg.norm(fields["displacement"].evaluate([p[0], p[1], 1.0]) - ref))
        val_err.append({"s_x": float(p[0]), "s_y": float(p[1]),
                        "relative_error": err / max(float(np.linalg.norm(ref)), 1e-300)})
    model = ReducedModel(spec["name"], mesh.p.T.copy(), mesh.t.T.copy(), _cell_type(mesh), axes, fields,
                         meshes.boundary_triangles(mesh), spec["description"], _material(spec).as_dict(),
                         spec["supports"],
                         {"force_N": ld["force"], "direction": list(force / ld["force"]), "where": "top_face"},
                         load_points=top, load_directions=np.tile(force / ld["force"], (len(top), 1)))
    model.provenance = _provenance(spec, t0, {"method": "Newton increments + NI-PGD (Eq. 5.4-5.6)",
                                              "newton_iterations": newton.ravel().tolist(),
                                              "between_positions_error": val_err, "workers": workers})
    model.snapshots = snaps
    return model


def build_joint_boot(spec: ModelSpec, progress: Progress | None = None) -> ReducedModel:
    t0 = time.time()
    g, ms, lv = spec["geometry"], spec["mesh"], spec["lever"]
    mesh = meshes.joint_boot(ms["n_profile"], ms["n_around"], ms["n_thick"], g["height"], g["r_bottom"], g["r_top"],
                             g["wall"], int(g["folds"]), g["fold_depth"])
    mat = _material(spec)
    solid = fem.Solid(mesh, mat, ms["order"], [fem.Support(fem.Region("zmin")), fem.Support(fem.Region("zmax"))])
    X = solid.basis.doflocs
    comp = np.arange(solid.N) % 3
    top = solid.fixed[np.abs(X[2, solid.fixed] - X[2].max()) < 1e-9]
    pivot = np.asarray(lv["pivot"], dtype=np.float64)
    thetas = np.deg2rad(np.linspace(lv["theta_deg"][0], lv["theta_deg"][1], lv["n"]))

    def ufix(theta: float) -> NDArray[np.float64]:
        u = np.zeros(solid.N)
        Xt = X[:, top].T - pivot
        new = Xt @ rot_axis(lv["axis"], theta).T + pivot
        u[top] = (new - X[:, top].T)[np.arange(len(top)), comp[top]]
        return u

    states = [(np.zeros(solid.N), ufix(t)) for t in thetas]
    path: list[NDArray[np.float64]] = []
    _u, info = solid.solve_states(states, path=path,
                                 progress=(lambda k: progress("snapshots", k, len(thetas),
                                                              f"theta = {np.rad2deg(thetas[k - 1]):.1f} deg"))
                                 if progress else None)
    nv = mesh.p.shape[1]
    U = np.stack([solid.vertex_displacement(v) for v in path], axis=-1)
    S = np.stack([solid.stress(v)["cauchy"] for v in path], axis=-1)
    # the rigid lever rides on the same parameter: its surface points move by (R(theta) - I)(p - pivot)
    lever_pts = lever_points(*lv["bar"])
    Ul = np.stack([(lever_pts - pivot) @ rot_axis(lv["axis"], t).T + pivot - lever_pts for t in thetas], axis=-1)
    U = np.concatenate([U, Ul], axis=0)
    S = np.concatenate([S, np.zeros((len(lever_pts), 6, len(thetas)))], axis=0)
    axes = [Axis("theta", thetas, "rad", description=f"lever rotation about {lv['axis']} through {lv['pivot']}")]
    fields = _nipgd_fields(["theta"], U, S, axes, spec["nipgd"], progress)
    snaps = fields.pop("_snapshots", None)
    rigid = [{"name": "alpha_z", "axis": "z", "unit": "rad", "range": [-np.pi, np.pi], "origin": [0.0, 0.0, 0.0],
              "description": "rotation of the whole boot (and the lever plane) about its axis: the rotation-axis "
                             "orientation of thesis §4.5.4, a rigid parameter estimated by the tracker"}]
    model = ReducedModel(spec["name"], np.concatenate([mesh.p.T, lever_pts]), mesh.t.T.copy(), _cell_type(mesh), axes,
                         fields, meshes.boundary_triangles(mesh), spec["description"], mat.as_dict(),
                         [{"region": "zmin", "kind": "clamped"},
                          {"region": "zmax", "kind": "prescribed lever rotation"}],
                         {"lever": lv}, rigid_parameters=rigid)
    model.provenance = _provenance(spec, t0, {"method": "Newton along theta + NI-PGD",
                                              "newton_iterations": info.newton_iterations,
                                              "lever_nodes": [int(nv), len(lever_pts)],
                                              "note": "self-contact of the folds is not modelled; nodes from "
                                                      "lever_nodes[0] are points of the rigid lever bar"})
    model.snapshots = snaps
    return model


def build_probe_nipgd(spec: ModelSpec, progress: Progress | None = None) -> ReducedModel:
    t0 = time.time()
    src = data_path(spec["surface"])
    V, F = meshes.read_surface(src)
    tr = spec["transform"]
    R = rot_axis("z", np.deg2rad(tr["rotate_deg"][2])) @ rot_axis("y", np.deg2rad(tr["rotate_deg"][1])) @ \
        rot_axis("x", np.deg2rad(tr["rotate_deg"][0]))
    V = V @ R.T
    V = V - np.array([(V[:, 0].min() + V[:, 0].max()) / 2, (V[:, 1].min() + V[:, 1].max()) / 2, V[:, 2].min()])
    scale = tr["height_m"] / np.ptp(V[:, 2]) if tr["height_m"] else tr["scale"]
    V = V * scale
    Hh = np.ptp(V[:, 2])
    if progress:
        progress("mesh", 0, 1, f"volume mesh of {src.name}")
    mesh = meshes.voxel_tet_mesh(V, F, spec["mesh"]["cell_size"] * Hh)
    mat = _material(spec)
    solid = fem.Solid(mesh, mat, 1, [fem.Support(fem.Region(box=[None, None, [None, spec["base_fraction"] * Hh]]))])
    nv = mesh.p.shape[1]
    # contact points: farthest-point sampling among surface vertices above min height
    btri = meshes.boundary_triangles(mesh)
    bnodes = np.unique(btri)
    cand = bnodes[mesh.p[2, bnodes] >= spec["contact"]["min_height_fraction"] * Hh]
    lp = _farthest_points(mesh.p[:, cand].T, spec["contact"]["points"])
    load_nodes = cand[lp]
    # vertex normals of the boundary, graph rings for the patches
    normals = vertex_normals(mesh.p.T, btri)
    adj = _adjacency(btri, nv)
    centroid = mesh.p.mean(axis=1)
    cc = spec["contact"]
    n_inc = cc["increments"]
    tau = np.linspace(0.0, 1.0, n_inc + 1)
    U = np.zeros((nv, 3, len(load_nodes), len(tau)))
    S = np.zeros((nv, 6, len(load_nodes), len(tau)))
    dirs = []
    newton = []
    for i, node in enumerate(load_nodes):
        patch = _rings(adj, node, cc["rings"])
        d = (centroid - mesh.p[:, node]) if cc["direction"] == "centroid" else -normals[node]
        d = d / np.linalg.norm(d)
        dirs.append(d)
        f = np.zeros(solid.N)
        for v in patch:
            f[solid.vertex_dofs(v)] += cc["force"] * d / len(patch)
        path: list[NDArray[np.float64]] = []
        try:
            _, info = solid.solve(f, steps=n_inc, path=path)
            newton.append(info.newton_iterations)
        except FemError as e:
            raise FemError(f"contact point {i} (node {node}): {e}; lower contact.force") from None
        for k, u in enumerate(path):
            U[:, :, i, k + 1] = solid.vertex_displacement(u)
            S[:, :, i, k + 1] = solid.stress(u)["cauchy"]
        if progress:
            progress("snapshots", i + 1, len(load_nodes),
                     f"contact point {i}: {info.newton_iterations} Newton iterations")
    axes = [Axis("load_point", np.arange(len(load_nodes), dtype=float), "", "discrete",
                 description="index of the contact point"),
            Axis("pseudo_time", tau, "",
                 description="deformation pseudo-time: 0 undeformed, 1 full contact force (Alg. 5.1)")]
    fields = _nipgd_fields(["load_point", "pseudo_time"], U, S, axes, spec["nipgd"], progress)
    snaps = fields.pop("_snapshots", None)
    # the scan surface rides on the volume mesh: append its vertices as extra nodes (embedded)
    tets, w = meshes.embed_points(mesh, V)
    for fld in fields.values():
        extra = np.einsum("mnkc,nk->mnc", fld.space[:, tets], w)
        fld.space = np.concatenate([fld.space, extra], axis=1)
    points = np.concatenate([mesh.p.T, V])
    surface = F + nv
    model = ReducedModel(spec["name"], points, mesh.t.T.copy(), "tet4", axes, fields, surface, spec["description"],
                         mat.as_dict(), [{"region": f"z < {spec['base_fraction']} height", "kind": "clamped"}],
                         {"force_N": cc["force"], "direction": cc["direction"], "rings": cc["rings"]},
                         load_points=load_nodes, load_directions=np.asarray(dirs))
    model.provenance = _provenance(spec, t0, {"method": "Newton increments + NI-PGD (Eq. 5.4-5.5)",
                                              "newton_iterations": newton,
                                              "volume_nodes": int(nv), "surface_vertices": len(V),
                                              "note": "nodes >= volume_nodes are the scan surface, embedded in "
                                                      "the tetrahedra"})
    model.snapshots = snaps
    return model


def lever_points(width: float, depth: float, z0: float, z1: float, step: float = 0.008) -> NDArray[np.float64]:
    """Points on the four long faces of the lever bar (centred on the z axis), every ``step`` metres."""
    zs = np.arange(z0, z1 + 1e-9, step)
    a = np.arange(-width / 2, width / 2 + 1e-9, step / 2)
    b = np.arange(-depth / 2, depth / 2 + 1e-9, step / 2)
    pts = []
    for z in zs:
        pts += [[x, -depth / 2, z] for x in a] + [[x, depth / 2, z] for x in a]
        pts += [[-width / 2, y, z] for y in b[1:-1]] + [[width / 2, y, z] for y in b[1:-1]]
    return np.asarray(pts, dtype=np.float64)


def _farthest_points(P: NDArray[np.float64], k: int) -> NDArray[np.int64]:
    k = min(k, len(P))
    chosen = [int(np.argmax(P[:, 2]))]
    d = np.linalg.norm(P - P[chosen[0]], axis=1)
    for _ in range(k - 1):
        i = int(np.argmax(d))
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(P - P[i], axis=1))
    return np.asarray(chosen)


def _adjacency(tris: NDArray[np.int64], n: int) -> sp.csr_matrix:
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return (A + A.T).tocsr()


def _rings(adj: sp.csr_matrix, node: int, rings: int) -> list[int]:
    cur = {int(node)}
    for _ in range(rings):
        nxt = set(cur)
        for v in cur:
            nxt.update(adj.indices[adj.indptr[v]:adj.indptr[v + 1]].tolist())
        cur = nxt
    return sorted(cur)


BUILDERS = {"beam_pgd": build_beam_pgd, "beam_snapshots": build_beam_snapshots,
            "beam_contact_nipgd": build_beam_contact_nipgd, "joint_boot": build_joint_boot,
            "probe_nipgd": build_probe_nipgd}


def build_model(spec: ModelSpec, progress: Progress | None = None) -> ReducedModel:
    return BUILDERS[spec["kind"]](spec, progress)


def source_digest(root: Path, module: str) -> str:
    """Digest of the code of ``module`` and of every module of its package that it imports, transitively (also
    imports inside functions), found as files under ``root`` (the folder holding the package).

    Each file enters as its syntax tree without docstrings, so comments, docstrings and layout do not count and
    any change to what the code does does: a model built by older code is never taken for a current one, and
    editing the prose of ``rom`` / ``physics`` does not rebuild every cached model."""
    package = module.partition(".")[0]

    def file_of(name: str) -> Path | None:
        base = root.joinpath(*name.split("."))
        return next((f for f in (base.with_suffix(".py"), base / "__init__.py") if f.is_file()), None)

    trees: dict[str, str] = {}
    todo = [module]
    while todo:
        name = todo.pop()
        path = file_of(name)
        if name in trees or path is None:
            continue
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                todo += [node.module] + [f"{node.module}.{a.name}" for a in node.names]  # a name may be a module
            elif isinstance(node, ast.Import):
                todo += [a.name for a in node.names]
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body \
                    and isinstance(first := node.body[0], ast.Expr) and isinstance(first.value, ast.Constant) \
                    and isinstance(first.value.value, str):
                node.body = node.body[1:]
        todo = [t for t in todo if t.partition(".")[0] == package]
        trees[name] = ast.dump(tree)
    h = hashlib.sha256()
    for name in sorted(trees):
        h.update(f"{name}\n{trees[name]}\n".encode())
    return h.hexdigest()[:16]


@functools.cache
def builder_version() -> str:
    """The version of the model builders that a cached model must match (with its spec): the digest of this
    module's code and of the package code it uses (:func:`source_digest`; FEM, PGD, NI-PGD, the model file).

    Computed rather than a number bumped by hand: a forgotten bump is exactly how a stale model stays in use, and
    the cost, one rebuild after a change that did not alter the result, is paid once."""
    return source_digest(Path(__file__).resolve().parents[2], __name__)


def cache_dir() -> Path:
    return Path(os.environ.get("SIMREAL_CACHE", REPO / "cache")) / "models"


def _spec_file(spec_name: str) -> str:
    return spec_name if spec_name.endswith(".yaml") else spec_name + ".yaml"


def _cache_file(spec: ModelSpec) -> Path:
    return cache_dir() / f"{spec['name']}.h5"


def cached_model_path(spec_name: str) -> Path:
    """Where the model of a built-in (or given) spec lives in the cache, built or not.

    Reads and validates the spec (an unknown name raises SceneError listing the built-in specs) but builds
    nothing: scene validation maps ``spec:NAME`` with it, :func:`cached_model` builds the file there."""
    return _cache_file(load_spec(_spec_file(spec_name)))


def cached_model(spec_name: str, progress: Progress | None = None, rebuild: bool = False) -> Path:
    """Path of the model built from a built-in (or given) spec, building it once into the cache.

    The cached file is rebuilt when the spec text or the builders' code (:func:`builder_version`) changed since
    it was built.
    """
    from simreal_nodes.rom.model_file import load_model, save_model

    spec = load_spec(_spec_file(spec_name))
    out = _cache_file(spec)
    if out.exists() and not rebuild:
        try:
            prov = load_model(out, fields=[], mesh=False).provenance
            if prov.get("spec") == spec["_text"] and prov.get("builder") == builder_version():
                return out
        except Exception:  # noqa: BLE001 - a damaged cache entry is rebuilt
            pass
    model = build_model(spec, progress)
    save_model(model, out)
    return out
