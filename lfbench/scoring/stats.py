"""Statistical honesty for benchmark numbers: bootstrap confidence intervals and paired tests.

What is resampled, and what it means:

- **Over pixels** (:func:`bootstrap_metric`, :func:`bootstrap_errors`): the scored pixels of one scene
  (the evaluation mask, finite ground truth) are treated as a sample from the scene's error
  distribution and resampled with replacement (nonparametric bootstrap, percentile interval).
  The interval answers "how much would the number move with a different draw of pixels"; it does
  not cover a different scene. Neighbouring pixels' errors are correlated, so the i.i.d. pixel
  bootstrap is too narrow on real maps; ``block=b`` resamples b x b pixel tiles instead (a spatial
  block / cluster bootstrap), which is the more honest choice for real predictions.
- **Over scenes** (:func:`bootstrap_mean_over_scenes`): the per-scene values are resampled to get an
  interval for their mean. With a handful of scenes this interval is rough (percentile intervals
  under-cover for k < ~10); it is reported as what it is.
- **Paired tests** compare two methods on the *same* pixels or scenes. Null hypothesis: for every
  pixel (tile, scene) the two methods' losses are exchangeable, i.e. swapping the labels "a" and "b"
  does not change the distribution. The statistic is the mean paired difference of a per-pixel loss
  (``metric(a) - metric(b)``; negative = a is better for error-type metrics); the p-value comes from
  random sign flips of the paired differences (exact McNemar / binomial test for BadPix indicators,
  exact enumeration over scenes when there are at most 16), the CI from the paired bootstrap.

Metrics follow :mod:`lfbench.scoring.metrics` (default rules: a non-finite prediction is a bad pixel for
BadPix, an infinite error for Q25, left out of MSE; ``toolkit=True`` reproduces the toolkit's rules).
The bootstrap estimate is always the metric's own value on the full sample.
Replicates: BadPix from the exact binomial law of the resampled bad count, Q25 from the exact law of
the resampled order statistic (both equal in distribution to index resampling, and O(n)), MSE by
index resampling in chunks (O(n x resamples): ~2 s for 1000 resamples of a 482 x 482 mask on one core);
the block bootstrap works on per-tile sums (~0.1-0.2 s for any metric).

From scenes and runs: :func:`scene_errors` takes the per-pixel errors of a prediction on exactly the pixels
the general metrics score (:meth:`lfbench.scoring.prepare.SceneReference.prepare`); :class:`ErrorCollector`
(a ``runner.evaluate`` prediction hook) gathers them for every run; :func:`ci_records` turns a Results plus
those errors into a long frame of intervals ('(mean)' rows over scenes), which
:func:`lfbench.reports.ci.format_ci_table` lays out as a table.
"""

from __future__ import annotations

import itertools
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd
from tqdm import tqdm

from lfbench.data.scene import Scene
from lfbench.scoring.base import Metric
from lfbench.scoring.general import check_maps
from lfbench.scoring.metrics import get_metric, list_metrics
from lfbench.scoring.pixels import ErrorsOnly
from lfbench.scoring.pixelwise import Family, PixelMetric, Proportion, Sample
from lfbench.scoring.prepare import Prepared, SceneReference
from lfbench.scoring.resample import chunks as _chunks
from lfbench.scoring.resample import group_counts as _group_counts
from lfbench.scoring.resample import index_means as _index_means
from lfbench.scoring.resample import weighted_quantile_replicates as _weighted_quantile_replicates  # noqa: F401
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.readfile import read_csv

__all__ = [
    "CI",
    "PairedTest",
    "ScoredErrors",
    "scored_errors",
    "metric_from_errors",
    "bootstrap_errors",
    "bootstrap_replicates",
    "bootstrap_metric",
    "bootstrap_mean_over_scenes",
    "pixel_loss",
    "paired_pixel_test",
    "paired_scene_test",
    "block_groups",
    "scene_errors",
    "ErrorCollector",
    "CI_COLUMNS",
    "ci_records",
    "read_ci_csv",
]

DEFAULT_RESAMPLES = 1000
DEFAULT_LEVEL = 0.95
_EXACT_FLIPS_MAX = 16  # enumerate all 2^k sign flips up to this many scenes/tiles
#: Columns of ci.csv (``lfbench evaluate --ci``): :func:`ci_records` as CSV.
CI_COLUMNS = ("method", "scene", "metric", "value", "low", "high", "n_pixels", "resolution")


