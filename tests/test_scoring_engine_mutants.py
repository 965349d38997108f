"""Scoring-engine cases (issue 23's PixelErrors, DotLayout, the per-scene caches) that survived mutation testing
(results/mutation/issue23/README.md), each against a hand count or the benchmark's formula written out in float32:
infinite ground truth, the public defaults of the pixel functions, overflowing errors scored silently, the
toolkit's dot rules with a valid mask, label masks larger than one counting chunk, the metrics' own backgammon
column at low resolution, and the per-scene caches given a ground truth that is not the scene's."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_scoring_engine import layout  # noqa: F401  (the module-scoped benchmark layout fixture)
from test_scoring_mutants import N, _backgammon_highres, _box

from lfbench.scoring.general import bad_pix_of, quantile_x100_of
from lfbench.scoring.metrics import bad_pix, get_metric
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.prepare import SceneReference
from lfbench.scoring.region_metrics import (
    fine_fattening,
    fine_fattening_of,
    fine_thinning,
    fine_thinning_of,
    median_angular_error,
    missed_dots,
)

F32 = np.float32


def test_infinite_ground_truth_is_not_scored():
    """gt +-inf is non-finite ground truth: left out as NaN is (kills `isfinite(gt)` -> `~isnan(gt)` in
    PixelErrors.gt_finite). By hand: of the finite gt pixels (0 and 0.5), |0.1 - 0| > 0.07 is bad: 50 %."""
    gt = np.array([[0.0, np.inf, -np.inf, 0.5]], F32)
    pred = np.array([[0.1, 0.0, 0.0, 0.5]], F32)
    assert bad_pix(gt, pred, 0.07) == 50.0
    assert get_metric("badpix_0.07").score_pixels(PixelErrors.of_maps(gt, pred)) == 50.0
    assert fine_thinning(gt, -pred) == 50.0  # gt - pred = 0.1 (good), 0.5 (> 0.15, bad)


def _ramp_errors(n_nan: int) -> PixelErrors:
    """gt 0, pred k / 100 for k = 0..49 (float32), the first ``n_nan`` predictions NaN."""
    pred = (np.arange(50, dtype=F32) / F32(100)).reshape(1, -1)
    pred[0, :n_nan] = np.nan
    return PixelErrors.of_maps(np.zeros_like(pred), pred)


def test_pixel_functions_default_to_lfbench_rule_and_the_benchmark_thresholds():
    """The public functions of PixelErrors default to threshold 0.07 / 25 % / 0.15 and the default rule
    (NaN predictions bad or worst), as the map functions do: kills changed defaults in bad_pix_of,
    quantile_x100_of, fine_*_of and Metric.score_pixels."""
    px = _ramp_errors(10)  # errors 0.10 .. 0.49 and 10 NaN
    # BadPix(0.07): every finite error is > 0.07 (40) and the 10 NaN are bad: 100 %; toolkit: 40 of 50
    assert bad_pix_of(px) == 100.0 and bad_pix_of(px, toolkit=True) == 80.0
    px = _ramp_errors(2)  # errors 0.02 .. 0.49, 2 NaN: BadPix(0.07) = (2 NaN + 42 above 0.07) / 50
    assert bad_pix_of(px) == 88.0 and get_metric("badpix_0.07").score_pixels(px) == 88.0
    # Q25: default rule, NaN -> inf: sorted 0.02 .. 0.49, inf, inf; index int(50 * 0.25) = 12 -> 0.14 (x100)
    expected = float(F32(F32(14) / F32(100)) * F32(100))
    assert quantile_x100_of(px) == expected
    # toolkit: the 48 finite errors, index int(48 * 0.25) = 12 -> 0.14 as well; Q26 would be index 13
    assert quantile_x100_of(px, 26) == float(F32(F32(15) / F32(100)) * F32(100))
    px = _ramp_errors(10)  # default: 50 values, index 12 of [0.10 .. 0.49, inf x 10] -> 0.22; toolkit: 40, index 10
    assert quantile_x100_of(px) == float(F32(F32(22) / F32(100)) * F32(100))
    assert quantile_x100_of(px, toolkit=True) == float(F32(F32(20) / F32(100)) * F32(100))
    # fine thinning (gt - pred > 0.15) is never true here (pred >= gt); fattening (gt - pred < -0.15): the 34
    # errors 0.16 .. 0.49 and, by the default rule, the 10 NaN
    assert fine_thinning_of(px) == 20.0 and fine_fattening_of(px) == 100.0 * 44 / 50
    assert fine_fattening_of(px, toolkit=True) == 100.0 * 34 / 50


def test_quantile_in_the_nan_predictions_is_infinite():
    """By the default rule a NaN prediction's error is +inf, also when the quantile's index falls among them:
    Q90 of 40 finite errors and 10 NaN is inf, not NaN (kills the NaN -> inf step skipped)."""
    assert quantile_x100_of(_ramp_errors(10), 90) == np.inf


def test_overflowing_errors_are_scored_silently():
    """An error that overflows float32 (in gt - pred, |gt - pred|, or x 100 for the quantiles) is inf, scored
    without a RuntimeWarning (kills the dropped `over="ignore"` entries)."""
    gt = np.array([[3e38, 0.0]], F32)
    pred = np.array([[-3e38, 1e37]], F32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        px = PixelErrors.of_maps(gt, pred)
        assert quantile_x100_of(px, 50) == np.inf  # 1e37 x 100 overflows: both errors x 100 are inf
        assert fine_thinning_of(px) == 50.0 and fine_fattening_of(px) == 50.0  # 6e38 -> inf > 0.15; -1e37 < -0.15
        boxes = np.ones((1, 2), np.uint8)
        dots = np.array([[1, 2]], np.uint8)
        assert missed_dots(gt, pred, boxes, dots) == 100.0  # both one-pixel dots are off by more than 0.4


def _dots_case():
    """Two boxes (left, right) of a 6 x 12 map. Box 1: dot 1 (4 px) and dot 2 (1 px, outside the valid
    mask); box 2: dot 1 only, so the pair (box 2, label 2) has no pixels; a label-1 pixel outside any box."""
    boxes = np.zeros((6, 12), np.uint8)
    boxes[:, :5], boxes[:, 6:] = 1, 2
    dots = np.zeros((6, 12), np.uint8)
    dots[1:3, 1:3] = 1
    dots[4, 4] = 2
    dots[1:3, 8:10] = 1
    dots[0, 5] = 1  # between the boxes: no dot
    valid = np.ones((6, 12), bool)
    valid[4, 4] = False
    return boxes, dots, valid


def test_missed_dots_with_a_valid_mask_in_both_rules():
    """By hand, a perfect prediction: the default rule scores the 2 dots with pixels, none missed: 0 %. The
    toolkit's rule counts the 4 (box, label) pairs, an empty pair as missed, and lfbench leaves out the pair
    whose only pixel the valid mask removes: 1 missed of 3 (kills had_pixels without minlength, >= 0 or > 1,
    the box test dropped or replaced by the valid mask)."""
    boxes, dots, valid = _dots_case()
    gt = np.zeros((6, 12), F32)
    for v in (valid, valid.astype(np.uint8)):  # a 0/1 valid mask is read as bool
        assert missed_dots(gt, gt, boxes, dots, valid=v) == 0.0
        assert missed_dots(gt, gt, boxes, dots, valid=v, toolkit=True) == pytest.approx(100 / 3)
    with pytest.raises(ValueError, match=r"valid mask \(6, 11\) must match gt \(6, 12\)"):
        missed_dots(gt, gt, boxes, dots, valid=valid[:, :11])


def test_no_dots_is_nan_in_both_rules():
    """Label masks without any dot: no (box, label) pair, NaN in both rules (not 100 % missed)."""
    gt = np.zeros((4, 4), F32)
    boxes = np.ones((4, 4), np.uint8)
    for toolkit in (False, True):
        assert np.isnan(missed_dots(gt, gt, boxes, np.zeros((4, 4), np.uint8), toolkit=toolkit))


def test_dot_labels_are_counted_over_every_chunk():
    """The labels present are counted a chunk of 2^20 pixels at a time: a label seen only in the first chunk
    stays present after the second (kills `|=` -> `=`). 1040 x 1024 px: dot 1 in the first rows, dot 2 in the
    last 16 (the second chunk); dot 1 predicted 1 px off: 1 of 2 dots missed."""
    shape = (1040, 1024)
    boxes = np.ones(shape, np.uint8)
    dots = np.zeros(shape, np.uint8)
    dots[0:2, 0:2] = 1
    dots[1030:1032, 0:2] = 2
    gt = np.zeros(shape, F32)
    pred = gt.copy()
    pred[0:2, 0:2] = 1.0
    assert missed_dots(gt, pred, boxes, dots) == 50.0


def test_backgammon_metric_function_at_low_resolution(tmp_path):
    """The metric's function of maps at low resolution takes the foreground at column 14 (scale 1), not 28:
    on 10 x 5 scored background pixels, 0.6 is beyond half way to the foreground (1.0 -> 0.5) on 5 rows,
    0.48 is not, though it would be half way to column 28's 0.9: 50 %."""
    scene, hi, fat, thin = _backgammon_highres(tmp_path)
    gt = hi[::10, ::10]
    assert gt[0, 14] == 1.0 and gt[0, 28] == F32(0.9)
    pred = np.zeros((N, N), F32)
    pred[15:25, 20:25] = 0.48
    pred[15:20, 20:25] = 0.6
    region = fat[::10, ::10] & _box(N, 15, 25, 15, 25)
    assert np.count_nonzero(region) == 50
    value = get_metric("backgammon_fattening")(gt, pred, region, scene=scene, resolution="lowres")
    assert value == 50.0
    # the toolkit's rule through the same function: a NaN prediction is good (24 of 50), by default bad
    pred[15, 20] = np.nan
    for toolkit, expected in ((False, 50.0), (True, 48.0)):
        assert get_metric("backgammon_fattening")(gt, pred, region, scene=scene, resolution="lowres",
                                                  toolkit=toolkit) == expected
    # thinning on the bar (gt 1, rows 15..24 x columns 15..19): half way to column 40 - 11 = 29 (0.9) is 0.95;
    # the prediction 0 is below it on all 50 pixels, the NaN at (16, 16) good by the toolkit's rule only
    assert gt[0, 29] == F32(0.9)
    pred[16, 16] = np.nan
    bar = thin[::10, ::10] & _box(N, 15, 25, 15, 25)
    assert np.count_nonzero(bar) == 50
    for toolkit, expected in ((False, 100.0), (True, 98.0)):
        assert get_metric("backgammon_thinning")(gt, pred, bar, scene=scene, resolution="lowres",
                                                 toolkit=toolkit) == expected


