"""SIGINT / SIGTERM as a request to stop (`lifetime.StopSignals`, ROS-free): what the launcher, the player, the
recorder and every node process take their stop signals through."""

import os
import signal
import threading
import time

import pytest

from simreal_nodes.lifetime import WAIT_STEP_S, StopSignals


def _signal_later(sig: int, after_s: float) -> threading.Timer:
    timer = threading.Timer(after_s, os.kill, (os.getpid(), sig))
    timer.start()
    return timer


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_wait_ends_at_a_signal_and_the_handlers_go_back(sig):
    before = [signal.getsignal(s) for s in StopSignals.SIGNALS]
    with StopSignals(interrupting=False) as stop:
        assert stop.active and not stop.is_set()
        _signal_later(sig, 0.2).join()  # it comes before the wait below (a signal during a wait: the test after)
        t0 = time.monotonic()
        assert stop.wait(10.0)
        assert time.monotonic() - t0 < 1.0
        assert stop.is_set() and stop.requested == sig
    assert [signal.getsignal(s) for s in StopSignals.SIGNALS] == before


def test_wait_returns_false_after_its_timeout_without_a_signal():
    with StopSignals(interrupting=False) as stop:
        t0 = time.monotonic()
        assert not stop.wait(0.3)
        assert 0.3 <= time.monotonic() - t0 < 0.3 + 10 * WAIT_STEP_S
        assert not stop.is_set()


def test_a_signal_during_wait_ends_it_long_before_its_timeout():
    with StopSignals(interrupting=False) as stop:
        t0 = time.monotonic()
        timer = _signal_later(signal.SIGINT, 0.3)
        came = stop.wait(10.0)
        waited = time.monotonic() - t0
        timer.join()
    assert came
    assert 0.3 <= waited < 0.3 + 0.5  # the signal's delay, plus at most a step or two of a loaded machine


def test_interrupting_raises_keyboard_interrupt():
    with StopSignals() as stop, pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5.0)  # the handler raises here
    assert stop.requested == signal.SIGINT


def test_sigint_ignored_as_a_background_job_is_taken_over_and_put_back():
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with StopSignals(interrupting=False) as stop:
            assert stop.active and signal.getsignal(signal.SIGINT) is stop
            os.kill(os.getpid(), signal.SIGINT)
            assert stop.wait(5.0) and stop.requested == signal.SIGINT
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_handlers_a_process_chose_are_kept():
    def own(signum, frame):
        own.calls.append(signum)

    own.calls = []
    previous = signal.signal(signal.SIGTERM, own)
    try:
        with StopSignals(interrupting=False) as stop:
            assert not stop.active
            assert signal.getsignal(signal.SIGTERM) is own
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.05)
            assert own.calls == [signal.SIGTERM]
            assert not stop.wait(0.1)
        assert signal.getsignal(signal.SIGTERM) is own
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_only_the_main_thread_takes_the_signals():
    made: list[StopSignals] = []
    worker = threading.Thread(target=lambda: made.append(StopSignals(interrupting=False)))
    worker.start()
    worker.join()
    assert not made[0].active
    assert signal.getsignal(signal.SIGINT) is not made[0]
