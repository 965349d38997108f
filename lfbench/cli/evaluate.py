"""Run methods on the scenes of a data root and score them as the benchmark does.

Writes OUT/results.json and OUT/results.csv (method, scene, metric, value, resolution), the
tables as markdown/LaTeX/CSV, and prints the per-scene table.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from lfbench.cli.argtypes import add_flag
from lfbench.utils.flags import DEVICE, JOBS, section_flags
from lfbench.utils.options import option

if TYPE_CHECKING:
    from lfbench.data.scene import Scene

HELP = "score methods on a dataset's scenes (results.json, results.csv, tables)"


@dataclass(frozen=True, kw_only=True)
class EvaluateFlags:
    """The flags only ``lfbench evaluate`` takes that carry a value, declared once."""

    ci_block: int = option(16, help="tile size of the block bootstrap in px (1 = independent pixels; errors of "
                           "neighbours correlate)", low=1, high=4096, metavar="PX")
    ci_resamples: int = option(1000, help="bootstrap resamples", low=1, high=10**6, metavar="N")
    metrics: str = option("", help="comma-separated ids of general metrics scored besides the dataset protocol's "
                          "(e.g. a metric plugin's, badpix_0.05, q50_x100); the protocol's are always scored, an "
                          "installed metric only where the protocol lists it or it is named here", metavar="IDS")


_EVALUATE = section_flags(EvaluateFlags)
CI_BLOCK, CI_RESAMPLES, METRIC_IDS = (_EVALUATE[name] for name in ("ci_block", "ci_resamples", "metrics"))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, type=Path, action="append", metavar="ROOT",
                   help="data root of a known dataset (its layout is detected: see `lfbench datasets`), e.g. "
                        "ROOT/<category>/<scene>/ (HCI) or ROOT/<split>/ImageN/ (UrbanLF-Syn); repeat to score the "
                        "scenes of several roots of one dataset into one results file (scenes keep their names: two "
                        "selected scenes of one name are refused, select one by category with --scenes)")
    p.add_argument("--dataset", metavar="NAME",
                   help="read ROOT as this dataset instead of detecting its layout (see `lfbench datasets`); it "
                        "sets the scoring protocol (border, metrics, resolutions) and the disparity range a method "
                        "searches where its spec does not set one")
    p.add_argument("--method", required=True, action="append", metavar="SPEC",
                   help="method spec name[:key=value,...]; repeat for several (see `lfbench methods`). Results "
                        "name it by its spec, a weights file by its content (weights=sha256:...), so that they "
                        "compare equal wherever the file lies (results.json keeps the path)")
    p.add_argument("--label", action="append", metavar="NAME",
                   help="name the results of the --method in the same position NAME instead (give one per --method)")
    p.add_argument("--scenes", default="", help="comma-separated scene, category or split names (default: all)")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder")
    p.add_argument("--toolkit-nonfinite", action="store_true",
                   help="score as the official toolkit's own code: NaN/inf predictions count as good in BadPix and "
                        "the other percentage metrics and are left out of Q25, bumpiness and MAE (by default they "
                        "are bad / the worst value); it also switches the missed-dots rule for (box, label) pairs "
                        "without pixels to the toolkit's (counted as missed dots), which changes missed_dots even "
                        "for finite predictions (docs/benchmark-rules.md, deliberate differences)")
    p.add_argument("--lowres-only", action="store_true",
                   help="score every scene at its views' resolution (HCI: 512x512), even where high-resolution "
                        "ground truth exists")
    add_flag(p, METRIC_IDS)
    p.add_argument("--all-metrics", action="store_true",
                   help="also score the region and stratified metrics wherever the scene has their mask files, "
                        "and the toolkit's runtime and runtime_log (log10 s) wherever the method reports a "
                        "runtime (a submission's runtimes/<scene>.txt, else the measured wall time)")
    p.add_argument("--save-maps", action="store_true",
                   help="also write each prediction as OUT/maps/<method>/ (submission layout)")
    p.add_argument("--ci", action="store_true",
                   help="also write 95%% bootstrap CIs: OUT/ci.csv and OUT/table_ci_per_scene.{md,tex,csv}")
    add_flag(p, CI_BLOCK)
    add_flag(p, CI_RESAMPLES)
    p.add_argument("--figures", action="store_true", help="also draw per-scene figures into OUT/figures/")
    p.add_argument("--html", action="store_true",
                   help="also write a static HTML report OUT/html/index.html (implies --save-maps; opens offline)")
    p.add_argument("--uncertainty", action="store_true",
                   help="also rate each method's uncertainty map (SubFocal: std of its distribution): "
                        "sparsification curves and AUSE/AURG in OUT/uncertainty.csv, OUT/table_uncertainty.md "
                        "and OUT/figures/sparsification_*.png")
    add_flag(p, JOBS, detail="each scores one scene at a time; the numbers are the same for any N, memory grows "
                             "with N scenes (not with the number of methods)")
    add_flag(p, DEVICE, detail="every method that has a device parameter (a spec's own device=... wins; default: "
                               "the method's, auto)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from lfbench.data.dataset import open_datasets
    from lfbench.data.provenance import is_synthetic_root
    from lfbench.method.registry import create_from_spec
    from lfbench.reports import writers as w
    from lfbench.reports.tables import per_scene_rows, render
    from lfbench.results import protocol_meta
    from lfbench.runs.folder import evaluate_to_folder
    from lfbench.scoring.protocol import protocol_scoring
    from lfbench.utils.errors import DataError, SpecError

    # one line for a root of no (or several) layouts, or a dataset file naming no general metric, before any scene
    extra = [m.strip() for m in args.metrics.split(",") if m.strip()]  # --metrics: scored beside the protocol's

    def scoring_of(protocol):  # its rules, metrics (ids checked: before any scene is opened) and method grid
        return protocol_scoring(protocol, toolkit=args.toolkit_nonfinite, allow_highres=not args.lowres_only,
                                extra=extra)

    dataset, protocol, bench = open_datasets(args.data, args.dataset, check=scoring_of)
    scoring = scoring_of(protocol)
    # errors before any work; the protocol's disparity grid unless a spec sets it
    methods = [create_from_spec(spec, {"device": args.device}, scoring.grid) for spec in args.method]
    if args.label is not None:
        if len(args.label) != len(methods):
            raise SpecError(f"--label: {len(args.label)} label(s) for {len(methods)} --method(s); give one per method")
        if not all(label.strip() for label in args.label):
            raise SpecError("--label: a label must not be empty")
        methods = [m.with_label(label) for m, label in zip(methods, args.label, strict=True)]
    if args.html:  # the site's module (jinja2) only for a run that draws one
        from lfbench.reports.html import SITE_DIR, check_site_dir

        check_site_dir(args.out / SITE_DIR)
    selected = bench.select([s for s in args.scenes.split(",") if s.strip()])
    with_gt = [s.has_gt() for s in selected]
    scenes = [s for s, gt in zip(selected, with_gt, strict=True) if gt]
    if not scenes:
        raise DataError(f"none of the selected scenes has ground truth ({dataset.name} layout: {dataset.layout})",
                        ", ".join(map(str, args.data)))
    protocol.check_angular_size(scenes)  # one line naming the scene, before any method runs
    _warn_without_gt([s for s, gt in zip(selected, with_gt, strict=True) if not gt])  # the README: not scored
    writers = [*([w.SceneFigures()] if args.figures else []), *([w.Maps()] if args.save_maps or args.html else []),
               w.Tables(),
               *([w.BootstrapCIs(w.CIOptions(resamples=args.ci_resamples, block=args.ci_block))] if args.ci else []),
               *([w.UncertaintyRatings()] if args.uncertainty else []), *([w.Site()] if args.html else [])]
    meta = {"data_root": str(args.data[0]), "dataset": dataset.name,
            "protocol": protocol_meta(protocol.metrics, protocol.disparity_range),  # what the pages show
            "methods": {m.label: m.provenance() for m in methods},
            **({"synthetic": True} if is_synthetic_root(args.data) else {})}  # the captions say so
    if len(args.data) > 1:  # readers take every root from here (Results.data_roots); data_root: the first
        meta["data_roots"] = [str(r) for r in args.data]
    results = evaluate_to_folder(methods, scenes, args.out, rules=scoring.rules, metrics=list(scoring.metrics),
                                 all_metrics=args.all_metrics, writers=writers,
                                 meta=meta, progress=not args.no_progress, jobs=args.jobs)
    if args.out / "table_uncertainty.md" in results.files:
        print((args.out / "table_uncertainty.md").read_text(encoding="utf-8"))
    print(render(per_scene_rows(results), "markdown"), end="")
    print(f"\nwrote {args.out / 'results.json'} and {args.out / 'results.csv'}")
    if args.html:
        print(f"HTML report: {args.out / SITE_DIR / 'index.html'}")
    return 0


def _warn_without_gt(scenes: Sequence[Scene]) -> None:
    """One warning line naming the selected ``scenes`` left out for having no ground truth (not scored)."""
    if scenes:
        names = ", ".join(s.name for s in scenes[:5]) + (f" and {len(scenes) - 5} more" if len(scenes) > 5 else "")
        logging.getLogger(__name__).warning("warning: %d selected scene(s) have no ground truth and are not scored: %s "
                                            "(first: %s)", len(scenes), names, scenes[0].path)
