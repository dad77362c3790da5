"""What a subscription alone holds after large messages: the DDS reader's sample pool (issue 20's fuzz memory).

    python -m benchmarks.dds_pool_memory          # about 2 minutes

`fuzz_graph --memory-detail` found the nodes' growth under hostile messages in native memory, not in Python. This
isolates the middleware: a subscriber process whose callback does nothing (``sensor_msgs/Image``, KEEP_LAST with
the depth named, reliable as the nodes' camera inputs under a lossless replay, or best effort) runs under the memory
probe of `benchmarks/memprobe` while this process publishes 8 000 images at 600 a second, either all of one size
(320 x 240 x 3 bytes, the fuzz's camera) or of random sizes up to 3 MB (the fuzz's huge payloads). The probe reads the
subscriber before, after each quarter and at the end, once its bytes in use have stopped moving (two readings a
second apart within 0.5 MB, at most 30 s after the last message: a slow subscriber is still taking what was queued
for it): resident size, Python's allocations, the C allocator's bytes in use, and its CPU time (per message it
received). The transport and discovery are the nodes'
(`simreal_nodes.launch.ros_environment`: the shared-memory profile, this host only). The subscriber's history memory
policy is rmw_fastrtps's own (PREALLOCATED_WITH_REALLOC: ``RMW_FASTRTPS_USE_QOS_FROM_XML=0``) or the project
profile's DYNAMIC (``=1``); the publisher keeps rmw_fastrtps's own.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import memprobe
from benchmarks.common import save

TOPIC = "/simreal_bench/dds_pool/image"
# (image sizes, reliability, history depth, the reader's history memory policy)
CASES = (("one size", "reliable", 10, "rmw default"), ("random sizes", "reliable", 10, "rmw default"),
         ("random sizes", "best effort", 10, "rmw default"), ("random sizes", "reliable", 1, "rmw default"),
         ("one size", "reliable", 10, "dynamic"), ("random sizes", "reliable", 10, "dynamic"),
         ("random sizes", "best effort", 10, "dynamic"))
# the reader's history memory policy -> RMW_FASTRTPS_USE_QOS_FROM_XML: 0, rmw_fastrtps's PREALLOCATED_WITH_REALLOC;
# 1, the profile's (simreal_nodes/ros/fastdds_shm.xml: DYNAMIC)
POLICY_ENV = {"rmw default": "0", "dynamic": "1"}
MESSAGES = 8000
MAX_BYTES = 3_000_000
RATE_HZ = 600.0
SETTLE_S = 30.0  # the longest wait, after the last message, for the subscriber's memory to stop moving
SETTLED_MB = 0.5


def _qos(reliability: str, depth: int):
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    rel = ReliabilityPolicy.RELIABLE if reliability == "reliable" else ReliabilityPolicy.BEST_EFFORT
    return QoSProfile(depth=depth, reliability=rel, history=HistoryPolicy.KEEP_LAST)


def subscriber(reliability: str, depth: int) -> None:
    """The subscriber process: a callback that only counts."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from sensor_msgs.msg import Image

    rclpy.init()
    node = rclpy.create_node("dds_pool_subscriber")
    count = [0]
    node.create_subscription(Image, TOPIC, lambda m: count.__setitem__(0, count[0] + 1), _qos(reliability, depth))
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    try:
        while rclpy.ok():
            ex.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    print(json.dumps({"received": count[0]}), flush=True)


