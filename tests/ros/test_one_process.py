"""`--one-process`: every node of a scene in one process on one executor (simreal_nodes.ros.compose). Each node
keeps its own name, namespace, parameters and remaps, so the graph gives the estimates the process-per-node graph
gives; a malformed node list is refused with a reason and nothing outside the node modules is imported."""

import json
from pathlib import Path

import numpy as np
import pytest

from simreal_nodes.errors import SimrealError
from simreal_nodes.launch import ONE_PROCESS, Launcher
from simreal_nodes.ros.compose import read_nodes
from simreal_nodes.scene.graph import NodeSpec


def test_the_launcher_runs_one_process_with_each_nodes_own_arguments(tmp_path):
    nodes = [NodeSpec("ingest", {"source": "topic"}), NodeSpec("tracker", {"lossless": True})]
    launcher = Launcher(nodes, remaps={"/a": "/b"}, env={}, log_dir=tmp_path, namespace="/cell2", one_process=True)
    (proc,) = launcher.procs
    assert proc.spec.name == ONE_PROCESS and proc.cmd[1:3] == ["-m", "simreal_nodes.ros.compose"]
    entries = read_nodes(proc.cmd[3])
    assert [m for m, _ in entries] == ["simreal_nodes.ros.nodes.ingest", "simreal_nodes.ros.nodes.tracker"]
    for (_, args), spec in zip(entries, nodes, strict=True):
        assert args[:3] == ["--ros-args", "-r", f"__node:={spec.name}"]
        assert "__ns:=/cell2" in args and "/a:=/b" in args
        params = args[args.index("--params-file") + 1]
        assert f"/cell2/{spec.name}" in Path(params).read_text()  # each node its own parameter file
    launcher._tmp.cleanup()


def test_the_launcher_runs_process_groups_and_refuses_bad_ones(tmp_path):
    """A group of one is that node's own process, a group of several one composed process (named ONE_PROCESS);
    groups that miss a node, name one twice, hold two groups of several or an empty one are refused."""
    nodes = [NodeSpec("ingest"), NodeSpec("localization"), NodeSpec("tracker"), NodeSpec("overlay")]
    launcher = Launcher(nodes, env={}, log_dir=tmp_path, groups=[["localization"], ["ingest", "tracker", "overlay"]])
    alone, shared = launcher.procs
    assert alone.spec.name == "localization" and alone.cmd[2] == "simreal_nodes.ros.nodes.localization"
    assert shared.spec.name == ONE_PROCESS and not shared.spec.per_frame
    assert [m for m, _ in read_nodes(shared.cmd[3])] == [f"simreal_nodes.ros.nodes.{n}"
                                                         for n in ("ingest", "tracker", "overlay")]
    launcher._tmp.cleanup()
    for bad in ([["localization"], ["ingest", "tracker"]], [["localization", "ingest"], ["tracker", "overlay"]],
                [["localization"], ["ingest", "tracker", "overlay", "ingest"]],
                [["localization"], ["ingest", "tracker", "overlay"], []]):
        with pytest.raises(SimrealError, match="process groups"):
            Launcher(nodes, env={}, log_dir=tmp_path, groups=bad)


@pytest.mark.parametrize("content, why", [
    ("not json", "cannot read"),
    ("[]", "non-empty list"),
    ('{"module": "simreal_nodes.ros.nodes.ingest", "args": []}', "non-empty list"),
    ('[{"module": "os", "args": []}]', "entry 0"),  # only the node modules are imported
    ('[{"module": "simreal_nodes.ros.nodes.ingest", "args": "--ros-args"}]', "entry 0"),
    ('[{"module": "simreal_nodes.ros.nodes.ingest"}]', "entry 0"),
])
def test_a_malformed_node_list_is_refused_with_a_reason(tmp_path, content, why):
    f = tmp_path / "nodes.json"
    f.write_text(content)
    with pytest.raises(SimrealError, match=why):
        read_nodes(f)


@pytest.mark.ros
def test_one_process_gives_the_estimates_of_a_process_per_node(tmp_path):
    """The demo graph (markers -> tracker -> overlay) replayed lossless both ways, the one-process run in a
    namespace (its node names, parameter files and the tracker's relative service call are per node)."""
    pytest.importorskip("rclpy")
    pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")
    from simreal_nodes.assimilation.evaluate import compare, read_parameters
    from simreal_nodes.ros.commands import replay
    from simreal_nodes.synth.samples import render_sample, sample

    name = "aluminium_beam_320x240"
    bag, scene = sample(name)
    if not bag.is_dir():
        render_sample(name, tmp_path)
        bag, scene = tmp_path / name, tmp_path / f"{name}.yaml"
    topic, truth_topic = "/simreal/objects/beam/parameters", "/ground_truth/objects/beam/parameters"
    runs = {}
    for one in (False, True):
        out = tmp_path / f"run_{one}"
        lines: list[str] = []
        stats, _, counts = replay(str(bag), str(scene), lossless=True, record=str(out), echo=lines.append,
                                  one_process=one, namespace="/one_process_test" if one else "")
        assert stats.frames_completed == stats.frames_published > 0 and stats.frames_dropped == 0
        assert counts[topic] == stats.frames_published
        # the RViz mesh is built only for a subscriber: the recorder is one (every 10th frame, overlay.marker_every)
        assert counts.get("/simreal/overlay/markers", 0) >= stats.frames_published // 10 - 1
        runs[one] = read_parameters(out, topic)
        if one:
            assert set(stats.cpu_s) == {ONE_PROCESS, "player + recorder"}
            assert any(x.startswith(f"[launch] started {ONE_PROCESS}") for x in lines), "\n".join(lines)
    truth = read_parameters(bag, truth_topic)
    err = {one: compare(runs[one], truth)[0] for one in runs}
    print({one: (e.median_abs, e.span) for one, e in err.items()})
    np.testing.assert_array_equal(runs[True].stamps, runs[False].stamps)
    # the same load position, frame by frame: the nodes compute the same things in the same order of frames
    a, b = runs[True].values[:, 0], runs[False].values[:, 0]
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))  # the same frames without an estimate
    assert np.isfinite(a).sum() > 0.5 * len(a)
    diff = np.abs(a - b)
    assert np.nanmax(diff) <= 1e-6 * err[False].span, np.nanmax(diff)  # every frame's, not most frames'
    assert err[True].median_abs <= 1.2 * err[False].median_abs + 1e-3 * err[False].span


def test_the_node_list_names_modules_that_have_a_node_class(tmp_path):
    from simreal_nodes.launch import node_modules

    pytest.importorskip("rclpy")
    from simreal_nodes.ros.compose import builders

    entries = [(m, []) for m in node_modules().values()]
    assert len(builders(entries)) == len(entries) == len(set(node_modules()))
    f = tmp_path / "nodes.json"
    f.write_text(json.dumps([{"module": "simreal_nodes.ros.nodes.nothing_here", "args": []}]))
    with pytest.raises(SimrealError, match=r"cannot import simreal_nodes\.ros\.nodes\.nothing_here"):
        builders(read_nodes(f))
