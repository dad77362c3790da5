"""CDR written from numpy arrays: the bytes must read back as the same message with the reference
deserializer (rosbags), field by field."""

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.io import bags
from simreal_nodes.io.cdr import TriangleListMarker, marker_array_cdr


def test_triangle_list_marker_array_reads_back():
    rng = np.random.default_rng(0)
    pose = G.make_T(G.rot_axis("z", 0.3) @ G.rot_axis("x", -0.2), [0.1, -0.2, 0.3])
    ms = [TriangleListMarker("simreal/beam", 0, pose, rng.random((9, 3)), rng.random((9, 3))),
          TriangleListMarker("simreal/boot", 1, np.eye(4), np.zeros((0, 3)), np.zeros((0, 4))),
          TriangleListMarker("x", 7, np.eye(4), rng.random((3, 3)), rng.random((3, 4)))]
    raw = marker_array_cdr(ms, 1_700_000_123_456_789_012 % 2**62, "map")
    arr = bags.typestore().deserialize_cdr(raw, "visualization_msgs/msg/MarkerArray")
    assert len(arr.markers) == 3
    for m, r in zip(ms, arr.markers):
        assert r.header.frame_id == "map" and r.ns == m.ns and r.id == m.id and r.type == 11 and r.action == 0
        assert r.header.stamp.sec * 10**9 + r.header.stamp.nanosec == 1_700_000_123_456_789_012 % 2**62
        p, q = r.pose.position, r.pose.orientation
        T = G.make_T(G.quat_to_matrix((q.x, q.y, q.z, q.w)), [p.x, p.y, p.z])
        np.testing.assert_allclose(T, m.pose, atol=1e-12)
        got = np.array([[v.x, v.y, v.z] for v in r.points]).reshape(-1, 3)
        np.testing.assert_array_equal(got, m.points)
        col = np.array([[c.r, c.g, c.b, c.a] for c in r.colors], np.float32).reshape(-1, 4)
        want = np.c_[m.colors, np.ones(len(m.colors))] if m.colors.shape[1] == 3 else m.colors
        np.testing.assert_array_equal(col, want.astype(np.float32))
        assert r.scale.x == 1.0 and r.texture_resource == "" and len(r.uv_coordinates) == 0
        assert r.mesh_file.filename == "" and not r.mesh_use_embedded_materials and r.text == ""


def test_mismatched_colours_are_refused():
    import pytest

    with pytest.raises(ValueError, match="colours"):
        marker_array_cdr([TriangleListMarker("m", 0, np.eye(4), np.zeros((6, 3)), np.zeros((5, 3)))], 0, "map")
