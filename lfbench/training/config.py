"""Training configuration: a TOML file parsed into frozen dataclasses, strictly (unknown keys and
wrong types are SpecErrors naming the file).

Layout (every table optional except ``[[stages]]``; defaults are the authors' settings)::

    seed = 42
    out = "runs/name"                       # default output folder (--out overrides)
    method = "subfocal"                     # the registered trainable network (lfbench.method.trainable)
    init = "runs/small/final.pt"            # optional: start from these weights (exported format, e.g. a
                                            # final.pt / best.pt / stage*.pt or methods/weights/*.pt) instead
                                            # of a random initialisation; [model] may change what the weights'
                                            # shapes do not fix (interval, interpolation); only a new run reads it

    [data]
    roots = ["${LFBENCH_HCI_ROOT}"]         # HCI-layout roots (ROOT/<category>/<scene>)
    train = ["additional"]                  # scene names, categories or splits; default: all but validation
    validation = ["backgammon"]             # scenes scored during training (need gt)
    invalid_area = "path"                   # optional: <path>/<scene>/input_Cam040_invalid_ver2.png
    patch = 32                              # patch and label size (px)
    strides = [1, 2, 3]                     # scale augmentation: stride s, label / s
    stride_weights = [8, 6, 3]              # relative probabilities of the strides
    texture = 0.01                          # reject a patch if sum |centre - centre pixel| < texture * patch^2
    default_scene_weight = 1.0              # scene sampling weight; scene_weights overrides per name
    scene_weights = { kitchen = 1 }
    random_gray = true                      # random RGB->gray weights per patch (else 0.299/0.587/0.114)
    [[data.synthetic]]                      # synthetic scenes generated into OUT/data/<category>
    category = "synthetic"; seed = 0; size = 128; scenes = 8

    [augment]                               # the authors' order: gamma, flip, rotate, noise, clip
    enabled = true; gamma = [0.8, 1.2]; flip = 0.5; rotate = true; noise = 0.08333; noise_std = 0.4472

    [model]                                 # the network's build parameters (here SubFocal's)
    width = 150; interval = 0.5; interpolation = "bilinear"; attention = true

    [training]
    batch_size = 32; accumulate = 1; threads = 0; device = "auto"
    checkpoint_every = 500; log_every = 50; prefetch = 2; channels_last = true
    workers = 0; pin_memory = true          # DataLoader processes (batches identical for any number), pinned copies
    precision = "fp32"; tf32 = false; cudnn_benchmark = false   # bf16 autocast, TF32, cuDNN autotuning

    [validation]
    every = 2000; max_size = 0; border = 15; threshold = 0.07

    [[stages]]                              # run in order; stage k > 1 starts from stage k-1's weights
    name = "l1"; loss = "l1"; lr = 1e-3; steps = 100000   # fresh Adam (eps 1e-7) per stage
    [[stages]]
    name = "uafl"; loss = "uafl"; beta = 0.1; lr = 1e-4; steps = 20000

Paths expand ``~`` and ``$VARS``; relative paths are taken from the current directory.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from lfbench.data.synth import MAX_SYNTH_SIZE
from lfbench.method.trainable import DEFAULT_TRAINABLE
from lfbench.utils.envvars import expand_vars
from lfbench.utils.errors import SpecError
from lfbench.utils.hardware import parse_device
from lfbench.utils.names import file_names

STAGE_KEYS = {"name", "loss", "lr", "steps", "eps", "betas"}
# Bounds of the sizes a config asks for, checked before anything is allocated.
MAX_BATCH = 4096
MAX_PATCH = 1024  # px
MAX_STRIDE = 16
MAX_STEPS = 10**9
MAX_SCENES = 10000
_SAFE_NAME = re.compile(r"[A-Za-z0-9._-]{1,100}")


@dataclass(frozen=True)
class SyntheticSpec:
    """Synthetic scenes written by lfbench.data.synth into OUT/data/<category>."""

    category: str = "synthetic"
    seed: int = 0
    size: int = 128
    scenes: int = 8


@dataclass(frozen=True)
class DataConfig:
    roots: tuple[str, ...] = ()
    synthetic: tuple[SyntheticSpec, ...] = ()
    train: tuple[str, ...] = ()
    validation: tuple[str, ...] = ()
    invalid_area: str | None = None
    patch: int = 32
    strides: tuple[int, ...] = (1, 2, 3)
    stride_weights: tuple[float, ...] = (8.0, 6.0, 3.0)
    texture: float = 0.01
    default_scene_weight: float = 1.0
    scene_weights: dict[str, float] = field(default_factory=dict)
    random_gray: bool = True

    def __post_init__(self) -> None:
        if len(self.strides) != len(self.stride_weights):
            raise SpecError(f"data.stride_weights needs one weight per stride: {list(self.strides)} vs "
                            f"{list(self.stride_weights)}")


@dataclass(frozen=True)
class AugmentConfig:
    enabled: bool = True
    gamma: tuple[float, float] = (0.8, 1.2)
    flip: float = 0.5
    rotate: bool = True
    noise: float = 1.0 / 12.0
    noise_std: float = math.sqrt(0.2)


@dataclass(frozen=True)
class TrainingConfig:
    batch_size: int = 32
    accumulate: int = 1
    threads: int = 0  # 0 = torch's default
    device: str = "auto"
    checkpoint_every: int = 500
    log_every: int = 50
    prefetch: int = 2
    channels_last: bool = True  # conv weights/activations channels-last (2-3x faster convolutions on CPU)
    workers: int = 0  # DataLoader processes making the batches (0: a prefetch thread); batches do not depend on it
    pin_memory: bool = True  # page-locked batches and non-blocking copies to a CUDA device
    precision: str = "fp32"  # or "bf16": autocast of the forward pass (CUDA, or a CPU with bf16 instructions)
    tf32: bool = False  # allow TF32 in CUDA fp32 matmuls / convolutions (default: IEEE fp32)
    cudnn_benchmark: bool = False  # let cuDNN time its algorithms per input shape (fixed patch size: faster)


# Training keys added after configs and cell fingerprints were first written: left out of to_dict() at their
# defaults, so that those stay the same (and old checkpoints resume).
NEW_TRAINING_KEYS = ("workers", "pin_memory", "precision", "tf32", "cudnn_benchmark")
NEW_TRAINING_DEFAULTS = {k: getattr(TrainingConfig, k) for k in NEW_TRAINING_KEYS}  # the dataclass's defaults


@dataclass(frozen=True)
class ValidationConfig:
    every: int = 0  # 0 = only at the end of each stage
    max_size: int = 0  # centre-crop larger images to this many px (0 = whole image)
    border: int = 15
    threshold: float = 0.07


@dataclass(frozen=True)
class StageConfig:
    name: str
    loss: str
    lr: float
    steps: int
    eps: float = 1e-7
    betas: tuple[float, float] = (0.9, 0.999)
    loss_params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TrainConfig:
    stages: tuple[StageConfig, ...]
    seed: int = 42
    out: str | None = None
    data: DataConfig = field(default_factory=DataConfig)
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    model: dict[str, Any] = field(default_factory=dict)
    training: TrainingConfig = field(default_factory=TrainingConfig)
    validation: ValidationConfig = field(default_factory=ValidationConfig)
    method: str = DEFAULT_TRAINABLE
    init: str | None = None  # weights the first stage starts from (None: a fresh initialisation)
    source: str | None = field(default=None, compare=False)

    def to_dict(self) -> dict[str, Any]:
        """The config in its TOML layout as plain values (storable in a weights-only checkpoint);
        ``TrainConfig.from_dict(cfg.to_dict()) == cfg``. The default ``method`` is left out, so that configs
        and cell fingerprints written before the key existed stay the same."""
        d = _plain(asdict(self))
        d.pop("source", None)
        if d["method"] == DEFAULT_TRAINABLE:
            del d["method"]
        if d["init"] is None:  # left out, so configs and fingerprints from before the key stay the same
            del d["init"]
        for key, default in NEW_TRAINING_DEFAULTS.items():
            if d["training"].get(key) == default:
                del d["training"][key]
        for st in d["stages"]:  # the TOML layout: loss parameters beside the stage's keys
            st.update(st.pop("loss_params"))
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str | Path | None = None) -> TrainConfig:
        return _parse(d, str(source) if source else None)

    @classmethod
    def from_toml(cls, path: str | Path) -> TrainConfig:
        from lfbench.utils.tomlfile import read_toml

        raw, _ = read_toml(path, "config file")
        return _parse(raw, str(path))


def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def expand_path(value: str, source: str | None = None) -> Path:
    """``~`` and ``$VAR`` / ``${VAR}`` expanded (lfbench.utils.envvars); SpecError if a variable is unset."""
    return Path(expand_vars(value, source))


class _Table:
    """Typed, strict access to one TOML table; ``done()`` rejects keys nobody asked for."""

    def __init__(self, raw: Any, where: str, source: str | None) -> None:
        if not isinstance(raw, dict):
            raise SpecError(f"[{where}] must be a table", source)
        self.raw, self.where, self.source, self.used = raw, where, source, set()

    def _fail(self, key: str, msg: str):
        raise SpecError(f"{self.where}.{key}: {msg}" if self.where else f"{key}: {msg}", self.source)

    def get(self, key: str, kind: type | tuple, default: Any = None, required: bool = False) -> Any:
        self.used.add(key)
        if self.raw.get(key) is None:  # absent (None only comes from to_dict(): TOML has no null)
            if required:
                self._fail(key, "is required")
            return default
        value = self.raw[key]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        ok = isinstance(value, kind) and not (kind in (int, float) and isinstance(value, bool))
        if not ok:
            name = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
            self._fail(key, f"expected {name}, got {value!r}")
        return value

    def number(self, key: str, default: float, low: float | None = None, high: float | None = None,
               integer: bool = False, low_open: bool = False) -> Any:
        value = self.get(key, int if integer else float, default)
        if not math.isfinite(value):
            self._fail(key, f"must be a finite number, got {value}")
        if low is not None and (value < low or (low_open and value == low)):
            self._fail(key, f"must be {'>' if low_open else '>='} {low}, got {value}")
        if high is not None and value > high:
            self._fail(key, f"must be <= {high}, got {value}")
        return value

    def strings(self, key: str, default: tuple[str, ...] = ()) -> tuple[str, ...]:
        value = self.get(key, (list, str), list(default))
        value = [value] if isinstance(value, str) else value
        if not all(isinstance(v, str) for v in value):
            self._fail(key, "expected a list of strings")
        return tuple(value)

    def floats(self, key: str, default: tuple[float, ...], length: int | None = None) -> tuple[float, ...]:
        value = self.get(key, list, list(default))
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            self._fail(key, "expected a list of numbers")
        if length is not None and len(value) != length:
            self._fail(key, f"expected {length} numbers, got {len(value)}")
        return tuple(float(v) for v in value)

    def table(self, key: str) -> _Table:
        self.used.add(key)
        where = f"{self.where}.{key}" if self.where else key
        return _Table(self.raw.get(key, {}), where, self.source)

    def done(self) -> None:
        unknown = sorted(set(self.raw) - self.used)
        if unknown:
            where = f"[{self.where}] " if self.where else ""
            raise SpecError(f"{where}unknown key(s): {', '.join(unknown)}", self.source)


def _parse(raw: dict[str, Any], source: str | None) -> TrainConfig:
    top = _Table(raw, "", source)
    seed = top.number("seed", 42, low=0, integer=True)
    out = top.get("out", str, None)
    method = top.get("method", str, DEFAULT_TRAINABLE)
    init = top.get("init", str, None)
    data = _parse_data(top.table("data"), source)
    augment = _parse_augment(top.table("augment"))
    model_t = top.table("model")
    model = dict(model_t.raw)
    model_t.used |= set(model)
    training = _parse_training(top.table("training"))
    validation = _parse_validation(top.table("validation"))
    stages_raw = top.get("stages", list, None, required=True)
    top.done()
    if not stages_raw:
        raise SpecError("at least one [[stages]] entry is required", source)
    stages = tuple(_parse_stage(_Table(s, f"stages[{i}]", source), i) for i, s in enumerate(stages_raw))
    names = [s.name for s in stages]
    if len(set(names)) != len(names):
        raise SpecError(f"stage names must be unique, got {names}", source)
    file_names(names, "stage name", source=source)  # they name the stage<k>_<name>.pt files
    _check_method(method, stages, source)
    return TrainConfig(stages=stages, seed=seed, out=out, data=data, augment=augment, model=model,
                       training=training, validation=validation, method=method, init=init, source=source)


def _check_method(method: str, stages: tuple[StageConfig, ...], source: str | None) -> None:
    """The network is registered, and has a distribution if a stage's loss needs one."""
    from lfbench.method.trainable import get_trainable
    from lfbench.training.losses import NEEDS_DISTRIBUTION

    try:
        trainable = get_trainable(method)
    except SpecError as exc:
        raise SpecError(f"method: {exc}", source) from None
    for i, st in enumerate(stages):
        if st.loss in NEEDS_DISTRIBUTION and not trainable.distribution:
            raise SpecError(f"stages[{i}].loss: {st.loss!r} needs a distribution over disparities, which network "
                            f"{method!r} does not return (use l1 or mse)", source)


