"""Localization on rendered sequences with exact truth: accuracy, relocalization, stated failures."""

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.vision.slam.config import INITIALIZING, LOST, NOT_STARTED, OK, RELOCALIZED, SlamConfig
from simreal_nodes.vision.slam.map import Map
from simreal_nodes.vision.slam.system import Slam
from simreal_nodes.vision.trajectory import ate
from tests.synthdata import sequence


@pytest.fixture(scope="module")
def room():
    return sequence("slam_room", 640, 480, duration=6.0, fps=30.0, stereo=True, ssaa=1)


def run(seq, mode, frames=None, **kw):
    slam = Slam(seq["cam"], mode, 1000, baseline=0.12 if mode == "stereo" else None, **kw)
    out = []
    for i in frames if frames is not None else range(len(seq["gray"])):
        r = slam.track(seq["gray"][i], i, depth=seq["depth"][i] if mode == "rgbd" else None,
                       right=seq["right"][i] if mode == "stereo" else None)
        out.append((i, r))
    return slam, out


def trajectory_error(seq, out, with_scale=False):
    ok = [(i, r.T_wc) for i, r in out if r.T_wc is not None]
    E = np.array([T[:3, 3] for _, T in ok])
    R = np.array([seq["T"][i][:3, 3] for i, _ in ok])
    return ate(E, R, with_scale), len(ok)


@pytest.mark.parametrize("mode", ["rgbd", "stereo"])
def test_metric_modes_reach_one_centimetre(room, mode):
    slam, out = run(room, mode)
    res, n = trajectory_error(room, out)
    assert n == len(room["gray"])  # tracked every frame, from the first
    assert res["rmse"] < 0.01, res["rmse"]
    assert 1.5 < res["length"] < 4.0  # a 1-2 m scene, a metre-radius arc
    assert len(slam.map.keyframes) >= 3 and len(slam.map.points) > 300


def test_monocular_within_one_percent_of_length(room):
    _slam, out = run(room, "mono", config=SlamConfig(ba_iterations=5))
    states = [r.state for _, r in out]
    assert states[0] == INITIALIZING and OK in states
    res, n = trajectory_error(room, out, with_scale=True)
    assert n >= len(room["gray"]) - 20
    assert res["rmse_pct_length"] < 1.0, res["rmse_pct_length"]


def test_blackout_is_reported_and_recovered_within_a_second(room):
    """1 s of black frames mid-sequence (the camera keeps moving, as when a hand covers the lens): state
    lost with a reason, relocalized within 1 s of the image returning."""
    seq = dict(room)
    fps, b0 = 30, 90
    black = set(range(b0, b0 + fps))
    seq["gray"] = [np.zeros_like(g) if i in black else g for i, g in enumerate(room["gray"])]
    seq["depth"] = [np.full_like(d, np.nan) if i in black else d for i, d in enumerate(room["depth"])]
    _slam, out = run(seq, "rgbd")
    during = [r for i, r in out if i in black]
    assert all(r.state == LOST and "black frame" in r.reason for r in during)
    after = [(i, r) for i, r in out if i >= b0 + fps]
    first_ok = next(i for i, r in after if r.state in (OK, RELOCALIZED))
    assert first_ok - (b0 + fps) <= fps
    assert any(r.state == RELOCALIZED for _, r in after)
    res, _ = trajectory_error(room, [(i, r) for i, r in out if i not in black])
    assert res["rmse"] < 0.02


def test_extreme_inputs_give_stated_states(room):
    slam = Slam(room["cam"], "rgbd")
    g = room["gray"][0]
    r = slam.track(np.full_like(g, 128), 0, depth=room["depth"][0])
    assert r.state == NOT_STARTED and "textureless" in r.reason
    r = slam.track(np.full_like(g, 255), 1)
    assert "saturated" in r.reason
    r = slam.track(np.zeros_like(g), 2)
    assert "black frame" in r.reason
    r = slam.track(g, 3, depth=room["depth"][0])
    assert r.state == OK
    # very fast motion: every 20th frame (about 0.4 m between frames)
    for k, i in enumerate(range(20, len(room["gray"]), 20)):
        r = slam.track(room["gray"][i], 4 + k, depth=room["depth"][i])
        assert r.state in (OK, LOST, RELOCALIZED) and (r.T_wc is not None or r.reason)
        if r.T_wc is not None:
            assert np.linalg.norm(r.T_wc[:3, 3] - room["T"][i][:3, 3]) < 0.05  # never a wild pose


def test_pure_rotation_cannot_initialize_a_monocular_map(room):
    from simreal_nodes.render.gl import Renderer
    from simreal_nodes.synth.makebag import make_scene

    sc = make_scene("slam_room", 640, 480)
    r = Renderer(sc.camera, ssaa=1)
    sc.build(sc, r, {})
    T0 = sc.camera_pose(0.0)
    slam = Slam(sc.camera, "mono")
    import cv2
    for k in range(20):
        T = T0 @ G.make_T(G.rot_axis("y", np.deg2rad(0.5 * k)))  # rotating about the optical centre
        rgb, _ = r.render(T)
        res = slam.track(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), k)
    r.release()
    assert res.state == INITIALIZING
    assert "parallax" in res.reason or "reconstruction" in res.reason


