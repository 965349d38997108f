"""nox sessions: tests, lint, regress, bench. `nox --no-venv -s NAME` runs one in the current environment
(CI does that for speed: the project is already installed there)."""

from __future__ import annotations

import os
from pathlib import Path

import nox

nox.options.sessions = ["lint", "tests", "regress"]
ROOT = Path(__file__).parent


def _install(session: nox.Session) -> None:
    if not isinstance(session.virtualenv, nox.virtualenv.PassthroughEnv):
        session.install("-e", ".[test]")


@nox.session
def tests(session: nox.Session) -> None:
    """The unit and end-to-end tests (real-data tests run when LFBENCH_HCI_ROOT is set)."""
    _install(session)
    session.run("pytest", "-q", *session.posargs)


@nox.session
def lint(session: nox.Session) -> None:
    """ruff over the package, the methods, tests, scripts and the example plugin."""
    if not isinstance(session.virtualenv, nox.virtualenv.PassthroughEnv):
        session.install("ruff")
    session.run("ruff", "check", "lfbench", "methods", "tests", "benchmarks", "results", "examples", "noxfile.py")


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
