"""A scoring worker that dies (issue 31, class 6): SIGKILL one ``evaluate --jobs 2`` worker (the pool's test hook
makes a worker kill itself on the item labelled by LFBENCH_TEST_KILL_WORKER, a scene's name here, as the
out-of-memory killer would) -> one line naming that scene, exit 1 (README), the previous output set kept, and the
next run works. It was a BrokenProcessPool traceback."""

from __future__ import annotations

import json

import pytest
from helpers import run_cli, write_scene

from lfbench.utils.executor import KILL_WORKER_ENV


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("data")
    for i, name in enumerate(("alpha", "beta", "gamma")):
        write_scene(root, name, "training", size=32, seed=i)
    return root


def _evaluate(capsys, root, out, method, jobs=2):
    return run_cli(capsys, "-q", "evaluate", "--data", root, "--method", method, "--out", out, "--jobs", str(jobs),
                   "--no-progress")


@pytest.mark.parametrize("victim", ["beta"])  # a scene with others in flight before and after it
def test_a_killed_scoring_worker_is_one_line_naming_its_scene(tmp_path, capsys, monkeypatch, root, victim):
    out = tmp_path / "out"
    rc, _, err = _evaluate(capsys, root, out, "gt", jobs=1)  # the previous output set (no pool needed for it)
    assert rc == 0, err
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    monkeypatch.setenv(KILL_WORKER_ENV, victim)
    rc, _, err = _evaluate(capsys, root, out, "constant")
    assert rc == 1, err  # not bad input: the run failed (README: exit 1)
    assert "Traceback" not in err and "BrokenProcessPool" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("lfbench evaluate: error: a scoring worker process died")
    assert f"while scoring scene {victim!r}:" in lines[0]
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before  # the old set, whole
    assert not [p for p in tmp_path.rglob("*") if p.name.startswith(".lfbench-stage")]
    monkeypatch.delenv(KILL_WORKER_ENV)
    rc, _, err = _evaluate(capsys, root, out, "constant")
    assert rc == 0, err
    records = json.loads((out / "results.json").read_text())["records"]
    assert {r["method"] for r in records} == {"constant"}
    assert {r["scene"] for r in records} == {"alpha", "beta", "gamma"}
