"""Generate a mini synthetic benchmark (no dataset, no network), run every registered method that can
run offline, score them as the benchmark does, and write results, tables and figures.

Files: OUT/data/ (the synthetic scenes, HCI layout), OUT/results.json, OUT/results.csv,
OUT/table_per_scene.{md,tex,csv}, OUT/table_average.{md,tex,csv}, OUT/figures/ (per-scene overviews,
BadPix-series curves), OUT/maps/ (every method's disparity maps) and OUT/html/index.html (the HTML
report: open it in a browser, no server needed). Re-running into OUT reuses its data when seed, size
and scenes match, and refuses otherwise.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lfbench.cli.argtypes import add_flag
from lfbench.utils.flags import SCENE_COUNT, SEED

HELP = "run a mini benchmark on generated synthetic scenes (no dataset needed)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from lfbench.data.synth import SYNTH_SIZE
    from lfbench.runs.demo import DEFAULT_SCENES, DEFAULT_SEED, DEFAULT_SIZE

    p.add_argument("--out", type=Path, default=Path("lfbench-demo"), metavar="DIR",
                   help="output folder (default: ./lfbench-demo)")
    add_flag(p, SEED, default=DEFAULT_SEED)
    add_flag(p, SYNTH_SIZE, default=DEFAULT_SIZE)
    add_flag(p, SCENE_COUNT, default=DEFAULT_SCENES)
    p.add_argument("--methods", action="append", metavar="SPEC,...",
                   help="methods to run, comma-separated specs (default: every registered method that runs offline)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--no-html", action="store_true", help="skip the HTML report (OUT/html/index.html)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    import time

    from lfbench.reports.tables import average_rows, render
    from lfbench.runs.demo import run_demo, split_specs

    specs = [s for text in (args.methods or []) for s in split_specs(text)] or None
    start = time.perf_counter()
    outcome = run_demo(args.out, seed=args.seed, size=args.size, scenes=args.scenes, methods=specs,
                       figures=not args.no_figures, html=not args.no_html, progress=not args.no_progress)
    print(f"lfbench demo: {len(outcome.results.scenes)} synthetic scene(s), {len(outcome.methods)} method(s), "
          f"{time.perf_counter() - start:.1f} s\n")
    print(render(average_rows(outcome.results), "markdown"), end="")
    out = args.out
    print(f"\nresults: {outcome.files['results.json']} and {outcome.files['results.csv']}")
    print(f"tables:  {out / 'table_per_scene.md'}, {out / 'table_average.md'} (also .tex, .csv)")
    if "figures" in outcome.files:
        print(f"figures: {outcome.files['figures']}/overview_<scene>.png, "
              f"{outcome.files['figures'] / 'badpix_series.png'}")
    if "html" in outcome.files:
        print(f"report:  {outcome.files['html']} (open it in a browser)")
    print(f"data:    {outcome.files['data']} (HCI layout; try `lfbench evaluate --data {outcome.files['data']} ...`)")
    return 0
