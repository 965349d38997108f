"""Ablation specs: a TOML file naming a base training config, a grid of variants, the training budget
of every cell, the evaluation scenes and the paper table to put beside ours. Parsed strictly:
a bad key or value is a SpecError naming the spec file and the key (the CLI exits with code 2).

Every key is declared once, as a field of the sections below (lfbench.utils.options.option: type, default,
bounds, help); the parser and the reference docs/ablation-spec.md (``python -m lfbench.ablation.reference``)
come from those declarations. An example (paths are relative to the spec file's folder; ``~`` and ``${VARS}``
are expanded)::

    title = "Table IV: disparity interval x interpolation"
    table = "table4"            # paper table beside ours: table4 | table5 | beta | tables12 | none
                                # (with "none": no paper numbers unless [report] or --paper asks)
    base = "../configs/subfocal_cpu_small.toml"   # or an inline [base] table (training-config layout)
    seeds = [1, 2, 3]           # optional: every cell once per seed (ids end in _seed=K)

    [budget]                    # every cell's training budget (written over the base config)
    steps = [48, 12]            # steps per stage, one number per [[stages]] of the base
    batch = 4                   # training.batch_size
    patch = 32                  # data.patch
    threads = 0                 # torch threads per cell (0: cores / --jobs)
    model = { width = 8 }       # [model] overrides (here SubFocal's 3D aggregation channels; paper 150)

    [set]                       # any other training-config keys, dotted; list items by 1-based
    "data.validation" = []      # position (stages.2.lr), stages also by name or "last"

    [[grid]]                    # the cells: the union of the products of every [[grid]] table
    interval = [1, 0.5, 0.25, 0.1]
    interpolation = ["bilinear"]

    [stage1]
    shared = false              # true: the stages before the last are trained once, in OUT/stage1

    [evaluation]
    synthetic = { seed = 1000, size = 64, scenes = 3 }   # generated into OUT/eval_data/
    data = "${LFBENCH_HCI_ROOT}"                          # and/or HCI scenes by name, category or split
    scenes = ["backgammon"]

    [[methods]]                 # more rows for Tables I/II: any registered method spec
    label = "SubFocal (published maps)"
    spec = "published:path=${LFBENCH_HCI_ROOT}/../published/subfocal"

    [report]                    # which paper stands beside ours (lfbench.reports.reference)
    reference = "subfocal-tci2023"  # a registered reference, or "none" (default: the network's own
                                # when the spec asks for a paper table or paper methods or --paper is given)
    paper_methods = ["SubFocal"]  # its methods beside ours in Tables I/II (default: the reference's own)

Grid axes: the network's own parameters (the base config's ``method``, a registered trainable:
SubFocal's interval, interpolation, width, attention, d_min, d_max; ``Trainable.axes``), written into
[model]; seed; loss (the last stage's loss: a name, or a table {loss = "uafl", beta = 0.5}; its
parameters are replaced and the stage is renamed finetune_<loss>); beta and lr (the last stage's); or
any dotted training-config key as in [set]. The cell id is ``axis=value`` joined by ``_`` (e.g.
``interval=0.5_interpolation=phase``).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from lfbench.data.synth import MAX_SYNTH_SIZE
from lfbench.method.registry import parse_spec as parse_method_spec
from lfbench.method.trainable import DEFAULT_TRAINABLE, Trainable, get_trainable
from lfbench.training.config import STAGE_KEYS, TrainConfig, comparable, model_problem
from lfbench.utils.envvars import expand_vars
from lfbench.utils.errors import SpecError
from lfbench.utils.flags import SCENE_COUNT
from lfbench.utils.names import FileNames
from lfbench.utils.options import Table, option, parse_section
from lfbench.utils.tomlfile import read_toml

NO_TABLE = ("tables12", "none")  # a spec without a reference table (Tables I/II are written for every spec)
#: Axes of every training config, whatever the network: the last stage's loss and learning rate, the seed (and,
#: beside them, each keyword parameter a registered loss declares: :func:`loss_axes`).
SPECIAL_AXES = ("loss", "lr", "seed")
#: The axis that sets the network a cell trains (the training config's top-level ``method``, a registered
#: trainable). It is applied first and starts the cell's [model] afresh (the base's [model] holds the base
#: network's parameters): the new network's own parameters come from ``model.KEY`` (or ``KEY``) axes of the same
#: [[grid]] table, so one spec can compare several networks, one [[grid]] table each.
NETWORK_AXIS = "method"
DEVICES = ("cpu", "cuda", "auto")
MAX_CELLS = 1024  # cells (x seeds) one spec may define: counted before any cell is made
MAX_REPEATS = 1000  # timed (and warm-up) runs of the test time
MAX_THREADS = 4096
_ID_SAFE = re.compile(r"[^A-Za-z0-9._=+-]")


@dataclass(frozen=True)
class Budget:
    """What every cell is trained with; None (or no entry) = the base config's value."""

    steps: tuple[int, ...] | None = option(None, low=1, single=True,
                                           help="steps per stage, one number per [[stages]] of the base config")
    batch: int | None = option(None, low=1, help="training.batch_size")
    patch: int | None = option(None, low=8, help="data.patch (px)")
    threads: int = option(0, low=0, high=MAX_THREADS, help="torch threads per cell (0: cores / --jobs)")
    model: dict[str, Any] = option({}, help="[model] overrides: the network's parameters every cell is built with",
                                   free_text="[model] overrides written over the base config's [model] (e.g. "
                                             "`model = { width = 8 }`: a network's width); "
                                             "checked against the network's parameters and their types")

    def describe(self, config: dict[str, Any]) -> str:
        """A short label of the budget actually used, e.g. 'width 8, batch 4, patch 32, 48+12 steps, cpu'
        (the [model] overrides first, with the cell's values)."""
        steps = "+".join(str(s["steps"]) for s in config["stages"])
        device = config.get("training", {}).get("device", "auto")
        model = "".join(f"{k} {config['model'].get(k, v)}, " for k, v in self.model.items())
        return (f"{model}batch {config['training']['batch_size']}, patch {config['data']['patch']}, {steps} steps, "
                f"{device}")


