"""The CLI's launch mode (issue 18), checked on scenes it was not chosen on: all nodes in one process, a process per
node and split (the SLAM in a process of its own, the other nodes in one), live (the bag's rate, live QoS) and
lossless (lock-step and with frames in flight), on RGB-D SLAM scenes that ``benchmarks/graph.py`` does not run.

    ./run bench launch_mode            # about 25 min (36 replays)
    .venv/bin/python -m benchmarks.launch_mode --report  # table and plot from the JSON's runs, the pick from the code

The rule (``simreal_nodes.scene.graph.default_launch``) was set on ``benchmarks/results/graph.md``'s cases, one
run each (stop 95): one process is faster or level in every lossless case and live for the markers demo, while live
the RGB-D SLAM scenes put more frames through with a process per node (the foam beam 60 % against 37 %, family-3 49
% against 34 %): their SLAM (34-39 ms a frame) or dense tracker (120 ms) holds one executor for longer than a camera
frame period, and in their own processes they run beside the others on the second core; with frames in flight
lossless, a process per node (stop 97; stop 98 tried split where a node is slow, ahead on graph.md's foam beam,
30.1 fps against 26.5, and family-3, 8.9 against 8.5, and kept it a choice on this benchmark's rows). Held out here:
the sample ``joint_boot`` (RGB-D SLAM, map points, the boot's neo-Hookean model; rendered by that model) and
``joint_boot_truth_live`` (the same graph, the boot placed by registration from a guess by eye, its images from an
independent full-order solve), each case twice with the order alternating (one process, per node, split, split, per
node, one process). Reported: frames through (% and per second), latency p50 / p95 to the overlay, the nodes' CPU
per frame, and what the rule picks against the launch that put more frames through (live) or went faster (lossless).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from benchmarks.common import RESULTS, save, saved_machine
from benchmarks.graph import IN_FLIGHT, run_case
from simreal_nodes.demo import sample_bag
from simreal_nodes.scene.graph import SPLIT

SCENES = ("joint_boot", "joint_boot_truth_live")
ORDER = (True, False, SPLIT, SPLIT, False, True)  # the launch of the runs of each case (replay's one_process)
LAUNCHES = {True: "one process", False: "process per node", SPLIT: "split"}
# (replay label, lossless, frames in flight): live, lossless lock-step, lossless with graph.py's frames in flight
MODES = (("real time (30 fps)", False, 1), ("lossless", True, 1), (f"lossless, {IN_FLIGHT} in flight", True, IN_FLIGHT))


def rule_pick(scene_yaml, lossless: bool, in_flight: int = 1) -> str:
    from simreal_nodes.scene.graph import default_launch
    from simreal_nodes.scene.schema import load_scene

    return LAUNCHES[default_launch(load_scene(scene_yaml), lossless, in_flight)]


def main() -> None:
    ap = argparse.ArgumentParser(description="./run bench launch_mode")
    ap.add_argument("--report", action="store_true",
                    help="rewrite table and plot from the results JSON's runs (the CLI's pick read from the code now)")
    a = ap.parse_args()
    runs = json.loads((RESULTS / "launch_mode.json").read_text())["runs"] if a.report else measure()
    report(runs, saved_machine("launch_mode") if a.report else {})


def measure() -> list[dict]:
    runs = []
    for scene in SCENES:
        bag, scene_yaml = sample_bag(scene, echo=lambda *a: None)
        for _, lossless, in_flight in MODES:
            for rep, one in enumerate(ORDER):
                r = run_case(scene, "640x480", bag, scene_yaml, lossless, one, in_flight=in_flight,
                             record_images=False)
                r["run"] = rep
                r.pop("budget", None)
                runs.append(r)
                print({k: r[k] for k in ("scene", "mode", "launch", "fps", "delivered_pct", "latency_p95",
                                         "nodes_cpu_ms")}, flush=True)
    return runs


def report(runs: list[dict], machine: dict) -> None:
    rows = []
    for scene in SCENES:
        _, scene_yaml = sample_bag(scene, echo=lambda *a: None)
        for mode, lossless, in_flight in MODES:
            by = {}
            for launch in LAUNCHES.values():
                rs = [r for r in runs if r["scene"] == scene and r["mode"] == mode and r["launch"] == launch]
                by[launch] = {k: float(np.median([r[k] for r in rs])) for k in
                              ("fps", "delivered_pct", "latency_p50", "latency_p95", "nodes_cpu_ms")}
                by[launch]["runs_fps"] = ", ".join(f"{r['fps']:.1f}" for r in rs)
            key = "fps" if lossless else "delivered_pct"
            better = max(by, key=lambda k: by[k][key])
            pick = rule_pick(scene_yaml, lossless, in_flight)
            for launch, v in by.items():
                rows.append(dict(scene=scene, mode=mode, launch=launch, **v, rule=pick == launch,
                                 better=better == launch))
    cols = [("scene", "scene", "{}"), ("mode", "replay", "{}"), ("launch", "launch", "{}"),
            ("fps", "fps through (median)", "{:.1f}"), ("runs_fps", "runs", "{}"),
            ("delivered_pct", "frames through (%)", "{:.0f}"), ("latency_p50", "latency p50 (ms)", "{:.0f}"),
            ("latency_p95", "p95 (ms)", "{:.0f}"), ("nodes_cpu_ms", "nodes' CPU/frame (ms)", "{:.1f}"),
            ("rule", "the CLI's pick", "{}"), ("better", "more frames through (live) / faster (lossless)", "{}")]

    def plot(plt):
        fig, ax = plt.subplots(figsize=(8, 3.8))
        cases = list(dict.fromkeys((r["scene"], r["mode"]) for r in rows))
        for k, (launch, color) in enumerate(zip(LAUNCHES.values(), ("tab:orange", "tab:blue", "tab:green"))):
            by = {(r["scene"], r["mode"]): r for r in rows if r["launch"] == launch}
            ax.bar([i + 0.27 * k - 0.27 for i in range(len(cases))],
                   [by[c]["fps"] if c[1].startswith("lossless") else by[c]["delivered_pct"] for c in cases],
                   width=0.27, color=color, label=launch)
        ax.set_xticks(range(len(cases)))
        ax.set_xticklabels([f"{s}\n{m}" for s, m in cases], fontsize=7)
        ax.set_ylabel("live: frames through (%); lossless: fps")
        ax.legend(fontsize=7)
        fig.tight_layout()
        return fig

    notes = ("Each case twice, order one process, per node, split, split, per node, one process; medians (each "
             "run's rate in 'runs'; every run in `runs` of the JSON). Live: the bag at its 30 fps, live QoS; the "
             "launch that put more frames through is the better. Lossless: lock-step, or with up to "
             f"{IN_FLIGHT} frames in the graph at once (`simreal replay --lossless --in-flight {IN_FLIGHT}`); the "
             "faster is the better. The CLI's pick: `simreal_nodes.scene.graph.default_launch`, set on "
             "`benchmarks/results/graph.md`'s scenes, none of them these (with frames in flight: stop 97; stop 98 "
             "tried split as the pick there where a node is slow, ahead on graph.md's SLAM scenes, and these runs did "
             "not bear it out). Split: the SLAM localization in a process of its own, the other nodes in one "
             "(`--split`). Since stop "
             "97 the recorder counts the graph's images without writing them, as `./run bench graph` does.")
    save("launch_mode", rows, cols, "The CLI's launch mode on held-out RGB-D SLAM scenes: one process, a process "
         "per node and split, live and lossless", notes, plot, extra={"runs": runs, **machine})


if __name__ == "__main__":
    main()
