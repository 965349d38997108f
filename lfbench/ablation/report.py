"""Tables and figures of an ablation run, with a reference's numbers (the paper of the spec's network,
lfbench.reports.reference) in adjacent, labelled columns: the ablation's output writers
(lfbench.reports.writers), which ``lfbench ablate`` runs into its staged set.

Written into OUT (each table as .md, .tex and .csv); every metric column is labelled by its definition
(lfbench.scoring.base.Metric.label), and the metrics are those the reference's table declares, else the
ordered metrics of the protocol of the dataset the cells were scored on (:func:`ablation_metrics`):

- ``table_cells``: one row per cell: its grid values, the mean of each metric over the evaluation scenes,
  train time and test time;
- the spec's ``table`` (an id the reference declares, e.g. ``table4``): our cells
  beside the declared table (:func:`reference_table`: its axes joined to the paper's key columns, its metrics,
  our measures beside its extra columns), named ``<id>`` (or ``table_<id>``), and the figure it declares:
  ``<axis>_curve.png`` or ``accuracy_vs_test_time.png`` (lfbench.ablation.plots);
- ``table_seeds`` / ``table_significance`` (the spec has seeds): mean and 95 % t-interval over seeds per
  variant (clipped to each metric's range), and the orderings the declared table states as paired t-tests;
- ``table_baselines`` (the spec has [[methods]]): every cell (with seeds: variant) against each extra
  method, e.g. the plane sweep and the zero map, per scene group, with a verdict per baseline
  (lfbench.ablation.baselines); its summary lines ("every cell beats ..." or "K of N cells do not beat ...")
  are logged and head the captions of table_cells, this table and the paper-style table;
- ``table_per_scene`` / ``table_average`` (Tables I/II) for every cell and extra method, and, with a
  reference whose Tables I/II cover some evaluation scene, ``table_per_scene_paper`` / ``table_average_paper``;
- ``table_<id>_paper``: each per-scene table the reference declares for the dataset the cells were scored on
  (e.g. Table III on UrbanLF-Syn), as ``lfbench report`` writes it (lfbench.reports.paper_scenes);
- figures/error_maps/ (per scene: one row per variant with disparity, BadPix map, signed error and
  uncertainty; the BadPix(t) curves), drawn from the maps the cells saved;
- html/ (``--html``): the site, with the tables of the means over seeds, the orderings and the verdicts.

"ours" columns are labelled with the budget (width, batch, patch, steps, device) and the test-time
input size; "paper" columns with the reference's label. Which reference: the spec's ``[report]
reference``, else the reference of the spec's network when the spec asks for a paper table
(``table`` is not "none"), names paper methods, or ``--paper`` is given; a plugin's ablation with
``table = "none"`` shows no paper numbers. Without the paper's tables (its folder not found) there
are no paper columns, and one line says so.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lfbench.ablation import plots
from lfbench.ablation.baselines import baselines_caption, baselines_table, scene_groups, summary_lines, verdict_metrics
from lfbench.ablation.cell import load_scenes
from lfbench.ablation.facts import axis_text, axis_value, cell_info, network_of, same_value
from lfbench.ablation.significance import ALPHA, ORDERING_METRIC, ordering_metric, seeds_table, significance_table
from lfbench.ablation.spec import NO_TABLE, AblationSpec
from lfbench.data.provenance import SYNTHETIC_CAPTION
from lfbench.reports.html import SiteInputs, SiteSection
from lfbench.reports.maps import saved_predictions
from lfbench.reports.paper import PaperTables, find_paper_dir, load_paper
from lfbench.reports.paper_scenes import scene_table_with_paper, scene_tables
from lfbench.reports.reference import PaperTable, Reference, default_reference, get_reference, reference_for_network
from lfbench.reports.tables import write_table
from lfbench.reports.writers import (
    FIGURES_DIR,
    OutputWriter,
    RunOutputs,
    SceneFigures,
    Site,
    Tables,
    drive_writers,
)
from lfbench.results import Results
from lfbench.scoring.metrics import METRICS, describe_metric, get_metric, metric_order, primary_metric
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.names import file_name
from lfbench.utils.outputs import check_within

__all__ = ["MAP_CHOICES", "AblationFigures", "AblationSite", "AblationTables", "best_cell", "cell_frame", "check_maps",
           "drawn_map_folders", "load_paper_tables", "primary_ablation_metric", "report_writers",
           "run_writers", "saved_map_folders", "spec_reference", "write_report"]

ERROR_MAPS_DIR = f"{FIGURES_DIR}/error_maps"
Log = Callable[[str], None]
_log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- the reference

def spec_reference(spec: AblationSpec, paper: str | Path | None = None) -> Reference | None:
    """The reference the spec's tables stand beside: its ``[report] reference`` ("none": no reference), else,
    when the spec asks for a paper table (``table`` other than "none"), names paper methods, or ``paper``
    (--paper) is given, the reference of the spec's network, else the default reference; None otherwise."""
    if spec.reference is not None:
        return None if spec.reference == "none" else get_reference(spec.reference)
    if spec.table == "none" and spec.paper_methods is None and paper is None:
        return None
    return reference_for_network(network_of(spec)) or default_reference()


