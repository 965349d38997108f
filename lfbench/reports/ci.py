"""Tables of bootstrap confidence intervals (``lfbench evaluate --ci``: table_ci_per_scene.*): rows
(scene, metric), a column per method, cells 'value [low, high]'; the '(mean)' rows carry the bootstrap
over scenes. The intervals are computed by :func:`lfbench.scoring.stats.ci_records`; tables render with
:func:`lfbench.reports.tables.render` (string cells pass through).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import pandas as pd

from lfbench.scoring.metrics import metric_order
from lfbench.scoring.stats import DEFAULT_LEVEL, DEFAULT_RESAMPLES, ErrorsLike, ci_records

__all__ = ["ci_table", "format_ci_table"]


def format_ci_table(long: pd.DataFrame, floatfmt: str = ".3f") -> pd.DataFrame:
    """The wide 'value [low, high]' table from :func:`lfbench.scoring.stats.ci_records` output: rows
    (scene, metric) in the order of the scenes and :func:`~lfbench.scoring.metrics.metric_order`, a column
    per method; '-' where a method has no value."""
    long = long.copy()
    if long.empty:
        return pd.DataFrame()

    def cell(r) -> str:
        if math.isnan(r.value):
            return "-"
        v = format(r.value, floatfmt)
        return v if math.isnan(r.low) else f"{v} [{format(r.low, floatfmt)}, {format(r.high, floatfmt)}]"

    long["cell"] = [cell(r) for r in long.itertuples(index=False)]
    table = long.pivot_table(index=["scene", "metric"], columns="method", values="cell", aggfunc="first", sort=False)
    table = table.reindex(columns=list(dict.fromkeys(long["method"])))
    order = metric_order(dict.fromkeys(long["metric"]))
    scenes = list(dict.fromkeys(long["scene"]))
    idx = [(s, m) for s in scenes for m in order if (s, m) in table.index]
    return table.loc[idx].fillna("-")


def ci_table(results, errors: Mapping[tuple[str, str], ErrorsLike], metrics: Sequence[str] | None = None,
             n: int = DEFAULT_RESAMPLES, seed: int = 0, level: float = DEFAULT_LEVEL, *, block: int | None = None,
             floatfmt: str = ".3f") -> pd.DataFrame:
    """Per-scene table like :func:`lfbench.reports.tables.per_scene_table` whose cells read 'value [low, high]'
    (:func:`lfbench.scoring.stats.ci_records` of ``results`` and the per-pixel ``errors``, then
    :func:`format_ci_table`)."""
    return format_ci_table(ci_records(results, errors, metrics, n, seed, level, block=block), floatfmt)
