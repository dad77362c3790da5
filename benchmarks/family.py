"""Deformable tracking on the scene family (issue 16): scenes drawn at random from wide ranges, rendered from an
independent full-order truth (never the tracked model), with held-out seeds that no default was tuned on.

    ./run bench family                       # the held-out seeds 1000-1099 (45 min with --jobs 2 on 2 cores)
    python -m benchmarks.family --seeds 0-9  # development seeds (tuning happens on 0-49 only): results/family_dev.*
    python -m benchmarks.family --report [--seeds 0-9]   # rewrite a table and plot from its JSON
    python -m benchmarks.family --seeds 0-4 --preloaded   # the load on from the first frame (no unloaded mapping)
    python -m benchmarks.family --seeds 0-9 --registration  # the registration step alone: results/family_registration.*
    python -m benchmarks.family --seeds 0-49 --registration --preloaded  # of loaded beams: *_registration_preloaded.*
    python -m benchmarks.family --seeds 0-9 --measurements map_points  # the sparse mode beside: *_map_points.*
    python -m benchmarks.family --seeds 0-4 --tracking dense_step_px=3  # a knob's trade: *_dense_step_px_3.*
    python -m benchmarks.family --seeds 0-9 --sensor stereo  # a stereo pair instead of RGB-D: *_stereo.*
    python -m benchmarks.family --object plate --seeds 0-9   # plates, a load anywhere (s_x, s_y): family_plate*
    ... --jobs 2                             # scenes in 2 processes (one core each)

Per scene: the load-position error over the loaded frames (median, p90, mean, in % of the load's range), the share
of loaded frames with an estimate of state OK, the scene's model error (how far the reduced model is from the
truth, and the load-position bias a perfect measurement would still give), the time per frame, and for a scene
that fails, why (the tracker's most common reason), and the registration's pose error (the scene files place the
beam by ``anchor: registration`` from a guess by eye, centimetres off). The estimator sees the images and depth only.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import copy
import functools
import json
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from benchmarks.common import RESULTS, save, saved_machine
from simreal_nodes import geometry as G
from simreal_nodes.assimilation.offline import Pipeline
from simreal_nodes.assimilation.registration import RegistrationConfig
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.states import EstimateState
from simreal_nodes.synth.family import HELD_OUT_SEEDS, scene_model_error
from simreal_nodes.synth.sequence import sequence
from simreal_nodes.vision.slam.config import SlamConfig

# the tables this script writes, under names composed from its options, that the docs quote as current
# (benchmarks.staleness checks them against the code; other names are labelled runs)
DEFAULT_TABLES = ("family", "family_plate", "family_registration", "family_registration_stereo", "family_stereo",
                  "family_preloaded", "family_preloaded_heldout", "family_registration_preloaded",
                  "family_registration_preloaded_heldout")

FPS = 15.0  # like the recording in the issue
# the registration-alone run of loaded beams (``--registration --preloaded``): frames for this many tries (a refused
# one collects its views again, as in the graph; twice refused for its slide alone, the guess places it along the axis)
LOADED_TRIES = 3


def parse_seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b) + 1) if b else [int(a)])
    return out


def scene_name(seed: int, preloaded: bool = False, sensor: str = "rgbd", object: str = "beam") -> str:
    """The family scene's name for :func:`~simreal_nodes.synth.makebag.make_scene`."""
    return (("family-plate-" if object == "plate" else "family-") + str(seed) + ("-preloaded" if preloaded else "")
            + ("-stereo" if sensor == "stereo" else ""))


def run_scene(seed: int, width: int = 640, height: int = 480, preloaded: bool = False,
              measurements: str | None = None, tracking: dict | None = None, sensor: str = "rgbd",
              seq: dict | None = None, object: str = "beam", slam: dict | None = None) -> dict:
    """One scene through the offline pipeline; ``measurements`` overrides the scene's ``tracking.measurements``,
    ``tracking`` any other key of its ``tracking`` block (a knob's trade); ``slam``: fields of the SLAM's
    :class:`~simreal_nodes.vision.slam.config.SlamConfig` (a knob's trade); ``sensor``: ``rgbd`` or ``stereo``;
    ``seq``: the scene's frames already rendered (and perhaps made worse: ``benchmarks/camera_quality.py``);
    ``object``: ``beam`` or ``plate`` (two load parameters: a frame's error is the larger of the two, each in % of
    its own range; each axis's median beside)."""
    t0 = time.perf_counter()
    if seq is None:
        seq = sequence.__wrapped__(scene_name(seed, preloaded, sensor, object), width, height, fps=FPS,
                                   stereo=sensor == "stereo")  # not cached: one scene in memory at a time
    t_render = time.perf_counter() - t0
    sc = seq["scene"]
    d = sc.state["draw"]
    doc = copy.deepcopy(sc.scene_yaml(sc))
    if measurements:
        doc["objects"][0]["tracking"]["measurements"] = measurements
    doc["objects"][0]["tracking"].update(tracking or {})
    scene = build_spec_models(validate_scene(doc, sc.name, "."))
    pipe = Pipeline(scene, seq["cam"], baseline=sc.stereo_baseline, slam_config=SlamConfig(**slam) if slam else None)
    run = track(pipe, seq, FPS)
    truth, est, states, reasons = run["truth"], run["est"], run["states"], run["reasons"]
    step_ms, cam_err, solve_ms, tracker_ms = run["step_ms"], run["cam_err"], run["solve_ms"], run["tracker_ms"]
    truth_a, est_a, states_a = np.array(truth), np.array(est), np.array(states)
    loaded = np.isfinite(truth_a)
    tv, ev = np.array(run["truth_all"]), np.array(run["est_all"])  # (frames, parameters)
    axis_err = 100 * np.abs(ev[loaded] - tv[loaded]) / np.asarray(d.spans)
    err = axis_err.max(axis=1)
    ok = states_a[loaded] == EstimateState.OK
    why = collections.Counter(r for r, s in zip(np.array(reasons)[loaded], states_a[loaded])
                              if s != EstimateState.OK and r)
    row = {
        "seed": seed, "measurements": scene["objects"][0]["tracking"]["measurements"], "sensor": sensor,
        "object": d.object, "parameters": d.parameters,
        "axis_median_err_pct": [float(v) for v in np.median(axis_err, axis=0)],
        "support": d.support, "slenderness": round(d.slenderness, 1), "peak_px": round(d.peak_px, 1),
        "contrast": round(d.speckle_contrast, 3), "distance_m": round(d.distance, 2),
        "loaded_frames": int(loaded.sum()),
        "ok_pct": float(100 * ok.mean()), "median_err_pct": float(np.median(err)),
        "p90_err_pct": float(np.percentile(err, 90)), "mean_err_pct": float(np.mean(err)),
        # the frames the tracker vouched for: a large error here is a silent failure
        "ok_median_err_pct": float(np.median(err[ok])) if ok.any() else float("nan"),
        "ok_p90_err_pct": float(np.percentile(err[ok], 90)) if ok.any() else float("nan"),
        "step_ms_p50": float(np.median(step_ms)), "render_s": round(t_render, 1),
        "solve_ms_p50": float(np.median(solve_ms)) if solve_ms else float("nan"),
        "tracker_ms_p50": float(np.median(tracker_ms)) if tracker_ms else float("nan"),
        "tracker_ms_mean": float(np.mean(tracker_ms)) if tracker_ms else float("nan"),
        "camera_ate_mm": float(1e3 * np.sqrt(np.mean(np.square(cam_err)))) if cam_err else float("nan"),
        "camera_tracked_pct": float(100 * len(cam_err) / len(seq["rgb"])),
        "reason": why.most_common(1)[0][0] if why else "",
        # why the object was not placed or followed, where something said so: the last refusal or lost camera
        # (the waiting count, "(1 of 3 depth views)", says only that it is waiting)
        "refusal": next((r for r in reversed(run["reasons"]) if "refused" in r or "no camera pose" in r), ""),
        **registration_error(pipe, seq),
        **scene_model_error(sc, pipe.objects.models["beam"]),
        "curve": {"truth": [None if not np.isfinite(v) else float(v) for v in truth_a], "est": est_a.tolist(),
                  "state": [int(v) for v in states_a],
                  "gain": [None if not np.isfinite(v) else round(v, 4) for v in run["gain"]],
                  "margin": [None if not np.isfinite(v) else round(v, 4) for v in run["margin"]],
                  "basin": [None if not np.isfinite(v) else round(v, 4) for v in run["basin"]],
                  "switched": [int(v) for v in run["switched"]],
                  "other": [None if not np.isfinite(v) else float(v) for v in run["other"]],
                  "warm": [int(v) for v in run["warm"]],
                  "ms": [None if not np.isfinite(v) else round(v, 1) for v in run["frame_ms"]],
                  # each parameter's standard deviation from the fit's normal equations, % of its range
                  "std_pct": [[None if not np.isfinite(v) else round(100 * v / sp, 3) for v, sp in zip(f, d.spans)]
                              for f in run["std_all"]],
                  **({"truth_y": [None if not np.isfinite(v) else float(v) for v in tv[:, 1]],
                      "est_y": ev[:, 1].tolist()} if tv.shape[1] > 1 else {})},
    }
    return row


def track(pipe: Pipeline, seq: dict, fps: float, oid: str = "beam") -> dict[str, list]:
    """Every frame of a rendered sequence through the offline pipeline: per frame the truth and estimate of the
    object's first parameter (``truth_all``, ``est_all``: of every parameter the truth gives), its state and
    reason, the step's time; the tracker's own time and the camera's position error (map frame: both start at the
    first camera frame) where the camera was localized; the solve's time where one ran; the dense fit's
    brightness gain and its coarse search's runner-up margin (NaN where no dense fit ran or the search had no
    candidate from another basin: the low-confidence flags are calibrated on them); where the runner-up was fitted
    too (``DenseSettings.basin_check``), how much more the other basin cost at full resolution, whether the fit moved
    there (``switched``: 1 to the runner-up's fit, 2 to the warm start's), where the other fit ended (``other``: the
    first parameter), whether the last frame's estimate was fitted as well (``warm``:
    ``DenseSettings.basin_warm``) and the tracker's time (``frame_ms``: NaN where the camera had no pose)."""
    run: dict[str, list] = {k: [] for k in ("truth", "est", "states", "reasons", "step_ms", "cam_err", "solve_ms",
                                            "tracker_ms", "truth_all", "est_all", "gain", "margin", "basin",
                                            "switched", "other", "warm", "frame_ms", "std_all")}
    for i in range(len(seq["rgb"])):
        bgr = np.ascontiguousarray(seq["rgb"][i][:, :, ::-1])
        t1 = time.perf_counter()
        T_wc, out = pipe.step(bgr, int(i * 1e9 / fps), *_depth_or_pair(seq, i))
        run["step_ms"].append(1e3 * (time.perf_counter() - t1))
        if T_wc is not None:
            run["cam_err"].append(float(np.linalg.norm(T_wc[:3, 3] - seq["T"][i][:3, 3])))
            run["tracker_ms"].append(pipe.tracker_ms)
        run["frame_ms"].append(pipe.tracker_ms if T_wc is not None else float("nan"))
        e = out[oid]
        if e.solve_ms > 0:
            run["solve_ms"].append(e.solve_ms)
        tp = seq["truth"][i].params[oid][2]
        run["truth"].append(tp[0])
        run["est"].append(float(e.values[0]))
        run["truth_all"].append([float(v) for v in tp])
        run["est_all"].append([float(v) for v in e.values[:len(tp)]])
        run["std_all"].append([float(v) for v in np.sqrt(np.clip(np.diag(e.cov), 0, None))[:len(tp)]]
                              if np.ndim(e.cov) == 2 and len(e.cov) >= len(tp) else [float("nan")] * len(tp))
        run["states"].append(int(e.state))
        run["reasons"].append(e.reason)
        run["gain"].append(float(e.debug.get("gain", float("nan"))))
        run["margin"].append(float(e.debug.get("grid_margin", float("nan"))))
        run["basin"].append(float(e.debug.get("basin_gap", float("nan"))))
        run["switched"].append(int(e.debug.get("basin_switched", 0.0)))  # 1: the runner-up kept, 2: the warm start
        run["other"].append(float(e.debug.get("basin_other_0", float("nan"))))
        run["warm"].append(int(e.debug.get("basin_warm", 0.0) > 0))
    return run


def _depth_or_pair(seq: dict, i: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Frame i's depth image (RGB-D) or right image (stereo: the rendered depth, the truth, is not passed)."""
    if seq["scene"].stereo_baseline:
        return None, seq["right"][i]
    return seq["depth"][i], None


def registration_error(pipe: Pipeline, seq: dict) -> dict:
    """The registered beam pose against the truth (both in the map frame, the first camera frame): position error
    of the object frame's origin (mm), the largest displacement of a model node it causes (mm) and the rotation
    angle (deg); NaN where no registration was accepted."""
    reg = pipe.objects.registrations.get("beam")
    if reg is None:
        return {"registration_mm": float("nan"), "registration_max_mm": float("nan"),
                "registration_deg": float("nan"), "registration_fitness": 0.0, "slide_spread_mm": float("nan"),
                "registration_noise_mm": float("nan"), "registration_doubt": ""}
    T_true = seq["truth"][0].object_poses["beam"]
    D = G.inv(T_true) @ reg.T_map_obj
    X = pipe.objects.models["beam"].points
    return {"registration_mm": float(1e3 * np.linalg.norm(D[:3, 3])),
            "registration_max_mm": float(1e3 * np.linalg.norm(X @ D[:3, :3].T + D[:3, 3] - X, axis=1).max()),
            "registration_deg": float(np.rad2deg(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1.0, 1.0)))),
            "registration_fitness": float(reg.fitness), "slide_spread_mm": 1e3 * float(reg.slide_spread),
            "registration_noise_mm": 1e3 * float(reg.noise), "registration_doubt": reg.doubt}


def run_registration(seed: int, width: int = 640, height: int = 480, sensor: str = "rgbd", view: str = "",
                     preloaded: bool = False) -> dict:
    """The registration step alone: the scene's first frames (as many as :class:`RegistrationConfig` collects)
    through the pipeline (RGB-D or stereo SLAM poses, the scene file's guess), until the beam is placed. ``view``:
    a camera override appended to the scene name (``-d0.5``, ``-el5``: :func:`~simreal_nodes.synth.family`'s
    scene names; benchmarks/camera_quality.py). ``preloaded``: the scene loaded from its first frame, so that the
    deformation is fitted with the pose (``registration.register_loaded``); up to ``LOADED_TRIES`` tries' frames
    run, and the row adds the fitted state's error against the truth at the first frame (% of the load's range)."""
    cfg = RegistrationConfig()
    tries = LOADED_TRIES if preloaded else 1
    seq = sequence.__wrapped__(scene_name(seed, preloaded, sensor) + view, width, height, fps=FPS,
                               frames=tries * (cfg.frames * cfg.every) + 2, stereo=sensor == "stereo")
    sc = seq["scene"]
    yaml_doc = sc.scene_yaml(sc)
    scene = build_spec_models(validate_scene(copy.deepcopy(yaml_doc), sc.name, "."))
    pipe = Pipeline(scene, seq["cam"], baseline=sc.stereo_baseline)
    t0, reason, frame = time.perf_counter(), "", -1
    for i in range(len(seq["rgb"])):
        _, out = pipe.step(np.ascontiguousarray(seq["rgb"][i][:, :, ::-1]), int(i * 1e9 / FPS),
                           *_depth_or_pair(seq, i))
        reason = out["beam"].reason
        if "beam" in pipe.objects.registrations:
            frame = i
            break
    guess = G.pose7_to_matrix(yaml_doc["objects"][0]["anchor"]["guess"])
    D = G.inv(seq["truth"][0].object_poses["beam"]) @ guess
    d = sc.state["draw"]
    row = {"seed": seed, "support": d.support, "length_mm": round(1e3 * d.length),
           "height_mm": round(1e3 * d.height, 1), "distance_m": round(d.distance, 2),
           "guess_mm": float(1e3 * np.linalg.norm(D[:3, 3])),
           "guess_deg": float(np.rad2deg(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1.0, 1.0)))),
           **registration_error(pipe, seq), "frame": frame, "seconds": round(time.perf_counter() - t0, 1),
           "reason": "" if frame >= 0 else reason}
    if preloaded:
        # the truth over the frames whose views were fused (a later try's, where one was refused): the load may have
        # moved on between tries, and a state read while it moved has no one truth (the row says so)
        last = frame if frame >= 0 else len(seq["rgb"]) - 1
        fused = [np.asarray(seq["truth"][i].params["beam"][2], dtype=np.float64)
                 for i in range(max(0, last - cfg.frames * cfg.every + 1), last + 1)]
        truth = fused[-1]
        reg = pipe.objects.registrations.get("beam")
        mu = None if reg is None or reg.state is None else np.asarray(reg.state, dtype=np.float64)[:len(truth)]
        row.update(truth=truth.tolist(), state=None if mu is None else mu.tolist(),
                   load_moved=bool(np.ptp(np.array(fused), axis=0).max() > 0),
                   # NaN: not placed, or placed with no deformation fitted (its rest shape stood)
                   state_err_pct=float("nan") if mu is None else
                   float(np.max(100 * np.abs(mu - truth) / np.asarray(d.spans))))
    return row


REG_COLS = [("seed", "seed", "{}"), ("support", "support", "{}"), ("length_mm", "length (mm)", "{}"),
            ("height_mm", "height (mm)", "{}"), ("distance_m", "camera distance (m)", "{}"),
            ("guess_mm", "guess off (mm)", "{:.0f}"), ("guess_deg", "guess off (deg)", "{:.1f}"),
            ("registration_mm", "registration error (mm)", "{:.2f}"),
            ("registration_max_mm", "largest node displacement (mm)", "{:.2f}"),
            ("registration_deg", "(deg)", "{:.2f}"),
            ("registration_fitness", "fitness", "{:.2f}"), ("frame", "placed at frame", "{}"),
            ("seconds", "time (s)", "{}"), ("reason", "refused because", "{}")]
REG_LOADED_COLS = REG_COLS[:-1] + [("state_err_pct", "load state error (% range)", "{:.1f}"),
                                   ("slide_spread_mm", "slide spread (mm)", "{:.0f}"),
                                   ("registration_doubt", "doubt", "{}"), REG_COLS[-1]]


def write_registration(rows: list[dict], label: str, suffix: str = "") -> None:
    mm = np.array([r["registration_mm"] for r in rows])
    deg = np.array([r["registration_deg"] for r in rows])
    worst = np.array([r["registration_max_mm"] for r in rows])
    sensor = "stereo SLAM poses and SGBM depth" if suffix == "_stereo" else "RGB-D SLAM poses"
    notes = (f"{label}: the registration step alone (`anchor: registration`) on each scene's first frames, {sensor}, "
             "the scene file's guess (about 5 cm and 10 degrees rms off). Median error "
             f"{np.nanmedian(mm):.2f} mm, {np.nanmedian(deg):.2f} deg (target <= 3 mm, <= 0.5 deg), largest node "
             f"displacement {np.nanmedian(worst):.2f} mm at the median; "
             f"{int(np.isnan(mm).sum())} of {len(rows)} scenes refused. Error: the object frame's origin (the beam's "
             "clamped corner), the largest displacement of a model node and the rotation angle, against the true pose "
             "in the map frame.")
    save("family_registration" + suffix, rows, REG_COLS, "Registration of the beam on the scene family", notes,
         extra={"summary": {"median_mm": float(np.nanmedian(mm)), "median_deg": float(np.nanmedian(deg)),
                            "median_max_mm": float(np.nanmedian(worst)),
                            "refused": int(np.isnan(mm).sum()), "label": label}})


def write_registration_loaded(rows: list[dict], label: str, name: str, machine: dict | None = None) -> None:
    """The registration step alone on loaded beams (``--registration --preloaded``): the pose as
    :func:`write_registration` gives it, with the fitted state's error, and the fits placed a centimetre or more off
    with no doubt raised (silent: a tracker started there reads the load from a misplaced model)."""
    mm = np.array([r["registration_mm"] for r in rows])
    deg = np.array([r["registration_deg"] for r in rows])
    state = np.array([r["state_err_pct"] for r in rows])
    # off by a centimetre anywhere: the origin (the clamped corner) or the model node furthest from its true place
    # (development seed 40 until stop 117: its origin 2.2 mm off, turned 4.7 degrees, its far end 72 mm)
    off = [max(r["registration_mm"], r["registration_max_mm"]) for r in rows]
    far = [r["seed"] for r, o in zip(rows, off) if o >= 10.0]
    silent = [r["seed"] for r, o in zip(rows, off) if o >= 10.0 and not r["registration_doubt"]]
    # placed with its rest shape: every scene here is loaded, so that is a state the depth did not read
    at_rest = [r["seed"] for r in rows if np.isfinite(r["registration_mm"]) and not np.isfinite(r["state_err_pct"])]
    moved = [r["seed"] for r in rows if r.get("load_moved")]
    placed = mm[np.isfinite(mm)]
    notes = (f"{label}, the load on from the first frame: the registration step alone (`anchor: registration`, the "
             "deformation fitted with the pose where the depth shows it: `registration.register_loaded`) on each "
             f"scene's first frames (up to {LOADED_TRIES} tries' views), RGB-D SLAM poses, the scene file's guess. "
             f"Placed: {len(placed)} of {len(rows)}; pose error {np.nanmedian(mm):.2f} mm at the median, p90 "
             f"{np.percentile(placed, 90) if len(placed) else float('nan'):.1f} mm, "
             f"{np.nanmedian(deg):.2f} deg; placed 10 mm or more off (the origin or any model node): {len(far)} "
             f"({', '.join(map(str, far)) or 'none'}), of them with no doubt raised: {len(silent)} "
             f"({', '.join(map(str, silent)) or 'none'}). Load state (the fitted mu against the truth at the last "
             "fused view, % of the load's range): "
             f"{np.nanmedian(state) if np.isfinite(state).any() else float('nan'):.1f} % at the median of the fits "
             f"that read one; placed at rest (the rest shape stood, no state read, blank): {len(at_rest)} "
             f"({', '.join(map(str, at_rest)) or 'none'}); the load moved while the views were taken: "
             f"{', '.join(map(str, moved)) or 'none'}. Pose error: the object frame's origin (the beam's clamped "
             "corner) against the true pose.")
    # a missing state is null in the JSON and a blank cell, not "nan"
    shown = [{**r, "state_err_pct": None if not np.isfinite(r["state_err_pct"]) else r["state_err_pct"]} for r in rows]
    save(name, shown, REG_LOADED_COLS, "Registration of loaded beams on the scene family", notes,
         extra={"summary": {"median_mm": float(np.nanmedian(mm)), "median_deg": float(np.nanmedian(deg)),
                            "p90_mm": float(np.percentile(placed, 90)) if len(placed) else float("nan"),
                            "refused": int(np.isnan(mm).sum()), "far": far, "silent": silent, "at_rest": at_rest,
                            "load_moved": moved,
                            "median_state_err_pct": float(np.nanmedian(state)) if np.isfinite(state).any()
                            else float("nan"), "label": label}, **(machine or {})})


COLS = [("seed", "seed", "{}"), ("support", "support", "{}"), ("slenderness", "L/h", "{:.0f}"),
        ("peak_px", "peak (px)", "{:.1f}"), ("contrast", "texture contrast", "{:.2f}"),
        ("median_err_pct", "median error (% range)", "{:.2f}"), ("p90_err_pct", "p90 (%)", "{:.2f}"),
        ("mean_err_pct", "mean (%)", "{:.2f}"), ("ok_pct", "OK frames (%)", "{:.0f}"),
        ("model_bias_median_pct_span", "model bias (% range)", "{:.2f}"),
        ("model_rel_l2_median_pct", "model error |u| (%)", "{:.1f}"),
        ("camera_ate_mm", "camera ATE (mm)", "{:.1f}"), ("camera_tracked_pct", "camera tracked (%)", "{:.0f}"),
        ("step_ms_p50", "step (ms)", "{:.0f}"), ("tracker_ms_p50", "tracker (ms)", "{:.0f}"),
        ("solve_ms_p50", "solve (ms)", "{:.0f}"),
        ("registration_mm", "registration (mm)", "{:.1f}"), ("registration_deg", "registration (deg)", "{:.2f}"),
        ("reason", "most common reason when not OK", "{}")]


def summary(rows: list[dict]) -> dict:
    med = np.array([r["median_err_pct"] for r in rows])
    return {"scenes": len(rows), "median_of_medians_pct": float(np.median(med)),
            "p90_of_medians_pct": float(np.percentile(med, 90)),
            "within_1pct": float(np.mean(med < 1.0) * 100), "within_2pct": float(np.mean(med < 2.0) * 100),
            "median_model_bias_pct": float(np.median([r["model_bias_median_pct_span"] for r in rows])),
            "median_registration_mm": float(np.nanmedian([r.get("registration_mm", np.nan) for r in rows])),
            "median_registration_deg": float(np.nanmedian([r.get("registration_deg", np.nan) for r in rows]))}


def write(rows: list[dict], label: str, name: str = "family", measured_on: dict | None = None) -> None:
    """The table, plot and JSON of a run; ``measured_on``: the machine line of the run being rewritten (``--report``)
    rather than this one."""
    s = summary(rows)
    slam = "stereo SLAM (SGBM depth for the registration and reference view)" if "stereo" in label else "RGB-D SLAM"
    notes = (f"{label}: {s['scenes']} scenes at 640x480, {FPS:.0f} fps, {slam} + PGD tracker with the defaults. "
             f"Over scenes: median of the per-scene median error {s['median_of_medians_pct']:.2f} % of the load range, "
             f"p90 {s['p90_of_medians_pct']:.2f} %, {s['within_1pct']:.0f} % of scenes within 1 %, "
             f"{s['within_2pct']:.0f} % within 2 % (targets: < 1 %, < 3 %, >= 90 % within 2 %). The model bias is "
             "the load-position error the reduced model alone makes (its least-squares best fit to the truth's surface "
             "displacement); model error |u| its relative displacement error; camera ATE the RMS camera position "
             f"error of the {slam.split(' (')[0]} (no alignment: both maps start at the first camera frame). The "
             "object is placed by registration from a guess by eye; its pose error (median "
             f"{s['median_registration_mm']:.1f} mm, {s['median_registration_deg']:.2f} deg) is in each row. "
             "Errors are over the loaded frames "
             "(the first 1.5 s map the unloaded scene unless the label says the load is on from the first frame).")
    if any(r.get("object") == "plate" for r in rows):
        notes += (" Plates: two load parameters (s_x, s_y); a frame's error is the larger of the two, each in % of its "
                  "own range; 'per axis' gives each axis's median over the loaded frames.")
    supports = sorted({r["support"] for r in rows})
    if len(supports) > 1:
        notes += " By support: " + "; ".join(
            f"{sup} ({len(b)} scenes) {np.median(b):.2f} %, {100 * np.mean(b < 2.0):.0f} % within 2 %"
            for sup in supports for b in [np.array([r["median_err_pct"] for r in rows if r["support"] == sup])]) + "."

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        med = [r["median_err_pct"] for r in rows]
        for support, marker in (("cantilever", "^"), ("two_support", "o"), ("clamped_ends", "s")):
            sel = [r for r in rows if r["support"] == support]
            if not sel:
                continue
            ax[0].scatter([r["peak_px"] for r in sel], [r["median_err_pct"] for r in sel], marker=marker,
                          c=[r["contrast"] for r in sel], cmap="viridis", vmin=0, vmax=1, label=support)
        ax[0].legend(fontsize=8)
        ax[0].set_xscale("log")
        ax[0].xaxis.set_minor_formatter(plt.NullFormatter())
        ax[0].set_yscale("log")
        ax[0].axhline(1.0, color="k", lw=0.8, ls="--")
        ax[0].set_xlabel("peak image motion (px)")
        ax[0].set_ylabel("median error (% of range)")
        ax[0].set_title("per scene (colour: texture contrast 0-1)", fontsize=9)
        ax[1].hist(np.clip(med, 0, 50), bins=25, color="tab:blue")
        ax[1].set_xlabel("median error (% of range, clipped at 50)")
        ax[1].set_ylabel("scenes")
        fig.tight_layout()
        return fig

    table_rows = [{k: v for k, v in r.items() if k != "curve"} for r in rows]
    cols = COLS
    if any(r.get("object") == "plate" for r in rows):  # each axis's median beside the frame-wise larger one
        for r in table_rows:
            r["axis_txt"] = " / ".join(f"{v:.2f}" for v in r.get("axis_median_err_pct", []))
        k = next(i for i, c in enumerate(COLS) if c[0] == "median_err_pct") + 1
        cols = [*COLS[:k], ("axis_txt", "per axis: s_x / s_y (%)", "{}"), *COLS[k:]]
    save(name, table_rows, cols, "Deformable tracking on the scene family (independent physics)", notes, plot,
         extra={"summary": s, "label": label, "curves": {r["seed"]: r["curve"] for r in rows},
                **({"machine": measured_on} if measured_on else {})})
    write_doc()


