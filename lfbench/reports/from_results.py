"""Tables and figures from an existing results.json (nothing is re-run): the library side of
``lfbench report``.

Writes OUT/table_per_scene.* and OUT/table_average.* (the tables ``lfbench evaluate`` writes) and,
with the paper's tables, OUT/table_per_scene_paper.* and OUT/table_average_paper.* with the paper's
numbers in labelled columns/rows. The BadPix series come from saved maps (``maps``: per-scene
overviews, exact curves and the toolkit's figure types), else from a saved curve CSV (``curves``,
default RESULTS_DIR/figures/badpix_series.csv), else from the BadPix thresholds the results hold.
With ``html``, OUT/html/index.html (lfbench.reports.html).

The files appear together or not at all (lfbench.utils.outputs): they are written into a staging
folder inside OUT and committed as one set that replaces the previous report there. OUT may not be
the results' own folder nor hold another run's results: the report's set would replace that run's files.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from lfbench.reports.tables import TABLE_FORMATS, average_table, per_scene_table, write_table
from lfbench.results import Results
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.errors import DataError
from lfbench.utils.outputs import check_within, staged_outputs

__all__ = ["ReportOutcome", "report_from_results"]


@dataclass
class ReportOutcome:
    """What a report wrote: the tables by name, every file, where the BadPix series came from, the
    figure folder and the HTML index (or None)."""

    tables: dict[str, pd.DataFrame]
    written: list[Path] = field(default_factory=list)
    curves_source: str = ""
    figures: Path | None = None
    html_index: Path | None = None


def report_from_results(results_path: str | Path, out: str | Path, *,
                        formats: Sequence[tuple[str, str]] = TABLE_FORMATS, paper: Any = None,
                        paper_methods: Sequence[str] = ("SubFocal",), curves: str | Path | None = None,
                        maps: str | Path | None = None, data: str | Path | None = None,
                        figure_formats: Sequence[str] = ("png",), html: bool = False) -> ReportOutcome:
    """Tables, figures (and the HTML report) into ``out`` from the results at ``results_path`` (a
    results.json or its folder). ``paper``: the paper's tables (lfbench.reports.paper.load_paper) or
    None; ``data``: the scenes' data root for ``maps`` (default: the one the results record).
    Everything a wrong input can fail on is checked before the first file is written."""
    results_path, out = Path(results_path), Path(out)
    results = Results.read(results_path)
    if not results.records:
        raise DataError("the results hold no records", results_path)
    results_dir = results_path if results_path.is_dir() else results_path.parent
    if paper is not None:
        for m in paper_methods:
            paper.resolve_method(m)  # unknown names fail before anything is written
    curves_path = Path(curves) if curves is not None else results_dir / "figures" / "badpix_series.csv"
    if curves is not None and not curves_path.is_file():
        raise DataError("curve file not found", curves_path)
    if curves is None and curves_path.is_symlink():
        check_within(curves_path, results_dir, "the results folder")

    per_scene, average = per_scene_table(results), average_table(results)
    tables = {"per_scene": per_scene, "average": average}
    if paper is not None:
        from lfbench.reports.paper import average_with_paper, per_scene_with_paper

        tables["per_scene_paper"] = per_scene_with_paper(per_scene, paper, list(paper_methods))
        tables["average_paper"] = average_with_paper(average, paper, results.scenes, list(paper_methods))
    check_report_folder(out, results_dir)
    with staged_outputs(out) as outputs:  # OUT checked and its staging folder made before any work
        outcome = _write_report(outputs.stage, results, results_path, results_dir, tables, formats=formats,
                                paper=paper, paper_methods=paper_methods, curves_path=curves_path, maps=maps,
                                data=data, figure_formats=figure_formats, html=html)
        outputs.commit([p.relative_to(outputs.stage).parts[0] for p in outcome.written])
    outcome.written = [outputs.final(p) for p in outcome.written]
    outcome.figures = out / "figures"
    if outcome.html_index is not None:
        outcome.html_index = outputs.final(outcome.html_index)
    return outcome


def check_report_folder(out: Path, results_dir: Path) -> None:
    """DataError when ``out`` is the results' own folder or holds another run's results: the report's
    set would replace that run's files (results.json, maps, figures)."""
    from lfbench.utils.outputs import read_manifest

    if out.is_dir() and results_dir.is_dir() and out.resolve() == results_dir.resolve():
        raise DataError("is the folder of the results being reported; a report there would replace the run's own "
                        "files: choose another --out", out)
    if out.is_dir() and "results.json" in read_manifest(out):
        raise DataError("holds the results of a run (results.json); a report there would replace that run's files: "
                        "choose another --out", out)


def _write_report(out: Path, results: Results, results_path: Path, results_dir: Path,
                  tables: dict[str, pd.DataFrame], *, formats: Sequence[tuple[str, str]], paper: Any,
                  paper_methods: Sequence[str], curves_path: Path, maps: str | Path | None,
                  data: str | Path | None, figure_formats: Sequence[str], html: bool) -> ReportOutcome:
    """The files of :func:`report_from_results`, written into the staging folder ``out``."""
    from lfbench.reports import figures as fig

    outcome = ReportOutcome(tables=tables, figures=out / "figures")
    for name, table in tables.items():
        outcome.written += write_table(table, out, f"table_{name}", formats=formats)

    fig_dir = out / "figures"
    scenes = scene_maps = None  # with maps: the scenes discovered and their maps loaded once, for figures and site
    if maps is not None:
        from lfbench.data.scene import Benchmark
        from lfbench.reports.maps import load_scene_maps, map_folders
        from lfbench.reports.toolkit_figures import toolkit_figures_from_scene_maps

        root = data or (Path(results.meta["data_root"]) if results.meta.get("data_root") else None)
        if root is None:
            raise DataError("--maps needs --data ROOT (the results do not record their data root)", results_path)
        scenes = Benchmark.discover(root).named(results.scenes)
        folders = map_folders(Path(maps), results.methods)
        rules = ScoringRules.from_meta(results.meta)  # the curves use the rules the results were scored with
        scene_maps = {s.name: load_scene_maps(s, folders, rules.border_px) for s in scenes if s.has_gt()}
        writer = fig.SceneFigureWriter(fig_dir, rules=rules)
        for sm in scene_maps.values():
            for label, pred in sm.preds.items():
                writer.add(label, sm.scene, pred)
        outcome.written += sorted(writer.written)
        outcome.written += toolkit_figures_from_scene_maps(results, scene_maps.values(), fig_dir / "toolkit",
                                                           formats=list(figure_formats))
        outcome.curves_source = f"saved maps in {maps}"
    elif curves_path.is_file():
        outcome.written += fig.draw_badpix_curves(fig.read_curves_csv(curves_path), fig_dir)
        outcome.curves_source = str(curves_path)
    else:
        series = fig.curves_from_records(results)
        outcome.written.append(fig.plot_badpix_series(series, fig_dir / "badpix_series.png",
                                                      "BadPix at the thresholds in the results, mean over scenes",
                                                      markers=True))
        outcome.curves_source = ("the BadPix thresholds in the results (no curves saved: run evaluate --figures "
                                 "for full curves)")

    if html:
        from lfbench.reports.html import SITE_DIR, build_site, site_inputs

        inputs = site_inputs(results, results_dir, data_root=data, maps=maps, scenes=scenes, scene_maps=scene_maps,
                             paper=paper, paper_methods=list(paper_methods) or ["SubFocal"])
        outcome.html_index = build_site(inputs, out / SITE_DIR)
        outcome.written.append(outcome.html_index)
    return outcome
