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

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from lfbench.utils.registry import Registry

__all__ = [
    "bad_pix",
    "bad_pix_curve",
    "mse_x100",
    "q25_x100",
    "quantile_x100",
    "nonfinite_count",
    "bad_pix_metric",
    "quantile_metric",
    "Metric",
    "PixelStatistic",
    "MetricRegistry",
    "METRICS",
    "SCENE_AGGREGATES",
    "GENERAL_METRICS",
    "RUNTIME_METRICS",
    "PERCENT",
    "NON_NEGATIVE",
    "get_metric",
    "find_metric",
    "list_metrics",
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


# --------------------------------------------------------------------------- metric definitions

MetricFn = Callable[..., float]

#: Value ranges (low, high) a metric declares: every value it can take lies in [low, high].
PERCENT: tuple[float, float] = (0.0, 100.0)
NON_NEGATIVE: tuple[float, float] = (0.0, math.inf)
ANY_VALUE: tuple[float, float] = (-math.inf, math.inf)

def _mean_of_finite(values: np.ndarray) -> float:
    v = values[~np.isnan(values)]
    return float(v.mean()) if v.size else float("nan")


#: How a metric's per-scene values are combined into one number per method (average tables, the
#: '(mean)' rows of CI tables): name -> reduction of a float64 array (NaN scenes are left out).
SCENE_AGGREGATES: dict[str, Callable[[np.ndarray], float]] = {"mean": _mean_of_finite}


@dataclass(frozen=True)
class PixelStatistic:
    """What a metric is as a statistic of the per-pixel errors, which is how it bootstraps.

    ``name``: 'badpix' (percentage of |error| > ``param`` px, non-finite = bad), 'mse' (100 x the mean
    squared error over finite errors) or 'quantile' (100 x the |error| at index int(n * ``param`` / 100)
    of the sorted errors). :mod:`lfbench.scoring.stats` resamples the per-pixel values accordingly.
    """

    name: str
    param: float = 0.0

    def __post_init__(self) -> None:
        if self.name not in ("badpix", "mse", "quantile"):
            raise ValueError(f"unknown pixel statistic {self.name!r}: badpix, mse or quantile")


@dataclass(frozen=True)
class Metric:
    """The one definition of a metric: what it computes, its unit and direction, how it is drawn,
    how its per-scene values aggregate and how it bootstraps.

    ``fn(gt, pred, mask, toolkit=...)`` returns the score in ``unit``. ``mask_name`` is the evaluation
    mask the metric needs (None = general metric, scored under the border mask); ``resolution`` is
    'scene' (the scene's rule), 'lowres' or 'highres'. Region / stratified metrics
    (lfbench.scoring.region_metrics) may also need ``extra_masks`` (further mask files the metric reads
    itself; it is skipped unless all exist) and, with ``needs_scene``, are called with the keywords
    ``scene`` and ``resolution`` too. ``category``: 'general', 'region' or 'stratified'.
    ``vmin``/``vmax``/``cmap``: plot settings. ``scene_aggregate``: a key of :data:`SCENE_AGGREGATES`.
    ``bootstrap``: the metric as a :class:`PixelStatistic` of the general scoring's per-pixel errors,
    or None when it cannot be resampled from them (region metrics score other pixels).
    ``value_range``: (low, high), every value the metric can take (e.g. (0, 100) for a percentage;
    infinite ends where it has no bound): it bounds regression tolerances and golden values.
    Category 'runtime' (:data:`RUNTIME_METRICS`): ``fn(runtime_s)`` of the runtime a method reports
    for a scene (no maps, no masks, no resolution of its own; see :func:`lfbench.scoring.rules.score_scene`).
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
    scene_aggregate: str = "mean"
    bootstrap: PixelStatistic | None = None
    value_range: tuple[float, float] = NON_NEGATIVE

    def __post_init__(self) -> None:
        if self.scene_aggregate not in SCENE_AGGREGATES:
            raise ValueError(f"metric {self.id!r}: unknown scene_aggregate {self.scene_aggregate!r}; "
                             f"use one of {', '.join(SCENE_AGGREGATES)}")
        low, high = self.value_range
        if math.isnan(low) or math.isnan(high) or not low < high:
            raise ValueError(f"metric {self.id!r}: value_range must be (low, high) with low < high, "
                             f"got {self.value_range}")

    @property
    def span(self) -> float:
        """high - low of :attr:`value_range` (inf when a side is unbounded): no change of the metric's
        value is larger, so a regression tolerance of this much or more accepts anything."""
        low, high = self.value_range
        return high - low

    @property
    def is_runtime(self) -> bool:
        """Scored from the runtime a method reports for a scene, not from its disparity map."""
        return self.category == "runtime"

    @property
    def lower_is_better(self) -> bool:
        return not self.higher_is_better

    @property
    def required_masks(self) -> tuple[str, ...]:
        """Every mask file (``<name>_<resolution>.png``) the metric needs."""
        return ((self.mask_name,) if self.mask_name else ()) + self.extra_masks

    def score_runtime(self, runtime_s: float | None) -> float | None:
        """A runtime metric's value for the runtime ``runtime_s`` (s) a method reports for a scene, or None
        (no record) when it reports none (None, NaN) or one that is not a positive finite number."""
        if not self.is_runtime:
            raise TypeError(f"metric {self.id!r} is scored from maps, not from a runtime")
        if runtime_s is None or not math.isfinite(runtime_s) or runtime_s <= 0:
            return None
        return float(self.fn(runtime_s))

    def aggregate(self, values: Sequence[float] | np.ndarray) -> float:
        """The per-scene ``values`` combined as the metric says (NaN scenes left out)."""
        return SCENE_AGGREGATES[self.scene_aggregate](np.asarray(values, dtype=np.float64))

    def __call__(self, gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *,
                 toolkit: bool = False, **context) -> float:
        if self.is_runtime:
            raise TypeError(f"metric {self.id!r} is scored from a runtime (score_runtime), not from maps")
        return self.fn(gt, pred, mask, toolkit=toolkit, **context)


class MetricRegistry(Registry[Metric]):
    """Every metric by id (and by the toolkit's id), plus parametrised families such as ``badpix_<t>``: the
    generic :class:`~lfbench.utils.registry.Registry` of :class:`Metric`.

    ``register`` refuses anything but a :class:`Metric` and a second metric under a taken id;
    ``get`` raises :class:`~lfbench.utils.errors.SpecError` "Unknown metric X. Available: ...".
    """

    def __init__(self) -> None:
        super().__init__("metric", Metric)
        self._families: list[tuple[str, Callable[[str], Metric | None]]] = []

    def register(self, metric: Metric) -> Metric:
        self.check(str(getattr(metric, "id", "?")), metric)
        self.add(metric.id, metric, aliases=(metric.toolkit_id,) if metric.toolkit_id else ())
        return metric

    def register_family(self, pattern: str, make: Callable[[str], Metric | None]) -> None:
        """A parametrised family: ``make(id)`` returns the metric for an id it understands, else None;
        ``pattern`` (e.g. 'badpix_<t>') is what the 'Available' list shows."""
        self._families.append((pattern, make))

    def find(self, metric_id: str) -> Metric | None:
        """The metric with this id or toolkit id (or from a family), or None."""
        metric = super().find(str(metric_id))
        if metric is not None:
            return metric
        for _, make in self._families:
            metric = make(str(metric_id))
            if metric is not None:
                return metric
        return None

    def get(self, metric_id: str) -> Metric:
        metric = self.find(metric_id)
        if metric is None:
            raise self.unknown(metric_id, [*self.registered(), *(p for p, _ in self._families)])
        return metric

    def all(self, category: str | None = None) -> tuple[Metric, ...]:
        """The registered metrics (families excluded), in registration order, optionally of one category."""
        return tuple(m for m in map(self.get, self.registered()) if category is None or m.category == category)


def _bad_pix_metric(t: float) -> Metric:
    def fn(gt, pred, mask=None, *, toolkit=False):
        return bad_pix(gt, pred, t, mask, toolkit=toolkit)

    return Metric(
        id=f"badpix_{t:g}", name=f"BadPix({t:g})",
        description=f"Percentage of pixels with |gt - pred| > {t:g} px (non-finite predictions count as bad).",
        unit="%", fn=fn, toolkit_id=("badpix_%0.3f" % t).replace(".", ""), vmin=0, vmax=1, cmap="RdYlGn_r",
        bootstrap=PixelStatistic("badpix", t), value_range=PERCENT,
    )


def _mse_metric() -> Metric:
    return Metric(
        id="mse_x100", name="MSE x100", description="Mean squared disparity error (px^2) multiplied by 100.",
        unit="px^2 x 100", fn=mse_x100, toolkit_id="mse_100", vmin=-0.2, vmax=0.2, cmap="seismic",
        bootstrap=PixelStatistic("mse"),
    )


def _ordinal(p: float) -> str:
    if p != int(p):
        return f"{p:g}th"
    n = int(p)
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def _quantile_metric(p: float) -> Metric:
    """Quantile(p): 100 x the |error| at index int(n * p / 100) of the n sorted errors, 0 <= p < 100."""
    def fn(gt, pred, mask=None, *, toolkit=False):
        return quantile_x100(gt, pred, p, mask, toolkit=toolkit)

    return Metric(
        id=f"q{p:g}_x100", name=f"Q{p:g}",
        description=f"{_ordinal(p)} percentile of the absolute disparity error, x100.",
        unit="px x 100", fn=fn, toolkit_id=f"q_{p:g}_100" if p == int(p) else None, vmin=0, vmax=0.5,
        cmap="YlOrRd", bootstrap=PixelStatistic("quantile", p),
    )


def _q25_metric() -> Metric:
    return Metric(
        id="q25_x100", name="Q25", description="25th percentile of the absolute disparity error, x100.",
        unit="px x 100", fn=q25_x100, toolkit_id="q_25_100", vmin=0, vmax=0.5, cmap="YlOrRd",
        bootstrap=PixelStatistic("quantile", 25.0),
    )


GENERAL_METRICS: tuple[Metric, ...] = (
    _bad_pix_metric(0.01), _bad_pix_metric(0.03), _bad_pix_metric(0.07), _mse_metric(), _q25_metric(),
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

#: The process-wide registry: the general and runtime metrics here, the region and stratified ones from
#: :mod:`lfbench.scoring.region_metrics` (registered when :func:`get_metric` first needs them), and the
#: families ``badpix_<t>`` and ``q<p>_x100``.
METRICS = MetricRegistry()
for _m in GENERAL_METRICS + RUNTIME_METRICS:
    METRICS.register(_m)


def _badpix_family(metric_id: str) -> Metric | None:
    """``badpix_<t>`` for any threshold t in px ('badpix_0.04'); the toolkit's 'badpix_0040' is t x 1000."""
    if not metric_id.startswith("badpix_"):
        return None
    text = metric_id.split("_", 1)[1]
    try:
        t = float(text) if "." in text or not text.isdigit() else int(text) / 1000.0
    except ValueError:
        return None
    return _bad_pix_metric(t) if np.isfinite(t) and t >= 0 else None


_QUANTILE_ID = re.compile(r"q(?P<p>\d{1,2}(?:\.\d{1,6})?)_x100|q_(?P<tk>\d{1,2})_100")


def _quantile_family(metric_id: str) -> Metric | None:
    """``q<p>_x100`` for a percentage 0 <= p < 100 ('q50_x100', 'q2.5_x100'); the toolkit's 'q_50_100'."""
    m = _QUANTILE_ID.fullmatch(metric_id)
    if m is None:
        return None
    p = float(m["p"] if m["p"] is not None else m["tk"])
    return _quantile_metric(p) if f"q{p:g}_x100" == metric_id or m["tk"] is not None else None


METRICS.register_family("badpix_<t>", _badpix_family)
METRICS.register_family("q<p>_x100", _quantile_family)


def bad_pix_metric(threshold: float) -> Metric:
    """The BadPix metric for any threshold (px)."""
    return _bad_pix_metric(float(threshold))


def quantile_metric(percentage: float) -> Metric:
    """The Quantile metric for any percentage 0 <= p < 100 (Q25 is ``quantile_metric(25)``)."""
    p = float(percentage)
    if not 0 <= p < 100:
        raise ValueError(f"quantile percentage must be from 0 to below 100, got {percentage}")
    return METRICS.get(f"q{p:g}_x100")


def _registry() -> MetricRegistry:
    import lfbench.scoring.region_metrics  # noqa: F401  (registers the region and stratified metrics)

    return METRICS


def get_metric(metric_id: str) -> Metric:
    """Any metric (general, region, stratified, ``badpix_<t>``) by its id or the toolkit's id.

    Raises SpecError "Unknown metric X. Available: ..." otherwise."""
    return _registry().get(metric_id)


def find_metric(metric_id: str) -> Metric | None:
    """Like :func:`get_metric`, but None for an unknown id (e.g. a plugin's own column)."""
    return _registry().find(metric_id)


def list_metrics(category: str | None = None) -> tuple[Metric, ...]:
    """Every registered metric (optionally of one category: 'general', 'region', 'stratified')."""
    return _registry().all(category)
