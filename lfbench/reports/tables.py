"""Tables like the paper's: Table I (per scene x metric x method) and Table II (averages).

Table I and II are built from the records in plain Python (:class:`Table`: no pandas, which costs a process that
scores one submission more CPU time to import than writing every table), with pandas' own semantics: Table I's
cell is the first non-NaN value of its (scene, metric, method) and a row with none is left out; Table II's is
the mean of the non-NaN values in pandas' groupby arithmetic (Kahan-compensated sums: :func:`group_mean`), so
every number is the one ``DataFrame.pivot_table`` gives. :meth:`Table.to_frame` is that DataFrame (what
:func:`per_scene_table` and :func:`average_table` return, for the reports that go on in pandas). :func:`render`
writes a Table or a DataFrame as markdown (tabulate), LaTeX or CSV.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tabulate import tabulate

from lfbench.reports import latex
from lfbench.results import Record, Results, RunInfo
from lfbench.scoring.metrics import METRICS, metric_order
from lfbench.utils.atomic import write_text
from lfbench.utils.markdown import markdown_cell

if TYPE_CHECKING:
    import pandas as pd


def _header(column: str) -> str:
    """A column's header: the name of the general metric the registry knows by that id (BadPix(0.07), MSE x100,
    any BadPix(t) such as BadPix(0.05), a general metric of a plugin), else as is."""
    metric = METRICS.find(column)
    return metric.name if metric is not None and metric.id == column and metric.category == "general" else column


def _scene_aggregate(metric_id: str) -> str:
    metric = METRICS.find(metric_id)
    return metric.scene_aggregate if metric is not None else "mean"


@dataclass(frozen=True)
class Table:
    """A table as rows: ``index`` (the names of the key columns), ``columns`` (the value columns, in order,
    under the axis name ``columns_name``), ``rows`` (each the keys, then one value per column: a float, NaN
    where there is none, an int or a str) and ``ints`` (the columns of ints)."""

    index: tuple[str, ...]
    columns: tuple[str, ...]
    rows: tuple[tuple[Any, ...], ...]
    columns_name: str | None = None
    ints: frozenset[str] = frozenset()

    @property
    def empty(self) -> bool:
        return not self.rows

    @property
    def headers(self) -> list[str]:
        """The names of every column, keys first."""
        return [*self.index, *self.columns]

    def to_csv(self) -> str:
        """CSV as ``DataFrame.to_csv(index=False, float_format="%.6g")`` of the flat table writes it: a float as
        %.6g, NaN as an empty field, every other value as its text."""
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(self.headers)
        for row in self.rows:
            writer.writerow(["" if isinstance(v, float) and math.isnan(v) else "%.6g" % v if isinstance(v, float)
                             else v for v in row])
        return buf.getvalue()

    def to_frame(self) -> pd.DataFrame:
        """The same table as a pandas DataFrame: the keys as its index (a MultiIndex for several), float64
        value columns (int64 for :attr:`ints`, str for text)."""
        import pandas as pd

        if self.empty:
            return pd.DataFrame()
        keys = [row[:len(self.index)] for row in self.rows]
        index = (pd.MultiIndex.from_tuples(keys, names=list(self.index)) if len(self.index) > 1
                 else pd.Index([k[0] for k in keys], name=self.index[0]))
        data = {}
        for j, name in enumerate(self.columns, start=len(self.index)):
            values = [row[j] for row in self.rows]
            numeric = all(isinstance(v, float | int) for v in values)
            data[name] = np.array(values, dtype=np.int64 if name in self.ints else np.float64) if numeric else values
        frame = pd.DataFrame(data, index=index, columns=list(self.columns))
        frame.columns.name = self.columns_name
        return frame


def group_mean(values: Sequence[float]) -> float:
    """The mean of the non-NaN ``values`` as pandas' Cython groupby kernel computes it (``group_mean``): a
    Kahan-compensated sum in order (a compensation made NaN by an infinity is reset to 0) divided by the
    count; NaN when there is none."""
    total = compensation = 0.0
    count = 0
    for value in values:
        if value != value:  # NaN
            continue
        count += 1
        y = value - compensation
        t = total + y
        compensation = t - total - y
        if compensation != compensation:
            compensation = 0.0
        total = t
    return total / count if count else float("nan")


def group_means(keys: Sequence[Any], values: Sequence[float], *, sort: bool = False) -> dict[Any, float]:
    """The mean of ``values`` per key (``keys[i]`` is the group of ``values[i]``), bit for bit as
    ``pandas.Series(values).groupby(keys, sort=sort).mean()`` (pandas 3.1): when every group's values are
    contiguous, in the groups' order (first appearance; sorted keys for ``sort``), and no value is NaN, each
    group's ``numpy.add.reduceat`` sum over its count; otherwise :func:`group_mean` of each group."""
    groups: dict[Any, list[float]] = {}
    for key, value in zip(keys, values, strict=True):
        groups.setdefault(key, []).append(value)
    rank = {key: k for k, key in enumerate(sorted(groups) if sort else groups)}
    codes = [rank[key] for key in keys]
    monotonic = all(a <= b for a, b in itertools.pairwise(codes))
    if monotonic and codes and not any(v != v for v in values):
        with np.errstate(invalid="ignore", over="ignore"):  # inf - inf is NaN, as pandas' mean gives
            return {key: float(np.add.reduceat(np.asarray(group, dtype=np.float64), [0])[0] / np.float64(len(group)))
                    for key, group in groups.items()}
    return {key: group_mean(group) for key, group in groups.items()}


