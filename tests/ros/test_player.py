"""The lossless player's frames in flight (`simreal replay --lossless --in-flight N`), against a stand-in graph that
reports the frames it is given: never more than N frames in the graph, each counted once as finished, dropped or
timed out, and a frame that never finishes holds up no other."""

import time

import numpy as np
import pytest

pytest.importorskip("rclpy")

from std_msgs.msg import Header

from simreal_nodes.io import bags
from simreal_nodes.ros.bagplay import MAX_IN_FLIGHT, Player, PlayStats
from simreal_nodes.ros.node import progress_id
from tests.helpers import write_camera_bag

pytestmark = pytest.mark.ros

NODES = ("ingest", "overlay")
IMAGE = "/camera/image_raw"


class _Pub:
    def publish(self, raw) -> None:
        pass


class _Node:
    """What the player asks of its node: publishers for the inputs, the progress subscription."""

    def create_publisher(self, cls, topic, qos):
        return _Pub()

    def create_subscription(self, cls, topic, cb, qos):
        return None


class _Graph:
    """The executor's stand-in: each spin, the graph finishes the oldest frame it holds (both nodes report it), or
    drops it (the first node says why, the second says nothing: the real graph's downstream nodes never see it), or
    never answers for it (``hung``). It notes how many published frames were not finished at each spin."""

    def __init__(self, player: Player, dropped=(), hung=()):
        self.player, self.dropped, self.hung = player, set(dropped), set(hung)
        self.answered: set[int] = set()
        self.most_open = 0

    def spin_once(self, timeout_sec=None) -> None:
        published = self.player.stats.published_stamps
        waiting = [s for s in published if s not in self.answered]
        self.most_open = max(self.most_open, len(waiting))
        todo = [s for s in waiting if published.index(s) not in self.hung]
        if not todo:
            time.sleep(0.001)
            return
        s = todo[0]
        self.answered.add(s)
        i = published.index(s)
        for k, name in enumerate(NODES):
            if i in self.dropped and k > 0:
                break
            h = Header()
            h.stamp.sec, h.stamp.nanosec = divmod(s, 10**9)
            h.frame_id = progress_id(name, time.monotonic(), "bad frame" if i in self.dropped else "")
            self.player._on_progress(h)


def _play(tmp_path, in_flight, n=12, frame_timeout_s=30.0, **graph):
    write_camera_bag(tmp_path / "in", n=n, w=64, h=48)
    said: list[tuple[str, int]] = []  # the player's messages, with how many frames the graph had answered then
    player = Player(_Node(), None, {IMAGE: "sensor_msgs/msg/Image"}, IMAGE, list(NODES), lossless=True,
                    frame_timeout_s=frame_timeout_s, echo=lambda m: said.append((m, len(g.answered))),
                    in_flight=in_flight)
    g = _Graph(player, **graph)
    player.executor = g
    stats = player.play(bags.read_bag(tmp_path / "in", topics=[IMAGE]))
    g.said = said
    return stats, g


@pytest.mark.parametrize("in_flight", [1, 3])
def test_no_more_frames_in_the_graph_than_allowed_and_each_counted_once(tmp_path, in_flight):
    stats, g = _play(tmp_path, in_flight)
    assert stats.frames_published == 12 and stats.frames_completed == 12
    assert stats.frames_dropped == stats.frames_timed_out == stats.conflicting_reports == 0
    assert g.most_open == in_flight  # the window filled, never overflowed


def test_a_dropped_frame_is_counted_dropped_once(tmp_path):
    stats, g = _play(tmp_path, 3, dropped={4, 9})
    assert stats.frames_completed == 10 and stats.frames_dropped == 2 and stats.frames_timed_out == 0
    pub = stats.published_stamps
    assert stats.completed_stamps == [s for i, s in enumerate(pub) if i not in (4, 9)]
    assert dict(stats.drop_reasons) == {"ingest: bad frame": 2}
    assert g.most_open <= 3


