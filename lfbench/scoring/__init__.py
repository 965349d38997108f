"""Scoring, in layers (each module imports only those above it in this list):

- ``pixels``: the pixels a metric scores on a scene and a prediction's errors there, each computed once
  (:class:`~lfbench.scoring.pixels.PixelSet`, :class:`~lfbench.scoring.pixels.PixelErrors`): what the
  pixel-wise metrics compute from;
- ``resample``: the bootstrap's resampling engines (functions of arrays);
- ``pixelwise``: a pixel-wise metric's one definition (:class:`~lfbench.scoring.pixelwise.PixelMetric`: a sample
  of the pixel errors and the family that reduces and resamples it: proportion, mean, order statistic);
- ``base``: what a metric is (:class:`Metric`, the metric registry type);
- ``general``: the general metrics (BadPix, MSE, Q25 as functions of arrays) and their definitions;
- ``rules``: the benchmark's scoring rules (:class:`~lfbench.scoring.rules.ScoringRules`: border,
  resolution of each metric, non-finite rule, the high-resolution scenes);
- ``prepare``: the one preparation of a prediction for scoring and what a scene gives every prediction
  (:class:`~lfbench.scoring.prepare.SceneReference`, the scoring engine's per-scene cache, and
  :class:`~lfbench.scoring.prepare.Prepared`, its per-prediction half);
- ``region_metrics``: the region and stratified metrics and their definitions;
- ``metrics``: every metric by id (:data:`METRICS`, :func:`get_metric`, :func:`list_metrics`) and their
  display order (:func:`~lfbench.scoring.metrics.metric_order`); the metric functions are imported from here;
- ``score``: scoring a prediction on a scene (:func:`~lfbench.scoring.score.score_scene`) and every method's
  prediction on one scene with one reference (:func:`~lfbench.scoring.score.score_predictions`);
- ``stats``: bootstrap confidence intervals and paired tests; ``uncertainty``: the quality of
  uncertainty maps (sparsification, AUSE).

Everything here is a function of arrays and scenes; tables, figures and report files are lfbench.reports.
"""

from lfbench.scoring.metrics import METRICS, Metric, get_metric, list_metrics

__all__ = ["METRICS", "Metric", "get_metric", "list_metrics"]
