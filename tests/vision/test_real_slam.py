"""The SLAM on real Kinect frames with ground truth (7-Scenes, ``../shared/data/real7scenes``; skipped without it), as
``./run bench real_slam`` runs it: a regression on real images fails here. The bounds are about twice what the SLAM
measured (RGB-D on the first 120 frames 12.7 mm), or, for the monocular ATE on all 500 frames (30 mm after a
similarity alignment since the keyframes' points are fused with their neighbours' as ORB-SLAM2 does; 458 mm without
that from the five-point start, 59 mm from the eight-point one), about 1.7 times: losing the fusion fails here. The
ground truth itself is good to 1-2 cm. A monocular change that held on the first 200 frames (21 mm) lost the map at
frame 486 with an ATE of 538 mm: hence the whole sequence."""

from __future__ import annotations

import pytest

from benchmarks.real_slam import load, run
from tests.conftest import shared


@pytest.fixture(scope="module")
def real7() -> dict:
    return load(shared("real7scenes"))


def test_rgbd_slam_tracks_real_kinect_frames(real7):
    seq = {**real7, "gray": real7["gray"][:120], "depth": real7["depth"][:120], "T": real7["T"][:120]}
    row = run(seq, "rgbd")
    assert row["tracked"] == 120 and row["first_tracked"] == 0
    assert row["ate_mm"] < 30.0, row


def test_monocular_slam_initializes_and_tracks_real_frames(real7):
    row = run(real7, "mono")
    assert row["first_tracked"] is not None and row["first_tracked"] < 60, row
    assert row["tracked"] >= 450 and row["first_lost"] is None, row
    assert row["ate_mm"] < 50.0, row  # after a similarity alignment (scale unknown); 458 mm without the fusion
