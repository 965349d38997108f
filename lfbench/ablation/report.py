"""Tables and figures of an ablation run, with the paper's numbers in adjacent, labelled columns.

Written into OUT (each table as .md, .tex and .csv):

- ``table_cells``: one row per cell: its grid values, mean BadPix 0.07/0.03/0.01 and MSE x100 over the
  evaluation scenes, train time and test time;
- ``table4`` (spec table = "table4"): interval, interpolation, BadPix 0.07, MSE x100, train time, test
  time, ours beside the paper's Table IV;
- ``table5`` ("table5"): BadPix 0.07 per fine-tuning loss, ours beside the paper's Table V;
- ``table_beta`` ("beta"): BadPix 0.07 and MSE x100 per UAFL beta (the paper prints no values);
- ``table_baselines`` (the spec has [[methods]]): every cell (with seeds: variant) against each extra
  method, e.g. the plane sweep and the zero map, per scene group in BadPix 0.07 and MSE x100, with a
  verdict per baseline (lfbench.ablation.baselines); its summary lines ("every cell beats ..." or "K of N
  cells do not beat ...") are logged and head the captions of table_cells, this table and the paper-style
  table;
- ``table_per_scene`` / ``table_average`` (Tables I/II) for every cell and extra method, and, when the
  evaluation includes scenes the paper reports, ``table_per_scene_paper`` / ``table_average_paper``;
- figures/: ``beta_curve.png`` (BadPix 0.07 against beta), ``accuracy_vs_test_time.png`` (BadPix 0.07
  against test time, per interval and interpolation, ours and the paper's), and ``error_maps/``
  (per scene: one row per variant with disparity, BadPix map, signed error and uncertainty; the
  BadPix(t) curves), drawn with lfbench.reports.figures.

"ours" columns are labelled with the budget (width, batch, patch, steps, device) and the test-time
input size; "paper" columns with "RTX 3090, full training". Without the paper's tables there are no
paper columns, and one line says so.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lfbench.ablation.spec import AblationSpec
from lfbench.reports.tables import write_table
from lfbench.runs.results import Results
from lfbench.scoring.metrics import get_metric
from lfbench.utils.errors import DataError

PAPER_LABEL = "paper (RTX 3090, full training)"
TABLE4_FILE, TABLE5_FILE = "table4_interval_interp", "table5_losses"
PAPER_LOSS_NAMES = {"l1": "baseline_l1"}  # our loss name -> the paper's Table V row
PAPER_UAFL_BETA = 0.1
METRICS = ("badpix_0.07", "badpix_0.03", "badpix_0.01", "mse_x100")
Log = Callable[[str], None]
_log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- facts per cell

def last_stage_loss(config: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """(loss name, loss parameters) of a cell's last training stage."""
    from lfbench.training.config import STAGE_KEYS

    st = config["stages"][-1]
    return st["loss"], {k: v for k, v in st.items() if k not in STAGE_KEYS}


def uafl_beta(config: dict[str, Any]) -> float | None:
    loss, params = last_stage_loss(config)
    return float(params.get("beta", PAPER_UAFL_BETA)) if loss == "uafl" else None


def _model_value(config: dict[str, Any], key: str, kind: type, missing: Any) -> Any:
    """[model] ``key`` of a cell's config, else the network's default; ``missing`` if it has no such parameter."""
    from lfbench.ablation.spec import network_default

    value = config["model"].get(key, network_default(config, key))
    return missing if value is None else kind(value)


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
                               "interval": _model_value(cell.config, "interval", float, np.nan),
                               "interpolation": _model_value(cell.config, "interpolation", str, ""),
                               "loss": loss + ("" if not params else "(" + ", ".join(f"{k}={v}" for k, v in
                                                                                       params.items()) + ")"),
                               "beta": uafl_beta(cell.config)}
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


def _paper_extra(paper, name: str, columns: Sequence[str], log: Log) -> pd.DataFrame | None:
    if paper is None:
        return None
    df = paper.extra.get(name)
    if df is None:
        log(f"the paper folder {paper.source} has no {name}.csv: no paper columns in that table")
        return None
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise DataError(f"missing column(s) {', '.join(missing)}", Path(paper.source) / f"{name}.csv")
    return df