def load_paper_tables(paper: str | Path | None, log: Log, reference: Reference | None = None) -> PaperTables | None:
    """The paper's tables (read as ``reference``'s, default the default reference), or None (with one line
    saying so) when no folder is given or found."""
    try:
        folder = find_paper_dir(paper)
    except DataError:
        log("the paper's tables were not found (--paper DIR or LFBENCH_PAPER_DIR): tables without paper columns")
        return None
    return load_paper(folder, reference)


# --------------------------------------------------------------------------- the cells

def ablation_metrics(results: Results) -> list[str]:
    """The metric ids the ablation's tables show: the ordered metrics of the protocol the results were scored
    by (results.json ``meta.protocol_metrics``, lfbench.scoring.protocol.Scoring.meta; results written before
    it was recorded: the protocol of the adapter ``meta.dataset`` names) that the results hold, else every
    general metric they hold (lfbench.scoring.metrics.metric_order)."""
    held = set(results.to_frame()["metric"]) if results.records else set()
    dataset = results.meta.get("dataset")
    recorded = results.meta.get("protocol_metrics")
    if isinstance(recorded, list) and all(isinstance(m, str) for m in recorded):
        declared = recorded
    elif dataset:
        from lfbench.data.dataset import DATASETS

        declared = DATASETS.get(str(dataset)).protocol.metrics
    else:
        declared = [m for m in held if (found := METRICS.find(m)) is not None and found.category == "general"]
    return [m for m in metric_order(declared) if m in held]


def primary_ablation_metric(results: Results) -> str | None:
    """The metric that picks the best cell (``--maps best``) and tests the orderings when no reference table
    declares one: the primary metric (lfbench.scoring.metrics.primary_metric) of :func:`ablation_metrics`,
    BadPix(0.07) on HCI; None when the results hold none."""
    return primary_metric(ablation_metrics(results))


def cell_frame(spec: AblationSpec, results: Results, markers: Sequence[dict[str, Any]],
               metrics: Sequence[str] | None = None) -> pd.DataFrame:
    """One row per cell (index: cell id): grid values (``grid:<axis>``), the mean of each of ``metrics``
    (default :func:`ablation_metrics`) over the evaluation scenes, scenes, and what was measured of it:
    train_s, own_train_s, test_s, time_size, time_angular ([V, U] views), device, threads."""
    df = results.to_frame()
    metrics = ablation_metrics(results) if metrics is None else metrics
    by_id = {m.get("id"): m for m in markers}
    rows = []
    for cell in spec.cells:
        m = by_id.get(cell.id, {})
        row: dict[str, Any] = {"cell": cell.id, **{f"grid:{k}": v for k, v in cell.values.items()}}
        sel = df[df["method"] == cell.id] if len(df) else df
        for metric in metrics:
            vals = sel[sel["metric"] == metric]["value"]
            row[metric] = float(vals.mean()) if len(vals) else np.nan
        row["scenes"] = int(sel["scene"].nunique()) if len(sel) else 0
        for key in ("train_s", "own_train_s", "test_s", "time_size", "time_angular", "device", "threads"):
            row[key] = m.get(key, np.nan)
        rows.append(row)
    return pd.DataFrame(rows).set_index("cell") if rows else pd.DataFrame()


def ours_label(spec: AblationSpec) -> str:
    return f"ours ({spec.budget_label()})"


def time_label(frame: pd.DataFrame) -> str:
    if frame.empty:
        return "ours"
    size = frame["time_size"].iloc[0]
    device, threads = frame["device"].iloc[0], frame["threads"].iloc[0]
    where = str(device)
    if device == "cpu" and pd.notna(threads):
        where += f", {int(threads)} thread{'s' if int(threads) != 1 else ''}"
    angular = frame["time_angular"].iloc[0] if "time_angular" in frame else None
    v, u = angular if isinstance(angular, list | tuple) and len(angular) == 2 else (9, 9)  # a marker before 0.x: 9x9
    return f"ours ({int(u)}x{int(v)}x{int(size)}x{int(size)}, {where})"


