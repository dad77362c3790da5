"""The SLAM alone on the scene family (issue 17: monocular and RGB-D on the project's held-out scenes):

    python -m benchmarks.family_slam                       # held-out seeds 1000-1099, mono and RGB-D, 2 jobs
    python -m benchmarks.family_slam --seeds 0-9 --jobs 1  # development seeds

Each scene of :mod:`simreal_nodes.synth.family` (640 x 480 RGB-D at 15 fps, about 6 s: a camera arc of 20-70
degrees around a loaded beam on a table before walls and clutter of drawn contrast; its speckle from faint to
painted, pixel noise sigma 0.5-3, motion blur) is rendered once and tracked by the SLAM in each mode with
ORB-SLAM2's budget (1000 features), synchronously (keyframes and local BAs on the frame that makes them), every
frame. The SLAM runs alone: no deformable tracker tells it which points lie on the beam, so the beam's bending (from
1.5 s on) is a small part of the scene it takes as static (in the tracking graph, `docs/family.md`, those points are
dropped as the tracker links them).

Per scene and mode: frames tracked (a pose in state ok or relocalized; the frames before a monocular map exists count
as not tracked, as ORB-SLAM2's own evaluations count them), the first lost frame, ATE RMSE after a similarity
(monocular) or rigid (RGB-D) alignment of the tracked frames, the same as % of the path length, RPE over 1 s, the
tracking time per frame (median, without keyframe insertion and local BA, as `localization.md`). The summary per mode:
the share of scenes with at least 95 % (monocular) or 99 % (RGB-D) of frames tracked and with ATE at most 0.3 % of
the path length (issue 17's targets), and the medians over scenes.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import time
from typing import Any

import numpy as np

from benchmarks.common import save
from benchmarks.family import scene_map  # scenes in parallel, one OpenCV and one BLAS thread per job

FPS = 15.0
TARGET_TRACKED = {"mono": 95.0, "rgbd": 99.0, "stereo": 99.0}
TARGET_ATE_PCT = 0.3


def slam_sequence(seed: int) -> tuple[dict, Any]:
    """One family scene rendered (640 x 480 RGB-D at 15 fps) as the SLAM benchmarks take it: gray frames, depth in
    metres, the true camera-to-world poses, the camera and the rate; and the scene's draw."""
    import cv2

    from benchmarks.family import scene_name
    from simreal_nodes.synth.sequence import sequence

    seq = sequence.__wrapped__(scene_name(seed), 640, 480, fps=FPS, stereo=False)
    data = {"gray": [cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in seq["rgb"]], "depth": seq["depth"],
            "T": np.asarray(seq["T"]), "cam": seq["cam"], "fps": FPS}
    return data, seq["scene"].state["draw"]


def run_scene(seed: int, modes: tuple[str, ...] = ("mono", "rgbd"), n_features: int = 1000,
              configs: dict[str, dict] | None = None) -> list[dict]:
    """One family scene rendered once, then the SLAM over it in each mode and configuration (``configs``: label ->
    ``SlamConfig`` fields; default the defaults, labelled "default"): one row per mode and configuration."""
    from benchmarks.real_slam import run

    t0 = time.perf_counter()
    data, d = slam_sequence(seed)
    render_s = time.perf_counter() - t0
    path = float(np.sum(np.linalg.norm(np.diff(data["T"][:, :3, 3], axis=0), axis=1)))
    rows = []
    for (label, overrides), mode in itertools.product((configs or {"default": {}}).items(), modes):
        r = run(data, mode, n_features=n_features, overrides=overrides)
        rows.append({"seed": seed, "mode": mode, "config": label, "features": n_features, "frames": r["frames"],
                     "tracked_pct": 100.0 * r["tracked"] / r["frames"], "first_tracked": r["first_tracked"],
                     "first_lost": r["first_lost"], "ate_mm": r.get("ate_mm", float("nan")),
                     "ate_pct": r.get("ate_pct", float("nan")), "rpe_1s_mm": r.get("rpe_1s_mm", float("nan")),
                     "scale": r.get("scale", float("nan")), "tracking_ms_p50": r["tracking_ms_p50"],
                     "keyframes": r["keyframes"], "path_m": path, "distance_m": round(d.distance, 2),
                     "arc_deg": round(d.arc_deg, 1), "contrast": round(d.speckle_contrast, 3),
                     "clutter": d.clutter, "clutter_contrast": round(d.clutter_contrast, 2),
                     "pixel_sigma": round(d.pixel_sigma, 2), "render_s": round(render_s, 1)})
    return rows


