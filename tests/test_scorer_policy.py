"""Issue 39 class 5: BadPix's comparison and the non-finite policy are a protocol's declared scorer
(lfbench.scoring.policy). UrbanLF-Syn is scored as the paper author's public scorer (ContextNet
evalution_urban.py: |error| >= t, NaN good in BadPix, MSE NaN); HCI and the TOML default keep lfbench's
(|error| > t, a non-finite prediction bad, left out of MSE). Values are computed by hand on maps whose errors
are exact in float32, with ties at the threshold and non-finite pixels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfbench.data.dataset import DATASETS
from lfbench.scoring.metrics import get_metric
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.policy import LFBENCH, PAPER_AUTHOR, scorer
from lfbench.scoring.rules import ScoringRules

NAN, INF = float("nan"), float("inf")


def _errors(pred: list[float], policy) -> PixelErrors:
    gt = np.zeros((2, 4), np.float32)
    px = PixelErrors.of_maps(gt, np.asarray(pred, np.float32).reshape(2, 4))
    px.scorer = policy
    return px


# errors 0.5 (twice, a tie with t = 0.5), 0.25, 1.0 and zeros; then a NaN and an inf prediction
FINITE = [0.5, -0.5, 0.25, 1.0, 0.0, 0.0, 0.0, 0.0]
NONFINITE = [0.5, -0.5, 0.25, 1.0, 0.0, NAN, INF, 0.0]


@pytest.mark.parametrize(("pred", "policy", "badpix", "mse"), [
    (FINITE, LFBENCH, 100 * 1 / 8, 100 * (0.25 + 0.25 + 0.0625 + 1.0) / 8),  # > t: only 1.0 is bad
    (FINITE, PAPER_AUTHOR, 100 * 3 / 8, 100 * (0.25 + 0.25 + 0.0625 + 1.0) / 8),  # >= t: the two ties too
    (NONFINITE, LFBENCH, 100 * 3 / 8, 100 * (0.25 + 0.25 + 0.0625 + 1.0) / 6),  # NaN, inf bad; left out of MSE
    (NONFINITE, PAPER_AUTHOR, 100 * 4 / 8, NAN),  # ties and inf bad, NaN good; MSE NaN
])
def test_badpix_and_mse_of_each_scorer_on_hand_computed_maps(pred, policy, badpix, mse):
    px = _errors(pred, policy)
    assert get_metric("badpix_0.5").score_pixels(px) == badpix
    got = get_metric("mse_x100").score_pixels(px)
    assert (math.isnan(got) and math.isnan(mse)) or got == pytest.approx(mse, rel=1e-7)


def test_the_protocols_declare_their_scorer():
    assert DATASETS.get("urbanlf-syn").protocol.scorer == "paper-author"
    assert DATASETS.get("hci").protocol.scorer == "lfbench"
    assert DATASETS.get("toml").protocol.scorer == "lfbench"
    assert scorer("paper-author") is PAPER_AUTHOR and "evalution_urban.py" in PAPER_AUTHOR.source
    with pytest.raises(ValueError, match="unknown scorer"):
        scorer("other")


def test_rules_record_the_scorer_only_when_it_is_not_lfbench():
    hci = ScoringRules.of_protocol(DATASETS.get("hci").protocol)
    assert "scorer" not in hci.to_meta()  # HCI's results files stay byte for byte as they were
    urban = ScoringRules.of_protocol(DATASETS.get("urbanlf-syn").protocol)
    assert urban.to_meta()["scorer"] == "paper-author"
    assert ScoringRules.from_meta({"scoring": urban.to_meta()}, allow_highres=False) == urban
    with pytest.raises(ValueError, match="'scoring.scorer'"):
        ScoringRules.from_meta({"scoring": {"scorer": "mine"}})


def test_a_toml_dataset_chooses_its_scorer(tmp_path, capsys):
    from helpers import assert_one_error_line, run_cli
    from test_hostile_round4 import _toml

    from lfbench.data.generic import read_dataset_spec

    root, _ = _toml(tmp_path, extra='scorer = "paper-author"\n')
    assert read_dataset_spec(root / "lfbench-dataset.toml")[1].scorer == "paper-author"
    (root / "lfbench-dataset.toml").write_text((root / "lfbench-dataset.toml").read_text().replace(
        "paper-author", "strict"))
    rc, _, err = run_cli(capsys, "check-dataset", root, "--no-progress")
    assert_one_error_line(rc, err, "lfbench-dataset.toml", "protocol.scorer: expected one of 'lfbench', 'paper-author'")


def test_urbanlf_scores_ties_as_the_paper_author_and_hci_as_lfbench(tmp_path):
    """End to end on a scene: a prediction whose error equals the threshold at some pixels."""
    from helpers import write_scene

    from lfbench.data.hci import HCIScene
    from lfbench.scoring.score import score_scene

    scene = HCIScene(write_scene(tmp_path, "s", size=40, view_disparity=1))  # gt = 1 everywhere
    pred = np.full((40, 40), 1.0, np.float32)
    pred[15:20, 15:25] = 1.5  # 50 of the 100 scored pixels off by exactly 0.5
    metric = get_metric("badpix_0.5")
    assert score_scene(scene, pred, [metric], ScoringRules()).values["badpix_0.5"] == 0.0
    urban = ScoringRules(scorer="paper-author")
    assert score_scene(scene, pred, [metric], urban).values["badpix_0.5"] == 50.0
