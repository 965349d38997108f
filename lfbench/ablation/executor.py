"""Where ablation cells run: worker processes on this machine, each with its own GPU (round-robin over the
visible CUDA devices; the CPU when there are none), or a cluster through submitit (``--executor slurm``,
one job per cell; ``--executor local`` runs the same path as local subprocesses, which is how it is
tested without a cluster).

Every path runs :func:`lfbench.ablation.cell.run_cell`, which skips a finished cell and resumes an
interrupted one from its checkpoint, so re-running the command after a crash, a pre-emption or a
cancelled job continues where it stopped.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lfbench.utils.errors import SpecError
from lfbench.utils.subprocesses import SAFE_PATH, safe_path_environ

EXECUTORS = ("local", "slurm")
_log = logging.getLogger(__name__)


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


# --------------------------------------------------------------------------- submitit

@dataclass(frozen=True)
class ClusterOptions:
    """Resources of each cell's job (``lfbench ablate --executor ...``)."""

    executor: str = "local"
    gpus_per_job: int = 0
    cpus_per_job: int = 0  # 0: the spec's threads per cell
    timeout_min: int = 24 * 60
    partition: str | None = None
    max_parallel: int = 0  # slurm array parallelism (0: no limit)

    def __post_init__(self) -> None:
        if self.executor not in EXECUTORS:
            raise SpecError(f"Unknown executor {self.executor!r}. Available: {', '.join(EXECUTORS)}")
        if self.gpus_per_job < 0 or self.cpus_per_job < 0 or self.timeout_min < 1 or self.max_parallel < 0:
            raise SpecError("--gpus-per-job, --cpus-per-job and --max-parallel must be >= 0, --timeout-min >= 1")


def make_executor(options: ClusterOptions, folder: Path, threads: int):
    """A submitit executor writing its logs and pickles under ``folder``."""
    try:
        import submitit
    except ImportError:
        raise SpecError('--executor needs submitit: pip install -e ".[cluster]" (or pip install submitit)') from None
    if options.executor == "local":
        ex = submitit.LocalExecutor(folder=str(folder))
        ex.update_parameters(timeout_min=options.timeout_min, gpus_per_node=options.gpus_per_job,
                             cpus_per_task=options.cpus_per_job or threads)
        return ex
    ex = submitit.SlurmExecutor(folder=str(folder))
    params: dict[str, Any] = {"time": options.timeout_min, "cpus_per_task": options.cpus_per_job or threads,
                              "ntasks_per_node": 1, "nodes": 1,
                              "setup": [f"export {k}={v}" for k, v in SAFE_PATH.items()]}  # not from the job's cwd
    if options.gpus_per_job:
        params["gpus_per_node"] = options.gpus_per_job
    if options.partition:
        params["partition"] = options.partition
    if options.max_parallel:
        params["array_parallelism"] = options.max_parallel
    ex.update_parameters(**params)
    return ex


def submit_cells(fn: Callable[[Any], dict], tasks: Sequence[Any], options: ClusterOptions, folder: Path,
                 threads: int, on_done: Callable[[dict], None]) -> None:
    """Submit ``fn(task)`` for each task as one job and wait for all; ``on_done`` sees each result. A failed job
    raises LFBenchError naming the cell and its log (the other jobs finish; re-running resumes)."""
    from lfbench.utils.errors import LFBenchError

    folder.mkdir(parents=True, exist_ok=True)
    executor = make_executor(options, folder, threads)
    with safe_path_environ():  # the jobs import lfbench as installed, not from the current folder
        jobs = [(t, executor.submit(fn, t)) for t in tasks]
    _log.info(f"submitted {len(jobs)} cell job(s) through submitit ({options.executor}); logs in {folder}")
    failed = []
    for task, job in jobs:
        try:
            on_done(job.result())
        except Exception as exc:  # noqa: BLE001 - a job's failure is reported per cell
            last = (str(exc).strip().splitlines() or [repr(exc)])[-1]
            failed.append(f"{task.cell_id} (job {job.job_id}: {last})")
    if failed:
        raise LFBenchError(f"{len(failed)} cell job(s) failed: {'; '.join(failed)}; logs in {folder}; run the same "
                           "command again to resume them")


__all__ = ["EXECUTORS", "ClusterOptions", "visible_gpus", "worker_gpus", "init_worker", "make_executor",
           "submit_cells"]
