"""Run methods on scenes and score them: the engine behind ``lfbench evaluate``, ``demo`` and the ablation cells
(through lfbench.runs.folder), scene by scene (lfbench.runs.pool)."""

from __future__ import annotations

import logging
import sys
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np
from tqdm import tqdm

from lfbench.data.scene import Scene
from lfbench.method.base import Method, Prediction
from lfbench.results import Record, Results, RunInfo
from lfbench.runs.pool import ScoringPool
from lfbench.scoring.metrics import GENERAL_METRICS, Metric
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import SceneScore
from lfbench.utils.errors import DataError

log = logging.getLogger(__name__)

PredictionHook = Callable[[Method, Scene, Prediction], None]
_NONFINITE_RULE = {False: "counted as bad pixels",
                   True: "toolkit rule: BadPix counts NaN as good, MSE and Q25 leave them out"}


def evaluate(methods: Sequence[Method], scenes: Sequence[Scene], *,
             metrics: Sequence[Metric] | Callable[[Scene], Sequence[Metric]] = GENERAL_METRICS,
             rules: ScoringRules = ScoringRules(), on_prediction: PredictionHook | None = None,
             progress: bool = True, jobs: int = 1) -> Results:
    """Run every method on every scene with ground truth and score it.

    ``metrics``: the metrics for every scene, or a function of the scene giving them (e.g.
    ``lfbench.scoring.score.applicable_metrics``).

    Scene by scene: every method runs on a scene, then the scene's predictions are scored together
    (lfbench.runs.pool: what does not depend on the method is made once per scene), in ``jobs`` worker
    processes when more than 1, and the records come out method by method, scene by scene, whatever
    ``jobs`` is. A (method, scene) pair the method cannot serve (e.g. no stored map) is skipped with a
    warning (logger ``lfbench.runs.runner``); a method that can serve none of the scenes is an error
    (DataError, raised before any work). ``on_prediction`` sees each prediction (to save maps or draw
    figures), scene by scene. Their names are trusted: the entry point checked them once, before any work
    (lfbench.runs.folder.evaluate_to_folder: lfbench.results.check_names).
    """
    reasons = check_runnable(methods, scenes)  # each (method, scene) asked once
    results = Results(meta={"scoring": rules.to_meta()})
    bar = tqdm(total=len(methods) * len(scenes), desc="evaluate", unit="run", disable=None if progress else True,
               file=sys.stderr, leave=False)
    scored: dict[tuple[int, int], tuple[Method, Scene, Prediction, SceneScore]] = {}
    pending: deque = deque()

    def collect(block: bool) -> None:
        while pending and (block or len(pending) > pool.jobs):
            j, batch, future = pending.popleft()
            for (i, method, pred), score in zip(batch, future.result(), strict=True):
                scored[i, j] = method, scenes[j], pred, score

    with ScoringPool(jobs) as pool:
        for j, scene in enumerate(scenes):
            batch = []
            for i, method in enumerate(methods):
                bar.set_postfix_str(f"{method.label} / {scene.name}"[-60:])
                bar.update()
                if reasons[i][j] is not None:
                    log.warning("lfbench: skipping %s on %s: %s", method.label, scene.name, reasons[i][j])
                    continue
                pred = method.run(scene, max_crop=rules.border_px)
                if on_prediction is not None:
                    on_prediction(method, scene, pred)
                batch.append((i, method, pred))
            release_views(scene)  # its predictions are made: one scene's views in memory at a time
            if batch:
                scene_metrics = metrics(scene) if callable(metrics) else metrics
                predictions = [(p.disparity, p.runtime_s, f"{m.label} on {scene.name}") for _, m, p in batch]
                pending.append((j, batch, pool.submit(scene, predictions, scene_metrics, rules)))
            collect(block=False)
        collect(block=True)
    bar.close()
    for i, j in sorted(scored):
        _record(results, *scored[i, j], rules)
    return results


def release_views(scene: Scene) -> None:
    """Let ``scene`` forget its loaded views (lfbench.data.scene.Scene.release_views; a light field held in memory
    by its caller keeps them)."""
    release = getattr(scene, "release_views", None)
    if release is not None:
        release()


def _record(results: Results, method: Method, scene: Scene, pred: Prediction, score: SceneScore,
            rules: ScoringRules) -> None:
    """Add one (method, scene) score to ``results`` and log its notes."""
    for metric_id, value in score.values.items():
        results.records.append(Record(method.label, scene.name, metric_id, value, score.resolution[metric_id]))
    results.runs.append(RunInfo(method.label, scene.name, float(pred.runtime_s or np.nan), score.nonfinite_pixels,
                                list(score.aligned_from) if score.aligned_from else None, score.notes))
    for note in score.notes:
        log.warning("lfbench: %s on %s: %s", method.label, scene.name, note)
    if score.nonfinite_pixels:
        log.warning("lfbench: %s on %s: %d non-finite pixels inside the evaluation mask (%s)", method.label,
                    scene.name, score.nonfinite_pixels, _NONFINITE_RULE[rules.toolkit])


def check_runnable(methods: Sequence[Method], scenes: Sequence[Scene]) -> list[list[str | None]]:
    """Why each method cannot run on each scene (``available_for``: None where it can), one row per
    method, one entry per scene. DataError when a method can run on none of ``scenes`` (its results
    would silently be empty)."""
    table = []
    for method in methods:
        reasons = [method.available_for(scene) for scene in scenes]
        if scenes and all(r is not None for r in reasons):
            names = ", ".join(s.name for s in scenes[:3]) + (" ..." if len(scenes) > 3 else "")
            raise DataError(f"{method.label} cannot run on any selected scene ({names}): {reasons[0]}")
        table.append(reasons)
    return table
