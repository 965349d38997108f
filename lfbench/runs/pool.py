"""Scoring scene by scene, in this process or in worker processes (``lfbench evaluate --jobs N``).

Each task is one scene with every method's prediction on it (:func:`lfbench.scoring.score.score_predictions`): the
scene's reference (ground truth, masks, scored pixels) is made once for all of them in the process that scores it
and dropped after, so memory holds a few scenes, not every method's. With ``jobs`` > 1 the tasks run in a pool of
``jobs`` worker processes (spawned: a parent's threads are not inherited), at most ``jobs`` tasks in flight beyond
the one being prepared; a worker reopens the scene from its folder and looks its metrics up by id, so that neither
the scene's loaded views nor a metric's function cross the process boundary (a pattern-named scene, e.g. UrbanLF-
Syn's, is pickled as its folder and layout and reopened). Light fields without a folder (in-memory scenes) are
scored here. The numbers are the same either way: the same function scores them. Scoring allocates and frees
arrays of a high-resolution scene's size (~100 MB) for every prediction; the process that scores keeps freed heap
for reuse (lfbench.utils.malloc.retain_freed_memory) instead of page-faulting it in again each time.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lfbench.data.pattern import PatternScene
from lfbench.data.scene import Scene
from lfbench.scoring.metrics import Metric, find_metric, get_metric
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import SceneScore, score_predictions
from lfbench.utils.errors import SpecError
from lfbench.utils.malloc import retain_freed_memory

__all__ = ["ScoringPool"]

Predictions = Sequence[tuple[np.ndarray, float | None, str]]


def _score_in_worker(path: str, category: str, predictions: Predictions, metric_ids: Sequence[str],
                     rules: ScoringRules) -> list[SceneScore]:
    retain_freed_memory()
    return score_predictions(Scene(Path(path), category), predictions, [get_metric(m) for m in metric_ids], rules)


def _score_scene_in_worker(scene: PatternScene, predictions: Predictions, metric_ids: Sequence[str],
                           rules: ScoringRules) -> list[SceneScore]:
    retain_freed_memory()
    return score_predictions(scene, predictions, [get_metric(m) for m in metric_ids], rules)


class _Done:
    """A result computed in this process, answering as a future does."""

    def __init__(self, value: list[SceneScore]) -> None:
        self.value = value

    def result(self) -> list[SceneScore]:
        return self.value


class ScoringPool:
    """Scores one scene's predictions per :meth:`submit`, in ``jobs`` worker processes (1: here, in order).
    A context manager: leaving it waits for (or, on an error, cancels) the work in flight."""

    def __init__(self, jobs: int = 1) -> None:
        if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
            raise SpecError(f"jobs must be a positive integer, got {jobs!r}")
        self.jobs = jobs
        self._executor: cf.ProcessPoolExecutor | None = None
        if jobs == 1:
            retain_freed_memory()

    def __enter__(self) -> ScoringPool:
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=exc[0] is not None)
            self._executor = None

    def submit(self, scene: Any, predictions: Predictions, metrics: Sequence[Metric], rules: ScoringRules):
        """Score ``predictions`` (disparity, runtime s or None, source) on ``scene`` with ``metrics`` under
        ``rules``; returns an object whose ``result()`` is the list of :class:`SceneScore`, in order."""
        if self.jobs == 1 or not isinstance(scene, Scene | PatternScene):
            return _Done(score_predictions(scene, predictions, metrics, rules))
        ids = [m.id for m in metrics]
        for metric in metrics:  # a worker knows the registered metrics only
            if find_metric(metric.id) != metric:
                raise SpecError(f"metric {metric.id!r} is not a registered metric: score it with jobs=1")
        if self._executor is None:
            self._executor = cf.ProcessPoolExecutor(self.jobs, mp_context=multiprocessing.get_context("spawn"))
        if isinstance(scene, PatternScene):  # pickled as its folder and layout (PatternScene.__reduce__)
            return self._executor.submit(_score_scene_in_worker, scene, list(predictions), ids, rules)
        return self._executor.submit(_score_in_worker, str(scene.path), scene.category, list(predictions), ids,
                                     rules)
