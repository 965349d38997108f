"""Ablation cells as jobs through submitit: ``local`` (subprocesses of this machine) and ``slurm`` (one job
array on a cluster, tested against a real one-node SLURM cluster in tests/test_slurm.py), the two
:class:`~lfbench.utils.executor.Executor` s registered lazily in
:data:`lfbench.utils.executor.EXECUTORS`.

Each job runs :func:`run_job`; a cell's own error reaches the submitting command as one line. On a cluster,
SIGTERM or the time limit's SIGUSR2 stops a cell at a checkpoint and ends its job without a result; the
submitting command then asks squeue what became of the job: it waits for a requeued one (which resumes) and
names a cancelled or timed-out one on one line. Every scheduler call is bounded in time
(lfbench.ablation.scheduler).
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from lfbench.ablation.scheduler import RETRIES_ENV, SchedulerError, SchedulerLimits, bounded_submission, squeue_states
from lfbench.utils.errors import LFBenchError, SpecError
from lfbench.utils.executor import EXECUTORS, WORKER_DIED, ClusterOptions, Executor, labelled
from lfbench.utils.subprocesses import SAFE_PATH, safe_path_environ

__all__ = ["SLURM_COMMANDS", "Submitit", "Slurm", "make_executor", "run_job"]

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


def _submitit():
    try:
        import submitit
    except ImportError:
        raise SpecError('--executor needs submitit: pip install -e ".[cluster]" (or pip install submitit)') from None
    return submitit


def make_executor(options: ClusterOptions, folder: Path, threads: int):
    """A submitit executor of ``options.executor`` (``local`` or ``slurm``) writing its logs and pickles under
    ``folder``."""
    executor = EXECUTORS.get(options.executor)(options, folder=folder)
    if not isinstance(executor, Submitit):
        raise SpecError(f"--executor {options.executor} does not submit jobs through submitit")
    return executor.submitit_executor(threads)


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


class Submitit(Executor):
    """Each item as one job through submitit's local executor (subprocesses of this machine), logs and
    pickles in ``folder``; the base of :class:`Slurm`."""

    help = "each cell as a submitit job in a local subprocess (the --executor slurm path, here)"
    submits_jobs = True

    def check(self) -> None:
        _submitit()

    def submitit_executor(self, threads: int):
        """The submitit executor, each job with ``threads`` CPUs unless --cpus-per-job says otherwise."""
        options = self.options
        ex = _submitit().LocalExecutor(folder=str(self.folder))
        ex.update_parameters(timeout_min=options.timeout_min, gpus_per_node=options.gpus_per_job,
                             cpus_per_task=options.cpus_per_job or threads)
        return ex

    def map(self, fn, items, *, labels, threads, on_done, on_start=None, cost=None, died=WORKER_DIED) -> None:
        """Run ``fn(item)`` for each item as one job and wait for all; ``on_done`` sees each result as it comes.
        A job that fails, or ends without a result (cancelled, timed out, killed), is reported after the other
        jobs finish: one LFBenchError naming each such job by its label and its log (re-running the command
        resumes them). A job the scheduler requeues is waited for. Every item is submitted at once (an
        iterable's items are all pulled first)."""
        pairs = list(labelled(items, labels))
        labels, items = [label for label, _ in pairs], [item for _, item in pairs]
        if not items:
            return
        if self.folder is None:
            raise ValueError(f"--executor {self.options.executor} needs a folder for its jobs' files")
        folder = Path(self.folder)
        folder.mkdir(parents=True, exist_ok=True)
        jobs = self._submit(self.submitit_executor(threads), fn, items, labels)
        self._log_submitted(jobs, labels, folder)
        failed = []
        seen: set[int] = set()
        try:
            for k, job, ended in self._wait(jobs):
                seen.add(k)
                self._collect(k, job, ended, labels, failed, on_done)
        except SchedulerError as exc:
            waiting = ", ".join(f"job {job.job_id} ({labels[k]})" for k, job in enumerate(jobs) if k not in seen)
            raise SchedulerError(f"{exc}: stopped waiting for {waiting}, which may still run (squeue / scancel once "
                                 "SLURM answers); finished cells are kept: run the same command again to resume the "
                                 "others") from None
        if failed:
            raise LFBenchError(f"{len(failed)} of {len(jobs)} job(s) did not finish: {'; '.join(failed)}; run the "
                               "same command again to resume them")

    @staticmethod
    def _collect(k: int, job, ended: str | None, labels: Sequence[str], failed: list[str],
                 on_done: Callable[[Any], None]) -> None:
        """A job that ended: its result to ``on_done``, or a line naming it into ``failed``."""
        if ended is not None:
            failed.append(f"{labels[k]} (job {job.job_id}) ended{' ' + ended if ended else ''} without a result "
                          f"(cancelled, timed out, pre-empted or killed; its log: {job.paths.stderr})")
            return
        try:
            result = job.result()
        except Exception as exc:  # noqa: BLE001 - a job's failure is reported per cell
            failed.append(f"{labels[k]} (job {job.job_id}) failed: {_reason(exc)} (its log: {job.paths.stderr})")
            return
        on_done(result)

    def _submit(self, executor, fn: Callable[[Any], Any], items: Sequence[Any], labels: Sequence[str]) -> list:
        """The submitted jobs (submitit Job objects), in the order of ``items``."""
        errors = io.StringIO()
        try:
            # the jobs import lfbench as installed, not from the current folder; submitit prints sbatch's
            # complaint, then raises it
            with safe_path_environ(), contextlib.redirect_stderr(errors):
                return executor.map_array(run_job, [fn] * len(items), items, labels)
        except Exception as exc:  # noqa: BLE001 - the scheduler refused the jobs (partition, limits, ...)
            raise SpecError(f"submitting the jobs failed: {_last_line(str(exc) or errors.getvalue())}") from None

    def _log_submitted(self, jobs: list, labels: Sequence[str], folder: Path) -> None:
        _log.info(f"submitted {len(jobs)} job(s) through submitit ({self.options.executor}); logs in {folder}")
        for label, job in zip(labels, jobs, strict=True):
            _log.info(f"{label}: job {job.job_id}, log {job.paths.stderr}")

    def _poll(self) -> Callable[[Any], tuple[str, bool]]:
        """Once per round of waiting: a function of a job without a result -> (its state, whether it ended).
        Here: submitit's own ``job.done()``."""
        return lambda job: ("", job.done())

    def _wait(self, jobs: list) -> Iterator[tuple[int, Any, str | None]]:
        """(index, job, None) for each job with a result, as they come; (index, job, its final state or "") for
        a job that ended without one (by :meth:`_poll`, given a grace for its result file to appear)."""
        pending = dict(enumerate(jobs))
        ended_since: dict[int, float] = {}
        start = time.monotonic()
        while pending:
            state_of = self._poll()
            with contextlib.suppress(OSError):  # refresh a network file system's cached view of the folder
                folder = jobs[0].paths.folder
                folder.chmod(folder.stat().st_mode)
            for k, job in list(pending.items()):
                if job.paths.result_pickle.exists():
                    del pending[k]
                    yield k, job, None
                    continue
                state, ended = state_of(job)
                if not ended:
                    ended_since.pop(k, None)
                elif time.monotonic() - ended_since.setdefault(k, time.monotonic()) > RESULT_GRACE_S:
                    del pending[k]  # its result file would have appeared by now, even on a slow shared file system
                    yield k, job, state
            if pending:
                time.sleep(min(30.0, max(1.0, (time.monotonic() - start) / 20)))


class Slurm(Submitit):
    """Each item as one task of one SLURM job array through submitit (at most ``max_parallel`` running). A
    job's state comes from squeue (submitit asks sacct, which needs an accounting database that not every
    cluster has: without one, a job that ended without a result was waited for forever)."""

    help = "each cell as a task of a SLURM job array (through submitit; run where sbatch, srun and squeue are)"

    def check(self) -> None:
        """Also SLURM's commands on PATH: sbatch submits, srun runs each job's step, squeue says what became
        of a job that ended without a result."""
        super().check()
        missing = [c for c in SLURM_COMMANDS if shutil.which(c) is None]
        if missing:
            raise SpecError(f"--executor slurm: no {', '.join(missing)} on PATH; run lfbench ablate where SLURM's "
                            "commands are (e.g. a login node), or use --executor local or --jobs N")
        SchedulerLimits.from_env()  # a bad LFBENCH_SCHEDULER_* is one line before any work

    def submitit_executor(self, threads: int):
        options = self.options
        ex = _submitit().SlurmExecutor(folder=str(self.folder))
        params: dict[str, Any] = {"time": options.timeout_min, "cpus_per_task": options.cpus_per_job or threads,
                                  "ntasks_per_node": 1, "nodes": 1, "job_name": "lfbench-ablate",
                                  "setup": [f"export {k}={v}" for k, v in SAFE_PATH.items()]}  # not the job's cwd
        if options.gpus_per_job:
            params["gpus_per_node"] = options.gpus_per_job
        if options.partition:
            params["partition"] = options.partition
        if options.max_parallel:
            params["array_parallelism"] = options.max_parallel
        ex.update_parameters(**params)
        return ex

    def _submit(self, executor, fn: Callable[[Any], Any], items: Sequence[Any], labels: Sequence[str]) -> list:
        """As submitit submits, with sbatch bounded by LFBENCH_SCHEDULER_TIMEOUT_S (lfbench.ablation.scheduler)."""
        with bounded_submission(SchedulerLimits.from_env().timeout_s):
            return super()._submit(executor, fn, items, labels)

    def _wait(self, jobs: list) -> Iterator[tuple[int, Any, str | None]]:
        self._limits = SchedulerLimits.from_env()
        self._failures = 0  # squeue calls in a row that failed
        yield from super()._wait(jobs)

    def _poll(self) -> Callable[[Any], tuple[str, bool]]:
        """A job's state from squeue: pending, running or requeued is waited for, and so is every job while
        squeue does not answer (UNKNOWN), with a warning, up to LFBENCH_SCHEDULER_RETRIES times in a row (then
        SchedulerError naming squeue and why); a job squeue no longer lists has ended."""
        try:
            states: dict[str, str] | None = squeue_states(self._limits.timeout_s)
            self._failures = 0
        except SchedulerError as exc:
            self._failures += 1
            if self._failures > self._limits.retries:
                times = f"{self._failures} time{'s' if self._failures != 1 else ''}"
                raise SchedulerError(f"squeue failed {times} in a row ({exc})") from None
            _log.warning(f"job states unknown: squeue failed ({exc}); asking again ({self._failures} of "
                         f"{self._limits.retries}, {RETRIES_ENV})")
            states = None

        def state_of(job) -> tuple[str, bool]:
            state = "UNKNOWN" if states is None else states.get(job.job_id, "(gone from squeue)")
            return state, state not in _ACTIVE and state != "UNKNOWN"

        return state_of



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
