"""Sparsification curves and AUSE (lfbench.scoring.uncertainty): a hand-computed 4-pixel example, the oracle
and random limits, tie handling, measures against lfbench.scoring.metrics, and the figure."""

from __future__ import annotations

import numpy as np
import pytest

from lfbench.reports.uncertainty import plot_sparsification, write_uncertainty_report
from lfbench.scoring import uncertainty as U
from lfbench.scoring.metrics import bad_pix, mse_x100

# 4 pixels: true absolute errors and predicted uncertainties
ERR = np.array([0.1, 0.4, 0.2, 0.3])
UNC = np.array([1.0, 3.0, 4.0, 2.0])  # removal order: pixel 2 (0.2), 1 (0.4), 3 (0.3), 0 (0.1)


def test_four_pixel_example_by_hand():
    f = [0.0, 0.25, 0.5, 0.75]
    sp = U.sparsification_from_loss(ERR, UNC, fractions=f)
    # remaining after removing 0, 1, 2, 3 pixels by uncertainty: {all}, {.1,.4,.3}, {.1,.3}, {.1}
    assert sp.curve == pytest.approx([0.25, 0.8 / 3, 0.2, 0.1])
    # by true error: {all}, {.1,.2,.3}, {.1,.2}, {.1}
    assert sp.oracle == pytest.approx([0.25, 0.2, 0.15, 0.1])
    assert sp.random == pytest.approx([0.25] * 4)
    # trapezoid of (0, 1/15, 1/20, 0) with steps of 1/4: (1/4) * (1/15 + 1/20) = 7/240
    assert sp.ause == pytest.approx(7 / 240)
    # random - curve = (0, -1/60, 1/20, 3/20): (1/4) * (-1/120 + (-1/60 + 1/20)/2 + (1/20 + 3/20)/2)
    assert sp.aurg == pytest.approx(0.25 * (-1 / 120 + 1 / 60 + 1 / 10))


def test_four_pixels_on_the_default_fraction_grid():
    sp = U.sparsification_from_loss(ERR, UNC)
    assert sp.fractions[0] == 0 and sp.fractions[-1] == 0.99 and sp.fractions.size == 100
    # floor(f * 4) pixels removed: step changes exactly at f = 0.25, 0.5, 0.75
    assert sp.curve[24] == pytest.approx(0.25) and sp.curve[25] == pytest.approx(0.8 / 3)
    assert sp.curve[49] == pytest.approx(0.8 / 3) and sp.curve[50] == pytest.approx(0.2)
    assert sp.curve[74] == pytest.approx(0.2) and sp.curve[75:] == pytest.approx(0.1)
    # the step curves differ by 1/15 on [0.25, 0.49], 1/20 on [0.5, 0.74]; ramps over one 0.01 step
    # at each end: 0.01 * (1/30 + 24/15 + (1/15 + 1/20)/2 + 24/20 + 1/40) = 7/240
    assert sp.ause == pytest.approx(7 / 240)


def test_removed_counts_are_exact_at_decimal_fractions():
    assert U.removed_counts([0.0, 0.29, 0.5, 0.99], 100).tolist() == [0, 29, 50, 99]
    assert U.removed_counts([0.99], 4).tolist() == [3]
    assert U.removed_counts([0.99], 1).tolist() == [0]  # at least one pixel is kept
    with pytest.raises(ValueError):
        U.removed_counts([0.5, 0.2], 10)


def test_true_error_as_uncertainty_is_the_oracle():
    rng = np.random.default_rng(0)
    loss = np.round(rng.exponential(0.05, 5000), 3)  # many ties
    sp = U.sparsification_from_loss(loss, loss)
    np.testing.assert_allclose(sp.curve, sp.oracle, rtol=1e-12)
    assert sp.ause == pytest.approx(0.0, abs=1e-12)
    # a monotone transform ranks the same: still the oracle
    assert U.sparsification_from_loss(loss, np.sqrt(loss) * 3 + 1).ause == pytest.approx(0.0, abs=1e-12)