def test_scene_caches_follow_a_ground_truth_that_is_not_the_scenes(layout):  # noqa: F811
    """MAE and missed dots keep per-scene data for the scene's own ground truth only: given other ground
    truths (with a prepared, read-only prediction) each value is that of the plain function of the maps."""
    _, scenes = layout
    by_name = {s.name: s for s in scenes}
    scene = next(s for s in scenes if "mask_planes" in SceneReference(s).mask_names("lowres"))
    reference = SceneReference(scene)
    rng = np.random.default_rng(3)
    mask = reference.scored_mask("lowres", "mask_planes")
    pred = reference.gt("lowres") + rng.normal(0, 0.05, reference.spatial_size).astype(F32)
    pred[tuple(np.argwhere(mask)[::7][:30].T)] = np.nan  # the two non-finite rules differ
    p = reference.prepare(pred, "lowres")
    metric = get_metric("mae_planes")
    own = metric(p.gt, p.pred, mask, scene=reference, resolution="lowres")
    assert own == median_angular_error(p.gt, p.pred, reference.params, mask)
    ramp = np.linspace(0, 0.5, p.gt.size, dtype=F32).reshape(p.gt.shape)
    for other in (p.gt.copy(), p.gt * F32(1.5) + ramp):
        for toolkit in (False, True):
            assert metric(other, p.pred, mask, scene=reference, resolution="lowres",
                          toolkit=toolkit) == median_angular_error(other, p.pred, reference.params, mask,
                                                                   toolkit=toolkit)
    assert median_angular_error(p.gt, p.pred, reference.params, mask, toolkit=True) != own
    dots = SceneReference(by_name["dots"])
    q = dots.prepare(dots.gt("lowres"), "highres")
    labels = (dots.label_mask("mask_boxes", "highres"), dots.label_mask("mask_dots_by_size", "highres"))
    values = []
    for other in (q.gt.copy(), q.gt + F32(1.0)):  # the second: every dot off by 1 px, all missed
        values.append(get_metric("missed_dots")(other, q.pred, None, scene=dots, resolution="highres"))
        assert values[-1] == missed_dots(other, q.pred, *labels, valid=dots.valid_mask("highres"))
    assert values[0] < 100.0 == values[1]