@dataclass(frozen=True)
class SyntheticEval:
    """Evaluation scenes from lfbench.data.synth: ``scenes`` scenes of ``size`` px, generated with ``seed``."""

    seed: int = option(0, low=0, help="generator seed")
    size: int = option(64, low=32, high=MAX_SYNTH_SIZE, help="height and width of every scene (px)")
    scenes: int = option(3, low=1, high=SCENE_COUNT.range.high, help="number of scenes")

    @property
    def folder_name(self) -> str:
        return f"synthetic_s{self.seed}_{self.size}px_{self.scenes}"


@dataclass(frozen=True)
class Evaluation:
    synthetic: SyntheticEval | None = option(None, help="synthetic scenes generated into OUT/eval_data/")
    data: Path | None = option(None, help="data root of the scenes below, of any dataset lfbench reads (relative to "
                                          "the spec's folder)")
    dataset: str | None = option(None, default_text="detected", help="the dataset adapter data is read with (a "
                                                                     "`lfbench datasets` name); its protocol scores "
                                                                     "the cells")
    scenes: tuple[str, ...] = option((), single=True, help="scenes of data by name, category or split")
    time_size: int = option(512, low=16, high=MAX_SYNTH_SIZE,
                            help="test time: one whole light field of the evaluation scenes' angular size, "
                                 "time_size x time_size px")
    time_repeats: int = option(1, low=1, high=MAX_REPEATS, help="timed runs (the median is reported)")
    time_warmup: int = option(0, low=0, high=MAX_REPEATS, help="untimed runs before them")
    device: Literal["cpu", "cuda", "auto"] = option("cpu", help="scoring and timing device (auto: cuda when "
                                                               "available)")
    threads: int = option(0, low=0, high=MAX_THREADS,
                          help="torch threads for scoring (0: the cell's) and for the test time, measured one cell "
                               "at a time after all cells are trained (0: all cores)")
    tile: int = option(0, low=0, high=MAX_SYNTH_SIZE, help="inference tile size (0: from max_memory_gb)")
    max_memory_gb: float = option(4.0, low=0.0, low_open=True, help="inference memory budget (GB)")
    precision: Literal["fp32", "bf16"] = option("fp32", help="inference precision")
    lowres_only: bool = option(False, help="score the low-resolution maps only")
    error_maps: bool = option(True, help="write the error-map figures")

    @staticmethod
    def check_options(values: dict[str, Any], t: Table) -> dict[str, Any]:
        if values["data"] is not None:
            values["data"] = _resolve(str(values["data"]), Path(t.source or "."), "evaluation.data")
        elif values["scenes"]:
            t.fail("scenes", "names scenes of evaluation.data, which is not given")
        elif values["dataset"] is not None:
            t.fail("dataset", "names the dataset of evaluation.data, which is not given")
        return values

    @property
    def is_synthetic(self) -> bool:
        """Whether the scenes are synthetic: generated by the ablation, or a data root written by lfbench synth
        (its SYNTHETIC marker, lfbench.data.provenance)."""
        from lfbench.data.provenance import is_synthetic_root

        return self.synthetic is not None or (self.data is not None and is_synthetic_root(self.data))

    def fingerprint(self) -> str:
        """What the scores of a cell depend on (not how fast or where they are computed)."""
        key = {"synthetic": None if self.synthetic is None else vars(self.synthetic),
               "data": None if self.data is None else str(self.data), "scenes": list(self.scenes),
               "time_size": self.time_size, "lowres_only": self.lowres_only, "precision": self.precision}
        if self.dataset is not None:  # (absent when detected: the fingerprints of earlier specs stay)
            key["dataset"] = self.dataset
        return sha256_of(key)


