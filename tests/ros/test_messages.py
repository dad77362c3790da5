"""Message helpers shared by the nodes: PointCloud2 with extra per-point fields (the tracker's feedback to the
localization: predicted positions, map point ids, drop flags)."""

import numpy as np
import pytest

pytest.importorskip("rclpy")

from std_msgs.msg import Header

from simreal_nodes.ros.convert import cloud_field, cloud_msg, cloud_to_array


def test_cloud_with_ids_and_flags_round_trips():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(7, 3))
    ids = np.array([3, 9, 4000000000, 0, 1, 2, 8], np.uint32)
    drop = np.array([0, 1, 0, 0, 1, 0, 0], np.uint8)
    m = cloud_msg(P, Header(), "map", {"id": ids, "drop": drop})
    assert m.header.frame_id == "map" and m.width == 7 and m.point_step == 17
    assert np.allclose(cloud_to_array(m), P.astype(np.float32))
    assert np.array_equal(cloud_field(m, "id"), ids) and np.array_equal(cloud_field(m, "drop"), drop)
    empty = cloud_msg(np.zeros((0, 3)), Header(), "map", {"id": np.zeros(0, np.uint32)})
    assert cloud_to_array(empty).shape == (0, 3)


def test_deformable_points_read_their_flags_and_a_recording_s_older_drop_field():
    from simreal_nodes.ros.convert import deformable_points

    P = np.arange(12.0).reshape(4, 3)
    ids = np.array([5, 6, 7, 8], np.uint32)
    flags = np.array([0, 1, 2, 3], np.uint8)
    got = deformable_points(cloud_msg(P, Header(), "map", {"id": ids, "flags": flags}))
    assert np.array_equal(got[0], ids) and np.allclose(got[1], P) and np.array_equal(got[2], flags)
    old = deformable_points(cloud_msg(P, Header(), "map", {"id": ids, "drop": np.array([0, 1, 0, 1], np.uint8)}))
    assert np.array_equal(old[2], [0, 1, 0, 1])  # drop was bit 0
    bare = deformable_points(cloud_msg(P, Header(), "map", {"id": ids}))
    assert np.array_equal(bare[2], np.zeros(4))


def test_malformed_clouds_are_refused_with_a_reason():
    m = cloud_msg(np.zeros((4, 3)), Header(), "map", {"id": np.arange(4, dtype=np.uint32)})
    with pytest.raises(ValueError, match="'drop'"):
        cloud_field(m, "drop")
    m.data = m.data[:-5]  # truncated
    with pytest.raises(ValueError, match="bytes"):
        cloud_field(m, "id")
    with pytest.raises(ValueError, match="3 values"):
        cloud_msg(np.zeros((4, 3)), Header(), "map", {"id": np.arange(3, dtype=np.uint32)})


def test_focus_polygon_round_trips():
    from simreal_nodes.ros.convert import focus_msg, focus_polygon

    poly = np.array([[10.5, 20.0], [300.0, 22.25], [280.0, 200.0], [12.0, 190.0]])
    head = Header()
    head.stamp.sec = 7
    m = focus_msg(poly, 2, head, "camera_optical")
    assert m.header.frame_id == "camera_optical" and m.header.stamp.sec == 7
    index, back = focus_polygon(m)
    assert index == 2 and np.allclose(back, poly, atol=1e-4)


def test_hostile_focus_polygons_are_refused_with_a_reason():
    """Found by the graph fuzz: a focus polygon with NaN or huge coordinates made the localization's frame fail
    (int(NaN) in the feature extractor), and invented object indices with big polygons piled up in its memory."""
    from simreal_nodes.ros.convert import focus_msg, focus_polygon

    poly = np.array([[10.0, 20.0], [30.0, 22.0], [28.0, 40.0]])
    for bad, what in ((np.r_[poly[:2], [[np.nan, 1.0]]], "non-finite"), (poly * 1e30, "non-finite|beyond"),
                      (poly + 2e5, "beyond")):
        with pytest.raises(ValueError, match=what):
            focus_polygon(focus_msg(bad, 0, Header(), "cam"))
    with pytest.raises(ValueError, match="object index"):
        focus_polygon(focus_msg(poly, 5000, Header(), "cam"))
    with pytest.raises(ValueError, match="points"):
        focus_polygon(focus_msg(np.zeros((20_000, 2)), 0, Header(), "cam"))


