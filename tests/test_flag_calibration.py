"""The flag calibration's per-scene counts (benchmarks/flag_calibration.py): which frames each threshold would flag,
and whether they are the frames more than 2 % of the span off."""

import numpy as np

from benchmarks.flag_calibration import quantity_row
from simreal_nodes.states import EstimateState


def test_counts_split_caught_bad_frames_from_flagged_good_ones():
    ok, low = int(EstimateState.OK), int(EstimateState.LOW_CONFIDENCE)
    errs = [0.1, 0.2, 5.0, 9.0, 0.3]
    row = quantity_row("gain", 3, "as drawn", [0.9, 0.4, 0.2, np.nan, 0.8], errs, [ok, ok, low, low, ok])
    assert row["frames"] == 5 and row["ok_frames"] == 3 and row["frames_over_2pct"] == 2
    # gain < 0.5: the bad frame at 0.2 and the NaN one (a fit with no gain is flagged) caught, one good frame flagged
    assert row["caught_0.5"] == 2 and row["good_0.5"] == 1
    assert row["caught_0.3"] == 2 and row["good_0.3"] == 0
    assert row["gain_min"] == 0.2 and row["values"][3] is None  # statistics over the finite values; NaN kept as None


def test_a_margin_that_is_not_finite_is_not_flagged():
    """No candidate from another basin in view: nothing to compare, so no margin flag would fire."""
    row = quantity_row("margin", 3, "as drawn", [np.nan, 0.004, 0.3], [5.0, 5.0, 0.1], [0, 0, 0])
    assert row["caught_0.005"] == 1 and row["good_0.005"] == 0
    assert row["caught_0.05"] == 1 and row["good_0.05"] == 0


def test_the_ambiguity_counts_only_other_fits_that_ended_apart(tmp_path, monkeypatch):
    """``--ambiguity`` from a family run's curves: a second fit that fell back into the kept basin is no tie however
    close its cost (NaN, never flagged); one that ended apart gives its gap; frames before the load are counted
    apart, in the table's notes."""
    import json

    import benchmarks.flag_calibration as fc
    from simreal_nodes.synth.family import draw

    span = draw(3).spans[0]
    c = {"truth": [None, None, 0.5 * span, 0.5 * span, 0.5 * span], "est": [0.1, 0.1, 0.5 * span, 0.5 * span, 0.5],
         "state": [1, 1, 0, 0, 0], "gain": [0.9] * 5, "basin": [0.002, 0.5, 0.004, 0.004, None],
         "other": [0.9 * span, 0.9 * span, 0.5 * span + 0.01 * span, 0.9 * span, None]}
    doc = {"rows": [{"seed": 3, "object": "beam"}], "curves": {"3": c}}
    (tmp_path / "runs.json").write_text(json.dumps(doc))
    monkeypatch.setattr(fc, "RESULTS", tmp_path)
    [(seed, _, fr)] = fc.frames_from_runs("runs", ("ambiguity",))
    assert seed == 3 and len(fr["ambiguity"]) == 3  # the loaded frames only
    assert np.isnan(fr["ambiguity"][0]) and fr["ambiguity"][1] == 0.004 and np.isnan(fr["ambiguity"][2])
    note = fc.unloaded_ties(["runs"])
    assert "2 frames had a second fit that ended apart: 1 read under 0.01" in note, note


def test_the_std_is_the_largest_parameters_and_flags_above_the_level(tmp_path, monkeypatch):
    """``--std`` from a family run's curves: per loaded frame with a dense fit, the larger of a plate's two standard
    deviations (None where the fit gave none); a frame is flagged when it is over the level, not under it."""
    import json

    import benchmarks.flag_calibration as fc
    from simreal_nodes.synth.family import draw_plate

    sx, sy = draw_plate(3).spans
    c = {"truth": [None, 0.5 * sx, 0.5 * sx, 0.5 * sx], "est": [0.1, 0.5 * sx, 0.5 * sx, 0.5 * sx],
         "truth_y": [None, 0.5 * sy, 0.5 * sy, 0.5 * sy], "est_y": [0.1, 0.5 * sy, 0.55 * sy, 0.5 * sy],
         "state": [1, 0, 0, 0], "gain": [0.9] * 4,
         "std_pct": [[9.0, 9.0], [0.2, 0.4], [0.3, 2.5], [None, None]]}
    doc = {"rows": [{"seed": 3, "object": "plate"}], "curves": {"3": c}}
    (tmp_path / "runs.json").write_text(json.dumps(doc))
    monkeypatch.setattr(fc, "RESULTS", tmp_path)
    [(_, _, fr)] = fc.frames_from_runs("runs", ("std",))
    assert fr["std"][:2] == [0.4, 2.5] and np.isnan(fr["std"][2])  # the loaded frames, each's largest
    assert fr["errs"][1] > 2.0 >= fr["errs"][0]  # s_y 5 % of its range off on the second
    row = quantity_row("std", 3, "", fr["std"], fr["errs"], fr["states"])
    assert row["caught_1"] == 1 and row["good_1"] == 0 and row["caught_3"] == 0


def test_the_std_note_counts_what_a_lower_level_would_flag_among_the_frames_the_flag_passed():
    """Runs made with the loose-hold flag on: its OK frames are those it passed, so a lower level flags exactly the
    OK frames over it; the note counts them per group (a plate's group from its support). A run whose OK frames go
    over the level predates the flag and says so instead."""
    import benchmarks.flag_calibration as fc
    from simreal_nodes.synth.family import draw_plate

    assert draw_plate(3).support == "clamped_ends"
    fr = {"std": [0.4, 0.8, 0.6, 2.0], "errs": [0.5, 3.0, 1.0, 4.0], "states": [0, 0, 0, 1]}
    note = fc.std_note([(3, "runs (plate)", fr)])
    assert ("plates bolted at both ends: of 1 OK frames more than 2 % off and 2 within, 0.5 % would flag 1 and 1, "
            "0.7 % would flag 1 and 0") in note
    old = {**fr, "states": [0, 0, 0, 0]}  # an OK frame at 2 %: no flag was on
    assert "predate the flag" in fc.std_note([(3, "runs (plate)", old)])
