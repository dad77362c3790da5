"""`anchor: registration` through the node graph: the tracker node takes the depth images and places the beam
of a family scene (its scene file gives only a guess by eye) before it tracks it."""

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")

from simreal_nodes.io import bags
from simreal_nodes.ros.commands import replay

pytestmark = pytest.mark.ros


def _registers_through_the_graph(tmp_path, *sensor: str) -> None:
    """A family scene's bag (320x240, 1.4 s) replayed through the graph: the beam waits for its registration, is
    placed, then tracked."""
    from simreal_nodes.cli import main

    assert main(["make-bag", "family", "--seed", "3", *sensor, "-o", str(tmp_path / "fam"), "--resolution", "320x240",
                 "--duration", "1.4", "--fps", "15", "--ssaa", "1", "--scene-out", str(tmp_path / "fam.yaml"),
                 "-q"]) == 0
    if sensor:
        topics = bags.bag_topics(tmp_path / "fam")
        assert "/camera/right/image_raw" in topics and "/camera/depth/image_raw" not in topics
    out = tmp_path / "out"
    _stats, report, _counts = replay(str(tmp_path / "fam"), str(tmp_path / "fam.yaml"), lossless=True,
                                     record=str(out), echo=lambda *_: None)
    assert report.problems == 0
    params = [bags.decode(m) for m in bags.read_bag(out, topics=["/simreal/objects/beam/parameters"])]
    reasons = [p.reason for p in params]
    assert reasons and reasons[0].startswith("waiting for registration")
    assert not reasons[-1].startswith("waiting for registration"), reasons[-1]  # placed, then tracked


def test_tracker_node_registers_the_beam_from_depth(tmp_path):
    _registers_through_the_graph(tmp_path)


def test_tracker_node_registers_the_beam_from_a_stereo_pair(tmp_path):
    """The same scene through a stereo pair: no depth topic; the tracker node matches the pair itself (SGBM) and
    places the beam from that depth."""
    _registers_through_the_graph(tmp_path, "--sensor", "stereo")
