"""The joint boot in the scene family (issue 16: "object ... the joint boot"):

    python -m benchmarks.family_boot                          # held-out seeds 1000-1099, 2 jobs (about 40 min)
    python -m benchmarks.family_boot --seeds 0-9 --jobs 1     # development seeds
    python -m benchmarks.family_boot --seeds 0-9 --localization freeze_map_on_deformation=true --out NAME  # a knob
    python -m benchmarks.family_boot --seeds 0-9 --registration [--anchor fine=upright]  # the registration alone

Each scene (:mod:`simreal_nodes.synth.boot_family`: the thesis's real boot turned an unknown ``alpha_z`` about its
axis, its lever held at 4-6 drawn angles, the camera's arc, the speckle's contrast, clutter, light, noise and blur
drawn; 640 x 480 RGB-D at 15 fps) is rendered from the independent full-order solve and run through the offline
pipeline with the settings of the boot's scene file (map points, registration from a guess by eye, alpha_z searched
over its range until first seen: ``tracking.constant_search``). Per scene: the lever angle's error over the frames
whose lever is more than about a degree from rest (as
``benchmarks/thesis_truth.py`` scores the boot), in degrees and in % of the model's 52 degree range, the turn
``alpha_z``'s error (the registration's turn about the axis and the tracker's constant together), the registration's
error (axis origin, axis tilt), the model's own bias and error, the camera's error and the step's time. The summary
is the beams' (median and p90 of the per-scene medians, shares within 1 % and 2 %).
"""

from __future__ import annotations

import argparse
import copy
import functools
import json
import time

import numpy as np

from benchmarks.common import RESULTS, most_common, save
from benchmarks.family import parse_seeds, scene_map, track
from benchmarks.thesis_truth import boot_model_error, boot_model_fit
from simreal_nodes import geometry as G
from simreal_nodes.synth.boot_family import THETA_RANGE_DEG

# the tables this script writes, under names composed from its options, that the docs quote as current
# (benchmarks.staleness checks them against the code; other names are labelled runs)
DEFAULT_TABLES = ("family_boot", "family_boot_registration")

FPS = 15.0
TRIES = 3  # the registration-alone run: frames for this many tries of the registration (a refused one starts over)
AT_REST_RAD = 0.02  # frames whose lever is within about a degree of rest are not scored (thesis_truth's rule)


