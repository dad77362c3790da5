"""The SLAM's tuning constants, in one frozen record, and its tracking states.

Every part of the SLAM (:mod:`two_view`, :mod:`tracking`, :mod:`relocalization`, :mod:`local_mapping`,
:mod:`deformable`) reads its constants from one :class:`SlamConfig`, so that a benchmark varies a knob by building
a config, never by setting attributes on a running system. The tracking states are defined here once and imported
by every part from here.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from simreal_nodes.states import TrackingState

# tracking states (the TrackingStatus message's ``state`` field)
NOT_STARTED, INITIALIZING, OK, LOST, RELOCALIZED = (TrackingState.NOT_STARTED, TrackingState.INITIALIZING,
                                                    TrackingState.OK, TrackingState.LOST, TrackingState.RELOCALIZED)
STATE_NAMES: dict[int, str] = {NOT_STARTED: "not started", INITIALIZING: "initializing", OK: "ok", LOST: "lost",
               RELOCALIZED: "relocalized"}


# which SLAM modes fuse a new keyframe's points with its neighbours' (``SlamConfig.fuse_neighbours``)
FUSE_MODES = ("none", "mono", "all")

# the monocular initialization's general two-view models (``SlamConfig.two_view_model``, :mod:`.two_view`)
TWO_VIEW_MODELS = ("fundamental", "essential")

# what tells a homography's decompositions apart at a monocular start (``SlamConfig.homography_ambiguity``)
H_AMBIGUITY = ("explained", "triangulated")


@dataclass(frozen=True)
class SlamConfig:
    """Tuning of the SLAM; the defaults are the values the tests and benchmarks were measured with."""

    min_parallax_deg: float = 1.0  # monocular initialization: less parallax is refused (weak depth vs. waiting)
    max_depth: float = 8.0  # metres; farther depth readings are dropped (noisy far points vs. coverage)
    keyframe_depth_points: int = 0  # RGB-D / stereo keyframe: 0 = ORB-SLAM2's rule: new points from the depth of
    # every unmatched feature nearer than ``keyframe_close_depth_m`` and, farther, on until 100 points are counted;
    # > 0: of at most this many unmatched features, nearest first (stop 123's default, 250: map size vs. coverage).
    # The cap starved a joint boot filmed from 0.45 m, whose 250 nearest features were all on the deforming boot
    # and culled (held-out boot 1083: the camera lost in 46 % of the frames); the rule lowered the camera's error on
    # the development beams and boots, their loads level and the stereo beams' too (docs/localization.md, stops
    # 123 and 124)
    keyframe_close_depth_m: float = 3.1  # ORB-SLAM2's ThDepth as its TUM RGB-D settings give it (40 x 0.077 m)
    local_kfs: int = 10  # covisible keyframes in the local map and local BA (accuracy vs. time per keyframe)
    ba_iterations: int = 10  # Levenberg-Marquardt iterations of a local BA (accuracy vs. mapping time)
    min_features: int = 40  # fewer ORB features: the frame is reported textureless (false loss vs. wild poses)
    max_ba_points: int = 0  # most-observed points a local BA optimizes, 0 = all (BA time vs. map accuracy)
    # 0 since stop 55: a cap leaves the other points where the keyframes that moved had put them (800 broke monocular
    # 2000-feature maps, 115 mm against 1.8 mm; benchmarks/local_ba.py)
    rgbd_disparity_sigma_px: float = 0.0  # RGB-D: noise of the depth reading as a virtual disparity fx b / z
    # (pixels; b the 0.08 m virtual baseline): the BA's and the fusion's weight on depth; 0 = ORB-SLAM2's model (u_r
    # as an independent measurement at the feature's level sigma: depth weighed about 10 times below a Kinect's)
    interrupt_ba: bool = True  # asynchronous mapping: a keyframe that must wait stops the running local BA after its
    # current iteration (ORB-SLAM2's abort flag; the partial result is applied): a current map vs. converged BAs
    deformable_radius: float = 20.0  # pixels; ORB re-acquisition radius around a deformable point's prediction
    # (most of what it finds on the bent joint boot is wrong, benchmarks/boot_measurements.py; 6 and 0 px clean the
    # measurements but lose the lever in fast moves: docs/family.md, stop 67)
    coherence_px: float = 0.0  # > 0: a deformable measurement whose offset from its prediction differs by more than
    # this from the median offset of its image neighbours' is dropped (a wrong match moves unlike its neighbours; a
    # lagging prediction moves them all alike); 0: off. 8 px helped the boot family's development seeds (0.88 against
    # 0.93 %), not its held-out ones (1.60 against 1.61 %), and broke the foam beam at 640 x 480: a knob
    # (docs/family.md, stop 68)
    coherence_radius_px: float = 40.0  # the neighbourhood of the coherence check (pixels)
    coherence_min: int = 3  # fewest neighbours the check needs; a point with fewer is kept
    reacquire_below: int = 8  # fewer flow tracks than this (once more were followed): wide re-acquisition
    reacquire_wide_px: float = 80.0  # pixels; the wide re-acquisition radius (recovers after gaps vs. wrong matches)
    hold_rest_points: bool = True  # keep the deformable points linked at rest (else culled like any young point)
    followed_px: float = 3.0  # pixels; no new keyframe point this near a followed deformable point (0: off)
    flow_fb_px: float = 0.5  # pixels; forward-backward flow agreement to keep a track (drift vs. lost tracks)
    flow_win: int = 11  # Lucas-Kanade window (pixels); larger straddles the object's silhouette and drifts
    flow_anchor_px: float = 0.0  # > 0: re-measure tracks on their first image if within this (drift vs. bias)
    max_anchor_images: int = 40  # images kept for the anchored re-measurement (memory vs. track restarts)
    focus_share: float = 0.2  # ORB budget guaranteed to each tracked object's predicted image region (faint objects)
    fuse_neighbours: str = "mono"  # modes whose keyframes' points fuse with the neighbours' (ORB-SLAM2): see below
    # "mono": halves the monocular drift on the real 7-Scenes frames; on RGB-D (its depth fixes the scale) it was level
    # on the room and 7-Scenes and mixed on family development scenes, so "all" is a knob (docs/localization.md)
    two_view_model: str = "essential"  # mono start: five-point E, or "fundamental" (ORB-SLAM2's eight-point F)
    # "essential" since stop 53: a better first pose (the rendered room's failing noise draw holds) and, with the
    # keyframe fusion, level or better on each of the real 7-Scenes starts (benchmarks/two_view.py)
    homography_ratio: float = 0.40  # mono start: the homography is decomposed when its share of the two models' scores
    # S_H / (S_H + S_F) exceeds this (ORB-SLAM2: 0.40; ORB-SLAM3: 0.50), else the general model
    homography_ambiguity: str = "explained"  # a homography start is refused when a second decomposition comes within
    # 75 % of the best one's count of "explained" matches (ORB-SLAM2's) or of "triangulated" points (with parallax)
    homography_fallback: bool = False  # a homography no decomposition of which is accepted (ambiguous, too few good
    # points): try the general model on the same frames
    # (ORB-SLAM2 waits for more motion; stop 114 measured it on development seeds, docs/localization.md)

    loop_closing: bool = False  # search every new keyframe for a loop and correct the map (:mod:`.loop_closing`)

    def __post_init__(self) -> None:
        if self.two_view_model not in TWO_VIEW_MODELS:
            raise ValueError(f"SlamConfig.two_view_model must be one of {', '.join(TWO_VIEW_MODELS)}, not "
                             f"{self.two_view_model!r}")
        if self.homography_ambiguity not in H_AMBIGUITY:
            raise ValueError(f"SlamConfig.homography_ambiguity must be one of {', '.join(H_AMBIGUITY)}, not "
                             f"{self.homography_ambiguity!r}")
        if self.fuse_neighbours not in FUSE_MODES:
            raise ValueError(f"SlamConfig.fuse_neighbours must be one of {', '.join(FUSE_MODES)}, not "
                             f"{self.fuse_neighbours!r}")
        for f in fields(self):
            if isinstance(getattr(self, f.name), (int, float)) and getattr(self, f.name) < 0:
                raise ValueError(f"SlamConfig.{f.name} must not be negative, not {getattr(self, f.name)}")
        if self.focus_share > 1:
            raise ValueError(f"SlamConfig.focus_share is a share of the ORB budget (0..1), not {self.focus_share}")
        if not 0.0 <= self.homography_ratio <= 1.0:  # NaN too (it would mean "never the homography")
            raise ValueError(f"SlamConfig.homography_ratio is a share of two scores (0..1), not "
                             f"{self.homography_ratio}")
        if self.flow_win < 3 or self.local_kfs < 1 or self.ba_iterations < 1:
            raise ValueError(f"SlamConfig: flow_win >= 3, local_kfs >= 1 and ba_iterations >= 1 needed, not "
                             f"{self.flow_win}, {self.local_kfs}, {self.ba_iterations}")

    def fuses(self, mode: str) -> bool:
        """Whether a SLAM in ``mode`` (mono, rgbd, stereo) fuses its keyframes' points (``fuse_neighbours``)."""
        return self.fuse_neighbours == "all" or (self.fuse_neighbours == "mono" and mode == "mono")

    @property
    def min_parallax(self) -> float:
        """The minimum parallax of a two-view initialization in radians."""
        return float(np.deg2rad(self.min_parallax_deg))
