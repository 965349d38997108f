"""Options declared once (in the spirit of detectron2's config): a section of a TOML file is a frozen
dataclass whose fields are declared with :func:`option` (the annotation is the type; the call gives the
default, bounds, help text and whether a resumed run may change it). From that one declaration come:

- the strict parser :func:`parse_section` (unknown keys and wrong types are one-line SpecErrors naming the
  file and the key, bounds checked, nested tables and arrays of tables parsed recursively);
- :func:`plain_dict`, the section as plain TOML values (``parse_section`` of it gives the section back);
- :func:`option_paths`, e.g. the keys a resumed training run may change;
- :func:`reference_markdown`, the reference tables of every key (type, default, bounds, meaning).

The same types, bounds and messages serve the options declared by name rather than as a field: a
:class:`Param` (a method's or network's keyword parameter, ``Annotated[int, "help", Range(1, 1024)]``, and
the command-line flags several commands share, lfbench.utils.flags). :func:`check` is the one check of a
value against a declared type and :class:`Bounds` (``expected int, got str``; ``must be in [1, 1024], got
0``), :func:`from_text` the one reading of a value written as text (a spec string, a flag).

Types understood: ``bool``, ``int``, ``float`` (an int is taken as a float), ``str``, ``Literal[...]``,
``X | None`` (None = absent: TOML has no null), ``tuple[X, ...]`` and ``tuple[X, X]`` (TOML arrays),
``dict[str, X]`` (a table of names), ``dict[str, Any]`` (a free table), another section (a table),
``tuple[Section, ...]`` (an array of tables) and ``Any``.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import types
import typing
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import PurePath
from typing import Any

from lfbench.utils.errors import SpecError
from lfbench.utils.markdown import markdown_cell, markdown_table

__all__ = ["Option", "option", "option_fields", "is_section", "Table", "parse_section", "check_options", "plain_dict",
           "coerce",
           "check", "from_text", "Bounds", "Range", "Param", "BadValue", "TypeMismatch", "type_name", "option_paths",
           "reference_markdown"]

_KEY = "lfbench.option"


@dataclass(frozen=True)
class Bounds:
    """Bounds of a number, or of every number of a list or table (None: unbounded on that side; an open end
    excludes the bound itself)."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def text(self) -> str:
        """The bounds as an interval, e.g. ``[1, 4096]``, ``> 0``, ``[0, 1)`` ('' when there are none)."""
        low, high = self.low, self.high
        if low is not None and high is not None:
            return f"{'(' if self.low_open else '['}{_num(low)}, {_num(high)}{')' if self.high_open else ']'}"
        if low is not None:
            return f"{'>' if self.low_open else '>='} {_num(low)}"
        return f"{'<' if self.high_open else '<='} {_num(high)}" if high is not None else ""

    def within(self) -> str:
        """``in [1, 4096]`` or ``>= 1``: what a message says a value must be."""
        text = self.text()
        return f"in {text}" if self.low is not None and self.high is not None else text

    def holds(self, value: float) -> bool:
        if isinstance(value, float) and not math.isfinite(value):
            return False
        low, high = self.low, self.high
        return (low is None or value > low or (value == low and not self.low_open)) and \
            (high is None or value < high or (value == high and not self.high_open))


class Range(Bounds):
    """The bounds of a parameter as its annotation writes them, ``Annotated[int, "help", Range(1, 1024)]``:
    inclusive ``min`` and ``max`` (None: unbounded on that side); the same :class:`Bounds` an option has."""

    def __init__(self, min: float | None = None, max: float | None = None) -> None:  # noqa: A002
        super().__init__(min, max)


NO_BOUNDS = Bounds()


@dataclass(frozen=True)
class Option:
    """What :func:`option` declares about one field (its type is the field's annotation)."""

    help: str
    bounds: Bounds = NO_BOUNDS  # of a number, or of every number of a list / table (option(low=, high=, ...))
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
    metavar: str | None = None  # the value's name where the option is also a command-line flag (``--jobs N``)


