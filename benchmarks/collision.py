"""Collision from depth (thesis Alg. 5.1, §5.2.4, §5.4.1) scored against an independent full-order contact truth
(issue 21), and its speed/accuracy trade against the depth decimation step, at 640 x 480 and 1280 x 720.

    ./run bench collision

Scene: the rendered crossed-beams probe (a real probe pushes virtual beam a near its free end; a, bending, pushes
virtual beam b). The truth is the Signorini problem of the two linear-elastic beams and the rigid probe, solved on
quadratic tetrahedra 60 x 6 x 4 per beam (`synth/contact_truth.py`; the model: hexahedra 30 x 3 x 2), never the
Alg. 5.1 state machine being scored. The estimator sees the noisy Kinect-like depth and the true camera pose (the
localization's error is measured elsewhere).

The thesis's crossed beams are St. Venant-Kirchhoff: the SVK rows run the same two set-ups with both beams the SVK
model (`crossed_beams_svk`: u(x, s_x, s_y, pseudo-time), Newton snapshots + NI-PGD) against a large-deformation
truth (`synth/beams_truth.py`: both beams SVK on quadratic tetrahedra 40 x 4 x 3, total Lagrangian, exact
frictionless contact, solved along the probe's stroke); one more row draws the linear model against that truth
(what the linear law costs in the scene).

Per frame (depth_points + ContactScene.step, both beams):
- contact: the estimate's CONTACT against a true contact force > 1 mN; precision, recall, agreement, beside the
  agreement of an estimator that always says "free" (the all-free baseline);
- contact point (frames both call contact): distance in the beam's plane between the estimate's load point and
  the true force centroid, mm;
- force: the beam's load scale (SVK: pseudo-time) times its 15 N against the true contact force (frames both call
  contact);
- surface: RMS over the model's surface nodes of |u_estimate - u_true| (mm), over the frames the truth is in
  contact; beside it the **model error**: the reduced model at the true contact's nearest load point, its load
  scale (SVK: pseudo-time) fitted to the true displacement (what a perfect Alg. 5.1 would still be off by: the model's
  discretisation, the load grid, and for beam a the one-way coupling -- the model of a does not know that b
  holds it up); phantom: the error drawn on frames the estimate calls contact and the truth does not.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from benchmarks.common import save
from simreal_nodes import geometry as G
from simreal_nodes.collision.contact import PusherSurface
from simreal_nodes.collision.scene import ContactScene
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.synth.sequence import sequence

STEPS = (1, 2, 4, 8, 16)
ANYWHERE_STEPS = (1, 2, 4, 8)
MULTI_STEPS = (2, 4, 8)
OBJECTS = ("beam_a", "beam_b")
KEYS = ("est", "tru", "cp", "force", "surf", "floor", "phantom", "size")


def surface_nodes(model) -> np.ndarray:
    return np.unique(np.asarray(model.surface).ravel())


def _rms(d: np.ndarray) -> float:
    """RMS length of displacement differences (n, 3), in mm."""
    return 1e3 * float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))


def run(seq, scene, step: int, anywhere: bool = False, max_contacts: int = 1, model: str | None = None) -> dict:
    """One estimator run; ``anywhere``: both beams' contacts placed where they touch, between the load points
    (``collision.anywhere``), instead of at the nearest load point; ``max_contacts``: ``collision.max_contacts``
    (above 1, the touch is looked for on the drawn surface between the load points too); ``model``: another model
    for both beams than the scene's (a built-in spec's name: the linear beams against the SVK scene's truth)."""
    objs = [o for o in scene["objects"] if o["collision"]["enabled"]]
    objs = [{**o, "collision": {**o["collision"], "anywhere": anywhere, "max_contacts": max_contacts}} for o in objs]
    models = {o["id"]: load_model(cached_model(model) if model else o["model"], fields=["displacement"])
              for o in objs}
    cs = ContactScene(objs, models, decimation=step)
    surface = {oid: surface_nodes(m) for oid, m in models.items()}
    stats: dict[str, dict[str, list]] = {oid: {k: [] for k in KEYS} for oid in OBJECTS}
    times, npts = [], []
    for i, depth in enumerate(seq["depth"]):
        t0 = time.perf_counter()
        res = cs.step(depth, seq["cam"], seq["T"][i])
        times.append(time.perf_counter() - t0)
        npts.append(res[0].state.points_used)
        by_id = {r.object_id: r.state for r in res}
        for oid in OBJECTS:
            _score(stats[oid], models[oid], cs.trackers[oid], by_id[oid], seq["truth"][i], oid, surface[oid])
    row: dict = dict(model=model or _spec_of(objs[0]["model"]), step=step, anywhere="yes" if anywhere else "no",
                     contacts=max_contacts, pusher="estimate",
                     points=int(np.median(npts)), ms=1e3 * float(np.median(times)),
                     p95_ms=1e3 * float(np.percentile(times, 95)), frames=len(times))
    for oid in OBJECTS:
        row.update(_summary(stats[oid], oid))
    return row


