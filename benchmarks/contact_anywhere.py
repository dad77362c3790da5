"""Contact anywhere (issue 21, item 3; the thesis's future work): a contact between the precomputed load points,
evaluated in the reduced space at the contact's own position, against snapping it to the nearest load point.
Both are scored against the full-order contact truth (`synth/contact_truth.py`) of the probe pressing the beam
there -- the reduced model is never its own reference.

    ./run bench contact_anywhere

Model: the crossed beam's intrusive PGD u(x; s_x, s_y) (load points on a 10 mm grid of the top face, its parameter
modes interpolated between them). Truth: P2 tetrahedra 60 x 6 x 4, a rigid sphere (r = 12 mm) pressing 3 mm, one
position at a time, with no second beam. For each probe position: the true displacement at the model's surface
nodes and the true force F; the model is evaluated at

- **snap**: the load point nearest the true force centroid (what Alg. 5.1 does);
- **anywhere**: the centroid itself (s_x, s_y continuous);

with the load scale either from the true force (F / 15 N: a force-driven contact) or fitted to the true
displacement by least squares (the shape's error alone). Reported: RMS over the surface nodes of the error,
in mm and in % of the true displacement's RMS. Positions: on the grid (control), half a step off in x, in y,
and in both (the worst case for snapping).
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import save
from simreal_nodes.physics import materials
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.rom.state import ModelState
from simreal_nodes.synth import contact_truth as CT

RADIUS, PRESS = 0.012, 0.003
XS = (0.10, 0.15, 0.20, 0.25, 0.28)  # on the 10 mm load grid
OFFSETS = {"on the grid": (0.0, 0.0), "half a step in x": (0.005, 0.0), "half a step in y": (0.0, 0.005),
           "half a step in x and y": (0.005, 0.005)}


def positions(W: float) -> list[tuple[str, np.ndarray]]:
    out = []
    for label, (dx, dy) in OFFSETS.items():
        for x in XS:
            for y in (0.01, 0.02) if dy == 0 else (0.01,):
                out.append((label, np.array([x + dx, y + dy])))
    return out


def main():
    m = load_model(cached_model("crossed_beams"), fields=["displacement"])
    L, W, H = (float(v) for v in m.points.max(axis=0))
    mat = materials.make_material(m.material["law"], m.material["E"], m.material["nu"])
    sup = [{k: v for k, v in bc.items() if v is not None} for bc in m.boundary_conditions]
    solid = CT.beam_solid(L, W, H, mat, sup, (60, 6, 4))
    pos = positions(W)
    P = np.array([p for _, p in pos])

    def select(X):
        top = np.abs(X[:, 2] - H) < 1e-7
        near = np.min(np.linalg.norm(X[:, None, :2] - P[None], axis=2), axis=1) < RADIUS + 1e-3
        return top & near

    body = CT.condense(solid, select, (0.0, 0.0, -1.0), m.points)
    sn = np.unique(np.asarray(m.surface).ravel())
    lp_xy = m.points[m.load_points][:, :2]
    F_model = float(m.loads.get("force_N", 1.0))
    rows = []
    for label, xy in pos:
        idx = np.flatnonzero(np.linalg.norm(body.cand[:, :2] - xy, axis=1) < RADIUS + 1e-3)
        prob = CT.SphereOnBodies(body, idx, RADIUS, (0.0, 0.0, -1.0))
        r = prob.solve(np.array([xy[0], xy[1], H + RADIUS - PRESS]))
        u_true = r.displacement["a"][sn]
        size = float(np.sqrt(np.mean(np.sum(u_true ** 2, axis=1))))
        cen = r.centroid["a"][:2]
        k = int(np.argmin(np.linalg.norm(lp_xy - cen, axis=1)))
        row = dict(where=label, x_mm=1e3 * xy[0], y_mm=1e3 * xy[1], force_N=r.total["a"],
                   snap_distance_mm=1e3 * float(np.linalg.norm(lp_xy[k] - cen)), true_rms_mm=1e3 * size)
        for name, mu in (("snap", lp_xy[k]), ("anywhere", cen)):
            u1 = m.deformation(ModelState(np.asarray(mu, dtype=np.float64), load_scale=1.0), nodes=sn)
            tau_fit = float(np.sum(u1 * u_true) / np.sum(u1 * u1))
            for how, tau in (("force", r.total["a"] / F_model), ("fit", tau_fit)):
                e = float(np.sqrt(np.mean(np.sum((tau * u1 - u_true) ** 2, axis=1))))
                row[f"{name}_{how}_mm"] = 1e3 * e
                row[f"{name}_{how}_pct"] = 100 * e / size
        rows.append(row)
        print(row, flush=True)

    summary = []
    for label in OFFSETS:
        rr = [r for r in rows if r["where"] == label]
        s = dict(where=label, positions=len(rr), snap_distance_mm=float(np.median([r["snap_distance_mm"] for r in rr])))
        for key in ("snap_force_pct", "anywhere_force_pct", "snap_fit_pct", "anywhere_fit_pct"):
            s[key] = float(np.median([r[key] for r in rr]))
            s[key.replace("_pct", "_max_pct")] = float(np.max([r[key] for r in rr]))
        summary.append(s)

    def plot(plt):
        fig, ax = plt.subplots(figsize=(8, 3.8))
        x = np.arange(len(summary))
        for j, (key, lab) in enumerate((("snap_force_pct", "snap, F/15 N"), ("anywhere_force_pct", "anywhere, F/15 N"),
                                        ("snap_fit_pct", "snap, fitted"), ("anywhere_fit_pct", "anywhere, fitted"))):
            ax.bar(x + (j - 1.5) * 0.2, [s[key] for s in summary], 0.2, label=lab)
        ax.set_xticks(x, [s["where"] for s in summary], fontsize=8)
        ax.set_ylabel("surface RMS error, % of the true |u| RMS (median)")
        ax.set_yscale("log")
        ax.legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("where", "probe position", "{}"), ("positions", "positions", "{}"),
            ("snap_distance_mm", "to the nearest load point (mm)", "{:.1f}"),
            ("snap_force_pct", "snap, F/15 N (%)", "{:.2f}"), ("snap_force_max_pct", "max", "{:.2f}"),
            ("anywhere_force_pct", "anywhere, F/15 N (%)", "{:.2f}"), ("anywhere_force_max_pct", "max", "{:.2f}"),
            ("snap_fit_pct", "snap, fitted (%)", "{:.2f}"), ("snap_fit_max_pct", "max", "{:.2f}"),
            ("anywhere_fit_pct", "anywhere, fitted (%)", "{:.2f}"), ("anywhere_fit_max_pct", "max", "{:.2f}")]
    notes = ("Surface RMS error of the reduced model against the full-order contact truth (P2 tetrahedra 60x6x4, "
             f"{body.info['dofs']} dofs), sphere r = {1e3 * RADIUS:.0f} mm "
             f"pressing {1e3 * PRESS:.0f} mm; median and max over the positions of each row; the per-position "
             "rows are in the JSON. 'snap': the nearest load point; 'anywhere': the true force centroid in the "
             "reduced space; load scale from the true force or fitted to the true displacement.")
    save("contact_anywhere", summary, cols, "Contact anywhere: off-grid contact in the reduced space against "
         "nearest-load-point snapping, scored against the full-order contact truth", notes, plot,
         extra={"positions": rows})


if __name__ == "__main__":
    main()
