"""Feature-based visual SLAM in the style of ORB-SLAM2 (Mur-Artal & Tardós 2017), on OpenCV and GTSAM.

Per frame: ORB features -> (not initialized) monocular two-view initialization (homography or
fundamental model, chosen by score) or an RGB-D / stereo map from the first frame -> tracking with a
constant-velocity motion model and search by projection, pose optimization with outlier rejection,
falling back to descriptor matching + PnP RANSAC -> tracking of the local map (points of the covisible
keyframes) -> keyframe decision. A new keyframe triggers local mapping: new points (triangulated with
covisible keyframes, or from depth), fusion with the neighbouring keyframes' points (monocular), local bundle
adjustment in GTSAM, map-point and keyframe culling; with ``SlamConfig.loop_closing``, a loop search (Sim3, essential
graph, global BA: :mod:`.loop_closing`).
A lost frame triggers relocalization (descriptor matching against the whole map + PnP RANSAC). In
localization-only mode the map is frozen: no keyframes, no new points.

Map points on a deforming object can be flagged ``deformable``: they never vote for the camera pose,
and they are followed from frame to frame as the deformable tracker's measurements (:mod:`.deformable`).

:class:`Slam` only sequences the parts, which share one :class:`~.context.SlamContext`: :mod:`.two_view`
(initialization), :mod:`.tracking`, :mod:`.relocalization`, :mod:`.local_mapping`, :mod:`.loop_closing` and
:mod:`.deformable`, tuned by one :class:`~.config.SlamConfig`.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from simreal_nodes.camera import CameraModel
from simreal_nodes.vision.orb import Features, OrbExtractor
from simreal_nodes.vision.slam.config import INITIALIZING, LOST, NOT_STARTED, OK, RELOCALIZED, SlamConfig
from simreal_nodes.vision.slam.context import SlamContext
from simreal_nodes.vision.slam.deformable import DeformableTracks
from simreal_nodes.vision.slam.local_mapping import LocalMapper
from simreal_nodes.vision.slam.loop_closing import LoopCloser
from simreal_nodes.vision.slam.map import Map
from simreal_nodes.vision.slam.relocalization import Relocalizer
from simreal_nodes.vision.slam.result import TrackResult
from simreal_nodes.vision.slam.tracking import PoseFix, Tracker
from simreal_nodes.vision.slam.two_view import Initializer
from simreal_nodes.vision.stereo import sparse_stereo_depth


class Slam:
    """The SLAM for one camera: :meth:`track` per frame. ``mode``: mono, rgbd or stereo (``baseline``: metres,
    from the right camera's projection); ``known_scale``: metres between the two views of a monocular
    initialization (else the map's median depth is 1); ``async_mapping``: local BA in a mapping process (live);
    ``config``: the tuning (:class:`SlamConfig`)."""

    def __init__(self, cam: CameraModel, mode: str = "mono", n_features: int = 1000, scale_factor: float = 1.2,
                 n_levels: int = 8, baseline: float | None = None, known_scale: float | None = None,
                 async_mapping: bool = False, config: SlamConfig | None = None) -> None:
        if mode not in ("mono", "rgbd", "stereo"):
            raise ValueError(f"SLAM mode must be mono, rgbd or stereo, not '{mode}'")
        if mode == "stereo" and not baseline:
            raise ValueError("stereo SLAM needs the stereo baseline (from the right CameraInfo's P[0,3] = -fx b)")
        self.cam = cam
        self.mode = mode
        self.config = config or SlamConfig()
        self.known_scale = known_scale
        self.async_mapping = async_mapping
        self.extractor = OrbExtractor(n_features, scale_factor, n_levels)
        self.localization_only = False
        self._start(baseline if mode == "stereo" else (0.08 if mode == "rgbd" else None))  # rgbd: virtual stereo

    def _start(self, baseline: float | None) -> None:
        """A fresh context and parts: no map, not started."""
        self.ctx = SlamContext(self.cam, self.cam.K.copy(), self.mode, baseline, self.config)
        self.mapper = LocalMapper(self.ctx, self.async_mapping)
        self.loop_closer = LoopCloser(self.ctx, self.mapper)
        self.initializer = Initializer(self.ctx, self.mapper, self.known_scale)
        self.tracker = Tracker(self.ctx)
        self.relocalizer = Relocalizer(self.ctx, self.tracker)
        self.tracks = DeformableTracks(self.ctx)

    @property
    def map(self) -> Map:
        return self.ctx.map

    @property
    def baseline(self) -> float | None:
        """Stereo baseline in metres (None for mono and RGB-D)."""
        return self.ctx.baseline

    @property
    def state(self) -> int:
        return self.ctx.state

    def close(self) -> None:
        """Stop the mapping process (asynchronous mapping)."""
        self.mapper.close()

    def reset(self) -> None:
        """Forget the map and start over (same camera, mode and tuning)."""
        self.close()
        self.localization_only = False
        self._start(self.ctx.baseline)

    def set_localization_only(self, on: bool) -> None:
        self.localization_only = bool(on)

    def set_deformable(self, ids: Iterable[int], predicted: ArrayLike | None = None,
                       held: Iterable[int] | None = None) -> None:
        """See :meth:`DeformableTracks.set_deformable`. ``held``: those of them the map keeps (linked at rest:
        exempt from the culling of young points, :meth:`LocalMapper._cull_points`)."""
        self.tracks.set_deformable(ids, predicted)
        self.ctx.held = {int(i) for i in held} if held is not None else set()

    def drop_tracks(self, ids: Iterable[int]) -> None:
        """See :meth:`DeformableTracks.drop_tracks`."""
        self.tracks.drop_tracks(ids)

    def load_map(self, m: Map) -> None:
        """Localize in a saved map: the next frame relocalizes into it. Every part that followed the map before
        (the tracker's local map, the deformable tracks and their predictions, the mapper's queue and any BA in
        flight, the loops) starts afresh, as :meth:`reset` makes them: a saved map numbers its keyframes and points
        from 0 as the session's own did, so nothing kept could be told from the new map's. The localization-only
        switch is kept. A session that has seen no frame and been told of no object point has nothing to forget (and
        keeps its mapping process: starting another costs about 0.3 s)."""
        ctx = self.ctx
        if ctx.frame_id or ctx.map.keyframes or ctx.map.points or ctx.deformable or self.tracks._predicted:
            only = self.localization_only
            self.reset()
            self.localization_only = only
        self.ctx.map = m
        self.ctx.state = LOST
        self.set_deformable({p.id for p in m.points.values() if p.deformable})

    def track(self, gray: np.ndarray, stamp: int = 0, depth: np.ndarray | None = None,
              right: np.ndarray | None = None, focus: Sequence[np.ndarray] = ()) -> TrackResult:
        """Process one frame. ``gray``: uint8 image; ``depth``: metres (NaN/0 invalid) registered to it;
        ``right``: the right image of a rectified stereo pair; ``focus``: image polygons ((K, 2) pixels) where
        tracked objects are predicted, each guaranteed ``config.focus_share`` of the ORB features."""
        ctx = self.ctx
        t0 = time.perf_counter()
        ctx.frame_id += 1
        self.tracks.new_frame(gray)
        tim: dict[str, float] = {}
        self.mapper.poll()
        ctx.map.compact()  # the rows of points the mapping erased go, once they outnumber the live ones
        quality = image_problem(gray)
        feats = Features.empty() if quality else self.extractor.extract(gray, self.cam, focus=focus,
                                                                           focus_share=self.config.focus_share)
        tim["extract_ms"] = (time.perf_counter() - t0) * 1e3
        if not quality and len(feats) < self.config.min_features:
            quality = f"too few features ({len(feats)}): textureless view"
        if quality:
            return self._fail(quality, tim, len(feats))
        z = self._feature_depth(feats, depth, right)
        tim["depth_ms"] = (time.perf_counter() - t0) * 1e3 - tim["extract_ms"]
        if ctx.state in (NOT_STARTED, INITIALIZING):
            res = self.initializer.initialize(feats, z, stamp)
        elif ctx.state == LOST:
            res, fix = self.relocalizer.relocalize(feats, tim)
            if fix is not None:
                self._observe(feats, fix, res, tim)
        else:
            res, fix = self.tracker.track(feats, tim)
            if fix is not None:
                self._observe(feats, fix, res, tim)
                if not self.localization_only and self.mapper.need_keyframe(res.n_inliers):
                    t3 = time.perf_counter()
                    kf = self.mapper.insert_keyframe(stamp, fix.T_cw, feats, z, fix.match, fix.inl,
                                                    followed=self.tracks.followed())
                    res.keyframe = True
                    tim["mapping_ms"] = (time.perf_counter() - t3) * 1e3
                    if self.config.loop_closing:
                        t4 = time.perf_counter()
                        loop = self.loop_closer.process(kf)
                        tim["loop_ms"] = (time.perf_counter() - t4) * 1e3
                        if loop is not None:
                            res.reason = (f"loop closed: keyframe {loop.kf} on {loop.loop_kf} ({loop.matches} "
                                          f"matches, scale {loop.scale:.3f})")
                            res.T_wc = kf.T_wc.copy()
        res.n_features = len(feats)
        res.timings.update(tim)
        res.timings["total_ms"] = (time.perf_counter() - t0) * 1e3
        return res

    def _observe(self, feats: Features, fix: PoseFix, res: TrackResult, tim: dict[str, float]) -> None:
        """The deforming objects' map points measured in this frame (:meth:`DeformableTracks.observe`), timed as
        ``deformable_ms``."""
        t0 = time.perf_counter()
        self.tracks.observe(feats, fix.T_cw, res, exclude=fix.match[:, 0])
        tim["deformable_ms"] = (time.perf_counter() - t0) * 1e3

    def _fail(self, reason: str, tim: dict[str, float], nf: int) -> TrackResult:
        """A frame not processed (``reason``): a tracked camera is lost."""
        if self.ctx.state in (OK, RELOCALIZED):
            self.ctx.lose()
        st = self.ctx.state
        if st == LOST:
            reason = f"lost: {reason}"
        return TrackResult(st, reason, None, nf, timings=tim)

    def _feature_depth(self, f: Features, depth: np.ndarray | None, right: np.ndarray | None) -> np.ndarray | None:
        """Metric depth per feature (NaN unknown): read from the registered depth image (RGB-D) or matched in the
        right image (stereo); None for a monocular camera."""
        if self.mode == "rgbd":
            if depth is None:
                return np.full(len(f), np.nan)
            h, w = depth.shape
            u = np.clip(np.round(f.uv[:, 0]).astype(int), 0, w - 1)
            v = np.clip(np.round(f.uv[:, 1]).astype(int), 0, h - 1)
            z = depth[v, u].astype(np.float64)
            z[~np.isfinite(z) | (z <= 0.05) | (z > self.config.max_depth)] = np.nan
            return z
        if self.mode == "stereo":
            if right is None:
                return np.full(len(f), np.nan)
            assert self.ctx.baseline is not None  # __init__ refuses stereo without a baseline
            return sparse_stereo_depth(f, right, self.extractor, self.cam, self.ctx.baseline, self.config.max_depth)
        return None


def image_problem(gray: np.ndarray) -> str:
    """Why a frame cannot be tracked at all (black, saturated, uniform), or ""."""
    m = float(gray[::4, ::4].mean())
    if m < 6:
        return "black frame (no light, lens covered or camera blackout)"
    if m > 249:
        return "saturated frame (overexposed)"
    if float(gray[::4, ::4].std()) < 2.0:
        return "textureless frame (uniform image)"
    return ""
