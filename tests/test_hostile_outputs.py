"""Whole output sets (issue 12.4, 12.5): a run's files appear together or not at all, stale temporaries
are cleaned, output paths are checked before the work, write errors are one line with nothing
half-written."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest
from helpers import assert_one_error_line, run_cli, write_scene

from lfbench.results import Results
from lfbench.utils.errors import DataError
from lfbench.utils.outputs import JOURNAL, MANIFEST, recover

SIZE = 32  # px: 2 px scored inside the 15 px border (a border that leaves none is refused)


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
    import lfbench.reports.writers as writers

    def full(*args, **kwargs):  # results.json and results.csv are written, then the disk fills
        raise OSError(errno.ENOSPC, "No space left on device", str(args[1]) + "/table_per_scene.md")

    monkeypatch.setattr(writers, "write_table", full)
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
    import lfbench.utils.outputs as outputs

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
    import lfbench.runs.runner as scoring  # where the runner scores each scene's predictions

    def no_work(*a, **k):
        raise AssertionError("scored before checking the output folder")

    monkeypatch.setattr(scoring, "score_predictions", no_work)
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


# --------------------------------------------------------------------------- a hostile output folder (issue 20.1)
# Everything read back from an output folder is untrusted: a journal or manifest naming paths outside OUT, a
# symbolic link among the staged files, must be refused in one line (exit 2) with nothing touched, in OUT or
# beside it.

PLANTED = ".lfbench-stage.1.planted"  # pid 1 is alive, but a journal names it: the commit is rolled forward


def tree(root: Path) -> dict[str, object]:
    """Every path under ``root``: file bytes, 'dir', or ('link', target); symbolic links are not followed."""
    out: dict[str, object] = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder) / name
            rel = str(path.relative_to(root))
            if path.is_symlink():
                out[rel] = ("link", os.readlink(path))
            elif path.is_dir():
                out[rel] = "dir"
            else:
                out[rel] = path.read_bytes()
    return out


def _journal(out: Path, stage: str = PLANTED, entries=(), remove=(), name: str = JOURNAL) -> Path:
    (out / name).write_text(json.dumps({"stage": stage, "entries": list(entries), "remove": list(remove)}))
    return out / name


def _victims(tmp: Path) -> Path:
    """A folder and a file beside OUT, as a user's own files."""
    (tmp / "victim_dir").mkdir()
    (tmp / "victim_dir" / "precious.txt").write_text("mine")
    (tmp / "victim_dir" / "results.json").write_text("not yours")
    (tmp / "victim.txt").write_text("mine too")
    return tmp


def _stage(out: Path) -> Path:
    (out / PLANTED).mkdir()
    return out / PLANTED


ATTACKS = {  # name -> (plant the attack into OUT beside the victims in tmp, file the one line names)
    "absolute-stage": (lambda out, t: _journal(out, stage=str(t / "victim_dir")), JOURNAL),
    "stage-dotdot": (lambda out, t: _journal(out, stage=".."), JOURNAL),
    "stage-is-out-itself": (lambda out, t: _journal(out, stage="."), JOURNAL),
    "remove-outside": (lambda out, t: (_stage(out), _journal(out, remove=["../victim.txt"])), JOURNAL),
    "remove-absolute": (lambda out, t: (_stage(out), _journal(out, remove=[str(t / "victim.txt")])), JOURNAL),
    "entry-outside": (lambda out, t: (_stage(out), (out / "X").write_text("planted"),
                                      _journal(out, entries=["../X"])), JOURNAL),
    "symlinked-stage": (lambda out, t: ((out / PLANTED).symlink_to(t / "victim_dir"),
                                        _journal(out, entries=["results.json"])), JOURNAL),
    "symlinked-entry": (lambda out, t: (_stage(out), (out / PLANTED / "results.json").symlink_to(t / "victim.txt"),
                                        _journal(out, entries=["results.json"])), JOURNAL),
    "symlink-inside-an-entry": (lambda out, t: (_stage(out), (out / PLANTED / "maps").mkdir(),
                                                (out / PLANTED / "maps" / "m").symlink_to(t / "victim_dir"),
                                                _journal(out, entries=["maps"])), JOURNAL),
    "symlinked-trash": (lambda out, t: (_stage(out), (out / PLANTED / ".trash").symlink_to(t / "victim_dir"),
                                        _journal(out, remove=["results.csv"])), JOURNAL),
    "journal-is-a-symlink": (lambda out, t: (out / JOURNAL).symlink_to(t / "victim.txt"), JOURNAL),
    "named-journal-absolute-stage": (lambda out, t: _journal(out, stage=str(t / "victim_dir"),
                                                             name=".lfbench-commit.train.json"),
                                     ".lfbench-commit.train.json"),
    "manifest-dotdot": (lambda out, t: (out / MANIFEST).write_text(
        json.dumps({"entries": ["results.json", "../victim.txt"]})), MANIFEST),
    "manifest-absolute": (lambda out, t: (out / MANIFEST).write_text(
        json.dumps({"entries": [str(t / "victim_dir")]})), MANIFEST),
    "manifest-names-the-journal": (lambda out, t: (out / MANIFEST).write_text(
        json.dumps({"entries": [JOURNAL]})), MANIFEST),
}


