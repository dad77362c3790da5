"""LLE of shapes and Eq. 6.4's interpolation, checked against scikit-learn and against exact cases."""

from __future__ import annotations

import numpy as np
import pytest

from simreal_nodes.aero.cars import car_family
from simreal_nodes.aero.grid import AeroGrid
from simreal_nodes.aero.manifold import ShapeManifold, reconstruction_weights


def test_weights_sum_to_one_and_reproduce_an_affine_combination() -> None:
    rng = np.random.default_rng(0)
    nb = rng.normal(size=(4, 50))
    w_true = np.array([0.5, 0.3, 0.4, -0.2])
    z = w_true @ nb
    w = reconstruction_weights(z, nb, reg=1e-9)
    assert w.sum() == pytest.approx(1.0)
    assert np.allclose(w, w_true, atol=1e-5)
    # more neighbours than the dimension they span: the regularisation keeps the system solvable
    w = reconstruction_weights(z, np.vstack([nb, nb[:2]]), reg=1e-3)
    assert np.isfinite(w).all() and w.sum() == pytest.approx(1.0)


@pytest.fixture(scope="module")
def shapes() -> tuple[np.ndarray, list]:
    grid = AeroGrid(shape=(70, 20, 10))
    cars = car_family(6, seed=5)
    return np.stack([grid.presence(c) for c in cars]), cars


def test_incremental_embedding_is_scikit_learns(shapes) -> None:
    Z, _ = shapes
    man = ShapeManifold(Z[:-3], n_neighbors=6)
    for z in Z[-3:]:
        nb = man.place(z)
        assert np.allclose(nb.coordinates, man.lle.transform(z[None])[0], atol=1e-8)
        assert nb.weights.sum() == pytest.approx(1.0)
        assert np.all(np.diff(nb.distances) >= 0)


def test_eq_6_4_is_exact_for_a_shape_between_its_neighbours(shapes) -> None:
    """A new 'shape' that is an affine combination of two database cars, and a field linear in the shape: Eq. 6.4
    with the LLE weights reproduces the field (to the regularisation); the nearest car's field alone does not."""
    Z, cars = shapes
    rng = np.random.default_rng(1)
    A = rng.normal(size=(Z.shape[1], 5)) / np.sqrt(Z.shape[1])
    F = Z @ A + 3.0
    man = ShapeManifold(Z, n_neighbors=8, reg=1e-9)
    for a in range(0, len(Z), 5):
        b = int(man.neighbours(Z[a], exclude=a)[0][0])
        z = 0.6 * Z[a] + 0.4 * Z[b]
        f = 0.6 * F[a] + 0.4 * F[b]
        nb = man.place(z)
        err = np.linalg.norm(ShapeManifold.interpolate(F, nb) - f)
        err_nearest = np.linalg.norm(F[nb.indices[0]] - f)
        assert err < 1e-3 * err_nearest, (cars[a].name, err, err_nearest)
    with pytest.raises(ValueError, match="more than"):
        ShapeManifold(Z[:5], n_neighbors=9)
    # leave-one-out inside the database never picks the car itself
    assert 0 not in man.place(Z[0], exclude=0).indices
