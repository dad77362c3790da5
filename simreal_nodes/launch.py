"""`simreal launch SCENE.yaml`: start only the nodes a scene requires, in one process or one OS process each.

There is no ros2 launch on PyPI, so this is a small process supervisor: each node runs as
``python -m <module> --ros-args -r __node:=NAME [-r __ns:=NAMESPACE] --params-file <generated.yaml> [-r from:=to]``
(the module of its ``simreal-NAME`` entry in pyproject.toml's ``[project.scripts]``, :func:`node_modules`), its
output is prefixed with its name, a node that exits unexpectedly is reported and restarted (up to ``respawn``
times), and SIGINT / SIGTERM stop every node cleanly (SIGINT, then SIGTERM, then SIGKILL).

With ``standby`` on (the CLI's default for live use), each node has a standby process: the same command, started
:data:`STANDBY_DELAY_S` after the node, that has done its imports and brought up its DDS participant and then
waits (:func:`simreal_nodes.ros.node.run_node`). A node that exits is replaced by its standby, which only has to
build the node and match its endpoints; a new standby follows after the delay (not at once: on 2 cores its
imports would slow the node it stands behind while that one recovers). Without a standby the restart is cold:
a new process, its imports, and a new participant that the others must discover
(``./run bench respawn`` measures both).

With ``one_process`` on (the CLI's default but for live SLAM or dense-tracker graphs and lossless replays with
frames in flight, :func:`~simreal_nodes.scene.graph.default_launch`; ``--process-per-node`` turns it off), the
nodes run in a single process on one executor (:mod:`simreal_nodes.ros.compose`), each with the arguments it would
have had in its own; the launcher then watches, restarts and stops that one process (named :data:`ONE_PROCESS`) as
it would a node, with one standby. ``--split`` puts the nodes slower than a camera frame (a SLAM localization, a
dense tracker) in processes of their own and the others in one (``groups``,
:func:`~simreal_nodes.scene.graph.process_groups`). ``./run bench graph`` measures the three. The class itself
starts a process per node unless asked (its callers, tests and benchmarks, say which they run).
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import yaml

from simreal_nodes.errors import SimrealError
from simreal_nodes.lifetime import StopSignals
from simreal_nodes.scene.graph import NodeSpec

FASTDDS_PROFILE = Path(__file__).resolve().parent / "ros" / "fastdds_shm.xml"
PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
NODE_SCRIPT_PREFIX = "simreal-"


@functools.cache
def node_modules(pyproject: Path = PYPROJECT) -> dict[str, str]:
    """Node name -> Python module, from the ``simreal-NAME = "module:main"`` entries of ``[project.scripts]``.

    The executables are declared once, in pyproject.toml; the launcher runs the module with ``python -m`` (every
    node module calls its ``main`` under ``__main__``) rather than the installed script, so a checkout works
    without re-installing after the table changes. Read from the file rather than the installed metadata for the
    same reason (every supported install, ``./run setup`` and the Dockerfile, is an editable one of the checkout).
    """
    with open(pyproject, "rb") as f:
        scripts: dict[str, str] = tomllib.load(f)["project"]["scripts"]
    return {name[len(NODE_SCRIPT_PREFIX):]: target.partition(":")[0] for name, target in scripts.items()
            if name.startswith(NODE_SCRIPT_PREFIX)}


QOS_FROM_XML = "RMW_FASTRTPS_USE_QOS_FROM_XML"  # 1: rmw_fastrtps takes the history memory policies from the profile
DISCOVERY_RANGE = "ROS_AUTOMATIC_DISCOVERY_RANGE"
DISCOVERY_RANGES = ("LOCALHOST", "SUBNET", "SYSTEM_DEFAULT", "OFF")  # the values rmw accepts (ROS 2 Jazzy)


def executor_kind(env: dict | None = None) -> str:
    """The executor named by :data:`EXECUTOR_ENV` in ``env`` (default: this process's environment), else
    :data:`DEFAULT_EXECUTOR`; :class:`SimrealError` for a name not in :data:`EXECUTORS`."""
    kind = (os.environ if env is None else env).get(EXECUTOR_ENV) or DEFAULT_EXECUTOR
    if kind not in EXECUTORS:
        raise SimrealError(f"{EXECUTOR_ENV}={kind!r}: the executor must be one of {', '.join(EXECUTORS)}")
    return kind


THREADS_ENV = "SIMREAL_THREADS"  # worker threads per pool in each node process (0: the libraries' own; unset: default)
# the thread pools the environment sizes: OpenMP (Open3D), OpenBLAS (numpy, scipy; the copy OpenCV bundles too), MKL.
# OpenCV's own pool is sized by the node process itself (cv2.setNumThreads: :func:`set_threads`)
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
# Mesa's llvmpipe (the overlay's OpenGL without a GPU) rasterizes on this many threads besides the caller's (0: in the
# caller's alone); sized only when the threads per pool are given (N > 0: N - 1 besides the caller)
LLVMPIPE_THREADS = "LP_NUM_THREADS"


def node_threads(env: dict | None = None) -> int | None:
    """The worker threads per pool named by :data:`THREADS_ENV` in ``env`` (default: this process's environment); None
    where it is unset or empty (the default sizing, :func:`ros_environment`); :class:`SimrealError` for anything but a
    whole number >= 0."""
    raw = (os.environ if env is None else env).get(THREADS_ENV)
    if raw is None or raw == "":
        return None
    try:
        n = int(raw)
    except ValueError:
        n = -1
    if n < 0:
        raise SimrealError(f"{THREADS_ENV}={raw!r}: the threads per pool must be a whole number >= 0 "
                           "(0: the libraries' own defaults)")
    return n


def thread_variables(base: dict, threads: int | None = None) -> dict[str, str]:
    """The variables that size a node process's thread pools, to add to ``base`` (the user's environment), as
    :func:`ros_environment` describes; also for ``ros2 launch`` (``ros2_ws``), whose node processes start from the
    user's environment."""
    out: dict[str, str] = {} if threads is None else {THREADS_ENV: str(threads)}
    n = node_threads(base | out)
    if n is None:
        out.update((var, "1") for var in THREAD_VARS if not base.get(var))
    elif n > 0:
        out.update((var, str(n)) for var in THREAD_VARS)
        out[LLVMPIPE_THREADS] = str(n - 1)
    return out


def set_threads(n: int | None) -> None:
    """OpenCV's worker threads in this process (a node's: :func:`simreal_nodes.ros.node.run_nodes`): ``n`` > 0 of
    them; 0 or None: OpenCV's own sizing (a thread per core). The pools sized by environment variables (OpenBLAS,
    OpenMP) were set before the process started (:func:`thread_variables`)."""
    if n:
        import cv2

        cv2.setNumThreads(n)


def ros_environment(base: dict | None = None, discovery_range: str | None = None,
                    executor: str | None = None, threads: int | None = None) -> dict:
    """Environment for node processes: SHM transport profile, ament prefix of the venv, DDS discovery range, the
    libraries' thread pools.

    Discovery stays on this host unless widened: ROS 2's own default (SUBNET) would announce every node, its camera
    images included, to the whole network, and take commands from it. ``discovery_range`` (one of
    :data:`DISCOVERY_RANGES`) sets it explicitly; otherwise a range already set in ``base`` (the user's environment)
    is kept; otherwise LOCALHOST. ``executor`` (one of :data:`EXECUTORS`) sets the nodes' executor; otherwise
    ``base``'s :data:`EXECUTOR_ENV`, else :data:`DEFAULT_EXECUTOR`.

    ``threads`` (else ``base``'s :data:`THREADS_ENV`): N > 0 sizes every pool of a node process to N threads
    (OpenBLAS, OpenMP, MKL through :data:`THREAD_VARS`, overriding the user's; OpenCV's by the process itself; Mesa
    llvmpipe's rasterizer to N - 1 besides the rendering thread, :data:`LLVMPIPE_THREADS`); 0
    leaves every pool at the library's own default (a thread per core; a variable of :data:`THREAD_VARS` the user set
    is kept). Neither given: the default, one thread for the linear algebra's pools (OpenBLAS, OpenMP, MKL; a
    variable of :data:`THREAD_VARS` the user set is kept) and OpenCV's own pool as OpenCV sizes it. The linear algebra
    of the nodes is small (tall, thin least squares of a few thousand rows) and its pool's threads only spin beside
    the other nodes; OpenCV's pool, on whole images, gains on a frame that one node works on alone (``./run bench
    threads``: the family scene's nodes used 37 % less CPU a frame than with every pool at its library's default, at
    the same frame rate; with OpenCV held to one thread as well the markers demo's lossless rate fell by 4-10 %)."""
    env = dict(os.environ if base is None else base)
    if executor is not None:
        env[EXECUTOR_ENV] = executor
    env[EXECUTOR_ENV] = executor_kind(env)
    env.update(thread_variables(env, threads))
    if discovery_range is not None:
        if discovery_range not in DISCOVERY_RANGES:
            raise SimrealError(f"DDS discovery range: expected one of {', '.join(DISCOVERY_RANGES)}; "
                               f"found {discovery_range!r}")
        env[DISCOVERY_RANGE] = discovery_range
    elif not env.get(DISCOVERY_RANGE):
        env[DISCOVERY_RANGE] = "LOCALHOST"
    env.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(FASTDDS_PROFILE))
    if env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(FASTDDS_PROFILE):
        # the profile's history memory policies apply (DYNAMIC readers: a subscription does not keep (depth + 1)
        # buffers as large as the largest message it has seen; benchmarks/results/dds_memory_policy.md); a user's
        # own profile, or this variable set to 0, leaves rmw_fastrtps's own
        env.setdefault(QOS_FROM_XML, "1")
    prefix = sys.prefix
    ament = env.get("AMENT_PREFIX_PATH", "")
    if prefix not in ament.split(os.pathsep):
        env["AMENT_PREFIX_PATH"] = prefix + (os.pathsep + ament if ament else "")
    env["PYTHONUNBUFFERED"] = "1"
    return env


