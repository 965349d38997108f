"""The general metrics of the HCI 4D Light Field Benchmark, as pure functions of arrays, and their definitions.

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

Their :class:`~lfbench.scoring.base.Metric` definitions: :data:`GENERAL_METRICS` (BadPix 0.01 / 0.03 / 0.07,
MSE x100, Q25, in the paper's table order 0.07, 0.03, 0.01, MSE, Q25), :data:`RUNTIME_METRICS` and the
families ``badpix_<t>`` (:func:`badpix_family`) and ``q<p>_x100`` (:func:`quantile_family`), registered by
:mod:`lfbench.scoring.metrics`. :func:`check_maps` is the input check every metric function starts with.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lfbench.scoring.base import ANY_VALUE, PERCENT, Metric
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.pixelwise import Mean, OrderStatistic, PixelMetric, Proportion, Sample, kept
from lfbench.scoring.policy import LFBENCH

__all__ = [
    "BadPixels",
    "GENERAL_METRICS",
    "RUNTIME_METRICS",
    "abs_error_x100",
    "bad_pix",
    "bad_pix_curve",
    "bad_pix_metric",
    "bad_pix_of",
    "badpix_family",
    "check_maps",
    "mse_x100",
    "mse_x100_of",
    "nonfinite_count",
    "percent_of",
    "q25_x100",
    "quantile_family",
    "quantile_x100",
    "quantile_x100_of",
    "squared_error",
]


def check_maps(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(gt, pred, mask)`` as every metric takes them: ``gt`` and ``pred`` (H, W) of one shape in their common
    precision (at least float32, no copy when they have it already), ``mask`` bool (H, W) (all True for None).
    ValueError when the shapes differ."""
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


def percent_of(total: int, part: int) -> float:
    """100 x part / total (NaN when nothing was scored)."""
    return float("nan") if total == 0 else 100.0 * part / float(total)


def nonfinite_count(pred: np.ndarray, mask: np.ndarray | None = None) -> int:
    """Number of NaN/inf predictions inside ``mask``."""
    bad = ~np.isfinite(np.asarray(pred))
    return int(np.count_nonzero(bad if mask is None else bad & np.asarray(mask, dtype=bool)))


def bad_pix(gt: np.ndarray, pred: np.ndarray, threshold: float = 0.07, mask: np.ndarray | None = None,
            *, toolkit: bool = False) -> float:
    """BadPix(t): percentage (0-100) of scored pixels with |gt - pred| > t (t in px)."""
    return bad_pix_of(PixelErrors.of_maps(gt, pred, mask), threshold, toolkit=toolkit)


@dataclass(frozen=True)
class BadPixels:
    """BadPix(``threshold``)'s sample: whether each scored pixel is bad, |error| > threshold px (compared in the
    errors' precision). Default: non-finite predictions are bad, pixels with non-finite ground truth are not
    scored; ``toolkit``: every pixel is scored and NaN is good (the toolkit's comparison)."""

    threshold: float

    def __call__(self, px: PixelErrors, *, toolkit: bool = False) -> Sample:
        if px.scorer is not LFBENCH:  # a protocol's own scorer (lfbench.scoring.policy)
            with np.errstate(invalid="ignore"):
                bad = px.err >= self.threshold if px.scorer.inclusive else px.err > self.threshold
            if px.scorer.nan_good:
                return Sample(bad)
            return kept(bad | ~px.pred_finite, px.gt_finite)
        with np.errstate(invalid="ignore"):
            bad = px.err > self.threshold  # NaN compares False
        if toolkit:  # counted as good
            return Sample(bad)
        if not px.pred_all_finite:
            bad |= ~px.pred_finite
        return Sample(bad) if px.gt_all_finite else kept(bad, px.gt_finite)


def bad_pix_of(px: PixelErrors, threshold: float = 0.07, *, toolkit: bool = False) -> float:
    """:func:`bad_pix` of the errors ``px`` (lfbench.scoring.pixels) at the pixels they hold."""
    return PixelMetric(BadPixels(threshold), Proportion())(px, toolkit=toolkit)