def run_scene(seed: int, tracking: dict | None = None, localization: dict | None = None,
              anchor: dict | None = None, slam: dict | None = None, guess_turn_deg: float = 0.0) -> dict:
    """One boot scene through the offline pipeline; ``tracking``, ``localization``, ``anchor``: keys of the object's
    ``tracking`` block, of the scene's ``localization`` block or of the object's ``anchor`` changed; ``slam``: fields
    of the SLAM's :class:`~simreal_nodes.vision.slam.config.SlamConfig` (a knob's trade); ``guess_turn_deg``: the
    guess turned about its own axis by this much, a turn the user does not know and the depth does not show (the
    registration keeps the guess's turn about the boot's axis, and alpha_z is measured from it)."""
    from simreal_nodes.assimilation.offline import Pipeline
    from simreal_nodes.scene.schema import build_spec_models, validate_scene
    from simreal_nodes.states import EstimateState
    from simreal_nodes.synth.scenes import boot_truth
    from simreal_nodes.synth.sequence import sequence
    from simreal_nodes.vision.slam.config import SlamConfig

    t0 = time.perf_counter()
    seq = sequence.__wrapped__(f"family-boot-{seed}", 640, 480, fps=FPS)  # not cached: one scene in memory at a time
    t_render = time.perf_counter() - t0
    sc = seq["scene"]
    d = sc.state["draw"]
    doc = copy.deepcopy(sc.scene_yaml(sc))
    doc["objects"][0]["tracking"].update(tracking or {})
    doc["localization"].update(localization or {})
    doc["objects"][0]["anchor"].update(anchor or {})
    if guess_turn_deg:
        guess = G.pose7_to_matrix(doc["objects"][0]["anchor"]["guess"]) @ G.make_T(G.rot_axis("z", np.deg2rad(
            guess_turn_deg)))
        doc["objects"][0]["anchor"]["guess"] = G.matrix_to_pose7(guess).tolist()
    scene = build_spec_models(validate_scene(doc, sc.name, "."))
    pipe = Pipeline(scene, seq["cam"], slam_config=SlamConfig(**slam) if slam else None)
    run = track(pipe, seq, FPS, oid="boot")
    th_true, th_est, states = (np.array(run[k], dtype=float) for k in ("truth", "est", "states"))
    loaded = th_true > AT_REST_RAD
    err = np.rad2deg(np.abs(th_est[loaded] - th_true[loaded]))
    pct = 100 * err / THETA_RANGE_DEG
    ok = states[loaded] == EstimateState.OK
    tracker = pipe.trackers["boot"]
    a_true = np.deg2rad(d.alpha_z_deg)
    # the alpha_z the estimate reports: the images' value with the depth fit's turn about the axis (depth_turn)
    a_est = float(tracker.values[tracker.names.index("alpha_z")]) + tracker.depth_turn if "alpha_z" in tracker.names \
        else 0.0
    a_frozen = bool(tracker.frozen[tracker.names.index("alpha_z")]) if "alpha_z" in tracker.names else False
    T_true = seq["truth"][0].object_poses["boot"]  # the boot's axis frame, before its turn alpha_z
    reg = pipe.objects.registrations.get("boot")
    if reg is not None:
        D = G.inv(T_true) @ reg.T_map_obj
        reg_mm = float(1e3 * np.linalg.norm(D[:3, 3]))
        reg_tilt = float(np.rad2deg(np.arccos(np.clip(D[2, 2], -1.0, 1.0))))
        a_err = float(np.rad2deg(abs((G.turn_about_z(D) + a_est - a_true + np.pi) % (2 * np.pi) - np.pi)))
        # the images' own alpha_z (without the depth's turn): what depth_turn changes
        a_img_err = float(np.rad2deg(abs((G.turn_about_z(D) + a_est - tracker.depth_turn - a_true + np.pi)
                                         % (2 * np.pi) - np.pi)))
    else:
        reg_mm = reg_tilt = a_err = a_img_err = float("nan")
    # the model's own reading of the truth at each scored frame's angle: its bias there, and the tracker's error
    # against that reading (what the images and the fit add to the model's error)
    model = pipe.objects.models["boot"]
    th_tab, fit_tab, _, _ = boot_model_fit(model, boot_truth())
    reads = np.interp(th_true[loaded], np.r_[0.0, th_tab], np.r_[0.0, fit_tab])
    bias_pct = 100 * np.rad2deg(np.abs(reads - th_true[loaded])) / THETA_RANGE_DEG
    vs_model_pct = 100 * np.rad2deg(np.abs(th_est[loaded] - reads)) / THETA_RANGE_DEG
    not_ok = [r for r, st in zip(np.array(run["reasons"])[loaded], states[loaded]) if st != EstimateState.OK and r]
    cam_err = run["cam_err"]
    return {
        "seed": seed, **d.summary(), "loaded_frames": int(loaded.sum()),
        "median_err_pct": float(np.median(pct)) if len(pct) else float("nan"),
        "p90_err_pct": float(np.percentile(pct, 90)) if len(pct) else float("nan"),
        "mean_err_pct": float(np.mean(pct)) if len(pct) else float("nan"),
        "median_err_deg": float(np.median(err)) if len(err) else float("nan"),
        "ok_pct": float(100 * ok.mean()) if len(ok) else float("nan"),
        "ok_median_err_pct": float(np.median(pct[ok])) if ok.any() else float("nan"),
        "alpha_z_err_deg": a_err, "alpha_z_image_err_deg": a_img_err, "alpha_z_frozen": a_frozen,
        "registration_mm": reg_mm, "registration_tilt_deg": reg_tilt,
        "model_bias_pct": float(np.median(bias_pct)) if len(pct) else float("nan"),
        "vs_model_median_pct": float(np.median(vs_model_pct)) if len(pct) else float("nan"),
        **boot_model_error(model, boot_truth()),
        "camera_ate_mm": float(1e3 * np.sqrt(np.mean(np.square(cam_err)))) if cam_err else float("nan"),
        "camera_tracked_pct": float(100 * len(cam_err) / len(seq["rgb"])),
        "step_ms_p50": float(np.median(run["step_ms"])),
        "tracker_ms_p50": float(np.median(run["tracker_ms"])) if run["tracker_ms"] else float("nan"),
        "render_s": round(t_render, 1), "reason": most_common(not_ok) if not_ok else "",
        "refusal": next((r for r in reversed(run["reasons"]) if "refused" in r or "no camera pose" in r), ""),
        "curve": {"truth": th_true.tolist(), "est": th_est.tolist(), "state": states.astype(int).tolist()},
    }


