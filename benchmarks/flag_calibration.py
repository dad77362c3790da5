"""Where the low-confidence flags of issue 20's camera sweep were set (development seeds only):

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
  or ``+blurN``: benchmarks/camera_quality.py's degradations);
- ``--margin``: on the same frames (one pass serves both), the dense fit's coarse-search margin (``grid_margin``:
  how much more the cheapest grid candidate more than a quarter of a range from the winner costs, as a share of the
  winner's cost): a diagnostic no flag reads, whether a fit in the wrong basin can be told from a sound one;
- ``--ambiguity``: per loaded frame of the development beams (``family_dev_0_19_other``: stop 58's rerun, which
  records where the other basin's fit ended), where that fit (``DenseSettings.basin_check``) ended more than
  ``ambiguity_apart`` of the range from the kept one, how much more it cost at full resolution (``basin_gap``;
  flagged under ``DenseSettings.max_ambiguity_gap``): two loads the image cannot tell apart;
- ``--std``: per loaded frame of the development beams and plates (``STD_RUNS``: stop 76's reruns, which record each
  parameter's standard deviation), the largest load parameter's standard deviation in % of its range (flagged over
  ``DenseSettings.max_std_frac``): a load the images hold too loosely to vouch for (the shelves' s_y). Stop 79
  recounted it on the development runs of the current defaults, which have the flag on (``--runs
  family_dev_0_19_template_gate,family_plate_dev_default --suffix _stop79``): the note then says what each lower
  level would flag among the frames the flag passed.

    ./run bench flag_calibration                      # all of them, on the sets the thresholds were chosen on
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
from typing import Any

import numpy as np

from benchmarks.common import RESULTS, save
from benchmarks.family import FPS, _depth_or_pair, run_registration, scene_name
from simreal_nodes.assimilation.dense import DenseSettings
from simreal_nodes.assimilation.offline import Pipeline
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.states import EstimateState
from simreal_nodes.synth.sequence import sequence

# the tables this script writes, under names composed from its options, that the docs quote as current
# (benchmarks.staleness checks them against the code; other names are labelled runs)
DEFAULT_TABLES = ("flag_calibration_gain", "flag_calibration_margin", "flag_calibration_std",
                  "flag_calibration_ambiguity", "flag_calibration_registration", "flag_calibration_camera")

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
MARGIN_LEVELS = (0.005, 0.01, 0.02, 0.05)
AMBIGUITY_LEVELS = (0.001, 0.002, 0.005, 0.01, 0.02)
# stop 58: the development beams rerun with the other basin's end point recorded (``other`` in the curves)
AMBIGUITY_RUNS = "family_dev_0_19_other"
STD_LEVELS = (0.5, 0.7, 1.0, 1.5, 2.0, 3.0)
# stop 76: the development beams 0-19 and plates rerun with each parameter's standard deviation recorded (``std_pct``
# in the curves), before the flag: every shelf of plates 0-29 and the plates bolted at both ends 0, 2, 3, 14, 18 and
# 19 (``family_plate_dev_std_stop76``, composed of three runs)
STD_RUNS = "family_dev_0_19_std,family_plate_dev_std_stop76"


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


# the per-frame quantities (``--gain``, ``--margin``; the family curves' key is the name): the dense fit's debug key,
# the thresholds the table counts at, what a threshold would flag (under it, or NaN too), the DenseSettings field of
# the flag that reads it (None: a diagnostic), the table's title, the plot's axis label and clipping
QUANTITIES: dict[str, dict[str, Any]] = {
    "gain": dict(debug="gain", levels=GAIN_LEVELS, nan_flagged=True, setting="min_gain", title="brightness gain",
                 label="dense fit's brightness gain", clip=(-0.2, 1.5)),
    # the other basin's fit (DenseSettings.basin_check) where it ended more than DenseSettings.ambiguity_apart of the
    # range away: how much more it cost at full resolution (NaN where it was not run or fell back to the winner's)
    "ambiguity": dict(debug="basin_gap", levels=AMBIGUITY_LEVELS, nan_flagged=False, setting="max_ambiguity_gap",
                      title="other basin's cost gap at full resolution (where it ended apart)",
                      label="other basin's full-resolution cost gap (ended apart)", clip=(1e-5, 2.0), xlog=True),
    # the largest standard deviation of a load parameter (the fit's normal equations scaled by its residual), % of
    # its range: flagged over the level (``above``); the family curves' key is ``std_pct`` (one per parameter)
    "std": dict(debug=None, levels=STD_LEVELS, nan_flagged=False, above=True, setting="max_std_frac", scale=100.0,
                title="largest load parameter's standard deviation (% of its range)",
                label="largest load parameter's std (% of its range)", clip=(1e-3, 50.0), xlog=True),
    "margin": dict(debug="grid_margin", levels=MARGIN_LEVELS, nan_flagged=False, setting=None,
                   title="coarse search's runner-up margin (other basin)",
                   label="coarse search's runner-up margin (other basin)", clip=(-0.05, 2.0)),
}


def quantity_row(q: str, seed: int, view: str, vals: list, errs: list, states: list) -> dict:
    """One scene's loaded frames with a dense fit: quantity ``q``'s distribution (over its finite values), the frames
    more than 2 % of the span off and how many of them (and of the others) each of its levels flags."""
    spec = QUANTITIES[q]
    g, err, st = np.array(vals, float), np.array(errs, float), np.array(states)
    fin = g[np.isfinite(g)]
    bad = err > 2.0
    row = {"seed": seed, "view": view, "frames": len(g), "ok_frames": int((st == int(EstimateState.OK)).sum()),
           f"{q}_min": float(fin.min()) if len(fin) else float("nan"),
           f"{q}_p10": float(np.percentile(fin, 10)) if len(fin) else float("nan"),
           f"{q}_median": float(np.median(fin)) if len(fin) else float("nan"),
           "err_median_pct": float(np.median(err)) if len(g) else float("nan"), "frames_over_2pct": int(bad.sum()),
           "values": [None if not np.isfinite(v) else round(float(v), 4) for v in g],
           "errs": [round(float(v), 4) for v in err]}
    for t in spec["levels"]:
        flagged = (g > t) if spec.get("above") else ~(g >= t) if spec["nan_flagged"] else (g < t)
        row[f"caught_{t:g}"] = int((bad & flagged).sum())
        row[f"good_{t:g}"] = int((~bad & flagged).sum())
    return row


def frames_from_runs(name: str, quantities: tuple[str, ...] = tuple(QUANTITIES)) -> list[tuple[int, str, dict]]:
    """The per-frame curves of a family results file (benchmarks/family.py): per scene its seed, a label and per
    loaded frame each quantity, the load error (% of the span; a plate: the larger of its two axes') and state."""
    from simreal_nodes.synth.family import draw, draw_plate

    doc = json.loads((RESULTS / f"{name}.json").read_text())
    assert all(r["seed"] < 50 for r in doc["rows"]), "development seeds only (0-49)"
    out = []
    for r in doc["rows"]:
        c = doc["curves"][str(r["seed"])]
        missing = [q for q in quantities if q not in c and not (q == "ambiguity" and "other" in c)
                   and not (q == "std" and "std_pct" in c)]
        if missing:
            raise SystemExit(f"{name} has no per-frame {missing} (rerun it with the current benchmarks/family.py)")
        spans = (draw_plate if r["object"] == "plate" else draw)(r["seed"]).spans
        fr: dict[str, list] = {k: [] for k in [*quantities, "errs", "states"]}
        for i, (t, e) in enumerate(zip(c["truth"], c["est"])):
            if t is None or c["gain"][i] is None:  # no dense fit ran
                continue
            err = 100 * abs(e - t) / spans[0]
            if "truth_y" in c and c["truth_y"][i] is not None:
                ey = 100 * abs(c["est_y"][i] - c["truth_y"][i]) / spans[1]
                err = max(err, ey) if np.isfinite(ey) else float("inf")
            for q in quantities:
                if q == "ambiguity":  # the first parameter's end point is recorded: beams (one parameter) only
                    o, b = c["other"][i], c["basin"][i]
                    apart = o is not None and abs(o - e) / spans[0] > DenseSettings().ambiguity_apart
                    fr[q].append(b if apart and b is not None and len(spans) == 1 else np.nan)
                elif q == "std":
                    fin = [v for v in c["std_pct"][i] if v is not None]
                    fr[q].append(max(fin) if fin else np.nan)
                else:
                    fr[q].append(np.nan if c[q][i] is None else c[q][i])
            fr["errs"].append(err)
            fr["states"].append(c["state"][i])
        out.append((r["seed"], f"{name} ({r['object']})", fr))
    return out


def frames_from_views(specs: list[tuple[int, str]]) -> list[tuple[int, str, dict]]:
    """The views of ``specs`` run here, 6 s each (a view may add ``+noiseN`` or ``+blurN``: made worse as
    benchmarks/camera_quality.py does): per loaded frame with a dense fit each quantity, load error and state."""
    from benchmarks.camera_quality import made_worse

    out = []
    for seed, view in specs:
        name, _, worse = view.partition("+")
        seq = sequence.__wrapped__(scene_name(seed) + name, 640, 480, duration=DURATION, fps=FPS)
        if worse:
            kind = worse.rstrip("0123456789.")
            seq = made_worse(seq, kind, float(worse[len(kind):]), seed)
        fr: dict[str, list] = {k: [] for k in [*QUANTITIES, "errs", "states"]}
        for e, truth, span in _view_frames(seq):
            if not np.isfinite(truth) or not np.isfinite(float(e.debug.get("gain", np.nan))):
                continue
            for q, spec in QUANTITIES.items():
                fr[q].append(100 * float(np.sqrt(max(e.cov[0, 0], 0.0))) / span if q == "std"
                             else float(e.debug.get(spec["debug"], np.nan)))
            if not float(e.debug.get("basin_apart", 0.0)) > DenseSettings().ambiguity_apart:
                fr["ambiguity"][-1] = np.nan
            fr["errs"].append(100 * abs(float(e.values[0]) - truth) / span)
            fr["states"].append(int(e.state))
        out.append((seed, view or "as drawn", fr))
        print({"seed": seed, "view": view, "frames": len(fr["errs"])}, flush=True)
    return out


def unloaded_ties(names: list[str]) -> str:
    """The same quantity on the runs' frames before the load comes on (the first 1.5 s), where nothing in the image
    places a load: how many of those with a second fit that ended apart read under the threshold, and their spread
    (a sentence for the table's notes: these frames are the development set's only ties)."""
    from simreal_nodes.synth.family import draw

    s = DenseSettings()
    gaps = []
    for name in names:
        doc = json.loads((RESULTS / f"{name}.json").read_text())
        for r in doc["rows"]:
            c = doc["curves"][str(r["seed"])]
            span = draw(r["seed"]).spans[0]
            for t, e, o, b in zip(c["truth"], c["est"], c["other"], c["basin"]):
                if t is None and b is not None and o is not None and abs(o - e) / span > s.ambiguity_apart:
                    gaps.append(b)
    if not gaps:
        return ""
    g = np.sort(gaps)
    return (f"Before the load comes on (no load in the image, so no position to tell: the development set's only "
            f"ties), {len(g)} frames had a second fit that ended apart: {int((g < s.max_ambiguity_gap).sum())} read "
            f"under {s.max_ambiguity_gap:g} (median {np.median(g):.4f}, p90 {np.percentile(g, 90):.4f}, the most "
            f"{g[-1]:.4f}).")


def std_note(scenes: list[tuple[int, str, dict]]) -> str:
    """What DenseSettings.max_std_frac flags on each object's frames (a sentence for the table's notes): the frames
    more than 2 % off it catches, the OK frames within 2 % it would take, the OK frames' std."""
    t = 100 * DenseSettings().max_std_frac
    out = []
    for obj in ("beam", "plate"):
        fr = [f for _, label, f in scenes if f"({obj})" in label]
        if not fr:
            continue
        g, err = (np.concatenate([np.asarray(f[k], float) for f in fr]) for k in ("std", "errs"))
        ok = np.concatenate([np.asarray(f["states"]) == int(EstimateState.OK) for f in fr])
        bad, over = err > 2.0, g > t
        out.append(f"{obj}s ({len(fr)} scenes): {int((bad & over).sum())} of {int(bad.sum())} frames more than 2 % "
                   f"off flagged, {int((~bad & ok & over).sum())} of {int((~bad & ok).sum())} OK frames within 2 % "
                   f"(the OK frames' std: median {np.nanmedian(g[ok]):.2f} %, the most {np.nanmax(g[ok]):.2f} %)")
    if not out:
        return ""
    text = f"At max_std_frac {t:g} %: " + "; ".join(out) + "."
    if not any(f["std"] and np.nanmax(np.asarray(f["std"], float)[np.asarray(f["states"]) == int(EstimateState.OK)],
                                      initial=0.0) > t for _, _, f in scenes):
        # runs made with the flag on: a lower level would flag exactly the OK frames over it (the flag changes a
        # frame's state only, never an estimate), so what it would catch and cost can be counted here
        lower = [v for v in STD_LEVELS if v < t]
        parts = []
        for group in ("beam", "plate shelves", "plates bolted at both ends"):
            G = [(seed, f) for seed, label, f in scenes if _group(seed, label) == group]
            if not G:
                continue
            g, err = (np.concatenate([np.asarray(f[k], float) for _, f in G]) for k in ("std", "errs"))
            ok = np.concatenate([np.asarray(f["states"]) == int(EstimateState.OK) for _, f in G])
            bad = ok & (err > 2.0)
            good = ok & (err <= 2.0)
            parts.append(f"{group}: of {int(bad.sum())} OK frames more than 2 % off and {int(good.sum())} within, "
                         + ", ".join(f"{v:g} % would flag {int((bad & (g > v)).sum())} and "
                                     f"{int((good & (g > v)).sum())}" for v in lower))
        text += " The runs have the flag on, so their OK frames are those it passed; a lower level: " + "; ".join(
            parts) + "."
    else:
        text += " The runs predate the flag: their OK frames are those the tracker called OK without it."
    return text


def _group(seed: int, label: str) -> str:
    """beam, plate shelves or plates bolted at both ends (a plate's support from its draw)."""
    from simreal_nodes.synth.family import draw_plate

    if "(plate)" not in label:
        return "beam"
    return "plate shelves" if draw_plate(seed).support == "cantilever" else "plates bolted at both ends"


def save_quantity(q: str, scenes: list[tuple[int, str, dict]], note: str = "", suffix: str = "") -> None:
    """flag_calibration_<q>: per scene the quantity against the load error, the totals, the scatter plot (``note``
    joins the table's notes)."""
    spec = QUANTITIES[q]
    rows = [quantity_row(q, seed, view, fr[q], fr["errs"], fr["states"]) for seed, view, fr in scenes]
    cols = [("seed", "seed", "{}"), ("view", "view", "{}"), ("frames", "loaded frames fitted", "{}"),
            ("ok_frames", "OK", "{}"), (f"{q}_min", f"{q} min", "{:.2f}"), (f"{q}_p10", "p10", "{:.2f}"),
            (f"{q}_median", "median", "{:.2f}"), ("err_median_pct", "load error median (% span)", "{:.2f}"),
            ("frames_over_2pct", "frames > 2 % off", "{}")]
    rel = ">" if spec.get("above") else "<"
    for t in spec["levels"]:
        cols += [(f"caught_{t:g}", f"of those, {q} {rel} {t:g}", "{}"),
                 (f"good_{t:g}", f"frames <= 2 % with {q} {rel} {t:g}", "{}")]
    tot = {k: sum(r[k] for r in rows) for k in ["frames", "frames_over_2pct"]
           + [f"{p}_{t:g}" for t in spec["levels"] for p in ("caught", "good")]}
    nan = float("nan")
    save(f"flag_calibration_{q}{suffix}", [{k: v for k, v in r.items() if k not in ("values", "errs")} for r in rows]
         + [{"seed": "all", "view": "", "ok_frames": sum(r["ok_frames"] for r in rows), f"{q}_min": nan,
             f"{q}_p10": nan, f"{q}_median": nan, "err_median_pct": nan, **tot}],
         cols, f"Dense fit: the {spec['title']} per frame against the load error (development seeds)",
         f"`python -m benchmarks.flag_calibration --{q}` (see its docstring). "
         + (f"A frame is flagged {'over' if spec.get('above') else 'under'} DenseSettings.{spec['setting']}"
            + (f" (x {spec['scale']:g})" if "scale" in spec else "")
            + f"{' (or where it is not finite)' if spec['nan_flagged'] else ''}. " if spec["setting"]
            else "No flag reads it (a diagnostic: the counts say what a threshold would catch). ")
         + "The "
         "frames are every loaded frame with a dense fit, whatever the tracker called it (a frame flagged for "
         "another reason counts too). Views of the camera sweep are 6 s long." + (f" {note}" if note else ""),
         lambda plt: _plot_quantity(plt, q, rows),
         extra={"frames": {f"{r['seed']}:{r['view']}": [r["values"], r["errs"]] for r in rows}})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--registration", action="store_true")
    ap.add_argument("--camera", action="store_true")
    ap.add_argument("--gain", action="store_true")
    ap.add_argument("--margin", action="store_true")
    ap.add_argument("--ambiguity", action="store_true")
    ap.add_argument("--std", action="store_true")
    ap.add_argument("--plan", help="SEED:SUFFIX,... (default: the set each threshold was chosen on)")
    ap.add_argument("--runs", default=GAIN_RUNS,
                    help="--gain, --margin: family results (development seeds) whose frames join")
    ap.add_argument("--suffix", default="", help="--std: appended to the results name (flag_calibration_std...)")
    a = ap.parse_args()
    if not (a.registration or a.camera or a.gain or a.margin or a.ambiguity or a.std):
        a.registration = a.camera = a.gain = a.margin = a.ambiguity = a.std = True
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
    qs = [q for q in QUANTITIES if getattr(a, q) and q not in ("ambiguity", "std")]
    if a.std:  # the development beams and plates rerun with each parameter's std (no views unless --plan)
        runs = a.runs if a.runs != GAIN_RUNS else STD_RUNS
        scenes = [sc for n in runs.split(",") for sc in frames_from_runs(n, ("std",))]
        save_quantity("std", scenes + frames_from_views(parse_plan(a.plan or "")), std_note(scenes), a.suffix)
    if a.ambiguity:  # the development beams rerun with the other basin's end point (no views unless --plan)
        runs = a.runs if a.runs != GAIN_RUNS else AMBIGUITY_RUNS
        save_quantity("ambiguity", [sc for n in runs.split(",") for sc in frames_from_runs(n, ("ambiguity",))]
                      + frames_from_views(parse_plan(a.plan or "")), unloaded_ties(runs.split(",")))
    if qs:  # one pass over the frames serves each quantity
        scenes = [] if a.runs in ("", "none") else [sc for n in a.runs.split(",")
                                                    for sc in frames_from_runs(n, tuple(qs))]
        scenes += frames_from_views(parse_plan(a.plan or GAIN_PLAN))
        for q in qs:
            save_quantity(q, scenes)


def _plot_quantity(plt, q: str, rows: list[dict]):
    spec = QUANTITIES[q]
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    g = np.array([np.nan if v is None else v for r in rows for v in r["values"]], float)
    e = np.concatenate([r["errs"] for r in rows])
    ax.plot(np.clip(g, *spec["clip"]), np.clip(e, 1e-3, 100), ".", ms=2, alpha=0.5)
    if spec["setting"]:
        ax.axvline(getattr(DenseSettings(), spec["setting"]) * spec.get("scale", 1.0), color="grey", lw=0.8)
    ax.axhline(2.0, color="grey", lw=0.5, ls=":")
    ax.set_yscale("log")
    if spec.get("xlog"):
        ax.set_xscale("log")
    ax.set_xlabel(f"{spec['label']} (clipped to {spec['clip'][0]:g}..{spec['clip'][1]:g})")
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
