"""`simreal replay`: a multi-process graph fed from a bag; lossless mode loses nothing; bad input
is reported, not fatal."""

import textwrap

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")

from simreal_nodes.io import bags
from simreal_nodes.ros.commands import replay
from tests.helpers import write_camera_bag

pytestmark = pytest.mark.ros

SCENE = """
simreal_scene: 1
name: camera_only
camera: {depth: /camera/depth/image_raw}
localization: {mode: static, static_pose: [0, 0, 0, 0, 0, 0, 1]}
overlay: {enabled: false}
"""


@pytest.fixture
def scene(tmp_path):
    f = tmp_path / "scene.yaml"
    f.write_text(textwrap.dedent(SCENE))
    return str(f)


def recorded(path, topic):
    return [bags.decode(m) for m in bags.read_bag(path, topics=[topic])]


def test_lossless_replay_loses_no_frame_and_keeps_order(tmp_path, scene):
    stamps = write_camera_bag(tmp_path / "in", n=60, w=320, h=240, depth=True)
    out = tmp_path / "out"
    stats, report, _counts = replay(str(tmp_path / "in"), scene, lossless=True, record=str(out), echo=lambda *_: None)
    assert report.problems == 0
    assert stats.frames_published == 60 and stats.frames_completed == 60
    imgs = recorded(out, "/simreal/camera/image")
    assert [bags.stamp_ns(m) for m in imgs] == stamps  # 0 of N lost, in order
    from tests.helpers import frame_pixels
    first = np.frombuffer(bytes(imgs[17].data), np.uint8).reshape(240, 320, 3)
    np.testing.assert_array_equal(first, frame_pixels(17, 320, 240))
    depth = recorded(out, "/simreal/camera/depth")
    assert len(depth) == 60
    infos = recorded(out, "/simreal/camera/camera_info")
    assert len(infos) == 60 and infos[0].k[0] == pytest.approx(500.0)
    diags = recorded(out, "/diagnostics")
    assert any(s.name == "simreal/ingest" for d in diags for s in d.status)


def test_with_frames_in_flight_a_lossless_replay_still_loses_none_and_keeps_order(tmp_path, scene):
    """`--in-flight 3`: up to three frames in the graph at once, every one still through every node in order; dropped
    frames counted as such (not as finished, not twice); images counted, not written, when told so."""
    stamps = write_camera_bag(tmp_path / "in", n=60, w=320, h=240, depth=True)
    out = tmp_path / "out"
    stats, report, counts = replay(str(tmp_path / "in"), scene, lossless=True, record=str(out),
                                   echo=lambda *_: None, in_flight=3, record_images=False)
    assert report.problems == 0
    assert stats.frames_published == 60 and stats.frames_completed == 60
    assert stats.frames_dropped == stats.frames_timed_out == stats.conflicting_reports == 0
    # the images were received (counted) but not written; the rest was written
    assert counts["/simreal/camera/image"] == 60 and counts["/simreal/camera/depth"] == 60
    assert recorded(out, "/simreal/camera/image") == [] and recorded(out, "/simreal/camera/depth") == []
    infos = recorded(out, "/simreal/camera/camera_info")
    assert [bags.stamp_ns(m) for m in infos] == stamps  # 0 of N lost, in order

    write_camera_bag(tmp_path / "bad", n=20, w=160, h=120, bad_step=(3, 7, 8))
    stats, _, _ = replay(str(tmp_path / "bad"), scene, lossless=True, record=str(tmp_path / "out_bad"),
                         echo=lambda *_: None, frame_timeout_s=10, in_flight=3)
    assert stats.frames_published == 20
    assert stats.frames_dropped == 3 and stats.frames_completed == 17 and stats.frames_timed_out == 0
    assert len(recorded(tmp_path / "out_bad", "/simreal/camera/image")) == 17


