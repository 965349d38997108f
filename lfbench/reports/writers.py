"""Output writers: every kind of output of a run is one writer, shared by ``lfbench evaluate``, ``demo``,
``report`` and ``ablate`` (its cells and its report).

A writer sees each prediction as it is made (:meth:`OutputWriter.on_prediction`: draw a figure row at
once, keep the pixel errors the intervals need, save the map), then writes its files into the run's
staged output set (:meth:`OutputWriter.write`, into ``run.stage``; lfbench.utils.outputs commits the set
as a whole). A command is a list of writers over a source of predictions, driven by the one
:func:`drive_writers`: methods run on scenes (lfbench.runs.folder.evaluate_to_folder) or saved maps read
back (lfbench.reports.from_results, lfbench.ablation.report), so a new kind of output is one new writer,
for example the worst scene of each method as a CSV::

    class WorstScenes(OutputWriter):
        def write(self, run):
            frame = run.results.to_frame()
            bp = frame[frame["metric"] == "badpix_0.07"]
            worst = bp.loc[bp.groupby("method")["value"].idxmax(), ["method", "scene", "value"]]
            write_text(run.stage / "worst_scenes.csv", worst.to_csv(index=False))
            return [run.stage / "worst_scenes.csv"]

    evaluate_to_folder(methods, scenes, out, writers=[Tables(), WorstScenes()])

The writers here: :class:`Tables` (Tables I/II, with a reference's numbers beside ours), :class:`Maps`
(every prediction in the submission layout), :class:`SceneFigures` (per-scene overviews and BadPix
series), :class:`CurveFigures` (the BadPix series from saved curves or the results' thresholds),
:class:`ToolkitFigures` (radar, error heatmaps, pairwise maps from saved maps), :class:`BootstrapCIs`
(ci.csv and table_ci_per_scene), :class:`UncertaintyRatings` (sparsification, AUSE/AURG) and
:class:`Site` (the HTML report, drawn from the staged files; it comes last).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from lfbench.data.scene import LightField
from lfbench.method.base import Prediction
from lfbench.reports.figures import (
    Curve,
    SceneFigureWriter,
    Thresholds,
    curves_from_records,
    draw_badpix_curves,
    plot_mean_series,
    read_curves_csv,
)
from lfbench.reports.maps import MAPS_DIR, MapSaver, SceneMaps
from lfbench.reports.paper import PaperTables, average_with_paper, per_scene_with_paper
from lfbench.reports.paper_scenes import RUN_RUNTIME_COLUMN, scene_table_with_paper, scene_tables
from lfbench.reports.plotting import method_colours
from lfbench.reports.tables import TABLE_FORMATS, Table, average_rows, per_scene_rows, write_table
from lfbench.reports.toolkit_figures import toolkit_figures_from_scene_maps
from lfbench.results import Results
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.atomic import write_text

if TYPE_CHECKING:  # the site's, the intervals' and the uncertainty's modules: imported by the writers that use them
    import pandas as pd

    from lfbench.reports.html import SiteInputs, SiteSection
    from lfbench.scoring.stats import ErrorCollector
    from lfbench.scoring.uncertainty import UncertaintyCollector

__all__ = ["FIGURES_DIR", "BootstrapCIs", "CIOptions", "CurveFigures", "Maps", "OutputWriter", "PredictionSink",
           "RunOutputs", "SceneFigures", "Site", "Tables", "ToolkitFigures", "UncertaintyRatings", "drive_writers",
           "paper_scene_sections", "scene_map_predictions"]

log = logging.getLogger(__name__)

FIGURES_DIR = "figures"


@dataclass
class RunOutputs:
    """What the writers of one output set share. ``stage``: the staging folder they write into;
    ``rules``: how the predictions were scored; ``scenes``: the light fields scored (ground truth and
    centre view for drawing); ``results``: set before the write steps; ``source``: the folder the results
    were read from (a report: its ci.csv and maps), None when they are made in this run (the stage holds
    them); ``maps``: method label -> submission folder of saved maps; ``scene_maps``: those maps already
    loaded per scene (lfbench.reports.maps.load_scene_maps); ``curves``: the BadPix series a writer of the
    set computed ((method label, scene) -> lfbench.reports.figures.Curve: :class:`SceneFigures`), which
    the site draws instead of computing them again."""

    stage: Path
    rules: ScoringRules = field(default_factory=ScoringRules)
    scenes: Sequence[LightField] = ()
    results: Results | None = None
    source: Path | None = None
    maps: Mapping[str, Path] = field(default_factory=dict)
    scene_maps: Mapping[str, SceneMaps] = field(default_factory=dict)
    curves: dict[tuple[str, str], Curve] = field(default_factory=dict)
    progress: bool = False
    metric_ids: Sequence[str] = ()

    @property
    def thresholds(self) -> Thresholds:
        """The BadPix thresholds the figures show: those of the run's protocol (``metric_ids``, else the
        results' :attr:`~lfbench.results.Results.protocol_metrics`)."""
        ids = self.metric_ids or (self.results.protocol_metrics if self.results is not None else ())
        return Thresholds.of_metrics(ids)

    @property
    def folder(self) -> Path:
        """Where the run's own files are read back from: ``source``, else the stage."""
        return self.source if self.source is not None else self.stage


