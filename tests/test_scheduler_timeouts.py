"""Schedulers that hang or fail are named on one line, in seconds (issue 31.3): fake ``sbatch`` / ``srun`` /
``squeue`` / ``sacct`` scripts on PATH (one that never answers, one that fails), with the short bounds of
LFBENCH_SCHEDULER_TIMEOUT_S and LFBENCH_SCHEDULER_RETRIES. The real-cluster path is tests/test_slurm.py."""

from __future__ import annotations

import logging
import os
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from lfbench.ablation import jobs
from lfbench.ablation.scheduler import RETRIES_ENV, TIMEOUT_ENV, SchedulerError, SchedulerLimits
from lfbench.utils import executor
from lfbench.utils.errors import SpecError

pytest.importorskip("submitit", reason="the cluster path needs submitit (pip install -e '.[cluster]')")

SUBMITTED = 'echo "Submitted batch job 4242"'
UNREACHABLE = 'echo "slurm_load_jobs error: Unable to contact slurm controller (connect failure)" >&2; exit 1'


@pytest.fixture
def slurm(tmp_path, monkeypatch):
    """Writes fake SLURM commands into a folder first on PATH: ``slurm(sbatch=..., squeue=...)`` (shell
    bodies). A command that hangs records the pid of its sleep in NAME.pid; every call is logged in
    calls.log."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv(TIMEOUT_ENV, "1")
    monkeypatch.setenv(RETRIES_ENV, "2")

    def write(**bodies: str) -> Path:
        bodies = {"srun": "exit 0", "sacct": hang("sacct"), **bodies}
        for name, body in bodies.items():
            path = bin_dir / name
            path.write_text(f"#!/bin/sh\necho {name} >> {bin_dir}/calls.log\n{body}\n")
            path.chmod(0o755)
        return bin_dir

    def hang(name: str) -> str:
        return f"sleep 600 &\necho $! > {bin_dir}/{name}.pid\nwait"

    write.hang = hang
    return write


def within(seconds: float, fn):
    """fn() in a thread: its outcome (the exception it raised, or its value), failing the test if it has not
    ended after ``seconds`` (the old code waited forever)."""
    outcome: dict = {}

    def call() -> None:
        try:
            outcome["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            outcome["error"] = exc

    start = time.monotonic()
    thread = threading.Thread(target=call, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"still waiting after {seconds} s"
    outcome["seconds"] = time.monotonic() - start
    return outcome


def no_op_job(folder: Path, results: list) -> None:
    """One job of ``int("0")`` through --executor slurm (what benchmarks/slurm_overhead.py times)."""
    executor.executor_for(executor.ClusterOptions("slurm", timeout_min=5), folder=folder).map(
        int, ["0"], labels=["no-op"], threads=1, on_done=results.append)


def gone(pid_file: Path) -> bool:
    pid = int(pid_file.read_text())
    for _ in range(50):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    return False


def test_an_sbatch_that_never_answers_is_killed_and_named_on_one_line(slurm, tmp_path):
    bin_dir = slurm(sbatch=slurm.hang("sbatch"), squeue=SUBMITTED)
    results: list = []
    outcome = within(60, lambda: no_op_job(tmp_path / "jobs", results))
    error = outcome["error"]
    assert isinstance(error, SpecError)
    assert str(error) == f"submitting the jobs failed: sbatch did not answer within 1 s ({TIMEOUT_ENV})"
    assert outcome["seconds"] < 20 and results == []
    assert gone(bin_dir / "sbatch.pid")  # what sbatch started is killed with it


def test_a_failing_sbatch_is_its_own_last_line(slurm, tmp_path):
    slurm(sbatch='echo "sbatch: error: Batch job submission failed: Invalid account" >&2; exit 1', squeue="exit 0")
    outcome = within(60, lambda: no_op_job(tmp_path / "jobs", []))
    assert str(outcome["error"]) == "submitting the jobs failed: sbatch: error: Batch job submission failed: " \
                                    "Invalid account"
    slurm(sbatch="exit 3")  # says nothing: its status, and its name
    outcome = within(60, lambda: no_op_job(tmp_path / "jobs", []))
    assert str(outcome["error"]) == "submitting the jobs failed: sbatch exited with status 3 and printed nothing"


@pytest.mark.parametrize("how", ["fails", "hangs"])
def test_squeue_that_fails_or_hangs_is_retried_with_a_line_then_named(slurm, tmp_path, caplog, how):
    bin_dir = slurm(sbatch=SUBMITTED, squeue=UNREACHABLE if how == "fails" else slurm.hang("squeue"))
    reason = ("slurm_load_jobs error: Unable to contact slurm controller (connect failure)" if how == "fails"
              else f"squeue did not answer within 1 s ({TIMEOUT_ENV})")
    with caplog.at_level(logging.WARNING, logger="lfbench.ablation.jobs"):
        outcome = within(60, lambda: no_op_job(tmp_path / "jobs", []))
    error = outcome["error"]
    assert isinstance(error, SchedulerError)
    assert str(error) == (f"squeue failed 3 times in a row ({reason}): stopped waiting for job 4242 (no-op), "
                          "which may still run (squeue / scancel once SLURM answers); finished cells are kept: run "
                          "the same command again to resume the others")
    assert [r.getMessage() for r in caplog.records if r.name == "lfbench.ablation.jobs"] == [
        f"job states unknown: squeue failed ({reason}); asking again ({k} of 2, {RETRIES_ENV})" for k in (1, 2)]
    assert outcome["seconds"] < 30
    calls = (bin_dir / "calls.log").read_text().split()
    assert calls == ["sbatch", "squeue", "squeue", "squeue"]  # no sacct (it would hang: no accounting database)
    if how == "hangs":
        assert gone(bin_dir / "squeue.pid")


def test_jobs_that_finished_before_squeue_failed_are_kept(slurm, tmp_path, monkeypatch):
    """The results of jobs that ended reach the caller before the run stops, and the message names only the
    jobs still waited for."""
    slurm(squeue=UNREACHABLE, sbatch=SUBMITTED)
    (tmp_path / "0.pkl").write_bytes(b"")

    def job(k: int) -> SimpleNamespace:
        paths = SimpleNamespace(result_pickle=tmp_path / f"{k}.pkl", folder=tmp_path, stderr=tmp_path / f"{k}.err")
        return SimpleNamespace(job_id=f"77_{k}", paths=paths, result=lambda: f"result {k}")

    monkeypatch.setattr(jobs.Slurm, "_submit", lambda self, ex, fn, items, labels: [job(0), job(1)])
    slurm_ex = executor.executor_for(executor.ClusterOptions("slurm"), folder=tmp_path / "jobs")
    results: list = []
    outcome = within(60, lambda: slurm_ex.map(int, ["0", "1"], labels=["cell a", "cell b"], threads=1,
                                              on_done=results.append))
    assert results == ["result 0"]
    assert "stopped waiting for job 77_1 (cell b), which may still run" in str(outcome["error"])


def test_a_squeue_that_answers_again_resets_the_count(slurm, tmp_path, monkeypatch):
    """Failures count in a row: squeue failing twice, answering, failing twice, ... never stops the wait; the
    job that squeue no longer lists then ends the wait as before (no result: one line naming it)."""
    bin_dir = slurm(sbatch=SUBMITTED, squeue=f"""n=$(grep -c squeue {os.fspath(tmp_path)}/bin/calls.log)
