"""The SLAM map's point store: rows that follow the live map, not every point ever made (issue 20's soak)."""

import h5py
import numpy as np
import pytest

from simreal_nodes.errors import SimrealError
from simreal_nodes.vision.slam.map import Map
from simreal_nodes.vision.slam.system import Slam
from tests.synthdata import sequence


def test_a_map_that_keeps_culling_what_it_makes_keeps_its_rows_bounded():
    """Points made and erased as a long live run does (ten made a step, most erased a few steps later, a few kept
    for good): the rows stay within a few times the live points while the ids keep growing, every live point keeps
    its own position, descriptor and counts through the compactions, and an erased id reads as dead."""
    m = Map()
    rng = np.random.default_rng(0)
    truth: dict[int, tuple[np.ndarray, np.ndarray, int]] = {}
    compactions, most_rows = 0, 0
    for _ in range(3000):
        compactions += m.compact(min_rows=256)
        for _ in range(10):
            p = m.new_point(rng.normal(size=3), rng.integers(0, 256, 32, dtype=np.uint8))
            p.n_visible = int(rng.integers(1, 100))
            truth[p.id] = (p.pos.copy(), p.desc.copy(), p.n_visible)
        for pid in [i for i in m.points if i >= m._next_pt - 60 and i % 7 != 0 and rng.random() < 0.3]:
            m.erase_point(pid)
            truth.pop(pid)
        most_rows = max(most_rows, m.n_rows)
    assert m._next_pt == 30000 and compactions > 10
    assert len(m.points) == len(truth) and len(m.points) > 4000  # the kept seventh, and the young ones
    assert most_rows <= 2 * len(m.points) + 256 and len(m._pos) <= 4 * len(m.points) + 1024
    ids = np.array(sorted(truth), np.int64)
    got_ids, P, D = m.point_arrays()
    assert np.array_equal(np.sort(got_ids), ids)
    order = np.argsort(got_ids)
    assert np.array_equal(P[order], np.array([truth[i][0] for i in ids]))
    assert np.array_equal(D[order], np.array([truth[i][1] for i in ids]))
    assert [m.points[i].n_visible for i in ids[:50]] == [truth[i][2] for i in ids[:50]]
    dead = np.setdiff1d(np.arange(30000), ids)[:100]
    assert not m.alive(dead).any() and m.alive(ids).all()
    assert m.alive(np.array([10**12, -5])).tolist() == [False, False]  # ids never made
    with pytest.raises(KeyError, match="without a row"):
        m.rows(dead[:3])  # compacted away: reading one is a bug, never another point's row


@pytest.fixture(scope="module")
def room():
    return sequence("slam_room", 640, 480, duration=3.0, fps=30.0, ssaa=1)


@pytest.mark.parametrize("mode", ["rgbd", "mono"])
def test_compacting_after_every_frame_changes_no_result(room, mode, monkeypatch):
    """The rows are storage only: a SLAM run that compacts whenever one erased point's row is left gives the same
    poses and the same observed points (ids and positions) to the bit as one that never compacts."""
    real, compacted = Map.compact, []

    def every_frame(m: Map, *_args) -> bool:
        compacted.append(real(m, 0, 0.0))
        return compacted[-1]

    def run(compact_every_frame: bool):
        monkeypatch.setattr(Map, "compact", every_frame if compact_every_frame else lambda *_: False)
        slam = Slam(room["cam"], mode, 1000)
        out = []
        for i in range(len(room["gray"])):
            r = slam.track(room["gray"][i], i, depth=room["depth"][i] if mode == "rgbd" else None)
            out.append((r.T_wc, r.obs_ids.copy(), r.obs_pos.copy()))
        return slam, out

    slam_a, a = run(False)
    slam_b, b = run(True)
    assert sum(compacted) >= 3  # points were erased and their rows dropped, several times
    assert slam_b.map.n_rows < slam_a.map.n_rows
    for (Ta, ia, Pa), (Tb, ib, Pb) in zip(a, b):
        assert (Ta is None) == (Tb is None)
        if Ta is not None:
            assert np.array_equal(Ta, Tb)
        assert np.array_equal(ia, ib) and np.array_equal(Pa, Pb)
    assert sum(T is not None for T, _, _ in a) >= 30  # poses to compare (mono starts after a while)


