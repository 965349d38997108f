"""Figures (matplotlib, Agg backend, PNG): per-scene overviews and BadPix-series curves.

Conventions of the benchmark's toolkit (docs/benchmark-rules.md, Outputs):

- disparity maps (px per view step) in viridis over 0.9 * [disp_min, disp_max] of parameters.cfg,
  or over the ground truth's range when the cfg has none;
- BadPix maps: bad pixels (|gt - pred| > t, or a non-finite prediction) pure red, good pixels light
  grey (a faint copy of the centre view), pixels outside the evaluation mask dark grey;
- signed error maps gt - pred (px) in a diverging colormap over +-0.2, outside the mask grey,
  non-finite predictions black;
- BadPix-series curves: BadPix(t) in % for t = 0 .. 0.1 px, per scene and averaged over scenes.

Every panel is first computed as an RGB array by a pure function (``badpix_image``,
``signed_error_image``, ...), so tests can check exactly what is drawn. Files are written atomically.

:class:`SceneFigureWriter` draws the figures of ``lfbench evaluate --figures``
(lfbench.reports.writers.SceneFigures) and of a report's saved maps: each prediction is drawn into its own
row PNG as it arrives, and the scene overview is re-assembled from the row PNGs on disk, so memory does
not grow with the number of methods or scenes (only the BadPix curves, 101 numbers per run, are kept).
"""

from __future__ import annotations

import csv
import io
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from lfbench.data.disparity import EVALUATION_BORDER_PX
from lfbench.data.scene import LightField
from lfbench.data.submission import find_disp_map, read_submission_map
from lfbench.method.base import Prediction
from lfbench.reports.plotting import add_colorbar, as_gray, colormap, legend_label, method_colours, pyplot, save_figure
from lfbench.scoring.metrics import bad_pix_curve, badpix_threshold, metric_order, primary_metric
from lfbench.scoring.prepare import SceneReference, align_prediction
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.atomic import write_bytes, write_text
from lfbench.utils.errors import DataError
from lfbench.utils.figure_text import plain_text
from lfbench.utils.names import FileNames, file_name, file_names
from lfbench.utils.readfile import check_regular_file, read_text

_log = logging.getLogger(__name__)

BADPIX_THRESHOLD = 0.07  # px
ERROR_LIMIT = 0.2  # px, range of the signed error maps
CURVE_THRESHOLDS = np.round(np.arange(101) * 0.001, 3)  # 0 .. 0.1 px in steps of 0.001 (exact decimals)
MARKED_THRESHOLDS = (0.01, 0.03, 0.07)



@dataclass(frozen=True)
class Thresholds:
    """The BadPix thresholds (px) a run's protocol scores, as the figures show them: ``marked`` (dotted lines
    on the BadPix series) and ``primary`` (the BadPix maps and their captions). The default is the
    benchmark's (0.01, 0.03, 0.07; maps at 0.07)."""

    marked: tuple[float, ...] = MARKED_THRESHOLDS
    primary: float = BADPIX_THRESHOLD

    @classmethod
    def of_metrics(cls, metric_ids: Sequence[str]) -> Thresholds:
        """The thresholds of the ``badpix_<t>`` ids among ``metric_ids`` (a protocol's metrics): every one
        marked, that of the protocol's primary metric (:func:`lfbench.scoring.metrics.primary_metric`: BadPix 0.07
        where scored) the primary; the default when there is none."""
        found = {m: t for m in metric_order(metric_ids) if (t := badpix_threshold(m)) is not None}
        if not found:
            return cls()
        return cls(marked=tuple(sorted(set(found.values()))), primary=found[primary_metric(found)])

    @property
    def curve(self) -> np.ndarray:
        """The thresholds of a BadPix series: :data:`CURVE_THRESHOLDS` (0 .. 0.1 px) unless a marked one lies
        beyond, then 101 from 0 to 1.25 x the largest (rounded up to 0.01 px)."""
        top = max(self.marked)
        if top <= CURVE_THRESHOLDS[-1]:
            return CURVE_THRESHOLDS
        return np.round(np.linspace(0.0, math.ceil(top * 125) / 100, 101), 6)


