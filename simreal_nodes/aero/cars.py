"""A procedural family of car bodies (thesis ch. 6, §6.2.3: large cars, sport cars, old cars, "various").

The thesis's database is 80 de-refined CAD bodies of real cars; we have no such files, so each body here is drawn
from a parametric generator with the same four groups. A body is a loft along the car's length ``x`` (nose at
``x = 0``, tail at ``x = L``) of superelliptic cross-sections, symmetric about the centre plane ``y = 0``, standing
on the ground ``z = 0`` with a clearance:

* side view: the roof line ``z_t(x)`` is a monotone cubic (PCHIP, so it never overshoots the roof) through the nose,
  the hood's end, the roof's front and rear, the deck and the tail; the floor ``z_b(x)`` is the clearance;
* plan view: the half-width ``w(x) = W/2 (1 - |2x/L - 1|^p)^(1/p)``, and the ends are rounded in side view the same
  way, so the body closes at the nose and the tail;
* section: ``|y / (w t(z))|^n + |(z - z_m) / h|^n <= 1`` with ``z_m, h`` the section's centre and half-height, ``n``
  its boxiness and ``t(z)`` the tumblehome (the glasshouse narrower than the body above the belt line).

The same inequality is the presence function of Eq. 6.1 (:meth:`CarShape.inside`), exact at any point, and its
boundary is the triangulated surface handed to the CFD mesher (:meth:`CarShape.surface`, closed and watertight).
"""

from __future__ import annotations

import struct
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator

GROUPS = ("large", "sport", "old", "various")


