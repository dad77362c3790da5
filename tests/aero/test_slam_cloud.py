"""The capture's cloud read off a SLAM map: map points, plus the keyframes' features with a measured depth placed from
their keyframe's pose (RGB-D), and nothing else."""

from __future__ import annotations

import numpy as np

from simreal_nodes.aero.slam_cloud import capture_cloud
from simreal_nodes.camera import CameraModel
from simreal_nodes.geometry import look_at
from simreal_nodes.vision.orb import Features
from simreal_nodes.vision.slam.map import Map


def _features(uv: np.ndarray) -> Features:
    n = len(uv)
    return Features(uv=uv.astype(np.float32), und=uv.astype(np.float64), octave=np.zeros(n, int),
                    desc=np.zeros((n, 32), np.uint8), response=np.ones(n))


def test_keyframe_features_with_depth_are_placed_from_their_keyframe() -> None:
    cam = CameraModel.from_intrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    rng = np.random.default_rng(0)
    world = rng.uniform([-1.0, -1.0, 0.0], [1.0, 1.0, 1.0], (40, 3))
    T_wc = look_at([4.0, 0.5, 1.5], [0.0, 0.0, 0.5])
    Xc = (world - T_wc[:3, 3]) @ T_wc[:3, :3]  # optical frame
    uv, z = cam.K[:2, :2] @ (Xc[:, :2] / Xc[:, 2:]).T + cam.K[:2, 2:3], Xc[:, 2].copy()
    z[0] = np.nan  # no depth reading
    z[1] = 9.5  # beyond the depth camera's range
    m = Map()
    kf = m.new_keyframe(0, T_wc, _features(uv.T), z)
    p = m.new_point(world[2] + 0.01, np.zeros(32, np.uint8), kf, 2)  # feature 2 is already a map point
    assert kf.mp[2] == p.id
    cloud = capture_cloud(m, cam)
    assert len(cloud) == 1 + 37  # the map point, and the 37 features with a depth and no map point
    np.testing.assert_allclose(cloud[0], world[2] + 0.01)
    np.testing.assert_allclose(cloud[1:], world[3:], atol=1e-9)
    only_map = capture_cloud(m, cam, keyframe_depth=False)
    assert len(only_map) == 1
    assert len(capture_cloud(m, cam, max_depth=20.0)) == 1 + 38  # the far reading kept under a longer range
