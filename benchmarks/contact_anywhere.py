"""Contact anywhere (issue 21, item 3; the thesis's future work): a contact between the precomputed load points,
evaluated in the reduced space at the contact's own position, against snapping it to the nearest load point.
Both are scored against the full-order contact truth (`synth/contact_truth.py`) of the probe pressing the beam
there -- the reduced model is never its own reference.

    ./run bench contact_anywhere            # the beam and the bunny (its full-order truths: minutes)
    ./run bench contact_anywhere --quick    # the beam only

Model: the crossed beam's intrusive PGD u(x; s_x, s_y) (load points on a 10 mm grid of the top face, its parameter
modes interpolated between them). Truth: P2 tetrahedra 60 x 6 x 4, a rigid sphere (r = 12 mm) pressing 3 mm, one
position at a time, with no second beam. For each probe position: the true displacement at the model's surface
nodes and the true force F; the model is evaluated at

- **snap**: the load point nearest the true force centroid (what Alg. 5.1 does);
- **anywhere**: the centroid itself (s_x, s_y continuous);

with the load scale either from the true force (F / 15 N: a force-driven contact) or fitted to the true
displacement by least squares (the shape's error alone). Reported: RMS over the surface nodes of the error,
in mm and in % of the true displacement's RMS. Positions: on the grid (control), half a step off in x, in y,
and in both (the worst case for snapping). Also:

- **the tracker's position**: where `ContactTracker(anywhere=True)` (the collision node with `collision.anywhere`)
  puts the load from the probe's surface points, and the error the model makes there;
- **load grid density**: the off-grid error with the load positions thinned along x (10, 20, 40, 80 mm);
- **two contacts at once**: one contact solve with two spheres against the two reduced fields summed
  (superposition; the beam is linear);
- **the bunny** (decoupled neo-Hookean, NI-PGD over 16 discrete load points): probes between the load points, the
  large-strain truth of the probe scenes, against snapping and against blending the nearest load points' fields,
  and the truth's own departure from linearity (why superposition is not offered there).
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.optimize as so
from scipy.spatial import cKDTree

from benchmarks.common import markdown_table, save
from simreal_nodes.collision.contact import ContactTracker
from simreal_nodes.physics import materials
from simreal_nodes.rom.build import cached_model, load_spec
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.rom.separated import Axis, SeparatedField
from simreal_nodes.rom.state import ModelState
from simreal_nodes.synth import contact_truth as CT

RADIUS, PRESS = 0.012, 0.003
BUNNY_POINTS = 4  # probes between the bunny's load points
PAIR_FORCE = 6.0  # newtons on each probe of a pair (the model's load: 15 N)
N_PAIRS = 8  # two-contact cases: pairs of off-grid positions 40 mm apart or more
# the tracker on the pairs: probes seen 1 mm inside their surface (delta), load steps of 1 % of the model's 15 N,
# pseudo-times up to 2 (30 N: the larger probe of a pair would take 14-20 N alone; the model is linear), 3 mm of
# approach over 40 frames, then 260 frames held (the slowest, a probe alone at 20 N, has settled by frame 170),
# scored over the last 130
PAIR_DELTA, PAIR_STEP, PAIR_TAU_MAX, PAIR_APPROACH, PAIR_DESCENT, PAIR_HOLD = 0.001, 0.01, 2.0, 0.003, 40, 260
TRACKERS = ("coupled", "one", "independent")
THIN = (1, 2, 4, 8)  # the load grid along x: every load position, every 2nd, 4th, 8th
# the bunny's pseudo-times: also fine near 0 (a probe 0.5 mm past the scan can take under 1 % of the model's 4 N)
TAUS_FINE = np.unique(np.r_[np.linspace(0.0, 1.0, 101), np.geomspace(1e-4, 0.05, 80)])
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the beam only (the bunny's truths take minutes)")
    args = ap.parse_args(argv)
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
    solved = []
    for label, xy in pos:
        idx = np.flatnonzero(np.linalg.norm(body.cand[:, :2] - xy, axis=1) < RADIUS + 1e-3)
        prob = CT.SphereOnBodies(body, idx, RADIUS, (0.0, 0.0, -1.0))
        center = np.array([xy[0], xy[1], H + RADIUS - PRESS])
        r = prob.solve(center)
        u_true = r.displacement["a"][sn]
        size = _rms(u_true)
        cen = r.centroid["a"][:2]
        k = int(np.argmin(np.linalg.norm(lp_xy - cen, axis=1)))
        # the tracker's own position: Alg. 5.1 with contact anywhere, fed the probe's surface as the depth sees it
        # (the sphere where it first comes within delta of the beam, 2 mm above the top face)
        tr = ContactTracker(m, np.eye(4), threshold=0.004, anywhere=True)
        st = tr.update(sphere_points(center + [0, 0, PRESS + 0.002], RADIUS))
        pos_tr = np.asarray(st.position[:2]) if st.in_contact else np.full(2, np.nan)
        row = dict(where=label, x_mm=1e3 * xy[0], y_mm=1e3 * xy[1], force_N=r.total["a"],
                   snap_distance_mm=1e3 * float(np.linalg.norm(lp_xy[k] - cen)), true_rms_mm=1e3 * size,
                   tracker_position_mm=1e3 * float(np.linalg.norm(pos_tr - cen)))
        solved.append((xy, center, idx, r, u_true, cen))
        for name, mu in (("snap", lp_xy[k]), ("anywhere", cen), ("tracker", pos_tr)):
            u1 = m.deformation(ModelState(np.asarray(mu, dtype=np.float64), load_scale=1.0), nodes=sn)
            tau_fit = float(np.sum(u1 * u_true) / np.sum(u1 * u1))
            for how, tau in (("force", r.total["a"] / F_model), ("fit", tau_fit)):
                e = _rms(tau * u1 - u_true)
                row[f"{name}_{how}_mm"] = 1e3 * e
                row[f"{name}_{how}_pct"] = 100 * e / size
        rows.append(row)
        print(row, flush=True)

    summary = []
    for label in OFFSETS:
        rr = [r for r in rows if r["where"] == label]
        s = dict(where=label, positions=len(rr), snap_distance_mm=float(np.median([r["snap_distance_mm"] for r in rr])))
        s["tracker_position_mm"] = float(np.median([r["tracker_position_mm"] for r in rr]))
        for key in ("snap_force_pct", "anywhere_force_pct", "tracker_force_pct", "snap_fit_pct", "anywhere_fit_pct",
                    "tracker_fit_pct"):
            s[key] = float(np.median([r[key] for r in rr]))
            s[key.replace("_pct", "_max_pct")] = float(np.max([r[key] for r in rr]))
        summary.append(s)
    off = [(xy, r, u, cen) for (xy, _, _, r, u, cen), (label, _) in zip(solved, pos) if label != "on the grid"]
    grid = grid_density(m, sn, off)
    pairs = two_contacts(m, body, sn, solved, H)
    bunny, bunny_info = ([], {}) if args.quick else bunny_rows()

    def plot(plt):
        fig, ax = plt.subplots(1, 4 if bunny else 3, figsize=(21 if bunny else 16, 3.8))
        a = ax[0]
        x = np.arange(len(summary))
        for j, (key, lab) in enumerate((("snap_force_pct", "snap, F/15 N"), ("anywhere_force_pct", "anywhere, F/15 N"),
                                        ("tracker_force_pct", "tracker's position, F/15 N"),
                                        ("snap_fit_pct", "snap, fitted"), ("anywhere_fit_pct", "anywhere, fitted"))):
            a.bar(x + (j - 2) * 0.16, [s[key] for s in summary], 0.16, label=lab)
        a.set_xticks(x, [s["where"] for s in summary], fontsize=7)
        a.set_ylabel("surface RMS error, % of the true |u| RMS (median)")
        a.set_yscale("log")
        a.legend(fontsize=6)
        b = ax[1]
        for method, mk in (("snap", "o-"), ("anywhere", "s-")):
            rr = [g for g in grid if g["method"] == method]
            b.plot([g["grid_mm"] for g in rr], [g["fit_pct"] for g in rr], mk, label=f"{method}, fitted")
            b.plot([g["grid_mm"] for g in rr], [g["force_pct"] for g in rr], mk.replace("-", "--"),
                   label=f"{method}, F/15 N")
        b.set_xscale("log", base=2)
        b.set_yscale("log")
        b.set_xlabel("load grid spacing along the beam (mm)")
        b.set_ylabel("off-grid surface RMS error (% , median)")
        b.legend(fontsize=7)
        if bunny:
            c = ax[2]
            for k, mk in ((1, "o"), (2, "s"), (3, "^"), (4, "v")):
                rr = [r for r in bunny if r["method"] == ("snap" if k == 1 else f"blend of {k}")]
                c.plot([r["point"] for r in rr], [r["local_mm"] for r in rr], mk + "-",
                       label="snap" if k == 1 else f"blend of {k}")
            rr = [r for r in bunny if r["method"] == "snap"]
            c.plot([r["point"] for r in rr], [r["truth_local_mm"] for r in rr], "k:", label="true |u| (local RMS)")
            c.set_xticks([r["point"] for r in rr])
            c.set_xlabel("bunny: off-grid probe")
            c.set_ylabel("RMS error within 20 mm of the contact (mm)")
            c.legend(fontsize=7)
        d = ax[-1]
        x = np.arange(len(pairs))
        for j, (key, lab) in enumerate((("anywhere_pct", "model at the true forces"),
                                        ("tracker_coupled_pct", "tracker, two contacts"),
                                        ("tracker_independent_pct", "two trackers summed"),
                                        ("tracker_one_pct", "tracker, one contact"))):
            d.bar(x + (j - 1.5) * 0.2, [p[key] for p in pairs], 0.2, label=lab)
        d.set_xticks(x, [p["x_mm"] for p in pairs], fontsize=6)
        d.set_xlabel("two probes at once: x of each (mm)")
        d.set_ylabel("surface RMS error, % of the true |u| RMS")
        d.set_yscale("log")
        d.legend(fontsize=6)
        fig.tight_layout()
        return fig

    cols = [("where", "probe position", "{}"), ("positions", "positions", "{}"),
            ("snap_distance_mm", "to the nearest load point (mm)", "{:.1f}"),
            ("tracker_position_mm", "tracker's position off (mm)", "{:.2f}"),
            ("snap_force_pct", "snap, F/15 N (%)", "{:.2f}"), ("snap_force_max_pct", "max", "{:.2f}"),
            ("anywhere_force_pct", "anywhere, F/15 N (%)", "{:.2f}"), ("anywhere_force_max_pct", "max", "{:.2f}"),
            ("tracker_force_pct", "tracker's position, F/15 N (%)", "{:.2f}"),
            ("tracker_force_max_pct", "max", "{:.2f}"),
            ("snap_fit_pct", "snap, fitted (%)", "{:.2f}"), ("snap_fit_max_pct", "max", "{:.2f}"),
            ("anywhere_fit_pct", "anywhere, fitted (%)", "{:.2f}"), ("anywhere_fit_max_pct", "max", "{:.2f}")]
    gcols = [("grid_mm", "load grid along x (mm)", "{:.0f}"), ("method", "method", "{}"),
             ("positions", "positions", "{}"), ("force_pct", "F/15 N (%)", "{:.2f}"),
             ("force_max_pct", "max", "{:.2f}"), ("fit_pct", "fitted (%)", "{:.2f}"), ("fit_max_pct", "max", "{:.2f}")]
    pcols = [("pair", "pair", "{}"), ("x_mm", "x (mm)", "{}"), ("y_mm", "y (mm)", "{}"),
             ("press_mm", "presses (mm)", "{}"), ("forces_N", "true forces, together (N)", "{}"),
             ("alone_N", "each alone (N)", "{}"),
             ("true_rms_mm", "true RMS (mm)", "{:.2f}"),
             ("single_sum_pct", "sum of single-probe truths (%)", "{:.2f}"),
             ("snap_pct", "snap, summed (%)", "{:.2f}"), ("anywhere_pct", "anywhere, summed (%)", "{:.2f}"),
             ("tracker_coupled_pct", "tracker, two contacts (%)", "{:.2f}"),
             ("tracker_independent_pct", "two trackers summed (%)", "{:.2f}"),
             ("tracker_one_pct", "tracker, one contact (%)", "{:.2f}")]
    bcols = [("point", "point", "{}"), ("nearest_mm", "nearest load point (mm)", "{:.0f}"),
             ("force_N", "true force (N)", "{:.2f}"), ("method", "method", "{}"), ("tau", "best tau", "{:.4f}"),
             ("rms_mm", "RMS err (mm)", "{:.4f}"), ("truth_rms_mm", "true RMS (mm)", "{:.4f}"),
             ("local_mm", "local err (mm)", "{:.4f}"), ("truth_local_mm", "true local (mm)", "{:.4f}"),
             ("linearity_pct", "|u(F) - 2 u(F/2)| (%)", "{:.1f}")]
    notes = ("Surface RMS error of the reduced model against the full-order contact truth (P2 tetrahedra 60x6x4, "
             f"{body.info['dofs']} dofs), sphere r = {1e3 * RADIUS:.0f} mm "
             f"pressing {1e3 * PRESS:.0f} mm; median and max over the positions of each row; the per-position "
             "rows are in the JSON. 'snap': the nearest load point; 'anywhere': the true force centroid in the "
             "reduced space; \"tracker's position\": where `ContactTracker(anywhere=True)` puts the load from the "
             "whole probe sphere's points 2 mm above the beam (a camera sees less: `collision.md`'s anywhere rows); "
             "load scale from the true force or fitted to the true displacement."
             "\n\n## Load grid density (the beam's off-grid positions)\n\n" + markdown_table(grid, gcols) + "\n\n"
             "The model's parameter modes sampled every 2nd, 4th, 8th load position along x (what a coarser load "
             "grid gives, without its offline cost), interpolated with the model's cubic splines; off-grid positions "
             "of the table above, the true force centroid."
             "\n\n## Two contacts at once (superposition, linear beam)\n\n" + markdown_table(pairs, pcols) + "\n\n"
             f"Two spheres pressing at once, on pairs of the off-grid positions at least 40 mm apart, each pressed "
             f"as deep as makes it carry {PAIR_FORCE:.0f} N with the other one pressing. One frictionless contact "
             "solve with both (the LCP over both "
             "spheres' candidate nodes), against the two models' displacements summed, each at its sphere's true "
             "force and centroid. 'sum of single-probe truths': each sphere's solve alone, summed: displacement-driven "
             "probes interact through the body (each takes less force when the other presses), so a tracker summing "
             "independent pseudo-times would be this far off; at the true forces a linear model superposes exactly "
             "up to its own error. Not valid for the bunny and the dragon (neo-Hookean, large strain: see below) "
             "nor for the St. Venant-Kirchhoff beams of the thesis: their contacts need the combined load "
             "precomputed (thesis §5.3).\n\n"
             "The tracker on the same pairs (Alg. 5.1 run over frames, `collision/contact.py`): each probe's points "
             f"(a sphere seen {1e3 * PAIR_DELTA:.0f} mm inside its surface: the sensor's margin that delta stands "
             f"for, delta = {1e3 * PAIR_DELTA:.0f} mm) come down {1e3 * PAIR_APPROACH:.0f} mm onto the beam over "
             f"{PAIR_DESCENT} frames to where the truth has it, then stay {PAIR_HOLD} frames; load steps of "
             f"{100 * PAIR_STEP:.0f} % of the model's 15 N, pseudo-times up to {PAIR_TAU_MAX:g} (so that no tracker "
             "is capped: the larger probe of a pair would take 14-20 N alone), anywhere on; the error is that of "
             "the surface averaged over the hold's last half, against the two-sphere truth. 'two contacts': one "
             "tracker with `max_contacts: 2` (each contact steps on the distance at its own probe with the beam at "
             "the summed deformation, measured from the drawn surface between the load points too); 'two trackers "
             "summed': one such tracker per probe, each seeing only its own, their deformations added (superposition "
             "without the coupling); 'one contact': the default tracker (`max_contacts: 1`, the distance measured at "
             "the load points), both probes in its points (100 % on pair 1: no deformation over the scored frames).")
    if bunny:
        notes += (
            "\n\n## The bunny: discrete load points, probes between them\n\n" + markdown_table(bunny, bcols) + "\n\n"
            f"Truth: {bunny_info['law']} on {bunny_info['truth_dofs']} dofs (h {bunny_info['h_mm']:.1f} mm), a rigid "
            f"12 mm sphere 0.5 mm past the scan towards the centroid, at {len(bunny_info['points'])} scan points "
            "halfway between neighbouring load points (the closest pairs). Estimates at their best pseudo-time (a "
            "perfect Alg. 5.1): the nearest load point (snap) and the Shepard blend of the k nearest load points' "
            "fields (weights 1/d^2: linear interpolation in the Euclidean space of the fields, which the thesis warns "
            "against, §7.3). 'local': scan vertices within 20 mm of the contact. |u(F) - 2 u(F/2)|: the truth's own "
            "departure from linearity along the stroke.")
    save("contact_anywhere", summary, cols, "Contact anywhere: off-grid contact in the reduced space against "
         "nearest-load-point snapping, scored against the full-order contact truth", notes, plot,
         extra={"positions": rows, "grid_density": grid, "two_contacts": pairs, "bunny": bunny,
                "bunny_truth": bunny_info})


def sphere_points(center, radius: float, n: int = 4000) -> np.ndarray:
    """The probe's surface as points (a golden-spiral sphere): what a depth camera would give of it, unoccluded."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    t = np.pi * (1 + 5 ** 0.5) * i
    r = np.sqrt(1 - z ** 2)
    return np.asarray(center) + radius * np.c_[r * np.cos(t), r * np.sin(t), z]


