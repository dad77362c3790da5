"""Run as a separate process by test_two_process.py: publishes N images and N ModelParameters (``N W H [READERS]``:
once READERS subscribers of the parameters, 2 by default, and one of the images where READERS is over 1, are
there, or after 20 s)."""

import sys
import time

import numpy as np
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import Image
from simreal_msgs.msg import ModelParameters

from simreal_nodes.io.images import fill_image_msg
from simreal_nodes.ros.qos import data_qos, reliable_qos


def params_msg(i: int) -> ModelParameters:
    m = ModelParameters()
    m.header.stamp.sec, m.header.stamp.nanosec = 100 + i, 0
    m.header.frame_id = "beam"
    m.object_id, m.model_id = "beam", "alu.h5#0123"
    m.names, m.units = ["s", "E"], ["m", "Pa"]
    m.values = [0.01 * i, 69e9]
    m.frozen = [False, True]
    m.covariance = [1e-6, 0.0, 0.0, 1e14]
    m.residual_rms_px, m.inliers, m.measurements, m.iterations = 0.25 + i, 30 + i, 40, 5
    m.state, m.reason = ModelParameters.STATE_OK, f"frame {i}"
    return m


def main():
    n, w, h = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    readers = int(sys.argv[4]) if len(sys.argv) > 4 else 2  # the parameters' subscribers to wait for
    rclpy.init()
    node = Node("test_publisher")
    pi = node.create_publisher(Image, "/test/image", data_qos(True))
    pp = node.create_publisher(ModelParameters, "/test/params", reliable_qos(100))
    t_end = time.monotonic() + 20
    while ((readers > 1 and pi.get_subscription_count() == 0) or pp.get_subscription_count() < readers) \
            and time.monotonic() < t_end:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(0.5)
    for i in range(n):
        img = np.full((h, w, 3), i % 256, np.uint8)
        msg = Image()
        msg.header.stamp.sec = 100 + i
        fill_image_msg(msg, img, "rgb8")
        pi.publish(msg)
        pp.publish(params_msg(i))
        time.sleep(1 / 30)
    time.sleep(1.0)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
