"""The renderer agrees with OpenCV's camera model: dots land where projectPoints puts them, depth of a
plane is exact, colour and depth are pixel-aligned."""

import cv2
import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.render.gl import MAX_HALF_ANGLE_DEG, Mesh, Renderer

CAMS = {
    "pinhole": CameraModel.from_intrinsics(640, 480, 525.0, 520.0, 318.7, 241.2),
    "distorted": CameraModel.from_intrinsics(640, 480, 525.0, 520.0, 318.7, 241.2,
                                             D=[-0.28, 0.09, 0.0012, -0.0007, -0.01]),
    # a fisheye (equidistant, k1..k4) whose image reaches 70 degrees off the axis
    "fisheye": CameraModel(640, 480, [[330.0, 0, 321.3], [0, 328.0, 238.6], [0, 0, 1]],
                           [-0.021, 0.0043, -0.0012, 0.0001], "equidistant"),
}


def opencv_project(cam: CameraModel, P: np.ndarray) -> np.ndarray:
    """OpenCV's own projection of camera-frame points (its fisheye functions for the equidistant lens)."""
    if cam.fisheye:
        uv, _ = cv2.fisheye.projectPoints(P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.D)
    else:
        uv, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), cam.K, cam.cv_dist())
    return uv.reshape(-1, 2)


def disks(points, radius, n=24):
    """Small camera-facing disks (in the xy plane of the world; camera looks along +z)."""
    V, F = [], []
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    for p in points:
        base = len(V)
        V.append(p)
        V.extend(p + radius * np.c_[np.cos(ang), np.sin(ang), np.zeros(n)])
        F.extend([[base, base + 1 + k, base + 1 + (k + 1) % n] for k in range(n)])
    return np.asarray(V), np.asarray(F)