def summary(rows: list[dict]) -> dict:
    med = np.array([r["median_err_pct"] for r in rows], dtype=float)
    med = np.where(np.isfinite(med), med, np.inf)  # a scene with no scored frame counts as failed

    def pct(q: float) -> float:  # the beams' (linear) percentile; one that reaches a failed scene is infinite
        v = float(np.percentile(np.minimum(med, 1e300), q))
        return v if v < 1e299 else float("inf")

    return {"scenes": len(rows), "median_of_medians_pct": pct(50), "p90_of_medians_pct": pct(90),
            "within_1pct": float(np.mean(med < 1.0) * 100), "within_2pct": float(np.mean(med < 2.0) * 100),
            "median_alpha_z_err_deg": float(np.nanmedian([r["alpha_z_err_deg"] for r in rows])),
            "median_alpha_z_image_err_deg": float(np.nanmedian([r.get("alpha_z_image_err_deg", np.nan)
                                                               for r in rows] + [np.nan])),
            "median_registration_mm": float(np.nanmedian([r["registration_mm"] for r in rows])),
            "median_registration_tilt_deg": float(np.nanmedian([r["registration_tilt_deg"] for r in rows])),
            "model_bias_median_pct": float(np.median([r["model_bias_pct"] for r in rows])),
            "vs_model_median_pct": float(np.median([r["vs_model_median_pct"] for r in rows]))}


COLS = [("seed", "seed", "{}"), ("alpha_z_deg", "alpha_z (deg)", "{:.0f}"), ("distance_m", "camera (m)", "{:.2f}"),
        ("elevation_deg", "elevation (deg)", "{:.0f}"), ("arc_deg", "arc (deg)", "{:.0f}"),
        ("contrast", "speckle contrast", "{:.2f}"), ("clutter", "clutter", "{}"),
        ("median_err_pct", "theta: median error (% of 52 deg)", "{:.2f}"), ("p90_err_pct", "p90 (%)", "{:.2f}"),
        ("mean_err_pct", "mean (%)", "{:.2f}"), ("median_err_deg", "median (deg)", "{:.2f}"),
        ("ok_pct", "OK frames (%)", "{:.0f}"), ("alpha_z_err_deg", "alpha_z error (deg)", "{:.1f}"),
        ("alpha_z_image_err_deg", "images' alpha_z error (deg)", "{:.1f}"),
        ("registration_mm", "registration: axis origin (mm)", "{:.1f}"),
        ("registration_tilt_deg", "axis tilt (deg)", "{:.2f}"),
        ("model_bias_pct", "model bias at the scene's angles (%)", "{:.2f}"),
        ("vs_model_median_pct", "error against the model's own reading (%)", "{:.2f}"),
        ("model_rel_l2_median_pct", "model error |u| (%)", "{:.1f}"),
        ("camera_ate_mm", "camera ATE (mm)", "{:.1f}"), ("camera_tracked_pct", "camera tracked (%)", "{:.0f}"),
        ("step_ms_p50", "step (ms)", "{:.0f}"), ("tracker_ms_p50", "tracker (ms)", "{:.0f}"),
        ("reason", "most common reason when not OK", "{}")]


