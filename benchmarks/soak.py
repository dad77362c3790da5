"""Soak (issue 20): 10 000 frames of RGB-D SLAM -> tracker -> overlay, live; is memory flat, does latency creep?

    ./run bench soak                      # 10 000 frames at the bag's 30 fps (about 6 minutes)
    python -m benchmarks.soak --frames 2000
    python -m benchmarks.soak --param localization.async_mapping=false --out soak_sync_mapping   # a knob row

Scene: the joint boot sample (`bags/joint_boot`, 640x480 RGB-D, 240 frames at 30 fps; the graph ingest ->
RGB-D SLAM -> tracker -> overlay), played forward, then backward, then forward again (the camera's path stays
continuous; the load steps where the direction turns), with fresh stamps, until ``--frames`` frames have been
published at the bag's rate. The graph sheds load live as it would from a camera (frames skipped are counted).

Measured: every node's resident memory (RSS) every 2 s, and each finished frame's latency from publication to
the overlay's report. Per node: RSS after the first 1000 frames and at the end, and its growth per 1000 frames
(least squares over the second half of the run); latency p50 / p95 over the first and the last 1000 frames
finished; and, since the frames repeat with the sample's cycle (forward and back: 478 frames), the latency's p50
over each cycle of frames finished, its range over the cycles after the first two (most of the map is made on those) and
its trend there (least squares over the cycles' p50, with its standard error): a creep shows as a trend, a
latency that wanders with the load as a range.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import struct
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil

from benchmarks.common import RESULTS, growth_per_1000, save, saved_machine
from simreal_nodes.demo import sample_bag
from simreal_nodes.io import bags
from simreal_nodes.ros import bagplay
from simreal_nodes.ros.commands import replay

STARTED = re.compile(r"\[launch\] started (\w+) \(pid (\d+)\)")
INPUTS = ("/camera/image_raw/compressed", "/camera/camera_info", "/camera/depth/image_raw")
READ_BAG = bags.read_bag  # the replay's reader is swapped for the ping-pong one below
CYCLE = [478]  # frames in one forward-and-back cycle of the sample (set by ping_pong; runs saved before it: 478)
SETTLE_CYCLES = 2  # cycles left out of the latency's range and trend: most of the map is made on them


def restamp(raw: bytes, ns: int) -> bytes:
    """A CDR message whose first field is a std_msgs/Header, with its stamp set to ``ns``."""
    return raw[:4] + struct.pack("<iI", ns // 10 ** 9, ns % 10 ** 9) + raw[12:]


def ping_pong(bag: Path, n_frames: int, fps: float):
    """The bag's camera frames forward, backward, forward ... with stamps ``1/fps`` apart, ``n_frames`` of them."""
    ts = bags.typestore()
    frames: dict[int, list[bags.BagMessage]] = {}
    for m in READ_BAG(bag, topics=list(INPUTS)):
        frames.setdefault(bags.stamp_ns(ts.deserialize_cdr(m.raw, m.msgtype)), []).append(m)
    order = [frames[k] for k in sorted(frames)]
    cycle = order + order[-2:0:-1]
    CYCLE[0] = len(cycle)
    t0 = time.time_ns()
    for k in range(n_frames):
        ns = t0 + round(k * 1e9 / fps)
        for m in sorted(cycle[k % len(cycle)], key=lambda m: m.topic != "/camera/camera_info"):
            yield bags.BagMessage(m.topic, m.msgtype, ns, restamp(m.raw, ns))


def run(n_frames: int, fps: float, params: dict | None = None) -> dict:
    bag, scene = sample_bag("joint_boot", echo=print)
    pids: dict[str, int] = {}
    rss: list[tuple[float, str, float]] = []
    cpu: list[tuple[float, str, float]] = []  # (frames published, node, CPU seconds user + system so far)
    stop = threading.Event()
    published = [0]

    restarts: list[str] = []

    def echo(line: str) -> None:
        if line.startswith("[launch]") and " exited with code " in line:
            restarts.append(line)  # a crash: the RSS series of that node then mixes two processes
        m = STARTED.match(line)
        if m:
            pids[m.group(1)] = int(m.group(2))
        if line.startswith(("[launch]", "[replay]")) or "rror" in line:
            print(line, flush=True)

    def sampler() -> None:  # while frames are published (not while the graph drains and stops)
        while not stop.wait(2.0) and published[0] < n_frames:
            for name, pid in list(pids.items()):
                with contextlib.suppress(psutil.Error):
                    proc = psutil.Process(pid)
                    k, mem, t = published[0], proc.memory_info().rss / 2 ** 20, proc.cpu_times()
                    rss.append((k, name, mem))
                    cpu.append((k, name, t.user + t.system))

    original = bagplay.Player._publish_image

    def counting(self, raw, s):
        published[0] += 1
        return original(self, raw, s)

    bagplay.Player._publish_image = counting
    th = threading.Thread(target=sampler, daemon=True)
    th.start()
    def read_bag(path, report=None, topics=None, **kw):
        if Path(path) == Path(bag) and not kw.get("only_headers"):
            return ping_pong(bag, n_frames, fps)
        return READ_BAG(path, report, topics=topics, **kw)

    bags.read_bag = read_bag
    try:
        with tempfile.TemporaryDirectory() as d:
            stats, _, _ = replay(str(bag), str(scene), rate=1.0, echo=echo, metrics_json=str(Path(d) / "m.json"),
                                 extra_params=params)
    finally:
        bags.read_bag = READ_BAG
        bagplay.Player._publish_image = original
        stop.set()
        th.join(5)
    return {"frames": n_frames, "fps": fps, "cycle": CYCLE[0], "params": params or {}, "stats": stats.as_dict(),
            "rss": rss, "cpu": cpu,
            "exits": restarts,
            "latency_ms": {n: list(v) for n, v in stats.latency_ms.items()}}


