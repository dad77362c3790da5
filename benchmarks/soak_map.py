"""The soak's frames through the ROS-free pipeline (issue 20): does the map stay bounded, does the work per frame?

    python -m benchmarks.soak_map                  # 10 cycles of the sample (4 780 frames, about 4 minutes)
    python -m benchmarks.soak_map --cycles 4

`benchmarks/soak.py` measures the live graph: latency and each node's CPU. This takes the same frames (the joint boot
sample played forward and back, :func:`benchmarks.soak.ping_pong`) through `assimilation/offline.py`'s
:class:`Pipeline` (the RGB-D SLAM core and the boot's deformable tracker, the trackers' word on the map points
reaching the localization a frame late, as live), every frame processed, and reports after each cycle: the map's
keyframes and points, the points flagged deformable and those the map holds for the tracker (never culled), and the
localization's and the tracker's time per frame (p50 over the cycle), and the process's memory: resident, glibc's
heap in use and held free, Python's blocks. A map that revisits the same views should stop growing, and the work per
frame and the memory with it; the live soak's localization node grows by a fraction of a megabyte per 1000 frames,
and this run, without DDS or a node, tells whether the core does.
"""

from __future__ import annotations

import argparse
import gc
import os
import time

import numpy as np

from benchmarks.common import growth_per_1000, save