def run_virtual(seq, scene) -> dict:
    """Virtual-virtual contact alone: beam b's Alg. 5.1 pushed by beam a drawn at its **true** deformation (the
    full-order solve's displacement at the model's nodes), no depth. What b's contact detection scores when the
    pusher's own estimate (from depth) is not in the way."""
    o = next(o for o in scene["objects"] if o["id"] == "beam_b")
    a = next(o for o in scene["objects"] if o["id"] == "beam_a")
    mb, ma = load_model(o["model"], fields=["displacement"]), load_model(a["model"], fields=["displacement"])
    cs = ContactScene([{**o, "collision": {**o["collision"], "pushes": []}}], {"beam_b": mb})
    tr = cs.trackers["beam_b"]
    T_a = G.pose7_to_matrix(a["anchor"]["pose"])
    F_a = np.asarray(ma.surface, np.int64)
    stats: dict[str, list] = {k: [] for k in KEYS}
    times = []
    for truth in seq["truth"]:
        push = [PusherSurface(G.transform(T_a, ma.points + truth.displacements["beam_a"]), F_a)] \
            if truth.contacts["beam_a"].in_contact else []
        t0 = time.perf_counter()
        st = tr.update(None, push)
        times.append(time.perf_counter() - t0)
        _score(stats, mb, tr, st, truth, "beam_b", surface_nodes(mb))
    row: dict = dict(model=_spec_of(o["model"]), step=0, anywhere="no", contacts=1, pusher="truth", points=0,
                     ms=1e3 * float(np.median(times)),
                     p95_ms=1e3 * float(np.percentile(times, 95)), frames=len(times))
    row.update(_summary(stats, "beam_b"))
    return row


def _spec_of(path: str) -> str:
    """The built-in spec a scene's model file was built from (its cache file's name: the spec's model name)."""
    stem = Path(path).stem
    return {"crossed_beam": "crossed_beams", "crossed_beam_svk": "crossed_beams_svk"}.get(stem, stem)


def _score(s: dict, m, tr, st, truth, oid: str, sn: np.ndarray) -> None:
    """One frame of one beam against the truth, into its lists ``s``."""
    tt = truth.contacts[oid]
    s["est"].append(st.in_contact)
    s["tru"].append(tt.in_contact)
    vals = truth.params[oid][2]
    F = float(m.loads.get("force_N", 1.0))
    if st.in_contact and tt.in_contact:
        est_xy = np.asarray(tr.model_state().mu[:2])  # the load's position (s_x, s_y) the model is drawn at
        s["cp"].append(1e3 * float(np.linalg.norm(est_xy - np.asarray(vals[:2]))))
        s["force"].append(abs(st.pseudo_time * F - vals[2] * F))
    u_est = tr.displacement(nodes=sn)
    if tt.in_contact:
        u_true = truth.displacements[oid][sn]
        s["surf"].append(_rms(u_est - u_true))
        s["size"].append(_rms(u_true))
        s["floor"].append(model_floor(m, tr, tt.load_point, u_true, sn))
    elif st.in_contact:  # deformation drawn where there is no contact
        s["phantom"].append(_rms(u_est - truth.displacements[oid][sn]))


