"""Where the joint boot's wrong measurements come from (issue 16): each object measurement of a family boot scene
labelled against the independent truth, by how the SLAM measured it.

    python -m benchmarks.boot_measurements                 # development seeds 10 and 12
    python -m benchmarks.boot_measurements --seeds 0-3 --slam deformable_radius=6 --out NAME   # a knob

A measurement is a linked map point's observed pixel. Its link names a material point of the model's surface and holds
where that point sits at rest in the map (``Link.X_rest``: the point under the pixel's viewing ray when it was linked).
The truth's material point there (the nearest point of the full-order truth's rest surface, placed by the true pose),
moved by the truth's displacement at the frame's lever angle and projected by the true camera, is where the measurement
should be. (Not the link's nodes read in the truth's frame: at rest the boot's turn alpha_z is not observable, and those
name the material point the tracker's current alpha_z puts there.) A measurement more than 3 x Huber (6 px) from it is
wrong: its feature does not sit on the material point its link claims. Labels by source
(:attr:`DeformableTracks.sources`): ``flow`` (followed from the previous frame by Lucas-Kanade), ``descriptor``
(re-acquired by ORB within ``SlamConfig.deformable_radius`` of the prediction) and ``map`` (matched by the pose's
search, before the point was flagged deformable). A point's track starts at a measurement of another source than flow;
each wrong flow measurement is traced to its track's start: wrong there already (the flow followed a wrong match), or
right there (the flow slid since).

Each frame is also fitted twice, from the previous frame's estimate and with its bounds, as the tracker's own fit
(Huber 2 px): on all of the frame's measurements, and on those the truth calls right (an oracle: what the tracker would
read without the wrong measurements; never an estimate). Their lever-angle errors over the frames more than about a
degree from rest (% of the 52 degree range, median per scene) say what the wrong measurements cost. The truth labels
nothing the pipeline sees.
"""

from __future__ import annotations

import argparse
import copy
import functools

import numpy as np

from benchmarks.common import save
from benchmarks.family import _depth_or_pair, parse_seeds, scene_map
from benchmarks.family_boot import AT_REST_RAD, FPS
from simreal_nodes.synth.boot_family import THETA_RANGE_DEG

WRONG_PX = 6.0  # 3 x the boot's Huber scale (2 px): the refits' inlier bound (lm.solve_generic)
SOURCES = ("flow", "descriptor", "map")


def truth_pixels(truth, T_map_truth: np.ndarray, T_map_cam: np.ndarray, K: np.ndarray, X_map: np.ndarray,
                 theta: float) -> np.ndarray:
    """(N, 2) ideal pixels where the truth (placed in the map by ``T_map_truth``) puts its material points nearest
    the rest positions ``X_map`` (map frame): each snapped to the nearest point of the truth's rest surface, moved by
    the truth's displacement at ``theta`` there (barycentric on its triangle), projected by the true camera."""
    import open3d as o3d

    from simreal_nodes import geometry as G

    mesh = o3d.t.geometry.TriangleMesh()
    mesh.vertex.positions = o3d.core.Tensor(truth.points.astype(np.float32))
    mesh.triangle.indices = o3d.core.Tensor(truth.surface.astype(np.int32))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(mesh)
    y = G.transform(G.inv(T_map_truth), X_map)
    cp = scene.compute_closest_points(o3d.core.Tensor(y.astype(np.float32)))
    tri = truth.surface[cp["primitive_ids"].numpy().astype(np.int64)]
    uv = cp["primitive_uvs"].numpy().astype(np.float64)
    bary = np.c_[1.0 - uv[:, 0] - uv[:, 1], uv]
    foot = np.einsum("nk,nkd->nd", bary, truth.points[tri])
    moved = foot + np.einsum("nk,nkd->nd", bary, truth.displacement(theta)[tri])
    Xc = G.transform(G.inv(T_map_cam) @ T_map_truth, moved)
    return Xc[:, :2] / Xc[:, 2:] * np.diag(K)[:2] + K[:2, 2]


def frame_fit(tr, meas: tuple, sel: np.ndarray, T_cw: np.ndarray, x0: np.ndarray, lo: np.ndarray,
              hi: np.ndarray) -> float:
    """The tracker's Huber fit of one frame's measurements ``meas`` (those in ``sel``) from ``x0``: the first
    parameter (theta)."""
    from simreal_nodes.assimilation import lm

    X, uvm, nodes, w = meas[:4]
    p = lm.Problem(X[sel], uvm[sel], tr._disp_fn(nodes[sel], w[sel]), T_cw, tr.R_wo, tr.K, tr.layout)
    return float(lm.solve(p, x0, lo, hi, tr.cfg.huber_px, tr.cfg.max_iterations).x[0])


