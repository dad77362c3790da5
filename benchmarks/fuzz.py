"""Hostile input to the model-file, scene and bag loaders (issue 20): seeded random mutations of valid files, and
what each loader makes of them.

    ./run bench fuzz                                   # 50 000 model files, 50 000 scenes, 20 000 bags
    python -m benchmarks.fuzz --cases 2000 --seed 1    # fewer, another draw

Seeds: a small model built by the real builder (``beam_pgd``, written by ``save_model``) and the committed sample
scenes plus one scene that names that model file. Mutations: byte-level (bit flips, overwritten runs, zeroed blocks,
truncation; scene text also gets YAML punctuation, deleted and repeated lines) and structural (an HDF5 object
deleted, re-shaped, re-typed, turned into a group, filled with NaN / inf / absurd values, declared absurdly large;
a scene node deleted, renamed, or given a value of another type; a bag's message type renamed to one no type
store knows). The bag seed is the first messages of a committed sample (JPEG images, CameraInfo, truth poses and
simreal parameters), a folder with its mcap file and metadata.yaml; either file is mutated. Every input is case
``i`` of a target drawn from ``numpy.random.default_rng([seed, target, i])``, so any one is reproduced alone
(:func:`make_input`).

Model files carry the SHA-256 of their contents in a user block (``rom/model_file.py``): structural mutations are
re-stamped (a writer's bug, consistent with its checksum: the loader's validation is tested), byte mutations are
not (corruption after writing: the checksum refuses them before libhdf5 reads a byte).

Per input the loader (``read_header`` then ``load_model``; ``load_scene``; ``read_bag`` and ``decode`` of every
message) either accepts it (a bag: or reads it with the damage reported), rejects it with the
project's own error (:class:`~simreal_nodes.errors.SimrealError`: one line meant for a user) or crashes (any other
exception: a traceback), or hangs (over ``--hang-s``). Cases run in worker processes with a 4 GiB address-space
limit, so a file that declares an absurd size ends as a MemoryError (a crash: the size was not checked before
allocating) instead of exhausting the machine. Messages are counted as distinct after the file name and numbers are
blanked.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
TARGETS = ("model", "scene", "bag")
MEMORY_LIMIT = 4 << 30
BAG_MESSAGES = 24  # the bag seed: this many messages of the aluminium beam sample (4 frames)
TINY_SPEC = """
simreal_model_spec: 1
name: fuzz_beam
kind: beam_pgd
material: {law: linear_elastic, E: 69.0e9, nu: 0.334}
geometry: {length: 0.2, width: 0.02, height: 0.01}
mesh: {cells: [4, 1, 1], element: hex, order: 1}
supports:
  - {region: xmin, kind: clamped}
