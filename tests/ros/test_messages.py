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


def test_observations_whose_lists_disagree_are_refused_with_their_lengths():
    from simreal_msgs.msg import FeatureObservations

    from simreal_nodes.ros.convert import observation_arrays

    obs = FeatureObservations(point_ids=[1, 2], points_xyz=[0.0] * 6, pixels_uv=[0.0] * 4)
    _T, _ids, P, uv = observation_arrays(obs)
    assert P.shape == (2, 3) and uv.shape == (2, 2)
    obs.points_xyz = [0.0] * 7  # found by the graph fuzz: numpy's "cannot reshape" reached the user before
    with pytest.raises(ValueError, match=r"2 ids, 7 point coordinates, 4 pixel coordinates"):
        observation_arrays(obs)
