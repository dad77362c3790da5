"""ORB-SLAM3 beside this project's SLAM on the same frames (issue 17's side-by-side benchmark).

    pip install pyorbslam3                                   # the comparator (GPL-3.0; not a project dependency)
    python -m benchmarks.orbslam3_side                       # held-out family 1000-1019, 7-Scenes, the long room
    python -m benchmarks.orbslam3_side --seeds 1000-1004 --no-real --no-long

About 40 minutes on 2 cores: the family's scenes are rendered once and run by both SLAMs (mono and RGB-D); the real
7-Scenes frames (``../shared/data``, skipped when absent) likewise; on the long room sequence of
`benchmarks/long_slam.py` (2 100 frames, its four runs' noise seeds) ORB-SLAM3 alone runs, beside `long_slam.json`.

The comparator is ORB-SLAM3 (Campos et al. 2021; ORB-SLAM2's tracking, local mapping and relocalization in its
monocular and RGB-D modes, with the Atlas added) through the ``pyorbslam3`` bindings, the one ORB-SLAM build on
PyPI. Its settings are ORB-SLAM2's published ones for 640 x 480: 1000 ORB features, scale 1.2, 8 levels, FAST thresholds
20 / 7; RGB-D with ``bf`` = fx times the 0.08 m virtual baseline this SLAM uses and the close/far depth threshold
``ThDepth`` 40 baselines; no IMU, no viewer. Its vocabulary is trained here (`benchmarks/orb_vocabulary.py`: k 10, L 6
as the authors' file, on ORB features of the family's development scenes 0-5, every second frame; `--levels 5` is the
knob that showed the tree's depth matters), since the authors' 139 MB ``ORBvoc.txt`` is not on PyPI (nor reachable from
these machines); that costs ORB-SLAM3 something in its BoW steps (tracking against the reference keyframe,
relocalization, loop detection), said beside the result.

This project's SLAM runs as the other family benchmarks run it (``benchmarks.real_slam.run``: its defaults,
keyframes and local BA on the frame that makes them, deterministic); ORB-SLAM3 as it always runs, local mapping and
loop closing in their own threads (the 2 cores), so its rows vary a little from run to run. Each scene is run by
both, one after the other, nothing else on the host: this SLAM in the benchmark's process, ORB-SLAM3 in a process
forked for each run (:func:`isolated`: ORB-SLAM3 keeps the first camera a process saw; until stop 75 the 7-Scenes
rows ran with the family's camera), or spawned for the long room's, which render their own frames (a forked child
of a process that has rendered hangs, stop 85).

Per scene and SLAM: frames tracked (ORB-SLAM3: state OK; this SLAM: ok or relocalized; the frames before a
monocular map count as not tracked), ATE RMSE after a similarity (monocular) or rigid (RGB-D) alignment of the
tracked frames, the same as % of the path, RPE over 1 s, the tracking call's time per frame (p50; this SLAM's
without its synchronous keyframe bookkeeping, as `localization.md`), and ORB-SLAM3's map resets (a monocular
ORB-SLAM3 that loses its map starts another in the Atlas; its poses then live in another frame, so a run with a
reset is aligned on its longest stretch of one map only and the row says so).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import save

CACHE = Path(__file__).resolve().parents[1] / "cache" / "orbslam3"
VOCAB_SEEDS = range(0, 6)  # development scenes of the family: never the held-out ones
N_FEATURES = 1000
CHILD_TIMEOUT_S = 3600.0  # an hour for one ORB-SLAM3 run: far beyond the longest (the long room's 2 100 frames)
VOCAB_LEVELS = 6  # the vocabulary tree's depth (k 10), as the authors' ORBvoc.txt (BoW matches grouped at L - 4)


def vocabulary(k: int = 10, levels: int = VOCAB_LEVELS, seeds: range = VOCAB_SEEDS) -> Path:
    """The ORB vocabulary ORB-SLAM3 loads, trained once on development scenes' frames (``seeds``) and cached."""
    import cv2

    from benchmarks import orb_vocabulary as ov
    from benchmarks.family import scene_name
    from simreal_nodes.synth.sequence import sequence

    path = CACHE / f"vocab_k{k}_L{levels}_dev{seeds.start}-{seeds.stop - 1}.txt"
    if path.exists():
        return path
    orb = cv2.ORB_create(N_FEATURES, 1.2, 8, fastThreshold=20)
    descs = []
    for seed in seeds:
        if seed >= 1000:
            raise ValueError(f"the vocabulary trains on development scenes only, not held-out seed {seed}")
        seq = sequence.__wrapped__(scene_name(seed), 640, 480, fps=15.0, stereo=False)
        for im in seq["rgb"][::2]:
            _, d = orb.detectAndCompute(cv2.cvtColor(im, cv2.COLOR_RGB2GRAY), None)
            if d is not None:
                descs.append(d)
    return ov.write_text(ov.train(descs, k, levels, seed=0), path)


