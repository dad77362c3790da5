"""Evaluation API: u(x, mu) at any mu in range, sensitivities = finite differences, truncation, errors."""

import numpy as np
import pytest

from simreal_nodes.rom.separated import Axis, SeparatedField


@pytest.fixture
def field():
    rng = np.random.default_rng(0)
    s = np.linspace(0, 0.5, 26)
    E = np.linspace(50e9, 90e9, 9)
    m = 6
    space = rng.standard_normal((m, 40, 3))
    G = np.stack([np.sin((i + 1) * 4 * s) for i in range(m)])
    H = np.stack([1.0 / (E / 69e9) ** (i + 1) for i in range(m)])
    return SeparatedField("displacement", space, [G, H], [Axis("s", s, "m"), Axis("E", E, "Pa")], "m", ["x", "y", "z"])


def test_sensitivities_match_finite_differences_off_grid(field):
    mu = np.array([0.2137, 61.3e9])
    nodes = np.array([3, 17, 29])
    for k, h in ((0, 1e-6), (1, 1e3)):
        d = field.sensitivity(mu, k, nodes)
        mp, mm = mu.copy(), mu.copy()
        mp[k] += h
        mm[k] -= h
        fd = (field.evaluate(mp, nodes) - field.evaluate(mm, nodes)) / (2 * h)
        np.testing.assert_allclose(d, fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())
    view = field.view(nodes, n_modes=4)
    u, J = view.evaluate_with_jacobian(mu)
    np.testing.assert_allclose(u, field.evaluate(mu, nodes, 4))
    np.testing.assert_allclose(J[:, :, 0], field.sensitivity(mu, 0, nodes, 4))


def test_a_view_evaluates_many_parameter_sets_in_one_product(field):
    """evaluate_many (a search's candidates at once) gives each row's evaluate, in its order."""
    view = field.view(np.array([3, 17, 29, 5]), n_modes=5)
    mus = np.array([[0.01, 52e9], [0.2137, 61.3e9], [0.49, 89e9]])
    many = view.evaluate_many(mus)
    assert many.shape == (3, 4, 3)
    for k, mu in enumerate(mus):
        np.testing.assert_allclose(many[k], view.evaluate(mu), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(view.evaluate_many(mus[1]), view.evaluate(mus[1])[None], rtol=1e-13, atol=1e-15)


def test_grid_values_are_reproduced_exactly(field):
    i, j = 7, 3
    mu = [field.axes[0].values[i], field.axes[1].values[j]]
    c = field.params[0][:, i] * field.params[1][:, j]
    np.testing.assert_allclose(field.evaluate(mu), np.tensordot(c, field.space, (0, 0)), rtol=1e-12)


def test_truncation_and_bad_requests(field):
    mu = [0.1, 70e9]
    assert np.allclose(field.evaluate(mu, n_modes=6), field.evaluate(mu))
    assert not np.allclose(field.evaluate(mu, n_modes=2), field.evaluate(mu))
    with pytest.raises(ValueError, match="has 6 modes; 9 were requested"):
        field.evaluate(mu, n_modes=9)
    with pytest.raises(ValueError, match="outside the model's range"):
        field.evaluate([0.7, 70e9])
    with pytest.raises(ValueError, match="not finite"):
        field.evaluate([np.nan, 70e9])
    with pytest.raises(ValueError, match="expected 2 parameters"):
        field.evaluate([0.1])


def test_discrete_axis():
    space = np.ones((2, 5, 3))
    f = SeparatedField("u", space, [np.array([[1.0, 2, 3], [0, 1, 0]]), np.array([[0, 0.5, 1.0], [0, 1, 0]])],
                       [Axis("load_point", [0, 1, 2], kind="discrete"), Axis("pseudo_time", [0, 0.5, 1])])
    np.testing.assert_allclose(f.evaluate([1, 1.0]), 2.0)
    with pytest.raises(ValueError, match="not an index"):
        f.evaluate([1.5, 0.5])
    with pytest.raises(ValueError, match="discrete"):
        f.sensitivity([1, 0.5], 0)
    assert np.isfinite(f.sensitivity([1, 0.5], 1)).all()
