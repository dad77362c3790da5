import textwrap
from pathlib import Path

import pytest

from simreal_nodes.errors import SceneError
from simreal_nodes.scene.graph import required_nodes
from simreal_nodes.scene.schema import load_scene

BASE = """
simreal_scene: 1
name: cam_only
localization: {mode: static, static_pose: [0, 0, 0, 0, 0, 0, 1]}
overlay: {enabled: false}
"""


def write(tmp_path, text):
    f = tmp_path / "scene.yaml"
    f.write_text(textwrap.dedent(text))
    return f


def test_minimal_scene_gets_defaults_and_starts_only_ingest(tmp_path):
    from simreal_nodes.scene.graph import ingest_note

    s = load_scene(write(tmp_path, BASE))
    assert s["camera"]["image"] == "/camera/image_raw"
    assert s["camera"]["depth"] is None
    nodes = required_nodes(s)
    assert [n.name for n in nodes] == ["ingest"]  # no other node: the camera stream, validated, is the graph
    assert ingest_note(s, nodes) == "ingest: the scene's only node"


@pytest.mark.parametrize("camera,source,why", [
    ("{}", None, []),
    ("{compressed: true}", None, ["decompresses the images"]),
    ("{undistort: true}", None, ["undistorts the images"]),
    ("{ingest: always}", None, ["camera.ingest: always"]),
    ("{source: video, path: CALIB}", None, ["reads frames from a video file"]),
    ("{source: video, path: CALIB}", "topic", []),  # a replay: the player publishes the frames
    ("{calibration: CALIB, depth: /d}", "topic", ["publishes the calibration file's intrinsics"]),
    ("{right_image: /r, right_camera_info: /ri, stereo_input: raw}", None, ["rectifies the raw stereo pair"]),
    ("{right_image: /r, right_camera_info: /ri, stereo_input: image_rect}", None,
     ["publishes the image_rect pair's rectified cameras"]),
    ("{right_image: /r, right_camera_info: /ri}", None, []),  # rectified (the default): read as they are
    ("{depth: /d, depth_camera_info: /di, depth_to_color: [-0.015, 0, 0, 0, 0, 0, 1]}", None,
     ["registers the depth images to the colour camera"]),
])
def test_the_ingest_starts_only_when_it_has_work(tmp_path, camera, source, why):
    """Issue 18: no hop that does nothing. Without decompression, undistortion, a calibration file or a file to read,
    the nodes subscribe to the camera's own topics and no ingest node starts; with any, every node reads the
    ingest's outputs and none reads the camera's."""
    from simreal_nodes.scene import graph

    (tmp_path / "cal.yaml").write_text("")
    camera = camera.replace("CALIB", str(tmp_path / "cal.yaml"))
    text = BASE.replace("enabled: false", "enabled: true") + f"camera: {camera}\n"
    s = load_scene(write(tmp_path, text))
    assert graph.ingest_work(s, source) == why
    nodes = required_nodes(s, source=source)
    cam = s["camera"]
    raw = {graph.image_topic(cam), cam["camera_info"], cam["depth"]} - {None}
    ours = {graph.CAM_IMAGE, graph.CAM_INFO, graph.CAM_DEPTH}
    ins = {t for n in nodes if n.name != "ingest" for t in n.inputs}
    if why:
        assert nodes[0].name == "ingest" and not ins & raw and graph.CAM_IMAGE in ins
        assert all("camera_direct" not in n.parameters for n in nodes)
        assert graph.ingest_note(s, nodes, source).startswith("ingest: " + why[0])
    else:
        assert "ingest" not in [n.name for n in nodes] and not ins & ours and cam["image"] in ins
        assert all(n.parameters["camera_direct"] for n in nodes)
        assert graph.ingest_note(s, nodes, source) == (
            "no ingest: the nodes read /camera/image_raw and its CameraInfo themselves")


