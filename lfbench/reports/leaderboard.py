"""The benchmark's leaderboard numbers from a Results: per metric, each method's value and rank on every
scene, its mean over scenes and its average rank; and the overall average rank over every (scene,
metric). Pure DataFrames, used by the HTML report (lfbench.reports.html) and tested against
hand-ranked cases.

Ranking as on the benchmark's site: on each scene, methods are ranked by the metric's value (lower is
better unless the metric says otherwise), 1 = best, ties share the best rank ("min" ranking), a
method without a finite value on a scene is not ranked there. The average rank of a method is the
mean of its ranks over the scenes (or scene x metric pairs) where it is ranked. A reference method
(the ``gt`` oracle, ``Results.references``) keeps its values but is never ranked: an oracle is the
line the others are measured against, not a competitor that takes rank 1.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

import numpy as np
import pandas as pd

from lfbench.scoring.metrics import describe_metric

__all__ = ["all_metric_ranks", "metric_ranks", "metric_table", "overall_ranks"]


def metric_ranks(results, metric: str, *, references: Collection[str] | None = None) -> pd.DataFrame:
    """Long frame of one metric: columns method, scene, value, resolution, rank (float, NaN where
    the value is not finite and for the ``references``, default ``results.references``: they are
    not ranked and do not move the others' ranks)."""
    refs = set(results.references if references is None else references)
    df = results.to_frame()
    df = df[df["metric"] == metric][["method", "scene", "value", "resolution"]].copy()
    if df.empty:
        return df.assign(rank=pd.Series(dtype=float))
    badness = df["value"].astype(float).map(describe_metric(metric).badness)  # a signed metric by its magnitude
    finite = badness.where(np.isfinite(badness) & ~df["method"].isin(refs))
    df["rank"] = finite.groupby(df["scene"]).rank(method="min", ascending=True)
    return df.reset_index(drop=True)


def all_metric_ranks(results, *, references: Collection[str] | None = None) -> dict[str, pd.DataFrame]:
    """:func:`metric_ranks` of every metric in the results, computed once for every table that
    ranks (metric id -> long frame)."""
    return {m: metric_ranks(results, m, references=references) for m in results.metrics}


def metric_table(results, metric: str, *, ranks: pd.DataFrame | None = None) -> pd.DataFrame:
    """Wide frame of one metric, one row per method (in the results' order): columns
    ``(scene, 'value' | 'rank' | 'resolution')`` for every scene, then ``('mean', 'value')`` (the
    metric's aggregate over the method's scenes, the mean for every benchmark metric),
    ``('mean', 'resolution')`` (the resolutions averaged, e.g.
    'highres+lowres') and ``('average rank', 'value')``. ``ranks``: :func:`metric_ranks` of the
    metric when already computed."""
    long = ranks if ranks is not None else metric_ranks(results, metric)
    methods = [m for m in results.methods if m in set(long["method"])]
    scenes = [s for s in results.scenes if s in set(long["scene"])]
    cols = pd.MultiIndex.from_tuples([(s, k) for s in scenes for k in ("value", "rank", "resolution")]
                                     + [("mean", "value"), ("mean", "resolution"), ("average rank", "value")])
    table = pd.DataFrame(index=pd.Index(methods, name="method"), columns=cols, dtype=object)
    for r in long.itertuples(index=False):
        table.loc[r.method, (r.scene, "value")] = float(r.value)
        table.loc[r.method, (r.scene, "rank")] = float(r.rank)
        table.loc[r.method, (r.scene, "resolution")] = r.resolution
    from lfbench.scoring.metrics import METRICS

    found = METRICS.find(metric)
    for method, g in long.groupby("method", sort=False):
        values = g["value"].astype(float).to_numpy()
        table.loc[method, ("mean", "value")] = float(found.aggregate(values) if found else np.nanmean(values))
        table.loc[method, ("mean", "resolution")] = "+".join(sorted(set(g["resolution"])))
        ranks = g["rank"].dropna()
        table.loc[method, ("average rank", "value")] = float(ranks.mean()) if len(ranks) else float("nan")
    return table


def overall_ranks(results, metrics=None, *, ranks: Mapping[str, pd.DataFrame] | None = None) -> pd.Series:
    """Average rank of each method over every (scene, metric) where it is ranked, for ``metrics``
    (default: all in the results); index method in the results' order. ``ranks``: metric id ->
    :func:`metric_ranks`, when already computed."""
    metrics = list(metrics) if metrics is not None else results.metrics
    frames = [ranks[m] if ranks is not None else metric_ranks(results, m) for m in metrics]
    long = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["method", "rank"])
    mean = long.groupby("method")["rank"].mean()
    return mean.reindex([m for m in results.methods]).astype(float)
