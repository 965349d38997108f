"""Metrics against hand-computed cases and against an independent re-statement of the toolkit's code.

The toolkit (docs/benchmark-rules.md, General metrics) computes, on the evaluation mask M:
  BadPix(t) = 100 * count(|gt - algo| > t on M) / count(M)        (NaN compares False: counted good)
  MSE x100  = 100 * mean((gt - algo)^2) on M & finite(algo) & finite(gt)
  Q25       = (sorted 100 |gt - algo| on M & finite)[int(0.25 n)]
"""

from __future__ import annotations

import numpy as np
import pytest

from lfbench.scoring.metrics import (
    GENERAL_METRICS,
    METRICS,
    SCENE_AGGREGATES,
    bad_pix,
    bad_pix_curve,
    bad_pix_metric,
    get_metric,
    list_metrics,
    mse_x100,
    nonfinite_count,
    q25_x100,
    quantile_x100,
)
from lfbench.scoring.prepare import border_mask
from lfbench.utils.errors import SpecError

# --------------------------------------------------------------------------- toolkit re-statement


def _valid(a: np.ndarray) -> np.ndarray:
    return ~(np.isposinf(a) | np.isneginf(a) | np.isnan(a))


def toolkit_badpix(algo, gt, mask, thresh):
    with np.errstate(invalid="ignore"):
        bad = np.abs(algo - gt) > thresh
    total = np.sum(mask)
    return np.nan if total == 0 else 100 * np.sum(bad[mask]) / float(total)


def toolkit_mse(algo, gt, mask):
    m = mask & _valid(algo) & _valid(gt)
    with np.errstate(invalid="ignore"):
        diff = np.square(gt - algo)
    # numpy 1.x (the toolkit's) promoted float32-scalar * int to float64: mean in float32, x100 in float64
    return float(np.average(diff[m])) * 100


def toolkit_quantile(algo, gt, mask, percentage=25):
    with np.errstate(invalid="ignore"):
        diffs = np.abs(algo - gt) * 100
    m = mask & _valid(diffs) & _valid(algo)
    s = np.sort(diffs[m])
    return float(s[int(np.size(s) * percentage / 100.0)])


# --------------------------------------------------------------------------- hand-computed cases

GT4 = np.zeros((2, 2), dtype=np.float32)
PRED4 = np.array([[0.005, 0.02], [0.05, 0.1]], dtype=np.float32)


def test_bad_pix_hand_computed():
    assert bad_pix(GT4, PRED4, 0.01) == 75.0
    assert bad_pix(GT4, PRED4, 0.03) == 50.0
    assert bad_pix(GT4, PRED4, 0.07) == 25.0
    assert bad_pix(GT4, PRED4, 0.2) == 0.0
    mask = np.array([[True, True], [True, False]])
    assert bad_pix(GT4, PRED4, 0.01, mask) == pytest.approx(200 / 3)


def test_bad_pix_threshold_is_strict():
    gt = np.zeros((1, 4), dtype=np.float32)
    pred = np.array([[0.5, -0.5, 0.25, 0.75]], dtype=np.float32)  # exactly representable
    assert bad_pix(gt, pred, 0.5) == 25.0  # |err| == t is good, only 0.75 is bad


def test_mse_hand_computed():
    expected = 100 * (0.005**2 + 0.02**2 + 0.05**2 + 0.1**2) / 4  # 0.323125
    assert mse_x100(GT4, PRED4) == pytest.approx(expected, rel=1e-6)
    gt = np.array([[1.0, 2.0]])
    pred = np.array([[1.5, 1.0]])
    assert mse_x100(gt, pred) == pytest.approx(100 * (0.25 + 1.0) / 2)


def test_q25_hand_computed():
    # sorted |diff| * 100 = 0.5, 2, 5, 10; index int(0.25 * 4) = 1
    assert q25_x100(GT4, PRED4) == pytest.approx(2.0, rel=1e-6)
    gt = np.zeros((1, 10))
    pred = np.arange(10, 0, -1, dtype=np.float64)[None] / 100  # errors 0.10 .. 0.01
    assert q25_x100(gt, pred) == pytest.approx(3.0)  # sorted 1..10, index int(2.5) = 2 -> 3
    assert quantile_x100(gt, pred, 50) == pytest.approx(6.0)  # index 5


