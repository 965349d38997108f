"""The method registry: ``@register_method("name")``, ``create("name", **params)``, spec strings.

Built-in methods and third-party plugins are found the same way: through the entry-point group
``lfbench.methods``. An entry point names a module (importing it runs its ``@register_method``
decorators) or a factory (registered under the entry point's name if it is not yet registered).

A spec string selects a method and its parameters on the command line: ``name`` or
``name:key=value,key=value``; values are converted to the types of the factory's signature.
"""

from __future__ import annotations

import inspect
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from importlib import metadata
from pathlib import Path
from typing import Any

from lfbench.utils.errors import SpecError

ENTRY_POINT_GROUP = "lfbench.methods"


@dataclass(frozen=True)
class Param:
    """One parameter of a method: name, type, default and the help text from the docstring."""

    name: str
    kind: Any
    default: Any
    help: str = ""

    @property
    def type_name(self) -> str:
        k = self.kind
        if isinstance(k, type):
            return k.__name__
        return str(k).replace("typing.", "")


@dataclass(frozen=True)
class MethodInfo:
    """A registered method: its factory (a Method subclass or a function returning a Method), its
    parameters (with this name's defaults), summary and docstring, the module it comes from, and the
    ``defaults`` a variant gives the factory (``lfattnet`` = SubFocal with interval 1)."""

    name: str
    factory: Callable[..., Any]
    params: dict[str, Param]
    summary: str
    doc: str
    source: str
    defaults: dict[str, Any] = field(default_factory=dict)

    def describe(self) -> str:
        lines = [f"{self.name}: {self.summary}", f"  source: {self.source}"]
        if self.params:
            lines.append("  parameters:")
            for p in self.params.values():
                default = "required" if p.default is inspect.Parameter.empty else f"default {p.default!r}"
                lines.append(f"    {p.name} ({p.type_name}, {default}){': ' + p.help if p.help else ''}")
        return "\n".join(lines)


def _param_help(doc: str) -> dict[str, str]:
    """Parameter help from a docstring's ``name: text`` lines (Google style 'Args:' or plain)."""
    out = {}
    for line in doc.splitlines():
        s = line.strip()
        if ":" in s and not s.endswith(":"):
            key, text = s.split(":", 1)
            key = key.split("(")[0].strip()
            if key.isidentifier():
                out.setdefault(key, text.strip())
    return out


def signature_params(target: Callable[..., Any], doc: str) -> dict[str, Param]:
    """The keyword parameters of ``target`` (a function, or a class's ``__init__``) with their type hints,
    defaults and the help of ``doc``'s ``name: text`` lines (``self`` and ``*args/**kwargs`` left out)."""
    if inspect.isclass(target):
        target = target.__init__
    try:
        hints = typing.get_type_hints(target)
    except Exception:  # unresolvable annotations: fall back to raw ones
        hints = {}
    helps = _param_help(doc)
    params = {}
    for p in inspect.signature(target).parameters.values():
        if p.name == "self" or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        params[p.name] = Param(p.name, hints.get(p.name, p.annotation), p.default, helps.get(p.name, ""))
    return params


def _introspect(name: str, factory: Callable[..., Any], defaults: dict[str, Any] | None = None,
                doc: str | None = None) -> MethodInfo:
    """The MethodInfo of ``factory`` registered as ``name``; a variant passes its ``defaults`` (they
    replace the signature's) and its own ``doc`` (summary line, and ``name: help`` lines that replace
    the factory's)."""
    from lfbench.method.base import Method

    if inspect.isclass(factory) and not issubclass(factory, Method):
        raise TypeError(f"{factory.__module__}.{factory.__qualname__} registered as method {name!r} is not a "
                        "Method (subclass lfbench.Method)")
    if not callable(factory):
        raise TypeError(f"{factory!r} registered as method {name!r} is not a Method class or factory")
    own = inspect.getdoc(factory) or ""
    doc = _variant_doc(inspect.cleandoc(doc), own) if doc else own
    params = signature_params(factory, doc)
    defaults = dict(defaults or {})
    unknown = sorted(set(defaults) - set(params))
    if unknown:
        raise TypeError(f"variant {name!r} gives defaults for {', '.join(unknown)}, which "
                        f"{getattr(factory, '__qualname__', factory)} does not take")
    params = {k: replace(p, default=defaults[k]) if k in defaults else p for k, p in params.items()}
    summary = doc.splitlines()[0] if doc else ""
    module = getattr(factory, "__module__", "?")
    return MethodInfo(name, factory, params, summary, doc, module, defaults)


