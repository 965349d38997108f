"""valid_mask.png (issue 20, class 8): the scene's low-resolution mask of the pixels that may be scored.

A mask of another size is refused with one line (it was silently ignored when scoring); at high
resolution it is upsampled exactly as the prediction is (the toolkit's ``zoom(order=0)``, written out
below by its definition), so the high-resolution metrics, the BadPix curves, the bootstrap and missed
dots leave out what it leaves out (they ignored it). Expected values are counted by hand or with the
definition of the zoom, not with lfbench.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, run_cli, write_scene
from PIL import Image

from lfbench.data.hci import HCIScene
from lfbench.data.scene import Scene
from lfbench.scoring.metrics import GENERAL_METRICS
from lfbench.scoring.region_metrics import missed_dots
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import score_scene
from lfbench.utils.errors import DataError

N = 40  # low resolution; high resolution is 10 N, border 150 px


def _save_mask(folder: Path, name: str, mask: np.ndarray) -> None:
    Image.fromarray(np.where(mask, 255, 0).astype(np.uint8)).save(folder / name)


def _zoom_by_definition(a: np.ndarray, factor: int) -> np.ndarray:
    """scipy.ndimage.zoom(order=0) written out: output o samples input round(o (n-1)/(N-1)) (not repetition)."""
    n = a.shape[0]
    idx = np.rint(np.arange(n * factor) * (n - 1) / (n * factor - 1)).astype(int)
    return a[np.ix_(idx, idx)]


def _interior(shape: tuple[int, int], border: int) -> np.ndarray:
    m = np.zeros(shape, bool)
    m[border:shape[0] - border, border:shape[1] - border] = True
    return m


def test_a_valid_mask_of_another_size_is_refused(tmp_path, capsys):
    folder = write_scene(tmp_path / "data", "s0", "training", size=N, views=False)
    _save_mask(folder, "valid_mask.png", np.ones((N - 8, N - 8), bool))
    with pytest.raises(DataError, match=f"mask is {N - 8}x{N - 8}, expected {N}x{N}"):
        HCIScene(folder).valid_mask()
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", "gt", "--out", tmp_path / "out")
    assert_one_error_line(rc, err, str(folder / "valid_mask.png"), f"expected {N}x{N}")
    _save_mask(folder, "valid_mask.png", np.ones((10 * N, 10 * N), bool))  # the high-resolution size too
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", "gt", "--out", tmp_path / "out")
    assert_one_error_line(rc, err, "valid_mask.png", f"is {10 * N}x{10 * N}, expected {N}x{N}")


@pytest.fixture()
def backgammon(tmp_path) -> tuple[Scene, np.ndarray, np.ndarray]:
    """A high-resolution scene (gt 0 everywhere) whose valid mask leaves out a block of the interior,
    and a prediction wrong (1 px) on that block and on one valid pixel."""
    folder = write_scene(tmp_path, "backgammon", "stratified", size=N, views=False,
                         gt=np.zeros((N, N), np.float32), gt_highres=np.zeros((10 * N, 10 * N), np.float32))
    valid = np.ones((N, N), bool)
    valid[15:20, 15:25] = False  # half of the 10x10 low-resolution interior
    _save_mask(folder, "valid_mask.png", valid)
    pred = np.zeros((N, N), np.float32)
    pred[15:20, 15:25] = 1.0  # wrong only where invalid ...
    pred[20, 15] = 1.0  # ... and on one valid pixel
    return HCIScene(folder), valid, pred


def test_high_resolution_metrics_leave_out_the_upsampled_valid_mask(backgammon):
    scene, valid, pred = backgammon
    score = score_scene(scene, pred, GENERAL_METRICS)
    assert set(score.resolution.values()) == {"highres"}
    scored = _zoom_by_definition(valid, 10) & _interior((10 * N, 10 * N), 150)
    bad = _zoom_by_definition(pred, 10) > 0.07
    expected = 100.0 * np.count_nonzero(bad & scored) / np.count_nonzero(scored)
    # by hand: high rows o = 150..249 sample low rows round(o 39/399) = 15..24, 10 each except 9 for 15
    # (o = 150..158) and 24 (241..249) and 11 for 17 and 22; columns alike (100 in all). Valid: low rows
    # 20..24 = 10 + 10 + 11 + 10 + 9 = 50 rows x 100 columns = 5000 px; bad: low pixel (20, 15), 10 x 9 px.
    assert np.count_nonzero(scored) == 5000 and np.count_nonzero(bad & scored) == 90
    assert expected == pytest.approx(100 * 90 / 5000)
    assert score.values["badpix_0.07"] == pytest.approx(expected, rel=1e-6)
    assert score.values["mse_x100"] == pytest.approx(100 * 90 / 5000, rel=1e-5)  # errors of 1 px
    low = score_scene(scene, pred, GENERAL_METRICS, ScoringRules(allow_highres=False))
    assert low.values["badpix_0.07"] == pytest.approx(100 * 1 / 50)  # 50 valid interior pixels, one bad


def test_curves_and_bootstrap_use_the_same_pixels(backgammon):
    """The BadPix curve at 0.07 equals the table's number, and the bootstrap ranks the same 5000 pixels."""
    from lfbench.reports.figures import scene_curve
    from lfbench.scoring.stats import scene_errors

    scene, _, pred = backgammon
    table = score_scene(scene, pred, GENERAL_METRICS).values["badpix_0.07"]
    curve = scene_curve("m", scene, pred)
    assert curve.resolution == "highres"
    assert curve.values[np.argmin(np.abs(curve.thresholds - 0.07))] == pytest.approx(table, rel=1e-6)
    assert scene_errors(scene, pred).flat_index.size == 5000


