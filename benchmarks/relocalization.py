"""Relocalization and map reuse (issue 17, item 4): a kidnapped camera, and a saved map loaded for a second pass in
localization-only mode.

    ./run bench relocalization          (about 10 min)
    python -m benchmarks.relocalization --modes rgbd --cuts 60

Scene: the rendered room of `benchmarks/localization.py` (``slam_room``: a hand-held arc of about 3.5 m there and
back in 10 s, 640 x 480 at 30 fps, exact truth), 1000 ORB features, synchronous mapping (deterministic).

- **Kidnapped camera**: the SLAM tracks frames 0-119 (4 s out along the arc), then the stream is cut for ``cut``
  frames and resumes ``cut`` frames later (60: 2 s, near where the camera was, on its way back; 120 and 170: where it
  passed 2 s and 3.3 s after the start). The SLAM is not told: it finds out from its own matches (a failed motion
  model falls back to the local map, then to relocalization). Reported: how far the camera moved meanwhile, frames
  lost, whether it relocalized, poses reported more than 5 cm off before the first good one (a camera "tracked" into
  the wrong place), the frames to the first pose within 5 cm of the truth and its state, the time per lost frame
  (the relocalization attempts), and the ATE over the frames after it.
- **Map reuse**: pass 1 maps the room's first lap (``slam_room_laps``, frames 0-299); its map is saved
  (`Map.save`, HDF5), loaded into a fresh SLAM (`Slam.load_map`) set to localization-only, and the second lap
  (frames 300-599: the same arc with other hand jitter and other image noise) runs against it. Reported: frames
  localized in pass 2, the first one, keyframes added (0 expected: the map is frozen), the pass-2 poses' error in
  pass 1's frame (pass 1's alignment to the truth applied to pass 2: the reused map must put the camera where the
  first pass's map would), and time per frame in each pass.

Monocular maps have no metric scale: their alignment to the truth is a similarity (from the frames before the cut,
or from pass 1).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import replot, save

KIDNAP_AT = 120
CUTS = (60, 120, 170)
LAP = 300


def _frames(name: str, duration: float, stereo: bool) -> tuple[list[dict], object]:
    """The scene's frames (gray, depth, right, true pose) and its camera."""
    from simreal_nodes.synth.sequence import FrameStream

    fs = FrameStream(name, 640, 480, duration=duration, fps=30.0, stereo=stereo, ssaa=1, seed=0)
    return [{"gray": f["gray"], "depth": f["depth"], "right": f["right"], "T": f["T"]} for f in fs], fs.cam


def _slam(cam, mode: str):
    from simreal_nodes.vision.slam.system import Slam

    return Slam(cam, mode, 1000, baseline=0.12 if mode == "stereo" else None)


def _track(slam, f: dict, i: int, mode: str):
    return slam.track(f["gray"], i, depth=f["depth"] if mode == "rgbd" else None,
                      right=f["right"] if mode == "stereo" else None)


def _align(est: list[np.ndarray], truth: list[np.ndarray], mono: bool) -> tuple[np.ndarray, np.ndarray, float]:
    from simreal_nodes.vision.trajectory import umeyama

    return umeyama(np.array(est), np.array(truth), with_scale=mono)


def kidnap(seq: list[dict], cam, mode: str, cut: int) -> dict:
    slam = _slam(cam, mode)
    before: dict[int, np.ndarray] = {}
    after: list[tuple[int, object]] = []
    try:
        for i in range(KIDNAP_AT):
            r = _track(slam, seq[i], i, mode)
            if r.T_wc is not None:
                before[i] = r.T_wc[:3, 3].copy()
        resume = KIDNAP_AT + cut
        for i in range(resume, len(seq)):
            t0 = time.perf_counter()
            r = _track(slam, seq[i], i, mode)
            after.append((i, r, 1e3 * (time.perf_counter() - t0)))
    finally:
        slam.close()
    row: dict = {"mode": mode, "cut_frames": cut, "cut_s": cut / 30.0, "resume": KIDNAP_AT + cut,
                 "tracked_before": len(before)}
    if len(before) < 10:
        row["failure"] = "too few frames tracked before the cut to align with the truth"
        return row
    idx = sorted(before)
    R, t, s = _align([before[i] for i in idx], [seq[i]["T"][:3, 3] for i in idx], mode == "mono")

    def err(i: int, T_wc: np.ndarray) -> float:
        return float(np.linalg.norm(s * R @ T_wc[:3, 3] + t - seq[i]["T"][:3, 3]))

    row["jump_m"] = float(np.linalg.norm(seq[KIDNAP_AT + cut]["T"][:3, 3] - seq[KIDNAP_AT - 1]["T"][:3, 3]))
    row["lost_frames"] = sum(r.state_name == "lost" for _i, r, _ms in after)
    row["relocalized"] = any(r.state_name == "relocalized" for _i, r, _ms in after)
    # back on track: the first pose after the resumption within 5 cm of the truth (found by tracking the local map
    # or by relocalizing: the SLAM is not told of the cut)
    first = next((k for k, (i, r, _ms) in enumerate(after) if r.T_wc is not None and err(i, r.T_wc) <= 0.05), None)
    wrong = [err(i, r.T_wc) for i, r, _ in (after if first is None else after[:first]) if r.T_wc is not None]
    row["wrong_before"] = len(wrong)
    lost_ms = [ms for _i, r, ms in after if r.state_name == "lost"]
    row["lost_ms_p50"] = float(np.median(lost_ms)) if lost_ms else float("nan")
    if first is None:
        row["failure"] = "no pose within 5 cm after the cut"
        print(row, flush=True)
        return row
    i0, r0, _ = after[first]
    row["frames_to_pose"] = first
    row["s_to_pose"] = first / 30.0
    row["first_state"] = r0.state_name
    row["first_err_mm"] = 1e3 * err(i0, r0.T_wc)
    rest = [err(i, r.T_wc) for i, r, _ in after[first:] if r.T_wc is not None]
    row["tracked_after_pct"] = 100.0 * len(rest) / len(after[first:])
    row["ate_after_mm"] = 1e3 * float(np.sqrt(np.mean(np.square(rest))))
    row["over_5cm_after"] = sum(e > 0.05 for e in rest)
    print(row, flush=True)
    return row


