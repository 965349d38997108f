"""Scoring cases that a plausible refactor of the scoring core would get wrong (issue 25).

Each case is checked against an independent reference: the toolkit's formula as the evaluation fact
sheet states it (/work/shared/docs/hci-evaluation-reference.md), restated here as a plain per-pixel loop in
float32 (the toolkit's arithmetic on PFM data), a hand-computed count, or scikit-image's Scharr filters.
Where a comparison with a threshold is the point, the tie is built explicitly in float32: NumPy compares a
float32 array with a Python-float threshold in float32, so an error of exactly float32(t) is not bad.

The mutation each test kills is named in its docstring (results/mutation/README.md lists them all).
"""

from __future__ import annotations

import numpy as np
import pytest
import skimage.filters as skf
from helpers import scene_parameters, write_scene
from PIL import Image
from scipy import ndimage

from lfbench.data.hci import HCIScene
from lfbench.data.scene import Scene
from lfbench.scoring.metrics import bad_pix, bad_pix_curve, get_metric
from lfbench.scoring.region_metrics import (
    backgammon_fattening,
    backgammon_thinning,
    bumpiness_x100,
    fine_fattening,
    fine_thinning,
    median_angular_error,
    missed_dots,
)
from lfbench.scoring.score import applicable_metrics, score_scene

F32 = np.float32

# (gt, pred) float32 pairs whose float32 difference |pred - gt| is exactly float32(t); each is checked
# where it is used. The last 0.07 pair is the issue's: 0 % bad in float32, 100 % in float64.
TIES_007 = [(0.0, 0.07), (0.1, 0.17), (0.1, 0.030000001), (-0.056658566, 0.013341434)]
TIES_04 = [(0.5, 0.099999994), (-0.3, 0.099999994), (0.1, 0.5), (0.25, -0.15)]
THIN_TIES_015 = [(0.5, 0.35), (0.25, 0.099999994), (-0.3, -0.45000002)]  # gt - pred == float32(0.15)
FAT_TIES_015 = [(0.25, 0.4), (-0.3, -0.15), (-0.056658566, 0.09334144)]  # gt - pred == -float32(0.15)


def _pairs(pairs) -> tuple[np.ndarray, np.ndarray]:
    gt = np.array([[g for g, _ in pairs]], dtype=F32)
    pred = np.array([[p for _, p in pairs]], dtype=F32)
    return gt, pred


# --------------------------------------------------------------------------- independent references

def _ref_badpix(gt: np.ndarray, pred: np.ndarray, t: float, mask: np.ndarray | None = None) -> float:
    """The toolkit's BadPix(t) = 100 * count(|gt - algo| > t on M) / count(M), one float32 pixel at a time."""
    mask = np.ones(gt.shape, bool) if mask is None else mask
    bad = total = 0
    for g, p, m in zip(gt.ravel(), pred.ravel(), mask.ravel(), strict=True):
        if m:
            total += 1
            bad += bool(F32(abs(F32(p) - F32(g))) > F32(t))
    return 100.0 * bad / total


def _toolkit_upsample(pred: np.ndarray, factor: int) -> np.ndarray:
    """The toolkit's upsampling of a low-res result: scipy.ndimage.zoom(order=0), nearest neighbour on
    zoom's grid (its blocks are not exactly factor x factor: their edges shift by up to one pixel)."""
    return ndimage.zoom(pred, factor, order=0)