STANDBY_ENV = "SIMREAL_STANDBY"  # "1" in a standby process's environment
LAUNCHER_PID_ENV = "SIMREAL_LAUNCHER_PID"  # a node ends when the process of this pid (its launcher) does
PROMOTE = "go"  # the line written to a standby's stdin to make it the node
STANDBY_READY = b"standby ready"  # how a standby's ready line starts (:func:`simreal_nodes.ros.node.run_node`)
QUIET_CORES = 0.15  # Launcher.wait_quiet: below this CPU use (cores) the graph is idle (its timers, diagnostics)
STANDBY_DELAY_S = 5.0  # a standby starts this long after the node it stands behind (start or restart)
WATCH_PERIOD_S = 0.05  # how often the launcher looks for exited nodes
EXECUTOR_ENV = "SIMREAL_EXECUTOR"  # the executor node processes (and the replay's player) spin on: EXECUTORS
EXECUTORS = ("events", "single")  # rclpy's EventsExecutor (C++), its SingleThreadedExecutor (Python)
DEFAULT_EXECUTOR = "events"
ONE_PROCESS = "nodes"  # the name (log, CPU figures) of a process of several nodes (all: the one-process launch)


@dataclass
class _Proc:
    spec: NodeSpec
    cmd: list[str]
    popen: subprocess.Popen[bytes] | None = None
    restarts: int = 0
    exit_codes: list[int] = field(default_factory=list)
    standby: subprocess.Popen[bytes] | None = None
    standby_due: float | None = None  # time.monotonic() at which to start the next standby
    standby_failures: int = 0
    standby_ready: bool = False  # the standby printed its ready line (imports done, participant up)


