"""Coloured dot detection (the glued markers of thesis §4.5.1): sub-pixel centroids of blobs whose hue
matches a reference colour."""

from __future__ import annotations

import math

import cv2
import numpy as np


def detect_color_blobs(bgr: np.ndarray, rgb_color, hue_tol: float = 14.0, min_sat: float = 0.45,
                       min_val: float = 0.2, min_area: int = 3, max_area: int = 2000) -> np.ndarray:
    """(N, 2) centroids (pixel coordinates) of blobs of the given colour (rgb in 0..1).

    A pixel belongs to a blob when its hue is within ``hue_tol`` (OpenCV hue units, 0..180, circular) of the
    colour's and its saturation and value are at least ``min_sat`` and ``min_val``; a blob's centroid
    weights its pixels by (1 - hue distance / hue_tol) x saturation. The pixel test runs on the whole image
    with ``cv2.inRange``; the weights only on the pixels that pass it."""
    if bgr.ndim != 3:
        return np.zeros((0, 2))
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    bgr_ref = np.array([[[int(255 * rgb_color[2]), int(255 * rgb_color[1]), int(255 * rgb_color[0])]]], dtype=np.uint8)
    ref = cv2.cvtColor(bgr_ref, cv2.COLOR_BGR2HSV)[0, 0].astype(np.int64)
    s_min, v_min = math.ceil(min_sat * 255 - 1e-9), math.ceil(min_val * 255 - 1e-9)
    reach = math.ceil(hue_tol) - 1  # integer hues at a distance < hue_tol
    mask = np.zeros(hsv.shape[:2], np.uint8)
    for lo, hi in _hue_ranges(int(ref[0]) - reach, int(ref[0]) + reach):
        mask |= cv2.inRange(hsv, (lo, s_min, v_min), (hi, 255, 255))
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return np.zeros((0, 2))
    ys, xs = np.nonzero(mask)
    labs = lab[ys, xs]
    px = hsv[ys, xs].astype(np.float64)
    dh = np.abs(px[:, 0] - ref[0])
    dh = np.minimum(dh, 180 - dh)
    wts = (1 - dh / hue_tol).clip(0, 1) * (px[:, 1] / 255.0)
    sw = np.bincount(labs, weights=wts, minlength=n)
    sx = np.bincount(labs, weights=wts * xs, minlength=n)
    sy = np.bincount(labs, weights=wts * ys, minlength=n)
    area = stats[:, cv2.CC_STAT_AREA]
    keep = (area >= min_area) & (area <= max_area) & (sw > 0)
    keep[0] = False  # the background label
    return np.c_[sx[keep] / sw[keep], sy[keep] / sw[keep]].astype(np.float64).reshape(-1, 2)


def _hue_ranges(lo: int, hi: int) -> list[tuple[int, int]]:
    """[lo, hi] on OpenCV's circular hue (0..179) as one or two plain ranges."""
    if hi - lo >= 179:
        return [(0, 179)]
    if lo < 0:
        return [(0, hi), (lo + 180, 179)]
    if hi > 179:
        return [(lo, 179), (0, hi - 180)]
    return [(lo, hi)]
