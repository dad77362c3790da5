"""Whole graph on the demo scene (issue 7): frames per second and latency of ingest -> markers localization ->
deformable tracker -> overlay, each its own process over DDS, at 640 x 480 and 1280 x 720.

    ./run bench graph

Two replays of the demo's sample bag per resolution (6 s at 640 x 480, 4 s at 1280 x 720): *lossless* (the player
waits for every frame to leave the graph before the next: lock-step throughput) and *real time* at the bag's 30
fps (live QoS: a busy node takes the newest frame and skips the others). Reported: frames that went through every
node per second of play and as a fraction, latency from publication to the overlay's report (its own clock),
each node's processing time, and the CPU each process used per published frame (from /proc).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from benchmarks.common import save
from simreal_nodes.demo import node_metrics, sample_bag
from simreal_nodes.ros.commands import replay

RESOLUTIONS = ("640x480", "1280x720")


def main():
    rows = []
    for res in RESOLUTIONS:
        # 640x480: the demo's own bag (6 s); 1280x720: a 4 s one beside it
        bag, scene_yaml = sample_bag("aluminium_beam", duration=None if res == "640x480" else 4.0, resolution=res,
                                     echo=lambda *a: None)
        for lossless in (True, False):
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.monotonic()
                stats, _, _ = replay(str(bag), str(scene_yaml), lossless=lossless, record=str(Path(tmp) / "run"),
                                     echo=lambda *a: None)
                wall = time.monotonic() - t0
                nodes = node_metrics(Path(tmp) / "run")
            d = stats.as_dict()
            lat = d["latency_ms"]
            last = lat.get("overlay") or next(iter(lat.values()), {"p50": float("nan"), "p95": float("nan")})
            row = dict(resolution=res, mode="lossless" if lossless else "real time (30 fps)",
                       fps=d["fps_through"],
                       delivered_pct=100 * d["frames_completed"] / max(d["frames_published"], 1),
                       latency_p50=last["p50"], latency_p95=last["p95"], wall_s=wall,
                       cores_busy=sum(stats.cpu_s.values()) / d["play_s"] if d["play_s"] > 0 else float("nan"),
                       **{f"{n}_p50_ms": v.get("processing_ms_p50") for n, v in nodes.items()},
                       **{f"cpu_{n.split(' ')[0]}_ms": v for n, v in d["cpu_ms_per_frame"].items()})
            rows.append(row)
            print(row, flush=True)

    report(rows)


def report(rows):
    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
        labels = [f"{r['resolution']}\n{r['mode']}" for r in rows]
        ax[0].bar(labels, [r["fps"] for r in rows], color="tab:blue")
        ax[0].axhline(60, color="k", ls=":", lw=0.8)
        ax[0].axhline(30, color="k", ls="--", lw=0.8)
        ax[0].set_ylabel("frames per second (goal 60 / 30)")
        ax[1].bar(labels, [r["latency_p95"] for r in rows], color="tab:red")
        ax[1].set_ylabel("latency to overlay output, p95 (ms)")
        for a in ax:
            a.tick_params(axis="x", labelsize=7)
        fig.tight_layout()
        return fig

    cols = [("resolution", "resolution", "{}"), ("mode", "replay", "{}"), ("fps", "fps through the graph", "{:.1f}"),
            ("delivered_pct", "frames through (%)", "{:.0f}"), ("latency_p50", "latency p50 (ms)", "{:.0f}"),
            ("latency_p95", "p95 (ms)", "{:.0f}")]
    node_cols = sorted({k for r in rows for k in r if k.endswith("_p50_ms")})
    cols += [(k, k.replace("_p50_ms", " p50 (ms)"), "{}") for k in node_cols]
    cpu_cols = sorted({k for r in rows for k in r if k.startswith("cpu_")})
    cols += [(k, k[4:-3] + " CPU/frame (ms)", "{:.1f}") for k in cpu_cols] + [("cores_busy", "cores busy", "{:.2f}")]
    save("graph", rows, cols, "Whole graph on the demo scene (aluminium beam, markers + dots)",
         "Goal (issue 7): >= 60 fps at 640x480 and >= 30 fps at 1280x720. Node p50 columns: processing time per "
         "frame inside each node (its /diagnostics). CPU/frame columns: CPU time (user + system, from /proc) each "
         "process used while the bag played, per published frame (the player + recorder is the test harness, the "
         "bag reader and the camera's stand-in); cores busy: all of it over the play time. Real time: live QoS, "
         "a busy node takes the newest frame (skipped frames are the 'not through' ones). 2-core CPU, Mesa "
         "llvmpipe for the overlay.", plot)


if __name__ == "__main__":
    main()