def _box(shape: int | tuple[int, int], y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
    """Bool mask of ``shape`` (an int: square) True on rows y0..y1-1, columns x0..x1-1."""
    m = np.zeros((shape, shape) if isinstance(shape, int) else shape, dtype=bool)
    m[y0:y1, x0:x1] = True
    return m


# --------------------------------------------------------------------------- 1. ties at a threshold

def test_ties_are_exact_in_float32():
    """The constructed ties really are ties in float32 (the tests below rely on it)."""
    for pairs, t in ((TIES_007, 0.07), (TIES_04, 0.4)):
        for g, p in pairs:
            assert abs(F32(p) - F32(g)) == F32(t), (g, p, t)
    for g, p in THIN_TIES_015:
        assert F32(g) - F32(p) == F32(0.15), (g, p)
    for g, p in FAT_TIES_015:
        assert F32(g) - F32(p) == -F32(0.15), (g, p)


@pytest.mark.parametrize("toolkit", [False, True])
def test_bad_pix_error_equal_to_the_threshold_is_good(toolkit):
    """Kills `err > threshold` -> `>=` in bad_pix (default and toolkit branch)."""
    gt, pred = _pairs(TIES_007 + [(0.0, 0.08), (0.5, 0.5)])  # 4 ties (good), 1 bad, 1 exact
    assert _ref_badpix(gt, pred, 0.07) == pytest.approx(100 / 6)
    assert bad_pix(gt, pred, 0.07, toolkit=toolkit) == pytest.approx(100 / 6)
    assert get_metric("badpix_0.07")(gt, pred, toolkit=toolkit) == pytest.approx(100 / 6)


def test_bad_pix_curve_counts_a_tie_as_good():
    """Kills `searchsorted(..., side="right")` -> "left" in bad_pix_curve (an error equal to a
    threshold would count as bad)."""
    gt, pred = _pairs(TIES_007 + [(0.0, 0.08), (0.0, 0.01), (0.0, -0.2)])
    thresholds = [0.0, 0.01, 0.07, 0.08, 0.1]
    expected = [_ref_badpix(gt, pred, float(F32(t))) for t in thresholds]
    assert expected == pytest.approx([100.0, 100 * 6 / 7, 100 * 2 / 7, 100 / 7, 100 / 7])
    assert bad_pix_curve(gt, pred, thresholds) == pytest.approx(expected, abs=1e-12)


def test_public_bad_pix_default_threshold_is_007():
    """Kills a change of `bad_pix`'s default threshold (0.07 px, the benchmark's headline metric)."""
    gt = np.zeros((1, 5), dtype=F32)
    pred = np.array([[0.05, 0.1, 0.5, 0.8, -0.069]], dtype=F32)
    assert bad_pix(gt, pred) == _ref_badpix(gt, pred, 0.07) == 60.0


@pytest.mark.parametrize("toolkit", [False, True])
def test_fine_thinning_tie_is_good(toolkit):
    """Kills `(gt - pred) > threshold` -> `>=` in fine_thinning."""
    gt, pred = _pairs(THIN_TIES_015 + [(0.5, 0.3), (0.0, 0.0)])  # gt - pred: 3 ties, 0.2 (thinning), 0
    assert fine_thinning(gt, pred, toolkit=toolkit) == pytest.approx(20.0)
    assert fine_fattening(gt, pred, toolkit=toolkit) == 0.0


@pytest.mark.parametrize("toolkit", [False, True])
def test_fine_fattening_tie_is_good(toolkit):
    """Kills `(gt - pred) < -threshold` -> `<=` in fine_fattening."""
    gt, pred = _pairs(FAT_TIES_015 + [(0.0, 0.2), (0.0, 0.0)])  # gt - pred: 3 ties, -0.2 (fattening), 0
    assert fine_fattening(gt, pred, toolkit=toolkit) == pytest.approx(20.0)
    assert fine_thinning(gt, pred, toolkit=toolkit) == 0.0


def test_fine_fattening_is_not_symmetric_with_thinning():
    """Kills a sign swap in fine_fattening (e.g. `gt - pred` -> `pred - gt`, or `< -t` -> `> t`): a
    prediction nearer than the ground truth (pred > gt) fattens, one farther away does not."""
    gt = np.zeros((2, 4), dtype=F32)
    pred = np.array([[0.2, 0.3, 0.16, 0.1], [-0.2, -0.3, -0.16, 0.0]], dtype=F32)
    # fattening (gt - pred < -0.15): 0.2, 0.3, 0.16 of 8; thinning (gt - pred > 0.15): -0.2, -0.3, -0.16
    assert fine_fattening(gt[:1], pred[:1]) == 75.0 and fine_thinning(gt[:1], pred[:1]) == 0.0
    assert fine_fattening(gt[:1], pred[1:]) == 0.0 and fine_thinning(gt[:1], pred[1:]) == 75.0
    assert get_metric("fine_fattening")(gt, pred) == pytest.approx(37.5)
    assert get_metric("fine_thinning")(gt, np.abs(pred)) == 0.0


@pytest.mark.parametrize("toolkit", [False, True])
def test_backgammon_prediction_exactly_half_way_is_neither_fattening_nor_thinning(toolkit):
    """Kills `pred > half` -> `>=` in backgammon_fattening and `pred < half` -> `<=` in thinning: the
    toolkit counts a pixel only when it is strictly nearer to the other layer than half way."""
    gt = np.zeros((4, 8), dtype=F32)
    gt[:, 2] = 1.0  # foreground at column 2 (half way from 0: 0.5); background at column 7 (0)
    gt[:, 4:6] = np.array([0.5, 1.5, 2.5, 3.5], dtype=F32)[:, None]  # bar pixels: half way to 0 = gt / 2
    fat_mask = _box((4, 8), 0, 4, 6, 7)  # background pixels, gt 0
    thin_mask = _box((4, 8), 0, 4, 4, 6)  # bar pixels
    pred = gt.copy()
    pred[:, 6] = [0.5, 0.5, 0.5000001, 0.4999999]  # ties, one beyond, one short
    pred[:, 4] = gt[:, 4] / 2  # exactly half way: ties
    pred[0, 5] = 0.2  # < 0.25 (half way from 0.5 to 0): thinning
    assert backgammon_fattening(gt, pred, fat_mask, fg_column=2, toolkit=toolkit) == 25.0
    assert backgammon_thinning(gt, pred, thin_mask, bg_column=7, toolkit=toolkit) == 12.5


# --------------------------------------------------------------------------- 5. missed dots

def _one_box_four_dots() -> tuple[np.ndarray, np.ndarray]:
    """One box over a 6x12 image; dots labelled 1..4, 2x2 px each, at columns 0, 3, 6, 9 (rows 2-3)."""
    boxes = np.ones((6, 12), dtype=np.int32)
    dots = np.zeros((6, 12), dtype=np.int32)
    for label, col in zip((1, 2, 3, 4), (0, 3, 6, 9), strict=True):
        dots[2:4, col:col + 2] = label
    return boxes, dots


def _ref_missed_dots(gt, pred, boxes, dots, labels=(1, 2, 3, 4)) -> float:
    """The toolkit's rule by hand: a dot (one label in one box) is missed when BadPix(0.4) >= 50 % on it."""
    missed = n_dots = 0
    for box in np.unique(boxes[boxes > 0]):
        for label in labels:
            px = (boxes == box) & (dots == label)
            if not px.any():
                continue
            n_dots += 1
            missed += _ref_badpix(gt[px][None], pred[px][None], 0.4) >= 50.0
    return 100.0 * missed / n_dots


def test_missed_dots_threshold_is_04_and_strict():
    """Kills the per-dot threshold 0.4 -> 0.3 (errors between 0.3 and 0.4 are not bad) and
    `abs(gt - pred) > threshold` -> `>=` (an error of exactly float32(0.4) is not bad)."""
    boxes, dots = _one_box_four_dots()
    gt = np.zeros(boxes.shape, dtype=F32)
    pred = gt.copy()
    pred[dots == 1] = 0.35  # dot 1: every pixel off by 0.35: detected
    pred[dots == 1] *= np.array([1, 1, 1.1, 1.1], dtype=F32)  # 0.35 and 0.385, still < 0.4
    (r2, c2) = np.nonzero(dots == 2)
    for (g, p), r, c in zip(TIES_04, r2, c2, strict=True):  # dot 2: every pixel a tie at 0.4: detected
        gt[r, c], pred[r, c] = g, p
    pred[2, 6:8] = 0.45  # dot 3: half of it off by 0.45: missed (BadPix exactly 50 %)
    assert _ref_missed_dots(gt, pred, boxes, dots) == 25.0
    assert missed_dots(gt, pred, boxes, dots) == 25.0
    assert missed_dots(gt, pred, boxes, dots, toolkit=True) == 25.0


# --------------------------------------------------------------------------- 6. non-finite ground truth

def test_region_metrics_leave_out_nonfinite_ground_truth():
    """Kills dropping `np.isfinite(reference)` from the scored pixels of the percentage metrics: a pixel
    without ground truth is not scored (the toolkit counts it as good: toolkit=True)."""
    nan = np.nan
    gt = np.array([[0.0, nan, 0.0, 0.0]], dtype=F32)
    pred = np.array([[0.2, 0.2, 0.0, 0.0]], dtype=F32)
    assert fine_fattening(gt, pred) == pytest.approx(100 / 3)
    assert fine_fattening(gt, pred, toolkit=True) == 25.0
    assert fine_thinning(gt, -pred) == pytest.approx(100 / 3)
    assert fine_thinning(gt, -pred, toolkit=True) == 25.0
    # backgammon: the reference is half way to the other layer's column, NaN where either gt is NaN
    bg = np.zeros((3, 5), dtype=F32)
    bg[:, 0] = [1.0, nan, 1.0]  # row 1 has no foreground: none of its pixels is scored
    bg[2, 3] = nan
    p = np.full(bg.shape, 0.6, dtype=F32)  # > 0.5 wherever half way is defined
    mask = _box((3, 5), 0, 3, 1, 5)  # 12 pixels, 4 + 1 without a reference
    assert backgammon_fattening(bg, p, mask, fg_column=0) == 100.0
    assert backgammon_fattening(bg, p, mask, fg_column=0, toolkit=True) == pytest.approx(100 * 7 / 12)
    assert backgammon_thinning(bg, np.zeros_like(p), mask, bg_column=0) == pytest.approx(100.0)
    assert backgammon_thinning(bg, np.zeros_like(p), mask, bg_column=0, toolkit=True) == pytest.approx(100 * 7 / 12)


def test_missed_dots_leave_out_nonfinite_ground_truth():
    """Kills dropping `np.isfinite(gt)` from the scored dot pixels: a dot with 2 pixels of unknown
    depth and 1 bad of the other 2 is 50 % bad (missed), not 25 %."""
    boxes, dots = _one_box_four_dots()
    gt = np.zeros(boxes.shape, dtype=F32)
    pred = gt.copy()
    gt[2, 0:2] = np.nan
    pred[3, 0] = 1.0
    assert missed_dots(gt, pred, boxes, dots) == 25.0
    assert missed_dots(gt, pred, boxes, dots, toolkit=True) == 0.0  # NaN compares good: 1 of 4


def test_mae_and_bumpiness_leave_out_nonfinite_ground_truth():
    """Kills dropping the ground-truth condition of MAE's and bumpiness's scored pixels: where the
    ground truth has no normal (no Hessian), the prediction is not scored, not given 180 deg (0.05)."""
    gt = np.full((16, 16), 0.5, dtype=F32)
    gt[8, 8] = np.nan  # spoils the 3x3 normals (5x5 Hessians) around it
    pred = np.full((16, 16), 0.8, dtype=F32)  # finite; a constant offset wherever gt is known
    mask = _box(16, 7, 11, 7, 11)  # 16 pixels, 9 of them without a ground-truth normal
    params = scene_parameters("s", "training", 16)
    assert median_angular_error(gt, pred, params, mask) == pytest.approx(0.0, abs=1e-6)
    bump_mask = _box(16, 3, 13, 3, 13)  # 100 pixels, 25 within 2 px of the NaN
    assert bumpiness_x100(gt, pred, bump_mask) == pytest.approx(0.0, abs=1e-4)
    y, _ = np.mgrid[0:16, 0:16].astype(np.float64)
    curved = (0.5 * 0.005 * y * y).astype(F32)  # bumpiness 2.0 where scored
    assert bumpiness_x100(gt, pred + curved, bump_mask) == pytest.approx(2.0, rel=1e-4)


# --------------------------------------------------------------------------- 2. precision

def test_bumpiness_takes_the_difference_in_float32():
    """Kills taking bumpiness's difference in float64 (`pred - gt` of float32 maps rounds; the toolkit's
    get_bumpiness subtracts float32 arrays, then filters in float64). Reference: the toolkit's formula
    with scikit-image's Scharr filters."""
    y, x = np.mgrid[0:24, 0:24].astype(np.float64)
    gt = (1.2 + 0.3 * np.sin(x / 5.0) * np.cos(y / 7.0)).astype(F32)  # in [0.9, 1.5]: ulp ~1e-7
    pred = (0.01 * np.sin(x / 3.0) + 0.002 * y).astype(F32)  # small: pred - gt rounds in float32
    mask = _box(24, 4, 20, 4, 20)

    def toolkit(diff: np.ndarray) -> float:
        dx, dy = skf.scharr_v(diff), skf.scharr_h(diff)
        norm = np.sqrt(skf.scharr_v(dx) ** 2 + skf.scharr_h(dx) ** 2 + skf.scharr_h(dy) ** 2 + skf.scharr_v(dy) ** 2)
        return 100 * float(np.mean(np.clip(norm, 0, 0.05)[mask]))

    ref32 = toolkit(np.asarray(pred - gt, dtype=np.float64))
    ref64 = toolkit(pred.astype(np.float64) - gt.astype(np.float64))
    assert 0 < ref32 < 5 and abs(ref32 - ref64) > 1e-8 * ref32  # the case tells the two apart
    assert bumpiness_x100(gt, pred, mask) == pytest.approx(ref32, rel=1e-12)


N = 40  # scene size: 10 x 10 pixels inside the 15 px border (100 x 100 of 400 x 400 at high resolution)


def test_score_scene_scores_in_float32(tmp_path):
    """Kills casting the prediction to float64 in score_scene (or dropping its cast to float32): the
    toolkit's difference of two float32 maps is exactly float32(0.07) here (not bad), 0.0700000003 in
    float64 (bad). A float64 prediction is scored as the float32 map it would be written as."""
    g, p = TIES_007[-1]
    folder = write_scene(tmp_path, "toy", size=N, views=False, gt=np.full((N, N), g, dtype=F32))
    pred = np.full((N, N), p, dtype=F32)
    assert np.float64(F32(p)) - np.float64(F32(g)) > 0.07  # bad if the difference were taken in float64
    expected = _ref_badpix(np.full((N, N), g, F32), pred, 0.07)
    assert expected == 0.0
    for given in (pred, pred.astype(np.float64)):
        score = score_scene(HCIScene(folder), given)
        assert score.values["badpix_0.07"] == expected
        assert score.values["badpix_0.03"] == 100.0


# --------------------------------------------------------------------------- 3. region masks and the border

def test_region_mask_is_combined_with_the_border_and_the_valid_mask(tmp_path):
    """Kills `mask &= region` -> `mask = region` (the border and valid_mask.png dropped) and dropping
    `mask &= valid`: the region mask reaches into the 15 px border, where the prediction is wrong."""
    region = _box(N, 0, 25, 0, 25)  # 625 px; inside the border: rows/cols 15..24 (100 px)
    folder = write_scene(tmp_path, "toy", size=N, views=False, gt=np.zeros((N, N), F32),
                         masks={"mask_discontinuities_lowres": region})
    valid = np.ones((N, N), dtype=bool)
    valid[15:17, :] = False  # 20 more pixels of the region not to score
    Image.fromarray(np.where(valid, 255, 0).astype(np.uint8)).save(folder / "valid_mask.png")
    pred = np.zeros((N, N), dtype=F32)
    pred[:15, :] = 0.5  # wrong only in the border...
    pred[:, :15] = 0.5
    pred[15:17, 15:25] = 0.5  # ... where the valid mask is False ...
    pred[20:22, 15:25] = 0.1  # ... and on 20 of the 80 scored pixels
    scored = region & valid & _box(N, 15, N - 15, 15, N - 15)
    assert scored.sum() == 80
    expected = _ref_badpix(np.zeros((N, N), F32), pred, 0.07, scored)
    assert expected == 25.0
    metrics = applicable_metrics(HCIScene(folder))
    assert "discontinuities" in [m.id for m in metrics]
    score = score_scene(HCIScene(folder), pred, metrics)
    assert score.values["discontinuities"] == expected
    assert score.values["badpix_0.07"] == pytest.approx(100 * 20 / 80)  # general: border & valid
    assert score.values["mse_x100"] == pytest.approx(100 * 20 * np.float32(0.1) ** 2 / 80, rel=1e-6)


# --------------------------------------------------------------------------- 4. backgammon at high resolution

FG_COL_HI = 140  # int(14 * 10): the toolkit scales the foreground column
BG_COL_HI = 400 - 11  # width - 11: the toolkit does not scale the background column


def _backgammon_highres(tmp_path) -> tuple[Scene, np.ndarray, np.ndarray, np.ndarray]:
    """A 40x40 'backgammon' scene with a 400x400 gt_disp_highres.pfm: a foreground bar (gt 1) at high-res
    columns 150..199, background (gt 0) at 200..249. The reference columns hold values no other candidate
    column holds: 140 = int(14 * 10) the foreground (1.0), every other column left of the bar 2.0 (14
    unscaled, 29 = 40 - 11 of the low-res width, 126 = 14 * 9, ...); 389 = 400 - 11 (the toolkit does not
    scale it) the background (0.0), every other column right of 249 0.9 (290 = 400 - 110, 399, ...)."""
    scale = 10
    hi = np.full((N * scale, N * scale), 2.0, dtype=F32)
    hi[:, 150:200] = 1.0  # the bar
    hi[:, 200:250] = 0.0  # the background scored beside it
    hi[:, 250:] = 0.9
    hi[:, FG_COL_HI] = 1.0
    hi[:, BG_COL_HI] = 0.0
    fat = np.zeros(hi.shape, dtype=bool)
    fat[100:260, 200:260] = True  # background beside the bar, reaching into the 150 px border
    thin = np.zeros(hi.shape, dtype=bool)
    thin[100:260, 150:200] = True  # the bar, reaching into the border
    low_gt = hi[::scale, ::scale].copy()
    folder = write_scene(tmp_path, "backgammon", "stratified", size=N, views=False, gt=low_gt, gt_highres=hi,
                         masks={"mask_foreground_fattening_highres": fat, "mask_foreground_thinning_highres": thin,
                                "mask_foreground_fattening_lowres": fat[::scale, ::scale],
                                "mask_foreground_thinning_lowres": thin[::scale, ::scale]})
    return HCIScene(folder), hi, fat, thin


def test_backgammon_metrics_at_high_resolution(tmp_path):
    """Kills the foreground column not scaled (14 instead of int(14 * scale)), scaled by the wrong
    side or rounded differently, the background column scaled (width - 110) or taken from the
    low-res width, and the high-res border not scaled: score_scene on a high-res scene against the
    toolkit's formula (half way to the gt at the reference column of each row, strictly beyond)."""
    scene, hi, fat, thin = _backgammon_highres(tmp_path)
    pred = np.zeros((N, N), dtype=F32)
    pred[:, 15:20] = 1.0
    pred[15:20, 20:22] = 0.6  # fattening (> 0.5) on 50 rows x 20 columns of the scored background
    pred[15:17, 22:25] = 1.6  # fattening, and beyond half way to 2.0 as well
    pred[10:15, 20:25] = 0.9  # in the border only
    pred[15:18, 15:17] = 0.4  # thinning (< 0.5) on 30 x 20 px of the scored bar
    pred[20:25, 17:20] = 0.6  # not thinning (>= 0.5), but < 0.95 (half way to 0.9)
    up = _toolkit_upsample(pred, 10)
    border = _box(N * 10, 150, 250, 150, 250)
    with np.errstate(invalid="ignore"):
        fat_bad = up > 0.5 * (hi[:, FG_COL_HI:FG_COL_HI + 1].astype(np.float64) + hi)
        thin_bad = up < 0.5 * (hi[:, BG_COL_HI:BG_COL_HI + 1].astype(np.float64) + hi)
    expected_fat = 100.0 * np.count_nonzero(fat_bad & fat & border) / np.count_nonzero(fat & border)
    expected_thin = 100.0 * np.count_nonzero(thin_bad & thin & border) / np.count_nonzero(thin & border)
    # by hand with 10 x 10 blocks: 50 x 20 + 20 x 30 of 100 x 50 fattened, 30 x 20 of 100 x 50 thinned
    # (zoom's block edges move the counts by a few rows or columns of pixels)
    assert expected_fat == pytest.approx(32.0, abs=1.0) and expected_thin == pytest.approx(12.0, abs=1.0)
    metrics = applicable_metrics(scene)
    score = score_scene(scene, pred, metrics)
    assert score.resolution["backgammon_fattening"] == score.resolution["backgammon_thinning"] == "highres"
    assert score.values["backgammon_fattening"] == pytest.approx(expected_fat, rel=1e-12)
    assert score.values["backgammon_thinning"] == pytest.approx(expected_thin, rel=1e-12)
    # the same metrics as functions of the high-res maps (Metric.__call__, without the scoring engine's pixel
    # sets): they find their columns on their own (int(14 x scale) from the scene's size, width - 11)
    for metric_id, region, expected in (("backgammon_fattening", fat, expected_fat),
                                        ("backgammon_thinning", thin, expected_thin)):
        value = get_metric(metric_id)(hi, up, region & border, scene=scene, resolution="highres")
        assert value == pytest.approx(expected, rel=1e-12)
    assert score.resolution["badpix_0.07"] == "highres"  # backgammon's general metrics are high-res too
    bad = np.abs(up - hi) > F32(0.07)  # the toolkit's BadPix, vectorised (float32 on both sides)
    assert score.values["badpix_0.07"] == 100.0 * np.count_nonzero(bad & border) / np.count_nonzero(border)

