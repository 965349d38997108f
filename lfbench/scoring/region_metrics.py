"""Region and stratified metrics of the HCI 4D Light Field Benchmark, as pure functions of arrays.

Disparity maps ``gt`` and ``pred`` are in px per view step, (H, W) float arrays of one shape;
``mask`` is a bool (H, W) of the pixels to score (None = all). Definitions follow the official
evaluation toolkit (docs/benchmark-rules.md, "Region metrics", "Stratified metrics"):

- bumpiness: 100 x mean over the mask of min(||Scharr Hessian of (pred - gt)||_F, 0.05);
- MAE: median angle (degrees) between the surface normals of the depth maps of gt and pred;
- fine fattening / thinning: % of pixels with gt - pred < -0.15 / > 0.15 px;
- backgammon fattening / thinning: % of pixels nearer to the foreground / background than half
  way between the ground truth and the foreground / background disparity of the same row;
- missed dots: % of dots (one size label inside one box) with BadPix(0.4) >= 50 %;
- discontinuities, stripes and dots background: BadPix(0.07) and MSE x100 on their masks.

Non-finite predictions, default (``toolkit=False``): a bad pixel for every percentage metric, the
clip value 0.05 for bumpiness and a 180 degree normal error for MAE; pixels whose ground truth
(or reference) is non-finite are not scored. ``toolkit=True`` reproduces the toolkit: percentage
metrics count NaN as good, bumpiness and MAE leave non-finite values out, a (box, size) pair
without pixels counts as a missed dot.

Each metric is also a :class:`~lfbench.scoring.base.Metric` (ids in :data:`REGION_METRICS` and
:data:`STRATIFIED_METRICS`; :func:`scene_metrics` says which belong to a scene), registered in
:data:`lfbench.scoring.metrics.METRICS` (look one up with :func:`lfbench.scoring.metrics.get_metric`).
Those that read further masks of their scene (missed dots, the pyramids' slanted surfaces) take them from
the scene's :class:`~lfbench.scoring.prepare.SceneReference` (read once per scene).
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

from lfbench.data.scene import Scene
from lfbench.scoring.base import NON_NEGATIVE, PERCENT, Metric
from lfbench.scoring.filters import correlate1d3, correlate3x3
from lfbench.scoring.general import BadPixels, check_maps, percent_of, squared_error
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.pixelwise import Mean, PixelMetric, Proportion, Sample, kept
from lfbench.scoring.prepare import SceneReference

__all__ = [
    "CameraParameters",
    "scharr_derivative",
    "bumpiness_map",
    "bumpiness_x100",
    "depth_normals",
    "angular_error_deg",
    "median_angular_error",
    "disparity_normals",
    "fine_fattening",
    "fine_thinning",
    "backgammon_fattening",
    "backgammon_thinning",
    "missed_dots",
    "DotLayout",
    "toolkit_depth",
    "REGION_METRICS",
    "STRATIFIED_METRICS",
    "scene_metrics",
]

BUMPINESS_CLIP = 0.05  # px per px^2 (Scharr response units), the toolkit's clip
FINE_THRESHOLD = 0.15  # px
DOT_THRESHOLD = 0.4  # px, BadPix threshold on a dot
DOT_MISSED_PERCENT = 50.0  # a dot with BadPix >= this is missed
DOT_MAX_LABEL = 8  # only size labels 1..8 (the biggest dots of each box) are scored
BACKGAMMON_FG_COLUMN = 14  # low-res column whose gt is the foreground disparity of each row (scaled)
BACKGAMMON_BG_FROM_RIGHT = 11  # column width - 11 holds the background disparity (not scaled, as the toolkit)

_SMOOTH = np.array([3.0, 10.0, 3.0]) / 16.0
_DIFF = np.array([-1.0, 0.0, 1.0])  # correlation: f[i + 1] - f[i - 1]


# --------------------------------------------------------------------------- shared helpers

_PERCENT = Proportion()  # the share of bad pixels, in %


def _bad_sample(bad: np.ndarray, reference_finite: np.ndarray, px: PixelErrors, toolkit: bool) -> Sample:
    """Which pixels of ``px`` are bad, at the scored ones. ``bad`` was computed with NaN comparisons False;
    the reference (gt or a value derived from it) must be finite (``reference_finite``) for a pixel to be scored."""
    if toolkit:  # the toolkit: every pixel is scored, NaN comparisons are good
        return Sample(bad)
    if not px.pred_all_finite:
        bad = bad | ~px.pred_finite
    return kept(bad, reference_finite)


_SCHARR_H = np.array([[3.0, 10.0, 3.0], [0.0, 0.0, 0.0], [-3.0, -10.0, -3.0]]) / 16.0  # scikit-image's HSCHARR


def scharr_derivative(image: np.ndarray, axis: int, mode: str = "reflect", zero_border: bool = True) -> np.ndarray:
    """Scharr derivative of a (H, W) array along ``axis`` (0 = rows, 1 = columns), float64.

    Kernel: difference [-1, 0, 1] (f[i+1] - f[i-1], i.e. twice the central difference) along
    ``axis`` times the smoothing [3, 10, 3] / 16 across it: scikit-image's ``scharr_h`` (axis 0)
    and ``scharr_v`` (axis 1), computed as it did (``scipy.ndimage.convolve`` with the 3x3 kernel,
    which skips the kernel's zero weights: an infinite value gives +-inf or NaN only where it has
    a non-zero weight, never inf * 0). ``zero_border`` sets the outermost 1 px ring to 0, as the
    scikit-image of the toolkit's era did (only pixels within 2 px of the edge are affected). The convolution
    is scipy's, computed in numpy (lfbench.scoring.filters: importing scipy.ndimage costs more than scoring).
    """
    kernel = _SCHARR_H if axis == 0 else _SCHARR_H.T
    out = correlate3x3(image, kernel[::-1, ::-1], mode=mode)  # a convolution: the flipped kernel correlated
    if zero_border:
        out[0, :] = out[-1, :] = 0.0
        out[:, 0] = out[:, -1] = 0.0
    return out


def _scharr_separable(image: np.ndarray, axis: int) -> np.ndarray:
    """Scharr derivative with periodic borders as two 1-D passes (every weight multiplies, so a
    non-finite value spreads NaN over its 3x3 neighbourhood, like the toolkit's
    ``scipy.signal.convolve2d`` used for surface normals); scipy.ndimage.correlate1d's passes
    (lfbench.scoring.filters)."""
    out = correlate1d3(image, _DIFF, axis=axis, mode="wrap")
    return correlate1d3(out, _SMOOTH, axis=1 - axis, mode="wrap")


def _hessian_norm(diff: np.ndarray) -> np.ndarray:
    """Frobenius norm of the Scharr Hessian (d/dx d/dx, d/dy d/dx, d/dy d/dy, d/dx d/dy) of a (H, W) map.

    On a smooth map it is 4 x the Frobenius norm of the true Hessian (each Scharr pass doubles)."""
    dx = scharr_derivative(diff, axis=1)
    dy = scharr_derivative(diff, axis=0)
    parts = (scharr_derivative(dx, axis=1), scharr_derivative(dx, axis=0),
             scharr_derivative(dy, axis=0), scharr_derivative(dy, axis=1))
    return np.sqrt(sum(np.square(p) for p in parts))


# --------------------------------------------------------------------------- bumpiness

def bumpiness_map(gt: np.ndarray, pred: np.ndarray, clip: float = BUMPINESS_CLIP) -> np.ndarray:
    """Per-pixel bumpiness (H, W) float64: min(||Scharr Hessian of (pred - gt)||_F, clip).

    The difference is taken in the inputs' precision (float32 for PFM data), then filtered in
    float64 with reflecting borders; NaN where a non-finite value lies within 2 px."""
    gt, pred, _ = check_maps(gt, pred, None)
    with np.errstate(invalid="ignore"):
        diff = (pred - gt).astype(np.float64)
        return np.clip(_hessian_norm(diff), 0.0, clip)


def bumpiness_x100(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *, clip: float = BUMPINESS_CLIP,
                   toolkit: bool = False) -> float:
    """Bumpiness: 100 x the mean clipped Scharr-Hessian norm of (pred - gt) over the mask.

    Units: 100 x px / px^2 (Scharr response); 0 for any prediction that differs from gt by a
    constant or a plane; 100 * clip (5) for a very rough one."""
    gt, pred, mask = check_maps(gt, pred, mask)
    return _bump_mean(bumpiness_map(gt, pred, clip), mask, None if toolkit else _gt_bump_ok(gt), clip, toolkit)


def _gt_bump_ok(gt: np.ndarray) -> np.ndarray | None:
    """Bool (H, W), the pixels whose bumpiness no non-finite ground truth reaches (the Hessian's support); None when
    the ground truth is finite everywhere (every pixel: the Hessian of zeros is zero)."""
    finite = np.isfinite(gt)
    if finite.all():
        return None
    with np.errstate(invalid="ignore"):
        return np.isfinite(_hessian_norm(np.where(finite, 0.0, np.nan)))


def _bump_mean(bump: np.ndarray, mask: np.ndarray, gt_ok: np.ndarray | None, clip: float, toolkit: bool) -> float:
    """:func:`bumpiness_x100` of the bumpiness map ``bump`` (not modified) over ``mask``; ``gt_ok``: :func:`_gt_bump_ok`
    (unused with ``toolkit``)."""
    if toolkit:
        scored = mask & np.isfinite(bump)
    else:  # non-finite from the prediction: the clip value; from the ground truth: not scored
        scored = mask if gt_ok is None else mask & gt_ok
        bump = np.where(np.isfinite(bump), bump, clip)
    n = int(np.count_nonzero(scored))
    return float("nan") if n == 0 else 100.0 * float(np.sum(bump[scored])) / float(n)


# --------------------------------------------------------------------------- surface normals

def depth_normals(depth: np.ndarray, focal_length_mm: float, sensor_size_mm: float) -> np.ndarray:
    """Unit surface normals (H, W, 3) float64 of a depth map (H, W) (any length unit).

    Camera coordinates as the toolkit builds them: X = 0.5 * col / (W - 1) * s / f * Z,
    Y = 0.5 * row / (H - 1) * s / f * Z (s sensor size, f focal length, both mm; note the
    toolkit's factor 0.5 and origin at the top-left pixel, kept so that angles match its
    numbers), Z = depth. Tangents: derivatives along rows and columns with the Scharr kernel
    ([3, 10, 3] smoothing, periodic borders); normal = row tangent x column tangent, normalised,
    pointing towards the camera (negative Z). The toolkit's normal maps differ from these by a
    fixed relabelling of the axes (an orthogonal map), which leaves every angle unchanged.
    """
    z = np.asarray(depth, dtype=np.float64)
    if z.ndim != 2 or min(z.shape) < 3:
        raise ValueError(f"depth must be a (H, W) map of at least 3x3, got {z.shape}")
    h, w = z.shape
    k = 0.5 * sensor_size_mm / focal_length_mm
    x = k * (np.arange(w) / (w - 1.0))[None, :] * z
    y = k * (np.arange(h) / (h - 1.0))[:, None] * z
    a0, a1, a2 = (_scharr_separable(c, axis=0) for c in (x, y, z))  # the row tangent
    b0, b1, b2 = (_scharr_separable(c, axis=1) for c in (x, y, z))  # the column tangent
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        # np.cross(row, col) and its np.linalg.norm, component by component in numpy's own operations and
        # order (a1 b2 - a2 b1, ...; sqrt((n0^2 + n1^2) + n2^2)): the same bits without the stacked copies
        n0, n1, n2 = a1 * b2, a2 * b0, a0 * b1
        n0 -= a2 * b1
        n1 -= a0 * b2
        n2 -= a1 * b0
        norm = n0 * n0
        norm += n1 * n1
        norm += n2 * n2
        np.sqrt(norm, out=norm)
        normal = np.empty((h, w, 3))
        for axis, component in enumerate((n0, n1, n2)):
            np.divide(component, norm, out=normal[..., axis])
    return normal


class CameraParameters(Protocol):
    """What the surface-normal metrics read of a scene's camera (``Scene.params``; HCI's parameters.cfg,
    lfbench.data.hci.SceneParameters, is one): lengths in mm and m as named, resolution in px."""

    baseline_mm: float
    focal_length_mm: float
    sensor_size_mm: float
    focus_distance_m: float
    image_resolution_x_px: int
    image_resolution_y_px: int


def toolkit_depth(disparity: np.ndarray, params: CameraParameters) -> np.ndarray:
    """Depth (m) of a disparity map (px per view step) exactly as the toolkit's ``disp2depth``: float32
    arithmetic in its order, 1 / ((1000 s) d / q + 1 / F) with q = b f max(W, H) (b, f, s in mm,
    F in m); the same formula as HCI's ``SceneParameters.disparity_to_depth``, which works in float64."""
    q = np.float32(params.baseline_mm * params.focal_length_mm
                   * max(params.image_resolution_x_px, params.image_resolution_y_px))
    d = np.asarray(disparity, dtype=np.float32)
    return np.float32(1.0) / (np.float32(1000.0 * params.sensor_size_mm) * d / q
                              + np.float32(1.0 / params.focus_distance_m))


