"""One preparation of a prediction for scoring, and what a scene gives every prediction it scores.

:meth:`SceneReference.prepare` is the only place where a disparity map is made ready to be compared with
the ground truth; every scorer goes through it (:func:`lfbench.scoring.score.score_scene`, the per-pixel
errors of the bootstrap :func:`lfbench.scoring.stats.scene_errors`, the uncertainty sparsification
:func:`lfbench.scoring.uncertainty.scene_sparsifications`, the BadPix-series curves of the figures and
the validation during training). The steps, the toolkit's rules (docs/benchmark-rules.md):

1. alignment: a map cropped by a symmetric border (482x482, 490x490 of 512x512) is placed at the centre
   of a NaN canvas of the scene's size (:func:`align_prediction`; a crop wider than the evaluation
   border is refused);
2. precision: float32, as the toolkit computes;
3. resolution: at high resolution the map is upsampled by the scale s of the high-resolution ground
   truth (10 for HCI) exactly as the toolkit's ``scipy.ndimage.zoom(order=0)`` (:func:`upsample_nearest`,
   which is not a plain repeat);
4. the pixels scored: all but ``border_px * s`` on each side (:func:`border_mask`), and the scene's
   valid_mask.png upsampled as the map is.

A :class:`SceneReference` holds what does not depend on the method: the ground truth at each resolution,
the valid and evaluation masks, the region and label masks and the mask names, the upsampling index (which
low-resolution pixel each high-resolution pixel takes, :func:`upsample_index`), the scored pixels of each
mask (:meth:`SceneReference.pixels`) and whatever a metric keeps per scene (:meth:`SceneReference.memo`),
each computed on first use and kept, so that one reference serves every method (and metric) scored on its
scene: the scoring engine's per-scene cache, owned by whoever scores (a run keeps one per scene while it
scores that scene). A :class:`Prepared` prediction is the per-method half: the map aligned once, upsampled
on first use, and its errors at each set of scored pixels gathered once (:meth:`Prepared.errors`). Cached
arrays are read-only. Disparity is in px per view step; shapes are (H, W) at low resolution, (H s, W s) at
high.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfbench.data.disparity import disparity_problem
from lfbench.data.scene import LOWRES, LightField, read_png
from lfbench.scoring.base import Metric
from lfbench.scoring.filters import zoom_index
from lfbench.scoring.pixels import PixelErrors, PixelSet
from lfbench.scoring.policy import LFBENCH, scorer
from lfbench.scoring.rules import ScoringRules, metric_resolution
from lfbench.utils.errors import DataError

__all__ = [
    "GroundTruth",
    "Prepared",
    "SceneReference",
    "align_prediction",
    "border_mask",
    "read_label_mask",
    "upsample_index",
    "upsample_nearest",
]


def border_mask(shape: tuple[int, int], border: int) -> np.ndarray:
    """Bool (H, W): True everywhere except ``border`` px on each side."""
    mask = np.zeros(shape, dtype=bool)
    h, w = shape
    mask[border:h - border, border:w - border] = True
    return mask


def align_prediction(pred: np.ndarray, shape: tuple[int, int], source: str = "prediction",
                     max_crop: int | None = None) -> tuple[np.ndarray, tuple[int, int] | None]:
    """Place a prediction cropped by a symmetric border (e.g. 482x482 of 512x512) at the centre of a
    NaN canvas of ``shape``. Returns (aligned, original shape or None if nothing was done).

    A crop wider than ``max_crop`` px per side (the evaluation border) is refused: the uncovered
    pixels would be scored, so such a map is the wrong size rather than a cropped one.
    """
    pred = np.asarray(pred)
    # the one rule of a prediction's size (lfbench.data.disparity); any real numbers here: a library caller's
    # integer map is scored as the float32 it becomes (a method's prediction was checked as floating already)
    problem = disparity_problem(pred.dtype.kind in "fiu", str(pred.dtype), pred.shape, shape, max_crop=max_crop)
    if problem:
        raise DataError(problem, source)
    if pred.shape == tuple(shape):
        return pred, None
    dh, dw = shape[0] - pred.shape[0], shape[1] - pred.shape[1]
    out = np.full(shape, np.nan, dtype=np.float32)
    out[dh // 2:dh // 2 + pred.shape[0], dw // 2:dw // 2 + pred.shape[1]] = pred
    return out, (int(pred.shape[0]), int(pred.shape[1]))


def upsample_nearest(pred: np.ndarray, factor: int) -> np.ndarray:
    """Nearest-neighbour upsampling exactly as the toolkit: scipy.ndimage.zoom(pred, factor, order=0)."""
    from scipy import ndimage  # imported when a prediction is scored, not by lfbench regress's start-up

    return ndimage.zoom(pred, factor, order=0)


def upsample_index(shape: tuple[int, int], factor: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols), intp: the low-resolution row of each of the ``h factor`` output rows and the column of
    each of the ``w factor`` output columns of :func:`upsample_nearest` on an (h, w) map, so that
    ``pred[rows][:, cols]`` is ``upsample_nearest(pred, factor)`` bit for bit. Order-0 zoom maps each axis
    on its own; the index is the toolkit's zoom applied to the row and column numbers themselves, computed
    as scipy computes it (:func:`lfbench.scoring.filters.zoom_index`; scoring does not import scipy)."""
    h, w = shape
    return zoom_index(h, factor), zoom_index(w, factor)


