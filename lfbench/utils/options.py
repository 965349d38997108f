"""Options declared once (in the spirit of detectron2's config): a section of a TOML file is a frozen
dataclass whose fields are declared with :func:`option` (the annotation is the type; the call gives the
default, bounds, help text and whether a resumed run may change it). From that one declaration come:

- the strict parser :func:`parse_section` (unknown keys and wrong types are one-line SpecErrors naming the
  file and the key, bounds checked, nested tables and arrays of tables parsed recursively);
- :func:`plain_dict`, the section as plain TOML values (``parse_section`` of it gives the section back);
- :func:`option_paths`, e.g. the keys a resumed training run may change;
- :func:`reference_markdown`, the reference tables of every key (type, default, bounds, meaning).

:func:`coerce` is the type check of every declared option (a network's ``[model]`` parameters are declared
by its constructor and checked by lfbench.method.params.value_problem).

Types understood: ``bool``, ``int``, ``float`` (an int is taken as a float), ``str``, ``Literal[...]``,
``X | None`` (None = absent: TOML has no null), ``tuple[X, ...]`` and ``tuple[X, X]`` (TOML arrays),
``dict[str, X]`` (a table of names), ``dict[str, Any]`` (a free table), another section (a table),
``tuple[Section, ...]`` (an array of tables) and ``Any``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import PurePath
from typing import Any

from lfbench.utils.errors import SpecError

__all__ = ["Option", "option", "option_fields", "is_section", "Table", "parse_section", "plain_dict", "coerce",
           "TypeMismatch", "type_name", "option_paths", "reference_markdown", "markdown_table", "bounds_text"]

_KEY = "lfbench.option"


@dataclass(frozen=True)
class Option:
    """What :func:`option` declares about one field (its type is the field's annotation)."""

    help: str
    low: float | None = None  # bounds of a number, or of every number of a list / table of numbers
    high: float | None = None
    low_open: bool = False  # low itself excluded
    high_open: bool = False
    min_length: int = 0  # fewest entries of a list
    resume_free: bool = False  # a resumed run may change it (it does not change the result)
    omit_default: bool = False  # left out of plain_dict() at its default (added after fingerprints were written)
    single: bool = False  # a list also given as one value (a string, or a table for an array of tables)
    rest: bool = False  # a free table holding every key that no option names (declare it last)
    check: Callable[[Any], str | None] | None = None  # further check: a problem ("must be ...") or None
    convert: Callable[[Any], Any] | None = None  # applied to the checked value (e.g. str.lower)
    default_from: Callable[[dict[str, Any], int | None], Any] | None = None  # default from the options before it
    default_text: str | None = None  # the default as the reference shows it, when not the value itself
    free_text: str = ""  # what the keys of a free table (dict[str, Any]) are, for the reference


def option(default: Any = dataclasses.MISSING, *, help: str, factory: Callable[[], Any] | None = None,
           **declared: Any) -> Any:
    """A dataclass field declared as an option (see :class:`Option` for ``declared``); without a default (or
    ``factory``, e.g. a section class) the option is required (declare the dataclass ``kw_only``). Mutable
    defaults (dict, list) are copied."""
    meta = {_KEY: Option(help=help, **declared)}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=meta)
    if default is dataclasses.MISSING:
        return dataclasses.field(metadata=meta)
    if isinstance(default, (dict, list)):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@functools.cache
def option_fields(cls: type) -> tuple[tuple[dataclasses.Field, Option, Any], ...]:
    """(field, its Option, its resolved type) of every declared option of the section ``cls``, in order."""
    hints = typing.get_type_hints(cls)
    return tuple((f, f.metadata[_KEY], hints[f.name]) for f in dataclasses.fields(cls) if _KEY in f.metadata)


def is_section(kind: Any) -> bool:
    return isinstance(kind, type) and dataclasses.is_dataclass(kind) and \
        any(_KEY in f.metadata for f in dataclasses.fields(kind))


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


# --------------------------------------------------------------------------- types

class TypeMismatch(Exception):
    """A value is not of its declared type: ``expected`` and ``got`` name both."""

    def __init__(self, expected: str, got: str) -> None:
        super().__init__(f"expected {expected}, got {got}")
        self.expected, self.got = expected, got


def _strip(kind: Any) -> Any:
    """``Annotated[X, ...]`` -> X."""
    while typing.get_origin(kind) is typing.Annotated:
        kind = typing.get_args(kind)[0]
    return kind


def _union_args(kind: Any) -> tuple[Any, ...] | None:
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        return typing.get_args(kind)
    return None


