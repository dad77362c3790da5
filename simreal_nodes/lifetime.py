"""How a process of this project ends (ROS-free): a child that ends with its parent (Linux ``PR_SET_PDEATHSIG``),
and SIGINT / SIGTERM taken as a request to stop (:class:`StopSignals`).

:func:`end_with_parent` is used by the node processes the launcher starts (they end when the launcher does, even by
``kill -9``) and by the tracker's registration worker (it ends with its node)."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time


def end_with_parent(parent: int, sig: int) -> bool:
    """Ask the kernel to send ``sig`` to this process when its parent ends (Linux; elsewhere nothing is asked and
    True is returned). False when the parent, pid ``parent``, is already gone: it died before the request, and no
    signal will come."""
    if not sys.platform.startswith("linux"):
        return True
    import ctypes

    pr_set_pdeathsig = 1
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(sig), 0, 0, 0)
    return os.getppid() == parent


#: the longest :meth:`StopSignals.wait` takes to notice a signal
WAIT_STEP_S = 0.05


class StopSignals:
    """SIGINT and SIGTERM, taken as a request to stop that the main thread acts on at its next step. In
    :func:`simreal_nodes.ros.node.run_nodes` (every node process) they end the spin between two ``spin_once`` steps,
    and rclpy's own handlers are not installed (``rclpy.init(signal_handler_options=NO)``); before the executor
    exists (the nodes being built, a standby waiting) a signal still raises ``KeyboardInterrupt``
    (``interrupting``), so a long build stops at once. ``simreal replay``'s player, ``simreal record`` and the
    launcher (:func:`simreal_nodes.launch.run_until_signal`) take them with ``interrupting`` off from the start (a
    context manager: the handlers go back on leaving it) and read :meth:`is_set` between their steps, or sleep in
    :meth:`wait`, which a signal ends within :data:`WAIT_STEP_S`.

    Why not rclpy's handlers: they shut the context down from a thread of their own, at any moment. When that lands
    while the EventsExecutor registers the nodes' entities (its first ``spin_once`` does it, in C++), the wait set it
    builds for a QoS event handler fails on the dead context, the registration stops half done with callbacks
    registered that the executor no longer tracks, and its destructor aborts the process ("Destroying callback
    manager with callbacks remaining", exit code -6, or a segfault). The ``KeyboardInterrupt`` that rclpy's handler
    passes on to Python's struck the same registration from inside (``event_handler.add_to_wait_set``). CI met it
    in ``tests/ros/test_launch.py``, a SIGINT a millisecond after the one-process launch built its nodes; reproduced
    here in 2 of 10 such runs (and 14 of 30 with the interrupt alone removed). Here the context stays up until
    every node is closed and destroyed, so a node's ``close()`` may still publish, and a second signal does not
    break into it. Installed only from the main thread (the only one that may), over handlers no one chose
    (:data:`NOT_CUSTOM`); :meth:`restore` puts those back. ``active`` False: the handlers the process had stay
    (rclpy's in a node process; the process's owner installed its own), and no signal reaches :meth:`is_set`."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)
    #: what a process may find that no one chose for it: Python's defaults, and SIGINT ignored, as a shell starts a
    #: command in the background (rclpy's handlers took over from all three, and so do these)
    NOT_CUSTOM = (signal.default_int_handler, signal.SIG_DFL, signal.SIG_IGN, None)

    def __init__(self, interrupting: bool = True) -> None:
        self.requested: int | None = None
        self.interrupting = interrupting
        self.active = threading.current_thread() is threading.main_thread() and all(
            signal.getsignal(s) in self.NOT_CUSTOM for s in self.SIGNALS)
        self._previous = {s: signal.signal(s, self) for s in self.SIGNALS} if self.active else {}

    def __call__(self, signum, frame) -> None:
        self.requested = signum
        if self.interrupting:
            raise KeyboardInterrupt

    def is_set(self) -> bool:
        """Whether a stop signal came."""
        return self.requested is not None

    def wait(self, timeout: float) -> bool:
        """Sleep until a stop signal comes (noticed within :data:`WAIT_STEP_S`) or ``timeout`` seconds pass; whether
        one came. Polled: a ``threading.Event`` set from the handler (the launcher's way until stop 114) deadlocks
        when the handler runs in the short stretches where ``Event.wait`` holds the event's own (non-reentrant) lock,
        before and after its blocking sleep (not during it: the sleep releases it)."""
        t_end = time.monotonic() + timeout
        while self.requested is None:
            left = t_end - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(WAIT_STEP_S, left))
        return self.requested is not None

    def __enter__(self) -> StopSignals:
        return self

    def __exit__(self, *exc) -> None:
        self.restore()

    def restore(self) -> None:
        for s, handler in self._previous.items():
            if signal.getsignal(s) is self:
                signal.signal(s, signal.SIG_DFL if handler is None else handler)
        self._previous = {}
