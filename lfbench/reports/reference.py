"""References: a published paper whose numbers lfbench puts beside ours, shipped as data by the plugin of
its method and registered through the entry-point group ``lfbench.references``, e.g. SubFocal's paper
(the bundled ``lfbench_methods``)::

    [project.entry-points."lfbench.references"]
    subfocal-tci2023 = "lfbench_methods.subfocal:paper.toml"   # package : its TOML file

A reference says what the paper's tables are and how ours line up with them; its numbers are not in it
(they are the user's transcription, a folder of CSV files: lfbench.reports.paper). The file is parsed by
the one declared-option system (lfbench.utils.options: :class:`Reference`, :class:`PaperTable`)::

    name = "subfocal-tci2023"                # the registered name (the entry point's)
    networks = ["subfocal", "lfattnet"]      # trainable networks whose ablations it stands beside
    methods = ["SubFocal"]                   # its methods shown beside ours in Tables I/II by default
    label = "paper (RTX 3090, full training)"   # the label of its columns in the ablation tables
    benchmark_note = "..."                   # caption line of the tables with its Tables I/II
    ablation_note = "..."                    # caption line of the tables with its ablation numbers

    [[tables]]                               # one generic declaration per table of the paper
    id = "table3"                            # what lfbench calls it (table1 .. table5, beta, ...)
    file = "table3_urbanlf.csv"              # its CSV in the paper folder ("" for a figure)
    caption = "..."
    keys = ["method"]                        # the CSV columns that identify a row
    metrics = { "badpix_0.07" = "badpix_0.07_avg" }      # metric id -> the CSV column holding it
    dataset = "urbanlf-syn"                  # shown beside results of this dataset (meta.dataset)
    scenes = { Image11 = "Img11" }           # a wide per-scene table: our scene -> column (of scene_metric)
    scene_metric = "badpix_0.07"
    extra = { params_millions = "params_millions" }      # other columns: name -> CSV column
    labels = { figure_title = "..." }        # free text the table's consumers show
    names = { l1 = "baseline_l1" }           # our key value -> the paper's, where they differ
    best = "uafl"                            # the row (key value) the paper finds best

An ablation's table (``table = ID`` in its spec; any declared table without a ``dataset``) is one generic
"our cells beside a declared table" (lfbench.ablation.report.reference_table), read from these keys too::

    axes = { interval = "interval" }         # our axis -> the key column it joins (default: keys by name)
    metrics = { mse_x100 = "" }              # "" : a metric the paper does not report (ours only)
    measures = ["train_time", "test_time"]   # our measured columns, each beside the extra of its name
    where = { beta = "0.1" }                 # what its rows were measured at (a cell with another value joins none)
    trend = { interval = "lower" }           # an ordering tested over seeds (lfbench.ablation.significance)
    order = "descending"                     # rows sorted by the axes
    figure = "curve"                         # or "time": the ablation's figure of this table

report's Table III reads a per-scene declaration (``scenes``) directly (lfbench.reports.paper_scenes).

Which reference an ablation uses: the spec's ``[report] reference``, else, when the spec asks for a
paper table or paper methods (or ``--paper`` is given), the reference of the spec's network, else the
default reference: that of the default network (lfbench.method.trainable.DEFAULT_TRAINABLE).
"""

from __future__ import annotations

import dataclasses
import importlib.util
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Literal

from lfbench.method.trainable import DEFAULT_TRAINABLE
from lfbench.utils.errors import SpecError
from lfbench.utils.options import Table, option, parse_section
from lfbench.utils.registry import Registry
from lfbench.utils.tomlfile import read_toml

__all__ = ["ENTRY_POINT_GROUP", "MEASURES", "PaperTable", "Reference", "default_reference",
           "get_reference", "list_references", "read_reference", "reference_for_network"]

ENTRY_POINT_GROUP = "lfbench.references"
#: What an ablation measures of every cell besides its scores, by name (a table's ``measures``).
MEASURES = ("train_time", "stage_train_time", "test_time")


