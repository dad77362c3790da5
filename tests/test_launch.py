"""The launcher's environment for its node processes: DDS discovery stays on this host unless widened; the
libraries' thread pools sized to one thread unless asked; `run_until_signal`'s stop (a stub launcher, no
processes)."""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from simreal_nodes.errors import SimrealError
from simreal_nodes.launch import (
    DISCOVERY_RANGE,
    LLVMPIPE_THREADS,
    THREAD_VARS,
    THREADS_ENV,
    Launcher,
    node_threads,
    ros_environment,
    run_until_signal,
)
from simreal_nodes.scene.graph import NodeSpec

PRINT_ENV = f"import os; print('{DISCOVERY_RANGE}=' + repr(os.environ.get('{DISCOVERY_RANGE}')))"


def child_says(tmp_path, base: dict, code: str, key: str, **kw) -> str:
    """What a node process started by the launcher prints after ``key=`` (the node's command swapped for ``code``)."""
    lines: list[str] = []
    launcher = Launcher([NodeSpec("ingest")], respawn=0, env=base, echo=lines.append, log_dir=tmp_path / "log", **kw)
    launcher.procs[0].cmd = [sys.executable, "-c", code]
    with launcher:
        t_end = time.monotonic() + 30
        while not any(f"{key}=" in x for x in lines) and time.monotonic() < t_end:
            time.sleep(0.05)
    return next(x for x in lines if f"{key}=" in x).split(f"{key}=", 1)[1]


def child_discovery_range(tmp_path, base: dict, **kw) -> str:
    return child_says(tmp_path, base, PRINT_ENV, DISCOVERY_RANGE, **kw)


@pytest.mark.parametrize("user,option,seen", [
    (None, None, "'LOCALHOST'"),  # ROS 2's own default would be SUBNET
    ("", None, "'LOCALHOST'"),
    ("SUBNET", None, "'SUBNET'"),  # the user's environment widens it
    ("SUBNET", "LOCALHOST", "'LOCALHOST'"),  # the option wins over both
    (None, "SYSTEM_DEFAULT", "'SYSTEM_DEFAULT'"),
])
def test_node_processes_discover_on_localhost_unless_widened(tmp_path, user, option, seen):
    base = {"PATH": "/usr/bin:/bin"} | ({DISCOVERY_RANGE: user} if user is not None else {})
    assert child_discovery_range(tmp_path, base, discovery_range=option) == seen


def test_unknown_discovery_range_is_refused(tmp_path):
    with pytest.raises(SimrealError, match="DDS discovery range: expected one of LOCALHOST, SUBNET"):
        Launcher([NodeSpec("ingest")], env={}, discovery_range="WORLD", log_dir=tmp_path)


# what a node process's pools hold once it has started as run_nodes starts it: the OpenBLAS pools (numpy's and the
# one OpenCV bundles) as the environment sized them when they loaded, OpenCV's own as set_threads set it
PRINT_POOLS = ("import cv2, numpy, threadpoolctl\n"
               "from simreal_nodes.launch import node_threads, set_threads\n"
               "set_threads(node_threads())\n"
               "blas = [p['num_threads'] for p in threadpoolctl.threadpool_info() if p['internal_api'] == 'openblas']\n"
               "print(f'pools=blas {max(blas)} cv2 {cv2.getNumThreads()}', flush=True)")


def own_pools() -> dict[str, int]:
    """The pools of a process that no one sized (the libraries' own defaults)."""
    env = {"PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", PRINT_POOLS.replace("set_threads(node_threads())", "")], env=env,
                         capture_output=True, text=True, timeout=60, check=True).stdout
    _, blas, _, cv = out.split("pools=", 1)[1].split()
    return {"blas": int(blas), "cv": int(cv)}


CORES = os.cpu_count() or 1  # OpenBLAS takes no more threads than the cores


