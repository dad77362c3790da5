"""Overlay of the hidden physics on the camera image (thesis §5.2.5), ROS-free.

Per object and frame:

    u_m(x)   = sum_{i<m} c_i(mu) F_i(x)            (surface nodes only, m chosen live, below)
    x_def    = X + k s R_z(alpha) u_m(X)             (k: the scene's drawing magnification; the model state's
                                                      alpha_z and load_scale s, ReducedModel.deformation)
    colour   = colormap(|u| or von Mises(sigma(x, mu)))   with a fixed colour range per object

The number of modes m is the smallest whose truncation error, *as seen in this view*, stays below
``max_error_px``: for every visible surface node the screen-space length of the omitted part,

    e_px(m) = max_j  f k |u_M(X_j) - u_m(X_j)| / Z_j          (f: the larger focal length, Z_j: depth)

so a far or barely loaded object is drawn with fewer modes (model only what the view requires).
The mesh is drawn by :class:`~simreal_nodes.render.gl.Renderer` over the camera image with per-pixel
occlusion against the real depth (fragments farther than the real surface are discarded in the shader).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.camera import IDEAL_MAP_STEP, CameraModel
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.state import ModelState

COLORMAPS = {"turbo": cv2.COLORMAP_TURBO, "viridis": cv2.COLORMAP_VIRIDIS, "jet": cv2.COLORMAP_JET,
             "inferno": cv2.COLORMAP_INFERNO}


def colormap_lut(name: str) -> np.ndarray:
    """(256, 3) RGB in [0, 1] for a named OpenCV colour map."""
    if name not in COLORMAPS:
        raise ValueError(f"unknown colour map '{name}' (known: {', '.join(COLORMAPS)})")
    bgr = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], COLORMAPS[name])[:, 0, :]
    return bgr[:, ::-1].astype(np.float64) / 255.0


def apply_colormap(values: np.ndarray, vmin: float, vmax: float, lut: np.ndarray) -> np.ndarray:
    """Values -> RGB [0, 1]; NaN -> grey."""
    v = np.asarray(values, dtype=np.float64)
    span = vmax - vmin if vmax > vmin else 1.0
    t = np.clip((v - vmin) / span, 0.0, 1.0)
    idx = np.nan_to_num(t * 255.0, nan=0.0).round().astype(np.int64)
    out = lut[idx]
    out[~np.isfinite(v)] = 0.5
    return out


def von_mises(stress: np.ndarray) -> np.ndarray:
    """Von Mises stress of Voigt-ordered Cauchy stress (xx, yy, zz, xy, yz, xz), shape (n, 6)."""
    s = np.asarray(stress, dtype=np.float64)
    xx, yy, zz, xy, yz, xz = (s[:, i] for i in range(6))
    return np.sqrt(0.5 * ((xx - yy) ** 2 + (yy - zz) ** 2 + (zz - xx) ** 2) + 3.0 * (xy ** 2 + yz ** 2 + xz ** 2))


def nice_unit(unit: str, vmax: float) -> tuple[str, float]:
    """A readable unit for the colour bar: m -> mm / um, Pa -> kPa / MPa."""
    if unit == "m":
        return ("mm", 1e3) if vmax >= 1e-4 else ("um", 1e6)
    if unit == "Pa":
        for u, f in (("GPa", 1e-9), ("MPa", 1e-6), ("kPa", 1e-3)):
            if vmax * f >= 1.0:
                return u, f
    return unit, 1.0


def draw_colorbar(img_bgr: np.ndarray, vmin: float, vmax: float, lut: np.ndarray, label: str, unit: str,
                  where: str = "right") -> np.ndarray:
    """Draw a vertical colour bar with five ticks and the label + unit, in place; returns the image."""
    H, W = img_bgr.shape[:2]
    s = max(0.9, H / 540.0)
    bh, bw = int(0.55 * H), max(8, int(14 * s))
    x0 = W - bw - int(70 * s) if where == "right" else int(12 * s)
    y0 = int(0.2 * H)
    grad = lut[np.linspace(255, 0, bh).round().astype(int)][:, None, ::-1] * 255.0
    img_bgr[y0:y0 + bh, x0:x0 + bw] = np.repeat(grad, bw, axis=1).astype(np.uint8)
    cv2.rectangle(img_bgr, (x0 - 1, y0 - 1), (x0 + bw, y0 + bh), (255, 255, 255), 1)
    nu, f = nice_unit(unit, max(abs(vmin), abs(vmax)))
    font, fs, th = cv2.FONT_HERSHEY_SIMPLEX, 0.42 * s, 1
    for k in range(5):
        v = vmin + (vmax - vmin) * k / 4
        y = y0 + bh - round(bh * k / 4)
        cv2.line(img_bgr, (x0 + bw, y), (x0 + bw + 4, y), (255, 255, 255), 1)
        txt = f"{v * f:.3g}"
        cv2.putText(img_bgr, txt, (x0 + bw + 6, y + 4), font, fs, (0, 0, 0), th + 2, cv2.LINE_AA)
        cv2.putText(img_bgr, txt, (x0 + bw + 6, y + 4), font, fs, (255, 255, 255), th, cv2.LINE_AA)
    title = f"{label} [{nu}]"
    (tw, _), _ = cv2.getTextSize(title, font, fs * 1.1, th)
    org = (max(2, min(x0 - int(20 * s), W - tw - 4)), y0 - int(10 * s))
    cv2.putText(img_bgr, title, org, font, fs * 1.1, (0, 0, 0), th + 2, cv2.LINE_AA)
    cv2.putText(img_bgr, title, org, font, fs * 1.1, (255, 255, 255), th, cv2.LINE_AA)
    return img_bgr


@dataclass
class DrawState:
    """What one object's overlay looked like in a frame (for metrics and tests)."""

    modes: int = 0
    error_px: float = 0.0
    visible_nodes: int = 0
    behind_camera: bool = False
    value_range: tuple = (0.0, 0.0)