def angular_error_deg(normals_a: np.ndarray, normals_b: np.ndarray) -> np.ndarray:
    """Angle in degrees (H, W) between two unit-normal maps (H, W, 3); NaN where either is NaN."""
    with np.errstate(invalid="ignore"):
        # np.sum(a * b, axis=-1) as numpy adds its three products, (p0 + p1) + p2, one component at a time: the
        # same bits without the reduction over a short axis
        cos = normals_a[..., 0] * normals_b[..., 0]
        cos += normals_a[..., 1] * normals_b[..., 1]
        cos += normals_a[..., 2] * normals_b[..., 2]
        cos = np.clip(cos, -1.0, 1.0, out=cos)
    return np.degrees(np.arccos(cos))


def median_angular_error(gt: np.ndarray, pred: np.ndarray, params: CameraParameters, mask: np.ndarray | None = None,
                         *, toolkit: bool = False) -> float:
    """MAE: median angle (degrees) between the surface normals of gt and pred over the mask.

    Disparities are converted to depth as the toolkit does (:func:`toolkit_depth`, float32), normals
    from :func:`depth_normals` in float64."""
    gt, pred, mask = check_maps(gt, pred, mask)
    n_gt = disparity_normals(gt, params)
    return _median_angle(angular_error_deg(n_gt, disparity_normals(pred, params)), n_gt, pred, mask, toolkit)


