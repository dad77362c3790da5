"""Live DDS between two processes: images, and a custom parameter message that must come out of a
recorded bag with identical content."""

import subprocess
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
simreal_msgs = pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402
from simreal_msgs.msg import ModelParameters  # noqa: E402

from simreal_nodes.io import bags  # noqa: E402
from simreal_nodes.io.images import image_to_array  # noqa: E402
from simreal_nodes.launch import ros_environment  # noqa: E402
from simreal_nodes.ros.bagplay import Recorder  # noqa: E402
from simreal_nodes.ros.qos import data_qos, reliable_qos  # noqa: E402
from tests.ros import _publisher  # noqa: E402

pytestmark = pytest.mark.ros


def test_images_and_parameters_between_processes_and_through_a_bag(tmp_path):
    n, w, h = 40, 640, 480
    rclpy.init()
    try:
        node = Node("test_subscriber")
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        got_img, got_par = [], []
        node.create_subscription(Image, "/test/image",
                                 lambda m: got_img.append((m.header.stamp.sec, image_to_array(m)[0, 0, 0])),
                                 data_qos(True))
        node.create_subscription(ModelParameters, "/test/params", got_par.append, reliable_qos(100))
        rec = Recorder(node, tmp_path / "rec", topics={"/test/params": "simreal_msgs/msg/ModelParameters"})
        proc = subprocess.Popen([sys.executable, _publisher.__file__, str(n), str(w), str(h)], env=ros_environment())
        t_end = time.monotonic() + 40
        while (len(got_img) < n or len(got_par) < n or rec.counts["/test/params"] < n) and time.monotonic() < t_end:
            ex.spin_once(timeout_sec=0.05)
        proc.wait(timeout=30)
        rec.close()
        node.destroy_node()
    finally:
        rclpy.shutdown()
    assert [s for s, _ in got_img] == [100 + i for i in range(n)]
    assert [int(v) for _, v in got_img] == [i % 256 for i in range(n)]
    assert len(got_par) == n
    for i, m in enumerate(got_par):
        ref = _publisher.params_msg(i)
        assert m == ref  # live round trip, every field
    # the recorded bag holds the same messages, readable without ROS and by rclpy
    recorded = [m for m in bags.read_bag(tmp_path / "rec")]
    assert len(recorded) == n
    for i, m in enumerate(recorded):
        assert deserialize_message(m.raw, ModelParameters) == _publisher.params_msg(i)
        obj = bags.decode(m)
        assert (list(obj.names) == ["s", "E"] and np.allclose(obj.values, [0.01 * i, 69e9])
                and obj.reason == f"frame {i}")


def test_simreal_record_stopped_by_sigint_writes_a_readable_bag(tmp_path):
    """`simreal record` of a live topic, Ctrl-C while messages still come: it exits 0 and the bag holds the messages
    it got, in order and intact (the recorder owns SIGINT: `lifetime.StopSignals`, not interrupting)."""
    import signal

    env = ros_environment()
    out = tmp_path / "rec"
    pub = subprocess.Popen([sys.executable, _publisher.__file__, "900", "32", "24", "1"], env=env)
    rec = subprocess.Popen([sys.executable, "-m", "simreal_nodes.cli", "record", "/test/params", "-o", str(out)],
                           env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert rec.stdout is not None
        first = rec.stdout.readline()
        assert "[record] recording /test/params" in first, first
        time.sleep(4.0)  # the publisher sends 30 a second for 30 s
        assert pub.poll() is None and rec.poll() is None
        rec.send_signal(signal.SIGINT)
        text, _ = rec.communicate(timeout=30)
    finally:
        for p in (rec, pub):
            if p.poll() is None:
                p.kill()
    assert rec.returncode == 0, text
    report = bags.BagReport()
    got = [deserialize_message(m.raw, ModelParameters) for m in bags.read_bag(out, report)]
    assert report.problems == 0, report.summary()
    assert len(got) >= 30, (len(got), text)
    first_i = got[0].header.stamp.sec - 100
    for k, m in enumerate(got):  # consecutive (reliable QoS), every field as published
        assert m == _publisher.params_msg(first_i + k)
    assert f"wrote {len(got)} messages" in text