@dataclass(frozen=True)
class CarShape:
    """One car body, metres. ``profile_x`` are fractions of the length, ``profile_z`` heights of the roof line."""

    name: str
    group: str
    length: float
    width: float
    height: float
    clearance: float
    profile_x: tuple[float, ...]
    profile_z: tuple[float, ...]
    plan_power: float  # p: how square the ends are in plan and side view
    section_power: float  # n: how boxy a cross-section is
    belt: float  # belt-line height (m) above which the tumblehome narrows the body
    tumblehome: float  # fraction the half-width loses from the belt line to the roof

    def __post_init__(self) -> None:
        px = np.asarray(self.profile_x)
        if len(px) != len(self.profile_z) or len(px) < 3 or px[0] != 0.0 or px[-1] != 1.0 or np.any(np.diff(px) <= 0):
            raise ValueError(f"car {self.name}: the roof line needs increasing fractions from 0 to 1")
        if not (self.length > 0 and self.width > 0 and self.height > self.clearance >= 0):
            raise ValueError(f"car {self.name}: needs length, width > 0 and height > clearance >= 0")
        if min(self.profile_z) <= self.clearance or max(self.profile_z) > self.height + 1e-9:
            raise ValueError(f"car {self.name}: the roof line must stay between the clearance and the height")
        numbers = (self.length, self.width, self.height, self.clearance, self.plan_power, self.section_power,
                   self.belt, self.tumblehome, *self.profile_x, *self.profile_z)
        if not all(np.isfinite(numbers)):
            raise ValueError(f"car {self.name}: a parameter is not finite")
        if self.plan_power <= 0 or self.section_power <= 0 or not (0.0 <= self.tumblehome < 1.0):
            raise ValueError(f"car {self.name}: powers must be positive and the tumblehome in [0, 1)")
        if not (self.clearance <= self.belt < self.height):
            raise ValueError(f"car {self.name}: the belt line must lie between the clearance and the height")

    # --- the body's outline -------------------------------------------------------------------------------------
    def _ends(self, x: np.ndarray) -> np.ndarray:
        """Rounding of the ends, 1 in the middle, 0 at the nose and the tail."""
        u = np.clip(np.abs(2.0 * x / self.length - 1.0), 0.0, 1.0)
        return (1.0 - u ** self.plan_power) ** (1.0 / self.plan_power)

    def section(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Half-width ``w``, centre height ``z_m`` and half-height ``h`` of the section at ``x`` (0 outside)."""
        x = np.asarray(x, float)
        inside = (x > 0) & (x < self.length)
        xs = np.clip(x, 0.0, self.length)
        top = PchipInterpolator(np.asarray(self.profile_x) * self.length, self.profile_z)(xs)
        e = np.where(inside, self._ends(xs), 0.0)
        zm = 0.5 * (top + self.clearance)
        h = 0.5 * (top - self.clearance) * e ** 0.5  # the ends round more gently in side view than in plan
        return 0.5 * self.width * e, zm, h

    def _tumble(self, z: np.ndarray) -> np.ndarray:
        return 1.0 - self.tumblehome * np.clip((z - self.belt) / (self.height - self.belt), 0.0, 1.0)

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Eq. 6.1's presence function: True where a point (n, 3) lies in the body (full car, both sides)."""
        p = np.asarray(points, float).reshape(-1, 3)
        w, zm, h = self.section(p[:, 0])
        ok = (w > 0) & (h > 0)
        wz = np.where(ok, w * self._tumble(p[:, 2]), 1.0)
        hz = np.where(ok, h, 1.0)
        n = self.section_power
        r = np.abs(p[:, 1] / wz) ** n + np.abs((p[:, 2] - zm) / hz) ** n
        return ok & (r <= 1.0)

    def surface(self, n_x: int = 60, n_ring: int = 48) -> tuple[np.ndarray, np.ndarray]:
        """A closed, outward-oriented triangulation of the body: ``n_x`` rings (cosine-spaced along the length,
        denser at the ends) of ``n_ring`` points, closed by a fan at the nose and at the tail."""
        s = 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n_x + 2)[1:-1]))  # strictly inside (0, 1)
        x = s * self.length
        w, zm, h = self.section(x)
        th = np.linspace(0.0, 2.0 * np.pi, n_ring, endpoint=False)
        c, sn = np.cos(th), np.sin(th)
        e = 2.0 / self.section_power
        uy = np.sign(c) * np.abs(c) ** e
        uz = np.sign(sn) * np.abs(sn) ** e
        z = zm[:, None] + h[:, None] * uz[None, :]
        y = w[:, None] * self._tumble(z) * uy[None, :]
        ring = np.stack([np.broadcast_to(x[:, None], z.shape), y, z], axis=-1).reshape(-1, 3)
        nose = np.array([[0.0, 0.0, zm[0]]])
        tail = np.array([[self.length, 0.0, zm[-1]]])
        vertices = np.vstack([ring, nose, tail])
        i_nose, i_tail = len(ring), len(ring) + 1
        tris = []
        j = np.arange(n_ring)
        jn = (j + 1) % n_ring
        for i in range(n_x - 1):
            a, b = i * n_ring + j, i * n_ring + jn
            a2, b2 = (i + 1) * n_ring + j, (i + 1) * n_ring + jn
            tris.append(np.stack([a, a2, b2], 1))
            tris.append(np.stack([a, b2, b], 1))
        tris.append(np.stack([np.full(n_ring, i_nose), j, jn], 1))
        last = (n_x - 1) * n_ring
        tris.append(np.stack([np.full(n_ring, i_tail), last + jn, last + j], 1))
        faces = np.vstack(tris).astype(np.int64)
        # orient outwards: the signed volume must be positive
        v0, v1, v2 = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
        if np.einsum("ij,ij->i", v0, np.cross(v1, v2)).sum() < 0:
            faces = faces[:, ::-1].copy()
        return vertices, faces

    def frontal_area(self) -> float:
        """Projected area on the y-z plane of the full car (m^2), from the largest section (for a drag coefficient)."""
        x = np.linspace(0.0, self.length, 401)[1:-1]
        z = np.linspace(self.clearance, self.height, 200)
        yy = np.linspace(0.0, 0.5 * self.width, 200)
        P = np.stack(np.meshgrid(x, yy, z, indexing="ij"), -1).reshape(-1, 3)
        occupied = self.inside(P).reshape(len(x), len(yy), len(z)).any(axis=0)
        return float(2.0 * occupied.sum() * (yy[1] - yy[0]) * (z[1] - z[0]))

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def car_from_dict(d: dict[str, object]) -> CarShape:
    """The inverse of :meth:`CarShape.to_dict` (a database's stored parameters); values are type-checked."""
    try:
        return CarShape(
            name=str(d["name"]), group=str(d["group"]), length=float(d["length"]), width=float(d["width"]),  # type: ignore[arg-type]
            height=float(d["height"]), clearance=float(d["clearance"]),  # type: ignore[arg-type]
            profile_x=tuple(float(v) for v in d["profile_x"]),  # type: ignore[attr-defined]
            profile_z=tuple(float(v) for v in d["profile_z"]),  # type: ignore[attr-defined]
            plan_power=float(d["plan_power"]), section_power=float(d["section_power"]),  # type: ignore[arg-type]
            belt=float(d["belt"]), tumblehome=float(d["tumblehome"]))  # type: ignore[arg-type]
    except (KeyError, TypeError) as exc:
        raise ValueError(f"not a car description: {exc}") from exc


