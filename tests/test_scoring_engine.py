"""The scoring engine (issue 23.1, 23.2): what a scene keeps for every method, what a prediction computes once,
and scoring in worker processes, against the benchmark's formulas written out and against scoring each
prediction on its own. Speed is measured in benchmarks/scoring_scale.py, not here."""

from __future__ import annotations

import importlib.util
import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from lfbench.data.hci import HCIDataset
from lfbench.data.scene import HIGHRES
from lfbench.method.registry import create_from_spec
from lfbench.runs.runner import ScoringTask, evaluate, score_scenes
from lfbench.scoring.metrics import GENERAL_METRICS, Metric, get_metric
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.prepare import SceneReference, upsample_index
from lfbench.scoring.region_metrics import (
    BACKGAMMON_BG_FROM_RIGHT,
    BACKGAMMON_FG_COLUMN,
    REGION_METRICS,
    STRATIFIED_METRICS,
)
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import applicable_metrics, score_predictions, score_scene
from lfbench.utils.errors import DataError, SpecError

ROOT = Path(__file__).resolve().parent.parent


def _hci_layout():
    spec = importlib.util.spec_from_file_location("hci_layout", ROOT / "benchmarks" / "hci_layout.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _bits(value: float) -> bytes:
    return struct.pack("<d", value)


# --------------------------------------------------------------------------- the upsampling index


@pytest.mark.parametrize("shape,factor", [((7, 7), 10), ((6, 9), 10), ((5, 3), 4), ((1, 4), 3), ((16, 16), 1)])
@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint8, bool])
def test_upsample_index_is_the_toolkits_zoom(shape, factor, dtype):
    """pred[rows][:, cols] equals scipy.ndimage.zoom(pred, factor, order=0) element for element (the toolkit's
    upsampling, which is not a plain repeat: np.repeat differs from it on these shapes)."""
    rng = np.random.default_rng(sum(shape) + factor)
    pred = (rng.uniform(-3, 3, shape) * 50).astype(dtype)
    rows, cols = upsample_index(shape, factor)
    expected = ndimage.zoom(pred, factor, order=0)
    assert np.array_equal(pred[rows][:, cols], expected)
    if factor == 10 and shape == (7, 7):  # the rule is not np.repeat's
        assert not np.array_equal(rows, np.repeat(np.arange(shape[0]), factor))


# --------------------------------------------------------------------------- pixel-wise metrics, written out


def _old_bad_pix(gt, pred, t, mask, toolkit):
    err = np.abs(pred - gt)
    if toolkit:
        return 100.0 * np.count_nonzero((err > t) & mask) / np.count_nonzero(mask)
    scored = mask & np.isfinite(gt)
    bad = (err > t) | ~np.isfinite(pred)
    return 100.0 * np.count_nonzero(bad & scored) / np.count_nonzero(scored)


def _old_mse(gt, pred, mask):
    scored = mask & np.isfinite(gt) & np.isfinite(pred)
    return float(np.average(np.square(gt - pred)[scored])) * 100


def _old_quantile(gt, pred, p, mask, toolkit):
    diffs = np.abs(pred - gt) * 100
    if toolkit:
        scored = mask & np.isfinite(diffs) & np.isfinite(pred)
    else:
        scored = mask & np.isfinite(gt)
        diffs = np.where(np.isfinite(pred), diffs, np.inf)
    values = np.sort(diffs[scored])
    return float(values[int(values.size * p / 100.0)])


def _old_percent_bad(bad, reference, pred, mask, toolkit):
    if toolkit:
        return 100.0 * np.count_nonzero(bad & mask) / np.count_nonzero(mask)
    scored = mask & np.isfinite(reference)
    bad = bad | ~np.isfinite(pred)
    return 100.0 * np.count_nonzero(bad & scored) / np.count_nonzero(scored)


