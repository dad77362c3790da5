"""Steady incompressible flow past a body with OpenFOAM (blockMesh + snappyHexMesh + simpleFoam), sampled on a grid.

The thesis computed its database with commercial CFD (§6.2.3); we use OpenFOAM (Debian's ``openfoam``, ESI v1912):

* half domain, ``y >= 0``, with a symmetry plane at ``y = 0`` (the thesis exploits the cars' symmetry the same way);
  uniform inflow ``U`` at ``x_min``, zero pressure at ``x_max``, slip top and side;
* the ground ``z = 0`` is a wall moving with the flow (a car on a road seen from the car) or a slip plane (a body in
  free stream, the validation case);
* a hexahedral background mesh refined twice by boxes (the sampling grid's box, a box close to the body) and at the
  body's surface, then snapped to it (snappyHexMesh); no prism layers (at the thesis's Reynolds number, about 9000
  on the car's length, the boundary layer is some 0.2 m thick: several surface cells);
* steady SIMPLE (simpleFoam), second order (``linearUpwind``) convection, laminar or k-omega SST (wall functions on
  the body and the moving ground: ``kqRWallFunction``, ``omegaWallFunction``, ``nutkWallFunction``). SST's inflow:
  intensity 1 %, length scale ``turbulence_length`` x ``length``; with the defaults (0.1 x 4.5 m at Re 9000) the
  inflow's eddy viscosity is about 6 nu (k / omega), inside the 1-10 usually set for external flows but, at so low
  a Reynolds number, a free stream about 7 times as viscous as nu alone (``aero_validation`` measures the effect);
* the body's drag and lift coefficients from OpenFOAM's ``forceCoeffs`` and the velocity and pressure interpolated by
  OpenFOAM's own ``sets`` sampling (``cellPoint``) at the grid's points. A point that lies in the body is not in
  the mesh: its velocity is zero (no slip) and its pressure NaN.

A steady solution is what the thesis's interpolation needs (one field per car); at Re 9000 the true wake sheds
vortices (a laminar steady solve of a bluff body does not converge there: the cube in ``aero_validation``); each run
reports its final residuals and whether they met ``settings.residual``. Re 9000 at 10 m/s over 4.5 m means
nu = 0.005 m^2/s, some 330 times air's: the thesis's Reynolds number, not air at road speed. Nothing here is
imported by an online node (the database is offline).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes.errors import SimrealError

FOAM_DIR = Path(os.environ.get("SIMREAL_OPENFOAM_DIR", "/usr/share/openfoam"))


class CfdError(SimrealError):
    """OpenFOAM is missing, or a mesh or a solve failed; the message names the step and its log."""


@dataclass(frozen=True)
class CfdSettings:
    """One CFD run's physics and mesh. Defaults: the thesis's 10 m/s inflow at Re = 9000 on a 4.5 m car."""

    speed: float = 10.0  # m/s, along +x
    nu: float = 0.005  # m^2/s: Re = speed * 4.5 m / nu = 9000
    domain_min: tuple[float, float, float] = (-8.0, 0.0, 0.0)
    domain_max: tuple[float, float, float] = (20.0, 8.0, 8.0)
    background: float = 0.4  # m, background cell size
    box_level: int = 1  # refinement level in the sampling grid's box (background / 2**level)
    near_level: int = 2  # in the box close to the body
    surface_level: int = 3  # at the body's surface
    iterations: int = 800  # SIMPLE iterations at most
    residual: float = 1e-4  # initial residual of p and U at which the solve stops
    ground: str = "moving"  # "moving": a wall at the inflow speed; "slip": free stream
    turbulence: str = "laminar"  # or "kOmegaSST" (steady RANS, inflow intensity 1 %)
    length: float = 4.5  # m, reference length of the body
    turbulence_length: float = 0.1  # the inflow turbulence's length scale, a fraction of ``length``
    extra: dict[str, str] = field(default_factory=dict)  # not used by the writer; recorded with results

    def reynolds(self, length: float) -> float:
        return self.speed * length / self.nu


@dataclass
class CfdResult:
    """What one run produced, at the grid's points."""

    velocity: np.ndarray  # (n, 3) m/s; zero inside the body
    pressure: np.ndarray  # (n,) kinematic pressure p/rho, m^2/s^2; NaN inside the body
    in_fluid: np.ndarray  # (n,) bool: the point was in the mesh
    cd: float
    cl: float
    iterations: int
    residuals: dict[str, float]
    converged: bool
    n_cells: int
    seconds: float


