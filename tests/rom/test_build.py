"""Builders for every kind of seed object, at test sizes (the full-size builds are benchmarks)."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from simreal_nodes.rom.build import build_model, load_spec
from tests.conftest import shared

FOAM = """
simreal_model_spec: 1
name: foam_small
kind: beam_snapshots
material: {law: saint_venant_kirchhoff, E: 1.1e+5, nu: 0.2}
geometry: {length: 0.7975, width: 0.2, height: 0.105}
mesh: {cells: [12, 3, 2]}
supports:
  - {region: {face: zmin, box: [[0.0, 0.07], null, null]}, kind: pinned}
  - {region: {face: zmin, box: [[0.73, 0.7975], null, null]}, kind: sliding, component: z}
load: {force: 15.0, patch_radius: 0.08, x_range: [0.2, 0.6], n: 5}
steps: 2
nipgd: {max_terms: 10, tol: 1.0e-8}
"""

BOOT = """
simreal_model_spec: 1
name: boot_small
kind: joint_boot
material: {law: neo_hookean, E: 5.0e+6, nu: 0.45}
mesh: {n_profile: 12, n_around: 12, n_thick: 1}
lever: {theta_deg: [0, 30], n: 6}
nipgd: {max_terms: 10, tol: 1.0e-6}
"""

BUNNY = """
simreal_model_spec: 1
name: bunny_tiny
kind: probe_nipgd
surface: data:meshes/stanford-bunny.ply
transform: {rotate_deg: [90, 0, 0], height_m: 0.15}
mesh: {cell_size: 0.16}
material: {law: neo_hookean_decoupled, E: 5.0e+5, nu: 0.4}
contact: {points: 3, rings: 1, force: 2.0, increments: 3}
nipgd: {max_terms: 40, tol: 1.0e-5}
"""

SVK_BEAM = """
simreal_model_spec: 1
name: svk_beam_small
kind: beam_contact_nipgd
material: {law: saint_venant_kirchhoff, E: 3.5e+9, nu: 0.36}
geometry: {length: 0.3, width: 0.03, height: 0.01}
mesh: {cells: [6, 1, 1]}
supports:
  - {region: xmin, kind: clamped}
