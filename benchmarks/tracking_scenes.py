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
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.states import EstimateState
from simreal_nodes.synth.sequence import sequence
from simreal_nodes.vision.slam.config import SlamConfig

# scene, object, width, height, freeze map on deformation, knob (label, tracker overrides, SlamConfig overrides)
DEFAULT = ("default", {}, {})
SHIFT = {"foam_beam": ("no object shift", {"object_shift_m": 0.0}, {}),  # the foam scene fits it by default
         "joint_boot": ("object shift 10 mm", {"object_shift_m": 0.01}, {})}
KNOBS = [("anchor foot", {"anchor": "foot"}, {}),  # rest position at the mapped point's foot, not on its pixel's ray
         ("flow anchor 1 px", {}, {"flow_anchor_px": 1.0}),  # tracks re-measured against their first image
         ("flow window 21", {}, {"flow_win": 21}),
         ("coherence 8 px", {}, {"coherence_px": 8.0}),  # object measurements moving unlike their neighbours dropped
         ("rest points culled", {}, {"hold_rest_points": False})]  # the map culls the points linked at rest (stop 64)
CASES = [
    ("foam_beam", "beam", 640, 480, False, DEFAULT),
    ("foam_beam", "beam", 640, 480, True, DEFAULT),
    *[("foam_beam", "beam", 640, 480, False, k) for k in KNOBS[-2:]],  # the two that touch the map's object points
    ("foam_beam", "beam", 1280, 720, False, DEFAULT),
    *[("foam_beam", "beam", 1280, 720, False, k) for k in [SHIFT["foam_beam"]] + KNOBS],
    ("joint_boot", "boot", 640, 480, False, DEFAULT),
    ("joint_boot", "boot", 640, 480, True, DEFAULT),
    *[("joint_boot", "boot", 640, 480, False, k) for k in [SHIFT["joint_boot"]] + KNOBS],
]
SPAN = {"s": 0.7575}  # foam beam: between the support centres (the target is 0.5 % of the span)


def run_case(seq, name, oid, freeze, knob=DEFAULT):
    scene = build_spec_models(validate_scene(seq["scene"].scene_yaml(seq["scene"]), name, "."))
    scene = copy.deepcopy(scene)
    scene["localization"]["freeze_map_on_deformation"] = freeze
    pipe = Pipeline(scene, seq["cam"], slam_config=SlamConfig(**knob[2]), **knob[1])
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
    for name, oid, w, h, freeze, knob in CASES:
        if (name, w) not in seqs:
            seqs = {(name, w): sequence(name, w, h)}  # one rendered sequence in memory at a time
        names, truth, est, states, step_ms, solve_ms = run_case(seqs[(name, w)], name, oid, freeze, knob)
        row = dict(scene=name, resolution=f"{w}x{h}", map="frozen" if freeze else "mapping", knob=knob[0],
                   ok_pct=100 * np.mean(states == EstimateState.OK),
                   lost_pct=100 * np.mean(states == EstimateState.LOST),
                   step_ms=float(np.median(step_ms)), solve_ms=float(np.median(solve_ms[solve_ms > 0])))
        loaded = np.isfinite(truth[:, 0]) & (np.abs(truth[:, 0]) > (0.02 if name == "joint_boot" else -1))
        for j, n in enumerate(names):
            if n == "alpha_z":
                row["alpha_err_deg"] = float(np.degrees(abs(est[-1, j] - truth[-1, j])))
                continue
            err = np.abs(est[loaded, j] - truth[loaded, j])
            if n == "s":
                row["median_err"] = f"{1e3 * np.median(err):.1f} mm ({100 * np.median(err) / SPAN['s']:.2f} % span)"
                p90 = np.percentile(err, 90)
                row["p90_err"] = f"{1e3 * p90:.1f} mm ({100 * p90 / SPAN['s']:.1f} %)"
            else:
                row["median_err"] = f"{np.degrees(np.median(err)):.2f} deg"
                row["p90_err"] = f"{np.degrees(np.percentile(err, 90)):.2f} deg"
        rows.append(row)
        if knob is DEFAULT:
            curves.append((f"{name} {w}x{h} {row['map']}", truth[:, 0], est[:, 0], names[0]))
        print(row, flush=True)

    notes = ("Targets (issue 6): foam beam median load-position error < 0.5 % of the span; joint boot theta within "
             "0.5 deg, alpha_z within 1 deg; the span is the 757.5 mm between the support centres. 'frozen': mapping "
             "stops at the first deformation (thesis §4.4.1); 'mapping': it goes on. knob: one setting changed from "
             "the default (anchor foot: a linked point's rest position is its mapped point's foot on the surface "
             "instead of its pixel's viewing ray; flow anchor: tracks re-measured against their first image; flow "
             "window: Lucas-Kanade window in pixels, 11 by default; coherence: an object measurement whose offset "
             "from its prediction differs by more than that from its image neighbours' median offset is dropped; rest "
             "points culled: the map culls young object points linked at rest like any other). step: localization + "
             "tracking per frame (Python, 2-core CPU); solve: the LM (with its global restarts) alone.")

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

    cols = [("scene", "scene", "{}"), ("resolution", "resolution", "{}"), ("map", "map", "{}"), ("knob", "knob", "{}"),
            ("median_err", "median error", "{}"), ("p90_err", "p90 error", "{}"),
            ("alpha_err_deg", "alpha_z error (deg)", "{:.2f}"),
            ("ok_pct", "OK (%)", "{:.0f}"), ("lost_pct", "lost (%)", "{:.0f}"), ("step_ms", "step (ms)", "{:.0f}"),
            ("solve_ms", "solve (ms)", "{:.2f}")]
    save("tracking_scenes", rows, cols, "Deformable tracking on rendered scenes (RGB-D SLAM + PGD tracker)", notes,
         plot)
    write_doc()