@pytest.mark.parametrize("user,option,seen", [
    ({}, None, "blas 1 cv2 {cv}"),  # the default: the linear algebra's pools one thread, OpenCV's its own
    ({"OPENBLAS_NUM_THREADS": "2"}, None, f"blas {min(2, CORES)} cv2 {{cv}}"),  # a pool the user sized is kept ...
    ({"OPENBLAS_NUM_THREADS": "2"}, 1, "blas 1 cv2 1"),  # ... unless the option says otherwise
    ({THREADS_ENV: "1", "OPENBLAS_NUM_THREADS": "2"}, None, "blas 1 cv2 1"),  # or the user's SIMREAL_THREADS
    ({THREADS_ENV: "3"}, None, f"blas {min(3, CORES)} cv2 3"),
    ({}, 0, "blas {blas} cv2 {cv}"),  # the libraries' own
])
def test_node_processes_size_the_libraries_pools(tmp_path, user, option, seen):
    got = child_says(tmp_path, {"PATH": "/usr/bin:/bin"} | user, PRINT_POOLS, "pools", threads=option).strip()
    assert got == seen.format(**own_pools())


@pytest.mark.parametrize("user,option,seen", [
    ({}, None, "1"),
    ({"OMP_NUM_THREADS": "4"}, None, {"OMP_NUM_THREADS": "4", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}),
    ({"OMP_NUM_THREADS": "4"}, 2, "2"),
    ({THREADS_ENV: "3"}, None, "3"),
    ({"MKL_NUM_THREADS": "4"}, 0, {"OMP_NUM_THREADS": None, "OPENBLAS_NUM_THREADS": None, "MKL_NUM_THREADS": "4"}),
])
def test_every_pool_variable_is_set(user, option, seen):
    env = ros_environment(user, threads=option)
    want = seen if isinstance(seen, dict) else dict.fromkeys(THREAD_VARS, seen)
    assert {k: env.get(k) for k in THREAD_VARS} == want
    # llvmpipe's rasterizer threads besides the rendering one: sized only when the threads per pool are given
    n = option if option is not None else int(user[THREADS_ENV]) if THREADS_ENV in user else None
    assert env.get(LLVMPIPE_THREADS) == (str(n - 1) if n else None)


def test_the_threads_option_reaches_the_replay(monkeypatch):
    """`--threads` on launch, replay and demo: parsed, refused when bad, and passed on (the demo's to its replay)."""
    from simreal_nodes.cli import build_parser
    from simreal_nodes.ros import commands

    p = build_parser()
    for cmd in (["launch", "s.yaml"], ["replay", "b", "--scene", "s.yaml"], ["demo"]):
        assert p.parse_args([*cmd, "--threads", "2"]).threads == 2
        assert p.parse_args(cmd).threads is None
        with pytest.raises(SystemExit):
            p.parse_args([*cmd, "--threads", "-1"])
    seen = {}

    class Reached(Exception):
        pass

    def fake_replay(*a, **kw):
        seen.update(kw)
        raise Reached

    import simreal_nodes.demo

    real_replay = commands.replay
    monkeypatch.setattr(commands, "replay", fake_replay)
    monkeypatch.setattr(simreal_nodes.demo, "run_demo", fake_replay)
    for cmd in (["replay", "b", "--scene", "s.yaml"], ["demo"]):
        seen.clear()
        a = p.parse_args([*cmd, "--threads", "3"])
        with pytest.raises(Reached):
            a.fn(a)
        assert seen["threads"] == 3
    # a bad SIMREAL_THREADS is refused before the replay reads anything
    monkeypatch.setenv(THREADS_ENV, "many")
    with pytest.raises(SimrealError, match="whole number >= 0"):
        real_replay("no-such-bag", "no-such-scene.yaml")


@pytest.mark.parametrize("raw", ["-1", "two", "1.5"])
def test_a_bad_thread_count_is_refused(raw):
    with pytest.raises(SimrealError, match="whole number >= 0"):
        node_threads({THREADS_ENV: raw})
    with pytest.raises(SimrealError, match="whole number >= 0"):
        ros_environment({THREADS_ENV: raw})