def reuse(seq: list[dict], cam, mode: str, work: Path) -> dict:
    from simreal_nodes.vision.slam.map import Map

    slam = _slam(cam, mode)
    p1: dict[int, np.ndarray] = {}
    ms1 = []
    try:
        for i in range(LAP):
            t0 = time.perf_counter()
            r = _track(slam, seq[i], i, mode)
            ms1.append(1e3 * (time.perf_counter() - t0))
            if r.T_wc is not None:
                p1[i] = r.T_wc[:3, 3].copy()
        path = work / f"{mode}.h5"
        slam.map.save(path, cam, mode)
        n_kf, n_pts = len(slam.map.keyframes), len(slam.map.points)
    finally:
        slam.close()
    row: dict = {"mode": mode, "pass1_tracked": len(p1), "map_keyframes": n_kf, "map_points": n_pts,
                 "map_mb": path.stat().st_size / 1e6, "pass1_ms_p50": float(np.median(ms1))}
    s2 = _slam(cam, mode)
    s2.load_map(Map.load(path))
    s2.set_localization_only(True)
    p2: dict[int, np.ndarray] = {}
    ms2 = []
    try:
        for i in range(LAP, min(2 * LAP, len(seq))):
            t0 = time.perf_counter()
            r = _track(s2, seq[i], i, mode)
            ms2.append(1e3 * (time.perf_counter() - t0))
            if r.T_wc is not None:
                p2[i] = r.T_wc[:3, 3].copy()
        row["keyframes_added"] = len(s2.map.keyframes) - n_kf
    finally:
        s2.close()
    n2 = min(2 * LAP, len(seq)) - LAP
    row.update(pass2_frames=n2, pass2_tracked=len(p2), pass2_tracked_pct=100.0 * len(p2) / n2,
               pass2_first=(min(p2) - LAP) if p2 else None, pass2_ms_p50=float(np.median(ms2)))
    idx1 = sorted(p1)
    if len(idx1) >= 10 and p2:
        R, t, s = _align([p1[i] for i in idx1], [seq[i]["T"][:3, 3] for i in idx1], mode == "mono")
        e1 = [np.linalg.norm(s * R @ p1[i] + t - seq[i]["T"][:3, 3]) for i in idx1]
        e2 = [np.linalg.norm(s * R @ p2[i] + t - seq[i]["T"][:3, 3]) for i in sorted(p2)]
        row["pass1_ate_mm"] = 1e3 * float(np.sqrt(np.mean(np.square(e1))))
        row["pass2_err_mm"] = 1e3 * float(np.sqrt(np.mean(np.square(e2))))
        row["pass2_err_p95_mm"] = 1e3 * float(np.percentile(e2, 95))
    print(row, flush=True)
    return row


