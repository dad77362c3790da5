"""Camera localization node: fiducial markers, monocular ORB SLAM, RGB-D or stereo (thesis §2.3, §4.4.1, §5.2.3).

Subscribes the ingest node's image (+ depth for RGB-D, + right image for stereo) and publishes for
every frame: the camera pose (PoseStamped and TF map -> camera optical frame), the tracking status
with a reason, and the map points matched in the image (FeatureObservations, what the deformable
tracker measures); the map as PointCloud2 once a second. Service ``~/set_localization_only``
(std_srvs/SetBool) freezes mapping; topic ``/simreal/localization/deformable_points`` (PointCloud2 in the
map frame with fields x, y, z, id (uint32), drop (uint8), from the tracker after each frame) names the map
points that lie on a deforming object, where the current estimate predicts them, and which of them the
last fit rejected (their image tracks are dropped and re-acquired).
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from simreal_msgs.msg import FeatureObservations, TrackingStatus
from std_srvs.srv import SetBool
from tf2_msgs.msg import TFMessage

from simreal_nodes import geometry as G
from simreal_nodes.errors import ImageFormatError
from simreal_nodes.io import images
from simreal_nodes.ros.common import (TF_QOS, SimrealNode, cloud_field, cloud_msg, cloud_to_array, data_qos, guarded, matrix_to_pose,
                                      pose_stamped, reliable_qos, run_node, stamp_ns, transform_stamped)
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.states import TrackingState
from simreal_nodes.sync import StampSync
from simreal_nodes.vision.camera import CameraModel



class LocalizationNode(SimrealNode):
    def __init__(self):
        super().__init__("localization")
        scene = load_scene(self.scene_file) if self.scene_file else None
        loc = scene["localization"] if scene else {}
        self.mode = self.param("mode", loc.get("mode", "mono"), "markers | mono | rgbd | stereo", read_only=True)
        self.n_features = self.param("features", int(loc.get("features", 1000)), "ORB features per frame", read_only=True)
        self.scale_factor = self.param("scale_factor", float(loc.get("scale_factor", 1.2)), "ORB pyramid factor", read_only=True)
        self.levels = self.param("pyramid_levels", int(loc.get("pyramid_levels", 8)), "ORB pyramid levels", read_only=True)
        self.map_file = self.param("map_file", loc.get("map_file") or "", "HDF5 map to load at start")
        self.save_map = self.param("save_map", "", "save the map here on shutdown ('' = no)")
        self.known_scale = self.param("known_scale_m", float(loc.get("known_scale_m") or 0.0),
                                      "monocular: metric distance between the first two keyframes (0 = unknown)")
        self.async_mapping = self.param("async_mapping", True, "run local bundle adjustment in a worker process")
        loc_only = self.param("localization_only", bool(loc.get("localization_only", False)), "start with mapping frozen")
        self.cam: CameraModel | None = None
        self.right_baseline: float | None = None
        self.core = None
        self.markers_cfg = loc.get("markers") if loc else None
        self._loc_only = loc_only
        q = data_qos(self.lossless)
        self.pub_pose = self.create_publisher(PoseStamped, graph.POSE, q if self.lossless else reliable_qos(10))
        self.pub_tf = self.create_publisher(TFMessage, graph.TF, TF_QOS)
        self.pub_status = self.create_publisher(TrackingStatus, graph.LOC_STATUS, reliable_qos(10))
        self.pub_obs = self.create_publisher(FeatureObservations, graph.LOC_OBS, q if self.lossless else reliable_qos(10))
        self.pub_map = self.create_publisher(PointCloud2, graph.LOC_MAP, reliable_qos(1))
        keys_opt = ()
        if self.mode == "rgbd":
            keys_opt = ("depth",)
        elif self.mode == "stereo":
            keys_opt = ("right",)
        self.sync = StampSync(("image",), keys_opt, wait=2)
        self.create_subscription(CameraInfo, graph.CAM_INFO, self.on_info, q)
        # live, which frames a busy node takes: 1 = always the newest (least latency); more = the oldest of that
        # many newest (a few frames of lag, but after a slow frame the next one is not far away: frame-to-frame
        # SLAM tracking keeps its features). Markers need no continuity.
        depth = self.param("live_queue", 1 if self.mode in ("markers", "static") else 5,
                           "live: images kept while busy (1 = newest first; SLAM modes default to 5: smaller gaps "
                           "between the frames tracked, a few frames of lag)", read_only=True)
        self.create_subscription(Image, graph.CAM_IMAGE, lambda m: self.on_input("image", m),
                                 data_qos(self.lossless, depth=max(1, int(depth))))
        if self.mode == "rgbd":
            self.create_subscription(Image, graph.CAM_DEPTH, lambda m: self.on_input("depth", m), q)
        if self.mode == "stereo":
            self.create_subscription(Image, graph.CAM_RIGHT_IMAGE, lambda m: self.on_input("right", m), q)
            self.create_subscription(CameraInfo, graph.CAM_RIGHT_INFO, self.on_right_info, q)
        self.create_subscription(PointCloud2, graph.LOC_DEFORMABLE, self.on_deformable, reliable_qos(10))
        self.create_service(SetBool, "~/set_localization_only", self.on_set_localization_only)
        self.create_timer(1.0, self.publish_map)
        self._last_status = None
        self.set_status("ok", f"waiting for images ({self.mode})")
        self.get_logger().info(f"localization mode {self.mode}")

    # -- set-up --------------------------------------------------------------------------------------------
    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        cam = self.camera_model(msg)
        if cam is None:
            return
        if self.cam is None or cam.width != self.cam.width or not np.allclose(cam.K, self.cam.K):
            if self.core is not None and hasattr(self.core, "close"):
                self.core.close()
            self.cam = cam
            # (re)built now with the right intrinsics (stereo: once the baseline is known), not on the first
            # frame: live, the frames that arrive while it builds (a mapping worker starts) would be skipped
            self.core = self._build_core()

    @guarded
    def on_right_info(self, msg: CameraInfo) -> None:
        from simreal_nodes.vision.stereo import baseline_from_projection

        try:
            self.right_baseline = baseline_from_projection(msg.p)
        except ValueError as e:
            self.set_status("error", str(e))

    def _build_core(self):
        if self.mode == "markers":
            from simreal_nodes.vision.markers import MarkerLocalizer

            mk = self.markers_cfg
            return MarkerLocalizer(self.cam, mk["dictionary"], mk["size_m"],
                                   {int(k): G.pose7_to_matrix(v) for k, v in mk["poses"].items()})
        from simreal_nodes.vision.slam.map import Map
        from simreal_nodes.vision.slam.system import Slam

        if self.mode == "stereo" and self.right_baseline is None:
            return None
        core = Slam(self.cam, self.mode, self.n_features, self.scale_factor, self.levels, baseline=self.right_baseline,
                    known_scale=self.known_scale or None, async_mapping=self.async_mapping)
        core.set_localization_only(self._loc_only)
        if self.map_file:
            core.load_map(Map.load(self.map_file))
            self.get_logger().info(f"loaded map {self.map_file}: {len(core.map.keyframes)} keyframes, "
                                   f"{len(core.map.points)} points")
        return core

    # -- frames --------------------------------------------------------------------------------------------
    def on_input(self, key: str, msg: Image) -> None:
        self.feed(self.sync, key, stamp_ns(msg.header.stamp), msg, self.process)

    @guarded
    def process(self, frame: dict) -> None:
        img_msg = frame["image"]
        header = img_msg.header
        t0 = self.metrics.arrived()
        if self.cam is None:
            self.drop(header.stamp, "waiting for a valid CameraInfo")
            return
        if self.core is None:
            self.core = self._build_core()
            if self.core is None:
                self.drop(header.stamp, "stereo: waiting for the right CameraInfo (baseline)")
                return
        try:
            img = images.image_to_array(img_msg)
            gray = _gray(img, img_msg.encoding)
            depth = None
            right = None
            if "depth" in frame:
                depth = images.depth_to_metres(images.image_to_array(frame["depth"]), frame["depth"].encoding)
            if "right" in frame:
                right = _gray(images.image_to_array(frame["right"]), frame["right"].encoding)
        except ImageFormatError as e:
            self.drop(header.stamp, f"malformed input: {e}")
            return
        if self.mode == "markers":
            res = self.core.locate(gray)
            T, state = res.T_wc, (TrackingState.OK if res.T_wc is not None else TrackingState.LOST)
            reason = res.reason if res.T_wc is None else f"{len(res.ids)} markers, {res.rms_px:.2f} px"
            self._publish(header, T, state, reason, n_feat=4 * len(res.ids))
        else:
            r = self.core.track(gray, stamp_ns(header.stamp), depth=depth, right=right)
            self._publish(header, r.T_wc, r.state, r.reason, r)
        self.metrics.done(t0, self.age_ms(header.stamp))
        self.progress(header.stamp)

    def _publish(self, header, T_wc, state: int, reason: str, r=None, n_feat: int = 0) -> None:
        obs = FeatureObservations()
        obs.header.stamp = header.stamp
        obs.header.frame_id = self.camera_frame
        if T_wc is not None:
            self.pub_pose.publish(pose_stamped(T_wc, header, self.map_frame))
            self.pub_tf.publish(TFMessage(transforms=[transform_stamped(T_wc, header.stamp, self.map_frame, self.camera_frame)]))
            matrix_to_pose(T_wc, obs.camera_pose)
        else:
            obs.camera_pose.orientation.w = 0.0  # no pose this frame (quaternion zero = invalid)
        if r is not None and T_wc is not None and len(r.obs_ids):
            obs.point_ids = [int(i) for i in r.obs_ids]
            obs.points_xyz = r.obs_pos.astype(np.float32).ravel().tolist()
            obs.pixels_uv = np.asarray(r.obs_uv, np.float32).ravel().tolist()
            obs.flags = [FeatureObservations.FLAG_POSE_INLIER if x else 0 for x in r.obs_inlier]
        self.pub_obs.publish(obs)
        st = TrackingStatus()
        st.header.stamp = header.stamp
        st.node, st.mode, st.state, st.reason = self.get_name(), self.mode, int(state), reason
        if r is not None:
            st.tracked_features = int(r.n_inliers)
            st.map_points = len(self.core.map.points)
            st.keyframes = len(self.core.map.keyframes)
            st.localization_only = bool(self.core.localization_only)
            self.metrics.extra = {k: f"{v:.1f}" for k, v in r.timings.items()}
        else:
            st.tracked_features = n_feat
        self.pub_status.publish(st)
        names = {0: "not started", 1: "initializing", 2: "ok", 3: "lost", 4: "relocalized"}
        level = "ok" if state in (2, 4) else ("warn" if state in (0, 1) else "error")
        self.set_status(level, f"{names.get(state, state)}" + (f": {reason}" if reason else ""))
        if state != self._last_status:
            self.get_logger().info(f"tracking {names.get(state, state)}" + (f": {reason}" if reason else ""))
            self._last_status = state

    # -- services / map ------------------------------------------------------------------------------------
    def on_set_localization_only(self, req, resp):
        self._loc_only = bool(req.data)
        if self.core is not None and hasattr(self.core, "set_localization_only"):
            self.core.set_localization_only(self._loc_only)
        resp.success = True
        resp.message = f"localization-only {'on' if self._loc_only else 'off'}"
        self.get_logger().info(resp.message)
        return resp

    @guarded
    def on_deformable(self, msg: PointCloud2) -> None:
        if self.core is None or not hasattr(self.core, "set_deformable"):
            return
        try:
            ids = cloud_field(msg, "id").astype(np.int64)
            P = cloud_to_array(msg)
            drop = cloud_field(msg, "drop") if any(f.name == "drop" for f in msg.fields) else np.zeros(len(ids), np.uint8)
        except ValueError as e:
            self.get_logger().warning(f"ignored malformed deformable points: {e}")
            return
        self.core.set_deformable(ids, P)
        self.core.drop_tracks(ids[drop == 1])

    def publish_map(self) -> None:
        if self.core is None or not hasattr(self.core, "map") or not self.core.map.points:
            return
        _, P, _ = self.core.map.point_arrays()
        from std_msgs.msg import Header

        h = Header()
        h.stamp = self.get_clock().now().to_msg()
        self.pub_map.publish(cloud_msg(P, h, self.map_frame))

    def close(self) -> None:
        if self.core is not None and hasattr(self.core, "map") and self.save_map:
            self.core.map.save(self.save_map, self.cam, self.mode)
            self.say(f"saved map to {self.save_map}")
        if self.core is not None and hasattr(self.core, "close"):
            self.core.close()


def _gray(img: np.ndarray, encoding: str) -> np.ndarray:
    import cv2

    if img.ndim == 2:
        return img if img.dtype == np.uint8 else cv2.convertScaleAbs(img, alpha=255.0 / max(float(img.max()), 1.0))
    return cv2.cvtColor(images.to_bgr8(img, encoding), cv2.COLOR_BGR2GRAY)


def main(args=None):
    return run_node(LocalizationNode, args)


if __name__ == "__main__":
    main()
