"""The model cache is keyed on the builders' code as well as the spec: a model built by other code is rebuilt."""

import shutil
import textwrap
from pathlib import Path

import pytest

from simreal_nodes.rom import build
from simreal_nodes.rom.build import cached_model, source_digest
from simreal_nodes.rom.model_file import load_model

TINY = """
simreal_model_spec: 1
name: tiny_beam
kind: beam_pgd
material: {law: linear_elastic, E: 69.0e9, nu: 0.334}
geometry: {length: 0.2, width: 0.02, height: 0.01}
mesh: {cells: [6, 1, 1], element: hex, order: 1}
supports:
  - {region: xmin, kind: clamped}
load: {force: 10.0, direction: [0, 0, -1], where: centreline, x_range: [0.0, 0.2]}
pgd: {max_modes: 3, tol: 1.0e-6}
"""


def _package(root, b_body):
    (root / "pkg").mkdir(exist_ok=True)
    (root / "pkg" / "__init__.py").write_text("")
    (root / "pkg" / "a.py").write_text("def f():\n    from pkg import b\n    return b.g()\n")
    (root / "pkg" / "b.py").write_text(textwrap.dedent(b_body))
    (root / "pkg" / "unused.py").write_text("X = 1\n")
    return source_digest(root, "pkg.a")


def test_source_digest_follows_code_not_prose(tmp_path):
    ref = _package(tmp_path, 'def g():\n    return 1\n')
    # a lazily imported module's docstring, comments and layout do not count
    assert _package(tmp_path, '"""Module."""\n\n\ndef g():  # one\n    """Why."""\n    return (1)\n') == ref
    (tmp_path / "pkg" / "unused.py").write_text("X = 2\n")  # not imported by pkg.a
    assert _package(tmp_path, 'def g():\n    return 1\n') == ref
    assert _package(tmp_path, 'def g():\n    return 2\n') != ref  # its code does


def test_builder_version_covers_the_fem_and_pgd_code(tmp_path):
    assert build.builder_version() == source_digest(build.REPO, "simreal_nodes.rom.build")
    # a copy of the package's code: the digest moves with a code change in each module the builders use, and with
    # nothing else (a docstring there; code in a module they do not import)
    shutil.copytree(build.REPO / "simreal_nodes", tmp_path / "simreal_nodes",
                    ignore=lambda d, names: [n for n in names if not (n.endswith(".py") or (Path(d) / n).is_dir())])
    ref = source_digest(tmp_path, "simreal_nodes.rom.build")
    assert ref == build.builder_version()
    for rel in ("rom/pgd.py", "rom/nipgd.py", "rom/separated.py", "physics/fem.py", "physics/materials.py",
                "physics/meshes.py"):
        f = tmp_path / "simreal_nodes" / rel
        text = f.read_text()
        f.write_text(text + "\n_PROBE = 1\n")
        assert source_digest(tmp_path, "simreal_nodes.rom.build") != ref, rel
        f.write_text(text)
    pgd = tmp_path / "simreal_nodes" / "rom" / "pgd.py"
    text = pgd.read_text()
    pgd.write_text(text + "\n\ndef _probe():\n    \"\"\"Prose only.\"\"\"\n")
    changed = source_digest(tmp_path, "simreal_nodes.rom.build")
    pgd.write_text(text + "\n\ndef _probe():\n    \"\"\"Other prose.\"\"\"\n")
    assert source_digest(tmp_path, "simreal_nodes.rom.build") == changed  # a docstring does not count
    pgd.write_text(text)
    node = tmp_path / "simreal_nodes" / "ros" / "node.py"
    node.write_text(node.read_text() + "\n_PROBE = 1\n")
    assert source_digest(tmp_path, "simreal_nodes.rom.build") == ref  # not the builders' code


def test_cached_model_is_rebuilt_when_the_builder_changes(tmp_path, monkeypatch):
    monkeypatch.setenv("SIMREAL_CACHE", str(tmp_path / "cache"))
    spec = tmp_path / "tiny_beam.yaml"
    spec.write_text(TINY)
    builds = []
    real_build = build.build_model
    monkeypatch.setattr(build, "build_model", lambda *a: builds.append(1) or real_build(*a))
    out = cached_model(str(spec))
    assert out == tmp_path / "cache" / "models" / "tiny_beam.h5" and len(builds) == 1
    assert load_model(out, fields=[], mesh=False).provenance["builder"] == build.builder_version()
    assert cached_model(str(spec)) == out and len(builds) == 1  # same spec, same code: the cached file
    monkeypatch.setattr(build, "builder_version", lambda: "changed-code")
    assert cached_model(str(spec)) == out and len(builds) == 2
    assert load_model(out, fields=[], mesh=False).provenance["builder"] == "changed-code"
    assert cached_model(str(spec)) == out and len(builds) == 2
    spec.write_text(TINY.replace("force: 10.0", "force: 12.0"))
    assert cached_model(str(spec)) == out and len(builds) == 3  # the spec's text, as before


@pytest.mark.parametrize("damage", [b"", b"not hdf5"])
def test_a_damaged_cache_entry_is_rebuilt(tmp_path, monkeypatch, damage):
    monkeypatch.setenv("SIMREAL_CACHE", str(tmp_path / "cache"))
    spec = tmp_path / "tiny_beam.yaml"
    spec.write_text(TINY)
    out = cached_model(str(spec))
    out.write_bytes(damage)
    assert cached_model(str(spec)) == out
    assert load_model(out, fields=[], mesh=False).provenance["builder"] == build.builder_version()