# --------------------------------------------------------------------------- the tables

def cells_table(spec: AblationSpec, frame: pd.DataFrame, metrics: Sequence[str]) -> pd.DataFrame:
    """table_cells: every cell's grid values, ``metrics`` (labelled by their Metric), train and test time."""
    if frame.empty:
        return frame
    grid_cols = [c for c in frame.columns if c.startswith("grid:")]
    out = frame[grid_cols].rename(columns=lambda c: c[5:]).copy()
    for metric in metrics:
        out[f"{get_metric(metric).label}, {ours_label(spec)}"] = frame[metric]
    out["train time (min)"] = frame["train_s"] / 60.0
    out[f"test time (s), {time_label(frame)}"] = frame["test_s"]
    out["scenes"] = frame["scenes"]
    return out


def table_file(table: PaperTable) -> str:
    """The file name (without suffix) of the ablation table beside the declared ``table``: its id when that
    starts with 'table' (table4), else table_<id> (table_beta)."""
    return table.id if table.id.startswith("table") else f"table_{table.id}"


def paper_frame(paper: PaperTables | None, table: PaperTable, log: Log) -> pd.DataFrame | None:
    """The paper's CSV of the declared ``table`` (checked for its key, metric and extra columns), or None:
    no file declared, no paper's numbers, or (with one line) the folder has no such file."""
    if paper is None or not table.file:
        return None
    name = Path(table.file).stem
    df = paper.extra.get(name)
    if df is None:
        log(f"the paper folder {paper.source} has no {name}.csv: no paper columns in that table")
        return None
    columns = [*table.keys, *(c for c in table.metrics.values() if c), *table.extra.values()]
    missing = [c for c in dict.fromkeys(columns) if c not in df.columns]
    if missing:
        raise DataError(f"missing column(s) {', '.join(missing)}", Path(paper.source) / f"{name}.csv")
    return df


def paper_key(config: dict[str, Any], table: PaperTable) -> tuple[str, ...] | None:
    """The key values of the paper's row a cell (its training config) stands beside: its value of each axis
    the table joins (renamed as ``names`` says), or None when a ``where`` value of the cell differs from the
    paper's (e.g. a loss at another parameter than the paper's row)."""
    for axis, value in table.where.items():
        ours = axis_value(config, axis)
        if ours is not None and not same_value(ours, value):
            return None
    keys = []
    for axis in table.join:
        value = axis_value(config, axis)
        if value is None:
            return None
        text = axis_text(config, axis) if axis != "loss" else str(value)
        keys.append(table.names.get(text, text))
    return tuple(keys)


def _paper_row(ref: pd.DataFrame, table: PaperTable, key: tuple[str, ...] | None) -> pd.Series | None:
    if key is None:
        return None
    hit = np.ones(len(ref), dtype=bool)
    for column, value in zip(table.join.values(), key, strict=True):
        hit &= np.array([same_value(v, value) for v in ref[column]], dtype=bool)
    return ref[hit].iloc[0] if hit.any() else None


def _measure(spec: AblationSpec, frame: pd.DataFrame, name: str, row: pd.Series) -> tuple[str, float]:
    """An ablation's measured column ``name`` (lfbench.reports.reference.MEASURES) of a cell-frame row:
    (header, value)."""
    if name == "train_time":
        return f"train time (min), {ours_label(spec)}", float(row["train_s"]) / 60.0
    if name == "stage_train_time":
        return f"last-stage train time (min), {ours_label(spec)}", float(row["own_train_s"]) / 60.0
    return f"test time (s), {time_label(frame)}", float(row["test_s"])


