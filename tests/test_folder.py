"""lfbench.runs.folder.evaluate_to_folder: the one orchestration behind evaluate, demo, golden.py and the ablation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import write_scene, write_submission

from lfbench.data.hci import HCIDataset
from lfbench.method.registry import create
from lfbench.reports.tables import TABLE_FORMATS, render, render_with_caption, write_table
from lfbench.reports.writers import BootstrapCIs, SceneFigures, Tables
from lfbench.results import Results
from lfbench.runs.folder import CIOptions, evaluate_to_folder

SIZE = 40  # 10 x 10 scored pixels inside the 15 px border


@pytest.fixture()
def scenes(tmp_path):
    gt = np.zeros((SIZE, SIZE), np.float32)
    for name in ("alpha", "beta"):
        write_scene(tmp_path / "data", name, gt=gt)
    return list(HCIDataset.open(tmp_path / "data"))


def test_results_tables_and_meta(scenes, tmp_path):
    out = tmp_path / "out"
    results = evaluate_to_folder([create("gt")], scenes, out, meta={"data_root": "somewhere"}, progress=False)
    assert {p.name for p in results.files} == {"results.json", "results.csv"} | {
        f"table_{t}.{ext}" for t in ("per_scene", "average") for _, ext in TABLE_FORMATS}
    assert all(p.is_file() for p in results.files)
    data = json.loads((out / "results.json").read_text())
    assert data["meta"]["data_root"] == "somewhere" and data["meta"]["scoring"]["border_px"] == 15
    assert {(r["method"], r["scene"]) for r in data["records"]} == {("gt", "alpha"), ("gt", "beta")}
    assert all(r["value"] == 0.0 for r in data["records"])
    assert Results.read(out).records == results.records


def test_label_more_groups_and_no_tables(scenes, tmp_path):
    sub = write_submission(tmp_path / "sub", {"beta": np.full((SIZE, SIZE), 0.1, np.float32)})
    out = tmp_path / "out"
    results = evaluate_to_folder([create("gt")], scenes[:1], out, more=[([create("published", path=sub)], scenes)],
                                 writers=[], progress=False)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["results.csv", "results.json"]
    assert {(r.method, r.scene) for r in results.records} == {("gt", "alpha"), ("published:sub", "beta")}
    assert results.value("published:sub", "beta", "badpix_0.07") == 100.0  # |0.1| > 0.07 on every pixel
    named = evaluate_to_folder([create("gt")], scenes, tmp_path / "cell", label="cell-1", writers=[],
                               progress=False)
    assert set(named.methods) == {"cell-1"} and {r.method for r in named.runs} == {"cell-1"}
    with pytest.raises(ValueError, match="single method"):
        evaluate_to_folder([create("gt"), create("gt")], scenes, tmp_path / "x", label="two", progress=False)


def test_figures_replace_an_earlier_run_and_ci_files(scenes, tmp_path):
    out = tmp_path / "out"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "stale.png").write_bytes(b"old run")
    results = evaluate_to_folder([create("gt")], scenes, out, progress=False,
                                 writers=[SceneFigures(), Tables(), BootstrapCIs(CIOptions(resamples=50, block=4))])
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert "stale.png" not in figures and "overview_alpha.png" in figures
    assert not [p for p in out.iterdir() if p.name.startswith(".figures.")]  # no temporary folder left
    ci = (out / "ci.csv").read_text().splitlines()
    assert ci[0] == "method,scene,metric,value,low,high,n_pixels,resolution"
    assert (out / "table_ci_per_scene.md").is_file() and out / "ci.csv" in results.files


def test_one_table_writer_with_captions(tmp_path):
    import pandas as pd

    table = pd.DataFrame({"method": ["a"], "badpix_0.07": [1.23456]}).set_index("method")
    paths = write_table(table, tmp_path, "t", ["line one", "line two"])
    assert [p.name for p in paths] == ["t.md", "t.tex", "t.csv"]
    md = (tmp_path / "t.md").read_text()
    assert md.startswith("line one  \nline two  \n\n") and "| BadPix(0.07)   |" in md and "1.235" in md
    assert (tmp_path / "t.tex").read_text().startswith("% line one\n% line two\n")
    assert (tmp_path / "t.csv").read_text() == render(table, "csv") == "method,badpix_0.07\na,1.23456\n"
    assert render_with_caption(table, "markdown") == render(table, "markdown")
    assert [p.name for p in write_table(table, tmp_path, "only", formats=[("csv", "csv")])] == ["only.csv"]
