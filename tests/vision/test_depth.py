"""The depth path: metric depth to points with decimation and invalid pixels; the real TUM frame; stereo
SGBM on the real Middlebury Motorcycle pair against its ground-truth disparity."""

import cv2
import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.io.images import depth_to_metres
from simreal_nodes.vision.depth import bad_pixel_rate, depth_points
from simreal_nodes.vision.stereo import sgbm_disparity
from tests.conftest import shared

CAM = CameraModel.from_intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)


def test_plane_points_with_decimation_and_pose():
    d = np.full((48, 64), 2.0, np.float32)
    for step in (1, 2, 4, 8):
        dp = depth_points(d, CAM, step)
        assert len(dp.points) == len(range(0, 48, step)) * len(range(0, 64, step))
        np.testing.assert_allclose(dp.points[:, 2], 2.0)
        np.testing.assert_allclose(CAM.project(dp.points), dp.pixels, atol=1e-9)
    T = G.make_T(G.rot_axis("y", 0.3), [1.0, 2.0, 3.0])
    dw = depth_points(d, CAM, 4, T)
    np.testing.assert_allclose(dw.points, G.transform(T, depth_points(d, CAM, 4).points))


def test_a_fisheye_depth_image_gives_the_points_its_rays_reach():
    """An equidistant (fisheye) camera: every pixel's point lies on its own ray through the lens (projected back to
    that pixel), at the depth given; the corners of a circular fisheye, past 90 degrees off the axis, give none."""
    fish = CameraModel(64, 48, [[24.0, 0, 31.5], [0, 24.0, 23.5], [0, 0, 1]], [-0.02, 0.004, -0.001, 0.0],
                       "equidistant")
    dp = depth_points(np.full((48, 64), 2.0, np.float32), fish, 1)
    assert 0.8 * 48 * 64 < len(dp.points) < 48 * 64  # the corners (radius over 1.53 f) have no ray in front
    np.testing.assert_allclose(dp.points[:, 2], 2.0)
    np.testing.assert_allclose(fish.project(dp.points), dp.pixels, atol=1e-6)
    r = np.hypot(dp.pixels[:, 0] - 31.5, dp.pixels[:, 1] - 23.5) / 24.0
    assert r.max() > 1.45 and np.degrees(np.arctan(np.hypot(*dp.points[:, :2].T) / 2.0)).max() > 80


def test_invalid_depth_is_skipped():
    d = np.full((48, 64), 1.0, np.float32)
    d[0, :] = np.nan
    d[1, :] = np.inf
    d[2, :] = -1.0
    d[3, :] = 0.0
    d[4, :] = 50.0  # beyond max_depth
    dp = depth_points(d, CAM, 1, max_depth=10.0)
    assert len(dp.points) == 43 * 64 and np.isfinite(dp.points).all()
    none = depth_points(np.full((48, 64), np.nan, np.float32), CAM, 2)
    assert len(none.points) == 0 and none.valid_fraction == 0.0
    with pytest.raises(ValueError, match="64x48"):
        depth_points(np.ones((10, 10)), CAM)
    with pytest.raises(ValueError, match="2-D"):
        depth_points(np.ones((48, 64, 3)), CAM)


def test_depth_encodings():
    mm = np.array([[0, 1000], [2500, 65535]], np.uint16)
    np.testing.assert_allclose(depth_to_metres(mm, "16UC1"), [[np.nan, 1.0], [2.5, 65.535]], equal_nan=True)
    m = np.array([[np.nan, 1.0], [np.inf, -2.0]], np.float32)
    np.testing.assert_allclose(depth_to_metres(m, "32FC1"), [[np.nan, 1.0], [np.nan, np.nan]], equal_nan=True)


@pytest.mark.shared_data
def test_real_tum_frame_through_the_depth_path():
    raw = cv2.imread(str(shared("rgbd", "tum_fr3_long_office_depth.png")), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16 and raw.shape == (480, 640)
    metres = raw.astype(np.float32) / 5000.0  # TUM's scale (value / 5000), 0 = invalid
    metres[raw == 0] = np.nan
    cam = CameraModel.from_intrinsics(640, 480, 535.4, 539.2, 320.1, 247.6)
    dp = depth_points(metres, cam, 1)
    invalid = 1.0 - dp.valid_fraction
    assert 0.10 < invalid < 0.30, invalid  # the README says about 19 % invalid
    assert np.isfinite(dp.points).all()
    z = dp.points[:, 2]
    assert 0.3 < np.median(z) < 4.0  # an office desk seen by a Kinect
    d4 = depth_points(metres, cam, 4)
    assert abs(d4.valid_fraction - dp.valid_fraction) < 0.02
    assert len(d4.points) < len(dp.points) / 12


def test_middlebury_motorcycle_bad_pixel_rate():
    """Real stereo pair with ground-truth disparity shipped with scikit-image (Middlebury 2014, Motorcycle)."""
    from skimage import data

    left, right, truth = data.stereo_motorcycle()
    truth = np.asarray(truth, np.float64)
    nd = int(np.ceil(np.nanmax(truth[np.isfinite(truth)]) / 16 + 1) * 16)
    disp = sgbm_disparity(left[:, :, ::-1].copy(), right[:, :, ::-1].copy(), num_disparities=nd, block=5)
    bad, density = bad_pixel_rate(disp, truth, threshold=2.0)
    print(f"Motorcycle: {nd} disparities, bad-2.0 {100 * bad:.1f} %, density {100 * density:.1f} %")
    assert bad < 0.25, bad
    assert density > 0.75, density
