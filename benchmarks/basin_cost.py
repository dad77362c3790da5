"""What the dense fit's basin checks cost and buy (issue 16 / 20: every knob's trade measured): development beams of
the scene family, each rendered once and tracked three times, with

- ``off``: no basin check (``tracking.dense_basin_check: 0``): one fit per frame from the coarse search's winner;
- ``check``: the defaults: the runner-up from another basin fitted too where it is close (``dense_basin_check`` 0.1)
  but not the last frame's estimate (``dense_basin_warm: false``);
- ``check+warm``: a third fit from the last frame's estimate where both fits end far from it
  (``dense_basin_warm: true``, the default of stop 58).

Per run: the tracker's time per frame with a camera pose (mean, median, p95), how many frames ran the second and the
third fit and the mean time of those frames, and the load-position error over the loaded frames (median, p90, frames
called OK more than 10 % of the span off). Run it alone on the host: ``--jobs`` is not offered, since the times are
the result.

    python -m benchmarks.basin_cost --seeds 0,1,9,14,17
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.common import save
from benchmarks.family import FPS, parse_seeds, run_scene, scene_name
from simreal_nodes.states import EstimateState
from simreal_nodes.synth.sequence import sequence

CONFIGS: dict[str, dict] = {
    "off": {"dense_basin_check": 0.0},
    "check": {},
    "check+warm": {"dense_basin_warm": True},
}
SEEDS = "0,1,9,14,17"  # development seeds: two as drawn, and the three where the checks ran most (stops 57-58)


def cost_row(seed: int, config: str, row: dict, span: float) -> dict:
    """One run's times from the family row's per-frame curves, its errors from the row (the frames called OK far off
    from the curves; ``span``: the load range)."""
    c = row["curve"]
    ms = np.array([np.nan if v is None else v for v in c["ms"]])
    second = np.array([v is not None for v in c["basin"]])  # a gap is recorded where the runner-up was fitted
    third = np.array(c["warm"], bool)
    posed = np.isfinite(ms)
    truth = np.array([np.nan if v is None else v for v in c["truth"]])
    est, state = np.array(c["est"]), np.array(c["state"])
    loaded = np.isfinite(truth)
    err = 100 * np.abs(est - truth)[loaded] / span
    ok = state[loaded] == EstimateState.OK

    def mean(mask: np.ndarray) -> float:
        return float(np.mean(ms[mask & posed])) if np.any(mask & posed) else float("nan")

    return {"seed": seed, "config": config, "frames": int(posed.sum()),
            "ms_mean": mean(np.ones_like(posed)), "ms_p50": float(np.median(ms[posed])),
            "ms_p95": float(np.percentile(ms[posed], 95)),
            "second_fits": int((second & posed).sum()), "ms_second": mean(second),
            "ms_without": mean(~second), "third_fits": int((third & posed).sum()), "ms_third": mean(third),
            "median_err_pct": row["median_err_pct"], "p90_err_pct": row["p90_err_pct"],  # the family's own
            "ok_far": int(np.sum(ok & (err > 10)))}


COLUMNS = [("seed", "seed", "{}"), ("config", "checks", "{}"), ("frames", "frames with a pose", "{}"),
           ("ms_mean", "tracker mean (ms)", "{:.0f}"), ("ms_p50", "p50 (ms)", "{:.0f}"),
           ("ms_p95", "p95 (ms)", "{:.0f}"),
           ("second_fits", "frames with a 2nd fit", "{}"), ("ms_second", "their mean (ms)", "{:.0f}"),
           ("ms_without", "the others' mean (ms)", "{:.0f}"), ("third_fits", "frames with a 3rd fit", "{}"),
           ("ms_third", "their mean (ms)", "{:.0f}"), ("median_err_pct", "median error (% span)", "{:.2f}"),
           ("p90_err_pct", "p90 (%)", "{:.2f}"), ("ok_far", "OK frames > 10 % off", "{}")]


def _plot(plt, rows: list[dict]):
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
    seeds = sorted({r["seed"] for r in rows})
    x = np.arange(len(seeds))
    for k, cfg in enumerate(CONFIGS):
        rs = {r["seed"]: r for r in rows if r["config"] == cfg}
        a.bar(x + (k - 1) * 0.27, [rs[s]["ms_mean"] for s in seeds], 0.27, label=cfg)
        b.bar(x + (k - 1) * 0.27, [rs[s]["p90_err_pct"] for s in seeds], 0.27, label=cfg)
    for ax, lab in ((a, "tracker time per frame, mean (ms)"), (b, "load-position error p90 (% of span)")):
        ax.set_xticks(x, [str(s) for s in seeds])
        ax.set_xlabel("development seed")
        ax.set_ylabel(lab)
    b.set_yscale("log")
    a.legend(fontsize=8)
    fig.tight_layout()
    return fig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default=SEEDS)
    a = ap.parse_args()
    seeds = parse_seeds(a.seeds)
    assert all(s < 50 for s in seeds), "development seeds only (0-49)"
    rows: list[dict] = []
    for seed in seeds:
        seq = sequence.__wrapped__(scene_name(seed), 640, 480, fps=FPS)
        for cfg, knobs in CONFIGS.items():
            rows.append(cost_row(seed, cfg, run_scene(seed, tracking=knobs, seq=seq), seq["scene"].state["draw"].span))
            print(rows[-1], flush=True)
    tot = {cfg: [r for r in rows if r["config"] == cfg] for cfg in CONFIGS}
    summary = "; ".join(f"{cfg}: {np.mean([r['ms_mean'] for r in rs]):.0f} ms" for cfg, rs in tot.items())
    save("basin_cost", rows, COLUMNS, "Dense fit: what the basin checks cost and buy (development beams)",
         "`python -m benchmarks.basin_cost` (see its docstring): each scene rendered once, tracked with no basin "
         "check, with the runner-up's fit (the defaults), and with the last frame's estimate fitted too where both "
         "fits end far from it. Tracker time per frame with a camera pose (the deformable tracking work of the "
         "offline pipeline). Mean over the scenes of the per-scene mean time: " + summary + ".",
         lambda plt: _plot(plt, rows))


if __name__ == "__main__":
    main()
