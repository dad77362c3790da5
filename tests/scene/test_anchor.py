"""``anchor: registration`` is accepted where the nodes can honour it (depth from an RGB-D camera or a stereo pair,
and a rough guess) and refused with its reason elsewhere."""

import pytest

from simreal_nodes.errors import SceneError
from simreal_nodes.scene.schema import validate_scene

GUESS = [0.0, 0.1, 1.2, 0.7, 0.0, 0.0, 0.7]


STEREO_CAMERA = {"right_image": "/camera/right/image_raw", "right_camera_info": "/camera/right/camera_info"}


def _doc(anchor: dict, mode: str = "rgbd") -> dict:
    return {"simreal_scene": 1, "name": "reg", "localization": {"mode": mode},
            "camera": STEREO_CAMERA if mode == "stereo" else {"depth": "/camera/depth/image_raw"},
            "objects": [{"id": "beam", "model": "spec:aluminium_beam", "anchor": anchor,
                         "tracking": {"enabled": True}}]}


def test_registration_anchor_is_accepted_with_a_guess_on_an_rgbd_map():
    o = validate_scene(_doc({"kind": "registration", "guess": GUESS}), "reg", ".")["objects"][0]
    assert o["anchor"]["kind"] == "registration"
    assert o["anchor"]["guess"] == pytest.approx(GUESS)


def test_registration_anchor_needs_a_guess_and_depth():
    with pytest.raises(SceneError, match=r"objects\[0\]\.anchor\.guess: required for kind 'registration'"):
        validate_scene(_doc({"kind": "registration"}), "reg", ".")
    with pytest.raises(SceneError, match=r"objects\[0\]\.anchor\.kind: 'registration' needs depth images "
                                         r"\(localization.mode 'rgbd' or 'stereo'\); found mode 'mono'"):
        validate_scene(_doc({"kind": "registration", "guess": GUESS}, mode="mono"), "reg", ".")


def test_registration_anchor_is_accepted_on_a_stereo_pair_whose_tracker_reads_both_images():
    from simreal_nodes.scene import graph

    s = validate_scene(_doc({"kind": "registration", "guess": GUESS}, mode="stereo"), "reg", ".")
    assert s["camera"]["stereo_min_depth_m"] == pytest.approx(0.4)
    nodes = {n.name: n for n in graph.required_nodes(s)}
    assert "ingest" not in nodes  # nothing to do for it: the nodes read the camera topics themselves
    cam, tracker = s["camera"], nodes["tracker"]
    assert {cam["image"], cam["right_image"], cam["right_camera_info"]} <= set(tracker.inputs)
    assert not any("depth" in t for t in tracker.inputs)


def test_pose_anchor_needs_no_guess():
    assert validate_scene(_doc({"kind": "pose", "pose": [0.1, 0, 0, 0, 0, 0, 1]}), "reg", ".")["objects"][0][
        "anchor"]["kind"] == "pose"


def test_a_registering_tracker_subscribes_to_depth():
    """The graph lists depth among the tracker's inputs exactly when the node subscribes to it: a registration, or
    a reference state read from depth; a posed sparse tracker with the rest shape as its reference reads none."""
    from simreal_nodes.scene import graph

    sparse_rest = {"enabled": True, "measurements": "map_points", "reference": "rest"}
    for anchor, tracking, wants in (({"kind": "registration", "guess": GUESS}, sparse_rest, True),
                                    ({"kind": "pose"}, sparse_rest, False),
                                    ({"kind": "pose"}, {**sparse_rest, "reference": "depth"}, True),
                                    ({"kind": "pose"}, {"enabled": True, "measurements": "dense"}, True)):
        doc = _doc(anchor)
        doc["objects"][0]["tracking"] = tracking
        s = validate_scene(doc, "reg", ".")
        nodes = {n.name: n for n in graph.required_nodes(s)}
        reads = s["camera"]["depth"] in nodes["tracker"].inputs
        assert reads == wants == graph.tracker_reads_depth(s), (anchor, tracking)


@pytest.mark.parametrize("fine, want", [(None, "full"), ("auto", "full"), ("upright", "upright"), ("full", "full")])
def test_the_anchor_chooses_the_registration_fine_stage(monkeypatch, fine, want):
    """``anchor.fine`` reaches the registration of that object (``auto``: the camera's choice, full for RGB-D)."""
    import numpy as np

    from simreal_nodes.assimilation import objects
    from simreal_nodes.assimilation.registration import RegistrationConfig, RegistrationError
    from simreal_nodes.rom.build import cached_model
    from simreal_nodes.rom.model_file import load_model
    from simreal_nodes.synth.scenes import default_camera

    anchor = {"kind": "registration", "guess": GUESS} | ({"fine": fine} if fine else {})
    scene = validate_scene(_doc(anchor), "reg", ".")
    seen = []

    def register(*args, **kw):
        seen.append(next(a for a in args if isinstance(a, RegistrationConfig)).fine)
        raise RegistrationError("stopped here")

    monkeypatch.setattr(objects, "register_loaded", register)
    monkeypatch.setattr(objects, "register_rgbd", register)
    model = load_model(cached_model("aluminium_beam"), fields=["displacement"])
    cam = default_camera(64, 48)
    tr = objects.ObjectTrackers(scene["objects"], {"beam": model}, RegistrationConfig.for_camera(scene["camera"]))
    tr.set_camera(cam)
    depth = np.full((48, 64), 1.2, np.float32)
    for _ in range(RegistrationConfig().frames * RegistrationConfig().every):
        tr._register(scene["objects"][0], np.eye(4), depth)
    assert seen == [want]
    with pytest.raises(SceneError, match="fine"):
        validate_scene(_doc({**anchor, "fine": "sideways"}), "reg", ".")
