"""The method registry: ``@register_method("name")``, ``create("name", **params)``, spec strings.

Built-in methods and third-party plugins are found the same way: through the entry-point group
``lfbench.methods``. An entry point names a module (importing it runs its ``@register_method`` and
``@register_trainable`` decorators) or a factory (registered under the entry point's name).

A registered trainable network is a method too: ``NAME:weights=PATH`` runs its weights through the
generic network method (lfbench.method.network_method) unless a method of that name is registered
(the two-class style, e.g. SubFocal's own method with its shipped weights).

A spec string selects a method and its parameters on the command line: ``name`` or
``name:key=value,key=value``; values are converted to the types of the factory's signature
(lfbench.method.params).
"""

from __future__ import annotations

import inspect
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from lfbench.method.base import Method, overrides
from lfbench.method.network_method import NetworkMethod, network_method_params
from lfbench.method.params import (
    Param,
    coerce,
    coerce_params,
    docstring_help,
    format_spec,
    parse_spec,
    signature_params,
    without_help_lines,
)
from lfbench.method.trainable import ENTRY_POINT_GROUP, TRAINABLES, Trainable
from lfbench.utils.errors import SpecError
from lfbench.utils.registry import Registry


@dataclass(frozen=True)
class MethodInfo:
    """A registered method: its factory (a Method subclass or a function returning a Method), its
    parameters (with this name's defaults), summary and description, the module it comes from, the
    ``defaults`` a variant gives the factory (``lfattnet`` = SubFocal with interval 1), the Method class
    it makes (None for a plain function factory) and the trainable network it runs, if any."""

    name: str
    factory: Callable[..., Any]
    params: dict[str, Param]
    summary: str
    doc: str
    source: str
    defaults: dict[str, Any] = field(default_factory=dict)
    method_class: type | None = None
    network: str | None = None

    @property
    def description(self) -> str:
        """The docstring after its summary, without the ``name: help`` lines the parameter list shows."""
        body = self.doc.split("\n", 1)[1] if "\n" in self.doc else ""
        return without_help_lines(body, self.params)

    def network_params(self) -> dict[str, Param]:
        """The parameters of the network this method runs: for the generic network method, those of its
        parameters that are the network's; for a method of the two-class style, the network's that it does not
        take itself (its trainable's ``[model]`` keys and ablation axes); empty otherwise (a subclass of the
        network method, such as SubFocal's, takes or fixes them itself)."""
        trainable = TRAINABLES.find(self.network) if self.network else None
        if trainable is None or self.method_class is None:
            return {}
        if self.method_class is NetworkMethod:
            return {k: self.params[k] for k in trainable.parameters() if k in self.params}
        if issubclass(self.method_class, NetworkMethod):
            return {}
        return {k: p for k, p in trainable.parameters().items() if k not in self.params}

    def describe(self) -> str:
        network = self.network_params()
        own = [p for p in self.params.values() if p.name not in network]
        lines = [f"{self.name}: {self.summary}", f"  source: {self.source}"]
        if own:
            lines.append("  parameters:")
            lines += [f"    {p.describe()}" for p in own]
        if network:
            note = "with weights=..., the weights' own (given, they must agree); " \
                if self.method_class is NetworkMethod else ""
            lines.append(f"  network parameters ({note}the [model] keys of lfbench train and the ablation axes of "
                         f"network {self.network!r}):")
            lines += [f"    {p.describe()}" for p in network.values()]
        return "\n".join(lines)


def _introspect(name: str, factory: Callable[..., Any], defaults: dict[str, Any] | None = None,
                doc: str | None = None, help: dict[str, str] | None = None) -> MethodInfo:  # noqa: A002
    """The MethodInfo of ``factory`` registered as ``name``; a variant passes its ``defaults`` (they replace
    the signature's), its own ``doc`` (summary and description) and ``help`` for parameters it words anew."""
    own = inspect.getdoc(factory) or ""
    params = signature_params(factory, own)
    if doc:
        doc = inspect.cleandoc(doc)
        legacy = {k: v for k, v in docstring_help(doc).items() if k in params}  # a variant's `name: text` lines
        help = {**legacy, **(help or {})}  # noqa: A001
    else:
        doc = own
    defaults = dict(defaults or {})
    for what, given in (("defaults", defaults), ("help", help or {})):
        unknown = sorted(set(given) - set(params))
        if unknown:
            raise TypeError(f"variant {name!r} gives {what} for {', '.join(unknown)}, which "
                            f"{getattr(factory, '__qualname__', factory)} does not take")
    params = {k: replace(p, default=defaults.get(k, p.default), help=(help or {}).get(k, p.help))
              for k, p in params.items()}
    summary = doc.splitlines()[0] if doc else ""
    cls = factory if inspect.isclass(factory) else None
    network = getattr(cls, "network", None) if cls is not None and issubclass(cls, NetworkMethod) else None
    return MethodInfo(name, factory, params, summary, doc, getattr(factory, "__module__", "?"), defaults, cls,
                      network or (name if TRAINABLES.find(name) is not None else None))


