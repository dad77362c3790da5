"""The online side of the car aerodynamics (thesis §6.4): a SLAM cloud in, the car's flow in the map frame out.

:class:`AeroEstimator` holds the offline database (never runs CFD) and its shape manifold. Per capture:
Alg. 6.1 on the cloud (:func:`~simreal_nodes.aero.capture.capture_car`, the nose chosen as the end whose shape lies
nearer the database's cars) -> the presence vector placed among its M nearest database cars (LLE weights) -> Eq. 6.4
(the velocity as the weighted sum of theirs, zero inside the captured body) -> streamlines from a rake upstream
(RK4, :func:`~simreal_nodes.aero.streamlines.trace`) -> everything mapped back into the map frame with the
capture's similarity. Plain numpy in and out; the ``aero`` node publishes :class:`FlowResult` as RViz markers and the
overlay node draws them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from simreal_nodes.aero.capture import CaptureSettings, capture_car
from simreal_nodes.aero.database import AeroDatabase
from simreal_nodes.aero.manifold import ShapeManifold
from simreal_nodes.aero.streamlines import FlowField, section, seed_rake, trace
from simreal_nodes.render.aero import FLOW_TUBE_RADIUS_M, car_to_world, speed_lut

SECTIONS = ("none", "pressure", "velocity")  # the contour planes on offer (scene key aero.section)
SPEED_SCALE = 1.4  # speeds are coloured from 0 to this x the inflow (streamlines and the velocity section)


@dataclass
class FlowResult:
    """One capture's flow, in the map frame (map units: metres for a metric map)."""

    lines: list[np.ndarray]  # streamlines, each (k, 3) points
    speeds: list[np.ndarray]  # each (k,) m/s
    body_vertices: np.ndarray  # the captured body (alpha shape)
    body_triangles: np.ndarray
    scale: float  # the capture's similarity: x_car = scale * R x_map + t
    rotation: np.ndarray
    translation: np.ndarray
    box_m: np.ndarray  # length, width, height (m)
    neighbours: list[str]  # the database cars of Eq. 6.4
    weights: np.ndarray
    cd: float  # Eq. 6.4 applied to the neighbours' drag coefficients
    speed_inf: float  # the database's inflow speed (m/s)
    cloud_points: int
    seconds: dict[str, float] = field(default_factory=dict)
    # a contour plane when asked (Fig. 6.10b): the pressure coefficient (Cp from -1 to 1) or the speed (0 to 1.4 x the
    # inflow, the streamlines' scale) on the symmetry plane outside the body: vertices (map frame), triangles, colours
    # (through the colour table)
    section: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def map_units_per_metre(self) -> float:
        return 1.0 / self.scale


@dataclass(frozen=True)
class RakeSettings:
    """Where the streamlines start: a plane ``upstream_m`` ahead of the nose, ``ny`` x ``nz`` seeds over the car's
    width (x ``span``) and height (from ``z0_m`` to ``span`` x its height)."""

    upstream_m: float = 1.5
    ny: int = 11
    nz: int = 9
    span: float = 1.35
    z0_m: float = 0.15
    step_m: float = 0.05
    draw_every: int = 3  # keep every n-th traced point (a 5 cm step drawn every 15 cm)


