"""The localizer factory and the one interface of its localizers (markers, static, SLAM), and the live localizer
the node keeps (built on CameraInfo, rebuilt when the intrinsics change, stereo waiting for its baseline)."""

import cv2
import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.localizer import (
    LiveLocalizer,
    MapFreeze,
    MarkerLocalization,
    SlamLocalization,
    StaticLocalization,
    make_localizer,
    status_text,
)
from simreal_nodes.camera import CameraModel

CAM = CameraModel.from_intrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
MARKERS = {"mode": "markers", "markers": {"dictionary": "DICT_4X4_50", "size_m": 0.1,
                                          "poses": {"0": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]}}}
SLAM = {"mode": "mono", "features": 500, "scale_factor": 1.2, "pyramid_levels": 8, "known_scale_m": None}


def _marker_image() -> np.ndarray:
    """Marker 0 (10 cm) seen face on from 0.5 m: 100 px wide in the middle of the image."""
    img = np.full((480, 640), 255, np.uint8)
    marker = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 0, 100)
    img[190:290, 270:370] = marker
    return img


def test_markers():
    # one 10 cm marker face on from 0.5 m holds the camera's position only to about 7 % of the distance (its tilt
    # trades against its offset): refused by default, with the knob that takes it
    refused = make_localizer(MARKERS, CAM).step(_marker_image(), 0)
    assert refused.T_wc is None and refused.state == 3
    assert refused.reason.startswith("pose refused: 1 marker holds")
    assert "localization.markers.max_std_pct" in refused.reason
    loc = make_localizer({**MARKERS, "markers": {**MARKERS["markers"], "max_std_pct": 10.0}}, CAM)
    assert isinstance(loc, MarkerLocalization) and loc.mode == "markers" and loc.map is None
    r = loc.step(_marker_image(), 0)
    assert r.state == 2 and r.reason.startswith("1 markers, ") and "of the distance" in r.reason
    assert r.features == 4 and r.timings is None
    # the camera 0.5 m in front of the marker, looking at it (camera y down = world -y, z into the marker)
    np.testing.assert_allclose(r.T_wc[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=0.02)
    np.testing.assert_allclose(r.T_wc[:3, 3], [0.0, 0.0, 0.5], atol=0.01)
    assert len(r.obs_ids) == 0 and r.obs_pos.shape == (0, 3)
    lost = loc.step(np.full((480, 640), 255, np.uint8), 1)
    assert lost.T_wc is None and lost.state == 3 and lost.reason == "no marker of the layout in view"
    assert status_text(lost) == ("error", "lost: no marker of the layout in view")
    # no map: feedback, freezing and closing do nothing
    loc.feedback(np.arange(3), np.zeros((3, 3)), np.zeros(3, np.uint8))
    loc.set_localization_only(True)
    loc.close()


def test_static():
    pose = [0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0]
    loc = make_localizer({"mode": "static", "static_pose": pose}, CAM)
    assert isinstance(loc, StaticLocalization) and loc.map is None
    r = loc.step(np.zeros((480, 640), np.uint8), 0)
    np.testing.assert_array_equal(r.T_wc, G.pose7_to_matrix(pose))
    assert r.state == 2 and r.reason == "" and status_text(r) == ("ok", "ok")


def test_slam():
    loc = make_localizer(SLAM, CAM, localization_only=True)
    assert isinstance(loc, SlamLocalization) and loc.mode == "mono" and loc.map is loc.slam.map
    assert loc.slam.localization_only
    r = loc.step(np.zeros((480, 640), np.uint8), 0)  # nothing to see
    assert r.T_wc is None and r.state in (0, 1) and r.reason and r.timings is not None
    assert r.map_points == 0 and r.keyframes == 0 and r.localization_only
    loc.set_localization_only(False)
    assert not loc.slam.localization_only
    loc.feedback(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.uint8))
    # the tracker's flags: bit 0 forget the image track, bit 1 linked at rest (the map keeps the point)
    loc.feedback(np.array([4, 5, 6, 7]), np.full((4, 3), np.nan), np.array([0, 1, 2, 3], np.uint8))
    assert loc.slam.ctx.deformable == {4, 5, 6, 7} and loc.slam.ctx.held == {6, 7}
    loc.close()
    with pytest.raises(ValueError, match="baseline"):
        make_localizer(dict(SLAM, mode="stereo"), CAM)


