"""Tables and figures of an ablation run, with a reference's numbers (the paper of the spec's network,
lfbench.reports.reference) in adjacent, labelled columns: the ablation's output writers
(lfbench.reports.writers), which ``lfbench ablate`` runs into its staged set.

Written into OUT (each table as .md, .tex and .csv):

- ``table_cells``: one row per cell: its grid values, mean BadPix 0.07/0.03/0.01 and MSE x100 over the
  evaluation scenes, train time and test time;
- ``table4`` (spec table = "table4"): interval, interpolation, BadPix 0.07, MSE x100, train time, test
  time, ours beside the reference's Table IV;
- ``table5`` ("table5"): BadPix 0.07 per fine-tuning loss, ours beside the reference's Table V;
- ``table_beta`` ("beta"): BadPix 0.07 and MSE x100 per loss beta (what the reference says about it);
- ``table_seeds`` / ``table_significance`` (the spec has seeds): mean and 95 % t-interval over seeds per
  variant (clipped to each metric's range), and the reference's orderings as paired t-tests;
- ``table_baselines`` (the spec has [[methods]]): every cell (with seeds: variant) against each extra
  method, e.g. the plane sweep and the zero map, per scene group in BadPix 0.07 and MSE x100, with a
  verdict per baseline (lfbench.ablation.baselines); its summary lines ("every cell beats ..." or "K of N
  cells do not beat ...") are logged and head the captions of table_cells, this table and the paper-style
  table;
- ``table_per_scene`` / ``table_average`` (Tables I/II) for every cell and extra method, and, with a
  reference whose Tables I/II cover some evaluation scene, ``table_per_scene_paper`` / ``table_average_paper``;
- figures/: ``beta_curve.png`` (BadPix 0.07 against beta), ``accuracy_vs_test_time.png`` (BadPix 0.07
  against test time, per interval and interpolation, ours and the reference's), and ``error_maps/``
  (per scene: one row per variant with disparity, BadPix map, signed error and uncertainty; the
  BadPix(t) curves), drawn from the maps the cells saved;
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
from lfbench.ablation.baselines import baselines_caption, baselines_table, scene_groups, summary_lines
from lfbench.ablation.facts import cell_info, last_stage_loss, loss_beta, model_value, network_of
from lfbench.ablation.significance import ALPHA, seeds_table, significance_table
from lfbench.ablation.spec import AblationSpec
from lfbench.data.hci import HCIScene
from lfbench.reports.html import SiteInputs, SiteSection
from lfbench.reports.maps import saved_predictions
from lfbench.reports.paper import PaperTables, find_paper_dir, load_paper
from lfbench.reports.reference import Reference, default_reference, get_reference, reference_for_network
from lfbench.reports.tables import write_table
from lfbench.reports.writers import (
    FIGURES_DIR,
    OutputWriter,
    RunOutputs,
    SceneFigures,
    Site,
    Tables,
    replay,
    write_outputs,
)
from lfbench.results import Results
from lfbench.scoring.metrics import get_metric
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.names import file_name
from lfbench.utils.outputs import check_within

__all__ = ["MAP_CHOICES", "AblationFigures", "AblationSite", "AblationTables", "best_cell", "cell_frame", "check_maps",
           "drawn_map_folders", "load_paper_tables", "report_writers",
           "run_writers", "saved_map_folders", "spec_reference", "write_report"]

METRICS = ("badpix_0.07", "badpix_0.03", "badpix_0.01", "mse_x100")
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

def cell_frame(spec: AblationSpec, results: Results, markers: Sequence[dict[str, Any]]) -> pd.DataFrame:
    """One row per cell (index: cell id): grid values, interval, interpolation, loss, beta, mean metrics
    over the evaluation scenes, train_s, own_train_s, test_s, time_size, scenes."""
    df = results.to_frame()
    by_id = {m.get("id"): m for m in markers}
    rows = []
    for cell in spec.cells:
        m = by_id.get(cell.id, {})
        loss, params = last_stage_loss(cell.config)
        row: dict[str, Any] = {"cell": cell.id, **{f"grid:{k}": v for k, v in cell.values.items()},
                               "interval": model_value(cell.config, "interval", float, np.nan),
                               "interpolation": model_value(cell.config, "interpolation", str, ""),
                               "loss": loss + ("" if not params else "(" + ", ".join(f"{k}={v}" for k, v in
                                                                                       params.items()) + ")"),
                               "beta": loss_beta(cell.config)}
        sel = df[df["method"] == cell.id]
        for metric in METRICS:
            vals = sel[sel["metric"] == metric]["value"]
            row[metric] = float(vals.mean()) if len(vals) else np.nan
        row["scenes"] = int(sel["scene"].nunique())
        for key in ("train_s", "own_train_s", "test_s", "time_size", "device", "threads"):
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
    return f"ours (9x9x{int(size)}x{int(size)}, {where})"


# --------------------------------------------------------------------------- the tables

def cells_table(spec: AblationSpec, frame: pd.DataFrame) -> pd.DataFrame:
    if frame.empty:
        return frame
    grid_cols = [c for c in frame.columns if c.startswith("grid:")]
    out = frame[grid_cols].rename(columns=lambda c: c[5:]).copy()
    for metric in METRICS:
        out[f"{get_metric(metric).label}, {ours_label(spec)}"] = frame[metric]
    out["train time (min)"] = frame["train_s"] / 60.0
    out[f"test time (s), {time_label(frame)}"] = frame["test_s"]
    out["scenes"] = frame["scenes"]
    return out


def _paper_extra(paper: PaperTables | None, file: str, columns: Sequence[str], log: Log) -> pd.DataFrame | None:
    """The paper's table in ``file`` of its folder (checked for ``columns``), or None (with one line) when
    the folder has no such file."""
    if paper is None:
        return None
    name = Path(file).stem
    df = paper.extra.get(name)
    if df is None:
        log(f"the paper folder {paper.source} has no {name}.csv: no paper columns in that table")
        return None
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise DataError(f"missing column(s) {', '.join(missing)}", Path(paper.source) / f"{name}.csv")
    return df


def _layout(paper: PaperTables | None, table: str) -> Any:
    """The reference's layout of ``table`` (its Table4 / Table5 / BetaSweep), None without one."""
    reference = paper.reference if paper is not None else None
    return getattr(reference, table, None) if reference is not None else None


