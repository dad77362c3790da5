"""The live start-up benchmark's summary (benchmarks/graph_startup.py): per launch, the runs with every frame through
and the frames lost in the first second and after it."""

from benchmarks.graph_startup import lost, summary


def test_the_summary_counts_per_launch_the_runs_through_and_the_frames_lost():
    rows = [dict(launch="one process", lost=0, lost_startup=0, latency_p95=20.0),
            dict(launch="one process", lost=3, lost_startup=2, latency_p95=30.0),
            dict(launch="process per node", lost=1, lost_startup=1, latency_p95=25.0)]
    rows = [r | lost(r) for r in rows]
    assert [r["lost_after"] for r in rows] == [0, 1, 0]
    one, per = summary(rows)
    assert one == dict(launch="one process", runs=2, all_through=1, startup_median=1.0, startup_most=2, after=1,
                       p95=25.0)
    assert per["runs"] == 1 and per["all_through"] == 0 and per["startup_most"] == 1 and per["after"] == 0
