"""A small declarative validator for YAML documents (scene files, model specs).

Every rejection names the key path, what was expected and what was found, e.g.
``objects[0].parameters.s.mode: expected one of 'tracked', 'constant', 'fixed'; found 'trackd'``.
Unknown keys are rejected (with a suggestion) rather than silently ignored.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

from simreal_nodes.errors import SceneError


def _show(v: object) -> str:
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, (dict, list)):
        s = repr(v)
        return s if len(s) < 60 else s[:57] + "..."
    return f"{v!r} ({type(v).__name__})" if v is not None else "nothing (null)"


class Spec:
    """Base of all field specs: ``check(value, path, ctx)`` returns the normalized value."""

    def __init__(self, doc: str = "", default: Any = None, required: bool = False, nullable: bool = False) -> None:
        self.doc, self.default, self.required, self.nullable = doc, default, required, nullable

    def fail(self, path: str, expected: str, found: object, ctx: Context) -> NoReturn:
        raise SceneError(f"{ctx.source}: {path}: expected {expected}; found {_show(found)}")

    def check(self, v: object, path: str, ctx: Context) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def validate(self, v: object, path: str, ctx: Context) -> Any:
        if v is None:
            if self.nullable:
                return None
            self.fail(path, self.describe(), v, ctx)
        return self.check(v, path, ctx)

    def describe(self) -> str:  # pragma: no cover - overridden
        return "a value"


@dataclass
class Context:
    source: str = "<scene>"
    base_dir: Path = field(default_factory=Path.cwd)


# Record's cross-field check: (the validated record, its key path, the context); it raises SceneError to reject.
CheckFn = Callable[[dict[str, Any], str, Context], object]


def _yaml_float(x: object) -> object:
    """'69.0e9' (a string to PyYAML) -> 69e9; anything else unchanged."""
    if isinstance(x, str):
        try:
            return float(x)
        except ValueError:
            return x
    return x


class Str(Spec):
    def __init__(self, doc: str = "", pattern: Callable[[str], bool] | None = None, what: str = "a string",
                 **kw: Any) -> None:
        super().__init__(doc, **kw)
        self.pattern, self.what = pattern, what

    def describe(self) -> str:
        return self.what

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if not isinstance(v, str) or (self.pattern and not self.pattern(v)):
            self.fail(path, self.what, v, ctx)
        return v


class Topic(Str):
    def __init__(self, doc: str = "", **kw: Any) -> None:
        super().__init__(doc, pattern=lambda s: s.startswith("/") and " " not in s and len(s) > 1,
                         what="a ROS topic name starting with '/'", **kw)


class Enum(Spec):
    def __init__(self, choices: Iterable[object], doc: str = "", **kw: Any) -> None:
        super().__init__(doc, **kw)
        self.choices = tuple(choices)

    def describe(self) -> str:
        return "one of " + ", ".join(repr(c) for c in self.choices)

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if v not in self.choices:
            self.fail(path, self.describe(), v, ctx)
        return v


class Bool(Spec):
    def describe(self) -> str:
        return "true or false"

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if not isinstance(v, bool):
            self.fail(path, self.describe(), v, ctx)
        return v


class Number(Spec):
    def __init__(self, doc: str = "", lo: float | None = None, hi: float | None = None, integer: bool = False,
                 lo_open: bool = False, **kw: Any) -> None:
        super().__init__(doc, **kw)
        self.lo, self.hi, self.integer, self.lo_open = lo, hi, integer, lo_open

    def describe(self) -> str:
        s = "an integer" if self.integer else "a number"
        if self.lo is not None and self.hi is not None:
            s += f" in [{self.lo}, {self.hi}]" if not self.lo_open else f" in ({self.lo}, {self.hi}]"
        elif self.lo is not None:
            s += f" > {self.lo}" if self.lo_open else f" >= {self.lo}"
        elif self.hi is not None:
            s += f" <= {self.hi}"
        return s

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if isinstance(v, str):
            # PyYAML reads 69.0e9 (no sign in the exponent) as a string: accept it as the number it is
            try:
                v = float(v)
            except ValueError:
                self.fail(path, self.describe(), v, ctx)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(path, self.describe(), v, ctx)
        if self.integer and not (isinstance(v, int) or float(v).is_integer()):
            self.fail(path, self.describe(), v, ctx)
        if not math.isfinite(v):
            self.fail(path, self.describe(), v, ctx)
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            self.fail(path, self.describe(), v, ctx)
        if self.hi is not None and v > self.hi:
            self.fail(path, self.describe(), v, ctx)
        return int(v) if self.integer else float(v)


class Vector(Spec):
    def __init__(self, n: int | tuple[int, ...], doc: str = "", what: str | None = None, **kw: Any) -> None:
        super().__init__(doc, **kw)
        self.n = (n,) if isinstance(n, int) else tuple(n)
        self.what = what or f"a list of {' or '.join(map(str, self.n))} numbers"

    def describe(self) -> str:
        return self.what

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if isinstance(v, list):
            v = [_yaml_float(x) for x in v]
        if not isinstance(v, list) or len(v) not in self.n or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
            self.fail(path, self.what, v, ctx)
        return [float(x) for x in v]


class FilePath(Spec):
    """A path, relative to the YAML file's folder; ``must_exist`` checks it."""

    def __init__(self, doc: str = "", must_exist: bool = True, **kw: Any) -> None:
        super().__init__(doc, **kw)
        self.must_exist = must_exist

    def describe(self) -> str:
        return "a file path"

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if not isinstance(v, str) or not v:
            self.fail(path, "a file path", v, ctx)
        try:
            p = Path(v).expanduser()
            if not p.is_absolute():
                p = (ctx.base_dir / p).resolve()
            missing = self.must_exist and not p.exists()
        except (OSError, ValueError) as e:  # a name too long for the file system, a NUL character
            raise SceneError(f"{ctx.source}: {path}: not a usable file path ({e.__class__.__name__}: "
                             f"{str(e)[:60]}): {v[:60]!r}") from None
        if missing:
            raise SceneError(f"{ctx.source}: {path}: file not found: {p}")
        return str(p)