@dataclass(frozen=True, kw_only=True)
class ExtraMethod:
    label: str | None = option(None, help="its label in the tables (default: the spec)")
    spec: str = option(help="a registered method spec, e.g. published:path=DIR")

    @staticmethod
    def check_options(values: dict[str, Any], t: Table) -> dict[str, Any]:
        where = f"{t.where}.spec"
        spec = expand_vars(values["spec"], t.source, where)
        try:
            parse_method_spec(spec)
        except SpecError as exc:
            t.fail("spec", _strip_path(exc))
        return {"label": values["label"] or spec, "spec": spec}


@dataclass(frozen=True)
class Stage1:
    shared: bool = option(False, help="train the stages before the last once, in OUT/stage1, and every cell's last "
                                      "stage from those weights (cells may then differ only in their last stage)")


@dataclass(frozen=True)
class Report:
    reference: str | None = option(None, default_text="the network's own, when asked",
                                   help="the paper beside ours: a registered reference (lfbench.reports.reference) "
                                        "or \"none\"; by default the network's own when the spec asks for a paper "
                                        "table or paper methods, or --paper is given")
    paper_methods: tuple[str, ...] | None = option(None, single=True, default_text="the reference's own",
                                                   help="the reference's methods beside ours in Tables I/II")


def _unique(values: tuple) -> str | None:
    return None if len(set(values)) == len(values) else f"each seed once, got {list(values)}"


@dataclass(frozen=True)
class SpecFile:
    """The keys of an ablation spec file, as declared (parse_spec makes an :class:`AblationSpec` of them)."""

    title: str | None = option(None, default_text="the file name", help="title of the tables")
    table: str = option(
        "none", help="the reference's table beside ours: the id of a table its declaration lists (e.g. "
                     "table4), or none / tables12 (Tables I/II, per scene and average, are written "
                     "for every spec)")
    base: str | dict[str, Any] | None = option(
        None, help="the training config every cell starts from (a file, relative to the spec), or an inline [base] "
                   "table in the training-config layout", free_text="")
    out: str | None = option(None, help="default output folder (relative to the current directory)")
    seeds: tuple[int, ...] = option((), low=0, check=_unique,
                                    help="train every cell once per seed (the config's seed; ids end in _seed=K); "
                                         "tables report the mean over seeds with a 95 % t-interval")
    budget: Budget = option(factory=Budget, help="every cell's training budget, written over the base config")
    set: dict[str, Any] = option({}, help="training-config keys written over the base config",
                                 free_text="any training-config keys, dotted (`\"training.log_every\" = 5`, or "
                                           "nested tables); list items by 1-based position (`stages.2.lr`), stages "
                                           "also by name or `last`")
    grid: tuple[dict[str, Any], ...] = option(
        (), help="the cells: the union of the products of every [[grid]] table's axis = [values] (identical configs "
                 "run once); axes: the network's parameters, seed, loss, a loss parameter (beta), lr, method (the "
                 "network, one [[grid]] table each) or a dotted training-config key")
    stage1: Stage1 = option(factory=Stage1, help="a stage 1 shared by the cells")
    evaluation: Evaluation = option(factory=Evaluation, help="the scenes and timing every cell is scored with")
    methods: tuple[ExtraMethod, ...] = option((), help="more rows for Tables I/II: any registered method spec")
    report: Report = option(factory=Report, help="what the tables show beside ours")


