"""Run the benchmark suite and keep its results: JSON records and a Markdown table in benchmarks/results/.

    python benchmarks/suite.py                 # the default suite (512x512, interval 0.5, fp32 + bf16)
    python benchmarks/suite.py --full          # + intervals 1, 0.25, 0.1 (about 3 h on a loaded 2-core CPU)
    python benchmarks/suite.py --quick         # 64x64 smoke run (about 2 min)
    python benchmarks/suite.py -- --max-memory 8 --threads 16   # anything after -- goes to `lfbench bench suite`

The same as ``lfbench bench suite`` (or ``nox -s bench``) with the output files named after the date and
host, so runs on different machines sit side by side. Every case runs in a fresh process; see
lfbench/runs/bench.py for what each bench measures.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

from lfbench.cli import main as lfbench_main

RESULTS = Path(__file__).resolve().parent / "results"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--full", action="store_true", help="all intervals (1, 0.5, 0.25, 0.1)")
    p.add_argument("--quick", action="store_true", help="64x64 smoke run")
    p.add_argument("--out", type=Path, default=RESULTS, help="folder for the JSON and Markdown results")
    p.add_argument("rest", nargs="*", help="further options for `lfbench bench suite` (after --)")
    args = p.parse_args(argv)
    stem = f"{time.strftime('%Y%m%d-%H%M')}-{platform.node() or 'host'}{'-quick' if args.quick else ''}"
    cmd = ["bench", "suite", "--json", str(args.out / f"{stem}.json"), "--table", str(args.out / f"{stem}.md")]
    if args.full:
        cmd += ["--interval", "1", "0.5", "0.25", "0.1"]
    if args.quick:
        cmd.append("--quick")
    return lfbench_main(cmd + args.rest)


if __name__ == "__main__":
    sys.exit(main())
