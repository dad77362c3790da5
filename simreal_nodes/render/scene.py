"""The overlay of a scene's objects on one camera, as the overlay node keeps it (thesis §5.2.5): the compositor built
for the camera's intrinsics, the latest parameters of every object, and one frame: image + camera pose (+ depth)
-> the image with the deformed objects painted on it."""

from __future__ import annotations

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.io.cdr import TriangleListMarker
from simreal_nodes.render.overlay import DrawState, ObjectOverlay, OverlayCompositor
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.model_file import load_model

Parameters = tuple[list[str], list[float]]  # (names, values) of one object's model parameters
WARM_UP_SIZE = (160, 120)  # the warm-up's camera (SceneOverlay.warm_up): the draw states, not the size, matter


def _view_of(T_world_object: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, float]:
    """(T_world_camera, distance): a camera three bounding radii from the centre of the points ``X`` (object frame),
    kept between 0.1 and 40 m (inside the overlay's near and far planes), on the object's +z side, looking at it along
    -z (its x axis along the object's, its y axis opposite)."""
    c = T_world_object[:3, :3] @ X.mean(axis=0) + T_world_object[:3, 3]
    r = float(np.linalg.norm(X - X.mean(axis=0), axis=1).max())
    dist = float(np.clip(3.0 * r, 0.1, 40.0))
    x, y = T_world_object[:3, 0], -T_world_object[:3, 1]
    T = np.eye(4)
    T[:3, :3] = np.c_[x, y, np.cross(x, y)]  # optical z = x cross y = the object's -z
    T[:3, 3] = c + dist * T_world_object[:3, 2]
    return T, dist


def overlay_models(objects: list[dict]) -> dict[str, ReducedModel]:
    """The reduced models of a scene's objects with the fields their overlay draws (the stress for von Mises)."""
    models = {}
    for o in objects:
        fields = ["displacement"] + (["stress"] if o["overlay"]["field"] == "von_mises" else [])
        models[o["id"]] = load_model(o["model"], fields=fields)
    return models


class SceneOverlay:
    """``objects``: validated scene objects, ``models`` their reduced models by id; ``modes``: a fixed number of
    modes for every object (-1 = each object's scene setting, 0 = chosen live); ``occlusion``, ``colorbar``,
    ``ssaa``: as :class:`OverlayCompositor` takes them."""

    def __init__(self, objects: list[dict], models: dict[str, ReducedModel], modes: int = -1, occlusion: bool = True,
                 colorbar: bool = True, ssaa: int = 1):
        self.objects, self.models, self.modes = objects, models, modes
        self.occlusion, self.colorbar, self.ssaa = occlusion, colorbar, ssaa
        self.cam: CameraModel | None = None
        self.comp: OverlayCompositor | None = None
        self.latest: dict[str, Parameters] = {}  # object id -> the newest parameters received

    def set_camera(self, cam: CameraModel) -> bool:
        """Intrinsics from a CameraInfo; True when they are new and the compositor was rebuilt (now, not on the first
        frame: that frame would wait for it)."""
        if cam.same_as(self.cam):
            return False
        if self.comp is not None:
            self.comp.release()
        self.cam, self.comp = cam, None  # (None first: a failing build leaves no stale compositor)
        self.build()
        return True

    def build(self) -> OverlayCompositor:
        """(Re)build the compositor for the current camera."""
        assert self.cam is not None  # built once a camera is set (set_camera; the node checks it first)
        self.comp = self._compositor(self.cam)
        return self.comp

    def warm_up(self) -> None:
        """Draw every object on a small camera of its own (with lens distortion), without and then with a depth image,
        and hand the renderer's context and programs on to the compositor of the real camera
        (``Renderer.release(keep=True)``): the GL driver compiles its shaders for these draws and OpenCV loads the
        colour bar's font now, not while the first camera frame waits. The overlay node calls it at start-up; live,
        the frames that come while the first waits are replaced in the one-deep queues (on llvmpipe the first draw
        took about 40 ms more than the next, 25 of them the font's loading; scratch measure, stop 99)."""
        W, H, f = WARM_UP_SIZE[0], WARM_UP_SIZE[1], float(WARM_UP_SIZE[0])
        cam = CameraModel(W, H, np.array([[f, 0.0, W / 2], [0.0, f, H / 2], [0.0, 0.0, 1.0]]),
                          np.array([-0.1, 0.01, 0.0, 0.0, 0.0]), "plumb_bob")
        comp = self._compositor(cam)  # (a failing build hands its context on itself)
        try:
            for ob in comp.objects.values():
                T_wc, dist = _view_of(ob.T, ob.X)
                img = np.zeros((H, W, 3), dtype=np.uint8)
                comp.compose(img, T_wc, {})
                comp.compose(img, T_wc, {}, np.full((H, W), dist, dtype=np.float32))
        finally:
            comp.release(keep=True)

    def _compositor(self, cam: CameraModel) -> OverlayCompositor:
        obs = {}
        for o in self.objects:
            ov = o["overlay"]
            modes = ov["modes"] if self.modes < 0 else self.modes
            obs[o["id"]] = ObjectOverlay(self.models[o["id"]], G.pose7_to_matrix(o["anchor"]["pose"]), ov["field"],
                                         ov["colormap"], modes, ov["max_error_px"], ov["magnify"], ov["range"])
        return OverlayCompositor(cam, obs, occlusion=self.occlusion, colorbar=self.colorbar, ssaa=self.ssaa)

    def draw(self, bgr: np.ndarray, T_wc: np.ndarray | None, params: dict[str, Parameters | None],
             depth: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, DrawState], str]:
        """(painted image, draw state per object, what was wrong or '') of one frame. ``params``: object id ->
        the parameters of this frame, or None (then the latest received are drawn); ``depth`` in metres, for
        occlusion (one not registered to the image is left out, with a note). ``T_wc`` None: the image passes
        through. ValueError / SimrealError when the image does not fit the camera."""
        if T_wc is None:
            return bgr, {}, "no camera pose: image passed through without overlay"
        est = {oid: p if p is not None else self.latest.get(oid, ([], [])) for oid, p in params.items()}
        notes = []
        if depth is not None and depth.shape != bgr.shape[:2]:
            notes.append(f"depth {depth.shape[1]}x{depth.shape[0]} is not registered to the "
                         f"{bgr.shape[1]}x{bgr.shape[0]} image: drawn without occlusion")
            depth = None
        assert self.comp is not None  # the camera is set (set_camera built the compositor)
        out, states = self.comp.compose(bgr, T_wc, est, depth)
        notes += [f"{k}: behind the camera" for k, s in states.items() if s.behind_camera]
        return out, states, "; ".join(notes)

    def markers(self) -> list[TriangleListMarker]:
        """The deformed surfaces of the last frame drawn, as RViz TRIANGLE_LIST markers with vertex colours."""
        arr = []
        assert self.comp is not None  # asked after frames were drawn, hence with a compositor
        for k, (oid, ob) in enumerate(self.comp.objects.items()):
            V, col = self.comp.last.get(oid, (None, None))
            if V is None:
                continue
            idx = ob.triangles.ravel()
            arr.append(TriangleListMarker(f"simreal/{oid}", k, ob.T, V[idx], col[idx]))
        return arr

    def release(self) -> None:
        if self.comp is not None:
            self.comp.release()