def _first_value(values: Sequence[float]) -> float:
    """pandas' groupby ``first``: the first non-NaN value, NaN when there is none."""
    return next((v for v in values if v == v), float("nan"))


def _records(results: Results, metrics: Sequence[str] | None) -> tuple[list[Record], list[str]]:
    """The records of the metrics shown (``metrics``, default the results'), with their order in tables."""
    order = metric_order(metrics or results.metrics)
    shown = set(order)
    return [r for r in results.records if r.metric in shown], order


def _value(record: Record) -> float:
    return float("nan") if record.value is None else float(record.value)


def _runtime(run: RunInfo) -> float:
    return float("nan") if run.runtime_s is None else float(run.runtime_s)


def per_scene_rows(results: Results, metrics: Sequence[str] | None = None) -> Table:
    """Table I as a :class:`Table`: rows (scene, metric) in the order scenes first appear and metrics are shown
    (:func:`~lfbench.scoring.metrics.metric_order`), a 'resolution' column (the resolutions its records were
    scored at, sorted, joined by '/'), then one column per method in the order they first appear; a row where
    no method has a value is left out, unless no row has one (then all are shown, as pandas did)."""
    records, order = _records(results, metrics)
    methods = list(dict.fromkeys(r.method for r in records))
    cells: dict[tuple[str, str], dict[str, list[float]]] = {}
    resolutions: dict[tuple[str, str], set[str]] = {}
    for r in records:
        cells.setdefault((r.scene, r.metric), {}).setdefault(r.method, []).append(_value(r))
        resolutions.setdefault((r.scene, r.metric), set()).add(r.resolution)
    rows = []
    for scene in dict.fromkeys(r.scene for r in records):
        for metric in order:
            by_method = cells.get((scene, metric))
            if by_method is not None:
                values = [_first_value(by_method.get(m, ())) for m in methods]
                rows.append((scene, metric, "/".join(sorted(resolutions[scene, metric])), *values))
    if any(v == v for row in rows for v in row[3:]):  # as pandas' pivot_table: a row of NaN only is left out,
        rows = [row for row in rows if any(v == v for v in row[3:])]  # unless no row has a value
    return Table(index=("scene", "metric"), columns=("resolution", *methods), rows=tuple(rows),
                 columns_name="method")


