"""Live replay of a SLAM scene (the joint boot: RGB-D localization -> tracker -> overlay) at the bag's 30 fps:
which frames a busy SLAM localization takes, the newest (``live_queue`` 1) or the oldest of the five newest
(5, the default), and what that does to the lever angle and the latency. Several runs per setting: a live run
on shared cores is not repeatable frame for frame.

    ./run bench live_slam
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import save
from simreal_nodes.assimilation.evaluate import compare, read_parameters
from simreal_nodes.demo import model_ranges, sample_bag
from simreal_nodes.ros.commands import replay
from simreal_nodes.scene.schema import build_spec_models, load_scene

RUNS = 4


def main():
    bag, scene_yaml = sample_bag("joint_boot", echo=print)
    obj = next(o for o in build_spec_models(load_scene(scene_yaml))["objects"] if o["tracking"]["enabled"])
    ranges = model_ranges(obj["model"])
    truth = read_parameters(bag, f"/ground_truth/objects/{obj['id']}/parameters")
    rows = []
    for queue in (1, 5):
        for run in range(RUNS):
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "run"
                stats, _, _ = replay(str(bag), str(scene_yaml), record=str(out), echo=lambda *a: None,
                                     extra_params={"localization": {"live_queue": queue}})
                est = read_parameters(out, f"/simreal/objects/{obj['id']}/parameters")
            rep = {r.name: r for r in compare(est, truth, ranges)}
            d = stats.as_dict()
            lat = d["latency_ms"].get("overlay", {"p50": float("nan"), "p95": float("nan")})
            theta = rep["theta"]
            lost = int(np.sum(np.asarray(est.states) == 2))  # ModelParameters state 2: lost
            row = dict(live_queue=queue, run=run + 1, frames=theta.n, theta_median_deg=np.degrees(theta.median_abs),
                       alpha_median_deg=np.degrees(rep["alpha_z"].median_abs) if "alpha_z" in rep else float("nan"),
                       lost_frames=lost, tracked=bool(np.degrees(theta.median_abs) < 2.0),
                       fps_through=d["fps_through"], latency_p50=lat["p50"], latency_p95=lat["p95"])
            rows.append(row)
            print(row, flush=True)
    report(rows)


def report(rows, machine: dict | None = None):
    """The table and plot of ``rows``; ``machine``: the run's own (``--report`` keeps it), else this one's."""
    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        for q, c in ((1, "tab:red"), (5, "tab:blue")):
            sel = [r for r in rows if r["live_queue"] == q]
            ax[0].plot([r["run"] for r in sel], [r["theta_median_deg"] for r in sel], "o-", color=c,
                       label=f"live_queue {q}")
            ax[1].plot([r["run"] for r in sel], [r["latency_p50"] for r in sel], "o-", color=c, label=f"live_queue {q}")
        ax[0].set_yscale("log")
        ax[0].set_ylabel("theta median |error| (deg)")
        ax[1].set_ylabel("latency to the overlay, p50 (ms)")
        for a in ax:
            a.set_xlabel("run")
            a.legend()
        fig.tight_layout()
        return fig

    n = {q: sum(1 for r in rows if r["live_queue"] == q) for q in (1, 5)}
    ok = {q: sum(r["tracked"] for r in rows if r["live_queue"] == q) for q in (1, 5)}
    # within every target: theta within 0.5 deg and alpha_z within 1 deg at the median (the boot's targets)
    good = {q: sum(r["theta_median_deg"] <= 0.5 and r["alpha_median_deg"] <= 1.0 for r in rows
                   if r["live_queue"] == q) for q in (1, 5)}
    fps = float(np.median([r["fps_through"] for r in rows]))
    save("live_slam", rows, [("live_queue", "live_queue", "{}"), ("run", "run", "{}"),
                             ("frames", "frames estimated", "{}"),
                             ("theta_median_deg", "theta median err (deg)", "{:.2f}"),
                             ("alpha_median_deg", "alpha_z median err (deg)", "{:.2f}"),
                             ("lost_frames", "frames lost", "{}"), ("fps_through", "fps through", "{:.1f}"),
                             ("latency_p50", "latency p50 (ms)", "{:.0f}"), ("latency_p95", "p95 (ms)", "{:.0f}")],
         "Live SLAM scene: which frames a busy localization takes (joint boot, 640x480, 30 fps, RGB-D)",
         f"Runs that kept tracking (theta median error < 2 deg): live_queue 1: {ok[1]} of {n[1]}, live_queue 5: "
         f"{ok[5]} of {n[5]}. Runs within every target (theta <= 0.5 deg and alpha_z <= 1 deg at the median): "
         f"live_queue 1: {good[1]} of {n[1]}, live_queue 5: {good[5]} of {n[5]}. The graph takes {fps:.0f} of the "
         "30 frames a second through at the median on these 2 shared cores. Newest-first, the gap between the "
         "frames it tracks varies; after a long gap during the lever's fast turn the object's tracks can be lost. "
         "The oldest of the five newest keeps the gaps even at the cost of ~100 ms more latency. The scene is rendered "
         "by the model the tracker fits, its pose given (a demo scene: zero model error). Lossless (every frame, "
         "offline): `benchmarks/results/tracking_scenes.md`, the boot rows; `tests/assimilation/test_tracker.py` "
         "prints the same scene's figures on the current code. Stop 86's run failed in 8 of 8: an asynchronous local "
         "BA's result erased the lever's points flagged deforming while it ran, and the standbys' imports fell in "
         "the bag's first seconds; stop 87 mended both (README).", plot,
         extra={"machine": machine} if machine else None)


if __name__ == "__main__":
    import sys

    if sys.argv[1:] == ["--report"]:  # re-write the table and plot from the last results
        import json

        from benchmarks.common import RESULTS

        last = json.loads((RESULTS / "live_slam.json").read_text())
        report(last["rows"], last["machine"])
    else:
        main()
