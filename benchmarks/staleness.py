"""Which published tables are older than the code that produces them (issue 20: every published number regenerates).

    python -m benchmarks.staleness              # every table in benchmarks/results, by state
    python -m benchmarks.staleness --stale      # only the default tables whose code changed since they were written
    python -m benchmarks.staleness --json       # the same as JSON

Per table (``results/<name>.json``):

- the script that wrote it: recorded in the table by :func:`benchmarks.common.save` (``machine.script``, since stop
  108); for older tables the one script whose source holds the table's title (up to its first formatted field) as a
  string, else ``<name>.py``;
- the commit it was written at: recorded (``machine.commit``, where the checkout was clean), else the last commit
  that changed the table's JSON (git);
- the script's code: the files it imports, transitively, within this repository (``benchmarks``, ``simreal_nodes``,
  ``simreal_msgs_py``; every import statement anywhere in a file, so imports inside functions count, with the
  packages' ``__init__`` modules), and the packages' data files (model specs, the DDS profile) that one of those
  files names;
- the state: ``current`` (none of those files differs as code from the table's commit: :class:`Code`, top-level
  statements compared by syntax tree less docstrings and a script's docs prose (``INTRO``, ``TABLES``), new
  definitions not counted, other files byte for byte),
  ``code changed`` (the files that differ: the table may no longer be what the code gives and is rerun to tell),
  ``labelled`` (a name the script does not write by default, :func:`default_names`: a run kept under a label, a
  knob's development sweep or a stop's record, quoted in the docs as such and not expected to follow the code) or
  ``no script``.

The check is conservative: a change anywhere in the imported code marks the table, whether or not it moves a number;
a rerun that gives the same numbers shows it did not. Library versions (requirements.txt) are listed apart: they move
timings and, across SIMD levels, digits (docs/family.md). Each table's host (``on``: the CPU and SIMD level it
records) is listed too: compare a rerun with a table from the same kind of host, or expect the digits the SIMD level
moves (RGB-D SLAM, RANSAC-seeded pairs, greedy solvers) to differ.
"""

from __future__ import annotations

import argparse
import ast
import json
import re
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("benchmarks", "simreal_nodes", "simreal_msgs_py")
# the names of a script's docs page prose (module-level constants made of strings alone that only build docs/*.md:
# ``INTRO``, the page's text in family.py, tracking_scenes.py and stability.py; ``TABLES``, family.py's section
# headings, (table, heading) pairs): not compared, so editing the prose a page quotes around its tables does not flag
# the tables. Other string constants stay code (model specs and shaders are strings too), and so does a prose name
# whose value holds anything but strings.
PROSE = ("INTRO", "TABLES")
RESULTS = "benchmarks/results"


