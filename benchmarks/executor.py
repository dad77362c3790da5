"""Executors (issue 18): rclpy's EventsExecutor (C++, ``rclpy.experimental``) against its SingleThreadedExecutor
(Python, which rebuilds its wait set on every wake-up), for the node processes and the replay's player.

    ./run bench executor                      # about 20 minutes on 2 cores
    python -m benchmarks.executor --reps 1    # one pair per case

Every case is run as pairs, single then events back to back, repeated (``--reps``), so that a host whose speed
drifts (this machine's does, between runs and within them) moves both runs of a pair alike. Reported: each case's
median over its runs, and the median of the pairs' changes, events against single.

1. *Messages*: one subscriber process receives 600 images of 640 x 480 rgb8 (921 600 bytes) at 60 per second from a
   publisher process (reliable, depth 10); its callback publishes a short reply, as a node publishes its result.
   Reported: the subscriber's CPU per message (``getrusage``: all its threads, the middleware's included), with the
   message deserialized into ``sensor_msgs/Image`` and taken raw (its CDR bytes, ``raw=True``).
2. *Graphs*, lossless replays of the sample bags (:func:`benchmarks.graph.run_case`): the demo (``aluminium_beam``,
   markers, 640 x 480) with a process per node and in one process, and the RGB-D SLAM scene (``foam_beam``, 640 x
   480) in one process. Reported: frames through per second, latency p50 / p95, the nodes' CPU per frame and the
   player's (the replay's own process, which spins on the same executor).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

from benchmarks.common import pair_changes, save, speed_probe

N_MESSAGES = 600
RATE_HZ = 60.0
TOPIC = "/simreal_bench/executor_image"
GRAPHS = (("aluminium_beam", False), ("aluminium_beam", True), ("foam_beam", True))


# --------------------------------------------------------------------------------------------- subprocess roles
def _publisher() -> None:
    import rclpy
    from sensor_msgs.msg import Image

    from simreal_nodes.ros.qos import reliable_qos

    rclpy.init()
    node = rclpy.create_node("executor_bench_pub")
    pub = node.create_publisher(Image, TOPIC, reliable_qos(10))
    msg = Image(height=480, width=640, encoding="rgb8", step=1920, data=bytes(480 * 640 * 3))
    t_end = time.monotonic() + 20.0
    while pub.get_subscription_count() == 0 and time.monotonic() < t_end:
        time.sleep(0.05)
    time.sleep(0.5)  # the reply's endpoints match too
    t0 = time.monotonic()
    for i in range(N_MESSAGES):
        msg.header.stamp.sec = i
        pub.publish(msg)
        time.sleep(max(0.0, t0 + (i + 1) / RATE_HZ - time.monotonic()))
    time.sleep(1.0)
    node.destroy_node()
    rclpy.shutdown()


def _subscriber(executor: str, raw: bool) -> None:
    import rclpy
    from sensor_msgs.msg import Image
    from std_msgs.msg import Header

    from simreal_nodes.ros.node import make_executor
    from simreal_nodes.ros.qos import reliable_qos

    rclpy.init()
    node = rclpy.create_node("executor_bench_sub")
    ex = make_executor(executor)
    ex.add_node(node)
    reply = node.create_publisher(Header, TOPIC + "_reply", reliable_qos(10))
    got = [0]
    start: list[float] = []

    def on_image(m):
        got[0] += 1
        if not start:
            ru = resource.getrusage(resource.RUSAGE_SELF)
            start.append(ru.ru_utime + ru.ru_stime)
        reply.publish(Header(frame_id="r"))

    node.create_subscription(Image, TOPIC, on_image, reliable_qos(10), raw=raw)
    node.create_timer(1.0, lambda: None)  # as every node's diagnostics timer
    t_end = time.monotonic() + 30.0
    while got[0] < N_MESSAGES and time.monotonic() < t_end:
        ex.spin_once(timeout_sec=0.5)
    ru = resource.getrusage(resource.RUSAGE_SELF)
    cpu = ru.ru_utime + ru.ru_stime - (start[0] if start else 0.0)
    print(json.dumps({"received": got[0], "cpu_ms_per_message": 1e3 * cpu / max(got[0] - 1, 1)}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


def message_run(executor: str, raw: bool) -> dict:
    cmd = [sys.executable, "-m", "benchmarks.executor", "--role"]
    sub = subprocess.Popen([*cmd, "sub", "--executor", executor, *(["--raw"] if raw else [])],
                           stdout=subprocess.PIPE, text=True)
    try:
        subprocess.run([*cmd, "pub"], check=True, timeout=60)
        out, _ = sub.communicate(timeout=60)
    finally:
        if sub.poll() is None:
            sub.kill()
    r = json.loads(out.strip().splitlines()[-1])
    return dict(measure="messages", case="640x480 rgb8 " + ("raw (CDR bytes)" if raw else "deserialized"),
                executor=executor, received=r["received"], cpu_ms=r["cpu_ms_per_message"])


def graph_run(scene: str, one_process: bool, executor: str) -> dict:
    from benchmarks.graph import PLAYER, run_case
    from simreal_nodes.demo import sample_bag

    bag, scene_yaml = sample_bag(scene, resolution="640x480", echo=lambda *a: None)
    r = run_case(scene, "640x480", bag, scene_yaml, True, one_process, executor)
    return dict(measure="graph", case=f"{scene} 640x480 lossless, {r['launch']}", executor=executor,
                fps=r["fps"], latency_p50=r["latency_p50"], latency_p95=r["latency_p95"], cpu_ms=r["nodes_cpu_ms"],
                player_cpu_ms=r.get(f"cpu_{PLAYER.split(' ')[0]}_ms", float("nan")), delivered_pct=r["delivered_pct"])


# ------------------------------------------------------------------------------------------------------- report
def summarize(runs: list[dict]) -> list[dict]:
    """Per case and executor the median of its runs; on the events rows the median of the pairs' changes."""
    rows = []
    for case in dict.fromkeys(r["case"] for r in runs):
        by = {e: [r for r in runs if r["case"] == case and r["executor"] == e] for e in ("single", "events")}
        for e, rs in by.items():
            row = dict(measure=rs[0]["measure"], case=case, executor=e, runs=len(rs))
            for k in ("fps", "latency_p50", "latency_p95", "cpu_ms", "player_cpu_ms"):
                if k in rs[0]:
                    row[k] = float(np.median([r[k] for r in rs]))
            if e == "events":
                row["cpu_change_pct"] = float(np.median(pair_changes(by["single"], rs, "cpu_ms")))
                if "fps" in rs[0]:
                    row["fps_change_pct"] = float(np.median(pair_changes(by["single"], rs, "fps")))
            rows.append(row)
    return rows


