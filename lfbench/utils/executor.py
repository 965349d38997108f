"""Where lfbench's work runs (the ablation's cells, the scoring of scenes, generated scenes): one
:class:`Executor` interface (``map`` a function over items, each result to a callback as it comes) with its
implementations in one registry, :data:`EXECUTORS`, from which ``lfbench ablate --executor`` takes its choices:

- ``inline``: one item after the other in this process;
- ``pool``: ``--jobs N`` worker processes on this machine, each with its own GPU (round-robin over the
  visible CUDA devices; the CPU when there are none); one job or one item runs inline;
- ``local`` / ``slurm``: each item as a job through submitit (lfbench.ablation.jobs; ``slurm``: one job
  array on a cluster; ``local``: the same path as local subprocesses).

A new executor is a subclass of :class:`Executor` added to :data:`EXECUTORS`; the runner
(lfbench.ablation.runner) and the command line need no change.

Every path runs :func:`lfbench.ablation.cell.run_cell`, which skips a finished cell and resumes an
interrupted one from its checkpoint, so re-running the command after a crash, a pre-emption or a
cancelled job continues where it stopped.

The same pool runs lfbench's other work in worker processes: ``lfbench evaluate --jobs N`` scores scene by
scene through :class:`ProcessPool` (lfbench.runs.runner.score_scenes: its items come from a generator that
runs the methods on the next scene only when a worker is about to be free) and ``lfbench synth --workers N``
writes its scenes through it (lfbench.data.synth.write_scenes); both pass ``threads=None``, so that their
workers never import torch nor look for GPUs. A worker that dies (SIGKILL, the out-of-memory killer) stops
any map with one line naming the item it was running (:class:`lfbench.utils.errors.RunFailed`, exit 1).
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import tempfile
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, TypeVar

from lfbench.utils.errors import RunFailed, SpecError
from lfbench.utils.flags import flag_name
from lfbench.utils.options import check_options, option
from lfbench.utils.registry import Lazy, Registry

_log = logging.getLogger(__name__)
Log = Callable[[str], None]
Item = TypeVar("Item")
Result = TypeVar("Result")
#: The labels of a map's items: one per item, in order, or a function of the item (for items a generator
#: makes as they are needed).
Labels = Sequence[str] | Callable[[Any], str]

#: What a map says when a worker process died: ``{names}`` is the label(s) of the item(s) it may have been
#: running, each quoted.
WORKER_DIED = ("a worker process died (killed, or out of memory) while running {names}: run the same command "
               "again")

#: Test hook: a pool worker about to run the item of this label SIGKILLs itself, as the kernel's out-of-memory
#: killer would (tests/test_dead_worker.py, tests/test_scoring_classes.py check what a run does then).
KILL_WORKER_ENV = "LFBENCH_TEST_KILL_WORKER"


def labelled(items: Iterable[Item], labels: Labels) -> Iterator[tuple[str, Item]]:
    """(label, item) for each of ``items``, pulled one at a time (a generator's next item is made only when
    asked for); ``labels``: one per item (ValueError when their counts differ), or a function of the item."""
    if callable(labels):
        return ((labels(item), item) for item in items)
    return ((label, item) for item, label in zip(items, labels, strict=True))


# --------------------------------------------------------------------------- GPUs of worker processes

def visible_gpus() -> list[str]:
    """The CUDA devices this process sees, as the ids a child's ``CUDA_VISIBLE_DEVICES`` takes: the entries
    of this process's ``CUDA_VISIBLE_DEVICES`` when set (indices or UUIDs), else ``0 .. count - 1``.
    Empty without CUDA."""
    import torch

    if not torch.cuda.is_available():
        return []
    count = torch.cuda.device_count()
    listed = [d.strip() for d in os.environ.get("CUDA_VISIBLE_DEVICES", "").split(",") if d.strip()]
    return listed[:count] if listed else [str(k) for k in range(count)]


def worker_gpus(jobs: int, gpus: Sequence[str]) -> list[str | None]:
    """The GPU of each of ``jobs`` workers: round-robin over ``gpus`` (worker k gets gpus[k % n]); None for
    every worker (the CPU) when there are none."""
    if not gpus:
        return [None] * jobs
    return [gpus[k % len(gpus)] for k in range(jobs)]


_marks: Path | None = None  # in a pool worker: the folder of "running now" marks (one file per pid)


def init_worker(threads: int | None, gpu_queue=None, marks: str | None = None) -> None:
    """Pool initializer: ``threads`` torch threads (None: torch is left alone, never imported); with a queue,
    take this worker's GPU from it and make it the only one the worker sees (before CUDA starts in this
    process), so ``device = "auto"`` / ``"cuda"`` in the cell's config land on it. ``marks``: the folder where
    the worker marks the item it runs (:func:`run_marked`), so that a worker that dies can be named."""
    global _marks
    if marks is not None:
        _marks = Path(marks)
        signal.signal(signal.SIGTERM, _stopped_by_pool)
    if gpu_queue is not None:
        gpu = gpu_queue.get()
        if gpu is not None:
            os.environ["CUDA_VISIBLE_DEVICES"] = gpu
    if threads is None:
        return
    import torch

    torch.set_num_threads(threads)


def _stopped_by_pool(signum: int, frame: Any) -> None:
    """SIGTERM: the pool stops this (healthy) worker because another one died; its mark goes first, so that the
    marks left name the dead worker's item."""
    if _marks is not None:
        (_marks / str(os.getpid())).unlink(missing_ok=True)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGTERM)


