"""The official toolkit's comparison figures for any set of methods: pairwise comparison maps, error
heatmaps over methods and radar charts over the region / stratified metrics (the BadPix series are in
lfbench.reports.figures).

Definitions (docs/hci-evaluation-reference.md, Figures; the toolkit's evaluations/*.py):

- pairwise comparison of A and B on a scene: ``|A - gt| - |B - gt|`` (px) per pixel, drawn in the
  diverging map over +-0.1 px (blue: A is better, red: B is better). Here a pixel is classed as
  "A better" / "B better" when the difference exceeds ``threshold`` px, "tie" otherwise; a
  non-finite prediction counts as an infinite error (as lfbench's BadPix counts it as bad);
- error heatmaps: per pixel, the median over methods of ``|gt - pred|`` (px), and the toolkit's
  percentage of methods with ``|gt - pred| > t`` (non-finite = bad);
- radar chart: per method, the median (or mean) over scenes of each region / stratified metric (the
  general metrics when the results hold none); each axis runs from 0 to 1.2 x the largest value
  on it, offset by one ring as in the toolkit.

The maps are compared at low resolution (the resolution of the saved maps). Every figure is first a
pure array or DataFrame (tested against numpy), then drawn by ``plot_*`` into PNG (and PDF / SVG
with ``formats``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lfbench.reports.plotting import add_colorbar, as_gray, colormap, legend_label, method_colours, pyplot, save_formats
from lfbench.scoring.metrics import METRICS, describe_metric, metric_order
from lfbench.utils.errors import SpecError
from lfbench.utils.figure_text import plain_text
from lfbench.utils.names import FileNames, file_names

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "A_BETTER", "B_BETTER", "HEATMAP_CMAP", "OUTSIDE", "PAIRWISE_LIMIT", "PAIRWISE_THRESHOLD", "TIE",
    "absolute_error", "bad_fraction_map", "heatmap_image", "median_error_map", "pairwise_classes",
    "pairwise_difference", "pairwise_image", "pairwise_shares", "plot_error_heatmaps", "plot_pairwise",
    "plot_radar", "radar_axis_name", "radar_figure", "radar_magnitudes", "radar_metric_ids", "radar_radii",
    "radar_scores", "save_formats",
    "toolkit_figures_from_scene_maps",
]

PAIRWISE_LIMIT = 0.1  # px, colour range of the pairwise maps (the toolkit's)
PAIRWISE_THRESHOLD = 0.01  # px: smaller differences of absolute error are a tie
HEATMAP_CMAP, PAIRWISE_CMAP = "inferno", "seismic"
MEDIAN_ERROR_LIMIT = 0.2  # px, colour range of the median-error heatmap

# pairwise class codes
OUTSIDE, TIE, A_BETTER, B_BETTER = 0, 1, 2, 3
OUTSIDE_GREY, TIE_LIGHT = 0.45, 0.88


# --------------------------------------------------------------------------- pure arrays

def absolute_error(gt: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """|gt - pred| in px, (H, W) float32: +inf where the prediction is non-finite, NaN where gt is."""
    gt = np.asarray(gt, dtype=np.float32)
    pred = np.asarray(pred, dtype=np.float32)
    if gt.shape != pred.shape:
        raise SpecError(f"ground truth {gt.shape} and prediction {pred.shape} differ in shape")
    with np.errstate(invalid="ignore"):
        err = np.abs(gt - pred)
    err = np.where(np.isfinite(pred), err, np.float32(np.inf))
    return np.where(np.isfinite(gt), err, np.float32(np.nan)).astype(np.float32)


def _scored(gt: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    scored = np.isfinite(np.asarray(gt, dtype=np.float32))
    return scored if mask is None else scored & np.asarray(mask, dtype=bool)


def pairwise_difference(gt: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - gt| - |b - gt| in px, (H, W) float32 (negative: A is better). +-inf where exactly one
    prediction is non-finite, NaN where both are or gt is."""
    with np.errstate(invalid="ignore"):
        return (absolute_error(gt, a) - absolute_error(gt, b)).astype(np.float32)


