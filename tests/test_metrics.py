"""Per-node counters published on /diagnostics: processing time, drops versus skips, time since the last
finished frame (what a live node uses to say that it only skips)."""

import pytest

from simreal_nodes.metrics import STAGES, StageMetrics


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_skips_are_counted_apart_from_drops_and_stalls_are_measured():
    c = Clock()
    m = StageMetrics(clock=c)
    c.t += 5.0
    assert m.seconds_since_done() == 5.0  # nothing finished since the start
    t0 = m.arrived()
    c.t += 0.02
    assert abs(m.done(t0) - 20.0) < 1e-9
    assert m.seconds_since_done() == 0.0
    m.skip("a newer frame was ready")
    m.drop("malformed image")
    c.t += 4.0
    d = m.as_dict()
    assert (d["processed"], d["skipped"], d["dropped"]) == ("1", "1", "1")
    assert d["last_skip_reason"] == "a newer frame was ready" and d["last_drop_reason"] == "malformed image"
    assert m.seconds_since_done() == 4.0


def test_a_replayed_recordings_stamps_give_no_age():
    """'now minus stamp' of a bag recorded long ago is the recording's age (issue 18 measured 95 billion ms in
    /diagnostics): such frames are counted off the clock and the age reads n/a; live stamps give the latency."""
    c = Clock()
    m = StageMetrics(clock=c)
    m.done(m.arrived(), age_ms=9.5e10)
    assert m.as_dict()["age_ms_p50"].startswith("n/a") and m.off_clock == 1
    m.done(m.arrived(), age_ms=12.0)
    m.done(m.arrived(), age_ms=14.0)
    assert m.as_dict()["age_ms_p50"] == "13.00"


def test_a_frames_processing_is_split_into_the_stages_it_marks():
    """decode + work + encode is the processing time of a frame whose node marks all three; a stage not marked
    is not reported."""
    c = Clock()
    m = StageMetrics(clock=c)
    for decode, work, encode in ((0.002, 0.010, 0.003), (0.004, 0.020, 0.001), (0.003, 0.015, 0.002)):
        t0 = m.arrived()
        c.t += decode
        m.lap("decode")
        c.t += work
        m.lap("work")
        c.t += encode
        m.lap("encode")
        m.done(t0)
    d = m.as_dict()
    assert float(d["decode_ms_p50"]) == pytest.approx(3.0)
    assert float(d["work_ms_p50"]) == pytest.approx(15.0)
    assert float(d["encode_ms_p50"]) == pytest.approx(2.0)
    assert float(d["processing_ms_p50"]) == pytest.approx(20.0)
    m2 = StageMetrics(clock=c)
    m2.done(m2.arrived())
    assert not any(f"{k}_ms_p50" in m2.as_dict() for k in STAGES)
