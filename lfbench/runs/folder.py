"""Evaluate into a folder: run methods on scenes, score them as the benchmark does and write every
output file of a run. The one orchestration behind ``lfbench evaluate``, ``lfbench demo``,
results/golden.py and the ablation cells.

Files in OUT: results.json, results.csv (always); table_per_scene.{md,tex,csv} and
table_average.{md,tex,csv} (``tables``); maps/<method>/ in the submission layout (``save_maps``);
figures/ (``figures``: per-scene overviews and BadPix series); ci.csv and
table_ci_per_scene.{md,tex,csv} (``ci``); uncertainty.csv, table_uncertainty.md and
figures/sparsification_*.png (``uncertainty``, when a method predicts an uncertainty map); html/
(``site``: the HTML report of lfbench.reports.html, drawn from the run's own files).

The files of a run appear together or not at all (lfbench.runs.outputs): they are written into a
staging folder inside OUT and committed as one set, which replaces the previous run's set (files of
an earlier run that this one does not write are dropped; other files in OUT are left alone).
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from lfbench.data.scene import Scene
from lfbench.method.base import Method
from lfbench.reports.maps import MAPS_DIR
from lfbench.runs.outputs import staged_outputs
from lfbench.runs.results import Results
from lfbench.runs.runner import PredictionHook, check_names, evaluate, save_prediction
from lfbench.scoring.metrics import GENERAL_METRICS, RUNTIME_METRICS, Metric
from lfbench.scoring.rules import ScoringRules

__all__ = ["CIOptions", "evaluate_to_folder"]

log = logging.getLogger(__name__)

FIGURES_DIR = "figures"


@dataclass(frozen=True)
class CIOptions:
    """Bootstrap confidence intervals of every number (lfbench.scoring.stats.ci_records).

    resamples: bootstrap resamples; block: tile size in prediction px of the block bootstrap
    (None or 1: independent pixels); seed: of the resampling."""

    resamples: int = 1000
    block: int | None = 16
    seed: int = 0


def evaluate_to_folder(methods: Sequence[Method], scenes: Sequence[Scene], out: str | Path, *,
                       rules: ScoringRules = ScoringRules(), metrics: Sequence[Metric] | None = None,
                       all_metrics: bool = False,
                       more: Sequence[tuple[Sequence[Method], Sequence[Scene]]] = (),
                       label: str | None = None, on_prediction: PredictionHook | None = None,
                       save_maps: bool = False, figures: bool = False, ci: CIOptions | None = None,
                       uncertainty: bool = False, tables: bool = True, site: bool = False,
                       meta: Mapping[str, Any] | None = None, progress: bool = True) -> Results:
    """Run every method on every scene, score and write the run into ``out``; returns the Results.

    metrics: the metrics of every scene (default the general ones); all_metrics: also the region and
    stratified metrics wherever the scene has their mask files, and the runtime metrics wherever the
    method reports a runtime (runtime, runtime_log). more: further (methods, scenes)
    groups scored with the same rules into the same results (e.g. stored maps on real scenes beside
    a synthetic run). label: the name the records get instead of the method's label (one method
    only). on_prediction: a further hook that sees each prediction. meta: added to results.meta.
    The other options add the files listed in the module docstring; ``results.files`` lists every
    file and folder written.
    """
    out = Path(out)
    if label is not None and len(methods) != 1:
        raise ValueError("label= names the records of a single method")
    check_names([(methods, scenes), *more], label)  # records and files that would collide: before any work
    with staged_outputs(out) as outputs:  # OUT checked and its staging folder made before any work
        results, staged = _run_into(outputs.stage, methods, scenes, rules=rules, metrics=metrics,
                                    all_metrics=all_metrics, more=more, label=label, on_prediction=on_prediction,
                                    save_maps=save_maps, figures=figures, ci=ci, uncertainty=uncertainty,
                                    tables=tables, meta=meta, progress=progress)
        if site:  # drawn from the staged files, as `lfbench report --html` draws it from the committed ones
            from lfbench.reports.html import SITE_DIR, build_site_from_dir

            scored = [*scenes, *(s for _, group in more for s in group)]  # not searched again: the scenes scored
            staged.append(build_site_from_dir(outputs.stage, outputs.stage / SITE_DIR, scenes=scored).parent)
        outputs.commit([p.relative_to(outputs.stage).parts[0] for p in staged])
    results.files = [outputs.final(p) for p in staged]
    return results


def _all_metrics(scene: Scene, rules: ScoringRules) -> list[Metric]:
    """Everything the toolkit scores on ``scene``: the general metrics, the region / stratified ones whose
    masks exist, and the runtime metrics (recorded where the method reports a runtime)."""
    from lfbench.scoring.score import applicable_metrics

    return [*applicable_metrics(scene, rules=rules), *RUNTIME_METRICS]


def _run_into(stage: Path, methods: Sequence[Method], scenes: Sequence[Scene], *, rules: ScoringRules,
              metrics: Sequence[Metric] | None, all_metrics: bool,
              more: Sequence[tuple[Sequence[Method], Sequence[Scene]]], label: str | None,
              on_prediction: PredictionHook | None, save_maps: bool, figures: bool, ci: CIOptions | None,
              uncertainty: bool, tables: bool, meta: Mapping[str, Any] | None,
              progress: bool) -> tuple[Results, list[Path]]:
    """The work of :func:`evaluate_to_folder`, writing into the staging folder ``stage``; returns the
    results and every file and folder written (paths in ``stage``)."""
    hooks: list[PredictionHook] = [] if on_prediction is None else [on_prediction]
    if save_maps:
        hooks.append(save_prediction(stage / MAPS_DIR))
    if figures:
        from lfbench.reports.figures import scene_figure_hook

        (stage / FIGURES_DIR).mkdir()
        hooks.append(scene_figure_hook(stage / FIGURES_DIR, rules=rules))
    collector = rater = None
    if ci is not None:
        from lfbench.scoring.stats import ErrorCollector

        collector = ErrorCollector(rules)
        hooks.append(collector)
    if uncertainty:
        from lfbench.scoring.uncertainty import UncertaintyCollector

        rater = UncertaintyCollector(rules)
        hooks.append(rater)

    def each_prediction(method, scene, pred) -> None:
        for hook in hooks:
            hook(method, scene, pred)

    chosen = metrics if metrics is not None else GENERAL_METRICS
    if all_metrics:
        chosen = functools.partial(_all_metrics, rules=rules)
    run = functools.partial(evaluate, metrics=chosen, rules=rules, on_prediction=each_prediction if hooks else None,
                            progress=progress)
    results = run(methods, scenes)
    for group_methods, group_scenes in more:
        results.extend(run(group_methods, group_scenes))
    if label is not None:
        results.records = [replace(r, method=label) for r in results.records]
        results.runs = [replace(r, method=label) for r in results.runs]
    results.meta.update(meta or {})
    files: list[Path] = list(results.write(stage))
    if figures:
        files.append(stage / FIGURES_DIR)
    if save_maps and (stage / MAPS_DIR).exists():
        files.append(stage / MAPS_DIR)
    if tables:
        from lfbench.reports.tables import write_tables

        files += write_tables(results, stage)
    if collector is not None:
        from lfbench.reports.ci import format_ci_table
        from lfbench.reports.tables import write_table
        from lfbench.scoring.stats import ci_records
        from lfbench.utils.atomic import write_text

        long = ci_records(results, collector.errors, n=ci.resamples, seed=ci.seed, block=ci.block,
                          progress=progress)
        write_text(stage / "ci.csv", long.to_csv(index=False))
        files.append(stage / "ci.csv")
        files += write_table(format_ci_table(long), stage, "table_ci_per_scene")
    if rater is not None:
        from lfbench.reports.uncertainty import write_uncertainty_report

        files += write_uncertainty_report(rater, stage)
        for name in sorted(rater.without):
            log.info("note: %s predicts no uncertainty map; not rated", name)
    return results, files
