"""Benchmark harness: every benchmark writes results/<name>.json, results/<name>.md and results/<name>.png."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def saved_machine(name: str) -> dict:
    """``{"machine": ...}`` of the saved results ``name`` (empty when there are none): for :func:`save`'s ``extra``
    when a benchmark rewrites its report from a saved run, so the report keeps the run's date and CPU probe, not the
    rewrite's."""
    path = RESULTS / f"{name}.json"
    if not path.is_file():
        return {}
    doc = json.loads(path.read_text())
    return {"machine": doc["machine"]} if isinstance(doc, dict) and "machine" in doc else {}


def machine() -> dict:
    import numpy as np

    info = {"python": platform.python_version(), "machine": platform.machine(), "cpus": os.cpu_count(),
            "numpy": np.__version__, "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name") and "cpu" not in info:
                    info["cpu"] = line.split(":", 1)[1].strip()
                elif line.startswith("flags") and "simd" not in info:
                    info["simd"] = simd_level(line.split(":", 1)[1].split())
                if "cpu" in info and "simd" in info:
                    break
    except OSError:
        pass
    info["cpu_probe_ms"] = speed_probe()
    info.update(provenance())
    return info


def provenance() -> dict:
    """What produced a table: ``script`` (the benchmark run as ``__main__``, repository-relative) and ``commit`` (the
    checkout's full commit, with '+' where its code, not counting results, differs from it; '?' outside git). Read by
    ``benchmarks.staleness`` to tell whether the code has changed since."""
    import subprocess
    import sys

    root = RESULTS.parents[1]
    main = getattr(sys.modules.get("__main__"), "__file__", None)
    out = {}
    if main and Path(main).resolve().is_relative_to(root):
        out["script"] = str(Path(main).resolve().relative_to(root))
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--", "simreal_nodes",
                                "simreal_msgs_py", "benchmarks", ":(exclude)benchmarks/results", "requirements.txt"],
                               capture_output=True, text=True, check=True).stdout.strip()
        out["commit"] = head + ("+" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        out["commit"] = "?"
    return out


def simd_level(flags: list[str] | set[str]) -> str:
    """The widest vector instruction set among a CPU's ``/proc/cpuinfo`` flags. Recorded with every result: the same
    code reads some scenes differently on hosts with and without AVX-512 (numpy's and OpenCV's kernels round
    differently), so per-scene rows compare only between hosts of the same level (docs/family.md)."""
    f = set(flags)
    for flag, name in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"), ("sse4_2", "SSE4.2"),
                       ("asimd", "NEON")):
        if flag in f:
            return name
    return "none known"


def speed_probe() -> float:
    """Milliseconds for a fixed single-threaded numpy + OpenCV workload, best of three: the same machine
    can run slower when its host is busy, and results taken at different times compare through this."""
    import cv2
    import numpy as np

    a = np.random.default_rng(0).random((200, 200))
    img = np.random.default_rng(0).integers(0, 255, (480, 640, 3), np.uint8)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    best = float("inf")
    try:
        for _ in range(3):
            t0 = time.perf_counter()
            for _ in range(10):
                np.sin(a @ a)
                cv2.GaussianBlur(img, (9, 9), 2)
            best = min(best, (time.perf_counter() - t0) * 1e3)
    finally:
        cv2.setNumThreads(threads)
    return best


def markdown_table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    """columns: (key, header, format) e.g. ("p50_ms", "p50 (ms)", "{:.2f}")."""
    head = "| " + " | ".join(h for _, h, _ in columns) + " |"
    sep = "|" + "|".join("---" for _ in columns) + "|"
    body = []
    for r in rows:
        cells = []
        for k, _, fmt in columns:
            v = r.get(k, "")
            try:
                cells.append(fmt.format(v) if v != "" and v is not None else "")
            except (ValueError, TypeError):
                cells.append(str(v))
        body.append("| " + " | ".join(cells) + " |")
    return "\n".join([head, sep, *body])


