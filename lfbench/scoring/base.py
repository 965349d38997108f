"""What a metric is: :class:`Metric` (the one definition of a metric: what it computes, its unit,
direction, label and display order, plot settings, how it aggregates over scenes and how it bootstraps)
and :class:`MetricRegistry` (the generic registry of metrics). A pixel-wise metric computes through its
:class:`~lfbench.scoring.pixelwise.PixelMetric` (lfbench.scoring.pixelwise), from which its function of maps
and its bootstrap derive.

The metrics themselves are defined beside their functions (:mod:`lfbench.scoring.general`,
:mod:`lfbench.scoring.region_metrics`) and registered in :mod:`lfbench.scoring.metrics`; the scoring
rules (:mod:`lfbench.scoring.rules`) need only this type.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from lfbench.scoring.pixelwise import Family, OnMaps, PixelMetric, plugin_failure
from lfbench.utils.errors import LFBenchError, SpecError
from lfbench.utils.registry import NameTaken, Registry

__all__ = [
    "ANY_VALUE",
    "BUILTIN_METRICS",
    "METRICS_GROUP",
    "Metric",
    "MetricFn",
    "MetricRegistry",
    "NON_NEGATIVE",
    "PERCENT",
    "SCENE_AGGREGATES",
]

MetricFn = Callable[..., float]
#: The entry-point group of metrics, and lfbench's own entry point's module (its built-in metrics).
METRICS_GROUP = "lfbench.metrics"
BUILTIN_METRICS = "lfbench.scoring.builtin"

#: Value ranges (low, high) a metric declares: every value it can take lies in [low, high].
PERCENT: tuple[float, float] = (0.0, 100.0)
NON_NEGATIVE: tuple[float, float] = (0.0, math.inf)
ANY_VALUE: tuple[float, float] = (-math.inf, math.inf)


def _not_defined(*args, **kwargs) -> float:
    raise TypeError("this metric id is not defined by lfbench: it has nothing to compute")


def _mean_of_finite(values: np.ndarray) -> float:
    v = values[~np.isnan(values)]
    return float(v.mean()) if v.size else float("nan")


#: How a metric's per-scene values are combined into one number per method (average tables, the
#: '(mean)' rows of CI tables): name -> reduction of a float64 array (NaN scenes are left out).
SCENE_AGGREGATES: dict[str, Callable[[np.ndarray], float]] = {"mean": _mean_of_finite}


@dataclass(frozen=True)
class Metric:
    """The one definition of a metric: what it computes, its unit and direction, its label and place in
    tables, how it is drawn, how its per-scene values aggregate and how it bootstraps.

    ``pixelwise``: a pixel-wise metric's one definition (:class:`~lfbench.scoring.pixelwise.PixelMetric`: a
    sample of per-pixel values of the prediction's errors at the pixels of ``mask_name`` inside the evaluation
    mask, and the family that reduces and resamples it), for metrics that depend only on those pixels' values:
    scoring then gathers each prediction once per set of pixels and computes |error| once for all of its metrics
    (:func:`lfbench.scoring.score.score_scene`), ``fn`` is derived from it
    (:class:`~lfbench.scoring.pixelwise.OnMaps`) and :attr:`bootstrap` is its family. None: ``fn`` is the
    definition. ``fn(gt, pred, mask, toolkit=...)`` returns the score in ``unit``. ``mask_name`` is the evaluation
    mask the metric needs (None = general metric, scored under the border mask); ``resolution`` is
    'scene' (the scene's rule), 'lowres' or 'highres'. Region / stratified metrics
    (lfbench.scoring.region_metrics) may also need ``extra_masks`` (further mask files the metric reads
    itself; it is skipped unless all exist) and, with ``needs_scene``, are called with the keywords
    ``scene`` and ``resolution`` too: scoring passes the scene's
    :class:`~lfbench.scoring.prepare.SceneReference`, which answers ``name``, ``path``, ``params``,
    ``spatial_size``, ``mask`` and ``mask_names`` as the scene does, from its caches (the scene itself
    is its ``.scene``). ``category``: 'general', 'region' or 'stratified'.
    ``vmin``/``vmax``/``cmap``: plot settings. ``scene_aggregate``: a key of :data:`SCENE_AGGREGATES`.
    ``value_range``: (low, high), every value the metric can take (e.g. (0, 100) for a percentage;
    infinite ends where it has no bound): it bounds regression tolerances and golden values.
    ``short_label``: the header of a table column that holds the metric with its unit ('BadPix 0.07 (%)'
    in the ablation and sweep tables; None: the name, see :attr:`label`). ``order``: the metric's place
    in tables and reports: metrics with an order come first, by it (the paper's BadPix 0.07, 0.03,
    0.01, MSE x100, Q25), the others after them in the order they come
    (:func:`lfbench.scoring.metrics.metric_order`).
    ``higher_is_better`` / ``signed``: the metric's direction (:attr:`direction`): lower values are better (the
    default), higher ones, or, for a ``signed`` metric (a bias: mean signed error), values closer to 0; rankings,
    the regression gate and ablation verdicts compare :meth:`badness` (the value, its negative, or its magnitude).
    Category 'runtime' (:data:`lfbench.scoring.general.RUNTIME_METRICS`): ``fn(runtime_s)`` of the runtime
    a method reports for a scene (no maps, no masks, no resolution of its own; see
    :func:`lfbench.scoring.score.score_scene`).
    """

    id: str
    name: str
    description: str
    unit: str
    fn: MetricFn | None = field(default=None, repr=False, compare=False)
    toolkit_id: str | None = None
    mask_name: str | None = None
    resolution: str = "scene"
    vmin: float = 0.0
    vmax: float = 1.0
    cmap: str = "viridis"
    higher_is_better: bool = False
    signed: bool = False
    category: str = "general"
    extra_masks: tuple[str, ...] = ()
    needs_scene: bool = False
    scene_aggregate: str = "mean"
    value_range: tuple[float, float] = NON_NEGATIVE
    short_label: str | None = None
    order: int | None = None
    pixelwise: PixelMetric | None = None

    def __post_init__(self) -> None:
        if self.fn is None:
            if self.pixelwise is None:
                raise ValueError(f"metric {self.id!r}: give fn or pixelwise, what it computes")
            object.__setattr__(self, "fn", OnMaps(self.pixelwise))
        if self.scene_aggregate not in SCENE_AGGREGATES:
            raise ValueError(f"metric {self.id!r}: unknown scene_aggregate {self.scene_aggregate!r}; "
                             f"use one of {', '.join(SCENE_AGGREGATES)}")
        low, high = self.value_range
        if math.isnan(low) or math.isnan(high) or not low < high:
            raise ValueError(f"metric {self.id!r}: value_range must be (low, high) with low < high, "
                             f"got {self.value_range}")
        if self.signed and (self.higher_is_better or not low < 0 < high):
            raise ValueError(f"metric {self.id!r}: a signed metric is best at 0 (not higher_is_better) and its "
                             f"value_range holds values on both sides of 0, got {self.value_range}")

    @classmethod
    def undefined(cls, metric_id: str) -> Metric:
        """What lfbench can say about a metric id it does not define (e.g. a plugin's own results column):
        named by its id, no unit or description, lower is better; it cannot be computed."""
        return cls(id=metric_id, name=metric_id, description="", unit="", fn=_not_defined, category="undefined")

    @property
    def label(self) -> str:
        """The metric's table-column header: :attr:`short_label`, else its name."""
        return self.short_label or self.name

    @property
    def span(self) -> float:
        """high - low of :attr:`value_range` (inf when a side is unbounded): no change of the metric's
        value is larger, so a regression tolerance of this much or more accepts anything."""
        low, high = self.value_range
        return high - low

    @property
    def bootstrap(self) -> Family | None:
        """How the metric resamples (its pixel-wise family) from the per-pixel errors of the general scoring
        (:mod:`lfbench.scoring.stats`), or None when it cannot be resampled from them: not pixel-wise, scored
        on other pixels (a mask of its own, further masks or its scene) or reading more than the errors."""
        p = self.pixelwise
        if p is None or not p.of_errors or self.mask_name is not None or self.extra_masks or self.needs_scene:
            return None
        return p.family

    @property
    def is_runtime(self) -> bool:
        """Scored from the runtime a method reports for a scene, not from its disparity map."""
        return self.category == "runtime"

    @property
    def lower_is_better(self) -> bool:
        return not self.higher_is_better and not self.signed

    @property
    def direction(self) -> str:
        """What is better, as pages and captions say it: 'lower is better', 'higher is better' or, for a
        :attr:`signed` metric, 'closer to 0 is better'."""
        if self.signed:
            return "closer to 0 is better"
        return "higher is better" if self.higher_is_better else "lower is better"

    def badness(self, value: float) -> float:
        """``value`` on a scale where lower is better (rankings, the regression gate, verdicts): the value, its
        negative where higher is better, its magnitude for a :attr:`signed` metric (NaN stays NaN)."""
        value = float(value)
        if self.signed:
            return abs(value)
        return -value if self.higher_is_better else value

    def worst_end(self, low: float, high: float) -> float:
        """The end of an interval [low, high] of this metric's values that is worse (:meth:`badness`): ``high``
        where lower is better, ``low`` where higher is better, the one farther from 0 for a signed metric."""
        if not self.signed:
            return low if self.higher_is_better else high
        return low if abs(low) > abs(high) else high

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
        fn = self.fn
        if isinstance(fn, OnMaps) or str(getattr(fn, "__module__", "")).split(".")[0] == "lfbench":
            return fn(gt, pred, mask, toolkit=toolkit, **context)
        name = f"{self.id!r} ({getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', type(fn).__name__)})"
        try:  # a plugin's function of maps: one line naming it for whatever it raises or returns
            value = fn(gt, pred, mask, toolkit=toolkit, **context)
        except LFBenchError:
            raise
        except Exception as exc:  # noqa: BLE001 - whatever the plugin's code raised
            raise plugin_failure(name, exc) from None
        if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
            raise LFBenchError(f"metric plugin {name} returned a {type(value).__name__}, expected a number")
        return float(value)

    def score_pixels(self, px, *, toolkit: bool = False) -> float:
        """The metric of the errors ``px`` (:class:`~lfbench.scoring.pixels.PixelErrors`) through
        :attr:`pixelwise` (TypeError for a metric without one)."""
        if self.pixelwise is None:
            raise TypeError(f"metric {self.id!r} is not pixel-wise: score it from maps")
        return self.pixelwise(px, toolkit=toolkit)


class MetricRegistry(Registry[Metric]):
    """Every metric by id (and by the toolkit's id), plus parametrised families such as ``badpix_<t>``: the
    generic :class:`~lfbench.utils.registry.Registry` of :class:`Metric`.

    ``register`` refuses anything but a :class:`Metric` and a second metric under a taken id;
    ``get`` raises :class:`~lfbench.utils.errors.SpecError` "Unknown metric X. Available: ...".
    ``group``: the entry-point group whose plugins fill it (``lfbench.metrics``: the built-in metrics come
    through it as a plugin's do). An entry point names a module (importing it registers its metrics) or a
    :class:`Metric` (registered under its id, which must be the entry point's name); lfbench's own entry
    points load first, so that the benchmark's metrics keep their order.
    """

    def __init__(self, group: str | None = None) -> None:
        # lfbench's own metrics load first (the benchmark's order), even where an install's metadata is older
        # than the group (e.g. a stale lfbench.egg-info beside the sources)
        super().__init__("metric", Metric, group=group,
                         builtins={"hci": BUILTIN_METRICS} if group == METRICS_GROUP else None)
        self._families: list[tuple[str, Callable[[str], Metric | None]]] = []
        self._refused: SpecError | None = None  # a plugin's id collision (name_taken)

    def register(self, metric: Metric) -> Metric:
        self.check(str(getattr(metric, "id", "?")), metric)
        self.add(metric.id, metric)
        return metric

    def add(self, name: str, obj, *, entry=None, aliases: tuple[str, ...] = ()) -> None:
        """:meth:`Registry.add`, with the metric's toolkit id as an alias; ValueError when ``name`` is not
        the metric's id (an entry point named otherwise than its metric)."""
        if isinstance(obj, Metric):
            if name != obj.id:
                raise ValueError(f"metric {obj.id!r} registered as {name!r}: the name must be the metric's id")
            aliases = aliases or ((obj.toolkit_id,) if obj.toolkit_id else ())
            for key in (name, *aliases):
                for pattern, make in self._families:
                    if make(key) is not None:
                        raise NameTaken(f"metric {key!r} is already defined by the family {pattern} "
                                        f"({getattr(make, '__module__', '?')})")
        super().add(name, obj, entry=entry, aliases=aliases)

    def name_taken(self, ep, exc: NameTaken) -> None:
        """A metric plugin that registers an id another metric has is refused loudly (SpecError naming the
        plugin and the metric it would shadow, raised by every later lookup too), never a silent replacement
        of a number in every table."""
        self._refused = SpecError(f"metric plugin {ep.name!r} ({ep.value}) refused: {exc}")
        raise self._refused

    def _load_entry_point(self, ep) -> None:
        before = self._objects.get(ep.name)
        super()._load_entry_point(ep)
        if before is None or ep.name in self.builtins:
            return
        try:  # the generic loader skips an entry point whose name is taken: a Metric under it is a collision
            obj = ep.load()
        except Exception:  # noqa: BLE001 - recorded in load_errors by the generic loader
            return
        if isinstance(obj, Metric) and not self._same(before, obj):
            self.name_taken(ep, NameTaken(f"metric {ep.name!r} is already registered by {self._source(ep.name)}"))

    def register_family(self, pattern: str, make: Callable[[str], Metric | None]) -> None:
        """A parametrised family: ``make(id)`` returns the metric for an id it understands, else None;
        ``pattern`` (e.g. 'badpix_<t>') is what the 'Available' list shows."""
        self._families.append((pattern, make))

    @property
    def family_patterns(self) -> list[str]:
        """The families' patterns ('badpix_<t>', 'q<p>_x100'), as the 'Available' lists show them."""
        return [p for p, _ in self._families]

    def find(self, metric_id: str) -> Metric | None:
        """The metric with this id or toolkit id (or from a family), or None. The first lookup loads every
        plugin of the group (lfbench's first: the order of the metrics does not depend on what is asked)."""
        if self._refused is not None:
            raise self._refused
        if not self._loaded:
            self.names()
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
            raise self.unknown(metric_id, [*self.registered(), *self.family_patterns])
        return metric

    def all(self, category: str | None = None) -> tuple[Metric, ...]:
        """The registered metrics (families excluded; every plugin loaded), in registration order, optionally
        of one category."""
        if not self._loaded:
            self.names()
        return tuple(m for m in map(self.get, self.registered()) if category is None or m.category == category)
