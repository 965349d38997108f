"""Scoring rules: 15 px border, the high-resolution rule, cropped predictions, non-finite predictions,
the runner, and the published SubFocal maps on the real backgammon (independent numpy reference)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import write_scene, write_submission
from PIL import Image
from scipy import ndimage

from lfbench.cli import main
from lfbench.data.hci import HCIScene
from lfbench.method.registry import create
from lfbench.runs.runner import evaluate
from lfbench.scoring.metrics import GENERAL_METRICS
from lfbench.scoring.prepare import border_mask, upsample_nearest
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import score_scene
from lfbench.utils.errors import DataError

GENERAL_IDS = ["badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100"]


def reference_scores(gt: np.ndarray, pred: np.ndarray, border: int) -> dict[str, float]:
    """The five general metrics straight from their definitions (finite predictions), on the border mask."""
    g = gt[border:gt.shape[0] - border, border:gt.shape[1] - border].astype(np.float32).ravel()
    p = pred[border:pred.shape[0] - border, border:pred.shape[1] - border].astype(np.float32).ravel()
    err = np.abs(g - p)
    out = {f"badpix_{t:g}": 100.0 * np.count_nonzero(err > t) / err.size for t in (0.01, 0.03, 0.07)}
    out["mse_x100"] = float(np.mean(np.square(g - p))) * 100
    s = np.sort(err * 100)
    out["q25_x100"] = float(s[int(0.25 * s.size)])
    return out


def assert_scores(values: dict[str, float], ref: dict[str, float]) -> None:
    for key, expected in ref.items():
        assert values[key] == pytest.approx(expected, rel=1e-5, abs=1e-9), key


def _noisy(gt: np.ndarray, seed: int, scale: float = 0.05) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (gt + rng.standard_normal(gt.shape) * scale).astype(np.float32)


# --------------------------------------------------------------------------- border


def test_border_mask():
    assert border_mask((40, 30), 15).sum() == 0  # 30 - 2 * 15 = 0 columns left
    m = border_mask((40, 36), 15)
    assert m.shape == (40, 36) and m.sum() == 10 * 6
    assert m[15, 15] and m[24, 20] and not m[14, 20] and not m[25, 20] and not m[20, 21]


def test_errors_inside_the_15px_border_do_not_count(tmp_path):
    gt = np.random.default_rng(0).uniform(-1, 1, (40, 40)).astype(np.float32)
    scene = HCIScene(write_scene(tmp_path, "tiny", size=40, views=False, gt=gt))
    pred = gt.copy()
    pred[:15] += 5
    pred[:, 25:] = np.nan
    score = score_scene(scene, pred, GENERAL_METRICS)
    assert score.values == {"badpix_0.01": 0.0, "badpix_0.03": 0.0, "badpix_0.07": 0.0, "mse_x100": 0.0,
                            "q25_x100": 0.0}
    assert score.nonfinite_pixels == 0 and set(score.resolution.values()) == {"lowres"}
    pred[15, 15] += 1.0  # first pixel inside the mask: 1 of 100 bad
    score = score_scene(scene, pred, GENERAL_METRICS)
    assert score.values["badpix_0.07"] == pytest.approx(1.0)
    assert score.values["mse_x100"] == pytest.approx(1.0, rel=1e-5)  # 100 * 1^2 / 100


def test_low_resolution_scores_match_definitions(tmp_path):
    gt = np.random.default_rng(1).uniform(-1, 1, (40, 40)).astype(np.float32)
    scene = HCIScene(write_scene(tmp_path, "boxes", size=40, views=False, gt=gt))
    pred = _noisy(gt, 2)
    score = score_scene(scene, pred, GENERAL_METRICS)
    assert_scores(score.values, reference_scores(gt, pred, 15))
    assert score.resolution == dict.fromkeys(GENERAL_IDS, "lowres")


def test_valid_mask_restricts_scoring(tmp_path):
    gt = np.zeros((40, 40), np.float32)
    folder = write_scene(tmp_path, "v", size=40, views=False, gt=gt)
    valid = np.ones((40, 40), np.uint8) * 255
    valid[15:20, 15:25] = 0  # half of the 10x10 interior is invalid
    Image.fromarray(valid).save(folder / "valid_mask.png")
    pred = gt.copy()
    pred[15:20, 15:25] = 1.0  # errors only where invalid
    pred[20, 15] = 1.0  # one error of the 50 valid pixels
    score = score_scene(HCIScene(folder), pred, GENERAL_METRICS)
    assert score.values["badpix_0.07"] == pytest.approx(2.0)


# --------------------------------------------------------------------------- high resolution


def _zoom_by_definition(a: np.ndarray, factor: int) -> np.ndarray:
    """scipy.ndimage.zoom(order=0, grid_mode=False) written out: output o samples input round(o (n-1)/(N-1))."""
    n = a.shape[0]
    big = n * factor
    idx = np.rint(np.arange(big) * (n - 1) / (big - 1)).astype(int)
    return a[np.ix_(idx, idx)]


@pytest.mark.parametrize("name", ["backgammon", "dots", "stripes"])
def test_highres_rule(tmp_path, name):
    rng = np.random.default_rng(3)
    gt_low = rng.uniform(-1, 1, (40, 40)).astype(np.float32)
    gt_high = np.kron(gt_low, np.ones((10, 10), np.float32)) + rng.standard_normal((400, 400)).astype(
        np.float32) * np.float32(0.02)
    scene = HCIScene(write_scene(tmp_path, name, "stratified", size=40, views=False, gt=gt_low, gt_highres=gt_high))
    pred = _noisy(gt_low, 4, 0.03)
    score = score_scene(scene, pred, GENERAL_METRICS)
    assert score.resolution == dict.fromkeys(GENERAL_IDS, "highres")
    up = _zoom_by_definition(pred, 10)
    assert np.array_equal(up, ndimage.zoom(pred, 10, order=0)) and np.array_equal(up, upsample_nearest(pred, 10))
    assert not np.array_equal(up, np.kron(pred, np.ones((10, 10), np.float32)))  # zoom is not plain repetition
    assert_scores(score.values, reference_scores(gt_high, up, 150))
    # scoring the low-res gt would give other numbers
    assert score.values["badpix_0.01"] != pytest.approx(reference_scores(gt_low, pred, 15)["badpix_0.01"])
    # --lowres-only
    low = score_scene(scene, pred, GENERAL_METRICS, ScoringRules(allow_highres=False))
    assert low.resolution == dict.fromkeys(GENERAL_IDS, "lowres")
    assert_scores(low.values, reference_scores(gt_low, pred, 15))


def test_highres_gt_of_another_scene_is_not_used(tmp_path):
    gt_low = np.zeros((40, 40), np.float32)
    scene = HCIScene(write_scene(tmp_path, "boxes", size=40, views=False, gt=gt_low,
                              gt_highres=np.ones((400, 400), np.float32)))
    assert score_scene(scene, gt_low, GENERAL_METRICS).resolution == dict.fromkeys(GENERAL_IDS, "lowres")


def test_backgammon_without_highres_gt_is_scored_at_low_resolution(tmp_path):
    gt = np.random.default_rng(5).uniform(-1, 1, (40, 40)).astype(np.float32)
    scene = HCIScene(write_scene(tmp_path, "backgammon", "stratified", size=40, views=False, gt=gt))
    pred = _noisy(gt, 6)
    score = score_scene(scene, pred, GENERAL_METRICS)
    assert score.resolution == dict.fromkeys(GENERAL_IDS, "lowres")
    assert_scores(score.values, reference_scores(gt, pred, 15))


# --------------------------------------------------------------------------- cropped / wrong-sized predictions


@pytest.fixture(scope="module")
def scene512(tmp_path_factory):
    gt = np.random.default_rng(7).uniform(-1, 1, (512, 512)).astype(np.float32)
    return HCIScene(write_scene(tmp_path_factory.mktemp("s512"), "cotton", size=512, views=False, gt=gt)), gt


@pytest.mark.parametrize("crop", [482, 490])
def test_cropped_predictions_are_aligned_to_the_centre(scene512, crop):
    scene, gt = scene512
    full = _noisy(gt, 8)
    b = (512 - crop) // 2
    score = score_scene(scene, full[b:b + crop, b:b + crop], GENERAL_METRICS)
    assert score.aligned_from == (crop, crop)
    assert score.notes and f"{crop}x{crop} prediction aligned to the centre of 512x512" in score.notes[0]
    assert score.nonfinite_pixels == 0
    assert score.values == score_scene(scene, full, GENERAL_METRICS).values
    assert_scores(score.values, reference_scores(gt, full, 15))


def test_crop_wider_than_the_border_is_refused(scene512):
    scene, gt = scene512
    with pytest.raises(DataError, match="472x472.*at most the evaluation border"):
        score_scene(scene, gt[20:-20, 20:-20], GENERAL_METRICS)


@pytest.mark.parametrize("shape", [(511, 511), (520, 520), (512, 511), (256, 257)])
def test_wrongly_sized_prediction_is_refused(scene512, shape):
    scene, _ = scene512
    with pytest.raises(DataError) as info:
        score_scene(scene, np.zeros(shape, np.float32), GENERAL_METRICS, source="mymethod on cotton")
    msg = str(info.value)
    assert msg.startswith("mymethod on cotton: ") and f"{shape[1]}x{shape[0]}" in msg and "512x512" in msg


def test_three_dimensional_prediction_is_refused(scene512):
    scene, _ = scene512
    with pytest.raises(DataError, match="2-D"):
        score_scene(scene, np.zeros((512, 512, 3), np.float32), GENERAL_METRICS)


# --------------------------------------------------------------------------- non-finite predictions


def test_nonfinite_prediction_counted_bad_and_reported(tmp_path):
    gt = np.zeros((40, 40), np.float32)
    scene = HCIScene(write_scene(tmp_path, "nan", size=40, views=False, gt=gt))
    pred = gt.copy()
    pred[15, 15:18] = np.nan
    pred[16, 15] = np.inf
    pred[0, 0] = np.nan  # in the border: not scored, not counted
    score = score_scene(scene, pred, GENERAL_METRICS)
    assert score.nonfinite_pixels == 4
    assert score.values["badpix_0.07"] == pytest.approx(4.0)
    assert score.values["mse_x100"] == 0.0
    tk = score_scene(scene, pred, GENERAL_METRICS, ScoringRules(toolkit=True))
    assert tk.values["badpix_0.07"] == pytest.approx(1.0)  # toolkit: NaN good, inf bad
    assert tk.nonfinite_pixels == 4


# --------------------------------------------------------------------------- runner


def test_runner_with_the_oracle(tmp_path):
    gt = np.random.default_rng(9).uniform(-1, 1, (40, 40)).astype(np.float32)
    scene = HCIScene(write_scene(tmp_path, "oracle", size=40, views=False, gt=gt))
    results = evaluate([create("gt")], [scene], metrics=GENERAL_METRICS, progress=False)
    assert {(r.method, r.scene, r.metric, r.resolution) for r in results.records} == {
        ("gt", "oracle", m, "lowres") for m in GENERAL_IDS}
    assert all(r.value == 0.0 for r in results.records)
    assert len(results.runs) == 1 and results.runs[0].runtime_s >= 0 and results.runs[0].nonfinite_pixels == 0


def test_runner_asks_each_method_once_per_scene(tmp_path, monkeypatch, caplog):
    # The up-front check (a method serving no scene is an error) and the skip of one scene use the same answer.
    scenes = [HCIScene(write_scene(tmp_path, name, size=24, views=False)) for name in ("served", "not_served")]
    method = create("gt")
    asked = []

    def available_for(lf):
        asked.append(lf.name)
        return None if lf.name == "served" else "no map for it"

    monkeypatch.setattr(method, "available_for", available_for)
    results = evaluate([method], scenes, progress=False)
    assert asked == ["served", "not_served"]
    assert results.scenes == ["served"]
    assert "skipping gt on not_served: no map for it" in caplog.text


def test_scoring_rules_read_back_from_results_meta(tmp_path):
    rules = ScoringRules(border_px=7, toolkit=True, highres_scenes=frozenset({"dots", "stripes"}))
    scene = HCIScene(write_scene(tmp_path, "oracle", size=24, views=False))
    evaluate([create("gt")], [scene], rules=rules, progress=False).write(tmp_path / "out")
    meta = json.loads((tmp_path / "out" / "results.json").read_text())["meta"]
    assert meta["scoring"] == {"border_px": 7, "toolkit_nonfinite": True, "highres_scenes": ["dots", "stripes"]}
    assert ScoringRules.from_meta(meta) == rules
    assert ScoringRules.from_meta(meta, allow_highres=False) == ScoringRules(7, rules.highres_scenes, True, False)
    assert ScoringRules.from_meta({}) == ScoringRules() == ScoringRules.from_meta({"scoring": {"border_px": 15}})


# --------------------------------------------------------------------------- real data


def _pfm_by_hand(path) -> np.ndarray:
    raw = path.read_bytes()
    ident, dims, scale, rest = raw.split(b"\n", 3)
    w, h = (int(v) for v in dims.split())
    assert ident == b"Pf" and float(scale) < 0
    return np.frombuffer(rest, dtype="<f4").reshape(h, w)[::-1]


def test_published_subfocal_on_real_backgammon(hci_root, shared_data, tmp_path, capsys):
    published = shared_data / "published" / "subfocal"
    if not (published / "disp_maps" / "backgammon.pfm").is_file():
        pytest.skip("published SubFocal maps not available")
    out = tmp_path / "out"
    rc = main(["evaluate", "--data", str(hci_root), "--method", f"published:path={published}",
               "--scenes", "backgammon", "--out", str(out), "--no-progress"])
    assert rc == 0
    data = json.loads((out / "results.json").read_text())
    recs = {r["metric"]: r for r in data["records"]}
    assert {r["scene"] for r in data["records"]} == {"backgammon"}
    assert {r["method"] for r in data["records"]} == {"published:subfocal"}
    for m in GENERAL_IDS:
        assert recs[m]["resolution"] == "lowres"  # no gt_disp_highres.pfm here: labelled as such
    gt = _pfm_by_hand(hci_root / "stratified" / "backgammon" / "gt_disp_lowres.pfm")
    pred = _pfm_by_hand(published / "disp_maps" / "backgammon.pfm")
    ref = reference_scores(gt, pred, 15)
    assert_scores({m: recs[m]["value"] for m in GENERAL_IDS}, ref)
    assert 0 < ref["badpix_0.07"] < 10  # a sane low-resolution number, not a high-res one copied from a paper
    printed = capsys.readouterr().out
    assert "backgammon" in printed and "lowres" in printed and "published:subfocal" in printed
    run = data["runs"][0]
    assert run["runtime_s"] == pytest.approx(float((published / "runtimes" / "backgammon.txt").read_text()))


def test_submission_round_trip_through_published(tmp_path):
    gt = np.random.default_rng(10).uniform(-1, 1, (40, 40)).astype(np.float32)
    scene = HCIScene(write_scene(tmp_path / "data", "tiny", size=40, views=False, gt=gt))
    pred = _noisy(gt, 11)
    sub = write_submission(tmp_path / "sub", {"tiny": pred}, {"tiny": "2.5\n"})
    results = evaluate([create("published", path=sub)], [scene], metrics=GENERAL_METRICS, progress=False)
    assert_scores({r.metric: r.value for r in results.records}, reference_scores(gt, pred, 15))
    assert results.runs[0].runtime_s == 2.5