def _strings_only(node: ast.expr) -> bool:
    """A string constant, or a tuple or list of them (nested): a value that can hold prose and nothing else."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str)
    return isinstance(node, (ast.Tuple, ast.List)) and all(_strings_only(e) for e in node.elts)


@dataclass
class Table:
    name: str
    script: str | None  # repository-relative path, None where none was found
    commit: str  # full hash of the commit the table stands for ('' where git has none)
    state: str = ""  # current / code changed / labelled / no script
    changed_by: list[str] = field(default_factory=list)  # files of its code that differ now
    files: int = 0  # files in the script's closure
    host: str = ""  # the kind of CPU the table was written on (host_of), '' where it does not say
    quoted: list[str] = field(default_factory=list)  # the pages that publish it (quoted_by)


def module_file(name: str, root: Path) -> Path | None:
    """The file of module ``name`` in this repository (a module or a package's ``__init__``), None elsewhere."""
    if name.split(".")[0] not in PACKAGES:
        return None
    base = root.joinpath(*name.split("."))
    for p in (base.with_suffix(".py"), base / "__init__.py"):
        if p.is_file():
            return p
    return None


def imported_modules(path: Path, root: Path) -> set[str]:
    """Names of the modules ``path`` imports anywhere in it (``from a import b`` gives ``a`` and ``a.b``: b may be a
    module), relative imports resolved against the file's package."""
    tree = ast.parse(path.read_text(), str(path))
    package = ".".join(path.relative_to(root).with_suffix("").parts[:-1])
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".") if package else []
                parts = parts[:len(parts) - (node.level - 1)] if node.level > 1 else parts
                mod = ".".join(parts + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod:
                names.add(mod)
                names.update(f"{mod}.{a.name}" for a in node.names if a.name != "*")
    return names


def closure(script: Path, root: Path) -> set[Path]:
    """``script`` and every repository file it imports, transitively, with each module's parent packages'
    ``__init__`` (importing ``a.b.c`` runs ``a`` and ``a.b`` first)."""
    seen: set[Path] = set()
    todo = [script]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        for name in imported_modules(path, root):
            parts = name.split(".")
            for k in range(1, len(parts) + 1):
                f = module_file(".".join(parts[:k]), root)
                if f is not None and f not in seen:
                    todo.append(f)
    return seen


def data_files(code: set[Path], tracked: list[str]) -> set[str]:
    """The packages' tracked non-Python files (model specs, the DDS profile) that a file of ``code`` names: by file
    name, or a spec by its name in quotes or after ``spec:`` (how scenes and specs name them)."""
    text = "\n".join(p.read_text() for p in code)
    out = set()
    for f in tracked:
        p = Path(f)
        if p.parts[0] not in PACKAGES or p.suffix in (".py", ".typed") or p.parts[0] == "benchmarks":
            continue
        if p.name in text or (p.parent.name == "specs" and any(
                f"{q}{p.stem}{e}" in text for q, e in (('"', '"'), ("'", "'"), ("spec:", "")))):
            out.add(f)
    return out


class Code:
    """Files as of a commit against the working tree, compared as code. Python: statement by top-level statement,
    each by its syntax tree less docstrings (comments, layout and docstrings move no number), and only those that
    were there at the commit (a definition added since is called by no code of then, unless a changed one calls it);
    other files byte for byte."""

    def __init__(self, root: Path):
        self.root = root
        self.trees: dict[str, dict[str, str]] = {}  # commit -> path -> blob
        self.norm: dict[str, dict[str, str]] = {}  # blob -> statements
        self.now: dict[str, dict[str, str]] = {}  # path -> the working tree's statements

    def _tree(self, commit: str) -> dict[str, str]:
        if commit not in self.trees:
            out = subprocess.run(["git", "-C", str(self.root), "ls-tree", "-r", commit], capture_output=True,
                                 text=True, check=True).stdout
            self.trees[commit] = {line.split("\t", 1)[1]: line.split()[2] for line in out.splitlines()}
        return self.trees[commit]

    @staticmethod
    def statements(path: str, text: str) -> dict[str, str]:
        """A file as {key: code}: for Python each top-level statement's syntax tree (docstrings dropped) under its
        name (a definition's, an assignment's targets, else the statement itself, counted where repeated); for
        other files the whole text under one key."""
        if not path.endswith(".py"):
            return {"": text}
        try:
            tree = ast.parse(text)
        except SyntaxError:
            return {"": text}
        for node in ast.walk(tree):
            body = getattr(node, "body", None)
            if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body
                    and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                    and isinstance(body[0].value.value, str)):
                node.body = body[1:] or [ast.Pass()]
        out: dict[str, str] = {}
        for node in tree.body:
            if (isinstance(node, ast.Assign) and len(node.targets) == 1
                    and getattr(node.targets[0], "id", None) in PROSE and _strings_only(node.value)):
                continue  # a docs page's prose (see PROSE)
            code = ast.dump(node, include_attributes=False)
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                key = f"def {node.name}"
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                key = "set " + " ".join(ast.dump(t, include_attributes=False) for t in targets)
            else:
                key = code
            k, n = key, 1
            while k in out:
                n += 1
                k = f"{key} #{n}"
            out[k] = code
        return out

    def changed(self, commit: str, path: str) -> bool:
        """Whether ``path``'s code of ``commit`` differs in the working tree (absent then: changed)."""
        blob = self._tree(commit).get(path)
        if blob is None:
            return True
        if blob not in self.norm:
            text = subprocess.run(["git", "-C", str(self.root), "cat-file", "-p", blob], capture_output=True,
                                  text=True, check=True).stdout
            self.norm[blob] = self.statements(path, text)
        if path not in self.now:
            f = self.root / path
            self.now[path] = self.statements(path, f.read_text()) if f.is_file() else {}
        then, now = self.norm[blob], self.now[path]
        return any(now.get(k) != v for k, v in then.items())


def host_of(doc: dict) -> str:
    """The kind of host a table records (``machine.cpu`` shortened, with ``machine.simd`` where recorded): a rerun is
    compared with a table written on the same kind, since the SIMD level moves digits (docs/localization.md: the
    same code reads `real_slam`'s RGB-D rows and `two_view`'s real pairs differently on AVX2 and AVX-512 hosts)."""
    m = doc.get("machine") if isinstance(doc, dict) else None
    if not isinstance(m, dict):
        return ""
    cpu = " ".join(str(m.get("cpu") or "").replace("(R)", "").replace("(TM)", "").replace("Processor", "").split())
    simd = str(m.get("simd") or "")
    return f"{cpu} ({simd})" if cpu and simd else cpu or simd


