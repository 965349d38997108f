"""Parameters of methods and networks, and the spec strings that set them.

A parameter is a keyword argument of a method's ``__init__`` or of a network's constructor; its type
and help are declared in the annotation::

    def __init__(self, channels: Annotated[int, "channels of the hidden convolutions", Range(1, 1024)] = 8):

The first string in ``Annotated[...]`` is the help that ``lfbench methods`` and ``lfbench info`` show,
a :class:`Range` bounds a number (checked before anything is built or generated). A plugin written
before annotations (help in ``name: text`` lines of the class docstring) still works: that is the
deprecated way, read only where an annotation gives no help.

A spec string selects a method and its parameters on the command line: ``name`` or
``name:key=value,key=value``; values are converted to the annotated types.
"""

from __future__ import annotations

import inspect
import math
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lfbench.utils.errors import SpecError


@dataclass(frozen=True)
class Range:
    """Inclusive bounds of a numeric parameter (None: unbounded on that side)."""

    min: float | None = None
    max: float | None = None

    def text(self) -> str:
        if self.min is not None and self.max is not None:
            return f"{self.min:g} to {self.max:g}"
        return f">= {self.min:g}" if self.min is not None else f"<= {self.max:g}" if self.max is not None else ""

    def contains(self, value: float) -> bool:
        return (self.min is None or value >= self.min) and (self.max is None or value <= self.max)


@dataclass(frozen=True)
class Param:
    """One parameter: name, type (without its ``Annotated`` metadata), default, help and bounds."""

    name: str
    kind: Any
    default: Any
    help: str = ""
    range: Range | None = None

    @property
    def required(self) -> bool:
        return self.default is inspect.Parameter.empty

    @property
    def type_name(self) -> str:
        k = self.kind
        if isinstance(k, type):
            return k.__name__
        return str(k).replace("typing.", "").replace("pathlib.", "")

    def describe(self) -> str:
        """``name (type, default 8, 1 to 1024): help``: one line of ``lfbench methods``."""
        parts = [self.type_name, "required" if self.required else f"default {self.default!r}"]
        if self.range is not None:
            parts.append(self.range.text())
        return f"{self.name} ({', '.join(parts)}){': ' + self.help if self.help else ''}"


def docstring_help(doc: str) -> dict[str, str]:
    """Parameter help from a docstring's ``name: text`` lines (deprecated: declare help in the annotation)."""
    out = {}
    for line in doc.splitlines():
        s = line.strip()
        if ":" in s and not s.endswith(":"):
            key, text = s.split(":", 1)
            key = key.split("(")[0].strip()
            if key.isidentifier():
                out.setdefault(key, text.strip())
    return out


def without_help_lines(doc: str, names: typing.Iterable[str]) -> str:
    """``doc`` without the ``name: text`` lines (and their indented continuations) of ``names``: what is
    left to print beside a parameter list that already shows that help."""
    names = set(names)
    lines, skipping = [], False
    for line in doc.splitlines():
        key = line.strip().split(":", 1)[0].split("(")[0].strip() if ":" in line else ""
        if not line.startswith((" ", "\t")):
            skipping = key in names and key.isidentifier()
        if not skipping:
            lines.append(line)
    return "\n".join(lines).strip()


def _annotation(hint: Any) -> tuple[Any, str, Range | None]:
    """(type, help, range) of a type hint, reading ``Annotated[type, "help", Range(...)]``."""
    if typing.get_origin(hint) is typing.Annotated:
        kind, *extra = typing.get_args(hint)
        text = next((e for e in extra if isinstance(e, str)), "")
        bounds = next((e for e in extra if isinstance(e, Range)), None)
        return kind, " ".join(text.split()), bounds
    return hint, "", None


def signature_params(target: Callable[..., Any], doc: str = "") -> dict[str, Param]:
    """The keyword parameters of ``target`` (a function, or a class's ``__init__``) with their types,
    defaults, help and bounds (``self`` and ``*args/**kwargs`` left out). Help comes from the annotation;
    ``doc``'s ``name: text`` lines fill in where none is annotated (the deprecated way)."""
    if inspect.isclass(target):
        target = target.__init__
    try:
        hints = typing.get_type_hints(target, include_extras=True)
    except Exception:  # noqa: BLE001 - unresolvable annotations: fall back to the raw ones
        hints = {}
    legacy = docstring_help(doc) if doc else {}
    params = {}
    for p in inspect.signature(target).parameters.values():
        if p.name == "self" or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        kind, text, bounds = _annotation(hints.get(p.name, p.annotation))
        params[p.name] = Param(p.name, kind, p.default, text or legacy.get(p.name, ""), bounds)
    return params


# --------------------------------------------------------------------------- spec strings