def disparity_normals(disparity: np.ndarray, params: CameraParameters) -> np.ndarray:
    """Unit normals (H, W, 3) of a disparity map's surface: :func:`depth_normals` of :func:`toolkit_depth`."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return depth_normals(toolkit_depth(disparity, params), params.focal_length_mm, params.sensor_size_mm)


def _median_angle(angle: np.ndarray, n_gt: np.ndarray, pred: np.ndarray, mask: np.ndarray, toolkit: bool) -> float:
    """The median of the angles (H, W) over the mask, under the non-finite rule of :func:`median_angular_error`."""
    if toolkit:
        scored = mask & np.isfinite(pred) & np.isfinite(angle)
    else:  # a normal the prediction cannot give is the worst angle; gt without a normal is not scored
        finite = np.isfinite(n_gt)
        scored = mask & finite[..., 0] & finite[..., 1] & finite[..., 2]  # all(axis=-1), without the short reduction
        angle = np.where(np.isfinite(angle), angle, 180.0)
    values = angle[scored]
    return float("nan") if values.size == 0 else float(np.median(values))


# --------------------------------------------------------------------------- fattening / thinning

def fine_fattening(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None,
                   threshold: float = FINE_THRESHOLD, *, toolkit: bool = False) -> float:
    """Fine fattening: % of scored pixels with gt - pred < -threshold (px), i.e. the prediction
    is nearer than the ground truth (scored on mask_fine_surrounding)."""
    return fine_fattening_of(PixelErrors.of_maps(gt, pred, mask), threshold, toolkit=toolkit)


def fine_fattening_of(px: PixelErrors, threshold: float = FINE_THRESHOLD, *, toolkit: bool = False) -> float:
    """:func:`fine_fattening` of the pixels ``px`` holds (lfbench.scoring.pixels)."""
    return _PERCENT.reduce(_fattened(px, threshold, toolkit=toolkit).values)


def _fattened(px: PixelErrors, threshold: float = FINE_THRESHOLD, *, toolkit: bool = False) -> Sample:
    """Fine fattening's sample: whether each scored pixel of ``px`` has gt - pred < -threshold (px)."""
    with np.errstate(invalid="ignore", over="ignore"):
        bad = (px.gt - px.pred) < -threshold
    return _bad_sample(bad, px.gt_finite, px, toolkit)


