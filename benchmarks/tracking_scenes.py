"""Deformable tracking end to end on rendered scenes with truth (issue 6): RGB-D SLAM + deformable tracker on the
foam beam (load position s, §4.5.2) and the joint boot (lever angle theta and unknown rotation alpha_z, §4.5.4),
with the map frozen at the first deformation (the thesis's localization-only mode, §4.4.1) or kept mapping
(the default: object points never vote for the pose, new ones are linked in the estimated deformed shape), and
at two resolutions.

    ./run bench tracking_scenes

The estimator sees the images and depth only; the truth is compared afterwards. Also writes docs/tracking.md.
"""

from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np

from benchmarks.common import RESULTS, save
from simreal_nodes.assimilation.offline import Pipeline
from simreal_nodes.assimilation.tracker import LOST, OK
from simreal_nodes.scene.schema import validate_scene
from simreal_nodes.synth.sequence import sequence

CASES = [  # scene, object, width, height, freeze map on deformation
    ("foam_beam", "beam", 640, 480, False),
    ("foam_beam", "beam", 640, 480, True),
    ("foam_beam", "beam", 1280, 720, False),
    ("joint_boot", "boot", 640, 480, False),
    ("joint_boot", "boot", 640, 480, True),
]
LOAD_RANGE = {"s": 0.6975 - 0.1}


def run_case(seq, name, oid, freeze):
    scene = validate_scene(seq["scene"].scene_yaml(seq["scene"]), name, ".")
    scene = copy.deepcopy(scene)
    scene["localization"]["freeze_map_on_deformation"] = freeze
    pipe = Pipeline(scene, seq["cam"])
    names = pipe.trackers[oid].names
    truth, est, states, step_ms, solve_ms = [], [], [], [], []
    for i in range(len(seq["rgb"])):
        bgr = np.ascontiguousarray(seq["rgb"][i][:, :, ::-1])
        t0 = time.perf_counter()
        _, out = pipe.step(bgr, int(i * 1e9 / seq["scene"].fps), seq["depth"][i])
        step_ms.append(1e3 * (time.perf_counter() - t0))
        e = out[oid]
        solve_ms.append(e.solve_ms)
        tn, _, tv = seq["truth"][i].params[oid]
        d = dict(zip(tn, tv))
        truth.append([d.get(n, np.nan) for n in names])
        est.append(e.values)
        states.append(e.state)
    return names, np.array(truth, float), np.array(est), np.array(states), np.array(step_ms), np.array(solve_ms)


def main():
    rows, curves = [], []
    seqs = {}
    for name, oid, w, h, freeze in CASES:
        if (name, w) not in seqs:
            seqs = {(name, w): sequence(name, w, h)}  # one rendered sequence in memory at a time
        names, truth, est, states, step_ms, solve_ms = run_case(seqs[(name, w)], name, oid, freeze)
        row = dict(scene=name, resolution=f"{w}x{h}", map="frozen" if freeze else "mapping",
                   ok_pct=100 * np.mean(states == OK), lost_pct=100 * np.mean(states == LOST),
                   step_ms=float(np.median(step_ms)), solve_ms=float(np.median(solve_ms[solve_ms > 0])))
        loaded = np.isfinite(truth[:, 0]) & (np.abs(truth[:, 0]) > (0.02 if name == "joint_boot" else -1))
        for j, n in enumerate(names):
            if n == "alpha_z":
                row["alpha_err_deg"] = float(np.degrees(abs(est[-1, j] - truth[-1, j])))
                continue
            err = np.abs(est[loaded, j] - truth[loaded, j])
            if n == "s":
                row["median_err"] = f"{1e3 * np.median(err):.1f} mm ({100 * np.median(err) / LOAD_RANGE['s']:.2f} % range)"
                row["p90_err"] = f"{1e3 * np.percentile(err, 90):.1f} mm ({100 * np.percentile(err, 90) / LOAD_RANGE['s']:.1f} %)"
            else:
                row["median_err"] = f"{np.degrees(np.median(err)):.2f} deg"
                row["p90_err"] = f"{np.degrees(np.percentile(err, 90)):.2f} deg"
        rows.append(row)
        curves.append((f"{name} {w}x{h} {row['map']}", truth[:, 0], est[:, 0], names[0]))
        print(row, flush=True)

    notes = ("Targets (issue 6): foam beam median load-position error < 0.5 % of the span; joint boot theta within "
             "0.5 deg, alpha_z within 1 deg. 'frozen': mapping stops at the first deformation (thesis §4.4.1); "
             "'mapping': it goes on. step: localization + tracking per frame (Python, 2-core CPU); solve: the LM "
             "(with its global restarts) alone.")

    def plot(plt):
        fig, ax = plt.subplots(1, len(curves), figsize=(4 * len(curves), 3.4), sharey=False)
        for a, (lbl, tr, es, n) in zip(ax, curves):
            a.plot(tr, "k-", lw=2, label="truth")
            a.plot(es, "-", color="tab:red", lw=1, label="estimate")
            a.set_title(lbl, fontsize=9)
            a.set_xlabel("frame")
            a.set_ylabel(n)
        ax[0].legend(fontsize=8)
        fig.tight_layout()
        return fig

    cols = [("scene", "scene", "{}"), ("resolution", "resolution", "{}"), ("map", "map", "{}"),
            ("median_err", "median error", "{}"), ("p90_err", "p90 error", "{}"), ("alpha_err_deg", "alpha_z error (deg)", "{:.2f}"),
            ("ok_pct", "OK (%)", "{:.0f}"), ("lost_pct", "lost (%)", "{:.0f}"), ("step_ms", "step (ms)", "{:.0f}"),
            ("solve_ms", "solve (ms)", "{:.2f}")]
    save("tracking_scenes", rows, cols, "Deformable tracking on rendered scenes (RGB-D SLAM + PGD tracker)", notes, plot)
    doc = Path(__file__).resolve().parents[1] / "docs" / "tracking.md"
    body = (RESULTS / "tracking_scenes.md").read_text().replace("](tracking_scenes.png)", "](../benchmarks/results/tracking_scenes.png)")
    doc.write_text(INTRO + "\n" + body.split("\n", 1)[1])


