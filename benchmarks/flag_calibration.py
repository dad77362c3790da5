"""Where the two low-confidence flags of issue 20's camera sweep were set (development seeds only):

- ``--registration``: the registration step alone on development scenes of the family, as drawn and with the
  camera at 0.5 and 0.7 m: its error and the share of the beam's length it could slide at about the same cover
  (:func:`~simreal_nodes.assimilation.registration.slide_share`; doubted past ``max_slide_share``);
- ``--camera``: per frame of development scenes (6 s each, as drawn and from other views), the gap between the
  dense fit's camera correction and the one the static surroundings alone give, in prior sigmas
  (``camera_gap_sigma``; flagged past ``DenseSettings.max_camera_gap``), beside the frame's load error;
- ``--gain``: per loaded frame of development scenes, the dense fit's brightness gain (the share of the reference's
  texture contrast the image shows where the fit put the samples; flagged under ``DenseSettings.min_gain``) beside
  the frame's load error: the frames of the development family's results (``--runs``, the per-frame curves of
  ``python -m benchmarks.family --seeds 0-19``) and of the views of ``--plan`` run here (a view may add ``+noiseN``
  or ``+blurN``: benchmarks/camera_quality.py's degradations).

    ./run bench flag_calibration                      # all three, on the sets the thresholds were chosen on
    python -m benchmarks.flag_calibration --registration --plan "1:-d0.5"   # one registration
    python -m benchmarks.flag_calibration --camera --plan "1:-el5"          # one scene's frames
    python -m benchmarks.flag_calibration --gain --plan "0:-az65-arc20,1:+noise16"

A plan is comma-separated SEED:SUFFIX (scene-name suffixes of the family: '' as drawn, -d0.5 the camera at 0.5 m,
-el5 at 5 degrees of elevation).
"""

from __future__ import annotations

import argparse
import copy
import json

import numpy as np

from benchmarks.common import RESULTS, save
from benchmarks.family import FPS, _depth_or_pair, run_registration, scene_name
from simreal_nodes.assimilation.dense import DenseSettings
from simreal_nodes.assimilation.offline import Pipeline
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.states import EstimateState
from simreal_nodes.synth.sequence import sequence

DURATION = 6.0  # seconds per scene in the camera sweep (as benchmarks/camera_quality.py)
# the sets the thresholds were chosen on (stop 35): seeds 0-29 as drawn, seeds 0-9 from 0.5 m and 0.7 m; seeds 0-5
# as drawn and five other views of seeds 0 and 1
REGISTRATION_PLAN = ",".join([f"{s}:" for s in range(30)] + [f"{s}:{v}" for v in ("-d0.5", "-d0.7") for s in range(10)])
CAMERA_PLAN = "0:,1:,2:,3:,4:,5:,0:-d2,0:-el65,1:-d2,1:-el5,1:-el80"
# stop 48: the camera sweep's views of seeds 0 and 1 (benchmarks/camera_quality.py) beside the family's development
# beams 0-19 (their results' per-frame curves)
GAIN_PLAN = ",".join(f"{s}:{v}" for s in (0, 1) for v in ("-az45-arc20", "-az65-arc20", "-az80-arc20", "-el5", "-el80",
                                                            "-d0.5", "-d2", "+noise16", "+blur4"))
GAIN_RUNS = "family_dev_0_19"
GAIN_LEVELS = (0.3, 0.5, 0.7)  # the thresholds the table counts at


def parse_plan(plan: str) -> list[tuple[int, str]]:
    out = [(int(x.split(":")[0]), x.split(":", 1)[1]) for x in plan.split(",") if x]
    assert all(s < 50 for s, _ in out), "development seeds only (0-49)"
    return out


