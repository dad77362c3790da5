"""The base of every simreal node: declared parameters, diagnostics, progress reports, guarded callbacks, main().

Nodes are thin: they declare parameters, convert messages to numpy, call the ROS-free core and
convert back. A callback that raises is caught here, logged, counted in diagnostics, and the
node keeps running.
"""

from __future__ import annotations

import functools
import os
import signal
import sys
import time
import traceback
from collections.abc import Callable
from typing import TYPE_CHECKING

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from simreal_nodes.errors import SimrealError
from simreal_nodes.launch import (
    EXECUTOR_ENV,
    LAUNCHER_PID_ENV,
    PROMOTE,
    STANDBY_ENV,
    STANDBY_READY,
    executor_kind,
    node_threads,
    set_threads,
)
from simreal_nodes.lifetime import StopSignals, end_with_parent
from simreal_nodes.metrics import StageMetrics
from simreal_nodes.ros.convert import image_view, ns_to_stamp, stamp_ns
from simreal_nodes.ros.qos import reliable_qos
from simreal_nodes.scene import graph
from simreal_nodes.sync import live_skip_reason

if TYPE_CHECKING:
    from simreal_nodes.sync import StampSync

STALL_S = 3.0  # live: a node that skips every frame for this long says so in its status

# Progress reports (/simreal/progress, std_msgs/Header: the frame's stamp, and in frame_id who, when, what)


def progress_id(node: str, t_monotonic: float, dropped: str = "") -> str:
    """``node@t[:dropped:why]``; t is the reporting process's CLOCK_MONOTONIC, which every process of one
    machine shares, so a player on the same machine measures latency without its own queueing delay."""
    return f"{node}@{t_monotonic:.6f}" + (f":dropped:{dropped}" if dropped else "")


def parse_progress(frame_id: str) -> tuple[str, float | None, str]:
    """(node, time or None, why dropped or '') of a progress report."""
    head, _, why = frame_id.partition(":dropped:")
    name, _, t = head.partition("@")
    try:
        return name, float(t), why
    except ValueError:
        return name, None, why


def guarded(fn):
    """Decorator for callbacks: an exception is logged and counted, never kills the node."""

    @functools.wraps(fn)
    def wrapper(self, *a, **kw):
        try:
            return fn(self, *a, **kw)
        except Exception as e:  # noqa: BLE001
            what = f"{type(e).__name__}: {e}"
            self.metrics.error(what)
            self.set_status("error", what)
            self.get_logger().error(f"{fn.__name__} failed: {what}\n{traceback.format_exc(limit=4)}",
                                    throttle_duration_sec=1.0)
            stamp = _stamp_of(a)
            if stamp is not None:
                self.progress(stamp, dropped=what)
            return None

    return wrapper