class AeroEstimator:
    """The database, its manifold (``neighbours`` = M) and the capture settings; :meth:`estimate` per cloud."""

    def __init__(self, db: AeroDatabase, neighbours: int = 15, capture: CaptureSettings | None = None,
                 rake: RakeSettings | None = None, section: str = "none") -> None:
        """``section``: also a contour plane on the symmetry plane: ``pressure`` (Eq. 6.4 on the database's pressure,
        as its coefficient) or ``velocity`` (the speed of Eq. 6.4's velocity); ``none``: no plane."""
        if section not in SECTIONS:
            raise ValueError(f"aero: section must be one of {', '.join(SECTIONS)}; found {section!r}")
        self.db = db
        self.section = section
        dbi = db.database
        if neighbours < 2 or neighbours > len(dbi) - 1:
            raise ValueError(f"aero: neighbours must be 2..{len(dbi) - 1} for a database of {len(dbi)} cars; "
                             f"found {neighbours}")
        self.Z = db.presence[dbi]
        self.V = db.velocity[dbi]
        self.P = db.pressure[dbi]
        self.cd_db = db.cd[dbi]
        self.names = [db.cars[i].name for i in dbi]
        self.manifold = ShapeManifold(self.Z, n_neighbors=neighbours)
        self.capture = capture or CaptureSettings()
        self.rake = rake or RakeSettings()
        self.speed_inf = float(db.cfd.get("speed", 10.0))
        self.lut = speed_lut()

    def _nearer_front(self, phi_a: np.ndarray, phi_b: np.ndarray) -> int:
        """Which reading of the principal axis is nose-first: the one whose shape lies nearer the database's cars."""
        return int(self.manifold.neighbours(phi_b)[1][0] < self.manifold.neighbours(phi_a)[1][0])

    def _flow(self, cloud: np.ndarray):
        """(capture, neighbourhood, Eq. 6.4's velocity on the grid (D, 3), zero inside the captured body)."""
        cap = capture_car(cloud, self.db.grid, self.capture, choose_front=self._nearer_front)
        nb = self.manifold.place(cap.presence)
        return cap, nb, ShapeManifold.interpolate(self.V, nb) * (1.0 - cap.presence)[:, None]

    def velocity(self, cloud: np.ndarray) -> np.ndarray:
        """Eq. 6.4's velocity (D, 3) on the database's grid, in the captured car's frame, for the car in ``cloud``."""
        return self._flow(cloud)[2]

    def estimate(self, cloud: np.ndarray) -> FlowResult:
        """The flow of the car in ``cloud`` ((n, 3) map frame). ValueError (with the step) when no car is found."""
        t0 = time.perf_counter()
        cap, nb, v = self._flow(cloud)
        t1 = t2 = time.perf_counter()
        r = self.rake
        _length, W, H = (float(x) for x in cap.box)
        seeds = seed_rake(-r.upstream_m, (-0.5 * r.span * W, 0.5 * r.span * W), (r.z0_m, r.span * H), r.ny, r.nz)
        lines = trace(FlowField(self.db.grid, v), seeds, step=r.step_m)
        t3 = time.perf_counter()
        lines = [ln[:: r.draw_every] for ln in lines if len(ln[:: r.draw_every]) >= 2]
        tm = (cap.scale, cap.rotation, cap.translation)
        sec = None
        if self.section != "none":
            if self.section == "pressure":  # Eq. 6.4 on the kinematic pressure; Cp = p / (U^2 / 2) (outlet's p: 0)
                vals = (ShapeManifold.interpolate(self.P[:, :, None], nb)[:, 0] * (1.0 - cap.presence)
                        / (0.5 * self.speed_inf ** 2))
                vmin, vmax = -1.0, 1.0
            else:  # the speed of Eq. 6.4's velocity, on the streamlines' colour scale
                vals, vmin, vmax = np.linalg.norm(v, axis=1), 0.0, SPEED_SCALE * self.speed_inf
            SV, ST, SC = section(self.db.grid, vals, axis=1, index=0, lut=self.lut, vmin=vmin, vmax=vmax,
                                 keep=cap.presence == 0)
            sec = (car_to_world(SV, *tm), ST, SC)
        return FlowResult(
            lines=[car_to_world(ln[:, :3], *tm) for ln in lines], speeds=[ln[:, 3].copy() for ln in lines],
            body_vertices=car_to_world(cap.vertices, *tm), body_triangles=np.asarray(cap.triangles),
            scale=float(cap.scale), rotation=np.asarray(cap.rotation), translation=np.asarray(cap.translation),
            box_m=np.asarray(cap.box, float), neighbours=[self.names[j] for j in nb.indices],
            weights=np.asarray(nb.weights, float), cd=float(nb.weights @ self.cd_db[nb.indices]),
            speed_inf=self.speed_inf, cloud_points=len(cloud),
            seconds={"capture": t1 - t0, "trace": t3 - t2}, section=sec)


def flow_markers(res: FlowResult, lut: np.ndarray, tube_radius_m: float = FLOW_TUBE_RADIUS_M,
                 body_color=(0.55, 0.6, 0.65)) -> list:
    """The result as RViz markers (map frame): the captured body (TRIANGLE_LIST, ns ``aero/body``) and one
    LINE_STRIP per streamline (ns ``aero/streamlines``, width = the tube's diameter in map units, coloured by speed
    from 0 to 1.4 x the inflow through ``lut``)."""
    from simreal_nodes.io.cdr import LINE_STRIP, TriangleListMarker

    eye = np.eye(4)
    tri = np.asarray(res.body_triangles).ravel()
    out = [TriangleListMarker("aero/body", 0, eye, res.body_vertices[tri], np.tile(body_color, (len(tri), 1)))]
    if res.section is not None:
        SV, ST, SC = res.section
        idx = np.asarray(ST).ravel()
        out.append(TriangleListMarker("aero/section", 0, eye, SV[idx], SC[idx]))
    top = SPEED_SCALE * res.speed_inf
    for k, (P, sp) in enumerate(zip(res.lines, res.speeds)):
        u = np.clip(np.nan_to_num(sp / top), 0.0, 1.0)
        out.append(TriangleListMarker("aero/streamlines", k, eye, P, lut[(u * 255).astype(int)], kind=LINE_STRIP,
                                      width=2.0 * tube_radius_m * res.map_units_per_metre))
    return out