class CI(NamedTuple):
    """A point estimate and its percentile confidence interval [low, high], in the metric's unit."""

    estimate: float
    low: float
    high: float


@dataclass(frozen=True)
class PairedTest:
    """Result of a paired comparison of methods a and b.

    difference: mean paired difference of the loss, a - b (metric units; negative = a has the
    lower error); [low, high]: its bootstrap percentile CI; p_value: two-sided, sign-flip
    (permutation) test of exchangeability; n: number of pairs (pixels or scenes) used;
    p_wilcoxon: Wilcoxon signed-rank p-value (scene tests only); test: what was done, in words.
    """

    difference: float
    low: float
    high: float
    p_value: float
    n: int
    measure: str
    test: str
    p_wilcoxon: float | None = None


# --------------------------------------------------------------------------- metric kinds

def _kind_of(metric: str | Metric) -> Metric:
    """The metric of an id or definition; SpecError when it has no bootstrap (no resampling family)."""
    m = metric if isinstance(metric, Metric) else get_metric(str(metric))
    if m.bootstrap is None:
        bootstrapped = ", ".join(x.id for x in list_metrics() if x.bootstrap is not None)
        raise SpecError(f"no bootstrap for metric {m.id!r}: supported are {bootstrapped}, badpix_<t>")
    return m


def _sample(errors: np.ndarray, metric: Metric, toolkit: bool) -> tuple[Sample, Family]:
    """The metric's own sample of the per-pixel ``errors`` (:func:`scored_errors`), and its family."""
    definition: PixelMetric = metric.pixelwise
    return definition.draw(ErrorsOnly(errors), toolkit=toolkit), definition.family


# --------------------------------------------------------------------------- per-pixel errors

def _scored(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None, toolkit: bool) -> tuple[np.ndarray, np.ndarray]:
    gt, pred, mask = check_maps(gt, pred, mask)  # the metrics' shapes and precision
    scored = mask if toolkit else mask & np.isfinite(gt)
    with np.errstate(invalid="ignore"):
        err = pred[scored] - gt[scored]
    return err, scored


def scored_errors(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *,
                  toolkit: bool = False) -> np.ndarray:
    """Signed errors pred - gt (px) of the scored pixels, 1-D in row-major order.

    Scored = ``mask`` (None = all) with finite gt (``toolkit=True``: every mask pixel, as the
    toolkit's BadPix). Entries are NaN/inf where the prediction (or, toolkit, the gt) is non-finite.
    """
    return _scored(gt, pred, mask, toolkit)[0]


