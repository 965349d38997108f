"""Where ablation cells run: worker processes on this machine, each with its own GPU (round-robin over the
visible CUDA devices; the CPU when there are none), or a cluster through submitit (``--executor slurm``:
the cells as one job array, then one job that measures their test times; ``--executor local`` runs the
same path as local subprocesses). Tested against a real one-node SLURM cluster (tests/test_slurm.py).

Every path runs :func:`lfbench.ablation.cell.run_cell`, which skips a finished cell and resumes an
interrupted one from its checkpoint, so re-running the command after a crash, a pre-emption or a
cancelled job continues where it stopped. On a cluster, SIGTERM or the time limit's SIGUSR2 stops a cell at
a checkpoint and ends its job without a result; the submitting command then asks squeue what became of the
job: it waits for a requeued one (which resumes) and names a cancelled or timed-out one on one line.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import shutil
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lfbench.utils.errors import LFBenchError, SpecError
from lfbench.utils.subprocesses import SAFE_PATH, safe_path_environ

EXECUTORS = ("local", "slurm")
#: SLURM commands ``--executor slurm`` calls: sbatch submits, srun runs each job's step, squeue gives job states.
SLURM_COMMANDS = ("sbatch", "srun", "squeue")
#: SLURM job states in which a job may still produce its result (a requeued job passes through them again).
_ACTIVE = frozenset({"PENDING", "CONFIGURING", "RUNNING", "COMPLETING", "REQUEUED", "REQUEUE_FED", "REQUEUE_HOLD",
                     "RESIZING", "SUSPENDED", "STOPPED", "SIGNALING", "STAGE_OUT", "SPECIAL_EXIT", "RESV_DEL_HOLD",
                     "POWER_UP_NODE"})
#: Seconds a job that ended is given for its result file to appear (a shared file system may show it late).
RESULT_GRACE_S = 10.0
#: How :func:`run_job` marks a cell's own error, so that the submitting command can show it on one line.
FAILED = "lfbench cell failed: "
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


def check_executor(options: ClusterOptions) -> None:
    """One SpecError line, before any work, when the executor cannot run here: submitit is not installed, or
    (``slurm``) SLURM's commands are not on PATH (sbatch submits, srun runs each job's step, squeue says what
    became of a job that ended without a result)."""
    try:
        import submitit  # noqa: F401
    except ImportError:
        raise SpecError('--executor needs submitit: pip install -e ".[cluster]" (or pip install submitit)') from None
    if options.executor == "slurm":
        missing = [c for c in SLURM_COMMANDS if shutil.which(c) is None]
        if missing:
            raise SpecError(f"--executor slurm: no {', '.join(missing)} on PATH; run lfbench ablate where SLURM's "
                            "commands are (e.g. a login node), or use --executor local or --jobs N")


def run_job(fn: Callable[[Any], Any], arg: Any, label: str) -> Any:
    """What each cluster job runs: ``fn(arg)``; ``label`` names the job in messages (e.g. ``cell ID``). An
    exception reaches the submitting command as one line (the traceback goes to the job's log). Training
    stopped at a checkpoint by SIGTERM (scancel, a pre-emption, ``scontrol requeue``, the time limit) or by
    SIGUSR2 (90 s before the time limit) ends the job without a result, so that the submitting command asks
    the scheduler what became of the job: requeued, it waits for its next run (which resumes from the
    checkpoint); cancelled or timed out, it reports the cell."""
    from lfbench.training.signals import TrainingInterrupted

    if hasattr(signal, "SIGUSR2") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGUSR2, _stop_at_a_checkpoint)
    try:
        return fn(arg)
    except TrainingInterrupted as exc:
        raise SystemExit(f"{label}: {exc}; the job ends without a result") from None
    except Exception as exc:
        _log.exception(f"{label} failed")
        message = str(exc) if isinstance(exc, LFBenchError) else f"{type(exc).__name__}: {exc}"
        raise RuntimeError(FAILED + " ".join(message.split())) from None


def _stop_at_a_checkpoint(signum, frame) -> None:
    """SIGUSR2, which submitit's job scripts ask SLURM for 90 s before the time limit: stop the training at a
    checkpoint as on SIGTERM (submitit's own handler would end a cell that is not a submitit Checkpointable
    with an error, and requeue it otherwise, either way without a checkpoint)."""
    os.kill(os.getpid(), signal.SIGTERM)


def run_as_jobs(fn: Callable[[Any], Any], args: Sequence[Any], labels: Sequence[str], options: ClusterOptions,
                folder: Path, threads: int, on_done: Callable[[Any], None]) -> None:
    """Run ``fn(arg)`` for each arg as one job (one job array on SLURM, at most ``max_parallel`` running, logs in
    ``folder``) and wait for all; ``on_done`` sees each result as it comes. A job that fails, or ends without a
    result (cancelled, timed out, killed), is reported after the other jobs finish: one LFBenchError naming
    each such job by its label and its log (re-running the command resumes them). A job the scheduler
    requeues is waited for."""
    folder.mkdir(parents=True, exist_ok=True)
    executor = make_executor(options, folder, threads)
    if options.executor == "slurm":
        executor.update_parameters(job_name="lfbench-ablate")
    sbatch_errors = io.StringIO()
    try:
        # the jobs import lfbench as installed, not from the current folder; submitit prints sbatch's
        # complaint, then raises it
        with safe_path_environ(), contextlib.redirect_stderr(sbatch_errors):
            jobs = executor.map_array(run_job, [fn] * len(args), args, labels)
    except Exception as exc:  # noqa: BLE001 - the scheduler refused the jobs (partition, limits, ...)
        raise SpecError(f"submitting the jobs failed: {_last_line(str(exc) or sbatch_errors.getvalue())}") from None
    _log.info(f"submitted {len(jobs)} job(s) through submitit ({options.executor}); logs in {folder}")
    for label, job in zip(labels, jobs, strict=True):
        _log.info(f"{label}: job {job.job_id}, log {job.paths.stderr}")
    failed = []
    for k, job, ended in _wait(jobs, options.executor):
        if ended is not None:
            failed.append(f"{labels[k]} (job {job.job_id}) ended{' ' + ended if ended else ''} without a result "
                          f"(cancelled, timed out, pre-empted or killed; its log: {job.paths.stderr})")
            continue
        try:
            result = job.result()
        except Exception as exc:  # noqa: BLE001 - a job's failure is reported per cell
            failed.append(f"{labels[k]} (job {job.job_id}) failed: {_reason(exc)} (its log: {job.paths.stderr})")
            continue
        on_done(result)
    if failed:
        raise LFBenchError(f"{len(failed)} of {len(jobs)} job(s) did not finish: {'; '.join(failed)}; run the same "
                           "command again to resume them")


def submit_cells(fn: Callable[[Any], dict], tasks: Sequence[Any], options: ClusterOptions, folder: Path,
                 threads: int, on_done: Callable[[dict], None]) -> None:
    """:func:`run_as_jobs` of ``fn(task)`` for each cell's task, labelled ``cell ID``."""
    run_as_jobs(fn, tasks, [f"cell {t.cell_id}" for t in tasks], options, folder, threads, on_done)


def _wait(jobs: list, executor: str) -> Iterator[tuple[int, Any, str | None]]:
    """(index, job, None) for each job with a result, as they come; (index, job, its final state or "") for a
    job that ended without one. A SLURM job's state comes from squeue (submitit asks sacct, which needs an
    accounting database that not every cluster has: without one, a job that ended without a result was
    waited for forever); a pending, running or requeued job is waited for."""
    pending = dict(enumerate(jobs))
    ended_since: dict[int, float] = {}
    start = time.monotonic()
    while pending:
        states = _slurm_states() if executor == "slurm" else {}
        with contextlib.suppress(OSError):  # refresh a network file system's cached view of the folder
            folder = jobs[0].paths.folder
            folder.chmod(folder.stat().st_mode)
        for k, job in list(pending.items()):
            if job.paths.result_pickle.exists():
                del pending[k]
                yield k, job, None
                continue
            if executor == "slurm":
                state = "UNKNOWN" if states is None else states.get(job.job_id, "(gone from squeue)")
                ended = state not in _ACTIVE and state != "UNKNOWN"
            else:
                state, ended = "", job.done()
            if not ended:
                ended_since.pop(k, None)
            elif time.monotonic() - ended_since.setdefault(k, time.monotonic()) > RESULT_GRACE_S:
                del pending[k]  # its result file would have appeared by now, even on a slow shared file system
                yield k, job, state
        if pending:
            time.sleep(min(30.0, max(1.0, (time.monotonic() - start) / 20)))


def _slurm_states() -> dict[str, str] | None:
    """Job id (``123``, ``123_4`` for array tasks) -> state of this user's jobs the controller knows: pending,
    running, requeued, and finished ones for MinJobAge (300 s by default); None when squeue does not answer."""
    try:
        proc = subprocess.run(["squeue", "--noheader", "--array", "--states=all", "--format=%i %T",
                               f"--user={os.getuid()}"], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if proc.returncode != 0:
        return None
    return {f[0]: f[1] for f in (line.split() for line in proc.stdout.splitlines()) if len(f) >= 2}


def _reason(exc: BaseException) -> str:
    """The one-line reason of a failed job: what :func:`run_job` raised, else the last line of the job's trace."""
    text = str(exc)
    if FAILED in text:
        return text.rsplit(FAILED, 1)[1].splitlines()[0].strip()
    trace = text.split("-" * 22)
    return _last_line(trace[1] if len(trace) > 2 else text)


def _last_line(text: str) -> str:
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[-1] if lines else "no message"


__all__ = ["EXECUTORS", "SLURM_COMMANDS", "ClusterOptions", "visible_gpus", "worker_gpus", "init_worker",
           "check_executor", "make_executor", "run_job", "run_as_jobs", "submit_cells"]