def test_live_localizer_follows_the_camera():
    live = LiveLocalizer(MARKERS)
    assert live.not_ready() == "waiting for a valid CameraInfo" and live.map_points() is None
    assert live.set_camera(CAM) and live.not_ready() == "" and isinstance(live.core, MarkerLocalization)
    first = live.core
    assert not live.set_camera(CameraModel.from_intrinsics(640, 480, 500.0, 500.0, 320.0, 240.0))  # same intrinsics
    assert live.core is first
    assert live.set_camera(CameraModel.from_intrinsics(640, 480, 510.0, 510.0, 320.0, 240.0)) and live.core is not first
    assert not live.close("/nonexistent/map.h5")  # no map to save


def test_live_stereo_waits_for_the_baseline():
    live = LiveLocalizer(dict(SLAM, mode="stereo"))
    assert live.set_camera(CAM) and live.core is None
    assert live.not_ready() == "stereo: waiting for the right CameraInfo (baseline)"
    live.baseline = 0.12
    assert live.not_ready() == "" and live.core.slam.baseline == 0.12
    live.set_localization_only(True)
    assert live.core.slam.localization_only
    live.close()


def test_live_focus_regions_expire():
    """The trackers' image regions steer the features of frames near their stamp only; a newer report replaces an
    object's region."""
    live = LiveLocalizer(MARKERS)
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    live.set_focus(0, 1_000_000_000, square)
    live.set_focus(1, 1_000_000_000, square + 50)
    assert len(live.focus(1_200_000_000)) == 2
    assert live.focus(2_000_000_000) == []  # a second later: stale
    live.set_focus(0, 1_900_000_000, square + 5)
    (p,) = live.focus(2_000_000_000)
    np.testing.assert_allclose(p, square + 5)


def test_focus_regions_held_stay_few_whatever_the_senders_invent():
    """Regions too old to steer are dropped as new ones come in: a sender inventing an index per message (the graph
    fuzz did) leaves only the regions of the last half second held, not one per message."""
    live = LiveLocalizer(MARKERS)
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    for i in range(1000):
        live.set_focus(i, i * 100_000_000, square)  # ten a second, each under a new index
    assert len(live._focus) == 5


def test_focus_polygons_that_are_not_finite_or_far_off_steer_nothing_and_break_nothing():
    """The feature extractor takes any polygon it is given: one with NaN is ignored (the features exactly those
    without it), one with huge coordinates is clipped (its pixel bounds must fit an int) and steers within the
    image."""
    from simreal_nodes.vision.orb import OrbExtractor

    rng = np.random.default_rng(2)
    img = rng.integers(0, 255, (240, 320)).astype(np.uint8)
    ex = OrbExtractor(300)
    plain = ex.extract(img)
    nan = np.array([[0, 0], [np.nan, 5.0], [10, 10]])
    huge = np.array([[-1e30, -1e30], [1e30, -1e30], [1e30, 1e30], [-1e30, 1e30]])
    ignored = ex.extract(img, focus=[nan], focus_share=0.2)
    np.testing.assert_array_equal(ignored.uv, plain.uv)
    np.testing.assert_array_equal(ignored.desc, plain.desc)
    got = ex.extract(img, focus=[nan, huge], focus_share=0.2)
    assert len(got) == pytest.approx(len(plain), rel=0.05)
    assert np.all((got.uv >= 0) & (got.uv < [320, 240]))


def test_live_map_stats_give_the_maps_size_for_the_diagnostics():
    markers = LiveLocalizer(MARKERS)
    assert markers.map_stats() == {}  # no camera yet, no localizer
    markers.set_camera(CAM)
    assert markers.map_stats() == {}  # markers build no map
    live = LiveLocalizer(SLAM)
    live.set_camera(CAM)
    assert live.map_stats() == {"map_keyframes": "0", "map_points": "0"}  # a SLAM before its start: empty
    m = live.map
    m.keyframes[7] = object()  # the stats count what the map holds, nothing else
    assert live.map_stats()["map_keyframes"] == "1"
    del m.keyframes[7]
    live.close()


