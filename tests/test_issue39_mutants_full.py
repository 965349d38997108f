"""Tests that must fail (issue 39 item 6): what the first full ``nox -s mutation`` over the committed configuration
left, that the rounds on single files could not see (their selections did not reach these functions).

Each test names the class of mutants it kills; every expected value is written out. In-process, no pool, no CLI.
Results: results/mutation/README.md ("The full run") and results/mutation/issue39/README.md.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from lfbench.scoring.base import ANY_VALUE, Metric, MetricRegistry
from lfbench.scoring.pixelwise import plugin_failure
from lfbench.utils.errors import DataError, LFBenchError, SpecError
from lfbench.utils.registry import NameTaken


def _mean_error(gt, pred, mask=None, *, toolkit=False, **_):
    return float(np.mean(pred - gt))


def _metric(**kwargs) -> Metric:
    return Metric(id="m", name="m", description="", unit="px", fn=_mean_error, **kwargs)


def test_worst_end_of_each_kind_of_metric():
    """Mutants of Metric.worst_end (no test of the selection reached it: the ablation's baselines table uses
    it): lower is better -> high, higher is better -> low, signed -> the end farther from 0, ``high`` on a
    tie of magnitudes (``>=`` for ``>``), whichever sign each end has."""
    lower, higher, signed = _metric(), _metric(higher_is_better=True), _metric(signed=True, value_range=ANY_VALUE)
    assert (lower.worst_end(1.0, 2.0), lower.worst_end(-3.0, 2.0)) == (2.0, 2.0)
    assert (higher.worst_end(1.0, 2.0), higher.worst_end(-3.0, 2.0)) == (1.0, -3.0)
    assert signed.worst_end(-0.7, 0.2) == -0.7
    assert signed.worst_end(-0.1, 0.3) == 0.3
    assert signed.worst_end(0.4, 0.9) == 0.9
    assert signed.worst_end(-0.9, -0.4) == -0.9
    assert signed.worst_end(-0.5, 0.5) == 0.5


def test_plugin_failure_is_one_line_naming_the_plugin():
    """Mutants of plugin_failure's message: the plugin's name, 'failed', the exception's type and first line."""
    error = plugin_failure("plug_mod.sample", RuntimeError("boom\nsecond line"))
    assert type(error) is LFBenchError
    assert str(error) == "metric plugin plug_mod.sample failed: RuntimeError: boom"
    assert str(plugin_failure("p.score", MemoryError())) == "metric plugin p.score failed: MemoryError"


def test_a_taken_metric_id_is_refused_and_stays_refused():
    """Mutants of MetricRegistry.name_taken: a SpecError naming the entry point, what it points to and the
    collision, raised now and kept (``_refused``) for every later lookup."""
    registry = MetricRegistry()
    entry_point = SimpleNamespace(name="badpix_0.07", value="plug_mod:PLUG")
    taken = NameTaken("metric 'badpix_0.07' is already registered by lfbench")
    with pytest.raises(SpecError) as raised:
        registry.name_taken(entry_point, taken)
    said = ("metric plugin 'badpix_0.07' (plug_mod:PLUG) refused: metric 'badpix_0.07' is already registered by "
            "lfbench")
    assert str(raised.value) == said
    assert registry._refused is raised.value


# --------------------------------------------------------------------------- the metrics a run scores


def _general_and_region():
    from lfbench.scoring.metrics import METRICS, list_metrics

    general = [*(m.id for m in list_metrics("general")), *METRICS.family_patterns]
    region = next(m for m in list_metrics("region") if m.pixelwise is None)
    return general, region


def test_scored_metrics_of_a_protocol_file_and_of_the_command_line(tmp_path):
    """Mutants of scored_metrics: a protocol file's unknown or non-general id is a DataError naming the file
    (found, not looked up: `find`/`get_metric` swapped, `and`/`or`), without a file an unknown id is the
    registry's SpecError; --metrics' unknown id lists the general metrics and the families only, a region metric
    there is refused naming its category; two asked-for metrics are both scored (`setdefault(None, ...)`)."""
    from lfbench.scoring.metrics import scored_metrics

    general, region = _general_and_region()
    toml = tmp_path / "lfbench-dataset.toml"
    for bad in ("nope", region.id):
        with pytest.raises(DataError) as raised:
            scored_metrics([bad], source=toml)
        assert str(raised.value) == (f"{toml}: 'protocol.metrics': {bad!r} is not a general metric (e.g. badpix_0.07, "
                                     "mse_x100, q25_x100)")
    with pytest.raises(SpecError, match=r"^Unknown metric 'nope'\. Available: "):
        scored_metrics(["nope"])
    with pytest.raises(SpecError) as raised:
        scored_metrics(["mse_x100"], extra=["nope"])
    assert str(raised.value) == f"--metrics: Unknown metric 'nope'. Available: {', '.join(general)}"
    assert region.id not in general and "badpix_<t>" in " ".join(general) and "mse_x100" in general
    with pytest.raises(SpecError) as raised:
        scored_metrics([], extra=[region.id])
    assert str(raised.value) == (f"--metrics: {region.id!r} is a region metric (scored with --all-metrics where the "
                                 f"scene supports it); --metrics takes general metrics: {', '.join(general)}")
    chosen = scored_metrics(["badpix_0.07", "mse_x100"], source=toml, extra=["q25_x100", "mse_x100", "badpix_0.03"])
    assert [m.id for m in chosen] == ["badpix_0.07", "mse_x100", "q25_x100", "badpix_0.03"]


def test_badpix_threshold_of_unknown_and_non_pixelwise_metrics():
    """Mutants of badpix_threshold's guard (`and False`, `and` for `or`): an unknown id and a metric without a
    pixel sample have no threshold (no AttributeError); a BadPix id has its own."""
    from lfbench.scoring.metrics import badpix_threshold

    _, region = _general_and_region()
    assert badpix_threshold("nope") is None and badpix_threshold(region.id) is None
    assert badpix_threshold("badpix_0.03") == 0.03 and badpix_threshold("mse_x100") is None


def test_a_border_that_leaves_no_pixel_is_refused_naming_the_scene(tmp_path):
    """Mutants of ScoringRules.check_border's error: the message and the scene's folder as its path."""
    from helpers import write_scene

    from lfbench.data.hci import HCIScene
    from lfbench.scoring.rules import ScoringRules

    path = write_scene(tmp_path, "tiny", size=40)
    scene = HCIScene(path)
    ScoringRules(border_px=19).check_border([scene])
    with pytest.raises(DataError) as raised:
        ScoringRules(border_px=20).check_border([scene])
    assert raised.value.path == path
    assert str(raised.value) == (f"{path}: the scoring border of 20 px (the dataset's protocol) leaves no pixel of "
                                 "this scene's 40x40 px views to score")
