"""The CFD database of car flows (thesis §6.2.3): a spec, a resumable sweep over Dask, a versioned HDF5 file.

``simreal build-aero-db SPEC -o DB.h5`` draws the spec's cars (:mod:`simreal_nodes.aero.cars`), solves each with
OpenFOAM (:mod:`simreal_nodes.aero.openfoam`) as one Dask task (a local cluster by default; ``--scheduler ADDRESS``
spreads the tasks over a distributed cluster's machines), keeps each car's result in the work folder as soon as it
is done (a rerun skips it: the sweep resumes), and writes the database:

Layout (format ``simreal-aero-db``, version 1)::

    /                   attrs: format, format_version, name, created, simreal_version, spec (JSON), grid (JSON),
                        cfd (JSON)
    /cars               attrs: list (JSON: every car's parameters, database then held-out)
    /held_out           (n_cars,) uint8: 1 for the cars kept out of the manifold (truth for the error analysis)
    /presence           (n_cars, D) uint8: Eq. 6.1 on the grid
    /in_fluid           (n_cars, D) uint8: the grid point was in the CFD mesh
    /velocity/mean      (3 D,) float32;  /velocity/modes (r, 3 D) float32;  /velocity/coeffs (n_database, r)
    /velocity/held_out_raw   (n_held_out, 3 D) float32: the held-out cars' fields as solved (no POD)
    /pressure/...       the same for the kinematic pressure (0 inside the body)
    /cd, /cl, /iterations, /converged, /cells, /seconds     per car

The database cars' fields are stored as their POD (thin SVD of the centred snapshots of the database cars only),
truncated where the relative Frobenius error of the centred snapshots (the car-to-car variation) falls under
``pod_tolerance`` (the spec's); the achieved errors, of the variation and of the whole fields, are in the file's
attributes. The held-out cars' fields are stored as solved. Like model files, the first 512 bytes hold the SHA-256
of the rest, checked before libhdf5 reads (a file without it is refused). Nothing online runs CFD: the online side
only loads this file.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import yaml

from simreal_nodes import __version__
from simreal_nodes.aero.cars import GROUPS, CarShape, car_family, car_from_dict, sample_car
from simreal_nodes.aero.grid import AeroGrid
from simreal_nodes.aero.openfoam import CfdError, CfdSettings, run_case, write_case
from simreal_nodes.errors import ModelFileError
from simreal_nodes.rom.model_file import USERBLOCK, stamp_checksum, verify_checksum

FORMAT = "simreal-aero-db"
FORMAT_VERSION = 1
SPEC_DIR = Path(__file__).resolve().parent.parent / "specs"
MAX_POINTS = 50_000_000  # a grid over this many points is refused before anything is allocated


@dataclass
class AeroSpec:
    name: str
    description: str
    seed: int
    per_group: int
    held_out_seed: int
    held_out_groups: tuple[str, ...]
    grid: AeroGrid
    cfd: CfdSettings
    pod_tolerance: float = 1e-3
    raw: dict[str, Any] = field(default_factory=dict)

    def cars(self) -> list[CarShape]:
        """The database's cars, then the held-out ones (drawn from their own seed, never from the database's)."""
        rng = np.random.default_rng(self.held_out_seed)
        held = [sample_car(g, rng, f"heldout_{g}_{k:02d}") for k, g in enumerate(self.held_out_groups)]
        return car_family(self.per_group, self.seed) + held

    @property
    def n_database(self) -> int:
        return self.per_group * len(GROUPS)


def load_aero_spec(path_or_name: str | Path) -> AeroSpec:
    """A YAML spec (path, or the name of one in ``simreal_nodes/specs``); every key is checked."""
    p = Path(path_or_name)
    if not p.is_file() and (SPEC_DIR / p.name).is_file():
        p = SPEC_DIR / p.name
    try:
        raw = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"cannot read aero spec {path_or_name}: {exc}") from exc
    if not isinstance(raw, dict):
        raise ValueError(f"aero spec {p}: expected a mapping at the top")
    known = {"name", "description", "cars", "held_out", "grid", "cfd", "pod_tolerance"}
    unknown = set(raw) - known
    if unknown:
        raise ValueError(f"aero spec {p}: unknown keys {sorted(unknown)}; expected {sorted(known)}")
    try:
        cars, held = raw.get("cars", {}), raw.get("held_out", {})
        g = raw.get("grid", {})
        grid = AeroGrid(lo=tuple(float(v) for v in g.get("lo", (-4.0, 0.0, 0.0))),  # type: ignore[arg-type]
                        hi=tuple(float(v) for v in g.get("hi", (10.0, 5.0, 4.0))),  # type: ignore[arg-type]
                        shape=tuple(int(v) for v in g.get("shape", (140, 40, 20))))  # type: ignore[arg-type]
        cfd_keys = {f for f in CfdSettings.__dataclass_fields__ if f != "extra"}
        c = raw.get("cfd", {}) or {}
        bad = set(c) - cfd_keys
        if bad:
            raise ValueError(f"unknown cfd keys {sorted(bad)}; expected {sorted(cfd_keys)}")
        c = {k: tuple(v) if isinstance(v, list) else v for k, v in c.items()}
        spec = AeroSpec(name=str(raw.get("name", p.stem)), description=str(raw.get("description", "")),
                        seed=int(cars.get("seed", 0)), per_group=int(cars.get("per_group", 20)),
                        held_out_seed=int(held.get("seed", 1000)),
                        held_out_groups=tuple(str(x) for x in held.get("groups", ())),
                        grid=grid, cfd=CfdSettings(**c), pod_tolerance=float(raw.get("pod_tolerance", 1e-3)), raw=raw)
    except (TypeError, AttributeError) as exc:
        raise ValueError(f"aero spec {p}: {exc}") from exc
    if grid.size > MAX_POINTS:
        raise ValueError(f"aero spec {p}: a grid of {grid.size} points is over the limit of {MAX_POINTS}")
    if spec.per_group < 1 or any(gr not in GROUPS for gr in spec.held_out_groups):
        raise ValueError(f"aero spec {p}: per_group >= 1 and held-out groups among {GROUPS}")
    if spec.cfd.turbulence not in ("laminar", "kOmegaSST") or spec.cfd.ground not in ("moving", "slip"):
        raise ValueError(f"aero spec {p}: cfd.turbulence laminar|kOmegaSST, cfd.ground moving|slip")
    c = spec.cfd
    if len(c.domain_min) != 3 or len(c.domain_max) != 3:
        raise ValueError(f"aero spec {p}: cfd.domain_min and domain_max take three numbers")
    positive = {"speed": c.speed, "nu": c.nu, "background": c.background, "iterations": c.iterations,
                "residual": c.residual, "length": c.length, "turbulence_length": c.turbulence_length}
    bad_values = [k for k, v in positive.items() if not (np.isfinite(v) and v > 0)]
    if bad_values:
        raise ValueError(f"aero spec {p}: cfd.{', cfd.'.join(bad_values)} must be positive")
    lo, hi = np.asarray(c.domain_min, float), np.asarray(c.domain_max, float)
    if np.any(np.asarray(grid.lo) < lo) or np.any(np.asarray(grid.hi) > hi):
        raise ValueError(f"aero spec {p}: the grid {grid.lo}..{grid.hi} must lie inside the CFD domain "
                         f"{c.domain_min}..{c.domain_max} (a point outside it would read as solid)")
    if spec.held_out_groups and spec.held_out_seed == spec.seed:
        raise ValueError(f"aero spec {p}: held_out.seed equals cars.seed: the held-out cars would be database cars")
    return spec


# --- one car ------------------------------------------------------------------------------------------------------
RESULT_KEYS = ("velocity", "pressure", "in_fluid", "presence", "cd", "cl", "iterations", "converged", "cells",
               "seconds", "residuals", "key")


def result_key(car: dict[str, Any], cfd: dict[str, Any], grid: dict[str, Any]) -> str:
    """What one result depends on (the car, the CFD settings, the grid), hashed: a result is reused only when this
    matches (a changed seed, setting or grid in the same work folder solves again)."""
    blob = json.dumps({"car": car, "cfd": {k: v for k, v in cfd.items() if k != "extra"}, "grid": grid},
                      sort_keys=True, default=list)
    return hashlib.sha256(blob.encode()).hexdigest()


def _result_matches(path: Path, key: str) -> bool:
    try:
        with np.load(path, allow_pickle=False) as z:
            return all(k in z for k in RESULT_KEYS) and str(z["key"]) == key
    except (OSError, ValueError, KeyError):
        return False


def solve_car(car: dict[str, Any], cfd: dict[str, Any], grid: dict[str, Any], work: str,
              keep_case: bool = False) -> str:
    """One database entry: mesh and solve the car, sample on the grid, save ``<work>/<name>.npz``. Returns the path.
    A result already there is kept (the sweep resumes). The case folder is removed after (``keep_case`` keeps it)."""
    shape = car_from_dict(car)
    out = Path(work) / f"{shape.name}.npz"
    key = result_key(car, cfd, grid)
    if out.is_file() and _result_matches(out, key):
        return str(out)
    kw: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in cfd.items()}
    settings = CfdSettings(**kw)
    g = AeroGrid(lo=tuple(grid["lo"]), hi=tuple(grid["hi"]), shape=tuple(grid["shape"]))
    pts = g.points()
    v, f = shape.surface()
    near = (np.array([-1.0, 0.0, 0.0]), np.array([shape.length + 3.0, 0.5 * shape.width + 1.0, shape.height + 1.0]))
    case = Path(work) / f"case_{shape.name}"
    write_case(case, v, f, pts, settings, near, (np.asarray(g.lo), np.asarray(g.hi)),
               ref_area=0.5 * shape.frontal_area(), ref_length=shape.length)
    r = run_case(case, pts, settings)
    tmp = out.with_suffix(f".{os.getpid()}.partial.npz")
    np.savez_compressed(tmp, velocity=r.velocity.astype(np.float32), pressure=r.pressure.astype(np.float32),
                        in_fluid=r.in_fluid, presence=g.presence(shape).astype(np.uint8), cd=r.cd, cl=r.cl,
                        iterations=r.iterations, converged=r.converged, cells=r.n_cells, seconds=r.seconds,
                        residuals=json.dumps(r.residuals), key=key)
    tmp.replace(out)
    if not keep_case:
        for d in case.iterdir():
            if d.is_dir():
                shutil.rmtree(d, ignore_errors=True)
    return str(out)


# --- the sweep ----------------------------------------------------------------------------------------------------
def run_sweep(spec: AeroSpec, work: str | Path, jobs: int = 2, scheduler: str | None = None,
              report: Callable[[int, int, str, str], None] | None = None) -> list[Path]:
    """Solve every car of ``spec`` not yet in ``work``, ``jobs`` at a time on a local Dask cluster (or on the
    cluster at ``scheduler``; its workers must see ``work`` at the same path: a shared file system).
    ``report(done, total, name, line)`` is called as each car ends. A failed car is reported and left out; the
    others go on."""
    from dask.distributed import Client, LocalCluster, as_completed

    work = Path(work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    cars = spec.cars()
    cfd = asdict(spec.cfd)
    cfd.pop("extra", None)
    grid = spec.grid.to_dict()
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        # loopback only, and no fixed port (two sweeps, or a sweep and a test, may run at once)
        cluster = LocalCluster(n_workers=max(1, jobs), threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0")
        client = Client(cluster)
    try:
        futures = {client.submit(solve_car, c.to_dict(), cfd, grid, str(work), key=f"car-{spec.name}-{c.name}",
                                 pure=False): c.name for c in cars}
        done: list[Path] = []
        for k, fut in enumerate(as_completed(futures), 1):
            name = futures[fut]
            try:
                path = Path(fut.result())
                done.append(path)
                with np.load(path, allow_pickle=False) as z:
                    line = (f"Cd {float(z['cd']):.3f}, {int(z['iterations'])} iterations, "
                            f"{'converged' if bool(z['converged']) else 'NOT converged'}, {int(z['cells'])} cells, "
                            f"{float(z['seconds']):.0f} s")
            except Exception as exc:  # noqa: BLE001 -- one car's failure (a solver, a killed worker) is reported
                line = f"FAILED: {type(exc).__name__}: {exc}"
            if report:
                report(k, len(cars), name, line)
        return done
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _pod(snapshots: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Mean, modes (r, n) and coefficients (m, r) of the centred snapshots (m, n), truncated where the relative
    Frobenius error of the *centred* snapshots (the car-to-car variation Eq. 6.4 interpolates, not the free stream
    every car shares) falls under ``tol``. Returns also the achieved errors, of the centred and of the whole
    snapshots."""
    mean = snapshots.mean(axis=0)
    X = snapshots - mean
    U, s, Vt = np.linalg.svd(X, full_matrices=False)
    varied = float(np.sum(s ** 2))
    tail = np.concatenate([np.cumsum((s ** 2)[::-1])[::-1][1:], [0.0]])  # energy left out after keeping r+1 modes
    err = np.sqrt(tail / max(varied, 1e-300))
    r = int(np.argmax(err <= tol)) + 1 if np.any(err <= tol) else len(s)
    whole = float(np.sqrt(tail[r - 1] / max(float(np.sum(snapshots ** 2)), 1e-300)))
    return mean, Vt[:r], U[:, :r] * s[:r], float(err[r - 1]), whole


