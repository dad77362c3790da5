"""The procedural car family: closed, outward surfaces whose inside is the presence function (Eq. 6.1)."""

from __future__ import annotations

import numpy as np
import pytest

from simreal_nodes.aero.cars import GROUPS, CarShape, car_family, car_from_dict, sample_car, write_stl
from simreal_nodes.aero.grid import THESIS_GRID, AeroGrid


@pytest.fixture(scope="module")
def family() -> list[CarShape]:
    return car_family(2, seed=3)


def test_every_surface_is_closed_outward_and_bounds_the_presence_function(family: list[CarShape]) -> None:
    rng = np.random.default_rng(0)
    for car in family:
        v, f = car.surface()
        edges = np.sort(np.vstack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        _, count = np.unique(edges, axis=0, return_counts=True)
        assert np.all(count == 2), f"{car.name}: an edge not shared by exactly two triangles"
        volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6.0
        assert volume > 0, f"{car.name}: triangles wound inwards"
        box = np.array([car.length, car.width, car.height])
        P = rng.uniform([0.0, -0.5 * car.width, 0.0], [car.length, 0.5 * car.width, car.height], (100_000, 3))
        mc = car.inside(P).mean() * np.prod(box)
        assert abs(mc - volume) < 0.02 * volume, f"{car.name}: surface {volume:.3f} m3, presence {mc:.3f} m3"


def test_groups_have_their_proportions() -> None:
    cars = car_family(10, seed=1)
    h = {g: np.mean([c.height for c in cars if c.group == g]) for g in GROUPS}
    assert h["sport"] < h["old"] < h["large"]
    assert all(c.inside(np.array([[0.5 * c.length, 0.0, 0.5 * (c.clearance + c.height)]]))[0] for c in cars)
    assert not any(c.inside(np.array([[0.5 * c.length, 0.0, 0.5 * c.clearance]]))[0] for c in cars)  # under the floor


def test_presence_on_the_thesis_grid_is_the_half_car(family: list[CarShape]) -> None:
    assert THESIS_GRID.size == 140 * 40 * 20
    assert np.allclose(THESIS_GRID.spacing, [0.1, 0.125, 0.2])
    car = family[0]
    phi = THESIS_GRID.presence(car)
    assert set(np.unique(phi)) == {0.0, 1.0}
    # the half car's volume on the grid is half the body's
    v, f = car.surface()
    volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6.0
    assert phi.sum() * np.prod(THESIS_GRID.spacing) == pytest.approx(volume / 2, rel=0.05)
    with pytest.raises(ValueError):
        AeroGrid(shape=(0, 1, 1))


def test_parameters_round_trip_and_bad_ones_are_refused(family: list[CarShape], tmp_path) -> None:
    car = family[1]
    assert car_from_dict(car.to_dict()) == car
    with pytest.raises(ValueError, match="not a car"):
        car_from_dict({"name": "x"})
    with pytest.raises(ValueError, match="roof line"):
        CarShape(**{**car.to_dict(), "profile_x": (0.0, 0.5, 0.4, 1.0), "profile_z": (0.5, 1.0, 1.0, 0.6)})
    with pytest.raises(ValueError, match="belt line"):
        CarShape(**{**car.to_dict(), "belt": car.height})
    with pytest.raises(ValueError, match="not finite"):
        CarShape(**{**car.to_dict(), "tumblehome": float("nan")})
    with pytest.raises(ValueError, match="unknown car group"):
        sample_car("truck", np.random.default_rng(0), "t")
    v, f = car.surface()
    write_stl(tmp_path / "car.stl", v, f)
    data = (tmp_path / "car.stl").read_bytes()
    assert len(data) == 84 + 50 * len(f) and int.from_bytes(data[80:84], "little") == len(f)