def reference_table(spec: AblationSpec, frame: pd.DataFrame, table: PaperTable, paper: PaperTables | None,
                    log: Log) -> pd.DataFrame:
    """Our cells beside the declared ``table`` (lfbench.reports.reference): the table's axes (headers from its
    ``labels``), the paper's row each cell joins ('paper row', when ``names`` or ``where`` make it differ
    from the cell's values), each declared metric (ours, then the paper's where it reports it; labels from
    :class:`~lfbench.scoring.base.Metric`), each declared measure (ours, then the paper's extra column of its
    name), the paper's other extra columns; rows sorted as ``order`` says."""
    ref = paper_frame(paper, table, log)
    label = paper.reference.label if paper is not None and paper.reference is not None else "paper"
    ours = ours_label(spec)
    configs = {c.id: c.config for c in spec.cells}
    rows = []
    for cid, r in frame.iterrows():
        config = configs[cid]
        key = paper_key(config, table)
        p = _paper_row(ref, table, key) if ref is not None else None
        row: dict[str, Any] = {"cell": cid}
        row |= {table.header(axis, axis): axis_text(config, axis) for axis in table.join}
        if table.names or table.where:
            row["paper row"] = " / ".join(key) if key else "-"
        for metric, column in table.metrics.items():
            name = get_metric(metric).label
            row[f"{name}, {ours}"] = r[metric] if metric in r.index else np.nan
            if ref is not None and column:
                row[f"{name}, {label}"] = _num(p, column)
        for measure in table.measures:
            header, value = _measure(spec, frame, measure, r)
            row[header] = value
            if ref is not None and measure in table.extra:
                row[table.header(measure, f"{measure}, {label}")] = _num(p, table.extra[measure])
        if ref is not None:
            for name, column in table.extra.items():
                if name not in table.measures:
                    row[table.header(name, f"{name}, {label}")] = _num(p, column)
        rows.append(row)
    out = pd.DataFrame(rows).set_index("cell")
    if table.order and len(out):
        axis = next(iter(table.join))
        values = pd.Series([axis_value(configs[c], axis) for c in out.index], index=out.index)
        out = out.loc[pd.to_numeric(values, errors="coerce").sort_values(
            ascending=table.order == "ascending", kind="stable").index]
    return out


def _num(row, key: str) -> float:
    if row is None:
        return np.nan
    value = pd.to_numeric(pd.Series([row[key]]), errors="coerce").iloc[0]
    return float(value)


# --------------------------------------------------------------------------- seeds and baselines

def seed_means(spec: AblationSpec, frame: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, str]]:
    """The cell frame averaged over seeds (one row per variant, indexed by its first seed's cell so the table
    builders find its config) and the map from that cell id to the variant id; unchanged without seeds."""
    if not spec.seeds or frame.empty:
        return frame, {}
    info = cell_info(spec).reindex(frame.index)
    numeric = frame.select_dtypes(include="number").columns
    rows, rename = [], {}
    for variant, group in info.groupby("variant", sort=False):
        first = group.index[0]
        row = frame.loc[first].copy()
        row[numeric] = frame.loc[group.index, numeric].mean()
        rows.append(row.rename(first))
        rename[first] = variant
    return pd.DataFrame(rows), rename


def baseline_verdicts(spec: AblationSpec, results: Results) -> tuple[pd.DataFrame, list[str], list[str]]:
    """table_baselines (every cell or variant against the spec's [[methods]], see lfbench.ablation.baselines),
    its caption and the summary lines (one per baseline); empty without cells or [[methods]]."""
    scores = results.to_frame()
    if not spec.cells or not spec.methods or scores.empty:
        return pd.DataFrame(), [], []
    labels = [m.label for m in spec.methods]
    metrics = verdict_metrics(ablation_metrics(results))  # the protocol's: the caption names them
    table = baselines_table(cell_info(spec), scores, labels, seeds=bool(spec.seeds), metrics=metrics)
    groups = list(dict.fromkeys(scene_groups(scores).values()))
    lines = summary_lines(table, labels, groups, metrics)
    what = "every cell against the baselines ([[methods]])" + (
        f", mean over seeds {', '.join(str(x) for x in spec.seeds)}" if spec.seeds else "")
    title, *ours = caption_lines(spec, what)  # the title, then (synthetic data: a line saying so) what ours is
    return table, [title, *lines, baselines_caption(metrics, seeds=bool(spec.seeds)), *ours], lines


# --------------------------------------------------------------------------- captions

def caption_lines(spec: AblationSpec, what: str | None = None) -> list[str]:
    """The first lines above a table: what it is and what 'ours' means (budget, scenes, times). A table with
    paper columns adds :func:`paper_line`; the others say nothing about the paper."""
    ev = spec.evaluation
    where = []
    if ev.synthetic is not None:
        where.append(f"{ev.synthetic.scenes} synthetic scenes ({ev.synthetic.size} px, seed {ev.synthetic.seed})")
    if ev.data is not None:
        where.append(f"{', '.join(ev.scenes) or 'all scenes'} of {ev.data}")
    scored = f"scored on {' and '.join(where)}"
    if spec.cells:
        ours = (f"ours: {spec.budget_label()}; {scored} (mean over scenes); train time = wall time of "
                "`lfbench train` (incl. the shared stage 1 when there is one); test time = one whole light field "
                f"of the evaluation scenes' angular size, {ev.time_size}x{ev.time_size} px")
    else:
        ours = f"ours: the methods listed, {scored}"
    synthetic = [SYNTHETIC_CAPTION] if ev.is_synthetic else []
    return [spec.title if what is None else f"{spec.title}: {what}", *synthetic, ours]


