"""One generic registry: names -> objects of one kind (methods, trainable networks, metrics, losses,
commands), in the style of lm-evaluation-harness's ``Registry(base_cls=...)``.

- :meth:`Registry.add` refuses an object of the wrong kind (not a ``base_cls`` subclass or instance)
  and a second, different object under a taken name;
- :meth:`Registry.get` answers an unknown name with ``Unknown <kind> 'x'. Available: a, b, c``
  (:class:`~lfbench.utils.errors.SpecError`, one line);
- an entry may be *lazy*: ``"module"`` or ``"module:attribute"``, imported on first :meth:`get` and
  checked then (a command's module is imported only when that command runs);
- a registry with an entry-point ``group`` loads the plugins of that group on demand: the entry point
  of the asked name first, every entry point only when that is not enough (listing all names).
  An entry point names a module (importing it runs the plugin's registering decorators) or an object
  (registered under the entry point's name when it is of this registry's kind); a registry may load its
  entry points its own way (``load=``: a command is a :class:`Lazy` of its module, a paper reference its
  data file read). lfbench's own entries (``builtins=``) come first, as entry points of the group, and a
  plugin cannot replace one. A plugin that fails to load is recorded in :attr:`Registry.load_errors` and
  does not break the others.

This is the one entry-point loader: methods, trainable networks, metrics, datasets, commands and
references all load their plugins through it.
"""

from __future__ import annotations

import importlib
import inspect
import types
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from importlib import metadata
from typing import Any, Generic, TypeVar

from lfbench.utils.errors import SpecError

T = TypeVar("T")


class NameTaken(ValueError):
    """A name registered a second time for another object (:meth:`Registry.add`)."""


@dataclass(frozen=True)
class Lazy:
    """A registered object not imported yet: ``target`` is ``"module"`` or ``"module:attribute"``."""

    target: str

    def load(self) -> Any:
        module, _, attr = self.target.partition(":")
        obj = importlib.import_module(module)
        for part in filter(None, attr.split(".")):
            obj = getattr(obj, part)
        return obj


def describe(obj: Any) -> str:
    """``module.QualName`` of a class or function (the object's repr otherwise), for messages."""
    name = getattr(obj, "__qualname__", None) or getattr(obj, "__name__", None)
    module = getattr(obj, "__module__", None)
    return f"{module}.{name}" if name and module else repr(obj)[:80]


