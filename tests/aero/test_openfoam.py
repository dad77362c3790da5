"""The CFD solver against a published value before it builds a database: a sphere at Re = 100 (steady,
axisymmetric wake), drag coefficient 1.09 (Clift, Grace & Weber's standard drag curve; Johnson & Patel 1999 give
1.087 by DNS)."""

from __future__ import annotations

import numpy as np
import pytest

from simreal_nodes.aero.bodies import sphere_surface
from simreal_nodes.aero.openfoam import CfdError, CfdSettings, openfoam_available, run_case, write_case

pytestmark = pytest.mark.skipif(not openfoam_available(), reason="OpenFOAM is not installed (./run setup installs "
                                "Debian's openfoam)")


def test_sphere_drag_at_re_100(tmp_path) -> None:
    v, f = sphere_surface()
    s = CfdSettings(speed=1.0, nu=0.01, domain_min=(-6.0, 0.0, -6.0), domain_max=(14.0, 6.0, 6.0), background=0.5,
                    box_level=1, near_level=2, surface_level=3, iterations=2000, residual=1e-5, ground="slip",
                    turbulence="laminar", length=1.0)
    pts = np.array([[1.0, 0.0625, 0.0], [0.0, 0.0625, 0.0], [-5.0, 3.0, 0.0]])
    case = write_case(tmp_path / "sphere", v, f, pts, s, (np.array([-1.5, 0.0, -1.5]), np.array([4.0, 1.5, 1.5])),
                      (np.array([-3.0, 0.0, -3.0]), np.array([8.0, 3.0, 3.0])), ref_area=np.pi / 8, ref_length=1.0)
    r = run_case(case, pts, s)
    assert r.converged
    assert r.cd == pytest.approx(1.09, rel=0.06)  # 1.14 on this mesh; 1.114 one level finer (docs/aero.md)
    assert abs(r.cl) < 1e-3
    assert r.velocity[0, 0] < 0  # one radius behind the sphere: inside the recirculation bubble (length ~0.9 D)
    assert not r.in_fluid[1] and np.all(r.velocity[1] == 0)  # the sphere's centre is not in the mesh
    assert r.velocity[2, 0] == pytest.approx(1.0, abs=0.02)


def test_a_failing_mesh_says_which_step_failed(tmp_path) -> None:
    v, f = sphere_surface()
    s = CfdSettings(speed=1.0, nu=0.01, iterations=5)
    pts = np.zeros((1, 3))
    case = write_case(tmp_path / "bad", v, f, pts, s, (np.zeros(3), np.ones(3)), (np.zeros(3), np.ones(3)), 1.0, 1.0)
    (case / "system/blockMeshDict").write_text("garbage")
    with pytest.raises(CfdError, match="blockMesh failed"):
        run_case(case, pts, s)
