"""The regression gate's public behaviour that a refactor could change silently (issue 25): a record at
tolerance 0 (what it gets when no tolerance pattern matches) passes when identical and fails on the
smallest worsening; failures are listed first, in golden order; make_golden leaves non-finite values out.

Expected findings are written by hand from the gate's contract (lfbench.runs.regress docstring), never
from its own output. The mutation each test kills is named in its docstring."""

from __future__ import annotations

import json
import math

import pytest

from lfbench.results import Record, Results
from lfbench.runs.regress import compare, make_golden, read_golden

METHOD, SCENE = "planesweep", "synth_0"


def _results(values: dict[str, float], resolution: str = "lowres") -> Results:
    return Results(records=[Record(METHOD, SCENE, m, v, resolution) for m, v in values.items()])


def _golden(tmp_path, values: dict[str, float], tolerance) -> list:
    path = tmp_path / "golden.json"
    make_golden(_results(values), tolerance, path)
    return read_golden(path)


def test_unmatched_metric_gets_tolerance_zero_and_identical_results_pass(tmp_path):
    """Kills `change > tolerance` -> `>=` (identical results would fail at tolerance 0) and
    `change < -tolerance` -> `<=` (identical results would be reported as better), and a non-zero
    default tolerance for a record that no pattern matches."""
    values = {"badpix_0.07": 5.0, "mse_x100": 2.0, "q25_x100": 0.75}
    golden = _golden(tmp_path, values, {"mse_x100": 0.05})  # badpix and q25: no pattern -> 0
    assert {g.metric: g.tolerance for g in golden} == {"badpix_0.07": 0.0, "mse_x100": 0.05, "q25_x100": 0.0}
    assert compare(golden, _results(values)) == []


@pytest.mark.parametrize("direction", [1, -1])
def test_tolerance_zero_catches_the_smallest_change(tmp_path, direction):
    """At tolerance 0 the next float up is a regression, the next float down an improvement."""
    golden = _golden(tmp_path, {"badpix_0.07": 5.0}, 0.0)
    new = math.nextafter(5.0, math.inf * direction)
    findings = compare(golden, _results({"badpix_0.07": new}))
    assert [(f.kind, f.failed) for f in findings] == ([("worse", True)] if direction > 0 else [("better", False)])


def test_findings_list_failures_first_in_golden_order(tmp_path):
    """Kills dropping or reversing the sort of findings (failures first, stable: golden order within
    failures and within the rest)."""
    golden = _golden(tmp_path, {"badpix_0.01": 10.0, "badpix_0.03": 8.0, "badpix_0.07": 5.0, "mse_x100": 2.0,
                                "q25_x100": 1.0}, 0.01)
    new = _results({"badpix_0.01": 9.0,   # better (reported, passes)
                    "badpix_0.03": 9.0,   # worse (fails)
                    "mse_x100": 2.0,      # equal: no finding
                    "q25_x100": 1.5,      # worse (fails)
                    "discontinuities": 3.0})  # new (reported, passes); badpix_0.07 missing (fails)
    findings = compare(golden, new)
    assert [(f.kind, f.key[2], f.failed) for f in findings] == [
        ("worse", "badpix_0.03", True), ("missing", "badpix_0.07", True), ("worse", "q25_x100", True),
        ("better", "badpix_0.01", False), ("new", "discontinuities", False)]


def test_make_golden_leaves_out_nonfinite_values(tmp_path):
    """Kills dropping make_golden's finite filter (a NaN value would make the JSON write fail or, with
    NaN allowed, write a golden file that read_golden refuses)."""
    path = tmp_path / "golden.json"
    results = _results({"badpix_0.07": 5.0, "mse_x100": math.nan, "q25_x100": math.inf})
    assert make_golden(results, 0.01, path) == 1
    text = path.read_text(encoding="utf-8")
    records = json.loads(text, parse_constant=lambda token: pytest.fail(f"golden file holds {token}"))
    assert records == [{"method": METHOD, "scene": SCENE, "metric": "badpix_0.07", "value": 5.0, "tolerance": 0.01,
                        "resolution": "lowres"}]
    assert [g.key for g in read_golden(path)] == [(METHOD, SCENE, "badpix_0.07")]


def _record(metric: str, value: float, scene: str = SCENE, resolution: str = "lowres") -> Record:
    return Record(METHOD, scene, metric, value, resolution)


