"""The toolkit's figure types and the leaderboard's ranks, checked against hand-made cases and numpy:
pairwise comparison classes, per-pixel median error and bad fraction over methods, radar scaling,
ranks and average ranks per metric."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from lfbench.reports import toolkit_figures as tk
from lfbench.reports.leaderboard import metric_ranks, metric_table, overall_ranks
from lfbench.results import Record, Results
from lfbench.utils.errors import SpecError

# --------------------------------------------------------------------------- pairwise


def test_pairwise_classes_of_a_hand_made_case():
    gt = np.zeros((2, 4), np.float32)
    a = np.array([[0.00, 0.30, 0.10, np.nan],
                  [0.05, 0.00, np.inf, 0.0]], np.float32)
    b = np.array([[0.20, 0.00, 0.105, 0.0],
                  [0.05, 0.02, np.nan, 0.0]], np.float32)
    mask = np.ones_like(gt, bool)
    mask[1, 3] = False
    codes = tk.pairwise_classes(gt, a, b, mask, threshold=0.01)
    # |a| - |b|:  -0.2 (A), +0.3 (B), -0.005 (tie), inf (B: a non-finite)
    #             0 (tie), -0.02 (A), nan (both non-finite: tie), outside
    expected = np.array([[tk.A_BETTER, tk.B_BETTER, tk.TIE, tk.B_BETTER],
                         [tk.TIE, tk.A_BETTER, tk.TIE, tk.OUTSIDE]], np.uint8)
    np.testing.assert_array_equal(codes, expected)
    share = tk.pairwise_shares(codes)  # 7 scored pixels: A 2, B 2, tie 3
    assert share["a_better"] == pytest.approx(200 / 7)
    assert share["b_better"] == pytest.approx(200 / 7)
    assert share["tie"] == pytest.approx(300 / 7)
    # a threshold of 0.03 turns the 0.02 difference into a tie
    assert tk.pairwise_classes(gt, a, b, mask, threshold=0.03)[1, 1] == tk.TIE
    with pytest.raises(SpecError):
        tk.pairwise_classes(gt, a, b, mask, threshold=-1)


def test_pairwise_image_colours_follow_the_classes():
    gt = np.zeros((1, 3), np.float32)
    a = np.array([[0.0, 0.2, 0.0]], np.float32)
    b = np.array([[0.2, 0.0, 0.0]], np.float32)
    import matplotlib

    seismic = matplotlib.colormaps["seismic"]
    rgb = tk.pairwise_image(gt, a, b, threshold=0.01)
    np.testing.assert_allclose(rgb[0, 0], seismic(0.0)[:3], atol=1e-6)  # A better by 0.2 > 0.1: blue end
    np.testing.assert_allclose(rgb[0, 1], seismic(1.0)[:3], atol=1e-6)  # B better: red end
    np.testing.assert_allclose(rgb[0, 2], [tk.TIE_LIGHT] * 3)  # tie: light grey


def test_pairwise_refuses_maps_of_other_shapes():
    with pytest.raises(SpecError, match="differ in shape"):
        tk.pairwise_difference(np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((3, 3)))


# --------------------------------------------------------------------------- heatmaps

def test_median_error_map_is_numpy_median_of_absolute_errors():
    rng = np.random.default_rng(3)
    gt = rng.normal(size=(6, 7)).astype(np.float32)
    preds = [gt + rng.normal(scale=0.1, size=gt.shape).astype(np.float32) for _ in range(4)]
    mask = np.ones(gt.shape, bool)
    mask[0] = False
    med = tk.median_error_map(gt, preds, mask)
    ref = np.median(np.abs(np.stack([gt - p for p in preds])), axis=0)
    np.testing.assert_allclose(med[1:], ref[1:], rtol=1e-6)
    assert np.isnan(med[0]).all()


def test_median_error_counts_a_non_finite_prediction_as_infinite():
    gt = np.zeros((1, 2), np.float32)
    preds = [np.array([[0.1, np.nan]], np.float32), np.array([[0.3, np.nan]], np.float32),
             np.array([[np.nan, 0.2]], np.float32)]
    med = tk.median_error_map(gt, preds)
    assert med[0, 0] == pytest.approx(0.3)  # median of 0.1, 0.3, inf
    assert math.isinf(med[0, 1])  # median of inf, inf, 0.2


def test_bad_fraction_map_is_the_toolkits_percentage_of_methods():
    gt = np.zeros((1, 3), np.float32)
    preds = [np.array([[0.0, 0.1, np.nan]], np.float32), np.array([[0.08, 0.0, 0.0]], np.float32),
             np.array([[0.0, 0.5, 0.0]], np.float32), np.array([[0.0, 0.06, 0.0]], np.float32)]
    frac = tk.bad_fraction_map(gt, preds, threshold=0.07)
    np.testing.assert_allclose(frac, [[25.0, 50.0, 25.0]])


def test_heatmap_image_greys_nan_and_clips():
    rgb = tk.heatmap_image(np.array([[np.nan, 5.0, np.inf]]), 0.0, 1.0)
    np.testing.assert_allclose(rgb[0, 0], [tk.OUTSIDE_GREY] * 3)
    np.testing.assert_allclose(rgb[0, 1], rgb[0, 2])  # both at the top of the map


# --------------------------------------------------------------------------- radar

def _results(rows) -> Results:
    return Results(records=[Record(m, s, k, v, r) for m, s, k, v, r in rows])


def test_radar_scores_take_the_median_over_scenes_and_scale_like_the_toolkit():
    rows = []
    for metric, vals in {"badpix_0.07": {"A": [1, 2, 9], "B": [4, 4, 4]},
                         "mse_x100": {"A": [0.5, 0.5, 0.5], "B": [1, 2, 3]},
                         "q25_x100": {"A": [0, 0, 0], "B": [0, 0, 0]}}.items():
        for method, v in vals.items():
            rows += [(method, f"s{i}", metric, float(x), "lowres") for i, x in enumerate(v)]
    res = _results(rows)
    scores = tk.radar_scores(res)
    assert list(scores.index) == ["badpix_0.07", "mse_x100", "q25_x100"]
    assert scores.loc["badpix_0.07", "A"] == 2.0 and scores.loc["mse_x100", "B"] == 2.0
    assert tk.radar_scores(res, average="mean").loc["badpix_0.07", "A"] == 4.0
    radii = tk.radar_radii(scores)
    # badpix axis: vmax = 1.2 * 4 = 4.8, step 1.2: A -> (2 + 1.2) / 6 , B -> (4 + 1.2) / 6
    assert radii.loc["badpix_0.07", "A"] == pytest.approx(3.2 / 6.0)
    assert radii.loc["badpix_0.07", "B"] == pytest.approx(5.2 / 6.0)
    # an all-zero axis runs to 1: zeros sit on the first ring (0.2)
    assert radii.loc["q25_x100", "A"] == pytest.approx(0.2)
    with pytest.raises(SpecError):
        tk.radar_scores(res, average="mode")


def test_radar_prefers_region_metrics_when_the_results_hold_them():
    res = _results([("A", "s", "badpix_0.07", 1.0, "lowres"), ("A", "s", "mae_planes", 3.0, "lowres"),
                    ("A", "s", "bumpiness_planes", 0.5, "lowres"), ("A", "s", "discontinuities", 4.0, "highres")])
    assert tk.radar_metric_ids(res) == ["mae_planes", "bumpiness_planes", "discontinuities"]


def test_figures_are_written_in_the_requested_formats(tmp_path):
    scores = pd.DataFrame({"A": [1.0, 2.0, 3.0], "B": [2.0, 1.0, 0.5]},
                          index=["badpix_0.07", "mse_x100", "q25_x100"])
    written = tk.plot_radar(scores, tmp_path / "radar", formats=("png", "pdf", "svg"))
    assert [p.name for p in written] == ["radar.png", "radar.pdf", "radar.svg"]
    assert written[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert written[1].read_bytes()[:5] == b"%PDF-"
    assert b"<svg" in written[2].read_bytes()
    assert b"http" not in written[0].read_bytes()  # no metadata link in the PNG
    # a dot inside the name is kept (a method label such as 'interval=0.25'); a format suffix is replaced
    dotted = tk.plot_radar(scores, tmp_path / "radar_interval=0.25", formats=("png", "svg"))
    assert [p.name for p in dotted] == ["radar_interval=0.25.png", "radar_interval=0.25.svg"]
    assert [p.name for p in tk.plot_radar(scores, tmp_path / "named.png")] == ["named.png"]
    with pytest.raises(SpecError, match="unknown figure format"):
        tk.plot_radar(scores, tmp_path / "x", formats=("gif",))
    with pytest.raises(SpecError, match="at least 3"):
        tk.plot_radar(scores.iloc[:2], tmp_path / "y")


def test_pairwise_and_heatmap_figures_are_drawn_per_scene(tmp_path):
    gt = {"s1": np.zeros((8, 8), np.float32), "s2": np.ones((8, 8), np.float32)}
    a = {s: g + 0.05 for s, g in gt.items()}
    b = {s: g - 0.2 for s, g in gt.items()}
    (png,) = tk.plot_pairwise(gt, a, b, ("A", "B"), tmp_path / "pair")
    assert png.name == "pair.png" and png.stat().st_size > 0
    (heat,) = tk.plot_error_heatmaps(gt, {s: [a[s], b[s]] for s in gt}, tmp_path / "heat", methods=["A", "B"])
    assert heat.stat().st_size > 0
    with pytest.raises(SpecError, match="share no scene"):
        tk.plot_pairwise(gt, {"x": gt["s1"]}, b, ("A", "B"), tmp_path / "none")


# --------------------------------------------------------------------------- ranks

def test_ranks_per_scene_ties_share_the_best_rank_and_nan_is_unranked():
    res = _results([
        ("A", "s1", "badpix_0.07", 1.0, "lowres"), ("B", "s1", "badpix_0.07", 3.0, "lowres"),
        ("C", "s1", "badpix_0.07", 1.0, "lowres"),
        ("A", "s2", "badpix_0.07", 5.0, "highres"), ("B", "s2", "badpix_0.07", 2.0, "highres"),
        ("C", "s2", "badpix_0.07", float("nan"), "highres"),
        ("A", "s1", "mse_x100", 0.2, "lowres"), ("B", "s1", "mse_x100", 0.1, "lowres"),
        ("C", "s1", "mse_x100", 0.3, "lowres"),
    ])
    ranks = metric_ranks(res, "badpix_0.07").set_index(["method", "scene"])["rank"]
    assert ranks[("A", "s1")] == 1 and ranks[("C", "s1")] == 1 and ranks[("B", "s1")] == 3
    assert ranks[("B", "s2")] == 1 and ranks[("A", "s2")] == 2 and math.isnan(ranks[("C", "s2")])
    table = metric_table(res, "badpix_0.07")
    assert table.loc["A", ("average rank", "value")] == 1.5
    assert table.loc["B", ("average rank", "value")] == 2.0
    assert table.loc["C", ("average rank", "value")] == 1.0  # ranked on s1 only
    assert table.loc["A", ("mean", "value")] == 3.0
    assert table.loc["A", ("mean", "resolution")] == "highres+lowres"
    assert table.loc["B", ("s2", "resolution")] == "highres"
    overall = overall_ranks(res)
    # A: ranks 1, 2 (badpix), 2 (mse) -> 5/3; B: 3, 1, 1 -> 5/3; C: 1, 3 -> 2
    assert overall["A"] == pytest.approx(5 / 3) and overall["B"] == pytest.approx(5 / 3) and overall["C"] == 2.0