def _maps(seed: int, shape=(40, 50)):
    """gt and pred in float32 with every kind of value the metrics must survive: NaN and +-inf in the
    prediction, a few non-finite gt pixels, values whose difference overflows float32."""
    rng = np.random.default_rng(seed)
    gt = rng.uniform(-2, 2, shape).astype(np.float32)
    pred = (gt + rng.normal(0, 0.05, shape)).astype(np.float32)
    flat = pred.ravel()
    picks = rng.choice(flat.size, 40, replace=False)
    flat[picks[:10]], flat[picks[10:20]], flat[picks[20:25]] = np.nan, np.inf, -np.inf
    flat[picks[25:30]] = 3e38
    gt.ravel()[picks[25:30]] = -3e38  # pred - gt overflows to inf
    gt.ravel()[rng.choice(flat.size, 6, replace=False)] = np.nan
    mask = rng.random(shape) < 0.7
    return gt, pred, mask


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("toolkit", [False, True])
def test_pixelwise_metrics_are_the_formulas_on_the_maps(seed, toolkit):
    """Each metric computed from the errors gathered at its pixels (once for all of them) is bit for bit the
    formula on the full maps inside the mask, in both non-finite rules."""
    gt, pred, mask = _maps(seed)
    px = PixelErrors.of_maps(gt, pred, mask)
    with np.errstate(invalid="ignore", over="ignore"):
        for t in (0.01, 0.03, 0.07, 0.5):
            assert _bits(get_metric(f"badpix_{t}").score_pixels(px, toolkit=toolkit)) == _bits(
                _old_bad_pix(gt, pred, t, mask, toolkit))
        assert _bits(get_metric("mse_x100").score_pixels(px, toolkit=toolkit)) == _bits(_old_mse(gt, pred, mask))
        for p in (25, 50, 90):
            assert _bits(get_metric(f"q{p}_x100").score_pixels(px, toolkit=toolkit)) == _bits(
                _old_quantile(gt, pred, p, mask, toolkit))
        fat = _old_percent_bad((gt - pred) < -0.15, gt, pred, mask, toolkit)
        thin = _old_percent_bad((gt - pred) > 0.15, gt, pred, mask, toolkit)
        half_fg = 0.5 * (gt[:, 14:15].astype(np.float64) + gt)
        half_bg = 0.5 * (gt[:, 39:40].astype(np.float64) + gt)
        fattening = _old_percent_bad(pred > half_fg, half_fg, pred, mask, toolkit)
        thinning = _old_percent_bad(pred < half_bg, half_bg, pred, mask, toolkit)
    region = {m.id: m for m in REGION_METRICS + STRATIFIED_METRICS["backgammon"]}
    assert _bits(region["fine_fattening"].score_pixels(px, toolkit=toolkit)) == _bits(fat)
    assert _bits(region["fine_thinning"].score_pixels(px, toolkit=toolkit)) == _bits(thin)
    assert _bits(region["backgammon_fattening"].score_pixels(px, toolkit=toolkit)) == _bits(fattening)
    assert 50 - BACKGAMMON_BG_FROM_RIGHT == 39 and BACKGAMMON_FG_COLUMN == 14  # the columns written out above
    assert _bits(region["backgammon_thinning"].score_pixels(px, toolkit=toolkit)) == _bits(thinning)


def test_every_pixelwise_metric_agrees_with_its_map_function():
    """``pixelwise`` and ``fn`` are one metric: on maps and a mask both give the same value."""
    gt, pred, mask = _maps(7)
    pixelwise = [m for m in (*GENERAL_METRICS, *REGION_METRICS, *(m for ms in STRATIFIED_METRICS.values() for m in ms))
                 if m.pixelwise is not None and not m.needs_scene]
    assert {"badpix_0.07", "mse_x100", "q25_x100", "discontinuities", "fine_fattening", "stripes_dark",
            "dots_background_mse"} <= {m.id for m in pixelwise}
    for metric in pixelwise:
        for toolkit in (False, True):
            assert _bits(metric.score_pixels(PixelErrors.of_maps(gt, pred, mask), toolkit=toolkit)) == _bits(
                metric(gt, pred, mask, toolkit=toolkit)), metric.id
    with pytest.raises(TypeError, match="not pixel-wise"):
        get_metric("bumpiness_planes").score_pixels(PixelErrors.of_maps(gt, pred, mask))


def test_errors_are_computed_once_per_region():
    """A prediction's errors at a region's pixels are gathered once and shared by every metric of that region."""
    gt = np.linspace(-1, 1, 64 * 64, dtype=np.float32).reshape(64, 64)
    from lfbench.scoring.prepare import GroundTruth

    reference = SceneReference(GroundTruth("g", gt), ScoringRules(border_px=4))
    p = reference.prepare(gt + np.float32(0.05), "lowres")
    px = p.errors()
    assert p.errors() is px and px.err is px.err  # kept
    assert px.size == 56 * 56 and reference.pixels("lowres") is px.pixels  # the scene's pixel set, shared
    q = reference.prepare(gt, "lowres")
    assert q.errors().pixels is px.pixels and q.errors() is not px