def _parse_data(t: _Table, source: str | None) -> DataConfig:
    syn_raw = t.get("synthetic", (list, dict), [])
    syn_raw = [syn_raw] if isinstance(syn_raw, dict) else syn_raw
    synthetic = []
    for i, s in enumerate(syn_raw):
        st = _Table(s, f"data.synthetic[{i}]", source)
        spec = SyntheticSpec(category=st.get("category", str, "synthetic"),
                             seed=st.number("seed", 0, low=0, integer=True),
                             size=st.number("size", 128, low=16, high=MAX_SYNTH_SIZE, integer=True),
                             scenes=st.number("scenes", 8, low=1, high=MAX_SCENES, integer=True))
        st.done()
        if not _SAFE_NAME.fullmatch(spec.category) or spec.category in (".", ".."):
            st._fail("category", f"must be a plain folder name (letters, digits, '.', '_', '-'), "
                                 f"got {spec.category[:60]!r}")
        synthetic.append(spec)
    if len({s.category for s in synthetic}) != len(synthetic):
        raise SpecError("each [[data.synthetic]] entry needs its own category", source)
    weights_t = t.table("scene_weights")
    scene_weights = {}
    for k in list(weights_t.raw):
        scene_weights[k] = weights_t.number(k, 1.0, low=0.0)
    weights_t.done()
    strides_f = t.floats("strides", (1, 2, 3))
    if any(s != int(s) or not 1 <= s <= MAX_STRIDE for s in strides_f):
        t._fail("strides", f"expected whole numbers from 1 to {MAX_STRIDE}, got {list(strides_f)}")
    strides = tuple(int(s) for s in strides_f)
    stride_weights = t.floats("stride_weights", (8.0, 6.0, 3.0) if len(strides) == 3 else (1.0,) * len(strides),
                              length=len(strides))
    if not strides or min(strides) < 1 or min(stride_weights) < 0 or sum(stride_weights) <= 0:
        raise SpecError("data.strides must be positive integers with non-negative weights (not all 0)", source)
    cfg = DataConfig(
        roots=t.strings("roots"),
        synthetic=tuple(synthetic),
        train=t.strings("train"),
        validation=t.strings("validation"),
        invalid_area=t.get("invalid_area", str, None),
        patch=t.number("patch", 32, low=8, high=MAX_PATCH, integer=True),
        strides=strides,
        stride_weights=stride_weights,
        texture=t.number("texture", 0.01, low=0.0),
        default_scene_weight=t.number("default_scene_weight", 1.0, low=0.0),
        scene_weights=scene_weights,
        random_gray=t.get("random_gray", bool, True),
    )
    t.done()
    if not cfg.roots and not cfg.synthetic:
        raise SpecError("[data] needs roots = [...] and/or [[data.synthetic]] scenes", source)
    return cfg


