"""The regression gate's mutants that the first full mutation run left alive (lfbench/runs/regress.py):
make_golden's refusals (a value outside its metric's range, a tolerance as wide as the range, nothing to
write, a duplicate) and which file each names (``source``, where the results came from, else the golden
file), make_golden's ``allow_empty`` default, the tolerance a key holding '/' gives, compare passing
``fail_on_new`` on, GateResult.summary for a gate that compared nothing, and GateResult.stale_hint's
defaults, plural and "and N more".

Every expected value is written out by hand from the gate's contract (the module docstring and each
function's): the whole error line, the whole summary or hint, which file an error names, whether a file was
written. The class of mutants each test kills is named in its docstring. In-process and fast. The survivors
no input can tell apart (make_golden's allow_nan: no non-finite number reaches json.dumps; check's
Metric.undefined id: only its badness is read) have their reasons in tools/mutation/classify.py.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from lfbench.results import Record, Results
from lfbench.runs.regress import check, compare, make_golden, read_golden
from lfbench.utils.errors import DataError, SpecError

METHOD, SCENE = "planesweep", "synth_0"
SOURCE = Path("runs/results.json")  # where the results came from (never read: make_golden only names it)
EMPTY = ("no finite records to make golden: an empty golden file is a gate that compares nothing "
         "(--allow-empty writes one anyway)")


def _results(*records: tuple[str, str, float]) -> Results:
    """Records of METHOD at lowres, each (scene, metric, value)."""
    return Results(records=[Record(METHOD, scene, metric, value, "lowres") for scene, metric, value in records])


# --------------------------------------------------------------------------- make_golden


@pytest.mark.parametrize("source", [None, SOURCE])
def test_make_golden_refuses_a_value_outside_its_metric_range_naming_where_it_came_from(tmp_path, source):
    """Kills make_golden's range check dropped (`problem = None`, `isfinite(...) and False`), its DataError
    without its message or without a file, and the file it names: `source` when given, else the golden file
    (`source is not None` negated, `and False`, `or True`)."""
    path = tmp_path / "golden.json"
    with pytest.raises(DataError) as info:
        make_golden(_results((SCENE, "mse_x100", 2.0), (SCENE, "badpix_0.07", 150.0)), 0.0, path, source=source)
    named = SOURCE if source is not None else path
    assert str(info.value) == (f"{named}: record planesweep/synth_0/badpix_0.07: value 150 is outside the range "
                               "of badpix_0.07 (0 to 100 %)")
    assert info.value.path == named
    assert not path.exists()


def test_make_golden_refuses_a_tolerance_as_wide_as_the_range_in_its_words(tmp_path):
    """Kills the rewording of _tolerance_too_wide's last words ("would pass" -> "XXwould passXX" /
    "WOULD PASS"): the whole SpecError line."""
    path = tmp_path / "golden.json"
    with pytest.raises(SpecError) as info:
        make_golden(_results((SCENE, "badpix_0.07", 5.0)), 100.0, path)
    assert str(info.value) == ("--tolerance for record planesweep/synth_0/badpix_0.07: tolerance 100 is as wide as "
                               "the range of badpix_0.07 (0 to 100 %): every value would pass")
    assert info.value.path is None and not path.exists()


def test_make_golden_checks_the_tolerance_a_method_pattern_gives(tmp_path):
    """Kills make_golden checking the tolerance of `None/METRIC` instead of `METHOD/METRIC`: the pattern
    'planesweep/*' gives badpix_0.07 a tolerance of 100 (its whole range), which must be refused, not
    checked as the '*' tolerance 0.5 and then written as 100."""
    path = tmp_path / "golden.json"
    with pytest.raises(SpecError) as info:
        make_golden(_results((SCENE, "badpix_0.07", 5.0)), {"planesweep/*": 100.0, "*": 0.5}, path)
    assert str(info.value) == ("--tolerance for record planesweep/synth_0/badpix_0.07: tolerance 100 is as wide as "
                               "the range of badpix_0.07 (0 to 100 %): every value would pass")
    assert not path.exists()
    # the same pattern, narrower: accepted and written (the check reads the tolerance the file gets)
    assert make_golden(_results((SCENE, "badpix_0.07", 5.0)), {"planesweep/*": 99.5, "*": 0.5}, path) == 1
    assert [(g.key, g.tolerance) for g in read_golden(path)] == [((METHOD, SCENE, "badpix_0.07"), 99.5)]


def test_a_pattern_with_a_slash_is_a_method_pattern_even_where_a_metric_id_would_match(tmp_path):
    """Kills tolerance_for trying a key that holds '/' as a metric-id pattern too (`"/" not in key` ->
    `"XX/XX" not in key`): 'mse_x10[0/]' is a METHOD/METRIC pattern (its '/' in a character class), which
    'planesweep/mse_x100' does not match, so the record gets the tolerance of no match, 0; read as a metric-id
    pattern it would match 'mse_x100' and give 0.3."""
    path = tmp_path / "golden.json"
    make_golden(_results((SCENE, "mse_x100", 2.0)), {"mse_x10[0/]": 0.3}, path)
    assert [(g.key, g.tolerance) for g in read_golden(path)] == [((METHOD, SCENE, "mse_x100"), 0.0)]


@pytest.mark.parametrize("source", [None, SOURCE])
def test_make_golden_refuses_to_write_nothing_by_default_naming_where_it_came_from(tmp_path, source):
    """Kills `allow_empty: bool = False` -> `True` (an empty golden file written by default), the rewording of
    the refusal, and the file it names (`source` when given, else the golden file: `source` negated, `and
    False`, `or True`, the path dropped or None). Every record non-finite is the same as none."""
    path = tmp_path / "golden.json"
    named = SOURCE if source is not None else path
    for results in (Results(records=[]), _results((SCENE, "mse_x100", float("nan")))):
        with pytest.raises(DataError) as info:
            make_golden(results, 0.0, path, source=source)
        assert str(info.value) == f"{named}: {EMPTY}"
        assert info.value.path == named
        assert not path.exists()
    assert make_golden(Results(records=[]), 0.0, path, source=source, allow_empty=True) == 0
    assert path.read_text(encoding="utf-8") == "[]\n"


def test_make_golden_names_the_source_of_duplicates_when_given(tmp_path):
    """Kills check_unique given the golden file although `source` was given (`source is not None and False`):
    a duplicate is a fault of the results, so the error names the results file."""
    path = tmp_path / "golden.json"
    twice = _results((SCENE, "mse_x100", 1.0), (SCENE, "mse_x100", 2.0))
    with pytest.raises(DataError) as info:
        make_golden(twice, 0.0, path, source=SOURCE)
    assert str(info.value) == f"{SOURCE}: record planesweep/synth_0/mse_x100 appears twice"
    assert info.value.path == SOURCE and not path.exists()


# --------------------------------------------------------------------------- compare


def test_compare_passes_fail_on_new_on(tmp_path):
    """Kills compare dropping `fail_on_new` (left out of check's call, or passed as None): a record absent
    from the golden file fails when asked to, and only then."""
    path = tmp_path / "golden.json"
    make_golden(_results((SCENE, "mse_x100", 2.0)), 0.0, path)
    golden = read_golden(path)
    new = _results((SCENE, "mse_x100", 2.0), (SCENE, "q25_x100", 1.0))
    expected = "NEW      planesweep/synth_0/q25_x100: 1 is not in the golden file"
    assert [(f.kind, f.failed, f.message) for f in compare(golden, new, fail_on_new=True)] == [
        ("new", True, expected)]
    assert [(f.kind, f.failed, f.message) for f in compare(golden, new)] == [("new", False, expected)]


# --------------------------------------------------------------------------- GateResult.summary


def test_summary_of_a_gate_that_compared_nothing_says_whether_that_was_intended():
    """Kills the summary's `if self.allow_empty` made always False or always True: with allow_empty the line
    says comparing nothing was intended (and OK), without it that the gate cannot pass (and FAIL)."""
    new = _results((SCENE, "mse_x100", 2.0))
    intended = check([], new, allow_empty=True)
    assert intended.passed
    assert intended.summary() == ("OK: 0 compared, 0 regressions, 0 improved beyond tolerance, 1 new records not in "
                                  "the golden file -- nothing was compared (the golden file holds no records): "
                                  "intended with --allow-empty")
    refused = check([], new)
    assert not refused.passed
    assert refused.summary() == ("FAIL: 0 compared, 0 regressions, 0 improved beyond tolerance, 1 new records not "
                                 "in the golden file -- nothing was compared (the golden file holds no records), so "
                                 "the gate cannot pass (--allow-empty if intended)")


# --------------------------------------------------------------------------- GateResult.stale_hint


def _gate(tmp_path, n: int):
    """A passing gate with ``n`` records better than golden beyond the tolerance (scenes s0, s1, ...)."""
    path = tmp_path / "golden.json"
    make_golden(_results(*((f"s{i}", "mse_x100", 2.0) for i in range(n))), 0.1, path)
    result = check(read_golden(path), _results(*((f"s{i}", "mse_x100", 1.0) for i in range(n))))
    assert result.passed
    return result


def _names(n: int) -> str:
    return ", ".join(f"planesweep/s{i}/mse_x100" for i in range(n))


def test_stale_hint_defaults_name_golden_and_new_and_show_five(tmp_path):
    """Kills stale_hint's default file names changed ("GOLDEN" -> "XXGOLDENXX" / "golden", "NEW" -> "XXNEWXX" /
    "new") and its default `shown` 5 -> 6: six records better, the first five named, "and 1 more"."""
    assert _gate(tmp_path, 6).stale_hint() == (
        f"hint: the golden file is stale: 6 records better than golden by more than the tolerance ({_names(5)} "
        "and 1 more); if the improvement is meant, refresh it with `lfbench regress GOLDEN NEW --update`")


def test_stale_hint_names_all_when_exactly_shown_are_better(tmp_path):
    """Kills `len(better) > shown` -> `>=`: exactly five better (the default shown) are all named, with no
    "and 0 more"."""
    assert _gate(tmp_path, 5).stale_hint("g.json", "n.json") == (
        f"hint: the golden file is stale: 5 records better than golden by more than the tolerance ({_names(5)}); "
        "if the improvement is meant, refresh it with `lfbench regress g.json n.json --update`")


def test_stale_hint_of_one_record_is_singular(tmp_path):
    """Kills the plural made unconditional (`len(better) != 1 or True`) and the singular's empty suffix
    replaced ('' -> 'XXXX'): one record better reads "1 record better"."""
    assert _gate(tmp_path, 1).stale_hint(Path("golden.json"), Path("results.json")) == (
        "hint: the golden file is stale: 1 record better than golden by more than the tolerance "
        "(planesweep/s0/mse_x100); if the improvement is meant, refresh it with "
        "`lfbench regress golden.json results.json --update`")
