"""Live start-up (issue 18): the frames a live replay of the demo loses, and when. Each replay plays the demo's sample
bag (``aluminium_beam``, 640 x 480, 180 frames at 30 fps) through the graph with live QoS (a busy node takes the
newest frame); a frame lost in the first second is the start-up's (the nodes build what the first CameraInfo asks for
while its frame waits, and the frames meanwhile are replaced in the one-deep queues), one lost later the steady
state's. ``graph.md`` has one such replay per launch among its cases; here each launch replays RUNS times, the
launches alternating, so that one replay's luck (the host's load at the start) is seen as such.

    ./run bench graph_startup
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import markdown_table, save
from benchmarks.graph import run_case
from simreal_nodes.demo import sample_bag

SCENE, RES = "aluminium_beam", "640x480"
RUNS = 5
LAUNCHES = ((True, "one process"), (False, "process per node"))  # (one_process, name); one process: the CLI's pick


def lost(row: dict) -> dict:
    """Frames lost after the first second, from a row of :func:`benchmarks.graph.run_case` (its ``lost`` in all and
    ``lost_startup`` in the first second)."""
    return dict(lost_after=row["lost"] - row["lost_startup"])


def summary(rows: list[dict]) -> list[dict]:
    """Per launch: runs, runs with every frame through, frames lost at start-up (median, most) and after it (all
    runs), latency p95 (median of the runs)."""
    out = []
    for _, name in LAUNCHES:
        rs = [r for r in rows if r["launch"] == name]
        if not rs:
            continue
        out.append(dict(launch=name, runs=len(rs), all_through=sum(r["lost"] == 0 for r in rs),
                        startup_median=float(np.median([r["lost_startup"] for r in rs])),
                        startup_most=max(r["lost_startup"] for r in rs), after=sum(r["lost_after"] for r in rs),
                        p95=float(np.median([r["latency_p95"] for r in rs]))))
    return out


def main():
    bag, scene_yaml = sample_bag(SCENE, resolution=RES, echo=lambda *a: None)
    rows = []
    for k in range(RUNS):
        for one_process, _ in (LAUNCHES if k % 2 == 0 else LAUNCHES[::-1]):
            r = run_case(SCENE, RES, bag, scene_yaml, False, one_process, record_images=False)
            r = {key: v for key, v in r.items() if key != "budget"} | dict(run=k) | lost(r)
            rows.append(r)
            print({key: r[key] for key in ("run", "launch", "delivered_pct", "lost_startup", "lost_after")},
                  flush=True)
    report(rows)


def report(rows: list[dict]) -> None:
    def plot(plt):
        fig, ax = plt.subplots(figsize=(6, 3.2))
        for k, (_, name) in enumerate(LAUNCHES):
            rs = [r for r in rows if r["launch"] == name]
            ax.bar([r["run"] + 0.4 * k - 0.2 for r in rs], [r["lost_startup"] for r in rs], width=0.4, label=name)
        ax.set_xlabel("run")
        ax.set_ylabel("frames lost in the first second")
        ax.legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("run", "run", "{}"), ("launch", "launch", "{}"), ("frames", "frames", "{}"),
            ("delivered_pct", "frames through (%)", "{:.1f}"), ("lost_startup", "lost in the first second", "{}"),
            ("lost_after", "lost after it", "{}"), ("latency_p50", "latency p50 (ms)", "{:.0f}"),
            ("latency_p95", "p95 (ms)", "{:.0f}"), ("nodes_cpu_ms", "nodes' CPU/frame (ms)", "{:.1f}")]
    table = markdown_table(summary(rows), [
        ("launch", "launch", "{}"), ("runs", "runs", "{}"), ("all_through", "runs with every frame through", "{}"),
        ("startup_median", "lost in the first second, median", "{:.0f}"), ("startup_most", "most", "{}"),
        ("after", "lost after the first second, all runs", "{}"), ("p95", "latency p95, median (ms)", "{:.0f}")])
    save("graph_startup", rows, cols, "Live start-up: the demo's frames lost in the first second, runs alternating",
         f"The demo (ingest -> markers -> tracker -> overlay) at {RES}, its sample bag's 180 frames at 30 fps, live "
         f"QoS, {RUNS} replays per launch, the launches alternating; one process is the CLI's pick for this graph "
         "live. Lost: frames that did not go through every node; in the first second (of the bag's stamps): the "
         "start-up's (the overlay's renderer, the localizer, the tracker built on the first CameraInfo while its "
         "frame waits; since stop 99 the overlay and the localizer warm up before the nodes spin, the overlay's "
         "distortion and occlusion maps take milliseconds, the player's clock starts with the bag's first "
         "message, and the first frame waits for the graph to go quiet: the standbys' discovery). Per launch:\n\n"
         + table, plot=plot)


if __name__ == "__main__":
    main()
