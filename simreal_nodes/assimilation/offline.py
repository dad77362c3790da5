"""The ROS-free tracking pipeline on frames in memory: localization core + deformable tracker, as the nodes
chain them (used by tests and benchmarks; the nodes add only message conversion and timing).

``scene``: a validated scene dict (``load_scene`` / ``validate_scene``) whose ``spec:NAME`` models are built
(``build_spec_models``: validation only names their cache files), unless ``models`` gives them; frames: BGR
images (+ depth for RGB-D, + right grey image for stereo: the trackers' depth is then SGBM on the pair, made only in
the frames where they read depth) with stamps. Returns one :class:`Estimate` per frame.
"""

from __future__ import annotations

import time
from typing import Any

import cv2
import numpy as np

from simreal_nodes.assimilation.localizer import make_localizer
from simreal_nodes.assimilation.objects import ObjectTrackers
from simreal_nodes.assimilation.registration import RegistrationConfig
from simreal_nodes.assimilation.tracker import Estimate
from simreal_nodes.camera import CameraModel
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.vision.slam.config import SlamConfig


class Pipeline:
    """Localization (markers / SLAM / static) + one deformable tracker per tracked object.

    ``feedback_delay``: the trackers' word on which map points lie on the object reaches the localization this
    many frames late (0: at once; in the live graph the localization is already on the next frame, 1).
    ``slam_config``: the SLAM's tuning (SLAM modes; default :class:`SlamConfig`)."""

    def __init__(self, scene: dict[str, Any], cam: CameraModel, baseline: float | None = None,
                 models: dict[str, ReducedModel] | None = None, feedback_delay: int = 0,
                 slam_config: SlamConfig | None = None, **cfg_overrides: Any) -> None:
        self.feedback_delay = int(feedback_delay)
        self._feedback: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.focus: list[np.ndarray] = []  # where the trackers put their objects in the last frame (image polygons)
        self.observed: tuple[np.ndarray | None, ...] = (None, None, None)  # the last step's observations (step)
        loc = scene["localization"]
        self.mode = loc["mode"]
        self.freeze_map = bool(loc.get("freeze_map_on_deformation", False))
        self.cam = cam
        self.loc = make_localizer(loc, cam, baseline, slam_config=slam_config)
        tracked = [o for o in scene["objects"] if o["tracking"]["enabled"]]
        models = {o["id"]: (models or {}).get(o["id"]) or load_model(o["model"], fields=["displacement"])
                  for o in tracked}
        self.objects = ObjectTrackers(tracked, models, RegistrationConfig.for_camera(scene["camera"]), **cfg_overrides)
        self.objects.set_camera(cam)
        if self.mode == "stereo" and not scene["camera"].get("depth"):  # the trackers' depth: SGBM on the pair
            self.objects.depth_baseline = baseline
            self.objects.stereo_min_depth = float(scene["camera"]["stereo_min_depth_m"])
        self.trackers = self.objects.trackers
        self.tracker_ms = 0.0  # the last step's deformable-tracking work (update, focus, feedback): the tracker node's

    def step(self, bgr: np.ndarray, stamp_ns: int, depth: np.ndarray | None = None,
             right: np.ndarray | None = None) -> tuple[np.ndarray | None, dict[str, Estimate]]:
        gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
        ids = P = uv = None
        r = self.loc.step(gray, stamp_ns, depth=depth, right=right, focus=self.focus)
        T_wc = r.T_wc
        if T_wc is not None and len(r.obs_ids):
            ids, P, uv = np.asarray(r.obs_ids), np.asarray(r.obs_pos), np.asarray(r.obs_uv)
        self.observed = (ids, P, uv)  # this frame's map point observations the trackers got (None: none)
        t0 = time.perf_counter()
        if depth is None and right is not None:
            depth = self.objects.depth_of_pair(gray, right)
        out = self.objects.update(T_wc, ids, P, uv, bgr, depth)
        # the objects' image regions for the next frame's features (a frame late, like the feedback; the camera
        # moves little in a frame and the polygons are hulls of the whole surface)
        self.focus = [poly for _, poly in self.objects.focus(T_wc)]
        feedback = self.objects.feedback()
        self.tracker_ms = (time.perf_counter() - t0) * 1e3
        if self.freeze_map and any(e.deforming for e in out.values()):
            self.loc.set_localization_only(True)
        # points on a tracked object leave the pose estimate as soon as they are linked (static/deformable
        # split, §4.4.1); they are searched where the current estimate puts them
        self._feedback.append(feedback)
        while len(self._feedback) > self.feedback_delay:
            ids, P, flags = self._feedback.pop(0)
            if len(ids):
                self.loc.feedback(ids, P, flags)
        return T_wc, out


def track_sequence(seq: dict[str, Any], scene: dict[str, Any], every: int = 1, feedback_delay: int = 0,
                   **cfg_overrides: Any) -> dict[str, dict[str, Any]]:
    """Run the pipeline over a rendered :func:`~simreal_nodes.synth.sequence.sequence` (every ``every``-th frame);
    returns per object (truth (T, n), estimates list, names)."""
    pipe = Pipeline(scene, seq["cam"], baseline=seq["scene"].stereo_baseline, feedback_delay=feedback_delay,
                    **cfg_overrides)
    res: dict[str, dict[str, Any]] = {oid: {"truth": [], "est": [], "names": tr.names}
                                      for oid, tr in pipe.trackers.items()}  # a registered object's: at its guess
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
