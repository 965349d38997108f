"""Scoring scene by scene, in this process or in worker processes (``lfbench evaluate --jobs N``).

Each task is one scene with every method's prediction on it (:func:`lfbench.scoring.score.score_predictions`):
the scene's reference (ground truth, masks, scored pixels) is made once for all of them in the process that
scores it and dropped after, so memory holds a few scenes, not every method's. With ``jobs`` > 1 the tasks
run in a pool of ``jobs`` worker processes (spawned: a parent's threads are not inherited), at most ``jobs``
tasks in flight beyond the one being prepared; a worker reopens the scene from its folder and looks its
metrics up by id, so that neither the scene's loaded views nor a metric's function cross the process
boundary. Light fields without a folder (in-memory scenes) are scored here. The numbers are the same
either way: the same function scores them. A worker that dies (SIGKILL, the out-of-memory killer) stops the
run with one line naming the scene it was scoring (:class:`lfbench.utils.errors.RunFailed`, exit 1): each
worker marks the scene it is scoring in a file named by its pid, and a worker the pool stops because
another one died (SIGTERM) removes its mark first, so that the marks left name the dead worker's scene.
Scoring allocates and frees arrays of a high-resolution scene's size (~100 MB) for every prediction; the
process that scores keeps freed heap for reuse (lfbench.utils.malloc.retain_freed_memory) instead of
page-faulting it in again each time.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import shutil
import signal
import tempfile
from collections.abc import Sequence
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import numpy as np

from lfbench.data.scene import Scene
from lfbench.scoring.metrics import METRICS, Metric, get_metric
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import SceneScore, score_predictions
from lfbench.utils.errors import RunFailed, SpecError
from lfbench.utils.flags import JOBS
from lfbench.utils.malloc import retain_freed_memory

__all__ = ["ScoringPool", "KILL_WORKER_ENV"]

Predictions = Sequence[tuple[np.ndarray, float | None, str]]


#: Test hook: a scoring worker about to score the scene of this name SIGKILLs itself, as the kernel's
#: out-of-memory killer would (tests/test_scoring_classes.py checks what a run does then).
KILL_WORKER_ENV = "LFBENCH_TEST_KILL_SCORING_WORKER"

_marks: Path | None = None  # in a worker: the folder of "scoring now" marks


def _init_worker(marks: str) -> None:
    global _marks
    _marks = Path(marks)
    signal.signal(signal.SIGTERM, _stopped_by_pool)


def _stopped_by_pool(signum: int, frame: Any) -> None:
    """SIGTERM: the pool stops this (healthy) worker because another one died; its mark goes first."""
    if _marks is not None:
        (_marks / str(os.getpid())).unlink(missing_ok=True)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGTERM)


def _score_in_worker(scene: Scene, predictions: Predictions, metric_ids: Sequence[str],
                     rules: ScoringRules) -> list[SceneScore]:
    """Score in a worker: the scene arrives pickled as its folder (lfbench.data.scene.Scene.__reduce__: reopened
    here, never its loaded views). The scene is marked as being scored here."""
    retain_freed_memory()
    mark = None if _marks is None else _marks / str(os.getpid())
    if mark is not None:
        mark.write_text(scene.name, encoding="utf-8")
    try:
        if os.environ.get(KILL_WORKER_ENV) == scene.name:
            os.kill(os.getpid(), signal.SIGKILL)
        return score_predictions(scene, predictions, [get_metric(m) for m in metric_ids], rules)
    finally:
        if mark is not None:
            mark.unlink(missing_ok=True)


class _Task:
    """A scene scored in a worker: ``result()`` is its scores, or RunFailed naming the scene a dead worker
    was scoring."""

    def __init__(self, pool: ScoringPool, future: cf.Future, scene: str) -> None:
        self.pool, self.future, self.scene = pool, future, scene

    def result(self) -> list[SceneScore]:
        try:
            return self.future.result()
        except BrokenProcessPool:
            raise self.pool.worker_died(self.scene) from None


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
        JOBS.require(jobs)
        self.jobs = jobs
        self._executor: cf.ProcessPoolExecutor | None = None
        self._marks: Path | None = None  # the workers' "scoring now" marks (a temporary folder)
        if jobs == 1:
            retain_freed_memory()

    def __enter__(self) -> ScoringPool:
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=exc[0] is not None)
            self._executor = None
        if self._marks is not None:
            shutil.rmtree(self._marks, ignore_errors=True)
            self._marks = None

    def worker_died(self, scene: str) -> RunFailed:
        """The error of a worker that died: the pool is shut down (the other workers stopped, their marks
        removed) and the marks left name the scene(s) it was scoring (``scene``, the task that saw it, when
        it died before marking one)."""
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None
        marked = sorted(p.read_text(encoding="utf-8", errors="replace") for p in self._marks.iterdir()) \
            if self._marks is not None and self._marks.is_dir() else []
        names = " or ".join(repr(n) for n in marked) if marked else repr(scene)
        return RunFailed(f"a scoring worker process died (killed, or out of memory) while scoring scene {names}: "
                         "nothing of this run was written; run the command again (--jobs 1 scores in this process)")

    def submit(self, scene: Any, predictions: Predictions, metrics: Sequence[Metric], rules: ScoringRules):
        """Score ``predictions`` (disparity, runtime s or None, source) on ``scene`` with ``metrics`` under
        ``rules``; returns an object whose ``result()`` is the list of :class:`SceneScore`, in order (RunFailed
        naming the scene when the worker scoring it died)."""
        if self.jobs == 1 or not isinstance(scene, Scene):
            return _Done(score_predictions(scene, predictions, metrics, rules))
        ids = [m.id for m in metrics]
        for metric in metrics:  # a worker knows the registered metrics only
            if METRICS.find(metric.id) != metric:
                raise SpecError(f"metric {metric.id!r} is not a registered metric: score it with jobs=1")
        if self._executor is None:
            self._marks = Path(tempfile.mkdtemp(prefix="lfbench-scoring-"))
            self._executor = cf.ProcessPoolExecutor(self.jobs, mp_context=multiprocessing.get_context("spawn"),
                                                    initializer=_init_worker, initargs=(str(self._marks),))
        try:
            future = self._executor.submit(_score_in_worker, scene, list(predictions), ids, rules)
        except BrokenProcessPool:  # a worker died since the last task was handed out
            raise self.worker_died(scene.name) from None
        return _Task(self, future, scene.name)