def written_at(root: Path, path: str) -> str:
    """The last commit that changed ``path`` ('' where none did)."""
    return subprocess.run(["git", "-C", str(root), "log", "-1", "--format=%H", "--", path], capture_output=True,
                          text=True, check=True).stdout.strip()


def title_prefix(title: str) -> str:
    """The title up to its first formatted field (``{``), stripped: what a script holds literally."""
    return title.split("{", 1)[0].strip()


def find_script(doc: dict, name: str, sources: dict[str, str]) -> str | None:
    """The script that wrote a table: recorded, else the one whose source holds the title's literal start (at least
    5 characters; the longest start that one script alone holds), else ``<name>.py``."""
    recorded = (doc.get("machine") or {}).get("script") if isinstance(doc, dict) else None
    if recorded and recorded in sources:
        return str(recorded)
    title = title_prefix(str(doc.get("title", ""))) if isinstance(doc, dict) else ""
    while len(title) >= 5:
        hits = [s for s, text in sources.items() if title in text and not s.endswith("staleness.py")]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            break
        title = title[:-1].rstrip()
    own = f"benchmarks/{name}.py"
    return own if own in sources else None


def default_names(script: str, source: str) -> set[str]:
    """The tables a script writes unless told otherwise: its own name; the strings in the name argument of its
    ``save`` calls (a module constant's value where the argument names one); the default of an ``--out`` or
    ``--name`` option; and a module-level ``DEFAULT_TABLES`` (scripts whose names are composed from options)."""
    tree = ast.parse(source)
    consts = {t.id: n.value.value for n in tree.body if isinstance(n, ast.Assign) and isinstance(n.value, ast.Constant)
              and isinstance(n.value.value, str) for t in n.targets if isinstance(t, ast.Name)}
    names = {Path(script).stem}
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        fn = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
        if fn == "save" and node.args:
            for sub in ast.walk(node.args[0]):
                if isinstance(sub, ast.Constant) and isinstance(sub.value, str):
                    names.add(sub.value)
                elif isinstance(sub, ast.Name) and sub.id in consts:
                    names.add(consts[sub.id])
        elif fn == "add_argument" and any(isinstance(a, ast.Constant) and a.value in ("--out", "--name")
                                          for a in node.args):
            names.update(k.value.value for k in node.keywords if k.arg == "default"
                         and isinstance(k.value, ast.Constant) and isinstance(k.value.value, str))
    for n in tree.body:
        if isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "DEFAULT_TABLES" for t in n.targets):
            names.update(e.value for e in ast.walk(n.value) if isinstance(e, ast.Constant) and isinstance(e.value, str))
    return names


def tables(root: Path = ROOT) -> list[Table]:
    """Every results table with its script, commit and state (see the module's notes)."""
    tracked = subprocess.run(["git", "-C", str(root), "ls-files"], capture_output=True, text=True,
                             check=True).stdout.split()
    sources = {f: (root / f).read_text() for f in tracked
               if f.startswith("benchmarks/") and f.endswith(".py") and (root / f).is_file()}
    code = Code(root)
    texts = pages(root)
    named = frozenset(p.name for p in (root / "docs").glob("*.md"))
    closures: dict[str, list[str]] = {}
    defaults: dict[str, set[str]] = {}
    out = []
    for f in sorted(tracked):
        p = Path(f)
        if str(p.parent) != RESULTS or p.suffix != ".json" or not (root / f).is_file():
            continue
        try:
            doc = json.loads((root / f).read_text())
        except ValueError:
            doc = {}
        name = p.stem
        script = find_script(doc, name, sources)
        recorded = str((doc.get("machine") or {}).get("commit", "")) if isinstance(doc, dict) else ""
        at = written_at(root, f)
        if recorded and not recorded.endswith("+") and recorded != "?":
            at = subprocess.run(["git", "-C", str(root), "rev-parse", recorded], capture_output=True, text=True,
                                check=False).stdout.strip() or at
        t = Table(name, script, at, host=host_of(doc), quoted=quoted_by(name, texts, named))
        if script is None:
            t.state = "no script"
            out.append(t)
            continue
        if script not in defaults:
            defaults[script] = default_names(script, sources[script])
        if name not in defaults[script]:
            t.state = "labelled"
            out.append(t)
            continue
        if script not in closures:
            files = closure(root / script, root)
            closures[script] = sorted({str(c.relative_to(root)) for c in files} | data_files(files, tracked))
        t.files = len(closures[script])
        t.changed_by = [c for c in closures[script] if not at or code.changed(at, c)]
        t.state = "code changed" if t.changed_by else "current"
        out.append(t)
    return out


