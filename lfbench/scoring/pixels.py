"""The scored pixels of a metric and a prediction's errors on them: what the pixel-wise metrics compute from.

A pixel-wise metric (BadPix, MSE, the quantiles, and the region metrics that count pixels of a mask) depends
only on the (ground truth, prediction) pairs of the pixels it scores, in raster order, not on where they lie.
So scoring keeps, per scene, each set of scored pixels once (:class:`PixelSet`: their mask, how a
low-resolution prediction reaches them, their ground truth), and per prediction gathers
its values at those pixels once (:class:`PixelErrors`) and computes the absolute error, the finite masks
and anything else its metrics ask for once, for every metric of that set.

The metric functions of arrays (:func:`lfbench.scoring.general.bad_pix`, ...) compute through the same
objects (:meth:`PixelErrors.of_maps`), so there is one definition of each metric. Values are bit for bit
those of the same formula on the full maps: the same elements in the same order (a boolean mask keeps raster
order), the same precision (the maps' common one, at least float32).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np

from lfbench.scoring.policy import LFBENCH, ScorerPolicy

__all__ = ["ErrorsOnly", "PixelErrors", "PixelSet", "common_precision"]


def common_precision(gt: np.ndarray, pred: np.ndarray) -> np.dtype:
    """The precision the metrics compute in: the maps' common float type, at least float32."""
    return np.result_type(gt.dtype, pred.dtype, np.float32)


def _read_only(arr: np.ndarray) -> np.ndarray:
    arr.flags.writeable = False
    return arr