def grid_density(m, sn, off) -> list[dict]:
    """Off-grid error against the load grid's spacing along x: the model's parameter modes thinned."""
    fld = m.field("displacement")
    xs, ys = fld.axes[0].values, fld.axes[1].values
    F_model = float(m.loads.get("force_N", 1.0))
    out = []
    for every in THIN:
        keep = np.unique(np.r_[np.arange(0, len(xs), every), len(xs) - 1])
        axes = [Axis(a.name, a.values[keep] if a.name == "s_x" else a.values, a.unit, a.kind, a.interpolation,
                     a.description) for a in fld.axes]
        params = [p[:, keep] if a.name == "s_x" else p for a, p in zip(fld.axes, fld.params)]
        f = SeparatedField(fld.name, fld.space[:, sn], params, axes, fld.unit, fld.components)
        g = np.stack(np.meshgrid(xs[keep], ys, indexing="ij"), axis=-1).reshape(-1, 2)
        res: dict[str, dict[str, list[float]]] = {"snap": {"force": [], "fit": []},
                                                  "anywhere": {"force": [], "fit": []}}
        for _, r, u_true, cen in off:
            size = _rms(u_true)
            for name, mu in (("snap", g[int(np.argmin(np.linalg.norm(g - cen, axis=1)))]), ("anywhere", cen)):
                u1 = f.evaluate(mu)
                for how, tau in (("force", r.total["a"] / F_model), ("fit", float(np.sum(u1 * u_true) /
                                                                                  np.sum(u1 * u1)))):
                    res[name][how].append(100 * _rms(tau * u1 - u_true) / size)
        for name in ("snap", "anywhere"):
            out.append(dict(grid_mm=1e3 * float(np.median(np.diff(xs[keep]))), method=name, positions=len(off),
                            force_pct=float(np.median(res[name]["force"])),
                            force_max_pct=float(np.max(res[name]["force"])),
                            fit_pct=float(np.median(res[name]["fit"])), fit_max_pct=float(np.max(res[name]["fit"]))))
            print(out[-1], flush=True)
    return out


