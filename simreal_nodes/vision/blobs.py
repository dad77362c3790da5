"""Coloured dot detection (the glued markers of thesis §4.5.1): sub-pixel centroids of blobs whose hue
matches a reference colour."""

from __future__ import annotations

import math

import cv2
import numpy as np


def detect_color_blobs(bgr: np.ndarray, rgb_color, hue_tol: float = 14.0, min_sat: float = 0.45,
                       min_val: float = 0.2, min_area: int = 3, max_area: int = 2000,
                       within: tuple[float, float, float, float] | None = None) -> np.ndarray:
    """(N, 2) centroids (pixel coordinates) of blobs of the given colour (rgb in 0..1).

    A pixel belongs to a blob when its hue is within ``hue_tol`` (OpenCV hue units, 0..180, circular) of the
    colour's and its saturation and value are at least ``min_sat`` and ``min_val``; a blob's centroid
    weights its pixels by (1 - hue distance / hue_tol) x saturation. The pixel test runs on the whole image
    with ``cv2.inRange``; the weights only on the pixels that pass it.

    ``within`` (x0, y0, x1, y1): only the blobs whose centroid lies in this box are asked for (where a tracker
    predicts its dots), and the same ones are returned as from the whole image (to rounding), read over the box grown by
    :func:`blob_reach` only: a blob of at most ``max_area`` pixels shaped like a disc lies in that window whatever
    its weights. A blob that touches the window's edge inside the image may reach the box from outside it: then
    the whole image is read after all (at the whole image's cost). Not found: a blob wholly outside the window whose
    centroid lies in the box (a ring or a U around the window, farther than the reach from its own centroid:
    nothing a glued dot looks like)."""
    if bgr.ndim != 3:
        return np.zeros((0, 2))
    if within is not None:
        return _blobs_within(bgr, within, dict(rgb_color=rgb_color, hue_tol=hue_tol, min_sat=min_sat,
                                               min_val=min_val, min_area=min_area, max_area=max_area))
    return _blobs(bgr, rgb_color, hue_tol, min_sat, min_val, min_area, max_area)[0]


def blob_reach(max_area: int) -> int:
    """Pixels from a blob's (weighted) centroid within which all of a disc-shaped blob of up to ``max_area`` pixels
    lies: the disc's diameter (the weights may pull the centroid to its rim), and a pixel for rounding."""
    return math.ceil(2.0 * math.sqrt(max_area / math.pi)) + 1


def _blobs_within(bgr: np.ndarray, box: tuple[float, float, float, float], kw: dict) -> np.ndarray:
    h, w = bgr.shape[:2]
    x0, y0, x1, y1 = (float(v) for v in box)
    if not all(math.isfinite(v) for v in (x0, y0, x1, y1)) or x1 < x0 or y1 < y0:
        return np.zeros((0, 2))
    reach = blob_reach(kw["max_area"])
    a0, b0 = max(math.floor(x0) - reach, 0), max(math.floor(y0) - reach, 0)
    a1, b1 = min(math.ceil(x1) + reach + 1, w), min(math.ceil(y1) + reach + 1, h)
    if a1 <= a0 or b1 <= b0:
        return np.zeros((0, 2))
    c, stats = _blobs(bgr[b0:b1, a0:a1], **kw)
    if stats is not None:
        # a blob touching the window's edge where the image goes on may be part of one that reaches the box
        left, top = stats[1:, cv2.CC_STAT_LEFT], stats[1:, cv2.CC_STAT_TOP]
        right, bottom = left + stats[1:, cv2.CC_STAT_WIDTH], top + stats[1:, cv2.CC_STAT_HEIGHT]
        cut = (((left == 0) & (a0 > 0)) | ((top == 0) & (b0 > 0)) | ((right == a1 - a0) & (a1 < w))
               | ((bottom == b1 - b0) & (b1 < h)))
        if cut.any():
            c = _blobs(bgr, **kw)[0]
            a0 = b0 = 0
    c = c + (a0, b0)
    inside = (c[:, 0] >= x0) & (c[:, 0] <= x1) & (c[:, 1] >= y0) & (c[:, 1] <= y1)
    return c[inside]


def _blobs(bgr: np.ndarray, rgb_color, hue_tol: float, min_sat: float, min_val: float, min_area: int,
           max_area: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The centroids of :func:`detect_color_blobs` and the connected components' stats (None: no component)."""
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
        return np.zeros((0, 2)), None
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
    return np.c_[sx[keep] / sw[keep], sy[keep] / sw[keep]].astype(np.float64).reshape(-1, 2), stats


def _hue_ranges(lo: int, hi: int) -> list[tuple[int, int]]:
    """[lo, hi] on OpenCV's circular hue (0..179) as one or two plain ranges."""
    if hi - lo >= 179:
        return [(0, 179)]
    if lo < 0:
        return [(0, hi), (lo + 180, 179)]
    if hi > 179:
        return [(lo, 179), (0, hi - 180)]
    return [(lo, hi)]
