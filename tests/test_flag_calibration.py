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
