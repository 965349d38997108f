"""Trainable networks: what a plugin declares so that ``lfbench train``, ``lfbench ablate`` and
``lfbench bench`` work for its network without a line of lfbench changing.

A plugin subclasses :class:`Trainable`, decorates it with ``@register_trainable("name")`` in a module of
its ``lfbench.methods`` entry points (the same group and usually the same module as the :class:`Method`
that runs its checkpoints), and says:

- how to build the network from the ``[model]`` table of a training config: :meth:`Trainable.build`
  (default ``network(**params)``); its keyword parameters, documented by ``name: help`` lines of the
  class docstring, are the ``[model]`` keys and the ablation axes (:attr:`Trainable.axes`);
- what the network returns (the contract below) and whether it has a distribution over disparities
  (:attr:`Trainable.distribution`; the distribution losses js, kl, l1+js, l1+kl, uafl need one);
- optionally, how a stage is optimised: :meth:`Trainable.configure_optimizers` (default: Adam with the
  stage's lr, betas and eps, a constant rate);
- how a trained checkpoint becomes a runnable method: :attr:`Trainable.method` (the registered
  method that takes ``weights=PATH``, default the same name) and :meth:`Trainable.runner`;
- what ``lfbench bench`` times: :meth:`Trainable.infer` (one whole light field), :meth:`Trainable.flops`
  and extra benches (:attr:`Trainable.benches`).

The network contract (a ``torch.nn.Module``):

- ``forward(views)``: views (B, N, H, W) float32 gray in [0, 1], N = angular^2, view k at angular row
  ``k // angular``, column ``k % angular`` -> ``(disparity, probability)``: disparity (B, H, W) in px per
  view step, probability (B, D, H, W) over ``disparities`` (softmax over D) or None;
- ``angular`` (int, default 9): views per angular row;
- ``disparities``: (D,) tensor of the candidate disparities (px), evenly spaced, when it has a distribution;
- ``config()`` (optional): the build keyword arguments that rebuild it (stored in checkpoints; default:
  the ``[model]`` parameters it was built with).

Checkpoints (``final.pt``, ``best.pt``, ``stage<k>_<name>.pt``) hold ``{"format", "method",
"state_dict", "config", "training"}``; :meth:`Trainable.load` rebuilds the network from one
(``torch.load(weights_only=True)``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from lfbench.method.registry import ENTRY_POINT_GROUP, Param, PluginRegistry, _decorator, signature_params
from lfbench.utils.errors import DataError

if TYPE_CHECKING:  # torch is imported where a network is built, not by `lfbench methods`
    import torch

    from lfbench.method.base import Method

DEFAULT_TRAINABLE = "subfocal"  # what a training config without ``method = ...`` trains
#: The most a network may hold in parameters and buffers (SubFocal at the paper's width: 19 MiB; at its
#: largest width, 1024: 0.7 GiB), checked on PyTorch's meta device before the network is built for real.
MAX_NETWORK_BYTES = 2 * 1024**3


def network_bytes(build: Callable[..., torch.nn.Module], params: dict[str, Any]) -> int | None:
    """Bytes of the parameters and buffers ``build(**params)`` would allocate, from a build on PyTorch's
    meta device (shapes only: nothing is allocated or initialised); None when the constructor cannot
    run there (e.g. it reads a tensor's value). ValueError/TypeError of the constructor propagate."""
    import torch

    try:
        with torch.device("meta"):
            net = build(**params)
    except (ValueError, TypeError):
        raise
    except Exception:  # noqa: BLE001 - a constructor that needs real tensors: its size is unknown here
        return None
    tensors = [*net.parameters(), *net.buffers()] if isinstance(net, torch.nn.Module) else []
    return sum(t.numel() * t.element_size() for t in tensors)


def check_network_size(build: Callable[..., torch.nn.Module], params: dict[str, Any]) -> int | None:
    """ValueError when ``build(**params)`` would hold more than MAX_NETWORK_BYTES; else its size in bytes
    (None when it cannot be known before a real build: see :func:`network_bytes`)."""
    size = network_bytes(build, params)
    if size is not None and size > MAX_NETWORK_BYTES:
        raise ValueError(f"the network would hold {size / 1024**3:.3g} GiB of parameters and buffers, more than "
                         f"lfbench builds ({MAX_NETWORK_BYTES / 1024**3:g} GiB)")
    return size


class StageOptions(Protocol):
    """What :meth:`Trainable.configure_optimizers` reads of a training stage (lfbench.training.config.StageConfig)."""

    name: str
    lr: float
    steps: int
    eps: float
    betas: tuple[float, float]


class Trainable:
    """A network that lfbench can train, ablate and time (see the module docstring for the contract).

    Subclasses set :attr:`network` (or override :meth:`build`) and document the parameters with
    ``name: help`` lines in their docstring. The registry sets :attr:`name`.
    """

    name: str = ""
    #: The nn.Module class that :meth:`build` instantiates with the [model] parameters.
    network: ClassVar[type | None] = None
    #: The registered method that runs a checkpoint as ``method:weights=PATH`` ("" = this trainable's name).
    method: ClassVar[str] = ""
    #: Whether forward returns a probability over ``disparities`` (needed by the distribution losses).
    distribution: ClassVar[bool] = False
    #: The parameters an ablation may vary (None = every build parameter), in the order error messages list.
    axes: ClassVar[tuple[str, ...] | None] = None
    #: Defaults that replace the network's own (a variant: e.g. ``lfattnet`` is SubFocal with interval 1).
    defaults: ClassVar[dict[str, Any]] = {}
    #: Extra ``lfbench bench`` cases: name -> function(**params) returning a record dict with "bench".
    benches: ClassVar[dict[str, Callable[..., dict]]] = {}

    # -- building ------------------------------------------------------------------------------

    def build(self, **params: Any) -> torch.nn.Module:
        """The network for the ``[model]`` parameters (ValueError/TypeError for bad values)."""
        if self.network is None:
            raise NotImplementedError(f"{type(self).__name__} sets no network and does not override build()")
        return self.network(**{**self.defaults, **params})

    def parameters(self) -> dict[str, Param]:
        """The build keyword parameters (types, defaults, help from the class docstring)."""
        target = self.build if type(self).build is not Trainable.build else self.network
        if target is None:
            return {}
        docs = [c.__doc__ for c in type(self).__mro__ if issubclass(c, Trainable) and c is not Trainable]
        doc = "\n".join(inspect.cleandoc(d) for d in (*docs, inspect.getdoc(target)) if d)
        params = signature_params(target, doc)
        return {k: dataclasses.replace(p, default=self.defaults[k]) if k in self.defaults else p
                for k, p in params.items()}

    def ablation_axes(self) -> tuple[str, ...]:
        """The parameters an ablation grid may vary."""
        return tuple(self.axes) if self.axes is not None else tuple(self.parameters())

    def check(self, params: dict[str, Any]) -> None:
        """Raise ValueError/TypeError if ``params`` cannot build the network. Unknown keys and the network's
        size are checked by :meth:`check_params`. This default builds the network on PyTorch's meta device
        (shapes only: no memory, no initialisation), and for real only when its constructor cannot run
        there (e.g. it reads a tensor's value; such a network's size cannot be bounded before it is
        built); override with a cheaper check where one exists."""
        if check_network_size(self.build, params) is None:  # a constructor that needs real tensors decides
            self.build(**params)

    def check_params(self, params: dict[str, Any]) -> None:
        """ValueError naming unknown [model] keys, then :meth:`check`, then the network's size: at most
        MAX_NETWORK_BYTES of parameters and buffers (a build on the meta device, for every network)."""
        accepted = set(self.parameters())
        unknown = sorted(set(params) - accepted)
        if unknown:
            raise ValueError(f"unknown [model] key(s) {', '.join(unknown)} (accepted: {', '.join(sorted(accepted))})")
        self.check(params)
        if type(self).check is not Trainable.check:  # the default check has measured it already
            check_network_size(self.build, params)

    def config_of(self, net: torch.nn.Module, params: dict[str, Any]) -> dict[str, Any]:
        """What a checkpoint stores as ``config``: ``net.config()`` when the network has one, else ``params``."""
        config = getattr(net, "config", None)
        return dict(config()) if callable(config) else dict(params)

    # -- training --------------------------------------------------------------------------------

    def configure_optimizers(self, net: torch.nn.Module, stage: StageOptions
                             ) -> torch.optim.Optimizer | tuple[torch.optim.Optimizer, Any]:
        """The optimizer of one training stage (``lfbench train`` makes a fresh one per stage) and, optionally,
        its learning-rate schedule (a ``torch.optim.lr_scheduler`` stepped after every optimizer step; its
        state is kept in checkpoints): an optimizer, or ``(optimizer, schedule or None)``. ``stage`` holds
        the stage's options (``lr``, ``betas``, ``eps``, ``steps``, ``name``). Default: Adam with the stage's
        lr, betas and eps (1e-7, Keras's), at a constant rate (so the steps of the stage in progress may
        change on resume)."""
        import torch

        return torch.optim.Adam(net.parameters(), lr=stage.lr, betas=stage.betas, eps=stage.eps)

    # -- checkpoints -----------------------------------------------------------------------------

    def load(self, path: str | Path, **overrides: Any) -> torch.nn.Module:
        """The network of a checkpoint (eval mode), rebuilt from its stored config with ``overrides``
        (entries that do not change the weights' shapes); DataError naming the file otherwise."""
        from lfbench.training import checkpoint as ckpt

        payload = ckpt.load(path)
        state, config = payload.get("state_dict"), payload.get("config")
        if not isinstance(state, dict) or not isinstance(config, dict):
            raise DataError("not an lfbench weights file (expected 'state_dict' and 'config')", path)
        return network_from_state(self.build, state, {**config, **overrides}, path)

    @property
    def method_name(self) -> str:
        return self.method or self.name

    def runner(self, weights: str | Path, *, device: str = "cpu", **options: Any) -> Method:
        """The registered method running ``weights`` on ``device``; ``options`` (threads, tile, precision,
        max_memory_gb, ...) are passed when the method has such a parameter and left out otherwise."""
        from lfbench.method.registry import create, method_info

        accepted = method_info(self.method_name).params
        method = create(self.method_name, weights=Path(weights),
                        **{k: v for k, v in options.items() if k in accepted})
        return method.to(device)

    # -- timing ----------------------------------------------------------------------------------

    def infer(self, net: torch.nn.Module, views: torch.Tensor, *, precision: str = "fp32", max_memory_gb: float = 4.0,
              tile: int = 0, timings: dict | None = None) -> tuple[torch.Tensor, torch.Tensor | None]:
        """One inference pass as ``lfbench bench inference`` times it: views (B, N, H, W) ->
        (disparity (B, H, W), probability or None). Default: ``net(views)`` in inference mode, under
        bf16 autocast for precision ``bf16`` (tile and max_memory_gb are the plugin's to use)."""
        import torch

        autocast = (torch.autocast("cpu" if views.device.type == "cpu" else views.device.type, dtype=torch.bfloat16)
                    if precision == "bf16" else contextlib.nullcontext())
        with torch.inference_mode(), autocast:
            return net.eval()(views)

    def flops(self, net: torch.nn.Module, height: int, width: int) -> dict[str, float] | None:
        """Floating-point operations of one eval forward on an H x W light field (``{"total": ...}`` and
        any parts), or None when unknown (then bench records carry no GFLOP/s)."""
        return None


def network_from_state(build: Callable[..., torch.nn.Module], state: dict, config: dict, path: str | Path
                       ) -> torch.nn.Module:
    """``build(**config)`` with ``state`` loaded, in eval mode; DataError naming ``path`` (the checkpoint)
    when the config does not build, would hold more than MAX_NETWORK_BYTES (checked on the meta device
    before anything is allocated) or the weights do not fit it."""
    try:
        check_network_size(build, config)
        net = build(**config)
    except (TypeError, ValueError) as exc:
        raise DataError(f"checkpoint config is not valid: {' '.join(str(exc).split())[:200]}", path) from None
    check_state_dict(state, net.state_dict(), path)
    try:
        net.load_state_dict(state)
    except (RuntimeError, TypeError, ValueError) as exc:
        raise DataError(f"weights do not fit the stored config: {' '.join(str(exc).split())[:200]}", path) from None
    return net.eval()


def check_state_dict(state: dict, expected: dict, path: str | Path, what: str = "state_dict") -> None:
    """DataError naming ``path`` and the first offending entry when ``state`` lacks a key of
    ``expected``, has one more, or holds a non-tensor or a tensor of another shape."""
    import torch

    missing = [k for k in expected if k not in state]
    extra = [k for k in state if k not in expected]
    if missing or extra:
        parts = ([f"missing {len(missing)} tensors (e.g. {missing[0]!r})"] if missing else []) + \
                ([f"{len(extra)} unexpected entries (e.g. {str(extra[0])[:60]!r})"] if extra else [])
        raise DataError(f"{what}: weights do not fit the network: {', '.join(parts)}", path)
    for key, ref in expected.items():
        value = state[key]
        if not isinstance(value, torch.Tensor):
            raise DataError(f"{what}: weights do not fit the network: {key!r} is a {type(value).__name__}, "
                            "not a tensor", path)
        if tuple(value.shape) != tuple(ref.shape):
            raise DataError(f"{what}: weights do not fit the network: {key!r} has shape "
                            f"{tuple(value.shape)}, it needs {tuple(ref.shape)}", path)


class TrainableRegistry(PluginRegistry):
    """Maps names to :class:`Trainable` instances; ``TRAINABLES`` is the process-wide default."""

    kind = "trainable network"
    names_attr = "__lfbench_trainable_names__"

    def _make(self, name: str, obj: Any, **options: Any) -> Trainable:
        if not (inspect.isclass(obj) and issubclass(obj, Trainable)):
            raise TypeError(f"{obj!r} registered as trainable network {name!r} is not a Trainable subclass")
        if options:
            raise TypeError(f"trainable network {name!r}: unexpected options {', '.join(options)}")
        instance = obj()
        instance.name = name
        return instance

    def _factory(self, entry: Trainable) -> Any:
        return type(entry)

    def _accepts(self, obj: Any) -> bool:
        return inspect.isclass(obj) and issubclass(obj, Trainable)

    def get(self, name: str) -> Trainable:
        return self._get(name)


TRAINABLES = TrainableRegistry(ENTRY_POINT_GROUP)


def register_trainable(name: str, registry: TrainableRegistry | None = None) -> Callable:
    """Class decorator: make a :class:`Trainable` subclass available as ``name``."""
    return _decorator(name, registry or TRAINABLES)


def get_trainable(name: str) -> Trainable:
    """The registered trainable network ``name`` (SpecError listing the available ones otherwise)."""
    return TRAINABLES.get(name)


def list_trainables() -> list[str]:
    return TRAINABLES.names()


__all__ = ["Trainable", "StageOptions", "TrainableRegistry", "network_from_state", "network_bytes",
           "check_network_size", "MAX_NETWORK_BYTES", "TRAINABLES", "DEFAULT_TRAINABLE",
           "register_trainable", "get_trainable", "list_trainables"]