def write(rows: list[dict], label: str, name: str) -> None:
    s = summary(rows)
    notes = (f"{label}: {s['scenes']} scenes of the real joint boot at 640x480, {FPS:.0f} fps, RGB-D SLAM + PGD "
             "tracker with the boot scene file's settings (map points, Huber 2 px, alpha_z a constant fixed over 40 "
             "informative frames, searched over 24 values until first seen) but for the knobs the label names, "
             "placed by registration from a guess by eye. "
             "Over scenes: median of the per-scene "
             f"median lever-angle error {s['median_of_medians_pct']:.2f} % of its 52 deg range, p90 "
             f"{s['p90_of_medians_pct']:.2f} %, {s['within_1pct']:.0f} % of scenes within 1 %, "
             f"{s['within_2pct']:.0f} % within 2 % (the beams' targets: < 1 %, < 3 %, >= 90 % within 2 %); alpha_z "
             "off by "
             f"{s['median_alpha_z_err_deg']:.1f} deg, the boot's axis by {s['median_registration_mm']:.1f} mm and "
             f"{s['median_registration_tilt_deg']:.2f} deg at the median. Errors over the frames whose lever is more "
             "than about 1 degree (0.02 rad) from rest. Model bias: how far the angle the reduced model itself reads "
             "for the truth's displacement of its surface nodes (its best fit: what a tracker that saw every surface "
             "node exactly would report) is from the true angle, at the median of the scene's scored frames "
             f"(median over scenes {s['model_bias_median_pct']:.2f} %); the error against the model's own reading is "
             "the tracker's estimate against that best fit (median over scenes "
             f"{s['vs_model_median_pct']:.2f} %): what the images and the fit add. Model error |u|: the model's "
             "relative displacement error over the lever's range (one boot, so the same in every row). alpha_z "
             "error: the registration's turn about "
             "the axis and the tracker's alpha_z together against the drawn turn; the images' alpha_z error: the "
             "same without the depth fit's turn (`depth_turn`; median over scenes "
             f"{s['median_alpha_z_image_err_deg']:.1f} deg). Camera ATE: RMS camera position "
             "error, no alignment (both maps start at the first camera frame).")

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
        med = np.sort([r["median_err_pct"] for r in rows])
        ax[0].plot(med, np.arange(1, len(med) + 1) / len(med) * 100, "o-")
        ax[0].axvline(1.0, color="g", ls=":")
        ax[0].axvline(2.0, color="r", ls=":")
        ax[0].set(xscale="log", xlabel="per-scene median lever-angle error (% of 52 deg)",
                  ylabel="scenes within (%)", title=label)
        for r in rows[:6]:
            ax[1].plot(np.rad2deg(r["curve"]["truth"]), "k-", lw=0.8)
            ax[1].plot(np.rad2deg(r["curve"]["est"]), lw=1.0, label=str(r["seed"]))
        ax[1].set(xlabel="frame", ylabel="theta (deg): truth (black), estimate", title="the first six scenes")
        ax[1].legend(fontsize=7)
        fig.tight_layout()
        return fig

    save(name, rows, COLS, "The joint boot in the scene family (independent physics, registration)", notes, plot,
         extra={"summary": s, "label": label})


