"""The lint gate's configuration (pyproject.toml) says what it claims to say."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _strict_override() -> dict[str, object]:
    mypy = CONFIG["tool"]["mypy"]
    return next(o for o in mypy["overrides"] if "simreal_nodes.rom.*" in o["module"])


def test_strict_override_spells_out_every_strict_flag():
    """mypy applies `strict = true` in an override to every module (mypy issue #11401), so the override lists
    the flags one by one; when a mypy update adds a flag to --strict, this test names it."""
    mypy_main = pytest.importorskip("mypy.main", reason="mypy is installed by ./run setup")
    _, _, assignments = mypy_main.define_options()
    override = _strict_override()
    global_only = {"warn_redundant_casts"}  # not a per-module option: set in [tool.mypy]
    missing = {k: v for k, v in assignments if k not in global_only and override.get(k) != v}
    assert not missing, f"add to the strict override in pyproject.toml: {missing}"
    assert all(CONFIG["tool"]["mypy"].get(k) is True for k in global_only)


def test_package_ships_its_type_marker():
    assert (ROOT / "simreal_nodes" / "py.typed").is_file()
    assert "py.typed" in CONFIG["tool"]["setuptools"]["package-data"]["simreal_nodes"]
