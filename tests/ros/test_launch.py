"""`simreal launch`: only the required nodes, in one process (the default) or each in its own; SIGTERM / SIGINT stop
all cleanly."""

import signal
import subprocess
import sys
import textwrap
import time

import psutil
import pytest

pytest.importorskip("rclpy")

from simreal_nodes.launch import ONE_PROCESS, ros_environment

pytestmark = pytest.mark.ros

SCENE = """
simreal_scene: 1
name: cam_only
localization: {mode: static, static_pose: [0, 0, 0, 0, 0, 0, 1]}
overlay: {enabled: false}
"""

# two nodes (the ingest kept by ``camera.ingest: always``), so the default launch has a process to share
TWO_NODES = """
simreal_scene: 1
name: cam_and_markers
camera: {ingest: always}
localization: {mode: markers, markers: {poses: {0: [0, 0, 0, 0, 0, 0, 1]}}}
overlay: {enabled: false}
"""


def node_children(proc):
    """The node processes of a launcher: one per node, or the one process that runs them all."""
    return [c for c in psutil.Process(proc.pid).children(recursive=True)
            if any(m in " ".join(c.cmdline()) for m in ("simreal_nodes.ros.nodes", "simreal_nodes.ros.compose"))]


@pytest.mark.parametrize("sig, mode", [(signal.SIGTERM, None), (signal.SIGINT, None),
                                       (signal.SIGINT, "--process-per-node")])
def test_launch_starts_required_nodes_and_stops_cleanly(tmp_path, sig, mode):
    f = tmp_path / "scene.yaml"
    f.write_text(textwrap.dedent(TWO_NODES))
    env = ros_environment()
    env["ROS_LOG_DIR"] = str(tmp_path / "logs")
    p = subprocess.Popen([sys.executable, "-m", "simreal_nodes.cli", "launch", str(f)] + ([mode] if mode else []),
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    import threading

    lines: list[str] = []
    up = threading.Event()
    # both nodes built (in the one process: by their own arguments), their handlers in place: a node signalled while
    # still importing rclpy (a loaded host) dies in the import, which is not what this test is about
    ready = {"camera ingest from", "localization mode"}

    def read() -> None:
        assert p.stdout is not None
        for line in p.stdout:
            lines.append(line)
            ready.difference_update({m for m in ready if m in line})
            if not ready:
                up.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    kids = []
    try:
        assert up.wait(60), "the nodes did not come up:\n" + "".join(lines)
        kids = node_children(p)
        want = (["simreal_nodes.ros.nodes.ingest", "simreal_nodes.ros.nodes.localization"] if mode else
                ["simreal_nodes.ros.compose"])
        assert sorted(k.cmdline()[2] for k in kids) == want
        p.send_signal(sig)
        p.wait(30)
        reader.join(10)
    finally:
        if p.poll() is None:
            p.kill()
    out = "".join(lines)
    assert p.returncode == 0, out
    assert ("ingest: exit code 0" if mode else f"{ONE_PROCESS}: exit code 0") in out
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


def test_a_killed_tracker_is_replaced_by_its_standby_mid_replay(tmp_path, monkeypatch):
    """kill -9 of the tracker during a live replay: the launcher promotes its standby process, which builds the
    node in its already discovered participant and publishes estimates again before the replay ends."""
    import os
    import threading

    import simreal_nodes.launch as launch
    from simreal_nodes.io import bags
    from simreal_nodes.ros import bagplay
    from simreal_nodes.ros.commands import replay
    from simreal_nodes.synth.samples import render_sample, sample

    pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")
    monkeypatch.setattr(launch, "STANDBY_DELAY_S", 0.2)
    name = "aluminium_beam_320x240"
    bag, scene = sample(name)
    if not bag.is_dir():
        render_sample(name, tmp_path)
        bag, scene = tmp_path / name, tmp_path / f"{name}.yaml"
    lines: list[str] = []
    ready, playing, killed = threading.Event(), threading.Event(), {}

    def echo(line: str) -> None:
        lines.append(line)
        if line.startswith("[tracker] standby ready"):
            ready.set()
        if line.startswith("[launch] started tracker (pid "):
            killed.setdefault("pids", []).append(int(line.split("(pid ")[1].split(")")[0]))

    def killer() -> None:
        if playing.wait(60) and ready.wait(30):
            time.sleep(0.5)
            killed["t"] = time.time()
            os.kill(killed["pids"][-1], signal.SIGKILL)

    original = bagplay.Player.play

    def play(self, *a, **kw):
        playing.set()
        return original(self, *a, **kw)

    monkeypatch.setattr(bagplay.Player, "play", play)
    th = threading.Thread(target=killer, daemon=True)
    th.start()
    out = tmp_path / "rec"
    replay(str(bag), str(scene), rate=0.25, record=str(out), echo=echo, standby=True)  # 2 s of frames over 8 s
    th.join(5)
    text = "\n".join(lines)
    assert "t" in killed, text
    assert "[launch] tracker exited with code -9; restarting (1/2)" in text
    promoted = [x for x in lines if x.startswith("[launch] started tracker") and x.endswith("from its standby")]
    assert len(promoted) == 1, text
    after = [m for m in bags.read_bag(out, topics=["/simreal/objects/beam/parameters"])
             if m.log_time_ns * 1e-9 > killed["t"]]
    assert len(after) > 5, text  # estimates again, from the promoted process


def test_nodes_end_when_their_launcher_is_killed(tmp_path):
    """`kill -9` of `simreal launch` itself: its nodes (in their own sessions, out of the terminal's reach) get
    SIGTERM from the kernel and end, instead of publishing on with nobody to stop them."""
    f = tmp_path / "scene.yaml"
    f.write_text(textwrap.dedent(SCENE))
    env = ros_environment() | {"ROS_LOG_DIR": str(tmp_path / "logs")}
    import threading

    p = subprocess.Popen([sys.executable, "-m", "simreal_nodes.cli", "launch", str(f), "--no-standby"], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    up = threading.Event()

    def read() -> None:
        for line in p.stdout:
            if "camera ingest from" in line:
                up.set()  # the node is built: past run_node's start, where it asked for the signal

    threading.Thread(target=read, daemon=True).start()
    kids = []
    try:
        assert up.wait(30), "the node did not come up"
        kids = node_children(p)
        assert kids, "no node process"
        p.kill()
        p.wait(10)
        _gone, alive = psutil.wait_procs(kids, timeout=15)
        assert not alive, [k.cmdline() for k in alive]
    finally:
        for k in kids:
            if k.is_running():
                k.kill()
