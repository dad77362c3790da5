"""The SLAM's time per frame, split by stage (issues 17 and 18): where tracking a frame goes (feature extraction,
matching, pose, local map) and what keyframes and local BAs add, and what a change of the code bought, on the same
frames.

    python -m benchmarks.slam_budget                        # this checkout: results/slam_budget.*
    python -m benchmarks.slam_budget --against ../other     # and another checkout (e.g. `git worktree add`)

Input: development scenes of the family (``--seeds``, default 0, 3, 12; 640 x 480 RGB-D at 15 fps, 90-135 frames),
rendered once and cached in ``cache/bench/slam_budget``. Each run tracks one scene in each mode (monocular, RGB-D) as
``family_slam`` does (1000 ORB features, synchronous mapping, every frame, no loop closing) in a fresh process, its
code from one checkout; with ``--against`` the two checkouts run in pairs, back to back and their order alternating
(ABBA).

Stages (the SLAM's own ``TrackResult.timings``, ms, medians over the tracked frames after the first five): feature
extraction (with the frame's checks and undistortion), depth lookup, matching against the last frame, the pose,
the local map's search and the pose on it, and the tracking in all (``total`` less keyframe insertion and local BA,
``family_slam``'s tracking time); keyframe insertion with its local BA is given as its mean per frame (it runs on
few frames). Also per run: the frames whose estimated pose differs from the scene's first run (this checkout's), to
the bit: a change meant to be pure speed must leave every pose as it was.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from benchmarks.common import save

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "cache" / "bench" / "slam_budget"
MODES = ("mono", "rgbd")
N_FEATURES = 1000
STAGES = ("extract_ms", "depth_ms", "match_ms", "pose_ms", "local_map_ms")


def frames(seed: int) -> Path:
    """The scene's grey frames, depth (metres) and camera, cached."""
    from benchmarks.family_slam import slam_sequence

    path = CACHE / f"family_{seed}.npz"
    if not path.exists():
        seq, _ = slam_sequence(seed)
        c = seq["cam"]
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, gray=np.array(seq["gray"]), depth=np.array(seq["depth"], np.float32), K=c.K,
                            D=c.D, size=[c.width, c.height])
    return path


def worker(seed: int, out: Path) -> None:
    """One run of each mode (in this process, with whatever ``simreal_nodes`` the path gives): per frame the SLAM's
    stage times and a digest of its pose."""
    import cv2

    from simreal_nodes.camera import CameraModel
    from simreal_nodes.vision.slam.config import SlamConfig
    from simreal_nodes.vision.slam.system import Slam

    cv2.setNumThreads(1)
    with np.load(frames(seed)) as z:  # each read of a compressed member inflates it whole: once
        gray, depth, K, D, size = z["gray"], z["depth"], z["K"], z["D"], z["size"]
    cam = CameraModel(int(size[0]), int(size[1]), K, D)
    runs = {}
    for mode in MODES:
        slam = Slam(cam, mode, N_FEATURES, config=SlamConfig(loop_closing=False))
        rows = []
        for i, g in enumerate(gray):
            r = slam.track(g, stamp=i, depth=depth[i] if mode == "rgbd" else None)
            pose = r.T_wc if r.state_name in ("ok", "relocalized") and r.T_wc is not None else None
            rows.append({**{k: float(v) for k, v in r.timings.items()},
                         "tracked": pose is not None,
                         "digest": hashlib.sha1(np.asarray(pose, np.float64).tobytes()).hexdigest()[:16]
                         if pose is not None else ""})
        slam.close()
        runs[mode] = {"frames": rows, "keyframes": len(slam.map.keyframes), "points": len(slam.map.points)}
    out.write_text(json.dumps({"seed": seed, "runs": runs}))


