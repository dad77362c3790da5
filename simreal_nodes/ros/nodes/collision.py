"""Collision node (thesis ch. 5, Alg. 5.1): real points seen in depth push virtual deformable objects.

Per frame: the depth image (RGB-D, or SGBM on the rectified stereo pair) is decimated and back-projected
into the map frame with the camera pose from the localization node; for every colliding object the ROS-free
:class:`ContactTracker` finds the nearest real point to its contact nodes (KD-tree) and advances or relaxes
the pseudo-time. Objects listed in another object's ``collision.pushes`` also receive that object's deformed
surface as points (virtual-virtual contact, §5.4.1), so the pushing object is updated first.

Publishes per object ``/simreal/objects/<id>/contact`` (simreal_msgs/ContactState) and
``/simreal/objects/<id>/parameters`` (ModelParameters: the load point / position and pseudo-time or load
scale that the overlay draws).
"""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CameraInfo, Image
from simreal_msgs.msg import ContactState as ContactMsg
from simreal_msgs.msg import FeatureObservations, ModelParameters

from simreal_nodes import geometry as G
from simreal_nodes.collision.contact import ContactTracker, facing_surface_samples
from simreal_nodes.errors import ImageFormatError
from simreal_nodes.io import images
from simreal_nodes.ros.common import (SimrealNode, data_qos, guarded, observation_pose, reliable_qos,
                                      run_node, stamp_ns)
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene
from simreal_nodes.states import ContactPhase
from simreal_nodes.sync import StampSync
from simreal_nodes.vision.camera import CameraModel
from simreal_nodes.vision.depth import depth_points


def pusher_order(objects: list[dict]) -> list[dict]:
    """Objects ordered so that an object that pushes another is updated before it (cycles keep file order)."""
    ids = [o["id"] for o in objects]
    pushed_by = {i: [o["id"] for o in objects if i in o["collision"]["pushes"]] for i in ids}
    out, seen = [], set()

    def visit(i, stack=()):
        if i in seen or i in stack:
            return
        for p in pushed_by[i]:
            visit(p, stack + (i,))
        seen.add(i)
        out.append(i)

    for i in ids:
        visit(i)
    by_id = {o["id"]: o for o in objects}
    return [by_id[i] for i in out]


