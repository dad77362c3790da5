"""The `simreal` command line.

    simreal demo                                 the end-to-end demo on the embedded default scene
    simreal launch SCENE.yaml                    start the nodes the scene requires (Ctrl-C stops)
    simreal replay BAG --scene SCENE.yaml        play a bag into the graph (--lossless, --rate, --record OUT)
    simreal record -o OUT [TOPIC ...]            record live topics to a bag
    simreal bag-info BAG                         topics, counts and problems of a bag
    simreal check-scene SCENE.yaml               validate a scene file
    simreal calibrate IMAGES... --board 9x6 --square 0.025 -o calib.yaml
    simreal build-model SPEC.yaml -o MODEL.h5    build a reduced-order model
    simreal build-aero-db SPEC.yaml -o DB.h5     build the CFD database of car flows (OpenFOAM, Dask)
    simreal make-bag SCENE -o BAG                render a synthetic scene with ground truth
    simreal eval-trajectory EST --truth REF      ATE / RPE of a camera trajectory
    simreal eval-tracking OUT_BAG --truth BAG    parameter errors (thesis Table 4.1 layout)

Errors that come from bad input print one line that says what was wrong (exit code 2).
"""

# The commands live in one module per concept (graph: launch / replay / record / bag-info; scene: check-scene /
# make-bag; camera: calibrate; models: build-model / model-info; evaluate: eval-tracking / eval-trajectory; demo);
# this module only wires them into one parser. Each command imports what it runs when it runs, so `simreal --help`
# never loads rclpy or an FEM stack.

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from simreal_nodes.cli import camera, demo, evaluate, graph, models, scene
from simreal_nodes.errors import SimrealError

# The order of `simreal --help`.
COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [
    graph.add_launch, graph.add_replay, graph.add_record, graph.add_bag_info, scene.add_check_scene,
    camera.add_calibrate, demo.add_demo, evaluate.add_eval_tracking, evaluate.add_eval_trajectory, scene.add_make_bag,
    models.add_build_model, models.add_model_info, models.add_build_aero_db,
]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="simreal", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    for add in COMMANDS:
        add(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.fn(args) or 0)
    except SimrealError as e:
        print(f"simreal {args.cmd}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
