"""A paper's published numbers, for "paper vs ours" columns in the tables.

A paper folder holds ``table1_per_scene.csv`` (method, scene, metric, value: Table I),
``table2_average.csv`` (method, metric, value: Table II, mean over the 12 benchmark scenes) and
other tables (e.g. an ablation's, which the paper's reference names: lfbench.reports.reference) kept as
plain DataFrames. lfbench ships no copy of them: the folder is the user's (e.g. ../shared/data/paper),
found by :func:`find_paper_dir` (--paper DIR, else $LFBENCH_PAPER_DIR, else $LFBENCH_HCI_ROOT/../paper)
and read as the numbers of a reference (by default the default reference: the default network's paper),
which says which of its methods are shown unless asked otherwise (:attr:`PaperTables.default_methods`).

Resolution: the benchmark (and so the paper) scores backgammon, dots and stripes at high
resolution (lfbench.scoring.rules.benchmark_highres_scenes), the other scenes at 512x512; the columns
added here say so.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lfbench.reports.reference import Reference, default_reference
from lfbench.scoring.rules import benchmark_highres_scenes
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.readfile import read_csv

if TYPE_CHECKING:
    import pandas as pd

PAPER_DIR_ENV, HCI_ROOT_ENV = "LFBENCH_PAPER_DIR", "LFBENCH_HCI_ROOT"
PER_SCENE_FILE, AVERAGE_FILE = "table1_per_scene.csv", "table2_average.csv"
PAPER_RESOLUTION_COLUMN = "paper resolution"


def find_paper_dir(explicit: str | Path | None = None) -> Path:
    """The folder holding the paper's tables, in this order: ``explicit`` (e.g. --paper DIR); the
    environment variable LFBENCH_PAPER_DIR; ``$LFBENCH_HCI_ROOT/../paper`` when that folder exists.
    The first two are returned as given (load_paper names them if they are missing); none of the
    three: DataError."""
    if explicit is not None and str(explicit):
        return Path(explicit)
    if os.environ.get(PAPER_DIR_ENV):
        return Path(os.environ[PAPER_DIR_ENV])
    if os.environ.get(HCI_ROOT_ENV):
        beside = Path(os.environ[HCI_ROOT_ENV]) / os.pardir / "paper"
        if beside.is_dir():
            return beside.resolve()
    raise DataError("the paper's tables were not found: pass --paper DIR (e.g. ../shared/data/paper) "
                    f"or set {PAPER_DIR_ENV}")


@dataclass
class PaperTables:
    """The paper's tables: per_scene (method, scene, metric, value), average (method, metric, value),
    and ``extra`` (file stem -> DataFrame) for the others; ``reference``: what the paper is (its
    methods shown by default, its labels and ablation tables), None when no reference is registered."""

    source: Path
    per_scene: pd.DataFrame
    average: pd.DataFrame
    extra: dict[str, pd.DataFrame] = field(default_factory=dict)
    reference: Reference | None = None

    @property
    def default_methods(self) -> tuple[str, ...]:
        """The paper's methods shown beside ours unless others are asked for (its reference's)."""
        return self.reference.methods if self.reference is not None else ()

    def methods_shown(self, asked: Sequence[str] | None = None) -> list[str]:
        """The paper's spelling of ``asked`` (default: :attr:`default_methods`); SpecError for an unknown
        name or when neither names any."""
        names = list(asked) if asked else list(self.default_methods)
        if not names:
            raise SpecError(f"the paper's tables in {self.source} come with no reference that names its methods: "
                            "name them (--paper-methods, [report] paper_methods)")
        return [self.resolve_method(m) for m in names]

    def shows(self, table_id: str, meta: Mapping[str, Any]) -> bool:
        """Whether the paper's table ``table_id`` stands beside results with ``meta``: unless its declaration
        names a dataset and the results record another (e.g. the HCI Tables I/II beside UrbanLF-Syn results)."""
        declared = self.reference.table(table_id) if self.reference is not None else None
        dataset = meta.get("dataset")
        return declared is None or not declared.dataset or not dataset or declared.dataset == dataset

    @property
    def methods(self) -> list[str]:
        return list(dict.fromkeys([*self.per_scene["method"], *self.average["method"]]))

    @property
    def scenes(self) -> list[str]:
        return list(dict.fromkeys(self.per_scene["scene"]))

    def resolve_method(self, name: str) -> str:
        """The paper's spelling of a method name (case-insensitive); SpecError listing them if unknown."""
        for m in self.methods:
            if m.lower() == name.lower():
                return m
        raise SpecError(f"the paper has no method {name!r}; it has: {', '.join(self.methods)}")

    def value(self, method: str, scene: str, metric: str) -> float:
        """Table I value, or NaN when the paper does not report it."""
        df = self.per_scene
        sel = df[(df["method"] == method) & (df["scene"] == scene) & (df["metric"] == metric)]
        return float(sel["value"].iloc[0]) if len(sel) else float("nan")

    def average_value(self, method: str, metric: str) -> float:
        """Table II value (mean over the 12 benchmark scenes), or NaN."""
        df = self.average
        sel = df[(df["method"] == method) & (df["metric"] == metric)]
        return float(sel["value"].iloc[0]) if len(sel) else float("nan")