def bad_pix_curve(gt: np.ndarray, pred: np.ndarray, thresholds: Sequence[float] | np.ndarray,
                  mask: np.ndarray | None = None) -> np.ndarray:
    """BadPix for many thresholds at once (one sort): float64 array of percentages."""
    gt, pred, mask = check_maps(gt, pred, mask)
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
    return mse_x100_of(PixelErrors.of_maps(gt, pred, mask), toolkit=toolkit)


def squared_error(px: PixelErrors, *, toolkit: bool = False) -> Sample:
    """MSE's sample: the squared error (px^2, |e|^2 = e^2 exactly) of the pixels with finite ground truth and
    prediction (one rule in both modes: no finite stand-in for a non-finite error exists)."""
    if px.scorer.nan_good:  # every pixel, as computed: a NaN error makes the mean NaN (lfbench.scoring.policy)
        return Sample(np.square(px.err), None)
    if px.gt_all_finite and px.pred_all_finite:
        return Sample(np.square(px.err), None)
    scored = px.finite  # some value is not finite here
    return Sample(np.square(px.err[scored]), scored)


# MSE x100: the toolkit (numpy 1.x) multiplied the float32 mean by 100 in float64; :class:`Mean` does the same
_MSE = PixelMetric(squared_error, Mean(100.0))


def mse_x100_of(px: PixelErrors, *, toolkit: bool = False) -> float:
    """:func:`mse_x100` of the errors ``px`` at the pixels they hold."""
    return _MSE(px, toolkit=toolkit)


def quantile_x100(gt: np.ndarray, pred: np.ndarray, percentage: float = 25, mask: np.ndarray | None = None,
                  *, toolkit: bool = False) -> float:
    """100 x the absolute error at index int(n * percentage / 100) of the sorted errors (px x 100)."""
    return quantile_x100_of(PixelErrors.of_maps(gt, pred, mask), percentage, toolkit=toolkit)


def abs_error_x100(px: PixelErrors, *, toolkit: bool = False) -> Sample:
    """The quantiles' sample: 100 x |error| (px x 100). Default: a non-finite prediction is an infinite error,
    pixels with non-finite ground truth are not scored; ``toolkit``: non-finite errors are left out."""
    with np.errstate(over="ignore"):
        diffs = px.err * 100
    if toolkit:
        return kept(diffs, np.isfinite(diffs) & px.pred_finite)
    diffs = diffs if px.pred_all_finite else np.where(px.pred_finite, diffs, np.inf)
    return Sample(diffs) if px.gt_all_finite else kept(diffs, px.gt_finite)


def quantile_x100_of(px: PixelErrors, percentage: float = 25, *, toolkit: bool = False) -> float:
    """:func:`quantile_x100` of the errors ``px`` at the pixels they hold (the element at that index of
    the sorted errors, found by a partition: the same value as a full sort's)."""
    return PixelMetric(abs_error_x100, OrderStatistic(float(percentage)))(px, toolkit=toolkit)


def q25_x100(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *, toolkit: bool = False) -> float:
    """Q25: 100 x the 25th-percentile absolute error, the benchmark's definition."""
    return quantile_x100(gt, pred, 25, mask, toolkit=toolkit)


# --------------------------------------------------------------------------- definitions

def bad_pix_metric(threshold: float, *, order: int | None = None) -> Metric:
    """The BadPix metric for any threshold (px); ``order``: its place in tables (the paper's three have one)."""
    t = float(threshold)
    return Metric(
        id=f"badpix_{t:g}", name=f"BadPix({t:g})",
        description=f"Percentage of pixels with |gt - pred| > {t:g} px (non-finite predictions count as bad).",
        unit="%", pixelwise=PixelMetric(BadPixels(t), Proportion()), toolkit_id=("badpix_%0.3f" % t).replace(".", ""),
        vmin=0, vmax=1, cmap="RdYlGn_r", value_range=PERCENT, short_label=f"BadPix {t:g} (%)", order=order,
    )


def _mse_metric() -> Metric:
    return Metric(
        id="mse_x100", name="MSE x100", description="Mean squared disparity error (px^2) multiplied by 100.",
        unit="px^2 x 100", pixelwise=_MSE, toolkit_id="mse_100", vmin=-0.2, vmax=0.2, cmap="seismic",
        short_label="MSE x100", order=3,
    )


