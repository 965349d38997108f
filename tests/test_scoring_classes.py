"""Tests that must fail when scoring changes (issue 31): a held-out hand-mutation round found seven classes of
realistic change that passed the whole relevant suite, because every test sat where the change does not
show. One test per class, each placed where it shows:

(a) a per-scene reference accepted for another folder's scene of the same name (other ground truth);
(b) runtime records tagged with the scene's high resolution (the tests used scenes without high-res GT);
(c) the bootstrap's block size not scaled with resolution (every grouping test ran at scale 1);
(d) tiles per row rounded down (every test width was a multiple of the block);
(e) a tie |e| == t counted bad by the bootstrap / paired / sparsification flags while the metric counts it
    good (no exact float32 ties in those tests);
(f) a NEW record with a non-finite (or out-of-range) value passing the regression gate;
(g) ``--jobs N`` workers scoring under the default rules (jobs 1 and 2 were compared under the default
    rules only: here under --toolkit-nonfinite too).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from helpers import run_cli, write_scene, write_submission

from lfbench.data.hci import HCIScene
from lfbench.data.scene import Scene
from lfbench.results import Record, Results
from lfbench.runs.regress import GoldenRecord, check
from lfbench.scoring.general import bad_pix
from lfbench.scoring.metrics import GENERAL_METRICS, get_metric
from lfbench.scoring.prepare import SceneReference
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import score_scene
from lfbench.scoring.stats import (
    ScoredErrors,
    block_groups,
    bootstrap_metric,
    paired_pixel_test,
    pixel_loss,
    scene_errors,
)
from lfbench.scoring.uncertainty import sparsification

F32 = np.float32
N, S = 20, 10  # a scene of N x N px whose high-resolution ground truth is S times finer
RULES = ScoringRules(border_px=2)


def _highres_scene(root, name: str = "backgammon", seed: int = 5, n: int = N) -> Scene:
    """A high-resolution scene (backgammon: scored at high resolution) of n x n px whose high-res ground truth is
    not a repeat of its low-res one."""
    gt_hi = np.random.default_rng(seed).uniform(-1, 1, (n * S, n * S)).astype(F32)
    return HCIScene(write_scene(root, name, "stratified", size=n, views=False, gt=gt_hi[::S, ::S].copy(),
                             gt_highres=gt_hi))


# --------------------------------------------------------------------------- (a) the reference of a scene

def test_a_reference_serves_its_own_scene_not_another_folders_scene_of_the_same_name(tmp_path):
    twin_a = HCIScene(write_scene(tmp_path, "twin", "stratified", size=N, views=False, gt=np.zeros((N, N), F32)))
    twin_b = HCIScene(write_scene(tmp_path, "twin", "training", size=N, views=False, gt=np.ones((N, N), F32)))
    assert twin_a.name == twin_b.name
    reference = SceneReference(twin_a, RULES)
    pred = np.zeros((N, N), F32)
    assert score_scene(twin_a, pred, GENERAL_METRICS, RULES, reference=reference).values["mse_x100"] == 0.0
    assert score_scene(twin_b, pred, GENERAL_METRICS, RULES).values["mse_x100"] == 100.0  # its own ground truth
    with pytest.raises(ValueError, match="not of the scene scored"):
        score_scene(twin_b, pred, GENERAL_METRICS, RULES, reference=reference)
    with pytest.raises(ValueError, match="not of the scene scored"):  # the bootstrap's errors: the same rule
        scene_errors(twin_b, pred, RULES, reference=reference)
    with pytest.raises(ValueError, match="not of the scene scored"):
        scene_errors(twin_a, pred, ScoringRules(), reference=reference)
    assert np.array_equal(scene_errors(twin_a, pred, RULES, reference=reference).errors,
                          scene_errors(twin_a, pred, RULES).errors)


# --------------------------------------------------------------------------- (b) runtime at low resolution

def test_runtime_records_are_low_resolution_on_a_scene_scored_at_high_resolution(tmp_path, capsys):
    scene = _highres_scene(tmp_path / "data")
    pred = np.zeros((N, N), F32)
    timed = [*GENERAL_METRICS, get_metric("runtime"), get_metric("runtime_log")]
    score = score_scene(scene, pred, timed, RULES, runtime_s=2.0)
    assert score.resolution["badpix_0.07"] == "highres"  # the scene is scored at high resolution ...
    assert score.resolution["runtime"] == score.resolution["runtime_log"] == "lowres"  # ... the time is the map's
    assert score.values["runtime"] == 2.0 and score.values["runtime_log"] == pytest.approx(math.log10(2.0))
    _highres_scene(tmp_path / "data32", n=32)  # the HCI protocol's 15 px border leaves 2 px of 32 to score
    sub = write_submission(tmp_path / "sub", {"backgammon": np.zeros((32, 32), F32)}, {"backgammon": "2.5\n"})
    rc, _, err = run_cli(capsys, "-q", "evaluate", "--data", tmp_path / "data32", "--method", f"published:path={sub}",
                         "--all-metrics", "--out", tmp_path / "out", "--no-progress")
    assert rc == 0, err
    records = json.loads((tmp_path / "out" / "results.json").read_text())["records"]
    resolution = {r["metric"]: r["resolution"] for r in records}
    assert resolution["runtime"] == resolution["runtime_log"] == "lowres"
    assert resolution["badpix_0.07"] == "highres"


# --------------------------------------------------------------------------- (c), (d) the bootstrap's tiles

def test_block_tiles_are_prediction_pixels_at_high_resolution(tmp_path):
    """A block of b prediction px spans b * S scored px a side at high resolution: with tiles of b scored px
    the block bootstrap's intervals are over-confident (backgammon's BadPix CI shrank from [7.8, 10.7] to
    [8.7, 9.7])."""
    scene = _highres_scene(tmp_path)
    pred = np.random.default_rng(1).uniform(-1, 1, (N, N)).astype(F32)
    se = scene_errors(scene, pred, RULES)
    assert se.scale == S and se.shape == (N * S, N * S)
    y, x = np.divmod(se.flat_index.astype(np.int64), N * S)
    side = 3 * S  # a block of 3 prediction px
    tiles_per_row = -(-N * S // side)  # 7: 200 px in tiles of 30
    assert np.array_equal(se.groups(3), (y // side) * tiles_per_row + x // side)
    assert len(np.unique(se.groups(3))) == 6 * 6  # the scored 160 px (border 20 px) lie in 6 tiles a side
    low = ScoredErrors(se.errors, se.flat_index, se.shape, scale=1)
    assert len(np.unique(low.groups(3))) > 40 * len(np.unique(se.groups(3)))  # what scale 1 would have made


@pytest.mark.parametrize(("shape", "block", "per_row"), [((5, 10), 4, 3), ((7, 13), 5, 3), ((4, 4), 3, 2)])
def test_tiles_per_row_are_rounded_up(shape, block, per_row):
    """A width that is not a multiple of the block: the last, narrower tile of a row is a tile of its own
    (rounded down, it shares an id with the first tile of the next row)."""
    mask = np.ones(shape, bool)
    y, x = np.nonzero(mask)
    expected = (y // block) * per_row + x // block
    assert np.array_equal(block_groups(mask, block), expected)
    assert len(np.unique(expected)) == -(-shape[0] // block) * per_row
    se = ScoredErrors(np.zeros(mask.size, F32), np.flatnonzero(mask), shape)
    assert np.array_equal(se.groups(block), expected)
    twice = ScoredErrors(np.zeros(4 * mask.size, F32), np.arange(4 * mask.size), (2 * shape[0], 2 * shape[1]),
                         scale=2)
    yy, xx = np.divmod(np.arange(4 * mask.size), 2 * shape[1])
    assert np.array_equal(twice.groups(block), (yy // (2 * block)) * per_row + xx // (2 * block))


# --------------------------------------------------------------------------- (e) a tie |e| == t is good

def test_a_tie_is_a_good_pixel_in_the_metric_and_in_every_flag():
    t = 0.07
    gt = np.zeros((12, 12), F32)
    tie = np.full((12, 12), F32(t))
    tie[:, 6:] = -F32(t)  # ties of both signs
    assert (np.abs(tie - gt) == F32(t)).all()  # exact float32 ties
    bad = tie * F32(1.5)
    half = np.where(np.arange(12)[None, :] % 2 == 0, tie, bad).astype(F32)
    assert bad_pix(gt, tie, t) == 0.0 and bad_pix(gt, half, t) == 50.0  # the metric: a tie is good
    assert tuple(bootstrap_metric(gt, tie, None, "badpix_0.07", n=50)) == (0.0, 0.0, 0.0)
    assert tuple(bootstrap_metric(gt, tie, None, "badpix_0.07", n=50, block=4)) == (0.0, 0.0, 0.0)
    assert bootstrap_metric(gt, half, None, "badpix_0.07", n=50).estimate == 50.0
    assert np.array_equal(pixel_loss((tie - gt).ravel(), "badpix_0.07")[0], np.zeros(tie.size))
    for block in (None, 4):
        same = paired_pixel_test(gt, tie, gt, None, "badpix_0.07", n=50, block=block)
        assert same.difference == 0.0 and same.low == same.high == 0.0
        assert paired_pixel_test(gt, half, tie, None, "badpix_0.07", n=50, block=block).difference == 50.0
    unc = np.random.default_rng(0).uniform(0, 1, gt.shape).astype(F32)
    curve = sparsification(gt, tie, unc, None, measure="badpix_0.07")
    assert not curve.curve.any() and not curve.oracle.any()
    assert sparsification(gt, half, unc, None, measure="badpix_0.07").curve[0] == 50.0


# --------------------------------------------------------------------------- (f) the gate and NEW records

@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 150.0, -1.0])
def test_a_new_record_that_cannot_be_a_value_fails_the_gate(tmp_path, capsys, value):
    """Only golden records were tested for NaN: a NEW record (absent from the golden file) that is not
    finite, or outside its metric's range, must fail without --fail-on-new."""
    golden = [GoldenRecord("m", "s", "mse_x100", 1.0, 0.0, "lowres")]
    good = Record("m", "s", "mse_x100", 1.0, "lowres")
    passed = check(golden, Results(records=[good, Record("m", "s", "badpix_0.07", 5.0, "lowres")]))
    assert passed.passed and [f.kind for f in passed.findings] == ["new"]
    gate = check(golden, Results(records=[good, Record("m", "s", "badpix_0.07", value, "lowres")]))
    assert not gate.passed
    assert [(f.kind, f.key, f.failed) for f in gate.failures] == [("new", ("m", "s", "badpix_0.07"), True)]
    (tmp_path / "g.json").write_text(json.dumps([{"method": "m", "scene": "s", "metric": "mse_x100", "value": 1.0,
                                                  "tolerance": 0.0, "resolution": "lowres"}]))
    Results(records=[good, Record("m", "s", "badpix_0.07", value, "lowres")]).write(tmp_path / "res")
    rc, out, err = run_cli(capsys, "regress", tmp_path / "g.json", tmp_path / "res" / "results.json")
    assert rc == 1, out + err
    assert "NEW      m/s/badpix_0.07" in out