def read_label_mask(path: str | Path) -> np.ndarray:
    """A label PNG (e.g. mask_boxes, mask_dots_by_size) as (H, W) non-negative integers in the image's own
    type (uint8 for 8-bit, uint16 or int32 for 16-bit PNGs): the gray value of each pixel. An RGB(A) image
    is accepted when its colour channels are equal."""
    path = Path(path)
    arr = read_png(path, "label mask")
    if arr.ndim == 3:
        rgb = arr[..., :3]
        if not (rgb == rgb[..., :1]).all():
            raise DataError("label mask must be gray (its colour channels differ)", path)
        arr = rgb[..., 0]
    if not np.issubdtype(arr.dtype, np.integer) or (arr.dtype.kind == "i" and arr.size and arr.min() < 0):
        arr = arr.astype(np.int32)
    return np.ascontiguousarray(arr)


def _kept(arr: np.ndarray | None) -> np.ndarray | None:
    """A read-only view of ``arr`` (None stays None): kept by a reference and shared by every prediction it
    scores, so no scorer may write into it (the array itself, e.g. a light field's own, stays as it was)."""
    if arr is None:
        return None
    view = np.asarray(arr).view()
    view.flags.writeable = False
    return view


@dataclass
class GroundTruth(LightField):
    """A ground truth (H, W) px held in memory, without views or masks (:meth:`SceneReference.of_ground_truth`)."""

    name: str
    gt: np.ndarray

    @property
    def spatial_size(self) -> tuple[int, int]:
        return tuple(self.gt.shape)

    def gt_disparity(self) -> np.ndarray:
        return self.gt


class Prepared:
    """A prediction made ready to be compared with the ground truth at one resolution (:meth:`SceneReference.prepare`).

    gt: (H s, W s) float32 ground-truth disparity (px); pred: (H s, W s) float32 prediction (px),
    aligned and upsampled (on first use); aligned: the prediction aligned at low resolution (H, W) float32;
    mask: (H s, W s) bool, the pixels scored (the border of ``border_px * s`` and the valid mask; region
    masks are the metrics' own); scale: s, 1 at low resolution (10 for HCI at high); resolution: 'lowres'
    or 'highres'; aligned_from: (h, w) of a cropped prediction placed at the centre, else None;
    uncertainty: the prediction's uncertainty map aligned and upsampled as the disparity (in its own
    dtype), or None. ``gt`` and ``mask`` belong to the scene's reference: read-only. :meth:`errors`: the
    prediction's errors at the scored pixels of a region (gathered once per region).
    """

    def __init__(self, reference: SceneReference, resolution: str, aligned: np.ndarray,
                 aligned_from: tuple[int, int] | None = None, uncertainty: np.ndarray | None = None) -> None:
        self.reference = reference
        self.resolution = resolution
        self.aligned = _kept(aligned)
        self.aligned_from = aligned_from
        self.uncertainty = uncertainty
        self.gt = reference.gt(resolution)
        self.mask = reference.evaluation_mask(resolution)
        self.scale = reference.scale(resolution)
        self._errors: dict[str | None, PixelErrors] = {}

    @functools.cached_property
    def pred(self) -> np.ndarray:
        """Read-only."""
        return _kept(self.reference.upsample(self.aligned, self.resolution))

    def errors(self, mask_name: str | None = None) -> PixelErrors:
        """The prediction's errors (:class:`~lfbench.scoring.pixels.PixelErrors`) at the pixels of the
        evaluation mask (and of the region mask ``mask_name``): :meth:`SceneReference.pixels`."""
        if mask_name not in self._errors:
            pixels = self.reference.pixels(self.resolution, mask_name)
            errors = PixelErrors(pixels, pixels.values(self.aligned))
            if self.reference.rules.scorer != LFBENCH.name:
                errors.scorer = scorer(self.reference.rules.scorer)
            self._errors[mask_name] = errors
        return self._errors[mask_name]

    def release(self, mask_name: str | None = None) -> None:
        """Drop the errors gathered at the pixels of ``mask_name`` (:meth:`errors` gathers them again if asked):
        a scorer done with a region frees its prediction values, errors and flags before the next region's."""
        self._errors.pop(mask_name, None)