def test_a_map_file_is_read_into_as_many_rows_as_it_has_points(tmp_path):
    """A point id far beyond the file's point count (a corrupt or hostile file) costs no memory by its size;
    repeated or negative ids are refused with a reason."""
    m = Map()
    rng = np.random.default_rng(1)
    for _ in range(5):
        m.new_point(rng.normal(size=3), rng.integers(0, 256, 32, dtype=np.uint8))
    f = tmp_path / "map.h5"
    m.save(f)
    with h5py.File(f, "r+") as h:
        ids = h["points/id"][()]
        ids[-1] = 2**40
        h["points/id"][...] = ids
    m2 = Map.load(f)
    assert m2.n_rows == 5 and len(m2._pos) < 2048
    assert np.array_equal(m2.points[2**40].pos, m.points[4].pos)
    assert m2._next_pt == 2**40 + 1
    with h5py.File(f, "r+") as h:
        ids[0] = ids[1]
        h["points/id"][...] = ids
    with pytest.raises(SimrealError, match="repeated point ids"):
        Map.load(f)


def test_a_points_descriptor_is_the_observation_closest_to_the_others():
    """ORB-SLAM2's representative descriptor: of the observations, the one with the least median Hamming distance
    to the others. One descriptor and four copies of it with 6-30 bits flipped (each copy its own bits), one of them
    observed twice: the unflipped one is nearest to all (each copy is further from the others than from it)."""
    from simreal_nodes.vision.orb import Features

    rng = np.random.default_rng(2)
    base = rng.integers(0, 256, 32, np.uint8)
    bits = rng.permutation(256)
    descs = [base]
    for k, n in enumerate((6, 12, 20, 30)):
        flip = np.zeros(256, np.uint8)
        flip[bits[40 * k:40 * k + n]] = 1
        descs.append(base ^ np.packbits(flip))
    descs.append(descs[1])
    order = [3, 0, 5, 1, 4, 2]  # the observations' keyframe order, the base among them
    m = Map()
    p = m.new_point(np.zeros(3), descs[3])
    for i in order:
        f = Features(np.zeros((1, 2), np.float32), np.zeros((1, 2)), np.zeros(1, np.int32), descs[i][None],
                     np.zeros(1, np.float32))
        m.link(p, m.new_keyframe(0, np.eye(4), f), 0)
    m.update_descriptor(p)
    assert np.array_equal(p.desc, base)
    D = np.array([descs[i] for i in order])
    dist = np.unpackbits(D[:, None, :] ^ D[None, :, :], axis=2).sum(axis=2)
    assert np.array_equal(p.desc, D[np.argmin(np.median(dist, axis=1))])


def test_the_observations_rows_follow_links_erasures_and_compactions():
    """The cached rows of every observation's point read as the rows looked up afresh after each kind of change:
    a new keyframe, a new link, an erased point, a compaction (which moves every live point's row)."""
    from simreal_nodes.vision.orb import Features

    rng = np.random.default_rng(4)
    m = Map()

    def keyframe(n):
        f = Features(np.zeros((n, 2), np.float32), np.zeros((n, 2)), np.zeros(n, np.int32),
                     rng.integers(0, 256, (n, 32), np.uint8), np.zeros(n, np.float32))
        return m.new_keyframe(0, np.eye(4), f)

    def check():
        pid, _, _ = m.observations()
        assert np.array_equal(m.observation_rows(), m.rows(pid))
        assert np.array_equal(m._ids[m.observation_rows()], pid)

    kfs = [keyframe(300) for _ in range(3)]
    pts = [m.new_point(rng.normal(size=3), rng.integers(0, 256, 32, np.uint8)) for _ in range(600)]
    for k, kf in enumerate(kfs):
        for i in range(300):
            m.link(pts[(i + 150 * k) % 600], kf, i)
    check()
    first = m.observation_rows()
    assert m.observation_rows() is first  # kept while nothing changed
    m.link(pts[5], keyframe(10), 0)
    check()
    for p in pts[:450]:
        m.erase_point(p.id)
    check()
    rows_before = m.observation_rows().copy()
    assert m.compact(min_rows=16)
    check()
    assert not np.array_equal(m.observation_rows(), rows_before)  # the compaction moved the rows
