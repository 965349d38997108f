"""Evaluate into a folder: run methods on scenes, score them as the benchmark does and write the run's
output set. The one orchestration behind ``lfbench evaluate``, ``lfbench demo``, results/golden.py and
the ablation cells.

Files in OUT: results.json, results.csv (always), then what the output writers
(lfbench.reports.writers) write: the tables (``Tables``), maps/<method>/ in the submission layout
(``Maps``), figures/ (``SceneFigures``), ci.csv and table_ci_per_scene (``BootstrapCIs``),
uncertainty.csv, table_uncertainty.md and figures/sparsification_*.png (``UncertaintyRatings``) and
html/ (``Site``, drawn from the run's own files). Each writer sees every prediction as it is made
and writes its files after the scoring (lfbench.reports.writers.drive_writers).

The files of a run appear together or not at all (lfbench.utils.outputs): they are written into a
staging folder inside OUT and committed as one set, which replaces the previous run's set (files of
an earlier run that this one does not write are dropped; other files in OUT are left alone).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from lfbench.data.scene import Scene
from lfbench.method.base import Method, Prediction
from lfbench.reports.writers import CIOptions, OutputWriter, PredictionSink, RunOutputs, Tables, drive_writers
from lfbench.results import Results, check_names
from lfbench.runs.runner import evaluate
from lfbench.scoring.metrics import GENERAL_METRICS, RUNTIME_METRICS, Metric
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import applicable_metrics
from lfbench.utils.outputs import staged_outputs

__all__ = ["CIOptions", "check_plan", "evaluate_to_folder"]


def evaluate_to_folder(methods: Sequence[Method], scenes: Sequence[Scene], out: str | Path, *,
                       rules: ScoringRules = ScoringRules(), metrics: Sequence[Metric] | None = None,
                       all_metrics: bool = False,
                       more: Sequence[tuple[Sequence[Method], Sequence[Scene]]] = (),
                       label: str | None = None, writers: Sequence[OutputWriter] = (Tables(),),
                       meta: Mapping[str, Any] | None = None, progress: bool = True, jobs: int = 1) -> Results:
    """Run every method on every scene, score and write the run into ``out``; returns the Results.

    metrics: the metrics of every scene (default lfbench's own general ones; a plugin's only where given);
    all_metrics: also the region and stratified metrics wherever the scene has their mask files, and the
    runtime metrics wherever the method reports a runtime (runtime, runtime_log). more: further (methods,
    scenes) groups scored with the same rules into the same results (e.g. stored maps on real scenes beside
    a synthetic run).
    label: the name the records get instead of the method's label (one method only). writers: the outputs besides
    results.json and results.csv (lfbench.reports.writers; default the tables), each seeing every prediction, in
    order (the site last). meta: added to results.meta. jobs: worker processes that score
    (lfbench.runs.runner.score_scenes; the results are the same for any number). ``results.files`` lists every
    file and folder written.
    """
    out = Path(out)
    if label is not None and len(methods) != 1:
        raise ValueError("label= names the records of a single method")
    check_plan([(methods, scenes), *more], label)  # records and files that would collide: before any work
    rules.check_border([*scenes, *(s for _, group in more for s in group)])
    with staged_outputs(out) as outputs:  # OUT checked and its staging folder made before any work
        scored = [*scenes, *(s for _, group in more for s in group)]
        chosen = list(metrics) if metrics is not None else list(GENERAL_METRICS)  # a plugin's only when chosen
        run = RunOutputs(stage=outputs.stage, rules=rules, scenes=scored, progress=progress,
                         metric_ids=((meta or {}).get("protocol") or {}).get("metrics")
                         or [m.id for m in chosen])  # the figures' BadPix thresholds: the protocol's
        if all_metrics:
            chosen = functools.partial(_all_metrics, rules=rules, general=chosen)

        def score(sink: PredictionSink) -> list[Path]:
            def each_prediction(method: Method, scene: Scene, pred: Prediction) -> None:
                sink(label if label is not None else method.label, scene, pred)

            run_group = functools.partial(evaluate, metrics=chosen, rules=rules, on_prediction=each_prediction,
                                          progress=progress, jobs=jobs)
            run.results = results = run_group(methods, scenes)
            for group_methods, group_scenes in more:
                results.extend(run_group(group_methods, group_scenes))
            if label is not None:
                results.records = [replace(r, method=label) for r in results.records]
                results.runs = [replace(r, method=label) for r in results.runs]
            references = [label if label is not None else m.label
                          for m in [*methods, *(m for group, _ in more for m in group)] if m.oracle]
            if references:  # shown as reference lines by the reports, never ranked (Results.references)
                results.meta["references"] = list(dict.fromkeys(references))
            results.meta.update(meta or {})
            return list(results.write(outputs.stage))

        staged = drive_writers(writers, run, produce=score)
        run.results.files = outputs.commit_written(staged)
    return run.results


def check_plan(groups: Sequence[tuple[Sequence[Method], Sequence[Scene]]], label: str | None = None) -> None:
    """:func:`lfbench.results.check_names` of a run of ``groups`` ((methods, scenes): each method on each of
    its scenes), before any work; ``label``: the name the records get instead of the method's label."""
    names = [label if label is not None else m.label for methods, _ in groups for m in methods]
    pairs = ((label if label is not None else m.label, s.name) for methods, scenes in groups
             for m in methods for s in scenes)
    check_names(names, (), pairs, scene_folders=[s for _, scenes in groups for s in scenes],
                twice=lambda key: f"method {key[0]!r} would run on scene {key[1]!r} twice (given twice?): its "
                                  "records would be duplicated")


def _all_metrics(scene: Scene, rules: ScoringRules, general: Sequence[Metric]) -> list[Metric]:
    """Everything the toolkit scores on ``scene``: the run's ``general`` metrics, the region / stratified ones
    whose masks exist, and the runtime metrics (recorded where the method reports a runtime)."""
    return [*applicable_metrics(scene, rules=rules, general=general), *RUNTIME_METRICS]
