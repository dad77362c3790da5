"""Messages <-> numpy for the nodes: stamps, poses, transforms, point clouds, CameraInfo and the simreal_msgs they
publish (no cv_bridge, no sensor_msgs_py)."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from geometry_msgs.msg import (
    Point32,
    Polygon,
    PolygonInstance,
    PolygonInstanceStamped,
    Pose,
    PoseStamped,
    TransformStamped,
)
from sensor_msgs.msg import CameraInfo
from simreal_msgs.msg import ContactState as ContactMsg
from simreal_msgs.msg import FeatureObservations, ModelParameters, TrackingStatus
from std_msgs.msg import Header

from simreal_nodes import geometry
from simreal_nodes.states import ContactPhase

if TYPE_CHECKING:  # (annotations only: the player imports this module and needs none of the cores)
    from simreal_nodes.assimilation.localizer import Localization
    from simreal_nodes.assimilation.tracker import Estimate
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.collision.contact import ContactState, ContactTracker


def stamp_ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int, msg=None):
    from builtin_interfaces.msg import Time

    t = msg or Time()
    t.sec, t.nanosec = int(ns // 1_000_000_000), int(ns % 1_000_000_000)
    return t


@dataclass(frozen=True, slots=True)
class ImageView:
    """A ``sensor_msgs/Image`` read from its CDR bytes (:func:`image_view`): the fields
    :func:`~simreal_nodes.io.images.image_to_array` reads, ``data`` a read-only numpy view on the bytes, ``header``
    an rclpy Header (output messages take its stamp)."""

    header: Header
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: np.ndarray


IMAGE_TYPE = "sensor_msgs/msg/Image"


@functools.lru_cache(maxsize=1)
def _jazzy_types():
    """rosbags' ROS 2 Jazzy type store (sensor_msgs among them; simreal's own messages are not needed here)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def prepare() -> None:
    """Load rosbags' type store now (its import, every ROS 2 distribution's store module, about 0.1 s of CPU): a
    node calls it at start-up, so that its first image does not wait for it."""
    _jazzy_types()


def read_image_cdr(raw: bytes | bytearray | memoryview):
    """An Image subscription's serialized message (``raw=True``) read by rosbags' CDR deserializer (its message
    class; ``data`` a read-only numpy view on ``raw``, not a copy), instead of rclpy's conversion into a message
    object, which copies ``data`` into a Python array (`./run bench executor` measures a subscriber's CPU both ways).
    rosbags' SerdeError for bytes that are not a serialized Image (rosbags reads the classic CDR that ROS 2's
    middlewares write for messages)."""
    return _jazzy_types().deserialize_cdr(memoryview(raw), IMAGE_TYPE)


def image_view(raw) -> ImageView:
    """An Image's serialized bytes, or rosbags' message of them (:func:`read_image_cdr`), as an :class:`ImageView`
    with an rclpy Header."""
    m = read_image_cdr(raw) if isinstance(raw, (bytes, bytearray, memoryview)) else raw
    h = Header(frame_id=m.header.frame_id)
    h.stamp.sec, h.stamp.nanosec = m.header.stamp.sec, m.header.stamp.nanosec
    return ImageView(h, m.height, m.width, m.encoding, m.is_bigendian, m.step, m.data)


def image_cdr(m, frame_id: str, pixels: np.ndarray | None = None) -> bytes:
    """Serialized bytes (to publish as they are) of rosbags' Image ``m`` with the frame ``frame_id`` and, if given,
    ``pixels`` (in ``m``'s encoding) instead of its own, by rosbags' serializer (no rclpy message object is built)."""
    from dataclasses import replace

    from simreal_nodes.io.images import array_to_image_fields

    out = replace(m, header=replace(m.header, frame_id=frame_id))
    if pixels is not None:
        f = array_to_image_fields(pixels, m.encoding)
        out = replace(out, height=f.height, width=f.width, is_bigendian=f.is_bigendian, step=f.step,
                      data=np.frombuffer(f.data, np.uint8))
    return bytes(_jazzy_types().serialize_cdr(out, IMAGE_TYPE))