@pytest.mark.parametrize("in_flight,answered", [(1, 2), (3, 11)])
def test_a_frame_that_never_finishes_times_out_and_holds_up_no_other_with_frames_in_flight(tmp_path, in_flight,
                                                                                          answered):
    stats, g = _play(tmp_path, in_flight, frame_timeout_s=0.5, hung={2})
    assert stats.frames_completed == 11 and stats.frames_timed_out == 1 and stats.frames_dropped == 0
    (msg, seen), = g.said
    assert "not finished after" in msg
    # lock-step: nothing after the hung frame went in before its timeout; with room in flight, every other frame did
    assert seen == answered


@pytest.mark.parametrize("in_flight", [0, MAX_IN_FLIGHT + 1])
def test_the_player_refuses_no_frame_or_more_than_the_nodes_hold_in_flight(in_flight):
    with pytest.raises(ValueError, match=f"lets 1 to {MAX_IN_FLIGHT} frames"):
        Player(_Node(), None, {IMAGE: "sensor_msgs/msg/Image"}, IMAGE, list(NODES), lossless=True,
               in_flight=in_flight)


def test_the_bound_stays_below_what_a_node_holds_waiting_for_inputs():
    from simreal_nodes.sync import StampSync

    assert StampSync(("a",)).max_pending >= 2 * MAX_IN_FLIGHT


def test_a_frame_with_the_stamp_of_one_still_in_the_graph_waits_for_it(tmp_path):
    """Frames are keyed by stamp: a second image with a stamp still in flight is published once the first left (as
    lock-step did), so every frame is counted once."""
    write_camera_bag(tmp_path / "in", n=6, w=64, h=48)
    msgs = list(bags.read_bag(tmp_path / "in", topics=[IMAGE]))
    msgs = msgs[:3] + [msgs[2]] + msgs[3:]  # frame 2 twice
    player = Player(_Node(), None, {IMAGE: "sensor_msgs/msg/Image"}, IMAGE, list(NODES), lossless=True,
                    echo=lambda *a: None, in_flight=3)
    player.executor = _Graph(player)
    stats = player.play(msgs)
    assert stats.frames_published == 7
    assert stats.frames_completed == 7 and stats.frames_dropped == stats.frames_timed_out == 0


def test_live_the_frames_every_node_finished_are_listed(tmp_path):
    """Live, the frames through are listed too (the steady share reads them), and one the graph never finished is
    not."""
    write_camera_bag(tmp_path / "in", n=8, w=64, h=48, fps=60.0)
    player = Player(_Node(), None, {IMAGE: "sensor_msgs/msg/Image"}, IMAGE, list(NODES), lossless=False,
                    echo=lambda *a: None)
    player.executor = _Graph(player, hung={5})
    stats = player.play(bags.read_bag(tmp_path / "in", topics=[IMAGE]))
    pub = stats.published_stamps
    assert len(pub) == 8 and sorted(stats.completed_stamps) == [s for i, s in enumerate(pub) if i != 5]
    assert stats.frames_completed == 7 and stats.frames_dropped == 1


def test_the_steady_share_leaves_the_start_up_out():
    """Live, the frames lost while the nodes build on the first CameraInfo are the start-up's; the share after the
    first second counts the rest (and says NaN where no frame is that late)."""
    st = PlayStats()
    st.published_stamps = [round(i * 1e9 / 30) for i in range(90)]  # 3 s at 30 fps
    st.completed_stamps = [s for i, s in enumerate(st.published_stamps) if i == 1 or (i > 8 and i != 60)]
    assert st.through_after(1.0) == pytest.approx(100 * 59 / 60)  # frame 60 lost in the steady state
    assert st.through_after(0.0) == pytest.approx(100 * 81 / 90)
    assert st.as_dict()["through_after_startup_pct"] == pytest.approx(100 * 59 / 60)
    assert st.lost_before(1.0) == 8 and st.lost_before(10.0) == 9  # frames 0 and 2-8 in the first second, 60 after
    assert st.through_after(5.0) != st.through_after(5.0)  # NaN: no frame 5 s in
    assert PlayStats().through_after(1.0) != PlayStats().through_after(1.0)


