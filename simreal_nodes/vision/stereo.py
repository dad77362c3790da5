"""Stereo depth: sparse (ORB features matched along rectified rows, for SLAM) and dense (SGBM, for
collision and occlusion; thesis §5.2.3: Z = f T / d)."""

from __future__ import annotations

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel
from simreal_nodes.vision.orb import hamming


def baseline_from_projection(P_right) -> float:
    """Stereo baseline (metres) from the right camera's projection matrix: P[0, 3] = -fx * b."""
    P = np.asarray(P_right, dtype=np.float64).reshape(3, 4)
    if P[0, 0] <= 0 or P[0, 3] >= 0:
        raise ValueError(f"right CameraInfo P does not describe a rectified right camera (P[0,3] = {P[0, 3]:g}, "
                         "expected -fx * baseline < 0)")
    return -P[0, 3] / P[0, 0]


def sparse_stereo_depth(f, right: np.ndarray, extractor, cam: CameraModel, baseline: float, max_depth: float,
                        min_depth: float = 0.2, max_hamming: int = 60) -> np.ndarray:
    """Depth of left features by matching right-image ORB features on the same row of a rectified pair
    (row band of 2 pixels x the pyramid scale, disparity within the depth range, same-ish octave,
    best Hamming distance), vectorized over all candidate pairs."""
    z = np.full(len(f), np.nan)
    if len(f) == 0:
        return z
    fr = extractor.extract(right, None)
    if len(fr) == 0:
        return z
    dmax = cam.fx * baseline / min_depth
    order = np.argsort(fr.uv[:, 1])
    rv = fr.uv[order, 1]
    tol = 2.0 * f.scale_factor ** f.octave
    lo = np.searchsorted(rv, f.uv[:, 1] - tol)
    hi = np.searchsorted(rv, f.uv[:, 1] + tol)
    n = hi - lo
    if n.sum() == 0:
        return z
    left = np.repeat(np.arange(len(f)), n)
    start = np.repeat(lo, n)
    offs = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    cand = order[start + offs]
    disp = f.uv[left, 0] - fr.uv[cand, 0]
    ok = (disp >= 0.5) & (disp < dmax) & (np.abs(fr.octave[cand] - f.octave[left]) <= 1)
    left, cand, disp = left[ok], cand[ok], disp[ok]
    if len(left) == 0:
        return z
    d = hamming(f.desc[left], fr.desc[cand])
    good = d <= max_hamming
    left, disp, d = left[good], disp[good], d[good]
    if len(left) == 0:  # candidates on the rows, none alike enough (a blank or unrelated right image)
        return z
    srt = np.lexsort((d, left))
    left, disp = left[srt], disp[srt]
    first = np.r_[True, left[1:] != left[:-1]]
    zz = cam.fx * baseline / disp[first]
    keep = zz <= max_depth
    z[left[first][keep]] = zz[keep]
    return z


def sgbm_disparity(left: np.ndarray, right: np.ndarray, num_disparities: int = 128, block: int = 5,
                   full_width: bool = False) -> np.ndarray:
    """Dense disparity (pixels, float32; NaN invalid) of a rectified pair with OpenCV's semi-global matching.

    OpenCV leaves the leftmost ``num_disparities`` columns without a disparity. ``full_width``: both images are
    padded on the left by that many columns first, so that a pixel there gets the disparities whose match lies
    inside the right image (those up to its column; larger ones are invalid)."""
    if left.ndim == 3:
        left = cv2.cvtColor(left, cv2.COLOR_BGR2GRAY)
    if right.ndim == 3:
        right = cv2.cvtColor(right, cv2.COLOR_BGR2GRAY)
    nd = int(np.ceil(num_disparities / 16) * 16)
    if full_width:
        pad = [cv2.copyMakeBorder(im, 0, 0, nd, 0, cv2.BORDER_CONSTANT, value=0) for im in (left, right)]
        d = sgbm_disparity(pad[0], pad[1], nd, block)[:, nd:]
        d[d > np.arange(d.shape[1], dtype=np.float32)] = np.nan  # matched into the padding
        return d
    # opencv's stubs list only cv2.StereoSGBM.create; StereoSGBM_create is its run-time alias
    sgbm = cv2.StereoSGBM_create(  # type: ignore[attr-defined]
        minDisparity=0, numDisparities=nd, blockSize=block, P1=8 * block * block,
                                 P2=32 * block * block, disp12MaxDiff=1, uniquenessRatio=10, speckleWindowSize=100,
                                 speckleRange=2, preFilterCap=31, mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    d = sgbm.compute(left, right).astype(np.float32) / 16.0
    d[d <= 0] = np.nan
    return d


def disparity_to_depth(disp: np.ndarray, fx: float, baseline: float) -> np.ndarray:
    """Z = f T / d (thesis §5.2.3); NaN where the disparity is invalid."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = fx * baseline / disp
    z[~np.isfinite(z) | (z <= 0)] = np.nan
    return z.astype(np.float32)


def disparities_for(fx: float, baseline: float, min_depth: float) -> int:
    """SGBM's disparity range (a multiple of 16) that reaches down to ``min_depth`` metres: d = f T / Z. Its cost
    grows with the range, so the range is no wider than the scene needs."""
    if not (fx > 0 and baseline > 0 and min_depth > 0):
        raise ValueError(f"stereo depth needs fx, baseline and min_depth > 0 (got {fx:g}, {baseline:g}, {min_depth:g})")
    return int(np.clip(np.ceil(fx * baseline / min_depth / 16), 1, 32)) * 16


def stereo_depth(left: np.ndarray, right: np.ndarray, fx: float, baseline: float, min_depth: float) -> np.ndarray:
    """Dense depth (metres, float32, NaN invalid) of a rectified pair: SGBM over the disparities that reach
    ``min_depth`` (:func:`disparities_for`) over the full image width, then Z = f T / d. What a depth image is to
    the trackers' registration and reference view when the camera is a stereo pair."""
    if left.shape[:2] != right.shape[:2]:
        raise ValueError(f"stereo pair of different sizes: left {left.shape[:2]}, right {right.shape[:2]}")
    d = sgbm_disparity(left, right, disparities_for(fx, baseline, min_depth), full_width=True)
    return disparity_to_depth(d, fx, baseline)
