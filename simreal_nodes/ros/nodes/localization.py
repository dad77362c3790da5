"""Camera localization node: fiducial markers, monocular ORB SLAM, RGB-D or stereo (thesis §2.3, §4.4.1, §5.2.3).

Takes the ingest node's image (+ depth for RGB-D, + right image for stereo) and publishes per frame the camera pose
(PoseStamped and TF map -> camera optical frame), the tracking status with a reason, the map points matched in the
image (FeatureObservations, what the deformable tracker measures); the map as PointCloud2 once a second. Service
``~/set_localization_only`` (std_srvs/SetBool) freezes mapping. ``/simreal/localization/deformable_points``
(PointCloud2 in the map frame: x, y, z, id (uint32), drop (uint8); from the tracker after each frame) names the map
points on a deforming object, where the estimate predicts them and which the last fit rejected (tracks to restart).
``/simreal/localization/focus`` (geometry_msgs/PolygonInstanceStamped, image pixels, id = object index; from the
tracker) is where each object projects: a share of the next frames' ORB features (``SlamConfig.focus_share``).
"""

from __future__ import annotations

from geometry_msgs.msg import PolygonInstanceStamped, PoseStamped
from sensor_msgs.msg import CameraInfo, PointCloud2
from simreal_msgs.msg import FeatureObservations, TrackingStatus
from std_msgs.msg import Header
from std_srvs.srv import SetBool
from tf2_msgs.msg import TFMessage

from simreal_nodes.aero.slam_cloud import capture_cloud
from simreal_nodes.assimilation.localizer import LiveLocalizer, Localization, status_text
from simreal_nodes.errors import ImageFormatError
from simreal_nodes.io import images
from simreal_nodes.ros import convert
from simreal_nodes.ros.node import SimrealNode, guarded, run_node
from simreal_nodes.ros.qos import TF_QOS, data_qos, reliable_qos
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.sync import StampSync