def test_region_functions_pass_on_their_own_thresholds():
    """fine_fattening / fine_thinning / missed_dots use the threshold, percentage and label limit they are given
    (not the benchmark defaults). By hand: gt - pred = 0.2 on 1 of 2 pixels."""
    gt = np.array([[0.2, 0.0]], F32)
    pred = np.zeros((1, 2), F32)
    assert fine_thinning(gt, pred) == 50.0 and fine_thinning(gt, pred, threshold=0.3) == 0.0
    assert fine_fattening(pred, gt) == 50.0 and fine_fattening(pred, gt, threshold=0.3) == 0.0
    boxes = np.ones((1, 6), np.uint8)
    dots = np.array([[1, 1, 2, 2, 3, 3]], np.uint8)
    gt = np.zeros((1, 6), F32)
    pred = np.array([[0.3, 0.3, 0.3, 0.0, 0.5, 0.5]], F32)  # dot 1: 2 of 2 off by 0.3, dot 2: 1 of 2, dot 3: 2 of 2
    assert missed_dots(gt, pred, boxes, dots) == 100.0 / 3  # only dot 3 is off by > 0.4
    assert missed_dots(gt, pred, boxes, dots, threshold=0.2) == 100.0  # BadPix 100, 50 (>= 50), 100
    assert missed_dots(gt, pred, boxes, dots, threshold=0.2, missed_percent=60.0) == 200.0 / 3
    assert missed_dots(gt, pred, boxes, dots, max_label=2) == 0.0  # dots 1 and 2 only