TAUS = np.linspace(0.0, 1.0, 101)
_FLOOR_TABLES: dict[tuple, np.ndarray] = {}


def model_floor(m, tr, lp: int, u_true: np.ndarray, sn: np.ndarray) -> float:
    """The model's own error (mm RMS): the best the model can do with the true contact's load point ``lp``. A linear
    model's load scale is fitted to the true displacement (least squares, exact); a non-linear one's pseudo-time is
    the best of a 101-value grid (its deformations at that load point tabulated once)."""
    if not tr.load_states.pseudo_time:
        u1 = m.deformation(tr.load_states.state(lp, 1.0), nodes=sn)
        tau = float(np.sum(u1 * u_true) / max(np.sum(u1 * u1), 1e-30))
        return _rms(tau * u1 - u_true)
    key = (m.model_id, lp, len(sn))
    if key not in _FLOOR_TABLES:
        _FLOOR_TABLES[key] = np.stack([m.deformation(tr.load_states.state(lp, float(t)), nodes=sn) for t in TAUS])
    U = _FLOOR_TABLES[key]
    return 1e3 * float(np.min(np.sqrt(np.mean(np.sum((U - u_true[None]) ** 2, axis=2), axis=1))))


def _summary(s: dict, oid: str) -> dict:
    """One beam's columns of a row."""
    est, tru = np.array(s["est"]), np.array(s["tru"])
    tp = int(np.sum(est & tru))
    key = oid.replace("beam_", "")
    return {
        f"{key}_true_frames": int(tru.sum()), f"{key}_est_frames": int(est.sum()),
        f"{key}_agree_pct": 100 * float(np.mean(est == tru)),
        f"{key}_free_baseline_pct": 100 * float(np.mean(~tru)),
        f"{key}_precision_pct": 100 * tp / est.sum() if est.sum() else float("nan"),
        f"{key}_recall_pct": 100 * tp / tru.sum() if tru.sum() else float("nan"),
        f"{key}_point_mm": float(np.median(s["cp"])) if s["cp"] else float("nan"),
        f"{key}_force_err_N": float(np.median(s["force"])) if s["force"] else float("nan"),
        f"{key}_surface_mm": float(np.median(s["surf"])) if s["surf"] else float("nan"),
        f"{key}_surface_max_mm": float(np.max(s["surf"])) if s["surf"] else float("nan"),
        f"{key}_model_error_mm": float(np.median(s["floor"])) if s["floor"] else float("nan"),
        f"{key}_model_error_max_mm": float(np.max(s["floor"])) if s["floor"] else float("nan"),
        f"{key}_truth_rms_mm": float(np.median(s["size"])) if s["size"] else float("nan"),
        f"{key}_phantom_mm": float(np.median(s["phantom"])) if s["phantom"] else 0.0,
    }


def truth_summary(seq) -> dict:
    """The truth's own figures over the sequence: peak contact forces and displacements (for the notes)."""
    out = {}
    for oid in OBJECTS:
        f = [t.params[oid][2][2] for t in seq["truth"]]
        u = [float(np.max(np.linalg.norm(t.displacements[oid], axis=1))) for t in seq["truth"]]
        out[oid] = {"peak_load_scale": float(np.max(f)), "peak_displacement_mm": 1e3 * float(np.max(u))}
    st = seq["scene"].state
    out["description"] = st["fe_path"].info["description"] if "fe_path" in st else st["fe"].description
    return out


CASES = (("crossed_beams_probe", "development", 640, 480), ("crossed_beams_probe_heldout", "held-out", 640, 480),
         ("crossed_beams_probe", "development", 1280, 720),
         # the thesis's St. Venant-Kirchhoff beams: the SVK model against the large-deformation truth, same set-ups
         ("crossed_beams_svk_probe", "SVK development", 640, 480),
         ("crossed_beams_svk_probe_heldout", "SVK held-out", 640, 480))


