"""Bootstrap CIs and paired tests (lfbench.scoring.stats) against independent references: lfbench.scoring.metrics,
exact enumeration of tiny bootstraps, analytic variances, known distributions, hand-computed p-values."""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats as sps

from lfbench.reports.ci import ci_table
from lfbench.results import Record, Results
from lfbench.scoring import stats
from lfbench.scoring.metrics import bad_pix, mse_x100, q25_x100
from lfbench.utils.errors import SpecError

METRICS = ("badpix_0.07", "badpix_0.01", "mse_x100", "q25_x100")


def _maps(seed=0, size=40, sigma=0.05):
    rng = np.random.default_rng(seed)
    gt = rng.uniform(-1.5, 1.5, (size, size)).astype(np.float32)
    pred = gt + (rng.standard_normal((size, size)) * sigma).astype(np.float32)
    return gt, pred


# --------------------------------------------------------------------------- estimates

@pytest.mark.parametrize("toolkit", [False, True])
def test_estimate_equals_metrics_module(toolkit):
    gt, pred = _maps()
    pred[3, 4], pred[10, 10], pred[20, 5] = np.nan, np.inf, -np.inf
    gt[7, 7] = np.nan
    mask = np.zeros(gt.shape, bool)
    mask[2:-2, 2:-2] = True
    refs = {"badpix_0.07": bad_pix(gt, pred, 0.07, mask, toolkit=toolkit),
            "badpix_0.01": bad_pix(gt, pred, 0.01, mask, toolkit=toolkit),
            "mse_x100": mse_x100(gt, pred, mask, toolkit=toolkit),
            "q25_x100": q25_x100(gt, pred, mask, toolkit=toolkit)}
    for metric, ref in refs.items():
        ci = stats.bootstrap_metric(gt, pred, mask, metric, n=200, toolkit=toolkit)
        assert ci.estimate == ref, metric
        assert ci.low <= ci.estimate <= ci.high
        assert stats.metric_from_errors(stats.scored_errors(gt, pred, mask, toolkit=toolkit), metric,
                                        toolkit=toolkit) == ref


def test_toolkit_alias_and_unknown_metric():
    gt, pred = _maps()
    assert stats.bootstrap_metric(gt, pred, None, "badpix_0070", n=10) == stats.bootstrap_metric(gt, pred, None,
                                                                                                    "badpix_0.07", n=10)
    with pytest.raises(SpecError):
        stats.bootstrap_metric(gt, pred, None, "ssim", n=10)
    with pytest.raises(SpecError):
        stats.bootstrap_metric(gt, pred, None, "mse_x100", n=10, level=1.5)


# --------------------------------------------------------------------------- replicate laws

def _exact_bootstrap_law(x: np.ndarray, statistic) -> dict[float, float]:
    """Exact distribution of a statistic over all N^N equally likely resamples of x."""
    n = x.size
    law: dict[float, float] = {}
    for idx in itertools.product(range(n), repeat=n):
        v = round(float(statistic(x[list(idx)])), 9)
        law[v] = law.get(v, 0.0) + 1.0 / n ** n
    return law


@pytest.mark.parametrize("metric", ["q25_x100", "badpix_0.07"])
def test_fast_paths_match_exact_enumeration(metric):
    # 5 pixels -> 5^5 = 3125 resamples enumerated exactly; the O(N) samplers must follow that law
    errors = np.array([0.01, -0.03, 0.08, -0.12, 0.3], dtype=np.float32)
    law = _exact_bootstrap_law(errors, lambda s: stats.metric_from_errors(s, metric))
    reps = stats.bootstrap_replicates(errors, metric, n=100_000, seed=1)
    values, counts = np.unique(np.round(reps, 9), return_counts=True)
    freq = dict(zip(values.tolist(), (counts / reps.size).tolist(), strict=True))
    assert set(freq) <= set(law)
    for v, p in law.items():
        assert abs(freq.get(v, 0.0) - p) < 0.006, (v, p, freq.get(v))


def test_mse_replicates_have_the_plugin_variance():
    rng = np.random.default_rng(2)
    errors = rng.standard_normal(500) * 0.1
    reps = stats.bootstrap_replicates(errors, "mse_x100", n=4000, seed=3)
    sq = 100 * errors ** 2
    assert reps.mean() == pytest.approx(sq.mean(), rel=0.01)
    # the bootstrap variance of a mean of N draws is the plug-in variance / N
    assert reps.std() == pytest.approx(sq.std() / math.sqrt(sq.size), rel=0.06)


