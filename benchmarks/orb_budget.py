"""ORB extraction's time per frame, split by stage (issues 17 and 18): where the SLAM's feature extraction
(``vision/orb.py:OrbExtractor``, ORB-SLAM2's distribution) spends a frame, and what a change of the code bought, on
the same frames.

    python -m benchmarks.orb_budget                        # this checkout: results/orb_budget.*
    python -m benchmarks.orb_budget --against ../other     # and another checkout (e.g. `git worktree add`)

Input: development scenes of the family (``--seeds``, default 0, 3, 12; 640 x 480 at 15 fps, 90-135 frames), their
grey frames rendered once and cached in ``cache/bench/orb_budget``. Each run extracts 1000 features (the SLAM's
budget, no focus region: the SLAM alone, as ``family_slam``) from every frame of one scene in a fresh process, its
code from one checkout; with ``--against`` the two checkouts run in pairs, back to back and their order alternating
(ABBA). Beside it, in the same process, OpenCV's own ORB (``cv2.ORB`` with the same budget, scale factor, levels and
border): the library's time for its globally ranked keypoints, a floor rather than the same output.

Stages (inclusive, ms per frame, medians over the frames): the pyramid, FAST with the per-cell fall-back
(``_candidates``), the even selection (``_grid_select``), the orientation (``ic_angle``), OpenCV's rBRIEF descriptors
(``compute``), and the rest (keypoint objects, undistortion, bookkeeping). Also per run: the frames whose features
(positions, levels, descriptors, scores) differ from the scene's first run (this checkout's): a change meant to be pure
speed must leave every one of them as it was.
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
CACHE = ROOT / "cache" / "bench" / "orb_budget"
FPS = 15.0
N_FEATURES = 1000
STAGES = ("pyramid", "fast", "selection", "orientation", "descriptors")


def frames(seed: int) -> Path:
    """The scene's grey frames (640 x 480), cached."""
    import cv2

    from benchmarks.family import scene_name
    from simreal_nodes.synth.sequence import sequence

    path = CACHE / f"family_{seed}.npz"
    if not path.exists():
        seq = sequence.__wrapped__(scene_name(seed), 640, 480, fps=FPS)
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, gray=np.array([cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in seq["rgb"]]))
    return path


