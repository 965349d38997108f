"""Edge cases of the scoring functions that mutation testing found unguarded (results/mutation/README.md).

Each expected value is hand-computed or comes from the toolkit's formula restated here (float32 where the
toolkit works in float32), scikit-image's Scharr filters, or the toolkit's surface normals (scipy's
convolve2d with periodic borders); never from lfbench itself. Docstrings name the mutants each test kills.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import skimage.filters as skf
from helpers import scene_parameters
from scipy import signal

from lfbench.scoring.metrics import bad_pix, bad_pix_curve, mse_x100, nonfinite_count, q25_x100, quantile_x100
from lfbench.scoring.region_metrics import (
    angular_error_deg,
    backgammon_fattening,
    backgammon_thinning,
    bumpiness_x100,
    depth_normals,
    fine_fattening,
    fine_thinning,
    median_angular_error,
    missed_dots,
    scharr_derivative,
    toolkit_depth,
)
from lfbench.scoring.rules import border_mask

F32 = np.float32
PARAMS = scene_parameters("s", "training", 16)


def _case(seed: int = 3, n: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    gt = rng.uniform(-1, 1, (n, n)).astype(F32)
    pred = (gt + rng.normal(0, 0.1, gt.shape)).astype(F32)
    mask = np.zeros((n, n), bool)
    mask[3:9, 2:10] = True
    return gt, pred, mask


# --------------------------------------------------------------------------- masks and dtypes

@pytest.mark.parametrize("mask_dtype", [np.uint8, np.int64, np.float32])
def test_a_mask_of_any_dtype_selects_its_nonzero_pixels(mask_dtype):
    """Kills dropping the bool cast of the mask (`np.asarray(mask, dtype=bool)` in _prepare and
    nonfinite_count): a 0/1 uint8 or float mask would index pixels 0 and 1 instead of selecting."""
    gt, pred, mask = _case()
    pred[4, 4] = np.nan
    m = mask.astype(mask_dtype)
    sel = mask & np.isfinite(pred)
    diff = np.abs(pred[sel] - gt[sel])  # float32
    assert mse_x100(gt, pred, m) == pytest.approx(100 * float(np.mean(np.square(diff))), rel=1e-6)
    errs = np.sort(np.concatenate([diff * F32(100), [np.inf]]))  # the NaN: an infinite error
    assert q25_x100(gt, pred, m) == float(errs[int(0.25 * errs.size)])
    assert nonfinite_count(pred, m) == 1
    expected = 100.0 * (np.count_nonzero(diff > F32(0.07)) + 1) / np.count_nonzero(mask)
    assert bad_pix(gt, pred, 0.07, m) == pytest.approx(expected)
    assert bad_pix_curve(gt, pred, [0.07], m) == pytest.approx([expected])
    fat = 100.0 * (np.count_nonzero((gt[sel] - pred[sel]) < -F32(0.15)) + 1) / np.count_nonzero(mask)
    assert fine_fattening(gt, pred, m) == pytest.approx(fat)


def test_float64_maps_are_not_rounded_to_float32():
    """Kills `np.result_type(gt.dtype, pred.dtype, float32)` losing gt's or pred's dtype: a float64 map is
    scored in float64 (an error of 0.0700000003 > 0.07: bad), not rounded to float32 first (a tie: good)."""
    g64, p32 = np.array([[-0.056658566]]), np.array([[0.013341434]], dtype=F32)
    assert float(p32[0, 0]) - g64[0, 0] > 0.07 and p32[0, 0] - F32(g64[0, 0]) == F32(0.07)
    assert bad_pix(g64, p32) == 100.0  # float64 gt
    assert bad_pix(g64.astype(F32), p32) == 0.0
    g32, p64 = np.zeros((1, 1), F32), np.array([[0.07000000001]])
    assert F32(p64[0, 0]) == F32(0.07)
    assert bad_pix(g32, p64) == 100.0  # float64 prediction


def test_half_precision_maps_are_scored_in_float32():
    """Kills dropping float32 from _prepare's result type: float16 maps are scored in float32 (the error
    float16(0.07) = 0.07000732 is above float32(0.07)), not in float16 (where it ties with 0.07)."""
    gt = np.zeros((1, 2), dtype=np.float16)
    pred = np.array([[0.07, 0.0]], dtype=np.float16)
    assert F32(pred[0, 0]) > F32(0.07)
    assert bad_pix(gt, pred) == 50.0


# --------------------------------------------------------------------------- general metrics

def test_quantile_default_is_the_25th_percentile():
    """Kills a change of quantile_x100's default percentage: index int(0.25 n) of the sorted errors."""
    gt = np.zeros((1, 100), F32)
    pred = (np.arange(100, dtype=F32) / F32(100))[None]  # errors 0.00 .. 0.99: index 25 holds 0.25
    assert quantile_x100(gt, pred) == pytest.approx(25.0, rel=1e-6)
    assert q25_x100(gt, pred) == quantile_x100(gt, pred, 25)


