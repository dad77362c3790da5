"""ObjectTrackers, the per-object bookkeeping of the tracker node and the offline pipeline: one tracker per tracked
object, built for a camera with the overrides, updated together, rebuilt when one is missing."""

import numpy as np

from simreal_nodes.assimilation.localizer import make_localizer
from simreal_nodes.assimilation.objects import ObjectTrackers
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene.schema import validate_scene
from simreal_nodes.states import EstimateState
from tests.synthdata import sequence


def test_object_trackers_on_the_aluminium_beam():
    seq = sequence("aluminium_beam", 640, 480)
    scene = validate_scene(seq["scene"].scene_yaml(seq["scene"]), "aluminium_beam", ".")
    o = scene["objects"][0]
    untracked = dict(o, id="other", tracking=dict(o["tracking"], enabled=False))
    models = {o["id"]: load_model(o["model"], fields=["displacement"])}
    trackers = ObjectTrackers(scene["objects"] + [untracked], models, huber_px=3.5)
    assert [x["id"] for x in trackers.objects] == [o["id"]] and trackers.cam is None
    same = trackers.trackers
    trackers.set_camera(seq["cam"])
    assert list(trackers.trackers) == [o["id"]] and trackers.trackers is same
    cfg = trackers.trackers[o["id"]].cfg
    assert cfg.huber_px == 3.5 and cfg.n_modes == o["tracking"]["modes"]  # overridden / the scene's
    T_wc = make_localizer(scene["localization"], seq["cam"]).step(seq["gray"][60], 0).T_wc
    bgr = np.ascontiguousarray(seq["rgb"][60][:, :, ::-1])
    est = trackers.update(T_wc, bgr=bgr)
    assert list(est) == [o["id"]] and est[o["id"]].state == EstimateState.OK
    ids, P, drop = trackers.feedback()  # glued dots: no map point on the object
    assert len(ids) == 0 and P.shape == (0, 3) and len(drop) == 0
    del trackers.trackers[o["id"]]  # (a build that failed on CameraInfo) -> built on the next frame
    again = trackers.update(T_wc, bgr=bgr)[o["id"]]
    assert o["id"] in trackers.trackers and trackers.trackers[o["id"]].cfg.huber_px == 3.5  # with the overrides
    # the rebuilt tracker, fresh on the same frame as the first one was, gives the first one's estimate
    assert again.state == EstimateState.OK
    np.testing.assert_allclose(again.values, est[o["id"]].values, rtol=0, atol=1e-12)
