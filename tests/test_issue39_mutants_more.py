"""Tests for the survivors of issue 39's second mutation round (results/mutation/issue39/README.md, passes 8 on):
the view grid's orientation check (lfbench.data.orientation), all of the statistics (lfbench.scoring.stats) and the
dataset seam and its adapters (lfbench.data.dataset, generic, urbanlf). Every expected value comes from an
independent computation: a plain-NumPy warp written from the docstring's geometry (bilinear sampling loop by loop,
not torch's grid_sample), hand-built light fields, scipy.stats, exact enumerations, laws and lines worked out by
hand. Each test names the class of mutants it kills."""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import math
import types
import warnings
from fractions import Fraction

import numpy as np
import pytest
from scipy import stats as sps

from lfbench.data.orientation import (
    AS_READ,
    ORIENTATIONS,
    check_orientation,
    distinct_readings,
    has_centre_view,
    orientation_errors,
    warp_error,
)
from lfbench.results import Record, Results
from lfbench.scoring import stats
from lfbench.scoring.metrics import get_metric, list_metrics
from lfbench.utils.errors import DataError, SpecError

# --------------------------------------------------------------------------- orientation: an independent warp


def _bilinear(image: np.ndarray, x: float, y: float) -> float:
    """``image`` (H, W) at (x, y) px, bilinear, zero outside (x, y inside [0, W-1] x [0, H-1] here)."""
    h, w = image.shape
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    total = 0.0
    for yy, wy in ((y0, 1.0 - fy), (y0 + 1, fy)):
        for xx, wx in ((x0, 1.0 - fx), (x0 + 1, fx)):
            if 0 <= yy < h and 0 <= xx < w and wx * wy:
                total += wx * wy * float(image[yy, xx])
    return total


def _warp_error_by_hand(gray: np.ndarray, disparity: np.ndarray, border_px: int = 0) -> float:
    """warp_error's docstring, pixel by pixel: the mean |view_{v,u}(x - (u - uc) d, y - (v - vc) d) - centre(x, y)|
    over the views of the centre's row, column and diagonals, the centre pixels inside the border with a finite
    d, and the samples inside the view."""
    n_rows, n_cols, h, w = gray.shape
    vc, uc = n_rows // 2, n_cols // 2
    errors = []
    for v in range(n_rows):
        for u in range(n_cols):
            if (v, u) == (vc, uc) or not (v == vc or u == uc or abs(v - vc) == abs(u - uc)):
                continue
            for y in range(border_px, h - border_px):
                for x in range(border_px, w - border_px):
                    d = float(disparity[y, x])
                    if not math.isfinite(d):
                        continue
                    sx, sy = x - (u - uc) * d, y - (v - vc) * d
                    if 0 <= sx <= w - 1 and 0 <= sy <= h - 1:
                        errors.append(abs(_bilinear(gray[v, u], sx, sy) - float(gray[vc, uc, y, x])))
    return float(np.mean(errors)) if errors else math.nan


