"""The depth made worse for the registration sweep (benchmarks/depth_quality.py): noise that grows with z^2 as
stated, holes in blocks at the stated fraction."""

import numpy as np

from benchmarks.depth_quality import worse


def test_noise_grows_with_the_square_of_the_distance():
    rng = np.random.default_rng(0)
    for z in (0.5, 1.0, 2.0):
        d = np.full((240, 320), z, np.float32)
        sigma = float(np.std(worse(d, "noise", 5.0, rng) - d))
        assert abs(sigma - 5e-3 * z * z) < 0.03 * 5e-3 * z * z


def test_holes_cover_the_fraction_in_blocks_and_leave_the_rest():
    rng = np.random.default_rng(1)
    d = np.full((480, 640), 1.0, np.float32)
    out = worse(d, "holes", 0.25, rng)
    holes = np.isnan(out)
    assert abs(holes.mean() - 0.25) < 0.02
    assert np.all(out[~holes] == 1.0)
    blocks = holes.reshape(60, 8, 80, 8).transpose(0, 2, 1, 3).reshape(60, 80, 64)
    assert np.all(blocks.all(axis=2) | ~blocks.any(axis=2))  # whole 8x8 blocks
    assert np.array_equal(worse(d, "clean", 0.0, rng), d)
