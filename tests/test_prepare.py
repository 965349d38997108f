"""The one preparation of a prediction (lfbench.scoring.prepare, issue 21 item 1), each scorer going through
it, the metrics' order and labels, and the layering of lfbench/scoring (issue 21 item 2).

References are independent of lfbench's code: the toolkit's own upsampling (scipy.ndimage.zoom, order 0),
masks and BadPix written out by hand in float32, label strings as the committed tables print them, and the
import statements of the source files."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
from helpers import write_scene
from PIL import Image
from scipy import ndimage

from lfbench.data.hci import HCIScene
from lfbench.data.hci.params import SceneParameters
from lfbench.data.pfm import write_pfm
from lfbench.data.scene import ArrayLightField, Scene
from lfbench.method.base import Prediction
from lfbench.scoring.metrics import RUNTIME_METRICS, describe_metric, get_metric, metric_order
from lfbench.scoring.prepare import SceneReference
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.errors import DataError

F32 = np.float32
N, S, BORDER, CROP = 20, 10, 3, 2  # 20x20 scene, x10 high resolution, 3 px border, a map cropped by 2 px a side
ROOT = Path(__file__).resolve().parent.parent


def _highres_scene(tmp_path: Path) -> tuple[Scene, np.ndarray, np.ndarray]:
    """Backgammon (a high-resolution scene) with a high-res ground truth that is not a repeat of the
    low-res one, and a valid mask with a hole: (scene, high-res gt, valid mask)."""
    rng = np.random.default_rng(5)
    gt_hi = rng.uniform(-1, 1, (N * S, N * S)).astype(F32)
    folder = write_scene(tmp_path, "backgammon", "stratified", size=N, views=False, gt=gt_hi[::S, ::S].copy(),
                         gt_highres=gt_hi)
    valid = np.ones((N, N), bool)
    valid[8:11, 4:16] = False
    Image.fromarray(np.where(valid, 255, 0).astype(np.uint8)).save(folder / "valid_mask.png")
    return HCIScene(folder), gt_hi, valid


def _cropped_prediction(gt_hi: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(6)
    pred = (gt_hi[::S, ::S] + rng.normal(0, 0.1, (N, N))).astype(F32)[CROP:-CROP, CROP:-CROP].copy()
    pred[3, 4] = np.nan
    pred[7, 9] = np.inf
    return pred


def _canvas(pred: np.ndarray) -> np.ndarray:
    canvas = np.full((N, N), np.nan, F32)
    canvas[CROP:N - CROP, CROP:N - CROP] = pred
    return canvas


def _expected(gt_hi: np.ndarray, valid: np.ndarray, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The toolkit's rules written out: the crop centred on a NaN canvas, scipy's zoom(order=0) x S,
    the border of BORDER * S px and the valid mask zoomed the same way."""
    up = ndimage.zoom(_canvas(pred), S, order=0)
    mask = np.zeros(gt_hi.shape, bool)
    mask[BORDER * S:(N - BORDER) * S, BORDER * S:(N - BORDER) * S] = True
    return up, mask & ndimage.zoom(valid.astype(np.uint8), S, order=0).astype(bool)


def test_prepare_is_the_toolkits_zoom_with_the_scaled_border_and_the_valid_mask(tmp_path):
    scene, gt_hi, valid = _highres_scene(tmp_path)
    pred = _cropped_prediction(gt_hi)
    reference = SceneReference(scene, ScoringRules(border_px=BORDER))
    p = reference.prepare(pred, "highres", "mine")
    up, mask = _expected(gt_hi, valid, pred)
    assert (p.scale, p.resolution, p.aligned_from) == (S, "highres", (N - 2 * CROP, N - 2 * CROP))
    assert type(p.scale) is int
    assert p.pred.dtype == F32 and np.array_equal(p.pred, up, equal_nan=True)
    assert np.array_equal(p.mask, mask) and np.array_equal(p.gt, gt_hi)
    # (the toolkit's zoom is not a plain repeat, so this reference tells the two apart)
    assert not np.array_equal(up, np.repeat(np.repeat(_canvas(pred), S, 0), S, 1), equal_nan=True)
    # what does not depend on the method is kept, read-only; the caller's own arrays are left writable
    again = reference.prepare(pred, "highres")
    assert again.gt is p.gt and again.mask is p.mask
    assert not p.gt.flags.writeable and not p.mask.flags.writeable and pred.flags.writeable
    with pytest.raises(ValueError):
        p.mask[0, 0] = True
    low = reference.prepare(pred, "lowres")
    low_mask = np.zeros((N, N), bool)
    low_mask[BORDER:N - BORDER, BORDER:N - BORDER] = True
    assert low.scale == 1 and np.array_equal(low.pred, _canvas(pred), equal_nan=True)
    assert np.array_equal(low.mask, low_mask & valid) and np.array_equal(low.gt, gt_hi[::S, ::S])