# BadPix map codes and colours (RGB in [0, 1]); GOOD is a grey level, never pure red.
OUTSIDE, GOOD, BAD = 0, 1, 2
BAD_RGB = (1.0, 0.0, 0.0)
NONFINITE_RGB = (0.0, 0.0, 0.0)
OUTSIDE_GREY = 0.45
GOOD_LIGHT = (0.80, 0.20)  # good pixel grey = 0.80 + 0.20 * centre-view gray (0.92 without a view)
DISPARITY_CMAP, ERROR_CMAP, UNCERTAINTY_CMAP = "viridis", "seismic", "magma"

PANEL_IN, ROW_HEIGHT_IN = 3.2, 3.0


# --------------------------------------------------------------------------- pure panel arrays

def badpix_codes(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None,
                 threshold: float = BADPIX_THRESHOLD) -> np.ndarray:
    """(H, W) uint8: BAD where |gt - pred| > threshold or pred is non-finite, GOOD elsewhere, OUTSIDE
    where the pixel is not scored (outside ``mask`` or non-finite gt). Same rule as metrics.bad_pix."""
    gt = np.asarray(gt, dtype=np.float32)
    pred = np.asarray(pred, dtype=np.float32)
    scored = np.isfinite(gt) if mask is None else np.asarray(mask, dtype=bool) & np.isfinite(gt)
    with np.errstate(invalid="ignore"):
        bad = (np.abs(gt - pred) > threshold) | ~np.isfinite(pred)
    return np.where(scored, np.where(bad, BAD, GOOD), OUTSIDE).astype(np.uint8)


def badpix_image(codes: np.ndarray, background: np.ndarray | None = None) -> np.ndarray:
    """The BadPix map drawn from :func:`badpix_codes`: (H, W, 3) float32 RGB; BAD pure red, GOOD light
    grey (a faint copy of ``background``, the centre view, when given), OUTSIDE dark grey."""
    gray = as_gray(background, codes.shape)
    light = np.full(codes.shape, GOOD_LIGHT[0] + GOOD_LIGHT[1] * 0.6, np.float32) if gray is None \
        else GOOD_LIGHT[0] + GOOD_LIGHT[1] * gray
    level = np.where(codes == GOOD, light, OUTSIDE_GREY).astype(np.float32)
    rgb = np.repeat(level[..., None], 3, axis=2)
    rgb[codes == BAD] = BAD_RGB
    return rgb


def disparity_image(disparity: np.ndarray, vmin: float, vmax: float, cmap: str = DISPARITY_CMAP) -> np.ndarray:
    """(H, W, 3) float32 RGB: ``disparity`` (px) in ``cmap`` over [vmin, vmax]; non-finite black."""
    d = np.asarray(disparity, dtype=np.float32)
    finite = np.isfinite(d)
    t = np.clip((np.where(finite, d, vmin) - vmin) / max(vmax - vmin, 1e-12), 0, 1)
    rgb = colormap(cmap)(t)[..., :3].astype(np.float32)
    rgb[~finite] = NONFINITE_RGB
    return rgb


def signed_error(gt: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """gt - pred in px, (H, W) float32 (NaN where either is non-finite)."""
    with np.errstate(invalid="ignore"):
        err = np.asarray(gt, dtype=np.float32) - np.asarray(pred, dtype=np.float32)
    return np.where(np.isfinite(err), err, np.nan).astype(np.float32)


def signed_error_image(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None,
                       limit: float = ERROR_LIMIT, cmap: str = ERROR_CMAP) -> np.ndarray:
    """(H, W, 3) float32 RGB of gt - pred in ``cmap`` over [-limit, +limit]; grey outside ``mask`` (and
    where gt is non-finite), black where the prediction is non-finite inside it."""
    err = signed_error(gt, pred)
    rgb = colormap(cmap)(np.clip((np.nan_to_num(err) + limit) / (2 * limit), 0, 1))[..., :3].astype(np.float32)
    scored = np.isfinite(np.asarray(gt, dtype=np.float32))
    if mask is not None:
        scored &= np.asarray(mask, dtype=bool)
    rgb[scored & ~np.isfinite(np.asarray(pred, dtype=np.float32))] = NONFINITE_RGB
    rgb[~scored] = OUTSIDE_GREY
    return rgb


def uncertainty_range(uncertainty: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float]:
    """Colour range of an uncertainty map: its 1st and 99th percentiles inside ``mask``."""
    u = np.asarray(uncertainty, dtype=np.float32)
    sel = np.isfinite(u) if mask is None or mask.shape != u.shape else np.isfinite(u) & mask
    if not sel.any():
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(u[sel], [1, 99]))
    return (lo, hi) if hi > lo else (lo, lo + 1e-6)


