"""The toolkit's Runtime (runtime, runtime_log) and Quantile(p) metrics (issue 20, fidelity), checked
against their definitions in the toolkit (general_metrics.py: Runtime reads runtimes/<scene>.txt's first
line as a float, log10 for runtime_log; Quantile(p) is 100 x the |error| at index int(n p / 100) of the
sorted errors) with values worked out by hand."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from helpers import run_cli, write_scene, write_submission

from lfbench.data.submission import read_runtime, write_submission_map
from lfbench.scoring.metrics import (
    GENERAL_METRICS,
    METRICS,
    RUNTIME_METRICS,
    OrderStatistic,
    get_metric,
    quantile_metric,
)
from lfbench.utils.errors import DataError, SpecError

# 20 absolute errors, already sorted: 0.00, 0.01, ..., 0.19 px
ERRORS = np.arange(20, dtype=np.float32) / np.float32(100)
GT = np.zeros((4, 5), np.float32)
PRED = ERRORS.reshape(4, 5)[::-1].copy()  # any order: the metric sorts


@pytest.mark.parametrize(("p", "index"), [(50, 10), (90, 18), (2.5, 0), (25, 5), (99, 19), (0, 0), (12.5, 2)])
def test_quantile_family_is_the_element_at_int_n_p_over_100(p, index):
    metric = get_metric(f"q{p:g}_x100")
    assert metric.id == f"q{p:g}_x100" and metric.name == f"Q{p:g}" and metric.unit == "px x 100"
    assert metric.bootstrap == OrderStatistic(float(p)) and metric.category == "general"
    assert metric(GT, PRED) == pytest.approx(100 * float(ERRORS[index]), rel=1e-6)
    assert quantile_metric(p).id == metric.id


def test_quantile_ids_follow_the_toolkit():
    assert get_metric("q_50_100").id == "q50_x100" and get_metric("q50_x100").toolkit_id == "q_50_100"
    assert get_metric("q_25_100") is get_metric("q25_x100") is quantile_metric(25)  # Q25 stays one metric
    assert get_metric("q2.5_x100").toolkit_id is None  # the toolkit's ids hold whole percentages only
    for bad in ("q100_x100", "q50", "q-5_x100", "q05_x100", "q50.0_x100", "qnan_x100", "q1e1_x100"):
        assert METRICS.find(bad) is None, bad
    with pytest.raises(SpecError, match=r"Unknown metric 'q100_x100'\. Available: .*q<p>_x100"):
        get_metric("q100_x100")
    with pytest.raises(ValueError, match="from 0 to below 100"):
        quantile_metric(100)


def test_quantile_nonfinite_predictions_default_and_toolkit():
    pred = PRED.copy()
    pred[0, 0] = np.nan  # one of the 20 errors becomes non-finite
    q90 = get_metric("q90_x100")
    # default: an infinite error, sorted last; the 19 finite ones keep their order, index 18 is the largest one
    finite = np.sort(np.abs(pred[np.isfinite(pred)]))
    assert q90(GT, pred) == pytest.approx(100 * float(finite[18]), rel=1e-6)
    # toolkit: left out, 19 errors, index int(19 * 0.9) = 17
    assert q90(GT, pred, toolkit=True) == pytest.approx(100 * float(finite[17]), rel=1e-6)


def test_runtime_metrics_are_the_reported_runtime_and_its_log10():
    runtime, log = get_metric("runtime"), get_metric("runtime_log")
    assert RUNTIME_METRICS == (runtime, log) and not set(RUNTIME_METRICS) & set(GENERAL_METRICS)
    assert runtime.toolkit_id == "runtime" and log.toolkit_id == "runtime_log" and runtime.unit == "s"
    assert runtime.category == log.category == "runtime" and runtime.bootstrap is None
    assert runtime.score_runtime(5.82449) == 5.82449
    assert log.score_runtime(5.82449) == pytest.approx(0.765258, abs=1e-6)  # log10(5.82449) = 0.7652579...
    assert log.score_runtime(0.01) == pytest.approx(-2.0)  # negative below 1 s
    for none in (None, float("nan"), 0.0, -1.0, float("inf")):
        assert runtime.score_runtime(none) is None and log.score_runtime(none) is None
    with pytest.raises(TypeError, match="scored from a runtime"):
        runtime(GT, PRED)
    with pytest.raises(TypeError, match="scored from maps"):
        get_metric("mse_x100").score_runtime(1.0)
    assert runtime.value_range == (0.0, math.inf) and log.value_range == (-math.inf, math.inf)


@pytest.mark.parametrize(("text", "value"), [("5.82449", 5.82449), ("  2.5  \n9\n", 2.5), ("2.5e-1\r\n", 0.25),
                                             ("nan\n", None), ("0\n", 0.0), ("-3", -3.0)])
def test_runtime_files_are_read_as_the_toolkit_reads_them(tmp_path, text, value):
    """The toolkit: float(f.readline()). What follows the first line is ignored; the value is returned as
    written (the runtime metrics leave non-positive and NaN runtimes out)."""
    path = tmp_path / "scene.txt"
    path.write_text(text)
    got = read_runtime(path)
    assert math.isnan(got) if value is None else got == value


@pytest.mark.parametrize(("text", "problem"), [("", "not a number"), ("\n2.5\n", "not a number"),
                                               ("fast\n", "not a number"), ("1" * 5000, "larger than 4096 bytes")])
def test_unreadable_runtime_files_are_one_line(tmp_path, text, problem):
    path = tmp_path / "scene.txt"
    path.write_text(text)
    with pytest.raises(DataError, match=problem) as info:
        read_runtime(path)
    assert str(path) in str(info.value) and "fast" not in str(info.value)  # never echo file content


def _submission(tmp_path, runtimes: dict[str, str | None]):
    """Two scenes a and b; the submission's runtime files as given (None: no file)."""
    data = tmp_path / "data"
    for name in runtimes:
        write_scene(data, name, "training", size=32)
    sub = write_submission(tmp_path / "sub", {name: np.ones((32, 32), np.float32) for name in runtimes},
                           {name: text or "" for name, text in runtimes.items()})
    for name, text in runtimes.items():
        if text is None:
            (sub / "runtimes" / f"{name}.txt").unlink()
    return data, sub


