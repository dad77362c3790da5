"""Sparse stereo depth (features matched along the rows of a rectified pair) and its edge cases."""

import numpy as np

from simreal_nodes.camera import CameraModel
from simreal_nodes.vision.orb import OrbExtractor
from simreal_nodes.vision.stereo import sparse_stereo_depth

CAM = CameraModel.from_intrinsics(320, 240, 300.0, 300.0, 160.0, 120.0)


def _texture(seed: int) -> np.ndarray:
    import cv2

    rng = np.random.default_rng(seed)
    img = cv2.resize(rng.integers(0, 256, (60, 80), dtype=np.uint8), (320, 240), interpolation=cv2.INTER_NEAREST)
    return cv2.GaussianBlur(img, (3, 3), 0)


def test_a_fronto_parallel_plane_reads_its_depth():
    ex = OrbExtractor(500)
    left = _texture(0)
    right = np.roll(left, -12, axis=1)  # disparity 12 px: z = 300 * 0.1 / 12 = 2.5 m
    z = sparse_stereo_depth(ex.extract(left, None), right, ex, CAM, 0.1, max_depth=10.0)
    ok = np.isfinite(z)
    assert ok.mean() > 0.3
    assert abs(np.median(z[ok]) - 2.5) < 0.05


def test_a_right_image_with_nothing_alike_gives_no_depth_and_no_error():
    """Candidates on the same rows exist but none is alike enough: every feature without depth (this raised an
    IndexError in a stereo family scene before)."""
    ex = OrbExtractor(500)
    left = _texture(0)
    f = ex.extract(left, None)
    z = sparse_stereo_depth(f, _texture(1), ex, CAM, 0.1, max_depth=10.0, max_hamming=0)
    assert len(z) == len(f) and np.all(np.isnan(z))