def parse_spec(spec: str) -> tuple[str, dict[str, str]]:
    """``name:key=value,key=value`` -> (name, {key: raw value}). Values may not contain commas."""
    spec = spec.strip()
    name, _, rest = spec.partition(":")
    name = name.strip()
    if not name or not all(c.isalnum() or c in "_-." for c in name):
        raise SpecError(f"bad method spec {spec!r}: expected name or name:key=value,key=value")
    params: dict[str, str] = {}
    if rest.strip():
        for item in rest.split(","):
            key, eq, value = item.partition("=")
            key = key.strip()
            if not eq or not key.isidentifier():
                raise SpecError(f"bad method spec {spec!r}: {item.strip()!r} is not key=value")
            if key in params:
                raise SpecError(f"bad method spec {spec!r}: {key!r} given twice")
            params[key] = value.strip()
    return name, params


def format_spec(name: str, params: dict[str, Any]) -> str:
    """The inverse of parse_spec (for labels): ``name:key=value,...`` in the given order."""
    if not params:
        return name
    return name + ":" + ",".join(f"{k}={v}" for k, v in params.items())


def coerce_params(raw: dict[str, str], params: dict[str, Param], owner: str, kind: str = "method") -> dict[str, Any]:
    """Spec values (text) converted to the types of ``params``; SpecError for a name not among them."""
    out = {}
    for key, text in raw.items():
        if key not in params:
            known = ", ".join(params) or "none"
            raise SpecError(f"{kind} {owner!r} has no parameter {key!r}; parameters: {known}")
        out[key] = coerce(text, params[key], owner)
    return out


_TRUE, _FALSE = {"1", "true", "yes", "on"}, {"0", "false", "no", "off"}


def coerce(text: str, param: Param, method: str = "") -> Any:
    """Convert a spec value to the parameter's type (bool, int, float, str, Path, Optional, Literal) and
    check it against the parameter's bounds."""
    value = _coerce(text, param, method)
    problem = value_problem(param, value)
    if problem:
        raise SpecError(f"{method}:{param.name} {problem}" if method else f"{param.name} {problem}")
    return value


def _coerce(text: str, param: Param, method: str) -> Any:
    kind = param.kind
    origin = typing.get_origin(kind)
    args = typing.get_args(kind)
    where = f"{method}:{param.name}" if method else param.name
    if origin in (typing.Union, types.UnionType):
        if text.lower() in ("none", "null", "") and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(text, Param(param.name, a, param.default), method)
            except SpecError as exc:
                errors.append(str(exc))
        raise SpecError(errors[0] if errors else f"{where}: cannot use {text!r}")
    if origin is typing.Literal:
        for a in args:
            if str(a) == text:
                return a
        raise SpecError(f"{where} must be one of {', '.join(map(str, args))}, got {text!r}")
    if kind is inspect.Parameter.empty or kind is Any:
        kind = type(param.default) if param.default not in (None, inspect.Parameter.empty) else str
    try:
        if kind is bool:
            low = text.lower()
            if low in _TRUE:
                return True
            if low in _FALSE:
                return False
            raise ValueError
        if kind is int:
            return int(text)
        if kind is float:
            return float(text)
        if kind is Path:
            return Path(text).expanduser()
        if kind is str:
            return text
        return kind(text)
    except (ValueError, TypeError):
        raise SpecError(f"{where} expects {getattr(kind, '__name__', kind)}, got {text!r}") from None


def value_problem(param: Param, value: Any) -> str | None:
    """Why ``value`` (e.g. from a TOML table, already typed) does not fit the parameter's type and bounds,
    as a phrase (``expects int, got str '16'``), or None. Types it cannot check are accepted."""
    if not _fits(param.kind, value):
        shown = repr(value) if len(repr(value)) <= 40 else repr(value)[:37] + "..."
        return f"expects {_type_text(param.kind)}, got {type(value).__name__} {shown}"
    if param.range is not None and isinstance(value, int | float) and not isinstance(value, bool):
        if not math.isfinite(value) or not param.range.contains(value):
            return f"must be {param.range.text()}, got {value!r}"
    return None


def _type_text(kind: Any) -> str:
    if typing.get_origin(kind) is typing.Literal:
        return "one of " + ", ".join(map(repr, typing.get_args(kind)))
    return getattr(kind, "__name__", None) or str(kind).replace("typing.", "")


def _fits(kind: Any, value: Any) -> bool:
    origin = typing.get_origin(kind)
    if origin in (typing.Union, types.UnionType):
        return any(_fits(a, value) for a in typing.get_args(kind))
    if origin is typing.Literal:
        return any(value == a and type(value) is type(a) for a in typing.get_args(kind))
    if kind is type(None) or kind is None:
        return value is None
    if kind is bool:
        return isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if kind is str:
        return isinstance(value, str)
    if kind is Path:
        return isinstance(value, str | Path)
    return True  # Any, unannotated or a type lfbench does not know: the network decides


__all__ = ["Param", "Range", "signature_params", "docstring_help", "without_help_lines", "parse_spec", "format_spec",
           "coerce", "coerce_params", "value_problem"]
