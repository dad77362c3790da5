"""The tracker node's frame checks: an image or depth image of another size than its CameraInfo says is dropped
with the reason before any arithmetic. The graph fuzz once drove a smaller image into a dense tracker's reference
view, which failed deep in the template (``ValueError: need at least one array to concatenate``), caught only by the
node's guard (docs/status.md, stop 121)."""

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")

from sensor_msgs.msg import CameraInfo, Image  # noqa: E402

from simreal_nodes.synth.samples import sample  # noqa: E402

pytestmark = pytest.mark.ros

W, H = 320, 240


def _info() -> CameraInfo:
    f, cx, cy = 300.0, 159.5, 119.5
    return CameraInfo(width=W, height=H, distortion_model="plumb_bob", d=[0.0] * 5,
                      k=[f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0], r=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
                      p=[f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0])


def _image(w: int, h: int, encoding: str = "rgb8") -> Image:
    msg = Image(width=w, height=h, encoding=encoding)
    if encoding == "32FC1":
        msg.step, msg.data = 4 * w, np.full((h, w), 0.6, np.float32).tobytes()
    else:
        msg.step, msg.data = 3 * w, bytes(np.full((h, w, 3), 128, np.uint8))
    msg.header.stamp.sec = 7
    return msg


@pytest.mark.parametrize("case", ["image", "depth image"])
def test_a_frame_of_another_size_than_the_camera_is_dropped_with_the_reason(tmp_path, case):
    from rclpy.parameter import Parameter

    from simreal_nodes.ros.nodes.tracker import TrackerNode

    _, src = sample("aluminium_beam_320x240")
    scene = yaml.safe_load(src.read_text())
    scene["camera"]["depth"] = "/camera/depth/image_raw"
    scene["objects"][0]["tracking"]["measurements"] = "dense"  # reads the image, and depth for its reference view
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    ctx = rclpy.Context()  # its own: whatever another test left initialized stays as it was
    rclpy.init(context=ctx)
    try:
        node = TrackerNode(context=ctx, parameter_overrides=[Parameter("scene_file", value=str(path))])
        try:
            node.on_info(_info())
            assert node.core.cam is not None and node.core.needs_depth
            small = (W // 2, H // 2)
            frame = {"image": _image(*small)} if case == "image" else \
                {"image": _image(W, H), "depth": _image(*small, "32FC1")}
            node.process(frame)
            assert node.metrics.errors == 0, node.metrics.last_error
            assert node.metrics.dropped == 1
            assert node.metrics.last_drop_reason == (f"malformed image: {case} is {W // 2}x{H // 2}, CameraInfo "
                                                     f"says {W}x{H}")
        finally:
            node.close()
            node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