# A stand-in for a node's process: a standby says it is ready and waits for the promotion line; a node (or a
# promoted standby) says so and runs until it is signalled.
FAKE_NODE = """
import os, sys, time
if os.environ.get("SIMREAL_STANDBY") == "1":
    print("standby ready", flush=True)
    line = sys.stdin.readline()
    if line.strip() != "go":
        print("standby ends", flush=True)
        sys.exit(0)
print(f"node up in {os.getpid()}", flush=True)
while True:
    time.sleep(0.05)
"""


def fake_launcher(tmp_path, respawn: int, standby: bool) -> tuple[Launcher, list[str]]:
    """A launcher of one node whose command is FAKE_NODE; the lines it echoes."""
    lines: list[str] = []
    launcher = Launcher([NodeSpec("ingest")], respawn=respawn, env={"PATH": "/usr/bin:/bin"}, echo=lines.append,
                        log_dir=tmp_path / "log", standby=standby)
    launcher.procs[0].cmd = [sys.executable, "-c", FAKE_NODE]
    return launcher, lines


def wait_for(cond, timeout: float = 20.0) -> None:
    t_end = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < t_end, "timed out"
        time.sleep(0.02)


def test_a_node_that_exits_is_replaced_by_its_standby(tmp_path, monkeypatch):
    import simreal_nodes.launch as launch

    monkeypatch.setattr(launch, "STANDBY_DELAY_S", 0.3)
    launcher, lines = fake_launcher(tmp_path, respawn=2, standby=True)
    p = launcher.procs[0]
    with launcher:
        wait_for(lambda: "[ingest] standby ready" in lines)
        first, standby = p.popen, p.standby
        assert first is not None and standby is not None and standby.pid != first.pid
        first.kill()
        wait_for(lambda: p.popen is not first)
        assert p.popen is standby  # promoted, not a new process
        assert f"[launch] started ingest (pid {standby.pid}) from its standby" in lines
        wait_for(lambda: f"[ingest] node up in {standby.pid}" in lines)
        wait_for(lambda: p.standby is not None)  # the next standby follows after the delay
        second = p.standby
        assert second.pid not in (first.pid, standby.pid)
        wait_for(lambda: lines.count("[ingest] standby ready") == 2)
        assert p.restarts == 1
    assert standby.poll() is not None and second.poll() == 0  # the standby ended at the EOF of its stdin
    assert "[ingest] standby ends" in lines


def test_a_replay_starts_the_standbys_before_its_first_frame(tmp_path):
    """``start_standbys`` starts a standby due only after the (default, 5 s) delay at once and returns when it has
    said it is ready: a replay plays its first frame only then (the standbys' imports took the nodes' CPU in the
    first seconds of the bag, stop 87). A launcher without standbys has none to wait for."""
    launcher, lines = fake_launcher(tmp_path, respawn=2, standby=True)
    p = launcher.procs[0]
    with launcher:
        assert p.standby is None and p.standby_due is not None  # waiting for its delay
        t0 = time.monotonic()
        assert launcher.start_standbys(timeout_s=20.0)
        assert time.monotonic() - t0 < 4.0  # not the delay
        assert p.standby is not None and p.standby_ready and "[ingest] standby ready" in lines
        assert p.standby.poll() is None
    plain, _ = fake_launcher(tmp_path, respawn=2, standby=False)
    with plain:
        assert plain.start_standbys(timeout_s=0.0)


BUSY_NODE = """
import sys, time
t_end = time.monotonic() + float(sys.argv[1])
while time.monotonic() < t_end:
    pass
print("idle", flush=True)
while True:
    time.sleep(0.05)
"""