class CollisionNode(SimrealNode):
    def __init__(self):
        super().__init__("collision")
        self.scene = load_scene(self.scene_file)
        cam = self.scene["camera"]
        self.stereo = cam["depth"] is None and cam["right_image"] is not None
        loc = self.scene["localization"]
        self.static_pose = G.pose7_to_matrix(loc["static_pose"]) if loc["mode"] == "static" else None
        self.objects = pusher_order([o for o in self.scene["objects"] if o["collision"]["enabled"]])
        self.decimation_override = self.param("decimation", 0, "override every object's depth decimation step (0 = scene)")
        self.surface_spacing = self.param("surface_spacing_m", 0.002, "sample spacing of a pushing object's surface, metres")
        self.trackers: dict[str, ContactTracker] = {}
        self.models = {}
        for o in self.objects:
            m = load_model(o["model"], fields=["displacement"])
            self.models[o["id"]] = m
            c = o["collision"]
            self.trackers[o["id"]] = ContactTracker(m, G.pose7_to_matrix(o["anchor"]["pose"]), threshold=c["threshold_m"],
                                                    step=c["step"])
            self.get_logger().info(f"object {o['id']}: {len(m.load_points)} contact nodes, delta {c['threshold_m']} m")
        self.cam: CameraModel | None = None
        self.baseline: float | None = None
        q = data_qos(self.lossless)
        need_pose = self.static_pose is None
        keys = (("depth",) if not self.stereo else ("image", "right")) + (("obs",) if need_pose else ())
        self.sync = StampSync(keys, (), wait=2)
        self.create_subscription(CameraInfo, graph.CAM_INFO, self.on_info, q)
        # live, the input that completes a frame last (the pose if needed, else the images) is the trigger:
        # depth 1, so the newest frame is taken first
        trigger = data_qos(self.lossless, depth=1)
        qi = q if need_pose else trigger
        if self.stereo:
            self.create_subscription(Image, graph.CAM_IMAGE, lambda m: self.on_input("image", m), qi)
            self.create_subscription(Image, graph.CAM_RIGHT_IMAGE, lambda m: self.on_input("right", m), q)
            self.create_subscription(CameraInfo, graph.CAM_RIGHT_INFO, self.on_right_info, q)
        else:
            self.create_subscription(Image, graph.CAM_DEPTH, lambda m: self.on_input("depth", m), qi)
        if need_pose:
            self.create_subscription(FeatureObservations, graph.LOC_OBS, lambda m: self.on_input("obs", m), trigger)
        self.pub_contact = {o["id"]: self.create_publisher(ContactMsg, graph.contact_topic(o["id"]), reliable_qos(50))
                            for o in self.objects}
        self.pub_params = {o["id"]: self.create_publisher(ModelParameters, graph.params_topic(o["id"]), reliable_qos(50))
                           for o in self.objects}
        self.set_status("ok", f"waiting for {'stereo pairs' if self.stereo else 'depth'}")

    @guarded
    def on_info(self, msg: CameraInfo) -> None:
        cam = self.camera_model(msg)
        if cam is not None:
            self.cam = cam

    @guarded
    def on_right_info(self, msg: CameraInfo) -> None:
        from simreal_nodes.vision.stereo import baseline_from_projection

        try:
            self.baseline = baseline_from_projection(msg.p)
        except ValueError as e:
            self.set_status("error", str(e))

    def on_input(self, key, msg) -> None:
        self.feed(self.sync, key, stamp_ns(msg.header.stamp), msg, self.process)

    def _depth(self, frame) -> np.ndarray:
        if not self.stereo:
            m = frame["depth"]
            return images.depth_to_metres(images.image_to_array(m), m.encoding)
        from simreal_nodes.vision.stereo import disparity_to_depth, sgbm_disparity

        left = images.to_bgr8(images.image_to_array(frame["image"]), frame["image"].encoding)
        right = images.to_bgr8(images.image_to_array(frame["right"]), frame["right"].encoding)
        return disparity_to_depth(sgbm_disparity(left, right), self.cam.fx, self.baseline)

    @guarded
    def process(self, frame: dict) -> None:
        head = next(iter(frame.values())).header
        t0 = self.metrics.arrived()
        if self.cam is None or (self.stereo and self.baseline is None):
            self.drop(head.stamp, "waiting for CameraInfo" + (" of both cameras" if self.stereo else ""))
            return
        T_wc = self.static_pose
        if "obs" in frame:
            T_wc = observation_pose(frame["obs"])
        try:
            depth = self._depth(frame)
        except (ImageFormatError, ValueError) as e:
            self.drop(head.stamp, f"malformed depth input: {e}")
            return
        pts_by_step: dict[int, np.ndarray] = {}
        reasons = []
        for o in self.objects:
            c = o["collision"]
            step = int(self.decimation_override or c["decimation"])
            if T_wc is None:
                pts, why = None, "no camera pose this frame"
            else:
                if step not in pts_by_step:
                    dp = depth_points(depth, self.cam, step, T_wc, max_depth=c["max_depth_m"])
                    pts_by_step[step] = dp.points
                pts = pts_by_step[step]
                why = "" if len(pts) else "no valid depth"
            pushers = [p for p in self.objects if o["id"] in p["collision"]["pushes"]]
            extra = [self._surface_world(p["id"], toward=o["id"]) for p in pushers]
            extra = [e for e in extra if e is not None and len(e)]
            if extra:
                pts = np.vstack([pts] + extra) if pts is not None and len(pts) else np.vstack(extra)
            st = self.trackers[o["id"]].update(pts)
            if why and not st.reason:
                st.reason = why
            if st.reason:
                reasons.append(f"{o['id']}: {st.reason}")
            self._publish(o["id"], st, head.stamp, "depth" if not extra else "depth+" + ",".join(p["id"] for p in pushers))
        self.metrics.done(t0, self.age_ms(head.stamp))
        self.set_status("warn" if reasons else "ok", "; ".join(reasons) or "ok")
        self.progress(head.stamp)

    def _surface_world(self, oid: str, toward: str) -> np.ndarray | None:
        """The pushing object's deformed surface that faces the pushed object, in the map frame (virtual-virtual
        contact, §5.4.1): triangles whose outward normal points towards the pushed object's centre."""
        tr = self.trackers[oid]
        if tr.state.pseudo_time <= 0:
            return None
        m = self.models[oid]
        P = G.transform(tr.T, m.points + tr.displacement())
        target = G.transform(self.trackers[toward].T, self.models[toward].points.mean(axis=0)[None])[0]
        return facing_surface_samples(P, m.surface, target, self.surface_spacing)

    def _publish(self, oid: str, st, stamp, source: str) -> None:
        tr = self.trackers[oid]
        c = ContactMsg()
        c.header.stamp = stamp
        c.header.frame_id = self.map_frame
        c.object_id, c.state, c.in_contact = oid, int(st.state), bool(st.in_contact)
        c.contact_node, c.load_point = int(st.node), int(st.load_point)
        c.pseudo_time, c.min_distance = float(st.pseudo_time), float(st.min_distance)
        cp = st.contact_point
        c.contact_point.x, c.contact_point.y, c.contact_point.z = (float(v) if np.isfinite(v) else 0.0 for v in cp)
        c.source, c.points_used, c.reason = source, int(st.points_used), st.reason
        self.pub_contact[oid].publish(c)
        m = ModelParameters()
        m.header.stamp = stamp
        m.header.frame_id = oid
        m.object_id, m.model_id = oid, tr.model.model_id
        m.names = tr.parameter_names()
        axes_units = [a.unit for a in tr.model.axes]
        m.units = axes_units + [""] * (len(m.names) - len(axes_units))
        m.values = [float(v) for v in tr.parameters()]
        m.frozen = [False] * len(m.names)
        m.covariance = [0.0] * (len(m.names) ** 2)
        m.residual_rms_px = -1.0
        m.state = ModelParameters.STATE_OK if st.state != ContactPhase.NO_DATA else ModelParameters.STATE_LOW_CONFIDENCE
        m.reason = st.reason
        self.pub_params[oid].publish(m)


def main(args=None):
    return run_node(CollisionNode, args)


if __name__ == "__main__":
    main()
