"""nox sessions: tests, lint, regress, bench, mutation. `nox --no-venv -s NAME` runs one in the current environment
(CI does that for speed: the project is already installed there)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import nox

nox.options.sessions = ["lint", "tests", "regress"]
ROOT = Path(__file__).parent


def _install(session: nox.Session) -> None:
    if not isinstance(session.virtualenv, nox.virtualenv.PassthroughEnv):
        session.install("-e", ".[test]")


@nox.session
def tests(session: nox.Session) -> None:
    """Every test, the slow ones included (-m ""; posargs replace it); real-data tests run when LFBENCH_HCI_ROOT
    is set."""
    _install(session)
    session.run("pytest", "-q", *(session.posargs or ["-m", ""]))


@nox.session
def lint(session: nox.Session) -> None:
    """ruff over the package, the methods, tests, scripts and the example plugin."""
    if not isinstance(session.virtualenv, nox.virtualenv.PassthroughEnv):
        session.install("ruff")
    session.run("ruff", "check", "lfbench", "methods", "tests", "benchmarks", "tools", "results", "examples",
                "noxfile.py")


@nox.session
def regress(session: nox.Session) -> None:
    """Recompute the deterministic golden runs and compare them with results/golden.json. Without
    LFBENCH_HCI_ROOT the synthetic runs are compared and the real-scene records skipped (the summary
    counts both and names the absent scenes); a run that compared nothing fails."""
    _install(session)
    out = Path(session.create_tmp()) / "regress"
    hci = os.environ.get("LFBENCH_HCI_ROOT")
    args = ["--out", str(out)] + (["--hci", hci] if hci else [])
    session.run("python", str(ROOT / "results" / "golden.py"), *args)
    skip = [] if hci else ["--skip-absent-scenes"]
    session.run("lfbench", "regress", str(ROOT / "results" / "golden.json"), str(out / "results.json"), *skip)


@nox.session
def bench(session: nox.Session) -> None:
    """Speed and memory benchmarks (not part of the tests)."""
    _install(session)
    session.run("lfbench", "bench", *session.posargs)


@nox.session
def mutation(session: nox.Session) -> None:
    """Mutation testing of the scoring core and the regression gate with mutmut (configured in pyproject.toml,
    [tool.mutmut]); long (~35 min on 2 cores), so not a default session. Starts from scratch, re-checks in
    fresh processes the mutants of code that runs at import, writes the survivors to results/mutation/
    (README.md there) with the scripts of tools/mutation/ and fails if one has no reason.
    ``nox -s mutation -- --max-children 2`` passes options to ``mutmut run``."""
    if not isinstance(session.virtualenv, nox.virtualenv.PassthroughEnv):
        session.install("-e", ".[test,mutation]")
    shutil.rmtree(ROOT / "mutants", ignore_errors=True)  # cached verdicts would hide changed tests
    out = ROOT / "results" / "mutation"  # what the run produces
    tools = ROOT / "tools" / "mutation"  # the scripts that produce it
    # one OpenMP thread: mutmut forks each mutant's tests from a process that ran torch, and a forked child that
    # finds the parent's OpenMP pool waits for its threads forever (the planesweep's sweep hung there, 0 CPU s)
    session.run("mutmut", "run", *(session.posargs or ["--max-children", "1"]),
                env={"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})
    session.run("python", str(tools / "recheck_import_time.py"), "--out", str(out / "recheck_import_time.json"))
    with open(out / "mutmut_results.txt", "w", encoding="utf-8") as f:
        session.run("mutmut", "results", stdout=f, stderr=None)
    with open(out / "survivors.txt", "w", encoding="utf-8") as f:
        session.run("python", str(tools / "survivors.py"), "--recheck", str(out / "recheck_import_time.json"),
                    stdout=f, stderr=None)
    # fails when a survivor has no reason: a test is missing, or classify.py must say why it is equivalent
    session.run("python", str(tools / "classify.py"), "--recheck", str(out / "recheck_import_time.json"),
                "--out", str(out / "survivors_classified.md"))
