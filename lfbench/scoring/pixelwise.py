"""Pixel-wise metrics, each defined once: a :class:`Sample` of per-pixel values drawn from a prediction's errors at
the scored pixels (:class:`~lfbench.scoring.pixels.PixelErrors`) and the :class:`Family` that reduces it to the
metric's value and resamples it.

A :class:`PixelMetric` is that one definition: ``sample(px, toolkit=...)`` and ``family``. Everything else derives
from it: the value on the pixels (scoring gathers each prediction's errors once per set of pixels,
:func:`lfbench.scoring.score.score_scene`), the value on maps (:class:`OnMaps`, ``Metric.fn``), the bootstrap's
estimate, replicates and paired losses (:mod:`lfbench.scoring.stats`, which chooses how to resample from the
family, never from the metric's name).

The families: :class:`Proportion` (scale x the share of True values: BadPix, the fattening and thinning
metrics), :class:`Mean` (scale x the mean: MSE) and :class:`OrderStatistic` (the value at index
int(n x p / 100) of the sorted sample: the quantiles). A new pixel-wise metric of an existing family is a
sample function and a :class:`PixelMetric`; its bootstrap comes with it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np

from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.resample import index_means, order_stat_replicates, weighted_quantile_replicates
from lfbench.utils.errors import LFBenchError, exception_line

__all__ = ["Family", "Mean", "OnMaps", "OrderStatistic", "PixelMetric", "Proportion", "Sample", "kept",
           "plugin_failure"]


class Sample(NamedTuple):
    """The per-pixel values a pixel-wise metric reduces: ``values`` (K,), those of the pixels ``keep`` marks (bool
    (N,) over the N pixels of the errors, in their order; None: every pixel, K = N)."""

    values: np.ndarray
    keep: np.ndarray | None = None


def kept(values: np.ndarray, keep: np.ndarray) -> Sample:
    """The :class:`Sample` of ``values`` (N,) at ``keep`` (bool (N,)); no copy when every pixel is kept."""
    return Sample(values, None) if keep.all() else Sample(values[keep], keep)


class Family:
    """How a sample reduces to a value (:meth:`reduce`) and how it is resampled: :meth:`replicates` (i.i.d.
    pixels) and :meth:`pooled_replicates` (whole clusters of pixels, the block bootstrap). ``per_pixel_mean``:
    the value is the mean of a per-pixel loss (``scale`` x the values), so paired tests can compare it pixel by
    pixel; ``loss_dtype``: the precision that loss is computed in (None: the errors', as the metric decides)."""

    per_pixel_mean: ClassVar[bool] = False
    loss_dtype: ClassVar[Any] = None
    scale: float = 1.0

    def reduce(self, values: np.ndarray) -> float:
        raise NotImplementedError

    def problem(self) -> str | None:
        """Why this family cannot reduce any sample (a declared parameter out of its range), or None."""
        return None

    def replicates(self, values: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n,) values of i.i.d. resamples of ``values`` (non-empty)."""
        raise NotImplementedError

    def pooled_replicates(self, values: np.ndarray, gid: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """Per row of ``counts`` (n, G): the value of the pixels pooled with cluster g (``gid``, (K,) 0..G-1)
        repeated counts[g] times."""
        raise NotImplementedError


@dataclass(frozen=True)
class Proportion(Family):
    """``scale`` x the share of True values (a percentage for scale 100). Resampled exactly: the count of a
    resample is binomial; clusters pool their counts."""

    scale: float = 100.0
    per_pixel_mean: ClassVar[bool] = True

    def reduce(self, values: np.ndarray) -> float:
        return float("nan") if values.size == 0 else self.scale * int(np.count_nonzero(values)) / float(values.size)

    def replicates(self, values: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
        bad = np.count_nonzero(values)
        return rng.binomial(values.size, bad / values.size, size=n) * (self.scale / values.size)

    def pooled_replicates(self, values: np.ndarray, gid: np.ndarray, counts: np.ndarray) -> np.ndarray:
        return _pooled_means(values.astype(np.float64), gid, counts, self.scale)


@dataclass(frozen=True)
class Mean(Family):
    """``scale`` x the mean of the values, in their precision (a float32 mean, then x scale in float64, as the
    toolkit's MSE). Resampled by index (float64 means, shifted by the rounding of the metric's own mean so that
    identical values give exactly the value); clusters pool their sums."""

    scale: float = 100.0
    per_pixel_mean: ClassVar[bool] = True
    loss_dtype: ClassVar[Any] = np.float64

    def reduce(self, values: np.ndarray) -> float:
        return float("nan") if values.size == 0 else float(np.average(values)) * self.scale

    def replicates(self, values: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
        return (index_means(values, n, rng) - float(values.mean(dtype=np.float64))) * self.scale \
            + self.reduce(values)

    def pooled_replicates(self, values: np.ndarray, gid: np.ndarray, counts: np.ndarray) -> np.ndarray:
        reps = _pooled_means(values, gid, counts, self.scale)
        reps += self.reduce(values) - self.scale * float(values.mean(dtype=np.float64))
        return reps


@dataclass(frozen=True)
class OrderStatistic(Family):
    """The value at index int(n x ``percentage`` / 100) of the n sorted values (0 <= percentage < 100).
    Resampled from the exact law of the resampled order statistic; clusters by the weighted quantile."""

    percentage: float = 25.0

    def problem(self) -> str | None:
        p = self.percentage
        if isinstance(p, bool) or not isinstance(p, int | float) or not 0 <= p < 100:
            return f"OrderStatistic({str(p)[:20]}): the percentage must be a number from 0 to below 100"
        return None

    def reduce(self, values: np.ndarray) -> float:
        if values.size == 0:
            return float("nan")
        k = int(values.size * self.percentage / 100.0)
        return float(np.partition(values, k)[k])  # the element a full sort puts there

    def replicates(self, values: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
        return order_stat_replicates(values, int(values.size * self.percentage / 100.0), n, rng)

    def pooled_replicates(self, values: np.ndarray, gid: np.ndarray, counts: np.ndarray) -> np.ndarray:
        return weighted_quantile_replicates(values, gid, counts, self.percentage)


def _pooled_means(values: np.ndarray, gid: np.ndarray, counts: np.ndarray, scale: float) -> np.ndarray:
    n_groups = counts.shape[1]
    sums = np.bincount(gid, weights=values, minlength=n_groups)
    sizes = np.bincount(gid, minlength=n_groups).astype(np.float64)
    return scale * (counts @ sums) / (counts @ sizes)


SampleFn = Callable[..., Sample]


@dataclass(frozen=True)
class PixelMetric:
    """The one definition of a pixel-wise metric: ``sample(px, toolkit=...)`` -> :class:`Sample` of the errors
    ``px`` (:class:`~lfbench.scoring.pixels.PixelErrors`; ``toolkit``: the official toolkit's non-finite rules)
    and the ``family`` that reduces it. Calling it gives the metric's value. ``of_errors``: the sample reads only
    the errors (``err``, ``signed``, ``size``, the finite flags), not ``gt``, ``pred`` or ``pixels``, so the
    bootstrap can draw it from the scored errors alone (:class:`~lfbench.scoring.pixels.ErrorsOnly`)."""

    sample: SampleFn
    family: Family
    of_errors: bool = True

    def __call__(self, px: PixelErrors, *, toolkit: bool = False) -> float:
        return self.family.reduce(self.draw(px, toolkit=toolkit).values)

    def draw(self, px: PixelErrors, *, toolkit: bool = False) -> Sample:
        """``sample(px, toolkit=...)``; a plugin's sample function (one outside lfbench) is guarded: its
        family's parameters, any exception it raises (a bug, MemoryError) and what it returns (a
        :class:`Sample` of a 1-D numeric ``values`` and a bool ``keep`` of one flag per pixel, as many True as
        values) are checked, each problem one LFBenchError naming the function."""
        problem = self.family.problem()
        if problem:
            raise LFBenchError(f"metric plugin {_describe(self.sample)}: {problem}")
        if _own(self.sample):
            return self.sample(px, toolkit=toolkit)
        name = _describe(self.sample)
        try:
            sample = self.sample(px, toolkit=toolkit)
        except LFBenchError:
            raise
        except Exception as exc:  # noqa: BLE001 - whatever the plugin's code raised: one line naming it
            raise plugin_failure(name, exc) from None
        problem = _sample_problem(sample, int(px.size))
        if problem:
            raise LFBenchError(f"metric plugin {name} returned {problem}")
        return Sample(*sample)


def plugin_failure(name: str, exc: BaseException) -> LFBenchError:
    """One line for an exception a metric plugin's code raised."""
    return LFBenchError(f"metric plugin {name} failed: {exception_line(exc)}")


def _own(fn: Callable) -> bool:
    """Whether ``fn`` is lfbench's own (not guarded: its exceptions are lfbench's bugs, with their traceback)."""
    return str(getattr(fn, "__module__", "")).split(".")[0] == "lfbench"


def _describe(fn: Callable) -> str:
    name = getattr(fn, "__qualname__", None) or type(fn).__name__
    return f"{getattr(fn, '__module__', '?')}.{name}"


def _sample_problem(sample: Any, n: int) -> str | None:
    """Why ``sample`` is not a :class:`Sample` of ``n`` pixels' errors (None when it is)."""
    if not isinstance(sample, tuple) or len(sample) != 2:
        return f"a {type(sample).__name__}, expected Sample(values, keep)"
    values, keep = sample
    if not isinstance(values, np.ndarray) or values.ndim != 1 or values.dtype.kind not in "biuf":
        what = f"{values.dtype} {values.shape}" if isinstance(values, np.ndarray) else type(values).__name__
        return f"values of {what}, expected a 1-D array of numbers"
    if keep is None:
        return None if values.size == n else f"{values.size} values for {n} pixels and no keep mask"
    if not isinstance(keep, np.ndarray) or keep.dtype != bool or keep.shape != (n,):
        what = f"{keep.dtype} {keep.shape}" if isinstance(keep, np.ndarray) else type(keep).__name__
        return f"a keep mask of {what}, expected bool ({n},): one flag per scored pixel"
    kept_count = int(np.count_nonzero(keep))
    return None if kept_count == values.size else f"{values.size} values for {kept_count} kept pixels"


@dataclass(frozen=True)
class OnMaps:
    """A pixel-wise metric as a function of maps (``Metric.fn``): ``(gt, pred, mask=None, *, toolkit=False)`` ->
    the value of :class:`PixelMetric` on the errors at the pixels of ``mask``. A metric scored with its scene
    (``scene=``, ``resolution=``) learns from it the scene's low-resolution width (e.g. backgammon's columns)."""

    pixelwise: PixelMetric

    def __call__(self, gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *, toolkit: bool = False,
                 scene: Any = None, resolution: str | None = None) -> float:
        low_width = None if scene is None else int(scene.spatial_size[1])
        return self.pixelwise(PixelErrors.of_maps(gt, pred, mask, low_width=low_width), toolkit=toolkit)