class LocalizationNode(SimrealNode):
    def __init__(self, **kw):
        super().__init__("localization", **kw)
        scene = load_scene(self.scene_file) if self.scene_file else {}
        loc = scene.get("localization", {})
        aero = scene.get("aero", {})
        # aero scenes: the cloud the car is captured from (map points + keyframe depth), published with the map
        self.capture = bool(aero.get("enabled", False))
        self.capture_depth = bool(aero.get("keyframe_depth", True))
        self.mode = self.param("mode", loc.get("mode", "mono"), "markers | mono | rgbd | stereo", read_only=True)
        n_features = self.param("features", int(loc.get("features", 1000)), "ORB features per frame", read_only=True)
        scale = self.param("scale_factor", float(loc.get("scale_factor", 1.2)), "ORB pyramid factor", read_only=True)
        levels = self.param("pyramid_levels", int(loc.get("pyramid_levels", 8)), "ORB pyramid levels", read_only=True)
        self.map_file = self.param("map_file", loc.get("map_file") or "", "HDF5 map to load at start")
        self.save_map = self.param("save_map", "", "save the map here on shutdown ('' = no)")
        known_scale = self.param("known_scale_m", float(loc.get("known_scale_m") or 0.0),
                                 "monocular: metric distance between the first two keyframes (0 = unknown)")
        loop = self.param("loop_closing", bool(loc.get("loop_closing", False)),
                          "SLAM: close loops (Sim3, essential graph, global BA)", read_only=True)
        # lossless: the BA in this process, each keyframe's before the next frame (a lock-step replay repeats to the
        # bit; simreal_nodes.ros.commands.replay_parameters); live: in a process of its own, off the tracking's core
        async_mapping = self.param("async_mapping", not self.lossless,
                                   "run local bundle adjustment in a worker process (default: live yes, lossless no)")
        frozen = self.param("localization_only", bool(loc.get("localization_only", False)), "start with mapping frozen")
        section = dict(loc, mode=self.mode, features=n_features, scale_factor=scale, pyramid_levels=levels,
                       known_scale_m=known_scale or None, loop_closing=loop)
        self.live = LiveLocalizer(section, async_mapping, self.map_file, frozen)
        try:  # what the first frame would set up, now (live, frames that come while it waits are skipped)
            self.live.warm_up()
        except Exception as e:  # noqa: BLE001 - an optimisation only: the first CameraInfo builds the localizer
            self.get_logger().warning(f"localizer warm-up failed ({type(e).__name__}: {e})")
        q = data_qos(self.lossless)
        ordered = q if self.lossless else reliable_qos(10)  # poses and observations: each one, in order
        self.pub_pose = self.create_publisher(PoseStamped, graph.POSE, ordered)
        self.pub_tf = self.create_publisher(TFMessage, graph.TF, TF_QOS)
        self.pub_status = self.create_publisher(TrackingStatus, graph.LOC_STATUS, reliable_qos(10))
        self.pub_obs = self.create_publisher(FeatureObservations, graph.LOC_OBS, ordered)
        self.pub_map = self.create_publisher(PointCloud2, graph.LOC_MAP, reliable_qos(1))
        self.pub_capture = (self.create_publisher(PointCloud2, graph.LOC_CAPTURE, reliable_qos(1)) if self.capture
                            else None)
        cam = self.camera_topics(scene.get("camera"))
        self.sync = StampSync(("image",), {"rgbd": ("depth",), "stereo": ("right",)}.get(self.mode, ()), wait=2)
        self.create_subscription(CameraInfo, cam["info"], self.on_info, q)
        depth = self.param("live_queue", 1 if self.mode in ("markers", "static") else 5,
                           "live: images kept while busy (1 = newest first, least latency; SLAM modes default to 5: "
                           "the oldest of the five newest, a few frames of lag for a few more frames tracked; "
                           "benchmarks/results/live_queue.md measures the trade; markers need no continuity)",
                           read_only=True)
        self.subscribe_image(cam["image"], "image", data_qos(self.lossless, depth=max(1, int(depth))))
        if self.mode == "rgbd":
            self.subscribe_image(cam["depth"], "depth", q)
        if self.mode == "stereo":
            self.subscribe_image(cam["right"], "right", q)
            self.create_subscription(CameraInfo, cam["right_info"], self.on_right_info, q)
        self.create_subscription(PointCloud2, graph.LOC_DEFORMABLE, self.on_deformable, reliable_qos(10))
        self.create_subscription(PolygonInstanceStamped, graph.LOC_FOCUS, self.on_focus, reliable_qos(10))
        self.create_service(SetBool, "~/set_localization_only", self.on_set_localization_only)
        self.create_timer(1.0, self.publish_map)
        self._last_status = None
        self._last_stamp = None  # the last processed frame's stamp: the map's clouds carry it (a replay's time)
        self.set_status("ok", f"waiting for images ({self.mode})")
        self.get_logger().info(f"localization mode {self.mode}")

    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        cam = self.camera_model(msg)
        if cam is not None and self.live.set_camera(cam) and self.map_file and (m := self.live.map) is not None:
            self.get_logger().info(f"loaded map {self.map_file}: {len(m.keyframes)} keyframes, {len(m.points)} points")

    @guarded
    def on_right_info(self, msg: CameraInfo) -> None:
        self.live.baseline = self.stereo_baseline(msg, self.live.baseline)

    @guarded
    def process(self, frame: dict) -> None:
        header = frame["image"].header
        t0 = self.metrics.arrived()
        if why := self.live.not_ready():
            self.drop(header.stamp, self.no_camera(why) if self.live.cam is None else why)
            return
        try:
            gray = images.gray8_of(frame["image"])
            depth = images.depth_metres_of(frame["depth"]) if "depth" in frame else None
            right = images.gray8_of(frame["right"]) if "right" in frame else None
            for what, img in (("image", gray), ("depth image", depth), ("right image", right)):
                if self.live.cam is not None and img is not None:
                    self.live.cam.check_size(img, what)
        except ImageFormatError as e:
            self.drop(header.stamp, f"malformed input: {e}")
            return
        ns = convert.stamp_ns(header.stamp)
        self.metrics.lap("decode")
        r = self.live.core.step(gray, ns, depth=depth, right=right, focus=self.live.focus(ns))
        self.metrics.lap("work")
        self._publish(header, r)
        self.metrics.lap("encode")
        self._last_stamp = header.stamp
        self.metrics.done(t0, self.age_ms(header.stamp))
        self.progress(header.stamp)

    def _publish(self, header, r: Localization) -> None:
        if r.T_wc is not None:
            self.pub_pose.publish(convert.pose_stamped(r.T_wc, header, self.map_frame))
            tf = convert.transform_stamped(r.T_wc, header.stamp, self.map_frame, self.camera_frame)
            self.pub_tf.publish(TFMessage(transforms=[tf]))
        self.pub_obs.publish(convert.observations_msg(r, header.stamp, self.camera_frame))
        if r.timings is not None:
            self.metrics.extra = {k: f"{v:.1f}" for k, v in r.timings.items()}
        self.metrics.extra.update(self.live.map_stats())
        self.pub_status.publish(convert.localization_status_msg(r, header.stamp, self.get_name(), self.mode))
        level, text = status_text(r)
        self.set_status(level, text)
        if r.state != self._last_status:
            self.get_logger().info(f"tracking {text}")
            self._last_status = r.state

    def on_set_localization_only(self, req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        self.live.set_localization_only(req.data)
        resp.success, resp.message = True, f"localization-only {'on' if self.live.localization_only else 'off'}"
        self.get_logger().info(resp.message)
        return resp

    @guarded
    def on_deformable(self, msg: PointCloud2) -> None:
        try:
            ids, P, flags = convert.deformable_points(msg)
        except ValueError as e:
            self.get_logger().warning(f"ignored malformed deformable points: {e}")
            return
        self.live.feedback(ids, P, flags)

    @guarded
    def on_focus(self, msg: PolygonInstanceStamped) -> None:
        try:
            index, poly = convert.focus_polygon(msg)
        except ValueError as e:
            self.get_logger().warning(f"ignored malformed focus polygon: {e}", throttle_duration_sec=1.0)
            return
        self.live.set_focus(index, convert.stamp_ns(msg.header.stamp), poly)

    @guarded
    def publish_map(self) -> None:
        # each cloud is built only for someone who reads it (RViz, a recorder, the aero node for the capture)
        want_map = self.pub_map.get_subscription_count() > 0
        want_capture = self.pub_capture is not None and self.pub_capture.get_subscription_count() > 0
        P = self.live.map_points() if want_map or want_capture else None
        if P is None:
            return
        head = Header(stamp=self._last_stamp if self._last_stamp is not None else self.get_clock().now().to_msg())
        if want_map:
            self.pub_map.publish(convert.cloud_msg(P, head, self.map_frame))
        if want_capture and self.pub_capture is not None and self.live.map is not None and self.live.cam is not None:
            cloud = capture_cloud(self.live.map, self.live.cam, keyframe_depth=self.capture_depth)
            self.pub_capture.publish(convert.cloud_msg(cloud, head, self.map_frame))

    def close(self) -> None:
        if self.live.close(self.save_map):
            self.say(f"saved map to {self.save_map}")


NODE_CLASS = LocalizationNode  # what the one-process launch (simreal_nodes.ros.compose) builds


def main(args=None):
    return run_node(LocalizationNode, args)


if __name__ == "__main__":
    main()