def table4(spec: AblationSpec, frame: pd.DataFrame, paper: PaperTables | None, log: Log) -> pd.DataFrame:
    """Table IV: interval, interpolation, BadPix 0.07, MSE x100, train time, test time (ours | paper)."""
    ours, test = ours_label(spec), time_label(frame)
    layout = _layout(paper, "table4")
    ref = None if layout is None else _paper_extra(paper, layout.file, (
        "interval", "interpolation", "badpix_0.07", "mse_x100", layout.train_hours, layout.test_seconds), log)
    label = paper.reference.label if ref is not None else ""
    rows = []
    for cid, r in frame.iterrows():
        p = None
        if ref is not None:
            hit = ref[(np.isclose(pd.to_numeric(ref["interval"], errors="coerce"), r["interval"], rtol=0, atol=1e-9))
                      & (ref["interpolation"].astype(str).str.strip() == r["interpolation"])]
            p = hit.iloc[0] if len(hit) else None
        row = {"cell": cid, "interval (px)": f"{r['interval']:g}", "interpolation": r["interpolation"],
               f"BadPix 0.07 (%), {ours}": r["badpix_0.07"]}
        if ref is not None:
            row[f"BadPix 0.07 (%), {label}"] = _num(p, "badpix_0.07")
        row[f"MSE x100, {ours}"] = r["mse_x100"]
        if ref is not None:
            row[f"MSE x100, {label}"] = _num(p, "mse_x100")
        row[f"train time (min), {ours}"] = float(r["train_s"]) / 60.0
        if ref is not None:
            row[f"train time (h), {label}"] = _num(p, layout.train_hours)
        row[f"test time (s), {test}"] = float(r["test_s"])
        if ref is not None:
            row[f"test time (s), {layout.test_label}"] = _num(p, layout.test_seconds)
        rows.append(row)
    return pd.DataFrame(rows).set_index("cell")


def paper_loss_name(config: dict[str, Any], reference: Reference | None = None) -> str | None:
    """The reference's (default: the default reference's) Table V row of a cell's last-stage loss: its best
    loss only at its beta, other losses without parameters by their name (or the name it gives them)."""
    reference = reference or default_reference()
    if reference is None or reference.table5 is None:
        return None
    loss, params = last_stage_loss(config)
    if loss == reference.table5.best_loss:
        beta, best = loss_beta(config), reference.beta.best if reference.beta is not None else None
        return loss if beta is None or best is None or abs(beta - best) < 1e-12 else None
    return reference.table5.loss_names.get(loss, loss) if not params else None