def names_file(param: Param) -> bool:
    """Whether ``param`` names a file: typed ``Path`` (or ``Path | None``), or called ``weights``."""
    kinds = (param.kind, *typing.get_args(param.kind))
    return param.name == "weights" or any(k is Path for k in kinds)


def network_method_info(trainable: Trainable) -> MethodInfo:
    """The MethodInfo of the generic network method running ``trainable``'s weights (``NAME:weights=...``)."""
    name = trainable.name

    def make(**params: Any) -> NetworkMethod:
        return NetworkMethod(network=name, **params)

    make.__qualname__ = make.__name__ = f"NetworkMethod[{name}]"
    body = trainable.description()
    doc = f"{trainable.summary}\n\n{body}" if body else trainable.summary
    return MethodInfo(name, make, network_method_params(trainable), trainable.summary, doc,
                      type(trainable).__module__, {}, NetworkMethod, name)


class MethodRegistry(Registry[MethodInfo]):
    """Maps method names to factories (a :class:`~lfbench.utils.registry.Registry` of :class:`Method`),
    with the registered trainable networks as methods of their own name; ``REGISTRY`` is the process-wide
    instance."""

    def __init__(self, group: str | None = ENTRY_POINT_GROUP, *, networks: bool | None = None) -> None:
        super().__init__("method", Method, group=group, factories=True, make=_introspect)
        #: whether the registered trainable networks without a method of their own are methods (default: for
        #: a registry of the plugins, i.e. with an entry-point group)
        self.networks = group is not None if networks is None else networks

    def register(self, name: str, obj: Any, *, defaults: dict[str, Any] | None = None, doc: str | None = None,
                 help: dict[str, str] | None = None) -> None:  # noqa: A002
        """Register ``obj`` (a Method subclass or a factory) as ``name`` (see :func:`register_method`)."""
        self.check(name, obj)
        self.add(name, obj, entry=_introspect(name, obj, defaults, doc, help))

    def find(self, name: str) -> MethodInfo | None:
        found = super().find(name)
        if found is None and self.networks:
            trainable = TRAINABLES.find(name)
            if trainable is not None and trainable.method_name == name:
                return network_method_info(trainable)
        return found

    def names(self) -> list[str]:
        names = set(super().names())
        if self.networks:
            names |= {n for n in TRAINABLES.names() if TRAINABLES.find(n).method_name == n}
        return sorted(names)

    def info(self, name: str) -> MethodInfo:
        return self.get(name)

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
        missing = [p.name for p in info.params.values() if p.required and p.name not in params]
        if missing:
            raise SpecError(f"method {name!r} needs parameter {', '.join(missing)} (e.g. {name}:{missing[0]}=...)")
        extra = {k: v for k, v in runtime.items() if v is not None and k in info.params and k not in params}
        try:
            method = info.factory(**{**info.defaults, **extra, **params})
        except (ValueError, TypeError) as exc:
            raise SpecError(f"method {name!r}: {exc}") from None
        if not isinstance(method, Method):
            raise SpecError(f"method {name!r}: {info.source}.{getattr(info.factory, '__qualname__', info.factory)} "
                            f"returned a {type(method).__name__}, which is not a Method")
        if self.network_of(name) is not None:  # the two-class style too: keyed by the weights' content, not path
            files = tuple(k for k, p in info.params.items() if names_file(p) and k not in method.content_params)
            if files:
                method.content_params = (*method.content_params, *files)
        method._bind(name, params)  # how it was made: results name a method by its canonical spec
        return method

    def network_of(self, name: str) -> str | None:
        """The registered trainable network method ``name`` runs, or None: the generic network method's, a
        subclass's, or that of a method of its own (the two-class style) named like a network or as a network's
        ``method`` (found now, whatever the order in which the plugin registered its two classes)."""
        info = self.info(name)
        if info.network is not None:
            return info.network
        if TRAINABLES.find(name) is not None:
            return name
        return next((n for n in TRAINABLES.names() if TRAINABLES.find(n).method_name == name), None)

    def create_from_spec(self, spec: str, runtime: Mapping[str, Any] | None = None,
                         defaults: Callable[[MethodInfo, dict[str, Any]], Mapping[str, Any]] | None = None) -> Any:
        """The method of ``name:key=value,...``; ``runtime`` (e.g. ``{"device": "cuda"}`` from ``--device``)
        fills the parameters the method has and the spec leaves out, without entering its label.
        ``defaults(info, params)``: parameters the spec leaves out that are set anyway and recorded (they
        enter the label), e.g. the disparity range a dataset declares (lfbench.data.dataset)."""
        name, raw = parse_spec(spec)
        info = self.info(name)
        params = coerce_params(raw, info.params, name)
        if defaults is not None:
            params = {**{k: v for k, v in defaults(info, params).items() if k in info.params}, **params}
        return self._create(name, params, runtime or {})


