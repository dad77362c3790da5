"""The joint boot's tracker time per frame, split by stage (issues 16 and 18): where the sparse tracker with the state
read from every depth image (``tracking.depth_fit``, set by the boot's scene files) spends a frame, and what a change
of the code bought, on the same frames.

    python -m benchmarks.depth_budget                        # this checkout: results/depth_budget.*
    python -m benchmarks.depth_budget --against ../other     # and another checkout (e.g. `git worktree add`)

Input: development scenes of the boot family (``--seeds``, default 0, 8, 22; RGB-D at 640 x 480, 15 fps), rendered
once and cached as arrays in ``cache/bench/depth_budget``. Each run is every frame through the offline pipeline
(RGB-D SLAM, registration, the tracker with the scene file's settings) in a fresh process, its code from one
checkout. With ``--against``, each scene runs in pairs, the two checkouts back to back and the order alternating
(ABBA), so that a host whose speed drifts favours neither (:func:`benchmarks.common.pair_ratios`).

Stages (inclusive times, ms per frame where the tracker ran, medians over those frames): the depth fit
(``DepthFollower.fit``), of it the search for each depth point's nearest model sample (``_Problem._nearest``) and the
residuals with their Jacobians less that search (``_Problem.residuals``); the links of map points to the model
(``link_points``, outside the search below); the search of alpha_z over its range (``_constant_search``, on the few
frames until the turn is first seen, so its median is usually 0 and its mean is given; it links the points anew for
each value it tries). The tracker column is the tracker's whole time per frame (the pipeline's ``tracker_ms``), the
next its CPU time (the objects' update on its thread's clock, which a busy host stretches less than the wall time);
its slowest frame is given apart (on these scenes the registration's: the object placed, ``anchor: registration``, and
its state read from the depth, ``tracking.reference: depth``, before any tracking). Also per run: the lever angle's
median error against the truth (% of its 52 degree range) and the largest difference of the estimates from the scene's
first run, in % of the range (a change meant to be pure speed must leave them where they were).
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks.common import save
from benchmarks.family_boot import AT_REST_RAD
from simreal_nodes.synth.boot_family import THETA_RANGE_DEG

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "cache" / "bench" / "depth_budget"
FPS = 15.0
OID = "boot"
# (class path, method, stage name, counted only inside this stage, counted only outside this stage): inclusive
# times. The search of alpha_z links the map points anew for each value it tries, so links inside it are its own
STAGES = (("simreal_nodes.assimilation.depth_state:DepthFollower", "fit", "depth_fit", None, None),
          ("simreal_nodes.assimilation.depth_state:_Problem", "_nearest", "nearest", "depth_fit", None),
          ("simreal_nodes.assimilation.depth_state:_Problem", "residuals", "residuals", "depth_fit", None),
          ("simreal_nodes.assimilation.tracker:DeformableTracker", "link_points", "links", None, "constant_search"),
          ("simreal_nodes.assimilation.tracker:DeformableTracker", "_constant_search", "constant_search", None, None))


def scene(seed: int) -> str:
    return f"family-boot-{seed}"


def frames(seed: int) -> Path:
    """The scene's rendered frames (RGB, depth) and the true lever angle per frame, cached."""
    from simreal_nodes.synth.sequence import FrameStream

    path = CACHE / f"boot_{seed}.npz"
    if not path.exists():
        rgb, depth, theta = [], [], []
        for f in FrameStream(scene(seed), 640, 480, None, FPS, False, 0, 2, None):
            rgb.append(f["rgb"])
            depth.append(np.asarray(f["depth"], np.float32))
            theta.append(float(f["truth"].params[OID][2][0]))
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, rgb=np.array(rgb), depth=np.array(depth), theta=np.array(theta))
    return path


