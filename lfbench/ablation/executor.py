"""Where ablation cells run: one :class:`Executor` interface (``map`` a function over items, each result
to a callback as it comes) with its implementations in one registry, :data:`EXECUTORS`, from which
``lfbench ablate --executor`` takes its choices:

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
"""

from __future__ import annotations

import itertools
import logging
import os
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, TypeVar

from lfbench.utils.errors import SpecError
from lfbench.utils.options import check_options, option
from lfbench.utils.registry import Lazy, Registry

_log = logging.getLogger(__name__)
Log = Callable[[str], None]
Item = TypeVar("Item")
Result = TypeVar("Result")


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


def init_worker(threads: int, gpu_queue=None) -> None:
    """Pool initializer: ``threads`` torch threads; with a queue, take this worker's GPU from it and make it
    the only one the worker sees (before CUDA starts in this process), so ``device = "auto"`` / ``"cuda"``
    in the cell's config land on it."""
    if gpu_queue is not None:
        gpu = gpu_queue.get()
        if gpu is not None:
            os.environ["CUDA_VISIBLE_DEVICES"] = gpu
    import torch

    torch.set_num_threads(threads)


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
        check_options(self, lambda name: "--" + name.replace("_", "-"))


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

    def runs_here(self, count: int) -> bool:
        """Whether a map over ``count`` items runs them in this process (where they may show progress bars)."""
        return False

    @property
    def cpus_per_item(self) -> int:
        """CPUs each item gets from the executor (0: this machine's cores are shared out by ``--jobs``)."""
        return self.options.cpus_per_job if self.submits_jobs else 0

    @abstractmethod
    def map(self, fn: Callable[[Item], Result], items: Sequence[Item], *, labels: Sequence[str], threads: int,
            on_done: Callable[[Result], None], on_start: Callable[[str], None] | None = None,
            cost: Callable[[Item], float] | None = None) -> None:
        """``fn(item)`` for every item, each result to ``on_done`` as it comes. ``labels`` name the items in
        messages; ``threads``: torch threads (a job's CPUs) per item; ``on_start(label)`` is called before an
        item runs in this process; ``cost(item)``: its relative cost, where items are started longest first.
        A failure raises: at once in this process, or after the other jobs ended, as one LFBenchError."""


class InProcess(Executor):
    """One item after the other, in this process."""

    help = "one cell after the other in this process"

    def check(self) -> None:
        if self.jobs > 1:
            raise SpecError(f"--executor {self.options.executor} runs one cell at a time: --jobs {self.jobs} needs "
                            "--executor pool")

    def runs_here(self, count: int) -> bool:
        return True

    def map(self, fn, items, *, labels, threads, on_done, on_start=None, cost=None) -> None:
        for item, label in zip(items, labels, strict=True):
            if on_start is not None:
                on_start(label)
            on_done(fn(item))


class ProcessPool(Executor):
    """``jobs`` items at a time, each in a worker process of this machine with ``threads`` torch threads and
    its own GPU (round-robin over the visible CUDA devices; the CPU when there are none); the longest first.
    One job, or one item, runs in this process (:class:`InProcess`)."""

    help = "--jobs N worker processes on this machine, each with its own GPU (the default)"

    def runs_here(self, count: int) -> bool:
        return self.jobs <= 1 or count <= 1

    def map(self, fn, items, *, labels, threads, on_done, on_start=None, cost=None) -> None:
        if self.runs_here(len(items)):
            InProcess(self.options, log=self.log).map(fn, items, labels=labels, threads=threads, on_done=on_done,
                                                      on_start=on_start)
            return
        import multiprocessing

        ordered = sorted(items, key=cost, reverse=True) if cost is not None else list(items)
        ctx = multiprocessing.get_context("spawn")
        gpus = worker_gpus(self.jobs, visible_gpus())
        queue = ctx.Queue()
        for gpu in gpus:
            queue.put(gpu)
        if gpus[0] is not None:
            self.log(f"{self.jobs} worker(s) on GPU(s) {', '.join(str(g) for g in gpus)} (round-robin)")
        pool = ProcessPoolExecutor(max_workers=self.jobs, mp_context=ctx, initializer=init_worker,
                                   initargs=(threads, queue))
        try:
            # At most `jobs` items are handed to the pool at a time: a pool queues submitted calls into its
            # workers ahead of time, where cancel_futures cannot reach them, so submitting every cell at once
            # made Ctrl-C (which stops the running cells at a checkpoint) start the pre-queued ones.
            waiting = iter(ordered)
            running: set[Future] = set()
            for item in itertools.islice(waiting, self.jobs):
                running.add(pool.submit(fn, item))
            while running:
                done, running = wait(running, return_when=FIRST_COMPLETED)
                for fut in done:
                    on_done(fut.result())  # a failed item stops the run (the waiting ones never start)
                    running.update(pool.submit(fn, item) for item in itertools.islice(waiting, 1))
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


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


__all__ = ["EXECUTORS", "ClusterOptions", "Executor", "InProcess", "ProcessPool", "executor_for", "visible_gpus",
           "worker_gpus", "init_worker"]