def summarize(r: dict) -> list[dict]:
    rows = []
    n = r["frames"]
    for name in sorted({x[1] for x in r["rss"]}):
        pts = np.array([(k, v) for k, nm, v in r["rss"] if nm == name])
        late = pts[pts[:, 0] >= n / 2]
        slope = growth_per_1000(late[:, 0], late[:, 1]) if len(late) > 3 else float("nan")  # four samples at least
        early = pts[pts[:, 0] >= min(1000, n / 4)]
        lat = np.asarray(r["latency_ms"].get(name, []))
        k = min(len(lat) // 4, 1000) if len(lat) else 0
        rows.append({"node": name, "rss_start": float(early[0, 1]) if len(early) else float("nan"),
                     "rss_end": float(pts[-1, 1]), "slope": slope,
                     "lat_first": float(np.percentile(lat[:k], 50)) if k else float("nan"),
                     "lat_last": float(np.percentile(lat[-k:], 50)) if k else float("nan"),
                     "lat_first95": float(np.percentile(lat[:k], 95)) if k else float("nan"),
                     "lat_last95": float(np.percentile(lat[-k:], 95)) if k else float("nan"),
                     "finished": len(lat), **cycle_trend(lat, int(r.get("cycle", 478))),
                     **cpu_drift(r.get("cpu", []), name, n, int(r.get("cycle", 478)))})
    return rows


def _samples(series: list, name: str) -> np.ndarray:
    """(frames published, value) rows of node ``name`` in a sampled series of (frames, node, value)."""
    return np.array([(k, v) for k, nm, v in series if nm == name], float).reshape(-1, 2)


def cpu_per_frame(cpu: list, name: str, window: float = 1000.0) -> np.ndarray:
    """(frames published at the window's end, CPU ms per frame published over the window) of node ``name``, from
    the cumulative CPU samples, windows of about ``window`` frames."""
    pts = _samples(cpu, name)
    out = []
    j = 0
    for i in range(1, len(pts)):
        if pts[i, 0] - pts[j, 0] >= window:
            out.append((pts[i, 0], 1e3 * (pts[i, 1] - pts[j, 1]) / (pts[i, 0] - pts[j, 0])))
            j = i
    return np.array(out, float).reshape(-1, 2)


def cpu_drift(cpu: list, name: str, n: int, cycle: int) -> dict:
    """A node's CPU per frame published over the 1000 frames after :data:`SETTLE_CYCLES` cycles and over the last
    1000 (NaN where the run sampled no CPU: runs saved before stop 91)."""
    pts = _samples(cpu, name)
    start = SETTLE_CYCLES * cycle

    def rate(a: float, b: float) -> float:
        sel = pts[(pts[:, 0] >= a) & (pts[:, 0] <= b)]
        if len(sel) < 2 or sel[-1, 0] - sel[0, 0] < 0.5 * (b - a):
            return float("nan")
        return float(1e3 * (sel[-1, 1] - sel[0, 1]) / (sel[-1, 0] - sel[0, 0]))

    return {"cpu_early": rate(start, start + 1000), "cpu_late": rate(n - 1000, n)}


def cycle_trend(lat: np.ndarray, cycle: int) -> dict:
    """The latency's p50 over each ``cycle`` frames finished; over the cycles after :data:`SETTLE_CYCLES`: their
    lowest and highest p50 and the least-squares trend of the p50 per 1000 frames with its standard error."""
    p50 = np.array([np.percentile(lat[i:i + cycle], 50) for i in range(0, len(lat) - cycle + 1, cycle)])
    late = p50[SETTLE_CYCLES:]
    out = {"cycles": len(p50), "cycle_lo": float("nan"), "cycle_hi": float("nan"), "trend": float("nan"),
           "trend_se": float("nan")}
    if len(late) >= 4:
        x = np.arange(len(late)) * cycle / 1000.0
        (slope, _icpt), cov = np.polyfit(x, late, 1, cov=True)
        out.update(cycle_lo=float(late.min()), cycle_hi=float(late.max()), trend=float(slope),
                   trend_se=float(np.sqrt(cov[0, 0])))
    return out


def main() -> None:
    import json

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--param", action="append", default=[], metavar="NODE.NAME=VALUE",
                    help="a node parameter for this run (a knob; JSON value), e.g. localization.async_mapping=false")
    ap.add_argument("--out", default="soak", help="results name (default: soak)")
    ap.add_argument("--report", action="store_true", help="rewrite table and plot from the results JSON")
    a = ap.parse_args()
    params: dict = {}
    for p in a.param:
        key, _, value = p.partition("=")
        node, _, name = key.partition(".")
        if not (node and name and value):
            ap.error(f"--param {p!r}: expected NODE.NAME=VALUE")
        params.setdefault(node, {})[name] = json.loads(value)
    r = json.loads((RESULTS / f"{a.out}.json").read_text())["run"] if a.report else run(a.frames, a.fps, params)
    kept = saved_machine(a.out) if a.report else {}  # the run's date and CPU probe, not the rewrite's
    rows = summarize(r)
    cols = [("node", "node", "{}"), ("rss_start", "RSS after 1000 frames (MB)", "{:.0f}"),
            ("rss_end", "RSS at the end (MB)", "{:.0f}"), ("slope", "growth, 2nd half (MB / 1000 frames)", "{:.2f}"),
            ("finished", "frames finished", "{}"), ("lat_first", "latency p50, first 1000 finished (ms)", "{:.0f}"),
            ("lat_last", "p50, last 1000 (ms)", "{:.0f}"), ("lat_first95", "p95 first (ms)", "{:.0f}"),
            ("lat_last95", "p95 last (ms)", "{:.0f}"),
            ("cycle_lo", "p50 per cycle after the 2nd: lowest (ms)", "{:.0f}"), ("cycle_hi", "highest (ms)", "{:.0f}"),
            ("trend", "trend of the cycles' p50 (ms / 1000 frames)", "{:+.1f}"), ("trend_se", "its std err", "{:.1f}"),
            ("cpu_early", f"CPU per frame, frames {SETTLE_CYCLES * int(r.get('cycle', 478))}+ (1000; ms)", "{:.1f}"),
            ("cpu_late", "CPU per frame, last 1000 (ms)", "{:.1f}")]
    st = r["stats"]

    def plot(plt):
        has_cpu = bool(r.get("cpu"))
        fig, ax = plt.subplots(1, 3 if has_cpu else 2, figsize=(16 if has_cpu else 11, 3.8))
        for name in sorted({x[1] for x in r["rss"]}):
            pts = np.array([(k, v) for k, nm, v in r["rss"] if nm == name])
            ax[0].plot(pts[:, 0], pts[:, 1], label=name)
        ax[0].set_xlabel("frames published")
        ax[0].set_ylabel("RSS (MB)")
        ax[0].legend(fontsize=7)
        for name, v in sorted(r["latency_ms"].items()):
            v = np.asarray(v)
            if len(v) > 50:
                w = 50
                ax[1].plot(np.convolve(v, np.ones(w) / w, mode="valid"), label=name, lw=0.8)
        ax[1].set_xlabel("frames finished (in order)")
        ax[1].set_ylabel("latency from publication (ms, mean of 50)")
        ax[1].legend(fontsize=7)
        if has_cpu:
            for name in sorted({x[1] for x in r["cpu"]}):
                c = cpu_per_frame(r["cpu"], name, 500.0)
                if len(c):
                    ax[2].plot(c[:, 0], c[:, 1], label=name, marker=".")
            ax[2].set_xlabel("frames published")
            ax[2].set_ylabel("CPU per frame published (ms, over ~500 frames)")
            ax[2].legend(fontsize=7)
        fig.tight_layout()
        return fig

    knobs = [(f"{n}.{k}", json.dumps(v)) for n, kv in sorted(r.get("params", {}).items())
             for k, v in sorted(kv.items())]
    save(a.out, rows, cols, f"Soak: {r['frames']} frames of RGB-D SLAM -> tracker -> overlay, live"
         + (f" ({', '.join(f'{k}: {v}' for k, v in knobs)})" if knobs else ""),
         f"`python -m benchmarks.soak --frames {r['frames']}" + "".join(f" --param {k}={v}" for k, v in knobs)
         + (f" --out {a.out}" if a.out != "soak" else "") + "` (see its docstring): the joint boot sample played "
         f"forward and backward at {r['fps']:.0f} fps, live. Frames published {st['frames_published']}, finished "
         f"by every node {st['frames_completed']} ({st.get('fps_through', float('nan')):.1f} fps through), the rest "
         f"skipped as live load shedding. Node exits during the run: {len(r.get('exits', [])) or 'none'}. RSS "
         "and CPU (user + system, of each node process) sampled every 2 s; latency from the player's publication "
         "to each node's report. Cycle: "
         f"{int(r.get('cycle', 478))} frames finished, one forward-and-back pass of the sample; the cycles' range "
         f"and trend leave out the first {SETTLE_CYCLES} (most of the map is made on them). The launcher's standby "
         "processes (the live default) are not in the RSS columns.", plot, extra={"run": r, **kept})


if __name__ == "__main__":
    main()