def timed(spent: dict[str, float], active: dict[str, int], name: str, inside: str | None, outside: str | None,
          fn: Callable) -> Callable:
    """``fn`` with its time (ms) added to ``spent[name]`` where it runs inside a call of stage ``inside`` (None: any)
    and outside any of stage ``outside`` (None: any), and not inside a call of itself; ``active`` counts the calls of
    each stage under way."""
    def wrapper(*a, **k):
        counted = ((inside is None or active[inside] > 0) and (outside is None or active[outside] == 0)
                   and active[name] == 0)
        active[name] += 1
        t0 = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            active[name] -= 1
            if counted:
                spent[name] += 1e3 * (time.perf_counter() - t0)
    return wrapper


def worker(seed: int, out: Path) -> None:
    """One run (in this process, with whatever ``simreal_nodes`` the path gives): per frame the stage times, the
    tracker's time and the estimate."""
    import copy
    import importlib

    from simreal_nodes.assimilation.offline import Pipeline
    from simreal_nodes.scene.schema import build_spec_models, validate_scene
    from simreal_nodes.synth.sequence import FrameStream

    spent = {name: 0.0 for _, _, name, _, _ in STAGES}
    active = dict.fromkeys(spent, 0)
    for where, method, name, inside, outside in STAGES:
        mod, _, cls_name = where.partition(":")
        cls = getattr(importlib.import_module(mod), cls_name)
        setattr(cls, method, timed(spent, active, name, inside, outside, getattr(cls, method)))
    # the objects' update on this thread's CPU clock as well: a host whose load varies stretches the wall time of a
    # run, less its CPU time (the SLAM's mapping runs in another thread, not counted)
    from simreal_nodes.assimilation.objects import ObjectTrackers

    cpu = {"ms": 0.0}
    update = ObjectTrackers.update

    def cpu_timed(*a, **k):
        t0 = time.thread_time()
        try:
            return update(*a, **k)
        finally:
            cpu["ms"] += 1e3 * (time.thread_time() - t0)

    ObjectTrackers.update = cpu_timed
    with np.load(frames(seed)) as z:  # each read of a compressed member inflates it whole: once
        rgb, depth, theta = z["rgb"], z["depth"], z["theta"]
    fs = FrameStream(scene(seed), 640, 480, None, FPS, False, 0, 2, None)
    doc = copy.deepcopy(fs.scene.scene_yaml(fs.scene))
    pipe = Pipeline(build_spec_models(validate_scene(doc, fs.scene.name, ".")), fs.cam)
    rows = []
    for i in range(len(rgb)):
        for k in spent:
            spent[k] = 0.0
        cpu["ms"] = 0.0
        T_wc, est = pipe.step(np.ascontiguousarray(rgb[i][:, :, ::-1]), int(i * 1e9 / FPS), depth[i], None)
        e = est[OID]
        rows.append({"tracker_ms": pipe.tracker_ms if T_wc is not None else None, "cpu_ms": cpu["ms"], **spent,
                     "est": [float(v) for v in e.values], "state": int(e.state), "theta": float(theta[i])})
    names = list(pipe.trackers[OID].names)
    lo, hi = pipe.trackers[OID].lo, pipe.trackers[OID].hi
    spans = [float(h - lo_) for lo_, h in zip(lo, hi, strict=True)]
    out.write_text(json.dumps({"seed": seed, "frames": rows, "spans": spans, "names": names}))