@dataclass(frozen=True)
class Cell:
    """One variant: ``values`` (axis -> value, as given in the grid) and the full training config
    (TrainConfig.to_dict() layout) it is trained with."""

    id: str
    values: dict[str, Any]
    config: dict[str, Any]

    def train_config(self, source: str | Path | None = None) -> TrainConfig:
        return TrainConfig.from_dict(self.config, source)

    @property
    def fingerprint(self) -> str:
        """SHA-256 of the config without the settings that may change on resume (threads, device, ...)."""
        return sha256_of(comparable(self.config))


@dataclass(frozen=True)
class AblationSpec:
    source: Path
    title: str
    table: str
    base_source: str
    budget: Budget
    cells: tuple[Cell, ...]
    shared_stage1: bool
    evaluation: Evaluation
    methods: tuple[ExtraMethod, ...] = ()
    paper_methods: tuple[str, ...] | None = None  # None: the reference's own
    reference: str | None = None  # a registered reference's name, "none", or None: the network's when asked
    out: str | None = None
    text: str = field(default="", repr=False)
    seeds: tuple[int, ...] = ()  # training seeds every cell runs (empty: the base config's seed, once)

    def budget_label(self) -> str:
        return self.budget.describe(self.cells[0].config) if self.cells else "no training"

    def stage1_config(self) -> dict[str, Any]:
        """The shared run's config: the first cell's without its last stage (with two stages: stage 1)."""
        cfg = copy.deepcopy(self.cells[0].config)
        cfg["stages"] = cfg["stages"][:-1]
        return cfg


def network_name(config: dict[str, Any]) -> str:
    """The name of the registered trainable network a training config (dict layout) trains."""
    return config.get("method", DEFAULT_TRAINABLE)


def trainable_of(config: dict[str, Any]) -> Trainable:
    """The registered trainable network a training config (dict layout) trains."""
    return get_trainable(network_name(config))


def network_default(config: dict[str, Any], key: str) -> Any:
    """The network's default for parameter ``key`` (None when it has no such parameter)."""
    param = trainable_of(config).parameters().get(key)
    return None if param is None else param.default


