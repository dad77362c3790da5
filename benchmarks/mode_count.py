"""PGD and POD mode counts against an independent truth: where added modes stop helping (issue 20, section 2).

    ./run bench mode_count                 # development seeds 0-5 of the scene family (4 and 5: cantilevers)
    python -m benchmarks.mode_count --seeds 0-7

`benchmarks/results/rom_models.md` gives each seed model's error against the full-order solves *of its own mesh*:
that error keeps falling with every mode (to 1e-5 and below), because it measures only the truncation. What a user
needs is where the modes stop paying against the physics. Each family scene (`synth/family.py`) carries its own
independent full-order truth (P2 tetrahedra on a finer mesh, the weight as a pressure on its footprint) beside the
reduced model the tracker fits (quadratic hexahedra, a nodal force: `rom/build.py:build_beam_pgd`). For n = 1 ... 19
PGD modes this benchmark reports, over the truth's load positions and the model's surface nodes:

- ``rel_l2``: ||u_model(s) - u_truth(s)|| / ||u_truth(s)|| (median over the positions);
- ``bias``: the load position whose n-mode displacement best fits the truth's, minus the true one, in % of the span
  (what a tracker seeing every surface point exactly would report: the load error the model alone causes);
- ``own mesh``: the PGD's error against its own mesh's solves (the builder's validation set), for contrast;
- ``POD``: the truth projected onto the first n POD modes of the model's snapshots (the SVD of its displacement
  at every tabulated load position): the best any n-term basis from these snapshots could do;
- the time to evaluate the field at 1000 nodes with n modes.

The seeds are development seeds (0-49): nothing here chose a default.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.common import save
from benchmarks.family import parse_seeds
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.synth.family import default_camera, draw, scaled_force, spec_path, truth_for
from simreal_nodes.synth.truth import model_error

MODES = [1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 19]


def seed_rows(seed: int) -> list[dict]:
    cam = default_camera(640, 480)
    d = scaled_force(draw(seed), max(cam.fx, cam.fy))
    truth = truth_for(d)
    model = load_model(cached_model(str(spec_path(d))))
    fld = model.field("displacement")
    ax = model.axis("s")
    nodes = np.unique(np.asarray(model.surface).ravel())
    emb = truth.embed(model.points[nodes])
    keep = [k for k in range(0, len(truth.s), 2) if ax.contains(float(truth.s[k]))]
    UT = np.stack([np.einsum("nk,nkc->nc", emb[1], truth.U[k][emb[0]]).ravel() for k in keep])  # (P, 3n)
    span = d.span
    snaps = np.stack([fld.evaluate([g], nodes=nodes).ravel() for g in ax.values])  # (n_s, 3n), all modes
    _, _, Vt = np.linalg.svd(snaps, full_matrices=False)
    rows = []
    for n in [m for m in MODES if m <= fld.n_modes]:
        # every second tabulated position; the best fit's resolution 1/4000 of the range
        err = model_error(model, truth, n_fit=4001, every=2, n_modes=n)
        rel, bias = err.rel_l2, np.abs(err.bias) / span * 100
        B = Vt[:n]
        pod = [np.linalg.norm(ut - (ut @ B.T) @ B) / max(np.linalg.norm(ut), 1e-300) for ut in UT]
        big = fld.view(np.resize(np.arange(model.n_nodes), 1000), n)
        times = []
        for s in np.linspace(*ax.range, 50):
            t0 = time.perf_counter()
            big.evaluate([float(s)])
            times.append(time.perf_counter() - t0)
        us = float(np.median(times)) * 1e6
        own = getattr(fld, "error_vs_modes", None)
        rows.append({"seed": seed, "support": d.support, "slenderness": round(d.slenderness, 1), "modes": n,
                     "of": fld.n_modes, "rel_l2_pct": float(100 * np.median(rel)),
                     "bias_pct_span": float(np.median(bias)), "bias_max_pct_span": float(np.max(bias)),
                     "own_mesh_pct": float(100 * own[n - 1]) if own is not None and len(own) >= n else float("nan"),
                     "pod_pct": float(100 * np.median(pod)), "eval_us": us})
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0-5", help="development seeds (0-49)")
    a = ap.parse_args()
    seeds = parse_seeds(a.seeds)
    assert all(s < 50 for s in seeds), "development seeds only (0-49)"
    rows = [r for s in seeds for r in seed_rows(s)]

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        for s in seeds:
            sel = [r for r in rows if r["seed"] == s]
            x = [r["modes"] for r in sel]
            line, = ax[0].plot(x, [r["rel_l2_pct"] for r in sel], "o-", label=f"seed {s}: PGD vs truth")
            ax[0].plot(x, [r["own_mesh_pct"] for r in sel], ":", color=line.get_color(), label=f"seed {s}: own mesh")
            ax[1].plot(x, [r["bias_pct_span"] for r in sel], "o-", color=line.get_color(), label=f"seed {s}")
        ax[0].set_yscale("log")
        ax[0].set_ylabel("displacement error (%)")
        ax[1].set_yscale("log")
        ax[1].set_ylabel("best-fit load position error (% span)")
        for a_ in ax:
            a_.set_xlabel("PGD modes")
        ax[0].legend(fontsize=6)
        fig.tight_layout()
        return fig

    cols = [("seed", "seed", "{}"), ("support", "support", "{}"), ("slenderness", "L/h", "{}"),
            ("modes", "modes", "{}"), ("of", "of", "{}"), ("rel_l2_pct", "error vs truth, median (%)", "{:.3g}"),
            ("pod_pct", "POD projection vs truth (%)", "{:.3g}"), ("own_mesh_pct", "error vs own mesh (%)", "{:.2g}"),
            ("bias_pct_span", "load bias median (% span)", "{:.3g}"), ("bias_max_pct_span", "max", "{:.3g}"),
            ("eval_us", "evaluation, 1000 nodes (us, median)", "{:.0f}")]
    save("mode_count", rows, cols, "PGD and POD mode counts against an independent truth",
         f"`python -m benchmarks.mode_count --seeds {a.seeds}` (see its docstring): development seeds of the RGB-D "
         "scene family; the truth is each scene's own full-order solve (P2 tetrahedra, finer, a pressure load), the "
         "model the one its tracker fits. Medians over every second tabulated load position of the truth.", plot)


if __name__ == "__main__":
    main()