TABLES = (("family", "Held-out seeds (the accuracy this project reports): the current defaults, all 100 in one run "
           "(`./run bench family`, stop 107; rerun in stop 125 with ORB-SLAM2's rule for an RGB-D keyframe's new "
           "points, the default since stop 124, on an AMD EPYC host: 0.43 %, p90 1.39 %, 83 % within 1 %, 99 % within "
           "2 %; its last run with the cap of the 250 nearest, on an Intel host, table b6e4b73: 0.42 %, "
           "1.34 %, 81 %, 98 %, `python -m benchmarks.rerun_diff family --against b6e4b73`; "
           "rerun in stop 114 on that session's code, 91 scenes and then the other 9 "
           "with `--resume`, every row's estimates, errors and registration the same to the bit, only the times "
           "moved; stops 78-80 composed it from two halves, `--compose "
           "family_heldout_1000_1049_default,family_heldout_1050_1099_default`, with the template averaged over up "
           "to 20 views at rest since stop 78; until stop 80 it was stop 59's code: `--compose "
           "family_stop59,family_room`)"),
          ("family_room", "Held-out seeds whose drawn camera path came within 0.1 m of a side wall or through it, "
           "rerun in the widened room (stop 60; the defaults)"),
          ("family_dev_room", "Development seeds whose drawn camera path came within 0.1 m of a side wall or through "
           "it, rerun in the widened room (stop 60; the defaults)"),
          ("family_stop59", "Held-out seeds, the main table of stop 59 (the same tracker, the rooms before stop 60: "
           "the cameras of 1050, 1062 and 1087 went through a wall)"),
          ("family_dev_20_49", "Development seeds 20-49 on the code of stop 59 (the defaults of stop 58: "
           "`dense_basin_warm: true`)"),
          ("family_dev_warm_off", "No third fit (`--tracking dense_basin_warm=false`, the defaults since stop 59), on "
           "the development seeds 20-49 where the third fit was kept on a frame in the table above (20, 32, 34, 36, "
           "40, 41, 47)"),
          ("family_dev", "Development seeds 12-49 on the defaults of 2026-11-23 (before stop 38's shading term)"),
          ("family_regen_check", "Held-out seeds 1000, 1011, 1021 and 1047 rerun on the code of stop 59 (AMD EPYC): "
           "the main table's rows came from stop 57's run on an Intel Xeon"),
          ("family_stop55", "Held-out seeds on the code of stop 55 (the main table of stops 57-58; seeds 1000-1036 "
           "run in stop 55, 1037-1099 in stop 56 from a clone of stop 55's code)"),
          ("family_stop58_warm", "Knob, held out: the code of stop 58 (`dense_basin_warm: true`, its default then): "
           "the seeds where a frame could meet its condition in the runs of stop 57's code (below), and two where "
           "none did (1066, 1072)"),
          ("family_stop58", "Held-out seeds 1041 and 1066-1099 on the code of stop 57 with stop 58's ambiguity flag "
           "(the rest of the held-out seeds of `family_stop57`)"),
          ("family_stop57", "Held-out seeds on the code of stop 57 (the other basin fitted at full detail, "
           "`dense_basin_check: 0.1`; seeds from 1000 up, in order, as far as the stop's time allowed)"),
          ("family_stop57_wrong_basin", "Held-out seeds on the code of stop 57: the five scenes whose frames the "
           "first table (stop 55's code) called OK in the wrong basin"),
          ("family_stop49", "Held-out seeds on the code of stop 49 (the SLAM before stops 50-55: RGB-D local BAs "
           "over at most 800 points)"),
          ("family_stop48", "Held-out seeds on the code of stop 48 (the coarse search fitted each candidate's "
           "brightness on every frame: what `--tracking dense_grid_brightness=always` gives)"),
          ("family_stop39", "Held-out seeds on the code of stop 39 (before the coarse search fitted each "
           "candidate's brightness: what `--tracking dense_grid_brightness=never` gives, on the SLAM of stop 39)"),
          ("family_stop38", "Held-out seeds on the code of stop 38 (the shading term, each frame's g alone: what "
           "`--tracking dense_shading_frames=0` gives)"),
          ("family_plate_heldout", "Plates, held-out seeds 1000-1019 on the current defaults (`--compose "
           "family_plate_stop78,family_plate_1019`: stop 78's run of 1000-1018, the template averaged over up to 20 "
           "views at rest, and stop 81's of 1019, which stop 78 stopped for time; the plates' tracking code is the "
           "same in both)"),
          ("family_plate", "Plates, held-out seeds 1000-1019 rerun in stop 125 with ORB-SLAM2's keyframe points "
           "(`--object plate --seeds 1000-1019 --out family_plate_stop125`, composed as `family_plate`; an AMD EPYC "
           "host: 1.15 %, p90 2.82 %, 35 % within 1 %, 75 % within 2 %; its last run with the cap of the 250 "
           "nearest, on an Intel host, table c93e8f3: 1.14 %, 2.58 %, 40 %, 75 %, `python -m "
           "benchmarks.rerun_diff family_plate --against c93e8f3`)"),
          ("family_heldout_1050_1099_default", "Beams, held-out seeds 1050-1099 on the current defaults (`--seeds "
           "1050-1099 --out family_heldout_1050_1099_default`: stop 80, run once)"),
          ("family_heldout_1000_1049_default", "Beams, held-out seeds 1000-1049 on the current defaults (`--compose "
           "family_heldout_1000_1009_template,family_heldout_1010_1029_template,family_heldout_1030_1049_template`: "
           "stop 78's run of 1000-1009 and stop 79's of 1010-1049, the template averaged)"),
          ("family_heldout_1000_1009_template", "Beams, held-out seeds 1000-1009 on this code (`--seeds 1000-1009 "
           "--out family_heldout_1000_1009_template`: stop 78, the template averaged, the default now)"),
          ("family_heldout_1000_1009_stop78", "Beams, held-out seeds 1000-1009 on the code of stop 78 with the "
           "template of one view (`--tracking dense_template_frames=0`, the default before; run before the default "
           "changed)"),
          ("family_dev_0_19_template_gate", "Beams, development seeds 0-19 with the template averaged and its "
           "averaging closed at a load too small to be called a deformation (stop 78; `--tracking "
           "dense_template_frames=20`, the default now)"),
          ("family_plate_dev_template_gate", "Plates, development seeds 0-4 with the template averaged and closed as "
           "above (stop 78; the run was stopped there for time)"),
          ("family_plate_dev_template_gate_17_21", "Plates, development seeds 17 and 21 (two of the three that stop "
           "77's averaging made worse) with the averaging closed as above (stop 78)"),
          ("family_plate_dev_default", "Plates, development seeds (stop 76's 24) on the defaults of stop 78 "
           "(`--compose family_plate_dev_template_gate,family_plate_dev_template_gate_17_21,"
           "family_plate_dev_template_gate_rest`: the last the other 17 seeds, run in stop 79)"),
          ("family_plate_stop76", "Plates, held-out seeds on the code of stop 76 (`--object plate --seeds 1000-1019 "
           "--out family_plate_stop76`: a load anywhere on the top face, s_x and s_y; stop 76, with the flag of a "
           "load held too loosely, `DenseSettings.max_std_frac`)"),
          ("family_plate_stop74", "Plates, held-out seeds on the code of stop 74 (`--object plate --seeds 1000-1019 "
           "--out family_plate_stop74`, with the registration's second coarse pass; before stop 76's flag)"),
          ("family_plate_dev_template_20", "Plates, development seeds (stop 76's 24) with the template averaged "
           "over up to 20 views at rest (`--tracking dense_template_frames=20`, stop 77; the loose-hold flag on)"),
          ("family_dev_0_19_template_20", "Beams, development seeds 0-9 with the template averaged over up to 20 "
           "views at rest (`--seeds 0-19 --tracking dense_template_frames=20`, stop 77, stopped after seed 9 for "
           "time)"),
          ("family_plate_dev_std_stop76", "Plates, development seeds (every shelf of 0-29 and the plates bolted at "
           "both ends 0, 2, 3, 14, 18, 19) rerun in stop 76 with each parameter's standard deviation recorded, before "
           "the flag was set on them (composed of `family_plate_dev_0_3_stop76`, `family_plate_dev_shelves_stop76` and "
           "`family_plate_dev_clamped_stop76`)"),
          ("family_dev_0_19_std", "Beams, development seeds 0-19 rerun in stop 76 with the standard deviation "
           "recorded, before the flag (`--seeds 0-19 --out family_dev_0_19_std`)"),
          ("family_plate_stop49", "Plates, held-out seeds 1000-1019 on the code of stop 49 (before the SLAM and "
           "tracker changes of stops 50-73 and the registration's second coarse pass: 1016 never placed)"),
          ("family_plate_dev_stop74", "Plates, development seeds 0-9 on the code of stop 74 (`--object plate --seeds "
           "0-9 --out family_plate_dev_stop74`)"),
          ("family_plate_dev", "Plates, development seeds 0-9 on the code of stop 49 (`--object plate --seeds 0-9`)"),
          ("family_plate_dev_10_29", "Plates, development seeds 10-29 (`--object plate --seeds 10-29`; stop 73's code, "
           "before the registration's second coarse pass: seed 13 never placed)"),
          ("family_plate_dev_13_facing", "Plates, development seed 13 with the registration's second coarse pass "
           "(stop 74)"),
          ("family_plate_stop48", "Plates, held-out seeds 1000-1019 on the code of stop 48 (the coarse search fitted "
           "each candidate's brightness on every frame: `--tracking dense_grid_brightness=always`)"),
          ("family_plate_dev_stop39", "Plates, development seeds 0-9 on the code of stop 39 (the shading fused over "
           "frames; the coarse search at the previous frame's brightness)"),
          ("family_plate_stop39", "Plates, held-out seeds 1000-1019 on the code of stop 39 (before the coarse "
           "search fitted each candidate's brightness)"),
          ("family_plate_stop38", "Plates, held-out seeds 1000-1019 on the code of stop 38 (the shading term, each "
           "frame's g alone: what `--tracking dense_shading_frames=0` gives)"),
          ("family_plate_dev_stop38", "Plates, development seeds 0-9 on the code of stop 38 (each frame's g alone: "
           "`--tracking dense_shading_frames=0`)"),
          ("family_plate_dev_stop37", "Plates, development seeds 0-9 on the code of stop 37, before the shading term "
           "(what `--tracking dense_shading=false` gives: seeds 1 and 7 rerun with it in stop 38 read the same "
           "medians to the digit)"),
          ("family_plate_dev_depth_fit", "Plates, knob: map points with the state read from every depth image "
           "instead of the dense measurement (`--object plate --seeds 0-9 --measurements map_points --tracking "
           "depth_fit=true`, stop 73)"),
          ("family_plate_dev_dense_rigid_false", "Plates, knob: no rigid correction (`--object plate --seeds 7 "
           "--tracking dense_rigid=false`), on the development plate whose s_y was worst (stop-37 code, before the "
           "shading term)"),
          ("family_boot", "The joint boot, held-out seeds (`python -m benchmarks.family_boot`: seeds 1000-1099; "
           "the lever angle theta, the turn alpha_z unknown; alpha_z searched until first seen, the registration "
           "polished; the map keeps the points linked at rest, no copies of followed points, a parameter the frame "
           "does not measure keeps its value; Huber alone; the lever read from every depth image, "
           "`tracking.depth_fit`; alpha_z reported with the depth fit's turn, `tracking.depth_turn`; both set in the "
           "boot's family scene file), rerun in stop 124 with ORB-SLAM2's keyframe points the default and the "
           "tracker's mend for constants on an AMD EPYC host (median 0.32 %, p90 0.70 %, 94 % within 1 %, 97 % "
           "within 2 %, every frame of all 100 tracked; stop 123's run with the cap of the 250 nearest, commit "
           "706df3b, table 124a730, the same host: 0.35 %, 0.78 %, 93 %, 97 %, `python -m benchmarks.rerun_diff "
           "family_boot --against 124a730`; stop 114's run of that code path on an Intel host: 0.38 %, 0.88 %, "
           "93 %, 98 %, every registration the same to 1e-7 mm and the scenes' levers moved by 0.03 points at the "
           "median, both ways: the host's arithmetic, stop 123's `rerun_diff` of its cap run against 02d378c; "
           "stop 105's table, commit 57695f1: 0.38 %, 0.80 %, 94 %, 97 %; stop 73's stood until then)"),
          ("family_boot_close_points", "The joint boot, held-out seeds: an RGB-D keyframe's new points by "
           "ORB-SLAM2's rule, a knob then (`--slam keyframe_depth_points=0 --out family_boot_close_points`, stop 123, "
           "once, after the development tables below; the same host as `family_boot` above; without stop 124's "
           "tracker mend: 98 rows the same as `family_boot`'s)"),
          ("family_boot_dev_close_points", "The joint boot, development seeds 0-19, knob: an RGB-D keyframe's new "
           "points by ORB-SLAM2's rule (`--seeds 0-19 --slam keyframe_depth_points=0 --out "
           "family_boot_dev_close_points`; run in stop 123 while it was the default)"),
          ("family_boot_dev_nearest250", "The joint boot, development seeds 0-19, knob: a keyframe's new points from "
           "its 250 nearest features, stop 123's default (`--seeds 0-19 --slam keyframe_depth_points=250 --out "
           "family_boot_dev_nearest250`), run beside the one above (its nearest sorted stably then, as the default "
           "does not: the same points but where two features' depths tie at the 250th)"),
          ("family_dev_0_19_close_points", "Beams, development seeds 0-19, an RGB-D keyframe's new points by "
           "ORB-SLAM2's rule (`--seeds 0-19 --slam keyframe_depth_points=0 --out family_dev_0_19_close_points`, stop "
           "124, before it became the default; run beside the one below)"),
          ("family_dev_0_19_nearest250", "Beams, development seeds 0-19, a keyframe's new points from its 250 nearest "
           "features, stop 123's default (`--seeds 0-19 --slam keyframe_depth_points=250 --out "
           "family_dev_0_19_nearest250`, stop 124)"),
          ("family_dev_stereo_0_9_close_points", "Stereo beams, development seeds 0-9, a keyframe's new points by "
           "ORB-SLAM2's rule (`--sensor stereo --seeds 0-19 --slam keyframe_depth_points=0`, stop 124, stopped after "
           "10 seeds for time and composed with `--seeds 0-9 --compose`; run beside the one below)"),
          ("family_dev_stereo_0_9_nearest250", "Stereo beams, development seeds 0-9, a keyframe's new points from its "
           "250 nearest features, stop 123's default (`--sensor stereo --slam keyframe_depth_points=250`, as above)"),
          ("family_boot_dev_0_19_stop105", "The joint boot, development seeds 0-19 on stop 105's code (`--seeds 0-19 "
           "--jobs 1 --out family_boot_dev_0_19_stop105`): the turn about the axis searched where the boot is found "
           "bent; every row's figures the same as stop 104's code gave in a run beside it (scratch), the times apart"),
          ("family_boot_stop72", "The joint boot, held-out seeds 1000-1019 on stop 72's code (the same fits as stop "
           "73's first 20 rows, to the bit; the depth fit's search trees built every step)"),
          ("family_boot_dev_0_39_stop72", "The joint boot, development seeds 0-39 (`--seeds 0-39 --out "
           "family_boot_dev_0_39_stop72`), stop 72's code: the depth fit sped up, alpha_z with the depth's turn"),
          ("family_boot_dev_0_39_depth_stride_3", "The joint boot, knob: the depth fit on one depth pixel in 3 along "
           "each axis instead of 2 (`--seeds 0-39 --tracking depth_stride=3`, stop 73; the development seeds' "
           "defaults are `family_boot_dev_0_39_stop72`, the same fits as stop 73's code)"),
          ("family_boot_dev_stop87", "The joint boot, development seeds 0-9 on stop 87's code (`--seeds 0-9 --out "
           "family_boot_dev_stop87`): a constant seen well is held at the median of the frames that saw it"),
          ("family_boot_dev_stop87_before", "The joint boot, development seeds 0-9 on stop 87's code before that rule "
           "(commit 4e9090d, `--out family_boot_dev_stop87_before`), run right after the table above"),
          ("family_boot_dev_stop88", "The joint boot, development seeds 0-9 on stop 88's code (`--seeds 0-9 --out "
           "family_boot_dev_stop88`): a frame with too few image measurements read from its depth alone "
           "(`tracking.depth_alone`), the support plane's RANSAC on a subset of the points"),
          ("family_boot_stop88_1000_1019", "The joint boot, held-out seeds 1000-1019 on stop 88's code (`--seeds "
           "1000-1019 --out family_boot_stop88_1000_1019`, run once after the choices above)"),
          ("family_boot_dev_hold_spin", "The joint boot, development seeds 0-9 on stop 89's code (`--seeds 0-9 --out "
           "family_boot_dev_hold_spin`): the registration's ICP steps hold the boot's turn about its axis"),
          ("family_boot_stop89_1000_1019", "The joint boot, held-out seeds 1000-1019 on stop 89's code (`--seeds "
           "1000-1019 --out family_boot_stop89_1000_1019`, run once after the choice above)"),
          ("family_1081_slide_guess", "Held-out seed 1081 on stop 90's code (`--seeds 1081 --out "
           "family_1081_slide_guess`): a fit that can only slide placed along its axis by the guess, doubted"),
          ("family_boot_stop87code_4seeds", "The joint boot, held-out seeds 1002, 1005, 1008, 1013 on stop 87's code "
           "(commit aef7d81), run after the table above to find what moved them"),
          ("family_boot_stop88_4seeds_depth_alone_false", "The joint boot, the same four held-out seeds on stop 88's "
           "code with `--tracking depth_alone=false`"),
          ("family_boot_dev_stop88_depth_alone_false", "The joint boot, development seeds 0-9 on stop 88's code with "
           "`--tracking depth_alone=false` (such a frame lost, as before), run right after the table above"),
          ("family_boot_stop71", "The joint boot, held-out seeds 1000-1019 on stop 71's code (the lever read from "
           "every depth image; alpha_z from the images alone)"),
          ("family_boot_dev_0_39_depth_fit", "The joint boot, development seeds 0-39 with the lever read from every "
           "depth image (`--seeds 0-39 --tracking depth_fit=true`, stop 71; the scene file's setting since)"),
          ("family_boot_dev_0_39_depth_turn", "The joint boot, development seeds 0-39, stop 71's variant reverted "
           "(commit 8aaae21: alpha_z reported with the depth fit's turn; the lever as in the table above, to the bit)"),
          ("family_boot_depth_turn", "The joint boot, held-out seeds 1000-1019, stop 71's variant reverted (commit "
           "8aaae21: alpha_z reported with the depth fit's turn; the lever as in `family_boot_stop71`, to the bit)"),
          ("family_boot_stop70", "The joint boot, held-out seeds 1000-1019 on stop 70's code (the lever from the "
           "images alone; the boot registered as a body of revolution)"),
          ("family_boot_dev_0_39", "The joint boot, development seeds 0-39 on stop 70's code (`--seeds 0-39 --out "
           "family_boot_dev_0_39`; the lever from the images alone)"),
          ("family_boot_dev_0_39_guess_turn_7_5", "The joint boot, development seeds 0-39 with the guess turned 7.5 "
           "degrees about the boot's axis (`--seeds 0-39 --guess-turn 7.5`: a turn the depth does not show and the "
           "user does not know; stop 70)"),
          ("family_boot_dev_0_39_icp_turn", "The joint boot, development seeds 0-39, stop 70's first version: the "
           "axis's tilt judged against the guess, the fit left at the turn about the axis the ICP drifted to"),
          ("family_boot_stop66", "The joint boot, held-out seeds 1000-1019 on stop 66's code (before stop 70's "
           "registration of a body of revolution), stop 66's host"),
          ("family_boot_dev", "The joint boot, development seeds 0-9 (`python -m benchmarks.family_boot --seeds "
           "0-9`), stop 66's code and host (before stop 70's registration of a body of revolution)"),
          ("family_boot_dev_10_19", "The joint boot, development seeds 10-19 (`--seeds 10-19 --out "
           "family_boot_dev_10_19`), stop 66's code and host"),
          ("family_boot_dev_20_39", "The joint boot, development seeds 20-39 (`--seeds 20-39 --out "
           "family_boot_dev_20_39`; new in stop 66), stop 66's code"),
          ("family_boot_dev_0_39_coherence_px_8", "The joint boot, knob: object measurements that move unlike their "
           "image neighbours dropped (`--seeds 0-39 --slam coherence_px=8`; default off), development seeds 0-39 "
           "(stop 68)"),
          ("family_boot_coherence_px_8", "The joint boot, knob: `--slam coherence_px=8`, held-out seeds 1000-1019 "
           "(stop 68)"),
          ("family_boot_dev_0_39_flow_anchor_px_1", "The joint boot, knob: each followed object point re-measured "
           "against the image its track began in (`--seeds 0-39 --slam flow_anchor_px=1`; default off), development "
           "seeds 0-39 (stop 68)"),
          ("family_boot_outlier_refits_3", "The joint boot, knob: each frame's fit refitted on its inliers "
           "(`--tracking outlier_refits=3`, ORB-SLAM2's rounds), held-out seeds 1000-1019 (run while it was the "
           "default)"),
          ("family_boot_dev_outlier_refits_3", "The joint boot, knob: `--tracking outlier_refits=3`, development "
           "seeds 0-9"),
          ("family_boot_dev_10_19_outlier_refits_3", "The joint boot, knob: `--tracking outlier_refits=3`, "
           "development seeds 10-19"),
          ("family_boot_dev_20_39_outlier_refits_3", "The joint boot, knob: `--tracking outlier_refits=3`, "
           "development seeds 20-39"),
          ("family_boot_dev_outlier_refits_3_unguarded", "The joint boot, knob: the refits' first version (a round "
           "that lost inliers was kept), development seeds 0-9"),
          ("family_boot_dev_10_19_outlier_refits_3_unguarded", "The joint boot, knob: the refits' first version, "
           "development seeds 10-19"),
          ("family_boot_dev_0_39_deformable_radius_6", "The joint boot, knob: the followed object points re-acquired "
           "by ORB only within 6 px of their prediction (`--seeds 0-39 --slam deformable_radius=6`; default 20 px), "
           "development seeds 0-39 (stop 67)"),
          ("family_boot_dev_sel_deformable_radius_0", "The joint boot, knob: no ORB re-acquisition of the followed "
           "object points but the wide one after most tracks are lost (`--slam deformable_radius=0`), development "
           "seeds 10, 12 (traced) and 7, 29, 26, 24 (those the 6 px knob lost) (stop 67)"),
          ("family_boot_stop65", "The joint boot, held-out seeds 1000-1019, stop 65's run (the same code as "
           "`family_boot_stop66`, an earlier session's host)"),
          ("family_boot_dev_stop65", "The joint boot, development seeds 0-9, stop 65's run (an earlier host)"),
          ("family_boot_dev_10_19_stop65", "The joint boot, development seeds 10-19, stop 65's run (an earlier "
           "host)"),
          ("family_boot_dev_hold_rest_points_false", "The joint boot, knob: the map culls the points linked at rest "
           "too (`--slam hold_rest_points=false`), development seeds 0-9 (the run was stopped before 10-19; the table "
           "written from its rows), stop 65's code otherwise"),
          ("family_dev_0_19_stop65", "Beams, development seeds 0-19 on stop 65's code (`--seeds 0-19 --out "
           "family_dev_0_19_stop65`): the map's new handling of object points checked on the beams (dense "
           "measurement; the run shared the cores with the test suite, its times are not comparable)"),
          ("family_boot_dev_followed_px_0", "The joint boot, knob: keyframes may copy followed object points "
           "(`--slam followed_px=0`), development seeds 0-9, stop 65's code otherwise"),
          ("family_boot_stop64", "The joint boot, held-out seeds 1000-1019, stop 64's code (every young object point "
           "culled)"),
          ("family_boot_dev_stop64", "The joint boot, development seeds 0-9, stop 64's code; run again as "
           "`family_boot_dev_repeat`: the same in every row and frame"),
          ("family_boot_dev_10_19_stop64", "The joint boot, development seeds 10-19, stop 64's code"),
          ("family_boot_stop63", "The joint boot, held-out seeds 1000-1019, stop 63's run (Open3D's ICP: one draw of "
           "the run-to-run spread)"),
          ("family_boot_dev_polish_4", "The joint boot, development seeds 0-9 with the registration polished "
           "(`anchor.polish_mm: 4`: the family's boot scene file since stop 63), stop 63's run (Open3D's ICP)"),
          ("family_boot_registration", "The joint boot's registration alone, held-out seeds 1000-1099 (`python -m "
           "benchmarks.family_boot --registration`: up to three tries each), stop 115's code (stop 70's run, "
           "2026-11-30, seeds 1000-1019 and one try: median 0.12 mm, worst 0.24 mm, none refused; here the same "
           "seeds read 0.15 mm, and 1013's first try is refused, its second 0.34 mm off)"),
          ("family_boot_registration_dev_polish_4", "The joint boot's registration alone, development seeds 0-9, "
           "`--anchor polish_mm=4` (chosen on this table)"),
          ("family_boot_registration_dev_before_polish", "The joint boot's registration alone, development seeds 0-9, "
           "the RGB-D defaults (no polish)"),
          ("family_boot_registration_dev_hold_spin", "The joint boot's registration alone, development seeds 0-9, "
           "stop 89: the ICP steps hold the boot's turn about its axis (`--jobs 1`)"),
          ("family_boot_registration_dev_plane_samples", "The joint boot's registration alone, development seeds "
           "0-9, stop 88: the support plane's RANSAC on 20 000 of the fused points (`--jobs 1`)"),
          ("family_boot_registration_dev_before_plane_samples", "The joint boot's registration alone, development "
           "seeds 0-9, the code before (RANSAC on every fused point; `--jobs 1`), run right before the table above"),
          ("family_boot_registration_dev_upright", "The joint boot's registration alone, knob: `--anchor fine=upright` "
           "(roll and pitch from the support plane), development seeds 0-9, no polish"),
          ("family_boot_before_polish", "The joint boot, held-out seeds 1000-1019 with the search after its fix, "
           "before the polish (stop 63)"),
          ("family_boot_fix_1000_1011", "The joint boot, held-out seeds 1000-1011 after the search's fix (the "
           "static-point set restored with the links), stop 62's rerun interrupted at 12 of 20 scenes: the same code "
           "as `family_boot_before_polish`, run again"),
          ("family_boot_dev_constant_search_24", "The joint boot, development seeds 0-9 with alpha_z searched over 24 "
           "values until first seen (`--tracking constant_search=24`), rerun in stop 63 after the search's fix, "
           "before the polish"),
          ("family_boot_dev_search_until_frozen", "The joint boot, knob: alpha_z searched on every frame until it is "
           "fixed (`--tracking constant_search_until=frozen`), development seeds 0-9, before the polish"),
          ("family_boot_before_search", "The joint boot, held-out seeds 1000-1019 before the search (stop 62's first "
           "run: the thesis boot scene file's settings alone)"),
          ("family_boot_dev_before_search", "The joint boot, development seeds 0-9 before the search (stop 62's "
           "first run)"),
          ("family_boot_dev_constant_frames_15", "The joint boot, knob: alpha_z fixed over 15 informative frames, not "
           "40 (`--tracking constant_frames=15`: the tracker's own default), development seeds 0-9, before the "
           "search"),
          ("family_boot_dev_freeze_map", "The joint boot, knob: no new map points once the boot deforms "
           "(`--localization freeze_map_on_deformation=true`, thesis §4.4.1), development seeds 0-9, before the "
           "search"),
          ("family_dev_0_19_other", "Development seeds 0-19 on the code of stop 57 rerun in stop 58 on another "
           "host (AMD EPYC; every row the same as the table below) with where the other basin's fit ended recorded: "
           "the low-confidence flag `max_ambiguity_gap` was set on its frames (`flag_calibration_ambiguity`)"),
          ("family_dev_warm", "Development seeds with the defaults of stop 58 (the last frame's basin fitted too "
           "where both fits of the basin check end far from it: `dense_basin_warm: true`): the seeds where a frame "
           "met that condition in the table above (0, 1, 6, 7, 11, 14, 16, 17) and seed 9, where none did"),
          ("family_dev_0_19_basin", "Development seeds 0-19 with the defaults of stop 57 (the other basin fitted "
           "at full detail where the coarse search's runner-up costs under 10 % more than its winner: "
           "`dense_basin_check: 0.1`), beside the knob below"),
          ("family_dev_basin_off_switched", "Knob: no second basin (`--tracking dense_basin_check=0`: the defaults "
           "before stop 57) on the development seeds where the check moved a frame (5, 6, 7, 8, 9, 11, 14, 16), the "
           "same code otherwise, run right after the table above"),
          ("family_dev_0_19", "Development seeds 0-19 with the defaults of stop 49 (the coarse search fits each "
           "candidate's brightness only after a frame whose gain fell under 0.5: `dense_grid_brightness: auto`), "
           "beside the two knobs below"),
          ("family_dev_0_19_dense_grid_brightness_always", "Knob: the coarse search fits each candidate's brightness "
           "on every frame (`--tracking dense_grid_brightness=always`: the defaults of stop 48, run in stop 48)"),
          ("family_dev_0_19_dense_grid_brightness_false", "Knob: the coarse search at the previous frame's brightness "
           "(`--tracking dense_grid_brightness=false` in stop 48, `never` now: the defaults before stop 48), run in "
           "stop 48 right after the table above"),
          ("family_dev_0_19_stop38", "Development seeds 0-19 with the defaults of stop 38 (the shading term on), "
           "beside the knob below"),
          ("family_dev_0_19_dense_shading_frames_50", "Development seeds 0-19 with the shading fused over 50 frames "
           "(`--tracking dense_shading_frames=50`: the defaults of stop 39), beside the table above (stop 38's, each "
           "frame's g alone)"),
          ("family_dev_0_19_dense_shading_false", "Knob: no shading term (`--tracking dense_shading=false`, seeds "
           "0-19): the affine brightness alone, the defaults before stop 38"),
          ("family_dev_dense_refine_false", "Knob: no search of the cost after Gauss-Newton "
           "(`--tracking dense_refine=false`: the defaults of stop 25, with the slide pin)"),
          ("family_dev_dense_camera_first_true", "Knob: the camera's error from the surroundings first, then held "
           "(`--tracking dense_camera_first=true`; rerun with the slide pin in stop 29)"),
          ("family_dev_camera_check_0_5", "Development seeds 0-5 with the defaults (stop 35: the check of the camera "
           "against the surroundings alone on), beside the knob below"),
          ("family_dev_dense_camera_check_false", "Knob: no check of the camera against the surroundings alone "
           "(`--tracking dense_camera_check=false`, seeds 0-5): the same estimates and, on these scenes, the same "
           "states; its tracker times are not comparable with the table above (this run shared the 2 cores with "
           "two other jobs): measured alone, the check costs 66 -> 81 ms per frame on seed 3 (docs/stability.md)"),
          ("family_dev_stop25", "Development seeds 0-11, 27, 31, 44, 46 on the code of stop 25 (before the search "
           "of the cost; kept as the baseline of the knob tables below, which ran on the same code)"),
          ("family_dev_map_points", "Development seeds 0-9, sparse measurements (`--measurements map_points`) "
           "beside: their accuracy, and the tracker's time per frame (target <= 10 ms p50)"),
          ("family_dev_dense_step_px_3", "Stop-25 code. Knob: dense samples 3 px apart, not 1.5 "
           "(`--tracking dense_step_px=3`)"),
          ("family_dev_dense_rigid_false", "Stop-25 code. Knob: no rigid correction (`--tracking dense_rigid=false`)"),
          ("family_dev_dense_surroundings_px_0", "Stop-25 code. Knob: the rigid correction on the object alone, no "
           "surroundings (`--tracking dense_surroundings_px=0`; the defaults before the surroundings)"),
          ("family_preloaded", "The load on from the first frame: development seeds (the reference state from "
           "depth was designed on these)"),
          ("family_preloaded_dev_20_49", "The load on from the first frame: development seeds 20-49 (`--seeds 20-49 "
           "--preloaded --out family_preloaded_dev_20_49`, stop 119: more development scenes for the loaded "
           "cantilevers)"),
          ("family_preloaded_heldout", "The load on from the first frame: held-out seeds (rerun in stop 126 on "
           "ORB-SLAM2's keyframe points and the reference view's mend, an AMD EPYC host; its run before, with the cap, "
           "on an Intel host, table 7503588: 0.73 %, p90 3.19 %, 63 % within 1 %, 83 % within 2 %)"),
          ("family_preloaded_heldout_reference_rest", "The load on from the first frame, held-out seeds 1000-1014, the "
           "reference taken to be the rest shape (`--tracking reference=rest`, the behaviour before stop 30)"),
          ("family_stereo", "Stereo pair: held-out seeds (`--sensor stereo --seeds 1000-1029`; rerun in stop 126 "
           "after the reference view's mend, ORB-SLAM2's keyframe points, an AMD EPYC host; stop 125's run before the "
           "mend: 0.60 %, p90 2.49 %, 67 % within 1 %, 87 % within 2 %; its last run with the cap of the 250 nearest, "
           "on an Intel host, table 5ca0eff: 0.53 %, 1.87 %, 73 %, 93 %)"),
          ("family_stereo_cap_probe", "Stereo pair: the three held-out scenes stop 125's rerun moved most (two over "
           "2 %), with the cap of the 250 nearest on the same host (`--sensor stereo --seeds 1001,1004,1023 --slam "
           "keyframe_depth_points=250 --out family_stereo_cap_probe`, a diagnosis)"),
          ("family_dev_stereo_0_19_close_points", "Stereo pair: development seeds 0-19, ORB-SLAM2's keyframe points "
           "(the default; `--compose family_dev_stereo_0_9_close_points,family_dev_stereo_10_19_close_points`: "
           "stop 124's run of 0-9, before the tracker's mend, and stop 125's of 10-19)"),
          ("family_dev_stereo_0_19_nearest250", "Stereo pair: development seeds 0-19, the cap of the 250 nearest (a "
           "knob; composed as above from `family_dev_stereo_0_9_nearest250` and "
           "`family_dev_stereo_10_19_nearest250`)"),
          ("family_dev_stereo", "Stereo pair: development seeds 0-19 (`--sensor stereo`)"),
          ("family_stereo_stop60", "Stereo pair: held-out seeds before stop 61 replaced 1001's row"),
          ("family_dev_stereo_stop60", "Stereo pair: development seeds 0-19 before stop 61 replaced 5, 14 and 18"),
          ("family_dev_rgbd_0_19", "RGB-D on the same development seeds 0-19 and the same code, beside the stereo "
           "table (`--seeds 0-19 --out family_dev_rgbd_0_19`)"),
          ("family_registration_stereo", "Stereo pair: the registration step alone, development seeds 0-9 "
           "(`--registration --sensor stereo`)"),
          ("family_registration_preloaded", "Loaded beams: the registration step alone, development seeds 0-49 "
           "(`--registration --preloaded`)"),
          ("family_registration_preloaded_heldout", "Loaded beams: the registration step alone, held-out seeds "
           "1000-1029 (`--registration --preloaded --seeds 1000-1029`)"))


