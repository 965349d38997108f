"""Scoring a disparity map on a scene under the benchmark's rules.

Rules (the official toolkit's; docs/benchmark-rules.md, General metrics): a 15 px border is ignored
(scaled with resolution); backgammon, dots and stripes are scored at high resolution when
``gt_disp_highres.pfm`` exists
(the 512x512 prediction upsampled x10 by nearest neighbour exactly as ``scipy.ndimage.zoom(order=0)``,
border 150 px), otherwise at low resolution; the resolution is recorded beside every number.
Region and stratified metrics (lfbench.scoring.region_metrics) are scored wherever their mask files exist,
at their own resolution (see :func:`metric_resolution`). A scene's valid_mask.png (low resolution; any other
size is refused) leaves its False pixels out of every metric at every resolution, upsampled to high
resolution exactly as predictions are (:func:`valid_mask_at`), missed dots included.
Predictions cropped symmetrically by a border (482x482, 490x490) are aligned to the centre.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lfbench.data.scene import HIGHRES, LOWRES, Scene
from lfbench.scoring.metrics import GENERAL_METRICS, Metric, nonfinite_count
from lfbench.utils.errors import DataError

DEFAULT_HIGHRES_SCENES = frozenset({"backgammon", "dots", "stripes"})


@dataclass(frozen=True)
class ScoringRules:
    """How a scene is scored. Defaults are the benchmark's."""

    border_px: int = 15
    highres_scenes: frozenset[str] = DEFAULT_HIGHRES_SCENES
    toolkit: bool = False  # reproduce the toolkit's non-finite handling exactly
    allow_highres: bool = True  # False: score everything at low resolution

    def to_meta(self) -> dict[str, Any]:
        """The rules as a results file records them (``meta["scoring"]``); ``allow_highres`` is not
        recorded: every number carries its resolution."""
        return {"border_px": self.border_px, "toolkit_nonfinite": self.toolkit,
                "highres_scenes": sorted(self.highres_scenes)}

    @classmethod
    def from_meta(cls, meta: Mapping[str, Any], **overrides: Any) -> ScoringRules:
        """The rules a results file was scored under, from its ``meta["scoring"]`` (:meth:`to_meta`);
        what it does not record keeps the default. ``overrides``: fields set by the caller (e.g.
        ``allow_highres``)."""
        scoring = meta.get("scoring") or {}
        recorded: dict[str, Any] = {}
        if "border_px" in scoring:
            recorded["border_px"] = int(scoring["border_px"])
        if "highres_scenes" in scoring:
            recorded["highres_scenes"] = frozenset(scoring["highres_scenes"])
        if "toolkit_nonfinite" in scoring:
            recorded["toolkit"] = bool(scoring["toolkit_nonfinite"])
        return cls(**{**recorded, **overrides})

    def general_resolution(self, scene: Scene) -> str:
        """'highres' for the benchmark's high-resolution scenes when their gt exists, else 'lowres'."""
        if self.allow_highres and scene.name in self.highres_scenes and scene.has_gt(HIGHRES):
            return HIGHRES
        return LOWRES


