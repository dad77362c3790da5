"""Where the camera is, frame by frame, behind one interface: fiducial markers, ORB SLAM (mono / RGB-D / stereo)
or a camera that does not move (thesis §2.3, §4.4.1, §5.2.3).

:func:`make_localizer` builds the one the scene's localization section asks for; the localization node and the
offline pipeline both use it, so they localize alike. Every :class:`Localizer` answers :meth:`~Localizer.step` with
a :class:`Localization` and takes the deformable tracker's word on which map points lie on the object
(:meth:`~Localizer.feedback`); those without a map have nothing to do with it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.states import PointFlag, TrackingState

if TYPE_CHECKING:
    from simreal_nodes.vision.markers import MarkerLocalizer
    from simreal_nodes.vision.slam.config import SlamConfig
    from simreal_nodes.vision.slam.map import Map
    from simreal_nodes.vision.slam.system import Slam


@dataclass
class Localization:
    """One frame's camera pose (``T_wc``, map <- camera; None: no pose), the tracking state (the numbers of
    ``vision.slam.system``: not started, initializing, ok, lost, relocalized) with its reason, and what the
    localization node reports about it: features tracked (SLAM: pose inliers; markers: 4 corners per marker),
    the map points observed (SLAM only), stage timings (SLAM only, ms) and the map's size."""

    T_wc: np.ndarray | None
    state: int
    reason: str = ""
    features: int = 0
    obs_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    obs_pos: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    obs_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))
    obs_inlier: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    timings: dict[str, float] | None = None
    map_points: int = 0
    keyframes: int = 0
    localization_only: bool = False


class Localizer:
    """The interface every localizer has. ``map``: the SLAM map (None: none to publish or save)."""

    mode: str

    @property
    def map(self) -> Map | None:
        """None here; a localizer that builds a map overrides it."""
        return None

    def step(self, gray: np.ndarray, stamp_ns: int, depth: np.ndarray | None = None,
             right: np.ndarray | None = None, focus: Sequence[np.ndarray] = ()) -> Localization:
        """Localize one grey image (uint8), with the registered depth in metres (RGB-D) or the right grey image
        (stereo). ``focus``: image polygons ((K, 2) pixels) where tracked objects are predicted (a frame late: the
        trackers' word on the previous frame); a feature-based localizer guarantees them a share of its features."""
        raise NotImplementedError

    def set_localization_only(self, on: bool) -> None:
        """Freeze (or resume) mapping; without a map there is nothing to freeze."""

    def feedback(self, ids: np.ndarray, predicted: np.ndarray, flags: np.ndarray) -> None:
        """The trackers' word after a frame (:func:`~simreal_nodes.assimilation.tracker.deformable_feedback`):
        map points ``ids`` lie on a deforming object, ``predicted`` where (map frame); ``flags`` bit 0: the last
        fit rejected the point's image track, bit 1: the point was linked at rest (the map keeps it). Only a map
        has such points."""

    def close(self) -> None:
        """Release workers (SLAM's mapping process)."""


class MarkerLocalization(Localizer):
    """Camera pose from the fiducial markers laid out in the map: no continuity, no map."""

    mode = "markers"

    def __init__(self, markers: MarkerLocalizer):
        self.markers = markers
        self.localization_only = False  # no map to freeze; reported as told (:class:`MapFreeze` reads it)

    def step(self, gray: np.ndarray, stamp_ns: int, depth: np.ndarray | None = None,
             right: np.ndarray | None = None, focus: Sequence[np.ndarray] = ()) -> Localization:
        res = self.markers.locate(gray)
        state = TrackingState.OK if res.T_wc is not None else TrackingState.LOST
        reason = (res.reason if res.T_wc is None
                  else f"{len(res.ids)} markers, {res.rms_px:.2f} px, position +-{res.std_pct:.2f} % of the distance")
        return Localization(res.T_wc, state, reason, features=4 * len(res.ids),
                            localization_only=self.localization_only)

    def set_localization_only(self, on: bool) -> None:
        self.localization_only = bool(on)


