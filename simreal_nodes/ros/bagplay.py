"""Bag replay into a live graph and recording of live topics (rclpy side; bag I/O is in io.bags).

- :class:`Player` publishes a bag's camera topics as raw CDR (no conversion) at the recorded
  rate, a scaled rate, or losslessly: every image is published once, in order, and the next is
  held until every node of the graph reported the frame finished (or dropped) on
  ``/simreal/progress``.
- :class:`Recorder` subscribes raw to topics and writes them to a self-describing bag; it closes
  the bag on SIGINT / SIGTERM, so what was recorded stays readable.
"""

from __future__ import annotations

import importlib
import time
from collections import defaultdict, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header

from simreal_nodes.io import bags
from simreal_nodes.ros.convert import stamp_ns
from simreal_nodes.ros.node import parse_progress
from simreal_nodes.ros.qos import data_qos, reliable_qos
from simreal_nodes.scene import graph

if TYPE_CHECKING:
    from rclpy.subscription import Subscription


def message_class(msgtype: str):
    """'sensor_msgs/msg/Image' -> the rclpy message class."""
    pkg, _, name = bags.normalize_type(msgtype).split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


# ---------------------------------------------------------------------------------------------


class Recorder:
    """Raw subscriptions on a node, written to a :class:`bags.BagWriter`."""

    def __init__(self, node: Node, path, storage: str = "mcap", topics: dict[str, str] | None = None,
                 discover: bool = False, exclude: tuple[str, ...] = ("/rosout", "/parameter_events"),
                 count_only: tuple[str, ...] = ()):
        """``count_only``: topics subscribed to and counted but not written (their messages cost a reader's
        reception, not a disk's)."""
        self.node = node
        self.count_only = frozenset(count_only)
        self.writer = bags.BagWriter(path, storage).open()
        self.exclude = exclude
        self._subs: dict[str, Subscription | None] = {}  # None: waiting for a publisher
        self._pending: dict[str, str] = {}  # topics waiting for a publisher (to match its QoS)
        self.counts: dict[str, int] = defaultdict(int)
        self.failed = ""  # why recording stopped (a write failed), or ''
        for t, ty in (topics or {}).items():
            self.add(t, ty)
        node.create_timer(0.2, self._subscribe_pending)
        if discover:
            node.create_timer(0.5, self._discover)

    def ready(self) -> bool:
        """True when every requested topic has a publisher and our subscription to it."""
        self._subscribe_pending()
        return not self._pending

    def _qos_for(self, topic: str) -> QoSProfile:
        infos = self.node.get_publishers_info_by_topic(topic)
        reliable = bool(infos) and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
        latched = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
        if latched:
            return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL)
        return reliable_qos(1000) if reliable else data_qos(False, depth=100)

    def add(self, topic: str, msgtype: str) -> None:
        """Record ``topic``; the subscription waits for a publisher so that its QoS can match."""
        if topic in self._subs or topic in self.exclude or self.failed:
            return
        if not self.node.get_publishers_info_by_topic(topic):
            self._pending[topic] = msgtype
            return
        self._pending.pop(topic, None)
        try:
            cls = message_class(msgtype)
            if topic not in self.count_only:
                self.writer.add_topic(topic, msgtype)
        except Exception as e:  # noqa: BLE001 - a type we cannot record is reported, not fatal
            self.node.get_logger().warning(f"not recording {topic} ({msgtype}): {e}")
            self._subs[topic] = None
            return

        def cb(raw: bytes, topic=topic):
            if self.failed:
                return
            if topic in self.count_only:
                self.counts[topic] += 1
                return
            try:
                self.writer.write_raw(topic, self.node.get_clock().now().nanoseconds, raw)
            except OSError as e:  # disk full, file too large, device gone: stop recording, keep what is written
                self._fail(e)
                return
            self.counts[topic] += 1

        self._subs[topic] = self.node.create_subscription(cls, topic, cb, self._qos_for(topic), raw=True)

    def _subscribe_pending(self) -> None:
        for t, ty in list(self._pending.items()):
            self.add(t, ty)

    def _discover(self) -> None:
        for topic, types in self.node.get_topic_names_and_types():
            if topic not in self._subs and types:
                self.add(topic, types[0])

    def _fail(self, e: OSError) -> None:
        self.failed = (f"recording to {self.writer.path} stopped after {self.writer.count} messages: "
                       f"{e.strerror or e} (the messages already on disk stay readable: `simreal bag-info` "
                       "salvages them)")
        self.node.get_logger().error(self.failed)
        for sub in self._subs.values():
            if sub is not None:
                self.node.destroy_subscription(sub)
        self._subs = dict.fromkeys(self._subs)

    def close(self) -> None:
        """Close the bag. After a failed write (or when the summary cannot be written either) the file ends
        without its index: the reader salvages it record by record up to that point."""
        try:
            self.writer.close()
        except OSError as e:
            if not self.failed:
                self._fail(e)


