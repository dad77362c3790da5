"""The map-points pipeline's time per frame by stage (issues 16 and 18): what the localization spends on a scene whose
object is tracked by its map points (``tracking.measurements: map_points``), where the SLAM also measures the
object's points (Lucas-Kanade flow, ORB re-acquisition near the tracker's prediction) and steers features onto the
object, and what a change of the code bought, on the same frames.

    python -m benchmarks.points_budget                        # this checkout: results/points_budget.*
    python -m benchmarks.points_budget --against ../other     # and another checkout (e.g. `git worktree add`)

Input: the foam beam (the graph benchmark's RGB-D SLAM scene, 640 x 480 at 30 fps) and the joint boot of
development seed 10 (``family-boot-10``, 640 x 480 RGB-D at 15 fps), rendered once and cached as arrays in
``cache/bench/points_budget``. Each run is every frame through the offline pipeline (RGB-D SLAM with synchronous
mapping, the map-points tracker, its feedback to the SLAM at once) in a fresh process, its code from one checkout;
with ``--against``, each scene runs in pairs, the two checkouts back to back and the order alternating (ABBA).

Columns (ms, medians over the frames after the first twenty): the localization's step as the node calls it
(``Localizer.step``), and of the SLAM's own timings the feature extraction (with the objects' focus regions), the
deformable points' measurement (``deformable_ms``, where the checkout times it) and the tracking in all (the
SLAM's ``total`` less keyframe insertion and its local BA: in the node the BA runs in a worker process); the
tracker's time. Also per run: the frames whose camera pose, observations or estimate differ from the scene's
first run (this checkout's), to the bit: a change meant to be pure speed must leave every one as it was.
"""

from __future__ import annotations

import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.common import save

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "cache" / "bench" / "points_budget"
SCENES = (("foam_beam", 30.0), ("family-boot-10", 15.0))  # (scene, fps); a run's "seed" is the index here
SKIP = 20  # the frames before the map and the tracker have started are not timed


def frames(index: int) -> Path:
    """The scene's rendered frames (RGB, depth), cached."""
    from simreal_nodes.synth.sequence import sequence

    name, fps = SCENES[index]
    path = CACHE / f"{name}.npz"
    if not path.exists():
        seq = sequence.__wrapped__(name, 640, 480, fps=fps)
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, rgb=np.array(seq["rgb"]), depth=np.array(seq["depth"], np.float32))
    return path


def worker(index: int, out: Path) -> None:
    """One run (in this process, with whatever ``simreal_nodes`` the path gives): per frame the localization's time,
    the SLAM's stage times, the tracker's time and a digest of the pose, the observations and the estimates."""
    import copy

    import cv2

    from simreal_nodes.assimilation.offline import Pipeline
    from simreal_nodes.scene.schema import build_spec_models, validate_scene
    from simreal_nodes.synth.sequence import FrameStream

    cv2.setNumThreads(1)
    name, fps = SCENES[index]
    with np.load(frames(index)) as z:  # each read of a compressed member inflates it whole: once
        rgb, depth = z["rgb"], z["depth"]
    fs = FrameStream(name, 640, 480, None, fps, False, 0, 2, None)
    doc = copy.deepcopy(fs.scene.scene_yaml(fs.scene))
    pipe = Pipeline(build_spec_models(validate_scene(doc, fs.scene.name, ".")), fs.cam,
                    baseline=fs.scene.stereo_baseline)
    step = pipe.loc.step
    last: dict = {}

    def timed(*a, **k):
        t0 = time.perf_counter()
        r = step(*a, **k)
        last.update(loc_ms=1e3 * (time.perf_counter() - t0), timings=dict(r.timings or {}))
        return r

    pipe.loc.step = timed
    rows = []
    for i in range(len(rgb)):
        T_wc, est = pipe.step(np.ascontiguousarray(rgb[i][:, :, ::-1]), int(i * 1e9 / fps), depth[i], None)
        h = hashlib.sha1()
        for a in (T_wc, *pipe.observed):
            h.update(b"-" if a is None else np.ascontiguousarray(a).tobytes())
        for _, e in sorted(est.items()):
            h.update(np.asarray(e.values, np.float64).tobytes() + bytes([int(e.state)]))
        rows.append({"loc_ms": last["loc_ms"], **last["timings"], "tracker_ms": pipe.tracker_ms,
                     "digest": h.hexdigest()[:16]})
    out.write_text(json.dumps({"seed": index, "scene": name, "frames": rows}))