def test_weighted_quantile_matches_pooling_by_hand():
    rng = np.random.default_rng(4)
    n_groups = 40
    gid = np.sort(rng.integers(0, n_groups, 6000))
    values = np.abs(rng.standard_normal(6000)) + gid * 0.2  # groups ordered by value: resamples move Q25 far
    counts = rng.multinomial(n_groups, np.full(n_groups, 1 / n_groups), size=30).astype(np.float64)
    counts[0] = 0
    counts[0, -1] = n_groups  # one resample of only the largest group: far outside the first window
    got = stats._weighted_quantile_replicates(values, gid, counts, 25.0)
    for row, value in zip(counts, got, strict=True):
        pooled = np.sort(np.repeat(values, row[gid].astype(int)))
        assert value == pooled[int(pooled.size * 0.25)]


def test_block_bootstrap_with_singleton_groups_is_the_pixel_law():
    rng = np.random.default_rng(5)
    errors = rng.standard_normal(400) * 0.05
    for metric in ("badpix_0.07", "mse_x100", "q25_x100"):
        iid = stats.bootstrap_replicates(errors, metric, n=3000, seed=6)
        grp = stats.bootstrap_replicates(errors, metric, n=3000, seed=7, groups=np.arange(400))
        assert np.quantile(grp, [0.05, 0.5, 0.95]) == pytest.approx(np.quantile(iid, [0.05, 0.5, 0.95]), rel=0.05)


def test_block_bootstrap_widens_for_spatially_correlated_errors():
    rng = np.random.default_rng(8)
    tiles = rng.standard_normal((8, 8)) * 0.05
    gt = np.zeros((64, 64), np.float32)
    pred = np.kron(tiles, np.ones((8, 8))).astype(np.float32)  # error constant within 8 x 8 tiles
    iid = stats.bootstrap_metric(gt, pred, None, "mse_x100", n=1000)
    blk = stats.bootstrap_metric(gt, pred, None, "mse_x100", n=1000, block=8)
    assert blk.estimate == iid.estimate
    # 64 independent tiles instead of 4096 independent pixels: about sqrt(64) = 8 times wider
    assert 5 < (blk.high - blk.low) / (iid.high - iid.low) < 12


# --------------------------------------------------------------------------- coverage, degenerate cases

def test_pixel_cis_cover_the_true_value_at_the_nominal_rate():
    sigma, n_pix, trials = 0.05, 400, 200
    truth = {"badpix_0.07": 100 * 2 * sps.norm.sf(0.07 / sigma), "mse_x100": 100 * sigma ** 2,
             "q25_x100": 100 * sigma * sps.norm.ppf(0.625)}  # |e| has P(|e| <= q) = 0.25 at q = sigma z_0.625
    rng = np.random.default_rng(9)
    hits = dict.fromkeys(truth, 0)
    for t in range(trials):
        errors = (rng.standard_normal(n_pix) * sigma).astype(np.float32)
        for metric, true_value in truth.items():
            ci = stats.bootstrap_errors(errors, metric, n=300, seed=t)
            hits[metric] += ci.low <= true_value <= ci.high
    for metric, h in hits.items():
        assert 0.88 <= h / trials <= 0.99, (metric, h / trials)


def test_scene_ci_covers_the_true_mean():
    rng = np.random.default_rng(10)
    hits = 0
    for t in range(300):
        ci = stats.bootstrap_mean_over_scenes(rng.normal(3.0, 1.0, 20), n=400, seed=t)
        hits += ci.low <= 3.0 <= ci.high
    assert 0.85 <= hits / 300 <= 0.98


def test_equal_errors_give_zero_width_intervals():
    gt = np.zeros((10, 10), np.float32)
    pred = np.full((10, 10), 0.1, np.float32)
    assert stats.bootstrap_metric(gt, pred, None, "badpix_0.07") == (100.0, 100.0, 100.0)
    assert stats.bootstrap_metric(gt, pred, None, "badpix_0.2") == (0.0, 0.0, 0.0)
    est, low, high = stats.bootstrap_metric(gt, pred, None, "mse_x100")
    assert est == pytest.approx(1.0, rel=1e-6) and low == high == pytest.approx(est, rel=1e-12)
    assert est == mse_x100(gt, pred)
    est, low, high = stats.bootstrap_metric(gt, pred, None, "q25_x100", block=3)
    assert low == high == est == pytest.approx(10.0, rel=1e-6)
    assert stats.bootstrap_mean_over_scenes([2.0, 2.0, 2.0]) == (2.0, 2.0, 2.0)