def pages(root: Path) -> dict[str, str]:
    """The pages that quote results: the README and docs/*.md but the status log (its closing notes quote tables as
    they stood at each stop) and the benchmarks' index (it names every script, quoting none)."""
    found = [root / "README.md", *sorted((root / "docs").glob("*.md"))]
    return {str(p.relative_to(root)): p.read_text() for p in found
            if p.is_file() and p.name not in ("status.md", "benchmarks.md")}


def quoted_by(name: str, texts: dict[str, str], pages_named: frozenset[str] = frozenset()) -> list[str]:
    """The pages that name table ``name``: its file (``name.md``, ``.png`` or ``.json``, under ``results/``, or bare
    where no docs page in ``pages_named`` has that name: ``family.md`` bare is docs/family.md), the command that
    writes it (``./run bench name``, ``--out name``), or the name in backticks where it has an underscore (a one-word
    name such as `graph` in backticks is as often a scene key or a mode). Where a rerun's numbers must be read back;
    a stale table no page names is the least urgent."""
    n = re.escape(name)
    bare = "" if f"{name}.md" in pages_named else r"|(?<![\w./-])"  # `family.md` bare is the docs page then
    forms = [rf"(?:results/{bare}){n}\.(?:md|png|json)\b", rf"(?:bench|--out|--name)[ =]{n}(?![\w-])"]
    forms += [rf"`{n}`"] if "_" in name else []
    pat = re.compile("|".join(forms))
    return [page for page, text in texts.items() if pat.search(text)]


def subject(root: Path, commit: str) -> str:
    return subprocess.run(["git", "-C", str(root), "log", "-1", "--format=%h %cs %s", commit], capture_output=True,
                          text=True, check=True).stdout.strip()


def report(rows: list[Table], root: Path = ROOT) -> str:
    """Markdown: counts by state, then the tables whose code changed (with the files that differ), the current ones,
    and the labelled ones (names only)."""
    by: dict[str, list[Table]] = {}
    for t in rows:
        by.setdefault(t.state, []).append(t)
    lines = ["# Published tables against the code that produces them", "",
             ", ".join(f"{k}: {len(v)}" for k, v in sorted(by.items())), ""]
    if by.get("code changed"):
        lines += ["## Code changed since the table was written (rerun: `./run bench SCRIPT`)", "",
                  "The pages that publish a table first (the README and docs/: where its numbers must be read "
                  "back after a rerun).", "",
                  "| table | script | written at | on | files of its code that differ now | of | quoted in |",
                  "|---|---|---|---|---|---|---|"]
        for t in sorted(by["code changed"], key=lambda t: (-len(t.quoted), t.name)):
            shown = ", ".join(Path(c).name for c in t.changed_by[:4]) + (" ..." if len(t.changed_by) > 4 else "")
            quoted = ", ".join(Path(q).stem for q in t.quoted) or "no page"
            lines.append(f"| {t.name} | {Path(t.script or '').stem} | {subject(root, t.commit)[:18]} | {t.host} | "
                         f"{len(t.changed_by)}: {shown} | {t.files} | {quoted} |")
        lines.append("")
    if by.get("current"):
        lines += ["## Current (no change to its code since)", "",
                  ", ".join(f"{t.name} ({Path(t.script or '').stem}; {t.host or 'host not recorded'})"
                            for t in by["current"]), ""]
    for state in ("labelled", "no script"):
        if by.get(state):
            lines += [f"## {state.capitalize()}", "", ", ".join(t.name for t in by[state]), ""]
    pins = subprocess.run(["git", "-C", str(root), "log", "-1", "--format=%h %cs", "--", "requirements.txt"],
                          capture_output=True, text=True, check=True).stdout.strip()
    lines.append(f"requirements.txt last changed: {pins or 'never'} (library versions move timings).")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stale", action="store_true", help="only the default tables whose code changed since")
    ap.add_argument("--json", action="store_true", help="JSON instead of markdown")
    a = ap.parse_args(argv)
    rows = tables()
    if a.stale:
        rows = [t for t in rows if t.state == "code changed"]
    if a.json:
        print(json.dumps([t.__dict__ for t in rows], indent=1))
    else:
        print(report(rows))


if __name__ == "__main__":
    main()