class OutputWriter:
    """One kind of output of a run. Override what the output needs: :meth:`start` (before the first
    prediction), :meth:`on_prediction` (each prediction as it is made) and :meth:`write` (the files,
    into ``run.stage``; returns the files and folders written)."""

    def start(self, run: RunOutputs) -> None:
        """Called once, after the staging folder is made and before any prediction."""

    def on_prediction(self, label: str, scene: LightField, pred: Prediction) -> None:
        """Called with each prediction (``label``: the name its records get)."""

    def write(self, run: RunOutputs) -> list[Path]:
        """Write this output into ``run.stage``; returns the paths written (files or folders)."""
        return []


PredictionSink = Callable[[str, LightField, Prediction], None]


def drive_writers(writers: Sequence[OutputWriter], run: RunOutputs, *,
                  predictions: Iterable[tuple[str, LightField, Prediction]] = (),
                  produce: Callable[[PredictionSink], Iterable[Path]] | None = None) -> list[Path]:
    """The one driver of output writers (evaluate, report, ablate): every writer's start, each prediction to
    every writer, then their writes in order (the site last); returns the paths staged, which the caller
    commits as one set. The predictions are saved ones (``predictions``: (label, scene, prediction)) or
    made now by ``produce(sink)``, which hands each to ``sink``, sets ``run.results`` and returns the files
    it staged itself (results.json and .csv: they come first)."""
    for writer in writers:
        writer.start(run)

    def sink(label: str, scene: LightField, pred: Prediction) -> None:
        for writer in writers:
            writer.on_prediction(label, scene, pred)

    staged = list(produce(sink)) if produce is not None else []
    for label, scene, pred in predictions:
        sink(label, scene, pred)
    return [*staged, *(path for writer in writers for path in writer.write(run))]


def scene_map_predictions(scene_maps: Iterable[SceneMaps]) -> Iterator[tuple[str, LightField, Prediction]]:
    """The maps already loaded per scene (lfbench.reports.maps.SceneMaps) as predictions, scene by scene."""
    for sm in scene_maps:
        for label, disparity in sm.preds.items():
            yield label, sm.scene, Prediction(disparity=disparity)


def _named(label: str) -> Any:
    """What the scoring collectors read of a method: its label."""
    return SimpleNamespace(label=label)


# --------------------------------------------------------------------------- tables

