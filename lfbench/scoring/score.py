"""Scoring a disparity map on a scene under the benchmark's rules: :func:`score_scene`.

Each metric is scored at the resolution the rules give it (:func:`lfbench.scoring.rules.metric_resolution`)
on the prediction as :meth:`lfbench.scoring.prepare.SceneReference.prepare` makes it ready (alignment of a
cropped map, float32, the toolkit's upsampling, border and valid mask), prepared once per resolution; a
region metric adds its own mask. A pixel-wise metric (``Metric.pixelwise``) is computed from the prediction's
errors at its pixels, gathered once per region and shared by every metric of that region (|error| once for
every BadPix threshold, MSE and the quantiles); the others from the maps. What does not depend on the method
is the scene's :class:`~lfbench.scoring.prepare.SceneReference`: pass one reference for every prediction
scored on a scene. :func:`applicable_metrics` lists what a scene supports.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lfbench.data.scene import HIGHRES, LOWRES, Scene
from lfbench.scoring.base import Metric
from lfbench.scoring.general import GENERAL_METRICS, nonfinite_count
from lfbench.scoring.prepare import Prepared, SceneReference
from lfbench.scoring.region_metrics import scene_metrics
from lfbench.scoring.rules import ScoringRules, metric_resolution

__all__ = ["SceneScore", "applicable_metrics", "score_predictions", "score_scene"]


@dataclass
class SceneScore:
    """Scores of one prediction on one scene: metric id -> value, and how it was scored."""

    scene: str
    values: dict[str, float]
    resolution: dict[str, str]
    nonfinite_pixels: int
    aligned_from: tuple[int, int] | None = None
    notes: list[str] = field(default_factory=list)


def applicable_metrics(scene: Scene, rules: ScoringRules = ScoringRules(),
                       general: Sequence[Metric] = GENERAL_METRICS) -> list[Metric]:
    """The ``general`` metrics (default lfbench's own; a run passes its protocol's,
    :func:`lfbench.scoring.metrics.scored_metrics`) plus the region / stratified metrics whose mask files exist
    for ``scene`` (at a resolution :func:`lfbench.scoring.rules.metric_resolution` can score them at), so that
    ``score_scene(scene, pred, applicable_metrics(scene))`` scores everything the scene supports."""
    regional = [m for m in scene_metrics(scene) if metric_resolution(scene, m, rules) is not None]
    return [*general, *regional]


def score_scene(scene: Scene, pred: np.ndarray, metrics: Sequence[Metric] = GENERAL_METRICS,
                rules: ScoringRules = ScoringRules(), source: str = "prediction", *,
                runtime_s: float | None = None, reference: SceneReference | None = None) -> SceneScore:
    """Score ``pred`` (H, W) disparity on ``scene`` with the benchmark's masks and resolution rules.

    ``reference``: the scene's :class:`~lfbench.scoring.prepare.SceneReference` under ``rules`` (what does
    not depend on the method, kept for every method scored on the scene); made here when None.
    Runtime metrics (``Metric.is_runtime``) take ``runtime_s``, the runtime in s the method reports for
    this scene; they give no value (no record) when it reports none (None or NaN) or one that is not a
    positive number (noted), and are recorded at low resolution (the resolution of the map timed)."""
    if reference is None:
        reference = SceneReference(scene, rules)
    else:
        reference.check_serves(scene, rules)
    h, w = reference.spatial_size
    pred, aligned_from = reference.align(pred, source)
    notes = []
    if aligned_from is not None:
        notes.append(f"{aligned_from[1]}x{aligned_from[0]} prediction aligned to the centre of {w}x{h}")
    values: dict[str, float] = {}
    resolution: dict[str, str] = {}
    prepared: dict[str, Prepared] = {}  # the prediction at each resolution a metric asks for
    nonfinite = nonfinite_count(pred, reference.evaluation_mask(LOWRES))
    # the errors of each region are dropped after the last metric that reads them: one region's in memory at a time
    last_use = {(reference.metric_resolution(m), m.mask_name): k for k, m in enumerate(metrics)
                if m.pixelwise is not None and not m.is_runtime}
    for k, metric in enumerate(metrics):
        if metric.is_runtime:
            continue
        res = reference.metric_resolution(metric)
        if res is None:  # a mask file the metric needs is absent: it does not apply to this scene
            continue
        if res not in prepared:
            if res == HIGHRES and not reference.has_gt(HIGHRES):  # a high-res-only metric without high-res gt
                continue
            prepared[res] = reference.prepare(pred, res, source)
        p = prepared[res]
        if metric.mask_name is not None and metric.mask_name not in reference.mask_names(res):
            continue
        if metric.pixelwise is not None:  # pixel-wise: from the errors at its pixels, gathered once per region
            values[metric.id] = metric.score_pixels(p.errors(metric.mask_name), toolkit=rules.toolkit)
            if last_use.get((res, metric.mask_name)) == k:  # no later metric reads them: their memory is the next's
                p.release(metric.mask_name)
        else:
            context = {"scene": reference, "resolution": res} if metric.needs_scene else {}
            values[metric.id] = metric(p.gt, p.pred, reference.scored_mask(res, metric.mask_name),
                                       toolkit=rules.toolkit, **context)
        resolution[metric.id] = res
    timed = [m for m in metrics if m.is_runtime]
    for metric in timed:
        value = metric.score_runtime(runtime_s)
        if value is not None:
            values[metric.id], resolution[metric.id] = value, LOWRES
    if timed and runtime_s is not None and not np.isnan(runtime_s) and timed[0].score_runtime(runtime_s) is None:
        notes.append(f"runtime {runtime_s:g} s is not a positive number: no runtime record")
    return SceneScore(scene=scene.name, values=values, resolution=resolution, nonfinite_pixels=nonfinite,
                      aligned_from=aligned_from, notes=notes)


def score_predictions(scene: Scene, predictions: Sequence[tuple[np.ndarray, float | None, str]],
                      metrics: Sequence[Metric] = GENERAL_METRICS, rules: ScoringRules = ScoringRules()
                      ) -> list[SceneScore]:
    """Score several predictions on one scene (e.g. every method's): ``predictions`` are (disparity (H, W),
    runtime in s or None, source: the name errors give it). One :class:`SceneReference` serves them all, so
    the ground truth, masks, upsampling index and scored pixels are made once; it is dropped on return (the
    memory of one scene). Each score is :func:`score_scene`'s."""
    reference = SceneReference(scene, rules)
    return [score_scene(scene, disparity, metrics, rules, source, runtime_s=runtime_s, reference=reference)
            for disparity, runtime_s, source in predictions]