def registration_rows(specs: list[tuple[int, str]]) -> list[dict]:
    rows = []
    for seed, view in specs:
        r = run_registration(seed, view=view)
        rows.append({"seed": seed, "view": view or "as drawn", "length_mm": r["length_mm"],
                     "registration_mm": r["registration_mm"], "slide_spread_mm": r["slide_spread_mm"],
                     "slide_share_pct": 100 * r["slide_spread_mm"] / r["length_mm"],
                     "doubt": r["registration_doubt"], "reason": r["reason"]})
        print(rows[-1], flush=True)
    return rows


def _view_frames(seq: dict):
    """Each frame of a rendered view through the offline pipeline: (the beam's estimate, the true load position,
    the span it is measured against)."""
    sc = seq["scene"]
    span = sc.state["draw"].span
    scene = build_spec_models(validate_scene(copy.deepcopy(sc.scene_yaml(sc)), sc.name, "."))
    pipe = Pipeline(scene, seq["cam"], baseline=sc.stereo_baseline)
    for i in range(len(seq["rgb"])):
        _, out = pipe.step(np.ascontiguousarray(seq["rgb"][i][:, :, ::-1]), int(i * 1e9 / FPS),
                           *_depth_or_pair(seq, i))
        yield out["beam"], seq["truth"][i].params["beam"][2][0], span


def camera_rows(specs: list[tuple[int, str]]) -> list[dict]:
    rows = []
    for seed, view in specs:
        seq = sequence.__wrapped__(scene_name(seed) + view, 640, 480, duration=DURATION, fps=FPS)
        gaps, errs = [], []
        for e, truth, span in _view_frames(seq):
            gap = float(e.debug.get("camera_gap_sigma", np.nan))
            if np.isfinite(truth) and np.isfinite(gap):
                gaps.append(gap)
                errs.append(100 * abs(float(e.values[0]) - truth) / span)
        g, err = np.array(gaps), np.array(errs)
        rows.append({"seed": seed, "view": view or "as drawn", "frames": len(g),
                     "gap_median": float(np.median(g)), "gap_p90": float(np.percentile(g, 90)),
                     "gap_max": float(g.max()), "err_median_pct": float(np.median(err)),
                     "frames_over_2pct": int((err > 2).sum()), "caught_over_1": int(((err > 2) & (g > 1)).sum()),
                     "good_over_1": int(((err <= 2) & (g > 1)).sum())})
        print(rows[-1], flush=True)
    return rows


def gain_row(seed: int, view: str, gains: list, errs: list, states: list) -> dict:
    """One scene's loaded frames with a dense fit: the gain's distribution, the frames more than 2 % of the span
    off and how many of them (and of the others) each of :data:`GAIN_LEVELS` flags."""
    g, err, st = np.array(gains, float), np.array(errs, float), np.array(states)
    bad = err > 2.0
    row = {"seed": seed, "view": view, "frames": len(g), "ok_frames": int((st == int(EstimateState.OK)).sum()),
           "gain_min": float(g.min()) if len(g) else float("nan"),
           "gain_p10": float(np.percentile(g, 10)) if len(g) else float("nan"),
           "gain_median": float(np.median(g)) if len(g) else float("nan"),
           "err_median_pct": float(np.median(err)) if len(g) else float("nan"), "frames_over_2pct": int(bad.sum()),
           "gains": [round(float(v), 4) for v in g], "errs": [round(float(v), 4) for v in err]}
    for t in GAIN_LEVELS:
        row[f"caught_{t:g}"] = int((bad & (g < t)).sum())
        row[f"good_{t:g}"] = int((~bad & (g < t)).sum())
    return row


