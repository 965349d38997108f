"""Tables and figures from an existing results.json (nothing is re-run): the library side of
``lfbench report``.

Writes OUT/table_per_scene.* and OUT/table_average.* (the tables ``lfbench evaluate`` writes) and,
with the paper's tables, OUT/table_per_scene_paper.* and OUT/table_average_paper.* with the paper's
numbers in labelled columns/rows. The BadPix series come from saved maps (``maps``, default
RESULTS_DIR/maps where the run saved them and its scenes are at hand: per-scene overviews, exact curves and the
toolkit's figure types), else from a saved curve CSV (``curves``,
default RESULTS_DIR/figures/badpix_series.csv), else from the BadPix thresholds the results hold.
With ``html``, OUT/html/index.html (lfbench.reports.html).

The files appear together or not at all (lfbench.utils.outputs): they are written into a staging
folder inside OUT and committed as one set that replaces the previous report there. OUT may not be
the results' own folder nor hold another run's results: the report's set would replace that run's files.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from lfbench.data.dataset import open_datasets
from lfbench.data.scene import Benchmark
from lfbench.reports.maps import MAPS_DIR, load_scene_maps, map_folders
from lfbench.reports.paper import PaperTables
from lfbench.reports.tables import TABLE_FORMATS, Table
from lfbench.reports.writers import (
    FIGURES_DIR,
    CurveFigures,
    OutputWriter,
    RunOutputs,
    SceneFigures,
    Site,
    Tables,
    ToolkitFigures,
    drive_writers,
    scene_map_predictions,
)
from lfbench.results import Results
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.errors import DataError
from lfbench.utils.outputs import check_within, read_manifest, staged_outputs

__all__ = ["ReportOutcome", "report_from_results"]

log = logging.getLogger(__name__)


@dataclass
class ReportOutcome:
    """What a report wrote: the tables by name, every file, where the BadPix series came from, the
    figure folder and the HTML index (or None)."""

    tables: dict[str, Table | pd.DataFrame]  # our Table I and II as Tables, the tables beside a paper as frames
    written: list[Path] = field(default_factory=list)
    curves_source: str = ""
    figures: Path | None = None
    html_index: Path | None = None


def report_from_results(results_path: str | Path, out: str | Path, *,
                        formats: Sequence[tuple[str, str]] = TABLE_FORMATS, paper: PaperTables | None = None,
                        paper_methods: Sequence[str] = (), curves: str | Path | None = None,
                        maps: str | Path | None = None, data: str | Path | Sequence[str | Path] | None = None,
                        figure_formats: Sequence[str] = ("png",), html: bool = False) -> ReportOutcome:
    """Tables, figures (and the HTML report) into ``out`` from the results at ``results_path`` (a
    results.json or its folder). ``paper``: the paper's tables (lfbench.reports.paper.load_paper) or
    None, showing ``paper_methods`` (default: the paper's own default methods); ``data``: the scenes'
    data root, or several, for ``maps`` (default: the roots the results record). Everything a wrong input can fail on
    is checked before the first file is written."""
    results_path, out = Path(results_path), Path(out)
    results = Results.read(results_path)
    if not results.records:
        raise DataError("the results hold no records", results_path)
    results_dir = results_path if results_path.is_dir() else results_path.parent
    tables = Tables(formats=formats, paper=paper, paper_methods=paper_methods)  # unknown paper methods: refused
    curves_path = Path(curves) if curves is not None else results_dir / FIGURES_DIR / "badpix_series.csv"
    if curves is not None and not curves_path.is_file():
        raise DataError("curve file not found", curves_path)
    if curves is None and curves_path.is_symlink():
        check_within(curves_path, results_dir, "the results folder")
    if maps is None:  # the maps the run saved beside its results (evaluate --save-maps), where its scenes are
        maps = _saved_maps(results_dir, results, data)
    figures = SceneFigures(files=True) if maps is not None else CurveFigures(curves_path)
    site = Site(data_root=data, maps=maps, paper=paper, paper_methods=paper_methods)
    writers: list[OutputWriter] = [tables, figures, *([ToolkitFigures(figure_formats)] if maps is not None else []),
                                   *([site] if html else [])]
    check_report_folder(out, results_dir)
    with staged_outputs(out) as outputs:  # OUT checked and its staging folder made before any work
        run = RunOutputs(stage=outputs.stage, rules=ScoringRules.from_meta(results.meta), results=results,
                         source=results_dir)
        if maps is not None:  # the saved maps, loaded once, handed as predictions to every writer
            _load_maps(run, Path(maps), data, results_path)
        staged = drive_writers(writers, run, predictions=scene_map_predictions(run.scene_maps.values()))
        written = outputs.commit_written(staged)
    return ReportOutcome(tables=tables.tables, written=written, figures=out / FIGURES_DIR,
                         curves_source=f"saved maps in {maps}" if maps is not None else figures.source,
                         html_index=outputs.final(site.index) if html else None)


def _saved_maps(results_dir: Path, results: Results, data: str | Path | Sequence[str | Path] | None) -> Path | None:
    """RESULTS_DIR/maps when the run saved its maps there (a real folder, not a link) and the scenes' data roots
    (``data``, else the roots the results record) are at hand to draw them on; else None (the series then come
    from saved curves or the results' thresholds). DataError when a saved folder leads out of it."""
    saved = results_dir / MAPS_DIR
    if saved.is_symlink() or not saved.is_dir():
        return None
    for entry in sorted(saved.iterdir()):  # a folder leading out is refused, drawn or not
        check_within(entry, saved, "the maps folder")
    roots = Benchmark.root_list(data) or results.data_roots
    if not roots or not all(Path(r).is_dir() for r in roots):
        log.info("saved maps in %s are not drawn: the data root of their scenes is not at hand (give --data)", saved)
        return None
    return saved


def _load_maps(run: RunOutputs, maps: Path, data: str | Path | Sequence[str | Path] | None,
               results_path: Path) -> None:
    """The results' scenes of the data root (``data``, else the roots the results record) and their saved
    maps under ``maps``, into ``run`` (scenes, maps, scene_maps)."""
    roots = Benchmark.root_list(data) or run.results.data_roots
    if not roots:
        raise DataError("--maps needs --data ROOT (the results do not record their data root)", results_path)
    run.scenes = open_datasets(roots, run.results.meta.get("dataset"))[2].named(run.results.scenes)
    run.maps = map_folders(maps, run.results.methods)
    run.scene_maps = {s.name: load_scene_maps(s, run.maps, run.rules.border_px) for s in run.scenes if s.has_gt()}


def check_report_folder(out: Path, results_dir: Path) -> None:
    """DataError when ``out`` is the results' own folder or holds another run's results: the report's
    set would replace that run's files (results.json, maps, figures)."""
    if out.is_dir() and results_dir.is_dir() and out.resolve() == results_dir.resolve():
        raise DataError("is the folder of the results being reported; a report there would replace the run's own "
                        "files: choose another --out", out)
    if out.is_dir() and "results.json" in read_manifest(out):
        raise DataError("holds the results of a run (results.json); a report there would replace that run's files: "
                        "choose another --out", out)
