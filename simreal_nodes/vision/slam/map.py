"""Map of a feature-based SLAM: keyframes (pose, ORB features, feature -> map point links) and map
points (position, representative descriptor, observations), with save / load to HDF5 (no pickle)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from simreal_nodes.errors import SimrealError
from simreal_nodes.vision.orb import Features, hamming

MAP_FORMAT = "simreal-slam-map"
MAP_VERSION = 1


class MapPoint:
    """A map point; its position and descriptor live in the map's arrays (fast batch access), in its row ``row``
    (:meth:`Map.rows`; the map renumbers the rows of its live points when it compacts them)."""

    __slots__ = ("_m", "bad", "deformable", "first_kf", "id", "obs", "row")

    def __init__(self, id: int, store: Map, row: int, obs=None, deformable: bool = False):
        self.id, self._m, self.row = id, store, row
        self.obs: dict = obs if obs is not None else {}  # keyframe id -> feature index
        store._nvis[row] = 1
        store._nfound[row] = 1
        self.first_kf = -1
        self.bad = False
        self.deformable = deformable

    @property
    def pos(self) -> np.ndarray:
        return self._m._pos[self.row]

    @pos.setter
    def pos(self, v) -> None:
        self._m._pos[self.row] = v

    @property
    def desc(self) -> np.ndarray:
        return self._m._desc[self.row]

    @desc.setter
    def desc(self, v) -> None:
        self._m._desc[self.row] = v

    @property
    def n_visible(self) -> int:
        return int(self._m._nvis[self.row])

    @n_visible.setter
    def n_visible(self, v) -> None:
        self._m._nvis[self.row] = v

    @property
    def n_found(self) -> int:
        return int(self._m._nfound[self.row])

    @n_found.setter
    def n_found(self, v) -> None:
        self._m._nfound[self.row] = v

    @property
    def found_ratio(self) -> float:
        return self.n_found / max(self.n_visible, 1)


@dataclass
class KeyFrame:
    id: int
    stamp: int
    T_wc: np.ndarray  # camera pose in the map (camera -> map)
    feats: Features
    mp: np.ndarray  # (N,) map point id per feature, -1 none
    depth: np.ndarray | None = None  # (N,) metric depth per feature (RGB-D / stereo), NaN unknown
    _tree: cKDTree | None = field(default=None, repr=False, compare=False)

    @property
    def tree(self) -> cKDTree:
        """k-d tree of the features' ideal pixels (built once: a keyframe's features never change)."""
        if self._tree is None:
            self._tree = cKDTree(self.feats.und)
        return self._tree

    @property
    def T_cw(self) -> np.ndarray:
        R = self.T_wc[:3, :3]
        T = np.eye(4)
        T[:3, :3] = R.T
        T[:3, 3] = -R.T @ self.T_wc[:3, 3]
        return T

    @property
    def center(self) -> np.ndarray:
        return self.T_wc[:3, 3]


class Map:
    def __init__(self) -> None:
        self.points: dict[int, MapPoint] = {}
        self.keyframes: dict[int, KeyFrame] = {}
        self._next_pt = 0
        self._next_kf = 0
        self.scale_known = False
        # the points' arrays, one row per point made since the last compaction, in the order of their ids (ids only
        # grow, so a point's row is found by bisection: rows()); the rows of erased points are dropped by compact(),
        # so memory follows the live map, not every point ever made (a map that keeps culling what it makes, as
        # the soak's camera sweeping back and forth over the boot)
        self._ids = np.zeros(1024, np.int64)  # the point id of each row
        self._n = 0  # rows in use
        self._pos = np.zeros((1024, 3))
        self._desc = np.zeros((1024, 32), np.uint8)
        self._nvis = np.zeros(1024, np.int64)
        self._nfound = np.zeros(1024, np.int64)
        self._alive = np.zeros(1024, bool)
        # distance at which a point would be seen at pyramid level 0 (its first observation's distance x scale^level;
        # ORB-SLAM2's max distance): the level it is predicted at from elsewhere; NaN unknown (points of a loaded map)
        self._dist0 = np.full(1024, np.nan)
        self.version = 0  # bumped by every keyframe change (caches key on it)
        self.links = 0  # bumped by every change of a keyframe's point links (caches of them key on it)
        # every observation as arrays (point id, keyframe id, feature index), from the keyframes' point links; rebuilt
        # on the first query after a link changes (the covisibility queries read it instead of looping over points)
        self._obs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        # the rows of those observations' points: (the observation arrays they belong to, the compactions done
        # then, the rows), redone for new arrays or after a compaction (observation_rows)
        self._obs_rows: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], int, np.ndarray] | None = None
        self._compactions = 0

    def _reserve(self, n: int) -> None:
        """Room for ``n`` rows."""
        if n > len(self._pos):
            cap = max(n, 2 * len(self._pos))
            self._ids = np.resize(self._ids, cap)
            self._pos = np.resize(self._pos, (cap, 3))
            self._desc = np.resize(self._desc, (cap, 32))
            self._nvis = np.resize(self._nvis, cap)
            self._nfound = np.resize(self._nfound, cap)
            alive = np.zeros(cap, bool)
            alive[: len(self._alive)] = self._alive
            self._alive = alive
            dist0 = np.full(cap, np.nan)
            dist0[: len(self._dist0)] = self._dist0
            self._dist0 = dist0

    @property
    def n_rows(self) -> int:
        """Rows in use (live points and erased ones not yet compacted): the size of a per-row array."""
        return self._n

    def _find(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, held) of each id: ``held`` where the map has a row for it (live, or erased since the last
        compaction)."""
        rows = np.searchsorted(self._ids[: self._n], ids)
        held = rows < self._n
        held[held] = self._ids[rows[held]] == ids[held]
        return rows, held

    def rows(self, ids) -> np.ndarray:
        """The array rows of the points ``ids`` (each must have a row: a live point, or one erased since the last
        :meth:`compact`; KeyError otherwise)."""
        ids = np.asarray(ids, np.int64)
        rows, held = self._find(ids)
        if not np.all(held):
            raise KeyError(f"map points without a row: {ids[~held][:5].tolist()}")
        return rows

    def alive(self, ids: np.ndarray) -> np.ndarray:
        """Mask of the ids that are live points."""
        ids = np.asarray(ids, np.int64)
        if not len(ids):
            return np.zeros(0, bool)
        rows, held = self._find(ids)
        held[held] = self._alive[rows[held]]
        return held

    def compact(self, min_rows: int = 4096, min_dead_share: float = 0.5) -> bool:
        """Drop the rows of erased points once they are over ``min_dead_share`` of the rows (and there are
        ``min_rows`` rows or more); live points keep their order and get their new rows. Call it where no row
        numbers are held (the SLAM: at a frame's start). True when it compacted."""
        n, live = self._n, len(self.points)
        if n < min_rows or n == live or n - live <= min_dead_share * n:
            return False
        keep = np.flatnonzero(self._alive[:n])
        for a in (self._ids, self._pos, self._desc, self._nvis, self._nfound, self._alive, self._dist0):
            a[: len(keep)] = a[keep]
        self._alive[len(keep):n] = False
        self._dist0[len(keep):n] = np.nan
        self._n = len(keep)
        for r, pid in enumerate(self._ids[: self._n].tolist()):
            self.points[pid].row = r
        self._compactions += 1
        return True

    # -- editing --------------------------------------------------------------------------------------------
    def new_keyframe(self, stamp, T_wc, feats, depth=None) -> KeyFrame:
        kf = KeyFrame(self._next_kf, stamp, np.array(T_wc, dtype=np.float64), feats, -np.ones(len(feats), np.int64),
                      depth)
        self.keyframes[kf.id] = kf
        self.version += 1
        self._next_kf += 1
        self._obs = None
        self.links += 1
        return kf

    def new_point(self, pos, desc, kf: KeyFrame | None = None, idx: int | None = None) -> MapPoint:
        self._reserve(self._n + 1)
        row = self._n
        self._ids[row] = self._next_pt
        self._n += 1
        p = MapPoint(self._next_pt, self, row)
        p.pos, p.desc = pos, desc
        self._alive[row] = True
        self._next_pt += 1
        self.points[p.id] = p
        if kf is not None:
            assert idx is not None  # every caller that links to a keyframe names the feature
            p.first_kf = kf.id
            self._dist0[row] = np.linalg.norm(np.asarray(pos) - kf.center) * kf.feats.scale_factor ** int(
                kf.feats.octave[idx])
            self.link(p, kf, idx)
        return p

    def link(self, p: MapPoint, kf: KeyFrame, idx: int) -> None:
        """``kf``'s feature ``idx`` observes ``p`` (replacing the point it observed; a keyframe observes a point
        through one feature, so a link of ``p`` elsewhere in ``kf`` is dropped: ``kf.mp`` and the points' ``obs``
        stay each other's inverse)."""
        old = kf.mp[idx]
        if old >= 0 and old != p.id and old in self.points:
            self.points[old].obs.pop(kf.id, None)
        prev = p.obs.get(kf.id)
        if prev is not None and prev != idx and kf.mp[prev] == p.id:
            kf.mp[prev] = -1
        kf.mp[idx] = p.id
        p.obs[kf.id] = idx
        self._obs = None
        self.links += 1

    def unlink(self, p: MapPoint, kf: KeyFrame) -> None:
        """``kf`` no longer observes ``p`` (an outlier observation)."""
        idx = p.obs.pop(kf.id, None)
        if idx is not None and kf.mp[idx] == p.id:
            kf.mp[idx] = -1
        self._obs = None
        self.links += 1

    def erase_point(self, pid: int) -> None:
        p = self.points.pop(pid, None)
        if p is None:
            return
        self._alive[p.row] = False
        self._obs = None
        self.links += 1
        for kid, idx in p.obs.items():
            kf = self.keyframes.get(kid)
            if kf is not None and kf.mp[idx] == pid:
                kf.mp[idx] = -1

    def erase_keyframe(self, kid: int) -> None:
        kf = self.keyframes.pop(kid, None)
        if kf is None:
            return
        self.version += 1
        self._obs = None
        self.links += 1
        for pid in kf.mp:
            if pid >= 0 and pid in self.points:
                p = self.points[pid]
                p.obs.pop(kid, None)
                if len(p.obs) == 0:
                    self.points.pop(pid)
                    self._alive[p.row] = False

    def predicted_level(self, ids: np.ndarray, center: np.ndarray, scale_factor: float) -> np.ndarray:
        """The pyramid level (float) at which the points ``ids`` should be detected from a camera at ``center``;
        NaN where unknown."""
        rows = self.rows(ids)
        d = np.linalg.norm(self._pos[rows] - center, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.log(self._dist0[rows] / np.maximum(d, 1e-9)) / np.log(scale_factor)

    def fuse(self, keep: MapPoint, drop: MapPoint) -> None:
        """Replace ``drop`` by ``keep`` in every keyframe that observes it."""
        for kid, idx in list(drop.obs.items()):
            kf = self.keyframes.get(kid)
            if kf is None:
                continue
            if kid in keep.obs:
                kf.mp[idx] = -1
            else:
                kf.mp[idx] = keep.id
                keep.obs[kid] = idx
        keep.n_visible += drop.n_visible
        keep.n_found += drop.n_found
        self.points.pop(drop.id, None)
        self._alive[drop.row] = False
        self._obs = None
        self.links += 1

    # -- queries --------------------------------------------------------------------------------------------
    def observations(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every observation as three arrays: point id, keyframe id, feature index (from the keyframes' point
        links, which are the inverse of the points' ``obs``); cached until a link changes."""
        if self._obs is None:
            kfs = list(self.keyframes.values())
            if not kfs:
                e = np.zeros(0, np.int64)
                self._obs = (e, e, e)
            else:
                mp = np.concatenate([k.mp for k in kfs]).astype(np.int64)
                kid = np.repeat(np.array([k.id for k in kfs], np.int64), [len(k.mp) for k in kfs])
                idx = np.concatenate([np.arange(len(k.mp), dtype=np.int64) for k in kfs])
                keep = mp >= 0
                keep[keep] = self.alive(mp[keep])
                self._obs = (mp[keep], kid[keep], idx[keep])
        return self._obs

    def observation_rows(self) -> np.ndarray:
        """The rows of :meth:`observations`' point ids (``rows(observations()[0])``), kept with those arrays until a
        link changes or the rows are compacted (the covisibility and BA queries of one frame read it several
        times)."""
        obs = self.observations()
        c = self._obs_rows
        if c is None or c[0] is not obs or c[1] != self._compactions:
            rows = self.rows(obs[0])
            rows.setflags(write=False)  # shared by every reader until the next change
            c = self._obs_rows = (obs, self._compactions, rows)
        return c[2]

    def observers(self, ids) -> dict[int, int]:
        """Keyframe id -> how many of the points ``ids`` it observes (a point listed twice counts twice; points no
        longer in the map are skipped), ordered by count, most first, then by keyframe id, newest first."""
        ids = np.asarray(ids, np.int64).ravel()
        ids = ids[self.alive(ids)]
        pid, kid, _ = self.observations()
        if len(ids) == 0 or len(pid) == 0:
            return {}
        weight = np.bincount(self.rows(ids), minlength=self._n)[self.observation_rows()]
        sel = weight > 0
        if not np.any(sel):
            return {}
        return self.ranked(kid[sel], weight[sel])

    @staticmethod
    def ranked(kid: np.ndarray, weight: np.ndarray | None = None) -> dict[int, int]:
        """Keyframe id -> its (weighted) count among ``kid``, most first, then the newest first."""
        if len(kid) == 0:
            return {}
        kids, inv = np.unique(kid, return_inverse=True)
        counts = np.bincount(inv, weights=weight).astype(np.int64)
        order = np.lexsort((-kids, -counts))
        return {int(k): int(c) for k, c in zip(kids[order], counts[order])}

    def covisible(self, kf: KeyFrame, n: int = 10, min_shared: int = 1) -> list[KeyFrame]:
        """The ``n`` keyframes sharing most points with ``kf`` (at least ``min_shared``), most first (ties: the
        newest first)."""
        counts = self.observers(kf.mp[kf.mp >= 0])
        counts.pop(kf.id, None)
        best = [k for k, c in counts.items() if c >= min_shared][:n]
        return [self.keyframes[k] for k in best if k in self.keyframes]

    def reference_keyframe(self, p: MapPoint) -> int:
        """The keyframe a point moves with when the map is corrected: the one that made it, or while that is gone the
        oldest that sees it (-1: none)."""
        return p.first_kf if p.first_kf in self.keyframes else min(p.obs, default=-1)

    def point_arrays(self, ids=None):
        """(ids, positions, descriptors) of live points (all, or those of ``ids`` that still exist)."""
        if ids is None:
            ids = np.fromiter(self.points.keys(), np.int64, len(self.points))
        else:
            ids = np.asarray(ids, np.int64)
            ids = ids[self.alive(ids)]
        if len(ids) == 0:
            return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 32), np.uint8)
        rows = self.rows(ids)
        return ids, self._pos[rows], self._desc[rows]

    def update_descriptor(self, p: MapPoint) -> None:
        """Representative descriptor: the observation with the least median distance to the others."""
        descs = [self.keyframes[k].feats.desc[i] for k, i in p.obs.items() if k in self.keyframes]
        if len(descs) < 3:
            if descs:
                p.desc = descs[-1]
            return
        D = np.array(descs, dtype=np.uint8)
        dist = hamming(D[:, None, :], D[None, :, :])  # every pair
        p.desc = D[int(np.argmin(np.median(dist, axis=1)))]

    # -- persistence ----------------------------------------------------------------------------------------
    def save(self, path: str | Path, camera=None, mode: str = "") -> None:
        import h5py

        path = Path(path)
        ids, P, D = self.point_arrays()
        with h5py.File(path, "w") as f:
            f.attrs.update(format=MAP_FORMAT, format_version=MAP_VERSION, mode=mode, scale_known=self.scale_known)
            if camera is not None:
                f.attrs["camera_K"] = camera.K
                f.attrs["camera_size"] = [camera.width, camera.height]
            g = f.create_group("points")
            g["id"], g["pos"], g["desc"] = ids, P, D
            g["deformable"] = np.array([self.points[i].deformable for i in ids], bool)
            obs = [(pid, kid, idx) for pid in ids for kid, idx in self.points[pid].obs.items()]
            g["obs"] = np.array(obs, np.int64).reshape(-1, 3)
            k = f.create_group("keyframes")
            for kf in self.keyframes.values():
                h = k.create_group(str(kf.id))
                h.attrs["stamp"] = kf.stamp
                h["T_wc"], h["uv"], h["und"] = kf.T_wc, kf.feats.uv, kf.feats.und
                h["octave"], h["desc"], h["response"] = kf.feats.octave, kf.feats.desc, kf.feats.response
                h["mp"] = kf.mp
                h.attrs["scale_factor"] = kf.feats.scale_factor
                if kf.feats.stretch is not None:  # a fisheye's (absent from maps of other cameras)
                    h["stretch"] = kf.feats.stretch
                if kf.depth is not None:
                    h["depth"] = kf.depth

    @classmethod
    def load(cls, path: str | Path) -> Map:
        import h5py

        path = Path(path)
        if not path.exists():
            raise SimrealError(f"map file not found: {path}")
        try:
            f = h5py.File(path, "r")
        except OSError as e:
            raise SimrealError(f"{path} is not a readable HDF5 map (truncated or corrupt?): {e}") from None
        with f:
            if f.attrs.get("format") != MAP_FORMAT:
                raise SimrealError(f"{path} is not a simreal SLAM map")
            if int(f.attrs.get("format_version", -1)) != MAP_VERSION:
                raise SimrealError(f"{path}: unsupported map version {f.attrs.get('format_version')}")
            m = cls()
            m.scale_known = bool(f.attrs.get("scale_known", False))
            try:
                for key, h in f["keyframes"].items():
                    stretch = h["stretch"][()] if "stretch" in h else None
                    feats = Features(h["uv"][()], h["und"][()], h["octave"][()], h["desc"][()], h["response"][()],
                                     float(h.attrs["scale_factor"]), stretch)
                    if stretch is not None and stretch.shape != (len(feats),):
                        raise SimrealError(f"{path}: keyframe {key}'s stretch has {stretch.shape}, not one value a "
                                           "feature")
                    kf = KeyFrame(int(key), int(h.attrs["stamp"]), h["T_wc"][()], feats, h["mp"][()],
                                  h["depth"][()] if "depth" in h else None)
                    m.keyframes[kf.id] = kf
                g = f["points"]
                ids = g["id"][()]
                pos_all, desc_all, dfm_all = g["pos"][()], g["desc"][()], g["deformable"][()]
                if not len(ids) == len(pos_all) == len(desc_all) == len(dfm_all):
                    raise SimrealError(f"{path}: the points' datasets differ in length")
                order = np.argsort(ids, kind="stable")
                if len(ids) and (ids[order[0]] < 0 or np.any(np.diff(ids[order]) == 0)):
                    raise SimrealError(f"{path}: negative or repeated point ids")
                m._reserve(max(len(ids), 1))
                for row, k in enumerate(order):
                    pid = int(ids[k])
                    m._ids[row] = pid
                    m._n = row + 1
                    p = MapPoint(pid, m, row, deformable=bool(dfm_all[k]))
                    p.pos, p.desc = pos_all[k], desc_all[k]
                    m._alive[row] = True
                    m.points[pid] = p
                for pid, kid, idx in g["obs"][()]:
                    if int(pid) in m.points and int(kid) in m.keyframes:
                        m.points[int(pid)].obs[int(kid)] = int(idx)
            except KeyError as e:
                raise SimrealError(f"{path}: incomplete map ({e})") from None
            m._next_pt = max(m.points, default=-1) + 1
            m._next_kf = max(m.keyframes, default=-1) + 1
            return m
