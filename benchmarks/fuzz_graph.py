"""Hostile messages into the live node graph (issue 20): a fuzzing publisher on every topic the graph's nodes
subscribe to, and what the nodes make of it.

    ./run bench fuzz_graph                                  # 25 000 messages into each of four graphs
    python -m benchmarks.fuzz_graph --messages 2000 --seed 1 --graphs rgbd
    python -m benchmarks.fuzz_graph --messages 20000 --graphs rgbd --memory-detail --name fuzz_graph_rgbd_20k_memory

Graphs (each from a scene file and a short bag made here, launched as `simreal launch` would, with **no respawn**
and no standby, so that a node that dies stays dead and is counted):

- ``rgbd``: a family scene (seed 3, 320x240 RGB-D): ingest -> RGB-D SLAM -> tracker (dense, reads depth, registers
  the beam) -> overlay;
- ``stereo``: the same draw through a stereo pair (right image and CameraInfo, SGBM in the tracker);
- ``probe``: the crossed beams pushed by a probe seen in depth (the collision node);
- ``markers``: the aluminium beam demo (JPEG ``CompressedImage`` input, marker localization).

The fuzzer finds the topics from the running graph (every subscription of a simreal node, camera inputs and the
nodes' own topics between them: anyone on the DDS domain can publish there). Valid templates: the bag's camera
messages and, for the topics between nodes, messages captured from the graph while the bag's frames went through
it once. Each hostile message is case ``i`` of ``numpy.random.default_rng([seed, graph, i])``: a template with one
field set to a hostile value of its type (numbers at their bounds, NaN / inf, empty / huge / mismatched arrays,
strings of other encodings), an image whose encoding, size, step and payload disagree or whose float depth holds
NaN, inf, negative values, a CameraInfo with zero / NaN / mismatched intrinsics, a stamp that is zero, jumps back,
repeats or lies far ahead, or a message of that type filled at random. A valid frame follows every
``--valid-every`` hostile ones, so the nodes are fuzzed in the states real frames put them in.

Counted per graph and node: **exits** (a crash: target 0), **unexpected exceptions** (caught by the nodes' guard,
reported as ``TypeName: message``: each one is an input that should have met a clear rejection), **rejections**
(frames dropped with a reason, each distinct reason listed), and at the end **hangs**: after the fuzz, valid frames
must still come out of every node (its progress reports). Node memory (RSS) before and after the fuzz.
"""

from __future__ import annotations

import argparse
import array
import contextlib
import math
import re
import tempfile
import time
from collections import Counter, defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks import memprobe
from benchmarks.common import RESULTS, save

GRAPHS = ("rgbd", "stereo", "probe", "markers")
ENCODINGS = ("rgb8", "bgr8", "mono8", "mono16", "16UC1", "32FC1", "64FC1", "bgra8", "rgba8", "8UC3", "8UC1",
             "yuv422", "bayer_rggb8", "16SC1", "32SC1", "", "garbage", "jpeg", "BGR8", "8UC4", "16UC3")
STRINGS = ("", "x" * 10000, "\x01\x7f", "é✓ unicode", "../../etc/passwd", "mono16", "32FC1", "plumb_bob",
           "rational_polynomial", "equidistant", "map", "camera_optical_frame", "%s%n", "nan")
# the guard's "TypeName: message" (OpenCV's exception type is the lowercase cv2.error)
UNEXPECTED = re.compile(r"^([A-Z]\w*(Error|Exception|Warning)|error)\b")
MAX_ITEMS = 300_000  # the longest array a mutation makes (a few MB on the wire)


# ---------------------------------------------------------------------------------------------------------------
# hostile values, by field type

def _bounds(base: str) -> tuple[int, int] | None:
    m = re.fullmatch(r"(u?)int(8|16|32|64)", base)
    if m:
        bits = int(m.group(2))
        return (0, 2 ** bits - 1) if m.group(1) else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return {"byte": (0, 255), "char": (0, 255), "octet": (0, 255)}.get(base)


