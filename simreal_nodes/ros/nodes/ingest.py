"""Camera ingest node: one validated camera stream for the rest of the graph.

Sources: a live topic (default), a bag, a video file or an image folder (scene ``camera.source``).
Publishes ``/simreal/camera/image`` + ``camera_info`` (+ ``depth``, + right image/info for stereo)
with sensor-data QoS. Intrinsics come from CameraInfo or from a calibration YAML (which wins);
images can be undistorted here. A malformed Image or an unusable CameraInfo is dropped with a
reason on /diagnostics; the node keeps going.
"""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import CameraInfoError, ImageFormatError, SimrealError
from simreal_nodes.io import images, sources
from simreal_nodes.ros.common import SimrealNode, data_qos, guarded, ns_to_stamp, run_node
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.vision.undistort import Undistorter


class IngestNode(SimrealNode):
    def __init__(self):
        super().__init__("ingest")
        scene = load_scene(self.scene_file) if self.scene_file else None
        cam = scene["camera"] if scene else {}
        self.source = self.param("source", cam.get("source", "topic"), "topic | bag | video | images")
        self.path = self.param("path", cam.get("path") or "", "bag, video or image folder for non-topic sources")
        self.rate_hz = self.param("rate_hz", float(cam.get("rate_hz", 30.0)), "rate for video / folder sources")
        self.loop = self.param("loop", bool(cam.get("loop", False)), "restart file sources at their end")
        self.undistort = self.param("undistort", bool(cam.get("undistort", False)), "undistort images here")
        calib = self.param("calibration_file", cam.get("calibration") or "", "ROS calibration YAML overriding CameraInfo")
        self.image_topic = self.param("image_topic", cam.get("image", "/camera/image_raw"), "input image topic")
        self.info_topic = self.param("camera_info_topic", cam.get("camera_info", "/camera/camera_info"), "input CameraInfo topic")
        self.depth_topic = self.param("depth_topic", cam.get("depth") or "", "input depth topic ('' = none)")
        self.right_topic = self.param("right_image_topic", cam.get("right_image") or "", "right image topic ('' = mono)")
        self.right_info_topic = self.param("right_camera_info_topic", cam.get("right_camera_info") or "", "right CameraInfo topic")
        self.compressed = self.param("compressed", bool(cam.get("compressed", False)),
                                     "subscribe to <image>/compressed (sensor_msgs/CompressedImage) instead of raw images")

        self.calibration = CameraModel.from_calibration_yaml(calib) if calib else None
        self.cam: CameraModel | None = self.calibration
        self.right_cam: CameraModel | None = None
        self._und: Undistorter | None = None
        self._info_error = ""

        q = data_qos(self.lossless)
        self.pub_img = self.create_publisher(Image, graph.CAM_IMAGE, q)
        self.pub_info = self.create_publisher(CameraInfo, graph.CAM_INFO, q)
        self.pub_depth = self.create_publisher(Image, graph.CAM_DEPTH, q) if self.depth_topic else None
        self.pub_right = self.create_publisher(Image, graph.CAM_RIGHT_IMAGE, q) if self.right_topic else None
        self.pub_right_info = self.create_publisher(CameraInfo, graph.CAM_RIGHT_INFO, q) if self.right_topic else None

        if self.source == "topic":
            sq = data_qos(self.lossless)
            trigger = data_qos(self.lossless, depth=1)  # live: a busy ingest takes the newest image next
            self.create_subscription(CameraInfo, self.info_topic, self.on_info, sq)
            if self.compressed:
                self.create_subscription(CompressedImage, self.image_topic + "/compressed", self.on_compressed, trigger)
            else:
                self.create_subscription(Image, self.image_topic, self.on_image, trigger)
            if self.depth_topic:
                self.create_subscription(Image, self.depth_topic, self.on_depth, sq)
            if self.right_topic:
                self.create_subscription(CameraInfo, self.right_info_topic, self.on_right_info, sq)
                if self.compressed:
                    self.create_subscription(CompressedImage, self.right_topic + "/compressed", self.on_right_compressed, sq)
                else:
                    self.create_subscription(Image, self.right_topic, self.on_right_image, sq)
        else:
            self._frames = self._open_source()
            self._t0 = None
            self.create_timer(1.0 / self.rate_hz, self.on_timer)
        self.set_status("ok", f"ingesting from {self.source}")
        self.get_logger().info(f"camera ingest from {self.source} {self.path or self.image_topic}")

    # ---------------------------------------------------------------------------------------
    def _open_source(self):
        if self.source == "video":
            return sources.video_frames(self.path, self.rate_hz)
        if self.source == "images":
            return sources.folder_frames(self.path, self.rate_hz)
        if self.source == "bag":
            return sources.bag_frames(self.path, self.image_topic, self.info_topic, self.depth_topic or None)
        raise SimrealError(f"unknown source '{self.source}'")

    def _set_camera(self, cam: CameraModel) -> None:
        self.cam = cam
        if self.undistort and cam.has_distortion and (self._und is None or not self._und.matches(cam)):
            self._und = Undistorter(cam)

    def _out_camera(self) -> CameraModel:
        return self._und.ideal if (self.undistort and self._und is not None) else self.cam

    def _info_msg(self, cam: CameraModel, header) -> CameraInfo:
        m = CameraInfo()
        m.header.stamp = header.stamp
        m.header.frame_id = self.camera_frame
        for k, v in cam.camera_info_fields().items():
            setattr(m, k, v)
        return m

    # topic source ---------------------------------------------------------------------------
    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        if self.calibration is not None:
            return
        try:
            cam = CameraModel.from_camera_info(msg)
        except CameraInfoError as e:
            if str(e) != self._info_error:
                self.get_logger().error(f"unusable CameraInfo on {self.info_topic}: {e}")
            self._info_error = str(e)
            self.cam = None
            self.set_status("error", f"unusable CameraInfo: {e}")
            return
        self._info_error = ""
        if self.cam is None or not np.allclose(cam.K, self.cam.K) or cam.width != self.cam.width:
            self._set_camera(cam)

    @guarded
    def on_compressed(self, msg: CompressedImage) -> None:
        try:
            arr, enc = images.decode_compressed(msg)
        except ImageFormatError as e:
            self.metrics.arrived()
            self.drop(msg.header.stamp, f"malformed compressed image: {e}")
            return
        out = Image()
        out.header = msg.header
        images.fill_image_msg(out, arr, enc)
        self.on_image(out, arr)

    @guarded
    def on_right_compressed(self, msg: CompressedImage) -> None:
        try:
            arr, enc = images.decode_compressed(msg)
        except ImageFormatError as e:
            self.metrics.drop(f"malformed right compressed image: {e}")
            return
        out = Image()
        out.header = msg.header
        images.fill_image_msg(out, arr, enc)
        self.on_right_image(out)

    @guarded
    def on_image(self, msg: Image, arr=None) -> None:
        t0 = self.metrics.arrived()
        if self.cam is None:
            why = f"unusable CameraInfo: {self._info_error}" if self._info_error else "waiting for a valid CameraInfo"
            self.drop(msg.header.stamp, why)
            return
        if arr is None:
            try:
                arr = images.image_to_array(msg)
            except ImageFormatError as e:
                self.drop(msg.header.stamp, f"malformed image: {e}")
                return
        if (arr.shape[1], arr.shape[0]) != (self.cam.width, self.cam.height):
            self.drop(msg.header.stamp, f"image is {arr.shape[1]}x{arr.shape[0]} but CameraInfo says "
                                        f"{self.cam.width}x{self.cam.height}")
            return
        self._publish_image(msg, arr)
        self.metrics.done(t0, self.age_ms(msg.header.stamp))
        self.set_status("ok", "ok")
        self.progress(msg.header.stamp)

    def _publish_image(self, msg: Image, arr: np.ndarray) -> None:
        if self.undistort and self._und is not None:
            out = Image()
            out.header = msg.header
            images.fill_image_msg(out, self._und.image(arr), msg.encoding)
            msg = out
        msg.header.frame_id = self.camera_frame
        self.pub_info.publish(self._info_msg(self._out_camera(), msg.header))
        self.pub_img.publish(msg)

    @guarded
    def on_depth(self, msg: Image) -> None:
        if msg.encoding not in images.DEPTH_ENCODINGS:
            self.metrics.drop(f"depth encoding '{msg.encoding}' (expected 16UC1 or 32FC1)")
            return
        try:
            arr = images.image_to_array(msg)
        except ImageFormatError as e:
            self.metrics.drop(f"malformed depth image: {e}")
            return
        if self.undistort and self._und is not None:
            out = Image()
            out.header = msg.header
            images.fill_image_msg(out, self._und.depth(arr), msg.encoding)
            msg = out
        msg.header.frame_id = self.camera_frame
        self.pub_depth.publish(msg)

    @guarded
    def on_right_info(self, msg: CameraInfo) -> None:
        try:
            self.right_cam = CameraModel.from_camera_info(msg)
        except CameraInfoError as e:
            self.right_cam = None
            self.set_status("error", f"unusable right CameraInfo: {e}")

    @guarded
    def on_right_image(self, msg: Image) -> None:
        if self.right_cam is None:
            self.metrics.drop("right image without a valid right CameraInfo")
            return
        try:
            images.image_to_array(msg)
        except ImageFormatError as e:
            self.metrics.drop(f"malformed right image: {e}")
            return
        info = CameraInfo()
        info.header = msg.header
        for k, v in self.right_cam.camera_info_fields().items():
            setattr(info, k, v)
        self.pub_right_info.publish(info)
        self.pub_right.publish(msg)

    # file sources ---------------------------------------------------------------------------
    @guarded
    def on_timer(self) -> None:
        try:
            f = next(self._frames)
        except StopIteration:
            if self.loop:
                self._frames = self._open_source()
                return
            self.set_status("ok", f"source {self.path} finished")
            return
        t0 = self.metrics.arrived()
        stamp = ns_to_stamp(self.get_clock().now().nanoseconds if self.source != "bag" else f.stamp_ns)
        if f.error:
            self.drop(stamp, f.error)
            return
        if f.camera_info is not None and self.calibration is None:
            try:
                self._set_camera(CameraModel.from_camera_info(f.camera_info))
            except CameraInfoError as e:
                self.drop(stamp, f"unusable CameraInfo in bag: {e}")
                return
        if self.cam is None:
            h, w = f.image.shape[:2]
            self.drop(stamp, f"no intrinsics for {w}x{h} frames: give camera.calibration (see `simreal calibrate`)")
            return
        msg = Image()
        msg.header.stamp = stamp
        msg.header.frame_id = self.camera_frame
        img = self._und.image(f.image) if (self.undistort and self._und) else f.image
        images.fill_image_msg(msg, img, f.encoding)
        self.pub_info.publish(self._info_msg(self._out_camera(), msg.header))
        self.pub_img.publish(msg)
        if f.depth is not None and self.pub_depth is not None:
            d = Image()
            d.header = msg.header
            images.fill_image_msg(d, self._und.depth(f.depth) if (self.undistort and self._und) else f.depth,
                                  f.depth_encoding)
            self.pub_depth.publish(d)
        self.metrics.done(t0)
        self.progress(stamp)


def main(args=None):
    return run_node(IngestNode, args)


if __name__ == "__main__":
    main()
