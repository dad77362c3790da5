"""The numerical libraries' thread pools in the node processes (issue 18), three settings of ``simreal launch|replay
--threads``: the default (one thread for the linear algebra's pools, OpenBLAS for numpy and scipy, OpenMP for
Open3D; OpenCV's own pool as OpenCV sizes it), ``1`` (every pool one thread, OpenCV's too) and ``0`` (every pool as
its library sizes it: a thread per core).

    ./run bench threads

Two parts, the settings' runs in the order default, 1, 0, 0, 1, default (a host whose speed drifts favours none):

- *offline*: the ROS-free pipeline (RGB-D SLAM, registration, the dense tracker) on every frame of development scene
  3 (the frames ``benchmarks.dense_budget`` renders and caches), in a fresh process whose environment is the one the
  launcher gives a node (:func:`simreal_nodes.launch.ros_environment`) and whose OpenCV pool is sized as a node sizes
  it (:func:`simreal_nodes.launch.set_threads`). Per frame: wall time, the process's CPU time (user + system: every
  thread's), the tracker's time (p50); and the estimates' largest difference between the settings (% of each
  parameter's range; the pools' reductions may round differently, nothing else may change);
- *graph*: ``benchmarks.graph.run_case`` on the demo (markers, 640 x 480) and on ``family-3`` (RGB-D SLAM -> the
  dense tracker), lossless, one process per node and all in one process: frames per second through the graph, the
  nodes' CPU per frame, the tracker process's CPU per frame.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import save

ROOT = Path(__file__).resolve().parents[1]
SEED = 3
ORDER = (None, 1, 0, 0, 1, None)  # --threads in the runs of each case (None: the default; 0: the libraries' own)
SETTINGS = (None, 1, 0)
GRAPH_CASES = (("aluminium_beam", "640x480"), ("family-3", "640x480"))


def worker(out: Path) -> None:
    """One offline run in this process (its environment already the node's): per frame wall, CPU, tracker time and
    the estimate."""
    from benchmarks.dense_budget import FPS, scene_pipeline
    from simreal_nodes.launch import node_threads, set_threads

    set_threads(node_threads())
    rgb, depth, pipe, fs = scene_pipeline(SEED)
    rows = []
    for i in range(len(rgb)):
        w0, c0 = time.perf_counter(), time.process_time()
        T_wc, est = pipe.step(np.ascontiguousarray(rgb[i][:, :, ::-1]), int(i * 1e9 / FPS), depth[i], None)
        rows.append({"wall_ms": 1e3 * (time.perf_counter() - w0), "cpu_ms": 1e3 * (time.process_time() - c0),
                     "tracker_ms": pipe.tracker_ms if T_wc is not None else None,
                     "est": [float(v) for v in est["beam"].values]})
    spans = [float(s) for s in fs.scene.state["draw"].spans]
    out.write_text(json.dumps({"frames": rows, "spans": spans}))


def label(threads: int | None) -> str:
    return {None: "default", 0: "0 (libraries' own)"}.get(threads, str(threads))


def offline_run(threads: int | None) -> dict:
    from simreal_nodes.launch import THREAD_VARS, THREADS_ENV, ros_environment

    env = ros_environment({k: v for k, v in os.environ.items() if k not in (THREADS_ENV, *THREAD_VARS)},
                          threads=threads)
    env["PYTHONPATH"] = str(ROOT)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", str(out)], cwd=ROOT, env=env,
                       check=True)
        return dict(json.loads(out.read_text()))


def offline_rows() -> list[dict]:
    from benchmarks.dense_budget import frames

    frames(SEED)  # rendered once, before the timed runs
    rows, first = [], None
    for rep, threads in enumerate(ORDER):
        doc = offline_run(threads)
        fr = doc["frames"][1:]  # the first frame: imports and the map's start
        est = np.array([f["est"] for f in doc["frames"]], float)
        span = np.asarray(doc["spans"], float)
        if first is None:
            first = est
        diff = float(100 * np.max(np.abs(est[:, :len(span)] - first[:, :len(span)]) / span))
        tr = [f["tracker_ms"] for f in fr if f["tracker_ms"] is not None]
        rows.append(dict(part="offline", case=f"family {SEED}, pipeline", threads=label(threads), run=rep,
                         wall_ms=float(np.mean([f["wall_ms"] for f in fr])),
                         cpu_ms=float(np.mean([f["cpu_ms"] for f in fr])), tracker_p50=float(np.median(tr)),
                         est_diff_pct=diff))
        print(rows[-1], flush=True)
    return rows


def graph_rows() -> list[dict]:
    from benchmarks.graph import _num, run_case
    from simreal_nodes.demo import sample_bag
    from simreal_nodes.launch import THREAD_VARS, THREADS_ENV

    rows = []
    names = (THREADS_ENV, *THREAD_VARS)
    saved = {k: os.environ.pop(k) for k in names if k in os.environ}  # each setting as on a bare environment
    try:
        for scene, res in GRAPH_CASES:
            bag, scene_yaml = sample_bag(scene, resolution=res, echo=lambda *a: None)
            for one_process in (False, True):
                for rep, threads in enumerate(ORDER):
                    # the launcher reads it as a user's variable (unset: the default)
                    os.environ.pop(THREADS_ENV, None)
                    if threads is not None:
                        os.environ[THREADS_ENV] = str(threads)
                    r = run_case(scene, res, bag, scene_yaml, True, one_process)
                    rows.append(dict(part="graph", case=f"{scene} {res}, {r['launch']}", threads=label(threads),
                                     run=rep,
                                     fps=r["fps"], nodes_cpu_ms=r["nodes_cpu_ms"],
                                     tracker_cpu_ms=_num(r.get("cpu_tracker_ms")),
                                     tracker_p50=_num(r.get("tracker_p50_ms")),
                                     latency_p50=r["latency_p50"]))
                    print(rows[-1], flush=True)
    finally:
        for k in names:
            os.environ.pop(k, None)
        os.environ.update(saved)
    return rows


def medians(rows: list[dict]) -> list[dict]:
    """Per case and setting: the median of its runs (each numeric column)."""
    out = []
    for case in dict.fromkeys(r["case"] for r in rows):
        for threads in map(label, SETTINGS):
            rs = [r for r in rows if r["case"] == case and r["threads"] == threads]
            keys = [k for k in rs[0] if isinstance(rs[0][k], float)]
            out.append(dict(case=case, threads=threads, **{k: float(np.median([r[k] for r in rs])) for k in keys}))
    return out


def plot_rows(plt, med: list[dict]):
    fig, ax = plt.subplots(1, 2, figsize=(12, 4))
    cases = list(dict.fromkeys(r["case"] for r in med))
    for k, (threads, color) in enumerate(zip(SETTINGS, ("tab:blue", "tab:green", "tab:orange"), strict=True)):
        by = {r["case"]: r for r in med if r["threads"] == label(threads)}
        x = [i + 0.27 * k - 0.27 for i in range(len(cases))]
        ax[0].bar(x, [by[c].get("cpu_ms", by[c].get("nodes_cpu_ms")) for c in cases], width=0.27, color=color,
                  label=f"--threads {label(threads)}")
        ax[1].bar(x, [by[c]["wall_ms"] if "wall_ms" in by[c] else 1e3 / by[c]["fps"] for c in cases],
                  width=0.27, color=color, label=f"--threads {label(threads)}")
    ax[0].set_ylabel("CPU per frame (ms; offline: the process,\ngraph: the nodes)")
    ax[1].set_ylabel("wall time per frame (ms; graph: 1000 / fps)")
    for a in ax:
        a.set_xticks(range(len(cases)))
        a.set_xticklabels([c.replace("aluminium_beam", "demo").replace(", ", "\n").replace(" 640x480", "\n640x480")
                           for c in cases], fontsize=7)
    ax[0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def main() -> None:
    if sys.argv[1:2] == ["--worker"]:
        worker(Path(sys.argv[2]))
        return
    if sys.argv[1:2] == ["--replot"]:  # the figure again from the saved rows
        from benchmarks.common import replot

        replot("threads", plot_rows)
        return
    rows = offline_rows() + graph_rows()
    med = medians(rows)
    cols = [("case", "case", "{}"), ("threads", "--threads", "{}"),
            ("fps", "fps through", "{:.1f}"), ("wall_ms", "wall ms/frame", "{:.1f}"),
            ("cpu_ms", "CPU ms/frame", "{:.1f}"), ("nodes_cpu_ms", "nodes' CPU ms/frame", "{:.1f}"),
            ("tracker_cpu_ms", "tracker process CPU ms/frame", "{:.1f}"), ("tracker_p50", "tracker p50 (ms)", "{:.1f}"),
            ("latency_p50", "latency p50 (ms)", "{:.0f}"), ("est_diff_pct", "estimates' largest difference (% range)",
                                                            "{:.2g}")]

    def plot(plt):
        return plot_rows(plt, med)

    notes = ("Medians of each setting's two runs (order default, 1, 0, 0, 1, default per case; every run in `runs` of "
             "the JSON). "
             "Offline: the ROS-free pipeline on every frame of development scene 3 but the first, in a fresh process "
             "with a node's environment; CPU is the process's (every thread's). Graph: `benchmarks.graph.run_case`, "
             "lossless; the nodes' CPU per frame from /proc. The estimates' difference is from the first offline run.")
    save("threads", med, cols, "The libraries' thread pools in the node processes: the default (linear algebra one "
         "thread, OpenCV its own), every pool one thread, every pool its library's own", notes, plot,
         extra={"runs": rows})


if __name__ == "__main__":
    main()