def cpu_s(pid: int) -> float:
    """Process ``pid``'s CPU time so far (user + system), seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_case(sizes: str, reliability: str, depth: int, policy: str, work: Path, messages: int = MESSAGES) -> dict:
    """One subscriber process under the probe, ``messages`` images published at RATE_HZ from this process (rclpy
    already initialised in the nodes' environment): the row of the table."""
    import rclpy
    from sensor_msgs.msg import Image

    from simreal_nodes.launch import ros_environment

    probe = work / f"{sizes}-{reliability}-{depth}-{policy}".replace(" ", "_")
    probe.mkdir()
    env = memprobe.probe_env(ros_environment() | {"PYTHONPATH": str(Path(__file__).resolve().parents[1]),
                                                  "RMW_FASTRTPS_USE_QOS_FROM_XML": POLICY_ENV[policy]}, probe)
    sub = subprocess.Popen([sys.executable, "-m", "benchmarks.dds_pool_memory", "--subscriber", reliability,
                            str(depth)], env=env, stdout=subprocess.PIPE, text=True)
    node = rclpy.create_node("dds_pool_publisher")
    pub = node.create_publisher(Image, TOPIC, _qos(reliability, depth))
    readings: list[dict] = []

    def read() -> None:
        memprobe.ask(sub.pid)
        time.sleep(0.5)
        readings.append(memprobe.latest(sub.pid, probe) | {"cpu_s": cpu_s(sub.pid)})

    try:
        t_end = time.monotonic() + 60
        while (pub.get_subscription_count() == 0 or not memprobe.ready(sub.pid, probe)) \
                and time.monotonic() < t_end:
            time.sleep(0.1)
        if pub.get_subscription_count() == 0:
            raise RuntimeError("the subscriber was not matched within 60 s")
        time.sleep(1.0)
        read()
        rng = np.random.default_rng(0)
        blob = rng.bytes(MAX_BYTES)
        t0 = time.monotonic()
        for i in range(messages):
            n = int(rng.integers(0, MAX_BYTES)) if sizes == "random sizes" else 320 * 240 * 3
            msg = Image(height=1, width=n, encoding="mono8", step=n)
            msg.data = blob[:n]
            pub.publish(msg)
            if (i + 1) % max(messages // 4, 1) == 0:
                read()
            lag = (i + 1) / RATE_HZ - (time.monotonic() - t0)
            if lag > 0:
                time.sleep(lag)
        # the subscriber may still be taking what is queued for it (reliable: the writer resends to a slow reader):
        # read until two readings a second apart agree within SETTLED_MB, at most SETTLE_S
        t_quiet = time.monotonic()
        time.sleep(2.0)
        read()
        while time.monotonic() - t_quiet < SETTLE_S:
            time.sleep(0.5)
            read()
            if abs(readings[-1]["malloc_in_use_mb"] - readings[-2]["malloc_in_use_mb"]) < SETTLED_MB:
                break
        settle_s = time.monotonic() - t_quiet
    finally:
        sub.send_signal(signal.SIGINT)
        out, _ = sub.communicate(timeout=30)
        node.destroy_node()
    received = next((json.loads(x)["received"] for x in out.splitlines() if x.startswith("{")), None)
    a, b = readings[0], readings[-1]
    series = readings[:1] + readings[1:-1][:4] + readings[-1:]  # before, each quarter, after
    return {"sizes": sizes, "reliability": reliability, "depth": depth, "policy": policy, "messages": messages,
            "received": received,
            # the subscriber's CPU time from the first reading to the last, per message it received (its probe's
            # readings are inside this window too: a few ms each)
            "cpu_ms_per_message": 1e3 * (b["cpu_s"] - a["cpu_s"]) / received if received else float("nan"),
            "rss_before": a["rss_mb"], "rss_after": b["rss_mb"], "python_before": a["python_mb"],
            "python_after": b["python_mb"], "in_use_before": a["malloc_in_use_mb"],
            "in_use_after": b["malloc_in_use_mb"], "in_use_growth": b["malloc_in_use_mb"] - a["malloc_in_use_mb"],
            "in_use_series": " -> ".join(f"{r['malloc_in_use_mb']:.0f}" for r in series), "settle_s": settle_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subscriber", nargs=2, metavar=("RELIABILITY", "DEPTH"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.subscriber:
        subscriber(a.subscriber[0], int(a.subscriber[1]))
        return
    import rclpy

    from simreal_nodes.launch import ros_environment

    os.environ.update(ros_environment())  # this process meets the subscriber as the nodes meet each other
    rclpy.init()
    rows = []
    try:
        with tempfile.TemporaryDirectory() as d:
            for sizes, reliability, depth, policy in CASES:
                rows.append(run_case(sizes, reliability, depth, policy, Path(d)))
                print(rows[-1], flush=True)
    finally:
        rclpy.shutdown()
    cols = [("sizes", "image sizes", "{}"), ("reliability", "reliability", "{}"), ("depth", "history depth", "{}"),
            ("policy", "reader's history memory", "{}"), ("messages", "published", "{}"),
            ("received", "received", "{}"), ("cpu_ms_per_message", "subscriber CPU per message (ms)", "{:.3f}"),
            ("rss_before", "RSS before (MB)", "{:.0f}"), ("rss_after", "RSS after (MB)", "{:.0f}"),
            ("python_before", "Python before (MB)", "{:.1f}"), ("python_after", "Python after (MB)", "{:.1f}"),
            ("in_use_series", "C allocator in use (MB): before, each quarter, after", "{}"),
            ("in_use_growth", "its growth (MB)", "{:.1f}"),
            ("settle_s", "last reading, s after the last message", "{:.1f}")]
    notes = (f"`python -m benchmarks.dds_pool_memory` (module docstring): a subscriber whose callback only counts, "
             f"{MESSAGES} `sensor_msgs/Image` messages at {RATE_HZ:.0f} a second, of one size (230 400 bytes) or of "
             f"random sizes up to {MAX_BYTES / 1e6:.0f} MB; the subscriber's memory by the probe of "
             "`benchmarks/memprobe` (Python's allocations by tracemalloc, the C allocator's bytes in use by glibc's "
             "mallinfo2). Python's own allocations do not move. Under rmw_fastrtps's own policy what grows is native, "
             "and it stops growing once the largest messages have been seen; under DYNAMIC each sample's buffer is "
             "freed once taken.")
    save("dds_pool_memory", rows, cols, "A subscription alone: memory after large messages", notes)


if __name__ == "__main__":
    main()
