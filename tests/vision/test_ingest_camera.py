"""The ingest's camera (IngestCamera): CameraInfo handling, the check of every incoming stream, undistortion of
the image (bilinear) and the depth (nearest neighbour) against a distorted camera, file-source frames."""

from types import SimpleNamespace

import numpy as np
import pytest

from simreal_nodes.camera import CameraModel
from simreal_nodes.io import images
from simreal_nodes.io.sources import Frame
from simreal_nodes.vision.undistort import IngestCamera, Undistorter

DIST = CameraModel.from_intrinsics(64, 48, 60.0, 60.0, 32.0, 24.0, D=[-0.3, 0.1, 0.001, -0.001, 0.0])
PINHOLE = CameraModel.from_intrinsics(64, 48, 60.0, 60.0, 32.0, 24.0)


def _msg(img: np.ndarray, encoding: str) -> SimpleNamespace:
    return images.fill_image_msg(SimpleNamespace(), img, encoding)


def _info(cam: CameraModel) -> SimpleNamespace:
    return SimpleNamespace(header=SimpleNamespace(frame_id="cam"), **cam.camera_info_fields())


def _checker() -> np.ndarray:
    y, x = np.mgrid[:48, :64]
    return np.repeat((((x // 8 + y // 8) % 2) * 255).astype(np.uint8)[..., None], 3, axis=2)


def test_a_distorted_image_and_depth_are_undistorted():
    ic = IngestCamera(undistort=True)
    assert ic.camera_info(_info(DIST)) == ""
    und = Undistorter(DIST)
    img = _checker()
    c = ic.check("image", _msg(img, "bgr8"))
    assert c.why == "" and c.pixels is not None
    np.testing.assert_array_equal(c.pixels, und.image(img))
    assert not np.array_equal(c.pixels, img)
    # the published camera is the ideal one: same K, no distortion
    assert not ic.out_camera.has_distortion and np.allclose(ic.out_camera.K, DIST.K)
    depth = np.arange(48 * 64, dtype=np.uint16).reshape(48, 64)
    d = ic.check("depth", _msg(depth, "16UC1"))
    np.testing.assert_array_equal(d.pixels, und.depth(depth))
    assert np.isin(d.pixels[d.pixels > 0], depth).all()  # nearest neighbour: no blended depths
    assert np.array_equal(ic.undistorted("image", img), c.pixels)


def test_without_undistortion_messages_pass_as_they_are():
    ic = IngestCamera(undistort=False)
    ic.camera_info(_info(DIST))
    img = _checker()
    assert ic.check("image", _msg(img, "bgr8")).pixels is None and ic.out_camera is ic.cam
    assert ic.undistorted("depth", img[..., 0]) is not None
    ic2 = IngestCamera(undistort=True)
    ic2.camera_info(_info(PINHOLE))  # nothing to undistort
    assert ic2.check("image", _msg(img, "bgr8")).pixels is None


def test_every_stream_states_why_it_is_left_out():
    ic = IngestCamera(undistort=False)
    img = _checker()
    assert ic.check("image", _msg(img, "bgr8")).why == "waiting for a valid CameraInfo"
    bad = _info(DIST)
    bad.k = [0.0] * 9
    err = ic.camera_info(bad)
    assert err and ic.info_error == err and ic.cam is None
    assert ic.check("image", _msg(img, "bgr8")).why == f"unusable CameraInfo: {err}"
    ic.camera_info(_info(DIST))
    assert ic.info_error == ""
    assert ic.check("image", _msg(img[:40], "bgr8")).why == "image is 64x40 but CameraInfo says 64x48"
    broken = _msg(img, "bgr8")
    broken.step = 10
    assert ic.check("image", broken).why.startswith("malformed image: ")
    assert ic.check("depth", _msg(img, "bgr8")).why == "depth encoding 'bgr8' (expected 16UC1 or 32FC1)"
    assert ic.check("right", _msg(img, "bgr8")).why == "right image without a valid right CameraInfo"
    # a stereo pair matched along rows must be rectified: a left lens with distortion says it is not
    assert "the left camera's lens has distortion" in ic.right_info(_info(PINHOLE))
    ic.camera_info(_info(PINHOLE))
    assert ic.right_info(_info(PINHOLE)) == "" and ic.check("right", _msg(img, "bgr8")).why == ""
    assert ic.check("right", broken).why.startswith("malformed right image: ")
    assert ic.check("right", _msg(img[:40], "bgr8")).why == "right image is 64x40 but its CameraInfo says 64x48"
    ic.camera_info(_info(DIST))
    # a decompressed one (its message has no encoding field): the decoder's encoding decides
    packed = SimpleNamespace(format="png")
    depth = np.full((48, 64), 1000, np.uint16)
    assert ic.check("depth", packed, depth, "16UC1").why == ""
    assert ic.check("depth", packed, img, "bgr8").why == "depth encoding 'bgr8' (expected 16UC1 or 32FC1)"
    # a calibration file wins: CameraInfo is ignored
    cal = IngestCamera(undistort=True, calibration=PINHOLE)
    assert cal.camera_info(bad) == "" and cal.cam is PINHOLE


def test_file_frames():
    ic = IngestCamera(undistort=True)
    img = _checker()
    assert ic.file_frame(Frame(0, 0, error="cannot decode")) == "cannot decode"
    assert ic.file_frame(Frame(0, 0, image=img)).startswith("no intrinsics for 64x48 frames")
    assert ic.file_frame(Frame(0, 0, image=img, camera_info=_info(DIST))) == ""
    assert ic.cam is not None and ic.out_camera is not ic.cam  # the bag's distorted camera, undistorted


def test_the_right_camera_keeps_its_baseline_in_p():
    """The ingest node republishes the right CameraInfo from the model it checked; the stereo baseline lives only in
    its projection P (P[0, 3] = -fx * b), which must reach the localization and tracker nodes unchanged."""
    from simreal_nodes.vision.stereo import baseline_from_projection

    ic = IngestCamera(undistort=False)
    info = _info(PINHOLE)
    P = np.array(info.p, dtype=np.float64).reshape(3, 4)
    P[0, 3] = -60.0 * 0.12
    info.p = P.ravel().tolist()
    assert ic.right_info(info) == ""
    assert ic.right_P is not None and baseline_from_projection(ic.right_P) == pytest.approx(0.12)
    assert ic.right_info(SimpleNamespace(**{**vars(info), "k": [0.0] * 9})) != "" and ic.right_P is None


def test_a_fisheye_image_is_undistorted_to_the_pinhole_image_of_its_k():
    """An equidistant (fisheye) CameraInfo: the published image is the pinhole image of the same K (dots rendered
    through the fisheye land where K puts them, within 0.3 px), the published camera has no distortion."""
    import cv2

    from simreal_nodes.render.gl import Mesh, Renderer
    from tests.render.test_gl import disks

    fish = CameraModel(320, 240, [[170.0, 0, 160.3], [0, 169.0, 119.6], [0, 0, 1]], [-0.021, 0.0043, -0.0012, 0.0001],
                       "equidistant")
    gx, gy = np.meshgrid(np.linspace(-0.6, 0.6, 5), np.linspace(-0.4, 0.4, 3))
    P = np.c_[gx.ravel(), gy.ravel(), np.full(gx.size, 1.5)]  # up to 25 degrees off the axis
    V, F = disks(P, 0.03)
    r = Renderer(fish, ssaa=2, background=(0, 0, 0))
    r.add(Mesh("dots", V, F, mode="flat", tint=(1, 1, 1), unlit=True))
    rgb, _ = r.render(np.eye(4))
    r.release()
    ic = IngestCamera(undistort=True)
    assert ic.camera_info(_info(fish)) == ""
    out = ic.check("image", _msg(np.ascontiguousarray(rgb[..., ::-1]), "bgr8")).pixels
    assert out is not None and not ic.out_camera.has_distortion and np.allclose(ic.out_camera.K, fish.K)
    gray = out[..., 0].astype(np.float64)
    n, lab = cv2.connectedComponents((gray > 0).astype(np.uint8))
    assert n - 1 == len(P)
    truth = fish.project(P, distort=False)
    for k in range(1, n):
        ys, xs = np.nonzero(lab == k)
        c = np.array([np.sum(xs * gray[ys, xs]), np.sum(ys * gray[ys, xs])]) / gray[ys, xs].sum()
        assert np.min(np.linalg.norm(truth - c, axis=1)) < 0.3


def _raw_pair(rect: np.ndarray, K: np.ndarray, baseline: float):
    """A raw stereo pair made from a rectified one (``rect``: its left and right images, camera K, ``baseline``):
    each raw camera its own K and barrel lens, turned against the rectified frame by R, its CameraInfo as a driver
    publishes it (K, D, R, P). Each raw pixel reads the rectified pixel its ray lands on (``cv2.undistortPoints``
    with R and P: the point mapping, not the maps under test)."""
    import cv2

    h, w = rect[0].shape[:2]
    out, infos = [], []
    for img, (Kr, D, rvec, tx) in zip(rect, ((np.array([[150.0, 0, 81.0], [0, 149.0, 58.5], [0, 0, 1]]),
                                              [-0.2, 0.05, 0.001, -0.001, 0.0], [0.02, -0.015, 0.01], 0.0),
                                             (np.array([[152.0, 0, 78.5], [0, 151.0, 61.0], [0, 0, 1]]),
                                              [-0.18, 0.04, -0.001, 0.0005, 0.0], [-0.01, 0.02, -0.012],
                                              -K[0, 0] * baseline))):
        R = cv2.Rodrigues(np.array(rvec))[0]
        P = np.c_[K, [tx, 0.0, 0.0]]
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
        p = cv2.undistortPoints(np.c_[xs.ravel(), ys.ravel()].reshape(-1, 1, 2), Kr, np.array(D), R=R, P=K)
        p = p.reshape(h, w, 2).astype(np.float32)
        out.append(cv2.remap(img, p[..., 0], p[..., 1], cv2.INTER_CUBIC, borderMode=cv2.BORDER_CONSTANT))
        cam = CameraModel(w, h, Kr, D)
        f = cam.camera_info_fields()
        f["r"], f["p"] = [float(x) for x in R.ravel()], [float(x) for x in P.ravel()]
        infos.append(SimpleNamespace(header=SimpleNamespace(frame_id="cam"), **f))
    return out, infos


def test_a_raw_stereo_pair_is_rectified_in_the_ingest_and_a_raw_one_is_not_taken_for_rectified():
    """``stereo_input: raw``: a driver's raw pair (its own lenses, turned by its R) comes out as the rectified pair
    it was made from (within a few grey levels where the raw view covers it: two resamplings), published with the
    rectified cameras (K = P's, no distortion) and the baseline in the right P; the images wait until both
    CameraInfos are in. Without it, the raw right CameraInfo is refused with what makes it raw, and its images are
    not passed on (before, they were matched along rows as if rectified)."""
    import cv2

    from simreal_nodes.vision.stereo import baseline_from_projection

    rng = np.random.default_rng(2)
    K = np.array([[140.0, 0, 79.5], [0, 140.0, 59.5], [0, 0, 1]])
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160)).astype(np.float32), (0, 0), 2.0)
    tex = cv2.normalize(tex, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    rect = [tex, np.roll(tex, -6, axis=1)]  # a plane 6 px of disparity away
    raw, (info_l, info_r) = _raw_pair(rect, K, 0.1)
    ic = IngestCamera(undistort=False, stereo_input="raw")
    assert ic.camera_info(info_l) == ""
    assert "waiting for both CameraInfos" in ic.check("image", _msg(raw[0], "mono8")).why
    assert ic.right_info(info_r) == ""
    got = [ic.check(kind, _msg(img, "mono8")) for kind, img in (("image", raw[0]), ("right", raw[1]))]
    assert all(c.why == "" and c.pixels is not None for c in got)
    for c, want, came in zip(got, rect, raw):
        inner = (slice(20, 100), slice(30, 130))
        assert np.median(np.abs(c.pixels[inner].astype(float) - want[inner])) < 3.0
        assert np.median(np.abs(np.asarray(came[inner], float) - want[inner])) > 10  # the raw view differs
    assert np.allclose(ic.out_camera.K, K) and not ic.out_camera.has_distortion
    right, right_P = ic.out_right
    assert right is not None and np.allclose(right.K, K) and not right.has_distortion
    assert baseline_from_projection(right_P) == pytest.approx(0.1)

    plain = IngestCamera(undistort=False)
    plain.camera_info(info_l)
    why = plain.right_info(info_r)
    assert "describes raw images" in why and "R is not the identity" in why and "stereo_input to raw" in why
    assert plain.check("right", _msg(raw[1], "mono8")).why == "right image without a valid right CameraInfo"
    # the same rectified images beside the raw cameras' CameraInfos (ROS's image_rect topics): passed as they are,
    # published with the rectified cameras read from P
    rect_in = IngestCamera(undistort=False, stereo_input="image_rect")
    assert rect_in.camera_info(info_l) == "" and rect_in.right_info(info_r) == ""
    for kind, img in (("image", rect[0]), ("right", rect[1])):
        c = rect_in.check(kind, _msg(img, "mono8"))
        assert c.why == "" and c.pixels is None
    assert np.allclose(rect_in.out_camera.K, K) and not rect_in.out_camera.has_distortion
    assert baseline_from_projection(rect_in.out_right[1]) == pytest.approx(0.1)
    # a depth stream is not rectified with the pair: refused; a CameraInfo gone bad drops the rectification
    depth = np.full((120, 160), 1000, np.uint16)
    assert "is not rectified with it" in ic.check("depth", _msg(depth, "16UC1")).why
    broken = SimpleNamespace(**{**vars(info_r), "p": [float("nan")] * 12})
    assert "NaN" in ic.right_info(broken)
    assert ic.check("image", _msg(raw[0], "mono8")).why.startswith("waiting for both CameraInfos")
    assert ic.right_info(info_r) == "" and ic.check("image", _msg(raw[0], "mono8")).why == ""



def test_a_depth_camera_s_images_are_registered_to_the_colour_camera_in_the_ingest():
    """With ``depth_to_color`` the ingest registers the depth images of their own camera (its CameraInfo) to the
    colour camera, in their own encoding (millimetres with 0 for none, or metres with NaN), and says what it waits
    for: the colour CameraInfo, the depth CameraInfo; a depth image of another size than its CameraInfo is refused."""
    from simreal_nodes import geometry as G
    from simreal_nodes.vision.depth import register_depth
    from tests.vision.test_depth import _scene_depth

    color = CameraModel(160, 120, [[150.0, 0, 80.5], [0, 150.0, 60.2], [0, 0, 1]], [0.04, -0.01, 0, 0, 0])
    depth_cam = CameraModel(160, 120, [[145.0, 0, 79.3], [0, 145.0, 59.1], [0, 0, 1]], [-0.03, 0.01, 0, 0, 0])
    T = G.make_T(G.exp_so3([0.004, -0.006, 0.003]), [-0.025, 0.001, 0.002])
    raw = _scene_depth(depth_cam, T)
    mm = np.where(np.isfinite(raw), np.rint(raw * 1e3), 0).astype(np.uint16)
    ic = IngestCamera(undistort=False, depth_to_color=T)
    assert ic.check("depth", _msg(mm, "16UC1")).why == "waiting for a valid CameraInfo to register the depth image to"
    ic.camera_info(_info(color))
    assert "waiting for the depth camera's CameraInfo" in ic.check("depth", _msg(mm, "16UC1")).why
    bad = _info(depth_cam)
    bad.k = [0.0] * 9
    assert ic.depth_info(bad) != "" and ic.check("depth", _msg(mm, "16UC1")).why.startswith("unusable depth")
    assert ic.depth_info(_info(depth_cam)) == ""
    got = ic.check("depth", _msg(mm, "16UC1"))
    want = register_depth(mm.astype(np.float32) * 1e-3, depth_cam, color, T)
    assert got.why == "" and got.pixels.dtype == np.uint16 and got.pixels.shape == (120, 160)
    np.testing.assert_array_equal(got.pixels, np.where(np.isfinite(want), np.rint(want * 1e3), 0).astype(np.uint16))
    truth = _scene_depth(color, np.eye(4))
    near = (got.pixels > 0) & np.isfinite(truth)
    assert near.mean() > 0.9 and np.median(np.abs(got.pixels[near] * 1e-3 - truth[near])) < 1e-3
    metres = ic.check("depth", _msg(raw, "32FC1"))
    assert metres.pixels.dtype == np.float32 and np.isnan(metres.pixels).any()
    assert "is 160x100 but its CameraInfo says 160x120" in ic.check("depth", _msg(mm[:100], "16UC1")).why
    refused = IngestCamera(undistort=False, depth_refused="depth registration needs a pose")
    refused.camera_info(_info(color))
    assert refused.check("depth", _msg(mm, "16UC1")).why == "depth registration needs a pose"

