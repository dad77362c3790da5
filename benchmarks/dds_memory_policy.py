"""What the readers' DYNAMIC history memory costs the graph (issue 20's memory, issue 18's throughput).

    ./run bench dds_memory_policy        # about 6 minutes

`dds_pool_memory` shows a subscription keeping (depth + 1) buffers as large as the largest message it has seen under
rmw_fastrtps's own history memory policy (PREALLOCATED_WITH_REALLOC), and none under DYNAMIC; `fuzz_graph
--memory-detail` shows the same in the nodes. DYNAMIC allocates each sample's buffer when it arrives and frees it
once taken: this measures what that costs where it matters, the graph's lossless throughput and its nodes' CPU per
frame, on the demo (aluminium_beam, 640 x 480) and the RGB-D SLAM scene (foam_beam, 640 x 480), one process per node.
Each policy runs ``--repeats`` times, alternating, the same bag each time (``benchmarks/graph.py``'s ``run_case``).
The policy is chosen by ``RMW_FASTRTPS_USE_QOS_FROM_XML`` in the environment every process of the replay inherits:
0, rmw_fastrtps's own; 1, the project profile's (``simreal_nodes/ros/fastdds_shm.xml``: DYNAMIC readers).
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from benchmarks.common import save
from benchmarks.graph import run_case
from simreal_nodes.demo import sample_bag

SCENES = (("aluminium_beam", "640x480"), ("foam_beam", "640x480"))
POLICIES = {"rmw default (PREALLOCATED_WITH_REALLOC)": "0", "DYNAMIC (the profile's)": "1"}
VAR = "RMW_FASTRTPS_USE_QOS_FROM_XML"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    runs = []
    before = os.environ.get(VAR)
    try:
        for scene, res in SCENES:
            bag, scene_yaml = sample_bag(scene, resolution=res, echo=lambda *x: None)
            for rep in range(a.repeats):
                for policy, value in POLICIES.items():
                    os.environ[VAR] = value
                    r = run_case(scene, res, bag, scene_yaml, lossless=True, one_process=False)
                    runs.append({"scene": scene, "resolution": res, "policy": policy, "repeat": rep,
                                 "fps": r["fps"], "nodes_cpu_ms": r["nodes_cpu_ms"],
                                 "latency_p50": r["latency_p50"], "delivered_pct": r["delivered_pct"]})
                    print(runs[-1], flush=True)
    finally:
        if before is None:
            os.environ.pop(VAR, None)
        else:
            os.environ[VAR] = before
    rows = []
    for scene, res in SCENES:
        for policy in POLICIES:
            sel = [r for r in runs if r["scene"] == scene and r["policy"] == policy]
            fps, cpu = np.array([r["fps"] for r in sel]), np.array([r["nodes_cpu_ms"] for r in sel])
            rows.append({"scene": scene, "resolution": res, "policy": policy, "runs": len(sel),
                         "fps_median": float(np.median(fps)), "fps_range": f"{fps.min():.1f}-{fps.max():.1f}",
                         "cpu_median": float(np.median(cpu)), "cpu_range": f"{cpu.min():.1f}-{cpu.max():.1f}",
                         "latency_p50": float(np.median([r["latency_p50"] for r in sel])),
                         "delivered_pct": float(min(r["delivered_pct"] for r in sel))})
    cols = [("scene", "scene", "{}"), ("resolution", "resolution", "{}"), ("policy", "readers' history memory", "{}"),
            ("runs", "runs", "{}"), ("fps_median", "fps through, median", "{:.1f}"), ("fps_range", "range", "{}"),
            ("cpu_median", "nodes' CPU/frame (ms), median", "{:.1f}"), ("cpu_range", "range", "{}"),
            ("latency_p50", "latency p50 (ms), median of runs", "{:.0f}"),
            ("delivered_pct", "frames through (%), least", "{:.0f}")]

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.4))
        for k, policy in enumerate(POLICIES):
            for i, (scene, _) in enumerate(SCENES):
                sel = [r for r in runs if r["scene"] == scene and r["policy"] == policy]
                for a, key in zip(ax, ("fps", "nodes_cpu_ms"), strict=True):
                    a.plot([i + 0.2 * k - 0.1] * len(sel), [r[key] for r in sel], "o^"[k], color=f"C{k}",
                           label=policy if i == 0 else None)
        for a, lab in zip(ax, ("fps through the graph (lossless)", "nodes' CPU per frame (ms)"), strict=True):
            a.set_xticks(range(len(SCENES)))
            a.set_xticklabels([s for s, _ in SCENES])
            a.set_ylabel(lab)
        ax[0].legend(fontsize=7)
        fig.tight_layout()
        return fig

    save("dds_memory_policy", rows, cols, "The readers' history memory policy: the graph's throughput and CPU",
         f"`python -m benchmarks.dds_memory_policy` (module docstring): lossless replays of each scene's sample bag, "
         f"one process per node, {a.repeats} runs of each policy, alternating. The memory side is in "
         "`dds_pool_memory.md` and `fuzz_graph_rgbd_20k_memory*.md`.", plot, extra={"runs": runs})


if __name__ == "__main__":
    main()
