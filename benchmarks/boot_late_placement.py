"""The joint boot placed after its lever moved (issue 16): registered from depth views of the lever already bent, as a
live graph whose SLAM starts late, or whose registration was refused at first, collects them.

The scene is ``joint_boot_truth``: the real boot rendered from an independent full-order solve (neo-Hookean
hexahedra on a finer mesh than the model's; `synth/truth.py:boot_lever_truth`), 8 s at 30 fps, its lever resting for
1.5 s and then moving (up to 49 degrees, in a direction alpha_z 20 degrees from the boot's own), the boot placed by
registration from the scene file's guess by eye, tracked with the scene file's settings (map points, the lever read
from every depth image, alpha_z a constant). The ROS-free pipeline runs every second frame (the live graph takes
11-16 of the 30 frames a second on 2 cores, ``live_slam.md``); the registration collects its depth views from a given
time of the clip on (earlier frames: "waiting"), and its result is placed 6 s into the clip at the earliest (when
the live graph's worker delivered it in stop 103's ``live_slam`` run of this clip) or at once. Deterministic: one run
per row.

Each setting runs twice on the same frames: as the code places a body of revolution registered deformed (its pose
keeps the guess's turn about its axis, the deformed fit's turn is the load's direction and starts the tracker's
alpha_z: ``register_loaded``, ``Registration.turn``, stop 104), and with that turn put back into the pose and alpha_z
started from the scene file (what the code did until stop 104; the deformed fit's polish, also stop 104's, in both).
Errors are over the frames after the placement whose true lever is more than about 1 degree from rest; beside them the
largest alpha_z error in the first 0.5 s after the placement (before the tracker's map points are linked) and the
tracker's time on the frame it was placed in (its first depth read).

Since stop 105, in both: the tracker's first depth read searches the turn about the boot's axis and starts alpha_z
there, the frames read from the depth alone (no map points linked yet) give their turn as the image-fitted ones do,
and the registration's deformed fit searches its turn over the circle (``depth_state._searched_turn``). Stop 104's
table, on its code, is kept as ``boot_late_placement_stop104``; stop 105's as ``boot_late_placement_stop105`` (stop
106 ranks the search's candidates from one search tree per state: every figure the same, the times shorter).

    ./run bench boot_late_placement
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from benchmarks.common import save
from simreal_nodes.assimilation.objects import ObjectTrackers
from simreal_nodes.assimilation.registration import Registration, turned_about_axis

SCENE = "joint_boot_truth"
EVERY = 2  # the frames the pipeline takes: every second one (about the live graph's rate on 2 cores)
PLACE_S = 6.0  # the earliest placement (s into the clip): the live worker's delivery in stop 103's run
VIEWS_FROM_S = (0.0, 1.5, 2.0, 2.5, 3.5, 5.0)  # the registration's depth views from this time of the clip on
LOADED_RAD = 0.02  # the lever more than about 1 degree from rest (as live_slam)
EARLY_S = 0.5  # the frames this soon after the placement (s): those the tracker had no map points linked in yet
CODES = ("turn as alpha_z (stop 104)", "turn in the pose (before)")


class LatePlacement(ObjectTrackers):
    """:class:`ObjectTrackers` whose registration takes its depth views from ``views_from_ns`` (bag time) on and whose
    result is placed at ``place_ns`` at the earliest; ``turn_in_pose``: a body of revolution's registration turn
    (:attr:`Registration.turn`) put back into its pose and alpha_z left at the scene's start (the code before stop
    104). ``now_ns``: the current frame's stamp, set by the caller before each update."""

    def __init__(self, *args: Any, views_from_ns: int, place_ns: int, turn_in_pose: bool, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.views_from_ns, self.place_ns, self.turn_in_pose = views_from_ns, place_ns, turn_in_pose
        self.now_ns = 0
        self.held: tuple[str, Registration] | None = None
        self._view_stamps: list[int] = []  # the stamps of the depth views taken, in order
        self.used_stamps: list[int] = []  # those of the views the placed registration was made from
        self.seconds = float("nan")  # the placed registration's time (s)

    def _register(self, o: dict[str, Any], T_wc: np.ndarray | None, depth: np.ndarray | None) -> str:
        if o["id"] in self.registrations:
            return ""
        if self.held is None:
            if self.now_ns < self.views_from_ns:
                return "waiting for registration (its views later in the clip)"
            # a depth view is taken this frame where the registration counts a posed frame with depth at its step
            # (ObjectTrackers._register); its stamp goes in first, as the registration may run on it at once
            step = (self._posed.get(o["id"], -1) + 1) % self.registration.every
            if T_wc is not None and depth is not None and step == 0:
                self._view_stamps.append(self.now_ns)
            t = time.perf_counter()
            why = super()._register(o, T_wc, depth)
            if self.held is not None:
                self.seconds = time.perf_counter() - t  # the registration that was placed: its call
            if self.held is None:
                return why
        if self.now_ns < self.place_ns:
            return "registering (the result held until the live graph's delivery)"
        assert self.held is not None
        oid, reg = self.held
        self.held = None
        return super()._placed(oid, reg)

    def _placed(self, oid: str, reg: Registration) -> str:
        if self.turn_in_pose and reg.turn:
            centre = self.models[oid].points.mean(axis=0)
            reg = dataclasses.replace(reg, T_map_obj=turned_about_axis(reg.T_map_obj, reg.turn, centre), turn=0.0)
        self.held = (oid, reg)
        self.used_stamps = self._view_stamps[-self.registration.frames:]
        return "registering (the result held until the live graph's delivery)"


def run_case(views_from_s: float, place_s: float, turn_in_pose: bool) -> dict:
    """One pass over the clip; the row of errors."""
    import cv2

    from simreal_nodes import geometry as G
    from simreal_nodes.assimilation.evaluate import read_parameters
    from simreal_nodes.assimilation.offline import Pipeline
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.demo import sample_bag
    from simreal_nodes.io import bags
    from simreal_nodes.io.sources import bag_frames
    from simreal_nodes.scene.schema import build_spec_models, load_scene

    cv2.setNumThreads(1)
    bag, scene_yaml = sample_bag(SCENE, echo=lambda *a: None)
    scene = build_spec_models(load_scene(scene_yaml))
    truth = read_parameters(bag, "/ground_truth/objects/boot/parameters")
    T_true = None
    for m in bags.read_bag(bag, topics=["/ground_truth/objects/boot/pose"]):
        p = bags.decode(m).pose
        T_true = G.pose7_to_matrix([p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y,
                                    p.orientation.z, p.orientation.w])
        break
    assert T_true is not None
    cam = scene["camera"]
    frames = list(bag_frames(bag, cam["image"], cam["camera_info"], cam["depth"]))[::EVERY]
    t0 = frames[0].stamp_ns
    pipe = Pipeline(scene, CameraModel.from_camera_info(frames[0].camera_info), feedback_delay=1)
    objs = LatePlacement(pipe.objects.objects, pipe.objects.models, pipe.objects.registration,
                         views_from_ns=t0 + round(views_from_s * 1e9), place_ns=t0 + round(place_s * 1e9),
                         turn_in_pose=turn_in_pose)
    objs.set_camera(pipe.cam)
    pipe.objects, pipe.trackers = objs, objs.trackers
    i_th, i_az = truth.names.index("theta"), truth.names.index("alpha_z")
    rows, placed_s, first_ms = [], float("nan"), float("nan")
    for f in frames:
        objs.now_ns = f.stamp_ns
        depth = f.depth.astype(np.float32) / (1000.0 if f.depth_encoding == "16UC1" else 1.0)
        k = int(np.searchsorted(truth.stamps, f.stamp_ns))
        _, est = pipe.step(f.image, f.stamp_ns, depth)
        e = est["boot"]
        if not np.isfinite(placed_s) and "boot" in objs.registrations:
            placed_s = (f.stamp_ns - t0) / 1e9
            first_ms = pipe.tracker_ms  # the frame it was placed in: the tracker built, its first depth read
        if "boot" in objs.registrations:
            rows.append((truth.values[k, i_th], e.values[e.names.index("theta")], truth.values[k, i_az],
                         e.values[e.names.index("alpha_z")], (f.stamp_ns - t0) / 1e9 - placed_s))
    a = np.array(rows) if rows else np.zeros((0, 5))
    keep = a[:, 0] > LOADED_RAD
    th = np.degrees(np.abs(a[keep, 1] - a[keep, 0]))
    az = np.degrees(np.abs(a[keep, 3] - a[keep, 2]))
    early = az[a[keep, 4] < EARLY_S]
    reg = objs.registrations.get("boot")
    row = dict(code=CODES[1] if turn_in_pose else CODES[0], views_from_s=views_from_s, place_s=place_s,
               placed_s=placed_s, lever_at_views_deg=float(np.degrees(np.mean(
                   [truth.values[int(np.searchsorted(truth.stamps, t)), i_th] for t in objs.used_stamps])))
               if objs.used_stamps else float("nan"),
               frames=int(keep.sum()), theta_median_deg=float(np.median(th)) if len(th) else float("nan"),
               theta_p90_deg=float(np.percentile(th, 90)) if len(th) else float("nan"),
               alpha_median_deg=float(np.median(az)) if len(az) else float("nan"),
               alpha_p90_deg=float(np.percentile(az, 90)) if len(az) else float("nan"),
               alpha_early_max_deg=float(early.max()) if len(early) else float("nan"), first_frame_ms=first_ms)
    if reg is not None:
        T = objs.trackers["boot"].T_map_obj  # the pose the tracker runs on
        D = G.inv(T_true) @ T
        row.update(registered_theta_deg=float(np.degrees(reg.state[0])) if reg.state is not None else 0.0,
                   registered_turn_deg=float(np.degrees(reg.turn)),
                   pose_turn_deg=float(np.degrees(G.turn_about_z(D[:3, :3]))),
                   pose_mm=float(1e3 * np.linalg.norm(D[:3, 3])), registration_s=objs.seconds)
    return row


COLS = [("code", "code", "{}"), ("views_from_s", "views from (s)", "{:.1f}"),
        ("lever_at_views_deg", "true lever at the views (deg)", "{:.1f}"),
        ("place_s", "placed at the earliest (s)", "{:.1f}"), ("placed_s", "placed (s)", "{:.1f}"),
        ("registered_theta_deg", "registration's lever (deg)", "{:.1f}"),
        ("registered_turn_deg", "registration's turn (deg)", "{:.1f}"),
        ("pose_turn_deg", "pose's turn off the truth (deg)", "{:.1f}"),
        ("pose_mm", "pose's origin off (mm)", "{:.1f}"), ("registration_s", "registration (s)", "{:.1f}"),
        ("frames", "lever frames scored", "{}"), ("theta_median_deg", "theta median err (deg)", "{:.2f}"),
        ("theta_p90_deg", "p90 (deg)", "{:.2f}"), ("alpha_median_deg", "alpha_z median err (deg)", "{:.2f}"),
        ("alpha_p90_deg", "alpha_z p90 (deg)", "{:.2f}"),
        ("alpha_early_max_deg", "alpha_z max err, first 0.5 s placed (deg)", "{:.2f}"),
        ("first_frame_ms", "tracker, frame placed (ms)", "{:.0f}")]


def main() -> None:
    rows = []
    for views_from in VIEWS_FROM_S:
        for place in (PLACE_S, 0.0):
            for turn_in_pose in (False, True):
                row = run_case(views_from, place, turn_in_pose)
                rows.append(row)
                print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
    report(rows)


def report(rows: list[dict]) -> None:
    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        for code, c in zip(CODES, ("tab:blue", "tab:red")):
            for place, ls in ((PLACE_S, "-"), (0.0, ":")):
                sel = [r for r in rows if r["code"] == code and r["place_s"] == place]
                lab = f"{code}, placed {'at 6 s' if place else 'at once'}"
                ax[0].plot([r["lever_at_views_deg"] for r in sel], [r["alpha_median_deg"] for r in sel], "o" + ls,
                           color=c, label=lab)
                ax[1].plot([r["lever_at_views_deg"] for r in sel], [r["theta_median_deg"] for r in sel], "o" + ls,
                           color=c, label=lab)
        ax[0].set_ylabel("alpha_z median |error| (deg)")
        ax[1].set_ylabel("theta median |error| (deg)")
        for a in ax:
            a.set_xlabel("true lever angle at the registration's views (deg)")
            a.set_yscale("log")
        ax[0].legend(fontsize=7)
        fig.tight_layout()
        return fig

    def worst(code, key):
        sel = [r[key] for r in rows if r["code"] == code and r["lever_at_views_deg"] > 1.0]
        return f"{min(sel):.2f}-{max(sel):.2f}" if sel else "n/a"

    save("boot_late_placement", rows, COLS,
         "The joint boot placed after its lever moved: the registration's turn about a body of revolution's axis",
         f"Over the settings whose registration saw the lever bent (true lever over 1 degree at its views), alpha_z's "
         f"median error: {worst(CODES[0], 'alpha_median_deg')} degrees with the turn as alpha_z, "
         f"{worst(CODES[1], 'alpha_median_deg')} with it in the pose; theta's "
         f"{worst(CODES[0], 'theta_median_deg')} and {worst(CODES[1], 'theta_median_deg')}. The scene "
         "(`joint_boot_truth`) is rendered from an independent full-order solve, every second frame taken (the live "
         "graph's rate), the registration's depth views from the given time on, its result placed at 6 s at the "
         "earliest (stop 103's live run of this clip) or at once. Model error: the angle whose model displacement is "
         "closest to the truth's is 0.40 degrees off at the median over the solved angles (`thesis_truth_boot.md`, "
         "'model bias'). alpha_z is 20 degrees in this clip; the boot's turn about its own axis is not in its rest "
         "shape, so the guess fixes it (1.1 degrees off here) and alpha_z is measured from it. 'pose's turn off the "
         "truth': the turn about the axis of the pose the tracker runs on against the true pose's; 'pose's origin "
         "off': its axis origin's distance from the truth's. One deterministic run per row (the ROS-free pipeline, "
         "synchronous).", plot)


if __name__ == "__main__":
    main()
