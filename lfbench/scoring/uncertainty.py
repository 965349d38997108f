"""Quality of a predicted uncertainty map: sparsification curves and AUSE.

A good uncertainty ranks pixels like their true error. Sparsification: remove the fraction f of the
scored pixels with the *largest predicted uncertainty* and compute the error measure on the pixels
that remain, for f = 0, 0.01, ..., 0.99. The **oracle** curve removes pixels in order of their true
error (the best any ranking can do); the **random** curve is the expectation under a random
ranking, which is flat at the full-sample value (the mean of a uniformly random subset is unbiased).

- AUSE (area under the sparsification error): trapezoid integral over f of (curve - oracle);
  0 for a perfect ranking, in the measure's unit x fraction.
- AURG (area under the random gain): integral of (random - curve); > 0 when the uncertainty is
  better than chance, ~0 for an uninformative one.

Removing round-down(f x N) pixels (floor of f * N, with f * N rounded to 6 decimals first to absorb
float noise), at least one pixel is always kept. Ties in the uncertainty are broken fairly: each pixel's
loss is replaced by the mean loss of its tie group, which is the expectation over all tie orders
(a constant uncertainty gives exactly the random curve). Measures (means of a per-pixel loss, see
:func:`lfbench.scoring.stats.pixel_loss`): 'abs' (EPE, px, default), 'mse_x100' (px^2 x 100) and
'badpix_<t>' (%). Non-finite predictions are left out for abs/mse_x100 and are bad pixels for BadPix;
non-finite uncertainties are treated as the most uncertain (removed first).

On a scene (:func:`scene_sparsifications`), the pixels and their errors are those of the general metrics
(:meth:`lfbench.scoring.prepare.SceneReference.prepare`, the uncertainty aligned and upsampled as the
disparity); :class:`UncertaintyCollector` rates every run of an evaluation and :func:`uncertainty_table`
tabulates the ratings. The report (table file and figures) is :mod:`lfbench.reports.uncertainty`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from lfbench.data.scene import Scene
from lfbench.scoring.metrics import METRICS
from lfbench.scoring.prepare import SceneReference
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.stats import ScoredErrors, pixel_loss

__all__ = [
    "DEFAULT_FRACTIONS",
    "Sparsification",
    "removed_counts",
    "sparsification_curve",
    "oracle_curve",
    "area_between",
    "sparsification",
    "sparsification_from_loss",
    "average_sparsification",
    "scene_sparsification",
    "scene_sparsifications",
    "REPORT_MEASURES",
    "UncertaintyCollector",
    "uncertainty_table",
]

DEFAULT_FRACTIONS = np.round(np.arange(100) * 0.01, 2)  # 0, 0.01, ..., 0.99 removed


def _unit_of(measure: str) -> str:
    """The unit of a measure: px for 'abs', else the metric's own (lfbench.scoring.metrics registry)."""
    if measure == "abs":
        return "px"
    metric = METRICS.find(measure)
    return metric.unit if metric is not None else ""


@dataclass(frozen=True)
class Sparsification:
    """Sparsification of one uncertainty map (or an average of several).

    fractions (F,): fraction of pixels removed; curve (F,): the measure on the remaining pixels when
    removing by decreasing predicted uncertainty; oracle (F,): removing by decreasing true loss;
    random (F,): expectation under random removal. measure/unit: what the curves are; n_pixels:
    pixels ranked (summed over scenes for an average); normalized: curves divided by the full-set value.
    """

    fractions: np.ndarray
    curve: np.ndarray
    oracle: np.ndarray
    random: np.ndarray
    measure: str
    unit: str
    n_pixels: int
    normalized: bool = False

    @property
    def ause(self) -> float:
        """Area between the sparsification and oracle curves (trapezoid over the fraction axis)."""
        return area_between(self.fractions, self.curve, self.oracle)

    @property
    def aurg(self) -> float:
        """Area between the random and sparsification curves (> 0: better than a random ranking)."""
        return area_between(self.fractions, self.random, self.curve)


def removed_counts(fractions: Sequence[float] | np.ndarray, n: int) -> np.ndarray:
    """Pixels removed at each fraction: floor(f * n) (f * n rounded to 6 decimals), at most n - 1."""
    f = np.asarray(fractions, dtype=np.float64)
    if f.ndim != 1 or f.size == 0 or np.any(f < 0) or np.any(f >= 1) or np.any(np.diff(f) < 0):
        raise ValueError("fractions must be a non-empty increasing 1-D sequence in [0, 1)")
    return np.minimum(np.floor(np.round(f * n, 6)).astype(np.int64), max(n - 1, 0))


def _remaining_means(sorted_loss: np.ndarray, removed: np.ndarray) -> np.ndarray:
    """Mean of sorted_loss[r:] for each r in ``removed`` (loss sorted by decreasing rank key)."""
    n = sorted_loss.size
    tail = np.concatenate([np.cumsum(sorted_loss[::-1], dtype=np.float64)[::-1], [0.0]])  # tail[r] = sum(loss[r:])
    return tail[removed] / (n - removed)