def assemble(spec: AeroSpec, work: str | Path, out: str | Path) -> Path:
    """Write the database file from the sweep's results (every car of the spec must be there)."""
    work, out = Path(work), Path(out)
    cars = spec.cars()
    cfd = asdict(spec.cfd)
    cfd.pop("extra", None)
    grid = spec.grid.to_dict()
    missing = [c.name for c in cars if not _result_matches(work / f"{c.name}.npz", result_key(c.to_dict(), cfd, grid))]
    if missing:
        raise CfdError(f"{len(missing)} cars have no CFD result for this spec in {work}: {', '.join(missing[:8])}"
                       f"{' ...' if len(missing) > 8 else ''}; rerun the sweep (it resumes)")
    D = spec.grid.size
    vel = np.zeros((len(cars), 3 * D), np.float64)
    pre = np.zeros((len(cars), D), np.float64)
    presence = np.zeros((len(cars), D), np.uint8)
    in_fluid = np.zeros((len(cars), D), np.uint8)
    scal: dict[str, list[float]] = {k: [] for k in ("cd", "cl", "iterations", "converged", "cells", "seconds")}
    for i, c in enumerate(cars):
        with np.load(work / f"{c.name}.npz", allow_pickle=False) as z:
            if z["velocity"].shape != (D, 3):
                raise CfdError(f"{c.name}: result on another grid ({z['velocity'].shape[0]} points, spec {D})")
            vel[i] = z["velocity"].ravel()
            pre[i] = np.nan_to_num(z["pressure"], nan=0.0)
            presence[i], in_fluid[i] = z["presence"], z["in_fluid"]
            for k in scal:
                scal[k].append(float(z[k]))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(f"{out.suffix}.{os.getpid()}.partial")
    with h5py.File(tmp, "w", userblock_size=USERBLOCK) as f:
        f.attrs.update(format=FORMAT, format_version=FORMAT_VERSION, name=spec.name, description=spec.description,
                       created=time.strftime("%Y-%m-%dT%H:%M:%S%z"), simreal_version=__version__,
                       spec=json.dumps(spec.raw), grid=json.dumps(spec.grid.to_dict()), cfd=json.dumps(cfd))
        g = f.create_group("cars")
        g.attrs["list"] = json.dumps([c.to_dict() for c in cars])
        held = np.array([i >= spec.n_database for i in range(len(cars))], np.uint8)
        f.create_dataset("held_out", data=held)
        kw: dict[str, Any] = {"compression": "gzip", "fletcher32": True}
        f.create_dataset("presence", data=presence, chunks=(1, D), **kw)
        f.create_dataset("in_fluid", data=in_fluid, chunks=(1, D), **kw)
        dbi = held == 0
        for name, X in (("velocity", vel), ("pressure", pre)):
            # the POD of the database's cars only: a held-out car shapes nothing stored for the others
            mean, modes, coeffs, err, whole = _pod(X[dbi], spec.pod_tolerance)
            h = f.create_group(name)
            h.attrs["pod_error"] = err
            h.attrs["pod_error_whole"] = whole
            h.create_dataset("mean", data=mean.astype(np.float32), **kw)
            h.create_dataset("modes", data=modes.astype(np.float32), chunks=(1, modes.shape[1]), **kw)
            h.create_dataset("coeffs", data=coeffs, **kw)
            h.create_dataset("held_out_raw", data=X[~dbi].astype(np.float32), **kw)  # the truth, not truncated
        for k, vals in scal.items():
            f.create_dataset(k, data=np.asarray(vals))
    stamp_checksum(tmp)
    tmp.replace(out)
    return out