class Tables(OutputWriter):
    """Table I (``table_per_scene``) and Table II (``table_average``) in ``formats``, with ``caption``
    lines; with a reference's numbers (``paper``: lfbench.reports.paper.PaperTables), also
    ``table_per_scene_paper`` and ``table_average_paper`` showing ``paper_methods`` beside ours, under
    ``paper_caption``. After the write, ``tables`` holds the tables by name."""

    def __init__(self, *, formats: Sequence[tuple[str, str]] = TABLE_FORMATS, caption: Sequence[str] = (),
                 paper: PaperTables | None = None, paper_methods: Sequence[str] = (),
                 paper_caption: Sequence[str] = ()) -> None:
        self.formats, self.caption = formats, list(caption)
        self.paper, self.paper_caption = paper, list(paper_caption)
        self.paper_methods = [paper.resolve_method(m) for m in paper_methods] if paper is not None else []
        self.tables: dict[str, Table | pd.DataFrame] = {}

    def write(self, run: RunOutputs) -> list[Path]:
        per_scene, average = per_scene_rows(run.results), average_rows(run.results)  # no pandas without a paper
        self.tables = {"per_scene": per_scene, "average": average}
        meta = run.results.meta
        if self.paper is not None and not per_scene.empty and self.paper.shows("table1", meta):
            self.tables["per_scene_paper"] = per_scene_with_paper(per_scene.to_frame(), self.paper,
                                                                  self.paper_methods)
            self.tables["average_paper"] = average_with_paper(average.to_frame(), self.paper, run.results.scenes,
                                                              self.paper_methods)
        captions = {}
        for section in paper_scene_sections(run.results, self.paper):  # e.g. Table III beside UrbanLF-Syn results
            self.tables[f"{section.id}_paper"] = section.table
            captions[f"{section.id}_paper"] = list(section.caption)
        written = []
        for name, table in self.tables.items():
            caption = captions.get(name) or (self.paper_caption if name.endswith("_paper") else self.caption)
            caption = with_synthetic_line(caption, run.results)
            written += write_table(table, run.stage, f"table_{name}", caption, formats=self.formats)
        return written


def with_synthetic_line(caption: Sequence[str], results: Results) -> list[str]:
    """``caption`` with :data:`~lfbench.data.provenance.SYNTHETIC_CAPTION` under its first line when the results
    were scored on synthetic data (``meta.synthetic``) and it does not say so yet."""
    from lfbench.data.provenance import SYNTHETIC_CAPTION

    caption = list(caption)
    if results.meta.get("synthetic") is True and SYNTHETIC_CAPTION not in caption:
        caption.insert(min(1, len(caption)), SYNTHETIC_CAPTION)
    return caption


def paper_scene_sections(results: Results, paper: PaperTables | None) -> list[SiteSection]:
    """The paper's per-scene tables of the results' dataset beside ours (lfbench.reports.paper_scenes), as
    sections: the report's table_<id>_paper files and tables on the site's index page."""
    if paper is None:
        return []
    from lfbench.reports.html import SiteSection

    out = []
    for decl in scene_tables(paper, results.meta):
        table = scene_table_with_paper(results, paper, decl)
        if not table.empty:
            caption = [decl.caption, f"ours: {decl.scene_metric} on the samples {', '.join(decl.scenes)} of this "
                       f"run, their mean ('{decl.scene_metric}', over the 'scenes' we have) and "
                       f"'{RUN_RUNTIME_COLUMN}' (at the data's resolution); rows 'NAME (paper)': the paper's file "
                       "as published"]
            out.append(SiteSection(id=decl.id, title=f"{decl.id}: ours beside the paper", table=table,
                                   caption=with_synthetic_line(caption, results)))
    return out


# --------------------------------------------------------------------------- maps

class Maps(OutputWriter):
    """Every prediction in the submission layout under ``folder``: ``<folder>/<method>/disp_maps/<scene>.pfm``
    and ``runtimes/`` (``per_method=False``: one method's maps right in ``<folder>``, as an ablation cell
    keeps them); ``uncertainty``: also ``uncertainty/<scene>.pfm`` where a prediction has one."""

    def __init__(self, folder: str = MAPS_DIR, *, per_method: bool = True, uncertainty: bool = False) -> None:
        self.folder, self.per_method, self.uncertainty = folder, per_method, uncertainty
        self._saver: MapSaver | None = None

    def start(self, run: RunOutputs) -> None:
        self._saver = MapSaver(run.stage / self.folder, per_method=self.per_method, uncertainty=self.uncertainty)

    def on_prediction(self, label: str, scene: LightField, pred: Prediction) -> None:
        self._saver.save(label, scene.name, pred)

    def write(self, run: RunOutputs) -> list[Path]:
        return [run.stage / self.folder] if (run.stage / self.folder).exists() else []