def run_marked(fn: Callable[[Item], Result], label: str, item: Item) -> Result:
    """``fn(item)`` in a pool worker, the worker's mark file holding ``label`` meanwhile."""
    mark = None if _marks is None else _marks / str(os.getpid())
    if mark is not None:
        mark.write_text(label, encoding="utf-8")
    try:
        if os.environ.get(KILL_WORKER_ENV) == label:
            os.kill(os.getpid(), signal.SIGKILL)
        return fn(item)
    finally:
        if mark is not None:
            mark.unlink(missing_ok=True)


# --------------------------------------------------------------------------- the interface

@dataclass(frozen=True)
class ClusterOptions:
    """How the cells run (``lfbench ablate --executor NAME ...``): the executor's name (one of
    :data:`EXECUTORS`) and the resources of each job of an executor that submits jobs. Declared once:
    ``lfbench ablate`` adds every option but the executor as a flag (``--gpus-per-job N``, ...:
    lfbench.utils.flags.section_flags), and a value given from Python is checked by the same declaration."""

    executor: str = option("local", help="where the cells run: one of the registered executors")
    gpus_per_job: int = option(0, help="GPUs of each cell's job (--executor)", low=0, metavar="N")
    cpus_per_job: int = option(0, help="CPUs of each cell's job (--executor; 0: the spec's threads per cell)", low=0,
                               metavar="N")
    timeout_min: int = option(24 * 60, help="time limit of each job in minutes", low=1, metavar="MIN")
    partition: str | None = option(None, help="SLURM partition (--executor slurm)", metavar="NAME")
    max_parallel: int = option(0, help="SLURM jobs running at once (0: no limit)", low=0, metavar="N")

    def __post_init__(self) -> None:
        EXECUTORS.get(self.executor)  # SpecError: Unknown executor 'x'. Available: ...
        check_options(self, flag_name)