# --- reading ------------------------------------------------------------------------------------------------------
@dataclass
class AeroDatabase:
    """A loaded database: every car's presence vector and fields (reconstructed from the POD)."""

    name: str
    grid: AeroGrid
    cfd: dict[str, Any]
    cars: list[CarShape]
    held_out: np.ndarray  # (n,) bool
    presence: np.ndarray  # (n, D) float64
    in_fluid: np.ndarray  # (n, D) bool
    velocity: np.ndarray  # (n, D, 3) float32
    pressure: np.ndarray  # (n, D) float32
    cd: np.ndarray
    cl: np.ndarray
    converged: np.ndarray
    pod_error: dict[str, float]

    @property
    def database(self) -> np.ndarray:
        return np.flatnonzero(~self.held_out)

    @property
    def held(self) -> np.ndarray:
        return np.flatnonzero(self.held_out)


def load_database(path: str | Path) -> AeroDatabase:
    """Read and check a database file; :class:`ModelFileError` with the reason for anything wrong."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such aero database")
    if not verify_checksum(path):
        raise ModelFileError(f"{path}: no checksum user block (every {FORMAT} file carries one): not a database "
                             "written by simreal build-aero-db, or its first bytes were overwritten")
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != FORMAT:
                raise ModelFileError(f"{path}: not a {FORMAT} file (format {f.attrs.get('format')!r})")
            if int(f.attrs.get("format_version", -1)) != FORMAT_VERSION:
                raise ModelFileError(f"{path}: {FORMAT} version {f.attrs.get('format_version')}, this reader knows "
                                     f"{FORMAT_VERSION}")
            gd = json.loads(f.attrs["grid"])
            grid = AeroGrid(lo=tuple(gd["lo"]), hi=tuple(gd["hi"]), shape=tuple(gd["shape"]))
            if grid.size > MAX_POINTS:
                raise ModelFileError(f"{path}: declares a grid of {grid.size} points (limit {MAX_POINTS})")
            cars = [car_from_dict(c) for c in json.loads(f["cars"].attrs["list"])]
            n, D = len(cars), grid.size
            expect = {"held_out": (n,), "presence": (n, D), "in_fluid": (n, D), "velocity/mean": (3 * D,),
                      "pressure/mean": (D,), "cd": (n,), "cl": (n,), "converged": (n,)}
            for key, shp in expect.items():
                if f[key].shape != shp:
                    raise ModelFileError(f"{path}: {key} has shape {f[key].shape}, expected {shp}")
            fields = {}
            pod_error = {}
            held = f["held_out"][()].astype(bool)
            n_db = int((~held).sum())
            for name, width in (("velocity", 3 * D), ("pressure", D)):
                modes, coeffs, raw = f[f"{name}/modes"], f[f"{name}/coeffs"], f[f"{name}/held_out_raw"]
                r = modes.shape[0]
                if modes.shape != (r, width) or coeffs.shape != (n_db, r) or raw.shape != (n - n_db, width):
                    raise ModelFileError(f"{path}: {name} of shapes {modes.shape}, {coeffs.shape}, {raw.shape}")
                full = np.empty((n, width), np.float32)
                full[~held] = f[f"{name}/mean"][()] + coeffs[()] @ modes[()]
                full[held] = raw[()]
                fields[name] = full
                pod_error[name] = float(f[name].attrs.get("pod_error", np.nan))
                pod_error[f"{name}_whole"] = float(f[name].attrs.get("pod_error_whole", np.nan))
            db = AeroDatabase(name=str(f.attrs["name"]), grid=grid, cfd=json.loads(f.attrs["cfd"]), cars=cars,
                              held_out=held, presence=f["presence"][()].astype(np.float64),
                              in_fluid=f["in_fluid"][()].astype(bool), velocity=fields["velocity"].reshape(n, D, 3),
                              pressure=fields["pressure"], cd=f["cd"][()], cl=f["cl"][()],
                              converged=f["converged"][()].astype(bool), pod_error=pod_error)
    except ModelFileError:
        raise
    except (OSError, KeyError, ValueError, TypeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"{path}: unreadable aero database ({type(exc).__name__}: {exc})") from exc
    return db
