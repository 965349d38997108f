"""Seeds and significance of ablations: ``seeds = [...]`` expansion, t-intervals, paired t-tests and the
verdicts on the paper's orderings, all on hand-made numbers (no training)."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest
from test_ablate import quiet, write_spec

from lfbench.ablation import report
from lfbench.ablation.facts import cell_info
from lfbench.ablation.significance import comparisons, paired_t, seeds_table, significance_table, t_interval
from lfbench.ablation.spec import load_spec
from lfbench.reports.reference import default_reference
from lfbench.results import Record, Results
from lfbench.utils.errors import SpecError


def _declared(table_id: str):
    """The shipped reference's declaration of ``table_id`` and its axes (what the report reads)."""
    table = default_reference().table(table_id)
    return table, tuple(table.join)


T975_DF2 = 4.302652729911275  # Student t 0.975 quantile, 2 degrees of freedom (printed tables: 4.303)


def test_t_interval_by_hand():
    mean, low, high = t_interval([1.0, 2.0, 3.0])  # sd 1, n 3
    half = T975_DF2 / math.sqrt(3)
    assert (mean, low, high) == pytest.approx((2.0, 2.0 - half, 2.0 + half), rel=1e-9)
    assert t_interval([4.0])[0] == 4.0 and math.isnan(t_interval([4.0])[1])
    assert all(math.isnan(x) for x in t_interval([]))


def test_paired_t_by_hand():
    # d = worse - better = 2, 3, 2: mean 7/3, sd 1/sqrt(3), t = 7; with 2 degrees of freedom the t tail has the
    # closed form P(T > t) = (1 - t / sqrt(t^2 + 2)) / 2, so p = 1 - 7 / sqrt(51).
    r = paired_t([10.0, 12.0, 11.0], [12.0, 15.0, 13.0])
    assert r["n"] == 3 and r["mean_diff"] == pytest.approx(7 / 3)
    assert r["t"] == pytest.approx(7.0)
    assert r["p"] == pytest.approx(1 - 7 / math.sqrt(51), rel=1e-9)
    assert r["low"] == pytest.approx(7 / 3 - T975_DF2 / 3) and r["high"] == pytest.approx(7 / 3 + T975_DF2 / 3)
    flipped = paired_t([12.0, 15.0, 13.0], [10.0, 12.0, 11.0])
    assert flipped["t"] == pytest.approx(-7.0) and flipped["p"] == pytest.approx(r["p"])
    constant = paired_t([1.0, 2.0], [2.0, 3.0])  # every difference 1: no spread
    assert constant["p"] == 0.0 and constant["mean_diff"] == 1.0
    assert math.isnan(paired_t([1.0], [2.0])["p"])


SEEDS_GRID = """seeds = [1, 2, 3]
table = "table4"
[[grid]]
interval = [1, 0.5, 0.25, 0.1]
"""


def _spec(tmp_path: Path, head: str = SEEDS_GRID, tail: str = ""):
    return load_spec(write_spec(tmp_path, head, tail))


def test_seeds_expand_every_cell_and_set_the_config_seed(tmp_path):
    spec = _spec(tmp_path)
    assert spec.seeds == (1, 2, 3) and len(spec.cells) == 12
    assert spec.cells[0].id == "interval=1_seed=1" and spec.cells[5].id == "interval=0.5_seed=3"
    assert [c.config["seed"] for c in spec.cells[:3]] == [1, 2, 3]
    table4, axes = _declared("table4")
    info = cell_info(spec, axes)
    assert list(info.loc[["interval=0.25_seed=2"], "variant"]) == ["interval=0.25"]
    comps = comparisons(table4, info)
    assert [(c.better, c.worse) for c in comps] == [("interval=0.5", "interval=1"), ("interval=0.25", "interval=0.5"),
                                                   ("interval=0.1", "interval=0.25")]


@pytest.mark.parametrize("head,message", [
    ("seeds = [1, 1]\n", "each seed once"),
    ("seeds = [1, -2]\n", r"seeds: expected numbers >= 0, got \[1, -2\]"),
    ("seeds = [1, 2]\n[[grid]]\nseed = [4, 5]\n", "both a grid axis and given by seeds"),
    ("seeds = [1, 2]\n[stage1]\nshared = true\n[[grid]]\nbeta = [0.1, 1]\n", "cannot vary with seeds"),
])
def test_seed_spec_errors(tmp_path, head, message):
    with pytest.raises(SpecError, match=message):
        _spec(tmp_path, head)


