"""What the graph benchmark's harness costs (issue 18): the replay's recorder writing the graph's image outputs (the
camera image the ingest publishes, the overlay's output) to the record, against receiving and counting them only
(``benchmarks.graph.run_case``'s ``record_images``, which ``./run bench graph`` turns off since stop 97). Since stop
98 the counting arm also leaves the camera images the ingest passes on unsubscribed
(``simreal_nodes.ros.commands.recorded_topics``): the table's last run (stop 97) measured counting them.

    ./run bench graph_harness

The demo at 640 x 480 and 1280 x 720, lossless and lock-step, all nodes in one process (the graph benchmark's
fastest lock-step launch), each case in pairs, the two arms back to back and their order alternating (ABBA), so a
drift of the host's speed falls on both. The player and the recorder share one process and one executor: a frame
whose images are being written waits for the write before the player sees it finished, and the write takes CPU
from the nodes on a 2-core machine. Writes benchmarks/results/graph_harness.{json,md,png}.
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import save
from benchmarks.graph import PLAYER, run_case
from simreal_nodes.demo import sample_bag

CASES = (("aluminium_beam", "640x480", None), ("aluminium_beam", "1280x720", 4.0))
PAIRS = 2


def main() -> None:
    runs = []
    for scene, res, duration in CASES:
        bag, scene_yaml = sample_bag(scene, duration=duration, resolution=res, echo=lambda *a: None)
        for k in range(PAIRS):
            arms = (True, False) if k % 2 == 0 else (False, True)
            for written in arms:
                r = run_case(scene, res, bag, scene_yaml, True, True, record_images=written)
                runs.append(dict(scene=scene, resolution=res, images_written=written, fps=r["fps"],
                                 latency_p50=r["latency_p50"], nodes_cpu_ms=r["nodes_cpu_ms"],
                                 player_cpu_ms=r.get(f"cpu_{PLAYER.split(' ')[0]}_ms", float("nan"))))
                print(runs[-1], flush=True)
    rows = []
    for scene, res, _ in CASES:
        for written in (True, False):
            mine = [r for r in runs if (r["scene"], r["resolution"], r["images_written"]) == (scene, res, written)]
            rows.append(dict(scene=scene, resolution=res, images="written" if written else "counted only",
                             runs=len(mine), **{k: float(np.median([r[k] for r in mine]))
                                                for k in ("fps", "latency_p50", "nodes_cpu_ms", "player_cpu_ms")},
                             fps_range=f"{min(r['fps'] for r in mine):.1f}-{max(r['fps'] for r in mine):.1f}"))

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
        labels = [f"{r['resolution']}\n{r['images']}" for r in rows]
        ax[0].bar(range(len(rows)), [r["fps"] for r in rows], color=["tab:red", "tab:green"] * len(CASES))
        ax[0].set_ylabel("fps through (lossless, lock-step)")
        ax[1].bar(range(len(rows)), [r["player_cpu_ms"] for r in rows], color=["tab:red", "tab:green"] * len(CASES))
        ax[1].set_ylabel("player + recorder CPU per frame (ms)")
        for a in ax:
            a.set_xticks(range(len(rows)))
            a.set_xticklabels(labels, fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("scene", "scene", "{}"), ("resolution", "resolution", "{}"), ("images", "graph's images", "{}"),
            ("runs", "runs", "{}"), ("fps", "fps through (median)", "{:.1f}"), ("fps_range", "range", "{}"),
            ("latency_p50", "latency p50 (ms)", "{:.0f}"), ("nodes_cpu_ms", "nodes' CPU/frame (ms)", "{:.1f}"),
            ("player_cpu_ms", "player + recorder CPU/frame (ms)", "{:.1f}")]
    save("graph_harness", rows, cols, "The graph benchmark's harness: the graph's images written to the record or "
         "counted only (demo, lossless lock-step, one process)",
         "Medians over the pairs (ABBA). Written: every output topic recorded as `simreal replay --record` does; "
         "counted only: the image topics (camera image and depth from the ingest, the overlay's image) received "
         "raw and counted, the rest written, as `./run bench graph` runs since stop 97. The nodes' work is the "
         "same in both arms; what differs is the harness's CPU on the shared 2 cores and its delay in seeing a "
         "frame finished.", plot, extra={"runs": runs})


if __name__ == "__main__":
    main()