load: {force: 10.0, direction: [0, 0, -1], where: centreline, x_range: [0.0, 0.2]}
pgd: {max_modes: 3, tol: 1.0e-6}
"""
ODD_VALUES = [None, True, False, 0, -1, 1, 2**31, 10**30, -1e308, 1e308, float("nan"), float("inf"), "", "x" * 500,
              "spec:", "../../etc/passwd", "\x00", "üñí", [], {}, [0], [None], [1.0, 2.0], {"a": 1}, [[1, 2], [3]]]
YAML_CHARS = list(":-[]{}#&*!|>'\"%@`,? \n\t\\") + ["\n  ", ": ", "- ", "...", "---", "~", "0x", "1e9999", ".nan"]


# ------------------------------------------------------------------------------------------------
# Seeds
def seeds(workdir: Path) -> dict[str, list[tuple[str, bytes]]]:
    """The valid inputs every mutation starts from: (name, content) per target (built once into ``workdir``)."""
    from simreal_nodes.rom.build import build_model, load_spec
    from simreal_nodes.rom.model_file import save_model
    from simreal_nodes.synth.samples import sample

    model = workdir / "seed_model.h5"
    if not model.exists():
        spec = workdir / "fuzz_beam.yaml"
        spec.write_text(TINY_SPEC)
        save_model(build_model(load_spec(spec)), model)
    scenes = []
    for name in ("aluminium_beam_320x240", "crossed_beams_probe_320x240"):
        _bag, scene = sample(name)
        scenes.append((name, scene.read_bytes()))
    own = {"simreal_scene": 1, "name": "fuzz", "camera": {"depth": "/camera/depth/image_raw"},
           "localization": {"mode": "rgbd"},
           "objects": [{"id": "beam", "model": str(model), "anchor": {"kind": "pose", "pose": [0, 0, 0.5, 0, 0, 0, 1]},
                        "parameters": {"s": {"mode": "tracked"}},
                        "collision": {"enabled": True, "threshold_m": 0.005}}]}
    scenes.append(("model_file_scene", yaml.safe_dump(own).encode()))
    bag = workdir / "seed_bag"
    if not bag.exists():  # the first messages of a committed sample: JPEG images, CameraInfo, truth, simreal types
        from simreal_nodes.io import bags

        src, _scene = sample("aluminium_beam_320x240")
        with bags.BagWriter(bag) as w:
            for k, m in enumerate(bags.read_bag(src)):
                if k >= BAG_MESSAGES:
                    break
                w.write_raw(m.topic, m.log_time_ns, m.raw, m.msgtype)
    mcap = next(bag.glob("*.mcap"))
    return {"model": [("fuzz_beam", model.read_bytes())], "scene": scenes,
            "bag": [(mcap.name, mcap.read_bytes()), ("metadata.yaml", (bag / "metadata.yaml").read_bytes())]}


# ------------------------------------------------------------------------------------------------
# Byte-level mutations (both targets)
def _bitflip(rng, b: bytearray) -> str:
    k = int(rng.integers(1, 9))
    for _ in range(k):
        i = int(rng.integers(len(b)))
        b[i] ^= 1 << int(rng.integers(8))
    return f"bitflip x{k}"


def _overwrite(rng, b: bytearray) -> str:
    n = int(rng.integers(1, 65))
    i = int(rng.integers(max(1, len(b) - n)))
    b[i:i + n] = rng.integers(0, 256, n, np.uint8).tobytes()
    return "overwrite"


def _zero(rng, b: bytearray) -> str:
    n = int(rng.integers(1, 513))
    i = int(rng.integers(max(1, len(b) - n)))
    b[i:i + n] = bytes(len(b[i:i + n]))
    return "zero block"


def _truncate(rng, b: bytearray) -> str:
    del b[int(rng.integers(len(b))):]
    return "truncate"


BYTE_MUTATIONS = (_bitflip, _overwrite, _zero, _truncate)


# ------------------------------------------------------------------------------------------------
# Structural HDF5 mutations
def _h5_objects(f) -> list[str]:
    names: list[str] = []
    f.visit(names.append)
    return names


def _storable(v):
    """An odd value as an HDF5 attribute can hold it: JSON text for None and containers, no NUL in strings, a float
    for an integer beyond 64 bits."""
    if v is None or isinstance(v, list | dict):
        return json.dumps(v)
    if isinstance(v, str):
        return v.replace("\x00", "")
    return float(v) if isinstance(v, int) and abs(v) >= 2**63 else v


def _h5_structural(rng, path: Path) -> str:
    import h5py

    with h5py.File(path, "r+") as f:
        names = _h5_objects(f)
        name = names[int(rng.integers(len(names)))]
        obj = f[name]
        kind = ("delete", "reshape", "retype", "group", "values", "attr", "huge")[int(rng.integers(7))]
        if kind == "attr" or (not isinstance(obj, h5py.Dataset) and kind != "delete"):
            target = f if rng.random() < 0.3 else obj
            keys = list(target.attrs.keys()) or ["format_version"]
            key = keys[int(rng.integers(len(keys)))]
            v = ODD_VALUES[int(rng.integers(len(ODD_VALUES)))]
            target.attrs[key] = _storable(v)
            return f"attr {key}"
        if kind == "delete":
            del f[name]
            return "delete"
        data = obj[()]
        del f[name]
        if kind == "reshape":
            flat = np.ravel(data)
            shape = tuple(int(x) for x in rng.integers(0, 6, int(rng.integers(0, 4))))
            f.create_dataset(name, data=np.resize(flat, shape) if flat.size else np.zeros(shape, flat.dtype))
        elif kind == "retype":
            f.create_dataset(name, data=(np.bytes_(b"text"), np.asarray([b"a", b"b"]), np.int8(3),
                                         np.asarray(data, np.float16) if np.asarray(data).dtype.kind in "fiu"
                                         else np.zeros(3))[int(rng.integers(4))])
        elif kind == "group":
            f.create_group(name)
        elif kind == "values":
            dt = np.asarray(data).dtype
            arr = np.array(data, np.float64) if dt.kind in "fiub" else np.zeros(4)
            if arr.size:
                idx = rng.integers(arr.size, size=int(rng.integers(1, 4)))
                arr.flat[idx] = (np.nan, np.inf, -np.inf, -1.0, 1e300, 2.0**40)[int(rng.integers(6))]
            f.create_dataset(name, data=arr.astype(dt) if dt.kind == "f" else arr)
        else:  # huge: the header declares far more than the file holds (reading it would allocate all of it)
            shape = (2**31,) + tuple(np.shape(data)[1:])
            f.create_dataset(name, shape=shape, dtype=np.asarray(data).dtype if np.asarray(data).dtype.kind in "fiu"
                             else np.float64, chunks=True)
        return kind


# ------------------------------------------------------------------------------------------------
# Structural scene mutations
def _nodes(doc, path=()) -> list[tuple]:
    out = [path]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _nodes(v, path + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += _nodes(v, path + (i,))
    return out


def _scene_structural(rng, text: bytes) -> tuple[bytes, str]:
    doc = yaml.safe_load(text)
    paths = [p for p in _nodes(doc) if p]
    p = paths[int(rng.integers(len(paths)))]
    parent = doc
    for k in p[:-1]:
        parent = parent[k]
    key = p[-1]
    kind = ("delete", "value", "value", "rename")[int(rng.integers(4))]
    if kind == "delete":
        del parent[key]
    elif kind == "rename" and isinstance(parent, dict):
        parent[f"{key}_x" if rng.random() < 0.5 else str(key).upper()] = parent.pop(key)
    else:
        parent[key] = ODD_VALUES[int(rng.integers(len(ODD_VALUES)))]
        kind = "value"
    return yaml.safe_dump(doc, allow_unicode=True).encode(), f"{kind} {'.'.join(map(str, p))}"[:80]


def _scene_text(rng, b: bytearray) -> str:
    lines = bytes(b).split(b"\n")
    kind = int(rng.integers(3))
    i = int(rng.integers(len(lines)))
    if kind == 0:
        lines.insert(i, lines[int(rng.integers(len(lines)))])
        b[:] = b"\n".join(lines)
        return "repeat line"
    if kind == 1:
        del lines[i]
        b[:] = b"\n".join(lines)
        return "delete line"
    j = int(rng.integers(len(b) + 1))
    b[j:j] = YAML_CHARS[int(rng.integers(len(YAML_CHARS)))].encode()
    return "yaml punctuation"


# ------------------------------------------------------------------------------------------------
def make_input(target: str, seed: int, case: int, seed_files: dict, workdir: Path) -> tuple[Path, str]:
    """Write input ``case`` of ``target`` (reproducible from ``seed`` alone); returns (its path, what was done)."""
    rng = np.random.default_rng([seed, TARGETS.index(target), case])
    if target == "bag":
        return _bag_input(rng, case, seed_files, workdir)
    name, content = seed_files[target][int(rng.integers(len(seed_files[target])))]
    path = workdir / (f"case_{target}_{case}" + (".h5" if target == "model" else ".yaml"))
    structural = rng.random() < 0.5
    if target == "model" and structural:
        path.write_bytes(content)
        what = _h5_structural(rng, path)
        # an edit through HDF5 models a writer's bug or another version, not corruption: the file is consistent
        # with its checksum, so the loader's own validation is what is tested (byte mutations below are left
        # unstamped: corruption after writing, which the checksum refuses before libhdf5 reads a byte)
        from simreal_nodes.errors import ModelFileError
        from simreal_nodes.rom.model_file import stamp_checksum

        with contextlib.suppress(ModelFileError):  # a seed file without a user block stays as it is
            stamp_checksum(path)
        return path, f"{name}: {what}"
    if target == "scene" and structural:
        out, what = _scene_structural(rng, content)
        path.write_bytes(out)
        return path, f"{name}: {what}"
    b = bytearray(content)
    muts = BYTE_MUTATIONS + ((_scene_text,) * 2 if target == "scene" else ())
    what = muts[int(rng.integers(len(muts)))](rng, b)
    path.write_bytes(bytes(b))
    return path, f"{name}: {what}"


def _bag_input(rng, case: int, seed_files: dict, workdir: Path) -> tuple[Path, str]:
    """A bag folder: its mcap file (most often) or its metadata.yaml mutated byte-wise, or a message type renamed to
    one no type store knows (same length, so the file stays well-formed)."""
    (mcap_name, mcap), (_, meta) = seed_files["bag"]
    path = workdir / f"case_bag_{case}"
    path.mkdir(exist_ok=True)
    m, y = bytearray(mcap), bytearray(meta)
    r = rng.random()
    if r < 0.15:
        what = "metadata " + BYTE_MUTATIONS[int(rng.integers(len(BYTE_MUTATIONS)))](rng, y)
    elif r < 0.25:
        old = (b"sensor_msgs/msg/CameraInfo", b"sensor_msgs/msg/CompressedImage", b"simreal_msgs/msg/ModelParameters",
               b"geometry_msgs/msg/PoseStamped")[int(rng.integers(4))]
        new = old[:-1] + b"Z"
        m, y = bytearray(bytes(m).replace(old, new)), bytearray(bytes(y).replace(old, new))
        what = f"unknown type {new.decode()}"
    else:
        what = BYTE_MUTATIONS[int(rng.integers(len(BYTE_MUTATIONS)))](rng, m)
    (path / mcap_name).write_bytes(bytes(m))  # the name metadata.yaml gives
    (path / "metadata.yaml").write_bytes(bytes(y))
    return path, f"sample_bag: {what}"


def _remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _load(target: str, path: Path) -> str:
    """Load the input as a user would; returns '' or, for a bag read with damage reported, the first problem."""
    if target == "bag":
        from simreal_nodes.io import bags

        report = bags.BagReport()
        for m in bags.read_bag(path, report):
            bags.decode(m)  # what `simreal eval-*` and the tools do with every message
        return report.summary().splitlines()[1].strip() if report.problems else ""
    if target == "model":
        from simreal_nodes.rom.model_file import load_model, read_header

        read_header(path)
        load_model(path)
    else:
        from simreal_nodes.scene.schema import load_scene

        load_scene(path)
    return ""


def blank(msg: str, path: Path) -> str:
    """A message with the input's file name and every number blanked: what counts as one kind of message."""
    msg = msg.replace(str(path), "<file>").replace(path.name, "<file>")
    return re.sub(r"\d+", "#", msg)[:240]