# --------------------------------------------------------------------------- figures

class SceneFigures(OutputWriter):
    """Per-scene overviews (one row per method) and BadPix series of the predictions seen, drawn as they
    arrive (lfbench.reports.figures.SceneFigureWriter) into ``folder`` under the stage. Returns the folder
    (``files=False``) or every file drawn."""

    def __init__(self, folder: str = FIGURES_DIR, *, files: bool = False) -> None:
        self.folder, self.files = folder, files
        self.writer: SceneFigureWriter | None = None

    def start(self, run: RunOutputs) -> None:
        methods = run.results.methods if run.results is not None else ()  # colours in the results' order
        self.writer = SceneFigureWriter(run.stage / self.folder, rules=run.rules, thresholds=run.thresholds,
                                        methods=methods)
        if not self.files:
            (run.stage / self.folder).mkdir(parents=True, exist_ok=True)

    def on_prediction(self, label: str, scene: LightField, pred: Prediction) -> None:
        self.writer.add(label, scene, pred)

    def write(self, run: RunOutputs) -> list[Path]:
        run.curves.update({(c.method, c.scene): c for c in self.writer.curves})  # the site's series too
        return sorted(self.writer.written) if self.files else [run.stage / self.folder]


class CurveFigures(OutputWriter):
    """The BadPix series without the maps: from saved curves (``curves``: a badpix_series.csv of
    ``evaluate --figures``) when there are any, else from the BadPix thresholds the results hold.
    ``source`` says which, after the write."""

    def __init__(self, curves: Path | None, folder: str = FIGURES_DIR) -> None:
        self.curves, self.folder = curves, folder
        self.source = ""

    def write(self, run: RunOutputs) -> list[Path]:
        out = run.stage / self.folder
        colours = method_colours(run.results.methods)
        if self.curves is not None and self.curves.is_file():
            self.source = str(self.curves)
            return draw_badpix_curves(read_curves_csv(self.curves), out, colours, marked=run.thresholds.marked)
        self.source = "the BadPix thresholds in the results (no curves saved: run evaluate --figures for full curves)"
        return [plot_mean_series(curves_from_records(run.results), out / "badpix_series.png",
                                 "BadPix at the thresholds in the results, mean over scenes", markers=True,
                                 colours=colours, marked=run.thresholds.marked)]


class ToolkitFigures(OutputWriter):
    """The toolkit's figure types for papers (radar, error heatmaps, pairwise comparisons) from the saved
    maps already loaded (``run.scene_maps``), into figures/toolkit in ``formats``."""

    def __init__(self, formats: Sequence[str] = ("png",), folder: str = f"{FIGURES_DIR}/toolkit") -> None:
        self.formats, self.folder = list(formats), folder

    def write(self, run: RunOutputs) -> list[Path]:
        return toolkit_figures_from_scene_maps(run.results, run.scene_maps.values(), run.stage / self.folder,
                                               formats=self.formats)


# --------------------------------------------------------------------------- statistics

@dataclass(frozen=True)
class CIOptions:
    """Bootstrap confidence intervals of every number (lfbench.scoring.stats.ci_records).

    resamples: bootstrap resamples; block: tile size in prediction px of the block bootstrap
    (None or 1: independent pixels); seed: of the resampling."""

    resamples: int = 1000
    block: int | None = 16
    seed: int = 0


