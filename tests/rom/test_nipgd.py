"""NI-PGD (greedy rank-one, Eq. 5.4-5.5) reconstructs snapshot tensors; HOSVD for comparison."""

import numpy as np
import pytest

from simreal_nodes.rom import nipgd


def smooth_tensor(n=(60, 12, 9), seed=0):
    x = np.linspace(0, 1, n[0])[:, None, None]
    a = np.linspace(0, 1, n[1])[None, :, None]
    t = np.linspace(0, 1, n[2])[None, None, :]
    return np.sin(3 * x + a) * t + 0.3 * np.exp(-((x - a) ** 2) / 0.05) * t ** 2


def test_nipgd_reaches_its_tolerance_and_error_falls():
    A = smooth_tensor()
    res = nipgd.nipgd(A, max_terms=40, tol=1e-4)
    assert res.errors[-1] < 1e-4
    assert np.linalg.norm(res.full() - A) / np.linalg.norm(A) == pytest.approx(res.errors[-1], rel=1e-6)
    assert np.all(np.diff(res.errors) <= 1e-12)


def test_exact_rank_one_and_rank_two():
    rng = np.random.default_rng(1)
    u, v, w = rng.standard_normal(20), rng.standard_normal(7), rng.standard_normal(5)
    A = np.einsum("i,j,k->ijk", u, v, w)
    res = nipgd.nipgd(A, tol=1e-10)
    assert res.n_terms == 1 and res.errors[0] < 1e-10
    B = A + 0.5 * np.einsum("i,j,k->ijk", rng.standard_normal(20), rng.standard_normal(7), rng.standard_normal(5))
    assert nipgd.nipgd(B, tol=1e-8, max_terms=10).errors[-1] < 1e-8


def test_hosvd_comparison():
    A = smooth_tensor()
    t = nipgd.hosvd(A, ranks=[6, 6, 5])
    cp = nipgd.nipgd(A, max_terms=12, tol=1e-12)
    e_t = np.linalg.norm(t.full() - A) / np.linalg.norm(A)
    assert e_t < 1e-2 and t.storage < A.size
    full = nipgd.hosvd(A)
    assert np.linalg.norm(full.full() - A) / np.linalg.norm(A) < 1e-12
    # both methods agree on what is reducible: a dozen terms reach the same order of error
    assert cp.errors[-1] < 10 * e_t


def test_bad_tensors_are_rejected():
    with pytest.raises(ValueError, match="zero"):
        nipgd.nipgd(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="NaN"):
        nipgd.nipgd(np.array([[1.0, np.nan]]))
