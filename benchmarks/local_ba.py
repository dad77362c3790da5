"""Local bundle adjustment: how many points a local BA optimizes (``SlamConfig.max_ba_points``) against the map's
accuracy and the BA's time, and how the fixed keyframes are held (a GTSAM prior of 1e-6 since stop 55).

    ./run bench local_ba                      # about 15 minutes
    python -m benchmarks.local_ba --caps 800,0 --runs mono:2000:sync
    python -m benchmarks.local_ba --caps 0 --runs mono:1000:async,mono:2000:async,rgbd:1000:async \
        --interrupt on,off --repeat 3 --out local_ba_interrupt   # the interrupted BA (stop 56), about 12 minutes

Scene: ``slam_room`` at 640 x 480 (the localization benchmark's 10 s arc, 300 frames; the development scene: the
default was chosen on it). Each run is one SLAM over the frames: ``sync`` runs every local BA in the tracking thread
at once (deterministic: the BA's own effect), ``async`` as the nodes run it (the mapping process; a keyframe that comes
while a BA runs waits, and the map moves under the BA meanwhile). Caps: the most observed points a local BA
optimizes; 0 = every point its keyframes see (ORB-SLAM2). A point left out stays where it was while the keyframes
that see it move. The held-out check of the default is elsewhere: the real 7-Scenes frames (`real_slam.md`) and the
orbit's noise seeds 1-2 (`loop_closing.md`), neither run while it was chosen.

Reported: frames tracked, ATE (monocular after a similarity alignment), the final map's keyframes and points, BAs
applied / submitted / deferred, the BAs' own time (mean per BA, in whichever process ran it) and, synchronous, the
keyframe work per frame the tracking thread pays.

Interrupt (``SlamConfig.interrupt_ba``, asynchronous runs only): a keyframe whose BA must wait stops the running
local BA after its current iteration, and what that BA has is applied (ORB-SLAM2's abort flag); "stopped" counts them.
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.common import save
from benchmarks.localization import run_slam
from simreal_nodes.synth.sequence import sequence
from simreal_nodes.vision.slam.config import SlamConfig

CAPS = (400, 800, 1600, 0)
RUNS = ("mono:1000:sync", "mono:2000:sync", "rgbd:1000:sync", "mono:1000:async", "mono:2000:async",
        "rgbd:1000:async")


def run(seq: dict, mode: str, n_features: int, mapping: str, cap: int, interrupt: bool = True) -> dict:
    row = run_slam(seq, mode, n_features, async_mapping=(mapping == "async"),
                   config=SlamConfig(max_ba_points=cap, interrupt_ba=interrupt))
    row.update(mapping=mapping, cap=cap if cap else "all", keyframe_ms_per_frame=row["mapping_ms_per_frame"],
               interrupt=("on" if interrupt else "off") if mapping == "async" else "-")
    return row


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--caps", default=",".join(map(str, CAPS)), help="comma-separated max_ba_points (0 = all)")
    ap.add_argument("--runs", default=",".join(RUNS), help="comma-separated MODE:FEATURES:sync|async")
    ap.add_argument("--interrupt", default="on", help="comma-separated on|off: SlamConfig.interrupt_ba (async runs)")
    ap.add_argument("--repeat", type=int, default=1, help="runs of each setting (asynchronous runs vary)")
    ap.add_argument("--out", default="local_ba", help="results name under benchmarks/results")
    args = ap.parse_args(argv)
    caps = [int(c) for c in args.caps.split(",") if c]
    interrupts = [v == "on" for v in args.interrupt.split(",") if v]
    seq = sequence("slam_room", 640, 480, duration=10.0, fps=30.0, ssaa=1)
    rows = []
    for spec in (s for s in args.runs.split(",") if s):
        mode, n, mapping = spec.split(":")
        for cap in caps:
            for rep in range(args.repeat):  # the settings interleaved: a change of the host's load hits both
                for interrupt in interrupts if mapping == "async" else interrupts[:1]:
                    row = run(seq, mode, int(n), mapping, cap, interrupt)
                    row["run"] = rep + 1
                    rows.append(row)
                    print({k: round(v, 2) if isinstance(v, float) else v for k, v in row.items()}, flush=True)
    cols = [("mode", "mode", "{}"), ("features", "ORB features", "{}"), ("mapping", "local BA", "{}"),
            ("cap", "points per BA (cap)", "{}"), ("interrupt", "interrupt", "{}"), ("run", "run", "{}"),
            ("tracked", "tracked", "{}"), ("frames", "frames", "{}"),
            ("ate_mm", "ATE (mm)", "{:.2f}"), ("ate_pct", "ATE % length", "{:.3f}"),
            ("keyframes", "keyframes", "{}"), ("points", "points", "{}"), ("ba_applied", "BAs applied", "{}"),
            ("ba_deferred", "deferred (busy)", "{}"), ("ba_stopped", "stopped", "{}"),
            ("ba_ms_mean", "BA time (ms, mean)", "{:.0f}"),
            ("keyframe_ms_per_frame", "keyframe work / frame, tracking thread (ms)", "{:.1f}"),
            ("tracking_ms_p50", "tracking p50 (ms)", "{:.1f}")]

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
        key = lambda r: f"{r['mode']} {r['features']} {r['mapping']}" + (  # noqa: E731
            f" interrupt {r['interrupt']}" if r["interrupt"] != "-" else "")
        cap_names = list(dict.fromkeys(str(r["cap"]) for r in rows))
        for spec, mk in zip(dict.fromkeys(key(r) for r in rows), "osd^v<>ph*"):
            sel = [r for r in rows if key(r) == spec]
            for a, col in zip(ax, ("ate_mm", "ba_ms_mean")):  # every run as a point, the mean over runs as a line
                x = [cap_names.index(str(r["cap"])) for r in sel]
                a.plot(x, [r[col] for r in sel], mk, alpha=0.5)
                xs = sorted(set(x))
                a.plot(xs, [np.mean([r[col] for r, xi in zip(sel, x) if xi == c]) for c in xs], mk + "-", label=spec)
        for a in ax:
            a.set_xticks(range(len(cap_names)), cap_names)
        ax[0].set_ylabel("ATE RMSE (mm)")
        ax[0].set_yscale("log")
        ax[1].set_ylabel("local BA time (ms, mean)")
        for a in ax:
            a.set_xlabel("points per local BA (cap; all = ORB-SLAM2)")
            a.grid(True, alpha=0.3)
            a.legend(fontsize=7)
        return fig

    save(args.out, rows, cols, "Local bundle adjustment: points per BA against accuracy and time",
         "`python -m benchmarks.local_ba` (see its docstring). slam_room at 640 x 480, 300 frames (the development "
         "scene). Fixed keyframes held by a GTSAM prior of 1e-6 (stop 55; a NonlinearEquality constraint gives poses "
         "1e-8 apart, 4.7 times slower in a scratch run). Synchronous runs are deterministic; asynchronous ones move "
         "from run to run with the host's timing.", plot)


if __name__ == "__main__":
    main()
