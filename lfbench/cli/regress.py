"""Check new results against golden metrics: exit 1 with a readable diff when any metric worsened
beyond its tolerance, went missing or changed resolution; exit 0 otherwise.

With --update, write NEW as the golden file instead (tolerance from --tolerance)."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "compare results with golden metrics (CI regression check)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("golden", type=Path,
                   help="golden JSON: list of {method, scene, metric, value, tolerance, resolution}")
    p.add_argument("new", type=Path, help="new results.json (or the folder holding it)")
    p.add_argument("--update", action="store_true", help="write NEW's records as the golden file instead of checking")
    p.add_argument("--tolerance", default="0.001", metavar="T|metric=T,...",
                   help="tolerance for --update: one number, or per metric id or METHOD/METRIC glob, e.g. "
                        "'*=0.01,mse_x100=0.005,published*/*=1e-6' (METHOD/METRIC keys win)")
    p.add_argument("--skip-absent-scenes", action="store_true",
                   help="ignore golden records of scenes absent from NEW (e.g. real scenes when the data is not here)")
    p.add_argument("--quiet", action="store_true", help="print only failures and the summary")


def _parse_tolerance(text: str):
    from lfbench.utils.errors import SpecError

    try:
        if "=" not in text:
            return float(text)
        return {k.strip(): float(v) for k, v in (item.split("=", 1) for item in text.split(","))}
    except ValueError:
        raise SpecError(f"--tolerance: cannot parse {text!r}") from None


def run(args: argparse.Namespace) -> int:
    from lfbench.runs.regress import compare, make_golden, read_golden
    from lfbench.runs.results import Results

    new = Results.read(args.new)
    if args.update:
        n = make_golden(new, _parse_tolerance(args.tolerance), args.golden)
        print(f"wrote {n} golden records to {args.golden}")
        return 0
    golden = read_golden(args.golden)
    findings = compare(golden, new, skip_absent_scenes=args.skip_absent_scenes)
    failed = [f for f in findings if f.failed]
    for f in findings:
        if f.failed or not args.quiet:
            print(f.message)
    better = len(findings) - len(failed)
    status = "FAIL" if failed else "OK"
    print(f"{status}: {len(golden)} golden metrics, {len(failed)} regressions, {better} improved beyond tolerance")
    return 1 if failed else 0