def test_scene_mean_skips_nan_and_needs_two_scenes():
    est, low, high = stats.bootstrap_mean_over_scenes([1.0, np.nan, 3.0], n=200)
    assert est == 2.0 and 1.0 <= low <= high <= 3.0
    one = stats.bootstrap_mean_over_scenes([5.0])
    assert one.estimate == 5.0 and math.isnan(one.low) and math.isnan(one.high)


def test_seed_makes_results_reproducible():
    gt, pred = _maps(seed=11)
    assert stats.bootstrap_metric(gt, pred, None, "mse_x100", n=300, seed=4) == \
        stats.bootstrap_metric(gt, pred, None, "mse_x100", n=300, seed=4)


def test_generic_callable_metric_agrees_with_the_fast_path():
    gt, pred = _maps(seed=12, size=20)
    generic = stats.bootstrap_metric(gt, pred, None, lambda g, p, m: mse_x100(g, p, m), n=1500, seed=1)
    fast = stats.bootstrap_metric(gt, pred, None, "mse_x100", n=1500, seed=2)
    assert generic.estimate == fast.estimate
    assert generic.low == pytest.approx(fast.low, rel=0.03) and generic.high == pytest.approx(fast.high, rel=0.03)


# --------------------------------------------------------------------------- paired tests

def test_paired_pixel_test_detects_a_real_difference():
    rng = np.random.default_rng(13)
    gt = np.zeros((50, 50), np.float32)
    a = (rng.standard_normal(gt.shape) * 0.03).astype(np.float32)
    b = (rng.standard_normal(gt.shape) * 0.05).astype(np.float32)
    res = stats.paired_pixel_test(gt, a, b, None, "abs", n=1000)
    true_diff = math.sqrt(2 / math.pi) * (0.03 - 0.05)  # E|N(0, s)| = s sqrt(2 / pi)
    assert res.p_value < 0.01 and res.high < 0
    assert res.low <= true_diff <= res.high
    assert res.difference == pytest.approx(np.abs(a).mean() - np.abs(b).mean(), rel=1e-5)
    for measure in ("mse_x100", "badpix_0.07"):
        r = stats.paired_pixel_test(gt, a, b, None, measure, n=1000)
        assert r.p_value < 0.01 and r.high < 0, measure
    bp = stats.paired_pixel_test(gt, a, b, None, "badpix_0.07")
    assert bp.difference == pytest.approx(bad_pix(gt, a, 0.07) - bad_pix(gt, b, 0.07), abs=1e-9)


def test_paired_pixel_test_does_not_flag_equal_methods():
    rng = np.random.default_rng(14)
    gt = np.zeros((50, 50), np.float32)
    a = (rng.standard_normal(gt.shape) * 0.05).astype(np.float32)
    b = (rng.standard_normal(gt.shape) * 0.05).astype(np.float32)
    for measure in ("abs", "mse_x100", "badpix_0.07"):
        r = stats.paired_pixel_test(gt, a, b, None, measure, n=1000)
        assert r.p_value > 0.05 and r.low <= 0 <= r.high, measure
    same = stats.paired_pixel_test(gt, a, a.copy(), None, "abs")
    assert (same.difference, same.low, same.high, same.p_value) == (0.0, 0.0, 0.0, 1.0)


def test_mcnemar_p_value_by_hand():
    gt = np.zeros(20, np.float32)
    a = np.zeros(20, np.float32)
    b = np.zeros(20, np.float32)
    a[:9] = 1.0  # 9 pixels bad only in a
    b[9] = 1.0  # 1 pixel bad only in b
    r = stats.paired_pixel_test(gt, a, b, None, "badpix_0.07")
    # two-sided exact binomial test of 9 of 10 at p = 1/2: 2 * (C(10,9) + C(10,10)) / 2^10
    assert r.p_value == pytest.approx(2 * 11 / 1024)
    assert r.difference == pytest.approx(100 * (9 - 1) / 20)
    assert r.n == 20


