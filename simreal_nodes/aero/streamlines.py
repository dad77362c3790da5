"""Streamlines of a car's flow on the grid (thesis §6.4.2, Fig. 6.10a), as geometry the overlay renderer draws.

The velocity lives on the half-car grid (``y >= 0``); the full field is its mirror image (``v_y`` changes sign
across the symmetry plane). Streamlines are integrated with the classical fourth-order Runge-Kutta scheme in
space, ``dx/ds = v / |v|`` (arc length ``s``, so a step is ``step`` metres wherever the flow is slow), through a
trilinear interpolation of the grid (scipy's ``RegularGridInterpolator``); a line stops where it leaves the grid or
where the flow stops (the body, whose grid points carry zero velocity). Each line becomes a tube of triangles
coloured by the speed, for :class:`simreal_nodes.render.gl.Renderer`.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from simreal_nodes.aero.grid import AeroGrid


class FlowField:
    """The full (mirrored) velocity field of one car, evaluable anywhere in the grid's box."""

    def __init__(self, grid: AeroGrid, velocity: np.ndarray) -> None:
        v = np.asarray(velocity, float).reshape(*grid.shape, 3)
        x, y, z = grid.axes()
        # mirror the half field so that interpolation across y = 0 is exact: y -> -y, v_y -> -v_y
        ym = np.concatenate([-y[::-1], y])
        vm = np.concatenate([v[:, ::-1] * np.array([1.0, -1.0, 1.0]), v], axis=1)
        self.lo = np.array([x[0], -y[-1], z[0]])
        self.hi = np.array([x[-1], y[-1], z[-1]])
        self._f = RegularGridInterpolator((x, ym, z), vm, bounds_error=False, fill_value=np.nan)

    def __call__(self, p: np.ndarray) -> np.ndarray:
        return np.asarray(self._f(np.asarray(p, float).reshape(-1, 3)))


