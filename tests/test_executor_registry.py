"""Where ablation cells run is one interface in one registry (issue 29.4): an executor added to
lfbench.utils.executor.EXECUTORS is a choice of ``lfbench ablate --executor`` and runs the cells and the
test timings, with no change to the runner or the command line."""

from __future__ import annotations

import argparse

import pytest

from lfbench.ablation import runner
from lfbench.ablation.cell import CellTask
from lfbench.cli import ablate
from lfbench.utils import executor
from lfbench.utils.errors import SpecError
from lfbench.utils.executor import EXECUTORS, ClusterOptions


class Recording(executor.Executor):
    """Runs nothing: records what it was asked to map."""

    help = "records the items"
    calls: list[tuple[list[str], int]] = []

    def map(self, fn, items, *, labels, threads, on_done, on_start=None, cost=None) -> None:
        Recording.calls.append((list(labels), threads))
        for label, item in zip(labels, items, strict=True):
            if label == "test time":  # one batch of every cell
                on_done([{"test_s": 0.25, "time_size": 64, "device": "cpu"} for _ in item])
            else:
                on_done({"id": item.cell_id, "steps": 5, "train_s": 1.0, "own_train_s": 0.5, "scenes": []})


@pytest.fixture
def recording(monkeypatch):
    """``recording`` registered for the test only."""
    monkeypatch.setitem(EXECUTORS._objects, "recording", Recording)
    monkeypatch.setitem(EXECUTORS._entries, "recording", Recording)
    Recording.calls = []


def tasks(tmp_path, count: int) -> list[CellTask]:
    config = {"model": {}, "stages": [{"steps": 10}]}
    return [CellTask(cell_id=f"c{i}", values={}, config=config, fingerprint="f", eval_fingerprint="e",
                     cell_dir=str(tmp_path / f"c{i}"), data_links={}, stage1_dir=None, scenes=(), evaluation=None,
                     threads=3) for i in range(count)]


def test_a_registered_executor_is_a_choice_and_runs_the_cells_and_the_timing(recording, tmp_path):
    parser = argparse.ArgumentParser()
    ablate.add_arguments(parser)
    args = parser.parse_args(["spec.toml", "--executor", "recording"])
    assert args.executor == "recording"
    assert "recording: records the items" in " ".join(parser.format_help().split())
    chosen = executor.executor_for(ClusterOptions(args.executor), jobs=1)
    assert type(chosen) is Recording
    seen: list[str] = []
    markers = runner.run_cells(tasks(tmp_path, 2), chosen, progress=False, log=seen.append)
    assert Recording.calls == [(["cell c0", "cell c1"], 3)]
    assert seen == [f"cell c{i}: trained 5 steps in 1.0 s (own 0.5 s), scored on 0 scene(s)" for i in (0, 1)]
    assert markers == [{}, {}]  # the markers are read back from the cells' folders (none written here)
    seen.clear()
    timings = runner.time_cells(tasks(tmp_path, 2), 2, progress=False, log=seen.append, executor=chosen)
    assert Recording.calls[1:] == [(["test time"], 2)]  # one item: every cell's timing, with the timing threads
    assert len(timings) == 2 and seen[0] == "cell c0: test time 0.25 s for 9x9x64x64 (cpu, 2 threads)"


def test_the_builtin_executors_and_an_unknown_name():
    assert EXECUTORS.names() == ["inline", "local", "pool", "slurm"]
    with pytest.raises(SpecError) as err:
        ClusterOptions("pbs")
    assert str(err.value) == "Unknown executor 'pbs'. Available: inline, local, pool, slurm"
    with pytest.raises(SpecError) as err:
        executor.executor_for(ClusterOptions("inline"), jobs=2).check()
    assert str(err.value) == "--executor inline runs one cell at a time: --jobs 2 needs --executor pool"
    pool = executor.executor_for(None, jobs=2)
    assert type(pool) is executor.ProcessPool and pool.runs_here(1) and not pool.runs_here(2)
    assert executor.executor_for(None, jobs=1).runs_here(5)
    assert executor.executor_for(ClusterOptions("slurm", cpus_per_job=4)).cpus_per_item == 4
    assert executor.executor_for(ClusterOptions("pool", cpus_per_job=4)).cpus_per_item == 0