def write_doc() -> None:
    """docs/family.md: the introduction, then each results table that exists (held-out, development, preloaded)."""
    parts = [INTRO]
    for name, heading in TABLES:
        md = RESULTS / f"{name}.md"
        if md.exists():
            body = md.read_text().replace(f"]({name}.png)", f"](../benchmarks/results/{name}.png)")
            parts.append(f"## {heading}\n\n`benchmarks/results/{name}.md`:\n" + body.split("\n", 1)[1])
    (Path(__file__).resolve().parents[1] / "docs" / "family.md").write_text("\n".join(parts))


INTRO = """# The scene family: deformable tracking on scenes it was not built for

Made by `./run bench family` (held-out seeds) or `python -m benchmarks.family --seeds 0-49` (development seeds);
the table below is its output, with the label of the seeds it ran on.

What a scene is (`simreal_nodes/synth/family.py`, `simreal make-bag family --seed N`): a loaded beam drawn at
random — cantilever or two supports, length 0.3-1 m, slenderness 10-60 (8-40 on two supports), section width 1-4x
its height, E 1e6-7e10 Pa, nu 0-0.45, a weight whose size makes the largest surface motion 2-40 px at the drawn
camera distance, a speckle texture from faint (contrast 0.04) to painted (1.0) with 1.5-6 mm speckles, 0-11
pieces of clutter of drawn contrast, drawn lighting, pixel noise sigma 0.5-3, motion blur of 1-3 sub-frames, the
camera on an arc of 20-70 degrees at 1.1-2x the beam length, 640x480 RGB-D at 15 fps, the load placed at 4-6
positions after 1.5 s of unloaded mapping.

The rules that make it evidence:

- **Held-out seeds.** Defaults may be chosen on the development seeds 0-49 only; accuracy is quoted on the
  held-out seeds 1000-1099, which nothing was tuned on.
- **No inverse crime.** The images are rendered from an independent full-order solve (`synth/truth.py`:
  quadratic tetrahedra on a finer grid, the weight as a pressure over its footprint), never from the reduced
  model the tracker fits (hexahedra, a nodal force on the centreline). Both discretise the same continuum
  problem: the truth's grid along the beam is a whole multiple of the model's so that a support strip ends on a
  node of both (before that alignment, the strips' discrete widths differed and the model error was 2.3 % of
  the range on seed 0 instead of 0.08 %). The tests check the truth against Euler-Bernoulli (3 %).
- **Model error stated.** Each row gives the model's own error: its relative displacement error against the
  truth, and its load-position bias — the least-squares best fit of the model to the truth's surface
  displacement, what a tracker that saw every surface point exactly would report.
- **No truth in the scene file**: the object is placed by `anchor: registration` (support plane, then ICP of the
  model surface to the first depth images) from a guess as a user gives it by eye, the true pose in the first
  camera frame moved by about 5 cm and 10 degrees rms; the registration's pose error against the truth is in
  each row (`python -m benchmarks.family --seeds 0-9 --registration` measures that step alone:
  `benchmarks/results/family_registration.md`: 0.47 mm and 0.14 degrees at the median on seeds 0-9; the
  held-out rows carry the registration's error for every scene). The guess is the one number in a scene
  file computed from the truth (in the first camera frame, through the rendered trajectory): 5 cm / 10 degrees
  off, it only picks the basin.

Where we stand (the tables below). The defaults are the dense measurement with the static surroundings
(`tracking.measurements: dense`, `dense_surroundings_px: 32`, `docs/tracking.md`) ending in a search of the cost
(`dense_refine: true`), with the shading of the turning surface modelled (`dense_shading: true`, stop 38) and fused
over frames (`dense_shading_frames: 50`, stop 39), the coarse search comparing each candidate at the brightness fitted
to it after a frame whose brightness gain fell under 0.5 (`dense_grid_brightness: auto`, stop 49), the template
averaged over up to 20 views at rest (`dense_template_frames: 20`, stop 78; the held-out table `family` is on it since
stop 80, rerun in stop 125 with ORB-SLAM2's keyframe points: 0.43 % at the median of the 100 scene medians, p90 1.39 %,
99 % within 2 %), registration with the slide pin
(a prism's position along its axis, from its end faces) and the object-aware ORB budget. They were chosen on
development seeds only: dense against the sparse `map_points` on seeds 0-9 (0.83 % against 7.0 % median of per-scene
medians, before the surroundings), then the surroundings on seeds 0-11, 27, 31, 44 and 46, where cantilevers with a
large load had failed (the knob table 'no surroundings' below is the previous default on the same seeds: seed 10 18 %,
seed 27 15 %, seed 46 24 %; with the surroundings 0.1 %, 0.3 % and 0.2 %), then the search of the cost and the slide
pin on seeds 12-49 (the search, on the same code otherwise: 84 % -> 95 % of scenes within 2 %, p90 2.5 % -> 1.2 %; the
slide pin brought seed 48's registration to 1.8 mm (the run before it was not kept); measuring the camera's error on
the surroundings first did worse than the joint fit, also when rerun with the slide pin in stop 29 (87 % within 2 %,
p90 2.4 %, unchanged; seed 48 5.4 % against the joint fit's 4.4 %), and stays a knob, off). The development tables'
tracker times (157 ms with the search, 70 ms without) differ by more than the search costs: the knob's table ran alone
on this host in this stop, the defaults' table in an earlier session under a load not recorded, so the two do not
compare (a measurement of one scene alone, seed 13, was not kept).

Stop 48 made the dense fit's coarse search compare each candidate at the brightness (a, b, g) fitted to it
(`tracking.dense_grid_brightness`, on; docs/tracking.md), after a camera-sweep view of development seed 0 (65
degrees of azimuth) stayed 28-58 % off once its brightness had collapsed in misaligned frames; and it flags a fit
whose brightness gain is under 0.5. Chosen on development beams 0-19 (`family_dev_0_19_dense_grid_brightness_always`
against `family_dev_0_19_dense_grid_brightness_false`, the same code otherwise, run one after the other): no scene
worse by more than 0.01 points, seed 7 0.56 % -> 0.54 % (p90 1.62 % -> 1.35 %), seed 12 0.83 % -> 0.77 % (p90 1.95 %
-> 1.74 %), the tracker 5-10 % slower per frame. All 100 held-out rows were rerun with it (`family_stop48`; stop
39's is `family_stop39`): median of the per-scene medians 0.50 % (0.50 % in stop 39), p90 1.58 % (1.58 %), 77 %
within 1 % (76 %) and 95 % within 2 % (95 %); 98 scenes within 0.1 points of stop 39's median, 1003 2.22 % -> 2.34 %
and 1011 1.91 % -> 1.69 %; two supports 0.38 % (100 % within 2 %), cantilevers 0.58 % (90 %). At or over 2 %: 1003
(2.3 %), 1056 (2.2 %), 1065 (2.4 %), 1070 (2.0 %, flagged on every frame) and 1081 (never placed), as in stop 39.
The change did not carry over to the held-out beams in accuracy: its gains are in the camera sweep's failing views
(docs/stability.md). Two held-out scenes keep frames called OK far off, as in stop 39: 1071 and 1041 (two-support
beams, L/h 8-11, loads under 2.5 px), the 90th percentile of their OK frames 71 % and 57 % of the span; not looked
into in this stop. The tracker's time in this table (244 ms per frame at the median of the rows, 156 ms in stop
39's) is not comparable: this run shared the 2 cores with two other benchmarks for most of its length. The
development table of stop 38 that the next paragraph compares with is kept as `family_dev_0_19_stop38`.

Stop 60 found why the camera was lost on development seeds 14 and 41 and held-out 1050 and 1087, the only scenes of
these tables where it was (76-86 % of frames tracked), and why seed 36's SLAM error jumped: the drawn arc took the
camera through a side wall of the room (past its inner face), so the view filled with the wall's texture at a few
centimetres, where the depth camera reads almost nothing (a trace of seed 14's frames there, scratch, not kept).
Nothing the SLAM could map, and no scene a user would film. The room (`synth/scenes.py:add_environment`) is now
widened wherever a drawn path would come within `WALL_CLEARANCE_M` = 0.1 m of a side wall (`room_half_width`; on the
development seeds a path nearer the wall than that without reaching it, seeds 5, 18 and 46, had tracked as well as
any). The draws, physics and every other scene are unchanged; 12 of the 150 beams (6 development, 6 held-out; no
plate) get a wider room and were rerun on the defaults. Development (`family_dev_room`): seed 14's p90 82.4 % ->
0.44 %, 41's 38.1 % -> 0.71 %, 36's 40.2 % -> 1.21 % (median 0.57 % -> 0.33 %; its camera ATE 9.4 -> 5.5 mm), all
frames tracked; 5, 18 and 46 within 0.31 points of their medians (5: 0.96 % -> 0.65 %, 18 and 46 within 0.04). Held
out (`family_room`): 1050's p90 7.37 % -> 0.56 % and 1087's 64.4 % -> 0.52 %, both now tracked on every frame; 1001,
1049, 1062 and 1068 within 0.05 points of their medians. The main table was then stop 59's with those six rows
replaced (`python -m benchmarks.family --compose family_stop59,family_room --out family`; since stop 80 `family` is
another run): the summary was unchanged (0.50 %, p90 1.50 %, 80 % within 1 %, 96 % within 2 %), the camera is now
tracked on **100 % of the frames of all 100 held-out scenes** (1050 77 % and 1087 78 % before), frames more than 2 %
of the span off 873 -> 828, more than 10 % off 138 -> 111; frames called OK more than 10 % off stay 7 (1041's six,
1056's one). Older tables that hold one of the 12 seeds were run in the old room, but for the stereo tables: stop 61
reran their four (development 5, 14 and 18, held-out 1001) in the wider room on its own code and composed them in
(below).

Stop 59 looked for development evidence for stop 58's third fit and found none. The development beams 20-49, last run
on the defaults of 2026-11-23 (`family_dev`), ran with it on (`family_dev_20_49`): median of the per-scene medians
0.49 % (0.57 % on the old defaults), p90 1.46 % (1.49 %), 80 % within 1 % (77 %), 90 % within 2 % (93 %: seed 30 1.93
% -> 2.47 %); seed 32's p90 92.9 % -> 1.16 %, seed 36's 9.5 % -> 40.2 % (a diagnosis run of this stop, not kept: while
the load moves along the beam, its frames read the load far from where it is with the brightness gain collapsed,
flagged low-confidence, and on those frames the SLAM's camera error jumps to several times its size before and the
camera check fires; the cause in the localization not looked into). The third fit ran on 20 frames of 15 of
these seeds and was kept on 7 frames of 7 (20, 32, 34, 36, 40, 41, 47); rerun with it off (`family_dev_warm_off`, the
same code otherwise), every row is the same to the hundredth but seed 41's (p90 36.5 % -> 38.1 % with it on: its frame
49, where the camera was about to be lost, read 0.826 against 0.815 for 0.611, and the value was held while the camera
was lost) and seed 32's mean (0.600 % -> 0.603 %). It helped no development scene, so it is off by default
(`tracking.dense_basin_warm: false`): a knob, whose held-out table is `family_stop58_warm` (`benchmarks/basin_cost.py`
measures its time). The defaults are then stop 57's tracker with stop 58's ambiguity flag, which has run on every
held-out seed, so the main table was then made of those runs (now `family_stop59`): the rows of `family_stop57`
(1000-1040, 1042-1065, Intel Xeon) and `family_stop58` (1041, 1066-1099, AMD EPYC); the flag changes a frame's state
(and so whether the frame joins the shading prior), not its estimate, and on the 35 seeds it ran on it fired only on
frames already low-confidence. Stop 55's main table is `family_stop55`. Median of the per-scene medians **0.50 %**
(stop 55: 0.49 %), p90 **1.50 %** (1.57 %), **80 %** within 1 % (79 %), **96 %** within 2 % (96 %); two supports 0.39
% (100 % within 2 %), cantilevers 0.62 % (92 %); frames called OK more than 10 % of the span off 35 -> 7 (1041's six,
1056's one), more than 2 % off 283 -> 256. At or over 2 %: 1003 (2.25 %), 1056 (2.13 %), 1065 (2.49 %) and 1081 (never
placed: its registration refused, the slide along the beam unresolved). Rerun on this stop's code
(`family_regen_check`: 1000, 1011, 1021, 1047, whose rows came from stop 57's run on the Intel host), every row the
same to the thousandth, no frame's state changed, estimates within 1.1e-5 of a range.

Stop 58 (docs/tracking.md) reran the development beams with where the other basin's fit ends recorded
(`family_dev_0_19_other`: every row as in `family_dev_0_19_basin`, on an AMD EPYC host where that ran on an Intel Xeon)
and found held-out 1041's six frames 55-58 % off to be both fits in one wrong basin, not a tie. The fit now also runs
from the last frame's estimate where both fits end more than a quarter of a range from it (`tracking.dense_basin_warm`,
on in stop 58, off since stop 59; made after looking at 1041, so 1041 is no held-out evidence for it). Development seeds
where a frame met its condition (`family_dev_warm`): every row the same to the hundredth. Held out, the 26 seeds where a
frame could meet it in the runs of stop 57's code and two where none could (`family_stop58_warm`, beside `family_stop57`
and `family_stop58`): 1041's frames called OK more than 10 % off 6 -> 0 (mean 4.61 % -> 0.89 %, median 0.88 % -> 0.76
%); elsewhere loaded estimates moved by 0.6 % of the span at most (1005 p90 0.57 % -> 0.64 %, 1062 mean 0.60 % -> 0.63
%); over the 28, median of the per-scene medians 0.56 % and p90 1.39 % either way, frames called OK more than 10 % off 7
-> 1. The held-out seeds stop 57 had not reached, 1041 and 1066-1099, ran on stop 57's code with stop 58's ambiguity
flag (`family_stop58`; the flag fired only before the load, on frames already low-confidence, so it changed no state):
median of the per-scene medians 0.51 % (the first table on the same 35 seeds: 0.54 %), p90 1.35 % (1.38 %), within 1 %
77 % (74 %), within 2 % 97 % (97 %); frames called OK more than 10 % off 31 -> 6 (1041's six), more than 2 % off 136 ->
107. With `family_stop57`, stop 57's code has run on all 100 held-out seeds (the main table since stop 59). Tracker
times in these tables are not comparable (two scenes at a time).

Stop 57 fits the other basin at full detail (`tracking.dense_basin_check`, 0.1; docs/tracking.md): where the coarse
search's best candidate from another basin costs less than 10 % more than its winner, the fit runs a second time from
that candidate and the cheaper of the two at full resolution is kept. The trigger was set from the development frames'
margins before any run with it. Development beams 0-19 (`family_dev_0_19_basin`, beside `family_dev_basin_off_switched`:
the same code with it off, on the seeds where it moved a frame): seed 9 from p90 99.5 % to 0.47 % of the span (its load
near a support read at the other support on 21 frames), seeds 6-8 within 0.07 points either way, the rest the same to
the hundredth. Held out, two runs after the trigger was fixed: the five scenes whose frames the first table called OK in
the wrong basin (`family_stop57_wrong_basin`: 1041, 1047, 1051, 1069, 1071) keep 6 frames called OK more than 10 % of
the span off, against 33 (1071 p90 71.2 % -> 1.62 %, 1069 mean 7.62 % -> 0.57 %, 1041 p90 53.1 % -> 2.20 %; 1041's 6,
which stop 57 took for two basins of the same cost, are frames where both fits ended in one wrong basin: stop 58 below);
and the held-out seeds from 1000 up in order, as far as the stop's time allowed (`family_stop57`):
seeds 1000-1065 (the run was cut there for time): median of the per-scene medians 0.50 % (the first table on the same 66
seeds: 0.49 %), p90 1.54 % (1.57 %), 82 % within 1 % (80 %), 95 % within 2 % (95 %); frames called OK more than 10 % off
16 -> 7 (1041's 6 among them), more than 2 % off 164 -> 160 (2-3 % frames of cantilevers the check did not touch: 1028
0.72 -> 0.81 %, 1029 0.69 -> 0.85 % moved with stop 56's change to the RGB-D BA, their camera ATE 1.15 -> 1.11 and 1.19
-> 1.16 mm); where it moved frames, 1011's mean 5.35 % -> 1.63 % and 1021's 1.48 % -> 0.52 %. Its tracker times are not
comparable (three runs shared the 2 cores).

Stop 55 reran the held-out seeds on the SLAM as it is now (the first table; seeds 1000-1036 in stop 55, 1037-1099 in
stop 56 from a clone of stop 55's code; promoted to the main table in stop 57 and since replaced, stop 49's is now
`family_stop49`): stops 50-55 changed the SLAM (the five-point start and keyframe fusion for monocular maps, array
covisibility queries whose ties order the BA differently, and stop 55's local BAs over every point their keyframes
see, where RGB-D's had optimized at most 800), the tracker not at all. All 100 scenes: median of the per-scene medians
0.49 % (stop 49's, `family_stop49`: 0.50 %), p90 1.57 % (1.58 %), within 1 % 79 % (76 %), within 2 % 96 % (95 %);
camera ATE median 2.06 mm (2.02 mm). At or over 2 %: 1003 (2.25 %), 1056 (2.12 %), 1065 (2.49 %) and 1081 (never
registered), as before; 1070 2.01 -> 1.79 %. 15 scenes moved by more than 0.1 points, both ways (1001 0.52 -> 0.69 %,
1014 0.66 -> 0.88 %, 1085 1.14 -> 1.37 %; 1008 1.24 -> 0.96 %, 1023 1.86 -> 1.49 %, 1089 1.58 -> 1.39 %): a wash. Stop
56's RGB-D outlier test in the BA came after this run (on the development orbit it changed nothing before a loop). Its
tracker times ran beside other benchmarks (about 1.5 times stop 49's at the median of the rows).

Stop 49 fits the candidates' brightness in the coarse search only when the warm start's gain is under 0.5
(`dense_grid_brightness: auto`): fitted on every frame (`always`, stop 48's default), a camera-sweep view of development
seed 1 at 80 degrees of azimuth picked wrong candidates (the 90th percentile of its frames called OK 0.34 % -> 9.8 % of
the span; docs/stability.md). On the development beams 0-19 (`family_dev_0_19`) `auto` reads as `never`
(`family_dev_0_19_dense_grid_brightness_false`, the defaults before stop 48) in every row to the hundredth, states and
all, but seed 14's mean (15.11 % -> 14.07 %); `always` (`family_dev_0_19_dense_grid_brightness_always`, stop 48's run)
was better on seeds 6, 7, 12 and 19 (their 90th percentile by 0.04-0.27 points, their median by up to 0.07) and worse
on none by more than 0.02: a few tenths on four scenes against a 10 % tail in a grazing view, traded for the tail
(docs/tracking.md). All 100 held-out rows were rerun (`family_stop49`; stop 48's is `family_stop48`): median of the
per-scene medians 0.50 %, p90 1.58 %, 76 % within 1 %, 95 % within 2 %, every scene's median within 0.01 points of
stop 39's (stop 48: 77 % within 1 %, 1003 2.34 % and 1011 1.69 %, now 2.22 % and 1.91 % as in stop 39). At or over 2
%: 1003, 1056, 1065, 1070 and 1081, as before; 1071 and 1041 keep their OK frames' 90th percentile at 71 % and 57 %.
The tracker's time in this table is not comparable (the run shared the 2 cores with the camera sweep and the gain
calibration).

Stop 39 fused the shading term's g over the frames the tracker judged sound (`tracking.dense_shading_frames`, 50;
docs/tracking.md), chosen on development plates and beams ("Plates" below; on development beams 0-19 every scene
within 0.2 points: `family_dev_0_19_dense_shading_frames_50` against `family_dev_0_19_stop38`). All 100 held-out rows
were rerun with it (two scenes at a time; `family_stop39`; stop 38's is `family_stop38`): median of the per-scene
medians 0.50 % (0.49 % in stop 38), p90 1.58 % (1.59 %), 76 % within 1 % (75 %) and 95 % within 2 % (96 %): the
targets still met; 96 scenes within 0.1 points of stop 38's median, the largest changes 1056 1.92 % -> 2.15 %, 1085
1.31 % -> 1.14 %, 1003 2.36 % -> 2.22 %; two supports 0.38 % (100 % within 2 %), cantilevers 0.55 % (90 %). At or over
2 %: 1003 (2.2 %), 1056 (2.2 %) and 1065 (2.5 %), loads under 3 px on faint speckles; 1070 (2.0 %, flagged on every
frame); 1081, never placed. The tracker takes 156 ms per frame at the median of the rows (148 ms in stop 38's run; the
first quarter of this run shared the host with a test run).

Stop 38 added the shading term to the dense measurement (`tracking.dense_shading`, on; docs/tracking.md), chosen on
development plates and beams ("Plates" below; on development beams 0-19 it changed no scene by more than 0.16
points: `family_dev_0_19_stop38` against `family_dev_0_19_dense_shading_false`). All 100 held-out rows were rerun
with it (`family_stop38`; two scenes at a time, alone on the AMD host): median of the per-scene medians 0.49 %,
p90 1.59 %, 75 % within 1 % and 96 % within 2 % (the run before it was not kept); on two
supports 0.38 % (100 % within 2 %), on cantilevers 0.53 % (92 %). The scenes at or over 2 %: 1003 (2.4 %) and 1065
(2.5 %), loads under 3 px on faint speckles; 1070 (2.0 %), flagged on every frame (its registration can slide 17 mm,
5.1 %); 1081, never placed (below). The tracker takes 148 ms per frame at the median of the rows (109 ms in stop
35's run: the shading term's 40-50 %, docs/tracking.md). The other beam tables below (development 12-49, the load on
from the first frame, the stereo pair, the older knobs) ran before the shading term and were not rerun. The rest of
this paragraph and the next is the history of the earlier runs.

The held-out seeds were reported several times before stop 38 (the first time without the surroundings, again in
stop 25, then after the search of the cost and the slide pin); each report steered only which development scenes
were studied (first cantilevers with a large load, then cantilevers with a small load on a faint texture), the
changes were designed and chosen on the development seeds above, and the held-out scenes were then rerun once. Those
runs' results were not kept and their figures are no longer quoted here; `family_stop38` and later tables are. What
failed then and fails still: cantilevers whose full load moves the image by under 3 px on a faint texture (a load in
the clamp's half moves the image by a fraction of a pixel and the fit reports no measurable deformation), and seed
1081, whose end faces are not seen well enough to pin the registration's slide. Since stop 29 the registration
refuses a fit that can slide over more than 60 mm at about the same cover (it refused none of development seeds
0-99); seed 1081 is refused on every try, so its beam is never placed and every frame is flagged "waiting for
registration": its row reads 39 % because the table scores the estimate's initial value on frames with no estimate.
A registration that can slide over more than 5 % of the beam (`RegistrationConfig.max_slide_share`, chosen on
development seeds, where no accepted fit passed it) is doubted on some held-out scenes placed within a few mm, so all
their frames are flagged: false alarms the development seeds did not show. The tracker's time per frame is in the
'tracker (ms)' column of each table (two scenes in parallel on the two cores: the times move with the host by tens of
percent). The sparse `map_points` tracker takes 2.7 ms per frame at the median over development seeds 0-9 (1.9-8.2
ms per scene, the whole tracker: linking, flow feedback and the LM; two scenes in parallel on the two cores, AMD
host; the issue's target is <= 10 ms), but reads the load 7.0 % off at the median there
(`family_dev_map_points`), where the dense measurement reads it within 1 % for tens of times the time.

**Stop 90: a fit that can only slide is placed along its axis by the guess.** Seed 1081's registration was refused on
every try for its slide alone (no view sees its end faces), so its beam was never placed. Now, after
`RegistrationConfig.slide_refusals` (2) such refusals of an object, each on new views, the next try keeps the fit
(`slide_from_guess`): its other five degrees of freedom are the data's, its position along the axis is the guess's
(`anchor.guess`, the user's measurement) but no further than the shifts the depth covers about as well as the best
allow, and the pose is doubted, so every estimate is flagged low-confidence with the reason
(`registration._slid_to_guess`; tests in `tests/assimilation/test_registration_rgbd.py`). Where the object is bent and
its deformation is fitted with the pose (`register_loaded`), the deformed shape may pin the slide itself (a bent beam is
not a prism): it is then placed along the axis by its own cover, as a rigid fit is, still doubted. No development seed
ever had a slide refusal, nor any other held-out scene of the current results (`family.json`: 1081 alone), so only
1081 moves. Rerun alone (`family_1081_slide_guess`): the rigid fit placed by the guess, then the loaded beam's
deformed fit pinned by its own cover: 4.4 mm and 0.21 degree off, the load read 7.52 % of its range off at the median
of the loaded frames against 39.0 % never placed (the initial value), every frame flagged. Not within 2 %: its load
moves the image by 2.1 px at most, the small-load case that also fails elsewhere (1065). The main table's row of 1081
is the run before; its median and its shares within 1 % and 2 % do not move with it (1081 is over 2 % either way).

Loaded from the first frame (`--preloaded`, `benchmarks/results/family_preloaded.md` and
`family_preloaded_heldout.md`): there is no view of the object at rest. Until stop 30 the dense measurement took
its reference view for the rest shape, so the deformation present then was never seen (the sparse links had the
same flaw): 18.7 % median on development seeds 0-4, and the rigid registration of a bent beam was refused or tilted
(seed 2: 6 degrees). Since stop 30 the object's state in the first views is read from its depth
(`assimilation/depth_state.py`, `tracking.reference: depth`, the default): the reduced model's deformed surface is
fitted to the depth cloud (non-rigid point-to-plane ICP through the PGD, with an upright rigid correction) and
compared with the rest shape fitted the same way. The registration fits the deformation with the pose
(`registration.register_loaded`), the dense template is taken where the deformed object is, and a sparse tracker
starts from that state. Its two thresholds (the deformed fit must lower the robust cost by 1 % and move the
surface by 0.5 mm) were chosen on the first frames of development seeds 0-49, loaded and unloaded (a sweep not kept):
the unloaded beams' gains fell short of 1 % and the loaded ones' passed it but one (a load next to a clamp, moving the
surface under 0.5 mm); the depth alone read the load position to a fraction of a percent of its range at the median
there and several times that at p90 (that sweep ran before the crop took the box of the model's shapes and before the
weak axis was held). On development seeds 0-19: median of the per-scene medians 0.81 % (p90 2.3 %, 85 % of scenes
within 2 %), registration 0.6 mm and 0.05 degrees at the median. On held-out seeds 1000-1029 (run once, after the
thresholds were fixed): median of the per-scene medians 1.49 % (p90 5.6 %, 37 % of scenes within 1 %, 73 % within 2 %;
two supports 1.0 % and 86 % within 2 %, cantilevers 1.7 % and 63 %), registration 1.2 mm and 0.06 degrees at the
median, refused on every try for two cantilevers (1004, 1025: their rows read the initial value). Against the rest
shape as the reference on the same code (`--tracking reference=rest`, seeds 1000-1014): 14.7 % -> 0.98 % median, p90
29.9 % -> 5.0 %, within 2 % 0 % -> 73 %; the registration's turn from up to 5.4 degrees to under 0.1. The loaded
scenes stay short of the unloaded family's targets: the state read from one depth image is off by 1-4 % of the range
on some scenes (1006: 1.6 % at its first frame, 4.3 % over the run; 1024: 4.3 % from 483 depth points) and the dense
measurement carries that error on; held-out seed 1005's registration is 10.5 mm off (1.1 mm for the rigid fit)
although its load reads 0.4 %. What is left: transient wrong basins when the load jumps on a
two-support beam (seeds 7, 9, 14: the mirror position s -> L - s for a few frames; the unloaded scenes show them
too, seed 9 at p90 99.5 % since stop 25), and faint cantilevers whose small load the images barely see (seeds 8 and
16, 2.3-2.6 %). At 320x240 the rigid stage can lock onto a wrong basin of a strongly bent beam (development seeds 0
and 1, 18 mm across the beam) and the deformed fit from there is refused: at 640x480 it was not.

**Stop 115: both loaded tables rerun on this code** (Intel host, 2 jobs; the last runs were stop 30's code of
2026-11-25), then again with one mend chosen on the development seeds. First run: development seeds 0-19
(`family_preloaded`) 0.90 % median of the per-scene medians (stop 30: 0.81 %), p90 1.71 % (2.28), 90 % within 2 %
(85); held out 1.28 % (1.49 %), p90 6.08 % (5.61), 37 % within 1 % and 73 % within 2 % (the same). Development seed
17 (two supports, 40 px, the surface bent 23 mm) was refused on every try (47 % of the faces turned to the camera
matched, 50 % needed; 3.33 -> 20.9 %). A reviewing helper traced it through both runs' stored curves: the old run
refused it too while the load held still and placed it once on views taken while the load moved, so the cause was
in both: a deformed fit's points were kept only above the *rest* shape's underside plus the contact band, while its
cover counted the whole bent surface, so a beam sagging by more than the band lost its lower faces near the load
from the numerator only. **The mend** (`registration._object_points`): for a deformed fit the band follows the bent
underside; where nothing moved (the supports, u = 0) the rule is the rest shape's, so no unloaded fit changes.
Development seeds 0-19 with it (the tables above): seed 17 20.9 -> 0.31 % (placed 1.7 mm off), every other row the
same to the bit: **0.77 %**, p90 1.37 %, 65 % within 1 %, 95 % within 2 %; registration 0.6 mm and 0.04 degrees.
Held out with it (run once, after that choice): **1.28 %** (the same), p90 **7.71 %** (6.08), 37 % within 1 %, 70 %
within 2 % (73); two supports 1.03 % and 86 % within 2 %, cantilevers 1.84 % and 56 %. Three rows moved: 1027 (two
supports) 4.34 -> 2.63 % (its cover 0.51 -> 0.99); **two cantilevers now placed far along their axis without a
doubt**: 1018 5.5 -> 57 mm off (1.58 -> 14.4 %, 91 % of its frames called OK) and 1025, placed by the guess and
doubted before (36.5 mm, no frame OK), now 52.8 mm off by its own cover (34.1 -> 16.1 %, 65 % called OK). Their
bent surface slid along the beam covers about as well as in place (cover 0.89): the pose along a cantilever's axis
trades against the load's position, and the fuller cover now passes a fit the old rule refused. That silent
failure is the next thing to study, on development cantilevers (seeds 20-49 are unused here); the mend stays,
chosen on the development seeds as the protocol says, with this held-out result beside it. Seed 4 reads its loaded
state 0.056 against 0.078 in stop 30's run (truth 0.082) and tracks 0.75 -> 3.86 %: the likeliest of the changes
between the runs is the deformed-state fit's damping (5dfb6a5, right after stop 30's run); not traced further.

**Stop 116: the silent slide traced and mended, and the state's crop over the bent underside.** Captured, the views of
held-out 1018 showed the cause, and it was not a cover as good slid as in place (stop 115's reading): the rigid fit of
the bent beam, judged without its sagging part (below the contact band over the *rest* underside), could slide along
the axis and was refused for that (62 mm at about the same cover); the deformed fit started from there, and its cost,
which crops the cloud around the model and leaves the slide to the registration (`depth_state._weak_direction`), kept
the slide; nothing pinned it, since only a rigid fit's slide was pinned. Slid, the deformed shape covered 0.78 of its
faces, in place 1.00 (1025: 0.62 against 0.96). **Two mends.** The deformed fit's slide is pinned by its cover as the
rigid fit's is, and its state fitted again from there, kept where that covers more of its faces
(`registration._pinned_state`). And a deformed state fit whose band over its *bent* underside keeps other points than
the rest rule is fitted again on those (`depth_state.fit_state`; the stop 115 mend of the registration's judging, now
in the fit itself): a cantilever's sagging tip, the points that tell its load, had been dropped (1018 in its true
pose: 3085 points, its load 4.9 % of the range off; 4944 points and 0.05 %). That second mend was chosen on
development cantilevers (the true pose, one depth image at 320x240: seeds 10, 11 and 18 from 1.4, 1.8 and 0.72 % to
0.09, 0.17 and 0.47 %, seven others within 0.04 %); it reaches every loaded fit, the registration's and the tracker's
reference view (`tracking.reference: depth`), but not `tracking.depth_fit`'s follower, which keeps the rest rule.
**The registration step alone on loaded beams** is a new table (`--registration --preloaded`:
`family_registration_preloaded`, development seeds 0-49, and `_heldout`, 1000-1029): the pose, the fitted state
against the truth at the first frame, and the fits placed a centimetre or more off with no doubt raised. Development
seeds 0-49, the code before both mends -> with both: pose 0.96 -> 0.84 mm at the median, p90 3.3 -> 3.0 mm; seed 33
(two supports) 24.3 -> 0.8 mm, placed silently before; seed 42 6.0 -> 0.5 mm; the state 0.52 -> 0.46 % of its range at
the median, p90 2.09 -> 1.89 %; one fit 10 mm or more off (49, 35 mm, doubted: it can slide 55 mm). Held out (run
after both choices; the pin alone first, then with the crop): 1018 57 -> 3.6 -> 4.1 mm, 1025 53 -> 21 -> 2.7 mm (the
stop 115 figures are the tracking table's), 1004 placed by the guess (doubted) -> 0.3 mm by its own cover; the state
1.01 -> 0.55 % at the median, p90 5.49 -> 3.01 %; one fit a centimetre off, 1005 (two supports, 10.7 mm, no doubt),
its state the mirror position (53 % of the range off: a load at s read at L - s, the pose slid to match) that the
tracking recovers from (its load 0.4 % at the median over the run). Tracking, the tables above rerun on this code:
development seeds 0-19 0.77 -> **0.65 %** median of the per-scene medians, p90 1.37 -> 1.53 %, within 1 % 65 -> 80 %,
within 2 % 95 % (the same); the two-support beams gain most (the reference state read over the bent underside: seeds
0, 2 and 9 from 1.16, 0.94 and 1.35 % to 0.54, 0.31 and 0.76 %); cantilever 8 loses (1.36 -> 1.59 %). Held out (the
same, run once after those choices): 1.28 -> **1.13 %**, p90 7.71 -> **2.42 %**, within 1 % 37 -> 47 %, within 2 % 70
-> 80 %; two supports 1.08 % and 93 % within 2 %, cantilevers 1.21 % and 69 % (were 1.03 % and 86 %, 1.84 % and 56 %);
1004 31.6 -> 3.5 %, 1018 14.4 -> 0.90 %, 1024 7.0 -> 0.27 %, 1025 16.2 -> 0.52 %; losses: 1014 0.68 -> 1.45 %, 1020
0.17 -> 0.65 %, 1019 1.70 -> 2.16 %. The loaded scenes still fall short of the unloaded family's targets on the median
(1.13 against 1 %) and within 2 % (80 against 90 %); the p90 meets its 3 %. Said plainly: the two held-out scenes that
showed the faults (1018, 1025) were captured and studied to find them, so their gains are not independent evidence;
the other 28 held-out scenes were not looked at before these runs, and both mends were chosen on development scenes.

**Stop 117: a tilted rigid fit levelled about the beam's ends.** The loaded registration table of stop 116 left
three development beams placed at rest (35, 40, 49), one of them silently misplaced: seed 40's origin was 2.2 mm
off but the beam was turned 4.7 degrees, its far end 72 mm off (the table counted a fit a centimetre off by its
origin only; it now counts the origin or any model node). Captured (scratch runs of the registration's own views),
40 and 49 showed one fault: a sagging two-support beam's rest shape, fitted rigidly, follows the sag down from one
end and tilts (4.7 and 4.0 degrees); levelled onto the support plane about the model's centre it sank by half the
tilt's drop (35 and 17 mm), and the deformed fit started there read no deformation (its cost -67 % and -35 % on the
rest shape's). Started in the true pose, they read their loads 0.6 and 0.1 % of the range off. 35 is not this fault: its
load sits next to the clamp and moves the surface 0.5 mm (at rest is the right reading). **The mend**
(`registration._levelled_state`, `RegistrationConfig.level_ends_deg`): where the rigid fit is tilted more than 1
degree from the support plane, it is levelled about each end of the model's long axis too (a beam's supports, a
cantilever's root, sit at their rest height), the state fitted from each, and the deformed fit whose deformation
lowers its own rest shape's cost the most is kept. A first version kept the fit that covered most of its faces:
on development seeds 27 and 46 the covers differed by a thousandth while the loads read 2.6 and 9.5 % off against
0.2 and 0.5 %; the cost's gain tells them apart (+62 against +93 %, +28 against +56 %). Both tables were run on
that first version too (not kept), so the held-out table was seen before the switch, which was chosen on those
two development seeds alone. **The registration step on loaded beams, rerun** (`family_registration_preloaded`,
`_heldout`): development seeds 0-49, pose 0.84 -> 0.80 mm at the median, p90 3.0 -> 2.4 mm; the state 0.46 ->
0.42 % of its range at the median, p90 1.89 -> 1.19 %; 40 and 49 placed 1.8 and 0.5 mm off, their loads 1.2 and
0.14 %; seed 11 (stop 116: 3.4 %, the pose 2.5 mm along the axis) 0.03 %, seed 7 3.7 -> 0.8 %, seed 41 1.9 ->
0.35 %; a loss: 33 0.09 -> 0.31 %. Held out (1000-1029): 1005 (two supports, stop 116's one silent centimetre,
its load read at the mirror position) 10.7 -> 2.3 mm and its state 53 -> 2.8 %; no fit a centimetre off any more;
pose p90 3.2 -> 2.8 mm, the state's median 0.55 % (the same), p90 3.0 -> 2.8 %, worst 53 -> 4.0 %; 1009 (a
cantilever) still placed at rest, not studied (held out).
**Tracking, rerun** (the held-out table run once, after the development choice): development seeds 0-19
(`family_preloaded`) 0.65 % median of the per-scene medians, p90 1.53 %, 80 % within 1 %, 95 % within 2 % (the
same; 2 and 7 a little better, 11 0.67 -> 0.70 % although its registration's state went 3.4 -> 0.03 %: the tracker
reads the load again from the images); held out 1.13 -> **1.07 %**, p90 2.42 %, 47 % within 1 %, 80 % within 2 %
(the same); 1014 1.45 -> 1.07 %, 1018 0.90 -> 0.69 %, 1024 0.27 -> 0.46 %, 1005 0.33 -> 0.43 %. The loaded scenes
still fall short of the unloaded family's targets on the median (1.07 against 1 %) and within 2 % (80 against 90 %).

**Stop 118: the reference view keeps the registration's state where its own depth agrees.** Development seed 4 (a
cantilever, 4.03 %, untraced until now) was captured: the registration, fitted on three fused depth views, read the
load 1.25 % of the range off, and the dense reference view (the registration's last view) fitted its own depth alone,
found a deformation there that moved the surface 0.5 mm (under `min_motion`) and took the beam to be at rest; every
later frame measured its deformation against a rest shape that was loaded (a bias of 2-3 % of the range over the run).
Over development seeds 0-19 (captured the same way) the reference frame's own fit read the load 0.63 % off at the
median, the registration's 0.36 %; on the reference frame the two states' costs were mostly within 0.2 % of each
other: one depth image barely tells load positions a few % of the range apart, three views tell them better. **The
mend** (`tracker.DeformableTracker._registration_agrees`, in `reference_from_depth`: the dense reference view and the
sparse start): where a registration found a state, it is kept unless the reference frame's own verdict (its deformed
fit, or the rest shape: no gain) lowers the rest shape's cost by more than `min_gain` (1 %, the yardstick a
deformation must pass to be seen at all) beyond what the registration's state lowers it, both held on the same points
at the same scale, their rigid parts a nuisance (`depth_state.held_gains`). Where the load moved or went after the
registration's views, the frame's own verdict stands (tested both ways); a body of revolution whose reference fit
reads its turn (the boot's scene files: `depth_fit` with `depth_turn`) is left as it was. Its cost: a rest fit and the
held states' rigid fits, once per reference view, 0.06-0.20 s of CPU (seeds 4, 0, 18; the frame's own fit 0.26-0.62
s). A first version compared each fit's own gain (`fit_state`'s, whose points differ where a fit is refitted over its
bent underside; a frame judged at rest counted its refused deformed fit's gain); a reviewer's reading replaced it on
that ground, after the first version's held-out run and before this one's. Both versions ran on both seed sets: the
development table the same to the bit, the held-out one apart in one row (1004: 2.81 % with the first, 3.54 % with
this one). **Tracking, rerun**: development seeds 0-19 (`family_preloaded`) 0.65 -> **0.46 %** median of the per-scene
medians, p90 1.53 -> 1.23 %, within 1 % 80 -> 85 %, within 2 % 95 -> 100 %; 4 4.03 -> 0.57 %, 11 0.70 -> 0.22 %, 13
0.69 -> 0.25 %, 15 1.07 -> 0.37 %; a loss, 5 0.84 -> 1.85 % (its registration's state, 2.8 % off, kept: on the
reference view it lowered the rest shape's cost by 0.9 %, the frame's own fit, 2.8 % off the other way, by 1.4 %).
Held out (1000-1029, run after that choice): 1.07 -> **0.73 %**, p90 2.42 -> **3.19 %**, within 1 % 47 -> 63 %, within
2 % 80 -> 83 %; two supports 1.03 -> 0.45 % (93 -> 100 % within 2 %), cantilevers 1.21 -> 0.80 % (69 % within 2 %, the
same); 1006 5.26 -> 2.11 %, 1021 2.29 -> 0.43 %, 1029 2.22 -> 1.33 %, 1015 1.57 -> 0.53 %; losses: 1019 2.16 -> 3.42 %
and 1023 1.71 -> 3.16 % (cantilevers moving 2.5-2.8 px at most, faint texture; their registrations' states 4.0 and 2.3
% off, now kept). The loaded held-out scenes now meet the median target (< 1 %) and miss the p90 (3.19 against 3 %)
and the share within 2 % (83 against 90 %): over 2 %, 1009 (5.98 %, still registered at rest), 1004 (3.54 %), 1019,
1023 and 1006, all cantilevers, the last four carrying their reference state's error; the state a registration reads
on a cantilever is what to mend next. The unloaded held-out family (`family`, 1000-1099), rerun on this code: its
summary the same to the bit (0.42 % median of the per-scene medians, p90 1.34 %, 98 % within 2 %); one row moved, 1081
(the cantilever registered late, once loaded) 7.47 -> 2.90 %.

**Stop 119: what the loaded cantilevers' error is made of (development seeds only; no code changed).** The loaded
family's development seeds 20-49 tracked on stop 118's code (`family_preloaded_dev_20_49`, new): 0.45 % median of the
per-scene medians, p90 2.52 %, 83 % within 2 %; the five over 2 % are cantilevers whose load moves them at most 3.4 px
(35 8.48 %, registered at rest while loaded, as held-out 1009; 26 7.39 %, 48 3.24 %, 30 2.44 %, 37 2.09 %), while the
nine development cantilevers that bend 11-33 px read 0.12-0.57 %. Scratch diagnoses on seeds 5, 8 and 16 (not
benchmarks: one gave the tracker the true reference state, which no estimate may see): with the reference state exact,
1.85 -> 1.07 %, 1.22 -> 1.01 %, 1.29 -> 0.83 %, so the reference state is part of these scenes' error and the dense
fit's own near 1 % the rest; on seed 5's fused registration cloud the load's position trades with the pose (states 8 %
of the range either side of the truth within 1 % of the rest shape's cost; the best 3 % apart from the registered and
the true pose, 0.06 degree apart). Two ways to read the reference state later were measured and dropped: later frames'
depth fits as an anchor (single-frame fits 3.7-4.1 % off and biased; the corrected tracking 1.85 -> 1.77 % and 1.29 ->
2.37 %), and the photometric residual of seed 5's reference taken again at states -6 ... +6 % about the truth (flat
within its noise at frames 40, 100 and 112, while the fitted state follows the reference's offset at 0.35-0.48 of it).
`docs/status.md` (stop 119) has the numbers.

**Stop 120: the reference state read again from the images, tried and dropped (development seeds only; no code
kept).** Where the load moves the image 8-39 px (development seeds 4, 6, 10, 11, 14, 31, 44) the residual of a later
frame over reference states is not flat (it was on seed 5's 3.8 px, stop 119), so a tracker was built that re-took its
reference view at 9 states over +-8 % of the range about the registration's, once a sound frame's state moved the
image 4 px from it, summed the residual of 3 such frames and moved the reference to its least (commit caf761e,
reverted in 0ccaeba). On the loaded development seeds 0-19 it made 1 scene better (0: 0.64 -> 0.49 %), 4 worse (4:
0.57 -> 0.92 %, 6: 0.46 -> 0.85 %, 11: 0.22 -> 0.38 %, 14: 0.31 -> 1.07 %) and left 15 unchanged: it moved sound
reference states (the registration's within 0.03-1.25 % of the truth) 1.2-4.2 % of the range (seed 4 from +1.25 to
-2.94 %, 6 from -0.23 to +1.35 %), and on seed 14, whose registration was 0.04 % off, the scan's parabola through its
lowest three states moved it 1.2 % while a quadratic fitted to the whole summed residual puts the least 3.4 % below,
six of its standard errors: a bias of the residual, not its noise. With the registration's state put about 3 % off on
purpose (scratch), it came back to within 1 % on seeds 11 (+3.0 -> -0.8 %) and 31 (-2.8 -> +0.2 %), went further off
on 10 (+3.3 -> +7.5 %) and found its least at the end of the scan on 44 (-2.8 %, kept). The residual over reference
states carries biases as large as the registration's errors it was to correct. Also measured (scratch): the
registration's pose lies level with the floor of its fused cloud within 0.002 degree on development seeds 4, 5, 8, 12,
16 and 19 (the true pose tilts 0.002-0.027 degree from that floor in the SLAM's map, the map's own tilt), so pinning
the pose to the floor would change nothing.

**Through a stereo pair** (`--sensor stereo`, `simreal make-bag family --seed N --sensor stereo`; stop 32): the same
draws seen by a rectified pair with a 0.12 m baseline (the right camera blurred along its own path), no depth
topic. The SLAM runs in stereo mode, and the trackers' depth (the registration's views, the dense reference view) is
SGBM on the pair (`vision/stereo.py:stereo_depth`), made only in the frames that read depth, over the full image
width (OpenCV leaves the leftmost columns, as many as the disparity range, without a disparity; both images are
padded first), down to `camera.stereo_min_depth_m` (the family's scene file: half the distance the user guesses the
object at; `benchmarks/results/stereo_depth.md`: 51 ms on one thread and every beam pixel measured at the median,
0.9x takes 34 ms and still measures it, 1.2x loses up to 62 % of a beam, and without the padding the worst seed keeps
63 % of its beam; stop 108's rerun on an AMD EPYC AVX2 host: every coverage figure the same, 78 ms and 53 ms).
Three changes were found on development seeds 0-13 and chosen there, each from the data (traced on the first three
views with the true camera poses, to separate the registration from the SLAM; scratch runs, not kept):

- the full fine stage of the registration rolled thin beams by degrees about their axis on SGBM depth (seeds 2
  and 5 the most; `test_registration_stereo.py` shows the roll on a rendered scene); on stereo depth the fine stage
  keeps the support plane's roll and pitch (`RegistrationConfig.for_camera`: 0.04-0.06 degree at the median in the
  tables below); RGB-D keeps the full stage;
- without the padding the leftmost 128-256 columns had no depth; a cantilever's clamped end there let the fit slide
  along the beam (seeds 6 and 8: centimetres off; 1.6 and 2.1 mm with it in `family_registration_stereo`);
- the slide pin counts only the model faces that some view can measure (`DepthViews`: in the image, and for stereo
  with its match inside the right image), and a fit is refused when it could slide over more than 60 mm judged
  either way (seed 13 had slid by centimetres and no longer does: 2.2 mm in the run below). On RGB-D seeds 0-9 the
  registration step reads the same to the digit.

On development seeds 0-19 (`family_dev_stereo_stop60`): median of the per-scene medians 0.57 % of the load range,
p90 1.4 %, 80 % of scenes within 1 %, 90 % within 2 %; registration 2.1 mm and 0.06 degrees at the median. RGB-D on
the same seeds and code (`family_dev_rgbd_0_19`): 0.30 %, p90 1.2 %, 85 % and 100 %; registration 0.50 mm and 0.14
degrees. The tracker's time per frame is about the same (86 ms against 80 ms at the median, two scenes in parallel);
the whole step is 126 ms against 104 ms (SGBM in the few frames that read depth, sparse stereo matching in the
SLAM). The registration step alone on seeds 0-9: 2.1 mm and 0.06 degrees at the median, seed 1 25.8 mm off
(`family_registration_stereo`).

On held-out seeds 1000-1029, run once after these choices (`family_stereo_stop60`): median of the per-scene medians
0.68 % (target < 1 %: met), p90 2.4 % (< 3 %: met), 73 % of scenes within 1 % and 83 % within 2 % (target >= 90 %: **not
met**); registration 2.7 mm and 0.05 degrees at the median (targets 3 mm and 0.5 degrees: met); camera ATE 2.6 mm at
the median (RGB-D 1.8 mm). The RGB-D rows of the same 30 seeds (held-out table above, older runs of code unchanged
for them): 0.52 %, p90 1.6 %, 97 % within 2 %. The five stereo scenes at 2 % or more: 1014 (13 %: a faint beam,
contrast 0.08, 1.8 m away, registered 8 mm and 1.2 degrees off), 1028 (5.6 %: faint, registration slid 13 mm along
the beam), 1012, 1019 and 1023 (2.4-2.5 %: faint textures or loads that move the image by under 3 px; RGB-D reads
them 1.5-1.8 %). Passive stereo matches texture, and a faint beam gives SGBM little to match: the end faces that pin
a beam along its axis are then a few noisy pixels, and where one end is outside what the pair can measure (dev seed
1: the left end outside the right camera's view in the first frames) the slide is not pinned and the registration
is 26 mm off without being refused. Still open: a photometric pin of the slide (the beam's end edges in the image),
and the monocular family (registration needs metric depth; a monocular map must get its scale first).

**Stop 61: the stereo tables' scenes that the camera's drawn path had taken through a wall** (development 5, 14 and
18, held-out 1001; stop 60's room mend above) were rerun in the wider room (`family_dev_stereo_room`,
`family_stereo_room`) on this stop's code and composed into `family_dev_stereo` and `family_stereo` (the tables
above are kept as `*_stop60`; the other rows are the older runs). Seed 14 now keeps the camera on every frame (86.8 %
before) and its p90 falls from 27.0 % to 1.55 % (median 0.26 -> 0.15 %); seed 5 0.67 -> 0.95 %, seed 18 0.85 ->
0.53 %; held-out 1001 0.70 -> 1.27 % (p90 2.62 -> 3.69 %). Development: 0.53 %, p90 1.42 %, 80 % within 1 %, 90 %
within 2 %. Held out: 0.70 %, p90 2.41 %, 70 % within 1 %, 83 % within 2 %. The reruns' "OK frames" are not
comparable with the older rows': a registration on depth that scatters over 3.5 mm about the fitted surface now
flags every frame (seed 14 and 1001: 4.6 and 4.8 mm, so 0 % OK), a check added after the older rows were run.

**Stop 115: the held-out stereo table rerun whole on this code** (`family_stereo`, one run of seeds 1000-1029, 2 jobs,
Intel host; nothing was tuned on it since stop 60): median of the per-scene medians **0.53 %** (0.70 % in the composed
table above), p90 **1.87 %** (2.41), 73 % of scenes within 1 % (70) and **93 % within 2 %** (83): the three targets
met through a stereo pair too. Twelve scenes better by more than 0.1 points (1028 5.57 -> 1.04 %, 1012 2.49 -> 1.60
%, 1021 1.74 -> 0.81 %), two worse (1010 0.90 -> 1.38 %, 1019 2.40 -> 2.62 %); between the runs are the tracker and
SLAM changes of stops 61-114, not traced one by one. The two scenes over 2 %: 1014 (12.1 %: the faint beam whose SGBM
depth scatters 7.2 mm about the fit, flagged on every frame) and 1019 (2.6 %: no measurable deformation read).
Registration 2.7 mm and 0.04 degrees at the median; tracker 121 ms a frame at the median (two scenes at a time).

**Plates** (`--object plate`, `simreal make-bag family --seed N --object plate`; stop 37): a plate 0.25-0.6 m long,
0.4-1 times as wide, 12-40 times as long as thick, clamped along one end (a shelf) or bolted on two blocks at both
ends, a weight anywhere on its top face: two load parameters (s_x, s_y), each scored in % of its own range, a
frame's error the larger of the two. Material, load size (2-40 px), texture, clutter, light, noise and camera are
drawn from the beams' ranges, from their own random stream (the beams' draws are unchanged). The truth
(`synth/truth.py:plate_load_truth`) is P2 tetrahedra with two layers through the thickness and 1.5 times the
model's cells across, the weight a pressure on its footprint, tabulated about a footprint's diameter apart and
interpolated bilinearly; the model a user would build is the `beam_pgd` builder's `where: top_face` load (Q2
hexahedra, one through the thickness, a nodal force, 60 PGD modes). The tests check the truth against
Euler-Bernoulli for a load spread across a shelf (3 %), its twist's mirror symmetry and its interpolation. Plates
run with the beams' defaults; the one default they changed (the shading term, stop 38) was measured on development
beams too and is a default for both.

Stop 37's first results (`family_plate_dev_stop37`: development seeds 0-9, median of the per-scene medians 1.27 %,
p90 5.4 %, 60 % within 2 %; held-out 1000-1012, whose run was not kept) failed on s_y on shelves.
Development seed 7 read s_y too close to the plate's middle on every hold although its load moves the image by 25 px.
Its diagnosis (scratch scripts on seed 7 alone, not kept): the model is not the cause (its best fit to the truth's
surface reads the load 0.58 % off at the median, the model bias of `family_plate_dev_stop37`), the photometric cost
itself had its minimum where the fit stopped (not a solver fault), and rendering the same scene with ambient light
only took most of s_y's error away: the plate's twist turns its surface, and under the scene's directional light the
faint speckle's change of shading outweighed its motion. The dense measurement now models that change (a matte
surface: three shading parameters g, the brightness change I_ref (n(mu) - n_ref).g with the normals smooth across each
face of the model, `tracking.dense_shading`, on; docs/tracking.md), and a unit test renders a faint plate bending
under a side light (fit 5 % of the range off without the term, within 1.5 % with it, g the light's direction). The
knob was chosen on development seeds only: plates 0-9 (`family_plate_dev_stop38` against `family_plate_dev_stop37`):
median of the per-scene medians 1.27 % -> 1.10 %, p90 5.4 % -> 3.2 %, within 2 % 60 % -> 70 % (seed 7 7.6 % -> 2.5 %,
seed 2 2.0 % -> 0.4 %; seed 1 5.2 % -> 9.6 %: a 3.2 px load on a faint speckle, read poorly even with ambient light
only, where three more free parameters cost more than they explain); beams 0-19 (`family_dev_0_19_stop38` against
`family_dev_0_19_dense_shading_false`): 0.30 % -> 0.29 % median, p90 1.15 % -> 1.11 %, 85 % within 1 % and 100 %
within 2 % both, every scene within 0.16 points of its value without the term; the tracker's time per frame about 1.5
times (92 -> 145 ms at the median of the two beam tables, each run alone with two scenes in parallel; each solve takes
more iterations and computes the normals). The two development tables ran before two changes made for speed (the
corners' blended normals no longer renormalised per sample, the last two mu's normals kept): one frame of beam seed 1,
checked by hand, read the same before and after but for a difference far below any error quoted here.

On held-out seeds 1000-1019 with the shading term (`family_plate_stop38`, all 20; run once): median of the per-scene
medians 1.20 % (target < 1 %: **not met**), p90 6.0 % (< 3 %: **not met**), 35 % within 1 %, 60 % within 2 % (>= 90 %:
**not met**); s_x 0.51 % and s_y 1.03 % at the median; model bias 0.46 %; registration 0.48 mm and 0.04 degrees at the
median (targets met). On the 13 seeds of stop 37's run (1000-1012): 1.29 %, 62 % within 2 % (stop 37's own figures on
them are not kept). **Plates bolted at both ends** (11 scenes): 0.97 % median, p90 1.1 %, 91 % within 2 %: the targets
but for the median's margin. **Shelves** (9 scenes): 3.3 % median, 22 % within 2 %, and these are the failures: s_y on
1000, 1001, 1008, 1009, 1011 and 1013 (2.5-6.3 %; their s_x 0.3-1.2 %): loads of 4-9 px on faint speckles (four of
six), where some frames report no measurable deformation and the twist that carries s_y is a fraction of a pixel;
1016's registration was refused on every try (a guess 91 mm and 10 degrees off, 73 mm of it across the support plane:
3 % of the plate matched), so it is never placed and its row (31 %) scores the initial values on frames flagged
"waiting for registration"; 1019 (bolted, a 2.9 px load on contrast 0.04: 3.1 %) is flagged on every frame (its
registration can slide 5.7 % of its length). The tracker takes 380 ms per frame at the median (60 modes over a plate's
whole surface, two scenes in parallel on the 2 cores), three to four times a beam's.

Stop 39: g is a property of the light, the same in every frame, so what each frame the tracker judged sound measured
of it is fused over about 50 such frames into the next frames' prior (`tracking.dense_shading_frames`, 50;
docs/tracking.md), and a barely bent frame can no longer pass its deformation off as shading. Chosen on development
seeds only. Plates 0-9 (`family_plate_dev` against `family_plate_dev_stop38`): median of the per-scene medians
1.10 % both, p90 3.2 % -> 2.8 %, within 1 % 30 % -> 40 %, within 2 % 70 % -> 80 % (seed 7 2.46 % -> 1.53 %, seed 1
9.6 % -> 8.7 %, seed 5 1.05 % -> 0.96 %; seed 3 2.14 % -> 2.20 %, the others within 0.05 points). Beams 0-19
(`family_dev_0_19_dense_shading_frames_50` against `family_dev_0_19_stop38`): 0.29 % median both, p90 1.11 % -> 1.08 %,
85 % / 100 % within 1 % / 2 % both, every scene within 0.2 points (seed 7 0.74 % -> 0.56 %); seed 14's p90 grew
(41 % -> 82 %: frames where the camera was lost hold the last estimate, a different one; its sound frames' p90 0.39 %
-> 0.41 %). Fusing every frame instead of the sound ones (a first try, not kept) made plate seed 2 (0.4 % with the
sound frames) far worse: the frames before the load is placed are fitted with a load the model cannot leave out,
measured a wrong g with great confidence, and held it for dozens of frames.
On held-out seeds 1000-1019 with it (`family_plate_stop39`, all 20, run once after the choice; `family_plate_stop38` is
the same seeds with each frame's g alone): median of the per-scene medians 1.20 % both (target < 1 %: **not met**),
p90 6.0 % -> 4.8 % (< 3 %: **not met**), within 1 % 35 % -> 30 %, within 2 % 60 % both (>= 90 %: **not met**); s_x
0.52 % and s_y 1.13 % at the median (0.51 % and 1.03 %); bolted at both ends 0.93 % (91 % within 2 %), shelves 3.5 %
(22 %). So the fusion did not carry over to the held-out plates at the median: better on 1001 (6.3 % -> 5.2 %), 1009
(6.0 % -> 4.8 %) and 1019 (3.1 % -> 2.5 %), worse on 1000 (3.3 % -> 3.5 %), 1008 (2.5 % -> 2.9 %), 1013 (3.9 % ->
4.1 %) and 1002 (1.0 % -> 1.2 %, its p90 3.3 % -> 14 % and its sound frames 87 % -> 63 %), the rest within 0.1
points; 1016 is not placed, as before. It stays the default because the development seeds chose it; the held-out
seeds were not used to judge it again. The shelves' s_y on small loads and faint speckles is still where plates fail.
The held-out table's tracker time (450 ms at the median of the rows, 383 ms in stop 38's) is not comparable: part of
this run shared the 2 cores with a scratch registration study; on the development plates, each run alone, the
fusion's time was 425 -> 405 ms (no measurable cost).
Stop 48's coarse search (each candidate at the brightness fitted to it; chosen on the development beams, the
development plates not rerun for lack of time: `family_plate_dev_stop39` is stop 39's) on the held-out plates
(`family_plate_stop48`, all 20; stop 39's is `family_plate_stop39`): median of the per-scene medians 1.18 % (1.20
%), p90 5.1 % (4.8 %), within 1 % 35 % (30 %), within 2 % 60 % (60 %): still short of every target. 16 scenes within
0.1 points; worse 1001 5.2 % -> 6.6 %, 1009 4.8 % -> 4.9 %, 1013 4.1 % -> 4.3 %, 1019 2.5 % -> 2.7 %: the plates'
faint small loads; perhaps what made seed 1 at 80 degrees of azimuth worse (docs/stability.md: five brightness
parameters fitted per candidate on the coarsest level's few samples), not looked into. Its tracker time (539 ms at
the median of the rows) is not comparable: the run shared the cores with the beams' and a test run.
Stop 49's `auto` (the candidates' brightness fitted only after a frame whose gain fell under 0.5): the development
plates 0-9 (`family_plate_dev`, rerun; stop 39's is `family_plate_dev_stop39`) read as stop 39's in every row to the
hundredth (1.10 %, p90 2.8 %, 40 % within 1 %, 80 % within 2 %); the held-out plates 1000-1019 (`family_plate_stop49`,
then rerun; stop 48's is `family_plate_stop48`): median of the per-scene medians 1.18 %, p90 4.8 %, 30 % within 1 %,
60 % within 2 %, as stop 39's but for 1002 (1.19 % -> 1.14 %): stop 48's losses on 1001, 1009, 1013 and 1019 are gone
with its gains (1002 1.11 %, 1015 0.45 %). Still short of every target. The tracker time (570 ms at the median of the
rows) is not comparable: the run shared the cores with the test suite and another benchmark.

**The joint boot** (`python -m benchmarks.family_boot`, `simreal make-bag family --seed N --object boot`; stop 62): the
thesis's real boot (§4.5.4; spec `joint_boot`, neo-Hookean bellows, its top ring carried by the lever) in drawn set-ups
(`simreal_nodes/synth/boot_family.py`, its own random stream): its turn alpha_z about its own axis (any, unknown to the
tracker), the lever held at 4-6 angles of 4-50 degrees after 1.5 s at rest, the camera 0.4-0.8 m away on an arc of
30-90 degrees centred anywhere around the boot at 20-50 degrees of elevation, a speckle on the rubber from faint
(0.04) to painted (1.0), clutter behind the boot, light, pixel noise and blur as the beams'. The boot itself is not
drawn: it is one product with one model, and the lever drives its top ring by displacement, so E does not change its
shape. The images come from the boot's full-order solve (`synth/scenes.py:boot_truth`: trilinear hexahedra 72 x 2 x
60 against the model's 36 x 1 x 48, Newton every 2 degrees; 20-25 minutes on one core, now kept on disk keyed on the
spec and the code); the boot is placed by registration from a guess by eye (5 cm, 10 degrees rms; since stop 63 the
fit polished from starts 4 mm away, `anchor.polish_mm: 4`, below); the tracker runs
with the boot scene file's settings (map points, Huber 2 px, alpha_z a constant fixed over 40 informative frames) and,
since the first run below, alpha_z searched over its range until it is first seen (`tracking.constant_search: 24`);
the dense measurement does not estimate alpha_z (the tracker refuses it for such an object). Each row gives the
model's own bias at the scene's angles (the angle the model's best fit to the truth's surface reads: 0.1 degree high
at 10 degrees of lever, 0.8 at 42, 1.3 at 50) and the tracker's error against that reading.

The first run, with the thesis boot scene file's settings alone (`family_boot_dev_before_search`,
`family_boot_before_search`): development seeds 0-9, median of the per-scene medians 1.32 % of the 52 degree range
(0.69 degree), p90 12.8 %, 40 % within 1 %, 60 % within 2 %; held-out seeds 1000-1019 2.22 % (1.2 degrees), p90 10.1
%, 20 % within 1 %, 45 % within 2 %. The failures were alpha_z's: on 1009, 1015, 1016 and development 3 and 8 the
tracker never found a frame that informs it; on development 2 it was fixed 49 degrees off. Development seed 3, rerun
with every frame printed (not kept): alpha_z started far from the boot's turn (the registration cannot tell the turn
of a body of revolution); at that alpha_z the bent boot fits no better than an unbent one, so the frame reads "no
measurable deformation", and a frame that looks undeformed holds alpha_z: theta stayed at 0 while the lever went to 44
degrees. The new knob `tracking.constant_search` (default 0, off): until a constant has its first informative frame,
each frame is also fitted with alpha_z held at N values over its range, the map points relinked at each (a point's
material point depends on the turn), and the best kept where its RMS beats the frame's own fit by
`min_deformation_px` (a unit test breaks the deadlock above on synthetic points; a first version without the
relinking failed it). Three knobs on the development seeds, the code otherwise the same: alpha_z fixed over 15
informative frames (the tracker's default) instead of 40: 1.32 % -> 1.27 %, p90 12.8 -> 12.9 %, the same shares, the
alpha_z failures unchanged; no new map points once the boot deforms (thesis §4.4.1): 1.32 % -> 5.48 %; **the search
over 24 values** (`family_boot_dev_constant_search_24` as first run): 1.32 % -> 1.21 %, p90 12.8 % -> 4.6 %, 40 %
within 1 %, 60 % -> 70 % within 2 % (seed 3 32.4 % -> 1.5 %, seed 2 10.6 % -> 4.3 %). The search was chosen for the
family's boot scene file on that run (the thesis's own boot scenes keep their settings and were not rerun). A fix came
after it: the search restored the links after each sampled turn but not the set of points the relinking had marked
static; now it restores both. Stop 63 reran the table on the fixed code (`family_boot_dev_constant_search_24`, the
file now holds that rerun): **1.19 %**, p90 **7.49 %**, 40 % within 1 %, 70 % within 2 %, alpha_z 1.1 degrees off at
the median; seed 2 went 4.3 % -> 11.4 % (alpha_z fixed 51 degrees off), the others within 0.5 points.

**Held-out seeds 1000-1019 with the search, after the fix** (`family_boot_before_polish`, stop 63; stop 62's run before
the fix is in git history: 2.29 %, p90 10.2 %): median of the per-scene medians **2.18 %** (2.22 % before the search,
`family_boot_before_search`), p90 **9.85 %** (10.1 %), **25 %** within 1 % (20 %), **45 %** within 2 % (45 %): short of
every target the beams meet; the search did not carry over. alpha_z is what fails where the registration holds: 1015
(16.6 degrees off, theta 10.1 %, every frame called OK), 1017 (23 degrees, 1.4 %) and 1018 (64 degrees, registered 12 mm
off on noisy depth at 0.46 m, every frame flagged); 1007 loses its measurements (12.9 %, "only 1 of 17 measurements
agree"), 1009 (8.0 %), 1011 (8.3 %) and 1013 (8.3 %) read theta off with alpha_z within 2.6-5.1 degrees. 1002, 1005,
1006 and 1011 were registered 3.9-4.6 mm off (below). The search's price: on every frame until alpha_z is first seen,
24 relinks and fits; where that never happens the tracker's median time per frame is 220-1412 ms (1002, 1010, 1013,
1015; about 15-70 ms elsewhere, this run sharing the cores with another benchmark). The thesis reports no figure for
this example; the boot's three fixed views at 30 fps (`thesis_truth_boot`, without the search) read 0.41-0.72 % at the
median (in that run; 0.33-0.59 % in stop 109's, which the table holds now).

**The same scene run twice did not give the same numbers** (found in stop 63, fixed in stop 64: below). Held-out
1000-1011 ran on the same code in stop 62 (`family_boot_fix_1000_1011`) and stop 63 (`family_boot_before_polish`): the
registrations agree to the digit, the per-scene medians by 0.14 points at the median, but 1009 read 22.6 % and 8.0 %,
1008 1.2 % and 2.7 %, 1005 4.3 % and 3.1 %. Development seed 0 run twice in one process (the OpenCV random state
reset, the frames copied afresh): the registered pose differs in its last bits (1e-15: Open3D's ICP, called on the
same clouds in one process with one OpenMP thread, returns poses 1e-15 apart from one call to the next; an open
upstream question, isl-org/Open3D#6225), theta by almost nothing in that frame but visibly at the lever's first move
some frames later (a check not kept), the camera from the next frame on through the feedback of the boot's map points.
The tracker's discrete choices (which map points link, which frame informs alpha_z, the search's winner) amplify a
rounding difference into another basin. So a single boot row is one draw of that spread; the summaries over 10-20
scenes moved too: over 1000-1011, the median of the per-scene medians read 1.80 % in one run and 2.06 % in the other.
The numbers of stop 63 above and below are such draws.

**alpha_z searched until it is fixed, a knob** (`tracking.constant_search_until: frozen`, default `seen`; stop 63).
Development seed 2, rerun with every frame printed (not kept): the registration took 32 frames (the lever already at
23 degrees), the depth image's reference state put alpha_z far off, and that first frame counted as informative, so a
search that stops once the constant is seen ran on one frame only (too few map points: no winner). alpha_z then
wandered along a flat cost with a small standard deviation claimed, and was fixed 51 degrees off
(`family_boot_dev_constant_search_24`). With `frozen` the search runs on every frame until alpha_z is fixed, and a
winner restarts its informative frames: seed 2's search won a few frames later, still well off, and alpha_z settled
13.3 degrees off (`family_boot_dev_search_until_frozen`; a test breaks the same deadlock on synthetic points).
Development seeds 0-9 (`family_boot_dev_search_until_frozen`, the same code otherwise): 1.19 % -> **1.40 %**, p90 7.49
% -> **3.06 %**, the same shares (40 %, 70 %); seed 2 11.4 % -> 2.8 %, 0 0.73 -> 0.44 %, 8 7.1 -> 5.7 %; 1 1.25 ->
1.42 %, 6 1.13 -> 1.38 %. Its price rules it out as a default: the tracker's median time per frame 28-4416 ms against
11-51 ms (the search runs on every frame until 40 frames inform alpha_z, which on some scenes is never). A knob for
offline replays; not run on the held-out seeds.

**Registration of the boot, and the polish** (stop 63; `python -m benchmarks.family_boot --seeds 0-9 --registration`,
the registration step alone on each scene's first 14 frames). With the RGB-D defaults
(`family_boot_registration_dev_before_polish`): median 0.38 mm and 0.13 degree, but seeds 1 and 5 3.8 mm off (3.8 mm
along the camera's line of sight; 3.8 mm with a 1.9 degree tilt). The fine stage of roll and pitch taken from the
support plane (`anchor.fine: upright`, new; `family_boot_registration_dev_upright`) did worse: 7 of 9 scenes 3.6-3.95
mm off. Traced on seeds 1 and 4 (not kept): the coarse stage (5 mm voxels) ends a few millimetres off, and the fine
stage's ICP stops in a neighbouring basin of the bellows' pleats, 3.8 mm away, where slightly more of the faces have a
measured point within 6 mm than at the true pose, but far fewer within 2 mm. The new
`anchor.polish_mm` (default 0, off): the fit and six starts that far away along the object's axes are refined by ICP
at 4 and 2 mm and the one with the most faces met within 2 mm is kept. With 4 mm
(`family_boot_registration_dev_polish_4`): median **0.09 mm** and **0.05 degree**, worst **0.42 mm** and 0.29 degree
(3.80 mm and 1.90 degrees before); seed 2 is not placed in 14 frames with or without it (32 in the whole run). It went
into the family's boot scene file on that table. The beams' scene files keep it off: their tables were not rerun with
it.

**With the polish, development seeds 0-9** (`family_boot_dev_polish_4`): median of the per-scene medians **0.62 %**
(1.19 % without), p90 **3.01 %** (7.49 %), **60 %** within 1 % (40 %), **80 %** within 2 % (70 %), alpha_z 0.7 degree
off at the median (1.1). Seed 1 1.25 -> 0.31 %, 5 2.39 -> 0.31 %, 2 11.4 -> 2.5 % (alpha_z 51 -> 1.6 degrees off); 7
0.38 -> 1.40 % (alpha_z 0.6 -> 2.0 degrees). Seed 8 stays at 7.8 %: the boot, 0.76 m away, holds few map points and
they fit loosely (a trace, not kept), which leaves alpha_z barely observable (the row's most common reason: a standard
deviation of 0.335 rad, about 19 degrees), so the search never ends (1.9 s per frame at the median).

**Held-out seeds 1000-1019 with the polish** (`family_boot_stop63`, run once after the choice; the registration alone:
`family_boot_registration` as run then, rerun in stop 70): median of the per-scene medians **2.06 %** (2.18 %
without), p90 **9.39 %** (9.85 %), **40 %** within 1 % (25 %), **45 %** within 2 % (45 %). The registration alone on
the first 14 frames: median 0.14 mm and 0.05 degree, worst 0.64 mm and 0.34 degree, 1000, 1013 and 1018 not placed
that early (without the polish, from the whole runs: 0.36 mm at the median, 1002, 1005, 1006 and 1011 3.9-4.6 mm off);
in the whole runs those four were placed 0.05-0.64 mm off. Better: 1011 8.3 -> 2.3 %, 1006 1.43 -> 0.81 %, 1017 1.38
-> 0.80 % (alpha_z 23 -> 2.7 degrees), 1016 2.9 -> 2.0 %, 1007 12.9 -> 9.8 %; worse: 1005 3.1 -> 4.4 % (registered 4.6
-> 0.2 mm off, alpha_z 1.2 degrees), 1004 2.2 -> 2.7 %, 1000 0.56 -> 0.96 %. The gain carried over in the share within
1 % and at p90, hardly at the median, and not to the share within 2 %: short of every target the beams meet. What
fails now: alpha_z on 1015 (22 degrees, theta 10.5 % with every frame called OK) and 1018 (registered 12 mm off on
noisy depth at 0.46 m, every frame flagged); theta 8.8-9.8 % off on 1007 (the measurements lost, 53 % of frames OK),
1009 and 1013 with alpha_z within 1.6-4.7 degrees; 1005 4.4 %. Against the spread between identical runs (above)
single rows moving by a point or less say little.


**Repeatable runs** (stop 64). Two causes, both removed. (1) Open3D's `registration_icp` returns poses 1e-15 apart from
one call to the next on the same clouds (repeated calls differed even with one OpenMP thread, in a check not kept; its
sums run over threads; isl-org/Open3D#6225). The registration's fine stage and polish now run `icp_point_to_plane`:
the same loop (point-to-plane, Tukey weights, the same pairs, steps and stopping rule) written out in numpy. On a
rendered beam scene it lands within a micrometre and a microradian of Open3D's result (the bound its test checks) and
repeats to the bit, and so does the whole registration (tests in `test_registration_rgbd.py`; with Open3D's ICP the
same check found the two poses apart in their last bits, a run not kept); it takes
about as long (timed by hand, not kept). (2) The benchmark's workers take whichever seed is next, and OpenCV's own
random generator (PnP RANSAC draws from it) carried over from the scenes a worker ran before: each scene now starts it
at its seed (`family.scene_map`; test in `test_family_bench.py`). The most common reason in a row broke its ties by
Python's per-process string hashing; now by the first seen. Development seeds 0-9 ran twice on this code
(`family_boot_dev_stop64`, `family_boot_dev_repeat`) and once with the generator still carried over: every row and every
frame's estimate the same. The registrations are those of stop 63 to the digit (`family_boot_registration` and its
development run, every row); the beams' (`family_registration`) read 0.47 mm and 0.14 degree at the median (0.50 mm and
0.15 in its last run, 2026-11-25, on older SLAM code), stereo 2.1 mm and 0.06 degree (2.0 mm). The beams' and plates'
tracking tables were not rerun: their registration moves by less than a micrometre where the test compares the two
ICPs, below the spread they were drawn with.

On this code, development seeds 0-9 (`family_boot_dev_stop64`): median of the per-scene medians **0.89 %**, p90 **3.41
%**, **60 %** within 1 %, **80 %** within 2 % (stop 63's draw, `family_boot_dev_polish_4`: 0.62 %, 3.01 %, 60 %, 80 %).
Held-out seeds 1000-1019 (`family_boot_stop64`, run once): **1.65 %**, p90 **9.66 %**, **30 %** within 1 %, **60 %**
within 2 %, alpha_z 2.3 degrees off at the median (stop 63's draw, `family_boot_stop63`: 2.06 %, 9.39 %, 40 %, 45 %).
Rows that moved most between the two draws: 1003 0.60 -> 1.05 % (p90 1.2 -> 15.4 %, alpha_z 0.4 -> 4.7 degrees), 1017
0.80 -> 0.70 % (alpha_z 2.7 -> 24.4 degrees: p90 4.4 -> 12.4 %), 1001 2.08 -> 1.19 %, 1008 2.45 -> 1.36 %, 1004 2.71 ->
1.95 %, 1005 4.44 -> 3.30 %, 1007 9.83 -> 11.86 %. What fails is what failed: alpha_z on 1015 (29 degrees, theta 10.8 %
with every frame called OK) and 1017's later frames; theta 7.9-11.9 % off on 1007, 1009 and 1013 with alpha_z within
1.3-4.3 degrees (1007 and 1013 partly flagged, 1009 not); 1018 registered 11.8 mm off on noisy depth, every frame
flagged. Development seeds 10-19 (`family_boot_dev_10_19_stop64`, new; no choice made on them yet): **0.98 %**, p90
**2.85 %**, **50 %** within 1 %, **80 %** within 2 %, alpha_z 0.6 degree off at the median. Theta read off with alpha_z
within a degree and every frame called OK: 13 (3.45 %) and 16 (2.78 %, where the search never ends: 1.7 s per frame at
the median); alpha_z 5.3 degrees off on 12 (p90 6.2 %). These are the held-out failures' kind, on scenes that may be
traced.

**Stop 65: the object points the map keeps.** Tracing development boots 13 and 16 (theta 3.45 and 2.78 % off in
`family_boot_dev_10_19_stop64`, far more than the standard deviation the fit claimed; the traces not kept) found the
tracker's measurements falling to a fraction of their number at rest once the lever bent, and why: a deformable point
never joins the pose's matches nor a keyframe's fusion, so it gains neither keyframes nor finds, and the SLAM's
culling of young points (ORB-SLAM2's rule: seen by too few keyframes two keyframes on) erased every object point made
after the start. The measurements were always the youngest points, each linked through the estimate of the moment it
was first seen. A first version kept every deformable point: boot 13 read better, but boot 1 far worse: points linked
while the boot was far off in alpha_z (the camera lost every other frame) kept that error for good (that run was
stopped at seed 6 and is not kept, so its figures are not quoted). What landed: the tracker tells the map which points
it linked at rest (`/simreal/localization/deformable_points` now carries `flags`: bit 0 the fit rejected the point,
bit 1 linked at rest), and the map keeps those (`SlamConfig.hold_rest_points`, thesis §4.4's scanned points); a point
linked while the object was deformed is culled as before. A keyframe no longer makes a copy of a followed deformable
point (its feature looked free to the keyframe because the pose's matches leave the point out;
`SlamConfig.followed_px`, 3 px). And a tracked parameter whose standard deviation exceeds a uniform draw's over its
range (range / sqrt 12) keeps its last value, flagged (a trace of development boot 12 had shown the lever read far off
at its 47 degree hold from a handful of points; with the rule its p90 is
8.6 %, `family_boot_dev_10_19_stop65`).

Development seeds 0-9 (`family_boot_dev_stop65`; stop 64's code: `family_boot_dev_stop64`): median of the per-scene
medians **0.66 %** (0.89 %), p90 **2.23 %** (3.41 %), **80 %** within 1 % (60 %), **80 %** within 2 % (80 %); seed 8's
search, which never ended (7.8 %, 0.86 s per frame), ends (0.67 %); seed 7 went 0.84 -> 2.14 % (alpha_z 3.9 degrees
off). Development seeds 10-19 (`family_boot_dev_10_19_stop65`; `family_boot_dev_10_19_stop64`): **0.55 %** (0.98 %), p90
**1.45 %** (2.85 %), **70 %** within 1 % (50 %), **90 %** within 2 % (80 %); 13 3.45 -> 0.63 %, 16 2.78 -> 0.41 % (its
search ends too). With the rest points culled as well (`--slam hold_rest_points=false`, seeds 0-9,
`family_boot_dev_hold_rest_points_false`): 1.25 %, p90 10.0 %, 40 % and 60 %: the copies' suppression alone is worse
than nothing (seed 8 32.7 %, seed 1 7.5 %). With the rest points kept and the copies allowed (`--slam followed_px=0`,
seeds 0-9, `family_boot_dev_followed_px_0`): 0.77 %, p90 1.77 %, 50 % within 1 %, 90 % within 2 %: a better tail, a
worse median and share within 1 % than the default's (0.66 %, 2.23 %, 80 %, 80 %); the default stays, the knob is
measured. The step times of the development runs are not comparable: traces ran beside them.

**Held-out seeds 1000-1019 on stop 65's code** (`family_boot_stop65`, run once after the choice): median of the
per-scene medians **1.60 %** (stop 64: 1.65 %), p90 **11.4 %** (9.66 %), **20 %** within 1 % (30 %), **60 %** within 2 %
(60 %), alpha_z **1.0 degree** off at the median (2.3). The development gain did not hold out. alpha_z improved: 1017
24.4 -> 1.1 degrees (p90 12.4 -> 3.3 %), 1003 4.7 -> 0.2 (p90 15.4 -> 0.74 %), 1015 28.8 -> 16.5 (theta still 11.3 %).
Theta's median improved on 11 scenes (1001 1.19 -> 0.56 %, 1006 0.80 -> 0.31 %) and worsened on 9: 1002 (alpha_z 2.8 ->
6.6 degrees), 1010 (0.87 -> 1.82 %), 1012, 1013 (9.5 -> 11.6 %), 1014 (0.49 -> 1.37 %), 1015, 1016, 1017 (0.70 -> 1.35
%) and 1019 (2.14 -> 4.03 %, alpha_z 4.5 degrees). The failures that remain: theta 6.6-11.7 % on 1007, 1009, 1013 and
1015; 1018 registered on noisy depth (flagged). On the model's own render (the unit test
`test_joint_boot_lever_angle_and_...`) the kept rest points cost accuracy: 1.55 degrees at the median against 0.61
before (0.37 with them culled), the lever read 0.6 degree off while it still rests as the camera travels. Three causes
were tried and ruled out on that scene (scratch variants, not kept): the flow's drift (old tracks snapped onto ORB
corners), the prediction as the flow's start, stale viewpoints (points measured only within 15 degrees of their link:
the lever was lost). Open. The beams (dense measurement, which reads no map point, but the same map) on development
seeds 0-19 (`family_dev_0_19_stop65`): median of the per-scene medians 0.27 %, p90 1.07 %, 85 % within 1 %, 100 %
within 2 % (`family_dev_0_19`, its last run, 2026-11-27: 0.29 %, 1.08 %, 85 %, 100 %); the beams' held-out tables were
not rerun.

**Stop 66: the fit refitted on its inliers, measured and left a knob.** A trace of development boot 12 (scratch; the
lever at 7-10 degrees, read 1.1-1.3 degrees high and alpha_z frozen 4.3 degrees off in `family_boot_dev_10_19`) showed
a large share of the followed object points more than 3 x Huber (6 px) off once the lever bent, and on boot 10 at 42
degrees too, against few at rest. Huber bounds each such point's pull but keeps it, and a large share of the points
off the same way biases a fit (the unit test `test_refits_remove_the_bias_of_outliers_off_in_one_direction`: 8 of 26
points 8-20 px off put Huber 34 % of the range off, 4.4 standard deviations; refitted, 1 %). The knob
`tracking.outlier_refits` (`lm.solve_generic(refits=)`) follows each frame's fit with up to that many fits on the
measurements then within 3 x Huber, re-classified each round, as ORB-SLAM2's pose optimisation does; a round that ends
with fewer inliers than it was fitted to is undone (the first version kept it and lost a frame of the starved
unit-test graph, where few points agreed: a run not kept).

It was first made the default (3) on development seeds 0-19, compared with stop 65's tables: 0.62 % against 0.63 %, p90
1.15 % against 2.15 %. Those tables came from an earlier session's host; this one (AMD EPYC with AVX-512, where a
contact-truth test failed on round-off) reads the same code otherwise, scene by scene (development seed 2: 3.06 % there,
0.55 % here). Run like for like on this host, Huber alone (`family_boot_dev`, `family_boot_dev_10_19`) read 0.66 %, p90
1.47 %, 85 % within 1 %, 90 % within 2 % over seeds 0-19, and the refits (`..._outlier_refits_3`) 0.62 %, 1.15 %, 85 %,
100 %. The held-out seeds then ran once with the refits (`family_boot_outlier_refits_3`): **1.98 %**, p90 6.60 %, 15 %
within 1 %, 50 % within 2 %. Huber alone on the same seeds and host (`family_boot_stop66`, run after the default was
fixed): **1.61 %**, p90 6.74 %, 30 %, 60 %. The development gain did not hold out. Before any change to the default, the
rule was written down: grow the development set to seeds 0-39 (`family_boot_dev_20_39`, new), and keep 3 only if its
median of the per-scene medians is no worse and its share within 2 % no smaller than Huber alone's there. Seeds 20-39
read 1.75 % with the refits and 1.89 % without (p90 25.3 and 19.0 %, 60 and 50 % within 2 %); over 0-39, **0.96 %** with
the refits against **0.93 %** without, 80 % against 70 % within 2 %. The median rule failed, so the default is Huber
alone again and the refits are a knob. The held-out table `family_boot_stop66` is Huber alone's run on this host: **1.61
%** of the lever's range at the median (stop 65's host: 1.60 %), p90 **6.74 %** (11.35 %), **30 %** within 1 % (20 %),
**60 %** within 2 % (60 %), alpha_z 1.3 degrees off at the median (1.0). Per scene the two hosts differ widely (1007
11.7 -> 4.1 %, 1018 8.4 -> 0.6 %, 1009 6.6 -> 5.7 %, 1017 1.35 -> 6.3 %: its registration lands 17 mm off on noisy depth
here, flagged, 0 % OK). The model's own reading of the truth is 0.78 % off at the median of the held-out scenes; the
tracker adds the rest (2.11 % against that reading). Development seeds 20-39 are as hard as the held-out ones (1.89 %
against 1.61 %); seeds 0-19, on which earlier stops chose the boot's settings, read 0.66 %.

**Stop 67: where the wrong measurements come from.** `python -m benchmarks.boot_measurements` (new:
`benchmarks/results/boot_measurements.md`, rerun in stop 70: stop 67's run is in git history) labels every object
measurement of a boot scene against the independent truth: a measurement is wrong when it lies more than 3 x Huber (6
px) from where the truth puts the material point its link holds, and each is labelled by how the SLAM measured it
(Lucas-Kanade flow from the previous frame, ORB re-acquisition by descriptor within `SlamConfig.deformable_radius` =
20 px of its prediction, or a match of the pose's search). On development seeds 10 and 12, over the frames more than a
degree from rest: **87 % of the 3399 re-acquisitions are wrong** (90 and 84 %). Of the wrong flow measurements, 72-74
% belong to tracks that began at a wrong re-acquisition, 16-21 % at a wrong match of the pose's search, and 7-11 %
began right and slid: the flow follows what it is given. Fitting each frame without the measurements the truth calls
wrong (an oracle, never an estimate) reads 1.21 and 1.39 % of the range against 2.13 and 2.26 % with them. The 6 px
label is coarse (the model's polygonal surface against the truth's round one puts a point seen obliquely a few pixels
off: at rest 23-32 % are labelled wrong), so the oracle bounds what cleaner measurements could give; it is not a
target.

Two ways to keep the wrong re-acquisitions out were measured against the rule of stop 66 (development seeds 0-39, the
median of the per-scene medians no worse, the share within 2 % no smaller than the default's 0.93 % and 70 %).
Re-acquiring only within 6 px of the prediction (`family_boot_dev_0_39_deformable_radius_6`) read **0.94 %**, 72.5 %
within 2 %: the median rule failed. It helped most scenes a little and lost some: when the lever moves fast the points
followed on it are lost, the estimate lags, and a point whose prediction lags by more than 6 px is not found again (seed
29 28.7 % against 1.18 %, seed 7 4.95 % against 0.81 %). No re-acquisition but the wide one after most tracks are lost
(`family_boot_dev_sel_deformable_radius_0`, six seeds): the two traced seeds read **0.57 and 0.78 %** (from 2.09 and
2.24 %; `boot_measurements_deformable_radius_0`: 19-40 % of their bent frames' measurements wrong against 50-61 %), and
the four scenes the 6 px knob lost are lost too (seeds 7, 29, 26, 24: 3.4, 26.3, 11.1, 4.0 % against 0.81, 1.18, 1.47,
0.45 %). On seed 29 the lever goes back from 41 to 21 degrees and the estimate stays at 36: the points that remain
measured do not pull it along. The wrong re-acquisitions are what drag the estimate along in those moves, and what bias
it everywhere else. **The default stays 20 px**; both radii are knobs with their tables. What is left: find lost object
points again without descriptors (the flow from the last image that followed them, started at the prediction) and a
prediction that does not lag a fast lever.

**Stop 68: measurements that move unlike their neighbours, measured and left a knob.** Where do the wrong
re-acquisitions come from? A scratch trace of development seed 10 found the prediction the SLAM searches around close
to the truth's pixel, and the wrong re-acquisitions far from it: the right feature is not among ORB's corners near the
prediction, and the closest descriptor within 50 bits is another corner of the speckle. A ratio test (the best under
0.8 of the second best at least 2 px away) with each feature given to one point left most of them wrong (scratch,
seeds 10 and 12): on the speckle a wrong match is as distinctive as a right one. Its motion tells it
apart: a lagging prediction offsets a region's measurements alike, a wrong match offsets its own. The knob
`SlamConfig.coherence_px` (new) drops each object measurement, followed or re-acquired, whose offset from its predicted
pixel differs by more than that from the median offset of its image neighbours (within `coherence_radius_px` = 40 px, at
least `coherence_min` = 3 of them; a point with fewer is kept).

It was set on development seeds. On six of them (7, 10, 12, 24, 26, 29; scratch runs) 4 px dropped too much (seed 12's
alpha_z went to the other basin) and 8 px lost none of the fast moves that the radii of stop 67 lost. Over seeds 0-39
(`family_boot_dev_0_39_coherence_px_8`) 8 px read **0.88 %** against the default's 0.93 % (`family_boot_dev`,
`_10_19`, `_20_39`), 72.5 % within 2 % against 70 %, 52.5 % within 1 % against 50 %, the 90th percentile of the scene
medians 4.6 % against 6.3 %. 19 scenes read better and 14 worse by more than 0.05 points (seed 22 18.4 -> 4.5 %, 10
2.09 -> 0.36 %; 26 1.47 -> 3.87 %, 24 0.45 -> 1.94 %, 12 2.24 -> 3.53 %); seeds 0-19 0.58 %, 20-39 2.07 %. On seeds 10
and 12 (`boot_measurements_coherence_px_8`) the bent frames' wrong measurements fall from 61 and 50 % to 40 and 30 %
(flow: 53 and 38 % -> 28 and 14 %; the re-acquisitions kept: 90 and 84 % -> 75 and 70 %). The rule of stop 66 held,
and the held-out seeds ran with it (`family_boot_coherence_px_8`): **1.60 %** against 1.61 %, p90 6.91 % against 6.74
%, 30 % within 1 % and 60 % within 2 % as before, alpha_z 1.2 degrees off at the median against 1.3; ten scenes better
and ten worse (1015 12.5 -> 3.7 %, 1009 5.7 -> 2.3 %; 1007 4.1 -> 9.5 %, 1002 0.98 -> 2.75 %, 1003 0.24 -> 1.41 %).
The development gain did not hold out. The check also reaches every scene tracked by map points: in
`docs/tracking.md`'s second table (rerun in this stop) the foam beam at 640 x 480 reads far worse with it (7.2 -> 18.6
mm, p90 26.6 -> 399 mm), the thesis's boot (1.55 -> 1.50 degrees) and the foam beam at 1280 x 720 (3.0 -> 3.1 mm)
level. A check that helps one family's development seeds, not its held-out ones, and breaks another scene is a knob,
so **the default stays off**; its rows are in both documents. Also tried on the six seeds and not kept (scratch, no
code): a guided re-acquisition, within 6 px of the prediction moved by the followed neighbours' median offset, lost
the fast moves again (seeds 29 and 7).

The rerun of `docs/tracking.md`'s second table made `flow anchor 1 px` (each followed point re-measured against the
image its track began in, `SlamConfig.flow_anchor_px`) the best row on both of its scenes (the thesis boot 1.43 against
1.55 degrees, the foam beam 1.4 against 3.0 mm). It had never run on the family. On development seeds 0-39
(`family_boot_dev_0_39_flow_anchor_px_1`) it reads **1.17 %** against 0.93 %, 62.5 % within 2 % against 70 % (15 scenes
better, 21 worse; seed 25 25.9 against 14.6 %, 26 4.04 against 1.47 %): it stays off, and the held-out seeds were not
run.

**Stop 70: the boot registered as a body of revolution.** The registration alone (`python -m benchmarks.family_boot
--registration --seeds 0-39`, scratch) refused its first try on several of the 40 development boots. Mostly because
every coarse fit had turned more than 30 degrees from the guess: the bellows is a body of revolution about its axis
(its surface turned by 17, 45, 90 or 151 degrees lies on itself within 2 mm; the beams', the bunny's and the dragon's
do not), so the ICP turns it about that axis freely, and the turn check took the right fits for another basin. Once
(seed 36) because the guess, its base under the table, was beyond every coarse start. A refused registration collects
its views again, and by then the lever is loaded: the loaded fit matched too few of the faces (seed 36: 16 %, its
refusal in `family_boot_dev_20_39`) and seed 36 was never placed (25.5 %), seeds 25 and 38 were placed late (14.6 and
24.7 %). Now (`registration.revolves_about_z`, `turned_like`, `lifted_onto`) a body of revolution is judged by its
axis's tilt alone and keeps the guess's turn about the axis (the fine stage had left seed 0's far from the guess: the
turn the tracker's alpha_z is measured from was a draw of the ICP), and a guess that sinks the model under the support
plane is lifted onto it. The first registration on development seeds 0-39 (`family_boot_dev_0_39`): none refused, 0.14
mm and 0.05 degrees at the median as before, worst 0.49 mm and 0.31 degrees. The beams' registration (`python -m
benchmarks.family --seeds 0-9 --registration`) reads as before in every row. Tests
(`tests/assimilation/test_registration_revolution.py`, a boot cloud made from its model's surface with clutter beside
it): guesses turned -120 and 180 degrees about the axis (refused before) and one 11 cm off under the floor are placed
within 1 mm and 0.3 degrees, with the guess's turn.

Development seeds 0-39 (`family_boot_dev_0_39`): **0.98 %** of the lever's range at the median of the scene medians
against 0.93 % on stop 66's code (`family_boot_dev`, `_10_19`, `_20_39`), p90 **3.65 %** against 6.30 %, 52.5 % within 1
% against 50 %, 65 % within 2 % against 70 %. The three scenes whose refused registration had placed them late or
never: 14.6 -> 4.3 % (25), 25.5 -> 0.74 % (36), 24.7 -> 4.3 % (38); seed 22, placed as before, 18.4 -> 3.2 % (alpha_z
11.9 -> 1.8 degrees off). Every other scene's registration moved by at most 0.2 mm and by its turn about the axis, and
their errors moved both ways (18 scenes better and 17 worse by more than 0.05 points; seed 7 0.81 -> 4.33 % with
alpha_z 6.9 degrees off, seed 8 1.40 -> 3.43 %). The first version of the change (`family_boot_dev_0_39_icp_turn`: the
tilt check, the fit left at the turn the ICP drifted to) read 1.02 %, p90 4.0 %, 50 % and 77.5 %, with its own
scene-by-scene spread (seed 7 1.23 %, seed 26 7.16 %). Turning the guess 7.5 degrees about the axis
(`family_boot_dev_0_39_guess_turn_7_5`, `--guess-turn 7.5`: a turn the depth does not show and the user does not know,
half a step of the alpha_z search) reads 0.91 %, p90 3.05 %, 52.5 % within 1 % and 75 % within 2 %: the scene medians
moved by 0.28 points at the median, by more than a point in 7 of the 40 scenes and by up to 4.7 (seed 38 4.29 -> 8.97
%, seed 7 4.33 -> 2.17 %). Over these three draws of a turn nothing can see, the development summary spans 0.91-1.02 %
at the median and 65-77.5 % within 2 %; stop 66's 0.93 % and 70 % lie inside that spread. That a boot scene's error
hangs on it by several points is a fault of the tracker (the alpha_z search's grid, the model's 48 facets around the
axis), left for a later stop. By stop 66's rule for a default (median no worse, share within 2 % no smaller) the
change would fail; it is kept because it is not a knob: a registration that refuses the right fit is a fault, and
which way the ICP left an invisible turn is a draw, not a setting.

Held-out seeds 1000-1019 (`family_boot_stop70`, run once on this code; stop 66's is `family_boot_stop66`): **1.42 %**
against 1.61 %, p90 **3.92 %** against 6.74 %, 20 % within 1 % against 30 %, **70 %** within 2 % against 60 %, alpha_z
0.83 degrees off at the median against 1.25. The registration: 0.12 mm and 0.04 degrees at the median, **worst 0.24 mm
and 0.10 degrees** (1017 was 17.1 mm off on noisy depth before, 1013 1.06 mm with its axis tilted 4.4 degrees); the
registration alone (`family_boot_registration`) refuses none of the 20 first tries (3 on the run before: 1000, 1013,
1018). Eleven scenes better and six worse by more than 0.05 points (1015 12.5 -> 5.0 %, 1013 10.7 -> 3.8 %, 1017 6.3 ->
1.6 %, 1009 5.7 -> 3.0 %; 1007 4.1 -> 8.7 %, 1018 0.60 -> 1.34 %, 1000 0.57 -> 0.95 %). The beams' targets (< 1 %, p90 <
3 %, >= 90 % within 2 %) are still not met; the model's own reading of the truth is 0.78 % off at the median, the
tracker's estimate 1.52 % off that reading. `boot_measurements` (development seeds 10 and 12) was rerun on this code:
88 % of the 3307 re-acquisitions on the bent boot are wrong (stop 67's table: 87 % of 3399), the frame fit on all
measurements reads 2.02 and 2.28 % (2.13 and 2.26 %), the oracle on the right ones 1.21 and 1.23 % (1.21 and 1.39 %).
Rerun again in stop 110 on this code (the SLAM and the tracker have changed since, stops 71-108; which change moved
what was not traced): 88 % of 5275 re-acquisitions wrong (92 and 86 % on seeds 10 and 12), the flow's measurements 31
and 19 % wrong (37 and 42 %), the frame fit on all measurements 0.76 and 1.37 % (2.02 and 2.28 %), the oracle 1.00 and
0.94 % (1.21 and 1.23 %): the re-acquisitions are as wrong as before, and the frame fits read closer to the oracle.

**Stop 71: the lever read from depth.** On stop 70's code the development boots worse than 2 % were not noisy but
biased: 11 of those 14 scenes (seeds 0-39) read the lever low over their whole run (seed 30 by 3.6 points, seed 8 by
3.4). The images' measurements are ORB map points followed by flow and re-acquired by descriptor on a faint speckle
that deforms; labelled against the truth (`boot_measurements`, above) most re-acquisitions and many flow tracks sit
pixels from the material point their link claims, and a robust fit cannot tell a consistent share of them from the
bending. An RGB-D camera measures the surface's shape without matching anything: the non-rigid point-to-plane fit that
reads a scene's first state from its depth (`depth_state.fit_state`) can read every frame. `tracking.depth_fit`
(`depth_state.DepthFollower`, default off) does that after the image fit: Gauss-Newton from the image fit's lever and
from the last depth state, the cheaper kept, with the upright rigid correction carried from frame to frame (the
camera's drift against the registered pose, a turn that alpha_z has wrong); the images still give alpha_z, the fit's
start and whether a deformation is seen, and the measurements the depth's state puts more than 4 px off are dropped from
the SLAM's tracks (they are searched again). A frame whose depth shows less than 300 points of the object, or whose fit
explains less than half of them, keeps the image fit.

Development seeds 0-39 (`family_boot_dev_0_39_depth_fit`): **0.33 %** of the lever's range at the median of the scene
medians against 0.98 %, p90 **0.69 %** against 3.65 %, **95 %** of the scenes within 1 % against 52.5 %, **100 %**
within 2 % against 65 %; 35 scenes better and 2 worse by more than 0.05 points (seed 4 0.36 -> 0.42 %, 24 0.57 -> 0.66
%). The 14 scenes over 2 % read 0.18-1.48 % (seed 30 3.58 -> 0.20 %, 8 3.43 -> 0.43 %, 28 5.80 -> 1.48 %, 25 4.27 ->
1.07 %). The model's own reading of the truth's surface nodes is 0.74 % off at the median: a fit of the surface's shape
to the depth leans less on the model's tangential error than one of its nodes' displacements. alpha_z is 1.2 degrees
off at the median as before (1.1); on seed 38 the image fit sent alpha_z to the other basin (124 degrees off) and the
lever still reads 0.40 % (the rigid correction takes the turn), but 59 % of its frames are flagged (the images fit
nothing). The price is time: the tracker's median time per frame goes from **8 to 123 ms** (the step from 40 to 155
ms; this host, two scenes at once). That was judged on these development seeds, so the boot's family scene file sets
it (as it sets `constant_search`), and the held-out seeds ran after, once.

Held-out seeds 1000-1019 (`family_boot_stop71`; stop 70's run is `family_boot_stop70`): **0.47 %** against 1.42 %, p90
**0.74 %** against 3.92 %, **95 %** of the scenes within 1 % against 20 %, **100 %** within 2 % against 70 %: the
beams' targets (< 1 %, p90 < 3 %, >= 90 % within 2 %) are met on these 20 boots. 19 scenes better and one worse by more
than 0.05 points (1003 0.28 -> 0.45 %); the worst scene medians 1.05 % (1019) and 0.97 % (1007, 8.74 % before; 18 % of
its frames flagged because the images fit nothing, as seed 38 above). The error against the model's own reading is 0.59
% at the median (1.52 % before), beside a model bias of 0.78 %. alpha_z is worse: 1.19 degrees off at the median
against 0.83, and 5-9 degrees off on five scenes (1007, 1015, 1013, 1019, 1008; 1007 was 0.3 before); the lever does
not suffer for it (the rigid correction takes the turn), the overlay's orientation of the bend does. The tracker's
median time per frame is **130 ms** (9 ms before; the step 163 ms against 44 ms), over the issue's 10 ms for map points:
with `depth_fit` off the boot's tracker is as fast and as biased as before. Registration as before: worst 0.24 mm and
0.10 degrees.

**Tried and reverted: alpha_z with the depth's turn.** The depth fit's upright rigid correction turns the model about
its centroid, which on the boot lies on its axis, so the turn it settles at looks like what the images' alpha_z missed.
A variant (commit 8aaae21, `DeformableTracker.depth_turn`) reported alpha_z with that turn, the images' own value still
driving the links, the search and the freezing (the lever the same to the bit). On the family it helped: development
seeds 0-39 (`family_boot_dev_0_39_depth_turn`) alpha_z 0.27 degrees off at the median against 1.16, p90 0.82 against
3.70; the held-out seeds, run once more (`family_boot_depth_turn`), 0.37 against 1.19, p90 1.07 against 5.43, none worse
by more than half a degree. On the thesis's boot views it failed (`thesis_truth_boot_depth_turn`): 6.47, 5.25 and 12.43
degrees against 0.33, 1.82 and 0.86 on the own, second and held-out views. Those scenes end with the lever back near
rest, where the bellows is round again and the fit's turn is free to drift; the family's scenes end on a hold. A turn
taken only from bent frames may fix it; it was not measured, so the variant is not in the code.

**Stop 72: the depth fit at half the cost, and alpha_z from the depth's turn.** Where the time went (a profile of
development seed 8): Gauss-Newton in the depth fit asked for the residuals at a trial state, then again for their
Jacobian at the same state, and for the step's cost a third time, each a new KD-tree over the 7000 model samples; and
the lens was undone for every pixel of every depth image. Now each state's association is kept for its Jacobian and the
step's cost comes from the residuals at hand (`depth_state._Problem`), the trees are built unbalanced (half the time,
the same neighbours), and the pixel grid is undone once per camera (`registration.depth_cloud`; tested against the lens
model in `test_registration_rgbd.py`). The alpha_z search relinks every map point two dozen times a frame; it now keeps
each deformation's search trees (`registration.LinkIndex`) and tests a point's candidate triangles in one array
operation. All of it gives the same numbers to the bit but one change: the samples' displacement comes from the field's
own evaluation instead of the Jacobian's (they differ by rounding). That alone moves single scenes (checked by hand:
stop 71's code with only that change reproduces stop 72's lever to the bit on seeds 1000 and 1001, which stop 71's
table read at 0.34 and 0.26 %, this stop's at 0.29 and 0.20 %). Over the 20 held-out scenes single scene medians moved
by up to 0.24 points (1019 1.05 -> 0.81 %, 1013 0.71 -> 0.54 %) and the summary by 0.01: the scale of this benchmark's
noise per scene.

alpha_z (`tracking.depth_turn`, set with `depth_fit` in the boot's scene files). The depth fit's upright rigid
correction turns the model about its centroid, which on the boot lies on its axis. Stop 71's variant (above) reported
the turn the fit had reached at the end and drifted on the thesis's views, which end with the bellows round again. Now a
frame's turn counts only where the depth holds it: the standard deviation of the turn on the fitted shape is under half
of what the round rest shape gives on the same points (`DepthFit.turn_held`, unit residuals; a ratio, so that it does
not depend on how many points the camera sees: 0.8-1.25 at rest and under 0.3 at levers of 34 and 46 degrees in
`test_depth_follow.py`). Each such frame gives the boot's whole turn, the images' alpha_z of its fit plus the depth
fit's turn, and the estimate reports the median over those frames (the last 300); the images' own alpha_z still drives
the links, the search and the freezing, so the lever is the same to the bit as without the knob. A first version took
the last such frame's turn and was worse than the images alone on the thesis's own view (the turn moves by degrees from
frame to frame; numbers in stop 72's note; that run also took in the thesis's held-out view, which is therefore not
blind to the choice between the two versions). The median over the frames reads the thesis's own view 0.26 degree off
and its second view 0.43 (the images alone: 0.07 and 0.53; `docs/tracking.md`), and the development seeds
(`family_boot_dev_0_39_stop72`): **0.26 degree** at the median against the images' 1.16, p90 0.63 against 3.71, the
worst 0.7 degree (seed 17); seed 38, whose images end with alpha_z in the other basin, 124 degrees off, reads 0.35
degree (its lever 0.40 %, but 59 % of its frames flagged, as in stop 71); one scene worse by more than half a degree
(seed 5, 0.0 -> 0.6). The lever there: 0.35 % at the median, p90 0.68 %, 95 % of the scenes within 1 %, all within 2 %;
the tracker 65 ms a frame (stop 71's table: 123 ms).

Held-out seeds 1000-1019, run once after that (`family_boot_stop72`; stop 71's is `family_boot_stop71`): alpha_z
**0.31 degree** off at the median against the images' 1.03 (stop 71: 1.19), p90 0.52 against 5.56, the worst 0.7
degree against 8.7; one scene worse by more than half a degree (1003, 0.1 -> 0.6). The lever: **0.48 %** at the median
of the scene medians (stop 71: 0.47 %), p90 **0.65 %** (0.74 %), **100 %** of the scenes within 1 % (95 %) and within
2 % (100 %). The tracker's median time per frame **62 ms** (130 ms), the step 98 ms (163); the scenes whose alpha_z
search ran long: 1002 743 -> 179 ms, 1015 502 -> 131 ms. Still six times the issue's 10 ms for map points, which holds
on the boot only with `depth_fit` off (9 ms). The thesis's held-out view (`docs/tracking.md`): alpha_z **0.11 degree**
off (the images' own 0.93; stop 71 0.86), the lever 0.22 degree as in stop 71.

**Stop 73: the depth fit's search trees kept, and the held-out boots 1000-1099.** Each step of the depth fit's
Gauss-Newton moves the model's samples by a fraction of a millimetre, and each still built a new KD-tree over all 7000
of them to find every measured point's nearest sample. Now the tree of an earlier placement answers while no sample
has moved half the sample spacing (1.5 mm) since (`depth_state._Problem._nearest`). A sample moved by at most delta is
no nearer to a point than its distance there less delta. So a point's 8 nearest samples there decide it wherever the
nearest of them now is nearer than the 8th was less delta (or the radius is), and the few other points search the old
tree within their distance plus delta. The answer is the one a new tree gives: `test_depth_state.py` checks it along a
walk of states (it fails with the few points' search taken out), and the held-out seeds 1000-1019 read as stop 72's
to the bit. Development seed 8's depth fit, replayed alone (scratch), took less time a frame; the thesis's boot views
(`docs/tracking.md`) 37-45 -> 31-35 ms; over the 20 held-out boots the tracker's median is within the host's noise of
stop 72's (62 ms both; the scenes' ratios 0.8-1.2, 0.95 at the median).

Held-out seeds 1000-1099, the issue's 100 (`family_boot`; seeds 1020-1099 never run before, the defaults all chosen on
development seeds 0-49; stop 72's 20 are `family_boot_stop72`): the lever **0.38 %** of its range off at the median of
the scene medians, p90 **0.81 %**, **93 %** of the scenes within 1 % and **98 %** within 2 % (the targets: < 1 %, < 3 %,
>= 90 % within 2 %). alpha_z **0.29 degree** off at the median (the images' own: 1.13), p90 0.59, the worst 1.1
degrees (1031, whose images end 124 degrees off, in the other basin). The registration: 0.15 mm and 0.05 degree at
the median, 0.37 mm and 0.21 degree at worst. Two scenes miss 2 %. 1083 (3.9 %): the SLAM lost the camera on 46 % of
the frames, and the lever kept its last value (10 degrees) through holds at 20-46 degrees. 1066 (2.7 %): the model's
own error, its best fit to the truth's surface reads 2.2 % off at the scene's levers of 46-50 degrees and the tracker
is 0.6 % from that best fit. The next two (1026 1.8 %, 1027 1.8 %) are of the same kind: the model's best fit 2.0 and
1.7 % off, the tracker 0.4 % from it. The tracker takes **58 ms** a frame at the median of the scenes (p90 115 ms), the
step 92 ms: six times the issue's 10 ms for map points, which the boot meets only with `depth_fit` off (9 ms).
Stop 84 made the same fits cheaper, with identical estimates (`benchmarks/results/depth_budget.md`,
`docs/tracking.md`): 0.90 of the tracker's time at the pairs' median on development seeds 0, 8 and 22; this table
was not rerun.

The depth fit's trade (`tracking.depth_stride`, new in stop 73: one depth pixel in so many along each axis is matched
to the model; 2 by default). Development seeds 0-39 with 3 (`family_boot_dev_0_39_depth_stride_3`, one depth pixel in
9 matched instead of one in 4) against the defaults (`family_boot_dev_0_39_stop72`, the same fits): the tracker
**65 -> 38 ms** a frame at the median of the scenes (0.58 of it, scene by scene), the step 94 -> 71 ms; the lever
**0.35 -> 0.40 %** at the median, p90 0.68 % both, 95 % within 1 % both, all within 2 %; worse by more than 0.2 points
on seeds 27 (0.69 -> 1.05 %) and 38 (0.40 -> 0.67 %), better on none; alpha_z 0.26 -> 0.29 degree. Accuracy first: the
default stays 2, and 3 is a knob for a user who wants the time. With 4, development seed 8's frames (replayed alone,
scratch) keep fewer points on the boot than the fit's 300, and the depth fit stops. Far from 10 ms either way.

**Stop 87: a constant seen well is not moved by weaker frames.** alpha_z is a constant: fitted on every frame until
`constant_frames` (40 in the boot's scene files) frames have shown it well (standard deviation under
`constant_std_frac` of its range), then frozen at their median. A graph that takes fewer frames a second gathers
fewer such frames: the live joint boot never froze it, and the frames between and after (the lever back at rest)
moved it freely (`tests/assimilation/test_tracker.py`, every 3rd frame of the boot sample: 138 degrees off at the end
before, 0.5 after). Now, once it has such frames, a frame that does not show it well holds it at their median; and a
constant a frame is blind to (the object undeformed, or its standard deviation over 5 % of its range) is reported
with the value it keeps, not the fit's. On the development seeds 0-9 (`family_boot_dev_stop87` against
`family_boot_dev_stop87_before`, the same code without the rule, run one after the other): five scenes identical, the
lever **0.29 -> 0.30 %** at the median of the scene medians, p90 0.42 -> 0.39 %, all within 1 % both; scene by scene
within 0.04 points (seed 4 0.42 -> 0.38 %, seed 8 0.28 -> 0.31 %, the one scene that never freezes alpha_z); alpha_z
0.28 -> 0.29 degree. Level on the family, which samples at 15 frames a second and reports alpha_z with the depth's
turn; the rule stays for the starved graph. The held-out table was not rerun.

**Stop 88: a frame without image measurements read from its depth alone; the support plane from a subset.** The live
joint boot on independent physics (`benchmarks/live_slam.py`, moved this stop from the demo sample to
`joint_boot_truth_live`) lost its lever in some runs (that table was not kept): once the lever moved, its map points
were not found again (the localization skipping frames, the registration placing the boot late), and a frame with
fewer than `min_measurements` image measurements on the object was reported lost with its last values although its
depth image showed the lever. With `depth_fit` such a frame is now read from its depth alone (`tracking.depth_alone`,
on): the depth fit from the last values, alpha_z held, reported low-confidence with the reason. On development seeds
0-9 it changes nothing (`family_boot_dev_stop88` against `family_boot_dev_stop88_depth_alone_false`: every curve and
state identical; offline, at 15 frames a second, no frame has too few image measurements); the live table shows what
it changes. The registration's support plane: RANSAC on 20 000 of the fused points
(`RegistrationConfig.plane_samples`) instead of all of them, its inliers then counted over all. The registration step
alone, development seeds 0-9, one run after the other (`family_boot_registration_dev_plane_samples` against
`..._before_plane_samples`): **3.6 s** at the median against 4.55 s, placed as well (0.14 against 0.13 mm and 0.06
against 0.05 degree at the median, worst 0.31 against 0.29 mm). With both, the development seeds against stop 87's run
(`family_boot_dev_stop88` against `family_boot_dev_stop87`): the lever **0.30 %** at the median of the scene medians
(0.297 -> 0.295 %), p90 0.39 -> 0.37 %, all within 1 %; seed 6 0.42 -> 0.30 %, seed 8 0.31 -> 0.35 %, seed 1 0.16 ->
0.19 %, the others within 0.03 points; alpha_z 0.29 -> 0.32 degree. Level.

Held-out seeds 1000-1019 on stop 88's code, run once after those choices (`family_boot_stop88_1000_1019`): median of
the scene medians **0.46 %** (the main table's rows of the same seeds, 2026-11-30's code: 0.48 %), p90 **1.09 %**
(0.65 %), 85 % within 1 % (100 %), 100 % within 2 % (100 %); alpha_z 0.36 degree (0.31); registration 0.12 mm and
0.05 degree. Over 1 %: 1005 (1.18 %), 1008 (1.09 %) and 1013 (1.09 %). Run again on stop 87's code
(`family_boot_stop87code_4seeds`, with 1002) they read 0.50, 0.89 and 0.68 % (1002 0.46 against 0.59 %), and on stop
88's code with `depth_alone` off every curve is the same (`family_boot_stop88_4seeds_depth_alone_false`): what moved
them is the support plane from a subset, whose registrations differ from the old ones by hundredths of a millimetre
(1005: 0.163 against 0.164 mm off). Other seeds moved the other way (1019 0.81 -> 0.45 %, 1007 0.97 -> 0.73 %): the
tracker amplifies such differences into per-scene medians a few tenths of a point apart, both ways, as on the
development seeds, so the tails of 20 scenes move by as much. The default stays as chosen on the development seeds;
the sensitivity itself is not mended (noted in docs/status.md).

**Stop 89: the boot's turn about its axis held in every ICP step of the registration.** The boot is a body of
revolution (`revolves_about_z`): its surface does not fix its turn about its axis, and the registration keeps the
guess's turn at the end (`turned_like`). Its ICP steps left that turn free: in a trace of development seed 0 (scratch)
the coarse stage's turn wandered widely from step to step and every start ran all 45 of its iterations, and each of
the fine stage's calls turned it again. Now, on a body of revolution, every step holds the turn
(`RegistrationConfig.hold_spin`, on; `icp_point_to_plane(..., hold_turn_about=...)`, the coarse stage a translation
alone) and the two coarse starts turned about the axis are left out; beams and plates are not bodies of revolution and
run as before, to the bit. The registration step alone, development seeds 0-9, `--jobs 1`
(`family_boot_registration_dev_hold_spin` against stop 88's `family_boot_registration_dev_plane_samples`): **2.6 s**
at the median against 3.6 s, placed as well (0.14 mm and 0.06 degree at the median both, worst 0.32 against 0.31 mm).
Development seeds 0-9 tracked (`family_boot_dev_hold_spin` against `family_boot_dev_stop88`): the lever 0.295 -> 0.314
% at the median of the scene medians, p90 0.37 -> 0.39 %, all within 1 % both; seed 6 0.30 -> 0.39 %, every other
scene within 0.03 points; alpha_z 0.32 degree both. Level within the tracker's sensitivity to small registration
differences (stop 88 above): 0.02 points of the range is 0.01 degree of lever. Kept for the time: live, the
registration runs in a worker on the cores the SLAM uses, and `benchmarks/live_slam.py` now places the boot 4.8-5.5 s
after the first frame (stop 88: 5.9-7.6 s; the run before the last, in git history: 4.9-6.1 s; stop 109's run, on an
AMD EPYC host with AVX2: 6.5-7.5 s; stop 113's, on the same kind of host, which `live_slam.md` holds now: 6.7-10.1
s).

Held-out seeds 1000-1019, run once after that choice (`family_boot_stop89_1000_1019`): median of the scene medians
**0.46 %** (stop 88's run: 0.46 %), p90 **0.67 %** (1.09 %), **100 %** within 1 % (85 %) and within 2 %; alpha_z 0.30
degree (0.36); registration 0.15 mm and 0.04 degree at the median (0.12 mm and 0.05 degree), the worst 0.34 mm (1013,
0.07 mm before, whose lever nevertheless reads 1.09 -> 0.51 %). The three scenes over 1 % in stop 88 read 0.47 (1005),
0.61 (1008) and 0.51 % (1013); worse by more than 0.1 points: 1019 0.45 -> 0.92 %, 1010 0.23 -> 0.49 % (alpha_z 2.1
degrees off), 1007 0.73 -> 0.87 %. Scene by scene the results move both ways by tenths of a point as in stop 88: the
tail of 20 scenes is better on this draw, not a measured gain of the change.

**Stop 104: a boot registered with its lever bent keeps the guess's turn, the bend's direction starts alpha_z, and the
deformed fit is polished.** The registration keeps a body of revolution's turn about its axis at the guess's (stop
89), but `register_loaded`, which fits the deformation with the pose where the depth shows the object loaded, let its
deformed fit turn the model about the up axis: with the lever bent, the fit turned the whole boot until the model's
bend (alpha_z 0) pointed where the depth's did, and the tracker then measured alpha_z from that turned pose. On the 8
s clip (`joint_boot_truth`, alpha_z 20 degrees, the lever moving from 1.5 s) registered from views of the bent lever,
the pose was turned 14-28 degrees and alpha_z read as far off; the family never showed it (its boots rest for 1.5 s
and every registration there saw the lever at rest: no alpha_z error in the held-out table over 1.1 degrees; 1.13 at
most in stop 105's rerun). Found by replaying that clip offline with the registration's views taken later and its
result held back, as the live graph's worker delivers it (stop 103's live run lost the lever there). Now the deformed
fit's turn about the axis is given apart (`Registration.turn`), the pose keeps the guess's turn, and the tracker
starts alpha_z from the turn where it estimates alpha_z from the registration's state (`ObjectTrackers`: a fixed
alpha_z keeps its value and the pose takes the rest of the turn; an object without alpha_z, or a tracker that starts
at rest, takes it all in its pose, as before). The same replays showed the deformed fit stopping a pleat away on the
bellows, as the rigid fine stage did before its polish (stop 63): 12 mm off with the lever read 30.7 degrees for 37.4.
The fit is now polished too where the scene asks for a polish (`anchor.polish_mm`, the boot's 4 mm;
`registration._polished_state`: the deformed shape polished as a rigid fit is, from itself and six starts 4 mm away,
and the state fitted again where that moved it). `python -m benchmarks.boot_late_placement` (`boot_late_placement.md`,
new: every second frame, the views from 0 to 5 s into the clip, the result placed at once or at 6 s, each setting also
run with the turn put back into the pose): where the views saw the lever bent (1.6-46.5 degrees on average over the
three views), alpha_z **0.23-1.49** degrees off at the median against 4.8-23.9 with the turn in the pose; theta
0.21-0.44 against 0.22-0.48. The polish, against this stop's first run of the table (commit 27e9066: the turn already
apart, the fit not polished, the same views), views from 2.0 / 2.5 / 3.5 s: the pose's axis origin 2.8 / 4.6 / 12.0 ->
**1.3 / 2.0 / 5.9 mm** off, the registration's lever 4.1 / 13.8 / 30.7 -> 6.5 / 15.4 / 37.3 degrees (the true lever
7.0 / 17.4 / 39.8 on average over the views, which span its motion), theta's p90 with the result held to 6 s 4.2 / 5.8
/ 6.3 -> 1.6 / 1.9 / 0.8 degrees (the review's fix below counts in the last); its cost: the registration from views of
2.0-5.0 s 3.3-4.1 -> 4.6-9.2 s on this host, shared (a boot at rest is not polished again: 2.5-2.6 s both). The views
from 5 s differ between the two runs (the first attempt's outcome moved), so those rows are not paired. The origin
still sits 6-7 mm off with the lever at 40-47 degrees (the model's bend against the independent solve's; 0.02 mm on a
cloud of the model's own bent surface). From a review: the tracker's first depth read (`reference_from_depth`, which
starts the sparse tracker's state) fitted the model unturned by alpha_z, so a turn from the registration of more than
a few tens of degrees would have been read as a boot at rest (now the model drawn as every later depth fit draws it);
the turn goes to alpha_z only where alpha_z turns the model about the vertical through its centroid (the axis a
registration turns a body of revolution about), else it stays in the pose; the benchmark's first run took the lever at
the views from two of the three views (fixed; its registrations are the same). Live (`live_slam`, this stop's rerun),
the 8 s clip's boot was registered from views of the lever at rest and placed after 6.3 s, the lever already bent:
theta 0.17 degrees off from then on, alpha_z 20 degrees off (its start, kept) over the loaded frames it estimated
after the placement, before the lever came back to rest (a scratch trace of the same case: the first frames after a
placement cost 0.3 s and 30-110 ms each offline, and the live graph published no estimate for 1.3 s after it, while
the lever went from 23 to 1 degree). Unit tests: the bent boot's cloud turned 25 degrees (the pose keeps the guess's
turn within 0.5 degree, 25 on the old code, checked; the turn 25 +- 1 degree; the lever 20 +- 0.5; the origin within
0.5 mm, 4.6 mm without the polish, checked); where `ObjectTrackers` puts the turn for each alpha_z mode, the model as
the tracker draws it being the registration's fit in each; a model whose alpha_z turns it about another axis keeps the
turn in its pose; the first depth read with alpha_z at 120 degrees reads the lever within a degree (read at rest
without the fix, checked); and the turn put back undoes the guess's turn.

**Stop 105: a boot placed after its lever bent reads its turn from the first depth image, and the turn is searched
over the circle.** Stop 104's table showed what it left: registered from views of the lever at rest and placed 6 s
into the 8 s clip, the lever already bent, the boot's alpha_z sat at its start (0 for 20) on every frame until its map
points were linked and searched, 6 frames (`boot_late_placement_stop104`: alpha_z p90 20.0 degrees; 15.8 with the
views from 1.5 s), as live (`live_slam`: "alpha_z kept at its start"). Two causes. The frames before the map points
were linked are read from the depth alone (`tracking.depth_alone`), and those gave no turn to `depth_turn` (now they
do, as an image-fitted frame does: `DeformableTracker._take_turn`). And the depth fit's turn has a basin of a few
degrees: on the model's own depth image of the boot bent 0.6 rad and turned 25 degrees, Gauss-Newton from 20 stopped
at 20, from none at 20.3; turned 120 degrees, the fit found no deformation at all; the bellows' round part gives most
of the points, and their re-association makes the cost bumpy (the cost at the true turn is 2.3 times lower than where
it stopped). Now a body of revolution's deformed fit searches its turn over the circle (`depth_state._searched_turn`:
24 turns, each with the fit's lever and 5 more, at the fit's translation and the pose's, ranked on at most 800 of the
points; quarter steps about the best; Gauss-Newton from there; taken where it costs less and the fitted shape holds
its turn, as the depth follower judges a turn). The tracker's first depth read uses it where `depth_turn` is on and
starts alpha_z at the turn it finds (`_start_turn`, as a registration's turn does since stop 104; a fixed alpha_z is
not moved), and so does a registration of a body of revolution (`register_loaded`). A first version also held the
depth follower's pose where the images' alpha_z jumped (the constant search moved it 20 -> 37 degrees on the
late-placed boot, and the depth fit read the lever at 4 degrees for 23 that frame); it lost the lever on development
seed 3 (p90 2.2 -> 24 %), and trying both starts moved seeds 0 and 3 both ways within the noise: not kept, the one
frame stays.

`python -m benchmarks.boot_late_placement` (rerun; stop 104's table kept as `boot_late_placement_stop104`; two new
columns: the largest alpha_z error in the first 0.5 s after the placement, and the tracker's time on the frame it was
placed in): placed at 6 s from views of the lever at rest, alpha_z p90 20.0 -> **0.48** degrees (median 0.27 -> 0.35,
its largest error in the first 0.5 s 0.53); from views at 1.5 s (the lever at 1.6 degrees) 15.8 -> 0.64; from views at
2.0 / 2.5 / 3.5 / 5.0 s, 5.7 / 5.0 / 2.4 / 4.7 -> 0.67 / 0.69 / 0.43 / 2.64. The registrations from views of the lever
bent found the bend's direction nearer the truth where the lever was far bent (the turn 22.4 / 23.7 -> 18.4 / 21.5
degrees against the true 20, the axis origin 5.9 / 6.9 -> **2.7 / 5.0 mm**, the lever at the views 37.3 -> 38.5 for
39.8), farther where it was little bent (14.3 / 15.0 -> 12.0 / 12.6 at levers of 7.0 and 17.4; the tracker then starts
alpha_z there and measures it, 0.55-0.95 degrees off at the median as before). theta's median 0.20-0.48 degrees
against 0.21-0.44; its p90 moved both ways (1.5 s views placed at 6 s 0.62 -> 2.67, 2.5 s 1.88 -> 0.55). The price is
the search (the table's run alone on this host, its CPU probe at 17 ms; kept as `boot_late_placement_stop105`, stop
106 made it cheaper, below): the frame the boot is placed in (the tracker
built, its first depth read) 0.49-0.77 s where the lever was bent then (a scratch trace of stop 104's code: 0.31 s),
the registration from views at rest 2.9-3.0 s (2.5-2.6 s), from views of the lever bent 4.7-9.3 s (4.1-10.0 s). Live
(`live_slam`, rerun on this stop's code), the 8 s clip's boot was registered from views at rest and placed after 6.9
s, the lever already bent: theta 0.29 and alpha_z **0.22** degrees off from then on (stop 104's run: 0.17, and alpha_z
20, its start kept).

A boot placed at rest gives the same figures as before: development seeds 0-19 (`family_boot_dev_0_19_stop105`) and
the five boot rows of `thesis_truth` (`thesis_truth_boot`) gave every figure as stop 104's code did in a worktree run
beside each (scratch; the times apart). The search's result is taken only where the fitted shape holds its turn, which
the round bellows at rest does not, and the tracker's first read searches only where `depth_turn` is on. Those runs
also showed two published tables older than their labels said they were current: `thesis_truth_boot` (stop 72's
figures; now rerun, see `docs/tracking.md`) and the held-out `family_boot` (stop 73's code: held-out seeds 1000 and
1001 read 0.34 and 0.20 % now against its 0.29 and 0.20 %, alpha_z 0.37 and 0.04 degrees against 0.10 and 0.04).
`family_boot` is rerun on this stop's code (commit 57695f1, all 100 scenes; the run shared the host with a CI run, so
its times are not comparable: the tracker 106 ms a frame at the median against stop 73's 58): the lever **0.38 %** of
its range off at the median of the scene medians (stop 73: 0.38 %), p90 0.80 % (0.81), 94 % of the scenes within 1 %
(93), 97 % within 2 % (98; over it 1027 2.05 %, 1066 2.61 % (2.72), 1083 2.37 % (3.90)); alpha_z 0.30 degree off at
the median, 1.13 at worst (0.29, 1.10); every registration within 0.49 mm. Every scene moved, twelve by more than 0.2
points, both ways (1084 0.47 -> 1.40 %, 1047 0.39 -> 0.84 %; 1083 3.90 -> 2.37 %, 1079 1.12 -> 0.70 %): the code of
stops 74-104, whose changes to these scenes were not traced one by one (this stop's change leaves a boot placed at
rest as it was, above).

**Stop 106: the turn search's price cut.** The search ranked each of its candidates (24 turns by 6 levers, at one or
two translations, then 7 finer turns) with a search tree of its own over the samples placed there. A rigid motion of
both the samples and the measured points changes no distance and no point-to-plane residual, so each state's turns are
now ranked from one tree over its samples, with the measured points turned back instead (`_Problem.turn_costs`; a unit
test checks each turn's cost against the old way's over the whole circle, to 1e-9). `python -m
benchmarks.boot_late_placement` (rerun, alone on this host, CPU probe 16 ms): every accuracy figure of every row the
same to the digit as `boot_late_placement_stop105`; the frame the boot is placed in (placed at 6 s) 0.49-0.77 s ->
**0.33-0.44 s** (stop 104, without the search: 0.31 s), the registration from views at rest 2.9-3.0 s -> **2.5-2.6 s**
(stop 104: 2.5-2.6), from views of the lever bent 4.7-9.3 s -> 4.1-8.2 s. (The table now holds stop 109's rerun, on a
2-core AMD EPYC host with AVX2, probe 19 ms, on later code; host and code moved it together, not separated: alpha_z
0.21-1.08 deg off at the median with the turn as alpha_z (0.13-1.42 in the run above), 0.50-22.9 with the turn in the
pose (0.35-21.0); the pose's origin 4.3 and 5.4 mm off from views taken at 2.5 s and 3.5 s (2.1 and 2.7 mm); the frame
the boot is placed in 0.39-0.64 s, the registration 3.4-3.8 s from views at rest and 5.4-10.4 s from views of the
lever bent.) Development seeds 0-19 (`python -m benchmarks.family_boot --seeds 0-19`, a scratch run on this code not
kept as a table) read every figure of `family_boot_dev_0_19_stop105` to the digit, the times apart. Also: a scene may
no longer fix alpha_z and ask for `depth_turn` (the schema refuses the pair with its reason), and a tracker built with
both reports the fixed value (until now the depth's turn was added to it: a given alpha_z moved).

**Stop 126: the reference view no longer keeps a registration's state that the frame's depth fits worse than the
rest shape.** Stop 125's held-out stereo rerun moved cantilever 1001 from 0.87 to 8.83 %, which it left untraced.
Traced now in scratch runs of that seed (not kept as tables): putting the true pose in for the registration's mended
both rules, and swapping the two rules' registered poses left each pose fine with the other rule's SLAM; the fault
was at the reference view. The registration, fitted on three fused stereo depth views (the points 4.9 mm about the
surface), read a load on the unloaded beam; the reference frame's own fit said "at rest", and the registration's
state raised that frame's cost over the rest shape by 0.4 % (the tracker's own reason on that frame), within
`min_gain` (1 %) of the frame's verdict, so stop 118's rule kept it and every later estimate was measured against a
bent rest shape (a near-constant offset of the load position). The mend (`DeformableTracker._registration_agrees`):
where the frame's verdict is the rest shape, the registration's state must lower the rest shape's cost at all (a
gain above zero) to be kept; a unit test holds both sides of the line. Judged on development seeds, each reference
decision logged in scratch runs: stereo 0-19 and loaded (`--preloaded`) 0-19, none of the 40 decisions changed (the
smallest kept gain was seed 4's, the case stop 118 was made for, just above zero); the stereo development run the
same to the bit as `family_dev_stereo_0_19_close_points`. The held-out stereo pair rerun (`family_stereo`; this seed
was looked at to find the fault, so the table is no longer one no choice saw): 1001 8.83 -> **0.33 %**, the other 29
rows the same in every accuracy field; **0.56 %** at the median of the scene medians (0.60), **p90 1.85 %** (2.49),
70 % within 1 % (67), **90 % within 2 %** (87): the three targets met again.

**Stop 126: the loaded held-out beams rerun** (`--preloaded --seeds 1000-1029`, this stop's code: ORB-SLAM2's
keyframe points and the reference view's mend, an AMD EPYC host) against the cap's last run on an Intel host (`python
-m benchmarks.rerun_diff family_preloaded_heldout --against 7503588`): **0.68 %** at the median of the scene medians
(0.73), **p90 3.56 %** (3.19), 60 % within 1 % (63), **83 % within 2 %** (83): the median target met, the p90 and
the share within 2 % missed, as before. 12 scenes better, 17 worse; the largest moves 1023 3.16 -> 3.92 %, 1010 +0.36
points, 1003 -0.23; the camera's error 1.65 mm at the median (1.68), lower on 21 of 30. Over 2 %: 1009 (6.09 %),
1023, 1019, 1004 and 1006, the same five cantilevers as before. Host, rule and mend changed together; on the loaded
development seeds the mend changed no reference decision, so the moves are most likely the first two's (the
held-out decisions were not logged).

**Stop 125: the held-out plates rerun with ORB-SLAM2's keyframe points.** `--object plate --seeds 1000-1019` on
stop 124's code (an AMD EPYC host; the first two scenes, then `--resume` for the other 18 after a pause for the
stereo development runs) against the cap's last run, on an Intel host (table c93e8f3): **1.15 %** at the
median of the scene medians (1.14), **p90 2.82 %** (2.58), 35 % within 1 % (40), **75 % within 2 %** (75): the same
two targets missed (the median and the share within 2 %), the p90 still under 3 %. Bolted at both ends 0.83 % and 91
% within 2 % (0.85, 91), shelves 1.92 % and 56 % (1.57, 56); the camera's error 1.37 mm at the median (1.45), lower on
14 of 20; 8 scenes better, 12 worse.

**Stop 125: the held-out stereo pair rerun with ORB-SLAM2's keyframe points, and the development stereo seeds
completed.** `--sensor stereo --seeds 1000-1029` on stop 124's code (AMD EPYC host) against the cap's last run
(Intel host, `python -m benchmarks.rerun_diff family_stereo --against 5ca0eff`): **0.60 %** at the median of the
scene medians (0.53), **p90 2.49 %** (1.87), 67 % within 1 % (73), **87 % within 2 %** (93): short of the 90 % target,
which the cap's table met. The camera's error 2.15 mm at the median (2.47), lower on 21 of 30. Two cantilevers moved
over 2 % and a third over 1 %: 1001 0.87 -> 8.83 %, 1023 1.87 -> 2.65 % (a load that moves the image 2.5 px), 1004
0.29 -> 1.30 %; the same three with the cap on this host (`family_stereo_cap_probe`) read 0.87, 1.89 and 0.28 %, so
the rule moved them, not the host; on 1004 the registration, which fuses the first views' depth at the SLAM's poses,
moved from 9.1 to 17.6 mm, on 1001 from 0.14 to 0.26 degree (not traced further). The development stereo seeds, the
evidence a default is chosen on, say the rule holds: seeds 10-19 run now with both rules, composed with stop 124's 0-9
(`family_dev_stereo_0_19_close_points` against `family_dev_stereo_0_19_nearest250`): 0.46 against 0.48 %, p90 0.87
against 0.84 %, 95 % within 1 % and within 2 % with both, 14 scenes better and 6 worse, the camera 2.23 against 2.35
mm. The default stays; the held-out stereo shortfall is reported as measured.

**Stop 125: the held-out beams rerun with ORB-SLAM2's keyframe points.** `./run bench family` on stop 124's code
(the rule the default, the tracker's mend; two scenes at a time on an AMD EPYC host; the table above) against the cap's
last run, on an Intel host (`python -m benchmarks.rerun_diff family --against b6e4b73`): **0.43 %** at the
median of the scene medians (0.42), **p90 1.39 %** (1.34), **83 % within 1 %, 99 % within 2 %** (81, 98); cantilevers
0.47 % and 98 % within 2 % (0.49, 96), beams on two supports 0.38 % and all within 2 % (0.38, 100); the camera's
error 1.72 mm at the median (1.98), lower on 67 of 100; registration 0.73 mm and 0.11 degree (the same). Every row
moved, by 0.03 points at the median; 22 by more than 0.1 points, 11 better and 11 worse: 1065 2.15 -> 0.77 % (the
cantilever whose load moves the image under 3 px), 1068 0.87 -> 0.45, 1086 1.33 -> 0.92, 1024 0.50 -> 0.24; 1081 2.90
-> 6.77 % (the cantilever registered late, once loaded: the one scene over 2 % now), 1078 0.89 -> 1.17, 1008 0.69 ->
0.88. The host changed with the rule, and stop 123 measured the RGB-D SLAM's choices parting on the hosts' last
digits, so the rows' moves are the two together; the development beams (stop 124, both rules on one host) said the
same: the loads level, the camera better.

**Stop 124: ORB-SLAM2's keyframe rule the default, after the tracker's mend.** Stop 123's rule failed one unit
test, the thesis's boot in a starved graph; traced (`docs/localization.md`, stop 124), a frame too weak to pin the
lever (16 measurements) turned alpha_z by 90 degrees and the next frames kept it. A constant now keeps its value in a
frame that cannot pin the tracked parameters (`DeformableTracker._conclude`): that test 3.22 -> 1.07 degrees. The
family benchmark takes `--slam FIELD=VALUE` now, and the rule was measured on the development beams beside the cap:
RGB-D seeds 0-19 (`family_dev_0_19_close_points` against `family_dev_0_19_nearest250`) 0.33 against 0.26 % at the
median of the scene medians (the medians have a gap there: their mean 0.415 against 0.409 %), p90 0.82 against 0.75
%, 90 % within 1 % and 100 % within 2 % with both, 9 scenes better and 11 worse; the camera's error lower on 14 (1.69
against 1.91 mm at the median); stereo seeds 0-9 (`family_dev_stereo_0_9_close_points` against
`family_dev_stereo_0_9_nearest250`, cut at 10 of 20 for time) 0.58 against 0.60 %, p90 1.66 both, 6 better and 4
worse. The loads about level (the same shares within 1 and 2 %), the camera better through RGB-D and level through
the stereo pair, and a failure of the cap's design gone: the rule is the default. The
held-out boots on it (`family_boot`, above): **0.32 %**, p90 **0.70 %**, 94 % within 1 %, 97 % within 2 %, every frame
of all 100 tracked; against stop 123's run of the rule (`family_boot_close_points`) two rows moved by the mend, 1036
0.46 -> 0.51 % (its alpha_z 0.52 -> 0.23 degree off) and 1084 0.37 -> 0.29 %. The beams', plates' and stereo tables
above were made with the cap and stand flagged until rerun (the beams' in stop 125, above).

**Stop 123: the held-out boots rerun on an AMD host, and a keyframe rule that mended 1083, left a knob.**
`family_boot` rerun on stop 122's code (its table above): 0.35 % at the median of the scene medians, p90 0.78 %, 93 %
within 1 %, 97 % within 2 % (the Intel run of the same code path: 0.38 %, 0.88 %, 93 %, 98 %). Row by row (`python -m
benchmarks.rerun_diff family_boot --against 02d378c`): every registration the same to 1e-7 mm, every other figure
moved (the lever by 0.03 points at the median; 1021 lost the camera for 20 % of its frames on the Intel host and for
none here, 1031 0.97 -> 1.60 %): the RGB-D SLAM's choices part on the hosts' last digits and the estimates follow
(scaling the depth images by factors from 1 - 1e-7 to 1 + 3e-7 moved 1024's camera error between 2.0 and 17.5 mm;
scratch). 1083 lost the camera for 46 % of its frames on both hosts. Traced (`docs/localization.md`, stop 123): an
RGB-D keyframe makes points from its 250 nearest features, which at 0.45 m were all on the bending boot and were
culled, and the static map starved. ORB-SLAM2's rule (every feature nearer than 3.1 m) mends it: `--slam
keyframe_depth_points=0` (`family_boot_close_points`, run once after the development tables
`family_boot_dev_close_points` and `family_boot_dev_nearest250`, where the camera's error fell on 15 of 20 boots and
the lever's median stayed level, 0.31 % against 0.31 %, its p90 0.44 against 0.38 %): **0.33 %**, p90 **0.70 %**, 94 %
within 1 %, 97 % within 2 %; the lever better on 64 of 100 scenes, the camera's error on 74 (1.29 mm against 1.62 at
the median); every scene tracks every frame (1083 0.36 % against 2.29 %; 1077, 73 % of its frames tracked before, 100
%). It stays a knob: with it the thesis's boot in a starved graph (every 10th frame, a unit test) read its lever 3.2
degrees off against 1.0.

**Stop 107: the held-out beams rerun in one piece on this code.** The table `family` above was composed from two runs
of stops 78-80 (`family_heldout_1000_1049_default`, `family_heldout_1050_1099_default`), older than stops 81-106's
changes to the SLAM and the tracker. `./run bench family` (all 100 held-out seeds, two at a time, CPU probe 18 ms)
reads **0.42 %** at the median of the scene medians (0.42), **p90 1.34 %** (1.33), **81 % within 1 %, 98 % within 2
%** (81, 98); cantilevers 0.49 % and 96 % within 2 % (0.50, 96), beams on two supports 0.38 % and all within 2 %
(0.37, 100); registration 0.73 mm and 0.11 degree at the median (0.73, 0.10). Six scenes read the same to the digit,
the median absolute change is 0.008 points; by more than 0.1 points: 1006 0.42 -> 0.63 %, 1011 1.40 -> 1.57, 1025 1.39
-> 1.67 worse, 1008 0.88 -> 0.69, 1033 0.70 -> 0.48, 1041 0.62 -> 0.51, 1078 1.02 -> 0.89 better. The two scenes over
2 % are those named before: 1065 (2.15 %, flagged 'no measurable deformation': a cantilever whose load moves the image
by under 3 px on a faint texture) and 1081, now 7.52 % in the table itself (its composed row, 39 %, predated stop 90's
placement along the axis by the guess, which `family_1081_slide_guess` measured alone at 7.5 %). The tracker's time in
this run, 148 ms a frame at the median over scenes, is two scenes at a time on the 2 cores with nothing else running
(the composed table's 531 ms: runs on a host whose CPU probe read 36 ms; neither is a speed figure).

Plates with the state read from depth (`family_plate_dev_depth_fit`: development plates 0-9 on map points with
`depth_fit`, against the dense measurement's `family_plate_dev`): 2.06 % at the median of the scene medians against
1.10 %, p90 6.6 % against 2.8 %, none within 1 % (40 %), the tracker 80-230 ms a frame (dense 380-1000). One depth
image on development plate 1 reads s_x well but s_y far off, and differently from frame to frame (a scratch check of
`fit_state`), and the tracker takes the images' word on whether the plate deforms at all: on the faint plates the map
points see no deformation and most frames are flagged. A knob measured, not a default; the plates keep the dense
measurement.

**Stop 74: a plate guessed too high is registered, and the plates rerun.** Development plates 10-29, never run before
(`family_plate_dev_10_29`, stop 73's code): **1.36 %** at the median of the scene medians, p90 14.4 %, 35 % within 1 %
and 70 % within 2 %; the plates bolted at both ends 1.07 % and all within 2 %, the shelves (cantilevers) 2.33 % and half
within 2 %. The held-out plates' two kinds of failure are now on development seeds too. Seed 13 was never placed: its
registration was refused, 2 % of the model's faces covered. The coarse ICP had put the plate one thickness too high (a
trace, not kept): the guess was so high that even the lowest start (5 cm lower) was more than half the thickness too
high. So the points of the top face found the model's underside nearer than its top face, and the fit settled with
them there. Now, where the coarse stage's best fit covers under half of the model's faces (`min_fitness`), its starts
are run again with each measured point paired only with the model faces turned to some camera at the guess (within
about 105 degrees of their normal: room for a guess turned by ten degrees). That fit is taken where it covers 5 % more
(`RegistrationConfig.coarse_gain`). Seed 13 is then placed 0.3 mm and 0.04 degree off and reads its load **3.67 %** off
(35.0 %; `family_plate_dev_13_facing`): no longer a failure of the placement, one of the shelves' s_y below. On the
other 29 development plates and the 20 held-out ones the first pass covers over half, so the second does not run and
every registration is the same to the bit (a scratch registration of each scene's three depth views, true camera
poses, with the pass off and on). A unit test builds a 36 mm plate on a block above a floor and checks both: 36 mm too
high and refused without the pass, within 2 mm with it.

Held-out plates 1000-1019 rerun on this code, once, after that choice (`family_plate_stop74`; the last run,
`family_plate_stop49`, was stop 49's code, before the SLAM and tracker changes of stops 50-73): **1.13 %** at the
median of the scene medians (1.18 %), p90 **4.29 %** (4.80 %), 35 % within 1 % (30 %), **65 %** within 2 % (60 %).
Bolted at both ends (11 scenes): 0.94 %, 91 % within 2 %. Shelves (9): 3.24 %, 33 % within 2 %. 1016, never placed
before (30.6 %), is placed 0.5 mm and 0.03 degree off and reads 1.45 %, every frame OK. The other rows moved by the
code of stops 50-73, not by the registration's new pass (it does not run on them): 1001 5.24 -> 4.57 %, 1002 1.14 ->
0.96 % (63 -> 100 % of its frames OK), 1009 4.76 -> 5.19 %, the rest within 0.2 points. Still short of the targets
(p90 < 3 %, 90 % within 2 %): the shelves' s_y, across the plate, on six of the nine (1000 3.35 %, 1001 4.57, 1008
2.79, 1009 5.19, 1011 3.24, 1013 4.26), and 1019 (2.53 %, bolted, its frames all flagged: the fit can slide 15 mm
along the plate). The tracker's times in this table are not comparable with stop 49's: a scratch registration study
and a development run shared the two cores for most of it.

Where the shelves' s_y goes wrong (development plate 1, 3.2 px of peak image motion, speckle contrast 0.10: s_y 8.65 %
off in `family_plate_dev`; scratch studies, not committed, so their figures are not quoted). The fit is not stuck:
started at the true load, it ends where it ends from its own start, and the true load costs a little more than the
estimate on every loaded frame checked. The cost itself is biased, and it is flat: it changes little over the whole
range of s_y. The shading term's light (`dense_shading_frames`: what the frames measured of g, fused) was far from the
renderer's light on those frames. With g held at the renderer's value, the cost's minimum over s_y moves toward the
true s_y on each of four frames checked, but stops short of it (the estimate's s_x and rigid parts held): the light's
error is part of the bias, not all of it. Two other suspects were measured on development plate 15 (s_y 3.53 % in
`family_plate_dev_10_29`): without the fusion of g (`dense_shading_frames=0`) and with the load's weight left out of
the render it read about the same; neither is the cause. The shelves' position across the plate
is read from the plate's twist, which under a small load moves the image by a fraction of a pixel; this stop found no
change that reads it better.

Development plates 0-9 rerun on this code too (`family_plate_dev_stop74`; stop 49's run is `family_plate_dev`): 1.12 %
at the median of the scene medians (1.10 %), p90 2.82 % (2.84 %), 30 % within 1 % (40 %), 80 % within 2 % (80 %); every
scene within 0.11 points of stop 49's (seed 7 1.53 -> 1.43 %, 5 0.96 -> 1.06 %, 1 8.65 -> 8.55 %). Seed 7's frames are
now all flagged (100 -> 0 % OK): its registration can slide 15 mm along the plate instead of 14, 5.1 % of its length,
just over the 5 % at which a fit is doubted (the slide is measured in 1 mm steps). The registration's new pass does
not run there; the SLAM's poses changed in stops 50-73.

**Stop 75: the shelves' s_y is barely in the images.** Scratch runs on development plate 1 (s_y 8.65 % off on the
independent truth, `family_plate_dev`; the runs were not kept, so their figures are not quoted) took the suspects away
one at a time: rendered with the tracked model's own displacement (no model error) it read as far off; with no image
noise or blur as well, much better; with the light's directional part off (no shading) as well, better again but still
off; with the true camera poses as well, no better. Development plate 15 rendered with the model's displacement read
about as on the truth. So it is neither the model nor the camera: the images hold little of s_y on a shelf. `python -m
benchmarks.plate_observability` (`plate_observability.md`, new; no tracking) says how little: how far 1 % of a
parameter's range moves the most-moving point of the top face in the image, at most, at the scene's load. For s_y it
is 0.0015-0.13 px on the shelves and 0.027-0.47 px on the plates bolted at both ends. On the development plates 0-29
every scene with s_y over 2 % off has at most 0.0109 px, every other at least 0.0132 px. On the held-out plates, every
s_y failure has at most 0.0142 px (1000 0.0039, 1001 0.0124, 1008 0.0127, 1009 0.0078, 1011 0.0063, 1013 0.0142), but
the development split (0.0120 px) is not sharp there: three failures lie just over it and two shelves under it read
within 2 % (1004 1.33 %, 1016 1.45 %). A 2 % reading of s_y on those shelves asks the images for a few hundredths of a
pixel, about what digital image correlation resolves on a good speckle, and these are faint ones. What it suggests,
not tried: flag s_y as barely observable where the estimate's own sensitivity is that small. Such a flag would leave
the beams alone: the held-out beams' s moves the image by 0.022-0.99 px per 1 % of its range (`beam_observability.md`,
`--object beam`), none under the plates' split. Also measured and left (scratch): reading s_y from the depth image
too, by fusing the depth follower's fit with the image fit's by their information, made plate 1's s_y worse and plate
15's better at the cost of its s_x; per frame the depth holds s_y less tightly than the images (a larger standard
deviation on every frame compared).

**Stop 76: a load the images hold too loosely is flagged.** The lead of stop 75, taken from the fit itself rather than
from the truth's sensitivity: the tracker reports a dense fit low-confidence where a tracked parameter's standard
deviation (the covariance it already publishes: the normal equations scaled by the residual) exceeds
`DenseSettings.max_std_frac` of its range, saying which parameter and how loosely ("s_y loosely held by the images
(std 1.3 % of its range, at most 1 %)"). It is applied after the shading is fused, so it changes no estimate, only the
state. To choose the level, the development beams 0-19 and 24 development plates (every shelf of 0-29 and the bolted
plates 0, 2, 3, 14, 18, 19) were rerun with each frame's standard deviations recorded (`family_dev_0_19_std`,
`family_plate_dev_std_stop76`; `python -m benchmarks.flag_calibration --std`, `flag_calibration_std.md`). 1 % flags
487 of the plates' 781 frames more than 2 % off (every such frame of the shelves 1, 13, 15, 21 and 28, 51 of 59 of
16's) and takes 105 of their 1081 OK frames within 2 %; it takes none of the beams' 1465 OK frames within 2 % (a
beam's OK frames hold s to 0.08 % of its range at the median, 0.86 % at the most). At 1.5 % most frames of 13, 15 and
16 would go unflagged. The held-out plates 1000-1019 were then run once with it (`family_plate_stop76`): the errors
are stop 74's within its run-to-run spread (median 1.11 % against 1.13 %, p90 4.29 %, 65 % within 2 %; shelves 3.24 %,
bolted plates 0.94 %; three scenes' medians moved by at most 0.07 point), and the states changed on the shelves only.
Frames called OK but more than 2 % off fell from 371 to 129 on the shelves (69 on the bolted plates, unchanged: none
of theirs is flagged); frames called OK and within 2 % fell from 312 to 131 on the shelves (false alarms), 762 on the
bolted plates unchanged. Per shelf, OK frames: 1000 93 -> 15 % (s_y 3.35 % off), 1009 76 -> 0 % (5.26 %), 1011 100 ->
1 % (3.24 %), 1013 100 -> 48 % (4.26 %), 1008 98 -> 60 % (2.79 %); 1001 (4.57 %) stays at 38 %, its fits holding s_y
to under 1 % while 4 % off, so half its failure is still silent. The false alarms are 1004 (1.33 %, 72 -> 19 %) and
1016 (1.45 %, 100 -> 13 %), the two shelves stop 75's sensitivity also put under its split. The plates' targets (p90 <
3 %, 90 % within 2 %) are still missed; what changed is that most of the shelves' misses are now said. The beams'
held-out tables predate the flag; on the development beams it changed no OK frame.

**Stop 77: the template's own noise, averaged over the views at rest (a knob).** The dense measurement compares every
frame with one reference image, so that image's noise is the same error in every comparison, which no number of frames
averages out. Scratch runs on development plates 1 and 15 (not kept), rendered without noise and then given noise of
the scene's level (another draw than the family's): with the first 20 frames (the reference view among them)
noiseless, s_y read better than with every frame noisy, on plate 1 most of the way to what every frame noiseless
gives, on plate 15 as well as that. `tracking.dense_template_frames` (`DenseSettings.template_frames`, new): each
frame the tracker judges at rest before any deformation (those that already measure the placement error) is aligned to
the template at the reference state (the zero-displacement fit, rigid correction, camera error and brightness, down to
full resolution) and its intensities, brought to the template's brightness, join each sample's running mean, the
static surroundings' too, up to so many views; a sample more than three robust standard deviations off is left out,
and a template taken in a deformed state is not refined. A unit test: 9 views cut the template's noise to under half
(1 / sqrt(9) where nothing else differs), 4 views less. With 20 (about the family's 1.5 s at rest), the 24 development
plates of stop 76 (`family_plate_dev_template_20` against `family_plate_dev_std_stop76`): median of the scene medians
1.42 -> 1.30 %, p90 7.20 -> 4.69 %, within 1 % 29 -> 33 %, within 2 % 67 -> 71 %; shelves 1 8.55 -> 4.56 %, 12 1.72 ->
1.06 %, 15 3.53 -> 2.39 %, 28 14.0 -> 11.0 %, 29 2.95 -> 1.92 %; worse 13 3.67 -> 4.74 %, 17 1.50 -> 1.90 %, 21 17.2
-> 20.0 %; the bolted plates within 0.2 points. Frames more than 2 % off 781 -> 690, and with the 1 % loose-hold flag
those called OK 245 of them (the flag catches 396). But on the development beams (`family_dev_0_19_template_20`, seeds
0-9 only: the run was stopped there for time) the cantilevers got worse: 4 0.55 -> 1.06 %, 5 0.65 -> 0.81 %, 8 1.96 ->
3.21 % (p90 of the ten 0.78 -> 1.28 %, within 2 % 100 -> 90 %), the two-support beams level or better (6 0.27 -> 0.21
%, 7 0.62 -> 0.54 %, 9 0.27 -> 0.16 %). Not traced: a cantilever's tip may already move under its own weight's change
of view, or the views at rest may carry the first sub-threshold load. So it stays a knob (default 0, the reference
view alone): it helps most plates and hurts beams. Not run on held-out seeds. Another noise draw read development
plate 1 far worse than the family's draw (8.55 %), so single scenes are weak evidence either way.

**Stop 78: the averaging closed at the first load, and made the default.** Stop 77's cantilevers traced (scratch runs
logging every frame of development beams 4 and 8): their first load stands near the clamp, too close to bend the beam
measurably, and the tracker rightly reported "no measurable deformation" for the frames that followed. Those frames
still counted as at rest before any deformation, so the first loaded views (the weight on the beam) were averaged into
the template: the template carried a bend, and every later comparison with it. What gives that load away without the
truth: the deformed fit's image motion (90th percentile of the motion its deformation makes), which at rest sits at
the least the model can make (a fixed weight bends the beam wherever it stands) and rose well above it under that
load; on development plates 13 and 21 it barely varied at rest and jumped at the load. The averaging now closes for
good at the first view whose fit moves the image more than `DenseSettings.template_motion_px` (0.05 px) beyond the
least motion of the views averaged so far. With the truth cut in by hand instead (scratch, beam 4: no view after the
load's first frame) beam 4 read what the rule gives (0.455 %, `family_dev_0_19_template_gate`). With the rule,
development beams 0-19 (`family_dev_0_19_template_gate` against `family_dev_0_19_std`, the same defaults otherwise):
median of the scene medians 0.271 -> 0.272 %, p90 1.07 -> 0.79 %, within 1 % 85 -> 90 %, within 2 % 100 %; cantilevers
4 0.55 -> 0.46 %, 5 0.65 -> 0.53 %, 8 1.96 -> 1.05 %, 16 1.03 -> 0.62 %, 19 1.41 -> 1.35 %; the largest loss 15 0.245
-> 0.277 %; frames more than 2 % off 100 -> 62, OK frames within 2 % 1465 -> 1533, OK frames more than 2 % off 15
-> 12. Plates rerun with the rule (time allowed seven): 0, 1, 3 and 4 as in stop 77 (no load hidden at the start), 2
0.51 -> 0.46 %, 17 1.90 % as in stop 77 (1.50 % with the reference view alone), 21 20.0 -> 22.5 % (17.2 % alone: a
failure with either template; its shelf's s_y is the one the images barely hold, stop 75). Stop 77's plates without
the rule (24: median 1.42 -> 1.30 %, p90 7.20 -> 4.69 %) and the beams with it both gained, so
`tracking.dense_template_frames: 20` is the default now, chosen on development seeds only. Held out, run once after
the choice: beams 1000-1009 on this code, one view against the averaged template (`family_heldout_1000_1009_stop78`
against `family_heldout_1000_1009_template`): median of the scene medians 0.57 -> 0.42 %, p90 1.12 -> 0.96 %, within 2
% 90 -> 100 %; 1003 (the one scene over 2 %) 2.25 -> 1.68 %, 1009 1.00 -> 0.38 %, 1006 0.93 -> 0.42 %; worse 1000 0.36
-> 0.42 % and 1004 0.39 -> 0.43 %; frames more than 2 % off 91 -> 63, OK frames within 2 % 594 -> 660, OK frames more
than 2 % off 10 -> 9. Plates 1000-1018 held out (`family_plate_stop78` against `family_plate_stop76`, the code of stop
76 with the one-view template; run once, 1019 stopped for time): median of the scene medians 1.11 -> 1.09 %, p90 4.32
-> 3.07 %, within 1 % 37 -> 42 %, within 2 % 68 -> 79 %; shelves 3.24 -> 1.60 % at the median (1011 3.24 -> 1.18 %,
1013 4.26 -> 2.25 %, 1008 2.80 -> 1.60 %, 1001 4.57 -> 3.18 %, 1016 1.45 -> 1.10 %, 1009 5.26 -> 4.57 %), bolted
plates 0.89 -> 0.79 %; no scene worse by more than 0.03 point at the median. Frames more than 2 % off 541 -> 427
(shelves 472 -> 386, bolted 69 -> 41); OK frames within 2 % 893 -> 1048; but OK frames more than 2 % off 198 -> 203
(shelves 129 -> 162: with a cleaner template the fits hold s_y more tightly, so the 1 % loose-hold flag lets more of
the still-wrong frames through, 1009 0 -> 47 % OK at 4.6 % off; bolted 69 -> 41). The plates' targets (p90 < 3 %, 90 %
within 2 %) are still missed, narrowly on p90. Still open: why averaging costs plate 17 (no hidden load there; the
views at rest move the camera by several centimetres, and a template averaged over them may blur where the alignment
is least sure), and the shelves' s_y.

**Stop 79: the development plates on the defaults, and the loose-hold flag recounted.** The 17 development plates that
stop 78 had no time for, run on its defaults, complete the set (`family_plate_dev_default`, 24 scenes): median of the
scene medians 1.28 %, p90 4.69 %, within 1 % 33 %, within 2 % 71 % (stop 76's one-view template,
`family_plate_dev_std_ stop76`: 1.42 %, 7.20 %, 29 %, 67 %); shelves 1.39 % (18), bolted plates 1.12 % (6). Worse than
stop 76 by more than 0.1 point: 13 3.67 -> 4.74 %, 17 1.50 -> 1.90 %, 21 17.2 -> 22.5 %; the failures (over 2 %) are
shelves 1, 13, 15, 16, 21 and 28 and one bolted plate, 3 (2.06 %, near its model's bias, below). Held-out plates
showed more of the shelves' wrong frames called OK with the cleaner template (stop 78), so the 1 % loose-hold flag was
recounted on these runs and development beams 0-19 (`flag_calibration_std_stop79`: `python -m
benchmarks.flag_calibration --std --runs family_dev_0_19_template_gate,family_plate_dev_default --suffix _stop79`; the
runs have the flag on and it changes a frame's state only, so a lower level's effect is exact). Of the OK frames more
than 2 % off (beams 12, shelves 167, bolted plates 79) and within 2 % (1533, 631, 447), 0.7 % would flag 0 and 7 on
the beams, 71 and 43 on the shelves, 5 and 20 on the bolted plates; 0.5 % 0 and 12, 104 and 167, 19 and 74. The wrong
frames are held as tightly as the right ones: 0.7 % catches 76 at the cost of 70, too thin a margin for a default, and
the flag stays at 1 %. What those frames are: on bolted plates 3 and 18 (48 and 12 of them) they are 2-3 % off where
the plate model's own bias, its best fit to the truth, reaches 3.0 and 2.1 % (the `model bias` columns of
`family_plate_dev_default`): the tracker sits at its model's error, and the lever there is a finer plate model, not a
flag; plate 14's 18 are not explained so (its model's bias at most 1.2 %). On the shelves (16: 40, 13: 28, 29: 25, 17:
17) it is s_y again. **Held-out beams 1010-1049 rerun on the current defaults** (run once, nothing chosen on them),
with stop 78's 1000-1009 (`family_heldout_1000_1049_default`, 50 scenes): median of the scene medians 0.45 %, p90 1.34
%, within 1 % 84 %, within 2 % 100 %; cantilevers 0.50 % (26), two-support beams 0.41 % (24). The same seeds in the
main table of then (stop 59's code, `family_stop59` with `family_room`): 0.52 %, 1.50 %, 82 %, 98 %. Worse by more
than 0.1 point: only 1014, 0.88 -> 1.12 % (no frame of it OK in either). Seeds 1050-1099 of `family` were not rerun
for time.

**Stop 80: the held-out beams complete on the current defaults.** Seeds 1050-1099 ran once on the current code
(`family_heldout_1050_1099_default`; two scenes at a time on the 2 cores, marker work beside them part of the time, so
its times are not quiet-host figures; nothing was chosen on them): median of the scene medians 0.36 %, p90 1.33 %,
within 1 % 78 %, within 2 % 96 %. The same seeds on stop 59's code: 0.42 %, 1.38 %, 78 %, 94 %. Worse by more than 0.1
point: 1064 (0.56 -> 0.70 %) and 1068 (0.56 -> 0.88 %); better by more than 0.1: 1056, 1059, 1063, 1065, 1071, 1085,
1086. With stops 78-79's 1000-1049 they make the main table `family` (100 scenes, `--compose
family_heldout_1000_1049_default,family_heldout_1050_1099_default`): **0.42 %** at the median of the scene medians,
**p90 1.33 %**, **81 % within 1 %, 98 % within 2 %** (cantilevers 0.50 %, 96 % within 2 %; two-support beams 0.37 %,
all within 2 %), against stop 59's main table on the same seeds: 0.50 %, 1.50 %, 80 %, 96 %. At or over 2 %: 1065
(2.18 %: a cantilever's load moves the image by under 3 px on a faint texture; 64 % of its frames are not OK, most of
them "no measurable deformation") and 1081 (39 %: never placed, its registration refused on every try, as since stop
29). The tracker's time in this table (531 ms per frame at the median of the rows) is the time of two scenes sharing
the host with other work, not a speed figure.

**Stop 81: the held-out plates complete.** Seed 1019, which stop 78's run had not reached, ran once on the current
code (`family_plate_1019`; the plates' tracking code has not changed since stop 78, the markers' corners of stops
79-80 are not used here): a plate bolted at both ends, texture contrast 0.04, a load that moves the image by 2.9 px at
most; median error 2.56 % (s_x 1.03 %, s_y 1.91 %), no frame OK; the most common reason: the fit can slide 15 mm along
the plate, whose ends are barely seen. With stop 78's 1000-1018 (`family_plate_heldout`, 20 scenes): median
of the scene medians 1.10 %, p90 3.06 %, within 1 % 40 %, within 2 % 75 %; the 11 bolted plates 0.84 %, 10 of 11
within 2 %; the 9 shelves 1.60 %, 5 of 9 within 2 %. The plates' targets (p90 < 3 %, 90 % within 2 %) are missed.

**Stop 102: the held-out plates rerun on the current code** (`family_plate`, once; stop 49's run that bore the name is
`family_plate_stop49`), to check the table above against 24 stops of SLAM, tracker and camera changes since stop 78
(none of them aimed at the plates, no default changed for them): median of the scene medians 1.14 % (1.10 %), p90
2.58 % (3.06 %), within 1 % 40 % (40 %), within 2 % 75 % (75 %); the 11 bolted plates 0.85 %, 10 of 11 within 2 %;
the 9 shelves 1.57 %, 5 of 9 within 2 %. Scene by scene within 0.13 points of stop 78's but 1001 (3.18 -> 2.51 %,
a shelf, half its frames "no measurable deformation"), the same frames OK to within 2 points: the plates' figures
stand on this code. Still missed: 90 % within 2 % (the shelves' s_y across the plate,
1000 3.17 %, 1001 2.51, 1009 4.57, 1013 2.28; and 1019, 2.44 %, whose fit slides along the plate). The tracker's time
(454 ms a frame at the median of the rows against 1797 in stop 78's run) is two scenes at a time on 2 cores here,
other work beside stop 78's; not a speed figure."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default=f"{HELD_OUT_SEEDS.start}-{HELD_OUT_SEEDS.stop - 1}")
    ap.add_argument("--preloaded", action="store_true",
                    help="the load on from the first frame (no unloaded mapping): results/family_preloaded.*")
    ap.add_argument("--report", action="store_true", help="rewrite table and plot from the results JSON")
    ap.add_argument("--registration", action="store_true",
                    help="the registration step alone on each scene's first frames: results/family_registration.*")
    ap.add_argument("--measurements", choices=("map_points", "dense"),
                    help="override the scenes' tracking.measurements (results name gets the suffix)")
    ap.add_argument("--tracking", action="append", default=[], metavar="KEY=VALUE",
                    help="override a key of the scenes' tracking block (YAML value; results name gets the suffix)")
    ap.add_argument("--slam", action="append", default=[], metavar="KEY=VALUE",
                    help="a knob: a field of the SLAM's SlamConfig (YAML value; results name gets the suffix)")
    ap.add_argument("--sensor", choices=("rgbd", "stereo"), default="rgbd",
                    help="the camera the family is seen through (stereo: results name gets the suffix _stereo)")
    ap.add_argument("--object", choices=("beam", "plate"), default="beam",
                    help="the family's beams, or its plates (a load anywhere on the top face: results "
                         "family_plate*)")
    ap.add_argument("--out", help="results name (default: from the seeds and options, e.g. family_dev_stereo)")
    ap.add_argument("--jobs", type=int, default=1, help="scenes run in parallel processes (one core each)")
    ap.add_argument("--compose", metavar="NAME,NAME,...",
                    help="write --out from the rows of these results (a later one's row replaces an earlier one's of "
                         "the same seed; nothing is run): a table made of several runs of the same defaults")
    ap.add_argument("--resume", action="store_true",
                    help="keep the rows of a results JSON with the same label (a run that was cut off on the same "
                         "code) and run only the seeds it lacks")
    a = ap.parse_args()
    seeds = parse_seeds(a.seeds)
    if a.registration and a.preloaded:
        if a.sensor != "rgbd" or a.object != "beam" or a.jobs != 1 or a.resume or a.measurements or a.tracking:
            raise SystemExit("--registration --preloaded: RGB-D beams, one process, no tracking options")
        held = all(s >= HELD_OUT_SEEDS.start for s in seeds)
        if not held and any(s >= HELD_OUT_SEEDS.start for s in seeds):
            raise SystemExit("--registration --preloaded: development or held-out seeds, not both in one table")
        name = a.out or "family_registration_preloaded" + ("_heldout" if held else "")
        if a.report:  # the table and notes again from the results JSON (the run's machine kept)
            doc = json.loads((RESULTS / f"{name}.json").read_text())
            write_registration_loaded(
                [{**r, "state_err_pct": float("nan") if r["state_err_pct"] is None else r["state_err_pct"]}
                 for r in doc["rows"]], doc["summary"]["label"], name, saved_machine(name))
            return
        reg_rows = []
        for seed in seeds:
            reg_rows.append(run_registration(seed, preloaded=True))
            print(reg_rows[-1], flush=True)
            write_registration_loaded(reg_rows, ("held-out seeds " if held else "development seeds ") + a.seeds, name)
        return
    if a.registration:
        reg_rows = []
        for seed in seeds:
            reg_rows.append(run_registration(seed, sensor=a.sensor))
            print(reg_rows[-1], flush=True)
            write_registration(reg_rows, f"seeds {a.seeds}" + (", stereo pair" if a.sensor == "stereo" else ""),
                               "_stereo" if a.sensor == "stereo" else "")
        return
    held_out = all(s >= HELD_OUT_SEEDS.start for s in seeds)
    stem = "family_plate" if a.object == "plate" else "family"
    name = (stem + "_preloaded" + ("_heldout" if held_out else "")) if a.preloaded else \
        (stem if held_out else stem + "_dev")
    if a.sensor == "stereo":
        name += "_stereo"
    if a.measurements:
        name += f"_{a.measurements}"
    pairs = [t.partition("=")[::2] for t in a.tracking]
    knobs = {k: yaml.safe_load(v) for k, v in pairs}
    name += "".join(f"_{k}_{v.lower()}" for k, v in pairs)
    slam_pairs = [t.partition("=")[::2] for t in a.slam]
    slam = {k: yaml.safe_load(v) for k, v in slam_pairs}
    name += "".join(f"_{k}_{v.lower()}" for k, v in slam_pairs)
    name = a.out or name
    if a.compose:
        if not a.out:
            raise SystemExit("--compose needs --out")
        by_seed: dict[int, dict] = {}
        machines = []
        for part in a.compose.split(","):
            doc = json.loads((RESULTS / f"{part}.json").read_text())
            curves = doc.get("curves", {})
            machines.append(doc.get("machine"))
            for r in doc["rows"]:
                by_seed[r["seed"]] = {**r, "curve": curves.get(str(r["seed"]), {})}
        rows = [by_seed[k] for k in sorted(by_seed) if k in seeds]
        label = (("held-out seeds " if all(k >= HELD_OUT_SEEDS.start for k in seeds) else "seeds ") + a.seeds
                 + ": the rows of " + ", ".join(f"`{p}`" for p in a.compose.split(","))
                 + " (a later one's row replaces an earlier one's)")
        write(rows, label, name, measured_on=machines[-1])
        return
    if a.report:
        doc = json.loads((RESULTS / f"{name}.json").read_text())
        curves = doc.get("curves", {})
        rows = [{**r, "curve": curves.get(str(r["seed"]), {})} for r in doc["rows"]]
        write(rows, doc.get("label", ""), name, measured_on=doc.get("machine"))
        return
    label = ("held-out seeds" if held_out else "development seeds") + f" {a.seeds}"
    label += ", plates" if a.object == "plate" else ""
    label += ", load on from the first frame" if a.preloaded else ""
    label += ", stereo pair (SGBM depth)" if a.sensor == "stereo" else ""
    label += f", measurements {a.measurements}" if a.measurements else ""
    label += "".join(f", tracking.{k}: {v}" for k, v in knobs.items())
    label += "".join(f", SlamConfig.{k}: {v}" for k, v in slam.items())
    rows: list[dict] = []
    if a.resume and (RESULTS / f"{name}.json").exists():
        doc = json.loads((RESULTS / f"{name}.json").read_text())
        if doc.get("label") != label:
            raise SystemExit(f"--resume: {name}.json holds '{doc.get('label')}', not '{label}'")
        curves = doc.get("curves", {})
        rows = [{**r, "curve": curves.get(str(r["seed"]), {})} for r in doc["rows"] if r["seed"] in seeds]
        done = {r["seed"] for r in rows}
        seeds = [s for s in seeds if s not in done]
        print(f"--resume: {len(done)} seeds kept, {len(seeds)} to run", flush=True)
    job = functools.partial(run_scene, preloaded=a.preloaded, measurements=a.measurements, tracking=knobs,
                            sensor=a.sensor, object=a.object, slam=slam)
    for row in scene_map(job, seeds, a.jobs):
        rows.append(row)
        print({k: v for k, v in row.items() if k != "curve"}, flush=True)
        write(sorted(rows, key=lambda r: r["seed"]), label, name)


def scene_map(fn: Callable[[int], Any], seeds: list[int], jobs: int) -> Iterator[Any]:
    """``fn`` of each seed, in seed order, ``jobs`` scenes at a time in spawned processes (one core each: one OpenCV
    and one BLAS thread, :func:`_one_thread`), each result as soon as it and those before it are done. Each scene
    starts OpenCV's own random generator (PnP RANSAC draws from it) at its seed (:func:`_seeded`): a worker takes
    whichever seed is next when it is free, so without that a scene's draws would depend on which scenes the same
    worker ran before it, and on the timing."""
    if jobs > 1:  # the spawned workers inherit it before numpy loads its BLAS
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = "1"
    else:  # this process's BLAS is loaded already: held to one thread too, so that rows' times compare
        _one_thread()
    with multiprocessing.get_context("spawn").Pool(jobs, initializer=_one_thread) if jobs > 1 else \
            contextlib.nullcontext() as pool:
        job = functools.partial(_seeded, fn)
        yield from (pool.imap(job, seeds) if pool is not None else map(job, seeds))


def _seeded(fn: Callable[[int], Any], seed: int) -> Any:
    import cv2

    cv2.setRNGSeed(seed)
    return fn(seed)


def _one_thread() -> None:
    """A worker of ``--jobs`` (or the one process of ``--jobs 1``): one OpenCV thread and one BLAS thread, so that N
    workers share N cores fairly and a row's times do not depend on the job count (a ``--jobs 1`` run with BLAS's
    default threads beside other work ran about five times slower)."""
    import cv2
    from threadpoolctl import threadpool_limits

    cv2.setNumThreads(1)
    threadpool_limits(1)


if __name__ == "__main__":
    main()