def foam_env() -> dict[str, str]:
    """The environment OpenFOAM's programs need (what its ``etc/bashrc`` sets), read once from that script."""
    bashrc = FOAM_DIR / "etc" / "bashrc"
    if not bashrc.is_file() or shutil.which("simpleFoam") is None:
        raise CfdError(f"OpenFOAM not found (no {bashrc} or no simpleFoam on PATH); install Debian's openfoam "
                       "(./run setup does)")
    out = subprocess.run(["bash", "-c", f"source {bashrc} >/dev/null 2>&1; env -0"], capture_output=True,
                         check=True).stdout
    env = dict(item.split("=", 1) for item in out.decode().split("\0") if "=" in item)
    env["OMPI_MCA_plm"] = "isolated"  # serial runs; never look for other hosts
    # A Dask worker sets MALLOC_TRIM_THRESHOLD_=65536 for itself; inherited, it made simpleFoam return memory to
    # the kernel at every step and run half as fast (0.52 against 0.22 s an iteration on a car, measured).
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    return env


def openfoam_available() -> bool:
    try:
        foam_env()
    except (CfdError, subprocess.CalledProcessError):
        return False
    return True


# --- dictionaries --------------------------------------------------------------------------------------------------
def _header(cls: str, obj: str, location: str = "") -> str:
    loc = f'    location    "{location}";\n' if location else ""
    return ("FoamFile\n{\n    version     2.0;\n    format      ascii;\n"
            f"    class       {cls};\n{loc}    object      {obj};\n}}\n\n")


def _vec(v: np.ndarray | tuple[float, ...] | list[float]) -> str:
    return "(" + " ".join(f"{float(c):.9g}" for c in v) + ")"


