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


def test_coefficients_that_do_not_invert_over_the_image_are_refused():
    """Issue 20: a plumb_bob lens whose radial curve turns back before the image's corners (k1 = -0.9 at f = 576: the
    curve peaks at a normalized radius of 0.41, the corners are at 0.69) has no ideal pixel for its border, and
    OpenCV's undistortion returned points 244 px off without a word; tangential terms of 0.5 give NaN. Real lenses
    pass: TUM fr1's (a strong fifth-order term), a strong barrel, 14 small coefficients, and a fisheye's dark corners
    (NaN by design) are not judged by this."""
    K = [576.0, 0.0, 321.5, 0.0, 570.0, 238.7, 0.0, 0.0, 1.0]
    for d in ([-0.9, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.5, 0.5, 0.0], [-5.0, 0.0, 0.0, 0.0, 0.0]):
        with pytest.raises(CameraInfoError, match="do not invert over the 640x480 image"):
            CameraModel.from_camera_info(Info(640, 480, K, d=d))
    for d in ([0.2624, -0.9531, -0.0054, 0.0026, 1.1633], [-0.35, 0.15, 0.001, -0.001, -0.03], [0.01] * 14):
        cam = CameraModel.from_camera_info(Info(640, 480, K, d=d))
        assert cam._border_round_trip() < 1e-6
    CameraModel.from_camera_info(Info(640, 480, K, d=[-0.9, 0.5, 0.0, 0.0], model="equidistant"))


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


FISHEYE_D = [-0.021, 0.0043, -0.0012, 0.0001]


def _equidistant(P, fx, fy, cx, cy, D):
    """The equidistant lens written out (ROS image_geometry's and OpenCV's cv::fisheye's): theta the ray's angle off
    the axis, its radius in the image f * theta_d with theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)."""
    a, b = P[:, 0] / P[:, 2], P[:, 1] / P[:, 2]
    r = np.hypot(a, b)
    th = np.arctan(r)
    thd = th * (1 + D[0] * th ** 2 + D[1] * th ** 4 + D[2] * th ** 6 + D[3] * th ** 8)
    s = np.where(r > 0, thd / np.where(r > 0, r, 1), 1.0)
    return np.c_[fx * a * s + cx, fy * b * s + cy]


def test_an_equidistant_camera_is_a_fisheye_not_a_pinhole_with_four_coefficients():
    """A CameraInfo with distortion_model 'equidistant' (a fisheye, k1..k4) was taken as plumb_bob's k1 k2 p1 p2:
    every pixel off. Now it projects as the model's formula does, its pixels undistort back to the ray's ideal
    pixel, a pixel whose ray would be 90 degrees or more off the axis has none (NaN), zero coefficients still
    are a fisheye (the radius f * theta, not f * tan theta), and it takes exactly four coefficients."""
    cam = CameraModel.from_camera_info(Info(640, 480, [300.0, 0, 321.3, 0, 298.0, 238.6, 0, 0, 1], d=FISHEYE_D,
                                            model="equidistant"))
    assert cam.fisheye and cam.has_distortion
    rng = np.random.default_rng(0)
    ang = rng.uniform(0, np.radians(80), 200)  # rays up to 80 degrees off the axis
    phi = rng.uniform(0, 2 * np.pi, 200)
    P = np.c_[np.sin(ang) * np.cos(phi), np.sin(ang) * np.sin(phi), np.cos(ang)] * rng.uniform(0.3, 5, (200, 1))
    uv = cam.project(P)
    np.testing.assert_allclose(uv, _equidistant(P, cam.fx, cam.fy, cam.cx, cam.cy, FISHEYE_D), atol=1e-6)
    pinhole = cam.project(P, distort=False)
    assert np.median(np.linalg.norm(uv - pinhole, axis=1)) > 20  # what the plumb_bob reading was off by, and more
    np.testing.assert_allclose(cam.undistort_points(uv), pinhole, atol=1e-4 * np.abs(pinhole).max())
    # pixels past the ray at 90 degrees (theta_d at pi/2 is about 1.51 here: a circular fisheye's dark corners)
    far = cam.undistort_points(np.array([[cam.cx + 300 * 1.6, cam.cy], [cam.cx, cam.cy - 298 * 1.7],
                                         [cam.cx + 300 * 1.45, cam.cy]]))
    assert np.isnan(far[:2]).all() and np.isfinite(far[2]).all() and far[2, 0] > cam.cx + 300 * 8
    zero = CameraModel(640, 480, cam.K, np.zeros(4), "equidistant")
    assert zero.has_distortion
    np.testing.assert_allclose(zero.project(np.array([[1.0, 0, 1]]))[0, 0], cam.cx + cam.fx * np.pi / 4)
    with pytest.raises(CameraInfoError, match="takes 4 distortion coefficients"):
        CameraModel(640, 480, cam.K, np.zeros(5), "equidistant")
    with pytest.raises(CameraInfoError, match="not OpenCV pinhole distortion"):
        cam.cv_dist()
    # the maps a node keeps are rebuilt when the lens changes, not only K
    assert cam.same_as(CameraModel(640, 480, cam.K.copy(), list(FISHEYE_D), "equidistant"))
    assert not cam.same_as(CameraModel(640, 480, cam.K, [-0.02, 0.0043, -0.0012, 0.0001], "equidistant"))
    assert not cam.same_as(CameraModel(640, 480, cam.K, FISHEYE_D, "plumb_bob"))
    assert not cam.same_as(None)