class Executor(ABC):
    """Runs a function over items (the cells, or one batch of test timings) and hands each result to a
    callback as it comes. ``jobs``: items at a time (where the executor runs several on this machine);
    ``folder``: where an executor keeps its files (logs, pickles; OUT/submitit); ``log``: progress lines."""

    #: what ``lfbench ablate --help`` says of it
    help: ClassVar[str] = ""
    #: whether each item runs as a job with its own resources (--gpus-per-job, --cpus-per-job, ...)
    submits_jobs: ClassVar[bool] = False

    def __init__(self, options: ClusterOptions, *, jobs: int = 1, folder: Path | None = None,
                 log: Log = _log.info) -> None:
        self.options = options
        self.jobs = jobs
        self.folder = folder
        self.log = log

    def check(self) -> None:
        """One SpecError line, before any work, when this executor cannot run here (nothing by default)."""
        return None

    def runs_here(self, count: int | None) -> bool:
        """Whether a map over ``count`` items (None: not known ahead, e.g. a generator's) runs them in this
        process (where they may show progress bars)."""
        return False

    @property
    def cpus_per_item(self) -> int:
        """CPUs each item gets from the executor (0: this machine's cores are shared out by ``--jobs``)."""
        return self.options.cpus_per_job if self.submits_jobs else 0

    @abstractmethod
    def map(self, fn: Callable[[Item], Result], items: Iterable[Item], *, labels: Labels, threads: int | None,
            on_done: Callable[[Result], None], on_start: Callable[[str], None] | None = None,
            cost: Callable[[Item], float] | None = None, died: str = WORKER_DIED) -> None:
        """``fn(item)`` for every item, each result to ``on_done`` as it comes. ``items``: a sequence, or any
        iterable, pulled as the work goes (an executor running items on this machine pulls one only when it is
        about to start, and at most one ahead). ``labels`` name the items in messages (:data:`Labels`);
        ``threads``: torch threads (a job's CPUs) per item, None for work that does not use torch (a worker
        process then never imports it); ``on_start(label)`` is called before an item runs in this process;
        ``cost(item)``: its relative cost, where the items of a sequence are started longest first; ``died``:
        the message of a worker process that died (:data:`WORKER_DIED`). A failure raises: at once in this
        process, or after the other jobs ended, as one LFBenchError."""


class InProcess(Executor):
    """One item after the other, in this process."""

    help = "one cell after the other in this process"

    def check(self) -> None:
        if self.jobs > 1:
            raise SpecError(f"--executor {self.options.executor} runs one cell at a time: --jobs {self.jobs} needs "
                            "--executor pool")

    def runs_here(self, count: int | None) -> bool:
        return True

    def map(self, fn, items, *, labels, threads, on_done, on_start=None, cost=None, died=WORKER_DIED) -> None:
        for label, item in labelled(items, labels):
            if on_start is not None:
                on_start(label)
            on_done(fn(item))