def uncertainty_image(uncertainty: np.ndarray, vmin: float, vmax: float,
                      cmap: str = UNCERTAINTY_CMAP) -> np.ndarray:
    """(H, W, 3) float32 RGB of an uncertainty map (larger = less sure) over [vmin, vmax]."""
    return disparity_image(uncertainty, vmin, vmax, cmap)


def disparity_range(lf: LightField, gt: np.ndarray | None = None,
                    pred: np.ndarray | None = None) -> tuple[float, float]:
    """Colour range (px) of disparity maps: 0.9 * [disp_min, disp_max] from the scene's parameters.cfg,
    else the finite range of ``gt`` (or of ``pred``), else [-1, 1]."""
    params = getattr(lf, "params", None)
    lo, hi = getattr(params, "disp_min", None), getattr(params, "disp_max", None)
    if lo is not None and hi is not None and hi > lo:
        return 0.9 * float(lo), 0.9 * float(hi)
    for arr in (gt, pred):
        finite = None if arr is None else np.asarray(arr)[np.isfinite(arr)]
        if finite is not None and finite.size:
            lo, hi = float(finite.min()), float(finite.max())
            return (lo, hi) if hi > lo else (lo - 0.5, hi + 0.5)
    return -1.0, 1.0


@dataclass
class MethodPanels:
    """What one method's row of an overview shows, as RGB (H, W, 3) float32 arrays."""

    label: str
    disparity: np.ndarray
    badpix: np.ndarray | None  # None without ground truth
    badpix_codes: np.ndarray | None
    badpix_percent: float  # BadPix(threshold) in % at low resolution (the map shown)
    error: np.ndarray | None
    uncertainty: np.ndarray | None
    uncertainty_range: tuple[float, float] | None
    disparity_range: tuple[float, float]
    threshold: float = BADPIX_THRESHOLD


def method_panels(label: str, lf: LightField, prediction: Prediction | np.ndarray, *,
                  gt: np.ndarray | None = None, mask: np.ndarray | None = None,
                  background: np.ndarray | None = None, disp_range: tuple[float, float] | None = None,
                  threshold: float = BADPIX_THRESHOLD, border_px: int = EVALUATION_BORDER_PX) -> MethodPanels:
    """The panels of one prediction on one light field at low resolution. ``gt``, ``mask`` and
    ``background`` default to the scene's ground truth, evaluation mask and centre view."""
    pred = prediction if isinstance(prediction, Prediction) else Prediction(disparity=np.asarray(prediction))
    if gt is None:
        gt = lf.gt_disparity()
    shape = tuple(gt.shape) if gt is not None else tuple(np.asarray(pred.disparity).shape)
    disp, _ = align_prediction(np.asarray(pred.disparity, dtype=np.float32), shape, f"{label} on {lf.name}")
    if mask is None:
        mask = SceneReference(lf, ScoringRules(border_px=border_px)).evaluation_mask()
    if disp_range is None:
        disp_range = disparity_range(lf, gt, disp)
    unc = unc_rgb = unc_range = None
    if pred.uncertainty is not None:
        unc = np.asarray(pred.uncertainty, dtype=np.float32)
        if unc.shape != shape:
            unc, _ = align_prediction(unc, shape, f"{label} uncertainty on {lf.name}")
        unc_range = uncertainty_range(unc, mask)
        unc_rgb = uncertainty_image(unc, *unc_range)
    codes = bp = err = None
    percent = float("nan")
    if gt is not None:
        codes = badpix_codes(gt, disp, mask, threshold)
        scored = np.count_nonzero(codes != OUTSIDE)
        percent = 100.0 * np.count_nonzero(codes == BAD) / scored if scored else float("nan")
        bp = badpix_image(codes, background)
        err = signed_error_image(gt, disp, mask)
    return MethodPanels(label=label, disparity=disparity_image(disp, *disp_range), badpix=bp, badpix_codes=codes,
                        badpix_percent=percent, error=err, uncertainty=unc_rgb, uncertainty_range=unc_range,
                        disparity_range=disp_range, threshold=threshold)


