"""Ablation specs: a TOML file naming a base training config, a grid of variants, the training budget
of every cell, the evaluation scenes and the paper table to put beside ours. Parsed strictly:
a bad key or value is a SpecError naming the spec file and the key (the CLI exits with code 2).

Layout (paths are relative to the spec file's folder; ``~`` and ``${VARS}`` are expanded)::

    title = "Table IV: disparity interval x interpolation"
    table = "table4"            # paper table beside ours: table4 | table5 | beta | tables12 | none
                                # (Tables I/II, per scene and average, are written for every spec;
                                # with "none" no paper numbers unless [report] or --paper asks)
    base = "../configs/subfocal_cpu_small.toml"   # the training config every cell starts from,
                                # or an inline [base] table in the training-config layout
    out = "runs/ablate/table4"  # default output folder (relative to the current directory)
    seeds = [1, 2, 3]           # optional: every cell is trained once per seed (the config's seed; cell ids
                                # end in _seed=K); tables report the mean over seeds with a 95 % t-interval
                                # and a paired test between neighbouring cells (lfbench.ablation.significance)

    [budget]                    # every cell's training budget (written over the base config)
    steps = [48, 12]            # steps per stage, one number per [[stages]] of the base
    batch = 4                   # training.batch_size
    width = 8                   # model.width (SubFocal: 3D aggregation channels; paper 150)
    patch = 32                  # data.patch
    threads = 0                 # torch threads per cell (0: cores / --jobs)

    [set]                       # any other training-config keys, dotted; list items by 1-based
    "data.validation" = []      # position (stages.2.lr), stages also by name or "last"

    [[grid]]                    # the cells: the union of the products of every [[grid]] table
    interval = [1, 0.5, 0.25, 0.1]              # (identical configs are run once)
    interpolation = ["bilinear"]
    [[grid]]
    interval = [0.5]
    interpolation = ["phase", "nearest", "bilinear"]

    [stage1]
    shared = false              # true: the stages before the last (stage 1) are trained once, in
                                # OUT/stage1, and every cell trains its last stage from those weights
                                # (the paper's Table V and beta sweep); cells may then differ only
                                # in their last stage

    [evaluation]
    synthetic = { seed = 1000, size = 64, scenes = 3 }   # generated into OUT/eval_data/
    data = "${LFBENCH_HCI_ROOT}"                          # and/or HCI scenes by name, category or split
    scenes = ["backgammon"]
    time_size = 512             # test time: one whole 9 x 9 x time_size x time_size light field
    time_repeats = 1            # timed runs (the median is reported) after time_warmup untimed ones
    time_warmup = 0
    device = "cpu"              # cpu, cuda or auto (auto: cuda when available)
    threads = 0                 # torch threads for scoring (0: the cell's) and for the test time, which
                                # is measured one cell at a time after all cells are trained (0: all cores)
    tile = 0; max_memory_gb = 4.0; precision = "fp32"; lowres_only = false; error_maps = true

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
from typing import Any

from lfbench.data.synth import MAX_SYNTH_SCENES, MAX_SYNTH_SIZE
from lfbench.training.config import STAGE_KEYS, TrainConfig, _Table
from lfbench.utils.envvars import expand_vars
from lfbench.utils.errors import SpecError

TABLES = ("table4", "table5", "beta", "tables12", "none")
SPECIAL_AXES = ("loss", "beta", "lr", "seed")
DEVICES = ("cpu", "cuda", "auto")
MAX_CELLS = 1024  # cells (x seeds) one spec may define: counted before any cell is made
MAX_REPEATS = 1000  # timed (and warm-up) runs of the test time
MAX_THREADS = 4096
_ID_SAFE = re.compile(r"[^A-Za-z0-9._=+-]")


@dataclass(frozen=True)
class Budget:
    """What every cell is trained with; None = the base config's value."""

    steps: tuple[int, ...] | None = None
    batch: int | None = None
    width: int | None = None
    patch: int | None = None
    threads: int = 0

    def describe(self, config: dict[str, Any]) -> str:
        """A short label of the budget actually used, e.g. 'width 8, batch 4, patch 32, 48+12 steps, cpu'
        (the width when the network has one: the config's, else the network's default)."""
        steps = "+".join(str(s["steps"]) for s in config["stages"])
        device = config.get("training", {}).get("device", "auto")
        width = config["model"].get("width", network_default(config, "width"))
        return (f"{f'width {width}, ' if width is not None else ''}batch {config['training']['batch_size']}, "
                f"patch {config['data']['patch']}, {steps} steps, {device}")


@dataclass(frozen=True)
class SyntheticEval:
    """Evaluation scenes from lfbench.data.synth: ``scenes`` scenes of ``size`` px, generated with ``seed``."""

    seed: int
    size: int
    scenes: int

    @property
    def folder_name(self) -> str:
        return f"synthetic_s{self.seed}_{self.size}px_{self.scenes}"


