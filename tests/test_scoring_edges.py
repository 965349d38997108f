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

from lfbench.scoring.general import BadPixels, abs_error_x100, squared_error
from lfbench.scoring.metrics import bad_pix, bad_pix_curve, mse_x100, nonfinite_count, q25_x100, quantile_x100
from lfbench.scoring.pixelwise import Mean, OrderStatistic, Proportion
from lfbench.scoring.prepare import border_mask
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
    with pytest.raises(ValueError, match="^box and dot labels must be non-negative integers$"):
        missed_dots(gt, pred, boxes, -dots)
    with pytest.raises(ValueError, match="non-negative"):
        missed_dots(gt, pred, -boxes, dots)


# --------------------------------------------------------------------------- no warnings on non-finite data

def test_non_finite_maps_are_scored_without_runtime_warnings():
    """Kills every dropped `np.errstate(...)` that guards a reachable floating-point exception: inf - inf
    (an infinite prediction on infinite ground truth), NaN and inf predictions, a disparity whose depth is
    infinite (the float32 denominator of disp2depth is exactly 0), a dot without pixels (0 / 0), zero
    normals, inf x 0 in a dot product, and the median of no angle: all scored silently."""
    d_inf = F32(-0.16523236)  # 1000 s d / q + 1 / F == 0 in float32 for these parameters
    with np.errstate(divide="ignore"):
        assert np.isinf(toolkit_depth(np.array([d_inf]), PARAMS)).all()
    gt = np.full((16, 16), 0.5, F32)
    gt[2, 2], gt[3, 3] = np.nan, np.inf
    pred = gt + F32(0.01)
    pred[5, 5], pred[6, 6], pred[7, 7], pred[8, 8] = np.nan, np.inf, -np.inf, d_inf
    pred[3, 3] = np.inf  # inf - inf
    mask = np.ones(gt.shape, bool)
    boxes = np.ones(gt.shape, np.int32)
    boxes[:, 12:] = 2  # box 2 has no dot 1: an empty (box, label) pair
    dots = np.zeros(gt.shape, np.int32)
    dots[2:9, 2:9] = 1
    dots[10:12, 10:14] = 2
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
                assert np.isnan(median_angular_error(gt, pred, PARAMS, np.zeros(gt.shape, bool), toolkit=toolkit))
                missed_dots(gt, pred, boxes, dots, toolkit=toolkit)
            assert np.isnan(depth_normals(np.zeros((5, 5)), 100.0, 35.0)).all()  # 0 / 0
            inf_normal, zero_normal = np.array([[[np.inf, 0.0, 0.0]]]), np.zeros((1, 1, 3))
            assert np.isnan(angular_error_deg(inf_normal, zero_normal)).all()  # inf x 0


def test_missed_dots_toolkit_counts_only_present_boxes():
    """Kills every box label up to the largest counted as a box (`bincount > 0` -> `>= 0`): with boxes 1
    and 3 only, the toolkit rule has 2 boxes x 1 label, not 3 (an empty box would be a missed dot)."""
    boxes = np.zeros((4, 8), np.int32)
    boxes[:, :4], boxes[:, 4:] = 1, 3
    dots = np.zeros_like(boxes)
    dots[1:3, 1:3] = dots[1:3, 5:7] = 1
    gt = np.zeros(boxes.shape, F32)
    assert missed_dots(gt, gt, boxes, dots, toolkit=True) == 0.0
    assert missed_dots(gt, gt, boxes, dots) == 0.0


def test_read_label_mask_rules_and_errors(tmp_path):
    """Kills read_label_mask comparing the alpha channel (an RGBA gray mask is a label mask), its errors
    losing their message, file or wording ("label mask")."""
    from PIL import Image

    from lfbench.scoring.prepare import read_label_mask
    from lfbench.utils.errors import DataError

    arr = np.array([[0, 1, 2], [3, 0, 8]], dtype=np.uint8)
    rgba = np.stack([arr, arr, arr, np.full_like(arr, 255)], axis=-1)
    Image.fromarray(rgba, mode="RGBA").save(tmp_path / "rgba.png")
    assert np.array_equal(read_label_mask(tmp_path / "rgba.png"), arr)
    Image.fromarray(np.stack([arr, arr, arr + 1], axis=-1)).save(tmp_path / "colour.png")
    with pytest.raises(DataError) as e:
        read_label_mask(tmp_path / "colour.png")
    assert str(e.value) == f"{tmp_path / 'colour.png'}: label mask must be gray (its colour channels differ)"
    with pytest.raises(DataError) as e:
        read_label_mask(tmp_path / "missing.png")
    assert str(e.value) == f"{tmp_path / 'missing.png'}: missing label mask"