def test_pixel_set_takes_a_low_resolution_prediction_block_by_block():
    """PixelSet.values is the toolkit's upsampling (scipy.ndimage.zoom, order 0) at the set's pixels in raster
    order, for any block of rows, a non-square map, pixels in the first row and no mask at all."""
    from scipy import ndimage

    from lfbench.scoring.pixels import PixelSet
    from lfbench.scoring.prepare import upsample_index

    rng = np.random.default_rng(4)
    low = rng.uniform(-1, 1, (7, 5)).astype(F32)
    up = ndimage.zoom(low, 10, order=0)
    mask = rng.random(up.shape) < 0.5
    mask[0, :3] = True
    index = upsample_index(low.shape, 10)
    for m in (mask, None):
        pixels = PixelSet(m, np.zeros(up.shape, F32), upsample=index, low_width=5)
        expected = up.ravel() if m is None else up[m]
        for block in (3, 7, 256):
            assert np.array_equal(pixels.values(low, rows_per_block=block), expected)
        assert np.array_equal(pixels.values(low), expected)


def test_plain_value_arrays_and_unmasked_backgammon():
    """Arrays that are not (H, W) maps are plain lists of pixels, with their mask; backgammon without a mask
    finds each row's column on a wide map (PixelSet's own width). By hand."""
    gt = np.zeros(5, F32)
    pred = np.array([0.1, 0.0, 0.2, 0.0, 0.3], F32)
    mask = np.array([True, True, False, False, True])
    assert bad_pix(gt, pred) == 60.0 and bad_pix(gt, pred, mask=mask) == 100.0 * 2 / 3
    gt = np.zeros((2, 30), F32)
    gt[:, 14] = 1.0  # the foreground column: half way is 0.5
    pred = np.zeros((2, 30), F32)
    pred[0, :10] = 0.6
    metric = get_metric("backgammon_fattening")
    assert metric.score_pixels(PixelErrors.of_maps(gt, pred)) == 100.0 * 10 / 60


def test_cached_pixels_are_read_only(layout):  # noqa: F811
    """A scene's pixel sets are shared by every method: their ground truth cannot be written."""
    _, scenes = layout
    pixels = SceneReference(scenes[0]).pixels("lowres")
    assert not pixels.gt.flags.writeable
    with pytest.raises(ValueError):
        pixels.gt[0] = 1.0


def test_general_metrics_in_the_papers_table_order_with_their_headers():
    """Tables show the general metrics as the paper does: BadPix 0.07, 0.03, 0.01, MSE x100, Q25, before any
    other metric, with these column headers (each metric's `order` and `short_label`)."""
    from lfbench.scoring.metrics import metric_order

    ids = ["q50_x100", "q25_x100", "mse_x100", "badpix_0.01", "badpix_0.03", "badpix_0.07", "discontinuities"]
    assert metric_order(ids) == ["badpix_0.07", "badpix_0.03", "badpix_0.01", "mse_x100", "q25_x100", "q50_x100",
                                 "discontinuities"]
    assert [get_metric(m).label for m in ids[1:6]] == ["Q25", "MSE x100", "BadPix 0.01 (%)", "BadPix 0.03 (%)",
                                                      "BadPix 0.07 (%)"]


def test_region_metrics_value_ranges_follow_their_units():
    """A region metric's value range (what a plausible value is) follows its unit: percentages 0-100, the
    bumpiness 0-5 (100 x the clip 0.05), angles 0-180 degrees, MSE x100 from 0."""
    expected = {"discontinuities": (0.0, 100.0), "missed_dots": (0.0, 100.0), "bumpiness_planes": (0.0, 5.0),
                "mae_planes": (0.0, 180.0), "dots_background_mse": (0.0, np.inf)}
    assert {m: tuple(map(float, get_metric(m).value_range)) for m in expected} == expected


def test_quantile_family_metric_uses_its_mask():
    """A quantile of the family (Q50 here) computed from maps keeps to the mask: errors 0.1, 0.2 of the masked
    pixels, index int(2 x 0.5) = 1 -> 0.2 px (x 100, float32); on every pixel it would be 0.3."""
    gt = np.zeros((1, 4), F32)
    pred = np.array([[0.1, 0.2, 0.3, 0.4]], F32)
    mask = np.array([[True, True, False, False]])
    assert get_metric("q50_x100")(gt, pred, mask) == float(F32(0.2) * F32(100))
    assert get_metric("q50_x100")(gt, pred) == float(F32(0.3) * F32(100))
