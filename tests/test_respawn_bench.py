"""The respawn benchmark's harness: a hung run is killed with every process below it."""

from __future__ import annotations

import subprocess
import sys
import time

import psutil

from benchmarks.respawn import kill_tree

# a child that starts a grandchild in a session of its own (as the launcher starts nodes), then hangs
SPAWNER = ("import subprocess, sys, time; "
           "p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'], start_new_session=True); "
           "print(p.pid, flush=True); time.sleep(60)")


def test_kill_tree_ends_the_child_and_the_process_it_started_in_another_session():
    child = subprocess.Popen([sys.executable, "-c", SPAWNER], stdout=subprocess.PIPE, text=True)
    assert child.stdout is not None
    grandchild = int(child.stdout.readline())
    assert psutil.pid_exists(grandchild)
    kill_tree(child.pid)
    assert child.wait(10) != 0
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            if psutil.Process(grandchild).status() == psutil.STATUS_ZOMBIE:
                break
        except psutil.NoSuchProcess:
            break
        time.sleep(0.05)
    else:
        raise AssertionError(f"process {grandchild} outlived kill_tree")


def test_kill_tree_of_a_process_gone_already_is_quiet():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    kill_tree(p.pid)
