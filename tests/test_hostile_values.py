"""Values that gave tracebacks or invalid files (issue 20, class 7): non-numeric ci.csv bounds read back
by the HTML report, a validation border that crops every pixel (NaN validation), and NaN literals in the
JSON files lfbench writes (every one is strict JSON: a NaN is null)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import assert_one_error_line, run_cli, write_scene

from lfbench.utils.jsonfile import json_text, read_json

SIZE = 24


def test_json_text_writes_non_finite_numbers_as_null():
    value = {"a": math.nan, "b": [math.inf, 1.5, {"c": -math.inf}], "d": (2, math.nan), "e": "NaN", "f": None}
    text = json_text(value, sort_keys=True)
    assert text == '{"a": null, "b": [null, 1.5, {"c": null}], "d": [2, null], "e": "NaN", "f": null}'
    assert json.loads(text, parse_constant=lambda name: pytest.fail(f"{name} literal"))


# --------------------------------------------------------------------------- ci.csv read back

@pytest.fixture(scope="module")
def ci_run(tmp_path_factory) -> Path:
    from lfbench.cli import main

    tmp = tmp_path_factory.mktemp("ci")
    write_scene(tmp / "data", "s0", "training", size=40)
    out = tmp / "out"
    assert main(["-q", "evaluate", "--data", str(tmp / "data"), "--method", "constant", "--out", str(out),
                 "--no-progress", "--ci", "--ci-resamples", "20"]) == 0
    return out


@pytest.mark.parametrize(("column", "text"), [("low", "abc"), ("high", "1.2.3"), ("value", "--")])
def test_report_html_refuses_a_ci_csv_bound_that_is_not_a_number(ci_run, tmp_path, capsys, column, text):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(ci_run, run)
    lines = (run / "ci.csv").read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    row = lines[3].split(",")
    row[header.index(column)] = text
    lines[3] = ",".join(row)
    (run / "ci.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    rc, _, err = run_cli(capsys, "report", run, "--out", tmp_path / "rep", "--html")
    assert_one_error_line(rc, err, str(run / "ci.csv"), f"line 4: {column} is not a number")
    assert text not in err  # the file's content is not echoed


def test_ci_csv_reads_back_as_text_and_numbers(ci_run, tmp_path):
    from lfbench.scoring.stats import CI_COLUMNS, read_ci_csv

    ci = read_ci_csv(ci_run / "ci.csv")
    assert tuple(ci.columns) == CI_COLUMNS
    assert ci["low"].dtype == float and ci["high"].dtype == float
    written = pd.read_csv(ci_run / "ci.csv")  # pandas' own reading of the numbers
    for column in ("value", "low", "high"):
        np.testing.assert_array_equal(ci[column].to_numpy(), written[column].to_numpy())
    assert ci["low"].notna().any()
    path = tmp_path / "ci.csv"
    path.write_text("method,scene,metric,value,low,high\n7,001,badpix_0.07,1.5,,\n", encoding="utf-8")
    ci = read_ci_csv(path)  # names stay text (scene '001' is not the number 1), empty bounds are NaN
    assert ci.loc[0, "method"] == "7" and ci.loc[0, "scene"] == "001" and math.isnan(ci.loc[0, "low"])


@pytest.mark.parametrize("where", ["header", "rows"])
def test_report_html_refuses_a_ci_csv_of_100000_columns_in_one_line(ci_run, tmp_path, capsys, where):
    """Issue 31, class 8: a ci.csv of 3 rows and 100,000 columns (600 KB) kept report --html busy for more than
    a minute (pandas and the site's lookup take rows x columns); the wide line may be the header or a row."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(ci_run, run)
    lines = (run / "ci.csv").read_text(encoding="utf-8").splitlines()[:3]
    wide = 100_000 - len(lines[0].split(","))
    if where == "header":
        lines = [lines[0] + "".join(f",x{i}" for i in range(wide))] + [ln + "," * wide for ln in lines[1:]]
    else:
        lines[2] += "," * wide
    (run / "ci.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    rc, _, err = run_cli(capsys, "report", run, "--out", tmp_path / "rep", "--html")
    assert_one_error_line(rc, err, str(run / "ci.csv"), "a line of 100000 comma-separated fields",
                          "more than lfbench reads (256 columns)")
    assert not (tmp_path / "rep").exists()


def test_csv_tables_are_bounded_in_rows_and_columns(tmp_path):
    from lfbench.utils.errors import DataError
    from lfbench.utils.readfile import read_csv

    path = tmp_path / "t.csv"
    path.write_text("a,b\n" + "1,2\n" * 5, encoding="utf-8")
    assert read_csv(path, max_rows=5, max_columns=2).shape == (5, 2)
    with pytest.raises(DataError, match="t.csv: table has 6 lines, more than lfbench reads \\(4 rows and a header\\)"):
        read_csv(path, "table", max_rows=4)
    with pytest.raises(DataError, match="a line of 2 comma-separated fields, more than lfbench reads \\(1 columns\\)"):
        read_csv(path, "table", max_columns=1)


# --------------------------------------------------------------------------- validation border

@pytest.fixture(scope="module")
def data_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("data")
    for i in range(2):
        write_scene(root, f"plane_{i}", "additional", size=SIZE, seed=i)
    return root


def _config(tmp_path: Path, data_root: Path, validation: str) -> Path:
    path = tmp_path / "c.toml"
    path.write_text(f'seed = 1\n[data]\nroots = ["{data_root}"]\nvalidation = ["plane_1"]\npatch = 16\nstrides = [1]\n'
                    'stride_weights = [1]\n[model]\nwidth = 2\ninterval = 1.0\n[training]\nbatch_size = 1\n'
                    f'threads = 1\ncheckpoint_every = 1\nlog_every = 1\nprefetch = 0\n[validation]\n{validation}\n'
                    '[[stages]]\nname = "l1"\nloss = "l1"\nlr = 1e-3\nsteps = 2\n', encoding="utf-8")
    return path


@pytest.mark.parametrize(("validation", "fragment"), [
    ("every = 1\nborder = 12", "validation.border = 12 leaves no pixel of validation scene 'plane_1' (24x24 px)"),
    ("every = 1\nborder = 5\nmax_size = 10", "(10x10 px after validation.max_size)"),
], ids=["border", "border-after-crop"])
def test_a_validation_border_that_crops_everything_is_refused_before_training(tmp_path, capsys, data_root,
                                                                             validation, fragment):
    rc, _, err = run_cli(capsys, "-q", "train", _config(tmp_path, data_root, validation), "--out", tmp_path / "run",
                         "--no-progress")
    assert_one_error_line(rc, err, "c.toml", fragment)
    assert not (tmp_path / "run").exists()  # refused before anything is written (planned synthetic scenes too)


def test_the_largest_border_that_leaves_a_pixel_trains(tmp_path, capsys, data_root, one_torch_thread):
    """border 11 of 24 px leaves 2x2 pixels: validation is a number, and both files are strict JSON."""
    out = tmp_path / "run"
    rc, _, err = run_cli(capsys, "-q", "train", _config(tmp_path, data_root, "every = 1\nborder = 11"), "--out", out,
                         "--no-progress")
    assert rc == 0, err
    entries = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    val = [e for e in entries if e["event"] == "validation"]
    assert val and all(e["pixels"] == 4 and math.isfinite(e["badpix"]) for e in val)
    assert read_json(out / "summary.json")["validation"]["pixels"] == 4


def test_nan_numbers_of_a_run_are_written_as_null(tmp_path, capsys, data_root, one_torch_thread, monkeypatch):
    """A NaN or infinite validation number (a diverged network) is null in metrics.jsonl and summary.json,
    which stay strict JSON (read_json refuses NaN literals), and the learning curve is still drawn from
    them. (A non-finite loss stops training with one line.)"""
    import lfbench.training.loop as loop

    real = loop.validate

    def nan_validation(*args, **kwargs):
        res = real(*args, **kwargs)
        res["mse_x100"] = math.nan
        res["scenes"]["plane_1"]["badpix"] = math.inf
        return res

    monkeypatch.setattr(loop, "validate", nan_validation)
    out = tmp_path / "run"
    config = _config(tmp_path, data_root, "every = 1\nborder = 5")
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", out, "--no-progress")
    assert rc == 0, err
    text = (out / "metrics.jsonl").read_text()
    assert "NaN" not in text and "Infinity" not in text
    entries = [json.loads(line) for line in text.splitlines()]
    assert all(e["mse_x100"] is None and e["scenes"]["plane_1"]["badpix"] is None
               for e in entries if e["event"] == "validation")
    assert read_json(out / "summary.json")["validation"]["mse_x100"] is None
    assert (out / "learning_curve.png").is_file()
