"""The few ``scipy.ndimage`` operations scoring uses, in numpy, computed as scipy computes them (bit for bit).

Scoring needs three: the order-0 zoom of the toolkit's upsampling (only the index it applies along an axis,
:func:`zoom_index`), a 3x3 correlation (the Scharr derivatives of bumpiness, :func:`correlate3x3`) and a 3-tap
correlation along one axis (the surface normals of MAE, :func:`correlate1d3`). Importing ``scipy.ndimage``
costs more CPU time than scoring a low-resolution scene (it imports ``scipy.special`` and the array-API
layer), so scoring does these here. Each follows the arithmetic of scipy's C code (``ni_filters.c``,
``ni_interpolation.c``): the same products and sums in the same order, in float64, so the same values; the
tests check them against scipy on maps with NaN, infinities and signed zeros. Only the sign bit of a NaN may
differ (an infinity times a zero weight), which no score sees: scoring tests values with ``isfinite``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["correlate1d3", "correlate3x3", "zoom_index"]

#: scipy.ndimage's boundary modes -> numpy.pad's (one pixel of padding)
_PAD_MODES = {"reflect": "symmetric", "mirror": "reflect", "nearest": "edge", "wrap": "wrap",
              "constant": "constant"}
_EPS = np.finfo(np.float64).eps  # scipy treats weights within it of zero as zero (and of symmetry as symmetric)


def zoom_index(length: int, factor: int) -> np.ndarray:
    """intp (length x factor,): the input position each output position takes in ``scipy.ndimage.zoom(.., factor,
    order=0)`` along an axis of ``length`` (grid_mode False): the nearest of position j x (length - 1) /
    (length x factor - 1), rounded half up as scipy's ``floor(c + 0.5)``."""
    out = int(round(length * factor))
    if out < 1 or length < 1:
        raise ValueError(f"zoom of an axis of {length} by {factor}: nothing to index")
    step = (length - 1) / (out - 1) if out > 1 else 1.0  # float64, as scipy's np.divide of the shapes
    coords = np.arange(out, dtype=np.float64) * step
    index = np.floor(coords + 0.5).astype(np.intp)
    index[coords > length - 1] = 0  # past the last input (by a rounding of the step): scipy's cval 0, as a position
    return index


def _padded(image: np.ndarray, mode: str, axis: int | None = None) -> np.ndarray:
    if mode not in _PAD_MODES:
        raise ValueError(f"unknown boundary mode {mode!r}: {', '.join(_PAD_MODES)}")
    width = 1 if axis is None else [(1, 1) if k == axis else (0, 0) for k in range(image.ndim)]
    return np.pad(image, width, mode=_PAD_MODES[mode])


def correlate3x3(image: np.ndarray, weights: np.ndarray, mode: str = "reflect") -> np.ndarray:
    """``scipy.ndimage.correlate(image, weights, mode=mode)`` of a (H, W) map with a 3x3 kernel, float64:
    0.0 plus each non-zero weight times its neighbour, in the kernel's raster order (zero weights are skipped,
    so an infinite neighbour there gives no NaN)."""
    image = np.asarray(image, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if image.ndim != 2 or weights.shape != (3, 3):
        raise ValueError(f"a (H, W) image and a 3x3 kernel, got {image.shape} and {weights.shape}")
    padded = _padded(image, mode)
    h, w = image.shape
    out = np.zeros((h, w), dtype=np.float64)
    for (a, b), weight in np.ndenumerate(weights):
        if abs(weight) > _EPS:
            out += weight * padded[a:a + h, b:b + w]
    return out


def _outside(lines: np.ndarray, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """The neighbours before the first and after the last of ``lines`` (the axis first, length n >= 1) that
    ``mode`` puts there, as scipy.ndimage pads: each of one line's shape."""
    if mode not in _PAD_MODES:
        raise ValueError(f"unknown boundary mode {mode!r}: {', '.join(_PAD_MODES)}")
    n = lines.shape[0]
    if mode == "constant":
        zero = np.zeros(lines.shape[1:], dtype=lines.dtype)
        return zero, zero
    if mode == "wrap":
        return lines[n - 1], lines[0]
    if mode == "mirror" and n > 1:
        return lines[1], lines[n - 2]
    return lines[0], lines[n - 1]  # reflect and nearest repeat the end line (so does mirror of one line)


def _neighbours(lines: np.ndarray, mode: str, op: np.ufunc) -> np.ndarray:
    """``op(left, right)`` of every line (the axis first) and its neighbours before and after it, computed
    line by line into one array (no padded copy of the map)."""
    before, after = _outside(lines, mode)
    n = lines.shape[0]
    out = np.empty_like(lines)
    op(before, lines[1] if n > 1 else after, out=out[0])
    if n > 1:
        op(lines[:-2], lines[2:], out=out[1:-1])
        op(lines[n - 2], after, out=out[n - 1])
    return out


def correlate1d3(image: np.ndarray, weights: np.ndarray, axis: int, mode: str = "reflect") -> np.ndarray:
    """``scipy.ndimage.correlate1d(image, weights, axis=axis, mode=mode)`` with 3 weights (w0, w1, w2), float64.
    As scipy: a symmetric kernel is x w1 + (left + right) w0, an antisymmetric one x w1 + (left - right) w0,
    any other (right w2 + left w0) + x w1 (left / right: the neighbours before / after along ``axis``, the
    boundary's from ``mode``). Computed from views of the map, line by line at its two ends: no padded copy."""
    image = np.asarray(image, dtype=np.float64)
    w0, w1, w2 = (float(v) for v in np.asarray(weights, dtype=np.float64).reshape(3))
    lines = np.moveaxis(image, axis, 0)  # a view: the lines along ``axis`` first
    if abs(w2 - w0) <= _EPS or abs(w2 + w0) <= _EPS:
        pair = _neighbours(lines, mode, np.add if abs(w2 - w0) <= _EPS else np.subtract)
        pair *= w0
        out = image * w1
        np.moveaxis(out, axis, 0)[...] += pair
        return out
    before, after = _outside(lines, mode)
    out = np.empty_like(image)
    moved = np.moveaxis(out, axis, 0)
    np.multiply(lines[1:], w2, out=moved[:-1])  # right w2
    np.multiply(after, w2, out=moved[-1])
    moved[1:] += lines[:-1] * w0  # + left w0
    moved[0] += before * w0
    out += image * w1
    return out
