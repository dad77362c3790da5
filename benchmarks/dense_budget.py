"""The dense tracker's time per frame, split by stage (issues 16 and 18): where the default measurement
(``tracking.measurements: dense``) spends a frame, and what a change of the code bought, on the same frames.

    python -m benchmarks.dense_budget                        # this checkout: results/dense_budget.*
    python -m benchmarks.dense_budget --against ../other     # and another checkout (e.g. `git worktree add`)

Input: development scenes of the family (`--seeds`, default 0, 3, 12; RGB-D at 640 x 480, 15 fps), rendered once
and cached as arrays in ``cache/bench/dense_budget``. Each run is every frame through the offline pipeline (RGB-D
SLAM, registration, the dense tracker with the scene's defaults) in a fresh process, its code from one checkout.
With ``--against``, each scene runs in pairs, the two checkouts back to back and the order alternating (ABBA), so
that a host whose speed drifts favours neither.

Stages (inclusive times inside ``DenseAligner.solve``, ms per frame where the tracker solved): the coarse search
over the loads (``_grid_start``), Gauss-Newton coarse to fine (``_fit_from`` less the search below), the
derivative-free search of the cost about its solution (``_refine``), the camera's error from the surroundings
alone (``_fit_camera``: the joint fit's check) and the rest (the zero-displacement fit that asks whether there is a
deformation at all, the covariance). The tracker column is the tracker's whole time per frame (the pipeline's
``tracker_ms``). Also per run: the largest difference of the estimates from the first checkout's, in % of each
parameter's range (a change meant to be pure speed must leave them where they were).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.common import save

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "cache" / "bench" / "dense_budget"
FPS = 15.0
STAGES = ("_grid_start", "_fit_from", "_refine", "_fit_camera", "solve")


def frames(seed: int) -> Path:
    """The scene's rendered frames (RGB, depth), cached."""
    from benchmarks.family import scene_name
    from simreal_nodes.synth.sequence import sequence

    path = CACHE / f"family_{seed}.npz"
    if not path.exists():
        seq = sequence.__wrapped__(scene_name(seed), 640, 480, fps=FPS)
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, rgb=np.array(seq["rgb"]), depth=np.array(seq["depth"], np.float32))
    return path


def scene_pipeline(seed: int):
    """Development scene ``seed``'s cached frames (RGB, depth), the offline pipeline with its scene's defaults (RGB-D
    SLAM, registration, the dense tracker) and its frame stream (the scene, its truth)."""
    import copy

    from benchmarks.family import scene_name
    from simreal_nodes.assimilation.offline import Pipeline
    from simreal_nodes.scene.schema import build_spec_models, validate_scene
    from simreal_nodes.synth.sequence import FrameStream

    with np.load(frames(seed)) as z:  # each read of a compressed member inflates it whole: once
        rgb, depth = z["rgb"], z["depth"]
    fs = FrameStream(scene_name(seed), 640, 480, None, FPS, False, 0, 2, None)
    doc = copy.deepcopy(fs.scene.scene_yaml(fs.scene))
    pipe = Pipeline(build_spec_models(validate_scene(doc, fs.scene.name, ".")), fs.cam,
                    baseline=fs.scene.stereo_baseline)
    return rgb, depth, pipe, fs