def test_map_freeze_asks_once_and_again_when_the_localization_maps_again():
    """``MapFreeze`` (the tracker's side of ``freeze_map_on_deformation``): one request once a deformation appears
    and the service is there; none while it is out or answered; asked again only after two status reports in a row
    say the localization maps (a respawned localization; one report may predate the request's service), or when the
    request was lost (its service went away, or many reports in a row say mapping while it is out); a report that
    says frozen answers a request out; never when the scene does not ask for it."""
    f = MapFreeze(True)
    assert not f.due(deforming=False, service_ready=True) and not f.due(deforming=True, service_ready=False)
    assert f.due(True, True)
    f.sent()
    assert not f.due(True, True)  # out: not again
    assert not f.status(False) and not f.status(False)  # reports before the answer re-arm nothing
    f.answered(True)
    assert f.told and not f.due(True, True)
    assert not f.status(False)  # one report may have left before the request was served
    assert not f.status(True) and not f.status(False)  # frozen in between: the count starts again
    assert f.status(False)  # two in a row: the localization maps again
    assert not f.told and not f.due(False, True) and f.due(True, True)
    f.sent()
    assert not f.due(True, True)
    assert not f.due(True, False)  # the service went away with the request in flight: forgotten
    assert f.due(True, True) and f.requests == 2
    f.sent()
    f.answered(False)  # refused: not told, asked again at the next deforming frame
    assert not f.told and f.due(True, True)
    # a request out is settled by the reports too: one that says frozen answers it, ...
    f.sent()
    assert not f.status(True) and f.told and not f.pending and not f.due(True, True)
    f.answered(True)  # its response, late: the same
    assert f.told and not f.due(True, True)
    # ... and LOST_AFTER in a row that say mapping lose it (the localization died with it; its service still listed)
    assert not f.status(False) and f.status(False) and f.due(True, True)
    f.sent()
    assert not any(f.status(False) for _ in range(MapFreeze.LOST_AFTER - 1)) and not f.due(True, True)
    assert f.status(False) and not f.pending and f.due(True, True) and f.requests == 5
    off = MapFreeze(False)
    assert not off.due(True, True) and not off.status(False)


def test_markers_and_a_static_camera_report_the_localization_only_they_were_asked():
    """No map to freeze, but their status says what they were told (the tracker's MapFreeze reads it to tell a
    restarted localization node, which was told nothing, from one that was)."""
    for loc in (make_localizer(MARKERS, CAM), make_localizer({"mode": "static", "static_pose": [0, 0, 0, 0, 0, 0, 1]},
                                                             CAM)):
        img = np.full((480, 640), 255, np.uint8)
        assert not loc.step(img, 0).localization_only
        loc.set_localization_only(True)
        assert loc.step(img, 1).localization_only
        loc.set_localization_only(False)
        assert not loc.step(img, 2).localization_only


@pytest.mark.parametrize("mode", ["markers", "rgbd", "stereo", "mono", "static"])
def test_the_warm_up_reaches_the_first_frames_work_and_leaves_nothing_behind(mode, monkeypatch):
    """Issue 18: the node's warm-up builds a localizer of its mode on a camera of its own, steps it once on a textured
    frame (so far that the markers are searched for, ORB features extracted) and closes it, with no mapping worker
    even when the node maps in one; the live localizer still waits for a CameraInfo."""
    from simreal_nodes.assimilation import localizer as loc_mod
    from simreal_nodes.vision.markers import MarkerLocalizer
    from simreal_nodes.vision.orb import OrbExtractor

    made, work = [], []
    real = loc_mod.make_localizer

    def spy(*a, **kw):
        made.append(kw)
        core = real(*a, **kw)
        closed = core.close
        core.close = lambda: (made.append("closed"), closed())
        return core

    for cls, name in ((OrbExtractor, "extract"), (MarkerLocalizer, "locate")):
        fn = getattr(cls, name)
        monkeypatch.setattr(cls, name,
                            lambda self, *a, _fn=fn, _n=name, **kw: (work.append(_n), _fn(self, *a, **kw))[1])
    monkeypatch.setattr(loc_mod, "make_localizer", spy)
    live = LiveLocalizer(MARKERS if mode == "markers" else dict(SLAM, mode=mode), async_mapping=True)
    live.warm_up()
    assert live.cam is None and live.core is None and live.not_ready() == "waiting for a valid CameraInfo"
    if mode == "static":
        assert made == [] and work == []
    else:
        assert made[-1] == "closed" and "async_mapping" not in made[0]  # (built without a worker)
        assert work and set(work) == {"locate" if mode == "markers" else "extract"}
