"""Disparity-map metrics of the HCI 4D Light Field Benchmark, as pure functions of arrays.

All functions take ``gt`` and ``pred``: disparity in px per view step, (H, W) float arrays of the
same shape, and an optional boolean ``mask`` (H, W) of the pixels to score (None = all).
Arithmetic follows the official toolkit exactly: the difference is taken in the inputs' precision
(float32 for PFM data), MSE is the plain mean of squares, Q25 the element at index
``int(0.25 * n)`` of the sorted absolute errors.

Non-finite predictions (NaN, +-inf), default (``toolkit=False``): a bad pixel for BadPix, an
infinite error for Q25, left out of MSE (where no finite stand-in exists); count them with
:func:`nonfinite_count` and report it. ``toolkit=True`` reproduces the toolkit bit for bit,
including its inconsistency: BadPix counts NaN as good, MSE and Q25 drop non-finite pixels.
Pixels whose ground truth is non-finite are never scored (the toolkit's BadPix scores them as
good; ``toolkit=True`` does too).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "bad_pix",
    "bad_pix_curve",
    "mse_x100",
    "q25_x100",
    "quantile_x100",
    "nonfinite_count",
    "Metric",
    "GENERAL_METRICS",
    "metric_by_id",
]


def _prepare(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    gt = np.asarray(gt)
    pred = np.asarray(pred)
    if gt.shape != pred.shape:
        raise ValueError(f"gt {gt.shape} and pred {pred.shape} differ in shape")
    if mask is None:
        mask = np.ones(gt.shape, dtype=bool)
    else:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != gt.shape:
            raise ValueError(f"mask {mask.shape} and gt {gt.shape} differ in shape")
    dtype = np.result_type(gt.dtype, pred.dtype, np.float32)
    return gt.astype(dtype, copy=False), pred.astype(dtype, copy=False), mask


def _percentage(total: int, part: int) -> float:
    return float("nan") if total == 0 else 100.0 * part / float(total)


def nonfinite_count(pred: np.ndarray, mask: np.ndarray | None = None) -> int:
    """Number of NaN/inf predictions inside ``mask``."""
    bad = ~np.isfinite(np.asarray(pred))
    return int(np.count_nonzero(bad if mask is None else bad & np.asarray(mask, dtype=bool)))


def bad_pix(gt: np.ndarray, pred: np.ndarray, threshold: float = 0.07, mask: np.ndarray | None = None,
            *, toolkit: bool = False) -> float:
    """BadPix(t): percentage (0-100) of scored pixels with |gt - pred| > t (t in px)."""
    gt, pred, mask = _prepare(gt, pred, mask)
    with np.errstate(invalid="ignore"):
        err = np.abs(pred - gt)
    if toolkit:
        with np.errstate(invalid="ignore"):
            bad = err > threshold  # NaN compares False: counted as good
        return _percentage(int(np.count_nonzero(mask)), int(np.count_nonzero(bad & mask)))
    scored = mask & np.isfinite(gt)
    with np.errstate(invalid="ignore"):
        bad = (err > threshold) | ~np.isfinite(pred)
    return _percentage(int(np.count_nonzero(scored)), int(np.count_nonzero(bad & scored)))


def bad_pix_curve(gt: np.ndarray, pred: np.ndarray, thresholds: Sequence[float] | np.ndarray,
                  mask: np.ndarray | None = None) -> np.ndarray:
    """BadPix for many thresholds at once (one sort): float64 array of percentages."""
    gt, pred, mask = _prepare(gt, pred, mask)
    scored = mask & np.isfinite(gt)
    err = np.abs(pred - gt)[scored]
    err = np.where(np.isfinite(err), err, np.inf)
    err.sort()
    n = err.size
    t = np.asarray(thresholds, dtype=err.dtype if n else np.float64)
    if n == 0:
        return np.full(t.shape, np.nan)
    good = np.searchsorted(err, t, side="right")  # count of err <= t
    return 100.0 * (n - good) / float(n)


def mse_x100(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *, toolkit: bool = False) -> float:
    """100 x mean squared error (px^2) over scored pixels with finite gt and prediction."""
    gt, pred, mask = _prepare(gt, pred, mask)
    scored = mask & np.isfinite(gt) & np.isfinite(pred)
    if not scored.any():
        return float("nan")
    diff = np.square(gt - pred)[scored]
    # the toolkit (numpy 1.x) multiplied the float32 mean by 100 in float64; do the same under numpy 2
    return float(np.average(diff)) * 100


def quantile_x100(gt: np.ndarray, pred: np.ndarray, percentage: float = 25, mask: np.ndarray | None = None,
                  *, toolkit: bool = False) -> float:
    """100 x the absolute error at index int(n * percentage / 100) of the sorted errors (px x 100)."""
    gt, pred, mask = _prepare(gt, pred, mask)
    with np.errstate(invalid="ignore"):
        diffs = np.abs(pred - gt) * 100
    if toolkit:
        scored = mask & np.isfinite(diffs) & np.isfinite(pred)
    else:
        scored = mask & np.isfinite(gt)
        diffs = np.where(np.isfinite(pred), diffs, np.inf)
    values = np.sort(diffs[scored])
    if values.size == 0:
        return float("nan")
    return float(values[int(values.size * percentage / 100.0)])


def q25_x100(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *, toolkit: bool = False) -> float:
    """Q25: 100 x the 25th-percentile absolute error, the benchmark's definition."""
    return quantile_x100(gt, pred, 25, mask, toolkit=toolkit)


