"""The Levenberg-Marquardt normal equations' conditioning against modes and parameters, parameters at their bounds
included (issue 20, section 2).

    ./run bench lm_conditioning       # writes benchmarks/results/lm_conditioning.{json,md,png}

The tracker's step solves [J^T W J + lambda diag(J^T W J)] delta = J^T W r (Eq. 4.8, `assimilation/lm.py`). How
well that system is posed depends on the model (how many modes, which parameters), on where the parameters are
(a load at a clamp moves nothing, so its position has no derivative; the joint boot's rotation alpha_z acts on the
displacement only, so an unbent boot leaves it unseen) and on the unknowns the tracker adds (a rigid shift).

Each row: one model, layout and true parameter point (its axes' lower bound, middle and upper bound, and
combinations), seen by a 640x480 camera (f = 520 px) from 35 degrees above, at 1.5 times the object's size, through
150 surface nodes. A linear model's load is scaled so that the largest surface motion, with the parameters at the
middle of their ranges, is 10 px (the scene family draws 2-40 px); the joint boot's lever turns as its model says.
The row gives:

- ``sensitivity``: how many pixels (rms over the points) 1 % of the weakest parameter's range moves;
- ``cond``: the condition number of J^T J at the truth, and ``cond scaled``: the same after the Jacobi scaling
  diag(J^T J)^-1/2 that Marquardt's damping amounts to (what the solve feels; a unit change of scale alone does not
  count);
- 20 solves from a start 10 % of each range off the truth (clipped to the bounds), with 0.5 px Gaussian pixel noise:
  the worst parameter's error in % of its range (median and max over the solves), the iterations, and how often
  the tracker's own observability rule (a standard deviation over 5 % of the range:
  `tracker.py:_conclude`) flags the estimate;
- ``silent``: solves whose error exceeds 5 % of a range while nothing is flagged (the number that matters).

The pixels are made by the model itself with all its modes: a deliberate zero model error, so the rows isolate
the conditioning (the accuracy against independent physics is in `benchmarks/results/family.md` and
`mode_count.md`). With fewer modes than the data the truncation error is part of the row.
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from benchmarks.common import save
from simreal_nodes import geometry as G
from simreal_nodes.assimilation import lm
from simreal_nodes.assimilation.registration import surface_nodes
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.rom.state import StateLayout

K = np.array([[520.0, 0, 320], [0, 520.0, 240], [0, 0, 1]])
TRIALS = 20
NOISE_PX = 0.5
SHIFT_M = 0.01  # the tracker's object_shift_m when a shift is estimated
FLAG = 0.05  # tracker.py: a standard deviation over 5 % of the range is "barely observable"

PEAK_PX = 10.0  # linear models: the load scaled so that the largest motion, mid-range, is this many pixels
CASES = [  # model, layout extras, mode counts, scale the load to PEAK_PX (a linear model's load is a free choice)
    ("aluminium_beam", {}, (1, 3, None), True),
    ("aluminium_beam", {"shift": True}, (None,), True),
    ("aluminium_beam_E", {}, (1, 3, None), True),
    ("crossed_beams", {}, (1, 3, None), True),
    ("joint_boot", {"alpha_z": True}, (1, 3, None), False),
]


def _camera(m) -> np.ndarray:
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    c, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    el, az = np.deg2rad(35.0), np.deg2rad(-70.0)
    eye = c + 1.5 * size * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return np.linalg.inv(G.look_at(eye, c))


def _points(m, rng: np.random.Generator, n: int = 150) -> np.ndarray:
    cand = surface_nodes(m)
    return np.sort(rng.choice(cand, min(n, len(cand)), replace=False))


def truth_points(layout: StateLayout) -> list[tuple[str, np.ndarray]]:
    """The axes' lower bound, middle and upper bound (all combinations for two axes); alpha_z at 0.3 rad."""
    levels = []
    for a in layout.axes:
        lo, hi = a.range
        levels.append([("lo", lo), ("mid", (lo + hi) / 2), ("hi", hi)])
    out = []
    for combo in itertools.product(*levels):
        name = ", ".join(f"{a.name} {lab}" for a, (lab, _) in zip(layout.axes, combo))
        x = [v for _, v in combo]
        if layout.alpha_z is not None:
            x.append(0.3)
        if layout.shift:
            x += [0.0, 0.0, 0.0]
        out.append((name, np.asarray(x, dtype=np.float64)))
    return out


def _scaled(view, a: float):
    """A deformation view whose displacement (and its derivatives) is ``a`` times the model's."""
    def disp(mu):
        dX, ddX = view.with_jacobian(mu)
        return a * dX, a * ddX
    return disp


