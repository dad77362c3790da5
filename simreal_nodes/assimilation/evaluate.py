"""Evaluation of estimated parameters against the truth of a synthetic bag (`simreal eval-tracking`).

The per-position table follows the thesis's Table 4.1: for every position the truth holds for a while,
the true value, the mean estimate over those frames and their absolute difference.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simreal_nodes.errors import SimrealError
from simreal_nodes.io import bags


@dataclass
class Series:
    stamps: np.ndarray
    names: list[str]
    units: list[str]
    values: np.ndarray  # (T, n)
    states: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    std: np.ndarray | None = None


def read_parameters(path: str | Path, topic: str) -> Series:
    st, vals, states, stds = [], [], [], []
    names: list[str] | None = None
    units: list[str] | None = None
    for m in bags.read_bag(path, topics=[topic]):
        o = bags.decode(m)
        st.append(bags.stamp_ns(o))
        names, units = list(o.names), list(o.units)
        v = np.asarray(o.values, dtype=np.float64)
        vals.append(v)
        states.append(int(o.state))
        c = np.asarray(o.covariance, dtype=np.float64)
        n = len(v)
        stds.append(np.sqrt(np.clip(np.diag(c.reshape(n, n)), 0, None)) if c.size == n * n else np.full(n, np.nan))
    if not st:
        raise SimrealError(f"{path} has no messages on {topic}")
    assert names is not None and units is not None  # every message sets them, and there was one
    width = max(len(v) for v in vals)
    V = np.full((len(vals), width), np.nan)
    for i, v in enumerate(vals):
        V[i, : len(v)] = v
    S = np.full((len(stds), width), np.nan)
    for i, v in enumerate(stds):
        S[i, : len(v)] = v
    return Series(np.asarray(st), names, units, V, np.asarray(states), S)


@dataclass
class ParameterReport:
    name: str
    unit: str
    n: int
    median_abs: float
    mean_abs: float
    max_abs: float
    span: float
    outside_range: int
    table: list[tuple[float, float, float, int]]  # (true, mean estimate, |difference|, frames)
    states: dict[int, int]  # estimate state -> frames


def holds(truth: np.ndarray, min_frames: int = 5) -> list[tuple[int, int]]:
    """(start, end) index ranges where the true value stays constant for at least ``min_frames``."""
    out, s = [], 0
    for i in range(1, len(truth) + 1):
        if i == len(truth) or not np.isclose(truth[i], truth[s], rtol=0, atol=1e-9):
            if i - s >= min_frames and np.isfinite(truth[s]):
                out.append((s, i))
            s = i
    return out


def compare(est: Series, truth: Series, ranges: dict[str, tuple[float, float]] | None = None,
            skip_states: Iterable[int] = ()) -> list[ParameterReport]:
    common, ie, it = np.intersect1d(est.stamps, truth.stamps, return_indices=True)
    if len(common) == 0:
        raise SimrealError("no estimate has the stamp of a ground-truth message (did the bags come from the same run?)")
    reports = []
    for k, name in enumerate(truth.names):
        if name not in est.names:
            continue
        j = est.names.index(name)
        e = est.values[ie, j]
        t = truth.values[it, k]
        keep = np.isfinite(t) & ~np.isin(est.states[ie], list(skip_states))
        err = np.abs(e - t)[keep]
        lo, hi = (ranges or {}).get(name, (np.nanmin(t), np.nanmax(t)))
        table = []
        for a, b in holds(t):
            sel = np.arange(a, b)
            sel = sel[keep[sel]]
            if len(sel):
                m = float(np.mean(e[sel]))
                table.append((float(t[a]), m, abs(m - float(t[a])), len(sel)))
        states = {int(s): int(c) for s, c in zip(*np.unique(est.states[ie], return_counts=True))}
        reports.append(ParameterReport(name, truth.units[k] if k < len(truth.units) else "", int(keep.sum()),
                                       float(np.median(err)) if len(err) else float("nan"),
                                       float(np.mean(err)) if len(err) else float("nan"),
                                       float(np.max(err)) if len(err) else float("nan"), float(hi - lo),
                                       int(np.sum((e < lo - 1e-9) | (e > hi + 1e-9))), table, states))
    return reports


def format_table41(r: ParameterReport, scale: float = 1.0, unit: str | None = None) -> str:
    """Two side-by-side columns of (actual, mean estimated, |difference|), as the thesis's Table 4.1."""
    u = unit or r.unit
    rows = [f"{a * scale:9.2f} {m * scale:10.2f} {d * scale:10.2f}" for a, m, d, _ in r.table]
    half = (len(rows) + 1) // 2
    head = f"{'actual':>9} {'mean est.':>10} {'|diff|':>10}"
    lines = [f"{r.name} [{u}]", f"{head}   {head}"]
    for i in range(half):
        right = rows[i + half] if i + half < len(rows) else ""
        lines.append(f"{rows[i]}   {right}")
    return "\n".join(lines)


@dataclass
class ContactReport:
    frames: int
    contact_agreement: float  # fraction of frames where estimated and true in_contact agree
    same_load_point: float  # among frames both in contact
    pseudo_time_median_abs: float
    pseudo_time_max_abs: float
    true_contact_frames: int
    est_contact_frames: int


def read_contacts(path: str | Path, topic: str) -> dict[int, tuple[bool, int, float]]:
    out: dict[int, tuple[bool, int, float]] = {}
    for m in bags.read_bag(path, topics=[topic]):
        o = bags.decode(m)
        out[bags.stamp_ns(o)] = (bool(o.in_contact) or float(o.pseudo_time) > 0, int(o.load_point),
                                 float(o.pseudo_time))
    if not out:
        raise SimrealError(f"{path} has no messages on {topic}")
    return out


def compare_contacts(est: dict[int, tuple[bool, int, float]],
                     truth: dict[int, tuple[bool, int, float]]) -> ContactReport:
    """Contact state, contact node and pseudo-time of a run against the synthetic truth (same stamps)."""
    common = sorted(set(est) & set(truth))
    if not common:
        raise SimrealError("no contact estimate has the stamp of a ground-truth message")
    agree = sum(est[s][0] == truth[s][0] for s in common)
    both = [s for s in common if est[s][0] and truth[s][0] and est[s][1] >= 0 and truth[s][1] >= 0]
    same = sum(est[s][1] == truth[s][1] for s in both)
    dt = np.array([abs(est[s][2] - truth[s][2]) for s in common])
    return ContactReport(len(common), agree / len(common), same / len(both) if both else float("nan"),
                         float(np.median(dt)), float(dt.max()), sum(truth[s][0] for s in common),
                         sum(est[s][0] for s in common))