def test_a_failure_in_a_synchronized_frame_is_reported_with_its_stamp():
    """The guard reports an exception to /simreal/progress with the stamp of the frame it failed on; a frame of
    synchronized messages (a dict) is found by its messages' stamp (before, such failures went uncounted)."""
    from simreal_nodes.ros.node import _stamp_of

    h = Header()
    h.stamp.sec = 42
    frame = {"image": type("M", (), {"header": h})(), "obs": None}
    assert _stamp_of((frame,)).sec == 42
    assert _stamp_of(({"x": 1},)) is None


def test_observations_whose_lists_disagree_are_refused_with_their_lengths():
    from simreal_msgs.msg import FeatureObservations

    from simreal_nodes.ros.convert import observation_arrays

    obs = FeatureObservations(point_ids=[1, 2], points_xyz=[0.0] * 6, pixels_uv=[0.0] * 4)
    _T, _ids, P, uv = observation_arrays(obs)
    assert P.shape == (2, 3) and uv.shape == (2, 2)
    obs.points_xyz = [0.0] * 7  # found by the graph fuzz: numpy's "cannot reshape" reached the user before
    with pytest.raises(ValueError, match=r"2 ids, 7 point coordinates, 4 pixel coordinates"):
        observation_arrays(obs)


def test_a_collision_with_two_contacts_sends_both_and_the_overlay_draws_their_sum():
    """collision.max_contacts: 2 from a scene object, two probes in the points, the ModelParameters message the
    collision node publishes (the second contact as name@2), and the overlay's state from it: the deformation the
    tracker holds, both contacts summed."""
    from simreal_nodes import geometry as G
    from simreal_nodes.collision.scene import ContactScene
    from simreal_nodes.render.overlay import ObjectOverlay
    from simreal_nodes.ros.convert import contact_parameters_msg
    from simreal_nodes.scene.schema import COLLISION
    from simreal_nodes.spec import Context
    from tests.modelkit import strip_load_model

    m = strip_load_model()
    coll = COLLISION.validate({"enabled": True, "threshold_m": 0.002, "step": 0.05, "anywhere": True,
                               "max_contacts": 2}, "collision", Context(source="test"))
    scene = ContactScene([{"id": "strip", "anchor": {"pose": [0.0, 0, 0, 0, 0, 0, 1]}, "collision": coll}],
                         {"strip": m})
    tr = scene.trackers["strip"]
    assert tr.max_contacts == 2
    probes = np.array([[0.12, 0.015, 0.001], [0.27, 0.015, -0.002]])
    for _ in range(3):
        tr.update(probes)
    assert len(tr.contacts) == 2
    msg = contact_parameters_msg("strip", tr, tr.state, Header().stamp)
    assert list(msg.names) == ["s", "load_scale", "s@2", "load_scale@2"] and len(msg.units) == 4
    ob = ObjectOverlay(m, np.eye(4), "displacement", modes=m.fields["displacement"].n_modes)
    V, _, _ = ob.geometry(list(msg.names), list(msg.values), G.make_T(G.rot_axis("x", np.pi), [0.15, 0, 1.0]),
                          _camera())
    np.testing.assert_allclose(V, m.points[ob.nodes] + tr.displacement(ob.nodes), atol=1e-9)


def _camera():
    from simreal_nodes.camera import CameraModel

    return CameraModel.from_intrinsics(64, 48, 100.0, 100.0, 32.0, 24.0)


def test_an_observation_pose_far_off_or_without_rotation_is_refused():
    """Found by the graph fuzz: a camera position of 1e300 m (or NaN) went through to the collision node's depth
    back-projection; a quaternion without a rotation is refused as before."""
    from simreal_msgs.msg import FeatureObservations

    from simreal_nodes.ros.convert import observation_pose

    obs = FeatureObservations()
    obs.camera_pose.orientation.w = 1.0
    assert observation_pose(obs).shape == (4, 4)
    for bad in (1e300, float("nan"), 2e6):
        obs.camera_pose.position.x = bad
        with pytest.raises(ValueError, match="camera position"):
            observation_pose(obs)
    obs.camera_pose.position.x = 0.0
    obs.camera_pose.orientation.x = float("inf")
    with pytest.raises(ValueError, match="quaternion"):
        observation_pose(obs)


def test_the_message_helpers_do_not_pull_scipy_into_every_node():
    """Every node imports these helpers; importing the reduced-model code from them (scipy) cost each node ~50 MB at
    start, the localization's standby 104 -> 165 MB (stop 47, found by the respawn benchmark's memory column)."""
    import subprocess
    import sys

    code = "import sys, simreal_nodes.ros.convert; print('scipy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("encoding, dtype, channels, pad", [("rgb8", np.uint8, 3, 0), ("32FC1", np.float32, 1, 0),
                                                            ("16UC1", np.uint16, 1, 6), ("mono8", np.uint8, 1, 3)])
