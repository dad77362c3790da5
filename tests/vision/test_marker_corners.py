"""Corner refinement of fiducial markers under blur: lines fitted to the sides against OpenCV's corner search."""

import cv2
import numpy as np
import pytest

from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import SimrealError
from simreal_nodes.vision.markers import MarkerLocalizer, refine_by_edges


def drawn_marker(corners: np.ndarray, blur_px: float, size=(320, 240), ss: int = 8) -> np.ndarray:
    """A DICT_4X4_50 marker (id 3) with a white quiet zone of one cell, on a mid-grey ground, warped so that its outer
    corners land on ``corners`` (pixel centres at integers), drawn at ``ss`` x supersampling and averaged down (the
    pixel's area), then blurred by a Gaussian of ``blur_px``."""
    cells, px = 6, 40
    tag = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 3, cells * px)
    tag = cv2.copyMakeBorder(tag, px, px, px, px, cv2.BORDER_CONSTANT, value=255)
    src = np.array([[px, px], [px + cells * px, px], [px + cells * px, px + cells * px], [px, px + cells * px]],
                   dtype=np.float32) - 0.5  # the tag's outer corners (pixel edges) in its own image
    # a big image's pixel (i, j) covers [j*ss - 0.5, ...]: its centre j maps to ss*j + (ss - 1)/2
    dst = (corners.astype(np.float64) * ss + (ss - 1) / 2.0).astype(np.float32)
    H = cv2.getPerspectiveTransform(src, dst)
    w, h = size
    big = cv2.warpPerspective(tag, H, (w * ss, h * ss), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=128)
    img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)
    return cv2.GaussianBlur(img, (0, 0), blur_px) if blur_px > 0 else img


CORNERS = np.array([[101.3, 72.6], [170.8, 80.2], [163.4, 151.7], [95.1, 140.9]])


def localizer(refinement: str = "edges") -> MarkerLocalizer:
    cam = CameraModel.from_intrinsics(320, 240, 300.0, 300.0, 160.0, 120.0)
    return MarkerLocalizer(cam, "DICT_4X4_50", 0.06, {3: np.eye(4)}, corner_refinement=refinement)


@pytest.mark.parametrize("blur_px", [0.0, 1.0, 2.0])
def test_edges_find_the_corners_that_blur_pulls_inward(blur_px):
    """A marker about 70 px wide, tilted and foreshortened: OpenCV's sub-pixel corners move inward as the blur grows
    (0.6 px at 2 px); the sides' lines keep every corner within 0.06 px of the truth."""
    img = drawn_marker(CORNERS, blur_px)
    subpix = localizer("subpix").detect(img)[3]
    edges = localizer("edges").detect(img)[3]
    err_edges = np.linalg.norm(edges - CORNERS, axis=1)
    err_subpix = np.linalg.norm(subpix - CORNERS, axis=1)
    assert err_edges.max() < 0.06, (err_edges, err_subpix)
    if blur_px >= 2.0:
        assert err_subpix.mean() > 0.4 and err_subpix.mean() > 4 * err_edges.mean(), (err_edges, err_subpix)
    # from OpenCV's sub-pixel corners the lines land on the same corners
    np.testing.assert_allclose(refine_by_edges(img, subpix, 6), edges, atol=0.03)


def test_edges_give_way_where_there_is_no_edge_to_fit():
    """A side too short to hold the search, or a flat image, leaves OpenCV's corners (None)."""
    img = drawn_marker(CORNERS, 1.0)
    assert refine_by_edges(img, CORNERS * 0.1, 6) is None
    assert refine_by_edges(np.full_like(img, 128), CORNERS, 6) is None
    with pytest.raises(SimrealError, match="corner refinement"):
        MarkerLocalizer(localizer().cam, "DICT_4X4_50", 0.06, {3: np.eye(4)}, corner_refinement="contour")


@pytest.mark.parametrize("blur_px", [0.0, 1.0])
def test_corners_found_on_the_half_size_image_land_on_the_full_one(blur_px):
    """The half-size image's corners, mapped to the full image (a reduced pixel's centre i is 2 i + 1/2) and searched
    there by OpenCV's sub-pixel rule, lie within 0.4 px of the truth, their centre within 0.1 px (the contour's own
    corners, unsearched, are up to 1.5 px off)."""
    img = drawn_marker(CORNERS, blur_px)
    c = localizer()._from_reduced(img)[3]
    assert np.linalg.norm(c - CORNERS, axis=1).max() < 0.4
    assert np.linalg.norm(c.mean(axis=0) - CORNERS.mean(axis=0)) < 0.1
    with pytest.raises(SimrealError, match="grey image"):
        localizer().detect(np.dstack([img] * 3))
