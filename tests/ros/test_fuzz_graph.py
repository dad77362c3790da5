"""The fuzzing publisher (benchmarks/fuzz_graph.py) against a live graph: hostile messages on every topic the nodes
subscribe to; no node exits, none raises past a clear rejection, and valid frames still come out afterwards."""

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")

from benchmarks import fuzz_graph

pytestmark = pytest.mark.ros


def test_a_case_is_reproduced_from_its_number():
    from sensor_msgs.msg import CameraInfo, Image

    tpl = Image(height=4, width=5, encoding="32FC1", step=20, data=bytes(80))
    info = CameraInfo(height=4, width=5, k=[100.0, 0, 2, 0, 100, 2, 0, 0, 1])
    for cls, t in ((Image, tpl), (CameraInfo, info)):
        # compared by repr: NaN != NaN, and serialized bytes hold uninitialised padding after a string with a NUL
        made = [[repr(fuzz_graph.make_message(cls, t, np.random.default_rng([7, i]), 10 ** 18, 10 ** 17)[0])
                 for i in range(40)] for _ in range(2)]
        assert made[0] == made[1]
        assert len(set(made[0])) > 30
        assert made[0].count(repr(t)) <= 2  # a mutation may set a value the template had


@pytest.mark.parametrize("graph", ["markers", "rgbd", "stereo"])
def test_the_graph_survives_hostile_messages(tmp_path, graph):
    """``markers``: JPEG input, so the ingest decodes it and the nodes read its outputs; ``rgbd`` and ``stereo``: raw
    images, no ingest node, the hostile camera messages (the right image and CameraInfo too) reach the SLAM, the
    tracker and the overlay themselves."""
    r = fuzz_graph.fuzz_graph(graph, 600, seed=0, work=tmp_path, echo=lambda *_: None)
    assert sum(r["sent"].values()) >= 550
    if graph == "markers":
        assert r["nodes"][0] == "ingest"
        assert "/camera/image_raw/compressed" in r["sent"] and "/simreal/camera/camera_info" in r["sent"]
    else:
        assert "ingest" not in r["nodes"] and not any(t.startswith("/simreal/camera") for t in r["sent"])
        cams = {"rgbd": {"/camera/depth/image_raw"}, "stereo": {"/camera/right/image_raw", "/camera/right/camera_info"}}
        assert {"/camera/image_raw", "/camera/camera_info"} | cams[graph] <= set(r["sent"])
    for name, s in r["per_node"].items():
        assert s["alive"] and not s["exit_codes"], (name, r["log_tail"])
        assert not s["unexpected"], (name, s["unexpected"])
        assert s["done_after_fuzz"] > 0, (name, "no valid frame finished after the fuzz")
    assert sum(sum(s["rejected"].values()) for s in r["per_node"].values()) > 0  # the fuzz reached the checks


def test_the_log_keeps_each_traceback_whole():
    lines = ["[tracker] [INFO] [1.0] [tracker]: up",
             "[tracker] [ERROR] [2.0] [tracker]: process failed: ValueError: need at least one array",
             "[tracker] Traceback (most recent call last):",
             '[tracker]   File "/x/tracker.py", line 9, in fit',
             "[tracker]     np.concatenate(parts)",
             "[tracker] ValueError: need at least one array",
             "[tracker] [INFO] [3.0] [tracker]: frame 7"]
    assert fuzz_graph.error_lines(lines) == lines[1:6]