def write_doc() -> None:
    """docs/tracking.md: the introduction, the thesis's beams on independent physics (`benchmarks/thesis_truth.py`)
    when that table exists, then this benchmark's table (scenes rendered by the model they fit)."""
    parts = [INTRO]
    for name, heading in (("thesis_truth", "The thesis's beams on independent physics (`./run bench thesis_truth`)"),
                          ("thesis_truth_boot", "The joint boot on independent physics (`./run bench thesis_truth`)"),
                          ("tracking_scenes", "Scenes rendered by the model they fit (`./run bench tracking_scenes`: "
                                              "zero model error, pose from the truth; knobs and unit-level checks, not "
                                              "evidence of accuracy)")):
        md = RESULTS / f"{name}.md"
        if md.exists():
            body = md.read_text().replace(f"]({name}.png)", f"](../benchmarks/results/{name}.png)")
            parts.append(f"## {heading}\n\n" + body.split("\n", 1)[1])
    (Path(__file__).resolve().parents[1] / "docs" / "tracking.md").write_text("\n".join(parts))


INTRO = """# Deformable tracking: how the measurements are made, and what it achieves

Made by `./run bench thesis_truth` (the first table) and `./run bench tracking_scenes` (the second); the tables
below are their output.

**The thesis's beams on independent physics** (the first table). The aluminium bar (§4.5.1) and the foam beam
(§4.5.2) rendered from full-order solves the tracker's models never saw (`synth/scenes.py`: `aluminium_truth`, linear
P2 tetrahedra on twice the model's grid, the weight as a pressure on its footprint; `foam_truth`, Saint
Venant-Kirchhoff P2 tetrahedra, Newton at each position of the disk), the object's pose not taken from the truth,
each scene's model error beside its result.

- *Foam beam*, the defaults (dense) and registration (0.1-0.2 mm, 0.02 deg off): median error 1.4 mm (0.18 % of the
  span), mean 1.8 mm at the thesis's 1280 x 720, where the thesis reports a mean "on the order of 1.5 mm": we are
  about 0.3 mm worse (our camera: 15 fps on a hand-held arc about 1 m away; the thesis's path is not given). 640 x
  480: median 1.6 mm, mean 2.2 mm. (Stops 107, 109, 119 and 122's runs, on Intel, AMD, Intel and AMD hosts, the same
  to the printed digit; stop 119's 640 x 480 p90 4.0 -> 4.1 mm and median 0.22 -> 0.21 % of the span; stop 86's run
  read a median of 1.3 mm at 1280 x 720 (1.35 against 1.39 now), as stop 80's did. The rows of 2026-11-27 read 1.3 /
  1.9 mm and 1.4 / 2.2 mm.) Model error: 1.7 % of the displacement, a load-position bias of 0.9 % of the span when
  fitted to every surface node.
- The foam *model* was wrong before this table existed: the spec's 32 linear hexahedra along the beam resolved the
  40 mm support strips as 25 mm, and its deflection was 26 % larger than the converged full-order solve (model bias
  11.8 % of the span; the tracker read the load 11 % of the span off, the model's error, not the tracker's). Its
  spec now has 40 cells (a node at each strip's end) of quadratic hexahedra (linear ones lock: 10 % too stiff at
  40 x 8 x 4); the truth's own grid is within 1 % of the converged linear deflection.
- *Aluminium bar* with the thesis's glued dots: its pose measured by hand (2.0 mm and 0.9 deg off) is fatal as given
  (median 91 mm: a cantilever's bending looks like a turn about its clamp). With `tracking.rest_frames: 10` the pose
  is corrected from the first frames, where the bar is at rest (by 0.4 deg and 2.7 mm; the dots' rms 2.1 -> 0.11 px),
  and then held: median 2.9 mm (0.60 % of the 480 mm range), mean 3.0 mm (stops 107, 109, 119 and 122; stop 86's run:
  2.8 mm, 0.59 %, 2.9 mm); Table 4.1's own measure (at each position the weight rests at, |mean estimate - position|;
  the median over the six positions) 2.0 mm against the thesis's 2.2 mm at the same positions (the thesis does not
  state its camera resolution; ours is 640 x 480 at 0.45-0.65 m). Rerun in stop 86 on this code, where the markers'
  edges start from OpenCV's sub-pixel corners (stop 80's run, on commit 9b5de31, started them from the unrefined
  corners): median 2.9 -> 2.8 mm, mean 3.0 -> 2.9 mm, p90 5.8 -> 5.9 mm, Table 4.1's measure 2.1 -> 2.0 mm, the
  corrected pose 0.04 mm off as before. Stop 80's run itself had moved them from the corners before the edges (the
  corrected pose's position 0.24 -> 0.04 mm off; the load's median 2.7 -> 2.9 mm, mean 3.3 -> 3.0 mm, p90 6.7 -> 5.8
  mm, Table 4.1's measure 1.9 -> 2.1 mm), position by position by up to 1.5 mm both ways: one recording's per-position
  means, not a trend. What stays of the pose error (0.8 deg) is the roll about the row of dots, which does not move
  them. The rest correction fits the undeformed bar's small rigid motion over the first `rest_frames` frames with a
  camera pose (Huber, a weak prior of 2 deg / 5 mm for the directions the dots cannot see; the estimate is
  'initializing' meanwhile) and is refused, with its reason, when it does not lower the residual or leaves it above
  1.5 x Huber, when it is larger than 5 deg / 3 cm, and when the frames were not at rest: a bent cantilever fits a
  rigid turn to a fraction of a pixel (0.35 px in the unit test), so the same frames are fitted with the deformation
  free too, and a fit under half the rigid residual (above 0.2 px) refuses it. Off by default: a user who starts the
  recording unloaded turns it on. The corrected pose lives in the tracker; the overlay and collision nodes still place
  the object at the scene file's pose. The project's default measurement, dense, cannot read this bar: its surface is
  plain metal: most loaded frames are flagged 'no measurable deformation' rather than reported (14 % of them OK in
  stops 119 and 122's runs, 13 % before; the estimate 209 mm off at the median).
- *Joint boot* (§4.5.4, its own table): the real boot rendered from an independent neo-Hookean solve
  (`synth/scenes.py:boot_truth`: trilinear hexahedra 72 x 2 x 60, two layers through the wall, Newton every 2 deg of
  the lever; the model: 36 x 1 x 48, NI-PGD), placed by registration from a guess by eye, map points as its scene file
  says. Stop 122's run, on stop 121's code (a 2-core AMD EPYC host, probe 19 ms): the lever read from every depth
  image and alpha_z reported with the depth fit's turn, as the boot's family scene file has it (`tracking.depth_fit`
  and `depth_turn`, chosen on the family's development seeds, `docs/family.md`; the registration polished,
  `anchor.polish_mm: 4`, the boot registered as a body of revolution; stop 119's run, on stop 118's code and an Intel
  Xeon host, then stop 109's, on stop 106's code and an AMD EPYC host, in brackets): the scene's own view reads theta
  **0.29 deg** off at the median (0.28, 0.31), p90 1.12 deg (1.13, 1.25), alpha_z 0.03 deg (0.03, 0.06; the images'
  own alpha_z, the table's next column: 0.15, 0.39 in stop 119), registration 0.2 mm and 0.08 deg off (the same). A
  third view that nothing was chosen on (another arc, the boot turned by 70 deg, another guess): **0.29 deg** (0.28,
  0.31), p90 0.84 deg (1.23, 0.81), alpha_z **0.46 deg** (0.49, 0.52; the images' own: 0.38, 0.38 in stop 119; this
  view also ran with a first version of `depth_turn`, dropped on the own view, so it is not blind to that choice). A
  second view, on which the tracker's handling of alpha_z was fixed: 0.19 deg (0.21, 0.17), alpha_z 0.34 deg (0.37,
  0.36; the images' own: 0.32, 0.06 in stop 119). Between stops 119 and 122 only the host changed for the scene files'
  rows (the code's changes since, a dense reference view refused where no pixel is finite and the tracker node's
  frame-size checks, are not on this ROS-free run's map-point path): every registration the same to the printed digit,
  the tracking after it moved by up to 0.02 deg at the median and 0.39 deg in the held-out view's p90 (1.23 -> 0.84,
  back near the 0.81 of stop 109's run, on an AMD EPYC host of the AVX2 kind; this one has AVX-512). So the p90 move
  between stops 109 and 119, which stop 119 could not split between the code and the host, points to the host; why a
  host's arithmetic moves the boot's later frames this much is not traced (the beams' rows of the first table and the
  registrations repeat to the printed digit across the two hosts). The tracker's time per frame: 27-35 ms in stop
  122's run; 34-44 ms in stop 119's (quiet); 39-48 ms in stop 109's (probe 27 ms against 19 quiet on that host); stop
  105's run (65-109 ms) was taken on a loaded host (its CPU probe read 83 ms against 15-17 quiet); stop 73's quiet run
  read 31-35 ms (stop 72: 37-45 ms; stop 71: 68-81; the images alone 9-16 ms; stop 84's cheaper depth fit, the same
  fits, `benchmarks/results/depth_budget.md`). With the knob `outlier_refits: 3` (commit 319a533's table, the images
  alone) the three read 1.43, 0.15 and 0.17 deg (alpha_z 0.45, 0.12, 0.42). Before stop 65 (the map then culled the
  object points linked at rest) the own view read 0.37 deg. With the Levenberg-Marquardt solver before stop 34 the
  three views read 0.26, 0.12 and 0.27 deg: its change cost the boot about 0.1 deg. Model error: 3.2 % of the
  displacement at the median (6.4 % at the largest angles, where the full-order folds buckle more than the one-layer
  model's; its worst node 17 mm off), a theta bias of 0.4 deg (1.3 deg at most). The thesis gives no figure for this
  example. The boot's table runs OpenCV on one thread: with its worker threads, the second view ended in the mirror
  basin (alpha_z 177 deg off) in one run of three.
- The boot's *model* was too coarse around its axis. With 24 cells, the polygon lay 0.43 mm inside the round boot at
  its base, and registration from a one-sided depth view tilted the boot 1.9 deg to split the difference. The spec now
  has 48 cells around. That choice was made on the scene's own view. The knob rows keep the old model: theta 0.34 deg
  and alpha_z 0.60 deg on the scene's own view, and 0.24 deg and 0.40 deg on the held-out one (the table above, stop
  122's run, the lever read from depth; stop 119's: 0.33 / 0.66 and 0.28 / 0.32; stop 109's: 0.31 / 0.62 and 0.25 /
  0.30; stop 72's: 0.36 / 0.45 and 0.27 / 0.48; 1.58 / 0.01 and 0.26 / 1.04 on the images alone in stop 70).
- alpha_z (a constant of the sequence, Fig. 4.19) keeps its value in frames that cannot see it: a frame judged
  undeformed, or one where its standard deviation exceeds 5 % of its range. A global restart no longer searches
  a constant that earlier frames have already pinned. Before this, on the second view, alpha_z drifted while
  the boot was at rest. In 3 of 4 runs it ended 99 deg off, and theta read 11-13 deg off.

How a frame is measured (thesis ch. 4, `vision/slam/deformable.py`, `assimilation/tracker.py`):

1. **Static / deformable split** (§4.4.1). Map points within `link_dist` of the registered model surface are
   linked to it and never vote for the camera pose; the rest localizes the camera.
2. **Links** (Eq. 4.10). Each object point gets 3 model nodes and weights: the corners of the closest surface
   triangle with barycentric weights (exactly the mesh's own interpolation). For nodes on no triangle (the
   lever's grid) the nearest triangle of near nodes. The thesis's inverse-distance weights (`method="idw"`)
   smear the displacement: 0.7 mm median on the boot at 50 deg, ~1 mm on the lever, which grows with the
   rotation into a theta bias. Where on its triangle: where the viewing ray of the pixel the point was observed
   at crosses it (`anchor: ray`), so the material point linked is the one under the pixel its image track
   follows; the mapped point's foot (`anchor: foot`) carries the depth error's tangential part (the foam beam's
   measurements were 1.1 px off at the first frames with the foot, 0.45 px with the ray). A point first mapped
   while the object is deformed is linked on the estimated deformed surface and carried back to rest.
3. **Deformable ORB tracking** (§4.4.2). A point flagged deformable starts its track at the pixel it was linked
   with; from then on it is followed from frame to frame by pyramidal Lucas-Kanade flow (11 px window,
   forward-backward check 0.5 px) started at its predicted pixel (rest position moved by the current
   estimate), and re-acquired by ORB descriptor near the prediction when the flow loses it.
   Descriptors alone lose a deforming, obliquely seen surface within a second (the median Hamming distance of
   the foam's points to their keyframe descriptors reaches ~60 bits by frame 30, the match limit is 50); the
   first version, which searched by descriptor near the last observation, lost the foam beam from frame 80
   (median error 0.12 m) and the boot at large theta. Frame-to-frame flow drifts (0.4 px after 5 frames, 1 px
   after 30 on the foam beam); re-measuring each track against its first image (`SlamConfig.flow_anchor_px`, off by
   default) holds it at 0.3 px there; its window is translation-only, which a turning surface strains (the
   'flow anchor' rows measure both scenes).
   **Which points the map keeps** (stop 65). A deformable point never joins the pose's matches nor a keyframe's
   fusion, so it gains neither keyframes nor finds, and the SLAM's culling of young points (ORB-SLAM2's) erased
   every object point two keyframes after it was made: on development boot 13, 556 of them in 124 frames, the
   tracker's measurements falling from about 170 at rest to 22-90 once the lever bent. Now the tracker tells the map
   which points it linked at rest (the `flags` field of `/simreal/localization/deformable_points`, bit 1; thesis
   §4.4's scanned points), and the map keeps those (`SlamConfig.hold_rest_points`); a point linked while the object
   was deformed took its material point from the estimate of that moment and is culled as before, a fresh one
   replacing it at a later keyframe. A keyframe makes no new point within `SlamConfig.followed_px` (3 px) of a
   followed deformable point: the pose's matches leave that point out, so its feature looked free, and each
   keyframe made a copy. Measured in docs/family.md (the stop-65 paragraph): the boot's development medians 0.89 /
   0.98 % -> 0.66 / 0.55 % of the lever's range, its held-out median unchanged (1.65 -> 1.60 %); on the boot's own
   view (the model's render in the unit test: 1.55 degrees off at the median, 0.37 with the rest points culled; the
   independent render in the table below: 1.45 in stop 65's run, 0.37 before; 0.31 in stop 109's) the kept points cost
   a degree.
4. **Assimilation** (Eq. 4.7-4.12). LM with Huber weights from the previous frame's estimate; if that fit is poor
   (RMS above 0.75 x Huber or under 85 % inliers) the cost is evaluated on a coarse grid of the free parameters and
   LM restarted from the best sample (a load moved across mid-span passes a larger deflection, a second basin).
   A knob, `outlier_refits` (0 by default), follows the fit with that many more solves on the measurements within 3 x
   Huber, re-classified each round (ORB-SLAM2's pose optimisation); a round that ends with fewer inliers than it was
   fitted to is undone. Huber keeps every outlier's bounded pull, and on the boot a third of the followed points sit
   over 6 px off once the lever bends; 3 rounds helped development boots 0-19 (0.66 -> 0.62 %) but not seeds 20-39
   nor the held-out ones (1.61 -> 1.98 %; docs/family.md, the stop-66 paragraph).
   Points the fit rejects (> 2 x Huber) lose their flow track and are re-acquired. A tracked parameter whose
   standard deviation exceeds that of a uniform draw over its range (range / sqrt 12) was not measured by the frame:
   it keeps its last value, flagged low-confidence (development boot 12 read 0.4 degree for a lever at 47, from 17
   points, and took 10 frames to come back).
5. **Constants** (Fig. 4.19). alpha_z is estimated only from frames where its standard deviation is below 0.25 %
   of its range (a barely bent boot says nothing about how it is turned) and frozen at the median of 40 such frames.

**Dense measurement** (`tracking.measurements: dense`, `assimilation/dense.py`; issue 16). The sparse steps above need
ORB keypoints on the object, and a faint surface gets none. The dense mode measures the object's own texture at every
pixel it covers, the idea of digital image correlation carried through the reduced model: points are sampled on the
model surface about 1.5 px apart in a reference view (the first frame with a camera pose and the object in view, taken
to be at rest); in each new image the residual of sample k is `I(pi(T_cw X_k(theta))) - (a I_ref,k + b + I_ref,k
(n_k(mu) - n_k,ref) . g)` with `X_k = c + R(omega) (T_map_obj (x_k + u_k(mu)) - c) + t`, where u_k(mu) is the PGD
displacement interpolated in the sample's surface triangle (Eq. 4.10's link, dense). Gauss-Newton with Levenberg damping
over a 3-level pyramid, the Jacobian through the PGD sensitivities du/dmu (Eq. 4.11 with image gradients in place of the
reprojection's), Tukey's biweight on the intensity residual (scale from the median absolute deviation: the load's dark
edges have gradients fifty times a faint speckle's and would pull under Huber), a coarse search over mu at the coarsest
level every frame (a load that jumps lands in another basin; the candidates compared at the last frame's brightness, or
each at the brightness fitted to it after a frame whose brightness went stale, `tracking.dense_grid_brightness`, below),
visibility by a coarse depth buffer of the samples. Nuisances: an affine brightness (a, b), the shading change g of a
matte surface whose normal n_k turns as it deforms (under ambient light and one distant light, a turn dn changes the
brightness by about I_ref dn.g; the normals smooth across each face of the model's surface, as a renderer shades it;
`tracking.dense_shading`, on) and a small rigid correction (omega, t) (camera drift, placement error). Without the
shading term a faint plate's twist showed mostly as shading, and the fit put the load across the plate 8-18 mm off
(development plate seed 7: 7.6 % -> 2.5 %; `docs/family.md`, "Plates"); it costs 40-50 % more time per solve (three more
iterations, the normals) and changes the beams' accuracy by nothing measurable on the development family; the beams'
table below was rerun with it in stop 46: the foam beam's errors moved by 0.1 mm at most, its tracker time rose from 109
to 152 ms a frame at 640 x 480 and from 140 to 189 ms at 1280 x 720, and the aluminium bar stays unreadable by dense;
the boot's table measures map points, which it does not touch; the scenes rendered by their own model,
`tracking_scenes.md`, were rerun after it in stop 68). g belongs to the light and the object, the same in every frame:
what each frame the tracker judged sound measured of it (its information with the frame's other unknowns marginalised
out, a Schur complement) is fused over about 50 such frames into the next frames' prior
(`tracking.dense_shading_frames`, 50; 0: each frame alone), so that a barely bent frame cannot pass its deformation off
as shading (`docs/family.md`, "Plates"). Frames the tracker did not judge sound are left out: the frames before a load
is placed, fitted with a load the model cannot leave out, measured g with a large, wrong confidence and held it there
for dozens of frames (development plate seed 2: 0.4 % -> 2.9 % when every frame was fused). A rigid motion of the object
looks much like a cantilever's bending and took its blame on the development scenes, so with a depth image (RGB-D) the
correction is measured where nothing can bend: the static surroundings, a ring 32 px wide around the object's outline in
the reference view (4 px off it), back-projected with that view's depth, enter the same robust cost with their own
brightness. The camera's error epsilon moves the surroundings and the object alike; the object's own placement error is
not refitted on top when the registration measured it from the same depth (it is measured at rest and held otherwise).
On development seeds 0-11, 27, 31, 44 and 46 this took large-load cantilevers that had failed (seed 10: 18 % -> 0.1 %,
seed 46: 24 % -> 0.2 %) to a fraction of a percent. A stereo pair's depth is SGBM on the pair (made in the frames that
read depth: docs/family.md, "Through a stereo pair"). Without depth (mono) the correction is the object's alone: once a
frame at rest has measured it, deformed fits stay within 0.1 deg / 3 mm of it. A further step came from a development
cantilever (seed 12: faint speckle, 6.6 px peak) that read 2.6 % with a steady bias towards less bending, which stayed
with the true camera poses and without shading (a diagnosis with scratch scripts, not in the repository): the
photometric cost itself had its minimum at the truth, but the solve did not reach it. The pyramid's coarse levels, where
the solve starts, sat well below the truth (a faint speckle's detail is gone there, and the brightness gain trades
against the misalignment), and at full resolution Gauss-Newton linearises with image gradients that are mostly noise:
its steps came out short and it stopped short of the minimum from any start. So the solve now ends with a search of the
cost itself (`tracking.dense_refine`, on by default) over each free parameter: 7 points over +-10 % of its range about
the Gauss-Newton solution, narrowed three times by 3, the brightness refitted for each by Tukey-weighted least squares,
at most three free parameters. Over development seeds 12-49, on the same code otherwise: 84 % -> 95 % of scenes within 2
%, p90 2.5 % -> 1.2 %, seed 12 2.6 % -> 0.8 % (`docs/family.md`). In the same diagnosis the camera's error epsilon,
fitted in one solve with the object, still took part of the bending; measured first on the surroundings alone and then
held (`tracking.dense_camera_first`) it took seed 12 to 0.5 %, but over seeds 12-49 it did worse than the joint fit (87
% of scenes within 2 %, p90 2.4 %; rerun with registration's slide pin, the same): a knob, off. Whether a deformation is
seen: the same fit with zero displacement, at the half-resolution level, must be worse by 5 % and the fitted deformation
must move the image by more than 0.3 px. A misaligned frame leaves its brightness behind: where the samples miss the
texture, the best affine brightness explains the image by its mean (a gain a near zero, the bias near the mean
intensity) and the shading g takes whatever it can. Development seed 0 seen at 65 degrees of azimuth
(`docs/stability.md`, the camera at the extremes) lost its camera for 44 frames in stops 47-49 (on the SLAM of stops
50-56 it no longer does: stop 89's rerun of that sweep); after it came back, each frame's coarse search compared its
candidates at that brightness (a low gain, a spurious shading), where they differed by how the spurious shading changed
with mu rather than by how the texture lined up, and the load stayed 28-58 % of the span off for 20 frames, 8 of them
called OK. The search now fits the brightness (a, b, g) to each candidate, as the final search of the cost does,
starting from the plain least-squares fit at that mu, when the warm start's gain is under `DenseSettings.min_gain` (0.5,
the check below): its brightness is stale (`tracking.dense_grid_brightness: auto`, the default since stop 49); the same
frames came back on the load a few frames after the camera's return (a per-frame trace with a scratch script in stop 48;
the sweep's table had the run's medians). Stop 48 fitted every candidate's brightness on every frame (`always`): on
development beams 0-19 that was better by up to 0.27 points of a scene's 90th percentile (seed 7 1.62 -> 1.35 %, seed 12
0.83 -> 0.77 % at the median, seed 19 1.12 -> 1.06 %), but in the camera sweep seed 1 at 80 degrees of azimuth, a
grazing view whose coarsest level keeps few samples of the face, then picked wrong candidates (five brightness
parameters free for each, a misplaced one explained the image nearly as well): the 90th percentile of its frames called
OK went from 0.34 % to 9.8 %. With `auto` that view reads as before stop 48 (0.12 %, p90 0.34 %), the two failing views
stay mended, and every row of the development beams reads as without the fit (`never`, the defaults before stop 48) to
the hundredth in its median, 90th percentile and states (few of their frames start from a gain under 0.5; on beam 14 the
frame after its one misfit moved, its mean 15.11 % -> 14.07 %): `benchmarks/results/family_dev_0_19*.md`,
`docs/stability.md`. Traded that way because a silent tail of 10 % weighs more than a few tenths of a point; `always`
stays a knob. As a last guard the tracker reports a fit whose gain is under `DenseSettings.min_gain` (0.5)
low-confidence, saying so: on the 2630 development frames within 2 % of the span (beams 0-19 and 18 views of seeds 0 and
1: grazing, near, far, 16 grey levels of noise, 4 px of blur) the gain was 0.77 at the least; it is under 0.5 on 5 of
the 240 frames more than 2 % off: seed 0's 4 at 65 degrees (gain -0.06 to 0.11) and one of beam 14 (-0.36) (`python -m
benchmarks.flag_calibration --gain`, `benchmarks/results/flag_calibration_gain.md`). It flags a fit that lost the
texture, not every wrong one: a load near a support, which bends the beam little, is fitted at the full gain at the
other support too (development seed 9: 21 frames at the wrong support, 8 of them called OK, until stop 57). Nor does the
coarse search's margin tell those apart (`grid_margin` in the fit's debug values: how much more the cheapest grid
candidate more than a quarter of a range from the winner costs, as a share of the winner's cost): seed 9's frames at the
wrong support read 0.013-0.07, while 1 % of the 2630 sound frames read under 0.033 and the least 0.0076; under 0.02 it
would catch 5 of the 240 frames more than 2 % off and flag 6 sound ones (`python -m benchmarks.flag_calibration
--margin`). It stays a diagnostic, no flag. What the margin does say is when to look twice (stop 57,
`tracking.dense_basin_check`, 0.1): where the runner-up from another basin costs less than 10 % more than the winner at
the coarsest level, the fit is run a second time from the runner-up (Gauss-Newton over every level, then the search of
the cost) and the cheaper of the two at the finest level is kept. The coarsest level sees a small load's bending at a
quarter of its size, and once it has picked a basin the finer levels only polish it; at full resolution the two basins
are told apart. The trigger was set from the development frames' margins before any run with it (seed 9's wrong frames
read at most 0.072; 9.5 % of the 2870 development frames of `flag_calibration_margin` read under 0.1), and it never
flags: it changes the estimate. It costs a second fit on the frames it runs on (9.5 % of the development frames, about
20 % of the held-out family's); no run of this stop had the host to itself, and on development seeds 0-2, run side by
side with it off, the tracker's median time per frame rose by 3-10 % (321 -> 330, 470 -> 492, 193 -> 212 ms, two scenes
at a time). Development beams 0-19 on the same code with it off and on (`family_dev_0_19_basin`,
`family_dev_basin_off_switched`: the scenes where it moved a loaded frame): seed 9, whose load near a support was read
at the other support on 21 frames, from p90 99.5 % to 0.47 % of the span (mean 19.6 % -> 0.28 %); seeds 6, 7 and 8
within 0.07 points either way (seed 7's p90 1.59 -> 1.66 %, seed 8's 3.72 -> 3.65 %); seeds 0, 1, 2, 5, 11, 14 and 16
the same to the hundredth; all twenty: median of the per-scene medians 0.27 %, p90 1.07 %, 85 % within 1 %, 100 % within
2 %. Held out: the five held-out scenes whose frames stop 55's table had called OK in the wrong basin (1041, 1047, 1051,
1069, 1071: `family_stop57_wrong_basin`, run after the trigger was fixed) keep 6 frames called OK more than 10 % of the
span off, against 33 before (1071: p90 71.2 % -> 1.62 %; 1069: mean 7.62 % -> 0.57 %; 1041: p90 53.1 % -> 2.20 %, its 6
left at 55-58 %, which stop 57 took for two basins of the same cost: stop 58 recorded where the other fit ends, and on
those frames both fits ended in one wrong basin, see below); the held-out seeds from 1000 up (`family_stop57`,
docs/family.md) move by a few hundredths where the check did not move a frame (stop 56's SLAM change) and gain where it
did (1011: mean 5.35 % -> 1.63 %, 1021: 1.48 % -> 0.52 %). A unit test builds two basins that the coarsest level cannot
tell apart (`tests/assimilation/test_dense.py`: a stretch the same for s and 1 - s with a sub-pixel ripple growing with
s): 0.2 read for 0.8 without the check, 0.806 with it. Stop 58 recorded where the other fit ends (the development beams
0-19 rerun, `family_dev_0_19_other`: every row as in stop 57, on another host) and found that held-out 1041's six frames
were no tie: on its frames 40-46 the load at 0.33 of the span was read at 0.14-0.15 by both fits (the other ended within
0.04 of a range of the kept one), while the frames before and after read 0.33 and found the 0.14 basin 9-12 % dearer:
the coarse search had led both starts into one basin. So where both fits end more than a quarter of a range from the
warm start (the last frame's estimate), the fit runs a third time from it and the cheapest is kept
(`tracking.dense_basin_warm`; on in stop 58, off since stop 59: below). It has no threshold of its own (the quarter
range is the runner-up's), but it was made after looking at a held-out scene, so 1041 is no held-out evidence for it. On
the development seeds where a frame met its condition (0, 1, 6, 7, 11, 14, 16, 17: `family_dev_warm`, with seed 9, where
none did) every row is the same to the hundredth: the third fit ran on 20 frames, 17 of them before the load came on,
and was never the cheapest (seed 14's frame 39, 40 % off and flagged for its gain, is one it ran on and lost). Held out
(`family_stop58_warm`: the seeds where a frame could meet its condition in the runs of stop 57's code, and two where
none could): the third fit ran on 37 frames of 23 of them. 1041 (no held-out evidence: it prompted the change): frames
called OK more than 10 % of the span off 6 -> 0, mean 4.61 % -> 0.89 %, p90 2.20 % -> 1.71 %, median 0.88 % -> 0.76 %.
Elsewhere it moved loaded frames' estimates by 0.6 % of the span at most (1005 p90 0.57 % -> 0.64 %, 1062 mean 0.60 % ->
0.63 %, 1044 median 0.66 % -> 0.64 %, 1011 1.74 % -> 1.70 %); 1066 and 1072, where it could not run, are the same to the
digit. Over the 28: median of the per-scene medians 0.56 % either way, p90 1.39 %, frames called OK more than 10 % off 7
-> 1 (1056's one is left), more than 2 % off 95 -> 89. Stop 59 looked for development evidence on the beams 20-49
(`family_dev_20_49`, with it on): the third fit ran on 20 frames of 15 of them and was kept on 7 frames of 7 (20, 32,
34, 36, 40, 41, 47), five of them before the load came on. Rerun with it off (`family_dev_warm_off`): seed 36's frame 52
read 0.695 against 0.696 (truth 0.686), seed 32's frame 111 0.672 against 0.675 (truth 0.679), and seed 41's frame 49,
where the camera was about to be lost, 0.826 against 0.815 (truth 0.611; the value then held while the camera was lost:
p90 36.5 % -> 38.1 % with it on); every other row the same to the hundredth. Over the 50 development beams it helped
none, so by the rule that a knob helping one scene is a knob, it is off by default. What the checks cost (`python -m
benchmarks.basin_cost`: development beams 0, 1, 9, 14, 17, alone on the host, each rendered once and tracked with no
check, with the runner-up's fit (the defaults) and with the third fit too): the second fit ran on 10-31 % of the frames
(40 of 131 on seed 9, whose p90 it takes from 99.5 % to 0.47 %), and on four of the five scenes those frames took 10-44
% longer than the others of the same run (seed 9 274 against 248 ms, seed 17 634 against 440 ms; on seed 14 15 % less);
a frame with the third fit took 1.3-2.2 times the others' time (seed 0 831 against 438 ms, seed 17 921 against 425 ms).
Per-scene means do not rank the settings: two runs of the same work differ by up to 15 % on this host (seed 9 with and
without the third fit, which never ran there: 256 and 295 ms). Stop 58 also flags a frame whose other fit ended more
than a tenth of a range away and costs less than 1 % more at full resolution (`DenseSettings.max_ambiguity_gap`, 0.01:
two loads explain the image alike), naming the other load. It was set on the development beams
(`flag_calibration_ambiguity`): of their 224 loaded frames with a second fit, 150 fell back into the kept basin and 72
ended apart, with gaps of 0.187 at the least (none flagged); before the load comes on, where the image holds no load to
place, 41 of 107 such frames read under 0.01 (median 0.015). On the held-out seeds 1041 and 1066-1099 (`family_stop58`)
it flagged 44 frames, all before the load and already low-confidence (no measurable deformation): it changed no state in
the family. Its unit test is a plate that two loads stretch identically. The gain is measured against the reference
view, so a camera whose automatic exposure halves the object's contrast since that view would be flagged too (the
rendered scenes keep their exposure: not measured); fix the exposure for dense tracking. The flag changes a frame's
state, not its estimate; a frame it flags is not fused into the shading prior (only frames called OK are), but a flagged
frame at rest before any load still holds the placement, as with the camera check. Map points on the object are still
linked, so the localization leaves them out of the camera pose. Scene keys: `tracking.dense_step_px` (sample spacing,
1.5 px), `tracking.dense_rigid` (the rigid correction, on) and `tracking.dense_surroundings_px` (the ring's width, 32
px; 0: the object alone), `tracking.dense_refine` (on), `tracking.dense_shading` (on), `tracking.dense_grid_brightness`
(`auto`) and `tracking.dense_camera_first` (off); their trades are measured on development seeds in `docs/family.md`'s
knob tables. The object's state in the reference view: read from its depth where there is a depth image
(`tracking.reference: depth`, the default, `assimilation/depth_state.py`: the model's deformed surface fitted to the
depth cloud and compared with the rest shape), else taken to be the rest shape. Where a registration fitted the state
to its fused depth views (`anchor: registration` on a loaded object), that state stands unless the reference view's
own depth sees another: its own verdict (its deformed fit, or the rest shape) lowering the rest shape's cost by more
than `depth_state.min_gain` (1 %) beyond what the registration's state lowers it, both held on the same points
(`depth_state.held_gains`; stop 118: one depth image cannot tell load positions a few % of the range
apart on a cantilever, three views tell them better; a body of revolution whose reference fit reads its turn, the
boot with `depth_turn`, keeps its own fit). A scene loaded from its first frame is measured in
`docs/family.md` ("loaded from the first frame"). Numbers: `docs/family.md` (the scene family, dense by
default, the sparse mode beside it).

Why mapping goes on by default: with the map frozen, the camera leaves the mapped views and its pose error grows to
centimetres, which the tracker reads as deformation (the 'frozen' rows below: the boot's p90 13 deg against 1.8 deg and
lost on a third of the frames, the foam beam 97 mm off at the median and lost on 29 % of the frames). The thesis's
behaviour stays available: `localization.freeze_map_on_deformation: true`.

The second table's two scenes run the sparse measurements (`tracking.measurements: map_points` in their scene
files); they are rendered by the model they fit, with the object's pose from the truth, so they show the
mechanics and the knobs' trades, not the accuracy on unseen scenes (that is the first table and `docs/family.md`).

The foam beam's load position (target: median under 0.5 % of the span, at the thesis's 1280 x 720) is weakly observable
where it matters: the beam rests on two supports, a load near mid-span gives the largest deflection and the deflected
shape changes slowly with s there, and most tracked points lie near the supports. What limits it is the camera pose: the
RGB-D map drifts a few mm while the camera sweeps past the beam, and the object's placement does not follow. So the foam
scene also fits a bounded translation of the whole object each frame (`tracking.object_shift_m: 0.01`, a nuisance
parameter marginalised out of the reported covariance): its supports and unloaded parts fix where the beam is relative
to the camera. On the foam model of earlier stops (32 linear hexahedra, 26 % too soft: the first table's notes) it took
the median from 3.2 to 2.0 mm; on the corrected model it trades the other way at the median: 2.7 mm without it and 2.9
mm with it, p90 13.2 mm against 6.7 mm (stop 109's run; stop 68's: 2.8 and 3.0 mm, p90 13.1 and 6.6 mm). The scene keeps
it for the shorter tail; on independent physics the default dense measurement does better than either (the first table).
It is not for an object whose visible part turns (the joint boot's lever: the shift absorbs the rotation, the 'object
shift' row). The load at mid-span (s = 0.4 m) remains the weak position. At 640 x 480 a pixel covers twice the beam (7.3
mm median; stop 68's run: 7.2 mm). Re-measuring tracks against their first image (`flow anchor`) gave the best boot
numbers with the boot's earlier model of 24 cells around (0.19 deg), not with the present one of 48 on the code of
2026-11-25 (0.61 deg against the default's 0.56 deg); on stop 68's code it reads 1.43 deg against 1.55 and gives the
best foam median (1.4 mm against 3.0 mm). Two scenes rendered by their own model do not choose a default (the
development family does), so it stays a measured knob: on the boot family's development seeds 0-39 it reads 1.17 % of
the lever's range against the default's 0.93 % (`docs/family.md`, stop 68).

This table was rerun in stop 68; the one before was of 2026-11-25's code. Since then the boot's default row went from
0.56 to 1.55 deg, the foam beam's from 4.9 to 3.0 mm at 1280 x 720 and from 8.5 to 7.2 mm at 640 x 480. Most of the
boot's degree is stop 65's change, chosen on the boot family's development seeds: the map holds the object points the
tracker linked at rest. Culled like any young point again (`rest points culled`, stop 64's behaviour) the boot reads
0.71 deg (p90 0.92 deg), while the foam beam reads 3.7 mm at 1280 x 720 and 17.9 mm at 640 x 480 (p90 403 mm). The
`coherence 8 px` rows (stop 68's knob, off by default: an object measurement whose offset from its prediction differs by
more than 8 px from its image neighbours' median offset is dropped) read the boot level (1.50 deg) and the foam beam
level at 1280 x 720 (3.1 mm) and far worse at 640 x 480 (18.6 mm, p90 399 mm against 26.6 mm): one reason it is not the
default (`docs/family.md`, stop 68).

Rerun in stop 107 on an Intel Xeon (AVX-512) host and in stop 109 on an AMD EPYC (AVX2) one, on the same code (only a
docstring differs; stop 68's table predated stops 69-106's SLAM and tracker changes). The default rows, stop 109's
with stop 107's in brackets: the boot 1.55 deg at the median (1.56; stop 68: 1.55), p90 1.85 (1.74), alpha_z 0.19 deg
(0.26); the foam beam 2.9 mm at 1280 x 720 (3.1), p90 6.7 (6.6), and 7.3 mm at 640 x 480 (7.4). So the host moves
these rows: the foam's by at most 0.2 mm at the median but for `coherence 8 px` at 640 x 480 (17.0 -> 18.7 mm), the
boot's by at most 0.11 deg, and the boot's alpha_z with a 10 mm object shift most (29.7 -> 20.5 deg). Against stop 68:
the boot with its map frozen 1.56 -> 1.94 deg, with the rest points culled 0.71 -> 0.37 deg (p90 0.92 -> 0.93).
Rendered by the model they fit, these rows check the knobs against each other; the accuracy on independent physics is
the first tables'.

## The dense tracker's time per frame (`python -m benchmarks.dense_budget`)

`benchmarks/results/dense_budget.md` splits the default measurement's time per frame by stage, on the family's
development scenes 0, 3 and 12 (RGB-D, 640 x 480, the offline pipeline, one BLAS thread). It runs each scene in a
fresh process and, with `--against`, in back-to-back pairs with another checkout, the order alternating. Stop 83 made
the same fit cheaper in four ways. Each projection is now one affine map (object frame to camera), and the rotation is
remembered. Image gradients are chained through (n, 3) rows, so the (n, 2, p) pixel Jacobian is never built. The
search's candidates (the refinement's grid, the coarse search's) are costed in one pass. And the cost at an
iteration's start comes from that iteration's own residuals. Against the code before it (8b92757), on a host whose CPU
probe read 25 ms, the tracker's time per frame fell to 0.73 of it (pairs' median; 0.63-0.88 over six pairs; the median
over the runs of each run's p50 268 ms against 366 ms), the estimates at most 1.7e-12 % of the load's range apart
(stop 83's run). Stop 95 reads the samples' intensities as one row of OpenCV's map rather than one column: `cv2.remap`
shares its rows among OpenCV's threads, and a few thousand samples in stripes cost more in wake-ups than they save.
Against stop 94's code (c94f417), probe 18 ms: 0.93 of the time (pairs' median, 0.92-0.96 over six pairs; 138 ms
against 146 at the median of the runs' p50), every estimate the same to the bit and no frame's state different. Stop
96 keeps what a level's fit asks for again and again: the samples' positions and intensities gathered once per level
and set of samples in view (not at every iteration and trial step; dropped when a view is averaged into the template),
the shading's prior until a frame's shading is accepted, the rigid corrections' prior widths; and the robust scale's
two medians come from one partition each, without `np.median`'s generality. Against stop 95's code (ddb8bd2), probe 15
ms: 0.91 of the time (pairs' median, 0.85-0.97 over six pairs; 101 ms against 108 at the median of the runs' p50),
every estimate the same to the bit and no frame's state different. What remains is spread over the stages (p50 per
solved frame, that run): Gauss-Newton 36-68 ms, the refinement 20-32 ms, the camera's check on the surroundings 12-16
ms, the zero-displacement fit (is there a deformation at all?) with the rest 12-19 ms, the coarse search 5-9 ms; the
tracker 91-149 ms a frame in all (stop 95's run: 119-201, on the slower host its probe's 18 ms says; the pairs' ratio
is the change). Stop 120 reran its code alone (two runs a scene, an Intel host, probe 15 ms): Gauss-Newton 38-69
ms, the refinement 20-32, the camera's check 12-16, the rest 13-19, the coarse search 6-9; the tracker 96-152 ms a
frame, every estimate of a scene's second run the same as its first. Stop 121's rerun after the dense reference view's
mend for a hostile lens (`dense_budget.md` holds it, the same host type, probe 16 ms): the same frames solved, every
estimate of a second run the same as its first, Gauss-Newton 40-73 ms, the refinement 22-33, the camera's check
14-17, the rest 15-21, the coarse search 6-10; the tracker 104-157 ms a frame. That is still 10-16 times the 10 ms the
issue asks of the sparse mode, and far from camera rate on 2 cores. The sparse mode (`map_points`) is fast but misses
the accuracy targets (`docs/family.md`).

## The joint boot's tracker time per frame (`python -m benchmarks.depth_budget`)

`benchmarks/results/depth_budget.md` does the same for the joint boot's tracker: map points with the state read from
every depth image (`tracking.depth_fit`, which the boot's scene files set), on the boot family's development scenes 0,
8 and 22 (RGB-D, 640 x 480, the offline pipeline, each run in a fresh process, pairs against another checkout in
alternating order). Stop 84 made the same fits cheaper. The depth image is back-projected only where its pixels can
hold the box the fit crops to (its depth and its undistorted pixel lie within the box corners' bounds, widened against
rounding), normals are turned only for the samples that a depth point matched, and the kept KD-tree's undecided points
are searched in one pass. The search of alpha_z (`constant_search`) links each group of map points for all 24 of its
values in one call instead of one call per group and value. Against the code before it (bce330b), on a host whose CPU
probe read 25 ms: the tracker's time per frame fell to 0.90 of it (pairs' median; 0.51-1.00 over six pairs; the median
over the runs of each run's p50 122 ms against 136 ms). The search of alpha_z costs about half (mean per frame: seed 8
57-64 ms against 99-128, seed 22 16-22 against 37-44), the depth fit 0.64-0.87 of it on seeds 0 and 8 (pair by pair)
and 0.92-1.01 on seed 22. The estimates are identical: no difference in any frame's values or state. What remains: on
seed 22 the depth fit takes 85-96 ms a frame, 49-55 ms of it the search for each depth point's nearest model sample;
on seed 8 the search of alpha_z runs on many frames. The tracker's p50 of 59-139 ms is still 6-14 times the 10 ms that
issue 16 asks of the sparse mode; with `depth_fit` off the boot's tracker took 9 ms (`docs/family.md`).
"""


if __name__ == "__main__":
    main()
