"""Training configuration: a TOML file parsed into frozen dataclasses, strictly (unknown keys and
wrong types are SpecErrors naming the file and the key).

Every option is declared once, as a dataclass field (lfbench.utils.options.option: type, default, bounds,
help, whether a resumed run may change it); the parser, the bounds checks, :data:`RESUME_FREE_KEYS` and the
reference docs/training-config.md (``python -m lfbench.training.reference``) come from those declarations.

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
    dataset = "urbanlf-syn"                 # optional: the adapter of every root (default: detected per root)
    [[data.synthetic]]                      # synthetic scenes generated into OUT/data/<category>
    category = "synthetic"; seed = 0; size = 128; scenes = 8
    layout = "hci"; width = 0               # or "urbanlf-syn" (u_v.png views; width: non-square scenes)

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
    every = 2000; max_size = 0; border = 15; threshold = 0.07   # border, threshold: default the data's protocol's

    [[stages]]                              # run in order; stage k > 1 starts from stage k-1's weights
    name = "l1"; loss = "l1"; lr = 1e-3; steps = 100000   # a fresh optimizer per stage (Trainable.configure_optimizers)
    [[stages]]
    name = "uafl"; loss = "uafl"; beta = 0.1; lr = 1e-4; steps = 20000

Paths expand ``~`` and ``$VARS``; relative paths are taken from the current directory.
"""

from __future__ import annotations

import dataclasses
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from lfbench.data.dataset import DATASETS, DEFAULT_METRICS, DatasetProtocol, protocol_of
from lfbench.data.synth import MAX_SYNTH_SIZE, scene_name
from lfbench.method.params import values_problem
from lfbench.method.trainable import DEFAULT_TRAINABLE, Trainable, get_trainable
from lfbench.scoring.policy import LFBENCH, SCORERS
from lfbench.training.losses import NEEDS_DISTRIBUTION, make_loss
from lfbench.utils.envvars import expand_vars
from lfbench.utils.errors import LFBenchError, SpecError
from lfbench.utils.hardware import parse_device
from lfbench.utils.names import file_names
from lfbench.utils.options import (
    Table,
    option,
    option_fields,
    option_paths,
    parse_section,
    plain_dict,
)
from lfbench.utils.tomlfile import read_toml

# Bounds of the sizes a config asks for, checked before anything is allocated.
MAX_BATCH = 4096
MAX_PATCH = 1024  # px
MAX_STRIDE = 16
MAX_STEPS = 10**9
MAX_SCENES = 10000
_SAFE_NAME = re.compile(r"[A-Za-z0-9._-]{1,100}")


def _folder_name(value: str) -> str | None:
    if not _SAFE_NAME.fullmatch(value) or value in (".", ".."):
        return f"must be a plain folder name (letters, digits, '.', '_', '-'), got {value[:60]!r}"
    return None


def _device(value: str) -> str | None:
    try:
        parse_device(value)
    except SpecError:
        return f"expected 'auto', 'cpu', 'cuda' or 'cuda:K', got {value[:40]!r}"
    return None


def _dataset(value: Any) -> str | None:
    from lfbench.data.dataset import DATASETS

    if value is None or value in DATASETS.names():
        return None
    return f"expected a dataset of `lfbench datasets` ({', '.join(DATASETS.names())}), got {str(value)[:40]!r}"


@dataclass(frozen=True)
class SyntheticSpec:
    """Synthetic scenes written by lfbench.data.synth into OUT/data/<category>."""

    category: str = option("synthetic", check=_folder_name,
                           help="folder OUT/data/<category> and the category the scenes are selected by")
    seed: int = option(0, low=0, help="generator seed; scene i is synth_<seed>_<i>")
    size: int = option(128, low=16, high=MAX_SYNTH_SIZE, help="height of every scene, and its width unless "
                                                                  "width is given (px)")
    width: int = option(0, low=0, high=MAX_SYNTH_SIZE, omit_default=True,
                        help="width of every scene (px; 0: size, square scenes; another width needs "
                             "layout = \"urbanlf-syn\")")
    scenes: int = option(8, low=1, high=MAX_SCENES, help="number of scenes")
    layout: Literal["hci", "urbanlf-syn"] = option(
        "hci", omit_default=True,
        help="the layout written: hci (OUT/data/<category>/synth_<seed>_<i>/, 9x9 input_CamNNN.png) or urbanlf-syn "
             "(OUT/data/<category>/Image<seed x 10000 + i + 1>/, 9x9 u_v.png, as lfbench synth --layout urbanlf-syn "
             "writes it)")

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) px of every scene of the set."""
        return self.size, self.width or self.size

    def first_index(self) -> int:
        """The number of the set's first UrbanLF-Syn sample folder (``Image<first>``): distinct per seed."""
        return self.seed * MAX_SCENES + 1

    def scene_names(self) -> tuple[str, ...]:
        if self.layout == "urbanlf-syn":
            return tuple(f"Image{self.first_index() + i}" for i in range(self.scenes))
        return tuple(scene_name(self.seed, i) for i in range(self.scenes))

    @staticmethod
    def check_options(values: dict[str, Any], t: Table) -> None:
        if values["width"] not in (0, values["size"]) and values["layout"] != "urbanlf-syn":
            t.fail("width", "the HCI layout has square scenes: leave width out or set layout = \"urbanlf-syn\"")