def _hostile_scalar(base: str, rng: np.random.Generator):
    if base == "boolean":
        return bool(rng.integers(2))
    if base in ("float", "double", "float32", "float64"):
        big = 3.0e38 if base in ("float", "float32") else 1e300
        return float(rng.choice([math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 1e-30, big, -big,
                                 float(rng.normal() * 10.0 ** rng.integers(-6, 9))]))
    if base in ("string", "wstring"):
        return str(rng.choice(STRINGS))
    lo, hi = _bounds(base) or (0, 255)
    return int(rng.choice([lo, hi, 0, 1, int(rng.integers(lo, hi, endpoint=True, dtype=np.int64)
                                             if hi - lo < 2 ** 63 else rng.integers(0, 2 ** 62))]))


def _numeric_array(base: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if base in ("float", "double", "float32", "float64"):
        x = rng.normal(size=n) * 10.0 ** float(rng.integers(-3, 6))
        bad = rng.random(n) < rng.choice([0.0, 0.1, 1.0])
        x[bad] = rng.choice([math.nan, math.inf, -math.inf, -1.0], size=int(bad.sum()))
        return x
    if base == "boolean":
        return rng.integers(0, 2, n).astype(bool)
    lo, hi = _bounds(base) or (0, 255)
    hi = min(hi, 2 ** 62)
    return rng.integers(lo, hi, size=n, endpoint=True, dtype=np.int64)


TYPECODES = {"float": "f", "double": "d", "float32": "f", "float64": "d", "int8": "b", "uint8": "B", "int16": "h",
             "uint16": "H", "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q", "byte": "B", "octet": "B",
             "char": "B"}


def _set_sequence(msg, name: str, base: str, values: np.ndarray) -> None:
    if base == "boolean":
        setattr(msg, name, [bool(v) for v in values])
    elif base in ("string", "wstring"):
        setattr(msg, name, [str(v) for v in values])
    else:
        code = TYPECODES[base]
        a = array.array(code)
        a.frombytes(np.asarray(values).astype(np.dtype(code)).tobytes())
        setattr(msg, name, a)


def _parse(ftype: str) -> tuple[str, str, int | None]:
    """('scalar' | 'array' | 'sequence', base type, length or bound)."""
    m = re.fullmatch(r"sequence<([^,>]+)(?:, (\d+))?>", ftype)
    if m:
        return "sequence", m.group(1), int(m.group(2)) if m.group(2) else None
    m = re.fullmatch(r"(.+)\[(\d+)\]", ftype)
    if m:
        return "array", m.group(1), int(m.group(2))
    m = re.fullmatch(r"(string|wstring)<(\d+)>", ftype)
    if m:
        return "scalar", m.group(1), int(m.group(2))
    return "scalar", ftype, None


def _is_message(base: str) -> bool:
    return "/" in base


def _message_class(base: str):
    from simreal_nodes.ros.bagplay import message_class

    return message_class(base)


def _leaves(msg, prefix: tuple = ()) -> list[tuple[tuple, object, str, str]]:
    """Every field of ``msg`` as (path, parent message, field name, type string), nested messages included."""
    out = []
    for name, ftype in msg.get_fields_and_field_types().items():
        kind, base, _ = _parse(ftype)
        out.append((prefix + (name,), msg, name, ftype))
        if kind == "scalar" and _is_message(base):
            out += _leaves(getattr(msg, name), prefix + (name,))
    return out


def mutate_field(msg, rng: np.random.Generator) -> str:
    """Set one field of ``msg`` (any depth) to a hostile value of its type; returns what was done."""
    path, parent, name, ftype = _leaves(msg)[int(rng.integers(len(_leaves(msg))))]
    kind, base, n = _parse(ftype)
    where = ".".join(path)
    if kind == "scalar" and _is_message(base):
        setattr(parent, name, random_message(_message_class(base), rng))
        return f"{where}: random"
    if kind == "scalar":
        v = _hostile_scalar(base, rng)
        if n is not None and isinstance(v, str):
            v = v[:n]
        setattr(parent, name, v)
        return f"{where} = {str(v)[:20]!r}"
    old = getattr(parent, name)
    if kind == "array":
        if _is_message(base) or base in ("string", "wstring"):
            return f"{where}: unchanged"
        vals = _numeric_array(base, n or 0, rng)
        setattr(parent, name, np.asarray(vals).astype(np.asarray(old).dtype))
        return f"{where}: hostile values"
    length = len(old)
    m = int(rng.choice([0, 1, max(length - 1, 0), length + 1, 2 * length + 3, int(rng.integers(0, 5000))]))
    m = min(m, MAX_ITEMS, n if n is not None else MAX_ITEMS)
    if _is_message(base):
        cls = _message_class(base)
        m = min(m, 2000)
        setattr(parent, name, [random_message(cls, rng) if rng.random() < 0.3 else cls() for _ in range(m)])
        return f"{where}: {m} items"
    if base in ("string", "wstring"):
        _set_sequence(parent, name, base, np.array([rng.choice(STRINGS) for _ in range(min(m, 100))]))
        return f"{where}: {min(m, 100)} strings"
    _set_sequence(parent, name, base, _numeric_array(base, m, rng))
    return f"{where}: {m} items"


def random_message(cls, rng: np.random.Generator, depth: int = 0):
    """A message of ``cls`` with each field drawn at random (nested messages too, two levels deep)."""
    msg = cls()
    for name, ftype in msg.get_fields_and_field_types().items():
        kind, base, n = _parse(ftype)
        if _is_message(base):
            if kind == "scalar" and depth < 2:
                setattr(msg, name, random_message(_message_class(base), rng, depth + 1))
            elif kind == "sequence" and depth < 2:
                setattr(msg, name, [random_message(_message_class(base), rng, depth + 1)
                                    for _ in range(int(rng.integers(0, 4)))])
            continue
        if kind == "scalar":
            v = _hostile_scalar(base, rng)
            setattr(msg, name, v[:n] if n is not None and isinstance(v, str) else v)
        elif kind == "array":
            if base not in ("string", "wstring"):
                setattr(msg, name, np.asarray(_numeric_array(base, n or 0, rng)).astype(getattr(msg, name).dtype))
        else:
            m = min(int(rng.integers(0, 64)), n if n is not None else 64)
            vals = np.array([rng.choice(STRINGS) for _ in range(m)]) if base in ("string", "wstring") \
                else _numeric_array(base, m, rng)
            _set_sequence(msg, name, base, vals)
    return msg


def hostile_image(msg, rng: np.random.Generator) -> str:
    """An Image whose encoding, size, step and payload disagree, or whose payload holds hostile values."""
    enc = str(rng.choice(ENCODINGS)) if rng.random() < 0.6 else msg.encoding
    w = int(rng.choice([0, 1, 7, msg.width, msg.width + 1, 2 * msg.width, 4000]))
    h = int(rng.choice([0, 1, 5, msg.height, msg.height - 1, 2 * msg.height, 3000]))
    bpp = {"32FC1": 4, "16UC1": 2, "mono16": 2, "rgb8": 3, "bgr8": 3, "8UC3": 3, "bgra8": 4, "rgba8": 4,
           "64FC1": 8, "16SC1": 2, "32SC1": 4, "8UC4": 4, "16UC3": 6}.get(enc, 1)
    step = int(rng.choice([w * bpp, w * bpp + 1, 0, max(w * bpp - 1, 0), 2 ** 32 - 1]))
    n = h * step if step < 2 ** 31 else 0
    n = int(rng.choice([n, max(n - 1, 0), n + 7, 0, int(rng.integers(0, 64))]))
    n = max(min(n, 12_000_000), 0)  # a 2000x2000 colour image at most
    if enc in ("32FC1", "64FC1") and rng.random() < 0.7:
        dt = np.float32 if enc == "32FC1" else np.float64
        vals = rng.choice(np.array([math.nan, math.inf, -math.inf, -1.0, 0.0, 1e30, 0.5, 1.0, 2.0]), n // bpp + 1)
        payload = vals.astype(dt).tobytes()[:n]
    else:
        payload = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
    msg.encoding, msg.width, msg.height, msg.step = enc, w, h, step
    msg.is_bigendian = int(rng.choice([0, 0, 1, 255]))
    msg.data = payload
    return f"image {enc!r} {w}x{h} step {step}, {n} bytes"


def hostile_float_depth(msg, rng: np.random.Generator) -> str:
    """A well-formed depth image (the template's size) full of NaN, inf, negative or absurd values."""
    w, h = msg.width, msg.height
    vals = np.array([math.nan, math.inf, -math.inf, -1.0, 0.0, 1e30, 1e-30, 0.8, 1.2])
    p = rng.dirichlet(np.ones(len(vals)) * 0.3)
    d = rng.choice(vals, size=(h, w), p=p).astype(np.float32)
    msg.encoding, msg.step, msg.is_bigendian = "32FC1", 4 * w, 0
    msg.data = d.tobytes()
    return "depth 32FC1: " + ", ".join(f"{v:g} {q:.0%}" for v, q in zip(vals, p, strict=True) if q > 0.05)


def hostile_compressed(msg, rng: np.random.Generator) -> str:
    data = bytes(msg.data)
    how = int(rng.integers(4))
    if how == 0:
        msg.data = data[: int(rng.integers(0, max(len(data), 1)))]
    elif how == 1:
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 20))):
            if b:
                b[int(rng.integers(len(b)))] = int(rng.integers(256))
        msg.data = bytes(b)
    elif how == 2:
        msg.data = rng.integers(0, 256, int(rng.integers(0, 100000)), dtype=np.uint8).tobytes()
    msg.format = str(rng.choice(["jpeg", "png", "", "rgb8; jpeg compressed bgr8", "16UC1; compressedDepth",
                                 "garbage", msg.format]))
    return f"compressed {('truncated', 'bytes flipped', 'random bytes', 'format')[how]} format {msg.format!r}"