load: {force: 15.0, increments: 4}
nipgd: {max_terms: 60, tol: 1.0e-6}
validation_points: 2
"""


def spec(tmp_path, text):
    f = tmp_path / "spec.yaml"
    f.write_text(textwrap.dedent(text))
    return load_spec(f)


def test_foam_beam_snapshots_and_nipgd(tmp_path):
    from simreal_nodes.physics.materials import LockingWarning

    with pytest.warns(LockingWarning, match="too stiff in bending"):  # linear elements (the default order)
        m = build_model(spec(tmp_path, FOAM))
    u = m.field("displacement")
    assert u.error_vs_modes[-1] < 1e-8  # NI-PGD reconstructs its snapshots to the stated tolerance
    assert m.displacement([0.4])[:, 2].min() < -0.005  # a 15 N disk sags a soft foam beam visibly
    mid = m.provenance["midpoint_interpolation_error"]
    assert all(e < 0.05 for e in mid.values())  # between snapshots the spline in s stays close to the FEM
    assert "stress" in m.fields and m.field("stress").n_comp == 6


def test_joint_boot_lever_sweep(tmp_path):
    m = build_model(spec(tmp_path, BOOT))
    assert m.axes[0].name == "theta" and m.axes[0].range[1] == pytest.approx(np.deg2rad(30))
    top = np.flatnonzero(np.isclose(m.points[:, 2], m.points[:, 2].max()))
    u = m.displacement([np.deg2rad(30)], nodes=top)
    # the top ring follows the lever: rigid rotation of 30 deg about y through the base centre
    c, s = np.cos(np.deg2rad(30)), np.sin(np.deg2rad(30))
    P = m.points[top]
    expected = np.stack([c * P[:, 0] + s * P[:, 2], P[:, 1], -s * P[:, 0] + c * P[:, 2]], 1) - P
    np.testing.assert_allclose(u, expected, atol=1e-4)
    assert m.rigid_parameters[0]["name"] == "alpha_z"


def test_bunny_probe_nipgd_reconstructs_snapshots(tmp_path):
    shared("meshes", "stanford-bunny.ply")
    from simreal_nodes.rom import build as B
    B.KEEP_SNAPSHOTS = True
    try:
        m = build_model(spec(tmp_path, BUNNY))
    finally:
        B.KEEP_SNAPSHOTS = False
    f = m.field("displacement")
    assert f.error_vs_modes[-1] < 1e-5
    U = m.snapshots["displacement"]
    nv = U.shape[0]
    for lp in range(3):
        for k in range(4):
            ref = U[:, :, lp, k]
            got = f.evaluate([lp, k / 3])[:nv]
            assert np.linalg.norm(got - ref) <= 1e-4 * max(np.linalg.norm(U), 1e-30)
    assert m.points.shape[0] > nv and m.surface.min() >= nv  # the scan surface rides on the volume mesh
    assert m.field("displacement").evaluate([1, 1.0])[:, 2].std() > 0


def test_svk_beam_over_load_position_and_pseudo_time(tmp_path, monkeypatch):
    """The thesis's crossed beam (SVK, a point load anywhere on the top face growing over pseudo-time): NI-PGD
    reconstructs its Newton snapshots, interpolates between load positions (checked against full-order solves there
    by the builder), and the sweep's processes do not change the model."""
    from simreal_nodes.physics import fem, materials, meshes
    from simreal_nodes.rom import build as B

    monkeypatch.setenv("SIMREAL_BUILD_WORKERS", "2")
    B.KEEP_SNAPSHOTS = True
    try:
        m = build_model(spec(tmp_path, SVK_BEAM))
    finally:
        B.KEEP_SNAPSHOTS = False
    assert [a.name for a in m.axes] == ["s_x", "s_y", "pseudo_time"]
    assert [len(a.values) for a in m.axes] == [7, 2, 5] and m.provenance["workers"] == 2
    assert len(m.load_points) == 14 and np.all(m.points[m.load_points, 2] == pytest.approx(0.01))
    U = m.snapshots["displacement"]
    f = m.field("displacement")
    for ix in (2, 6):
        for k in (1, 4):
            got = f.evaluate([m.axes[0].values[ix], 0.03, k / 4])
            assert np.linalg.norm(got - U[:, :, ix, 1, k]) <= 1e-5 * np.linalg.norm(U)
    # the snapshot at the tip is the full-order SVK solve of a point force at that vertex
    solid = fem.Solid(meshes.box(0.3, 0.03, 0.01, (6, 1, 1), "hex"),
                      materials.make_material("saint_venant_kirchhoff", 3.5e9, 0.36), 2,
                      [{"region": "xmin", "kind": "clamped"}])
    u, _ = solid.solve(solid.point_load([0.3, 0.03, 0.01], [0.0, 0.0, -15.0]), steps=4)
    np.testing.assert_allclose(U[:, :, 6, 1, 4], solid.vertex_displacement(u), rtol=0, atol=1e-9)
    assert all(e["relative_error"] < 0.02 for e in m.provenance["between_positions_error"])
    monkeypatch.setenv("SIMREAL_BUILD_WORKERS", "1")
    again = build_model(spec(tmp_path, SVK_BEAM))
    np.testing.assert_array_equal(again.field("displacement").space, f.space)


def test_cli_build_model_and_bad_spec(tmp_path):
    f = tmp_path / "boot.yaml"
    f.write_text(textwrap.dedent(BOOT))
    out = tmp_path / "boot.h5"
    r = subprocess.run([sys.executable, "-m", "simreal_nodes.cli", "build-model", str(f), "-o", str(out), "-q"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert out.exists() and "boot_small@" in r.stdout
    f.write_text(textwrap.dedent(BOOT).replace("theta_deg: [0, 30]", "theta_deg: [0]"))
    r = subprocess.run([sys.executable, "-m", "simreal_nodes.cli", "build-model", str(f), "-o", str(out), "-q"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "lever.theta_deg: expected a list of 2 numbers" in r.stderr