@pytest.mark.parametrize("busy_s", [0.8, 60.0])
def test_a_replay_waits_for_the_graph_to_go_quiet_before_its_first_frame(tmp_path, busy_s):
    """Issue 18: ``wait_quiet`` returns once the processes the launcher started use (almost) no CPU: not while a
    node works (here a node that spins for ``busy_s``), and False at its timeout when the graph never goes quiet
    (a live replay that started while the standbys' participants were being discovered lost 8-10 of the demo's
    first frames in 3 of 5 runs)."""
    launcher, lines = fake_launcher(tmp_path, respawn=0, standby=False)
    launcher.procs[0].cmd = [sys.executable, "-c", BUSY_NODE, str(busy_s)]
    with launcher:
        t0 = time.monotonic()
        quiet = launcher.wait_quiet(timeout_s=3.0)
        waited = time.monotonic() - t0
        if busy_s < 3.0:
            assert quiet and waited >= busy_s - 0.3 and "[ingest] idle" in lines
        else:
            assert not quiet and 3.0 <= waited < 4.0
            t0 = time.monotonic()  # a stop (Ctrl-C) ends the wait at the next window
            assert not launcher.wait_quiet(timeout_s=30.0, should_stop=lambda: time.monotonic() - t0 > 0.5)
            assert time.monotonic() - t0 < 1.5


def test_without_standby_a_restart_is_a_new_process(tmp_path):
    launcher, lines = fake_launcher(tmp_path, respawn=1, standby=False)
    p = launcher.procs[0]
    with launcher:
        wait_for(lambda: any(x.startswith("[ingest] node up") for x in lines))
        first = p.popen
        assert first is not None and p.standby is None
        first.kill()
        wait_for(lambda: p.popen is not first and p.popen is not None)
        assert p.standby is None and not any("from its standby" in x or "standby for" in x for x in lines)
        wait_for(lambda: p.popen.poll() is None and sum(x.startswith("[ingest] node up") for x in lines) == 2)
        p.popen.kill()  # respawn=1: the second exit is the last
        wait_for(lambda: p.popen is None)
    assert lines[-1].startswith("[launch] ingest exited with code -9; not restarting") or \
        any("not restarting" in x for x in lines)


SAMPLES = Path(__file__).resolve().parents[1] / "bags" / "samples"


class Reached(Exception):
    """Raised by :func:`catch_launcher`'s stand-in: the launch got as far as starting the nodes."""


def catch_launcher(monkeypatch, module) -> dict:
    """Swap ``module``'s Launcher for one that records its keyword arguments (returned) and raises :class:`Reached`;
    the scene's models are not built (the launch's pick needs none)."""
    import simreal_nodes.scene.schema

    seen: dict = {}

    def fake_launcher(nodes, **kw):
        seen.update(kw)
        raise Reached

    monkeypatch.setattr(module, "Launcher", fake_launcher)
    monkeypatch.setattr(module if hasattr(module, "build_spec_models") else simreal_nodes.scene.schema,
                        "build_spec_models", lambda s: s)
    return seen


@pytest.mark.parametrize("sample,lossless,in_flight,groups", [
    ("aluminium_beam_320x240", False, 1, [4]),  # markers: one process, live too
    ("crossed_beams_probe_320x240", False, 1, [1, 1, 1, 1]),  # RGB-D SLAM live: a process per node
    ("crossed_beams_probe_320x240", True, 1, [4]),  # lossless, lock-step: one process
    ("aluminium_beam_320x240", True, 3, [1, 1, 1, 1]),  # lossless with frames in flight: a process per node
    ("crossed_beams_probe_320x240", True, 3, [1, 1, 1, 1]),  # ... with a slow node too (split: a choice)
    ("aluminium_beam_320x240", False, 3, [4]),  # live: the player's in-flight bound does not apply
])
def test_a_replay_picks_the_launch_the_cli_left_open(monkeypatch, sample, lossless, in_flight, groups):
    """`simreal replay` without --one-process / --process-per-node: the scene's pick
    (scene.graph.default_launch) reaches the launcher."""
    from simreal_nodes.ros import commands

    seen = catch_launcher(monkeypatch, commands)
    with pytest.raises(Reached):
        commands.replay(str(SAMPLES / sample), str(SAMPLES / f"{sample}.yaml"), lossless=lossless, one_process=None,
                        echo=lambda *a: None, in_flight=in_flight)
    assert [len(g) for g in seen["groups"]] == groups


