"""DeformableTracker.screen_region: where the object projects, for the SLAM's object-aware feature budget."""

from __future__ import annotations

import cv2
import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.tracker import DeformableTracker
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.synth.scenes import default_camera


def test_region_holds_the_projected_object_and_vanishes_behind_the_camera():
    model = load_model(cached_model("aluminium_beam"), fields=["displacement"])
    cam = default_camera(640, 480)
    T_map_obj = G.make_T(G.rot_axis("z", 0.2), [0.1, 0.0, 0.0])
    centre = G.transform(T_map_obj, model.points).mean(axis=0)
    # optical frame: x right = map x, y down = map -z, looking along map +y from 1 m in front of the object
    R_wc = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    T_wc = G.make_T(R_wc, centre - [0.0, 1.0, 0.0])
    tr = DeformableTracker(model, T_map_obj, {}, cam)
    poly = tr.screen_region(T_wc)
    assert poly is not None and len(poly) >= 3
    uv = cam.project(G.transform(G.inv(T_wc) @ T_map_obj, model.points))
    inside = [cv2.pointPolygonTest(poly.astype(np.float32), (float(u), float(v)), True) >= -2.0 for u, v in uv]
    assert np.mean(inside) > 0.99  # every node, not only the sampled surface ones, lies in the hull
    assert 500 < cv2.contourArea(poly.astype(np.float32)) < 640 * 480
    behind = T_wc @ G.make_T(G.rot_axis("y", np.pi))  # the camera turned around
    assert tr.screen_region(behind) is None
