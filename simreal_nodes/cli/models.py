"""Model commands: build-model (spec -> reduced-order model file) and model-info (summary of a model file)."""

from __future__ import annotations

import argparse
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
