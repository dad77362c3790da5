"""Loop closing (issue 17): does closing the loop remove the drift of a full turn, what does the search cost per
keyframe, and does it ever close a false loop?

    ./run bench loop_closing                    # monocular noise seeds 0 / 1 / 2 and RGB-D seed 0, each without
                                                # and with loop closing (8 runs of 720 frames, about 25 minutes)
    python -m benchmarks.loop_closing --runs mono:1 --loop on

Scene: ``slam_room_orbit``, the static textured room of `benchmarks/localization.py` circled once all the way round
its objects (radius 0.75 m, 24 s at 30 fps: 720 frames, 640 x 480) and on past the start by 60 degrees, so the
camera comes back to where the map began from the other side with the drift of the whole turn. Frames are rendered
one at a time and fed as live: local bundle adjustment (and the global one after a loop) in the mapping process.
The seed draws the image (and depth) noise only; the camera path is the same. Seed 0 was the development run (the
code was debugged on it); seeds 1 and 2 were not run before these rows. The thresholds (`vision/slam/loop_closing.py`)
are ORB-SLAM2's or set before any run, not tuned on these scenes.

Reported per run: frames tracked; ATE of the trajectory as it was tracked (each frame's pose when it was processed;
monocular after a similarity alignment); the final keyframe trajectory's ATE (the map after the run: what a loop
correction and the global BA improve); the return error: the last 60 frames' error after aligning the first 200
(the drift of the turn as the camera sees it when it comes back); loops closed (keyframe pair, projection matches,
scale) and the cost: loop search per keyframe (mean, p95) and the correction (Sim3, fusion, essential graph).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.common import save
from simreal_nodes.synth.sequence import FrameStream
from simreal_nodes.vision.slam.config import SlamConfig
from simreal_nodes.vision.slam.system import Slam
from simreal_nodes.vision.trajectory import ate, umeyama

FPS = 30.0
DURATION = 24.0
ALIGN_FRAMES = 200  # the return error aligns the first frames ...
RETURN_FRAMES = 60  # ... and measures the last ones


def run(mode: str, seed: int, loop: bool) -> dict:
    fs = FrameStream("slam_room_orbit", 640, 480, duration=DURATION, fps=FPS, ssaa=1, seed=seed)
    slam = Slam(fs.cam, mode, 1000, async_mapping=True, config=SlamConfig(loop_closing=loop))
    est: list[np.ndarray | None] = []
    ref: list[np.ndarray] = []
    loop_ms: list[float] = []
    t0 = time.perf_counter()
    try:
        for i, f in enumerate(fs):
            r = slam.track(f["gray"], i, depth=f["depth"] if mode == "rgbd" else None)
            est.append(None if r.T_wc is None else np.array(r.T_wc))
            ref.append(f["T"])
            if "loop_ms" in r.timings:
                loop_ms.append(r.timings["loop_ms"])
        # the final map: let the mapping process's last result land
        for _ in range(50):
            if slam.mapper._inflight is None and not slam.mapper._pending_global:
                break
            time.sleep(0.1)
            slam.mapper.poll()
    finally:
        slam.close()
    wall = time.perf_counter() - t0
    scaled = mode == "mono"
    idx = [i for i, T in enumerate(est) if T is not None]
    P = np.array([est[i][:3, 3] for i in idx])  # type: ignore[index]
    Q = np.array([ref[i][:3, 3] for i in idx])
    a = ate(P, Q, with_scale=scaled)
    kfs = sorted(slam.map.keyframes.values(), key=lambda k: k.id)
    ka = ate(np.array([k.center for k in kfs]), np.array([ref[k.stamp][:3, 3] for k in kfs]), with_scale=scaled)
    first = [j for j, i in enumerate(idx) if i < ALIGN_FRAMES]
    last = [j for j, i in enumerate(idx) if i >= len(est) - RETURN_FRAMES]
    R, t, s = umeyama(P[first], Q[first], scaled)
    ret = np.linalg.norm(s * P[last] @ R.T + t - Q[last], axis=1)
    loops = slam.loop_closer.loops
    search = loop_ms
    corr = [lp.ms for lp in loops]
    return dict(mode=mode, seed=seed, loop="on" if loop else "off", frames=len(est), tracked=len(idx),
                ate_mm=1e3 * a["rmse"], kf_ate_mm=1e3 * ka["rmse"], return_mm=1e3 * float(np.sqrt(np.mean(ret ** 2))),
                loops=len(loops),
                loop_detail="; ".join(f"kf {lp.kf} on {lp.loop_kf}: {lp.matches} matches, scale {lp.scale:.3f}, "
                                      f"{lp.fused} points fused" for lp in loops),
                search_ms_mean=float(np.mean(search)) if search else float("nan"),
                search_ms_p95=float(np.percentile(search, 95)) if search else float("nan"),
                correction_ms=float(np.mean(corr)) if corr else float("nan"),
                keyframes=len(kfs), points=len(slam.map.points), fps_wall=len(est) / wall,
                ba_stale=slam.mapper.ba_stats.get("stale", 0), length_m=a["length"] if "length" in a else float("nan"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="mono:0,mono:1,mono:2,rgbd:0", help="mode:noise-seed pairs")
    ap.add_argument("--loop", default="off,on", help="loop closing off, on or both (off,on)")
    ap.add_argument("--name", default="loop_closing", help="results name")
    args = ap.parse_args(argv)
    rows = []
    for item in args.runs.split(","):
        mode, seed = item.split(":")
        for lp in args.loop.split(","):
            row = run(mode, int(seed), lp == "on")
            rows.append(row)
            print(row, flush=True)

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
        labels = sorted({f"{r['mode']} {r['seed']}" for r in rows})
        x = np.arange(len(labels))
        for k, (lp, off) in enumerate((("off", -0.2), ("on", 0.2))):
            sel = {f"{r['mode']} {r['seed']}": r for r in rows if r["loop"] == lp}
            ax[0].bar(x + off, [sel[lb]["return_mm"] if lb in sel else np.nan for lb in labels], 0.4,
                      label=f"loop closing {lp}", color=f"C{k}")
            ax[1].bar(x + off, [sel[lb]["kf_ate_mm"] if lb in sel else np.nan for lb in labels], 0.4,
                      label=f"loop closing {lp}", color=f"C{k}")
        for a_, yl in zip(ax, ("return error: last 60 frames after aligning the first 200 (mm)",
                               "final keyframe trajectory ATE (mm)")):
            a_.set_xticks(x, labels)
            a_.set_ylabel(yl, fontsize=8)
            a_.legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("mode", "mode", "{}"), ("seed", "noise seed", "{}"), ("loop", "loop closing", "{}"),
            ("frames", "frames", "{}"), ("tracked", "tracked", "{}"), ("ate_mm", "ATE as tracked (mm)", "{:.2f}"),
            ("kf_ate_mm", "keyframe ATE, final map (mm)", "{:.2f}"), ("return_mm", "return error (mm)", "{:.2f}"),
            ("loops", "loops", "{}"), ("search_ms_mean", "loop search per keyframe (ms, mean)", "{:.1f}"),
            ("search_ms_p95", "p95", "{:.1f}"), ("correction_ms", "correction (ms)", "{:.0f}"),
            ("keyframes", "keyframes", "{}"), ("points", "points", "{}"),
            ("fps_wall", "fps (wall, all work)", "{:.1f}"),
            ("loop_detail", "loops closed", "{}")]
    notes = ("`slam_room_orbit`: one full turn round the room's objects and 60 degrees on (720 frames at 30 fps, "
             "640 x 480), 1000 ORB features, local and global bundle adjustment in the mapping process (as live). "
             "ATE as tracked: every frame's pose when it was processed (monocular: similarity alignment). Keyframe "
             "ATE: the keyframes of the final map against the truth at their frames. Return error: the last 60 frames "
             "after aligning the first 200 frames only (the turn's drift where the camera comes back). The loop "
             "search runs at every keyframe once the map holds 12; the correction is the Sim3, the fusion, the "
             "essential graph and the start of the global BA (which runs in the mapping process).")
    save(args.name, rows, cols, "Loop closing on a full turn: drift at the return, final map, cost", notes, plot)


if __name__ == "__main__":
    main()