def _no_blank(value: str) -> str | None:
    return "must not be empty" if not value.strip() else None


@dataclass(frozen=True, kw_only=True)
class PaperTable:
    """One table of a paper, declared generically: where its numbers are and how they line up with ours."""

    id: str = option(help="what lfbench and ablation specs call the table (e.g. table3)", check=_no_blank)
    file: str = option("", help="its CSV file in the paper folder ('' for a figure whose values are not printed)")
    caption: str = option("", help="caption line of the tables that show it")
    keys: tuple[str, ...] = option((), help="the CSV columns that identify a row (join keys), e.g. method")
    metrics: dict[str, str] = option({}, help="metric id -> the CSV column holding it")
    dataset: str = option("", help="the dataset its numbers are of (a `lfbench datasets` name): report shows "
                                  "the table beside results of that dataset ('' for an ablation's table)")
    scenes: dict[str, str] = option({}, help="a wide per-scene table: our scene name -> the CSV column "
                                            "holding its value of `scene_metric`")
    scene_metric: str = option("", help="the metric id of the per-scene columns")
    extra: dict[str, str] = option({}, help="other columns (runtime, parameters, train time): name -> CSV column")
    labels: dict[str, str] = option({}, help="free text its consumers show (figure titles, axis labels): "
                                            "name -> text")
    names: dict[str, str] = option({}, help="our key value -> the paper's row, where they differ")
    best: str = option("", help="the row (key value) the paper finds best, as text")
    axes: dict[str, str] = option({}, help="an ablation's table: our axis (a grid axis, a network parameter, "
                                          "loss, a loss parameter) -> the key column it joins (default: each key "
                                          "is the axis of its name)")
    where: dict[str, str] = option({}, help="what the paper's rows were measured at: a cell joins a row only when "
                                           "each of these values (axis -> value) is unset in it or the same")
    measures: tuple[str, ...] = option((), help="an ablation's table: our measured columns after the metrics "
                                               f"({', '.join(MEASURES)}), each followed by the extra column of "
                                               "its name when declared")
    trend: dict[str, str] = option({}, help="axis -> lower or higher: the paper finds a lower (higher) value "
                                           "better, at equal values of the other axes (tested over seeds)")
    order: Literal["", "ascending", "descending"] = option("", help="an ablation's table: rows sorted by its "
                                                                   "axes ('' : the cells' order)")
    figure: Literal["", "curve", "time"] = option("", help="an ablation's figure: curve (the first metric "
                                                          "against the axis) or time (against test time; colour: "
                                                          "the second axis, labels: the first)")

    @staticmethod
    def check_options(values: dict, table: Table) -> None:
        """A per-scene table names its file and its metric; a trend is lower or higher."""
        for key in ("file", "scene_metric"):
            if values["scenes"] and not values[key]:
                table.fail(key, "is required with scenes")
        for axis, way in values["trend"].items():
            if way not in ("lower", "higher"):
                table.fail("trend", f"{axis}: expected lower or higher, got {way!r}")
        unknown = [m for m in values["measures"] if m not in MEASURES]
        if unknown:
            table.fail("measures", f"unknown {', '.join(unknown)} (known: {', '.join(MEASURES)})")

    @property
    def join(self) -> dict[str, str]:
        """Our axis -> the key column it joins (``axes``, else each key as the axis of its name)."""
        return dict(self.axes) if self.axes else {k: k for k in self.keys}

    def header(self, name: str, default: str) -> str:
        """``labels[name]`` when declared, else ``default``."""
        return self.labels.get(name, default)

    def label(self, name: str) -> str:
        """``labels[name]``; SpecError naming the table when the reference does not give it."""
        if name not in self.labels:
            raise SpecError(f"reference table {self.id!r}: labels.{name} is required")
        return self.labels[name]

    def column(self, name: str) -> str:
        """The CSV column of the extra column ``name``; SpecError when the reference does not give it."""
        if name not in self.extra:
            raise SpecError(f"reference table {self.id!r}: extra.{name} is required")
        return self.extra[name]


