"""Commands that run the node graph or talk to it: launch, replay, record, bag-info."""

from __future__ import annotations

import argparse

from simreal_nodes.errors import SimrealError
from simreal_nodes.launch import DISCOVERY_RANGES, EXECUTORS


def _remaps(items: list[str] | None) -> dict[str, str]:
    out = {}
    for it in items or []:
        a, sep, b = it.partition(":=")
        if not sep or not a or not b:
            raise SimrealError(f"--remap expects FROM:=TO, got '{it}'")
        out[a] = b
    return out


def _launch_mode(s: argparse.ArgumentParser) -> None:
    g = s.add_mutually_exclusive_group()
    g.add_argument("--one-process", dest="one_process", action="store_true", default=None,
                   help="every node in one process on one executor (the default, but for a live graph with a SLAM "
                        "localization or a dense tracker and a lossless replay with frames in flight: "
                        "benchmarks/results/graph.md, launch_mode.md)")
    g.add_argument("--process-per-node", dest="one_process", action="store_false",
                   help="each node in its own process: a fault in one node leaves the others (and the SLAM map) "
                        "running (the default for a live graph with a SLAM localization or a dense tracker, whose "
                        "work a frame outlasts a camera frame period)")
    g.add_argument("--split", dest="one_process", action="store_const", const="split",
                   help="the nodes slower than a camera frame (a SLAM localization, a dense tracker) each in a "
                        "process of its own, the others together in one: on 2 cores the fastest with frames in "
                        "flight for graph.md's RGB-D SLAM graphs, not for launch_mode.md's (benchmarks/results)")
    add_executor(s)


def add_executor(s: argparse.ArgumentParser) -> None:
    s.add_argument("--executor", choices=EXECUTORS, default=None,
                   help="the rclpy executor the nodes spin on: events (C++, the default) or single (rclpy's Python "
                        "SingleThreadedExecutor); default: $SIMREAL_EXECUTOR, else events "
                        "(benchmarks/results/executor.md)")
    s.add_argument("--threads", type=_threads, default=None, metavar="N",
                   help="worker threads of each pool of a node process's numerical libraries (OpenBLAS, OpenMP, "
                        "OpenCV; llvmpipe N - 1 besides the caller); 0: the libraries' own defaults; default: "
                        "$SIMREAL_THREADS, else one thread for the linear algebra's pools and OpenCV's own, and "
                        "with frames in flight one for every pool (benchmarks/results/threads.md, graph_threads.md)")


def _in_flight(text: str) -> int:
    from simreal_nodes.ros.bagplay import MAX_IN_FLIGHT, in_flight_ok

    try:
        n = int(text)
    except ValueError:
        n = 0
    if not in_flight_ok(n):
        raise argparse.ArgumentTypeError(f"expected a whole number from 1 to {MAX_IN_FLIGHT}, got {text!r}")
    return n


def _threads(text: str) -> int:
    from simreal_nodes.launch import THREADS_ENV, node_threads

    try:
        n = node_threads({THREADS_ENV: text})  # the launcher's own check
    except SimrealError:
        n = None
    if n is None:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return n


def cmd_launch(a: argparse.Namespace) -> int:
    from simreal_nodes.launch import Launcher, run_until_signal
    from simreal_nodes.scene.graph import (
        ingest_note,
        launch_choice,
        process_groups,
        required_nodes,
        unestimated_notes,
    )
    from simreal_nodes.scene.schema import build_spec_models, load_scene

    scene = build_spec_models(load_scene(a.scene))  # before the nodes start: they load the built models
    nodes = required_nodes(scene, lossless=a.lossless)
    how_run, how = launch_choice(scene, a.lossless, a.one_process)
    print(f"[launch] scene '{scene['name']}': starting {', '.join(n.name for n in nodes)} "
          f"({ingest_note(scene, nodes)}; {how})")
    for note in unestimated_notes(scene):
        print(f"[launch] {note}")
    return run_until_signal(Launcher(nodes, remaps=_remaps(a.remap), respawn=a.respawn, namespace=a.namespace,
                                     discovery_range=a.discovery_range, standby=not a.no_standby,
                                     groups=process_groups(scene, nodes, how_run), executor=a.executor,
                                     threads=a.threads))


