"""Figures of an ablation (PNG, written atomically through lfbench.reports.plotting): the beta curve and
accuracy against test time per interval, each with what the reference says beside ours (the error maps
per variant are lfbench.reports.writers.SceneFigures over the cells' saved maps)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from lfbench.reports.plotting import INTERPOLATION_COLOURS, pyplot, save_figure
from lfbench.reports.reference import Table4
from lfbench.utils.figure_text import plain_text


@plain_text
def beta_curve(frame: pd.DataFrame, records: pd.DataFrame, path: Path, ours: str, said: str | None = None) -> Path:
    """BadPix 0.07 (%) against the UAFL beta: the mean over scenes (line) and each scene (faint); the axis
    runs from the largest beta down to the smallest. ``said``: what the reference says about beta (title)."""
    plt = pyplot()
    cells = frame[frame["beta"].notna()].sort_values("beta")
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    bp = records[records["metric"] == "badpix_0.07"]
    scenes = list(dict.fromkeys(bp["scene"]))
    for scene in scenes:
        sel = bp[bp["scene"] == scene].set_index("method")["value"]
        ys = [sel.get(cid, np.nan) for cid in cells.index]
        ax.plot(cells["beta"], ys, color="0.75", linewidth=0.8, marker=".", markersize=3)
    ax.plot(cells["beta"], cells["badpix_0.07"], color="tab:red", marker="o", linewidth=2,
            label=f"mean over {len(scenes)} scene(s)")
    ax.invert_xaxis()
    ax.set_xlabel("UAFL beta")
    ax.set_ylabel("BadPix 0.07 (%)")
    ax.set_title(f"BadPix 0.07 vs beta: {ours}\n(grey: single scenes{f'; {said}' if said else ''})", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def _scatter(ax, xs: Sequence[float], ys: Sequence[float], intervals: Sequence[float], interps: Sequence[str],
             title: str, xlabel: str) -> None:
    done = set()
    for x, y, iv, ip in zip(xs, ys, intervals, interps, strict=True):
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        colour = INTERPOLATION_COLOURS.get(ip, "tab:gray")
        ax.scatter([x], [y], color=colour, s=40, label=ip if ip not in done else None, zorder=3)
        done.add(ip)
        ax.annotate(f"{iv:g}", (x, y), textcoords="offset points", xytext=(5, 4), fontsize=8)
    # bilinear points joined in order of the interval: the accuracy/time trade-off of the interval
    pts = sorted((x, y) for x, y, ip in zip(xs, ys, interps, strict=True) if ip == "bilinear" and np.isfinite(x)
                 and np.isfinite(y))
    if len(pts) > 1:
        ax.plot(*zip(*pts, strict=True), color=INTERPOLATION_COLOURS["bilinear"], linewidth=1, alpha=0.5)
    finite = [x for x in xs if np.isfinite(x) and x > 0]
    if finite and max(finite) / min(finite) > 8:  # a log axis with plain labels (1, 2, 5, 10, ...)
        from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(xlabel)
    ax.set_ylabel("BadPix 0.07 (%)")
    ax.set_title(title, fontsize=8)
    ax.grid(alpha=0.3, which="both")
    if done:
        ax.legend(fontsize=7, title="interpolation (labels: interval px)", title_fontsize=7)


@plain_text
def accuracy_vs_time(frame: pd.DataFrame, paper: pd.DataFrame | None, path: Path, ours: str, time_label: str,
                     layout: Table4 | None = None) -> Path:
    """BadPix 0.07 against test time for each interval and interpolation: ours and, beside, the reference's
    Table IV (``paper``, read as its ``layout`` says)."""
    plt = pyplot()
    panels = 2 if paper is not None and layout is not None else 1
    fig, axes = plt.subplots(1, panels, figsize=(6.0 * panels, 4.4), squeeze=False)
    _scatter(axes[0, 0], frame["test_s"].astype(float).tolist(), frame["badpix_0.07"].astype(float).tolist(),
             frame["interval"].astype(float).tolist(), frame["interpolation"].astype(str).tolist(),
             f"{ours}", f"test time (s), {time_label}")
    if paper is not None and layout is not None:
        _scatter(axes[0, 1], pd.to_numeric(paper[layout.test_seconds], errors="coerce").tolist(),
                 pd.to_numeric(paper["badpix_0.07"], errors="coerce").tolist(),
                 pd.to_numeric(paper["interval"], errors="coerce").tolist(),
                 paper["interpolation"].astype(str).str.strip().tolist(),
                 layout.figure_title, layout.figure_time_label)
    fig.suptitle("Accuracy vs test time per disparity interval", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
