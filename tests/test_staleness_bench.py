"""benchmarks/staleness.py: which results tables are older than the code that writes them."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from benchmarks.staleness import Code, closure, default_names, find_script, host_of, quoted_by, tables


def test_code_compares_statements_not_text():
    old = 'def f(x):\n    """Doc."""\n    return x + 1  # one\n'
    same = 'def f(x):\n    """Other doc."""\n\n    return x + 1\n'
    assert Code.statements("a.py", old) == Code.statements("a.py", same)
    assert Code.statements("a.py", old) != Code.statements("a.py", "def f(x):\n    return x + 2\n")
    # a script's docs prose (INTRO) is not code; any other string constant is (specs and shaders are strings too)
    assert Code.statements("b.py", 'INTRO = "# Page\\nOld words."\nN = 3\n') == \
        Code.statements("b.py", 'INTRO = "# Page\\nNew words."\nN = 3\n')
    assert Code.statements("b.py", 'SPEC = "E: 1"\n') != Code.statements("b.py", 'SPEC = "E: 2"\n')
    assert Code.statements("b.py", 'INTRO = "a"\nN = 3\n') != Code.statements("b.py", 'INTRO = "a"\nN = 4\n')
    # family.py's section headings, (table, heading) pairs, are prose too; the same name holding anything else is code
    assert Code.statements("c.py", 'TABLES = (("t", "Old heading"),)\n') == \
        Code.statements("c.py", 'TABLES = (("t", "New " "heading"), ("u", "More"))\n')
    assert Code.statements("c.py", 'TABLES = (("t", f(1)),)\n') != Code.statements("c.py", 'TABLES = (("t", f(2)),)\n')
    assert Code.statements("c.py", 'TABLES = ("t", 1)\n') != Code.statements("c.py", 'TABLES = ("t", 2)\n')
    # other files: byte for byte
    assert Code.statements("s.yaml", "a: 1\n") != Code.statements("s.yaml", "a: 1 \n")


def _git(root: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, check=True).stdout


@pytest.fixture()
def repo(tmp_path: Path) -> Path:
    """A repository with a benchmark, the core module it imports inside a function (relatively, through a package),
    a spec it names, and three tables: the benchmark's own, one under a label, one of no known script."""
    files = {
        "benchmarks/__init__.py": "",
        "benchmarks/bench.py": ('from benchmarks.common import save\n\n\ndef main():\n'
                                '    from simreal_nodes.core import go\n'
                                '    save("bench", go("spec:beam"), "Beams under a load: error")\n'),
        "benchmarks/common.py": "def save(*a):\n    pass\n",
        "simreal_nodes/__init__.py": "",
        "simreal_nodes/core/__init__.py": "from .work import go\n",
        "simreal_nodes/core/work.py": "def go(x):\n    return x\n",
        "simreal_nodes/specs/beam.yaml": "E: 70e9\n",
        "simreal_nodes/specs/plate.yaml": "E: 1e9\n",
        "simreal_nodes/unused.py": "def unused():\n    return 0\n",
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    results = tmp_path / "benchmarks" / "results"
    results.mkdir()
    for name, title in (("bench", "Beams under a load: error"), ("bench_knob_2", "Beams under a load: error"),
                        ("orphan", "Nothing writes this")):
        (results / f"{name}.json").write_text(json.dumps({"benchmark": name, "title": title, "rows": []}))
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "add", ".")
    _git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "tables")
    return tmp_path


def _states(root: Path) -> dict[str, tuple[str, list[str]]]:
    return {t.name: (t.state, t.changed_by) for t in tables(root)}


def test_the_closure_follows_imports_in_functions_and_packages(repo: Path):
    files = {str(p.relative_to(repo)) for p in closure(repo / "benchmarks" / "bench.py", repo)}
    assert files == {"benchmarks/bench.py", "benchmarks/__init__.py", "benchmarks/common.py",
                     "simreal_nodes/__init__.py", "simreal_nodes/core/__init__.py", "simreal_nodes/core/work.py"}


def test_tables_are_current_until_their_code_changes(repo: Path):
    assert _states(repo) == {"bench": ("current", []), "bench_knob_2": ("labelled", []),
                             "orphan": ("no script", [])}
    # a docstring, a comment, a new function and a file the benchmark does not import change nothing
    (repo / "simreal_nodes/core/work.py").write_text('def go(x):\n    """Doc."""\n    return x  # same\n\n\n'
                                                      "def other():\n    return 1\n")
    (repo / "simreal_nodes/unused.py").write_text("def unused():\n    return 1\n")
    (repo / "simreal_nodes/specs/plate.yaml").write_text("E: 2e9\n")
    assert _states(repo)["bench"] == ("current", [])
    # the code it runs, or a spec it names, does
    (repo / "simreal_nodes/core/work.py").write_text("def go(x):\n    return 2 * x\n")
    (repo / "simreal_nodes/specs/beam.yaml").write_text("E: 69e9\n")
    assert _states(repo)["bench"] == ("code changed", ["simreal_nodes/core/work.py", "simreal_nodes/specs/beam.yaml"])


