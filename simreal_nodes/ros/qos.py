"""The QoS profiles of the simreal graph: live sensor data, lossless replay, reliable state and TF."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data


def data_qos(lossless: bool, depth: int = 5) -> QoSProfile:
    """Sensor-data QoS (best effort, keep last ``depth``) live; reliable with a deep queue when lossless.

    Live, the input that triggers a node's work (its newest frame) is subscribed with depth 1, so a node
    that was busy takes the newest frame next, not the oldest one still queued (the SLAM localization keeps
    a few, for even gaps between the frames it tracks); the inputs it pairs with that frame by stamp keep a
    few frames (the default 5), as they arrive earlier than the trigger."""
    if lossless:
        return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                          depth=1000, durability=DurabilityPolicy.VOLATILE)
    q = QoSProfile(**{k: getattr(qos_profile_sensor_data, k) for k in ("reliability", "history", "durability")},
                   depth=depth)
    return q


def reliable_qos(depth: int = 10) -> QoSProfile:
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=depth)


TF_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=100)
# the aero node's flow: reliable and latched (transient local), so an overlay started later still gets the last one
LATCHED_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=1,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