@pytest.mark.parametrize("gt_bad, pred_bad, gt_ok, pred_ok", [
    (None, None, True, True),  # all finite: one read of the errors decides both
    (np.nan, None, False, True), (np.inf, None, False, True), (-np.inf, None, False, True),
    (None, np.nan, True, False), (None, np.inf, True, False),
    (np.inf, np.inf, False, False),  # inf - inf is NaN
    (3e38, -3e38, True, True),  # both finite, the float32 error overflows to inf: decided on the maps
])
def test_all_finite_flags_by_hand(gt_bad, pred_bad, gt_ok, pred_ok):
    """Whether every ground truth value / prediction is finite, from one read of the errors when they all are,
    else from the maps: a finite pair whose difference overflows float32 is still finite."""
    gt, pred = np.zeros(20, np.float32), np.full(20, 0.5, np.float32)
    if gt_bad is not None:
        gt[7] = gt_bad
    if pred_bad is not None:
        pred[7] = pred_bad
    px = PixelErrors.of_maps(gt, pred)
    assert (px.gt_all_finite, px.pred_all_finite) == (gt_ok, pred_ok)
    assert px.errors_all_finite == (gt_ok and pred_ok and gt_bad is None)
    empty = PixelErrors.of_maps(np.zeros(0, np.float32), np.zeros(0, np.float32))
    assert empty.gt_all_finite and empty.pred_all_finite


# --------------------------------------------------------------------------- one reference for every method


@pytest.fixture(scope="module")
def layout(tmp_path_factory):
    """The 9-scene HCI layout at 48x48 px, 4x high resolution on the stratified scenes, every mask, and
    four submissions (one with NaN pixels)."""
    root = tmp_path_factory.mktemp("hci")
    hci = _hci_layout()
    hci.write_benchmark(root / "data", "issue", size=48, scale=4)
    scenes = [s for s in HCIDataset.open(root / "data") if s.has_gt()]
    hci.write_submissions(root / "subs", [(s.name, s.gt_disparity()) for s in scenes], 10)
    return root, scenes


def test_the_layout_has_every_mask_and_highres_where_the_benchmark_has_it(layout):
    _, scenes = layout
    by_name = {s.name: s for s in scenes}
    assert len(scenes) == 9 and {s.name for s in scenes if s.has_gt(HIGHRES)} == {
        "backgammon", "dots", "pyramids", "stripes"}
    for scene in scenes:  # every region / stratified metric of the scene applies
        expected = {m.id for m in STRATIFIED_METRICS.get(scene.name, REGION_METRICS)}
        assert expected <= {m.id for m in applicable_metrics(scene)}, scene.name
    assert set(by_name["dots"].mask_names(HIGHRES)) == {"mask_background", "mask_boxes", "mask_dots_by_size"}


def test_one_reference_scores_each_prediction_as_a_reference_of_its_own(layout):
    """Scoring several predictions through one scene reference (what the engine keeps per scene) gives each
    one exactly what scoring it alone gives: nothing of one prediction leaks into the next."""
    root, scenes = layout
    rng = np.random.default_rng(3)
    for scene in scenes:
        metrics = applicable_metrics(scene)
        gt = scene.gt_disparity()
        preds = [(gt + rng.normal(0, s, gt.shape)).astype(np.float32) for s in (0.02, 0.3, 0.0)]
        preds[1][2, 3] = np.nan
        together = score_predictions(scene, [(p, 1.0, "m") for p in preds], metrics)
        for pred, score in zip(preds, together, strict=True):
            alone = score_scene(scene, pred, metrics, runtime_s=1.0, source="m")
            assert list(score.values) == list(alone.values) and score.resolution == alone.resolution
            assert [_bits(v) for v in score.values.values()] == [_bits(v) for v in alone.values.values()], scene.name
        if together[2].resolution["badpix_0.07"] == "lowres":
            assert together[2].values["badpix_0.07"] == 0.0  # the exact prediction after two others