class SceneReference:
    """What scoring needs of one scene, whatever the method: computed on first use, then kept.

    ``scene``: a :class:`~lfbench.data.scene.Scene` (or any light field with ground truth); ``rules``: the
    scoring rules (border, resolutions). A reference answers what scoring asks of a scene the way the
    scene does (``name``, ``path``, ``params``, ``spatial_size``, ``has_gt``, ``mask_names``, ``mask``,
    ``valid_mask``), from its caches, and adds the prepared forms: the ground truth at a resolution
    (:meth:`gt`), the scale and shape of a resolution, the evaluation mask (:meth:`evaluation_mask`), label
    masks (:meth:`label_mask`), and :meth:`prepare` for each prediction. Memory: what it has been asked for
    (at HCI high resolution ~100 MB for the ground truth, ~26 MB per mask).
    """

    def __init__(self, scene: LightField, rules: ScoringRules = ScoringRules()) -> None:
        self.scene = scene
        self.rules = rules
        self._gt: dict[str, np.ndarray | None] = {}
        self._valid: dict[str, np.ndarray | None] = {}
        self._evaluation: dict[str, np.ndarray] = {}
        self._mask_names: dict[str, list[str]] = {}
        self._masks: dict[tuple[str, str], np.ndarray] = {}
        self._labels: dict[tuple[str, str], np.ndarray] = {}
        self._spatial_size: tuple[int, int] | None = None
        self._index: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._pixels: dict[tuple[str, str | None], PixelSet] = {}
        self._scored: dict[tuple[str, str], np.ndarray] = {}
        self._memo: dict[Any, Any] = {}
        self._per_prediction: dict[Any, tuple[np.ndarray, Any]] = {}

    @classmethod
    def of(cls, scene: LightField | SceneReference) -> SceneReference:
        """``scene`` itself when it is a reference (what scoring passes to a metric), else a new one."""
        return scene if isinstance(scene, SceneReference) else cls(scene)

    @classmethod
    def of_ground_truth(cls, gt: np.ndarray, rules: ScoringRules, name: str) -> SceneReference:
        """A reference to a low-resolution ground truth (H, W) px held in memory, without views or masks
        (e.g. a validation crop during training), named ``name``: scored inside the rules' border."""
        return cls(GroundTruth(name, np.asarray(gt)), rules)

    def __repr__(self) -> str:
        return f"SceneReference({self.scene!r}, {self.rules!r})"

    def check_serves(self, scene: LightField, rules: ScoringRules | None = None) -> None:
        """ValueError unless this reference was made for ``scene`` itself (the same object: not another
        folder's scene of the same name, whose ground truth differs) and, when given, under ``rules``."""
        if self.scene is not scene or (rules is not None and self.rules != rules):
            raise ValueError(f"the reference is of {self.scene!r} under {self.rules}, not of the scene scored")

    # ------------------------------------------------------------------ the scene, as scoring asks it

    @property
    def name(self) -> str:
        return self.scene.name

    @property
    def path(self) -> Path | None:
        return getattr(self.scene, "path", None)

    @property
    def params(self) -> Any:
        return self.scene.params

    @property
    def spatial_size(self) -> tuple[int, int]:
        """(H, W) at low resolution: the scene's own size (a light field's: of its views)."""
        if self._spatial_size is None:
            size = getattr(self.scene, "spatial_size", None)
            self._spatial_size = tuple(size) if size is not None else tuple(self.scene.gray_views().shape[2:4])
        return self._spatial_size

    def has_gt(self, resolution: str = LOWRES) -> bool:
        if resolution in self._gt:
            return self._gt[resolution] is not None
        if hasattr(self.scene, "has_gt"):
            return self.scene.has_gt(resolution)
        return resolution == LOWRES and self.scene.gt_disparity() is not None

    def mask_names(self, resolution: str = LOWRES) -> list[str]:
        """The names of the scene's evaluation masks at ``resolution`` (none for a light field without)."""
        if resolution not in self._mask_names:
            names = getattr(self.scene, "mask_names", None)
            self._mask_names[resolution] = list(names(resolution)) if callable(names) else []
        return self._mask_names[resolution]

    def mask(self, name: str, resolution: str = LOWRES, shape: tuple[int, ...] | None = None) -> np.ndarray:
        """Evaluation mask ``<name>_<resolution>.png`` as bool (read-only). ``shape``: the ground truth's
        (H, W), which the mask must have (DataError naming the file otherwise)."""
        key = (name, resolution)
        if key not in self._masks:
            self._masks[key] = _kept(self.scene.mask(name, resolution))
        return self._checked(self._masks[key], name, resolution, shape)

    def label_mask(self, name: str, resolution: str = LOWRES, shape: tuple[int, ...] | None = None) -> np.ndarray:
        """Label mask ``<name>_<resolution>.png`` (:func:`read_label_mask`, integers, read-only), checked against
        ``shape`` as :meth:`mask` does."""
        key = (name, resolution)
        if key not in self._labels:
            self._labels[key] = _kept(read_label_mask(self.path / f"{name}_{resolution}.png"))
        return self._checked(self._labels[key], name, resolution, shape)

    def _checked(self, mask: np.ndarray, name: str, resolution: str, shape: tuple[int, ...] | None) -> np.ndarray:
        if shape is not None and mask.shape != tuple(shape):
            raise DataError(f"mask is {mask.shape[1]}x{mask.shape[0]}, ground truth is {shape[1]}x{shape[0]}",
                            self.path / f"{name}_{resolution}.png")
        return mask

    # ------------------------------------------------------------------ what every prediction is scored against

    def gt(self, resolution: str = LOWRES) -> np.ndarray:
        """Ground-truth disparity at ``resolution`` (float32 px, read-only). DataError when the scene has none."""
        if resolution not in self._gt:
            read = self.scene.gt_disparity
            self._gt[resolution] = _kept(read() if resolution == LOWRES else read(resolution))
        gt = self._gt[resolution]
        if gt is None:
            raise DataError(f"no ground truth at {resolution} to score against", self.path)
        return gt

    def shape(self, resolution: str = LOWRES) -> tuple[int, int]:
        """(H, W) at low resolution; at high resolution the shape of the high-resolution ground truth."""
        return self.spatial_size if resolution == LOWRES else tuple(self.gt(resolution).shape)

    def scale(self, resolution: str = LOWRES) -> int:
        """How many pixels of ``resolution`` one low-resolution pixel spans per axis (1 at low resolution)."""
        return self.shape(resolution)[0] // self.spatial_size[0]

    def valid_mask(self, resolution: str = LOWRES) -> np.ndarray | None:
        """The scene's valid_mask.png (True = may be scored) at ``resolution`` (read-only): its own low
        resolution, upsampled as predictions are (:func:`upsample_nearest`, the toolkit's ``zoom(order=0)``),
        so each high-resolution pixel is valid where the low-resolution pixel its prediction comes from
        is. None without a valid mask (or for a light field that has none)."""
        if resolution not in self._valid:
            read = getattr(self.scene, "valid_mask", None)
            valid = read() if callable(read) else None
            shape = self.shape(resolution)
            if valid is not None and valid.shape != shape:
                h, w = valid.shape
                scale = shape[0] // h
                if scale < 1 or shape != (h * scale, w * scale):
                    raise ValueError(f"valid mask {w}x{h} does not scale to {shape[1]}x{shape[0]}")
                valid = self.upsample(valid, resolution)
            self._valid[resolution] = _kept(valid)
        return self._valid[resolution]

    def evaluation_mask(self, resolution: str = LOWRES) -> np.ndarray:
        """Bool (read-only), the pixels scored at ``resolution``: all but the rules' border (scaled to
        the resolution) on each side, and the valid mask where the scene has one."""
        if resolution not in self._evaluation:
            mask = border_mask(self.shape(resolution), self.rules.border_px * self.scale(resolution))
            valid = self.valid_mask(resolution)
            if valid is not None:
                mask &= valid
            self._evaluation[resolution] = _kept(mask)
        return self._evaluation[resolution]

    def scored_mask(self, resolution: str, mask_name: str | None = None) -> np.ndarray:
        """The evaluation mask at ``resolution`` and, when given, the region mask ``mask_name`` there (read-only)."""
        if mask_name is None:
            return self.evaluation_mask(resolution)
        key = (resolution, mask_name)
        if key not in self._scored:
            mask = self.evaluation_mask(resolution)
            self._scored[key] = _kept(mask & self.mask(mask_name, resolution, mask.shape))
        return self._scored[key]

    def upsample_index(self, resolution: str) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of :func:`upsample_index` from the scene's size to ``resolution``'s."""
        if resolution not in self._index:
            h, w = self.spatial_size
            scale = self.scale(resolution)
            shape = self.shape(resolution)
            if shape != (h * scale, w * scale):
                raise DataError(f"the {resolution} ground truth is {shape[1]}x{shape[0]}, not {scale} x the scene's "
                                f"{w}x{h}", self.path)
            self._index[resolution] = upsample_index((h, w), scale)
        return self._index[resolution]

    def upsample(self, arr: np.ndarray, resolution: str) -> np.ndarray:
        """A low-resolution (H, W) map at ``resolution`` as the toolkit upsamples (``zoom(order=0)``, through
        :meth:`upsample_index`); itself at low resolution."""
        if self.scale(resolution) == 1:
            return arr
        rows, cols = self.upsample_index(resolution)
        return np.take(np.take(arr, rows, axis=0), cols, axis=1)

    def pixels(self, resolution: str, mask_name: str | None = None) -> PixelSet:
        """The pixels scored at ``resolution`` (:meth:`scored_mask`) as a :class:`~lfbench.scoring.pixels.PixelSet`
        that takes predictions there by the toolkit's upsampling: what every pixel-wise metric of that region
        computes on."""
        key = (resolution, mask_name)
        if key not in self._pixels:
            gt = self.gt(resolution)
            mask = self.scored_mask(resolution, mask_name)
            upsample = self.upsample_index(resolution) if self.scale(resolution) > 1 else None
            self._pixels[key] = PixelSet(mask, gt, upsample=upsample, low_width=self.spatial_size[1],
                                         box=self._border_box(resolution) if mask_name is None else None)
        return self._pixels[key]

    def _border_box(self, resolution: str) -> tuple[int, int, int, int] | None:
        """The evaluation mask at ``resolution`` as the rectangle (top, bottom, left, right) it is when the scene
        has no valid mask (:func:`border_mask`), else None."""
        if self.valid_mask(resolution) is not None:
            return None
        h, w = self.shape(resolution)
        border = self.rules.border_px * self.scale(resolution)
        return (border, h - border, border, w - border) if 0 <= 2 * border <= min(h, w) else None

    def memo(self, key: Any, compute: Callable[[], Any]) -> Any:
        """What a metric keeps of this scene (method-independent): ``compute()`` the first time ``key`` is asked
        for, then the same value."""
        if key not in self._memo:
            self._memo[key] = compute()
        return self._memo[key]

    def per_prediction(self, key: Any, pred: np.ndarray, compute: Callable[[], Any]) -> Any:
        """What a metric keeps of one prepared prediction (e.g. a map two metrics of different masks share):
        ``compute()`` once while ``pred`` is the same (read-only) array object, kept until another
        prediction replaces it under ``key``."""
        slot = self._per_prediction.get(key)
        if slot is None or slot[0] is not pred:
            slot = self._per_prediction[key] = (pred, compute())
        return slot[1]

    def general_resolution(self) -> str:
        """The resolution of the general metrics on this scene (:meth:`ScoringRules.general_resolution`)."""
        return self.rules.general_resolution(self)

    def metric_resolution(self, metric: Metric) -> str | None:
        """The resolution ``metric`` is scored at on this scene, or None (:func:`metric_resolution`)."""
        return metric_resolution(self, metric, self.rules)

    # ------------------------------------------------------------------ one prediction

    def align(self, pred: np.ndarray, source: str = "prediction") -> tuple[np.ndarray, tuple[int, int] | None]:
        """(the prediction at the scene's low-resolution size in float32, its own (h, w) when it was a
        cropped map placed at the centre, else None); a crop wider than the rules' border is refused."""
        pred, aligned_from = align_prediction(pred, self.spatial_size, source, max_crop=self.rules.border_px)
        pred = pred.astype(np.float32, copy=False)
        return pred, aligned_from

    def prepare(self, pred: np.ndarray, resolution: str, source: str = "prediction", *,
                uncertainty: np.ndarray | None = None) -> Prepared:
        """The prediction ``pred`` (H, W) px (or a symmetric crop of it) made ready to be scored at
        ``resolution``: aligned, float32, upsampled as the toolkit does, with the ground truth and the
        evaluation mask at that resolution. ``uncertainty`` (same shape as ``pred``), when given, is
        aligned and upsampled the same way. ``source`` names the prediction in errors."""
        self.gt(resolution)  # DataError without ground truth there, before the prediction is looked at
        aligned, aligned_from = self.align(pred, source)
        if uncertainty is not None:
            uncertainty, _ = align_prediction(np.asarray(uncertainty), self.spatial_size, f"{source} uncertainty",
                                              max_crop=self.rules.border_px)
            uncertainty = self.upsample(uncertainty, resolution)
        return Prepared(self, resolution, aligned, aligned_from, uncertainty)