def test_shape_errors_say_which_shapes():
    """Kills _prepare's shape errors losing their message."""
    with pytest.raises(ValueError, match=r"gt \(2, 2\) and pred \(2, 3\) differ in shape"):
        bad_pix(np.zeros((2, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"mask \(3, 3\) and gt \(2, 2\) differ in shape"):
        bad_pix(np.zeros((2, 2)), np.zeros((2, 2)), 0.07, np.ones((3, 3), bool))


# --------------------------------------------------------------------------- the metric definitions

# The benchmark's metrics as results files name them (the toolkit's ids), with what decides their numbers:
# id: (toolkit id, unit, evaluation mask, extra masks, resolution, category, needs scene, and for a metric that
# bootstraps: its sample of the pixel errors and its resampling family).
# From the evaluation fact sheet (General / Region / Stratified metrics); units as the tables print them.
_REGION, _STRAT = "region", "stratified"
METRIC_TABLE = {
    "badpix_0.01": ("badpix_0010", "%", None, (), "scene", "general", False, (BadPixels(0.01), Proportion())),
    "badpix_0.03": ("badpix_0030", "%", None, (), "scene", "general", False, (BadPixels(0.03), Proportion())),
    "badpix_0.07": ("badpix_0070", "%", None, (), "scene", "general", False, (BadPixels(0.07), Proportion())),
    "mse_x100": ("mse_100", "px^2 x 100", None, (), "scene", "general", False, (squared_error, Mean())),
    "q25_x100": ("q_25_100", "px x 100", None, (), "scene", "general", False, (abs_error_x100, OrderStatistic(25.0))),
    # the toolkit's runtime metrics: read from the method's runtime, not computed from maps (no bootstrap)
    "runtime": ("runtime", "s", None, (), "scene", "runtime", False, None),
    "runtime_log": ("runtime_log", "log10 s", None, (), "scene", "runtime", False, None),
    "discontinuities": ("discontinuities_0070", "%", "mask_discontinuities", (), "highres", _REGION, False, None),
    "bumpiness_planes": ("bumpiness_planes_100_0050", "px/px^2 x 100", "mask_planes", (), "lowres", _REGION, True,
                         None),
    "bumpiness_contin_surfaces": ("bumpiness_contin_surfaces_100_0050", "px/px^2 x 100", "mask_smooth_surfaces", (),
                                  "lowres", _REGION, True, None),
    "mae_planes": ("mae_planes", "deg", "mask_planes", (), "lowres", _REGION, True, None),
    "mae_contin_surfaces": ("mae_contin_surfaces", "deg", "mask_smooth_surfaces", (), "lowres", _REGION, True, None),
    "fine_fattening": ("fine_fattening_0150", "%", "mask_fine_surrounding", (), "highres", _REGION, False, None),
    "fine_thinning": ("fine_thinning_0150", "%", "mask_fine", (), "highres", _REGION, False, None),
    "backgammon_fattening": ("backgammon_fattening_0070", "%", "mask_foreground_fattening", (), "highres", _STRAT,
                             True, None),
    "backgammon_thinning": ("backgammon_thinning_0070", "%", "mask_foreground_thinning", (), "highres", _STRAT, True,
                            None),
    "dots_background_mse": ("background_mse_100", "px^2 x 100", "mask_background", (), "highres", _STRAT, False,
                            None),
    "missed_dots": ("missed_dots_50_0400", "% of dots", None, ("mask_boxes", "mask_dots_by_size"), "highres", _STRAT,
                    True, None),
    "pyramids_bumpiness_slanted": ("bumpiness_slanted_100_0050", "px/px^2 x 100", None,
                                   ("mask_sphere_in", "mask_sphere_out", "mask_pyramids"), "lowres", _STRAT, True,
                                   None),
    "pyramids_bumpiness_parallel": ("bumpiness_parallel_100_0050", "px/px^2 x 100", "mask_plane", (), "lowres",
                                    _STRAT, True, None),
    "stripes_low_texture": ("low_texture_0070", "%", "mask_low_texture", (), "highres", _STRAT, False, None),
    "stripes_dark": ("dark_stripes_0070", "%", "mask_high_contrast", (), "highres", _STRAT, False, None),
    "stripes_bright": ("bright_stripes_0070", "%", "mask_low_contrast", (), "highres", _STRAT, False, None),
}


def test_metric_definitions_are_the_benchmarks():
    """Kills any change of what decides a metric's number or where it is recorded: its id and the toolkit's id,
    unit, masks, resolution, category, scene context and bootstrap statistic (the metric definitions run at
    import; results/mutation/README.md: checked in a fresh process)."""
    from lfbench.scoring.metrics import get_metric, list_metrics

    assert [m.id for m in list_metrics()] == list(METRIC_TABLE)
    for m in list_metrics():
        boot = None if m.bootstrap is None else (m.pixelwise.sample, m.bootstrap)
        assert (m.toolkit_id, m.unit, m.mask_name, m.extra_masks, m.resolution, m.category, m.needs_scene,
                boot) == METRIC_TABLE[m.id], m.id
        assert get_metric(m.toolkit_id) is m and not m.higher_is_better and m.scene_aggregate == "mean"
    assert get_metric("badpix_0.04").toolkit_id == "badpix_0040"


def test_region_badpix_and_mse_metrics_score_their_mask():
    """Kills the region metrics built on BadPix(0.07) / MSE losing their mask, threshold or non-finite rule
    (their BadPixels(0.07) sample; the stratified MSE)."""
    from lfbench.scoring.metrics import get_metric

    gt = np.zeros((1, 5), F32)
    pred = np.array([[0.05, 0.1, np.nan, 0.5, 0.0]], F32)
    mask = np.array([[True, True, True, False, True]])
    for mid in ("discontinuities", "stripes_low_texture", "stripes_dark", "stripes_bright"):
        metric = get_metric(mid)
        assert metric(gt, pred, mask) == 50.0, mid  # 0.1 and NaN bad of 4
        assert metric(gt, pred, mask, toolkit=True) == 25.0, mid  # the toolkit: NaN good
    assert get_metric("dots_background_mse")(gt, pred, mask) == pytest.approx(100 * (0.05**2 + 0.1**2) / 3, rel=1e-6)


def test_badpix_family_and_registry_lookups():
    """Kills, in the `badpix_<t>` family: exponent ids (tiny thresholds) refused (`"." in text or` -> `and`), negative
    or infinite thresholds accepted, threshold 0 refused (`t >= 0` -> `t > 0`); and `in` / list_metrics /
    aggregate changes."""
    from lfbench.scoring.metrics import METRICS, get_metric, list_metrics

    assert METRICS.find("badpix_1e-05").id == "badpix_1e-05"  # the id of a tiny threshold is in exponent form
    assert METRICS.find("badpix_5e-2") is None  # one spelling per id (issue 31): 0.05 is 'badpix_0.05'
    assert METRICS.find("badpix_0").id == "badpix_0" and METRICS.find("badpix_0")(np.zeros((1, 2)), np.eye(1, 2)) == 50
    for bad in ("badpix_-0.1", "badpix_inf", "badpix_nan", "badpix_x"):
        assert METRICS.find(bad) is None, bad
    assert "badpix_0.05" in METRICS and "mse_x100" in METRICS and "psnr" not in METRICS and 5 not in METRICS
    assert [m.id for m in list_metrics("stratified")][:2] == ["backgammon_fattening", "backgammon_thinning"]
    assert {m.category for m in list_metrics("region")} == {"region"}
    mse = get_metric("mse_x100")
    assert mse.aggregate([1.0, None, 3.0]) == 2.0  # a JSON null is a missing scene
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "mean of empty slice"
        assert np.isnan(mse.aggregate([np.nan, np.nan]))


# --------------------------------------------------------------------------- every metric through score_scene

def _write_labels(folder, name: str, labels: np.ndarray) -> None:
    from PIL import Image

    Image.fromarray(labels.astype(np.uint8)).save(folder / f"{name}.png")


def _block(y0: int, x0: int, size: int = 4, n: int = 40) -> np.ndarray:
    m = np.zeros((n, n), bool)
    m[y0:y0 + size, x0:x0 + size] = True
    return m


@pytest.mark.parametrize("toolkit", [False, True])
def test_every_region_metric_follows_the_scoring_rules_through_score_scene(tmp_path, toolkit):
    """Kills a region metric's wrapper losing the caller's `toolkit` rule (None / omitted), its mask (MAE
    scored everywhere), or, for the slanted pyramids, the union of its masks (`|=` -> `=`). One NaN
    prediction per region: by default a bad pixel (the clip value, 180 degrees), for the toolkit good
    (left out). Values by hand; each metric's mask is a 4 x 4 block inside the 15 px border."""
    from helpers import write_scene

    from lfbench.data.hci import HCIScene
    from lfbench.scoring.rules import ScoringRules
    from lfbench.scoring.score import applicable_metrics, score_scene

    rules = ScoringRules(toolkit=toolkit)
    region = _block(18, 18)  # rows / cols 18..21; the NaN at (20, 20) spoils 9 normals and all 16 Hessians
    names = ("mask_discontinuities", "mask_fine", "mask_fine_surrounding", "mask_planes", "mask_smooth_surfaces")
    folder = write_scene(tmp_path, "toy", size=40, views=False, gt=np.zeros((40, 40), F32),
                         masks={f"{m}_lowres": region for m in names})
    pred = np.zeros((40, 40), F32)
    pred[20, 20] = np.nan
    values = score_scene(HCIScene(folder), pred, applicable_metrics(HCIScene(folder)), rules).values
    pct = 0.0 if toolkit else 100 / 16
    for mid in ("discontinuities", "fine_fattening", "fine_thinning"):
        assert values[mid] == pct, mid
    assert values["badpix_0.07"] == (0.0 if toolkit else 1.0)  # 1 of the 10 x 10 pixels inside the border
    for mid in ("bumpiness_planes", "bumpiness_contin_surfaces"):
        assert np.isnan(values[mid]) if toolkit else values[mid] == pytest.approx(5.0), mid
    for mid in ("mae_planes", "mae_contin_surfaces"):
        assert values[mid] == (pytest.approx(0.0, abs=1e-6) if toolkit else 180.0), mid

    # backgammon at low resolution: foreground column 14 (1.0; a decoy 3.0 at column 28), background column 29
    gt = np.zeros((40, 40), F32)
    gt[:, 14], gt[:, 28] = 1.0, 3.0
    gt[20:24, 20:24] = 1.0  # a piece of the bar
    folder = write_scene(tmp_path, "backgammon", "stratified", size=40, views=False, gt=gt,
                         masks={"mask_foreground_fattening_lowres": _block(15, 15),
                                "mask_foreground_thinning_lowres": _block(20, 20)})
    pred = gt.copy()
    pred[15, 15], pred[16, 16] = 0.6, np.nan  # fattening (> 0.5), NaN
    pred[20, 20], pred[21, 21] = 0.4, np.nan  # thinning (< 0.5), NaN
    values = score_scene(HCIScene(folder), pred, applicable_metrics(HCIScene(folder)), rules).values
    assert values["backgammon_fattening"] == values["backgammon_thinning"] == (100 / 16 if toolkit else 200 / 16)

    # dots: dot 1 half NaN (missed by default, detected by the toolkit), dot 2 right
    folder = write_scene(tmp_path, "dots", "stratified", size=40, views=False, gt=np.zeros((40, 40), F32))
    boxes, dots = np.zeros((40, 40)), np.zeros((40, 40))
    boxes[16:24, 16:32] = 1
    dots[17:19, 17:19], dots[17:19, 21:23] = 1, 2
    _write_labels(folder, "mask_boxes_lowres", boxes)
    _write_labels(folder, "mask_dots_by_size_lowres", dots)
    pred = np.zeros((40, 40), F32)
    pred[17, 17:19] = np.nan
    values = score_scene(HCIScene(folder), pred, applicable_metrics(HCIScene(folder)), rules).values
    assert values["missed_dots"] == (0.0 if toolkit else 50.0)

    # pyramids: the slanted surfaces are the union of three masks; the NaN spoils all of mask_sphere_in
    folder = write_scene(tmp_path, "pyramids", "stratified", size=40, views=False, gt=np.zeros((40, 40), F32),
                         masks={"mask_sphere_in_lowres": _block(15, 15), "mask_sphere_out_lowres": _block(15, 21),
                                "mask_pyramids_lowres": _block(21, 15)})
    pred = np.zeros((40, 40), F32)
    pred[16, 16] = np.nan
    values = score_scene(HCIScene(folder), pred, applicable_metrics(HCIScene(folder)), rules).values
    assert values["pyramids_bumpiness_slanted"] == (0.0 if toolkit else pytest.approx(100 * 16 * 0.05 / 48))


def test_a_label_mask_of_the_wrong_size_names_its_file(tmp_path):
    """Kills the size check of the dots' label masks weakened or its message / file lost."""
    from helpers import write_scene

    from lfbench.data.hci import HCIScene
    from lfbench.scoring.metrics import get_metric
    from lfbench.scoring.score import score_scene
    from lfbench.utils.errors import DataError

    folder = write_scene(tmp_path, "dots", "stratified", size=40, views=False, gt=np.zeros((40, 40), F32))
    _write_labels(folder, "mask_boxes_lowres", np.ones((40, 40)))
    _write_labels(folder, "mask_dots_by_size_lowres", np.ones((30, 40)))
    with pytest.raises(DataError, match="mask is 40x30, ground truth is 40x40") as info:
        score_scene(HCIScene(folder), np.zeros((40, 40), F32), [get_metric("missed_dots")])
    assert "mask_dots_by_size_lowres.png" in str(info.value)


def test_slanted_bumpiness_keeps_the_border(tmp_path):
    """Kills the slanted-surfaces metric scoring the union of its masks without the caller's mask (the
    15 px border): mask_pyramids reaches into the border, where the prediction is curved."""
    from helpers import write_scene

    from lfbench.data.hci import HCIScene
    from lfbench.scoring.metrics import get_metric
    from lfbench.scoring.score import score_scene

    pyramids = np.zeros((40, 40), bool)
    pyramids[2:19, 15:19] = True  # rows 2..14 in the border, 15..18 inside
    folder = write_scene(tmp_path, "pyramids", "stratified", size=40, views=False, gt=np.zeros((40, 40), F32),
                         masks={"mask_sphere_in_lowres": _block(20, 15), "mask_sphere_out_lowres": _block(20, 20),
                                "mask_pyramids_lowres": pyramids})
    y, _ = np.mgrid[0:40, 0:40].astype(np.float64)
    pred = np.where(y < 12, 0.5 * 0.01 * (y - 6) ** 2, 0.0).astype(F32)  # curved on rows 0..11 only
    score = score_scene(HCIScene(folder), pred, [get_metric("pyramids_bumpiness_slanted")])
    assert score.values["pyramids_bumpiness_slanted"] == 0.0  # rows 15.. are 3 px from the curved part
    # without a mask (a direct call): the union of the three masks, border included (68 + 16 + 16 px)
    direct = get_metric("pyramids_bumpiness_slanted")(np.zeros((40, 40), F32), pred, scene=HCIScene(folder),
                                                      resolution="lowres")
    assert 0 < direct < 5


def test_bad_metric_definitions_are_refused_with_a_reason():
    """Kills the errors of a bad metric definition (a plugin's) losing their message: an unknown scene
    aggregate, nothing to compute, an empty or NaN value range, a non-Metric registered."""
    from lfbench.scoring.metrics import METRICS, Metric

    with pytest.raises(ValueError, match="^metric 'x': unknown scene_aggregate 'median'; use one of mean$"):
        Metric(id="x", name="x", description="x", unit="%", fn=bad_pix, scene_aggregate="median")
    with pytest.raises(ValueError, match="^metric 'x': give fn or pixelwise, what it computes$"):
        Metric(id="x", name="x", description="x", unit="%")
    for bad in ((1.0, 1.0), (2.0, 1.0), (float("nan"), 1.0), (0.0, float("nan"))):  # an empty or NaN range
        with pytest.raises(ValueError, match=r"^metric 'x': value_range must be \(low, high\) with low < high, got "):
            Metric(id="x", name="x", description="x", unit="%", fn=bad_pix, value_range=bad)
    with pytest.raises(TypeError, match="^{} registered as metric '\\?' is not a Metric$"):
        METRICS.register({})
