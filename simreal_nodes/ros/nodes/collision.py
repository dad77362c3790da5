"""Collision node (thesis ch. 5, Alg. 5.1): real points seen in depth push virtual deformable objects.

Per frame: the depth image (RGB-D, or SGBM on the rectified stereo pair) and the camera pose from the localization
node go to the ROS-free :class:`ContactScene`: it back-projects the decimated depth into the map frame, and for
every colliding object a :class:`ContactTracker` finds the nearest real point to its contact nodes (KD-tree) and
advances or relaxes the pseudo-time. Objects listed in another object's ``collision.pushes`` also receive that
object's deformed surface (virtual-virtual contact, §5.4.1: touching at a gap of zero along the push direction),
so the pushing object is updated first.

Publishes per object ``/simreal/objects/<id>/contact`` (simreal_msgs/ContactState) and
``/simreal/objects/<id>/parameters`` (ModelParameters: the load point / position and pseudo-time or load
scale that the overlay draws).
"""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CameraInfo
from simreal_msgs.msg import ContactState as ContactMsg
from simreal_msgs.msg import FeatureObservations, ModelParameters

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.collision.scene import ContactScene, ObjectContact
from simreal_nodes.errors import ImageFormatError
from simreal_nodes.io import images
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.ros.convert import contact_msg, contact_parameters_msg, observation_pose
from simreal_nodes.ros.node import SimrealNode, guarded, run_node
from simreal_nodes.ros.qos import data_qos, reliable_qos
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.sync import StampSync


class CollisionNode(SimrealNode):
    def __init__(self, **kw) -> None:
        super().__init__("collision", **kw)
        self.scene = load_scene(self.scene_file)
        cam = self.scene["camera"]
        self.stereo = cam["depth"] is None and cam["right_image"] is not None
        loc = self.scene["localization"]
        self.static_pose = G.pose7_to_matrix(loc["static_pose"]) if loc["mode"] == "static" else None
        decimation = self.param("decimation", 0, "override every object's depth decimation step (0 = scene)")
        colliding = [o for o in self.scene["objects"] if o["collision"]["enabled"]]
        models = {o["id"]: load_model(o["model"], fields=["displacement"]) for o in colliding}
        self.core = ContactScene(colliding, models, decimation)
        self.objects = self.core.objects
        for o in self.objects:
            c, lp = o["collision"], models[o["id"]].load_points
            assert lp is not None  # ContactScene refuses a model without load points
            self.get_logger().info(f"object {o['id']}: {len(lp)} contact nodes, "
                                   f"delta {c['threshold_m']} m")
        self.cam: CameraModel | None = None
        self.baseline: float | None = None
        q = data_qos(self.lossless)
        need_pose = self.static_pose is None
        keys = (("depth",) if not self.stereo else ("image", "right")) + (("obs",) if need_pose else ())
        self.sync = StampSync(keys, (), wait=2)
        topics = self.camera_topics(cam)
        self.create_subscription(CameraInfo, topics["info"], self.on_info, q)
        # live, the input that completes a frame last (the pose if needed, else the images) is the trigger:
        # depth 1, so the newest frame is taken first
        trigger = data_qos(self.lossless, depth=1)
        qi = q if need_pose else trigger
        if self.stereo:
            self.subscribe_image(topics["image"], "image", qi)
            self.subscribe_image(topics["right"], "right", q)
            self.create_subscription(CameraInfo, topics["right_info"], self.on_right_info, q)
        else:
            self.subscribe_image(topics["depth"], "depth", qi)
        if need_pose:
            self.create_subscription(FeatureObservations, graph.LOC_OBS, lambda m: self.on_input("obs", m), trigger)
        self.pub_contact = {o["id"]: self.create_publisher(ContactMsg, graph.contact_topic(o["id"]), reliable_qos(50))
                            for o in self.objects}
        self.pub_params = {o["id"]: self.create_publisher(ModelParameters, graph.params_topic(o["id"]),
                                                          reliable_qos(50)) for o in self.objects}
        self.set_status("ok", f"waiting for {'stereo pairs' if self.stereo else 'depth'}")

    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        cam = self.camera_model(msg)
        if cam is not None:
            self.cam = cam

    @guarded
    def on_right_info(self, msg: CameraInfo) -> None:
        self.baseline = self.stereo_baseline(msg, self.baseline)

    def _depth(self, frame) -> np.ndarray:
        if not self.stereo:
            return images.depth_metres_of(frame["depth"])
        from simreal_nodes.vision.stereo import disparity_to_depth, sgbm_disparity

        left = images.bgr8_of(frame["image"])
        right = images.bgr8_of(frame["right"])
        assert self.cam is not None and self.baseline is not None  # process waits for both in stereo
        return disparity_to_depth(sgbm_disparity(left, right), self.cam.fx, self.baseline)

    @guarded
    def process(self, frame: dict) -> None:
        head = next(iter(frame.values())).header
        t0 = self.metrics.arrived()
        if self.cam is None or (self.stereo and self.baseline is None):
            self.drop(head.stamp, self.no_camera("waiting for CameraInfo" + (" of both cameras" if self.stereo
                                                                             else "")))
            return
        T_wc = self.static_pose
        if "obs" in frame:
            try:
                T_wc = observation_pose(frame["obs"])
            except ValueError as e:
                self.drop(head.stamp, f"malformed observations: {e}")
                return
        try:
            depth = self._depth(frame)
            self.cam.check_size(depth, "depth image")
        except (ImageFormatError, ValueError) as e:
            self.drop(head.stamp, f"malformed depth input: {e}")
            return
        reasons = []
        for r in self.core.step(depth, self.cam, T_wc):
            if r.state.reason:
                reasons.append(f"{r.object_id}: {r.state.reason}")
            self._publish(r, head.stamp)
        self.metrics.done(t0, self.age_ms(head.stamp))
        self.set_status("warn" if reasons else "ok", "; ".join(reasons) or "ok")
        self.progress(head.stamp)

    def _publish(self, r: ObjectContact, stamp) -> None:
        self.pub_contact[r.object_id].publish(contact_msg(r.object_id, r.state, r.source, stamp, self.map_frame))
        self.pub_params[r.object_id].publish(contact_parameters_msg(r.object_id, self.core.trackers[r.object_id],
                                                                    r.state, stamp))


NODE_CLASS = CollisionNode  # what the one-process launch (simreal_nodes.ros.compose) builds


def main(args=None):
    return run_node(CollisionNode, args)


if __name__ == "__main__":
    main()