def array_image_cdr(pixels: np.ndarray, encoding: str, stamp, frame_id: str) -> bytes:
    """Serialized bytes (to publish as they are) of an Image of ``pixels`` in ``encoding``, stamped ``stamp`` (an
    rclpy Time message) in ``frame_id``, by rosbags' serializer: plain buffer copies of the pixels (to bytes, into
    the CDR buffer, into the bytes returned), cheaper than filling an rclpy message's data field and converting it
    to the C message (the ingest's CPU a frame 5.5 -> 4.8 ms on the foam beam's JPEG frames, stop 98, scratch)."""
    from simreal_nodes.io.images import array_to_image_fields

    ts = _jazzy_types()
    f = array_to_image_fields(pixels, encoding)
    head = ts.types["std_msgs/msg/Header"](
        stamp=ts.types["builtin_interfaces/msg/Time"](sec=int(stamp.sec), nanosec=int(stamp.nanosec)),
        frame_id=frame_id)
    img = ts.types[IMAGE_TYPE](header=head, height=f.height, width=f.width, encoding=f.encoding,
                               is_bigendian=f.is_bigendian, step=f.step, data=np.frombuffer(f.data, np.uint8))
    return bytes(ts.serialize_cdr(img, IMAGE_TYPE))


def camera_info_msg(cam: CameraModel, stamp, frame_id: str) -> CameraInfo:
    """sensor_msgs/CameraInfo of a camera model."""
    m = CameraInfo()
    m.header.stamp, m.header.frame_id = stamp, frame_id
    for k, v in cam.camera_info_fields().items():
        setattr(m, k, v)
    return m


def pose_to_matrix(p: Pose) -> np.ndarray:
    q = (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)
    T = np.eye(4)
    T[:3, :3] = geometry.quat_to_matrix(q)
    T[:3, 3] = (p.position.x, p.position.y, p.position.z)
    return T


MAX_POSITION_M = 1e6  # a camera farther than this from the map origin is not a pose (a damaged message)


def observation_pose(obs) -> np.ndarray | None:
    """T_map_camera of a FeatureObservations, or None when localization had no pose (zero quaternion); ValueError
    for a quaternion without a rotation or a position that is not finite or absurdly far (over MAX_POSITION_M)."""
    q = obs.camera_pose.orientation
    if abs(q.x) + abs(q.y) + abs(q.z) + abs(q.w) == 0:
        return None
    p = obs.camera_pose.position
    t = np.array([p.x, p.y, p.z], np.float64)
    if not np.all(np.isfinite(t)) or np.abs(t).max() > MAX_POSITION_M:
        raise ValueError(f"camera position {t.tolist()} is not finite or beyond {MAX_POSITION_M:g} m")
    return pose_to_matrix(obs.camera_pose)


def matrix_to_pose(T: np.ndarray, p: Pose | None = None) -> Pose:
    p = p or Pose()
    q = geometry.matrix_to_quat(T[:3, :3])
    p.position.x, p.position.y, p.position.z = (float(v) for v in T[:3, 3])
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = (float(v) for v in q)
    return p


def pose_stamped(T: np.ndarray, header: Header, frame_id: str) -> PoseStamped:
    m = PoseStamped()
    m.header.stamp = header.stamp
    m.header.frame_id = frame_id
    matrix_to_pose(T, m.pose)
    return m


def transform_stamped(T: np.ndarray, stamp, parent: str, child: str) -> TransformStamped:
    m = TransformStamped()
    m.header.stamp = stamp
    m.header.frame_id = parent
    m.child_frame_id = child
    q = geometry.matrix_to_quat(T[:3, :3])
    m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = (float(v) for v in T[:3, 3])
    r = m.transform.rotation
    r.x, r.y, r.z, r.w = (float(v) for v in q)
    return m