# --------------------------------------------------------------------------- metric descriptors

MetricFn = Callable[..., float]


@dataclass(frozen=True)
class Metric:
    """A metric with its id, description and plot settings.

    ``fn(gt, pred, mask, toolkit=...)`` returns the score. ``mask_name`` is the evaluation mask the
    metric needs (None = general metric, scored under the border mask); ``resolution`` is
    'scene' (the scene's rule), 'lowres' or 'highres'. Region / stratified metrics
    (lfbench.scoring.region_metrics) may also need ``extra_masks`` (further mask files the metric reads
    itself; it is skipped unless all exist) and, with ``needs_scene``, are called with the keywords
    ``scene`` and ``resolution`` too. ``category``: 'general', 'region' or 'stratified'.
    """

    id: str
    name: str
    description: str
    unit: str
    fn: MetricFn = field(repr=False, compare=False)
    toolkit_id: str | None = None
    mask_name: str | None = None
    resolution: str = "scene"
    vmin: float = 0.0
    vmax: float = 1.0
    cmap: str = "viridis"
    higher_is_better: bool = False
    category: str = "general"
    extra_masks: tuple[str, ...] = ()
    needs_scene: bool = False

    @property
    def required_masks(self) -> tuple[str, ...]:
        """Every mask file (``<name>_<resolution>.png``) the metric needs."""
        return ((self.mask_name,) if self.mask_name else ()) + self.extra_masks

    def __call__(self, gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *,
                 toolkit: bool = False, **context) -> float:
        return self.fn(gt, pred, mask, toolkit=toolkit, **context)


def _bad_pix_metric(t: float) -> Metric:
    def fn(gt, pred, mask=None, *, toolkit=False):
        return bad_pix(gt, pred, t, mask, toolkit=toolkit)

    return Metric(
        id=f"badpix_{t:g}", name=f"BadPix({t:g})",
        description=f"Percentage of pixels with |gt - pred| > {t:g} px (non-finite predictions count as bad).",
        unit="%", fn=fn, toolkit_id=("badpix_%0.3f" % t).replace(".", ""), vmin=0, vmax=1, cmap="RdYlGn_r",
    )


def _mse_metric() -> Metric:
    return Metric(
        id="mse_x100", name="MSE x100", description="Mean squared disparity error (px^2) multiplied by 100.",
        unit="px^2 x 100", fn=mse_x100, toolkit_id="mse_100", vmin=-0.2, vmax=0.2, cmap="seismic",
    )


def _q25_metric() -> Metric:
    return Metric(
        id="q25_x100", name="Q25", description="25th percentile of the absolute disparity error, x100.",
        unit="px x 100", fn=q25_x100, toolkit_id="q_25_100", vmin=0, vmax=0.5, cmap="YlOrRd",
    )


GENERAL_METRICS: tuple[Metric, ...] = (
    _bad_pix_metric(0.01), _bad_pix_metric(0.03), _bad_pix_metric(0.07), _mse_metric(), _q25_metric(),
)


def bad_pix_metric(threshold: float) -> Metric:
    """The BadPix metric for any threshold (px)."""
    return _bad_pix_metric(float(threshold))


def metric_by_id(metric_id: str) -> Metric:
    """A general metric by id; ``badpix_<t>`` works for any threshold t."""
    for m in GENERAL_METRICS:
        if metric_id in (m.id, m.toolkit_id):
            return m
    if metric_id.startswith("badpix_"):
        try:
            return bad_pix_metric(float(metric_id.split("_", 1)[1]))
        except ValueError:
            pass
    known = ", ".join(m.id for m in GENERAL_METRICS)
    raise KeyError(f"unknown metric {metric_id!r}; known: {known}, badpix_<t>")