def _stride_weights(values: dict[str, Any], index: int | None) -> tuple[float, ...]:
    n = len(values["strides"])
    return (8.0, 6.0, 3.0) if n == 3 else (1.0,) * n


@dataclass(frozen=True)
class DataConfig:
    roots: tuple[str, ...] = option(
        (), single=True, help="data roots, each in a dataset layout (`lfbench datasets`: HCI ROOT/<category>/<scene>, "
                              "UrbanLF-Syn ROOT/<split>/ImageN, ...), detected per root unless dataset is given")
    dataset: str | None = option(
        None, check=_dataset, omit_default=True,
        help="the dataset adapter every root is read with (a name of `lfbench datasets`, e.g. \"urbanlf-syn\"); "
             "default: detected per root")
    synthetic: tuple[SyntheticSpec, ...] = option(
        (), single=True, help="synthetic scene sets generated into OUT/data/<category> (when train names scenes: "
                              "only the sets that train or validation select)")
    train: tuple[str, ...] = option((), single=True, help="training scenes: names, categories or splits "
                                                            "(empty: every scene with gt but the validation ones)")
    validation: tuple[str, ...] = option((), single=True, help="scenes scored during training (need gt)")
    invalid_area: str | None = option(None, help="folder of <scene>/input_Cam040_invalid_ver2.png masks: "
                                                 "patches touching them are not sampled")
    patch: int = option(32, low=8, high=MAX_PATCH, help="patch and label size (px)")
    strides: tuple[int, ...] = option((1, 2, 3), low=1, high=MAX_STRIDE, min_length=1,
                                      help="scale augmentation: a patch of stride s, its label / s")
    stride_weights: tuple[float, ...] = option((8.0, 6.0, 3.0), low=0.0, default_from=_stride_weights,
                                               default_text="[8, 6, 3] for three strides, else 1 each",
                                               help="relative probabilities of the strides (one per stride)")
    texture: float = option(0.01, low=0.0, help="reject a patch if sum |centre - centre pixel| < texture * patch^2")
    default_scene_weight: float = option(1.0, low=0.0, help="scene sampling weight (scene_weights overrides it)")
    scene_weights: dict[str, float] = option({}, low=0.0, help="sampling weight per scene name")
    random_gray: bool = option(True, help="random RGB->gray weights per patch (else 0.299 / 0.587 / 0.114)")

    def __post_init__(self) -> None:
        if len(self.strides) != len(self.stride_weights):
            raise SpecError(f"data.stride_weights needs one weight per stride: {list(self.strides)} vs "
                            f"{list(self.stride_weights)}")

    def synthetic_in_use(self) -> tuple[SyntheticSpec, ...]:
        """The [[data.synthetic]] sets a run reads (and so generates): all of them when ``train`` is empty
        (every scene with gt trains), else those that ``train`` or ``validation`` select by category, scene
        name or split."""
        if not self.train:
            return self.synthetic
        names = {*self.train, *self.validation}

        def selected(spec: SyntheticSpec) -> bool:  # by category, by a split of its layout's adapter, or by name
            splits = DATASETS.get(spec.layout).splits
            return (spec.category in names or any(spec.category in splits.get(n, ()) for n in names)
                    or bool(names.intersection(spec.scene_names())))

        return tuple(s for s in self.synthetic if selected(s))

    @staticmethod
    def check_options(values: dict[str, Any], t: Table) -> None:
        n = len(values["strides"])
        if len(values["stride_weights"]) != n:
            t.fail("stride_weights", f"expected {n} numbers (one per stride), got {len(values['stride_weights'])}")
        if sum(values["stride_weights"]) <= 0:
            t.fail("stride_weights", "must not all be 0")
        categories = [s.category for s in values["synthetic"]]
        if len(set(categories)) != len(categories):
            t.fail("synthetic", "each [[data.synthetic]] entry needs its own category")
        if not values["roots"] and not values["synthetic"]:
            t.fail(None, "needs roots = [...] and/or [[data.synthetic]] scenes")