def write_case(case: str | Path, vertices: np.ndarray, faces: np.ndarray, points: np.ndarray,
               settings: CfdSettings, near_box: tuple[np.ndarray, np.ndarray], grid_box: tuple[np.ndarray, np.ndarray],
               ref_area: float, ref_length: float) -> Path:
    """Write a complete case: the body as ``constant/triSurface/body.stl``, the mesh, the flow and the sampling.

    ``points``: where the fields are sampled (n, 3). ``ref_area``: the half body's frontal area (the half domain
    carries half the force). ``near_box`` and ``grid_box`` are (min, max) corners of the two refinement boxes."""
    from simreal_nodes.aero.cars import write_stl

    case = Path(case)
    if case.exists():
        shutil.rmtree(case)
    for d in ("system", "constant/triSurface", "0"):
        (case / d).mkdir(parents=True)
    write_stl(case / "constant/triSurface/body.stl", vertices, faces, solid="body")
    s = settings
    lo, hi = np.asarray(s.domain_min, float), np.asarray(s.domain_max, float)
    n = np.maximum(np.round((hi - lo) / s.background).astype(int), 1)
    v = [(lo[0], lo[1], lo[2]), (hi[0], lo[1], lo[2]), (hi[0], hi[1], lo[2]), (lo[0], hi[1], lo[2]),
         (lo[0], lo[1], hi[2]), (hi[0], lo[1], hi[2]), (hi[0], hi[1], hi[2]), (lo[0], hi[1], hi[2])]
    ground_type = "wall" if s.ground == "moving" else "patch"
    (case / "system/blockMeshDict").write_text(
        _header("dictionary", "blockMeshDict") + "scale 1;\nvertices\n(\n" + "".join(f"    {_vec(p)}\n" for p in v)
        + ");\nblocks\n(\n    hex (0 1 2 3 4 5 6 7) " + f"({n[0]} {n[1]} {n[2]}) simpleGrading (1 1 1)\n);\n"
        "edges ();\nboundary\n(\n"
        "    inlet { type patch; faces ((0 4 7 3)); }\n"
        "    outlet { type patch; faces ((1 2 6 5)); }\n"
        "    symmetry { type symmetryPlane; faces ((0 1 5 4)); }\n"
        "    side { type patch; faces ((3 7 6 2)); }\n"
        "    top { type patch; faces ((4 5 6 7)); }\n"
        f"    ground {{ type {ground_type}; faces ((0 3 2 1)); }}\n);\n")
    inside_pt = lo + np.array([0.13, 0.77, 0.71]) * (hi - lo) + 1e-3  # upstream of nothing, above everything
    (case / "system/snappyHexMeshDict").write_text(
        _header("dictionary", "snappyHexMeshDict")
        + "castellatedMesh true;\nsnap true;\naddLayers false;\n"
        "geometry\n{\n    body.stl { type triSurfaceMesh; name body; }\n"
        f"    gridBox {{ type searchableBox; min {_vec(grid_box[0])}; max {_vec(grid_box[1])}; }}\n"
        f"    nearBox {{ type searchableBox; min {_vec(near_box[0])}; max {_vec(near_box[1])}; }}\n}}\n"
        "castellatedMeshControls\n{\n    maxLocalCells 2000000;\n    maxGlobalCells 4000000;\n"
        "    minRefinementCells 0;\n    maxLoadUnbalance 0.1;\n    nCellsBetweenLevels 2;\n    features ();\n"
        f"    refinementSurfaces {{ body {{ level ({s.surface_level} {s.surface_level}); "
        "patchInfo { type wall; } } }\n"
        "    resolveFeatureAngle 30;\n"
        f"    refinementRegions {{ gridBox {{ mode inside; levels ((1e15 {s.box_level})); }}\n"
        f"        nearBox {{ mode inside; levels ((1e15 {s.near_level})); }} }}\n"
        f"    locationInMesh {_vec(inside_pt)};\n    allowFreeStandingZoneFaces true;\n}}\n"
        "snapControls\n{\n    nSmoothPatch 3;\n    tolerance 2.0;\n    nSolveIter 50;\n    nRelaxIter 5;\n"
        "    nFeatureSnapIter 10;\n    implicitFeatureSnap true;\n    explicitFeatureSnap false;\n"
        "    multiRegionFeatureSnap false;\n}\n"
        "addLayersControls\n{\n    relativeSizes true;\n    layers {}\n    expansionRatio 1.0;\n"
        "    finalLayerThickness 0.3;\n    minThickness 0.1;\n    nGrow 0;\n    featureAngle 60;\n"
        "    nRelaxIter 3;\n    nSmoothSurfaceNormals 1;\n    nSmoothNormals 3;\n    nSmoothThickness 10;\n"
        "    maxFaceThicknessRatio 0.5;\n    maxThicknessToMedialRatio 0.3;\n    minMedialAxisAngle 90;\n"
        "    nBufferCellsNoExtrude 0;\n    nLayerIter 50;\n}\n"
        "meshQualityControls\n{\n    #includeEtc \"caseDicts/meshQualityDict\"\n    nSmoothScale 4;\n"
        "    errorReduction 0.75;\n}\nmergeTolerance 1e-6;\n")
    (case / "system/controlDict").write_text(
        _header("dictionary", "controlDict")
        + f"application simpleFoam;\nstartFrom startTime;\nstartTime 0;\nstopAt endTime;\nendTime {s.iterations};\n"
        "deltaT 1;\nwriteControl timeStep;\n" + f"writeInterval {s.iterations};\n"
        "purgeWrite 1;\nwriteFormat ascii;\nwritePrecision 8;\nwriteCompression off;\ntimeFormat general;\n"
        "timePrecision 6;\nrunTimeModifiable false;\n"
        "functions\n{\n"
        "    coeffs\n    {\n        type forceCoeffs;\n        libs (forces);\n        writeControl timeStep;\n"
        "        writeInterval 1;\n        log false;\n        patches (body);\n        rho rhoInf;\n"
        f"        rhoInf 1;\n        liftDir (0 0 1);\n        dragDir (1 0 0);\n        CofR (0 0 0);\n"
        f"        pitchAxis (0 1 0);\n        magUInf {s.speed:.9g};\n        lRef {ref_length:.9g};\n"
        f"        Aref {ref_area:.9g};\n    }}\n"
        "    grid\n    {\n        type sets;\n        libs (sampling);\n        writeControl writeTime;\n"
        "        interpolationScheme cellPoint;\n        setFormat raw;\n        fields (U p);\n"
        "        sets\n        (\n            points\n            {\n                type cloud;\n"
        "                axis xyz;\n                points #include \"gridPoints\";\n            }\n        );\n"
        "    }\n}\n")
    pts = np.asarray(points, float).reshape(-1, 3)
    (case / "system/gridPoints").write_text("(\n" + "\n".join(f"({p[0]:.9g} {p[1]:.9g} {p[2]:.9g})" for p in pts)
                                            + "\n)\n")
    (case / "system/fvSchemes").write_text(
        _header("dictionary", "fvSchemes")
        + "ddtSchemes { default steadyState; }\n"
        "gradSchemes { default Gauss linear; grad(U) cellLimited Gauss linear 1; }\n"
        "divSchemes\n{\n    default none;\n    div(phi,U) bounded Gauss linearUpwindV grad(U);\n"
        "    div(phi,k) bounded Gauss upwind;\n    div(phi,omega) bounded Gauss upwind;\n"
        "    div((nuEff*dev2(T(grad(U))))) Gauss linear;\n}\n"
        "wallDist { method meshWave; }\n"
        "laplacianSchemes { default Gauss linear limited corrected 0.5; }\n"
        "interpolationSchemes { default linear; }\nsnGradSchemes { default limited corrected 0.5; }\n")
    (case / "system/fvSolution").write_text(
        _header("dictionary", "fvSolution")
        + "solvers\n{\n    p { solver GAMG; smoother GaussSeidel; tolerance 1e-7; relTol 0.05; }\n"
        "    \"(U|k|omega)\" { solver smoothSolver; smoother GaussSeidel; tolerance 1e-8; relTol 0.1; nSweeps 1; }\n}\n"
        "SIMPLE\n{\n    nNonOrthogonalCorrectors 1;\n    consistent yes;\n"
        f"    residualControl {{ p {s.residual:g}; U {s.residual:g}; }}\n}}\n"
        "relaxationFactors { equations { U 0.7; k 0.7; omega 0.7; } fields { p 1; } }\n")
    (case / "constant/transportProperties").write_text(
        _header("dictionary", "transportProperties") + f"transportModel Newtonian;\nnu {s.nu:.9g};\n")
    if s.turbulence == "laminar":
        model = "simulationType laminar;\n"
    elif s.turbulence == "kOmegaSST":
        model = "simulationType RAS;\nRAS { RASModel kOmegaSST; turbulence on; printCoeffs off; }\n"
        k = 1.5 * (0.01 * s.speed) ** 2
        omega = k ** 0.5 / (0.09 ** 0.25 * s.turbulence_length * s.length)
        for name, dim, val, wall in (("k", "[0 2 -2 0 0 0 0]", k, "kqRWallFunction"),
                                     ("omega", "[0 0 -1 0 0 0 0]", omega, "omegaWallFunction"),
                                     ("nut", "[0 2 -1 0 0 0 0]", 0.0, "nutkWallFunction")):
            inlet = (f"type fixedValue; value uniform {val:.9g};" if name != "nut"
                     else "type calculated; value uniform 0;")
            outlet = (f"type inletOutlet; inletValue uniform {val:.9g}; value uniform {val:.9g};" if name != "nut"
                      else "type calculated; value uniform 0;")
            ground = f"type {wall}; value uniform {val:.9g};" if s.ground == "moving" else "type slip;"
            (case / f"0/{name}").write_text(
                _header("volScalarField", name, "0") + f"dimensions {dim};\ninternalField uniform {val:.9g};\n"
                "boundaryField\n{\n"
                f"    inlet {{ {inlet} }}\n    outlet {{ {outlet} }}\n    symmetry {{ type symmetryPlane; }}\n"
                "    side { type slip; }\n    top { type slip; }\n"
                f"    ground {{ {ground} }}\n    body {{ type {wall}; value uniform {val:.9g}; }}\n}}\n")
    else:
        raise ValueError(f"unknown turbulence model {s.turbulence!r}: laminar or kOmegaSST")
    (case / "constant/turbulenceProperties").write_text(_header("dictionary", "turbulenceProperties") + model)
    u = _vec((s.speed, 0.0, 0.0))
    ground_u = f"type movingWallVelocity; value uniform {u};" if s.ground == "moving" else "type slip;"
    (case / "0/U").write_text(
        _header("volVectorField", "U", "0") + f"dimensions [0 1 -1 0 0 0 0];\ninternalField uniform {u};\n"
        "boundaryField\n{\n"
        f"    inlet {{ type fixedValue; value uniform {u}; }}\n"
        "    outlet { type inletOutlet; inletValue uniform (0 0 0); value uniform (0 0 0); }\n"
        "    symmetry { type symmetryPlane; }\n    side { type slip; }\n    top { type slip; }\n"
        f"    ground {{ {ground_u} }}\n    body {{ type noSlip; }}\n}}\n")
    (case / "0/p").write_text(
        _header("volScalarField", "p", "0") + "dimensions [0 2 -2 0 0 0 0];\ninternalField uniform 0;\n"
        "boundaryField\n{\n    inlet { type zeroGradient; }\n    outlet { type fixedValue; value uniform 0; }\n"
        "    symmetry { type symmetryPlane; }\n    side { type slip; }\n    top { type slip; }\n"
        "    ground { type zeroGradient; }\n    body { type zeroGradient; }\n}\n")
    return case


