"""The fuzz harness (benchmarks/fuzz.py) over the model-file and scene loaders: inputs reproducible from their case
number, every one accounted for, the outcomes told apart (accepted, rejected with the project's error, crash)."""

import pytest

from benchmarks import fuzz
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene.schema import load_scene


@pytest.fixture(scope="module")
def seed_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    return d, fuzz.seeds(d)


@pytest.mark.parametrize("target", fuzz.TARGETS)
def test_an_input_is_reproduced_from_its_case_number(seed_files, target, tmp_path):
    _d, files = seed_files
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = [fuzz.make_input(target, 3, i, files, tmp_path / "a") for i in range(30)]
    b = [fuzz.make_input(target, 3, i, files, tmp_path / "b") for i in range(30)]
    assert [w for _, w in a] == [w for _, w in b]
    assert all(_content(pa) == _content(pb) for (pa, _), (pb, _) in zip(a, b))
    contents = [_content(p) for p, _ in a]
    assert len(set(contents)) > 25
    seeds = {s for _, s in files[target]} if target != "bag" else {b"".join(s for _, s in files["bag"])}
    assert sum(c in seeds for c in contents) <= 2  # a mutation may hit a byte as it was


def _content(path):
    """A file's bytes; a bag folder's files' bytes in name order."""
    return b"".join(f.read_bytes() for f in sorted(path.iterdir())) if path.is_dir() else path.read_bytes()


def test_outcomes_are_told_apart(seed_files, tmp_path, monkeypatch):
    d, files = seed_files
    assert load_model(d / "seed_model.h5").name == "fuzz_beam"  # the seeds are valid
    for name, text in files["scene"]:
        assert load_scene(_write(tmp_path / f"{name}.yaml", text))["objects"], name
    short = {"model": [("short", files["model"][0][1][:1000])]}
    rec = fuzz.run_case("model", 0, 0, short, tmp_path)  # a truncated file, mutated further: never valid
    assert rec["outcome"] == "rejected" and rec["error"] == "ModelFileError" and "<file>" in rec["message"]

    def broken(target, path):
        raise KeyError(f"no such thing in {path}")

    monkeypatch.setattr(fuzz, "_load", broken)
    rec = fuzz.run_case("scene", 0, 0, files, tmp_path)
    assert rec["outcome"] == "crash" and rec["error"] == "KeyError" and rec["message"] == "'no such thing in <file>'"
    assert rec["site"].startswith("tests/test_fuzz.py:")  # where it was raised (no project line on the way)


def _write(path, content):
    path.write_bytes(content)
    return path


@pytest.mark.parametrize("target", fuzz.TARGETS)
def test_a_few_hundred_inputs_each_end_in_one_outcome(seed_files, target, tmp_path):
    recs = fuzz.run(target, 0, 200, tmp_path, hang_s=5.0)
    assert sorted(r["case"] for r in recs) == list(range(200))
    rows, messages = fuzz.summary(recs)
    total = next(r for r in rows if r["target"] == target and r["mutation"] == "all")
    # a damaged bag is read up to the damage and reported (flagged); other loaders refuse damage
    assert total["inputs"] == 200 and total["flagged" if target == "bag" else "rejected"] > 50
    assert total["accepted"] + total["flagged"] + total["rejected"] + total["crashes"] + total["hangs"] == 200
    # every damaged input is rejected with one line naming it, none crashes (found before: invalid UTF-8 in a
    # scene; KeyError / RuntimeError from h5py on corrupt object headers, int() of an odd format_version, a group
    # where a dataset belongs, text where numbers belong)
    assert total["crashes"] == 0, messages[target]["crashes"]
    # seed 0's model case 34 (a zeroed block) makes HDF5 loop for ever reading the root's attributes, inside its C
    # library: seen as a hang (the worker is killed after hang_s), left open
    assert total["hangs"] <= (1 if target == "model" else 0)
    truncated = [r for r in recs if r["mutation"] == "truncate"]
    assert truncated and all(r["outcome"] == "rejected" for r in truncated if target == "model")  # HDF5: no tail spare


@pytest.mark.parametrize("target,case", [("model", 950), ("scene", 1106), ("scene", 4227)])
def test_inputs_a_longer_run_found_crashing_are_rejected(seed_files, target, case, tmp_path):
    """From ``python -m benchmarks.fuzz --cases 5000``: format_version = inf (int() overflowed), a model path with a
    NUL character, one too long for the file system."""
    _d, files = seed_files
    rec = fuzz.run_case(target, 0, case, files, tmp_path)
    assert rec["outcome"] == "rejected", rec
