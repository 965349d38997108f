"""Tests for the survivors of issue 39's second mutation round (results/mutation/issue39/README.md, passes 8 on):
the view grid's orientation check (lfbench.data.orientation) and the rest of the statistics (lfbench.scoring.stats).
Every expected value comes from an independent computation: a plain-NumPy warp written from the docstring's
geometry (bilinear sampling loop by loop, not torch's grid_sample), hand-built light fields, scipy.stats, exact
enumerations. Each test names the class of mutants it kills."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from lfbench.data.orientation import (
    AS_READ,
    ORIENTATIONS,
    check_orientation,
    distinct_readings,
    has_centre_view,
    orientation_errors,
    warp_error,
)

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