def _plumb_bob(x, y, D):
    """Brown-Conrady written out (ROS's plumb_bob, OpenCV's k1 k2 p1 p2 k3 order) on normalised coordinates."""
    k1, k2, p1, p2, k3 = D
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def test_a_plumb_bob_undistortion_map_takes_each_ideal_pixel_to_its_distorted_pixel():
    """The ingest's undistortion of a plumb_bob lens (``Undistorter``, on ``undistort_maps``): each pixel of the
    ideal image reads the raw pixel its ray lands on by the lens model written out here, and a raw image's dot moves
    to where the pinhole puts its ray."""
    import cv2

    from simreal_nodes.vision.undistort import Undistorter

    D = [-0.28, 0.09, 0.0012, -0.0009, 0.01]
    cam = CameraModel(640, 480, [[520.0, 0, 318.7], [0, 515.0, 241.2], [0, 0, 1]], D, "plumb_bob")
    mx, my = cam.undistort_maps(cam.K, (640, 480), cv2.CV_32FC1)
    ys, xs = np.mgrid[0:480:37, 0:640:41]
    xd, yd = _plumb_bob((xs.ravel() - cam.cx) / cam.fx, (ys.ravel() - cam.cy) / cam.fy, D)
    expect = np.c_[cam.fx * xd + cam.cx, cam.fy * yd + cam.cy]
    assert np.median(np.linalg.norm(expect - np.c_[xs.ravel(), ys.ravel()], axis=1)) > 5  # a lens that bends
    np.testing.assert_allclose(np.c_[mx[ys, xs].ravel(), my[ys, xs].ravel()], expect, atol=2e-3)
    # a bright dot in the raw image at the distorted pixel of a ray lands, undistorted, on the ray's pinhole pixel
    und = Undistorter(cam)
    for u, v in ((100.0, 80.0), (560.0, 420.0), (320.0, 240.0)):
        x, y = (u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy
        xr, yr = _plumb_bob(x, y, D)
        raw = np.zeros((480, 640), np.uint8)
        cv2.circle(raw, (round(4 * (cam.fx * xr + cam.cx)), round(4 * (cam.fy * yr + cam.cy))), 8, 255, -1,
                   cv2.LINE_AA, shift=2)
        out = und.image(raw).astype(float)
        yy, xx = np.mgrid[:480, :640]
        centre = np.array([(out * xx).sum(), (out * yy).sum()]) / out.sum()
        assert np.linalg.norm(centre - [u, v]) < 0.3, (u, v, centre)


def test_a_fisheye_undistortion_map_takes_each_ideal_pixel_to_its_fisheye_pixel():
    """The maps the ingest's undistortion and the dense tracker remap with (``undistort_maps``): each pixel of the
    ideal pinhole image reads the fisheye pixel its ray lands on; undistorting that pixel gives the ideal one back."""
    import cv2

    cam = CameraModel(640, 480, [[300.0, 0, 321.3], [0, 298.0, 238.6], [0, 0, 1]], FISHEYE_D, "equidistant")
    mx, my = cam.undistort_maps(cam.K, (640, 480), cv2.CV_32FC1)
    ys, xs = np.mgrid[0:480:37, 0:640:41]
    rays = np.c_[(xs.ravel() - cam.cx) / cam.fx, (ys.ravel() - cam.cy) / cam.fy, np.ones(xs.size)]
    expect = _equidistant(rays, cam.fx, cam.fy, cam.cx, cam.cy, FISHEYE_D)
    np.testing.assert_allclose(np.c_[mx[ys, xs].ravel(), my[ys, xs].ravel()], expect, atol=2e-3)
    inside = (expect[:, 0] > 0) & (expect[:, 0] < 639) & (expect[:, 1] > 0) & (expect[:, 1] < 479)
    assert inside.sum() > 100
    back = cam.undistort_points(expect[inside])  # and undistorting those fisheye pixels gives the ideal ones back
    np.testing.assert_allclose(back, np.c_[xs.ravel(), ys.ravel()][inside], atol=1e-6)


def test_a_fisheyes_stretch_is_the_undistortions_jacobian_in_closed_form():
    """``stretch`` (ideal pixels per image pixel, what weighs a fisheye's measurements) comes from the lens curve in
    closed form: the larger singular value of the undistortion's Jacobian, against central differences of
    ``undistort_points`` over 0.01 px (a skewed K, another lens); 1 at the centre, NaN where a pixel has no ray."""
    rng = np.random.default_rng(3)
    uv = rng.uniform([0, 0], [640, 480], (500, 2))
    for K, D in (([[300.0, 0, 321.3], [0, 298.0, 238.6], [0, 0, 1]], FISHEYE_D),
                 ([[280.0, 2.5, 318.0], [0, 310.0, 242.0], [0, 0, 1]], [0.05, -0.02, 0.01, -0.003])):
        cam = CameraModel(640, 480, K, D, "equidistant")
        h = 0.01
        d = [cam.undistort_points(uv + s) for s in ((h, 0), (-h, 0), (0, h), (0, -h))]
        J = np.stack([np.stack([(d[0] - d[1])[:, 0], (d[2] - d[3])[:, 0]], -1),
                      np.stack([(d[0] - d[1])[:, 1], (d[2] - d[3])[:, 1]], -1)], 1) / (2 * h)
        finite = np.isfinite(J).all(axis=(1, 2))
        expect = np.full(len(uv), np.nan)
        expect[finite] = np.linalg.svd(J[finite], compute_uv=False)[:, 0]
        got = cam.stretch(uv)
        np.testing.assert_array_equal(np.isfinite(got), finite)
        np.testing.assert_allclose(got[finite], expect[finite], rtol=1e-5)
        assert got[finite].max() > 3.0  # the periphery is stretched (corners about 70 degrees off the axis)
        if K[0][1] == 0:  # (with a skew the ideal image is sheared against the lens's: over 1 at the centre)
            np.testing.assert_allclose(cam.stretch(np.array([[cam.cx, cam.cy]])), 1.0, rtol=1e-9)
    far = np.array([[cam.cx + 280 * 1.7, cam.cy]])  # past 90 degrees
    assert np.isnan(cam.stretch(far)).all() and np.isnan(cam.undistort_points(far)).all()


@pytest.mark.parametrize("model,D", [("plumb_bob", [-0.25, 0.08, 0.001, -0.0008, 0.0]), ("equidistant", FISHEYE_D)])
def test_a_binned_and_cropped_camera_info_gives_the_camera_of_the_images_sent(model, D):
    """REP 104: a CameraInfo's K and D are the full sensor's; with binning and a region of interest the camera sends
    the region binned (image_geometry reduces K so). The model is the sent images' camera: its size the region's over
    the binning, and every ray lands where the full camera puts it, moved and divided as the pixels are (1e-9 px);
    the undistortion agrees the same way. A region off the sensor or a binning that leaves no pixel is refused;
    binning 0 or 1 and an all-zero region are the whole sensor."""
    from types import SimpleNamespace

    from simreal_nodes.camera import sensor_reduction

    K = [400.0, 0, 321.3, 0, 398.0, 238.6, 0, 0, 1]
    full = CameraModel.from_camera_info(Info(640, 480, K, D, model))

    def info(bx, by, roi):
        m = Info(640, 480, K, D, model)
        m.binning_x, m.binning_y = bx, by
        m.roi = SimpleNamespace(x_offset=roi[0], y_offset=roi[1], width=roi[2], height=roi[3], do_rectify=False)
        return m

    cam = CameraModel.from_camera_info(info(2, 2, (100, 50, 400, 300)))
    assert (cam.width, cam.height) == (200, 150) and cam.fisheye == full.fisheye
    rng = np.random.default_rng(5)
    P = np.c_[rng.uniform(-0.4, 0.5, 100), rng.uniform(-0.3, 0.3, 100), np.ones(100)] * rng.uniform(1, 3, (100, 1))
    np.testing.assert_allclose(cam.project(P), (full.project(P) - [100, 50]) / 2, atol=1e-9)
    np.testing.assert_allclose(cam.project(P, distort=False), (full.project(P, distort=False) - [100, 50]) / 2,
                               atol=1e-9)
    uv = full.project(P)
    np.testing.assert_allclose(cam.undistort_points((uv - [100, 50]) / 2), (full.undistort_points(uv) - [100, 50]) / 2,
                               atol=1e-6)
    for plain in (info(0, 0, (0, 0, 0, 0)), info(1, 1, (0, 0, 640, 480)), Info(640, 480, K, D, model)):
        S, size = sensor_reduction(plain)
        assert size == (640, 480) and np.array_equal(S, np.eye(3))
    with pytest.raises(CameraInfoError, match="does not fit its 640x480 sensor"):
        CameraModel.from_camera_info(info(1, 1, (400, 0, 400, 480)))
    with pytest.raises(CameraInfoError, match="leaves no pixel"):
        CameraModel.from_camera_info(info(1000, 1, (0, 0, 0, 0)))
