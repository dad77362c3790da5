"""What the SLAM reports for one frame."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simreal_nodes.vision.orb import Features
from simreal_nodes.vision.slam.config import STATE_NAMES
from simreal_nodes.vision.slam.map import Map


@dataclass
class TrackResult:
    """One frame's outcome: the state (with the reason when not tracking), the camera pose, and the observations
    (map point id, measured pixel, pose inlier, map position) the deformable tracker takes as measurements."""

    state: int
    reason: str = ""
    T_wc: np.ndarray | None = None
    n_features: int = 0
    n_matches: int = 0
    n_inliers: int = 0
    obs_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    obs_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))
    obs_inlier: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    obs_pos: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    keyframe: bool = False
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def state_name(self) -> str:
        return STATE_NAMES[self.state]


def frame_result(m: Map, state: int, reason: str, T_wc: np.ndarray, f: Features, kp: np.ndarray, ids: np.ndarray,
                 inl: np.ndarray) -> TrackResult:
    """A tracked frame's result: feature ``kp[k]`` observes map point ``ids[k]`` (a pose inlier where ``inl``)."""
    ids = np.asarray(ids, np.int64)
    kp = np.asarray(kp, np.int64)
    pos = m._pos[m.rows(ids)] if len(ids) else np.zeros((0, 3))
    return TrackResult(state, reason, T_wc, len(f), len(ids), int(np.sum(inl)), ids, f.uv[kp], np.asarray(inl, bool),
                       pos)