# --- running -------------------------------------------------------------------------------------------------------
def _run(case: Path, env: dict[str, str], *cmd: str) -> str:
    log = case / f"log.{cmd[0]}"
    with open(log, "w") as fh:
        rc = subprocess.run(list(cmd), cwd=case, env=env, stdout=fh, stderr=subprocess.STDOUT).returncode
    text = log.read_text(errors="replace")
    if rc != 0 or "FOAM FATAL" in text:
        tail = "\n".join(text.strip().splitlines()[-15:])
        raise CfdError(f"{cmd[0]} failed in {case} (exit {rc}); the end of {log.name}:\n{tail}")
    return text


def run_case(case: str | Path, points: np.ndarray, settings: CfdSettings) -> CfdResult:
    """Mesh and solve a case written by :func:`write_case`, and read its results at ``points``."""
    case = Path(case)
    env = foam_env()
    t0 = time.perf_counter()
    _run(case, env, "blockMesh")
    _run(case, env, "snappyHexMesh", "-overwrite")
    check = _run(case, env, "checkMesh", "-constant")
    m = re.search(r"cells:\s+(\d+)", check)
    n_cells = int(m.group(1)) if m else -1
    log = _run(case, env, "simpleFoam")
    seconds = time.perf_counter() - t0
    iters = [int(t) for t in re.findall(r"^Time = (\d+)\s*$", log, flags=re.M)]
    residuals: dict[str, float] = {}
    for name in ("Ux", "Uy", "Uz", "p"):
        found = re.findall(rf"Solving for {name}, Initial residual = ([0-9.eE+-]+)", log)
        if found:
            residuals[name] = float(found[-1])
    converged = "SIMPLE solution converged" in log
    cd, cl = _read_coeffs(case)
    velocity, pressure, in_fluid = _read_sets(case, points)
    return CfdResult(velocity=velocity, pressure=pressure, in_fluid=in_fluid, cd=cd, cl=cl,
                     iterations=max(iters) if iters else 0, residuals=residuals, converged=converged,
                     n_cells=n_cells, seconds=seconds)


