"""Aero node (thesis ch. 6, §6.4): the car captured from the SLAM map and its flow from the offline database.

Takes the localization node's capture cloud (``/simreal/localization/capture_cloud``: the map's points and, RGB-D,
every keyframe feature with a measured depth; once a second) and, once it holds ``aero.min_points`` points and again
whenever it has grown by ``aero.recapture_growth``, runs the ROS-free :class:`AeroEstimator`: Alg. 6.1 -> the shape
manifold -> Eq. 6.4 -> streamlines. Publishes ``/simreal/aero/flow`` (visualization_msgs/MarkerArray in the map
frame: the captured body as a TRIANGLE_LIST, each streamline as a LINE_STRIP coloured by speed, width the tube's
diameter; transient local, so a late subscriber gets the last flow), which the overlay node draws over the video
with occlusion by the body. Diagnostics: the captured box, Eq. 6.4's neighbours and drag coefficient, the times.
The database is loaded once at start; the node never runs CFD.
"""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

from simreal_nodes.aero.capture import CaptureSettings
from simreal_nodes.aero.database import load_database
from simreal_nodes.aero.online import AeroEstimator, RakeSettings, flow_markers
from simreal_nodes.io.cdr import marker_array_cdr
from simreal_nodes.render.aero import speed_lut
from simreal_nodes.ros.convert import cloud_to_array, stamp_ns
from simreal_nodes.ros.node import SimrealNode, guarded, run_node
from simreal_nodes.ros.qos import LATCHED_QOS, reliable_qos
from simreal_nodes.scene import graph
from simreal_nodes.scene.schema import load_scene

RETRY_GROWTH = 0.1  # a failed capture is tried again once the cloud has grown by this fraction


class AeroNode(SimrealNode):
    def __init__(self, **kw) -> None:
        super().__init__("aero", **kw)
        self.scene = load_scene(self.scene_file)
        a = self.scene["aero"]
        self.min_points = self.param("min_points", int(a["min_points"]), "capture once the cloud holds this many")
        self.growth = self.param("recapture_growth", float(a["recapture_growth"]),
                                 "capture again when the cloud has grown by this fraction (0: once)")
        self.say(f"loading the aero database {a['database']}")
        db = load_database(a["database"])
        n = int(a["streamlines"])
        # a metric map keeps its scale: length_m is used for a monocular one only
        length = a["length_m"] if self.scene["localization"]["mode"] == "mono" else None
        capture = CaptureSettings(alpha_m=float(a["alpha_m"]), length_m=length, max_points=int(a["max_points"]) or None)
        self.core = AeroEstimator(db, int(a["neighbours"]), capture, RakeSettings(ny=n, nz=max(1, round(0.8 * n))),
                                  section=a["section"])
        self.lut = speed_lut()
        self.captured_at = 0  # cloud size at the last successful capture (0: none yet)
        self.tried_at = 0  # cloud size at the last attempt (a failed one is retried on a larger cloud)
        self.pub = self.create_publisher(MarkerArray, graph.AERO_FLOW, LATCHED_QOS)
        self.create_subscription(PointCloud2, graph.LOC_CAPTURE, self.on_cloud, reliable_qos(1))
        self.set_status("ok", f"database of {len(db.database)} cars loaded; waiting for the map")

    @guarded
    def on_cloud(self, msg: PointCloud2) -> None:
        P = cloud_to_array(msg)
        P = P[np.all(np.isfinite(P), axis=1)]
        n = len(P)
        if n < self.min_points:
            self.set_status("ok", f"waiting for the map: {n} of {self.min_points} points")
            return
        if self.captured_at and (self.growth <= 0 or n < (1.0 + self.growth) * self.captured_at):
            return  # captured: again only when the map has grown enough (never with growth 0)
        if self.tried_at and n < (1.0 + RETRY_GROWTH) * self.tried_at:
            return  # the last attempt failed: again on a larger map, not on the same one every second
        self.tried_at = n  # before the attempt: an unexpected error is not retried on the same cloud either
        t0 = self.metrics.arrived()
        try:
            res = self.core.estimate(P)
        except ValueError as e:  # too little left at one of Alg. 6.1's steps: try again on a larger map
            self.set_status("warn", f"no car captured from {n} points: {e}")
            return
        self.captured_at = n
        self.pub.publish(marker_array_cdr(flow_markers(res, self.lut), stamp_ns(msg.header.stamp), self.map_frame))
        self.metrics.extra.update({
            "cloud_points": str(n), "box_m": " x ".join(f"{x:.2f}" for x in res.box_m),
            "neighbours": ", ".join(f"{c} ({w:+.2f})" for c, w in zip(res.neighbours, res.weights)),
            "cd_eq64": f"{res.cd:.3f}", "streamlines": str(len(res.lines)),
            **{f"{k}_s": f"{v:.2f}" for k, v in res.seconds.items()}})
        self.metrics.done(t0)
        self.set_status("ok", f"car captured from {n} points: {res.box_m[0]:.2f} x {res.box_m[1]:.2f} x "
                              f"{res.box_m[2]:.2f} m, Cd {res.cd:.3f} (Eq. 6.4), {len(res.lines)} streamlines")


NODE_CLASS = AeroNode  # what the one-process launch (simreal_nodes.ros.compose) builds


def main(args=None):
    return run_node(AeroNode, args)


if __name__ == "__main__":
    main()
