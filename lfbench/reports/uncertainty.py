"""The uncertainty report of ``lfbench evaluate --uncertainty``: OUT/uncertainty.csv, OUT/table_uncertainty.md
and the sparsification figures (:func:`plot_sparsification`), from the ratings an
:class:`lfbench.scoring.uncertainty.UncertaintyCollector` gathered (AUSE / AURG of each method's
uncertainty map against its error, :mod:`lfbench.scoring.uncertainty`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from lfbench.reports.plotting import method_colours, pyplot, save_figure
from lfbench.reports.tables import render
from lfbench.scoring.uncertainty import Sparsification, UncertaintyCollector, average_sparsification, uncertainty_table
from lfbench.utils.atomic import write_text
from lfbench.utils.figure_text import plain_text

__all__ = ["plot_sparsification", "write_uncertainty_report"]


ABS_LABEL = "mean abs. error (EPE)"  # the sparsification's own measure (not a metric of lfbench.scoring.metrics)


def _measure_label(sp: Sparsification) -> str:
    """The y label of a sparsification curve: its measure's metric name (lfbench.scoring.base.Metric), or the
    mean absolute error."""
    from lfbench.scoring.metrics import METRICS

    found = METRICS.find(sp.measure) if sp.measure != "abs" else None
    name = ABS_LABEL if sp.measure == "abs" else found.name if found is not None else sp.measure
    suffix = " (relative)" if sp.normalized else f" [{sp.unit}]" if sp.unit else ""
    return f"{name} of remaining pixels{suffix}"


@plain_text
def plot_sparsification(results: Sparsification | Mapping[str, Sparsification], path: str | Path,
                        title: str | None = None, dpi: int = 110) -> Path:
    """Draw sparsification (solid), oracle (dashed) and random (dotted) curves with AUSE/AURG in the
    legend, one colour per entry of ``results`` (label -> Sparsification); writes a PNG atomically."""
    plt = pyplot()
    items = {"": results} if isinstance(results, Sparsification) else dict(results)
    if not items:
        raise ValueError("nothing to plot")
    fig, ax = plt.subplots(figsize=(5.6, 4.0))
    try:
        colours = method_colours(list(items))
        for label, sp in items.items():
            c = colours[label]
            prefix = f"{label}: " if label else ""
            ax.plot(sp.fractions, sp.curve, color=c, lw=1.8,
                    label=f"{prefix}uncertainty (AUSE {sp.ause:.4g}, AURG {sp.aurg:.4g})")
            ax.plot(sp.fractions, sp.oracle, color=c, lw=1.2, ls="--", label=f"{prefix}oracle")
            ax.plot(sp.fractions, sp.random, color=c, lw=1.0, ls=":", label=f"{prefix}random")
        first = next(iter(items.values()))
        ax.set_xlabel("fraction of pixels removed (most uncertain first)")
        ax.set_ylabel(_measure_label(first))
        ax.set_xlim(0, 1)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best")
        if title:
            ax.set_title(title, fontsize=9)
        fig.tight_layout()
    except BaseException:
        plt.close(fig)
        raise
    return save_figure(fig, path, dpi=dpi)


def write_uncertainty_report(collector: UncertaintyCollector, out: str | Path) -> list[Path]:
    """OUT/uncertainty.csv (see :func:`uncertainty_table`), OUT/table_uncertainty.md and one figure per
    measure, OUT/figures/sparsification_<measure>.png (curves averaged over scenes, one colour per
    method). Returns the written paths (none when no method predicted an uncertainty)."""
    out = Path(out)
    if not collector.items:
        return []
    table = uncertainty_table(collector.items)
    write_text(out / "uncertainty.csv", table.to_csv(index=False))
    shown = table.assign(ause=table.ause.map("{:.4g}".format), aurg=table.aurg.map("{:.4g}".format),
                         full=table.full.map("{:.4g}".format), oracle_half=table.oracle_half.map("{:.4g}".format))
    lines = ["Uncertainty quality: sparsification of each method's uncertainty map against its error "
             "(AUSE: 0 = ranks pixels like the true error; AURG > 0: better than a random ranking).", "",
             render(shown.set_index("method"), "markdown")]  # labels escaped as in every table
    write_text(out / "table_uncertainty.md", "\n".join(lines))
    written = [out / "uncertainty.csv", out / "table_uncertainty.md"]
    for measure in collector.measures:
        curves: dict[str, Sparsification] = {}
        for method in dict.fromkeys(m for m, _, _ in collector.items):
            sps = [sp for (m, _, me), sp in collector.items.items() if m == method and me == measure]
            if sps:
                curves[method] = average_sparsification(sps)
        if curves:
            path = out / "figures" / f"sparsification_{measure}.png"
            n = len({s for _, s, _ in collector.items})
            written.append(plot_sparsification(curves, path, title=f"sparsification, mean of {n} scene(s)"))
    return written