def _value_name(value: Any) -> str:
    """The TOML-ish type of a value, for messages (never the value itself)."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, dict):
        return "table"
    if isinstance(value, (list, tuple)):
        inner = sorted({_value_name(v) for v in value})
        return f"list of {' and '.join(inner)}" if inner else "empty list"
    return type(value).__name__


def type_name(kind: Any) -> str:
    """A declared type as messages and the reference name it: int, float, list of str, table, ..."""
    kind = _strip(kind)
    if kind is Any or kind is dataclasses.MISSING:
        return "any"
    args = _union_args(kind)
    if args is not None:
        return " or ".join(type_name(a) for a in args if a is not type(None))
    origin = typing.get_origin(kind)
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(kind))
    if origin is tuple:
        items = typing.get_args(kind)
        if len(items) == 2 and items[1] is Ellipsis:
            inner = type_name(items[0])
            return "list of tables" if inner == "table" else f"list of {inner}"
        return f"list of {len(items)} {type_name(items[0])}"
    if origin is dict:
        value = typing.get_args(kind)[1]
        return "table" if _strip(value) is Any else f"table of {type_name(value)}"
    if is_section(kind):
        return "table"
    if isinstance(kind, type) and issubclass(kind, PurePath):
        return "str (a path)"
    return getattr(kind, "__name__", str(kind))


def coerce(value: Any, kind: Any) -> Any:
    """``value`` as the declared type ``kind`` (an int becomes a float where a float is declared, a list a
    tuple); TypeMismatch naming both types otherwise. Unknown kinds (and ``Any``) accept anything."""
    kind = _strip(kind)
    if kind is Any or kind is dataclasses.MISSING:
        return value
    if kind is type(None):
        if value is None:
            return value
        raise TypeMismatch("none", _value_name(value))
    args = _union_args(kind)
    if args is not None:
        for a in args:
            try:
                return coerce(value, a)
            except TypeMismatch:
                continue
        raise TypeMismatch(type_name(kind), _value_name(value))
    origin = typing.get_origin(kind)
    if origin is typing.Literal:
        if value in typing.get_args(kind) and not isinstance(value, bool):
            return value
        raise TypeMismatch(type_name(kind), repr(value) if isinstance(value, str) else _value_name(value))
    if origin is tuple:
        items = typing.get_args(kind)
        if not isinstance(value, (list, tuple)):
            raise TypeMismatch(type_name(kind), _value_name(value))
        if len(items) == 2 and items[1] is Ellipsis:
            items = (items[0],) * len(value)
        elif len(value) != len(items):
            raise TypeMismatch(type_name(kind), f"list of {len(value)}")
        try:
            return tuple(coerce(v, k) for v, k in zip(value, items, strict=True))
        except TypeMismatch:
            raise TypeMismatch(type_name(kind), _value_name(value)) from None
    if origin is dict:
        if not isinstance(value, dict):
            raise TypeMismatch(type_name(kind), _value_name(value))
        inner = typing.get_args(kind)[1]
        try:
            return {k: coerce(v, inner) for k, v in value.items()}
        except TypeMismatch:
            raise TypeMismatch(type_name(kind), "a table with " + _value_name(list(value.values()))) from None
    if origin is not None or not isinstance(kind, type):
        return value  # a type this check does not know (e.g. a Protocol): the consumer decides
    if kind is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    elif issubclass(kind, PurePath):
        if isinstance(value, (str, PurePath)):
            return kind(value)
    elif kind is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif isinstance(value, kind):
        return value
    raise TypeMismatch(type_name(kind), _value_name(value))


def bounds_text(opt: Option) -> str:
    """The bounds as an interval, e.g. ``[1, 4096]``, ``> 0``, ``[0, 1)`` ('' when there are none)."""
    if opt.low is not None and opt.high is not None:
        return f"{'(' if opt.low_open else '['}{_num(opt.low)}, {_num(opt.high)}{')' if opt.high_open else ']'}"
    if opt.low is not None:
        return f"{'>' if opt.low_open else '>='} {_num(opt.low)}"
    if opt.high is not None:
        return f"{'<' if opt.high_open else '<='} {_num(opt.high)}"
    return ""


def _num(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _bound_problem(value: Any, opt: Option) -> str | None:
    """Why a number is out of the option's bounds (the messages name the declared bound as written)."""
    if isinstance(value, float) and not math.isfinite(value):
        return f"must be a finite number, got {value}"
    if opt.low is not None and (value < opt.low or (opt.low_open and value == opt.low)):
        return f"must be {'>' if opt.low_open else '>='} {opt.low}, got {value}"
    if opt.high is not None and (value > opt.high or (opt.high_open and value == opt.high)):
        return f"must be {'<' if opt.high_open else '<='} {opt.high}, got {value}"
    return None


