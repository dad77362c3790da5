"""The launcher's environment for its node processes: DDS discovery stays on this host unless widened."""

import sys
import time

import pytest

from simreal_nodes.errors import SimrealError
from simreal_nodes.launch import DISCOVERY_RANGE, Launcher
from simreal_nodes.scene.graph import NodeSpec

PRINT_ENV = f"import os; print('{DISCOVERY_RANGE}=' + repr(os.environ.get('{DISCOVERY_RANGE}')))"


def child_discovery_range(tmp_path, base: dict, **kw) -> str:
    """What a node process started by the launcher sees (the node's command swapped for one that prints it)."""
    lines: list[str] = []
    launcher = Launcher([NodeSpec("ingest")], respawn=0, env=base, echo=lines.append, log_dir=tmp_path / "log", **kw)
    launcher.procs[0].cmd = [sys.executable, "-c", PRINT_ENV]
    with launcher:
        t_end = time.monotonic() + 20
        while not any(DISCOVERY_RANGE in x for x in lines) and time.monotonic() < t_end:
            time.sleep(0.05)
    return next(x for x in lines if DISCOVERY_RANGE in x).split("=", 1)[1]


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
