"""The cloud Alg. 6.1 captures a car from, read off the project's SLAM map (thesis §6.3.1).

A feature-based SLAM keeps few points on a car: an RGB-D keyframe makes map points of its closest unmatched
features only (ORB-SLAM2's choice, good for tracking: the floor at the camera's feet), so a car a few metres away gets
points mostly from the first keyframe that sees it. Its keyframes still hold every feature's measured depth. With
``keyframe_depth`` the cloud is the map's points plus every keyframe feature with a depth (and no map point) placed
from its keyframe's optimised pose: the same features and poses, more of them. A monocular map has no depth: its
points alone.
"""

from __future__ import annotations

import numpy as np

from simreal_nodes.camera import CameraModel
from simreal_nodes.vision.slam.map import Map


def capture_cloud(m: Map, cam: CameraModel, keyframe_depth: bool = True, max_depth: float = 8.0) -> np.ndarray:
    """(n, 3) points in the map frame: the map's points, and with ``keyframe_depth`` the keyframes' features with a
    measured depth (at most ``max_depth`` metres) that are not map points."""
    _ids, pts, _ = m.point_arrays()
    parts = [np.asarray(pts, float).reshape(-1, 3)]
    if keyframe_depth:
        for kf in list(m.keyframes.values()):
            if kf.depth is None:
                continue
            z = np.asarray(kf.depth, float)
            ok = np.isfinite(z) & (z > 0) & (z <= max_depth) & (np.asarray(kf.mp) < 0)
            if not ok.any():
                continue
            P = cam.backproject(kf.feats.und[ok], z[ok])
            parts.append(P @ kf.T_wc[:3, :3].T + kf.T_wc[:3, 3])
    return np.concatenate(parts)