def _unique_ids(tables: tuple[PaperTable, ...]) -> str | None:
    ids = [t.id for t in tables]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    return f"table id {twice[0]!r} declared twice" if twice else None


@dataclass(frozen=True, kw_only=True)
class Reference:
    """A paper lfbench puts beside ours (see the module docstring for the file layout)."""

    name: str = option(help="the registered name (the entry point's)", check=_no_blank)
    networks: tuple[str, ...] = option(help="trainable networks whose ablations it stands beside")
    methods: tuple[str, ...] = option(help="its methods shown beside ours in Tables I/II by default")
    label: str = option(help="the label of its columns in the ablation tables")
    benchmark_note: str = option(help="caption line of the tables with its Tables I/II")
    ablation_note: str = option(help="caption line of the tables with its ablation numbers")
    tables: tuple[PaperTable, ...] = option((), help="its tables (an array of tables)", check=_unique_ids)
    source: str = field(default="", compare=False)

    def table(self, table_id: str) -> PaperTable | None:
        """The declaration of the table ``table_id``, None when the paper has none."""
        return next((t for t in self.tables if t.id == table_id), None)

    def ablation_tables(self) -> tuple[PaperTable, ...]:
        """The tables an ablation spec may stand beside (``table = ID``): those not of a dataset's results."""
        return tuple(t for t in self.tables if not t.dataset)


def read_reference(path: str | Path) -> Reference:
    """The reference in the TOML file ``path`` (SpecError naming the file and key when it is not one)."""
    path = Path(path)
    raw, _ = read_toml(path, "reference")
    ref = parse_section(Reference, Table(raw, "", str(path)))
    return dataclasses.replace(ref, source=str(path))


def list_references() -> dict[str, Reference]:
    """Every registered reference by name (the entry points of ``lfbench.references``, loaded by the one
    Registry: a broken one is left out and named in ``REFERENCES.load_errors``)."""
    return {name: REFERENCES.get(name) for name in REFERENCES.names()}


def _entry_reference(ep: metadata.EntryPoint) -> Reference:
    """The reference an entry point ``package:file.toml`` names, read from its data file."""
    path = _data_file(ep)
    reference = read_reference(path)
    if reference.name != ep.name:
        raise SpecError(f"reference {ep.name!r}: its file says name = {reference.name!r}", path)
    return reference


#: Every registered reference, by name: the entry points of ``lfbench.references``, each read from its data file.
REFERENCES: Registry[Reference] = Registry("reference", Reference, group=ENTRY_POINT_GROUP, load=_entry_reference)


def _data_file(ep: metadata.EntryPoint) -> Path:
    """The file an entry point ``package:file.toml`` names, found without running the package's
    ``__init__`` (a plugin's package may import torch: a report needs only its data file)."""
    try:
        spec = importlib.util.find_spec(ep.module)
    except (ImportError, ValueError) as exc:
        spec, why = None, str(exc)
    else:
        why = "no such package"
    folders = list(spec.submodule_search_locations or []) if spec is not None else []
    if not folders or not ep.attr:
        raise SpecError(f"reference {ep.name!r} ({ep.value}): expected 'package:file.toml' of an installed "
                        f"package ({why})")
    return Path(folders[0]) / ep.attr


def get_reference(name: str) -> Reference:
    """The registered reference ``name``; SpecError 'Unknown reference ... Available: ...' otherwise."""
    return REFERENCES.get(name)


def reference_for_network(network: str) -> Reference | None:
    """The registered reference whose ``networks`` include ``network`` (None when there is none)."""
    return next((r for r in list_references().values() if network in r.networks), None)


def default_reference() -> Reference | None:
    """The reference of the default network: what a paper folder is read as when nothing names another."""
    return reference_for_network(DEFAULT_TRAINABLE)
