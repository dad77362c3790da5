"""The images made worse for the camera sweep (benchmarks/camera_quality.py): noise of the stated sigma, blur of
the stated width, and nothing else touched (a viewpoint row is a new rendering, its pixels as rendered)."""

import numpy as np

from benchmarks.camera_quality import made_worse, view_name


def _seq():
    rng = np.random.default_rng(0)
    rgb = [np.clip(rng.normal(128, 40, (60, 80, 3)), 0, 255).astype(np.uint8) for _ in range(2)]
    return {"rgb": rgb, "gray": [im[:, :, 0] for im in rgb], "depth": [np.ones((60, 80), np.float32)] * 2}


def test_noise_and_blur_are_as_stated_and_the_depth_untouched():
    seq = _seq()
    noisy = made_worse(seq, "noise", 8.0, 0)
    diff = noisy["rgb"][0].astype(float) - seq["rgb"][0]
    inside = (seq["rgb"][0] > 40) & (seq["rgb"][0] < 215)  # away from clipping
    assert abs(diff[inside].std() - 8.0) < 0.5
    blurred = made_worse(seq, "blur", 2.0, 0)
    assert blurred["rgb"][0].std() < 0.5 * seq["rgb"][0].std()
    assert noisy["depth"] is seq["depth"] and blurred["depth"] is seq["depth"]
    assert blurred["gray"][0].shape == (60, 80)


def test_viewpoint_rows_are_rendered_again_not_filtered():
    seq = _seq()
    for kind, level in (("distance", 4.0), ("azimuth", 45.0), ("elevation", 65.0), ("as drawn", 0.0)):
        assert made_worse(seq, kind, level, 0) is seq
    assert view_name(3, "distance", 0.5) == "family-3-d0.5"
    assert view_name(3, "azimuth", 45.0) == "family-3-az45-arc20"
    assert view_name(3, "noise", 4.0) == "family-3"
