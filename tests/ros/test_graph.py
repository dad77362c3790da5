"""Whole graphs on synthetic scene bags with truth: a probe pushing two crossed virtual beams
(ingest -> RGB-D localization -> collision -> overlay), and the aluminium beam (markers -> tracker -> overlay)
as the demo runs it. The estimators see only the bag's sensor topics."""

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("simreal_msgs.msg", reason="simreal_msgs is built by ./run setup")

from simreal_nodes.assimilation.evaluate import compare_contacts, read_contacts
from simreal_nodes.io import bags
from simreal_nodes.ros.commands import replay
from simreal_nodes.synth.samples import render_sample, sample

pytestmark = pytest.mark.ros


def test_probe_pushes_crossed_beams_through_the_graph(tmp_path):
    name = "crossed_beams_probe_320x240"  # the committed sample (bags/samples/), rendered here if absent
    bag, scene = sample(name)
    if not bag.is_dir():
        render_sample(name, tmp_path)
        bag, scene = tmp_path / name, tmp_path / f"{name}.yaml"
    info = {"frames": sum(1 for _ in bags.read_bag(bag, topics=["/camera/camera_info"]))}
    out = tmp_path / "run"
    # synchronous local BA: the localization (and so the contacts) is the same on every run
    stats, _report, counts = replay(str(bag), str(scene), lossless=True, record=str(out),
                                   extra_params={"localization": {"async_mapping": False}})
    n = info["frames"]
    assert stats.frames_completed == n and stats.frames_dropped == 0
    for t in ("/simreal/objects/beam_a/contact", "/simreal/objects/beam_b/contact",
              "/simreal/objects/beam_a/parameters", "/simreal/overlay/image_raw"):
        assert counts[t] == n, t
    a = compare_contacts(read_contacts(out, "/simreal/objects/beam_a/contact"),
                         read_contacts(bag, "/ground_truth/objects/beam_a/contact"))
    print(f"beam_a: {a}")
    assert a.contact_agreement >= 0.8  # measured 0.91 (the depth sees the probe's near side a little late)
    # measured 0.2-0.36: pseudo-time lags while the noisy distance hovers at delta
    assert a.pseudo_time_median_abs <= 0.4
    # the contact point found from depth is the true one or a neighbour on the load grid
    est = read_contacts(out, "/simreal/objects/beam_a/contact")
    tru = read_contacts(bag, "/ground_truth/objects/beam_a/contact")
    from simreal_nodes.rom.build import cached_model
    from simreal_nodes.rom.model_file import load_model

    m = load_model(cached_model("crossed_beams"), fields=[])
    P = m.points[m.load_points]
    both = [s for s in est if est[s][1] >= 0 and tru[s][1] >= 0]
    assert len(both) > n // 3
    dist = np.array([np.linalg.norm(P[est[s][1]] - P[tru[s][1]]) for s in both])
    assert np.median(dist) < 0.03, np.median(dist)  # measured 28 mm: the diagonal neighbour on the 20 mm load grid
    # the overlay shows the deformation: overlay images differ from the camera images while pressed
    imgs = {bags.stamp_ns(o): o
            for o in (bags.decode(x) for x in bags.read_bag(out, topics=["/simreal/overlay/image_raw"]))}
    assert len(imgs) == n


def test_real_time_replay_sheds_load_and_accounts_for_every_frame(tmp_path):
    """Live QoS on the demo graph (markers -> tracker -> overlay) at the bag's own rate: busy nodes take the
    newest frame and skip older ones. Every published frame ends as finished by every node or as left out
    with a reason; no node both finishes and drops a frame (parameters that come after their frame was
    drawn are ignored, not reported as a dropped frame); the skips are load shedding, not errors."""
    name = "aluminium_beam_320x240"
    bag, scene = sample(name)
    if not bag.is_dir():
        render_sample(name, tmp_path)
        bag, scene = tmp_path / name, tmp_path / f"{name}.yaml"
    stats, _, _ = replay(str(bag), str(scene), lossless=False, record=str(tmp_path / "run"), echo=lambda *_: None)
    d = stats.as_dict()
    print(stats.summary())
    assert stats.frames_completed + stats.frames_dropped + stats.frames_timed_out == stats.frames_published
    assert stats.conflicting_reports == 0
    assert stats.frames_completed > 0.2 * stats.frames_published  # measured 0.9 alone on 2 cores
    assert all(why.startswith("never reached") or all(": skipped: " in part for part in why.split("; "))
               for why in stats.drop_reasons), dict(stats.drop_reasons)
    assert d["latency_ms"]["overlay"]["p50"] < 1000.0  # newest first: no backlog (measured ~60 ms)
