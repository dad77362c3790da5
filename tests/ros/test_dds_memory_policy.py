"""The history memory policy the nodes' environment gives a subscription (simreal_nodes/ros/fastdds_shm.xml with
RMW_FASTRTPS_USE_QOS_FROM_XML=1: DYNAMIC readers): large messages leave nothing behind once taken, where
rmw_fastrtps's own policy keeps (depth + 1) buffers as large as the largest message seen
(benchmarks/dds_pool_memory.py, whose subscriber and probe this runs with fewer messages)."""

import os

import pytest

rclpy = pytest.importorskip("rclpy")

from benchmarks.dds_pool_memory import run_case  # noqa: E402
from simreal_nodes.launch import FASTDDS_PROFILE, QOS_FROM_XML, ros_environment  # noqa: E402

pytestmark = pytest.mark.ros


def test_the_nodes_environment_takes_the_profiles_policy_unless_told_otherwise():
    base = {"PATH": "/usr/bin:/bin"}
    assert ros_environment(base)[QOS_FROM_XML] == "1"
    assert ros_environment(base | {QOS_FROM_XML: "0"})[QOS_FROM_XML] == "0"  # the user's word stands
    own = ros_environment(base | {"FASTRTPS_DEFAULT_PROFILES_FILE": "/elsewhere/profile.xml"})
    assert QOS_FROM_XML not in own  # a user's own profile may not set the policies: rmw_fastrtps's own apply
    assert ros_environment(base)["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(FASTDDS_PROFILE)


def test_a_subscription_keeps_no_buffers_of_large_messages_under_the_nodes_policy(tmp_path):
    saved = dict(os.environ)
    os.environ.update(ros_environment())
    rclpy.init()
    try:
        rows = {policy: run_case("random sizes", "reliable", 10, policy, tmp_path, messages=400)
                for policy in ("rmw default", "dynamic")}
    finally:
        rclpy.shutdown()
        os.environ.clear()
        os.environ.update(saved)
    def shown(r: dict) -> str:  # pytest cuts a long dict short: what tells a lagging subscriber from a kept buffer
        return f"received {r['received']}, in use (MB) {r['in_use_series']}, last read {r['settle_s']:.1f} s after"

    for r in rows.values():
        assert r["received"] and r["received"] > 50, shown(r)
    # 400 messages of up to 3 MB: the preallocating reader keeps about 11 buffers near 3 MB; the dynamic one frees them
    # (read once the subscriber's memory has stopped moving: a CI host once read it 9 MB up 2 s after the last message)
    assert rows["rmw default"]["in_use_growth"] > 15.0, shown(rows["rmw default"])
    assert rows["dynamic"]["in_use_growth"] < 3.0, shown(rows["dynamic"])


def test_fast_dds_reads_the_whole_profile():
    """Fast DDS reports a profile it cannot parse on stderr and goes on with its defaults (no shared-memory segment
    of 32 MB, no policies): a node started in the nodes' environment must not see such an error."""
    import subprocess
    import sys

    code = ("import rclpy; rclpy.init(); n = rclpy.create_node('profile_check'); "
            "from sensor_msgs.msg import Image; n.create_subscription(Image, '/profile_check', lambda m: None, 10); "
            "n.create_publisher(Image, '/profile_check', 10); print('up'); rclpy.shutdown()")
    r = subprocess.run([sys.executable, "-c", code], env=ros_environment(), capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "up" in r.stdout, r.stderr
    assert "XMLPARSER" not in r.stderr and "Error" not in r.stderr, r.stderr
