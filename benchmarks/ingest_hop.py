"""The ingest hop (issue 18, item 1): a graph whose camera needs no decompression, undistortion, calibration file or
file source starts no ingest node; its nodes read the camera topics themselves (``camera.ingest: auto``, the
default). Measured against the same graph with every frame through the ingest (``camera.ingest: always``, what every
graph did before).

    ./run bench ingest_hop                      # about 10 minutes on 2 cores
    python -m benchmarks.ingest_hop --reps 2    # two pairs per case

Input: the sample bags of the demo (``aluminium_beam``, markers, glued dots) and of the RGB-D SLAM scene
(``foam_beam``), 640 x 480, with their JPEG images decoded once into raw ``rgb8`` Images (a raw camera, as a
RealSense's or a USB camera's driver publishes them): both arms see the same pixels. Each case runs as pairs (always
and auto back to back, the order alternating), repeated (``--reps``), so that a host whose speed drifts moves both
runs of a pair alike; lossless replays (:func:`benchmarks.graph.run_case`). Reported per case and arm: the median of
its runs of frames through per second, latency p50 / p95, the nodes' CPU per frame (summed over their processes) and
the player's, and the load estimate's median error (% of its range, against the bag's truth): it must not change,
since the nodes get the same bytes either way. On the auto rows, the median of the pairs' changes.
"""

from __future__ import annotations

import argparse
import functools
import os
from pathlib import Path

import numpy as np
import yaml

from benchmarks.common import pair_changes, save, saved_machine, speed_probe

CASES = (("aluminium_beam", True), ("aluminium_beam", False), ("foam_beam", True))  # (scene, one process)
ARMS = ("always", "auto")
WORK = Path(__file__).resolve().parents[1] / "cache" / "bench" / "ingest_hop"


def raw_bag(scene: str) -> tuple[Path, dict[str, Path]]:
    """The sample bag of ``scene`` at 640 x 480 with its compressed images decoded into raw rgb8 Images (written once
    under cache/), and a scene file per arm (``camera.compressed: false``, ``camera.ingest`` the arm)."""
    from simreal_nodes.demo import sample_bag
    from simreal_nodes.io import bags, images

    src, src_yaml = sample_bag(scene, resolution="640x480", echo=lambda *a: None)
    out = WORK / f"{scene}_raw"
    if not out.is_dir():
        WORK.mkdir(parents=True, exist_ok=True)
        tmp = WORK / f"{scene}_raw.part"
        if tmp.exists():
            import shutil

            shutil.rmtree(tmp)
        ts = bags.typestore()
        image_t = ts.types["sensor_msgs/msg/Image"]
        with bags.BagWriter(tmp) as w:
            for m in bags.read_bag(src):
                if m.msgtype.endswith("CompressedImage") and m.topic.endswith("/compressed"):
                    c = bags.decode(m)
                    arr, enc = images.decode_compressed(c)
                    f = images.array_to_image_fields(arr, enc)
                    msg = image_t(header=c.header, height=f.height, width=f.width, encoding=f.encoding,
                                  is_bigendian=0, step=f.step, data=np.frombuffer(bytes(f.data), np.uint8))
                    w.write(m.topic[: -len("/compressed")], m.log_time_ns, msg, "sensor_msgs/msg/Image")
                else:
                    w.write_raw(m.topic, m.log_time_ns, m.raw, m.msgtype)
        tmp.rename(out)
    doc = yaml.safe_load(src_yaml.read_text())
    scenes = {}
    for arm in ARMS:
        doc["camera"] = dict(doc["camera"], compressed=False, ingest=arm)
        scenes[arm] = WORK / f"{scene}_{arm}.yaml"
        scenes[arm].write_text(yaml.safe_dump(doc, sort_keys=False))
    return out, scenes


def load_error(scene_yaml: Path, truth: Path, record: Path) -> dict:
    """``evaluate`` for :func:`benchmarks.graph.run_case` (bound to a scene and its truth with ``partial``): the
    median error of each tracked parameter, % of its range, and their median."""
    from simreal_nodes.demo import evaluate_run
    from simreal_nodes.scene.schema import load_scene

    res = evaluate_run(record, truth, load_scene(scene_yaml), record.parent)
    pct = [r["median_pct_of_range"] for r in res.values() if r.get("median_pct_of_range") is not None]
    return {"error_pct": float(np.median(pct)) if pct else float("nan"),
            "errors": {k: r.get("median_pct_of_range", r.get("error")) for k, r in res.items()}}


def graph_run(scene: str, one_process: bool, arm: str) -> dict:
    from benchmarks.graph import PLAYER, run_case

    bag, scenes = raw_bag(scene)
    r = run_case(scene, "640x480", bag, scenes[arm], True, one_process,
                 evaluate=functools.partial(load_error, scenes[arm], bag))
    return dict(case=f"{scene} 640x480 raw lossless, {r['launch']}", arm=arm, fps=r["fps"],
                latency_p50=r["latency_p50"], latency_p95=r["latency_p95"], cpu_ms=r["nodes_cpu_ms"],
                player_cpu_ms=r.get(f"cpu_{PLAYER.split(' ')[0]}_ms", float("nan")),
                delivered_pct=r["delivered_pct"], error_pct=r["error_pct"], errors=r["errors"],
                cpu_by_node={k[4:-3]: v for k, v in r.items() if k.startswith("cpu_") and k.endswith("_ms")})