def settings_yaml(cam, mode: str, fps: float, path: Path, baseline: float = 0.08) -> Path:
    """ORB-SLAM3's settings file (its older format, as ORB-SLAM2's TUM examples): OpenCV YAML, reals written with a
    decimal point (ORB-SLAM3 checks the node types)."""
    if cam.fisheye:  # ORB-SLAM3 has it (KannalaBrandt8), the settings written here do not
        raise ValueError("ORB-SLAM3's pinhole settings take k1 k2 p1 p2 k3, not an equidistant (fisheye) lens")
    D = np.r_[np.asarray(cam.cv_dist(), float).ravel(), np.zeros(5)]
    if np.any(D[5:] != 0):
        raise ValueError(f"ORB-SLAM3's pinhole model takes k1 k2 p1 p2 k3, not a {cam.distortion_model} distortion")
    r = lambda v: repr(float(v))  # noqa: E731 - '525.0', '-0.04': a real to OpenCV's YAML reader
    lines = ["%YAML:1.0", 'Camera.type: "PinHole"',
             f"Camera.fx: {r(cam.fx)}", f"Camera.fy: {r(cam.fy)}", f"Camera.cx: {r(cam.cx)}", f"Camera.cy: {r(cam.cy)}",
             f"Camera.k1: {r(D[0])}", f"Camera.k2: {r(D[1])}", f"Camera.p1: {r(D[2])}", f"Camera.p2: {r(D[3])}",
             f"Camera.k3: {r(D[4])}", f"Camera.width: {int(cam.width)}", f"Camera.height: {int(cam.height)}",
             f"Camera.fps: {r(fps)}", "Camera.RGB: 1",
             f"ORBextractor.nFeatures: {N_FEATURES}", "ORBextractor.scaleFactor: 1.2", "ORBextractor.nLevels: 8",
             "ORBextractor.iniThFAST: 20", "ORBextractor.minThFAST: 7",
             "Viewer.KeyFrameSize: 0.05", "Viewer.KeyFrameLineWidth: 1.0", "Viewer.GraphLineWidth: 0.9",
             "Viewer.PointSize: 2.0", "Viewer.CameraSize: 0.08", "Viewer.CameraLineWidth: 3.0",
             "Viewer.ViewpointX: 0.0", "Viewer.ViewpointY: -0.7", "Viewer.ViewpointZ: -1.8", "Viewer.ViewpointF: 500.0"]
    if mode == "rgbd":
        lines += [f"Camera.bf: {r(cam.fx * baseline)}", "ThDepth: 40.0", "DepthMapFactor: 1.0"]
    path.write_text("\n".join(lines) + "\n")
    return path


def run_orbslam3(seq: dict, mode: str, vocab: Path) -> dict:
    """ORB-SLAM3 over the sequence (gray frames; depth in metres, NaN invalid; poses): the row's measures."""
    return run_orbslam3_stream(zip(seq["gray"], seq["depth"], seq["T"]), seq["cam"], seq["fps"], mode, vocab)


def run_orbslam3_stream(frames: Iterable[tuple], cam, fps: float, mode: str, vocab: Path) -> dict:
    """ORB-SLAM3 over (gray, depth, true camera-to-world pose) frames as they come: the row's measures. Each run is
    a process of its own, forked (:func:`isolated`), so the frames must not be rendered in it: a sequence rendered
    one frame at a time goes through :func:`_run_orbslam3_rendered` in a spawned child instead."""
    return isolated(_run_orbslam3_here, frames, cam, fps, mode, vocab)