def _records(results):
    return ([(r.method, r.scene, r.metric, _bits(r.value), r.resolution) for r in results.records],
            [(r.method, r.scene, _bits(r.runtime_s), r.nonfinite_pixels, r.aligned_from, r.notes)
             for r in results.runs])


def test_jobs_give_the_same_results_as_one_process(layout):
    """``evaluate(jobs=2)`` scores in worker processes: the same records, in the same order, bit for bit, as
    ``jobs=1``; and the records come method by method whatever order the scenes were scored in."""
    root, scenes = layout
    methods = [create_from_spec(f"published:path={root / 'subs' / f'm{k:03d}'}") for k in range(10)]
    metrics = applicable_metrics
    one = evaluate(methods, scenes, metrics=metrics, progress=False)
    two = evaluate(methods, scenes, metrics=metrics, progress=False, jobs=2)
    assert _records(one) == _records(two)
    order = [(r.method, r.scene) for r in one.records]
    assert order == sorted(order, key=lambda k: ([m.label for m in methods].index(k[0]),
                                                 [s.name for s in scenes].index(k[1])))
    assert {r.metric for r in one.records if r.scene == "dots"} >= {"missed_dots", "dots_background_mse"}
    assert any(r.nonfinite_pixels for r in one.runs)  # method 9 leaves NaN pixels


def test_worker_errors_name_the_file(layout, tmp_path):
    """A prediction that cannot be scored fails the same way in a worker as here: one line naming it."""
    root, scenes = layout
    bad = [(np.zeros((5, 5), np.float32), None, "mine.pfm")]
    for jobs in (1, 2):
        with pytest.raises(DataError, match="mine.pfm"):
            score_scenes([ScoringTask(0, scenes[0], bad, GENERAL_METRICS, ScoringRules())], jobs=jobs, on_done=print)


def test_jobs_need_registered_metrics_and_a_positive_count(layout):
    root, scenes = layout
    odd = Metric(id="my_metric", name="mine", description="", unit="", fn=lambda gt, pred, mask=None, **k: 0.0)
    task = ScoringTask(0, scenes[0], [(scenes[0].gt_disparity(), None, "m")], (odd,), ScoringRules())
    with pytest.raises(SpecError, match="my_metric"):
        score_scenes([task], jobs=2, on_done=print)
    done = []
    score_scenes([task], jobs=1, on_done=done.append)  # in this process any metric scores
    assert [(index, scores[0].values) for index, scores in done] == [(0, {"my_metric": 0.0})]
    for jobs in (0, -1, 1.5, True):
        with pytest.raises(SpecError, match="jobs"):
            score_scenes([task], jobs=jobs, on_done=print)


def test_cli_jobs_option(layout, tmp_path):
    root, _ = layout
    outs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"j{jobs}"
        proc = subprocess.run([sys.executable, "-m", "lfbench", "-q", "evaluate", "--data", str(root / "data"),
                               "--method", f"published:path={root / 'subs' / 'm000'}", "--method",
                               f"published:path={root / 'subs' / 'm009'}", "--all-metrics", "--jobs", jobs,
                               "--out", str(out), "--no-progress"], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
        outs.append((out / "results.csv").read_bytes())
    assert outs[0] == outs[1]
    proc = subprocess.run([sys.executable, "-m", "lfbench", "evaluate", "--data", str(root / "data"), "--method",
                           "oracle", "--jobs", "0", "--out", str(tmp_path / "x")], capture_output=True, text=True)
    assert proc.returncode == 2 and "--jobs" in proc.stderr and "Traceback" not in proc.stderr


def test_scale_benchmark_quick_run(tmp_path):
    """benchmarks/scoring_scale.py --quick runs end to end and writes its record (the numbers are not judged)."""
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "scoring_scale.py"), "--quick", "--work",
                           str(tmp_path / "work"), "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    record = json.loads((tmp_path / "out" / "scoring_scale.json").read_text())
    assert [m["methods"] for m in record["methods"]] == [1, 2] and record["jobs"]["identical"] is True
    assert record["floor"]["per_method_s"] > 0 and record["data"]["scenes_issue"] == 9
    assert (tmp_path / "out" / "scoring_scale.md").read_text().startswith("# Scoring at scale")


