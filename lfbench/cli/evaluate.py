"""Run methods on the scenes of a data root and score them as the benchmark does.

Writes OUT/results.json and OUT/results.csv (method, scene, metric, value, resolution), the
tables as markdown/LaTeX/CSV, and prints the per-scene table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "score methods on HCI scenes (results.json, results.csv, tables)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, type=Path, metavar="ROOT",
                   help="data root laid out as ROOT/<category>/<scene>/ (HCI layout)")
    p.add_argument("--method", required=True, action="append", metavar="SPEC",
                   help="method spec name[:key=value,...]; repeat for several (see `lfbench methods`)")
    p.add_argument("--scenes", default="", help="comma-separated scene, category or split names (default: all)")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder")
    p.add_argument("--toolkit-nonfinite", action="store_true",
                   help="treat NaN/inf predictions exactly as the official toolkit (BadPix counts NaN as good)")
    p.add_argument("--lowres-only", action="store_true",
                   help="score every scene at 512x512, even where high-resolution ground truth exists")
    p.add_argument("--all-metrics", action="store_true",
                   help="also score the region and stratified metrics wherever the scene has their mask files")
    p.add_argument("--save-maps", action="store_true",
                   help="also write each prediction as OUT/maps/<method>/ (submission layout)")
    p.add_argument("--ci", action="store_true",
                   help="also write 95%% bootstrap CIs: OUT/ci.csv and OUT/table_ci_per_scene.{md,tex,csv}")
    p.add_argument("--ci-block", type=int, default=16, metavar="PX",
                   help="tile size of the block bootstrap (1 = independent pixels; errors of neighbours correlate)")
    p.add_argument("--ci-resamples", type=int, default=1000, metavar="N", help="bootstrap resamples")
    p.add_argument("--figures", action="store_true", help="also draw per-scene figures into OUT/figures/")
    p.add_argument("--uncertainty", action="store_true",
                   help="also rate each method's uncertainty map (SubFocal: std of its distribution): "
                        "sparsification curves and AUSE/AURG in OUT/uncertainty.csv, OUT/table_uncertainty.md "
                        "and OUT/figures/sparsification_*.png")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    import functools

    from lfbench.data.scene import Benchmark
    from lfbench.method.registry import create_from_spec
    from lfbench.reports.tables import per_scene_table, render, write_tables
    from lfbench.runs.runner import evaluate, save_prediction
    from lfbench.scoring.metrics import GENERAL_METRICS
    from lfbench.scoring.rules import ScoringRules

    methods = [create_from_spec(spec) for spec in args.method]  # spec errors before any work
    bench = Benchmark.discover(args.data)
    scenes = bench.select([s for s in args.scenes.split(",") if s.strip()])
    scenes = [s for s in scenes if s.has_gt()]
    if not scenes:
        from lfbench.utils.errors import DataError

        raise DataError("none of the selected scenes has ground truth (gt_disp_lowres.pfm)", args.data)
    rules = ScoringRules(toolkit=args.toolkit_nonfinite, allow_highres=not args.lowres_only)
    hooks = []
    if args.save_maps:
        hooks.append(save_prediction(args.out / "maps"))
    if args.figures:
        from lfbench.reports.figures import scene_figure_hook

        hooks.append(scene_figure_hook(args.out / "figures", rules=rules))

    if args.ci:
        from lfbench.scoring.stats import ErrorCollector

        collector = ErrorCollector(rules)
        hooks.append(collector)

    if args.uncertainty:
        from lfbench.scoring.uncertainty import UncertaintyCollector

        rater = UncertaintyCollector(rules)
        hooks.append(rater)

    def on_prediction(method, scene, pred):
        for hook in hooks:
            hook(method, scene, pred)

    metrics = GENERAL_METRICS
    if args.all_metrics:
        from lfbench.scoring.region_metrics import applicable_metrics

        metrics = functools.partial(applicable_metrics, rules=rules)
    results = evaluate(methods, scenes, metrics=metrics, rules=rules, on_prediction=on_prediction if hooks else None,
                       progress=not args.no_progress)
    results.meta["data_root"] = str(args.data)
    results.write(args.out)
    write_tables(results, args.out)
    if args.ci:
        from lfbench.scoring.stats import ci_records, format_ci_table
        from lfbench.utils.atomic import write_text

        long = ci_records(results, collector.errors, n=args.ci_resamples, block=args.ci_block,
                          progress=not args.no_progress)
        write_text(args.out / "ci.csv", long.to_csv(index=False))
        for fmt, ext in (("markdown", "md"), ("latex", "tex"), ("csv", "csv")):
            write_text(args.out / f"table_ci_per_scene.{ext}", render(format_ci_table(long), fmt))
    if args.uncertainty:
        from lfbench.scoring.uncertainty import write_uncertainty_report

        if write_uncertainty_report(rater, args.out):
            print((args.out / "table_uncertainty.md").read_text(encoding="utf-8"))
        for label in sorted(rater.without):
            print(f"note: {label} predicts no uncertainty map; not rated")
    print(render(per_scene_table(results), "markdown"), end="")
    print(f"\nwrote {args.out / 'results.json'} and {args.out / 'results.csv'}")
    return 0