def _dots() -> tuple[np.ndarray, np.ndarray]:
    """One box over 8x12 px; dots 1, 2, 3 of 2x2 px."""
    boxes = np.ones((8, 12), np.int32)
    dots = np.zeros((8, 12), np.int32)
    dots[1:3, 1:3] = 1
    dots[1:3, 5:7] = 2
    dots[5:7, 1:3] = 3
    return boxes, dots


def test_missed_dots_leave_out_pixels_outside_the_valid_mask():
    boxes, dots = _dots()
    gt = np.zeros(boxes.shape, np.float32)
    pred = gt.copy()
    pred[1:3, 1:3] = 1.0  # dot 1 wrong
    pred[1:3, 5] = 1.0  # dot 2: its left half wrong (50 %: missed)
    valid = np.ones(boxes.shape, bool)
    assert missed_dots(gt, pred, boxes, dots, valid=valid) == pytest.approx(200 / 3)
    valid[1:3, 1:3] = False  # dot 1 has no valid pixel: no dot
    valid[1, 6] = False  # dot 2: 2 wrong of 3 valid pixels (67 %): missed
    assert missed_dots(gt, pred, boxes, dots, valid=valid) == pytest.approx(100 / 2)
    assert missed_dots(gt, pred, boxes, dots, valid=valid, toolkit=True) == pytest.approx(100 / 2)
    valid[1:3, 5] = False  # dot 2: its 2 valid pixels are right: detected
    assert missed_dots(gt, pred, boxes, dots, valid=valid) == 0.0
    assert missed_dots(gt, pred, boxes, dots, valid=np.zeros_like(valid)) != missed_dots(gt, pred, boxes, dots)


def test_missed_dots_through_score_scene_use_the_valid_mask(tmp_path):
    boxes = np.zeros((N, N), np.uint8)
    boxes[10:30, 10:30] = 1
    dots = np.zeros((N, N), np.uint8)
    dots[12:16, 12:16] = 1
    dots[20:24, 20:24] = 2
    folder = write_scene(tmp_path, "dots", "stratified", size=N, views=False, gt=np.zeros((N, N), np.float32))
    for name, labels in (("mask_boxes_lowres.png", boxes), ("mask_dots_by_size_lowres.png", dots)):
        Image.fromarray(labels).save(folder / name)
    pred = np.zeros((N, N), np.float32)
    pred[12:16, 12:16] = 1.0  # dot 1 missed
    from lfbench.scoring.score import applicable_metrics

    scene = HCIScene(folder)
    assert score_scene(scene, pred, applicable_metrics(scene)).values["missed_dots"] == pytest.approx(50.0)
    valid = np.ones((N, N), bool)
    valid[12:16, 12:16] = False  # dot 1 is outside the valid area: 0 of 1 dot missed
    _save_mask(folder, "valid_mask.png", valid)
    assert score_scene(scene, pred, applicable_metrics(scene)).values["missed_dots"] == 0.0