def test_malformed_images_and_zero_camera_info_are_dropped_with_reasons(tmp_path, scene):
    write_camera_bag(tmp_path / "bad", n=20, w=160, h=120, bad_step=(3, 7, 8))
    out = tmp_path / "out_bad"
    stats, _, _ = replay(str(tmp_path / "bad"), scene, lossless=True, record=str(out), echo=lambda *_: None,
                         frame_timeout_s=10)
    assert stats.frames_published == 20
    assert stats.frames_dropped == 3 and stats.frames_completed == 17 and stats.frames_timed_out == 0
    assert any("step" in why for why in stats.drop_reasons)
    assert len(recorded(out, "/simreal/camera/image")) == 17  # the node kept going

    write_camera_bag(tmp_path / "zero", n=10, w=160, h=120, zero_info=True)
    stats, _, _ = replay(str(tmp_path / "zero"), scene, lossless=True, record=str(tmp_path / "out_zero"),
                         echo=lambda *_: None, frame_timeout_s=10)
    assert stats.frames_dropped == 10
    assert any("focal lengths must be positive" in why for why in stats.drop_reasons)
    # diagnostics say why, and the recorded output is readable
    diags = recorded(tmp_path / "out_zero", "/diagnostics")
    msgs = [s.message for d in diags for s in d.status if s.name == "simreal/ingest"]
    assert any("CameraInfo" in m for m in msgs)


def test_without_an_ingest_the_nodes_drop_malformed_frames_with_reasons(tmp_path):
    """A raw camera needs no ingest node (issue 18): the overlay reads the camera's topics itself. A malformed
    image or an unusable CameraInfo is then its drop, with the reason the ingest would have given, and the lossless
    player accounts for every frame without waiting out a timeout."""
    f = tmp_path / "overlay.yaml"
    f.write_text(textwrap.dedent(SCENE.replace("overlay: {enabled: false}", "overlay: {enabled: true}")))
    write_camera_bag(tmp_path / "bad", n=20, w=160, h=120, bad_step=(3, 7, 8), depth=True)
    out = tmp_path / "out_bad"
    lines: list[str] = []
    stats, _, counts = replay(str(tmp_path / "bad"), str(f), lossless=True, record=str(out), echo=lines.append,
                              frame_timeout_s=10)
    assert ("[replay] nodes: overlay (no ingest: the nodes read /camera/image_raw and its CameraInfo themselves; "
            "a process per node)") in lines
    assert stats.frames_published == 20
    assert stats.frames_dropped == 3 and stats.frames_completed == 17 and stats.frames_timed_out == 0
    assert any("step" in why for why in stats.drop_reasons)
    assert counts["/simreal/overlay/image_raw"] == 17 and "/simreal/camera/image" not in counts  # no ingest ran
    assert {s.name for d in recorded(out, "/diagnostics") for s in d.status} == {"simreal/overlay"}

    write_camera_bag(tmp_path / "zero", n=10, w=160, h=120, zero_info=True, depth=True)
    stats, _, _ = replay(str(tmp_path / "zero"), str(f), lossless=True, record=str(tmp_path / "out_zero"),
                         echo=lambda *_: None, frame_timeout_s=10)
    assert stats.frames_dropped == 10 and stats.frames_timed_out == 0
    assert any("unusable CameraInfo: " in why and "focal lengths must be positive" in why for why in stats.drop_reasons)


def test_replays_one_after_another_in_one_process_keep_no_memory(tmp_path, scene):
    """Each replay shuts its executor down: rclpy's EventsExecutor kept the native memory of what it had received
    until then (stop 82: with the shutdown removed, this test measured +338 MB between the first replay and the
    third; with it, +5 MB)."""
    import gc

    import psutil

    write_camera_bag(tmp_path / "in", n=90, w=640, h=480)
    rss = []
    for i in range(3):
        stats, _, _ = replay(str(tmp_path / "in"), scene, lossless=True, record=str(tmp_path / f"out{i}"),
                             echo=lambda *_: None, executor="events")
        assert stats.frames_completed == 90
        gc.collect()
        rss.append(psutil.Process().memory_info().rss / 1e6)
    assert rss[2] - rss[0] < 60, rss  # measured +5 MB; without the shutdown +340 MB