class PixelSet:
    """Pixels a metric scores on one scene at one resolution, whatever the method (kept by the scene's
    :class:`~lfbench.scoring.prepare.SceneReference`).

    ``mask``: bool (H, W), the pixels; ``gt_map``: the ground truth (H, W); ``upsample``: (rows, cols), the
    low-resolution row of each of the H rows and column of each of the W columns (the toolkit's upsampling,
    lfbench.scoring.prepare.upsample_index) when predictions come at low resolution, else None.
    ``low_width``: the width of the low-resolution map (the scene's; W when the maps are at it).
    ``box``: (top, bottom, left, right) when ``mask`` is exactly the rectangle [top:bottom, left:right] (the
    evaluation mask of a scene without a valid mask: all but the border), so that its pixels are sliced, not
    selected by the mask (the same pixels in the same order). :meth:`memo` keeps further method-independent
    arrays of the set (e.g. a metric's per-pixel reference values).
    """

    def __init__(self, mask: np.ndarray | None, gt_map: np.ndarray, *,
                 upsample: tuple[np.ndarray, np.ndarray] | None = None, low_width: int | None = None,
                 box: tuple[int, int, int, int] | None = None) -> None:
        self.mask = mask
        self.gt_map = gt_map
        self.shape: tuple[int, ...] = tuple(gt_map.shape)
        self.upsample = upsample
        self.low_width = int(self.shape[-1] if low_width is None else low_width)
        if box is not None and not (0 <= box[0] <= box[1] <= self.shape[0] and 0 <= box[2] <= box[3] <= self.shape[1]):
            raise ValueError(f"box {box} is not a rectangle of the {self.shape} map")
        self.box = box
        self._memo: dict[Any, Any] = {}

    def _selected(self, arr: np.ndarray) -> np.ndarray:
        """``arr`` (a map of ``shape``) at the pixels, in raster order."""
        if self.box is not None:
            top, bottom, left, right = self.box
            return arr[top:bottom, left:right].ravel()
        return arr.ravel() if self.mask is None else arr[self.mask]

    @functools.cached_property
    def gt(self) -> np.ndarray:
        """The ground truth at the pixels (1-D, the map's dtype, read-only)."""
        return _read_only(self._selected(self.gt_map))

    def per_row(self, values: np.ndarray) -> np.ndarray:
        """``values`` (one per row of the map) at each pixel: the value of its row (raster order is row by row)."""
        h, w = self.shape
        counts = np.full(h, w) if self.mask is None else np.count_nonzero(self.mask, axis=1)
        return np.repeat(values, counts)

    @functools.cached_property
    def size(self) -> int:
        return int(self.gt.size)

    def memo(self, key: Any, compute: Callable[[], Any]) -> Any:
        """``compute()`` the first time ``key`` is asked for, then the same value (method-independent data)."""
        if key not in self._memo:
            self._memo[key] = compute()
        return self._memo[key]

    def values(self, pred: np.ndarray, rows_per_block: int = 256) -> np.ndarray:
        """A prediction's values at the pixels, in raster order: ``pred`` is the low-resolution map when the
        set upsamples (taken to the set's resolution a block of rows at a time, never whole), else a map of
        ``shape``. IndexError when ``pred`` is narrower than the low-resolution columns the set reads."""
        pred = np.asarray(pred)
        if self.upsample is None:
            return self._selected(pred)
        rows, cols = self.upsample
        top, bottom, left, right = self.box if self.box is not None else (0, self.shape[0], 0, self.shape[1])
        sliced = self.mask is None or self.box is not None  # a rectangle of pixels: no mask to apply
        first, repeats = self._column_runs
        if repeats is not None and first + repeats.size > pred.shape[-1]:
            repeats = None
        out = np.empty(self.size, dtype=pred.dtype)
        at = 0
        for r in range(top, bottom, rows_per_block):
            block = pred.take(rows[r:min(r + rows_per_block, bottom)], axis=0)
            if repeats is None:
                block = block.take(cols[left:right], axis=1)
            else:
                block = np.repeat(block[:, first:first + repeats.size], repeats, axis=1)
            block = block.ravel() if sliced else block[self.mask[r:r + rows_per_block]]
            out[at:at + block.size] = block
            at += block.size
        return out

    @functools.cached_property
    def _column_runs(self) -> tuple[int, np.ndarray | None]:
        """(the first low-resolution column, how many times each column from it repeats) in the upsampling's
        columns of the set (those of its box) when they run in order: then ``np.repeat`` takes them, a fifth
        faster than ``take``, the same values. (0, None) when they do not."""
        cols = self.upsample[1] if self.box is None else self.upsample[1][self.box[2]:self.box[3]]
        if cols.size == 0 or (cols.size > 1 and bool(np.any(cols[1:] < cols[:-1]))):
            return 0, None
        first = int(cols[0])
        return first, np.bincount(cols - first)


