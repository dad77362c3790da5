"""Online cost of the reduced model: u(x, mu) + du/dmu versus number of modes and of nodes, and the
offline build time versus mesh size (intrusive PGD of a foam-beam-sized linear beam, up to the
thesis foam mesh of 18,938 nodes). Target: <= 1 ms for 19 modes on 18,938 nodes.

    ./run bench rom_eval
"""

from __future__ import annotations

import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

from benchmarks.common import save
from simreal_nodes.rom.build import build_model, load_spec

SPEC = """
simreal_model_spec: 1
name: foam_linear_{n}
kind: beam_pgd
material: {{law: linear_elastic, E: 1.1e+5, nu: 0.2}}
geometry: {{length: 0.7975, width: 0.2, height: 0.105}}
mesh: {{cells: [{cx}, {cy}, {cz}], element: hex, order: 1}}
supports: [{{region: {{face: zmin, box: [[0.0, 0.04], null, null]}}, kind: pinned}},
           {{region: {{face: zmin, box: [[0.7575, 0.7975], null, null]}}, kind: sliding, component: z}}]
load: {{force: 15.0, where: centreline, x_range: [0.1, 0.6975]}}
pgd: {{max_modes: 30, tol: 1.0e-9, fixed_point_iterations: 25}}
validation_every: 8
"""

MESHES = [(20, 4, 3), (40, 10, 6), (60, 14, 8), (82, 18, 11)]  # the last: 83 x 19 x 12 = 18,924 nodes


def timeit(fn, n=None) -> float:
    fn()
    reps = n or 200
    t = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t) / reps * 1e3


def main():
    rows, build_rows = [], []
    with tempfile.TemporaryDirectory() as d:
        for cx, cy, cz in MESHES:
            f = Path(d) / f"m{cx}.yaml"
            f.write_text(textwrap.dedent(SPEC.format(n=cx, cx=cx, cy=cy, cz=cz)))
            spec = load_spec(f)
            t0 = time.perf_counter()
            model = build_model(spec)
            tb = time.perf_counter() - t0
            fld = model.field("displacement")
            n = model.n_nodes
            build_rows.append({"nodes": n, "dofs": 3 * n, "modes": fld.n_modes, "build_s": tb,
                               "err_19": float(fld.error_vs_modes[min(18, fld.n_modes - 1)])})
            rng = np.random.default_rng(0)
            sub300 = np.sort(rng.choice(n, min(300, n), replace=False))
            surf = np.unique(model.surface)
            for m in (1, 5, 10, 19, min(30, fld.n_modes)):
                if m > fld.n_modes:
                    continue
                for label, nodes in (("all", None), ("surface", surf), ("300 tracked", sub300)):
                    v = fld.view(nodes, m)
                    mu = [0.3712]
                    rows.append({"nodes": n, "subset": label, "n_eval": v.n_sel, "modes": m,
                                 # timeit calls each lambda before the loop moves on: v and mu are this pass's
                                 "u_ms": timeit(lambda: v.evaluate(mu)),  # noqa: B023
                                 "u_du_ms": timeit(lambda: v.evaluate_with_jacobian(mu))})  # noqa: B023
    cols = [("nodes", "mesh nodes", "{}"), ("subset", "evaluated", "{}"), ("n_eval", "nodes evaluated", "{}"),
            ("modes", "modes", "{}"), ("u_ms", "u(x,mu) ms", "{:.3f}"), ("u_du_ms", "u + du/dmu ms", "{:.3f}")]

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(11, 4))
        for n in sorted({r["nodes"] for r in rows}):
            sel = [r for r in rows if r["nodes"] == n and r["subset"] == "all"]
            ax[0].plot([r["modes"] for r in sel], [r["u_du_ms"] for r in sel], "o-", label=f"{n} nodes")
        ax[0].axhline(1.0, color="k", ls="--", lw=0.8, label="1 ms target")
        ax[0].set_xlabel("modes")
        ax[0].set_ylabel("u + du/dmu, all nodes (ms)")
        ax[0].legend()
        ax[1].plot([r["nodes"] for r in build_rows], [r["build_s"] for r in build_rows], "s-")
        ax[1].set_xlabel("mesh nodes")
        ax[1].set_ylabel("offline PGD build (s)")
        ax[1].set_xscale("log")
        ax[1].set_yscale("log")
        return fig

    target = [r for r in rows if r["nodes"] == build_rows[-1]["nodes"] and r["subset"] == "all" and r["modes"] == 19]
    notes = ("Online evaluation is one (1 + n_params) x modes by modes x (3 nodes) product per call "
             "(FieldView). Offline: intrusive PGD with one sparse LU reused for every fixed-point step.\n\n"
             "Build time versus mesh size:\n\n"
             + "\n".join(["| nodes | dofs | modes | build (s) | error at 19 modes |", "|---|---|---|---|---|"]
                         + [f"| {r['nodes']} | {r['dofs']} | {r['modes']} | {r['build_s']:.1f} | {r['err_19']:.2e} |"
                            for r in build_rows])
             + (f"\n\nTarget check: 19 modes on {target[0]['nodes']} nodes: "
                f"u + du/dmu in {target[0]['u_du_ms']:.3f} ms." if target else ""))
    save("rom_eval", rows, cols, "Reduced model: online evaluation time and offline build time", notes, plot,
         extra={"build": build_rows})


if __name__ == "__main__":
    main()