@pytest.mark.parametrize("text,match", [
    (BASE + "camra: {}\n", r"camra: unknown key \(did you mean 'camera'\?\)"),
    (BASE.replace("mode: static", "mode: sttic"),
     r"localization.mode: expected one of 'markers', 'mono'.*found 'sttic'"),
    (BASE + "camera: {undistort: 3}\n", r"camera.undistort: expected true or false; found 3 \(int\)"),
    (BASE + "camera: {stereo_input: raw}\n", r"camera.stereo_input: 'raw' reads a stereo pair .* needs "
                                             r"camera.right_image and camera.right_camera_info"),
    (BASE + "camera: {stereo_input: image_rect, right_image: /r}\n", r"camera.stereo_input: 'image_rect' reads"),
    (BASE + "camera: {stereo_input: raw, right_image: /r, right_camera_info: /ri, depth: /d}\n",
     r"no camera.calibration or camera.depth"),
    (BASE + "camera: {stereo_input: rectify}\n", r"camera.stereo_input: expected one of 'rectified', 'raw'"),
    (BASE + "camera: {depth: /d, depth_camera_info: /di}\n", r"registering a depth camera's images .* needs both"),
    (BASE + "camera: {depth: /d, depth_camera_info: /di, depth_to_color: [0, 0, 0, 0, 0, 0, 0]}\n",
     r"camera.depth_to_color: its quaternion .* is zero"),
    (BASE + "camera: {depth_camera_info: /di, depth_to_color: [0, 0, 0, 0, 0, 0, 1]}\n",
     r"needs both, camera.depth"),
    (BASE + "camera: {image: camera/image}\n", r"camera.image: expected a ROS topic name"),
    (BASE.replace("simreal_scene: 1", "simreal_scene: 7"), r"simreal_scene: expected format version 1; found 7"),
    (BASE.replace("name: cam_only\n", ""), r"name: required key is missing"),
    (BASE + "objects:\n  - {id: beam, model: no_such_model.h5}\n",
     r"objects\[0\].model: file not found: .*no_such_model.h5"),
    (BASE + "objects:\n  - {id: beam}\n", r"objects\[0\].model: required key is missing"),
    (BASE + "objects:\n  - {id: beam, model: spec:aluminium_beam, tracking: {rest_frames: 10}}\n",
     r"objects\[0\].tracking.rest_frames: the pose is corrected at rest from dots .*found measurements 'dense'"),
    (BASE.replace("static_pose: [0, 0, 0, 0, 0, 0, 1]", "static_pose: [0, 0, 0]"),
     r"localization.static_pose: expected a pose"),
    (BASE + "localization: {mode: rgbd}\n", r"duplicate|camera.depth: required"),
    ("- just a list\n", r"expected a mapping at the top level"),
    ("a: [unclosed\n", r"not valid YAML"),
])
def test_mistakes_name_key_expected_and_found(tmp_path, text, match):
    with pytest.raises(SceneError, match=match):
        load_scene(write(tmp_path, text))


def test_rgbd_without_depth_topic(tmp_path):
    text = BASE.replace("localization: {mode: static, static_pose: [0, 0, 0, 0, 0, 0, 1]}",
                        "localization: {mode: rgbd}")
    with pytest.raises(SceneError, match=r"camera.depth: required for localization.mode 'rgbd'"):
        load_scene(write(tmp_path, text))


def test_missing_scene_file(tmp_path):
    with pytest.raises(SceneError, match="scene file not found"):
        load_scene(tmp_path / "nope.yaml")