class ObjectOverlay:
    """One deformable object drawn from its reduced model.

    ``field``: 'displacement' (|u|) or 'von_mises' (needs the model's stress field) or 'none' (plain).
    ``modes``: fixed number of modes, or 0 to choose live per view (``max_error_px``).
    ``value_range``: colour bar range in model units; None = from the model's extreme parameter values.
    """

    def __init__(self, model: ReducedModel, T_world_object: np.ndarray, field: str = "displacement",
                 colormap: str = "turbo", modes: int = 0, max_error_px: float = 0.5, magnify: float = 1.0,
                 value_range=None, tint=(0.8, 0.8, 0.8)):
        if len(model.surface) == 0:
            raise ValueError(f"model '{model.name}' has no surface triangles to draw")
        self.model = model
        self.T = np.asarray(T_world_object, dtype=np.float64)
        self.field_name = field
        self.lut = colormap_lut(colormap)
        self.fixed_modes = int(modes)
        self.max_error_px = float(max_error_px)
        self.magnify = float(magnify)
        self.tint = tint
        tri = np.asarray(model.surface, dtype=np.int64)
        self.nodes, inv = np.unique(tri.ravel(), return_inverse=True)
        self.triangles = inv.reshape(-1, 3)
        self.X = model.points[self.nodes]
        u_field = model.field("displacement")
        self.M = u_field.n_modes
        if self.fixed_modes > self.M:
            raise ValueError(f"overlay asks for {self.fixed_modes} modes; model '{model.name}' has {self.M}")
        self.u_view = model.deformation_view(self.nodes)  # all M modes; each frame evaluates the first m
        self.s_view = model.field("stress").view(self.nodes) if field == "von_mises" else None
        self.unit = "Pa" if field == "von_mises" else u_field.unit or "m"
        self.label = "von Mises" if field == "von_mises" else "|u|"
        self.axis_names = [a.name for a in model.axes]
        self.value_range: tuple[float, float] = tuple(value_range) if value_range is not None else self._model_range()
        self.state = DrawState()

    # -- model side -------------------------------------------------------------------------------------
    def _model_range(self) -> tuple[float, float]:
        """Colour range over the model's parameter grid extremes (stable across frames)."""
        if self.field_name == "none":
            return (0.0, 1.0)
        grids = [np.unique(np.r_[a.values[0], a.values[len(a.values) // 2], a.values[-1]]) for a in self.model.axes]
        mus = np.stack(np.meshgrid(*grids, indexing="ij"), -1).reshape(-1, len(grids))
        vmax = 0.0
        for mu in mus:
            vmax = max(vmax, float(np.nanmax(self.values(ModelState(mu), self.M)[1])))
        return (0.0, vmax if vmax > 0 else 1.0)

    def values(self, state: ModelState, m: int) -> tuple[np.ndarray, np.ndarray]:
        """(deformation u (n, 3), colour values (n,)) of a model state with m modes; stress scales with the
        load like the displacement (the linear models that have a load_scale)."""
        u = self.u_view(state, m)
        if self.s_view is not None:
            s = self.s_view.evaluate(state.mu, min(m, self.s_view.n_modes))
            val = abs(state.load_scale) * von_mises(s)
        elif self.field_name == "displacement":
            val = np.linalg.norm(u, axis=1)
        else:
            val = np.zeros(len(u))
        return u, val

    def values_sum(self, states: list[ModelState], m: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`values` of several contacts at once (a linear model): their deformations and stresses add, and
        the von Mises stress is that of the summed stress."""
        u = np.sum([self.u_view(s, m) for s in states], axis=0)
        if self.s_view is not None:
            sv = self.s_view
            val = von_mises(np.sum([s.load_scale * sv.evaluate(s.mu, min(m, sv.n_modes)) for s in states], axis=0))
        elif self.field_name == "displacement":
            val = np.linalg.norm(u, axis=1)
        else:
            val = np.zeros(len(u))
        return u, val

    def choose_modes(self, state: ModelState, T_cam_obj: np.ndarray, cam: CameraModel) -> tuple[int, float]:
        """Smallest m whose on-screen truncation error over visible nodes is <= max_error_px."""
        if self.fixed_modes:
            return self.fixed_modes, float("nan")
        c = self.u_view.coefficients(state.mu)
        Xc = G.transform(T_cam_obj, self.X)
        vis = Xc[:, 2] > 1e-3
        if not np.any(vis):
            return 1, 0.0
        # px per metre at each visible node
        scale = abs(state.load_scale) * self.magnify * max(cam.fx, cam.fy) / Xc[vis, 2]
        S_u = self.u_view.modes  # (M, n, 3)
        S = S_u if vis.all() else S_u[:, vis]
        contrib = c[1:, None, None] * S[1:]  # (M - 1, n_vis, 3): modes 2..M
        tail = np.cumsum(contrib[::-1], axis=0)[::-1]  # tail[m - 1] = sum_{i>=m} (omitted when using m modes)
        err2 = np.einsum("mni,mni->mn", tail, tail) * (scale * scale)[None, :]
        err_m = np.r_[np.sqrt(err2.max(axis=1)), 0.0]  # error with m = 1..M modes
        ok = np.nonzero(err_m <= self.max_error_px)[0]
        m = int(ok[0]) + 1 if len(ok) else self.M
        return m, float(err_m[m - 1])

    def geometry(self, names, values, T_world_cam: np.ndarray, cam: CameraModel):
        """Deformed vertices (object frame), RGB colours and the draw state for this frame."""
        states = ModelState.from_named_contacts(self.model.axes, names, values)
        T_cam_obj = np.linalg.inv(T_world_cam) @ self.T
        st = DrawState()
        Xc = G.transform(T_cam_obj, self.X)
        st.visible_nodes = int(np.count_nonzero(Xc[:, 2] > 1e-3))
        st.behind_camera = st.visible_nodes == 0
        chosen = [self.choose_modes(s, T_cam_obj, cam) for s in states]
        m, err = max(c[0] for c in chosen), float(np.sum([c[1] for c in chosen]))
        u, val = self.values(states[0], m) if len(states) == 1 else self.values_sum(states, m)
        V = self.X + self.magnify * u
        if self.field_name == "none":
            col = np.tile(np.asarray(self.tint, dtype=np.float64), (len(V), 1))
        else:
            col = apply_colormap(val, *self.value_range, self.lut)
        st.modes, st.error_px = m, err
        st.value_range = (float(np.nanmin(val)) if len(val) else 0.0, float(np.nanmax(val)) if len(val) else 0.0)
        self.state = st
        return V, col, st


class OverlayCompositor:
    """Draws objects over camera images: one Renderer, one mesh per object, occlusion, colour bar."""

    def __init__(self, cam: CameraModel, objects: dict[str, ObjectOverlay], occlusion: bool = True,
                 colorbar: bool = True, occlusion_margin: float = 0.005, ssaa: int = 1):
        from simreal_nodes.render.gl import Mesh, Renderer

        self.cam = cam
        self.objects = objects
        self.occlusion = occlusion
        self.colorbar = colorbar
        self.margin = occlusion_margin
        self.renderer = Renderer(cam, near=0.02, far=50.0, ssaa=ssaa, ambient=0.6, map_step=IDEAL_MAP_STEP)
        try:
            for oid, ob in objects.items():
                # a closed surface (the boundary of a solid model) is drawn without its back faces: half the
                # fragments, the same picture from outside (from inside it, nothing is drawn)
                outward = G.outward_triangles(ob.X, ob.triangles)
                self.renderer.add(Mesh(oid, ob.X.copy(), ob.triangles if outward is None else outward,
                                       mode="vertex", colors=np.tile([0.7, 0.7, 0.7], (len(ob.X), 1)), pose=ob.T,
                                       cull_back=outward is not None))
        except Exception:
            self.renderer.release(keep=True)  # its context to the next compositor, not lost with this one
            raise
        self.last: dict[str, tuple] = {}

    def compose(self, image_bgr: np.ndarray, T_world_cam: np.ndarray, estimates: dict[str, tuple],
                real_depth: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, DrawState]]:
        """``estimates``: object id -> (names, values). Objects without an estimate are drawn undeformed.
        ``real_depth``: metres (0/NaN invalid), registered to the image. Returns (BGR image, states)."""
        if image_bgr.shape[:2] != (self.cam.height, self.cam.width):
            raise ValueError(f"image is {image_bgr.shape[1]}x{image_bgr.shape[0]}, the overlay camera "
                             f"{self.cam.width}x{self.cam.height}")
        states = {}
        for oid, ob in self.objects.items():
            names, values = estimates.get(oid, ([], []))
            V, col, st = ob.geometry(names, values, T_world_cam, self.cam)
            self.renderer.update(oid, vertices=V, colors=col)
            self.last[oid] = (V, col)
            states[oid] = st
        depth = real_depth if (self.occlusion and real_depth is not None) else None
        out = self.renderer.composite(T_world_cam, image_bgr, real_depth=depth, occlusion_margin=self.margin, bgr=True)
        if self.colorbar:
            for oid, ob in self.objects.items():
                if ob.field_name != "none":
                    draw_colorbar(out, *ob.value_range, ob.lut, f"{oid} {ob.label}", ob.unit)
                    break  # one bar: the first coloured object (scenes colour one object)
        return out, states

    def release(self, keep: bool = False) -> None:
        """Free the GL objects; ``keep``: the context goes to the next renderer (``Renderer.release``)."""
        self.renderer.release(keep)