def _scores(values: dict[tuple[float, int], tuple[float, float]]) -> pd.DataFrame:
    """(interval, seed) -> (BadPix 0.07 on scene a, on scene b) as the long results frame."""
    rows = []
    for (interval, seed), per_scene in values.items():
        for scene, v in zip(("a", "b"), per_scene, strict=True):
            rows.append({"method": f"interval={interval:g}_seed={seed}", "scene": scene, "metric": "badpix_0.07",
                         "value": v, "resolution": "lowres"})
    return pd.DataFrame(rows)


# Made-up scores. 1 -> 0.5: better by 10, 11, 9 (scene means 50/40, 52/41, 48/39): reproduced, t = 10 sqrt(3).
# 0.5 -> 0.25: +1, -1, 0: not resolved. 0.25 -> 0.1: worse by exactly 2 each seed: reversed (p = 0).
HAND = {(1, 1): (49, 51), (1, 2): (52, 52), (1, 3): (47, 49),
        (0.5, 1): (39, 41), (0.5, 2): (40, 42), (0.5, 3): (38, 40),
        (0.25, 1): (38, 40), (0.25, 2): (41, 43), (0.25, 3): (38, 40),
        (0.1, 1): (40, 42), (0.1, 2): (43, 45), (0.1, 3): (40, 42)}


def test_significance_verdicts_on_hand_made_scores(tmp_path):
    spec = _spec(tmp_path)
    table4, axes = _declared("table4")
    table = significance_table(table4, cell_info(spec, axes), _scores(HAND)).set_index("worse")
    first = table.loc["interval=1"]
    assert first["better"] == "interval=0.5" and first["seeds"] == 3
    assert first["better mean"] == pytest.approx(40.0) and first["worse mean"] == pytest.approx(50.0)
    assert first["difference (worse - better)"] == pytest.approx(10.0)
    assert first["t"] == pytest.approx(10 * math.sqrt(3))  # d = 10, 11, 9: sd 1
    assert first["verdict"] == "reproduced"
    second = table.loc["interval=0.5"]
    assert second["difference (worse - better)"] == pytest.approx(0.0) and second["verdict"] == "not resolved"
    third = table.loc["interval=0.25"]
    assert third["difference (worse - better)"] == pytest.approx(-2.0) and third["p"] == 0.0
    assert third["verdict"] == "reversed"
    # A seed missing from one side leaves the pair out (2 seeds left); one seed cannot resolve anything.
    partial = {k: v for k, v in HAND.items() if k != (0.1, 3)}
    row = significance_table(table4, cell_info(spec, axes), _scores(partial)).set_index("worse").loc["interval=0.25"]
    assert row["seeds"] == 2
    single = {k: v for k, v in HAND.items() if k[1] == 1}
    rows = significance_table(table4, cell_info(spec, axes), _scores(single))
    assert set(rows["verdict"]) == {"not resolved"} and set(rows["seeds"]) == {1}


def test_seeds_table_means_and_intervals(tmp_path):
    spec = _spec(tmp_path)
    table, clipped = seeds_table(cell_info(spec), _scores(HAND), ["badpix_0.07"])
    row = table.loc["interval=1"]  # scene means 50, 52, 48: mean 50, sd 2
    assert row["seeds"] == 3 and row["badpix_0.07 mean"] == pytest.approx(50.0)
    assert row["badpix_0.07 95% low"] == pytest.approx(50 - T975_DF2 * 2 / math.sqrt(3))
    assert row["badpix_0.07 95% high"] == pytest.approx(50 + T975_DF2 * 2 / math.sqrt(3))
    assert clipped == []  # 50 +- 5 stays inside 0 .. 100 %


T975_DF1 = 12.706204736174696  # scipy.stats.t.ppf(0.975, 1)