def fine_thinning(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None,
                  threshold: float = FINE_THRESHOLD, *, toolkit: bool = False) -> float:
    """Fine thinning: % of scored pixels with gt - pred > threshold (px), i.e. the prediction is
    farther than the ground truth (scored on mask_fine)."""
    return fine_thinning_of(PixelErrors.of_maps(gt, pred, mask), threshold, toolkit=toolkit)


def fine_thinning_of(px: PixelErrors, threshold: float = FINE_THRESHOLD, *, toolkit: bool = False) -> float:
    """:func:`fine_thinning` of the pixels ``px`` holds."""
    return _PERCENT.reduce(_thinned(px, threshold, toolkit=toolkit).values)


def _thinned(px: PixelErrors, threshold: float = FINE_THRESHOLD, *, toolkit: bool = False) -> Sample:
    """Fine thinning's sample: whether each scored pixel of ``px`` has gt - pred > threshold (px)."""
    with np.errstate(invalid="ignore", over="ignore"):
        bad = (px.gt - px.pred) > threshold
    return _bad_sample(bad, px.gt_finite, px, toolkit)


def _halfway_of(px: PixelErrors, column: int) -> np.ndarray:
    """Float64 at each pixel of ``px``: half way between its gt and the gt at ``column`` of its row (the
    foreground or background extrapolated along the row), in float64 as the toolkit computes it; kept by
    the pixel set (it does not depend on the prediction)."""
    pixels = px.pixels

    def compute() -> np.ndarray:
        extrapolated = pixels.per_row(pixels.gt_map[:, column].astype(px.gt.dtype).astype(np.float64))
        extrapolated += pixels.gt.astype(px.gt.dtype)
        extrapolated *= 0.5
        return extrapolated

    return pixels.memo(("halfway", column, px.gt.dtype.str), compute)


def _backgammon_sample(px: PixelErrors, column: int, nearer_foreground: bool, toolkit: bool) -> Sample:
    half = _halfway_of(px, column)
    with np.errstate(invalid="ignore"):
        bad = px.pred > half if nearer_foreground else px.pred < half
    finite = px.pixels.memo(("halfway finite", column, px.gt.dtype.str), lambda: np.isfinite(half))  # per pixel set
    return _bad_sample(bad, finite, px, toolkit)


def _backgammon_of(px: PixelErrors, column: int, nearer_foreground: bool, toolkit: bool) -> float:
    return _PERCENT.reduce(_backgammon_sample(px, column, nearer_foreground, toolkit).values)


