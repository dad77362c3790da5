"""benchmarks/family_boot.py's bookkeeping: the knobs it parses and the summary over scenes (a scene with no scored
frame counts as failed, not as missing)."""

import math

from benchmarks.family_boot import _knobs, summary


def _row(median, alpha=1.0, reg=0.5):
    return {"median_err_pct": median, "alpha_z_err_deg": alpha, "registration_mm": reg,
            "registration_tilt_deg": 0.1, "model_bias_pct": 0.5, "vs_model_median_pct": 1.0}


def test_knobs_read_json_values_and_keep_text():
    assert _knobs(["freeze_map_on_deformation=true", "huber_px=3", "measurements=dense"]) == {
        "freeze_map_on_deformation": True, "huber_px": 3, "measurements": "dense"}


def test_summary_counts_a_scene_without_scored_frames_as_failed():
    s = summary([_row(0.5), _row(1.5), _row(float("nan"), alpha=float("nan"), reg=float("nan")), _row(0.8)])
    assert s["scenes"] == 4 and s["within_1pct"] == 50.0 and s["within_2pct"] == 75.0
    assert s["median_of_medians_pct"] == 1.15 and math.isinf(s["p90_of_medians_pct"])
    assert s["median_alpha_z_err_deg"] == 1.0 and s["median_registration_mm"] == 0.5