def sparsification_curve(loss: np.ndarray, uncertainty: np.ndarray,
                         fractions: Sequence[float] | np.ndarray = DEFAULT_FRACTIONS) -> np.ndarray:
    """Mean ``loss`` of the pixels left after removing the most uncertain fraction f, per f.

    loss, uncertainty: (N,) per pixel (uncertainty: larger = less sure; NaN/inf removed first).
    Tied uncertainties count as in random order (their mean loss, see the module docstring).
    """
    loss = np.asarray(loss, dtype=np.float64).ravel()
    unc = np.asarray(uncertainty, dtype=np.float64).ravel()
    if loss.shape != unc.shape:
        raise ValueError(f"loss {loss.shape} and uncertainty {unc.shape} differ in size")
    if loss.size == 0:
        return np.full(len(fractions), np.nan)
    unc = np.where(np.isfinite(unc), unc, np.inf)
    order = np.argsort(-unc, kind="stable")
    u, lo = unc[order], loss[order]
    # tie groups of equal uncertainty -> each pixel carries its group's mean loss
    starts = np.flatnonzero(np.concatenate([[True], u[1:] != u[:-1]]))
    sums = np.add.reduceat(lo, starts)
    sizes = np.diff(np.concatenate([starts, [u.size]]))
    lo = np.repeat(sums / sizes, sizes)
    return _remaining_means(lo, removed_counts(fractions, loss.size))


def oracle_curve(loss: np.ndarray, fractions: Sequence[float] | np.ndarray = DEFAULT_FRACTIONS) -> np.ndarray:
    """The best sparsification: pixels removed by decreasing true loss."""
    loss = np.asarray(loss, dtype=np.float64).ravel()
    if loss.size == 0:
        return np.full(len(fractions), np.nan)
    return _remaining_means(np.sort(loss)[::-1], removed_counts(fractions, loss.size))


def area_between(fractions: np.ndarray, upper: np.ndarray, lower: np.ndarray) -> float:
    """Trapezoid integral of (upper - lower) over ``fractions``."""
    return float(np.trapezoid(np.asarray(upper, np.float64) - np.asarray(lower, np.float64),
                              np.asarray(fractions, np.float64)))


def sparsification_from_loss(loss: np.ndarray, uncertainty: np.ndarray, measure: str = "abs", unit: str = "",
                             fractions: Sequence[float] | np.ndarray = DEFAULT_FRACTIONS,
                             normalize: bool = False) -> Sparsification:
    """Sparsification, oracle and random curves from a per-pixel loss (N,) and uncertainty (N,)."""
    f = np.asarray(fractions, dtype=np.float64)
    loss = np.asarray(loss, dtype=np.float64).ravel()
    curve = sparsification_curve(loss, uncertainty, f)
    oracle = oracle_curve(loss, f)
    unit = unit or _unit_of(measure)
    full = float(loss.mean()) if loss.size else float("nan")
    random = np.full(f.shape, full)
    if normalize:
        scale = full if full != 0 else 1.0
        curve, oracle, random = curve / scale, oracle / scale, random / scale
    return Sparsification(f, curve, oracle, random, measure, "relative" if normalize else unit, int(loss.size),
                          normalize)


def sparsification(gt: np.ndarray, pred: np.ndarray, uncertainty: np.ndarray, mask: np.ndarray | None = None,
                   measure: str = "abs", fractions: Sequence[float] | np.ndarray = DEFAULT_FRACTIONS,
                   normalize: bool = False) -> Sparsification:
    """Sparsification of an uncertainty map against the true error of a disparity map.

    gt, pred: disparity (H, W) in px; uncertainty: (H, W), larger = less sure (e.g. the std of
    SubFocal's distribution, px); mask: bool (H, W) of scored pixels (None = all; pixels with
    non-finite gt are never scored). measure: 'abs' (default), 'mse_x100' / 'sq', 'badpix_<t>'.
    normalize: divide all curves by the full-set value (curves start at 1; AUSE then unitless).
    """
    gt = np.asarray(gt)
    pred = np.asarray(pred)
    unc = np.asarray(uncertainty)
    if not gt.shape == pred.shape == unc.shape:
        raise ValueError(f"gt {gt.shape}, pred {pred.shape} and uncertainty {unc.shape} must have one shape")
    scored = np.isfinite(gt) if mask is None else np.asarray(mask, dtype=bool) & np.isfinite(gt)
    dtype = np.result_type(gt.dtype, pred.dtype, np.float32)
    with np.errstate(invalid="ignore"):
        err = pred.astype(dtype, copy=False)[scored] - gt.astype(dtype, copy=False)[scored]
    loss, mid, unit = pixel_loss(err, measure)
    keep = np.isfinite(loss)  # abs / sq: non-finite predictions left out (BadPix: already bad, finite)
    return sparsification_from_loss(loss[keep], unc[scored][keep], mid, unit, fractions, normalize)