INTRO = """# Deformable tracking: how the measurements are made, and what it achieves

Made by `./run bench tracking_scenes`; the table below is its output.

How a frame is measured (thesis ch. 4, `vision/slam/system.py`, `assimilation/tracker.py`):

1. **Static / deformable split** (§4.4.1). Map points within `link_dist` of the registered model surface are
   linked to it and never vote for the camera pose; the rest localizes the camera.
2. **Links** (Eq. 4.10). Each object point gets 3 model nodes and weights: the corners of the closest surface
   triangle with the barycentric coordinates of its foot (exactly the mesh's own interpolation), and the point's
   rest position is that foot. For nodes on no triangle (the lever's grid) the nearest triangle of near nodes.
   The thesis's inverse-distance weights (`method="idw"`) smear the displacement: 0.7 mm median on the boot at
   50 deg, ~1 mm on the lever, which grows with the rotation into a theta bias. A point first mapped while the
   object is deformed is linked on the estimated deformed surface and carried back to rest.
3. **Deformable ORB tracking** (§4.4.2). Each object point is followed from frame to frame by pyramidal
   Lucas-Kanade flow (11 px window, forward-backward check 0.5 px) started at its predicted pixel (rest position
   moved by the current estimate), and re-acquired by ORB descriptor near the prediction when the flow loses it.
   Descriptors alone lose a deforming, obliquely seen surface within a second (the median Hamming distance of
   the foam's points to their keyframe descriptors reaches ~60 bits by frame 30, the match limit is 50); the
   first version, which searched by
   descriptor near the last observation, lost the foam beam from frame 80 (median error 0.12 m) and the boot at
   large theta.
4. **Assimilation** (Eq. 4.7-4.12). LM with Huber weights from the previous frame's estimate; if that fit is poor
   (RMS above 0.75 x Huber or under 85 % inliers) the cost is evaluated on a coarse grid of the free parameters and
   LM restarted from the best sample (a load moved across mid-span passes a larger deflection, a second basin).
   Points the fit rejects (> 2 x Huber) lose their flow track and are re-acquired.
5. **Constants** (Fig. 4.19). alpha_z is estimated only from frames where its standard deviation is below 0.25 %
   of its range (a barely bent boot says nothing about how it is turned) and frozen at the median of 40 such frames.

Why mapping goes on by default: with the map frozen, the camera leaves the mapped views and its pose error grows
to 6-25 mm, which the tracker reads as deformation (the 'frozen' rows below: boot theta error 4x larger, the foam
beam lost on 16 % of the frames). The thesis's behaviour stays available:
`localization.freeze_map_on_deformation: true`.

Why the foam beam misses its target (0.5 % of the span): its load position is weakly observable where it matters.
The beam rests on two supports, so a load at mid-span (s = 0.4 m) gives the largest deflection and the deflected
shape changes with s only to second order there; most tracked points also lie near the supports, where loads at
0.2 and 0.4 m bend the beam alike. A 1-2 px measurement error then moves s by centimetres (errors of 5 cm at
s = 0.4, flagged low-confidence on part of those frames). More pixels help (0.77 % at 1280 x 720, the thesis's
resolution); more ORB features helped on one run (3 000 instead of 1 500: 4.2 mm) but not on another (5 000:
7.4 mm), so the default stays.
"""


if __name__ == "__main__":
    main()