_PF_TYPES: dict[np.dtype[Any], int] = {
    np.dtype(np.int8): 1, np.dtype(np.uint8): 2, np.dtype(np.int16): 3, np.dtype(np.uint16): 4,
    np.dtype(np.int32): 5, np.dtype(np.uint32): 6, np.dtype(np.float32): 7, np.dtype(np.float64): 8}


def cloud_msg(points: np.ndarray, header: Header, frame_id: str, extra: dict | None = None):
    """sensor_msgs/PointCloud2 with float32 x, y, z and optional per-point ``extra`` fields
    (name -> (N,) array of a PointField type, e.g. uint32 ids); no sensor_msgs_py on PyPI."""
    import array

    from sensor_msgs.msg import PointCloud2, PointField

    P = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    cols = [("x", P[:, 0]), ("y", P[:, 1]), ("z", P[:, 2])]
    for name, v in (extra or {}).items():
        v = np.asarray(v).reshape(-1)
        if len(v) != len(P) or v.dtype not in _PF_TYPES:
            raise ValueError(f"cloud field '{name}': {len(v)} values of {v.dtype} for {len(P)} points")
        cols.append((name, v))
    rec = np.zeros(len(P), dtype=[(n, v.dtype.newbyteorder("<")) for n, v in cols])  # packed, little-endian
    for n, v in cols:
        rec[n] = v
    m = PointCloud2()
    m.header.stamp = header.stamp
    m.header.frame_id = frame_id
    m.height, m.width = 1, len(P)
    fields = rec.dtype.fields
    assert fields is not None  # a structured dtype has its fields
    m.fields = [PointField(name=n, offset=fields[n][1], datatype=_PF_TYPES[np.dtype(v.dtype)], count=1)
                for n, v in cols]
    m.is_bigendian = False
    m.point_step, m.row_step = rec.dtype.itemsize, rec.dtype.itemsize * len(P)
    m.is_dense = True
    m.data = array.array("B", rec.tobytes())
    return m


def cloud_field(msg, name: str) -> np.ndarray:
    """One named field of a PointCloud2 as an (N,) array (ValueError if absent or malformed)."""
    f = next((f for f in msg.fields if f.name == name), None)
    if f is None:
        raise ValueError(f"PointCloud2 without a '{name}' field")
    dt = next((d for d, t in _PF_TYPES.items() if t == f.datatype), None)
    if dt is None:
        raise ValueError(f"PointCloud2 field '{name}' has unknown datatype {f.datatype}")
    n = msg.width * msg.height
    data = bytes(msg.data)
    if msg.point_step < f.offset + dt.itemsize or len(data) < n * msg.point_step:
        raise ValueError(f"PointCloud2 of {n} points with step {msg.point_step} has only {len(data)} bytes")
    raw = np.frombuffer(data, np.uint8, count=n * msg.point_step).reshape(n, msg.point_step)
    field = raw[:, f.offset:f.offset + dt.itemsize].copy().view(dt.newbyteorder(">" if msg.is_bigendian else "<"))
    return field.ravel().astype(dt)


def cloud_to_array(msg) -> np.ndarray:
    """x, y, z of a PointCloud2 into (N, 3)."""
    return np.stack([cloud_field(msg, k).astype(np.float64) for k in "xyz"], axis=1)


def deformable_points(msg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ids (N,) int64, (N, 3) points, flags (N,) uint8) of the tracker's deformable-points cloud (fields x, y, z,
    id and optionally flags, :func:`~simreal_nodes.assimilation.tracker.deformable_feedback`; a recording's older
    field drop is flags' bit 0; absent: no flag); ValueError when malformed."""
    ids = cloud_field(msg, "id").astype(np.int64)
    P = cloud_to_array(msg)
    names = [f.name for f in msg.fields]
    key = "flags" if "flags" in names else "drop" if "drop" in names else None
    flags = cloud_field(msg, key).astype(np.uint8) if key else np.zeros(len(ids), np.uint8)
    return ids, P, flags