def table4(spec: AblationSpec, frame: pd.DataFrame, paper, log: Log) -> pd.DataFrame:
    """Table IV: interval, interpolation, BadPix 0.07, MSE x100, train time, test time (ours | paper)."""
    ours, test = ours_label(spec), time_label(frame)
    ref = _paper_extra(paper, TABLE4_FILE, ("interval", "interpolation", "badpix_0.07", "mse_x100",
                                            "train_hours_rtx3090", "test_seconds_512x512_rtx3090"), log)
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
            row[f"BadPix 0.07 (%), {PAPER_LABEL}"] = _num(p, "badpix_0.07")
        row[f"MSE x100, {ours}"] = r["mse_x100"]
        if ref is not None:
            row[f"MSE x100, {PAPER_LABEL}"] = _num(p, "mse_x100")
        row[f"train time (min), {ours}"] = float(r["train_s"]) / 60.0
        if ref is not None:
            row[f"train time (h), {PAPER_LABEL}"] = _num(p, "train_hours_rtx3090")
        row[f"test time (s), {test}"] = float(r["test_s"])
        if ref is not None:
            row["test time (s), paper (RTX 3090, 512x512)"] = _num(p, "test_seconds_512x512_rtx3090")
        rows.append(row)
    return pd.DataFrame(rows).set_index("cell")


def paper_loss_name(config: dict[str, Any]) -> str | None:
    """The paper's Table V row of a cell's last-stage loss (UAFL only with the paper's beta 0.1)."""
    loss, params = last_stage_loss(config)
    if loss == "uafl":
        return "uafl" if abs(float(params.get("beta", PAPER_UAFL_BETA)) - PAPER_UAFL_BETA) < 1e-12 else None
    return PAPER_LOSS_NAMES.get(loss, loss) if not params else None


def table5(spec: AblationSpec, frame: pd.DataFrame, paper, log: Log) -> pd.DataFrame:
    """Table V: BadPix 0.07 per fine-tuning loss (ours | paper), and our MSE x100."""
    ours = ours_label(spec)
    ref = _paper_extra(paper, TABLE5_FILE, ("loss", "badpix_0.07"), log)
    configs = {c.id: c.config for c in spec.cells}
    rows = []
    for cid, r in frame.iterrows():
        name = paper_loss_name(configs[cid])
        row = {"cell": cid, "loss (stage 2)": r["loss"], "paper row": name or "-",
               f"BadPix 0.07 (%), {ours}": r["badpix_0.07"]}
        if ref is not None:
            hit = ref[ref["loss"].astype(str).str.strip() == name] if name else ref.iloc[0:0]
            row[f"BadPix 0.07 (%), {PAPER_LABEL}"] = float(hit["badpix_0.07"].iloc[0]) if len(hit) else np.nan
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


# --------------------------------------------------------------------------- seeds

def seed_means(spec: AblationSpec, frame: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, str]]:
    """The cell frame averaged over seeds (one row per variant, indexed by its first seed's cell so the table
    builders find its config) and the map from that cell id to the variant id; unchanged without seeds."""
    if not spec.seeds or frame.empty:
        return frame, {}
    from lfbench.ablation.significance import cell_info

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
    from lfbench.ablation.baselines import baselines_caption, baselines_table, scene_groups, summary_lines
    from lfbench.ablation.significance import cell_info

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


def write_seed_tables(spec: AblationSpec, results: Results, out: Path) -> list[Path]:
    """table_seeds (mean and 95 % t-interval over seeds per variant) and table_significance (the paper's
    orderings as paired t-tests over seeds); see lfbench.ablation.significance."""
    from lfbench.ablation.significance import ALPHA, cell_info, seeds_table, significance_table

    info, scores = cell_info(spec), results.to_frame()
    caption = caption_lines(spec, f"mean over seeds {', '.join(str(x) for x in spec.seeds)} and 95 % "
                                        "t-interval over seeds of the scene-mean score")
    written = write_table(seeds_table(info, scores, METRICS), out, "table_seeds", caption)
    sig = significance_table(spec.table, info, scores)
    if not sig.empty:
        caption = caption_lines(spec, "the paper's orderings, paired t-test over seeds (BadPix 0.07, lower "
                                            f"is better; two-sided, alpha {ALPHA:g})")
        written += write_table(sig.set_index("claim (paper)"), out, "table_significance", caption)
    return written


# --------------------------------------------------------------------------- writing

PAPER_ABLATION_NOTE = ("paper: Chao et al., IEEE TCI 2023 (RTX 3090, full training: 50 + 10 epochs, batch 32, the 16 "
                       "additional scenes; scored on 8 validation scenes; test time for a 512x512 input)")
PAPER_BENCHMARK_NOTE = ("paper: Chao et al., IEEE TCI 2023, Tables I/II (HCI benchmark; backgammon, dots and stripes "
                        "scored at high resolution, see 'paper resolution')")


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


def paper_line(paper, note: str = PAPER_ABLATION_NOTE) -> str:
    """What the 'paper' columns of a table that can have them are, or that they are absent and why."""
    return note if paper is not None else "paper: not shown (the paper's tables were not found)"


def _with_summary(caption: list[str], summary: Sequence[str]) -> list[str]:
    """The caption with the baseline summary lines right under its title line."""
    return [*caption[:1], *summary, *caption[1:]]


