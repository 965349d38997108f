"""A signed metric (a bias: the mean signed error) is best at 0 (issue 38): rankings, the regression gate and
ablation verdicts compare its magnitude, so -0.5 is worse than 0.1, never "an improvement"."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfbench.results import Record, Results
from lfbench.scoring.base import ANY_VALUE, NON_NEGATIVE, Metric


def _bias(gt, pred, mask=None, *, toolkit=False, **_):
    keep = np.ones(gt.shape, bool) if mask is None else mask
    return float(np.mean((pred - gt)[keep]))


BIAS = Metric(id="bias_signed", name="Bias", description="Mean signed disparity error (px).", unit="px", fn=_bias,
              signed=True, value_range=ANY_VALUE)


@pytest.fixture
def registered(monkeypatch):
    """BIAS in the process-wide registry for this test only."""
    from lfbench.scoring.metrics import METRICS

    METRICS.all()  # the entry points loaded before the copy
    for attr in ("_objects", "_entries", "_aliases", "load_errors"):
        monkeypatch.setattr(METRICS, attr, dict(getattr(METRICS, attr)))
    METRICS.register(BIAS)
    return BIAS


def test_a_signed_metric_is_better_closer_to_zero():
    assert BIAS.direction == "closer to 0 is better" and not BIAS.lower_is_better
    assert [BIAS.badness(v) for v in (-0.5, 0.1, 0.0)] == [0.5, 0.1, 0.0]
    assert math.isnan(BIAS.badness(math.nan))
    assert BIAS.worst_end(-0.7, 0.2) == -0.7 and BIAS.worst_end(-0.1, 0.3) == 0.3
    mse = Metric(id="m", name="m", description="", unit="", fn=_bias)
    assert mse.badness(-0.5) == -0.5 and mse.worst_end(1.0, 2.0) == 2.0 and mse.direction == "lower is better"
    higher = Metric(id="h", name="h", description="", unit="", fn=_bias, higher_is_better=True)
    assert higher.badness(3.0) == -3.0 and higher.worst_end(1.0, 2.0) == 1.0
    with pytest.raises(ValueError, match="signed metric"):  # no value below 0: it cannot be signed
        Metric(id="b", name="b", description="", unit="", fn=_bias, signed=True, value_range=NON_NEGATIVE)


def test_a_signed_metric_ranks_by_magnitude(registered):
    from lfbench.reports.leaderboard import metric_ranks

    results = Results([Record("under", "s", "bias_signed", -0.5, "lowres"),
                       Record("over", "s", "bias_signed", 0.1, "lowres"),
                       Record("far", "s", "bias_signed", 0.8, "lowres")])
    ranks = metric_ranks(results, "bias_signed").set_index("method")["rank"]
    assert ranks.to_dict() == {"over": 1.0, "under": 2.0, "far": 3.0}


def test_regress_does_not_call_a_larger_bias_an_improvement(registered):
    from lfbench.runs.regress import GoldenRecord, check

    def kinds(old: float, new: float) -> list[str]:
        golden = [GoldenRecord("m", "s", "bias_signed", old, 0.05, "lowres")]
        return [f.kind for f in check(golden, Results([Record("m", "s", "bias_signed", new, "lowres")])).findings]

    assert kinds(0.1, -0.5) == ["worse"]  # |-0.5| > |0.1|: lower, yet worse
    assert kinds(-0.5, 0.1) == ["better"]
    assert kinds(0.1, -0.12) == []  # the magnitude moved 0.02, within the tolerance, though the value moved 0.22


def test_ablation_verdicts_and_best_cell_use_the_magnitude(registered):
    from lfbench.ablation.baselines import BEATS, NOT_BEATEN, verdict

    assert verdict({("bias_signed", "g"): (0.1, math.nan)}, {("bias_signed", "g"): -0.5}, seeds=False) == BEATS
    assert verdict({("bias_signed", "g"): (-0.5, math.nan)}, {("bias_signed", "g"): 0.1},
                   seeds=False).startswith(NOT_BEATEN)
