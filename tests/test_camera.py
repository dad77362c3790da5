import numpy as np
import pytest

from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import CameraInfoError


class Info:
    def __init__(self, w, h, k, d=(0, 0, 0, 0, 0), model="plumb_bob"):
        class H:
            frame_id = "cam"
        self.header, self.width, self.height, self.k, self.d, self.distortion_model = H(), w, h, k, d, model


def test_zero_camera_info_is_rejected_clearly():
    with pytest.raises(CameraInfoError, match="focal lengths must be positive"):
        CameraModel.from_camera_info(Info(640, 480, [0.0] * 9))
    with pytest.raises(CameraInfoError, match="size 0x0"):
        CameraModel.from_camera_info(Info(0, 0, [500, 0, 320, 0, 500, 240, 0, 0, 1]))
    with pytest.raises(CameraInfoError, match="has 4 values"):
        CameraModel.from_camera_info(Info(640, 480, [1, 2, 3, 4]))
    with pytest.raises(CameraInfoError, match="distortion model"):
        CameraModel.from_camera_info(Info(640, 480, [500, 0, 320, 0, 500, 240, 0, 0, 1], model="fisheye9"))
    # found by the graph fuzz (benchmarks/fuzz_graph.py): the overlay allocated by the declared width
    with pytest.raises(CameraInfoError, match="over 16384 pixels a side"):
        CameraModel.from_camera_info(Info(2 ** 32 - 1, 480, [500, 0, 320, 0, 500, 240, 0, 0, 1]))
    # found by the graph fuzz in stop 47: 3 coefficients passed, and OpenCV asserted in the collision node
    K = [500, 0, 320, 0, 500, 240, 0, 0, 1]
    for n in (0, 4, 5, 8, 12, 14):
        CameraModel.from_camera_info(Info(640, 480, K, d=[0.01] * n))
    for n in (1, 3, 6, 20):
        with pytest.raises(CameraInfoError, match=f"{n} distortion coefficients"):
            CameraModel.from_camera_info(Info(640, 480, K, d=[0.01] * n))


def test_project_backproject_and_yaml(tmp_path):
    cam = CameraModel.from_intrinsics(640, 480, 520.0, 515.0, 319.5, 239.5, D=[0.1, -0.05, 0.001, 0.002, 0.0])
    rng = np.random.default_rng(1)
    P = np.c_[rng.uniform(-0.5, 0.5, (50, 2)), rng.uniform(1, 3, 50)]
    uv = cam.project(P)
    ideal = cam.undistort_points(uv)
    back = cam.backproject(ideal, P[:, 2])
    np.testing.assert_allclose(back, P, atol=1e-6)
    assert np.isnan(cam.project(np.array([[0, 0, -1.0]]))).all()
    f = tmp_path / "calib.yaml"
    cam.to_calibration_yaml(f)
    again = CameraModel.from_calibration_yaml(f)
    np.testing.assert_allclose(again.K, cam.K)
    np.testing.assert_allclose(again.D, cam.D)


def test_bad_calibration_yaml(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, data: [1, 2]}\n")
    with pytest.raises(CameraInfoError, match=r"camera_matrix.data"):
        CameraModel.from_calibration_yaml(f)
    with pytest.raises(CameraInfoError, match="not found"):
        CameraModel.from_calibration_yaml(tmp_path / "missing.yaml")


def test_an_image_of_another_size_than_the_camera_is_refused_with_both_sizes():
    from simreal_nodes.errors import ImageFormatError

    cam = CameraModel.from_camera_info(Info(64, 48, [50, 0, 32, 0, 50, 24, 0, 0, 1]))
    cam.check_size(np.zeros((48, 64, 3)))
    with pytest.raises(ImageFormatError, match="depth image is 64x1, CameraInfo says 64x48"):
        cam.check_size(np.zeros((1, 64)), "depth image")


def test_the_ideal_pixel_map_is_within_a_fiftieth_of_a_pixel_of_the_exact_one():
    """Issue 18: the overlay's distortion map is exact every 4th pixel and bilinear between (a tenth of the time of
    every pixel exactly, the first frame waits for it); on a strong barrel distortion (and a mild one) it stays
    within 0.02 px of undistorting every pixel, and is exact on the grid."""
    for D in ([-0.35, 0.15, 0.001, -0.001, -0.03], [-0.04, 0.01, 0.0, 0.0, 0.0]):
        cam = CameraModel.from_intrinsics(640, 480, 576.0, 570.0, 321.5, 238.7, D=D)
        exact = cam.ideal_pixel_map(step=1)
        fast = cam.ideal_pixel_map()
        assert fast.shape == exact.shape == (480, 640, 2)
        assert np.abs(fast - exact).max() < 0.02
        np.testing.assert_allclose(fast[::4, ::4], exact[::4, ::4], atol=2e-4)  # float32 on the grid
    # without distortion the map is the identity
    plain = CameraModel.from_intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5).ideal_pixel_map()
    np.testing.assert_allclose(plain[..., 0], np.broadcast_to(np.arange(64.0), (48, 64)), atol=1e-4)
    with pytest.raises(ValueError, match="power of two"):
        cam.ideal_pixel_map(step=3)