class SlamLocalization(Localizer):
    """ORB SLAM: the map it builds, the deformable map points it follows for the tracker."""

    def __init__(self, slam: Slam):
        self.slam = slam
        self.mode = slam.mode

    @property
    def map(self) -> Map:
        return self.slam.map

    def step(self, gray: np.ndarray, stamp_ns: int, depth: np.ndarray | None = None,
             right: np.ndarray | None = None, focus: Sequence[np.ndarray] = ()) -> Localization:
        r = self.slam.track(gray, stamp_ns, depth=depth, right=right, focus=focus)
        return Localization(r.T_wc, r.state, r.reason, int(r.n_inliers), r.obs_ids, r.obs_pos, r.obs_uv, r.obs_inlier,
                            r.timings, len(self.slam.map.points), len(self.slam.map.keyframes),
                            bool(self.slam.localization_only))

    def set_localization_only(self, on: bool) -> None:
        self.slam.set_localization_only(on)

    def feedback(self, ids: np.ndarray, predicted: np.ndarray, flags: np.ndarray) -> None:
        flags = np.asarray(flags, np.uint8)
        self.slam.set_deformable(ids, predicted, held=ids[(flags & PointFlag.HELD) > 0])
        self.slam.drop_tracks(ids[(flags & PointFlag.DROP) > 0])

    def close(self) -> None:
        self.slam.close()


class StaticLocalization(Localizer):
    """A camera that does not move: the scene's ``static_pose`` every frame."""

    mode = "static"

    def __init__(self, T_wc: np.ndarray):
        self.T_wc = T_wc
        self.localization_only = False  # no map to freeze; reported as told (:class:`MapFreeze` reads it)

    def step(self, gray: np.ndarray, stamp_ns: int, depth: np.ndarray | None = None,
             right: np.ndarray | None = None, focus: Sequence[np.ndarray] = ()) -> Localization:
        return Localization(self.T_wc, 2, localization_only=self.localization_only)

    def set_localization_only(self, on: bool) -> None:
        self.localization_only = bool(on)


def make_localizer(loc: dict[str, Any], cam: CameraModel, baseline: float | None = None, async_mapping: bool = False,
                   map_file: str = "", localization_only: bool = False,
                   slam_config: SlamConfig | None = None) -> Localizer:
    """The localizer of a scene's ``localization`` section (``mode``; for markers ``markers``, for a static camera
    ``static_pose``, for SLAM ``features``, ``scale_factor``, ``pyramid_levels``, ``known_scale_m``,
    ``loop_closing``) on camera ``cam``. SLAM only: ``baseline`` (stereo, metres), ``async_mapping`` (local bundle
    adjustment in a worker process), ``map_file`` (a saved map to relocalize into), ``localization_only`` (start with
    mapping frozen), ``slam_config`` (the SLAM's tuning; default :class:`SlamConfig`; the section's ``loop_closing``
    overrides its field)."""
    mode = loc["mode"]
    if mode == "markers":
        from simreal_nodes.vision.markers import DETECT_SCALE, MAX_STD_PCT, MarkerLocalizer

        mk = loc["markers"]
        return MarkerLocalization(MarkerLocalizer(cam, mk["dictionary"], mk["size_m"],
                                                  {int(k): G.pose7_to_matrix(v) for k, v in mk["poses"].items()},
                                                  max_std_pct=mk.get("max_std_pct", MAX_STD_PCT),
                                                  corner_refinement=mk.get("corner_refinement", "edges"),
                                                  detect_scale=mk.get("detect_scale", DETECT_SCALE)))
    if mode == "static":
        return StaticLocalization(G.pose7_to_matrix(loc["static_pose"]))
    from simreal_nodes.vision.slam.map import Map
    from simreal_nodes.vision.slam.system import Slam

    if loc.get("loop_closing") is not None:
        from simreal_nodes.vision.slam import config as slam_cfg

        slam_config = replace(slam_config or slam_cfg.SlamConfig(), loop_closing=bool(loc["loop_closing"]))
    slam = Slam(cam, mode, loc["features"], loc["scale_factor"], loc["pyramid_levels"], baseline=baseline,
                known_scale=loc.get("known_scale_m"), async_mapping=async_mapping, config=slam_config)
    if localization_only:
        slam.set_localization_only(True)
    if map_file:
        slam.load_map(Map.load(map_file))
    return SlamLocalization(slam)


WARM_UP_SIZE = (320, 240)  # LiveLocalizer.warm_up's camera
FOCUS_MAX_AGE_NS = 500_000_000  # an object's image region older than this (ns) no longer steers the features


