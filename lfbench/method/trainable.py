"""Trainable networks: what a plugin declares, once, so that ``lfbench evaluate``, ``predict``, ``train``,
``ablate`` and ``bench`` work for its network without a line of lfbench changing.

A plugin subclasses :class:`Trainable`, decorates it with ``@register_trainable("name")`` in a module of
its ``lfbench.methods`` entry points, and says:

- how to build the network: :attr:`Trainable.network` (a ``torch.nn.Module`` class, or ``"module:Class"``
  imported only when a network is needed) or :meth:`Trainable.build`; the keyword parameters of the
  constructor, typed and documented with ``typing.Annotated`` (:mod:`lfbench.method.params`), are the
  ``[model]`` keys of a training config, the ablation axes (:attr:`Trainable.axes`) and the parameters of
  the method ``name:weights=PATH,...`` (:mod:`lfbench.method.network_method`, made for it by the registry);
- what the network returns (the contract below) and whether it has a distribution over disparities
  (:attr:`Trainable.distribution`; the distribution losses js, kl, l1+js, l1+kl, uafl need one);
- optionally how inference runs (:meth:`Trainable.infer`: whole image, or exact tiles when the network
  has a ``receptive_radius``: :meth:`Trainable.receptive_radius`), its FLOPs (:meth:`Trainable.flops`)
  and its own benches and bench options (:attr:`Trainable.benches`, :attr:`Trainable.train_bench_options`).
- optionally how a training stage is optimised: :meth:`Trainable.configure_optimizers` (default:
  Adam with the stage's lr, betas and eps, a constant rate).

The network contract (a ``torch.nn.Module``):

- ``forward(views)``: views (B, N, H, W) float32 gray in [0, 1] (from RGB with the trainable's
  :attr:`Trainable.gray_weights` where the light field has colour), N = angular^2, view k at angular row
  ``k // angular``, column ``k % angular`` -> ``(disparity, probability)``: disparity (B, H, W) float32 in px
  per view step, probability (B, D, H, W) float32 over ``disparities`` (softmax over D) or None; the sign is
  the HCI data's: a point of the centre view at (x, y) with disparity d appears in view (u, v) at
  (x - (u - c) d, y - (v - c) d), c = angular // 2;
- ``angular`` (int, default 9): views per angular row;
- ``output_margin`` (optional int, default 0): px per side of the returned map that are filled, not computed
  (a network of valid convolutions: :meth:`Trainable.output_margin`); losses skip them;
- ``disparities``: (D,) tensor of the candidate disparities (px), evenly spaced, when it has a distribution;
- ``config()`` (optional): the build keyword arguments that rebuild it (stored in checkpoints; default:
  the ``[model]`` parameters it was built with);
- ``forward(views, target=target)`` in training, for a network whose trainable sets
  :attr:`Trainable.training_target`: the ground truth (B, H, W) px of the batch's patches, the loss's
  target (e.g. OACC-Net builds its occlusion mask from it); every training forward (``lfbench train``,
  ``bench train``, ``check-plugin``) goes through :meth:`Trainable.training_forward`; inference and
  validation never pass it.

Weights files (``final.pt``, ``best.pt``, ``stage<k>_<name>.pt``) hold ``{"format", "method",
"state_dict", "config", "training"}``; :meth:`Trainable.load` rebuilds the network from one, read by
the one checkpoint reader (:mod:`lfbench.method.checkpoint`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
import itertools
import math
import numbers
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from lfbench.data.disparity import disparity_problem
from lfbench.method.checkpoint import read_weights
from lfbench.method.params import Param, docstring_help, signature_params, values_problem
from lfbench.utils.errors import DataError, PluginError
from lfbench.utils.flags import Flag, section_flags
from lfbench.utils.registry import Lazy, Registry

if TYPE_CHECKING:  # torch is imported where a network is built, not by `lfbench methods`
    import torch

ENTRY_POINT_GROUP = "lfbench.methods"  # the modules that register methods and networks
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


@dataclasses.dataclass(frozen=True)
class BenchOption(Flag):
    """An option a network adds to ``lfbench bench train`` (``--NAME V [V ...]``; each value is a variant the
    bench times), as a flag: made by :func:`bench_options` from the network's section of them
    (:attr:`Trainable.train_bench_options`, declared with :func:`~lfbench.utils.options.option` as every option
    is). Its ``kind`` is the ``Literal`` of its choices (read and checked by the one declared-option check:
    ``expected one of 'fast', 'reference', got 'x'``); ``default``: the values timed when it is not given
    (None: unset)."""

    @property
    def choices(self) -> tuple[str, ...]:
        return typing.get_args(self.kind)


def bench_options(section: type | None) -> tuple[BenchOption, ...]:
    """The options of a network's training-bench section as flags that take one or more values: each field is
    declared ``name: tuple[Literal["a", "b"] | None, ...] = option(("a",), help=...)`` (the values timed by
    default; a None among them: unset, the network's own choice); the flag's type is the ``Literal``, its
    metavar the choices. ``()`` for a network without such options."""
    if section is None:
        return ()
    out = []
    for name, flag in section_flags(section).items():
        element = typing.get_args(flag.kind)[0] if typing.get_origin(flag.kind) is tuple else flag.kind
        union = typing.get_origin(element) in (typing.Union, types.UnionType)
        members = typing.get_args(element) if union else (element,)
        literal = next(m for m in members if m is not type(None))
        choices = typing.get_args(literal)
        out.append(BenchOption(name, literal, tuple(flag.default), flag.help, None,
                               flag.metavar or "{" + ",".join(choices) + "}"))
    return tuple(out)


class Trainable:
    """A network that lfbench can run, train, ablate and time (see the module docstring for the contract).

    Subclasses set :attr:`network` (or override :meth:`build`), with the constructor's parameters typed and
    documented by ``Annotated``. The registry sets :attr:`name`.
    """

    name: str = ""
    #: The nn.Module class :meth:`build` instantiates, or ``"module:Class"`` (imported when first needed).
    network: ClassVar[type | str | None] = None
    #: The registered method that runs its weights as ``method:weights=PATH`` ("" = this trainable's name: the
    #: generic network method, unless a method of that name is registered).
    method: ClassVar[str] = ""
    #: Whether forward returns a probability over ``disparities`` (needed by the distribution losses).
    distribution: ClassVar[bool] = False
    #: Whether forward takes the ground truth in training (``forward(views, target=...)``, see the contract).
    training_target: ClassVar[bool] = False
    #: The network's own RGB -> gray weights (R, G, B), used by its method on light fields that have colour
    #: (None: lfbench's 0.299 / 0.587 / 0.114; e.g. OACC-Net's authors average the channels).
    gray_weights: ClassVar[tuple[float, float, float] | None] = None
    #: The parameters an ablation may vary (None = every build parameter), in the order error messages list.
    axes: ClassVar[tuple[str, ...] | None] = None
    #: Defaults that replace the network's own (a variant: e.g. ``lfattnet`` is SubFocal with interval 1).
    defaults: ClassVar[dict[str, Any]] = {}
    #: Extra ``lfbench bench`` cases: name -> function(**params) returning a record dict with "bench".
    benches: ClassVar[dict[str, Callable[..., dict]]] = {}
    #: Options this network adds to ``lfbench bench train`` (see :meth:`prepare_training`): a section of
    #: options (a frozen dataclass whose fields are declared with ``option()``; :func:`bench_options`).
    train_bench_options: ClassVar[type | None] = None
    #: Network parameter values ``lfbench bench train`` times when none are given (e.g. SubFocal's widths).
    train_bench_defaults: ClassVar[dict[str, tuple[Any, ...]]] = {}

    # -- building ------------------------------------------------------------------------------

    def network_class(self) -> type:
        """The network class (imported now when :attr:`network` names it as ``"module:Class"``)."""
        net = type(self).network
        if net is None:
            raise NotImplementedError(f"{type(self).__name__} sets no network and does not override build()")
        if isinstance(net, str):
            net = Lazy(net).load()
        return net

    def build(self, **params: Any) -> torch.nn.Module:
        """The network for the ``[model]`` parameters (ValueError/TypeError for bad values)."""
        return self.network_class()(**{**self.defaults, **params})

    def parameters(self) -> dict[str, Param]:
        """The build keyword parameters (types, defaults, help and bounds from the annotations)."""
        target = self.build if type(self).build is not Trainable.build else self.network_class()
        docs = [c.__doc__ for c in type(self).__mro__ if issubclass(c, Trainable) and c is not Trainable]
        doc = "\n".join(inspect.cleandoc(d) for d in (*docs, inspect.getdoc(target)) if d)
        params = signature_params(target, doc)
        return {k: dataclasses.replace(p, default=self.defaults[k]) if k in self.defaults else p
                for k, p in params.items()}

    @property
    def summary(self) -> str:
        """The first line of the class docstring."""
        doc = inspect.getdoc(type(self)) or ""
        return doc.splitlines()[0] if doc else ""

    def description(self) -> str:
        """The class docstring after its summary, without ``name: help`` lines (the parameters show them)."""
        from lfbench.method.params import without_help_lines

        doc = inspect.getdoc(type(self)) or ""
        body = doc.split("\n", 1)[1] if "\n" in doc else ""
        return without_help_lines(body, docstring_help(body))

    def ablation_axes(self) -> tuple[str, ...]:
        """The parameters an ablation grid may vary."""
        return tuple(self.axes) if self.axes is not None else tuple(self.parameters())

    def check(self, params: dict[str, Any]) -> None:
        """Raise ValueError/TypeError if ``params`` cannot build the network. Unknown keys, types, bounds and
        the network's size are checked by :meth:`check_params`. This default builds the network on PyTorch's
        meta device (shapes only: no memory, no initialisation), and for real only when its constructor
        cannot run there (e.g. it reads a tensor's value; such a network's size cannot be bounded before it
        is built); override with a cheaper check where one exists."""
        if check_network_size(self.build, params) is None:  # a constructor that needs real tensors decides
            construct(self.build, params)

    def check_values(self, params: dict[str, Any]) -> None:
        """ValueError naming unknown keys and values that do not fit a parameter's annotated type or bounds
        (``channels: expected int, got str``): no network is built or imported."""
        problem = values_problem(self.parameters(), params)
        if problem:
            key, text = problem
            raise ValueError(f"{key}: {text}" if key else f"[model] {text}")

    def check_params(self, params: dict[str, Any]) -> None:
        """:meth:`check_values`, then :meth:`check`, then the network's size: at most MAX_NETWORK_BYTES of
        parameters and buffers (a build on the meta device, for every network)."""
        self.check_values(params)
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

    def training_forward(self, net: Any, views: torch.Tensor, target: torch.Tensor
                         ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """One training forward pass of ``net`` (or its DDP wrapper): ``net(views, target=target)`` when
        :attr:`training_target` is set, else ``net(views)``; target (B, H, W) px, the loss's."""
        return net(views, target=target) if self.training_target else net(views)

    # -- weights ---------------------------------------------------------------------------------

    def load(self, path: str | Path, **overrides: Any) -> torch.nn.Module:
        """The network of a weights file (eval mode), rebuilt from its stored config with ``overrides``
        (entries that do not change the weights' shapes); DataError naming the file otherwise, e.g. for
        the weights of another network (``a subfocal checkpoint, not tinycnn``)."""
        payload = read_weights(path, self.name or None, self.same_network())
        return network_from_state(self.build, payload["state_dict"], {**payload["config"], **overrides}, path)

    def stored_config(self, path: str | Path) -> dict[str, Any]:
        """The network config stored in a weights file (read and checked as :meth:`load` does)."""
        return dict(read_weights(path, self.name or None, self.same_network())["config"])

    def same_network(self) -> tuple[str, ...]:
        """Names of other registered networks whose weights this one loads (the same network class)."""
        mine = type(self).network
        if mine is None:
            return ()
        return tuple(n for n in TRAINABLES.registered()
                     if n != self.name and type(TRAINABLES.get(n)).network == mine)

    @property
    def method_name(self) -> str:
        return self.method or self.name

    # -- running ---------------------------------------------------------------------------------

    def views_of(self, lf: Any) -> Any:
        """The (V, U, H, W) float32 views in [0, 1] the network reads from a light field (``lf``: a
        lfbench.data.scene.LightField): by default its gray with :attr:`gray_weights` where it has colour, else
        ``lf.gray_views()`` (0.299 R + 0.587 G + 0.114 B); a network trained on another conversion declares its
        weights (OACC-Net) or says so here (DistgDisp: numpy's mean of R, G and B, as the authors compute it)."""
        from lfbench.data.scene import weighted_gray_views

        return weighted_gray_views(lf, self.gray_weights)

    def receptive_radius(self, net: torch.nn.Module) -> int | None:
        """px of context one output pixel of ``net`` depends on, when that is finite (a stack of k x k
        convolutions: the sum of (k - 1) / 2 over the layers): inference may then run in exact tiles.
        Default: the network's ``receptive_radius`` attribute; None (no such attribute): whole images only."""
        radius = getattr(net, "receptive_radius", None)
        return int(radius) if isinstance(radius, int) and not isinstance(radius, bool) and radius >= 0 else None

    def output_margin(self, net: torch.nn.Module) -> int:
        """px on each side of ``net``'s full-size output that the network does not compute but fills (e.g.
        EPINET's valid convolutions: 11 px, filled by edge replication): training losses compare only the inner
        part, ``[m:H-m, m:W-m]``, of prediction and target, and a patch must be larger than 2 m. Default: the
        network's ``output_margin`` attribute (an int >= 0), else 0."""
        margin = getattr(net, "output_margin", 0)
        return int(margin) if isinstance(margin, int) and not isinstance(margin, bool) and margin >= 0 else 0

    def can_tile(self, net: torch.nn.Module) -> bool:
        """Whether :meth:`infer` runs ``net`` in exact tiles when given ``tile`` (default: when it has a
        receptive radius; a trainable whose own ``infer`` tiles says so)."""
        return self.receptive_radius(net) is not None

    def infer(self, net: torch.nn.Module, views: torch.Tensor, *, precision: str = "fp32",
              max_memory_gb: float | None = None, tile: int = 0, timings: dict | None = None
              ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """One inference pass, as the network method and ``lfbench bench inference`` run it: views
        (B, N, H, W) on the network's device -> (disparity (B, H, W), probability (B, D, H, W) or None).

        Default: ``net(views)`` in inference mode, under bf16 autocast for precision ``bf16``; with
        ``tile`` > 0, in exact tiles of tile x tile px, each computed with :meth:`receptive_radius` px of
        context around it (only the tile's own pixels are kept: the result equals the whole image's);
        ValueError for a tile of a network without a receptive radius. ``max_memory_gb`` is the plugin's."""
        import torch

        autocast = (torch.autocast(views.device.type, dtype=torch.bfloat16) if precision == "bf16"
                    else contextlib.nullcontext())
        net = net.eval()
        radius = self.receptive_radius(net) if tile > 0 else None
        if tile > 0 and radius is None:
            raise ValueError(f"network {self.name!r} runs on whole images only (it has no receptive_radius): "
                             "leave tile out")
        h, w = views.shape[-2:]
        with torch.inference_mode(), autocast:
            if radius is None or (tile >= h and tile >= w):
                return net(views)
            return tiled_forward(net, views, tile, radius, timings)

    def check_forward(self, net: torch.nn.Module, size: int = 16) -> None:
        """ValueError when ``net`` fails one :meth:`infer` pass on a size x size light field of random views
        (on its device), or returns what the network contract does not allow: what a bench checks before it
        starts its cases, for a network that has no :meth:`check` of its own. A network of valid convolutions
        gets a light field large enough for one computed pixel (size >= 2 * output_margin + 1)."""
        import torch

        size = max(size, 2 * self.output_margin(net) + 1)
        angular = int(getattr(net, "angular", 9))
        device = next(iter(net.parameters()), torch.empty(0)).device
        views = torch.rand((1, angular * angular, size, size), generator=torch.Generator().manual_seed(0))
        try:
            out = self.infer(net, views.to(device))
        except (TypeError, ValueError):
            raise
        except Exception as exc:  # noqa: BLE001 - whatever the plugin's forward raised: one line
            raise ValueError(plugin_failure(f"network {self.name!r} on a {size}x{size} light field of "
                                            f"{angular}x{angular} views", exc)) from None
        problem = contract_problem(out, size, getattr(net, "disparities", None))
        if problem:
            raise ValueError(f"network {self.name!r} breaks the network contract: {problem}")

    def cost_estimate(self, model: dict[str, Any], steps: int) -> float | None:
        """The relative cost of training this network with the ``[model]`` values ``model`` for ``steps`` steps
        (any unit: only ratios between the cells of one ablation matter; ``lfbench ablate`` starts the
        costliest cells first), or None when unknown: then the cost is the number of steps."""
        return None

    def flops(self, net: torch.nn.Module, height: int, width: int) -> float | dict[str, float] | None:
        """Floating-point operations (a count, 2 per multiply-add) of one eval forward pass of ``net`` on one
        H x W light field (batch 1): a number, or ``{"total": n, part: n, ...}`` (parts are reported beside the
        total), or None when unknown (then bench records carry no GFLOP/s). Read through :meth:`flop_count`."""
        return None

    def flop_count(self, net: torch.nn.Module, height: int, width: int) -> dict[str, float] | None:
        """:meth:`flops` as ``{"total": n, part: n, ...}`` (a number ``n``, also a one-element tensor or array,
        becomes ``{"total": n}``) or None;
        PluginError naming this network and its plugin class when it returns anything else or a number that
        is not finite and >= 0."""
        value = self.flops(net, height, width)
        value = {k: _scalar(v) for k, v in value.items()} if isinstance(value, dict) else _scalar(value)
        problem = flops_problem(value)
        if problem:
            raise PluginError(f"network {self.name!r} ({plugin_source(self)}): flops() {problem}")
        if value is None:
            return None
        if not isinstance(value, dict):
            return {"total": float(value)}
        return {str(k): float(v) for k, v in value.items()}

    # -- benches ---------------------------------------------------------------------------------

    def train_variants(self, chosen: dict[str, list[str | None]]) -> list[dict[str, str]]:
        """The training variants ``lfbench bench train`` times for the values of the network's options
        (:attr:`train_bench_options`; an option not given has its default values). Default: every
        combination, unset (None) values left out."""
        options = bench_options(self.train_bench_options)
        names = [o.name for o in options]
        values = [chosen.get(n) or list(o.default) for n, o in zip(names, options, strict=True)]
        return [{n: v for n, v in zip(names, combo, strict=True) if v is not None}
                for combo in itertools.product(*values)]

    def prepare_training(self, net: torch.nn.Module, **variant: str) -> bool:
        """Switch ``net`` to a training variant before ``lfbench bench train`` times it (the values of
        :attr:`train_bench_options`; ValueError for a combination it does not have). Returns whether the
        variant trains as ``lfbench train`` does (the bench then sets the process up as training does; a
        "before" variant keeps the defaults). Default: a network without options accepts none."""
        if variant:
            raise ValueError(f"network {self.name!r} has no training option {', '.join(variant)}")
        return True


FLOPS_CONTRACT = "return the FLOPs of one forward pass on an H x W light field: a number, or {'total': n, ...}"


def _scalar(value: Any) -> Any:
    """A one-element tensor or array as its Python number (what a flops() computed with torch may return)."""
    size = getattr(value, "numel", None) or getattr(value, "size", None)
    if hasattr(value, "item") and (size() if callable(size) else size) == 1:
        return value.item()
    return value


def _number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def flops_problem(value: Any) -> str | None:
    """What is wrong with a value :meth:`Trainable.flops` returned (None: a number, a dict with a numeric
    ``total`` and numeric parts, or None), as the rest of a line that starts with ``flops()``."""
    if value is None:
        return None
    if isinstance(value, dict):
        if "total" not in value:
            return f"returned a dict without 'total' (keys: {', '.join(map(str, list(value)[:6]))}): {FLOPS_CONTRACT}"
        bad = [str(k) for k, v in value.items() if not _number(v)]
        if bad:
            kind = type(value[bad[0]]).__name__
            return f"returned a dict whose {bad[0]!r} is a {kind}, not a number: {FLOPS_CONTRACT}"
        numbers_ = list(value.values())
    elif _number(value):
        numbers_ = [value]
    else:
        return f"returned a {type(value).__name__}: {FLOPS_CONTRACT}"
    if not all(math.isfinite(float(v)) and float(v) >= 0 for v in numbers_):
        return f"returned {value!r}: counts must be finite and >= 0"
    return None


def plugin_source(trainable: Trainable) -> str:
    """``module.Class`` of a trainable: the plugin that registered it, for error lines."""
    cls = type(trainable)
    return f"{cls.__module__}.{cls.__qualname__}"


def network_summary(trainable: Trainable, params: dict[str, Any], *, height: int = 512, width: int = 512
                    ) -> dict[str, Any]:
    """What ``lfbench info`` says of a network without weights: ``parameters`` (count), ``trainable`` (count of
    those with requires_grad) and ``flops`` (:meth:`Trainable.flop_count` at height x width, or None) of
    ``trainable.build(**params)``, built on PyTorch's meta device (shapes only: nothing allocated), or on the
    CPU after the size check when its constructor or flops() cannot run there."""
    import torch

    def measure(net: torch.nn.Module) -> dict[str, Any]:
        return {"parameters": sum(p.numel() for p in net.parameters()),
                "trainable": sum(p.numel() for p in net.parameters() if p.requires_grad),
                "flops": trainable.flop_count(net, height, width)}

    try:
        with torch.device("meta"):
            return measure(trainable.build(**params))
    except PluginError:
        raise
    except Exception:  # noqa: BLE001 - a constructor or flops() that needs real tensors: build it for real
        check_network_size(trainable.build, params)
    return measure(trainable.build(**params))


def contract_problem(out: Any, size: int | tuple[int, int], disparities: Any) -> str | None:
    """What is wrong with a forward pass's ``out`` on one light field of ``size`` (H, W) px, or size x size
    (None: nothing): it must be ``(disparity (B, H, W), probability (B, D, H, W) or None)`` of real floating
    tensors, D the number of ``disparities``; each disparity map is held to the one rule of a prediction
    (lfbench.data.disparity.disparity_problem: real floating values, exactly the light field's size)."""
    import torch

    h, w = (size, size) if isinstance(size, int) else tuple(size)
    if not isinstance(out, tuple | list) or len(out) != 2:
        what = f"a {type(out).__name__} of {len(out)}" if isinstance(out, tuple | list) else f"a {type(out).__name__}"
        return f"forward returned {what}, not (disparity, probability or None)"
    disparity, probability = out
    if not isinstance(disparity, torch.Tensor) or disparity.dim() != 3 or disparity.shape[0] != 1:
        shape = tuple(disparity.shape) if isinstance(disparity, torch.Tensor) else type(disparity).__name__
        return f"disparity is {shape}, not (B, H, W) = (1, {h}, {w})"
    problem = disparity_problem(disparity.is_floating_point(), str(disparity.dtype), tuple(disparity.shape[1:]),
                                (h, w))
    if problem:
        return problem
    if probability is None:
        return None
    d = int(disparities.numel()) if isinstance(disparities, torch.Tensor) else None
    if not isinstance(probability, torch.Tensor) or probability.dim() != 4 or \
            tuple(probability.shape[2:]) != (h, w) or (d is not None and probability.shape[1] != d):
        shape = tuple(probability.shape) if isinstance(probability, torch.Tensor) else type(probability).__name__
        return f"probability is {shape}, not (B, D, H, W) = (1, {d if d is not None else 'D'}, {h}, {w})"
    if not probability.is_floating_point():
        return f"probability must be real floating-point values, got {probability.dtype}"
    return None


def crop_margin(disparity: torch.Tensor, probability: torch.Tensor | None, target: torch.Tensor, margin: int
                ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
    """The inner part of a prediction and its target that a loss compares: ``margin`` px cut from every side
    of disparity (B, H, W), probability (B, D, H, W) or None and target (B, H, W) (no copy: views)."""
    if margin <= 0:
        return disparity, probability, target
    inner = (..., slice(margin, -margin), slice(margin, -margin))
    return disparity[inner], None if probability is None else probability[inner], target[inner]


def plugin_failure(what: str, exc: BaseException) -> str:
    """One line for an exception a plugin's code raised (its constructor or forward): ``what failed:
    RuntimeError: <first line of the message>`` (an allocator's refusal, a CUDA error, a bug)."""
    first = (str(exc).strip().splitlines() or [""])[0][:200]
    return f"{what} failed: {type(exc).__name__}: {first}"


class ConstructorError(ValueError):
    """A plugin network's constructor failed with something other than ValueError/TypeError (one line)."""


def construct(build: Callable[..., torch.nn.Module], params: dict[str, Any]) -> torch.nn.Module:
    """``build(**params)``: ValueError and TypeError as the constructor raised them (a bad value); any other
    exception of the plugin's constructor (a RuntimeError, the allocator refusing 10**12 floats, MemoryError)
    a :class:`ConstructorError` (a ValueError) of one line, so that every caller that turns a bad value into
    an error line names it."""
    try:
        return build(**params)
    except (TypeError, ValueError):
        raise
    except Exception as exc:  # noqa: BLE001 - whatever the plugin's constructor raised: one line
        raise ConstructorError(plugin_failure("the network's constructor", exc)) from None


def to_channels_last(model: torch.nn.Module) -> torch.nn.Module:
    """Conv2d weights channels-last and Conv3d weights channels-last-3d (in place): oneDNN then runs the
    convolutions in that layout, 2-3x faster on CPU for SubFocal's few-channel convs."""
    import torch

    for m in model.modules():
        if isinstance(m, torch.nn.Conv2d):
            m.to(memory_format=torch.channels_last)
        elif isinstance(m, torch.nn.Conv3d):
            m.to(memory_format=torch.channels_last_3d)
    return model


def tiled_forward(net: torch.nn.Module, views: torch.Tensor, tile: int, radius: int, timings: dict | None = None
                  ) -> tuple[torch.Tensor, torch.Tensor | None]:
    """``net(views)`` in tiles of tile x tile px, each run on the tile plus ``radius`` px of the image around
    it (less at the image's edges, where the network pads as it does for the whole image), keeping the
    tile's own pixels: equal to the whole image's result for a network whose output pixel depends on at
    most ``radius`` px around it."""
    import torch

    h, w = views.shape[-2:]
    disparity = probability = None
    count = 0
    for y0 in range(0, h, tile):
        for x0 in range(0, w, tile):
            y1, x1 = min(y0 + tile, h), min(x0 + tile, w)
            ya, xa = max(0, y0 - radius), max(0, x0 - radius)
            yb, xb = min(h, y1 + radius), min(w, x1 + radius)
            d, p = net(views[..., ya:yb, xa:xb])
            core = (slice(y0 - ya, y0 - ya + y1 - y0), slice(x0 - xa, x0 - xa + x1 - x0))
            if disparity is None:
                disparity = d.new_empty((*d.shape[:-2], h, w))
                probability = None if p is None else p.new_empty((*p.shape[:-2], h, w))
            disparity[..., y0:y1, x0:x1] = d[(..., *core)]
            if probability is not None:
                probability[..., y0:y1, x0:x1] = p[(..., *core)]
            count += 1
    if timings is not None:
        timings["tile"], timings["tiles"] = (tile, tile), count
    assert disparity is not None  # an image has at least one tile
    return disparity, probability if isinstance(probability, torch.Tensor) else None


def network_from_state(build: Callable[..., torch.nn.Module], state: dict, config: dict, path: str | Path
                       ) -> torch.nn.Module:
    """``build(**config)`` with ``state`` loaded, in eval mode; DataError naming ``path`` (the checkpoint)
    when the config does not build, would hold more than MAX_NETWORK_BYTES (checked on the meta device
    before anything is allocated) or the weights do not fit it."""
    try:
        check_network_size(build, config)
        net = construct(build, config)
    except ConstructorError as exc:
        raise DataError(f"the network of this checkpoint does not build: {exc}", path) from None
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


def _instance(name: str, cls: type[Trainable]) -> Trainable:
    instance = cls()
    instance.name = name
    return instance


def trainable_registry(group: str | None = ENTRY_POINT_GROUP) -> Registry[Trainable]:
    """A registry of trainable networks (classes registered, instances stored)."""
    return Registry("trainable network", Trainable, group=group, make=_instance)


#: Every registered trainable network, by name (the ``lfbench.methods`` entry points fill it).
TRAINABLES: Registry[Trainable] = trainable_registry()


def register_trainable(name: str, registry: Registry[Trainable] | None = None) -> Callable:
    """Class decorator: make a :class:`Trainable` subclass available as ``name`` (a network lfbench trains,
    ablates and times, and runs as the method ``name:weights=PATH``)."""
    def deco(cls: type[Trainable]) -> type[Trainable]:
        (registry if registry is not None else TRAINABLES).add(name, cls)
        return cls

    return deco


def get_trainable(name: str) -> Trainable:
    """The registered trainable network ``name`` (SpecError listing the available ones otherwise)."""
    return TRAINABLES.get(name)


__all__ = ["Trainable", "StageOptions", "BenchOption", "bench_options", "network_from_state", "check_state_dict",
           "network_bytes",
           "check_network_size", "contract_problem", "construct", "ConstructorError", "plugin_failure",
           "flops_problem", "plugin_source", "network_summary", "FLOPS_CONTRACT", "to_channels_last",
           "tiled_forward", "crop_margin", "MAX_NETWORK_BYTES",
           "TRAINABLES", "DEFAULT_TRAINABLE", "ENTRY_POINT_GROUP", "register_trainable", "get_trainable",
           "trainable_registry"]