def test_training_validation_scores_as_the_formulas():
    """Validation during training scores through the same errors: per scene and pooled over the pixels of
    every scene inside the border, BadPix and MSE as written out (non-finite gt pixels left out)."""
    import torch

    from lfbench.training.data import ValidationScene
    from lfbench.training.validate import validate

    rng = np.random.default_rng(5)
    preds = {}

    class Fixed(torch.nn.Module):  # returns the prediction stored for the scene whose views it is given
        def forward(self, views):
            return torch.from_numpy(preds[float(views[0, 0, 0, 0])])[None], None

    scenes = []
    for k, shape in enumerate(((30, 34), (28, 28))):
        gt = rng.uniform(-1, 1, shape).astype(np.float32)
        gt[10, 10] = np.nan
        pred = (gt + rng.normal(0, 0.08, shape)).astype(np.float32)
        pred[12, 12] = np.inf
        views = np.full((9, *shape), k, np.float32)
        preds[float(k)] = pred
        scenes.append(ValidationScene(name=f"s{k}", views=views, gt=gt))
    out = validate(Fixed(), scenes, torch.device("cpu"), border=4, threshold=0.07)
    gts, ps = [], []
    for s in scenes:
        mask = np.zeros(s.gt.shape, bool)
        mask[4:-4, 4:-4] = True
        mask &= np.isfinite(s.gt)
        pred = preds[float(s.views[0, 0, 0])]
        assert out["scenes"][s.name]["badpix"] == _old_bad_pix(s.gt, pred, 0.07, mask, False)
        assert out["scenes"][s.name]["mse_x100"] == _old_mse(s.gt, pred, mask)
        gts.append(s.gt[mask])
        ps.append(pred[mask])
    gt, pred = np.concatenate(gts), np.concatenate(ps)
    everything = np.ones(gt.shape, bool)
    assert out["badpix"] == _old_bad_pix(gt, pred, 0.07, everything, False)
    assert out["mse_x100"] == _old_mse(gt, pred, everything) and out["pixels"] == gt.size == 22 * 26 + 20 * 20 - 2


def test_training_validation_scores_by_the_paper_authors_scorer():
    """scorer="paper-author" (the UrbanLF-Syn protocol's, lfbench.scoring.policy): BadPix counts |error| >= t over
    every pixel inside the border (a NaN prediction good, an exact tie bad), MSE x100 is 100 x the plain mean (one NaN
    makes it NaN); pooled over the scenes the same way. Worked out by hand on 2 x 2 scored pixels per scene."""
    import torch

    from lfbench.training.data import ValidationScene
    from lfbench.training.validate import validate

    gt = np.zeros((4, 4), np.float32)
    preds = {0.0: np.full((4, 4), 0.5, np.float32), 1.0: np.full((4, 4), 0.5, np.float32)}
    preds[0.0][1:3, 1:3] = [[0.5, 0.0], [0.25, 0.125]]  # errors 0.5 (tie at t = 0.5), 0, 0.25, 0.125
    preds[1.0][1:3, 1:3] = [[np.nan, 1.0], [0.0, 0.0]]  # NaN, 1, 0, 0

    class Fixed(torch.nn.Module):
        def forward(self, views):
            return torch.from_numpy(preds[float(views[0, 0, 0, 0])])[None], None

    scenes = [ValidationScene(name=f"s{k}", views=np.full((9, 4, 4), k, np.float32), gt=gt) for k in (0, 1)]
    author = validate(Fixed(), scenes, torch.device("cpu"), border=1, threshold=0.5, scorer="paper-author")
    assert author["scenes"]["s0"] == {"badpix": 25.0, "mse_x100": 100 * (0.25 + 0.0625 + 0.015625) / 4}
    assert author["scenes"]["s1"]["badpix"] == 25.0 and np.isnan(author["scenes"]["s1"]["mse_x100"])
    assert author["badpix"] == 25.0 and np.isnan(author["mse_x100"]) and author["pixels"] == 8
    # lfbench's own (the default): > t, a NaN prediction bad, MSE over the finite errors
    own = validate(Fixed(), scenes, torch.device("cpu"), border=1, threshold=0.5)
    assert own["scenes"]["s0"]["badpix"] == 0.0 and own["scenes"]["s1"]["badpix"] == 50.0
    assert own["scenes"]["s1"]["mse_x100"] == 100 * float(np.float32(1) / np.float32(3))  # float32 errors
    assert own["badpix"] == 25.0
