"""benchmarks/soak.py: the latency's summary per cycle of the sample (the 10 000-frame run itself is the
benchmark's)."""

import numpy as np
import pytest

from benchmarks.soak import SETTLE_CYCLES, cycle_trend, summarize


def test_a_creeping_latency_shows_as_a_trend_a_wandering_one_as_a_range():
    rng = np.random.default_rng(0)
    cycle, n = 100, 20
    creep = np.concatenate([np.full(cycle, 40.0 + 2.0 * k) + rng.normal(0, 1, cycle) for k in range(n)])
    t = cycle_trend(creep, cycle)
    assert t["cycles"] == n
    # 2 ms more per cycle of 100 frames: 20 ms per 1000 frames, the first SETTLE_CYCLES cycles left out
    assert t["trend"] == pytest.approx(20.0, abs=1.0)
    assert t["trend_se"] < 1.0
    assert t["cycle_lo"] == pytest.approx(40.0 + 2.0 * SETTLE_CYCLES, abs=1.0)
    levels = np.where(np.arange(n) % 2 == 0, 50.0, 150.0)  # two levels, as a queue that fills and drains
    wander = np.concatenate([np.full(cycle, v) + rng.normal(0, 1, cycle) for v in levels])
    w = cycle_trend(wander, cycle)
    assert abs(w["trend"]) < 3 * w["trend_se"]
    assert (w["cycle_lo"], w["cycle_hi"]) == (pytest.approx(50.0, abs=1.0), pytest.approx(150.0, abs=1.0))


def test_too_few_cycles_give_no_trend_and_a_summary_row_carries_it():
    short = cycle_trend(np.full(250, 30.0), 100)
    assert short["cycles"] == 2 and np.isnan(short["trend"]) and np.isnan(short["cycle_lo"])
    lat = list(np.repeat(np.arange(10, dtype=float), 50))
    run = {"frames": 500, "cycle": 50, "rss": [(k, "tracker", 100.0 + 0.001 * k) for k in range(0, 500, 20)],
           "latency_ms": {"tracker": lat}}
    (row,) = summarize(run)
    assert row["node"] == "tracker" and row["finished"] == 500
    assert row["trend"] == pytest.approx(20.0)  # one ms per cycle of 50 frames
    assert row["slope"] == pytest.approx(1.0)  # MB per 1000 frames


def test_cpu_per_frame_from_the_cumulative_samples():
    from benchmarks.soak import cpu_drift, cpu_per_frame

    # 20 ms per frame up to frame 3000, then 30 ms per frame: cumulative seconds sampled every 100 frames
    ks = np.arange(0, 6001, 100)
    secs = np.where(ks <= 3000, 0.020 * ks, 0.020 * 3000 + 0.030 * (ks - 3000))
    cpu = [(float(k), "localization", float(c)) for k, c in zip(ks, secs, strict=True)]
    d = cpu_drift(cpu, "localization", 6000, cycle=500)
    assert d["cpu_early"] == pytest.approx(20.0) and d["cpu_late"] == pytest.approx(30.0)
    w = cpu_per_frame(cpu, "localization", 1000.0)
    assert w[0, 1] == pytest.approx(20.0) and w[-1, 1] == pytest.approx(30.0)
    assert np.isnan(cpu_drift([], "localization", 6000, cycle=500)["cpu_late"])  # a run that sampled no CPU