def test_every_kind_of_finding_with_its_message_and_nothing_skipped(tmp_path):
    """Kills `continue` -> `break` after each kind of finding (later golden records would go unchecked),
    a finding without its key or message, and `skip_absent_scenes` stopping at the first absent scene.
    The messages are the report's lines, written here by hand."""
    golden_results = Results(records=[
        _record("badpix_0.07", 5.0, scene="absent"),  # its scene is not in the new results: skipped
        _record("badpix_0.01", 10.0, resolution="highres"),  # now scored at lowres
        _record("badpix_0.03", 8.0),  # new value NaN
        _record("badpix_0.07", 5.0),  # missing
        _record("mse_x100", 2.0),  # worse
        _record("q25_x100", 1.0),  # better
    ])
    path = tmp_path / "golden.json"
    make_golden(golden_results, 0.01, path)
    new = Results(records=[_record("badpix_0.01", 10.0), _record("badpix_0.03", math.nan),
                           _record("mse_x100", 2.5), _record("q25_x100", 0.5), _record("discontinuities", 7.0)])
    findings = compare(read_golden(path), new, skip_absent_scenes=True)
    name = f"{METHOD}/{SCENE}"
    assert [(f.kind, f.key, f.failed, f.message) for f in findings] == [
        ("resolution", (METHOD, SCENE, "badpix_0.01"), True,
         f"CHANGED  {name}/badpix_0.01: scored at lowres, golden at highres"),
        ("nan", (METHOD, SCENE, "badpix_0.03"), True, f"INVALID  {name}/badpix_0.03: new value is nan"),
        ("missing", (METHOD, SCENE, "badpix_0.07"), True,
         f"MISSING  {name}/badpix_0.07: in golden (5) but not in the new results"),
        ("worse", (METHOD, SCENE, "mse_x100"), True, f"WORSE    {name}/mse_x100: 2 -> 2.5 (+0.5, tolerance 0.01)"),
        ("better", (METHOD, SCENE, "q25_x100"), False,
         f"better   {name}/q25_x100: 1 -> 0.5 (-0.5, tolerance 0.01)"),
        ("new", (METHOD, SCENE, "discontinuities"), False,
         f"NEW      {name}/discontinuities: 7 is not in the golden file"),
    ]
    assert [f.key[1] for f in compare(read_golden(path), new)].count("absent") == 1  # without the skip: missing


def test_a_higher_is_better_metric_worsens_when_it_falls(tmp_path, monkeypatch):
    """Kills the sign of a higher-is-better metric lost or scaled (`-1.0` -> `+1.0` / `-2.0`, its
    condition inverted or dropped, the metric not looked up): a plugin may register such a metric."""
    import lfbench.runs.regress as regress
    from lfbench.scoring.metrics import Metric

    score = Metric(id="psnr_db", name="PSNR", description="peak signal-to-noise ratio", unit="dB",
                   fn=lambda *a, **k: 0.0, higher_is_better=True)
    known = regress.METRICS.find
    monkeypatch.setattr(regress.METRICS, "find", lambda m: score if m == "psnr_db" else known(m))
    golden = _golden(tmp_path, {"psnr_db": 30.0, "mse_x100": 2.0}, 1.0)
    # PSNR: 30 -> 29.4 is within the tolerance 1 (a doubled change, 1.2, would not be); 28.9 is worse; 31.5 better
    assert compare(golden, _results({"psnr_db": 29.4, "mse_x100": 2.0})) == []
    assert [(f.kind, f.failed) for f in compare(golden, _results({"psnr_db": 28.9, "mse_x100": 2.0}))] == [
        ("worse", True)]
    assert [(f.kind, f.failed) for f in compare(golden, _results({"psnr_db": 31.5, "mse_x100": 3.5}))] == [
        ("worse", True), ("better", False)]
    assert [f.key[2] for f in compare(golden, _results({"psnr_db": 31.5, "mse_x100": 3.5}))] == ["mse_x100",
                                                                                             "psnr_db"]


def test_make_golden_tolerance_by_method_and_file_layout(tmp_path):
    """Kills make_golden passing no method to tolerance_for (METHOD/METRIC patterns would never match)
    and a change of the file's layout (one key per line, indent 1: diffs of golden files stay readable)."""
    path = tmp_path / "golden.json"
    make_golden(_results({"mse_x100": 2.0}), {f"{METHOD}/*": 0.25, "*": 0.01}, path)
    assert path.read_text(encoding="utf-8") == (
        '[\n {\n  "method": "planesweep",\n  "scene": "synth_0",\n  "metric": "mse_x100",\n  "value": 2.0,\n'
        '  "tolerance": 0.25,\n  "resolution": "lowres"\n }\n]\n')


def test_make_golden_names_the_golden_file_for_duplicates_without_a_source(tmp_path):
    """Kills make_golden naming `source` (None) instead of the golden file when no source is given."""
    from lfbench.utils.errors import DataError

    path = tmp_path / "golden.json"
    twice = Results(records=[_record("mse_x100", 1.0), _record("mse_x100", 2.0)])
    with pytest.raises(DataError, match="appears twice") as info:
        make_golden(twice, 0.0, path)
    assert str(path) in str(info.value) and not path.exists()


