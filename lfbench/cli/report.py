"""Tables and the BadPix-series figure from existing results (nothing is re-run; the work is
lfbench.reports.from_results.report_from_results).

Writes OUT/table_per_scene.* and OUT/table_average.* (the same tables `lfbench evaluate` writes) and,
with --paper, OUT/table_per_scene_paper.* and OUT/table_average_paper.* with the paper's numbers in
labelled columns/rows (HCI results), and the reference's per-scene tables of the results' dataset, e.g.
OUT/table_table3_paper.* beside UrbanLF-Syn results (SubFocal's Table III: our BadPix 0.07 on its eight
samples and their mean beside its rows; lfbench.reports.paper_scenes). lfbench ships no copy of the
paper's tables: --paper DIR names the folder (e.g. ../shared/data/paper); a bare --paper finds it
through $LFBENCH_PAPER_DIR or $LFBENCH_HCI_ROOT/../paper. The BadPix series (t = 0 .. 0.1 px) come from the curves an
`evaluate --figures` run saved (RESULTS_DIR/figures/badpix_series.csv, or --curves CSV); without them, from the BadPix
thresholds the results hold (0.01, 0.03, 0.07). With saved maps (--maps DIR, by default RESULTS_DIR/maps of
`evaluate --save-maps` where the results' data root is at hand) the per-scene overviews and exact curves are drawn
from them.

With --html, OUT/html/index.html: a self-contained static site (leaderboard with ranks, a page per
scene with every method's maps, a page per method; opens from the file system, no network) drawn
from the results, the saved maps (--maps, default RESULTS_DIR/maps) and the scenes (--data, default
the data root the results record). With saved maps, OUT/figures/toolkit/ holds the toolkit's figure
types for papers (radar, error heatmaps, pairwise comparisons) in --figure-format.
"""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "tables (md, tex, csv) and BadPix-series figures from a results.json, optionally beside the paper's numbers"



def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("results", type=Path, metavar="RESULTS.json|DIR", help="a results.json or the folder holding one")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder")
    p.add_argument("--paper", nargs="?", const="", metavar="DIR",
                   help="add the paper's numbers from DIR, a folder with table1_per_scene.csv and table2_average.csv "
                        "(and table3_urbanlf.csv for UrbanLF-Syn results; e.g. ../shared/data/paper); a bare --paper "
                        "uses $LFBENCH_PAPER_DIR, else $LFBENCH_HCI_ROOT/../paper")
    p.add_argument("--paper-methods", default="", metavar="NAMES",
                   help="comma-separated paper methods to show (default: the paper's own, as its reference says; "
                        "e.g. SubFocal,SubFocal-L,OACC-Net)")
    p.add_argument("--format", default="md,tex,csv", help="comma-separated table formats: md, tex, csv")
    p.add_argument("--curves", type=Path, metavar="CSV",
                   help="BadPix curves CSV (default: RESULTS_DIR/figures/badpix_series.csv when present)")
    p.add_argument("--maps", type=Path, metavar="DIR",
                   help="saved maps (OUT/maps of `evaluate --save-maps`): draw per-scene overviews from them (default: "
                        "the results folder's maps/ where there is one and the scenes' data root is at hand)")
    p.add_argument("--data", type=Path, action="append", metavar="ROOT",
                   help="the data root of the scenes, for --maps and the site (default: the ones recorded in the "
                        "results); repeat for results scored on several roots")
    p.add_argument("--html", action="store_true",
                   help="also write a static HTML report OUT/html/index.html (opens offline, no server)")
    p.add_argument("--figure-format", default="png", metavar="FMTS",
                   help="comma-separated formats of the toolkit figures drawn from saved maps: png, pdf, svg")


def parse_formats(text: str) -> list[tuple[str, str]]:
    """--format as (render format, extension) pairs of lfbench.reports.tables.TABLE_FORMATS, each named
    by its extension or its format (md or markdown, tex or latex, csv)."""
    from lfbench.reports.tables import TABLE_FORMATS
    from lfbench.utils.errors import SpecError

    by_name = {name: pair for pair in TABLE_FORMATS for name in pair}
    known = ", ".join(ext for _, ext in TABLE_FORMATS)
    out = []
    for item in (s.strip().lower() for s in text.split(",") if s.strip()):
        if item not in by_name:
            raise SpecError(f"--format: unknown table format {item!r}; use {known}")
        if by_name[item] not in out:
            out.append(by_name[item])
    if not out:
        raise SpecError(f"--format: no table format given; use {known}")
    return out


def parse_figure_formats(text: str) -> list[str]:
    from lfbench.reports.plotting import FIGURE_FORMATS
    from lfbench.utils.errors import SpecError

    out = list(dict.fromkeys(s.strip().lower() for s in text.split(",") if s.strip()))
    bad = [f for f in out if f not in FIGURE_FORMATS]
    if bad or not out:
        raise SpecError(f"--figure-format: unknown format {', '.join(bad) or '(none)'}; "
                        f"use {', '.join(FIGURE_FORMATS)}")
    return out


def run(args: argparse.Namespace) -> int:
    from lfbench.reports.from_results import report_from_results
    from lfbench.reports.tables import render

    formats = parse_formats(args.format)
    figure_formats = parse_figure_formats(args.figure_format)
    if args.html:
        from lfbench.reports.html import SITE_DIR, check_site_dir

        check_site_dir(args.out / SITE_DIR)
    paper = None
    if args.paper is not None:
        from lfbench.reports.paper import find_paper_dir, load_paper

        paper = load_paper(find_paper_dir(args.paper or None))
    paper_methods = [m.strip() for m in args.paper_methods.split(",") if m.strip()]
    outcome = report_from_results(args.results, args.out, formats=formats, paper=paper, paper_methods=paper_methods,
                                  curves=args.curves, maps=args.maps, data=args.data, figure_formats=figure_formats,
                                  html=args.html)
    if outcome.html_index is not None:
        print(f"HTML report: {outcome.html_index}")
    print(render(outcome.tables.get("average_paper", outcome.tables["average"]), "markdown"), end="")
    print(f"\nBadPix series from {outcome.curves_source}")
    print(f"wrote {len(outcome.written)} files into {args.out}: tables table_*.{{{','.join(e for _, e in formats)}}}, "
          f"figures in {outcome.figures}")
    return 0
