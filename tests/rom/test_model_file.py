"""Build -> save -> load -> evaluate round trip; damaged or foreign files are rejected clearly."""

import shutil
import textwrap

import h5py
import numpy as np
import pytest

from simreal_nodes.errors import ModelFileError
from simreal_nodes.rom.build import build_model, load_spec
from simreal_nodes.rom.model_file import load_model, read_header, save_model, stamp_checksum

SPEC = """
simreal_model_spec: 1
name: tiny_beam
kind: beam_pgd
material: {law: linear_elastic, E: 69.0e9, nu: 0.334}
geometry: {length: 0.3, width: 0.04, height: 0.01}
mesh: {cells: [15, 2, 1], element: hex, order: 2}
supports: [{region: xmin}]
load: {force: 10.0, where: centreline}
pgd: {max_modes: 10, tol: 1.0e-7}
validation_every: 2
"""


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    d = tmp_path_factory.mktemp("model")
    spec_file = d / "tiny.yaml"
    spec_file.write_text(textwrap.dedent(SPEC))
    model = build_model(load_spec(spec_file))
    path = d / "tiny.h5"
    save_model(model, path)
    return model, path


def test_round_trip_evaluates_identically(built):
    model, path = built
    back = load_model(path)
    assert back.model_id == model.model_id and back.model_id.startswith("tiny_beam@")
    for mu in ([0.0], [0.1234], [0.3]):
        np.testing.assert_allclose(back.displacement(mu), model.displacement(mu), rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(back.field("stress").evaluate(mu), model.field("stress").evaluate(mu),
                                   rtol=1e-12, atol=1e-6)
    assert back.surface.shape == model.surface.shape and back.cell_type == "hex8"
    assert back.material["E"] == 69e9 and "spec" in back.provenance
    err = back.field("displacement").error_vs_modes
    assert err[0] > err[-1] and err[-1] < 1e-3  # error versus modes is stored and falls


def test_error_against_fem_at_an_off_grid_load(built):
    """Between two load nodes the model (cubic in s) stays close to the FEM with a consistent load."""
    model, _ = built
    from simreal_nodes.physics import fem, materials, meshes
    m = meshes.box(0.3, 0.04, 0.01, (15, 2, 1), "hex")
    s = fem.Solid(m, materials.LinearElastic(69e9, 0.334), 2, [{"region": "xmin"}])
    a = s.nearest_vertex([0.14, 0.02, 0.01])
    b = s.nearest_vertex([0.16, 0.02, 0.01])
    f = np.zeros(s.N)
    f[s.vertex_dofs(a)[2]] -= 5.0  # 10 N at x = 0.15: half on each neighbour (linear interpolation)
    f[s.vertex_dofs(b)[2]] -= 5.0
    ref = s.vertex_displacement(s.solve_linear(f))
    got = model.displacement([0.15])
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) < 0.02


def test_partial_loading(built):
    _, path = built
    m = load_model(path, fields=["displacement"], n_modes=3)
    assert list(m.fields) == ["displacement"] and m.field("displacement").n_modes == 3
    with pytest.raises(ModelFileError, match="10 modes; 40 were requested"):
        load_model(path, n_modes=40)
    with pytest.raises(ModelFileError, match="no field 'pressure'"):
        load_model(path, fields=["pressure"])
    h = read_header(path)
    assert h["axes"][0]["name"] == "s" and h["n_modes"]["displacement"] == 10


def test_damaged_and_foreign_files_are_rejected(built, tmp_path):
    _, path = built
    trunc = tmp_path / "trunc.h5"
    trunc.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(ModelFileError, match="corrupt, truncated"):
        load_model(trunc)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00" * 500)
    with pytest.raises(ModelFileError):
        load_model(junk)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = 1
    with pytest.raises(ModelFileError, match="not a simreal model file"):
        load_model(other)
    broken = tmp_path / "broken.h5"
    shutil.copy(path, broken)
    with h5py.File(broken, "a") as f:
        del f["fields/displacement/params/s"]
    stamp_checksum(broken)  # a writer's bug, not corruption: the file is consistent with its checksum
    with pytest.raises(ModelFileError, match="missing 'params/s'"):
        load_model(broken)
    newer = tmp_path / "newer.h5"
    shutil.copy(path, newer)
    with h5py.File(newer, "a") as f:
        f.attrs["format_version"] = 99
    stamp_checksum(newer)
    with pytest.raises(ModelFileError, match="version 99"):
        load_model(newer)
    nan = tmp_path / "nan.h5"
    shutil.copy(path, nan)
    with h5py.File(nan, "a") as f:
        f["fields/displacement/space"][0, 0, 0] = np.nan
    stamp_checksum(nan)
    with pytest.raises(ModelFileError, match="NaN"):
        load_model(nan)
    with pytest.raises(ModelFileError, match="not found"):
        load_model(tmp_path / "absent.h5")