@pytest.mark.parametrize("attack", sorted(ATTACKS))
def test_a_hostile_journal_or_manifest_is_refused_and_nothing_is_touched(tmp_path, capsys, data, attack):
    out = tmp_path / "out"
    assert evaluate(capsys, data, out)[0] == 0
    plant, named = ATTACKS[attack]
    plant(out, _victims(tmp_path))
    before = tree(tmp_path)
    rc, _, err = evaluate(capsys, data, out, "--scenes", "s0")
    assert_one_error_line(rc, err, str(out / named), "nothing was changed")
    assert tree(tmp_path) == before  # the victims beside OUT, and OUT itself, exactly as they were


def _spec(tmp: Path, out: Path) -> Path:
    path = tmp / "spec.toml"
    path.write_text(f'title = "t"\nout = "{out}"\n[base.data]\ntrain = ["synthetic"]\n'
                    '[[base.data.synthetic]]\ncategory = "synthetic"\nseed = 1\nsize = 48\nscenes = 1\n'
                    '[base.model]\nwidth = 2\n[[base.stages]]\nname = "l1"\nloss = "l1"\nlr = 1e-3\nsteps = 1\n'
                    '[evaluation]\nsynthetic = { seed = 5, size = 48, scenes = 1 }\n[[grid]]\ninterval = [1.0]\n')
    return path


def _train_config(tmp: Path, data: Path) -> Path:
    path = tmp / "train.toml"
    path.write_text(f'[data]\nroots = ["{data}"]\n[model]\nwidth = 2\n[[stages]]\nloss = "l1"\nlr = 1e-3\n'
                    'steps = 1\n')
    return path


SET_WRITERS = {  # every command that writes a set (or finishes a cut commit) into OUT, and its argv
    "evaluate": lambda t, d, out: ["evaluate", "--data", d, "--method", "gt", "--out", out, "--no-progress"],
    "evaluate-html": lambda t, d, out: ["evaluate", "--data", d, "--method", "gt", "--out", out, "--html",
                                        "--no-progress"],
    "demo": lambda t, d, out: ["demo", "--out", out, "--size", "32", "--scenes", "1", "--methods", "gt",
                               "--no-progress"],
    "report": lambda t, d, out: ["report", _results(t, d), "--out", out, "--html"],
    "ablate": lambda t, d, out: ["ablate", _spec(t, out), "--out", out, "--no-progress"],
    "ablate-report-only": lambda t, d, out: ["ablate", _spec(t, out), "--out", out, "--report-only", "--html"],
    "train": lambda t, d, out: ["-q", "train", _train_config(t, d), "--out", out, "--no-progress"],
}


def _results(tmp: Path, data: Path) -> Path:
    from lfbench.cli import main

    assert main(["-q", "evaluate", "--data", str(data), "--method", "gt", "--out", str(tmp / "ev"),
                 "--no-progress"]) == 0
    return tmp / "ev"


@pytest.mark.parametrize("command", sorted(SET_WRITERS))
@pytest.mark.parametrize("attack", ["absolute-stage", "remove-outside", "manifest-dotdot"])
def test_every_set_writer_refuses_a_hostile_folder_before_any_work(tmp_path, capsys, data, command, attack):
    out = tmp_path / "out"
    out.mkdir()
    argv = SET_WRITERS[command](tmp_path, data, out)
    capsys.readouterr()
    plant, named = ATTACKS[attack]
    plant(out, _victims(tmp_path))
    if command == "train" and named == MANIFEST:  # a training run's exports are the set named 'train'
        named = ".lfbench-outputs.train.json"
        os.rename(out / MANIFEST, out / named)
    before = tree(tmp_path)
    rc, _, err = run_cli(capsys, *argv)
    assert_one_error_line(rc, err, str(out / named), "nothing was changed")
    after = {k: v for k, v in tree(tmp_path).items() if not k.endswith(".lock")}  # the commands' locks
    assert after == before


def test_a_report_never_writes_outside_its_folder_whatever_names_the_results_hold(tmp_path, capsys, data):
    """Method and scene names are file names in a report (figures, pages, images): '..', '.' or a path
    in results.json or its curves must stay names inside the report's folder."""
    res = tmp_path / "res"
    assert evaluate(capsys, data, res, "--figures")[0] == 0
    doc = json.loads((res / "results.json").read_text())
    names = {"s0": "..", "s1": "../../escaped"}
    for item in doc["records"] + doc["runs"]:
        item["scene"] = names[item["scene"]]
        item["method"] = "." if item["method"] == "gt" else "/abs/method"
    (res / "results.json").write_text(json.dumps(doc))
    curves = res / "figures" / "badpix_series.csv"
    text = curves.read_text()
    for old, new in names.items():
        text = text.replace(f",{old},", f",{new},")
    curves.write_text(text)
    before = tree(tmp_path)
    rc, _, err = run_cli(capsys, "report", res, "--out", tmp_path / "rep" / "r", "--html")
    assert rc == 0, err
    after = tree(tmp_path)
    new = sorted(k for k in after if k not in before)
    assert all(k == "rep" or k.startswith("rep/r") for k in new), new  # nothing beside the report's folder
    top = sorted(p.name for p in (tmp_path / "rep" / "r").iterdir())
    assert top == [MANIFEST, "figures", "html", "table_average.csv", "table_average.md", "table_average.tex",
                   "table_per_scene.csv", "table_per_scene.md", "table_per_scene.tex"]