@dataclass(frozen=True)
class AugmentConfig:
    enabled: bool = option(True, help="augment at all (the authors' order: gamma, flip, rotate, noise, clip)")
    gamma: tuple[float, float] = option((0.8, 1.2), low=0.0, low_open=True,
                                        help="[low, high]: every patch x becomes x^g, g ~ U(low, high)")
    flip: float = option(0.5, low=0.0, high=1.0, help="probability of flipping the rows (and the angular rows)")
    rotate: bool = option(True, help="rotate by k x 90 degrees, k uniform in 0..3 (views and angular grid)")
    noise: float = option(1.0 / 12.0, low=0.0, high=1.0, help="probability of additive Gaussian noise")
    noise_std: float = option(0.2 ** 0.5, low=0.0, help="the noise's std is U(0, 1) x noise_std")

    @staticmethod
    def check_options(values: dict[str, Any], t: Table) -> None:
        low, high = values["gamma"]
        if low > high:
            t.fail("gamma", f"expected [low, high] with 0 < low <= high, got {[low, high]}")


@dataclass(frozen=True)
class TrainingConfig:
    batch_size: int = option(32, low=1, high=MAX_BATCH, help="samples per optimizer step, over all processes")
    accumulate: int = option(1, low=1, high=MAX_BATCH, help="micro-batches per step (gradients accumulated)")
    threads: int = option(0, low=0, high=1024, resume_free=True, help="torch threads (0: torch's default)")
    device: str = option("auto", check=_device, resume_free=True, help="auto, cpu, cuda or cuda:K")
    checkpoint_every: int = option(500, low=1, resume_free=True, help="steps between checkpoints")
    log_every: int = option(50, low=1, resume_free=True, help="steps between log lines")
    prefetch: int = option(2, low=0, high=64, resume_free=True, help="batches made ahead of the step")
    channels_last: bool = option(True, resume_free=True,
                                 help="conv weights and activations channels-last (2-3x faster convolutions on CPU)")
    workers: int = option(0, low=0, high=256, resume_free=True, omit_default=True,
                          help="DataLoader processes making the batches (0: a prefetch thread); batches do not "
                               "depend on it")
    pin_memory: bool = option(True, resume_free=True, omit_default=True,
                              help="page-locked batches and non-blocking copies to a CUDA device")
    precision: Literal["fp32", "bf16"] = option("fp32", omit_default=True,
                                                help="bf16: autocast of the forward pass (CUDA, or a CPU with bf16 "
                                                     "instructions)")
    tf32: bool = option(False, omit_default=True,
                        help="allow TF32 in CUDA fp32 matmuls and convolutions (default: IEEE fp32)")
    cudnn_benchmark: bool = option(False, resume_free=True, omit_default=True,
                                   help="let cuDNN time its algorithms per input shape (fixed patch size: faster)")


def _scorer_problem(name: str | None) -> str | None:
    return None if name is None or name in SCORERS else f"must be one of {', '.join(SCORERS)}, got {name!r}"


@dataclass(frozen=True)
class ValidationConfig:
    every: int = option(0, low=0, help="steps between validations (0: only at the end of each stage)")
    max_size: int = option(0, low=0, help="centre-crop larger images to this many px (0: whole image)")
    border: int | None = option(None, low=0, default_text="the training data's protocol's border (HCI: 15)",
                                help="pixels left out at each image border when scoring")
    threshold: float | None = option(None, low=0.0, low_open=True,
                                     default_text="the training data's protocol's first BadPix (HCI: 0.07)",
                                     help="BadPix threshold (px)")
    scorer: str | None = option(None, omit_default=True, check=_scorer_problem,
                                default_text="the training data's protocol's scorer (HCI: lfbench)",
                                help="how BadPix compares and what a non-finite value counts as: lfbench or "
                                     "paper-author (lfbench.scoring.policy)")

    @property
    def needs_protocol(self) -> bool:
        """Whether an option is left to the training data's protocol (:meth:`of_protocol`)."""
        return self.border is None or self.threshold is None or self.scorer is None

    def of_protocol(self, protocol: DatasetProtocol) -> ValidationConfig:
        """This section with the options it leaves unset taken from ``protocol`` (the training data's): its border,
        its first BadPix threshold in table order (lfbench.scoring.protocol.badpix_thresholds; 0.07 where it
        scores no BadPix) and its scorer (kept unset for lfbench's own: a stored HCI config stays as it was)."""
        from lfbench.scoring.protocol import badpix_thresholds  # the metric registry: only when a config is read

        threshold = self.threshold
        if threshold is None:
            threshold = (badpix_thresholds(protocol.metrics) or badpix_thresholds(DEFAULT_METRICS))[0]
        scorer = self.scorer
        if scorer is None and protocol.scorer != LFBENCH.name:
            scorer = protocol.scorer
        return dataclasses.replace(self, border=protocol.border_px if self.border is None else self.border,
                                   threshold=threshold, scorer=scorer)


