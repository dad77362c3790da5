"""Building blocks of synthetic scenes: photographic textures, primitive meshes, fiducials, camera and
parameter trajectories, and sensor noise (pixel noise, Kinect-like depth noise with holes, motion blur)."""

from __future__ import annotations

import functools

import cv2
import numpy as np

from simreal_nodes import geometry as G

# ------------------------------------------------------------------------------------------------
# Textures (real photographs shipped with scikit-image)


@functools.cache
def texture(name: str) -> np.ndarray:
    """RGB uint8 texture: brick, gravel, grass (photographs), tinted variants for materials."""
    import skimage.data as d

    tints = {"brick": (1.0, 0.78, 0.62), "gravel": (0.95, 0.93, 0.88), "grass": (0.65, 0.95, 0.55),
             "foam": (1.0, 0.9, 0.55), "rubber": (0.35, 0.35, 0.38), "aluminium": (1.0, 1.0, 1.05),
             "wood": (0.82, 0.66, 0.5), "plate": (0.6, 0.62, 0.7), "lever": (0.97, 0.97, 0.95),
             "probe": (0.85, 0.6, 0.5)}
    src = {"brick": "brick", "gravel": "gravel", "grass": "grass", "foam": "gravel", "rubber": "grass",
           "aluminium": "moon", "wood": "gravel", "plate": "brick", "lever": "gravel", "probe": "grass"}[name]
    g = getattr(d, src)().astype(np.float32) / 255.0
    if name == "aluminium":
        g = 0.55 + 0.45 * cv2.GaussianBlur(g, (0, 0), sigmaX=6, sigmaY=0.5)  # brushed, light
    if name in ("lever", "foam"):
        g = 0.55 + 0.45 * g  # light material, still textured
    if name == "rubber":
        g = 0.4 + 0.6 * g
    rgb = np.clip(g[..., None] * np.asarray(tints[name], np.float32)[None, None, :], 0, 1)
    return (rgb * 255).astype(np.uint8)


def aruco_image(marker_id: int, dictionary: str = "DICT_4X4_50", module_px: int = 40,
                border_bits: int = 1) -> np.ndarray:
    """RGB image of an ArUco marker with a white quiet zone of one module; every module is exactly
    ``module_px`` pixels, so the black square is exactly (bits + 2 border) / (bits + 4) of the print."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    n = d.markerSize + 2 * border_bits
    img = cv2.aruco.generateImageMarker(d, int(marker_id), n * module_px, borderBits=border_bits)
    pad = module_px
    img = cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)
    return np.repeat(img[:, :, None], 3, axis=2)


# ------------------------------------------------------------------------------------------------
# Primitive meshes (vertices, triangles[, uv])


def box(size, center=(0, 0, 0)) -> tuple[np.ndarray, np.ndarray]:
    sx, sy, sz = (s / 2 for s in size)
    c = np.asarray(center, dtype=np.float64)
    V = np.array([[-sx, -sy, -sz], [sx, -sy, -sz], [sx, sy, -sz], [-sx, sy, -sz],
                  [-sx, -sy, sz], [sx, -sy, sz], [sx, sy, sz], [-sx, sy, sz]]) + c
    F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                  [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    return V, F


def quad(w: float, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quad in the z = 0 plane centred at the origin, normal +z, with UVs (0..1)."""
    V = np.array([[-w / 2, -h / 2, 0], [w / 2, -h / 2, 0], [w / 2, h / 2, 0], [-w / 2, h / 2, 0]])
    UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    return V, np.array([[0, 1, 2], [0, 2, 3]]), UV


def cylinder(radius: float, length: float, n: int = 24, axis: str = "z") -> tuple[np.ndarray, np.ndarray]:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.c_[radius * np.cos(a), radius * np.sin(a)]
    V = np.concatenate([np.c_[ring, np.zeros(n)], np.c_[ring, np.full(n, length)], [[0, 0, 0], [0, 0, length]]])
    F = []
    for k in range(n):
        k1 = (k + 1) % n
        F += [[k, k1, n + k1], [k, n + k1, n + k], [2 * n, k1, k], [2 * n + 1, n + k, n + k1]]
    V = V @ {"z": np.eye(3), "x": G.rot_axis("y", np.pi / 2).T, "y": G.rot_axis("x", -np.pi / 2).T}[axis]
    return V, np.asarray(F)


def sphere(radius: float, n: int = 16) -> tuple[np.ndarray, np.ndarray]:
    th = np.linspace(0, np.pi, n + 1)
    ph = np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    V = [[0, 0, radius]]
    for t in th[1:-1]:
        V += [[radius * np.sin(t) * np.cos(p), radius * np.sin(t) * np.sin(p), radius * np.cos(t)] for p in ph]
    V.append([0, 0, -radius])
    m = 2 * n
    F = [[0, 1 + k, 1 + (k + 1) % m] for k in range(m)]
    for r in range(n - 2):
        a, b = 1 + r * m, 1 + (r + 1) * m
        for k in range(m):
            k1 = (k + 1) % m
            F += [[a + k, b + k, b + k1], [a + k, b + k1, a + k1]]
    last = len(V) - 1
    base = 1 + (n - 2) * m
    F += [[last, base + (k + 1) % m, base + k] for k in range(m)]
    return np.asarray(V, dtype=np.float64), np.asarray(F)