def test_a_crop_wider_than_the_border_is_refused_by_every_scorer(tmp_path):
    from lfbench.scoring.score import score_scene
    from lfbench.scoring.stats import scene_errors

    scene, gt_hi, _ = _highres_scene(tmp_path)
    pred = gt_hi[::S, ::S][4:-4, 4:-4].copy()  # 4 px a side, the border is 3
    rules = ScoringRules(border_px=BORDER)
    for score in (lambda: score_scene(scene, pred, rules=rules, source="mine"),
                  lambda: scene_errors(scene, pred, rules, source="mine"),
                  lambda: SceneReference(scene, rules).prepare(pred, "lowres", "mine")):
        with pytest.raises(DataError, match="^mine: prediction is 12x12, scene is 20x20"):
            score()
    reference = SceneReference(scene, rules)
    for step in (lambda: reference.prepare(np.zeros((N, N, 3), F32), "lowres"), lambda: reference.align(pred)):
        with pytest.raises(DataError, match="^prediction: "):  # a prediction not named is 'prediction'
            step()


H2, W2, S2 = 8, 12, 2  # a non-square scene whose high resolution is x2


def _nonsquare_scene(tmp_path: Path) -> tuple[Scene, np.ndarray]:
    """Stripes (a high-resolution scene) of H2 x W2 px at x S2, with a valid mask: (scene, valid mask)."""
    folder = tmp_path / "stratified" / "stripes"
    folder.mkdir(parents=True)
    params = SceneParameters(focal_length_mm=100.0, image_resolution_x_px=W2, image_resolution_y_px=H2,
                             sensor_size_mm=35.0, num_cams_x=9, num_cams_y=9, baseline_mm=30.0, focus_distance_m=8.3,
                             disp_min=-1.0, disp_max=1.0, depth_map_scale=float(S2), name="stripes",
                             category="stratified")
    (folder / "parameters.cfg").write_text(params.to_cfg(), encoding="utf-8")
    rng = np.random.default_rng(8)
    write_pfm(folder / "gt_disp_lowres.pfm", rng.uniform(-1, 1, (H2, W2)).astype(F32))
    write_pfm(folder / "gt_disp_highres.pfm", rng.uniform(-1, 1, (H2 * S2, W2 * S2)).astype(F32))
    valid = np.ones((H2, W2), bool)
    valid[2:4, 3:9] = False
    Image.fromarray(np.where(valid, 255, 0).astype(np.uint8)).save(folder / "valid_mask.png")
    return HCIScene(folder), valid