def test_shape_mismatch_is_an_error():
    with pytest.raises(ValueError):
        bad_pix(np.zeros((2, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError):
        mse_x100(np.zeros((2, 2)), np.zeros((2, 2)), np.ones((3, 3), bool))


def test_empty_mask_gives_nan():
    mask = np.zeros((2, 2), bool)
    assert np.isnan(bad_pix(GT4, PRED4, 0.07, mask))
    assert np.isnan(mse_x100(GT4, PRED4, mask))
    assert np.isnan(q25_x100(GT4, PRED4, mask))


# --------------------------------------------------------------------------- non-finite predictions


def _with_nonfinite() -> tuple[np.ndarray, np.ndarray]:
    gt = np.zeros((2, 3), dtype=np.float32)
    pred = np.array([[0.0, 0.1, np.nan], [np.inf, -np.inf, 0.02]], dtype=np.float32)
    return gt, pred


def test_nonfinite_default_counts_bad_and_is_reported():
    gt, pred = _with_nonfinite()
    assert nonfinite_count(pred) == 3
    assert nonfinite_count(pred, np.array([[True, True, False], [True, True, True]])) == 2
    # 6 pixels: NaN, inf, -inf and 0.1 are bad at t = 0.07
    assert bad_pix(gt, pred, 0.07) == pytest.approx(100 * 4 / 6)
    assert bad_pix(gt, pred, 0.01) == pytest.approx(100 * 5 / 6)
    # MSE has no finite stand-in: finite pixels only
    assert mse_x100(gt, pred) == pytest.approx(100 * (0.1**2 + 0.02**2) / 3, rel=1e-6)
    # Q25: non-finite = infinite error; sorted 0, 2, 10, inf, inf, inf -> index 1
    assert q25_x100(gt, pred) == pytest.approx(2.0, rel=1e-6)
    assert quantile_x100(gt, pred, 50) == np.inf


def test_nonfinite_toolkit_mode_reproduces_its_inconsistency():
    gt, pred = _with_nonfinite()
    # NaN compares False (good), +-inf are bad: 0.1, inf, -inf of 6
    assert bad_pix(gt, pred, 0.07, toolkit=True) == pytest.approx(50.0)
    assert mse_x100(gt, pred, toolkit=True) == pytest.approx(100 * (0.1**2 + 0.02**2) / 3, rel=1e-6)
    # Q25 drops the non-finite: 0, 2, 10 -> index int(0.75) = 0
    assert q25_x100(gt, pred, toolkit=True) == 0.0


def test_nonfinite_ground_truth_is_not_scored_by_default():
    gt = np.array([[0.0, np.nan, 0.0, 0.0]], dtype=np.float32)
    pred = np.array([[0.5, 0.5, 0.0, 0.0]], dtype=np.float32)
    assert bad_pix(gt, pred, 0.07) == pytest.approx(100 / 3)
    assert bad_pix(gt, pred, 0.07, toolkit=True) == 25.0  # the toolkit scores it as good
    assert mse_x100(gt, pred) == pytest.approx(100 * 0.25 / 3)


# --------------------------------------------------------------------------- against the toolkit


def _random_case(seed: int, size: int = 64):
    rng = np.random.default_rng(seed)
    gt = rng.uniform(-2, 2, (size, size)).astype(np.float32)
    scale = rng.choice(np.array([0.003, 0.02, 0.08, 0.5], dtype=np.float32), (size, size))
    pred = (gt + rng.standard_normal((size, size)).astype(np.float32) * scale).astype(np.float32)
    idx = rng.choice(size * size, 40, replace=False)
    pred.flat[idx[:20]] = np.nan
    pred.flat[idx[20:30]] = np.inf
    pred.flat[idx[30:]] = -np.inf
    return gt, pred, border_mask((size, size), 15)


@pytest.mark.parametrize("seed", range(6))
def test_toolkit_mode_equals_toolkit_exactly(seed):
    gt, pred, mask = _random_case(seed)
    assert nonfinite_count(pred, mask) > 0  # the case exercises the non-finite paths
    for t in (0.01, 0.03, 0.07, 0.2):
        assert bad_pix(gt, pred, t, mask, toolkit=True) == toolkit_badpix(pred, gt, mask, t)
    assert mse_x100(gt, pred, mask, toolkit=True) == toolkit_mse(pred, gt, mask)
    assert q25_x100(gt, pred, mask, toolkit=True) == toolkit_quantile(pred, gt, mask)
    for metric in GENERAL_METRICS:  # the descriptors route to the same functions
        ref = {"badpix_0.01": lambda: toolkit_badpix(pred, gt, mask, 0.01),
               "badpix_0.03": lambda: toolkit_badpix(pred, gt, mask, 0.03),
               "badpix_0.07": lambda: toolkit_badpix(pred, gt, mask, 0.07),
               "mse_x100": lambda: toolkit_mse(pred, gt, mask),
               "q25_x100": lambda: toolkit_quantile(pred, gt, mask)}[metric.id]()
        assert metric(gt, pred, mask, toolkit=True) == ref


@pytest.mark.parametrize("seed", range(4))
def test_finite_predictions_default_equals_toolkit_exactly(seed):
    gt, pred, mask = _random_case(seed)
    pred = np.where(np.isfinite(pred), pred, gt + np.float32(0.3)).astype(np.float32)
    for t in (0.01, 0.03, 0.07):
        assert bad_pix(gt, pred, t, mask) == toolkit_badpix(pred, gt, mask, t)
    assert mse_x100(gt, pred, mask) == toolkit_mse(pred, gt, mask)
    assert q25_x100(gt, pred, mask) == toolkit_quantile(pred, gt, mask)


@pytest.mark.parametrize("seed", range(4))
def test_default_nonfinite_rule_on_random_data(seed):
    gt, pred, mask = _random_case(seed)
    finite = np.isfinite(pred)
    n = int(mask.sum())
    n_nonfinite = int((~finite & mask).sum())
    assert nonfinite_count(pred, mask) == n_nonfinite
    for t in (0.01, 0.07):
        with np.errstate(invalid="ignore"):
            bad_finite = int(((np.abs(pred - gt) > t) & finite & mask).sum())
        assert bad_pix(gt, pred, t, mask) == 100 * (bad_finite + n_nonfinite) / float(n)
        # the toolkit under-counts exactly the NaN pixels (counted good there)
        n_nan = int((np.isnan(pred) & mask).sum())
        assert bad_pix(gt, pred, t, mask) - bad_pix(gt, pred, t, mask, toolkit=True) == pytest.approx(
            100 * n_nan / n)
    assert mse_x100(gt, pred, mask) == toolkit_mse(pred, gt, mask)  # MSE: same rule in both modes
    errs = np.sort(np.where(finite, np.abs(pred - gt) * 100, np.inf)[mask])
    assert q25_x100(gt, pred, mask) == float(errs[int(0.25 * errs.size)])


def test_bad_pix_curve_matches_bad_pix():
    gt, pred, mask = _random_case(7)
    thresholds = np.linspace(0, 0.1, 21)
    curve = bad_pix_curve(gt, pred, thresholds, mask)
    assert curve.shape == (21,)
    for t, value in zip(thresholds, curve, strict=True):
        assert value == pytest.approx(bad_pix(gt, pred, float(np.float32(t)), mask), abs=1e-9)
    assert np.all(np.diff(curve) <= 0)  # monotone in the threshold


# --------------------------------------------------------------------------- descriptors


def test_metric_ids_and_toolkit_ids():
    assert [m.id for m in GENERAL_METRICS] == ["badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100"]
    assert [m.toolkit_id for m in GENERAL_METRICS] == ["badpix_0010", "badpix_0030", "badpix_0070", "mse_100",
                                                       "q_25_100"]
    assert get_metric("badpix_0070").id == "badpix_0.07"
    assert get_metric("q_25_100").id == "q25_x100"
    m = get_metric("badpix_0.04")
    assert m.id == "badpix_0.04" and m(GT4, PRED4) == 50.0
    assert get_metric("badpix_0040").id == "badpix_0.04"  # the toolkit's spelling of any threshold
    assert bad_pix_metric(0.2)(GT4, PRED4) == 0.0


def test_one_registry_for_every_metric():
    ids = [m.id for m in list_metrics()]
    assert ids[:5] == [m.id for m in GENERAL_METRICS] and len(ids) == len(set(ids)) == 23
    assert get_metric("discontinuities").category == "region"
    assert get_metric("missed_dots_50_0400").id == "missed_dots"
    available = r"Available: badpix_0\.01, .*runtime_log, .*missed_dots.*badpix_<t>, q<p>_x100"
    with pytest.raises(SpecError, match=r"Unknown metric .psnr.\. " + available):
        get_metric("psnr")
    with pytest.raises(TypeError, match="registered as metric .* is not a Metric"):
        METRICS.register(object())
    with pytest.raises(ValueError, match="already registered"):
        METRICS.register(bad_pix_metric(0.5).__class__(**{**vars(GENERAL_METRICS[3]), "name": "other"}))
    for m in list_metrics():  # every definition says how it aggregates over scenes, in what unit, which way
        assert m.unit and m.description and m.scene_aggregate in SCENE_AGGREGATES and m.lower_is_better
        assert (m.bootstrap is not None) == (m.category == "general")
    assert get_metric("mse_x100").aggregate([1.0, np.nan, 3.0]) == 2.0
