"""The seed probe scenes (thesis §5.4.2-3: a real probe pushes the virtual Stanford bunny and dragon), scored against
an independent full-order contact truth (issue 21), from RGB-D depth and from stereo (SGBM) depth, and the contact
detection's speed/accuracy trade against the depth decimation step.

    ./run bench probe_scenes            # 640 x 480, decimation 1, 2, 4, 8
    ./run bench probe_scenes --quick    # decimation 2 only (the scenes' own setting)

Scenes: ``bunny_probe``, ``bunny_probe_stereo``, ``dragon_probe``, ``dragon_probe_stereo`` (6 s at 30 fps; the probe
presses two of the model's load points, 70 % of the model's largest deflection past the scan surface), and
``bunny_probe_heldout`` (two other load points, fixed before any result; ``dragon_probe_heldout`` only with
``--scenes``: its first stroke's truth did not finish in 26-28 minutes, twice). Rows also at Alg. 5.1's delta 3, 5,
12 mm and with the models at the thesis's load grid (``--no-thesis-grid`` skips them: 6-7 minutes to build each).
The truth is a large-strain neo-Hookean solve of a rigid sphere pressing the scanned body (`synth/contact_truth.py`:
`probe_path_truth`), on its own tetrahedra (0.6 of the model's cell size), the probe's real contact with the scan
surface (penalty, frictionless), never the reduced model nor Alg. 5.1. The estimator (`ContactScene.step`, what the
collision node runs) sees the noisy Kinect-like depth, or SGBM's depth from the rendered stereo pair (grey images),
and the true camera pose (the localization is measured elsewhere).

Per frame and scene:
- contact: the estimate's CONTACT against a true contact force > 1 mN: precision, recall, agreement, beside the
  agreement of an estimator that always says "free";
- contact point (frames both call contact): distance between the estimate's load point and the true force
  centroid (object frame), mm;
- force: the model's pseudo-time times its load against the true force's magnitude, N;
- surface: RMS over the scan's vertices of |u_estimate - u_true| (mm), median over the frames the truth is in
  contact, beside the true displacement's RMS and the **model error** (the model at the true contact's nearest load
  point, its pseudo-time chosen to fit the true displacement best: what a perfect Alg. 5.1 would still be off by);
- stress: RMS over the scan's vertices of the drawn von Mises stress minus the true one (kPa), same frames, beside
  the true von Mises RMS and the model error's;
- phantom: the drawn displacement's RMS on frames the estimate calls contact and the truth does not.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.common import save
from simreal_nodes import geometry as G
from simreal_nodes.collision.scene import ContactScene
from simreal_nodes.render.overlay import von_mises
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.synth.sequence import sequence

SCENES = (("bunny_probe", "bunny", "RGB-D"), ("bunny_probe_stereo", "bunny", "stereo"),
          ("dragon_probe", "dragon", "RGB-D"), ("dragon_probe_stereo", "dragon", "stereo"),
          # other load points, fixed before any result was seen and never used to choose anything
          ("bunny_probe_heldout", "bunny", "RGB-D"), ("dragon_probe_heldout", "dragon", "RGB-D"))
# dragon_probe_heldout is run only when asked for (--scenes): the truth of its first stroke (load point 5) takes hours.
# Load point 5 sits on a slender part, 21.5 mm of model deflection under the model's 2 N where the other strokes' are
# 0.7-2.3 mm, so the stroke presses it 14 mm, and past the first touch the part bends away under the frictionless
# sphere: Newton's tangent is near-singular there and the contact's active set flips (stop 45 found no path through).
# Since stop 50 the truth falls back to a damped descent of the potential (`synth/contact_truth.py`), which does follow
# it: in stop 51, 14 of the stroke's 17 travels solved in 112 minutes (forces up to 0.45 N; descents of 2-41 minutes
# each, on a 2-core host shared with other runs) before the run was stopped for time: no row yet. The held-out pair is
# not changed (it was fixed before any result).
DEFAULT_SCENES = tuple(s for s in SCENES if s[0] != "dragon_probe_heldout")
STEPS = (1, 2, 4, 8)
DELTAS = (0.003, 0.005, 0.012)  # Alg. 5.1's delta besides the scenes' 8 mm
TAUS = np.linspace(0.0, 1.0, 101)


def _rms(d: np.ndarray) -> float:
    """RMS length of displacement differences (n, 3), in mm."""
    return 1e3 * float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))


def _rms_kpa(v: np.ndarray) -> float:
    return 1e-3 * float(np.sqrt(np.mean(v ** 2)))


def stereo_depths(seq) -> tuple[list[np.ndarray], float]:
    """SGBM depth per frame from the rendered pair (what the collision node does in stereo), and its median time."""
    from simreal_nodes.vision.stereo import disparity_to_depth, sgbm_disparity

    out, times = [], []
    base = float(seq["scene"].stereo_baseline)
    for left, right in zip(seq["gray"], seq["right"]):
        t0 = time.perf_counter()
        out.append(disparity_to_depth(sgbm_disparity(left, right), seq["cam"].fx, base).astype(np.float32))
        times.append(time.perf_counter() - t0)
    return out, 1e3 * float(np.median(times))


class ModelFloor:
    """The model's own error against the truth at a true contact: the best pseudo-time at the true contact's nearest
    load point (a 101-value grid search), its displacement and von Mises errors."""

    def __init__(self, model, tracker, nodes):
        self.m, self.tr, self.nodes = model, tracker, nodes
        self.cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def _table(self, lp: int):
        if lp not in self.cache:
            U, S = [], []
            for tau in TAUS:
                st = self.tr.load_states.state(lp, float(tau))
                U.append(self.m.deformation(st, nodes=self.nodes))
                S.append(von_mises(self.m.field("stress").evaluate(st.mu, self.nodes)))
            self.cache[lp] = (np.stack(U), np.stack(S))
        return self.cache[lp]

    def __call__(self, lp: int, u_true: np.ndarray, vm_true: np.ndarray) -> tuple[float, float, float]:
        U, S = self._table(lp)
        err = np.sqrt(np.mean(np.sum((U - u_true[None]) ** 2, axis=2), axis=1))
        k = int(np.argmin(err))
        return 1e3 * float(err[k]), _rms_kpa(S[k] - vm_true), float(TAUS[k])


def run(seq, depths, scene: dict, step: int, model_path: str | None = None, threshold: float | None = None) -> dict:
    """One estimator run over the sequence; ``model_path``: another model of the same body (the same volume mesh
    and scan, another load grid) in place of the scene's; ``threshold``: Alg. 5.1's delta (metres) in place of the
    scene's ``collision.threshold_m``."""
    objs = [o for o in scene["objects"] if o["collision"]["enabled"]]
    if threshold is not None:
        objs = [{**o, "collision": {**o["collision"], "threshold_m": float(threshold)}} for o in objs]
    oid = objs[0]["id"]
    model = load_model(model_path or objs[0]["model"], fields=["displacement", "stress"])
    scene_model = seq["scene"].state["models"]["object"]
    if len(model.points) != len(scene_model.points) or model.loads.get("force_N") != scene_model.loads.get("force_N"):
        raise ValueError("the model's nodes or load are not the ones the truth was observed and scaled with")
    P = model.points[model.load_points]
    cs = ContactScene(objs, {oid: model}, decimation=step)
    tr = cs.trackers[oid]
    nv = int(model.provenance["volume_nodes"])
    scan = np.arange(nv, len(model.points))  # the scan surface's vertices: what is drawn
    floor = ModelFloor(model, tr, scan)
    stress = model.field("stress")
    keys = ("est", "tru", "cp", "force", "surf", "size", "floor", "vm", "vm_size", "vm_floor", "phantom")
    s: dict[str, list] = {k: [] for k in keys}
    times = []
    for i, depth in enumerate(depths):
        t0 = time.perf_counter()
        res = cs.step(depth, seq["cam"], seq["T"][i])
        times.append(time.perf_counter() - t0)
        st = {r.object_id: r for r in res}[oid].state
        truth = seq["truth"][i]
        tt = truth.contacts[oid if oid in truth.contacts else "object"]
        key = oid if oid in truth.displacements else "object"
        u_true = truth.displacements[key][scan]
        vm_true = truth.von_mises[key][scan]
        s["est"].append(st.in_contact)
        s["tru"].append(tt.in_contact)
        u_est = tr.displacement(nodes=scan)
        if st.pseudo_time > 0 and st.load_point >= 0:
            vm_est = von_mises(stress.evaluate(tr.model_state().mu, scan))
        else:
            vm_est = np.zeros(len(scan))
        F0 = float(model.loads.get("force_N", 1.0))
        if tt.in_contact:
            # where the truth's force acts (object frame), and this model's load point nearest to it
            cen = G.transform(G.inv(truth.object_poses[key]), np.asarray(tt.contact_point)[None])[0]
            lp_true = int(np.argmin(np.linalg.norm(P - cen, axis=1)))
        if st.in_contact and tt.in_contact:
            s["cp"].append(1e3 * float(np.linalg.norm(P[st.load_point] - cen)))
            s["force"].append(abs(st.pseudo_time - tt.pseudo_time) * F0)  # both over the same load (checked)
        if tt.in_contact:
            s["surf"].append(_rms(u_est - u_true))
            s["size"].append(_rms(u_true))
            fu, fs, _ = floor(lp_true, u_true, vm_true)
            s["floor"].append(fu)
            s["vm"].append(_rms_kpa(vm_est - vm_true))
            s["vm_size"].append(_rms_kpa(vm_true))
            s["vm_floor"].append(fs)
        elif st.in_contact:
            s["phantom"].append(_rms(u_est - u_true))
    est, tru = np.array(s["est"]), np.array(s["tru"])
    tp = int(np.sum(est & tru))

    def med(k):
        return float(np.median(s[k])) if s[k] else float("nan")

    return dict(step=step, threshold_mm=1e3 * float(objs[0]["collision"]["threshold_m"]), frames=len(times),
                true_frames=int(tru.sum()), est_frames=int(est.sum()),
                agree_pct=100 * float(np.mean(est == tru)), free_baseline_pct=100 * float(np.mean(~tru)),
                precision_pct=100 * tp / est.sum() if est.sum() else float("nan"),
                recall_pct=100 * tp / tru.sum() if tru.sum() else float("nan"),
                point_mm=med("cp"), force_err_N=med("force"), surface_mm=med("surf"), truth_rms_mm=med("size"),
                model_error_mm=med("floor"), model_error_max_mm=float(np.max(s["floor"])) if s["floor"] else np.nan,
                stress_kpa=med("vm"), truth_vm_kpa=med("vm_size"), model_stress_kpa=med("vm_floor"),
                phantom_mm=float(np.median(s["phantom"])) if s["phantom"] else 0.0,
                ms=1e3 * float(np.median(times)), p95_ms=1e3 * float(np.percentile(times, 95)))