case $n in 3|6) echo "4242 RUNNING";; 1|2|4|5) exit 1;; esac""")
    monkeypatch.setattr(jobs, "RESULT_GRACE_S", 0.0)
    outcome = within(60, lambda: no_op_job(tmp_path / "jobs", []))
    assert "no-op (job 4242) ended (gone from squeue) without a result" in str(outcome["error"])
    assert (bin_dir / "calls.log").read_text().split().count("squeue") >= 7


@pytest.mark.parametrize(("name", "value", "expected"), [
    (TIMEOUT_ENV, "abc", f"{TIMEOUT_ENV}='abc': expected seconds in (0, 86400]"),
    (TIMEOUT_ENV, "0", f"{TIMEOUT_ENV}='0': expected seconds in (0, 86400]"),
    (TIMEOUT_ENV, "nan", f"{TIMEOUT_ENV}='nan': expected seconds in (0, 86400]"),
    (RETRIES_ENV, "-1", f"{RETRIES_ENV}='-1': expected a whole number in [0, 1000]"),
    (RETRIES_ENV, "1.5", f"{RETRIES_ENV}='1.5': expected a whole number in [0, 1000]"),
])
def test_the_bounds_from_the_environment_are_checked(name, value, expected):
    with pytest.raises(SpecError) as err:
        SchedulerLimits.from_env({name: value})
    assert str(err.value) == expected
    assert SchedulerLimits.from_env({TIMEOUT_ENV: "2.5", RETRIES_ENV: "0"}) == SchedulerLimits(2.5, 0)
    assert SchedulerLimits.from_env({}) == SchedulerLimits(120.0, 10)


def test_ablate_with_a_bad_bound_is_one_line_before_any_work(slurm, tmp_path, monkeypatch, capsys):
    from lfbench.cli import main

    slurm(sbatch=SUBMITTED, squeue="exit 0")
    monkeypatch.setenv(TIMEOUT_ENV, "soon")
    spec = Path(__file__).resolve().parent.parent / "ablations" / "table4_cpu.toml"
    assert main(["ablate", str(spec), "--out", str(tmp_path / "out"), "--executor", "slurm"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"lfbench ablate: error: {TIMEOUT_ENV}='soon': expected seconds in (0, 86400]"]
    assert not (tmp_path / "out").exists()
