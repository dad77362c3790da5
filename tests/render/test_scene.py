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
    assert why == "" and (rest != img).any() and states["beam"].modes >= 0
    bent, _, _ = overlay.draw(img, VIEW, {"beam": (["s"], [0.5])})
    assert (bent != rest).any()
    overlay.latest["beam"] = (["s"], [0.5])  # none with this frame: the latest received are drawn
    again, _, _ = overlay.draw(img, VIEW, {"beam": None})
    np.testing.assert_array_equal(again, bent)
    _, _, why = overlay.draw(img, VIEW, {"beam": None}, depth=np.ones((10, 10), np.float32))
    assert why == "depth 10x10 is not registered to the 320x240 image: drawn without occlusion"
    (m,) = overlay.markers()
    assert m.ns == "simreal/beam" and m.id == 0 and len(m.points) == 3 * len(overlay.comp.objects["beam"].triangles)
    with pytest.raises(ValueError, match="320x240"):
        overlay.draw(img[:100], VIEW, {"beam": None})
