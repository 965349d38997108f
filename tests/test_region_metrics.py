"""Region and stratified metrics: hand-computed cases, the toolkit's definitions, and which metrics
apply to which scene (skipped when their mask files are absent)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import skimage.filters as skf
from PIL import Image

from lfbench.data.hci import HCIDataset, HCIScene
from lfbench.data.hci.params import SceneParameters
from lfbench.data.pfm import write_pfm
from lfbench.data.scene import Scene
from lfbench.scoring.metrics import GENERAL_METRICS, get_metric
from lfbench.scoring.prepare import read_label_mask
from lfbench.scoring.region_metrics import (
    REGION_METRICS,
    STRATIFIED_METRICS,
    angular_error_deg,
    backgammon_fattening,
    backgammon_thinning,
    bumpiness_map,
    bumpiness_x100,
    depth_normals,
    fine_fattening,
    fine_thinning,
    median_angular_error,
    missed_dots,
    scharr_derivative,
)
from lfbench.scoring.rules import ScoringRules, metric_resolution
from lfbench.scoring.score import applicable_metrics, score_scene
from lfbench.utils.errors import DataError

GENERAL_IDS = [m.id for m in GENERAL_METRICS]
PARAMS = SceneParameters(focal_length_mm=100.0, image_resolution_x_px=32, image_resolution_y_px=32,
                         sensor_size_mm=35.0, num_cams_x=9, num_cams_y=9, baseline_mm=100.0, focus_distance_m=7.0)


def _grid(n: int = 24) -> tuple[np.ndarray, np.ndarray]:
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)
    return y, x


def _interior(n: int, b: int = 3) -> np.ndarray:
    m = np.zeros((n, n), dtype=bool)
    m[b:n - b, b:n - b] = True
    return m


# --------------------------------------------------------------------------- Scharr and bumpiness

def test_scharr_derivative_matches_scikit_image_in_the_interior():
    img = np.random.default_rng(1).normal(size=(20, 17))
    assert np.allclose(scharr_derivative(img, 0)[1:-1, 1:-1], skf.scharr_h(img)[1:-1, 1:-1], atol=1e-12)
    assert np.allclose(scharr_derivative(img, 1)[1:-1, 1:-1], skf.scharr_v(img)[1:-1, 1:-1], atol=1e-12)
    # twice the slope of a ramp; the toolkit-era outer ring is zero
    y, x = _grid(8)
    d = scharr_derivative(3.0 * x, axis=1)
    assert np.allclose(d[1:-1, 1:-1], 6.0) and not d[0].any() and not d[:, -1].any()


def test_bumpiness_perfect_constant_and_planar_offsets_are_zero():
    y, x = _grid()
    gt = (0.3 + 0.01 * x - 0.02 * y + 0.001 * x * x).astype(np.float32)
    mask = _interior(24)
    assert bumpiness_x100(gt, gt, mask) == 0.0
    assert bumpiness_x100(gt, gt + np.float32(0.5), mask) == pytest.approx(0.0, abs=1e-4)  # float32 rounding
    planar = (gt + 0.05 * x - 0.03 * y + 1.0).astype(np.float32)
    assert bumpiness_x100(gt, planar, mask) == pytest.approx(0.0, abs=1e-4)


@pytest.mark.parametrize("a, expected", [(0.005, 2.0), (0.01, 4.0), (0.02, 5.0)])
def test_bumpiness_of_a_parabola_is_four_times_its_curvature_clipped(a, expected):
    # diff = a y^2 / 2: each Scharr pass doubles, so d2/dy2 reads 4a; 100 * min(4a, 0.05)
    y, _ = _grid()
    gt = np.zeros((24, 24))
    assert bumpiness_x100(gt, 0.5 * a * y * y, _interior(24)) == pytest.approx(expected, rel=1e-9)


def test_bumpiness_of_a_saddle_counts_both_mixed_derivatives():
    # diff = c x y: d2/dxdy and d2/dydx each read 4c, norm 4c sqrt(2)
    y, x = _grid()
    c = 0.005
    expected = 100 * 4 * c * math.sqrt(2)
    assert bumpiness_x100(np.zeros((24, 24)), c * x * y, _interior(24)) == pytest.approx(expected, rel=1e-9)


def test_bumpiness_map_matches_the_toolkit_formula_with_scikit_image():
    rng = np.random.default_rng(2)
    gt = rng.normal(size=(30, 30)).astype(np.float32)
    pred = (gt + rng.normal(scale=0.01, size=gt.shape)).astype(np.float32)
    diff = np.asarray(pred - gt, dtype=np.float64)
    dx, dy = skf.scharr_v(diff), skf.scharr_h(diff)
    ref = np.sqrt(skf.scharr_v(dx) ** 2 + skf.scharr_h(dx) ** 2 + skf.scharr_h(dy) ** 2 + skf.scharr_v(dy) ** 2)
    assert np.allclose(bumpiness_map(gt, pred)[2:-2, 2:-2], np.clip(ref, 0, 0.05)[2:-2, 2:-2], atol=1e-12)


def test_bumpiness_nonfinite_prediction_is_the_clip_value_or_left_out():
    gt = np.zeros((20, 20), dtype=np.float32)
    pred = gt.copy()
    pred[10, 10] = np.nan  # spoils the 5x5 pixels around it
    mask = _interior(20)  # 14 x 14 = 196 pixels
    assert bumpiness_x100(gt, pred, mask) == pytest.approx(100 * 25 * 0.05 / 196)
    assert bumpiness_x100(gt, pred, mask, toolkit=True) == 0.0
    gt_nan = gt.copy()
    gt_nan[10, 10] = np.nan  # ground truth undefined there: those pixels are not scored
    assert bumpiness_x100(gt_nan, gt_nan, mask) == 0.0


# --------------------------------------------------------------------------- normals and MAE

def test_fronto_parallel_depth_has_normals_facing_the_camera():
    n = depth_normals(np.full((9, 9), 4.0), 100.0, 35.0)
    assert np.allclose(n[1:-1, 1:-1], [0.0, 0.0, -1.0])


def test_mae_of_a_constant_offset_on_a_fronto_parallel_plane_is_zero():
    gt = np.full((32, 32), 0.5, dtype=np.float32)
    assert median_angular_error(gt, gt + np.float32(0.3), PARAMS, _interior(32)) == pytest.approx(0.0, abs=1e-6)


def test_mae_of_a_slanted_plane_against_a_fronto_parallel_one_is_its_tilt():
    # depth Z = Z0 + m * col (m per px). With the toolkit's camera X = k col Z, Y = k row Z,
    # k = 0.5 s / (f (W - 1)): the column tangent is (k (Z + m col), k row m, m), the row tangent
    # (0, k Z, 0), so the normal is ~ (m, 0, -k (Z0 + 2 m col)): tilt atan(m / (k (Z0 + 2 m col))).
    z0, m, col = 5.0, 0.01, 16
    _, x = _grid(32)
    gt = PARAMS.depth_to_disparity(z0 + m * x)
    pred = np.full_like(gt, float(PARAMS.depth_to_disparity(np.array(z0))))
    mask = np.zeros((32, 32), dtype=bool)
    mask[2:30, col] = True
    k = 0.5 * 35.0 / (100.0 * 31)
    expected = math.degrees(math.atan(m / (k * (z0 + 2 * m * col))))
    assert expected == pytest.approx(18.4, abs=0.05)
    # depth comes from float32 disparities in float32 (the toolkit's disp2depth): the tangents are
    # differences of float32 depths, so the angle matches the exact one to ~1e-5 relative
    assert median_angular_error(gt, pred, PARAMS, mask) == pytest.approx(expected, rel=1e-4)
    # the same angle whichever map is the ground truth
    assert median_angular_error(pred, gt, PARAMS, mask) == pytest.approx(expected, rel=1e-4)


def test_angular_error_of_perpendicular_normals_is_90_degrees():
    a = np.zeros((1, 1, 3))
    b = np.zeros((1, 1, 3))
    a[..., 0] = 1.0
    b[..., 2] = -1.0
    assert angular_error_deg(a, b)[0, 0] == pytest.approx(90.0)


def test_mae_nonfinite_prediction_is_180_degrees_or_left_out():
    gt = np.full((16, 16), 0.5, dtype=np.float32)
    pred = gt.copy()
    pred[8, 8] = np.nan  # spoils the 3x3 normals around it
    mask = np.zeros((16, 16), dtype=bool)
    mask[7:11, 7:11] = True  # 16 pixels, 9 spoiled: the median is 180
    assert median_angular_error(gt, pred, PARAMS, mask) == 180.0
    assert median_angular_error(gt, pred, PARAMS, mask, toolkit=True) == pytest.approx(0.0, abs=1e-6)


# --------------------------------------------------------------------------- fattening / thinning

def test_fine_fattening_and_thinning_count_signed_errors_beyond_015():
    gt = np.zeros((2, 4), dtype=np.float32)
    pred = np.array([[0.2, 0.1, -0.2, -0.1], [0.16, -0.16, 0.0, np.nan]], dtype=np.float32)
    # fattening (pred nearer, gt - pred < -0.15): 0.2, 0.16 (+ NaN as bad) of 8
    assert fine_fattening(gt, pred) == pytest.approx(100 * 3 / 8)
    assert fine_fattening(gt, pred, toolkit=True) == pytest.approx(100 * 2 / 8)
    # thinning (pred farther, gt - pred > 0.15): -0.2, -0.16 (+ NaN)
    assert fine_thinning(gt, pred) == pytest.approx(100 * 3 / 8)
    assert fine_thinning(gt, pred, toolkit=True) == pytest.approx(100 * 2 / 8)
    mask = np.zeros_like(gt, dtype=bool)
    mask[0] = True  # first row: fattening 0.2 only (1 of 4)
    assert fine_fattening(gt, pred, mask) == pytest.approx(25.0)
    assert fine_fattening(gt, gt) == 0.0 and fine_thinning(gt, gt) == 0.0


def _backgammon_gt(h: int = 6, w: int = 40) -> np.ndarray:
    """Background 0, a foreground bar at columns 10..19 whose disparity is 1 + 0.1 * row."""
    gt = np.zeros((h, w), dtype=np.float32)
    gt[:, 10:20] = (1.0 + 0.1 * np.arange(h))[:, None]
    return gt


def test_backgammon_fattening_uses_the_foreground_of_each_row():
    gt = _backgammon_gt()
    mask = np.zeros(gt.shape, dtype=bool)
    mask[:, 20:22] = True  # 12 background pixels beside the bar
    pred = gt.copy()
    # half way to the foreground is 0.5 + 0.05 row: row 0 at 0.55 is fattening, row 5 at 0.55 (< 0.75) is not
    pred[0, 20] = 0.55
    pred[5, 20] = 0.55
    pred[3, 21] = 0.7  # > 0.65: fattening
    assert backgammon_fattening(gt, pred, mask, fg_column=14) == pytest.approx(100 * 2 / 12)
    assert backgammon_fattening(gt, gt, mask, fg_column=14) == 0.0


def test_backgammon_thinning_uses_the_background_column():
    gt = _backgammon_gt()
    mask = np.zeros(gt.shape, dtype=bool)
    mask[:, 10:20] = True  # 60 bar pixels; background column w - 11 = 29 holds 0
    pred = gt.copy()
    pred[0, 12] = 0.45  # < 0.5: thinning
    pred[5, 12] = 0.7  # < 0.75: thinning
    pred[5, 13] = 0.8  # >= 0.75: not
    pred[2, 15] = np.nan  # bad by default, good for the toolkit
    assert backgammon_thinning(gt, pred, mask, bg_column=29) == pytest.approx(100 * 3 / 60)
    assert backgammon_thinning(gt, pred, mask, bg_column=29, toolkit=True) == pytest.approx(100 * 2 / 60)


# --------------------------------------------------------------------------- dots

def _dots_layout() -> tuple[np.ndarray, np.ndarray]:
    """One box over an 8x12 image; dots labelled 1, 2, 3 (2x2 px each) and a label-9 dot (ignored)."""
    boxes = np.ones((8, 12), dtype=np.int32)
    dots = np.zeros((8, 12), dtype=np.int32)
    dots[1:3, 1:3] = 1
    dots[1:3, 5:7] = 2
    dots[5:7, 1:3] = 3
    dots[5:7, 8:10] = 9
    return boxes, dots


def test_missed_dots_one_of_three():
    boxes, dots = _dots_layout()
    gt = np.full(boxes.shape, 0.2, dtype=np.float32)
    pred = gt.copy()
    pred[1:3, 5:7] = 1.0  # dot 2 entirely wrong
    pred[5, 1] = 1.0  # dot 3: 1 of 4 pixels wrong (25 %): detected
    pred[5:7, 8:10] = 1.0  # label 9 is not scored
    assert missed_dots(gt, pred, boxes, dots) == pytest.approx(100 / 3)
    assert missed_dots(gt, gt, boxes, dots) == 0.0


def test_a_box_mask_without_label_0_scores_every_label_as_a_box():
    """docs/benchmark-rules.md: the toolkit stops with a ValueError on a box mask without label 0; lfbench scores
    each non-zero label as a box, exactly as with a label-0 background around the dots."""
    boxes, dots = _dots_layout()
    assert not (boxes == 0).any()
    gt = np.full(boxes.shape, 0.2, dtype=np.float32)
    pred = gt.copy()
    pred[1:3, 5:7] = 1.0
    framed = boxes.copy()
    framed[0, :] = framed[:, 0] = 0  # a background row and column that touches no dot pixel's box
    framed[:, 11] = 0
    assert missed_dots(gt, pred, boxes, dots) == missed_dots(gt, pred, framed, dots) == pytest.approx(100 / 3)
    for toolkit in (False, True):
        assert missed_dots(gt, pred, boxes, dots, toolkit=toolkit) == missed_dots(gt, pred, framed, dots,
                                                                                  toolkit=toolkit)


def test_missed_dots_half_bad_is_missed_and_nan_rule():
    boxes, dots = _dots_layout()
    gt = np.zeros(boxes.shape, dtype=np.float32)
    pred = gt.copy()
    pred[1, 1:3] = 0.5  # dot 1: exactly 50 % bad -> missed
    pred[1, 5:7] = np.nan  # dot 2: 50 % NaN -> missed by default, detected by the toolkit
    assert missed_dots(gt, pred, boxes, dots) == pytest.approx(200 / 3)
    assert missed_dots(gt, pred, boxes, dots, toolkit=True) == pytest.approx(100 / 3)


def test_missed_dots_over_two_boxes_and_an_empty_pair():
    boxes, dots = _dots_layout()
    boxes[:, 6:] = 2  # box 2 holds dot 2's right half only; it has no dot 1 or 3
    gt = np.zeros(boxes.shape, dtype=np.float32)
    pred = gt.copy()
    pred[1:3, 6] = 1.0  # dot 2 in box 2 (2 px) fully wrong
    # dots: (1,1), (1,2), (1,3), (2,2) -> 1 of 4 missed; the toolkit counts the 2 empty pairs as missed too
    assert missed_dots(gt, pred, boxes, dots) == pytest.approx(25.0)
    assert missed_dots(gt, pred, boxes, dots, toolkit=True) == pytest.approx(100 * 3 / 6)


def test_read_label_mask(tmp_path):
    arr = np.array([[0, 1, 2], [3, 0, 8]], dtype=np.uint8)
    Image.fromarray(arr).save(tmp_path / "gray.png")
    assert np.array_equal(read_label_mask(tmp_path / "gray.png"), arr)
    Image.fromarray(np.stack([arr] * 3, axis=-1)).save(tmp_path / "rgb.png")
    assert np.array_equal(read_label_mask(tmp_path / "rgb.png"), arr)
    Image.fromarray(np.stack([arr, arr, arr + 1], axis=-1)).save(tmp_path / "colour.png")
    with pytest.raises(DataError, match="colour"):
        read_label_mask(tmp_path / "colour.png")
    with pytest.raises(DataError):
        read_label_mask(tmp_path / "missing.png")


# --------------------------------------------------------------------------- scenes on disk

N = 64  # scene size: 34 x 34 pixels inside the 15 px border


def _write_mask(path: Path, mask: np.ndarray) -> None:
    Image.fromarray(np.where(mask, 255, 0).astype(np.uint8)).save(path)


def _make_scene(root: Path, category: str, name: str, gt: np.ndarray, masks: dict[str, np.ndarray] | None = None,
                gt_highres: np.ndarray | None = None, labels: dict[str, np.ndarray] | None = None) -> Scene:
    """An HCI-layout scene without views: parameters.cfg, gt, masks named '<mask>_<res>' -> bool array."""
    path = root / category / name
    path.mkdir(parents=True)
    cfg = SceneParameters(focal_length_mm=100.0, image_resolution_x_px=N, image_resolution_y_px=N,
                          sensor_size_mm=35.0, num_cams_x=9, num_cams_y=9, baseline_mm=100.0,
                          focus_distance_m=7.0, disp_min=-1.0, disp_max=1.0, name=name, category=category)
    (path / "parameters.cfg").write_text(cfg.to_cfg())
    write_pfm(path / "gt_disp_lowres.pfm", gt.astype(np.float32))
    if gt_highres is not None:
        write_pfm(path / "gt_disp_highres.pfm", gt_highres.astype(np.float32))
    for key, mask in (masks or {}).items():
        _write_mask(path / f"{key}.png", mask)
    for key, arr in (labels or {}).items():
        Image.fromarray(arr.astype(np.uint8)).save(path / f"{key}.png")
    return HCIScene(path, category=category)


def _box(y0: int, y1: int, x0: int, x1: int, n: int = N) -> np.ndarray:
    m = np.zeros((n, n), dtype=bool)
    m[y0:y1, x0:x1] = True
    return m


def test_real_scenes_without_masks_score_only_the_general_metrics(hci_root):
    for scene in HCIDataset.open(hci_root):
        metrics = applicable_metrics(scene)
        assert [m.id for m in metrics] == GENERAL_IDS, scene.name
        gt = scene.gt_disparity()
        score = score_scene(scene, gt, metrics)
        assert sorted(score.values) == sorted(GENERAL_IDS)


def test_photorealistic_scene_gets_the_region_metrics_whose_masks_exist(tmp_path):
    gt = np.zeros((N, N), dtype=np.float32)
    scene = _make_scene(tmp_path, "training", "toy", gt, masks={
        "mask_planes_lowres": _box(20, 40, 20, 40),
        "mask_discontinuities_lowres": _box(20, 30, 20, 30),  # 100 pixels, low-res only
        "mask_plane_lowres": _box(0, N, 0, N),  # a pyramids mask: not a photorealistic one
    })
    ids = [m.id for m in applicable_metrics(scene)]
    assert ids == GENERAL_IDS + ["discontinuities", "bumpiness_planes", "mae_planes"]
    pred = gt.copy()
    pred[20:30, 20:27] = 0.1  # 70 of the 100 discontinuity pixels off by 0.1 > 0.07
    score = score_scene(scene, pred, applicable_metrics(scene))
    assert score.values["discontinuities"] == pytest.approx(70.0)
    assert score.resolution["discontinuities"] == "lowres"  # a high-res metric without high-res data
    assert score.resolution["bumpiness_planes"] == "lowres"
    perfect = score_scene(scene, gt, applicable_metrics(scene))
    assert perfect.values["bumpiness_planes"] == 0.0
    assert perfect.values["mae_planes"] == pytest.approx(0.0, abs=1e-6)
    assert "fine_fattening" not in score.values and "pyramids_bumpiness_parallel" not in score.values


def test_highres_region_metric_uses_highres_gt_and_mask_when_present(tmp_path):
    gt = np.zeros((N, N), dtype=np.float32)
    hi = np.zeros((10 * N, 10 * N), dtype=np.float32)
    fine_hi = np.zeros((10 * N, 10 * N), dtype=bool)
    fine_hi[200:300, 200:300] = True  # 10000 high-res pixels = low-res pixels 20..29
    hi[200:300, 200:250] = 1.0  # gt says half of the fine structure is at 1.0
    scene = _make_scene(tmp_path, "training", "fine", gt, gt_highres=hi,
                        masks={"mask_fine_highres": fine_hi, "mask_fine_lowres": _box(20, 30, 20, 30)})
    pred = np.zeros((N, N), dtype=np.float32)  # misses the structure: gt - pred = 1 > 0.15 on half of it
    metrics = applicable_metrics(scene)
    assert "fine_thinning" in [m.id for m in metrics]
    score = score_scene(scene, pred, metrics)
    assert score.resolution["fine_thinning"] == "highres"
    assert score.values["fine_thinning"] == pytest.approx(50.0)
    assert score.resolution["mse_x100"] == "lowres"  # general metrics: only backgammon/dots/stripes go high-res
    low = score_scene(scene, pred, metrics, ScoringRules(allow_highres=False))
    assert low.resolution["fine_thinning"] == "lowres" and low.values["fine_thinning"] == 0.0


def test_a_lowres_metric_is_skipped_when_only_the_highres_mask_exists(tmp_path):
    gt = np.zeros((N, N), dtype=np.float32)
    scene = _make_scene(tmp_path, "training", "hionly", gt,
                        masks={"mask_planes_highres": np.ones((10 * N, 10 * N), dtype=bool)})
    planes = get_metric("bumpiness_planes")
    assert metric_resolution(scene, planes) is None
    assert [m.id for m in applicable_metrics(scene)] == GENERAL_IDS
    assert "bumpiness_planes" not in score_scene(scene, gt, [*GENERAL_METRICS, planes]).values


def test_stratified_scene_gets_only_its_own_metrics(tmp_path):
    gt = np.zeros((N, N), dtype=np.float32)
    scene = _make_scene(tmp_path, "stratified", "pyramids", gt, masks={
        "mask_plane_lowres": _box(15, 49, 15, 49),
        "mask_sphere_in_lowres": _box(20, 30, 20, 30),
        "mask_sphere_out_lowres": _box(30, 40, 30, 40),
        "mask_planes_lowres": _box(15, 49, 15, 49),  # a photorealistic mask: ignored on a stratified scene
    })
    ids = [m.id for m in applicable_metrics(scene)]
    assert ids == GENERAL_IDS + ["pyramids_bumpiness_parallel"]  # slanted needs mask_pyramids too
    _write_mask(scene.path / "mask_pyramids_lowres.png", _box(40, 45, 40, 45))
    ids = [m.id for m in applicable_metrics(scene)]
    assert ids == GENERAL_IDS + ["pyramids_bumpiness_slanted", "pyramids_bumpiness_parallel"]
    y, _ = np.mgrid[0:N, 0:N].astype(np.float64)
    pred = (0.5 * 0.005 * y * y).astype(np.float32)  # curvature 0.005 everywhere: bumpiness 2.0
    score = score_scene(scene, pred, applicable_metrics(scene))
    assert score.values["pyramids_bumpiness_slanted"] == pytest.approx(2.0, rel=1e-4)
    assert score.values["pyramids_bumpiness_parallel"] == pytest.approx(2.0, rel=1e-4)
    assert score.resolution["pyramids_bumpiness_slanted"] == "lowres"


def test_backgammon_metrics_through_score_scene(tmp_path):
    gt = np.zeros((N, N), dtype=np.float32)
    gt[:, 10:30] = 1.0  # foreground bar covering column 14; background column 64 - 11 = 53 is 0
    scene = _make_scene(tmp_path, "stratified", "backgammon", gt, masks={
        "mask_foreground_fattening_lowres": _box(20, 40, 30, 35),  # 100 background pixels
        "mask_foreground_thinning_lowres": _box(20, 40, 20, 30),  # 200 bar pixels
    })
    ids = [m.id for m in applicable_metrics(scene)]
    assert ids == GENERAL_IDS + ["backgammon_fattening", "backgammon_thinning"]
    pred = gt.copy()
    pred[20:40, 30:32] = 0.6  # 40 fattening pixels (> 0.5)
    pred[20:30, 20:25] = 0.4  # 50 thinning pixels (< 0.5)
    score = score_scene(scene, pred, applicable_metrics(scene))
    assert score.values["backgammon_fattening"] == pytest.approx(40.0)
    assert score.values["backgammon_thinning"] == pytest.approx(25.0)
    assert score.resolution["backgammon_fattening"] == "lowres"


def test_dots_metrics_through_score_scene(tmp_path):
    gt = np.full((N, N), 0.3, dtype=np.float32)
    boxes = np.zeros((N, N), dtype=np.uint8)
    boxes[16:32, 16:48] = 1
    boxes[32:48, 16:48] = 2
    dots = np.zeros((N, N), dtype=np.uint8)
    for top in (18, 34):
        dots[top:top + 4, 18:22] = 1
        dots[top:top + 3, 26:29] = 2
        dots[top:top + 2, 36:38] = 3
    background = (boxes > 0) & (dots == 0)
    scene = _make_scene(tmp_path, "stratified", "dots", gt, masks={"mask_background_lowres": background},
                        labels={"mask_boxes_lowres": boxes, "mask_dots_by_size_lowres": dots})
    ids = [m.id for m in applicable_metrics(scene)]
    assert ids == GENERAL_IDS + ["dots_background_mse", "missed_dots"]
    pred = gt.copy()
    pred[34:37, 26:29] = 1.0  # dot 2 of box 2 missed: 1 of 6 dots
    pred[background] += 0.1  # background error 0.1: MSE x100 = 1
    score = score_scene(scene, pred, applicable_metrics(scene))
    assert score.values["missed_dots"] == pytest.approx(100 / 6)
    assert score.values["dots_background_mse"] == pytest.approx(1.0, rel=1e-5)
    assert score.resolution["missed_dots"] == "lowres"


def test_metric_descriptors_are_complete_and_unique():
    all_metrics = list(REGION_METRICS) + [m for ms in STRATIFIED_METRICS.values() for m in ms]
    ids = [m.id for m in all_metrics]
    assert len(ids) == len(set(ids)) == 16
    assert not set(ids) & set(GENERAL_IDS)
    for m in all_metrics:
        assert m.description and m.unit and m.toolkit_id and m.required_masks
        assert m.resolution in ("lowres", "highres") and m.category in ("region", "stratified")
        assert get_metric(m.toolkit_id) is m
    assert get_metric("mae_planes").resolution == "lowres"
    assert get_metric("discontinuities").resolution == "highres"


def test_cli_evaluate_all_metrics(tmp_path):
    gt = np.zeros((N, N), dtype=np.float32)
    _make_scene(tmp_path / "data", "training", "toy", gt, masks={"mask_planes_lowres": _box(20, 40, 20, 40)})
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "lfbench", "evaluate", "--data", str(tmp_path / "data"), "--method", "gt",
           "--out", str(out), "--all-metrics", "--no-progress"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    records = {r["metric"]: r for r in json.loads((out / "results.json").read_text())["records"]}
    # and the runtime metrics: the gt method reports the wall time lfbench measured
    assert set(records) == set(GENERAL_IDS) | {"bumpiness_planes", "mae_planes", "runtime", "runtime_log"}
    assert records["bumpiness_planes"]["value"] == 0.0 and records["bumpiness_planes"]["resolution"] == "lowres"