@dataclass(frozen=True)
class Evaluation:
    synthetic: SyntheticEval | None = None
    data: Path | None = None
    scenes: tuple[str, ...] = ()
    time_size: int = 512
    time_repeats: int = 1
    time_warmup: int = 0
    device: str = "cpu"
    threads: int = 0
    tile: int = 0
    max_memory_gb: float = 4.0
    precision: str = "fp32"
    lowres_only: bool = False
    error_maps: bool = True

    def fingerprint(self) -> str:
        """What the scores of a cell depend on (not how fast or where they are computed)."""
        key = {"synthetic": None if self.synthetic is None else vars(self.synthetic),
               "data": None if self.data is None else str(self.data), "scenes": list(self.scenes),
               "time_size": self.time_size, "lowres_only": self.lowres_only, "precision": self.precision}
        return _sha(key)


@dataclass(frozen=True)
class ExtraMethod:
    label: str
    spec: str


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
        from lfbench.training.loop import comparable

        return _sha(comparable(self.config))


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


def trainable_of(config: dict[str, Any]):
    """The registered trainable network a training config (dict layout) trains."""
    from lfbench.method.trainable import DEFAULT_TRAINABLE, get_trainable

    return get_trainable(config.get("method", DEFAULT_TRAINABLE))


def network_default(config: dict[str, Any], key: str) -> Any:
    """The network's default for parameter ``key`` (None when it has no such parameter)."""
    param = trainable_of(config).parameters().get(key)
    return None if param is None else param.default


def _sha(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def _resolve(value: str, source: Path, key: str) -> Path:
    path = Path(expand_vars(value, source, key))
    return path if path.is_absolute() else (source.parent / path)


# --------------------------------------------------------------------------- reading

def load_spec(path: str | Path) -> AblationSpec:
    """Read and check an ablation spec (every cell's training config is parsed; no work is done)."""
    from lfbench.utils.tomlfile import read_toml

    path = Path(path)
    raw, text = read_toml(path, "ablation spec")
    return parse_spec(raw, path, text)


def parse_spec(raw: dict[str, Any], source: Path, text: str = "") -> AblationSpec:
    src = str(source)
    top = _Table(raw, "", src)
    title = top.get("title", str, source.stem)
    table = top.get("table", str, "none")
    if table not in TABLES:
        top._fail("table", f"expected one of {', '.join(TABLES)}, got {table!r}")
    out = top.get("out", str, None)
    seeds = _parse_seeds(top)
    base_cfg, base_source = _parse_base(top, source)
    budget = _parse_budget(top.table("budget"), base_cfg, source)
    set_t = top.table("set")
    overrides = flatten(set_t.raw)
    set_t.used |= set(set_t.raw)
    grid_raw = top.get("grid", list, [])
    stage1_t = top.table("stage1")
    shared = stage1_t.get("shared", bool, False)
    stage1_t.done()
    evaluation = _parse_evaluation(top.table("evaluation"), source)
    methods = _parse_methods(top.get("methods", list, []), source)
    report_t = top.table("report")
    paper_methods = report_t.strings("paper_methods") if "paper_methods" in report_t.raw else None
    reference = report_t.get("reference", str, None)
    report_t.done()
    top.done()

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
    _check_method_names(cells, methods, source)
    if not cells and not methods:
        raise SpecError("nothing to run: give a base config (with a [[grid]], or one cell from the base alone) "
                        "and/or [[methods]]", source)
    if shared:
        if len(seeds) > 1:
            raise SpecError("stage1.shared trains one stage 1 for all cells, so it cannot vary with seeds; start "
                            "every cell from trained weights instead ([set] init = \"WEIGHTS.pt\", one stage)",
                            source)
        _check_shared_stage1(cells, source)
    if evaluation.synthetic is None and evaluation.data is None:
        raise SpecError("evaluation: give synthetic = {seed, size, scenes} and/or data = ROOT with scenes", source)
    return AblationSpec(source=source, title=title, table=table, base_source=base_source, budget=budget,
                        cells=cells, shared_stage1=shared, evaluation=evaluation, methods=methods,
                        paper_methods=paper_methods, reference=reference, out=out, text=text, seeds=seeds)


def _parse_seeds(top: _Table) -> tuple[int, ...]:
    raw = top.get("seeds", list, [])
    if not all(isinstance(x, int) and not isinstance(x, bool) and 0 <= x < 2**63 for x in raw):
        top._fail("seeds", f"expected a list of non-negative integers, got {raw!r}")
    if len(set(raw)) != len(raw):
        top._fail("seeds", f"each seed once, got {raw!r}")
    return tuple(raw)


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


def _parse_base(top: _Table, source: Path) -> tuple[TrainConfig | None, str]:
    value = top.get("base", (str, dict), None)
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


def _parse_budget(t: _Table, base: TrainConfig | None, source: Path) -> Budget:
    steps = t.get("steps", (list, int), None)
    if isinstance(steps, int) and not isinstance(steps, bool):
        steps = [steps]
    if steps is not None:
        if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 1 for s in steps):
            t._fail("steps", f"expected positive integers (one per stage), got {steps!r}")
        if base is not None and len(steps) != len(base.stages):
            t._fail("steps", f"expected {len(base.stages)} numbers (one per [[stages]] of the base config), "
                             f"got {len(steps)}")
    budget = Budget(steps=tuple(steps) if steps is not None else None,
                    batch=t.number("batch", None, low=1, integer=True) if "batch" in t.raw else None,
                    width=t.number("width", None, low=1, integer=True) if "width" in t.raw else None,
                    patch=t.number("patch", None, low=8, integer=True) if "patch" in t.raw else None,
                    threads=t.number("threads", 0, low=0, high=MAX_THREADS, integer=True))
    t.done()
    if budget.width is not None and base is not None:
        from lfbench.method.trainable import get_trainable

        if "width" not in get_trainable(base.method).parameters():
            _fail(source, "budget.width", f"network {base.method!r} has no width parameter; set its [model] "
                                          "parameters with [set] instead")
    return budget