def run_case(target: str, seed: int, case: int, seed_files: dict, workdir: Path) -> dict:
    """One input through its loader: outcome accepted / rejected / crash, with the message and timing (a hang is
    seen from outside: :func:`run`)."""
    from simreal_nodes.errors import SimrealError

    path, what = make_input(target, seed, case, seed_files, workdir)
    rec = {"target": target, "case": case, "mutation": what.split(": ", 1)[1].split(" ")[0], "what": what}
    t0 = time.perf_counter()
    try:
        note = _load(target, path)
        rec.update(outcome="flagged", message=blank(note, path)) if note else rec.update(outcome="accepted")
    except SimrealError as e:
        rec.update(outcome="rejected", error=type(e).__name__, message=blank(str(e), path))
    except Exception as e:  # noqa: BLE001 - the point: anything else is a crash, recorded with where it came from
        frame = ([fr for fr in traceback.extract_tb(e.__traceback__) if "simreal_nodes" in fr.filename]
                 or traceback.extract_tb(e.__traceback__))[-1]  # the project's last line it passed
        rec.update(outcome="crash", error=type(e).__name__, message=blank(str(e), path),
                   site=f"{frame.filename.replace(str(ROOT) + os.sep, '')}:{frame.lineno}")
    rec["ms"] = 1e3 * (time.perf_counter() - t0)
    _remove(path)
    return rec