def test_read_golden_accepts_a_records_object_and_refuses_empty_names(tmp_path):
    """Kills read_golden ignoring the {"records": [...]} form (results.json's layout) and accepting an
    empty method/scene/metric/resolution (`isinstance(v, str) and v` -> `or`)."""
    from lfbench.utils.errors import DataError

    record = {"method": METHOD, "scene": SCENE, "metric": "mse_x100", "value": 2.0, "tolerance": 0.5,
              "resolution": "lowres"}
    path = tmp_path / "golden.json"
    path.write_text(json.dumps({"records": [record]}), encoding="utf-8")
    assert [(g.key, g.value, g.tolerance) for g in read_golden(path)] == [((METHOD, SCENE, "mse_x100"), 2.0, 0.5)]
    path.write_text(json.dumps([{**record, "scene": ""}]), encoding="utf-8")
    with pytest.raises(DataError, match="golden record 0 is malformed.*non-empty strings"):
        read_golden(path)
    path.write_text(json.dumps([record, {**record, "metric": "q25_x100", "resolution": "midres"}]), encoding="utf-8")
    with pytest.raises(DataError, match=r"golden record 1 \(planesweep/synth_0/q25_x100\): resolution must be one "
                                        r"of lowres, highres"):
        read_golden(path)


@pytest.mark.parametrize(("text", "problem"), [
    ('{"records": 5}', "expected a JSON list of golden records"),
    ("[5]", "golden record 0 is malformed (needs method, scene, metric, value, tolerance, resolution): "
            "not an object"),
    ('[{"method": "m", "scene": "s", "metric": "mse_x100", "value": 1, "tolerance": "0.1", "resolution": "lowres"}]',
     "tolerance must be a JSON number, got str '0.1'"),
    ('[{"method": "m", "scene": "s", "metric": "mse_x100", "value": 1, "tolerance": 0, "resolution": "x"}]',
     "golden record 0 (m/s/mse_x100): resolution must be one of lowres, highres"),
    ("{", "golden file"),
])
def test_read_golden_errors_name_the_file_and_the_problem(tmp_path, text, problem):
    """Kills read_golden's errors losing their file, their wording or the name of the bad field."""
    from lfbench.utils.errors import DataError

    path = tmp_path / "golden.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DataError) as e:
        read_golden(path)
    assert str(e.value).startswith(f"{path}: ") and problem in str(e.value)


def test_make_golden_errors_name_the_golden_file(tmp_path):
    """Kills make_golden's errors (a folder, an unknown metric) losing the golden file or their wording."""
    from lfbench.utils.errors import DataError

    with pytest.raises(DataError) as e:
        make_golden(_results({"mse_x100": 1.0}), 0.0, tmp_path)
    assert str(e.value) == f"{tmp_path}: golden file is a folder, expected a file"
    path = tmp_path / "golden.json"
    with pytest.raises(DataError) as e:
        make_golden(_results({"my_metric": 1.0}), 0.0, path)
    assert str(e.value) == (f"{path}: record {METHOD}/{SCENE}/my_metric: unknown metric 'my_metric', "
                            "cannot make it golden")


def test_gate_error_messages_word_for_word(tmp_path):
    """Kills rewordings of the gate's user-facing errors (the whole line is the contract: one line naming
    the file and the problem), the field name cut at a different length, and a tolerance error without
    the bad value."""
    from lfbench.runs.regress import check_tolerance
    from lfbench.utils.errors import DataError, SpecError

    path = tmp_path / "golden.json"
    rec = {"method": "m", "scene": "s", "metric": "mse_x100", "value": 1, "tolerance": 0, "resolution": "lowres"}
    malformed = "golden record 0 is malformed (needs method, scene, metric, value, tolerance, resolution): "
    cases = [('{"records": 5}', "expected a JSON list of golden records"),
             (json.dumps([{**rec, "method": ""}]), malformed + "method, scene, metric and resolution must be "
                                                              "non-empty strings"),
             (json.dumps([{**rec, "value": "x" * 300}]),
              malformed + ("value must be a JSON number, got str '" + "x" * 300)[:120])]
    for text, message in cases:
        path.write_text(text, encoding="utf-8")
        with pytest.raises(DataError) as e:
            read_golden(path)
        assert str(e.value) == f"{path}: {message}"
    path.unlink()
    with pytest.raises(DataError) as e:
        read_golden(path)
    assert str(e.value) == f"{path}: golden file not found"
    with pytest.raises(SpecError, match="got -1.5"):
        check_tolerance({"mse_x100": -1.5})
