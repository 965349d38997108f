"""The scoring rules (lfbench.scoring.rules) on cases mutation testing found unguarded: non-square scenes
(rows and columns never swapped), one-sided crops, a missing ground truth, metrics that do not apply.
Expected values are hand-computed; docstrings name the mutants each test kills (results/mutation/README.md)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import write_scene

from lfbench.data.hci import HCIScene
from lfbench.data.hci.params import SceneParameters
from lfbench.data.pfm import write_pfm
from lfbench.data.scene import Scene
from lfbench.scoring.metrics import GENERAL_METRICS, Metric, get_metric
from lfbench.scoring.prepare import align_prediction
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import applicable_metrics, score_scene
from lfbench.utils.errors import DataError

F32 = np.float32
H, W, S = 40, 60, 2  # a non-square scene; its high-res ground truth is S times larger


def _nonsquare_scene(root, name: str = "stripes", highres: bool = True) -> tuple[Scene, np.ndarray]:
    """A stratified scene of H x W px (parameters.cfg with depth_map_scale S), ground truth 0 at low
    resolution and, at high resolution, 0 with a 1.0 stripe on rows 30..35 (inside the 15 S px border)."""
    folder = root / "stratified" / name
    folder.mkdir(parents=True)
    params = SceneParameters(focal_length_mm=100.0, image_resolution_x_px=W, image_resolution_y_px=H,
                             sensor_size_mm=35.0, num_cams_x=9, num_cams_y=9, baseline_mm=30.0, focus_distance_m=8.3,
                             disp_min=-1.0, disp_max=1.0, depth_map_scale=float(S), name=name, category="stratified")
    (folder / "parameters.cfg").write_text(params.to_cfg(), encoding="utf-8")
    write_pfm(folder / "gt_disp_lowres.pfm", np.zeros((H, W), F32))
    hi = np.zeros((H * S, W * S), F32)
    hi[30:36, :] = 1.0
    if highres:
        write_pfm(folder / "gt_disp_highres.pfm", hi)
    return HCIScene(folder), hi


def test_nonsquare_crop_is_aligned_rows_to_rows_and_columns_to_columns():
    """Kills rows and columns mixed up in align_prediction (`shape[1] - pred.shape[0]`, `pred.shape[1]` in
    the row slice, the recorded original shape) and its float32 canvas."""
    pred = np.arange(30 * 44, dtype=F32).reshape(30, 44)
    out, original = align_prediction(pred, (H, W))
    assert original == (30, 44) and out.dtype == np.float32 and out.shape == (H, W)
    expected = np.full((H, W), np.nan, F32)
    expected[5:35, 8:52] = pred  # (40 - 30) / 2 rows and (60 - 44) / 2 columns on each side
    assert np.array_equal(out, expected, equal_nan=True)


@pytest.mark.parametrize(("shape", "ok"), [((40, 44), True), ((30, 60), True), ((42, 44), False), ((30, 62), False),
                                           ((31, 44), False), ((30, 45), False), ((40, 60), True)])
def test_crop_of_one_side_only_and_bad_crops(shape, ok):
    """Kills the crop checks weakened or tightened: a crop of the width only (dh == 0) or the height only
    is aligned; a larger map on either side (`or` -> `and`) or an odd crop on either side is refused."""
    pred = np.zeros(shape, F32)
    if ok:
        out, original = align_prediction(pred, (H, W))
        assert out.shape == (H, W) and np.count_nonzero(out == 0) == pred.size
        assert original == (None if shape == (H, W) else shape)
    else:
        with pytest.raises(DataError, match=rf"prediction is {shape[1]}x{shape[0]}, scene is {W}x{H} \(only a "
                                            "symmetric crop of at most the evaluation border can be aligned\\)") as e:
            align_prediction(pred, (H, W), source="mine.pfm")
        assert str(e.value).startswith("mine.pfm")


def test_a_3d_map_is_refused_naming_its_source():
    """Kills align_prediction's error losing its source (the file a user passed)."""
    with pytest.raises(DataError, match="disparity must be a 2-D map") as e:
        align_prediction(np.zeros((H, W, 3), F32), (H, W), source="mymethod on cotton")
    assert str(e.value).startswith("mymethod on cotton")
    with pytest.raises(DataError) as e:
        align_prediction(np.zeros((H, W, 3), F32), (H, W))
    assert str(e.value).startswith("prediction")  # the default source


