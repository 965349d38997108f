"""One definition per pixel-wise metric (issue 29): a sample of the pixel errors and a resampling family
(lfbench.scoring.pixelwise). The function of maps, the value on gathered pixels, the bootstrap's estimate,
replicates and paired losses all derive from it; the bootstrap chooses how to resample from the family the
metric declares, never from its name. References here are independent: the formulas written out in NumPy."""

from __future__ import annotations

import numpy as np
import pytest

from lfbench.scoring import stats
from lfbench.scoring.metrics import Mean, Metric, OrderStatistic, PixelMetric, Proportion, Sample, get_metric
from lfbench.scoring.pixels import ErrorsOnly, PixelErrors
from lfbench.scoring.pixelwise import kept
from lfbench.utils.errors import SpecError


def _maps(seed: int = 0, size: int = 30) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    gt = rng.uniform(-1.5, 1.5, (size, size)).astype(np.float32)
    pred = gt + (rng.standard_normal((size, size)) * 0.3).astype(np.float32)
    pred[2, 3], pred[5, 5], gt[7, 1] = np.nan, np.inf, np.nan
    return gt, pred


def _abs_error(px, *, toolkit=False) -> Sample:
    """End-point error |pred - gt| (px) at the pixels where both are finite: a sample of the errors only."""
    return kept(px.err, px.finite)


def _far(px, *, toolkit=False) -> Sample:
    """Whether |error| > 0.5 px (non-finite: far), at the scored pixels."""
    with np.errstate(invalid="ignore"):
        return kept((px.err > 0.5) | ~px.pred_finite, px.gt_finite)


EPE = Metric(id="epe", name="EPE", description="Mean end-point error.", unit="px",
             pixelwise=PixelMetric(_abs_error, Mean(scale=1.0)))
FAR = Metric(id="far", name="Far", description="% of errors over 0.5 px.", unit="%",
             pixelwise=PixelMetric(_far, Proportion()))
MEDIAN = Metric(id="median_err", name="Median error", description="Median |error|.", unit="px",
                pixelwise=PixelMetric(_abs_error, OrderStatistic(50.0)))


def test_a_metric_defined_once_is_a_function_of_maps_and_bootstraps_in_its_family():
    """A metric that is only a sample and a family (no code in lfbench.scoring.stats) has its function of maps,
    its value on the pixel errors and i.i.d. and block bootstrap CIs whose estimate is that value."""
    gt, pred = _maps()
    scored = np.isfinite(gt)
    err = np.abs(pred[scored] - gt[scored])
    finite = err[np.isfinite(err)]
    assert EPE(gt, pred) == float(np.average(finite)) == EPE.score_pixels(PixelErrors.of_maps(gt, pred))
    assert FAR(gt, pred) == 100.0 * np.count_nonzero(~(err <= np.float32(0.5))) / err.size
    assert MEDIAN(gt, pred) == float(np.sort(finite)[finite.size // 2])
    mask = np.zeros(gt.shape, bool)
    mask[3:9, 4:20] = True  # a plugin's sample may count the pixels it is given: the mask's, not the map's
    assert PixelErrors.of_maps(gt, pred, mask).size == 96 == ErrorsOnly(stats.scored_errors(gt, pred, mask)).size
    for metric in (EPE, FAR, MEDIAN):
        assert metric.bootstrap is metric.pixelwise.family
        for block in (None, 4):
            ci = stats.bootstrap_metric(gt, pred, None, metric, n=300, seed=1, block=block)
            assert ci.estimate == metric(gt, pred) and ci.low < ci.estimate < ci.high, (metric.id, block)
        e = stats.scored_errors(gt, pred)
        assert stats.metric_from_errors(e, metric) == metric(gt, pred)
    # the family decides the resampling: a proportion's replicates are multiples of 100 / n (binomial counts)
    reps = stats.bootstrap_replicates(stats.scored_errors(gt, pred), FAR, 50, seed=2)
    n = int(np.count_nonzero(scored))
    assert np.allclose(reps * n / 100.0, np.round(reps * n / 100.0))


def test_a_metric_reading_more_than_the_errors_does_not_bootstrap():
    """A sample that reads the ground truth is no function of the errors: it declares so and has no bootstrap;
    the bootstrap's errors-only view refuses to hand out the maps."""
    def relative(px, *, toolkit=False) -> Sample:
        return kept(px.err / np.abs(px.gt), px.finite)

    rel = Metric(id="rel", name="Rel", description="Relative error.", unit="",
                 pixelwise=PixelMetric(relative, Mean(scale=1.0), of_errors=False))
    gt, pred = np.full((2, 2), 2.0, np.float32), np.full((2, 2), 3.0, np.float32)
    assert rel(gt, pred) == 0.5 and rel.bootstrap is None
    with pytest.raises(SpecError, match="^no bootstrap for metric 'rel': supported are badpix_0.01, "):
        stats.bootstrap_metric(gt, pred, None, rel, n=10)
    view = ErrorsOnly(np.array([1.0, -np.inf, np.nan], np.float32))
    assert view.err.tolist()[:2] == [1.0, np.inf] and view.pred_finite.tolist() == [True, False, False]
    with pytest.raises(TypeError, match="^gt: only the errors pred - gt of the scored pixels are kept here"):
        relative(view)
    # region metrics score their own pixels: pixel-wise, but not from the general scoring's errors
    assert get_metric("discontinuities").pixelwise is not None and get_metric("discontinuities").bootstrap is None


def test_mse_is_the_float32_mean_times_100():
    """Kills MSE's mean taken in float64 (the toolkit averages float32 squares, then multiplies by 100)."""
    rng = np.random.default_rng(3)
    gt = np.zeros((1, 1001), np.float32)
    pred = rng.uniform(0, 1, (1, 1001)).astype(np.float32)
    f32 = float(np.mean(np.square(pred))) * 100
    assert f32 != float(np.mean(np.square(pred), dtype=np.float64)) * 100  # the case tells them apart
    assert get_metric("mse_x100")(gt, pred) == f32
    assert stats.metric_from_errors(pred.ravel(), "mse_x100") == f32


def test_paired_losses_follow_the_family_not_the_name():
    """The per-pixel loss of a paired test is the metric's own sample x its scale; McNemar's exact test is
    chosen for indicator (Proportion) losses."""
    e = np.array([0.0, 0.05, 0.0700001, -0.2, np.nan, np.inf], np.float32)
    loss, mid, unit = stats.pixel_loss(e, "badpix_0.07")
    assert (mid, unit) == ("badpix_0.07", "%") and loss.tolist() == [0.0, 0.0, 100.0, 100.0, 100.0, 100.0]
    loss, mid, _ = stats.pixel_loss(e, "sq")
    assert mid == "mse_x100" and loss[:4].tolist() == (100.0 * np.square(e[:4].astype(np.float64))).tolist()
    assert np.isinf(loss[4:]).all()
    with pytest.raises(SpecError, match="is not a mean of per-pixel losses"):
        stats.pixel_loss(e, "q25_x100")
    gt = np.zeros((20, 20), np.float32)
    a, b = gt + 0.01, gt + 0.01
    b[:5] = 1.0
    assert stats.paired_pixel_test(gt, a, b, None, "badpix_0.07", n=50).test.startswith("exact McNemar")
    assert stats.paired_pixel_test(gt, a, b, None, "mse_x100", n=50).test.startswith("sign-flip")