def plot_kidnap_rows(plt, rows: list[dict]):
    """Per SLAM mode and cut: the first pose's error after the cut and the ATE over the frames after it."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    cuts = list(dict.fromkeys(r["cut_s"] for r in rows))
    for ax, key, label in ((axes[0], "first_err_mm", "first pose within 5 cm: its error (mm)"),
                           (axes[1], "ate_after_mm", "ATE after the cut (mm)")):
        for k, mode in enumerate(modes):
            v = {r["cut_s"]: r.get(key) for r in rows if r["mode"] == mode}
            x = np.arange(len(cuts)) + 0.8 / len(modes) * (k - (len(modes) - 1) / 2)
            ax.bar(x, [v.get(c) if v.get(c) is not None else np.nan for c in cuts], width=0.8 / len(modes),
                   label=mode)
        ax.set_xticks(np.arange(len(cuts)), [f"cut {c:.1f} s" for c in cuts])
        ax.set_ylabel(label)
        ax.legend(title="SLAM")
    return fig


def plot_reuse_rows(plt, rows: list[dict]):
    """Per SLAM mode: pass 1's ATE beside pass 2's error (RMS and p95) against the loaded map."""
    fig, ax = plt.subplots(figsize=(6, 4))
    x = np.arange(len(rows))
    for k, (key, label) in enumerate((("pass1_ate_mm", "pass 1 ATE (mapping)"),
                                      ("pass2_err_mm", "pass 2 error, RMS (map loaded)"),
                                      ("pass2_err_p95_mm", "pass 2 error, p95"))):
        ax.bar(x + 0.27 * (k - 1), [r.get(key) if r.get(key) is not None else np.nan for r in rows], width=0.27,
               label=label)
    ax.set_xticks(x, [f"{r['mode']} ({r['pass2_tracked_pct']:.0f} % localized)" for r in rows])
    ax.set_ylabel("mm against the truth (pass 1's alignment)")
    ax.legend()
    return fig


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--modes", default="rgbd,stereo,mono")
    ap.add_argument("--cuts", default=",".join(str(c) for c in CUTS), help="frames cut out of the stream")
    ap.add_argument("--only", choices=("kidnap", "reuse"), default=None, help="run one of the two parts")
    ap.add_argument("--replot", action="store_true", help="only redraw the two PNGs from the saved results (no run)")
    a = ap.parse_args(argv)
    if a.replot:
        print(replot("relocalization", plot_kidnap_rows), replot("map_reuse", plot_reuse_rows))
        return
    modes = a.modes.split(",")
    stereo = "stereo" in modes
    if a.only != "reuse":
        rows_k = []
        frames, cam = _frames("slam_room", 10.0, stereo)
        for mode in modes:
            for cut in (int(c) for c in a.cuts.split(",")):
                rows_k.append(kidnap(frames, cam, mode, cut))
        del frames
        cols_k = [("mode", "SLAM", "{}"), ("cut_s", "cut (s)", "{:.1f}"), ("resume", "resumes at frame", "{}"),
                  ("jump_m", "camera moved meanwhile (m)", "{:.2f}"), ("lost_frames", "frames lost", "{}"),
                  ("relocalized", "relocalized", "{}"), ("wrong_before", "poses > 5 cm off before", "{}"),
                  ("frames_to_pose", "frames to a pose within 5 cm", "{}"), ("s_to_pose", "seconds", "{:.2f}"),
                  ("first_state", "its state", "{}"), ("first_err_mm", "its error (mm)", "{:.1f}"),
                  ("lost_ms_p50", "ms per lost frame (p50)", "{:.0f}"),
                  ("tracked_after_pct", "tracked after (%)", "{:.0f}"), ("ate_after_mm", "ATE after (mm)", "{:.1f}"),
                  ("over_5cm_after", "poses > 5 cm off after", "{}"), ("failure", "failure", "{}")]
        save("relocalization", rows_k, cols_k, "Kidnapped camera: relocalization in the rendered room",
             "`python -m benchmarks.relocalization` (see its docstring): frames 0-119 tracked, then the stream jumps "
             "ahead by the cut (the arc goes out and back: 2 s resumes near where the camera was, going the other "
             "way; longer cuts resume where it passed earlier). Errors after the similarity (monocular) or rigid "
             "alignment of the frames before the cut to the truth.", lambda plt: plot_kidnap_rows(plt, rows_k))
    if a.only == "kidnap":
        return
    rows_r = []
    frames, cam = _frames("slam_room_laps", 20.0, stereo)
    with tempfile.TemporaryDirectory() as d:
        for mode in modes:
            rows_r.append(reuse(frames, cam, mode, Path(d)))
    cols_r = [("mode", "SLAM", "{}"), ("map_keyframes", "map keyframes", "{}"), ("map_points", "map points", "{}"),
              ("map_mb", "map file (MB)", "{:.1f}"), ("pass1_ate_mm", "pass 1 ATE (mm)", "{:.1f}"),
              ("pass2_tracked_pct", "pass 2 localized (%)", "{:.0f}"), ("pass2_first", "pass 2 first frame", "{}"),
              ("keyframes_added", "keyframes added", "{}"),
              ("pass2_err_mm", "pass 2 error in pass 1's frame (mm)", "{:.1f}"), ("pass2_err_p95_mm", "p95", "{:.1f}"),
              ("pass1_ms_p50", "ms/frame pass 1 (p50)", "{:.0f}"), ("pass2_ms_p50", "pass 2 (p50)", "{:.0f}")]
    save("map_reuse", rows_r, cols_r, "Map reuse: a saved map, loaded, localization-only on a second pass",
         "`python -m benchmarks.relocalization` (see its docstring): pass 1 maps lap 1 of `slam_room_laps`, pass 2 "
         "(lap 2: other hand jitter, other image noise) localizes against the loaded map with mapping off. Pass 2's "
         "error uses pass 1's alignment to the truth.", lambda plt: plot_reuse_rows(plt, rows_r))


if __name__ == "__main__":
    main()