def worker(target: str, seed: int, first: int, n: int, workdir: Path, out: Path) -> None:
    """Cases first .. first + n - 1 of ``target`` in this process, under the address-space limit; one JSON line per
    case as it ends (after a first line once the seeds are ready), so a watcher sees which case it is at."""
    _soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard == resource.RLIM_INFINITY or hard > MEMORY_LIMIT:
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, hard))
    files = seeds(workdir)
    with open(out, "w") as f:
        f.write(json.dumps({"ready": True}) + "\n")
        f.flush()
        for i in range(first, first + n):
            f.write(json.dumps(run_case(target, seed, i, files, workdir)) + "\n")
            f.flush()


def run(target: str, seed: int, cases: int, workdir: Path, hang_s: float = 10.0) -> list[dict]:
    """All cases of ``target`` in worker processes. A worker that stays on one case over ``hang_s`` (HDF5 can loop
    for ever inside its C library, where no Python signal reaches) is killed and the case recorded as a hang; one
    that dies (a fault in a C library) as a crash; a fresh worker goes on from the next case."""
    out: list[dict] = []
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    first = 0
    while first < cases:
        log, err = workdir / f"{target}_{first}.jsonl", workdir / f"{target}_{first}.err"
        cmd = [sys.executable, "-m", "benchmarks.fuzz", "--worker", target, "--seed", str(seed), "--first",
               str(first), "--cases", str(cases - first), "--workdir", str(workdir), "--out", str(log)]
        with open(err, "w") as ferr:
            p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=ferr)
        size, deadline, hung = 0, time.monotonic() + 60.0 + hang_s, False  # first: start-up and seed files
        while p.poll() is None:
            time.sleep(0.02)
            now_size = log.stat().st_size if log.exists() else 0
            if now_size != size:
                size, deadline = now_size, time.monotonic() + hang_s
            elif time.monotonic() > deadline:
                p.kill()
                p.wait()
                hung = True
        got = [r for r in map(json.loads, log.read_text().splitlines()) if "ready" not in r] if log.exists() else []
        out += got
        if len(got) < cases - first:
            case = first + len(got)
            why = {"outcome": "hang", "error": "hang", "message": f"no answer in {hang_s:.0f} s"} if hung else \
                {"outcome": "crash", "error": f"process exit {p.returncode}", "message": err.read_text()[-240:]}
            path, what = make_input(target, seed, case, seeds(workdir), workdir)  # what the input was
            _remove(path)
            out.append({"target": target, "case": case, "mutation": what.split(": ", 1)[1].split(" ")[0],
                        "what": what, "ms": 0.0, "site": "worker", **why})
            first += len(got) + 1
        else:
            first = cases
    return out