def paper_line(paper: PaperTables | None) -> str:
    """What the 'paper' columns of a table that can have them are, or that they are absent and why."""
    if paper is None:
        return "paper: not shown (the paper's tables were not found)"
    return paper.reference.ablation_note if paper.reference is not None else f"paper: {paper.source}"


def _with_summary(caption: list[str], summary: Sequence[str]) -> list[str]:
    """The caption with the baseline summary lines right under its title line."""
    return [*caption[:1], *summary, *caption[1:]]


# --------------------------------------------------------------------------- the writers

class AblationTables(OutputWriter):
    """table_cells, the reference's table the spec names (:func:`reference_table`), table_seeds and
    table_significance (seeds) and table_baselines ([[methods]]). ``paper``: the reference's numbers
    (None: no paper columns). After the write, ``sections`` holds the tables the site shows besides its
    leaderboard: the means over seeds with their intervals, the orderings and the verdicts."""

    def __init__(self, spec: AblationSpec, markers: Sequence[dict[str, Any]], paper: PaperTables | None,
                 reference: Reference | None, log: Log = _log.info) -> None:
        self.spec, self.markers, self.paper, self.reference, self.log = spec, markers, paper, reference, log
        self.sections: list[SiteSection] = []

    def write(self, run: RunOutputs) -> list[Path]:
        spec, results, out = self.spec, run.results, run.stage
        metrics = ablation_metrics(results)
        frame = cell_frame(spec, results, self.markers, metrics)
        if frame.empty:
            return []
        bar, bar_caption, bar_lines = baseline_verdicts(spec, results)
        for line in bar_lines:
            self.log(line)
        written = write_table(cells_table(spec, frame, metrics), out, "table_cells",
                              _with_summary(caption_lines(spec, "all cells"), bar_lines))
        means, rename = seed_means(spec, frame)
        seeds_note = ([f"ours: mean over seeds {', '.join(str(x) for x in spec.seeds)} (intervals and paired tests: "
                       "table_seeds, table_significance)"] if spec.seeds else [])
        table = spec_table(spec, self.reference)
        if table is not None:
            said = paper_line(self.paper) if table.file else table.caption
            caption = _with_summary([*caption_lines(spec), said, *seeds_note], bar_lines)
            written += write_table(reference_table(spec, means, table, self.paper, self.log).rename(index=rename),
                                   out, table_file(table), caption)
        if spec.seeds:
            written += self._seed_tables(results, out, metrics, table)
        if not bar.empty:
            written += write_table(bar, out, "table_baselines", bar_caption)
            self.sections.append(SiteSection("baselines", "Against the baselines", bar, bar_caption))
        written += self._scene_tables(run)
        return written

    def _scene_tables(self, run: RunOutputs) -> list[Path]:
        """The reference's per-scene tables of the dataset the cells were scored on (e.g. a paper's Table III
        on UrbanLF-Syn), as ``lfbench report`` writes them (lfbench.reports.paper_scenes)."""
        if self.paper is None:
            return []
        written = []
        for table in scene_tables(self.paper, run.results.meta):
            both = scene_table_with_paper(run.results, self.paper, table)
            if PARAMS_COLUMN in both.columns:  # each cell's network beside the paper's (e.g. Table III's M)
                for cell_id_, millions in cell_parameters(self.spec).items():
                    if cell_id_ in both.index:
                        both.loc[cell_id_, PARAMS_COLUMN] = millions
            if not both.empty:
                written += write_table(both, run.stage, f"table_{table.id}_paper",
                                       [*caption_lines(self.spec, f"{table.id} beside the paper's"), table.caption])
        return written

    def _seed_tables(self, results: Results, out: Path, metrics: Sequence[str], table: PaperTable | None) -> list[Path]:
        """table_seeds (mean and 95 % t-interval over seeds per variant, within each metric's range) and
        table_significance (the orderings the reference's table declares, as paired t-tests over seeds);
        see lfbench.ablation.significance."""
        spec = self.spec
        info, scores = cell_info(spec, tuple(table.join) if table is not None else ()), results.to_frame()
        seeds, clipped = seeds_table(info, scores, metrics)
        caption = caption_lines(spec, f"mean over seeds {', '.join(str(x) for x in spec.seeds)} and 95 % "
                                      "t-interval over seeds of the scene-mean score")
        if clipped:
            caption.append(f"intervals clipped to the metric's range ({'; '.join(clipped)}): with few seeds the "
                           "t-interval can reach past it")
        written = write_table(seeds, out, "table_seeds", caption)
        self.sections.append(SiteSection("seeds", "Mean over seeds", seeds, caption))
        ordering = ordering_metric(table, primary_metric(metrics) or ORDERING_METRIC)
        sig = significance_table(table, info, scores, ordering)
        if not sig.empty:
            metric = get_metric(ordering)
            caption = caption_lines(spec, f"the paper's orderings, paired t-test over seeds ({metric.label}, "
                                          f"{metric.direction}; two-sided, alpha {ALPHA:g})")
            sig = sig.set_index("claim (paper)")
            written += write_table(sig, out, "table_significance", caption)
            self.sections.append(SiteSection("significance", "The paper's orderings", sig, caption))
        return written


