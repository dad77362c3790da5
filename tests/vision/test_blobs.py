"""Coloured dot detection (`vision/blobs.py`): the window around where dots may be associated finds what the whole
image finds there, and reads the whole image when a blob crosses the window's edge."""

import cv2
import numpy as np
import pytest

from simreal_nodes.vision.blobs import blob_reach, detect_color_blobs

BLUE = (0.1, 0.25, 0.95)  # the demo's dot colour (rgb)
BGR = (242, 64, 26)


def _image(seed: int = 0) -> np.ndarray:
    """A grey image with noise, blue dots of several sizes and shades all over it, a green and a red patch."""
    rng = np.random.default_rng(seed)
    img = rng.integers(90, 160, (480, 640, 3)).astype(np.uint8)
    for _ in range(60):
        u, v = rng.uniform(0, 640), rng.uniform(0, 480)
        shade = tuple(int(c * rng.uniform(0.6, 1.0)) for c in BGR)
        cv2.circle(img, (round(u * 16), round(v * 16)), int(rng.uniform(20, 120)), shade, -1, cv2.LINE_AA, shift=4)
    cv2.rectangle(img, (300, 100), (340, 140), (40, 200, 40), -1)
    cv2.rectangle(img, (20, 400), (60, 430), (30, 30, 220), -1)
    return img


def _in_box(c: np.ndarray, box) -> np.ndarray:
    return c[(c[:, 0] >= box[0]) & (c[:, 0] <= box[2]) & (c[:, 1] >= box[1]) & (c[:, 1] <= box[3])]


def test_the_window_finds_what_the_whole_image_finds_in_the_box():
    """Boxes all over an image of dots (some cut by the image's edge): the same blobs as the whole image's in the
    box, to rounding."""
    img = _image()
    full = detect_color_blobs(img, BLUE)
    assert len(full) > 30
    rng = np.random.default_rng(1)
    for _ in range(40):
        x0, y0 = rng.uniform(-50, 600), rng.uniform(-50, 440)
        box = (x0, y0, x0 + rng.uniform(0, 300), y0 + rng.uniform(0, 200))
        got, want = detect_color_blobs(img, BLUE, within=box), _in_box(full, box)
        assert got.shape == want.shape
        # the same blobs (in the order of OpenCV's labels: a window's scan meets them in another order)
        np.testing.assert_allclose(got[np.lexsort(got.T)], want[np.lexsort(want.T)], atol=1e-9)


@pytest.mark.parametrize("side", ["left", "right", "top", "bottom"])
def test_a_blob_crossing_the_window_edge_is_read_from_the_whole_image(side):
    """A long blue stroke (under the area limit) from far outside the window into the box, from each side: its part in
    the window alone would give a centroid in the box; the whole image is read instead (its centroid outside)."""
    r = blob_reach(2000)
    img = np.full((480, 640, 3), 128, np.uint8)
    strokes = {"left": ((100, 240), (440, 240), (380.0, 230.0, 420.0, 250.0)),
               "right": ((540, 240), (200, 240), (220.0, 230.0, 260.0, 250.0)),
               "top": ((320, 20), (320, 400), (310.0, 340.0, 330.0, 380.0)),
               "bottom": ((320, 460), (320, 80), (310.0, 100.0, 330.0, 140.0))}
    p0, p1, box = strokes[side]
    cv2.line(img, p0, p1, BGR, 3)
    full = detect_color_blobs(img, BLUE)
    assert len(full) == 1 and not len(_in_box(full, box))  # the stroke's centroid lies outside the box
    assert 3 * 400 < 2000  # under the area limit
    assert not len(detect_color_blobs(img, BLUE, within=box))
    # what the window alone would have returned: the stroke's part in it, centred in the box
    a0, b0 = max(int(box[0]) - r, 0), max(int(box[1]) - r, 0)
    a1, b1 = min(int(np.ceil(box[2])) + r + 1, 640), min(int(np.ceil(box[3])) + r + 1, 480)
    cut = detect_color_blobs(img[b0:b1, a0:a1], BLUE) + (a0, b0)
    assert len(_in_box(cut, box)) == 1


def test_windows_without_pixels_find_nothing():
    img = _image()
    for box in ((700.0, 10.0, 800.0, 50.0), (10.0, -300.0, 50.0, -200.0), (np.nan, 0.0, 10.0, 10.0),
                (50.0, 50.0, 40.0, 60.0)):
        assert detect_color_blobs(img, BLUE, within=box).shape == (0, 2)