def summary(records: list[dict]) -> tuple[list[dict], dict]:
    """Table rows per target and mutation (+ a total per target), and the distinct messages with their counts."""
    rows = []
    messages: dict = {}
    for target in TARGETS:
        recs = [r for r in records if r["target"] == target]
        if not recs:
            continue
        groups = sorted({r["mutation"] for r in recs}) + ["all"]
        for g in groups:
            rs = recs if g == "all" else [r for r in recs if r["mutation"] == g]
            c = Counter(r["outcome"] for r in rs)
            rows.append({"target": target, "mutation": g, "inputs": len(rs), "accepted": c["accepted"],
                         "flagged": c["flagged"], "rejected": c["rejected"], "crashes": c["crash"], "hangs": c["hang"],
                         "messages": len({r["message"] for r in rs if r["outcome"] == "rejected"}),
                         "max_ms": max(r["ms"] for r in rs)})
        bad = [r for r in recs if r["outcome"] in ("crash", "hang")]
        sites = Counter(f"{r['error']} at {r['site']}" for r in bad)
        example = {f"{r['error']} at {r['site']}": (r["message"], r["case"]) for r in bad}
        messages[target] = {
            "rejected": Counter(r["message"] for r in recs if r["outcome"] == "rejected").most_common(),
            "flagged": Counter(r["message"] for r in recs if r["outcome"] == "flagged").most_common(),
            "crashes": [(site, n, *example[site]) for site, n in sites.most_common()]}
    return rows, messages