@dataclass
class SceneScore:
    """Scores of one prediction on one scene: metric id -> value, and how it was scored."""

    scene: str
    values: dict[str, float]
    resolution: dict[str, str]
    nonfinite_pixels: int
    aligned_from: tuple[int, int] | None = None
    notes: list[str] = field(default_factory=list)


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
    if pred.ndim != 2:
        raise DataError(f"disparity must be a 2-D map, got shape {pred.shape}", source)
    if pred.shape == tuple(shape):
        return pred, None
    dh, dw = shape[0] - pred.shape[0], shape[1] - pred.shape[1]
    if dh < 0 or dw < 0 or dh % 2 or dw % 2 or (max_crop is not None and max(dh, dw) // 2 > max_crop):
        raise DataError(f"prediction is {pred.shape[1]}x{pred.shape[0]}, scene is {shape[1]}x{shape[0]} "
                        "(only a symmetric crop of at most the evaluation border can be aligned)", source)
    out = np.full(shape, np.nan, dtype=np.float32)
    out[dh // 2:dh // 2 + pred.shape[0], dw // 2:dw // 2 + pred.shape[1]] = pred
    return out, (int(pred.shape[0]), int(pred.shape[1]))


def upsample_nearest(pred: np.ndarray, factor: int) -> np.ndarray:
    """Nearest-neighbour upsampling exactly as the toolkit: scipy.ndimage.zoom(pred, factor, order=0)."""
    from scipy import ndimage  # imported when a prediction is scored, not by lfbench regress's start-up

    return ndimage.zoom(pred, factor, order=0)


def valid_mask_at(scene: Any, shape: tuple[int, int]) -> np.ndarray | None:
    """The scene's valid_mask.png (True = may be scored) at ``shape``: its own low resolution, or an
    integer multiple of it, upsampled as predictions are (:func:`upsample_nearest`, the toolkit's
    ``zoom(order=0)``), so each high-resolution pixel is valid where the low-resolution pixel its
    prediction comes from is. None without a valid mask (or for a light field that has none)."""
    valid_fn = getattr(scene, "valid_mask", None)
    valid = valid_fn() if callable(valid_fn) else None
    if valid is None or valid.shape == tuple(shape):
        return valid
    h, w = valid.shape
    scale = shape[0] // h
    if scale < 1 or tuple(shape) != (h * scale, w * scale):
        raise ValueError(f"valid mask {w}x{h} does not scale to {shape[1]}x{shape[0]}")
    return upsample_nearest(valid.view(np.uint8), scale).astype(bool)


def evaluation_mask(scene: Any, shape: tuple[int, int], border_px: int) -> np.ndarray:
    """Bool ``shape``: the pixels scored at that resolution: all but ``border_px`` (at that resolution)
    on each side, and valid_mask.png where the scene has one (:func:`valid_mask_at`)."""
    mask = border_mask(shape, border_px)
    valid = valid_mask_at(scene, shape)
    if valid is not None:
        mask &= valid
    return mask


def metric_resolution(scene: Scene, metric: Metric, rules: ScoringRules = ScoringRules()) -> str | None:
    """The resolution ``metric`` is scored at on ``scene``, or None when it does not apply.

    General metrics ('scene'): the scene's rule. A 'highres' metric: high resolution when
    high-res scoring is allowed and the high-res gt and all its masks exist, else low resolution
    (recorded as such) when its low-res masks exist, else None. A 'lowres' metric: low resolution
    when its low-res masks exist, else None.
    """
    if metric.resolution == "scene":
        return rules.general_resolution(scene)
    needed = metric.required_masks

    def has_masks(res: str) -> bool:
        present = set(scene.mask_names(res)) if needed else set()
        return all(name in present for name in needed)

    if metric.resolution == HIGHRES and rules.allow_highres and scene.has_gt(HIGHRES) and has_masks(HIGHRES):
        return HIGHRES
    return LOWRES if has_masks(LOWRES) else None


def score_scene(scene: Scene, pred: np.ndarray, metrics: Sequence[Metric] = GENERAL_METRICS,
                rules: ScoringRules = ScoringRules(), source: str = "prediction", *,
                runtime_s: float | None = None) -> SceneScore:
    """Score ``pred`` (H, W) disparity on ``scene`` with the benchmark's masks and resolution rules.

    Runtime metrics (``Metric.is_runtime``) take ``runtime_s``, the runtime in s the method reports for
    this scene; they give no value (no record) when it reports none (None or NaN) or one that is not a
    positive number (noted), and are recorded at low resolution (the resolution of the map timed)."""
    h, w = scene.spatial_size
    pred, aligned_from = align_prediction(pred, (h, w), source, max_crop=rules.border_px)
    pred = pred.astype(np.float32, copy=False)
    notes = []
    if aligned_from is not None:
        notes.append(f"{aligned_from[1]}x{aligned_from[0]} prediction aligned to the centre of {w}x{h}")
    values: dict[str, float] = {}
    resolution: dict[str, str] = {}
    gts: dict[str, np.ndarray] = {}
    preds: dict[str, np.ndarray] = {}
    masks = {LOWRES: evaluation_mask(scene, (h, w), rules.border_px)}  # border and valid mask, per resolution
    nonfinite = nonfinite_count(pred, masks[LOWRES])
    for metric in metrics:
        if metric.is_runtime:
            continue
        res = metric_resolution(scene, metric, rules)
        if res is None:  # a mask file the metric needs is absent: it does not apply to this scene
            continue
        if res not in gts:
            gt = scene.gt_disparity(res)
            if gt is None:
                if res == HIGHRES:  # a high-res-only metric on a scene without high-res gt: skip it
                    continue
                raise DataError("no ground truth (gt_disp_lowres.pfm) to score against", scene.path)
            scale = gt.shape[0] // h
            gts[res] = gt
            preds[res] = pred if scale == 1 else upsample_nearest(pred, scale)
            if res not in masks:
                masks[res] = evaluation_mask(scene, gt.shape, rules.border_px * scale)
        gt, p = gts[res], preds[res]
        mask = masks[res]
        if metric.mask_name is not None:
            if metric.mask_name not in scene.mask_names(res):
                continue
            region = scene.mask(metric.mask_name, res)
            if region.shape != mask.shape:
                expected = f"{mask.shape[1]}x{mask.shape[0]}"
                raise DataError(f"mask is {region.shape[1]}x{region.shape[0]}, expected {expected}",
                                scene.path / f"{metric.mask_name}_{res}.png")
            mask = mask & region
        context = {"scene": scene, "resolution": res} if metric.needs_scene else {}
        values[metric.id] = metric(gt, p, mask, toolkit=rules.toolkit, **context)
        resolution[metric.id] = res
    timed = [m for m in metrics if m.is_runtime]
    for metric in timed:
        value = metric.score_runtime(runtime_s)
        if value is not None:
            values[metric.id], resolution[metric.id] = value, LOWRES
    if timed and runtime_s is not None and not np.isnan(runtime_s) and timed[0].score_runtime(runtime_s) is None:
        notes.append(f"runtime {runtime_s:g} s is not a positive number: no runtime record")
    return SceneScore(scene=scene.name, values=values, resolution=resolution, nonfinite_pixels=nonfinite,
                      aligned_from=aligned_from, notes=notes)