#: A paper table's extra column (its declared name) that our cells fill with their network's parameter count (M).
PARAMS_COLUMN = "params_millions"


def cell_parameters(spec: AblationSpec) -> dict[str, float]:
    """Each cell's trainable-parameter count in millions: its network (the config's ``method``) built with its
    [model] on PyTorch's meta device (lfbench.method.trainable.network_summary; nothing allocated)."""
    from lfbench.ablation.spec import trainable_of
    from lfbench.method.trainable import network_summary

    return {cell.id: network_summary(trainable_of(cell.config), dict(cell.config["model"]))["trainable"] / 1e6
            for cell in spec.cells}


def spec_table(spec: AblationSpec, reference: Reference | None) -> PaperTable | None:
    """The declared ablation table the spec's ``table`` names in its reference (None: none, tables12, no
    reference, or a dataset's per-scene table such as table3, which the cells stand beside as
    ``table_<id>_paper`` when they are scored on that dataset: AblationTables._scene_tables)."""
    if reference is None or spec.table in NO_TABLE:
        return None
    table = reference.table(spec.table)
    if table is None:
        raise SpecError(f"table: reference {reference.name!r} declares no table {spec.table!r}", spec.source)
    return None if table.dataset else table


class AblationFigures(OutputWriter):
    """The figure the spec's reference table declares (``figure``): ``<axis>_curve.png`` (``curve``: its first
    metric against its axis) or ``accuracy_vs_test_time.png`` (``time``: against test time, with the paper's
    points beside ours when its numbers are there)."""

    def __init__(self, spec: AblationSpec, markers: Sequence[dict[str, Any]], paper: PaperTables | None,
                 reference: Reference | None) -> None:
        self.spec, self.markers, self.paper, self.reference = spec, markers, paper, reference

    def write(self, run: RunOutputs) -> list[Path]:
        spec, fig_dir = self.spec, run.stage / FIGURES_DIR
        table = spec_table(spec, self.reference)
        if table is None or not table.figure or not table.metrics:
            return []
        metric = next(iter(table.metrics))
        frame = cell_frame(spec, run.results, self.markers, [metric])
        if frame.empty:
            return []
        configs = {c.id: c.config for c in spec.cells}
        axes = list(table.join)
        values = {axis: [axis_value(configs[c], axis) for c in frame.index] for axis in axes}
        if table.figure == "curve":
            xs = pd.to_numeric(pd.Series(values[axes[0]], index=frame.index), errors="coerce")
            if not xs.notna().any():
                return []
            return [plots.metric_curve(frame[metric], xs, run.results.to_frame(), metric,
                                       fig_dir / f"{axes[0]}_curve.png", ours_label(spec), axes[0],
                                       table.labels.get("figure_title"), descending=table.order == "descending")]
        ref = paper_frame(self.paper, table, lambda _: None)
        theirs = None
        if ref is not None and "test_time" in table.extra and table.metrics[metric]:
            theirs = plots.Points(pd.to_numeric(ref[table.extra["test_time"]], errors="coerce").tolist(),
                                  pd.to_numeric(ref[table.metrics[metric]], errors="coerce").tolist(),
                                  *_point_labels(ref, list(table.join.values())),
                                  title=table.labels.get("figure_title", self.paper.reference.label),
                                  xlabel=table.header("test_time", "test time (s), paper"))
        ours = plots.Points(frame["test_s"].astype(float).tolist(), frame[metric].astype(float).tolist(),
                            *_point_labels(pd.DataFrame(values), axes), title=ours_label(spec),
                            xlabel=f"test time (s), {time_label(frame)}")
        return [plots.accuracy_vs_time(ours, theirs, metric, fig_dir / "accuracy_vs_test_time.png",
                                       " / ".join(table.header(a, a) for a in axes[:1]),
                                       axes[1] if len(axes) > 1 else "")]


