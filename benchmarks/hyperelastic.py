"""Hyperelastic laws into large strain and compression, and the load-step count (issue 20, section 2).

    ./run bench hyperelastic      # writes benchmarks/results/hyperelastic.{json,md,png}

**Uniaxial stress, against its analytic solution.** A cube (side 20 mm, quadratic hexahedra 2 x 2 x 2) rests on
three sliding supports (x = 0, y = 0 and z = 0 each hold their normal component only), so its deformation is
homogeneous; a dead nominal traction P (force per reference area) pulls or pushes its x = a face. With stretch a
along x and b across, the first Piola-Kirchhoff stress of each law with the lateral faces free gives

- Saint Venant-Kirchhoff: S = lambda tr(E) I + 2 mu E; free sides make E_yy = -nu E_xx, so
  P_xx = a E (a^2 - 1) / 2. In compression it peaks at a = 1/sqrt(3) with |P| = E / (3 sqrt 3) = 0.192 E: a
  larger compressive load has **no** equilibrium at all (the law softens to zero stiffness and then negative);
- compressible neo-Hookean (``materials.NeoHookean``): P = mu (F - F^-T) + lambda ln(J) F^-T with F = diag(a, b, b):
  the free sides give mu (b^2 - 1) + lambda ln(a b^2) = 0 for b, then P_xx = mu (a - 1/a) + lambda ln(a b^2) / a.
  It carries any compression (J -> 0 costs infinite energy).

The reference stretch for each load comes from these scalar equations (scipy's brentq), not from the FEM code.
Each row: the FEM stretch, its error, the Newton iterations and sub-steps it needed, the time, and the failure
message where Newton could not reach the load (expected past 0.192 E for SVK; a wrong answer there would be the
bug).

**The load-step count.** The hardest converged cases (neo-Hookean at 60 % compression; the cantilever of
`benchmarks/stability.py` bent to 60 % of its length, both laws) solved with 1 to 50 load steps: the solver halves
a step that Newton cannot finish, so fewer steps cost sub-steps, not answers; the table shows the iterations,
accepted increments, time and the difference from the 50-step answer.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import brentq

from benchmarks.common import save
from simreal_nodes.errors import FemError
from simreal_nodes.physics import fem, materials, meshes

A = 0.02  # cube side, metres
E_MOD, NU = 1e6, 0.3  # a foam-like solid; the stretch depends on P / E only
COMPRESSION = [0.01, 0.05, 0.1, 0.15, 0.18, 0.19, 0.2, 0.3, 0.6, 1.0]  # nominal stress / E
TENSION = [0.1, 0.5, 1.0, 2.0]
STEPS = [1, 2, 5, 10, 20, 50]


def _lame() -> tuple[float, float]:
    return E_MOD * NU / ((1 + NU) * (1 - 2 * NU)), E_MOD / (2 * (1 + NU))


def svk_stretch(p_over_E: float) -> float:
    """Stretch a for the nominal stress P = p_over_E * E (negative: compression); NaN where none exists."""
    f = lambda a: a * (a * a - 1) / 2 - p_over_E  # noqa: E731  P_xx / E
    if p_over_E < -1 / (3 * np.sqrt(3)):
        return float("nan")
    lo, hi = (1 / np.sqrt(3), 1.0) if p_over_E < 0 else (1.0, 10.0)
    return float(brentq(f, lo, hi, xtol=1e-14))


def nh_stretch(p_over_E: float) -> float:
    lam, mu = _lame()

    def lateral(a: float) -> float:
        return brentq(lambda b: mu * (b * b - 1) + lam * np.log(a * b * b), 1e-6, 1e3, xtol=1e-15)

    def P(a: float) -> float:
        b = lateral(a)
        return (mu * (a - 1 / a) + lam * np.log(a * b * b) / a) / E_MOD - p_over_E

    return float(brentq(P, 1e-3, 1.0, xtol=1e-14) if p_over_E < 0 else brentq(P, 1.0, 20.0, xtol=1e-14))


def cube(law: str, p_over_E: float, steps: int = 10) -> dict:
    mesh = meshes.box(A, A, A, (2, 2, 2), "hex")
    sup = [{"region": f"{ax}min", "kind": "sliding", "component": k} for k, ax in enumerate("xyz")]
    solid = fem.Solid(mesh, materials.make_material(law, E_MOD, NU), 2, sup)
    f = solid.traction("xmax", (p_over_E * E_MOD, 0.0, 0.0))
    t0 = time.perf_counter()
    out: dict = {"law": law, "load": p_over_E, "steps": steps}
    try:
        u, info = solid.solve(f, steps=steps)
        V = solid.vertex_displacement(u)
        end = np.abs(mesh.p[0] - A) < 1e-9
        out.update(stretch=float(1 + V[end, 0].mean() / A), newton=int(info.newton_iterations),
                   increments=int(info.steps), failure="",
                   spread=float(np.ptp(V[end, 0]) / A))  # a homogeneous state has none
    except FemError as e:
        out.update(stretch=float("nan"), newton=None, increments=None, failure=str(e)[:150], spread=float("nan"))
    out["ms"] = 1e3 * (time.perf_counter() - t0)
    return out


def rows_uniaxial() -> list[dict]:
    rows = []
    for sign, loads in ((-1, COMPRESSION), (1, TENSION)):
        for p in loads:
            for law, ref in (("saint_venant_kirchhoff", svk_stretch), ("neo_hookean", nh_stretch)):
                r = cube(law, sign * p)
                a_ref = ref(sign * p)
                err = 100 * (r["stretch"] - a_ref) / abs(1 - a_ref) if np.isfinite(a_ref) else float("nan")
                r.update(case="compression" if sign < 0 else "tension", reference=a_ref, error_pct=err,
                         expected="no equilibrium exists" if not np.isfinite(a_ref) else "")
                rows.append(r)
                print({k: r[k] for k in ("case", "law", "load", "reference", "stretch", "newton", "failure")},
                      flush=True)
    return rows


def rows_steps() -> list[dict]:
    from benchmarks.stability import H, cantilever, timoshenko

    rows = []
    L = 20 * H
    load = 0.6 * L / timoshenko(L, 1e7, 0.3, load=1.0)
    cases = [("compression 60 % (cube)", "neo_hookean", lambda n: cube("neo_hookean", -nh_to_load(0.4), n), "stretch")]
    for law in ("saint_venant_kirchhoff", "neo_hookean"):
        cases.append(("cantilever bent to 60 % of L", law,
                      lambda n, law=law: cantilever(L, 1e7, 0.3, "hex", 2, (20, 2, 2), law, load, n), "deflection"))
    for case, law, fn, key in cases:
        runs = {n: fn(n) for n in STEPS}
        ref = runs[STEPS[-1]][key]
        for n in STEPS:
            r = runs[n]
            rows.append({"case": case, "law": law, "steps": n, "value": r[key],
                         "difference_pct": 100 * abs(r[key] - ref) / abs(ref) if np.isfinite(r[key]) else float("nan"),
                         "newton": r.get("newton"), "increments": r.get("increments", ""), "ms": r["ms"],
                         "failure": r.get("failure", "")})
            print(rows[-1], flush=True)
    return rows


def nh_to_load(stretch: float) -> float:
    """The compressive nominal stress / E that brings the neo-Hookean cube to ``stretch``."""
    return float(brentq(lambda p: nh_stretch(-p) - stretch, 1e-6, 50.0, xtol=1e-12))


def main() -> None:
    uni = rows_uniaxial()
    steps = rows_steps()
    rows = [{"table": "uniaxial", **r} for r in uni] + [{"table": "steps", **r} for r in steps]

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        for law, mk in (("saint_venant_kirchhoff", "o"), ("neo_hookean", "s")):
            sel = sorted([r for r in uni if r["law"] == law], key=lambda r: r["load"])
            ax[0].plot([r["stretch"] for r in sel], [r["load"] for r in sel], mk, label=f"{law} (FEM)")
        a = np.linspace(0.05, 3.0, 300)
        ax[0].plot(a, a * (a * a - 1) / 2, "-", lw=0.8, label="SVK analytic")
        ax[0].plot([nh_stretch(p) for p in np.linspace(-1.0, 2.0, 61)], np.linspace(-1.0, 2.0, 61), "--", lw=0.8,
                   label="neo-Hookean analytic")
        ax[0].axhline(-1 / (3 * np.sqrt(3)), color="grey", lw=0.6)
        ax[0].set_xlabel("stretch a")
        ax[0].set_ylabel("nominal stress P / E")
        ax[0].set_ylim(-1.1, 2.1)
        ax[0].legend(fontsize=7)
        for case in sorted({r["case"] + " / " + r["law"] for r in steps}):
            sel = [r for r in steps if r["case"] + " / " + r["law"] == case]
            ax[1].plot([r["steps"] for r in sel], [r["ms"] / 1e3 for r in sel], "o-", label=case)
        ax[1].set_xscale("log")
        ax[1].set_xlabel("load steps asked for")
        ax[1].set_ylabel("solve time (s)")
        ax[1].legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("table", "table", "{}"), ("case", "case", "{}"), ("law", "law", "{}"),
            ("load", "P / E", "{:g}"), ("reference", "stretch, analytic", "{:.5f}"),
            ("stretch", "stretch, FEM", "{:.5f}"), ("error_pct", "error (% of 1 - a)", "{:+.2g}"),
            ("steps", "load steps", "{}"), ("value", "result", "{:.5g}"),
            ("difference_pct", "vs 50 steps (%)", "{:.2g}"), ("newton", "Newton iterations", "{}"),
            ("increments", "increments accepted", "{}"), ("ms", "time (ms)", "{:.0f}"),
            ("expected", "analytic says", "{}"), ("failure", "failure", "{}")]
    save("hyperelastic", rows, cols, "Hyperelastic laws into large strain and compression; the load-step count",
         "`./run bench hyperelastic` (see its docstring). Uniaxial rows: a cube of quadratic hexahedra on three "
         "sliding supports under a dead nominal traction, E = 1 MPa, nu = 0.3, 10 load steps; the reference is the "
         "analytic homogeneous solution of each law. Load-step rows: the same solver asked for 1-50 steps; "
         "'result' is the stretch (cube) or the end deflection in metres (cantilever); 'increments accepted' counts "
         "the sub-steps the solver took after halving the ones Newton could not finish. Time on a 2-core CPU.",
         plot)


if __name__ == "__main__":
    main()