@pytest.mark.parametrize("where", ["method-folder", "maps-folder"])
def test_saved_maps_that_lead_out_of_the_results_folder_are_refused(tmp_path, capsys, data, where):
    res = tmp_path / "res"
    assert evaluate(capsys, data, res, "--save-maps")[0] == 0
    elsewhere = tmp_path / "elsewhere"
    if where == "method-folder":  # maps/gt -> a folder outside, holding maps of its own
        os.rename(res / "maps" / "gt", elsewhere)
        (res / "maps" / "gt").symlink_to(elsewhere)
        link = res / "maps" / "gt"
    else:  # maps itself -> outside
        os.rename(res / "maps", elsewhere)
        (res / "maps").symlink_to(elsewhere)
        link = res / "maps"
    rc, _, err = run_cli(capsys, "report", res, "--out", tmp_path / "rep", "--html")
    assert_one_error_line(rc, err, str(link), "symbolic link leading out of")
    assert not (tmp_path / "rep").exists()


def test_a_journal_whose_staging_folder_is_gone_is_refused_not_guessed(tmp_path, capsys, data):
    out = tmp_path / "out"
    assert evaluate(capsys, data, out)[0] == 0
    _journal(out, entries=["results.json"])
    before = tree(tmp_path)
    rc, _, err = evaluate(capsys, data, out)
    assert_one_error_line(rc, err, str(out / JOURNAL), "staging folder", "is gone")
    assert tree(tmp_path) == before


@pytest.mark.parametrize("where", ["stage1", "cells", "methods/zero"])
def test_an_ablation_folder_leading_out_of_out_is_refused_before_any_work(tmp_path, capsys, where):
    """An ablation trains and scores into OUT/stage1, OUT/cells/<id> and OUT/methods/<label>: a symbolic
    link there to a folder elsewhere would make it write (and replace files) outside OUT."""
    out = tmp_path / "out"
    spec = _spec(tmp_path, out)
    spec.write_text(spec.read_text() + '[[methods]]\nlabel = "zero"\nspec = "constant:value=0"\n')
    _victims(tmp_path)
    (out / where).parent.mkdir(parents=True, exist_ok=True)
    (out / where).symlink_to(tmp_path / "victim_dir")
    before = tree(tmp_path)
    rc, _, err = run_cli(capsys, "ablate", spec, "--out", out, "--no-progress")
    assert_one_error_line(rc, err, str(out / where), "symbolic link leading out of the ablation folder")
    after = {k: v for k, v in tree(tmp_path).items() if not k.endswith(".lock")}
    assert after == before


@pytest.mark.parametrize(("key", "value", "fragment"), [
    ("data_root", 5, "'meta.data_root' must be a folder name"),
    ("data_root", ["/etc"], "'meta.data_root' must be a folder name"),
    ("scenes", "s0", "'meta.scenes' must be a list"),
    ("scenes", [1, 2], "must be folder names"),
    ("ablation", "title", "'meta.ablation' must be an object"),
    ("ablation", {"title": {"x": 1}}, "string title"),
    ("scoring", [], "'meta.scoring' must be an object"),
    ("scoring", {"border_px": "15"}, "'meta.scoring.border_px' must be an integer >= 0"),
    ("scoring", {"border_px": -5}, "'meta.scoring.border_px' must be an integer >= 0"),
    ("scoring", {"highres_scenes": "dots"}, "'meta.scoring.highres_scenes' must be a list"),
    ("scoring", {"toolkit_nonfinite": "false"}, "'meta.scoring.toolkit_nonfinite' must be true or false"),
    ("created", 3, "'meta.created' must be a string"),
])
@pytest.mark.parametrize("command", ["report", "report-html", "report-maps"])
def test_meta_read_back_with_the_wrong_types_is_one_line(tmp_path, capsys, data, key, value, fragment, command):
    """What a results file's meta tells a later command (its data root, scenes, ablation title, scoring
    rules) is untrusted: a value of the wrong type is one line naming results.json, before any output."""
    res = tmp_path / "res"
    assert evaluate(capsys, data, res)[0] == 0
    doc = json.loads((res / "results.json").read_text())
    doc["meta"][key] = value
    (res / "results.json").write_text(json.dumps(doc))
    extra = {"report": [], "report-html": ["--html"], "report-maps": ["--maps", str(res / "maps")]}[command]
    rc, _, err = run_cli(capsys, "report", res, "--out", tmp_path / "rep", *extra)
    assert_one_error_line(rc, err, str(res / "results.json"), fragment)
    assert not (tmp_path / "rep").exists()