def isolated(fn: Callable[..., dict], *args: Any, start: str = "fork", timeout_s: float = CHILD_TIMEOUT_S) -> dict:
    """``fn(*args)`` in a child process forked for it (``start="spawn"``: a fresh interpreter, ``fn`` and ``args``
    pickled), its dict returned (as JSON: numbers, strings, lists). A child that has not answered after
    ``timeout_s`` is killed and the run fails with that reason instead of waiting forever.

    Why: ORB-SLAM3 keeps the camera in static members of its ``Frame`` class (fx, fy, cx, cy, their inverses, the
    undistorted image bounds and the feature grid's cell size), set by the first frame a process makes and never
    again. A second ``Slam`` in the same process with another camera tracks with the first one's: the real 7-Scenes
    frames (fx 585) run after a family scene (fx 525, barrel distortion) read 105-108 mm of ATE in RGB-D against
    36-37 mm alone (stop 75, scratch), and this benchmark published the 100 mm. The parent never makes a ``Slam``,
    so every child starts from a clean class.

    A child that renders must be spawned: a forked child of a process that has rendered (the family's frames, through
    Mesa's EGL) inherits a GL state whose worker threads were not forked, and its first frame waits on them forever
    (stop 85: the long room's first run hung so after the family's scenes; stop 75's run had no family scenes)."""
    import multiprocessing

    ctx = multiprocessing.get_context(start)
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(send, fn, args), daemon=True)
    child.start()
    send.close()
    try:
        if recv.poll(timeout_s):
            ok, value = json.loads(recv.recv_bytes())
        else:
            child.kill()
            ok, value = False, f"no answer after {timeout_s:.0f} s (killed)"
    except EOFError:
        ok, value = False, "it died before it answered"
    finally:
        recv.close()
        child.join()
    if not ok:
        raise RuntimeError(f"{getattr(fn, '__name__', fn)} in a child process (exit code {child.exitcode}): {value}")
    out: dict = value
    return out


def _child(conn: Any, fn: Callable[..., dict], args: tuple) -> None:
    def plain(v: Any) -> Any:
        if isinstance(v, np.integer):
            return int(v)
        if isinstance(v, np.floating):
            return float(v)
        if isinstance(v, np.ndarray):
            return v.tolist()
        raise TypeError(f"{type(v).__name__} is not a plain value")

    try:
        msg = [True, fn(*args)]
    except Exception as e:  # noqa: BLE001 - the parent raises it with its message
        msg = [False, f"{type(e).__name__}: {e}"]
    try:
        try:
            data = json.dumps(msg, default=plain)
        except TypeError as e:  # a result that is not plain data: the parent raises with this
            data = json.dumps([False, f"the result is not plain data: {e}"])
        conn.send_bytes(data.encode())
    finally:
        conn.close()


def _run_orbslam3_here(frames: Iterable[tuple], cam, fps: float, mode: str, vocab: Path) -> dict:
    """:func:`run_orbslam3_stream`'s work, in this process."""
    import pyorbslam3 as pos

    with tempfile.TemporaryDirectory() as tmp:
        cfg = settings_yaml(cam, mode, fps, Path(tmp) / "orbslam3.yaml")
        slam = pos.Slam(str(vocab), str(cfg), pos.Sensor.MONOCULAR if mode == "mono" else pos.Sensor.RGBD)
    est: dict[int, np.ndarray] = {}
    map_of: dict[int, int] = {}
    ms: list[float] = []
    truth: list[np.ndarray] = []
    maps, prev = 0, None
    t_all = time.perf_counter()
    try:
        for i, (g, depth, T) in enumerate(frames):
            truth.append(np.asarray(T))
            stamp = i / fps
            t0 = time.perf_counter()
            if mode == "mono":
                r = slam.track_monocular(g, stamp)
            else:
                d = np.nan_to_num(np.asarray(depth, np.float32), nan=0.0)
                r = slam.track_rgbd(g, d, stamp)
            ms.append(1e3 * (time.perf_counter() - t0))
            ok = r.state == pos.TrackingState.OK
            if ok and (not est or prev in (pos.TrackingState.LOST, pos.TrackingState.NOT_INITIALIZED)):
                maps += 1  # the first map, or another after a loss (ORB-SLAM3 makes a new one in its Atlas)
            if ok:
                est[i] = np.asarray(r.pose_wc)[:3, 3].copy()
                map_of[i] = maps
            prev = r.state
    finally:
        slam.shutdown()
    wall = time.perf_counter() - t_all
    return _measures(np.array(truth), fps, est, map_of, ms, mode, wall)