def test_paired_pixel_test_drops_nonfinite_for_abs_and_counts_them_bad_for_badpix():
    gt = np.zeros(6, np.float32)
    a = np.array([0.0, 0.0, 0.0, 0.0, 0.0, np.nan], np.float32)
    b = np.array([0.1, 0.1, 0.1, 0.1, 0.1, 0.0], np.float32)
    r = stats.paired_pixel_test(gt, a, b, None, "abs", n=100)
    assert r.n == 5 and r.difference == pytest.approx(-0.1)
    r = stats.paired_pixel_test(gt, a, b, None, "badpix_0.07")
    assert r.n == 6 and r.difference == pytest.approx(100 * (1 - 5) / 6)


def test_paired_block_test_is_more_cautious_on_correlated_errors():
    rng = np.random.default_rng(15)
    gt = np.zeros((64, 64), np.float32)
    tiles_a, tiles_b = rng.standard_normal((2, 8, 8)) * 0.05
    a = np.kron(tiles_a, np.ones((8, 8))).astype(np.float32)
    b = np.kron(tiles_b, np.ones((8, 8))).astype(np.float32)
    iid = stats.paired_pixel_test(gt, a, b, None, "abs", n=1000)
    blk = stats.paired_pixel_test(gt, a, b, None, "abs", n=1000, block=8)
    assert iid.difference == pytest.approx(blk.difference)
    assert iid.p_value < 0.01 < blk.p_value  # 64 equal-variance tiles: no real difference
    assert blk.high - blk.low > 4 * (iid.high - iid.low)


def test_paired_scene_test_exact_by_hand():
    r = stats.paired_scene_test([1.0, 2.0, 3.0, 4.0], [0.0, 0.0, 0.0, 0.0])
    # all 16 sign flips of (1, 2, 3, 4): |sum| >= 10 only for all + and all -
    assert r.p_value == pytest.approx(2 / 16)
    assert r.p_wilcoxon == pytest.approx(0.125)
    assert r.difference == 2.5 and r.n == 4
    same = stats.paired_scene_test([1.0, 2.0], [1.0, 2.0])
    assert same.p_value == 1.0 and same.p_wilcoxon == 1.0


def test_paired_scene_test_many_scenes():
    rng = np.random.default_rng(16)
    base = rng.uniform(1, 5, 30)
    better = stats.paired_scene_test(base - 0.3 + rng.normal(0, 0.1, 30), base, n=2000)
    assert better.p_value < 0.01 and better.p_wilcoxon < 0.01 and better.high < 0
    null = stats.paired_scene_test(base + rng.normal(0, 0.1, 30), base + rng.normal(0, 0.1, 30), n=2000)
    assert null.p_value > 0.05 and null.low <= 0 <= null.high


# --------------------------------------------------------------------------- tables

def test_ci_records_and_table():
    results = Results()
    errors = {}
    for method, sigma in (("a", 0.03), ("b", 0.06)):
        for k, scene in enumerate(("s1", "s2", "s3")):
            gt, pred = _maps(seed=20 + k, size=30, sigma=sigma)
            mask = np.ones(gt.shape, bool)
            mask[:2] = False
            errors[(method, scene)] = stats.ScoredErrors.from_maps(gt, pred, mask)
            for metric, value in (("badpix_0.07", bad_pix(gt, pred, 0.07, mask)),
                                  ("mse_x100", mse_x100(gt, pred, mask))):
                results.records.append(Record(method, scene, metric, value, "lowres"))
    long = stats.ci_records(results, errors, n=200)
    scenes = long[long["scene"] != "(mean)"]
    assert len(scenes) == 12 and (scenes["low"] <= scenes["value"]).all() and (scenes["value"] <= scenes["high"]).all()
    assert (scenes["n_pixels"] == 28 * 30).all()
    mean_a = long[(long["method"] == "a") & (long["scene"] == "(mean)") & (long["metric"] == "mse_x100")].iloc[0]
    assert mean_a["value"] == pytest.approx(np.mean([results.value("a", s, "mse_x100") for s in ("s1", "s2", "s3")]))
    table = ci_table(results, errors, n=200, block=5)
    assert list(table.columns) == ["a", "b"]
    assert table.index[0] == ("s1", "badpix_0.07") and table.index[-1] == ("(mean)", "mse_x100")
    cell = table.loc[("s1", "mse_x100"), "a"]
    value, rest = cell.split(" [")
    low, high = (float(v) for v in rest.rstrip("]").split(", "))
    assert float(value) == pytest.approx(results.value("a", "s1", "mse_x100"), abs=5e-4) and low <= float(value) <= high
    from lfbench.reports.tables import render

    assert "[" in render(table, "markdown")