def table5(spec: AblationSpec, frame: pd.DataFrame, paper: PaperTables | None, log: Log) -> pd.DataFrame:
    """Table V: BadPix 0.07 per fine-tuning loss (ours | paper), and our MSE x100."""
    ours = ours_label(spec)
    layout = _layout(paper, "table5")
    ref = None if layout is None else _paper_extra(paper, layout.file, ("loss", "badpix_0.07"), log)
    reference = paper.reference if paper is not None else None
    configs = {c.id: c.config for c in spec.cells}
    rows = []
    for cid, r in frame.iterrows():
        name = paper_loss_name(configs[cid], reference)
        row = {"cell": cid, "loss (stage 2)": r["loss"], "paper row": name or "-",
               f"BadPix 0.07 (%), {ours}": r["badpix_0.07"]}
        if ref is not None:
            hit = ref[ref["loss"].astype(str).str.strip() == name] if name else ref.iloc[0:0]
            row[f"BadPix 0.07 (%), {reference.label}"] = float(hit["badpix_0.07"].iloc[0]) if len(hit) else np.nan
        row[f"MSE x100, {ours}"] = r["mse_x100"]
        row["stage-2 train time (min)"] = r["own_train_s"] / 60.0
        rows.append(row)
    return pd.DataFrame(rows).set_index("cell")


def table_beta(spec: AblationSpec, frame: pd.DataFrame) -> pd.DataFrame:
    ours = ours_label(spec)
    out = pd.DataFrame({"beta": frame["beta"], f"BadPix 0.07 (%), {ours}": frame["badpix_0.07"],
                        f"MSE x100, {ours}": frame["mse_x100"]}, index=frame.index)
    return out.sort_values("beta", ascending=False, kind="stable")


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
    table = baselines_table(cell_info(spec), scores, labels, seeds=bool(spec.seeds))
    groups = list(dict.fromkeys(scene_groups(scores).values()))
    lines = summary_lines(table, labels, groups)
    what = "every cell against the baselines ([[methods]])" + (
        f", mean over seeds {', '.join(str(x) for x in spec.seeds)}" if spec.seeds else "")
    title, ours = caption_lines(spec, what)
    return table, [title, *lines, baselines_caption(seeds=bool(spec.seeds)), ours], lines


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
                "`lfbench train` (incl. the shared stage 1 when there is one); test time = one whole "
                f"9x9x{ev.time_size}x{ev.time_size} light field")
    else:
        ours = f"ours: the methods listed, {scored}"
    return [spec.title if what is None else f"{spec.title}: {what}", ours]


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
    """table_cells, the reference's table of the spec (table4, table5, table_beta), table_seeds and
    table_significance (seeds) and table_baselines ([[methods]]). ``paper``: the reference's numbers
    (None: no paper columns). After the write, ``sections`` holds the tables the site shows besides its
    leaderboard: the means over seeds with their intervals, the orderings and the verdicts."""

    def __init__(self, spec: AblationSpec, markers: Sequence[dict[str, Any]], paper: PaperTables | None,
                 reference: Reference | None, log: Log = _log.info) -> None:
        self.spec, self.markers, self.paper, self.reference, self.log = spec, markers, paper, reference, log
        self.sections: list[SiteSection] = []

    def write(self, run: RunOutputs) -> list[Path]:
        spec, results, out = self.spec, run.results, run.stage
        frame = cell_frame(spec, results, self.markers)
        if frame.empty:
            return []
        bar, bar_caption, bar_lines = baseline_verdicts(spec, results)
        for line in bar_lines:
            self.log(line)
        written = write_table(cells_table(spec, frame), out, "table_cells",
                              _with_summary(caption_lines(spec, "all cells"), bar_lines))
        means, rename = seed_means(spec, frame)
        seeds_note = ([f"ours: mean over seeds {', '.join(str(x) for x in spec.seeds)} (intervals and paired tests: "
                       "table_seeds, table_significance)"] if spec.seeds else [])
        with_paper = _with_summary([*caption_lines(spec), paper_line(self.paper), *seeds_note], bar_lines)
        if spec.table == "table4":
            written += write_table(table4(spec, means, self.paper, self.log).rename(index=rename), out, "table4",
                                   with_paper)
        elif spec.table == "table5":
            written += write_table(table5(spec, means, self.paper, self.log).rename(index=rename), out, "table5",
                                   with_paper)
        elif spec.table == "beta":
            said = [self.reference.beta.note] if self.reference is not None and self.reference.beta else []
            caption = _with_summary([*caption_lines(spec), *seeds_note, *said], bar_lines)
            written += write_table(table_beta(spec, means).rename(index=rename), out, "table_beta", caption)
        if spec.seeds:
            written += self._seed_tables(results, out)
        if not bar.empty:
            written += write_table(bar, out, "table_baselines", bar_caption)
            self.sections.append(SiteSection("baselines", "Against the baselines", bar, bar_caption))
        return written

    def _seed_tables(self, results: Results, out: Path) -> list[Path]:
        """table_seeds (mean and 95 % t-interval over seeds per variant, within each metric's range) and
        table_significance (the reference's orderings as paired t-tests over seeds);
        see lfbench.ablation.significance."""
        spec = self.spec
        info, scores = cell_info(spec), results.to_frame()
        seeds, clipped = seeds_table(info, scores, METRICS)
        caption = caption_lines(spec, f"mean over seeds {', '.join(str(x) for x in spec.seeds)} and 95 % "
                                      "t-interval over seeds of the scene-mean score")
        if clipped:
            caption.append(f"intervals clipped to the metric's range ({'; '.join(clipped)}): with few seeds the "
                           "t-interval can reach past it")
        written = write_table(seeds, out, "table_seeds", caption)
        self.sections.append(SiteSection("seeds", "Mean over seeds", seeds, caption))
        sig = significance_table(spec.table, info, scores, reference=self.reference)
        if not sig.empty:
            caption = caption_lines(spec, "the paper's orderings, paired t-test over seeds (BadPix 0.07, lower "
                                          f"is better; two-sided, alpha {ALPHA:g})")
            sig = sig.set_index("claim (paper)")
            written += write_table(sig, out, "table_significance", caption)
            self.sections.append(SiteSection("significance", "The paper's orderings", sig, caption))
        return written


