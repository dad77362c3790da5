"""The benchmark harness: its record of the machine (the vector instruction set a result was computed with) and
the pairs that the A/B benchmarks summarize."""

import os
from pathlib import Path

import pytest

from benchmarks.common import checkout_notes, pair_changes, pair_ratios, simd_level


@pytest.mark.parametrize(("flags", "level"), [
    ("fpu sse sse2 sse4_1 sse4_2 avx avx2 fma avx512f avx512dq avx512bw", "AVX-512"),
    ("fpu sse sse2 sse4_1 sse4_2 avx avx2 fma", "AVX2"),
    ("fpu sse sse2 sse4_1 sse4_2", "SSE4.2"),
    ("fp asimd evtstrm aes pmull sha1", "NEON"),
    ("fpu vme de", "none known"),
])
def test_the_widest_instruction_set_is_named(flags, level):
    assert simd_level(flags.split()) == level


def test_a_flag_that_only_starts_like_avx512_does_not_count():
    # avx512_bf16 and friends come with avx512f on every real CPU; alone they must not read as AVX-512
    assert simd_level(["avx2", "avx512_bf16"]) == "AVX2"


def test_pairs_are_matched_by_position_and_read_second_over_first():
    first = [{"ms": 10.0}, {"ms": 20.0}, {"ms": 40.0}]
    second = [{"ms": 5.0}, {"ms": 30.0}]  # the third run has no partner: left out
    assert pair_ratios(first, second, "ms") == [0.5, 1.5]
    assert pair_changes(first, second, "ms") == pytest.approx([-50.0, 50.0])


def test_checkout_notes_give_each_checkouts_median_and_the_pairs_ratios():
    this, other = "this checkout (abc1234)", "other (def5678)"
    rows = [{"seed": 0, "rep": 0, "code": this, "ms": 50.0}, {"seed": 0, "rep": 0, "code": other, "ms": 100.0},
            {"seed": 0, "rep": 1, "code": other, "ms": 80.0}, {"seed": 0, "rep": 1, "code": this, "ms": 60.0},
            {"seed": 3, "rep": 0, "code": this, "ms": 90.0}]  # its partner never ran: no pair
    text = checkout_notes(rows, [("ms", "the time")])
    assert f"{this} 60 ms; {other} 90 ms" in text
    assert "median 0.62 (from 0.50 to 0.75, 2 pairs)" in text
    assert "Pairs'" not in checkout_notes([r for r in rows if r["code"] == this], [("ms", "the time")])


def test_a_report_rewritten_from_a_saved_run_keeps_the_runs_machine(tmp_path, monkeypatch):
    import json

    from benchmarks import common

    monkeypatch.setattr(common, "RESULTS", tmp_path)
    assert common.saved_machine("nothing") == {}
    run_machine = {"python": "3.11", "cpus": 2, "date": "2026-01-01 00:00:00", "cpu_probe_ms": 16.0, "cpu": "x"}
    common.save("b", [{"v": 1}], [("v", "v", "{}")], "t", extra={"machine": run_machine})
    assert common.saved_machine("b") == {"machine": run_machine}
    common.save("b", [{"v": 2}], [("v", "v", "{}")], "t", extra=common.saved_machine("b"))  # the rewrite
    assert json.loads((tmp_path / "b.json").read_text())["machine"] == run_machine
    assert "2026-01-01 00:00:00; CPU probe 16 ms" in (tmp_path / "b.md").read_text()
    common.save("b", [{"v": 3}], [("v", "v", "{}")], "t")  # a new run: this machine, now
    assert json.loads((tmp_path / "b.json").read_text())["machine"]["date"] != run_machine["date"]


FOREIGN_ALLOCATOR = "LD_PRELOAD" in os.environ or "PYTHONMALLOC" in os.environ  # jemalloc, tcmalloc, malloc-only


@pytest.mark.skipif(FOREIGN_ALLOCATOR, reason="another allocator than glibc's malloc and Python's is in use")
def test_process_memory_sees_an_allocation_in_the_native_heap():
    import numpy as np

    from benchmarks.common import process_memory

    before = process_memory()
    assert before["rss"] > 0 and before["py_blocks"] > 0
    if not np.isfinite(before["malloc_used"]):
        pytest.skip("glibc's mallinfo2 is not available here")
    held = np.ones(8 * 2 ** 20, np.uint8)  # 8 MB from the native heap (numpy allocates with malloc)
    after = process_memory()
    assert after["malloc_used"] - before["malloc_used"] == pytest.approx(8, abs=1)
    del held
    assert process_memory()["malloc_used"] < after["malloc_used"] - 7