def sha256_of(obj: Any) -> str:
    """SHA-256 (hex) of ``obj`` as canonical JSON (sorted keys; other objects as their str)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def _resolve(value: str, source: Path, key: str) -> Path:
    path = Path(expand_vars(value, source, key))
    return path if path.is_absolute() else (source.parent / path)


# --------------------------------------------------------------------------- reading

def load_spec(path: str | Path) -> AblationSpec:
    """Read and check an ablation spec (every cell's training config is parsed; no work is done)."""
    path = Path(path)
    raw, text = read_toml(path, "ablation spec")
    return parse_spec(raw, path, text)


def parse_spec(raw: dict[str, Any], source: Path, text: str = "") -> AblationSpec:
    top = Table(raw, "", str(source))
    if isinstance(raw.get("budget"), dict) and "width" in raw["budget"]:
        top.fail("budget.width", "is now [budget.model] width (model = { width = N }: any of the network's "
                                 "parameters)")
    f = parse_section(SpecFile, top)
    base_cfg, base_source = _parse_base(f.base, source)
    budget = f.budget
    if base_cfg is not None:
        _check_budget(budget, base_cfg, source)
    overrides = flatten(f.set)
    seeds, grid_raw = f.seeds, list(f.grid)
    cells: tuple[Cell, ...] = ()
    if base_cfg is not None:
        base = _apply_budget(base_cfg.to_dict(), budget)
        for key, value in overrides.items():
            _set_dotted(base, key, value, lambda msg, k=key: _fail(source, f"set.{k}", msg))
        _check_config(base, source, "set")
        _check_cell_count(grid_raw, max(1, len(seeds)), source)
        cells = _expand_grid(grid_raw, base, source)
        if seeds:
            cells = _with_seeds(cells, seeds, source)
    elif grid_raw:
        raise SpecError("grid: cells need a base training config (base = \"CONFIG.toml\" or [base])", source)
    methods = f.methods
    labels = [m.label for m in methods]
    if len(set(labels)) != len(labels):
        raise SpecError(f"methods: labels must be unique, got {labels}", source)
    _check_method_names(cells, methods, source)
    if not cells and not methods:
        raise SpecError("nothing to run: give a base config (with a [[grid]], or one cell from the base alone) "
                        "and/or [[methods]]", source)
    shared = f.stage1.shared
    if shared:
        if len(seeds) > 1:
            raise SpecError("stage1.shared trains one stage 1 for all cells, so it cannot vary with seeds; start "
                            "every cell from trained weights instead ([set] init = \"WEIGHTS.pt\", one stage)",
                            source)
        _check_shared_stage1(cells, source)
    evaluation = f.evaluation
    if evaluation.synthetic is None and evaluation.data is None:
        raise SpecError("evaluation: give synthetic = {seed, size, scenes} and/or data = ROOT with scenes", source)
    _check_table(f.table, f.report.reference, network_name(cells[0].config if cells else {}), source)
    return AblationSpec(source=source, title=f.title if f.title is not None else source.stem, table=f.table,
                        base_source=base_source, budget=budget, cells=cells, shared_stage1=shared,
                        evaluation=evaluation, methods=methods, paper_methods=f.report.paper_methods,
                        reference=f.report.reference, out=f.out, text=text, seeds=seeds)


def _check_table(table: str, reference: str | None, network: str, source: Path) -> None:
    """SpecError unless ``table`` is none / tables12 or a table the spec's reference declares (its ``[report]
    reference``, else its network's: lfbench.reports.reference): one for ablations, or a dataset's per-scene
    table (e.g. table3, UrbanLF-Syn), beside which the cells stand when they are scored on that dataset."""
    if table in NO_TABLE:
        return
    from lfbench.reports.reference import get_reference, reference_for_network

    if reference == "none":  # no reference: the spec's table is not written
        return
    ref = get_reference(reference) if reference is not None else reference_for_network(network)
    known = [t.id for t in ref.tables] if ref is not None else []
    if table not in known:
        whose = f"reference {ref.name!r}" if ref is not None else f"no reference of network {network!r}"
        raise SpecError(f"table: expected one of {', '.join([*known, *NO_TABLE])} ({whose}), got {table!r}", source)


def _with_seeds(cells: tuple[Cell, ...], seeds: tuple[int, ...], source: Path) -> tuple[Cell, ...]:
    """Every cell once per seed: values gain seed = K (last), the config's seed is K, the id ends in _seed=K."""
    out = []
    for cell in cells:
        if "seed" in cell.values:
            raise SpecError(f"cell {cell.id}: seed is both a grid axis and given by seeds = [...]; use one", source)
        for seed in seeds:
            values = {**cell.values, "seed": seed}
            config = copy.deepcopy(cell.config)
            config["seed"] = seed
            out.append(Cell(id=cell_id(values), values=values, config=config))
    return tuple(out)


def variant_values(cell: Cell) -> dict[str, Any]:
    """The cell's grid values without the seed: what a row of a seed-averaged table stands for."""
    return {k: v for k, v in cell.values.items() if k != "seed"}


LEAF_TABLES = frozenset({"data.scene_weights"})  # config entries whose value is itself a table


def flatten(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested TOML tables as dotted keys: ``model.width = 8`` (TOML: {"model": {"width": 8}}) and
    ``"model.width" = 8`` both give {"model.width": 8}; tables that are config values stay whole."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, dict) and v and key not in LEAF_TABLES:
            out.update(flatten(v, key))
        else:
            out[key] = v
    return out


def _fail(source: Path, key: str, msg: str):
    raise SpecError(f"{key}: {msg}", source)


def _strip_path(exc: SpecError) -> str:
    return " ".join(str(exc.args[0]).split()) if exc.args else str(exc)


def _parse_base(value: str | dict[str, Any] | None, source: Path) -> tuple[TrainConfig | None, str]:
    if value is None:
        return None, ""
    if isinstance(value, str):
        path = _resolve(value, source, "base")
        if not path.is_file():
            _fail(source, "base", f"training config {path} not found")
        try:
            return TrainConfig.from_toml(path), str(path)
        except SpecError as exc:
            _fail(source, "base", f"{path}: {_strip_path(exc)}")
    try:
        return TrainConfig.from_dict(value, source), "[base]"
    except SpecError as exc:
        _fail(source, "base", _strip_path(exc))
    raise AssertionError  # unreachable


def _check_budget(budget: Budget, base: TrainConfig, source: Path) -> None:
    """One number of steps per stage of the base; [budget.model] names parameters of its network, with
    values of their types."""
    if budget.steps is not None and len(budget.steps) != len(base.stages):
        _fail(source, "budget.steps", f"expected {len(base.stages)} numbers (one per [[stages]] of the base config), "
                                      f"got {len(budget.steps)}")
    problem = model_problem(get_trainable(base.method), budget.model, "budget.model")
    if problem:
        raise SpecError(problem, source)


def _apply_budget(cfg: dict[str, Any], budget: Budget) -> dict[str, Any]:
    cfg = copy.deepcopy(cfg)
    cfg.pop("out", None)
    if budget.steps is not None:
        for stage, steps in zip(cfg["stages"], budget.steps, strict=True):
            stage["steps"] = steps
    if budget.batch is not None:
        cfg["training"]["batch_size"] = budget.batch
    cfg["model"].update(copy.deepcopy(budget.model))
    if budget.patch is not None:
        cfg["data"]["patch"] = budget.patch
    return cfg


def _check_method_names(cells: tuple[Cell, ...], methods: tuple[ExtraMethod, ...], source: Path) -> None:
    """Cell ids and [[methods]] labels name the records (method = id or label), the HTML pages and the
    cells/<id> and methods/<label> folders: SpecError when a label is a cell's id, DataError when two
    are one file name (lfbench.utils.names: 'm<1' and 'm>1' would share methods/m_1)."""
    ids = {c.id for c in cells}
    for m in methods:
        if m.label in ids:
            raise SpecError(f"methods: label {m.label!r} is also the id of a cell; rename it", source)
    names = FileNames("method (cell id or [[methods]] label)", source=source)
    for name in [*(c.id for c in cells), *(m.label for m in methods)]:
        names(name)


# --------------------------------------------------------------------------- cells

def _format_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, dict):  # a loss with parameters: uafl_beta=0.5
        return "_".join([str(v.get("loss", "?")), *(f"{k}={_format_value(x)}" for k, x in v.items() if k != "loss")])
    return str(v)


def cell_id(values: dict[str, Any]) -> str:
    """``axis=value`` joined by ``_``, e.g. ``interval=0.5_interpolation=bilinear`` (file-name safe)."""
    if not values:
        return "base"
    return _ID_SAFE.sub("_", "_".join(f"{k}={_format_value(v)}" for k, v in values.items()))


def _stage_index(stages: list[dict], part: str, fail: Callable[[str], None]) -> int:
    if part == "last":
        return len(stages) - 1
    if part.isdigit():
        k = int(part)
        if not 1 <= k <= len(stages):
            fail(f"stage {k} does not exist (the config has {len(stages)})")
        return k - 1
    for i, st in enumerate(stages):
        if st.get("name") == part:
            return i
    fail(f"no stage named {part!r} (stages: {', '.join(str(s.get('name')) for s in stages)})")
    raise AssertionError  # unreachable


def _set_dotted(cfg: dict[str, Any], key: str, value: Any, fail: Callable[[str], None]) -> None:
    """cfg[a][b]... = value for key 'a.b...'; list items by 1-based position, stages also by name or 'last'."""
    parts = key.split(".")
    node: Any = cfg
    for i, part in enumerate(parts[:-1]):
        if isinstance(node, list):
            idx = _stage_index(node, part, fail) if parts[i - 1] == "stages" else _list_index(node, part, fail)
            node = node[idx]
        elif isinstance(node, dict):
            if part not in node:
                if i == 0 and part not in ("data", "augment", "model", "training", "validation", "stages"):
                    fail(f"unknown training-config table {part!r}")
                node[part] = {}
            node = node[part]
        else:
            fail(f"{'.'.join(parts[:i + 1])} is not a table")
    last = parts[-1]
    if isinstance(node, list):
        node[_list_index(node, last, fail)] = value
    elif isinstance(node, dict):
        node[last] = copy.deepcopy(value)
    else:
        fail(f"{'.'.join(parts[:-1])} is not a table")


def _list_index(items: list, part: str, fail: Callable[[str], None]) -> int:
    if not part.isdigit() or not 1 <= int(part) <= len(items):
        fail(f"{part!r} is not a position 1..{len(items)}")
    return int(part) - 1


def _loss_stage_name(loss: str, index: int, taken: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9]+", "_", loss).strip("_") or "loss"
    name = f"finetune_{base}" if index > 0 else base
    k = 2
    while name in taken:
        name, k = f"{name}_{k}", k + 1
    return name


def apply_axis(cfg: dict[str, Any], axis: str, value: Any, fail: Callable[[str], None]) -> None:
    """Write one grid value into a training config (dict layout of TrainConfig.to_dict())."""
    stages = cfg["stages"]
    last = stages[-1]
    if axis == NETWORK_AXIS:
        _set_network(cfg, value, fail)
        return
    model_axes = trainable_of(cfg).ablation_axes()
    if axis in model_axes:
        cfg["model"][axis] = value
    elif axis == "seed":
        cfg["seed"] = value
    elif axis == "loss":
        if isinstance(value, str):
            loss, params = value, {}
        elif isinstance(value, dict) and isinstance(value.get("loss"), str):
            loss, params = value["loss"], {k: v for k, v in value.items() if k != "loss"}
        else:
            fail(f"expected a loss name or a table {{loss = NAME, ...parameters}}, got {value!r}")
        for k in [k for k in last if k not in STAGE_KEYS]:
            del last[k]
        last["loss"] = loss.strip().lower()
        last.update(params)
        others = {s["name"] for s in stages[:-1]}
        last["name"] = _loss_stage_name(last["loss"], len(stages) - 1, others)
    elif axis in loss_axes():
        last[axis] = value
    elif axis == "lr":
        last["lr"] = value
    elif "." in axis:
        _set_dotted(cfg, axis, value, fail)
    else:
        fail(f"unknown axis; use {', '.join(model_axes + (SPECIAL_AXES[0], *loss_axes(), *SPECIAL_AXES[1:]))}, "
             f"{NETWORK_AXIS} or a "
             "dotted training-config key (e.g. model.width, stages.2.lr)")


def _set_network(cfg: dict[str, Any], value: Any, fail: Callable[[str], None]) -> None:
    """The :data:`NETWORK_AXIS`: the cell trains the registered trainable ``value``, its [model] starting empty
    (the network's defaults); an unregistered name fails naming the registered ones."""
    from lfbench.method.trainable import TRAINABLES

    if not isinstance(value, str) or TRAINABLES.find(value) is None:
        fail(f"{value!r} is not a registered trainable network (registered: {', '.join(TRAINABLES.names())}); "
             "install the network's package first, or comment out this [[grid]] table")
    cfg["method"] = value
    cfg["model"] = {}


def loss_axes() -> tuple[str, ...]:
    """The parameters the registered losses declare after their tensors (lfbench.training.losses.make_loss: e.g.
    a focusing exponent), each an axis that sets the last stage's loss parameter."""
    import inspect

    from lfbench.training.losses import LOSSES

    return tuple(dict.fromkeys(name for loss in LOSSES.names()
                               for name in list(inspect.signature(LOSSES.get(loss)).parameters)[4:]))


def _check_config(cfg: dict[str, Any], source: Path, where: str) -> TrainConfig:
    """Parse the config and check its [model] with the network's ``Trainable.check_params`` (unknown keys, bad
    values); SpecError naming ``where``."""
    try:
        tc = TrainConfig.from_dict(cfg, source)
    except SpecError as exc:
        _fail(source, where, _strip_path(exc))
    try:
        trainable_of(cfg).check_params(tc.model)
    except (TypeError, ValueError) as exc:
        _fail(source, where, f"[model]: {exc}")
    return tc


def _check_cell_count(grid_raw: list[Any], seeds: int, source: Path) -> None:
    """SpecError when the [[grid]] tables (the sum of the products of their value lists) times ``seeds``
    define more than MAX_CELLS cells; counted from the list lengths, before any cell is made."""
    total = 0
    for g in grid_raw:
        count = 1
        for values in (flatten(g).values() if isinstance(g, dict) else ()):
            count *= len(values) if isinstance(values, list) else 1
        total += count
    if total * seeds > MAX_CELLS:
        times = f" x {seeds} seeds" if seeds > 1 else ""
        raise SpecError(f"grid: {total} cells{times} is more than one spec may run ({MAX_CELLS}); split the grid "
                        "into several specs", source)


def _expand_grid(grid_raw: list[Any], base: dict[str, Any], source: Path) -> tuple[Cell, ...]:
    if not grid_raw:
        return (Cell(id="base", values={}, config=base),)
    cells: list[Cell] = []
    seen: dict[str, str] = {}
    for gi, g in enumerate(grid_raw):
        if not isinstance(g, dict) or not g:
            raise SpecError(f"grid[{gi}]: expected a table of axis = [values]", source)
        g = flatten(g)
        axes = list(g)
        for a in axes:
            if not isinstance(g[a], list) or not g[a]:
                _fail(source, f"grid[{gi}].{a}", f"expected a non-empty list of values, got {g[a]!r}")
        # The network first (it resets [model] and decides which axes are its parameters), then the loss (it
        # resets the stage's parameters).
        axes.sort(key=lambda a: (a != NETWORK_AXIS, a != "loss"))
        for combo in itertools.product(*(g[a] for a in axes)):
            values = dict(zip(axes, combo, strict=True))
            order = [a for a in g if a in values]
            values = {a: values[a] for a in order}
            cfg = copy.deepcopy(base)
            for a in axes:
                apply_axis(cfg, a, values[a], lambda msg, a=a, gi=gi: _fail(source, f"grid[{gi}].{a}", msg))
            cid = cell_id(values)
            _check_config(cfg, source, f"grid[{gi}] cell {cid}")
            key = json.dumps(comparable(cfg), sort_keys=True)
            if key in seen:
                continue  # the same training run as an earlier cell
            if any(c.id == cid for c in cells):
                raise SpecError(f"grid[{gi}]: two different cells are both named {cid!r}", source)
            seen[key] = cid
            cells.append(Cell(id=cid, values=values, config=cfg))
    return tuple(cells)


def _check_shared_stage1(cells: tuple[Cell, ...], source: Path) -> None:
    """With a shared stage 1, cells may differ only in their last stage (and need two stages or more)."""
    if not cells:
        raise SpecError("stage1.shared: there are no cells", source)
    first = cells[0].config
    if len(first["stages"]) < 2:
        raise SpecError("stage1.shared needs a base config with two [[stages]] or more", source)
    ref = comparable({**first, "stages": first["stages"][:-1]})
    for c in cells[1:]:
        other = comparable({**c.config, "stages": c.config["stages"][:-1]})
        if other != ref or len(c.config["stages"]) != len(first["stages"]):
            diff = _first_difference(ref, other)
            raise SpecError(f"stage1.shared: cell {c.id} differs from {cells[0].id} outside the last stage "
                            f"({diff}); a shared stage 1 allows only last-stage axes (loss, beta, lr, stages.last.*)",
                            source)


def _first_difference(a: Any, b: Any, path: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else str(k))
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return _first_difference(x, y, f"{path}.{i + 1}")
    return f"{path}: {a!r} vs {b!r}"
