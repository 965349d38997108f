"""Does every cell of an ablation clear the baselines of its spec (``[[methods]]``, e.g. the plane sweep and
the zero map ``constant``)? ``table_baselines`` and one summary line per baseline say so.

Scores are compared per scene group (lfbench.reports.sweep_table.scene_group: the synthetic evaluation
scenes together, each real scene alone; a group's value is the metric's scene aggregate, the mean, of the
per-scene scores, each the mean over resolutions as in table_seeds) on the verdict metrics of the results'
protocol (:func:`verdict_metrics`: its primary metric and MSE x100, BadPix 0.07 and MSE x100 on HCI), in the
direction the metric registry gives. A cell *beats* a baseline when it is better on every metric on every
group. With seeds, a row is a variant: it beats a baseline on a (metric, group) when the end of its 95 %
t-interval over seeds on the baseline's side (the upper end when lower is better) is better than the
baseline's value (the baseline is deterministic); when only the mean is better the comparison is *not
resolved*. Verdict strings:

- ``beats``;
- ``does not beat: <metric> on <group> (<cell> vs <baseline>); ...``: the mean is not better somewhere;
- ``not resolved: <metric> on <group> (95% high <bound> vs <baseline>); ...``: the mean is better
  everywhere, but an interval reaches the baseline (or a score or an interval is missing);
- ``not resolved: no scores to compare``: the baseline (or the cell) has no score on any group.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import pandas as pd

from lfbench.ablation.significance import LEVEL, scene_scores, t_interval, within_range
from lfbench.reports.sweep_table import SYNTH_PREFIX, scene_group
from lfbench.scoring.metrics import get_metric, primary_metric

__all__ = ["BEATS", "VERDICT_METRICS", "baselines_caption", "baselines_table", "group_scores", "scene_groups",
           "summary_lines", "verdict", "verdict_metrics"]

#: The verdict metrics of HCI's protocol (:func:`verdict_metrics` of its metrics), the functions' default.
VERDICT_METRICS = ("badpix_0.07", "mse_x100")
BEATS = "beats"
NOT_BEATEN, NOT_RESOLVED = "does not beat", "not resolved"
NO_SCORES = "no scores to compare"


def verdict_metrics(metric_ids: Sequence[str]) -> tuple[str, ...]:
    """The metrics the verdicts compare, of a protocol's metrics (``metric_ids``): its primary metric
    (lfbench.scoring.metrics.primary_metric, its first BadPix in table order), then MSE x100 where the protocol
    scores it (:data:`VERDICT_METRICS` on HCI); the captions name them (:func:`baselines_caption`)."""
    primary = primary_metric(metric_ids)
    chosen = ([primary] if primary is not None else []) + (["mse_x100"] if "mse_x100" in metric_ids else [])
    return tuple(dict.fromkeys(chosen))


def _fmt(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:.3f}"


def _bound_name(metric: str) -> str:
    """'95% high' when lower is better (the interval's end nearest a worse value), '95% low' when higher is
    better, '95% far end' (from 0) for a signed metric."""
    found = get_metric(metric)
    end = "far end" if found.signed else "low" if found.higher_is_better else "high"
    return f"{round(LEVEL * 100)}% {end}"


def scene_groups(scores: pd.DataFrame) -> dict[str, str]:
    """Scene -> its group, in order of first appearance in ``scores`` (long frame with a 'scene' column)."""
    scenes = list(dict.fromkeys(scores["scene"]))
    synth = sum(s.startswith(SYNTH_PREFIX) for s in scenes)
    return {s: scene_group(s, synth) for s in scenes}


def group_scores(scores: pd.DataFrame, metrics: Sequence[str] = VERDICT_METRICS) -> pd.DataFrame:
    """Index (method, group), one column per metric: the metric's scene aggregate over the group's scenes.
    ``scores``: long frame (method, scene, metric, value, resolution). Groups in order of first appearance."""
    groups = scene_groups(scores)
    order = list(dict.fromkeys(groups.values()))
    columns = []
    for metric in metrics:
        per_scene = scene_scores(scores, metric)
        per_scene["group"] = per_scene["scene"].map(groups)
        agg = get_metric(metric).aggregate
        columns.append(per_scene.groupby(["method", "group"])["value"].agg(lambda v, f=agg: f(v.to_numpy()))
                       .rename(metric))
    frame = pd.concat(columns, axis=1) if columns else pd.DataFrame()
    methods = list(dict.fromkeys(scores["method"]))
    return frame.reindex(pd.MultiIndex.from_product([methods, order], names=["method", "group"]))


def verdict(cell: dict[tuple[str, str], tuple[float, float]], baseline: dict[tuple[str, str], float], *,
            seeds: bool) -> str:
    """The verdict of one cell against one baseline. ``cell``: (metric, group) -> (mean, interval end on the
    baseline's side; NaN without seeds); ``baseline``: (metric, group) -> value."""
    failed, open_, unscored = [], [], 0
    for (metric, group), (mean, bound) in cell.items():
        base = baseline.get((metric, group), math.nan)
        where = f"{get_metric(metric).name} on {group}"
        badness = get_metric(metric).badness  # a signed metric: its magnitude
        if not (math.isfinite(mean) and math.isfinite(base)):
            unscored += 1
            open_.append(f"{where} (no score)")
        elif not badness(mean) < badness(base):
            failed.append(f"{where} ({_fmt(mean)} vs {_fmt(base)})")
        elif seeds and not (math.isfinite(bound) and badness(bound) < badness(base)):
            open_.append(f"{where} ({_bound_name(metric)} {_fmt(bound)} vs {_fmt(base)})")
    if failed:
        return f"{NOT_BEATEN}: " + "; ".join(failed)
    if cell and unscored == len(cell):
        return f"{NOT_RESOLVED}: {NO_SCORES}"
    return f"{NOT_RESOLVED}: " + "; ".join(open_) if open_ else BEATS


def baselines_table(info: pd.DataFrame, scores: pd.DataFrame, baselines: Sequence[str], *, seeds: bool,
                    metrics: Sequence[str] = VERDICT_METRICS) -> pd.DataFrame:
    """One row per variant (``seeds``: the mean over its seeds, index 'variant') or cell (index 'cell'): per
    scene group and metric the cell's value (with seeds also its 95 % interval end that decides), each
    baseline's value, then one verdict column 'vs <baseline>' per baseline (:func:`verdict`).
    ``info``: lfbench.ablation.facts.cell_info; ``baselines``: method labels in ``scores``."""
    if info.empty:
        return pd.DataFrame()
    values = group_scores(scores, metrics)
    groups = list(dict.fromkeys(scene_groups(scores).values()))
    scored = set(scores["method"])
    keys = info["variant"] if seeds else pd.Series(info.index, index=info.index)
    rows = []
    for key, cells in keys.groupby(keys, sort=False):
        row: dict[str, object] = {"variant" if seeds else "cell": key}
        if seeds:
            row["seeds"] = sum(c in scored for c in cells.index)
        mine: dict[tuple[str, str], tuple[float, float]] = {}
        for group in groups:
            for metric in metrics:
                vals = [float(values.loc[(c, group), metric]) for c in cells.index if (c, group) in values.index]
                mean, low, high = t_interval(vals)
                low, high, _ = within_range(metric, low, high)  # the cell's interval within the metric's range
                bound = get_metric(metric).worst_end(low, high) if seeds else math.nan
                mine[(metric, group)] = (mean, bound)
                name = get_metric(metric).name
                row[f"{name}, {group}, cell"] = mean
                if seeds:
                    row[f"{name}, {group}, cell {_bound_name(metric)}"] = bound
                for label in baselines:
                    row[f"{name}, {group}, {label}"] = _value(values, label, group, metric)
        for label in baselines:
            base = {(m, g): _value(values, label, g, m) for g in groups for m in metrics}
            row[f"vs {label}"] = verdict(mine, base, seeds=seeds)
        rows.append(row)
    return pd.DataFrame(rows).set_index("variant" if seeds else "cell")


def _value(values: pd.DataFrame, method: str, group: str, metric: str) -> float:
    return float(values.loc[(method, group), metric]) if (method, group) in values.index else math.nan


def summary_lines(table: pd.DataFrame, baselines: Sequence[str], groups: Sequence[str],
                  metrics: Sequence[str] = VERDICT_METRICS) -> list[str]:
    """One line per baseline of a :func:`baselines_table`: 'every cell beats <label> on <metrics> on
    <groups>' or 'K of N cells do not beat <label>: <cell> (<verdict>); ...'."""
    names = " and ".join(get_metric(m).name for m in metrics)
    lines = []
    for label in baselines:
        column = table[f"vs {label}"]
        misses = column[column != BEATS]
        if (column == f"{NOT_RESOLVED}: {NO_SCORES}").all():
            lines.append(f"no verdict against {label}: {NO_SCORES} (not scored, or the cells have no scores)")
        elif misses.empty:
            lines.append(f"every cell beats {label} on {names} on {', '.join(groups)}")
        else:
            lines.append(f"{len(misses)} of {len(column)} cells do not beat {label}: "
                         + "; ".join(f"{cid} ({v})" for cid, v in misses.items()))
    return lines


def baselines_caption(metrics: Sequence[str] = VERDICT_METRICS, *, seeds: bool) -> str:
    """The rule of the verdict columns, in words."""
    how = ", ".join(f"{get_metric(m).name} ({get_metric(m).direction})" for m in metrics)
    rule = (f"'{BEATS}' = better than the baseline on each of {how} on every scene group (synthetic: the mean over its "
            "scenes)")
    if seeds:
        rule += (f"; with seeds, on each, the cell's {round(LEVEL * 100)} % t-interval over seeds (within the metric's "
                 "range) must lie wholly on the better side of the baseline's value (the baseline is deterministic); "
                 f"'{NOT_RESOLVED}' when the mean is better but the interval reaches the baseline")
    return rule