def test_a_bit_flip_in_stored_numbers_is_caught_by_the_checksum(built, tmp_path):
    """One byte changed inside a dataset's stored chunk (a disk or copy error the HDF5 structure does not notice)
    is a clear error, never a silently wrong mode."""
    _, path = built
    for name in ("fields/displacement/params/s", "fields/displacement/space", "mesh/points"):
        flipped = tmp_path / f"flip_{name.replace('/', '_')}.h5"
        shutil.copy(path, flipped)
        with h5py.File(flipped, "r") as f:
            ds = f[name]
            assert ds.fletcher32
            chunk = ds.id.get_chunk_info(0)
            at = chunk.byte_offset + chunk.size // 2
        raw = bytearray(flipped.read_bytes())
        raw[at] ^= 0x10
        flipped.write_bytes(bytes(raw))
        with pytest.raises(ModelFileError, match="do not match the SHA-256"):  # the whole file's checksum first
            load_model(flipped)
        stamp_checksum(flipped)  # the same flip before the file was stamped: the chunk's Fletcher-32 catches it
        with pytest.raises(ModelFileError, match=f"cannot read '/{name}'"):
            load_model(flipped)


def test_a_zeroed_block_is_refused_before_hdf5_reads_it(built, tmp_path):
    """Zeroed metadata blocks made libhdf5 loop (21 hangs in 5 000 fuzzed files, benchmarks/fuzz.py): the SHA-256
    in the user block is checked before a byte reaches the library. A damaged user block is refused too."""
    import time

    _, path = built
    raw = bytearray(path.read_bytes())
    assert raw.startswith(b"simreal-model sha256 ")
    for start in (600, 2048, len(raw) // 2):
        z = tmp_path / f"zero_{start}.h5"
        bad = bytearray(raw)
        bad[start:start + 512] = b"\0" * 512
        z.write_bytes(bytes(bad))
        t0 = time.perf_counter()
        with pytest.raises(ModelFileError, match="do not match the SHA-256"):
            load_model(z)
        assert time.perf_counter() - t0 < 2.0
    head = tmp_path / "head.h5"
    bad = bytearray(raw)
    bad[0:8] = b"\0" * 8
    head.write_bytes(bytes(bad))
    with pytest.raises(ModelFileError, match="checksum block is damaged"):
        load_model(head)


def test_a_file_written_before_the_checksum_block_still_loads(built, tmp_path, monkeypatch):
    from simreal_nodes.rom import model_file

    m, _ = built
    monkeypatch.setattr(model_file, "USERBLOCK", 0)
    monkeypatch.setattr(model_file, "stamp_checksum", lambda p: None)
    old = tmp_path / "old.h5"
    save_model(m, old)
    monkeypatch.undo()
    assert old.read_bytes().startswith(b"\x89HDF")
    assert not model_file.verify_checksum(old)
    assert load_model(old).n_nodes == m.n_nodes


def test_an_absurd_declared_size_is_refused_before_allocating(built, tmp_path):
    """A header that declares 3 GiB of mode values the file does not hold (HDF5 would fill them in)."""
    import time
    import tracemalloc

    _, path = built
    huge = tmp_path / "huge.h5"
    shutil.copy(path, huge)
    with h5py.File(huge, "a") as f:
        del f["fields/displacement/space"]
        f.create_dataset("fields/displacement/space", shape=(2**26, 2, 3), dtype=np.float64, chunks=(1, 2, 3))
    stamp_checksum(huge)
    tracemalloc.start()
    t0 = time.perf_counter()
    with pytest.raises(ModelFileError, match=r"'/fields/displacement/space' declares shape \(67108864, 2, 3\) "
                                             r"\(3.0 GiB\) but the file stores 0 bytes of it"):
        load_model(huge)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 50e6 and time.perf_counter() - t0 < 5.0


def test_spec_errors_name_the_key(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text(SPEC.replace("nu: 0.334", "nu: 0.7"))
    from simreal_nodes.errors import SceneError
    with pytest.raises(SceneError, match=r"material.nu: expected a number in \[-0.999, 0.4999\]; found 0.7"):
        load_spec(f)
    f.write_text(SPEC.replace("kind: beam_pgd", "kind: beem"))
    with pytest.raises(SceneError, match="kind: expected one of"):
        load_spec(f)
