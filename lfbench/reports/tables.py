"""Tables like the paper's: Table I (per scene x metric x method) and Table II (averages).

Each table is a pandas DataFrame; :func:`render` writes it as markdown (tabulate), LaTeX or CSV.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from tabulate import tabulate

from lfbench.reports import latex
from lfbench.results import Results
from lfbench.scoring.metrics import METRICS, list_metrics, metric_order
from lfbench.utils.atomic import write_text
from lfbench.utils.markdown import markdown_cell


def _header(column: str) -> str:
    """A column's header: a registered general metric's name (BadPix(0.07), MSE x100, ...), else as is."""
    for m in list_metrics("general"):
        if m.id == column:
            return m.name
    return column


def _scene_aggregate(metric_id: str) -> str:
    metric = METRICS.find(metric_id)
    return metric.scene_aggregate if metric is not None else "mean"


def per_scene_table(results: Results, metrics: Sequence[str] | None = None) -> pd.DataFrame:
    """Table I: rows (scene, metric), one column per method. Cells scored at high resolution are
    marked in the 'resolution' column (lowres / highres, or mixed)."""
    df = results.to_frame()
    if df.empty:
        return pd.DataFrame()
    order = metric_order(metrics or list(dict.fromkeys(df["metric"])))
    df = df[df["metric"].isin(order)]
    table = df.pivot_table(index=["scene", "metric"], columns="method", values="value", aggfunc="first", sort=False)
    res = df.groupby(["scene", "metric"], sort=False)["resolution"].agg(lambda s: "/".join(sorted(set(s))))
    table = table.reindex(columns=list(dict.fromkeys(df["method"])))
    table.insert(0, "resolution", res)
    scenes = list(dict.fromkeys(df["scene"]))
    idx = [(s, m) for s in scenes for m in order if (s, m) in table.index]
    return table.loc[idx]


def average_table(results: Results, metrics: Sequence[str] | None = None) -> pd.DataFrame:
    """Table II: per method (rows) and metric (columns) the metric's aggregate over scenes (the mean for
    every benchmark metric, see ``Metric.scene_aggregate``), with runtime (s)
    and the number of scenes. A method missing a scene is averaged over the scenes it has."""
    df = results.to_frame()
    if df.empty:
        return pd.DataFrame()
    order = metric_order(metrics or list(dict.fromkeys(df["metric"])))
    how = {m: _scene_aggregate(m) for m in order}  # each metric aggregates over scenes as it defines
    parts = [df[df["metric"].isin([m for m in order if how[m] == agg])]
             .pivot_table(index="method", columns="metric", values="value", aggfunc=agg, sort=False)
             for agg in dict.fromkeys(how.values())]
    table = pd.concat(parts, axis=1) if parts else pd.DataFrame()
    table = table.reindex(index=list(dict.fromkeys(df["method"])), columns=order)
    table["scenes"] = df.groupby("method", sort=False)["scene"].nunique()
    if results.runs:
        rt = pd.DataFrame([(r.method, r.runtime_s) for r in results.runs], columns=["method", "runtime_s"])
        table["runtime_s"] = rt.groupby("method")["runtime_s"].mean()
    return table


def render(table: pd.DataFrame, fmt: str = "markdown", floatfmt: str = ".3f") -> str:
    """A table as 'markdown' (GitHub pipes), 'latex' (booktabs; every string escaped by
    lfbench.reports.latex), 'csv' or 'plain' text."""
    if table.empty:
        return "(no results)\n"
    flat = table.reset_index()
    headers = [_header(str(c)) for c in flat.columns]
    if fmt == "csv":
        return flat.to_csv(index=False, float_format="%.6g")
    if fmt not in ("markdown", "latex", "plain"):
        raise ValueError(f"unknown table format {fmt!r}: markdown, latex, csv or plain")

    def cell(v):
        if isinstance(v, (float, np.floating)):
            return "-" if np.isnan(v) else format(float(v), floatfmt)
        return v

    rows = [[cell(v) for v in row] for row in flat.itertuples(index=False)]
    if fmt == "latex":
        return latex.tabular(headers, rows)  # every cell and header escaped (lfbench.reports.latex)
    if fmt == "markdown":  # a label's "|" or newline would break the row (lfbench.utils.markdown)
        headers = [markdown_cell(h) for h in headers]
        rows = [[markdown_cell(v) for v in row] for row in rows]
    return tabulate(rows, headers=headers, tablefmt="github" if fmt == "markdown" else "simple",
                    disable_numparse=True) + "\n"


#: The formats every table is written in: (render format, file extension).
TABLE_FORMATS: tuple[tuple[str, str], ...] = (("markdown", "md"), ("latex", "tex"), ("csv", "csv"))


def render_with_caption(table: pd.DataFrame, fmt: str, caption: Sequence[str] = ()) -> str:
    """:func:`render` with caption lines above the table: Markdown lines (hard breaks) or LaTeX
    comments (escaped, one line each: lfbench.reports.latex.comment); CSV stays a plain table."""
    body = render(table, fmt)
    if not caption:
        return body
    if fmt == "markdown":
        return "".join(f"{line}  \n" for line in caption) + "\n" + body
    if fmt == "latex":
        return latex.comment(caption) + body
    return body


def write_table(table: pd.DataFrame, out_dir: str | Path, stem: str, caption: Sequence[str] = (), *,
                formats: Sequence[tuple[str, str]] = TABLE_FORMATS) -> list[Path]:
    """Write one table as OUT/<stem>.<ext> for each (format, ext) of ``formats`` (atomically);
    returns the paths."""
    written = []
    for fmt, ext in formats:
        path = Path(out_dir) / f"{stem}.{ext}"
        write_text(path, render_with_caption(table, fmt, caption))
        written.append(path)
    return written