class Launcher:
    """Start, watch and stop a set of node processes.

    ``env``, ``discovery_range``, ``executor`` and ``threads``: as :func:`ros_environment` takes them (DDS discovery
    on this host unless widened). ``namespace`` (e.g. ``/cell2``): every node is started in it, so node names and the
    services they address by relative names (the tracker's call to ``localization/set_localization_only``) do not
    collide with a second graph; the data topics are absolute (:mod:`simreal_nodes.scene.graph`) and move only by
    ``remaps``. ``groups``: the node names that share a process (each node named once; a group of one is that
    node's own process, one of several runs them on one executor, :mod:`simreal_nodes.ros.compose`, and is named
    :data:`ONE_PROCESS`: :func:`~simreal_nodes.scene.graph.process_groups` makes at most one such group); None:
    ``one_process`` says (every node in one, or one each)."""

    def __init__(self, nodes: list[NodeSpec], remaps: dict[str, str] | None = None, respawn: int = 2,
                 env: dict | None = None, echo=print, log_dir: str | Path | None = None, namespace: str = "",
                 discovery_range: str | None = None, standby: bool = False, one_process: bool = False,
                 executor: str | None = None, threads: int | None = None, groups: list[list[str]] | None = None):
        self.nodes = nodes
        self.remaps = remaps or {}
        self.respawn = respawn
        self.standby = standby and respawn > 0
        self.env = ros_environment(env, discovery_range, executor, threads)
        self.echo = echo
        self._tmp = tempfile.TemporaryDirectory(prefix="simreal-launch-")
        if log_dir is None:
            base = Path(os.environ.get("ROS_LOG_DIR", Path(os.environ.get("ROS_HOME", Path.home() / ".ros")) / "log"))
            log_dir = base / time.strftime("simreal-%Y%m%d-%H%M%S")
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs: list[_Proc] = []
        self._stopping = False
        self._stopped = threading.Event()
        self._pumps: list[threading.Thread] = []
        self._lock = threading.Lock()
        modules = node_modules()
        for spec in nodes:
            if spec.name not in modules:
                raise SimrealError(f"node '{spec.name}' has no entry {NODE_SCRIPT_PREFIX}{spec.name} in the "
                                   f"[project.scripts] of {PYPROJECT}")
            pfile = Path(self._tmp.name) / f"{spec.name}.params.yaml"
            fqn = f"{namespace.rstrip('/')}/{spec.name}" if namespace else spec.name  # a params file names the node
            pfile.write_text(yaml.safe_dump({fqn: {"ros__parameters": spec.parameters}}))
            cmd = [sys.executable, "-m", modules[spec.name], "--ros-args", "-r", f"__node:={spec.name}"]
            cmd += ["-r", f"__ns:={namespace}"] if namespace else []
            cmd += ["--params-file", str(pfile)]
            for a, b in self.remaps.items():
                cmd += ["-r", f"{a}:={b}"]
            self.procs.append(_Proc(spec, cmd))
        if groups is None:
            groups = [[p.spec.name for p in self.procs]] if one_process else [[p.spec.name] for p in self.procs]
        by_name = {p.spec.name: p for p in self.procs}
        if (sorted(n for g in groups for n in g) != sorted(by_name) or sum(len(g) > 1 for g in groups) > 1
                or not all(groups)):
            raise SimrealError(f"process groups {groups} must name each node ({', '.join(by_name)}) once, with at "
                               "most one group of several and none empty")
        procs = []
        for g in groups:
            if len(g) == 1:
                procs.append(by_name[g[0]])
                continue
            nodes_json = Path(self._tmp.name) / f"nodes{len(procs)}.json"
            nodes_json.write_text(json.dumps([{"module": modules[n], "args": by_name[n].cmd[3:]} for n in g],
                                             indent=1))
            procs.append(_Proc(NodeSpec(ONE_PROCESS, per_frame=False),
                               [sys.executable, "-m", "simreal_nodes.ros.compose", str(nodes_json)]))
        self.procs = procs

    # -----------------------------------------------------------------------------------------
    def start(self) -> Launcher:
        for p in self.procs:
            self._spawn(p)
        threading.Thread(target=self._watch, daemon=True).start()
        return self

    def _spawn(self, p: _Proc) -> None:
        p.popen = self._popen(p, standby=False)
        self.echo(f"[launch] started {p.spec.name} (pid {p.popen.pid})")
        self._schedule_standby(p)

    def _popen(self, p: _Proc, standby: bool) -> subprocess.Popen[bytes]:
        log = open(self.log_dir / f"{p.spec.name}.log", "ab")  # noqa: SIM115 - the pump thread owns and closes it
        env = self.env | {LAUNCHER_PID_ENV: str(os.getpid())} | ({STANDBY_ENV: "1"} if standby else {})
        popen = subprocess.Popen(p.cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 stdin=subprocess.PIPE if standby else subprocess.DEVNULL, start_new_session=True)
        if standby:
            p.standby_ready = False
        pump = threading.Thread(target=self._pump, args=(p, popen, log, standby), daemon=True)
        pump.start()
        self._pumps.append(pump)
        return popen

    def _schedule_standby(self, p: _Proc) -> None:
        """The next standby of ``p`` after :data:`STANDBY_DELAY_S`. All nodes' standbys start together: spread 1 s
        apart, the ones still importing slowed a node promoted meanwhile on 2 cores (`./run bench respawn`: the
        localization back after 0.64-2.38 s instead of 0.36-0.43 s), and one burst is over sooner."""
        if self.standby and p.standby is None and p.restarts < self.respawn and p.standby_failures < 2:
            p.standby_due = time.monotonic() + STANDBY_DELAY_S

    def _promote(self, p: _Proc) -> bool:
        """Make ``p``'s standby the node (False: there is none alive, or it cannot be told)."""
        sb, p.standby = p.standby, None
        if sb is None or sb.poll() is not None:
            return False
        try:
            assert sb.stdin is not None  # standbys are started with stdin=PIPE
            sb.stdin.write(PROMOTE.encode() + b"\n")
            sb.stdin.flush()
        except OSError:
            return False
        p.popen = sb
        self.echo(f"[launch] started {p.spec.name} (pid {sb.pid}) from its standby")
        self._schedule_standby(p)
        return True

    def _pump(self, p: _Proc, popen: subprocess.Popen[bytes], log: IO[bytes], standby: bool = False) -> None:
        assert popen.stdout is not None  # started with stdout=PIPE
        with log:
            for line in iter(popen.stdout.readline, b""):
                if standby and line.startswith(STANDBY_READY):  # (p.standby is set only after this thread starts)
                    p.standby_ready = True
                log.write(line)
                log.flush()
                self.echo(f"[{p.spec.name}] {line.decode(errors='replace').rstrip()}")

    def _watch(self) -> None:
        while not self._stopping:
            time.sleep(WATCH_PERIOD_S)
            with self._lock:
                if self._stopping:
                    break
                try:
                    self._watch_once()
                except Exception as e:  # noqa: BLE001 - the watcher outlives a failing echo or spawn
                    print(f"[launch] watcher: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
        # the processes this thread started get SIGTERM when it ends (PR_SET_PDEATHSIG is per thread): it ends only
        # after stop() has ended them in its own order (SIGINT first)
        self._stopped.wait()

    def _watch_once(self) -> None:
        for p in self.procs:
            self._watch_standby(p)
            rc = p.popen.poll() if p.popen else None
            if rc is None:
                continue
            p.exit_codes.append(rc)
            if p.restarts < self.respawn:
                p.restarts += 1
                self.echo(f"[launch] {p.spec.name} exited with code {rc}; restarting "
                          f"({p.restarts}/{self.respawn}), log: {self.log_dir / (p.spec.name + '.log')}")
                if not self._promote(p):
                    self._spawn(p)
            else:
                self.echo(f"[launch] {p.spec.name} exited with code {rc}; not restarting")
                p.popen = None
                self._end_standby(p)

    def _watch_standby(self, p: _Proc) -> None:
        """Start a standby when it is due; notice one that ended before it was needed (it is not replaced
        after two such ends: the node's restarts are then cold)."""
        if p.standby is not None and p.standby.poll() is not None:
            p.standby_failures += 1
            self.echo(f"[launch] the standby for {p.spec.name} exited with code {p.standby.returncode}")
            p.standby = None
            self._schedule_standby(p)
        if p.standby_due is not None and time.monotonic() >= p.standby_due and p.popen is not None:
            p.standby_due = None
            p.standby = self._popen(p, standby=True)
            self.echo(f"[launch] standby for {p.spec.name} started (pid {p.standby.pid})")

    def start_standbys(self, timeout_s: float) -> bool:
        """Start every standby still waiting for its delay now and wait until each is ready (False: not all within
        ``timeout_s``). For a replay, before its first frame: on 2 cores the standbys' imports, started by the delay
        a few seconds into the bag, took CPU from the nodes just as they built their map (stop 87: the joint boot's
        localization got few frames, far apart, in those seconds and lost its map). A live camera has no first frame
        to hold back; there the delay stands."""
        if not self.standby:
            return True
        with self._lock:
            for p in self.procs:
                if p.standby_due is not None:
                    p.standby_due = time.monotonic()
                self._watch_standby(p)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if all(p.standby is None or p.standby_ready for p in self.procs):
                return True
            time.sleep(0.05)
        return False

    def wait_quiet(self, timeout_s: float, window_s: float = 0.25, busy_cores: float = QUIET_CORES,
                   should_stop=lambda: False) -> bool:
        """Wait until the graph is quiet: every process this one started (nodes, their workers, standbys) and this
        one together used less than ``busy_cores`` of CPU in each of two windows of ``window_s`` in a row (False:
        not within ``timeout_s``, or ``should_stop()``). For a live replay, before its first frame: a standby says
        it is ready when its participant is up, and the discovery that follows takes every participant's CPU for
        0.4-0.9 s on 2 cores (stop 99: a live replay of the demo that started then lost 8-10 of its first frames
        with a process per node in 3 of 5 runs, none with the standbys off). Each process's CPU counts by its own
        growth (one that ends meanwhile takes nothing back). Linux /proc; True at once where it cannot be read."""
        deadline = time.monotonic() + timeout_s
        before, t = _tree_cpu_by_pid(os.getpid()), time.monotonic()
        if before is None:
            return True
        quiet = 0
        while not should_stop():
            time.sleep(window_s)
            now, t_now = _tree_cpu_by_pid(os.getpid()), time.monotonic()
            if now is None:
                return True
            used = sum(max(0.0, c - before.get(pid, 0.0)) for pid, c in now.items())
            quiet = quiet + 1 if used / max(t_now - t, 1e-3) < busy_cores else 0
            if quiet >= 2:
                return True
            if t_now > deadline:
                return False
            before, t = now, t_now
        return False

    @staticmethod
    def _end_standby(p: _Proc) -> subprocess.Popen[bytes] | None:
        """Tell ``p``'s standby to end (EOF on its stdin); returns it to be waited for."""
        sb, p.standby, p.standby_due = p.standby, None, None
        if sb is not None and sb.stdin is not None:
            with contextlib.suppress(OSError):
                sb.stdin.close()
        return sb

    def cpu_seconds(self) -> dict[str, float]:
        """CPU time (user + system) used so far by each running node and the processes it started (Linux
        /proc; empty where that is unavailable)."""
        table = _proc_table()
        if table is None:
            return {}
        return {p.spec.name: sum(_tree_cpu(table, p.popen.pid).values()) for p in self.procs
                if p.popen is not None and p.popen.poll() is None}

    def alive(self) -> dict[str, bool]:
        return {p.spec.name: p.popen is not None and p.popen.poll() is None for p in self.procs}

    def stop(self, timeout: float = 8.0) -> dict[str, int | None]:
        """SIGINT every node, wait, then SIGTERM, then SIGKILL; end the standbys. Returns the nodes' exit codes.
        ``timeout``: the wait after SIGINT for one node; a process running several closes them one after the other
        (worker processes joined, a map saved, a video finished), so it is given that much per node."""
        with self._lock:
            self._stopping = True
        if len(self.procs) < len(self.nodes):  # the one-process launch
            timeout *= len(self.nodes)
        # the processes themselves: with _stopping set, _watch no longer replaces or clears any p.popen
        live = [p.popen for p in self.procs if p.popen is not None and p.popen.poll() is None]
        # standbys end at the EOF of their stdin: they are signalled only from SIGTERM on, if they have not
        standbys = [sb for sb in map(self._end_standby, self.procs) if sb is not None and sb.poll() is None]
        for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 3.0), (signal.SIGKILL, 2.0)):
            for popen in live + (standbys if sig != signal.SIGINT else []):
                if popen.poll() is None:
                    with contextlib.suppress(ProcessLookupError):
                        popen.send_signal(sig)
            t_end = time.monotonic() + wait
            while time.monotonic() < t_end and any(popen.poll() is None for popen in live + standbys):
                time.sleep(0.05)
            live = [popen for popen in live if popen.poll() is None]
            standbys = [popen for popen in standbys if popen.poll() is None]
            if not live and not standbys:
                break
        codes = {p.spec.name: (p.popen.returncode if p.popen else (p.exit_codes[-1] if p.exit_codes else None))
                 for p in self.procs}
        self._stopped.set()
        for pump in self._pumps:  # the last lines of output reach the log and the echo
            pump.join(timeout=2.0)
        self._tmp.cleanup()
        return codes

    def __enter__(self) -> Launcher:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def run_until_signal(launcher: Launcher) -> int:
    """Block until SIGINT / SIGTERM (:class:`~simreal_nodes.lifetime.StopSignals`: taken only from the main thread,
    over handlers no one chose, and put back after), or until every node has exited for good; then stop the nodes.
    Exit code 0 if all stopped cleanly. Where the process chose its own handlers (or this is not the main thread), it
    says so and keeps them: they decide when it stops; a ``KeyboardInterrupt`` they let through stops the nodes as
    SIGINT does."""
    with StopSignals(interrupting=False) as stop:
        if not stop.active:
            launcher.echo("[launch] SIGINT / SIGTERM left to the handlers this process has (its own, or not the main "
                          "thread): they decide when the nodes stop")
        try:
            launcher.start()
            while not stop.wait(0.5):
                if not any(launcher.alive().values()) and all(p.restarts >= launcher.respawn for p in launcher.procs):
                    launcher.echo("[launch] every node has exited")
                    break
        except KeyboardInterrupt:  # from a handler of the process's own (or SIGINT's default, off the main thread)
            launcher.echo(f"[launch] KeyboardInterrupt: stopping {len(launcher.nodes)} nodes")
        finally:
            if stop.requested is not None:
                launcher.echo(f"[launch] {signal.Signals(stop.requested).name}: stopping {len(launcher.nodes)} nodes")
            codes = launcher.stop()
    bad = {n: c for n, c in codes.items() if c not in (0, None, -signal.SIGINT)}
    for n, c in codes.items():
        launcher.echo(f"[launch] {n}: exit code {c}")
    return 1 if bad else 0