def _light_field(rows: int, cols: int, h: int, w: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Independent random views (every sample its own error, so each pixel counted or not moves the mean) and a
    disparity of whole and fractional steps (whole steps land exactly on a view's first and last pixel), one
    NaN pixel."""
    rng = np.random.default_rng(seed)
    gray = rng.random((rows, cols, h, w))
    disparity = rng.choice([-1.0, 1.0, 0.5, -0.75, 1.25, 0.0, 2.0], size=(h, w)) + 0.1 * (rng.random((h, w)) < 0.3)
    disparity[h // 2, 0] = np.nan
    return gray, disparity


@pytest.mark.parametrize("rows, cols, h, w, border", [
    (5, 5, 6, 7, 0),  # 16 star views: two chunks of 9; off-star views (0, 1) ... are left out
    (5, 5, 6, 7, 1),  # a border of one pixel on every side, bottom and right included
    (3, 5, 5, 4, 0),  # a non-square grid: the first index is the row (v), the second the column (u)
    (5, 3, 7, 6, 2),
    (3, 3, 2, 3, 0),  # a view two pixels high / wide: the normalisation of a 2-pixel axis
    (3, 3, 3, 2, 0),
    (1, 5, 3, 6, 0),  # one row of views
])
def test_warp_error_is_the_docstrings_mean_by_hand(rows, cols, h, w, border):
    """Kills the warp's class: which views are in the star (and/or, ==/!= of row, column and diagonal), the
    border's frame on each side, the bounds of a valid sample (>= 0, <= W-1, <= H-1 with a sample exactly on
    the first or last pixel), the normalisation of a 2-pixel axis, the running count over chunks of views."""
    gray, disparity = _light_field(rows, cols, h, w, seed=rows * 100 + cols * 10 + h + w + border)
    got = warp_error(gray.astype(np.float32), disparity.astype(np.float32), border_px=border)
    want = _warp_error_by_hand(gray.astype(np.float32), disparity.astype(np.float32), border)
    assert got == pytest.approx(want, rel=1e-5, abs=1e-7)


def test_warp_error_default_is_no_border_and_float64_input_reads_as_float32():
    """Kills the default border (0 -> 1) of warp_error, orientation_errors and check_orientation, and the
    dtype mutants that let float64 views or disparity (NumPy's default, an npy ground truth) reach torch as
    float64 (grid_sample refuses a float64 grid with float32 views)."""
    gray, disparity = _light_field(3, 3, 5, 6, seed=7)
    want = _warp_error_by_hand(gray, disparity)
    assert warp_error(gray, disparity) == pytest.approx(want, rel=1e-5)
    errors = orientation_errors(gray, disparity)
    check = check_orientation("street", gray, disparity)
    assert check.scene == "street"
    for o in distinct_readings(3, 3):
        by_hand = _warp_error_by_hand(np.ascontiguousarray(o.apply(gray)), disparity)
        assert errors[o] == pytest.approx(by_hand, rel=1e-5)
        assert check.errors[o] == pytest.approx(by_hand, rel=1e-5)


def test_warp_error_emits_no_warning():
    """Kills ``torch.meshgrid`` without ``indexing=``: torch warns on every call (a line on check-dataset's
    stderr per scene and reading)."""
    gray, disparity = _light_field(3, 3, 4, 4, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warp_error(gray, disparity)


def test_a_grid_needs_a_centre_view_both_ways():
    """Kills ``or`` for ``and`` in has_centre_view: an even count of rows or of columns has no centre view."""
    assert has_centre_view(3, 5) and has_centre_view(1, 1)
    assert not has_centre_view(3, 4) and not has_centre_view(4, 3) and not has_centre_view(2, 2)
    gray, disparity = _light_field(3, 4, 4, 4, seed=1)
    with pytest.raises(ValueError, match=r"must have a centre view \(odd size\), got 3x4"):
        warp_error(gray, disparity)
    with pytest.raises(ValueError, match=r"must have a centre view \(odd size\), got 4x3"):
        warp_error(gray.swapaxes(0, 1), disparity)


def test_a_disparity_of_another_size_is_refused_with_both_sizes():
    """Kills the emptied message of the disparity-shape refusal."""
    gray, disparity = _light_field(3, 3, 4, 5, seed=2)
    with pytest.raises(ValueError, match=r"^disparity is \(5, 4\), the views are 4x5$"):
        warp_error(gray, disparity.T)


def test_a_hand_built_plane_names_the_row_index_and_the_sign():
    """A hand-built light field (no renderer): a vertical-stripe texture shifted by u * d along x and a
    horizontal-stripe one by v * d along y, so rows and columns of the grid move different textures. Stored
    with the first index the row and HCI's sign it is read as is; the grid transposed or the sign negated is
    named as such (which index of u_v.png is the row, and the disparity sign)."""
    rng = np.random.default_rng(11)
    h = w = 24
    cols_tex, rows_tex = rng.random(w + 8), rng.random(h + 8)
    n = 5
    gray = np.empty((n, n, h, w))
    for v in range(n):
        for u in range(n):
            # view (v, u) at (x, y) shows the centre's (x + (u - 2) d, y + (v - 2) d) for d = 1
            xs = np.arange(w) + (u - 2) + 4
            ys = np.arange(h) + (v - 2) + 4
            gray[v, u] = 0.5 * cols_tex[xs][None, :] + 0.5 * rows_tex[ys][:, None] * cols_tex[xs][None, :]
    disparity = np.ones((h, w))
    assert warp_error(gray, disparity) < 1e-6
    check = check_orientation("plane", gray, disparity)
    assert check.best is AS_READ and check.agrees
    swapped = ORIENTATIONS[4]
    assert check_orientation("plane", gray.swapaxes(0, 1), disparity).best is swapped
    assert check_orientation("plane", gray, -disparity).best is ORIENTATIONS[1]


# --------------------------------------------------------------------------- stats.py: helpers


def _nan_equal(a, b) -> bool:
    return (math.isnan(a) and math.isnan(b)) if isinstance(a, float) and math.isnan(a) else a == b


def _assert_result(got: stats.PairedTest, *want) -> None:
    """Every field of a PairedTest, with its type (a NaN is a float NaN, n an int, the words a str)."""
    fields = dataclasses.astuple(got)
    for value, expected in zip(fields, want, strict=True):
        assert type(value) is type(expected), (value, expected)
        assert _nan_equal(value, expected), (value, expected)


@contextlib.contextmanager
def _quiet():
    """No floating-point warning may escape (they are lines on a user's stderr)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def _exact_signflip_p(d) -> float:
    """Two-sided sign-flip p by exact rational enumeration (the hand reference of issue 39's first round)."""
    x = [Fraction(float(v)) for v in d]
    observed = abs(sum(x))
    hits = sum(abs(sum(s * v for s, v in zip(signs, x, strict=True))) >= observed
               for signs in itertools.product((1, -1), repeat=len(x)))
    return hits / 2 ** len(x)


# --------------------------------------------------------------------------- stats.py: empty and degenerate input

NAN = float("nan")


def test_no_common_pixels_or_scenes_is_a_nan_result_of_every_field():
    """Kills the empty results' class: each NaN field replaced, dropped, None or the words changed, n != 0, the
    measure's id dropped, and ``d.size == 1`` for ``== 0`` (one pair is a result, not an empty one)."""
    gt = np.zeros((3, 4), np.float32)
    none = np.zeros((3, 4), bool)
    for measure, mid in (("abs", "abs"), ("badpix_0.03", "badpix_0.03"), ("sq", "mse_x100")):
        _assert_result(stats.paired_pixel_test(gt, gt + 1, gt, none, measure), NAN, NAN, NAN, NAN, 0, mid,
                       "no common scored pixels", None)
    _assert_result(stats.paired_scene_test([NAN, 1.0], [2.0, NAN], measure="m"), NAN, NAN, NAN, NAN, 0, "m",
                   "no paired scenes", None)
    one = np.zeros((3, 4), bool)
    one[1, 2] = True
    single = stats.paired_pixel_test(gt, gt + 0.5, gt + 0.25, one, "abs", n=20)
    assert (single.difference, single.n) == (0.25, 1)
    assert stats.paired_scene_test([3.0], [1.0], n=20).difference == 2.0


def test_scene_means_of_no_or_one_scene_have_nan_bounds():
    """Kills bootstrap_mean_over_scenes' and _percentile_ci's NaN class (fields None, dropped, ``nan`` misspelt)
    and ``reps.size == 1`` / ``and`` in the NaN test: a NaN estimate has NaN bounds whatever the replicates, one
    replicate is an interval of width 0."""
    for values in ([], [NAN, NAN]):
        got = stats.bootstrap_mean_over_scenes(values)
        assert all(type(v) is float and math.isnan(v) for v in got) and len(got) == 3
    one = stats.bootstrap_mean_over_scenes([NAN, 2.5])
    assert one.estimate == 2.5 and type(one.low) is float and math.isnan(one.low) and math.isnan(one.high)
    got = stats._percentile_ci(NAN, np.array([1.0, 2.0, 3.0]), 0.9)
    assert len(got) == 3 and all(type(v) is float and math.isnan(v) for v in got)
    assert tuple(stats._percentile_ci(0.5, np.array([0.5]), 0.9)) == (0.5, 0.5, 0.5)
    assert tuple(stats._percentile_ci(0.5, np.array([NAN, 0.5, NAN]), 0.9)) == (0.5, 0.5, 0.5)


def test_a_confidence_level_must_be_strictly_between_0_and_1():
    """Kills ``<=`` in either bound of the level check and its emptied message."""
    for level in (0.0, 1.0, 1.5, -0.1):
        with pytest.raises(SpecError, match=rf"^confidence level must be in \(0, 1\), got {level}$"):
            stats.bootstrap_mean_over_scenes([1.0, 2.0], level=level)


# --------------------------------------------------------------------------- stats.py: intervals of a known law


def test_percentile_interval_of_known_replicates_by_hand():
    """Kills the alpha (``/ 3``), the quantile method (linear between order statistics; nearest when a
    replicate is infinite, so inf - inf never makes a NaN bound; ``and False`` / ``or True`` / a misspelt or
    dropped method): replicates 0 and 1 at level 0.5 are [0.25, 0.75] by linear interpolation; with infinite
    replicates the nearest order statistics."""
    assert tuple(stats._percentile_ci(0.5, np.array([0.0, 1.0]), 0.5)) == (0.5, 0.25, 0.75)
    assert tuple(stats._percentile_ci(0.5, np.array([1.0, 0.0]), 0.8)) == pytest.approx((0.5, 0.1, 0.9))
    got = stats._percentile_ci(1.0, np.array([0.0, 1.0, np.inf, np.inf]), 0.5)
    assert tuple(got) == (1.0, 1.0, np.inf)
    # ints (a caller's counts) are read as float64
    assert tuple(stats._percentile_ci(1.0, np.array([0, 1]), 0.5)) == (1.0, 0.25, 0.75)


def test_scene_bootstrap_of_two_scenes_has_the_known_law():
    """Two scenes 0 and 1: a resampled mean is 0, 0.5 or 1 with chances 1/4, 1/2, 1/4, so at level 0.95 the
    interval is [0, 1] and at 0.4 it is [0.5, 0.5] (2000 resamples: the 0.3 and 0.7 quantiles are 0.5 with
    overwhelming probability). Kills the alpha, a dropped level, the seed default and a seed of None (the same
    seed must give the same interval)."""
    assert tuple(stats.bootstrap_mean_over_scenes([0.0, 1.0], n=2000)) == (0.5, 0.0, 1.0)
    assert tuple(stats.bootstrap_mean_over_scenes([0.0, 1.0], n=2000, level=0.4)) == (0.5, 0.5, 0.5)
    values = np.arange(7.0) ** 2
    first = stats.bootstrap_mean_over_scenes(values, n=50)
    assert first == stats.bootstrap_mean_over_scenes(values, n=50, seed=0)
    assert first == stats.bootstrap_mean_over_scenes(values, n=50, seed=0)
    assert first != stats.bootstrap_mean_over_scenes(values, n=50, seed=1)  # the seed matters
    assert stats.bootstrap_mean_over_scenes(values, n=50, seed=5) == stats.bootstrap_mean_over_scenes(values, n=50,
                                                                                                      seed=5)


def test_the_mean_over_scenes_is_taken_in_float64():
    """Kills the dropped ``dtype=np.float64`` of the scene values: float32 values (a float32 frame) are averaged
    in float64, as the average table does."""
    values = np.array([0.1, 0.2, 0.7, 1e-3, 3.3], np.float32)
    assert stats.bootstrap_mean_over_scenes(values, n=10).estimate == float(values.astype(np.float64).mean())
    assert float(values.mean()) != float(values.astype(np.float64).mean())  # the test can tell them apart


def test_tile_bootstrap_of_two_tiles_has_the_known_law():
    """Two tiles of two pixels, one all good and one all bad: a tile resample is 0, 50 or 100 % bad with chances
    1/4, 1/2, 1/4, so at level 0.4 the interval is [50, 50]. Kills ``n_groups + 2`` (two empty tiles drawn
    change the law) in bootstrap_replicates and in the paired tile test, the ratio ``*`` for ``/`` of the
    paired tile replicates."""
    errors = np.array([0.0, 0.0, 1.0, 1.0])
    groups = np.array([3, 3, 8, 8])
    got = stats.bootstrap_errors(errors, "badpix_0.07", n=2000, level=0.4, groups=groups)
    assert tuple(got) == (50.0, 50.0, 50.0)
    assert tuple(stats.bootstrap_errors(errors, "badpix_0.07", n=2000, groups=groups)) == (50.0, 0.0, 100.0)
    # the paired tile test: a's loss minus b's is 0 on the left 2x2 tile and 1 px on the right one
    gt = np.zeros((2, 4), np.float32)
    pred_a = np.array([[0, 0, 1, 1], [0, 0, 1, 1]], np.float32)
    paired = stats.paired_pixel_test(gt, pred_a, gt, None, "abs", n=2000, level=0.4, block=2)
    assert (paired.difference, paired.low, paired.high, paired.n) == (0.5, 0.5, 0.5, 8)
    assert paired.test == "tile sign-flip permutation test and tile bootstrap CI (2x2 px tiles, 2 tiles, 8 pixels)"
    assert paired.p_value == _exact_signflip_p([0.0, 4.0]) == 1.0  # tile sums 0 and 4: every flip ties
    wide = stats.paired_pixel_test(gt, pred_a, gt, None, "abs", n=2000, block=2)
    assert (wide.low, wide.high) == (0.0, 1.0)


# --------------------------------------------------------------------------- stats.py: bootstrap_replicates and co.


def test_replicates_of_nothing_or_of_no_draws():
    """Kills the empty-or-no-draws class of bootstrap_replicates: ``and`` for ``or``, ``n < 0``, ``n <= 1``,
    ``values.size == 1`` and the NaN array's shape and fill (None, dropped, max(n, 1))."""
    for n in (0, -3):
        out = stats.bootstrap_replicates(np.array([0.5, 1.0]), "mse_x100", n)
        assert out.shape == (0,)
    out = stats.bootstrap_replicates(np.array([]), "mse_x100", 5)
    assert out.shape == (5,) and out.dtype == np.float64 and np.isnan(out).all()
    one = stats.bootstrap_replicates(np.array([0.5]), "mse_x100", 1)
    assert one.shape == (1,) and one[0] == 25.0
    assert (stats.bootstrap_replicates(np.array([0.5]), "mse_x100", 4) == 25.0).all()


def test_groups_of_another_shape_are_refused_with_both_shapes():
    """Kills the emptied and the mis-built message of the groups' shape check."""
    with pytest.raises(ValueError, match=r"^groups \(3,\) and errors \(4,\) differ in shape$"):
        stats.bootstrap_replicates(np.zeros(4), "mse_x100", 5, groups=np.zeros(3, int))


def test_the_toolkit_rules_reach_the_replicates_and_default_to_lfbench():
    """A NaN error is left out of MSE by lfbench's rules and counted by the toolkit's (its MSE is NaN). Kills
    the default ``toolkit=True`` of bootstrap_replicates, bootstrap_errors, scored_errors, from_maps and
    bootstrap_metric, and toolkit dropped on its way to the replicates."""
    errors = np.array([0.1, np.nan, 0.2, 0.3])
    ours = stats.bootstrap_replicates(errors, "badpix_0.15", 300)
    assert np.array_equal(ours, stats.bootstrap_replicates(errors, "badpix_0.15", 300, toolkit=False))
    assert not np.array_equal(ours, stats.bootstrap_replicates(errors, "badpix_0.15", 300, toolkit=True))
    assert stats.metric_from_errors(errors, "badpix_0.15") == 75.0  # the NaN is bad: 0.2, 0.3, NaN of 4
    assert stats.metric_from_errors(errors, "badpix_0.15", toolkit=True) == 50.0
    ci = stats.bootstrap_errors(errors, "badpix_0.15", 300)
    assert ci == stats.bootstrap_errors(errors, "badpix_0.15", 300, toolkit=False) and ci.estimate == 75.0
    tk = stats.bootstrap_errors(errors, "badpix_0.15", 30, toolkit=True)
    reps = stats.bootstrap_replicates(errors, "badpix_0.15", 30, toolkit=True)
    assert tk.estimate == stats.metric_from_errors(errors, "badpix_0.15", toolkit=True)
    assert (tk.low, tk.high) == tuple(np.quantile(reps, [0.025, 0.975]))
    gt = np.array([[0.0, np.nan], [1.0, 2.0]], np.float32)
    pred = gt + 0.5
    assert stats.scored_errors(gt, pred).size == 3 and stats.scored_errors(gt, pred, toolkit=True).size == 4
    assert stats.ScoredErrors.from_maps(gt, pred).toolkit is False
    assert stats.ScoredErrors.from_maps(gt, pred).flat_index.dtype == np.int64  # int positions, not float
    tk_maps = stats.ScoredErrors.from_maps(gt, pred, toolkit=True)
    assert tk_maps.toolkit is True and tk_maps.errors.size == 4
    assert stats.bootstrap_metric(gt, pred, metric="badpix_0.07", n=20).estimate == 100.0
    assert stats.bootstrap_metric(gt, pred, metric="mse_x100", n=20) == stats.bootstrap_metric(
        gt, pred, None, "mse_x100", 20, 0, toolkit=False)


def test_bootstrap_errors_passes_its_seed_and_level_on():
    """Kills a dropped seed (bootstrap_errors and ci_records) and a dropped level: the interval is the
    replicates' of that seed at that level."""
    errors = np.linspace(-0.3, 0.3, 41)
    for seed, level in ((3, 0.5), (11, 0.9)):
        reps = stats.bootstrap_replicates(errors, "mse_x100", 40, seed)
        alpha = (1 - level) / 2
        got = stats.bootstrap_errors(errors, "mse_x100", 40, seed, level)
        assert (got.low, got.high) == tuple(np.quantile(reps, [alpha, 1 - alpha]))


def test_bootstrap_metric_defaults_and_callable_path():
    """Kills bootstrap_metric's defaults (metric 'badpix_0.07', seed 0), the callable path's scored pixels
    (``|`` for ``&`` with the finite ground truth, the mask ignored or not read as bool), the estimate taken
    without the mask, a seed of None, ``rng.integers(1, ...)`` (the first pixel never drawn), the empty case,
    and its refusal of a block, word for word."""
    gt = np.array([[0.0, 1.0, np.nan], [2.0, 3.0, 4.0]], np.float32)
    pred = np.array([[0.0, 1.5, 9.0], [2.0, 3.0, 4.05]], np.float32)
    mask = np.array([[1, 1, 1], [0, 1, 1]], np.uint8)  # a 0/1 mask (an image) is a bool mask
    default = stats.bootstrap_metric(gt, pred, mask.astype(bool), n=30)
    assert default == stats.bootstrap_metric(gt, pred, mask.astype(bool), "badpix_0.07", 30, 0)
    assert default.estimate == 25.0  # 4 scored pixels (NaN gt left out), one with |error| > 0.07
    calls = []

    def mean_abs(g, p, m):
        calls.append((g.shape, m is None))
        keep = np.ones(g.shape, bool) if m is None else np.asarray(m, bool)
        keep &= np.isfinite(g)
        return float(np.abs(p[keep] - g[keep]).mean()) if keep.any() else NAN

    got = stats.bootstrap_metric(gt, pred, mask, mean_abs, n=25, seed=4)
    assert calls[0] == ((2, 3), False) and all(c == ((4,), True) for c in calls[1:]) and len(calls) == 26
    assert got.estimate == pytest.approx((0 + 0.5 + 0 + 0.05) / 4)
    assert got == stats.bootstrap_metric(gt, pred, mask, mean_abs, n=25, seed=4)
    # two pixels of error 0 and 1: resampled means 0, 0.5, 1 with chances 1/4, 1/2, 1/4
    two = stats.bootstrap_metric(np.zeros(2), np.array([0.0, 1.0]), None, mean_abs, n=2000)
    assert tuple(two) == (0.5, 0.0, 1.0)
    calls.clear()
    empty = stats.bootstrap_metric(np.full(3, np.nan), np.zeros(3), None, mean_abs, n=5)
    assert math.isnan(empty.low) and math.isnan(empty.high)
    assert calls == [((3,), True)]  # the estimate only: no resample of no pixel
    with pytest.raises(SpecError, match="^block bootstrap needs a general metric id, not a callable$"):
        stats.bootstrap_metric(gt, pred, mask, mean_abs, block=4)


def test_a_metric_object_is_used_as_given_and_a_metric_without_bootstrap_is_named():
    """Kills _kind_of's ``isinstance(...) and False`` (a Metric object looked up again by its text) and its
    message (the metric's id and every id with a bootstrap, written out by hand here)."""
    custom = dataclasses.replace(get_metric("mse_x100"), id="my_mse")
    assert stats.metric_from_errors(np.array([0.5]), custom) == 25.0
    with_bootstrap = [m.id for m in list_metrics() if m.bootstrap is not None]
    assert "mse_x100" in with_bootstrap and "runtime" not in with_bootstrap
    with pytest.raises(SpecError) as info:
        stats.metric_from_errors(np.array([0.5]), "runtime")
    supported = ", ".join(with_bootstrap)
    assert str(info.value) == f"no bootstrap for metric 'runtime': supported are {supported}, badpix_<t>"


def test_scored_errors_emit_no_warning_and_keep_their_precision():
    """Kills ``np.errstate(invalid=None)`` around pred - gt (inf - inf under the toolkit's rules) and
    from_prepared's dtypes: float32 errors and int32 positions while they fit (``and False``, ``2 * 31``,
    ``astype(None)``), its toolkit flag stored as given."""
    gt = np.array([[np.inf, 1.0]], np.float32)
    with _quiet():
        err = stats.scored_errors(gt, gt.copy(), toolkit=True)
    assert np.isnan(err[0]) and err[1] == 0.0
    g = np.arange(100, dtype=np.float64).reshape(10, 10)
    # from_prepared reads a prepared prediction's gt, pred, mask and scale
    prepared = types.SimpleNamespace(gt=g, pred=g + 0.5, mask=np.ones((10, 10), bool), scale=1)
    se = stats.ScoredErrors.from_prepared(prepared)
    assert se.errors.dtype == np.float32 and se.flat_index.dtype == np.int32 and se.toolkit is False
    assert np.array_equal(se.flat_index, np.arange(100)) and (se.errors == 0.5).all()
    assert stats.ScoredErrors.from_prepared(prepared, toolkit=True).toolkit is True


# --------------------------------------------------------------------------- stats.py: losses


def test_pixel_loss_ids_aliases_units_and_values_by_hand():
    """Kills _loss's alias class (epe / mae / EPE in any case; mse, sq; badpix = badpix_0.07), the ids and units
    returned, inf (not NaN) for a non-finite error, the float64 loss, the MSE loss squared in float64 (the Mean
    family's loss precision: a float32 error squared in float32 loses its last bits)."""
    e = np.array([0.5, -0.25, np.nan, np.inf], np.float32)
    for name in ("abs", "epe", "EPE", "mae", "Mae"):
        loss, mid, unit = stats.pixel_loss(e, name)
        assert (mid, unit) == ("abs", "px") and loss.dtype == np.float64
        assert loss.tolist() == [0.5, 0.25, np.inf, np.inf]
    for name in ("sq", "mse", "MSE", "mse_x100"):
        loss, mid, unit = stats.pixel_loss(e, name)
        assert mid == "mse_x100" and loss.tolist() == [25.0, 6.25, np.inf, np.inf]
    for name in ("badpix", "BadPix", "badpix_0.07"):
        loss, mid, _ = stats.pixel_loss(e, name)
        assert mid == "badpix_0.07" and loss.tolist() == [100.0, 100.0, 100.0, 100.0]
    assert stats.pixel_loss(np.array([0.05]), "badpix")[0].tolist() == [0.0]
    x = np.float32(1 + 2.0 ** -12)
    assert stats.pixel_loss(np.array([x]), "mse_x100")[0][0] == 100.0 * float(x) ** 2
    assert float(x) ** 2 != float(x * x)  # float32 squaring would differ


def test_pixel_loss_refusals_word_for_word():
    """Kills the emptied messages of an unknown measure and of a metric that is not a mean of per-pixel losses,
    and ``and`` for ``or`` in that check (q25 has a family that is not a per-pixel mean; runtime has none)."""
    with pytest.raises(SpecError, match=r"^unknown measure 'foo': use abs, mse_x100 or badpix_<t>$"):
        stats.pixel_loss(np.zeros(2), "foo")
    for name in ("q25_x100", "runtime"):
        with pytest.raises(SpecError, match=rf"^measure '{name}' is not a mean of per-pixel losses: use abs, "
                                            r"mse_x100 or badpix_<t>$"):
            stats.pixel_loss(np.zeros(2), name)


def test_pixel_loss_emits_no_warning():
    """Kills the errstate class of _loss (invalid / over set to None or dropped): NaN, inf and an error whose
    square overflows give their loss silently."""
    e = np.array([np.nan, np.inf, -np.inf, 1e200, 0.5])
    with _quiet():
        for name in ("abs", "mse_x100", "badpix_0.07"):
            stats.pixel_loss(e, name)
        loss = stats.pixel_loss(np.array([1e200]), "mse_x100")[0]
    assert loss.tolist() == [np.inf]


# --------------------------------------------------------------------------- stats.py: paired tests


def test_paired_pixel_test_by_hand():
    """Kills paired_pixel_test's defaults (measure 'abs', seed 0), the mask and the finite-gt rule of either
    prediction (mask None, toolkit True), a seed of None, and the measure and test words of the result."""
    rng = np.random.default_rng(5)
    gt = rng.uniform(-1, 1, (6, 7)).astype(np.float32)
    gt[0, 0] = np.nan
    pred_a = gt + rng.normal(0, 0.05, gt.shape).astype(np.float32)
    pred_b = gt + rng.normal(0, 0.2, gt.shape).astype(np.float32)
    mask = np.ones(gt.shape, bool)
    mask[:, :2] = False
    pred_a[:, :2] = 50.0  # outside the mask: must not count
    pred_b[:, :2] = -50.0
    got = stats.paired_pixel_test(gt, pred_a, pred_b, mask, n=60)
    assert got == stats.paired_pixel_test(gt, pred_a, pred_b, mask, "abs", 60, 0)
    assert got == stats.paired_pixel_test(gt, pred_a, pred_b, mask, "abs", 60, 0)
    keep = mask & np.isfinite(gt)
    d = np.abs(pred_a - gt)[keep].astype(np.float64) - np.abs(pred_b - gt)[keep].astype(np.float64)
    assert got.n == 30 and got.difference == pytest.approx(d.mean(), rel=1e-12)
    assert got.measure == "abs"
    assert got.test == "sign-flip permutation test (60 flips) and paired bootstrap CI over 30 pixels (i.i.d.)"
    # BadPix under lfbench's rules: a NaN ground truth is not scored (the toolkit's rules would score it)
    bad = stats.paired_pixel_test(gt, pred_a, pred_b, mask | np.isnan(gt), "badpix_0.1", n=20)
    assert bad.n == 30 and bad.measure == "badpix_0.1"


def test_mcnemar_branch_by_hand():
    """Kills the McNemar branch's class: p = 1 with no discordant pixel (not 2), its replicates' scale
    (``101.0``, ``* d.size``), the test's words (counts, ``worse - better``): every discordant pixel bad only in
    a makes every replicate exactly 100 %; the p-value is scipy's exact binomial test."""
    gt = np.zeros((2, 5), np.float32)
    pred_a = np.full((2, 5), 0.5, np.float32)
    got = stats.paired_pixel_test(gt, pred_a, gt, None, "badpix_0.07", n=50)
    _assert_result(got, 100.0, 100.0, 100.0, float(sps.binomtest(10, 10, 0.5).pvalue), 10, "badpix_0.07",
                   "exact McNemar (two-sided binomial) on 10 discordant pixels (10 bad only in a, 0 bad only in b); "
                   "paired bootstrap CI over 10 pixels", None)
    same = stats.paired_pixel_test(gt, pred_a, pred_a, None, "badpix_0.07", n=50)
    _assert_result(same, 0.0, 0.0, 0.0, 1.0, 10, "badpix_0.07",
                   "exact McNemar (two-sided binomial) on 0 discordant pixels (0 bad only in a, 0 bad only in b); "
                   "paired bootstrap CI over 10 pixels", None)
    pred_b = pred_a.copy()
    pred_b[0, :3] = 0.0  # b good on 3 pixels: 3 discordant, all bad only in a
    pred_b[1, 0] = 0.5
    pred_a2 = pred_a.copy()
    pred_a2[1, 1:] = 0.0  # a good on 4 pixels where b is bad: 4 bad only in b
    mixed = stats.paired_pixel_test(gt, pred_a2, pred_b, None, "badpix_0.07", n=50)
    assert mixed.p_value == float(sps.binomtest(3, 7, 0.5).pvalue)
    assert mixed.test.startswith("exact McNemar (two-sided binomial) on 7 discordant pixels (3 bad only in a, "
                                 "4 bad only in b)")
    assert mixed.difference == pytest.approx(100.0 * (3 - 4) / 10)


def test_paired_scene_test_by_hand():
    """Kills paired_scene_test's class: the pairs kept (``|`` for ``&`` of the finite values), unsigned input
    read as float64 (uint8 a - b wraps), the exact p by rational enumeration, scipy's Wilcoxon, 1.0 when every
    difference is 0 (``np.all(None)``, ``d == 1``), the CI passed its seed and level, the seed default, the
    measure and the words (exact up to 16 scenes, random from 17), a seed of None for the Monte Carlo p."""
    a = [0.3, NAN, 0.9, 0.45, 0.2, 0.75]
    b = [0.1, 0.5, NAN, 0.4, 0.25, 0.5]
    d = np.array([0.3 - 0.1, 0.45 - 0.4, 0.2 - 0.25, 0.75 - 0.5])
    got = stats.paired_scene_test(a, b, n=40, level=0.5, measure="mse_x100")
    ci = stats.bootstrap_mean_over_scenes(d, 40, 0, 0.5)
    _assert_result(got, float(d.mean()), ci.low, ci.high, _exact_signflip_p(d), 4, "mse_x100",
                   "exact sign-flip permutation test over 4 scenes; bootstrap CI over scenes",
                   float(sps.wilcoxon(d).pvalue))
    assert got == stats.paired_scene_test(a, b, 40, 0, 0.5, "mse_x100")
    assert stats.paired_scene_test(a, b, n=40).measure == ""
    ci7 = stats.bootstrap_mean_over_scenes(d, 40, 7, 0.95)
    seeded = stats.paired_scene_test(a, b, n=40, seed=7)
    assert (seeded.low, seeded.high) == (ci7.low, ci7.high)
    u = stats.paired_scene_test(np.array([1, 5, 2], np.uint8), np.array([3, 1, 2], np.uint8), n=10)
    assert u.difference == pytest.approx((-2 + 4 + 0) / 3)
    with _quiet():  # scipy's Wilcoxon of all-zero differences divides by zero: not asked
        zeros = stats.paired_scene_test([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], n=10)
    assert (zeros.p_value, zeros.p_wilcoxon) == (1.0, 1.0)
    ones = stats.paired_scene_test([2.0] * 6, [1.0] * 6, n=10)
    assert ones.p_wilcoxon == float(sps.wilcoxon(np.ones(6)).pvalue) and ones.p_wilcoxon < 1.0
    d16 = np.linspace(-0.5, 1.0, 16)
    sixteen = stats.paired_scene_test(d16, np.zeros(16), n=10)
    assert sixteen.test == "exact sign-flip permutation test over 16 scenes; bootstrap CI over scenes"
    d17 = np.linspace(-0.5, 1.0, 17)
    many = stats.paired_scene_test(d17, np.zeros(17), n=300, seed=2)
    assert many.test == "300 random sign-flip permutation test over 17 scenes; bootstrap CI over scenes"
    assert many == stats.paired_scene_test(d17, np.zeros(17), n=300, seed=2)
    with pytest.raises(ValueError, match=r"^values_a \(3\) and values_b \(2\) must be paired \(same length\)$"):
        stats.paired_scene_test([1, 2, 3], [1, 2])


# --------------------------------------------------------------------------- stats.py: ErrorCollector, ci_records


def test_error_collector_keeps_the_errors_of_scenes_with_ground_truth(monkeypatch):
    """Kills ErrorCollector's class (rules and errors not kept, ``if scene.has_gt()`` inverted, the call's
    arguments dropped or None, the source words): scene_errors replaced by a recorder."""
    seen = []

    def recorder(scene, pred, rules=None, source="prediction", *, reference=None):
        seen.append((scene, pred, rules, source))
        return ("errors of", scene.name)

    monkeypatch.setattr(stats, "scene_errors", recorder)

    class Scene:
        def __init__(self, name, gt):
            self.name, self._gt = name, gt

        def has_gt(self):
            return self._gt

    class Method:
        label = "m1"

    class Pred:
        disparity = "the disparity"

    rules = object()
    collector = stats.ErrorCollector(rules)
    assert collector.rules is rules and collector.errors == {}
    collector(Method(), Scene("s0", False), Pred())
    assert collector.errors == {} and seen == []
    s1 = Scene("s1", True)
    collector(Method(), s1, Pred())
    assert collector.errors == {("m1", "s1"): ("errors of", "s1")}
    assert seen == [(s1, "the disparity", rules, "m1 on s1")]


def _ci_inputs():
    rng = np.random.default_rng(3)
    results = Results()
    errors = {}
    # method b first: the rows keep the results' order (not sorted)
    for method in ("b", "a"):
        for scene, resolution in (("s1", "lowres"), ("s2", "highres"), ("s3", "lowres"), ("s4", "lowres")):
            gt = rng.uniform(-1, 1, (8, 8)).astype(np.float32)
            pred = gt + rng.normal(0, 0.1, gt.shape).astype(np.float32)
            pred[:3, :4] = np.nan  # a bad pixel by lfbench's rules, a good one by the toolkit's
            errors[(method, scene)] = stats.ScoredErrors.from_maps(gt, pred)
            for metric in ("mse_x100", "badpix_0.07", "runtime"):
                results.records.append(Record(method, scene, metric, float(rng.random()), resolution))
    return results, errors


def test_ci_records_row_by_row():
    """Kills ci_records' class: the seed default, the metrics filter (``in`` / ``break``), the NaN bounds and
    0 pixels of a row without errors or bootstrap, toolkit / groups / seed / level passed on (block tiles from
    ScoredErrors), the mean rows (seed, level, resolutions joined by '/', the results' order, a fresh index),
    and the block refusal for plain errors, word for word."""
    results, errors = _ci_inputs()
    errors[("a", "s2")] = dataclasses.replace(errors[("a", "s2")], toolkit=True)
    toolkit_ci = stats.bootstrap_errors(errors[("a", "s2")].errors, "badpix_0.07", 40, 0, 0.8, toolkit=True,
                                        groups=errors[("a", "s2")].groups(3))
    assert toolkit_ci != stats.bootstrap_errors(errors[("a", "s2")].errors, "badpix_0.07", 40, 0, 0.8,
                                                groups=errors[("a", "s2")].groups(3))
    out = stats.ci_records(results, errors, n=40, level=0.8, block=3)
    assert list(out.columns) == list(stats.CI_COLUMNS) and list(out.index) == list(range(len(out)))
    scene_rows = out[out["scene"] != "(mean)"]
    assert list(zip(scene_rows["method"], scene_rows["scene"], scene_rows["metric"], strict=True)) == [
        (r.method, r.scene, r.metric) for r in results.records]
    for row in scene_rows.itertuples(index=False):
        rec = next(r for r in results.records if (r.method, r.scene, r.metric) == (row.method, row.scene, row.metric))
        assert row.value == rec.value and row.resolution == rec.resolution
        if row.metric == "runtime":
            assert math.isnan(row.low) and math.isnan(row.high) and row.n_pixels == 0
            continue
        item = errors[(row.method, row.scene)]
        ci = stats.bootstrap_errors(item.errors, row.metric, 40, 0, 0.8, toolkit=item.toolkit,
                                    groups=item.groups(3))
        assert (row.low, row.high, row.n_pixels) == (ci.low, ci.high, 64)
    means = out[out["scene"] == "(mean)"]
    assert list(zip(means["method"], means["metric"], strict=True)) == [(m, k) for m in ("b", "a")
                                                           for k in ("mse_x100", "badpix_0.07", "runtime")]
    for row in means.itertuples(index=False):
        values = [r.value for r in results.records if (r.method, r.metric) == (row.method, row.metric)]
        ci = stats.bootstrap_mean_over_scenes(values, 40, 0, 0.8)
        assert (row.value, row.low, row.high, row.resolution) == (ci.estimate, ci.low, ci.high, "highres/lowres")
        assert (row.low, row.high) != tuple(stats.bootstrap_mean_over_scenes(values, 40, 0, 0.95))[1:]
        assert row.n_pixels == (0 if row.metric == "runtime" else 256)
    assert out.equals(stats.ci_records(results, errors, None, 40, 0, 0.8, block=3))
    only = stats.ci_records(results, errors, metrics=["mse_x100"], n=10, average=False)
    assert list(only["metric"]) == ["mse_x100"] * 8
    missing = stats.ci_records(results, {}, n=10, average=False)
    assert missing["low"].dtype == np.float64 and missing["low"].isna().all() and (missing["n_pixels"] == 0).all()
    plain = {key: se.errors for key, se in errors.items()}
    no_block = stats.ci_records(results, plain, n=10, average=False)
    assert no_block["low"].notna().sum() == 16
    for row in no_block[no_block["metric"] == "badpix_0.07"].itertuples(index=False):  # plain errors: lfbench's rules
        ci = stats.bootstrap_errors(plain[(row.method, row.scene)], "badpix_0.07", 10)
        assert (row.low, row.high) == (ci.low, ci.high)
    with pytest.raises(SpecError, match=r"^block bootstrap needs ScoredErrors \(pixel positions\) for every run$"):
        stats.ci_records(results, plain, n=10, block=3)
    assert stats.ci_records(Results(), errors).empty


# --------------------------------------------------------------------------- stats.py: read_ci_csv


def _ci_csv(tmp_path, text):
    path = tmp_path / "ci.csv"
    path.write_text(text, encoding="utf-8")
    return path


def test_read_ci_csv_reads_text_and_numbers(tmp_path):
    """Kills read_ci_csv's reading class: numbers as float64 (an empty cell NaN, whitespace too), the names kept
    as text ('nan' and '1' are names), the columns checked only where present."""
    path = _ci_csv(tmp_path, "method,scene,metric,value,low,high,n_pixels\n"
                             "nan,1,mse_x100,0.5, ,2.5,10\n"
                             "b,(mean),badpix_0.07,1e-3,,3,0\n")
    ci = stats.read_ci_csv(path)
    assert list(ci["method"]) == ["nan", "b"] and list(ci["scene"]) == ["1", "(mean)"]
    assert ci["value"].dtype == np.float64 and ci["value"].tolist() == [0.5, 1e-3]
    assert math.isnan(ci["low"][0]) and math.isnan(ci["low"][1]) and ci["high"].tolist() == [2.5, 3.0]
    assert ci["n_pixels"].tolist() == ["10", "0"]
    no_value = stats.read_ci_csv(_ci_csv(tmp_path, "method,scene,metric,low,high\na,s,m,1,2\n"))
    assert "value" not in no_value.columns and no_value["low"].tolist() == [1.0]


def test_read_ci_csv_refusals_name_the_file_line_and_column(tmp_path):
    """Kills read_ci_csv's refusal class: each missing column listed in order, the line number (the header is
    line 1), the column named, the file named (DataError)."""
    path = _ci_csv(tmp_path, "method,metric,value,high\na,m,1,2\n")
    with pytest.raises(DataError) as info:
        stats.read_ci_csv(path)
    assert str(info.value) == f"{path}: missing column(s) scene, low"
    for column, line in (("value", 3), ("low", 2), ("high", 4)):
        rows = [["a", "s", "m", "1", "0", "2"] for _ in range(3)]
        rows[line - 2][("value", "low", "high").index(column) + 3] = "x1"
        text = "method,scene,metric,value,low,high\n" + "".join(",".join(r) + "\n" for r in rows)
        with pytest.raises(DataError) as info:
            stats.read_ci_csv(_ci_csv(tmp_path, text))
        assert str(info.value) == f"{tmp_path / 'ci.csv'}: line {line}: {column} is not a number"
    binary = tmp_path / "ci.csv"
    binary.write_bytes(b"method,scene\n\xff\xfe\n")
    with pytest.raises(DataError, match=r": ci\.csv is not UTF-8 text$"):
        stats.read_ci_csv(binary)


def test_scene_errors_name_the_prediction_and_follow_the_rules(tmp_path):
    """Kills scene_errors' class (no test ran it in pass 10): the source named in a refusal ('prediction' unless
    given), the rules' toolkit flag carried to the errors, the default rules."""
    from helpers import write_scene

    from lfbench.data.hci import HCIScene
    from lfbench.scoring.rules import ScoringRules

    gt = np.random.default_rng(2).uniform(-1, 1, (40, 40)).astype(np.float32)
    scene = HCIScene(write_scene(tmp_path, "dino", "training", size=40, views=False, gt=gt))
    pred = gt + 0.5
    pred[20, 20] = np.nan
    default = stats.scene_errors(scene, pred)
    assert default.toolkit is False and default.errors.size == 10 * 10  # the 15 px border of the default rules
    assert np.isnan(default.errors).sum() == 1 and default.shape == (40, 40)
    assert stats.scene_errors(scene, pred, ScoringRules(toolkit=True)).toolkit is True
    for source, named in ((None, "prediction"), ("mine", "mine")):
        with pytest.raises(DataError, match=rf"^{named}: prediction is 8x8, scene is 40x40"):
            if source is None:
                stats.scene_errors(scene, gt[:8, :8])
            else:
                stats.scene_errors(scene, gt[:8, :8], source=source)


def test_ci_records_progress_bar_goes_to_stderr_only_when_asked(monkeypatch):
    """Kills the progress display's class of ci_records (tqdm's words, unit, stream, when it shows and whether it
    stays): tqdm replaced by a recorder of its arguments."""
    import sys

    seen = []

    def recorder(iterable, **kwargs):
        seen.append(kwargs)
        return iterable

    monkeypatch.setattr(stats, "tqdm", recorder)
    results, errors = _ci_inputs()
    stats.ci_records(results, errors, n=5, average=False)
    stats.ci_records(results, errors, n=5, average=False, progress=True)
    common = {"desc": "bootstrap", "unit": "number", "file": sys.stderr, "leave": False}
    assert seen == [{**common, "disable": True}, {**common, "disable": None}]


# --------------------------------------------------------------------------- the dataset seam and its adapters


def _protocol(**changes):
    from lfbench.data.dataset import DatasetProtocol

    base = dict(border_px=4, metrics=("mse_x100",), disparity_range=(-1.0, 2.0))
    return DatasetProtocol(**{**base, **changes})


def test_a_protocol_refuses_what_no_dataset_can_mean_word_for_word():
    """Kills DatasetProtocol.__post_init__'s class: ``<=`` for ``<`` in the range (an empty range refused),
    the interval's bounds (0 and above max - min refused, max - min itself allowed, NaN refused), a negative
    border, a scorer not known; each message word for word."""
    with pytest.raises(ValueError, match=r"^disparity range must be \(min, max\) with min < max, got \(1\.0, 1\.0\)$"):
        _protocol(disparity_range=(1.0, 1.0))
    with pytest.raises(ValueError, match=r"^disparity range must be .* got \(2\.0, 1\.0\)$"):
        _protocol(disparity_range=(2.0, 1.0))
    assert _protocol(disparity_interval=3.0).disparity_interval == 3.0
    for step in (0.0, -0.1, 3.5, NAN):
        with pytest.raises(ValueError, match=rf"^disparity interval must be > 0 and at most max - min = 3 px, "
                                             rf"got {step}$"):
            _protocol(disparity_interval=step)
    assert _protocol(border_px=0).border_px == 0
    with pytest.raises(ValueError, match=r"^border must be >= 0 px, got -1$"):
        _protocol(border_px=-1)
    assert _protocol(scorer="paper-author").scorer == "paper-author"
    with pytest.raises(ValueError, match=r"^scorer must be 'lfbench' or 'paper-author', got 'toolkit'$"):
        _protocol(scorer="toolkit")


def test_a_protocol_describes_itself_line_by_line():
    """Kills describe()'s class: sizes W x H from (H, W) and views U x V from (V, U) (a non-square grid), 'any'
    where unset, the metrics and resolutions joined by ', ', the range and interval as %g, the high-resolution
    scenes sorted, and the scorer's line only for another scorer than lfbench's; every line written out by
    hand."""
    full = _protocol(border_px=15, metrics=("badpix_0.07", "mse_x100"), disparity_range=(-0.5, 1.6),
                     disparity_interval=0.1, resolutions=("lowres", "highres"), highres_scenes=frozenset({"b", "a"}),
                     spatial_size=(480, 640), angular_size=(9, 7), reference_view="centre view 5_5.png",
                     scorer="paper-author")
    assert full.describe() == [
        "views: 7x9, 640x480 px (W x H); scored: centre view 5_5.png, 15 px border",
        "metrics: badpix_0.07, mse_x100",
        "resolutions: lowres, highres",
        "disparity range: [-0.5, 1.6] px per view step, interval 0.1 px",
        "high-resolution scenes: a, b",
        "scorer: paper-author (BadPix |error| >= t, NaN good in BadPix and NaN in MSE; lfbench.scoring.policy)"]
    assert _protocol().describe() == [
        "views: any, any; scored: centre view, 4 px border",
        "metrics: mse_x100",
        "resolutions: lowres",
        "disparity range: [-1, 2] px per view step, each method's own interval"]


def test_which_adapters_read_their_protocol_from_the_data():
    """Kills ``is`` for ``is not`` in protocol_from_data: the TOML adapter reads it, UrbanLF-Syn and a plain
    adapter do not."""
    from lfbench.data.dataset import Dataset
    from lfbench.data.generic import GenericDataset
    from lfbench.data.urbanlf import UrbanLFSyn

    class Plain(Dataset):
        name = "plain"

    assert GenericDataset.protocol_from_data() is True
    assert UrbanLFSyn.protocol_from_data() is False and Plain.protocol_from_data() is False


def _toml_root(tmp_path, *, category: str | None = "cat"):
    """ROOT/lfbench-dataset.toml and one 3x3 scene of 8x6 px views ROOT/[cat/]street/v1.png .. v9.png, gt.npy."""
    from PIL import Image

    from lfbench.data.generic import SPEC_FILE

    root = tmp_path / "root"
    root.mkdir()
    (root / SPEC_FILE).write_text('[views]\npattern = "v{k}.png"\nangular = 3\nfirst = 1\n'
                                  '[ground_truth]\nfile = "gt.npy"\n[protocol]\nborder = 1\n', encoding="utf-8")
    scene = root / category / "street" if category else root / "street"
    scene.mkdir(parents=True)
    for k in range(1, 10):
        Image.new("RGB", (8, 6)).save(scene / f"v{k}.png")
    np.save(scene / "gt.npy", np.zeros((6, 8), np.float32))
    return root


def test_the_toml_adapter_opens_scenes_with_their_category_and_root(tmp_path):
    """Kills GenericDataset.open's class: the scene's category (its folder's parent under the root), the
    benchmark's root and its empty splits, and the refusal of a root without scenes (words, the root named)."""
    from lfbench.data.generic import GenericDataset

    root = _toml_root(tmp_path)
    assert GenericDataset.matches(root) and not GenericDataset.matches(tmp_path)
    bench = GenericDataset.open(root)
    assert bench.root == root and dict(bench.splits) == {}
    assert [(s.name, s.category) for s in bench.scenes] == [("street", "cat")]
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "lfbench-dataset.toml").write_text((root / "lfbench-dataset.toml").read_text(encoding="utf-8"),
                                                encoding="utf-8")
    with pytest.raises(DataError) as info:
        GenericDataset.open(empty)
    assert str(info.value) == f"{empty}: no scene folders holding v5.png (the centre view lfbench-dataset.toml names)"


def test_read_dataset_spec_maps_every_key_to_the_layout_and_protocol(tmp_path):
    """Kills read_dataset_spec's class: each key of lfbench-dataset.toml carried to its field of the ViewLayout or
    the DatasetProtocol (rows / columns of the grid, first, the ground truth's file / format / scale / offset,
    the three orientation keys, border, metrics, range, interval, scorer, the source file, the reference view
    named by the centre's file), every value set away from its default."""
    from lfbench.data.generic import read_dataset_spec

    path = tmp_path / "lfbench-dataset.toml"
    path.write_text('[views]\npattern = "view_{v}_{u}.png"\nangular = [3, 5]\nfirst = 1\nreverse_rows = true\n'
                    'reverse_columns = true\n'
                    '[ground_truth]\nfile = "gt.pfm"\nformat = "pfm"\nscale = -2.0\noffset = 0.5\n'
                    '[protocol]\nborder = 2\nmetrics = ["badpix_0.03", "mse_x100"]\ndisparity_range = [-2.0, 3.0]\n'
                    'disparity_interval = 0.5\nscorer = "paper-author"\n', encoding="utf-8")
    layout, protocol = read_dataset_spec(path)
    assert (layout.pattern, layout.angular, layout.first) == ("view_{v}_{u}.png", (3, 5), 1)
    assert (layout.gt_file, layout.gt_format, layout.gt_scale, layout.gt_offset) == ("gt.pfm", "pfm", -2.0, 0.5)
    assert (layout.transpose, layout.reverse_rows, layout.reverse_cols) == (False, True, True)
    assert (protocol.border_px, protocol.metrics, protocol.disparity_range) == (2, ("badpix_0.03", "mse_x100"),
                                                                               (-2.0, 3.0))
    assert (protocol.disparity_interval, protocol.scorer, protocol.angular_size) == (0.5, "paper-author", (3, 5))
    assert protocol.source == path
    # the centre (row 1, column 2, 0-based) read with both axes reversed and counted from 1: view_2_3.png
    assert protocol.reference_view == "centre view view_2_3.png"
    square = tmp_path / "square.toml"
    square.write_text('[views]\npattern = "v_{v}_{u}.png"\nangular = 3\ntranspose = true\n', encoding="utf-8")
    layout, protocol = read_dataset_spec(square)
    assert (layout.angular, layout.first, layout.transpose, layout.reverse_rows, layout.reverse_cols) == (
        (3, 3), 0, True, False, False)
    assert (layout.gt_file, layout.gt_scale, layout.gt_offset) == (None, 1.0, 0.0)
    assert (protocol.border_px, protocol.disparity_range, protocol.disparity_interval, protocol.scorer) == (
        15, (-4.0, 4.0), None, "lfbench")
    assert protocol.reference_view == "centre view v_1_1.png"


@pytest.mark.parametrize("text, said", [
    ('[veiws]\npattern = "v{k}.png"\n', "unknown key(s): veiws (accepted: ground_truth, protocol, views)"),
    ('[views]\npattern = "v{k}.png"\nangular = 0\n', "views.angular: must be in [1, 33], got 0"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\ncolour = 1\n',
     "[views] unknown key(s): colour (accepted: angular, first, pattern, reverse_columns, reverse_rows, transpose)"),
    ("[views\n", "invalid TOML: Expected ']' at the end of a table declaration (at line 1, column 7)"),
    (b"\xff\xfe", "dataset description is not UTF-8 text"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\nborder = -1\n',
     "protocol.border: must be in [0, 1024], got -1"),
    ('[views]\nangular = 3\n', "views.pattern: is required"),
], ids=["section", "value", "key", "syntax", "utf8", "protocol", "required"])
def test_a_bad_dataset_file_is_one_line_naming_the_file_once(tmp_path, text, said):
    """Kills read_dataset_spec's refusal class: the file named once, in front (the prefix the key's error carries
    removed, not a suffix), the key's path from the top table (no name of its own), the file's label in a read
    error, a misspelt section named before a missing one; each line word for word."""
    from lfbench.data.generic import read_dataset_spec

    path = tmp_path / "lfbench-dataset.toml"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    with pytest.raises(DataError) as info:
        read_dataset_spec(path)
    assert str(info.value) == f"{path}: {said}"


def test_urbanlf_names_and_layout():
    """Kills urbanlf's names: ``u_v.png`` is angular row u, column v counted from 1 (the centre 5_5.png), the
    disparity and depth files of a view, the centre's by default."""
    from lfbench.data import urbanlf

    assert urbanlf.view_name(2, 7) == "2_7.png"
    assert urbanlf.gt_name() == "5_5_disparity.npy" and urbanlf.gt_name(1, 9) == "1_9_disparity.npy"
    assert urbanlf.depth_name() == "5_5_depth.npy" and urbanlf.depth_name(3, 4) == "3_4_depth.npy"
    layout = urbanlf.URBANLF_LAYOUT
    assert layout.view_name(1, 6) == "2_7.png" and layout.view_name(*layout.centre) == "5_5.png"


def test_urbanlf_opens_samples_of_each_split_and_refuses_a_root_without(tmp_path):
    """Kills UrbanLFSyn's and UrbanLFScene's class: a sample is a folder holding 5_5.png (a broken link there
    counts), its category the split, its reopen arguments, detection at any depth, the refusal's words."""
    import io

    from PIL import Image

    from lfbench.data.urbanlf import UrbanLFScene, UrbanLFSyn

    png = io.BytesIO()
    Image.new("RGB", (4, 3)).save(png, format="PNG")
    root = tmp_path / "urban"
    for split, image in (("train", "Image1"), ("val", "Image7")):
        folder = root / split / image
        folder.mkdir(parents=True)
        for r in range(1, 10):
            for c in range(1, 10):
                (folder / f"{r}_{c}.png").write_bytes(png.getvalue())
    linked = tmp_path / "linked" / "test" / "Image9"
    linked.mkdir(parents=True)
    (linked / "5_5.png").symlink_to(tmp_path / "nowhere.png")  # a broken link: a sample (refused when opened)
    assert UrbanLFSyn.matches(tmp_path / "linked") and UrbanLFSyn.matches(linked)
    assert UrbanLFSyn.matches(root) and UrbanLFSyn.matches(root / "train")
    assert UrbanLFSyn.matches(root / "val" / "Image7")
    bench = UrbanLFSyn.open(root)
    assert bench.root == root and dict(bench.splits) == {}
    got = sorted((s.name, s.category) for s in bench.scenes)
    assert got == [("Image1", "train"), ("Image7", "val")]
    scene = next(s for s in bench.scenes if s.name == "Image1")
    assert isinstance(scene, UrbanLFScene) and scene.reopen_args() == (root / "train" / "Image1", "train")
    assert UrbanLFScene(root / "train" / "Image1").category == "other"
    empty = tmp_path / "empty"
    empty.mkdir()
    assert not UrbanLFSyn.matches(empty)
    with pytest.raises(DataError) as info:
        UrbanLFSyn.open(empty)
    assert str(info.value) == f"{empty}: no UrbanLF-Syn samples found (expected <root>/<split>/ImageN/5_5.png)"


def _method_info(d_min=-4.0, d_max=4.0, interval=None, weights=None):
    """What method_range_params reads of a registered method: its parameters' defaults, its class (with an
    optional range_from_weights) and its name."""
    params = {"d_min": types.SimpleNamespace(default=d_min), "d_max": types.SimpleNamespace(default=d_max)}
    if interval is not None:
        params["interval"] = types.SimpleNamespace(default=interval)
    cls = types.SimpleNamespace() if weights is None else types.SimpleNamespace(range_from_weights=weights)
    return types.SimpleNamespace(params=params, method_class=cls, name="sweep")


def test_method_range_params_by_hand(caplog):
    """Kills method_range_params' class, each expected grid worked out by hand from its docstring: no range for a
    method without d_min / d_max or a spec that sets either; the range where it differs from the method's
    defaults; with an interval the top raised to the first grid point at or above the maximum (ceil of the
    steps, rounded to 9 digits first: 80.00000000000001 steps are 80); the dataset's interval where the spec
    sets none and it differs; a spec's interval kept; a zero step leaves the maximum; weights that fix the grid
    get nothing (logged)."""
    from lfbench.data.dataset import method_range_params

    urban = method_range_params((-0.5, 1.6))
    no_range = types.SimpleNamespace(params={"interval": types.SimpleNamespace(default=0.1)}, method_class=None,
                                     name="x")
    assert urban(no_range, {}) == {}
    assert urban(_method_info(), {"d_min": -1.0}) == {} and urban(_method_info(), {"d_max": 1.0}) == {}
    assert method_range_params((-4, 4))(_method_info(), {}) == {}
    assert urban(_method_info(), {}) == {"d_min": -0.5, "d_max": 1.6}
    assert urban(_method_info(interval=0.25), {}) == {"d_min": -0.5, "d_max": 1.75}  # 8.4 steps: 9
    assert urban(_method_info(interval=0.25), {"interval": 0.5}) == {"d_min": -0.5, "d_max": 2.0}  # 4.2: 5
    assert urban(_method_info(interval=0.25), {"interval": 0.0}) == {"d_min": -0.5, "d_max": 1.6}
    assert urban(_method_info(interval=0.7), {}) == {"d_min": -0.5, "d_max": 1.6}  # 3 steps exactly
    grid = method_range_params((-0.5, 1.6), 0.1)
    assert grid(_method_info(interval=0.25), {}) == {"d_min": -0.5, "d_max": 1.6, "interval": 0.1}
    assert grid(_method_info(interval=0.25), {"interval": 0.25}) == {"d_min": -0.5, "d_max": 1.75}
    assert method_range_params((-0.5, 1.6), 0.25)(_method_info(interval=0.25), {}) == {"d_min": -0.5,
                                                                                        "d_max": 1.75}
    assert method_range_params((-4, 4), 0.1)(_method_info(interval=0.25), {}) == {"interval": 0.1}  # 80 steps
    assert method_range_params((-0.5, 1.75))(_method_info(-0.5, 1.75, interval=0.25), {}) == {}
    # the steps rounded to 9 digits before the ceiling (4.0000000004 steps are 4), the top to 9 digits
    assert method_range_params((0.0, 1.0000000001))(_method_info(interval=0.25), {}) == {"d_min": 0.0, "d_max": 1.0}
    assert method_range_params((2e-10, 1.0))(_method_info(interval=0.25), {}) == {"d_min": 2e-10, "d_max": 1.0}
    assert urban(_method_info(weights=lambda info, params: False), {}) == {"d_min": -0.5, "d_max": 1.6}
    asked = []
    fixed = _method_info(weights=lambda info, params: asked.append((info.name, params)) or True)
    with caplog.at_level("INFO", logger="lfbench.data.dataset"):
        assert urban(fixed, {"weights": "w.pt"}) == {}
    assert asked == [("sweep", {"weights": "w.pt"})]
    assert caplog.messages == ["sweep: searches the disparity grid its weights were trained on (the dataset's "
                               "[-0.5, 1.6] px is not laid over weights)"]


# --------------------------------------------------------------------------- detection and the plugin guards


class _Registry:
    """The few calls detection makes of DATASETS, over adapters given here (no entry point, no CLI)."""

    def __init__(self, *adapters):
        self.adapters = {a.name: a for a in adapters}

    def names(self):
        return list(self.adapters)

    def get(self, name):
        if name not in self.adapters:
            raise SpecError(f"unknown dataset {name!r}")
        return self.adapters[name]


def _adapter(name, *, matches=True, opened=None, protocol=None, module="plugin_mod"):
    """A dataset adapter class named ``name`` defined in ``module`` (a plugin's unless it is lfbench's): matches()
    returns ``matches`` (or raises it), open() returns ``opened`` (or raises it), protocol_for() ``protocol``."""
    from lfbench.data.dataset import Dataset

    def act(value):
        if isinstance(value, BaseException):
            raise value
        return value

    cls = type(name.title().replace("-", ""), (Dataset,), {
        "name": name, "layout": f"{name} layout", "__module__": module,
        "matches": classmethod(lambda c, root: act(matches)),
        "open": classmethod(lambda c, root: act(opened)),
        "protocol": protocol if protocol is not None else _protocol(),
    })
    if protocol is not None:
        cls.protocol_for = classmethod(lambda c, root: act(protocol))
    return cls


@pytest.fixture
def datasets(monkeypatch):
    from lfbench.data import dataset as seam

    def install(*adapters):
        monkeypatch.setattr(seam, "DATASETS", _Registry(*adapters))
        return seam

    return install


def test_a_plugin_is_named_with_its_module_and_class():
    """Kills _plugin's class: lfbench's own adapters (module lfbench or lfbench.*) are not guarded, any other is
    named ``'name' (module.Class)``."""
    from lfbench.data.dataset import _plugin

    assert _plugin(_adapter("own", module="lfbench.data.fake")) is None
    assert _plugin(_adapter("top", module="lfbench")) is None
    assert _plugin(_adapter("near", module="lfbenchx.data")) == "'near' (lfbenchx.data.Near)"
    assert _plugin(_adapter("my-set")) == "'my-set' (plugin_mod.MySet)"


def test_detection_by_hand(datasets, tmp_path, caplog):
    """Kills detect_dataset's and _matches' class: a missing root, no layout (the names listed, 'none installed',
    the first failing plugin's line), several layouts, one layout with a failing plugin left out (logged), a
    plugin's matches() counted only when it returns True, an LFBenchError's and another exception's line."""
    from lfbench.utils.errors import LFBenchError

    missing = tmp_path / "missing"
    seam = datasets(_adapter("a", matches=False), _adapter("b", matches=False))
    with pytest.raises(DataError) as info:
        seam.detect_dataset(missing)
    assert str(info.value) == f"{missing}: data root not found"
    with pytest.raises(DataError) as info:
        seam.detect_dataset(tmp_path)
    assert str(info.value) == (f"{tmp_path}: no scenes found: no known dataset layout (a, b; see `lfbench datasets`)")
    seam = datasets()
    with pytest.raises(DataError, match=r"no known dataset layout \(none installed; see `lfbench datasets`\)$"):
        seam.detect_dataset(tmp_path)
    seam = datasets(_adapter("a", matches=False), _adapter("bad", matches=RuntimeError("boom\nsecond line")),
                    _adapter("worse", matches=LFBenchError("not readable")))
    with pytest.raises(DataError) as info:
        seam.detect_dataset(tmp_path)
    assert str(info.value).endswith("(a, bad, worse; see `lfbench datasets`); adapter 'bad' (plugin_mod.Bad): "
                                    "matches() failed: RuntimeError: boom")
    good = _adapter("good")
    seam = datasets(_adapter("bad", matches=RuntimeError("boom")), good, _adapter("truthy", matches=1),
                    _adapter("worse", matches=LFBenchError("not readable")))
    with caplog.at_level("WARNING", logger="lfbench.data.dataset"):
        assert seam.detect_dataset(tmp_path) is good
    assert caplog.messages == [
        "dataset adapter 'bad' (plugin_mod.Bad): matches() failed: RuntimeError: boom; left out of the detection",
        "dataset adapter 'worse' (plugin_mod.Worse): not readable; left out of the detection"]
    seam = datasets(_adapter("a"), _adapter("b"), _adapter("c", matches=False))
    with pytest.raises(DataError) as info:
        seam.detect_dataset(tmp_path)
    assert str(info.value) == (f"{tmp_path}: the layout matches several datasets (a, b): choose one with "
                               "--dataset NAME")
    own = _adapter("own", matches=RuntimeError("a bug of lfbench's"), module="lfbench.data.fake")
    with pytest.raises(RuntimeError, match="a bug of lfbench's"):  # lfbench's own adapter keeps its traceback
        datasets(own).detect_dataset(tmp_path)
    assert datasets(_adapter("a", matches=False), good)._detected(tmp_path) is good
    assert datasets(_adapter("a", matches=False))._detected(tmp_path) is None


def test_a_named_dataset_by_hand(datasets, tmp_path):
    """Kills dataset_of's class: detection without a name; an unknown name (the registry's line, no path); a
    missing root; a root not laid out as the named dataset (its layout said); a named plugin whose matches()
    fails (its line)."""
    a, b = _adapter("a"), _adapter("b", matches=False)
    seam = datasets(a, b, _adapter("bad", matches=ValueError("no")))
    assert seam.dataset_of(tmp_path) is a and seam.dataset_of(tmp_path, "a") is a
    with pytest.raises(DataError) as info:
        seam.dataset_of(tmp_path, "zzz")
    assert str(info.value) == "unknown dataset 'zzz'"
    with pytest.raises(DataError) as info:
        seam.dataset_of(tmp_path / "missing", "a")
    assert str(info.value) == f"{tmp_path / 'missing'}: data root not found"
    with pytest.raises(DataError) as info:
        seam.dataset_of(tmp_path, "b")
    assert str(info.value) == f"{tmp_path}: not laid out as dataset 'b' (b layout)"
    with pytest.raises(DataError) as info:
        seam.dataset_of(tmp_path, "bad")
    assert str(info.value) == f"{tmp_path}: dataset adapter 'bad' (plugin_mod.Bad): matches() failed: ValueError: no"


def test_a_plugins_open_and_protocol_are_guarded(datasets, tmp_path):
    """Kills _call_adapter's, _open's, _protocol's and open_dataset's class: what a plugin returns is checked
    against the type expected (its type named), what it raises is one line naming it, the method and the root
    (an LFBenchError passes as it is), lfbench's own adapter is called unguarded."""
    from lfbench.data.scene import Benchmark
    from lfbench.utils.errors import LFBenchError

    bench = Benchmark(root=tmp_path, scenes=())
    plugin = _adapter("p", opened=bench)
    assert datasets(plugin).open_dataset(tmp_path) == (plugin, bench)
    assert datasets(plugin).open_dataset(tmp_path, "p") == (plugin, bench)
    for opened, said in ((ValueError("bad file\nmore"), "open() failed: ValueError: bad file"),
                         ("a text", "open() returned a str, expected a Benchmark")):
        with pytest.raises(DataError) as info:
            datasets(_adapter("p", opened=opened)).open_dataset(tmp_path)
        assert str(info.value) == f"{tmp_path}: dataset adapter 'p' (plugin_mod.P): {said}"
    with pytest.raises(LFBenchError, match="^its own line$"):
        datasets(_adapter("p", opened=LFBenchError("its own line"))).open_dataset(tmp_path)
    with pytest.raises(KeyError):
        datasets(_adapter("own", opened=KeyError("x"), module="lfbench.data.fake")).open_dataset(tmp_path)
    seam = datasets(_adapter("p", opened=bench, protocol={"border": 1}))
    with pytest.raises(DataError) as info:
        seam.open_datasets([tmp_path])
    assert str(info.value) == (f"{tmp_path}: dataset adapter 'p' (plugin_mod.P): protocol_for() returned a dict, "
                               "expected a DatasetProtocol")
    with pytest.raises(NotImplementedError, match="^dataset 'p' has no writer of generated scenes$"):
        plugin.write_scene(tmp_path, None)


def test_several_roots_by_hand(datasets, tmp_path):
    """Kills open_datasets' class: no root, a root given twice (resolved), a root of another dataset (both
    named), another protocol, the check called with the protocol before any scene is opened, the scenes of
    every root in order in the first root's benchmark with the others listed."""
    from lfbench.data.scene import Benchmark

    one, two, three = (tmp_path / n for n in ("one", "two", "three"))
    for root in (one, two, three):
        root.mkdir()
    events = []

    class Adapter(_adapter("a")):
        @classmethod
        def matches(cls, root):
            return root.name != "three"

        @classmethod
        def open(cls, root):
            events.append(("open", root.name))
            return Benchmark(root=root, scenes=(f"{root.name}-1", f"{root.name}-2"), splits={"x": ("y",)})

    seam = datasets(Adapter, _adapter("other", matches=False))
    with pytest.raises(DataError, match="^no data root given$"):
        seam.open_datasets([])
    with pytest.raises(DataError) as info:
        seam.open_datasets([one, tmp_path / "two" / ".." / "one"])
    assert str(info.value) == f"{tmp_path / 'two' / '..' / 'one'}: data root given twice (also as {one})"
    dataset, protocol, bench = seam.open_datasets([one, two], check=lambda p: events.append(("check", p)))
    assert dataset is Adapter and protocol == Adapter.protocol
    assert events == [("check", Adapter.protocol), ("open", "one"), ("open", "two")]
    assert bench.root == one and bench.scenes == ("one-1", "one-2", "two-1", "two-2") and bench.others == (two,)
    assert dict(bench.splits) == {"x": ("y",)}

    class Third(_adapter("third")):
        @classmethod
        def matches(cls, root):
            return root.name == "three"

    seam = datasets(Adapter, Third)
    with pytest.raises(DataError) as info:
        seam.open_datasets([one, three])
    assert str(info.value) == (f"{three}: is dataset 'third', {one} is 'a': one results file holds one dataset's "
                               "numbers (their protocols differ); evaluate each into its own --out")
    with pytest.raises(DataError) as info:
        seam.open_datasets([one, three], "a")
    assert str(info.value) == f"{three}: not laid out as dataset 'a' (a layout)"

    class Declared(Adapter):
        @classmethod
        def protocol_for(cls, root):
            return _protocol(border_px=7 if root.name == "two" else 4)

    seam = datasets(Declared)
    with pytest.raises(DataError) as info:
        seam.open_datasets([one, two])
    assert str(info.value) == (f"{two}: scored by another protocol than {one} (one results file holds one "
                               "dataset's numbers): evaluate it on its own")
    assert seam.open_datasets([one])[1] == _protocol()


def test_a_name_decides_where_detection_cannot_and_every_adapter_gets_the_root(datasets, tmp_path):
    """Kills the name dropped on its way to dataset_of (open_dataset, open_datasets' first root, ``name and``
    for ``name or`` on the later roots) and the root dropped on its way to lfbench's own adapters: a root that
    two layouts match is opened by the one named, or, after a first root detected as one dataset, as that one."""
    from lfbench.data.scene import Benchmark

    one, two = tmp_path / "one", tmp_path / "two"
    one.mkdir()
    two.mkdir()
    seen = []

    class Own(_adapter("own")):
        __module__ = "lfbench.data.fake"  # lfbench's own adapter: called unguarded

        @classmethod
        def matches(cls, root):
            seen.append(root)
            return root in (one, two)

        @classmethod
        def open(cls, root):
            return Benchmark(root=root, scenes=(root.name,))

    class Also(_adapter("also")):
        @classmethod
        def matches(cls, root):
            return root == two

    seam = datasets(Own, Also)
    with pytest.raises(DataError, match="matches several datasets"):
        seam.detect_dataset(two)
    assert seam.open_dataset(two, "own")[0] is Own and seam.open_dataset(two, "own")[1].root == two
    assert seam.open_datasets([two], "own")[2].scenes == ("two",)
    assert seam.open_datasets([one, two])[2].scenes == ("one", "two")  # two: 'own', as the first root
    assert set(seen) == {one, two}
    assert seam._plugin(Own) is None