def disk(radius: float, n: int = 20) -> tuple[np.ndarray, np.ndarray]:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = np.concatenate([[[0, 0, 0]], np.c_[radius * np.cos(a), radius * np.sin(a), np.zeros(n)]])
    return V, np.array([[0, 1 + k, 1 + (k + 1) % n] for k in range(n)])


def merge(parts) -> tuple[np.ndarray, np.ndarray]:
    V, F, off = [], [], 0
    for v, f in parts:
        V.append(v)
        F.append(f + off)
        off += len(v)
    return np.concatenate(V), np.concatenate(F)


# ------------------------------------------------------------------------------------------------
# Trajectories


def smooth_noise(t: np.ndarray, amplitude: float, seed: int, freqs=(0.37, 0.71, 1.3)) -> np.ndarray:
    """Sum of a few sinusoids with random phases: hand-held jitter (deterministic)."""
    rng = np.random.default_rng(seed)
    out = np.zeros((len(t), 3))
    for f in freqs:
        ph = rng.uniform(0, 2 * np.pi, 3)
        out += np.sin(2 * np.pi * f * t[:, None] + ph) / len(freqs)
    return amplitude * out


def arc_trajectory(t: np.ndarray, target, radius: float, height: float, az0: float, az1: float,
                   jitter: float = 0.005, seed: int = 0, period: float | None = None) -> list[np.ndarray]:
    """Hand-held-like arc around ``target``: azimuth sweeps az0 -> az1 (-> back if ``period``), height fixed."""
    target = np.asarray(target, dtype=np.float64)
    T = t[-1] if len(t) > 1 and t[-1] > 0 else 1.0
    ph = 0.5 - 0.5 * np.cos(2 * np.pi * t / period) if period else 0.5 - 0.5 * np.cos(np.pi * t / T)
    az = az0 + (az1 - az0) * ph
    eyes = np.c_[target[0] + radius * np.cos(az), target[1] + radius * np.sin(az), np.full(len(t), target[2] + height)]
    eyes = eyes + smooth_noise(t, jitter, seed)
    look = target + smooth_noise(t, jitter * 0.5, seed + 1)
    return [G.look_at(e, l) for e, l in zip(eyes, look)]


def holds(t: np.ndarray, values, hold_s: float, move_s: float) -> np.ndarray:
    """Piecewise-constant parameter with smooth (cosine) moves between values: a load placed, then moved."""
    values = np.asarray(values, dtype=np.float64)
    seg = hold_s + move_s
    k = np.minimum((t // seg).astype(int), len(values) - 1)
    frac = np.clip(((t - k * seg) - hold_s) / move_s, 0, 1)
    nxt = np.minimum(k + 1, len(values) - 1)
    w = 0.5 - 0.5 * np.cos(np.pi * frac)
    return values[k] * (1 - w) + values[nxt] * w


# ------------------------------------------------------------------------------------------------
# Sensor noise


def pixel_noise(img: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    if sigma <= 0:
        return img
    return np.clip(img.astype(np.float32) + rng.normal(0, sigma, img.shape), 0, 255).round().astype(np.uint8)


def kinect_depth(depth: np.ndarray, rng: np.random.Generator, sigma0: float = 0.0012, sigma2: float = 0.0019,
                 dropout: float = 0.01, edge_holes: bool = True, max_range: float = 6.0,
                 min_range: float = 0.3) -> np.ndarray:
    """Structured-light-like depth: sigma(z) = sigma0 + sigma2 (z - 0.4)^2 (Nguyen et al. 2012), invalid (0)
    out of range, in the projector's shadow beside depth discontinuities and at random speckles."""
    d = depth.astype(np.float32).copy()
    valid = d > 0
    sig = sigma0 + sigma2 * (d - 0.4) ** 2
    d[valid] += (rng.standard_normal(np.count_nonzero(valid)) * sig[valid]).astype(np.float32)
    bad = ~valid | (d < min_range) | (d > max_range)
    if edge_holes:
        # the projector (left of the IR camera) casts a shadow on the *farther* surface to the right of a depth
        # edge: those background pixels (about 2 px) have no pattern; the near object's own pixels stay valid
        z = np.where(depth > 0, depth, np.float32(max_range * 2)).astype(np.float32)
        jump = np.zeros(z.shape, bool)
        jump[:, 1:] = (z[:, 1:] - z[:, :-1]) > 0.08 * z[:, :-1]
        shadow = jump.copy()
        shadow[:, 1:] |= jump[:, :-1]
        bad |= shadow
    if dropout > 0:
        seeds = rng.random(d.shape) < dropout / 9
        bad |= cv2.dilate(seeds.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    d[bad] = 0.0
    return d


def depth_to_16uc1(d: np.ndarray) -> np.ndarray:
    """metres (0 invalid) -> uint16 millimetres (0 invalid), REP-118."""
    return np.where(d > 0, np.clip(np.round(d * 1000), 1, 65535), 0).astype(np.uint16)