class AblationFigures(OutputWriter):
    """figures/beta_curve.png (spec table "beta") and figures/accuracy_vs_test_time.png ("table4", with
    the reference's Table IV beside ours when its numbers are there)."""

    def __init__(self, spec: AblationSpec, markers: Sequence[dict[str, Any]], paper: PaperTables | None,
                 reference: Reference | None) -> None:
        self.spec, self.markers, self.paper, self.reference = spec, markers, paper, reference

    def write(self, run: RunOutputs) -> list[Path]:
        spec, fig_dir = self.spec, run.stage / FIGURES_DIR
        frame = cell_frame(spec, run.results, self.markers)
        written = []
        if not frame.empty and spec.table == "beta" and frame["beta"].notna().any():
            said = self.reference.beta.curve_note if self.reference is not None and self.reference.beta else None
            written.append(plots.beta_curve(frame, run.results.to_frame(), fig_dir / "beta_curve.png",
                                            ours_label(spec), said))
        if not frame.empty and spec.table == "table4":
            layout = _layout(self.paper, "table4")
            ref = None if layout is None else _paper_extra(self.paper, layout.file, (
                "interval", "interpolation", "badpix_0.07", layout.test_seconds), lambda _: None)
            written.append(plots.accuracy_vs_time(frame, ref, fig_dir / "accuracy_vs_test_time.png", ours_label(spec),
                                                  time_label(frame), layout))
        return written


class AblationSite(Site):
    """The ablation's site: the leaderboard of the cells and extra methods, their maps, and the tables of
    :class:`AblationTables` (means over seeds with intervals, orderings, verdicts against each baseline)."""

    def __init__(self, spec: AblationSpec, tables: AblationTables, folder: Path, maps: str = "all") -> None:
        notes = [f"Ablation {spec.source}: budget {spec.budget_label()}; one method per cell (its id) and per extra "
                 f"method. Training curves: tensorboard --logdir {folder / 'cells'}."]
        if maps != "all":
            notes.append(f"Maps drawn with --maps {maps}: "
                         + ("none." if maps == "none" else "the best cell's (BadPix(0.07)) and the extra methods'.")
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


def best_cell(spec: AblationSpec, results: Results, metric: str = "badpix_0.07") -> str | None:
    """The cell with the best mean of ``metric`` over its scenes (the first in the spec's order on a tie), or
    None when no cell has a finite value of it."""
    frame = results.to_frame()
    frame = frame[(frame["metric"] == metric) & frame["method"].isin([c.id for c in spec.cells])]
    means = frame.groupby("method", sort=False)["value"].mean().dropna()
    if means.empty:
        return None
    order = {c.id: i for i, c in enumerate(spec.cells)}
    sign = -1.0 if get_metric(metric).higher_is_better else 1.0
    return min(means.index, key=lambda m: (sign * float(means[m]), order[m]))


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
        writers.append(AblationSite(spec, ablation, folder, maps))
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
    error maps), on the evaluation scenes the results record; ``scenes``: the evaluation scenes, for the site."""
    run = RunOutputs(stage=stage, results=results, scenes=scenes, source=folder,
                     maps=drawn_map_folders(spec, results, folder, maps))
    for writer in writers:
        writer.start(run)
    if spec.evaluation.error_maps:
        recorded = [HCIScene(d) for d in results.meta.get("scenes", [])]
        replay(writers, saved_predictions(recorded, run.maps, within=folder))
    return write_outputs(writers, run)