def _variant_doc(variant: str, base: str) -> str:
    """A variant's docstring followed by the base's body lines that it does not replace (``name:`` lines
    it gives again, and the base's summary line, are left out)."""
    given = set(_param_help(variant))
    body = base.split("\n", 1)[1] if "\n" in base else ""
    lines, skipping = [], False
    for line in body.splitlines():
        key = line.strip().split(":", 1)[0].split("(")[0].strip() if ":" in line else ""
        if key.isidentifier() and not line.startswith((" ", "\t")):
            skipping = key in given
        elif not line.startswith((" ", "\t")):
            skipping = False
        if not skipping:
            lines.append(line)
    return variant.rstrip() + "\n" + "\n".join(lines)


class PluginRegistry:
    """Names -> registered objects of one kind, filled by decorators and by the plugins of an
    entry-point group. Subclasses say what they hold (``kind``, ``names_attr``, :meth:`_make`)."""

    kind = "object"
    names_attr = "__lfbench_names__"  # the names a decorator gave an object (see :func:`decorated_names`)

    def __init__(self, group: str | None = ENTRY_POINT_GROUP) -> None:
        self._items: dict[str, Any] = {}
        self._group = group
        self._loaded = group is None
        self.load_errors: dict[str, str] = {}

    def _make(self, name: str, obj: Any, **options: Any) -> Any:
        """The stored entry for ``obj`` registered as ``name`` (TypeError if it is of the wrong kind)."""
        return obj

    def _factory(self, entry: Any) -> Any:
        return entry

    def _source(self, entry: Any) -> str:
        return getattr(self._factory(entry), "__module__", "?")

    def register(self, name: str, obj: Any, **options: Any) -> None:
        """Register ``obj`` as ``name`` (``options``: what the registry takes, e.g. a variant's defaults)."""
        if name in self._items and self._factory(self._items[name]) is not obj:
            raise ValueError(f"{self.kind} {name!r} is already registered by {self._source(self._items[name])}")
        self._items[name] = self._make(name, obj, **options)

    def _accepts(self, obj: Any) -> bool:
        """Whether an entry point's object (not a module) is registered under the entry point's name."""
        return callable(obj)

    def _load_entry_point(self, ep: metadata.EntryPoint) -> None:
        try:
            obj = ep.load()
        except Exception as exc:  # a broken plugin must not break the others
            self.load_errors[ep.name] = f"{type(exc).__name__}: {exc}"  # shown by `lfbench methods`
            return
        if isinstance(obj, types.ModuleType):
            self._register_module(obj)
        elif ep.name not in self._items and self._accepts(obj):
            try:
                self.register(ep.name, obj)
            except (TypeError, ValueError) as exc:
                self.load_errors[ep.name] = str(exc)

    def _load_entry_points(self, name: str | None = None) -> None:
        """Load the plugins: only the entry point called ``name`` when there is one (so that using one
        method does not import every plugin, e.g. torch for a metric-only run), else all of them."""
        if self._loaded:
            return
        eps = list(metadata.entry_points(group=self._group))
        if name is not None:
            named = [ep for ep in eps if ep.name == name]
            if named:
                for ep in named:
                    self._load_entry_point(ep)
                if name in self._items:
                    return
        self._loaded = True
        for ep in eps:
            self._load_entry_point(ep)

    def _register_module(self, module: types.ModuleType) -> None:
        """Register what a plugin module's decorators named (its import registered them in the registry
        the decorator named; a fresh registry learns them here), including objects it imported."""
        seen: set[int] = set()
        for obj in list(vars(module).values()):
            if id(obj) in seen:
                continue
            seen.add(id(obj))
            options = _decorated_options(obj, self.names_attr)
            for name in decorated_names(obj, self.names_attr):
                try:
                    self.register(name, obj, **options.get(name, {}))
                except (TypeError, ValueError) as exc:
                    self.load_errors[name] = str(exc)

    def names(self) -> list[str]:
        self._load_entry_points()
        return sorted(self._items)

    def _get(self, name: str) -> Any:
        if name not in self._items:
            self._load_entry_points(name)
        if name not in self._items:
            hint = f" (plugin failed to load: {self.load_errors[name]})" if name in self.load_errors else ""
            raise SpecError(f"unknown {self.kind} {name!r}{hint}; available: {', '.join(self.names()) or 'none'}")
        return self._items[name]