def _bg_fattened(px: PixelErrors, *, toolkit: bool = False) -> Sample:
    """Backgammon fattening's sample; the foreground column scales with the resolution of ``px``'s pixels."""
    scale = max(1, px.pixels.shape[1] // px.pixels.low_width)
    return _backgammon_sample(px, int(BACKGAMMON_FG_COLUMN * scale), True, toolkit)


def _bg_thinned(px: PixelErrors, *, toolkit: bool = False) -> Sample:
    """Backgammon thinning's sample; the background column counts from the right edge, unscaled (as the toolkit)."""
    return _backgammon_sample(px, px.pixels.shape[1] - BACKGAMMON_BG_FROM_RIGHT, False, toolkit)


def backgammon_fattening(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *, fg_column: int,
                         toolkit: bool = False) -> float:
    """Backgammon fattening: % of scored pixels with pred > (gt + fg) / 2, where fg (per row) is
    the gt at column ``fg_column`` (the foreground extrapolated along each row): the prediction
    is nearer to the foreground than to the true (background) disparity."""
    return _backgammon_of(PixelErrors.of_maps(gt, pred, mask), fg_column, True, toolkit)


def backgammon_thinning(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None, *, bg_column: int,
                        toolkit: bool = False) -> float:
    """Backgammon thinning: % of scored pixels with pred < (gt + bg) / 2, where bg (per row) is
    the gt at column ``bg_column`` (the background extrapolated along each row): the prediction
    is nearer to the background than to the true (foreground) disparity."""
    return _backgammon_of(PixelErrors.of_maps(gt, pred, mask), bg_column, False, toolkit)


# --------------------------------------------------------------------------- dots

def missed_dots(gt: np.ndarray, pred: np.ndarray, boxes: np.ndarray, dots_by_size: np.ndarray, *,
                threshold: float = DOT_THRESHOLD, missed_percent: float = DOT_MISSED_PERCENT,
                max_label: int = DOT_MAX_LABEL, toolkit: bool = False, valid: np.ndarray | None = None) -> float:
    """Missed dots: % of dots whose BadPix(threshold) is >= ``missed_percent``.

    ``boxes`` (H, W) int labels the cells of the dots scene (0 = none); ``dots_by_size`` (H, W)
    int labels each dot by its size rank (0 = background). A dot is the set of pixels with one
    label 1..n inside one box, n = the number of distinct labels of 1..max_label present (the
    toolkit's rule: with a label missing, 1..n still includes it and leaves out the highest). As
    in the toolkit the border mask does not apply; every pixel of a dot counts. Default: pixels
    with non-finite gt are left out, non-finite predictions are bad, (box, label) pairs without
    pixels are not dots. ``toolkit=True``: NaN is good and an empty pair counts as a missed dot
    (the toolkit's NaN < 50 is False). ``valid`` (H, W) bool, the scene's valid mask (lfbench's, not the
    toolkit's): pixels outside it are not scored, and a dot with no valid pixel is no dot, in both modes.
    """
    gt, pred, _ = check_maps(gt, pred, None)
    dots = DotLayout.of(boxes, dots_by_size, valid, shape=gt.shape, max_label=max_label)
    return dots.missed(gt.ravel()[dots.index], pred.ravel()[dots.index], threshold=threshold,
                       missed_percent=missed_percent, toolkit=toolkit)


class DotLayout:
    """The dots of :func:`missed_dots` on one scene, whatever the prediction: ``index``, the flat indices of
    the pixels of every dot (inside ``valid``); ``key``, each one's dot ((box, label) pair) number;
    ``n_pairs``, the number of (box, label) pairs; ``dropped``, pairs whose pixels all lie outside ``valid``."""

    def __init__(self, index: np.ndarray, key: np.ndarray, n_pairs: int, dropped: int) -> None:
        self.index, self.key, self.n_pairs, self.dropped = index, key, n_pairs, dropped

    @classmethod
    def of(cls, boxes: np.ndarray, dots_by_size: np.ndarray, valid: np.ndarray | None, *, shape: tuple[int, ...],
           max_label: int = DOT_MAX_LABEL) -> DotLayout:
        """The layout of the label masks ``boxes`` and ``dots_by_size`` ((H, W) int, the ground truth's
        ``shape``) and the valid mask (bool (H, W) or None); ValueError for other shapes or negative labels."""
        boxes = np.asarray(boxes)
        dots_by_size = np.asarray(dots_by_size)
        if boxes.shape != tuple(shape) or dots_by_size.shape != tuple(shape):
            raise ValueError(f"boxes {boxes.shape} and dots {dots_by_size.shape} must match gt {tuple(shape)}")
        if boxes.size and (boxes.min() < 0 or dots_by_size.min() < 0):
            raise ValueError("box and dot labels must be non-negative integers")
        box_lut = _label_lut(boxes, 1, None)  # label value -> index of the box, -1 for none
        dot_lut = _first_labels(dots_by_size, max_label)
        n_boxes, n_labels = int(box_lut.max()) + 1, int(dot_lut.max()) + 1
        n_pairs = n_boxes * n_labels
        if n_pairs == 0:
            return cls(np.zeros(0, np.intp), np.zeros(0, np.intp), 0, 0)
        # only pixels with a dot label 1..n can lie in a dot: the rest of the work is on them alone
        candidates = np.flatnonzero((dots_by_size > 0).ravel() & (dots_by_size <= n_labels).ravel())
        box_idx = box_lut[boxes.ravel()[candidates]]
        dot_idx = dot_lut[dots_by_size.ravel()[candidates]]
        in_dot = (box_idx >= 0) & (dot_idx >= 0)
        key = box_idx * n_labels + dot_idx
        dropped = 0
        if valid is not None:
            valid = np.asarray(valid, dtype=bool)
            if valid.shape != tuple(shape):
                raise ValueError(f"valid mask {valid.shape} must match gt {tuple(shape)}")
            had_pixels = np.bincount(key[in_dot], minlength=n_pairs) > 0
            in_dot &= valid.ravel()[candidates]
            dropped = int(np.count_nonzero(had_pixels & (np.bincount(key[in_dot], minlength=n_pairs) == 0)))
        return cls(candidates[in_dot], key[in_dot], n_pairs, dropped)

    def missed(self, gt: np.ndarray, pred: np.ndarray, *, threshold: float = DOT_THRESHOLD,
               missed_percent: float = DOT_MISSED_PERCENT, toolkit: bool = False) -> float:
        """:func:`missed_dots` of the ground truth and prediction at :attr:`index` (1-D, one precision)."""
        if self.n_pairs == 0:
            return float("nan")
        with np.errstate(invalid="ignore", over="ignore"):
            bad = np.abs(gt - pred) > threshold
        if toolkit:
            key = self.key
        else:
            scored = np.isfinite(gt)
            bad = (bad | ~np.isfinite(pred))[scored]
            key = self.key[scored]
        n = np.bincount(key, minlength=self.n_pairs)
        n_bad = np.bincount(key[bad], minlength=self.n_pairs)
        with np.errstate(invalid="ignore", divide="ignore"):
            dot_bad_pix = 100.0 * n_bad / n
        missed = (n > 0) & (dot_bad_pix >= missed_percent)
        if toolkit:
            return percent_of(self.n_pairs - self.dropped, int(np.count_nonzero(missed | (n == 0))) - self.dropped)
        return percent_of(int(np.count_nonzero(n > 0)), int(np.count_nonzero(missed)))


def _first_labels(labels: np.ndarray, highest: int) -> np.ndarray:
    """The toolkit's dot labels: with n = the number of distinct labels in 1..highest present, the
    labels 1..n (even when one of them is absent and a higher one present). Lookup table: label
    value -> its index 0..n-1, else -1."""
    present = _present(labels)
    n = int(np.count_nonzero(present[1:highest + 1]))
    lut = np.full(max(present.size, n + 1), -1, dtype=np.intp)
    lut[1:n + 1] = np.arange(n)
    return lut


#: label values below this are found by one OR of 1 << label (a pass in 32-bit words, ~15 ms per 26 M uint8)
#: rather than counted (a copy in the index type, ~4 ms per M)
_FEW_LABELS = 32


def _present(labels: np.ndarray, chunk: int = 1 << 20) -> np.ndarray:
    """Bool by label value 0..max: whether it occurs in ``labels`` (non-negative integers), a chunk at a time, so
    that no copy of a high-resolution mask in the index type is made. Few values (the masks' labels: 0..16): the
    bits 1 << label ORed together; else counted."""
    flat = labels.ravel()
    present = np.zeros(int(flat.max()) + 1 if flat.size else 1, bool)
    if present.size <= _FEW_LABELS:
        word = np.uint32(0)
        for start in range(0, flat.size, chunk):  # labels 0..31 (max checked): exact in uint32, whatever their type
            bits = np.left_shift(np.uint32(1), flat[start:start + chunk], dtype=np.uint32, casting="unsafe")
            word |= np.bitwise_or.reduce(bits)
        present[:] = [bool((int(word) >> value) & 1) for value in range(present.size)]
        return present
    for start in range(0, flat.size, chunk):
        counts = np.bincount(flat[start:start + chunk])
        present[:counts.size] |= counts > 0
    return present


def _label_lut(labels: np.ndarray, lowest: int, highest: int | None) -> np.ndarray:
    """A lookup table: label value -> rank among the values present in [lowest, highest], else -1."""
    present = _present(labels)
    present[:lowest] = False
    if highest is not None:
        present[highest + 1:] = False
    return np.where(present, np.cumsum(present) - 1, -1)


# --------------------------------------------------------------------------- metric descriptors
# Metrics with needs_scene get scene= (the scene's SceneReference, or a Scene) and resolution= from
# score_scene (lfbench.scoring.score).

def _bump_fn(gt, pred, mask=None, *, toolkit=False, scene: Scene | SceneReference | None = None,
             resolution: str | None = None):
    if scene is None:
        return bumpiness_x100(gt, pred, mask, toolkit=toolkit)
    reference = SceneReference.of(scene)
    if gt is not reference.gt(resolution) or np.asarray(pred).flags.writeable:
        return bumpiness_x100(gt, pred, mask, toolkit=toolkit)
    # the scene's own gt and a prepared (read-only) prediction: the map once per prediction (the metrics of planes,
    # smooth surfaces and slanted surfaces share it), which ground truth pixels it can score once per scene
    gt, pred, mask = check_maps(gt, pred, mask)
    bump = reference.per_prediction(("bump_map", resolution), pred, lambda: bumpiness_map(gt, pred))
    gt_ok = None if toolkit else reference.memo(("bump_gt_ok", resolution, gt.dtype.str), lambda: _gt_bump_ok(gt))
    return _bump_mean(bump, mask, gt_ok, BUMPINESS_CLIP, toolkit)


def _mae_fn(gt, pred, mask=None, *, toolkit=False, scene: Scene | SceneReference, resolution: str):
    reference = SceneReference.of(scene)
    if gt is not reference.gt(resolution) or np.asarray(pred).flags.writeable:
        return median_angular_error(gt, pred, reference.params, mask, toolkit=toolkit)
    # the scene's own gt and a prepared (read-only) prediction: gt normals kept for the scene, the angles for
    # the prediction (MAE of planes and of smooth surfaces share them)
    gt, pred, mask = check_maps(gt, pred, mask)
    n_gt = reference.memo(("gt_normals", resolution, gt.dtype.str), lambda: disparity_normals(gt, reference.params))
    angle = reference.per_prediction(("mae_angle", resolution), pred,
                                     lambda: angular_error_deg(n_gt, disparity_normals(pred, reference.params)))
    return _median_angle(angle, n_gt, pred, mask, toolkit)


def _missed_dots_fn(gt, pred, mask=None, *, toolkit=False, scene: Scene | SceneReference, resolution: str):
    reference = SceneReference.of(scene)
    check_maps(gt, pred, None)  # one shape

    def layout() -> tuple[DotLayout, np.ndarray]:
        boxes = reference.label_mask("mask_boxes", resolution, gt.shape)
        dots = DotLayout.of(boxes, reference.label_mask("mask_dots_by_size", resolution, gt.shape),
                            reference.valid_mask(resolution), shape=gt.shape)
        return dots, gt.ravel()[dots.index]

    if gt is reference.gt(resolution):  # the scene's own: its dots and their gt kept for every prediction
        dots, gt_dots = reference.memo(("missed_dots", resolution), layout)
    else:
        dots, gt_dots = layout()
    gt_dots, pred_dots = check_maps(gt_dots, np.asarray(pred).ravel()[dots.index], None)[:2]
    return dots.missed(gt_dots, pred_dots, toolkit=toolkit)


_SLANTED_MASKS = ("mask_sphere_in", "mask_sphere_out", "mask_pyramids")


def _slanted_fn(gt, pred, mask=None, *, toolkit=False, scene: Scene | SceneReference, resolution: str):
    reference = SceneReference.of(scene)
    union = np.zeros(gt.shape, dtype=bool)
    for name in _SLANTED_MASKS:
        union |= reference.mask(name, resolution, gt.shape)
    return _bump_fn(gt, pred, union if mask is None else mask & union, toolkit=toolkit, scene=scene,
                    resolution=resolution)


_BUMP_UNIT = "px/px^2 x 100"
#: The values a region / stratified metric can take, by its unit: percentages, the bumpiness (a mean of
#: norms clipped at 0.05, x 100), angles between normals, and mean squared errors.
_RANGE_OF_UNIT = {"%": PERCENT, "% of dots": PERCENT, _BUMP_UNIT: (0.0, 100 * BUMPINESS_CLIP), "deg": (0.0, 180.0),
                  "px^2 x 100": NON_NEGATIVE}


class Plot(NamedTuple):
    """How a region metric's maps are drawn: colour range [vmin, vmax] and colour map."""

    vmin: float
    vmax: float
    cmap: str


_PERCENT_PLOT = Plot(0, 1, "RdYlGn_r")
_BUMP_PLOT = Plot(0, 5, "viridis")
_MAE_PLOT = Plot(0, 80, "RdYlGn_r")


def _region(*, unit: str, plot: Plot, category: str = "region", **fields) -> Metric:
    """A region (or stratified) metric from its named fields (those of :class:`Metric`); its value range
    follows from its unit."""
    return Metric(unit=unit, vmin=plot.vmin, vmax=plot.vmax, cmap=plot.cmap, category=category,
                  value_range=_RANGE_OF_UNIT[unit], **fields)


def _strat(**fields) -> Metric:
    return _region(category="stratified", **fields)


_BUMP_DESC = ("100 x the mean of min(||Scharr Hessian of (pred - gt)||_F, 0.05) over {}: 0 = as smooth as the ground "
              "truth (a constant or planar offset is not penalised).")
_BADPIX_007 = PixelMetric(BadPixels(0.07), _PERCENT)

REGION_METRICS: tuple[Metric, ...] = (
    _region(id="discontinuities", name="Discontinuities", toolkit_id="discontinuities_0070",
            description="BadPix(0.07): % of pixels at depth discontinuities (mask_discontinuities) with "
                        "|gt - pred| > 0.07 px.",
            unit="%", pixelwise=_BADPIX_007, mask_name="mask_discontinuities", resolution="highres",
            plot=_PERCENT_PLOT),
    _region(id="bumpiness_planes", name="Bumpiness Planes", toolkit_id="bumpiness_planes_100_0050",
            description=_BUMP_DESC.format("planar regions (mask_planes)"),
            unit=_BUMP_UNIT, fn=_bump_fn, mask_name="mask_planes", resolution="lowres", plot=_BUMP_PLOT,
            needs_scene=True),
    _region(id="bumpiness_contin_surfaces", name="Bumpiness Contin. Surfaces",
            toolkit_id="bumpiness_contin_surfaces_100_0050",
            description=_BUMP_DESC.format("smooth non-planar regions (mask_smooth_surfaces)"),
            unit=_BUMP_UNIT, fn=_bump_fn, mask_name="mask_smooth_surfaces", resolution="lowres",
            plot=_BUMP_PLOT, needs_scene=True),
    _region(id="mae_planes", name="MAE Planes", toolkit_id="mae_planes",
            description="Median angle (degrees) between surface normals of gt and pred depth on planar regions "
                        "(mask_planes).",
            unit="deg", fn=_mae_fn, mask_name="mask_planes", resolution="lowres", plot=_MAE_PLOT, needs_scene=True),
    _region(id="mae_contin_surfaces", name="MAE Contin. Surfaces", toolkit_id="mae_contin_surfaces",
            description="Median angle (degrees) between surface normals of gt and pred depth on smooth non-planar "
                        "regions (mask_smooth_surfaces).",
            unit="deg", fn=_mae_fn, mask_name="mask_smooth_surfaces", resolution="lowres", plot=_MAE_PLOT,
            needs_scene=True),
    _region(id="fine_fattening", name="Fine Fattening", toolkit_id="fine_fattening_0150",
            description="% of pixels around fine structures (mask_fine_surrounding) with gt - pred < -0.15 px.",
            unit="%", pixelwise=PixelMetric(_fattened, _PERCENT, of_errors=False), mask_name="mask_fine_surrounding",
            resolution="highres", plot=_PERCENT_PLOT),
    _region(id="fine_thinning", name="Fine Thinning", toolkit_id="fine_thinning_0150",
            description="% of pixels on fine structures (mask_fine) with gt - pred > 0.15 px.",
            unit="%", pixelwise=PixelMetric(_thinned, _PERCENT, of_errors=False), mask_name="mask_fine",
            resolution="highres", plot=_PERCENT_PLOT),
)


def _stripes(*, id: str, name: str, toolkit_id: str, region: str, mask_name: str) -> Metric:
    """A stripes metric: BadPix(0.07) on ``region`` (in words) of the mask ``mask_name``."""
    return _strat(id=id, name=f"Stripes: {name}", toolkit_id=toolkit_id,
                  description=f"BadPix(0.07) on the {region} ({mask_name}).", unit="%", pixelwise=_BADPIX_007,
                  mask_name=mask_name, resolution="highres", plot=_PERCENT_PLOT)


# The benchmark's rule data: which stratified metrics belong to which stratified scene.
STRATIFIED_METRICS: dict[str, tuple[Metric, ...]] = {
    "backgammon": (
        _strat(id="backgammon_fattening", name="Backgammon: Fattening", toolkit_id="backgammon_fattening_0070",
               description="% of background pixels between the foreground bars (mask_foreground_fattening) whose "
                           "prediction is nearer to the foreground than half way from the ground truth.",
               unit="%", pixelwise=PixelMetric(_bg_fattened, _PERCENT, of_errors=False),
               mask_name="mask_foreground_fattening", resolution="highres", plot=_PERCENT_PLOT, needs_scene=True),
        _strat(id="backgammon_thinning", name="Backgammon: Thinning", toolkit_id="backgammon_thinning_0070",
               description="% of pixels on the foreground bars (mask_foreground_thinning) whose prediction is nearer "
                           "to the background than half way from the ground truth.",
               unit="%", pixelwise=PixelMetric(_bg_thinned, _PERCENT, of_errors=False),
               mask_name="mask_foreground_thinning", resolution="highres", plot=_PERCENT_PLOT, needs_scene=True),
    ),
    "dots": (
        _strat(id="dots_background_mse", name="Dots: Background MSE", toolkit_id="background_mse_100",
               description="Mean squared disparity error (px^2) x 100 on the noisy background (mask_background).",
               unit="px^2 x 100", pixelwise=PixelMetric(squared_error, Mean()), mask_name="mask_background",
               resolution="highres", plot=Plot(-0.2, 0.2, "seismic")),
        _strat(id="missed_dots", name="Dots: Missed Dots", toolkit_id="missed_dots_50_0400",
               description="% of dots (size labels 1-8 of mask_dots_by_size in each cell of mask_boxes) with "
                           "BadPix(0.4) >= 50%.",
               unit="% of dots", fn=_missed_dots_fn, resolution="highres", plot=_PERCENT_PLOT,
               extra_masks=("mask_boxes", "mask_dots_by_size"), needs_scene=True),
    ),
    "pyramids": (
        _strat(id="pyramids_bumpiness_slanted", name="Pyramids: Bump. Slanted", toolkit_id="bumpiness_slanted_100_0050",
               description=_BUMP_DESC.format("the slanted surfaces (mask_sphere_in | mask_sphere_out | mask_pyramids)"),
               unit=_BUMP_UNIT, fn=_slanted_fn, resolution="lowres", plot=_BUMP_PLOT, extra_masks=_SLANTED_MASKS,
               needs_scene=True),
        _strat(id="pyramids_bumpiness_parallel", name="Pyramids: Bump. Parallel",
               toolkit_id="bumpiness_parallel_100_0050",
               description=_BUMP_DESC.format("the fronto-parallel plane (mask_plane)"),
               unit=_BUMP_UNIT, fn=_bump_fn, mask_name="mask_plane", resolution="lowres", plot=_BUMP_PLOT,
               needs_scene=True),
    ),
    "stripes": (
        _stripes(id="stripes_low_texture", name="Low Texture", toolkit_id="low_texture_0070",
                 region="low-texture region", mask_name="mask_low_texture"),
        _stripes(id="stripes_dark", name="Dark Stripes", toolkit_id="dark_stripes_0070",
                 region="high-contrast (dark) stripes", mask_name="mask_high_contrast"),
        _stripes(id="stripes_bright", name="Bright Stripes", toolkit_id="bright_stripes_0070",
                 region="low-contrast (bright) stripes", mask_name="mask_low_contrast"),
    ),
}


def scene_metrics(scene: Scene) -> tuple[Metric, ...]:
    """The region or stratified metrics defined for a scene, whether or not its masks exist:
    a stratified scene's own metrics, the region metrics for every other (photorealistic) scene."""
    return STRATIFIED_METRICS.get(scene.name, REGION_METRICS)
