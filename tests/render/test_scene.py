"""SceneOverlay, the overlay node's core: the compositor built on the camera's intrinsics (and rebuilt when they
change), a frame's parameters or else the latest, depth that does not fit, no pose, RViz markers."""

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.render.scene import SceneOverlay
from tests.modelkit import beam_model

CAM = CameraModel.from_intrinsics(320, 240, 262.0, 260.0, 159.3, 120.6)
VIEW = G.make_T(G.rot_axis("x", np.pi), [0.25, 0.01, 0.8])  # above the beam, looking down
OBJ = {"id": "beam", "anchor": {"pose": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]},
       "overlay": {"field": "displacement", "colormap": "turbo", "modes": 0, "max_error_px": 0.5, "magnify": 1.0,
                   "range": None}}


@pytest.fixture
def overlay():
    so = SceneOverlay([OBJ], {"beam": beam_model()}, colorbar=False)
    yield so
    so.release()


def test_camera_builds_and_rebuilds(overlay):
    assert overlay.comp is None
    assert overlay.set_camera(CAM) and overlay.comp is not None
    first = overlay.comp
    assert not overlay.set_camera(CameraModel.from_intrinsics(320, 240, 262.0, 260.0, 159.3, 120.6))
    assert overlay.set_camera(CameraModel.from_intrinsics(320, 240, 270.0, 270.0, 159.3, 120.6))
    assert overlay.comp is not first
    overlay.modes = 2  # the node's "modes" parameter: a fixed number for every object
    assert overlay.build().objects["beam"].fixed_modes == 2


def test_draw(overlay):
    overlay.set_camera(CAM)
    img = np.full((CAM.height, CAM.width, 3), 90, np.uint8)
    out, states, why = overlay.draw(img, None, {"beam": None})
    assert out is img and states == {} and why == "no camera pose: image passed through without overlay"
    assert overlay.markers() == []  # nothing drawn yet
    rest, states, why = overlay.draw(img, VIEW, {"beam": None})  # no parameters yet: the rest shape
    drawn = (rest != img).any(axis=2).sum()
    assert why == "" and drawn > 500 and states["beam"].modes >= 1  # the beam covers about 1000 px here
    bent, _, _ = overlay.draw(img, VIEW, {"beam": (["s"], [0.5])})
    assert (bent != rest).any(axis=2).sum() > 0.5 * drawn  # coloured by its displacement
    near, _, _ = overlay.draw(img, VIEW, {"beam": (["s"], [0.1])})
    assert (near != bent).any(axis=2).sum() > 0.5 * drawn  # the parameters reach the drawing
    overlay.latest["beam"] = (["s"], [0.5])  # none with this frame: the latest received are drawn
    again, _, _ = overlay.draw(img, VIEW, {"beam": None})
    np.testing.assert_array_equal(again, bent)
    _, _, why = overlay.draw(img, VIEW, {"beam": None}, depth=np.ones((10, 10), np.float32))
    assert why == "depth 10x10 is not registered to the 320x240 image: drawn without occlusion"
    (m,) = overlay.markers()
    assert m.ns == "simreal/beam" and m.id == 0 and len(m.points) == 3 * len(overlay.comp.objects["beam"].triangles)
    with pytest.raises(ValueError, match="320x240"):
        overlay.draw(img[:100], VIEW, {"beam": None})


def test_the_warm_up_draws_on_a_camera_of_its_own_and_hands_its_context_to_the_real_one(monkeypatch):
    """Issue 18 (live, the frames that come while the first one waits are skipped): the warm-up draws the objects
    once on a small camera of its own, with and without depth, then leaves its GL context to the compositor the real
    camera builds; what that one draws is what a compositor without warm-up draws."""
    from simreal_nodes.render import gl

    monkeypatch.setattr(gl, "_SPARE", [])
    cam = CameraModel.from_intrinsics(320, 240, 262.0, 260.0, 159.3, 120.6, D=[-0.2, 0.05, 0.0, 0.0, 0.0])
    img = np.full((cam.height, cam.width, 3), 90, np.uint8)
    depth = np.full((cam.height, cam.width), 0.7, np.float32)
    depth[:, 160:] = 0.9
    out = []
    for warm in (True, False):
        so = SceneOverlay([OBJ], {"beam": beam_model()})
        if warm:
            so.warm_up()
            assert so.comp is None and len(gl._SPARE) == 1  # nothing kept but the context (and its programs)
            ctx = gl._SPARE[0][0]
        so.set_camera(cam)
        assert (so.comp.renderer.ctx is ctx) == warm and not gl._SPARE
        out.append(so.draw(img, VIEW, {"beam": (["s"], [0.4])}, depth)[0])
        so.release()
    assert (out[0] != img).sum() > 1000
    np.testing.assert_array_equal(out[0], out[1])


def test_the_warm_up_view_sees_the_whole_object():
    """The warm-up's camera (three bounding radii away, on the object's +z side) has every point of the object in
    front of it and inside its image: the draw it makes runs the shaders over the object."""
    from simreal_nodes.render.scene import WARM_UP_SIZE, _view_of

    X = beam_model().points
    T_wc, dist = _view_of(np.eye(4), X)
    assert dist > 0
    W, H = WARM_UP_SIZE
    cam = CameraModel.from_intrinsics(W, H, float(W), float(W), W / 2, H / 2)
    P = (np.linalg.inv(T_wc) @ np.c_[X, np.ones(len(X))].T).T[:, :3]
    assert (P[:, 2] > 0).all() and np.isclose(np.linalg.det(T_wc[:3, :3]), 1.0)
    uv = cam.project(P)
    assert (uv >= 0).all() and (uv[:, 0] < W).all() and (uv[:, 1] < H).all()