# --------------------------------------------------------------------------- drawing

def _row_figure(title: str):
    plt = pyplot()
    fig, axes = plt.subplots(1, 4, figsize=(4 * PANEL_IN, ROW_HEIGHT_IN))
    fig.subplots_adjust(left=0.01, right=0.95, top=0.83, bottom=0.03, wspace=0.28)
    fig.suptitle(title, fontsize=9, x=0.01, ha="left")
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    return fig, axes


def _blank(ax: Any, text: str) -> None:
    ax.axis("off")
    ax.text(0.5, 0.5, text, ha="center", va="center", fontsize=8, color="0.4", transform=ax.transAxes, wrap=True)


@plain_text
def draw_method_row(panels: MethodPanels, path: str | Path, resolution_note: str = "") -> Path:
    """One method's row: disparity | BadPix map | signed error | uncertainty, as a PNG of fixed size."""
    fig, axes = _row_figure(panels.label + (f"  ({resolution_note})" if resolution_note else ""))
    lo, hi = panels.disparity_range
    axes[0].imshow(panels.disparity, interpolation="nearest")
    axes[0].set_title("disparity (px)", fontsize=8)
    add_colorbar(fig, axes[0], DISPARITY_CMAP, lo, hi)
    if panels.badpix is not None:
        axes[1].imshow(panels.badpix, interpolation="nearest")
        axes[1].set_title(f"BadPix({panels.threshold:g}) = {panels.badpix_percent:.2f}% (red = bad)", fontsize=8)
        axes[2].imshow(panels.error, interpolation="nearest")
        axes[2].set_title("gt - pred (px)", fontsize=8)
        add_colorbar(fig, axes[2], ERROR_CMAP, -ERROR_LIMIT, ERROR_LIMIT)
    else:
        _blank(axes[1], "no ground truth")
        _blank(axes[2], "no ground truth")
    if panels.uncertainty is not None and panels.uncertainty_range is not None:
        axes[3].imshow(panels.uncertainty, interpolation="nearest")
        axes[3].set_title("uncertainty", fontsize=8)
        add_colorbar(fig, axes[3], UNCERTAINTY_CMAP, *panels.uncertainty_range)
    else:
        _blank(axes[3], "no uncertainty map")
    return save_figure(fig, path)


