"""Deformable tracking node (thesis ch. 4): estimates each tracked object's physical parameters.

Per frame it takes the localization node's FeatureObservations (camera pose + matched map points)
and, for glued-dot measurements, the image of the same stamp, runs the ROS-free
:class:`DeformableTracker` of every tracked object and publishes ``/simreal/objects/<id>/parameters``
(ModelParameters: values, covariance, residual, inliers, state and reason). Once deformation appears
(if the scene's ``localization.freeze_map_on_deformation``) it asks the localization node to stop mapping
(parameter ``localization_service``: a name relative to the tracker's namespace, so a graph launched in a
namespace reaches its own localization node; remappable like any service name), and asks again when the
localization's status reports it mapping after it was told (a restarted localization node). An object with
``anchor: registration`` is placed from the depth images (taken while it waits for them); dense measurements read
the depth of their reference view. On a stereo camera the node makes that depth itself, by SGBM on the rectified
pair (``camera.stereo_min_depth_m``), and only in the frames where depth is still read. After every frame it tells
the localization which map points lie on the object, where the current estimate predicts them, which the fit
rejected and which were linked at rest (``/simreal/localization/deformable_points``, PointCloud2 x, y, z, id, flags
in the map frame) and where each object projects in the image (``/simreal/localization/focus``,
PolygonInstanceStamped, id = the object's index).
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PolygonInstanceStamped
from sensor_msgs.msg import CameraInfo, PointCloud2
from simreal_msgs.msg import FeatureObservations, ModelParameters, TrackingStatus
from std_srvs.srv import SetBool

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.localizer import MapFreeze
from simreal_nodes.assimilation.objects import ObjectTrackers
from simreal_nodes.assimilation.registration import RegistrationConfig
from simreal_nodes.assimilation.tracker import Estimate
from simreal_nodes.errors import ImageFormatError
from simreal_nodes.io import images
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.ros.convert import cloud_msg, estimate_msg, focus_msg, observation_arrays
from simreal_nodes.ros.node import SimrealNode, guarded, run_node
from simreal_nodes.ros.qos import data_qos, reliable_qos
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.states import EstimateState, tracking_state
from simreal_nodes.sync import StampSync


class TrackerNode(SimrealNode):
    def __init__(self, **kw):
        super().__init__("tracker", **kw)
        self.scene = load_scene(self.scene_file)
        self.objects = [o for o in self.scene["objects"] if o["tracking"]["enabled"]]
        loc = self.scene["localization"]
        self.static_pose = G.pose7_to_matrix(loc["static_pose"]) if loc["mode"] == "static" else None
        huber = self.param("huber_px", 0.0, "override every object's Huber threshold (0 = scene)")
        modes = self.param("modes", 0, "override the number of PGD modes (0 = scene)")
        models = {}
        for o in self.objects:
            models[o["id"]] = load_model(o["model"], fields=["displacement"])
            self.get_logger().info(f"object {o['id']}: {models[o['id']].summary().splitlines()[0]}")
        overrides = {k: v for k, v in (("huber_px", huber), ("n_modes", modes)) if v}  # 0: the scene's
        # live, an object is registered in a worker process while frames go on; lossless, in the frame (repeatable)
        self.core = ObjectTrackers(self.objects, models, RegistrationConfig.for_camera(self.scene["camera"]),
                                   background=not self.lossless, **overrides)
        keys = graph.tracker_inputs(self.scene)
        self.need_image = any(o["tracking"]["measurements"] in graph.IMAGE_MEASUREMENTS for o in self.objects)
        reads_depth = graph.tracker_reads_depth(self.scene)
        self.stereo = graph.tracker_stereo_depth(self.scene)
        self.core.stereo_min_depth = float(self.scene["camera"]["stereo_min_depth_m"])
        optional = ()
        if reads_depth:
            optional = (("right",) + (() if "image" in keys else ("image",))) if self.stereo else ("depth",)
        self.sync = StampSync(keys, optional, wait=2)
        q = data_qos(self.lossless)
        self.pubs = {o["id"]: self.create_publisher(ModelParameters, graph.params_topic(o["id"]), reliable_qos(50))
                     for o in self.objects}
        self.pub_status = self.create_publisher(TrackingStatus, graph.TRACKER_STATUS, reliable_qos(10))
        self.pub_deformable = self.create_publisher(PointCloud2, graph.LOC_DEFORMABLE, reliable_qos(10))
        self.pub_focus = self.create_publisher(PolygonInstanceStamped, graph.LOC_FOCUS, reliable_qos(10))
        self.freeze_map = bool(loc.get("freeze_map_on_deformation", False))
        cam = self.camera_topics(self.scene["camera"])
        self.create_subscription(CameraInfo, cam["info"], self.on_info, q)
        trigger = data_qos(self.lossless, depth=1)  # the newest frame first (live)
        if "obs" in keys:
            self.create_subscription(FeatureObservations, graph.LOC_OBS, lambda m: self.on_input("obs", m), trigger)
        if "image" in keys:
            self.subscribe_image(cam["image"], "image", q if "obs" in keys else trigger)
        if reads_depth and not self.stereo:
            self.subscribe_image(cam["depth"], "depth", q)
        if self.stereo:
            if "image" not in keys:
                self.subscribe_image(cam["image"], "image", q)
            self.subscribe_image(cam["right"], "right", q)
            self.create_subscription(CameraInfo, cam["right_info"], self.on_right_info, q)
        service = self.param("localization_service", "localization/set_localization_only",
                             "the localization node's SetBool freezing its map; relative: in this node's namespace",
                             read_only=True)
        self.loc_client = self.create_client(SetBool, service)
        self.freeze = MapFreeze(self.freeze_map)
        if graph.tracker_reads_status(self.scene):  # what the localization was told: a restarted one is asked again
            self.create_subscription(TrackingStatus, graph.LOC_STATUS, self.on_localization_status, reliable_qos(10))
        self.set_status("ok", f"tracking {', '.join(o['id'] for o in self.objects)}")

    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        cam = self.camera_model(msg)
        if cam is None:
            return
        if not cam.same_as(self.core.cam):
            self.core.set_camera(cam)

    @guarded
    def on_right_info(self, msg: CameraInfo) -> None:
        self.core.depth_baseline = self.stereo_baseline(msg, self.core.depth_baseline)

    def _depth(self, frame: dict, left: np.ndarray | None) -> np.ndarray | None:
        """The frame's depth (metres) where the trackers still read it: the RGB-D image, or SGBM on the pair
        (``left``: the frame's image already decoded and checked, or None)."""
        if not self.core.needs_depth:
            return None
        cam = self.core.cam
        assert cam is not None  # process() drops a frame while there is no camera
        if not self.stereo:
            if "depth" not in frame:
                return None
            depth = images.depth_metres_of(frame["depth"])
            cam.check_size(depth, "depth image")  # registered to the image: read through this camera
            return depth
        if "image" not in frame or "right" not in frame:
            return None
        if left is None:
            left = images.bgr8_of(frame["image"])
            cam.check_size(left)  # the right image: stereo_depth refuses a pair of two sizes
        return self.core.depth_of_pair(left, images.bgr8_of(frame["right"]))

    @guarded
    def process(self, frame: dict) -> None:
        first = frame.get("obs") or frame.get("image")
        assert first is not None  # a frame holds the observations or the image it was completed by
        head = first.header
        t0 = self.metrics.arrived()
        if self.core.cam is None:
            self.drop(head.stamp, self.no_camera())
            return
        T_wc, ids, P, uv = None, None, None, None
        if "obs" in frame:
            try:
                T_wc, ids, P, uv = observation_arrays(frame["obs"])
            except ValueError as e:
                self.drop(head.stamp, str(e))
                return
        else:
            T_wc = self.static_pose
        bgr = depth = None
        try:
            bgr = images.bgr8_of(frame["image"]) if "image" in frame and self.need_image else None
            if bgr is not None:  # an image of another size than CameraInfo's: its pixels are not this camera's
                self.core.cam.check_size(bgr)
            self.metrics.lap("decode")  # the depth below is work where it is SGBM on a stereo pair
            depth = self._depth(frame, bgr)
        except (ImageFormatError, ValueError) as e:
            self.drop(head.stamp, f"malformed image: {e}")
            return
        estimates = self.core.update(T_wc, ids, P, uv, bgr, depth)
        # what the localization is told: the object's points where the estimate predicts them, its image regions
        feedback = self.core.feedback() if self.static_pose is None else None
        focus = self.core.focus(T_wc) if self.static_pose is None else []
        self.metrics.lap("work")
        for oid, est in estimates.items():
            self._publish(oid, est, head)
        self._coordinate_localization(any(e.deforming for e in estimates.values()), head, feedback, focus)
        self.metrics.lap("encode")
        self.metrics.done(t0, self.age_ms(head.stamp))
        self.progress(head.stamp)

    def _publish(self, oid: str, est: Estimate, head) -> None:
        self.pubs[oid].publish(estimate_msg(oid, self.core.trackers[oid].model.model_id, est, head.stamp))
        st = TrackingStatus()
        st.header.stamp = head.stamp
        st.node, st.mode = self.get_name(), f"deformable:{oid}"
        st.state = int(tracking_state(est.state))
        st.reason, st.tracked_features = est.reason, int(est.inliers)
        self.pub_status.publish(st)
        self.metrics.extra[f"{oid}_solve_ms"] = f"{est.solve_ms:.2f}"
        self.set_status("ok" if est.state == EstimateState.OK else "warn", f"{oid}: " + (est.reason or "ok"))

    def _coordinate_localization(self, deforming: bool, head, feedback, focus) -> None:
        """Points on the object leave the pose estimate and are searched where the estimate predicts them
        (``feedback``: :meth:`ObjectTrackers.feedback`, None with a static camera); each object's image region
        (``focus``) gets its share of the next frame's features; mapping stops once deformation appears if the scene
        asks for it (§4.4.1)."""
        if feedback is not None:
            ids, P, flags = feedback
            if len(ids):
                self.pub_deformable.publish(cloud_msg(P, head, self.map_frame, {"id": ids, "flags": flags}))
        for k, poly in focus:
            self.pub_focus.publish(focus_msg(poly, k, head, self.camera_frame))
        # the service's presence is asked of rcl only where the scene freezes the map (not every frame of every scene)
        if self.freeze.enabled and self.freeze.due(deforming, self.loc_client.service_is_ready()):
            self.freeze.sent()
            self.loc_client.call_async(SetBool.Request(data=True)).add_done_callback(self._freeze_answered)
            self.get_logger().info("deformation appeared: localization-only mode requested"
                                   + (" again" if self.freeze.requests > 1 else ""))

    @guarded
    def _freeze_answered(self, future) -> None:
        self.freeze.answered(future.exception() is None and bool(future.result().success))

    @guarded
    def on_localization_status(self, msg: TrackingStatus) -> None:
        if self.freeze.status(bool(msg.localization_only)):
            self.get_logger().warning("the localization is mapping (restarted, or the request was lost): "
                                      "localization-only mode will be requested again")

    def close(self) -> None:
        self.core.close()


NODE_CLASS = TrackerNode  # what the one-process launch (simreal_nodes.ros.compose) builds


def main(args=None):
    return run_node(TrackerNode, args)


if __name__ == "__main__":
    main()
