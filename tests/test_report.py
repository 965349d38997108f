"""`lfbench report` and the paper's numbers: tables regenerated from results equal evaluate's, paper
columns carry the numbers of the paper folder the user names (lfbench ships no copy), and bad input
fails with one line."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import require

from lfbench.cli import main
from lfbench.reports.paper import (
    HCI_ROOT_ENV,
    PAPER_DIR_ENV,
    average_with_paper,
    find_paper_dir,
    load_paper,
    paper_column,
    per_scene_with_paper,
)
from lfbench.reports.tables import average_table, per_scene_table
from lfbench.results import Record, Results
from lfbench.utils.errors import DataError, SpecError

ROOT = Path(__file__).resolve().parent.parent
TABLE_FILES = [f"table_{n}.{e}" for n in ("per_scene", "average") for e in ("md", "tex", "csv")]
NOT_FOUND = ("the paper's tables were not found: pass --paper DIR (e.g. ../shared/data/paper) "
             "or set LFBENCH_PAPER_DIR")

# A tiny paper folder with made-up numbers (same layout and columns as the paper's tables): 3 methods,
# 4 scenes, Table II averages, and one of the other tables. The tests look these literals up.
TINY_TABLE1 = """method,scene,metric,value
SubFocal,backgammon,badpix_0.07,3.194
SubFocal,backgammon,mse_x100,3.667
SubFocal,boxes,badpix_0.07,8.5
SubFocal,boxes,mse_x100,2.25
SubFocal,dots,badpix_0.07,0.75
SubFocal,dots,mse_x100,1.5
SubFocal,cotton,badpix_0.07,0.25
SubFocal,cotton,mse_x100,0.125
SubFocal-L,backgammon,badpix_0.07,2.5
SubFocal-L,boxes,badpix_0.07,7.0
OACC-Net,backgammon,badpix_0.07,3.9
OACC-Net,boxes,badpix_0.07,10.25
"""
TINY_TABLE2 = """method,metric,value
SubFocal,badpix_0.07,2.956
SubFocal,mse_x100,1.875
SubFocal-L,badpix_0.07,2.735
OACC-Net,badpix_0.07,3.5
"""
TINY_TABLE5 = "loss,badpix_0.07\nbaseline_l1,2.04\nuafl,1.93\n"


def write_paper(folder: Path) -> Path:
    """Write the tiny made-up paper tables into ``folder``; returns it."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "table1_per_scene.csv").write_text(TINY_TABLE1)
    (folder / "table2_average.csv").write_text(TINY_TABLE2)
    (folder / "table5_losses.csv").write_text(TINY_TABLE5)
    return folder


@pytest.fixture
def paper(tmp_path):
    return load_paper(write_paper(tmp_path / "paper"))


# --------------------------------------------------------------------------- paper data

def test_paper_tables_are_read_from_the_folder(tmp_path):
    paper = load_paper(write_paper(tmp_path / "paper"))
    assert paper.source == tmp_path / "paper"
    assert paper.value("SubFocal", "backgammon", "badpix_0.07") == 3.194
    assert paper.value("SubFocal", "boxes", "mse_x100") == 2.25
    assert np.isnan(paper.value("SubFocal", "boxes", "q25_x100"))
    assert paper.average_value("SubFocal", "badpix_0.07") == 2.956
    assert paper.average_value("SubFocal-L", "badpix_0.07") == 2.735
    assert np.isnan(paper.average_value("SubFocal-L", "mse_x100"))
    assert paper.methods == ["SubFocal", "SubFocal-L", "OACC-Net"]
    assert paper.scenes == ["backgammon", "boxes", "dots", "cotton"]
    assert set(paper.extra) == {"table5_losses"}
    t5 = paper.extra["table5_losses"].set_index("loss")["badpix_0.07"]
    assert t5["uafl"] == 1.93 and t5["baseline_l1"] == 2.04


def test_shared_paper_tables_hold_the_published_numbers(shared_data):
    paper = load_paper(require(shared_data / "paper"))
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