def pairwise_classes(gt: np.ndarray, a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None,
                     threshold: float = PAIRWISE_THRESHOLD) -> np.ndarray:
    """(H, W) uint8 codes: A_BETTER where |a - gt| < |b - gt| - threshold, B_BETTER where
    |b - gt| < |a - gt| - threshold, TIE otherwise (both non-finite included), OUTSIDE outside
    ``mask`` or where gt is non-finite."""
    if threshold < 0:
        raise SpecError(f"the pairwise threshold must be >= 0 px, got {threshold}")
    diff = pairwise_difference(gt, a, b)
    with np.errstate(invalid="ignore"):
        codes = np.where(diff < -threshold, A_BETTER, np.where(diff > threshold, B_BETTER, TIE))
    return np.where(_scored(gt, mask), codes, OUTSIDE).astype(np.uint8)


def pairwise_shares(codes: np.ndarray) -> dict[str, float]:
    """% of the scored pixels where A is better, B is better, and tied."""
    scored = np.count_nonzero(codes != OUTSIDE)
    if not scored:
        return {"a_better": float("nan"), "b_better": float("nan"), "tie": float("nan")}
    return {name: 100.0 * np.count_nonzero(codes == code) / scored
            for name, code in (("a_better", A_BETTER), ("b_better", B_BETTER), ("tie", TIE))}