def _parse_augment(t: _Table) -> AugmentConfig:
    cfg = AugmentConfig(
        enabled=t.get("enabled", bool, True),
        gamma=t.floats("gamma", (0.8, 1.2), length=2),  # type: ignore[arg-type]
        flip=t.number("flip", 0.5, low=0.0, high=1.0),
        rotate=t.get("rotate", bool, True),
        noise=t.number("noise", 1.0 / 12.0, low=0.0, high=1.0),
        noise_std=t.number("noise_std", math.sqrt(0.2), low=0.0),
    )
    t.done()
    if not 0 < cfg.gamma[0] <= cfg.gamma[1]:
        t._fail("gamma", f"expected [low, high] with 0 < low <= high, got {list(cfg.gamma)}")
    return cfg


def _parse_training(t: _Table) -> TrainingConfig:
    d = TrainingConfig  # the defaults are the dataclass's
    cfg = TrainingConfig(
        batch_size=t.number("batch_size", d.batch_size, low=1, high=MAX_BATCH, integer=True),
        accumulate=t.number("accumulate", d.accumulate, low=1, high=MAX_BATCH, integer=True),
        threads=t.number("threads", d.threads, low=0, high=1024, integer=True),
        device=t.get("device", str, d.device),
        checkpoint_every=t.number("checkpoint_every", d.checkpoint_every, low=1, integer=True),
        log_every=t.number("log_every", d.log_every, low=1, integer=True),
        prefetch=t.number("prefetch", d.prefetch, low=0, high=64, integer=True),
        channels_last=t.get("channels_last", bool, d.channels_last),
        workers=t.number("workers", d.workers, low=0, high=256, integer=True),
        pin_memory=t.get("pin_memory", bool, d.pin_memory),
        precision=t.get("precision", str, d.precision),
        tf32=t.get("tf32", bool, d.tf32),
        cudnn_benchmark=t.get("cudnn_benchmark", bool, d.cudnn_benchmark),
    )
    t.done()
    if cfg.precision not in ("fp32", "bf16"):
        t._fail("precision", f"expected 'fp32' or 'bf16', got {cfg.precision!r}")
    try:
        parse_device(cfg.device)
    except SpecError:
        t._fail("device", f"expected 'auto', 'cpu', 'cuda' or 'cuda:K', got {cfg.device!r}")
    return cfg