def test_a_recorded_commit_is_the_one_compared_against(repo: Path):
    first = _git(repo, "rev-parse", "HEAD").strip()
    (repo / "simreal_nodes/core/work.py").write_text("def go(x):\n    return 2 * x\n")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qam", "code")
    # the table rewritten (e.g. a reflowed note) after the code change, but recorded as produced at the first commit
    doc = {"benchmark": "bench", "title": "Beams under a load: error", "rows": [1],
           "machine": {"script": "benchmarks/bench.py", "commit": first}}
    (repo / "benchmarks/results/bench.json").write_text(json.dumps(doc))
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qam", "table")
    assert _states(repo)["bench"] == ("code changed", ["simreal_nodes/core/work.py"])
    # produced on uncommitted code ('+'): the commit that wrote the table stands for it
    doc["machine"]["commit"] = first + "+"
    (repo / "benchmarks/results/bench.json").write_text(json.dumps(doc))
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qam", "table again")
    assert _states(repo)["bench"] == ("current", [])


def test_default_names_and_the_script_of_a_title():
    src = ('NAME = "live"\nDEFAULT_TABLES = ("fam", "fam_plate")\n\n\ndef main(ap, a, q):\n'
           '    ap.add_argument("--out", default="mine")\n    save(NAME, [], [], "t")\n'
           '    save("reg" + q, [], [], "t")\n    save(a.out, [], [], f"Runs of {q} under a load")\n')
    assert default_names("benchmarks/x.py", src) == {"x", "live", "fam", "fam_plate", "mine", "reg"}
    sources = {"benchmarks/x.py": src, "benchmarks/y.py": "save('y', [], [], 'Something else entirely')"}
    assert find_script({"title": "Runs of 3 under a load"}, "z", sources) == "benchmarks/x.py"
    assert find_script({"title": "Nothing known"}, "y", sources) == "benchmarks/y.py"
    assert find_script({"title": "Nothing known"}, "z", sources) is None
    assert find_script({"machine": {"script": "benchmarks/y.py"}}, "z", sources) == "benchmarks/y.py"


def test_host_of_names_the_cpu_and_its_simd_level():
    assert host_of({"machine": {"cpu": "Intel(R) Xeon(R) Processor", "simd": "AVX-512"}}) == "Intel Xeon (AVX-512)"
    assert host_of({"machine": {"cpu": "AMD EPYC", "simd": None}}) == "AMD EPYC"  # tables older than the simd field
    assert host_of({"machine": {"simd": "AVX2"}}) == "AVX2"
    assert host_of({"rows": []}) == "" and host_of([]) == ""


def test_tables_carry_their_host(repo: Path):
    table = repo / "benchmarks" / "results" / "bench.json"
    doc = json.loads(table.read_text())
    doc["machine"] = {"cpu": "AMD EPYC", "simd": "AVX2"}
    table.write_text(json.dumps(doc))
    hosts = {t.name: t.host for t in tables(repo)}
    assert hosts["bench"] == "AMD EPYC (AVX2)" and hosts["orphan"] == ""


def test_a_table_lists_the_pages_that_publish_it(repo: Path):
    (repo / "docs").mkdir()
    (repo / "README.md").write_text("Beams: `bench.md` says 0.4 %.\n")
    (repo / "docs/overview.md").write_text("See benchmarks/results/bench.md and `bench_knob_2`.\n")
    (repo / "docs/status.md").write_text("bench.md and orphan.md as they stood at a stop\n")
    (repo / "docs/benchmarks.md").write_text("| `orphan` | what orphan.md measures |\n")
    quoted = {t.name: t.quoted for t in tables(repo)}
    assert quoted == {"bench": ["README.md", "docs/overview.md"], "bench_knob_2": ["docs/overview.md"], "orphan": []}
    # another table's name that contains it, a docs page of the same name, or a one-word name in backticks (a scene
    # key, a mode) is not a quote; its plot, its results path and the command that writes it are
    assert quoted_by("bench", {"a.md": "the mybench.md table", "b.md": "bench_2.md", "c.md": "`bench`",
                               "d.md": "see docs/bench.md", "e.md": "--out bench_2, ./run bench benches"}) == []
    assert quoted_by("bench", {"a.md": "![x](../benchmarks/results/bench.png)", "b.md": "`./run bench bench`",
                               "c.md": "python -m benchmarks.x --out bench)", "d.md": "bench.json"}) == \
        ["a.md", "b.md", "c.md", "d.md"]
    # a table named as a docs page: only its results path is a quote (the bare name is the page)
    pages = {"a.md": "see `bench.md` and docs/bench.md", "b.md": "benchmarks/results/bench.md"}
    assert quoted_by("bench", pages, frozenset({"bench.md"})) == ["b.md"]
    assert quoted_by("bench", pages) == ["a.md", "b.md"]
