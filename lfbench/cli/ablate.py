"""Run an ablation: a grid of variants of SubFocal or any registered trainable network (the base config's
``method``; the grid's axes are its parameters), each trained with the spec's budget (an in-process
``lfbench train`` per cell), scored on the spec's scenes and timed on a whole scene; then the tables
(markdown, LaTeX, CSV) with the paper's numbers in adjacent, labelled columns, and the figures.

Shipped specs: ablations/table4_cpu.toml, table5_cpu.toml, beta_cpu.toml (2-core CPU presets on
synthetic scenes), *_paper.toml (the paper's widths, steps and data, for a GPU) and tables12_*.toml
(Tables I/II for any set of methods). Every key of a spec, with its type, default, bounds and meaning:
docs/ablation-spec.md (or ``python -m lfbench.ablation.reference``).

Re-running the same command skips finished cells and resumes an interrupted one from its
checkpoint. ``--jobs N`` trains N cells at a time in separate processes (cores / N threads each), each
with its own GPU (round-robin over the visible CUDA devices; the CPU when there are none). The shared
stage 1 is trained once under a file lock, and OUT/results.json is merged under one, so several ablate
processes on one OUT (e.g. different --cells) add up. ``--executor slurm`` submits one job per cell
through submitit (``--gpus-per-job``, ``--partition``, ...; ``--executor local``: the same path as local
processes); re-running the command resumes unfinished cells. The executors (``--executor``'s choices) are
those of lfbench.utils.executor.EXECUTORS.
The paper's tables come from --paper DIR, else $LFBENCH_PAPER_DIR, else $LFBENCH_HCI_ROOT/../paper;
without them the tables have no paper columns.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from lfbench.cli.argtypes import add_flag
from lfbench.utils.errors import SpecError
from lfbench.utils.executor import EXECUTORS, ClusterOptions
from lfbench.utils.flags import JOBS, section_flags
from lfbench.utils.tomlfile import toml_text

HELP = ("train and score a grid of network variants (SubFocal's Tables IV, V, beta sweep, I/II beside the paper's "
        "numbers, or a plugin's network)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", type=Path, metavar="SPEC.toml", help="ablation spec (see ablations/*.toml)")
    p.add_argument("--out", type=Path, default=None,
                   help="output folder (default: the spec's 'out', else runs/ablate/<spec name>)")
    add_flag(p, JOBS, detail="each trains one cell with cores / N torch threads (--executor pool)")
    p.add_argument("--paper", default=None, metavar="DIR",
                   help="folder of the paper's tables (default: $LFBENCH_PAPER_DIR, else $LFBENCH_HCI_ROOT/../paper)")
    p.add_argument("--cells", default="", metavar="IDS",
                   help="comma-separated cell ids: run (and tabulate) only these (see --list)")
    p.add_argument("--list", action="store_true", help="print the cells and their training configs, run nothing")
    p.add_argument("--report-only", action="store_true",
                   help="rewrite the tables and figures from the finished cells in OUT (train nothing)")
    p.add_argument("--html", action="store_true",
                   help="also write the HTML report OUT/html/index.html (leaderboard of the cells, their maps)")
    p.add_argument("--maps", choices=["all", "best", "none"], default="all",
                   help="whose saved maps the error-map figures and the HTML report draw: every cell's (default), only "
                        "the best cell's by the protocol's primary metric (its first BadPix: BadPix(0.07) on HCI) "
                        "and the [[methods]]', or none (drawing maps can take longer than training short cells; the "
                        "cells save their maps anyway, so --report-only --maps all draws them later)")
    p.add_argument("--no-maps", dest="maps", action="store_const", const="none", help="the same as --maps none")
    p.add_argument("--executor", choices=EXECUTORS.names(), default=None,
                   help="where the cells run: " + "; ".join(f"{name}: {EXECUTORS.get(name).help}"
                                                            for name in EXECUTORS.names()))
    for name, flag in section_flags(ClusterOptions).items():
        if name != "executor":  # its choices are the registry's (above)
            add_flag(p, flag)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from lfbench.ablation.spec import load_spec  # imported here (torch): `lfbench --help` starts without it

    spec = load_spec(args.spec)
    if args.cells.strip():
        wanted = [c.strip() for c in args.cells.split(",") if c.strip()]
        known = {c.id: c for c in spec.cells}
        unknown = [c for c in wanted if c not in known]
        if unknown:
            raise SpecError(f"--cells: no cell {', '.join(unknown)} in {args.spec}; cells: {', '.join(known)}")
        spec = dataclasses.replace(spec, cells=tuple(known[c] for c in wanted))
    out = args.out or (Path(spec.out) if spec.out else Path("runs") / "ablate" / args.spec.stem)
    if args.list:
        print(f"{spec.title}: {len(spec.cells)} cell(s), budget {spec.budget_label()}"
              f"{', shared stage 1' if spec.shared_stage1 else ''}; output {out}")
        for cell in spec.cells:
            print(f"\n## cell {cell.id}\n{toml_text(cell.config)}", end="")
        for m in spec.methods:
            print(f"\n## method {m.label}: {m.spec}")
        return 0
    progress = False if args.no_progress else None
    if args.report_only:
        from lfbench.ablation.runner import report_only

        report_only(spec, out, paper=args.paper, html=args.html, maps=args.maps)
    else:
        from lfbench.ablation.runner import run_ablation

        cluster = None
        if args.executor is not None:
            cluster = ClusterOptions(**{name: getattr(args, name) for name in section_flags(ClusterOptions)})
        run_ablation(spec, out, jobs=args.jobs, progress=progress, paper=args.paper, cluster=cluster, html=args.html,
                     maps=args.maps)
    if args.html:
        from lfbench.reports.html import SITE_DIR

        print(f"HTML report: {out / SITE_DIR / 'index.html'}")
    return 0
