"""Live SLAM graphs: which frame a busy SLAM localization takes next (issue 20: the live latency), the newest
(``localization.live_queue`` 1) or the oldest of the five newest (5), on RGB-D SLAM scenes replayed at their 30 fps:

    ./run bench live_queue                 # development scenes, then the held-out one
    python -m benchmarks.live_queue --report

A SLAM localization slower than the camera cannot take every frame. With a queue of five it works through the oldest
frame kept, which is then about five frame periods old; with one it takes the newest. Once it is behind for good the
gaps between the frames it tracks are the same either way (they are set by its rate); the queue of five absorbs a slow
frame (a keyframe) by working off the frames kept meanwhile, at the price of the latency the overlay shows. Scenes:
the foam beam's sample (ingest -> RGB-D SLAM -> tracker on map points -> overlay; rendered by the model it fits, so
only its camera error is independent) and the family's development seed 3 (independent physics, the beam placed by
registration, the dense tracker) decide; the family's held-out seed 1000 reports. Each setting runs RUNS times per
scene, the order alternating (a live run on shared cores is not repeatable frame for frame).

Per run: frames through every node and camera poses out (% of the frames published), latency from publication to the
overlay's output (p50, p95), the camera's ATE over the frames the localization published a pose for (rigid alignment,
its own RGB-D scale), and the load's median error (% of its range) over the frames the tracker published, against the
bag's ground truth, also over those from the object's placement on (a scene that registers its object does so in a
worker, seconds into a live run; until then the estimate waits at its start value).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import RESULTS, save, saved_machine

NAME = "live_queue"
DEVELOPMENT = ("foam_beam", "family-3")
HELD_OUT = ("family-1000",)
QUEUES = (1, 5)
RUNS = 3
POSE = "/simreal/localization/pose"


def run_one(scene: str, queue: int) -> dict:
    """One live replay of ``scene``'s sample bag with the localization's ``live_queue`` at ``queue``."""
    from benchmarks.live_slam import placed_after_s
    from simreal_nodes.assimilation.evaluate import Series, compare, read_parameters
    from simreal_nodes.demo import sample_bag
    from simreal_nodes.ros.commands import replay
    from simreal_nodes.scene.schema import build_spec_models, load_scene
    from simreal_nodes.vision.trajectory import associate, ate, read_bag_poses

    bag, scene_yaml = sample_bag(scene, echo=print)
    obj = next(o for o in build_spec_models(load_scene(scene_yaml))["objects"] if o["tracking"]["enabled"])
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        stats, _, counts = replay(str(bag), str(scene_yaml), record=str(out), echo=lambda *a: None,
                                  extra_params={"localization": {"live_queue": queue}}, one_process=None)
        te, Te = read_bag_poses(out, POSE)
        tr, Tr = read_bag_poses(bag, "/ground_truth/camera_pose")
        ie, ir = associate(te, tr)
        cam = ate(np.array([Te[i][:3, 3] for i in ie]), np.array([Tr[i][:3, 3] for i in ir])) if len(ie) >= 3 \
            else {"rmse": float("nan")}
        topic = f"/simreal/objects/{obj['id']}/parameters"
        est = read_parameters(out, topic)
        truth = read_parameters(bag, f"/ground_truth/objects/{obj['id']}/parameters")
        placed = placed_after_s(out, topic, int(truth.stamps[0]))
    # errors in % of the truth's range over the whole clip, also over the frames from the object's placement on (a
    # live graph registers in a worker on the cores the SLAM uses: until then the estimate waits at its start value)
    ranges = {n: (float(np.nanmin(truth.values[:, k])), float(np.nanmax(truth.values[:, k])))
              for k, n in enumerate(truth.names)}
    first = compare(est, truth, ranges)[0]
    after = float("nan")
    if np.isfinite(placed):
        keep = est.stamps >= int(truth.stamps[0]) + round(placed * 1e9)
        if np.isin(est.stamps[keep], truth.stamps).any():
            sub = Series(est.stamps[keep], est.names, est.units, est.values[keep], est.states[keep])
            r = compare(sub, truth, ranges)[0]
            after = 100 * r.median_abs / r.span if r.span else float("nan")
    d = stats.as_dict()
    lat = d["latency_ms"].get("overlay", {"p50": float("nan"), "p95": float("nan")})
    frames = max(d["frames_published"], 1)
    return dict(scene=scene, held_out=scene in HELD_OUT, live_queue=queue,
                through_pct=100 * d["frames_completed"] / frames, poses_pct=100 * counts.get(POSE, 0) / frames,
                latency_p50=lat["p50"], latency_p95=lat["p95"], camera_ate_mm=1e3 * cam["rmse"],
                parameter=first.name, load_frames=first.n,
                load_median_pct=100 * first.median_abs / first.span if first.span else float("nan"),
                placed_s=placed, load_after_pct=after)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--report", action="store_true", help="rewrite the table and plot from the results JSON")
    ap.add_argument("--runs", type=int, default=RUNS)
    a = ap.parse_args()
    if a.report:
        report(json.loads((RESULTS / f"{NAME}.json").read_text())["rows"], saved_machine(NAME))
        return
    rows = []
    for scene in DEVELOPMENT + HELD_OUT:
        for run in range(a.runs):
            for queue in (QUEUES if run % 2 == 0 else QUEUES[::-1]):  # the order alternating
                rows.append(dict(run=run + 1, **run_one(scene, queue)))
                print(rows[-1], flush=True)
                report(rows)


def _median(rows: list[dict], key: str) -> float:
    v = [r[key] for r in rows if np.isfinite(r[key])]
    return float(np.median(v)) if v else float("nan")


def summary(rows: list[dict]) -> list[dict]:
    """Medians over the runs, per scene and queue."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for q in QUEUES:
            sel = [r for r in rows if r["scene"] == scene and r["live_queue"] == q]
            if sel:
                out.append(dict(scene=scene, held_out=sel[0]["held_out"], live_queue=q, runs=len(sel),
                                **{k: _median(sel, k) for k in ("through_pct", "poses_pct", "latency_p50",
                                                               "latency_p95", "camera_ate_mm", "load_median_pct",
                                                               "placed_s", "load_after_pct")}))
    return out