def case_rows(name: str, extras: dict, modes: tuple, scale_load: bool) -> list[dict]:
    m = load_model(cached_model(name), fields=["displacement"])
    rng = np.random.default_rng(7)
    nodes = _points(m, rng)
    layout = StateLayout.of(m, alpha_z=bool(extras.get("alpha_z")))
    if extras.get("shift"):
        layout = layout.with_shift()
    lo, hi = layout.bounds(SHIFT_M)
    span = hi - lo
    T_cw = _camera(m)
    X = m.points[nodes]
    full = m.deformation_view(nodes, None)
    a = 1.0
    if scale_load:  # the load that moves the surface by PEAK_PX pixels at the middle of the ranges
        mid = (lo + hi) / 2
        p_mid = lm.Problem(X, np.zeros((len(X), 2)), full.with_jacobian, T_cw, np.eye(3), K, layout)
        uv_mid, _, _ = lm.predict(p_mid, mid, with_jacobian=False)
        uv_rest, _, _ = lm.predict(lm.Problem(X, np.zeros((len(X), 2)), _scaled(full, 0.0), T_cw, np.eye(3), K,
                                              layout), mid, with_jacobian=False)
        a = PEAK_PX / max(float(np.linalg.norm(uv_mid - uv_rest, axis=1).max()), 1e-300)
    truth_disp = _scaled(full, a)
    rows = []
    for n in modes:
        view = m.deformation_view(nodes, n)
        n_used = view.n_modes if hasattr(view, "n_modes") else n
        disp = _scaled(view, a)
        for label, x_true in truth_points(layout):
            p_true = lm.Problem(X, np.zeros((len(X), 2)), truth_disp, T_cw, np.eye(3), K, layout)
            uv0, _, _ = lm.predict(p_true, x_true, with_jacobian=False)
            p = lm.Problem(X, uv0, disp, T_cw, np.eye(3), K, layout)
            _, _, J = lm.predict(p, x_true)
            Jf = J.reshape(-1, layout.size)
            H = Jf.T @ Jf
            d = np.sqrt(np.maximum(np.diag(H), 1e-300))
            cond = float(np.linalg.cond(H))
            cond_s = float(np.linalg.cond(H / d[:, None] / d[None, :]))
            # pixels (rms over the points) that 1 % of each parameter's range moves: the weakest one
            sens = float(np.min(np.sqrt(np.diag(H) / len(X)) * 0.01 * span))
            errs, iters, flagged, silent, times = [], [], 0, 0, []
            for _ in range(TRIALS):
                uv = uv0 + rng.normal(0.0, NOISE_PX, uv0.shape)
                x0 = np.clip(x_true + rng.choice([-1, 1], layout.size) * 0.1 * span, lo, hi)
                q = lm.Problem(X, uv, disp, T_cw, np.eye(3), K, layout)
                t0 = time.perf_counter()
                r = lm.solve(q, x0, lo, hi)
                times.append(time.perf_counter() - t0)
                e = np.abs(r.x - x_true) / span
                sd = np.sqrt(np.clip(np.diag(r.cov), 0, None)) / span
                flag = bool(np.any(~np.isfinite(sd)) or np.any(sd > FLAG))
                errs.append(float(e.max()))
                iters.append(r.iterations)
                flagged += flag
                silent += bool(e.max() > FLAG and not flag)
            rows.append({"model": name, "unknowns": ", ".join(layout.names), "modes": n_used, "truth": label,
                         "sensitivity_px": sens, "cond": cond, "cond_scaled": cond_s,
                         "err_median_pct": 100 * float(np.median(errs)),
                         "err_max_pct": 100 * float(np.max(errs)), "iterations": float(np.median(iters)),
                         "flagged": flagged, "silent": silent, "trials": TRIALS,
                         "solve_ms": 1e3 * float(np.median(times))})
            print({k: (f"{v:.3g}" if isinstance(v, float) else v) for k, v in rows[-1].items()}, flush=True)
    return rows


def main() -> None:
    rows = [r for case in CASES for r in case_rows(*case)]

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        for model in dict.fromkeys(r["model"] + " / " + r["unknowns"] for r in rows):
            sel = [r for r in rows if r["model"] + " / " + r["unknowns"] == model]
            ax[0].plot([r["cond_scaled"] for r in sel], [max(r["err_median_pct"], 1e-4) for r in sel], "o",
                       label=model)
        ax[0].set_xscale("log")
        ax[0].set_yscale("log")
        ax[0].set_xlabel("condition number, Jacobi-scaled J^T J")
        ax[0].set_ylabel("worst parameter error, median (% range)")
        ax[0].axhline(100 * FLAG, color="grey", lw=0.6)
        ax[0].legend(fontsize=6)
        sel = [r for r in rows if r["model"] == "aluminium_beam" and r["unknowns"] == "s"]
        for lab in ("s lo", "s mid", "s hi"):
            rr = [r for r in sel if r["truth"] == lab]
            ax[1].plot([r["modes"] for r in rr], [r["cond"] for r in rr], "o-", label=f"aluminium beam, {lab}")
        ax[1].set_yscale("log")
        ax[1].set_xlabel("modes")
        ax[1].set_ylabel("condition number of J^T J")
        ax[1].legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("model", "model", "{}"), ("unknowns", "unknowns", "{}"), ("modes", "modes", "{}"),
            ("truth", "true point", "{}"), ("sensitivity_px", "px per 1 % of range (weakest)", "{:.2g}"),
            ("cond", "cond(J^T J)", "{:.2g}"),
            ("cond_scaled", "cond, Jacobi-scaled", "{:.2g}"),
            ("err_median_pct", "error median (% range)", "{:.3g}"), ("err_max_pct", "max", "{:.3g}"),
            ("iterations", "iterations", "{:g}"), ("flagged", "flagged", "{}"), ("silent", "silent", "{}"),
            ("trials", "of", "{}"), ("solve_ms", "solve (ms)", "{:.2f}")]
    save("lm_conditioning", rows, cols, "The LM normal equations' conditioning against modes and parameters",
         "`./run bench lm_conditioning` (see its docstring). 'error': the worst parameter's |estimate - truth| in % "
         "of its range; 'flagged': solves where some parameter's standard deviation exceeds 5 % of its range (the "
         "tracker reports those LOW_CONFIDENCE); 'silent': solves more than 5 % off with nothing flagged. "
         f"{TRIALS} solves per row, {NOISE_PX} px noise, start 10 % of each range off.", plot)


if __name__ == "__main__":
    main()
