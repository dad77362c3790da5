"""A simulated sparse SLAM map of a car standing on a textured floor (input to Alg. 6.1, with its truth).

What a feature-based SLAM keeps after circling a car at about head height: points on the car's sides, ends and
roof (never its underside), many points on the floor around it, triangulation noise, a few gross outliers, all in
an arbitrary map frame (a random rotation and translation) and, for a monocular map, at an arbitrary scale. The
truth (the car and the map -> car-frame similarity) is returned beside the cloud for scoring only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from simreal_nodes.aero.cars import CarShape


@dataclass
class CarMap:
    cloud: np.ndarray  # (n, 3) map frame: x_map = scale * R x_car + translation
    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def to_car(self, x: np.ndarray) -> np.ndarray:
        """The truth's map -> car-frame transform (for scoring)."""
        return ((np.asarray(x) - self.translation) @ self.rotation) / self.scale


def simulate_map(car: CarShape, rng: np.random.Generator, n_car: int = 3000, n_floor: int = 3000,
                 noise: float = 0.01, outliers: float = 0.03, metric: bool = True,
                 floor_noise: float | None = None) -> CarMap:
    """``noise``: the points' triangulation noise (m, each axis); ``floor_noise``: the floor's own (default the same:
    a depth camera's floor a few metres away is thicker than the car's near side)."""
    v, f = car.surface()
    tri = v[f]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(nrm, axis=1)
    unit = nrm / np.maximum(2.0 * area[:, None], 1e-300)
    seen = (unit[:, 2] > -0.3) & (tri[:, :, 2].mean(axis=1) > car.clearance + 0.05)
    pick = rng.choice(np.flatnonzero(seen), size=n_car, p=area[seen] / area[seen].sum())
    r1, r2 = rng.random(n_car), rng.random(n_car)
    flip = r1 + r2 > 1
    r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
    body = tri[pick, 0] + r1[:, None] * (tri[pick, 1] - tri[pick, 0]) + r2[:, None] * (tri[pick, 2] - tri[pick, 0])
    floor = np.column_stack([rng.uniform(-3.0, car.length + 3.0, 4 * n_floor),
                             rng.uniform(-3.5, 3.5, 4 * n_floor), np.zeros(4 * n_floor)])
    below = car.inside(floor + np.array([0.0, 0.0, car.clearance + 0.01]))
    floor = floor[~below][:n_floor]
    body = body + rng.normal(0.0, noise, body.shape)
    floor = floor + rng.normal(0.0, noise if floor_noise is None else floor_noise, floor.shape)
    pts = np.vstack([body, floor])
    n_out = int(outliers * len(pts))
    lo, hi = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0
    pts = np.vstack([pts, rng.uniform(lo, hi, (n_out, 3))])
    rng.shuffle(pts)
    R = Rotation.random(random_state=rng).as_matrix()
    s = 1.0 if metric else float(np.exp(rng.uniform(np.log(0.2), np.log(5.0))))
    t = rng.normal(0.0, 3.0, 3)
    return CarMap(cloud=s * pts @ R.T + t, scale=s, rotation=R, translation=t)