def report(rows: list[dict], extra: dict | None = None) -> None:
    med = summary(rows)

    def plot(plt):
        fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
        scenes = list(dict.fromkeys(r["scene"] for r in rows))
        for q, c in zip(QUEUES, ("tab:red", "tab:blue")):
            for k, (key, label) in enumerate((("latency_p50", "latency to the overlay, p50 (ms)"),
                                              ("camera_ate_mm", "camera ATE (mm)"),
                                              ("load_median_pct", "load median |error| (% of range)"))):
                xs = [scenes.index(r["scene"]) + (0.1 if q == 5 else -0.1) for r in rows if r["live_queue"] == q]
                ax[k].plot(xs, [r[key] for r in rows if r["live_queue"] == q], "o", color=c,
                           label=f"live_queue {q}" if k == 0 else None)
                ax[k].set_ylabel(label)
                ax[k].set_xticks(range(len(scenes)), scenes)
        ax[0].legend()
        fig.tight_layout()
        return fig

    lines = []
    for m in med:
        lines.append(f"{m['scene']}{' (held out)' if m['held_out'] else ''}, live_queue {m['live_queue']} "
                     f"({m['runs']} runs): {m['through_pct']:.0f} % of the frames through, poses for "
                     f"{m['poses_pct']:.0f} %, latency p50 {m['latency_p50']:.0f} ms (p95 {m['latency_p95']:.0f}), "
                     f"camera ATE {m['camera_ate_mm']:.2f} mm, load {m['load_median_pct']:.2f} % of its range "
                     f"({m['load_after_pct']:.2f} % from its placement on, {m['placed_s']:.1f} s after the first "
                     f"frame)")
    notes = ("`./run bench live_queue` (`benchmarks/live_queue.py`: what a run measures). Medians over the runs: "
             + "; ".join(lines) + ". Development scenes decide the default; the held-out scene reports. 2-core CPU, "
             "the launch the CLI picks (a process per node for a live SLAM graph).")
    cols = [("scene", "scene", "{}"), ("held_out", "held out", "{}"), ("live_queue", "live_queue", "{}"),
            ("run", "run", "{}"), ("through_pct", "frames through (%)", "{:.0f}"),
            ("poses_pct", "camera poses out (%)", "{:.0f}"), ("latency_p50", "latency p50 (ms)", "{:.0f}"),
            ("latency_p95", "p95 (ms)", "{:.0f}"), ("camera_ate_mm", "camera ATE (mm)", "{:.2f}"),
            ("parameter", "load parameter", "{}"), ("load_frames", "frames with an estimate", "{}"),
            ("load_median_pct", "load median error (% range)", "{:.2f}"), ("placed_s", "placed after (s)", "{:.1f}"),
            ("load_after_pct", "from the placement on (% range)", "{:.2f}")]
    save(NAME, rows, cols, "Live SLAM graphs: the newest frame next (live_queue 1) or the oldest of five (5)",
         notes=notes, plot=plot, extra={**(extra or {}), "summary": med})


if __name__ == "__main__":
    main()
