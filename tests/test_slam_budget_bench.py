"""benchmarks/slam_budget.py: the stage split and the poses' comparison (the timed runs themselves are the
benchmark's, not a test's)."""

import numpy as np
import pytest

from benchmarks.slam_budget import MODES, summary


def _frame(total, digest, mapping=0.0, tracked=True, extract=10.0):
    f = {"total_ms": total, "extract_ms": extract, "depth_ms": 0.1, "pose_ms": 1.0, "local_map_ms": 2.0,
         "tracked": tracked, "digest": digest if tracked else ""}
    if tracked:
        f["match_ms"] = 2.0
    if mapping:
        f["mapping_ms"] = mapping
    return f


def _doc(frames):
    return {"seed": 0, "runs": {m: {"frames": frames, "keyframes": 3, "points": 100} for m in MODES}}


def test_tracking_time_leaves_out_mapping_and_the_first_frames_and_changed_poses_are_counted():
    start = [_frame(500.0, f"s{i}") for i in range(5)]  # the map's start: left out of the medians
    ref = _doc(start + [_frame(20.0, "a"), _frame(60.0, "b", mapping=40.0), _frame(30.0, "c"),
                        _frame(99.0, "", tracked=False)])
    other = _doc(start + [_frame(18.0, "a"), _frame(58.0, "b", mapping=40.0), _frame(28.0, "x"),
                          _frame(99.0, "", tracked=False)])
    s = summary(other, ref)
    assert s["mono_tracking_ms_p50"] == pytest.approx(18.0)  # 18, 58 - 40, 28
    assert s["mono_extract_ms_p50"] == pytest.approx(10.0)
    assert s["mono_mapping_ms_per_frame"] == pytest.approx(40.0 / 9)
    assert s["mono_tracked"] == 8 and s["mono_frames"] == 9
    assert s["mono_poses_differ"] == 1 and s["rgbd_poses_differ"] == 1
    short = _doc(other["runs"]["mono"]["frames"][:-2])
    assert summary(short, ref)["mono_poses_differ"] == 2  # two frames missing (the changed one among them)
    assert "mono_poses_differ" not in summary(ref, None)
    assert np.isnan(summary(_doc(start), None)["mono_tracking_ms_p50"])  # nothing tracked past the start