@pytest.mark.parametrize("name,needs_image", [("aluminium_beam", True), ("joint_boot", False), ("foam_beam", False)])
def test_tracker_inputs_are_what_it_subscribes(name, needs_image):
    """The replay waits until every node subscribes to its declared inputs: the tracker takes the image only for
    glued dots / homography (a map-point scene that declared it never came up), and the deformable-point feedback
    runs tracker -> localization whenever an object is tracked through the map."""
    from simreal_nodes.scene import graph
    from simreal_nodes.scene.schema import validate_scene
    from simreal_nodes.synth.makebag import make_scene

    if name == "aluminium_beam":  # its YAML needs the rendered dots: take the committed sample's
        from simreal_nodes.synth.samples import sample

        s = load_scene(sample("aluminium_beam_320x240")[1])
    else:
        sc = make_scene(name, 320, 240, None, 30.0)
        s = validate_scene(sc.scene_yaml(sc), name, ".")
    nodes = {n.name: n for n in required_nodes(s)}
    image = graph.camera_topics(s["camera"], direct="ingest" not in nodes)["image"]
    assert (image in nodes["tracker"].inputs) == needs_image
    assert graph.LOC_DEFORMABLE in nodes["localization"].inputs
    assert graph.LOC_DEFORMABLE in nodes["tracker"].outputs
    assert graph.LOC_FOCUS in nodes["localization"].inputs and graph.LOC_FOCUS in nodes["tracker"].outputs
    # the localization's status: read only to ask a restarted localization again to freeze its map
    assert graph.LOC_STATUS not in nodes["tracker"].inputs
    s["localization"]["freeze_map_on_deformation"] = True
    assert graph.LOC_STATUS in {n.name: n for n in required_nodes(s)}["tracker"].inputs


SPEC_SCENE = BASE + "objects:\n  - {id: beam, model: 'spec:aluminium_beam', parameters: {PARAM: {mode: tracked}}}\n"


