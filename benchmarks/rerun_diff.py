"""What a rerun changed in a published table (issue 20: a rerun reproduces the numbers, within the noise it states).

    python -m benchmarks.rerun_diff family_boot                 # the work tree's table against HEAD's
    python -m benchmarks.rerun_diff family_boot --against 02d378c
    python -m benchmarks.rerun_diff family_boot --field median_err_pct --field p90_err_pct

A table (``benchmarks/results/<name>.json``) holds rows, one per scene or setting. The rows of the rerun (the file in
the work tree) are matched with the committed ones by their key (``seed`` where the rows have one, else the first
text field), and each numeric field is sorted into

- ``same``: equal to the digit (relative difference under ``--rtol``, 1e-9 by default: the arithmetic of one host);
- ``moved``: an accuracy figure that differs; the report gives how many rows moved, the median and largest absolute
  change and the rows that moved most, so that a rerun on another host (another SIMD level, other BLAS kernels: the
  RGB-D SLAM's greedy choices part on the last digits and the estimates downstream follow) states its own noise;
- timings (fields named ``*_ms*``, ``*_s``, ``*fps*``, ``*_per_s``): never "same"; the report gives the median ratio
  new/old, a host's speed rather than the code's.

Nothing is run and nothing is written: it reads the two JSON files (``git show`` for the committed one).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = "benchmarks/results"
TIMING = re.compile(r"(^|_)(ms|s|per_s)(_|$)|fps")


def is_timing(field: str) -> bool:
    """A field that measures speed (its value follows the host, not the code)."""
    return bool(TIMING.search(field))


def _number(v) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v)


#: text fields that describe a run's outcome rather than name its row (they may differ between runs)
FREE_TEXT = ("reason", "refusal", "axis_txt", "note", "notes", "doubt")


def row_key(rows: list[dict]) -> tuple[str, ...]:
    """The fields that name a row: ``seed`` where every row has one, then text or yes/no fields present in every row
    (in their order, outcomes such as ``reason`` left out), as few as make the rows' keys unique; () if none do."""
    if not rows:
        return ()
    names = (["seed"] if all("seed" in r for r in rows) else []) + [
        k for k in rows[0] if k != "seed" and not any(w in k for w in FREE_TEXT)
        and all(isinstance(r.get(k), (str, bool)) for r in rows)]
    key: list[str] = []
    for k in names:
        key.append(k)
        if len({tuple(r.get(f) for f in key) for r in rows}) == len(rows):
            return tuple(key)
    return ()


def close(a: float, b: float, rtol: float) -> bool:
    if math.isnan(a) and math.isnan(b):
        return True
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= rtol * max(abs(a), abs(b), 1e-300)