def _read_csv(path: Path, columns: Sequence[str] | None) -> pd.DataFrame:
    import pandas as pd

    df = read_csv(path, "paper table")
    if columns is None:
        return df
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise DataError(f"missing column(s) {', '.join(missing)}; expected {', '.join(columns)}", path)
    df = df[list(columns)].copy()
    values = pd.to_numeric(df["value"], errors="coerce")
    bad = values.isna() & df["value"].notna()
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy())[0])
        raise DataError(f"line {row + 2}: value {df['value'].iloc[row]!r} is not a number", path)
    df["value"] = values.astype(float)
    for c in columns:
        if c != "value":
            df[c] = df[c].astype(str).str.strip()
    return df


def load_paper(path: str | Path, reference: Reference | None = None) -> PaperTables:
    """Load the paper's tables from a folder (see :func:`find_paper_dir` to locate it) as the numbers of
    ``reference`` (default: the default reference). DataError naming the file when a table is missing or
    malformed."""
    folder = Path(path)
    reference = reference or default_reference()
    per_scene_file = _declared_file(reference, "table1", PER_SCENE_FILE)
    average_file = _declared_file(reference, "table2", AVERAGE_FILE)
    if not folder.is_dir():
        raise DataError(f"paper folder not found (expected {per_scene_file}, {average_file})", folder)
    per_scene = _read_csv(folder / per_scene_file, ("method", "scene", "metric", "value"))
    average = _read_csv(folder / average_file, ("method", "metric", "value"))
    extra = {p.stem: _read_csv(p, None) for p in sorted(folder.glob("*.csv"))
             if p.name not in (per_scene_file, average_file)}
    return PaperTables(source=folder, per_scene=per_scene, average=average, extra=extra, reference=reference)


def _declared_file(reference: Reference | None, table_id: str, default: str) -> str:
    """The file the reference declares for its table ``table_id`` (Tables I/II: long tables of method, scene,
    metric, value), else ``default``."""
    table = reference.table(table_id) if reference is not None else None
    return table.file if table is not None and table.file else default


def paper_resolution(scene: str) -> str:
    """How the benchmark (and so the paper) scored ``scene``: 'highres' or 'lowres'."""
    return "highres" if scene in benchmark_highres_scenes() else "lowres"


def paper_column(method: str) -> str:
    """The label of a paper column: e.g. 'SubFocal (paper)'."""
    return f"{method} (paper)"


def per_scene_with_paper(table: pd.DataFrame, paper: PaperTables,
                         methods: Sequence[str] | None = None) -> pd.DataFrame:
    """Table I (rows (scene, metric), from report.tables.per_scene_table) with the paper's values of
    ``methods`` (default: the paper's default methods) in columns 'NAME (paper)' and the resolution the
    paper's number was scored at in 'paper resolution' (high resolution for backgammon, dots and
    stripes). Cells the paper does not report (other scenes, Q25) are NaN."""
    if table.empty:
        return table
    names = paper.methods_shown(methods)
    out = table.copy()
    scenes = out.index.get_level_values(0)
    metrics = out.index.get_level_values(1)
    out[PAPER_RESOLUTION_COLUMN] = [paper_resolution(s) if s in paper.scenes else "-" for s in scenes]
    lookup = paper.per_scene.set_index(["method", "scene", "metric"])["value"]
    for name in names:
        out[paper_column(name)] = [float(lookup.get((name, s, m), np.nan)) for s, m in zip(scenes, metrics,
                                                                                            strict=True)]
    return out


def average_with_paper(table: pd.DataFrame, paper: PaperTables, scenes: Sequence[str],
                       methods: Sequence[str] | None = None) -> pd.DataFrame:
    """Table II (rows method, from report.tables.average_table) with rows for the paper's methods:
    'NAME (paper, Table II, 12 scenes)' (the published averages) and, when the paper reports some of
    ``scenes`` (ours) but not all 12, 'NAME (paper, N of our scenes)': the mean of its Table I over
    those N scenes, the row to compare with a method scored on the same scenes (see 'scenes')."""
    import pandas as pd

    if table.empty:
        return table
    names = paper.methods_shown(methods)
    metric_cols = [c for c in table.columns if c not in ("scenes", "runtime_s")]
    rows = {}
    n_paper = len(paper.scenes)
    covered = [s for s in dict.fromkeys(scenes) if s in paper.scenes]
    for name in names:
        label = f"{name} (paper, Table II, {n_paper} scenes)"
        rows[label] = {c: paper.average_value(name, c) for c in metric_cols} | {"scenes": n_paper}
        if covered and len(covered) != n_paper:
            label = f"{name} (paper, {len(covered)} of our scenes)"
            vals = {c: float(np.mean([paper.value(name, s, c) for s in covered])) for c in metric_cols}
            rows[label] = vals | {"scenes": len(covered)}
    extra = pd.DataFrame.from_dict(rows, orient="index").reindex(columns=table.columns)
    extra.index.name = table.index.name
    out = pd.concat([table, extra])
    if "scenes" in out.columns:
        out["scenes"] = out["scenes"].astype("Int64")
    return out