class MethodRegistry(PluginRegistry):
    """Maps method names to factories. ``REGISTRY`` is the process-wide default instance."""

    kind = "method"
    names_attr = "__lfbench_method_names__"

    def _make(self, name: str, obj: Any, defaults: dict[str, Any] | None = None, doc: str | None = None
              ) -> MethodInfo:
        return _introspect(name, obj, defaults, doc)

    def _factory(self, entry: MethodInfo) -> Any:
        return entry.factory

    def _source(self, entry: MethodInfo) -> str:
        return entry.source

    def info(self, name: str) -> MethodInfo:
        return self._get(name)

    def create(self, name: str, **params: Any) -> Any:
        return self._create(name, params, {})

    def _create(self, name: str, params: dict[str, Any], runtime: Mapping[str, Any]) -> Any:
        """The method made with ``params`` (recorded: they name it) plus the ``runtime`` options it accepts
        and ``params`` does not set (not recorded: where it runs does not change what it is)."""
        info = self.info(name)
        unknown = sorted(set(params) - set(info.params))
        if unknown:
            known = ", ".join(info.params) or "none"
            raise SpecError(f"method {name!r} has no parameter {', '.join(map(repr, unknown))}; parameters: {known}")
        missing = [p.name for p in info.params.values()
                   if p.default is inspect.Parameter.empty and p.name not in params]
        if missing:
            raise SpecError(f"method {name!r} needs parameter {', '.join(missing)} (e.g. {name}:{missing[0]}=...)")
        extra = {k: v for k, v in runtime.items() if v is not None and k in info.params and k not in params}
        try:
            method = info.factory(**{**info.defaults, **extra, **params})
        except (ValueError, TypeError) as exc:
            raise SpecError(f"method {name!r}: {exc}") from None
        from lfbench.method.base import Method

        if not isinstance(method, Method):
            raise SpecError(f"method {name!r}: {info.source}.{getattr(info.factory, '__qualname__', info.factory)} "
                            f"returned a {type(method).__name__}, which is not a Method")
        method._bind(name, params)  # how it was made: results name a method by its canonical spec
        return method

    def create_from_spec(self, spec: str, runtime: Mapping[str, Any] | None = None) -> Any:
        """The method of ``name:key=value,...``; ``runtime`` (e.g. ``{"device": "cuda"}`` from ``--device``)
        fills the parameters the method has and the spec leaves out, without entering its label."""
        name, raw = parse_spec(spec)
        info = self.info(name)
        return self._create(name, coerce_params(raw, info.params, name), runtime or {})


def coerce_params(raw: dict[str, str], params: dict[str, Param], owner: str, kind: str = "method") -> dict[str, Any]:
    """Spec values (text) converted to the types of ``params``; SpecError for a name not among them."""
    out = {}
    for key, text in raw.items():
        if key not in params:
            known = ", ".join(params) or "none"
            raise SpecError(f"{kind} {owner!r} has no parameter {key!r}; parameters: {known}")
        out[key] = coerce(text, params[key], owner)
    return out


