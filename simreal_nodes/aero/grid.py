"""The grid every car's shape and flow live on (thesis §6.2.1): 140 x 40 x 20 points over 14 x 5 x 4 m around the half
car, and the presence function of Eq. 6.1 on it.

Frame: the car's nose at ``x = 0`` pointing to ``-x`` (the flow goes along ``+x``), its centre plane ``y = 0`` (the
half car is ``y >= 0``), the ground ``z = 0``. The grid spans ``x`` from 4 m before the nose to 10 m behind it; its
points are the centres of the 140 x 40 x 20 cells of that box (spacing 0.1, 0.125, 0.2 m), so none lies on the
symmetry plane or the ground.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simreal_nodes.aero.cars import CarShape


@dataclass(frozen=True)
class AeroGrid:
    lo: tuple[float, float, float] = (-4.0, 0.0, 0.0)
    hi: tuple[float, float, float] = (10.0, 5.0, 4.0)
    shape: tuple[int, int, int] = (140, 40, 20)

    def __post_init__(self) -> None:
        if any(n < 1 for n in self.shape) or any(h <= lo for lo, h in zip(self.lo, self.hi)):
            raise ValueError(f"grid needs positive counts and hi > lo, got {self}")

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def spacing(self) -> np.ndarray:
        return (np.asarray(self.hi) - np.asarray(self.lo)) / np.asarray(self.shape)

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lo, h = np.asarray(self.lo), self.spacing
        return tuple(lo[k] + (np.arange(self.shape[k]) + 0.5) * h[k] for k in range(3))

    def points(self) -> np.ndarray:
        """(size, 3), x slowest, z fastest (C order of ``shape``)."""
        x, y, z = self.axes()
        return np.stack(np.meshgrid(x, y, z, indexing="ij"), -1).reshape(-1, 3)

    def presence(self, car: CarShape) -> np.ndarray:
        """Eq. 6.1 at every grid point: 1 inside the (half) car, 0 outside; float64, C order of ``shape``."""
        return car.inside(self.points()).astype(np.float64)

    def to_dict(self) -> dict[str, list[float] | list[int]]:
        return {"lo": list(self.lo), "hi": list(self.hi), "shape": list(self.shape)}


THESIS_GRID = AeroGrid()
