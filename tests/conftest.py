"""Test set-up: an isolated ROS domain per run, the SHM transport profile, shared-data paths."""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"

# A ROS domain of our own (0..101 are safe for Fast DDS port ranges), localhost discovery only.
os.environ["ROS_DOMAIN_ID"] = os.environ.get("SIMREAL_TEST_DOMAIN_ID", str(random.Random(os.getpid()).randint(20, 100)))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(ROOT / "simreal_nodes" / "ros" / "fastdds_shm.xml"))
os.environ.setdefault("MPLBACKEND", "Agg")


def shared(*parts) -> Path:
    """A file under ../shared/data; the test is skipped (with the reason) when the folder is absent."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real data not available: {p} (the ../shared/data folder is absent in this checkout)")
    return p


@pytest.fixture
def shared_data():
    return shared
