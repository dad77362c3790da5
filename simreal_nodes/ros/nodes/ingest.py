"""Camera ingest node: one validated camera stream for the rest of the graph, from a topic, bag, video or folder.

Source: scene ``camera.source`` (default: a live topic). Publishes ``/simreal/camera/image`` + ``camera_info`` (+
``depth``, + right image/info for stereo) with sensor-data QoS, intrinsics from CameraInfo or a calibration YAML (which
wins), images undistorted if asked. A malformed Image or unusable CameraInfo is dropped with a reason on /diagnostics.
"""

from __future__ import annotations

import functools
import math

from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import ImageFormatError
from simreal_nodes.io import images, sources
from simreal_nodes.ros import convert
from simreal_nodes.ros.convert import camera_info_msg, ns_to_stamp
from simreal_nodes.ros.node import SimrealNode, guarded, run_node
from simreal_nodes.ros.qos import data_qos
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.vision.undistort import STEREO_INPUTS, IngestCamera


class IngestNode(SimrealNode):
    def __init__(self, **kw):
        super().__init__("ingest", **kw)
        cam = load_scene(self.scene_file)["camera"] if self.scene_file else {}
        self.source = self.param("source", cam.get("source", "topic"), "topic | bag | video | images")
        self.path = self.param("path", cam.get("path") or "", "bag, video or image folder for non-topic sources")
        self.rate_hz = self.param("rate_hz", float(cam.get("rate_hz", 30.0)), "rate for video / folder sources")
        self.loop = self.param("loop", bool(cam.get("loop", False)), "restart file sources at their end")
        undistort = self.param("undistort", bool(cam.get("undistort", False)), "undistort images here")
        cal = self.param("calibration_file", cam.get("calibration") or "", "ROS calibration YAML overriding CameraInfo")
        self.image_topic = self.param("image_topic", cam.get("image", "/camera/image_raw"), "input image topic")
        self.info_topic = self.param("camera_info_topic", cam.get("camera_info", "/camera/camera_info"),
                                     "input CameraInfo topic")
        self.depth_topic = self.param("depth_topic", cam.get("depth") or "", "input depth topic ('' = none)")
        right_topic = self.param("right_image_topic", cam.get("right_image") or "", "right image topic ('' = mono)")
        right_info = self.param("right_camera_info_topic", cam.get("right_camera_info") or "", "right CameraInfo topic")
        compressed = self.param("compressed", bool(cam.get("compressed", False)),
                                "subscribe to <image>/compressed (sensor_msgs/CompressedImage) instead of raw images")
        stereo_input = self.param("stereo_input", cam.get("stereo_input", "rectified"),
                                  "rectified | raw | image_rect: what a stereo pair's images and CameraInfos are "
                                  "(raw: rectified here from the CameraInfos' lens, R and P)")
        if stereo_input not in STEREO_INPUTS:
            self.get_logger().error(f"stereo_input '{stereo_input}' is none of {', '.join(STEREO_INPUTS)}: taking the "
                                    "pair as rectified (a raw one is then refused)")
            stereo_input = "rectified"
        depth_info = self.param("depth_camera_info_topic", cam.get("depth_camera_info") or "",
                                "CameraInfo of the depth images' own camera ('' = depth registered to the colour "
                                "image); with depth_to_color the depth is registered here")
        pose_text = self.param("depth_to_color", " ".join(str(float(x)) for x in (cam.get("depth_to_color") or [])),
                               "the depth camera's optical frame in the colour camera's: 'x y z qx qy qz qw' "
                               "(metres, unit quaternion; '' = none)")
        try:
            pose7 = [float(x) for x in str(pose_text).split()]
        except ValueError:
            pose7 = [float("nan")]
        to_color, refused = None, ""
        if depth_info and len(pose7) == 7 and all(map(math.isfinite, pose7)) and math.hypot(*pose7[3:]) > 1e-6:
            to_color = G.pose7_to_matrix(pose7)
        elif depth_info or pose7:
            refused = (f"depth registration needs depth_camera_info_topic and depth_to_color 'x y z qx qy qz qw' "
                       f"(finite, a non-zero quaternion); got '{depth_info}' and '{pose_text}'")
            self.get_logger().error(refused + ": no depth is passed on")
        self.core = IngestCamera(undistort, CameraModel.from_calibration_yaml(cal) if cal else None,
                                 stereo_input=stereo_input, depth_to_color=to_color, depth_refused=refused)
        q = data_qos(self.lossless)
        self.pubs = {"image": self.create_publisher(Image, graph.CAM_IMAGE, q)}
        self.pub_info = {"image": self.create_publisher(CameraInfo, graph.CAM_INFO, q)}
        if self.depth_topic:
            self.pubs["depth"] = self.create_publisher(Image, graph.CAM_DEPTH, q)
        if right_topic:
            self.pubs["right"] = self.create_publisher(Image, graph.CAM_RIGHT_IMAGE, q)
            self.pub_info["right"] = self.create_publisher(CameraInfo, graph.CAM_RIGHT_INFO, q)
        if self.source == "topic":
            trigger = data_qos(self.lossless, depth=1)  # live: a busy ingest takes the newest image next
            self.create_subscription(CameraInfo, self.info_topic, self.on_info, q)
            self._subscribe_image("image", self.image_topic, compressed, trigger)
            if self.depth_topic:
                self._subscribe_image("depth", self.depth_topic, False, q)
                if depth_info:
                    self.create_subscription(CameraInfo, depth_info, self.on_depth_info, q)
            if right_topic:
                self.create_subscription(CameraInfo, right_info, self.on_right_info, q)
                self._subscribe_image("right", right_topic, compressed, q)
        else:
            self._open = functools.partial(sources.open_source, self.source, self.path, self.rate_hz, self.image_topic,
                                           self.info_topic, self.depth_topic or None)
            self._frames = self._open()
            self.create_timer(1.0 / self.rate_hz, self.on_timer)
        self.set_status("ok", f"ingesting from {self.source}")
        self.get_logger().info(f"camera ingest from {self.source} {self.path or self.image_topic}")

    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        before = self.core.info_error
        if why := self.core.camera_info(msg):
            if why != before:
                self.get_logger().error(f"unusable CameraInfo on {self.info_topic}: {why}")
            self.set_status("error", f"unusable CameraInfo: {why}")

    @guarded
    def on_depth_info(self, msg: CameraInfo) -> None:
        before = self.core.depth_error
        if why := self.core.depth_info(msg):
            if why != before:
                self.get_logger().error(f"unusable depth CameraInfo: {why}")
            self.set_status("error", f"unusable depth CameraInfo: {why}")

    @guarded
    def on_right_info(self, msg: CameraInfo) -> None:
        if why := self.core.right_info(msg):
            self.set_status("error", f"unusable right CameraInfo: {why}")

    def _subscribe_image(self, kind: str, topic: str, compressed: bool, qos) -> None:
        """Compressed images come as messages (OpenCV decodes them); raw ones serialized, read and passed on by
        rosbags' CDR code (:meth:`on_serialized`) without rclpy's message conversion either way."""
        if compressed:
            self.create_subscription(CompressedImage, topic + "/compressed", functools.partial(self.on_image, kind),
                                     qos)
        else:
            self.create_subscription(Image, topic, functools.partial(self.on_serialized, kind), qos, raw=True)

    @guarded
    def on_serialized(self, kind: str, raw: bytes) -> None:
        """One serialized image of stream ``kind``: checked and undistorted as :meth:`on_image` does, and published
        serialized (its bytes re-serialized by rosbags with the camera's frame and any new pixels)."""
        t0 = self.metrics.arrived() if kind == "image" else None
        m = convert.read_image_cdr(raw)
        if t0 is not None:
            self.metrics.lap("decode")
        self._pass_on(kind, convert.image_view(m), m, t0)

    @guarded
    def _pass_on(self, kind: str, view: convert.ImageView, m, t0: float | None) -> None:
        """:meth:`on_serialized` once the image is read (a failure here is reported with the frame's stamp)."""
        checked = self.core.check(kind, view)
        if checked.why:
            return self._left_out(kind, view.header.stamp, checked.why)
        if t0 is not None:
            self.metrics.lap("work")
        frame_id = m.header.frame_id if kind == "right" else self.camera_frame
        self._publish(kind, convert.image_cdr(m, frame_id, checked.pixels), view.header.stamp, frame_id, t0)

    @guarded
    def on_image(self, kind: str, msg: Image | CompressedImage) -> None:
        """One image of stream ``kind`` (image, depth, right): checked, undistorted if asked, republished with its
        CameraInfo (the depth without). A colour image left out is a dropped frame, a depth or right one counted."""
        t0 = self.metrics.arrived() if kind == "image" else None
        arr, enc = None, ""  # enc: a decompressed image's encoding (the message has none)
        if isinstance(msg, CompressedImage):
            try:
                arr, enc = images.decode_compressed(msg)
            except ImageFormatError as e:
                what = "right compressed image" if kind == "right" else "compressed image"
                return self._left_out(kind, msg.header.stamp, f"malformed {what}: {e}")
        if t0 is not None:
            self.metrics.lap("decode")
        checked = self.core.check(kind, msg, arr, enc or None)
        if checked.why:
            return self._left_out(kind, msg.header.stamp, checked.why)
        if t0 is not None:
            self.metrics.lap("work")
        frame_id = msg.header.frame_id if kind == "right" else self.camera_frame
        if arr is not None:  # decoded here: published serialized (convert.array_image_cdr), no rclpy message
            out = convert.array_image_cdr(arr if checked.pixels is None else checked.pixels, enc, msg.header.stamp,
                                          frame_id)
            return self._publish(kind, out, msg.header.stamp, frame_id, t0)
        if checked.pixels is not None:
            msg = images.fill_image_msg(Image(header=msg.header), checked.pixels, msg.encoding)
        msg.header.frame_id = frame_id
        self._publish(kind, msg, msg.header.stamp, frame_id, t0)

    def _publish(self, kind: str, msg: Image | bytes, stamp, frame_id: str, t0: float | None) -> None:
        """The image (a message or its serialized bytes) with its CameraInfo (the depth without)."""
        if kind != "depth":
            cam, right_P = self.core.out_right if kind == "right" else (self.core.out_camera, None)
            info = camera_info_msg(cam, stamp, frame_id)
            if right_P is not None:  # the baseline lives in P: passed on (a raw pair's: the rectified right's)
                info.p = [float(x) for x in right_P.ravel()]
            self.pub_info[kind].publish(info)
        self.pubs[kind].publish(msg)
        if t0 is not None:
            self.metrics.lap("encode")
            self.metrics.done(t0, self.age_ms(stamp))
            self.set_status("ok", "ok")
            self.progress(stamp)

    def _left_out(self, kind: str, stamp, why: str) -> None:
        if kind == "image":
            self.drop(stamp, why)
        else:
            self.metrics.drop(why)

    @guarded
    def on_timer(self) -> None:
        """File sources: the next frame, stamped now (a bag's frames keep their stamps)."""
        try:
            f = next(self._frames)
        except StopIteration:
            if self.loop:
                self._frames = self._open()
                return
            self.set_status("ok", f"source {self.path} finished")
            return
        t0 = self.metrics.arrived()
        stamp = ns_to_stamp(self.get_clock().now().nanoseconds if self.source != "bag" else f.stamp_ns)
        if why := self.core.file_frame(f):
            self.drop(stamp, why)
            return
        msg = images.fill_image_msg(Image(), self.core.undistorted("image", f.image), f.encoding)
        msg.header.stamp, msg.header.frame_id = stamp, self.camera_frame
        self.pub_info["image"].publish(camera_info_msg(self.core.out_camera, stamp, self.camera_frame))
        self.pubs["image"].publish(msg)
        if f.depth is not None and "depth" in self.pubs:
            d = self.core.undistorted("depth", f.depth)
            self.pubs["depth"].publish(images.fill_image_msg(Image(header=msg.header), d, f.depth_encoding))
        self.metrics.done(t0)
        self.progress(stamp)


NODE_CLASS = IngestNode  # what the one-process launch (simreal_nodes.ros.compose) builds


def main(args=None):
    return run_node(IngestNode, args)


if __name__ == "__main__":
    main()