def _read_coeffs(case: Path) -> tuple[float, float]:
    files = sorted(case.glob("postProcessing/coeffs/*/coefficient*.dat")) + \
        sorted(case.glob("postProcessing/coeffs/*/forceCoeffs*.dat"))
    if not files:
        raise CfdError(f"no force coefficients written in {case}/postProcessing/coeffs")
    header: list[str] = []
    last: list[str] = []
    for line in files[-1].read_text().splitlines():
        if line.startswith("#"):
            cols = line.lstrip("#").split()
            if cols and cols[0] == "Time":
                header = cols
        elif line.strip():
            last = line.split()
    if not header or not last:
        raise CfdError(f"unreadable force coefficients in {files[-1]}")
    row = dict(zip(header, (float(v) for v in last)))
    if "Cd" not in row or not np.isfinite(row["Cd"]):
        raise CfdError(f"no finite drag coefficient in {files[-1]} (columns {header}): did the body patch get faces?")
    return row["Cd"], row.get("Cl", float("nan"))


def _read_sets(case: Path, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pts = np.asarray(points, float).reshape(-1, 3)
    dirs = sorted(case.glob("postProcessing/grid/*"), key=lambda p: float(p.name))
    if not dirs:
        raise CfdError(f"no sampled fields in {case}/postProcessing/grid")
    d = dirs[-1]
    fu = list(d.glob("points*U*.xy"))
    fp = list(d.glob("points*p*.xy"))
    if not fu or not fp:
        raise CfdError(f"sampled U or p missing in {d}")
    if fu[0] == fp[0]:  # one file with every field: x y z p Ux Uy Uz (scalars first)
        a = np.loadtxt(fu[0], ndmin=2)
        xyz, pv, uv = a[:, :3], a[:, 3], a[:, 4:7]
        xyz_p = xyz
    else:
        a = np.loadtxt(fu[0], ndmin=2)
        b = np.loadtxt(fp[0], ndmin=2)
        xyz, uv, xyz_p, pv = a[:, :3], a[:, 3:6], b[:, :3], b[:, 3]
    velocity = np.zeros((len(pts), 3))
    pressure = np.full(len(pts), np.nan)
    in_fluid = np.zeros(len(pts), bool)
    tree = cKDTree(pts)
    dist, idx = (np.asarray(a) for a in tree.query(xyz))
    ok = dist < 1e-5
    velocity[idx[ok]] = uv[ok]
    in_fluid[idx[ok]] = True
    dist, idx = (np.asarray(a) for a in tree.query(xyz_p))
    ok = dist < 1e-5
    pressure[idx[ok]] = pv[ok]
    return velocity, pressure, in_fluid
