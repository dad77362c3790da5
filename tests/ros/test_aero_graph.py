"""The car aerodynamics through the node graph (thesis ch. 6): a rendered RGB-D clip circling a held-out car is
replayed into ingest -> localization (RGB-D SLAM, capture cloud) -> aero (Alg. 6.1, Eq. 6.4, streamlines) -> overlay;
the flow's body lies on the true car and the overlay draws the streamlines over the video. The small database
(tests/conftest.py) stands in for the full one (a coarse grid; the flow's accuracy is measured by
benchmarks/aero_video.py, not here)."""

import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy")
pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")

from scipy.spatial import cKDTree

from simreal_nodes.io import bags
from simreal_nodes.io.cdr import LINE_STRIP, TRIANGLE_LIST
from simreal_nodes.ros.commands import replay
from simreal_nodes.synth.car_video import car_aero_scene

pytestmark = pytest.mark.ros


def test_the_car_is_captured_and_its_flow_drawn_through_the_graph(tmp_path, small_aero_db):
    from simreal_nodes.cli import main

    bag, scene = tmp_path / "car", tmp_path / "car.yaml"
    assert main(["make-bag", "car_aero", "-o", str(bag), "--resolution", "320x240", "--duration", "4",
                 "--ssaa", "1", "--scene-out", str(scene), "-q"]) == 0
    doc = yaml.safe_load(scene.read_text())
    assert doc["aero"]["enabled"] and doc["localization"]["mode"] == "rgbd"
    doc["aero"].update({"database": str(small_aero_db[1]), "neighbours": 3, "min_points": 300})
    scene.write_text(yaml.safe_dump(doc))
    out = tmp_path / "out"
    stats, report, _ = replay(str(bag), str(scene), lossless=True, record=str(out), echo=lambda *_: None)
    assert report.problems == 0 and stats.frames_completed == 120
    flows = [bags.decode(m) for m in bags.read_bag(out, topics=["/simreal/aero/flow"])]
    assert flows, "the aero node published no flow"
    last = flows[-1].markers
    body = [m for m in last if m.ns == "aero/body"]
    lines = [m for m in last if m.ns == "aero/streamlines"]
    assert len(body) == 1 and body[0].type == TRIANGLE_LIST and body[0].header.frame_id == "map"
    assert len(lines) >= 30 and all(m.type == LINE_STRIP for m in lines)
    # the captured body lies on the car: its vertices, in the world, near the true surface (one side seen in 4 s)
    sc = car_aero_scene("rgbd", 320, 240)
    T_world_map = np.linalg.inv(sc.T_map_world())
    V = np.array([[p.x, p.y, p.z] for p in body[0].points]) @ T_world_map[:3, :3].T + T_world_map[:3, 3]
    from simreal_nodes.aero.database import load_aero_spec

    spec = load_aero_spec("aero_cars.yaml")
    surf, _ = spec.cars()[spec.n_database].surface(120, 64)
    d, _ = cKDTree(surf).query(V)
    assert np.median(d) < 0.25, np.percentile(d, [50, 90])
    # the overlay drew the streamlines: the last frame differs from the camera's image over a good part of it, the
    # first (no flow yet) nowhere
    # the camera image: the bag's own (its raw images need no ingest node, so the graph has none and records none)
    cams = [bags.decode(m) for m in bags.read_bag(bag, topics=["/camera/image_raw"])]
    assert not list(bags.read_bag(out, topics=["/simreal/camera/image"]))
    ovs = [bags.decode(m) for m in bags.read_bag(out, topics=["/simreal/overlay/image_raw"])]

    # the flow carries the replayed frames' time (the capture cloud's stamp is the last tracked frame's, not the
    # wall clock's)
    def ns(st) -> int:
        return st.sec * 1_000_000_000 + st.nanosec

    frame_ns = {ns(c.header.stamp) for c in cams}
    assert all(ns(m.header.stamp) in frame_ns for f in flows for m in f.markers)

    def changed(k: int) -> float:
        assert cams[k].encoding == "rgb8" and ovs[k].encoding == "bgr8"
        a = np.asarray(cams[k].data, np.uint8).reshape(240, 320, 3)[..., ::-1]
        b = np.asarray(ovs[k].data, np.uint8).reshape(240, 320, 3)
        return float(np.mean(np.abs(a.astype(int) - b.astype(int)).max(axis=2) > 40))

    assert changed(0) == 0.0
    assert changed(-1) > 0.05