def _run_orbslam3_rendered(scene: str, frame_kw: dict, mode: str, vocab: Path) -> dict:
    """ORB-SLAM3 over the frames of ``FrameStream(scene, **frame_kw)``, rendered one at a time in this process (a
    spawned child: :func:`isolated`), on one OpenCV and one BLAS thread as the forked runs inherit from the parent."""
    from benchmarks.family import _one_thread
    from simreal_nodes.synth.sequence import FrameStream

    _one_thread()
    fs = FrameStream(scene, **frame_kw)
    return _run_orbslam3_here(((f["gray"], f["depth"], f["T"]) for f in fs), fs.cam, float(frame_kw["fps"]), mode,
                              vocab)


def _measures(T_true: np.ndarray, fps: float, est: dict[int, np.ndarray], map_of: dict[int, int], ms: list[float],
              mode: str, wall: float) -> dict:
    from benchmarks.real_slam import accuracy

    n = len(T_true)
    n_maps = len(set(map_of.values()))
    row = {"frames": n, "tracked_pct": 100.0 * len(est) / n, "first_tracked": min(est) if est else None,
           "maps": n_maps, "tracking_ms_p50": float(np.median(ms[5:])),
           "tracking_ms_p95": float(np.percentile(ms[5:], 95)), "fps_wall": n / wall}
    if n_maps > 1:  # align the longest map only
        best = Counter(map_of.values()).most_common(1)[0][0]
        est = {i: p for i, p in est.items() if map_of[i] == best}
    return {**row, "aligned_frames": len(est), **accuracy(est, T_true, mode, fps)}


def run_ours(seq: dict, mode: str) -> dict:
    """This project's SLAM over the same frames (`benchmarks.real_slam.run`, its defaults)."""
    from benchmarks.real_slam import run

    t0 = time.perf_counter()
    r = run(seq, mode, n_features=N_FEATURES)
    wall = time.perf_counter() - t0
    n = r["frames"]
    return {"frames": n, "tracked_pct": 100.0 * r["tracked"] / n, "first_tracked": r["first_tracked"], "maps": 1,
            "tracking_ms_p50": r["tracking_ms_p50"], "tracking_ms_p95": float("nan"), "fps_wall": n / wall,
            "ate_mm": r.get("ate_mm", float("nan")), "ate_pct": r.get("ate_pct", float("nan")),
            "aligned_frames": r["tracked"], "rpe_1s_mm": r.get("rpe_1s_mm", float("nan"))}


def long_rows(vocab: Path) -> list[dict]:
    """The long sequence of `benchmarks/long_slam.py` (the room's lap seven times, 2 100 frames at 30 fps, each of its
    runs' noise seed): ORB-SLAM3 on the same frames, rendered again one at a time; this SLAM's rows are
    `long_slam.json`'s (the same frames, its mapping in a process as live), not rerun here."""
    from benchmarks.common import RESULTS
    from benchmarks.long_slam import FPS, LAP_S

    if not (RESULTS / "long_slam.json").is_file():
        raise SystemExit("the long sequence's rows of this SLAM come from long_slam.json: run `./run bench long_slam` "
                         "first, or pass --no-long")
    ours = json.loads((RESULTS / "long_slam.json").read_text())
    laps = round(ours["rows"][0]["frames"] / (LAP_S * FPS))
    rows = []
    for o in ours["rows"]:
        name = f"room, {laps} laps (noise {o['seed']})"
        rows.append({"scene": name, "mode": o["mode"], "slam": "simreal", "frames": o["frames"],
                     "tracked_pct": o["tracked_pct"], "first_tracked": None, "maps": 1,
                     "tracking_ms_p50": o["tracking_ms_p50"], "tracking_ms_p95": o["tracking_ms_p95"],
                     "fps_wall": o["fps_wall"], "ate_mm": o["ate_mm"], "ate_pct": o["ate_pct"],
                     "aligned_frames": o["tracked"], "rpe_1s_mm": o["rpe_mm"], "from": "long_slam.json"})
        kw = {"width": 640, "height": 480, "duration": laps * LAP_S, "fps": FPS, "ssaa": 1, "seed": o["seed"]}
        m = isolated(_run_orbslam3_rendered, "slam_room_laps", kw, o["mode"], vocab, start="spawn")
        rows.append({"scene": name, "mode": o["mode"], "slam": "ORB-SLAM3", **m})
        print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in rows[-1].items()}, flush=True)
    return rows


