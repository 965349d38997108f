"""Run methods on scenes and score them: the engine behind ``lfbench evaluate``, ``demo`` and the ablation cells
(through lfbench.runs.folder), scene by scene (:func:`score_scenes`).

Scoring, scene by scene, in this process or in worker processes (``lfbench evaluate --jobs N``): each task
(:class:`ScoringTask`) is one scene with every method's prediction on it
(:func:`lfbench.scoring.score.score_predictions`): the scene's reference (ground truth, masks, scored pixels) is
made once for all of them in the process that scores it and dropped after, so memory holds a few scenes, not
every method's. With ``jobs`` > 1 the tasks run in lfbench's one process pool
(lfbench.utils.executor.ProcessPool: ``jobs`` spawned workers that never import torch, the next scene's
predictions made while they score); a worker reopens the scene from its folder (lfbench.data.scene.Scene
pickles as its folder) and looks its metrics up by id (a task pickles its metrics as their ids), so that
neither the scene's loaded views nor a metric's function cross the process boundary. Light fields without a
folder (in-memory scenes) are scored here. The numbers are the same either way: the same function scores
them. A worker that dies (SIGKILL, the out-of-memory killer) stops the run with one line naming the scene it
was scoring (:class:`lfbench.utils.errors.RunFailed`, exit 1; the pool's marks). Scoring allocates and frees
arrays of a high-resolution scene's size (~100 MB) for every prediction; the process that scores keeps freed
heap for reuse (lfbench.utils.malloc.retain_freed_memory) instead of page-faulting it in again each time.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from lfbench.data.scene import Scene
from lfbench.method.base import Method, Prediction
from lfbench.results import Record, Results, RunInfo
from lfbench.scoring.metrics import GENERAL_METRICS, METRICS, Metric, get_metric
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import SceneScore, score_predictions
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.executor import ClusterOptions, ProcessPool
from lfbench.utils.flags import JOBS
from lfbench.utils.malloc import retain_freed_memory

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
    (:func:`score_scenes`: what does not depend on the method is made once per scene), in ``jobs`` worker
    processes when more than 1 (the next scene's predictions made while they score), and the records come out
    method by method, scene by scene, whatever ``jobs`` is. A (method, scene) pair the method cannot serve (e.g.
    no stored map) is skipped with a warning (logger ``lfbench.runs.runner``); a method that can serve none of the
    scenes is an error (DataError, raised before any work). ``on_prediction`` sees each prediction (to save maps
    or draw figures), scene by scene. Their names are trusted: the entry point checked them once, before any work
    (lfbench.runs.folder.evaluate_to_folder: lfbench.results.check_names).
    """
    JOBS.require(jobs)
    reasons = check_runnable(methods, scenes)  # each (method, scene) asked once
    results = Results(meta={"scoring": rules.to_meta()})
    bar = tqdm(total=len(methods) * len(scenes), desc="evaluate", unit="run", disable=None if progress else True,
               file=sys.stderr, leave=False)
    made: dict[int, list[tuple[int, Method, Prediction]]] = {}  # scene index -> its predictions
    scored: dict[tuple[int, int], tuple[Method, Scene, Prediction, SceneScore]] = {}

    def tasks() -> Iterable[ScoringTask]:
        """Scene by scene, as the scoring asks for the next one: every method's prediction on it."""
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
                made[j] = batch
                predictions = [(p.disparity, p.runtime_s, f"{m.label} on {scene.name}") for _, m, p in batch]
                yield ScoringTask(j, scene, predictions, tuple(metrics(scene) if callable(metrics) else metrics),
                                  rules)

    def collect(done: tuple[int, list[SceneScore]]) -> None:
        j, scores = done
        for (i, method, pred), score in zip(made.pop(j), scores, strict=True):
            scored[i, j] = method, scenes[j], pred, score

    score_scenes(tasks(), jobs=jobs, on_done=collect)
    bar.close()
    for i, j in sorted(scored):
        _record(results, *scored[i, j], rules)
    return results


@dataclass(frozen=True)
class ScoringTask:
    """One scene's predictions to score: ``index`` (returned with the scores), the scene, the predictions
    (disparity, runtime s or None, source), the metrics and the rules. Pickled (to a worker), its metrics
    travel as their ids, looked up in the worker's registry, and its scene as its folder."""

    index: int
    scene: Scene
    predictions: Sequence[tuple[np.ndarray, float | None, str]]
    metrics: Sequence[Metric]
    rules: ScoringRules

    def __reduce__(self):
        return _task_in_worker, (self.index, self.scene, list(self.predictions), [m.id for m in self.metrics],
                                 self.rules)


def _task_in_worker(index: int, scene: Scene, predictions, metric_ids: Sequence[str],
                    rules: ScoringRules) -> ScoringTask:
    return ScoringTask(index, scene, predictions, tuple(get_metric(m) for m in metric_ids), rules)


def score_task(task: ScoringTask) -> tuple[int, list[SceneScore]]:
    """``task``'s index and the :class:`SceneScore` of each of its predictions, in order (in the process that
    scores, freed heap is kept for the next scene: lfbench.utils.malloc.retain_freed_memory)."""
    retain_freed_memory()
    return task.index, score_predictions(task.scene, task.predictions, task.metrics, task.rules)


#: The one line of a scoring worker that died (lfbench.utils.executor.ProcessPool: ``names`` its scene).
SCORING_WORKER_DIED = ("a scoring worker process died (killed, or out of memory) while scoring scene {names}: "
                       "nothing of this run was written; run the command again (--jobs 1 scores in this process)")


def score_scenes(tasks: Iterable[ScoringTask], *, jobs: int = 1,
                 on_done: Callable[[tuple[int, list[SceneScore]]], None]) -> None:
    """Score each task (:func:`score_task`), each result to ``on_done`` as it comes (in order with ``jobs`` 1).
    ``tasks`` is pulled as the scoring goes: with ``jobs`` > 1, at most ``jobs`` scenes are scored in worker
    processes while the next one is made (lfbench.utils.executor.ProcessPool, ``threads=None``: the workers
    never import torch); a task whose scene is held in memory (not a :class:`Scene`) is scored here. SpecError
    for jobs out of range (the flag's check) and, with jobs > 1, for a metric a worker cannot look up (not the
    registered metric of its id); RunFailed naming the scene of a worker that died."""
    JOBS.require(jobs)
    pool = ProcessPool(ClusterOptions("pool"), jobs=jobs)
    here = pool.runs_here(None)

    def handed() -> Iterable[ScoringTask]:
        for task in tasks:
            if not here and not isinstance(task.scene, Scene):
                on_done(score_task(task))  # no folder to reopen it from
                continue
            for metric in task.metrics if not here else ():  # a worker knows the registered metrics only
                if METRICS.find(metric.id) != metric:
                    raise SpecError(f"metric {metric.id!r} is not a registered metric: score it with jobs=1")
            yield task

    pool.map(score_task, handed(), labels=lambda task: task.scene.name, threads=None, on_done=on_done,
             died=SCORING_WORKER_DIED)


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
