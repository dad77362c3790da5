"""The tracker asks the localization node over ROS to stop mapping once the beam deforms
(``freeze_map_on_deformation``), and it reaches that node's service when the whole graph runs in a namespace:
the service name is relative to the tracker's namespace, not ``/localization/...``. And where the node runs its
local BA: lossless in its own callback, live in a mapping process."""

import pytest
import yaml

pytest.importorskip("rclpy")
pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")

from simreal_nodes.ros.commands import replay
from simreal_nodes.synth.samples import render_sample, sample

pytestmark = pytest.mark.ros


def test_tracker_freezes_the_map_through_the_namespaced_service(tmp_path):
    name = "aluminium_beam_320x240"  # markers -> tracker -> overlay; the load bends the beam from the first frames
    bag, scene = sample(name)
    if not bag.is_dir():
        render_sample(name, tmp_path)
        bag, scene = tmp_path / name, tmp_path / f"{name}.yaml"
    doc = yaml.safe_load(scene.read_text())
    doc["localization"]["freeze_map_on_deformation"] = True
    doc["overlay"]["enabled"] = False
    f = tmp_path / "scene.yaml"
    f.write_text(yaml.safe_dump(doc))
    lines: list[str] = []
    stats, _report, _counts = replay(str(bag), str(f), lossless=True, echo=lines.append, namespace="/simreal_ns_test")
    assert stats.frames_completed > 0
    out = "\n".join(lines)
    assert any(x.startswith("[tracker]") and "localization-only mode requested" in x for x in lines), out
    # the localization node's own word: the request arrived and was served
    assert any(x.startswith("[localization]") and "localization-only on" in x for x in lines), out


@pytest.mark.parametrize("lossless", [True, False])
def test_a_lossless_localization_runs_its_local_ba_in_its_own_process_a_live_one_apart(lossless):
    """The node's default for ``async_mapping``: lossless (every frame, in order) the local BA in the callback, each
    keyframe's before the next frame, so that a lock-step replay repeats to the bit (`replay_parameters` asks for the
    mapping process where frames are in flight); live in a process of its own, off the tracking's core."""
    import rclpy
    from rclpy.parameter import Parameter

    from simreal_nodes.ros.nodes.localization import LocalizationNode

    _, scene = sample("crossed_beams_probe_320x240")  # a committed RGB-D SLAM scene file
    ctx = rclpy.Context()  # its own: whatever another test left initialized stays as it was
    rclpy.init(context=ctx)
    try:
        node = LocalizationNode(context=ctx, parameter_overrides=[Parameter("scene_file", value=str(scene)),
                                                                  Parameter("lossless", value=lossless)])
        try:
            assert node.mode == "rgbd"
            assert node.get_parameter("async_mapping").value is (not lossless)
            assert node.live.async_mapping is (not lossless)
        finally:
            node.close()
            node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