def _parse_validation(t: _Table) -> ValidationConfig:
    cfg = ValidationConfig(
        every=t.number("every", 0, low=0, integer=True),
        max_size=t.number("max_size", 0, low=0, integer=True),
        border=t.number("border", 15, low=0, integer=True),
        threshold=t.number("threshold", 0.07, low=0.0, low_open=True),
    )
    t.done()
    return cfg


def _parse_stage(t: _Table, index: int) -> StageConfig:
    from lfbench.training.losses import make_loss

    loss = t.get("loss", str, None, required=True).strip().lower()
    params = {k: v for k, v in t.raw.items() if k not in STAGE_KEYS}
    t.used |= set(params)
    try:
        make_loss(loss, **params)  # SpecError for an unknown loss or parameter
    except SpecError as exc:
        raise SpecError(f"{t.where}: {exc}", t.source) from None
    t.get("steps", int, required=True)
    betas = t.floats("betas", (0.9, 0.999), length=2)
    if not all(0.0 <= b < 1.0 for b in betas):
        t._fail("betas", f"expected two numbers in [0, 1), got {list(betas)}")
    stage = StageConfig(
        name=t.get("name", str, f"stage{index + 1}"),
        loss=loss,
        lr=t.number("lr", 1e-3, low=0.0, low_open=True),
        steps=t.number("steps", 1, low=1, high=MAX_STEPS, integer=True),
        eps=t.number("eps", 1e-7, low=0.0),
        betas=betas,  # type: ignore[arg-type]
        loss_params=params,
    )
    t.done()
    return stage