def test_map_save_load_and_relocalize(room, tmp_path):
    slam, _out = run(room, "rgbd", frames=range(0, 60))
    f = tmp_path / "map.h5"
    slam.map.save(f, room["cam"], "rgbd")
    m = Map.load(f)
    assert len(m.points) == len(slam.map.points) and len(m.keyframes) == len(slam.map.keyframes)
    s2 = Slam(room["cam"], "rgbd")
    s2.load_map(m)
    s2.set_localization_only(True)
    r = s2.track(room["gray"][35], 0, depth=room["depth"][35])
    assert r.state == RELOCALIZED
    assert np.linalg.norm(r.T_wc[:3, 3] - room["T"][35][:3, 3]) < 0.01
    n_kf = len(s2.map.keyframes)
    for i in range(36, 60):
        s2.track(room["gray"][i], i, depth=room["depth"][i])
    assert len(s2.map.keyframes) == n_kf  # localization-only: the map stays frozen
    (tmp_path / "bad.h5").write_bytes(b"not hdf5")
    from simreal_nodes.errors import SimrealError
    with pytest.raises(SimrealError, match="not a readable HDF5 map"):
        Map.load(tmp_path / "bad.h5")


def test_a_map_loaded_into_a_running_slam_leaves_nothing_of_the_session_before(room, tmp_path):
    """A saved map numbers its points and keyframes from 0, as the running session did: whatever the session kept
    about its own map (the deformable tracks' predictions, the tracker's local map, the mapper's new points) would be
    read as the loaded map's. load_map starts those parts afresh and keeps the localization-only switch."""
    saved, _ = run(room, "rgbd", frames=range(0, 60))
    f = tmp_path / "map.h5"
    saved.map.save(f, room["cam"], "rgbd")
    slam, _ = run(room, "rgbd", frames=range(100, 150))  # a session of its own on another stretch of the room
    ids = sorted(slam.map.points)[:40]
    slam.set_deformable(ids, np.zeros((len(ids), 3)))
    r = slam.track(room["gray"][150], 150, depth=room["depth"][150])
    assert 0 < r.timings["deformable_ms"] < r.timings["total_ms"]  # the object's points' measurement, timed
    assert slam.tracks._predicted and slam.tracker._local_cache and slam.mapper._recent_points
    slam.set_localization_only(True)
    m = Map.load(f)
    slam.load_map(m)
    assert slam.map is m and slam.state == LOST and slam.localization_only
    assert not slam.tracks._predicted and not slam.tracks._last_seen and not slam.tracks._flow
    assert not slam.tracker._local_cache and not slam.mapper._recent_points
    assert slam.ctx.deformable == {p.id for p in m.points.values() if p.deformable}
    r = slam.track(room["gray"][35], 151, depth=room["depth"][35])
    assert r.state == RELOCALIZED
    assert np.linalg.norm(r.T_wc[:3, 3] - room["T"][35][:3, 3]) < 0.01
    n_kf = len(m.keyframes)
    for i in range(36, 50):
        assert slam.track(room["gray"][i], 151 + i, depth=room["depth"][i]).T_wc is not None
    assert len(slam.map.keyframes) == n_kf
    fresh = Slam(room["cam"], "rgbd")  # nothing seen: nothing to forget, its parts kept
    mapper = fresh.mapper
    fresh.load_map(Map.load(f))
    assert fresh.mapper is mapper
    told = Slam(room["cam"], "rgbd")  # no frame yet, but told of object points: those go
    told.set_deformable([1, 2], np.zeros((2, 3)))
    told.load_map(Map.load(f))
    assert not told.tracks._predicted and told.ctx.deformable == set()



def test_every_change_of_a_keyframes_links_renews_the_local_map_cache(room):
    """Issue 18: the tracker keeps the local map's point ids between frames while the map's version, its links'
    count and the keyframes are the same (``Tracker._local_cache``). Each way a keyframe's links change (a link, a new
    point on a keyframe, an unlink, a fusion, a point erased, a keyframe erased) must give the set computed afresh;
    a change that left ``Map.links`` as it was would leave the old set (checked: without its bump, a link, an unlink
    or a fusion fails here; an erased point is left out by the alive filter, an erased keyframe changes the version).
    On the room's frames the poses would not show it: every mapping step there also adds a keyframe."""
    slam, _ = run(room, "rgbd", range(45))
    tr, m = slam.tracker, slam.map
    kf = slam.ctx.ref_kf
    assert kf is not None and len(m.keyframes) >= 3

    def check(change) -> np.ndarray:
        before = tr.local_points()  # the set cached before the change
        change()
        cached = tr.local_points()
        tr._local_cache.clear()
        np.testing.assert_array_equal(cached, tr.local_points())
        return before

    some = m.points[int(kf.mp[kf.mp >= 0][0])]
    p, q = (m.new_point(some.pos + d, some.desc) for d in (0.01, 0.02))  # points no keyframe observes yet
    free = np.flatnonzero(kf.mp < 0)
    assert len(free) >= 2
    before = check(lambda: m.link(p, kf, int(free[0])))
    assert p.id not in before and p.id in tr.local_points()  # the change is one the set shows
    new = []
    check(lambda: new.append(m.new_point(p.pos + 0.01, p.desc, kf, int(free[1]))))
    assert new[0].id in tr.local_points()
    check(lambda: m.unlink(p, kf))
    inside = int(kf.mp[kf.mp >= 0][0])
    check(lambda: m.fuse(q, m.points[inside]))
    assert q.id in tr.local_points()
    check(lambda: m.erase_point(new[0].id))
    check(lambda: m.erase_keyframe(max(k for k in m.keyframes if k != kf.id)))


