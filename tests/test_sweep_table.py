"""lfbench.reports.sweep_table: Table IV of a training-free method from an ablation run's methods/ folders,
on hand-made results."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from lfbench.reports.sweep_table import collect, main, sweep_table


def _method(run: Path, label: str, spec: str, scores: dict[str, tuple[float, float]], runtime: float) -> None:
    """scores: scene -> (BadPix 0.07, MSE x100); the other metrics are fixed made-up values."""
    folder = run / "methods" / label.replace(" ", "_")
    folder.mkdir(parents=True)
    (folder / "method.json").write_text(json.dumps({"label": label, "spec": spec, "key": "x"}))
    records, runs = [], []
    for scene, (bp, mse) in scores.items():
        for metric, value in (("badpix_0.07", bp), ("badpix_0.03", bp + 10), ("badpix_0.01", bp + 20),
                              ("mse_x100", mse), ("q25_x100", 1.0)):
            records.append({"method": label, "scene": scene, "metric": metric, "value": value,
                            "resolution": "lowres"})
        runs.append({"method": label, "scene": scene, "runtime_s": runtime})
    records.append({"method": label, "scene": "stripes", "metric": "badpix_0.07", "value": 99.0,
                    "resolution": "highres"})  # left out: the table is low resolution
    (folder / "results.json").write_text(json.dumps({"meta": {}, "records": records, "runs": runs}))


@pytest.fixture()
def run(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    _method(run, "a", "planesweep:interval=1,interpolation=nearest",
            {"backgammon": (30.0, 8.0), "synth_1000_0": (40.0, 20.0), "synth_1000_1": (50.0, 30.0)}, 2.0)
    _method(run, "b", "planesweep:interval=0.25,interpolation=nearest",
            {"backgammon": (10.0, 4.0), "synth_1000_0": (20.0, 10.0), "synth_1000_1": (30.0, 12.0)}, 6.0)
    _method(run, "c", "planesweep:interval=0.25,interpolation=bilinear,subpixel=none",
            {"backgammon": (12.0, 5.0), "synth_1000_0": (22.0, 11.0), "synth_1000_1": (24.0, 13.0)}, 4.0)
    (run / "methods" / "unfinished").mkdir()  # a method still running: no results.json yet
    return run


def test_table_rows_means_and_order(run):
    frame = collect(run)
    assert set(frame["label"]) == {"a", "b", "c"} and (frame["value"] != 99.0).all()
    table = sweep_table(frame)
    assert list(table.index) == ["backgammon"] * 3 + ["synthetic (mean of 2)"] * 3
    synth = table.loc["synthetic (mean of 2)"].reset_index()
    # fit first (nearest 1 then 0.25, coarse to fine), then the no-fit rows
    assert list(zip(synth["interpolation"], synth["sub-pixel fit"], synth["interval (px)"], strict=True)) == [
        ("nearest", "equiangular", "1"), ("nearest", "equiangular", "0.25"), ("bilinear", "none", "0.25")]
    assert list(synth["BadPix 0.07 (%)"]) == [45.0, 25.0, 23.0]
    assert list(synth["BadPix 0.01 (%)"]) == [65.0, 45.0, 43.0]
    assert list(synth["MSE x100"]) == [25.0, 11.0, 12.0]
    assert list(synth["time per scene (s)"]) == [2.0, 6.0, 4.0]


def test_command_writes_table_and_figure(run, tmp_path, capsys):
    out = tmp_path / "out"
    assert main([str(run), str(out), "--caption", "made-up numbers"]) == 0
    csv = pd.read_csv(out / "interval_sweep.csv", comment="#")
    assert len(csv) == 6
    assert (out / "figures" / "interval_sweep.png").stat().st_size > 1000
    assert "made-up numbers" in (out / "interval_sweep.md").read_text()
    assert main([str(tmp_path / "nothing"), str(out)]) == 2
    assert "not an ablation output folder" in capsys.readouterr().err


@pytest.mark.parametrize("text", ["{not json", '{"records": [{"method": "a", "scene": "s", "metric": "mse_x100"}]}'])
def test_malformed_method_results_are_one_line_naming_the_file(run, tmp_path, capsys, text):
    bad = run / "methods" / "a" / "results.json"
    bad.write_text(text)
    assert main([str(run), str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(bad) in err[0], err
    assert not (tmp_path / "out").exists()