def test_a_non_square_scene_and_its_uncertainty_are_prepared_rows_to_rows(tmp_path):
    """The valid mask and the uncertainty map of a non-square scene at x2 follow the toolkit's zoom; an
    uncertainty map cropped wider than the border is refused, named as the prediction's uncertainty."""
    scene, valid = _nonsquare_scene(tmp_path)
    rng = np.random.default_rng(9)
    pred = rng.uniform(-1, 1, (H2 - 2, W2 - 2)).astype(F32)  # cropped by the 1 px border
    unc = rng.uniform(0, 1, (H2 - 2, W2 - 2))  # float64: kept as it is
    reference = SceneReference(scene, ScoringRules(border_px=1))
    p = reference.prepare(pred, "highres", "mine", uncertainty=unc)

    def zoomed(low: np.ndarray, dtype) -> np.ndarray:
        canvas = np.full((H2, W2), np.nan, dtype)
        canvas[1:-1, 1:-1] = low
        return ndimage.zoom(canvas, S2, order=0)

    mask = np.zeros((H2 * S2, W2 * S2), bool)
    mask[S2:-S2, S2:-S2] = True
    assert p.scale == S2 and np.array_equal(p.pred, zoomed(pred, F32), equal_nan=True)
    assert np.array_equal(p.mask, mask & ndimage.zoom(valid.astype(np.uint8), S2, order=0).astype(bool))
    assert p.uncertainty.dtype == np.float32 and np.array_equal(p.uncertainty, zoomed(unc, F32), equal_nan=True)
    whole = reference.prepare(np.zeros((H2, W2), F32), "highres", uncertainty=np.ones((H2, W2)))
    assert whole.uncertainty.dtype == np.float64 and whole.uncertainty.shape == (H2 * S2, W2 * S2)
    with pytest.raises(DataError, match="^mine uncertainty: prediction is 8x4, scene is 12x8"):
        reference.prepare(np.zeros((H2, W2), F32), "highres", "mine", uncertainty=np.ones((H2 - 4, W2 - 4)))


def test_a_light_field_held_in_memory_is_scored_inside_the_border():
    """A light field without files (views in memory, a training validation crop): its own size, its ground
    truth at low resolution only, no masks, the border of the rules; none of its arrays made read-only."""
    rng = np.random.default_rng(7)
    gt = rng.uniform(-1, 1, (12, 16)).astype(F32)
    views = rng.random((3, 3, 12, 16)).astype(F32)
    rules = ScoringRules(border_px=2)
    inside = np.zeros((12, 16), bool)
    inside[2:10, 2:14] = True
    lf = ArrayLightField(views=views, name="toy", gt=gt)
    reference = SceneReference(lf, rules)
    assert SceneReference.of(reference) is reference and SceneReference.of(lf).scene is lf
    assert reference.has_gt() and not reference.has_gt("highres") and reference.mask_names() == []
    assert reference.spatial_size == (12, 16) and reference.general_resolution() == "lowres"
    assert reference.valid_mask() is None and np.array_equal(reference.evaluation_mask(), inside)
    p = reference.prepare(gt + F32(0.5), "lowres")
    assert np.array_equal(p.gt, gt) and np.array_equal(p.mask, inside) and p.scale == 1
    bare = SceneReference(ArrayLightField(views=views, name="bare"), rules)
    assert not bare.has_gt() and np.array_equal(bare.evaluation_mask(), inside)
    with pytest.raises(DataError, match="^no ground truth at lowres to score against$"):
        bare.prepare(gt, "lowres")
    crop = SceneReference.of_ground_truth(gt, rules, name="val")
    assert (crop.name, crop.spatial_size, crop.rules) == ("val", (12, 16), rules)
    assert np.array_equal(crop.gt(), gt) and np.array_equal(crop.evaluation_mask(), inside)
    assert gt.flags.writeable and views.flags.writeable


def test_score_scene_records_the_runtime_a_method_reports(tmp_path):
    """Runtime metrics, in any place of the list, take the reported runtime; none, NaN or a non-positive
    one gives no record, and a non-positive one a note."""
    from lfbench.scoring.score import score_scene

    scene = HCIScene(write_scene(tmp_path, "toy", size=40, views=False))
    runtime, log = RUNTIME_METRICS
    metrics = [runtime, get_metric("badpix_0.07"), log]
    score = score_scene(scene, np.ones((40, 40), F32), metrics, runtime_s=2.5)
    assert score.values == {"runtime": 2.5, "runtime_log": float(np.log10(2.5)), "badpix_0.07": 0.0}
    assert score.resolution == {"runtime": "lowres", "runtime_log": "lowres", "badpix_0.07": "lowres"}
    assert score.notes == []
    for reported in (None, float("nan")):
        score = score_scene(scene, np.ones((40, 40), F32), [runtime], runtime_s=reported)
        assert score.values == {} and score.notes == []
    score = score_scene(scene, np.ones((40, 40), F32), [runtime], runtime_s=0.0)
    assert score.values == {} and score.notes == ["runtime 0 s is not a positive number: no runtime record"]


