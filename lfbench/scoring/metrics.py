"""Every metric by id: the process-wide registry :data:`METRICS` (:func:`get_metric`, ``METRICS.find``,
:func:`list_metrics`) and the one display order of metric ids (:func:`metric_order`).

The registry is assembled here from the definitions beside their functions: the general and runtime
metrics and the families ``badpix_<t>`` and ``q<p>_x100`` (:mod:`lfbench.scoring.general`), the region and
stratified metrics (:mod:`lfbench.scoring.region_metrics`). What a metric is: :class:`Metric`
(:mod:`lfbench.scoring.base`).

This module is also where the metric functions are imported from (``from lfbench.scoring.metrics import
bad_pix, mse_x100, q25_x100``): plain functions of ``(gt, pred, mask)`` arrays, disparity in px per view
step, :mod:`lfbench.scoring.general` documents their arithmetic and non-finite rules.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from lfbench.scoring.base import (
    ANY_VALUE,
    METRICS_GROUP,
    NON_NEGATIVE,
    PERCENT,
    SCENE_AGGREGATES,
    Metric,
    MetricRegistry,
)
from lfbench.scoring.general import (
    GENERAL_METRICS,
    RUNTIME_METRICS,
    BadPixels,
    bad_pix,
    bad_pix_curve,
    bad_pix_metric,
    mse_x100,
    nonfinite_count,
    q25_x100,
    quantile_x100,
)
from lfbench.scoring.pixelwise import Mean, OrderStatistic, PixelMetric, Proportion, Sample
from lfbench.utils.errors import DataError, SpecError

__all__ = [
    "bad_pix",
    "bad_pix_curve",
    "mse_x100",
    "q25_x100",
    "quantile_x100",
    "nonfinite_count",
    "bad_pix_metric",
    "quantile_metric",
    "BadPixels",
    "Metric",
    "PixelMetric",
    "Sample",
    "Proportion",
    "Mean",
    "OrderStatistic",
    "MetricRegistry",
    "METRICS",
    "SCENE_AGGREGATES",
    "GENERAL_METRICS",
    "RUNTIME_METRICS",
    "PERCENT",
    "NON_NEGATIVE",
    "ANY_VALUE",
    "get_metric",
    "list_metrics",
    "describe_metric",
    "scored_metrics",
    "metric_order",
    "badpix_threshold",
    "primary_metric",
]

#: The process-wide registry, filled from the entry-point group ``lfbench.metrics``: lfbench's own metrics first
#: (lfbench.scoring.builtin: the general and runtime metrics, the region metrics, the stratified metrics of each
#: stratified scene; the families ``badpix_<t>`` and ``q<p>_x100``), then the plugins'.
METRICS = MetricRegistry(group=METRICS_GROUP)


def quantile_metric(percentage: float) -> Metric:
    """The Quantile metric for any percentage 0 <= p < 100 (Q25 is ``quantile_metric(25)``)."""
    p = float(percentage)
    if not 0 <= p < 100:
        raise ValueError(f"quantile percentage must be from 0 to below 100, got {percentage}")
    return METRICS.get(f"q{p:g}_x100")


def get_metric(metric_id: str) -> Metric:
    """Any metric (general, region, stratified, ``badpix_<t>``) by its id or the toolkit's id.

    Raises SpecError "Unknown metric X. Available: ..." otherwise."""
    return METRICS.get(metric_id)


def list_metrics(category: str | None = None) -> tuple[Metric, ...]:
    """Every registered metric (optionally of one category: 'general', 'region', 'stratified')."""
    return METRICS.all(category)


def scored_metrics(ids: Iterable[str], source: str | Path | None = None, extra: Iterable[str] = ()) -> list[Metric]:
    """The metrics a run scores: exactly those of ``ids`` (a dataset protocol's), then those of ``extra`` (asked
    for on the command line: ``lfbench evaluate --metrics``), each once, in that order. An installed metric
    plugin is scored only where a protocol lists it or it is asked for. ``source``: the file that declared
    ``ids`` (a dataset's TOML file): an id there that is not a general metric is a DataError naming it. An id
    of ``extra`` that is not registered is a SpecError ``Unknown metric 'x'. Available: ...``; one that is not
    a general metric (a region, stratified or runtime metric) a SpecError saying so."""
    chosen: dict[str, Metric] = {}
    for metric_id in dict.fromkeys(ids):
        metric = METRICS.find(metric_id) if source is not None else get_metric(metric_id)
        if metric is None or metric.resolution != "scene" or metric.is_runtime:
            raise DataError(f"'protocol.metrics': {metric_id!r} is not a general metric (e.g. badpix_0.07, mse_x100, "
                            "q25_x100)", source)
        chosen.setdefault(metric.id, metric)
    general = [*(m.id for m in list_metrics("general")), *METRICS.family_patterns]
    for metric_id in dict.fromkeys(extra):
        metric = METRICS.find(metric_id)
        if metric is None:
            raise SpecError(f"--metrics: {METRICS.unknown(metric_id, general)}")
        if metric.resolution != "scene" or metric.is_runtime:
            raise SpecError(f"--metrics: {metric_id!r} is a {metric.category} metric (scored with --all-metrics "
                            f"where the scene supports it); --metrics takes general metrics: {', '.join(general)}")
        chosen.setdefault(metric.id, metric)
    return list(chosen.values())


def describe_metric(metric_id: str) -> Metric:
    """The metric an id names, for labels and directions in reports: the registered one, else
    :meth:`Metric.undefined` (the id as its name, no unit, lower is better)."""
    return METRICS.find(metric_id) or Metric.undefined(metric_id)


def _order(metric_id: str) -> int | None:
    metric = METRICS.find(metric_id)
    return metric.order if metric is not None and metric.id == metric_id else None


def metric_order(metric_ids: Iterable[str]) -> list[str]:
    """``metric_ids`` in the order tables and reports show them: the metrics that have a
    :attr:`Metric.order` first, by it (the paper's BadPix 0.07, 0.03, 0.01, MSE x100, Q25), each once;
    then the others in the order given."""
    ids = list(metric_ids)
    first = sorted(dict.fromkeys(m for m in ids if _order(m) is not None), key=_order)
    return first + [m for m in ids if m not in first]


def badpix_threshold(metric_id: str) -> float | None:
    """The threshold (px) of a general BadPix(t) metric by its definition (its pixel sample), else None."""
    m = METRICS.find(metric_id)
    sample = None if m is None or m.pixelwise is None else m.pixelwise.sample
    if isinstance(sample, BadPixels) and m.category == "general" and m.bootstrap is not None:
        return float(sample.threshold)
    return None


def primary_metric(metric_ids: Iterable[str]) -> str | None:
    """The one metric of a protocol (``metric_ids``: its metrics, e.g. lfbench.results.Results.protocol_metrics)
    that judges where one must: the BadPix maps and their captions, the best cell of an ablation, its orderings
    and its verdicts against baselines. It is the first BadPix(t) in table order (:func:`metric_order`: where
    the metrics have a table order, its first BadPix, BadPix(0.07) on HCI; else the protocol's first BadPix),
    else the first metric in that order; None for no metric."""
    ordered = metric_order(metric_ids)
    return next((m for m in ordered if badpix_threshold(m) is not None), ordered[0] if ordered else None)
