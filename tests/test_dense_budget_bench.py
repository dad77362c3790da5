"""benchmarks/dense_budget.py: the stage split and the estimates' comparison (the runs themselves are the
benchmark's, not a test's)."""

import subprocess

import numpy as np
import pytest

from benchmarks.common import commit
from benchmarks.dense_budget import summary


def _frame(solve, grid, fit_from, refine, camera, est, state=1, tracker=None):
    return {"solve": solve, "_grid_start": grid, "_fit_from": fit_from, "_refine": refine, "_fit_camera": camera,
            "tracker_ms": tracker if tracker is not None else solve + 5.0, "est": est, "state": state}


def test_the_stages_split_the_solve_and_the_estimates_are_compared_in_percent_of_range():
    ref = {"spans": [0.5], "frames": [_frame(0.0, 0, 0, 0, 0, [0.2], tracker=1.0),
                                      _frame(100.0, 10, 60, 20, 15, [0.25]),
                                      _frame(120.0, 12, 70, 25, 20, [0.30])]}
    other = {"spans": [0.5], "frames": [_frame(0.0, 0, 0, 0, 0, [0.2], tracker=1.0),
                                        _frame(80.0, 8, 50, 15, 10, [0.2505], state=2),
                                        _frame(90.0, 9, 55, 18, 12, [0.30])]}
    s = summary(other, ref)
    assert s["frames_solved"] == 2  # a frame without a solve (no template yet) is left out of the stages
    assert s["solve_ms_p50"] == pytest.approx(85.0)
    assert s["gauss_newton_ms_p50"] == pytest.approx(np.median([50 - 15, 55 - 18]))
    assert s["rest_ms_p50"] == pytest.approx(np.median([80 - 8 - 50 - 10, 90 - 9 - 55 - 12]))
    assert s["est_diff_pct"] == pytest.approx(100 * 0.0005 / 0.5)
    assert s["states_differ"] == 1
    assert s["tracker_ms_p50"] == pytest.approx(85.0)  # over every frame with a camera pose
    assert "est_diff_pct" not in summary(ref, None)


def test_a_checkout_is_named_by_its_commit(tmp_path):
    assert commit(tmp_path) == "?"  # not a git checkout
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    (tmp_path / "a").write_text("1")
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(git + ["add", "a"], check=True)
    subprocess.run(git + ["commit", "-qm", "a"], check=True)
    rev = commit(tmp_path)
    assert len(rev) == 7 and not rev.endswith("+")
    (tmp_path / "a").write_text("2")
    assert commit(tmp_path) == rev + "+"  # tracked files changed since the commit
