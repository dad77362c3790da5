"""What the crossed beams' linear law costs against the thesis's St. Venant-Kirchhoff (issue 21, §5.4.1).

    ./run bench crossed_beams_law     # writes benchmarks/results/crossed_beams_law.{json,md,png}

The thesis's crossed beams are St. Venant-Kirchhoff; ours (model and full-order contact truth) are linear elastic.
Here one crossed beam (300 x 30 x 10 mm, E = 3.5 GPa, nu = 0.36, clamped at x = 0: the `crossed_beams` spec) is
solved on the contact truth's own mesh (quadratic tetrahedra 60 x 6 x 4, `synth/contact_truth.py:beam_solid`)
under the scene's press (a 5 mm patch load near the free end, where the probe presses) with both laws, at half,
once and twice the models' 15 N, with Newton (load steps) for SVK. Reported: the tip deflection of each, and the
linear solution's error against SVK over every mesh vertex (RMS relative to SVK's RMS, and the largest, mm): the
model error that the linear substitution adds to every crossed-beams figure at that load.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import save
from simreal_nodes.physics import materials
from simreal_nodes.synth.contact_truth import beam_solid

L, W, H = 0.3, 0.03, 0.01
E_MOD, NU = 3.5e9, 0.36
PRESS = (0.285, 0.015)  # the development scene's press point on the top face (15 mm from the tip, mid-width)
FORCES = (7.5, 15.0, 30.0)


def main():
    sup = [{"region": "xmin", "kind": "clamped"}]
    solids = {law: beam_solid(L, W, H, materials.make_material(law, E_MOD, NU), sup, (60, 6, 4), 2)
              for law in ("linear_elastic", "saint_venant_kirchhoff")}
    rows = []
    for F in FORCES:
        out = {}
        for law, s in solids.items():
            f = s.patch_load("zmax", [PRESS[0], PRESS[1], H], 0.005, [0.0, 0.0, -F])
            t0 = time.perf_counter()
            u, info = s.solve(f, steps=1 if law == "linear_elastic" else 5)
            out[law] = (s.vertex_displacement(u), time.perf_counter() - t0, info.newton_iterations)
        lin, svk = out["linear_elastic"][0], out["saint_venant_kirchhoff"][0]
        d = lin - svk
        rows.append(dict(
            force_N=F, tip_linear_mm=-1e3 * float(lin[:, 2].min()), tip_svk_mm=-1e3 * float(svk[:, 2].min()),
            rel_rms_pct=100 * float(np.sqrt(np.mean(np.sum(d ** 2, axis=1)) / np.mean(np.sum(svk ** 2, axis=1)))),
            max_mm=1e3 * float(np.max(np.linalg.norm(d, axis=1))),
            axial_max_mm=1e3 * float(np.max(np.abs(d[:, 0]))),
            newton_svk=int(out["saint_venant_kirchhoff"][2]),
            s_linear=out["linear_elastic"][1], s_svk=out["saint_venant_kirchhoff"][1]))
        print(rows[-1], flush=True)

    def plot(plt):
        fig, ax = plt.subplots(figsize=(5, 3.6))
        x = [r["force_N"] for r in rows]
        ax.plot(x, [r["rel_rms_pct"] for r in rows], "o-", label="linear vs SVK, RMS (% of SVK's)")
        ax.plot(x, [r["max_mm"] for r in rows], "s--", label="largest difference (mm)")
        ax.axvline(15.0, color="gray", lw=0.8, ls=":", label="the models' load")
        ax.set_xlabel("press force (N)")
        ax.legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("force_N", "force (N)", "{:.1f}"), ("tip_linear_mm", "tip, linear (mm)", "{:.3f}"),
            ("tip_svk_mm", "tip, SVK (mm)", "{:.3f}"), ("rel_rms_pct", "linear vs SVK: RMS (%)", "{:.2f}"),
            ("max_mm", "largest (mm)", "{:.3f}"), ("axial_max_mm", "largest along the beam (mm)", "{:.3f}"),
            ("newton_svk", "SVK Newton iterations", "{}"), ("s_linear", "linear (s)", "{:.1f}"),
            ("s_svk", "SVK (s)", "{:.1f}")]
    notes = ("One crossed beam on the contact truth's mesh (P2 tetrahedra 60 x 6 x 4), a 5 mm patch load at the "
             "development scene's press point. RMS over every mesh vertex of |u_linear - u_SVK|, relative to SVK's "
             "own RMS. The tip deflections agree; the difference is the beam's shortening along its length as it "
             "bends (and the linear law's rotation artefact), which grows with the square of the load.")
    save("crossed_beams_law", rows, cols, "The crossed beams' linear law against the thesis's St. Venant-Kirchhoff",
         notes, plot)


if __name__ == "__main__":
    main()