def test_no_copy_of_the_paper_tables_ships_with_lfbench():
    import tomllib

    shipped = [p for top in ("lfbench", "methods") for p in (ROOT / top).rglob("table*.csv")]
    assert shipped == []
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    # the HTML report's templates and new-plugin's skeleton
    assert package_data["lfbench"] == ["py.typed", "reports/site_assets/*", "method/plugin_skeleton/*.tmpl",
                                       "method/plugin_skeleton/package/*.tmpl"]
    assert not [p for p in (ROOT / "lfbench" / "reports" / "site_assets").iterdir() if p.suffix == ".csv"]


def test_find_paper_dir_order_and_error(tmp_path, monkeypatch):
    beside = write_paper(tmp_path / "data" / "paper")
    (tmp_path / "data" / "hci").mkdir()
    monkeypatch.setenv(PAPER_DIR_ENV, str(tmp_path / "env_paper"))
    monkeypatch.setenv(HCI_ROOT_ENV, str(tmp_path / "data" / "hci"))
    # 1. the explicit folder, as given (even when missing: load_paper then names it)
    assert find_paper_dir(tmp_path / "explicit") == tmp_path / "explicit"
    assert find_paper_dir(str(tmp_path / "explicit")) == tmp_path / "explicit"
    # 2. LFBENCH_PAPER_DIR ("" / None: not given, e.g. a bare --paper)
    assert find_paper_dir(None) == tmp_path / "env_paper"
    assert find_paper_dir("") == tmp_path / "env_paper"
    with pytest.raises(DataError, match="paper folder not found"):
        load_paper(find_paper_dir(None))
    # 3. $LFBENCH_HCI_ROOT/../paper when it exists
    monkeypatch.setenv(PAPER_DIR_ENV, "")
    assert find_paper_dir(None) == beside.resolve()
    assert load_paper(find_paper_dir(None)).value("SubFocal", "backgammon", "badpix_0.07") == 3.194
    monkeypatch.delenv(PAPER_DIR_ENV)
    assert find_paper_dir(None) == beside.resolve()
    # 4. nothing: one line naming both ways to give the folder
    (tmp_path / "elsewhere" / "hci").mkdir(parents=True)
    monkeypatch.setenv(HCI_ROOT_ENV, str(tmp_path / "elsewhere" / "hci"))
    with pytest.raises(DataError) as exc:
        find_paper_dir(None)
    assert str(exc.value) == NOT_FOUND
    monkeypatch.delenv(HCI_ROOT_ENV)
    with pytest.raises(DataError) as exc:
        find_paper_dir()
    assert str(exc.value) == NOT_FOUND


def _results() -> Results:
    r = Results()
    for method, offset in (("gt", 0.0), ("mine", 1.0)):
        for scene in ("backgammon", "boxes"):
            for metric, value in (("badpix_0.07", 2.0), ("mse_x100", 1.5), ("q25_x100", 0.5)):
                r.records.append(Record(method, scene, metric, value * offset, "lowres"))
    return r


def test_per_scene_table_gets_labelled_paper_columns(paper):
    table = per_scene_with_paper(per_scene_table(_results()), paper, ["subfocal", "OACC-Net"])
    assert paper_column("SubFocal") == "SubFocal (paper)"
    assert table.loc[("backgammon", "badpix_0.07"), "SubFocal (paper)"] == 3.194
    assert table.loc[("boxes", "mse_x100"), "SubFocal (paper)"] == 2.25
    assert table.loc[("boxes", "badpix_0.07"), "OACC-Net (paper)"] == 10.25
    assert np.isnan(table.loc[("boxes", "mse_x100"), "OACC-Net (paper)"])  # not in the paper's table
    assert np.isnan(table.loc[("boxes", "q25_x100"), "SubFocal (paper)"])  # the paper has no Q25
    assert table.loc[("backgammon", "badpix_0.07"), "paper resolution"] == "highres"
    assert table.loc[("boxes", "badpix_0.07"), "paper resolution"] == "lowres"
    assert table.loc[("backgammon", "badpix_0.07"), "mine"] == 2.0  # ours untouched