def compare(old: dict, new: dict, rtol: float = 1e-9, fields: list[str] | None = None) -> dict:
    """Row-by-row and summary differences between two saved tables (the dicts :func:`benchmarks.common.save` writes).

    Returns ``rows_old``, ``rows_new``, ``matched``, ``only_old``, ``only_new`` (keys), ``identical`` (matched rows
    whose every non-timing numeric field is the same), ``fields`` (per field: ``n``, ``moved``, ``median_abs``,
    ``max_abs``, ``max_row``; timings: ``ratio_median``), ``summary`` (per numeric summary field: old, new).
    """
    orows, nrows = old.get("rows") or [], new.get("rows") or []
    key = row_key(orows) or row_key(nrows)
    out: dict = {"key": ", ".join(key) or "row order", "rows_old": len(orows), "rows_new": len(nrows)}
    if not key:
        by_old, by_new = dict(enumerate(orows)), dict(enumerate(nrows))
    else:
        def name(r: dict):
            return r.get(key[0]) if len(key) == 1 else tuple(r.get(k) for k in key)
        by_old = {name(r): r for r in orows}
        by_new = {name(r): r for r in nrows}
    matched = [k for k in by_old if k in by_new]
    out["matched"] = len(matched)
    out["only_old"] = [k for k in by_old if k not in by_new]
    out["only_new"] = [k for k in by_new if k not in by_old]
    stats: dict[str, dict] = {}
    identical = 0
    for k in matched:
        a, b = by_old[k], by_new[k]
        same_row = True
        for f in a:
            if fields and f not in fields:
                continue
            x, y = _number(a.get(f)), _number(b.get(f))
            if x is None or y is None or f in key:
                continue
            s = stats.setdefault(f, {"n": 0, "moved": 0, "diffs": [], "ratios": []})
            s["n"] += 1
            if is_timing(f):
                if x > 0 and y > 0:
                    s["ratios"].append(y / x)
                continue
            if not close(x, y, rtol):
                same_row = False
                s["moved"] += 1
                d = y - x if math.isfinite(x) and math.isfinite(y) else math.inf
                s["diffs"].append((abs(d), d, k))
        identical += same_row
    out["identical"] = identical
    out["fields"] = {}
    for f, s in stats.items():
        e: dict = {"n": s["n"], "timing": is_timing(f)}
        if e["timing"]:
            r = sorted(s["ratios"])
            e["ratio_median"] = r[len(r) // 2] if r else None
        else:
            d = sorted(s["diffs"], key=lambda t: t[0])
            e["moved"] = s["moved"]
            e["median_abs"] = d[len(d) // 2][0] if d else 0.0
            e["max_abs"] = d[-1][0] if d else 0.0
            e["max_row"] = d[-1][2] if d else None
            e["largest"] = [(t[2], t[1]) for t in reversed(d[-3:])]
        out["fields"][f] = e
    summ: dict[str, tuple] = {}
    so, sn = old.get("summary") or {}, new.get("summary") or {}
    if isinstance(so, dict) and isinstance(sn, dict):
        for f in so:
            x, y = _number(so.get(f)), _number(sn.get(f))
            if x is not None and y is not None:
                summ[f] = (x, y)
    out["summary"] = summ
    return out


def _fmt(v: float) -> str:
    return f"{v:.4g}" if math.isfinite(v) else str(v)


def report(name: str, diff: dict, old_on: str, new_on: str) -> str:
    """The differences as markdown."""
    lines = [f"## `{name}`: the rerun ({new_on}) against the committed table ({old_on})", ""]
    lines.append(f"Rows: {diff['matched']} matched by `{diff['key']}` ({diff['rows_old']} before, {diff['rows_new']} "
                 f"now); {diff['identical']} the same in every accuracy field.")
    if diff["only_old"] or diff["only_new"]:
        lines.append(f"Only before: {diff['only_old']}; only now: {diff['only_new']}.")
    acc = {f: e for f, e in diff["fields"].items() if not e["timing"] and e["moved"]}
    if acc:
        lines += ["", "| field | rows moved | of | median change of those | largest change (row) |",
                  "|---|---|---|---|---|"]
        for f, e in sorted(acc.items(), key=lambda t: -t[1]["moved"]):
            big = ", ".join(f"{_fmt(d)} ({k})" for k, d in e["largest"])
            lines.append(f"| {f} | {e['moved']} | {e['n']} | {_fmt(e['median_abs'])} | {big} |")
    tim = {f: e for f, e in diff["fields"].items() if e["timing"] and e.get("ratio_median")}
    if tim:
        lines += ["", "Timings, median ratio now/before: " + ", ".join(
            f"{f} {e['ratio_median']:.2f}" for f, e in sorted(tim.items()))]
    moved = {f: v for f, v in diff["summary"].items() if not close(v[0], v[1], 1e-9)}
    if moved:
        lines += ["", "Summary: " + "; ".join(f"{f} {_fmt(a)} -> {_fmt(b)}" for f, (a, b) in moved.items())]
    elif diff["summary"]:
        lines += ["", "Summary: every figure the same."]
    return "\n".join(lines) + "\n"


def _host(doc: dict) -> str:
    m = doc.get("machine") or {}
    cpu = str(m.get("cpu", "?")).split("(")[0].strip() or "?"
    return f"{cpu} {m.get('simd', '')}, {str(m.get('commit', '?'))[:7]} {m.get('date', '')}".replace(" ,", ",")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("name", help="the table's name (benchmarks/results/NAME.json)")
    ap.add_argument("--against", default="HEAD", help="the git revision whose table the work tree's is compared with")
    ap.add_argument("--rtol", type=float, default=1e-9, help="relative difference under which a figure is the same")
    ap.add_argument("--field", action="append", help="compare only these row fields (repeatable)")
    a = ap.parse_args(argv)
    path = f"{RESULTS}/{a.name}.json"
    try:
        new = json.loads((ROOT / path).read_text())
    except (OSError, ValueError) as e:
        print(f"rerun_diff: cannot read {path}: {e}", file=sys.stderr)
        return 2
    got = subprocess.run(["git", "show", f"{a.against}:{path}"], cwd=ROOT, capture_output=True, text=True)
    if got.returncode:
        print(f"rerun_diff: no {path} at {a.against}: {got.stderr.strip()}", file=sys.stderr)
        return 2
    try:
        old = json.loads(got.stdout)
    except ValueError as e:
        print(f"rerun_diff: {path} at {a.against} is not JSON: {e}", file=sys.stderr)
        return 2
    print(report(a.name, compare(old, new, a.rtol, a.field), _host(old), _host(new)), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