@dataclass(frozen=True)
class ScoredErrors:
    """Per-pixel errors of one (method, scene) with their positions, for block bootstraps.

    errors: (N,) pred - gt in px (see :func:`scored_errors`); flat_index: (N,) int row-major index
    of each pixel in a map of ``shape`` (H, W); toolkit: which non-finite rules the errors follow;
    scale: how many scored pixels one prediction pixel spans per axis (10 for high-res scoring).
    """

    errors: np.ndarray
    flat_index: np.ndarray
    shape: tuple[int, int]
    toolkit: bool = False
    scale: int = 1

    @classmethod
    def from_maps(cls, gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *,
                  toolkit: bool = False) -> ScoredErrors:
        err, scored = _scored(gt, pred, mask, toolkit)
        return cls(err, np.flatnonzero(scored).astype(np.int64), tuple(np.shape(gt)), toolkit)

    @classmethod
    def from_prepared(cls, prepared: Prepared, *, toolkit: bool = False) -> ScoredErrors:
        """The errors of a prepared prediction on its scored pixels (float32 errors; int32 positions
        while they fit), with its scale."""
        err, scored = _scored(prepared.gt, prepared.pred, prepared.mask, toolkit)
        index = np.flatnonzero(scored).astype(_position_dtype(scored.size))
        return cls(err.astype(np.float32, copy=False), index, tuple(prepared.gt.shape), toolkit, prepared.scale)

    def groups(self, block: int | None) -> np.ndarray | None:
        """Tile id of each pixel for tiles of block x block *prediction* pixels (block * scale scored
        pixels a side, so high-res scoring keeps the same tiles), or None for block None/0/1."""
        if not block or block <= 1:
            return None
        block = int(block) * self.scale
        h, w = self.shape
        y, x = np.divmod(self.flat_index, w)
        return (y // block) * (-(-w // block)) + x // block


def _position_dtype(size: int) -> type[np.signedinteger]:
    """The dtype of the flat positions of a map of ``size`` pixels: int32 while every position (0 .. size - 1)
    is below 2^31, int64 from 2^31 pixels on (a map that large cannot be built in a fast test; this rule can)."""
    return np.int32 if size < 2**31 else np.int64


def block_groups(mask: np.ndarray, block: int | None) -> np.ndarray | None:
    """Tile ids (block x block px tiles, row-major) of the True pixels of ``mask`` (H, W), in
    row-major order, or None when ``block`` is None/0/1 (i.i.d. pixels)."""
    if not block or block <= 1:
        return None
    mask = np.asarray(mask, dtype=bool)
    y, x = np.nonzero(mask)
    return (y // block) * (-(-mask.shape[1] // block)) + x // block


def metric_from_errors(errors: np.ndarray, metric: str | Metric, *, toolkit: bool = False) -> float:
    """The metric's value from :func:`scored_errors` output; equals lfbench.scoring.metrics on the maps (it is
    the metric's own definition, :class:`~lfbench.scoring.pixelwise.PixelMetric`, on the errors)."""
    return _kind_of(metric).pixelwise(ErrorsOnly(np.asarray(errors)), toolkit=toolkit)


# --------------------------------------------------------------------------- resampling

def bootstrap_replicates(errors: np.ndarray, metric: str | Metric, n: int = DEFAULT_RESAMPLES, seed: int | None = 0,
                         *, toolkit: bool = False, groups: np.ndarray | None = None) -> np.ndarray:
    """(n,) bootstrap replicates of ``metric`` over the pixels of ``errors`` (see :func:`scored_errors`).

    ``groups``: optional (N,) int cluster id per pixel (e.g. :func:`block_groups`): whole clusters
    are resampled instead of pixels (cluster bootstrap; the metric is taken on the pooled pixels).
    """
    (values, keep), family = _sample(np.asarray(errors), _kind_of(metric), toolkit)
    rng = np.random.default_rng(seed)
    if values.size == 0 or n <= 0:
        return np.full(max(n, 0), np.nan)
    if groups is None:
        return family.replicates(values, n, rng)
    groups = np.asarray(groups)
    if groups.shape != np.shape(errors):
        raise ValueError(f"groups {groups.shape} and errors {np.shape(errors)} differ in shape")
    _, gid = np.unique(groups if keep is None else groups[keep], return_inverse=True)
    n_groups = int(gid.max()) + 1
    return family.pooled_replicates(values, gid, _group_counts(n_groups, n, rng))


def _percentile_ci(estimate: float, reps: np.ndarray, level: float) -> CI:
    if not 0 < level < 1:
        raise SpecError(f"confidence level must be in (0, 1), got {level}")
    reps = np.asarray(reps, dtype=np.float64)
    reps = reps[~np.isnan(reps)]
    if math.isnan(estimate) or reps.size == 0:
        return CI(float(estimate), float("nan"), float("nan"))
    alpha = (1.0 - level) / 2.0
    # linear interpolation between order statistics; 'nearest' when infinite replicates (inf - inf) occur
    method = "linear" if np.isfinite(reps).all() else "nearest"
    low, high = np.quantile(reps, [alpha, 1.0 - alpha], method=method)
    return CI(float(estimate), float(low), float(high))


def bootstrap_errors(errors: np.ndarray, metric: str | Metric, n: int = DEFAULT_RESAMPLES, seed: int | None = 0,
                     level: float = DEFAULT_LEVEL, *, toolkit: bool = False, groups: np.ndarray | None = None) -> CI:
    """Percentile bootstrap CI of ``metric`` from per-pixel errors (:func:`scored_errors`)."""
    estimate = metric_from_errors(errors, metric, toolkit=toolkit)
    return _percentile_ci(estimate, bootstrap_replicates(errors, metric, n, seed, toolkit=toolkit, groups=groups),
                          level)


def bootstrap_metric(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None,
                     metric: str | Metric | Callable[..., float] = "badpix_0.07", n: int = DEFAULT_RESAMPLES,
                     seed: int | None = 0, level: float = DEFAULT_LEVEL, *, toolkit: bool = False,
                     block: int | None = None) -> CI:
    """Bootstrap CI over the scored pixels of one scene: (estimate, low, high) in the metric's unit.

    gt, pred: disparity (H, W) in px; mask: bool (H, W) or None. ``metric``: a general metric id
    ('badpix_0.07', 'mse_x100', 'q25_x100', any 'badpix_<t>'), a :class:`Metric`, or any callable
    ``fn(gt, pred, mask) -> float`` (generic path: the scored pixels are resampled and ``fn`` is
    called once per resample on 1-D arrays, with mask None). ``block``: tile size in px for a
    spatial block bootstrap (None = i.i.d. pixels). Percentile interval at ``level``.
    """
    if callable(metric) and not isinstance(metric, Metric):
        if block:
            raise SpecError("block bootstrap needs a general metric id, not a callable")
        gt = np.asarray(gt)
        pred = np.asarray(pred)
        scored = (np.ones(gt.shape, bool) if mask is None else np.asarray(mask, bool)) & np.isfinite(gt)
        g, p = gt[scored], pred[scored]
        estimate = float(metric(gt, pred, mask))
        rng = np.random.default_rng(seed)
        reps = np.array([metric(g[i], p[i], None) for i in (rng.integers(0, g.size, g.size) for _ in range(n))]) \
            if g.size else np.array([])
        return _percentile_ci(estimate, reps, level)
    err, scored = _scored(gt, pred, mask, toolkit)
    groups = block_groups(scored, block)
    return bootstrap_errors(err, metric, n, seed, level, toolkit=toolkit, groups=groups)


def bootstrap_mean_over_scenes(values: Sequence[float] | np.ndarray, n: int = DEFAULT_RESAMPLES, seed: int | None = 0,
                               level: float = DEFAULT_LEVEL) -> CI:
    """CI of the mean of per-scene values (scenes resampled with replacement; NaN scenes left out,
    as the average table does). Fewer than 2 scenes: the interval is NaN (nothing to resample)."""
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[~np.isnan(v)]
    if v.size == 0:
        return CI(float("nan"), float("nan"), float("nan"))
    estimate = float(v.mean())
    if v.size < 2:
        return CI(estimate, float("nan"), float("nan"))
    rng = np.random.default_rng(seed)
    return _percentile_ci(estimate, _index_means(v, n, rng), level)


# --------------------------------------------------------------------------- paired tests

def pixel_loss(errors: np.ndarray, measure: str) -> tuple[np.ndarray, str, str]:
    """Per-pixel loss whose mean is the named measure: (loss (N,) float64, canonical id, unit).

    'abs' (EPE, px): |e|; 'mse_x100' (alias 'sq'): 100 e^2 (px^2 x 100, mean = MSE x100);
    'badpix_<t>': 100 * [|e| > t or non-finite] (%, mean = BadPix(t)). Non-finite errors give
    inf for abs/sq (callers drop them) and a bad pixel for BadPix.
    """
    return _loss(errors, measure)[:3]


def _loss(errors: np.ndarray, measure: str) -> tuple[np.ndarray, str, str, Family | None]:
    """:func:`pixel_loss` and the metric's family (None for 'abs'). A metric's loss: ``scale`` x its own sample
    of the errors (in the family's loss precision), inf at the pixels its sample leaves out."""
    e = np.asarray(errors)
    name = str(measure).lower()
    if name in ("abs", "epe", "mae"):
        with np.errstate(invalid="ignore"):
            return np.where(np.isfinite(e), np.abs(e), np.inf).astype(np.float64), "abs", "px", None
    name = {"sq": "mse_x100", "mse": "mse_x100", "badpix": "badpix_0.07"}.get(name, name)
    try:
        metric = get_metric(name)
    except SpecError:
        raise SpecError(f"unknown measure {measure!r}: use abs, mse_x100 or badpix_<t>") from None
    family = metric.bootstrap
    if family is None or not family.per_pixel_mean:
        raise SpecError(f"measure {measure!r} is not a mean of per-pixel losses: use abs, mse_x100 or badpix_<t>")
    e = e if family.loss_dtype is None else e.astype(family.loss_dtype)
    with np.errstate(invalid="ignore", over="ignore"):
        values, keep = metric.pixelwise.draw(ErrorsOnly(e), toolkit=False)
        loss = np.full(e.shape, np.inf)
        loss[slice(None) if keep is None else keep] = family.scale * values
    return loss, metric.id, metric.unit, family


def _signflip_p(sums: np.ndarray, n: int, rng: np.random.Generator) -> float:
    """Two-sided p-value of |sum(s_i x_i)| >= |sum(x_i)| under random signs s_i (x: per-unit sums).

    Exact enumeration for <= 16 units, else ``n`` Monte Carlo flips with p = (1 + hits) / (1 + n)."""
    x = np.asarray(sums, dtype=np.float64)
    observed = abs(x.sum())
    tol = 1e-9 * max(np.abs(x).sum(), 1e-300)
    if x.size <= _EXACT_FLIPS_MAX:
        signs = np.array(list(itertools.product((1.0, -1.0), repeat=x.size))) if x.size else np.ones((1, 0))
        return float(np.mean(np.abs(signs @ x) >= observed - tol))
    hits = 0
    total = float(x.sum())
    for c in _chunks(n, x.size):
        raw = np.frombuffer(rng.bytes(c * ((x.size + 7) // 8)), dtype=np.uint8).reshape(c, -1)
        bits = np.unpackbits(raw, axis=1, count=x.size).astype(np.float64)
        flipped = total - 2.0 * (bits @ x)  # bits mark the flipped units
        hits += int(np.count_nonzero(np.abs(flipped) >= observed - tol))
    return (1.0 + hits) / (1.0 + n)


def paired_pixel_test(gt: np.ndarray, pred_a: np.ndarray, pred_b: np.ndarray, mask: np.ndarray | None = None,
                      measure: str = "abs", n: int = DEFAULT_RESAMPLES, seed: int | None = 0,
                      level: float = DEFAULT_LEVEL, *, block: int | None = None) -> PairedTest:
    """Paired comparison of two predictions on the same scored pixels of one scene.

    Per-pixel loss (:func:`pixel_loss`): 'abs' (px), 'mse_x100', 'badpix_<t>' (%); the difference is
    mean(loss_a - loss_b) = measure(a) - measure(b) on the common pixels (for abs/sq, pixels where
    either prediction is non-finite are left out; for BadPix they are bad). H0: per pixel (per tile
    with ``block``), the losses of a and b are exchangeable. p-value: sign-flip permutation test of
    the mean difference (BadPix, i.i.d.: exact two-sided binomial test on the discordant pixels,
    i.e. McNemar). CI: paired bootstrap of the mean difference (percentile).
    """
    err_a, scored = _scored(gt, pred_a, mask, False)
    err_b, _ = _scored(gt, pred_b, mask, False)
    loss_a, mid, _unit, family = _loss(err_a, measure)
    loss_b = _loss(err_b, measure)[0]
    keep = np.isfinite(loss_a) & np.isfinite(loss_b)
    d = (loss_a - loss_b)[keep]
    groups = block_groups(scored, block)
    rng = np.random.default_rng(seed)
    if d.size == 0:
        return PairedTest(float("nan"), float("nan"), float("nan"), float("nan"), 0, mid, "no common scored pixels")
    diff = float(d.mean())
    if groups is None and isinstance(family, Proportion):  # indicator losses: McNemar on the discordant pixels
        worse, better = int(np.count_nonzero(d > 0)), int(np.count_nonzero(d < 0))
        probs = np.array([worse, d.size - worse - better, better], dtype=np.float64) / d.size
        counts = rng.multinomial(d.size, probs, size=n)
        reps = family.scale * (counts[:, 0] - counts[:, 2]) / d.size  # in the metric's units, as diff
        import scipy.stats  # on first use, as below

        p = 1.0 if worse + better == 0 else float(scipy.stats.binomtest(worse, worse + better, 0.5).pvalue)
        test = (f"exact McNemar (two-sided binomial) on {worse + better} discordant pixels "
                f"({worse} bad only in a, {better} bad only in b); paired bootstrap CI over {d.size} pixels")
    elif groups is None:
        reps = _index_means(d, n, rng)
        p = _signflip_p(d, n, rng)
        test = f"sign-flip permutation test ({n} flips) and paired bootstrap CI over {d.size} pixels (i.i.d.)"
    else:
        _, gid = np.unique(groups[keep], return_inverse=True)
        n_groups = int(gid.max()) + 1
        sums = np.bincount(gid, weights=d, minlength=n_groups)
        sizes = np.bincount(gid, minlength=n_groups).astype(np.float64)
        counts = _group_counts(n_groups, n, rng)
        reps = (counts @ sums) / (counts @ sizes)
        p = _signflip_p(sums, n, rng)
        test = (f"tile sign-flip permutation test and tile bootstrap CI ({block}x{block} px tiles, "
                f"{n_groups} tiles, {d.size} pixels)")
    ci = _percentile_ci(diff, reps, level)
    return PairedTest(diff, ci.low, ci.high, float(p), int(d.size), mid, test)


def paired_scene_test(values_a: Sequence[float] | np.ndarray, values_b: Sequence[float] | np.ndarray,
                      n: int = DEFAULT_RESAMPLES, seed: int | None = 0, level: float = DEFAULT_LEVEL,
                      measure: str = "") -> PairedTest:
    """Paired comparison over scenes: values_a[i], values_b[i] are one metric on scene i.

    difference = mean(a - b) over scenes where both are finite; CI: bootstrap over scenes; p_value:
    two-sided sign-flip permutation test (exact for <= 16 scenes; note the smallest possible p with
    k scenes is 2 / 2^k, e.g. 0.125 for 4); p_wilcoxon: scipy's Wilcoxon signed-rank test (1.0 when
    every difference is zero).
    """
    a = np.asarray(values_a, dtype=np.float64).ravel()
    b = np.asarray(values_b, dtype=np.float64).ravel()
    if a.shape != b.shape:
        raise ValueError(f"values_a ({a.size}) and values_b ({b.size}) must be paired (same length)")
    d = (a - b)[np.isfinite(a) & np.isfinite(b)]
    if d.size == 0:
        return PairedTest(float("nan"), float("nan"), float("nan"), float("nan"), 0, measure, "no paired scenes")
    rng = np.random.default_rng(seed)
    ci = bootstrap_mean_over_scenes(d, n, seed, level)
    p = _signflip_p(d, n, rng)
    if np.all(d == 0):
        p_w = 1.0
    else:
        import scipy.stats  # on first use: importing it costs 1.4 s CPU, more than scoring one submission

        p_w = float(scipy.stats.wilcoxon(d).pvalue)
    exact = "exact" if d.size <= _EXACT_FLIPS_MAX else f"{n} random"
    return PairedTest(float(d.mean()), ci.low, ci.high, float(p), int(d.size), measure,
                      f"{exact} sign-flip permutation test over {d.size} scenes; bootstrap CI over scenes", p_w)


# --------------------------------------------------------------------------- from scenes and runs

def scene_errors(scene: Scene, pred: np.ndarray, rules: ScoringRules | None = None, source: str = "prediction", *,
                 reference: SceneReference | None = None) -> ScoredErrors:
    """Per-pixel errors of a prediction (H, W) on a :class:`lfbench.data.scene.Scene`, on exactly the pixels
    :func:`lfbench.scoring.score.score_scene` scores the general metrics on (the scene's resolution, the
    prediction prepared by :meth:`~lfbench.scoring.prepare.SceneReference.prepare`: alignment, the
    toolkit's upsampling, border and valid masks; the rules' non-finite handling). ``reference``: the
    scene's SceneReference (its rules are used; ValueError when it is another scene's, or ``rules`` are
    given and differ), made from ``scene`` and ``rules`` when None.
    Memory: ~8 bytes per scored pixel (2 MB at 512 x 512, ~200 MB for a 5120 x 5120 high-res scene)."""
    if reference is None:
        reference = SceneReference(scene, rules or ScoringRules())
    reference.check_serves(scene, rules)  # not another folder's scene of the same name
    prepared = reference.prepare(pred, reference.general_resolution(), source)
    return ScoredErrors.from_prepared(prepared, toolkit=reference.rules.toolkit)


class ErrorCollector:
    """Prediction hook for ``runner.evaluate(on_prediction=...)``: keeps the per-pixel errors of
    every (method label, scene) in ``self.errors`` for :func:`ci_table` / :func:`ci_records`."""

    def __init__(self, rules=None) -> None:
        self.rules = rules
        self.errors: dict[tuple[str, str], ScoredErrors] = {}

    def __call__(self, method, scene, pred) -> None:
        if not scene.has_gt():
            return
        self.errors[(method.label, scene.name)] = scene_errors(scene, pred.disparity, self.rules,
                                                               source=f"{method.label} on {scene.name}")


# --------------------------------------------------------------------------- tables

ErrorsLike = ScoredErrors | np.ndarray


def ci_records(results, errors: Mapping[tuple[str, str], ErrorsLike], metrics: Sequence[str] | None = None,
               n: int = DEFAULT_RESAMPLES, seed: int = 0, level: float = DEFAULT_LEVEL, *,
               block: int | None = None, average: bool = True, progress: bool = False):
    """Long DataFrame of CIs: columns method, scene, metric, value, low, high, n_pixels, resolution.

    ``results``: a :class:`lfbench.results.Results`; ``errors``: (method label, scene) -> per-pixel
    errors (:class:`ScoredErrors` or :func:`scored_errors` output) scored as the results were.
    ``value`` is the Results value; low/high the bootstrap over pixels (NaN where no errors were
    given or the metric has no bootstrap). With ``average``, a row per (method, metric) with
    scene '(mean)': the mean over scenes (as the average table) with a bootstrap over scenes.
    ``block``: tile size in prediction pixels for the spatial block bootstrap (None = i.i.d. pixels).
    """
    df = results.to_frame()
    rows = []
    for rec in tqdm(list(df.itertuples(index=False)), desc="bootstrap", unit="number", file=sys.stderr,
                    disable=None if progress else True, leave=False):
        if metrics is not None and rec.metric not in metrics:
            continue
        low = high = float("nan")
        npix = 0
        item = errors.get((rec.method, rec.scene))
        if item is not None:
            try:
                _kind_of(rec.metric)
            except SpecError:
                item = None
        if item is not None:
            err = item.errors if isinstance(item, ScoredErrors) else np.asarray(item)
            toolkit = item.toolkit if isinstance(item, ScoredErrors) else False
            groups = item.groups(block) if isinstance(item, ScoredErrors) else None
            if block and groups is None and not isinstance(item, ScoredErrors):
                raise SpecError("block bootstrap needs ScoredErrors (pixel positions) for every run")
            ci = bootstrap_errors(err, rec.metric, n, seed, level, toolkit=toolkit, groups=groups)
            low, high, npix = ci.low, ci.high, int(err.size)
        rows.append((rec.method, rec.scene, rec.metric, float(rec.value), low, high, npix, rec.resolution))
    out = pd.DataFrame(rows, columns=list(CI_COLUMNS))
    if average and not out.empty:
        means = []
        for (method, metric), grp in out.groupby(["method", "metric"], sort=False):
            ci = bootstrap_mean_over_scenes(grp["value"].to_numpy(), n, seed, level)
            res = "/".join(sorted(set(grp["resolution"])))
            means.append((method, "(mean)", metric, ci.estimate, ci.low, ci.high, int(grp["n_pixels"].sum()), res))
        out = pd.concat([out, pd.DataFrame(means, columns=out.columns)], ignore_index=True)
    return out


def read_ci_csv(path):
    """A ci.csv read back (an untrusted file): a DataFrame with method, scene and metric as text and
    value, low and high as float (an empty cell is NaN). DataError naming the file, and the line and
    column, when it is not a CSV table, lacks a column or holds a number that is not one."""
    path = Path(path)
    ci = read_csv(path, "ci.csv", dtype=str, keep_default_na=False)
    missing = [c for c in ("method", "scene", "metric", "low", "high") if c not in ci.columns]
    if missing:
        raise DataError(f"missing column(s) {', '.join(missing)}", path)
    for column in ("value", "low", "high"):
        if column not in ci.columns:
            continue
        numbers = []
        for line, text in enumerate(ci[column], start=2):
            try:
                numbers.append(float(text) if text.strip() else math.nan)
            except ValueError:
                raise DataError(f"line {line}: {column} is not a number", path) from None
        ci[column] = np.array(numbers, dtype=np.float64)
    return ci