def parallax_onset(seed: int, min_deg: float = 1.0, step_px: int = 8) -> dict:
    """The geometry's earliest monocular start: the first frame whose parallax with frame 0 reaches ``min_deg``,
    from the truth (frame 0's depth on a ``step_px`` grid, back-projected through the true pose; each point's
    parallax the angle between its rays from the two true camera centres, over the points in view of both). Two
    statistics: the median over the points (this SLAM's rule, ``SlamConfig.min_parallax_deg``) and the 95th
    percentile (about ORB-SLAM2's, the 51st largest of some 1000 features). Renders frame 0 only."""
    from benchmarks.family import scene_name
    from simreal_nodes.synth.sequence import FrameStream

    fs = FrameStream(scene_name(seed), 640, 480, fps=FPS, frames=1)
    f0 = next(iter(fs))
    sc, cam = fs.scene, fs.cam
    T_mw = sc.T_map_world()
    n = round(sc.duration * sc.fps)
    T = np.array([T_mw @ sc.camera_pose(i / sc.fps) for i in range(n)])
    v, u = np.mgrid[step_px // 2:cam.height:step_px, step_px // 2:cam.width:step_px]
    z = f0["depth"][v, u].astype(np.float64)
    ok = np.isfinite(z) & (z > 0)
    uv = cam.undistort_points(np.c_[u[ok], v[ok]].astype(np.float64))
    X = cam.backproject(uv, z[ok]) @ T[0, :3, :3].T + T[0, :3, 3]
    r0 = X - T[0, :3, 3]
    r0 /= np.linalg.norm(r0, axis=1, keepdims=True)
    onset: dict[str, int | None] = {"median": None, "p95": None}
    for k in range(1, n):
        Pc = (X - T[k, :3, 3]) @ T[k, :3, :3]
        pix = cam.project(Pc)
        seen = (Pc[:, 2] > 0) & np.all(np.isfinite(pix), axis=1) & (pix[:, 0] >= 0) & (pix[:, 0] < cam.width) \
            & (pix[:, 1] >= 0) & (pix[:, 1] < cam.height)
        rk = X[seen] - T[k, :3, 3]
        rk /= np.linalg.norm(rk, axis=1, keepdims=True)
        par = np.rad2deg(np.arccos(np.clip(np.sum(r0[seen] * rk, axis=1), -1, 1)))
        for name, q in (("median", 50), ("p95", 95)):
            if onset[name] is None and len(par) and np.percentile(par, q) >= min_deg:
                onset[name] = k
        if onset["median"] is not None:
            break
    return {"seed": seed, "frames": n, "onset_median": onset["median"], "onset_p95": onset["p95"]}


def _key(r: dict) -> str:
    """A row's group: its mode, and its configuration where that is not the defaults."""
    c = r.get("config", "default")
    return r["mode"] if c == "default" else f"{r['mode']} ({c})"


def summary(rows: list[dict]) -> dict:
    """Per mode (and configuration): scenes, the shares meeting issue 17's targets, and the medians over scenes."""
    out = {}
    for key in sorted({_key(r) for r in rows}):
        rs = [r for r in rows if _key(r) == key]
        mode = rs[0]["mode"]
        tracked = np.array([r["tracked_pct"] for r in rs])
        ate_pct = np.array([r["ate_pct"] for r in rs], dtype=float)
        ok = (tracked >= TARGET_TRACKED[mode]) & (np.nan_to_num(ate_pct, nan=np.inf) <= TARGET_ATE_PCT)
        out[key] = {"mode": mode, "scenes": len(rs), "tracked_pct_median": float(np.median(tracked)),
                     "tracked_pct_mean": float(np.mean(tracked)),
                     "share_tracked_target": float(100 * np.mean(tracked >= TARGET_TRACKED[mode])),
                     "ate_mm_median": float(np.nanmedian([r["ate_mm"] for r in rs])),
                     "ate_pct_median": float(np.nanmedian(ate_pct)),
                     "ate_pct_p90": float(np.nanpercentile(ate_pct, 90)),
                     "share_ate_target": float(100 * np.mean(np.nan_to_num(ate_pct, nan=np.inf) <= TARGET_ATE_PCT)),
                     "share_both_targets": float(100 * np.mean(ok)),
                     "tracking_ms_p50_median": float(np.median([r["tracking_ms_p50"] for r in rs]))}
        on = [r for r in rs if r.get("onset") is not None and r.get("init_delay") is not None]
        if on:
            out[key].update(onset_scenes=len(on), onset_median=float(np.median([r["onset"] for r in on])),
                            init_delay_median=float(np.median([r["init_delay"] for r in on])),
                            init_delay_max=int(max(r["init_delay"] for r in on)),
                            tracked_after_onset_median=float(np.median([r["tracked_after_onset_pct"] for r in on])))
    return out


def write(rows: list[dict], label: str, name: str, runs: list[dict] | None = None) -> None:
    """The table of ``rows``. ``runs``: where the rows are rewritten from saved results (``--report``,
    ``--compose``), each source's ``{"name", "machine"}``: the report keeps the machine line of the run (of the
    newest, with every source's date and CPU probe in the notes), not the rewrite's."""
    onsets = _onsets()
    for r in rows:  # the monocular start against the earliest the truth allows (the median rule)
        o = onsets.get(r["seed"])
        if r["mode"] == "mono" and o is not None and o["onset_median"] is not None:
            r["onset"] = o["onset_median"]
            r["init_delay"] = (r["first_tracked"] - o["onset_median"]) if r["first_tracked"] is not None else None
            r["tracked_after_onset_pct"] = 100.0 * r["tracked_pct"] / o["best_tracked_pct_median"]
    s = summary(rows)
    cols = [("seed", "seed", "{}"), ("mode", "mode", "{}")]
    if any(r.get("config", "default") != "default" for r in rows):
        cols.append(("config", "SLAM configuration", "{}"))
    cols += [("tracked_pct", "tracked (%)", "{:.1f}"),
            ("first_tracked", "first tracked", "{}"), ("onset", "1 deg median parallax at", "{}"),
            ("tracked_after_onset_pct", "tracked from there (%)", "{:.1f}"), ("first_lost", "first lost", "{}"),
            ("ate_mm", "ATE (mm)", "{:.2f}"), ("ate_pct", "ATE % path", "{:.3f}"),
            ("rpe_1s_mm", "RPE 1 s (mm)", "{:.2f}"), ("scale", "alignment scale", "{:.3f}"),
            ("tracking_ms_p50", "tracking p50 (ms)", "{:.1f}"), ("keyframes", "keyframes", "{}"),
            ("path_m", "path (m)", "{:.2f}"), ("distance_m", "distance (m)", "{}"), ("arc_deg", "arc (deg)", "{}"),
            ("contrast", "beam texture contrast", "{}"), ("clutter", "clutter", "{}"),
            ("clutter_contrast", "clutter contrast", "{}"), ("pixel_sigma", "pixel noise", "{}")]
    lines = []
    for key, m in s.items():
        lines.append(
            f"{key}: {m['scenes']} scenes; frames tracked median {m['tracked_pct_median']:.1f} % (mean "
            f"{m['tracked_pct_mean']:.1f} %), {m['share_tracked_target']:.0f} % of scenes with at least "
            f"{TARGET_TRACKED[m['mode']]:.0f} % tracked; ATE median {m['ate_mm_median']:.2f} mm, "
            f"{m['ate_pct_median']:.3f} % of the path (p90 {m['ate_pct_p90']:.3f} %), {m['share_ate_target']:.0f} % "
            f"of scenes within {TARGET_ATE_PCT} %; both targets {m['share_both_targets']:.0f} %; tracking p50 "
            f"{m['tracking_ms_p50_median']:.1f} ms (median over scenes)."
            + (f" Start: the truth's median parallax reaches 1 deg at frame {m['onset_median']:.0f} (median over "
               f"{m['onset_scenes']} scenes, `{ONSET}.md`); the map starts a median {m['init_delay_median']:.0f} "
               f"frames after that (at most {m['init_delay_max']}), and {m['tracked_after_onset_median']:.1f} % of "
               "the frames from there on are tracked (median)." if "onset_median" in m else ""))
    notes = (f"{label}. " + " ".join(lines) + " The SLAM alone (no deformable tracker), 1000 ORB features, "
             "synchronous mapping, every frame; monocular ATE after a similarity alignment, RGB-D after a rigid one, "
             "over the tracked frames. `benchmarks/family_slam.py` (its docstring says what a scene is)."
             + (f" Monocular rows: '1 deg median parallax at' is the first frame at which the truth's median parallax "
                f"with frame 0 reaches 1 deg (`{ONSET}.md`); 'tracked from there' the frames tracked over the frames "
                "from that one on (over 100 % where the map started earlier: its own estimate of the parallax "
                "passed 1 deg first)." if any("onset" in r for r in rows) else ""))

    def plot(plt):
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
        for key in s:
            rs = [r for r in rows if _key(r) == key]
            axes[0].scatter([r["seed"] for r in rs], [r["ate_pct"] for r in rs], s=12, label=key)
            axes[1].scatter([r["seed"] for r in rs], [r["tracked_pct"] for r in rs], s=12, label=key)
        axes[0].axhline(TARGET_ATE_PCT, color="k", lw=0.8, ls="--")
        axes[0].set_yscale("log")
        axes[0].set_ylabel("ATE (% of path length)")
        axes[1].set_ylabel("frames tracked (%)")
        for ax in axes:
            ax.set_xlabel("seed")
            ax.grid(True, alpha=0.3)
            ax.legend()
        fig.tight_layout()
        return fig

    extra: dict = {"summary": s, "label": label}
    runs = runs or []
    known = [r for r in runs if r.get("machine")]
    if known:
        extra["machine"] = max(known, key=lambda r: r["machine"]["date"])["machine"]
    if len(runs) > 1 or (runs and not known):
        notes += " Composed from the saved runs " + ", ".join(
            f"`{r['name']}` ({r['machine'].get('cpu', '?')}, {r['machine']['date']}, CPU probe "
            f"{r['machine']['cpu_probe_ms']:.0f} ms)" if r.get("machine") else f"`{r['name']}` (no machine recorded)"
            for r in runs) + ("; the machine line below is the newest's." if known else
                              "; the machine line below is the rewrite's.")
    save(name, rows, cols, "The SLAM alone on the scene family: frames tracked, ATE, time", notes, plot,
         extra=extra)


ONSET = "family_slam_onset"


def _ranges(seeds: list[int]) -> str:
    """Seeds as ranges: 0-9, 1000-1099."""
    out: list[str] = []
    for k in sorted(seeds):
        if out and int(out[-1].split("-")[-1]) == k - 1:
            out[-1] = out[-1].split("-")[0] + f"-{k}"
        else:
            out.append(str(k))
    return ", ".join(out)


def write_onset(rows: list[dict]) -> None:
    """The onset table: per scene, the frames before a monocular start is possible, and the share left to track."""
    from benchmarks.family import HELD_OUT_SEEDS

    held = [r for r in rows if r["seed"] >= HELD_OUT_SEEDS.start]
    over = f"the {len(held)} held-out ones" if held else "these development ones"
    held = held or rows  # a development-only table: its shares over its own scenes
    for r in rows:
        for q in ("median", "p95"):
            k = r[f"onset_{q}"]
            r[f"best_tracked_pct_{q}"] = float("nan") if k is None else 100.0 * (r["frames"] - k) / r["frames"]
    best = np.array([r["best_tracked_pct_median"] for r in held])
    best95 = np.array([r["best_tracked_pct_p95"] for r in held])
    cols = [("seed", "seed", "{}"), ("frames", "frames", "{}"),
            ("onset_median", "median parallax >= 1 deg from frame", "{}"),
            ("onset_p95", "95th percentile >= 1 deg from frame", "{}"),
            ("best_tracked_pct_median", "frames left to track (%), median rule", "{:.1f}"),
            ("best_tracked_pct_p95", "frames left to track (%), 95th-percentile rule", "{:.1f}")]
    notes = (f"Seeds {_ranges([r['seed'] for r in rows])} ({len(rows)} scenes; the shares below are over "
             f"{over}). The drawn camera starts at rest (its arc is a cosine in time), so "
             "a monocular map, which needs parallax, cannot start on the first frames. From the truth (frame 0's "
             "depth back-projected through the true poses, `parallax_onset` in `benchmarks/family_slam.py`): the "
             "first frame whose median parallax with frame 0 reaches 1 deg (this SLAM's rule, "
             "`SlamConfig.min_parallax_deg`) and whose 95th percentile does (about ORB-SLAM2's rule, the 51st "
             "largest of some 1000 features); the frames from there on are all a SLAM with that rule can track. "
             f"Median rule: at most {np.nanmedian(best):.1f} % of frames (median over scenes), at least 95 % possible "
             f"on {np.mean(best >= 95.0) * 100:.0f} % of scenes; 95th-percentile rule: {np.nanmedian(best95):.1f} %, "
             f"{np.mean(best95 >= 95.0) * 100:.0f} % of scenes. No SLAM runs here.")

    def plot(plt):
        fig, ax = plt.subplots(figsize=(6, 3.4))
        ax.hist([best, best95], bins=20, label=["median rule", "95th-percentile rule"])
        ax.axvline(95.0, color="k", lw=0.8, ls="--")
        ax.set_xlabel("frames a monocular start leaves to track (%)")
        ax.set_ylabel("scenes")
        ax.legend()
        fig.tight_layout()
        return fig

    save(ONSET, rows, cols, "The scene family's monocular start: parallax from the truth", notes, plot)


def _onsets() -> dict[int, dict]:
    """The onset rows by seed, where `--onset` has been run."""
    from benchmarks.common import RESULTS

    path = RESULTS / f"{ONSET}.json"
    return {r["seed"]: r for r in json.loads(path.read_text())["rows"]} if path.exists() else {}


def _field(text: str) -> tuple[str, object]:
    """``name=value`` of ``--config``: the value as a number or boolean where it reads as one, else text."""
    import ast

    from simreal_nodes.vision.slam.config import SlamConfig

    name, _, value = text.partition("=")
    if name not in SlamConfig.__dataclass_fields__:
        raise SystemExit(f"--config: SlamConfig has no field {name!r}")
    try:
        return name, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        return name, value


def main() -> None:
    from benchmarks.family import HELD_OUT_SEEDS, parse_seeds

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default=f"{HELD_OUT_SEEDS.start}-{HELD_OUT_SEEDS.stop - 1}")
    ap.add_argument("--modes", default="mono,rgbd", help="comma-separated SLAM modes (mono, rgbd)")
    ap.add_argument("--features", type=int, default=1000)
    ap.add_argument("--config", action="append", default=[], metavar="LABEL:FIELD=VALUE[,FIELD=VALUE]",
                    help="run each scene also with these SlamConfig fields (repeatable; the defaults run as "
                         "'default' unless --no-default); values are parsed as Python literals or taken as text")
    ap.add_argument("--no-default", action="store_true", help="with --config: leave out the defaults' run")
    ap.add_argument("--jobs", type=int, default=2, help="scenes run in parallel processes (one core each)")
    ap.add_argument("--out", help="results name (default family_slam, or family_slam_dev for development seeds)")
    ap.add_argument("--report", action="store_true",
                    help="rewrite table and plot from the results JSON, labelled with the seeds it holds (a run "
                         "stopped early is reported on the seeds it finished)")
    ap.add_argument("--compose", metavar="NAME,NAME",
                    help="write --out (default family_slam) from these results' rows (a later one's row for the "
                         "same seed, mode and configuration replaces an earlier one's), labelled as --report does")
    ap.add_argument("--onset", action="store_true",
                    help="no SLAM: the frame at which each scene's true parallax first allows a monocular start "
                         "(:func:`parallax_onset`), into family_slam_onset, which the other tables then quote")
    a = ap.parse_args()
    if a.report or a.compose:
        from benchmarks.common import RESULTS

        name = a.out or "family_slam"
        merged: dict[tuple, dict] = {}
        runs = []
        for src in (a.compose.split(",") if a.compose else [name]):
            doc = json.loads((RESULTS / f"{src}.json").read_text())
            runs.append({"name": src, "machine": doc.get("machine")})
            for r in doc["rows"]:
                merged[(r["seed"], r["mode"], r.get("config", "default"))] = r
        kept = [merged[k] for k in sorted(merged)]
        done = sorted({r["seed"] for r in kept})
        kind = "held-out" if all(k >= HELD_OUT_SEEDS.start for k in done) else "development"
        write(kept, f"{kind} seeds {done[0]}-{done[-1]} ({len(done)} scenes)", name, runs)
        return
    seeds = parse_seeds(a.seeds)
    if a.onset:  # other seeds' rows already in the table are kept
        kept = [r for k, r in _onsets().items() if k not in seeds]
        onsets = []
        for o in scene_map(parallax_onset, seeds, a.jobs):
            print(o, flush=True)
            onsets.append(o)
            write_onset(sorted(kept + onsets, key=lambda r: r["seed"]))
        return
    modes = tuple(m for m in a.modes.split(",") if m)
    unknown = set(modes) - {"mono", "rgbd"}
    if unknown:
        raise SystemExit(f"--modes: unknown {sorted(unknown)} (mono, rgbd)")
    held_out = all(s >= HELD_OUT_SEEDS.start for s in seeds)
    name = a.out or ("family_slam" if held_out else "family_slam_dev")
    label = ("held-out seeds " if held_out else "development seeds ") + a.seeds
    configs: dict[str, dict] = {} if a.no_default and a.config else {"default": {}}
    for spec in a.config:
        clabel, _, fields = spec.partition(":")
        configs[clabel] = dict(_field(f) for f in fields.split(",") if f)
    job = functools.partial(run_scene, modes=modes, n_features=a.features, configs=configs)
    rows: list[dict] = []
    for scene_rows in scene_map(job, seeds, a.jobs):
        rows.extend(scene_rows)
        for r in scene_rows:
            print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}, flush=True)
        write(sorted(rows, key=lambda r: (r["seed"], r["mode"])), label, name)


if __name__ == "__main__":
    main()