def test_spec_model_is_named_not_built(tmp_path, monkeypatch):
    """Validation (what `simreal check-scene` and every node runs) reads the spec and names the model's cache file;
    building it is left to build_spec_models, so checking a scene never starts an FEM build."""
    import simreal_nodes.rom.build as build

    monkeypatch.setenv("SIMREAL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(build, "build_model", lambda *a, **k: pytest.fail("validation built a model"))
    s = load_scene(write(tmp_path, SPEC_SCENE.replace("PARAM", "not_checked_until_built")))
    o = s["objects"][0]
    assert o["model"] == str(tmp_path / "cache" / "models" / "aluminium_beam.h5")
    assert o["_model_spec"] == "aluminium_beam"
    assert not (tmp_path / "cache").exists()


def test_spec_model_fixed_parameter_needs_a_value_before_any_build(tmp_path):
    with pytest.raises(SceneError, match=r"objects\[0\].parameters.s.value: required for mode 'fixed'"):
        load_scene(write(tmp_path, SPEC_SCENE.replace("PARAM: {mode: tracked}", "s: {mode: fixed}")))


def test_unknown_spec_is_a_scene_error(tmp_path):
    with pytest.raises(SceneError, match=r"objects\[0\].model: model spec not found: .*built-in specs: "
                                         r".*aluminium_beam"):
        load_scene(write(tmp_path, SPEC_SCENE.replace("spec:aluminium_beam", "spec:no_such_spec")))


@pytest.mark.parametrize("param,match", [("s", None), ("nope", r"objects\[0\].parameters.nope: the model .* has no "
                                                                  r"parameter 'nope' \(it has: s\)")])
def test_build_spec_models_builds_then_checks_parameters(tmp_path, monkeypatch, param, match):
    """build_spec_models (run by launch / replay / demo before nodes start) builds each spec model once and checks
    the scene's parameter names against the built file, as validation does for a model file."""
    import simreal_nodes.rom.build as build
    from simreal_nodes.rom.model_file import save_model
    from simreal_nodes.scene.schema import build_spec_models
    from tests.modelkit import beam_model

    def fake_cached_model(name: str, progress=None):
        out = build.cached_model_path(name)
        save_model(beam_model(), out)
        return out

    monkeypatch.setenv("SIMREAL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(build, "cached_model", fake_cached_model)
    s = load_scene(write(tmp_path, SPEC_SCENE.replace("PARAM", param)))
    if match:
        with pytest.raises(SceneError, match=match):
            build_spec_models(s)
        return
    o = build_spec_models(s)["objects"][0]
    assert Path(o["model"]).exists() and o["_model_header"]["axes"][0]["name"] == "s"


AERO = """
simreal_scene: 1
name: car
camera: {depth: /camera/depth/image_raw}
localization: {mode: rgbd}
aero: {enabled: true, database: db.h5}
"""


def test_an_aero_scene_starts_the_aero_node_and_wires_its_flow(tmp_path):
    (tmp_path / "db.h5").write_bytes(b"")  # existence is what the scene checks; the node reads the file
    s = load_scene(write(tmp_path, AERO))
    nodes = {n.name: n for n in required_nodes(s)}
    assert list(nodes) == ["localization", "aero", "overlay"]  # a raw camera topic: no ingest
    assert "/simreal/localization/capture_cloud" in nodes["localization"].outputs
    assert nodes["aero"].inputs == ["/simreal/localization/capture_cloud"]
    assert nodes["aero"].outputs == {"/simreal/aero/flow": "visualization_msgs/msg/MarkerArray"}
    assert not nodes["aero"].per_frame and all(n.per_frame for k, n in nodes.items() if k != "aero")
    assert "/simreal/aero/flow" in nodes["overlay"].inputs
    # without aero, nothing of it: no node, no capture cloud
    plain = load_scene(write(tmp_path, AERO.replace("enabled: true", "enabled: false")))
    nodes = {n.name: n for n in required_nodes(plain)}
    assert "aero" not in nodes and "/simreal/localization/capture_cloud" not in nodes["localization"].outputs


@pytest.mark.parametrize("change,match", [
    (("mode: rgbd", "mode: markers, markers: {poses: {0: [0, 0, 0, 0, 0, 0, 1]}}"), r"aero.enabled: .*SLAM map"),
    (("database: db.h5", "database: missing.h5"), r"aero.database: .*not found.*build-aero-db"),
    (("mode: rgbd", "mode: mono"), r"aero.length_m: a monocular map has no scale"),
    (("enabled: true", "enabled: true, neighbours: 1"), r"aero.neighbours: expected"),
    (("enabled: true", "enabled: true, max_points: -1"), r"aero.max_points: expected"),
])
def test_aero_mistakes_are_named(tmp_path, change, match):
    (tmp_path / "db.h5").write_bytes(b"")
    with pytest.raises(SceneError, match=match):
        load_scene(write(tmp_path, AERO.replace(*change)))


@pytest.mark.parametrize("mode,measurements,lossless,one", [
    ("markers", "dots", False, True),  # the demo: one executor keeps up live
    ("static", "dots", False, True),
    ("rgbd", "map_points", False, False),  # a SLAM takes longer than a frame period: its own process, live
    ("mono", "map_points", False, False),
    ("stereo", "map_points", False, False),
    ("markers", "dense", False, False),  # so does the dense tracker
    ("rgbd", "map_points", True, True),  # lossless: one process, whatever runs
    ("markers", "dense", True, True),
])
def test_the_cli_launches_live_graphs_with_a_heavy_node_a_process_per_node(mode, measurements, lossless, one):
    """Issue 18: the launch the CLI picks when told neither --one-process nor --process-per-node
    (benchmarks/results/graph.md, launch_mode.md)."""
    from simreal_nodes.scene.graph import default_launch

    scene = {"localization": {"mode": mode},
             "objects": [{"tracking": {"enabled": True, "measurements": measurements}},
                         {"tracking": {"enabled": False, "measurements": "dense"}}]}  # a disabled one weighs nothing
    assert default_launch(scene, lossless) is one
    # lossless with frames in flight: a process per node, whatever runs (graph.md's rows with frames in flight;
    # split, ahead there on the SLAM scenes, was not on the held-out ones: launch_mode.md)
    assert default_launch(scene, lossless, in_flight=4) is (one and not lossless)
    assert default_launch(scene, lossless, in_flight=1) is one
    scene["objects"][0]["tracking"]["enabled"] = False
    assert default_launch(scene, lossless) is (lossless or mode not in ("rgbd", "mono", "stereo"))
    assert default_launch(scene, lossless, in_flight=4) is (not lossless and mode not in ("rgbd", "mono", "stereo"))


@pytest.mark.parametrize("mode,measurements,slow", [
    ("markers", "dots", set()),
    ("rgbd", "map_points", {"localization"}),
    ("markers", "dense", {"tracker"}),
    ("stereo", "dense", {"localization", "tracker"}),
])
def test_process_groups_of_each_launch(mode, measurements, slow):
    """One process: one group of all; a process per node: one each; split: each slow node alone, the others (if
    any) in one group."""
    from simreal_nodes.scene.graph import SPLIT, NodeSpec, process_groups, slow_nodes

    scene = {"localization": {"mode": mode}, "objects": [{"tracking": {"enabled": True, "measurements": measurements}}]}
    assert slow_nodes(scene) == slow
    nodes = [NodeSpec(n) for n in ("ingest", "localization", "tracker", "overlay")]
    names = [n.name for n in nodes]
    assert process_groups(scene, nodes, True) == [names]
    assert process_groups(scene, nodes, False) == [[n] for n in names]
    split = process_groups(scene, nodes, SPLIT)
    assert [g for g in split if len(g) == 1] == [[n] for n in names if n in slow]
    assert [g for g in split if len(g) > 1] == [[n for n in names if n not in slow]]
    with pytest.raises(ValueError, match="launch"):
        process_groups(scene, nodes, "two")


def test_an_object_that_nothing_estimates_is_noted(tmp_path):
    """An object whose parameters no node estimates (tracking and collision off, the defaults) is drawn at the low
    end of each parameter's range: `check-scene`, `launch` and `replay` say so, and what would estimate it (its
    parameters are `tracked` by default)."""
    from simreal_nodes.scene.graph import unestimated_notes

    obj = """
    objects:
    - id: beam
      model: spec:aluminium_beam
      anchor: {kind: pose, pose: [0, 0, 0.1, 0, 0, 0, 1]}
      parameters: {s: {mode: tracked}}
    """
    drawn = load_scene(write(tmp_path, BASE.replace("overlay: {enabled: false}", "") + textwrap.dedent(obj)))
    notes = unestimated_notes(drawn)
    assert len(notes) == 1 and "objects[0] 'beam'" in notes[0] and "set tracking.enabled: true to fit" in notes[0]
    assert "the overlay draws it with each parameter at the low end of its range" in notes[0]
    fixed_obj = textwrap.dedent(obj).replace("{mode: tracked}", "{mode: fixed, value: 0.2}")
    fixed = load_scene(write(tmp_path, BASE + fixed_obj))
    assert "to have its fixed values drawn" in unestimated_notes(fixed)[0]
    assert "tracker" not in [n.name for n in required_nodes(drawn)]
    tracked = load_scene(write(tmp_path, BASE + textwrap.dedent(obj) + "  tracking: {enabled: true}\n"))
    assert unestimated_notes(tracked) == [] and "tracker" in [n.name for n in required_nodes(tracked)]
    hidden = load_scene(write(tmp_path, BASE + textwrap.dedent(obj)))  # overlay off too: the object does nothing
    assert "no overlay draws it" in unestimated_notes(hidden)[0]
    # the crossed beams' lower beam with its collision off: the upper beam's push never reaches it
    sample = Path(__file__).resolve().parents[2] / "bags" / "samples" / "crossed_beams_probe_320x240.yaml"
    assert unestimated_notes(load_scene(sample)) == []
    text = sample.read_text()
    lower = text.index("- id: beam_b")
    f = tmp_path / "crossed.yaml"
    off = text[lower:].replace("  collision:\n    enabled: true", "  collision:\n    enabled: false", 1)
    f.write_text(text[:lower] + off)
    notes = unestimated_notes(load_scene(f))
    assert len(notes) == 1 and "objects[1] 'beam_b'" in notes[0] and "objects[0] pushes it" in notes[0], notes


def test_the_readme_example_scene_is_valid(tmp_path):
    """The README's example scene passes the schema as written, and starts what its comments say."""
    from simreal_nodes.scene.graph import unestimated_notes

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    start = readme.index("```yaml\n") + len("```yaml\n")
    f = tmp_path / "my_beam.yaml"
    f.write_text(readme[start:readme.index("```", start)])
    s = load_scene(f)
    assert s["localization"]["mode"] == "rgbd" and s["objects"][0]["anchor"]["kind"] == "registration"
    assert [n.name for n in required_nodes(s)] == ["localization", "tracker", "overlay"]
    assert unestimated_notes(s) == []
