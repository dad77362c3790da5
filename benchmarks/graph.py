"""Whole graph (issues 7, 18): frames per second, latency and CPU of the node graph, one process per node against
all nodes in one process (``--one-process``) and, for the scenes with a node slower than a frame, the split launch
(``--split``: that node alone, the others in one process), on these scenes:

- the demo (``aluminium_beam``: ingest -> markers localization -> deformable tracker (glued dots) -> overlay) at
  640 x 480 and 1280 x 720;
- an RGB-D SLAM scene (``foam_beam``: ingest -> RGB-D SLAM -> tracker (map points) -> overlay) at 640 x 480;
- a scene of the family (development seed 3, ``family-3``: RGB-D SLAM -> the dense tracker, its beam placed by
  registration from depth -> overlay) at 640 x 480: the heaviest tracker, where one executor for every node
  makes the others wait for it.

    ./run bench graph

Three replays of each scene's sample bag per resolution and launch: *lossless* (the player waits for every frame to
leave the graph before the next: lock-step throughput), *lossless with IN_FLIGHT frames in flight* (every frame still
processed by every node, in order; the nodes of a process per node overlap) and *real time* at the bag's 30 fps
(live QoS: a busy node takes the newest frame and skips the others); on the demo at 640 x 480 also 2 and 8 frames in
flight (``graph_in_flight``: the trade of frames a second against latency). Reported: frames that went through
every node per second of play and as a fraction, latency from publication to the overlay's report (its own clock),
each node's processing time, the CPU each process used per published frame (from /proc), and the nodes' CPU per
frame in all. The recorder counts the graph's image outputs without writing them (``run_case``'s
``record_images``). Last, the library pools' threads with frames in flight, one (the replay's default there)
against two (``graph_threads``).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import markdown_table, save
from simreal_nodes.demo import node_metrics, sample_bag
from simreal_nodes.launch import executor_kind
from simreal_nodes.metrics import STAGES
from simreal_nodes.ros.bagplay import STARTUP_S
from simreal_nodes.ros.commands import replay
from simreal_nodes.scene.graph import SPLIT, slow_nodes
from simreal_nodes.scene.schema import load_scene

CASES = (("aluminium_beam", "640x480", None), ("aluminium_beam", "1280x720", 4.0), ("foam_beam", "640x480", None),
         ("family-3", "640x480", None))
PLAYER = "player + recorder"
LAUNCH_NAMES = {False: "process per node", True: "one process", SPLIT: "split"}
POSE_TOPIC = "/simreal/localization/pose"
# the lossless rows with frames in flight: as many as the graphs' per-frame nodes (ingest, localization, tracker,
# overlay), so that with a process per node each can work on a frame of its own
IN_FLIGHT = 4
SWEEP_CASE = ("aluminium_beam", "640x480")  # the in-flight trade, measured besides 1 and IN_FLIGHT at these
SWEEP = (2, 8)
# the pools' threads with frames in flight (replay's IN_FLIGHT_THREADS, one, against two: OpenCV's own count here)
THREADS_CASES = ((("aluminium_beam", "640x480"), False), (("foam_beam", "640x480"), SPLIT))


def main():
    rows, sweep = [], []
    for scene, res, duration in CASES:
        bag, scene_yaml = sample_bag(scene, duration=duration, resolution=res, echo=lambda *a: None)
        slow = bool(slow_nodes(load_scene(scene_yaml)))
        for lossless, in_flight in ((True, 1), (True, IN_FLIGHT), (False, 1)):
            # the split launch where the scene has a slow node (else it is the one process) and nodes overlap
            for one_process in (False, True) + ((SPLIT,) if slow and (in_flight > 1 or not lossless) else ()):
                rows.append(run_case(scene, res, bag, scene_yaml, lossless, one_process, in_flight=in_flight,
                                     record_images=False))
                print(rows[-1], flush=True)
        if (scene, res) == SWEEP_CASE:
            for in_flight in SWEEP:
                for one_process in (False, True):
                    sweep.append(run_case(scene, res, bag, scene_yaml, True, one_process, in_flight=in_flight,
                                          record_images=False))
                    print(sweep[-1], flush=True)
    report(rows)
    report_in_flight(rows, sweep)
    threads = []
    for (scene, res), launch in THREADS_CASES:
        bag, scene_yaml = sample_bag(scene, resolution=res, echo=lambda *a: None)
        for n in (1, 2, 2, 1):  # pairs, the order alternating
            threads.append(run_case(scene, res, bag, scene_yaml, True, launch, in_flight=IN_FLIGHT, threads=n,
                                    record_images=False))
            print(threads[-1], flush=True)
    report_threads(threads)


def run_case(scene, res, bag, scene_yaml, lossless, one_process, executor=None, evaluate=None,
             isolated=True, in_flight=1, record_images=True, threads=None) -> dict:
    """One replay; ``executor``: the nodes' and the player's (None: the default); ``evaluate(record) -> dict``:
    more of the row, read from the replay's record (picklable: a top-level function or a partial of one);
    ``in_flight``: lossless, the frames the player lets into the graph at once (1: lock-step); ``record_images``:
    False, the graph's image outputs are received and counted, not written (the harness then costs what a display
    would, not a disk: at 1280 x 720 the two raw images a frame cost the player about 7 ms of CPU a frame to write).

    ``isolated``: the replay runs in a fresh process, as ``simreal replay`` does, so that no case inherits another's
    process state. (Until stop 82 the replay never shut its EventsExecutor down, which kept the native memory of
    what it had received, replay after replay: a long benchmark filled the host's memory and slowed every later
    case. Fixed in ``replay``; ``tests/ros/test_replay.py`` keeps the measure.)"""
    if isolated:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            return pool.submit(run_case, scene, res, bag, scene_yaml, lossless, one_process, executor, evaluate,
                               False, in_flight, record_images, threads).result()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.monotonic()
        stats, _, counts = replay(str(bag), str(scene_yaml), lossless=lossless, record=str(Path(tmp) / "run"),
                                  echo=lambda *a: None, one_process=one_process, executor=executor,
                                  in_flight=in_flight, record_images=record_images, threads=threads)
        wall = time.monotonic() - t0
        nodes = node_metrics(Path(tmp) / "run")
        extra = evaluate(Path(tmp) / "run") if evaluate else {}
    d = stats.as_dict()
    lat = d["latency_ms"]
    last = lat.get("overlay") or next(iter(lat.values()), {"p50": float("nan"), "p95": float("nan")})
    cpu = d["cpu_ms_per_frame"]
    mode = ("lossless" if in_flight == 1 else f"lossless, {in_flight} in flight") if lossless else "real time (30 fps)"
    return dict(scene=scene, resolution=res, mode=mode, in_flight=in_flight if lossless else None, threads=threads,
                launch=LAUNCH_NAMES[one_process], executor=executor or executor_kind(),
                fps=d["fps_through"], delivered_pct=100 * d["frames_completed"] / max(d["frames_published"], 1),
                # the localization's own output (pose, TF): what a robot stack reads, whatever the later nodes do
                pose_pct=100 * counts.get(POSE_TOPIC, 0) / max(d["frames_published"], 1),
                # after the first second: the steady state, without the nodes' start-up (bagplay.STARTUP_S)
                steady_pct=_num(d["through_after_startup_pct"]),
                frames=d["frames_published"], lost=d["frames_published"] - d["frames_completed"],
                lost_startup=stats.lost_before(STARTUP_S),
                latency_p50=last["p50"], latency_p95=last["p95"], wall_s=wall,
                cores_busy=sum(stats.cpu_s.values()) / d["play_s"] if d["play_s"] > 0 else float("nan"),
                nodes_cpu_ms=sum(v for n, v in cpu.items() if n != PLAYER),
                nodes_work_ms=float(np.nansum([_num(v.get("processing_ms_p50")) for v in nodes.values()])),
                **{f"{n}_p50_ms": v.get("processing_ms_p50") for n, v in nodes.items()},
                **{f"cpu_{n.split(' ')[0]}_ms": v for n, v in cpu.items()},
                budget={n: {k: _num(v.get(f"{k}_ms_p50")) for k in (*STAGES, "processing")} for n, v in nodes.items()},
                **extra)


def _num(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


NODES = ("ingest", "localization", "tracker", "overlay")


def budget_rows(rows: list[dict]) -> list[dict]:
    """Per-stage budget of the lossless runs: each node's decode / work / encode and processing (p50, ms), and
    with one process per node the rest of its CPU per frame (the executor, the middleware, timers; for the
    localization also its mapping process)."""
    out = []
    for r in rows:
        if r["mode"] != "lossless":  # the lock-step runs: each node's time alone
            continue
        for n in NODES:
            b = r["budget"].get(n)
            if b is None:
                continue
            cpu = r.get(f"cpu_{n}_ms", float("nan"))
            out.append(dict(scene=r["scene"], resolution=r["resolution"], launch=r["launch"], node=n,
                            **{k: b[k] for k in (*STAGES, "processing")}, cpu=cpu,
                            rest=cpu - b["processing"] if cpu == cpu else float("nan")))
    return out


def report(rows):
    def plot(plt):
        fig, ax = plt.subplots(1, 3, figsize=(14, 3.8))
        cases = list(dict.fromkeys((r["scene"], r["resolution"], r["mode"]) for r in rows))
        x = range(len(cases))
        for k, (launch, color) in enumerate((("process per node", "tab:blue"), ("one process", "tab:orange"),
                                             ("split", "tab:green"))):
            by = {(r["scene"], r["resolution"], r["mode"]): r for r in rows if r["launch"] == launch}
            for a, key in zip(ax, ("fps", "latency_p95", "nodes_cpu_ms"), strict=True):
                a.bar([i + 0.28 * k - 0.28 for i in x], [by[c][key] if c in by else 0 for c in cases], width=0.28,
                      color=color, label=launch)
        ax[0].axhline(60, color="k", ls=":", lw=0.8)
        ax[0].axhline(30, color="k", ls="--", lw=0.8)
        ax[0].set_ylabel("frames per second (goal 60 / 30)")
        ax[1].set_ylabel("latency to overlay output, p95 (ms)")
        ax[2].axhline(30, color="k", ls=":", lw=0.8)
        ax[2].set_ylabel("nodes' CPU per frame (ms; goal 30 at 640x480)")
        for a in ax:
            a.set_xticks(list(x))
            a.set_xticklabels([f"{sc}\n{res}\n{m}" for sc, res, m in cases], fontsize=6)
        ax[0].legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("scene", "scene", "{}"), ("resolution", "resolution", "{}"), ("mode", "replay", "{}"),
            ("launch", "launch", "{}"), ("fps", "fps through the graph", "{:.1f}"),
            ("delivered_pct", "frames through (%)", "{:.0f}"),
            ("steady_pct", "after the first second (%)", "{:.0f}"), ("pose_pct", "camera poses out (%)", "{:.0f}"),
            ("latency_p50", "latency p50 (ms)", "{:.0f}"),
            ("latency_p95", "p95 (ms)", "{:.0f}"), ("nodes_cpu_ms", "nodes' CPU/frame (ms)", "{:.1f}"),
            ("nodes_work_ms", "nodes' processing p50, summed (ms)", "{:.1f}")]
    cpu_cols = sorted({k for r in rows for k in r if k.startswith("cpu_")})
    cols += [(k, k[4:-3] + " CPU/frame (ms)", "{:.1f}") for k in cpu_cols] + [("cores_busy", "cores busy", "{:.2f}")]
    save("graph", rows, cols, "Whole graph: the demo scene (markers + dots), RGB-D SLAM scenes (foam beam, map "
         "points; family seed 3, dense, registered), one process per node against one process and split",
         "Goals (issues 7, 18): >= 60 fps at 640x480 and >= 30 fps at 1280x720 lossless, 100 % through live at 30 fps "
         "with p95 <= 2 frame periods, nodes' CPU <= 30 ms per frame at 640x480; RGB-D SLAM graph >= 30 fps "
         "lossless. Node p50 columns: processing time per frame inside each node's callback (its /diagnostics: "
         "message to array, the core's work, array to message); their sum beside the nodes' CPU per frame (CPU "
         "time, user + system, from /proc, of every node process while the bag played, over the published "
         "frames): the difference is the executor, the middleware and the timers. 'nodes' is the process of several "
         "nodes: all of them with `--one-process`, all but the slow one(s) with `--split` (split: the nodes slower "
         "than a frame, a SLAM localization or a dense tracker, each in a process of its own); the player + "
         "recorder is the test harness (the bag reader, the camera's stand-in). "
         "After the first second: the frames through among those published a second or more after the first (the "
         "steady state: live, a graph's first frame waits for what each node builds on the first CameraInfo, which "
         "comes with it, and the frames meanwhile are replaced in the one-deep queues). "
         "Camera poses out: the frames the localization published a pose (and TF) for, whatever the later nodes did. "
         "Cores busy: all CPU over the play time. Lossless: reliable QoS with deep queues, every frame processed by "
         "every node in order; plain 'lossless' is lock-step (the player publishes a frame when every node reported "
         f"the last: one frame in the graph, its fps the inverse of a frame's trip), 'lossless, {IN_FLIGHT} in "
         f"flight' lets up to {IN_FLIGHT} frames in at once (nodes in their own processes work on different frames; "
         "latency then includes the queue; `simreal replay --lossless --in-flight N`, which then gives each "
         "library pool one thread: graph_threads.md). Real time: live QoS, a busy "
         "node takes the newest frame (skipped frames are the 'not through' ones). The recorder counts the graph's "
         "image outputs without writing them (the harness costs a display's reception, not a disk's) and, since "
         "stop 98, leaves the camera images the ingest passes on to the other nodes unsubscribed. "
         "2-core CPU, Mesa llvmpipe for the overlay.\n\n"
         "## Per-stage budget (lock-step lossless runs; ms per frame, p50 of each node's /diagnostics)\n\n"
         + markdown_table(budget_rows(rows), BUDGET_COLS) + "\n\n"
         "decode: messages to arrays (for ingest: the JPEG decompression); work: the ROS-free core; encode: arrays "
         "to messages and their publication; processing: the whole callback. CPU/frame and the rest (CPU/frame "
         "less processing: the executor, the middleware's receiving side, timers, and for the localization its "
         "mapping process) only where each node has its own process.", plot)


def report_in_flight(rows: list[dict], sweep: list[dict]) -> None:
    """The in-flight trade on the demo at 640 x 480: frames a second against latency, for 1, 2, IN_FLIGHT and 8
    frames in flight, each launch."""
    pts = sorted([r for r in rows if (r["scene"], r["resolution"]) == SWEEP_CASE and r["in_flight"]] + sweep,
                 key=lambda r: (r["launch"], r["in_flight"]))

    def plot(plt):
        fig, ax = plt.subplots(figsize=(6, 4))
        for launch, color in (("process per node", "tab:blue"), ("one process", "tab:orange")):
            mine = [r for r in pts if r["launch"] == launch]
            ax.plot([r["latency_p50"] for r in mine], [r["fps"] for r in mine], "o-", color=color, label=launch)
            for r in mine:
                ax.annotate(str(r["in_flight"]), (r["latency_p50"], r["fps"]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")
        ax.axhline(60, color="k", ls=":", lw=0.8)
        ax.set_xlabel("latency to the overlay's output, p50 (ms)")
        ax.set_ylabel("frames per second through the graph")
        ax.set_title("demo, 640 x 480, lossless: frames in flight (labels)", fontsize=9)
        ax.legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("launch", "launch", "{}"), ("in_flight", "frames in flight", "{}"), ("fps", "fps through", "{:.1f}"),
            ("delivered_pct", "frames through (%)", "{:.0f}"), ("latency_p50", "latency p50 (ms)", "{:.0f}"),
            ("latency_p95", "p95 (ms)", "{:.0f}"), ("nodes_cpu_ms", "nodes' CPU/frame (ms)", "{:.1f}"),
            ("cores_busy", "cores busy", "{:.2f}")]
    save("graph_in_flight", pts, cols, "Lossless replay of the demo (640 x 480): frames in flight against frames a "
         "second and latency, one process per node and one process",
         "`./run bench graph` (the 1 and 4 rows are graph.md's). Every frame goes through every node, in order, at "
         "any setting (frames through 100 %). More frames in flight let the nodes of a process per node work at "
         "once, on two cores; one process runs one callback at a time and gains only the player's overlap. The "
         "price is latency: a frame waits behind the ones before it.", plot)


def report_threads(runs: list[dict]) -> None:
    """The library pools' threads per node process with frames in flight: one (the replay's default there,
    ``commands.IN_FLIGHT_THREADS``) against two (OpenCV's own count on 2 cores), medians of two runs each."""
    rows = []
    for key in dict.fromkeys((r["scene"], r["launch"], r["threads"]) for r in runs):
        mine = [r for r in runs if (r["scene"], r["launch"], r["threads"]) == key]
        rows.append(dict(scene=key[0], launch=key[1], threads=key[2], runs=len(mine),
                         **{k: float(np.median([r[k] for r in mine]))
                            for k in ("fps", "nodes_cpu_ms", "cpu_player_ms", "latency_p50", "cores_busy")}))
    cols = [("scene", "scene", "{}"), ("launch", "launch", "{}"), ("threads", "threads a pool", "{}"),
            ("fps", "fps through", "{:.1f}"), ("nodes_cpu_ms", "nodes' CPU/frame (ms)", "{:.1f}"),
            ("cpu_player_ms", "player CPU/frame (ms)", "{:.1f}"), ("latency_p50", "latency p50 (ms)", "{:.0f}"),
            ("cores_busy", "cores busy", "{:.2f}")]

    def plot(plt):
        fig, ax = plt.subplots(figsize=(6, 3.5))
        labels = [f"{r['scene']}\n{r['launch']}\n{r['threads']} a pool" for r in rows]
        ax.bar(range(len(rows)), [r["fps"] for r in rows], color=["tab:blue" if r["threads"] == 1 else "tab:gray"
                                                                 for r in rows])
        ax.set_xticks(range(len(rows)))
        ax.set_xticklabels(labels, fontsize=7)
        ax.axhline(30, color="k", ls="--", lw=0.8)
        ax.set_ylabel(f"fps through, lossless, {IN_FLIGHT} in flight")
        fig.tight_layout()
        return fig

    save("graph_threads", rows, cols, f"Library pools' threads per node process, lossless with {IN_FLIGHT} frames "
         "in flight", "`./run bench graph`: each case twice per setting, order 1, 2, 2, 1; medians. With frames in "
         "flight every core is busy with a node, so a pool's helper threads (OpenCV's own count is one per core) "
         "only add switching and synchronisation: `simreal replay --lossless --in-flight N` gives every pool one "
         "thread unless told (`--threads`, `SIMREAL_THREADS`). 2 a pool is near the default before stop 98 on this "
         "2-core host, which was not run here: OpenCV a thread a core as there, the linear algebra's pools two "
         "against one, llvmpipe one thread besides the caller against its own count, a thread a core.", plot)


BUDGET_COLS = [("scene", "scene", "{}"), ("resolution", "resolution", "{}"), ("launch", "launch", "{}"),
               ("node", "node", "{}"), ("decode", "decode", "{:.2f}"), ("work", "work", "{:.2f}"),
               ("encode", "encode", "{:.2f}"), ("processing", "processing", "{:.2f}"),
               ("cpu", "CPU/frame", "{:.1f}"), ("rest", "rest", "{:.1f}")]


if __name__ == "__main__":
    main()