def summarize(runs: list[dict]) -> list[dict]:
    """Per case and arm the median of its runs; on the auto rows the median of the pairs' changes."""
    rows = []
    for case in dict.fromkeys(r["case"] for r in runs):
        by = {a: [r for r in runs if r["case"] == case and r["arm"] == a] for a in ARMS}
        for a, rs in by.items():
            row = dict(case=case, arm=a, runs=len(rs),
                       nodes="ingest + " if a == "always" else "",
                       **{k: float(np.median([r[k] for r in rs]))
                          for k in ("fps", "latency_p50", "latency_p95", "cpu_ms", "player_cpu_ms", "delivered_pct",
                                    "error_pct")})
            ingest = [r["cpu_by_node"]["ingest"] for r in rs if "ingest" in r["cpu_by_node"]]
            if ingest:  # its own process's, where each node has one
                row["ingest_cpu_ms"] = float(np.median(ingest))
            if a == "auto":
                change = pair_changes(by["always"], rs, "cpu_ms")
                row["cpu_change_pct"] = float(np.median(change))
                row["cpu_change_range"] = f"{min(change):+.0f} to {max(change):+.0f}"
                row["fps_change_pct"] = float(np.median(pair_changes(by["always"], rs, "fps")))
                row["p50_change_pct"] = float(np.median(pair_changes(by["always"], rs, "latency_p50")))
            rows.append(row)
    return rows


COLUMNS = [("case", "case", "{}"), ("arm", "camera.ingest", "{}"), ("runs", "runs", "{}"),
           ("delivered_pct", "frames through (%)", "{:.0f}"), ("fps", "fps through", "{:.1f}"),
           ("fps_change_pct", "fps change, pairs' median (%)", "{:+.0f}"),
           ("cpu_ms", "nodes' CPU per frame (ms)", "{:.1f}"),
           ("cpu_change_pct", "CPU change, pairs' median (%)", "{:+.0f}"),
           ("cpu_change_range", "pairs' range (%)", "{}"),
           ("ingest_cpu_ms", "the ingest's own CPU per frame (ms)", "{:.1f}"),
           ("latency_p50", "latency p50 (ms)", "{:.0f}"), ("p50_change_pct", "p50 change (%)", "{:+.0f}"),
           ("latency_p95", "p95 (ms)", "{:.0f}"), ("player_cpu_ms", "player CPU per frame (ms)", "{:.1f}"),
           ("error_pct", "load error, median (% of range)", "{:.2f}")]


def report(runs: list[dict], probes: list[float]) -> None:
    rows = summarize(runs)

    def plot(plt):
        cases = list(dict.fromkeys(r["case"] for r in rows))
        fig, ax = plt.subplots(1, 2, figsize=(12, 3.8))
        for k, (a, color) in enumerate((("always", "tab:blue"), ("auto", "tab:orange"))):
            for j, key in enumerate(("cpu_ms", "fps")):
                v = [next(r[key] for r in rows if r["case"] == c and r["arm"] == a) for c in cases]
                ax[j].barh([i + 0.4 * k for i in range(len(cases))], v, height=0.4, color=color,
                           label=f"camera.ingest: {a}")
                for i, c in enumerate(cases):
                    pts = [r[key] for r in runs if r["case"] == c and r["arm"] == a]
                    ax[j].plot(pts, [i + 0.4 * k] * len(pts), "k.", ms=4)
        for j, lab in enumerate(("nodes' CPU per frame (ms); dots: runs", "frames through per second; dots: runs")):
            ax[j].set_yticks([i + 0.2 for i in range(len(cases))],
                             [c.replace(" raw lossless,", "\n") for c in cases] if j == 0 else [])
            ax[j].set_xlabel(lab)
        ax[0].legend(fontsize=7)
        fig.tight_layout()
        return fig

    graph = saved_machine("graph").get("machine", {})
    graph_probe = (f" (`graph.md`'s run, {graph['date'][:10]}: {graph['cpu_probe_ms']:.0f} ms)"
                   if "cpu_probe_ms" in graph and "date" in graph else "")
    notes = ("Each case ran as pairs (always and auto back to back, the order alternating); the table gives the "
             "median of each case's runs and, on the auto rows, the median of the pairs' changes. Lossless replays "
             "of the sample bags with raw images (`benchmarks/graph.py`'s `run_case`, each replay in a fresh "
             "process); the nodes' CPU per frame is summed over their processes (with `always` it includes the "
             "ingest's), the player's is the replay's own process. The ingest's own CPU: its process's, where each "
             "node has one. The load error: the median over the tracked parameters of each one's median error "
             "against the bag's truth, % of its range (the demo's load position; the foam beam's load; its RGB-D "
             "SLAM maps in a worker process, so its runs differ a little run to run). 2-core CPU; the host's CPU "
             f"probe read {min(probes):.0f}-{max(probes):.0f} ms over the run{graph_probe}, so the absolute figures "
             "are `graph.md`'s only on a host as fast; the pairs' changes are what this table is for.")
    save("ingest_hop", rows, COLUMNS, "The ingest hop: nodes reading a raw camera's topics themselves "
         "(camera.ingest: auto) against every frame through the ingest node (always)", notes, plot,
         extra={"runs": runs, "cpu_probes_ms": probes})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=4, help="pairs per case (default 4; the order alternates)")
    a = ap.parse_args()
    from simreal_nodes.launch import ros_environment

    os.environ.update(ros_environment())
    probes = [speed_probe()]
    runs = []
    for rep in range(a.reps):
        for scene, one in CASES:
            for arm in ARMS if rep % 2 == 0 else ARMS[::-1]:  # ABBA: a drift in the host's speed favours neither
                runs.append(graph_run(scene, one, arm))
                print({k: v for k, v in runs[-1].items() if k != "errors"}, flush=True)
        probes.append(speed_probe())
    report(runs, probes)


if __name__ == "__main__":
    main()
