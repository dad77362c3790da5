"""The projection-error benchmark's measures (thesis Fig. 5.11 / 5.14) on a small separated field with a known
error: the reconstruction is the model's own evaluation at the grid, and each measure reads what was put in."""

from types import SimpleNamespace

import numpy as np

from benchmarks.projection_errors import reconstruct, state_errors
from simreal_nodes.render.overlay import von_mises
from simreal_nodes.rom.separated import Axis, SeparatedField


def _field(name: str, comps: int, rng) -> SeparatedField:
    axes = [Axis("load_point", np.arange(4.0), kind="discrete"), Axis("pseudo_time", np.linspace(0, 1, 5))]
    P1 = rng.normal(size=(3, 5))
    P1[:, 0] = 0.0  # the rest state is zero
    return SeparatedField(name, rng.normal(size=(3, 7, comps)), [rng.normal(size=(3, 4)), P1], axes)


def test_the_reconstruction_is_the_fields_own_evaluation_at_the_grid():
    f = _field("displacement", 3, np.random.default_rng(0))
    R = reconstruct(f)
    assert R.shape == (7, 3, 4, 5)
    for i in range(4):
        for k in range(5):
            np.testing.assert_allclose(R[:, :, i, k], f.evaluate([float(i), k / 4.0]), atol=1e-12)


def test_the_measures_read_a_known_error():
    rng = np.random.default_rng(1)
    fields = {"displacement": _field("displacement", 3, rng), "stress": _field("stress", 6, rng)}
    model = SimpleNamespace(fields=fields, provenance={"volume_nodes": 5})  # nodes 5, 6: scan vertices, left out
    snaps = {n: reconstruct(f)[:5].copy() for n, f in fields.items()}
    snaps["displacement"][2, 0, 1, 3] -= 0.004  # one node of one state 4 mm off (the model is 4 mm above it)
    err = state_errors(model, snaps)
    d = err["displacement_max"]
    assert d.shape == (4, 4)
    assert abs(d[1, 2] - 4.0) < 1e-9 and np.count_nonzero(d > 1e-9) == 1
    assert err["displacement_median"].max() < 1e-9  # one node of five: the median does not see it
    S = snaps["displacement"][:, :, 1, 3]
    assert abs(err["displacement_l2"][1, 2] - 0.004 / np.linalg.norm(S)) < 1e-12
    assert np.all(err["stress_l2"] < 1e-12) and np.all(err["stress_max"] < 1e-9)
    snaps["stress"][0, 0, 3, 1] += 2000.0  # 2 kPa on sigma_xx at one node
    err = state_errors(model, snaps)
    vm = lambda s: von_mises(s[None])[0]  # noqa: E731
    s0 = snaps["stress"][0, :, 3, 1]
    expected = abs(vm(s0) - vm(s0 - [2000.0, 0, 0, 0, 0, 0])) * 1e-3
    assert abs(err["stress_max"][3, 0] - expected) < 1e-9 and expected > 0.1
