"""Bags written by rosbags: self-describing custom types, damage reports, salvage of truncated files."""


import numpy as np
import pytest

from simreal_nodes.errors import BagError
from simreal_nodes.io import bags
from tests.helpers import write_camera_bag


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_custom_message_round_trip_is_self_describing(tmp_path, storage):
    ts = bags.typestore()
    P = ts.types["simreal_msgs/msg/ModelParameters"]
    H = ts.types["std_msgs/msg/Header"]
    T = ts.types["builtin_interfaces/msg/Time"]
    msg = P(header=H(stamp=T(sec=5, nanosec=7), frame_id="beam"), object_id="beam", model_id="alu.h5#abc",
            names=["s"], units=["m"], values=np.array([0.25]), frozen=np.array([False]), covariance=np.array([1e-6]),
            residual_rms_px=0.4, inliers=37, measurements=40, iterations=4, state=0, reason="")
    path = tmp_path / "p"
    with bags.BagWriter(path, storage) as w:
        w.write("/simreal/objects/beam/parameters", 5 * 10**9, msg, "simreal_msgs/msg/ModelParameters")
    # a fresh reader with only the stock Jazzy store still decodes it: definitions travel in the bag
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
        (con, _t, raw), = list(r.messages())
        back = r.deserialize(raw, con.msgtype)
    assert con.msgtype == "simreal_msgs/msg/ModelParameters"
    assert back.names == ["s"] and back.values[0] == 0.25 and back.inliers == 37 and back.model_id == "alu.h5#abc"


def test_read_reports_gaps_and_out_of_order(tmp_path):
    ts = bags.typestore()
    from tests.helpers import image_obj
    path = tmp_path / "g"
    with bags.BagWriter(path) as w:
        stamps = [0, 1, 2, 3, 20, 21, 19, 22]  # a gap after 3, then 19 after 21
        for k, s in enumerate(stamps):
            t = 10**9 + s * 33_333_333
            w.write("/camera/image_raw", 10**9 + k * 33_333_333 + (500_000_000 if k >= 4 else 0),
                    image_obj(ts, np.zeros((2, 2, 3), np.uint8), "rgb8", (t // 10**9, t % 10**9)),
                    "sensor_msgs/msg/Image")
    rep = bags.BagReport()
    n = sum(1 for _ in bags.read_bag(path, rep))
    assert n == 8
    assert len(rep.gaps) == 1 and rep.gaps[0][2] == pytest.approx(0.533, abs=0.01)
    assert len(rep.out_of_order) == 1 and rep.out_of_order[0][1] == 6
    assert "gap" in rep.summary() and "out-of-order" in rep.summary()


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_bag_folder_named_dot_bag_reads_whole(tmp_path, storage):
    """A rosbag2 folder named 'run.bag' (rosbags takes such a path for a ROS 1 bag file) reads as the bag it is: every
    message, no damage reported (it used to say 'damaged' and read the mcap's records one by one)."""
    path = tmp_path / "run.bag"
    stamps = write_camera_bag(path, n=12, storage=storage)
    rep = bags.BagReport()
    got = [m for m in bags.read_bag(path, rep) if m.topic == "/camera/image_raw"]
    assert not rep.damage and not rep.salvaged and rep.problems == 0, rep.summary()
    assert [bags.stamp_ns(bags.decode(m)) for m in got] == stamps
    assert "/camera/image_raw" in bags.bag_topics(path)


def test_truncated_mcap_is_salvaged(tmp_path):
    path = tmp_path / "b"
    stamps = write_camera_bag(path, n=40)
    f = next(path.glob("*.mcap"))
    data = f.read_bytes()
    f.write_bytes(data[: int(len(data) * 0.6)])
    rep = bags.BagReport()
    got = [m for m in bags.read_bag(path, rep) if m.topic == "/camera/image_raw"]
    assert rep.salvaged and rep.damage
    assert 5 <= len(got) < 40  # the messages before the cut are there, in order
    s = [bags.stamp_ns(bags.decode(m)) for m in got]
    assert s == stamps[: len(s)]


def test_corrupt_and_missing_bags_raise_clear_errors(tmp_path):
    with pytest.raises(BagError, match="bag not found"):
        list(bags.read_bag(tmp_path / "nope"))
    path = tmp_path / "c"
    write_camera_bag(path, n=5, storage="sqlite3")
    db = next(path.glob("*.db3"))
    db.write_bytes(b"garbage" * 100)
    with pytest.raises(BagError, match="cannot read bag"):
        list(bags.read_bag(path))


def test_undecodable_message_is_reported_not_raised(tmp_path):
    path = tmp_path / "u"
    with bags.BagWriter(path) as w:
        w.add_topic("/camera/image_raw", "sensor_msgs/msg/Image")
        w.write_raw("/camera/image_raw", 1, b"\x00\x01\x00\x00\xff\xff")
    rep = bags.BagReport()
    assert list(bags.read_bag(path, rep)) == []
    assert len(rep.undecodable) == 1 and "undecodable" in rep.summary()


def test_writer_refuses_to_overwrite(tmp_path):
    (tmp_path / "x").mkdir()
    with pytest.raises(BagError, match="already exists"):
        bags.BagWriter(tmp_path / "x")
