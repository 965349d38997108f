"""``planesweep``: the training-free plane-sweep method.

Synthetic light fields are rendered here analytically (no lfbench code): a texture that is a sum of
sinusoids can be evaluated at any real position, so view (u, v) of a surface with disparity d is
exactly ``texture(x + (u - uc) d, y + (v - vc) d)`` (the benchmark's geometry: the centre pixel x is
seen in view u at x - (u - uc) d). A real-data test checks the issue's targets on the HCI scenes.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from lfbench_methods.planesweep import estimator as ps

from lfbench.data.hci import HCIDataset
from lfbench.data.scene import ArrayLightField
from lfbench.data.shift import angular_offsets, shift_views
from lfbench.method.registry import create, create_from_spec
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import score_scene
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.threads import torch_threads

SIZE, ANGULAR = 64, 9


def sinusoid_texture(seed: int, waves: int = 24, k_max: float = 0.9):
    """A band-limited random texture in [0.05, 0.95]: f(x, y) for float arrays of positions (px)."""
    rng = np.random.default_rng(seed)
    k = rng.uniform(0.15, k_max, waves)[:, None, None]
    theta = rng.uniform(0, np.pi, waves)[:, None, None]
    phase = rng.uniform(0, 2 * np.pi, waves)[:, None, None]
    amp = rng.uniform(0.5, 1.0, waves)
    amp = (amp / amp.sum() * 0.45)[:, None, None]

    def f(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return 0.5 + (amp * np.sin(k * (np.cos(theta) * x + np.sin(theta) * y) + phase)).sum(0)

    return f


def render(layer_at) -> np.ndarray:
    """(A, A, SIZE, SIZE) float32 views; layer_at(x, y, du, dv) gives the gray level seen by view (du, dv)."""
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    c = ANGULAR // 2
    views = np.empty((ANGULAR, ANGULAR, SIZE, SIZE), np.float32)
    for v in range(ANGULAR):  # test-data rendering, 81 small images
        for u in range(ANGULAR):
            views[v, u] = layer_at(x, y, u - c, v - c)
    return views


def plane(d: float, seed: int = 0) -> np.ndarray:
    """A textured fronto-parallel plane at disparity d (px per view step)."""
    tex = sinusoid_texture(seed)
    return render(lambda x, y, du, dv: tex(x + du * d, y + dv * d))


def two_layers(d_fg: float = 2.0, d_bg: float = -1.0, lo: int = 20, hi: int = 44) -> tuple[np.ndarray, np.ndarray]:
    """A textured square [lo, hi)^2 at d_fg in front of a textured plane at d_bg: views and exact gt.

    The square is closer (larger disparity), so it hides a band of the background in the outer views:
    a background pixel up to |d_fg - d_bg| * 4 px from the square is occluded in some views.
    """
    fg, bg = sinusoid_texture(1), sinusoid_texture(2)

    def layer_at(x, y, du, dv):
        xf, yf = x + du * d_fg, y + dv * d_fg  # where this view pixel would hit the square, centre coords
        inside = (xf >= lo) & (xf < hi) & (yf >= lo) & (yf < hi)
        return np.where(inside, fg(xf, yf), bg(x + du * d_bg, y + dv * d_bg))

    gt = np.full((SIZE, SIZE), d_bg, np.float32)
    gt[lo:hi, lo:hi] = d_fg
    return render(layer_at), gt


def predict(light_field: np.ndarray, **params) -> np.ndarray:
    return create("planesweep", **params).predict(ArrayLightField(light_field)).disparity


# --------------------------------------------------------------------------- plane: accuracy and sub-pixel


@pytest.fixture(scope="module")
def plane_between_grid_values() -> np.ndarray:
    return plane(1.125)  # halfway between the grid values 1.0 and 1.25 (interval 0.25)


INNER = (slice(12, -12), slice(12, -12))  # 12 px from the border: beyond the largest shift (4 * 1.125 px)


@pytest.mark.parametrize("interpolation, tol_mean, tol_max", [("bilinear", 0.01, 0.03), ("phase", 0.01, 0.03),
                                                                ("nearest", 0.04, 0.06)])
def test_every_interpolation_recovers_a_plane_between_grid_values(plane_between_grid_values, interpolation,
                                                                   tol_mean, tol_max):
    # Grid alone would be 0.125 px off (half the interval). Bilinear and phase shifts are exact up to
    # interpolation error, leaving the sub-pixel fit's residual (measured about 0.001 px mean); nearest
    # rounds every view's shift to whole px (up to 0.5 px per view, averaging out over 33 views; measured
    # about 0.016 px). Tolerances leave about 5x margin on the bilinear/phase means.
    err = np.abs(predict(plane_between_grid_values, interpolation=interpolation) - 1.125)[INNER]
    assert err.mean() < tol_mean and err.max() < tol_max, (err.mean(), err.max())


def test_subpixel_refinement_beats_the_grid(plane_between_grid_values):
    coarse = predict(plane_between_grid_values, subpixel="none")[INNER]
    assert set(np.unique(coarse)) <= {1.0, 1.25}  # winner-takes-all lands on the grid ...
    assert np.abs(coarse - 1.125).min() == pytest.approx(0.125)  # ... half an interval away
    for fit in ("equiangular", "parabola"):
        err = np.abs(predict(plane_between_grid_values, subpixel=fit) - 1.125)[INNER]
        assert err.mean() < 0.125 / 10, (fit, err.mean())  # at least 10x better than the grid


@pytest.mark.parametrize("d", [-2.6, 0.0, 3.3])
def test_plane_at_negative_zero_and_large_disparity(d):
    b = int(np.ceil(4 * abs(d))) + 3  # views are read up to 4 |d| px away: border pixels see the replicated edge
    err = np.abs(predict(plane(d, seed=3)) - d)[b:-b, b:-b]
    assert np.median(err) < 0.01 and err.max() < 0.05, (np.median(err), err.max())


def test_all_views_and_the_star_agree_on_a_plane():
    views = plane(0.7, seed=4)
    a, b = predict(views, views="all")[INNER], predict(views, views="star")[INNER]
    assert np.abs(a - 0.7).mean() < 0.01 and np.abs(b - 0.7).mean() < 0.01


# --------------------------------------------------------------------------- occlusion


@pytest.fixture(scope="module")
def occlusion_case():
    from scipy import ndimage

    views, gt = two_layers()
    fg = gt > 0
    outside = ndimage.distance_transform_cdt(~fg, metric="chessboard")  # px from the square, outside it
    inside = ndimage.distance_transform_cdt(fg, metric="chessboard")
    scored = np.zeros_like(fg)
    scored[8:-8, 8:-8] = True
    # background hidden in some views: 3 .. 12 px (= 4 views x 3 px relative disparity) outside the square
    half_occluded = scored & (outside >= 3) & (outside <= 12)
    edge_distance = np.maximum(outside, inside)  # 1 = the pixels on either side of the boundary
    return views, gt, scored, half_occluded, edge_distance


def test_two_layers_with_occlusion(occlusion_case):
    views, gt, scored, half_occluded, edge_distance = occlusion_case
    err = np.abs(predict(views) - gt)
    # the wrong layer is picked only right at the boundary, where the matching windows straddle it:
    # 5x5 contrast normalisation + 3x3 subset choice reach 3 px
    gross = scored & (err > 0.5)
    assert gross.any() and edge_distance[gross].max() <= 3
    assert (err[scored & (edge_distance > 3)] > 0.5).sum() == 0
    # half-occluded background: right layer everywhere and accurate (measured 0.7 % above 0.05 px)
    assert err[half_occluded].max() < 0.1
    assert (err[half_occluded] > 0.05).mean() < 0.015
    # the occlusion-aware view subsets are what makes it accurate there (all views: 2.2 % above 0.05 px)
    err_all_views = np.abs(predict(views, occlusion="none") - gt)
    assert (err[half_occluded] > 0.05).sum() < (err_all_views[half_occluded] > 0.05).sum()


def test_uncertainty_is_larger_where_the_estimate_is_wrong(occlusion_case):
    views, gt, scored, _, _ = occlusion_case
    pred = create("planesweep").predict(ArrayLightField(views))
    wrong = scored & (np.abs(pred.disparity - gt) > 0.5)
    right = scored & (np.abs(pred.disparity - gt) < 0.05)
    assert np.median(pred.uncertainty[wrong]) > 5 * np.median(pred.uncertainty[right])


# --------------------------------------------------------------------------- building blocks


@pytest.mark.parametrize("mode", ["bilinear", "nearest"])
def test_shifter_matches_lfbench_shift_away_from_the_border(monkeypatch, mode):
    # bands of rows and chunks of disparities (tiny chunk budget) must give the same as one shot
    monkeypatch.setattr(ps, "_CHUNK_ELEMENTS", 9 * 16 * 40)
    rng = np.random.default_rng(0)
    views = torch.from_numpy(rng.uniform(0, 1, (9, 40, 40)).astype(np.float32))
    off = angular_offsets(3)
    disps = torch.tensor([-2.3, -1.0, 0.0, 0.4, 1.75])
    ref = shift_views(views[None, :, None], off, disps, mode)[0, :, :, 0]  # (D, N, H, W), zero fill
    shifter = ps._Shifter(views, off, disps, mode)
    ours = torch.cat([shifter.shift(disps, y0, 16) for y0 in (0, 16)] + [shifter.shift(disps, 32, 8)], dim=2)
    inner = (slice(None), slice(None), slice(4, -4), slice(4, -4))  # beyond the largest shift (2.3 px)
    assert ours.shape == ref.shape
    assert (ours - ref)[inner].abs().max() < 1e-5


def test_phase_shifter_is_an_exact_shift_of_a_smooth_image():
    # A Gaussian blob (sigma 2.5 px) is band-limited to float precision and zero at the border, so the
    # Fourier shift must reproduce the analytic translate blob(x - sx, y - sy) everywhere.
    y, x = torch.meshgrid(torch.arange(40.0), torch.arange(40.0), indexing="ij")

    def blob(sx: torch.Tensor, sy: torch.Tensor) -> torch.Tensor:
        return torch.exp(-((x - 19.5 - sx) ** 2 + (y - 20.2 - sy) ** 2) / (2 * 2.5**2))

    off = angular_offsets(3)
    disps = torch.tensor([-2.3, 0.4, 1.75])
    views = blob(torch.tensor(0.0), torch.tensor(0.0)).expand(9, 40, 40).contiguous()
    ours = ps._Shifter(views, off, disps, "phase").shift(disps, 0, 40)
    sx, sy = disps[:, None] * off[None, :, 0], disps[:, None] * off[None, :, 1]
    exact = blob(sx[..., None, None], sy[..., None, None])
    assert (ours - exact).abs().max() < 1e-4


def test_sweep_costs_do_not_depend_on_chunking(monkeypatch):
    views = torch.from_numpy(plane(0.5, seed=6).reshape(81, SIZE, SIZE)[:, :32, :32].copy())
    off = angular_offsets(9)
    weights = ps.subset_weights(off, "subsets")
    disps = torch.tensor([-1.0, 0.0, 0.5, 1.5])
    whole = ps.sweep_costs(views, off, disps, weights, views[40], "bilinear")
    monkeypatch.setattr(ps, "_CHUNK_ELEMENTS", 81 * 5 * 32)  # bands of 8 rows, one disparity at a time
    pieces = ps.sweep_costs(views, off, disps, weights, views[40], "bilinear")
    assert torch.allclose(whole, pieces, atol=1e-6)
    # cost of the "all views" subset at the true disparity is ~0 inside, large elsewhere
    inner = whole[:, 0, 8:-8, 8:-8].mean(dim=(-1, -2))
    assert inner[2] < 0.01 < inner[[0, 1, 3]].min()


def test_subset_weights():
    off = angular_offsets(9)
    w = ps.subset_weights(off, "subsets")
    assert w.shape == (7, 81) and torch.allclose(w.sum(1), torch.ones(7))
    assert [int((r > 0).sum()) for r in w] == [81, 45, 45, 45, 45, 9, 9]
    left = w[1] > 0
    assert bool((off[left, 0] <= 0).all())
    assert ps.subset_weights(off, "none").shape == (1, 81)
    row = angular_offsets(1, 9)  # a 1 x 9 camera row: column subset has 1 view, row = all: both dropped
    assert [int((r > 0).sum()) for r in ps.subset_weights(row, "subsets")] == [9, 5, 5]


def test_subpixel_minimum_on_analytic_costs():
    grid = torch.arange(-2.0, 2.01, 0.5)
    truth = torch.tensor([[-1.3, 0.1], [0.74, 1.6]])
    v_shape = (grid[:, None, None] - truth).abs()
    bowl = (grid[:, None, None] - truth) ** 2
    assert torch.allclose(ps.subpixel_minimum(v_shape, grid, 0.5, "equiangular"), truth, atol=1e-5)
    assert torch.allclose(ps.subpixel_minimum(bowl, grid, 0.5, "parabola"), truth, atol=1e-5)
    assert torch.equal(ps.subpixel_minimum(v_shape, grid, 0.5, "none"), torch.tensor([[-1.5, 0.0], [0.5, 1.5]]))
    edge = (grid[:, None, None] - torch.tensor([[-3.0]])).abs()  # minimum at the grid's end: kept as is
    assert ps.subpixel_minimum(edge, grid, 0.5, "equiangular").item() == -2.0


def test_cross_arms_and_aggregation():
    guide = torch.zeros(5, 7)
    guide[:, 4:] = 1.0  # an intensity edge between columns 3 and 4
    arms = ps.cross_arms(guide, 3, 0.1)
    assert arms[0, 2].tolist() == [0, 1, 2, 3, 0, 1, 2]  # left arms stop at the edge and the border
    assert arms[1, 2].tolist() == [3, 2, 1, 0, 2, 1, 0]  # right arms
    assert arms[2, :, 0].tolist() == [0, 1, 2, 3, 3] and arms[3, :, 0].tolist() == [3, 3, 2, 1, 0]
    cost = torch.zeros(2, 5, 7)
    cost[0, :, :4] = 1.0  # constant on each side of the edge: aggregation must not mix them
    cost[1] = torch.arange(35, dtype=torch.float32).reshape(5, 7)
    out = ps.cross_aggregate(cost, arms)
    assert torch.equal(out[0], cost[0])
    # pixel (2, 1): rows 0..4 (vertical arm 2 up, 2 down), each row's columns 0..3 (arms of that row)
    assert out[1, 2, 1].item() == pytest.approx(cost[1, :, 0:4].mean().item())
    flat = ps.cross_aggregate(cost, torch.zeros_like(arms))
    assert torch.equal(flat, cost)  # no arms: every pixel on its own


def test_prediction_outputs(plane_between_grid_values):
    pred = create("planesweep", interval=0.5).predict(ArrayLightField(plane_between_grid_values))
    assert pred.disparity.shape == (SIZE, SIZE) and pred.disparity.dtype == np.float32
    assert np.array_equal(pred.disparity_values, np.arange(-4.0, 4.01, 0.5, dtype=np.float32))
    assert pred.distribution.shape == (17, SIZE, SIZE)
    assert np.allclose(pred.distribution.sum(0), 1.0, atol=1e-5)
    assert np.isfinite(pred.uncertainty).all() and (pred.uncertainty >= 0).all()
    assert pred.distribution[:, 32, 32].argmax() in (10, 11)  # the grid values 1.0 and 1.5 around 1.125


def test_parameters_and_errors():
    m = create_from_spec("planesweep:interval=0.5,interpolation=nearest,d_min=-2,d_max=2")
    assert m.disparities.tolist() == [-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0]
    for bad in ("planesweep:interpolation=cubic", "planesweep:interval=0.3", "planesweep:views=some",
                "planesweep:subpixel=spline", "planesweep:arm_tau=0", "planesweep:d_min=4,d_max=-4",
                "planesweep:occlusion=maybe", "planesweep:arm_length=-1"):
        with pytest.raises(SpecError):
            create_from_spec(bad)
    bad = plane(0.0)
    bad[4, 4, 3, 3] = np.nan
    with pytest.raises(DataError, match="NaN"):
        create("planesweep").predict(ArrayLightField(bad))
    with pytest.raises(DataError, match="single view"):
        create("planesweep").predict(ArrayLightField(np.zeros((1, 1, 8, 8), np.float32)))


def test_small_and_non_square_inputs():
    views = plane(0.5, seed=7)[:, 2:7, :24, :40]  # 9 x 5 cameras, 24 x 40 px
    disp = create("planesweep").predict(ArrayLightField(np.ascontiguousarray(views))).disparity
    assert disp.shape == (24, 40) and np.abs(disp[8:-8, 8:-8] - 0.5).max() < 0.05


# --------------------------------------------------------------------------- real scenes


@pytest.mark.realdata
@pytest.mark.slow
@pytest.mark.parametrize("scene_name, max_badpix, max_mse", [("backgammon", 10.0, 10.0), ("antinous", 30.0, 25.0)])
def test_issue_targets_on_real_scenes(hci_root, scene_name, max_badpix, max_mse):
    """Issue 2's accuracy targets: low resolution, 15 px border (its time is measured by
    benchmarks/planesweep_real.py, not here: a timed unit test fails on a loaded machine)."""
    scenes = [s for s in HCIDataset.open(hci_root).scenes if s.name == scene_name]
    if not scenes:
        pytest.skip(f"{scene_name} not under {hci_root}")
    scene = scenes[0]
    scene.gray_views()  # PNG decoding is not the method's time
    with torch_threads(2):
        pred = create("planesweep").predict(scene)
    score = score_scene(scene, pred.disparity, rules=ScoringRules(allow_highres=False))
    assert all(r == "lowres" for r in score.resolution.values())
    assert score.values["badpix_0.07"] <= max_badpix, score.values
    assert score.values["mse_x100"] <= max_mse, score.values
