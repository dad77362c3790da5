"""Overlay node (thesis §5.2.5): paints each object's deformation and its |u| or von Mises stress on the video.

Per frame it takes the ingest node's image (and registered depth, for occlusion), the camera pose from the
localization node's FeatureObservations, and the latest parameters of every object (tracker and / or
collision node), draws the deformed surfaces with the ROS-free :class:`OverlayCompositor` (OpenGL over EGL,
per-pixel occlusion in the shader), and publishes ``/simreal/overlay/image_raw`` (bgr8), an RViz
``MarkerArray`` (TRIANGLE_LIST with vertex colours, every ``marker_every`` frames) and optionally writes
an MP4. The number of modes drawn is chosen per frame so the truncation error on screen stays below the
scene's ``max_error_px`` (reported in diagnostics).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sensor_msgs.msg import CameraInfo, Image
from simreal_msgs.msg import FeatureObservations, ModelParameters
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from simreal_nodes import geometry as G
from simreal_nodes.errors import ImageFormatError, SimrealError
from simreal_nodes.io import images
from simreal_nodes.io.cdr import TriangleListMarker, marker_array_cdr
from simreal_nodes.render.overlay import ObjectOverlay, OverlayCompositor
from simreal_nodes.ros.common import (SimrealNode, data_qos, guarded, observation_pose, parse_progress, reliable_qos,
                                      run_node, stamp_ns)
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.sync import StampSync
from simreal_nodes.vision.camera import CameraModel


class VideoSink:
    """MP4 writer that opens on the first frame (size known then) and is closed on shutdown."""

    def __init__(self, path: str, fps: float):
        self.path, self.fps = path, fps
        self.writer = None
        self.frames = 0

    def write(self, bgr: np.ndarray) -> None:
        import cv2

        if self.writer is None:
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            self.writer = cv2.VideoWriter(self.path, cv2.VideoWriter_fourcc(*"mp4v"), self.fps,
                                          (bgr.shape[1], bgr.shape[0]))
            if not self.writer.isOpened():
                self.writer = None
                raise OSError(f"cannot open video writer for {self.path}")
        self.writer.write(bgr)
        self.frames += 1

    def close(self) -> None:
        if self.writer is not None:
            self.writer.release()
            self.writer = None


class OverlayNode(SimrealNode):
    def __init__(self):
        super().__init__("overlay")
        self.scene = load_scene(self.scene_file)
        ov = self.scene["overlay"]
        loc = self.scene["localization"]
        self.static_pose = G.pose7_to_matrix(loc["static_pose"]) if loc["mode"] == "static" else None
        video = self.param("video", ov["video"] or "", "write the overlay to this MP4 ('' = no video)")
        self.video = VideoSink(video, self.param("video_fps", 30.0, "frame rate written in the MP4")) if video else None
        self.marker_every = self.param("marker_every", 10, "publish the RViz MarkerArray every N frames (0 = never)")
        self.ssaa = self.param("supersampling", 1, "render at N x resolution and average (anti-aliasing)")
        self.modes_override = self.param("modes", -1, "fixed number of modes for every object (-1 = scene, 0 = live choice)")
        self.occlusion = ov["occlusion"]
        self.colorbar = ov["colorbar"]
        if not ov["marker"]:
            self.marker_every = 0
        self.objects = self.scene["objects"]
        self.models = {}
        for o in self.objects:
            fields = ["displacement"] + (["stress"] if o["overlay"]["field"] == "von_mises" else [])
            self.models[o["id"]] = load_model(o["model"], fields=fields)
        self.param_objects = [o["id"] for o in self.objects if o["tracking"]["enabled"] or o["collision"]["enabled"]]
        self.has_depth = self.scene["camera"]["depth"] is not None
        self.cam: CameraModel | None = None
        self.comp: OverlayCompositor | None = None
        self.latest: dict[str, tuple] = {}
        q = data_qos(self.lossless)
        req = ["image"] + (["obs"] if self.static_pose is None else [])
        opt = (["depth"] if self.has_depth else []) + [f"p:{i}" for i in self.param_objects]
        # optional inputs are waited for until they come; lossless, or until their producer says it dropped
        # the frame; live, or until one newer frame is complete (then drawn with the latest parameters)
        self.sync = StampSync(tuple(req), tuple(opt), wait=10**9 if self.lossless else 1)
        self._producers = {}
        for o in self.objects:
            if o["tracking"]["enabled"]:
                self._producers.setdefault("tracker", []).append(o["id"])
            if o["collision"]["enabled"]:
                self._producers.setdefault("collision", []).append(o["id"])
        self.pub_image = self.create_publisher(Image, graph.OVERLAY_IMAGE, q if self.lossless else data_qos(False))
        self.pub_markers = self.create_publisher(MarkerArray, graph.OVERLAY_MARKERS, reliable_qos(2))
        self.create_subscription(CameraInfo, graph.CAM_INFO, self.on_info, q)
        trigger = data_qos(self.lossless, depth=1)  # live: the newest frame first
        self.create_subscription(Image, graph.CAM_IMAGE, lambda m: self.on_input("image", m),
                                 trigger if self.static_pose is not None else q)
        if self.has_depth:
            self.create_subscription(Image, graph.CAM_DEPTH, lambda m: self.on_input("depth", m), q)
        if self.static_pose is None:
            self.create_subscription(FeatureObservations, graph.LOC_OBS, lambda m: self.on_input("obs", m), trigger)
        for oid in self.param_objects:
            self.create_subscription(ModelParameters, graph.params_topic(oid),
                                     lambda m, oid=oid: self.on_input(f"p:{oid}", m), reliable_qos(50))
        if self.lossless:  # live, a frame waits for its parameters until a newer one is complete: no need to
            # hear every node's per-frame report (an executor wake-up each, several per frame)
            self.create_subscription(Header, graph.PROGRESS, self.on_progress, reliable_qos(1000))
        self.frames = 0
        self.set_status("ok", "waiting for images")

    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        cam = self.camera_model(msg)
        if cam is None:
            return
        if self.cam is None or cam.width != self.cam.width or cam.height != self.cam.height or not np.allclose(cam.K, self.cam.K):
            if self.comp is not None:
                self.comp.release()
            self.cam, self.comp = cam, None  # (None first: a failing build leaves no stale compositor)
            self.comp = self._build()  # now, not on the first frame: that frame would wait for it

    def _build(self) -> OverlayCompositor:
        obs = {}
        for o in self.objects:
            ov = o["overlay"]
            modes = ov["modes"] if self.modes_override < 0 else self.modes_override
            obs[o["id"]] = ObjectOverlay(self.models[o["id"]], G.pose7_to_matrix(o["anchor"]["pose"]), ov["field"],
                                         ov["colormap"], modes, ov["max_error_px"], ov["magnify"], ov["range"])
        comp = OverlayCompositor(self.cam, obs, occlusion=self.occlusion, colorbar=self.colorbar, ssaa=self.ssaa)
        self.get_logger().info(f"overlay renderer: {comp.renderer.gl_renderer}")
        return comp

    def on_progress(self, h: Header) -> None:
        """Lossless: a producer that dropped a frame will not send its parameters: stop waiting for them."""
        name, _, why = parse_progress(h.frame_id)
        if why and name in self._producers:
            for oid in self._producers[name]:
                self.on_input(f"p:{oid}", None, stamp=stamp_ns(h.stamp))

    def on_input(self, key, msg, stamp: int | None = None) -> None:
        s = stamp if stamp is not None else stamp_ns(msg.header.stamp)
        if key.startswith("p:") and msg is not None:
            self.latest[key[2:]] = (list(msg.names), list(msg.values))
        self.feed(self.sync, key, s, msg, self.process)

    @guarded
    def process(self, frame: dict) -> None:
        img_msg = frame["image"]
        head = img_msg.header
        t0 = self.metrics.arrived()
        if self.cam is None:
            self.drop(head.stamp, "waiting for a valid CameraInfo")
            return
        if self.comp is None:
            self.comp = self._build()
        try:
            bgr = images.bgr8_of(img_msg)
            depth = None
            if frame.get("depth") is not None:
                depth = images.depth_metres_of(frame["depth"])
        except ImageFormatError as e:
            self.drop(head.stamp, f"malformed input: {e}")
            return
        T_wc = self.static_pose
        if frame.get("obs") is not None:
            T_wc = observation_pose(frame["obs"])
        if T_wc is None:
            out, why = bgr, "no camera pose: image passed through without overlay"
            states = {}
        else:
            est = {}
            for oid in self.param_objects:
                m = frame.get(f"p:{oid}")
                est[oid] = (list(m.names), list(m.values)) if m is not None else self.latest.get(oid, ([], []))
            notes = []
            if depth is not None and depth.shape != bgr.shape[:2]:
                notes.append(f"depth {depth.shape[1]}x{depth.shape[0]} is not registered to the "
                             f"{bgr.shape[1]}x{bgr.shape[0]} image: drawn without occlusion")
                depth = None
            try:
                out, states = self.comp.compose(bgr, T_wc, est, depth)
            except (ValueError, SimrealError) as e:  # an image of another size than CameraInfo says
                self.drop(head.stamp, f"cannot draw: {e}")
                return
            notes += [f"{k}: behind the camera" for k, s in states.items() if s.behind_camera]
            why = "; ".join(notes)
        self._publish(out, head, states)
        for k, s in states.items():
            self.metrics.extra[f"{k}_modes"] = str(s.modes)
            self.metrics.extra[f"{k}_error_px"] = f"{s.error_px:.3f}"
        self.metrics.done(t0, self.age_ms(head.stamp))
        self.set_status("warn" if why else "ok", why or "ok")
        self.progress(head.stamp)

    def _publish(self, bgr: np.ndarray, head, states) -> None:
        msg = images.fill_image_msg(Image(), bgr, "bgr8")
        msg.header.stamp = head.stamp
        msg.header.frame_id = head.frame_id or self.camera_frame
        self.pub_image.publish(msg)
        if self.video is not None:
            try:
                self.video.write(bgr)
            except OSError as e:
                self.set_status("error", str(e))
                self.video = None
        self.frames += 1
        if self.marker_every and states and self.frames % self.marker_every == 1 % self.marker_every:
            self.pub_markers.publish(self._markers(head.stamp))

    def _markers(self, stamp) -> bytes:
        """The deformed surfaces as a serialized MarkerArray (TRIANGLE_LIST, vertex colours), written from
        the arrays directly: as rclpy message objects a 3 700-vertex mesh took ~110 ms to build."""
        arr = []
        for k, (oid, ob) in enumerate(self.comp.objects.items()):
            V, col = self.comp.last.get(oid, (None, None))
            if V is None:
                continue
            idx = ob.triangles.ravel()
            arr.append(TriangleListMarker(f"simreal/{oid}", k, ob.T, V[idx], col[idx]))
        return marker_array_cdr(arr, stamp_ns(stamp), self.map_frame)

    def close(self) -> None:
        if self.video is not None:
            self.video.close()
            self.say(f"wrote {self.video.frames} frames to {self.video.path}")
        if self.comp is not None:
            self.comp.release()


def main(args=None):
    return run_node(OverlayNode, args)


if __name__ == "__main__":
    main()