def test_bad_pix_curve_of_one_pixel_and_of_none():
    """Kills bad_pix_curve's empty-mask branch changed (`n == 0` -> `n == 1`, or the NaN array it returns)."""
    gt = np.zeros((1, 2), F32)
    pred = np.array([[0.5, 0.0]], F32)
    one = np.array([[True, False]])
    assert bad_pix_curve(gt, pred, [0.1, 0.7], one).tolist() == [100.0, 0.0]
    empty = bad_pix_curve(gt, pred, [0.1, 0.7], np.zeros((1, 2), bool))
    assert empty.shape == (2,) and np.isnan(empty).all()


def test_border_mask_excludes_every_side():
    """Kills `h - border` / `w - border` -> `+`: the border is left out at the bottom and right too."""
    expected = np.zeros((50, 40), bool)
    expected[15:35, 15:25] = True
    assert np.array_equal(border_mask((50, 40), 15), expected)


# --------------------------------------------------------------------------- region metrics

def test_percentage_metrics_of_one_pixel_and_of_none():
    """Kills `total == 0` -> `total == 1` (one scored pixel gives NaN) and the NaN of an empty mask lost."""
    gt = np.zeros((1, 2), F32)
    pred = np.array([[0.5, -0.5]], F32)
    one, none = np.array([[True, False]]), np.zeros((1, 2), bool)
    assert fine_fattening(gt, pred, one) == 100.0 and fine_thinning(gt, pred, one) == 0.0
    assert np.isnan(fine_fattening(gt, pred, none)) and np.isnan(fine_thinning(gt, pred, none))
    assert backgammon_fattening(gt, pred, one, fg_column=1) == 100.0  # half way to -0.5: -0.25 < 0.5
    assert np.isnan(backgammon_thinning(gt, pred, none, bg_column=1))


def test_backgammon_fattening_default_counts_a_nan_prediction_as_bad():
    """Kills backgammon_fattening's default `toolkit=False` -> True (NaN would count as good)."""
    gt = np.array([[1.0, 0.0, 0.0]], F32)
    pred = np.array([[1.0, np.nan, 0.0]], F32)
    mask = np.array([[False, True, True]])
    assert backgammon_fattening(gt, pred, mask, fg_column=0) == 50.0


def test_bumpiness_uses_the_given_clip_and_scores_one_pixel():
    """Kills bumpiness_map called without the caller's clip, and `n == 0` -> `n == 1` (one pixel: NaN)."""
    y, _ = np.mgrid[0:16, 0:16].astype(np.float64)
    diff = 0.5 * 0.01 * y * y  # Scharr Hessian norm 4 x 0.01 = 0.04 (under the default clip 0.05)
    gt = np.zeros((16, 16))
    one = np.zeros((16, 16), bool)
    one[8, 8] = True
    assert bumpiness_x100(gt, diff, one) == pytest.approx(4.0, rel=1e-9)
    assert bumpiness_x100(gt, diff, one, clip=0.01) == pytest.approx(1.0, rel=1e-9)
    assert np.isnan(bumpiness_x100(gt, diff, np.zeros((16, 16), bool)))


def test_scharr_derivative_of_float32_is_computed_in_float64():
    """Kills dropping scharr_derivative's float64 cast: scikit-image's scharr_h / scharr_v of the float64
    image (the toolkit's arithmetic), to 1e-12, not a float32 filter."""
    img = np.random.default_rng(5).normal(size=(9, 11)).astype(F32)
    for axis, ref in ((0, skf.scharr_h), (1, skf.scharr_v)):
        out = scharr_derivative(img, axis)
        assert out.dtype == np.float64
        assert np.allclose(out[1:-1, 1:-1], ref(img.astype(np.float64))[1:-1, 1:-1], rtol=0, atol=1e-12)