class ProcessPool(Executor):
    """``jobs`` items at a time, each in a worker process of this machine (spawned: a parent's threads are not
    inherited) with ``threads`` torch threads and its own GPU (round-robin over the visible CUDA devices; the
    CPU when there are none; ``threads=None``: no torch at all); the items of a sequence longest first, those
    of any other iterable in their order, each pulled when a worker is about to be free (at most one ahead of
    the ``jobs`` running: the next one is made while they run). One job, or one item, runs in this process
    (:class:`InProcess`).

    A worker that dies (SIGKILL, the out-of-memory killer) stops the map with one :class:`RunFailed` line
    naming the item it was running (``died``): each worker marks the label of its item in a file named by its
    pid, and a worker the pool stops because another one died (SIGTERM) removes its mark first, so that the
    marks left name the dead worker's item."""

    help = "--jobs N worker processes on this machine, each with its own GPU (the default)"

    def runs_here(self, count: int | None) -> bool:
        return self.jobs <= 1 or (count is not None and count <= 1)

    def map(self, fn, items, *, labels, threads, on_done, on_start=None, cost=None, died=WORKER_DIED) -> None:
        if self.runs_here(len(items) if isinstance(items, Sequence) else None):
            InProcess(self.options, log=self.log).map(fn, items, labels=labels, threads=threads, on_done=on_done,
                                                      on_start=on_start)
            return
        waiting = labelled(items, labels)
        if isinstance(items, Sequence) and cost is not None:  # the longest first (a stable sort: ties in order)
            waiting = iter(sorted(waiting, key=lambda pair: cost(pair[1]), reverse=True))
        ahead = next(waiting, None)  # the first item before any worker starts (none: no pool at all)
        if ahead is None:
            return
        pool, marks = self._start(threads)
        running: dict[Future, str] = {}

        def submit(label: str, item: Any) -> None:
            try:
                running[pool.submit(run_marked, fn, label, item)] = label
            except BrokenProcessPool:  # a worker died since the last item was handed out
                raise self._died(pool, marks, label, died) from None

        try:
            # At most `jobs` items are handed to the pool at a time: a pool queues submitted calls into its
            # workers ahead of time, where cancel_futures cannot reach them, so submitting every cell at once
            # made Ctrl-C (which stops the running cells at a checkpoint) start the pre-queued ones. The next
            # item is pulled (made, for a generator) while they run.
            while ahead is not None and len(running) < self.jobs:
                submit(*ahead)
                ahead = next(waiting, None)
            while running:
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for fut in done:
                    label = running.pop(fut)
                    try:
                        result = fut.result()  # a failed item stops the run (the waiting ones never start)
                    except BrokenProcessPool:
                        raise self._died(pool, marks, label, died) from None
                    on_done(result)
                    if ahead is not None:
                        submit(*ahead)
                        ahead = next(waiting, None)
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
            shutil.rmtree(marks, ignore_errors=True)

    def _start(self, threads: int | None) -> tuple[ProcessPoolExecutor, Path]:
        """The pool and the folder of its workers' marks; with ``threads``, each worker's GPU."""
        import multiprocessing

        ctx = multiprocessing.get_context("spawn")
        queue = None
        if threads is not None:
            gpus = worker_gpus(self.jobs, visible_gpus())
            queue = ctx.Queue()
            for gpu in gpus:
                queue.put(gpu)
            if gpus[0] is not None:
                self.log(f"{self.jobs} worker(s) on GPU(s) {', '.join(str(g) for g in gpus)} (round-robin)")
        marks = Path(tempfile.mkdtemp(prefix="lfbench-pool-"))
        pool = ProcessPoolExecutor(max_workers=self.jobs, mp_context=ctx, initializer=init_worker,
                                   initargs=(threads, queue, str(marks)))
        return pool, marks

    @staticmethod
    def _died(pool: ProcessPoolExecutor, marks: Path, label: str, died: str) -> RunFailed:
        """The error of a worker that died: the pool is shut down (the other workers stopped, their marks
        removed) and the marks left name the item(s) it was running (``label``, the item that saw it, when it
        died before marking one)."""
        pool.shutdown(wait=True, cancel_futures=True)
        marked = sorted(p.read_text(encoding="utf-8", errors="replace") for p in marks.iterdir()) \
            if marks.is_dir() else []
        return RunFailed(died.format(names=" or ".join(repr(n) for n in (marked or [label]))))


# --------------------------------------------------------------------------- the registry

#: Every executor by name; ``lfbench ablate --executor`` offers these.
EXECUTORS: Registry[type[Executor]] = Registry("executor", Executor)
EXECUTORS.add("inline", InProcess)
EXECUTORS.add("pool", ProcessPool)
EXECUTORS.add("local", Lazy("lfbench.ablation.jobs:Submitit"))
EXECUTORS.add("slurm", Lazy("lfbench.ablation.jobs:Slurm"))


def executor_for(options: ClusterOptions | None, *, jobs: int = 1, folder: Path | None = None,
                 log: Log = _log.info) -> Executor:
    """The executor ``options`` name (None: ``pool``, which runs in this process with one job)."""
    options = options if options is not None else ClusterOptions("pool")
    return EXECUTORS.get(options.executor)(options, jobs=jobs, folder=folder, log=log)


__all__ = ["EXECUTORS", "KILL_WORKER_ENV", "WORKER_DIED", "ClusterOptions", "Executor", "InProcess", "Labels",
           "ProcessPool", "executor_for", "init_worker", "labelled", "run_marked", "visible_gpus", "worker_gpus"]
