"""Overlay node (thesis §5.2.5): paints each object's deformation and its |u| or von Mises stress on the video.

Per frame it takes the ingest node's image (and registered depth, for occlusion), the camera pose from the
localization node's FeatureObservations and the latest parameters of every object (tracker and / or collision node),
draws the deformed surfaces with the ROS-free :class:`SceneOverlay` (OpenGL over EGL, per-pixel occlusion in the
shader) and publishes ``/simreal/overlay/image_raw`` (bgr8), an RViz ``MarkerArray`` (TRIANGLE_LIST with vertex
colours, every ``marker_every`` frames) and optionally writes an MP4. The number of modes drawn is chosen per frame so
the truncation error on screen stays below the scene's ``max_error_px`` (reported in diagnostics).
"""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CameraInfo, Image
from simreal_msgs.msg import FeatureObservations, ModelParameters
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from simreal_nodes import geometry as G
from simreal_nodes.aero.streamlines import tubes
from simreal_nodes.errors import ImageFormatError, SimrealError
from simreal_nodes.io import images
from simreal_nodes.io.cdr import marker_array_cdr
from simreal_nodes.io.video import VideoSink
from simreal_nodes.render.aero import FLOW_TUBE_RADIUS_M, FlowOverlay, flow_geometry
from simreal_nodes.render.gl import prepare_context
from simreal_nodes.render.scene import SceneOverlay, overlay_models
from simreal_nodes.ros.convert import observation_pose, stamp_ns
from simreal_nodes.ros.node import SimrealNode, guarded, parse_progress, run_node
from simreal_nodes.ros.qos import LATCHED_QOS, data_qos, reliable_qos
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.sync import StampSync


