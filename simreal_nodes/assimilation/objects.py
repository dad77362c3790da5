"""The deformable trackers of a scene's tracked objects, as the tracker node and the offline pipeline both keep them:
one :class:`DeformableTracker` per object, built for a camera, updated together every frame."""

from __future__ import annotations

from typing import Any

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.tracker import DeformableTracker, Estimate, deformable_feedback, tracker_config
from simreal_nodes.camera import CameraModel
from simreal_nodes.rom.model import ReducedModel


class ObjectTrackers:
    """``objects``: validated scene objects (those with tracking enabled are tracked); ``models``: their reduced
    models by id; ``cfg_overrides``: :class:`TrackerConfig` fields that override every object's scene settings.

    The trackers depend on the intrinsics (they project the model): :meth:`set_camera` (re)builds them;
    ``trackers`` is the same dict throughout, so a reference to it stays valid."""

    def __init__(self, objects: list[dict[str, Any]], models: dict[str, ReducedModel], **cfg_overrides: Any) -> None:
        self.objects = [o for o in objects if o["tracking"]["enabled"]]
        self.models = models
        self.cfg_overrides = cfg_overrides
        self.cam: CameraModel | None = None
        self.trackers: dict[str, DeformableTracker] = {}

    def set_camera(self, cam: CameraModel) -> None:
        """New intrinsics: every tracker starts again (built now, not on the first frame: that frame would wait)."""
        self.cam = cam
        self.trackers.clear()
        for o in self.objects:
            self._tracker(o)

    def _tracker(self, o: dict[str, Any]) -> DeformableTracker:
        tr = self.trackers.get(o["id"])
        if tr is None:
            assert self.cam is not None, "ObjectTrackers.set_camera comes first"
            tr = DeformableTracker(self.models[o["id"]], G.pose7_to_matrix(o["anchor"]["pose"]), o["parameters"],
                                   self.cam, tracker_config(o, **self.cfg_overrides))
            self.trackers[o["id"]] = tr
        return tr

    def update(self, T_wc: np.ndarray | None, ids: np.ndarray | None = None, P: np.ndarray | None = None,
               uv: np.ndarray | None = None, bgr: np.ndarray | None = None) -> dict[str, Estimate]:
        """One frame for every object (arguments as :meth:`DeformableTracker.update`): estimates by object id.
        A tracker whose build failed on :meth:`set_camera` is built again here."""
        return {o["id"]: self._tracker(o).update(T_wc, ids, P, uv, bgr) for o in self.objects}

    def feedback(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What the localization needs after a frame: :func:`deformable_feedback` of every tracker."""
        return deformable_feedback(self.trackers.values())
