"""ORB extraction: the per-cell FAST threshold fall-back, the focus regions' guaranteed share, determinism."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from simreal_nodes.vision.orb import OrbExtractor, ic_angle


def _speckle(rng: np.random.Generator, h: int, w: int, contrast: float) -> np.ndarray:
    """Blurred random dots around mid grey with the given peak-to-peak contrast (grey levels)."""
    dots = (rng.random((h, w)) < 0.02).astype(np.float32)
    tex = cv2.GaussianBlur(dots, (0, 0), 1.5)
    return 128 + contrast * (tex / tex.max() - 0.5)


def faint_beside_strong(seed: int = 0) -> np.ndarray:
    """640 x 480: the left half painted speckle (contrast 200), the right half a faint one (contrast 30) that
    FAST at 20 barely finds, as a low-contrast beam beside a textured background."""
    rng = np.random.default_rng(seed)
    img = np.empty((480, 640), np.float32)
    img[:, :320] = _speckle(rng, 480, 320, 200.0)
    img[:, 320:] = _speckle(rng, 480, 320, 30.0)
    return np.clip(img + rng.normal(0, 0.5, img.shape), 0, 255).astype(np.uint8)


def test_per_cell_fallback_puts_features_on_the_faint_half():
    """A global threshold gives the strong half the whole budget; the per-cell fall-back offers the faint cells'
    corners, and the even selection takes them (the old extractor put almost none there)."""
    img = faint_beside_strong()
    strong_only = cv2.FastFeatureDetector_create(20).detect(img[:, 320:])
    f = OrbExtractor(1000).extract(img)
    on_faint = int((f.uv[:, 0] >= 330).sum())
    assert len(f) >= 900
    assert len(strong_only) < 100  # the faint half has few corners at the usual threshold
    assert on_faint >= 0.3 * len(f), (on_faint, len(f))


def test_focus_region_receives_its_share():
    """A faint patch inside a strong image: without focus it gets few features; as a focus polygon it gets at
    least its share of the budget."""
    rng = np.random.default_rng(1)
    img = _speckle(rng, 480, 640, 200.0)
    img[180:300, 240:400] = _speckle(rng, 120, 160, 12.0)
    img = np.clip(img + rng.normal(0, 0.5, img.shape), 0, 255).astype(np.uint8)
    poly = np.array([[240, 180], [399, 180], [399, 299], [240, 299]], np.float64)
    ex = OrbExtractor(1000)

    def inside(f):
        return int(((f.uv[:, 0] >= 240) & (f.uv[:, 0] < 400) & (f.uv[:, 1] >= 180) & (f.uv[:, 1] < 300)).sum())

    plain = ex.extract(img)
    focused = ex.extract(img, focus=[poly], focus_share=0.2)
    assert inside(focused) >= 0.17 * ex.n, (inside(plain), inside(focused))
    assert inside(focused) > 3 * max(inside(plain), 1)
    assert abs(len(focused) - ex.n) <= 0.05 * ex.n  # the share comes out of the budget, not on top of it


def test_extraction_is_deterministic_and_oriented():
    img = faint_beside_strong(3)
    ex = OrbExtractor(800)
    poly = np.array([[350, 100], [600, 100], [600, 400], [350, 400]], np.float64)
    a, b = ex.extract(img, focus=[poly]), OrbExtractor(800).extract(img.copy(), focus=[poly])
    assert np.array_equal(a.uv, b.uv) and np.array_equal(a.desc, b.desc) and np.array_equal(a.octave, b.octave)
    assert len(np.unique(a.octave)) == ex.levels  # every pyramid level contributes


def test_ic_angle_points_to_the_bright_side():
    """The intensity centroid of a patch bright on its right is at 0 degrees, bright below at 90 (image y down)."""
    img = np.zeros((64, 64), np.uint8)
    img[:, 33:] = 200
    assert abs(ic_angle(img, np.array([[32, 32]]))[0] - 0.0) < 1.0
    assert abs(ic_angle(img.T.copy(), np.array([[32, 32]]))[0] - 90.0) < 1.0


def _grid_select_by_one_key(pts: np.ndarray, resp: np.ndarray, cell: float, n: int) -> np.ndarray:
    """The even selection as one stable sort on a single key per round (cell, then strength), every round ordered:
    the plain statement of what :func:`orb._grid_select` computes in fewer passes."""
    if len(pts) <= n:
        return np.arange(len(pts))
    cx, cy = (pts[:, 0] // cell).astype(np.int64), (pts[:, 1] // cell).astype(np.int64)
    cid = cy * (int(cx.max()) + 1) + cx
    weak = 255 - np.clip(resp, 0, 255).astype(np.int64)
    order = np.argsort(cid * 256 + weak, kind="stable")
    rank = np.empty(len(order), np.int64)
    seen: dict[int, int] = {}
    for j, i in enumerate(order):
        rank[j] = seen.get(int(cid[i]), 0)
        seen[int(cid[i])] = rank[j] + 1
    return order[np.argsort(rank * 256 + weak[order], kind="stable")[:n]]


def test_even_selection_matches_its_plain_statement():
    """The selection's two-pass radix ordering and its cut to the rounds that can fill the budget pick the same
    keypoints in the same order as the plain single-key sort: with ties in strength, one crowded cell, more than
    65 536 cell keys (the 64-bit pass) and a budget that needs every round."""
    from simreal_nodes.vision import orb

    rng = np.random.default_rng(3)
    cases = [(rng.integers(0, 640, (4000, 2)), rng.integers(7, 60, 4000), 38.0, 200),  # many ties
             (rng.integers(0, 60, (500, 2)), rng.integers(7, 255, 500), 30.0, 100),  # four crowded cells
             (rng.integers(0, 90_000, (3000, 2)), rng.integers(7, 80, 3000), 1.0, 2500),  # keys past 16 bits
             (rng.integers(0, 640, (300, 2)), rng.integers(7, 40, 300), 64.0, 299),  # nearly every round
             (rng.integers(0, 640, (50, 2)), rng.integers(7, 40, 50), 64.0, 80),  # fewer than the budget
             (rng.integers(-300, 300, (800, 2)), rng.integers(7, 40, 800), 20.0, 150)]  # cells of both signs
    for pts, resp, cell, n in cases:
        resp = resp.astype(np.float32)
        got = orb._grid_select(pts.astype(np.int64), resp, cell, n)
        want = _grid_select_by_one_key(pts.astype(np.int64), resp, cell, n)
        assert np.array_equal(got, want), (cell, n)
        assert len(got) == min(n, len(pts)) and len(np.unique(got)) == len(got)


@pytest.mark.parametrize("word_count", [True, False], ids=["numpy-2-bitwise-count", "byte-table"])
def test_hamming_counts_the_differing_bits_of_any_layout(monkeypatch, word_count):
    """Descriptors as the matchers hand them over: gathered rows, a strided view, Fortran order, one row against
    many, every pair by broadcasting; each distance is the count of differing bits (against unpacking them one by
    one), with numpy 2's bit count and with the byte table a numpy 1 install falls back on."""
    from simreal_nodes.vision import orb

    monkeypatch.setattr(orb, "_BITWISE_COUNT", word_count and orb._BITWISE_COUNT)
    rng = np.random.default_rng(5)
    a, b = rng.integers(0, 256, (300, 32), np.uint8), rng.integers(0, 256, (300, 32), np.uint8)
    wide = rng.integers(0, 256, (300, 64), np.uint8)
    for x, y in ((a, b), (a[::-1], b[rng.permutation(300)]), (wide[:, ::2], b), (np.asfortranarray(a), b),
                 (a[:1], b), (a[:0], b[:0]), (a[:, :31], b[:, :31])):
        want = np.unpackbits(np.bitwise_xor(x, y), axis=1).sum(axis=1)
        got = orb.hamming(x, y)
        assert got.dtype == np.int32 and np.array_equal(got, want)
    assert orb.hamming(a[:1], a[:1])[0] == 0 and orb.hamming(a[:1], ~a[:1])[0] == 256
    pairs = orb.hamming(a[:7, None, :], b[None, :5, :])
    assert pairs.shape == (7, 5) and pairs[3, 2] == orb.hamming(a[3:4], b[2:3])[0]


