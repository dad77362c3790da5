"""POD and intrusive PGD (Algorithm 2.1) against the full-order FEM on the moving-load cantilever."""

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from simreal_nodes.physics import fem, meshes
from simreal_nodes.physics import materials as mat
from simreal_nodes.rom import pgd, pod


def cantilever_2d(nx=45, ny=5, E=1000.0):
    m = meshes.rectangle(9.0, 1.0, (nx, ny), "tri")
    s = fem.Solid(m, mat.LinearElastic(E, 0.3), order=1, supports=[{"region": "xmin"}])
    top = s.vertices_in({"face": "ymax"})
    top = top[np.argsort(m.p[0, top])]
    H = sp.lil_matrix((s.N, len(top)))
    for j, v in enumerate(top):
        H[s.vertex_dofs(v)[1], j] = -1.0
    return s, top, m.p[0, top], H.tocsr()


def truth(s, H, E_scale=1.0):
    K = s.stiffness() * s.material.E * E_scale
    U = np.zeros((s.N, H.shape[1]))
    U[s.free] = spla.splu(K[s.free][:, s.free].tocsc()).solve(H[s.free].toarray())
    return U


def test_pgd_error_falls_as_modes_are_added():
    s, _top, xs, H = cantilever_2d()
    K = s.stiffness() * s.material.E
    res = pgd.pgd_solve(pgd.SeparatedOperator([(K, [np.ones(len(xs))])]), pgd.SeparatedLoad(H, [np.eye(len(xs))]),
                        [pgd.ParameterAxis(xs)], s.free, max_modes=15, tol=1e-8)
    U = truth(s, H)
    errs = [np.linalg.norm(res.evaluate_grid(n) - U) / np.linalg.norm(U) for n in (1, 2, 4, 8, 15)]
    assert errs[0] < 0.05 and errs[-1] < 5e-4
    assert all(b < a for a, b in itertools.pairwise(errs))
    assert res.amplitudes[4] < 1e-2 * res.amplitudes[0]


def test_three_field_pgd_with_young_modulus():
    """u(x, s, E) (thesis §2.1.4): K(E) = E K1, the E modes carry 1/E."""
    s, _top, xs, H = cantilever_2d(30, 4)
    K1 = s.stiffness()  # E units
    Ev = np.linspace(0.5, 2.0, 7)
    res = pgd.pgd_solve(pgd.SeparatedOperator([(K1, [np.ones(len(xs)), Ev])]),
                        pgd.SeparatedLoad(H / s.material.E, [np.eye(len(xs)), np.ones((len(xs), len(Ev)))]),
                        [pgd.ParameterAxis(xs), pgd.ParameterAxis(Ev)], s.free, max_modes=20, tol=1e-7)
    full = res.evaluate_grid()  # (N, ns, nE)
    for k in (0, 3, 6):
        U = truth(s, H, Ev[k])
        assert np.linalg.norm(full[:, :, k] - U) / np.linalg.norm(U) < 2e-3


def test_pgd_in_3d():
    m = meshes.box(1.0, 0.1, 0.1, (20, 2, 2), "hex")
    s = fem.Solid(m, mat.LinearElastic(1e9, 0.3), order=1, supports=[{"region": "xmin"}])
    top = s.vertices_in({"face": "zmax"})
    top = top[np.abs(m.p[1, top] - 0.05) < 1e-9]
    top = top[np.argsort(m.p[0, top])]
    H = sp.lil_matrix((s.N, len(top)))
    for j, v in enumerate(top):
        H[s.vertex_dofs(v)[2], j] = -10.0
    H = H.tocsr()
    K = s.stiffness() * 1e9
    res = pgd.pgd_solve(pgd.SeparatedOperator([(K, [np.ones(len(top))])]), pgd.SeparatedLoad(H, [np.eye(len(top))]),
                        [pgd.ParameterAxis(m.p[0, top])], s.free, max_modes=12, tol=1e-8)
    U = truth(s, H)
    assert np.linalg.norm(res.evaluate_grid() - U) / np.linalg.norm(U) < 1e-3


def test_pod_energy_criterion_and_galerkin_solve():
    s, _top, xs, H = cantilever_2d()
    U = truth(s, H)
    basis = pod.pod(U[s.free], energy=1 - 1e-8)
    assert basis.energy[basis.n_modes - 1] >= 1 - 1e-8
    assert basis.n_modes < len(xs)
    K = (s.stiffness() * s.material.E)[s.free][:, s.free]
    errs = []
    for n in (1, 3, 6, basis.n_modes):
        _, Ur = pod.galerkin_solve(K, H[s.free].toarray(), basis.B[:, :n])
        errs.append(np.linalg.norm(Ur - U[s.free]) / np.linalg.norm(U[s.free]))
    assert all(b <= a * 1.0000001 for a, b in itertools.pairwise(errs)) and errs[-1] < 1e-3
    with pytest.raises(ValueError, match="NaN"):
        pod.pod(np.full((3, 3), np.nan))
