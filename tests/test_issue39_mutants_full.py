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
from lfbench.utils.errors import LFBenchError, SpecError
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