def test_the_local_map_cache_stays_bounded_on_a_map_that_does_not_change(room):
    """A frozen map (localization only) keeps its version and links while the camera moves over new sets of
    keyframes: the tracker keeps a few sets, not one per set ever seen."""
    from simreal_nodes.vision.slam.tracking import LOCAL_CACHE_SETS

    slam, _ = run(room, "rgbd", range(60), config=SlamConfig(local_kfs=2))  # a local map of a few keyframes
    tr, m = slam.tracker, slam.map
    kids = sorted(m.keyframes)
    seen = set()
    for i in range(len(kids)):
        slam.ctx.ref_kf = m.keyframes[kids[i]]
        seen.add(tuple(tr.local_points()))
        seed = m.keyframes[kids[-1 - i]].mp
        seen.add(tuple(tr.local_points(seed_ids=seed[seed >= 0][:40])))
        assert len(tr._local_cache) <= LOCAL_CACHE_SETS
    assert len(seen) > LOCAL_CACHE_SETS  # more sets were asked for than are kept


def test_rgbd_slam_through_a_fisheye_lens(tmp_path):
    """An equidistant (fisheye) camera's frames, rendered through that lens (the room, 3 s): every frame tracked,
    the trajectory within 1 cm (3.2 mm when written). A fisheye's periphery lies far outside the ideal image's
    rectangle and is stretched there (4 ideal pixels a pixel at 60 degrees off the axis): with the rectangle as the
    image's bounds and errors weighed in ideal pixels as a pinhole's, the SLAM lost this clip at frame 30. A map saved
    and loaded keeps each keyframe's stretch."""
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.synth.sequence import FrameStream

    fish = CameraModel(640, 480, [[330.0, 0, 321.3], [0, 328.0, 238.6], [0, 0, 1]],
                       [-0.021, 0.0043, -0.0012, 0.0001], "equidistant")
    fs = FrameStream("slam_room", 640, 480, duration=3.0, fps=30.0, ssaa=1)
    fs.cam = fs.scene.camera = fish
    slam = Slam(fish, "rgbd", 1000)
    E, R = [], []
    for i, f in enumerate(fs):
        r = slam.track(f["gray"], i, depth=f["depth"])
        assert r.T_wc is not None, (i, r.reason)
        E.append(r.T_wc[:3, 3])
        R.append(f["T"][:3, 3])
    assert len(E) == 90 and ate(np.array(E), np.array(R), False)["rmse"] < 0.01
    kf = next(iter(slam.map.keyframes.values()))
    assert kf.feats.stretch is not None and kf.feats.stretch.max() > 2.0 and kf.feats.stretch.min() >= 1.0
    slam.map.save(tmp_path / "fisheye.h5", fish, "rgbd")
    back = Map.load(tmp_path / "fisheye.h5").keyframes[kf.id].feats.stretch
    np.testing.assert_array_equal(back, kf.feats.stretch)


def test_monocular_slam_through_a_fisheye_lens():
    """The room's 6 s through the same fisheye, monocular (as the pinhole camera's monocular test asks): all but 20
    frames tracked, the trajectory within 1 % of its length after a Sim3 alignment (0.10 % when written, the pinhole
    camera 0.08 %)."""
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.synth.sequence import FrameStream

    fish = CameraModel(640, 480, [[330.0, 0, 321.3], [0, 328.0, 238.6], [0, 0, 1]],
                       [-0.021, 0.0043, -0.0012, 0.0001], "equidistant")
    fs = FrameStream("slam_room", 640, 480, duration=6.0, fps=30.0, ssaa=1)
    fs.cam = fs.scene.camera = fish
    slam = Slam(fish, "mono", 1000, config=SlamConfig(ba_iterations=5))
    E, R = [], []
    for i, f in enumerate(fs):
        r = slam.track(f["gray"], i)
        if r.T_wc is not None:
            E.append(r.T_wc[:3, 3])
            R.append(f["T"][:3, 3])
    assert len(E) >= fs.n - 20
    assert ate(np.array(E), np.array(R), True)["rmse_pct_length"] < 1.0