def summary(doc: dict, first: dict | None) -> dict:
    """Medians over the frames after the first :data:`SKIP`; the frames whose digest differs from ``first``'s."""
    fr = doc["frames"][SKIP:]

    def med(key: str) -> float:
        v = [f[key] for f in fr if key in f]
        return float(np.median(v)) if v else float("nan")

    tracking = [f["total_ms"] - f.get("mapping_ms", 0.0) - f.get("loop_ms", 0.0) for f in fr if "total_ms" in f]
    out = {"scene": doc["scene"], "frames": len(doc["frames"]), "loc_ms_p50": med("loc_ms"),
           "loc_ms_mean": float(np.mean([f["loc_ms"] for f in fr])), "extract_ms_p50": med("extract_ms"),
           "deformable_ms_p50": med("deformable_ms"), "tracking_ms_p50": float(np.median(tracking)),
           "tracker_ms_p50": med("tracker_ms")}
    if first is not None:
        out["frames_differ"] = int(sum(a["digest"] != b["digest"] for a, b in zip(first["frames"], doc["frames"]))
                                   + abs(len(first["frames"]) - len(doc["frames"])))  # a frame missing differs
    return out


def main() -> None:
    if sys.argv[1:2] == ["--worker"]:  # one run, in a fresh process (benchmarks.common.run_worker)
        worker(int(sys.argv[2]), Path(sys.argv[3]))
        return
    # here, not at the top: a worker run with an older checkout's benchmarks need not have them
    from benchmarks.common import budget_runs, checkout_notes

    args, rows = budget_runs(__doc__, ",".join(str(k) for k in range(len(SCENES))), "points_budget", Path(__file__),
                             ROOT, frames, summary)
    columns = [("scene", "scene", "{}"), ("code", "code", "{}"), ("rep", "run", "{}"), ("frames", "frames", "{}"),
               ("loc_ms_p50", "localization (ms, p50)", "{:.1f}"), ("loc_ms_mean", "mean", "{:.1f}"),
               ("extract_ms_p50", "extraction", "{:.1f}"), ("deformable_ms_p50", "deformable points", "{:.1f}"),
               ("tracking_ms_p50", "tracking less mapping", "{:.1f}"), ("tracker_ms_p50", "tracker", "{:.1f}"),
               ("frames_differ", "frames that differ", "{}")]
    notes = ("Per frame after the first twenty: medians (ms). `--seeds` are indices into the scenes (0: foam beam, "
             "1: the boot of development seed 10). Frames that differ: camera pose, observations or estimate not "
             "the scene's first run's (this checkout's) to the bit. A checkout that does not time the deformable "
             "points leaves that column empty. "
             + checkout_notes(rows, [("loc_ms_p50", "the localization's p50")], fmt="{:.1f}"))

    def plot(plt):
        fig, ax = plt.subplots(figsize=(8, 4))
        labels = [f"{r['scene']} {r['code']} {r['rep']}" for r in rows]
        ax.barh(labels, [r["loc_ms_p50"] for r in rows], label="localization step")
        ax.barh(labels, [r["deformable_ms_p50"] for r in rows], label="of it: deformable points", height=0.4)
        ax.set_xlabel("ms per frame (p50)")
        ax.legend(fontsize=7)
        ax.invert_yaxis()
        return fig

    save(args.out, rows, columns, "The map-points pipeline's localization per frame (640x480 RGB-D)", notes, plot)


if __name__ == "__main__":
    main()