def _ordinal(p: float) -> str:
    if p != int(p):
        return f"{p:g}th"
    n = int(p)
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def _quantile_metric(p: float, *, name: str | None = None, order: int | None = None) -> Metric:
    """Quantile(p): 100 x the |error| at index int(n * p / 100) of the n sorted errors, 0 <= p < 100."""
    return Metric(
        id=f"q{p:g}_x100", name=name or f"Q{p:g}",
        description=f"{_ordinal(p)} percentile of the absolute disparity error, x100.",
        unit="px x 100", pixelwise=PixelMetric(abs_error_x100, OrderStatistic(float(p))),
        toolkit_id=f"q_{p:g}_100" if p == int(p) else None, vmin=0, vmax=0.5, cmap="YlOrRd", order=order,
    )


#: The benchmark's general metrics (registration order); ``order`` puts them in the paper's table order.
GENERAL_METRICS: tuple[Metric, ...] = (
    bad_pix_metric(0.01, order=2), bad_pix_metric(0.03, order=1), bad_pix_metric(0.07, order=0), _mse_metric(),
    _quantile_metric(25.0, order=4),
)


def _runtime_s(runtime_s: float) -> float:
    """The runtime in s, as reported."""
    return float(runtime_s)


def _runtime_log10(runtime_s: float) -> float:
    """log10 of the runtime in s (negative below 1 s)."""
    return math.log10(runtime_s)


#: The toolkit's runtime metrics: the runtime a method reports for a scene (a submission's
#: runtimes/<scene>.txt, or the wall time lfbench measured around ``predict``), not scored from maps.
RUNTIME_METRICS: tuple[Metric, ...] = (
    Metric(id="runtime", name="Runtime", description="The runtime in seconds, as the method reports it.",
           unit="s", fn=_runtime_s, toolkit_id="runtime", category="runtime", vmin=0, vmax=1, cmap="YlOrRd"),
    Metric(id="runtime_log", name="Runtime (log10)",
           description="Decadic logarithm of the runtime in seconds, as the method reports it (negative below 1 s).",
           unit="log10 s", fn=_runtime_log10, toolkit_id="runtime_log", category="runtime", vmin=0, vmax=1,
           cmap="YlOrRd", value_range=ANY_VALUE),
)


def badpix_family(metric_id: str) -> Metric | None:
    """``badpix_<t>`` for any threshold t >= 0 in px, spelled as the metric's id spells it (``f"badpix_{t:g}"``:
    'badpix_0.04', 'badpix_0.1', 'badpix_0.015'), or the toolkit's id of it ('badpix_0040': t x 1000, as
    ``"%0.3f"`` writes it). Any other spelling of a threshold ('badpix_0.0700', 'badpix_ 0.07', 'badpix_.07',
    non-ASCII digits) is no id (None): one spelling per metric, so that records under another one are
    refused as an unknown metric rather than read as a metric of their own."""
    if not (metric_id.startswith("badpix_") and metric_id.isascii()):
        return None
    text = metric_id.split("_", 1)[1]
    if text.isdigit():  # the toolkit's id ('badpix_0070'), else a whole threshold ('badpix_1')
        metric = bad_pix_metric(int(text) / 1000.0)
        if metric.toolkit_id == metric_id:
            return metric
    try:
        t = float(text)
    except ValueError:
        return None
    if not (np.isfinite(t) and t >= 0) or text.startswith("-"):
        return None
    metric = bad_pix_metric(t)
    return metric if metric.id == metric_id else None


_QUANTILE_ID = re.compile(r"q(?P<p>\d{1,2}(?:\.\d{1,6})?)_x100|q_(?P<tk>\d{1,2})_100", re.ASCII)


def quantile_family(metric_id: str) -> Metric | None:
    """``q<p>_x100`` for a percentage 0 <= p < 100 spelled as the metric's id spells it (``f"q{p:g}_x100"``:
    'q50_x100', 'q12.5_x100'), or the toolkit's id of a whole percentage ('q_50_100'); any other spelling
    ('q050_x100', 'q50.0_x100', 'q_05_100', non-ASCII digits) is no id (None)."""
    m = _QUANTILE_ID.fullmatch(metric_id)
    if m is None:
        return None
    p = float(m["p"] if m["p"] is not None else m["tk"])
    metric = _quantile_metric(p)
    return metric if metric_id in (metric.id, metric.toolkit_id) else None