def summary(doc: dict, first: dict | None) -> dict:
    """Per mode: the stages' medians over the tracked frames after the first five, the tracking time (the step less
    mapping), mapping per frame; the frames whose pose differs from ``first``'s."""
    out: dict = {}
    for mode in MODES:
        fr = doc["runs"][mode]["frames"]
        ok = [f for f in fr[5:] if f["tracked"] and "match_ms" in f]
        track = [f["total_ms"] - f.get("mapping_ms", 0.0) - f.get("loop_ms", 0.0) for f in ok]
        out[f"{mode}_tracked"] = sum(f["tracked"] for f in fr)
        out[f"{mode}_frames"] = len(fr)
        out[f"{mode}_tracking_ms_p50"] = float(np.median(track)) if track else float("nan")
        for k in STAGES:
            out[f"{mode}_{k}_p50"] = float(np.median([f.get(k, 0.0) for f in ok])) if ok else float("nan")
        out[f"{mode}_mapping_ms_per_frame"] = float(np.mean([f.get("mapping_ms", 0.0) for f in fr]))
        out[f"{mode}_keyframes"] = doc["runs"][mode]["keyframes"]
        if first is not None:
            a, b = first["runs"][mode]["frames"], fr
            out[f"{mode}_poses_differ"] = int(sum(x["digest"] != y["digest"] for x, y in zip(a, b))
                                              + abs(len(a) - len(b)))
    return out


def main() -> None:
    if sys.argv[1:2] == ["--worker"]:  # one run, in a fresh process (benchmarks.common.run_worker)
        worker(int(sys.argv[2]), Path(sys.argv[3]))
        return
    from benchmarks.common import budget_runs, checkout_notes

    args, rows = budget_runs(__doc__, "0,3,12", "slam_budget", Path(__file__), ROOT, frames, summary)
    columns = [("seed", "seed", "{}"), ("code", "code", "{}"), ("rep", "run", "{}")]
    for mode, name in (("mono", "mono"), ("rgbd", "RGB-D")):
        columns += [(f"{mode}_tracking_ms_p50", f"{name} tracking (ms, p50)", "{:.2f}"),
                    (f"{mode}_extract_ms_p50", "extraction", "{:.2f}"),
                    (f"{mode}_match_ms_p50", "last-frame match", "{:.2f}"),
                    (f"{mode}_pose_ms_p50", "pose", "{:.2f}"), (f"{mode}_local_map_ms_p50", "local map", "{:.2f}"),
                    (f"{mode}_mapping_ms_per_frame", "keyframes + local BA (ms per frame)", "{:.1f}"),
                    (f"{mode}_poses_differ", "poses that differ", "{}")]
    notes = (f"{N_FEATURES} ORB features, synchronous mapping, every frame, one OpenCV and one BLAS thread. Tracking: "
             "the SLAM's time for a frame less keyframe insertion and local BA (as `family_slam`), median over the "
             "tracked frames after the first five; stages are the SLAM's own timings (medians, so they need not add "
             "up; RGB-D's depth lookup, 0.1 ms, not shown). Poses that differ: frames whose pose is not the scene's "
             "first run's (this checkout's) to the bit. Monocular: "
             + checkout_notes(rows, [("mono_tracking_ms_p50", "the monocular tracking p50")], "{:.2f}")
             + " RGB-D: " + checkout_notes(rows, [("rgbd_tracking_ms_p50", "the RGB-D tracking p50")], "{:.2f}"))

    def plot(plt):
        fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
        labels = [f"{r['seed']} {r['code']} {r['rep']}" for r in rows]
        for ax, (mode, name) in zip(axes, (("mono", "monocular"), ("rgbd", "RGB-D"))):
            bottom = np.zeros(len(rows))
            for key, stage in (("extract_ms", "extraction"), ("match_ms", "last-frame match"), ("pose_ms", "pose"),
                               ("local_map_ms", "local map")):
                v = np.array([r[f"{mode}_{key}_p50"] for r in rows])
                ax.barh(labels, v, left=bottom, label=stage)
                bottom += v
            ax.plot([r[f"{mode}_tracking_ms_p50"] for r in rows], labels, "k|", markersize=12, label="tracking p50")
            ax.set_title(name)
            ax.set_xlabel("ms per frame (p50 of each stage)")
        axes[0].legend(fontsize=7)
        axes[0].invert_yaxis()
        return fig

    save(args.out, rows, columns, "The SLAM's time per frame by stage (family development scenes, 640x480)", notes,
         plot)


if __name__ == "__main__":
    main()
