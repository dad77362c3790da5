"""The family SLAM benchmark's bookkeeping: a configuration's rows summarised apart from the defaults', the
``--config`` fields parsed against ``SlamConfig``, seed ranges written compactly."""

import pytest

from benchmarks.family_slam import _field, _ranges, summary


def _row(seed: int, config: str, tracked: float, ate_pct: float, **extra) -> dict:
    return {"seed": seed, "mode": "mono", "config": config, "tracked_pct": tracked, "ate_mm": 1.0,
            "ate_pct": ate_pct, "tracking_ms_p50": 30.0, **extra}


def test_summary_keeps_each_configuration_apart():
    rows = [_row(0, "default", 92.0, 0.1), _row(1, "default", 96.0, 0.5),
            _row(0, "early", 95.0, 0.2, onset=6, init_delay=0, tracked_after_onset_pct=100.0),
            _row(1, "early", 97.0, 0.2, onset=5, init_delay=1, tracked_after_onset_pct=99.0)]
    s = summary(rows)
    assert set(s) == {"mono", "mono (early)"}
    assert s["mono"]["share_tracked_target"] == 50.0 and s["mono"]["share_ate_target"] == 50.0
    assert s["mono"]["share_both_targets"] == 0.0  # each scene misses one of the two targets
    assert s["mono (early)"]["share_both_targets"] == 100.0
    assert "onset_median" not in s["mono"]  # no onset rows: no start summary
    assert s["mono (early)"]["init_delay_max"] == 1 and s["mono (early)"]["onset_median"] == 5.5


def test_config_fields_are_parsed_and_checked():
    assert _field("min_parallax_deg=1.5") == ("min_parallax_deg", 1.5)
    assert _field("homography_ambiguity=triangulated") == ("homography_ambiguity", "triangulated")
    assert _field("loop_closing=True") == ("loop_closing", True)
    with pytest.raises(SystemExit, match="no field"):
        _field("min_paralax_deg=1.5")


def test_seed_ranges():
    assert _ranges([1001, 0, 1, 2, 5, 1000, 1099]) == "0-2, 5, 1000-1001, 1099"
    assert _ranges([]) == ""


def test_a_report_rewritten_from_saved_runs_keeps_their_machine(tmp_path, monkeypatch):
    import json

    import benchmarks.common as common
    from benchmarks.family_slam import write

    monkeypatch.setattr(common, "RESULTS", tmp_path)
    rows = [_row(0, "default", 92.0, 0.1, frames=100, first_tracked=8, first_lost=None, rpe_1s_mm=1.0,
                 scale=1.0, keyframes=5, path_m=1.0)]

    def run(date: str, probe: float) -> dict:
        return {"cpu": "a CPU", "cpus": 2, "python": "3.11", "date": date, "cpu_probe_ms": probe}

    write(rows, "held-out seeds 0", "slam_one", [{"name": "slam_one", "machine": run("2026-01-02 03:04:05", 21.0)}])
    md = (tmp_path / "slam_one.md").read_text()
    assert "2026-01-02 03:04:05; CPU probe 21 ms" in md and "Composed" not in md
    assert json.loads((tmp_path / "slam_one.json").read_text())["machine"]["date"] == "2026-01-02 03:04:05"
    write(rows, "held-out seeds 0", "slam_two", [{"name": "a", "machine": run("2026-01-05 00:00:00", 30.0)},
                                                  {"name": "b", "machine": run("2026-01-02 00:00:00", 20.0)}])
    md = (tmp_path / "slam_two.md").read_text()
    assert "2026-01-05 00:00:00; CPU probe 30 ms" in md  # the newest run's line
    assert "`a` (a CPU, 2026-01-05 00:00:00, CPU probe 30 ms), `b` (a CPU, 2026-01-02 00:00:00, CPU probe 20 ms)" in md
    write(rows, "held-out seeds 0", "slam_three", [{"name": "a", "machine": run("2026-01-05 00:00:00", 30.0)},
                                                    {"name": "old", "machine": None}])
    assert "`old` (no machine recorded)" in (tmp_path / "slam_three.md").read_text()