def test_random_uncertainty_gives_a_nearly_flat_curve():
    rng = np.random.default_rng(1)
    loss = rng.exponential(0.05, 20000)
    sp = U.sparsification_from_loss(loss, rng.random(loss.size))
    flat = sp.random[0]
    assert flat == pytest.approx(loss.mean())
    assert np.max(np.abs(sp.curve[:91] - flat)) / flat < 0.1  # f <= 0.9: >= 2000 pixels remain
    assert abs(sp.aurg) < 0.02 * flat
    # an uninformative ranking loses (almost) the whole area between random and oracle
    assert sp.ause == pytest.approx(U.area_between(sp.fractions, sp.random, sp.oracle), rel=0.05)


def test_constant_uncertainty_is_exactly_random_and_inverted_is_worse():
    rng = np.random.default_rng(2)
    loss = rng.exponential(0.05, 1000)
    const = U.sparsification_from_loss(loss, np.ones(loss.size))
    np.testing.assert_allclose(const.curve, const.random, rtol=1e-12)
    assert const.aurg == pytest.approx(0.0, abs=1e-12)
    inverted = U.sparsification_from_loss(loss, -loss)
    assert inverted.aurg < 0 and inverted.ause > const.ause
    assert np.all(np.diff(inverted.curve) >= -1e-15)  # removing the best pixels first: the error rises


def test_nonfinite_uncertainty_is_removed_first():
    sp = U.sparsification_from_loss(np.array([0.9, 0.1, 0.2]), np.array([np.nan, 5.0, 1.0]), fractions=[0.0, 0.34])
    assert sp.curve == pytest.approx([0.4, 0.15])


def test_maps_measures_agree_with_metrics_at_zero_removed():
    rng = np.random.default_rng(3)
    gt = rng.uniform(-1, 1, (30, 30)).astype(np.float32)
    pred = gt + (rng.standard_normal(gt.shape) * 0.06).astype(np.float32)
    pred[4, 4] = np.nan
    mask = np.ones(gt.shape, bool)
    mask[:3] = False
    unc = np.abs(pred - gt) + rng.random(gt.shape) * 0.02
    bp = U.sparsification(gt, pred, unc, mask, "badpix_0.07")
    assert bp.curve[0] == pytest.approx(bad_pix(gt, pred, 0.07, mask)) and bp.unit == "%"
    assert bp.n_pixels == 27 * 30  # the NaN prediction is a bad pixel, kept
    mse = U.sparsification(gt, pred, unc, mask, "sq")
    assert mse.measure == "mse_x100" and mse.curve[0] == pytest.approx(mse_x100(gt, pred, mask), rel=1e-5)
    epe = U.sparsification(gt, pred, unc, mask)
    assert epe.n_pixels == 27 * 30 - 1  # the NaN prediction is left out
    assert epe.curve[0] == pytest.approx(np.nanmean(np.abs(pred - gt)[mask]), rel=1e-5)
    assert epe.ause < 0.2 * epe.aurg  # an informative uncertainty: close to the oracle
    norm = U.sparsification(gt, pred, unc, mask, normalize=True)
    assert norm.curve[0] == pytest.approx(1.0) and norm.ause == pytest.approx(epe.ause / epe.curve[0])


def test_average_over_scenes():
    rng = np.random.default_rng(4)
    items = [U.sparsification_from_loss(rng.exponential(0.05, 500), rng.random(500)) for _ in range(3)]
    avg = U.average_sparsification(items)
    assert avg.ause == pytest.approx(np.mean([it.ause for it in items]))
    assert avg.n_pixels == 1500


