"""Scoring's own numpy for what it once called a library for: lfbench.scoring.filters computes scipy.ndimage's zoom
index and 3-tap / 3x3 correlations as scipy does (the same values on maps with NaN, infinities and signed zeros, a
NaN's sign bit aside, for every boundary mode); the surface normals are np.cross and np.linalg.norm's bits, and
the label values present are those a count finds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from lfbench.scoring.filters import correlate1d3, correlate3x3, zoom_index
from lfbench.scoring.region_metrics import _DIFF, _SCHARR_H, _SMOOTH, _present, _scharr_separable, depth_normals

MODES = ["reflect", "mirror", "nearest", "wrap", "constant"]


def _hostile(shape: tuple[int, int], seed: int = 0) -> np.ndarray:
    """Values over seven decades with NaN, +-inf, 0.0 and -0.0 sprinkled in."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(shape) * 10.0 ** rng.integers(-3, 4, shape)
    for value, share in ((np.nan, 20), (np.inf, 30), (-np.inf, 30), (-0.0, 10), (0.0, 10)):
        x.ravel()[rng.integers(0, x.size, max(1, x.size // share))] = value
    return x


def _same(got: np.ndarray, expected: np.ndarray) -> None:
    assert got.dtype == expected.dtype == np.float64 and got.shape == expected.shape
    nan = np.isnan(expected)
    assert np.array_equal(np.isnan(got), nan)
    assert np.array_equal(got[~nan].view(np.uint64), expected[~nan].view(np.uint64))  # bits: signed zeros too


@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (2, 2), (3, 3), (7, 9), (64, 48)])
@pytest.mark.parametrize("mode", MODES)
def test_correlate3x3_is_scipys_convolve_of_the_flipped_kernel(shape, mode):
    x = _hostile(shape)
    with np.errstate(invalid="ignore"):
        for kernel in (_SCHARR_H, _SCHARR_H.T, np.random.default_rng(1).standard_normal((3, 3))):
            _same(correlate3x3(x, kernel[::-1, ::-1], mode), ndimage.convolve(x, kernel, mode=mode))
            _same(correlate3x3(x, kernel, mode), ndimage.correlate(x, kernel, mode=mode))


@pytest.mark.parametrize("shape", [(1, 5), (2, 2), (5, 1), (3, 3), (7, 9), (64, 48)])
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("weights", [_DIFF, _SMOOTH, np.array([0.3, -1.2, 2.5])], ids=["anti", "sym", "general"])
def test_correlate1d3_is_scipys_correlate1d(shape, mode, weights):
    x = _hostile(shape, seed=2)
    with np.errstate(invalid="ignore"):
        for axis in (0, 1):
            _same(correlate1d3(x, weights, axis, mode), ndimage.correlate1d(x, weights, axis=axis, mode=mode))


@pytest.mark.parametrize("factor", range(1, 13))
def test_zoom_index_is_scipys_order0_zoom_of_the_positions(factor):
    """Including the lengths where the last position's coordinate overshoots the input by a rounding (scipy's
    constant mode gives 0 there): 512 x 3, 256 x 5, 434 x 6, ..."""
    for length in [*range(1, 80), 100, 256, 434, 512, 600, 1024]:
        positions = np.repeat(np.arange(length, dtype=np.float64)[:, None], 2, axis=1)
        expected = ndimage.zoom(positions, factor, order=0)[:, 0].astype(np.intp)
        assert np.array_equal(zoom_index(length, factor), expected), (length, factor)


def test_unknown_mode_and_shapes_are_refused():
    with pytest.raises(ValueError, match="boundary mode"):
        correlate3x3(np.zeros((3, 3)), np.ones((3, 3)), "grid-wrap")
    with pytest.raises(ValueError, match="3x3 kernel"):
        correlate3x3(np.zeros((3, 3)), np.ones((5, 5)))
    with pytest.raises(ValueError, match="nothing to index"):
        zoom_index(0, 10)


def _stacked_normals(depth: np.ndarray, focal_length_mm: float, sensor_size_mm: float) -> np.ndarray:
    """depth_normals as it was written: stacked tangents, np.cross and np.linalg.norm."""
    z = np.asarray(depth, dtype=np.float64)
    h, w = z.shape
    k = 0.5 * sensor_size_mm / focal_length_mm
    points = (k * (np.arange(w) / (w - 1.0))[None, :] * z, k * (np.arange(h) / (h - 1.0))[:, None] * z, z)
    d_row = np.stack([_scharr_separable(c, axis=0) for c in points], axis=-1)
    d_col = np.stack([_scharr_separable(c, axis=1) for c in points], axis=-1)
    normal = np.cross(d_row, d_col)
    return normal / np.linalg.norm(normal, axis=-1, keepdims=True)


@pytest.mark.parametrize("shape", [(3, 3), (37, 53), (128, 96)])
def test_depth_normals_are_numpys_cross_and_norm_bit_for_bit(shape):
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.5, 20, shape) * 10.0 ** rng.integers(-3, 3, shape)
    for value, share in ((np.nan, 50), (np.inf, 80), (0.0, 80)):
        depth.ravel()[rng.integers(0, depth.size, max(1, depth.size // share))] = value
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        expected = _stacked_normals(depth, 100.0, 35.0)
        got = depth_normals(depth, 100.0, 35.0)
    nan = np.isnan(expected)
    assert got.shape == expected.shape and np.array_equal(np.isnan(got), nan)
    assert np.array_equal(got[~nan].view(np.uint64), expected[~nan].view(np.uint64))


@pytest.mark.parametrize(("dtype", "top"), [(np.uint8, 0), (np.uint8, 9), (np.uint8, 31), (np.uint8, 32),
                                             (np.uint16, 300), (np.int32, 5), (np.int32, 300)])
def test_present_labels_are_the_counted_ones(dtype, top):
    rng = np.random.default_rng(top)
    labels = rng.choice(np.array([0, top // 2, top], dtype=dtype), size=(61, 47))
    expected = np.bincount(labels.ravel().astype(np.intp)) > 0
    assert np.array_equal(_present(labels), expected)
    assert np.array_equal(_present(labels, chunk=100), expected)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_angular_error_is_numpys_sum_of_products_bit_for_bit(dtype):
    """The angle between normal maps: the dot product added one component at a time gives np.sum(a * b, axis=-1)'s
    bits (numpy adds three products in order), NaN where either normal is NaN or an infinity meets a zero."""
    from lfbench.scoring.region_metrics import angular_error_deg

    rng = np.random.default_rng(4)
    a, b = (rng.standard_normal((37, 53, 3)).astype(dtype) for _ in range(2))
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    a[1, 2] = np.nan
    b[3, 4, 1] = np.inf
    a[3, 4, 1] = 0.0
    a[5, 6] = -0.0
    with np.errstate(invalid="ignore"):
        expected = np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))
        got = angular_error_deg(a, b)
    nan = np.isnan(expected)
    assert got.dtype == expected.dtype and np.array_equal(np.isnan(got), nan) and nan[1, 2] and nan[3, 4]
    assert np.array_equal(got[~nan].view(np.uint8), expected[~nan].view(np.uint8))