def two_contacts(m, body, sn, solved, H: float) -> list[dict]:
    """Pairs of the off-grid probes pressing at once: one contact solve with both spheres (each candidate node takes
    the gap to the nearer sphere), against the sum of the model at each sphere's true force and centroid.

    Each probe is pressed as deep as makes it carry PAIR_FORCE with the other pressing too (a root search on the
    contact solve: at equal depths the probe nearer the clamp lifts the beam off the other one)."""
    lp_xy = m.points[m.load_points][:, :2]
    F_model = float(m.loads.get("force_N", 1.0))
    off = [s for s in solved if np.min(np.linalg.norm(lp_xy - s[0], axis=1)) > 1e-6]
    pairs = [(off[i], off[j]) for i in range(len(off)) for j in range(i + 1, len(off))
             if off[j][0][0] - off[i][0][0] > 0.04]  # two patches, 40 mm apart or more, the first nearer the clamp
    out: list[dict] = []
    for p, q in pairs[::max(1, len(pairs) // N_PAIRS)][:N_PAIRS]:
        idx = np.union1d(p[2], q[2])
        both = CT.SphereOnBodies(body, idx, RADIUS, (0.0, 0.0, -1.0))
        centre = [int(np.argmin(np.linalg.norm(body.cand[x[2], :2] - x[0], axis=1))) for x in (p, q)]
        centre = [x[2][c] for x, c in zip((p, q), centre)]

        def forces_at(press, both=both, p=p, q=q):
            cs = [np.array([x[0][0], x[0][1], H + RADIUS - d]) for x, d in zip((p, q), press)]
            gaps = [both.probe_gaps(c) for c in cs]
            owner = np.argmin(np.stack(gaps), axis=0)  # which sphere each candidate faces
            lam, _ = CT.solve_lcp(both.M, np.minimum(gaps[0], gaps[1]))
            return np.array([lam[owner == sd].sum() for sd in (0, 1)]), cs, owner, lam

        # the presses that give each probe PAIR_FORCE newtons: from the compliance between the patch centres, then
        # a root search on the contact solve
        press0 = body.C[np.ix_(centre, centre)] @ np.full(2, PAIR_FORCE)
        sol = so.root(lambda d: forces_at(d)[0] - PAIR_FORCE, press0, method="hybr", options={"xtol": 1e-10})
        F_both, cs, owner, lam = forces_at(sol.x)
        if np.max(np.abs(F_both - PAIR_FORCE)) > 0.01 * PAIR_FORCE:
            raise RuntimeError(f"no presses give {PAIR_FORCE} N at both {p[0]} and {q[0]}: {F_both}")
        press = sol.x
        alone = [CT.SphereOnBodies(body, x[2], RADIUS, (0.0, 0.0, -1.0)).solve(c) for x, c in zip((p, q), cs)]
        f = np.zeros(len(body.cand))
        f[idx] = lam
        u_true = body.displacement(f)[sn]
        size = _rms(u_true)
        snap, anyw, forces = np.zeros_like(u_true), np.zeros_like(u_true), []
        for s in (0, 1):
            fs = np.zeros(len(body.cand))
            fs[idx[owner == s]] = lam[owner == s]
            F = float(fs.sum())
            forces.append(F)
            cen = (fs @ body.cand)[:2] / F
            j = int(np.argmin(np.linalg.norm(lp_xy - cen, axis=1)))
            for acc, mu in ((snap, lp_xy[j]), (anyw, cen)):
                acc += (F / F_model) * m.deformation(ModelState(np.asarray(mu, dtype=np.float64), load_scale=1.0),
                                                     nodes=sn)
        single = alone[0].displacement["a"][sn] + alone[1].displacement["a"][sn]
        pct = [100 * _rms(u - u_true) / size for u in (single, snap, anyw)]
        tracked = {how: 100 * _rms(track_pair(m, sn, cs, how) - u_true) / size for how in TRACKERS}
        out.append(dict(pair=len(out), x_mm=f"{1e3 * p[0][0]:.0f}, {1e3 * q[0][0]:.0f}",
                        y_mm=f"{1e3 * p[0][1]:.0f}, {1e3 * q[0][1]:.0f}",
                        forces_N=f"{forces[0]:.1f}, {forces[1]:.1f}",
                        press_mm=f"{1e3 * press[0]:.1f}, {1e3 * press[1]:.1f}",
                        alone_N=f"{alone[0].total['a']:.1f}, {alone[1].total['a']:.1f}", true_rms_mm=1e3 * size,
                        single_sum_pct=pct[0], snap_pct=pct[1], anywhere_pct=pct[2],
                        **{f"tracker_{how}_pct": v for how, v in tracked.items()}))
        print(out[-1], flush=True)
    return out


def track_pair(m, sn, centres: list[np.ndarray], how: str) -> np.ndarray:
    """The surface displacement (at ``sn``) Alg. 5.1 settles at with two probes pressing, each descending from
    PAIR_APPROACH above its final centre to it over PAIR_DESCENT frames and held for PAIR_HOLD: averaged over the
    hold's last half (the pseudo-times oscillate by a step there). The probes are seen as points PAIR_DELTA inside
    their surface (the sensor's margin that delta stands for), so a contact settles on the probe's true surface.

    ``how``: "coupled" (one tracker, two contacts at once: each sees the other's deformation), "one" (one tracker,
    one contact: what Alg. 5.1 does without slots), "independent" (one tracker per probe, the deformations summed:
    superposition without the coupling)."""
    down = np.array([0.0, 0.0, 1.0])

    def probe(c, f):
        z = PAIR_APPROACH * max(0.0, 1.0 - f / PAIR_DESCENT)
        return sphere_points(np.asarray(c) + z * down, RADIUS - PAIR_DELTA)

    kw = dict(threshold=PAIR_DELTA, step=PAIR_STEP, tau_max=PAIR_TAU_MAX, anywhere=True,
              max_contacts=1 if how == "one" else 2)
    if how == "independent":
        trackers = [(ContactTracker(m, np.eye(4), **kw), [i]) for i in (0, 1)]
    else:
        trackers = [(ContactTracker(m, np.eye(4), **kw), [0, 1])]
    u = np.zeros((len(sn), 3))
    frames = PAIR_DESCENT + PAIR_HOLD
    for f in range(frames):
        for tr, which in trackers:
            tr.update(np.vstack([probe(centres[i], f) for i in which]))
        if f >= frames - PAIR_HOLD // 2:
            u += sum(tr.displacement(nodes=sn) for tr, _ in trackers)
    return u / (PAIR_HOLD // 2)


def between_load_points(LP: np.ndarray, S: np.ndarray, k: int) -> np.ndarray:
    """``k`` scan vertices (indices into S) halfway between neighbouring load points: the scan vertex nearest the
    midpoint of each load point and its nearest neighbour, the closest pairs first, each pair once."""
    d = np.linalg.norm(LP[:, None] - LP[None], axis=2)
    np.fill_diagonal(d, np.inf)
    pairs = sorted({tuple(sorted((i, int(np.argmin(d[i]))))) for i in range(len(LP))}, key=lambda ij: d[ij])
    tree = cKDTree(S)
    out: list[int] = []
    for i, j in pairs:
        v = int(tree.query(0.5 * (LP[i] + LP[j]))[1])
        if v not in out:
            out.append(v)
        if len(out) == k:
            break
    return np.asarray(out)


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))


def bunny_rows() -> tuple[list[dict], dict]:
    """Probes between the bunny's load points: snap and Euclidean blends against the large-strain truth."""
    from simreal_nodes.synth.scenes import _FE_CACHE, TRUTH_MESH_FACTOR

    spec = load_spec("bunny.yaml")
    m = load_model(cached_model("bunny"), fields=["displacement"])
    nv = int(m.provenance["volume_nodes"])
    scan = np.arange(nv, len(m.points))
    S = m.points[scan]
    Hh = float(np.ptp(S[:, 2]))
    h = float(spec["mesh"]["cell_size"]) * Hh * TRUTH_MESH_FACTOR
    LP = m.points[m.load_points]
    chosen = between_load_points(LP, S, BUNNY_POINTS)
    centroid = m.points[:nv].mean(axis=0)
    tr = ContactTracker(m, np.eye(4))
    tables: dict[int, np.ndarray] = {}

    def table(lp):
        if lp not in tables:
            tables[lp] = np.stack([m.deformation(tr.load_states.state(lp, float(t)), nodes=scan) for t in TAUS_FINE])
        return tables[lp]

    rows, info = [], []
    path = None
    for n, i in enumerate(chosen):
        X = S[i]
        d = (centroid - X) / np.linalg.norm(centroid - X)
        path = CT.probe_path_truth(m, -1, 5e-4, RADIUS, float(spec["base_fraction"]), h, n_travels=8,
                                   solid_cache=_FE_CACHE, at=(X, d))
        u = path.displacement[-1][scan]
        F = np.linalg.norm(path.total, axis=1)
        half = float(np.interp(F[-1] / 2, F, path.travels))
        lin = 100 * _rms(u - 2 * path.at(half)[2][scan]) / _rms(u)
        local = np.linalg.norm(S - X, axis=1) < 0.02
        dist = np.linalg.norm(LP - X, axis=1)
        order = np.argsort(dist)
        info.append(dict(point=n, nearest_mm=1e3 * float(dist[order[0]]), force_N=float(F[-1]), linearity_pct=lin,
                         seconds=path.info["seconds"], interp_err_pct=path.info["interp_err_pct"]))
        for k in (1, 2, 3, 4):
            nb = order[:k]
            w = 1.0 / np.maximum(dist[nb], 1e-9) ** 2
            w /= w.sum()
            est = np.tensordot(w, np.stack([table(int(j)) for j in nb]), axes=(0, 0))  # (taus, n, 3)
            err = np.sqrt(np.mean(np.sum((est - u[None]) ** 2, axis=2), axis=1))
            b = int(np.argmin(err))
            rows.append(dict(point=n, nearest_mm=1e3 * float(dist[order[0]]), force_N=float(F[-1]),
                             method="snap" if k == 1 else f"blend of {k}", tau=float(TAUS_FINE[b]),
                             rms_mm=1e3 * float(err[b]), truth_rms_mm=1e3 * _rms(u),
                             local_mm=1e3 * _rms(est[b][local] - u[local]), truth_local_mm=1e3 * _rms(u[local]),
                             linearity_pct=lin))
            print(rows[-1], flush=True)
    assert path is not None
    return rows, {"points": info, "truth_dofs": path.info["dofs"], "h_mm": 1e3 * h, "law": path.info["law"]}


if __name__ == "__main__":
    main()