def option(default: Any = dataclasses.MISSING, *, help: str, factory: Callable[[], Any] | None = None,
           **declared: Any) -> Any:
    """A dataclass field declared as an option (see :class:`Option` for ``declared``; the bounds are given as
    ``low``, ``high``, ``low_open`` and ``high_open``, see :class:`Bounds`); without a default (or ``factory``,
    e.g. a section class) the option is required (declare the dataclass ``kw_only``). Mutable defaults (dict,
    list) are copied."""
    bounds = Bounds(**{k: declared.pop(k) for k in ("low", "high", "low_open", "high_open") if k in declared})
    meta = {_KEY: Option(help=help, bounds=bounds, **declared)}
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

class BadValue(Exception):
    """A value that does not fit its declaration, as one phrase (``must be in [1, 1024], got 0``)."""


class TypeMismatch(BadValue):
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
        return "path"
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
        raise TypeMismatch(type_name(kind), repr(value[:40]) if isinstance(value, str) else _value_name(value))
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


def _num(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _numbers(value: Any) -> list[float]:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [value]
    if isinstance(value, (list, tuple)):
        return [v for v in value if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if isinstance(value, dict):
        return [v for v in value.values() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    return []


def check(value: Any, kind: Any, bounds: Bounds = NO_BOUNDS) -> Any:
    """``value`` as the declared type ``kind`` (:func:`coerce`), its numbers finite and inside ``bounds``
    (every number of a list or table); BadValue as one phrase otherwise: ``expected int, got str``, ``must be
    in [1, 1024], got 0``, ``must be a finite number, got nan``, ``expected numbers in [0, 1), got [2, 0.5]``."""
    value = coerce(value, kind)
    numbers = _numbers(value)
    if all(bounds.holds(v) for v in numbers):
        return value
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise BadValue(f"must be a finite number, got {value}")
        raise BadValue(f"must be {bounds.within()}, got {value}")
    shown = list(value.values()) if isinstance(value, dict) else list(value)
    raise BadValue(f"expected {'numbers ' + bounds.within() if bounds.text() else 'finite numbers'}, got {shown}")


_TRUE, _FALSE = {"1", "true", "yes", "on"}, {"0", "false", "no", "off"}


def from_text(text: str, kind: Any) -> Any:
    """A value written as text (a spec string's ``key=value``, a flag's argument) as the declared type: bool
    (1/0, true/false, yes/no, on/off), int, float, str, a path (``~`` expanded), ``Literal`` (by its text),
    ``X | None`` (``none``, ``null`` or nothing: None), another class by calling it with the text;
    TypeMismatch naming the type and the text. Bounds are :func:`check`'s."""
    kind = _strip(kind)
    args = _union_args(kind)
    if args is not None:
        if type(None) in args and text.strip().lower() in ("none", "null", ""):
            return None
        for a in (a for a in args if a is not type(None)):
            try:
                return from_text(text, a)
            except TypeMismatch:
                continue
    elif typing.get_origin(kind) is typing.Literal:
        match = [a for a in typing.get_args(kind) if str(a) == text]
        if match:
            return match[0]
    elif kind is Any or kind is str or kind is dataclasses.MISSING or not isinstance(kind, type):
        return text
    elif kind is not type(None):
        try:
            if kind is bool:
                if text.strip().lower() in _TRUE | _FALSE:
                    return text.strip().lower() in _TRUE
                raise ValueError(text)
            value = kind(text)
            return value.expanduser() if isinstance(value, PurePath) and hasattr(value, "expanduser") else value
        except (ValueError, TypeError, ArithmeticError):
            pass
    raise TypeMismatch(type_name(kind), repr(text[:40]))


@dataclass(frozen=True)
class Param:
    """An option declared by name: a keyword parameter of a method or network (type, default, help and
    :class:`Range` from its ``Annotated`` annotation; lfbench.method.params) or a command-line flag that
    several commands share (lfbench.utils.flags). It checks values as a section's option does."""

    name: str
    kind: Any  # the type, without its Annotated metadata; Any for an unannotated parameter
    default: Any  # inspect.Parameter.empty: required
    help: str = ""
    range: Bounds | None = None

    def __post_init__(self) -> None:
        if self.kind is inspect.Parameter.empty:
            object.__setattr__(self, "kind", Any)

    @property
    def required(self) -> bool:
        return self.default is inspect.Parameter.empty

    @property
    def type_name(self) -> str:
        return type_name(self.kind)

    def check(self, value: Any) -> Any:
        """``value`` (e.g. from a TOML table, already typed) as the parameter's type, inside its bounds;
        BadValue as one phrase otherwise. Types this cannot check are accepted."""
        return check(value, self.kind, self.range or NO_BOUNDS)

    def problem(self, value: Any) -> str | None:
        """Why ``value`` does not fit (:meth:`check`'s phrase), or None."""
        try:
            self.check(value)
        except BadValue as exc:
            return str(exc)
        return None

    def parse(self, text: str) -> Any:
        """A value written as text, converted (:func:`from_text`; an unannotated parameter takes its
        default's type) and checked."""
        kind = self.kind
        if kind is Any and self.default not in (None, inspect.Parameter.empty):
            kind = type(self.default)
        return self.check(from_text(text, kind))

    def describe(self) -> str:
        """``name (int in [1, 1024], default 8): help``: one line of ``lfbench methods``."""
        kind = " ".join(filter(None, (self.type_name, self.range.text() if self.range else "")))
        parts = [kind, "required" if self.required else f"default {self.default!r}"]
        return f"{self.name} ({', '.join(parts)}){': ' + self.help if self.help else ''}"


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
            value = check(raw, kind, opt.bounds)
        except BadValue as exc:
            t.fail(key, str(exc))
    try:
        return _finish(value, opt)
    except BadValue as exc:
        t.fail(key, str(exc))


def _finish(value: Any, opt: Option) -> Any:
    """A typed, bounds-checked value of ``opt``: its length checked (``min_length``), converted (``convert``) and
    checked (``check``); BadValue with the problem otherwise."""
    if isinstance(value, (tuple, list, dict)) and len(value) < opt.min_length:
        raise BadValue(f"needs at least {opt.min_length} entr{'y' if opt.min_length == 1 else 'ies'}")
    if opt.convert is not None:
        value = opt.convert(value)
    problem = opt.check(value) if opt.check is not None else None
    if problem:
        raise BadValue(problem)
    return value


def check_options(section: Any, name: Callable[[str], str] = str) -> None:
    """The options of a section built from Python (not parsed from a table) checked as :func:`parse_section`
    checks them (type, bounds, then :func:`_finish`: length and ``check``); SpecError ``<name(key)>: <problem>``
    at the first that does not fit (e.g. ``--jobs: must be in [1, 256], got 0`` with the flags' names)."""
    for f, opt, kind in option_fields(type(section)):
        value = getattr(section, f.name)
        try:
            _finish(check(value, kind, opt.bounds), opt)
        except BadValue as exc:
            raise SpecError(f"{name(f.name)}: {exc}") from None


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
        rows.append((f"`{f.name}`", type_name(kind), _default_text(f, opt, kind), opt.bounds.text(), opt.resume_free,
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
            text += f"\n{'#' * level} `{sub_heading}`\n\n{markdown_cell(opt.free_text or opt.help)}\n"
        else:
            text += "\n" + reference_markdown(sub, sub_heading, level)
    return text




def _all_options(cls: type) -> Iterator[tuple[dataclasses.Field, Option, Any]]:
    for f, opt, kind in option_fields(cls):
        yield f, opt, kind
        base = _optional(kind)
        sub = base if is_section(base) else _items_kind(base)
        if sub is not None:
            yield from _all_options(sub)
