"""Figures of an ablation (PNG, written atomically through lfbench.reports.plotting), as the spec's reference
table declares them (lfbench.reports.reference.PaperTable.figure): a metric against the table's axis, and a
metric against test time per variant, each with what the reference says beside ours. Axis labels come
from the metric's definition (lfbench.scoring.base.Metric). The error maps per variant are
lfbench.reports.writers.SceneFigures over the cells' saved maps."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from lfbench.reports.plotting import INTERPOLATION_COLOURS, pyplot, save_figure
from lfbench.scoring.metrics import get_metric
from lfbench.utils.figure_text import plain_text

__all__ = ["Points", "accuracy_vs_time", "metric_curve"]


@plain_text
def metric_curve(means: pd.Series, xs: pd.Series, records: pd.DataFrame, metric: str, path: Path, ours: str,
                 axis: str, said: str | None = None, *, descending: bool = False) -> Path:
    """``metric`` against a numeric axis (``xs``: cell id -> the cell's value): the mean over scenes (``means``,
    line) and each scene (faint, from the long ``records``); ``descending``: the axis runs from the largest
    value down. ``said``: what the reference says about it (title)."""
    plt = pyplot()
    label = get_metric(metric).label
    order = xs[xs.notna()].sort_values().index
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    sel = records[records["metric"] == metric]
    scenes = list(dict.fromkeys(sel["scene"]))
    for scene in scenes:
        values = sel[sel["scene"] == scene].set_index("method")["value"]
        ax.plot(xs[order], [values.get(cid, np.nan) for cid in order], color="0.75", linewidth=0.8, marker=".",
                markersize=3)
    ax.plot(xs[order], means[order], color="tab:red", marker="o", linewidth=2,
            label=f"mean over {len(scenes)} scene(s)")
    if descending:
        ax.invert_xaxis()
    ax.set_xlabel(axis)
    ax.set_ylabel(label)
    ax.set_title(f"{label} vs {axis}: {ours}\n(grey: single scenes{f'; {said}' if said else ''})", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


@dataclass(frozen=True)
class Points:
    """One panel of :func:`accuracy_vs_time`: x (test time, s) and y (the metric) per variant, each point's
    annotation (e.g. its interval) and group (its colour, e.g. its interpolation), the panel's title and x label."""

    xs: Sequence[float]
    ys: Sequence[float]
    notes: Sequence[str]
    groups: Sequence[str]
    title: str
    xlabel: str


def _scatter(ax, points: Points, metric: str, note: str, group: str) -> None:
    done = set()
    fallback = iter(["tab:gray", "tab:olive", "tab:cyan", "tab:pink", "tab:brown"] * 4)
    colours: dict[str, str] = {}
    for x, y, text, g in zip(points.xs, points.ys, points.notes, points.groups, strict=True):
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        colour = colours.setdefault(g, INTERPOLATION_COLOURS.get(g) or next(fallback))
        ax.scatter([x], [y], color=colour, s=40, label=(g or None) if g not in done else None, zorder=3)
        done.add(g)
        ax.annotate(text, (x, y), textcoords="offset points", xytext=(5, 4), fontsize=8)
    # each group's points joined in order of time: the accuracy/time trade-off along the annotated axis
    for g, colour in colours.items():
        pts = sorted((x, y) for x, y, h in zip(points.xs, points.ys, points.groups, strict=True)
                     if h == g and np.isfinite(x) and np.isfinite(y))
        if len(pts) > 1:
            ax.plot(*zip(*pts, strict=True), color=colour, linewidth=1, alpha=0.5)
    finite = [x for x in points.xs if np.isfinite(x) and x > 0]
    if finite and max(finite) / min(finite) > 8:  # a log axis with plain labels (1, 2, 5, 10, ...)
        from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(points.xlabel)
    ax.set_ylabel(get_metric(metric).label)
    ax.set_title(points.title, fontsize=8)
    ax.grid(alpha=0.3, which="both")
    if any(done):
        ax.legend(fontsize=7, title=f"{group} (labels: {note})" if group else None, title_fontsize=7)


@plain_text
def accuracy_vs_time(ours: Points, paper: Points | None, metric: str, path: Path, note: str, group: str) -> Path:
    """``metric`` against test time for each variant: ours and, beside, the reference's (``paper``).
    ``note``: what the point labels are (e.g. 'interval (px)'); ``group``: what the colours are."""
    plt = pyplot()
    panels = 2 if paper is not None else 1
    fig, axes = plt.subplots(1, panels, figsize=(6.0 * panels, 4.4), squeeze=False)
    _scatter(axes[0, 0], ours, metric, note, group)
    if paper is not None:
        _scatter(axes[0, 1], paper, metric, note, group)
    fig.suptitle(f"{get_metric(metric).label} vs test time per {note}", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
