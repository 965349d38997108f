"""`lfbench report` and the paper's numbers: tables regenerated from results equal evaluate's, paper
columns carry the published values, and bad input fails with one line."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lfbench.cli import main
from lfbench.errors import DataError, SpecError
from lfbench.report.paper import (
    average_with_paper,
    bundled_dir,
    load_paper,
    paper_column,
    per_scene_with_paper,
)
from lfbench.report.tables import average_table, per_scene_table
from lfbench.results import Record, Results

TABLE_FILES = [f"table_{n}.{e}" for n in ("per_scene", "average") for e in ("md", "tex", "csv")]


# --------------------------------------------------------------------------- paper data

def test_bundled_paper_tables_hold_the_published_numbers():
    paper = load_paper("bundled")
    assert paper.value("SubFocal", "backgammon", "badpix_0.07") == 3.194
    assert paper.value("SubFocal", "backgammon", "mse_x100") == 3.667
    assert paper.average_value("SubFocal", "badpix_0.07") == 2.956
    assert paper.average_value("SubFocal-L", "mse_x100") == 1.581
    assert len(paper.scenes) == 12 and "SubFocal" in paper.methods
    assert set(paper.extra) >= {"table4_interval_interp", "table5_losses"}
    t5 = paper.extra["table5_losses"].set_index("loss")["badpix_0.07"]
    assert t5["uafl"] == 1.93 and t5["baseline_l1"] == 2.04
    # Table II is the mean of Table I over the 12 scenes, up to the paper's rounding
    t1 = paper.per_scene.groupby(["method", "metric"])["value"].mean()
    t2 = paper.average.set_index(["method", "metric"])["value"]
    assert np.abs((t1.reindex(t2.index) - t2).to_numpy()).max() < 0.035


def test_bundled_copy_equals_the_shared_paper_tables(shared_data):
    src = shared_data / "paper"
    if not src.is_dir():
        pytest.skip(f"{src} not available")
    for p in sorted(bundled_dir().glob("*.csv")):
        assert p.read_bytes() == (src / p.name).read_bytes(), p.name


def _results() -> Results:
    r = Results()
    for method, offset in (("gt", 0.0), ("mine", 1.0)):
        for scene in ("backgammon", "boxes"):
            for metric, value in (("badpix_0.07", 2.0), ("mse_x100", 1.5), ("q25_x100", 0.5)):
                r.records.append(Record(method, scene, metric, value * offset, "lowres"))
    return r


def test_per_scene_table_gets_labelled_paper_columns():
    paper = load_paper()
    table = per_scene_with_paper(per_scene_table(_results()), paper, ["subfocal", "OACC-Net"])
    assert paper_column("SubFocal") == "SubFocal (paper)"
    assert table.loc[("backgammon", "badpix_0.07"), "SubFocal (paper)"] == 3.194
    assert table.loc[("boxes", "mse_x100"), "SubFocal (paper)"] == paper.value("SubFocal", "boxes", "mse_x100")
    assert table.loc[("boxes", "badpix_0.07"), "OACC-Net (paper)"] == paper.value("OACC-Net", "boxes", "badpix_0.07")
    assert np.isnan(table.loc[("boxes", "q25_x100"), "SubFocal (paper)"])  # the paper has no Q25
    assert table.loc[("backgammon", "badpix_0.07"), "paper resolution"] == "highres"
    assert table.loc[("boxes", "badpix_0.07"), "paper resolution"] == "lowres"
    assert table.loc[("backgammon", "badpix_0.07"), "mine"] == 2.0  # ours untouched


def test_average_table_gets_table2_and_same_scene_rows():
    paper = load_paper()
    results = _results()
    table = average_with_paper(average_table(results), paper, results.scenes)
    assert table.loc["SubFocal (paper, Table II, 12 scenes)", "badpix_0.07"] == 2.956
    same = table.loc["SubFocal (paper, 2 of our scenes)"]
    expected = (paper.value("SubFocal", "backgammon", "badpix_0.07")
                + paper.value("SubFocal", "boxes", "badpix_0.07")) / 2
    assert same["badpix_0.07"] == pytest.approx(expected)
    assert same["scenes"] == 2
    assert table.loc["mine", "badpix_0.07"] == 2.0
    # only the scenes the paper reports are averaged; none of them: no such row
    mixed = Results(records=[Record("m", s, "badpix_0.07", 1.0, "lowres") for s in ("synth_0_0", "dots")])
    table = average_with_paper(average_table(mixed), paper, mixed.scenes)
    dots = paper.value("SubFocal", "dots", "badpix_0.07")
    assert table.loc["SubFocal (paper, 1 of our scenes)", "badpix_0.07"] == dots
    other = Results(records=[Record("m", "synth_0_0", "badpix_0.07", 1.0, "lowres")])
    rows = average_with_paper(average_table(other), paper, other.scenes).index
    assert not any("of our scenes" in r for r in rows)


def test_bad_paper_input_fails_clearly(tmp_path):
    with pytest.raises(DataError, match="paper folder not found"):
        load_paper(tmp_path / "nope")
    shutil.copytree(bundled_dir(), tmp_path / "p")
    (tmp_path / "p" / "table2_average.csv").write_text("method,metric,value\nSubFocal,badpix_0.07,abc\n")
    with pytest.raises(DataError, match=r"table2_average.csv.*line 2.*not a number"):
        load_paper(tmp_path / "p")
    (tmp_path / "p" / "table2_average.csv").write_text("method,value\nSubFocal,1\n")
    with pytest.raises(DataError, match="missing column"):
        load_paper(tmp_path / "p")
    with pytest.raises(SpecError, match="no method 'Nope'"):
        load_paper().resolve_method("Nope")


# --------------------------------------------------------------------------- report CLI

@pytest.fixture(scope="module")
def evaluated(tmp_path_factory) -> Path:
    """A synthetic data root, a 'published' submission of perturbed maps, and an evaluate run of it."""
    from lfbench.scene import Benchmark
    from lfbench.submission import write_submission_map
    from lfbench.synth import write_benchmark

    base = tmp_path_factory.mktemp("report")
    write_benchmark(base / "data", seed=3, size=48, scenes=2)
    rng = np.random.default_rng(0)
    for scene in Benchmark.discover(base / "data"):
        gt = scene.gt_disparity()
        write_submission_map(base / "sub", scene.name, gt + rng.normal(0, 0.05, gt.shape).astype(np.float32), 1.5)
    rc = main(["evaluate", "--data", str(base / "data"), "--method", "gt", "--method", f"published:path={base / 'sub'}",
               "--out", str(base / "eval"), "--figures", "--save-maps", "--no-progress"])
    assert rc == 0
    return base


def test_report_regenerates_the_evaluate_tables(evaluated, tmp_path, capsys):
    capsys.readouterr()
    assert main(["report", str(evaluated / "eval" / "results.json"), "--out", str(tmp_path / "r")]) == 0
    for name in TABLE_FILES:
        assert (tmp_path / "r" / name).read_text() == (evaluated / "eval" / name).read_text(), name
    out = capsys.readouterr().out
    assert "published:sub" in out and "badpix_series.csv" in out
    curves = tmp_path / "r" / "figures"
    assert (curves / "badpix_series.png").stat().st_size > 5000
    assert sorted(p.name for p in curves.iterdir() if p.is_dir()) == ["synth_3_0", "synth_3_1"]


def test_report_with_paper_columns_and_formats(evaluated, tmp_path):
    rc = main(["report", str(evaluated / "eval"), "--out", str(tmp_path / "r"), "--paper", "bundled",
               "--paper-methods", "SubFocal,SubFocal-L", "--format", "csv"])
    assert rc == 0
    assert sorted(p.name for p in (tmp_path / "r").glob("table_*")) == [
        "table_average.csv", "table_average_paper.csv", "table_per_scene.csv", "table_per_scene_paper.csv"]
    avg = pd.read_csv(tmp_path / "r" / "table_average_paper.csv").set_index("method")
    assert avg.loc["SubFocal (paper, Table II, 12 scenes)", "badpix_0.07"] == 2.956
    assert avg.loc["SubFocal-L (paper, Table II, 12 scenes)", "badpix_0.07"] == 2.735
    assert avg.loc["gt", "badpix_0.07"] == 0.0
    per = pd.read_csv(tmp_path / "r" / "table_per_scene_paper.csv")
    assert {"SubFocal (paper)", "SubFocal-L (paper)", "paper resolution"} <= set(per.columns)


def test_report_without_saved_curves_uses_the_results_thresholds(evaluated, tmp_path, capsys):
    (tmp_path / "only").mkdir()
    shutil.copy(evaluated / "eval" / "results.json", tmp_path / "only" / "results.json")
    assert main(["report", str(tmp_path / "only"), "--out", str(tmp_path / "r")]) == 0
    assert "thresholds in the results" in capsys.readouterr().out
    assert (tmp_path / "r" / "figures" / "badpix_series.png").is_file()


def test_report_draws_overviews_from_saved_maps(evaluated, tmp_path):
    rc = main(["report", str(evaluated / "eval"), "--out", str(tmp_path / "r"),
               "--maps", str(evaluated / "eval" / "maps"), "--format", "md"])
    assert rc == 0
    figs = tmp_path / "r" / "figures"
    assert (figs / "overview_synth_3_0.png").is_file()
    # the curves drawn from the saved maps reproduce the evaluate run's curves
    from lfbench.report.figures import read_curves_csv

    ours = {(c.method, c.scene): c.values for c in read_curves_csv(figs / "badpix_series.csv")}
    saved = evaluated / "eval" / "figures" / "badpix_series.csv"
    theirs = {(c.method, c.scene): c.values for c in read_curves_csv(saved)}
    assert ours.keys() == theirs.keys() and len(ours) == 4
    for key in ours:
        np.testing.assert_allclose(ours[key], theirs[key])
    results = json.loads((evaluated / "eval" / "results.json").read_text())
    bp = {(r["method"], r["scene"]): r["value"] for r in results["records"] if r["metric"] == "badpix_0.07"}
    for key, values in ours.items():
        assert values[70] == pytest.approx(bp[key])


@pytest.mark.parametrize("argv, message", [
    (["report", "MISSING", "--out", "OUT"], "results file not found"),
    (["report", "RESULTS", "--out", "OUT", "--format", "docx"], "unknown table format"),
    (["report", "RESULTS", "--out", "OUT", "--paper", "bundled", "--paper-methods", "Nope"], "no method 'Nope'"),
    (["report", "RESULTS", "--out", "OUT", "--paper", "NOPAPER"], "paper folder not found"),
])
def test_report_bad_input_is_one_line_exit_2(evaluated, tmp_path, capsys, argv, message):
    subst = {"MISSING": str(tmp_path / "missing.json"), "OUT": str(tmp_path / "out"),
             "RESULTS": str(evaluated / "eval"), "NOPAPER": str(tmp_path / "nopaper")}
    capsys.readouterr()
    assert main([subst.get(a, a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
