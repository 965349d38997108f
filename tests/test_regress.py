"""`lfbench regress`: passes on equal results, fails with a readable diff on doctored ones."""

from __future__ import annotations

import json

import pytest

from lfbench.cli import main
from lfbench.runs.regress import compare, make_golden, read_golden
from lfbench.runs.results import Record, Results


def _results(**overrides: float) -> Results:
    values = {"badpix_0.07": 5.0, "mse_x100": 2.0}
    values.update(overrides)
    return Results(records=[Record("planesweep", "synth_0", m, v, "lowres") for m, v in values.items()])


@pytest.fixture()
def golden(tmp_path):
    path = tmp_path / "golden.json"
    make_golden(_results(), {"*": 0.01, "mse_x100": 0.05}, path)
    return path


def test_golden_records_carry_tolerances(golden):
    recs = {r.metric: r for r in read_golden(golden)}
    assert recs["badpix_0.07"].tolerance == 0.01 and recs["mse_x100"].tolerance == 0.05
    assert recs["badpix_0.07"].value == 5.0 and recs["badpix_0.07"].resolution == "lowres"


def test_tolerance_by_method_and_metric():
    from lfbench.runs.regress import tolerance_for

    spec = {"published*/*": 1e-6, "subfocal:width=16/badpix_*": 0.25, "mse_x100": 0.05, "*": 0.01}
    assert tolerance_for("published:subfocal", "mse_x100", spec) == 1e-6  # METHOD/METRIC keys win
    assert tolerance_for("subfocal:width=16", "badpix_0.07", spec) == 0.25
    assert tolerance_for("subfocal:width=16", "mse_x100", spec) == 0.05
    assert tolerance_for("planesweep", "q25_x100", spec) == 0.01
    assert tolerance_for("planesweep", "q25_x100", {"mse_x100": 1.0}) == 0.0
    assert tolerance_for("planesweep", "q25_x100", 0.5) == 0.5


def test_within_tolerance_passes(golden):
    assert not [f for f in compare(read_golden(golden), _results(**{"badpix_0.07": 5.009})) if f.failed]


def test_worse_beyond_tolerance_fails(golden):
    findings = compare(read_golden(golden), _results(mse_x100=2.051))
    assert [f.kind for f in findings if f.failed] == ["worse"]
    assert "planesweep/synth_0/mse_x100: 2 -> 2.051" in findings[0].message


def test_improvement_is_reported_not_failed(golden):
    findings = compare(read_golden(golden), _results(**{"badpix_0.07": 4.0}))
    assert [f.kind for f in findings] == ["better"] and not findings[0].failed


def test_missing_metric_and_resolution_change_fail(golden):
    res = _results()
    res.records = [r for r in res.records if r.metric != "mse_x100"]
    res.records[0] = Record("planesweep", "synth_0", "badpix_0.07", 5.0, "highres")
    kinds = sorted(f.kind for f in compare(read_golden(golden), res))
    assert kinds == ["missing", "resolution"]


def test_skip_absent_scenes_only_skips_whole_scenes(golden):
    other = Results(records=[Record("planesweep", "other_scene", "badpix_0.07", 1.0, "lowres")])
    assert compare(read_golden(golden), other, skip_absent_scenes=True) == []
    assert len(compare(read_golden(golden), other)) == 2


def test_cli_exit_codes_and_diff(golden, tmp_path, capsys):
    good, bad = tmp_path / "good", tmp_path / "bad"
    _results().write(good)
    _results(**{"badpix_0.07": 7.5}).write(bad)  # doctored: BadPix worsened by 2.5
    assert main(["regress", str(golden), str(good)]) == 0
    assert "OK: 2 golden metrics, 0 regressions" in capsys.readouterr().out
    assert main(["regress", str(golden), str(bad / "results.json")]) == 1
    out = capsys.readouterr().out
    assert "WORSE    planesweep/synth_0/badpix_0.07: 5 -> 7.5 (+2.5, tolerance 0.01)" in out
    assert "FAIL: 2 golden metrics, 1 regressions" in out


def test_cli_bad_golden_is_one_line_exit_2(tmp_path, capsys):
    path = tmp_path / "golden.json"
    path.write_text(json.dumps([{"method": "m", "scene": "s", "metric": "x"}]))
    _results().write(tmp_path / "new")
    assert main(["regress", str(path), str(tmp_path / "new")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "golden record 0 is malformed" in err[0] and str(path) in err[0]