def test_every_scorer_scores_the_prepared_pixels(tmp_path):
    """score_scene, the bootstrap's per-pixel errors, the figures' BadPix curve and the uncertainty rating
    all score the same pixels: BadPix(0.07) and MSE x100 written out in float32 on the expected arrays."""
    from lfbench.reports.figures import scene_curve
    from lfbench.scoring.score import score_scene
    from lfbench.scoring.stats import metric_from_errors, scene_errors
    from lfbench.scoring.uncertainty import scene_sparsification

    scene, gt_hi, valid = _highres_scene(tmp_path)
    pred = _cropped_prediction(gt_hi)
    up, mask = _expected(gt_hi, valid, pred)
    scored = mask & np.isfinite(gt_hi)
    err = up[scored] - gt_hi[scored]
    bad = (np.abs(err) > F32(0.07)) | ~np.isfinite(err)
    badpix = 100.0 * np.count_nonzero(bad) / err.size
    finite = err[np.isfinite(err)]
    mse = float(np.average(np.square(finite))) * 100
    rules = ScoringRules(border_px=BORDER)

    score = score_scene(scene, pred, [get_metric("badpix_0.07"), get_metric("mse_x100")], rules)
    assert score.values == {"badpix_0.07": badpix, "mse_x100": mse}
    assert score.resolution == {"badpix_0.07": "highres", "mse_x100": "highres"}
    errors = scene_errors(scene, pred, rules)
    assert errors.scale == S and np.array_equal(errors.errors, err, equal_nan=True)
    assert metric_from_errors(errors.errors, "badpix_0.07") == badpix
    curve = scene_curve("mine", scene, pred, rules)
    assert curve.resolution == "highres" and curve.values[list(np.round(curve.thresholds, 3)).index(0.07)] == badpix
    rating = scene_sparsification(scene, Prediction(pred, uncertainty=np.abs(pred)), rules)
    assert rating.n_pixels == finite.size  # the abs measure leaves the non-finite errors out
    assert rating.curve[0] == pytest.approx(float(np.mean(np.abs(finite.astype(np.float64)))))


def test_one_reference_serves_many_methods_with_the_same_numbers(tmp_path):
    from lfbench.scoring.score import applicable_metrics, score_scene

    scene, gt_hi, _ = _highres_scene(tmp_path)
    rules = ScoringRules(border_px=BORDER)
    reference = SceneReference(scene, rules)
    metrics = applicable_metrics(scene, rules)
    for k in range(3):
        pred = (gt_hi[::S, ::S] + 0.05 * k).astype(F32)
        assert score_scene(scene, pred, metrics, rules, reference=reference) == score_scene(scene, pred, metrics, rules)
    with pytest.raises(ValueError, match="not of the scene scored"):
        score_scene(scene, pred, metrics, ScoringRules(), reference=reference)


def test_metric_order_and_labels_come_from_the_metrics():
    ids = ["q25_x100", "discontinuities", "badpix_0.01", "runtime", "mse_x100", "badpix_0070", "badpix_0.07",
           "badpix_0.03", "mine", "badpix_0.03"]
    # the paper's order first, each once; the rest as given (a toolkit alias is not the metric's own id)
    assert metric_order(ids) == ["badpix_0.07", "badpix_0.03", "badpix_0.01", "mse_x100", "q25_x100",
                                 "discontinuities", "runtime", "badpix_0070", "mine"]
    assert metric_order(["mine", "stripes_dark"]) == ["mine", "stripes_dark"]
    # the column headers of the committed ablation and sweep tables (results/ablations, results/planesweep_table4)
    labels = {m: get_metric(m).label for m in ("badpix_0.07", "badpix_0.03", "badpix_0.01", "mse_x100")}
    assert labels == {"badpix_0.07": "BadPix 0.07 (%)", "badpix_0.03": "BadPix 0.03 (%)",
                      "badpix_0.01": "BadPix 0.01 (%)", "mse_x100": "MSE x100"}
    assert get_metric("badpix_0.05").label == "BadPix 0.05 (%)" and get_metric("q25_x100").label == "Q25"
    assert all(get_metric(m).value_range == (0.0, 100.0) for m in ("badpix_0.07", "badpix_0.05"))
    unknown = describe_metric("mine")
    assert (unknown.id, unknown.name, unknown.unit, unknown.higher_is_better) == ("mine", "mine", "", False)
    assert unknown.category == "undefined"  # none of the categories lfbench scores
    with pytest.raises(TypeError, match="not defined by lfbench"):
        unknown(np.zeros((2, 2)), np.zeros((2, 2)))
    assert describe_metric("badpix_0070") is get_metric("badpix_0.07")