def _point_labels(frame: pd.DataFrame, columns: Sequence[str]) -> tuple[list[str], list[str]]:
    """(annotation, group) of each point: the first column's value (a number as :g) and the second's."""
    def text(v: Any) -> str:
        number = pd.to_numeric(pd.Series([v]), errors="coerce").iloc[0]
        return f"{number:g}" if pd.notna(number) else str(v).strip()

    first = [text(v) for v in frame[columns[0]]]
    second = [text(v) for v in frame[columns[1]]] if len(columns) > 1 else [""] * len(frame)
    return first, second


class AblationSite(Site):
    """The ablation's site: the leaderboard of the cells and extra methods, their maps, and the tables of
    :class:`AblationTables` (means over seeds with intervals, orderings, verdicts against each baseline)."""

    def __init__(self, spec: AblationSpec, tables: AblationTables, folder: Path, maps: str = "all",
                 best_by: str | None = ORDERING_METRIC) -> None:
        notes = [f"Ablation {spec.source}: budget {spec.budget_label()}; one method per cell (its id) and per extra "
                 f"method. Training curves: tensorboard --logdir {folder / 'cells'}."]
        if maps != "all":  # best_by: the metric that picked the best cell (best_cell), None when there is none
            best = (f"the best cell's ({describe_metric(best_by).name})" if best_by is not None
                    else "no cell's (no scores)")
            notes.append(f"Maps drawn with --maps {maps}: "
                         + ("none." if maps == "none" else f"{best} and the extra methods'.")
                         + " (lfbench ablate SPEC --report-only --html --maps all draws every cell's.)")
        super().__init__(title=spec.title, notes=notes)
        self.tables = tables

    def inputs(self, run: RunOutputs) -> SiteInputs:
        for path in run.maps.values():
            if (path / "disp_maps").is_dir():
                check_within(path, run.folder, "the ablation folder")
        self.maps, self.sections = run.maps, self.tables.sections
        return super().inputs(run)


def saved_map_folders(spec: AblationSpec, folder: Path) -> dict[str, Path]:
    """Where each cell and extra method of the ablation in ``folder`` saved its maps: label -> submission folder."""
    maps = {cell.id: folder / "cells" / cell.id / "maps" for cell in spec.cells}
    return maps | {m.label: folder / "methods" / file_name(m.label) / "maps" for m in spec.methods}


#: What ``lfbench ablate --maps`` draws from the saved maps (error-map figures, the site's maps): every cell's,
#: only the best cell's (and the extra methods'), or none. The cells save their maps in every case (a PFM per
#: scene, cheap beside drawing), so ``--report-only --maps all`` draws them later.
MAP_CHOICES = ("all", "best", "none")


def check_maps(maps: str) -> None:
    """SpecError unless ``maps`` is one of :data:`MAP_CHOICES`."""
    if maps not in MAP_CHOICES:
        raise SpecError(f"--maps must be one of {', '.join(MAP_CHOICES)}, got {maps!r}")


def best_cell(spec: AblationSpec, results: Results, metric: str | None = None) -> str | None:
    """The cell with the best mean of ``metric`` (default: the primary metric of the results' protocol,
    :func:`primary_ablation_metric`) over its scenes (the first in the spec's order on a tie), or None when no cell
    has a finite value of it."""
    metric = metric or primary_ablation_metric(results)
    if metric is None:
        return None
    frame = results.to_frame()
    frame = frame[(frame["metric"] == metric) & frame["method"].isin([c.id for c in spec.cells])]
    means = frame.groupby("method", sort=False)["value"].mean().dropna()
    if means.empty:
        return None
    order = {c.id: i for i, c in enumerate(spec.cells)}
    badness = get_metric(metric).badness
    return min(means.index, key=lambda m: (badness(means[m]), order[m]))


