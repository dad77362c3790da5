"""The respawn benchmark's harness: a run in a child process, killed with every process below it when it hangs."""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import psutil

from benchmarks.respawn import kill_tree, run_isolated

# a child that starts a grandchild in a session of its own (as the launcher starts nodes), then hangs
SPAWNER = ("import subprocess, sys, time; "
           "p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'], start_new_session=True); "
           "print(p.pid, flush=True); time.sleep(60)")


def _gone(pid: int, within_s: float = 10.0) -> bool:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            if psutil.Process(pid).status() == psutil.STATUS_ZOMBIE:
                return True
        except psutil.NoSuchProcess:
            return True
        time.sleep(0.05)
    return False


def test_kill_tree_ends_the_child_and_the_process_it_started_in_another_session():
    child = subprocess.Popen([sys.executable, "-c", SPAWNER], stdout=subprocess.PIPE, text=True)
    assert child.stdout is not None
    grandchild = None
    try:
        grandchild = int(child.stdout.readline())
        assert psutil.pid_exists(grandchild)
        kill_tree(child.pid)
        assert child.wait(10) != 0
        assert _gone(grandchild), f"process {grandchild} outlived kill_tree"
    finally:
        for pid in (child.pid, grandchild):
            if pid is not None and psutil.pid_exists(pid):
                psutil.Process(pid).kill()
        child.stdout.close()
        child.wait()


def test_kill_tree_of_a_process_gone_already_is_quiet():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    kill_tree(p.pid)


def test_a_run_that_hangs_is_killed_and_reported_as_a_failed_try():
    def hang(victim: str, standby: bool, row: Path) -> list[str]:
        return [sys.executable, "-c", "import time; time.sleep(60)"]

    t0 = time.monotonic()
    row, why = run_isolated("tracker", True, timeout=1.0, command=hang)
    assert row is None and why == "timed out after 1 s"
    assert time.monotonic() - t0 < 30


def test_a_run_that_fails_is_a_failed_try_and_a_row_keeps_its_nan():
    def fail(victim: str, standby: bool, row: Path) -> list[str]:
        return [sys.executable, "-c", "raise SystemExit(3)"]

    def write(victim: str, standby: bool, row: Path) -> list[str]:
        code = (f"import json; open({str(row)!r}, 'w').write(json.dumps("
                f"{{'node': {victim!r}, 'standby': {standby!r}, 'gap_s': float('nan')}}))")
        return [sys.executable, "-c", code]

    assert run_isolated("overlay", False, timeout=30.0, command=fail) == (None, "exit status 3")
    row, why = run_isolated("overlay", False, timeout=30.0, command=write)
    assert why == "" and row is not None and row["node"] == "overlay" and row["standby"] is False
    assert math.isnan(row["gap_s"])
