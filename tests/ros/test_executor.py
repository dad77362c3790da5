"""The node processes' executor (``SIMREAL_EXECUTOR``): both kinds run a node's timers, subscriptions and services
and end cleanly on SIGTERM; an unknown kind is refused with the choices named."""

import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytest.importorskip("rclpy")

from simreal_nodes.errors import SimrealError
from simreal_nodes.launch import DEFAULT_EXECUTOR, EXECUTOR_ENV, EXECUTORS, executor_kind, ros_environment

pytestmark = pytest.mark.ros

# A node process as run_nodes runs one: a timer publishes, the node's own subscription counts, a service answers a
# call made from the timer; it reports each once, then waits to be signalled; close() reports on the way out.
NODE = textwrap.dedent("""
    from rclpy.node import Node
    from std_msgs.msg import Header
    from std_srvs.srv import SetBool
    from simreal_nodes.ros.node import run_nodes

    class Probe(Node):
        def __init__(self):
            super().__init__("executor_probe")
            self.ticks, self.heard, self.answered = 0, 0, False
            self.pub = self.create_publisher(Header, "~/beat", 10)
            self.create_subscription(Header, "~/beat", self.on_beat, 10)
            self.create_service(SetBool, "~/ask", lambda req, resp: setattr(resp, "success", req.data) or resp)
            self.cli = self.create_client(SetBool, "~/ask")
            self.create_timer(0.02, self.on_timer)

        def on_timer(self):
            self.ticks += 1
            self.pub.publish(Header(frame_id=str(self.ticks)))
            if self.ticks == 5:
                print("timer fired", flush=True)
                self.cli.call_async(SetBool.Request(data=True)).add_done_callback(self.on_answer)

        def on_beat(self, msg):
            self.heard += 1
            if self.heard == 5:
                print("subscription heard", flush=True)

        def on_answer(self, future):
            if future.result().success and not self.answered:
                self.answered = True
                print("service answered", flush=True)

        def close(self):
            print(f"closed after {self.ticks} ticks", flush=True)

    run_nodes([Probe])
""")


@pytest.mark.parametrize("kind", EXECUTORS)
def test_node_process_runs_and_ends_on_sigterm(kind):
    env = ros_environment(executor=kind)
    assert env[EXECUTOR_ENV] == kind
    p = subprocess.Popen([sys.executable, "-c", NODE], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True)
    lines: list[str] = []
    try:
        assert p.stdout is not None
        t_end = time.monotonic() + 30
        while time.monotonic() < t_end and not {"timer fired", "subscription heard",
                                                "service answered"} <= set(lines):
            line = p.stdout.readline()
            if not line:
                break
            lines.append(line.strip())
        assert {"timer fired", "subscription heard", "service answered"} <= set(lines), lines
        p.send_signal(signal.SIGTERM)
        out, _ = p.communicate(timeout=10)  # the EventsExecutor's own spin() would spin here for ever
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, out
    assert "closed after" in out


def test_executor_kind_default_environment_and_refusal():
    assert DEFAULT_EXECUTOR == "events"
    assert executor_kind({}) == DEFAULT_EXECUTOR
    assert executor_kind({EXECUTOR_ENV: "single"}) == "single"
    assert ros_environment({EXECUTOR_ENV: "single"})[EXECUTOR_ENV] == "single"  # the user's choice is passed on
    assert ros_environment({EXECUTOR_ENV: "single"}, executor="events")[EXECUTOR_ENV] == "events"  # the option wins
    with pytest.raises(SimrealError, match="must be one of events, single"):
        executor_kind({EXECUTOR_ENV: "multi"})
    with pytest.raises(SimrealError, match="must be one of events, single"):
        ros_environment({}, executor="multi")


# A stop signal that lands while the executor takes in the nodes' entities (its first spin_once: the EventsExecutor
# registers a callback per subscription, from C++, and reads each one's ``handle`` there): the signal is sent from
# inside the second such read of the spin. With rclpy's handlers (before stop 112), the KeyboardInterrupt they pass
# on broke the registration half done and the EventsExecutor's destructor aborted the process ("Destroying callback
# manager with callbacks remaining", exit code -6), as a SIGINT a millisecond after the one-process launch built its
# nodes did in CI.
SIGNAL_IN_REGISTRATION = textwrap.dedent("""
    import os, signal, sys
    import rclpy
    from rclpy.node import Node
    from rclpy.subscription import Subscription
    from std_msgs.msg import Header
    from simreal_nodes.ros import node as node_mod

    plain = Subscription.handle.fget
    reads = []

    def in_spin():
        f = sys._getframe(2)
        while f is not None:
            if f.f_code is node_mod.spin.__code__:
                return True
            f = f.f_back
        return False

    def handle(self):
        if in_spin():
            reads.append(1)
            if len(reads) == 2:
                os.kill(os.getpid(), signal.SIGINT)
        return plain(self)

    Subscription.handle = property(handle)

    class Listener(Node):
        def __init__(self):
            super().__init__("registration_probe")
            for i in range(3):
                self.create_subscription(Header, f"~/in{i}", lambda m: None, 10)

        def close(self):
            print(f"closed, context up {rclpy.ok()}", flush=True)

    code = node_mod.run_nodes([Listener])
    print(f"signal read {len(reads) >= 2}, returned {code}", flush=True)
""")


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# "ignored": the process starts with SIGINT ignored, as a shell starts a background command (a CI job run with `&`)
@pytest.mark.parametrize("inherited", ["default", "ignored"])
@pytest.mark.parametrize("kind", EXECUTORS)
def test_a_signal_while_the_executor_registers_the_nodes_ends_the_process_cleanly(kind, inherited):
    p = subprocess.run([sys.executable, "-c", SIGNAL_IN_REGISTRATION], env=ros_environment(executor=kind),
                       capture_output=True, text=True, timeout=60,
                       preexec_fn=_ignore_sigint if inherited == "ignored" else None)
    out = p.stdout + p.stderr
    assert "callbacks remaining" not in out, out
    assert p.returncode == 0, out
    # the spin ended on the signal, and the nodes closed with the context still up (it goes down after them)
    assert "signal read True, returned 0" in out and "closed, context up True" in out, out