COLUMNS = [("case", "case", "{}"), ("executor", "executor", "{}"), ("runs", "runs", "{}"),
           ("cpu_ms", "CPU per message / nodes' CPU per frame (ms)", "{:.2f}"),
           ("cpu_change_pct", "CPU change, pairs' median (%)", "{:+.0f}"), ("fps", "fps through", "{:.1f}"),
           ("fps_change_pct", "fps change, pairs' median (%)", "{:+.0f}"),
           ("latency_p50", "latency p50 (ms)", "{:.0f}"), ("latency_p95", "p95 (ms)", "{:.0f}"),
           ("player_cpu_ms", "player CPU per frame (ms)", "{:.1f}")]


def report(runs: list[dict], probes: list[float]) -> None:
    rows = summarize(runs)

    def plot(plt):
        cases = list(dict.fromkeys(r["case"] for r in rows))
        fig, ax = plt.subplots(figsize=(10, 3.8))
        for k, (e, color) in enumerate((("single", "tab:blue"), ("events", "tab:orange"))):
            v = [next(r["cpu_ms"] for r in rows if r["case"] == c and r["executor"] == e) for c in cases]
            ax.barh([i + 0.4 * k for i in range(len(cases))], v, height=0.4, color=color, label=e)
            for i, c in enumerate(cases):
                pts = [r["cpu_ms"] for r in runs if r["case"] == c and r["executor"] == e]
                ax.plot(pts, [i + 0.4 * k] * len(pts), "k.", ms=4)
        ax.set_yticks([i + 0.2 for i in range(len(cases))], [c.replace(" lossless,", "\n") for c in cases])
        ax.set_xlabel("CPU per message (messages) / nodes' CPU per frame (graphs), ms; dots: runs")
        ax.legend()
        return fig

    notes = ("Each case ran as pairs (single, then events, back to back); the table gives the median of each case's "
             "runs and, on the events rows, the median of the pairs' changes. Messages: the subscriber's CPU per "
             "received 640 x 480 image at 60 per second (its callback publishes a reply). Graphs: lossless replays "
             "(`benchmarks/graph.py`'s `run_case`), the nodes' CPU per frame summed over their processes, the player's "
             f"own. 2-core CPU; the host's CPU probe read {min(probes):.0f}-{max(probes):.0f} ms over the run (the "
             "graph table's host read 14 ms), so the absolute figures are slower than `graph.md`'s; the pairs' changes "
             "are what this table is for.")
    save("executor", rows, COLUMNS, "Executors: rclpy's EventsExecutor against its SingleThreadedExecutor", notes,
         plot, extra={"runs": runs, "cpu_probes_ms": probes})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--role", choices=("pub", "sub"), help=argparse.SUPPRESS)
    ap.add_argument("--executor", default="single", help=argparse.SUPPRESS)
    ap.add_argument("--raw", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--reps", type=int, default=3, help="pairs per case (default 3)")
    ap.add_argument("--no-graphs", action="store_true", help="the message runs only")
    a = ap.parse_args()
    if a.role == "pub":
        return _publisher()
    if a.role == "sub":
        return _subscriber(a.executor, a.raw)
    from simreal_nodes.launch import ros_environment

    os.environ.update(ros_environment())
    probes = [speed_probe()]
    runs = []
    for _ in range(a.reps):
        for raw in (False, True):
            for e in ("single", "events"):
                runs.append(message_run(e, raw))
                print(runs[-1], flush=True)
    probes.append(speed_probe())
    if not a.no_graphs:
        for _ in range(a.reps):
            for scene, one in GRAPHS:
                for e in ("single", "events"):
                    runs.append(graph_run(scene, one, e))
                    print(runs[-1], flush=True)
            probes.append(speed_probe())
    report(runs, probes)


if __name__ == "__main__":
    main()
