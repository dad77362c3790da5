"""The images made worse for the camera sweep (benchmarks/camera_quality.py): noise of the stated sigma, blur of
the stated width, and nothing else touched (a viewpoint row is a new rendering, its pixels as rendered)."""

import numpy as np
import pytest

from benchmarks.camera_quality import made_worse, view_name


def _seq():
    rng = np.random.default_rng(0)
    rgb = [np.clip(rng.normal(128, 40, (60, 80, 3)), 0, 255).astype(np.uint8) for _ in range(2)]
    return {"rgb": rgb, "gray": [im[:, :, 0] for im in rgb], "depth": [np.ones((60, 80), np.float32)] * 2}


def _luma(rgb: np.ndarray) -> np.ndarray:
    return rgb.astype(float) @ [0.299, 0.587, 0.114]


def test_noise_and_blur_are_as_stated_and_the_depth_untouched():
    seq = _seq()
    noisy = made_worse(seq, "noise", 8.0, 0)
    diff = noisy["rgb"][0].astype(float) - seq["rgb"][0]
    inside = (seq["rgb"][0] > 40) & (seq["rgb"][0] < 215)  # away from clipping
    assert abs(diff[inside].std() - 8.0) < 0.5
    inner = (slice(8, -8), slice(8, -8))  # away from the border's reflection
    for sigma in (1.0, 2.0, 3.0):
        blurred = made_worse(seq, "blur", sigma, 0)
        # a Gaussian of width sigma leaves white noise 1 / (2 sqrt(pi) sigma) of its std (the kernel's l2 norm)
        ratio = blurred["rgb"][0][inner].astype(float).std() / seq["rgb"][0][inner].astype(float).std()
        assert ratio == pytest.approx(1 / (2 * np.sqrt(np.pi) * sigma), rel=0.08), sigma
        # the grey copies are the worsened colour images' (ITU-R 601 luma), not the originals'
        assert np.abs(blurred["gray"][0] - _luma(blurred["rgb"][0])).max() <= 1.0
    assert np.abs(noisy["gray"][0] - _luma(noisy["rgb"][0])).max() <= 1.0
    assert noisy["depth"] is seq["depth"] and blurred["depth"] is seq["depth"]


def test_viewpoint_rows_are_rendered_again_not_filtered():
    seq = _seq()
    for kind, level in (("distance", 4.0), ("azimuth", 45.0), ("elevation", 65.0), ("as drawn", 0.0)):
        assert made_worse(seq, kind, level, 0) is seq
    assert view_name(3, "distance", 0.5) == "family-3-d0.5"
    assert view_name(3, "azimuth", 45.0) == "family-3-az45-arc20"
    assert view_name(3, "noise", 4.0) == "family-3"