def test_the_in_flight_option_is_parsed_refused_when_bad_and_reaches_the_replay(monkeypatch):
    """`simreal replay --in-flight N`: a whole number >= 1 (default 1, lock-step), passed on to the player."""
    from simreal_nodes.cli import build_parser
    from simreal_nodes.ros import commands

    p = build_parser()
    cmd = ["replay", "b", "--scene", "s.yaml", "--lossless"]
    assert p.parse_args(cmd).in_flight == 1
    assert p.parse_args([*cmd, "--in-flight", "4"]).in_flight == 4
    assert p.parse_args([*cmd, "--in-flight", "15"]).in_flight == 15
    for bad in ("0", "-2", "1.5", "two", "16"):
        with pytest.raises(SystemExit):
            p.parse_args([*cmd, "--in-flight", bad])
    seen = {}

    def fake_replay(*a, **kw):
        seen.update(kw)
        raise Reached

    real_replay = commands.replay
    monkeypatch.setattr(commands, "replay", fake_replay)
    a = p.parse_args([*cmd, "--in-flight", "3"])
    with pytest.raises(Reached):
        a.fn(a)
    assert seen["in_flight"] == 3
    # the function refuses what the parser would, before it reads anything
    for bad in (0, -1, 2.0, True, 16):
        with pytest.raises(SimrealError, match="frames in flight"):
            real_replay("no-such-bag", "no-such-scene.yaml", in_flight=bad)
    # live, the bound means nothing: said, not silently ignored
    said = []
    with pytest.raises(SimrealError):  # (then the scene is missing)
        real_replay("no-such-bag", "no-such-scene.yaml", in_flight=3, echo=said.append)
    assert any("live replay" in m and "--lossless" in m for m in said)


@pytest.mark.parametrize("sample,lossless,one", [
    ("aluminium_beam_320x240", False, True),
    ("crossed_beams_probe_320x240", False, False),
    ("crossed_beams_probe_320x240", True, True),
])
def test_simreal_launch_picks_the_launch_it_was_not_told(monkeypatch, capsys, sample, lossless, one):
    """`simreal launch SCENE` without --one-process / --process-per-node: the scene's pick reaches the launcher and
    its first line says so; told, the flag wins."""
    import simreal_nodes.launch
    from simreal_nodes.cli import build_parser

    seen = catch_launcher(monkeypatch, simreal_nodes.launch)
    p = build_parser()
    a = p.parse_args(["launch", str(SAMPLES / f"{sample}.yaml"), *(["--lossless"] if lossless else [])])
    assert a.one_process is None
    with pytest.raises(Reached):
        a.fn(a)
    assert (len(seen["groups"]) == 1) is one
    assert ("in one process" if one else "a process per node") in capsys.readouterr().out
    for flag, told in (("--one-process", True), ("--process-per-node", False)):
        a = p.parse_args(["launch", str(SAMPLES / f"{sample}.yaml"), flag])
        with pytest.raises(Reached):
            a.fn(a)
        assert (len(seen["groups"]) == 1) is told