def main():
    rows = []
    summary: dict = {}
    for name, kind, w, h in CASES:
        seq = sequence(name, w, h)
        scene = build_spec_models(validate_scene(seq["scene"].scene_yaml(seq["scene"]), name, "."))
        summary[kind] = truth_summary(seq)
        head = dict(scene=kind, resolution=f"{w}x{h}")
        runs: list[tuple] = [(run, (s,)) for s in STEPS]
        if w == 640:  # the lower beam pushed by the upper one's true deformation: virtual-virtual contact alone
            runs.append((run_virtual, ()))
        if w == 640 and kind == "development":  # contact anywhere (the load where the contact is), same frames
            runs += [(run, (s, True)) for s in ANYWHERE_STEPS]
            runs += [(run, (s, True, 2)) for s in MULTI_STEPS]  # the knob max_contacts on this one-probe scene
        if kind.startswith("SVK"):  # what the linear law costs in the scene: the linear model, the SVK truth
            runs.append((run, (4, False, 1, "crossed_beams")))
        for fn, args in runs:
            row = dict(head, **fn(seq, scene, *args))
            rows.append(row)
            print(row, flush=True)

    def rows_model(kind: str) -> str:
        return "crossed_beams_svk" if kind.startswith("SVK") else "crossed_beams"

    def plot(plt):
        fig, ax = plt.subplots(1, 3, figsize=(15, 3.8))
        for (kind, res), mk in ((("development", "640x480"), "o-"), (("held-out", "640x480"), "^-."),
                                (("development", "1280x720"), "s--"), (("SVK development", "640x480"), "D:"),
                                (("SVK held-out", "640x480"), "v:")):
            rr = [r for r in rows if r["resolution"] == res and r["scene"] == kind and r["anywhere"] == "no"
                  and r["pusher"] == "estimate" and r["contacts"] == 1 and r["model"] == rows_model(kind)]
            res = f"{kind} {res}"
            x = [r["step"] for r in rr]
            ax[0].plot(x, [r["a_agree_pct"] for r in rr], mk, label=f"{res} beam a agreement")
            ax[0].plot(x, [r["b_agree_pct"] for r in rr], mk, alpha=0.5, label=f"{res} beam b agreement")
            ax[1].plot(x, [r["a_surface_mm"] for r in rr], mk, label=f"{res} beam a")
            ax[1].plot(x, [r["b_surface_mm"] for r in rr], mk, alpha=0.5, label=f"{res} beam b")
            ax[2].plot(x, [r["ms"] for r in rr], mk, label=res)
        ax[0].axhline(rows[0]["a_free_baseline_pct"], color="gray", lw=0.8, ls=":", label="a: always 'free'")
        ax[1].axhline(rows[0]["a_model_error_mm"], color="gray", lw=0.8, ls=":", label="a: model error")
        for a in ax:
            a.set_xscale("log", base=2)
            a.set_xlabel("decimation step (every N-th pixel per direction)")
        ax[0].set_ylabel("% of frames")
        ax[1].set_ylabel("surface RMS error vs full-order truth (mm)")
        ax[2].set_ylabel("depth -> contact per frame, both beams (ms)")
        for a in ax:
            a.legend(fontsize=7)
        fig.tight_layout()
        return fig

    cols = [("scene", "scene", "{}"), ("resolution", "resolution", "{}"), ("model", "model", "{}"),
            ("step", "decimation", "{}"),
            ("anywhere", "anywhere", "{}"), ("contacts", "max contacts", "{}"), ("pusher", "b pushed by a's", "{}"),
            ("points", "depth points", "{}"),
            ("a_agree_pct", "a: agrees (%)", "{:.0f}"), ("a_free_baseline_pct", "a: all-free (%)", "{:.0f}"),
            ("a_precision_pct", "a: precision (%)", "{:.0f}"), ("a_recall_pct", "a: recall (%)", "{:.0f}"),
            ("a_point_mm", "a: point (mm)", "{:.1f}"), ("a_force_err_N", "a: force err (N)", "{:.1f}"),
            ("a_surface_mm", "a: surface (mm)", "{:.2f}"), ("a_truth_rms_mm", "a: true |u| RMS (mm)", "{:.2f}"),
            ("a_model_error_mm", "a: model error (mm)", "{:.3f}"), ("a_model_error_max_mm", "max", "{:.2f}"),
            ("a_phantom_mm", "a: phantom (mm)", "{:.2f}"),
            ("b_agree_pct", "b: agrees (%)", "{:.0f}"), ("b_free_baseline_pct", "b: all-free (%)", "{:.0f}"),
            ("b_precision_pct", "b: precision (%)", "{:.0f}"), ("b_recall_pct", "b: recall (%)", "{:.0f}"),
            ("b_point_mm", "b: point (mm)", "{:.1f}"),
            ("b_surface_mm", "b: surface (mm)", "{:.2f}"), ("b_truth_rms_mm", "b: true |u| RMS (mm)", "{:.2f}"),
            ("b_model_error_mm", "b: model error (mm)", "{:.3f}"), ("b_model_error_max_mm", "max", "{:.2f}"),
            ("b_phantom_mm", "b: phantom (mm)", "{:.2f}"),
            ("ms", "time (ms)", "{:.2f}"), ("p95_ms", "p95 (ms)", "{:.2f}")]
    truths = "; ".join(
        f"{kind}: peak contact force on a {15 * t['beam_a']['peak_load_scale']:.0f} N, on b "
        f"{15 * t['beam_b']['peak_load_scale']:.0f} N" for kind, t in summary.items())
    notes = (f"Truth: {summary['development']['description']}; the SVK rows (the thesis's St. Venant-Kirchhoff "
             "beams: the model `crossed_beams_svk`, u(x, s_x, s_y, pseudo-time), NI-PGD of Newton snapshots, against "
             f"the large-deformation truth `synth/beams_truth.py`): {summary['SVK development']['description']}, "
             "solved along the stroke and interpolated between its travels; "
             f"{truths} (the models' load: 15 N). The held-out "
             "set-up (b crossing 35 mm from a's tip instead of 20, a 5 mm rest gap instead of 3, the probe at another "
             "load point, pressing 60 % of the model's deflection there instead of 50 %, another camera arc: "
             "`synth/scenes.py:CROSSED_BEAMS`) was fixed before any estimate on it was seen. "
             "Contact: Alg. 5.1's CONTACT against a true force > 1 mN; 'all-free' is the agreement of an estimator "
             "that never reports a contact. b is pushed by a's drawn surface ('estimate': a's own Alg. 5.1 from "
             "depth, what the graph does) or, to score virtual-virtual contact alone, by a drawn at its true "
             "deformation ('truth', no depth); b touches a at a gap of zero along its load direction (exact "
             "surfaces), a the depth points within delta. Point: where the estimate puts the load (its load point, or "
             "with 'anywhere' the contact's own position: `collision.anywhere`) to the true force centroid, in the "
             "beam's plane. Surface: RMS of the displacement error over the model's surface nodes, median over the "
             "frames the truth is in contact (beside it, the true displacement's own RMS); model error: the same for "
             "the model at the true contact's nearest load point with its load scale (SVK: its pseudo-time) fitted "
             "to the true displacement (median and max over those frames: the error a perfect Alg. 5.1 would keep); "
             "phantom: the drawn "
             "displacement's RMS error on frames the estimate calls contact and the truth does not. True camera "
             "pose. 'max contacts' 2: the knob `collision.max_contacts` (several contacts at once, the touch looked "
             "for on the drawn surface between the load points too; `benchmarks/results/contact_anywhere.md` for "
             "two probes) on this one-probe scene: what it costs or gains where one contact would do.")
    save("collision", rows, cols,
         "Collision from depth against a full-order contact truth: detection, contact point, force and deformed "
         "surface versus decimation (crossed beams + probe)", notes, plot, extra={"truth": summary})


if __name__ == "__main__":
    main()