def run_scene(seed: int, slam: dict | None = None, tracking: dict | None = None) -> dict:
    """One boot scene through the offline pipeline, its measurements labelled frame by frame (module docstring)."""
    from simreal_nodes import geometry as G
    from simreal_nodes.assimilation.offline import Pipeline
    from simreal_nodes.scene.schema import build_spec_models, validate_scene
    from simreal_nodes.synth.sequence import sequence
    from simreal_nodes.vision.slam.config import SlamConfig

    seq = sequence.__wrapped__(f"family-boot-{seed}", 640, 480, fps=FPS)
    sc = seq["scene"]
    d, truth = sc.state["draw"], sc.state["truth"]
    doc = copy.deepcopy(sc.scene_yaml(sc))
    doc["objects"][0]["tracking"].update(tracking or {})
    scene = build_spec_models(validate_scene(doc, sc.name, "."))
    pipe = Pipeline(scene, seq["cam"], slam_config=SlamConfig(**slam) if slam else None)
    K = seq["cam"].K
    # the truth's mesh frame: the boot's axis frame turned by the drawn alpha_z (as the scene renders it)
    T_map_truth = seq["truth"][0].object_poses["boot"] @ G.make_T(G.rot_axis("z", np.deg2rad(d.alpha_z_deg)))
    labels: list[tuple[str, bool, bool, str]] = []  # (source, wrong, bent, the track's start: source + "-wrong"/"")
    start: dict[int, str] = {}  # point id -> how its current track started ("descriptor", "map-wrong", ...)
    last_frame: dict[int, int] = {}  # point id -> the last frame it was measured in
    fits: list[tuple[float, float, float]] = []  # (true theta, all measurements' fit, the right ones' fit)
    for i in range(len(seq["rgb"])):
        tr = pipe.trackers.get("boot")
        x_prev = None if tr is None else tr.values.copy()
        bgr = np.ascontiguousarray(seq["rgb"][i][:, :, ::-1])
        T_wc, _ = pipe.step(bgr, int(i * 1e9 / FPS), *_depth_or_pair(seq, i))
        tr = pipe.trackers.get("boot")
        ids, P, uv = pipe.observed
        if tr is None or T_wc is None or ids is None or x_prev is None or len(x_prev) != len(tr.values):
            continue
        meas = tr.map_point_measurements(ids, P, uv)
        if meas is None:
            continue
        X, uvm, _, _, mids = meas[:5]
        theta = float(seq["truth"][i].params["boot"][2][0])
        wrong = np.linalg.norm(uvm - truth_pixels(truth, T_map_truth, seq["T"][i], K, X, theta), axis=1) > WRONG_PX
        bent = theta > AT_REST_RAD
        src = pipe.loc.slam.tracks.sources
        for pid, bad in zip(mids, wrong):
            pid = int(pid)
            s = src.get(pid, "map")
            if s != "flow" or last_frame.get(pid) != i - 1 or pid not in start:
                start[pid] = s + ("-wrong" if bad else "")
            labels.append((s, bool(bad), bent, start[pid]))
            last_frame[pid] = i
        if not bent or (~wrong).sum() < tr.cfg.min_measurements:
            continue
        lo, hi = tr._free_bounds()
        lo, hi = np.minimum(lo, x_prev), np.maximum(hi, x_prev)
        T_cw = G.inv(T_wc)
        fits.append((theta, frame_fit(tr, meas, np.ones(len(X), bool), T_cw, x_prev, lo, hi),
                     frame_fit(tr, meas, ~wrong, T_cw, x_prev, lo, hi)))
    # per measurement: source index, wrong, bent, its track's start (bit 0: wrong there, bit 1: a descriptor match)
    L = np.array([(SOURCES.index(s), bad, bent, b.endswith("-wrong") + 2 * b.startswith("descriptor"))
                  for s, bad, bent, b in labels], dtype=int).reshape(-1, 4)
    row: dict = {"seed": seed, "speckle": d.speckle_contrast}
    for phase, sel in (("bent", L[:, 2] == 1), ("rest", L[:, 2] == 0)):
        row[f"{phase}_n"] = int(sel.sum())
        row[f"{phase}_wrong_pct"] = float(100 * L[sel, 1].mean()) if sel.any() else float("nan")
    bent = L[:, 2] == 1
    for k, s in enumerate(SOURCES):
        sel = bent & (L[:, 0] == k)
        row[f"{s}_n"] = int(sel.sum())
        row[f"{s}_wrong_pct"] = float(100 * L[sel, 1].mean()) if sel.any() else float("nan")
    wrong_flow = bent & (L[:, 0] == 0) & (L[:, 1] == 1)
    n_wf = max(int(wrong_flow.sum()), 1)
    row["wrong_flow_from_descriptor_pct"] = float(100 * (wrong_flow & (L[:, 3] == 3)).sum() / n_wf)
    row["wrong_flow_from_map_pct"] = float(100 * (wrong_flow & (L[:, 3] == 1)).sum() / n_wf)
    row["wrong_flow_slid_pct"] = float(100 * (wrong_flow & (L[:, 3] % 2 == 0)).sum() / n_wf)
    F = np.array(fits, dtype=float).reshape(-1, 3)
    for k, name in ((1, "fit_all"), (2, "fit_right")):
        err = 100 * np.rad2deg(np.abs(F[:, k] - F[:, 0])) / THETA_RANGE_DEG
        row[f"{name}_median_pct"] = float(np.median(err)) if len(err) else float("nan")
    row["fitted_frames"] = len(F)
    return row


