"""Every seed object's model: offline build time, modes, and error versus number of modes
(displacement and stress, against the full-order snapshots); NI-PGD against HOSVD on the bunny's
(space x contact point x pseudo-time) tensors.

    ./run bench rom_models          (bunny / dragon need ../shared/data; about 15 minutes in all)
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import save
from simreal_nodes.rom import build as B
from simreal_nodes.rom import nipgd
from simreal_nodes.rom.build import build_model, data_path, load_spec

SPECS = ["aluminium_beam", "aluminium_beam_E", "crossed_beams", "foam_beam", "joint_boot", "bunny", "dragon"]


def main():
    B.KEEP_SNAPSHOTS = True
    rows, curves, hosvd_rows = [], {}, []
    for name in SPECS:
        spec = load_spec(name + ".yaml")
        if spec["kind"] == "probe_nipgd" and not data_path(spec["surface"]).exists():
            print(f"skipping {name}: {data_path(spec['surface'])} is absent")
            continue
        t0 = time.perf_counter()
        model = build_model(spec)
        tb = time.perf_counter() - t0
        for fname in ("displacement", "stress"):
            f = model.fields[fname]
            e = f.error_vs_modes
            if e is None:
                continue
            curves[f"{name}/{fname}"] = e.tolist()
            rows.append({"object": name, "field": fname, "method": model.provenance.get("method", "").split(" (")[0],
                         "nodes": model.n_nodes, "params": ", ".join(a.name for a in model.axes), "modes": f.n_modes,
                         "err_1": e[0], "err_5": e[min(4, len(e) - 1)], "err_10": e[min(9, len(e) - 1)],
                         "err_last": e[-1],
                         "build_s": tb})
        snaps = getattr(model, "snapshots", None)
        if name == "bunny" and snaps is not None:
            U = snaps["displacement"]
            A = U.reshape((-1,) + U.shape[2:])
            cp = nipgd.nipgd(A, max_terms=40, tol=1e-6)
            for n in (5, 10, 20, 40):
                if n <= cp.n_terms:
                    storage = n * sum(A.shape)
                    hosvd_rows.append({"method": f"NI-PGD {n} terms", "storage": storage,
                                       "error": float(cp.errors[n - 1])})
            for r in ((10, 8, 6), (20, 12, 8), (40, 16, 11)):
                t = nipgd.hosvd(A, ranks=list(r))
                hosvd_rows.append({"method": f"HOSVD ranks {r}", "storage": t.storage,
                                   "error": float(np.linalg.norm(t.full() - A) / np.linalg.norm(A))})
    cols = [("object", "object", "{}"), ("field", "field", "{}"), ("method", "method", "{}"), ("nodes", "nodes", "{}"),
            ("params", "parameters", "{}"), ("modes", "modes", "{}"), ("err_1", "error 1 mode", "{:.2e}"),
            ("err_5", "5 modes", "{:.2e}"), ("err_10", "10 modes", "{:.2e}"), ("err_last", "all modes", "{:.2e}"),
            ("build_s", "build (s)", "{:.1f}")]

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
        for k, e in curves.items():
            a = ax[0] if k.endswith("displacement") else ax[1]
            a.semilogy(np.arange(1, len(e) + 1), e, "o-", ms=3, label=k.split("/")[0])
        for a, t in zip(ax, ("displacement", "stress")):
            a.set_xlabel("modes")
            a.set_ylabel(f"relative {t} error vs full order")
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=8)
        return fig

    notes = ("Errors are relative Frobenius norms over the full-order snapshots "
             "(PGD: FEM solves at every k-th load position).")
    if hosvd_rows:
        notes += ("\n\nNI-PGD vs HOSVD on the bunny displacement tensor (space x contact point x pseudo-time), "
                  "storage in floats:\n\n| method | storage | error |\n|---|---|---|\n"
                  + "\n".join(f"| {r['method']} | {r['storage']} | {r['error']:.2e} |" for r in hosvd_rows))
    save("rom_models", rows, cols, "Seed models: error versus number of modes and build time", notes, plot,
         extra={"curves": curves, "nipgd_vs_hosvd": hosvd_rows})


if __name__ == "__main__":
    main()