def _stage_name(values: dict[str, Any], index: int | None) -> str:
    return f"stage{(index or 0) + 1}"


@dataclass(frozen=True, kw_only=True)
class StageConfig:
    name: str = option(default_from=_stage_name, default_text="stage<k>",
                       help="names the stage<k>_<name>.pt weights (unique)")
    loss: str = option(convert=lambda s: s.strip().lower(), help="l1, mse, js, kl, l1+js, l1+kl or uafl "
                                                                  "(lfbench.training.losses)")
    lr: float = option(1e-3, low=0.0, low_open=True, help="learning rate (constant within the stage)")
    steps: int = option(low=1, high=MAX_STEPS, help="optimizer steps")
    eps: float = option(1e-7, low=0.0, help="Adam's epsilon (the default optimizer's)")
    betas: tuple[float, float] = option((0.9, 0.999), low=0.0, high=1.0, high_open=True,
                                        help="Adam's betas (the default optimizer's)")
    loss_params: dict[str, Any] = option({}, rest=True, help="a parameter of the loss, e.g. beta = 0.1 for uafl")

    @staticmethod
    def check_options(values: dict[str, Any], t: Table) -> None:
        try:
            make_loss(values["loss"], **values["loss_params"])  # SpecError for an unknown loss or parameter
        except SpecError as exc:
            t.fail(None, str(exc))


MODEL_HELP = ("the network's build parameters: the keyword arguments of the registered trainable network that "
              "`method` names (`lfbench info NAME` lists them; SubFocal: d_min, d_max, interval, interpolation, width, "
              "attention, angular); checked against its annotated types before anything runs")


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    stages: tuple[StageConfig, ...] = option(min_length=1, help="the stages, run in order; stage k > 1 starts from "
                                                                "stage k-1's weights with a fresh optimizer")
    seed: int = option(42, low=0, help="seed of the initialisation and of every sample")
    out: str | None = option(None, resume_free=True, help="default output folder (--out overrides)")
    data: DataConfig = option(factory=DataConfig, help="the training and validation scenes")
    augment: AugmentConfig = option(factory=AugmentConfig, help="augmentation of the patches")
    model: dict[str, Any] = option({}, help="the network's build parameters", free_text=MODEL_HELP)
    training: TrainingConfig = option(factory=TrainingConfig, help="how the steps run")
    validation: ValidationConfig = option(factory=ValidationConfig, help="validation during training")
    method: str = option(DEFAULT_TRAINABLE, omit_default=True,
                         help="the registered trainable network (lfbench.method.trainable)")
    init: str | None = option(None, omit_default=True,
                              help="start from these exported weights (final.pt, best.pt, stage*.pt, "
                                   "methods/weights/*.pt) instead of a random initialisation; only a new run reads "
                                   "it")
    source: str | None = field(default=None, compare=False)  # the file it was read from (not an option)

    @staticmethod
    def check_options(values: dict[str, Any], t: Table) -> dict[str, Any]:
        stages = values["stages"]
        names = [s.name for s in stages]
        if len(set(names)) != len(names):
            t.fail(None, f"stage names must be unique, got {names}")
        file_names(names, "stage name", source=t.source)  # they name the stage<k>_<name>.pt files
        try:
            trainable = get_trainable(values["method"])
        except SpecError as exc:
            t.fail("method", str(exc))
        for i, st in enumerate(stages):
            if st.loss in NEEDS_DISTRIBUTION and not trainable.distribution:
                t.fail(f"stages[{i}].loss", f"{st.loss!r} needs a distribution over disparities, which network "
                                            f"{values['method']!r} does not return (use l1 or mse)")
        problem = model_problem(trainable, values["model"])
        if problem:
            raise SpecError(problem, t.source)
        validation = values["validation"]
        if validation.needs_protocol:  # from the data's protocol (read only then: by file names)
            validation = validation.of_protocol(training_protocol(values["data"], t.source))
        return {**values, "validation": validation}

    def to_dict(self) -> dict[str, Any]:
        """The config in its TOML layout as plain values (storable in a weights-only checkpoint);
        ``TrainConfig.from_dict(cfg.to_dict()) == cfg``. Options declared ``omit_default`` (``method``,
        ``init`` and the training keys added later) are left out at their defaults, so that configs and
        cell fingerprints written before they existed stay the same."""
        return plain_dict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str | Path | None = None) -> TrainConfig:
        src = str(source) if source else None
        cfg = parse_section(cls, Table(d, "", src))
        return dataclasses.replace(cfg, source=src)

    @classmethod
    def from_toml(cls, path: str | Path) -> TrainConfig:
        raw, _ = read_toml(path, "config file")
        return cls.from_dict(raw, path)


