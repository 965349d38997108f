"""Tables and the BadPix-series figure from existing results (nothing is re-run).

Writes OUT/table_per_scene.* and OUT/table_average.* (the same tables `lfbench evaluate` writes) and,
with --paper, OUT/table_per_scene_paper.* and OUT/table_average_paper.* with the paper's numbers in
labelled columns/rows. lfbench ships no copy of the paper's tables: --paper DIR names the folder
(e.g. ../shared/data/paper); a bare --paper finds it through $LFBENCH_PAPER_DIR or
$LFBENCH_HCI_ROOT/../paper. The BadPix series (t = 0 .. 0.1 px) come from the curves an
`evaluate --figures` run saved (RESULTS_DIR/figures/badpix_series.csv, or --curves CSV); without them, from the BadPix
thresholds the results hold (0.01, 0.03, 0.07). With --maps (maps saved by `evaluate --save-maps`)
the per-scene overviews and exact curves are drawn from the saved maps.

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

FORMATS = {"md": ("markdown", "md"), "markdown": ("markdown", "md"), "tex": ("latex", "tex"),
           "latex": ("latex", "tex"), "csv": ("csv", "csv")}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("results", type=Path, metavar="RESULTS.json|DIR", help="a results.json or the folder holding one")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder")
    p.add_argument("--paper", nargs="?", const="", metavar="DIR",
                   help="add the paper's numbers from DIR, a folder with table1_per_scene.csv and table2_average.csv "
                        "(e.g. ../shared/data/paper); a bare --paper uses $LFBENCH_PAPER_DIR, else "
                        "$LFBENCH_HCI_ROOT/../paper")
    p.add_argument("--paper-methods", default="SubFocal", metavar="NAMES",
                   help="comma-separated paper methods to show (default SubFocal; e.g. SubFocal,SubFocal-L,OACC-Net)")
    p.add_argument("--format", default="md,tex,csv", help="comma-separated table formats: md, tex, csv")
    p.add_argument("--curves", type=Path, metavar="CSV",
                   help="BadPix curves CSV (default: RESULTS_DIR/figures/badpix_series.csv when present)")
    p.add_argument("--maps", type=Path, metavar="DIR",
                   help="saved maps (OUT/maps of `evaluate --save-maps`): draw per-scene overviews from them")
    p.add_argument("--data", type=Path, metavar="ROOT",
                   help="the data root of the scenes, for --maps (default: the one recorded in the results)")
    p.add_argument("--html", action="store_true",
                   help="also write a static HTML report OUT/html/index.html (opens offline, no server)")
    p.add_argument("--figure-format", default="png", metavar="FMTS",
                   help="comma-separated formats of the toolkit figures drawn from saved maps: png, pdf, svg")


def parse_formats(text: str) -> list[tuple[str, str]]:
    from lfbench.utils.errors import SpecError

    out = []
    for item in (s.strip().lower() for s in text.split(",") if s.strip()):
        if item not in FORMATS:
            raise SpecError(f"--format: unknown table format {item!r}; use md, tex, csv")
        if FORMATS[item] not in out:
            out.append(FORMATS[item])
    if not out:
        raise SpecError("--format: no table format given; use md, tex, csv")
    return out


def parse_figure_formats(text: str) -> list[str]:
    from lfbench.reports.toolkit_figures import FIGURE_FORMATS
    from lfbench.utils.errors import SpecError

    out = list(dict.fromkeys(s.strip().lower() for s in text.split(",") if s.strip()))
    bad = [f for f in out if f not in FIGURE_FORMATS]
    if bad or not out:
        raise SpecError(f"--figure-format: unknown format {', '.join(bad) or '(none)'}; "
                        f"use {', '.join(FIGURE_FORMATS)}")
    return out


def run(args: argparse.Namespace) -> int:
    from lfbench.reports import figures as fig
    from lfbench.reports.tables import average_table, per_scene_table, render, write_table
    from lfbench.runs.results import Results
    from lfbench.utils.errors import DataError

    formats = parse_formats(args.format)
    figure_formats = parse_figure_formats(args.figure_format)
    results = Results.read(args.results)
    if not results.records:
        raise DataError("the results hold no records", args.results)
    results_dir = args.results if args.results.is_dir() else args.results.parent
    paper = paper_methods = None
    if args.paper is not None:
        from lfbench.reports.paper import find_paper_dir, load_paper

        paper = load_paper(find_paper_dir(args.paper or None))
        paper_methods = [m.strip() for m in args.paper_methods.split(",") if m.strip()]
        for m in paper_methods:
            paper.resolve_method(m)  # unknown names fail before anything is written
    curves_path = args.curves or results_dir / "figures" / "badpix_series.csv"
    if args.curves is not None and not curves_path.is_file():
        raise DataError("curve file not found", curves_path)

    per_scene, average = per_scene_table(results), average_table(results)
    tables = {"per_scene": per_scene, "average": average}
    if paper is not None:
        from lfbench.reports.paper import average_with_paper, per_scene_with_paper

        tables["per_scene_paper"] = per_scene_with_paper(per_scene, paper, paper_methods)
        tables["average_paper"] = average_with_paper(average, paper, results.scenes, paper_methods)
    written = [path for name, table in tables.items() for path in write_table(table, args.out, f"table_{name}",
                                                                              formats=formats)]

    fig_dir = args.out / "figures"
    if args.maps is not None:
        from lfbench.data.scene import Benchmark

        root = args.data or (Path(results.meta["data_root"]) if results.meta.get("data_root") else None)
        if root is None:
            raise DataError("--maps needs --data ROOT (the results do not record their data root)", args.results)
        bench = Benchmark.discover(root)
        scenes = [s for s in bench if s.name in set(results.scenes) and s.has_gt()]
        from lfbench.reports.maps import map_folders
        from lfbench.reports.toolkit_figures import write_toolkit_figures

        folders = map_folders(args.maps, results.methods)
        writer = fig.figures_from_maps(scenes, folders, fig_dir)
        written += sorted(writer.written)
        written += write_toolkit_figures(results, scenes, folders, fig_dir / "toolkit", formats=figure_formats,
                                         border_px=int((results.meta.get("scoring") or {}).get("border_px", 15)))
        source = f"saved maps in {args.maps}"
    elif curves_path.is_file():
        written += fig.draw_badpix_curves(fig.read_curves_csv(curves_path), fig_dir)
        source = str(curves_path)
    else:
        series = fig.curves_from_records(results)
        written.append(fig.plot_badpix_series(series, fig_dir / "badpix_series.png",
                                              "BadPix at the thresholds in the results, mean over scenes",
                                              markers=True))
        source = "the BadPix thresholds in the results (no curves saved: run evaluate --figures for full curves)"

    if args.html:
        from lfbench.reports.html import SITE_DIR, build_site, site_inputs_from_dir

        inputs = site_inputs_from_dir(args.results, data_root=args.data, maps=args.maps, paper=paper,
                                      paper_methods=paper_methods or ("SubFocal",))
        index = build_site(inputs, args.out / SITE_DIR)
        written.append(index)
        print(f"HTML report: {index}")
    print(render(tables.get("average_paper", average), "markdown"), end="")
    print(f"\nBadPix series from {source}")
    print(f"wrote {len(written)} files into {args.out}: tables table_*.{{{','.join(e for _, e in formats)}}}, "
          f"figures in {fig_dir}")
    return 0