def run_registration(seed: int, anchor: dict | None = None) -> dict:
    """The registration step alone on a boot scene's first frames, with the scene file's guess and ``anchor`` keys
    changed: the error of the boot's axis frame (its origin, in mm, split into the part along the first camera's
    line of sight and across it, horizontally, and the vertical; the axis's tilt). A refused fit starts collecting
    its views again, as in the graph: up to ``TRIES`` tries' frames run, and the row says how many were refused."""
    from simreal_nodes.assimilation.offline import Pipeline
    from simreal_nodes.assimilation.registration import RegistrationConfig
    from simreal_nodes.scene.schema import build_spec_models, validate_scene
    from simreal_nodes.synth.sequence import sequence

    cfg = RegistrationConfig()
    seq = sequence.__wrapped__(f"family-boot-{seed}", 640, 480, fps=FPS, frames=TRIES * (cfg.frames * cfg.every + 2))
    sc = seq["scene"]
    doc = copy.deepcopy(sc.scene_yaml(sc))
    doc["objects"][0]["anchor"].update(anchor or {})
    pipe = Pipeline(build_spec_models(validate_scene(doc, sc.name, ".")), seq["cam"])
    t0, frame, reason, refused = time.perf_counter(), -1, "", []
    for i in range(len(seq["rgb"])):
        _, out = pipe.step(np.ascontiguousarray(seq["rgb"][i][:, :, ::-1]), int(i * 1e9 / FPS), seq["depth"][i])
        reason = out["boot"].reason
        if reason.startswith("waiting for registration: "):  # a try that ended without a pose (refused or failed)
            refused.append(reason.removeprefix("waiting for registration: "))
        if "boot" in pipe.objects.registrations:
            frame = i
            break
    if refused:
        why = (f"placed on try {len(refused) + 1}" if frame >= 0 else "not placed") + f"; try 1 refused: {refused[0]}"
    else:
        why = "" if frame >= 0 else reason
    row = {"seed": seed, "distance_m": round(sc.state["draw"].distance, 2), "frame": frame, "refused": len(refused),
           "seconds": round(time.perf_counter() - t0, 1), "reason": why}
    reg = pipe.objects.registrations.get("boot")
    if reg is None:
        return row | {k: float("nan") for k in ("registration_mm", "along_mm", "across_mm", "vertical_mm",
                                               "registration_tilt_deg", "fitness")}
    T_true = seq["truth"][0].object_poses["boot"]  # the axis frame in the map (the first camera frame)
    d = reg.T_map_obj[:3, 3] - T_true[:3, 3]  # map frame
    up = T_true[:3, 2]
    sight = T_true[:3, 3] / np.linalg.norm(T_true[:3, 3])  # the first camera sits at the map's origin
    along = sight - up * (sight @ up)
    along /= np.linalg.norm(along)
    D = G.inv(T_true) @ reg.T_map_obj
    return row | {"registration_mm": float(1e3 * np.linalg.norm(d)), "along_mm": float(1e3 * d @ along),
                  "across_mm": float(1e3 * d @ np.cross(up, along)), "vertical_mm": float(1e3 * d @ up),
                  "registration_tilt_deg": float(np.rad2deg(np.arccos(np.clip(D[2, 2], -1.0, 1.0)))),
                  "fitness": float(reg.fitness)}


REG_COLS = [("seed", "seed", "{}"), ("distance_m", "camera (m)", "{:.2f}"),
            ("registration_mm", "axis origin error (mm)", "{:.2f}"), ("along_mm", "along the line of sight (mm)",
                                                                    "{:+.2f}"),
            ("across_mm", "across (mm)", "{:+.2f}"), ("vertical_mm", "vertical (mm)", "{:+.2f}"),
            ("registration_tilt_deg", "axis tilt (deg)", "{:.2f}"), ("fitness", "fitness", "{:.2f}"),
            ("frame", "placed at frame", "{}"), ("refused", "tries refused", "{}"), ("seconds", "time (s)", "{:.1f}"),
            ("reason", "why not placed, or refused first", "{}")]


