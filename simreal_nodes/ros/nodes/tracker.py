"""Deformable tracking node (thesis ch. 4): estimates each tracked object's physical parameters.

Per frame it takes the localization node's FeatureObservations (camera pose + matched map points)
and, for glued-dot measurements, the image of the same stamp, runs the ROS-free
:class:`DeformableTracker` of every tracked object and publishes ``/simreal/objects/<id>/parameters``
(ModelParameters: values, covariance, residual, inliers, state and reason). Once deformation appears
(if the scene's ``localization.freeze_map_on_deformation``) it asks the localization node to stop mapping
(``set_localization_only``). After every frame it tells the localization which map points lie on the
object, where the current estimate predicts them and which the fit rejected
(``/simreal/localization/deformable_points``, PointCloud2 x, y, z, id, drop in the map frame).
"""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from simreal_msgs.msg import FeatureObservations, ModelParameters, TrackingStatus
from std_srvs.srv import SetBool

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.tracker import DeformableTracker, deformable_feedback, tracker_config
from simreal_nodes.errors import ImageFormatError
from simreal_nodes.io import images
from simreal_nodes.ros.common import (SimrealNode, cloud_msg, data_qos, guarded, observation_pose, reliable_qos, run_node,
                                      stamp_ns)
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.states import EstimateState, tracking_state
from simreal_nodes.sync import StampSync
from simreal_nodes.vision.camera import CameraModel



