"""`simreal make-bag SCENE -o BAG`: render a seed scene into a ROS 2 bag with ground truth.

Topics: /camera/image_raw (rgb8), /camera/camera_info, /camera/depth/image_raw (16UC1 mm) or
/camera/right/image_raw + /camera/right/camera_info (rectified stereo), and, never read by the
estimators, /ground_truth/camera_pose (PoseStamped, map frame), /ground_truth/objects/<id>/parameters
(ModelParameters), /ground_truth/objects/<id>/contact (ContactState), /ground_truth/objects/<id>/pose.
Deterministic: same command, same pixels (seeded noise; single-threaded software rendering).
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import yaml

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import SimrealError
from simreal_nodes.io import bags
from simreal_nodes.render.gl import Renderer
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.states import EstimateState
from simreal_nodes.synth import world as W
from simreal_nodes.synth.scenes import SCENES, SynthScene

EPOCH_S = 1_700_000_000  # stamps start here (fixed: bags are reproducible)
GT = "/ground_truth"


class MsgFactory:
    """rosbags message objects for the bag (no rclpy needed)."""

    def __init__(self):
        self.ts = bags.typestore()
        t = self.ts.types
        self.Time, self.Header = t["builtin_interfaces/msg/Time"], t["std_msgs/msg/Header"]
        self.Image, self.Info = t["sensor_msgs/msg/Image"], t["sensor_msgs/msg/CameraInfo"]
        self.RoI = t["sensor_msgs/msg/RegionOfInterest"]
        self.PoseStamped, self.Pose = t["geometry_msgs/msg/PoseStamped"], t["geometry_msgs/msg/Pose"]
        self.Point, self.Quat = t["geometry_msgs/msg/Point"], t["geometry_msgs/msg/Quaternion"]
        self.Params, self.Contact = t["simreal_msgs/msg/ModelParameters"], t["simreal_msgs/msg/ContactState"]
        self.Compressed = t["sensor_msgs/msg/CompressedImage"]

    def compressed(self, ns, frame, rgb, fmt: str, quality: int = 90):
        """sensor_msgs/CompressedImage as image_transport's compressed plugin writes it."""
        import cv2

        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        if fmt == "jpeg":
            _ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        else:
            _ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 6])
        return self.Compressed(header=self.header(ns, frame), format=f"rgb8; {fmt} compressed bgr8",
                               data=np.frombuffer(buf.tobytes(), np.uint8))

    def header(self, ns: int, frame: str):
        return self.Header(stamp=self.Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)

    def image(self, ns, frame, arr, encoding):
        a = np.ascontiguousarray(arr)
        h, w = a.shape[:2]
        raw = a.view(np.uint8).reshape(-1)
        return self.Image(header=self.header(ns, frame), height=h, width=w, encoding=encoding, is_bigendian=0,
                          step=raw.size // h, data=raw)

    def camera_info(self, ns, frame, cam, P=None, R=None):
        f = cam.camera_info_fields()
        p = np.asarray(P if P is not None else f["p"], dtype=np.float64)
        r = np.asarray(R if R is not None else f["r"], dtype=np.float64).ravel()
        return self.Info(header=self.header(ns, frame), height=cam.height, width=cam.width,
                         distortion_model=f["distortion_model"], d=np.asarray(f["d"], np.float64),
                         k=np.asarray(f["k"], np.float64), r=r, p=p,
                         binning_x=0, binning_y=0,
                         roi=self.RoI(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))

    def pose(self, T):
        q = G.matrix_to_quat(T[:3, :3])
        return self.Pose(position=self.Point(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                         orientation=self.Quat(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))

    def pose_stamped(self, ns, frame, T):
        return self.PoseStamped(header=self.header(ns, frame), pose=self.pose(T))

    def params(self, ns, oid, names, units, values):
        n = len(values)
        return self.Params(header=self.header(ns, oid), object_id=oid, model_id="ground_truth", names=list(names),
                           units=list(units), values=np.asarray(values, np.float64), frozen=np.zeros(n, bool),
                           covariance=np.zeros(n * n), residual_rms_px=0.0, inliers=0, measurements=0, iterations=0,
                           state=int(EstimateState.OK), reason="ground truth")

    def contact(self, ns, oid, st, frame="map"):
        cp = st.contact_point
        return self.Contact(header=self.header(ns, frame), object_id=oid, state=int(st.state),
                            in_contact=bool(st.in_contact),
                            contact_node=int(st.node), load_point=int(st.load_point), pseudo_time=float(st.pseudo_time),
                            min_distance=float(st.min_distance),
                            contact_point=self.Point(x=float(cp[0]), y=float(cp[1]), z=float(cp[2])),
                            source="ground_truth", points_used=int(st.points_used), reason=st.reason)


def make_scene(name: str, width: int = 640, height: int = 480, duration: float | None = None,
               fps: float = 30.0) -> SynthScene:
    # one scene of the family (synth.family; "family-plate-N": a plate's; "family-boot-N": the joint boot's,
    # synth.boot_family). "-preloaded": the load is on from the first frame; "-stereo": a stereo pair instead of
    # RGB-D; "-d2.5", "-el60", "-az45", "-arc20": the camera's distance (m), elevation, azimuth and arc (deg) changed
    num = r"(\d+(?:\.\d+)?)"
    family = re.fullmatch(rf"family[-_](plate[-_])?(\d+)(-preloaded)?(-stereo)?(?:-d{num})?(?:-el{num})?"
                          rf"(?:-az(-?\d+(?:\.\d+)?))?(?:-arc{num})?", name)
    boot = re.fullmatch(r"family[-_]boot[-_](\d+)", name)
    if boot:  # the joint boot in a drawn set-up (synth.boot_family)
        from simreal_nodes.synth.boot_family import boot_family_scene
        return boot_family_scene(int(boot[1]), width, height, fps=fps, duration=duration)
    if family:
        from simreal_nodes.synth.family import T_FREE, family_scene
        keys = ("distance", "elevation_deg", "azimuth_deg", "arc_deg")
        view = {k: float(v) for k, v in zip(keys, family.groups()[4:]) if v is not None}
        return family_scene(int(family[2]), width, height, fps=fps, duration=duration,
                            t_free=0.0 if family[3] else T_FREE, sensor="stereo" if family[4] else "rgbd", view=view,
                            object="plate" if family[1] else "beam")
    car = re.fullmatch(r"car_aero(-mono)?", name)
    if car:  # a held-out car of the aero database (its CFD is the flow's truth), circled once (thesis ch. 6)
        from simreal_nodes.synth.car_video import car_aero_scene
        return car_aero_scene("mono" if car[1] else "rgbd", width, height, fps=fps, duration=duration)
    if name not in SCENES:
        raise SimrealError(f"unknown scene '{name}' (known: {', '.join(SCENES)})")
    kw = {"width": width, "height": height, "fps": fps}
    if duration:
        kw["duration"] = duration
    return SCENES[name](**kw)


def render_frame(scene: SynthScene, r: Renderer, t: float, T: np.ndarray,
                 T_offset: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Colour and depth at time t from camera pose T; with ``scene.blur_subframes`` > 1 the colour is the mean of
    renders along the camera's path over half a frame period (motion blur of a 1/(2 fps) exposure). ``T_offset``:
    a camera rigidly mounted on the moving one (a stereo pair's right camera, in the left camera's frame); ``T`` is
    then the left camera's pose, and the right camera blurs along its own path."""
    off = np.eye(4) if T_offset is None else T_offset
    rgb, depth = r.render(T @ off)
    n = scene.blur_subframes
    if n > 1:
        acc = rgb.astype(np.float32)
        for k in range(1, n):
            acc += r.render(scene.camera_pose(t + 0.5 * k / (n * scene.fps)) @ off)[0]
        rgb = np.clip(acc / n + 0.5, 0, 255).astype(np.uint8)
    return rgb, depth


def load_models(scene: SynthScene, progress=None) -> dict:
    return {oid: load_model(cached_model(spec, progress)) for oid, spec in scene.models.items()}


FISHEYE_D = (-0.021, 0.0043, -0.0012, 0.0001)  # k1..k4 of fisheye_camera's equidistant lens
FISHEYE_CORNER_DEG = 70.0  # how far off the axis its image corners look


def fisheye_camera(cam: CameraModel) -> CameraModel:
    """An equidistant (fisheye) camera of ``cam``'s size and principal point, its focal length such that the image's
    corners look ``FISHEYE_CORNER_DEG`` off the axis (about 330 px at 640 x 480; the scene's 525 px pinhole sees 37
    degrees there), its lens ``FISHEYE_D``."""
    th = np.radians(FISHEYE_CORNER_DEG)
    k = np.asarray(FISHEYE_D)
    theta_d = th * (1 + k[0] * th ** 2 + k[1] * th ** 4 + k[2] * th ** 6 + k[3] * th ** 8)
    r = np.hypot(max(cam.cx, cam.width - 1 - cam.cx), max(cam.cy, cam.height - 1 - cam.cy))
    f = float(r / theta_d)
    K = np.array([[f, 0.0, cam.cx], [0.0, f, cam.cy], [0.0, 0.0, 1.0]])
    return CameraModel(cam.width, cam.height, K, np.array(FISHEYE_D), "equidistant", cam.frame_id)


RAW_STEREO = (  # a stereo driver's raw pair about the rectified one: focal scale, principal point shift (px at
    # 640 x 480, scaled with the image), plumb_bob k1 k2 p1 p2 k3, and the raw camera's turn off the rectified frame
    (0.96, (2.5, -3.0), (-0.20, 0.05, 0.001, -0.001, 0.0), (0.02, -0.015, 0.01)),
    (0.97, (-4.0, 3.5), (-0.18, 0.04, -0.001, 0.0005, 0.0), (-0.01, 0.02, -0.012)),
)


class RawStereo:
    """A rectified stereo render published as a driver's raw pair (``make-bag --lens raw``): each camera its own
    lens (:data:`RAW_STEREO`) and turn R off the rectified frame, its CameraInfo K, D, R and P (P the rectified
    camera: ``cam``'s K, the right's P[0, 3] = -fx * baseline), each raw pixel reading the rectified pixel its ray
    lands on (``cv2.undistortPoints`` with R and P, computed once)."""

    def __init__(self, cam: CameraModel, baseline: float) -> None:
        import cv2

        s = cam.width / 640.0
        ys, xs = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
        pts = np.c_[xs.ravel(), ys.ravel()].reshape(-1, 1, 2)
        self.cams, self.R, self.P, self.maps = [], [], [], []
        for (scale, (dx, dy), D, rvec), tx in zip(RAW_STEREO, (0.0, -cam.fx * baseline)):
            K = cam.K.copy()
            K[0, 0] *= scale
            K[1, 1] *= scale
            K[0, 2] += dx * s
            K[1, 2] += dy * s
            R = cv2.Rodrigues(np.array(rvec))[0]
            P = np.c_[cam.K, [tx, 0.0, 0.0]]
            m = cv2.undistortPoints(pts, K, np.array(D), R=R, P=cam.K).reshape(cam.height, cam.width, 2)
            self.cams.append(CameraModel(cam.width, cam.height, K, np.array(D), "plumb_bob", cam.frame_id))
            self.R.append(R)
            self.P.append(P)
            self.maps.append(m.astype(np.float32))

    def image(self, i: int, rect: np.ndarray) -> np.ndarray:
        """Camera ``i``'s (0 left, 1 right) raw image of its rectified one (black where it sees past it)."""
        import cv2

        m = self.maps[i]
        return cv2.remap(rect, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


def make_bag(name: str, out: str | Path, width: int = 640, height: int = 480, duration: float | None = None,
             fps: float = 30.0, storage: str = "mcap", seed: int = 0, scene_out: str | Path | None = None,
             ssaa: int = 2, progress=None, compress: bool = True, image_format: str = "raw",
             jpeg_quality: int = 90, lens: str | Callable[[CameraModel], CameraModel] = "scene") -> dict:
    """Render the scene into a bag; returns a summary (frames, seconds, bytes). ``lens``: ``scene`` (the scene's
    own camera), ``fisheye`` (:func:`fisheye_camera`: the frames rendered through an equidistant lens), ``raw`` (a
    stereo scene's pair published as a driver's raw images: :class:`RawStereo`; its scene file says
    ``camera.stereo_input: raw``), or a function of the scene's camera giving the one to render through (a
    benchmark's control camera)."""
    scene = make_scene(name, width, height, duration, fps)
    raw_stereo = lens == "raw"
    if raw_stereo and not scene.stereo_baseline:
        raise SimrealError(f"--lens raw: '{name}' is not a stereo scene (a raw pair is a stereo driver's)")
    if lens not in ("scene", "raw"):
        if not callable(lens) and lens != "fisheye":
            raise SimrealError(f"lens '{lens}': 'scene', 'fisheye' or 'raw'")
        if scene.stereo_baseline:
            raise SimrealError(f"--lens {lens}: '{name}' is a rectified stereo pair (no lens distortion left)")
        scene.camera = (fisheye_camera if lens == "fisheye" else lens)(scene.camera)  # type: ignore[operator]
    models = load_models(scene, progress)
    scene.state["models"] = models
    if "prepare" in scene.state:
        scene.state["progress"] = progress  # a full-order truth solved in prepare reports through it
        scene.state["prepare"](scene, models)
    cam = scene.camera
    r = Renderer(cam, ssaa=ssaa, **scene.render_kw)
    scene.build(scene, r, models)
    if scene.stereo_baseline:
        # rectified stereo: the right camera shares K, no distortion on either after rectification
        rect = CameraModel(cam.width, cam.height, cam.K.copy(), np.zeros(5), "plumb_bob")
        scene.camera = cam = rect
        r.release()
        r = Renderer(cam, ssaa=ssaa)
        scene.build(scene, r, models)
    raw = RawStereo(cam, scene.stereo_baseline) if raw_stereo and scene.stereo_baseline else None
    rng = np.random.default_rng(seed)
    fac = MsgFactory()
    frame = "camera_optical_frame"
    n = round(scene.duration * scene.fps)
    t0 = time.perf_counter()
    out = Path(out)
    T_map_world = scene.T_map_world()
    from rosbags.rosbag2 import CompressionFormat, CompressionMode

    writer = bags.BagWriter(out, storage)
    if compress and storage == "mcap":
        writer._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer as w:
        for i in range(n):
            t = i / scene.fps
            ns = EPOCH_S * 10**9 + round(t * 1e9)
            truth = scene.update(scene, r, t)
            T = scene.camera_pose(t)
            rgb, depth = render_frame(scene, r, t, T)
            rgb = W.pixel_noise(rgb, scene.pixel_sigma, rng)
            if raw is not None:
                rgb = raw.image(0, rgb)
                w.write("/camera/camera_info", ns, fac.camera_info(ns, frame, raw.cams[0], raw.P[0].ravel(), raw.R[0]),
                        "sensor_msgs/msg/CameraInfo")
            else:
                w.write("/camera/camera_info", ns, fac.camera_info(ns, frame, cam), "sensor_msgs/msg/CameraInfo")
            if image_format == "raw":
                w.write("/camera/image_raw", ns, fac.image(ns, frame, rgb, "rgb8"), "sensor_msgs/msg/Image")
            else:
                w.write("/camera/image_raw/compressed", ns, fac.compressed(ns, frame, rgb, image_format, jpeg_quality),
                        "sensor_msgs/msg/CompressedImage")
            if scene.depth:
                d = W.kinect_depth(depth, rng, max_range=scene.depth_range_m) if scene.depth_noise else depth
                w.write("/camera/depth/image_raw", ns, fac.image(ns, frame, W.depth_to_16uc1(d), "16UC1"),
                        "sensor_msgs/msg/Image")
            if scene.stereo_baseline:
                b = scene.stereo_baseline
                rgb_r, _ = render_frame(scene, r, t, T, G.make_T(t=[b, 0, 0]))
                rgb_r = W.pixel_noise(rgb_r, scene.pixel_sigma, rng)
                P = np.zeros((3, 4))
                P[:, :3] = cam.K
                P[0, 3] = -cam.fx * b
                if raw is not None:
                    rgb_r = raw.image(1, rgb_r)
                    info_r = fac.camera_info(ns, "camera_right_optical_frame", raw.cams[1], raw.P[1].ravel(), raw.R[1])
                else:
                    info_r = fac.camera_info(ns, "camera_right_optical_frame", cam, P.ravel())
                w.write("/camera/right/camera_info", ns, info_r, "sensor_msgs/msg/CameraInfo")
                if image_format == "raw":
                    w.write("/camera/right/image_raw", ns, fac.image(ns, "camera_right_optical_frame", rgb_r, "rgb8"),
                            "sensor_msgs/msg/Image")
                else:
                    w.write("/camera/right/image_raw/compressed", ns,
                            fac.compressed(ns, "camera_right_optical_frame", rgb_r, image_format, jpeg_quality),
                            "sensor_msgs/msg/CompressedImage")
            w.write(f"{GT}/camera_pose", ns, fac.pose_stamped(ns, "map", T_map_world @ T),
                    "geometry_msgs/msg/PoseStamped")
            for oid, (names, units, vals) in truth.params.items():
                w.write(f"{GT}/objects/{oid}/parameters", ns, fac.params(ns, oid, names, units, vals),
                        "simreal_msgs/msg/ModelParameters")
            for oid, st in truth.contacts.items():
                w.write(f"{GT}/objects/{oid}/contact", ns, fac.contact(ns, oid, st), "simreal_msgs/msg/ContactState")
            for oid, Tp in truth.object_poses.items():
                w.write(f"{GT}/objects/{oid}/pose", ns, fac.pose_stamped(ns, "map", Tp),
                        "geometry_msgs/msg/PoseStamped")
            if progress:
                progress("render", i + 1, n, f"t = {t:.2f} s")
    r.release()
    if scene_out:
        doc = scene.scene_yaml(scene)
        if image_format != "raw":
            doc["camera"]["compressed"] = True
        if raw is not None:
            doc["camera"]["stereo_input"] = "raw"
        Path(scene_out).parent.mkdir(parents=True, exist_ok=True)
        Path(scene_out).write_text(f"# Generated by `simreal make-bag {name}` together with its bag.\n"
                                   + yaml.safe_dump(doc, sort_keys=False, width=120))
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    return {"scene": name, "frames": n, "seconds": time.perf_counter() - t0, "bytes": size, "path": str(out),
            "resolution": f"{cam.width}x{cam.height}"}


def depth_aside_bag(src: str | Path, out: str | Path, T_color_depth: np.ndarray) -> None:
    """An RGB-D bag ``src`` written to ``out`` with its registered depth re-made as a depth camera of its own at
    ``T_color_depth`` (its optical frame in the colour camera's) sees it, as a RealSense without align_depth
    publishes it: the camera's K 580/640 of the image width in pixels, its principal point a few pixels off and a
    mild barrel lens, its CameraInfo on /camera/depth/camera_info (``camera.depth_camera_info``), each depth image
    the colour depth registered to it (:func:`~simreal_nodes.vision.depth.register_depth`, so pixels the colour
    camera did not see stay empty); every other message copied."""
    from simreal_nodes.io.images import image_to_array
    from simreal_nodes.vision.depth import register_depth

    fac = MsgFactory()
    color = depth_cam = None
    with bags.BagWriter(out, "mcap") as w:
        for m in bags.read_bag(src):
            msg = bags.decode(m)
            if m.topic == "/camera/camera_info":
                color = CameraModel.from_camera_info(msg)
                s = color.width / 640
                K = np.array([[580.0 * s, 0, color.cx - 3.1 * s], [0, 580.0 * s, color.cy + 2.2 * s], [0, 0, 1]])
                depth_cam = CameraModel(color.width, color.height, K, np.array([-0.04, 0.01, 0.0, 0.0, 0.0]))
                w.write("/camera/depth/camera_info", m.log_time_ns,
                        fac.camera_info(m.log_time_ns, "camera_depth_optical_frame", depth_cam),
                        "sensor_msgs/msg/CameraInfo")
            if m.topic == "/camera/depth/image_raw":
                assert color is not None and depth_cam is not None  # the bag's CameraInfo comes first
                z = image_to_array(msg).astype(np.float32) * 1e-3
                z[z == 0] = np.nan
                zd = register_depth(z, color, depth_cam, G.inv(T_color_depth))
                mm = np.where(np.isfinite(zd), np.rint(zd * 1e3), 0).astype(np.uint16)
                w.write(m.topic, m.log_time_ns, fac.image(m.log_time_ns, "camera_depth_optical_frame", mm, "16UC1"),
                        "sensor_msgs/msg/Image")
                continue
            w.write_raw(m.topic, m.log_time_ns, m.raw, m.msgtype)