def test_average_table_gets_table2_and_same_scene_rows(paper):
    results = _results()
    table = average_with_paper(average_table(results), paper, results.scenes)
    # Table II row: the published averages, labelled with the number of scenes in the paper's Table I
    assert table.loc["SubFocal (paper, Table II, 4 scenes)", "badpix_0.07"] == 2.956
    assert table.loc["SubFocal (paper, Table II, 4 scenes)", "mse_x100"] == 1.875
    assert table.loc["SubFocal (paper, Table II, 4 scenes)", "scenes"] == 4
    same = table.loc["SubFocal (paper, 2 of our scenes)"]
    assert same["badpix_0.07"] == pytest.approx((3.194 + 8.5) / 2)  # backgammon and boxes
    assert same["mse_x100"] == pytest.approx((3.667 + 2.25) / 2)
    assert same["scenes"] == 2
    assert table.loc["mine", "badpix_0.07"] == 2.0
    # only the scenes the paper reports are averaged; none of them: no such row
    mixed = Results(records=[Record("m", s, "badpix_0.07", 1.0, "lowres") for s in ("synth_0_0", "dots")])
    table = average_with_paper(average_table(mixed), paper, mixed.scenes)
    assert table.loc["SubFocal (paper, 1 of our scenes)", "badpix_0.07"] == 0.75  # dots
    other = Results(records=[Record("m", "synth_0_0", "badpix_0.07", 1.0, "lowres")])
    rows = average_with_paper(average_table(other), paper, other.scenes).index
    assert not any("of our scenes" in r for r in rows)


def test_bad_paper_input_fails_clearly(tmp_path):
    with pytest.raises(DataError, match="paper folder not found"):
        load_paper(tmp_path / "nope")
    write_paper(tmp_path / "p")
    (tmp_path / "p" / "table1_per_scene.csv").unlink()
    with pytest.raises(DataError, match=r"table1_per_scene.csv.*paper table not found"):
        load_paper(tmp_path / "p")
    write_paper(tmp_path / "p")
    (tmp_path / "p" / "table2_average.csv").write_text("method,metric,value\nSubFocal,badpix_0.07,abc\n")
    with pytest.raises(DataError, match=r"table2_average.csv.*line 2.*not a number"):
        load_paper(tmp_path / "p")
    (tmp_path / "p" / "table2_average.csv").write_text("method,value\nSubFocal,1\n")
    with pytest.raises(DataError, match="missing column"):
        load_paper(tmp_path / "p")
    with pytest.raises(SpecError, match="no method 'Nope'; it has: SubFocal, SubFocal-L, OACC-Net"):
        load_paper(write_paper(tmp_path / "q")).resolve_method("Nope")


# --------------------------------------------------------------------------- report CLI

@pytest.fixture(scope="module")
def evaluated(tmp_path_factory) -> Path:
    """A synthetic data root, a 'published' submission of perturbed maps, and an evaluate run of it."""
    from lfbench.data.hci import HCIDataset
    from lfbench.data.submission import write_submission_map
    from lfbench.data.synth import write_benchmark

    base = tmp_path_factory.mktemp("report")
    write_benchmark(base / "data", seed=3, size=48, scenes=2)
    rng = np.random.default_rng(0)
    for scene in HCIDataset.open(base / "data"):
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
    # the maps the run saved are drawn without --maps (issue 38): overviews, and the exact curves of the run
    assert "published:sub" in out and f"saved maps in {evaluated / 'eval' / 'maps'}" in out
    curves = tmp_path / "r" / "figures"
    assert (curves / "badpix_series.png").stat().st_size > 5000
    assert sorted(p.name for p in curves.iterdir() if p.is_dir()) == ["synth_3_0", "synth_3_1", "toolkit"]
    assert (curves / "overview_synth_3_0.png").is_file()
    saved = evaluated / "eval" / "figures" / "badpix_series.csv"
    assert (curves / "badpix_series.csv").read_text() == saved.read_text()


def test_report_without_the_scenes_takes_the_saved_curves(evaluated, tmp_path, capsys):
    """Saved maps whose data root is not at hand (results copied elsewhere) are not drawn: the saved curves are."""
    copy = tmp_path / "copy"
    shutil.copytree(evaluated / "eval", copy)
    data = json.loads((copy / "results.json").read_text())
    data["meta"]["data_root"] = str(tmp_path / "gone")
    (copy / "results.json").write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["report", str(copy), "--out", str(tmp_path / "r")]) == 0
    assert f"BadPix series from {copy / 'figures' / 'badpix_series.csv'}" in capsys.readouterr().out
    assert not (tmp_path / "r" / "figures" / "overview_synth_3_0.png").exists()


