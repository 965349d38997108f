"""Seeds and significance of an ablation run (``seeds = [...]`` in the spec).

Each variant (a cell's grid values without the seed) is trained once per seed. For every variant and
metric the tables report the mean over seeds of the scene-mean score and a 95 % t-interval over the
seeds (mean +- t_{0.975, n-1} s / sqrt(n)): the seed is the unit of replication, the evaluation scenes
are a fixed test set, so the interval says how much a re-training with another seed moves the number.

Each ordering the reference's declared table states becomes paired comparisons of variants
(lfbench.reports.reference.PaperTable): a ``trend`` (e.g. ``interval = "lower"`` in Table IV:
interval 1 worse than 0.5 worse than 0.25 worse than 0.1 at the same interpolation) and a ``best`` row
(e.g. its Table V: the best loss, at the table's ``where`` values, better than each other loss; its beta
sweep: the best beta better than each other beta), in the table's first declared metric (lower is better).
The test is a paired t-test over seeds of d_s = score(worse, s) - score(better, s), each score the mean
over the scenes both cells were scored on: pairing by seed removes what the seeds share (the sampled
patches, the initialisation), and averaging over scenes first keeps one independent value per training
run. Pairs over (scene, seed) would count each network once per scene as if the scenes were independent
replicates, which they are not (one network scores all of them): the p-values would be too small. With
n seeds the test has n - 1 degrees of freedom (with 3 seeds an effect must be about 4.3 standard errors
to reach p < 0.05), so "not resolved" is a common, honest outcome at a small budget. With so few seeds a
t-interval can also reach past what the metric can take (BadPix over 100 %): the seeds table clips it to
the metric's range (``Metric.value_range``) and says so.

Verdict per comparison at alpha = 0.05 (two-sided): ``reproduced`` (the paper's better variant is
significantly better), ``reversed`` (significantly worse), ``not resolved`` (otherwise, or fewer than
2 seeds in common).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from lfbench.ablation.facts import same_value
from lfbench.reports.reference import PaperTable
from lfbench.scoring.metrics import METRICS, Metric

__all__ = ["ALPHA", "Comparison", "comparisons", "paired_t", "scene_scores", "seeds_table",
           "ordering_metric", "significance_table", "t_interval", "verdict"]

ALPHA = 0.05
LEVEL = 0.95
#: HCI's primary metric (lfbench.scoring.metrics.primary_metric): the orderings' metric by default.
ORDERING_METRIC = "badpix_0.07"


def t_interval(values: Sequence[float], level: float = LEVEL) -> tuple[float, float, float]:
    """(mean, low, high): the t-interval of the mean of ``values`` (NaN bounds for fewer than 2 values)."""
    x = np.asarray([v for v in values if np.isfinite(v)], dtype=np.float64)
    if x.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(x.mean())
    if x.size < 2:
        return mean, math.nan, math.nan
    half = float(stats.t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return mean, mean - half, mean + half


def paired_t(better: Sequence[float], worse: Sequence[float], level: float = LEVEL) -> dict[str, float]:
    """Paired t-test of d = worse - better (positive: ``better`` has the lower score). Returns n, mean_diff,
    low, high (its t-interval), t and the two-sided p (NaN with fewer than 2 pairs; with all differences
    equal, p is 0 for a non-zero difference and 1 for none)."""
    d = np.asarray(worse, dtype=np.float64) - np.asarray(better, dtype=np.float64)
    d = d[np.isfinite(d)]
    n = int(d.size)
    mean, low, high = t_interval(d, level)
    if n < 2:
        return {"n": n, "mean_diff": mean, "low": low, "high": high, "t": math.nan, "p": math.nan}
    sd = float(d.std(ddof=1))
    if sd == 0.0:
        t = math.inf if mean > 0 else (-math.inf if mean < 0 else 0.0)
        return {"n": n, "mean_diff": mean, "low": mean, "high": mean, "t": t, "p": 0.0 if mean != 0 else 1.0}
    t = mean / (sd / math.sqrt(n))
    p = float(2 * stats.t.sf(abs(t), n - 1))
    return {"n": n, "mean_diff": mean, "low": low, "high": high, "t": float(t), "p": p}


def verdict(test: dict[str, float], alpha: float = ALPHA) -> str:
    """reproduced / reversed / not resolved for a :func:`paired_t` result (positive mean_diff: as the paper)."""
    if test["n"] < 2 or not np.isfinite(test["p"]) or test["p"] >= alpha:
        return "not resolved"
    return "reproduced" if test["mean_diff"] > 0 else "reversed"


@dataclass(frozen=True)
class Comparison:
    """One paired comparison: the paper says ``better`` beats ``worse`` (variant ids)."""

    claim: str
    better: str
    worse: str


def comparisons(table: PaperTable | None, info: pd.DataFrame) -> list[Comparison]:
    """The orderings the declared ``table`` states, as comparisons of the variants present (``info``:
    lfbench.ablation.facts.cell_info with a column per axis of the table): each ``trend`` axis (a lower or
    higher value better, between neighbouring values at equal values of the table's other axes), and its
    ``best`` row (the first axis at that value, and at its ``where`` values, better than each variant with
    another value)."""
    if info.empty or table is None:
        return []
    variants = info.drop_duplicates("variant").set_index("variant")
    axes = [a for a in table.join if a in variants.columns]
    out: list[Comparison] = []
    for axis, way in table.trend.items():
        if axis not in variants.columns:
            continue
        others = [a for a in axes if a != axis]
        groups = variants.groupby(others, sort=False) if others else [((), variants)]
        for key, group in groups:
            prefix = " / ".join(_text(k) for k in (key if isinstance(key, tuple) else (key,)))
            ordered = group.sort_values(axis, ascending=way == "higher")  # worse -> better
            ids, steps = list(ordered.index), list(ordered[axis])
            for i in range(len(ids) - 1):
                if steps[i] == steps[i + 1]:
                    continue
                out.append(Comparison(f"{prefix + ': ' if prefix else ''}{axis} {_text(steps[i + 1])} better than "
                                      f"{_text(steps[i])}", better=ids[i + 1], worse=ids[i]))
    if table.best and axes:
        axis = axes[0]
        valued = variants[variants[axis].notna()]
        is_best = np.array([same_value(v, table.best) for v in valued[axis]], dtype=bool)
        best = valued[is_best]
        for key, value in table.where.items():
            if key in best.columns:
                best = best[[pd.isna(v) or same_value(v, value) for v in best[key]]]
        for b in best.index:
            for other in valued[~is_best].index:
                out.append(Comparison(f"{axis} {table.best} better than {axis} {_text(valued.loc[other, axis])}",
                                      better=b, worse=other))
    return out


def _text(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float | int) and not isinstance(value, bool) else str(value)


def ordering_metric(table: PaperTable | None, default: str = ORDERING_METRIC) -> str:
    """The metric a table's orderings are tested in: its first declared metric, else ``default`` (the primary
    metric of the results' protocol, lfbench.scoring.metrics.primary_metric; :data:`ORDERING_METRIC`, HCI's)."""
    return next(iter(table.metrics), default) if table is not None else default


def scene_scores(scores: pd.DataFrame, metric: str) -> pd.DataFrame:
    """(cell, scene) -> value of one metric (the mean over resolutions, as the cell tables average)."""
    sel = scores[scores["metric"] == metric]
    return sel.groupby(["method", "scene"])["value"].mean().rename("value").reset_index()


def within_range(metric: str, low: float, high: float) -> tuple[float, float, bool]:
    """(low, high) of an interval of ``metric`` clipped to the values it can take (``Metric.value_range``;
    a metric lfbench does not define is left as it is), and whether clipping changed them."""
    found = METRICS.find(metric)
    if found is None:
        return low, high, False
    lo, hi = found.value_range
    clipped_low, clipped_high = min(max(low, lo), hi), max(min(high, hi), lo)
    changed = (np.isfinite(low) and clipped_low != low) or (np.isfinite(high) and clipped_high != high)
    return (low if np.isnan(low) else clipped_low), (high if np.isnan(high) else clipped_high), bool(changed)


def seeds_table(info: pd.DataFrame, scores: pd.DataFrame, metrics: Sequence[str]) -> tuple[pd.DataFrame, list[str]]:
    """Per variant (index) and metric: the mean over seeds of the scene-mean score, its 95 % t-interval
    (clipped to the metric's range, :func:`within_range`) and the number of seeds; and the metrics whose
    intervals were clipped, with their range (for the caption). ``scores``: long frame (method = cell id,
    scene, metric, value)."""
    rows: dict[str, dict[str, Any]] = {}
    clipped: dict[str, str] = {}
    for metric in metrics:
        per_cell = scene_scores(scores, metric).groupby("method")["value"].mean()
        for variant, group in info.groupby("variant", sort=False):
            vals = [float(per_cell[c]) for c in group.index if c in per_cell.index]
            mean, low, high = t_interval(vals)
            low, high, changed = within_range(metric, low, high)
            if changed:
                lo, hi = METRICS.find(metric).value_range
                clipped[metric] = f"{METRICS.find(metric).name}: {lo:g} to {hi:g}"
            row = rows.setdefault(variant, {"variant": variant, "seeds": len(vals)})
            row[f"{metric} mean"] = mean
            row[f"{metric} 95% low"] = low
            row[f"{metric} 95% high"] = high
    table = pd.DataFrame(list(rows.values())).set_index("variant") if rows else pd.DataFrame()
    return table, list(clipped.values())


def significance_table(table: PaperTable | None, info: pd.DataFrame, scores: pd.DataFrame,
                       metric: str | None = None) -> pd.DataFrame:
    """One row per comparison of :func:`comparisons`: both variants' means over the paired seeds, the mean
    paired difference (worse - better, in the direction the metric improves: of the negated scores where higher
    is better) with its 95 % interval, t, p and the verdict; in ``metric`` (default: the table's first declared
    metric, else :data:`ORDERING_METRIC`)."""
    metric = metric or ordering_metric(table)
    found = METRICS.find(metric)
    badness = (found or Metric.undefined(metric)).badness
    values = scene_scores(scores, metric)
    cell_scores = {c: dict(zip(g["scene"], g["value"], strict=True)) for c, g in values.groupby("method")}
    rows = []
    for comp in comparisons(table, info):
        better_cells = info[info["variant"] == comp.better]
        worse_cells = info[info["variant"] == comp.worse]
        worse_by_seed = {s: c for c, s in zip(worse_cells.index, worse_cells["seed"], strict=True)}
        b_vals, w_vals, seeds = [], [], []
        for cell, seed in zip(better_cells.index, better_cells["seed"], strict=True):
            other = worse_by_seed.get(seed)
            if other is None or cell not in cell_scores or other not in cell_scores:
                continue
            common = sorted(set(cell_scores[cell]) & set(cell_scores[other]))
            if not common:
                continue
            b_vals.append(float(np.mean([cell_scores[cell][s] for s in common])))
            w_vals.append(float(np.mean([cell_scores[other][s] for s in common])))
            seeds.append(seed)
        # d = worse - better of the scores' badness (negated where higher is better, the magnitude of a signed
        # metric), so that a positive difference is always "as the paper says"
        test = paired_t([badness(v) for v in b_vals], [badness(v) for v in w_vals])
        rows.append({"claim (paper)": comp.claim, "better": comp.better, "worse": comp.worse, "metric": metric,
                     "seeds": test["n"], "better mean": float(np.mean(b_vals)) if b_vals else math.nan,
                     "worse mean": float(np.mean(w_vals)) if w_vals else math.nan,
                     "difference (worse - better)": test["mean_diff"], "95% low": test["low"],
                     "95% high": test["high"], "t": test["t"], "p": test["p"], "verdict": verdict(test)})
    return pd.DataFrame(rows)