def test_a_node_process_loads_before_its_nodes_what_their_first_frame_would_wait_for():
    """Issue 18 (live, the frames that arrive while the first one waits are lost): rosbags' type store is loaded and
    inspect's module index (rclpy's logger's caller search) built before the nodes are."""
    import inspect

    from simreal_nodes.ros import convert
    from simreal_nodes.ros.node import warm_start

    convert._jazzy_types.cache_clear()
    inspect.modulesbyfile.clear()
    inspect._filesbymodname.clear()  # else a module another test indexed already is skipped (CI: 12 indexed)
    warm_start()
    assert convert._jazzy_types.cache_info().currsize == 1
    assert len(inspect.modulesbyfile) > 100  # every loaded module indexed


def test_a_node_process_warms_up_before_it_builds_its_nodes(monkeypatch):
    """`run_nodes` (every node process, and the one-process launch) calls the warm start before it builds its nodes
    (a signal in the warm start then meets no node half started) and spins after."""
    from rclpy.node import Node

    from simreal_nodes.ros import node as node_mod

    order = []

    def build(name):
        order.append(("build", name))
        return Node(name)

    monkeypatch.setattr(node_mod, "warm_start", lambda: order.append(("warm", None)))
    monkeypatch.setattr(node_mod, "spin", lambda ex, stop=None: order.append(("spin", None)))
    import signal

    before = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]
    assert node_mod.run_nodes([lambda: build("warm_a"), lambda: build("warm_b")]) == 0
    assert order == [("warm", None), ("build", "warm_a"), ("build", "warm_b"), ("spin", None)]
    # the process's stop-signal handlers (StopSignals) are put back as they were once run_nodes is done
    assert [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)] == before


def test_a_signal_while_the_nodes_are_built_stops_the_process_cleanly(monkeypatch):
    """A stop signal between two node builds of the one-process launch (rclpy's handler shuts the context down; here
    the first build does it): the second build fails on the dead context, and `run_nodes` closes what it built and
    returns 0, as a stop during the spin does. Before, the build's RCLError ended the process with exit code 1 and a
    traceback (`tests/ros/test_launch.py`, SIGTERM right after the ingest node came up, met it in CI)."""
    import rclpy
    from rclpy.node import Node

    from simreal_nodes.ros import node as node_mod

    built = []

    def first():
        n = Node("sig_a")
        built.append(n)
        rclpy.shutdown()  # the signal arrives now
        return n

    monkeypatch.setattr(node_mod, "warm_start", lambda: None)
    monkeypatch.setattr(node_mod, "spin", lambda ex, stop=None: pytest.fail("the process spun after the signal"))
    assert node_mod.run_nodes([first, lambda: Node("sig_b")]) == 0
    assert len(built) == 1 and not rclpy.ok()


def test_live_the_bags_clock_starts_with_its_first_message_in_hand(tmp_path):
    """Issue 18: live, the frames go out at the bag's rate from the first one on, however long the bag took to open
    and yield its first message (counted from before, frame 0 went out late and frame 1 right after it: a busy
    node's one-deep queue kept only frame 1, and a replay of the demo lost its first frame that way)."""
    write_camera_bag(tmp_path / "in", n=4, w=64, h=48, fps=30.0)

    def slow_to_open():
        time.sleep(0.2)
        yield from bags.read_bag(tmp_path / "in", topics=[IMAGE])

    player = Player(_Node(), None, {IMAGE: "sensor_msgs/msg/Image"}, IMAGE, list(NODES), lossless=False,
                    echo=lambda *a: None)
    player.executor = _Graph(player)
    stats = player.play(slow_to_open())
    t = [player._t_pub[s] for s in stats.published_stamps]
    assert len(t) == 4
    assert min(np.diff(t)) > 0.8 / 30  # a frame period apart, the first two too
