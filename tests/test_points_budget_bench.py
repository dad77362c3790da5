"""benchmarks/points_budget.py: the stage medians and the frames' comparison (the runs themselves are the
benchmark's, not a test's)."""

import pytest

from benchmarks.points_budget import SKIP, summary


def _frame(loc, total, digest, extract=5.0, deformable=None, mapping=None, tracker=2.0):
    f = {"loc_ms": loc, "total_ms": total, "extract_ms": extract, "tracker_ms": tracker, "digest": digest}
    if deformable is not None:
        f["deformable_ms"] = deformable
    if mapping is not None:
        f["mapping_ms"] = mapping
    return f


def test_the_first_frames_are_left_out_and_keyframes_mapping_is_not_tracking():
    warm = [_frame(500.0, 500.0, "w", mapping=400.0) for _ in range(SKIP)]
    loop = _frame(41.0, 40.0, "d", deformable=5.0, mapping=5.0)
    loop["loop_ms"] = 9.0  # 40 - 5 - 9 = 26: loop closing is not tracking either
    frames = warm + [_frame(30.0, 28.0, "a", deformable=4.0), _frame(90.0, 88.0, "b", deformable=6.0, mapping=60.0),
                     _frame(32.0, 30.0, "c", deformable=5.0), loop]
    ref = {"scene": "foam_beam", "frames": frames}
    s = summary(ref, None)
    assert s["frames"] == SKIP + 4 and "frames_differ" not in s
    assert s["loc_ms_p50"] == pytest.approx(36.5) and s["loc_ms_mean"] == pytest.approx(193 / 4)
    assert s["tracking_ms_p50"] == pytest.approx(28.0)  # 28, 88 - 60, 30, 26 (not 35): mapping and loops left out
    assert s["deformable_ms_p50"] == pytest.approx(5.0)
    other = {"scene": "foam_beam", "frames": warm[:-1] + [_frame(1.0, 1.0, "x")] + [dict(f) for f in frames[SKIP:]]}
    other["frames"][SKIP + 2]["digest"] = "changed"
    s2 = summary(other, ref)
    assert s2["frames_differ"] == 2  # a warm-up frame counts: every frame's pose and estimate are compared
    other["frames"] = other["frames"][:-1]
    assert summary(other, ref)["frames_differ"] == 3  # a frame missing differs
    old = {"scene": "foam_beam", "frames": warm + [_frame(30.0, 28.0, "a")]}  # a checkout that does not time it
    assert summary(old, None)["deformable_ms_p50"] != summary(old, None)["deformable_ms_p50"]  # NaN