def hostile_stamp(msg, last_ns: int, rng: np.random.Generator) -> str:
    st = msg.header.stamp
    how = int(rng.integers(4))
    ns = (0, max(last_ns - 10 ** 10, 0), last_ns, 2 ** 31 * 10 ** 9 - 1)[how]
    st.sec, st.nanosec = ns // 10 ** 9, ns % 10 ** 9
    return f"stamp {('zero', 'back 10 s', 'repeated', 'far ahead')[how]}"


def make_message(cls, template, rng: np.random.Generator, stamp_ns: int, last_ns: int):
    """One hostile message of ``cls`` from ``template`` (None: random); returns (message, description)."""
    from rclpy.serialization import deserialize_message, serialize_message

    if template is None or rng.random() < 0.1:
        msg, what = random_message(cls, rng), "random"
    else:
        msg = deserialize_message(serialize_message(template), cls)
        name = cls.__name__
        r = rng.random()
        if name == "Image" and r < 0.45:
            what = hostile_float_depth(msg, rng) if template.encoding in ("32FC1", "16UC1") and r < 0.2 \
                else hostile_image(msg, rng)
        elif name == "CompressedImage" and r < 0.5:
            what = hostile_compressed(msg, rng)
        else:
            what = "; ".join(mutate_field(msg, rng) for _ in range(int(rng.integers(1, 3))))
    if hasattr(msg, "header"):
        if rng.random() < 0.15:
            what += "; " + hostile_stamp(msg, last_ns, rng)
        elif "stamp" not in what and "header" not in what:
            msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_ns // 10 ** 9, stamp_ns % 10 ** 9
    return msg, what


