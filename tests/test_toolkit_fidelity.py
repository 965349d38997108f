"""Region and stratified metrics follow the official toolkit's arithmetic (issue 12, fidelity): each case
restates the toolkit's formula (dtype and order of operations) or is computed by hand."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import scene_parameters
from scipy import signal

from lfbench.scoring.region_metrics import (
    backgammon_fattening,
    backgammon_thinning,
    bumpiness_x100,
    median_angular_error,
    missed_dots,
    toolkit_depth,
)

PARAMS = scene_parameters("s", "training", 64)


def _toolkit_disp2depth(disp: np.ndarray) -> np.ndarray:
    """The toolkit's BaseScene.disp2depth, as written (Python floats with a float32 array stay float32)."""
    q = PARAMS.baseline_mm * PARAMS.focal_length_mm * max(PARAMS.image_resolution_x_px, PARAMS.image_resolution_y_px)
    return 1.0 / ((1000.0 * PARAMS.sensor_size_mm) * disp / q + (1.0 / PARAMS.focus_distance_m))


def _toolkit_normals(depth: np.ndarray) -> np.ndarray:
    """The toolkit's BaseScene.get_depth_normals (square maps), as written."""
    h, w = depth.shape
    zz = depth
    xx, yy = np.meshgrid(range(0, h), range(0, w))
    xx = (xx / (h - 1.0) * 0.5) * PARAMS.sensor_size_mm * zz / PARAMS.focal_length_mm
    yy = (yy / (w - 1.0) * 0.5) * PARAMS.sensor_size_mm * zz / PARAMS.focal_length_mm
    kernel = np.asarray([[3., 10., 3.], [0., 0., 0.], [-3., -10., -3.]]) / 64.
    d = {name: (signal.convolve2d(c, kernel, mode="same", boundary="wrap"),
                signal.convolve2d(c, kernel.T, mode="same", boundary="wrap")) for name, c in (("x", xx), ("y", yy),
                                                                                            ("z", zz))}
    (dxdx, dxdy), (dydx, dydy), (dzdx, dzdy) = d["x"], d["y"], d["z"]
    n = np.stack([dzdx * dxdy - dxdx * dzdy, -(dydx * dzdy - dzdx * dydy), -(dxdx * dydy - dydx * dxdy)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def test_disparity_to_depth_is_the_toolkits_float32_arithmetic():
    rng = np.random.default_rng(0)
    disp = rng.uniform(-2, 2, (64, 64)).astype(np.float32)
    ref = _toolkit_disp2depth(disp)
    assert ref.dtype == np.float32
    got = toolkit_depth(disp, PARAMS)
    assert got.dtype == np.float32 and np.array_equal(got, ref)  # bit for bit
    assert not np.array_equal(got.astype(np.float64), PARAMS.disparity_to_depth(disp))  # float64 differs


def test_mae_matches_the_toolkit_formula():
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:64, 0:64]
    gt = (0.8 + 0.01 * x - 0.02 * y + 0.2 * np.sin(x / 7.0)).astype(np.float32)
    pred = (gt + rng.normal(0, 0.02, gt.shape)).astype(np.float32)
    mask = np.zeros(gt.shape, bool)
    mask[15:-15, 15:-15] = True
    n_pred, n_gt = _toolkit_normals(_toolkit_disp2depth(pred)), _toolkit_normals(_toolkit_disp2depth(gt))
    angle = np.degrees(np.arccos(np.clip(np.sum(n_pred * n_gt, axis=2), -1.0, 1.0)))
    expected = float(np.median(angle[mask & np.isfinite(pred) & np.isfinite(angle)]))
    assert median_angular_error(gt, pred, PARAMS, mask, toolkit=True) == pytest.approx(expected, rel=1e-9)
    assert median_angular_error(gt, pred, PARAMS, mask) == pytest.approx(expected, rel=1e-9)


def _dots():
    """Two boxes (left, right half) holding dots labelled 1, 2, 3 and 5 (no 4): 3 px squares."""
    boxes = np.zeros((20, 40), np.int32)
    boxes[:, :20], boxes[:, 20:] = 1, 2
    dots = np.zeros_like(boxes)
    for b in (0, 20):
        for i, label in enumerate((1, 2, 3, 5)):
            dots[2 + 4 * i:5 + 4 * i, b + 2:b + 5] = label
    return boxes, dots


def test_missed_dots_checks_labels_1_to_n_even_with_a_gap():
    """The toolkit: n = number of labels present in 1..8 (here 4: 1, 2, 3, 5); it checks labels 1..n
    = 1..4, so label 4 (no pixels) counts as missed and label 5 is never looked at."""
    boxes, dots = _dots()
    gt = np.zeros(boxes.shape, np.float32)
    pred = np.where(dots == 1, 1.0, 0.0).astype(np.float32)  # dot 1 wrong in both boxes, every other dot right
    # toolkit rule: 8 (box, label) pairs; missed: label 1 twice + empty label 4 twice
    assert missed_dots(gt, pred, boxes, dots, toolkit=True) == pytest.approx(100.0 * 4 / 8)
    # default: empty pairs are not dots, so 6 dots (labels 1..3), 2 missed
    assert missed_dots(gt, pred, boxes, dots) == pytest.approx(100.0 * 2 / 6)
    pred5 = np.where(dots == 5, 1.0, 0.0).astype(np.float32)  # only label 5 wrong: never checked
    assert missed_dots(gt, pred5, boxes, dots) == 0.0


def _backgammon(value_at_column: float, column: int):
    gt = np.full((8, 30), np.float32(7e-8), np.float32)
    gt[:, column] = value_at_column
    mask = np.ones(gt.shape, bool)
    mask[:, column] = False
    return gt, mask


def test_backgammon_half_way_value_is_float64():
    """half = 0.5 * (extrapolated + gt) with the toolkit's float64 extrapolation: 0.5 * (1 + 7e-8) =
    0.500000035 in float64, but 0.50000006 if 1 + 7e-8 is rounded to float32 first. A prediction of
    nextafter(0.5f) = 0.50000006 is beyond the float64 half-way value (fattening) but not the float32 one."""
    pred = np.full((8, 30), np.nextafter(np.float32(0.5), np.float32(1)), np.float32)
    gt, mask = _backgammon(1.0, 14)
    assert float(pred[0, 0]) > 0.5 * (1.0 + float(np.float32(7e-8)))  # hand computation: fattened
    assert backgammon_fattening(gt, pred, mask, fg_column=14, toolkit=True) == 100.0
    assert backgammon_fattening(gt, pred, mask, fg_column=14) == 100.0
    # thinning: 1 + 5e-8 is 1.0 in float32, so half is 0.5 in float32 but 0.500000025 in float64, and a
    # prediction of 0.5 is thinned (nearer the background) only in float64
    gt, mask = _backgammon(1.0, 19)
    gt[:, :19] = np.float32(5e-8)
    gt[:, 20:] = np.float32(5e-8)
    pred = np.full((8, 30), np.float32(0.5), np.float32)
    assert 0.5 < 0.5 * (1.0 + float(np.float32(5e-8)))
    assert backgammon_thinning(gt, pred, mask, bg_column=19, toolkit=True) == 100.0


def test_bumpiness_with_infinite_predictions_follows_the_toolkit():
    """The toolkit's scharr filters (scipy.ndimage.convolve in scikit-image) skip zero kernel weights,
    so +-inf gives +-inf (clipped to 0.05 and scored), not inf * 0 = NaN (left out)."""
    skf = pytest.importorskip("skimage.filters")
    rng = np.random.default_rng(2)
    gt = rng.normal(0, 0.01, (32, 32)).astype(np.float32)
    pred = gt.copy()
    pred[10, 12] = np.inf
    pred[20, 20] = -np.inf
    mask = np.zeros(gt.shape, bool)
    mask[4:-4, 4:-4] = True
    diff = np.asarray(pred - gt, dtype="float64")  # the toolkit's get_bumpiness, as written
    dx, dy = skf.scharr_v(diff), skf.scharr_h(diff)
    with np.errstate(invalid="ignore"):
        bump = np.clip(np.sqrt(np.square(skf.scharr_v(dx)) + np.square(skf.scharr_h(dx)) + np.square(skf.scharr_h(dy))
                               + np.square(skf.scharr_v(dy))), 0, 0.05)
    scored = mask & np.isfinite(bump)
    expected = 100 * np.sum(bump[scored]) / float(np.sum(scored))
    assert np.count_nonzero(np.isinf(diff)) == 2 and np.count_nonzero(mask & ~np.isfinite(bump)) > 0
    assert bumpiness_x100(gt, pred, mask, toolkit=True) == pytest.approx(expected, rel=1e-12)