def drawn_map_folders(spec: AblationSpec, results: Results, folder: Path, maps: str = "all") -> dict[str, Path]:
    """The saved maps the report draws (label -> submission folder), as ``maps`` (:data:`MAP_CHOICES`) says:
    ``all`` of them, the ``best`` cell's (:func:`best_cell`) and the extra methods', or ``none``."""
    check_maps(maps)
    saved = saved_map_folders(spec, folder)
    if maps == "all":
        return saved
    if maps == "none":
        return {}
    keep = {best_cell(spec, results), *(m.label for m in spec.methods)}
    return {label: path for label, path in saved.items() if label in keep}


def report_writers(spec: AblationSpec, markers: Sequence[dict[str, Any]], results: Results, *,
                   paper: str | Path | None = None, folder: Path, html: bool = False,
                   log: Log = _log.info, maps: str = "all") -> list[OutputWriter]:
    """The writers of an ablation's tables and figures (and, with ``html``, its site), in order. ``paper``:
    the paper's tables folder (--paper; None: found as lfbench.reports.paper.find_paper_dir says) when
    the spec has a reference (:func:`spec_reference`); ``folder``: the ablation's folder; ``maps``: whose
    saved maps are drawn (:data:`MAP_CHOICES`; ``none``: no error-map figures at all)."""
    reference = spec_reference(spec, paper)
    tables = load_paper_tables(paper, log, reference) if reference is not None else None
    ablation = AblationTables(spec, markers, tables, reference, log)
    writers: list[OutputWriter] = [ablation, _tables_i_ii(spec, results, tables),
                                   AblationFigures(spec, markers, tables, reference)]
    if spec.evaluation.error_maps and maps != "none":
        writers.append(SceneFigures(ERROR_MAPS_DIR, files=True))
    if html:
        writers.append(AblationSite(spec, ablation, folder, maps, primary_ablation_metric(results)))
    return writers


def _tables_i_ii(spec: AblationSpec, results: Results, paper: PaperTables | None) -> Tables:
    """Tables I/II of every cell and method, with the paper's beside them when it reports an evaluation scene.
    Only the tables beside a paper are called its "Tables I/II" (a spec with ``table = "none"`` and no
    paper's numbers names no paper's tables)."""
    caption = caption_lines(spec, "every cell and method, per scene (table_per_scene) and averaged over the scenes "
                                  "(table_average)")
    covered = paper is not None and any(s in paper.scenes for s in results.scenes)
    if not covered:
        return Tables(caption=caption)
    note = [paper.reference.benchmark_note] if paper.reference is not None else []
    return Tables(caption=caption, paper=paper, paper_methods=spec.paper_methods or (),
                  paper_caption=[*caption_lines(spec, "Tables I/II beside the paper's"), *note])


def write_report(spec: AblationSpec, out: str | Path, results: Results, markers: Sequence[dict[str, Any]], *,
                 paper: str | Path | None = None, log: Log = _log.info, folder: str | Path | None = None,
                 maps: str = "all") -> list[Path]:
    """Every table and figure of the run straight into ``out`` (:func:`report_writers` without the site);
    returns the files written. ``folder``: the ablation's folder, whose cells' and methods' saved maps the
    error maps are drawn from (default ``out``); ``maps``: whose (:data:`MAP_CHOICES`)."""
    out = Path(out)
    folder = Path(folder) if folder is not None else out
    writers = report_writers(spec, markers, results, paper=paper, folder=folder, log=log, maps=maps)
    return run_writers(writers, spec, results, out, folder, maps=maps)


def run_writers(writers: Sequence[OutputWriter], spec: AblationSpec, results: Results, stage: Path, folder: Path,
                scenes: Sequence[Any] = (), *, maps: str = "all") -> list[Path]:
    """Run the ablation's ``writers`` into ``stage``: the saved maps of its cells and methods under
    ``folder`` (those ``maps`` selects, :func:`drawn_map_folders`) are handed to them as predictions (the
    error maps), on the evaluation scenes the results record; ``scenes``: the evaluation scenes, for the site.
    The figures draw at the border the results were scored with (``meta.scoring``)."""
    run = RunOutputs(stage=stage, rules=ScoringRules.from_meta(results.meta), results=results, scenes=scenes,
                     source=folder, maps=drawn_map_folders(spec, results, folder, maps))
    saved = ()
    if spec.evaluation.error_maps:
        recorded = load_scenes(tuple((d, None) for d in results.meta.get("scenes", [])), spec.evaluation)
        saved = saved_predictions(recorded, run.maps, within=folder)
    return drive_writers(writers, run, predictions=saved)