def _apply_budget(cfg: dict[str, Any], budget: Budget) -> dict[str, Any]:
    cfg = copy.deepcopy(cfg)
    cfg.pop("out", None)
    if budget.steps is not None:
        for stage, steps in zip(cfg["stages"], budget.steps, strict=True):
            stage["steps"] = steps
    if budget.batch is not None:
        cfg["training"]["batch_size"] = budget.batch
    if budget.width is not None:
        cfg["model"]["width"] = budget.width
    if budget.patch is not None:
        cfg["data"]["patch"] = budget.patch
    return cfg


def _parse_evaluation(t: _Table, source: Path) -> Evaluation:
    syn = None
    if "synthetic" in t.raw:
        st = t.table("synthetic")
        syn = SyntheticEval(seed=st.number("seed", 0, low=0, integer=True),
                            size=st.number("size", 64, low=32, high=MAX_SYNTH_SIZE, integer=True),
                            scenes=st.number("scenes", 3, low=1, high=MAX_SYNTH_SCENES, integer=True))
        st.done()
    data_value = t.get("data", str, None)
    data = _resolve(data_value, source, "evaluation.data") if data_value is not None else None
    scenes = t.strings("scenes")
    if scenes and data is None:
        t._fail("scenes", "names scenes of evaluation.data, which is not given")
    device = t.get("device", str, "cpu")
    if device not in DEVICES:
        t._fail("device", f"expected one of {', '.join(DEVICES)}, got {device!r}")
    precision = t.get("precision", str, "fp32")
    if precision not in ("fp32", "bf16"):
        t._fail("precision", f"expected fp32 or bf16, got {precision!r}")
    ev = Evaluation(synthetic=syn, data=data, scenes=scenes,
                    time_size=t.number("time_size", 512, low=16, high=MAX_SYNTH_SIZE, integer=True),
                    time_repeats=t.number("time_repeats", 1, low=1, high=MAX_REPEATS, integer=True),
                    time_warmup=t.number("time_warmup", 0, low=0, high=MAX_REPEATS, integer=True),
                    device=device, threads=t.number("threads", 0, low=0, high=MAX_THREADS, integer=True),
                    tile=t.number("tile", 0, low=0, high=MAX_SYNTH_SIZE, integer=True),
                    max_memory_gb=t.number("max_memory_gb", 4.0, low=0.0, low_open=True),
                    precision=precision, lowres_only=t.get("lowres_only", bool, False),
                    error_maps=t.get("error_maps", bool, True))
    t.done()
    return ev


def _parse_methods(raw: list[Any], source: Path) -> tuple[ExtraMethod, ...]:
    from lfbench.method.registry import parse_spec as parse_method_spec

    out = []
    for i, item in enumerate(raw):
        t = _Table(item, f"methods[{i}]", str(source))
        spec = t.get("spec", str, None, required=True)
        label = t.get("label", str, None)
        t.done()
        spec = expand_vars(spec, source, f"methods[{i}].spec")
        try:
            parse_method_spec(spec)
        except SpecError as exc:
            _fail(source, f"methods[{i}].spec", _strip_path(exc))
        out.append(ExtraMethod(label=label or spec, spec=spec))
    labels = [m.label for m in out]
    if len(set(labels)) != len(labels):
        raise SpecError(f"methods: labels must be unique, got {labels}", source)
    return tuple(out)


def _check_method_names(cells: tuple[Cell, ...], methods: tuple[ExtraMethod, ...], source: Path) -> None:
    """Cell ids and [[methods]] labels name the records (method = id or label), the HTML pages and the
    cells/<id> and methods/<label> folders: SpecError when a label is a cell's id, DataError when two
    are one file name (lfbench.utils.names: 'm<1' and 'm>1' would share methods/m_1)."""
    from lfbench.utils.names import FileNames

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
    elif axis == "beta":
        last["beta"] = value
    elif axis == "lr":
        last["lr"] = value
    elif "." in axis:
        _set_dotted(cfg, axis, value, fail)
    else:
        fail(f"unknown axis; use {', '.join(model_axes + SPECIAL_AXES)} or a dotted training-config key "
             "(e.g. model.width, stages.2.lr)")


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
    from lfbench.training.loop import comparable

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
        axes.sort(key=lambda a: a != "loss")  # the loss resets the stage's parameters: set it first
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
    from lfbench.training.loop import comparable

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
