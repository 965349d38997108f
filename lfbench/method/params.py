"""Parameters of methods and networks, and the spec strings that set them.

A parameter is a keyword argument of a method's ``__init__`` or of a network's constructor; its type
and help are declared in the annotation::

    def __init__(self, channels: Annotated[int, "channels of the hidden convolutions", Range(1, 1024)] = 8):

The first string in ``Annotated[...]`` is the help that ``lfbench methods`` and ``lfbench info`` show,
a :class:`Range` bounds a number (checked before anything is built or generated). A plugin written
before annotations (help in ``name: text`` lines of the class docstring) still works: that is the
deprecated way, read only where an annotation gives no help.

A spec string selects a method and its parameters on the command line: ``name`` or
``name:key=value,key=value``; values are converted to the annotated types. :class:`Param` and
:class:`Range` are lfbench.utils.options': a parameter's type, bounds and messages are those of every
declared option.
"""

from __future__ import annotations

import inspect
import typing
from collections.abc import Callable, Mapping
from typing import Any

from lfbench.utils.errors import SpecError
from lfbench.utils.options import BadValue, Bounds, Param, Range


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


def _annotation(hint: Any) -> tuple[Any, str, Bounds | None]:
    """(type, help, bounds) of a type hint, reading ``Annotated[type, "help", Range(...)]``."""
    if typing.get_origin(hint) is typing.Annotated:
        kind, *extra = typing.get_args(hint)
        text = next((e for e in extra if isinstance(e, str)), "")
        bounds = next((e for e in extra if isinstance(e, Bounds)), None)
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


def coerce(text: str, param: Param, method: str = "") -> Any:
    """A spec value converted to the parameter's type and checked against its bounds (:meth:`Param.parse`);
    SpecError ``method:name: expected int, got 'x'`` otherwise."""
    try:
        return param.parse(text)
    except BadValue as exc:
        raise SpecError(f"{method + ':' if method else ''}{param.name}: {exc}") from None


def values_problem(params: Mapping[str, Param], values: Mapping[str, Any]) -> tuple[str | None, str] | None:
    """Why ``values`` (e.g. a TOML ``[model]`` table, already typed) cannot set ``params``: (the key, the
    problem as :meth:`Param.check` words it), or (None, the unknown keys and the accepted ones); None when
    they fit."""
    unknown = sorted(set(values) - set(params))
    if unknown:
        return None, f"unknown key(s): {', '.join(unknown)} (accepted: {', '.join(sorted(params))})"
    for key, value in values.items():
        problem = params[key].problem(value)
        if problem:
            return key, problem
    return None


__all__ = ["Param", "Range", "signature_params", "docstring_help", "without_help_lines", "parse_spec", "format_spec",
           "coerce", "coerce_params", "values_problem"]
