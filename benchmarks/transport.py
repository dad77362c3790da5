"""Image transport over DDS: between two processes and within one process, 640x480 and 1280x720.

Reports throughput (publish as fast as the subscriber keeps up, reliable) and latency
percentiles at 30 Hz (best effort, sensor-data QoS) with the 32 MB shared-memory profile.

    ./run bench transport
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np

from benchmarks.common import save

N_FRAMES = int(os.environ.get("SIMREAL_BENCH_FRAMES", "300"))


def _publisher(topic: str, w: int, h: int, n: int, hz: float, reliable: bool):
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from simreal_nodes.io.images import fill_image_msg
    from simreal_nodes.ros.qos import data_qos

    rclpy.init()
    node = Node("bench_pub")
    pub = node.create_publisher(Image, topic, data_qos(reliable, depth=10))
    t_end = time.monotonic() + 20
    while pub.get_subscription_count() == 0 and time.monotonic() < t_end:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(0.5)
    img = np.random.default_rng(0).integers(0, 255, (h, w, 3), np.uint8)
    msg = Image()
    fill_image_msg(msg, img, "rgb8")
    period = 1.0 / hz if hz > 0 else 0.0
    t0 = time.monotonic()
    for i in range(n):
        if period:
            while time.monotonic() < t0 + i * period:
                time.sleep(0.0005)
        now = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = now // 10**9, now % 10**9
        msg.header.frame_id = str(i)
        pub.publish(msg)
    time.sleep(1.0)
    node.destroy_node()
    rclpy.shutdown()


def run_case(mode: str, w: int, h: int, hz: float, reliable: bool, n: int = N_FRAMES) -> dict:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from simreal_nodes.launch import ros_environment
    from simreal_nodes.ros.qos import data_qos

    topic = f"/bench/{mode}/res_{w}x{h}"
    lat, got = [], set()
    rclpy.init()
    sub_node = Node("bench_sub")

    def cb(m):
        lat.append((time.time_ns() - (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)) * 1e-6)
        got.add(int(m.header.frame_id))

    sub_node.create_subscription(Image, topic, cb, data_qos(reliable, depth=10))
    ex = SingleThreadedExecutor()
    ex.add_node(sub_node)
    t_first = t_last = None
    if mode == "two_processes":
        p = subprocess.Popen([sys.executable, "-c", f"from benchmarks.transport import _publisher; "
                              f"_publisher('{topic}', {w}, {h}, {n}, {hz}, {reliable})"], env=ros_environment())
        t_end = time.monotonic() + 60 + n / max(hz, 1)
        while p.poll() is None and time.monotonic() < t_end:
            before = len(got)
            ex.spin_once(timeout_sec=0.05)
            if len(got) > before:
                t_last = time.monotonic()
                t_first = t_first or t_last
        p.wait(timeout=10)
    else:  # one process: publisher node and subscriber node on one executor
        from simreal_nodes.io.images import fill_image_msg

        pub_node = Node("bench_pub_same")
        pub = pub_node.create_publisher(Image, topic, data_qos(reliable, depth=10))
        ex.add_node(pub_node)
        for _ in range(40):
            ex.spin_once(timeout_sec=0.05)
        msg = Image()
        fill_image_msg(msg, np.random.default_rng(0).integers(0, 255, (h, w, 3), np.uint8), "rgb8")
        period = 1.0 / hz if hz > 0 else 0.0
        t0 = time.monotonic()
        for i in range(n):
            while period and time.monotonic() < t0 + i * period:
                ex.spin_once(timeout_sec=0.0005)
            now = time.time_ns()
            msg.header.stamp.sec, msg.header.stamp.nanosec = now // 10**9, now % 10**9
            msg.header.frame_id = str(i)
            pub.publish(msg)
            ex.spin_once(timeout_sec=0)
            if len(got) and t_first is None:
                t_first = time.monotonic()
        t_end = time.monotonic() + 2
        while time.monotonic() < t_end and len(got) < n:
            ex.spin_once(timeout_sec=0.01)
        t_last = time.monotonic()
        pub_node.destroy_node()
    sub_node.destroy_node()
    rclpy.shutdown()
    a = np.asarray(lat) if lat else np.array([np.nan])
    span = (t_last - t_first) if (t_first and t_last and t_last > t_first) else float("nan")
    return {"mode": mode, "resolution": f"{w}x{h}", "qos": "reliable" if reliable else "best effort",
            "rate": f"{hz:.0f} Hz" if hz else "max", "sent": n, "delivered_pct": 100.0 * len(got) / n,
            "fps": (len(got) - 1) / span if span == span and span > 0 else float("nan"),
            "p50_ms": float(np.percentile(a, 50)), "p95_ms": float(np.percentile(a, 95)),
            "max_ms": float(np.max(a))}


def main():
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from simreal_nodes.launch import ros_environment

    os.environ.update({k: v for k, v in ros_environment().items() if k == "FASTRTPS_DEFAULT_PROFILES_FILE"})
    rows = []
    for mode in ("two_processes", "one_process"):
        for w, h in ((640, 480), (1280, 720)):
            rows.append(run_case(mode, w, h, 30.0, reliable=False))
            rows.append(run_case(mode, w, h, 0.0, reliable=True))
    cols = [("mode", "mode", "{}"), ("resolution", "resolution", "{}"), ("qos", "QoS", "{}"), ("rate", "rate", "{}"),
            ("delivered_pct", "delivered %", "{:.1f}"), ("fps", "received fps", "{:.1f}"),
            ("p50_ms", "latency p50 (ms)", "{:.2f}"), ("p95_ms", "p95 (ms)", "{:.2f}"),
            ("max_ms", "max (ms)", "{:.1f}")]

    def plot(plt):
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
        for ax, rate in zip(axes, ("30 Hz", "max")):
            sel = [r for r in rows if r["rate"] == rate]
            labels = [f"{r['mode'].replace('_', ' ')}\n{r['resolution']}" for r in sel]
            x = np.arange(len(sel))
            if rate == "30 Hz":
                ax.bar(x - 0.2, [r["p50_ms"] for r in sel], 0.4, label="p50")
                ax.bar(x + 0.2, [r["p95_ms"] for r in sel], 0.4, label="p95")
                ax.set_ylabel("latency (ms)")
                ax.set_title("latency at 30 Hz, best effort")
                ax.legend()
            else:
                ax.bar(x, [r["fps"] for r in sel])
                ax.set_ylabel("frames / s")
                ax.set_title("throughput, reliable, publish flat out")
            ax.set_xticks(x, labels, fontsize=8)
        return fig

    save("transport", rows, cols, "Image transport over Fast DDS (SHM 32 MB profile)",
         notes=f"{N_FRAMES} rgb8 frames per case. Latency = receive time - header stamp (same clock). "
               "'one process' runs publisher and subscriber nodes on one SingleThreadedExecutor (rclpy has no "
               "intra-process shortcut, so this still crosses DDS). At rate 'max' the publisher outruns the subscriber "
               "and frames queue in the reliable history: read throughput there; its latency is queueing delay.",
         plot=plot)


if __name__ == "__main__":
    main()
