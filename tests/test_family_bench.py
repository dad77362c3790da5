"""benchmarks/family.py's scene runner: each scene starts OpenCV's random generator at its seed, so that its RANSAC
draws do not depend on which scenes the same worker ran before it; and the most common reason, picked the same way in
every process."""

import numpy as np

from benchmarks.family import _seeded


def _draws(seed: int) -> np.ndarray:
    import cv2

    out = np.zeros(8, np.float64)
    cv2.randu(out, 0.0, 1.0)  # OpenCV's global generator, the one solvePnPRansac draws from
    return out


def test_a_scene_draws_the_same_whatever_ran_before_it_in_its_worker():
    first = _seeded(_draws, 7)
    _seeded(_draws, 3)
    _draws(0)  # a scene that left the generator elsewhere
    assert np.array_equal(_seeded(_draws, 7), first)
    assert not np.array_equal(_seeded(_draws, 8), first)


def test_the_most_common_reason_breaks_ties_by_first_seen_not_by_hash():
    from benchmarks.common import most_common

    assert most_common(["waiting (2 of 3)", "waiting (1 of 3)", "waiting (1 of 3)", "waiting (2 of 3)"]) == \
        "waiting (2 of 3)"
    assert most_common(["lost", "lost", "flagged"]) == "lost"


def test_the_loaded_registration_table_names_the_fits_placed_far_off_and_those_with_no_doubt(tmp_path, monkeypatch):
    """``--registration --preloaded``: a fit a centimetre or more off is named, and named again as silent where it
    raised no doubt (a tracker started there reads the load from a misplaced model); a refused scene counts as
    refused, not as far off; the state's error is summarised over the fits that have one, and a placed fit that read
    no state (its rest shape stood, though every scene is loaded) is counted and shown blank."""
    import json

    import benchmarks.common as common
    from benchmarks.family import write_registration_loaded

    monkeypatch.setattr(common, "RESULTS", tmp_path)

    def row(seed, mm, doubt="", state=0.5, node_mm=None):
        return {"seed": seed, "support": "cantilever", "length_mm": 500, "height_mm": 10.0, "distance_m": 0.6,
                "guess_mm": 50.0, "guess_deg": 10.0, "registration_mm": mm,
                "registration_max_mm": mm if node_mm is None else node_mm,
                "registration_deg": 0.1, "registration_fitness": 0.9, "frame": 8, "seconds": 1.0, "reason": "",
                "state_err_pct": state, "slide_spread_mm": 10.0, "registration_doubt": doubt}

    rows = [row(1, 1.0), row(2, 57.0), row(3, 12.0, doubt="the fit can slide"),
            row(4, float("nan"), state=float("nan")), row(5, 2.0, state=1.5), row(6, 1.0, state=float("nan")),
            row(7, 2.2, node_mm=72.0)]  # the origin in place, the far end turned off (development seed 40)
    write_registration_loaded(rows, "development seeds 1-7", "reg_loaded")
    doc = json.loads((tmp_path / "reg_loaded.json").read_text())
    assert doc["summary"]["far"] == [2, 3, 7] and doc["summary"]["silent"] == [2, 7]
    assert doc["summary"]["refused"] == 1
    assert doc["summary"]["median_state_err_pct"] == 0.5 and doc["summary"]["at_rest"] == [6]
    md = (tmp_path / "reg_loaded.md").read_text()
    assert "with no doubt raised: 2 (2, 7)" in md
    assert "placed at rest (the rest shape stood, no state read, blank): 1 (6)" in md
    assert "nan" not in md.split("\n| 6 |")[1].split("\n")[0]  # the missing state a blank cell
    assert [r["state_err_pct"] for r in doc["rows"]][5] is None