def test_report_with_paper_columns_and_formats(evaluated, tmp_path):
    paper_dir = write_paper(tmp_path / "paper")
    rc = main(["report", str(evaluated / "eval"), "--out", str(tmp_path / "r"), "--paper", str(paper_dir),
               "--paper-methods", "SubFocal,SubFocal-L", "--format", "csv"])
    assert rc == 0
    assert sorted(p.name for p in (tmp_path / "r").glob("table_*")) == [
        "table_average.csv", "table_average_paper.csv", "table_per_scene.csv", "table_per_scene_paper.csv"]
    avg = pd.read_csv(tmp_path / "r" / "table_average_paper.csv").set_index("method")
    assert avg.loc["SubFocal (paper, Table II, 4 scenes)", "badpix_0.07"] == 2.956
    assert avg.loc["SubFocal-L (paper, Table II, 4 scenes)", "badpix_0.07"] == 2.735
    assert avg.loc["gt", "badpix_0.07"] == 0.0
    per = pd.read_csv(tmp_path / "r" / "table_per_scene_paper.csv")
    assert {"SubFocal (paper)", "SubFocal-L (paper)", "paper resolution"} <= set(per.columns)
    assert set(per["paper resolution"]) == {"-"}  # the synthetic scenes are not in the paper


def test_report_bare_paper_uses_lfbench_paper_dir(evaluated, tmp_path, monkeypatch):
    monkeypatch.setenv(PAPER_DIR_ENV, str(write_paper(tmp_path / "paper")))
    rc = main(["report", str(evaluated / "eval"), "--out", str(tmp_path / "r"), "--format", "csv", "--paper"])
    assert rc == 0
    avg = pd.read_csv(tmp_path / "r" / "table_average_paper.csv").set_index("method")
    assert avg.loc["SubFocal (paper, Table II, 4 scenes)", "mse_x100"] == 1.875


def test_report_bare_paper_finds_the_shared_tables(evaluated, shared_data, tmp_path, monkeypatch):
    require(shared_data / "paper")
    monkeypatch.delenv(PAPER_DIR_ENV, raising=False)
    monkeypatch.setenv(HCI_ROOT_ENV, str(shared_data / "hci"))
    rc = main(["report", str(evaluated / "eval"), "--out", str(tmp_path / "r"), "--format", "csv",
               "--paper", "--paper-methods", "SubFocal,SubFocal-L"])
    assert rc == 0
    avg = pd.read_csv(tmp_path / "r" / "table_average_paper.csv").set_index("method")
    assert avg.loc["SubFocal (paper, Table II, 12 scenes)", "badpix_0.07"] == 2.956
    assert avg.loc["SubFocal-L (paper, Table II, 12 scenes)", "badpix_0.07"] == 2.735


def test_report_without_saved_curves_uses_the_results_thresholds(evaluated, tmp_path, capsys):
    (tmp_path / "only").mkdir()
    shutil.copy(evaluated / "eval" / "results.json", tmp_path / "only" / "results.json")
    assert main(["report", str(tmp_path / "only"), "--out", str(tmp_path / "r")]) == 0
    assert "thresholds in the results" in capsys.readouterr().out
    assert (tmp_path / "r" / "figures" / "badpix_series.png").is_file()