def worker(seed: int, out: Path) -> None:
    """One run (in this process, with whatever ``simreal_nodes`` the path gives): per frame the stage times, the
    whole extraction's, OpenCV ORB's, and a digest of the features."""
    import cv2

    from simreal_nodes.vision import orb

    cv2.setNumThreads(1)
    spent = dict.fromkeys(STAGES, 0.0)

    def timed(name, fn):
        def wrapper(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                spent[name] += 1e3 * (time.perf_counter() - t0)
        return wrapper

    class Describer:  # OpenCV's extractor object, its compute timed
        def __init__(self, inner):
            self.inner = inner

        def compute(self, *a):
            t0 = time.perf_counter()
            try:
                return self.inner.compute(*a)
            finally:
                spent["descriptors"] += 1e3 * (time.perf_counter() - t0)

    ex = orb.OrbExtractor(N_FEATURES)
    ex.pyramid = timed("pyramid", ex.pyramid)  # type: ignore[method-assign]
    ex._candidates = timed("fast", ex._candidates)  # type: ignore[method-assign]
    ex.describer = Describer(ex.describer)
    orb._grid_select = timed("selection", orb._grid_select)
    orb.ic_angle = timed("orientation", orb.ic_angle)
    ref = cv2.ORB_create(N_FEATURES, ex.sf, ex.levels, orb.EDGE, 0, 2, cv2.ORB_FAST_SCORE,  # type: ignore[attr-defined]
                         2 * orb.RADIUS + 1, 20)
    with np.load(frames(seed)) as z:
        gray = z["gray"]
    for im in gray[:3]:  # warm the caches and OpenCV's allocations
        ex.extract(im)
        ref.detectAndCompute(im, None)
    rows = []
    for im in gray:
        for k in spent:
            spent[k] = 0.0
        t0 = time.perf_counter()
        f = ex.extract(im)
        total = 1e3 * (time.perf_counter() - t0)
        t0 = time.perf_counter()
        ref.detectAndCompute(im, None)
        opencv = 1e3 * (time.perf_counter() - t0)
        digest = hashlib.sha1()
        for a in (f.uv, f.octave, f.desc, f.response):
            digest.update(np.ascontiguousarray(a).tobytes())
        rows.append({"total": total, "opencv": opencv, **spent, "n": len(f), "digest": digest.hexdigest()})
    out.write_text(json.dumps({"seed": seed, "frames": rows}))


def summary(doc: dict, first: dict | None) -> dict:
    """Per-frame medians of the stages; the frames whose features differ from ``first``'s."""
    fr = doc["frames"]
    med = {k: float(np.median([f[k] for f in fr])) for k in (*STAGES, "total", "opencv")}
    out = {"frames": len(fr), "extract_ms_p50": med["total"],
           "extract_ms_mean": float(np.mean([f["total"] for f in fr])),
           **{f"{k}_ms_p50": med[k] for k in STAGES},
           "rest_ms_p50": float(np.median([f["total"] - sum(f[k] for k in STAGES) for f in fr])),
           "opencv_ms_p50": med["opencv"], "features": float(np.median([f["n"] for f in fr]))}
    if first is not None:
        out["frames_differ"] = int(sum(a["digest"] != b["digest"] for a, b in zip(first["frames"], fr))
                                   + abs(len(first["frames"]) - len(fr)))
    return out


def main() -> None:
    if sys.argv[1:2] == ["--worker"]:  # one run, in a fresh process (benchmarks.common.run_worker)
        worker(int(sys.argv[2]), Path(sys.argv[3]))
        return
    from benchmarks.common import budget_runs, checkout_notes

    args, rows = budget_runs(__doc__, "0,3,12", "orb_budget", Path(__file__), ROOT, frames, summary)
    columns = [("seed", "seed", "{}"), ("code", "code", "{}"), ("rep", "run", "{}"), ("frames", "frames", "{}"),
               ("features", "features (median)", "{:.0f}"),
               ("extract_ms_p50", "extraction (ms, p50)", "{:.2f}"), ("extract_ms_mean", "mean", "{:.2f}"),
               ("pyramid_ms_p50", "pyramid", "{:.2f}"), ("fast_ms_p50", "FAST + fall-back", "{:.2f}"),
               ("selection_ms_p50", "even selection", "{:.2f}"), ("orientation_ms_p50", "orientation", "{:.2f}"),
               ("descriptors_ms_p50", "descriptors (OpenCV)", "{:.2f}"), ("rest_ms_p50", "rest", "{:.2f}"),
               ("opencv_ms_p50", "OpenCV ORB alone (ms, p50)", "{:.2f}"),
               ("frames_differ", "frames whose features differ", "{}")]
    notes = (f"{N_FEATURES} features a frame, one OpenCV thread; stages: medians over the frames (ms), so they need "
             "not add up to the extraction's median. The features' difference is from the scene's first run (this "
             "checkout's). OpenCV ORB alone: `cv2.ORB` with the same budget, pyramid and border on the same frame "
             "(its keypoints ranked over the whole image, not spread per cell: a reference for the library's own "
             "cost, not the same output). "
             + checkout_notes(rows, [("extract_ms_p50", "the extraction's p50")], "{:.2f}"))

    def plot(plt):
        fig, ax = plt.subplots(figsize=(8, 4))
        stages = [("pyramid_ms_p50", "pyramid"), ("fast_ms_p50", "FAST + fall-back"),
                  ("selection_ms_p50", "even selection"), ("orientation_ms_p50", "orientation"),
                  ("descriptors_ms_p50", "descriptors (OpenCV)"), ("rest_ms_p50", "rest")]
        labels = [f"{r['seed']} {r['code']} {r['rep']}" for r in rows]
        bottom = np.zeros(len(rows))
        for key, name in stages:
            v = np.array([r[key] for r in rows])
            ax.barh(labels, v, left=bottom, label=name)
            bottom += v
        ax.plot([r["opencv_ms_p50"] for r in rows], labels, "k|", markersize=12, label="OpenCV ORB alone")
        ax.set_xlabel("ms per frame (p50 of each stage)")
        ax.legend(fontsize=7)
        ax.invert_yaxis()
        return fig

    save(args.out, rows, columns, "ORB extraction's time per frame by stage (family development scenes, 640x480)",
         notes, plot)


if __name__ == "__main__":
    main()