class Registry(Generic[T]):
    """Names -> registered entries of one ``kind``.

    ``base_cls``: what may be registered: a subclass or an instance of it (a runtime-checkable Protocol
    works too); None accepts anything callable. ``factories``: functions are accepted as well (they
    make a ``base_cls`` when called; the caller checks what they return). ``group``: the entry-point
    group whose plugins fill the registry; ``load(entry_point)``: the object an entry point registers
    (default: ``entry_point.load()``); ``builtins``: lfbench's own entries of the group, name -> target,
    loaded first whether or not the install's metadata lists them (an older install's may not). An
    *entry* is what :meth:`get` returns: the object itself, or what ``make(name, obj)`` derives from it
    (e.g. a method's introspected info), or the ``entry=`` given to :meth:`add`.
    """

    def __init__(self, kind: str, base_cls: type | None = None, *, group: str | None = None,
                 factories: bool = False, make: Callable[[str, Any], T] | None = None,
                 load: Callable[[metadata.EntryPoint], Any] | None = None,
                 builtins: Mapping[str, str] | None = None) -> None:
        self.kind = kind
        self.base_cls = base_cls
        self.group = group
        self.factories = factories
        self.make = make
        self.load = load
        self.builtins = dict(builtins or {})
        self._objects: dict[str, Any] = {}  # name -> the registered object (or a Lazy)
        self._entries: dict[str, T] = {}
        self._aliases: dict[str, str] = {}  # other name -> name
        self._loaded = group is None
        self.load_errors: dict[str, str] = {}  # entry-point name -> why it did not load

    # -- registering -----------------------------------------------------------------------------

    def accepts(self, obj: Any) -> bool:
        """Whether ``obj`` is of this registry's kind."""
        if self.base_cls is None:
            return callable(obj)
        if inspect.isclass(obj):
            return issubclass(obj, self.base_cls)
        if self.factories and (inspect.isfunction(obj) or inspect.ismethod(obj)):
            return True
        return isinstance(obj, self.base_cls)

    def check(self, name: str, obj: Any) -> None:
        """TypeError naming ``obj`` when it is not of this registry's kind."""
        if not self.accepts(obj):
            what = self.base_cls.__name__ if self.base_cls is not None else "callable"
            raise TypeError(f"{describe(obj)} registered as {self.kind} {name!r} is not a {what}")

    def add(self, name: str, obj: Any, *, entry: Any = None, aliases: tuple[str, ...] = ()) -> None:
        """Register ``obj`` as ``name`` (and ``aliases``), stored as ``entry`` (default: ``make(name, obj)``,
        or ``obj``). The same object again is a no-op; another object under a taken name is a ValueError;
        ``obj`` of the wrong kind a TypeError. A :class:`Lazy` object is checked when it is first loaded."""
        if not isinstance(obj, Lazy):
            self.check(name, obj)
        for key in (name, *aliases):
            owner = self._aliases.get(key, key)
            if owner in self._objects and not self._same(self._objects[owner], obj):
                raise NameTaken(f"{self.kind} {key!r} is already registered by {self._source(owner)}")
        if entry is None and self.make is not None and not isinstance(obj, Lazy):
            entry = self.make(name, obj)
        self._objects[name] = obj
        self._entries[name] = obj if entry is None else entry
        for alias in aliases:
            self._aliases.setdefault(alias, name)

    @staticmethod
    def _same(a: Any, b: Any) -> bool:
        try:
            return a is b or bool(a == b)
        except Exception:  # noqa: BLE001 - an object whose == fails is simply not the same one
            return False

    def _source(self, name: str) -> str:
        obj = self._objects[name]
        return obj.target if isinstance(obj, Lazy) else getattr(obj, "__module__", None) or describe(obj)

    def decorator(self, name: str) -> Callable[[Any], Any]:
        """A decorator registering what it decorates as ``name``."""
        def deco(obj: Any) -> Any:
            self.add(name, obj)
            return obj

        return deco

    # -- looking up ------------------------------------------------------------------------------

    def find(self, name: str) -> T | None:
        """The entry of ``name`` (or an alias), loading plugins as needed; None when there is none."""
        key = self._aliases.get(name, name)
        if key not in self._objects:
            self._load_entry_points(name)
            key = self._aliases.get(name, name)
        if key not in self._objects:
            return None
        obj = self._objects[key]
        if isinstance(obj, Lazy):
            loaded = obj.load()
            self.check(key, loaded)
            self._objects[key] = loaded
            self._entries[key] = self.make(key, loaded) if self.make is not None else loaded
        return self._entries[key]

    def get(self, name: str) -> T:
        """The entry of ``name``; SpecError ``Unknown <kind> 'name'. Available: ...`` otherwise."""
        found = self.find(name)
        if found is None:
            raise self.unknown(name)
        return found

    def unknown(self, name: str, available: list[str] | None = None) -> SpecError:
        """The error for a name this registry lacks (with why its plugin failed to load, if it did)."""
        hint = f" (plugin failed to load: {self.load_errors[name]})" if name in self.load_errors else ""
        names = self.names() if available is None else available
        return SpecError(f"Unknown {self.kind} {name!r}{hint}. Available: {', '.join(names) or 'none'}")

    def names(self) -> list[str]:
        """Every registered name, sorted (loads every plugin of the group)."""
        self._load_entry_points()
        return sorted(self._objects)

    def registered(self) -> list[str]:
        """The names registered so far, in registration order, without loading plugins."""
        return list(self._objects)

    def target(self, name: str) -> str | None:
        """The import target of a lazy entry not loaded yet (None otherwise)."""
        obj = self._objects.get(name)
        return obj.target if isinstance(obj, Lazy) else None

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self.find(name) is not None

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self.names())

    def __getitem__(self, name: str) -> T:
        return self.get(name)

    # -- plugins ---------------------------------------------------------------------------------

    def entry_points(self) -> list[metadata.EntryPoint]:
        """The entry points of the group: lfbench's own (``builtins``) first, then the plugins', by name
        (none without a group)."""
        if self.group is None:
            return []
        own = [metadata.EntryPoint(name=n, value=v, group=self.group) for n, v in self.builtins.items()]
        plugins = (ep for ep in metadata.entry_points(group=self.group) if ep.value not in self.builtins.values())
        return own + sorted(plugins, key=lambda ep: ep.name)

    def _load_entry_points(self, name: str | None = None) -> None:
        """Load the plugins: only the entry points called ``name`` when there are some (so that using one
        method does not import every plugin, e.g. torch for a metric-only run), else all of them."""
        if self._loaded:
            return
        eps = self.entry_points()
        if name is not None:
            named = [ep for ep in eps if ep.name == name]
            for ep in named:
                self._load_entry_point(ep)
            if named and self._aliases.get(name, name) in self._objects:
                return
        self._loaded = True
        for ep in eps:
            self._load_entry_point(ep)

    def _load_entry_point(self, ep: metadata.EntryPoint) -> None:
        if ep.name in self.builtins and ep.value != self.builtins[ep.name]:
            self.load_errors[ep.name] = f"{ep.value} would replace a built-in {self.kind}; left out"
            return
        try:
            obj = self.load(ep) if self.load is not None else ep.load()
        except NameTaken as exc:
            self.name_taken(ep, exc)
            return
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break the others
            self.load_errors[ep.name] = f"{type(exc).__name__}: {exc}"  # shown by `lfbench methods`
            return
        if isinstance(obj, types.ModuleType) or ep.name in self._objects:
            return  # a module registered what it holds when it was imported
        if not (isinstance(obj, Lazy) or self.accepts(obj)):
            return
        try:
            self.add(ep.name, obj)
        except NameTaken as exc:
            self.name_taken(ep, exc)
        except (TypeError, ValueError) as exc:
            self.load_errors[ep.name] = str(exc)

    def name_taken(self, ep: metadata.EntryPoint, exc: NameTaken) -> None:
        """A plugin (entry point ``ep``) registered a name another entry has: recorded in :attr:`load_errors`
        (the plugin is left out); a registry where one name must mean one thing raises instead."""
        self.load_errors[ep.name] = str(exc)


__all__ = ["Lazy", "NameTaken", "Registry", "describe"]