def test_plot_writes_a_png_atomically(tmp_path):
    from PIL import Image

    sp = U.sparsification_from_loss(ERR, UNC)
    other = U.sparsification_from_loss(ERR, ERR)
    path = plot_sparsification({"subfocal": sp, "oracle-like": other}, tmp_path / "fig" / "sparsification.png",
                                 title="4 pixels")
    with Image.open(path) as im:
        assert im.format == "PNG" and im.size[0] > 300
    assert sorted(p.name for p in path.parent.iterdir()) == ["sparsification.png"]  # no temporary left behind
    single = plot_sparsification(sp, tmp_path / "single.png")
    assert single.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_scene_sparsification_on_a_real_scene(hci_root):
    from lfbench.data.hci import HCIDataset
    from lfbench.method.base import Prediction

    scene = next(s for s in HCIDataset.open(hci_root).select([]) if s.name == "backgammon")
    gt = scene.gt_disparity()
    rng = np.random.default_rng(5)
    pred = (gt + rng.standard_normal(gt.shape).astype(np.float32) * 0.05).astype(np.float32)
    err = np.abs(pred - gt)
    cropped = Prediction(pred[4:-4, 4:-4], uncertainty=err[4:-4, 4:-4])  # aligned to the centre like a 504 px map
    sp = U.scene_sparsification(scene, cropped)
    assert sp.n_pixels == 482 * 482  # the 15 px border is not scored
    assert sp.ause == pytest.approx(0.0, abs=1e-9)
    assert sp.curve[0] == pytest.approx(err[15:-15, 15:-15].mean(), rel=1e-5)
    assert U.scene_sparsification(scene, Prediction(pred)) is None


class _Named:
    def __init__(self, label: str) -> None:
        self.label = label


def test_collector_table_and_report(tmp_path):
    from helpers import write_scene

    from lfbench.data.hci import HCIDataset
    from lfbench.method.base import Prediction

    rng = np.random.default_rng(3)
    for k in range(2):
        write_scene(tmp_path / "data", f"s{k}", size=40, gt=rng.uniform(-1, 1, (40, 40)).astype(np.float32), seed=k)
    scenes = list(HCIDataset.open(tmp_path / "data"))
    rater = U.UncertaintyCollector(measures=("sq", "badpix_0.07"))
    assert rater.measures == ("mse_x100", "badpix_0.07")
    expected_full = []
    for scene in scenes:
        gt = scene.gt_disparity()
        pred = gt + rng.standard_normal(gt.shape).astype(np.float32) * 0.1
        err = np.abs(pred - gt)
        rater(_Named("oracle"), scene, Prediction(pred, uncertainty=err))  # ranks exactly like the error
        rater(_Named("inverted"), scene, Prediction(pred, uncertainty=-err))
        rater(_Named("none"), scene, Prediction(pred))
        expected_full.append(100 * np.mean(np.square(pred - gt)[15:-15, 15:-15].astype(np.float64)))
    assert rater.without == {"none"}
    table = U.uncertainty_table(rater.items)
    mse = table[table.measure == "mse_x100"].set_index(["method", "scene"])
    assert set(mse.index) == {(m, s) for m in ("oracle", "inverted") for s in ("s0", "s1", "average")}
    assert mse.loc[("oracle", "s0"), "ause"] == pytest.approx(0.0, abs=1e-9)
    assert mse.loc[("oracle", "s1"), "full"] == pytest.approx(expected_full[1], rel=1e-5)
    assert mse.loc[("inverted", "s0"), "aurg"] < 0 < mse.loc[("oracle", "s0"), "aurg"]
    assert mse.loc[("inverted", "average"), "ause"] == pytest.approx(
        (mse.loc[("inverted", "s0"), "ause"] + mse.loc[("inverted", "s1"), "ause"]) / 2)
    assert (mse.n_pixels.loc[[("oracle", "s0")]] == 10 * 10).all()  # 40 px minus the 15 px border
    written = write_uncertainty_report(rater, tmp_path / "out")
    names = sorted(p.relative_to(tmp_path / "out").as_posix() for p in written)
    assert names == ["figures/sparsification_badpix_0.07.png", "figures/sparsification_mse_x100.png",
                     "table_uncertainty.md", "uncertainty.csv"]
    assert "| inverted" in (tmp_path / "out" / "table_uncertainty.md").read_text()
    assert write_uncertainty_report(U.UncertaintyCollector(), tmp_path / "empty") == []
    assert not (tmp_path / "empty").exists()
