"""The CFD database end to end on the small family: OpenFOAM meshes and solves each car (a Dask task), the file
round-trips, and Eq. 6.4 predicts a held-out car's flow. Skipped with the reason where OpenFOAM is not installed
(./run setup installs it)."""

from __future__ import annotations

import os
import shutil
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from simreal_nodes.aero.database import AeroDatabase, assemble, load_aero_spec, load_database, run_sweep
from simreal_nodes.aero.manifold import ShapeManifold
from simreal_nodes.aero.openfoam import CfdError, openfoam_available
from simreal_nodes.errors import ModelFileError
from simreal_nodes.rom.model_file import stamp_checksum

pytestmark = pytest.mark.skipif(not openfoam_available(), reason="OpenFOAM is not installed (./run setup installs "
                                "Debian's openfoam)")


@pytest.fixture(scope="module")
def built(small_aero_db) -> tuple[Path, Path, AeroDatabase]:
    root, out, lines = small_aero_db  # tests/conftest.py: the small family solved once per session
    assert len(lines) == 10 and not any("FAILED" in line for line in lines), lines
    return root, out, load_database(out)


def test_every_car_is_solved_and_physically_sound(built) -> None:
    _, _, db = built
    assert len(db.cars) == 10 and db.held_out.sum() == 2
    assert db.converged.all()
    assert np.all((db.cd > 0.25) & (db.cd < 0.8)), db.cd  # bluff road vehicles
    x = db.grid.axes()[0]
    pts = db.grid.points()
    upstream = pts[:, 0] < x[0] + 1.0
    for i in range(len(db.cars)):
        v = db.velocity[i]
        assert np.allclose(v[upstream], [10.0, 0.0, 0.0], atol=0.4)  # the inflow, a body length upstream
        inside = db.presence[i] > 0
        solid = inside & ~db.in_fluid[i]
        assert solid.sum() > 0.9 * inside.sum()
        assert np.abs(v[solid]).max() < 1e-3  # no velocity where the mesh has no cell (stored through the POD)
        # the mesh's fluid and the presence function agree but for points within a cell of the surface
        assert np.mean(db.in_fluid[i] == ~inside) > 0.99


def test_eq_6_4_predicts_a_held_out_car_better_than_the_database_mean(built) -> None:
    _, _, db = built
    man = ShapeManifold(db.presence[db.database], n_neighbors=3)
    V = db.velocity[db.database]
    h = next(i for i in db.held if db.cars[i].group == "sport")
    fluid = db.presence[h] == 0
    nb = man.place(db.presence[h])
    v = ShapeManifold.interpolate(V, nb)
    err = np.linalg.norm((v - db.velocity[h])[fluid]) / np.linalg.norm(db.velocity[h][fluid])
    err_mean = np.linalg.norm((V.mean(0) - db.velocity[h])[fluid]) / np.linalg.norm(db.velocity[h][fluid])
    assert {db.cars[i].group for i in nb.indices[:2]} == {"sport"}
    assert err < 0.03 and err < 0.5 * err_mean, (err, err_mean)


def test_the_sweep_resumes_and_a_damaged_file_is_refused(built, tmp_path) -> None:
    root, out, _ = built
    spec = load_aero_spec("aero_cars_small.yaml")
    work = tmp_path / "work"
    shutil.copytree(root / "work", work)
    stamps = {p.name: p.stat().st_mtime_ns for p in work.glob("*.npz")}
    run_sweep(spec, work, jobs=1)
    assert {p.name: p.stat().st_mtime_ns for p in work.glob("*.npz")} == stamps  # nothing re-solved
    # a result of other settings is not this spec's: assembling refuses it (the sweep would solve it again)
    other = replace(spec, cfd=replace(spec.cfd, iterations=spec.cfd.iterations + 1))
    with pytest.raises(CfdError, match="no CFD result for this spec"):
        assemble(other, work, tmp_path / "other.h5")
    os.remove(work / "old_00.npz")
    with pytest.raises(CfdError, match="no CFD result"):
        assemble(spec, work, tmp_path / "db.h5")
    # a flipped byte, a file without the checksum block, a dataset of the wrong shape (checksum re-stamped)
    data = bytearray(out.read_bytes())
    data[len(data) // 2] ^= 0xFF
    (tmp_path / "bad.h5").write_bytes(bytes(data))
    with pytest.raises(ModelFileError):
        load_database(tmp_path / "bad.h5")
    with h5py.File(out, "r") as src, h5py.File(tmp_path / "plain.h5", "w") as dst:
        for k, v in src.attrs.items():
            dst.attrs[k] = v
    with pytest.raises(ModelFileError, match="no checksum"):
        load_database(tmp_path / "plain.h5")
    shaped = tmp_path / "shaped.h5"
    shutil.copy(out, shaped)
    with h5py.File(shaped, "r+") as f:
        del f["cd"]
        f.create_dataset("cd", data=np.zeros(3))
    stamp_checksum(shaped)
    with pytest.raises(ModelFileError, match="cd has shape"):
        load_database(shaped)
    (tmp_path / "spec.yaml").write_text("name: x\ncfd: {speed: 10, warp: 9}\n")
    with pytest.raises(ValueError, match="unknown cfd keys"):
        load_aero_spec(tmp_path / "spec.yaml")
    (tmp_path / "spec.yaml").write_text("name: x\ncars: {seed: 3}\nheld_out: {seed: 3, groups: [sport]}\n")
    with pytest.raises(ValueError, match="held-out cars would be database cars"):
        load_aero_spec(tmp_path / "spec.yaml")
    (tmp_path / "spec.yaml").write_text("name: x\ngrid: {lo: [-30, 0, 0]}\n")
    with pytest.raises(ValueError, match="inside the CFD domain"):
        load_aero_spec(tmp_path / "spec.yaml")
