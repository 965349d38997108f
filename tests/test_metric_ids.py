"""One spelling per metric id (issue 31, class 7): the families ``badpix_<t>`` and ``q<p>_x100`` accept the id a
metric has (``f"badpix_{t:g}"``, ``f"q{p:g}_x100"``) and the toolkit's id of it, and refuse every other spelling
of the same number as an unknown metric, so that a golden record under another spelling is refused rather than
read as a metric of its own (and then reported as MISSING)."""

from __future__ import annotations

import json

import pytest

from lfbench.cli import main
from lfbench.results import Record, Results
from lfbench.scoring.metrics import METRICS, get_metric
from lfbench.utils.errors import SpecError

CANONICAL = {
    "badpix_0.07": ("badpix_0.07", 0.07), "badpix_0070": ("badpix_0.07", 0.07),
    "badpix_0.1": ("badpix_0.1", 0.1), "badpix_0100": ("badpix_0.1", 0.1),
    "badpix_0.015": ("badpix_0.015", 0.015), "badpix_0015": ("badpix_0.015", 0.015),
    "badpix_0.5": ("badpix_0.5", 0.5), "badpix_1": ("badpix_1", 1.0), "badpix_1000": ("badpix_1", 1.0),
    "q50_x100": ("q50_x100", 50.0), "q_50_100": ("q50_x100", 50.0), "q12.5_x100": ("q12.5_x100", 12.5),
    "q25_x100": ("q25_x100", 25.0), "q_25_100": ("q25_x100", 25.0), "q0_x100": ("q0_x100", 0.0),
}

OTHER_SPELLINGS = [
    "badpix_0.0700", "badpix_ 0.07", "badpix_0.07 ", "badpix_.07", "badpix_0.070", "badpix_7e-2", "badpix_0.7e-1",
    "badpix_070", "badpix_+0.07", "badpix_0.0_7", "badpix_-0", "badpix_\u0660.\u0660\u0667",
    "badpix_\uff10.\uff10\uff17", "badpix_\u0660\u0660\u0667\u0660", "badpix_0.1000", "badpix_0.10", "badpix_0.0150",
    "badpix_1.0", "badpix_01", "q050_x100", "q50.0_x100", "q_05_100", "q12.50_x100", "q\u0665\u0660_x100",
    "q_\u0665\u0660_100", "q 50_x100", "q12.5_100", "q_12.5_100",
]


@pytest.mark.parametrize("metric_id", sorted(CANONICAL))
def test_the_id_and_the_toolkit_id_name_the_metric(metric_id):
    canonical, number = CANONICAL[metric_id]
    metric = get_metric(metric_id)
    assert metric.id == canonical
    definition = metric.pixelwise  # BadPix: its sample's threshold (px); a quantile: its family's percentage
    named = getattr(definition.sample, "threshold", None)
    assert (named if named is not None else definition.family.percentage) == pytest.approx(number)
    assert metric_id in (metric.id, metric.toolkit_id)


def test_the_families_spell_their_ids_as_documented():
    assert [get_metric(f"badpix_{t:g}").id for t in (0.07, 0.1, 0.015)] == ["badpix_0.07", "badpix_0.1", "badpix_0.015"]
    assert [get_metric(f"badpix_{t:g}").toolkit_id for t in (0.07, 0.1, 0.015)] == ["badpix_0070", "badpix_0100",
                                                                                   "badpix_0015"]
    assert [get_metric(f"q{p:g}_x100").id for p in (50, 12.5)] == ["q50_x100", "q12.5_x100"]
    assert get_metric("q50_x100").toolkit_id == "q_50_100" and get_metric("q12.5_x100").toolkit_id is None
    assert get_metric("badpix_70").pixelwise.sample.threshold == 70.0  # a whole threshold in px, not the toolkit's 0.07


@pytest.mark.parametrize("metric_id", OTHER_SPELLINGS)
def test_any_other_spelling_is_an_unknown_metric(metric_id):
    assert METRICS.find(metric_id) is None
    with pytest.raises(SpecError, match="Unknown metric"):
        get_metric(metric_id)


@pytest.mark.parametrize("metric_id", ["badpix_0.0700", "badpix_ 0.07", "badpix_\u0660.\u0660\u0667", "q050_x100"])
def test_a_golden_record_under_another_spelling_is_an_unknown_metric_not_missing(tmp_path, capsys, metric_id):
    golden = tmp_path / "golden.json"
    golden.write_text(json.dumps([{"method": "planesweep", "scene": "synth_0", "metric": metric_id, "value": 5.0,
                                   "tolerance": 0.01, "resolution": "lowres"}]), encoding="utf-8")
    Results(records=[Record("planesweep", "synth_0", "badpix_0.07", 5.0, "lowres"),
                     Record("planesweep", "synth_0", "q50_x100", 5.0, "lowres")]).write(tmp_path / "new")
    assert main(["regress", str(golden), str(tmp_path / "new")]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and f"unknown metric {metric_id!r}" in err[0] and str(golden) in err[0], err
    assert "MISSING" not in captured.out