def average_rows(results: Results, metrics: Sequence[str] | None = None) -> Table:
    """Table II as a :class:`Table`: per method (rows, in the order they first appear) and metric (columns, as
    shown) the metric's aggregate over scenes (the mean of its non-NaN values, :func:`group_mean`, for every
    benchmark metric: ``Metric.scene_aggregate``), then 'scenes' (how many scenes the method has records on)
    and, when the results hold runs, 'runtime_s' (its mean over them). A method missing a scene is averaged
    over the scenes it has."""
    if not results.records:
        return Table(index=("method",), columns=(), rows=())
    records, order = _records(results, metrics)
    unknown = {_scene_aggregate(m) for m in order} - {"mean"}
    if unknown:
        raise ValueError(f"scene aggregate {sorted(unknown)[0]!r} has no table rule")
    means = group_means([(r.method, r.metric) for r in records], [_value(r) for r in records])
    scenes: dict[str, set[str]] = {}
    for r in results.records:
        scenes.setdefault(r.method, set()).add(r.scene)
    runtimes = group_means([run.method for run in results.runs], [_runtime(run) for run in results.runs], sort=True)
    columns = [*order, "scenes", *(["runtime_s"] if results.runs else [])]
    rows = []
    for method in dict.fromkeys(r.method for r in results.records):
        row = [method, *(means.get((method, m), float("nan")) for m in order), len(scenes[method])]
        if results.runs:
            row.append(runtimes.get(method, float("nan")))
        rows.append(tuple(row))
    return Table(index=("method",), columns=tuple(columns), rows=tuple(rows), columns_name="metric",
                 ints=frozenset({"scenes"}))


def per_scene_table(results: Results, metrics: Sequence[str] | None = None) -> pd.DataFrame:
    """Table I (:func:`per_scene_rows`) as a pandas DataFrame: rows (scene, metric), one column per method. Cells
    scored at high resolution are marked in the 'resolution' column (lowres / highres, or mixed)."""
    return per_scene_rows(results, metrics).to_frame()


def average_table(results: Results, metrics: Sequence[str] | None = None) -> pd.DataFrame:
    """Table II (:func:`average_rows`) as a pandas DataFrame: per method (rows) and metric (columns) the
    metric's aggregate over scenes, with runtime (s) and the number of scenes."""
    return average_rows(results, metrics).to_frame()


def render(table: Table | pd.DataFrame, fmt: str = "markdown", floatfmt: str = ".3f") -> str:
    """A table (a :class:`Table` or a DataFrame, its index as the first columns) as 'markdown' (GitHub pipes),
    'latex' (booktabs; every string escaped by lfbench.reports.latex), 'csv' or 'plain' text."""
    if table.empty:
        return "(no results)\n"
    if isinstance(table, Table):
        names, values = table.headers, table.rows
    else:
        flat = table.reset_index()
        names, values = [str(c) for c in flat.columns], flat.itertuples(index=False)
    if fmt == "csv":
        return table.to_csv() if isinstance(table, Table) else flat.to_csv(index=False, float_format="%.6g")
    if fmt not in ("markdown", "latex", "plain"):
        raise ValueError(f"unknown table format {fmt!r}: markdown, latex, csv or plain")
    headers = [_header(name) for name in names]

    def cell(v):
        if isinstance(v, float | np.floating):
            return "-" if np.isnan(v) else format(float(v), floatfmt)
        return v

    rows = [[cell(v) for v in row] for row in values]
    if fmt == "latex":
        return latex.tabular(headers, rows)  # every cell and header escaped (lfbench.reports.latex)
    if fmt == "markdown":  # a label's "|" or newline would break the row (lfbench.utils.markdown)
        headers = [markdown_cell(h) for h in headers]
        rows = [[markdown_cell(v) for v in row] for row in rows]
    return tabulate(rows, headers=headers, tablefmt="github" if fmt == "markdown" else "simple",
                    disable_numparse=True) + "\n"


#: The formats every table is written in: (render format, file extension).
TABLE_FORMATS: tuple[tuple[str, str], ...] = (("markdown", "md"), ("latex", "tex"), ("csv", "csv"))


def render_with_caption(table: Table | pd.DataFrame, fmt: str, caption: Sequence[str] = ()) -> str:
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


def write_table(table: Table | pd.DataFrame, out_dir: str | Path, stem: str, caption: Sequence[str] = (), *,
                formats: Sequence[tuple[str, str]] = TABLE_FORMATS) -> list[Path]:
    """Write one table as OUT/<stem>.<ext> for each (format, ext) of ``formats`` (atomically);
    returns the paths."""
    written = []
    for fmt, ext in formats:
        path = Path(out_dir) / f"{stem}.{ext}"
        write_text(path, render_with_caption(table, fmt, caption))
        written.append(path)
    return written
