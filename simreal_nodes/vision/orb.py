"""ORB features with a scale pyramid and a spatially even distribution (in the style of ORB-SLAM2).

OpenCV's ORB ranks keypoints by response over the whole image, which piles them on the most textured
patch. Here FAST keypoints are detected generously on every pyramid level, bucketed into a grid per
level, and the strongest few per cell are kept, so features cover the image and every scale; then
OpenCV computes their orientation and rBRIEF descriptors.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel

POPCOUNT = np.array([bin(i).count("1") for i in range(256)], np.uint8)  # set bits of every byte value


@dataclass
class Features:
    uv: np.ndarray  # (N, 2) float32, measured (distorted) pixel coordinates
    und: np.ndarray  # (N, 2) float64, ideal (undistorted) pixel coordinates of the same K
    octave: np.ndarray  # (N,) pyramid level
    desc: np.ndarray  # (N, 32) uint8
    response: np.ndarray  # (N,)
    scale_factor: float = 1.2

    def __len__(self) -> int:
        return len(self.uv)

    def sigma2(self) -> np.ndarray:
        """Measurement variance per feature (pixels^2), growing with the pyramid level."""
        return (self.scale_factor ** (2 * self.octave)).astype(np.float64)

    def subset(self, idx) -> Features:
        return Features(self.uv[idx], self.und[idx], self.octave[idx], self.desc[idx], self.response[idx],
                        self.scale_factor)

    @classmethod
    def empty(cls, scale_factor: float = 1.2) -> Features:
        return cls(np.zeros((0, 2), np.float32), np.zeros((0, 2)), np.zeros(0, np.int32), np.zeros((0, 32), np.uint8),
                   np.zeros(0, np.float32), scale_factor)


class OrbExtractor:
    """ORB with an even spatial distribution: OpenCV detects ~2.5x the wanted keypoints over its scale
    pyramid (FAST + Harris ranking), then each level keeps its share (geometric in the level, as
    ORB-SLAM2) spread over a grid of cells, strongest first; descriptors for the kept ones only."""

    def __init__(self, n_features: int = 1000, scale_factor: float = 1.2, n_levels: int = 8, grid_cell: int = 32,
                 fast_threshold: int = 20, oversample: float = 2.5):
        self.n = int(n_features)
        self.sf = float(scale_factor)
        self.levels = int(n_levels)
        self.cell = int(grid_cell)
        # opencv's stubs list only cv2.ORB.create; ORB_create and KeyPoint_convert are its run-time aliases
        self.detector = cv2.ORB_create(  # type: ignore[attr-defined]
            nfeatures=int(self.n * oversample), scaleFactor=self.sf, nlevels=self.levels, edgeThreshold=19,
            patchSize=31, fastThreshold=fast_threshold)
        self.detector_low = cv2.ORB_create(  # type: ignore[attr-defined]
            nfeatures=int(self.n * oversample), scaleFactor=self.sf, nlevels=self.levels, edgeThreshold=19,
            patchSize=31, fastThreshold=max(5, fast_threshold // 3))
        f = 1.0 / self.sf
        per = self.n * (1 - f) / (1 - f ** self.levels)
        self.per_level = [round(per * f ** k) for k in range(self.levels)]
        self.per_level[0] += self.n - sum(self.per_level)

    def extract(self, gray: np.ndarray, cam: CameraModel | None = None, mask: np.ndarray | None = None) -> Features:
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        if gray.dtype != np.uint8:
            gray = cv2.convertScaleAbs(gray)
        h, w = gray.shape
        kps = self.detector.detect(gray, mask)
        if len(kps) < self.n // 2:  # low contrast: a lower FAST threshold
            kps = self.detector_low.detect(gray, mask)
        if not kps:
            return Features.empty(self.sf)
        pts = cv2.KeyPoint_convert(kps)  # type: ignore[attr-defined]
        resp = np.fromiter((k.response for k in kps), np.float32, len(kps))
        octv = np.fromiter((k.octave for k in kps), np.int32, len(kps))
        sel = []
        for lvl in range(self.levels):
            idx = np.flatnonzero(octv == lvl)
            if len(idx) == 0:
                continue
            s = self.sf ** lvl
            keep = _grid_select(pts[idx] / s, resp[idx], self.cell, self.per_level[lvl], int(w / s), int(h / s))
            sel.append(idx[keep])
        chosen = np.concatenate(sel) if sel else np.zeros(0, np.int64)
        kps, desc = self.detector.compute(gray, [kps[i] for i in chosen])
        if desc is None or not kps:
            return Features.empty(self.sf)
        uv = cv2.KeyPoint_convert(kps).astype(np.float32)  # type: ignore[attr-defined]
        octave = np.fromiter((k.octave for k in kps), np.int32, len(kps))
        resp = np.fromiter((k.response for k in kps), np.float32, len(kps))
        und = cam.undistort_points(uv) if cam is not None and cam.has_distortion else uv.astype(np.float64)
        return Features(uv, und, octave, desc, resp, self.sf)


def _grid_select(pts: np.ndarray, resp: np.ndarray, cell: int, n: int, w: int, h: int) -> np.ndarray:
    """Strongest keypoints spread over a grid: round-robin over cells by rank until ``n`` are taken."""
    if len(pts) <= n:
        return np.arange(len(pts))
    cx = (pts[:, 0] // cell).astype(np.int64)
    cy = (pts[:, 1] // cell).astype(np.int64)
    cid = cy * (w // cell + 1) + cx
    order = np.lexsort((-resp, cid))  # by cell, strongest first
    cid_sorted = cid[order]
    first = np.r_[0, np.flatnonzero(np.diff(cid_sorted)) + 1]
    rank = np.arange(len(order)) - np.repeat(first, np.diff(np.r_[first, len(order)]))
    # take rank 0 of every cell, then rank 1, ... ; within one rank prefer strong responses
    key = rank * 1e9 - resp[order] / (resp.max() + 1e-9)
    chosen = order[np.argsort(key, kind="stable")[:n]]
    return chosen


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise Hamming distance between two (n, 32) uint8 descriptor arrays (vectorized over candidate pairs,
    where a brute-force matcher would compare every row with every row)."""
    return POPCOUNT[np.bitwise_xor(a, b)].sum(axis=1, dtype=np.int32)


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
