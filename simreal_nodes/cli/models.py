"""Model commands: build-model (spec -> reduced-order model file) and model-info (summary of a model file)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from simreal_nodes.cli.progress import TqdmProgress


def cmd_build_model(a: argparse.Namespace) -> int:
    from simreal_nodes.rom.build import build_model, load_spec
    from simreal_nodes.rom.model_file import save_model

    spec = load_spec(a.spec)
    progress = TqdmProgress() if not a.quiet else None
    try:
        model = build_model(spec, progress)
    finally:
        if progress:
            progress.close()
    mid = save_model(model, a.output)
    print(model.summary())
    print(f"wrote {a.output} ({Path(a.output).stat().st_size / 1e6:.2f} MB, id {mid}) in "
          f"{model.provenance.get('build_time_s', 0):.1f} s")
    return 0


def cmd_model_info(a: argparse.Namespace) -> int:
    from simreal_nodes.rom.model_file import load_model

    m = load_model(a.model)
    print(m.summary())
    if a.provenance:
        for k, v in m.provenance.items():
            if k != "spec":
                print(f"  {k}: {v}")
    return 0


def add_build_model(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("build-model", help="build a reduced-order model file from a spec")
    s.add_argument("spec", help="model spec YAML (or the name of a built-in spec, e.g. aluminium_beam.yaml)")
    s.add_argument("-o", "--output", required=True, help="output .h5")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    s.set_defaults(fn=cmd_build_model)


def add_model_info(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("model-info", help="summary of a model file")
    s.add_argument("model")
    s.add_argument("--provenance", action="store_true")
    s.set_defaults(fn=cmd_model_info)


def cmd_build_aero_db(a: argparse.Namespace) -> int:
    from simreal_nodes.aero.database import assemble, load_aero_spec, run_sweep
    from simreal_nodes.errors import SceneError

    try:
        spec = load_aero_spec(a.spec)
    except ValueError as exc:
        raise SceneError(str(exc)) from exc
    out = Path(a.output)
    work = Path(a.work) if a.work else out.with_name(out.name + ".work")
    cars = spec.cars()
    print(f"{spec.name}: {len(cars)} cars ({spec.n_database} in the database, {len(cars) - spec.n_database} held "
          f"out), grid {spec.grid.shape}, results kept in {work} (a rerun resumes)", flush=True)

    def report(k: int, n: int, name: str, line: str) -> None:
        if not a.quiet:
            print(f"[{k}/{n}] {name}: {line}", flush=True)

    run_sweep(spec, work, jobs=a.jobs, scheduler=a.scheduler, report=report)
    assemble(spec, work, out)
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB)")
    return 0


def add_build_aero_db(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("build-aero-db", help="build the CFD database of car flows (OpenFOAM, one Dask task a car)")
    s.add_argument("spec", help="aero spec YAML (or the name of a built-in one, e.g. aero_cars.yaml)")
    s.add_argument("-o", "--output", required=True, help="output .h5")
    s.add_argument("--work", help="folder for the per-car results (default: OUTPUT.work); a rerun skips what is there")
    s.add_argument("--jobs", type=int, default=max(1, (os.cpu_count() or 2)),
                   help="cars solved at once on the local Dask cluster (one core each; default: the CPU count)")
    s.add_argument("--scheduler", help="address of a Dask scheduler (tcp://host:8786): spread the cars over its "
                   "workers instead of a local cluster")
    s.add_argument("-q", "--quiet", action="store_true", help="no line per car")
    s.set_defaults(fn=cmd_build_aero_db)