@plain_text
def draw_scene_header(lf: LightField, path: str | Path, gt: np.ndarray | None,
                      disp_range: tuple[float, float], threshold: float = BADPIX_THRESHOLD,
                      border_px: int = EVALUATION_BORDER_PX) -> Path:
    """The first row of a scene overview: centre view | ground truth | colour legend | notes."""
    fig, axes = _row_figure(f"scene {lf.name}")
    center = np.clip(np.asarray(lf.center_view(), dtype=np.float32), 0, 1)
    axes[0].imshow(center, cmap="gray" if center.ndim == 2 else None, vmin=0, vmax=1, interpolation="nearest")
    axes[0].set_title("centre view", fontsize=8)
    if gt is not None:
        axes[1].imshow(disparity_image(gt, *disp_range), interpolation="nearest")
        axes[1].set_title("ground truth (px)", fontsize=8)
        add_colorbar(fig, axes[1], DISPARITY_CMAP, *disp_range)
    else:
        _blank(axes[1], "no ground truth")
    ax = axes[2]
    ax.axis("off")
    legend = ((BAD_RGB, f"bad: |gt - pred| > {threshold:g} px or non-finite"),
              ((GOOD_LIGHT[0] + GOOD_LIGHT[1] * 0.6,) * 3, "good"),
              ((OUTSIDE_GREY,) * 3, "outside the evaluation mask"),
              (NONFINITE_RGB, "non-finite prediction (maps)"))
    for i, (colour, text) in enumerate(legend):
        y = 0.85 - 0.2 * i
        ax.add_patch(pyplot().Rectangle((0.0, y - 0.05), 0.1, 0.1, color=colour, transform=ax.transAxes))
        ax.text(0.14, y, text, va="center", fontsize=7, transform=ax.transAxes)
    ax.set_title("BadPix map colours", fontsize=8)
    h, w = (gt.shape if gt is not None else center.shape[:2])
    notes = [f"{w}x{h} px (maps at low resolution)", f"evaluation mask: {border_px} px border",
             f"disparity colours: {disp_range[0]:.2f} .. {disp_range[1]:.2f} px",
             f"signed error colours: -{ERROR_LIMIT:g} .. +{ERROR_LIMIT:g} px"]
    _blank(axes[3], "\n".join(notes))
    return save_figure(fig, path)


def stack_rows(row_paths: Sequence[str | Path], path: str | Path) -> Path:
    """Stack row PNGs (equal widths, as drawn by this module) vertically into one PNG (atomic)."""
    images = []
    for p in row_paths:
        check_regular_file(p, "figure row")
        with Image.open(p) as img:
            images.append(img.convert("RGB"))
    width = max(img.width for img in images)
    canvas = Image.new("RGB", (width, sum(img.height for img in images)), "white")
    y = 0
    for img in images:
        canvas.paste(img, (0, y))
        y += img.height
    buf = io.BytesIO()
    canvas.save(buf, format="PNG")
    write_bytes(path, buf.getvalue())
    return Path(path)


# --------------------------------------------------------------------------- BadPix-series curves

@dataclass(frozen=True)
class Curve:
    """BadPix(t) in % of one method on one scene for t in ``thresholds`` (px), scored at ``resolution``."""

    method: str
    scene: str
    resolution: str
    thresholds: np.ndarray
    values: np.ndarray


def scene_curve(label: str, scene: LightField, disparity: np.ndarray, rules: ScoringRules = ScoringRules(),
                thresholds: np.ndarray = CURVE_THRESHOLDS) -> Curve | None:
    """The BadPix series of a prediction under the scene's scoring rule (resolution, border, valid
    mask), prepared as lfbench.scoring.score.score_scene prepares it (SceneReference.prepare), so
    BadPix(0.07) equals the table's. None without gt."""
    reference = SceneReference(scene, rules)
    res = reference.general_resolution()
    if not reference.has_gt(res):
        return None
    p = reference.prepare(disparity, res, f"{label} on {scene.name}")
    return Curve(label, scene.name, res, np.asarray(thresholds, dtype=np.float64),
                 bad_pix_curve(p.gt, p.pred, thresholds, p.mask))


def average_curves(curves: Sequence[Curve]) -> dict[str, tuple[np.ndarray, np.ndarray, int]]:
    """Mean BadPix series per method over its scenes: method -> (thresholds, values, number of scenes)."""
    out: dict[str, list[Curve]] = {}
    for c in curves:
        out.setdefault(c.method, []).append(c)
    return {m: (cs[0].thresholds, np.mean([c.values for c in cs], axis=0), len(cs)) for m, cs in out.items()}


def plot_mean_series(averaged: Mapping[str, tuple[np.ndarray, np.ndarray, int]], path: str | Path, title: str, *,
                     markers: bool = False, colours: Mapping[str, str] | None = None,
                     marked: Sequence[float] = MARKED_THRESHOLDS) -> Path:
    """:func:`plot_badpix_series` of series averaged over scenes (method -> (t, values, number of scenes), as
    :func:`average_curves` and :func:`curves_from_records` give them), each labelled with its scene count."""
    return plot_badpix_series({m: (t, v) for m, (t, v, _) in averaged.items()}, path, title, markers=markers,
                              colours=colours, scenes={m: k for m, (_, _, k) in averaged.items()}, marked=marked)