COLS = [("scene", "scene", "{}"), ("mode", "mode", "{}"), ("slam", "SLAM", "{}"), ("frames", "frames", "{}"),
        ("tracked_pct", "tracked (%)", "{:.1f}"), ("first_tracked", "first tracked", "{}"),
        ("maps", "maps", "{}"), ("ate_mm", "ATE (mm)", "{:.2f}"), ("ate_pct", "ATE % of path", "{:.3f}"),
        ("rpe_1s_mm", "RPE 1 s (mm)", "{:.2f}"), ("tracking_ms_p50", "tracking p50 (ms)", "{:.1f}"),
        ("fps_wall", "fps (wall)", "{:.1f}")]


def summary(rows: list[dict]) -> list[dict]:
    """Per mode and SLAM over the family's scenes: medians and the issue's targets' counts."""
    from benchmarks.family_slam import TARGET_ATE_PCT, TARGET_TRACKED

    out = []
    fam = [r for r in rows if str(r["scene"]).startswith("family")]
    for mode in ("mono", "rgbd"):
        for slam in ("simreal", "ORB-SLAM3"):
            rs = [r for r in fam if r["mode"] == mode and r["slam"] == slam]
            if not rs:
                continue
            ate_pct = np.array([r.get("ate_pct", np.nan) for r in rs], float)
            out.append({"mode": mode, "slam": slam, "scenes": len(rs),
                        "tracked_median_pct": float(np.median([r["tracked_pct"] for r in rs])),
                        "tracked_target": int(sum(r["tracked_pct"] >= TARGET_TRACKED[mode] for r in rs)),
                        "ate_median_mm": float(np.nanmedian([r.get("ate_mm", np.nan) for r in rs])),
                        "ate_median_pct": float(np.nanmedian(ate_pct)),
                        "ate_p90_pct": float(np.nanpercentile(ate_pct, 90)),
                        "within_target": int(np.sum(ate_pct <= TARGET_ATE_PCT)),
                        "multi_map": int(sum(r["maps"] > 1 for r in rs)),
                        "tracking_ms_p50": float(np.median([r["tracking_ms_p50"] for r in rs]))})
    return out


SUMMARY_COLS = [("mode", "mode", "{}"), ("slam", "SLAM", "{}"), ("scenes", "scenes", "{}"),
                ("tracked_median_pct", "tracked (median %)", "{:.1f}"),
                ("tracked_target", "scenes >= 95 % (mono) / 99 % (RGB-D) tracked", "{}"),
                ("ate_median_mm", "ATE median (mm)", "{:.2f}"), ("ate_median_pct", "ATE % of path: median", "{:.3f}"),
                ("ate_p90_pct", "p90", "{:.3f}"), ("within_target", "scenes within 0.3 %", "{}"),
                ("multi_map", "scenes with a map reset", "{}"), ("tracking_ms_p50", "tracking p50 (ms)", "{:.1f}")]


def write(rows: list[dict], label: str, vocab: Path, name: str = "orbslam3_side",
          vocab_seeds: range = VOCAB_SEEDS) -> None:
    from benchmarks.common import RESULTS, markdown_table

    summ = summary(rows)
    notes = (f"{label}. Each scene run by both SLAMs one after the other (ORB-SLAM3 in a process of its own per run), "
             "1000 ORB features "
             f"(`python -m benchmarks.orbslam3_side`, module docstring). ORB-SLAM3 {_version()} through pyorbslam3; "
             f"its vocabulary trained here ({vocab.name}, k 10 and L as named, on the family's development scenes "
             f"{vocab_seeds.start}-{vocab_seeds.stop - 1}). 'maps': the maps ORB-SLAM3 made (a reset starts "
             "another; ATE then over the longest one's frames). ORB-SLAM3 runs its mapping in threads and varies "
             "from run to run; this SLAM runs its keyframes synchronously and repeats to the bit."
             + (" The long room sequence's rows of this SLAM are `long_slam.json`'s (its mapping in a process, as "
                "live; the same frames), not rerun here." if any(r.get("from") for r in rows) else "")
             + ("\n\nOver the family's scenes:\n\n" + markdown_table(summ, SUMMARY_COLS) if summ else ""))

    def plot(plt):
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        for ax, mode in zip(axes, ("mono", "rgbd")):
            for slam, mk in (("simreal", "o"), ("ORB-SLAM3", "x")):
                rs = [r for r in rows if r["mode"] == mode and r["slam"] == slam and "ate_pct" in r]
                ax.scatter([r["tracking_ms_p50"] for r in rs], [r["ate_pct"] for r in rs], marker=mk, label=slam)
            ax.axhline(0.3, color="gray", lw=0.8, ls="--")
            ax.set_xlabel("tracking p50 (ms per frame)")
            ax.set_ylabel("ATE (% of path)")
            ax.set_yscale("log")
            ax.set_title(mode)
            ax.legend()
        fig.tight_layout()
        return fig

    save(name, rows, COLS, "ORB-SLAM3 beside this SLAM on the same frames", notes, plot,
         extra={"summary": summ, "label": label, "vocabulary": vocab.name})
    print((RESULTS / f"{name}.md").read_text()[:4000], flush=True)