# ---------------------------------------------------------------------------------------------


# the most frames a lossless replay lets into the graph at once: a node holds up to StampSync's max_pending (30)
# frames waiting for their inputs and drops the oldest beyond; half of that leaves room for the inputs that come early
MAX_IN_FLIGHT = 15


def in_flight_ok(n) -> bool:
    """Whether ``n`` is a bound a lossless replay takes for its frames in flight: a whole number (not a bool) from 1
    to :data:`MAX_IN_FLIGHT` (the player's, ``replay``'s and the CLI's one check)."""
    return isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_IN_FLIGHT

# the start-up a replay's steady-state share leaves out (``PlayStats.through_after``, ``lost_before``): live, a graph's
# first frame waits for what every node builds once the first CameraInfo comes with it (the overlay's compositor and
# distortion maps, the localizer, the trackers; since stop 99 the overlay and the localizer warm up before, and those
# builds take tens of milliseconds), and the frames that arrive meanwhile are replaced in the nodes' one-deep queues
STARTUP_S = 1.0


@dataclass
class PlayStats:
    frames_published: int = 0
    frames_completed: int = 0
    frames_dropped: int = 0
    frames_timed_out: int = 0
    conflicting_reports: int = 0
    drop_reasons: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    latency_ms: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    wall_s: float = 0.0
    play_s: float = 0.0  # first publication to the last one (real time) or the last frame's end (lossless)
    published_stamps: list[int] = field(default_factory=list)
    completed_stamps: list[int] = field(default_factory=list)  # the frames every node finished, in their order
    cpu_s: dict[str, float] = field(default_factory=dict)  # CPU seconds per process while playing
    record_error: str = ""  # why the recording stopped early ('' when it did not)

    def summary(self) -> str:
        fps = self.frames_published / self.play_s if self.play_s > 0 else 0.0
        lines = [f"published {self.frames_published} frames in {self.play_s:.2f} s ({fps:.1f} fps); "
                 f"completed {self.frames_completed}, dropped {self.frames_dropped}, timed out {self.frames_timed_out}"]
        for why, n in sorted(self.drop_reasons.items(), key=lambda kv: -kv[1])[:10]:
            lines.append(f"  dropped x{n}: {why}")
        for node, lat in sorted(self.latency_ms.items()):
            if lat:
                a = np.asarray(lat)
                lines.append(f"  {node}: {len(a)} frames, latency from publish p50 {np.percentile(a, 50):.1f} ms, "
                             f"p95 {np.percentile(a, 95):.1f} ms")
        return "\n".join(lines)

    def lost_before(self, seconds: float) -> int:
        """How many of the frames published less than ``seconds`` (of the bag's stamps) after the first did not go
        through every node: the start-up's losses (:meth:`through_after` the share of the rest)."""
        if not self.published_stamps:
            return 0
        t0, done = min(self.published_stamps), set(self.completed_stamps)
        return sum(s - t0 < seconds * 1e9 and s not in done for s in self.published_stamps)

    def through_after(self, seconds: float) -> float:
        """The share (%) of the frames published ``seconds`` (of the bag's stamps) or more after the first that went
        through every node: the steady state, without the nodes' start-up (NaN when no frame is that late)."""
        if not self.published_stamps:
            return float("nan")
        t0 = min(self.published_stamps)
        late = [s for s in self.published_stamps if s - t0 >= seconds * 1e9]
        if not late:
            return float("nan")
        done = set(self.completed_stamps)
        return 100.0 * sum(s in done for s in late) / len(late)

    def as_dict(self) -> dict:
        out = {k: getattr(self, k) for k in ("frames_published", "frames_completed", "frames_dropped",
                                             "frames_timed_out", "conflicting_reports", "wall_s", "play_s")}
        out["fps"] = self.frames_published / self.play_s if self.play_s > 0 else 0.0
        out["fps_through"] = self.frames_completed / self.play_s if self.play_s > 0 else 0.0
        steady = self.through_after(STARTUP_S)
        out["through_after_startup_pct"] = None if steady != steady else steady  # JSON has no NaN
        out["cpu_ms_per_frame"] = {n: 1e3 * v / max(self.frames_published, 1) for n, v in self.cpu_s.items()}
        out["drop_reasons"] = dict(self.drop_reasons)
        out["latency_ms"] = {n: {"p50": float(np.percentile(v, 50)), "p95": float(np.percentile(v, 95)),
                                 "n": len(v)} for n, v in self.latency_ms.items() if v}
        return out