@plain_text
def badpix_series_figure(series: Mapping[str, tuple[np.ndarray, np.ndarray]], title: str, *, markers: bool = False,
                         colours: Mapping[str, str] | None = None, scenes: Mapping[str, int] | None = None,
                         marked: Sequence[float] = MARKED_THRESHOLDS) -> Any:
    """The figure of :func:`plot_badpix_series` (not saved): the legend beside the axes, never over the
    curves, its labels wrapped (plotting.legend_label); dotted lines at the ``marked`` thresholds (px), the
    axis from 0 to 0.1 px or to the largest threshold drawn or marked."""
    plt = pyplot()
    colours = colours if colours is not None else method_colours(list(series))
    fig, ax = plt.subplots(figsize=(8.4, 4.2))
    for method, (t, v) in series.items():
        label = method if scenes is None else f"{method} ({scenes[method]} scene{'s' if scenes[method] != 1 else ''})"
        ax.plot(t, v, marker="o" if markers else None, markersize=4, linewidth=1.5, label=legend_label(label),
                color=colours.get(method))
    for t in marked:
        ax.axvline(t, color="0.7", linestyle=":", linewidth=1)
    ax.set_xlim(0, max([0.1, *marked, *(float(np.max(t)) for t, _ in series.values() if len(t))]))
    ax.set_ylim(bottom=0)
    ax.set_xlabel("threshold t (px)")
    ax.set_ylabel("BadPix(t) (%)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    if series:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, frameon=False)
    fig.tight_layout()
    return fig


@plain_text
def plot_badpix_series(series: Mapping[str, tuple[np.ndarray, np.ndarray]], path: str | Path, title: str, *,
                       markers: bool = False, colours: Mapping[str, str] | None = None,
                       scenes: Mapping[str, int] | None = None, marked: Sequence[float] = MARKED_THRESHOLDS) -> Path:
    """BadPix(t) (%) against t (px), one line per method (``series``: method -> (t, values)); dotted lines
    mark the protocol's thresholds (``marked``, default 0.01, 0.03 and 0.07). ``colours``: method -> colour
    (default: plotting.method_colours in the series' order); ``scenes``: method -> number of scenes averaged,
    added to its label."""
    fig = badpix_series_figure(series, title, markers=markers, colours=colours, scenes=scenes, marked=marked)
    return save_figure(fig, path, dpi=110)


CURVE_CSV_COLUMNS = ("method", "scene", "resolution", "threshold", "value")


def write_curves_csv(curves: Sequence[Curve], path: str | Path) -> Path:
    """The curves as tidy CSV: method, scene, resolution, threshold (px), value (%)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CURVE_CSV_COLUMNS)
    for c in curves:
        for t, v in zip(c.thresholds, c.values, strict=True):
            w.writerow([c.method, c.scene, c.resolution, f"{t:.6g}", repr(float(v))])
    write_text(path, buf.getvalue())
    return Path(path)


def read_curves_csv(path: str | Path) -> list[Curve]:
    """Curves written by :func:`write_curves_csv`; DataError naming the file when malformed."""
    path = Path(path)
    rows: dict[tuple[str, str, str], list[tuple[float, float]]] = {}
    reader = csv.DictReader(io.StringIO(read_text(path, "curve file"), newline=""))
    if tuple(reader.fieldnames or ()) != CURVE_CSV_COLUMNS:
        raise DataError(f"expected columns {', '.join(CURVE_CSV_COLUMNS)}", path)
    for i, r in enumerate(reader, start=2):
        try:
            rows.setdefault((r["method"], r["scene"], r["resolution"]), []).append(
                (float(r["threshold"]), float(r["value"])))
        except (TypeError, ValueError):
            raise DataError(f"line {i}: threshold and value must be numbers", path) from None
    out = []
    for (m, s, res), pts in rows.items():
        arr = np.array(sorted(pts), dtype=np.float64)
        out.append(Curve(m, s, res, arr[:, 0], arr[:, 1]))
    return out


def draw_badpix_curves(curves: Sequence[Curve], out_dir: str | Path,
                       colours: Mapping[str, str] | None = None, marked: Sequence[float] = MARKED_THRESHOLDS
                       ) -> list[Path]:
    """badpix_series.png (mean over scenes per method) in out_dir and <scene>/badpix_series.png per scene;
    ``colours``: method -> colour (default: by first appearance in ``curves``); ``marked``: the protocol's
    thresholds (px), dotted."""
    out = Path(out_dir)
    written = []
    by_scene: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    res_of: dict[str, set[str]] = {}
    for c in curves:
        by_scene.setdefault(c.scene, {})[c.method] = (c.thresholds, c.values)
        res_of.setdefault(c.scene, set()).add(c.resolution)
    folders = file_names(by_scene, "scene", reserved=RESERVED_SCENE_NAMES)
    colours = colours if colours is not None else method_colours([c.method for c in curves])
    for scene, series in by_scene.items():
        written.append(plot_badpix_series(series, out / folders[scene] / "badpix_series.png",
                                          f"BadPix series, {scene} ({'/'.join(sorted(res_of[scene]))})",
                                          colours=colours, marked=marked))
    written.append(plot_mean_series(average_curves(curves), out / "badpix_series.png",
                                    "BadPix series, mean over scenes", colours=colours, marked=marked))
    return written


def curves_from_records(results: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Mean BadPix at the thresholds a results file holds (badpix_<t>), per method: the coarse series
    available without the maps, method -> (thresholds, values, number of scenes) as :func:`average_curves`
    gives them. Only scenes where the method has every threshold are averaged."""
    df = results.to_frame()
    thresholds = {m: t for m in dict.fromkeys(df["metric"]) if (t := badpix_threshold(m)) is not None}
    df = df[df["metric"].isin(list(thresholds))].copy()
    if df.empty:
        return {}
    df["t"] = df["metric"].map(thresholds).astype(float)
    out = {}
    for method, g in df.groupby("method", sort=False):
        table = g.pivot_table(index="scene", columns="t", values="value", aggfunc="first").dropna()
        if not table.empty:
            out[method] = (table.columns.to_numpy(dtype=float), table.mean(axis=0).to_numpy(dtype=float), len(table))
    return out


# --------------------------------------------------------------------------- the evaluate hook

#: A method label or scene name as a file name (lfbench.utils.names.file_name, the one rule).
safe_name = file_name


#: Names the figure folder and a scene's folder hold besides the scenes' folders and the methods' rows:
#: a scene or a method label whose file name is one of them is refused (lfbench.utils.names).
RESERVED_SCENE_NAMES = ("badpix_series.csv", "badpix_series.png", "toolkit")
RESERVED_ROW_NAMES = ("header", "badpix_series")


class SceneFigureWriter:
    """Draws figures as predictions arrive; call it as the hook (method, scene, prediction) -> None.

    Writes into ``out_dir``: ``<scene>/header.png`` (centre view, ground truth),
    ``<scene>/<method>.png`` (one row per method), ``overview_<scene>.png`` (header and rows stacked),
    and, when ``curves`` is set, ``badpix_series.csv``, ``badpix_series.png`` (mean over scenes) and
    ``<scene>/badpix_series.png``. Only the row file names and the curves are kept in memory. Scene and
    method names are file names by lfbench.utils.names: two that would share a file are refused
    (DataError) before anything of the second is drawn. Each method keeps one colour on every series
    chart (plotting.method_colours, by its place in ``methods``, else by arrival).
    """

    def __init__(self, out_dir: str | Path, rules: ScoringRules = ScoringRules(),
                 thresholds: Thresholds = Thresholds(), curves: bool = True, methods: Sequence[str] = ()) -> None:
        self.out = Path(out_dir)
        self.rules = rules
        self.thresholds = thresholds
        self.threshold = thresholds.primary
        self.curves_enabled = curves
        self._rows: dict[str, dict[str, Path]] = {}  # scene -> method label -> row PNG (arrival order)
        self._headers: dict[str, tuple[Path, tuple[float, float]]] = {}
        self._curves: dict[tuple[str, str], Curve] = {}
        self._scene_names = FileNames("scene", reserved=RESERVED_SCENE_NAMES)
        self._method_names = FileNames("method label", reserved=RESERVED_ROW_NAMES)
        self.written: set[Path] = set()
        self._methods = list(methods)  # the order colours are given in; methods not named follow as they arrive

    def __call__(self, method: Any, scene: LightField, prediction: Prediction) -> None:
        self.add(method.label, scene, prediction)

    @property
    def curves(self) -> list[Curve]:
        return list(self._curves.values())

    def add(self, label: str, scene: LightField, prediction: Prediction | np.ndarray) -> list[Path]:
        """Draw one prediction's row, re-assemble the scene's overview and update the curves."""
        pred = prediction if isinstance(prediction, Prediction) else Prediction(disparity=np.asarray(prediction))
        scene_name, method_name = self._scene_names(scene.name), self._method_names(label)
        if label not in self._methods:
            self._methods.append(label)
        scene_dir = self.out / scene_name
        gt = scene.gt_disparity()
        written = []
        center = None
        if scene.name not in self._headers:
            disp, _ = (align_prediction(np.asarray(pred.disparity), gt.shape) if gt is not None
                       else (np.asarray(pred.disparity), None))
            disp_range = disparity_range(scene, gt, disp)
            header = draw_scene_header(scene, scene_dir / "header.png", gt, disp_range, self.threshold,
                                       self.rules.border_px)
            self._headers[scene.name] = (header, disp_range)
            written.append(header)
        header, disp_range = self._headers[scene.name]
        if gt is not None:
            center = scene.center_view()
        panels = method_panels(label, scene, pred, gt=gt, background=center, disp_range=disp_range,
                               threshold=self.threshold, border_px=self.rules.border_px)
        rows = self._rows.setdefault(scene.name, {})
        rows[label] = draw_method_row(panels, scene_dir / f"{method_name}.png", "low resolution")
        del panels
        written.append(rows[label])
        written.append(stack_rows([header, *rows.values()], self.out / f"overview_{scene_name}.png"))
        if self.curves_enabled:
            curve = scene_curve(label, scene, pred.disparity, self.rules, self.thresholds.curve)
            if curve is not None:
                self._curves[(label, scene.name)] = curve
                written.append(write_curves_csv(self.curves, self.out / "badpix_series.csv"))
                colours = method_colours(self._methods)
                series = {c.method: (c.thresholds, c.values) for c in self.curves if c.scene == scene.name}
                written.append(plot_badpix_series(series, scene_dir / "badpix_series.png",
                                                  f"BadPix series, {scene.name} ({curve.resolution})", colours=colours,
                                                  marked=self.thresholds.marked))
                written.append(plot_mean_series(average_curves(self.curves), self.out / "badpix_series.png",
                                                "BadPix series, mean over scenes", colours=colours,
                                                marked=self.thresholds.marked))
        self.written.update(written)
        return written


def figures_from_maps(scenes: Sequence[LightField], maps: Mapping[str, str | Path], out_dir: str | Path,
                      rules: ScoringRules = ScoringRules(), progress: bool = False,
                      thresholds: Thresholds = Thresholds()) -> SceneFigureWriter:
    """Figures from saved maps: ``maps`` maps a method label to a submission folder
    (disp_maps/<scene>.pfm, as written by ``evaluate --save-maps`` or a published submission).
    Scenes without a map for a method are left out for that method. Returns the writer (its
    ``written`` files and ``curves``)."""
    writer = SceneFigureWriter(out_dir, rules=rules, thresholds=thresholds)
    for scene in scenes:
        for label, folder in maps.items():
            if not find_disp_map(folder, scene.name).is_file():
                continue
            disp, runtime = read_submission_map(folder, scene.name, max_shape=getattr(scene, "spatial_size", None))
            writer.add(label, scene, Prediction(disparity=disp, runtime_s=runtime))
            if progress:
                _log.info("drew %s on %s", label, scene.name)
    return writer
