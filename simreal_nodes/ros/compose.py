"""The one-process launch (``simreal launch --one-process``): a scene's nodes in one process, on one executor.

    python -m simreal_nodes.ros.compose NODES.json

``NODES.json`` (written by :class:`~simreal_nodes.launch.Launcher`) is a list of ``{"module": ..., "args": [...]}``:
the node module (its ``NODE_CLASS`` is built) and the node's own ROS arguments (``--ros-args -r __node:=NAME
--params-file FILE ...``), exactly the command line the node would have in its own process. Each node gets them as
node-specific arguments (rclpy's ``cli_args``), so names, namespaces, parameter files and remaps behave as in
separate processes; the nodes share one DDS participant and one executor
(:func:`~simreal_nodes.ros.node.run_nodes`), and their topics stay visible to other processes.

The trade, measured by ``./run bench graph`` (``benchmarks/results/graph.md``): one process saves the per-process
overhead (an interpreter, a participant, a publication that wakes another process) but runs every callback on one
thread, so the nodes no longer overlap and a fault in one ends them all. On two cores it was faster end to end or level
on every scene measured lossless and live for the markers demo, so it is the CLI's default (``--process-per-node`` for
one each), but for a live graph with a SLAM localization or a dense tracker, whose work a frame outlasts a camera
frame period: there a process per node put more frames through (``scene.graph.default_launch``); and for a
lossless replay with frames in flight (``simreal replay --in-flight N``), where the nodes of a process per node work
on different frames at once and one executor cannot.
"""

from __future__ import annotations

import functools
import importlib
import json
import sys
from pathlib import Path

from simreal_nodes.errors import SimrealError


def read_nodes(path: str | Path) -> list[tuple[str, list[str]]]:
    """(module, node arguments) per node of a ``NODES.json``; :class:`SimrealError` naming what is wrong."""
    try:
        entries = json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise SimrealError(f"one-process launch: cannot read {path}: {err}") from None
    if not isinstance(entries, list) or not entries:
        raise SimrealError(f"one-process launch: {path} must hold a non-empty list of nodes")
    out = []
    for i, e in enumerate(entries):
        module, args = (e.get("module"), e.get("args")) if isinstance(e, dict) else (None, None)
        if not isinstance(module, str) or not module.startswith("simreal_nodes.ros.nodes.") \
                or not isinstance(args, list) or not all(isinstance(a, str) for a in args):
            raise SimrealError(f"one-process launch: entry {i} of {path} must be {{'module': "
                               f"'simreal_nodes.ros.nodes.NAME', 'args': [str, ...]}}; found {e!r}")
        out.append((module, args))
    return out


def builders(entries: list[tuple[str, list[str]]]) -> list:
    """One callable per node that builds it with its own arguments (the classes are imported here, first)."""
    out = []
    for module, args in entries:
        try:
            cls = getattr(importlib.import_module(module), "NODE_CLASS", None)
        except ImportError as err:
            raise SimrealError(f"one-process launch: cannot import {module}: {err}") from None
        if cls is None:
            raise SimrealError(f"one-process launch: module {module} has no NODE_CLASS")
        out.append(functools.partial(cls, cli_args=args))
    return out


def main(argv: list[str] | None = None) -> int:
    from simreal_nodes.ros.node import run_nodes

    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m simreal_nodes.ros.compose NODES.json", file=sys.stderr)
        return 2
    try:
        build = builders(read_nodes(argv[0]))
    except SimrealError as e:
        print(f"error: {e}", file=sys.stderr, flush=True)
        return 2
    return run_nodes(build)


if __name__ == "__main__":
    sys.exit(main())
