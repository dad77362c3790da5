"""``anchor: registration`` is accepted where the nodes can honour it (an RGB-D map and a rough guess) and refused
with its reason elsewhere."""

import pytest

from simreal_nodes.errors import SceneError
from simreal_nodes.scene.schema import validate_scene

GUESS = [0.0, 0.1, 1.2, 0.7, 0.0, 0.0, 0.7]


def _doc(anchor: dict, mode: str = "rgbd") -> dict:
    return {"simreal_scene": 1, "name": "reg", "localization": {"mode": mode},
            "camera": {"depth": "/camera/depth/image_raw"},
            "objects": [{"id": "beam", "model": "spec:aluminium_beam", "anchor": anchor,
                         "tracking": {"enabled": True}}]}


def test_registration_anchor_is_accepted_with_a_guess_on_an_rgbd_map():
    o = validate_scene(_doc({"kind": "registration", "guess": GUESS}), "reg", ".")["objects"][0]
    assert o["anchor"]["kind"] == "registration"
    assert o["anchor"]["guess"] == pytest.approx(GUESS)


def test_registration_anchor_needs_a_guess_and_depth():
    with pytest.raises(SceneError, match=r"objects\[0\]\.anchor\.guess: required for kind 'registration'"):
        validate_scene(_doc({"kind": "registration"}), "reg", ".")
    with pytest.raises(SceneError, match=r"objects\[0\]\.anchor\.kind: 'registration' needs the depth images"):
        validate_scene(_doc({"kind": "registration", "guess": GUESS}, mode="mono"), "reg", ".")


def test_pose_anchor_needs_no_guess():
    assert validate_scene(_doc({"kind": "pose", "pose": [0.1, 0, 0, 0, 0, 0, 1]}), "reg", ".")["objects"][0][
        "anchor"]["kind"] == "pose"


def test_a_registering_tracker_subscribes_to_depth():
    from simreal_nodes.scene import graph

    for anchor, wants in (({"kind": "registration", "guess": GUESS}, True), ({"kind": "pose"}, False)):
        s = validate_scene(_doc(anchor), "reg", ".")
        nodes = {n.name: n for n in graph.required_nodes(s)}
        assert (graph.CAM_DEPTH in nodes["tracker"].inputs) == wants
