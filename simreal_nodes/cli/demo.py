"""The demo command: the end-to-end demo on an embedded sample scene (simreal_nodes.demo)."""

from __future__ import annotations

import argparse


def cmd_demo(a: argparse.Namespace) -> int:
    from simreal_nodes.demo import run_demo

    m = run_demo(a.scene, a.output, regenerate=a.regenerate, resolution=a.resolution, duration=a.duration,
                 one_process=a.one_process, executor=a.executor, threads=a.threads)
    bad = [k for k, p in m["parameters"].items() if "error" in p]
    return 1 if bad or m["frames"]["frames_completed"] == 0 else 0


def add_demo(sub: argparse._SubParsersAction) -> None:
    from simreal_nodes.cli.graph import add_executor
    from simreal_nodes.demo import DEFAULT_SCENE

    s = sub.add_parser("demo", help="end-to-end demo on an embedded sample scene (no camera needed)")
    s.add_argument("--scene", default=DEFAULT_SCENE, help=f"synthetic seed scene (default {DEFAULT_SCENE})")
    s.add_argument("-o", "--output", default="out/demo", help="folder for the MP4, plot and metrics")
    s.add_argument("--resolution", default="640x480")
    s.add_argument("--duration", type=float, help="seconds, when the sample bag has to be rendered")
    s.add_argument("--regenerate", action="store_true", help="render the sample bag again")
    s.add_argument("--process-per-node", dest="one_process", action="store_false",
                   help="each node in its own process (default: every node in one process, as `simreal launch` runs "
                        "a lossless graph)")
    add_executor(s)
    s.set_defaults(fn=cmd_demo)