def test_report_with_maps_and_html_reads_every_input_once(evaluated, tmp_path, monkeypatch):
    # Tables, figures, the toolkit's figures and the site share one reading of results.json, one discovery
    # of the scenes and one load of every saved map; the site ranks each metric once for all its tables.
    from collections import Counter

    from lfbench.data.hci import dataset as hci_dataset
    from lfbench.reports import leaderboard
    from lfbench.reports import maps as saved_maps

    counts: Counter = Counter()

    def counted(key, fn):
        def call(*args, **kwargs):
            counts[key(*args)] += 1
            return fn(*args, **kwargs)
        return call

    monkeypatch.setattr(Results, "read", counted(lambda path: "results.json", Results.read))
    monkeypatch.setattr(hci_dataset, "discover", counted(lambda root: "discover", hci_dataset.discover))
    monkeypatch.setattr(saved_maps, "read_submission_map", counted(lambda root, scene: (Path(root).name, scene),
                                                                   saved_maps.read_submission_map))
    monkeypatch.setattr(leaderboard, "metric_ranks", counted(lambda results, metric: metric, leaderboard.metric_ranks))
    assert main(["report", str(evaluated / "eval"), "--out", str(tmp_path / "r"), "--maps",
                 str(evaluated / "eval" / "maps"), "--html", "--format", "md"]) == 0
    assert (tmp_path / "r" / "html" / "scene-synth_3_0.html").is_file()
    maps = {k: n for k, n in counts.items() if isinstance(k, tuple)}
    assert len(maps) == 4 and set(maps.values()) == {1}, maps  # 2 methods x 2 scenes, each read once
    assert counts["results.json"] == 1 and counts["discover"] == 1
    ranked = {k: n for k, n in counts.items() if isinstance(k, str) and k not in ("results.json", "discover")}
    assert len(ranked) == 5 and set(ranked.values()) == {1}, ranked  # the five general metrics


def test_report_draws_overviews_from_saved_maps(evaluated, tmp_path):
    rc = main(["report", str(evaluated / "eval"), "--out", str(tmp_path / "r"),
               "--maps", str(evaluated / "eval" / "maps"), "--format", "md"])
    assert rc == 0
    figs = tmp_path / "r" / "figures"
    assert (figs / "overview_synth_3_0.png").is_file()
    # the curves drawn from the saved maps reproduce the evaluate run's curves
    from lfbench.reports.figures import read_curves_csv

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


def test_report_curves_from_saved_maps_use_the_recorded_scoring_rules(evaluated, tmp_path):
    # results scored with a 5 px border: the redrawn curves must use 5 px too, not the default 15
    from lfbench.data.hci import HCIDataset
    from lfbench.data.pfm import read_pfm
    from lfbench.data.submission import disp_map_path
    from lfbench.reports.figures import read_curves_csv

    results = json.loads((evaluated / "eval" / "results.json").read_text())
    results["meta"]["scoring"]["border_px"] = 5
    (tmp_path / "eval").mkdir()
    (tmp_path / "eval" / "results.json").write_text(json.dumps(results))
    assert main(["report", str(tmp_path / "eval"), "--out", str(tmp_path / "r"), "--maps",
                 str(evaluated / "eval" / "maps"), "--data", str(evaluated / "data"), "--format", "md"]) == 0
    curves = {(c.method, c.scene): c.values for c in read_curves_csv(tmp_path / "r" / "figures" / "badpix_series.csv")}
    for scene in HCIDataset.open(evaluated / "data"):
        err = np.abs(read_pfm(disp_map_path(evaluated / "sub", scene.name)) - scene.gt_disparity())[5:-5, 5:-5]
        by_hand = 100 * np.mean(err > 0.07)
        assert by_hand != pytest.approx(100 * np.mean(err[10:-10, 10:-10] > 0.07))  # the border matters here
        assert curves[("published:sub", scene.name)][70] == pytest.approx(by_hand)


@pytest.mark.parametrize("argv, message", [
    (["report", "MISSING", "--out", "OUT"], "results file not found"),
    (["report", "RESULTS", "--out", "OUT", "--format", "docx"], "unknown table format"),
    (["report", "RESULTS", "--out", "OUT", "--paper", "PAPER", "--paper-methods", "Nope"], "no method 'Nope'"),
    (["report", "RESULTS", "--out", "OUT", "--paper", "NOPAPER"], "paper folder not found"),
    (["report", "RESULTS", "--out", "OUT", "--paper"], NOT_FOUND),
])
def test_report_bad_input_is_one_line_exit_2(evaluated, tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.delenv(PAPER_DIR_ENV, raising=False)
    monkeypatch.delenv(HCI_ROOT_ENV, raising=False)
    subst = {"MISSING": str(tmp_path / "missing.json"), "OUT": str(tmp_path / "out"),
             "RESULTS": str(evaluated / "eval"), "NOPAPER": str(tmp_path / "nopaper"),
             "PAPER": str(write_paper(tmp_path / "paper"))}
    capsys.readouterr()
    assert main([subst.get(a, a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