def test_levels_too_small_for_a_patch_are_skipped_not_a_crash():
    """A pyramid deeper than the image allows (the scene schema takes up to 16 levels): the levels no 31-pixel patch
    fits in give no keypoints, the others theirs (before stop 99 such a level made OpenCV raise on a negative size)."""
    img = np.random.default_rng(3).integers(0, 256, (240, 320), dtype=np.uint8)
    ex = OrbExtractor(500, n_levels=16)
    f = ex.extract(img)
    top = max(k for k, lv in enumerate(ex.pyramid(img)) if min(lv.shape) > 2 * ex.edge)
    assert len(f) > 100 and f.octave.max() <= top < 15


def test_a_fisheye_camera_keeps_only_keypoints_with_a_ray():
    """On an equidistant (fisheye) camera whose image corners lie past 90 degrees off the axis, the corners'
    keypoints (no ideal pixel: NaN) are left out, and so are those where the lens stretches the ideal image over
    ``MAX_STRETCH`` times (about 72 degrees: an ideal position says too little there); every kept one undistorts
    to where the lens puts its ray, with a finite stretch, and every one well inside is kept."""
    from simreal_nodes.camera import CameraModel
    from simreal_nodes.vision.orb import MAX_STRETCH

    img = np.clip(_speckle(np.random.default_rng(1), 480, 640, 200.0), 0, 255).astype(np.uint8)
    fish = CameraModel(640, 480, [[200.0, 0, 319.5], [0, 200.0, 239.5], [0, 0, 1]], [-0.02, 0.004, -0.001, 0.0],
                       "equidistant")
    ext = OrbExtractor(1000)
    plain, f = ext.extract(img), ext.extract(img, fish)
    r_plain = np.hypot(plain.uv[:, 0] - 319.5, plain.uv[:, 1] - 239.5) / 200.0
    assert (r_plain > 1.52).sum() > 20  # the speckle has keypoints past the lens's 90 degrees
    r = np.hypot(f.uv[:, 0] - 319.5, f.uv[:, 1] - 239.5) / 200.0
    assert len(f) == len(f.und) == len(f.desc) == len(f.octave) == len(f.response) and r.max() < 1.52
    assert np.isfinite(f.und).all() and f.stretch is not None and np.isfinite(f.stretch).all()
    assert f.stretch.min() >= 1.0 and f.stretch.max() <= MAX_STRETCH and r.max() < 1.3
    inside = {tuple(q) for q in plain.uv[r_plain < 1.0].tolist()}
    assert inside <= {tuple(q) for q in f.uv.tolist()}
    rays = np.c_[(f.und - [319.5, 239.5]) / 200.0, np.ones(len(f))]
    np.testing.assert_allclose(fish.project(rays), f.uv, atol=0.01)