COLS = [("seed", "seed", "{}"), ("speckle", "speckle contrast", "{:.2f}"),
        ("rest_n", "at rest: measurements", "{}"), ("rest_wrong_pct", "wrong (%)", "{:.1f}"),
        ("bent_n", "bent: measurements", "{}"), ("bent_wrong_pct", "wrong (%)", "{:.1f}"),
        ("flow_n", "flow", "{}"), ("flow_wrong_pct", "flow wrong (%)", "{:.1f}"),
        ("wrong_flow_from_descriptor_pct", "wrong flow: track began at a wrong descriptor match (%)", "{:.0f}"),
        ("wrong_flow_from_map_pct", "at a wrong map match (%)", "{:.0f}"),
        ("wrong_flow_slid_pct", "began right, slid (%)", "{:.0f}"),
        ("descriptor_n", "descriptor", "{}"), ("descriptor_wrong_pct", "descriptor wrong (%)", "{:.1f}"),
        ("map_n", "map", "{}"), ("map_wrong_pct", "map wrong (%)", "{:.1f}"),
        ("fitted_frames", "frames fitted", "{}"),
        ("fit_all_median_pct", "frame fit, all: theta error (% of range)", "{:.2f}"),
        ("fit_right_median_pct", "frame fit, the right ones (oracle)", "{:.2f}")]


def main() -> None:
    from benchmarks.family_boot import _knobs

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="10,12", help="development seeds (default: the two traced in stop 66)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--slam", nargs="*", default=[], metavar="KEY=VALUE", help="SlamConfig fields (a knob)")
    ap.add_argument("--tracking", nargs="*", default=[], metavar="KEY=VALUE", help="the object's tracking keys")
    ap.add_argument("--out", default="boot_measurements")
    a = ap.parse_args()
    slam, tracking = _knobs(a.slam), _knobs(a.tracking)
    rows = list(scene_map(functools.partial(run_scene, slam=slam, tracking=tracking), parse_seeds(a.seeds), a.jobs))
    knobs = "".join(f", SlamConfig.{k}: {v}" for k, v in slam.items()) + "".join(
        f", tracking.{k}: {v}" for k, v in tracking.items())
    tot = {s: sum(r[f"{s}_n"] for r in rows) for s in SOURCES}
    bad = {s: sum(r[f"{s}_n"] * r[f"{s}_wrong_pct"] / 100 for r in rows if r[f"{s}_n"]) for s in SOURCES}
    notes = (f"Development seeds {a.seeds}{knobs}: each object measurement of the boot labelled against the "
             f"independent truth (wrong: more than {WRONG_PX:g} px from where the truth puts the material point its "
             "link claims; `python -m benchmarks.boot_measurements`, module docstring). Over the scenes, frames "
             "more than about a degree from rest: "
             + ", ".join(f"{s} {tot[s]} measurements, {100 * bad[s] / max(tot[s], 1):.0f} % wrong" for s in SOURCES)
             + ". Each wrong flow measurement is traced to the start of its track (a descriptor or map match, wrong "
             "already there, or right there and slid since). The frame fits start from the "
             "previous frame's estimate with the tracker's Huber fit; 'the right ones' is an oracle that drops the "
             "measurements the truth calls wrong, never an estimate.")

    def plot(plt):
        fig, ax = plt.subplots(figsize=(7, 3.5))
        x = np.arange(len(rows))
        for k, s in enumerate(SOURCES):
            ax.bar(x + (k - 1) * 0.27, [r[f"{s}_wrong_pct"] for r in rows], 0.27, label=s)
        ax.set_xticks(x, [str(r["seed"]) for r in rows])
        ax.set_xlabel("development seed")
        ax.set_ylabel("wrong measurements, bent (%)")
        ax.legend()
        return fig

    save(a.out, rows, COLS, "Where the joint boot's wrong measurements come from", notes, plot)


if __name__ == "__main__":
    main()