def load_paper_tables(paper: str | Path | None, log: Log):
    """The paper's tables, or None (with one line saying so) when no folder is given or found."""
    from lfbench.reports.paper import find_paper_dir, load_paper

    try:
        folder = find_paper_dir(paper)
    except DataError:
        log("the paper's tables were not found (--paper DIR or LFBENCH_PAPER_DIR): tables without paper columns")
        return None
    return load_paper(folder)


def write_report(spec: AblationSpec, out: str | Path, results: Results, markers: Sequence[dict[str, Any]], *,
                 paper: str | Path | None = None, log: Log = _log.info, folder: str | Path | None = None) -> list[Path]:
    """Every table and figure of the run into ``out``; returns the files written. ``folder``: the
    ablation's folder, whose cells' and methods' saved maps the error maps are drawn from (default ``out``)."""
    from lfbench.reports.paper import average_with_paper, per_scene_with_paper
    from lfbench.reports.tables import average_table, per_scene_table

    out = Path(out)
    paper_tables = load_paper_tables(paper, log)
    frame = cell_frame(spec, results, markers)
    written: list[Path] = []
    if not frame.empty:
        bar, bar_caption, bar_lines = baseline_verdicts(spec, results)
        for line in bar_lines:
            log(line)
        written += write_table(cells_table(spec, frame), out, "table_cells",
                               _with_summary(caption_lines(spec, "all cells"), bar_lines))
        means, rename = seed_means(spec, frame)
        seeds_note = ([f"ours: mean over seeds {', '.join(str(x) for x in spec.seeds)} (intervals and paired tests: "
                       "table_seeds, table_significance)"] if spec.seeds else [])
        with_paper = _with_summary([*caption_lines(spec), paper_line(paper_tables), *seeds_note], bar_lines)
        if spec.table == "table4":
            written += write_table(table4(spec, means, paper_tables, log).rename(index=rename), out, "table4",
                                   with_paper)
        elif spec.table == "table5":
            written += write_table(table5(spec, means, paper_tables, log).rename(index=rename), out, "table5",
                                   with_paper)
        elif spec.table == "beta":
            caption = _with_summary([*caption_lines(spec), *seeds_note, "paper: no values printed (its "
                                     "figure: BadPix 0.07 improves as beta goes from 1 down to 0.1)"], bar_lines)
            written += write_table(table_beta(spec, means).rename(index=rename), out, "table_beta", caption)
        if spec.seeds:
            written += write_seed_tables(spec, results, out)
        if not bar.empty:
            written += write_table(bar, out, "table_baselines", bar_caption)
    per_scene, average = per_scene_table(results), average_table(results)
    base_caption = caption_lines(spec, "Tables I/II")
    written += write_table(per_scene, out, "table_per_scene", base_caption)
    written += write_table(average, out, "table_average", base_caption)
    if paper_tables is not None and not per_scene.empty:
        covered = [s for s in results.scenes if s in paper_tables.scenes]
        if covered:
            methods = [paper_tables.resolve_method(m) for m in spec.paper_methods]
            caption = [*caption_lines(spec, "Tables I/II"), PAPER_BENCHMARK_NOTE]
            written += write_table(per_scene_with_paper(per_scene, paper_tables, methods), out,
                                   "table_per_scene_paper", caption)
            written += write_table(average_with_paper(average, paper_tables, results.scenes, methods), out,
                                   "table_average_paper", caption)
    written += write_figures(spec, out, frame, results, paper_tables, log, Path(folder) if folder is not None else out)
    return written


# --------------------------------------------------------------------------- figures

def write_figures(spec: AblationSpec, out: Path, frame: pd.DataFrame, results: Results, paper, log: Log,
                  folder: Path | None = None) -> list[Path]:
    """The figures into out/figures; the error maps from the maps saved under ``folder`` (default ``out``)."""
    from lfbench.ablation import plots

    fig_dir = out / "figures"
    written = []
    if not frame.empty and spec.table == "beta" and frame["beta"].notna().any():
        per_scene = results.to_frame()
        written.append(plots.beta_curve(frame, per_scene, fig_dir / "beta_curve.png", ours_label(spec)))
    if not frame.empty and spec.table == "table4":
        ref = _paper_extra(paper, TABLE4_FILE, ("interval", "interpolation", "badpix_0.07",
                                                "test_seconds_512x512_rtx3090"), lambda _: None)
        written.append(plots.accuracy_vs_time(frame, ref, fig_dir / "accuracy_vs_test_time.png", ours_label(spec),
                                              time_label(frame)))
    if spec.evaluation.error_maps:
        folder = folder if folder is not None else out
        maps = {cid: folder / "cells" / cid / "maps" for cid in frame.index} if not frame.empty else {}
        from lfbench.utils.names import file_name

        for m in spec.methods:
            maps[m.label] = folder / "methods" / file_name(m.label) / "maps"
        written += plots.error_maps(results.meta.get("scenes", []), maps, fig_dir / "error_maps", folder)
    return written