def gain_rows_from_runs(name: str) -> list[dict]:
    """The per-frame curves of a family results file (benchmarks/family.py): gain, state, truth and estimate."""
    from simreal_nodes.synth.family import draw, draw_plate

    doc = json.loads((RESULTS / f"{name}.json").read_text())
    assert all(r["seed"] < 50 for r in doc["rows"]), "development seeds only (0-49)"
    rows = []
    for r in doc["rows"]:
        c = doc["curves"][str(r["seed"])]
        if "gain" not in c:
            raise SystemExit(f"{name} has no per-frame gain (rerun it with the current benchmarks/family.py)")
        spans = (draw_plate if r["object"] == "plate" else draw)(r["seed"]).spans
        gains, errs, states = [], [], []
        for i, (t, e, g) in enumerate(zip(c["truth"], c["est"], c["gain"])):
            if t is None or g is None:
                continue
            err = 100 * abs(e - t) / spans[0]
            if "truth_y" in c and c["truth_y"][i] is not None:  # a plate: the larger of its two axes' errors
                ey = 100 * abs(c["est_y"][i] - c["truth_y"][i]) / spans[1]
                err = max(err, ey) if np.isfinite(ey) else float("inf")
            gains.append(g)
            errs.append(err)
            states.append(c["state"][i])
        rows.append(gain_row(r["seed"], f"{name} ({r['object']})", gains, errs, states))
        print({k: v for k, v in rows[-1].items() if k not in ("gains", "errs")}, flush=True)
    return rows