def run(cycles: int) -> list[dict]:
    import cv2

    from benchmarks import soak
    from benchmarks.common import malloc_trim, process_memory
    from simreal_nodes.assimilation.offline import Pipeline
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.demo import sample_bag
    from simreal_nodes.io import bags, images
    from simreal_nodes.scene.schema import build_spec_models, load_scene

    bag, scene_path = sample_bag("joint_boot", echo=print)
    scene = load_scene(scene_path)
    build_spec_models(scene)
    ts = bags.typestore()
    n_cycle = 2 * len({m.log_time_ns for m in bags.read_bag(bag, topics=["/camera/depth/image_raw"])}) - 2
    pipe: Pipeline | None = None
    frame: dict = {}
    # one cycle's times in preallocated arrays: lists of every frame's times would grow the process this measures
    loc_ms, trk_ms = np.zeros(n_cycle), np.zeros(n_cycle)
    n_frames = 0
    rows: list[dict] = []
    for m in soak.ping_pong(bag, cycles * n_cycle, 30.0):
        msg = ts.deserialize_cdr(m.raw, m.msgtype)
        if m.topic.endswith("camera_info"):
            if pipe is None:
                pipe = Pipeline(scene, CameraModel.from_camera_info(msg), feedback_delay=1)
            continue
        if m.topic.endswith("compressed"):
            frame["bgr"] = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_COLOR)
        else:
            frame["depth"] = images.depth_metres_of(msg)
        if pipe is None or "bgr" not in frame or "depth" not in frame:
            continue
        t0 = time.perf_counter()
        pipe.step(frame["bgr"], m.log_time_ns, depth=frame["depth"])
        loc_ms[n_frames % n_cycle] = 1e3 * (time.perf_counter() - t0) - pipe.tracker_ms
        trk_ms[n_frames % n_cycle] = pipe.tracker_ms
        n_frames += 1
        frame = {}
        if n_frames % n_cycle == 0:
            gc.collect()  # the memory of live objects, not of cyclic garbage the collector has yet to reach
            slam = pipe.loc.slam  # type: ignore[attr-defined]  # an RGB-D scene: a SlamLocalization
            mp = slam.map
            rows.append({"cycle": len(rows) + 1, "frames": n_frames, "keyframes": len(mp.keyframes),
                         "points": len(mp.points),
                         "deformable": sum(1 for p in mp.points.values() if p.deformable),
                         "held": len(slam.ctx.held),
                         "loc_ms": float(np.median(loc_ms)), "trk_ms": float(np.median(trk_ms)),
                         **process_memory()})
            if len(rows) == cycles:  # what of the resident size the allocator held free: returned by a trim
                malloc_trim()  # (False also where glibc had nothing to return: the RSS after it says so)
                rows[-1]["rss_trimmed"] = process_memory()["rss"]
            print(rows[-1], flush=True)
    if pipe is not None:
        pipe.loc.close()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cycles", type=int, default=10)
    ap.add_argument("--out", default="soak_map", help="results name (e.g. a run under other malloc settings)")
    a = ap.parse_args()
    if a.cycles < 1:
        ap.error("--cycles: at least 1 (the memory's growth over the second half needs 6 or more)")
    rows = run(a.cycles)
    cols = [("cycle", "cycle", "{}"), ("frames", "frames", "{}"), ("keyframes", "keyframes", "{}"),
            ("points", "map points", "{}"), ("deformable", "flagged deformable", "{}"),
            ("held", "held for the tracker", "{}"), ("loc_ms", "localization p50 (ms/frame)", "{:.1f}"),
            ("trk_ms", "tracker p50 (ms/frame)", "{:.1f}"), ("rss", "RSS (MB)", "{:.1f}"),
            ("malloc_used", "malloc in use (MB)", "{:.1f}"), ("malloc_free", "malloc held free (MB)", "{:.1f}"),
            ("py_blocks", "Python blocks (k)", "{:.0f}")]
    half = [r for r in rows if r["cycle"] > len(rows) / 2]
    growth = "; ".join(f"{label} {growth_per_1000([r['frames'] for r in half], [r[k] for r in half]):+.2f}"
                       for k, label in (("rss", "RSS"), ("malloc_used", "malloc in use"),
                                        ("malloc_free", "held free")))

    def plot(plt):
        fig, ax = plt.subplots(1, 3, figsize=(14, 3.6))
        f = [r["frames"] for r in rows]
        for k in ("keyframes", "points", "held"):
            v = np.array([r[k] for r in rows], float)
            ax[0].plot(f, v / v[0], marker=".", label=f"{k} (/{v[0]:.0f})")
        ax[0].set_xlabel("frames")
        ax[0].set_ylabel("relative to the first cycle")
        ax[0].legend(fontsize=7)
        ax[1].plot(f, [r["loc_ms"] for r in rows], marker=".", label="localization")
        ax[1].plot(f, [r["trk_ms"] for r in rows], marker=".", label="tracker")
        ax[1].set_xlabel("frames")
        ax[1].set_ylabel("ms per frame (p50 over the cycle)")
        ax[1].legend(fontsize=7)
        for k, label in (("rss", "RSS"), ("malloc_used", "malloc in use"), ("malloc_free", "malloc held free")):
            ax[2].plot(f, [r[k] for r in rows], marker=".", label=label)
        ax[2].set_xlabel("frames")
        ax[2].set_ylabel("MB (after each cycle)")
        ax[2].legend(fontsize=7)
        fig.tight_layout()
        return fig

    env = " ".join(f"{k}={v}" for k, v in sorted(os.environ.items())
                   if k.startswith(("MALLOC_", "GLIBC_TUNABLES")))
    save(a.out, rows, cols, "The soak's frames through the ROS-free pipeline: map size and work per cycle",
         f"`{env + ' ' if env else ''}python -m benchmarks.soak_map --cycles {a.cycles}"
         f"{'' if a.out == 'soak_map' else ' --out ' + a.out}` (see its docstring): the joint boot sample (640x480 "
         "RGB-D) forward and back, every frame through the RGB-D SLAM and the boot's tracker in one process (the "
         "local BA in the same process, not the node's worker), the trackers' feedback a frame late. Times are "
         "wall-clock per frame with nothing else running by intent; the live graph's are in `soak.md`. Memory after "
         "each cycle (after a garbage collection; `benchmarks.common.process_memory`): growth over the second half "
         f"of the cycles, MB per 1000 frames: {growth}. After the last cycle, glibc's free memory returned to "
         f"the OS (`malloc_trim`): RSS {rows[-1]['rss']:.1f} -> {rows[-1].get('rss_trimmed', float('nan')):.1f} MB. "
         "Every figure includes the sample's frames, which the benchmark holds in memory to play them back and forth "
         "(a constant).", plot)


if __name__ == "__main__":
    main()
