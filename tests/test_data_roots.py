"""Issue 32.6: `lfbench evaluate --data ROOT1 --data ROOT2` scores the scenes of several data roots into one
results file (so one golden file gates them all); scenes keep their names, two selected scenes of one name
are refused with one line naming both folders (never renamed), and the report finds every root again."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import write_scene

from lfbench.cli import main
from lfbench.results import Results


@pytest.fixture()
def roots(tmp_path):
    """Two data roots: boxes (training) in the first, dots (stratified) in the second."""
    first, second = tmp_path / "hci", tmp_path / "synthetic"
    write_scene(first, "boxes", "training", size=40, seed=0)
    write_scene(second, "dots", "stratified", size=40, seed=1, gt=np.full((40, 40), 0.5, np.float32))
    return first, second


def test_two_data_roots_are_scored_into_one_results_file(roots, tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["evaluate", "--data", str(roots[0]), "--data", str(roots[1]), "--method", "constant:value=0.5",
               "--out", str(out), "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    results = Results.read(out)
    assert results.scenes == ["boxes", "dots"]
    assert results.value("constant:value=0.5", "dots", "badpix_0.07") == 0.0  # its ground truth is 0.5 px
    assert results.data_roots == list(roots)
    meta = json.loads((out / "results.json").read_text())["meta"]
    assert meta["data_root"] == str(roots[0]) and meta["data_roots"] == [str(r) for r in roots]
    # one golden file from the merged results gates both roots' scenes
    golden = tmp_path / "golden.json"
    assert main(["regress", str(golden), str(out), "--update"]) == 0
    assert {r["scene"] for r in json.loads(golden.read_text())} == {"boxes", "dots"}
    capsys.readouterr()
    assert main(["regress", str(golden), str(out)]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith("OK: 10 compared, 0 regressions")


def test_scene_selection_spans_the_roots(roots, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["evaluate", "--data", str(roots[0]), "--data", str(roots[1]), "--method", "gt", "--scenes", "dots",
                 "--out", str(out), "--no-progress"]) == 0
    assert Results.read(out).scenes == ["dots"]
    capsys.readouterr()
    assert main(["evaluate", "--data", str(roots[0]), "--data", str(roots[1]), "--method", "gt", "--scenes", "nope",
                 "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no scene 'nope'; available: boxes, dots" in err[0]
    assert str(roots[0]) in err[0] and str(roots[1]) in err[0]


def test_a_scene_name_in_two_roots_is_refused_in_one_line_before_any_work(roots, tmp_path, capsys):
    write_scene(roots[1], "boxes", "additional", size=40, seed=2)
    out = tmp_path / "run"
    rc = main(["evaluate", "--data", str(roots[0]), "--data", str(roots[1]), "--method", "gt", "--out", str(out),
               "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "two scenes are named 'boxes'" in err[0]
    assert str(roots[0] / "training" / "boxes") in err[0] and str(roots[1] / "additional" / "boxes") in err[0]
    assert not out.exists()
    # selecting one of them by category is the way out
    assert main(["evaluate", "--data", str(roots[0]), "--data", str(roots[1]), "--method", "gt", "--scenes",
                 "training,stratified", "--out", str(out), "--no-progress"]) == 0
    assert Results.read(out).scenes == ["boxes", "dots"]


def test_a_root_given_twice_is_refused(roots, tmp_path, capsys):
    rc = main(["evaluate", "--data", str(roots[0]), "--data", str(roots[0] / "." ), "--method", "gt", "--out",
               str(tmp_path / "run"), "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "data root given twice" in err[0]


def test_the_report_finds_the_scenes_of_every_recorded_root(roots, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["evaluate", "--data", str(roots[0]), "--data", str(roots[1]), "--method", "gt", "--out", str(out),
                 "--save-maps", "--no-progress"]) == 0
    rep = tmp_path / "rep"
    assert main(["report", str(out), "--out", str(rep), "--html", "--maps", str(out / "maps")]) == 0, \
        capsys.readouterr().err
    for scene in ("boxes", "dots"):
        page = (rep / "html" / f"scene-{scene}.html").read_text(encoding="utf-8")
        assert f'src="img/{scene}/centre.png"' in page and f'src="img/{scene}/gt.disp.png"' in page
    # the roots moved: give them again, one --data each
    moved = [tmp_path / "moved_hci", tmp_path / "moved_synthetic"]
    for old, new in zip(roots, moved, strict=True):
        old.rename(new)
    rep2 = tmp_path / "rep2"
    assert main(["report", str(out), "--out", str(rep2), "--html", "--maps", str(out / "maps"), "--data",
                 str(moved[0]), "--data", str(moved[1])]) == 0, capsys.readouterr().err
    for scene in ("boxes", "dots"):
        assert f'src="img/{scene}/gt.disp.png"' in (rep2 / "html" / f"scene-{scene}.html").read_text(encoding="utf-8")


@pytest.mark.parametrize(("key", "value", "message"), [
    ("data_roots", [1], "'meta.data_roots' must be folder names"),
    ("data_roots", "ROOT", "'meta.data_roots' must be a list of folder names"),
    ("references", [None], "'meta.references' must be method labels"),
])
def test_recorded_roots_and_references_are_checked_where_they_are_read(roots, tmp_path, capsys, key, value, message):
    out = tmp_path / "run"
    assert main(["evaluate", "--data", str(roots[0]), "--method", "gt", "--out", str(out), "--no-progress"]) == 0
    data = json.loads((out / "results.json").read_text())
    data["meta"][key] = value
    (out / "results.json").write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["report", str(out), "--out", str(tmp_path / "rep")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "results.json" in err[0]