def test_collector_errors_reproduce_the_evaluated_metrics(hci_root, shared_data):
    from conftest import require

    from lfbench.data.hci import HCIDataset
    from lfbench.method.registry import create
    from lfbench.runs.runner import evaluate

    maps = require(shared_data / "published" / "subfocal")
    scenes = [s for s in HCIDataset.open(hci_root).select([]) if s.name == "backgammon"]
    collector = stats.ErrorCollector()
    results = evaluate([create("published", path=maps)], scenes, on_prediction=collector, progress=False)
    (label, scene), = collector.errors
    se = collector.errors[(label, scene)]
    assert se.errors.size == 482 * 482
    for metric in METRICS:
        assert stats.metric_from_errors(se.errors, metric) == results.value(label, scene, metric)
    iid = stats.bootstrap_errors(se.errors, "badpix_0.07", n=300)
    blk = stats.bootstrap_errors(se.errors, "badpix_0.07", n=300, groups=se.groups(16))
    assert iid.low < iid.estimate < iid.high and blk.high - blk.low > 1.5 * (iid.high - iid.low)


def test_paired_pixel_test_of_a_proportion_in_its_own_scale(monkeypatch):
    """A metric plugin's proportion of scale 1 (a share, not a percentage): the McNemar counts take d > 0 as
    'worse' (its losses are -1, 0, 1, not -100, 0, 100) and the bootstrap CI is in the metric's own units, the
    same as the difference: BadPix(0.07)'s test / 100, with the same resamples (the CI was 100 x too wide)."""
    from lfbench.scoring.metrics import METRICS, Metric, PixelMetric, Proportion, get_metric

    badpix = get_metric("badpix_0.07")
    for attr in ("_objects", "_entries", "_aliases"):
        monkeypatch.setattr(METRICS, attr, dict(getattr(METRICS, attr)))
    METRICS.add("share_bad_0.07", Metric(id="share_bad_0.07", name="share", description="", unit="",
                                         pixelwise=PixelMetric(badpix.pixelwise.sample, Proportion(scale=1.0))))
    rng = np.random.default_rng(3)
    gt = rng.uniform(-1, 1, (20, 20)).astype(np.float32)
    pred_a = gt + rng.normal(0, 0.08, gt.shape).astype(np.float32)
    pred_b = gt + rng.normal(0, 0.05, gt.shape).astype(np.float32)
    percent = stats.paired_pixel_test(gt, pred_a, pred_b, None, "badpix_0.07", n=200)
    share = stats.paired_pixel_test(gt, pred_a, pred_b, None, "share_bad_0.07", n=200)
    assert percent.test.startswith("exact McNemar") and share.test == percent.test
    assert share.p_value == percent.p_value and share.n == percent.n == 400
    assert percent.low < percent.difference < percent.high
    for got, want in ((share.difference, percent.difference), (share.low, percent.low), (share.high, percent.high)):
        assert got == pytest.approx(want / 100, rel=1e-12)


def test_scored_positions_are_int32_below_2_31_pixels_and_int64_from_there():
    """ScoredErrors.from_prepared's positions: int32 while they fit, int64 for a map of 2^31 pixels or more (the
    largest position, 2^31 - 1, would still fit; 2^31 + 1 pixels would not). Kills the bound's `or True`, `3**31`,
    `2**32` and `<=`, which only a map of over 8 GiB could show through from_prepared."""
    assert [stats._position_dtype(n) for n in (0, 1, 2**31 - 1)] == [np.int32] * 3
    assert [stats._position_dtype(n) for n in (2**31, 2**31 + 1, 2**40)] == [np.int64] * 3
    gt = np.zeros((3, 4), np.float32)
    small = stats.ScoredErrors.from_prepared(SimpleNamespace(gt=gt, pred=gt + 1, mask=None, scale=1))
    assert small.flat_index.dtype == np.int32 and small.flat_index.tolist() == list(range(12))
