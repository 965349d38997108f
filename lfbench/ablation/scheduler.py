"""The submitting command's calls to a cluster scheduler (``sbatch``, ``squeue``), each bounded in time: a
command that does not answer within the timeout is killed (with what it started) and named on one line, and
a scheduler that cannot say what became of the jobs is asked again a bounded number of times, with a
warning each time, before the run stops with one line naming the command (finished cells are kept; running
the command again resumes the others).

Both bounds come from the environment (for tests and for slow controllers):

- ``LFBENCH_SCHEDULER_TIMEOUT_S`` (default 120): seconds each scheduler command may take;
- ``LFBENCH_SCHEDULER_RETRIES`` (default 10): failed state queries in a row that are waited through (the
  jobs' states are unknown meanwhile) before the run stops.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import subprocess
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from lfbench.utils.errors import LFBenchError, SpecError

__all__ = ["TIMEOUT_ENV", "RETRIES_ENV", "SchedulerError", "SchedulerLimits", "run_command", "bounded_submission",
           "squeue_states"]

TIMEOUT_ENV = "LFBENCH_SCHEDULER_TIMEOUT_S"
RETRIES_ENV = "LFBENCH_SCHEDULER_RETRIES"
#: Bounds of the two settings: up to a day per command, up to 1000 failed queries in a row.
_MAX_TIMEOUT_S = 86400.0
_MAX_RETRIES = 1000


class SchedulerError(LFBenchError):
    """A scheduler command failed or did not answer in time (one line naming it; exit code 2)."""


@dataclass(frozen=True)
class SchedulerLimits:
    """``timeout_s``: seconds each scheduler command may take; ``retries``: failed state queries in a row
    that are waited through before the run stops."""

    timeout_s: float = 120.0
    retries: int = 10

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None) -> SchedulerLimits:
        """The limits from ``environ`` (default: this process's environment); SpecError naming the variable
        when one is not a number in its bounds."""
        env = os.environ if environ is None else environ
        timeout_s, retries = cls.timeout_s, cls.retries
        text = env.get(TIMEOUT_ENV, "").strip()
        if text:
            try:
                timeout_s = float(text)
            except ValueError:
                timeout_s = math.nan
            if not 0 < timeout_s <= _MAX_TIMEOUT_S:
                raise SpecError(f"{TIMEOUT_ENV}={text!r}: expected seconds in (0, {_MAX_TIMEOUT_S:g}]")
        text = env.get(RETRIES_ENV, "").strip()
        if text:
            retries = int(text) if text.isascii() and text.isdigit() else -1
            if not 0 <= retries <= _MAX_RETRIES:
                raise SpecError(f"{RETRIES_ENV}={text!r}: expected a whole number in [0, {_MAX_RETRIES}]")
        return cls(timeout_s=timeout_s, retries=retries)


def run_command(command: list[str], timeout_s: float, *, cwd: str | Path | None = None,
                env: Mapping[str, str] | None = None) -> str:
    """The standard output of ``command`` (run in ``cwd`` with ``env``, default this process's); SchedulerError
    naming it when it cannot start, does not end within ``timeout_s`` (it is killed with every process it
    started) or exits non-zero (its last line on stderr)."""
    name = Path(command[0]).name
    try:
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                errors="replace", start_new_session=True, cwd=cwd, env=env)
    except OSError as exc:
        raise SchedulerError(f"{name} could not be started: {exc.strerror or exc}") from None
    with proc:
        try:
            out, err = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(OSError):
                os.killpg(proc.pid, signal.SIGKILL)  # its own session: what it started goes too
            proc.kill()
            proc.wait()
            raise SchedulerError(f"{name} did not answer within {timeout_s:g} s ({TIMEOUT_ENV})") from None
    if proc.returncode != 0:
        said = [line.strip() for line in err.splitlines() if line.strip()]
        raise SchedulerError(said[-1] if said else f"{name} exited with status {proc.returncode} and printed nothing")
    return out


@contextlib.contextmanager
def bounded_submission(timeout_s: float) -> Iterator[None]:
    """While the block runs, submitit submits through :func:`run_command` (its own call of ``sbatch`` has no
    timeout: an sbatch that never returns hung the command forever)."""
    from submitit.core import utils

    class Bounded:
        """submitit's CommandFunction, as core.Executor._submit_command calls it: ``Bounded(cmd, ...)()``."""

        def __init__(self, command: list[str], verbose: bool = True, cwd: str | Path | None = None,
                     env: Mapping[str, str] | None = None) -> None:
            self.command, self.cwd, self.env = command, cwd, env

        def __call__(self) -> str:
            return run_command(self.command, timeout_s, cwd=self.cwd, env=self.env)

    before = utils.CommandFunction
    utils.CommandFunction = Bounded
    try:
        yield
    finally:
        utils.CommandFunction = before


def squeue_states(timeout_s: float) -> dict[str, str]:
    """Job id (``123``, ``123_4`` for array tasks) -> state of this user's jobs the controller knows: pending,
    running, requeued, and finished ones for MinJobAge (300 s by default). SchedulerError when squeue fails
    or does not answer within ``timeout_s``."""
    out = run_command(["squeue", "--noheader", "--array", "--states=all", "--format=%i %T", f"--user={os.getuid()}"],
                      timeout_s)
    return {f[0]: f[1] for f in (line.split() for line in out.splitlines()) if len(f) >= 2}