REGISTRY = MethodRegistry()


def register_method(name: str, registry: MethodRegistry | None = None, *, defaults: dict[str, Any] | None = None,
                    doc: str | None = None) -> Callable:
    """Class or function decorator: make a method factory (a Method subclass, or a function returning a
    Method) available as ``name``. A variant registers the same factory under another name with its own
    ``defaults`` (replacing the signature's) and ``doc`` (summary line; ``name: help`` lines replace the
    factory's), the way timm registers resnet18 = ``_create_resnet("resnet18", **dict(defaults, **kwargs))``."""
    options = {k: v for k, v in (("defaults", defaults), ("doc", doc)) if v is not None}
    return _decorator(name, registry or REGISTRY, **options)


def _decorator(name: str, registry: PluginRegistry, **options: Any) -> Callable:
    def deco(obj: Any) -> Any:
        registry.register(name, obj, **options)
        try:  # remember the name (and options) so that any registry loading the module finds the object
            setattr(obj, registry.names_attr, (*decorated_names(obj, registry.names_attr), name))
            setattr(obj, registry.names_attr + "options",
                    {**_decorated_options(obj, registry.names_attr), name: options})
        except (AttributeError, TypeError):
            pass
        return obj

    return deco


def _decorated_options(obj: Any, attr: str) -> dict[str, dict[str, Any]]:
    try:
        return dict(vars(obj).get(attr + "options", {}))
    except TypeError:  # no __dict__
        return {}


def decorated_names(obj: Any, attr: str = MethodRegistry.names_attr) -> tuple[str, ...]:
    """Names given to ``obj`` itself by a registering decorator (not inherited from a registered base class)."""
    try:
        return tuple(vars(obj).get(attr, ()))
    except TypeError:  # no __dict__
        return ()


def create(name: str, **params: Any) -> Any:
    """Create a registered method with keyword parameters (variants are parameters)."""
    return REGISTRY.create(name, **params)


def create_from_spec(spec: str, runtime: Mapping[str, Any] | None = None) -> Any:
    """Create a method from ``name:key=value,key=value`` (``runtime``: see MethodRegistry.create_from_spec)."""
    return REGISTRY.create_from_spec(spec, runtime)


def list_methods() -> list[MethodInfo]:
    return [REGISTRY.info(n) for n in REGISTRY.names()]


def method_info(name: str) -> MethodInfo:
    return REGISTRY.info(name)


def offline_variants(name: str) -> list[dict[str, Any]]:
    """Parameter sets under which ``name`` runs with what is installed: the ``Method.offline_variants()``
    of the method made with its defaults (e.g. ``[{"width": 16}]``, the architecture of its shipped weights)
    when it implements the hook and offers a non-empty list, else ``[{}]`` (its defaults). A method that
    needs a parameter (no defaults) and does not implement the hook is not made."""
    from lfbench.method.base import overrides

    info = REGISTRY.info(name)
    cls = info.factory if inspect.isclass(info.factory) else None
    if cls is not None and not overrides(cls, "offline_variants"):
        return [{}]
    return REGISTRY.create(name).offline_variants() or [{}]


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


_TRUE, _FALSE = {"1", "true", "yes", "on"}, {"0", "false", "no", "off"}


def coerce(text: str, param: Param, method: str = "") -> Any:
    """Convert a spec value to the parameter's annotated type (bool, int, float, str, Path, Optional, Literal)."""
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
                return coerce(text, Param(param.name, a, param.default), method)
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


__all__ = ["register_method", "create", "create_from_spec", "list_methods", "method_info", "parse_spec",
           "format_spec", "MethodRegistry", "PluginRegistry", "REGISTRY", "ENTRY_POINT_GROUP", "Param", "MethodInfo",
           "signature_params", "coerce_params", "decorated_names"]