def gain_rows(specs: list[tuple[int, str]]) -> list[dict]:
    from benchmarks.camera_quality import made_worse

    rows = []
    for seed, view in specs:
        name, _, worse = view.partition("+")
        seq = sequence.__wrapped__(scene_name(seed) + name, 640, 480, duration=DURATION, fps=FPS)
        if worse:
            kind = worse.rstrip("0123456789.")
            seq = made_worse(seq, kind, float(worse[len(kind):]), seed)
        gains, errs, states = [], [], []
        for e, truth, span in _view_frames(seq):
            gain = float(e.debug.get("gain", np.nan))
            if np.isfinite(truth) and np.isfinite(gain):
                gains.append(gain)
                errs.append(100 * abs(float(e.values[0]) - truth) / span)
                states.append(int(e.state))
        rows.append(gain_row(seed, view or "as drawn", gains, errs, states))
        print({k: v for k, v in rows[-1].items() if k not in ("gains", "errs")}, flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--registration", action="store_true")
    ap.add_argument("--camera", action="store_true")
    ap.add_argument("--gain", action="store_true")
    ap.add_argument("--plan", help="SEED:SUFFIX,... (default: the set each threshold was chosen on)")
    ap.add_argument("--runs", default=GAIN_RUNS, help="--gain: family results (development seeds) whose frames join")
    a = ap.parse_args()
    if not (a.registration or a.camera or a.gain):
        a.registration = a.camera = a.gain = True
    if a.registration:
        rows = registration_rows(parse_plan(a.plan or REGISTRATION_PLAN))
        save("flag_calibration_registration", rows,
             [("seed", "seed", "{}"), ("view", "view", "{}"), ("length_mm", "length (mm)", "{}"),
              ("registration_mm", "registration error (mm)", "{:.1f}"),
              ("slide_spread_mm", "slide spread (mm)", "{:.0f}"), ("slide_share_pct", "share of length (%)",
                                                                    "{:.1f}"),
              ("doubt", "doubt", "{}"), ("reason", "not placed because", "{}")],
             "Registration: how far a fit can slide along the beam (development seeds)",
             "`python -m benchmarks.flag_calibration --registration` (see its docstring). A fit is doubted past "
             "RegistrationConfig.max_slide_share of its length.",
             lambda plt: _plot_share(plt, rows))
    if a.camera:
        rows = camera_rows(parse_plan(a.plan or CAMERA_PLAN))
        save("flag_calibration_camera", rows,
             [("seed", "seed", "{}"), ("view", "view", "{}"), ("frames", "loaded frames", "{}"),
              ("gap_median", "gap median (sigma)", "{:.2f}"), ("gap_p90", "p90", "{:.2f}"),
              ("gap_max", "max", "{:.2f}"), ("err_median_pct", "load error median (% span)", "{:.2f}"),
              ("frames_over_2pct", "frames > 2 % off", "{}"), ("caught_over_1", "of those, gap > 1", "{}"),
              ("good_over_1", "frames <= 2 % with gap > 1", "{}")],
             "Dense fit: the camera's gap to the surroundings alone, per frame (development seeds)",
             "`python -m benchmarks.flag_calibration --camera` (see its docstring). A frame is flagged past "
             "DenseSettings.max_camera_gap sigma.", lambda plt: _plot_gap(plt, rows))
    if a.gain:
        rows = [] if a.runs in ("", "none") else [r for n in a.runs.split(",") for r in gain_rows_from_runs(n)]
        rows += gain_rows(parse_plan(a.plan or GAIN_PLAN))
        cols = [("seed", "seed", "{}"), ("view", "view", "{}"), ("frames", "loaded frames fitted", "{}"),
                ("ok_frames", "OK", "{}"), ("gain_min", "gain min", "{:.2f}"), ("gain_p10", "p10", "{:.2f}"),
                ("gain_median", "median", "{:.2f}"), ("err_median_pct", "load error median (% span)", "{:.2f}"),
                ("frames_over_2pct", "frames > 2 % off", "{}")]
        for t in GAIN_LEVELS:
            cols += [(f"caught_{t:g}", f"of those, gain < {t:g}", "{}"),
                     (f"good_{t:g}", f"frames <= 2 % with gain < {t:g}", "{}")]
        tot = {k: sum(r[k] for r in rows) for k in ["frames", "frames_over_2pct"]
               + [f"{p}_{t:g}" for t in GAIN_LEVELS for p in ("caught", "good")]}
        save("flag_calibration_gain", [{k: v for k, v in r.items() if k not in ("gains", "errs")} for r in rows]
             + [{"seed": "all", "view": "", "ok_frames": sum(r["ok_frames"] for r in rows), "gain_min": float("nan"),
                 "gain_p10": float("nan"), "gain_median": float("nan"), "err_median_pct": float("nan"), **tot}],
             cols, "Dense fit: the brightness gain per frame against the load error (development seeds)",
             "`python -m benchmarks.flag_calibration --gain` (see its docstring). A frame is flagged under "
             "DenseSettings.min_gain. The frames are every loaded frame with a dense fit, whatever the tracker "
             "called it (a frame flagged for another reason counts too). Views of the camera sweep are 6 s long.",
             lambda plt: _plot_gains(plt, rows), extra={"frames": {f"{r['seed']}:{r['view']}": [r["gains"], r["errs"]]
                                                                 for r in rows}})


def _plot_gains(plt, rows: list[dict]):
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    g = np.concatenate([r["gains"] for r in rows])
    e = np.concatenate([r["errs"] for r in rows])
    ax.plot(np.clip(g, -0.2, 1.5), np.clip(e, 1e-3, 100), ".", ms=2, alpha=0.5)
    ax.axvline(DenseSettings().min_gain, color="grey", lw=0.8)
    ax.axhline(2.0, color="grey", lw=0.5, ls=":")
    ax.set_yscale("log")
    ax.set_xlabel("dense fit's brightness gain (clipped to -0.2..1.5)")
    ax.set_ylabel("load error (% span)")
    fig.tight_layout()
    return fig


def _plot_share(plt, rows: list[dict]):
    fig, ax = plt.subplots(figsize=(5, 3.4))
    x = [r["slide_share_pct"] for r in rows]
    y = [r["registration_mm"] for r in rows]
    ax.plot(x, y, "o")
    ax.set_xlabel("slide spread, % of the beam's length")
    ax.set_ylabel("registration error (mm)")
    ax.set_yscale("log")
    fig.tight_layout()
    return fig


def _plot_gap(plt, rows: list[dict]):
    fig, ax = plt.subplots(figsize=(5, 3.4))
    ax.plot([r["gap_max"] for r in rows], [r["err_median_pct"] for r in rows], "o")
    ax.axvline(1.0, color="grey", lw=0.8)
    ax.set_xlabel("largest camera gap over the run (sigma)")
    ax.set_ylabel("load error median (% span)")
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    main()