def test_an_image_read_from_its_serialized_bytes_equals_rclpy_s_message(encoding, dtype, channels, pad):
    """The nodes take images serialized (``subscribe_image``): the pixels, stamp and frame must be rclpy's own."""
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Image

    from simreal_nodes.io.images import image_to_array
    from simreal_nodes.ros.convert import image_view

    rng = np.random.default_rng(1)
    h, w = 5, 7
    px = (rng.random((h, w, channels)) * 1000).astype(dtype).reshape((h, w) if channels == 1 else (h, w, channels))
    step = w * channels * np.dtype(dtype).itemsize + pad
    rows = np.zeros((h, step), np.uint8)
    rows[:, :step - pad] = px.reshape(h, -1).view(np.uint8)
    msg = Image(height=h, width=w, encoding=encoding, step=step, data=rows.tobytes())
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 1700000000, 123456789, "camera_optical"
    raw = serialize_message(msg)
    view = image_view(raw)
    assert isinstance(view.header, Header)  # output messages take its stamp as rclpy's
    assert (view.header.stamp.sec, view.header.stamp.nanosec, view.header.frame_id) == (1700000000, 123456789,
                                                                                         "camera_optical")
    assert np.array_equal(image_to_array(view), px)
    assert np.array_equal(image_to_array(view), image_to_array(deserialize_message(raw, Image)))


def test_bytes_that_are_no_serialized_image_are_refused():
    from rosbags.serde import SerdeError

    from simreal_nodes.ros.convert import image_view

    with pytest.raises(SerdeError):
        image_view(b"\x00\x01\x00\x00" + b"\xff" * 30)


def test_an_image_passed_on_serialized_keeps_its_pixels_or_takes_new_ones_and_the_camera_frame():
    """The ingest node passes raw images on serialized (``image_cdr``): rclpy must read back the frame it set and
    the pixels, its own or the undistorted ones, with their size, encoding and step."""
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Image

    from simreal_nodes.io.images import image_to_array
    from simreal_nodes.ros.convert import image_cdr, read_image_cdr

    px = np.arange(4 * 6 * 3, dtype=np.uint8).reshape(4, 6, 3)
    padded = np.pad(px.reshape(4, 18), ((0, 0), (0, 2)))  # rows of 18 bytes in a step of 20
    msg = Image(height=4, width=6, encoding="rgb8", step=20, data=padded.tobytes())
    msg.header.stamp.sec, msg.header.frame_id = 42, "sensor"
    m = read_image_cdr(serialize_message(msg))
    same = deserialize_message(image_cdr(m, "camera_optical_frame"), Image)
    assert (same.header.stamp.sec, same.header.frame_id, same.step) == (42, "camera_optical_frame", 20)
    assert np.array_equal(image_to_array(same), px)
    new = np.full((3, 5, 3), 7, np.uint8)
    other = deserialize_message(image_cdr(m, "camera_optical_frame", new), Image)
    assert (other.height, other.width, other.encoding, other.step, other.header.stamp.sec) == (3, 5, "rgb8", 15, 42)
    assert np.array_equal(image_to_array(other), new)


def test_a_decoded_image_published_serialized_reads_back_with_its_stamp_frame_and_pixels():
    """The ingest node publishes a decompressed image as serialized bytes (``array_image_cdr``): rclpy reads the
    stamp, the frame, the encoding and the pixels back (colour and 16-bit depth)."""
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Image

    from simreal_nodes.io.images import image_to_array
    from simreal_nodes.ros.convert import array_image_cdr

    rng = np.random.default_rng(0)
    for px, enc in ((rng.integers(0, 256, (5, 7, 3), dtype=np.uint8), "bgr8"),
                    (rng.integers(0, 65535, (4, 6), dtype=np.uint16), "16UC1")):
        back = deserialize_message(array_image_cdr(px, enc, Time(sec=12, nanosec=345), "camera_optical_frame"), Image)
        assert (back.header.stamp.sec, back.header.stamp.nanosec, back.header.frame_id) == (12, 345,
                                                                                          "camera_optical_frame")
        assert (back.height, back.width, back.encoding) == (px.shape[0], px.shape[1], enc)
        assert np.array_equal(image_to_array(back), px)