def test_sigint_during_a_lossless_replay_closes_a_readable_record(tmp_path, scene):
    """Ctrl-C in the middle of `simreal replay --lossless --record`: the player stops at the next frame, the nodes
    stop, and the record holds every output written so far, readable, with no damage."""
    import signal
    import subprocess
    import sys
    import time

    from simreal_nodes.launch import ros_environment

    n = 800
    write_camera_bag(tmp_path / "in", n=n, w=160, h=120, depth=True)
    out = tmp_path / "out"
    env = ros_environment() | {"ROS_LOG_DIR": str(tmp_path / "logs")}
    p = subprocess.Popen([sys.executable, "-m", "simreal_nodes.cli", "replay", str(tmp_path / "in"), "--scene", scene,
                          "--lossless", "--record", str(out)], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    try:
        t_end = time.monotonic() + 90
        while time.monotonic() < t_end and p.poll() is None and \
                sum(f.stat().st_size for f in out.glob("*") if f.is_file()) < 2_000_000:
            time.sleep(0.05)  # until the record holds some frames
        assert p.poll() is None, "the replay ended before the signal"
        p.send_signal(signal.SIGINT)
        text, _ = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, text
    assert "[replay] stopped by signal" in text
    report = bags.BagReport()
    images = [m for m in bags.read_bag(out, report) if m.topic == "/simreal/camera/image"]
    assert report.problems == 0, report.summary()
    assert 0 < len(images) < n, (len(images), text[-2000:])


def test_a_record_that_runs_out_of_space_stops_with_a_clear_error_and_stays_readable(tmp_path, scene):
    """The disk fills while recording (here: a file-size limit, which fails the write the same way): the replay says
    so in one line and exits 1, the nodes are unharmed, and what was written before reads back (salvaged)."""
    import resource
    import signal
    import subprocess
    import sys

    from simreal_nodes.launch import ros_environment

    write_camera_bag(tmp_path / "in", n=150, w=320, h=240, depth=True)  # 55 MB of outputs
    out = tmp_path / "out"
    limit = 40 << 20  # over Fast DDS's 32 MB shared-memory segment (a file too), under the record

    def small_files():  # in the child: writes past the limit fail with EFBIG instead of killing it (SIGXFSZ)
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    env = ros_environment() | {"ROS_LOG_DIR": str(tmp_path / "logs")}
    r = subprocess.run([sys.executable, "-m", "simreal_nodes.cli", "replay", str(tmp_path / "in"), "--scene", scene,
                        "--lossless", "--record", str(out)], env=env, capture_output=True, text=True, timeout=180,
                       preexec_fn=small_files)
    text = r.stdout + r.stderr
    assert r.returncode == 1, text
    assert "[replay] error: recording to" in text and "File too large" in text, text[-3000:]
    assert "Traceback" not in text, text[-3000:]
    assert "published 150 frames" in text  # the replay went on to its end
    assert "SHM Transport" not in text  # the nodes' transport was not hit by the limit
    report = bags.BagReport()
    images = [m for m in bags.read_bag(out, report) if m.topic == "/simreal/camera/image"]
    assert images and report.salvaged, report.summary()
    assert sum(f.stat().st_size for f in out.glob("*")) <= limit


def test_a_record_of_images_counted_only_leaves_out_the_camera_images_the_ingest_passes_on():
    """`replay(record_images=False)` (the graph benchmark's harness): the graph's images are counted, not written,
    and the camera images an ingest passes on to the other nodes are not subscribed; an ingest alone keeps its
    images (they are its product), and `record_images=True` writes every output."""
    from pathlib import Path

    from simreal_nodes.ros.commands import recorded_topics
    from simreal_nodes.scene.graph import CAM_DEPTH, CAM_IMAGE, OVERLAY_IMAGE, required_nodes
    from simreal_nodes.scene.schema import load_scene

    sample = Path(__file__).resolve().parents[2] / "bags" / "samples" / "aluminium_beam_320x240.yaml"
    nodes = required_nodes(load_scene(sample), lossless=True, source="topic")
    assert nodes[0].name == "ingest" and len(nodes) > 1  # its JPEG images keep the ingest
    every, none = recorded_topics(nodes, record_images=True)
    assert CAM_IMAGE in every and none == ()
    topics, counted = recorded_topics(nodes, record_images=False)
    assert CAM_IMAGE not in topics and OVERLAY_IMAGE in counted
    assert set(counted) <= set(topics) and set(topics) == set(every) - {CAM_IMAGE, CAM_DEPTH}
    alone = [n for n in nodes if n.name == "ingest"]
    topics, counted = recorded_topics(alone, record_images=False)
    assert CAM_IMAGE in topics and CAM_IMAGE in counted
