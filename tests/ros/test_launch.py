"""`simreal launch`: only the required nodes, each its own process; SIGTERM / SIGINT stop all cleanly."""

import signal
import subprocess
import sys
import textwrap
import time

import psutil
import pytest

pytest.importorskip("rclpy")

from simreal_nodes.launch import ros_environment

pytestmark = pytest.mark.ros

SCENE = """
simreal_scene: 1
name: cam_only
localization: {mode: static, static_pose: [0, 0, 0, 0, 0, 0, 1]}
overlay: {enabled: false}
"""


def node_children(proc):
    return [c for c in psutil.Process(proc.pid).children(recursive=True)
            if "simreal_nodes.ros.nodes" in " ".join(c.cmdline())]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_launch_starts_required_nodes_and_stops_cleanly(tmp_path, sig):
    f = tmp_path / "scene.yaml"
    f.write_text(textwrap.dedent(SCENE))
    env = ros_environment()
    env["ROS_LOG_DIR"] = str(tmp_path / "logs")
    p = subprocess.Popen([sys.executable, "-m", "simreal_nodes.cli", "launch", str(f)], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        t_end = time.monotonic() + 20
        kids = []
        while time.monotonic() < t_end:
            kids = node_children(p)
            if kids:
                break
            time.sleep(0.2)
        time.sleep(2.0)
        kids = node_children(p)
        assert [k.cmdline()[2] for k in kids] == ["simreal_nodes.ros.nodes.ingest"]
        p.send_signal(sig)
        out, _ = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, out
    assert "ingest: exit code 0" in out
    assert not any(k.is_running() and k.status() != psutil.STATUS_ZOMBIE for k in kids)
    assert (tmp_path / "logs").exists()


def test_launch_rejects_a_bad_scene_with_one_line(tmp_path):
    f = tmp_path / "scene.yaml"
    f.write_text(SCENE.replace("mode: static", "mode: orbslam"))
    r = subprocess.run([sys.executable, "-m", "simreal_nodes.cli", "launch", str(f)], capture_output=True, text=True,
                       env=ros_environment(), timeout=60)
    assert r.returncode == 2
    assert "localization.mode: expected one of" in r.stderr and "found 'orbslam'" in r.stderr
    assert "Traceback" not in r.stderr