# lfbench/scoring from the bottom up: a module may import only those before it (and data, utils)
SCORING_LAYERS = ("filters", "policy", "pixels", "resample", "pixelwise", "base", "general", "rules", "prepare",
                  "region_metrics", "metrics", "builtin", "protocol", "score", "stats", "uncertainty")


def _lfbench_imports(path: Path) -> list[tuple[str, list[str]]]:
    """(module, names) of every ``from lfbench... import`` / ``import lfbench...`` in the file, anywhere."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("lfbench"):
            found.append((node.module, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            found += [(a.name, []) for a in node.names if a.name.startswith("lfbench")]
    return found


def test_scoring_imports_run_one_way():
    folder = ROOT / "lfbench" / "scoring"
    assert sorted(p.stem for p in folder.glob("*.py")) == sorted([*SCORING_LAYERS, "__init__"])
    for i, name in enumerate(SCORING_LAYERS):
        allowed = {f"lfbench.scoring.{m}" for m in SCORING_LAYERS[:i]}
        for module, names in _lfbench_imports(folder / f"{name}.py"):
            top = module.split(".")[1] if "." in module else ""
            assert top in ("data", "utils") or module in allowed, f"scoring/{name}.py imports {module}"
            assert not [n for n in names if n.startswith("_")], f"scoring/{name}.py imports private {names}"


@pytest.mark.parametrize("factor", [1, 3, 10])
@pytest.mark.parametrize("border", [0, 2, 5])
def test_a_border_rectangle_reads_the_pixels_its_mask_selects(factor, border):
    """Issue 39.7: the evaluation pixels of a scene without a valid mask are sliced as a rectangle (no mask pass),
    the same pixels in the same order as through the mask, upsampled or not, in order-run columns or not."""
    from lfbench.scoring.pixels import PixelSet
    from lfbench.scoring.prepare import border_mask, upsample_index

    rng = np.random.default_rng(factor + border)
    low = rng.standard_normal((10, 12)).astype(F32)
    shape = (10 * factor, 12 * factor)
    gt = rng.standard_normal(shape).astype(F32)
    b = border * factor
    upsample = upsample_index((10, 12), factor) if factor > 1 else None
    pred = low if factor > 1 else rng.standard_normal(shape).astype(F32)
    masked = PixelSet(border_mask(shape, b), gt, upsample=upsample, low_width=12)
    boxed = PixelSet(border_mask(shape, b), gt, upsample=upsample, low_width=12,
                     box=(b, shape[0] - b, b, shape[1] - b))
    full = ndimage.zoom(low, factor, order=0) if factor > 1 else pred  # the toolkit's upsampling
    assert np.array_equal(boxed.gt, gt[border_mask(shape, b)]) and np.array_equal(boxed.gt, masked.gt)
    assert np.array_equal(masked.values(pred, rows_per_block=7), full[border_mask(shape, b)])
    assert np.array_equal(boxed.values(pred, rows_per_block=7), full[border_mask(shape, b)])
    if upsample is not None:  # the same through take as through repeat
        boxed.__dict__["_column_runs"] = (0, None)
        assert np.array_equal(boxed.values(pred), masked.values(pred))
    with pytest.raises(ValueError, match="not a rectangle"):
        PixelSet(None, gt, box=(0, shape[0] + 1, 0, 1))