def worker(seed: int, out: Path) -> None:
    """One run (in this process, with whatever ``simreal_nodes`` the path gives): per frame the stage times, the
    tracker's time and the estimate."""
    from simreal_nodes.assimilation import dense

    spent = dict.fromkeys(STAGES, 0.0)

    def timed(name, fn):
        def wrapper(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                spent[name] += 1e3 * (time.perf_counter() - t0)
        return wrapper

    for name in STAGES:
        setattr(dense.DenseAligner, name, timed(name, getattr(dense.DenseAligner, name)))
    rgb, depth, pipe, fs = scene_pipeline(seed)
    rows = []
    for i in range(len(rgb)):
        for k in spent:
            spent[k] = 0.0
        T_wc, est = pipe.step(np.ascontiguousarray(rgb[i][:, :, ::-1]), int(i * 1e9 / FPS), depth[i], None)
        e = est["beam"]
        rows.append({"tracker_ms": pipe.tracker_ms if T_wc is not None else None, **spent,
                     "est": [float(v) for v in e.values], "state": int(e.state)})
    spans = [float(s) for s in fs.scene.state["draw"].spans]
    out.write_text(json.dumps({"seed": seed, "frames": rows, "spans": spans}))


def summary(doc: dict, first: dict | None) -> dict:
    """Per-frame medians of the stages over the frames where the tracker solved; the estimates' largest difference
    from ``first``'s (% of range)."""
    fr = [f for f in doc["frames"] if f["solve"] > 0]
    med = {k: float(np.median([f[k] for f in fr])) for k in STAGES}
    tr = [f["tracker_ms"] for f in doc["frames"] if f["tracker_ms"] is not None]
    out = {"frames_solved": len(fr), "tracker_ms_p50": float(np.median(tr)), "tracker_ms_mean": float(np.mean(tr)),
           "solve_ms_p50": med["solve"], "grid_ms_p50": med["_grid_start"],
           "gauss_newton_ms_p50": float(np.median([f["_fit_from"] - f["_refine"] for f in fr])),
           "refine_ms_p50": med["_refine"], "camera_check_ms_p50": med["_fit_camera"],
           "rest_ms_p50": float(np.median([f["solve"] - f["_grid_start"] - f["_fit_from"] - f["_fit_camera"]
                                           for f in fr]))}
    if first is not None:
        a = np.array([f["est"] for f in first["frames"]], float)
        b = np.array([f["est"] for f in doc["frames"]], float)
        span = np.asarray(doc["spans"], float)
        n = len(span)
        out["est_diff_pct"] = float(100 * np.max(np.abs(a[:, :n] - b[:, :n]) / span))
        out["states_differ"] = int(sum(x["state"] != y["state"] for x, y in zip(first["frames"], doc["frames"])))
    return out


def main() -> None:
    if sys.argv[1:2] == ["--worker"]:  # one run, in a fresh process (benchmarks.common.run_worker)
        worker(int(sys.argv[2]), Path(sys.argv[3]))
        return
    # here, not at the top: a worker run with an older checkout's benchmarks need not have them
    from benchmarks.common import budget_runs, checkout_notes

    args, rows = budget_runs(__doc__, "0,3,12", "dense_budget", Path(__file__), ROOT, frames, summary)
    columns = [("seed", "seed", "{}"), ("code", "code", "{}"), ("rep", "run", "{}"),
               ("tracker_ms_p50", "tracker (ms, p50)", "{:.0f}"), ("tracker_ms_mean", "mean", "{:.0f}"),
               ("solve_ms_p50", "solve", "{:.0f}"), ("grid_ms_p50", "coarse search", "{:.1f}"),
               ("gauss_newton_ms_p50", "Gauss-Newton", "{:.1f}"), ("refine_ms_p50", "refine", "{:.1f}"),
               ("camera_check_ms_p50", "camera check", "{:.1f}"), ("rest_ms_p50", "rest fit and other", "{:.1f}"),
               ("est_diff_pct", "estimates' largest difference (% range)", "{:.2g}"),
               ("states_differ", "frames whose state differs", "{}")]
    notes = ("Per frame where the dense tracker solved: the stages' medians (ms). The estimates' difference is "
             "from the scene's first run (this checkout's). "
             + checkout_notes(rows, [("tracker_ms_p50", "the tracker's p50")]))

    def plot(plt):
        fig, ax = plt.subplots(figsize=(8, 4))
        stages = [("grid_ms_p50", "coarse search"), ("gauss_newton_ms_p50", "Gauss-Newton"),
                  ("refine_ms_p50", "refine"), ("camera_check_ms_p50", "camera check"),
                  ("rest_ms_p50", "rest fit and other")]
        labels = [f"{r['seed']} {r['code']} {r['rep']}" for r in rows]
        bottom = np.zeros(len(rows))
        for key, name in stages:
            v = np.array([r[key] for r in rows])
            ax.barh(labels, v, left=bottom, label=name)
            bottom += v
        ax.set_xlabel("ms per frame (p50 of each stage)")
        ax.legend(fontsize=7)
        ax.invert_yaxis()
        return fig

    save(args.out, rows, columns, "The dense tracker's time per frame by stage (family development scenes, 640x480)",
         notes, plot)


if __name__ == "__main__":
    main()