def scene_sparsification(scene: Scene, prediction, rules: ScoringRules | None = None,
                         measure: str = "abs", fractions: Sequence[float] | np.ndarray = DEFAULT_FRACTIONS,
                         normalize: bool = False) -> Sparsification | None:
    """Sparsification of a method's :class:`lfbench.method.base.Prediction` on a :class:`lfbench.data.scene.Scene`,
    scored on exactly the pixels of the general metrics (:meth:`lfbench.scoring.prepare.SceneReference.prepare`:
    alignment, resolution, border and valid masks; the uncertainty is aligned and upsampled like the disparity).
    The default non-finite rules apply even under toolkit rules. None when the prediction has no
    uncertainty map."""
    found = scene_sparsifications(scene, prediction, rules, (measure,), fractions, normalize)
    return next(iter(found.values())) if found else None


def scene_sparsifications(scene: Scene, prediction, rules: ScoringRules | None = None,
                          measures: Sequence[str] = ("abs",),
                          fractions: Sequence[float] | np.ndarray = DEFAULT_FRACTIONS,
                          normalize: bool = False) -> dict[str, Sparsification]:
    """:func:`scene_sparsification` for several measures, preparing the prediction once: canonical
    measure id -> Sparsification (empty when the prediction has no uncertainty map)."""
    if prediction.uncertainty is None:
        return {}
    reference = SceneReference(scene, dataclasses.replace(rules or ScoringRules(), toolkit=False))
    prepared = reference.prepare(prediction.disparity, reference.general_resolution(),
                                 uncertainty=prediction.uncertainty)
    se = ScoredErrors.from_prepared(prepared)
    scored_unc = prepared.uncertainty.ravel()[se.flat_index]
    out = {}
    for measure in measures:
        loss, mid, unit = pixel_loss(se.errors, measure)
        keep = np.isfinite(loss)
        out[mid] = sparsification_from_loss(loss[keep], scored_unc[keep], mid, unit, fractions, normalize)
    return out


def average_sparsification(items: Sequence[Sparsification]) -> Sparsification:
    """Mean curves over scenes (each scene weighted equally, as the benchmark's averages); the AUSE
    of the mean equals the mean of the AUSEs. All items must share fractions, measure and normalization."""
    if not items:
        raise ValueError("nothing to average")
    first = items[0]
    for it in items[1:]:
        if (it.measure, it.normalized) != (first.measure, first.normalized) or \
                not np.array_equal(it.fractions, first.fractions):
            raise ValueError("sparsification results differ in fractions, measure or normalization")
    mean = lambda name: np.mean([getattr(it, name) for it in items], axis=0)  # noqa: E731
    return Sparsification(first.fractions, mean("curve"), mean("oracle"), mean("random"), first.measure, first.unit,
                          int(sum(it.n_pixels for it in items)), first.normalized)


# --------------------------------------------------------------------------- evaluation hook and table

REPORT_MEASURES: tuple[str, ...] = ("abs", "badpix_0.07")


class UncertaintyCollector:
    """Prediction hook for ``runner.evaluate(on_prediction=...)``: the sparsification of every
    (method label, scene) whose prediction carries an uncertainty map, per measure of ``measures``,
    in ``self.items[(label, scene, measure)]``. Methods without uncertainty are listed in ``self.without``."""

    def __init__(self, rules=None, measures: Sequence[str] = REPORT_MEASURES) -> None:
        self.rules = rules
        self.measures = tuple(dict.fromkeys(pixel_loss(np.zeros(1), m)[1] for m in measures))  # canonical ids
        self.items: dict[tuple[str, str, str], Sparsification] = {}
        self.without: set[str] = set()

    def __call__(self, method, scene, pred) -> None:
        if not scene.has_gt():
            return
        if pred.uncertainty is None:
            self.without.add(method.label)
            return
        for measure, sp in scene_sparsifications(scene, pred, self.rules, self.measures).items():
            self.items[(method.label, scene.name, measure)] = sp


def uncertainty_table(items: Mapping[tuple[str, str, str], Sparsification]):
    """Long DataFrame with columns method, scene, measure, unit, ause, aurg, full (the measure on all
    pixels), oracle_half (the measure after removing the worst half by true error), n_pixels; a scene
    ``average`` per (method, measure) averages the curves over scenes (equal weights)."""
    rows = []

    def row(method: str, scene: str, sp: Sparsification) -> dict:
        half = int(np.argmin(np.abs(sp.fractions - 0.5)))
        return {"method": method, "scene": scene, "measure": sp.measure, "unit": sp.unit, "ause": sp.ause,
                "aurg": sp.aurg, "full": float(sp.curve[0]), "oracle_half": float(sp.oracle[half]),
                "n_pixels": sp.n_pixels}

    groups: dict[tuple[str, str], list[Sparsification]] = {}
    for (method, scene, measure), sp in items.items():
        rows.append(row(method, scene, sp))
        groups.setdefault((method, measure), []).append(sp)
    for (method, _), sps in groups.items():
        if len(sps) > 1:
            rows.append(row(method, "average", average_sparsification(sps)))
    return pd.DataFrame(rows, columns=["method", "scene", "measure", "unit", "ause", "aurg", "full", "oracle_half",
                                       "n_pixels"])