def _records(out) -> dict[tuple[str, str], float]:
    data = json.loads((out / "results.json").read_text())
    return {(r["scene"], r["metric"]): r["value"] for r in data["records"]}


def test_evaluate_all_metrics_records_runtimes_where_the_submission_has_them(tmp_path, capsys):
    data, sub = _submission(tmp_path, {"a": "3.5\n", "b": None, "c": "0\n"})
    rc, _, err = run_cli(capsys, "evaluate", "--data", data, "--method", f"published:path={sub}", "--all-metrics",
                         "--out", tmp_path / "out", "--no-progress")
    assert rc == 0, err
    records = _records(tmp_path / "out")
    assert records[("a", "runtime")] == 3.5
    assert records[("a", "runtime_log")] == pytest.approx(math.log10(3.5), abs=1e-15)
    for scene in ("b", "c"):  # no runtime file / a runtime of 0: absent, not NaN; the maps are still scored
        assert (scene, "runtime") not in records and (scene, "runtime_log") not in records
        assert (scene, "badpix_0.07") in records and (scene, "mse_x100") in records
    runs = {r["scene"]: r for r in json.loads((tmp_path / "out" / "results.json").read_text())["runs"]}
    assert any("runtime 0 s is not a positive number" in n for n in runs["c"]["notes"])


def test_default_runs_have_no_runtime_records(tmp_path, capsys):
    """Runtimes are not general metrics: default results (and the golden records) are unchanged."""
    data, sub = _submission(tmp_path, {"a": "3.5\n"})
    rc, _, err = run_cli(capsys, "evaluate", "--data", data, "--method", f"published:path={sub}", "--out",
                         tmp_path / "out", "--no-progress")
    assert rc == 0, err
    assert {m for _, m in _records(tmp_path / "out")} == {m.id for m in GENERAL_METRICS}


def test_saved_maps_get_no_made_up_runtime(tmp_path, capsys):
    """A method that reports no runtime used to get runtimes/<scene>.txt = 1e-9 s in its saved maps."""
    data, sub = _submission(tmp_path, {"a": "3.5\n", "b": None})
    rc, _, err = run_cli(capsys, "evaluate", "--data", data, "--method", f"published:path={sub}", "--save-maps",
                         "--out", tmp_path / "out", "--no-progress")
    assert rc == 0, err
    maps = next((tmp_path / "out" / "maps").iterdir())
    assert read_runtime(maps / "runtimes" / "a.txt") == 3.5
    assert (maps / "disp_maps" / "b.pfm").is_file() and not (maps / "runtimes" / "b.txt").exists()
    write_submission_map(tmp_path / "direct", "x", np.zeros((2, 2), np.float32), float("nan"))
    assert not (tmp_path / "direct" / "runtimes").exists()


def test_published_subfocal_runtime_on_real_backgammon(hci_root, shared_data, tmp_path, capsys):
    published = shared_data / "published" / "subfocal"
    if not (published / "runtimes" / "backgammon.txt").is_file():
        pytest.skip("no published SubFocal runtimes beside the HCI data")
    rc, _, err = run_cli(capsys, "evaluate", "--data", hci_root, "--scenes", "backgammon", "--method",
                         f"published:path={published}", "--all-metrics", "--out", tmp_path / "out", "--no-progress")
    assert rc == 0, err
    records = _records(tmp_path / "out")
    assert records[("backgammon", "runtime")] == 5.82449  # the file says 5.82449
    assert records[("backgammon", "runtime_log")] == pytest.approx(0.7652579, abs=1e-7)