#: Every registered method, by name (the ``lfbench.methods`` entry points fill it).
REGISTRY = MethodRegistry()


def register_method(name: str, registry: MethodRegistry | None = None, *, defaults: dict[str, Any] | None = None,
                    doc: str | None = None, help: dict[str, str] | None = None) -> Callable:  # noqa: A002
    """Class or function decorator: make a method factory (a Method subclass, or a function returning a
    Method) available as ``name``. A variant registers the same factory under another name with its own
    ``defaults`` (replacing the signature's), ``doc`` (summary line and description) and ``help`` (parameter
    help worded for the variant), the way timm registers resnet18 = ``_create_resnet("resnet18", **kwargs)``."""
    def deco(obj: Any) -> Any:
        (registry if registry is not None else REGISTRY).register(name, obj, defaults=defaults, doc=doc, help=help)
        return obj

    return deco


def create(name: str, **params: Any) -> Any:
    """Create a registered method with keyword parameters (variants are parameters)."""
    return REGISTRY.create(name, **params)


def create_from_spec(spec: str, runtime: Mapping[str, Any] | None = None,
                     defaults: Callable[[MethodInfo, dict[str, Any]], Mapping[str, Any]] | None = None) -> Any:
    """Create a method from ``name:key=value,key=value`` (``runtime``, ``defaults``: see
    MethodRegistry.create_from_spec)."""
    return REGISTRY.create_from_spec(spec, runtime, defaults)


def list_methods() -> list[MethodInfo]:
    return [REGISTRY.info(n) for n in REGISTRY.names()]


def network_runner(network: str, weights: str | Path, *, device: str = "cpu", **options: Any) -> Method:
    """The registered method running ``weights`` of the trainable ``network`` (its ``method``, by default the
    generic network method) on ``device``; ``options`` (threads, tile, precision, max_memory_gb, ...) are
    passed when the method has such a parameter and left out otherwise."""
    from lfbench.method.trainable import get_trainable

    name = get_trainable(network).method_name
    accepted = REGISTRY.info(name).params
    method = create(name, weights=Path(weights), **{k: v for k, v in options.items() if k in accepted})
    return method.to(device)


def offline_variants(name: str) -> list[dict[str, Any]]:
    """Parameter sets under which ``name`` runs with what is installed: the ``Method.offline_variants()``
    of the method made with its defaults (e.g. ``[{"width": 16}]``, the architecture of its shipped weights)
    when it implements the hook and offers a non-empty list, else ``[{}]`` (its defaults). A method that
    needs a parameter (no defaults) and does not implement the hook is not made."""
    info = REGISTRY.info(name)
    cls = info.method_class
    if cls is None or not overrides(cls, "offline_variants"):
        return [{}]
    return REGISTRY.create(name).offline_variants() or [{}]


__all__ = ["register_method", "create", "create_from_spec", "list_methods", "parse_spec",
           "format_spec", "coerce", "coerce_params", "MethodRegistry", "REGISTRY", "ENTRY_POINT_GROUP",
           "Param", "MethodInfo", "names_file", "signature_params", "network_method_info", "network_runner",
           "offline_variants"]