class LiveLocalizer:
    """The localizer of a live camera, as the localization node keeps it: built once the intrinsics are known (for
    stereo, and the baseline), built again when they change; mapping frozen or not as last asked.

    ``loc``, ``async_mapping``, ``map_file``, ``localization_only``: as :func:`make_localizer` takes them."""

    def __init__(self, loc: dict[str, Any], async_mapping: bool = False, map_file: str = "",
                 localization_only: bool = False):
        self.loc, self.async_mapping, self.map_file = loc, async_mapping, map_file
        self.localization_only = localization_only
        self.cam: CameraModel | None = None
        self.baseline: float | None = None
        self.core: Localizer | None = None
        self._focus: dict[int, tuple[int, np.ndarray]] = {}  # object index -> (stamp ns, (K, 2) image polygon)

    def warm_up(self) -> None:
        """Build a localizer of this mode on a camera of its own, give it one textured frame (a seeded random
        pattern, 1 m away for RGB-D; for stereo the same image on both sides) and drop it: the modules it imports and
        what its first frame sets up (the marker detector's, ORB's extraction and matching, a SLAM's map
        initialisation) are loaded before the first CameraInfo, whose frame would wait for them (live, the frames
        that come meanwhile are replaced in the queues). Its mapping runs in this process (no worker is started); no
        saved map is read."""
        if self.loc["mode"] == "static":
            return
        W, H = WARM_UP_SIZE
        cam = CameraModel.from_intrinsics(W, H, float(W), float(W), W / 2, H / 2)
        core = make_localizer(self.loc, cam, baseline=0.1)
        try:
            img = np.random.default_rng(0).integers(0, 256, (H, W), dtype=np.uint8)
            core.step(img, 0, depth=np.ones((H, W), np.float32) if self.loc["mode"] == "rgbd" else None,
                      right=img if self.loc["mode"] == "stereo" else None)
        finally:
            core.close()

    def set_focus(self, index: int, stamp_ns: int, polygon: np.ndarray) -> None:
        """Where tracked object ``index`` projected in the frame of ``stamp_ns`` (from the tracker). Regions too
        old (or too far ahead) to steer a frame of this time are forgotten, so the regions held stay as many as
        the objects reporting now, whatever indices and stamps a sender invents."""
        t = int(stamp_ns)
        self._focus = {k: v for k, v in self._focus.items() if abs(t - v[0]) < FOCUS_MAX_AGE_NS}
        self._focus[int(index)] = (t, np.asarray(polygon, np.float64).reshape(-1, 2))

    def focus(self, stamp_ns: int) -> list[np.ndarray]:
        """The objects' image regions that steer the features of the frame at ``stamp_ns``: those reported for a
        frame within :data:`FOCUS_MAX_AGE_NS` (live they come a frame or two late; an object no longer reported
        stops steering)."""
        return [p for t, p in self._focus.values() if abs(stamp_ns - t) < FOCUS_MAX_AGE_NS]

    def set_camera(self, cam: CameraModel) -> bool:
        """Intrinsics from a CameraInfo; True when they are new and the localizer was (re)built. Built now, not on
        the first frame: live, the frames that arrive while it builds (a mapping worker starts) would be skipped."""
        if cam.same_as(self.cam):
            return False
        if self.core is not None:
            self.core.close()
        self.cam, self.core = cam, None
        self.core = self._build()
        return True

    def _build(self) -> Localizer | None:
        if self.loc["mode"] == "stereo" and self.baseline is None:
            return None
        assert self.cam is not None  # built only once set_camera gave the intrinsics
        return make_localizer(self.loc, self.cam, self.baseline, self.async_mapping, self.map_file,
                              self.localization_only)

    def not_ready(self) -> str:
        """Why the localizer cannot take a frame yet ('' = it can: :attr:`core` is built)."""
        if self.cam is None:
            return "waiting for a valid CameraInfo"
        if self.core is None:
            self.core = self._build()
            if self.core is None:
                return "stereo: waiting for the right CameraInfo (baseline)"
        return ""

    def set_localization_only(self, on: bool) -> None:
        self.localization_only = bool(on)
        if self.core is not None:
            self.core.set_localization_only(self.localization_only)

    def feedback(self, ids: np.ndarray, predicted: np.ndarray, flags: np.ndarray) -> None:
        """:meth:`Localizer.feedback`, once there is a localizer."""
        if self.core is not None:
            self.core.feedback(ids, predicted, flags)

    @property
    def map(self) -> Map | None:
        """The SLAM map (None: no localizer yet, or one without a map)."""
        return self.core.map if self.core is not None else None

    def map_stats(self) -> dict[str, str]:
        """The map's size for the node's diagnostics (``map_keyframes``, ``map_points``; empty without a map): what a
        long run watches to see that the map stays bounded (`benchmarks/soak_map.py`)."""
        m = self.map
        return {} if m is None else {"map_keyframes": str(len(m.keyframes)), "map_points": str(len(m.points))}

    def map_points(self) -> np.ndarray | None:
        """(N, 3) points of the SLAM map (None: no map, or an empty one)."""
        if self.map is None or not self.map.points:
            return None
        # Map.point_arrays is not annotated (vision): called through the signature it has
        point_arrays: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]] = self.map.point_arrays
        return point_arrays()[1]

    def close(self, save_map: str = "") -> bool:
        """Release the localizer, its map saved to ``save_map`` first if given (and there is one): True if saved."""
        saved = bool(save_map) and self.map is not None
        if saved:
            assert self.map is not None  # what saved says
            self.map.save(save_map, self.cam, self.loc["mode"])
        if self.core is not None:
            self.core.close()
        return saved