def pairwise_image(gt: np.ndarray, a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None,
                   threshold: float = PAIRWISE_THRESHOLD, limit: float = PAIRWISE_LIMIT,
                   background: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) float32 RGB: the difference in the diverging map over +-``limit`` (blue: A better,
    red: B better) where one method is better by more than ``threshold``; ties light grey (a faint
    copy of ``background``, the centre view), outside the mask dark grey."""
    diff = pairwise_difference(gt, a, b)
    codes = pairwise_classes(gt, a, b, mask, threshold)
    t = np.clip((np.nan_to_num(diff, nan=0.0, posinf=limit, neginf=-limit) + limit) / (2 * limit), 0, 1)
    rgb = colormap(PAIRWISE_CMAP)(t)[..., :3].astype(np.float32)
    gray = as_gray(background, codes.shape)
    tie = np.full(codes.shape, TIE_LIGHT, np.float32) if gray is None else 0.80 + 0.15 * gray
    rgb[codes == TIE] = np.repeat(tie[..., None], 3, axis=2)[codes == TIE]
    rgb[codes == OUTSIDE] = OUTSIDE_GREY
    return rgb


def median_error_map(gt: np.ndarray, preds: Sequence[np.ndarray], mask: np.ndarray | None = None) -> np.ndarray:
    """Per pixel, the median over the methods' predictions of |gt - pred| (px), (H, W) float32; a
    non-finite prediction is an infinite error; NaN outside ``mask`` and where gt is non-finite."""
    if not len(preds):
        raise SpecError("the median-error heatmap needs at least one method")
    errors = np.stack([absolute_error(gt, p) for p in preds])
    med = np.median(errors, axis=0).astype(np.float32)
    return np.where(_scored(gt, mask), med, np.float32(np.nan))


def bad_fraction_map(gt: np.ndarray, preds: Sequence[np.ndarray], mask: np.ndarray | None = None,
                     threshold: float = 0.07) -> np.ndarray:
    """The toolkit's error heatmap: per pixel, the % of methods with |gt - pred| > ``threshold`` px
    (non-finite = bad), (H, W) float32; NaN outside ``mask`` and where gt is non-finite."""
    if not len(preds):
        raise SpecError("the error heatmap needs at least one method")
    bad = np.stack([absolute_error(gt, p) > threshold for p in preds])
    pct = (100.0 * bad.sum(axis=0) / len(preds)).astype(np.float32)
    return np.where(_scored(gt, mask), pct, np.float32(np.nan))


def heatmap_image(values: np.ndarray, vmin: float, vmax: float, cmap: str = HEATMAP_CMAP) -> np.ndarray:
    """(H, W, 3) float32 RGB of ``values`` in ``cmap`` over [vmin, vmax] (clipped; +inf at the top);
    NaN (outside the mask) dark grey."""
    v = np.asarray(values, dtype=np.float64)
    nan = np.isnan(v)
    t = np.clip((np.nan_to_num(v, nan=vmin, posinf=vmax) - vmin) / max(vmax - vmin, 1e-12), 0, 1)
    rgb = colormap(cmap)(t)[..., :3].astype(np.float32)
    rgb[nan] = OUTSIDE_GREY
    return rgb


# --------------------------------------------------------------------------- radar

def radar_metric_ids(results: Any) -> list[str]:
    """The metrics a radar chart shows: the region and stratified metrics the results hold, else the
    general ones (in the tables' order)."""
    held = list(dict.fromkeys(r.metric for r in results.records))
    region = [m for m in held if getattr(METRICS.find(m), "category", "general") in ("region", "stratified")]
    return region or metric_order(held)


def radar_scores(results: Any, methods: Sequence[str] | None = None, metrics: Sequence[str] | None = None,
                 average: str = "median") -> pd.DataFrame:
    """The radar chart's numbers: rows metric ids, columns methods; each the median (or mean) over the
    scenes where the method has that metric. Metrics no method has are dropped."""
    if average not in ("median", "mean"):
        raise SpecError(f"radar average must be 'median' or 'mean', got {average!r}")
    df = results.to_frame()
    methods = list(methods) if methods is not None else list(dict.fromkeys(df["method"]))
    metrics = list(metrics) if metrics is not None else radar_metric_ids(results)
    df = df[df["method"].isin(methods) & df["metric"].isin(metrics)]
    table = df.groupby(["metric", "method"])["value"].agg(average).unstack("method")
    table = table.reindex(index=[m for m in metrics if m in table.index], columns=methods)
    return table.dropna(how="all")


def radar_magnitudes(scores: pd.DataFrame) -> pd.DataFrame:
    """:func:`radar_scores` as the chart plots them, lower is better on every axis: a signed metric's row (a
    bias, :attr:`lfbench.scoring.base.Metric.signed`) as its magnitude, as tables, ranks and the regression
    gate compare it (:meth:`~lfbench.scoring.base.Metric.badness`); every other row as it is."""
    signed = [m for m in scores.index if getattr(METRICS.find(m), "signed", False)]
    if not signed:
        return scores
    shown = scores.copy()
    shown.loc[signed] = shown.loc[signed].abs()
    return shown


def _radar_top(scores: pd.DataFrame) -> pd.Series:
    """Each axis's outer value: 1.2 x the largest value on it (1 if that is <= 0)."""
    vmax = scores.max(axis=1, skipna=True) * 1.2
    return vmax.where(vmax > 0, 1.0)


def radar_radii(scores: pd.DataFrame, rings: int = 4) -> pd.DataFrame:
    """Radii in [0, 1] of :func:`radar_scores`, per axis as the toolkit draws them: the axis runs from 0
    to vmax = 1.2 x the largest value on it (1 if that is <= 0), offset by one ring so 0 is not the
    centre: r = (value + vmax / rings) / (vmax + vmax / rings); a signed metric by its magnitude
    (:func:`radar_magnitudes`)."""
    scores = radar_magnitudes(scores)
    vmax = _radar_top(scores)
    step = vmax / rings
    return scores.add(step, axis=0).div(vmax + step, axis=0)


# --------------------------------------------------------------------------- drawing

@plain_text
def plot_pairwise(gt_by_scene: Mapping[str, np.ndarray], a_by_scene: Mapping[str, np.ndarray],
                  b_by_scene: Mapping[str, np.ndarray], labels: tuple[str, str], path: str | Path, *,
                  masks: Mapping[str, np.ndarray] | None = None, backgrounds: Mapping[str, np.ndarray] | None = None,
                  threshold: float = PAIRWISE_THRESHOLD, formats: Sequence[str] = ("png",),
                  per_row: int = 4) -> list[Path]:
    """Pairwise comparison maps of methods A and B (``labels``), one panel per scene both have, with
    the shares of pixels where each is better. Written as ``path`` in ``formats``."""
    scenes = [s for s in gt_by_scene if s in a_by_scene and s in b_by_scene]
    if not scenes:
        raise SpecError(f"{labels[0]} and {labels[1]} share no scene with ground truth")
    plt = pyplot()
    cols = min(per_row, len(scenes))
    rows = -(-len(scenes) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 3.3 * rows + 0.7), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, scene in zip(axes.flat, scenes, strict=False):
        mask = None if masks is None else masks.get(scene)
        bg = None if backgrounds is None else backgrounds.get(scene)
        gt, a, b = gt_by_scene[scene], a_by_scene[scene], b_by_scene[scene]
        ax.imshow(pairwise_image(gt, a, b, mask, threshold, background=bg), interpolation="nearest")
        share = pairwise_shares(pairwise_classes(gt, a, b, mask, threshold))
        ax.set_title(f"{scene}\nA better {share['a_better']:.1f}%, B better {share['b_better']:.1f}%", fontsize=8)
    add_colorbar(fig, list(axes.flat), PAIRWISE_CMAP, -PAIRWISE_LIMIT, PAIRWISE_LIMIT, "|A - gt| - |B - gt| (px)")
    fig.suptitle(f"A = {labels[0]}  vs  B = {labels[1]}: blue = A better, red = B better by > {threshold:g} px, "
                 "grey = tie (low resolution)", fontsize=9)
    return save_formats(fig, path, formats)


@plain_text
def plot_error_heatmaps(gt_by_scene: Mapping[str, np.ndarray], preds_by_scene: Mapping[str, Sequence[np.ndarray]],
                        path: str | Path, *, masks: Mapping[str, np.ndarray] | None = None, threshold: float = 0.07,
                        methods: Sequence[str] = (), formats: Sequence[str] = ("png",)) -> list[Path]:
    """One row per scene: the per-pixel median |gt - pred| over the methods (px, 0 .. 0.2) and the % of
    methods with |gt - pred| > ``threshold`` (the toolkit's heatmap)."""
    scenes = [s for s in gt_by_scene if preds_by_scene.get(s)]
    if not scenes:
        raise SpecError("no scene has both ground truth and maps for the error heatmaps")
    plt = pyplot()
    fig, axes = plt.subplots(len(scenes), 2, figsize=(7.4, 3.2 * len(scenes) + 0.6), squeeze=False)
    for row, scene in zip(axes, scenes, strict=True):
        mask = None if masks is None else masks.get(scene)
        preds = preds_by_scene[scene]
        med = median_error_map(gt_by_scene[scene], preds, mask)
        frac = bad_fraction_map(gt_by_scene[scene], preds, mask, threshold)
        row[0].imshow(heatmap_image(med, 0.0, MEDIAN_ERROR_LIMIT), interpolation="nearest")
        row[0].set_title(f"{scene}: median |gt - pred| over {len(preds)} methods", fontsize=8)
        row[1].imshow(heatmap_image(frac, 0.0, 100.0), interpolation="nearest")
        row[1].set_title(f"{scene}: % of methods with |gt - pred| > {threshold:g} px", fontsize=8)
        add_colorbar(fig, row[0], HEATMAP_CMAP, 0.0, MEDIAN_ERROR_LIMIT, "px")
        add_colorbar(fig, row[1], HEATMAP_CMAP, 0.0, 100.0, "%")
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    names = f" ({', '.join(methods)})" if methods else ""
    fig.suptitle(f"Error heatmaps over methods{names}, low resolution", fontsize=9)
    fig.tight_layout()
    return save_formats(fig, path, formats)


@plain_text
def radar_axis_name(metric_id: str) -> str:
    """A radar axis's label: the metric's name, |name| for a signed metric (drawn by its magnitude)."""
    metric = describe_metric(metric_id)
    return f"|{metric.name}|" if metric.signed else metric.name


def radar_figure(scores: pd.DataFrame, *, title: str = "", highlight: str | None = None,
                 labels: Mapping[str, str] | None = None, colours: Mapping[str, str] | None = None) -> Any:
    """The figure of :func:`plot_radar` (not saved): the chart at the left, the legend beside it with
    labels wrapped to fit the figure (plotting.legend_label)."""
    if len(scores.index) < 3:
        raise SpecError(f"a radar chart needs at least 3 metrics, got {len(scores.index)}")
    plt = pyplot()
    colours = colours if colours is not None else method_colours(list(scores.columns))
    radii = radar_radii(scores)
    n = len(scores.index)
    angles = (np.pi / 2 + np.arange(n) * 2 * np.pi / n) % (2 * np.pi)
    fig = plt.figure(figsize=(7.8, 5.6))
    ax = fig.add_axes((0.085, 0.08, 0.49, 0.78), projection="polar")
    ax.set_ylim(0, 1)
    ax.set_yticks([0.2, 0.4, 0.6, 0.8, 1.0])
    ax.set_yticklabels([])
    ax.set_xticks(angles)
    names = [(labels or {}).get(m, radar_axis_name(m)) for m in scores.index]
    ax.set_xticklabels([n.replace(": ", ":\n") for n in names], fontsize=8)
    ax.set_thetalim(0, 2 * np.pi)  # set_xticks may have narrowed the view to the ticks
    ax.grid(alpha=0.35)
    vmax = _radar_top(radar_magnitudes(scores))
    for angle, top in zip(angles, vmax, strict=True):
        for k in (1, 2, 3, 4):
            ax.text(angle + 0.09, 0.2 * (k + 1), f"{top * k / 4:.3g}", fontsize=6, color="0.45", ha="center",
                    va="center")  # ring values beside the axis, off the method lines' corners
    closed = np.r_[angles, angles[:1]]
    for method in scores.columns:
        r = radii[method].to_numpy(dtype=float)
        width = 2.6 if method == highlight else (1.0 if highlight else 1.8)
        ax.plot(closed, np.r_[r, r[:1]], linewidth=width, label=legend_label(method), color=colours.get(method),
                alpha=1.0 if method == highlight or not highlight else 0.7)
    ax.legend(loc="upper left", bbox_to_anchor=(1.12, 1.05), fontsize=8, frameon=False)
    fig.suptitle(title or "Median over scenes (outer ring = 1.2 x the largest value per axis; lower is better)",
                 fontsize=9)
    return fig


@plain_text
def plot_radar(scores: pd.DataFrame, path: str | Path, *, title: str = "", highlight: str | None = None,
               labels: Mapping[str, str] | None = None, colours: Mapping[str, str] | None = None,
               formats: Sequence[str] = ("png",)) -> list[Path]:
    """A radar chart of :func:`radar_scores` (rows metrics, columns methods): one closed line per
    method, axes scaled by :func:`radar_radii`, ring values printed on each axis. ``highlight``: a
    method drawn thicker (the others thinner); ``colours``: method -> colour (default:
    plotting.method_colours in the columns' order). Needs at least 3 metrics."""
    return save_formats(radar_figure(scores, title=title, highlight=highlight, labels=labels, colours=colours),
                        path, formats)


def toolkit_figures_from_scene_maps(results: Any, scene_maps: Iterable[Any], out_dir: str | Path, *,
                                    formats: Sequence[str] = ("png",),
                                    threshold: float = PAIRWISE_THRESHOLD) -> list[Path]:
    """The toolkit's figures for papers into ``out_dir``: ``radar`` (from the results), and from the maps
    already loaded (lfbench.reports.maps.SceneMaps, one per scene): ``error_heatmaps`` and
    ``pairwise_<A>_vs_<B>`` for every pair of methods, each in ``formats``. Reference methods (the oracle,
    ``results.references``) are compared with nothing."""
    out = Path(out_dir)
    written: list[Path] = []
    scores = radar_scores(results, methods=results.competitors)
    if len(scores.index) >= 3:
        written += plot_radar(scores, out / "radar", formats=formats, colours=method_colours(results.methods))
    gts, masks, centres, preds = {}, {}, {}, {}
    for sm in scene_maps:
        if sm.gt is None or not sm.preds:
            continue
        gts[sm.name], masks[sm.name], centres[sm.name] = sm.gt, sm.mask, sm.centre
        preds[sm.name] = sm.preds
    labels = [m for m in results.competitors if any(m in p for p in preds.values())]
    if not gts or not labels:  # nothing to compare (no maps, or only the references' maps)
        return written
    names, pair_names = file_names(labels, "method label"), FileNames("method pair")
    pairs = [(a, b, pair_names.claim(f"{a} vs {b}", f"pairwise_{names[a]}_vs_{names[b]}"))
             for i, a in enumerate(labels) for b in labels[i + 1:]]  # every name checked before drawing
    written += plot_error_heatmaps(gts, {s: [p[m] for m in labels if m in p] for s, p in preds.items()},
                                   out / "error_heatmaps", masks=masks, methods=labels, formats=formats)
    for a, b, name in pairs:
        a_maps = {s: p[a] for s, p in preds.items() if a in p}
        b_maps = {s: p[b] for s, p in preds.items() if b in p}
        if set(a_maps) & set(b_maps):
            written += plot_pairwise(gts, a_maps, b_maps, (a, b), out / name, masks=masks, backgrounds=centres,
                                     threshold=threshold, formats=formats)
    return written