def trace(field: FlowField, seeds: np.ndarray, step: float = 0.05, n_steps: int = 400,
          min_speed: float = 0.2) -> list[np.ndarray]:
    """Streamlines from ``seeds`` (n, 3) downstream, RK4 in arc length; each a (k, 4) array of x, y, z, speed."""
    p = np.asarray(seeds, float).reshape(-1, 3).copy()
    alive = np.ones(len(p), bool)
    out: list[list[np.ndarray]] = [[] for _ in range(len(p))]

    def direction(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        v = field(q)
        s = np.linalg.norm(v, axis=1)
        ok = np.isfinite(s) & (s > min_speed)
        d = np.zeros_like(v)
        d[ok] = v[ok] / s[ok, None]
        return d, np.where(ok, s, np.nan)

    for _ in range(n_steps):
        idx = np.flatnonzero(alive)
        if len(idx) == 0:
            break
        q = p[idx]
        k1, s1 = direction(q)
        ok = np.isfinite(s1)
        for j, i in enumerate(idx):
            if ok[j]:
                out[i].append(np.append(q[j], s1[j]))
        k2, _ = direction(q + 0.5 * step * k1)
        k3, _ = direction(q + 0.5 * step * k2)
        k4, _ = direction(q + step * k3)
        q_new = q + step / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        inside = np.all((q_new >= field.lo) & (q_new <= field.hi), axis=1)
        alive[idx] = ok & inside
        p[idx] = q_new
    return [np.array(line) for line in out if len(line) >= 2]


def tubes(lines: list[np.ndarray], radius: float = 0.015, sides: int = 6,
          lut: np.ndarray | None = None, vmax: float | None = None,
          colors: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tubes around the lines: vertices (n, 3), triangles (m, 3), colours (n, 3) in [0, 1] from the speed through a
    256-entry colour table (``lut``, (256, 3) in [0, 1], e.g. ``render.overlay.colormap_lut``; a grey ramp without
    one), 0 to ``vmax`` (the fastest point of the lines by default). With ``colors`` (one (k, 3) array per line, as
    a received marker carries them) the lines may be (k, 3) points and are coloured by them instead."""
    verts, tris, cols = [], [], []
    base = 0
    top = 1.0 if colors is not None else (
        vmax if vmax is not None else max((float(np.nanmax(ln[:, 3])) for ln in lines), default=1.0))
    ang = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    for li, ln in enumerate(lines):
        P = ln[:, :3]
        sp = ln[:, 3] if colors is None else np.zeros(len(ln))
        t = np.gradient(P, axis=0)
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
        ref = np.where(np.abs(t[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        n1 = np.cross(t, ref)
        n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
        n2 = np.cross(t, n1)
        ring = P[:, None, :] + radius * (np.cos(ang)[None, :, None] * n1[:, None, :]
                                         + np.sin(ang)[None, :, None] * n2[:, None, :])
        verts.append(ring.reshape(-1, 3))
        u = np.clip(sp / max(top, 1e-9), 0.0, 1.0)
        if colors is not None:
            c = np.asarray(colors[li], float)[:, :3]
        else:
            c = lut[(u * 255).astype(int)] if lut is not None else np.repeat(u[:, None], 3, axis=1)
        cols.append(np.repeat(c, sides, axis=0))
        k = np.arange(len(P) - 1)[:, None] * sides + base
        j = np.arange(sides)[None, :]
        jn = (j + 1) % sides
        a, b, a2, b2 = k + j, k + jn, k + sides + j, k + sides + jn
        tris.append(np.stack([a, a2, b2], -1).reshape(-1, 3))
        tris.append(np.stack([a, b2, b], -1).reshape(-1, 3))
        base += len(P) * sides
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros((0, 3))
    return np.vstack(verts), np.vstack(tris).astype(np.int64), np.vstack(cols)


def seed_rake(x: float, y_range: tuple[float, float], z_range: tuple[float, float], ny: int, nz: int) -> np.ndarray:
    """A rectangular rake of seeds upstream of the car (a plane ``x`` = const)."""
    yy, zz = np.meshgrid(np.linspace(*y_range, ny), np.linspace(*z_range, nz), indexing="ij")
    return np.column_stack([np.full(yy.size, x), yy.ravel(), zz.ravel()])


def section(grid: AeroGrid, values: np.ndarray, axis: int, index: int, lut: np.ndarray, vmin: float, vmax: float,
            keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A plane of the grid (``axis`` 0/1/2 held at its ``index``-th value) as coloured quads, one per cell between
    four grid points (thesis Fig. 6.10b: velocity or pressure contours). ``values``: (D,) on the grid; ``keep``:
    (D,) bool, the points that may be drawn (e.g. outside the car); a quad is drawn when its four corners are kept.
    Returns vertices, triangles and colours ((n, 3) in [0, 1] through ``lut`` from ``vmin``..``vmax``)."""
    shape = grid.shape
    vals = np.asarray(values, float).reshape(shape)
    ok = np.ones(shape, bool) if keep is None else np.asarray(keep, bool).reshape(shape)
    P = grid.points().reshape(*shape, 3)
    sl = [slice(None)] * 3
    sl[axis] = slice(index, index + 1)
    t = tuple(sl)
    p2, v2, k2 = (np.squeeze(a[t], axis=axis) for a in (P, vals, ok))
    n0, n1 = v2.shape
    ij = np.arange(n0 * n1).reshape(n0, n1)
    a, b, c, d = ij[:-1, :-1], ij[1:, :-1], ij[1:, 1:], ij[:-1, 1:]
    k = k2.ravel()
    quad = k[a] & k[b] & k[c] & k[d]
    tris = np.concatenate([np.stack([a[quad], b[quad], c[quad]], 1), np.stack([a[quad], c[quad], d[quad]], 1)])
    u = np.clip((v2.ravel() - vmin) / max(vmax - vmin, 1e-12), 0.0, 1.0)
    colours = lut[np.nan_to_num(u * 255.0, nan=0.0).astype(int)]
    return p2.reshape(-1, 3), tris.astype(np.int64), colours
