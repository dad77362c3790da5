"""What the parts of the SLAM share: the sensor setup, the tuning, the map and the camera's track through it.

The orchestrator (:class:`~simreal_nodes.vision.slam.system.Slam`) owns one :class:`SlamContext`; the parts hold a
reference to it and read or advance it in the order the orchestrator calls them, as ORB-SLAM2's threads share its
``Tracking`` members. Keeping it in one record (rather than copies in each part) is what lets a loaded map or a lost
state reach every part at once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simreal_nodes.camera import CameraModel
from simreal_nodes.vision.slam.config import LOST, NOT_STARTED, SlamConfig
from simreal_nodes.vision.slam.map import KeyFrame, Map


@dataclass
class SlamContext:
    """The SLAM's shared state; each field is written by the part named in its comment or by the orchestrator."""

    cam: CameraModel
    K: np.ndarray  # (3, 3) intrinsics of the ideal (undistorted) pixels the SLAM works in
    mode: str  # mono, rgbd or stereo
    baseline: float | None  # stereo baseline (metres); RGB-D: a virtual one for the BA's stereo factors
    config: SlamConfig
    map: Map = field(default_factory=Map)  # edited by initialization and local mapping; replaced by a loaded map
    frame_id: int = 0  # frames seen, failed ones too (orchestrator)
    state: int = NOT_STARTED  # initialization, tracking, relocalization
    T_cw_last: np.ndarray | None = None  # pose of the last tracked frame, world -> camera (same parts)
    velocity: np.ndarray | None = None  # constant-velocity model: the last frame-to-frame motion (same parts)
    ref_kf: KeyFrame | None = None  # the reference keyframe: the last one made (initialization, local mapping), or
    # after a relocalization the one that sees most of the frame's points (relocalization)
    lost_since: int | None = None  # frame id at which tracking was last lost (:meth:`lose`)
    last_kf_frame: int = 0  # frame id of the last keyframe (initialization, local mapping)
    kf_inliers: int = 0  # pose inliers of the frame that made the last keyframe (same parts)
    deformable: set[int] = field(default_factory=set)  # points on a deforming object (deformable tracks)
    held: set[int] = field(default_factory=set)  # those of them linked at rest: never culled (deformable tracks)

    def in_image(self, uv: np.ndarray, z: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Mask of the projections (ideal pixels ``uv`` at depths ``z``) that fall in the image, grown by ``margin``
        pixels. The ideal image's rectangle for a pinhole or an OpenCV-distorted lens (as before); a fisheye's image
        in the ideal one is no rectangle (its periphery lies far outside it), so there each ray is taken through
        the lens and tested in the image itself."""
        W, H = self.cam.width, self.cam.height
        if self.cam.fisheye:
            front = z > 0
            px = np.full((len(uv), 2), np.nan)
            if np.any(front):
                px[front] = self.cam.project(self.cam.backproject(uv[front], np.ones(int(front.sum()))))
            uv = px
        with np.errstate(invalid="ignore"):
            return (z > 0) & (uv[:, 0] >= -margin) & (uv[:, 0] < W + margin) & (uv[:, 1] >= -margin) \
                & (uv[:, 1] < H + margin)

    def rigid(self, ids: np.ndarray) -> np.ndarray:
        """Mask of the point ids that may vote for the camera pose (not flagged deformable)."""
        return ~np.isin(ids, np.fromiter(self.deformable, np.int64) if self.deformable else np.zeros(0, np.int64))

    def lose(self) -> None:
        """Tracking failed in this frame: the motion model is void and relocalization starts."""
        self.state = LOST
        self.lost_since = self.frame_id
        self.velocity = None