class PixelErrors:
    """One prediction on a :class:`PixelSet`: ground truth and prediction at its pixels in their common
    precision, and what every pixel-wise metric computes from them, each computed once: ``err`` =
    |pred - gt|, ``gt_finite``, ``pred_finite``."""

    #: how BadPix compares and what a non-finite value counts as (lfbench.scoring.policy; set from the rules)
    scorer: ScorerPolicy = LFBENCH

    def __init__(self, pixels: PixelSet, pred: np.ndarray) -> None:
        self.pixels = pixels
        dtype = common_precision(pixels.gt, pred)
        self.gt = pixels.gt.astype(dtype, copy=False)
        self.pred = np.asarray(pred).astype(dtype, copy=False)

    @classmethod
    def of_maps(cls, gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *,
                low_width: int | None = None) -> PixelErrors:
        """The errors of ``pred`` against ``gt`` ((H, W) of one shape) at the pixels of ``mask`` (bool (H, W),
        None = all). ``low_width``: the scene's low-resolution width when the maps are at a higher one (None:
        the maps' width). ValueError when the shapes differ."""
        gt, pred = np.asarray(gt), np.asarray(pred)
        if gt.shape != pred.shape:
            raise ValueError(f"gt {gt.shape} and pred {pred.shape} differ in shape")
        if mask is not None:
            mask = np.asarray(mask, dtype=bool)
            if mask.shape != gt.shape:
                raise ValueError(f"mask {mask.shape} and gt {gt.shape} differ in shape")
        if gt.ndim != 2:  # a plain array of values: every element is a pixel
            gt, pred = gt.reshape(1, -1), pred.reshape(1, -1)
            mask = None if mask is None else mask.reshape(1, -1)
        pixels = PixelSet(mask, gt, low_width=low_width)
        return cls(pixels, pixels.values(pred))

    @property
    def size(self) -> int:
        return int(self.gt.size)

    @functools.cached_property
    def err(self) -> np.ndarray:
        """|pred - gt| (NaN where either is NaN)."""
        with np.errstate(invalid="ignore", over="ignore"):
            err = np.subtract(self.pred, self.gt)
            return np.abs(err, out=err)

    @functools.cached_property
    def signed(self) -> np.ndarray:
        """pred - gt (px; NaN where either is NaN)."""
        with np.errstate(invalid="ignore", over="ignore"):
            return np.subtract(self.pred, self.gt)

    @functools.cached_property
    def gt_finite(self) -> np.ndarray:
        return np.isfinite(self.gt)

    @functools.cached_property
    def pred_finite(self) -> np.ndarray:
        return np.isfinite(self.pred)

    @functools.cached_property
    def finite(self) -> np.ndarray:
        """Both finite."""
        return self.gt_finite & self.pred_finite

    @functools.cached_property
    def errors_all_finite(self) -> bool:
        """Whether every error |pred - gt| is finite: then every ground truth value and prediction is (an infinite
        or NaN one gives a non-finite error), found by one read of :attr:`err` (its maximum is NaN or infinite
        if any error is), which the metrics compute anyway."""
        if self.size == 0:
            return True
        with np.errstate(invalid="ignore"):
            return bool(np.isfinite(self.err.max()))

    @functools.cached_property
    def gt_all_finite(self) -> bool:
        """Whether every ground truth value is finite (then no metric leaves a pixel out for it: one test for all)."""
        return self.errors_all_finite or bool(self.gt_finite.all())

    @functools.cached_property
    def pred_all_finite(self) -> bool:
        """Whether every prediction is finite (then no metric's non-finite rule changes a pixel: one test for all)."""
        return self.errors_all_finite or bool(self.pred_finite.all())


class ErrorsOnly(PixelErrors):
    """The signed errors pred - gt (1-D, px) of scored pixels without the maps they came from: what the bootstrap
    keeps per pixel (:mod:`lfbench.scoring.stats`). It answers what a metric of the errors asks for (``err``,
    ``signed``, ``size`` and the finite flags: the ground truth of scored pixels is finite, a non-finite error
    is a non-finite prediction), computed from the errors exactly as :class:`PixelErrors` computes it from the
    maps; ``gt``, ``pred`` and ``pixels`` raise TypeError (a metric that reads them is not a function of the
    errors and declares so, :class:`lfbench.scoring.pixelwise.PixelMetric`)."""

    def __init__(self, errors: np.ndarray) -> None:  # no maps: PixelErrors.__init__ is not called
        self.signed = np.asarray(errors)

    def _no_maps(self, name: str):
        raise TypeError(f"{name}: only the errors pred - gt of the scored pixels are kept here, not the maps")

    gt = property(lambda self: self._no_maps("gt"))
    pred = property(lambda self: self._no_maps("pred"))
    pixels = property(lambda self: self._no_maps("pixels"))

    @property
    def size(self) -> int:
        return int(self.signed.size)

    @functools.cached_property
    def err(self) -> np.ndarray:
        """|pred - gt| (NaN where the error is NaN)."""
        with np.errstate(invalid="ignore"):
            return np.abs(self.signed)

    @functools.cached_property
    def gt_finite(self) -> np.ndarray:
        return np.ones(self.signed.shape, dtype=bool)

    @functools.cached_property
    def pred_finite(self) -> np.ndarray:
        return np.isfinite(self.signed)