def _proc_table() -> tuple[dict[int, float], dict[int, list[int]]] | None:
    """Every process's CPU seconds (user + system) so far and each process's children (Linux /proc; None where it
    cannot be read)."""
    try:
        tick = os.sysconf("SC_CLK_TCK")
        cpu: dict[int, float] = {}
        kids: dict[int, list[int]] = {}
        for d in os.listdir("/proc"):
            if d.isdigit():
                try:
                    f = Path(f"/proc/{d}/stat").read_text().rsplit(")", 1)[1].split()
                except OSError:
                    continue
                cpu[int(d)] = (int(f[11]) + int(f[12])) / tick
                kids.setdefault(int(f[1]), []).append(int(d))
    except (OSError, ValueError, AttributeError):
        return None
    return cpu, kids


def _tree_cpu(table: tuple[dict[int, float], dict[int, list[int]]], root: int) -> dict[int, float]:
    """CPU seconds so far of process ``root`` (all its threads) and of every process below it, by process id, from a
    :func:`_proc_table`."""
    cpu, kids = table
    out, todo = {}, [root]
    while todo:
        pid = todo.pop()
        out[pid] = cpu.get(pid, 0.0)
        todo += kids.get(pid, [])
    return out


def _tree_cpu_by_pid(root: int) -> dict[int, float] | None:
    """:func:`_tree_cpu` of ``root`` read now (None where /proc cannot be read)."""
    table = _proc_table()
    return None if table is None else _tree_cpu(table, root)