class BootstrapCIs(OutputWriter):
    """95 % bootstrap intervals of every number: ci.csv (long) and table_ci_per_scene ('value [low,
    high]'), from the per-pixel errors of each prediction."""

    def __init__(self, options: CIOptions = CIOptions()) -> None:
        self.options = options
        self.collector: ErrorCollector | None = None

    def start(self, run: RunOutputs) -> None:
        from lfbench.scoring.stats import ErrorCollector

        self.collector = ErrorCollector(run.rules)

    def on_prediction(self, label: str, scene: LightField, pred: Prediction) -> None:
        self.collector(_named(label), scene, pred)

    def write(self, run: RunOutputs) -> list[Path]:
        from lfbench.reports.ci import format_ci_table
        from lfbench.scoring.stats import ci_records

        o = self.options
        long = ci_records(run.results, self.collector.errors, n=o.resamples, seed=o.seed, block=o.block,
                          progress=run.progress)
        write_text(run.stage / "ci.csv", long.to_csv(index=False))
        return [run.stage / "ci.csv", *write_table(format_ci_table(long), run.stage, "table_ci_per_scene")]


class UncertaintyRatings(OutputWriter):
    """How well each method's uncertainty map ranks its errors: uncertainty.csv, table_uncertainty.md
    and figures/sparsification_<measure>.png (methods without an uncertainty map are named in the log)."""

    def __init__(self) -> None:
        self.collector: UncertaintyCollector | None = None

    def start(self, run: RunOutputs) -> None:
        from lfbench.scoring.uncertainty import UncertaintyCollector

        self.collector = UncertaintyCollector(run.rules)

    def on_prediction(self, label: str, scene: LightField, pred: Prediction) -> None:
        self.collector(_named(label), scene, pred)

    def write(self, run: RunOutputs) -> list[Path]:
        from lfbench.reports.uncertainty import write_uncertainty_report

        written = write_uncertainty_report(self.collector, run.stage)
        for name in sorted(self.collector.without):
            log.info("note: %s predicts no uncertainty map; not rated", name)
        return written


# --------------------------------------------------------------------------- the site

class Site(OutputWriter):
    """The HTML report (lfbench.reports.html) into ``html/`` of the stage, drawn from the run's files
    (``run.folder``: its ci.csv and saved maps, unless ``maps`` names them: a folder of submission folders
    or label -> folder), the scenes (``run.scenes``, else those of ``data_root`` or of the data root the
    results record) and the maps already loaded (``run.scene_maps``). ``paper``: a reference's numbers
    beside ours; ``sections``: more tables on the index page (e.g. an ablation's seeds and verdicts).
    Written last: it reads what the other writers staged (and the staged results.json, when the set has
    one, as it will be committed). ``index`` is its index.html after the write."""

    def __init__(self, *, data_root: str | Path | Sequence[str | Path] | None = None,
                 maps: str | Path | Mapping[str, Path] | None = None,
                 paper: PaperTables | None = None, paper_methods: Sequence[str] = (), title: str | None = None,
                 notes: Sequence[str] = (), sections: Sequence[SiteSection] = ()) -> None:
        self.data_root, self.maps, self.paper, self.paper_methods = data_root, maps, paper, list(paper_methods)
        self.title, self.notes, self.sections = title, list(notes), list(sections)
        self.index: Path | None = None

    def inputs(self, run: RunOutputs) -> SiteInputs:
        from lfbench.reports.html import site_inputs

        staged = run.stage / "results.json"  # the results as this set commits them (names checked), else as given
        results = Results.read(run.stage, names_checked=True) if staged.is_file() else run.results
        paper = self.paper if self.paper is not None and self.paper.shows("table1", results.meta) else None
        inputs = site_inputs(results, run.folder, data_root=self.data_root, maps=self.maps,
                             scenes=list(run.scenes) if run.scenes else None, scene_maps=run.scene_maps,
                             curves=run.curves, paper=paper, paper_methods=self.paper_methods, title=self.title)
        inputs.notes = [*self.notes, *inputs.notes]
        inputs.sections = [*self.sections, *paper_scene_sections(results, self.paper)]
        return inputs

    def write(self, run: RunOutputs) -> list[Path]:
        from lfbench.reports.html import SITE_DIR, build_site

        self.index = build_site(self.inputs(run), run.stage / SITE_DIR)
        return [self.index]