STATE_NAMES: dict[int, str] = {TrackingState.NOT_STARTED: "not started", TrackingState.INITIALIZING: "initializing",
               TrackingState.OK: "ok", TrackingState.LOST: "lost", TrackingState.RELOCALIZED: "relocalized"}


def status_text(r: Localization) -> tuple[str, str]:
    """(diagnostic level ok / warn / error, text) of a frame's localization: lost is an error, starting a warning."""
    level = ("ok" if r.state in (TrackingState.OK, TrackingState.RELOCALIZED)
             else "warn" if r.state in (TrackingState.NOT_STARTED, TrackingState.INITIALIZING) else "error")
    return level, f"{STATE_NAMES.get(r.state, r.state)}" + (f": {r.reason}" if r.reason else "")


class MapFreeze:
    """The tracker's side of ``localization.freeze_map_on_deformation`` (thesis §4.4.1): once a deformation appears,
    ask the localization to stop mapping; and ask again when the localization reports mapping after it was told (a
    localization node restarted by the launcher's respawn starts a new map, mapping: what the first one was told died
    with it). ROS-free: the tracker node feeds it and sends what it says.

    Per frame :meth:`due` (is there a deformation, is the localization's service there): True means send the request
    now (call :meth:`sent` first); :meth:`answered` when the response comes; :meth:`status` with each of the
    localization's status reports (its ``localization_only``). After an answer, :data:`STRIKES` reports in a row that
    say mapping re-arm the request (one such report may have left the localization before the request was served). A
    request still out is settled by the reports as well: one that says frozen is taken as its answer, and
    :data:`LOST_AFTER` in a row that say mapping as its loss (a node that died with the request, or a server that
    dropped it: the response never comes, and while the localization is down the tracker gets no frame to see its
    service gone); so is one whose service went away."""

    STRIKES = 2
    LOST_AFTER = 30  # status reports (frames) in a row that say mapping while a request is out: it was lost

    def __init__(self, enabled: bool) -> None:
        self.enabled = bool(enabled)
        self.pending = False  # a request is out, not answered
        self.told = False  # the localization answered (or reported) that it stopped mapping
        self.requests = 0  # requests sent so far
        self._strikes = 0

    def due(self, deforming: bool, service_ready: bool) -> bool:
        """Whether to send the request now."""
        if self.pending and not service_ready:
            self.pending = False
        return self.enabled and deforming and service_ready and not self.pending and not self.told

    def sent(self) -> None:
        self.pending, self._strikes = True, 0
        self.requests += 1

    def answered(self, success: bool) -> None:
        self.pending, self._strikes = False, 0
        self.told = bool(success)

    def status(self, localization_only: bool) -> bool:
        """One status report of the localization; True when it re-armed the request (the localization is mapping
        again after it was told not to, or a request out was lost)."""
        if localization_only:
            if self.pending:  # served: its response may still come (and says the same)
                self.pending, self.told = False, True
            self._strikes = 0
            return False
        if not (self.told or self.pending):
            return False
        self._strikes += 1
        if self._strikes < (self.LOST_AFTER if self.pending else self.STRIKES):
            return False
        self.told = self.pending = False
        self._strikes = 0
        return True
