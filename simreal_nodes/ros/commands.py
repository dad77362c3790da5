"""`simreal replay` and `simreal record` (they need rclpy; the CLI imports this lazily)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from simreal_nodes.errors import BagError, SimrealError
from simreal_nodes.io import bags
from simreal_nodes.launch import (
    DISCOVERY_RANGE,
    EXECUTOR_ENV,
    QOS_FROM_XML,
    THREADS_ENV,
    Launcher,
    executor_kind,
    node_threads,
    ros_environment,
    thread_variables,
)
from simreal_nodes.lifetime import StopSignals
from simreal_nodes.ros.bagplay import MAX_IN_FLIGHT, Player, Recorder, in_flight_ok
from simreal_nodes.ros.node import make_executor
from simreal_nodes.scene.graph import (
    NodeSpec,
    image_topic,
    ingest_note,
    launch_choice,
    output_topics,
    process_groups,
    required_nodes,
    unestimated_notes,
)
from simreal_nodes.scene.schema import build_spec_models, load_scene

# the outputs a replay with ``record_images`` off counts without writing them
IMAGE_TYPES = frozenset({"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"})


def _share_node_environment() -> None:
    """This process's own node (player, recorder) uses the nodes' transport profile and discovery range: with
    another range it would not meet them, or would announce itself beyond this host."""
    env = ros_environment({k: v for k, v in os.environ.items() if k != THREADS_ENV})  # the pools: the nodes' alone
    os.environ.update({k: env[k] for k in ("FASTRTPS_DEFAULT_PROFILES_FILE", DISCOVERY_RANGE, QOS_FROM_XML)
                       if k in env})


QUIET_TIMEOUT_S = 5.0  # a replay waits at most this long for the graph to go quiet before its first frame
IN_FLIGHT_THREADS = 1  # each library pool's threads per node process in a lossless replay with frames in flight


def recorded_topics(nodes: list[NodeSpec], record_images: bool = True) -> tuple[dict[str, str], tuple[str, ...]]:
    """(topic -> type, the topics only counted) of a replay's record of ``nodes``' outputs: every output, written;
    with ``record_images`` False what a display receives: the graph's images counted, not written, and the camera's
    images that an ingest passes on to the other nodes not subscribed at all (no display shows them again; an ingest
    alone keeps them, they are its product)."""
    outputs = output_topics(nodes)
    if record_images:
        return outputs, ()
    passed_on = {t for n in nodes if n.name == "ingest" and len(nodes) > 1
                 for t, ty in n.outputs.items() if ty in IMAGE_TYPES}
    outputs = {t: ty for t, ty in outputs.items() if t not in passed_on}
    return outputs, tuple(t for t, ty in outputs.items() if ty in IMAGE_TYPES)


def replay_parameters(node: str, lossless: bool, in_flight: int) -> dict:
    """What a replay sets on ``node`` beyond the scene's parameters. A lossless graph runs the SLAM's local bundle
    adjustment in the localization's own process (its ``async_mapping`` parameter's default there), each keyframe's
    before the next frame: in lock-step every frame then meets the map the one before left, and a replay's estimates
    repeat to the bit (in the mapping's process of its own, live's default, a BA's result reached the tracking a frame
    or two earlier or later from run to run: two lock-step replays of the foam beam parted from its first keyframe
    on, 1.2 mm apart; the cost, 6-11 % fewer frames a second there, scratch). With frames in flight the tracker's
    word reaches the localization by the run's timing anyway (:func:`replay`), and the BA's own process keeps its
    work off the SLAM's core (with 4 in flight 23.1 against 21.7 frames a second on the foam beam, scratch): such a
    replay asks for it."""
    if node == "localization" and lossless and in_flight > 1:
        return {"async_mapping": True}
    return {}


def replay(bag: str, scene_file: str, rate: float = 1.0, lossless: bool = False, record: str | None = None,
           storage: str = "mcap", launch: bool = True, frame_timeout_s: float = 30.0, ready_timeout_s: float = 90.0,
           metrics_json: str | None = None, echo=print, extra_params: dict | None = None, namespace: str = "",
           standby: bool | None = None, one_process: bool | str | None = False, executor: str | None = None,
           threads: int | None = None, in_flight: int = 1, record_images: bool = True):
    """Replay ``bag`` into the graph of ``scene_file``; returns (PlayStats, BagReport, recorder counts).
    ``namespace``: the nodes' namespace; ``standby``: a standby process per node (:class:`~simreal_nodes.launch.
    Launcher`), by default in a live replay and not in a lossless one (a node that exits there is a fault to see,
    and time does not press); ``one_process``: every node in one process on one executor (here a process per node
    unless asked, so that a caller says which it runs; ``"split"``: the slow nodes apart, the others in one,
    :func:`~simreal_nodes.scene.graph.process_groups`; None: the scene's pick, as the CLI's default,
    :func:`~simreal_nodes.scene.graph.default_launch`); ``executor``: the nodes' and the
    player's (one of :data:`~simreal_nodes.launch.EXECUTORS`; None: :func:`~simreal_nodes.launch.executor_kind`);
    ``threads``: the worker threads of each node process's libraries (:func:`~simreal_nodes.launch.ros_environment`;
    None: ``SIMREAL_THREADS``, else the default: the linear algebra's pools one thread, OpenCV's its own, and with
    frames in flight :data:`IN_FLIGHT_THREADS` for every pool);
    ``in_flight``: lossless, how many frames the player lets into the graph at once (1 to
    :data:`~simreal_nodes.ros.bagplay.MAX_IN_FLIGHT`; 1: lock-step, the next frame published when every node
    reported the last; more: the nodes of a process per node overlap, every frame still processed, in order, by
    every node, but what the tracker tells the localization about a frame (its map points' flags, its focus region,
    the map's freeze) reaches it up to ``in_flight - 1`` frames later than lock-step, by the timing of the run: a
    SLAM scene's estimates then need not repeat; lock-step for evaluation: its estimates repeat to the bit,
    :func:`replay_parameters`); ``record_images``: False, the graph's image outputs are received and counted but
    not written to the record (what a display costs, not a disk), and the camera's images that the ingest passes on
    to the other nodes are not subscribed (a display shows the graph's products)."""
    executor = executor_kind(None if executor is None else {EXECUTOR_ENV: executor})
    thread_variables(dict(os.environ), threads)  # a bad SIMREAL_THREADS (or threads) refused before any work
    if not in_flight_ok(in_flight):
        raise SimrealError(f"frames in flight {in_flight!r}: a lossless replay lets a whole number from 1 to "
                           f"{MAX_IN_FLIGHT} into the graph at once (a node holds 30 frames waiting for inputs)")
    if in_flight > 1 and not lossless:
        echo(f"[replay] warning: {in_flight} frames in flight asked of a live replay, which publishes at the bag's "
             "rate and bounds nothing: the bound is the lossless replay's (--lossless)")
    if threads is None and lossless and in_flight > 1 and node_threads(dict(os.environ)) is None:
        # frames in flight keep every core busy with a node: a pool's helper threads then only add switching
        # (benchmarks/results/graph_threads.md)
        threads, pools = IN_FLIGHT_THREADS, f"; {IN_FLIGHT_THREADS} thread per library pool (frames in flight)"
    else:
        pools = ""
    scene = load_scene(scene_file)
    if launch:
        build_spec_models(scene)  # before the nodes start: they find the built spec:NAME models in the cache
    cam = scene["camera"]
    nodes = required_nodes(scene, lossless=lossless, source="topic")  # the player is the source
    how_run, how = launch_choice(scene, lossless, one_process, in_flight if lossless else 1)
    how = f"; {how}{pools}" if launch else ""
    echo(f"[replay] nodes: {', '.join(n.name for n in nodes)} ({ingest_note(scene, nodes, 'topic')}{how})")
    for note in unestimated_notes(scene):
        echo(f"[replay] {note}")
    for n in nodes:
        n.parameters.update(replay_parameters(n.name, lossless, in_flight))
        n.parameters.update((extra_params or {}).get(n.name, {}))
    report = bags.BagReport()
    topics = bags.bag_topics(bag)
    img = image_topic(cam)
    assert img is not None  # camera.image is never null in a validated scene (it has a default)
    if img not in topics:
        hint = ""
        if not cam["compressed"] and img + "/compressed" in topics:
            hint = " (the bag has compressed images: set camera.compressed: true in the scene)"
        raise BagError(f"bag {bag} has no topic {img} (the scene's camera.image){hint}; it has: "
                       f"{', '.join(sorted(topics)) or 'no topics'}")
    right = image_topic(cam, right=True)
    depth_info = cam.get("depth_camera_info")
    wanted = [img, cam["camera_info"], cam["depth"], depth_info, right, cam["right_camera_info"]]
    inputs = {t: topics[t] for t in wanted if t and t in topics}
    for t, key in ((cam["camera_info"], "camera_info"), (cam["depth"], "depth"), (depth_info, "depth_camera_info"),
                   (right, "right_image"), (cam["right_camera_info"], "right_camera_info")):
        if t and t not in topics:  # the nodes that need it wait for it: every frame would time out in lossless
            echo(f"[replay] warning: bag {bag} has no topic {t} (the scene's camera.{key}); the nodes that read it "
                 "will wait for it")
    hold_for = tuple(t for t in (cam["depth"], depth_info, right, cam["right_camera_info"]) if t and t in topics)

    if standby is None:
        standby = not lossless
    launcher = Launcher(nodes, echo=echo, namespace=namespace, standby=standby,
                        groups=process_groups(scene, nodes, how_run), executor=executor,
                        threads=threads) if launch else None
    _share_node_environment()
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node("simreal_player")
    ex = make_executor(executor)
    ex.add_node(node)
    recorder = None
    stats = None
    try:
        with StopSignals(interrupting=False) as stop:
            if record:
                outputs, count_only = recorded_topics(nodes, record_images)
                recorder = Recorder(node, record, storage, topics=outputs, count_only=count_only)
            player = Player(node, ex, inputs, img, [n.name for n in nodes if n.per_frame], lossless, rate,
                            frame_timeout_s, echo=echo, in_flight=in_flight)
            player.should_stop = stop.is_set
            # what the nodes must have subscribed to before the first frame: the graph's topics and the player's
            player.node_inputs = {n.name: [t for t in n.inputs if t.startswith("/simreal/") or t in inputs]
                                  for n in nodes}
            if recorder:
                player.extra_ready = recorder.ready
            if launcher:
                launcher.start()
            if launcher:
                player.dead_nodes = lambda: [p.spec.name for p in launcher.procs
                                             if p.popen is None and p.restarts >= launcher.respawn]
            if not player.wait_ready(ready_timeout_s):
                raise SimrealError("the graph did not come up; see the node output above")
            if launcher and not launcher.start_standbys(ready_timeout_s):
                echo(f"[replay] warning: not every standby was ready within {ready_timeout_s:.0f} s; playing anyway")
            # live, the first frame meets a quiet graph (lossless loses no frame to a busy start)
            if launcher and not lossless and not launcher.wait_quiet(QUIET_TIMEOUT_S, should_stop=stop.is_set) \
                    and not stop.is_set():
                echo(f"[replay] warning: the graph was still busy {QUIET_TIMEOUT_S:.0f} s after it came up; playing")
            cpu0, own0 = (launcher.cpu_seconds() if launcher else {}), time.process_time()
            stats = player.play(bags.read_bag(bag, report, topics=inputs.keys()), hold_for=hold_for)
            cpu1 = launcher.cpu_seconds() if launcher else {}
            stats.cpu_s = {n: cpu1[n] - cpu0[n] for n in cpu1 if n in cpu0}
            stats.cpu_s["player" + (" + recorder" if recorder else "")] = time.process_time() - own0
    finally:
        if recorder:
            recorder.close()
        if launcher:
            launcher.stop()
        # the EventsExecutor keeps the native memory of what it received until shut down: replays one after another
        # in one process grew without this (stop 82; tests/ros/test_replay.py keeps the measure)
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown()
    echo(report.summary())
    if stats:
        echo("[replay] " + stats.summary())
    if recorder:
        echo(f"[replay] recorded {recorder.writer.count} messages to {record}: " +
             ", ".join(f"{t} {n}" for t, n in sorted(recorder.counts.items())))
        if recorder.failed:
            echo(f"[replay] error: {recorder.failed}")
            if stats is not None:
                stats.record_error = recorder.failed
    if metrics_json and stats:
        Path(metrics_json).write_text(json.dumps({"play": stats.as_dict(), "bag_problems": report.problems}, indent=2))
    return stats, report, (dict(recorder.counts) if recorder else {})


def record(out: str, topics: list[str] | None = None, storage: str = "mcap", echo=print,
           duration_s: float | None = None) -> dict[str, int]:
    """Record live topics (all, if none are named) until SIGINT / SIGTERM or ``duration_s``."""
    import time

    _share_node_environment()
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node("simreal_recorder")
    ex = make_executor()
    ex.add_node(node)
    rec = None
    try:
        with StopSignals(interrupting=False) as stop:
            rec = Recorder(node, out, storage, discover=not topics)
            pending = set(topics or [])
            t_end = time.monotonic() + duration_s if duration_s else None
            echo(f"[record] recording {'all topics' if not topics else ', '.join(topics)} to {out}; Ctrl-C stops")
            while not stop.is_set() and (t_end is None or time.monotonic() < t_end) and not rec.failed:
                ex.spin_once(timeout_sec=0.1)
                if pending:
                    for t, types in node.get_topic_names_and_types():
                        if t in pending and types:
                            rec.add(t, types[0])
                            pending.discard(t)
    finally:
        if rec:
            rec.close()
        ex.shutdown()  # the EventsExecutor keeps what it received until shut down (see replay)
        node.destroy_node()
        rclpy.shutdown()
    echo(f"[record] wrote {rec.writer.count if rec else 0} messages to {out}")
    if rec and rec.failed:
        raise SimrealError(rec.failed)
    return dict(rec.counts) if rec else {}