# --------------------------------------------------------------------------- (g) workers and the rules

def test_scoring_workers_score_under_the_rules_given(tmp_path, capsys):
    """evaluate --jobs 2 against --jobs 1 under --toolkit-nonfinite: the same records (the
    workers were checked under the default rules only); and the rules change them (the maps hold NaN and
    inf, so a worker scoring under the default rules would give other numbers)."""
    maps, size = {}, 48  # scored inside the default 15 px border
    for i, name in enumerate(("one", "two", "three")):
        write_scene(tmp_path / "data", name, "training", size=size, seed=i, views=False)
        pred = np.random.default_rng(i).uniform(0.9, 1.1, (size, size)).astype(F32)
        pred[16:24, 16:30] = np.nan
        pred[26:28, 18:30] = np.inf
        maps[name] = pred
    sub = write_submission(tmp_path / "sub", maps)
    runs = {}
    for rules in ((), ("--toolkit-nonfinite",)):
        for jobs in ("1", "2"):
            out = tmp_path / f"out_{len(rules)}_{jobs}"
            rc, _, err = run_cli(capsys, "-q", "evaluate", "--data", tmp_path / "data", "--method",
                                 f"published:path={sub}", "--out", out, "--jobs", jobs, "--no-progress", *rules)
            assert rc == 0, err
            results = json.loads((out / "results.json").read_text())
            runs[len(rules), jobs] = (results["records"], results["meta"]["scoring"])
    for rules in (0, 1):
        assert runs[rules, "1"] == runs[rules, "2"]
    values = {k: {(r["scene"], r["metric"]): r["value"] for r in v[0]} for k, v in runs.items()}
    for scene in maps:  # NaN: a bad pixel by default, a good one under the toolkit's rule; Q25 too
        for metric in ("badpix_0.07", "badpix_0.01", "q25_x100"):
            assert values[0, "1"][scene, metric] > values[1, "2"][scene, metric], (scene, metric)
    assert runs[1, "2"][1]["toolkit_nonfinite"] is True and runs[0, "2"][1]["toolkit_nonfinite"] is False