class SimrealNode(Node):
    """Base of simreal nodes: declared parameters, diagnostics on /diagnostics, progress reports."""

    # a node whose inputs go through on_input sets its ``sync`` and defines ``process`` (takes a completed frame)
    sync: StampSync
    process: Callable[[dict], None]

    def __init__(self, name: str, **kw):
        super().__init__(name, **kw)
        self.lossless = self.param("lossless", False, "reliable QoS and per-frame progress for lossless replay")
        self.scene_file = self.param("scene_file", "", "scene YAML this node serves")
        self.map_frame = self.param("map_frame", "map", "fixed frame (REP-105)")
        self.camera_frame = self.param("camera_frame", "camera_optical_frame", "camera optical frame (REP-103)")
        self.camera_direct = self.param("camera_direct", False, "read the camera's own topics (the scene's camera "
                                        "block): the graph has no ingest node; false: the ingest's outputs",
                                        read_only=True)
        self.metrics = StageMetrics()
        self.info_error = ""  # why the last CameraInfo was unusable ('' = it was not; see camera_model)
        self._diag_pub = self.create_publisher(DiagnosticArray, graph.DIAGNOSTICS, reliable_qos(10))
        self._progress_pub = self.create_publisher(Header, graph.PROGRESS, reliable_qos(1000))
        self._diag_level = DiagnosticStatus.OK
        self._diag_message = "starting"
        self._last_immediate = 0.0
        self.create_timer(1.0, self._publish_diagnostics)

    def say(self, message: str) -> None:
        """Log at info level; on shutdown (the context is gone, /rosout cannot take it) print instead."""
        if self.context.ok():
            self.get_logger().info(message)
        else:
            print(message, flush=True)

    # parameters -----------------------------------------------------------------------------
    def param(self, name: str, default, description: str, read_only: bool = False):
        d = ParameterDescriptor(description=description, read_only=read_only)
        return self.declare_parameter(name, default, d).value

    # diagnostics ----------------------------------------------------------------------------
    def set_status(self, level: str, message: str) -> None:
        """Set the diagnostic level and message; a change of level is published at once."""
        new = {"ok": DiagnosticStatus.OK, "warn": DiagnosticStatus.WARN,
               "error": DiagnosticStatus.ERROR, "stale": DiagnosticStatus.STALE}[level]
        changed = new != self._diag_level
        self._diag_level, self._diag_message = new, message
        now = time.monotonic()
        if changed and now - self._last_immediate > 0.1:
            self._last_immediate = now
            self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        st = DiagnosticStatus()
        st.level = self._diag_level
        st.name = f"simreal/{self.get_name()}"
        st.hardware_id = "simreal"
        st.message = self._diag_message
        st.values = [KeyValue(key=k, value=v) for k, v in self.metrics.as_dict().items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [st]
        self._diag_pub.publish(arr)

    # progress (lossless replay) ------------------------------------------------------------
    def progress(self, stamp, dropped: str = "") -> None:
        """Report that the frame with this stamp is finished here (or dropped, with why)."""
        h = Header()
        h.stamp = stamp
        h.frame_id = progress_id(self.get_name(), time.monotonic(), dropped)
        self._progress_pub.publish(h)

    def feed(self, sync, key: str, stamp: int, msg, process) -> None:
        """Add one input to a :class:`~simreal_nodes.sync.StampSync` (``msg`` None: its producer dropped
        this frame, stop waiting for it), process the frames that became ready and report those dropped.

        Live, only the newest ready frame is processed: older ones are skipped (a node that fell behind
        catches up instead of working through a backlog). Lossless replay processes every frame."""
        ready = sync.give_up(key, stamp) if msg is None else sync.add(key, stamp, msg)
        for s, why in sync.pop_dropped():
            if self.lossless:
                self.drop(ns_to_stamp(s), why)
            else:
                self.skip(ns_to_stamp(s), live_skip_reason(why))
        if not self.lossless and len(ready) > 1:
            for s, _ in ready[:-1]:
                self.skip(ns_to_stamp(s), "a newer frame was ready")
            ready = ready[-1:]
        for _, frame in ready:
            process(frame)

    def camera_topics(self, camera: dict | None) -> dict[str, str]:
        """The camera topics this node reads (:func:`~simreal_nodes.scene.graph.camera_topics`): the camera's own
        when ``camera_direct``, else the ingest's outputs. ``camera``: the scene's ``camera`` block."""
        return graph.camera_topics(camera, self.camera_direct)

    def subscribe_image(self, topic: str, key: str, qos):
        """An Image input of the node's ``sync`` taken serialized and read without rclpy's message conversion
        (:func:`~simreal_nodes.ros.convert.image_view`): for a node that reads the pixels and the header only."""
        return self.create_subscription(Image, topic, functools.partial(self.on_raw_image, key), qos, raw=True)

    @guarded
    def on_raw_image(self, key: str, raw: bytes) -> None:
        self.on_input(key, image_view(raw))

    def on_input(self, key: str, msg) -> None:
        """Subscription callback of an input synchronised by stamp: :meth:`feed` into the node's ``sync``, the
        frames it completes to the node's ``process``."""
        self.feed(self.sync, key, stamp_ns(msg.header.stamp), msg, self.process)

    def skip(self, stamp, reason: str) -> None:
        """Live: a frame left out because the graph is busy or an upstream node left it out (normal
        load shedding: counted, reported in progress, no warning) -- unless no frame at all has been
        finished for ``STALL_S`` seconds (an upstream node that stopped): then the status says so."""
        self.metrics.skip(reason)
        self.progress(stamp, dropped=f"skipped: {reason}")
        idle = self.metrics.seconds_since_done()
        if idle > STALL_S:
            self.set_status("warn", f"no frame finished for {idle:.0f} s, skipping: {reason}")

    def drop(self, stamp, reason: str) -> None:
        self.metrics.drop(reason)
        self.get_logger().warning(f"dropped frame: {reason}", throttle_duration_sec=2.0)
        self.set_status("warn", reason)
        if stamp is not None:
            self.progress(stamp, dropped=reason)

    def camera_model(self, msg):
        """CameraModel of a CameraInfo, or None (status set to error with the reason) when it is unusable."""
        from simreal_nodes.camera import CameraModel
        from simreal_nodes.errors import CameraInfoError

        try:
            cam = CameraModel.from_camera_info(msg)
        except CameraInfoError as e:
            self.info_error = str(e)
            self.set_status("error", f"unusable CameraInfo: {e}")
            return None
        self.info_error = ""
        return cam

    def no_camera(self, waiting: str = "waiting for a valid CameraInfo") -> str:
        """Why a frame cannot be taken while the node has no camera: the last CameraInfo's fault if it had one
        (a node that reads the camera's topics itself says what the ingest would have said), else ``waiting``."""
        return f"unusable CameraInfo: {self.info_error}" if self.info_error else waiting

    def stereo_baseline(self, msg, current: float | None) -> float | None:
        """Stereo baseline (metres) of the right camera's CameraInfo, or ``current`` (status set to error with the
        reason) when it is malformed or its projection matrix holds none; None (status error) when it describes raw
        images (a pair matched along its rows must be rectified: the ingest reads a raw pair with
        ``camera.stereo_input: raw`` or ``image_rect``)."""
        from simreal_nodes.errors import CameraInfoError
        from simreal_nodes.vision.rectify import rectified_problem
        from simreal_nodes.vision.stereo import baseline_from_projection

        try:
            baseline = baseline_from_projection(msg.p)
            why = rectified_problem(msg)
        except (ValueError, CameraInfoError) as e:
            self.set_status("error", f"unusable right CameraInfo: {e}")
            return current
        if why:
            self.set_status("error", f"right CameraInfo describes raw images ({why}): stereo needs a rectified pair; "
                                     "set camera.stereo_input to raw (a driver's raw images) or image_rect (rectified "
                                     "images beside the raw cameras' CameraInfo)")
            return None
        return baseline

    def age_ms(self, stamp) -> float:
        """How old an input stamped ``stamp`` is now (meaningful for live sources only)."""
        return (self.get_clock().now().nanoseconds - stamp_ns(stamp)) * 1e-6


def _stamp_of(args):
    """The stamp of the message a callback was given, or of a synchronized frame's (a dict of messages): the
    frame a failure is reported for."""
    for a in args:
        for m in (a.values() if isinstance(a, dict) else (a,)):
            h = getattr(m, "header", None)
            if h is not None and hasattr(h, "stamp"):
                return h.stamp
    return None


def _standby_until_promoted() -> Node | None:
    """A standby process (``SIMREAL_STANDBY=1``, :class:`~simreal_nodes.launch.Launcher`): its imports are done and
    its DDS participant is up, held by a hidden placeholder node, before it is needed. It then waits for the
    launcher's :data:`PROMOTE` line on stdin; on EOF (the launcher stopped it, or died) the process ends.

    Why the participant: a new participant is found by the running ones only after the announcements cross
    (0.4-0.9 s on 2 cores with five running participants, more while the graph is busy); endpoints created in a
    participant that is already matched are matched within tens of milliseconds. The placeholder does not take
    the node's name or namespace (``use_global_arguments=False``) and serves nothing; it lives until the node
    exists, because the participant goes with the context's last node."""
    placeholder = Node(f"_simreal_standby_{os.getpid()}", use_global_arguments=False,
                       start_parameter_services=False, enable_rosout=False)
    print(f"{STANDBY_READY.decode()} (pid {os.getpid()})", flush=True)
    line = sys.stdin.readline()
    if line.strip() != PROMOTE:
        placeholder.destroy_node()
        return None
    return placeholder


def _end_with_launcher() -> bool:
    """A node started by the launcher gets SIGTERM when the launcher dies (Linux ``PR_SET_PDEATHSIG``), so that a
    launcher killed with ``kill -9`` leaves no node publishing behind it (they run in their own sessions, out of
    reach of the terminal's Ctrl-C). False when the launcher is already gone."""
    launcher = os.environ.get(LAUNCHER_PID_ENV)
    if not launcher or not launcher.isdigit():
        return True
    return end_with_parent(int(launcher), signal.SIGTERM)


def make_executor(kind: str | None = None):
    """The executor of a node process (``kind`` None: :func:`~simreal_nodes.launch.executor_kind`'s).

    ``single``: rclpy's SingleThreadedExecutor, in Python, which rebuilds its wait set (every subscription, timer
    and service of every node) on each wake-up. ``events``: rclpy's EventsExecutor (``rclpy.experimental``, in
    C++), to which the middleware's listeners queue events; cheaper per message (``./run bench executor``).
    :class:`~simreal_nodes.errors.SimrealError` for another name."""
    if executor_kind(None if kind is None else {EXECUTOR_ENV: kind}) == "single":
        return SingleThreadedExecutor()
    from rclpy.experimental import EventsExecutor

    return EventsExecutor()


def _rclpy_signal_options(stop: StopSignals):
    """``rclpy.init``'s ``signal_handler_options``: none of rclpy's while ``stop``'s handlers are in place (its
    ``active``), rclpy's own otherwise (the process's owner installed handlers of its own)."""
    from rclpy.signals import SignalHandlerOptions

    return SignalHandlerOptions.NO if stop.active else None


#: the longest a stop signal waits for the spin to notice it (a ``spin_once`` step with nothing to do)
STOP_POLL_S = 0.1


def spin(ex, stop: StopSignals | None = None) -> None:
    """Spin until ``stop`` has a signal, or the context shuts down (another owner's handlers:
    ExternalShutdownException), in ``spin_once`` steps of at most :data:`STOP_POLL_S`: the EventsExecutor of this
    rclpy wheel (7.1.6) never fires a timer in its own ``spin()`` (measured here). A shutdown that lands between the
    context's check and the wait set's construction raises RCLError ("the given context is not valid") in either
    executor; with the context down, that is the end of the spin, not a failure."""
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    while ex.context.ok() and (stop is None or stop.requested is None):
        try:
            ex.spin_once(timeout_sec=STOP_POLL_S)
        except _rclpy.RCLError:
            if ex.context.ok():
                raise


def warm_start() -> None:
    """Before the nodes are built (so before they subscribe), what would otherwise fall on a node's first frame: live,
    the frames that arrive while it waits are replaced in the one-deep queues (a replay's first second lost 5-8 of
    the demo's 30 frames so). Loaded: rosbags' type store, which reads and writes the images serialized (about 0.1 s
    of CPU); and :mod:`inspect`'s index of the loaded modules, which rclpy's logger builds on its first call to find
    its caller (about 0.1 s; a node that logs while it is built adds its own imports to it then)."""
    import inspect

    from simreal_nodes.ros.convert import prepare

    prepare()
    inspect.getframeinfo(sys._getframe())


def run_node(node_cls, args=None) -> int:
    """main() body for every node: one process, one executor (:func:`make_executor`), clean shutdown."""
    return run_nodes([node_cls], args)


def run_nodes(builders: list[Callable[[], Node]], args=None) -> int:
    """Build the nodes (a node class, or any callable returning a node) and spin them all on one executor
    (:func:`make_executor`, as ``SIMREAL_EXECUTOR`` names it) until shutdown; then close and destroy each, in the
    reverse order of their building. One builder is a node's own process (:func:`run_node`); several are the
    one-process launch (:mod:`simreal_nodes.ros.compose`). A node that fails to build ends the process (the launcher
    restarts it)."""
    if not _end_with_launcher():
        return 0
    try:
        set_threads(node_threads())
    except SimrealError as e:
        print(f"error: {e}", file=sys.stderr, flush=True)
        return 2
    stop = StopSignals()
    rclpy.init(args=args, signal_handler_options=_rclpy_signal_options(stop))
    nodes: list[Node] = []
    # development: a cProfile of the process's spin (SIMREAL_PROFILE_CPU=1: its main thread's CPU time, not wall time)
    profile_dir = os.environ.get("SIMREAL_PROFILE_DIR")
    prof = None
    try:
        placeholder = None
        if os.environ.get(STANDBY_ENV) == "1":
            placeholder = _standby_until_promoted()
            if placeholder is None:
                return 0
        warm_start()
        for build in builders:
            try:
                nodes.append(build())
            except Exception:
                if not rclpy.ok():
                    # a signal shut the context down while the nodes were being built (rclpy's handler; the
                    # one-process launch builds several): the build failed on the dead context, and the process stops
                    # cleanly, closing what it built, as a stop during the spin does. Until stop 104 the build's
                    # RCLError ended it with exit code 1 (tests/ros/test_launch.py met that race in CI)
                    return 0
                raise
        if placeholder is not None:
            placeholder.destroy_node()
        stop.interrupting = False  # from here a signal ends the spin between two steps (StopSignals)
        ex = make_executor()
        for node in nodes:
            ex.add_node(node)
        if profile_dir:
            import cProfile

            prof = cProfile.Profile(time.thread_time) if os.environ.get("SIMREAL_PROFILE_CPU") == "1" \
                else cProfile.Profile()
            prof.enable()
        spin(ex, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if prof is not None:
            assert profile_dir is not None and nodes  # prof is made only once the nodes exist
            prof.disable()
            os.makedirs(profile_dir, exist_ok=True)
            prof.dump_stats(os.path.join(profile_dir, "+".join(n.get_name() for n in nodes) + ".prof"))
        for node in reversed(nodes):
            close = getattr(node, "close", None)
            if close:
                try:
                    close()
                except Exception as e:  # noqa: BLE001
                    print(f"[{node.get_name()}] close failed: {e}", flush=True)
            try:  # one node's failure here must not keep the others (in one process) from closing
                node.destroy_node()
            except Exception as e:  # noqa: BLE001
                print(f"[{node.get_name()}] destroy failed: {e}", flush=True)
        if rclpy.ok():
            rclpy.shutdown()
        stop.restore()
    return 0