def write_registration(rows: list[dict], label: str, name: str) -> None:
    mm = np.array([r["registration_mm"] for r in rows], dtype=float)
    tilt = np.array([r["registration_tilt_deg"] for r in rows], dtype=float)
    notes = (f"{label}: the registration step alone (`anchor: registration`) on each boot scene's first frames, "
             "RGB-D SLAM poses, the scene file's guess by eye. The error of the boot's axis frame: its origin (the "
             "base's centre) against the truth, split along the first camera's horizontal line of sight, across "
             "it and vertically; the axis's tilt. Over scenes: median "
             f"{np.nanmedian(mm):.2f} mm and {np.nanmedian(tilt):.2f} deg, worst {np.nanmax(mm):.2f} mm and "
             f"{np.nanmax(tilt):.2f} deg; {int(np.sum(np.isnan(mm)))} not placed; "
             f"{sum(1 for r in rows if r.get('refused', 0) and r['frame'] >= 0)} placed on a later try (a refused fit "
             f"collects its views again; up to {TRIES} tries' frames run).")

    def plot(plt):
        fig, ax = plt.subplots(figsize=(6, 3.8))
        ax.scatter([r["along_mm"] for r in rows], [r["across_mm"] for r in rows], c=tilt, cmap="viridis")
        ax.axhline(0, color="k", lw=0.5)
        ax.axvline(0, color="k", lw=0.5)
        ax.set(xlabel="along the line of sight (mm)", ylabel="across (mm)", title=label)
        fig.tight_layout()
        return fig

    save(name, rows, REG_COLS, "Registration of the joint boot in the scene family", notes, plot,
         extra={"label": label})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="1000-1099", help="e.g. 0-9 (development) or 1000-1099 (held out)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", help="the result's name (default family_boot, or family_boot_dev on seeds < 1000)")
    ap.add_argument("--tracking", nargs="*", default=[], metavar="KEY=VALUE",
                    help="a knob: a key of the object's tracking block (its value read as JSON, else as text)")
    ap.add_argument("--localization", nargs="*", default=[], metavar="KEY=VALUE",
                    help="a knob: a key of the scene's localization block (its value read as JSON, else as text)")
    ap.add_argument("--anchor", nargs="*", default=[], metavar="KEY=VALUE",
                    help="a knob: a key of the object's anchor block (e.g. fine=upright)")
    ap.add_argument("--slam", nargs="*", default=[], metavar="KEY=VALUE",
                    help="a knob: a field of the SLAM's SlamConfig (e.g. hold_rest_points=false)")
    ap.add_argument("--guess-turn", type=float, default=0.0, metavar="DEG",
                    help="turn the scene file's guess about the boot's axis by DEG (the turn the depth cannot show)")
    ap.add_argument("--registration", action="store_true",
                    help="the registration step alone (results family_boot_registration*)")
    a = ap.parse_args()
    seeds = parse_seeds(a.seeds)
    dev = max(seeds) < 1000
    tracking, localization, anchor, slam = _knobs(a.tracking), _knobs(a.localization), _knobs(a.anchor), _knobs(a.slam)
    label = (f"{'development' if dev else 'held-out'} seeds {a.seeds}"
             + "".join(f", tracking.{k}: {v}" for k, v in tracking.items())
             + "".join(f", localization.{k}: {v}" for k, v in localization.items())
             + "".join(f", anchor.{k}: {v}" for k, v in anchor.items())
             + "".join(f", SlamConfig.{k}: {v}" for k, v in slam.items())
             + (f", the guess turned {a.guess_turn:g} deg about the axis" if a.guess_turn else ""))
    if a.registration:
        rows = list(scene_map(functools.partial(run_registration, anchor=anchor), seeds, a.jobs))
        write_registration(rows, label, a.out or "family_boot_registration" + ("_dev" if dev else ""))
        return
    name = a.out or ("family_boot_dev" if dev else "family_boot")
    rows = []
    for row in scene_map(functools.partial(run_scene, tracking=tracking, localization=localization, anchor=anchor,
                                           slam=slam, guess_turn_deg=a.guess_turn), seeds, a.jobs):
        rows.append(row)
        print({k: v for k, v in row.items() if k != "curve"}, flush=True)
        (RESULTS / f"{name}.partial.json").write_text(json.dumps(rows, default=float))
    write(rows, label, name)
    (RESULTS / f"{name}.partial.json").unlink(missing_ok=True)


def _knobs(pairs: list[str]) -> dict:
    """KEY=VALUE pairs, each value read as JSON where it is (numbers, true/false), else as text."""
    out: dict = {}
    for kv in pairs:
        k, _, v = kv.partition("=")
        try:
            out[k] = json.loads(v)
        except json.JSONDecodeError:
            out[k] = v
    return out


if __name__ == "__main__":
    main()