# --- the four groups -------------------------------------------------------------------------------------------
def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def sample_car(group: str, rng: np.random.Generator, name: str) -> CarShape:
    """One body of ``group`` drawn from its ranges (sizes of real cars of the group, metres)."""
    if group == "large":  # SUVs: tall, boxy, long roof, near-vertical tail
        L, W, H, c = _u(rng, 4.5, 5.1), _u(rng, 1.88, 2.05), _u(rng, 1.65, 1.95), _u(rng, 0.20, 0.28)
        hood, ws, roof_end, deck = _u(rng, 0.22, 0.30), _u(rng, 0.36, 0.44), _u(rng, 0.86, 0.93), 0.97
        h_nose, h_hood, h_deck, h_tail = _u(rng, 0.70, 0.85), _u(rng, 0.98, 1.15), H - _u(rng, 0.05, 0.15), \
            _u(rng, 0.95, 1.15)
        p, n, tumble = _u(rng, 6.0, 10.0), _u(rng, 3.5, 5.5), _u(rng, 0.08, 0.14)
    elif group == "sport":  # low, long hood, short fastback cabin
        L, W, H, c = _u(rng, 4.2, 4.7), _u(rng, 1.85, 1.98), _u(rng, 1.15, 1.32), _u(rng, 0.10, 0.13)
        hood, ws, roof_end, deck = _u(rng, 0.36, 0.45), _u(rng, 0.50, 0.56), _u(rng, 0.62, 0.70), _u(rng, 0.88, 0.93)
        h_nose, h_hood, h_deck, h_tail = _u(rng, 0.42, 0.52), _u(rng, 0.80, 0.90), _u(rng, 0.92, 1.02), \
            _u(rng, 0.80, 0.95)
        p, n, tumble = _u(rng, 3.0, 4.5), _u(rng, 2.2, 3.0), _u(rng, 0.15, 0.25)
    elif group == "old":  # classic saloons and muscle cars: long flat hood and deck, upright glass, notchback
        L, W, H, c = _u(rng, 4.7, 5.3), _u(rng, 1.75, 1.92), _u(rng, 1.30, 1.45), _u(rng, 0.14, 0.18)
        hood, ws, roof_end, deck = _u(rng, 0.34, 0.42), _u(rng, 0.42, 0.48), _u(rng, 0.64, 0.72), _u(rng, 0.76, 0.82)
        h_nose, h_hood, h_deck, h_tail = _u(rng, 0.68, 0.80), _u(rng, 0.85, 0.95), _u(rng, 0.88, 0.98), \
            _u(rng, 0.80, 0.92)
        p, n, tumble = _u(rng, 7.0, 12.0), _u(rng, 3.0, 4.5), _u(rng, 0.10, 0.18)
    elif group == "various":  # hatchbacks, saloons and vans
        kind = int(rng.integers(3))
        if kind == 0:  # hatchback
            L, W, H, c = _u(rng, 3.7, 4.2), _u(rng, 1.68, 1.80), _u(rng, 1.42, 1.52), _u(rng, 0.13, 0.16)
            hood, ws, roof_end, deck = _u(rng, 0.18, 0.24), _u(rng, 0.36, 0.42), _u(rng, 0.80, 0.86), 0.96
            h_nose, h_hood, h_deck, h_tail = _u(rng, 0.62, 0.72), _u(rng, 0.88, 0.98), H - _u(rng, 0.15, 0.25), \
                _u(rng, 0.85, 1.00)
        elif kind == 1:  # saloon
            L, W, H, c = _u(rng, 4.4, 4.9), _u(rng, 1.75, 1.86), _u(rng, 1.40, 1.50), _u(rng, 0.13, 0.16)
            hood, ws, roof_end, deck = _u(rng, 0.26, 0.32), _u(rng, 0.42, 0.48), _u(rng, 0.68, 0.74), \
                _u(rng, 0.82, 0.88)
            h_nose, h_hood, h_deck, h_tail = _u(rng, 0.62, 0.72), _u(rng, 0.90, 1.00), _u(rng, 1.00, 1.10), \
                _u(rng, 0.90, 1.02)
        else:  # van
            L, W, H, c = _u(rng, 4.5, 5.0), _u(rng, 1.85, 2.0), _u(rng, 1.80, 2.00), _u(rng, 0.16, 0.20)
            hood, ws, roof_end, deck = _u(rng, 0.10, 0.15), _u(rng, 0.25, 0.30), _u(rng, 0.92, 0.96), 0.985
            h_nose, h_hood, h_deck, h_tail = _u(rng, 0.75, 0.90), _u(rng, 1.05, 1.20), H - _u(rng, 0.03, 0.08), \
                _u(rng, 1.50, 1.75)
        p, n, tumble = _u(rng, 5.0, 9.0), _u(rng, 3.0, 4.5), _u(rng, 0.06, 0.14)
    else:
        raise ValueError(f"unknown car group {group!r}; expected one of {', '.join(GROUPS)}")
    xs = (0.0, 0.03, hood, ws, roof_end, deck, 1.0)
    raw = (h_nose * 0.8, h_nose, h_hood, H, H, h_deck, min(h_tail, h_deck))
    zs = tuple(float(np.clip(z, c + 0.1, H)) for z in raw)
    return CarShape(name=name, group=group, length=L, width=W, height=H, clearance=c, profile_x=xs, profile_z=zs,
                    plan_power=p, section_power=n, belt=min(h_hood, H - 0.1), tumblehome=tumble)


def car_family(n_per_group: int, seed: int = 0) -> list[CarShape]:
    """``n_per_group`` bodies of each group, reproducible from ``seed`` (names ``<group>_<k>``)."""
    rng = np.random.default_rng(seed)
    return [sample_car(g, rng, f"{g}_{k:02d}") for k in range(n_per_group) for g in GROUPS]


def write_stl(path: str | Path, vertices: np.ndarray, faces: np.ndarray, solid: str = "car") -> None:
    """A binary STL (what snappyHexMesh reads), normals from the triangles' winding."""
    v = np.asarray(vertices, np.float64)[np.asarray(faces)]
    nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    rec = np.zeros(len(v), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = nrm, v
    with open(path, "wb") as fh:
        fh.write(solid.encode()[:80].ljust(80, b" "))
        fh.write(struct.pack("<I", len(v)))
        fh.write(rec.tobytes())
