"""The flow drawn over the video (thesis §6.4.2, Fig. 6.10a): streamlines as tubes coloured by speed, hidden where
the car's reconstructed body is in front of them (occlusion culling).

Per frame: the body's depth from the camera (one depth-only pass of its surface), then the streamlines composited
over the image with that depth as the occluder (:meth:`simreal_nodes.render.gl.Renderer.composite`'s real-depth
test). Geometry is given in the world (map) frame: the caller maps the car frame into it with the capture's
similarity (:func:`car_to_world`).
"""

from __future__ import annotations

import numpy as np

from simreal_nodes.camera import CameraModel
from simreal_nodes.render.gl import Mesh, Renderer
from simreal_nodes.render.overlay import colormap_lut


def car_to_world(points_car: np.ndarray, scale: float, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Invert the capture's similarity ``x_car = scale * R x + t``: car-frame points into the map frame."""
    return ((np.asarray(points_car, float) - translation) @ np.asarray(rotation)) / scale


class FlowOverlay:
    """Streamline tubes over camera images, occluded by the car's body."""

    def __init__(self, cam: CameraModel, body_vertices: np.ndarray, body_triangles: np.ndarray,
                 tube_vertices: np.ndarray, tube_triangles: np.ndarray, tube_colors: np.ndarray,
                 occlusion: bool = True, world_scale: float = 1.0) -> None:
        """``world_scale``: map units per metre (a monocular map's scale: 1 / the capture's ``scale``), so that the
        near and far planes (5 cm, 20 m) hold in the map's units."""
        self.renderer = Renderer(cam, near=0.05 * world_scale, far=20.0 * world_scale)
        self.occlusion = occlusion
        self.layers: list[str] = []
        self.renderer.add(Mesh("aero_body", np.asarray(body_vertices, float), np.asarray(body_triangles),
                               smooth=False))
        self.add_layer("aero_streamlines", tube_vertices, tube_triangles, tube_colors)

    def add_layer(self, name: str, vertices: np.ndarray, triangles: np.ndarray, colors: np.ndarray,
                  visible: bool = True) -> None:
        """Another coloured surface drawn with the streamlines (e.g. a contour plane, ``aero.streamlines.section``),
        in the world frame; ``show`` switches layers on and off."""
        self.renderer.add(Mesh(name, np.asarray(vertices, float), np.asarray(triangles), mode="vertex",
                               colors=np.asarray(colors, float), smooth=True, unlit=True))
        self.layers.append(name)
        if not visible:
            self.renderer.meshes[name].visible = False

    def show(self, *names: str) -> None:
        """Draw only these layers."""
        for n in self.layers:
            self.renderer.meshes[n].visible = n in names

    def draw(self, image_bgr: np.ndarray, T_world_cam: np.ndarray) -> np.ndarray:
        """The image with the streamlines drawn (BGR uint8 in, BGR uint8 out)."""
        depth = None
        if self.occlusion:
            _, depth = self.renderer.render(T_world_cam, names=["aero_body"])  # 0 where no body: no occluder
        names = [n for n in self.layers if self.renderer.meshes[n].visible]
        return self.renderer.composite(T_world_cam, image_bgr, names=names, real_depth=depth, bgr=True)

    def release(self) -> None:
        self.renderer.release()


FLOW_TUBE_RADIUS_M = 0.02  # the streamlines' tubes, metres (a marker's line width is their diameter in map units)


def flow_geometry(parts) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], float,
                                  tuple[np.ndarray, np.ndarray] | None]:
    """A received flow's geometry, checked: ``parts`` are (namespace, points (k, 3), colours (k, 3 or 4), width) of
    its markers (``aero/body``: a triangle list; ``aero/streamlines``: one line each; ``aero/section``, optional: a
    coloured triangle list). Returns (body vertices, three per triangle; lines; their colours; line width; the
    section's (vertices, colours) or None). ValueError naming what is wrong (no body, a triangle list not in threes,
    colours that do not match the points, a width that is not positive, non-finite values)."""
    body, lines, colors, width, sec = None, [], [], None, None
    for ns, P, C, w in parts:
        P = np.asarray(P, float).reshape(-1, 3)
        if not np.all(np.isfinite(P)):
            raise ValueError(f"flow marker '{ns}': non-finite points")
        if ns in ("aero/body", "aero/section") and (len(P) < 3 or len(P) % 3):
            raise ValueError(f"flow {ns[5:]}: {len(P)} points (a triangle list needs a multiple of 3)")
        if ns == "aero/body":
            body = P
        elif ns == "aero/section":
            C = np.asarray(C, float).reshape(len(C), -1) if len(C) else np.zeros((0, 3))
            if len(C) != len(P) or C.shape[1] not in (3, 4) or not np.all(np.isfinite(C)):
                raise ValueError(f"flow section: {len(C)} colours for {len(P)} points")
            sec = (P, np.clip(C[:, :3], 0.0, 1.0))
        elif ns == "aero/streamlines":
            C = np.asarray(C, float).reshape(len(C), -1) if len(C) else np.zeros((0, 3))
            if len(C) != len(P) or C.shape[1] not in (3, 4) or not np.all(np.isfinite(C)):
                raise ValueError(f"flow streamline: {len(C)} colours for {len(P)} points")
            if not (np.isfinite(w) and w > 0):
                raise ValueError(f"flow streamline: width {w} (expected > 0)")
            if len(P) >= 2:
                lines.append(P)
                colors.append(np.clip(C[:, :3], 0.0, 1.0))
                width = float(w)
    if body is None or not lines or width is None:
        raise ValueError("flow without a body or streamlines")
    return body, lines, colors, width, sec


def speed_lut(name: str = "turbo") -> np.ndarray:
    """The colour table for speeds ((256, 3) RGB in [0, 1])."""
    return colormap_lut(name)