def _polygon_centroid(q: np.ndarray) -> np.ndarray:
    x, y = q[:, 0], q[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    c = x * yn - xn * y
    return np.array([np.sum((x + xn) * c), np.sum((y + yn) * c)]) / (3.0 * np.sum(c))


@pytest.mark.parametrize("name", list(CAMS))
@pytest.mark.parametrize("ssaa", [1, 2])
def test_dots_land_where_project_points_puts_them(name, ssaa):
    cam = CAMS[name]
    rng = np.random.default_rng(3)
    z = rng.uniform(1.5, 3.0, 40)
    gx, gy = np.meshgrid(np.linspace(40, 600, 8), np.linspace(40, 440, 5))
    uv_target = np.c_[gx.ravel(), gy.ravel()] + rng.uniform(-15, 15, (40, 2))
    ideal = cam.undistort_points(uv_target)
    P = np.c_[(ideal[:, 0] - cam.cx) / cam.fx * z, (ideal[:, 1] - cam.cy) / cam.fy * z, z]
    V, F = disks(P, 0.025 if cam.fisheye else 0.008)  # a fisheye's edge shrinks a dot to a pixel or two
    r = Renderer(cam, ssaa=ssaa, background=(0, 0, 0))
    r.add(Mesh("dots", V, F, mode="flat", tint=(1, 1, 1), unlit=True))
    rgb, depth = r.render(np.eye(4))
    r.release()
    gray = rgb[..., 0].astype(np.float64)
    # where OpenCV puts each dot: the centroid of its rim's image (a fisheye squeezes a dot off the axis unevenly,
    # so that the image of its centre is up to a pixel off the image's centroid there)
    uv_cv = np.array([_polygon_centroid(opencv_project(cam, V[k * 25 + 1:(k + 1) * 25])) for k in range(len(P))])
    n, lab = cv2.connectedComponents((gray > 0).astype(np.uint8))
    errs = []
    for k in range(1, n):
        ys, xs = np.nonzero(lab == k)
        w = gray[ys, xs]
        c = np.array([np.sum(xs * w), np.sum(ys * w)]) / w.sum()
        errs.append(np.min(np.linalg.norm(uv_cv - c, axis=1)))
    assert n - 1 == len(P)
    assert max(errs) <= 0.5, f"max dot error {max(errs):.3f} px"
    # depth and colour are pixel-aligned: every lit pixel has its dot's depth
    lit = gray > 250
    assert np.all(depth[lit] > 0)


@pytest.mark.parametrize("name", list(CAMS))
def test_plane_depth_is_exact(name):
    cam = CAMS[name]
    r = Renderer(cam, ssaa=2)
    V = np.array([[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]], float)
    r.add(Mesh("plane", V, np.array([[0, 1, 2], [0, 2, 3]]), pose=G.make_T(G.rot_axis("x", 0.5), [0.2, -0.1, 2.2])))
    _, d = r.render(np.eye(4))
    r.release()
    n = G.rot_axis("x", 0.5) @ [0, 0, 1.0]
    p0 = np.array([0.2, -0.1, 2.2])
    ys, xs = np.mgrid[0:cam.height, 0:cam.width]
    ideal = cam.undistort_points(np.c_[xs.ravel(), ys.ravel()]).reshape(cam.height, cam.width, 2)
    ray = np.dstack([(ideal[..., 0] - cam.cx) / cam.fx, (ideal[..., 1] - cam.cy) / cam.fy, np.ones(xs.shape)])
    with np.errstate(invalid="ignore", divide="ignore"):
        Z = (n @ p0) / (ray @ n)
    # a fisheye's rays reach past the plane's horizon and the far plane (20 m), and past the rays it draws
    reach = np.tan(np.radians(MAX_HALF_ANGLE_DEG)) * np.array([cam.fx, cam.fy])
    on_plane = np.all(np.abs(((ray * Z[..., None] - p0) @ G.rot_axis("x", 0.5))[..., :2]) < 8.5, axis=-1)
    drawn = np.all(np.abs(ideal - [cam.cx, cam.cy]) <= 0.97 * reach, axis=-1)
    hit = (Z > 0) & np.less(Z, 0.9 * r.far) & on_plane & drawn
    assert hit.mean() > 0.7 and (cam.fisheye or hit.all())  # a pinhole's every pixel sees the plane
    assert np.all(d[hit] > 0) and np.all(d[~(Z > 0)] == 0)  # (those past the horizon: NaN or negative Z)
    np.testing.assert_allclose(d[hit], Z[hit], rtol=2e-6)  # float32 precision


def test_occlusion_by_real_depth_is_exact():
    """A virtual plane at 2 m behind real geometry at 1.5 m (left half) is hidden there, shown elsewhere."""
    cam = CAMS["pinhole"]
    r = Renderer(cam, ssaa=1)
    V = np.array([[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]], float)
    r.add(Mesh("virtual", V, np.array([[0, 1, 2], [0, 2, 3]]), tint=(1, 0, 0), unlit=True,
               pose=G.make_T(t=[0, 0, 2.0])))
    real = np.zeros((cam.height, cam.width), np.float32)
    real[:, :320] = 1.5  # closer real surface on the left
    real[:100, 400:] = 2.5  # farther real surface: the virtual one is in front
    real[100:200, 400:] = np.nan  # invalid depth never hides anything
    rgb, _ = r.render(np.eye(4), real_depth=real)
    r.release()
    shown = rgb[..., 0] > 0
    assert not shown[:, :320].any()
    assert shown[:, 320:].all()


def test_a_context_made_ahead_is_the_one_the_next_renderer_takes(monkeypatch):
    """Issue 18: the overlay node makes its GL context at start-up (the driver's loading off its first frame); the
    next renderer takes that one, the one after makes its own; a backend that cannot give a context is refused with
    the reason, as the renderer refuses it."""
    from simreal_nodes.render import gl

    monkeypatch.setattr(gl, "_SPARE", [])
    assert gl.prepare_context() not in ("", "?")
    spare, programs = gl._SPARE[0]
    assert gl.prepare_context()
    assert len(gl._SPARE) == 1 and gl._SPARE[0][0] is spare  # asked again: still the one
    r = Renderer(CAMS["pinhole"])
    assert r.ctx is spare and r.progs is programs and not gl._SPARE
    V, F = disks([np.array([-0.3, 0.0, 2.0])], 0.1)  # a disk on the left for this one
    r.add(Mesh("d", V, F, tint=(1.0, 0.0, 0.0)))
    r2 = Renderer(CAMS["pinhole"])  # made after: its context is the thread's current one now
    assert r2.ctx is not spare
    V, F = disks([np.array([0.3, 0.0, 2.0])], 0.1)  # on the right for the other
    r2.add(Mesh("d", V, F, tint=(1.0, 0.0, 0.0)))
    # each draws into its own context (before stop 97's review, the first drew the last one's scene)
    (_, d1), (_, d2) = r.render(np.eye(4)), r2.render(np.eye(4))
    w = d1.shape[1]
    assert (d1[:, : w // 2] > 0).sum() > 100 and (d1[:, w // 2:] > 0).sum() == 0
    assert (d2[:, w // 2:] > 0).sum() > 100 and (d2[:, : w // 2] > 0).sum() == 0
    r.release()
    r2.release()
    monkeypatch.setenv("SIMREAL_GL_BACKEND", "no-such-backend")
    with pytest.raises(gl.RenderError, match="cannot create an OpenGL context over no-such-backend"):
        gl.prepare_context()
    assert not gl._SPARE


@pytest.mark.parametrize("ssaa", [1, 2])
def test_the_occlusion_lookup_puts_each_render_pixel_where_the_camera_sees_its_ray(ssaa):
    """Issue 18: the render pixel -> camera pixel lookup of the occlusion shader is OpenCV's rectification map (made
    in milliseconds; projecting each ray took 0.1-1 s on the first depth frame): the same pixels as projecting each
    render pixel's ray with the camera's distortion, to float32 precision; rays that land outside the image are -1 (and
    those on an edge pixel's outer half read that pixel: before, x in (-0.5, 0) read as outside, never occluded)."""
    cam = CAMS["distorted"]
    r = Renderer(cam, ssaa=ssaa)
    r._set_real_depth(np.ones((cam.height, cam.width), np.float32))
    rc = r.render_cam
    lookup = np.frombuffer(r._depth_map_tex.read(), np.float32).reshape(rc.height, rc.width, 2)[::-1]
    r.release()
    xs, ys = np.meshgrid(np.arange(rc.width, dtype=np.float64), np.arange(rc.height, dtype=np.float64))
    rays = np.stack([(xs - rc.cx) / rc.fx, (ys - rc.cy) / rc.fy, np.ones_like(xs)], -1).reshape(-1, 3)
    uv = cam.project(rays).reshape(rc.height, rc.width, 2)
    inside = (uv[..., 0] > -0.5) & (uv[..., 0] < cam.width - 0.5) \
        & (uv[..., 1] > -0.5) & (uv[..., 1] < cam.height - 0.5)
    assert inside.mean() > 0.5 and (~inside).any()  # the render's margin reaches past the distorted image
    ok = inside & (lookup[..., 0] >= 0)
    assert ok.sum() >= inside.sum() - 4  # (rays on the very edge may fall either side in float32)
    # (a ray in the outer half of an edge pixel reads that pixel: clipped to it, as the shader reads x < 0 as outside)
    np.testing.assert_allclose(lookup[ok], np.clip(uv, 0, [cam.width - 1, cam.height - 1])[ok], atol=2e-3)
    assert (lookup[~inside & (np.abs(uv[..., 0] - cam.width / 2) > cam.width / 2 + 1)] == -1).all()


def test_a_renderer_released_to_keep_hands_its_context_and_programs_to_the_next(monkeypatch):
    """Issue 18 (the overlay's warm-up): a renderer released with ``keep`` leaves its context and compiled programs to
    the next renderer of the process, its own GL objects freed; the next draws as a renderer of a fresh context
    does."""
    from simreal_nodes.render import gl

    monkeypatch.setattr(gl, "_SPARE", [])
    V, F = disks([np.array([0.1, -0.05, 2.0])], 0.2)
    small = Renderer(CameraModel.from_intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5, D=[-0.1, 0.01, 0, 0, 0]))
    small.add(Mesh("d", V, F, tint=(0.0, 1.0, 0.0)))
    small.render(np.eye(4), real_depth=np.ones((120, 160), np.float32))
    ctx, progs = small.ctx, small.progs
    small.release(keep=True)
    assert len(gl._SPARE) == 1 and gl._SPARE[0] == (ctx, progs) and small.meshes == {}
    r = Renderer(CAMS["distorted"])
    assert r.ctx is ctx and r.progs is progs and not gl._SPARE
    fresh = Renderer(CAMS["distorted"])
    assert fresh.ctx is not ctx
    real = np.full((480, 640), 1.9, np.float32)
    real[:, :345] = 2.5  # the disk (centre near column 345) drawn on its left half
    images = []
    for rend in (r, fresh):
        rend.add(Mesh("d", V, F, tint=(0.0, 1.0, 0.0)))
        images.append(rend.render(np.eye(4), real_depth=real))
        rend.release()
    (rgb1, d1), (rgb2, d2) = images
    assert (rgb1[:, :345, 1] > 0).sum() > 1000 and not (rgb1[:, 347:, 1] > 0).any()  # hidden where it is nearer
    np.testing.assert_array_equal(rgb1, rgb2)
    np.testing.assert_array_equal(d1, d2)


def test_a_renderer_that_fails_to_build_hands_its_context_on(monkeypatch):
    """A renderer whose camera set-up fails leaves the context (and programs) it took to the next renderer, which
    then needs no new one; a distortion map step that is not a power of two up to 32 is refused before any."""
    from simreal_nodes.render import gl

    monkeypatch.setattr(gl, "_SPARE", [])
    gl.prepare_context()
    (spare, programs), = gl._SPARE
    with pytest.raises(ValueError, match="map_step 3"):
        Renderer(CAMS["pinhole"], map_step=3)
    assert len(gl._SPARE) == 1 and gl._SPARE[0] == (spare, programs)

    def broken(self, cam):
        raise RuntimeError("set-up failed")

    with monkeypatch.context() as m:
        m.setattr(Renderer, "_setup_camera", broken)
        with pytest.raises(RuntimeError, match="set-up failed"):
            Renderer(CAMS["pinhole"])
    assert len(gl._SPARE) == 1 and gl._SPARE[0][0] is spare
    r = Renderer(CAMS["pinhole"])
    assert r.ctx is spare and not gl._SPARE
    r.release()
