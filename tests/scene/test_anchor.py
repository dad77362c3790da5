"""An anchor the nodes cannot honour is refused with its reason, never accepted and left at the map origin."""

import pytest

from simreal_nodes.errors import SceneError
from simreal_nodes.scene.schema import validate_scene


def test_registration_anchor_is_refused_until_the_nodes_run_it():
    doc = {"simreal_scene": 1, "name": "reg", "localization": {"mode": "rgbd"},
           "camera": {"depth": "/camera/depth/image_raw"},
           "objects": [{"id": "beam", "model": "spec:aluminium_beam", "anchor": {"kind": "registration"},
                        "tracking": {"enabled": True}}]}
    with pytest.raises(SceneError, match=r"objects\[0\]\.anchor\.kind: 'registration' is not available yet"):
        validate_scene(doc, "reg", ".")
    doc["objects"][0]["anchor"] = {"kind": "pose", "pose": [0.1, 0, 0, 0, 0, 0, 1]}
    assert validate_scene(doc, "reg", ".")["objects"][0]["anchor"]["kind"] == "pose"
