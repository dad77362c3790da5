"""The deformable trackers of a scene's tracked objects, as the tracker node and the offline pipeline both keep them:
one :class:`DeformableTracker` per object, built for a camera, updated together every frame.

An object with ``anchor: registration`` is placed by :func:`~simreal_nodes.assimilation.registration.register_rgbd`
before it is tracked: its depth views (``RegistrationConfig.frames`` frames that have a camera pose, every
``every``-th) are collected, fused in the map frame and registered from the scene's rough ``anchor.guess``. Until
that succeeds its estimate is LOST with the reason (waiting, or the refusal of a bad fit: the views are then
collected afresh from later frames), and its tracker sits at the guess without being updated (it holds no links,
so it tells the localization nothing); on success the tracker is built again at the registered pose."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.registration import (
    DepthViews,
    Registration,
    RegistrationConfig,
    RegistrationError,
    SlideRefused,
    depth_cloud,
    register_loaded,
    register_rgbd,
    turned_about_axis,
)
from simreal_nodes.assimilation.registration_worker import BackgroundRegistration
from simreal_nodes.assimilation.tracker import DeformableTracker, Estimate, deformable_feedback, tracker_config
from simreal_nodes.camera import CameraModel
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.state import ALPHA_Z
from simreal_nodes.states import EstimateState
from simreal_nodes.vision.stereo import stereo_depth


class ObjectTrackers:
    """``objects``: validated scene objects (those with tracking enabled are tracked); ``models``: their reduced
    models by id; ``registration``: how registered objects are placed; ``cfg_overrides``: :class:`TrackerConfig`
    fields that override every object's scene settings.

    The trackers depend on the intrinsics (they project the model): :meth:`set_camera` (re)builds them;
    ``trackers`` is the same dict throughout, so a reference to it stays valid. ``registrations``: the
    registered objects' :class:`Registration` by id, once found."""

    def __init__(self, objects: list[dict[str, Any]], models: dict[str, ReducedModel],
                 registration: RegistrationConfig | None = None, background: bool = False,
                 **cfg_overrides: Any) -> None:
        self.objects = [o for o in objects if o["tracking"]["enabled"]]
        self.models = models
        self.registration = registration or RegistrationConfig()
        self.cfg_overrides = cfg_overrides
        self.cam: CameraModel | None = None
        self.trackers: dict[str, DeformableTracker] = {}
        self.registrations: dict[str, Registration] = {}
        self._views: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self._posed: dict[str, int] = {}  # frames with a camera pose seen while waiting for the registration
        # registrations refused for their slide along the object's axis alone, by object: after
        # RegistrationConfig.slide_refusals of them the position along the axis is taken from the guess
        self._slides: dict[str, int] = {}
        self.depth_baseline: float | None = None  # the depth is SGBM on a stereo pair of this baseline (None: RGB-D)
        self.stereo_min_depth = 0.4  # metres: the nearest depth SGBM searches (the scene's camera.stereo_min_depth_m)
        self.background: BackgroundRegistration | None = None
        if any(o["anchor"]["kind"] == "registration" for o in self.objects):
            if background:  # live: registered in a worker process while frames go on (registration_worker.py)
                self.background = BackgroundRegistration()
            else:
                # Open3D is imported now, not inside the first registration (about 2 s on 2 busy cores)
                import open3d  # noqa: F401

    def set_camera(self, cam: CameraModel) -> None:
        """New intrinsics: every tracker starts again (built now, not on the first frame: that frame would wait);
        depth views taken with the old intrinsics are dropped, a registration found stays."""
        self.cam = cam
        self.trackers.clear()
        self._views.clear()
        for o in self.objects:
            self._tracker(o)

    def _tracker(self, o: dict[str, Any]) -> DeformableTracker:
        tr = self.trackers.get(o["id"])
        if tr is None:
            assert self.cam is not None, "ObjectTrackers.set_camera comes first"
            tr = DeformableTracker(self.models[o["id"]], self._pose(o), o["parameters"], self.cam,
                                   tracker_config(o, **self.cfg_overrides))
            reg = self.registrations.get(o["id"])
            if reg is not None and reg.state is not None and tr.cfg.reference == "depth":
                tr.reference_state = reg.state.copy()
                tr.values[:len(reg.state)] = reg.state
                if self._takes_turn(o):  # the direction the load bends the body of revolution in (register_loaded)
                    i = tr.layout.alpha_index
                    tr.values[i] = float(np.clip(reg.turn, tr.lo[i], tr.hi[i]))
            self.trackers[o["id"]] = tr
        return tr

    def _pose(self, o: dict[str, Any]) -> np.ndarray:
        """The object's pose in the map: the scene's, the registered one, or (not registered yet) the guess. A body of
        revolution registered deformed (:attr:`Registration.turn`) is turned by what its tracker's alpha_z does not
        carry of that turn: nothing where the tracker starts alpha_z from it (:meth:`_takes_turn`), the turn beyond a
        fixed alpha_z's value, the whole turn where there is no alpha_z (or the tracker starts at rest)."""
        if o["anchor"]["kind"] != "registration":
            return G.pose7_to_matrix(o["anchor"]["pose"])
        reg = self.registrations.get(o["id"])
        if reg is None:
            return G.pose7_to_matrix(o["anchor"]["guess"])
        turn = self._turn_in_pose(o, reg)
        if not turn:
            return reg.T_map_obj
        return turned_about_axis(reg.T_map_obj, turn, self.models[o["id"]].points.mean(axis=0))

    def _turn_in_pose(self, o: dict[str, Any], reg: Registration) -> float:
        """The part of ``reg``'s turn that object ``o``'s pose carries (:meth:`_pose`)."""
        if not reg.turn or self._takes_turn(o):
            return 0.0
        p = o["parameters"].get(ALPHA_Z, {})
        if self._has_alpha(o) and p.get("mode") == "fixed":
            return reg.turn - float(p.get("value", 0.0))
        return reg.turn

    def _has_alpha(self, o: dict[str, Any]) -> bool:
        """Whether object ``o``'s tracker carries alpha_z (the scene names it, its model declares it) and turns the
        model about the axis a registration turns it about (the vertical through the model's centroid, within 1 mm):
        then a registration's turn and alpha_z are the same turn."""
        model = self.models[o["id"]]
        rigid = next((r for r in model.rigid_parameters if r["name"] == ALPHA_Z), None)
        if ALPHA_Z not in o["parameters"] or rigid is None:
            return False
        origin = np.asarray(rigid.get("origin", (0.0, 0.0, 0.0)), np.float64)
        return rigid.get("axis", "z") == "z" and bool(np.hypot(*(model.points.mean(axis=0)[:2] - origin[:2])) < 1e-3)

    def _takes_turn(self, o: dict[str, Any]) -> bool:
        """Whether object ``o``'s tracker starts its alpha_z from the registration's :attr:`Registration.turn`: it
        estimates alpha_z (tracked or constant) and starts from the registration's state (``reference: depth``)."""
        reg = self.registrations.get(o["id"])
        return (reg is not None and reg.turn != 0.0 and reg.state is not None and self._has_alpha(o)
                and o["parameters"][ALPHA_Z].get("mode", "tracked") != "fixed"
                and tracker_config(o, **self.cfg_overrides).reference == "depth")

    def update(self, T_wc: np.ndarray | None, ids: np.ndarray | None = None, P: np.ndarray | None = None,
               uv: np.ndarray | None = None, bgr: np.ndarray | None = None,
               depth: np.ndarray | None = None) -> dict[str, Estimate]:
        """One frame for every object (arguments as :meth:`DeformableTracker.update`; ``depth``: the frame's depth
        image, metres, which a registered object needs until it is placed and a dense tracker in its reference
        view): estimates by object id. A tracker whose build failed on :meth:`set_camera` is built again here."""
        out = {}
        for o in self.objects:
            waiting = self._register(o, T_wc, depth)
            if waiting:
                tr = self._tracker(o)
                out[o["id"]] = Estimate(tr.names, tr.units, tr.values.copy(), tr.frozen.copy(),
                                        np.full((len(tr.values),) * 2, np.nan), state=EstimateState.LOST,
                                        reason=waiting)
            else:
                est = out[o["id"]] = self._tracker(o).update(T_wc, ids, P, uv, bgr, depth)
                reg = self.registrations.get(o["id"])
                if reg is not None and reg.doubt and est.state in (EstimateState.OK, EstimateState.LOW_CONFIDENCE):
                    # placed on depth too noisy, or with its ends too little seen, to trust the pose to millimetres:
                    # every estimate says so, first (a doubt about this frame's fit follows it)
                    est.reason = reg.doubt if est.state == EstimateState.OK else f"{reg.doubt}; {est.reason}"
                    est.state = EstimateState.LOW_CONFIDENCE
        return out

    def _register(self, o: dict[str, Any], T_wc: np.ndarray | None, depth: np.ndarray | None) -> str:
        """Registration of a registered object not placed yet, fed this frame: '' once it is placed (or needs no
        registration), else why its estimate waits."""
        oid, cfg = o["id"], self.registration
        if o["anchor"]["kind"] != "registration" or oid in self.registrations:
            return ""
        registering = f"registering from {cfg.frames} depth views (in the background)"
        if self.background is not None:
            done = self.background.poll(oid)
            if done is not None:
                status, value = done
                if status == "ok":
                    return self._placed(oid, value)
                if status == "slide":
                    self._slides[oid] = self._slides.get(oid, 0) + 1
                return f"waiting for registration: {value}"  # the views are collected afresh from the next frame
            if self.background.pending(oid):
                return registering
        if T_wc is None:
            return "waiting for registration: no camera pose yet"
        if depth is None:
            return "waiting for registration: it needs the depth image"
        assert self.cam is not None, "ObjectTrackers.set_camera comes first"
        k = self._posed[oid] = self._posed.get(oid, -1) + 1
        views = self._views.setdefault(oid, [])
        if k % cfg.every == 0:
            views.append((np.array(depth, dtype=np.float32), np.asarray(T_wc, dtype=np.float64).copy()))
        if len(views) < cfg.frames:
            return f"waiting for registration ({len(views)} of {cfg.frames} depth views)"
        cloud = np.vstack([depth_cloud(self.cam, d, T, cfg.stride, cfg.max_range) for d, T in views])
        cams = DepthViews(np.array([T for _, T in views]), self.cam, self.depth_baseline)
        views.clear()
        model = self.models[oid]
        guess = G.pose7_to_matrix(o["anchor"]["guess"])
        cfg = self._registration_config(o)
        try:
            tr = self._tracker(o)
            if tr.cfg.reference == "depth":
                # the object may be loaded while it is registered: its deformation fitted with its pose
                lo, hi = tr._free_bounds()
                n_mu = len(model.axes)
                n_modes = tr.cfg.n_modes or None
                if self.background is not None:
                    self.background.submit(oid, "loaded", cloud, model, guess, cams, lo[:n_mu], hi[:n_mu], cfg,
                                           n_modes=n_modes)
                    return registering
                reg = register_loaded(cloud, model, guess, cams, lo[:n_mu], hi[:n_mu], cfg, n_modes=n_modes)
            else:
                if self.background is not None:
                    self.background.submit(oid, "rgbd", cloud, model, guess, cams, cfg)
                    return registering
                reg = register_rgbd(cloud, model, guess, cams, cfg)
        except RegistrationError as e:
            if isinstance(e, SlideRefused):
                self._slides[oid] = self._slides.get(oid, 0) + 1
            return f"waiting for registration: {e.args[0]}"
        return self._placed(oid, reg)

    def _registration_config(self, o: dict[str, Any]) -> RegistrationConfig:
        """The registration settings for object ``o``: the camera's, with the scene file's ``anchor.fine`` and
        ``anchor.polish_mm`` where it sets them, and ``slide_from_guess`` once the object's registration has been
        refused ``slide_refusals`` times for its slide along its axis alone."""
        cfg, a = self.registration, o["anchor"]
        if self._slides.get(o["id"], 0) >= cfg.slide_refusals:  # refused so often for its slide alone: the guess's
            cfg = dataclasses.replace(cfg, slide_from_guess=True)
        if a.get("fine", "auto") != "auto":
            cfg = dataclasses.replace(cfg, fine=a["fine"])
        if a.get("polish_mm", 0.0) > 0:
            cfg = dataclasses.replace(cfg, polish=1e-3 * float(a["polish_mm"]))
        return cfg

    def _placed(self, oid: str, reg: Registration) -> str:
        """A registration found: kept, and the object's tracker built again at its pose on its next frame."""
        self.registrations[oid] = reg
        self.trackers.pop(oid, None)
        if self.background is not None and all(o["id"] in self.registrations for o in self.objects
                                               if o["anchor"]["kind"] == "registration"):
            self.background.close(wait=False)  # every object placed: the worker ends, its memory is given back
        return ""

    def close(self) -> None:
        """End the background registration's worker, if there is one."""
        if self.background is not None:
            self.background.close()

    def depth_of_pair(self, left: np.ndarray, right: np.ndarray) -> np.ndarray | None:
        """The trackers' depth from a rectified stereo pair (:func:`~simreal_nodes.vision.stereo.stereo_depth`),
        made only in a frame where depth is still read (:attr:`needs_depth`); None there, or while the baseline
        (:attr:`depth_baseline`) or the camera is not known yet."""
        if not self.depth_baseline or self.cam is None or not self.needs_depth:
            return None
        return stereo_depth(left, right, self.cam.fx, self.depth_baseline, self.stereo_min_depth)

    @property
    def needs_depth(self) -> bool:
        """Whether depth is still read: a registered object waits for its depth views, or a dense tracker for its
        reference view (the surroundings' depth), a sparse one for the state it starts from; afterwards depth is not
        read."""
        return any(o["anchor"]["kind"] == "registration" and o["id"] not in self.registrations
                   and not (self.background is not None and self.background.pending(o["id"])) for o in self.objects) \
            or any(tr.dense is not None and not tr.dense.has_template for tr in self.trackers.values()) \
            or any(tr.needs_depth for tr in self.trackers.values()) \
            or any(o["tracking"]["measurements"] == "dense" and o["id"] not in self.trackers for o in self.objects)

    def focus(self, T_wc: np.ndarray | None) -> list[tuple[int, np.ndarray]]:
        """(object index, image polygon) of every object in view from camera pose ``T_wc``: the regions whose
        features the localization guarantees a share in the next frame (see
        :meth:`DeformableTracker.screen_region`)."""
        if T_wc is None:
            return []
        regions = ((k, tr.screen_region(T_wc)) for k, tr in enumerate(self.trackers.values()))
        return [(k, poly) for k, poly in regions if poly is not None]

    def feedback(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What the localization needs after a frame: :func:`deformable_feedback` of every tracker."""
        return deformable_feedback(self.trackers.values())
