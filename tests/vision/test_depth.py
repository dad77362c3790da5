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


COLOR = CameraModel(640, 480, [[600.0, 0, 321.0], [0, 600.0, 241.5], [0, 0, 1]], [0.05, -0.02, 0.0005, 0.0003, 0.0])
DEPTH_CAM = CameraModel(640, 480, [[580.0, 0, 318.2], [0, 580.0, 237.9], [0, 0, 1]], [-0.04, 0.01, 0.0, 0.0, 0.0])
T_COLOR_DEPTH = G.make_T(G.exp_so3([0.004, -0.006, 0.003]), [-0.025, 0.001, 0.002])  # a depth camera 25 mm aside


def _scene_depth(cam: CameraModel, T_color_cam: np.ndarray) -> np.ndarray:
    """Ray-cast depth (metres, NaN where nothing) of a camera at ``T_color_cam`` in the colour camera's frame: a square
    patch 0.8 m away (20 cm a side) before a plane tilted about y (z = 1.5 + 0.2 x)."""
    ys, xs = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    und = cam.undistort_points(np.c_[xs.ravel(), ys.ravel()])
    r = cam.backproject(und, np.ones(len(und)))  # rays, z = 1 in the camera
    o, d = T_color_cam[:3, 3], r @ T_color_cam[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t_near = (0.8 - o[2]) / d[:, 2]
        p = o + t_near[:, None] * d
        near = (np.abs(p[:, 0]) <= 0.1) & (np.abs(p[:, 1]) <= 0.1) & (t_near > 0)
        t_far = (1.5 - o[2] + 0.2 * o[0]) / (d[:, 2] - 0.2 * d[:, 0])
    t = np.where(near, t_near, t_far)
    return t.reshape(cam.height, cam.width).astype(np.float32)


def test_a_depth_camera_s_image_is_registered_to_the_colour_camera():
    """A depth camera 25 mm beside the colour camera (its own intrinsics, lens and a small turn), both ray-cast on a
    patch 0.8 m away before a tilted plane: the registered image has a depth at over 99 % of the colour pixels and
    reads the colour camera's own depth there within 1 mm, the near patch not overwritten by the plane it hides (a
    z-buffer) nor showing the plane through gaps between its samples; only the one-pixel ring along the patch's edge
    may read the other side of it (where a pixel's centre and the depth camera's samples fall on either side). Read
    as if registered (the same pixels), a fifth of the image is over 5 mm off."""
    from simreal_nodes.vision.depth import register_depth

    truth = _scene_depth(COLOR, np.eye(4))
    raw = _scene_depth(DEPTH_CAM, T_COLOR_DEPTH)
    reg = register_depth(raw, DEPTH_CAM, COLOR, T_COLOR_DEPTH)
    assert reg.shape == truth.shape and reg.dtype == np.float32
    ok = np.isfinite(reg)
    assert ok.mean() > 0.99, ok.mean()
    patch = (np.abs(truth - 0.8) < 1e-6).astype(np.uint8)
    ring = cv2.dilate(patch, np.ones((3, 3), np.uint8)) != cv2.erode(patch, np.ones((3, 3), np.uint8))
    assert patch.sum() > 5000 and ring.sum() < 0.01 * ring.size
    err = np.abs(reg - truth)[ok & ~ring]
    assert err.max() < 1e-3, err.max()
    assert np.mean(np.abs(raw - truth) > 5e-3) > 0.2
    with pytest.raises(ValueError, match="its CameraInfo says"):
        register_depth(raw[:100], DEPTH_CAM, COLOR, T_COLOR_DEPTH)
    # nothing valid: nothing registered
    assert np.isnan(register_depth(np.zeros_like(raw), DEPTH_CAM, COLOR, T_COLOR_DEPTH)).all()


def test_depth_registration_at_the_extremes():
    """A depth camera 4.6 times coarser than the colour camera still covers the colour image (footprints of several
    pixels, centred); a strong barrel colour lens (k1 = -0.3) does not take points far outside its view back into
    the image (its polynomial folds back there); a frame whose depth reaches nothing in the colour view, or has none,
    registers to no depth rather than failing."""
    from simreal_nodes.vision.depth import register_depth

    coarse = CameraModel(140, 104, [[580.0 / 4.6, 0, 69.5], [0, 580.0 / 4.6, 51.5], [0, 0, 1]])
    truth = _scene_depth(COLOR, np.eye(4))
    reg = register_depth(_scene_depth(coarse, T_COLOR_DEPTH), coarse, COLOR, T_COLOR_DEPTH)
    ok = np.isfinite(reg)
    assert ok.mean() > 0.97, ok.mean()
    assert np.median(np.abs(reg[ok] - truth[ok])) < 2e-3

    barrel = CameraModel(640, 480, [[600.0, 0, 320.0], [0, 600.0, 240.0], [0, 0, 1]], [-0.3, 0.0, 0.0, 0.0, 0.0])
    wide = CameraModel(640, 480, [[150.0, 0, 320.0], [0, 150.0, 240.0], [0, 0, 1]])  # 130 degrees across
    far_off = np.full((480, 640), 0.6, np.float32)
    far_off[:, 200:440] = np.nan  # only what lies 50-65 degrees off the axis, beyond the barrel camera's view
    reg = register_depth(far_off, wide, barrel, np.eye(4))
    assert np.isnan(reg).all(), np.isfinite(reg).sum()
    assert barrel.project(np.array([[np.tan(np.radians(60)), 0.0, 1.0]]))[0, 0] < 640  # (folded back inside)

    behind = G.make_T(G.exp_so3([0.0, np.pi, 0.0]), [0.0, 0.0, 0.0])  # the depth camera looking backwards
    assert np.isnan(register_depth(_scene_depth(DEPTH_CAM, T_COLOR_DEPTH), DEPTH_CAM, COLOR, behind)).all()
    assert np.isnan(register_depth(np.full((480, 640), np.nan, np.float32), DEPTH_CAM, COLOR, T_COLOR_DEPTH)).all()