class Player:
    """Publish a bag's input topics into the graph."""

    def __init__(self, node: Node, executor, input_topics: dict[str, str], image_topic: str,
                 nodes: list[str], lossless: bool, rate: float = 1.0, frame_timeout_s: float = 30.0,
                 echo=print, in_flight: int = 1):
        if not in_flight_ok(int(in_flight)):
            raise ValueError(f"in_flight {in_flight}: a lossless replay lets 1 to {MAX_IN_FLIGHT} frames into the "
                             "graph")
        self.node, self.executor = node, executor
        self.in_flight = int(in_flight)
        self._open: dict[int, tuple[float, float | None]] = {}  # frames in the graph: stamp -> (deadline, grace end)
        self.image_topic = image_topic
        self.nodes = list(nodes)
        self.lossless, self.rate, self.frame_timeout_s = lossless, rate, frame_timeout_s
        self.echo = echo
        self.stats = PlayStats()
        self.should_stop = lambda: False
        self.extra_ready = lambda: True
        self.dead_nodes: Callable[[], list[str]] = lambda: []
        self.node_inputs: dict[str, list[str]] = {}
        self.pubs = {t: node.create_publisher(message_class(ty), t, data_qos(lossless))
                     for t, ty in input_topics.items()}
        self._reports: dict[int, dict[str, str]] = defaultdict(dict)
        self._t_pub: dict[int, float] = {}
        self._t_first: float | None = None
        node.create_subscription(Header, graph.PROGRESS, self._on_progress, reliable_qos(1000))

    def _on_progress(self, h: Header) -> None:
        s = stamp_ns(h.stamp)
        name, t_done, why = parse_progress(h.frame_id)
        if name in self._reports[s] and bool(self._reports[s][name]) != bool(why):
            self.stats.conflicting_reports += 1  # a node both finished and dropped this frame: a bug
        self._reports[s][name] = why
        if s in self._t_pub and not why:  # latency of the frames a node finished, not of those it left out
            # from publication to the node's report (its own clock when it sent one: not this process's backlog)
            self.stats.latency_ms[name].append(((t_done or time.monotonic()) - self._t_pub[s]) * 1e3)

    def wait_ready(self, timeout_s: float = 60.0) -> bool:
        """Wait until every node is up and subscribes to its inputs (the image topic: the ingest, or the nodes that
        read the camera themselves)."""
        t_end = time.monotonic() + timeout_s
        want = set(self.nodes)
        while time.monotonic() < t_end:
            self.executor.spin_once(timeout_sec=0.1)
            dead = self.dead_nodes()
            if dead:
                self.echo(f"[replay] node(s) {', '.join(dead)} exited and will not restart")
                return False
            names = set(self.node.get_node_names())
            if want <= names and self.pubs[self.image_topic].get_subscription_count() > 0 and self.extra_ready() \
                    and self._inputs_matched():
                # the graph view can list a reader before every writer has matched it (discovery is per
                # participant): give the remaining endpoints time to match, or a node misses frame one
                t1 = time.monotonic() + 2.0
                while time.monotonic() < t1:
                    self.executor.spin_once(timeout_sec=0.05)
                return True
        missing = want - set(self.node.get_node_names())
        self.echo(f"[replay] graph not ready after {timeout_s:.0f} s; missing nodes: "
                  f"{', '.join(sorted(missing)) or 'none'}; "
                  f"image subscribers: {self.pubs[self.image_topic].get_subscription_count()}")
        return False

    def _inputs_matched(self) -> bool:
        """Every node subscribes to each of its inputs (a frame published earlier would be lost)."""
        for name, topics in self.node_inputs.items():
            for t in topics:
                subs = {i.node_name for i in self.node.get_subscriptions_info_by_topic(t)}
                if name not in subs:
                    return False
        return True

    def _frame_done(self, s: int) -> str | None:
        rep = self._reports.get(s, {})
        dropped = [f"{n}: {w}" for n, w in rep.items() if w]
        if dropped:
            return "dropped:" + "; ".join(dropped)
        if all(n in rep for n in self.nodes):
            return "done"
        return None

    def _publish_image(self, raw: bytes, s: int) -> None:
        self._t_pub[s] = time.monotonic()
        if self._t_first is None:
            self._t_first = self._t_pub[s]
        self.pubs[self.image_topic].publish(raw)
        self.stats.frames_published += 1
        self.stats.published_stamps.append(s)

    def _settle(self, most: int) -> None:
        """Spin until at most ``most`` published frames are still in the graph: each leaves it when every node
        reported it finished, when a node dropped it (after a short grace for the others' reports) or at its
        timeout. ``most`` 0: the graph drained; the lock-step player settles to 0 after every frame."""
        while len(self._open) > most and not self.should_stop():
            # returns as soon as a report (or anything) arrives: a long timeout only saves idle wake-ups,
            # which cost the graph CPU (each builds the executor's wait set)
            self.executor.spin_once(timeout_sec=0.05)
            for s in list(self._open):
                if self._closed(s):
                    del self._open[s]

    def _closed(self, s: int) -> bool:
        """Whether frame ``s`` has left the graph (counted in the stats once, here)."""
        t_end, grace_end = self._open[s]
        st = self._frame_done(s)
        if st == "done":
            self.stats.frames_completed += 1
            self.stats.completed_stamps.append(s)
            return True
        now = time.monotonic()
        if st and st.startswith("dropped"):
            # a node dropped it: its downstream nodes will not report; give others a moment
            if grace_end is None:
                grace_end = now + 0.3
                self._open[s] = (t_end, grace_end)
            if now > grace_end or all(n in self._reports[s] for n in self.nodes):
                self.stats.frames_dropped += 1
                self.stats.drop_reasons[st[8:]] += 1
                return True
        if now > t_end:
            self.stats.frames_timed_out += 1
            missing = [n for n in self.nodes if n not in self._reports.get(s, {})]
            self.echo(f"[replay] frame {s * 1e-9:.3f} s not finished after {self.frame_timeout_s:.0f} s "
                      f"(no report from {', '.join(missing)})")
            return True
        return False

    def play(self, messages, hold_for: tuple[str, ...] = ()) -> PlayStats:
        """Play an iterable of :class:`bags.BagMessage` (already filtered to the input topics)."""
        t0_wall = time.monotonic()
        t0_bag, t0_clock = None, t0_wall
        held: list[tuple[bytes, int, set]] = []  # images waiting for same-stamp companions
        seen_since: list[int] = []
        recent: dict[str, deque] = {t: deque(maxlen=64) for t in hold_for}  # stamps already published
        ts = bags.typestore()

        def release(i):
            raw, s, _ = held.pop(i)
            if self.lossless:  # a frame with the stamp of one still in the graph waits for it (frames are keyed by it)
                while s in self._open and not self.should_stop():
                    self._settle(len(self._open) - 1)
            self._publish_image(raw, s)
            if self.lossless:
                self._open[s] = (time.monotonic() + self.frame_timeout_s, None)
                self._settle(self.in_flight - 1)

        for m in messages:
            if self.should_stop():
                self.echo("[replay] stopped by signal")
                break
            if t0_bag is None:  # the bag's clock starts with its first message in hand (opening the bag and
                # reading it take tens of milliseconds: counted from before, frame 0 went out late and frame 1, on
                # time, right after it, replacing it in a busy node's one-deep queue)
                t0_bag, t0_clock = m.log_time_ns, time.monotonic()
            if not self.lossless:
                due = t0_clock + (m.log_time_ns - t0_bag) * 1e-9 / self.rate
                while True:
                    now = time.monotonic()
                    if now >= due:
                        break
                    self.executor.spin_once(timeout_sec=due - now)  # returns early when a message arrives
                if m.topic == self.image_topic:
                    s = bags.stamp_ns(ts.deserialize_cdr(m.raw, m.msgtype))
                    self._publish_image(m.raw, s)
                else:
                    self.pubs[m.topic].publish(m.raw)
                self.executor.spin_once(timeout_sec=0)
                continue
            # lossless: images wait until their same-stamp companions (depth, right image) are out
            if m.topic == self.image_topic:
                s = bags.stamp_ns(ts.deserialize_cdr(m.raw, m.msgtype))
                held.append((m.raw, s, {t for t in hold_for if s in recent[t]}))
                seen_since.append(0)
            else:
                self.pubs[m.topic].publish(m.raw)
                if m.topic in hold_for:
                    try:
                        s2 = bags.stamp_ns(ts.deserialize_cdr(m.raw, m.msgtype))
                    except Exception:  # noqa: BLE001
                        s2 = None
                    recent[m.topic].append(s2)
                    for _, s, got in held:
                        if s == s2:
                            got.add(m.topic)
            seen_since = [k + 1 for k in seen_since]
            while held and (held[0][2] >= set(hold_for) or seen_since[0] > 8):
                seen_since.pop(0)
                release(0)
        while held:
            seen_since.pop(0)
            release(0)
        self._settle(0)
        if self._t_pub:
            assert self._t_first is not None  # set with the first publication
            self.stats.play_s = time.monotonic() - self._t_first
        # let the graph drain what is in flight (outputs travel on other topics than progress)
        t_end = time.monotonic() + (2.0 if not self.lossless else 0.5)
        while time.monotonic() < t_end:
            self.executor.spin_once(timeout_sec=0.02)
        if not self.lossless:
            for s in self.stats.published_stamps:
                st = self._frame_done(s)
                if st == "done":
                    self.stats.frames_completed += 1
                    self.stats.completed_stamps.append(s)
                elif st:
                    self.stats.frames_dropped += 1
                    self.stats.drop_reasons[st[8:]] += 1
                else:  # live queues keep the newest frame: an older one may never reach a busy node
                    missing = [n for n in self.nodes if n not in self._reports.get(s, {})]
                    self.stats.frames_dropped += 1
                    self.stats.drop_reasons[f"never reached {', '.join(missing)} (a newer frame replaced it "
                                            f"in the queue)"] += 1
        self.stats.wall_s = time.monotonic() - t0_wall
        return self.stats
