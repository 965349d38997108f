"""Run methods on scenes and score them: the engine behind ``lfbench evaluate`` and ``demo``."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable, Sequence

import numpy as np
from tqdm import tqdm

from lfbench.data.scene import Scene
from lfbench.method.base import Method, Prediction
from lfbench.results import Record, Results, RunInfo
from lfbench.scoring.metrics import GENERAL_METRICS, Metric
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import score_scene
from lfbench.utils.errors import DataError
from lfbench.utils.names import FileNames

log = logging.getLogger(__name__)

PredictionHook = Callable[[Method, Scene, Prediction], None]
_NONFINITE_RULE = {False: "counted as bad pixels",
                   True: "toolkit rule: BadPix counts NaN as good, MSE and Q25 leave them out"}


def evaluate(methods: Sequence[Method], scenes: Sequence[Scene], *,
             metrics: Sequence[Metric] | Callable[[Scene], Sequence[Metric]] = GENERAL_METRICS,
             rules: ScoringRules = ScoringRules(), on_prediction: PredictionHook | None = None,
             progress: bool = True) -> Results:
    """Run every method on every scene with ground truth and score it.

    ``metrics``: the metrics for every scene, or a function of the scene giving them (e.g.
    ``lfbench.scoring.score.applicable_metrics``).

    A (method, scene) pair the method cannot serve (e.g. no stored map) is skipped with a warning
    (logger ``lfbench.runs.runner``); a method that can serve none of the scenes is an error
    (DataError, raised before any work). ``on_prediction`` sees each prediction (to save maps or draw figures).
    """
    check_names([(methods, scenes)])
    reasons = check_runnable(methods, scenes)  # each (method, scene) asked once
    results = Results(meta={"scoring": rules.to_meta()})
    pairs = [(m, s, r) for m, row in zip(methods, reasons, strict=True) for s, r in zip(scenes, row, strict=True)]
    bar = tqdm(pairs, desc="evaluate", unit="run", disable=None if progress else True, file=sys.stderr, leave=False)
    for method, scene, reason in bar:
        bar.set_postfix_str(f"{method.label} / {scene.name}"[-60:])
        if reason is not None:
            log.warning("lfbench: skipping %s on %s: %s", method.label, scene.name, reason)
            continue
        pred = method.run(scene)
        if on_prediction is not None:
            on_prediction(method, scene, pred)
        scene_metrics = metrics(scene) if callable(metrics) else metrics
        score = score_scene(scene, pred.disparity, scene_metrics, rules, source=f"{method.label} on {scene.name}",
                            runtime_s=pred.runtime_s)
        for metric_id, value in score.values.items():
            results.records.append(Record(method.label, scene.name, metric_id, value, score.resolution[metric_id]))
        results.runs.append(RunInfo(method.label, scene.name, float(pred.runtime_s or np.nan), score.nonfinite_pixels,
                                    list(score.aligned_from) if score.aligned_from else None, score.notes))
        for note in score.notes:
            log.warning("lfbench: %s on %s: %s", method.label, scene.name, note)
        if score.nonfinite_pixels:
            log.warning("lfbench: %s on %s: %d non-finite pixels inside the evaluation mask (%s)", method.label,
                        scene.name, score.nonfinite_pixels, _NONFINITE_RULE[rules.toolkit])
    return results


def check_names(groups: Sequence[tuple[Sequence[Method], Sequence[Scene]]], label: str | None = None) -> None:
    """DataError before any work when the records or files of a run of ``groups`` ((methods, scenes)
    pairs, each method on each of its scenes) would collide: a (method, scene) pair twice (the same
    method given twice), two methods or two scenes whose names are one file name (lfbench.utils.names),
    two scenes of one name from different folders (lfbench.data.scene.check_scene_names). ``label``:
    the name the records get instead of the method's label."""
    from lfbench.data.scene import check_scene_names

    check_scene_names([s for _, scenes in groups for s in scenes])
    names = FileNames("method label")
    pairs: set[tuple[str, str]] = set()
    for methods, scenes in groups:
        for method in methods:
            name = label if label is not None else method.label
            names(name)
            for scene in scenes:
                if (name, scene.name) in pairs:
                    raise DataError(f"method {name!r} would run on scene {scene.name!r} twice (given twice?): its "
                                    "records would be duplicated")
                pairs.add((name, scene.name))


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