@pytest.mark.parametrize("sample,apart", [
    ("crossed_beams_probe_320x240", ["localization"]),  # RGB-D SLAM: the localization alone
    ("aluminium_beam_320x240", []),  # markers: no slow node, all in one process
])
def test_split_puts_the_slow_nodes_in_processes_of_their_own(monkeypatch, capsys, sample, apart):
    """`simreal launch SCENE --split` and `simreal replay --split`: each slow node alone, the others in one."""
    import simreal_nodes.launch
    from simreal_nodes.cli import build_parser
    from simreal_nodes.ros import commands

    seen = catch_launcher(monkeypatch, simreal_nodes.launch)
    a = build_parser().parse_args(["launch", str(SAMPLES / f"{sample}.yaml"), "--split"])
    assert a.one_process == "split"
    with pytest.raises(Reached):
        a.fn(a)
    groups = seen["groups"]
    assert [g for g in groups if len(g) == 1 and g[0] in apart] == [[n] for n in apart]
    shared = [g for g in groups if g[0] not in apart]
    assert len(shared) == 1 and len(shared[0]) >= 2 and not set(shared[0]) & set(apart)
    assert "split" in capsys.readouterr().out
    seen = catch_launcher(monkeypatch, commands)
    with pytest.raises(Reached):
        commands.replay(str(SAMPLES / sample), str(SAMPLES / f"{sample}.yaml"), lossless=True, one_process="split",
                        echo=lambda *a: None, in_flight=4)
    assert seen["groups"] == groups


class _StubLauncher:
    """What `run_until_signal` uses of a Launcher, without processes: nodes that run until stopped (or have exited,
    ``exited``), and a log of what it was asked."""

    def __init__(self, exited: bool = False, codes: dict | None = None, signal_at_start: int | None = None):
        self.nodes = [NodeSpec("ingest"), NodeSpec("overlay")]
        self.respawn = 0
        self.procs = [type("P", (), {"restarts": 0})() for _ in self.nodes]
        self.lines: list[str] = []
        self.calls: list[str] = []
        self.exited = exited
        self.codes = codes if codes is not None else {"ingest": 0, "overlay": -signal.SIGINT}
        self.signal_at_start = signal_at_start  # sent 0.3 s after start(): the handlers are in place by then
        self.timer: threading.Timer | None = None

    def echo(self, line: str) -> None:
        self.lines.append(line)

    def start(self):
        self.calls.append("start")
        if self.signal_at_start is not None:
            self.timer = threading.Timer(0.3, os.kill, (os.getpid(), self.signal_at_start))
            self.timer.start()
        return self

    def alive(self) -> dict[str, bool]:
        return {n.name: not self.exited for n in self.nodes}

    def stop(self) -> dict:
        self.calls.append("stop")
        return self.codes


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_run_until_signal_stops_the_nodes_at_a_signal_and_puts_the_handlers_back(sig):
    before = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]
    launcher = _StubLauncher(signal_at_start=sig)
    t0 = time.monotonic()
    code = run_until_signal(launcher)
    launcher.timer.join()
    assert code == 0
    assert time.monotonic() - t0 < 5.0
    assert launcher.calls == ["start", "stop"]
    assert f"[launch] {signal.Signals(sig).name}: stopping 2 nodes" in launcher.lines
    assert "[launch] overlay: exit code -2" in launcher.lines
    assert [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)] == before


def test_run_until_signal_returns_1_when_a_node_failed_and_ends_when_all_have_exited():
    launcher = _StubLauncher(exited=True, codes={"ingest": 0, "overlay": 1})
    assert run_until_signal(launcher) == 1
    assert launcher.calls == ["start", "stop"]
    assert "[launch] every node has exited" in launcher.lines
    assert not any("stopping" in line for line in launcher.lines)


def test_run_until_signal_keeps_a_process_own_handler_and_says_so():
    def own(signum, frame):
        raise KeyboardInterrupt  # the owner's way to stop: it reaches the launcher as SIGINT would

    previous = signal.signal(signal.SIGTERM, own)
    try:
        launcher = _StubLauncher(signal_at_start=signal.SIGTERM)
        assert run_until_signal(launcher) == 0
        launcher.timer.join()
        assert signal.getsignal(signal.SIGTERM) is own
        assert any("left to the handlers this process has" in line for line in launcher.lines)
        assert "[launch] KeyboardInterrupt: stopping 2 nodes" in launcher.lines
        assert launcher.calls == ["start", "stop"]
    finally:
        signal.signal(signal.SIGTERM, previous)
