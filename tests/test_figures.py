"""Figures: the panel arrays that are drawn (BadPix, signed error, disparity), the evaluate hook's files,
and the BadPix-series curves against the metric definitions."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from lfbench.data.scene import ArrayLightField
from lfbench.method.base import Prediction
from lfbench.reports import figures as fig
from lfbench.reports.plotting import write_image
from lfbench.scoring.metrics import bad_pix
from lfbench.scoring.prepare import border_mask
from lfbench.utils.errors import DataError

RED = np.array([1.0, 0.0, 0.0], dtype=np.float32)


def _is_red(rgb: np.ndarray) -> np.ndarray:
    return np.all(rgb == RED, axis=-1)


def _hand_case():
    """6x6, gt 0 everywhere; errors placed by hand; mask leaves out the first column."""
    gt = np.zeros((6, 6), np.float32)
    pred = np.zeros((6, 6), np.float32)
    pred[1, 1] = 0.07  # |err| == 0.07: not bad (strictly greater)
    pred[1, 2] = 0.0701  # bad
    pred[2, 3] = -0.08  # bad (negative error)
    pred[3, 4] = np.nan  # non-finite: bad
    pred[4, 0] = 5.0  # bad but outside the mask
    pred[5, 5] = 0.069  # good
    mask = np.ones((6, 6), bool)
    mask[:, 0] = False
    expected_bad = np.zeros((6, 6), bool)
    expected_bad[1, 2] = expected_bad[2, 3] = expected_bad[3, 4] = True
    return gt, pred, mask, expected_bad


def test_badpix_map_red_pixels_are_exactly_the_bad_pixels_inside_the_mask():
    gt, pred, mask, expected_bad = _hand_case()
    codes = fig.badpix_codes(gt, pred, mask, 0.07)
    rgb = fig.badpix_image(codes)
    assert rgb.shape == (6, 6, 3) and rgb.dtype == np.float32
    np.testing.assert_array_equal(_is_red(rgb), expected_bad)
    # outside the mask: one grey level, not red, not the good colour
    assert np.all(rgb[~mask] == fig.OUTSIDE_GREY)
    good = mask & ~expected_bad
    assert np.all(rgb[good] > fig.OUTSIDE_GREY + 0.2) and np.all(rgb[good][:, 0] == rgb[good][:, 1])
    # the share of red pixels is the benchmark's BadPix (3 of 30 scored pixels)
    assert 100 * expected_bad.sum() / mask.sum() == pytest.approx(10.0)
    assert bad_pix(gt, pred, 0.07, mask) == pytest.approx(10.0)


def test_badpix_map_with_a_centre_view_background_stays_grey_where_good():
    gt, pred, mask, expected_bad = _hand_case()
    background = np.random.default_rng(0).random((6, 6, 3)).astype(np.float32)
    rgb = fig.badpix_image(fig.badpix_codes(gt, pred, mask), background)
    np.testing.assert_array_equal(_is_red(rgb), expected_bad)
    good = mask & ~expected_bad
    assert np.all(rgb[good][:, 0] == rgb[good][:, 2]) and np.all(rgb[good] >= fig.GOOD_LIGHT[0])


def test_written_badpix_png_has_red_exactly_at_the_bad_pixels(tmp_path):
    gt, pred, mask, expected_bad = _hand_case()
    path = write_image(tmp_path / "bp.png", fig.badpix_image(fig.badpix_codes(gt, pred, mask)))
    with Image.open(path) as img:
        arr = np.asarray(img.convert("RGB"))
    assert arr.shape == (6, 6, 3)
    np.testing.assert_array_equal(np.all(arr == [255, 0, 0], axis=-1), expected_bad)


def test_method_panels_of_a_light_field_mark_the_bad_pixels_of_the_evaluation_mask():
    rng = np.random.default_rng(1)
    h = w = 40
    gt = rng.uniform(-1, 1, (h, w)).astype(np.float32)
    pred = gt + rng.normal(0, 0.08, (h, w)).astype(np.float32)
    lf = ArrayLightField(views=rng.random((3, 3, h, w)).astype(np.float32), name="toy", gt=gt)
    unc = np.abs(pred - gt)
    panels = fig.method_panels("toy-method", lf, Prediction(pred, uncertainty=unc), border_px=15)
    mask = border_mask((h, w), 15)
    expected = (np.abs(gt - pred) > np.float32(0.07)) & mask
    assert expected.any() and (~expected & mask).any()
    np.testing.assert_array_equal(_is_red(panels.badpix), expected)
    assert panels.badpix_percent == pytest.approx(bad_pix(gt, pred, 0.07, mask))
    assert panels.uncertainty is not None and panels.uncertainty.shape == (h, w, 3)
    lo, hi = panels.uncertainty_range
    assert lo == pytest.approx(np.percentile(unc[mask], 1)) and hi == pytest.approx(np.percentile(unc[mask], 99))


def test_signed_error_image_uses_the_diverging_map_over_plus_minus_02():
    import matplotlib

    cmap = matplotlib.colormaps[fig.ERROR_CMAP]
    gt = np.array([[0.0, 0.0, 0.0, 0.0, 0.0]], np.float32)
    pred = np.array([[0.0, -0.2, 0.2, -1.0, np.nan]], np.float32)  # gt - pred = 0, +0.2, -0.2, +1 (clipped), NaN
    mask = np.array([[True, True, True, True, True]])
    rgb = fig.signed_error_image(gt, pred, mask)
    np.testing.assert_allclose(rgb[0, 0], cmap(0.5)[:3], atol=1e-6)
    np.testing.assert_allclose(rgb[0, 1], cmap(1.0)[:3], atol=1e-6)
    np.testing.assert_allclose(rgb[0, 2], cmap(0.0)[:3], atol=1e-6)
    np.testing.assert_allclose(rgb[0, 3], cmap(1.0)[:3], atol=1e-6)
    np.testing.assert_array_equal(rgb[0, 4], fig.NONFINITE_RGB)
    outside = fig.signed_error_image(gt, pred, ~mask)
    assert np.all(outside == fig.OUTSIDE_GREY)


def test_disparity_colours_follow_the_cfg_range_or_the_ground_truth():
    class WithParams:
        class params:  # noqa: N801 - mimics Scene.params
            disp_min, disp_max = -2.0, 3.0

    assert fig.disparity_range(WithParams()) == pytest.approx((-1.8, 2.7))
    gt = np.array([[-0.5, np.nan], [1.5, 0.0]], np.float32)
    lf = ArrayLightField(views=np.zeros((1, 1, 2, 2), np.float32), gt=gt)
    assert fig.disparity_range(lf, gt) == (-0.5, 1.5)
    import matplotlib

    rgb = fig.disparity_image(np.array([[-0.5, 1.5, np.inf]], np.float32), -0.5, 1.5)
    viridis = matplotlib.colormaps["viridis"]
    np.testing.assert_allclose(rgb[0, 0], viridis(0.0)[:3], atol=1e-6)
    np.testing.assert_allclose(rgb[0, 1], viridis(1.0)[:3], atol=1e-6)
    np.testing.assert_array_equal(rgb[0, 2], fig.NONFINITE_RGB)


class _Method:
    def __init__(self, label: str) -> None:
        self.label = label


def _png_size(path) -> tuple[int, int]:
    with Image.open(path) as img:
        img.verify()
    with Image.open(path) as img:
        assert img.format == "PNG"
        return img.size


def test_hook_writes_overviews_rows_and_curves(tmp_path):
    rng = np.random.default_rng(2)
    h = w = 48
    scenes = []
    for k in range(2):
        gt = rng.uniform(-1.5, 1.5, (h, w)).astype(np.float32)
        scenes.append(ArrayLightField(views=rng.random((3, 3, h, w)).astype(np.float32), name=f"toy{k}", gt=gt))
    hook = fig.SceneFigureWriter(tmp_path / "figs")
    preds = {}
    for label, sigma in (("oracle", 0.0), ("noisy", 0.05)):
        for lf in scenes:
            pred = lf.gt + rng.normal(0, sigma, (h, w)).astype(np.float32) if sigma else lf.gt.copy()
            preds[label, lf.name] = pred
            hook(_Method(label), lf, Prediction(pred))
    out = tmp_path / "figs"
    row_w, row_h = _png_size(out / "toy0" / "header.png")
    assert row_w >= 800 and row_h >= 200
    for lf in scenes:
        assert _png_size(out / lf.name / "oracle.png") == (row_w, row_h)
        assert _png_size(out / lf.name / "noisy.png") == (row_w, row_h)
        assert _png_size(out / f"overview_{lf.name}.png") == (row_w, 3 * row_h)  # header + 2 methods
        assert _png_size(out / lf.name / "badpix_series.png")[0] > 300
    assert _png_size(out / "badpix_series.png")[0] > 300
    # the writer keeps file names and curves, never the maps
    assert all(isinstance(p, type(out)) for rows in hook._rows.values() for p in rows.values())
    curves = fig.read_curves_csv(out / "badpix_series.csv")
    assert {(c.method, c.scene) for c in curves} == set(preds)
    mask = border_mask((h, w), 15)
    for c in curves:
        gt = next(s.gt for s in scenes if s.name == c.scene)
        assert c.resolution == "lowres" and len(c.thresholds) == 101
        for t in (0.0, 0.01, 0.03, 0.07, 0.1):
            i = int(np.argmin(np.abs(c.thresholds - t)))
            assert c.values[i] == pytest.approx(bad_pix(gt, preds[c.method, c.scene], t, mask))
    noisy = [c for c in curves if c.method == "noisy"]
    assert all(np.all(np.diff(c.values) <= 0) for c in noisy)  # BadPix falls as t grows
    avg = fig.average_curves(curves)
    np.testing.assert_allclose(avg["noisy"][1], np.mean([c.values for c in noisy], axis=0))
    assert avg["noisy"][2] == 2


def test_curves_from_records_average_the_stored_thresholds():
    from lfbench.results import Record, Results

    values = (("a", "badpix_0.07", 2.0), ("a", "badpix_0.01", 8.0), ("b", "badpix_0.07", 4.0),
              ("b", "badpix_0.01", 10.0), ("b", "mse_x100", 1.0))
    r = Results(records=[Record("m", s, k, v, "lowres") for s, k, v in values])
    series = fig.curves_from_records(r)
    (method, (t, v, scenes)), = series.items()
    assert method == "m" and scenes == 2
    np.testing.assert_allclose(t, [0.01, 0.07])
    np.testing.assert_allclose(v, [9.0, 3.0])


def test_malformed_curve_csv_is_a_data_error(tmp_path):
    bad = tmp_path / "c.csv"
    bad.write_text("method,scene,resolution,threshold,value\nm,s,lowres,x,1\n")
    with pytest.raises(DataError, match="c.csv.*line 2"):
        fig.read_curves_csv(bad)
    with pytest.raises(DataError, match="expected columns"):
        (tmp_path / "d.csv").write_text("a,b\n1,2\n")
        fig.read_curves_csv(tmp_path / "d.csv")


def test_curve_on_a_real_scene_matches_the_scored_badpix(hci_root, tmp_path):
    from lfbench.data.hci import HCIDataset
    from lfbench.scoring.score import score_scene

    scene = HCIDataset.open(hci_root).select(["backgammon"])[0]
    gt = scene.gt_disparity()
    pred = gt + np.float32(0.05) * np.sign(np.sin(np.arange(gt.size, dtype=np.float32))).reshape(gt.shape)
    pred[200:220, 200:220] += 0.5
    curve = fig.scene_curve("m", scene, pred)
    score = score_scene(scene, pred)
    for t in (0.01, 0.03, 0.07):
        assert curve.values[int(round(t * 1000))] == pytest.approx(score.values[f"badpix_{t:g}"], abs=1e-9)
    assert curve.resolution == score.resolution["badpix_0.07"]
    writer = fig.figures_from_maps([scene], {}, tmp_path)
    assert not writer.written
    writer.add("m", scene, Prediction(pred))
    assert _png_size(tmp_path / "overview_backgammon.png")[1] == 2 * _png_size(tmp_path / "backgammon" / "m.png")[1]