def cmd_replay(a: argparse.Namespace) -> int:
    from simreal_nodes.ros.commands import replay

    stats, _report, _ = replay(a.bag, a.scene, rate=a.rate, lossless=a.lossless, record=a.record,
                              storage=a.storage, launch=not a.no_launch, frame_timeout_s=a.frame_timeout,
                              metrics_json=a.metrics, namespace=a.namespace,
                              standby=False if a.no_standby else None, one_process=a.one_process,
                              executor=a.executor, threads=a.threads, in_flight=a.in_flight)
    return 0 if stats is not None and not stats.record_error else 1


def cmd_record(a: argparse.Namespace) -> int:
    from simreal_nodes.ros.commands import record

    record(a.output, a.topics, a.storage, duration_s=a.duration)
    return 0


def cmd_bag_info(a: argparse.Namespace) -> int:
    from simreal_nodes.io import bags

    rep = bags.BagReport()
    for _ in bags.read_bag(a.bag, rep):
        pass
    print(rep.summary())
    return 0 if rep.problems == 0 else 1


def add_launch(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("launch", help="start the nodes a scene requires")
    s.add_argument("scene")
    s.add_argument("--remap", action="append", metavar="FROM:=TO", help="remap a topic in every node")
    s.add_argument("--lossless", action="store_true", help="reliable QoS everywhere")
    s.add_argument("--respawn", type=int, default=2,
                   help="restarts allowed per node process (default 2; in one process, of the whole graph)")
    s.add_argument("--no-standby", action="store_true",
                   help="no standby process (one per node process): a restart is cold (slower: imports, discovery)")
    _launch_mode(s)
    s.add_argument("--namespace", default="", help="start the nodes in this ROS namespace")
    s.add_argument("--discovery-range", choices=DISCOVERY_RANGES,
                   help="DDS discovery range (default: LOCALHOST unless ROS_AUTOMATIC_DISCOVERY_RANGE is set)")
    s.set_defaults(fn=cmd_launch)


def add_replay(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("replay", help="play a bag into the graph")
    s.add_argument("bag")
    s.add_argument("--scene", required=True)
    g = s.add_mutually_exclusive_group()
    g.add_argument("--rate", type=float, default=1.0, help="playback rate (1 = recorded rate)")
    g.add_argument("--lossless", action="store_true", help="every frame processed exactly once, in order")
    s.add_argument("--record", metavar="OUT", help="record every output topic to this bag")
    s.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    s.add_argument("--no-launch", action="store_true", help="the graph is already running")
    s.add_argument("--frame-timeout", type=float, default=30.0, help="lossless: seconds to wait per frame")
    s.add_argument("--in-flight", type=_in_flight, default=1, metavar="N",
                   help="lossless: frames let into the graph at once, 1 to 15 (default 1: each frame waits for the "
                        "last to leave, the least latency, the same estimates run to run; more: a process per node "
                        "overlaps them, more frames a second, none lost, but the tracker's feedback to a SLAM "
                        "localization comes frames late, by the run's timing; latency and --frame-timeout count from "
                        "publication, queueing included; benchmarks/results/graph.md measures the trade)")
    s.add_argument("--metrics", metavar="JSON", help="write replay statistics here")
    s.add_argument("--namespace", default="", help="the graph's ROS namespace")
    s.add_argument("--no-standby", action="store_true",
                   help="live: no standby process (one per node process): a restarted node comes back slower")
    _launch_mode(s)
    s.set_defaults(fn=cmd_replay)


def add_record(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("record", help="record live topics")
    s.add_argument("topics", nargs="*", help="topics (default: all)")
    s.add_argument("-o", "--output", required=True)
    s.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    s.add_argument("--duration", type=float, help="stop after this many seconds")
    s.set_defaults(fn=cmd_record)


def add_bag_info(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("bag-info", help="topics, counts and problems of a bag")
    s.add_argument("bag")
    s.set_defaults(fn=cmd_bag_info)
