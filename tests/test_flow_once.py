"""Issue 29.5, checks and work done once along a flow: the names of a run are checked once per entry point, by one
function (lfbench.results.check_names), before any work; the layers below (the runner, the site, the staged
results read back) trust them. The messages of the check are the ones the hostile-name tests pin. The HTML site
draws the BadPix series the figure writer computed instead of computing them again."""

from __future__ import annotations

import inspect
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, run_cli, write_scene
from test_ablation_maps import ablation  # noqa: F401 - a finished ablation (module fixture)

import lfbench.results
from lfbench.results import check_names

SIZE = 40


@pytest.fixture()
def count_checks(monkeypatch) -> list[tuple]:
    """Every call of lfbench.results.check_names, wherever a module bound it, as (methods, scenes)."""
    calls: list[tuple] = []

    def counted(methods, scenes, keys=(), **kwargs):
        methods, keys = list(methods), list(keys)
        calls.append((methods, kwargs.get("scene_folders") or list(scenes)))
        return check_names(methods, scenes, keys, **kwargs)

    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("lfbench") and getattr(module, "check_names", 0) is check_names:
            monkeypatch.setattr(module, "check_names", counted)
    return calls


@pytest.fixture()
def data(tmp_path) -> Path:
    gt = np.zeros((SIZE, SIZE), np.float32)
    for name in ("alpha", "beta"):
        write_scene(tmp_path / "data", name, gt=gt)
    return tmp_path / "data"


def test_one_function_named_check_names():
    """No second function of that name anywhere in lfbench (there were two, with different arguments)."""
    import lfbench.ablation.runner
    import lfbench.reports.from_results
    import lfbench.reports.html
    import lfbench.runs.folder
    import lfbench.runs.runner  # noqa: F401

    found = {f"{m.__name__}.check_names" for m in list(sys.modules.values())
             if getattr(m, "__name__", "").startswith("lfbench") and inspect.isfunction(getattr(m, "check_names", None))
             and m.check_names is not check_names}
    assert found == set()
    assert check_names.__module__ == "lfbench.results"


def test_evaluate_checks_once(data, tmp_path, capsys, count_checks):
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", data, "--method", "gt", "--method", "constant", "--out", out,
                         "--html", "--no-progress")
    assert rc == 0, err
    assert len(count_checks) == 1  # before: the folder's, the runner's, the staged results' and the site's
    methods, scenes = count_checks[0]
    assert methods == ["gt", "constant"] and [s.name for s in scenes] == ["alpha", "beta"]
    assert (out / "html" / "index.html").is_file()

    # report of that run (--html): the results file's check when it is read, none by the site
    count_checks.clear()
    rc, _, err = run_cli(capsys, "report", out, "--out", tmp_path / "rep", "--html")
    assert rc == 0, err
    assert len(count_checks) == 1 and count_checks[0][0] == ["gt", "constant"]
    assert (tmp_path / "rep" / "html" / "index.html").is_file()


def test_the_messages_are_those_of_the_one_check(data, tmp_path, capsys, count_checks):
    """A method given twice, and two labels of one file name: one line each, before anything is written."""
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", data, "--method", "gt", "--method", "gt", "--out", out)
    assert_one_error_line(rc, err, "method 'gt' would run on scene 'alpha' twice (given twice?): its records "
                                   "would be duplicated")
    rc, _, err = run_cli(capsys, "evaluate", "--data", data, "--method", "gt", "--method", "constant", "--label", "m<1",
                         "--label", "m>1", "--out", out)
    line = assert_one_error_line(rc, err, "method label", "'m<1'", "'m>1'")
    assert len(count_checks) == 2 and not out.exists(), line


def test_a_results_file_with_a_record_twice(tmp_path, capsys, count_checks):
    results = lfbench.results.Results(records=[lfbench.results.Record("m", "s", "badpix_0.07", 1.0, "lowres")] * 2)
    results.write(tmp_path / "res")
    rc, _, err = run_cli(capsys, "report", tmp_path / "res", "--out", tmp_path / "rep")
    assert_one_error_line(rc, err, "record m/s/badpix_0.07 appears twice", str(tmp_path / "res" / "results.json"))
    assert len(count_checks) == 1 and not (tmp_path / "rep").exists()


def test_ablate_report_checks_once(request, count_checks):
    """`lfbench ablate --report-only --html`: the results file's one check; the site trusts it."""
    from lfbench.cli import main

    path, out, _ = request.getfixturevalue("ablation")
    count_checks.clear()
    assert main(["ablate", str(path), "--out", str(out), "--report-only", "--html", "--no-maps"]) == 0
    assert len(count_checks) == 1  # before: the results file's and the site's
    assert (out / "html" / "index.html").is_file()


def test_the_site_draws_the_series_the_figure_writer_computed(data, tmp_path, capsys, monkeypatch):
    """`evaluate --figures --html`: each BadPix series is computed once (by the figure writer) and the site
    draws that one; the site's series images are those of a run whose site computes them itself."""
    from lfbench.reports import figures

    computed: list[tuple[str, str]] = []
    real = figures.scene_curve

    def counted(label, scene, *args, **kwargs):
        computed.append((label, scene.name))
        return real(label, scene, *args, **kwargs)

    monkeypatch.setattr(figures, "scene_curve", counted)
    common = ["evaluate", "--data", data, "--method", "constant:value=0.05", "--method", "constant:value=-0.02",
              "--method", "gt", "--html", "--no-progress"]
    rc, _, err = run_cli(capsys, *common, "--figures", "--out", tmp_path / "both")
    assert rc == 0, err
    pairs = [(m, s) for s in ("alpha", "beta") for m in ("constant:value=0.05", "constant:value=-0.02", "gt")]
    assert sorted(computed) == sorted(pairs)  # once each (the oracle's too: the figures draw it); before: twice
    computed.clear()
    rc, _, err = run_cli(capsys, *common, "--out", tmp_path / "site_only")
    assert rc == 0, err
    assert len(computed) == 4  # the site alone: the two ranked methods on the two scenes
    for image in ("img/badpix_series.png", "img/alpha/badpix_series.png", "img/beta/badpix_series.png"):
        both, alone = tmp_path / "both" / "html" / image, tmp_path / "site_only" / "html" / image
        assert both.read_bytes() == alone.read_bytes(), image


def test_one_writer_driver():
    """evaluate (lfbench.runs.folder), report (lfbench.reports.from_results) and ablate (lfbench.ablation.report)
    drive their writers through lfbench.reports.writers.drive_writers: no other module starts writers, hands
    them predictions or calls their write steps."""
    root = Path(lfbench.results.__file__).parent
    loops = re.compile(r"\.(start|on_prediction|write)\(run\b|writer\.on_prediction\(")
    drivers = sorted(str(p.relative_to(root)) for p in root.rglob("*.py")
                     if loops.search(p.read_text(encoding="utf-8")))
    assert drivers == ["reports/writers.py"]
    for module in ("runs/folder.py", "reports/from_results.py", "ablation/report.py"):
        assert "drive_writers(" in (root / module).read_text(encoding="utf-8"), module
