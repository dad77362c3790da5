"""ORB features with a scale pyramid and a spatially even distribution (in the style of ORB-SLAM2).

OpenCV's ORB ranks keypoints by response over the whole image, which piles them on the most textured
patch: a faint object beside a textured background gets none. Here, as ORB-SLAM2 does, FAST runs on
every pyramid level with a per-cell threshold fall-back (a cell with no corner at the threshold offers
its corners at a lower one), each level keeps its share of the budget spread evenly over the image
(every occupied cell its best corner first; a vectorised per-cell round robin in place of ORB-SLAM2's
quadtree), the orientation is the intensity centroid's, and OpenCV computes the rBRIEF descriptors.
Image regions where tracked objects are predicted (``focus``) get a guaranteed share of the budget.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel

_RESPONSE = operator.attrgetter("response")
# hamming: numpy 2 counts bits itself; a ROS install's python3-numpy (Ubuntu 24.04: numpy 1.26) does not
_BITWISE_COUNT = hasattr(np, "bitwise_count")
_BYTE_BITS = np.array([bin(i).count("1") for i in range(256)], np.uint8)  # set bits of every byte value


@dataclass
class Features:
    uv: np.ndarray  # (N, 2) float32, measured (distorted) pixel coordinates
    und: np.ndarray  # (N, 2) float64, ideal (undistorted) pixel coordinates of the same K
    octave: np.ndarray  # (N,) pyramid level
    desc: np.ndarray  # (N, 32) uint8
    response: np.ndarray  # (N,)
    scale_factor: float = 1.2
    # (N,) ideal pixels per image pixel where the lens stretches the ideal image (a fisheye's periphery:
    # CameraModel.stretch); None: 1 everywhere (a pinhole, or a lens whose figures were measured without it)
    stretch: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.uv)

    def sigma(self) -> np.ndarray:
        """Measurement standard deviation per feature in ideal pixels: the pyramid level's scale, times the lens's
        stretch of the ideal image where there is one."""
        s = (self.scale_factor ** self.octave).astype(np.float64)
        return s if self.stretch is None else s * self.stretch

    def sigma2(self) -> np.ndarray:
        """Measurement variance per feature (ideal pixels^2), growing with the pyramid level (and the stretch)."""
        if self.stretch is None:
            return (self.scale_factor ** (2 * self.octave)).astype(np.float64)
        return self.sigma() ** 2

    def max_sigma(self) -> float:
        """The largest :meth:`sigma` (a search's radius bound before the per-feature test); 1 when empty."""
        return float(self.sigma().max()) if len(self.octave) else 1.0

    def subset(self, idx) -> Features:
        return Features(self.uv[idx], self.und[idx], self.octave[idx], self.desc[idx], self.response[idx],
                        self.scale_factor, None if self.stretch is None else self.stretch[idx])

    @classmethod
    def empty(cls, scale_factor: float = 1.2) -> Features:
        return cls(np.zeros((0, 2), np.float32), np.zeros((0, 2)), np.zeros(0, np.int32), np.zeros((0, 32), np.uint8),
                   np.zeros(0, np.float32), scale_factor)


class OrbExtractor:
    """ORB in the style of ORB-SLAM2's extractor: FAST on every level of a scale pyramid with a per-cell threshold
    fall-back, each level's share of the budget (geometric in the level) spread evenly over the image, orientation
    by the intensity centroid, rBRIEF descriptors by OpenCV for the kept keypoints only.

    Per cell the fall-back matters: a global threshold lets a few strong patches take the whole budget while a
    faint object (a beam with a low-contrast texture) gets nothing; with the fall-back a cell with no corner at
    ``fast_threshold`` offers its corners at ``min_threshold``, and the even selection gives every occupied cell
    its best corner before any cell gets a second. ``focus`` regions (:meth:`extract`) get a guaranteed share.
    """

    def __init__(self, n_features: int = 1000, scale_factor: float = 1.2, n_levels: int = 8, grid_cell: int = 30,
                 fast_threshold: int = 20, min_threshold: int = 7):
        self.n = int(n_features)
        self.sf = float(scale_factor)
        self.levels = int(n_levels)
        self.cell = int(grid_cell)
        self.edge = EDGE
        # opencv's stubs list only cv2.ORB.create; ORB_create and KeyPoint_convert are its run-time aliases
        self.describer = cv2.ORB_create(  # type: ignore[attr-defined]
            nfeatures=self.n, scaleFactor=self.sf, nlevels=self.levels, edgeThreshold=EDGE, patchSize=2 * RADIUS + 1)
        self.fast = cv2.FastFeatureDetector.create(int(fast_threshold), True)
        self.fast_low = cv2.FastFeatureDetector.create(int(min_threshold), True)
        self.fast_focus = cv2.FastFeatureDetector.create(FOCUS_THRESHOLD, True)
        f = 1.0 / self.sf
        per = self.n * (1 - f) / (1 - f ** self.levels)
        self.per_level = [round(per * f ** k) for k in range(self.levels)]
        self.per_level[0] += self.n - sum(self.per_level)

    def pyramid(self, gray: np.ndarray) -> list[np.ndarray]:
        """Level k is the image scaled by 1 / scale_factor^k (sizes rounded as OpenCV's ORB rounds them, so that its
        descriptors are computed on the same grid)."""
        h, w = gray.shape
        levels = [gray]
        for k in range(1, self.levels):
            s = self.sf ** k
            levels.append(cv2.resize(levels[-1], (round(w / s), round(h / s)), interpolation=cv2.INTER_LINEAR))
        return levels

    def extract(self, gray: np.ndarray, cam: CameraModel | None = None, mask: np.ndarray | None = None,
                focus: Sequence[np.ndarray] = (), focus_share: float = 0.2) -> Features:
        """ORB features of one image. ``mask`` (uint8, non-zero = allowed) limits where keypoints may lie.
        ``focus``: image polygons ((K, 2) pixels, e.g. the hull of where a tracked object is predicted); each first
        receives up to ``focus_share`` of every level's budget from its own best corners, spread evenly over it (a
        faint object is measured although the rest of the image is stronger), then competes with the rest."""
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        if gray.dtype != np.uint8:
            gray = cv2.convertScaleAbs(gray)
        # a polygon that is not finite steers nothing; one far off the image is clipped to a margin around it
        # (its pixel bounds must fit an int)
        big = 4.0 * max(gray.shape)
        polys = [np.clip(q, -big, big) for q in (np.asarray(p, np.float64).reshape(-1, 2) for p in focus if len(p) >= 3)
                 if np.all(np.isfinite(q))]
        kps: list[cv2.KeyPoint] = []
        scores, levels = [], []  # per level, the kept keypoints' FAST scores and their level
        for lvl, img in enumerate(self.pyramid(gray)):
            if min(img.shape) <= 2 * self.edge:  # no pixel a patch fits around (a small image, many levels)
                continue
            s = self.sf ** lvl
            lmask = None if mask is None else cv2.resize(mask, img.shape[::-1], interpolation=cv2.INTER_NEAREST)
            pts, resp = self._candidates(img, lmask)
            chosen: list[np.ndarray] = []
            taken = None  # the focus picks' pixels (flat), so that the even selection skips them
            for poly in polys:
                want = int(focus_share * self.per_level[lvl])
                if want <= 0:
                    continue
                bp, br, area = self._focus_candidates(img, lmask, poly / s)
                key = _keys(bp, img.shape[1])
                if taken is None:
                    taken = np.zeros(img.size, bool)
                fresh = ~taken[key]
                bp, br, key = bp[fresh], br[fresh], key[fresh]
                keep = _grid_select(bp, br, _cell_for(area, want), want)
                chosen.append(np.column_stack((bp[keep], br[keep])))
                taken[key[keep]] = True
            rest = self.per_level[lvl] - sum(len(c) for c in chosen)
            if taken is not None:
                fresh = ~taken[_keys(pts, img.shape[1])]
                pts, resp = pts[fresh], resp[fresh]
            keep = _grid_select(pts, resp, _cell_for(float(img.shape[0] * img.shape[1]), max(rest, 1)), max(rest, 0))
            chosen.append(np.column_stack((pts[keep], resp[keep])))
            sel = np.concatenate(chosen)
            if not len(sel):
                continue
            p = sel[:, :2].astype(np.int64)
            # keypoints built in OpenCV per level (one call), then their orientation set
            level_kps = cv2.KeyPoint_convert((p * s).astype(np.float32), (2 * RADIUS + 1) * s, 0.0,  # type: ignore
                                             lvl)
            for k, ang in zip(level_kps, ic_angle(img, p).tolist()):
                k.angle = ang
            kps.extend(level_kps)
            scores.append(sel[:, 2])
            levels.append(np.full(len(sel), lvl, np.int32))
        if not kps:
            return Features.empty(self.sf)
        uv_in = cv2.KeyPoint_convert(kps)  # type: ignore[attr-defined]
        kps, desc = self.describer.compute(gray, kps)
        if desc is None or not kps:
            return Features.empty(self.sf)
        uv = cv2.KeyPoint_convert(kps).astype(np.float32)  # type: ignore[attr-defined]
        octave, response = np.concatenate(levels), np.concatenate(scores).astype(np.float32)
        if len(uv) != len(uv_in) or not np.array_equal(uv, uv_in):
            # OpenCV left some out (or reordered them): each output keypoint's own level and score, by position
            at = {(x, y, o): r for (x, y), o, r in zip(uv_in.tolist(), octave.tolist(), response.tolist())}
            octave = np.fromiter((k.octave for k in kps), np.int32, len(kps))
            response = np.fromiter((at.get((x, y, o), 0.0) for (x, y), o in zip(uv.tolist(), octave.tolist())),
                                   np.float32, len(kps))
        und = cam.undistort_points(uv) if cam is not None and cam.has_distortion else uv.astype(np.float64)
        stretch = None
        if cam is not None and cam.fisheye:
            # its stretch weighs each feature's error (ideal pixels) as the image pixels it was measured in; past
            # MAX_STRETCH (about 72 degrees off the axis) or with no ray at all (90), an ideal position says too little
            stretch = cam.stretch(uv)
            with np.errstate(invalid="ignore"):
                keep = np.isfinite(und[:, 0]) & (stretch <= MAX_STRETCH)
            if not keep.all():
                uv, und, octave, desc, response = uv[keep], und[keep], octave[keep], desc[keep], response[keep]
                stretch = stretch[keep]
        return Features(uv, und, octave, desc, response, self.sf, stretch)

    def _candidates(self, img: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """FAST corners of one level (all of it but the border), (N, 2) int pixel positions and their FAST scores:
        those at the threshold, plus, in the cells of about ``grid_cell`` pixels that have none, those at the
        fall-back threshold (one pass over the level where many cells are empty, one pass per empty cell where few
        are)."""
        h, w = img.shape
        e, c = self.edge, self.cell
        x0, y0, x1, y1 = e, e, w - e, h - e
        strong, weak = self.fast, self.fast_low
        pts, resp = _fast(strong, img, (x0, y0, x1, y1), mask)
        nx, ny = max((x1 - x0) // c, 1), max((y1 - y0) // c, 1)
        cw, ch = (x1 - x0) / nx, (y1 - y0) / ny  # the box split into whole cells of about c pixels
        cid = _cell_ids(pts, x0, y0, cw, ch, nx, ny)
        empty = np.flatnonzero(np.bincount(cid, minlength=nx * ny) == 0)
        if not len(empty):
            return pts, resp
        if len(empty) > 0.25 * nx * ny:  # one pass, the empty cells as its mask (OpenCV drops the rest)
            flags = np.zeros(nx * ny, np.uint8)
            flags[empty] = 255
            allowed = np.zeros((h, w), np.uint8)
            allowed[y0:y1, x0:x1] = cv2.resize(flags.reshape(ny, nx), (x1 - x0, y1 - y0),
                                               interpolation=cv2.INTER_NEAREST)
            wp, wr = _fast(weak, img, (x0, y0, x1, y1), allowed if mask is None else allowed & mask)
        else:
            wp, wr = _fast_boxes(weak, img, [(round(x0 + (k % nx) * cw), round(y0 + (k // nx) * ch),
                                              round(x0 + (k % nx + 1) * cw), round(y0 + (k // nx + 1) * ch))
                                             for k in empty], mask)
        return np.concatenate((pts, wp)), np.concatenate((resp, wr))

    def _focus_candidates(self, img: np.ndarray, mask: np.ndarray | None,
                          poly: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """FAST corners down to threshold 3 inside one focus polygon (level pixels, kept off the border), their
        scores, and the polygon's area in pixels. So low a threshold is for the object alone: a faint texture's
        corners, of which the even selection takes the best per cell."""
        h, w = img.shape
        e = self.edge
        x0, y0 = max(int(np.floor(poly[:, 0].min())), e), max(int(np.floor(poly[:, 1].min())), e)
        x1, y1 = min(int(np.ceil(poly[:, 0].max())) + 1, w - e), min(int(np.ceil(poly[:, 1].max())) + 1, h - e)
        if x1 - x0 < 1 or y1 - y0 < 1:
            return np.zeros((0, 2), np.int64), np.zeros(0, np.float32), 0.0
        inside = np.zeros((h, w), np.uint8)
        cv2.fillPoly(inside[y0 - 3:y1 + 3, x0 - 3:x1 + 3], [np.rint(poly - (x0 - 3, y0 - 3)).astype(np.int32)], 255)
        if mask is not None:
            inside &= mask
        pts, resp = _fast(self.fast_focus, img, (x0, y0, x1, y1), inside)
        return pts, resp, float(np.count_nonzero(inside[y0:y1, x0:x1]))


MAX_STRETCH = 10.0  # a fisheye's features kept where the ideal image is stretched at most this much (1 / cos^2 72 deg)
EDGE = 19  # pixels kept clear of a level's border: OpenCV ORB's edgeThreshold (the rotated 31 x 31 patch fits)
FOCUS_THRESHOLD = 3  # FAST threshold inside a focus polygon: a faint object's texture, a few grey levels
RADIUS = 15  # the orientation patch's radius (ORB: half the 31-pixel patch)
_YY, _XX = np.mgrid[-RADIUS:RADIUS + 1, -RADIUS:RADIUS + 1]
_DISC = np.hypot(_YY, _XX) <= RADIUS + 0.5
_MOMENTS = np.stack([(_XX * _DISC).ravel(), (_YY * _DISC).ravel()], axis=1).astype(np.float32)  # (961, 2)


def ic_angle(img: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Orientation in degrees [0, 360) of keypoints ``p`` ((N, 2) int x, y, at least RADIUS off the border): the
    direction to the intensity centroid of the circular patch (Rosin; ORB). All patches are gathered at once
    from a strided window view and their first moments taken by one matrix product (no loop per keypoint)."""
    k = 2 * RADIUS + 1
    patches = np.lib.stride_tricks.sliding_window_view(img, (k, k))[p[:, 1] - RADIUS, p[:, 0] - RADIUS]
    m = patches.reshape(len(p), k * k).astype(np.float32) @ _MOMENTS
    return np.degrees(np.arctan2(m[:, 1], m[:, 0])) % 360.0


def _fast(det: cv2.FastFeatureDetector, img: np.ndarray, box: tuple[int, int, int, int],
          mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """FAST corners with their scores inside ``box`` (x0, y0, x1, y1): detected on the box grown by FAST's
    3-pixel circle, so that a corner may lie on the box's edge, and those outside the box dropped."""
    return _fast_boxes(det, img, [box], mask)


def _fast_boxes(det: cv2.FastFeatureDetector, img: np.ndarray, boxes: list[tuple[int, int, int, int]],
                mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_fast` over several boxes, their corners in the boxes' order: the sub-images given to OpenCV's
    detector in one call (it loops over them itself) and their keypoints converted in one call (the empty cells'
    fall-back: dozens of small boxes a level, where a call per box cost more in Python than in FAST)."""
    h, w = img.shape
    grown = [(max(x0 - 3, 0), max(y0 - 3, 0), min(x1 + 3, w), min(y1 + 3, h)) for x0, y0, x1, y1 in boxes]
    subs = [img[b0:b1, a0:a1] for a0, b0, a1, b1 in grown]
    found = det.detect(subs, None if mask is None else [mask[b0:b1, a0:a1] for a0, b0, a1, b1 in grown])
    counts = np.fromiter(map(len, found), np.int64, len(found))
    kps = [k for part in found for k in part]
    if not kps:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.float32)
    at = np.repeat(np.asarray(grown, np.int64), counts, axis=0)  # each corner's grown box
    p = np.rint(cv2.KeyPoint_convert(kps)).astype(np.int64) + at[:, :2]  # type: ignore[attr-defined]
    r = np.fromiter(map(_RESPONSE, kps), np.float32, len(kps))
    box = np.repeat(np.asarray(boxes, np.int64), counts, axis=0)
    ok = (p[:, 0] >= box[:, 0]) & (p[:, 0] < box[:, 2]) & (p[:, 1] >= box[:, 1]) & (p[:, 1] < box[:, 3])
    return p[ok], r[ok]


def _cell_ids(p: np.ndarray, x0: int, y0: int, cw: float, ch: float, nx: int, ny: int) -> np.ndarray:
    cx = np.clip(((p[:, 0] - x0) / cw).astype(np.int64), 0, nx - 1)
    cy = np.clip(((p[:, 1] - y0) / ch).astype(np.int64), 0, ny - 1)
    return cy * nx + cx


def _keys(p: np.ndarray, w: int) -> np.ndarray:
    return p[:, 1] * w + p[:, 0]


def _cell_for(area: float, n: int) -> float:
    """The distribution cell over ``area`` pixels: about one cell per wanted keypoint, so that the first round of
    the even selection covers the area as ORB-SLAM2's quadtree would."""
    return max(float(np.sqrt(area / max(n, 1))), 1.0)


def _grid_select(pts: np.ndarray, resp: np.ndarray, cell: float, n: int) -> np.ndarray:
    """Indices of ``n`` keypoints spread evenly: every occupied cell gives its strongest, then every cell its
    second strongest, ...; within one round the stronger first (deterministic: stable sorts on exact keys, ties in
    the candidates' order). A vectorised stand-in for ORB-SLAM2's quadtree: the same even coverage with no loop over
    nodes. Only the rounds that can fill ``n`` are ordered in the second sort."""
    if n <= 0 or len(pts) == 0:
        return np.zeros(0, np.int64)
    if len(pts) <= n:
        return np.arange(len(pts))
    cx = (pts[:, 0] // cell).astype(np.int64)
    cy = (pts[:, 1] // cell).astype(np.int64)
    cid = cy * (int(cx.max()) + 1) + cx
    weak = 255 - np.clip(resp, 0, 255).astype(np.int64)  # FAST scores are whole grey levels
    order = _stable_order(cid, weak)  # by cell, strongest first
    cid_sorted = cid[order]
    at = np.arange(len(order))
    starts = np.empty(len(order), bool)  # where a cell's run begins in the sorted order
    starts[0] = True
    np.not_equal(cid_sorted[1:], cid_sorted[:-1], out=starts[1:])
    rank = at - np.maximum.accumulate(np.where(starts, at, 0))  # round of each: its place in its cell's run
    rounds = int(np.searchsorted(np.cumsum(np.bincount(rank)), n)) + 1  # the first rounds that hold n
    live = rank < rounds
    cand = order[live]
    return cand[_stable_order(rank[live], weak[cand])[:n]]


def _stable_order(major: np.ndarray, minor: np.ndarray) -> np.ndarray:
    """The stable argsort of the key ``major * 256 + minor`` (``minor`` in 0..255) as two stable passes, least
    significant first; the major pass on 16-bit keys where they fit (0..65535), which numpy sorts by radix."""
    by_minor = np.argsort(minor.astype(np.uint8), kind="stable")
    m = major[by_minor]
    small = int(m.min()) >= 0 and int(m.max()) < 1 << 16
    return by_minor[np.argsort(m.astype(np.uint16) if small else m, kind="stable")]


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise Hamming distance between two (n, 32) uint8 descriptor arrays (vectorized over candidate pairs,
    where a brute-force matcher would compare every row with every row; they broadcast, so (n, 1, 32) against
    (1, m, 32) gives every pair): the XOR's set bits, counted four 64-bit words a row where numpy can
    (``np.bitwise_count``, numpy 2), else byte by byte from a table."""
    x = np.bitwise_xor(a, b, order="C")
    if _BITWISE_COUNT and x.dtype == np.uint8 and x.shape[-1] % 8 == 0:
        return np.bitwise_count(x.view(np.uint64)).sum(axis=-1, dtype=np.int32)
    return _BYTE_BITS[x].sum(axis=-1, dtype=np.int32)


def match_descriptors(d1: np.ndarray, d2: np.ndarray, mask: np.ndarray | None = None, max_dist: int = 64,
                      ratio: float | None = None) -> np.ndarray:
    """(K, 2) index pairs: best Hamming match in d2 for each row of d1 (only where ``mask`` allows),
    with a distance bound and an optional Lowe ratio test; duplicates in d2 keep the best."""
    if len(d1) == 0 or len(d2) == 0:
        return np.zeros((0, 2), np.int64)
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    m8 = None if mask is None else np.ascontiguousarray(mask, dtype=np.uint8)
    pairs, dists = [], []
    if ratio is None:
        for mt in bf.match(d1, d2, m8) if m8 is not None else bf.match(d1, d2):
            if mt.distance <= max_dist:
                pairs.append((mt.queryIdx, mt.trainIdx))
                dists.append(mt.distance)
    else:
        knn = bf.knnMatch(d1, d2, k=2, mask=m8) if m8 is not None else bf.knnMatch(d1, d2, k=2)
        for ms in knn:
            if not ms:
                continue
            a = ms[0]
            if a.distance > max_dist:
                continue
            if len(ms) > 1 and a.distance > ratio * ms[1].distance:
                continue
            pairs.append((a.queryIdx, a.trainIdx))
            dists.append(a.distance)
    if not pairs:
        return np.zeros((0, 2), np.int64)
    P = np.asarray(pairs, np.int64)
    D = np.asarray(dists)
    order = np.argsort(D, kind="stable")
    _, first = np.unique(P[order, 1], return_index=True)
    return P[order[np.sort(first)]]