def truth_notes(seq) -> dict:
    paths = seq["scene"].state["fe_paths"]
    return {"dofs": paths[0].info["dofs"], "h_mm": 1e3 * paths[0].info["h_m"],
            "peak_force_N": [p.info["peak_force_N"] for p in paths],
            "max_penetration_mm": max(p.info["max_penetration_mm"] for p in paths),
            "interp_err_pct": max(max(p.info["interp_err_pct"]) for p in paths),
            "first_touch_mm": [1e3 * p.info["first_touch_m"] for p in paths],
            "press_mm": [1e3 * p for p in seq["scene"].state["presses"]],
            "threshold_mm": 1e3 * seq["scene"].state["delta"], "law": paths[0].info["law"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="decimation 2 only")
    ap.add_argument("--scenes", default="", help="comma-separated subset of the scenes")
    ap.add_argument("--out", default="probe_scenes",
                    help="results name under benchmarks/results/ (e.g. probe_scenes_dragon_heldout for a subset)")
    ap.add_argument("--no-thesis-grid", action="store_true",
                    help="skip the rows of the models at the thesis's load grid (bunny 34 x 26, dragon 32 x 16)")
    args = ap.parse_args(argv)
    steps = (2,) if args.quick else STEPS
    chosen = [s for s in SCENES if s[0] in args.scenes.split(",")] if args.scenes else list(DEFAULT_SCENES)
    rows, truths = [], {}
    for name, obj, depth_kind in chosen:
        stereo = depth_kind == "stereo"
        seq = sequence(name, 640, 480, stereo=stereo)
        scene = build_spec_models(validate_scene(seq["scene"].scene_yaml(seq["scene"]), name, "."))
        sgbm_ms = float("nan")
        if stereo:
            depths, sgbm_ms = stereo_depths(seq)
        else:
            depths = seq["depth"]
        truths[name] = truth_notes(seq)
        m0 = seq["scene"].state["models"]["object"]
        grid0 = f"{len(m0.load_points)} x {len(m0.axis('pseudo_time').values) - 1}"
        for step in steps:
            r = dict(scene=name, object=obj, depth=depth_kind, grid=grid0, sgbm_ms=sgbm_ms,
                     **run(seq, depths, scene, step))
            rows.append(r)
            print(r, flush=True)
        if not args.quick:  # Alg. 5.1's delta, the scene's decimation: contact found against deformation overdrawn
            for delta in DELTAS:
                r = dict(scene=name, object=obj, depth=depth_kind, grid=grid0, sgbm_ms=sgbm_ms,
                         **run(seq, depths, scene, 2, threshold=delta))
                rows.append(r)
                print(r, flush=True)
        if not args.no_thesis_grid:  # the same frames, the estimator on the thesis's load grid (scene's decimation)
            path = str(cached_model(f"{obj}_thesis_grid"))
            mt = load_model(path, fields=["displacement"])
            r = dict(scene=name, object=obj, depth=depth_kind,
                     grid=f"{len(mt.load_points)} x {len(mt.axis('pseudo_time').values) - 1}", sgbm_ms=sgbm_ms,
                     **run(seq, depths, scene, 2, model_path=path))
            rows.append(r)
            print(r, flush=True)
        del seq, depths

    def plot(plt):
        fig, ax = plt.subplots(1, 3, figsize=(15, 3.8))
        for name, _, _ in chosen:
            rr = [r for r in rows if r["scene"] == name]
            rr = [r for r in rr if r["grid"] == rr[0]["grid"] and r["threshold_mm"] == rr[0]["threshold_mm"]]
            x = [r["step"] for r in rr]
            mk = "o-" if "stereo" not in name else "s--"
            ax[0].plot(x, [r["agree_pct"] for r in rr], mk, label=name)
            ax[1].plot(x, [r["surface_mm"] for r in rr], mk, label=name)
            ax[2].plot(x, [r["ms"] for r in rr], mk, label=name)
        for name, _, _ in chosen[:1]:
            ax[0].axhline(next(r for r in rows if r["scene"] == name)["free_baseline_pct"], color="gray", lw=0.8,
                          ls=":", label="always 'free'")
        for a in ax:
            a.set_xscale("log", base=2)
            a.set_xlabel("decimation step (every N-th pixel per direction)")
            a.legend(fontsize=7)
        ax[0].set_ylabel("contact agreement with the truth (% of frames)")
        ax[1].set_ylabel("surface RMS error vs full-order truth (mm)")
        ax[2].set_ylabel("depth -> contact per frame (ms)")
        fig.tight_layout()
        return fig

    cols = [("scene", "scene", "{}"), ("depth", "depth", "{}"), ("grid", "load grid", "{}"),
            ("step", "decimation", "{}"), ("threshold_mm", "delta (mm)", "{:.0f}"),
            ("agree_pct", "agrees (%)", "{:.0f}"), ("free_baseline_pct", "all-free (%)", "{:.0f}"),
            ("precision_pct", "precision (%)", "{:.0f}"), ("recall_pct", "recall (%)", "{:.0f}"),
            ("point_mm", "point (mm)", "{:.1f}"), ("force_err_N", "force err (N)", "{:.2f}"),
            ("surface_mm", "surface (mm)", "{:.3f}"), ("truth_rms_mm", "true |u| RMS (mm)", "{:.3f}"),
            ("model_error_mm", "model error (mm)", "{:.3f}"), ("model_error_max_mm", "max", "{:.3f}"),
            ("stress_kpa", "von Mises err (kPa)", "{:.2f}"), ("truth_vm_kpa", "true von Mises RMS (kPa)", "{:.2f}"),
            ("model_stress_kpa", "model error (kPa)", "{:.2f}"), ("phantom_mm", "phantom (mm)", "{:.3f}"),
            ("ms", "time (ms)", "{:.2f}"), ("p95_ms", "p95 (ms)", "{:.2f}"), ("sgbm_ms", "SGBM (ms)", "{:.0f}")]
    tnotes = "; ".join(
        f"{n}: {t['law']} on {t['dofs']} dofs (h {t['h_mm']:.1f} mm), probe past the scan "
        f"{', '.join(f'{p:.2f}' for p in t['press_mm'])} mm, peak force "
        f"{', '.join(f'{f:.2f}' for f in t['peak_force_N'])} N, penetration <= {t['max_penetration_mm']:.4f} mm, "
        f"interpolation <= {t['interp_err_pct']:.2f} %, the model's load point "
        f"{', '.join(f'{f:.1f}' for f in t['first_touch_mm'])} mm off the scan, threshold {t['threshold_mm']:.0f} mm"
        for n, t in truths.items() if "stereo" not in n)
    notes = ("Truth: full-order large-strain contact solve of the rigid probe sphere on the scanned body, per stroke ("
             + tnotes + "). Contact: Alg. 5.1's CONTACT against a true force > 1 mN; 'all-free' is the agreement of "
             "an estimator that never reports a contact. Point: the estimate's load point to the true contact's "
             "force centroid (object frame), mm. Surface / von Mises: RMS over the scan's vertices, median "
             "over the frames the truth is in contact; model error: the model at the true contact's nearest load "
             "point with the pseudo-time that fits the true displacement best. Phantom: drawn displacement on frames "
             "the estimate calls contact and the truth does not. True camera pose; SGBM on the grey pair, its time "
             "apart from the contact time.")
    save(args.out, rows, cols,
         "The seed probe scenes (bunny, dragon; RGB-D and stereo) against a full-order large-strain contact truth",
         notes, plot, extra={"truth": truths})


if __name__ == "__main__":
    main()