class TrackerNode(SimrealNode):
    def __init__(self):
        super().__init__("tracker")
        self.scene = load_scene(self.scene_file)
        self.objects = [o for o in self.scene["objects"] if o["tracking"]["enabled"]]
        loc = self.scene["localization"]
        self.static_pose = G.pose7_to_matrix(loc["static_pose"]) if loc["mode"] == "static" else None
        self.huber_override = self.param("huber_px", 0.0, "override every object's Huber threshold (0 = scene)")
        self.modes_override = self.param("modes", 0, "override the number of PGD modes (0 = scene)")
        self.models = {}
        for o in self.objects:
            fields = ["displacement"]
            self.models[o["id"]] = load_model(o["model"], fields=fields)
            self.get_logger().info(f"object {o['id']}: {self.models[o['id']].summary().splitlines()[0]}")
        self.trackers: dict[str, DeformableTracker] = {}
        self.cam: CameraModel | None = None
        keys = graph.tracker_inputs(self.scene)
        self.need_image = any(o["tracking"]["measurements"] in ("dots", "homography") for o in self.objects)
        self.sync = StampSync(keys, (), wait=2)
        q = data_qos(self.lossless)
        self.pubs = {o["id"]: self.create_publisher(ModelParameters, graph.params_topic(o["id"]), reliable_qos(50))
                     for o in self.objects}
        self.pub_status = self.create_publisher(TrackingStatus, graph.TRACKER_STATUS, reliable_qos(10))
        self.pub_deformable = self.create_publisher(PointCloud2, graph.LOC_DEFORMABLE, reliable_qos(10))
        self.freeze_map = bool(loc.get("freeze_map_on_deformation", False))
        self.create_subscription(CameraInfo, graph.CAM_INFO, self.on_info, q)
        trigger = data_qos(self.lossless, depth=1)  # the newest frame first (live)
        if "obs" in keys:
            self.create_subscription(FeatureObservations, graph.LOC_OBS, lambda m: self.on_input("obs", m), trigger)
        if "image" in keys:
            self.create_subscription(Image, graph.CAM_IMAGE, lambda m: self.on_input("image", m),
                                     q if "obs" in keys else trigger)
        self.loc_client = self.create_client(SetBool, "/localization/set_localization_only")
        self._loc_only_requested = False
        self.set_status("ok", f"tracking {', '.join(o['id'] for o in self.objects)}")

    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        cam = self.camera_model(msg)
        if cam is None:
            return
        if self.cam is None or not np.allclose(cam.K, self.cam.K):
            self.cam = cam
            self.trackers = {}
            for o in self.objects:  # now, not on the first frame: that frame would wait for them
                self._tracker(o)

    def _tracker(self, o) -> DeformableTracker:
        tr = self.trackers.get(o["id"])
        if tr is None:
            t = o["tracking"]
            cfg = tracker_config(o, huber_px=self.huber_override or t["huber_px"], n_modes=self.modes_override or t["modes"])
            tr = DeformableTracker(self.models[o["id"]], G.pose7_to_matrix(o["anchor"]["pose"]), o["parameters"], self.cam, cfg)
            self.trackers[o["id"]] = tr
        return tr

    def on_input(self, key, msg) -> None:
        self.feed(self.sync, key, stamp_ns(msg.header.stamp), msg, self.process)

    @guarded
    def process(self, frame: dict) -> None:
        head = (frame.get("obs") or frame.get("image")).header
        t0 = self.metrics.arrived()
        if self.cam is None:
            self.drop(head.stamp, "waiting for a valid CameraInfo")
            return
        T_wc, ids, P, uv = None, None, None, None
        if "obs" in frame:
            o = frame["obs"]
            T_wc = observation_pose(o)
            ids = np.asarray(o.point_ids, dtype=np.int64)
            P = np.asarray(o.points_xyz, dtype=np.float64).reshape(-1, 3)
            uv = np.asarray(o.pixels_uv, dtype=np.float64).reshape(-1, 2)
            if len(P) != len(ids) or len(uv) != len(ids):
                self.drop(head.stamp, f"malformed observations ({len(ids)} ids, {len(P)} points, {len(uv)} pixels)")
                return
        else:
            T_wc = self.static_pose
        bgr = None
        if "image" in frame and self.need_image:
            try:
                bgr = images.to_bgr8(images.image_to_array(frame["image"]), frame["image"].encoding)
            except ImageFormatError as e:
                self.drop(head.stamp, f"malformed image: {e}")
                return
        deforming = False
        for o in self.objects:
            tr = self._tracker(o)
            est = tr.update(T_wc, ids, P, uv, bgr)
            deforming |= est.deforming
            self._publish(o, tr, est, head)
        self._coordinate_localization(deforming, head)
        self.metrics.done(t0, self.age_ms(head.stamp))
        self.progress(head.stamp)

    def _publish(self, o, tr, est, head) -> None:
        m = ModelParameters()
        m.header.stamp = head.stamp
        m.header.frame_id = o["id"]
        m.object_id = o["id"]
        m.model_id = tr.model.model_id
        m.names, m.units = list(est.names), list(est.units)
        m.values = [float(v) for v in est.values]
        m.frozen = [bool(f) for f in est.frozen]
        m.covariance = [float(c) if np.isfinite(c) else float("inf") for c in np.asarray(est.cov).ravel()]
        m.residual_rms_px = float(est.rms_px) if np.isfinite(est.rms_px) else -1.0
        m.inliers, m.measurements, m.iterations = int(est.inliers), int(est.measurements), int(est.iterations)
        m.state, m.reason = int(est.state), est.reason
        self.pubs[o["id"]].publish(m)
        st = TrackingStatus()
        st.header.stamp = head.stamp
        st.node, st.mode = self.get_name(), f"deformable:{o['id']}"
        st.state = int(tracking_state(est.state))
        st.reason, st.tracked_features = est.reason, int(est.inliers)
        self.pub_status.publish(st)
        self.metrics.extra[f"{o['id']}_solve_ms"] = f"{est.solve_ms:.2f}"
        self.set_status("ok" if est.state == EstimateState.OK else "warn", f"{o['id']}: " + (est.reason or "ok"))

    def _coordinate_localization(self, deforming: bool, head) -> None:
        """Points on the object leave the pose estimate and are searched where the estimate predicts them;
        mapping stops once deformation appears if the scene asks for it (§4.4.1)."""
        if self.static_pose is None:
            ids, P, drop = deformable_feedback(self.trackers.values())
            if len(ids):
                self.pub_deformable.publish(cloud_msg(P, head, self.map_frame, {"id": ids, "drop": drop}))
        if deforming and self.freeze_map and not self._loc_only_requested and self.loc_client.service_is_ready():
            self.loc_client.call_async(SetBool.Request(data=True))
            self._loc_only_requested = True
            self.get_logger().info("deformation appeared: localization-only mode requested")


def main(args=None):
    return run_node(TrackerNode, args)


if __name__ == "__main__":
    main()
