"""Tiny reduced models built in memory for unit tests (no FEM): a unit square plate of nodes whose
displacement is known in closed form, so every expected value can be written down."""

import numpy as np

from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.separated import Axis, SeparatedField


def plate_points(n: int = 6, size: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """n x n nodes on the z = 0 plane (object frame) and its 2 (n-1)^2 triangles."""
    xs = np.linspace(0, size, n)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    P = np.c_[X.ravel(), Y.ravel(), np.zeros(n * n)]
    tris = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            tris += [[a, b, c], [a, c, d]]
    return P, np.asarray(tris, np.int64)


def probe_model(n: int = 6, size: float = 0.1, depth: float = 0.01, n_modes: int = 1) -> ReducedModel:
    """Contact model: load points = every node, u(x; lp, tau) = -depth * tau * e_z at the loaded node's
    neighbourhood (a bump). Axes (load_point, pseudo_time) as the probe NI-PGD models have."""
    P, tris = plate_points(n, size)
    k = len(P)
    lp = np.arange(k, dtype=np.float64)
    tau = np.linspace(0, 1, 11)
    # separated form of a bump centred at each load point: one mode per load point (space) x indicator (lp)
    space = np.zeros((k, k, 3))
    for i in range(k):
        r = np.linalg.norm(P - P[i], axis=1)
        space[i, :, 2] = -depth * np.exp(-(r / (0.25 * size)) ** 2)
    g_lp = np.eye(k)
    g_tau = np.tile(tau, (k, 1))
    axes = [Axis("load_point", lp, "", "discrete", "linear"), Axis("pseudo_time", tau, "")]
    fld = SeparatedField("displacement", space, [g_lp, g_tau], axes, "m", ["x", "y", "z"])
    return ReducedModel("plate", P, tris, "tri3", axes, {"displacement": fld}, tris, "test plate",
                        {"law": "neo_hookean"}, load_points=np.arange(k), load_directions=np.tile([0, 0, -1.0], (k, 1)))


def beam_model(n_modes: int = 6, length: float = 0.5) -> ReducedModel:
    """Cantilever-like model u_z(x; s) = sum_i a_i(s) phi_i(x) with quickly decaying modes (for truncation)."""
    n = 26
    x = np.linspace(0, length, n)
    P = np.c_[np.repeat(x, 2), np.tile([0.0, 0.02], n), np.zeros(2 * n)]
    tris = []
    for i in range(n - 1):
        a, b, c, d = 2 * i, 2 * i + 1, 2 * i + 3, 2 * i + 2
        tris += [[a, b, c], [a, c, d]]
    s = np.linspace(0, length, 25)
    space = np.zeros((n_modes, 2 * n, 3))
    params = np.zeros((n_modes, len(s)))
    for i in range(n_modes):
        space[i, :, 2] = -0.01 * (P[:, 0] / length) ** (i + 2)
        space[i, :, 1] = 0.006 * (P[:, 0] / length) ** (i + 2)  # a sideways part: a rotation about z is observable
        params[i] = (0.3 ** i) * (s / length) ** (i + 1)
    axes = [Axis("s", s, "m")]
    fld = SeparatedField("displacement", space, [params], axes, "m", ["x", "y", "z"])
    tri = np.asarray(tris, np.int64)
    return ReducedModel("beam", P, tri, "tri3", axes, {"displacement": fld}, tri, "test beam",
                        {"law": "linear_elastic"})


def plate_load_model(n: int = 6, size: float = 0.1, depth: float = 0.01) -> ReducedModel:
    """Linear model over the load's position on the plate, axes (s_x, s_y) as the crossed beam's PGD has: the load at
    grid node g makes a bump -depth exp(-(r / 0.25 size)^2) e_z around g; one separated mode per node, its parameter
    modes the indicators of g's grid position, interpolated linearly (between nodes: the bilinear blend of the four
    neighbouring bumps). Every node is a load point."""
    P, tris = plate_points(n, size)
    xs = np.linspace(0, size, n)
    k = len(P)
    space = np.zeros((k, k, 3))
    gx, gy = np.zeros((k, n)), np.zeros((k, n))
    for g in range(k):
        r = np.linalg.norm(P - P[g], axis=1)
        space[g, :, 2] = -depth * np.exp(-(r / (0.25 * size)) ** 2)
        gx[g, g // n] = 1.0
        gy[g, g % n] = 1.0
    axes = [Axis("s_x", xs, "m", interpolation="linear"), Axis("s_y", xs, "m", interpolation="linear")]
    fld = SeparatedField("displacement", space, [gx, gy], axes, "m", ["x", "y", "z"])
    return ReducedModel("plate_load", P, tris, "tri3", axes, {"displacement": fld}, tris, "test plate, load anywhere",
                        {"law": "linear_elastic"}, load_points=np.arange(k),
                        load_directions=np.tile([0, 0, -1.0], (k, 1)))


def strip_load_model(n: int = 31, length: float = 0.3, width: float = 0.03, tip: float = 0.02) -> ReducedModel:
    """A linear cantilever strip (a sheet, clamped at x = 0) loaded along its centreline, axis ``s`` (the load's x)
    as the beams' PGD has: the load at s bends it by Euler-Bernoulli's Green's function, w(x; s) = x^2 (3 s - x) / 6
    for x <= s, s^2 (3 x - s) / 6 beyond, scaled so that the load at the tip bends the tip by ``tip`` (down). One
    separated mode per load position, its parameter mode the position's indicator (linear between positions). A
    load anywhere bends the whole strip: two loads share it (what makes two contacts at once couple)."""
    xs = np.linspace(0.0, length, n)
    X, Y = np.meshgrid(xs, [0.0, width / 2, width], indexing="ij")
    P = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    tris = []
    for i in range(n - 1):
        for j in range(2):
            a, b, c, d = 3 * i + j, 3 * (i + 1) + j, 3 * (i + 1) + j + 1, 3 * i + j + 1
            tris += [[a, b, c], [a, c, d]]
    x = P[:, 0]
    space = np.zeros((n, len(P), 3))
    for g, s in enumerate(xs):
        w = np.where(x <= s, x ** 2 * (3 * s - x), s ** 2 * (3 * x - s)) / 6.0
        space[g, :, 2] = -tip * w / (length ** 3 / 3.0)
    axes = [Axis("s", xs, "m", interpolation="linear")]
    fld = SeparatedField("displacement", space, [np.eye(n)], axes, "m", ["x", "y", "z"])
    lp = 3 * np.arange(n) + 1  # the centreline
    return ReducedModel("strip_load", P, np.asarray(tris, np.int64), "tri3", axes, {"displacement": fld},
                        np.asarray(tris, np.int64), "test strip, cantilever, load along its centreline",
                        {"law": "linear_elastic"}, load_points=lp, load_directions=np.tile([0, 0, -1.0], (n, 1)))
