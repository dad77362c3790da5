"""benchmarks/orb_budget.py: the stage split and the features' comparison (the timed runs themselves are the
benchmark's, not a test's)."""

import json

import cv2
import numpy as np
import pytest

from benchmarks import orb_budget


def _frame(total, stages, digest, n=1000, opencv=5.0):
    return {"total": total, "opencv": opencv, **dict(zip(orb_budget.STAGES, stages)), "n": n, "digest": digest}


def test_the_stages_split_the_extraction_and_changed_features_are_counted():
    ref = {"frames": [_frame(10.0, (0.5, 5, 1, 1, 2), "a"), _frame(12.0, (0.5, 6, 1, 1, 2), "b")]}
    other = {"frames": [_frame(11.0, (0.5, 5, 2, 1, 2), "a"), _frame(13.0, (0.5, 6, 2, 1, 2), "c", n=990)]}
    s = orb_budget.summary(other, ref)
    assert s["extract_ms_p50"] == pytest.approx(12.0)
    assert s["selection_ms_p50"] == pytest.approx(2.0)
    assert s["rest_ms_p50"] == pytest.approx(np.median([11 - 10.5, 13 - 11.5]))
    assert s["features"] == pytest.approx(995.0)
    assert s["frames_differ"] == 1
    assert orb_budget.summary({"frames": ref["frames"][:1]}, ref)["frames_differ"] == 1  # a frame missing
    assert "frames_differ" not in orb_budget.summary(ref, None)


def test_a_run_times_every_stage_and_digests_the_same_features_alike(tmp_path, monkeypatch):
    from simreal_nodes.vision import orb

    # the worker times the module's functions by rebinding them: this test's teardown puts the originals back
    monkeypatch.setattr(orb, "_grid_select", orb._grid_select)
    monkeypatch.setattr(orb, "ic_angle", orb.ic_angle)
    monkeypatch.setattr(orb_budget, "CACHE", tmp_path)
    rng = np.random.default_rng(0)
    dots = (rng.random((5, 480, 640)) < 0.02).astype(np.float32)
    gray = np.stack([np.clip(128 + 400 * cv2.GaussianBlur(d, (0, 0), 1.5), 0, 255) for d in dots]).astype(np.uint8)
    np.savez_compressed(tmp_path / "family_7.npz", gray=gray)
    runs = []
    for k in range(2):
        orb_budget.worker(7, tmp_path / f"run{k}.json")
        runs.append(json.loads((tmp_path / f"run{k}.json").read_text()))
    assert len(runs[0]["frames"]) == 5
    for f in runs[0]["frames"]:
        assert 500 < f["n"] <= orb_budget.N_FEATURES and f["total"] > 0 and f["opencv"] > 0
        assert all(f[k] > 0 for k in orb_budget.STAGES)
        assert sum(f[k] for k in orb_budget.STAGES) <= f["total"]
    assert len({f["digest"] for f in runs[0]["frames"]}) == 5  # each frame's features told apart
    assert orb_budget.summary(runs[1], runs[0])["frames_differ"] == 0