def _toolkit_normals(depth: np.ndarray) -> np.ndarray:
    """The toolkit's get_depth_normals (square maps), in float64 with periodic borders."""
    h, w = depth.shape
    xx, yy = np.meshgrid(range(h), range(w))
    k = PARAMS.sensor_size_mm / PARAMS.focal_length_mm
    xx = (xx / (h - 1.0) * 0.5) * k * depth
    yy = (yy / (w - 1.0) * 0.5) * k * depth
    kernel = np.asarray([[3., 10., 3.], [0., 0., 0.], [-3., -10., -3.]]) / 64.

    def d(c):
        return (signal.convolve2d(c, kernel, mode="same", boundary="wrap"),
                signal.convolve2d(c, kernel.T, mode="same", boundary="wrap"))

    (dxdx, dxdy), (dydx, dydy), (dzdx, dzdy) = d(xx), d(yy), d(depth)
    n = np.stack([dzdx * dxdy - dxdx * dzdy, -(dydx * dzdy - dzdx * dydy), -(dxdx * dydy - dydx * dxdy)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def test_mae_wraps_around_the_borders_like_the_toolkit():
    """Kills dropping `mode="wrap"` from the normals' Scharr passes: on the whole map (borders included)
    the angles are the toolkit's, whose convolution is periodic. Kills float32 normals too
    (depth_normals' float64 cast)."""
    y, x = np.mgrid[0:16, 0:16]
    gt = (0.4 + 0.03 * x - 0.02 * y + 0.1 * np.sin(x / 2.0)).astype(F32)
    pred = (gt + np.random.default_rng(4).normal(0, 0.02, gt.shape)).astype(F32)
    n_gt, n_pred = _toolkit_normals(toolkit_depth(gt, PARAMS)), _toolkit_normals(toolkit_depth(pred, PARAMS))
    angle = np.degrees(np.arccos(np.clip(np.sum(n_gt * n_pred, axis=-1), -1, 1)))
    edge = np.zeros(gt.shape, bool)
    edge[:, 0] = edge[:, -1] = True
    assert median_angular_error(gt, pred, PARAMS, edge) == pytest.approx(float(np.median(angle[edge])), rel=1e-9)


def test_mae_of_one_pixel():
    """Kills `values.size == 0` -> `== 1` in median_angular_error (one scored pixel: its angle, not NaN)."""
    gt = np.full((8, 8), 0.5, F32)
    one = np.zeros((8, 8), bool)
    one[4, 4] = True
    assert median_angular_error(gt, gt, PARAMS, one) == pytest.approx(0.0, abs=1e-6)
    assert np.isnan(median_angular_error(gt, gt, PARAMS, np.zeros((8, 8), bool)))


def test_depth_normals_need_a_2d_map_of_at_least_3x3():
    """Kills the size check of depth_normals weakened (`or` -> `and`, `< 3` -> `<= 3` / `< 4`)."""
    assert np.allclose(depth_normals(np.full((3, 3), 2.0), 100.0, 35.0)[1, 1], [0.0, 0.0, -1.0])
    for bad in (np.ones((2, 5)), np.ones(9), np.ones((3, 3, 3))):
        with pytest.raises(ValueError, match="at least 3x3"):
            depth_normals(bad, 100.0, 35.0)


def test_toolkit_depth_of_float64_disparity_is_float32_arithmetic():
    """Kills dropping toolkit_depth's float32 cast: a float64 disparity is converted as the toolkit's
    float32 PFM data would be."""
    d = np.random.default_rng(6).uniform(-2, 2, (4, 4))
    q = F32(PARAMS.baseline_mm * PARAMS.focal_length_mm * PARAMS.image_resolution_x_px)
    ref = F32(1.0) / (F32(1000.0 * PARAMS.sensor_size_mm) * d.astype(F32) / q + F32(1.0 / PARAMS.focus_distance_m))
    got = toolkit_depth(d, PARAMS)
    assert got.dtype == np.float32 and np.array_equal(got, ref)


def test_angle_between_equal_or_opposite_normals_is_0_or_180_despite_rounding():
    """Kills dropping the clip of the cosine to [-1, 1]: this unit normal's dot product with itself is
    1.0000000000000002 in float64 (arccos would give NaN)."""
    n = np.array([0.7696741376445092, 0.0800898974604638, -0.6333935034131261])[None, None]
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    assert np.sum(n * n) > 1.0 and np.sum(n * -n) < -1.0
    assert angular_error_deg(n, n)[0, 0] == 0.0
    assert angular_error_deg(n, -n)[0, 0] == 180.0


# --------------------------------------------------------------------------- missed dots

def test_missed_dots_edge_cases():
    """Kills, in missed_dots: the NaN of a layout without dots (`n_pairs == 0` -> `== 1`), one-pixel dots
    left out (`n > 0` -> `n > 1`), the percentage scaled wrongly (100 -> 101: 50 bad of 101 pixels is
    49.5 %, detected), label 8 left out (`<= highest` -> `<`), and the shape and sign checks weakened."""
    boxes = np.ones((12, 24), np.int32)
    dots = np.zeros_like(boxes)
    dots[0, 0] = 1  # a one-pixel dot
    dots[2:12, 2:12] = 2  # 100 px ...
    dots[1, 2] = 2  # ... + 1 = 101 px
    for label in range(3, 9):  # labels 3..8, 1 px each
        dots[0, 12 + label] = label
    gt = np.zeros(boxes.shape, F32)
    pred = gt.copy()
    pred[0, 0] = 1.0  # dot 1 missed
    rows, cols = np.nonzero(dots == 2)
    pred[rows[:50], cols[:50]] = 1.0  # dot 2: 50 of 101 bad: 49.5 %, detected
    pred[0, 20] = 1.0  # dot 8 missed
    assert missed_dots(gt, pred, boxes, dots) == pytest.approx(100 * 2 / 8)
    single = np.zeros((1, 1), np.int32)
    assert missed_dots(np.zeros((1, 1), F32), np.ones((1, 1), F32), single + 1, single + 1) == 100.0
    assert np.isnan(missed_dots(gt, pred, np.zeros_like(boxes), dots))  # no box: no dot
    assert np.isnan(missed_dots(np.zeros((0, 0), F32), np.zeros((0, 0), F32), np.zeros((0, 0), np.int32),
                                np.zeros((0, 0), np.int32)))
    with pytest.raises(ValueError, match="must match"):
        missed_dots(gt, pred, boxes[:, :-1], dots)
    with pytest.raises(ValueError, match="must match"):
        missed_dots(gt, pred, boxes, dots[:-1])
    with pytest.raises(ValueError, match="non-negative"):
        missed_dots(gt, pred, boxes, -dots)
    with pytest.raises(ValueError, match="non-negative"):
        missed_dots(gt, pred, -boxes, dots)


# --------------------------------------------------------------------------- no warnings on non-finite data

def test_non_finite_maps_are_scored_without_runtime_warnings():
    """Kills every dropped `np.errstate(...)`: NaN and inf predictions and ground truth, and a disparity
    whose depth is infinite (the float32 denominator of disp2depth is exactly 0), are scored silently."""
    d_inf = F32(-0.16523236)  # 1000 s d / q + 1 / F == 0 in float32 for these parameters
    with np.errstate(divide="ignore"):
        assert np.isinf(toolkit_depth(np.array([d_inf]), PARAMS)).all()
    gt = np.full((16, 16), 0.5, F32)
    gt[2, 2] = np.nan
    pred = gt + F32(0.01)
    pred[5, 5], pred[6, 6], pred[7, 7], pred[8, 8] = np.nan, np.inf, -np.inf, d_inf
    mask = np.ones(gt.shape, bool)
    boxes = np.ones(gt.shape, np.int32)
    dots = np.zeros(gt.shape, np.int32)
    dots[4:9, 4:9] = 1
    dots[10:12, 10:12] = 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="warn"):
            for toolkit in (False, True):
                bad_pix(gt, pred, 0.07, mask, toolkit=toolkit)
                q25_x100(gt, pred, mask, toolkit=toolkit)
                fine_fattening(gt, pred, mask, toolkit=toolkit)
                fine_thinning(gt, pred, mask, toolkit=toolkit)
                backgammon_fattening(gt, pred, mask, fg_column=2, toolkit=toolkit)
                backgammon_thinning(gt, pred, mask, bg_column=2, toolkit=toolkit)
                bumpiness_x100(gt, pred, mask, toolkit=toolkit)
                median_angular_error(gt, pred, PARAMS, mask, toolkit=toolkit)
                missed_dots(gt, pred, boxes, dots, toolkit=toolkit)
            angular_error_deg(np.full((1, 1, 3), np.nan), np.full((1, 1, 3), np.inf))
