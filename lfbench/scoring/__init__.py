"""Scoring: the benchmark's general metrics and the one metric registry (metrics: :class:`Metric`,
:data:`METRICS`, :func:`get_metric`), region and stratified metrics (region_metrics), the scoring rules
that decide border and resolution (rules), bootstrap statistics (stats) and the quality of
uncertainty maps (uncertainty)."""

from lfbench.scoring.metrics import METRICS, Metric, get_metric, list_metrics

__all__ = ["METRICS", "Metric", "get_metric", "list_metrics"]