def model_problem(trainable: Trainable, params: dict[str, Any], where: str = "model") -> str | None:
    """Why ``params`` cannot be the ``[model]`` table (at ``where``) of ``trainable``: a key the network does not
    take (naming the ones it does), or a value that does not fit the type and bounds its constructor annotates,
    worded as for any option (``model.channels: expected int, got str``); None when they fit. What the network
    checks itself (Trainable.check) is checked before a run builds it."""
    problem = values_problem(trainable.parameters(), params)
    if problem is None:
        return None
    key, text = problem
    return f"{where}.{key}: {text}" if key else f"[{where}] {text}"


#: The keys of a [[stages]] entry that are not loss parameters.
STAGE_KEYS = frozenset(f.name for f, opt, _ in option_fields(StageConfig) if not opt.rest)

#: The settings a resumed run may change (they do not change the result), as key paths.
RESUME_FREE_KEYS: tuple[tuple[str, ...], ...] = option_paths(TrainConfig, lambda o: o.resume_free)


def comparable(config: dict[str, Any]) -> dict[str, Any]:
    """The config (dict layout) without the settings that may change on resume (RESUME_FREE_KEYS)."""
    d = json.loads(json.dumps(config))
    for keys in RESUME_FREE_KEYS:
        node = d
        for k in keys[:-1]:
            node = node.get(k, {})
        node.pop(keys[-1], None)
    return d


def resume_view(config: dict[str, Any], stages: int, in_progress: int | None = None) -> dict[str, Any]:
    """:func:`comparable` with only the first ``stages`` stages: what a resumed run must keep. The stage
    ``in_progress`` (index) is compared without its ``steps``: the learning rate is constant within a
    stage, so cutting or extending the stage in progress gives the run the new config describes."""
    d = comparable(config)
    d["stages"] = [dict(s) for s in list(d.get("stages", []))[:stages]]
    if in_progress is not None and in_progress < len(d["stages"]):
        d["stages"][in_progress].pop("steps", None)
    return d


def training_protocol(data: DataConfig, source: str | Path | None = None) -> DatasetProtocol:
    """The protocol of the data a run trains on, which [validation] follows where it sets no border, threshold or
    scorer: the first root's as its adapter (data.dataset's, else the one its layout matches, by file names: nothing
    is decoded) reads it, else data.dataset's adapter's declared protocol (a named dataset whose root is not there
    yet: the same values on every machine), else the layout's of the first synthetic set in use; the benchmark's
    (HCI's) where none of these is known (a root not found: the run refuses it before any work,
    lfbench.training.scenes.check_data)."""
    roots = data.roots
    try:
        if roots:
            try:
                return protocol_of(expand_path(roots[0], None if source is None else str(source)), data.dataset)
            except LFBenchError:
                if data.dataset is None:
                    raise
        if data.dataset is not None:  # also for a root not there (yet): the same config, the same values everywhere
            return DATASETS.get(data.dataset).protocol
        in_use = data.synthetic_in_use()
        if in_use:
            return DATASETS.get(in_use[0].layout).protocol
    except LFBenchError:  # the run names the root's problem itself, before anything is written
        pass
    from lfbench.scoring.rules import BENCHMARK_DATASET

    return DATASETS.get(BENCHMARK_DATASET).protocol


def expand_path(value: str, source: str | None = None) -> Path:
    """``~`` and ``$VAR`` / ``${VAR}`` expanded (lfbench.utils.envvars); SpecError if a variable is unset."""
    return Path(expand_vars(value, source))
