"""Worker processes import lfbench and plugins as installed, never from the current folder (issue 20,
class 9): run from a folder holding a decoy ``lfbench`` package (as a clone named lfbench would be), the
bench's per-case processes and the ablation's submitit jobs used to import the decoy."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

DECOY = 'raise ImportError("decoy lfbench imported from the current folder")\n'


@pytest.fixture()
def decoy_cwd(tmp_path, monkeypatch) -> Path:
    """The current folder holds a package named lfbench that fails to import, and one named like the
    bundled plugins' package."""
    for name in ("lfbench", "lfbench_methods"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text(DECOY, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("PYTHONSAFEPATH", raising=False)
    return tmp_path


def test_bench_cases_do_not_import_from_the_current_folder(decoy_cwd):
    from lfbench.runs import bench

    record = bench.run_isolated("metrics", {"scenes": 1, "methods": 1, "size": 32}, timeout_s=300)
    assert "error" not in record, record
    assert record["metrics"] == 5 and record["scores_per_s"] > 0
    assert "PYTHONSAFEPATH" not in os.environ  # only the workers' environment


def test_safe_path_environ_restores_the_environment(monkeypatch):
    from lfbench.utils.subprocesses import safe_path_env, safe_path_environ

    monkeypatch.setenv("PYTHONSAFEPATH", "")
    with safe_path_environ():
        assert os.environ["PYTHONSAFEPATH"] == "1"
    assert os.environ["PYTHONSAFEPATH"] == ""
    monkeypatch.delenv("PYTHONSAFEPATH")
    with safe_path_environ():
        pass
    assert "PYTHONSAFEPATH" not in os.environ
    assert safe_path_env({"A": "b"}) == {"A": "b", "PYTHONSAFEPATH": "1"}


def test_ablation_jobs_do_not_import_from_the_current_folder(decoy_cwd):
    """submitit's local executor (the --executor path): a job unpickles its function, importing lfbench."""
    pytest.importorskip("submitit", reason="the cluster path needs submitit (pip install -e '.[cluster]')")
    from lfbench.utils.executor import ClusterOptions, executor_for
    from lfbench.utils.names import file_name

    done: list = []
    executor_for(ClusterOptions(executor="local", timeout_min=5), folder=decoy_cwd / "jobs").map(
        file_name, ["a<b", ".."], labels=["job a<b", "job .."], threads=1, on_done=done.append)
    assert done == ["a_b", "__"]
