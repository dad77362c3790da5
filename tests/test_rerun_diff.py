"""benchmarks/rerun_diff.py: a rerun's table compared with the committed one, row by row."""

import math

from benchmarks.rerun_diff import compare, is_timing, main, report, row_key


def _table(rows, **summary):
    return {"rows": rows, "summary": summary, "machine": {"cpu": "X", "commit": "abc"}}


def test_timing_fields_are_told_from_accuracy_fields():
    for f in ("step_ms_p50", "tracker_ms_mean", "render_s", "cpu_probe_ms", "fps", "frames_per_s"):
        assert is_timing(f), f
    for f in ("registration_mm", "median_err_pct", "distance_m", "seed", "holds_deg", "camera_tracked_pct"):
        assert not is_timing(f), f


def test_identical_rerun_is_the_same_in_every_row_and_timings_give_a_ratio():
    old = _table([{"seed": s, "median_err_pct": 0.1 * s, "step_ms_p50": 10.0} for s in range(5)], median=0.2)
    new = _table([{"seed": s, "median_err_pct": 0.1 * s, "step_ms_p50": 12.0} for s in range(5)], median=0.2)
    d = compare(old, new)
    assert (d["matched"], d["identical"]) == (5, 5)
    assert d["fields"]["median_err_pct"]["moved"] == 0
    assert math.isclose(d["fields"]["step_ms_p50"]["ratio_median"], 1.2)
    assert "every figure the same" in report("t", d, "a", "b")


def test_moved_rows_are_counted_and_the_largest_named():
    old = _table([{"seed": s, "err": 1.0} for s in range(4)], median=1.0)
    new = _table([{"seed": 0, "err": 1.0}, {"seed": 1, "err": 1.0 + 1e-12}, {"seed": 2, "err": 1.5},
                  {"seed": 3, "err": 0.8}], median=1.1)
    d = compare(old, new)
    assert d["identical"] == 2  # 1e-12 is the same to the digit (rtol 1e-9)
    e = d["fields"]["err"]
    assert (e["moved"], e["max_row"]) == (2, 2)
    assert math.isclose(e["max_abs"], 0.5) and e["largest"][0] == (2, 0.5)
    text = report("t", d, "a", "b")
    assert "| err | 2 | 4 |" in text and "median 1 -> 1.1" in text


def test_rows_present_on_one_side_only_and_text_keys():
    old = _table([{"name": "a", "x": 1.0}, {"name": "b", "x": 2.0}])
    new = _table([{"name": "b", "x": 2.0}, {"name": "c", "x": 3.0}])
    assert row_key(old["rows"]) == ("name",)
    d = compare(old, new)
    assert (d["matched"], d["only_old"], d["only_new"]) == (1, ["a"], ["c"])


def test_nan_equals_nan_and_nan_against_a_number_moves():
    old = _table([{"seed": 0, "e": float("nan")}, {"seed": 1, "e": float("nan")}])
    new = _table([{"seed": 0, "e": float("nan")}, {"seed": 1, "e": 1.0}])
    d = compare(old, new)
    assert d["identical"] == 1 and d["fields"]["e"]["max_row"] == 1


def test_main_on_a_committed_table_against_itself(capsys):
    assert main(["family_boot"]) == 0  # the work tree's table at HEAD: the same unless a rerun wrote it
    assert "matched by `seed`" in capsys.readouterr().out
    assert main(["no_such_table"]) == 2


def test_rows_named_by_several_fields_and_outcomes_left_out_of_the_key():
    rows = [{"mode": m, "fusion": f, "reason": "lost" if m == "mono" else "", "ate": 1.0}
            for m in ("mono", "rgbd") for f in ("yes", "no")]
    assert row_key(rows) == ("mode", "fusion")
    moved = [dict(r, ate=2.0) if (r["mode"], r["fusion"]) == ("rgbd", "no") else r for r in rows]
    d = compare(_table(rows), _table(moved))
    assert (d["matched"], d["identical"], d["fields"]["ate"]["max_row"]) == (4, 3, ("rgbd", "no"))
    assert row_key([{"seed": 1, "x": 1.0}, {"seed": 1, "x": 2.0}]) == ()  # no key: rows matched in order
