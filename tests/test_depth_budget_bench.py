"""benchmarks/depth_budget.py: which calls each stage counts, the stage split and the estimates' comparison (the
runs themselves are the benchmark's, not a test's)."""

import numpy as np
import pytest

from benchmarks.depth_budget import summary, timed


def test_a_stage_counts_its_calls_only_where_its_rule_says(monkeypatch):
    import benchmarks.depth_budget as db

    clock = [0.0]  # a clock that moves only when a stage "works": exact, whatever the host's load
    monkeypatch.setattr(db.time, "perf_counter", lambda: clock[0])
    spent = {"search": 0.0, "links": 0.0, "fit": 0.0, "nearest": 0.0}
    active = dict.fromkeys(spent, 0)

    def work(ms):
        clock[0] += ms / 1e3

    links = timed(spent, active, "links", None, "search", lambda: work(5))
    nearest = timed(spent, active, "nearest", "fit", None, lambda: work(3))
    search = timed(spent, active, "search", None, None, lambda: [links() for _ in range(3)])
    fit = timed(spent, active, "fit", None, None, lambda: (nearest(), nearest(), work(1)))
    links()  # outside the search: counted
    search()  # its three links are its own
    nearest()  # outside a fit: not counted
    fit()
    assert spent == pytest.approx({"search": 15.0, "links": 5.0, "fit": 7.0, "nearest": 6.0})
    assert all(v == 0 for v in active.values())


def _frame(tracker, fit, nearest, residuals, links, search, est, theta=0.5, state=1):
    return {"tracker_ms": tracker, "cpu_ms": 0.9 * (tracker or 0.0), "depth_fit": fit, "nearest": nearest,
            "residuals": residuals, "links": links, "constant_search": search, "est": est, "theta": theta,
            "state": state}


def test_the_stages_split_the_frame_and_the_estimates_are_compared_in_percent_of_range():
    span = [0.9, 3.0]
    ref = {"spans": span, "frames": [_frame(None, 0, 0, 0, 0, 0, [0.0, 0.0], theta=0.0),
                                     _frame(500.0, 30, 10, 12, 5, 400, [0.50, 1.0]),
                                     _frame(60.0, 40, 15, 20, 6, 0, [0.52, 1.0]),
                                     _frame(50.0, 30, 12, 15, 4, 0, [0.56, 1.0])]}
    other = {"spans": span, "frames": [_frame(None, 0, 0, 0, 0, 0, [0.0, 0.0], theta=0.0),
                                       _frame(400.0, 20, 8, 10, 4, 350, [0.50, 1.0]),
                                       _frame(40.0, 25, 10, 12, 4, 0, [0.52, 1.03], state=2),
                                       _frame(30.0, 20, 9, 10, 3, 0, [0.56, 1.0])]}
    s = summary(other, ref)
    assert s["frames_tracked"] == 3  # a frame without a camera pose is left out
    assert s["slowest_ms"] == 400.0
    assert s["tracker_ms_p50"] == pytest.approx(40.0)
    assert s["cpu_ms_p50"] == pytest.approx(36.0)
    assert s["residuals_ms_p50"] == pytest.approx(np.median([10 - 8, 12 - 10, 10 - 9]))  # less the nearest search
    assert s["other_ms_p50"] == pytest.approx(np.median([400 - 20 - 4 - 350, 40 - 25 - 4, 30 - 20 - 3]))
    assert s["constant_search_ms_mean"] == pytest.approx(350 / 3)
    assert s["theta_err_pct_p50"] == pytest.approx(100 * np.rad2deg(0.02) / 52.0)  # 0.50, 0.52, 0.56 against 0.5
    assert s["est_diff_pct"] == pytest.approx(100 * 0.03 / 3.0)
    assert s["states_differ"] == 1
    assert "est_diff_pct" not in summary(ref, None)