class OverlayNode(SimrealNode):
    def __init__(self, **kw):
        super().__init__("overlay", **kw)
        self.scene = load_scene(self.scene_file)
        ov, loc = self.scene["overlay"], self.scene["localization"]
        self.static_pose = G.pose7_to_matrix(loc["static_pose"]) if loc["mode"] == "static" else None
        video = self.param("video", ov["video"] or "", "write the overlay to this MP4 ('' = no video)")
        self.video = VideoSink(video, self.param("video_fps", 30.0, "frame rate written in the MP4")) if video else None
        self.marker_every = self.param("marker_every", 10, "publish the RViz MarkerArray every N frames (0 = never)")
        ssaa = self.param("supersampling", 1, "render at N x resolution and average (anti-aliasing)")
        modes = self.param("modes", -1, "fixed number of modes for every object (-1 = scene, 0 = live choice)")
        self.marker_every = self.marker_every if ov["marker"] else 0
        objects = self.scene["objects"]
        self.core = SceneOverlay(objects, overlay_models(objects), modes, ov["occlusion"], ov["colorbar"], ssaa)
        self.param_objects = [o["id"] for o in objects if o["tracking"]["enabled"] or o["collision"]["enabled"]]
        has_depth = self.scene["camera"]["depth"] is not None
        q, trigger = data_qos(self.lossless), data_qos(self.lossless, depth=1)  # trigger live: the newest frame first
        req = ["image"] + (["obs"] if self.static_pose is None else [])
        opt = (["depth"] if has_depth else []) + [f"p:{i}" for i in self.param_objects]
        # optional inputs are waited for until they come; lossless, or until their producer says it dropped
        # the frame; live, or until one newer frame is complete (then drawn with the latest parameters)
        self.sync = StampSync(tuple(req), tuple(opt), wait=10**9 if self.lossless else 1)
        self._producers = {name: [o["id"] for o in objects if o[block]["enabled"]]  # whose parameters each node sends
                           for name, block in (("tracker", "tracking"), ("collision", "collision"))}
        self.pub_image = self.create_publisher(Image, graph.OVERLAY_IMAGE, q if self.lossless else data_qos(False))
        self.pub_markers = self.create_publisher(MarkerArray, graph.OVERLAY_MARKERS, reliable_qos(2))
        cam = self.camera_topics(self.scene["camera"])
        self.create_subscription(CameraInfo, cam["info"], self.on_info, q)
        self.subscribe_image(cam["image"], "image", trigger if self.static_pose is not None else q)
        if has_depth:
            self.subscribe_image(cam["depth"], "depth", q)
        if self.static_pose is None:
            self.create_subscription(FeatureObservations, graph.LOC_OBS, lambda m: self.on_input("obs", m), trigger)
        for oid in self.param_objects:
            self.create_subscription(ModelParameters, graph.params_topic(oid),
                                     lambda m, oid=oid: self.on_input(f"p:{oid}", m), reliable_qos(50))
        # aero scenes: the car's flow (the aero node's markers) drawn over the video, hidden behind its body
        self.flow: FlowOverlay | None = None
        self.flow_geometry: tuple | None = None
        if self.scene["aero"]["enabled"]:
            self.create_subscription(MarkerArray, graph.AERO_FLOW, self.on_flow, LATCHED_QOS)
        if self.lossless:  # live, a frame waits for its parameters until a newer one is complete: no need to
            # hear every node's per-frame report (an executor wake-up each, several per frame)
            self.create_subscription(Header, graph.PROGRESS, self.on_progress, reliable_qos(1000))
        self.frames = 0
        self.set_status("ok", "waiting for images")
        try:  # the GL driver loaded now, not while the first frame waits (its intrinsics come with it)
            renderer = prepare_context()
        except SimrealError as e:  # said here; the first frame reports it again, as a drop with the reason
            self.set_status("error", str(e))
        else:
            try:  # the shaders compiled and the font read now too (live, the frames that come meanwhile are skipped)
                self.core.warm_up()
                self.say(f"overlay renderer: {renderer} (its context made and warmed up at start-up)")
            except Exception as e:  # noqa: BLE001 - an optimisation only: the first frame builds what it needs
                self.get_logger().warning(f"overlay warm-up failed ({type(e).__name__}: {e}); the first frame "
                                          "builds the renderer")

    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        cam = self.camera_model(msg)
        if cam is not None and self.core.set_camera(cam):
            self._drop_flow_layer()  # rebuilt for the new intrinsics at the next frame
            self.get_logger().info(f"overlay renderer: {self.core.comp.renderer.gl_renderer}")

    @guarded
    def on_flow(self, msg: MarkerArray) -> None:
        """A new flow from the aero node: its body and streamlines, drawn from the next frame on (a malformed one is
        refused with the reason; the previous flow stays)."""
        parts = [(m.ns, [[p.x, p.y, p.z] for p in m.points], [[c.r, c.g, c.b, c.a] for c in m.colors], m.scale.x)
                 for m in msg.markers]
        try:
            geometry = flow_geometry(parts)
        except ValueError as e:
            self.set_status("warn", f"aero flow not drawn: {e}")
            return
        self.flow_geometry = geometry
        self._drop_flow_layer()

    def _drop_flow_layer(self) -> None:
        if self.flow is not None:
            self.flow.release()
            self.flow = None

    def _flow_layer(self) -> FlowOverlay | None:
        """The flow's renderer, built at the first frame after a new flow or camera (the camera is known then)."""
        if self.flow is None and self.flow_geometry is not None and self.core.cam is not None:
            body, lines, colors, width, sec = self.flow_geometry
            try:
                V, T, C = tubes(lines, radius=0.5 * width, sides=5, colors=colors)
                self.flow = FlowOverlay(self.core.cam, body, np.arange(len(body)).reshape(-1, 3), V, T, C,
                                        world_scale=width / (2.0 * FLOW_TUBE_RADIUS_M))
                if sec is not None:  # the contour plane (pressure or speed; Fig. 6.10b), drawn with the streamlines
                    self.flow.add_layer("aero_section", sec[0], np.arange(len(sec[0])).reshape(-1, 3), sec[1])
            except (ValueError, SimrealError) as e:
                self.flow_geometry = None  # not tried again on every frame
                self.set_status("warn", f"aero flow not drawn: {e}")
        return self.flow

    def on_progress(self, h: Header) -> None:
        """Lossless: a producer that dropped a frame will not send its parameters: stop waiting for them."""
        name, _, why = parse_progress(h.frame_id)
        if why and name in self._producers:
            for oid in self._producers[name]:
                self.on_input(f"p:{oid}", None, stamp=stamp_ns(h.stamp))

    def on_input(self, key: str, msg, stamp: int | None = None) -> None:
        s = stamp if stamp is not None else stamp_ns(msg.header.stamp)
        if key.startswith("p:") and msg is not None:
            self.core.latest[key[2:]] = (list(msg.names), list(msg.values))
        self.feed(self.sync, key, s, msg, self.process)

    @guarded
    def process(self, frame: dict) -> None:
        head, t0 = frame["image"].header, self.metrics.arrived()
        if self.core.cam is None:
            self.drop(head.stamp, self.no_camera())
            return
        if self.core.comp is None:
            self.get_logger().info(f"overlay renderer: {self.core.build().renderer.gl_renderer}")
        try:
            bgr = images.bgr8_of(frame["image"])
            depth = images.depth_metres_of(frame["depth"]) if frame.get("depth") is not None else None
        except ImageFormatError as e:
            self.drop(head.stamp, f"malformed input: {e}")
            return
        try:
            T_wc = observation_pose(frame["obs"]) if frame.get("obs") is not None else self.static_pose
        except ValueError as e:  # a pose whose quaternion has no rotation
            self.drop(head.stamp, f"malformed observations: {e}")
            return
        params = {oid: (list(m.names), list(m.values)) if (m := frame.get(f"p:{oid}")) is not None else None
                  for oid in self.param_objects}
        self.metrics.lap("decode")
        try:
            out, states, why = self.core.draw(bgr, T_wc, params, depth)
        except (ValueError, SimrealError) as e:  # an image of another size than CameraInfo says
            self.drop(head.stamp, f"cannot draw: {e}")
            return
        flow = self._flow_layer() if T_wc is not None else None
        if flow is not None and T_wc is not None:
            out = flow.draw(out, T_wc)
        self.metrics.lap("work")
        self._publish(out, head, states)
        self.metrics.lap("encode")
        for k, st in states.items():
            self.metrics.extra.update({f"{k}_modes": str(st.modes), f"{k}_error_px": f"{st.error_px:.3f}"})
        self.metrics.done(t0, self.age_ms(head.stamp))
        self.set_status("warn" if why else "ok", why or "ok")
        self.progress(head.stamp)

    def _publish(self, bgr: np.ndarray, head, states: dict) -> None:
        msg = images.fill_image_msg(Image(), bgr, "bgr8")
        msg.header.stamp, msg.header.frame_id = head.stamp, head.frame_id or self.camera_frame
        self.pub_image.publish(msg)
        if self.video is not None:
            try:
                self.video.write(bgr)
            except OSError as e:
                self.set_status("error", str(e))
                self.video = None
        self.frames += 1
        if self.marker_every and states and self.frames % self.marker_every == 1 % self.marker_every \
                and self.pub_markers.get_subscription_count() > 0:  # built only for someone who reads it
            # serialized from the arrays directly: as rclpy message objects a 3 700-vertex mesh took ~110 ms
            self.pub_markers.publish(marker_array_cdr(self.core.markers(), stamp_ns(head.stamp), self.map_frame))

    def close(self) -> None:
        if self.video is not None:
            self.video.close()
            self.say(f"wrote {self.video.frames} frames to {self.video.path}")
        self.core.release()
        if self.flow is not None:
            self.flow.release()


NODE_CLASS = OverlayNode  # what the one-process launch (simreal_nodes.ros.compose) builds


def main(args=None):
    return run_node(OverlayNode, args)


if __name__ == "__main__":
    main()
