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