def _version() -> str:
    try:
        from importlib.metadata import version

        return f"(pyorbslam3 {version('pyorbslam3')})"
    except Exception:  # noqa: BLE001 - a label only
        return ""


def main() -> None:
    from benchmarks.family import HELD_OUT_SEEDS, _one_thread, parse_seeds
    from benchmarks.family_slam import slam_sequence

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default=f"{HELD_OUT_SEEDS.start}-{HELD_OUT_SEEDS.start + 19}",
                    help="family seeds (held out: 1000-1099)")
    ap.add_argument("--modes", default="mono,rgbd")
    ap.add_argument("--no-real", action="store_true", help="leave out the real 7-Scenes frames")
    ap.add_argument("--no-long", action="store_true", help="leave out the long room sequence (long_slam's frames)")
    ap.add_argument("--out", default="orbslam3_side")
    ap.add_argument("--slams", default="simreal,ORB-SLAM3", help="which of the two to run")
    ap.add_argument("--levels", type=int, default=VOCAB_LEVELS, help="the vocabulary tree's depth L")
    ap.add_argument("--vocab-seeds", default=f"{VOCAB_SEEDS.start}-{VOCAB_SEEDS.stop - 1}",
                    help="development scenes the vocabulary trains on (a range: the vocabulary's own sensitivity)")
    a = ap.parse_args()
    try:
        import pyorbslam3  # noqa: F401
    except ImportError:
        raise SystemExit("this benchmark needs the comparator: pip install pyorbslam3 (GPL-3.0, ORB-SLAM3)") from None
    _one_thread()  # this SLAM's OpenCV and BLAS on one thread each, as in the family benchmarks
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    lo, _, hi = a.vocab_seeds.partition("-")
    vocab_seeds = range(int(lo), int(hi or lo) + 1)
    vocab = vocabulary(levels=a.levels, seeds=vocab_seeds)
    slams = [x for x in a.slams.split(",") if x]
    if set(slams) - {"simreal", "ORB-SLAM3"}:
        raise SystemExit(f"--slams: simreal and/or ORB-SLAM3, not {a.slams}")
    modes = [m for m in a.modes.split(",") if m]
    seeds = parse_seeds(a.seeds) if a.seeds else []
    rows: list[dict] = []
    kind = "held-out" if all(s >= HELD_OUT_SEEDS.start for s in seeds) else "development"
    label = " and ".join(([f"{kind} family seeds {a.seeds}"] if seeds else []) + ([] if a.no_real else ["7-Scenes"]))
    scenes: list[tuple[str, int | None]] = [(f"family {s}", s) for s in seeds]
    if not a.no_real:
        scenes.append(("7-Scenes (real)", None))
    for name, seed in scenes:
        if seed is None:
            from benchmarks.real_slam import DATA, load

            if not DATA.is_dir():
                print(f"skipped: {DATA} absent", flush=True)
                continue
            seq = load()
        else:
            seq = slam_sequence(seed)[0]
        for mode in modes:
            for slam in slams:
                m = run_ours(seq, mode) if slam == "simreal" else run_orbslam3(seq, mode, vocab)
                r = {"scene": name, "mode": mode, "slam": slam, **m}
                print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}, flush=True)
                rows.append(r)
        write(rows, label, vocab, a.out, vocab_seeds)
    if not a.no_long and "ORB-SLAM3" in slams:
        rows += long_rows(vocab)
        write(rows, ", ".join(([label] if label else []) + ["the long room sequence"]), vocab, a.out, vocab_seeds)


if __name__ == "__main__":
    main()