def test_seed_intervals_stay_within_the_metric_range(tmp_path):
    """Two seeds far apart: the t-interval (df 1) of BadPix reaches far past 0 and 100 %; the table bounds it
    by the metric's value_range and the caption says so (issue 22.8)."""
    spec = _spec(tmp_path, 'seeds = [1, 2]\ntable = "table4"\n[[grid]]\ninterval = [1, 0.5]\n')
    wide = {(1, 1): (2, 4), (1, 2): (88, 92), (0.5, 1): (40, 42), (0.5, 2): (41, 43)}
    table, clipped = seeds_table(cell_info(spec), _scores(wide), ["badpix_0.07"])
    row = table.loc["interval=1"]  # scene means 3 and 90: mean 46.5, sd 61.52
    half = T975_DF1 * math.sqrt(((3 - 46.5) ** 2 + (90 - 46.5) ** 2) / 1) / math.sqrt(2)
    assert 46.5 - half < 0 and 46.5 + half > 100  # what the bare t-interval gives
    assert row["badpix_0.07 mean"] == pytest.approx(46.5)
    assert (row["badpix_0.07 95% low"], row["badpix_0.07 95% high"]) == (0.0, 100.0)
    narrow = table.loc["interval=0.5"]  # 41 and 42: 41.5 +- 6.35, inside the range, untouched
    assert narrow["badpix_0.07 95% low"] == pytest.approx(41.5 - T975_DF1 * math.sqrt(0.5) / math.sqrt(2))
    assert clipped == ["BadPix(0.07): 0 to 100"]
    results = Results(records=[Record(r.method, r.scene, r.metric, float(r.value), r.resolution)
                               for r in _scores(wide).itertuples()])
    markers = [{"id": c.id, "train_s": 60.0, "own_train_s": 60.0, "test_s": 1.0, "time_size": 16, "device": "cpu",
                "threads": 1} for c in spec.cells]
    report.write_report(spec, tmp_path / "out", results, markers, log=quiet)
    text = (tmp_path / "out" / "table_seeds.md").read_text()
    assert "intervals clipped to the metric's range (BadPix(0.07): 0 to 100)" in text
    lows = pd.read_csv(tmp_path / "out" / "table_seeds.csv")
    assert lows["badpix_0.07 95% low"].min() >= 0 and lows["badpix_0.07 95% high"].max() <= 100


def test_loss_and_beta_orderings(tmp_path):
    spec = _spec(tmp_path, 'seeds = [1, 2]\ntable = "table5"\n[[grid]]\nloss = ["l1", "mse", "uafl"]\n')
    comps = comparisons(_declared("table5")[0], cell_info(spec, _declared("table5")[1]))
    assert [(c.better, c.worse) for c in comps] == [("loss=uafl", "loss=l1"), ("loss=uafl", "loss=mse")]
    spec = _spec(tmp_path, 'seeds = [1, 2]\ntable = "beta"\n[[grid]]\nbeta = [1, 0.5, 0.1]\n')
    comps = comparisons(_declared("beta")[0], cell_info(spec, _declared("beta")[1]))
    assert [(c.better, c.worse) for c in comps] == [("beta=0.1", "beta=1"), ("beta=0.1", "beta=0.5")]


def test_report_writes_seed_tables_and_seed_means(tmp_path):
    spec = _spec(tmp_path)
    frame = _scores(HAND)
    results = Results(records=[Record(method=r.method, scene=r.scene, metric=r.metric, value=float(r.value),
                                      resolution=r.resolution) for r in frame.itertuples()])
    out = tmp_path / "out"
    markers = [{"id": c.id, "train_s": 60.0, "own_train_s": 60.0, "test_s": 1.0, "time_size": 16, "device": "cpu",
                "threads": 1} for c in spec.cells]
    report.write_report(spec, out, results, markers, log=quiet)
    sig = (out / "table_significance.csv").read_text()
    assert "reproduced" in sig and "reversed" in sig and "not resolved" in sig
    seeds = pd.read_csv(out / "table_seeds.csv", comment="#")
    assert set(seeds["variant"]) == {"interval=1", "interval=0.5", "interval=0.25", "interval=0.1"}
    table4 = (out / "table4.md").read_text()
    assert "| interval=1 " in table4 and "_seed=" not in table4 and "mean over seeds 1, 2, 3" in table4


@pytest.mark.slow
def test_an_ablation_with_seeds_and_init_runs_end_to_end(tmp_path):
    import torch
    from lfbench_methods.subfocal.network import SubFocalNet

    from lfbench.ablation.runner import run_ablation
    from lfbench.training import checkpoint as ckpt

    torch.manual_seed(0)
    weights = tmp_path / "trained.pt"
    ckpt.export_weights(weights, SubFocalNet(width=2, interval=1.0))
    head = ('seeds = [1, 2]\ntable = "beta"\n[set]\ninit = "' + str(weights) + '"\n'
            '"stages" = [{ name = "finetune", loss = "uafl", beta = 0.1, lr = 1e-4, steps = 1 }]\n'
            '[[grid]]\nbeta = [1.0, 0.1]\n')
    spec = load_spec(write_spec(tmp_path / "spec", head))
    assert [c.id for c in spec.cells] == ["beta=1_seed=1", "beta=1_seed=2", "beta=0.1_seed=1", "beta=0.1_seed=2"]
    out = tmp_path / "out"
    run_ablation(spec, out, jobs=1, progress=False, log=quiet)
    final = ckpt.load(out / "cells" / "beta=0.1_seed=2" / "final.pt")
    assert final["training"]["init"]["path"] == str(weights)
    sig = pd.read_csv(out / "table_significance.csv", comment="#")
    assert list(sig["better"]) == ["beta=0.1"] and list(sig["seeds"]) == [2]
    assert sig["verdict"].iloc[0] in ("reproduced", "reversed", "not resolved")