# ---------------------------------------------------------------------------------------------------------------
# the graphs

def prepare(graph: str, d: Path) -> tuple[Path, Path]:
    """(bag, scene file) of one graph."""
    from simreal_nodes.cli import main as cli
    from simreal_nodes.synth.samples import render_sample, sample

    if graph in ("rgbd", "stereo"):
        extra = ["--sensor", "stereo"] if graph == "stereo" else []
        assert cli(["make-bag", "family", "--seed", "3", *extra, "-o", str(d / graph), "--resolution", "320x240",
                    "--duration", "1.4", "--fps", "15", "--ssaa", "1", "--scene-out", str(d / f"{graph}.yaml"),
                    "-q"]) == 0
        return d / graph, d / f"{graph}.yaml"
    name = {"probe": "crossed_beams_probe_320x240", "markers": "aluminium_beam_320x240"}[graph]
    bag, scene = sample(name)
    if not bag.is_dir():
        render_sample(name, d)
        bag, scene = d / name, d / f"{name}.yaml"
    return bag, scene


def fuzz_graph(graph: str, n_messages: int, seed: int, work: Path, valid_every: int = 50, rate_hz: float = 600.0,
               echo=print, memory_detail: bool = False) -> dict:
    """Launch one graph, fuzz every topic its nodes subscribe to, and account for what happened; with
    ``memory_detail`` the nodes run under the memory probe (``benchmarks/memprobe``: tracemalloc in every node, slower)
    and each RSS sample also splits the nodes' memory into Python's and the C allocator's."""
    import psutil
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Header

    from simreal_nodes.io import bags
    from simreal_nodes.launch import Launcher
    from simreal_nodes.ros.bagplay import message_class
    from simreal_nodes.ros.commands import _share_node_environment
    from simreal_nodes.ros.node import parse_progress
    from simreal_nodes.ros.qos import reliable_qos
    from simreal_nodes.scene.graph import required_nodes
    from simreal_nodes.scene.schema import build_spec_models, load_scene

    bag, scene_file = prepare(graph, work)
    scene = build_spec_models(load_scene(scene_file))
    nodes = required_nodes(scene)
    names = [n.name for n in nodes]
    lines: list[str] = []
    launcher = Launcher(nodes, respawn=0, standby=False, echo=lines.append, log_dir=work / f"log-{graph}")
    probe_dir = work / f"mem-{graph}"
    if memory_detail:
        probe_dir.mkdir()
        launcher.env = memprobe.probe_env(launcher.env, probe_dir)
    by_stamp: dict[int, dict[str, bytes]] = defaultdict(dict)  # the bag's messages (raw CDR) per header stamp
    for m in bags.read_bag(bag):
        header = getattr(deserialize_message(m.raw, message_class(m.msgtype)), "header", None)
        if header is not None:
            by_stamp[header.stamp.sec * 10 ** 9 + header.stamp.nanosec][m.topic] = m.raw
    frames = [by_stamp[k] for k in sorted(by_stamp)]

    _share_node_environment()
    rclpy.init()
    node = rclpy.create_node("simreal_fuzzer")
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    reports: dict[str, Counter] = defaultdict(Counter)  # node -> why -> count ('' = done)
    node.create_subscription(Header, "/simreal/progress", lambda h: reports[parse_progress(h.frame_id)[0]].update(
        [parse_progress(h.frame_id)[2]]), reliable_qos(1000))
    out: dict = {"graph": graph, "nodes": names}
    try:
        launcher.start()
        spin_until(ex, lambda: set(names) <= set(node.get_node_names()), 90)
        spin_for(ex, 3.0)
        inputs = subscribed_topics(node, names)
        templates: dict[str, object] = {}
        capturing = True  # the graph's own messages become templates until the fuzz starts (not the fuzz's)
        pubs, classes = {}, {}
        for topic, (ty, qos) in inputs.items():
            classes[topic] = message_class(ty)
            pubs[topic] = node.create_publisher(classes[topic], topic, qos)
            if not topic.startswith("/simreal/"):
                continue
            node.create_subscription(classes[topic], topic,
                                     lambda m, t=topic: templates.__setitem__(t, m) if capturing else None, qos)
        spin_for(ex, 2.0)
        # the bag once through the graph, live: the nodes' own messages become templates
        stamp = [int(time.time() * 1e9)]

        def valid_frame() -> None:
            f = frames[valid_frame.k % len(frames)]
            valid_frame.k += 1
            stamp[0] += 66_666_667
            for topic, raw in f.items():
                if topic not in pubs:
                    continue
                msg = deserialize_message(raw, classes[topic])
                if hasattr(msg, "header"):
                    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp[0] // 10 ** 9, stamp[0] % 10 ** 9
                templates.setdefault(topic, msg)
                pubs[topic].publish(msg)
        valid_frame.k = 0
        for _ in range(len(frames)):
            valid_frame()
            spin_for(ex, 1 / 15)
        spin_for(ex, 2.0)
        capturing = False
        rss0 = node_rss(launcher, psutil)
        rss_series: list[tuple[int, dict[str, float]]] = [(0, rss0)]
        mem_series: list[tuple[int, dict[str, dict]]] = []
        if memory_detail:
            mem_series.append((0, memory_probe(launcher, probe_dir, lambda: spin_for(ex, 1.0))))
        done0 = {n: reports[n][""] for n in names}
        topics = sorted(pubs)
        sent: Counter = Counter()
        kinds: Counter = Counter()
        t0 = time.monotonic()
        for i in range(n_messages):
            rng = np.random.default_rng([seed, GRAPHS.index(graph), i])
            topic = topics[int(rng.integers(len(topics)))]
            stamp[0] += 1_000_000
            try:
                msg, what = make_message(classes[topic], templates.get(topic), rng, stamp[0], stamp[0] - 10 ** 9)
            except (AssertionError, ValueError, TypeError, OverflowError) as e:
                kinds["not made (the message type refused the value)"] += 1
                echo(f"[fuzz] case {i} on {topic}: not made: {type(e).__name__}: {e}")
                continue
            try:
                pubs[topic].publish(msg)
            except (SystemError, ValueError, TypeError) as e:  # rclpy's conversion refused it: nothing went out
                kinds["not sent (rclpy refused the message)"] += 1
                echo(f"[fuzz] case {i} on {topic}: not sent: {type(e).__name__}: {e}")
                continue
            sent[topic] += 1
            kinds[what.split(":")[0].split(" ")[0]] += 1
            if (i + 1) % valid_every == 0:
                valid_frame()
            ex.spin_once(timeout_sec=0)
            lag = (i + 1) / rate_hz - (time.monotonic() - t0)
            if lag > 0:
                spin_for(ex, lag)
            if (i + 1) % max(n_messages // 5, 1) == 0:
                rss_series.append((i + 1, node_rss(launcher, psutil)))
                if memory_detail:
                    mem_series.append((i + 1, memory_probe(launcher, probe_dir, lambda: spin_for(ex, 1.0))))
                echo(f"[fuzz] {graph}: {i + 1}/{n_messages}; alive: {launcher.alive()}")
        fuzz_s = time.monotonic() - t0
        spin_for(ex, 3.0)
        # hangs: valid frames must still come out of every node
        before = {n: reports[n][""] for n in names}
        for _ in range(3 * len(frames)):
            valid_frame()
            spin_for(ex, 1 / 15)
        spin_for(ex, 3.0)
        alive = launcher.alive()
        rss1 = node_rss(launcher, psutil)
        out.update(fuzz_s=fuzz_s, sent=dict(sent), kinds=dict(kinds), topics=topics, rss_series=rss_series)
        if memory_detail:
            out["mem_series"] = mem_series
        out["per_node"] = {}
        for n in names:
            why = reports[n]
            unexpected = {w: c for w, c in why.items() if w and UNEXPECTED.match(w)}
            rejected = {w: c for w, c in why.items() if w and not UNEXPECTED.match(w)}
            out["per_node"][n] = {
                "alive": alive.get(n, False), "exit_codes": next(p.exit_codes for p in launcher.procs
                                                                 if p.spec.name == n),
                "done_during_fuzz": before[n] - done0[n], "done_after_fuzz": reports[n][""] - before[n],
                "unexpected": unexpected, "rejected": rejected,
                "rss_mb_before": rss0.get(n, math.nan), "rss_mb_after": rss1.get(n, math.nan)}
    finally:
        launcher.stop()
        node.destroy_node()
        rclpy.shutdown()
    out["log_tail"] = error_lines(lines)[-40:]
    return out


def error_lines(lines: list[str]) -> list[str]:
    """The log's error lines with each traceback whole (the frames a node's guard logs between its first and last
    line)."""
    keep, in_tb = [], False
    for x in lines:
        if "Traceback" in x:
            in_tb = True
        if in_tb or "Error" in x:
            keep.append(x)
        if in_tb and "Traceback" not in x and not x.split("] ", 1)[-1].startswith(" "):
            in_tb = False  # the exception's own line ends it
    return keep


def spin_for(ex, seconds: float) -> None:
    t_end = time.monotonic() + seconds
    while (left := t_end - time.monotonic()) > 0:
        ex.spin_once(timeout_sec=min(left, 0.05))


def spin_until(ex, cond, timeout: float) -> None:
    t_end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > t_end:
            raise RuntimeError("the graph did not come up")
        ex.spin_once(timeout_sec=0.1)


def subscribed_topics(node, names: list[str]) -> dict[str, tuple[str, object]]:
    """topic -> (type, a QoS the subscriber matches) of every subscription of the graph's nodes."""
    from rclpy.qos import HistoryPolicy, QoSProfile

    out = {}
    for topic, _types in node.get_topic_names_and_types():
        for info in node.get_subscriptions_info_by_topic(topic):
            if info.node_name in names and topic not in ("/parameter_events",):
                q = info.qos_profile
                out[topic] = (info.topic_type, QoSProfile(depth=10, reliability=q.reliability,
                                                          durability=q.durability, history=HistoryPolicy.KEEP_LAST))
    return out


def memory_probe(launcher, probe_dir: Path, wait: Callable[[], None]) -> dict[str, dict]:
    """Each live node's memory as the probe in it reports it (``benchmarks/memprobe/sitecustomize.py``): SIGUSR1 to
    the nodes whose probe said it is in place, ``wait()`` (the fuzzer spins meanwhile), then each one's newest line.
    A node that did not answer in time is left out."""
    asked = {}
    for p in launcher.procs:
        if p.popen is not None and p.popen.poll() is None and memprobe.ready(p.popen.pid, probe_dir):
            with contextlib.suppress(ProcessLookupError):
                memprobe.ask(p.popen.pid)
                asked[p.spec.name] = p.popen.pid
    wait()
    out = {}
    for name, pid in asked.items():
        rec = memprobe.latest(pid, probe_dir)
        if rec.get("event") == "probe":
            out[name] = rec
    return out


def node_rss(launcher, psutil) -> dict[str, float]:
    out = {}
    for p in launcher.procs:
        if p.popen is not None and p.popen.poll() is None:
            with contextlib.suppress(psutil.Error):
                out[p.spec.name] = psutil.Process(p.popen.pid).memory_info().rss / 2 ** 20
    return out


def memory_cell(series: list, node: str) -> str:
    """The probe's first and last reading of ``node``: Python's allocations (tracemalloc), the C allocator's bytes in
    use (Python's numpy buffers among them) and its free bytes, in MB."""
    recs = [m[node] for _, m in series if node in m]
    if not recs:
        return ""

    def one(r: dict) -> str:
        return (f"{r['python_mb']:.0f} / {r.get('malloc_in_use_mb', math.nan):.0f} / "
                f"{r.get('malloc_free_mb', math.nan):.0f}")

    return f"{one(recs[0])} -> {one(recs[-1])}"


def main() -> None:
    import json

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--messages", type=int, default=25_000, help="hostile messages per graph")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--graphs", default=",".join(GRAPHS), help=f"comma-separated, of {', '.join(GRAPHS)}")
    ap.add_argument("--report", action="store_true", help="rewrite table and plot from the results JSON")
    ap.add_argument("--memory-detail", action="store_true",
                    help="the nodes under the memory probe (benchmarks/memprobe): Python's and the C allocator's share")
    ap.add_argument("--name", default="fuzz_graph",
                    help="results name (benchmarks/results/NAME.md): a longer run beside the default one")
    a = ap.parse_args()
    if a.report:
        runs = json.loads((RESULTS / f"{a.name}.json").read_text())["runs"]
    else:
        runs = []
        with tempfile.TemporaryDirectory() as d:
            for g in a.graphs.split(","):
                r = fuzz_graph(g, a.messages, a.seed, Path(d), memory_detail=a.memory_detail)
                r["messages"] = a.messages
                runs.append(r)
                print(json.dumps({k: v for k, v in r.items() if k != "log_tail"})[:3000], flush=True)
    rows = []
    for r in runs:
        for n, s in r["per_node"].items():
            rows.append({"graph": r["graph"], "node": n, "inputs": sum(r["sent"].values()),
                         "exits": len(s["exit_codes"]),
                         "unexpected": sum(s["unexpected"].values()), "rejected": sum(s["rejected"].values()),
                         "reasons": len(s["rejected"]), "done_during": s["done_during_fuzz"],
                         "hang": "no" if s["done_after_fuzz"] > 0 else "YES",
                         "rss": " -> ".join(f"{x.get(n, math.nan):.0f}" for _, x in r.get("rss_series", []))
                         or f"{s['rss_mb_before']:.0f} -> {s['rss_mb_after']:.0f}",
                         "memory": memory_cell(r.get("mem_series", []), n)})
    cols = [("graph", "graph", "{}"), ("node", "node", "{}"), ("inputs", "hostile messages into the graph", "{}"),
            ("exits", "node exits (crashes)", "{}"), ("unexpected", "unexpected exceptions (caught)", "{}"),
            ("rejected", "frames rejected with a reason", "{}"), ("reasons", "distinct reasons", "{}"),
            ("done_during", "frames finished during the fuzz", "{}"),
            ("hang", "hang (no valid frame out after)", "{}"),
            ("rss", "RSS MB: before, then after each fifth of the messages", "{}")]
    if any(r.get("mem_series") for r in runs):
        cols.append(("memory", "MB before -> after (--memory-detail): Python's / C allocator's in use / its free",
                     "{}"))
    lines = []
    for r in runs:
        lines.append(f"\n**{r['graph']}** ({', '.join(r['nodes'])}): {sum(r['sent'].values())} messages in "
                     f"{r['fuzz_s']:.0f} s on " + ", ".join(f"`{t}` {c}" for t, c in sorted(r["sent"].items())))
        for n, s in r["per_node"].items():
            for w, c in sorted(s["unexpected"].items(), key=lambda x: -x[1]):
                lines.append(f"- {n}, unexpected ({c}x): `{w[:200]}`")
            for w, c in sorted(s["rejected"].items(), key=lambda x: -x[1])[:12]:
                lines.append(f"- {n}, rejected ({c}x): {w[:200]}")
    n_msg = runs[0].get("messages", a.messages) if runs else a.messages
    detail = any(r.get("mem_series") for r in runs)
    args = "" if a.name == "fuzz_graph" else \
        f" --messages {n_msg} --graphs {','.join(r['graph'] for r in runs)}" + (" --memory-detail" if detail else "") \
        + f" --name {a.name}"
    memory_note = (" The last column (`--memory-detail`): each node under the memory probe of `benchmarks/memprobe` "
                   "(tracemalloc in the node, which slows it), before the fuzz and after it: what Python holds "
                   "(numpy's buffers included), what glibc's allocator has handed out and not had back (Python's "
                   "buffers among it), and what it holds free in its arenas. In use less Python is at least what "
                   "native code holds (the DDS, rclpy's C layer, OpenCV)." if detail else "")
    save(a.name, rows, cols, "Hostile messages into the live node graph",
         f"`python -m benchmarks.fuzz_graph{args}` (see its docstring): per graph, seeded hostile messages on every "
         "topic "
         "its nodes subscribe to, a valid frame after every 50; the nodes run without respawn, so an exit stays "
         "counted. The count is of messages published (at 600 a second); a node busy with one takes the newest "
         "next, so not every message reaches its callback: the frames rejected and finished are what the nodes "
         "handled. 'unexpected': an exception the node's guard caught (an input that should have met a clear "
         "rejection); 'hang': no valid frame finished by the node after the fuzz. The rejections' reasons, most "
         "frequent first (12 per node at most):" + memory_note + "\n" + "\n".join(lines), None, extra={"runs": runs})


if __name__ == "__main__":
    main()