def focus_msg(poly: np.ndarray, index: int, header: Header, frame_id: str) -> PolygonInstanceStamped:
    """A tracked object's predicted image region ((K, 2) pixels of the camera image in ``frame_id``) for the
    localization's feature budget; ``index``: the object's place in the scene's tracked objects."""
    m = PolygonInstanceStamped(header=Header(stamp=header.stamp, frame_id=frame_id))
    m.polygon = PolygonInstance(id=int(index), polygon=Polygon(
        points=[Point32(x=float(x), y=float(y), z=0.0) for x, y in np.asarray(poly, np.float64).reshape(-1, 2)]))
    return m


FOCUS_MAX_PX = 1e5  # a focus polygon's coordinates beyond this (pixels) are not an image region
FOCUS_MAX_POINTS = 10_000  # a tracked object's image hull has tens of corners
FOCUS_MAX_INDEX = 1024  # object indices of a scene's tracked objects


def focus_polygon(msg: PolygonInstanceStamped) -> tuple[int, np.ndarray]:
    """(object index, (K, 2) pixels) of :func:`focus_msg`'s message; ValueError for an index or a size no scene
    has, and for coordinates that are not finite or lie absurdly far off any image (over FOCUS_MAX_PX)."""
    index, n = int(msg.polygon.id), len(msg.polygon.polygon.points)
    if not 0 <= index < FOCUS_MAX_INDEX or n > FOCUS_MAX_POINTS:
        raise ValueError(f"focus polygon of object index {index} with {n} points (at most {FOCUS_MAX_INDEX} objects, "
                         f"{FOCUS_MAX_POINTS} points)")
    pts = np.array([(p.x, p.y) for p in msg.polygon.polygon.points], np.float64).reshape(-1, 2)
    if not np.all(np.isfinite(pts)) or (len(pts) and np.abs(pts).max() > FOCUS_MAX_PX):
        raise ValueError(f"focus polygon of {len(pts)} points has non-finite coordinates or ones beyond "
                         f"{FOCUS_MAX_PX:g} px")
    return index, pts


# simreal_msgs ------------------------------------------------------------------------------------------------


def observation_arrays(obs: FeatureObservations) -> tuple[np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]:
    """(T_map_camera or None, point ids (N,), map points (N, 3), pixels (N, 2)) of a FeatureObservations;
    ValueError when the three lists disagree in length."""
    ids = np.asarray(obs.point_ids, dtype=np.int64)
    P = np.asarray(obs.points_xyz, dtype=np.float64)
    uv = np.asarray(obs.pixels_uv, dtype=np.float64)
    if len(P) != 3 * len(ids) or len(uv) != 2 * len(ids):
        raise ValueError(f"malformed observations ({len(ids)} ids, {len(P)} point coordinates, {len(uv)} pixel "
                         "coordinates: expected 3 and 2 per id)")
    P, uv = P.reshape(-1, 3), uv.reshape(-1, 2)
    return observation_pose(obs), ids, P, uv


def observations_msg(r: Localization, stamp, frame_id: str) -> FeatureObservations:
    """FeatureObservations of one localized frame: the camera pose (zero quaternion: none this frame) and the map
    points matched in the image, with their pixels and whether they voted for the pose."""
    obs = FeatureObservations()
    obs.header.stamp = stamp
    obs.header.frame_id = frame_id
    if r.T_wc is not None:
        matrix_to_pose(r.T_wc, obs.camera_pose)
    else:
        obs.camera_pose.orientation.w = 0.0  # no pose this frame (quaternion zero = invalid)
    if r.T_wc is not None and len(r.obs_ids):
        obs.point_ids = [int(i) for i in r.obs_ids]
        obs.points_xyz = r.obs_pos.astype(np.float32).ravel().tolist()
        obs.pixels_uv = np.asarray(r.obs_uv, np.float32).ravel().tolist()
        obs.flags = [FeatureObservations.FLAG_POSE_INLIER if x else 0 for x in r.obs_inlier]
    return obs


