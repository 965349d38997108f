"""A paper's wide per-scene table beside ours (e.g. SubFocal's Table III on UrbanLF-Syn: one row per method,
one column per sample, their mean, runtime and parameters), generic over the reference's declaration
(lfbench.reports.reference.PaperTable with ``scenes``): which scenes, which metric, which CSV columns.

The table is shown when the results are of the declaration's ``dataset`` (results.json ``meta.dataset``)
and the paper folder holds its file. Rows: every method of the results under its own name (the values
are the results' ``scene_metric`` on the declared scenes, their mean over the declared scenes it has, the
number of them, and the run's mean per-scene runtime at the data's resolution), then every row of the
paper's file as 'NAME (paper)' (its per-scene columns, its own mean column, its extra columns such as a
runtime measured at another size: the caption says which).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from lfbench.reports.paper import PaperTables, paper_column
from lfbench.reports.reference import PaperTable
from lfbench.results import Results
from lfbench.utils.errors import DataError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["RUN_RUNTIME_COLUMN", "SCENES_COLUMN", "scene_tables", "scene_table_with_paper"]

log = logging.getLogger(__name__)

SCENES_COLUMN = "scenes"
RUN_RUNTIME_COLUMN = "runtime_s (this run, per scene)"


def scene_tables(paper: PaperTables, meta: Mapping[str, object]) -> list[PaperTable]:
    """The reference's per-scene tables (declared ``scenes``) of the dataset the results are of."""
    if paper.reference is None:
        return []
    dataset = str(meta.get("dataset") or "")
    return [t for t in paper.reference.tables if t.scenes and t.dataset and t.dataset == dataset]


def _paper_frame(paper: PaperTables, table: PaperTable) -> pd.DataFrame:
    """The paper's CSV of ``table`` with its declared columns checked (DataError naming the file)."""
    import pandas as pd

    path = Path(paper.source) / table.file
    stem = Path(table.file).stem
    if stem not in paper.extra:
        raise DataError(f"not found: the paper's {table.id} (the reference names {table.file})", path)
    df = paper.extra[stem]
    needed = [*table.keys, *table.scenes.values(), *table.metrics.values(), *table.extra.values()]
    missing = [c for c in dict.fromkeys(needed) if c not in df.columns]
    if missing:
        raise DataError(f"missing column(s) {', '.join(missing)} of the paper's {table.id}", path)
    for column in dict.fromkeys([*table.scenes.values(), *table.metrics.values(), *table.extra.values()]):
        values = pd.to_numeric(df[column], errors="coerce")
        bad = values.isna() & df[column].notna()
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise DataError(f"line {row + 2}: {column} {df[column].iloc[row]!r} is not a number", path)
    return df


def scene_table_with_paper(results: Results, paper: PaperTables, table: PaperTable) -> pd.DataFrame:
    """Ours and the paper's rows of the per-scene table ``table`` (see the module docstring); columns: the
    paper's scene columns, the metric's mean (named by the metric id), ``scenes``, the paper's extra
    columns and :data:`RUN_RUNTIME_COLUMN`. Empty when the results hold none of the declared scenes."""
    import pandas as pd

    paper_df = _paper_frame(paper, table)
    metric = table.scene_metric
    df = results.to_frame()
    df = df[(df["metric"] == metric) & df["scene"].isin(list(table.scenes))]
    if df.empty:
        log.warning("the results hold %s on none of the paper's %s scenes (%s): no %s table", metric, table.id,
                    ", ".join(table.scenes), table.id)
        return pd.DataFrame()
    ours = df.pivot_table(index="method", columns="scene", values="value", aggfunc="first", sort=False)
    ours = ours.reindex(index=list(dict.fromkeys(df["method"])), columns=list(table.scenes))
    out = pd.DataFrame(index=ours.index)
    for scene, column in table.scenes.items():
        out[column] = ours[scene].astype(float)
    out[metric] = ours.mean(axis=1, skipna=True)
    out[SCENES_COLUMN] = ours.notna().sum(axis=1).astype("Int64")
    for name in table.extra:
        out[name] = np.nan
    runtimes = pd.DataFrame([(r.method, r.scene, r.runtime_s) for r in results.runs],
                            columns=["method", "scene", "runtime_s"])
    runtimes = runtimes[runtimes["scene"].isin(list(table.scenes))]
    out[RUN_RUNTIME_COLUMN] = runtimes.groupby("method")["runtime_s"].mean().reindex(out.index)
    mean_column = table.metrics.get(metric)
    rows = {}
    for _, row in paper_df.iterrows():
        label = paper_column(" / ".join(str(row[k]) for k in table.keys))
        values = {column: float(row[column]) for column in table.scenes.values()}
        values[metric] = float(row[mean_column]) if mean_column else float(np.mean(list(values.values())))
        values[SCENES_COLUMN] = len(table.scenes)
        values |= {name: float(row[column]) for name, column in table.extra.items()}
        rows[label] = values
    theirs = pd.DataFrame.from_dict(rows, orient="index").reindex(columns=out.columns)
    both = pd.concat([out, theirs])
    both[SCENES_COLUMN] = both[SCENES_COLUMN].astype("Int64")
    both.index.name = "method"
    return both