def _numbers(value: Any) -> list[float]:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [value]
    if isinstance(value, (list, tuple)):
        return [v for v in value if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if isinstance(value, dict):
        return [v for v in value.values() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    return []


# --------------------------------------------------------------------------- parsing

class Table:
    """Strict access to one TOML table of ``source``; ``where`` is its dotted name in messages, and
    :meth:`done` rejects keys nobody asked for."""

    def __init__(self, raw: Any, where: str, source: str | None) -> None:
        if not isinstance(raw, dict):
            raise SpecError(f"[{where}] must be a table", source)
        self.raw, self.where, self.source, self.used = raw, where, source, set()

    def fail(self, key: str | None, msg: str) -> typing.NoReturn:
        """SpecError '<where>.<key>: msg' naming the file."""
        name = ".".join(p for p in (self.where, key) if p)
        raise SpecError(f"{name}: {msg}" if name else msg, self.source)

    def has(self, key: str) -> bool:
        return self.raw.get(key) is not None  # None only comes from plain_dict(): TOML has no null

    def table(self, key: str) -> Table:
        self.used.add(key)
        where = f"{self.where}.{key}" if self.where else key
        return Table(self.raw.get(key) or {}, where, self.source)

    def rest(self) -> dict[str, Any]:
        """Every key not asked for yet (they count as used)."""
        out = {k: v for k, v in self.raw.items() if k not in self.used}
        self.used |= set(out)
        return out

    def done(self, accepted: typing.Iterable[str] = ()) -> None:
        unknown = sorted(set(self.raw) - self.used)
        if unknown:
            where = f"[{self.where}] " if self.where else ""
            listed = sorted(accepted) or sorted(self.used)
            raise SpecError(f"{where}unknown key(s): {', '.join(unknown)} (accepted: {', '.join(listed)})",
                            self.source)


def _items_kind(kind: Any) -> Any:
    """The section type of an array of tables (``tuple[Section, ...]``), else None."""
    kind = _strip(kind)
    if typing.get_origin(kind) is tuple:
        items = typing.get_args(kind)
        if len(items) == 2 and items[1] is Ellipsis and is_section(items[0]):
            return items[0]
    return None


def _optional(kind: Any) -> Any:
    args = _union_args(_strip(kind))
    if args is not None and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        return rest[0] if len(rest) == 1 else kind
    return kind


def _read(t: Table, f: dataclasses.Field, opt: Option, kind: Any, values: dict[str, Any], index: int | None) -> Any:
    key = f.name
    if opt.rest:
        return t.rest()
    t.used.add(key)
    base = _optional(kind)
    section = base if is_section(base) else None
    if not t.has(key):
        if section is not None and _default(f) is not None:  # an absent table: its defaults, checked
            return parse_section(section, t.table(key))
        if opt.default_from is not None:
            return opt.default_from(values, index)
        default = _default(f)
        if default is dataclasses.MISSING:
            t.fail(key, "is required")
        return default
    raw = t.raw[key]
    items = _items_kind(base)
    if section is not None:
        value = parse_section(section, t.table(key))
    elif items is not None:
        if opt.single and isinstance(raw, dict):
            raw = [raw]
        if not isinstance(raw, list):
            t.fail(key, f"expected {type_name(kind)}, got {_value_name(raw)}")
        where = f"{t.where}.{key}" if t.where else key
        value = tuple(parse_section(items, Table(item, f"{where}[{i}]", t.source), i) for i, item in enumerate(raw))
    else:
        if opt.single and isinstance(raw, (str, int, float)) and typing.get_origin(_strip(base)) is tuple:
            raw = [raw]
        try:
            value = coerce(raw, kind)
        except TypeMismatch as exc:
            t.fail(key, str(exc))
    if isinstance(value, (tuple, list, dict)) and len(value) < opt.min_length:
        t.fail(key, f"needs at least {opt.min_length} entr{'y' if opt.min_length == 1 else 'ies'}")
    if section is None and items is None:
        _check_bounds(t, key, value, opt)
    if opt.convert is not None:
        value = opt.convert(value)
    if opt.check is not None:
        problem = opt.check(value)
        if problem:
            t.fail(key, problem)
    return value


def _check_bounds(t: Table, key: str, value: Any, opt: Option) -> None:
    """Numbers are finite and inside the option's bounds (every number of a list or table)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        problem = _bound_problem(value, opt)
        if problem:
            t.fail(key, problem)
    elif any(_bound_problem(v, opt) for v in _numbers(value)):
        shown = list(value.values()) if isinstance(value, dict) else list(value)
        bounds = bounds_text(opt)
        within = f"in {bounds}" if opt.low is not None and opt.high is not None else bounds
        t.fail(key, f"expected {'numbers ' + within if bounds else 'finite numbers'}, got {shown}")


def parse_section(cls: type, table: Table, index: int | None = None) -> Any:
    """The section ``cls`` from ``table``: every declared option read, typed and bounds-checked in
    declaration order, then unknown keys refused, then ``cls.check_options(values, table)`` when the
    section has one (checks across options; it may return replaced values). ``index``: the position in
    an array of tables (for defaults that depend on it)."""
    values: dict[str, Any] = {}
    names = []
    for f, opt, kind in option_fields(cls):
        names.append(f.name)
        values[f.name] = _read(table, f, opt, kind, values, index)
    table.done(names)
    check = getattr(cls, "check_options", None)
    if check is not None:
        values = check(values, table) or values
    return cls(**values)


def plain_dict(section: Any) -> dict[str, Any]:
    """A parsed section as plain TOML values (lists, dicts), in declaration order; options declared
    ``omit_default`` are left out at their default, a ``rest`` table is merged into its section."""
    out: dict[str, Any] = {}
    for f, opt, _ in option_fields(type(section)):
        value = getattr(section, f.name)
        if opt.omit_default and value == _default(f):
            continue
        plain = _plain(value)
        if opt.rest:
            out.update(plain)
        else:
            out[f.name] = plain
    return out


def _plain(x: Any) -> Any:
    if is_section(type(x)):
        return plain_dict(x)
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def option_paths(cls: type, where: Callable[[Option], bool],
                 prefix: tuple[str, ...] = ()) -> tuple[tuple[str, ...], ...]:
    """The key paths (e.g. ``("training", "threads")``) of the options of ``cls`` and its nested tables
    (not arrays of tables) for which ``where(option)`` holds."""
    out: list[tuple[str, ...]] = []
    for f, opt, kind in option_fields(cls):
        path = (*prefix, f.name)
        if where(opt):
            out.append(path)
        base = _optional(kind)
        if is_section(base):
            out += option_paths(base, where, path)
    return tuple(out)


# --------------------------------------------------------------------------- reference

def _default_text(f: dataclasses.Field, opt: Option, kind: Any) -> str:
    if opt.default_text is not None:
        return opt.default_text
    if is_section(_optional(kind)) and _default(f) is not None:
        return "see below"
    default = _default(f)
    if default is dataclasses.MISSING:
        return "required"
    if default is None or default in ((), {}, []):
        return "—" if default is None else "empty"
    return _toml(_plain(default))


def _toml(x: Any) -> str:
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, str):
        return f'"{x}"'
    if isinstance(x, float):
        return f"{x:.6g}"
    if isinstance(x, list):
        return "[" + ", ".join(_toml(v) for v in x) + "]"
    if isinstance(x, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in x.items()) + "}"
    return str(x)


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def reference_markdown(cls: type, heading: str = "", level: int = 2, free: dict[str, str] | None = None) -> str:
    """Markdown tables of every option of ``cls`` and of its nested tables and arrays of tables: key, type,
    default, bounds, whether a resumed run may change it, meaning. ``heading``: the table's TOML header
    ('' for the top level)."""
    rows, nested = [], []
    resumable = any(o.resume_free for _, o, _ in _all_options(cls))
    for f, opt, kind in option_fields(cls):
        base = _optional(kind)
        if opt.rest:
            rows.append(("*(any other key)*", "any", "", "", False, opt.help))
            continue
        rows.append((f"`{f.name}`", type_name(kind), _default_text(f, opt, kind), bounds_text(opt), opt.resume_free,
                     opt.help))
        name = f"{heading.strip('[]')}.{f.name}" if heading else f.name
        if is_section(base):
            nested.append((f"[{name}]", base, opt))
        elif _items_kind(base) is not None:
            nested.append((f"[[{name}]]", _items_kind(base), opt))
        elif typing.get_origin(_strip(base)) is dict and _strip(typing.get_args(_strip(base))[1]) is Any:
            nested.append((f"[{name}]", None, opt))
    head = ["key", "type", "default", "bounds"] + (["resume"] if resumable else []) + ["meaning"]
    table = markdown_table(head, [[key, typ, default, bounds] + (["may change" if free_resume else ""] if resumable
                                                                 else []) + [meaning]
                                  for key, typ, default, bounds, free_resume, meaning in rows])
    text = (f"{'#' * level} `{heading}`\n\n" if heading else "") + table
    for sub_heading, sub, opt in nested:
        if sub is None:
            text += f"\n{'#' * level} `{sub_heading}`\n\n{_cell(opt.free_text or opt.help)}\n"
        else:
            text += "\n" + reference_markdown(sub, sub_heading, level)
    return text


def markdown_table(head: list[str], rows: list[list[str]]) -> str:
    """A Markdown table; cells on one line, ``|`` escaped."""
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _all_options(cls: type) -> Iterator[tuple[dataclasses.Field, Option, Any]]:
    for f, opt, kind in option_fields(cls):
        yield f, opt, kind
        base = _optional(kind)
        sub = base if is_section(base) else _items_kind(base)
        if sub is not None:
            yield from _all_options(sub)
