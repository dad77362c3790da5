"""Streamlines over the video, hidden behind the car's body (thesis §6.4.2)."""

from __future__ import annotations

import numpy as np
import pytest

from simreal_nodes.aero.streamlines import tubes
from simreal_nodes.camera import CameraModel
from simreal_nodes.geometry import look_at
from simreal_nodes.render.aero import FlowOverlay, car_to_world


def box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    v = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return v, np.array([t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])


def test_a_streamline_behind_the_body_is_hidden_and_one_in_front_is_drawn() -> None:
    cam = CameraModel.from_intrinsics(320, 240, 250, 250, 160, 120)
    T_wc = look_at([0.0, -5.0, 0.5], [0.0, 0.0, 0.5])  # looking along +y
    body = box([-1.0, -0.5, 0.0], [1.0, 0.5, 1.0])
    x = np.linspace(-3.0, 3.0, 60)
    behind = np.column_stack([x, np.full(60, 1.5), np.full(60, 0.5), np.full(60, 10.0)])
    front = np.column_stack([x, np.full(60, -1.5), np.full(60, 0.8), np.full(60, 10.0)])
    img = np.zeros((240, 320, 3), np.uint8)
    for line, visible_at_centre in ((behind, False), (front, True)):
        V, T, C = tubes([line], radius=0.05, lut=np.ones((256, 3)))
        ov = FlowOverlay(cam, *body, V, T, C)
        out = ov.draw(img, T_wc)
        plain = FlowOverlay(cam, *body, V, T, C, occlusion=False)
        free = plain.draw(img, T_wc)
        plain.release()
        ov.release()
        row = np.flatnonzero(free[:, 160].max(axis=1) > 100)
        assert len(row) > 0  # without occlusion the line crosses the image's middle column
        assert (out[row, 160].max() > 100) == visible_at_centre
        assert out[row, 60].max() > 100  # beside the body the line is drawn either way


def test_car_to_world_inverts_the_capture_similarity() -> None:
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R = q * np.sign(np.linalg.det(q))
    x = rng.normal(size=(10, 3))
    car = 2.5 * x @ R.T + np.array([1.0, -2.0, 0.5])
    assert np.allclose(car_to_world(car, 2.5, R, np.array([1.0, -2.0, 0.5])), x)


def test_a_received_flow_is_checked_before_it_is_drawn() -> None:
    from simreal_nodes.render.aero import flow_geometry

    tri = np.zeros((3, 3))
    line = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    red = np.tile([1.0, 0, 0, 1], (3, 1))
    body, lines, colors, width, sec = flow_geometry([("aero/body", tri, [], 1.0),
                                                     ("aero/streamlines", line, red, 0.04)])
    assert body.shape == (3, 3) and len(lines) == 1 and colors[0].shape == (3, 3) and width == 0.04 and sec is None
    *_, sec = flow_geometry([("aero/body", tri, [], 1.0), ("aero/streamlines", line, red, 0.04),
                             ("aero/section", tri, red, 1.0)])
    assert sec is not None and sec[0].shape == (3, 3) and sec[1].shape == (3, 3)
    bad = [
        ([("aero/streamlines", line, red, 0.04)], "without a body"),
        ([("aero/body", tri[:2], [], 1.0), ("aero/streamlines", line, red, 0.04)], "multiple of 3"),
        ([("aero/body", tri, [], 1.0), ("aero/streamlines", line, red[:1], 0.04)], "1 colours for 3 points"),
        ([("aero/body", tri, [], 1.0), ("aero/streamlines", line, [], 0.04)], "0 colours for 3 points"),
        ([("aero/body", tri, [], 1.0), ("aero/streamlines", line, red, 0.0)], "width"),
        ([("aero/body", tri + np.nan, [], 1.0), ("aero/streamlines", line, red, 0.04)], "non-finite"),
        ([("aero/body", tri, [], 1.0), ("aero/streamlines", line, red, 0.04), ("aero/section", tri, [], 1.0)],
         "section: 0 colours"),
    ]
    for parts, match in bad:
        with pytest.raises(ValueError, match=match):
            flow_geometry(parts)