def localization_status_msg(r: Localization, stamp, node: str, mode: str) -> TrackingStatus:
    """TrackingStatus of one localized frame: state, reason, features tracked and the map's size."""
    st = TrackingStatus()
    st.header.stamp = stamp
    st.node, st.mode, st.state, st.reason = node, mode, int(r.state), r.reason
    st.tracked_features, st.map_points, st.keyframes = r.features, r.map_points, r.keyframes
    st.localization_only = r.localization_only
    return st


def contact_msg(oid: str, st: ContactState, source: str, stamp, frame_id: str) -> ContactMsg:
    """simreal_msgs/ContactState of one object's Alg. 5.1 state (a non-finite contact point is sent as zeros)."""
    c = ContactMsg()
    c.header.stamp = stamp
    c.header.frame_id = frame_id
    c.object_id, c.state, c.in_contact = oid, int(st.state), bool(st.in_contact)
    c.contact_node, c.load_point = int(st.node), int(st.load_point)
    c.pseudo_time, c.min_distance = float(st.pseudo_time), float(st.min_distance)
    cp = st.contact_point
    c.contact_point.x, c.contact_point.y, c.contact_point.z = (float(v) if np.isfinite(v) else 0.0 for v in cp)
    c.source, c.points_used, c.reason = source, int(st.points_used), st.reason
    return c


def contact_parameters_msg(oid: str, tr: ContactTracker, st: ContactState, stamp) -> ModelParameters:
    """ModelParameters of a contact (load point / position and pseudo-time or load scale): what the overlay draws.
    No fit behind them: no covariance, no residual."""
    from simreal_nodes.rom.state import CONTACT_SEP  # here: importing rom (scipy) costs every node ~50 MB at start

    m = ModelParameters()
    m.header.stamp = stamp
    m.header.frame_id = oid
    m.object_id, m.model_id = oid, tr.model.model_id
    names = tr.parameter_names()
    axes_units = [a.unit for a in tr.model.axes]
    units = axes_units + [""] * (len(names) - len(axes_units))
    all_names, all_units, values = list(names), list(units), [float(v) for v in tr.parameters(st)]
    # several contacts at once (collision.max_contacts): the further ones as name@k, their deformations added
    for k, c in enumerate(tr.states()[1:], start=2):
        all_names += [f"{n}{CONTACT_SEP}{k}" for n in names]
        all_units += units
        values += [float(v) for v in tr.parameters(c)]
    m.names, m.units, m.values = all_names, all_units, values
    m.frozen = [False] * len(m.names)
    m.covariance = [0.0] * (len(m.names) ** 2)
    m.residual_rms_px = -1.0
    m.state = ModelParameters.STATE_OK if st.state != ContactPhase.NO_DATA else ModelParameters.STATE_LOW_CONFIDENCE
    m.reason = st.reason
    return m


def estimate_msg(oid: str, model_id: str, est: Estimate, stamp) -> ModelParameters:
    """ModelParameters of a deformable tracker's estimate (a non-finite covariance entry is sent as inf, a
    non-finite residual as -1)."""
    m = ModelParameters()
    m.header.stamp = stamp
    m.header.frame_id = oid
    m.object_id = oid
    m.model_id = model_id
    m.names, m.units = list(est.names), list(est.units)
    m.values = [float(v) for v in est.values]
    m.frozen = [bool(f) for f in est.frozen]
    m.covariance = [float(c) if np.isfinite(c) else float("inf") for c in np.asarray(est.cov).ravel()]
    m.residual_rms_px = float(est.rms_px) if np.isfinite(est.rms_px) else -1.0
    m.inliers, m.measurements, m.iterations = int(est.inliers), int(est.measurements), int(est.iterations)
    m.state, m.reason = int(est.state), est.reason
    return m