class ListOf(Spec):
    def __init__(self, item: Spec, doc: str = "", min_len: int = 0, **kw: Any) -> None:
        super().__init__(doc, **kw)
        self.item, self.min_len = item, min_len

    def describe(self) -> str:
        return f"a list of {self.item.describe()}" + (f" (at least {self.min_len})" if self.min_len else "")

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if not isinstance(v, list) or len(v) < self.min_len:
            self.fail(path, self.describe(), v, ctx)
        return [self.item.validate(x, f"{path}[{i}]", ctx) for i, x in enumerate(v)]


class MapOf(Spec):
    """A mapping with free keys (checked by ``key``) and values of one spec."""

    def __init__(self, value: Spec, key: Spec | None = None, doc: str = "", **kw: Any) -> None:
        super().__init__(doc, **kw)
        self.value, self.key = value, key or Str()

    def describe(self) -> str:
        return "a mapping"

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if not isinstance(v, dict):
            self.fail(path, "a mapping", v, ctx)
        out: dict[Any, Any] = {}
        for k, x in v.items():
            kk = self.key.validate(k, f"{path} key", ctx)
            out[kk] = self.value.validate(x, f"{path}.{k}", ctx)
        return out


class Record(Spec):
    """A mapping with named fields; unknown keys are errors."""

    def __init__(self, fields: Mapping[str, Spec], doc: str = "", check_fn: CheckFn | None = None, **kw: Any) -> None:
        super().__init__(doc, **kw)
        self.fields, self.check_fn = fields, check_fn

    def describe(self) -> str:
        return "a mapping with keys " + ", ".join(self.fields)

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if not isinstance(v, dict):
            self.fail(path, "a mapping", v, ctx)
        prefix = f"{path}." if path else ""
        for k in v:
            if k not in self.fields:
                close = difflib.get_close_matches(str(k), list(self.fields), n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise SceneError(
                    f"{ctx.source}: {prefix}{k}: unknown key{hint}; expected one of: {', '.join(self.fields)}")
        out: dict[str, Any] = {}
        for k, spec in self.fields.items():
            if k in v:
                out[k] = spec.validate(v[k], f"{prefix}{k}", ctx)
            elif spec.required:
                raise SceneError(f"{ctx.source}: {prefix}{k}: required key is missing; expected {spec.describe()}")
            elif isinstance(spec, Record) and spec.default is None and not spec.nullable:
                out[k] = spec.validate({}, f"{prefix}{k}", ctx)
            else:
                out[k] = spec.default
        if self.check_fn:
            self.check_fn(out, path, ctx)
        return out


def record_defaults(spec: Record) -> dict[str, Any]:
    """The defaults of a record (used when a whole optional section is absent)."""
    return spec.validate({}, "", Context())
