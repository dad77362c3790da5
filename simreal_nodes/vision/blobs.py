"""Coloured dot detection (the glued markers of thesis §4.5.1): sub-pixel centroids of blobs whose hue
matches a reference colour."""

from __future__ import annotations

import cv2
import numpy as np


def detect_color_blobs(bgr: np.ndarray, rgb_color, hue_tol: float = 14.0, min_sat: float = 0.45,
                       min_val: float = 0.2, min_area: int = 3, max_area: int = 2000) -> np.ndarray:
    """(N, 2) centroids (pixel coordinates) of blobs of the given colour (rgb in 0..1)."""
    if bgr.ndim != 3:
        return np.zeros((0, 2))
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV).astype(np.float32)
    ref = cv2.cvtColor(np.uint8([[[int(255 * rgb_color[2]), int(255 * rgb_color[1]), int(255 * rgb_color[0])]]]),
                       cv2.COLOR_BGR2HSV)[0, 0].astype(np.float32)
    dh = np.abs(hsv[..., 0] - ref[0])
    dh = np.minimum(dh, 180 - dh)
    score = (1 - dh / hue_tol).clip(0, 1) * (hsv[..., 1] / 255.0 >= min_sat) * (hsv[..., 2] / 255.0 >= min_val)
    mask = (score > 0).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    out = []
    ys, xs = np.nonzero(lab)
    labs = lab[ys, xs]
    wts = score[ys, xs] * (hsv[ys, xs, 1] / 255.0)
    sw = np.bincount(labs, weights=wts, minlength=n)
    sx = np.bincount(labs, weights=wts * xs, minlength=n)
    sy = np.bincount(labs, weights=wts * ys, minlength=n)
    for k in range(1, n):
        area = stats[k, cv2.CC_STAT_AREA]
        if min_area <= area <= max_area and sw[k] > 0:
            out.append((sx[k] / sw[k], sy[k] / sw[k]))
    return np.asarray(out, dtype=np.float64).reshape(-1, 2)
