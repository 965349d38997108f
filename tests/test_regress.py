"""`lfbench regress`: passes on equal results, fails with a readable diff on doctored ones."""

from __future__ import annotations

import json

import pytest

from lfbench.cli import main
from lfbench.results import Record, Results
from lfbench.runs.regress import compare, make_golden, read_golden


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
    assert [f.kind for f in compare(read_golden(golden), other, skip_absent_scenes=True)] == ["new"]
    assert [f.kind for f in compare(read_golden(golden), other)] == ["missing", "missing", "new"]


def test_cli_exit_codes_and_diff(golden, tmp_path, capsys):
    good, bad = tmp_path / "good", tmp_path / "bad"
    _results().write(good)
    _results(**{"badpix_0.07": 7.5}).write(bad)  # doctored: BadPix worsened by 2.5
    assert main(["regress", str(golden), str(good)]) == 0
    assert "OK: 2 compared, 0 regressions" in capsys.readouterr().out
    assert main(["regress", str(golden), str(bad / "results.json")]) == 1
    out = capsys.readouterr().out
    assert "WORSE    planesweep/synth_0/badpix_0.07: 5 -> 7.5 (+2.5, tolerance 0.01)" in out
    assert "FAIL: 2 compared, 1 regressions" in out


def test_cli_bad_golden_is_one_line_exit_2(tmp_path, capsys):
    path = tmp_path / "golden.json"
    path.write_text(json.dumps([{"method": "m", "scene": "s", "metric": "x"}]))
    _results().write(tmp_path / "new")
    assert main(["regress", str(path), str(tmp_path / "new")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "golden record 0 is malformed" in err[0] and str(path) in err[0]


# --------------------------------------------------------------------------- hostile golden files (issue 12.1)

def _golden_text(tmp_path, text: str):
    path = tmp_path / "golden.json"
    path.write_text(text, encoding="utf-8")
    return path


_REC = '{{"method": "planesweep", "scene": "synth_0", "metric": "{metric}", "value": {value}, "tolerance": {tol}, ' \
       '"resolution": "lowres"}}'


@pytest.mark.parametrize(("text", "problem"), [
    ("[" + _REC.format(metric="badpix_0.07", value="NaN", tol=0) + "]", "NaN is not a JSON number"),
    ("[" + _REC.format(metric="badpix_0.07", value="Infinity", tol=0) + "]", "Infinity is not a JSON number"),
    ("[" + _REC.format(metric="badpix_0.07", value='"NaN"', tol=0) + "]", "value must be a JSON number"),
    ("[" + _REC.format(metric="badpix_0.07", value='"inf"', tol=0) + "]", "value must be a JSON number"),
    ("[" + _REC.format(metric="badpix_0.07", value="true", tol=0) + "]", "value must be a JSON number"),
    ("[" + _REC.format(metric="badpix_0.07", value=1, tol="NaN") + "]", "NaN is not a JSON number"),
    ("[" + _REC.format(metric="badpix_0.07", value=1, tol=-1) + "]", "tolerance must be a finite number >= 0"),
    ("[" + _REC.format(metric="badpix_0.07", value="1e999", tol=0) + "]", "value must be a finite number"),
    ("[" + _REC.format(metric="badpixx_0.07", value=1, tol=0) + "]", "unknown metric 'badpixx_0.07'"),
    ("[" + _REC.format(metric="badpix_0.07", value=1, tol=0) + "," + _REC.format(metric="badpix_0.07", value=9, tol=0)
     + "]", "duplicate record"),
    ('[{"method": "planesweep", "scene": "s", "metric": "mse_x100", "metric": "badpix_0.07", "value": 1, '
     '"tolerance": 0, "resolution": "lowres"}]', "duplicate key 'metric'"),
    ("[" * 5000 + "]" * 5000, "nested 5000 levels deep"),
    ('{"records": 5}', "expected a JSON list of golden records"),
    ("[5]", "golden record 0 is malformed"),
])
def test_invalid_golden_is_refused_before_comparing(tmp_path, capsys, text, problem):
    """A NaN/Infinity golden value used to pass every check ("OK: 0 regressions", exit 0); a
    duplicate record silently let the last one win."""
    path = _golden_text(tmp_path, text)
    _results(**{"badpix_0.07": 1000.0}).write(tmp_path / "new")
    assert main(["regress", str(path), str(tmp_path / "new")]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and problem in err[0] and str(path) in err[0], err
    assert "OK" not in captured.out


def test_nonfinite_new_value_is_a_regression(golden, tmp_path, capsys):
    for value in ("NaN", "Infinity", "null"):
        new = tmp_path / f"new_{value}.json"
        new.write_text('[{"method": "planesweep", "scene": "synth_0", "metric": "badpix_0.07", "value": %s, '
                       '"resolution": "lowres"}, {"method": "planesweep", "scene": "synth_0", "metric": "mse_x100", '
                       '"value": 2.0, "resolution": "lowres"}]' % value)
        assert main(["regress", str(golden), str(new)]) == 1
        assert "INVALID  planesweep/synth_0/badpix_0.07" in capsys.readouterr().out


def _new_with(tmp_path, extra: Record):
    res = _results()
    res.records.append(extra)
    res.write(tmp_path / "new")


def test_new_records_absent_from_golden_are_reported_and_fail_on_request(golden, tmp_path, capsys):
    _new_with(tmp_path, Record("planesweep", "synth_0", "q25_x100", 3.0, "lowres"))
    assert main(["regress", str(golden), str(tmp_path / "new")]) == 0
    out = capsys.readouterr().out
    assert "NEW      planesweep/synth_0/q25_x100: 3 is not in the golden file" in out
    assert "1 new records not in the golden file" in out
    assert main(["regress", "--fail-on-new", str(golden), str(tmp_path / "new")]) == 1
    assert "FAIL: 2 compared, 1 regressions" in capsys.readouterr().out


def test_duplicate_new_records_are_refused(golden, tmp_path, capsys):
    _new_with(tmp_path, Record("planesweep", "synth_0", "badpix_0.07", 99.0, "lowres"))
    assert main(["regress", str(golden), str(tmp_path / "new")]) == 2
    assert "appears twice" in capsys.readouterr().err


def test_duplicate_new_records_are_refused_on_update(golden, tmp_path, capsys):
    before = golden.read_bytes()
    _new_with(tmp_path, Record("planesweep", "synth_0", "badpix_0.07", 99.0, "lowres"))
    assert main(["regress", "--update", str(golden), str(tmp_path / "new")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "planesweep/synth_0/badpix_0.07 appears twice" in err[0], err
    assert str(tmp_path / "new") in err[0] and str(golden) not in err[0]  # the results hold the duplicate
    assert golden.read_bytes() == before


@pytest.mark.parametrize("tolerance", ["-5", "nan", "inf", "*=0.01,mse_x100=-1", "x"])
def test_bad_tolerance_is_refused_and_golden_untouched(golden, tmp_path, capsys, tolerance):
    before = golden.read_bytes()
    _results().write(tmp_path / "new")
    assert main(["regress", "--update", "--tolerance", tolerance, str(golden), str(tmp_path / "new")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--tolerance" in err[0]
    assert golden.read_bytes() == before


def test_update_refuses_a_folder_and_unknown_metrics(tmp_path, capsys):
    _results().write(tmp_path / "new")
    assert main(["regress", "--update", str(tmp_path), str(tmp_path / "new")]) == 2
    assert "is a folder" in capsys.readouterr().err
    Results(records=[Record("m", "s", "my_metric", 1.0, "lowres")]).write(tmp_path / "odd")
    assert main(["regress", "--update", str(tmp_path / "g.json"), str(tmp_path / "odd")]) == 2
    assert "unknown metric 'my_metric'" in capsys.readouterr().err
    assert not (tmp_path / "g.json").exists()


@pytest.mark.parametrize("runs", ['5', '[5]', '[{"method": "m"}]', '[{"method": "m", "scene": "s", "bogus": 1}]',
                                  '[{"method": "m", "scene": "s", "runtime_s": "x"}]',
                                  '[{"method": "m", "scene": "s", "notes": "abc"}]'])
def test_malformed_runs_in_results_are_one_line(tmp_path, runs):
    from lfbench.utils.errors import DataError

    path = tmp_path / "results.json"
    path.write_text('{"records": [], "runs": %s}' % runs)
    if runs.endswith('"bogus": 1}]'):  # unknown fields are ignored (older/newer versions)
        assert Results.read(path).runs[0].method == "m"
        return
    with pytest.raises(DataError, match="results.json"):
        Results.read(path)


# ------------------------------------------------------------------- a gate that cannot pass on nothing (issue 20.5)

@pytest.mark.parametrize("text", ["[]", '{"records": []}'])
def test_an_empty_golden_file_fails_unless_allowed(tmp_path, capsys, text):
    """It printed "OK: 0 golden metrics" and exited 0: a gate that compared nothing passed."""
    path = _golden_text(tmp_path, text)
    _results().write(tmp_path / "new")
    assert main(["regress", str(path), str(tmp_path / "new")]) == 1
    summary = capsys.readouterr().out.strip().splitlines()[-1]
    assert summary.startswith("FAIL: 0 compared, 0 regressions")
    assert "nothing was compared (the golden file holds no records)" in summary and "--allow-empty" in summary
    assert main(["regress", "--allow-empty", str(path), str(tmp_path / "new")]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith("OK: 0 compared")


def test_every_golden_scene_absent_fails_and_says_what_was_skipped(golden, tmp_path, capsys):
    """--skip-absent-scenes with every golden scene absent printed "OK: 2 golden metrics, 0 regressions"."""
    Results(records=[Record("planesweep", "elsewhere", "badpix_0.07", 1.0, "lowres")]).write(tmp_path / "new")
    argv = ["regress", "--skip-absent-scenes", str(golden), str(tmp_path / "new")]
    assert main(argv) == 1
    summary = capsys.readouterr().out.strip().splitlines()[-1]
    assert summary.startswith("FAIL: 0 compared, 0 regressions")
    assert "2 skipped: scene absent from the new results (synth_0)" in summary
    assert "nothing was compared (every golden record was skipped)" in summary
    assert main([*argv, "--allow-empty"]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith("OK: 0 compared")


def test_summary_counts_compared_and_skipped_records(tmp_path, capsys):
    golden = tmp_path / "golden.json"
    both = Results(records=[*_results().records, Record("published:x", "backgammon", "mse_x100", 1.5, "lowres"),
                            Record("published:x", "antinous", "mse_x100", 0.5, "lowres")])
    make_golden(both, 0.01, golden)
    _results().write(tmp_path / "new")
    assert main(["regress", "--skip-absent-scenes", str(golden), str(tmp_path / "new")]) == 0
    assert capsys.readouterr().out.strip() == ("OK: 2 compared, 0 regressions, 0 improved beyond tolerance; 2 skipped: "
                                               "scene absent from the new results (backgammon, antinous)")
    assert main(["regress", str(golden), str(tmp_path / "new")]) == 1  # without the flag: missing records
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith("FAIL: 4 compared, 2 regressions")


@pytest.mark.parametrize(("metric", "tolerance", "refused"), [
    ("badpix_0.07", "1e308", True), ("badpix_0.07", "100", True), ("badpix_0.07", "99.5", False),
    ("stripes_dark", "100", True), ("missed_dots", "1e308", True), ("bumpiness_planes", "5", True),
    ("bumpiness_planes", "4.9", False), ("mae_planes", "180", True), ("mse_x100", "1e6", False),
])
def test_tolerances_are_bounded_by_the_metric_range(tmp_path, capsys, metric, tolerance, refused):
    """A tolerance of 1e308 on a 0-100 % metric was accepted: every value passed."""
    path = _golden_text(tmp_path, "[" + _REC.format(metric=metric, value=1, tol=tolerance) + "]")
    Results(records=[Record("planesweep", "synth_0", metric, 1.0, "lowres")]).write(tmp_path / "new")
    rc = main(["regress", str(path), str(tmp_path / "new")])
    captured = capsys.readouterr()
    if refused:
        assert rc == 2 and "as wide as the range of" in captured.err and str(path) in captured.err
    else:
        assert rc == 0 and captured.out.startswith("OK: 1 compared")


def test_values_outside_the_metric_range_are_refused_or_fail(tmp_path, capsys):
    path = _golden_text(tmp_path, "[" + _REC.format(metric="badpix_0.07", value=150, tol=0) + "]")
    _results().write(tmp_path / "new")
    assert main(["regress", str(path), str(tmp_path / "new")]) == 2
    assert "value 150 is outside the range of badpix_0.07 (0 to 100 %)" in capsys.readouterr().err
    golden = tmp_path / "g2.json"
    make_golden(_results(), 0.5, golden)
    _results(**{"badpix_0.07": -3.0}).write(tmp_path / "neg")  # "better" by 8, but not a percentage
    assert main(["regress", str(golden), str(tmp_path / "neg")]) == 1
    assert ("INVALID  planesweep/synth_0/badpix_0.07: new value -3 is outside the range of badpix_0.07 (0 to 100 %)"
            in capsys.readouterr().out)


def test_update_refuses_an_empty_golden_file_and_wide_tolerances(tmp_path, capsys):
    Results(records=[Record("m", "s", "mse_x100", float("nan"), "lowres")]).write(tmp_path / "nan")
    target = tmp_path / "g.json"
    assert main(["regress", "--update", str(target), str(tmp_path / "nan")]) == 2
    assert "no finite records to make golden" in capsys.readouterr().err and not target.exists()
    assert main(["regress", "--update", "--allow-empty", str(target), str(tmp_path / "nan")]) == 0
    assert json.loads(target.read_text()) == []
    _results().write(tmp_path / "new")
    assert main(["regress", "--update", "--tolerance", "badpix_*=250,*=0.01", str(tmp_path / "g3.json"),
                 str(tmp_path / "new")]) == 2
    err = capsys.readouterr().err
    assert "--tolerance for record planesweep/synth_0/badpix_0.07" in err and "as wide as the range" in err
    assert not (tmp_path / "g3.json").exists()


@pytest.mark.parametrize("value", ["9" * 400, "9" * 5000, "-" + "9" * 30, "18446744073709551616"])
def test_huge_integers_in_golden_or_new_results_are_one_line(tmp_path, capsys, value):
    """A 400-digit integer ended in OverflowError, a 5000-digit one in ValueError (Python's int limit)."""
    path = _golden_text(tmp_path, "[" + _REC.format(metric="mse_x100", value=value, tol=0) + "]")
    _results().write(tmp_path / "new")
    assert main(["regress", str(path), str(tmp_path / "new")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and ("digits" in err[0] or "64-bit" in err[0]), err
    new = tmp_path / "new.json"
    new.write_text('[{"method": "planesweep", "scene": "synth_0", "metric": "mse_x100", "value": %s}]' % value)
    assert main(["regress", str(path.with_name("golden_ok.json")), str(new)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(new) in err[0] and ("digits" in err[0] or "64-bit" in err[0]), err


def test_a_golden_file_beaten_beyond_tolerance_passes_with_a_stale_hint_naming_the_records(golden, tmp_path, capsys):
    """Issue 32.6: new values better than golden by more than the tolerance pass, and one hint line says the
    golden file is stale, naming those records (a golden file that is not refreshed would let them fall back)."""
    _results(**{"badpix_0.07": 4.0, "mse_x100": 1.9}).write(tmp_path / "new")
    assert main(["regress", str(golden), str(tmp_path / "new")]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-2] == "OK: 2 compared, 0 regressions, 2 improved beyond tolerance"
    assert lines[-1].startswith("hint: the golden file is stale: 2 records better than golden by more than the "
                                "tolerance (planesweep/synth_0/badpix_0.07, planesweep/synth_0/mse_x100)")
    assert f"lfbench regress {golden} {tmp_path / 'new'} --update" in lines[-1]
    # within tolerance, or a regression beside the improvement: no hint
    _results(**{"badpix_0.07": 4.995}).write(tmp_path / "close")
    assert main(["regress", str(golden), str(tmp_path / "close")]) == 0
    assert "hint" not in capsys.readouterr().out
    _results(**{"badpix_0.07": 4.0, "mse_x100": 3.0}).write(tmp_path / "mixed")
    assert main(["regress", "--quiet", str(golden), str(tmp_path / "mixed")]) == 1
    assert "hint" not in capsys.readouterr().out


def test_the_stale_hint_names_the_first_records_and_counts_the_rest(tmp_path):
    from lfbench.runs.regress import check

    golden = tmp_path / "golden.json"
    make_golden(Results(records=[Record("m", f"s{i}", "mse_x100", 5.0, "lowres") for i in range(7)]), 0.01, golden)
    better = Results(records=[Record("m", f"s{i}", "mse_x100", 1.0, "lowres") for i in range(7)])
    hint = check(read_golden(golden), better).stale_hint(shown=2)
    assert "7 records better than golden" in hint and "(m/s0/mse_x100, m/s1/mse_x100 and 5 more)" in hint
