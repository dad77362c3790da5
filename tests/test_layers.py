"""The package's import structure: no import cycle between modules, and no arrow from a lower layer to a higher one.

Every ``import`` in every module of simreal_nodes counts, also those inside functions (a lazy import is still a
dependency: the rom <-> scene cycle this test was written against was one), read with ``ast`` so that nothing is
imported. A module's layer is that of its top-level name under simreal_nodes (``simreal_nodes.rom.build`` ->
``rom``); a module may import modules of its own layer or lower ones.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "simreal_nodes"
PKG = "simreal_nodes"

# Lowest first. Placement of the modules the issue left open, from what they import:
# - io (bags, images, cdr, sources) reads and writes data with errors / geometry only: layer 1, beside physics.
# - metrics and sync are plain data structures (no simreal import): ground floor.
# - launch is the process supervisor: it turns scene.graph's node list into processes (python -m, modules from
#   pyproject's [project.scripts]) and never imports a node, so it sits right above scene.
# - ros holds the rclpy adapters: the nodes (processes nobody imports), their common base, and the player /
#   recorder behind `simreal replay` / `record` (ros.commands), which start the graph through launch: above launch.
# - demo and cli are the user's entry points; they run replay / record (ros.commands, imported lazily so that
#   `simreal --help` needs no rclpy), so they sit on top of ros.
# - studies (thesis reproductions, e.g. chapter 3) use the core but nothing may depend on them: the very top.
LAYERS: list[set[str]] = [
    {"__init__", "errors", "geometry", "camera", "spec", "states", "sync", "metrics", "lifetime"},
    {"physics", "io"},
    {"rom", "vision"},
    {"assimilation", "collision", "render", "aero"},
    {"synth", "scene"},
    {"launch"},
    {"ros"},
    {"demo", "cli"},
    {"studies"},
]
LAYER = {name: i for i, names in enumerate(LAYERS) for name in names}
ROS_IFACE = ("_msgs", "_srvs", "_interfaces")  # rosidl interface packages (sensor_msgs, std_srvs, rcl_interfaces)

# Known cycles, each to be removed by the branch named with it; the test fails once one is gone, so that the
# entry is dropped with the fix.
KNOWN_CYCLES: dict[frozenset[str], str] = {}  # cycles tolerated while a branch removes them (none now)


def _module_name(path: Path, base: Path) -> str:
    rel = path.relative_to(base).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _modules(root: Path = ROOT) -> dict[str, Path]:
    return {_module_name(p, root.parent): p for p in sorted(root.rglob("*.py"))}


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The simreal_nodes modules that ``name`` imports (anywhere in its body)."""
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolved against the importing module's package
                pkg = name.split(".") if is_pkg else name.split(".")[:-1]
                pkg = pkg[: len(pkg) - (node.level - 1)]
                base = ".".join(pkg + ([base] if base else []))
            # `from pkg import mod` imports the module pkg.mod; `from mod import name` the module mod
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in modules:  # `import a.b.c` where only a.b is ours, or a third-party name
                t = t.rpartition(".")[0]
            if t.split(".")[0] == PKG and t != name:
                out.add(t)
    return out


def _graph(root: Path = ROOT) -> dict[str, set[str]]:
    modules = _modules(root)
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _top(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _cycles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[frozenset[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = set()
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.add(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(frozenset(comp))
    return out


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return _graph()


def test_every_top_level_name_has_a_layer(graph):
    missing = sorted({_top(m) for m in graph} - LAYER.keys())
    assert not missing, f"add these to LAYERS in {Path(__file__).name}: {missing}"


def test_no_import_cycle_between_modules(graph):
    cycles = _cycles(graph)
    new = [sorted(c) for c in cycles if c not in KNOWN_CYCLES]
    assert not new, f"import cycles: {new}"
    gone = [f"{sorted(c)} ({branch})" for c, branch in KNOWN_CYCLES.items() if c not in cycles]
    assert not gone, f"these known cycles are gone: drop them from KNOWN_CYCLES: {gone}"


def test_no_import_cycle_between_top_level_packages(graph):
    """Same-layer packages may import each other's modules, but not both ways (e.g. rom and vision)."""
    packages: dict[str, set[str]] = {}
    for m, deps in graph.items():
        packages.setdefault(_top(m), set()).update(_top(d) for d in deps if _top(d) != _top(m))
    assert not _cycles(packages), f"cycles between packages: {[sorted(c) for c in _cycles(packages)]}"


def test_only_ros_imports_rclpy_and_ros_interfaces():
    """The numerical core and the CLI run without a ROS graph: rclpy and message packages stay inside ros (the CLI
    reaches them only through ros.commands, lazily)."""
    bad = []
    for name, path in _modules().items():
        if _top(name) == "ros":
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or ""]
            else:
                continue
            tops = [n.split(".")[0] for n in names]
            bad += [f"{name}: {t}" for t in tops if t == "rclpy" or t.endswith(ROS_IFACE)]
    assert not bad, f"ROS imports outside simreal_nodes.ros: {bad}"


def test_no_import_from_a_lower_layer_to_a_higher_one(graph):
    bad = sorted(f"{m} (layer {LAYER[_top(m)]}) imports {d} (layer {LAYER[_top(d)]})"
                 for m, deps in graph.items() for d in deps
                 if _top(m) in LAYER and _top(d) in LAYER and LAYER[_top(d)] > LAYER[_top(m)])
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_the_checker_sees_lazy_relative_and_package_imports(tmp_path):
    """The parser itself: imports inside functions, relative imports and `from package import module` all count."""
    pkg = tmp_path / PKG / "sub"
    pkg.mkdir(parents=True)
    (tmp_path / PKG / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from . import b\n")
    (pkg / "b.py").write_text("from simreal_nodes.sub.c import x\n")
    (pkg / "c.py").write_text("import numpy\nfrom simreal_nodes.sub import a\nx = 1\n")
    g = _graph(tmp_path / PKG)
    assert g["simreal_nodes.sub.a"] == {"simreal_nodes.sub.b"}
    assert g["simreal_nodes.sub.b"] == {"simreal_nodes.sub.c"}
    assert g["simreal_nodes.sub.c"] == {"simreal_nodes.sub.a"}
    assert _cycles(g) == [frozenset({"simreal_nodes.sub.a", "simreal_nodes.sub.b", "simreal_nodes.sub.c"})]