def test_growth_per_1000_is_the_fitted_slope():
    from benchmarks.common import growth_per_1000

    assert growth_per_1000([0, 500, 1000, 1500], [10.0, 10.5, 11.0, 11.5]) == pytest.approx(1.0)
    assert growth_per_1000([0, 500, float("nan"), 1500], [10.0, 10.0, 99.0, 10.0]) == pytest.approx(0.0)
    assert growth_per_1000([0, 500], [1.0, 2.0]) != growth_per_1000([0, 500], [1.0, 2.0])  # NaN: too few points


@pytest.mark.skipif(FOREIGN_ALLOCATOR, reason="another allocator than glibc's malloc and Python's is in use")
def test_malloc_trim_returns_what_the_heap_held_free():
    import numpy as np

    from benchmarks.common import malloc_trim, process_memory

    if not np.isfinite(process_memory()["malloc_free"]):
        pytest.skip("glibc's malloc is not this process's allocator")
    blocks = [bytes(2000) + bytes([i % 256]) for i in range(40_000)]  # 80 MB of malloc'd blocks, brk-heap sized
    keep = blocks[-1]  # the heap's top stays in use: only a trim (not free) can hand the rest back
    del blocks
    before = process_memory()
    assert before["malloc_free"] > 60
    assert malloc_trim()
    after = process_memory()
    assert before["rss"] - after["rss"] > 40
    assert after["malloc_used"] == pytest.approx(before["malloc_used"], abs=1)
    del keep


def test_every_benchmark_is_described_in_docs_benchmarks_md():
    """`docs/benchmarks.md` says what each benchmark measures: every `benchmarks/NAME.py` that `./run bench` lists is
    named there (a new benchmark without a line fails here)."""
    root = Path(__file__).resolve().parents[1]
    doc = (root / "docs" / "benchmarks.md").read_text()
    listed = sorted(p.stem for p in (root / "benchmarks").glob("*.py")
                    if p.stem not in ("common", "__init__", "orb_vocabulary"))
    assert len(listed) > 50
    missing = [n for n in listed if f"`{n}`" not in doc]
    assert not missing, missing


def _figures_of(text: str, rows_with: set[str]) -> set[str]:
    """Every figure with a unit (%, mm, deg) in a results table's summary (its text outside the rows and the machine
    line: a figure that only some row holds is one scene's), and every number in the rows that name one of
    ``rows_with`` (a resolution the page names); each also rounded half up to fewer decimals (0.176 as 0.18)."""
    import re
    from decimal import ROUND_HALF_UP, Decimal

    lines = text.splitlines()
    summary = " ".join(x for x in lines if not x.lstrip().startswith(("|", "Machine:")))
    rows = " ".join(x for x in lines if x.lstrip().startswith("|") and any(f"| {w} |" in x for w in rows_with))
    found = re.findall(r"(?<![\d.])(\d+(?:\.\d+)?) ?(?:%|mm\b|deg)", summary)
    found += re.findall(r"(?<![\d.])\d+(?:\.\d+)?(?!\d)", rows)
    out = set()
    for x in found:
        out.add(x)
        for k in range(len(x.partition(".")[2])):
            out.add(str(Decimal(x).quantize(Decimal(1).scaleb(-k), rounding=ROUND_HALF_UP)))
    return out


def test_the_readme_quotes_its_headline_figures_from_the_tables_it_names():
    """The README's "How well it works": each bullet that quotes a figure (a percentage or millimetres; not the
    thesis's own, in "(the thesis: ...)") names the results table it comes from, and the figure is in that table's
    summary, or in its rows at the resolution the bullet names, to the decimals quoted. A rerun that moves a number
    fails here until the README says the new one (issue 20: published numbers regenerate)."""
    import re

    root = Path(__file__).resolve().parents[1]
    results = root / "benchmarks" / "results"
    readme = (root / "README.md").read_text()
    assert "## How well it works" in readme
    section = readme.split("## How well it works", 1)[1].split("\n## ", 1)[0]
    quoted = 0
    for bullet in re.split(r"\n(?=- )", section):
        tables: list[str] = []
        for sentence in re.split(r"(?<=[.:])\s+(?=\*\*|[A-Z])", bullet):  # a sentence reads the tables named in
            tables += [n for n in re.findall(r"`([a-z0-9_]+)\.md`", sentence)  # it and before it in its bullet
                       if (results / f"{n}.md").is_file()]
            figures = re.findall(r"(?<![\w.])(\d+(?:\.\d+)?) ?(?:%|mm\b)",
                                 re.sub(r"\(the thesis:[^)]*\)", "", sentence))
            if not figures:
                continue
            assert tables, f"{figures} quoted but no table in benchmarks/results named: {sentence[:80]!r}"
            resolutions = set(re.findall(r"\d+x\d+", sentence))
            written = _figures_of(" ".join((results / f"{n}.md").read_text() for n in tables), resolutions)
            missing = [f for f in figures if f not in written]
            assert not missing, f"{missing} quoted from {tables} but not in them: {sentence[:80]!r}"
            quoted += len(figures)
    assert quoted >= 15  # the section quotes the beam, plate, boot, foam and camera figures