COLUMNS = [("target", "loader", "{}"), ("mutation", "mutation", "{}"), ("inputs", "inputs", "{}"),
           ("accepted", "accepted", "{}"), ("flagged", "read, damage reported", "{}"),
           ("rejected", "rejected (clear error)", "{}"), ("crashes", "crashes", "{}"),
           ("hangs", "hangs", "{}"), ("messages", "distinct messages", "{}"), ("max_ms", "slowest (ms)", "{:.0f}")]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=50000, help="inputs per loader (model files, scenes)")
    ap.add_argument("--bag-cases", type=int, default=20000, help="inputs into the bag reader (slower per input)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--hang-s", type=float, default=10.0, help="an input slower than this is a hang")
    ap.add_argument("--worker", choices=TARGETS, help=argparse.SUPPRESS)
    ap.add_argument("--first", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--workdir", help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        worker(a.worker, a.seed, a.first, a.cases, Path(a.workdir), Path(a.out))
        return
    from benchmarks.common import save

    t0 = time.time()
    with tempfile.TemporaryDirectory(prefix="simreal-fuzz-") as d:
        records = [r for t in TARGETS for r in run(t, a.seed, a.bag_cases if t == "bag" else a.cases, Path(d),
                                                      a.hang_s)]
    rows, messages = summary(records)
    lines = []
    for target, m in messages.items():
        lines += [f"**{target}: crashes and hangs** ({sum(c[1] for c in m['crashes'])}, at {len(m['crashes'])} "
                  "sites; e.g. the message and the case that reproduces it)", ""]
        lines += [f"- {n} x {site}: `{msg[:160]}` (case {case})" for site, n, msg, case in m["crashes"]] or ["- none"]
        lines += ["", f"**{target}: the most frequent rejections** (of {len(m['rejected'])} distinct)", ""]
        lines += [f"- {n} x {msg}" for msg, n in m["rejected"][:15]] + [""]
        if m["flagged"]:
            lines += [f"**{target}: read, with the damage reported** (the most frequent of {len(m['flagged'])} "
                      "distinct first problems)", ""]
            lines += [f"- {n} x {msg}" for msg, n in m["flagged"][:10]] + [""]
    notes = (f"`python -m benchmarks.fuzz --cases {a.cases} --bag-cases {a.bag_cases} --seed {a.seed}` "
             f"({time.time() - t0:.0f} s). "
             "Accepted inputs are mutations the loader cannot tell from valid content: for model files, edits "
             "through HDF5 that leave a valid model (an attribute it does not read, a value changed to another valid "
             "one) and bytes changed in the user block's padding after the checksum; for scenes, a value changed to "
             "another valid one; for bags, bytes changed inside a message's payload that still decodes, or in a part "
             "of the file the reader does not need. A bag 'read, damage reported' yields the messages it could "
             "read (salvaged up to the damage) and its report names the damage or the undecodable messages, as "
             "`simreal bag-info` and a replay print it.\n\n" + "\n".join(lines))
    save("fuzz", rows, COLUMNS, "Hostile input to the model-file, scene and bag loaders", notes,
         extra={"seed": a.seed, "cases_per_loader": a.cases, "bag_cases": a.bag_cases,
                "messages": {t: {k: v[:100] for k, v in m.items()} for t, m in messages.items()},
                "crash_cases": [r for r in records if r["outcome"] in ("crash", "hang")][:200]})


if __name__ == "__main__":
    with contextlib.suppress(BrokenPipeError):
        main()