def summary(doc: dict, first: dict | None) -> dict:
    """Per-frame medians of the stages over the frames where the tracker ran; the lever's error against the truth;
    the estimates' largest difference from ``first``'s (% of range)."""
    fr = [f for f in doc["frames"] if f["tracker_ms"] is not None]

    def med(fn) -> float:
        return float(np.median([fn(f) for f in fr])) if fr else float("nan")

    tr = [f["tracker_ms"] for f in fr]
    loaded = [f for f in doc["frames"] if f["theta"] > AT_REST_RAD]  # the family's scored frames
    err = [100 * abs(np.rad2deg(f["est"][0] - f["theta"])) / THETA_RANGE_DEG for f in loaded]
    out = {"frames_tracked": len(fr), "tracker_ms_p50": med(lambda f: f["tracker_ms"]),
           "tracker_ms_mean": float(np.mean(tr)) if tr else float("nan"),
           "cpu_ms_p50": med(lambda f: f["cpu_ms"]),
           "slowest_ms": float(np.max(tr)) if tr else float("nan"),
           "depth_fit_ms_p50": med(lambda f: f["depth_fit"]), "nearest_ms_p50": med(lambda f: f["nearest"]),
           "residuals_ms_p50": med(lambda f: f["residuals"] - f["nearest"]),
           "links_ms_p50": med(lambda f: f["links"]),
           "constant_search_ms_mean": float(np.mean([f["constant_search"] for f in fr])) if fr else float("nan"),
           "other_ms_p50": med(lambda f: f["tracker_ms"] - f["depth_fit"] - f["links"] - f["constant_search"]),
           "theta_err_pct_p50": float(np.median(err)) if err else float("nan")}
    if first is not None:
        a = np.array([f["est"] for f in first["frames"]], float)
        b = np.array([f["est"] for f in doc["frames"]], float)
        span = np.asarray(doc["spans"], float)
        out["est_diff_pct"] = float(100 * np.max(np.abs(a - b) / span))
        out["states_differ"] = int(sum(x["state"] != y["state"] for x, y in zip(first["frames"], doc["frames"])))
    return out


def main() -> None:
    if sys.argv[1:2] == ["--worker"]:  # one run, in a fresh process (benchmarks.common.run_worker)
        worker(int(sys.argv[2]), Path(sys.argv[3]))
        return
    # here, not at the top: a worker run with an older checkout's benchmarks need not have them
    from benchmarks.common import budget_runs, checkout_notes

    args, rows = budget_runs(__doc__, "0,8,22", "depth_budget", Path(__file__), ROOT, frames, summary)
    columns = [("seed", "seed", "{}"), ("code", "code", "{}"), ("rep", "run", "{}"),
               ("tracker_ms_p50", "tracker (ms, p50)", "{:.0f}"), ("tracker_ms_mean", "mean", "{:.0f}"),
               ("cpu_ms_p50", "its CPU (ms, p50)", "{:.0f}"),
               ("slowest_ms", "slowest frame", "{:.0f}"),
               ("depth_fit_ms_p50", "depth fit", "{:.1f}"), ("nearest_ms_p50", "of it: nearest samples", "{:.1f}"),
               ("residuals_ms_p50", "residuals, Jacobians", "{:.1f}"), ("links_ms_p50", "links", "{:.1f}"),
               ("constant_search_ms_mean", "alpha_z search (mean)", "{:.1f}"),
               ("other_ms_p50", "other", "{:.1f}"), ("theta_err_pct_p50", "lever error (% range, p50)", "{:.2f}"),
               ("est_diff_pct", "estimates' largest difference (% range)", "{:.2g}"),
               ("states_differ", "frames whose state differs", "{}")]
    notes = ("Per frame where the tracker ran: the stages' medians (ms). The estimates' difference is from the "
             "scene's first run (this checkout's). " + checkout_notes(rows, [("tracker_ms_p50", "the tracker's p50"),
                                                                            ("cpu_ms_p50", "its CPU time's p50")]))

    def plot(plt):
        fig, ax = plt.subplots(figsize=(8, 4))
        stages = [("nearest_ms_p50", "nearest samples"), ("residuals_ms_p50", "residuals, Jacobians"),
                  ("links_ms_p50", "links"), ("other_ms_p50", "other")]
        labels = [f"{r['seed']}/{r['rep']}\n{r['code'].split('(')[-1].rstrip(')')}" for r in rows]
        bottom = np.zeros(len(rows))
        for key, name in stages:
            v = np.array([max(r[key], 0.0) for r in rows])
            ax.bar(range(len(rows)), v, bottom=bottom, label=name)
            bottom += v
        ax.set_xticks(range(len(rows)), labels, fontsize=6)
        ax.set_ylabel("ms per frame (p50 of each stage)")
        ax.legend(fontsize=7)
        fig.tight_layout()
        return fig

    save(args.out, rows, columns, "The joint boot's tracker (map points + depth fit): time per frame by stage",
         notes=notes, plot=plot)


if __name__ == "__main__":
    main()
