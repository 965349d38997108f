"""Whole output sets (issue 12.4, 12.5): a run's files appear together or not at all, stale temporaries
are cleaned, output paths are checked before the work, write errors are one line with nothing
half-written."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest
from helpers import assert_one_error_line, run_cli, write_scene

from lfbench.runs.outputs import JOURNAL, recover
from lfbench.runs.results import Results
from lfbench.utils.errors import DataError

SIZE = 24


@pytest.fixture()
def data(tmp_path) -> Path:
    for i in range(2):
        write_scene(tmp_path / "data", f"s{i}", "training", size=SIZE, seed=i, view_disparity=i)
    return tmp_path / "data"


def evaluate(capsys, data: Path, out: Path, *extra):
    return run_cli(capsys, "evaluate", "--data", data, "--method", "gt", "--method", "planesweep:interval=1",
                   "--out", out, "--no-progress", *extra)


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_failure_while_writing_leaves_the_previous_run_whole(tmp_path, capsys, data, monkeypatch):
    out = tmp_path / "out"
    rc, _, err = evaluate(capsys, data, out)
    assert rc == 0, err
    before = snapshot(out)
    import lfbench.reports.tables as tables

    def full(*args, **kwargs):  # results.json and results.csv are written, then the disk fills
        raise OSError(errno.ENOSPC, "No space left on device", str(args[1]) + "/table_per_scene.md")

    monkeypatch.setattr(tables, "write_tables", full)
    rc, _, err = evaluate(capsys, data, out, "--scenes", "s0")
    assert_one_error_line(rc, err, "table_per_scene.md", "No space left on device", f"nothing written to {out}")
    assert str(out / "table_per_scene.md") in err  # named where it would have landed, not in the staging folder
    assert snapshot(out) == before  # the old run, complete: no new results.json beside old tables
    assert not [p.name for p in out.iterdir() if p.name.startswith(".lfbench-stage")]


def test_a_commit_cut_short_is_refused_by_readers_and_rolled_forward(tmp_path, capsys, data, monkeypatch):
    """As if killed during the commit (after the journal, between two renames): readers refuse the folder
    instead of mixing two runs; the next run finishes the commit."""
    out = tmp_path / "out"
    assert evaluate(capsys, data, out)[0] == 0
    import lfbench.runs.outputs as outputs

    real_replace, calls = os.replace, []

    def killed(src, dst):
        if ".lfbench-stage" in str(src) and Path(dst).parent == out:  # an entry moved into OUT
            calls.append(dst)
        if len(calls) == 3:
            raise KeyboardInterrupt  # stands for kill -9: nothing after this line runs
        return real_replace(src, dst)

    monkeypatch.setattr(outputs.os, "replace", killed)
    rc, _, _ = evaluate(capsys, data, out, "--scenes", "s0")
    assert rc == 130 and (out / JOURNAL).is_file()
    monkeypatch.setattr(outputs.os, "replace", real_replace)
    with pytest.raises(DataError, match="interrupted run left this folder half updated"):
        Results.read(out)
    rc, _, err = run_cli(capsys, "report", out / "results.json", "--out", tmp_path / "rep")
    assert_one_error_line(rc, err, "interrupted run")
    recover(out)  # what the next run does first
    res = Results.read(out)
    assert res.scenes == ["s0"]  # the new run's records ...
    csv_rows = (out / "results.csv").read_text().splitlines()[1:]
    assert len(csv_rows) == len(res.records) and all(",s0," in row for row in csv_rows)  # ... and its csv
    assert "s1" not in (out / "table_per_scene.md").read_text()


def test_outputs_of_the_previous_run_it_does_not_write_are_dropped_others_kept(tmp_path, capsys, data):
    out = tmp_path / "out"
    assert evaluate(capsys, data, out, "--ci", "--ci-resamples", "20")[0] == 0
    assert (out / "ci.csv").is_file()
    (out / "notes.txt").write_text("mine")
    assert evaluate(capsys, data, out)[0] == 0
    assert not (out / "ci.csv").exists() and not (out / "table_ci_per_scene.md").exists()  # stale: gone
    assert (out / "notes.txt").read_text() == "mine"


def test_stale_temporaries_are_cleaned_by_the_next_run(tmp_path, capsys, data):
    out = tmp_path / "out"
    for name in (".lfbench-stage.999999999.abc", ".figures.x1.tmp", ".maps.x2.tmp", ".data.x3.tmp",
                 ".figures.x4.old", ".html.x5.tmp"):
        (out / name).mkdir(parents=True)
        (out / name / "junk").write_text("x")
    assert evaluate(capsys, data, out)[0] == 0
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == [".lfbench-outputs.json"]


def test_output_paths_are_checked_before_the_work(tmp_path, capsys, data, monkeypatch):
    import lfbench.runs.runner as runner

    def no_work(*a, **k):
        raise AssertionError("scored before checking the output folder")

    monkeypatch.setattr(runner, "score_scene", no_work)
    (tmp_path / "file").write_text("x")
    rc, _, err = evaluate(capsys, data, tmp_path / "file")
    assert_one_error_line(rc, err, "file", "output folder is a file")
    rc, _, err = evaluate(capsys, data, tmp_path / "file" / "sub")
    assert_one_error_line(rc, err, "cannot create the output folder")
    if os.geteuid() != 0:  # root may write anywhere
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        rc, _, err = evaluate(capsys, data, ro)
        assert_one_error_line(rc, err, "ro", "not writable")


def test_a_scene_folder_name_that_is_not_utf8_is_one_line(tmp_path, capsys, data):
    bad = os.fsencode(data / "training") + b"/caf\xe9"
    os.rename(os.fsencode(data / "training" / "s1"), bad)
    rc, _, err = evaluate(capsys, data, tmp_path / "out")
    assert_one_error_line(rc, err, "caf\\xe9", "not valid UTF-8")
    assert not (tmp_path / "out").exists()
