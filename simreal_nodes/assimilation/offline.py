"""The ROS-free tracking pipeline on frames in memory: localization core + deformable tracker, as the nodes
chain them (used by tests and benchmarks; the nodes add only message conversion and timing).

``scene``: a validated scene dict (``load_scene`` / ``validate_scene``) whose ``spec:NAME`` models are built
(``build_spec_models``: validation only names their cache files), unless ``models`` gives them; frames: BGR
images (+ depth for RGB-D, + right grey image for stereo) with stamps. Returns one :class:`Estimate` per frame.
"""

from __future__ import annotations

import cv2
import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.tracker import DeformableTracker, Estimate, deformable_feedback, tracker_config
from simreal_nodes.camera import CameraModel
from simreal_nodes.rom.model_file import load_model


class Pipeline:
    """Localization (markers / SLAM) + one deformable tracker per tracked object.

    ``feedback_delay``: the trackers' word on which map points lie on the object reaches the localization this
    many frames late (0: at once; in the live graph the localization is already on the next frame, 1)."""

    def __init__(self, scene: dict, cam: CameraModel, baseline: float | None = None, models: dict | None = None,
                 feedback_delay: int = 0, **cfg_overrides):
        self.feedback_delay = int(feedback_delay)
        self._feedback: list = []
        loc = scene["localization"]
        self.mode = loc["mode"]
        self.freeze_map = bool(loc.get("freeze_map_on_deformation", False))
        self.cam = cam
        if self.mode == "markers":
            from simreal_nodes.vision.markers import MarkerLocalizer

            mk = loc["markers"]
            self.loc = MarkerLocalizer(cam, mk["dictionary"], mk["size_m"],
                                       {int(k): G.pose7_to_matrix(v) for k, v in mk["poses"].items()})
        elif self.mode == "static":
            self.loc = None
            self.static = G.pose7_to_matrix(loc["static_pose"])
        else:
            from simreal_nodes.vision.slam.system import Slam

            self.loc = Slam(cam, self.mode, loc["features"], loc["scale_factor"], loc["pyramid_levels"], baseline=baseline,
                            known_scale=loc.get("known_scale_m"), async_mapping=False)
        self.trackers = {}
        for o in scene["objects"]:
            if not o["tracking"]["enabled"]:
                continue
            m = (models or {}).get(o["id"]) or load_model(o["model"], fields=["displacement"])
            self.trackers[o["id"]] = DeformableTracker(m, G.pose7_to_matrix(o["anchor"]["pose"]), o["parameters"], cam,
                                                       tracker_config(o, **cfg_overrides))

    def step(self, bgr: np.ndarray, stamp_ns: int, depth=None, right=None) -> tuple[np.ndarray | None, dict[str, Estimate]]:
        gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
        ids = P = uv = None
        if self.mode == "markers":
            T_wc = self.loc.locate(gray).T_wc
        elif self.mode == "static":
            T_wc = self.static
        else:
            r = self.loc.track(gray, stamp_ns, depth=depth, right=right)
            T_wc = r.T_wc
            if T_wc is not None and len(r.obs_ids):
                ids, P, uv = np.asarray(r.obs_ids), np.asarray(r.obs_pos), np.asarray(r.obs_uv)
        out = {}
        deforming = False
        for oid, tr in self.trackers.items():
            out[oid] = tr.update(T_wc, ids, P, uv, bgr)
            deforming |= out[oid].deforming
        if deforming and self.freeze_map and self.loc is not None and hasattr(self.loc, "set_localization_only"):
            self.loc.set_localization_only(True)
        if self.loc is not None and hasattr(self.loc, "set_deformable"):
            # points on a tracked object leave the pose estimate as soon as they are linked (static/deformable
            # split, §4.4.1); they are searched where the current estimate puts them
            self._feedback.append(deformable_feedback(self.trackers.values()))
            while len(self._feedback) > self.feedback_delay:
                ids, P, drop = self._feedback.pop(0)
                if len(ids):
                    self.loc.set_deformable(ids, P)
                    self.loc.drop_tracks(ids[drop == 1])
        return T_wc, out


def track_sequence(seq: dict, scene: dict, every: int = 1, feedback_delay: int = 0, **cfg_overrides) -> dict:
    """Run the pipeline over a rendered :func:`~simreal_nodes.synth.sequence.sequence` (every ``every``-th frame);
    returns per object (truth (T, n), estimates list, names)."""
    pipe = Pipeline(scene, seq["cam"], baseline=seq["scene"].stereo_baseline, feedback_delay=feedback_delay,
                    **cfg_overrides)
    res = {oid: {"truth": [], "est": [], "names": tr.names} for oid, tr in pipe.trackers.items()}
    for i in range(0, len(seq["rgb"]), every):
        bgr = np.ascontiguousarray(seq["rgb"][i][:, :, ::-1])
        depth = seq["depth"][i] if scene["camera"]["depth"] else None
        right = seq["right"][i] if seq["right"] else None
        _, est = pipe.step(bgr, int(i * 1e9 / seq["scene"].fps), depth, right)
        for oid, e in est.items():
            names, _, vals = seq["truth"][i].params[oid]
            d = dict(zip(names, vals))
            res[oid]["truth"].append([d.get(n, np.nan) for n in res[oid]["names"]])
            res[oid]["est"].append(e)
    for r in res.values():
        r["truth"] = np.asarray(r["truth"], dtype=np.float64)
    return res