def save(name: str, rows: list[dict], columns, title: str, notes: str = "", plot=None,
         extra: dict | None = None) -> Path:
    """Write the JSON (rows + machine), the markdown table and, if ``plot(ax_or_fig)`` is given, a PNG."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    doc = {"benchmark": name, "title": title, "machine": machine(), "rows": rows}
    if extra:
        doc.update(extra)
    (RESULTS / f"{name}.json").write_text(json.dumps(doc, indent=2, default=float))
    md = [f"# {title}", "", markdown_table(rows, columns), ""]
    if notes:
        md += [notes, ""]
    m = doc["machine"]
    simd = f" ({m['simd']})" if m.get("simd") else ""
    md.append(f"Machine: {m.get('cpu', '?')}{simd}, {m['cpus']} CPUs, Python {m['python']}, {m['date']}; CPU probe "
              f"{m['cpu_probe_ms']:.0f} ms (`benchmarks/common.py:speed_probe`, lower is faster: the host's load "
              "changes this machine's speed).")
    if plot is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig = plot(plt)
        fig.savefig(RESULTS / f"{name}.png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        md += ["", f"![{title}]({name}.png)"]
    (RESULTS / f"{name}.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return RESULTS / f"{name}.json"


def replot(name: str, plot_rows) -> Path:
    """Redraw results/<name>.png from the rows saved in results/<name>.json by the benchmark's last run (no rerun:
    the rows, the table and the machine line stay as that run wrote them). ``plot_rows(plt, rows)`` returns the figure;
    the table gets the image link if it lacks one."""
    doc = json.loads((RESULTS / f"{name}.json").read_text())
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plot_rows(plt, doc["rows"])
    png = RESULTS / f"{name}.png"
    fig.savefig(png, dpi=110, bbox_inches="tight")
    plt.close(fig)
    md = RESULTS / f"{name}.md"
    if md.exists() and f"({name}.png)" not in md.read_text():
        md.write_text(md.read_text().rstrip("\n") + f"\n\n![{doc['title']}]({name}.png)\n")
    return png


def process_memory() -> dict[str, float]:
    """This process's memory (MB): ``rss`` (resident, from the OS), ``malloc_used`` and ``malloc_free`` (glibc's
    heap over all arenas, ``mallinfo2``: bytes handed out, mmapped chunks included, and bytes held free inside the
    arenas) and ``py_blocks`` (thousands of blocks Python's own allocator holds). Together they tell where a process
    grows: Python objects (``py_blocks``), native allocations of the extensions (``malloc_used`` without
    ``py_blocks``), or the allocator keeping freed memory (``malloc_free``). The malloc fields are NaN off glibc."""
    import ctypes
    import sys

    import psutil

    out = {"rss": psutil.Process().memory_info().rss / 2 ** 20, "malloc_used": float("nan"),
           "malloc_free": float("nan"), "py_blocks": sys.getallocatedblocks() / 1e3}
    try:
        fn = ctypes.CDLL("libc.so.6").mallinfo2
    except (OSError, AttributeError):
        return out

    class MallInfo2(ctypes.Structure):
        _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                   "fsmblks", "uordblks", "fordblks", "keepcost")]

    fn.restype = MallInfo2
    mi = fn()
    out["malloc_used"] = (mi.uordblks + mi.hblkhd) / 2 ** 20
    out["malloc_free"] = mi.fordblks / 2 ** 20
    return out


def malloc_trim() -> bool:
    """Ask glibc to return the free memory its arenas hold to the OS (``malloc_trim(0)``); False off glibc. What
    the resident size loses by it was the allocator's, not the program's."""
    import ctypes

    try:
        return bool(ctypes.CDLL("libc.so.6").malloc_trim(0))
    except (OSError, AttributeError):
        return False


def growth_per_1000(frames, values) -> float:
    """Least-squares slope of ``values`` against ``frames``, per 1000 frames (NaN under three points)."""
    import numpy as np

    x, y = np.asarray(frames, float), np.asarray(values, float)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return float("nan")
    return float(np.polyfit(x[ok], y[ok], 1)[0] * 1000)


def most_common(items: list) -> object:
    """The most frequent item; of several as frequent, the first seen (``max(set(...))`` broke ties by the set's
    order, which follows Python's per-process string hashing: the same run printed another reason)."""
    import collections

    return collections.Counter(items).most_common(1)[0][0]


def pair_ratios(first: list[dict], second: list[dict], key: str) -> list[float]:
    """Each pair's ``second[i][key] / first[i][key]``: runs made as pairs (the two arms back to back, the order
    alternating) so that a host whose speed drifts moves both runs of a pair alike (``benchmarks.executor``,
    ``benchmarks.ingest_hop``, ``benchmarks.dense_budget``). Pairs are matched by position; a run without its
    partner is left out."""
    return [float(b[key]) / float(a[key]) for a, b in zip(first, second, strict=False)]


def pair_changes(first: list[dict], second: list[dict], key: str) -> list[float]:
    """Each pair's change of ``key`` in % of the first arm's run (see :func:`pair_ratios`)."""
    return [100.0 * (x - 1.0) for x in pair_ratios(first, second, key)]


def commit(checkout: Path) -> str:
    """The checkout's commit, and '+' where its tracked files differ from it ('?': not a git checkout)."""
    import subprocess

    try:
        rev = subprocess.run(["git", "-C", str(checkout), "describe", "--always", "--dirty=+", "--abbrev=7"],
                             capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"
    return rev


def run_worker(script: Path, seed: int, checkout: Path) -> dict:
    """``script --worker SEED OUT`` in a fresh process whose ``simreal_nodes`` and ``benchmarks`` come from
    ``checkout`` (one BLAS thread): the JSON it wrote to OUT. The script itself is this checkout's, so the other
    checkout need not have it; its module-level imports must exist there (import newer helpers in ``main``)."""
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        env = {**os.environ, "PYTHONPATH": str(checkout), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
               "MKL_NUM_THREADS": "1"}
        subprocess.run([sys.executable, str(Path(script).resolve()), "--worker", str(seed), str(out)],
                       cwd=checkout, env=env, check=True)
        result: dict = json.loads(out.read_text())
        return result


def checkout_pairs(script: Path, root: Path, against: Path | None, seeds: list[int], reps: int,
                   summary) -> list[dict]:
    """Every seed run ``reps`` times per checkout (this one, ``root``, and ``against`` where given) with
    :func:`run_worker`, the two checkouts back to back and their order alternating (ABBA, :func:`pair_ratios`). Per
    run a row: seed, ``code`` (which checkout, by :func:`commit`), ``rep`` and ``summary(doc, first)``, with
    ``first`` the seed's first run (this checkout's)."""
    arms = [(f"this checkout ({commit(root)})", root)] + (
        [(f"other ({commit(against)})", against.resolve())] if against is not None else [])
    rows = []
    for seed in seeds:
        reference = None
        for rep in range(reps):
            for label, path in (arms if rep % 2 == 0 else arms[::-1]):
                doc = run_worker(script, seed, path)
                if reference is None:
                    reference = doc
                row = {"seed": seed, "code": label, "rep": rep, **summary(doc, reference)}
                print(json.dumps(row), flush=True)
                rows.append(row)
    return rows


def checkout_notes(rows: list[dict], keys: list[tuple[str, str]], fmt: str = "{:.0f}") -> str:
    """Sentences on :func:`checkout_pairs`'s rows: each checkout's median over its runs of ``keys[0]`` (ms, written
    with ``fmt``), and with two checkouts, for each (key, what) of ``keys``, the pairs' ratio this checkout / the
    other (median and range)."""
    import numpy as np

    first, what0 = keys[0]
    by_code: dict[str, list[float]] = {}
    for r in rows:
        by_code.setdefault(r["code"], []).append(float(r[first]))
    out = (f"Median over the runs of {what0}: "
           + "; ".join(f"{c} {fmt.format(np.median(v))} ms" for c, v in by_code.items()) + ".")
    arms = sorted(by_code, key=lambda c: not c.startswith("this"))
    if len(arms) == 2:
        pairs: dict[tuple, dict[str, dict]] = {}
        for r in rows:
            pairs.setdefault((r["seed"], r["rep"]), {})[r["code"]] = r
        whole = [p for p in pairs.values() if len(p) == 2]
        for key, what in keys:
            ratio = pair_ratios([p[arms[1]] for p in whole], [p[arms[0]] for p in whole], key)
            out += (f" Pairs' ratio this checkout / the other, {what}: median {np.median(ratio):.2f} (from "
                    f"{min(ratio):.2f} to {max(ratio):.2f}, {len(ratio)} pairs).")
    return out


def budget_runs(doc: str, seeds: str, out: str, script: Path, root: Path, frames, summary) -> tuple:
    """The command line of a budget benchmark (``benchmarks.dense_budget``, ``benchmarks.depth_budget``) past its
    ``--worker`` form: ``--seeds`` (default ``seeds``), ``--against``, ``--reps``, ``--out`` (default ``out``); each
    seed's frames made (``frames(seed)``), then :func:`checkout_pairs`. Returns (arguments, rows)."""
    import argparse

    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default=seeds, help="development scenes of the family")
    ap.add_argument("--against", type=Path, help="another checkout, run in pairs with this one")
    ap.add_argument("--reps", type=int, default=2, help="runs (pairs with --against) per scene; the order alternates")
    ap.add_argument("--out", default=out)
    args = ap.parse_args()
    chosen = [int(s) for s in args.seeds.split(",")]
    for seed in chosen:
        frames(seed)
    return args, checkout_pairs(script, root, args.against, chosen, args.reps, summary)