def test_nonsquare_highres_scene_is_scored_with_its_own_scale_and_border(tmp_path):
    """Kills the high-res scale taken from the width (`gt.shape[1] // h`), the upsampling skipped for a
    scale of 2, and the note of an aligned crop with rows and columns swapped. Hand-computed: the crop
    is aligned, upsampled x2 by nearest neighbour; the 30 px border (15 x 2) leaves 20 x 60 high-res px."""
    scene, hi = _nonsquare_scene(tmp_path)
    pred = np.zeros((30, 44), F32)  # a crop of 5 rows and 8 columns on each side
    pred[10:13, :] = 1.0  # low-res rows 15..17 of the scene: high-res rows 30..35, the stripe
    score = score_scene(scene, pred, GENERAL_METRICS)
    assert score.scene == "stripes" and score.aligned_from == (30, 44)
    assert score.notes == ["44x30 prediction aligned to the centre of 60x40"]
    assert score.resolution["badpix_0.07"] == "highres"
    assert score.values["badpix_0.07"] == 0.0  # every pixel inside the 30 px border is right
    pred[10:13, :] = 0.0
    score = score_scene(scene, pred, GENERAL_METRICS)  # the stripe missed: 6 rows x 60 columns of 20 x 60
    assert score.values["badpix_0.07"] == pytest.approx(100 * 6 / 20)
    assert score.nonfinite_pixels == 0


def test_missing_ground_truth_is_an_error_naming_the_scene(tmp_path):
    """Kills the missing low-res ground truth skipped silently (`res == HIGHRES` -> `!=`) or its error
    losing its message or folder."""
    folder = write_scene(tmp_path, "toy", size=40, views=False)
    (folder / "gt_disp_lowres.pfm").unlink()
    with pytest.raises(DataError) as e:
        score_scene(HCIScene(folder), np.zeros((40, 40), F32), GENERAL_METRICS)
    assert str(e.value) == f"{folder}: no ground truth at lowres to score against"


def test_score_scene_names_the_prediction_by_default(tmp_path):
    """Kills a change of score_scene's default source (the name its errors give a prediction)."""
    folder = write_scene(tmp_path, "toy", size=40, views=False)
    with pytest.raises(DataError) as e:
        score_scene(HCIScene(folder), np.zeros((41, 40), F32), GENERAL_METRICS)
    assert str(e.value).startswith("prediction: prediction is 40x41, scene is 40x40")


def test_metrics_that_do_not_apply_are_skipped_without_stopping(tmp_path):
    """Kills `continue` -> `break` where score_scene skips a metric: one without its mask file (no
    resolution) and a plugin metric scored at the scene's resolution whose mask is absent; the metrics
    after them are still scored."""
    folder = write_scene(tmp_path, "toy", size=40, views=False)
    plugin = Metric(id="my_region", name="mine", description="BadPix(0.07) on mask_mine", unit="%",
                    fn=GENERAL_METRICS[2].fn, mask_name="mask_mine")
    metrics = [get_metric("bumpiness_planes"), plugin, *GENERAL_METRICS]
    score = score_scene(HCIScene(folder), np.full((40, 40), 1.0, F32), metrics)
    assert sorted(score.values) == sorted(m.id for m in GENERAL_METRICS)


def test_applicable_metrics_follow_the_rules(tmp_path):
    """Kills applicable_metrics ignoring the caller's rules: without high-res scoring, a high-res metric
    whose only mask is high-res does not apply."""
    folder = write_scene(tmp_path, "toy", size=40, views=False, gt_highres=np.zeros((400, 400), F32),
                         masks={"mask_fine_highres": np.ones((400, 400), bool)})
    scene = HCIScene(folder)
    assert "fine_thinning" in [m.id for m in applicable_metrics(scene)]
    assert "fine_thinning" not in [m.id for m in applicable_metrics(scene, ScoringRules(allow_highres=False))]


def test_wrong_size_dots_label_masks_name_their_file(tmp_path):
    """Kills the label masks' size check naming the wrong file or the ground truth's size transposed."""
    from PIL import Image

    scene, _ = _nonsquare_scene(tmp_path, "dots", highres=False)
    for bad in ("mask_boxes", "mask_dots_by_size"):
        for name in ("mask_boxes", "mask_dots_by_size"):
            size = (H - 2, W) if name == bad else (H, W)
            Image.fromarray(np.ones(size, np.uint8)).save(scene.path / f"{name}_lowres.png")
        with pytest.raises(DataError) as e:
            score_scene(scene, np.zeros((H, W), F32), [get_metric("missed_dots")])
        assert str(e.value) == f"{scene.path / f'{bad}_lowres.png'}: mask is {W}x{H - 2}, ground truth is {W}x{H}"
